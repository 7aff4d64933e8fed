"""How many CPU threads the work runs on: torch, OpenCV and NumPy's BLAS, all the same count.

``--threads N`` must bound every thread pool a command uses, not torch's alone. The photo
chain also solves small least-squares problems and QR factorisations in NumPy (the per-bit
check, :mod:`deepmorph_detect.synthesis`), whose OpenBLAS pool otherwise keeps one thread per
core: on 2 cores with the other one busy, its threads wait on each other and a frame of the
bundled ghost took 38 ms instead of 17 (``docs/design-notes.md``). The BLAS pool is limited at
run time with ``threadpoolctl`` (environment variables are read only when NumPy loads).
"""

from __future__ import annotations

from functools import cache


@cache
def _controller():  # noqa: ANN202 - threadpoolctl is untyped
    """The process's thread pools, inspected once (about 0.1 s)."""
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def use_threads(threads: int | None, opencv: bool = True) -> int:
    """Run torch, OpenCV and NumPy's BLAS on ``threads`` CPU threads (``None``: torch's
    default, one per physical core), the same count for all; returns the count in use.
    ``opencv`` false leaves OpenCV's pool as it is: in a process forked after OpenCV's pool had
    run, ``cv2.setNumThreads`` waits for ever (:mod:`deepmorph_detect.close_up_pool`)."""
    import torch

    if threads is not None:
        torch.set_num_threads(threads)
    n = torch.get_num_threads()
    if opencv:
        import cv2

        cv2.setNumThreads(n)
    _controller().limit(limits=n, user_api="blas")
    return n


__all__ = ["use_threads"]
