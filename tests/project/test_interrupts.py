"""Interrupted training, end to end in real processes: SIGTERM and Ctrl-C leave a checkpoint,
``kill -9`` at any moment loses at most one checkpoint interval and never corrupts the bundle,
and ``--resume`` finishes the run."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from deepmorph_core.model import DeepMorphModel
from tests.conftest import make_svg

TINY = make_svg(
    '<g stroke="black" stroke-width="2.5" stroke-linecap="round" fill="none" dm:move="2">'
    '<polyline points="4 6 12 4 20 6"/><line x1="4" y1="12" x2="20" y2="12"/><circle cx="12" cy="18" r="3"/></g>'
)
TRAIN = ["--payload-bits", "4", "--crc", "8", "--ecc-t", "0", "--image-width", "32", "--batch", "4",
         "--severity", "none", "--real-render-share", "0", "--threads", "1", "--validation", "8,0"]  # fmt: skip
CHECKPOINT_EVERY = 10


def _train(svg: Path, out: Path, steps: int, *extra: str) -> subprocess.Popen[str]:
    every = ["--checkpoint-every", str(CHECKPOINT_EVERY)]
    args = ["train", str(svg), "--out", str(out), "--steps", str(steps), *every, *TRAIN, *extra]
    return subprocess.Popen(
        [sys.executable, "-m", "deepmorph", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_as_at_a_terminal,
    )


def _as_at_a_terminal() -> None:
    """Ctrl-C's default action, as in a shell's foreground: a job a script starts in the
    background (``cmd &``, as CI runners may) inherits SIGINT ignored, and Python then never
    raises KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _resume(svg: Path, out: Path, steps: int) -> subprocess.CompletedProcess[str]:
    """``deepmorph train --resume`` of the checkpoint at ``out`` up to ``steps``, to the end."""
    args = ["train", str(svg), "--out", str(out), "--resume", "--steps", str(steps), "--validation", "8,0"]
    return subprocess.run([sys.executable, "-m", "deepmorph", *args], capture_output=True, text=True, timeout=120)


def _wait_for_steps(log: Path, steps: int, proc: subprocess.Popen[str], timeout: float = 120) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if log.is_file():
            lines = [json.loads(x) for x in log.read_text().splitlines() if x.strip().endswith("}")]
            if lines and lines[-1]["step"] >= steps:
                return
        if proc.poll() is not None:
            pytest.fail(f"training ended early: {proc.stderr.read() if proc.stderr else ''}")
        time.sleep(0.05)
    pytest.fail("training made no progress")


@pytest.fixture
def svg(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.svg"
    path.write_bytes(TINY)
    return path


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_sigterm_and_ctrl_c_leave_a_checkpoint_that_resumes(svg: Path, tmp_path: Path, sig: signal.Signals) -> None:
    out = tmp_path / "model.dmm"
    proc = _train(svg, out, 400)
    _wait_for_steps(out.with_suffix(".log.jsonl"), 14, proc)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1, err
    assert "Traceback" not in err and "interrupted at step" in err and "checkpoint written" in err
    step = DeepMorphModel.load(out).meta.record.step
    assert step >= 14 and not DeepMorphModel.load(out).meta.record.finished
    done = _resume(svg, out, step + 6)
    assert done.returncode == 0, done.stderr
    finished = DeepMorphModel.load(out).meta.record
    assert finished.finished and finished.step == step + 6


def test_kill_9_at_any_moment_loses_at_most_one_checkpoint_interval(svg: Path, tmp_path: Path) -> None:
    out = tmp_path / "model.dmm"
    log = out.with_suffix(".log.jsonl")
    for kill_at in (3, 40, 70):  # before the first checkpoint, and between later ones
        resuming = out.exists()
        proc = _train(svg, out, 100_000, *(["--resume"] if resuming else []))
        _wait_for_steps(log, kill_at, proc)
        time.sleep(0.05 * (kill_at % 4))  # somewhere in the next steps, maybe mid-write
        logged = max(json.loads(x)["step"] for x in log.read_text().splitlines() if x.strip().endswith("}"))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        if out.exists():
            record = DeepMorphModel.load(out).meta.record  # never corrupt
            assert logged - record.step <= CHECKPOINT_EVERY + 2, (logged, record.step)
    strays = [p.name for p in tmp_path.iterdir() if p.name.startswith(".dm-")]
    done = _resume(svg, out, 120)
    assert done.returncode == 0, done.stderr
    assert DeepMorphModel.load(out).meta.record.finished
    log_steps = [json.loads(x)["step"] for x in log.read_text().splitlines()]
    assert log_steps == sorted(set(log_steps)), "each step is logged once after resuming"
    left = [p.name for p in tmp_path.iterdir() if p.name.startswith(".dm-")]
    assert not left, f"stray temporary files {strays} were not cleaned: {left}"
