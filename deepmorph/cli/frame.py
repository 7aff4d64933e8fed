"""What every command shares: the consoles, one-line errors, common options, progress bars.

Commands (the command line's own in :mod:`deepmorph.cli.commands`, plugins' through the
``deepmorph_register_commands`` hook) import these; nothing here imports torch.
"""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, TypeVar

import typer
from rich.console import Console
from rich.text import Text

from deepmorph.training.settings import PHOTO_SAMPLES, RENDER_SAMPLES, TrainSettings, exposed
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.fileio import atomic_write

_UNPRINTABLE = re.compile(r"[\x00-\x08\x0b-\x1f\x7f-\x9f\u200b-\u200f\u202a-\u202e\u2066-\u2069]")


def safe(text: object) -> str:
    """``text`` with control characters (terminal escapes, bidirectional overrides) shown as
    ``\\xNN`` escapes: what a path or a bundle's metadata holds is printed, never obeyed."""
    return _UNPRINTABLE.sub(_escape, str(text))


def _escape(m: re.Match[str]) -> str:
    code = ord(m.group())
    return f"\\x{code:02x}" if code < 256 else f"\\u{code:04x}"


class _Console(Console):
    """A console that never reads markup in what it prints and escapes control characters in
    every string it is given (paths and names come from users and from files). Text written to
    a pipe or a file is not wrapped: one result stays on one line for the program reading it,
    however long its path."""

    def print(self, *objects: Any, **kwargs: Any) -> None:  # noqa: A003 - rich's name
        kwargs.setdefault("markup", False)
        kwargs.setdefault("highlight", False)
        if not self.is_terminal and all(isinstance(o, str) for o in objects):
            kwargs.setdefault("soft_wrap", True)
        super().print(*(safe(o) if isinstance(o, str) else o for o in objects), **kwargs)


out = _Console(markup=False, highlight=False, emoji=False)
err = _Console(stderr=True, markup=False, highlight=False, emoji=False)

F = TypeVar("F", bound=Callable[..., Any])


def print_json(data: Any) -> None:
    """``data`` as JSON on stdout, one document, no colour (fast for large results, and what a
    program reading the output expects)."""
    import json
    import sys

    sys.stdout.write(json.dumps(data, indent=2) + "\n")
    sys.stdout.flush()


def print_error(exc: BaseException) -> None:
    """One line on stderr, never interpreted as markup, never wrapped."""
    err.print(Text.assemble(("error: ", "bold red"), safe(exc)), soft_wrap=True, highlight=False)


def friendly(fn: F) -> F:
    """Turn a DeepMorphError raised by a command into one ``error:`` line and exit status 1,
    and each :class:`~deepmorph_core.errors.DeepMorphWarning` into one ``warning:`` line."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with warnings.catch_warnings():
            shown = warnings.showwarning

            def show(message: Warning | str, category: type[Warning], *rest: Any, **more: Any) -> None:
                if issubclass(category, DeepMorphWarning):
                    err.print(Text.assemble(("warning: ", "yellow"), safe(message)), soft_wrap=True)
                else:
                    shown(message, category, *rest, **more)

            warnings.showwarning = show
            try:
                return fn(*args, **kwargs)
            except DeepMorphError as exc:
                print_error(exc)
                raise typer.Exit(1) from None

    return wrapper  # type: ignore[return-value]


SvgArg = Annotated[Path, typer.Argument(help="An SVG drawing.", show_default=False)]


MoveOpt = Annotated[Optional[float], typer.Option("--move", help="Default dm:move radius for elements without bounds.")]


ShiftOpt = Annotated[Optional[str], typer.Option("--shift", help='Default dm:shift: "R" or "RX,RY".')]


ScaleOpt = Annotated[Optional[str], typer.Option("--scale", help='Default dm:scale: "LO,HI".')]


RotateOpt = Annotated[Optional[str], typer.Option("--rotate", help='Default dm:rotate in degrees: "LO,HI".')]


DropOpt = Annotated[
    bool,
    typer.Option(
        "--drop-unsupported",
        help="Leave out what DeepMorph cannot model (CSS, filters, text, images ...) instead of refusing the file.",
    ),
]
JsonOpt = Annotated[
    bool, typer.Option("--json", help="Print the result as one JSON document on stdout, and nothing else there.")
]


def add_commands(cli: typer.Typer, table: tuple[tuple[str, Callable[..., Any], str | None], ...]) -> None:
    """Add ``(name, function, help panel)`` commands to ``cli``, each turning a DeepMorphError
    into one ``error:`` line (:func:`friendly`)."""
    for name, command, panel in table:
        cli.command(name, rich_help_panel=panel)(friendly(command))


def training_result(summary: Any, metrics: dict[str, Any] | None, **extra: Any) -> dict[str, Any]:
    """The ``--json`` result of a training command: what it wrote (``summary``: ``bundle``,
    ``log``, ``plot``, ``steps``, ``elapsed_s``), ``extra`` fields, and the last logged metrics."""
    files = [summary.bundle, summary.log, summary.plot]
    return {
        "written": [str(p) for p in files if p is not None],
        "bundle": str(summary.bundle),
        "log": str(summary.log),
        "plot": None if summary.plot is None else str(summary.plot),
        "steps": summary.steps,
        **extra,
        "elapsed_s": round(summary.elapsed_s, 3),
        "metrics": metrics,
    }


def parse_pair(text: str | None, name: str, single_ok: bool = False) -> tuple[float, float] | None:
    if text is None:
        return None
    parts = [p for p in text.replace(",", " ").split() if p]
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise DeepMorphError(f"--{name}={text!r}: expected numbers") from None
    if single_ok and len(nums) == 1:
        return nums[0], nums[0]
    if len(nums) != 2:
        raise DeepMorphError(f'--{name}={text!r}: expected two numbers "LO,HI"')
    return nums[0], nums[1]


def progress_bar(description: str = "{task.description}"):  # noqa: ANN201 - a rich Progress
    """The progress bar of long commands: description, bar, count, elapsed, ETA.

    Drawn on stderr, and only when stderr is a terminal: stdout holds the result alone (the
    one JSON document of ``--json``), and logs and pipes get no redrawn lines."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn(description),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=err,
        disable=not err.is_terminal,
    )


class StepProgress:
    """The progress bar of a training run, and its last logged metrics.

    Called as ``on_start(total, done)`` by the training functions: starts the bar and returns
    the per-log callback (``describe(metrics)`` is the bar's text; the metrics are kept in
    :attr:`last` for the command's result).
    """

    def __init__(self, label: str, describe: Callable[[Any], str]):
        self.label = label
        self.describe = describe
        self.last: dict[str, Any] | None = None
        self.progress = progress_bar()

    def __call__(self, total: int, done: int) -> Callable[[Any], None]:
        self.progress.start()
        task = self.progress.add_task(self.label, total=total, completed=done)
        bar_total = total

        def on_log(m: dict[str, Any]) -> None:
            nonlocal bar_total
            self.last = dict(m)
            # an auto code cut when training ended trains on past the steps the bar started with
            bar_total = max(bar_total, m["step"])
            self.progress.update(task, completed=m["step"], total=bar_total, description=self.describe(m))

        return on_log


@contextmanager
def step_progress(label: str, describe: Callable[[Any], str]) -> Iterator[StepProgress]:
    """A :class:`StepProgress` stopped on the way out. Callers start it only once the settings
    are validated, so an error prints alone; a bar never started is never stopped (that would
    print a stray newline)."""
    bar = StepProgress(label, describe)
    try:
        yield bar
    finally:
        if bar.progress.live.is_started:
            bar.progress.stop()


def warn_dropped(drawing: Any) -> None:
    """One warning line per thing ``--drop-unsupported`` left out of a drawing."""
    for line, what in getattr(drawing, "dropped", []):
        err.print(f"warning: {drawing.source}:{line}: left out {what}")


def write_text_atomic(path: Path, text: str) -> None:
    """Write a text file so that a crash never leaves it half written."""
    atomic_write(path, text.encode("utf-8"))


ModelArg = Annotated[Path, typer.Argument(help="A DeepMorph model bundle (.dmm).", show_default=False)]


SeedOpt = Annotated[int, typer.Option("--seed", help="Random seed (reproducible runs).")]


DeviceOpt = Annotated[
    Literal["auto", "cpu", "cuda"],
    typer.Option("--device", help="Where torch runs: auto is CUDA where a CUDA device is present, else the CPU."),
]


ThreadsOpt = Annotated[
    Optional[int],
    typer.Option(
        "--threads",
        min=1,
        max=256,
        help="CPU threads for torch and OpenCV [default: one per physical core].",
        show_default=False,
    ),
]

#: ``decode``'s exit status when an input gave no verified payload (zbarimg's "nothing found").
EXIT_NOTHING_READ = 4

#: The capture severities (:data:`deepmorph_core.severity.SEVERITIES`; a test keeps them equal).
SeverityName = Literal["none", "easy", "medium", "hard"]
#: The severities with photo settings (:data:`deepmorph_core.severity.PHOTO_SEVERITIES`).
PhotoSeverityName = Literal["easy", "medium", "hard"]

#: Panels grouping the commands in ``deepmorph --help``.
PANEL_DRAWINGS = "Drawings"
PANEL_MODELS = "Models"
PANEL_CODES = "Codes and photos"
PANEL_MEASURE = "Measuring"

ValidationOpt = Annotated[
    Optional[str],
    typer.Option(
        "--validation",
        help="Fresh payloads read back when done, from renders and close-up photos: R,P "
        f"(default {RENDER_SAMPLES},{PHOTO_SAMPLES}; 0: none).",
    ),
]


def setting_option(field: str, help: str | None = None, settings: type = TrainSettings) -> Any:  # noqa: A002 - the option's help
    """The option of training setting ``field``: its flag, help and bounds as
    :class:`~deepmorph.training.settings.TrainSettings` (or ``settings``, such as
    :class:`~deepmorph.training.settings.TuneSettings`) declares them (``help`` replaces its
    line; a flag on or off is ``--x/--no-x``). Its default is the class's own."""
    setting = exposed(settings)[field]
    flag = f"--{setting.option}" + (f"/--no-{setting.option}" if setting.switch else "")
    return typer.Option(flag, min=setting.ge, max=setting.le, help=help or setting.help)
