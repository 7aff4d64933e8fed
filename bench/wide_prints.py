"""Any trained bundles read in photos, counting the prints at least as wide as each model reads.

For models that no panel script trains (a colour drawing trained with ``--pixels``, a user's own
bundle): ``--scenes`` medium and ``--scenes`` hard scenes of ``--frame`` pixels per bundle, read
with the universal detector and scored as ``bench/time_to_print.py`` scores its scenes
(:func:`time_to_print.read_scenes`: one or two prints of fresh payloads, another drawing, an
ArUco marker in every other scene). **Wide** counts only the prints at least the model's
``smallest_print_px`` wide seen head-on, which the issue's targets are about; narrower prints
are refused as too small. **Wrong** counts every print.

    .venv/bin/python bench/wide_prints.py crystal-oscillator.dmm face-without-mouth.dmm --scenes 250 --seed 11
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, frame_size, set_threads, table, write_json  # noqa: E402
from time_to_print import read_scenes, wide_read  # noqa: E402

SEVERITIES = ("medium", "hard")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", type=Path, nargs="+", help="trained bundles (.dmm)")
    ap.add_argument("--scenes", type=int, default=250, help="scenes per bundle and severity")
    ap.add_argument("--frame", type=frame_size, default=(1280, 720), help="the scenes' size, WxH (1280x720)")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "wide_prints.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    results, rows = {}, []
    for bundle in args.bundles:
        reading = read_scenes(bundle, args.scenes, args.seed, args.frame)
        results[bundle.stem] = reading
        wrong = sum(reading[s]["wrong"] for s in SEVERITIES)
        rows.append([bundle.stem, reading["medium"]["wide_px"], *(wide_read(reading[s]) for s in SEVERITIES), wrong])
        print(f"{bundle.stem}: {reading}", file=sys.stderr, flush=True)
    frame = "x".join(map(str, args.frame))
    print(f"\n{args.scenes} scenes of {frame} per severity ({threads} thread(s)), universal detector")
    print(table(["bundle", "reads from px", "medium, wide prints", "hard, wide prints", "wrong (all prints)"], rows))
    write_json(args.out, {"environment": environment(), "threads": threads, "scenes": args.scenes, "seed": args.seed,
                          "frame": list(args.frame), "results": results})  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
