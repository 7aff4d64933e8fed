"""The documented example runs as documented (docs/training.md points at it)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_encode_decode_example_runs(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # this checkout's packages, whatever is installed
    result = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "encode_decode.py"), str(tmp_path / "example")],
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("trained in ")
    assert lines[1] == "wrote code.svg, code.png, code.pdf (0xA5, 30 x 30 mm)"
    decoded = [line for line in lines if line.startswith(("png:", "pdf:", "photo:"))]
    assert len(decoded) == 3
    assert any("0xA5 ok=True" in line for line in decoded)
    assert not any("ok=True" in line and "0xA5" not in line for line in decoded)  # never a wrong payload
    written = {p.name for p in (tmp_path / "example").iterdir()}
    assert {"drawing.svg", "model.dmm", "code.svg", "code.png", "code.pdf"} <= written
