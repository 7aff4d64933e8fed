"""Two checkouts of the photo chain side by side: the same scenes, the same run, alternating order.

``bench/side_by_side.py`` compares two *bundles* under one checkout. A change to the chain's
code needs the other comparison: the code before the change (a ``git worktree`` of an earlier
commit, say) against the code after it, each with the same bundle, on the same scenes. Each
checkout runs in a worker process of its own that imports the packages from that checkout
(``--a`` and ``--b``: repository roots); this process makes the scenes (with the current
checkout's ``deepmorph synth`` generator), hands each to both workers in alternating order, and
times OpenCV's QR ``detectAndDecode`` on a same-size frame between them. The times are taken
inside the workers, around ``Locator.locate`` alone, so the transfer is not counted. Then
``--negatives`` scenes without the drawing go to both.

The table gives prints found and read, wrong payloads reported ok, corner error, scenes where
the two checkouts differ (found, payload or ok), and the median time per frame with its ratio
to QR's and to the first checkout's. The machine is noisy: the ratios, taken in one run, are
what to read.

    git worktree add /tmp/before HEAD~1
    .venv/bin/python bench/checkouts.py --a /tmp/before --b . --n 300 --negatives 300

``--first``: both read the first print alone (``locate(first=True)``, ``decode --first``).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import set_threads  # noqa: E402
from _pairs import add_scene_arguments, compare, print_report  # noqa: E402


def _worker(root: str, bundle: str | None, detector: str | None, threads: int, first: bool, conn: Any) -> None:
    """Serve ``locate`` requests with the packages of the checkout at ``root`` (``first``: the
    first print read alone, as ``decode --first``)."""
    # the editable install's finder would hand out the installed checkout: take it away (the
    # plugins' finders stay), so that every ``deepmorph_*`` import comes from ``root``
    sys.meta_path[:] = [f for f in sys.meta_path if "deepmorph_core" not in _editable_mapping(f)]
    sys.path.insert(0, root)
    import cv2
    import torch
    from threadpoolctl import threadpool_limits

    torch.set_num_threads(threads)
    cv2.setNumThreads(threads)
    threadpool_limits(limits=threads, user_api="blas")  # NumPy's BLAS too, in either checkout
    import deepmorph_detect
    from deepmorph_detect.locate import Locator

    try:
        from deepmorph_core.bundled import BUNDLED_MODEL
        from deepmorph_core.model import DeepMorphModel
    except ImportError:  # a checkout from before the packages were restructured
        from deepmorph_core.api import BUNDLED_MODEL
        from deepmorph_core.codemodel import DeepMorphModel

    model = DeepMorphModel.load(Path(bundle) if bundle else BUNDLED_MODEL)
    locator = Locator(model, detector=detector) if detector else Locator(model)
    conn.send(str(Path(deepmorph_detect.__file__).resolve().parent.parent))
    while True:
        job = conn.recv()
        if job is None:
            return
        image, camera = job
        t0 = time.perf_counter()
        found = locator.locate(image, camera, first=True) if first else locator.locate(image, camera)
        ms = 1000 * (time.perf_counter() - t0)
        conn.send((ms, [{"corners": d.corners, "payload": d.result.payload, "ok": bool(d.result.ok)} for d in found]))


def _editable_mapping(finder: Any) -> dict[str, str]:
    """The packages a setuptools editable-install finder maps to source folders (else empty)."""
    module = sys.modules.get(getattr(finder, "__module__", ""), None)
    return getattr(module, "MAPPING", {}) if "editable" in getattr(finder, "__module__", "") else {}


def _as_detections(found: list[dict[str, Any]]) -> list[Any]:
    """Worker answers in the shape :func:`~deepmorph_detect.metrics.matched_detections` reads."""
    return [
        SimpleNamespace(corners=f["corners"], result=SimpleNamespace(payload=f["payload"], ok=f["ok"])) for f in found
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", type=Path, required=True, help="first checkout (repository root): the code before")
    ap.add_argument("--b", type=Path, default=Path("."), help="second checkout: the code after (default: this one)")
    ap.add_argument("--bundle", type=Path, default=None, help="bundle both decode with (default: the bundled ghost)")
    ap.add_argument("--detector", default=None, help="detector both use (default: the bundle's)")
    ap.add_argument("--first", action="store_true", help="both read the first print alone (decode --first)")
    add_scene_arguments(ap, "checkouts.json")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel

    cv2.setNumThreads(args.threads)
    model = DeepMorphModel.load(args.bundle or BUNDLED_MODEL)
    ctx = mp.get_context("spawn")
    roots = {"a": str(args.a.resolve()), "b": str(args.b.resolve())}
    conns, procs = {}, []
    for k, root in roots.items():
        parent, child = ctx.Pipe()
        bundle = str(args.bundle) if args.bundle else None
        proc = ctx.Process(target=_worker, args=(root, bundle, args.detector, args.threads, args.first, child))
        proc.start()
        procs.append(proc)
        conns[k] = parent
    for k, conn in conns.items():
        loaded = conn.recv()
        if Path(loaded) != Path(roots[k]):
            sys.exit(f"checkouts: worker {k} imported the packages from {loaded}, not {roots[k]}")

    def locate(k: str, image: Any, camera: Any) -> tuple[float, list[Any]]:
        conns[k].send((image, camera))
        ms, found = conns[k].recv()
        return ms, _as_detections(found)

    report, rows = compare(model, locate, args)
    for conn in conns.values():
        conn.send(None)
    for proc in procs:
        proc.join()
    report["checkouts"] = roots
    report["detector"] = args.detector or "the bundle's"
    report["first"] = args.first
    print_report(report, rows, roots, "checkout", args.out)


if __name__ == "__main__":
    main()
