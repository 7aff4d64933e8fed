"""How reading depends on the print's size in the photo, in the camera's pixels.

Close-up photos of fresh payloads (``deepmorph_detect.photo_validation.validate_close_ups``)
whose drawing spans about ``--widths`` camera pixels, at ``medium`` and ``hard``: blur, motion
and noise are the camera's, in its pixels, so a print seen small keeps less of its morph. For
each bundle and width: payloads read whole, wrong, prints not found; and the smallest width at
which at least 99 % of medium and 95 % of hard close-ups read (the issue's bars).

    .venv/bin/python bench/print_pixels.py                       # the bundled ghost
    .venv/bin/python bench/print_pixels.py model.dmm --samples 200 --widths 36,52,73,102,158,258,366
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, parse_ints, set_threads, table, write_json  # noqa: E402

BARS = {"medium": 0.99, "hard": 0.95}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", nargs="*", type=Path, help="trained bundles (default: the bundled ghost)")
    ap.add_argument("--widths", type=parse_ints, default=[36, 52, 73, 102, 158, 258, 366])
    ap.add_argument("--samples", type=int, default=100, help="close-ups per width and severity")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "print_pixels.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.photo_validation import validate_close_ups

    rows, results = [], []
    for path in args.bundles or [BUNDLED_MODEL]:
        model = DeepMorphModel.load(path)
        smallest: dict[str, int | None] = {}
        for severity, bar in BARS.items():
            passing = []
            for width in args.widths:
                start = time.perf_counter()
                rec = validate_close_ups(model, args.samples, args.seed, severity, print_px=width)
                seconds = time.perf_counter() - start
                rate = rec.read / rec.samples
                passing.append((width, rate >= bar and rec.wrong == 0))
                rows.append([path.stem, severity, width, f"{100 * rate:.1f}", rec.wrong, rec.missed, f"{seconds:.0f}"])
                results.append({"bundle": str(path), "severity": severity, "print_px": width, **rec.model_dump()})
                print(f"{path.stem} {severity} {width} px: {rec.read}/{rec.samples}", file=sys.stderr, flush=True)
            # the smallest width from which every wider one passes too
            smallest[severity] = next((w for i, (w, _) in enumerate(passing) if all(ok for _, ok in passing[i:])), None)
        results.append({"bundle": str(path), "smallest_print_px": smallest})
        rows.append([path.stem, "smallest passing", f"{smallest['medium']} / {smallest['hard']}", "", "", "", ""])
    print(table(["bundle", "severity", "print px", "read %", "wrong", "not found", "s"], rows))
    write_json(args.out, {"environment": {**environment(), "threads": threads}, "results": results})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
