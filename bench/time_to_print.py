"""Time from a drawing to a print that reads in photos, on this machine's CPU, with no
per-drawing detector step.

**Drawings**, by rule: the first ``--drawings`` (3) Feather icons, alphabetically, with 30 to 60
variables at the capacity panel's move (2 % of the viewBox width) that the universal detector
never saw in training (``held_out`` in ``deepmorph/training/universal.py``). Each is
trained as the README says (``--payload-bits auto``, every other setting at its default, or
``--steps``/``--set KEY=VALUE`` where given) on ``--threads`` (2) threads, with the bundle's
validation (1000 renders, 200 close-ups) and the proposal verifier training ends with (with
``--set print_px=200``: ``train --pixels``) counted in the time, as a user waits for them.

**Reading**: ``--n`` scenes (640x480: one or two prints of fresh payloads, one other drawing, an
ArUco marker in every other scene) at ``medium`` and at ``hard`` are located with the universal
detector, the drawing's own bundle otherwise untouched: **read** is the share of prints whose
payload was read whole and vouched for, **wrong** counts payloads vouched for that are not the
print's. The same share is also given among the prints at least as wide as the model reads
(its ``smallest_print_px``, the decoder's 96-px frame by default: ``decode`` calls a narrower
print it does not read too small). The same scenes (seeded) for every run, so settings compare side by side.

With ``--curve K``, a copy of the checkpoint is kept every ``K`` steps and each copy is read on
the same scenes after training (not counted in the time): how many steps a drawing needs.
``--reread`` reads the bundles a run of the same ``--tag`` left on the same scenes again, without
training, and keeps that run's times: a change to the photo chain, measured on the same models.

    .venv/bin/python bench/time_to_print.py /work/shared/data/drawings/feather --n 100
    .venv/bin/python bench/time_to_print.py ../shared/data/drawings/feather --curve 500 --tag curve
    .venv/bin/python bench/time_to_print.py ../shared/data/drawings/feather --n 80 --tag after --reread
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

MOVE_SHARE = 0.02  # the capacity panel's default move (bench/capacity.py)
VARIABLES = (30, 60)


def pick_drawings(folder: Path, count: int) -> list[tuple[Path, float, int]]:
    """The rule in the module docstring: ``(svg, move, variables)`` of each drawing."""
    from deepmorph.training.universal import held_out
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morphable import MorphableDrawing

    picked = []
    for path in sorted(folder.glob("*.svg")):
        if not held_out(path.stem):
            continue
        try:
            move = round(MOVE_SHARE * MorphableDrawing.load(path, move=1.0).drawing.viewbox[2], 4)
            n = MorphableDrawing.load(path, move=move).n_variables
        except DeepMorphError:
            continue
        if VARIABLES[0] <= n <= VARIABLES[1]:
            picked.append((path, move, n))
        if len(picked) == count:
            return picked
    raise SystemExit(f"only {len(picked)} held-out icons in {folder} have {VARIABLES[0]}-{VARIABLES[1]} variables")


def train(svg: Path, move: float, out: Path, settings: dict[str, Any], curve: int) -> dict[str, Any]:
    """Train and validate one drawing as ``deepmorph train`` does; its times and record."""
    from deepmorph.training.codec import train_model
    from deepmorph.training.settings import DEFAULTS

    keep: list[Path] = []
    phases: dict[str, float] = {}
    logged = {"step": 0}

    def on_start(total: int, done: int) -> Any:
        def on_log(line: dict[str, Any]) -> None:
            logged["step"] = line["step"]
            # the loop checkpoints after it logs: at a multiple of ``curve`` plus one log, the
            # file holds the checkpoint of that multiple
            step = line["step"] - settings.get("log_every", DEFAULTS.log_every)
            if curve and step > 0 and step % curve == 0 and out.is_file():
                copy = out.with_name(f"{out.stem}.step{step:05d}.dmm")
                shutil.copyfile(out, copy)
                keep.append(copy)

        return on_log

    def on_validation() -> None:
        phases["validation_start"] = time.perf_counter()
        # said as it happens: a run cut short in its validation (a time limit) keeps its steps' figures
        print(f"  training ended after {phases['validation_start'] - t0:.0f} s (last logged step "
              f"{logged['step']}); validating", flush=True)  # fmt: skip

    def on_verifier(text: str) -> None:
        if "verifier_start" not in phases:
            phases["verifier_start"] = time.perf_counter()
            took = phases["verifier_start"] - t0
            print(f"  validated after {took:.0f} s; training the proposal verifier", flush=True)

    t0 = time.perf_counter()
    summary = train_model(
        svg,
        out,
        payload_bits="auto",
        bounds={"move": move},
        train={**settings, **({"checkpoint_every": curve} if curve else {})},
        overwrite=True,
        on_start=on_start,
        on_warning=lambda text: print(f"  warning: {text}", flush=True),
        on_validation=on_validation,
        on_verifier=on_verifier,
    )
    end = time.perf_counter()
    total = end - t0
    verifier_s = end - phases.get("verifier_start", end)
    validation_s = phases.get("verifier_start", end) - phases.get("validation_start", end)
    return {
        "total_s": total,
        "steps": summary.steps,
        "stage2_start": summary.stage2_start,
        "steps_s": summary.elapsed_s,
        "step_ms": summary.elapsed_s / max(1, summary.steps) * 1000,
        "validation_s": validation_s,
        "verifier_s": verifier_s,
        "validation": [r.model_dump() for r in summary.validation],
        "curve_files": [str(p) for p in keep],
    }


def trained_code(bundle: Path) -> tuple[int, int]:
    """``(payload bits, code bits)`` of a trained bundle (after any cut its training made)."""
    from deepmorph_core.model import DeepMorphModel

    spec = DeepMorphModel.load(bundle).codec.spec
    return spec.payload_bits, spec.code_bits


def read_scenes(bundle: Path, n: int, seed: int, frame: tuple[int, int] = (640, 480)) -> dict[str, Any]:
    """Prints read (and wrong) in ``n`` medium and ``n`` hard scenes of ``frame`` pixels,
    universal detector, each scored as ``bench/universal_detector.py`` scores its scenes; also
    among the prints at least as wide as the model reads (``smallest_print_px``, seen head-on:
    narrower ones are too small for it)."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.metrics import SceneTally
    from deepmorph_detect.results import across_px
    from deepmorph_detect.scenes import SceneMaker

    model = DeepMorphModel.load(bundle)
    locator = Locator(model, detector="universal")
    out: dict[str, Any] = {}
    for sev in ("medium", "hard"):
        maker = SceneMaker(model, frame, sev, seed=seed)
        tally, wide = SceneTally(), {"prints": 0, "read": 0}
        times = []
        for i in range(n):
            scene = maker.make(drawings=1 + i % 2, distractors=1, aruco=i % 2 == 0)
            drawings = [p for p in scene.placements if p.kind == "drawing"]
            t0 = time.perf_counter()
            dets = locator.locate(scene.image)
            times.append(time.perf_counter() - t0)
            read = {id(p) for det, p, right in tally.add(dets, drawings) if p is not None and det.result.ok and right}
            for p in drawings:
                if across_px(p.homography, locator.frame_corners) >= model.smallest_print_px:
                    wide["prints"] += 1
                    wide["read"] += id(p) in read
        out[sev] = {"prints": tally.prints, "read": tally.read, "wrong": tally.wrong,
                    "read_share": tally.read / max(1, tally.prints), "frame_s_median": statistics.median(times),
                    "wide_px": model.smallest_print_px, "wide_prints": wide["prints"], "wide_read": wide["read"],
                    "wide_read_share": wide["read"] / max(1, wide["prints"])}  # fmt: skip
    return out


def wide_read(read: dict[str, Any]) -> str:
    """``read/prints (percent)`` of the prints at least as wide as the model reads, from
    :func:`read_scenes`'s counts for one severity; ``-`` where there were none."""
    n = read["wide_prints"]
    return f"{read['wide_read']}/{n} ({100 * read['wide_read'] / n:.1f} %)" if n else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("feather", type=Path, help="the Feather icons folder (../shared/data/drawings/feather)")
    ap.add_argument("--drawings", type=int, default=3)
    ap.add_argument("--n", type=int, default=100, help="scenes per drawing and severity")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, help="training steps (default: TrainConfig's)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="another TrainConfig field")
    ap.add_argument("--curve", type=int, default=0, help="read a checkpoint copy every this many steps")
    ap.add_argument("--seed", type=int, default=0, help="scene seed")
    ap.add_argument("--work", type=Path, default=RESULTS / "time_to_print")
    ap.add_argument("--tag", default="default", help="names the bundles folder and the JSON")
    ap.add_argument("--reread", action="store_true", help="read the tag's bundles again, no training")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    settings: dict[str, Any] = {"threads": threads}
    if args.steps:
        settings["steps"] = args.steps
    for item in args.set:
        key, _, value = item.partition("=")
        settings[key] = json.loads(value) if value[:1] in "0123456789-[{tf" else value
    work = args.work / args.tag
    work.mkdir(parents=True, exist_ok=True)
    out = args.work.parent / f"time_to_print_{args.tag}.json"
    earlier: dict[str, Any] = {}
    if args.reread:  # the training's own record stays: its threads, times and steps
        previous = json.loads(out.read_text())
        earlier, settings = previous["drawings"], {**previous["settings"], "reread_threads": threads}
    results: dict[str, Any] = {}
    rows = []
    for svg, move, variables in pick_drawings(args.feather, args.drawings):
        name = svg.stem
        print(f"{name}: {variables} variables, move {move}", flush=True)
        if args.reread:
            run = {**earlier[name], "curve_files": []}
        else:
            run = train(svg, move, work / f"{name}.dmm", settings, args.curve)
        run["variables"] = variables
        run["payload_bits"], run["code_bits"] = trained_code(work / f"{name}.dmm")
        run["reading"] = read_scenes(work / f"{name}.dmm", args.n, args.seed)
        run["curve"] = {Path(p).stem.rsplit(".step", 1)[1]: read_scenes(Path(p), args.n, args.seed)
                        for p in run.pop("curve_files")}  # fmt: skip
        results[name] = run
        med, hard = run["reading"]["medium"], run["reading"]["hard"]
        rows.append([
            name, variables, f"{run['payload_bits']} ({run['code_bits']})", run["steps"], f"{run['step_ms']:.0f}",
            f"{run['steps_s'] / 60:.1f}",
            f"{run['validation_s'] / 60:.1f}", f"{run.get('verifier_s', 0) / 60:.1f}", f"{run['total_s'] / 60:.1f}",
            f"{med['read_share']:.1%}", f"{hard['read_share']:.1%}",
            f"{med['wide_read_share']:.1%}", f"{hard['wide_read_share']:.1%}", med["wrong"] + hard["wrong"],
        ])  # fmt: skip
        for step, reading in run["curve"].items():
            print(f"  step {int(step)}: medium {reading['medium']['read_share']:.1%}, "
                  f"hard {reading['hard']['read_share']:.1%}, wrong "
                  f"{reading['medium']['wrong'] + reading['hard']['wrong']}", flush=True)  # fmt: skip
        write_json(out, {"environment": environment(),
                   "settings": settings, "n": args.n, "drawings": results})  # fmt: skip
    print(f"\nTime to print-ready ({settings['threads']} threads; {args.n} scenes per severity, universal detector):")
    print(table(["drawing", "variables", "payload (code) bits", "steps", "ms/step", "steps min", "validation min",
                 "verifier min", "total min", "medium read", "hard read", "medium, prints it reads",
                 "hard, prints it reads", "wrong"], rows))  # fmt: skip
    totals = [r["total_s"] / 60 for r in results.values()]
    print(f"total minutes: median {statistics.median(totals):.1f}, worst {max(totals):.1f}")


if __name__ == "__main__":
    main()
