"""Command-line conventions: ``--version``, a help that lists every command, a start that
imports no torch, one meaning per flag, ``--json`` results and ``decode``'s exit status."""

from __future__ import annotations

import inspect
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, Union, get_args, get_origin, get_type_hints

import cv2
import numpy as np
import typer
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.cli.frame import EXIT_NOTHING_READ, PhotoSeverityName, SeverityName
from deepmorph_core import __version__
from deepmorph_core.bundled import BUNDLED_DRAWING, BUNDLED_MODEL
from deepmorph_core.severity import PHOTO_SEVERITIES, SEVERITIES

ROOT = Path(__file__).resolve().parents[2]
app = application()
runner = CliRunner()
commands: dict[str, Any] = typer.main.get_command(app).commands  # type: ignore[attr-defined]


def run(*args: object):
    return runner.invoke(app, [str(a) for a in args])


def test_version_names_deepmorph_its_libraries_and_plugins() -> None:
    res = run("--version")
    assert res.exit_code == 0
    lines = res.stdout.splitlines()
    assert lines[0] == f"deepmorph {__version__}"
    assert "torch " in lines[1] and "python " in lines[1] and lines[2].startswith("plugins: ")


def test_help_lists_every_command_and_the_exit_statuses() -> None:
    text = " ".join(run("--help").stdout.split())
    assert set(commands) >= {"list-primitives", "inspect", "decode", "bench-photos", "synth", "train", "demo"}
    for name, command in commands.items():
        assert f" {name} " in text, name
        assert command.get_short_help_str(limit=200).split(".")[0][:30] in text, name
    assert f"{EXIT_NOTHING_READ} decode read no verified payload" in text


def test_help_version_and_list_primitives_import_no_torch() -> None:
    """A fast start: these answer without importing torch (timed by bench/cli_start.py)."""
    probe = (
        "import sys\nfrom deepmorph.cli import main\nsys.argv = ['deepmorph', *sys.argv[1:]]\n"
        "try:\n    main()\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "print('IMPORTED', sorted(m for m in ('torch', 'cv2', 'deepmorph_primitives.line') if m in sys.modules),"
        " file=sys.stderr)\n"
    )
    # the checkout's code, the Bézier example's included, whatever the environment installed
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "plugins" / "deepmorph-bezier")])}
    for args in (["--help"], ["--version"], ["list-primitives"], ["list-primitives", "--json"]):
        done = subprocess.run([sys.executable, "-c", probe, *args], cwd=ROOT, env=env, capture_output=True,
                              text=True, timeout=120)  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert "IMPORTED []" in done.stderr, (args, done.stderr)
    listed = subprocess.run([sys.executable, "-m", "deepmorph", "list-primitives", "--json"], cwd=ROOT, env=env,
                            capture_output=True, text=True, timeout=120)  # fmt: skip
    assert {"circle", "path-arc"} <= {row["kind"] for row in json.loads(listed.stdout)}


@dataclass(frozen=True)
class Flag:
    command: str
    kind: str  # the value's type ("Literal" for a fixed choice)
    help: str
    default: Any


def _flags() -> dict[str, list[Flag]]:
    """Every option of every command, by flag, read from the commands' declarations."""
    found: dict[str, list[Flag]] = {}
    for info in app.registered_commands:
        fn = inspect.unwrap(info.callback)
        defaults = inspect.signature(fn).parameters
        for name, hint in get_type_hints(fn, include_extras=True).items():
            if get_origin(hint) is not Annotated:
                continue
            base, *meta = get_args(hint)
            option = next((m for m in meta if isinstance(m, typer.models.OptionInfo)), None)
            if option is None:
                continue
            args = [a for a in get_args(base) if a is not type(None)] if get_origin(base) is Union else [base]
            kind = "Literal" if get_origin(args[0]) is Literal else getattr(args[0], "__name__", str(args[0]))
            for flag in (option.default, *option.param_decls):
                if isinstance(flag, str) and flag.startswith("-"):
                    for spelling in flag.split("/"):
                        found.setdefault(spelling, []).append(
                            Flag(info.name, kind, option.help, defaults[name].default)
                        )
    return found


def test_one_meaning_per_flag() -> None:
    """A flag shared by commands takes the same kind of value everywhere; the shared ones
    (threads, JSON, camera, detector) have one help text and one default; the names that once
    meant different things in different commands now name one thing each."""
    flags = _flags()
    for flag, uses in flags.items():
        assert len({f.kind for f in uses}) == 1, (flag, uses)
    for flag in ("--threads", "--json", "--camera", "--detector", "--hard-decision"):
        assert len({(f.help, f.default) for f in flags[flag]}) == 1, flags[flag]
    assert {f.command for f in flags["--threads"]} >= {"train", "tune-decoder", "train-detector", "decode", "synth",
                                                     "bench-scenes", "bench-photos"}  # fmt: skip
    assert flags["--threads"][0].default is None
    assert [f.command for f in flags["--overlay"]] == ["decode"] and [f.command for f in flags["--size"]] == ["synth"]
    assert "--width" not in flags
    # fixed choices are listed in --help
    for command, flag, choices in (("train", "--severity", SEVERITIES), ("synth", "--severity", PHOTO_SEVERITIES),
                                   ("train", "--encoder-init", ("spread", "random"))):  # fmt: skip
        shown = runner.invoke(app, [command, "--help"], env={"COLUMNS": "250"}).stdout
        assert "|".join(choices) in shown, (command, flag, shown)
    assert get_args(SeverityName) == tuple(SEVERITIES) and get_args(PhotoSeverityName) == PHOTO_SEVERITIES


def test_refused_choice_is_a_usage_error() -> None:
    res = run("train", BUNDLED_DRAWING, "--out", "x.dmm", "--severity", "brutal")
    assert res.exit_code == 2 and "brutal" in res.output


def test_json_results_of_morph_render_and_encode(tmp_path: Path) -> None:
    """Each prints one JSON object on stdout and nothing else (docs/cli.md)."""
    res = run("morph", BUNDLED_DRAWING, "--random", "--seed", "2", "--out", tmp_path / "m.svg", "--json")
    assert res.exit_code == 0 and json.loads(res.stdout) == {
        "written": [str(tmp_path / "m.svg")], "variables": 58, "seed": 2}  # fmt: skip
    res = run("render", tmp_path / "m.svg", "--base", BUNDLED_DRAWING, "--out", tmp_path / "m.png", "--width-px", 64,
              "--json")  # fmt: skip
    data = json.loads(res.stdout)
    assert res.exit_code == 0 and data["written"] == [str(tmp_path / "m.png")] and data["renderer"] == "resvg"
    assert (data["width"], data["height"]) == (64, np.asarray(cv2.imread(str(tmp_path / "m.png"))).shape[0])
    res = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", tmp_path / "c.svg", "--png",
              tmp_path / "c.png", "--json")  # fmt: skip
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["written"] == [str(tmp_path / "c.svg"), str(tmp_path / "c.png")]
    assert data["payload"] == {"hex": "0xA1B2C3", "bits": "101000011011001011000011"}


def test_decode_exits_4_when_nothing_is_read_and_still_prints_the_result(tmp_path: Path) -> None:
    blank = tmp_path / "blank.png"
    cv2.imwrite(str(blank), np.full((240, 320), 255, np.uint8))
    res = run("decode", BUNDLED_MODEL, blank, "--json")
    assert res.exit_code == EXIT_NOTHING_READ == 4
    assert json.loads(res.stdout) == [{"image": str(blank), "detections": []}]
    res = run("decode", BUNDLED_MODEL, blank)
    assert res.exit_code == 4 and "no drawing found" in " ".join(res.stdout.split()) and res.stderr == ""
    assert "Exits with status 4" in " ".join(run("decode", "--help").stdout.split())


def test_the_readmes_usage_block_uses_existing_commands_and_flags() -> None:
    """Every ``deepmorph COMMAND --flag`` in the README's usage block exists (renames included)."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index("## Using it") :]
    block = block[block.index("```bash") : block.index("```", block.index("```bash") + 7)]
    flags = _flags()
    lines = [line.split("#")[0] for line in block.splitlines() if line.startswith("deepmorph ")]
    assert len(lines) > 10
    for line in lines:
        words = line.replace("[", " ").replace("]", " ").split()
        command = words[1]
        assert command in commands, line
        for flag in (w for w in words[2:] if w.startswith("--")):
            assert any(f.command == command for f in flags.get(flag, [])), (command, flag)


def test_a_piped_result_stays_on_one_line_however_long_its_path(tmp_path: Path) -> None:
    folder = tmp_path / ("a-long-folder-name-" * 5)
    folder.mkdir()
    blank = folder / "blank.png"
    cv2.imwrite(str(blank), np.full((240, 320), 255, np.uint8))
    res = run("decode", BUNDLED_MODEL, blank)
    lines = [line for line in res.stdout.splitlines() if str(blank) in line]
    assert len(lines) == 1 and "no drawing found" in lines[0], res.stdout
