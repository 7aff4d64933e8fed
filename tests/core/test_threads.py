"""``--threads``: one count for torch, OpenCV and NumPy's BLAS (deepmorph_core/threads.py).

Each case runs in a fresh interpreter: thread pools are process-wide, and the suite's own must
stay as they are.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

PROBE = """
import json, sys
import numpy  # loaded first, as in the commands: its OpenBLAS pool is already sized by then
from deepmorph_core.threads import use_threads
import cv2, torch
from threadpoolctl import threadpool_info
arg = None if sys.argv[1] == "none" else int(sys.argv[1])
n = use_threads(arg)
blas = sorted({p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"})
print(json.dumps({"n": n, "torch": torch.get_num_threads(), "cv2": cv2.getNumThreads(), "blas": blas}))
"""


def probe(threads: str) -> dict:
    out = subprocess.run([sys.executable, "-c", PROBE, threads], capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


@pytest.mark.parametrize("threads", [1, 2])
def test_use_threads_bounds_torch_opencv_and_blas(threads: int) -> None:
    got = probe(str(threads))
    assert got == {"n": threads, "torch": threads, "cv2": threads, "blas": [threads]}


def test_default_threads_are_torchs_for_every_pool() -> None:
    got = probe("none")
    assert got["torch"] == got["n"] == got["cv2"]
    assert got["blas"] == [got["n"]]
