"""The studio's training queue: runs kept on disk, trained one at a time in a child process.

Each run is a JSON file in ``<data>/studio/jobs/``, rewritten whole at each change, so a page
reload (or a restarted studio) finds every run where it was; a run left ``running`` by a studio
that stopped is marked ``interrupted`` (its checkpoint stays, ``deepmorph train --resume``
continues it). One thread starts queued runs in order, each as ``python -m
deepmorph.studio.worker``; cancelling a running one sends it SIGTERM, and the training loop
writes its checkpoint before it stops. A run is refused before it is queued when the data
folder's disk has less than :data:`MIN_FREE_BYTES` free.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write

MIN_FREE_BYTES = 512 * 1024 * 1024  # a bundle is a few MB, its checkpoints and logs as much again
HISTORY_POINTS = 400  # bit accuracy points kept for the page's plot
ACTIVE = ("queued", "running")


@dataclass
class Job:
    """One training run as the page shows it.

    Attributes:
        id: its name in URLs.
        drawing: the drawing's file name.
        svg: the drawing as it was when the run was queued.
        out: the bundle it writes.
        settings: ``payload_bits``, ``train`` (TrainConfig fields) and ``validation``.
        status: ``queued``, ``running``, ``validating``, ``finished``, ``failed``, ``cancelled``
            or ``interrupted``.
        step, total: training steps done and to do.
        elapsed_s: training time so far.
        metrics: the last log line's metrics (``loss``, ``bit_acc`` ...).
        history: ``[step, bit_acc]`` pairs for the plot.
        message: why it failed or stopped; or the validation in words.
        warnings: what training warned of (a payload above the predicted capacity, a validation
            under 99 % ...).
        created: when it was queued (seconds since the epoch).
    """

    id: str
    drawing: str
    svg: str
    out: str
    settings: dict[str, Any]
    status: str = "queued"
    step: int = 0
    total: int = 0
    elapsed_s: float = 0.0
    metrics: dict[str, float] = field(default_factory=dict)
    history: list[list[float]] = field(default_factory=list)
    message: str = ""
    warnings: list[str] = field(default_factory=list)
    created: float = field(default_factory=time.time)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def validation_words(records: list[dict[str, Any]]) -> str:
    """The validation in plain words: "reads 99.4 % of simulated phone photos ..."."""
    parts = []
    for r in records:
        if not r.get("samples"):
            continue
        share = 100.0 * r["read"] / r["samples"]
        what = "simulated phone photos" if r["name"] == "close-ups" else "fresh renders"
        wrong = f", {r['wrong']} wrong" if r.get("wrong") else ""
        parts.append(f"reads {share:.1f} % of {r['samples']} {what}{wrong}")
    return "; ".join(parts) if parts else "finished (no validation asked for)"


class JobQueue:
    """The queue of training runs kept in ``folder``.

    Args:
        folder: where runs are kept (``<data>/studio/jobs``).
        models: where bundles are written (``<data>/studio/models``).
        min_free_bytes: free disk space a run needs before it is queued.
    """

    def __init__(self, folder: Path, models: Path, min_free_bytes: int = MIN_FREE_BYTES) -> None:
        self.folder = folder
        self.models = models
        self.min_free_bytes = min_free_bytes
        folder.mkdir(parents=True, exist_ok=True)
        models.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._jobs: dict[str, Job] = {}
        self._process: subprocess.Popen[str] | None = None
        self._running: str | None = None
        self._cancelled: set[str] = set()  # runs asked to stop (a worker killed before its loop began says nothing)
        self.version = 0  # bumped at every change: the event stream sends a snapshot then
        for path in sorted(folder.glob("*.json")):
            try:
                job = Job(**json.loads(path.read_text()))
            except (OSError, ValueError, TypeError):
                continue
            if job.status in ("running", "validating"):
                job.status, job.message = "interrupted", "the studio stopped during this run; its checkpoint is kept"
                self._save(job)
            self._jobs[job.id] = job
        self._thread = threading.Thread(target=self._serve, name="deepmorph-studio-jobs", daemon=True)
        self._thread.start()

    def list(self) -> list[dict[str, Any]]:  # noqa: A003 - the queue's verb
        """Every run, newest first, as JSON (without the drawing's text)."""
        with self._lock:
            jobs = sorted(self._jobs.values(), key=lambda j: j.created, reverse=True)
            return [{k: v for k, v in j.to_json().items() if k != "svg"} for j in jobs]

    def submit(self, drawing: str, svg: str, settings: dict[str, Any]) -> dict[str, Any]:
        """Queue a run for ``svg``.

        Raises:
            DeepMorphError: too little free disk space.
        """
        free = shutil.disk_usage(self.folder).free
        if free < self.min_free_bytes:
            raise DeepMorphError(
                f"{self.folder}: only {free / 2**20:.0f} MiB free on this disk; a training run needs "
                f"{self.min_free_bytes / 2**20:.0f} MiB (free some space, or start the studio with another --data)"
            )
        job_id = time.strftime("%Y%m%d-%H%M%S-") + uuid.uuid4().hex[:6]
        stem = Path(drawing).stem[:40] or "drawing"
        out = self.models / f"{stem}-{job_id}.dmm"
        job = Job(job_id, drawing, svg, str(out), settings)
        with self._lock:
            self._jobs[job_id] = job
            self._save(job)
        self._wake.set()
        return {k: v for k, v in job.to_json().items() if k != "svg"}

    def cancel(self, job_id: str) -> None:
        """Cancel a queued run, or stop a running one (its checkpoint is written first).

        Raises:
            DeepMorphError: no such run, or one that has ended.
        """
        with self._lock:
            job = self._jobs.get(job_id)
            if job is None:
                raise DeepMorphError(f"no training run {job_id}")
            if job.status not in (*ACTIVE, "validating"):
                raise DeepMorphError(f"training run {job_id} has already ended ({job.status})")
            if job.status == "queued":
                job.status, job.message = "cancelled", "cancelled before it started"
                self._save(job)
                return
            process = self._process if self._running == job_id else None
            self._cancelled.add(job_id)
        if process is not None:
            process.terminate()  # SIGTERM: the training loop checkpoints, then the worker says "cancelled"

    def close(self) -> None:
        """Stop a running run (its checkpoint is written) when the studio stops."""
        process = self._process
        if process is not None and process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()

    def _save(self, job: Job) -> None:
        atomic_write(self.folder / f"{job.id}.json", json.dumps(job.to_json()).encode())
        self.version += 1

    def _next(self) -> Job | None:
        with self._lock:
            queued = [j for j in self._jobs.values() if j.status == "queued"]
            return min(queued, key=lambda j: j.created) if queued else None

    def _serve(self) -> None:
        while True:
            job = self._next()
            if job is None:
                self._wake.wait(1.0)
                self._wake.clear()
                continue
            try:
                self._run(job)
            except OSError as exc:  # the worker could not be started (no disk space for its files, say)
                with self._lock:
                    job.status, job.message = "failed", f"the training process could not start: {exc}"
                    self._process, self._running = None, None
                    self._save(job)

    def _run(self, job: Job) -> None:
        svg_path = self.folder / f"{job.id}.svg"
        svg_path.write_text(job.svg)
        spec = self.folder / f"{job.id}.run.json"
        spec.write_text(json.dumps({"svg": str(svg_path), "out": job.out, "settings": job.settings}))
        env = {**os.environ, "OMP_NUM_THREADS": str(job.settings["train"].get("threads") or 1)}
        with self._lock:
            job.status = "running"
            self._save(job)
            self._process = subprocess.Popen(
                [sys.executable, "-m", "deepmorph.studio.worker", str(spec)],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
            )
            self._running = job.id
        process = self._process
        assert process.stdout is not None
        ended = False
        for line in process.stdout:
            try:
                event = json.loads(line)
            except ValueError:
                continue
            with self._lock:
                ended |= self._apply(job, event)
                self._save(job)
        stderr = process.stderr.read() if process.stderr else ""
        code = process.wait()
        with self._lock:
            if not ended and job.id in self._cancelled:
                job.status, job.message = "cancelled", "cancelled before training began"
            elif not ended:
                job.status = "failed"
                last = stderr.strip().splitlines()[-1:] or [f"exit status {code}"]
                job.message = f"the training process stopped: {last[0][:300]}"
            self._process, self._running = None, None
            self._save(job)
        for path in (spec, svg_path):
            path.unlink(missing_ok=True)

    def _apply(self, job: Job, event: dict[str, Any]) -> bool:
        """Update ``job`` with a worker's event; True when the run has ended."""
        kind = event.get("event")
        if kind == "start":
            job.total, job.step = int(event["total"]), int(event["done"])
        elif kind == "log":
            line = event["line"]
            job.step = int(line.get("step", job.step))
            job.total = max(job.total, job.step)  # an auto code cut when training ended trains on past it
            job.elapsed_s = float(line.get("elapsed_s", job.elapsed_s))
            job.metrics = {k: v for k, v in line.items() if k not in ("step", "stage", "elapsed_s")}
            job.metrics["stage"] = line.get("stage", 0)
            if "bit_acc" in line:
                job.history.append([job.step, float(line["bit_acc"])])
                job.history = job.history[-HISTORY_POINTS:]
        elif kind == "warning":
            job.warnings.append(str(event["text"])[:500])
        elif kind == "validating":
            job.status = "validating"
        elif kind == "done":
            job.status, job.message = "finished", validation_words(event.get("validation", []))
            return True
        elif kind in ("error", "cancelled"):
            job.status = "failed" if kind == "error" else "cancelled"
            job.message = event.get("message", "")
            return True
        return False


__all__ = ["MIN_FREE_BYTES", "Job", "JobQueue", "validation_words"]
