"""Where a codec training step's time goes, at the default settings, on one CPU thread.

The drawing, by rule: the first Feather icon (alphabetically) with 30 to 60 variables at the
capacity panel's default move (2 % of the viewBox width), trained at ``--payload-bits auto``
with :class:`~deepmorph.training.codec.TrainConfig`'s defaults (batch 32, 96 px, medium corruption,
a quarter of each batch drawn by resvg). Steps are timed at the end of the curriculum's ramp
(full ``medium`` corruption), in stage 1 (decoder alone: the morphs carry no gradient) and in
stage 2 (encoder too: the gradient runs back through the corruption and the soft rasterizer).
``--pixels N`` profiles ``train --pixels N`` instead: the capture in the camera's pixels, and each
render registered onto the unmorphed drawing (its own part).

Each part is timed where it runs: forward calls are wrapped; backward is split by gradient
hooks on the decoder's input and on the soft raster's output (the autograd engine runs on
the one thread in order, so the hooks fire between the parts). ``other`` is the step's time not
in any part (bit draws, loss, metrics, the learning-rate schedule).

    .venv/bin/python bench/train_profile.py                       # table + bench/results/train_profile.json
    .venv/bin/python bench/train_profile.py --pixels 200 --out bench/results/train_profile_pixels200.json
    .venv/bin/python bench/train_profile.py --steps 20 --drawing path/to/icon.svg --move 0.48
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

FEATHER = Path(__file__).resolve().parents[2] / "shared" / "data" / "drawings" / "feather"
MOVE_SHARE = 0.02  # the capacity panel's default move (bench/capacity.py)
PARTS = (
    "encoder fwd",
    "soft raster fwd",
    "real renders (resvg)",
    "framing + ink stretch",
    "registration (--pixels)",
    "corruption fwd",
    "decoder fwd",
    "decoder bwd",
    "corruption + framing bwd",
    "soft raster + encoder bwd",
    "optimiser",
    "other",
)


def pick_drawing(folder: Path) -> tuple[Path, float, int]:
    """The rule in the module docstring: ``(svg, move, variables)``."""
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morphable import MorphableDrawing

    for path in sorted(folder.glob("*.svg")):
        try:
            move = round(MOVE_SHARE * MorphableDrawing.load(path, move=1.0).drawing.viewbox[2], 4)
            n = MorphableDrawing.load(path, move=move).n_variables
        except DeepMorphError:
            continue
        if 30 <= n <= 60:
            return path, move, n
    raise SystemExit(f"no Feather icon in {folder} has 30 to 60 variables")


class Timer:
    """Seconds per part, and the marks the backward hooks leave."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.marks: dict[str, float] = {}

    def wrap(self, name: str, fn: Callable[..., Any], hook: str | None = None) -> Callable[..., Any]:
        """``fn`` timed under ``name``; with ``hook``, the time its output's gradient arrives
        is marked as ``hook``."""

        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            out = fn(*args, **kwargs)
            self.seconds[name] += time.perf_counter() - start
            if hook and getattr(out, "requires_grad", False):
                out.register_hook(lambda grad: self._mark(hook))
            return out

        return timed

    def wrap_input_hook(self, fn: Callable[..., Any], hook: str) -> Callable[..., Any]:
        """``fn`` (the decoder) marking when the gradient of its input arrives."""

        def hooked(images: Any, *args: Any, **kwargs: Any) -> Any:
            if images.requires_grad:
                images.register_hook(lambda grad: self._mark(hook))
            return fn(images, *args, **kwargs)

        return hooked

    def _mark(self, name: str) -> None:
        self.marks[name] = time.perf_counter()


def instrument(run: Any, timer: Timer) -> None:
    """Wrap the run's parts (its instance attributes). The framing's time is the model's
    ``framed`` less the registration inside it."""
    model = run.model
    model.encoder.forward = timer.wrap("encoder fwd", model.encoder.forward)
    run.raster.forward = timer.wrap("soft raster fwd", run.raster.forward, hook="raster_out")
    run.raster.render_rgb = timer.wrap("soft raster fwd", run.raster.render_rgb, hook="raster_out")
    model.real_renders = timer.wrap("real renders (resvg)", model.real_renders)
    model.framed = timer.wrap("framing + ink stretch", model.framed)
    if model.registered:
        registration = model.registration(run.device)
        registration.forward = timer.wrap("registration (--pixels)", registration.forward)
    for augment in run._augments.values():
        augment.forward = timer.wrap("corruption fwd", augment.forward)
    decoder_forward = timer.wrap("decoder fwd", model.decoder.forward)
    model.decoder.forward = timer.wrap_input_hook(decoder_forward, "decoder_in")
    for opt in (run.opt_dec, run.opt_enc):
        opt.step = timer.wrap("optimiser", opt.step)


def time_steps(run: Any, timer: Timer, steps: int) -> dict[str, float]:
    """Mean seconds per step of each part over ``steps`` steps (after one warm-up step)."""
    import torch

    original_backward = torch.Tensor.backward
    backward = {"total": 0.0, "decoder": 0.0, "corruption": 0.0, "raster": 0.0}

    def timed_backward(self: torch.Tensor, *args: Any, **kwargs: Any) -> None:
        timer.marks.clear()
        start = time.perf_counter()
        original_backward(self, *args, **kwargs)
        end = time.perf_counter()
        dec = timer.marks.get("decoder_in", end)
        ras = timer.marks.get("raster_out", end)
        backward["total"] += end - start
        backward["decoder"] += dec - start
        backward["corruption"] += ras - dec
        backward["raster"] += end - ras

    run.step()  # warm-up: caches, first allocations
    timer.seconds.clear()
    for key in backward:
        backward[key] = 0.0
    torch.Tensor.backward = timed_backward  # type: ignore[method-assign]
    try:
        start = time.perf_counter()
        for _ in range(steps):
            run.step()
        total = time.perf_counter() - start
    finally:
        torch.Tensor.backward = original_backward  # type: ignore[method-assign]
    parts = dict(timer.seconds)
    parts["framing + ink stretch"] = parts.get("framing + ink stretch", 0.0) - parts.get("registration (--pixels)", 0.0)
    parts["decoder bwd"] = backward["decoder"]
    parts["corruption + framing bwd"] = backward["corruption"]
    parts["soft raster + encoder bwd"] = backward["raster"]
    parts["other"] = total - sum(parts.values())
    out = {name: parts.get(name, 0.0) / steps for name in PARTS}
    out["step"] = total / steps
    return out


def count_operators(run: Any, steps: int) -> dict[str, float]:
    """Mean ATen operator calls per step over ``steps`` steps, forward and backward: ``calls``
    in all and ``views`` among them (metadata only). Eager PyTorch dispatches each from Python
    one at a time, and on a GPU each call that is not a view launches at least one kernel, so
    the count bounds from below what a step pays on the host however fast the device computes.
    (The optimiser's calls are counted as the CPU makes them; on CUDA Adam batches them.)"""
    from torch.utils._python_dispatch import TorchDispatchMode

    counts = {"calls": 0, "views": 0}

    class Count(TorchDispatchMode):
        def __torch_dispatch__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None) -> Any:
            counts["calls"] += 1
            counts["views"] += bool(func.is_view)
            return func(*args, **(kwargs or {}))

    with Count():
        for _ in range(steps):
            run.step()
    return {key: value / max(1, steps) for key, value in counts.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--feather", type=Path, default=FEATHER)
    ap.add_argument("--drawing", type=Path, default=None, help="another drawing than the rule's")
    ap.add_argument("--move", type=float, default=None, help="its move (with --drawing)")
    ap.add_argument("--steps", type=int, default=30, help="steps timed in each stage")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--pixels", type=int, default=None, help="profile train --pixels N")
    ap.add_argument("--op-steps", type=int, default=3, help="steps whose ATen operator calls are counted per stage")
    ap.add_argument("--out", type=Path, default=RESULTS / "train_profile.json")
    args = ap.parse_args(argv)
    threads = set_threads(args.threads)

    import torch

    from deepmorph.training.codec import CodecRun, TrainConfig, open_model

    if args.drawing:
        svg, move = args.drawing, args.move
        n_variables = None
    else:
        svg, move, n_variables = pick_drawing(args.feather)
    defaults = TrainConfig()
    with tempfile.TemporaryDirectory() as tmp:
        model, config, _ = open_model(
            svg,
            Path(tmp) / "m.dmm",
            "auto",
            bounds={"move": move},
            train={"threads": threads, "seed": args.seed, **({"print_px": args.pixels} if args.pixels else {})},
        )
        run = CodecRun(model, config, Path(tmp) / "m.dmm")
        timer = Timer()
        instrument(run, timer)
        ramp_end = int(config.curriculum * config.steps)  # full corruption from here on
        run.record.step = ramp_end
        run.cfg = config.model_copy(update={"stage1_max_fraction": 1.0})  # stays in stage 1 while timed
        stage1 = time_steps(run, timer, args.steps)
        stage1_operators = count_operators(run, args.op_steps)
        run.cfg = config
        run.record.stage, run.record.stage2_start = 2, ramp_end
        stage2 = time_steps(run, timer, args.steps)
        operators = {"stage 1": stage1_operators, "stage 2": count_operators(run, args.op_steps)}
        # the same stage-2 steps with the decoder in the default (NCHW) layout: the step before
        # CodecRun trained it channels-last on the CPU
        layout, run.memory_format = run.memory_format, torch.contiguous_format
        model.decoder.to(memory_format=torch.contiguous_format)
        nchw = time_steps(run, timer, args.steps)
    # a default run: stage 1 for at most stage1_max_fraction of the steps, stage 2 the rest
    s1_share = config.stage1_max_fraction
    run_minutes = config.steps * (s1_share * stage1["step"] + (1 - s1_share) * stage2["step"]) / 60
    rows = [
        (name, 1000 * stage1[name], 100 * stage1[name] / stage1["step"], 1000 * stage2[name],
         100 * stage2[name] / stage2["step"])
        for name in PARTS
    ]  # fmt: skip
    rows.append(("step", 1000 * stage1["step"], 100.0, 1000 * stage2["step"], 100.0))
    print(
        f"{svg.name}: {model.meta.n_variables} variables, {model.codec.spec.payload_bits} payload / "
        f"{model.codec.spec.code_bits} code bits, batch {config.batch}, {config.width} px, "
        f"{config.severity}{f', prints {config.print_px} px' if config.print_px else ''}, real-render share "
        f"{config.hard_fraction}; {threads} thread(s), {args.steps} steps each"
    )
    print(table(("part", "stage 1 ms", "stage 1 %", "stage 2 ms", "stage 2 %"), rows))
    print(
        f"a default run ({config.steps} steps, stage 1 at most {s1_share:.0%}): about {run_minutes:.1f} min of "
        "training steps"
    )
    print(
        "ATen operator calls per step (views among them): "
        + ", ".join(f"{stage} {n['calls']:.0f} ({n['views']:.0f})" for stage, n in operators.items())
    )
    nchw_decoder = 1000 * (nchw["decoder fwd"] + nchw["decoder bwd"])
    print(
        f"decoder layout: stage 2 {1000 * stage2['step']:.0f} ms/step {str(layout).split('.')[-1]}, "
        f"{1000 * nchw['step']:.0f} ms/step NCHW (decoder fwd + bwd {nchw_decoder:.0f} ms); "
        f"{nchw['step'] / stage2['step']:.2f}x"
    )
    write_json(
        args.out,
        {
            "environment": environment(),
            "threads": threads,
            "drawing": svg.name,
            "rule": None if args.drawing else "first Feather icon with 30-60 variables at move 2 % of the viewBox",
            "move": move,
            "n_variables": model.meta.n_variables if n_variables is None else n_variables,
            "payload_bits": model.codec.spec.payload_bits,
            "code_bits": model.codec.spec.code_bits,
            "config": {
                k: getattr(config, k) for k in ("batch", "width", "print_px", "severity", "hard_fraction", "steps")
            },
            "default_config": (defaults.batch, defaults.width, defaults.print_px)
            == (config.batch, config.width, config.print_px),
            "steps_timed": args.steps,
            "stage1_s": stage1,
            "stage2_s": stage2,
            "decoder_layout": str(layout).split(".")[-1],
            "stage2_nchw_decoder_s": nchw,
            "layout_speedup": round(nchw["step"] / stage2["step"], 3),
            "operators_per_step": operators,
            "load_average": os.getloadavg(),
            "default_run_minutes": round(run_minutes, 2),
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
