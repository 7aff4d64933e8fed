"""Training every drawing of a folder: one process per device, done ones skipped, checkpoints resumed.

``deepmorph train-many drawings/ --out models/`` trains ``drawings/<name>.svg`` into
``models/<name>.dmm`` with :func:`~deepmorph.training.codec.train_model`:

* a bundle whose training has finished is **done** and left alone; a checkpoint (a bundle not
  finished) is **resumed**; anything else is trained from the start;
* the drawings are shared by worker processes, one per device: each CUDA device has one
  process of its own; on the CPU there is one process, or ``jobs`` of them (each with its share
  of the threads). The pool is :class:`concurrent.futures.ProcessPoolExecutor`; nothing more;
* a drawing that fails (unreadable, unsupported, no payload fits) is reported with its one-line
  error and the others go on.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

from deepmorph.training.distributed import World
from deepmorph_core.bundle import load_bundle
from deepmorph_core.device import resolve_device
from deepmorph_core.errors import DeepMorphError

Status = Literal["trained", "resumed", "done", "failed"]


@dataclass
class DrawingResult:
    """What happened to one drawing.

    Attributes:
        drawing: the SVG.
        bundle: its bundle (written, resumed, or found done).
        status: ``trained`` (from the start), ``resumed`` (from its checkpoint), ``done``
            (finished before: left alone) or ``failed``.
        payload_bits: the bundle's payload size (``None`` when failed).
        steps: its training steps.
        seconds: time spent on it in this run.
        validation: ``{name: share of payloads read}`` of its stored validation.
        error: the one-line error of a failed drawing.
        warnings: warnings its training gave.
    """

    drawing: str
    bundle: str
    status: Status
    payload_bits: int | None = None
    steps: int | None = None
    seconds: float = 0.0
    validation: dict[str, float] = field(default_factory=dict)
    error: str | None = None
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Job:
    """One drawing to train, and how (picklable: it crosses to a worker process)."""

    svg: Path
    out: Path
    resume: bool
    payload_bits: int | Literal["auto"]
    bounds: dict[str, Any]
    train: dict[str, Any]
    validation_samples: tuple[int, int] | None


def drawings_in(folder: Path) -> list[Path]:
    """The ``*.svg`` files of ``folder``, by name.

    Raises:
        DeepMorphError: not a folder, or one without drawings.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise DeepMorphError(f"{folder}: not a folder of drawings")
    svgs = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".svg" and p.is_file())
    if not svgs:
        raise DeepMorphError(f"{folder}: no .svg drawings in it")
    return svgs


def plan(svgs: list[Path], out_dir: Path) -> list[tuple[Path, Path, Status | None]]:
    """``(svg, bundle, state)`` per drawing: ``done`` (finished bundle), ``resumed`` (a
    checkpoint) or ``None`` (train from the start). A bundle that cannot be read is ``failed``
    there, not overwritten."""
    rows: list[tuple[Path, Path, Status | None]] = []
    for svg in svgs:
        bundle = out_dir / f"{svg.stem}.dmm"
        if not bundle.exists():
            rows.append((svg, bundle, None))
            continue
        try:
            meta, _ = load_bundle(bundle)
        except DeepMorphError:
            rows.append((svg, bundle, "failed"))
            continue
        rows.append((svg, bundle, "done" if meta.record.finished else "resumed"))
    return rows


def result_of(
    svg: Path, bundle: Path, status: Status, seconds: float = 0.0, warnings: list[str] | None = None
) -> DrawingResult:
    """The :class:`DrawingResult` of a bundle on disk (payload, steps, stored validation)."""
    meta, _ = load_bundle(bundle)
    return DrawingResult(
        str(svg),
        str(bundle),
        status,
        payload_bits=meta.codec.payload_bits,
        steps=meta.record.step,
        seconds=round(seconds, 1),
        validation={r.name: round(r.rate, 4) for r in meta.validation},
        warnings=warnings or [],
    )


def run_job(job: Job) -> DrawingResult:
    """Train one drawing; every failure becomes its :class:`DrawingResult`'s one-line ``error``."""
    from deepmorph.training.codec import train_model

    start = time.perf_counter()
    warnings: list[str] = []
    try:
        train_model(
            job.svg,
            job.out,
            payload_bits=job.payload_bits,
            bounds=job.bounds,
            train=job.train,
            resume=job.resume,
            on_warning=warnings.append,
            validation_samples=job.validation_samples,
            world=World(),  # one process a drawing, whatever the environment says
        )
        status: Status = "resumed" if job.resume else "trained"
        return result_of(job.svg, job.out, status, time.perf_counter() - start, warnings)
    except DeepMorphError as exc:
        error = str(exc)
    except Exception as exc:  # noqa: BLE001 - one drawing's failure must not stop the others
        error = f"{type(exc).__name__}: {exc}"
    first = error.splitlines()[0] if error else "failed"
    seconds = round(time.perf_counter() - start, 1)
    return DrawingResult(str(job.svg), str(job.out), "failed", seconds=seconds, error=first, warnings=warnings)


def _pin_worker(devices: Any) -> None:
    """A CUDA worker's initializer: take one device of the queue and use it alone."""
    import torch

    torch.cuda.set_device(devices.get())


def train_many(
    folder: str | Path,
    out_dir: str | Path,
    *,
    payload_bits: int | Literal["auto"] = "auto",
    bounds: dict[str, Any] | None = None,
    train: dict[str, Any] | None = None,
    device: str = "auto",
    jobs: int | None = None,
    validation_samples: tuple[int, int] | None = None,
    on_result: Callable[[DrawingResult, int, int], None] | None = None,
) -> list[DrawingResult]:
    """Train every drawing in ``folder`` into ``out_dir`` (module docstring).

    Args:
        payload_bits, bounds, validation_samples: as :func:`~deepmorph.training.codec.train_model`
            takes them, the same for every drawing (``auto``: each its own predicted size).
        train: :class:`~deepmorph.training.codec.TrainConfig` fields for new trainings (a resumed
            one keeps its checkpoint's, but for ``steps`` and ``threads``).
        device: ``auto``, ``cpu`` or ``cuda``.
        jobs: worker processes (default: one per CUDA device, one on the CPU).
        on_result: ``on_result(result, finished, total)`` as each drawing ends (a progress line).

    Returns:
        One result per drawing, in the folder's order.

    Raises:
        DeepMorphError: the folder has no drawings, ``out_dir`` is not a folder, or ``jobs`` is
            more than the CUDA devices.
    """
    where = resolve_device(device)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise DeepMorphError(f"--out {out_dir}: not a folder")
    svgs = drawings_in(Path(folder))
    out_dir.mkdir(parents=True, exist_ok=True)
    import torch

    gpus = torch.cuda.device_count() if where == "cuda" else 0
    workers = jobs or (gpus or 1)
    if where == "cuda" and workers > gpus:
        raise DeepMorphError(f"--jobs {workers}: one process per CUDA device, and there are {gpus}")
    settings = {**(train or {}), "device": where}
    if where == "cpu" and workers > 1 and settings.get("threads") is None:
        settings["threads"] = max(1, (os.cpu_count() or 1) // workers)
    results: dict[int, DrawingResult] = {}
    pending: list[tuple[int, Job]] = []
    for i, (svg, bundle, state) in enumerate(plan(svgs, out_dir)):
        if state == "done":
            results[i] = result_of(svg, bundle, "done")
        elif state == "failed":
            why = f"{bundle}: exists and is not a readable model; move it away to retrain"
            results[i] = DrawingResult(str(svg), str(bundle), "failed", error=why)
        else:
            job = Job(svg, bundle, state == "resumed", payload_bits, dict(bounds or {}), settings, validation_samples)
            pending.append((i, job))
    total, finished = len(svgs), len(results)
    for i in sorted(results):
        if on_result:
            on_result(results[i], finished, total)
    if workers == 1 or len(pending) <= 1:
        for i, job in pending:
            results[i] = run_job(job)
            finished += 1
            if on_result:
                on_result(results[i], finished, total)
    else:
        context = multiprocessing.get_context("spawn")  # a fresh interpreter: no forked torch state
        initializer, initargs = None, ()
        if where == "cuda":
            queue = context.Manager().Queue()
            for g in range(workers):
                queue.put(g)
            initializer, initargs = _pin_worker, (queue,)
        with ProcessPoolExecutor(min(workers, len(pending)), context, initializer, initargs) as pool:
            futures = {pool.submit(run_job, job): i for i, job in pending}
            for future in as_completed(futures):
                i = futures[future]
                try:
                    results[i] = future.result()
                except Exception as exc:  # noqa: BLE001 - a worker that died (out of memory, say)
                    job = dict(pending)[i]
                    results[i] = DrawingResult(str(job.svg), str(job.out), "failed", error=f"its worker died: {exc}")
                finished += 1
                if on_result:
                    on_result(results[i], finished, total)
    return [results[i] for i in range(len(svgs))]
