"""Colour artwork: how much of a colour set loads, how faithfully the soft rasterizer draws it,
and the reading panel fixed by rule.

For each folder of ``*.svg`` (the shared ``flat-color-icons`` and ``fluent-emoji-flat`` sets):

* **coverage**: the share that loads and inspects (with ``--move 0.5``, every installed plugin);
  the others grouped by the first words of their one-line error;
* **fidelity**: the unmorphed soft render in colour (:meth:`SoftRasterizer.render_rgb`) against
  resvg's at the same width, mean absolute difference per channel, on every file that loads;
* **speed**: the soft rasterizer's forward and backward pass on a batch of 32 morphs, on the
  panel's drawings;
* **panel**: the reading panel, by this rule (fixed before any tuning): in each set, the
  drawings that load with at most :data:`PANEL_MAX_VARIABLES` variables and at most 200 shapes,
  sorted by variable count (ties by name); the drawings at 10, 35, 60 and 85 % of that list.

    .venv/bin/python bench/colour.py ../shared/data/drawings/flat-color-icons ../shared/data/drawings/fluent-emoji-flat
    .venv/bin/python bench/colour.py ../shared/data/drawings/flat-color-icons --limit 60      # quick
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

#: Panel drawings carry at most this many variables (what trains in CPU minutes).
PANEL_MAX_VARIABLES = 200
#: Where in each set's sorted list the panel's drawings sit.
PANEL_QUANTILES = (0.10, 0.35, 0.60, 0.85)
MOVE = 0.5


def error_kind(message: str) -> str:
    """The part of a one-line error that names what is unsupported (without file, line or id)."""
    text = message.split(": ", 1)[1] if ": " in message else message
    for cut in ("=", "(", " '", ' "'):
        if cut in text[12:]:
            text = text[: 12 + text[12:].index(cut)]
    return text.strip()


def panel(loaded: list[tuple[str, int, int]]) -> list[str]:
    """The panel's drawings of one set by the module's rule: ``loaded`` is (name, variables, shapes)."""
    eligible = sorted((n_v, name) for name, n_v, shapes in loaded if n_v <= PANEL_MAX_VARIABLES and shapes <= 200)
    if not eligible:
        return []
    return [eligible[min(len(eligible) - 1, int(q * len(eligible)))][1] for q in PANEL_QUANTILES]


def raster_seconds(drawing, width: int, repeats: int = 3) -> float:
    """Median seconds of one soft-raster forward and backward pass over a batch of 32 morphs
    (in colour for a colour drawing)."""
    import statistics

    raster = drawing.rasterizer(width)
    values = drawing.values_from_unit(drawing.random_unit(32, seed=1)).requires_grad_(True)
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        (raster.render_rgb(values) if drawing.colour else raster(values)).sum().backward()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folders", type=Path, nargs="+", help="folders of .svg files")
    p.add_argument("--width", type=int, default=96, help="render width for fidelity (default: %(default)s)")
    p.add_argument("--target", type=float, default=0.03, help="MAD target per drawing and channel")
    p.add_argument("--limit", type=int, default=0, help="only the first N files of each folder (quick runs)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", default=str(RESULTS / "colour.json"))
    args = p.parse_args(argv)

    threads = set_threads(args.threads)
    warnings.filterwarnings("ignore", message="Converting a tensor with requires_grad")
    import numpy as np
    import torch

    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_core.render import render_svg_rgb

    started = time.perf_counter()
    sets = {}
    for folder in args.folders:
        files = sorted(folder.glob("*.svg"))
        if args.limit:
            files = files[: args.limit]
        if not files:
            p.error(f"no .svg files in {folder}")
        failures: dict[str, str] = {}
        mads: dict[str, float] = {}
        loaded: list[tuple[str, int, int]] = []
        for path in files:
            try:
                drawing = MorphableDrawing.load(path, move=MOVE)
                drawing.describe()
            except DeepMorphError as exc:
                failures[path.name] = str(exc)
                continue
            loaded.append((path.name, drawing.n_variables, len(drawing.drawing.primitives)))
            values = drawing.neutral_values()
            with torch.no_grad():
                soft = drawing.rasterizer(args.width).render_rgb(values)[0].permute(1, 2, 0).numpy()
            real = render_svg_rgb(drawing.to_svg(values[0]), args.width)
            mads[path.name] = float(np.abs(soft - real).mean())
        kinds: dict[str, int] = {}
        for message in failures.values():
            kinds[error_kind(message)] = kinds.get(error_kind(message), 0) + 1
        chosen = panel(loaded)
        speeds = {}
        for name in chosen:
            drawing = MorphableDrawing.load(folder / name, move=MOVE)
            speeds[name] = {"variables": drawing.n_variables, "raster_s": raster_seconds(drawing, args.width)}
        vals = np.array(list(mads.values())) if mads else np.zeros(1)
        sets[folder.name] = {
            "files": len(files),
            "loaded": len(loaded),
            "share": len(loaded) / len(files),
            "failures": failures,
            "failure_kinds": dict(sorted(kinds.items(), key=lambda kv: -kv[1])),
            "mad_median": float(np.median(vals)),
            "mad_mean": float(vals.mean()),
            "mad_max": float(vals.max()),
            "over_target": int((vals > args.target).sum()),
            "worst": sorted(mads.items(), key=lambda kv: -kv[1])[:8],
            "panel": speeds,
            "per_drawing": {name: {"variables": n_v, "shapes": s, "mad": mads[name]} for name, n_v, s in loaded},
        }

    print("Coverage (loads and inspects with --move 0.5):")
    print(
        table(
            ["set", "loaded", "files", "share"],
            [[k, s["loaded"], s["files"], f"{100 * s['share']:.1f}%"] for k, s in sets.items()],
        )
    )
    print(f"\nSoft rasterizer against resvg at {args.width} px, mean absolute difference per channel:")
    print(
        table(
            ["set", "drawings", "median", "mean", "worst", f"> {args.target:g}"],
            [[k, s["loaded"], s["mad_median"], s["mad_mean"], s["mad_max"], s["over_target"]] for k, s in sets.items()],
        )
    )
    for k, s in sets.items():
        print(f"\n{k}, refused: " + "; ".join(f"{n} x {why}" for why, n in s["failure_kinds"].items()))
        print(f"{k}, worst fidelity: " + ", ".join(f"{n.removesuffix('.svg')} {m:.4f}" for n, m in s["worst"][:5]))
    print("\nPanel (rule in the module docstring), soft raster of 32 morphs, forward + backward:")
    print(
        table(
            ["set", "drawing", "variables", "seconds"],
            [[k, n, v["variables"], v["raster_s"]] for k, s in sets.items() for n, v in s["panel"].items()],
        )
    )
    out = write_json(
        args.out,
        {
            "benchmark": "colour",
            "environment": {**environment(), "threads": threads},
            "width": args.width,
            "move": MOVE,
            "target": args.target,
            "sets": sets,
            "wall_s": time.perf_counter() - started,
        },
    )
    print(f"\nwrote {out} ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
