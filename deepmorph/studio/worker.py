"""One training run of the studio's queue, in its own process: ``python -m deepmorph.studio.worker
JOB.json``. It calls :func:`deepmorph.training.codec.train_model` (the function ``deepmorph train``
calls) and reports on stdout, one JSON object a line: ``start`` (total and done steps), ``log``
(each log line of the training loop), ``validating``, then ``done`` (the bundle and its
validation) or ``error`` / ``cancelled``. SIGTERM cancels: the loop writes its checkpoint first.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def _say(event: str, **data: Any) -> None:
    sys.stdout.write(json.dumps({"event": event, **data}) + "\n")
    sys.stdout.flush()


def run(job_path: Path) -> int:
    """Train the job described in ``job_path``; the exit status is 0 when it finished."""
    from deepmorph.training.codec import train_model
    from deepmorph.training.loop import Interrupted
    from deepmorph_core.errors import DeepMorphError

    job = json.loads(job_path.read_text())
    settings = job["settings"]

    def on_start(total: int, done: int):  # noqa: ANN202 - the loop's per-log callback
        _say("start", total=total, done=done)
        return lambda line: _say("log", line=line)

    try:
        summary = train_model(
            job["svg"],
            job["out"],
            payload_bits=settings["payload_bits"],
            train=settings["train"],
            on_start=on_start,
            on_warning=lambda text: _say("warning", text=text),
            validation_samples=tuple(settings["validation"]),
            on_validation=lambda: _say("validating"),
        )
    except Interrupted as exc:
        _say("cancelled", message=str(exc))
        return 3
    except DeepMorphError as exc:
        _say("error", message=str(exc))
        return 1
    _say("done", bundle=str(summary.bundle), validation=[r.model_dump() for r in summary.validation])
    return 0


def main() -> None:
    sys.exit(run(Path(sys.argv[1])))


if __name__ == "__main__":
    main()
