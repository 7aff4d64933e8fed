"""``deepmorph studio`` started as a user starts it: a child process on a free port with its own
data folder, its printed address and token read back. Shared by ``bench/studio.py`` (which times
its first page from :attr:`StudioProcess.started`) and ``tests/studio`` (which waits for its API)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from _common import free_port

ROOT = Path(__file__).resolve().parent.parent
ADDRESS = re.compile(r"(http://127\.0\.0\.1:\d+)/\?token=(\S+)")


@dataclass
class StudioProcess:
    """A started studio: its address, token and process, and when (``time.perf_counter``) the
    command was started, before Python loaded anything."""

    base: str
    token: str
    process: subprocess.Popen[str]
    started: float

    @property
    def url(self) -> str:
        """The address the studio printed, what a user opens."""
        return f"{self.base}/?token={self.token}"


@contextmanager
def studio_process(data: Path) -> Iterator[StudioProcess]:
    """``python -m deepmorph studio --no-browser`` on a free port, keeping its files in ``data``,
    on one torch thread; stopped (killed if it does not stop in 30 s) when the block ends."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    command = [sys.executable, "-m", "deepmorph", "studio", "--no-browser", "--port", str(free_port())]
    started = time.perf_counter()
    process = subprocess.Popen(
        [*command, "--data", str(data)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )
    try:
        assert process.stdout is not None
        line = process.stdout.readline()
        match = ADDRESS.search(line)
        if match is None:
            raise RuntimeError(f"the studio printed {line!r}, not its address")
        yield StudioProcess(match.group(1), match.group(2), process, started)
    finally:
        process.terminate()
        try:
            process.wait(timeout=30)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
