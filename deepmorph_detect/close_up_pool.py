"""Close-ups read by several processes at once, in the order they were made.

Reading one close-up through the photo chain is many small NumPy, OpenCV and ONNX Runtime calls
that one thread runs best, so hundreds of close-ups (a model's validation, the wrong payloads
training counts: :mod:`deepmorph_detect.photo_validation`) gain from processes, not threads.
Each worker is forked from the caller with the model already in memory (it does not pickle: its
SVG tree), builds its own :class:`~deepmorph_detect.locate.Locator`, runs torch on one thread,
and reads the close-ups handed to it. The caller makes the close-ups (their random draws stay one
stream) and receives each result in the order the close-ups came, a few in flight per worker so
that no more are held than that.
"""

from __future__ import annotations

import multiprocessing
import signal
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from multiprocessing.pool import AsyncResult
from typing import Any, TypeVar

import torch

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.threads import use_threads
from deepmorph_detect.locate import Locator

T = TypeVar("T")
#: Close-ups handed out ahead per worker: enough to keep it busy while the caller makes the next.
IN_FLIGHT_PER_WORKER = 2

#: The longest a close-up may take in a worker before the pool is taken for broken (a hard colour
#: close-up takes 0.2-0.9 s; the slowest seen a few seconds).
ANSWER_WITHIN_S = 300.0
#: The worker's reader, set once in each worker process (:func:`_start_worker`).
_WORKER: tuple[Locator, Callable[[Locator, Any], Any]] | None = None


def one_per_thread() -> int:
    """The workers a caller reads close-ups with: one process per thread it runs torch on, as a
    close-up's reading is single-threaded work (training's threads, ``--threads``)."""
    return torch.get_num_threads()


def read_close_ups(
    model: DeepMorphModel,
    shots: Iterable[Any],
    read: Callable[[Locator, Any], T],
    workers: int = 1,
    detector: str | None = None,
) -> Iterator[T]:
    """``read(locator, shot)`` for each of ``shots``, in their order, by ``workers`` processes
    (1: here), each on one :class:`Locator` of ``model`` with ``detector`` (``None``: the
    model's). ``read`` runs in the workers, so it is a module-level function, and what it
    returns comes back by pickling: a small result, not the locator's detections."""
    if workers <= 1:
        locator = Locator(model, detector=detector)
        for shot in shots:
            yield read(locator, shot)
        return
    # every worker is forked at once, before the pool starts its own threads (a fork beside a
    # running thread can copy a lock that thread holds: the child would wait on it for ever)
    context = multiprocessing.get_context("fork")  # the model is inherited, not pickled
    with context.Pool(workers, _start_worker, (model, read, detector)) as pool:
        pending: deque[AsyncResult[T]] = deque()
        for shot in shots:
            pending.append(pool.apply_async(_read_in_worker, (shot,)))
            if len(pending) >= workers * IN_FLIGHT_PER_WORKER:
                yield _answer(pending.popleft())
        while pending:
            yield _answer(pending.popleft())


def _answer(result: AsyncResult[T]) -> T:
    """A worker's result, or an error where none came within :data:`ANSWER_WITHIN_S`: a pool
    whose worker died (killed for memory, say) never answers for the close-up it held."""
    try:
        return result.get(ANSWER_WITHIN_S)
    except multiprocessing.TimeoutError:
        raise DeepMorphError(
            f"a process reading close-ups gave no answer in {ANSWER_WITHIN_S:.0f} s (killed, perhaps for memory); "
            "run again with --threads 1 to read them in one process"
        ) from None


def _start_worker(model: DeepMorphModel, read: Callable[[Locator, Any], Any], detector: str | None) -> None:
    """Each worker's start: one thread for torch and BLAS, its own locator, and Ctrl-C left to
    the caller (which stops handing out close-ups; a worker's own traceback would only repeat
    it). OpenCV's thread count is left as forked: ``cv2.setNumThreads`` in a child forked after
    the caller's OpenCV ran its thread pool waited for ever (the pool's threads are not forked)."""
    global _WORKER
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    use_threads(1, opencv=False)
    _WORKER = (Locator(model, detector=detector), read)


def _read_in_worker(shot: Any) -> Any:
    """One close-up read in a worker."""
    if _WORKER is None:  # pragma: no cover - every worker starts with _start_worker
        raise RuntimeError("a close-up worker was not started")
    locator, read = _WORKER
    return read(locator, shot)


__all__ = ["ANSWER_WITHIN_S", "IN_FLIGHT_PER_WORKER", "one_per_thread", "read_close_ups"]
