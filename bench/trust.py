"""The wrong payloads a model's photos could give, as training measures them, and the CRC its rule picks.

For each bundle, ``--samples`` hard close-ups of fresh payloads at the model's trained print width
are read by the photo chain with six of the CRC's bits unchecked (two of CRC-8's checked)
(:func:`deepmorph.training.trust.measure_trust`, as training runs it, 1 thread). Each wrong
payload seen stands for 64 fewer with the whole CRC. The table: the model's payload and CRC, close-ups,
the prints' width, wrong payloads, the rate they imply with the model's CRC (per 10,000 reads; an
upper 95 % bound where none was seen), the CRC the rule would give a ``--payload-bits auto``
model (:func:`deepmorph.training.trust.crc_for`) with the payload that leaves, and what an ``auto``
training gives the same code now: a colour drawing's plan first gives its payload bits to a CRC of
up to 12 (:func:`deepmorph_core.capacity.plan_code`), then the rule lengthens it where the count
needs (:func:`deepmorph.training.trust.crc_needed`). ``--crc W`` counts the same code bits split
into a CRC of W bits and the payload left: a colour training counts its plan's CRC-12 before it
lengthens it. The JSON keeps each record.

    .venv/bin/python bench/trust.py model.dmm other.dmm --samples 1000 --seed 0
    .venv/bin/python bench/trust.py colour.dmm --crc 12 --samples 600 --seed 0
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


def measure(bundle: Path, samples: int, seed: int, workers: int, crc: int | None = None) -> dict[str, Any]:
    """One bundle's row: its code (its code bits split for a CRC of ``crc`` bits where given), the
    record :func:`measure_trust` gives and what the rule picks."""
    from deepmorph.training.trust import TRUST_TARGET, crc_for, crc_needed, measure_trust
    from deepmorph_core.bundle import per_10k
    from deepmorph_core.capacity import default_crc_code, plan_code
    from deepmorph_core.codec import with_crc
    from deepmorph_core.model import DeepMorphModel

    model = DeepMorphModel.load(bundle)
    if crc is not None:
        model.use_code(with_crc(model.codec.spec, crc))
    spec = model.codec.spec
    record = measure_trust(model, samples, seed, workers)
    width = crc_for(record, spec)
    planned = plan_code(default_crc_code(spec), bool(model.drawing.colour))
    now = with_crc(planned, crc_needed(record, planned))
    return {
        "bundle": bundle.stem,
        "colour": model.drawing.colour,
        "code": f"{spec.payload_bits} + CRC-{spec.crc_bits}",
        "samples": record.samples,
        "print_px": record.print_px,
        "wrong": record.wrong,
        "per_10k": ("" if record.wrong else "< ") + per_10k(record.at_most_per_read()),
        "meets": record.wrong_per_read() <= TRUST_TARGET,
        "rule_crc": width,
        "rule_payload": None if width is None else with_crc(spec, width).payload_bits,
        "planned": f"{planned.payload_bits} + CRC-{planned.crc_bits}",
        "now": f"{now.payload_bits} + CRC-{now.crc_bits}",
        "seconds": record.seconds,
        "record": record.model_dump(),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", type=Path, nargs="+")
    ap.add_argument("--samples", type=int, default=600)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="processes reading the close-ups, one thread each")
    ap.add_argument("--crc", type=int, default=None, help="count the same code bits with a CRC this wide")
    ap.add_argument("--out", type=Path, default=RESULTS / "trust.json")
    args = ap.parse_args()
    threads = set_threads(1)
    import cv2

    cv2.setNumThreads(1)
    from pydantic import ValidationError

    from deepmorph_core.codec import format_codec_error

    try:
        rows = [measure(bundle, args.samples, args.seed, args.workers, args.crc) for bundle in args.bundles]
    except ValidationError as exc:  # a --crc the code's bits cannot hold
        ap.error(f"--crc {args.crc}: {format_codec_error(exc)}")
    columns = {"bundle": "bundle", "colour": "colour", "code": "payload + CRC", "samples": "hard close-ups",
               "print_px": "print px", "wrong": "wrong (6 CRC bits unchecked)", "per_10k": "per 10k, its CRC",
               "meets": "at most 0.1", "rule_crc": "CRC the rule picks", "rule_payload": "payload then",
               "planned": "its code, colour CRC", "now": "after the count", "seconds": "s"}  # fmt: skip
    print(f"hard close-ups at each model's trained width, seed {args.seed}, {threads} thread, {args.workers} workers")
    print(table(list(columns.values()), [[row[k] for k in columns] for row in rows]))
    report = {"environment": environment(), "seed": args.seed, "workers": args.workers, "crc": args.crc, "rows": rows}
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
