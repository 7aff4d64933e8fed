"""Close-ups read by several processes at once, in the order they were made.

Reading one close-up through the photo chain is many small NumPy, OpenCV and ONNX Runtime calls
that one thread runs best, so a count over hundreds of close-ups (the wrong payloads training
counts, :func:`~deepmorph_detect.photo_validation.count_wrong_payloads`) gains from processes,
not threads. Each worker is forked from the caller with the model already in memory, builds its
own :class:`~deepmorph_detect.locate.Locator` on one thread, and reads the close-ups handed to it;
the caller makes the close-ups (their random draws stay one stream) and receives each result in
the order the close-ups came, a few in flight per worker so that no more are held than that.
"""

from __future__ import annotations

import multiprocessing
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from typing import Any, TypeVar

from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.locate import Locator

T = TypeVar("T")
#: Close-ups handed out ahead per worker: enough to keep it busy while the caller makes the next.
IN_FLIGHT_PER_WORKER = 2

#: The worker's reader, set once in each worker process (:func:`_start_worker`).
_WORKER: tuple[Locator, Callable[[Locator, Any], Any]] | None = None


def read_close_ups(
    model: DeepMorphModel, shots: Iterable[Any], read: Callable[[Locator, Any], T], workers: int = 1
) -> Iterator[T]:
    """``read(locator, shot)`` for each of ``shots``, in their order, by ``workers`` processes
    (1: here, on one :class:`Locator` of ``model``). ``read`` runs in the workers, so it is a
    module-level function, and what it returns comes back by pickling: a small result, not the
    locator's detections with their images."""
    if workers <= 1:
        locator = Locator(model)
        for shot in shots:
            yield read(locator, shot)
        return
    context = multiprocessing.get_context("fork")  # the model is inherited, not pickled
    with ProcessPoolExecutor(workers, context, initializer=_start_worker, initargs=(model, read)) as pool:
        pending: deque[Future[T]] = deque()
        for shot in shots:
            pending.append(pool.submit(_read_in_worker, shot))
            if len(pending) >= workers * IN_FLIGHT_PER_WORKER:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()


def _start_worker(model: DeepMorphModel, read: Callable[[Locator, Any], Any]) -> None:
    """Each worker's start: one thread for torch, OpenCV and BLAS, and its own locator."""
    global _WORKER
    from deepmorph_core.threads import use_threads

    use_threads(1)
    _WORKER = (Locator(model), read)


def _read_in_worker(shot: Any) -> Any:
    """One close-up read in a worker."""
    if _WORKER is None:  # pragma: no cover - every worker starts with _start_worker
        raise RuntimeError("a close-up worker was not started")
    locator, read = _WORKER
    return read(locator, shot)


__all__ = ["IN_FLIGHT_PER_WORKER", "read_close_ups"]
