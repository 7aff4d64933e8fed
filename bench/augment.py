"""Cost of each capture corruption: forward and forward+backward on a batch of drawings,
median of interleaved repeats, with kornia's ``RandomJPEG`` (three channels: it refuses one) as the
baseline for our JPEG.

Each augmentation runs at p=1 with its "medium" preset settings (its defaults where the preset
has none); the presets run as whole pipelines. "fwd" is a forward pass on an input that does
not require grad; "fwd+bwd" is a forward pass on one that does, then ``backward`` of a
weighted sum.

    .venv/bin/python bench/augment.py                  # batch 32, 96x96, 1 thread
    .venv/bin/python bench/augment.py --repeats 5      # quick
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


def drawing(batch: int, size: int):
    """White paper with strokes of several widths and a grey patch (a render stand-in)."""
    import torch

    g = torch.Generator().manual_seed(0)
    images = torch.ones(batch, 1, size, size)
    for i in range(batch):
        for _ in range(6):
            x0, y0 = torch.randint(4, size - 20, (2,), generator=g).tolist()
            w = int(torch.randint(1, 4, (1,), generator=g))
            if i % 2:
                images[i, 0, y0 : y0 + 16, x0 : x0 + w] = 0.0
            else:
                images[i, 0, y0 : y0 + w, x0 : x0 + 16] = 0.0
        images[i, 0, 2:10, 2:10] = 0.5
    return images


def timers(op: Callable, images) -> tuple[Callable[[], None], Callable[[], None]]:
    """The forward and forward+backward calls of ``op(images, generator)`` to time."""
    import torch

    weights = torch.rand(images.shape, generator=torch.Generator().manual_seed(1))

    def forward() -> None:
        op(images, torch.Generator().manual_seed(0))

    def forward_backward() -> None:
        x = images.detach().requires_grad_(True)
        (op(x, torch.Generator().manual_seed(0)) * weights).sum().backward()

    return forward, forward_backward


def elapsed_ms(fn: Callable[[], None]) -> float:
    t0 = time.perf_counter()
    fn()
    return (time.perf_counter() - t0) * 1e3


def measure(calls: list[Callable[[], None]], repeats: int, warmup: int = 3) -> list[list[float]]:
    """Milliseconds of each call, ``repeats`` times. Calls are interleaved round by round, so
    that load from other processes on a shared machine spreads over all of them alike."""
    for _ in range(warmup):
        for fn in calls:
            fn()
    times: list[list[float]] = [[] for _ in calls]
    for _ in range(repeats):
        for fn, record in zip(calls, times):
            record.append(elapsed_ms(fn))
    return times


def cases(batch: int, size: int):
    """``(name, what, op, images)`` for every measured case."""
    import kornia.augmentation

    import deepmorph_augment.plugin as plugin
    from deepmorph_core.corruption import AugmentConfig, AugmentPipeline
    from deepmorph_core.plugins import load_registry

    registry = load_registry([plugin], entry_points=False)
    medium = {s.name: s.params for s in AugmentConfig.preset("medium", size=size).steps}
    gray = drawing(batch, size)
    rgb = gray.expand(-1, 3, -1, -1).contiguous()

    for name, reg in registry.augmentations.items():
        params = medium.get(name, {})
        what = ", ".join(f"{k}={v}" for k, v in params.items()) or "defaults"
        yield name, what, reg.obj(p=1.0, **params), gray
    jpeg = registry.augmentations["jpeg"].obj
    yield "jpeg (cubic)", "rounding=cubic", jpeg(p=1.0, quality=medium["jpeg"]["quality"], rounding="cubic"), gray
    yield "jpeg (3 ch)", "same work as kornia", jpeg(p=1.0, quality=medium["jpeg"]["quality"]), rgb
    kornia_jpeg = kornia.augmentation.RandomJPEG(jpeg_quality=tuple(medium["jpeg"]["quality"]), p=1.0)
    yield "kornia RandomJPEG (3 ch)", "baseline", lambda x, g: kornia_jpeg(x), rgb
    geometry = {
        "steps": [
            s
            for s in AugmentConfig.preset("medium").model_dump()["steps"]
            if s["name"] in ("perspective", "scale", "rotation", "translation")
        ]
    }
    yield "geometry, fused", "4 medium warps as 1", AugmentPipeline(geometry, registry), gray
    for severity in ("easy", "medium", "hard"):
        config = AugmentConfig.preset(severity, size=size)
        yield f"pipeline {severity}", "preset, stated p", AugmentPipeline(config, registry), gray


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--size", type=int, default=96)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, default=RESULTS / "augment.json")
    args = parser.parse_args()
    set_threads(args.threads)

    load_before = os.getloadavg()
    listed = list(cases(args.batch, args.size))
    calls = [fn for _, _, op, images in listed for fn in timers(op, images)]
    times = measure(calls, args.repeats)
    rows, records = [], []
    for i, (name, what, _, _) in enumerate(listed):
        fwd, both = statistics.median(times[2 * i]), statistics.median(times[2 * i + 1])
        rows.append([name, fwd, both, what])
        records.append(
            {
                "name": name,
                "settings": what,
                "forward_ms": fwd,
                "forward_backward_ms": both,
                "forward_min_ms": min(times[2 * i]),
                "forward_backward_min_ms": min(times[2 * i + 1]),
            }
        )
    base = next(r for r in records if r["name"].startswith("kornia"))
    ours = next(r for r in records if r["name"] == "jpeg")
    load = f"load average {load_before[0]:.1f} -> {os.getloadavg()[0]:.1f} on {os.cpu_count()} cpus"
    print(
        f"\nbatch {args.batch}, {args.size}x{args.size}, {args.threads} thread(s), median of {args.repeats}; {load}\n"
    )
    print(table(["augmentation", "fwd ms", "fwd+bwd ms", "settings"], rows))
    speedup = (base["forward_ms"] / ours["forward_ms"], base["forward_backward_ms"] / ours["forward_backward_ms"])
    print(f"\njpeg vs kornia RandomJPEG: {speedup[0]:.0f}x faster forward, {speedup[1]:.0f}x forward+backward")
    path = write_json(
        args.out,
        {
            "environment": environment(),
            "load_average_1min": {"before": load_before[0], "after": os.getloadavg()[0]},
            "batch": args.batch,
            "size": args.size,
            "repeats": args.repeats,
            "results": records,
            "jpeg_speedup_vs_kornia": {"forward": speedup[0], "forward_backward": speedup[1]},
        },
    )
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main()
