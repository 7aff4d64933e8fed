"""The one training loop: steps, a JSONL log, checkpoints, resume, interrupts, progress, a plot.

Codec training, decoder tuning and detector training each define what one step does and how
their state is written (a :class:`Run`); this loop does the rest the same way for all three:

* it calls :meth:`Run.step` until the record's step reaches its total, averaging the metrics of
  the steps between two log lines;
* every ``log_every`` steps it appends one JSON line to the log and calls ``on_log`` (the
  command line's progress bar);
* every ``checkpoint_every`` steps, on Ctrl-C and on SIGTERM it has the run write a checkpoint
  (atomically: a crash at any moment leaves the last good file); an interrupt then raises
  :class:`Interrupted`, whose message says how to go on;
* resuming continues from the record's step: log lines written after that checkpoint (and a
  line cut by a crash) are dropped, so the log and the plot hold each step once;
* in a data-parallel run (torchrun) every process steps and calls :meth:`Run.checkpoint`
  (which gathers state from all of them), but only the main process writes the log and the
  plot; an interrupt there writes no checkpoint (the processes would wait on each other), the
  last periodic one stands;
* at the end the run writes its final state and a PNG plot of the log goes beside the log
  (matplotlib is optional, the ``plot`` extra: without it one
  :class:`~deepmorph_core.errors.DeepMorphWarning` says how to get the plot).
"""

from __future__ import annotations

import json
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

from deepmorph_core.bundle import TrainingRecord
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.fileio import append_line, atomic_write

#: What a run without matplotlib says instead of drawing its plot.
NO_PLOT = "no training plot: matplotlib is not installed (pip install 'deepmorph[plot]' draws one)"


class Interrupted(DeepMorphError):
    """Training stopped by Ctrl-C or SIGTERM after writing a checkpoint."""


@dataclass(frozen=True)
class Panel:
    """One panel of the training plot: the log's ``keys`` against steps.

    Attributes:
        title: the panel's title.
        keys: metrics drawn in it (each a line).
        log_scale: a logarithmic y axis (losses).
        unit_range: a y axis from 0 to 1 (accuracies, recalls).
    """

    title: str
    keys: tuple[str, ...]
    log_scale: bool = False
    unit_range: bool = False


class Run(Protocol):
    """What the loop trains: one step at a time, with its own state and files.

    Attributes:
        record: the run's progress (``step``, ``total_steps``, ``elapsed_s``, ``finished``,
            ``metrics``, ``stage``); the loop advances ``step`` and ``elapsed_s``.
        panels: what the plot shows.
    """

    record: TrainingRecord
    panels: tuple[Panel, ...]

    def step(self) -> dict[str, float]:
        """Train one step; its metrics (averaged by the loop between log lines)."""
        ...

    def checkpoint(self) -> None:
        """Write the run's state (final when ``record.finished``), atomically."""
        ...


@dataclass
class LoopSummary:
    """What a finished run wrote, and how long it took."""

    log: Path
    plot: Path | None
    steps: int
    elapsed_s: float
    history: list[dict[str, Any]] = field(default_factory=list)


class Cadence(Protocol):
    """How often a run logs and writes a checkpoint, in steps (every run's settings say it)."""

    log_every: int
    checkpoint_every: int


class TrainingLoop:
    """Runs a :class:`Run` to its record's ``total_steps``.

    Args:
        out: the file the run checkpoints to; its log goes beside it.
        cadence: how often to log and checkpoint (the run's settings).
        log_suffix: the JSONL log is ``out`` with this suffix (created, or continued when the
            record has steps).
        resume_hint: what the interrupt message says after the step: where the checkpoint is
            and how to go on (default: continue ``out`` with ``--resume``).
        main: whether this process writes the log and the plot (rank 0 of a torchrun).
        checkpoint_on_interrupt: write a checkpoint on Ctrl-C or SIGTERM (not in a run of
            several processes: the last periodic checkpoint stands).
    """

    def __init__(
        self,
        out: str | Path,
        cadence: Cadence,
        log_suffix: str = ".log.jsonl",
        resume_hint: str | None = None,
        main: bool = True,
        checkpoint_on_interrupt: bool = True,
    ) -> None:
        self.log_path = Path(out).with_suffix(log_suffix)
        self.log_every = cadence.log_every
        self.checkpoint_every = cadence.checkpoint_every
        self.resume_hint = resume_hint or f"checkpoint written to {out} (continue with --resume)"
        self.main = main
        self.checkpoint_on_interrupt = checkpoint_on_interrupt
        self._last_checkpoint = 0

    def run(self, run: Run, on_log: Callable[[dict[str, Any]], None] | None = None) -> LoopSummary:
        """Train until ``run.record.total_steps``.

        Raises:
            Interrupted: after Ctrl-C or SIGTERM, once the checkpoint is written.
        """
        rec = run.record
        history = self._start_log(rec.step)
        started = time.perf_counter() - rec.elapsed_s
        sums: dict[str, float] = {}
        count = 0
        try:
            with _sigterm_as_interrupt():
                while rec.step < rec.total_steps:
                    metrics = run.step()
                    rec.step += 1
                    rec.elapsed_s = time.perf_counter() - started
                    for key, value in metrics.items():
                        sums[key] = sums.get(key, 0.0) + float(value)
                    count += 1
                    if rec.step % self.log_every == 0 or rec.step == rec.total_steps:
                        line = {"step": rec.step, "stage": rec.stage}
                        line.update({k: round(v / count, 5) for k, v in sums.items()})
                        line["elapsed_s"] = round(rec.elapsed_s, 2)
                        sums, count = {}, 0
                        history.append(line)
                        if self.main:
                            append_line(self.log_path, json.dumps(line))
                        rec.metrics = {k: line[k] for k in line if k not in ("step", "stage", "elapsed_s")}
                        if on_log:
                            on_log(line)
                    if rec.step % self.checkpoint_every == 0 and rec.step < rec.total_steps:
                        run.checkpoint()
                        self._last_checkpoint = rec.step
        except KeyboardInterrupt:
            rec.elapsed_s = time.perf_counter() - started
            if not self.checkpoint_on_interrupt:
                raise Interrupted(
                    f"interrupted at step {rec.step}/{rec.total_steps}; the last checkpoint is from step "
                    f"{self._last_checkpoint}: {self.resume_hint}"
                ) from None
            run.checkpoint()
            raise Interrupted(f"interrupted at step {rec.step}/{rec.total_steps}; {self.resume_hint}") from None
        rec.finished = True
        run.checkpoint()
        plot = plot_history(history, run.panels, self.log_path.with_suffix(".png")) if self.main else None
        return LoopSummary(self.log_path, plot, rec.step, rec.elapsed_s, history)

    def _start_log(self, step: int) -> list[dict[str, Any]]:
        """The log's lines up to ``step`` (a fresh, empty log at step 0), written back so that
        the lines a resumed run logs again follow them exactly once."""
        history = [line for line in read_log(self.log_path) if line.get("step", 0) <= step] if step else []
        if self.main:
            text = "".join(json.dumps(line) + "\n" for line in history)
            atomic_write(self.log_path, text.encode())
        self._last_checkpoint = step
        return history


def read_log(path: Path) -> list[dict[str, Any]]:
    """The JSON lines of a training log; a line cut by a crash (or any unreadable one) is left out."""
    try:
        text = Path(path).read_text()
    except OSError:
        return []
    out = []
    for line in text.splitlines():
        try:
            entry = json.loads(line)
        except ValueError:
            continue
        if isinstance(entry, dict):
            out.append(entry)
    return out


@contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM (what ``kill`` and container stops send) handled as Ctrl-C while training, so it
    too leaves a checkpoint; the previous handler is restored afterwards. Only the main thread
    can set handlers: elsewhere SIGTERM keeps its meaning."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def plot_history(history: list[dict[str, Any]], panels: tuple[Panel, ...], path: Path) -> Path | None:
    """The log's metrics against steps, one panel each, with the switch to stage 2 marked (PNG);
    ``None`` when there is nothing to plot, or when matplotlib is not installed (then a
    :class:`~deepmorph_core.errors.DeepMorphWarning` says so: :data:`NO_PLOT`)."""
    if not history or not panels:
        return None
    try:
        import matplotlib
    except ImportError:
        warnings.warn(NO_PLOT, DeepMorphWarning, stacklevel=2)
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [h["step"] for h in history]
    switch = next((h["step"] for h in history if h.get("stage") == 2), None)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.5 * len(panels), 3.2), squeeze=False)
    for ax, panel in zip(axes[0], panels):
        for key in panel.keys:
            ax.plot(steps, [h.get(key, float("nan")) for h in history], label=key.replace("_", " "))
        ax.set(xlabel="step", title=panel.title)
        if panel.log_scale:
            ax.set_yscale("log")
        if panel.unit_range:
            ax.set_ylim(0, 1.01)
        if switch is not None:
            ax.axvline(switch, color="grey", linestyle=":", label="stage 2")
        if len(panel.keys) > 1 or switch is not None:
            ax.legend(loc="best", fontsize=8)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write(path, buf.getvalue())
    return path
