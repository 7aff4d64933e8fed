"""How often the photo chain finds colour prints in hard close-ups, before any training: the
universal detector's proposals aligned to the unmorphed drawing, with and without the shifted
sweep of a colour print's ink square (:data:`~deepmorph_detect.refine.SHIFTED_SWEEP_SHIFTS`),
and every way the chain aligns a print it cannot read (the proposals, then the whole photo
framed by its ink: :meth:`Locator.every_alignment
<deepmorph_detect.locate.Locator.every_alignment>`, what ``deepmorph capacity`` simulates), on
the same photos in the same run.

    .venv/bin/python bench/findable.py ../shared/data/drawings/flat-color-icons \\
        ../shared/data/drawings/fluent-emoji-flat --per-set 10 --shots 40

The panel is fixed by rule: in each folder's seeded order (``random.seed(20261207)``,
``random.sample`` of the sorted names), the first ``--per-set`` colour drawings that load at
``--move 0.5`` with 10-80 variables (``--black-and-white``: black-and-white ones). Each is set
up as ``train --move 0.5 --pixels 200`` starts it
(:func:`deepmorph_detect.findable.untrained_model`: finding a print does not depend on its
decoder), and photographed in ``--shots`` hard close-ups, as ``deepmorph capacity`` simulates
them (:mod:`deepmorph_detect.findable`: a print is *found* when one of its alignments has the
drawing's frame within 0.15 of its width of the truth, in any corner order).
"""

from __future__ import annotations

import argparse
import random
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

PANEL_SEED = 20261207
VARIABLES = (10, 80)


def panel(folders: list[Path], per_set: int, colour: bool = True) -> list[Path]:
    """The drawings of the module docstring's rule, ``per_set`` from each folder (``colour``
    false: black-and-white drawings instead)."""
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morphable import MorphableDrawing

    chosen = []
    for folder in folders:
        names = sorted(p.stem for p in folder.glob("*.svg"))
        random.seed(PANEL_SEED)
        taken = 0
        for name in random.sample(names, len(names)):
            if taken == per_set:
                break
            path = folder / f"{name}.svg"
            try:
                drawing = MorphableDrawing.load(path.read_bytes(), move=0.5)
            except DeepMorphError:
                continue
            if drawing.colour == colour and VARIABLES[0] <= drawing.n_variables <= VARIABLES[1]:
                chosen.append(path)
                taken += 1
    return chosen


def measure(path: Path, shots: int) -> dict[str, Any]:
    """One drawing's found prints from proposals with the shifted sweep off and on, and every way
    the chain aligns an unread print (the shifted sweep as the chain sets it: on for colour), and ms
    per shot each way."""
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_detect.camera import project
    from deepmorph_detect.findable import FOUND_WITHIN, SEED, frame_error, untrained_model
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import close_ups

    drawing = MorphableDrawing.load(path.read_bytes(), move=0.5)
    svg_text = drawing.to_svg(drawing.neutral_values()[0])
    model = untrained_model(svg_text, path.name, {"move": 0.5}, None, 200)
    locator = Locator(model, "universal", use_verifier=False)
    ways = {
        "before": (False, locator.alignments),
        "after": (True, locator.alignments),
        "chain": (model.drawing.colour, locator.every_alignment),  # as the chain aligns this drawing
    }
    found = dict.fromkeys(ways, 0)
    seconds = dict.fromkeys(ways, 0.0)
    errors: dict[str, list[float | None]] = {way: [] for way in ways}
    for shot in close_ups(model, shots, SEED, "hard"):
        truth = project(shot.homography, locator.frame_corners)
        for way, (shifted, aligned) in ways.items():
            locator.aligner.shifted_sweep = shifted
            start = time.perf_counter()
            error = frame_error(locator.frame_corners, aligned(shot.photo), truth)
            seconds[way] += time.perf_counter() - start
            errors[way].append(None if error is None else round(error, 4))
            found[way] += error is not None and error < FOUND_WITHIN
    return {"drawing": path.stem, "set": path.parent.name, "variables": model.drawing.n_variables, "shots": shots,
            **{f"found_{way}": found[way] for way in ways},
            **{f"ms_{way}": round(1000 * seconds[way] / shots, 1) for way in ways}, "errors": errors}  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path, help="folders of colour SVG drawings (one set each)")
    ap.add_argument("--per-set", type=int, default=10)
    ap.add_argument("--shots", type=int, default=40, help="hard close-ups per drawing")
    ap.add_argument("--black-and-white", action="store_true", help="the rule's black-and-white drawings instead")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "findable.json")
    args = ap.parse_args(argv)
    set_threads(args.threads)
    start = time.perf_counter()
    rows = []
    for path in panel(args.folders, args.per_set, colour=not args.black_and_white):
        rows.append(measure(path, args.shots))
        r = rows[-1]
        print(
            f"{r['drawing']}: {r['found_before']} -> {r['found_after']}, chain {r['found_chain']} of {r['shots']}",
            flush=True,
        )
    headers = [
        "drawing",
        "set",
        "variables",
        "proposals, centred",
        "proposals",
        "chain",
        "ms centred",
        "ms",
        "ms chain",
    ]
    body = [[r["drawing"], r["set"], r["variables"], r["found_before"], r["found_after"], r["found_chain"],
             r["ms_before"], r["ms_after"], r["ms_chain"]] for r in rows]  # fmt: skip
    print(f"\nHard close-ups of {args.shots} per drawing, prints found: from the detector's proposals with the")
    print("ink square swept centred only, then moved too, and by the chain (proposals, then the whole photo):")
    print(table(headers, body))
    shares = {k: [r[k] / r["shots"] for r in rows] for k in ("found_before", "found_after", "found_chain")}
    summary = {k: {"median": statistics.median(v), "worst": min(v)} for k, v in shares.items() if v}
    for k, v in summary.items():
        print(f"{k}: median {v['median']:.3f}, worst {v['worst']:.3f}")
    wall = round(time.perf_counter() - start, 1)
    write_json(args.out, {"benchmark": "findable", "environment": environment(),
                          "rows": rows, "summary": summary, "wall_s": wall})  # fmt: skip
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
