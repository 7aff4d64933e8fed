"""Soft-rasterizer fidelity: the unmorphed soft render of each icon against resvg.

For every ``*.svg`` in a folder: parse it (also counting how many parse with and without the
Bézier plugin), soft-render the neutral morph, render the file with resvg at the same width,
and take the mean absolute pixel difference (MAD, ink in [0, 1]).

    .venv/bin/python bench/fidelity.py /work/shared/data/drawings/feather
    .venv/bin/python bench/fidelity.py ../shared/data/drawings/feather --widths 96 --limit 40   # quick
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, parse_ints, set_threads, table, write_json  # noqa: E402


def parse_share(files: list[Path], registry) -> dict:
    """How many files parse with ``registry``, and why the others do not."""
    from deepmorph_core.drawing import load_drawing
    from deepmorph_core.errors import DeepMorphError

    failures = {}
    for path in files:
        try:
            load_drawing(path, registry=registry)
        except DeepMorphError as exc:
            failures[path.name] = str(exc)
    return {"parsed": len(files) - len(failures), "total": len(files), "failures": failures}


def registries() -> dict[str, object]:
    import deepmorph_primitives.plugin as builtin
    from deepmorph_core.plugins import default_registry, load_registry

    out = {"installed (default)": default_registry(), "without bezier": load_registry([builtin], entry_points=False)}
    try:
        import deepmorph_bezier.plugin as bezier
    except ImportError:
        return out
    out["with bezier"] = load_registry([builtin, bezier], entry_points=False)
    return out


def strip(rows: list[tuple[str, object, object]], path: Path) -> None:
    """Save soft | resvg | |difference| for each icon, one icon per row (paper white, ink black)."""
    import numpy as np

    from deepmorph_core.image_io import save_gray

    gap = 3
    lines = []
    for _, soft, ref in rows:
        h, w = soft.shape
        sep = np.full((h, gap), 0.6, dtype=np.float32)
        lines.append(np.concatenate([1 - soft, sep, 1 - ref, sep, 1 - np.abs(soft - ref)], 1))
        lines.append(np.full((gap, 3 * w + 2 * gap), 0.6, dtype=np.float32))
    save_gray(np.concatenate(lines[:-1], 0), path)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("folder", type=Path, help="folder of .svg files (e.g. /work/shared/data/drawings/feather)")
    p.add_argument("--widths", default="96,128,256", help="soft-render widths (default: %(default)s)")
    p.add_argument("--sum-width", type=int, default=96, help='width for the blend="sum" comparison (0: off)')
    p.add_argument("--target", type=float, default=0.03, help="MAD target per icon (default: %(default)s)")
    p.add_argument("--worst", type=int, default=10, help="worst icons listed per width")
    p.add_argument("--strip", type=int, default=5, help="worst icons in each PNG strip (0: none)")
    p.add_argument("--limit", type=int, default=0, help="only the first N files (quick runs)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", default=str(RESULTS / "fidelity.json"))
    args = p.parse_args(argv)

    threads = set_threads(args.threads)
    warnings.filterwarnings("ignore", message="Converting a tensor with requires_grad")
    import numpy as np
    import torch

    from deepmorph_core.drawing import load_drawing
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morph import MorphSpace
    from deepmorph_core.raster import RasterSettings, SoftRasterizer
    from deepmorph_core.render import render_svg_ink

    started = time.perf_counter()
    files = sorted(args.folder.glob("*.svg"))
    if args.limit:
        files = files[: args.limit]
    if not files:
        p.error(f"no .svg files in {args.folder}")
    widths = parse_ints(args.widths)

    parsing = {name: parse_share(files, reg) for name, reg in registries().items()}
    # (label, width, blend) -> {icon: mad}; images kept for the strips
    variants = [(f"union@{w}", w, "union") for w in widths]
    if args.sum_width:
        variants.append((f"sum@{args.sum_width}", args.sum_width, "sum"))
    mads: dict[str, dict[str, float]] = {label: {} for label, _, _ in variants}
    images: dict[str, dict[str, tuple]] = {label: {} for label, _, _ in variants}
    render_failures: dict[str, str] = {}
    references: dict[tuple[str, int], np.ndarray] = {}
    for path in files:
        try:
            drawing = load_drawing(path)
        except DeepMorphError:
            continue  # counted in `parsing`
        text = path.read_text()
        space = MorphSpace(drawing)
        values = space.values_from_unit(space.neutral_unit(1))
        for label, width, blend in variants:
            try:
                ref = references.get((path.name, width))
                if ref is None:
                    ref = references[(path.name, width)] = render_svg_ink(text, width)
                with torch.no_grad():
                    soft = SoftRasterizer(space, RasterSettings(width=width, blend=blend))(values)[0, 0].numpy()
            except DeepMorphError as exc:
                render_failures[f"{path.name}@{label}"] = str(exc)
                continue
            if soft.shape != ref.shape:
                render_failures[f"{path.name}@{label}"] = f"shape {soft.shape} vs resvg {ref.shape}"
                continue
            mads[label][path.name] = float(np.abs(soft - ref).mean())
            images[label][path.name] = (soft, ref)

    summary = {}
    for label, width, blend in variants:
        m = mads[label]
        if not m:
            continue
        vals = np.array(list(m.values()))
        worst = sorted(m.items(), key=lambda kv: -kv[1])
        summary[label] = {
            "width": width,
            "blend": blend,
            "icons": len(m),
            "mean": float(vals.mean()),
            "median": float(np.median(vals)),
            "max": float(vals.max()),
            "over_target": int((vals > args.target).sum()),
            "worst": [{"icon": k, "mad": v} for k, v in worst[: args.worst]],
        }
        if args.strip:
            png = Path(args.out).parent / f"fidelity_worst_{blend}_{width}.png"
            strip([(k, *images[label][k]) for k, _ in worst[: args.strip]], png)
            summary[label]["strip"] = str(png)
    # union vs sum per icon at the comparison width
    union_label, sum_label = f"union@{args.sum_width}", f"sum@{args.sum_width}"
    compare = None
    if args.sum_width and union_label in mads and mads[sum_label]:
        common = sorted(set(mads[union_label]) & set(mads[sum_label]))
        diff = np.array([mads[sum_label][k] - mads[union_label][k] for k in common])
        compare = {
            "width": args.sum_width,
            "icons": len(common),
            "sum_worse": int((diff > 0).sum()),
            "mean_mad_increase_with_sum": float(diff.mean()),
        }

    print("Parsing:")
    print(
        table(
            ["registry", "parsed", "total", "share"],
            [[name, r["parsed"], r["total"], f"{100 * r['parsed'] / r['total']:.1f}%"] for name, r in parsing.items()],
        )
    )
    print(f"\nMean absolute difference to resvg (ink in [0, 1]; target <= {args.target:g} per icon):")
    print(
        table(
            ["variant", "icons", "mean MAD", "median MAD", "max MAD", f"> {args.target:g}"],
            [[k, s["icons"], s["mean"], s["median"], s["max"], s["over_target"]] for k, s in summary.items()],
        )
    )
    if compare:
        print(
            f"\nblend=sum vs union at {compare['width']} px: sum worse on {compare['sum_worse']}/{compare['icons']} "
            f"icons, mean MAD +{compare['mean_mad_increase_with_sum']:.4f}"
        )
    for label, s in summary.items():
        print(f"\nworst {label}: " + ", ".join(f"{w['icon'].removesuffix('.svg')} {w['mad']:.4f}" for w in s["worst"]))
    for name, r in parsing.items():
        if r["failures"]:
            print(f"\nnot parsed ({name}): " + "; ".join(f"{k}: {v}" for k, v in list(r["failures"].items())[:10]))
    if render_failures:
        print("\nrender failures: " + "; ".join(f"{k}: {v}" for k, v in list(render_failures.items())[:10]))

    out = write_json(
        args.out,
        {
            "benchmark": "fidelity",
            "environment": {**environment(), "threads": threads},
            "folder": str(args.folder),
            "target": args.target,
            "parsing": parsing,
            "summary": summary,
            "union_vs_sum": compare,
            "render_failures": render_failures,
            "per_icon": mads,
            "wall_s": time.perf_counter() - started,
        },
    )
    print(f"\nwrote {out} ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
