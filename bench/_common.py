"""Helpers shared by the benchmark scripts: threads, environment, tables, JSON."""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"


def free_port() -> int:
    """A TCP port on 127.0.0.1 free at the time of asking (the system's pick), for a server
    started by a benchmark or a test (the studio, ``torch.distributed``'s rendezvous)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def set_threads(n: int) -> int:
    """Pin torch, NumPy's BLAS (and the BLAS/OpenMP pools of any child process) to ``n``
    threads. The BLAS pool is limited at run time (``threadpoolctl``): NumPy may already be
    loaded, and its OpenBLAS pool then keeps one thread per core whatever the environment says."""
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = str(n)
    import torch
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=n, user_api="blas")

    torch.set_num_threads(n)
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:  # already set (only allowed once per process)
        pass
    return torch.get_num_threads()


def environment() -> dict[str, Any]:
    """What the numbers were measured on."""
    import torch

    return {
        "torch": torch.__version__,
        "threads": torch.get_num_threads(),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": _cpu_name(),
        "cpus": os.cpu_count(),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
    }


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "?"


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A GitHub-flavoured markdown table (also readable in a terminal); text columns left-aligned."""
    cells = [[_fmt(c) for c in row] for row in rows]
    widths = [max([len(h), *(len(r[i]) for r in cells)]) for i, h in enumerate(headers)]
    numeric = [all(_numeric(row[i]) for row in rows) for i in range(len(headers))]
    just = lambda c, i: c.rjust(widths[i]) if numeric[i] else c.ljust(widths[i])  # noqa: E731
    line = lambda r: "| " + " | ".join(just(c, i) for i, c in enumerate(r)) + " |"  # noqa: E731
    sep = "|" + "|".join(("-" * (w + 1) + ":") if n else (":" + "-" * (w + 1)) for w, n in zip(widths, numeric)) + "|"
    return "\n".join([line(headers), sep, *(line(r) for r in cells)])


def _numeric(value: Any) -> bool:
    return value is None or isinstance(value, (int, float)) or str(value)[:1] in "~0123456789.-"


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        if value != value:  # nan
            return "-"
        if value == 0 or abs(value) >= 100:
            return f"{value:.0f}"
        if abs(value) >= 1:
            return f"{value:.1f}"
        if abs(value) >= 1e-3:
            return f"{value:.4f}"
        return f"{value:.1e}"
    return str(value)


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON, creating the folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + "\n")
    return path


def parse_ints(text: str) -> list[int]:
    """``"64,128"`` -> ``[64, 128]``."""
    return [int(x) for x in text.replace(" ", "").split(",") if x]


def frame_size(text: str) -> tuple[int, int]:
    """``"1280x720"`` -> ``(1280, 720)``."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT (e.g. 1280x720)") from None
    return w, h


def add_scene_options(ap: argparse.ArgumentParser, n: int, out: Path) -> None:
    """The options every scene benchmark takes: the bundle, scenes per severity, severities,
    threads, seed and the JSON output."""
    ap.add_argument("--model", type=Path, default=None, help="bundle (default: the bundled ghost)")
    ap.add_argument("--n", type=int, default=n, help="scenes per severity")
    ap.add_argument("--severities", default="easy,medium,hard")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=out)


def add_close_up_options(ap: argparse.ArgumentParser, samples: int, seed: int, out: Path) -> None:
    """The options every close-up benchmark takes: the capture's severity, the print's width in
    camera pixels, close-ups, seed and the JSON output."""
    ap.add_argument("--severity", default="hard")
    ap.add_argument("--width", type=float, default=None, help="close-ups: the print's width in camera px")
    ap.add_argument("--samples", type=int, default=samples)
    ap.add_argument("--seed", type=int, default=seed)
    ap.add_argument("--out", type=Path, default=out)


def load_scene_model(args: argparse.Namespace) -> tuple[Path, Any]:
    """Pin torch and OpenCV to ``--threads``, then load ``--model`` (default: the bundled ghost):
    its path and the :class:`~deepmorph_core.codemodel.DeepMorphModel`."""
    set_threads(args.threads)
    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel

    cv2.setNumThreads(args.threads)
    path = args.model or BUNDLED_MODEL
    return path, DeepMorphModel.load(path)


def pose_error(viewbox: Any, found: Any, truth: Any) -> float:
    """How far the homography ``found`` (SVG units -> photo pixels) places the drawing from the
    simulator's pose ``truth``: the mean distance of the viewBox's corners, a share of the print's
    width at the pose."""
    import numpy as np

    from deepmorph_detect.camera import project, viewbox_corners
    from deepmorph_detect.metrics import corner_error

    frame = viewbox_corners(viewbox)
    true_quad = project(truth, frame)
    return corner_error(project(found, frame), true_quad) / float(np.linalg.norm(true_quad[1] - true_quad[0]))
