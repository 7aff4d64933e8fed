"""Culled vs dense soft rasterizer: forward+backward time and peak memory, side by side.

Per configuration, the peak memory of each setting is measured in a fresh subprocess of its
own, and both settings are then timed in one more, alternating step by step (see
``bench/README.md`` for why); culled and dense see the same drawing and the same inputs, and
their outputs and input gradients are compared.

    .venv/bin/python bench/raster.py                       # full grid
    .venv/bin/python bench/raster.py --widths 64,128 --counts 10,50 --repeats 3   # quick, ~75 s
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import random
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, parse_ints, set_threads, table, write_json  # noqa: E402

TARGET_CONFIG = (128, 50)
TARGET_SPEED, TARGET_MEMORY = 10.0, 5.0


def synthetic_svg(count: int, seed: int = 0) -> bytes:
    """A 24x24 icon-like drawing of ``count`` stroked pieces: short lines, small circles and
    3-point polylines, stroke-width 1-2, round caps, every element ``dm:move="0.5"``."""
    rng = random.Random(seed)
    elements = []
    for i in range(count):
        kind = ("line", "circle", "polyline")[i % 3]
        common = f'stroke-width="{rng.uniform(1, 2):.2f}" dm:move="0.5"'
        if kind == "line":
            x, y = rng.uniform(3, 21), rng.uniform(3, 21)
            length, angle = rng.uniform(2, 6), rng.uniform(0, 2 * math.pi)
            x2, y2 = x + length * math.cos(angle), y + length * math.sin(angle)
            elements.append(f'<line x1="{x:.2f}" y1="{y:.2f}" x2="{x2:.2f}" y2="{y2:.2f}" {common}/>')
        elif kind == "circle":
            r = rng.uniform(1, 3)
            cx, cy = rng.uniform(2 + r, 22 - r), rng.uniform(2 + r, 22 - r)
            elements.append(f'<circle cx="{cx:.2f}" cy="{cy:.2f}" r="{r:.2f}" {common}/>')
        else:
            x, y = rng.uniform(5, 19), rng.uniform(5, 19)
            points = [(x, y)]
            angle = rng.uniform(0, 2 * math.pi)
            for _ in range(2):
                angle += rng.uniform(-2.0, 2.0)
                step = rng.uniform(1.5, 3)
                x, y = x + step * math.cos(angle), y + step * math.sin(angle)
                points.append((x, y))
            pts = " ".join(f"{px:.2f},{py:.2f}" for px, py in points)
            elements.append(f'<polyline points="{pts}" {common}/>')
    return (
        '<svg xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1" viewBox="0 0 24 24" '
        'fill="none" stroke="#000" stroke-linecap="round" stroke-linejoin="round">\n  '
        + "\n  ".join(elements)
        + "\n</svg>\n"
    ).encode()


# -- worker: one (width, count, cull) measurement in a fresh process ---------------------------


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _maxrss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB


def worker(cfg: dict) -> dict:
    """``mode="memory"``: peak of one step of setting ``cull``. ``mode="time"``: the settings in
    ``culls`` timed alternately in this one process, so that both see the same background load."""
    warnings.filterwarnings("ignore", message="Converting a tensor with requires_grad")
    threads = set_threads(cfg["threads"])
    import torch

    from deepmorph_core.drawing import load_drawing
    from deepmorph_core.morph import MorphSpace
    from deepmorph_core.raster import RasterSettings, SoftRasterizer

    drawing = load_drawing(synthetic_svg(cfg["count"], cfg["seed"]), label="synthetic")
    space = MorphSpace(drawing)
    u0 = torch.rand(cfg["batch"], space.n_variables, generator=torch.Generator().manual_seed(cfg["seed"]))

    def step(r: SoftRasterizer, u_init: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        u = u_init.clone().requires_grad_(True)
        ink = r(space.values_from_unit(u))
        ink.mean().backward()
        return ink.detach(), u.grad

    if cfg["mode"] == "time":
        rasters = {c: SoftRasterizer(space, RasterSettings(width=cfg["width"], cull=c)) for c in cfg["culls"]}
        out = {}
        for c, r in rasters.items():  # one warm-up each
            t0 = time.perf_counter()
            step(r, u0)
            out[c] = {"first_ms": (time.perf_counter() - t0) * 1e3, "times_ms": [], "cpu_ms": []}
        for _ in range(cfg["repeats"]):
            for c, r in rasters.items():
                t0, c0 = time.perf_counter(), time.process_time()
                step(r, u0)
                out[c]["times_ms"].append((time.perf_counter() - t0) * 1e3)
                out[c]["cpu_ms"].append((time.process_time() - c0) * 1e3)
        for o in out.values():
            o["median_ms"] = statistics.median(o["times_ms"]) if o["times_ms"] else o["first_ms"]
            o["median_cpu_ms"] = statistics.median(o["cpu_ms"]) if o["cpu_ms"] else None
        return {"threads": threads, "by_cull": {str(c): o for c, o in out.items()}}
    raster = SoftRasterizer(space, RasterSettings(width=cfg["width"], cull=cfg["cull"]))
    out = {"threads": threads, "n_variables": space.n_variables, "pixels": raster.height * raster.width}
    # mode "memory": a tiny warm-up (8 px, batch 2) so that lazy library initialisation falls
    # outside the measured step, then one full step; its peak RSS over the RSS just before it.
    step(SoftRasterizer(space, RasterSettings(width=8, cull=cfg["cull"])), u0[:2])
    gc.collect()
    base_rss, base_max = _rss_mb(), _maxrss_mb()
    ink, grad = step(raster, u0)
    peak_max = _maxrss_mb()
    if cfg.get("save"):
        torch.save({"ink": ink, "grad": grad}, cfg["save"])
    out.update(
        baseline_rss_mb=base_rss,
        peak_mb=peak_max - base_rss,
        peak_reliable=peak_max > base_max,  # else the high-water mark predates the step
    )
    if cfg["cull"]:
        out["box_area_fraction"] = _box_area_fraction(space, raster, u0)
    return out


def _box_area_fraction(space, raster, u0) -> float:
    """Mean share of the canvas inside each primitive's culling box (the rasterizer's rule:
    outline extent over the batch, padded by the half-width and the sigmoid's reach). Since
    multi-piece strokes are now tiled per piece inside that box, it bounds the work from above."""
    import torch

    from deepmorph_core import raster as R
    from deepmorph_core.outline import pixel_bbox

    st, H, W = raster.settings, raster.height, raster.width
    with torch.no_grad():
        frames = space.frames(space.values_from_unit(u0), W)
        areas = []
        for prim, frame in zip(space.drawing.primitives, frames):
            if hasattr(R, "stroke_half_width"):
                half = float(R.stroke_half_width(frame, prim.style.stroke_width, "stroke").max())
            else:
                half = float((frame.scale * prim.style.stroke_width / 2).max())
            box = pixel_bbox(prim.primitive.outline(frame), half + R._SIGMOID_REACH / st.sharpness).tolist()
            w = min(W, math.ceil(box[2]) + 1) - max(0, math.floor(box[0]))
            h = min(H, math.ceil(box[3]) + 1) - max(0, math.floor(box[1]))
            areas.append(max(0, w) * max(0, h) / (H * W))
    return sum(areas) / len(areas)


#: For the memory worker only: a fixed mmap threshold (which also turns off glibc's dynamic
#: one) puts every allocation above 128 KiB in its own mapping, unmapped when freed, so the RSS
#: high-water mark follows the peak of live tensor bytes. With glibc's defaults the same dense
#: step read anywhere from 1980 to 2450 MB over repeated runs (heap reuse); with this, +-1 MB.
MEMORY_ENV = {"MALLOC_MMAP_THRESHOLD_": "131072"}


def run_worker(cfg: dict) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": str(cfg["threads"]), "MKL_NUM_THREADS": str(cfg["threads"])}
    if cfg["mode"] == "memory":
        env.update(MEMORY_ENV)
    proc = subprocess.run(
        [sys.executable, __file__, "--worker", json.dumps(cfg)], capture_output=True, text=True, env=env
    )
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"worker {cfg} failed (rc={proc.returncode}):\n{proc.stderr[-3000:]}")


# -- driver ----------------------------------------------------------------------------------


def _estimate(done: list[dict], width: int, count: int, key: str) -> float | None:
    """Extrapolate a dense cost linearly in pixels x primitives from the largest measured dense
    configuration, preferring one of the same width (per-pixel cost depends on the width)."""
    measured = [r for r in done if r.get("dense") and r["dense"].get(key) is not None]
    same = [r for r in measured if r["width"] == width]
    if not measured:
        return None
    ref = max(same or measured, key=lambda r: r["width"] ** 2 * r["count"])
    return ref["dense"][key] * (width**2 * count) / (ref["width"] ** 2 * ref["count"])


def compare(culled_path: str, dense_path: str) -> dict:
    import torch

    a, b = torch.load(culled_path), torch.load(dense_path)
    grad_scale = float(b["grad"].abs().max())
    return {
        "ink_max_abs_diff": float((a["ink"] - b["ink"]).abs().max()),
        "grad_max_abs_diff": float((a["grad"] - b["grad"]).abs().max()),
        "grad_max_abs": grad_scale,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--widths", default="64,128,256", help="raster widths (default: %(default)s)")
    p.add_argument("--counts", default="10,50,200", help="primitive counts (default: %(default)s)")
    p.add_argument("--repeats", type=int, default=3, help="timed repeats after one warm-up (median)")
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--threads", type=int, default=1, help="torch threads (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-dense-mb", type=float, default=4096, help="skip dense runs estimated above this")
    p.add_argument("--max-dense-s", type=float, default=240, help="skip dense runs estimated to take longer")
    p.add_argument("--out", default=str(RESULTS / "raster.json"))
    p.add_argument("--worker", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker:
        print("RESULT " + json.dumps(worker(json.loads(args.worker))), flush=True)
        return 0

    threads = set_threads(args.threads)
    results: list[dict] = []
    tmp = tempfile.mkdtemp(prefix="dm-bench-")
    started = time.perf_counter()
    for width in parse_ints(args.widths):
        for count in sorted(parse_ints(args.counts)):
            base = dict(
                width=width, count=count, batch=args.batch, threads=args.threads, seed=args.seed, repeats=args.repeats
            )
            row: dict = {"width": width, "count": count}
            culled_file, dense_file = os.path.join(tmp, "culled.pt"), os.path.join(tmp, "dense.pt")
            row["culled"] = run_worker({**base, "mode": "memory", "cull": True, "save": culled_file})
            est_mb = _estimate(results, width, count, "peak_mb")
            est_ms = _estimate(results, width, count, "median_ms")
            est_s = est_ms * (args.repeats + 2) / 1e3 if est_ms is not None else None
            if est_mb is not None and est_mb > args.max_dense_mb:
                row["dense"] = {"skipped": f"estimated peak {est_mb:.0f} MB > --max-dense-mb {args.max_dense_mb:.0f}"}
            elif est_s is not None and est_s > args.max_dense_s:
                row["dense"] = {"skipped": f"estimated {est_s:.0f} s > --max-dense-s {args.max_dense_s:.0f}"}
            else:
                row["dense"] = run_worker({**base, "mode": "memory", "cull": False, "save": dense_file})
                row["agreement"] = compare(culled_file, dense_file)
            culls = [True] if "skipped" in row["dense"] else [True, False]
            timing = run_worker({**base, "mode": "time", "culls": culls})
            row["culled"].update(timing["by_cull"]["True"])
            if "skipped" not in row["dense"]:
                row["dense"].update(timing["by_cull"]["False"])
                row["speed_ratio"] = row["dense"]["median_ms"] / row["culled"]["median_ms"]
                row["speed_ratio_cpu"] = row["dense"]["median_cpu_ms"] / row["culled"]["median_cpu_ms"]
                row["memory_ratio"] = row["dense"]["peak_mb"] / max(row["culled"]["peak_mb"], 1e-9)
            if "skipped" in row["dense"]:
                row["dense"]["estimated_peak_mb"], row["dense"]["estimated_ms"] = est_mb, est_ms
            results.append(row)
            d, c = row["dense"], row["culled"]
            print(
                f"  {width:4d} px {count:4d} prims: culled {c['median_ms']:.0f} ms {c['peak_mb']:.0f} MB | dense "
                + (d["skipped"] if "skipped" in d else f"{d['median_ms']:.0f} ms {d['peak_mb']:.0f} MB"),
                file=sys.stderr,
                flush=True,
            )

    shutil.rmtree(tmp, ignore_errors=True)
    headers = [
        "width",
        "prims",
        "N_v",
        "dense ms",
        "culled ms",
        "speed x",
        "cpu x",
        "dense MB",
        "culled MB",
        "memory x",
        "box area",
        "max|d ink|",
        "max|d grad|",
    ]
    rows = []
    for r in results:
        d, c, agree = r["dense"], r["culled"], r.get("agreement", {})
        dense_ms, dense_mb, speed, memory = (
            d.get("median_ms"),
            d.get("peak_mb"),
            r.get("speed_ratio"),
            r.get("memory_ratio"),
        )
        if "skipped" in d and d.get("estimated_ms") is not None:  # extrapolated, marked with "~"
            dense_ms, dense_mb = f"~{d['estimated_ms']:.0f} (skip)", f"~{d['estimated_peak_mb']:.0f} (skip)"
            speed = f"~{d['estimated_ms'] / c['median_ms']:.1f}"
            memory = f"~{d['estimated_peak_mb'] / c['peak_mb']:.1f}"
        rows.append(
            [
                r["width"],
                r["count"],
                c["n_variables"],
                dense_ms,
                c["median_ms"],
                speed,
                r.get("speed_ratio_cpu"),
                dense_mb,
                c["peak_mb"],
                memory,
                f"{100 * c['box_area_fraction']:.1f}%",
                agree.get("ink_max_abs_diff"),
                agree.get("grad_max_abs_diff"),
            ]
        )
    print(table(headers, rows))
    for r in results:
        if "skipped" in r["dense"]:
            print(f"dense {r['width']} px / {r['count']} prims skipped: {r['dense']['skipped']}")
    target = next((r for r in results if (r["width"], r["count"]) == TARGET_CONFIG and "speed_ratio" in r), None)
    verdict = None
    if target:
        met_speed, met_mem = target["speed_ratio"] >= TARGET_SPEED, target["memory_ratio"] >= TARGET_MEMORY
        verdict = {
            "speed_ratio": target["speed_ratio"],
            "memory_ratio": target["memory_ratio"],
            "speed_met": met_speed,
            "memory_met": met_mem,
        }
        print(
            f"target at {TARGET_CONFIG[0]} px / {TARGET_CONFIG[1]} prims: speed {target['speed_ratio']:.1f}x "
            f"(>= {TARGET_SPEED:g}x: {'met' if met_speed else 'NOT met'}), memory {target['memory_ratio']:.1f}x "
            f"(>= {TARGET_MEMORY:g}x: {'met' if met_mem else 'NOT met'})"
        )
    out = write_json(
        args.out,
        {
            "benchmark": "raster",
            "environment": {**environment(), "threads": threads},
            "settings": {
                "batch": args.batch,
                "repeats": args.repeats,
                "seed": args.seed,
                "timing": "median wall time of forward+backward after one warm-up; culled and dense "
                "steps alternate in one process (cpu_ms: process CPU time of the same steps)",
                "memory": "ru_maxrss after one step minus the RSS just before it, in a fresh process "
                "with MALLOC_MMAP_THRESHOLD_=131072 (timing runs in another, default allocator)",
            },
            "target": {
                "config": list(TARGET_CONFIG),
                "speed": TARGET_SPEED,
                "memory": TARGET_MEMORY,
                "result": verdict,
            },
            "results": results,
            "wall_s": time.perf_counter() - started,
        },
    )
    print(f"wrote {out} ({time.perf_counter() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
