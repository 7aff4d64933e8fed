"""The universal detector against per-drawing detectors, on the same scenes.

**Drawings**, by rule: the bundled ghost, and every ``NAME-detector.dmm`` in ``--models`` (a
model with a per-drawing detector trained from scratch: ``deepmorph train-detector --from-scratch
--steps 2000 --lr 2e-3``, what ``train-detector`` did before the universal detector). With
``--tuned``, also every ``NAME-tuned.dmm`` there (``train-detector`` at its defaults: a short
fine-tune of the universal detector), located on the same scenes.
None of them was in the universal detector's training set (``held_out`` in
``deepmorph/training/universal.py``; checked here).

For each drawing and severity (medium, hard), ``--n`` scenes (640x480: one or two payload morphs,
one other drawing, an ArUco marker in every other scene) are located twice, once with the
drawing's own detector and once with the universal one, on ``--threads`` (default 1):

* **found**: prints matched by a detection (its centre within a quarter of the diagonal);
* **read**: prints whose payload was read whole and vouched for; **wrong**: payloads vouched
  for that are not the print's;
* **corner error**: mean distance of the reported corners from the truth (pixels);
* **frame time**: median seconds of ``locate`` per scene.

Then ``--negatives`` scenes without any print of a model (other drawings, markers, photos and
clutter; shared out over the drawings) are located with the universal detector: every
detection there is a false one.

    .venv/bin/python bench/universal_detector.py --models bench/results/colour_models --n 200 --negatives 10000

``--bundles`` reads trained bundles (no detector of their own needed) in the same scenes with the
universal detector alone (``--severities``; no negatives): prints read and wrong payloads, what a
user of ``train`` without ``train-detector`` gets. With ``--tuned``, each bundle's ``NAME-tuned.dmm``
beside it (``train-detector`` at its defaults) is located on the same scenes: what the short
fine-tune changes, frame time included.

    .venv/bin/python bench/universal_detector.py --bundles bench/results/colour_models/bar-chart.dmm --n 300
    .venv/bin/python bench/universal_detector.py --bundles models/*.dmm --tuned --n 60  # NAME-tuned.dmm skipped
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


def panel(models: Path | None) -> list[tuple[str, Path]]:
    """``(name, bundle)`` of the drawings, by the rule in the module docstring."""
    from deepmorph_core.bundled import BUNDLED_MODEL

    found = [("ghost", BUNDLED_MODEL)]
    if models is not None:
        found += [(p.name.removesuffix("-detector.dmm"), p) for p in sorted(models.glob("*-detector.dmm"))]
    return found


#: (detector, alignment, matched a print) of every detection in scenes whose payload was not read
UNREAD: list[tuple[str, float, bool]] = []


def score(kind: str, locator: Any, scene: Any) -> tuple[dict[str, int], list[float], float]:
    """Counts, corner errors and the seconds ``locator`` took on one scene."""
    from deepmorph_detect.metrics import SceneTally, corner_error

    drawings = [p for p in scene.placements if p.kind == "drawing"]
    t0 = time.perf_counter()
    dets = locator.locate(scene.image)
    seconds = time.perf_counter() - t0
    tally = SceneTally()
    errors = []
    for det, p, _ in tally.add(dets, drawings):
        if not det.result.ok:
            UNREAD.append((kind, round(float(det.correlation), 4), p is not None))
        if p is not None:
            errors.append(corner_error(det.corners, p.corners))
    counts = {"prints": tally.prints, "found": tally.found, "read": tally.read, "wrong": tally.wrong,
              "false": tally.false, "unread_true": tally.unread}  # fmt: skip
    return counts, errors, seconds


def compare(
    name: str,
    path: Path,
    n: int,
    seed: int,
    tuned: Path | None,
    own: bool = True,
    severities: tuple[str, ...] = ("medium", "hard"),
) -> dict[str, Any]:
    """The detectors on the same scenes of one drawing, per severity (``own``: also the bundle's
    own detector)."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import SceneMaker

    model = DeepMorphModel.load(path)
    locators = {"universal": Locator(model, detector="universal")}
    if own:
        locators = {"own": Locator(model), **locators}
    if tuned is not None and tuned.is_file():
        locators["tuned"] = Locator(DeepMorphModel.load(tuned))
    out: dict[str, Any] = {}
    for sev in severities:
        maker = SceneMaker(model, (640, 480), sev, seed=seed)
        scenes = [maker.make(drawings=1 + i % 2, distractors=1, aruco=i % 2 == 0) for i in range(n)]
        for loc in locators.values():  # first calls allocate and load
            loc.locate(scenes[0].image)
        for kind, loc in locators.items():
            totals = {"prints": 0, "found": 0, "read": 0, "wrong": 0, "false": 0, "unread_true": 0}
            errors: list[float] = []
            times: list[float] = []
            for scene in scenes:
                counts, errs, seconds = score(kind, loc, scene)
                for key, val in counts.items():
                    totals[key] += val
                errors += errs
                times.append(seconds)
            out[f"{sev}/{kind}"] = {
                **totals,
                "found_share": totals["found"] / max(1, totals["prints"]),
                "read_share": totals["read"] / max(1, totals["prints"]),
                "corner_error_px": statistics.mean(errors) if errors else None,
                "corner_error_median_px": statistics.median(errors) if errors else None,
                "frame_s_median": statistics.median(times),
            }
        print(f"{name} {sev}: {n} scenes", flush=True)
    return out


#: the columns of :func:`side_by_side`
SIDE_BY_SIDE = ("found", "read", "wrong", "corner px", "frame ms")


def side_by_side(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """Two detectors' :func:`compare` results on the same scenes as ``a / b`` cells, in the
    order of :data:`SIDE_BY_SIDE`."""
    return [
        f"{a['found_share']:.1%} / {b['found_share']:.1%}",
        f"{a['read_share']:.1%} / {b['read_share']:.1%}",
        f"{a['wrong']} / {b['wrong']}",
        f"{a['corner_error_px'] or 0:.2f} / {b['corner_error_px'] or 0:.2f}",
        f"{a['frame_s_median'] * 1000:.0f} / {b['frame_s_median'] * 1000:.0f}",
    ]


def negatives(paths: list[tuple[str, Path]], total: int, seed: int) -> dict[str, Any]:
    """Scenes without any print of a model, located with the universal detector."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import SceneMaker

    out: dict[str, Any] = {"scenes": 0, "detections": 0, "wrong_ok": 0, "frame_s_median": None, "alignments": []}
    times: list[float] = []
    for k, (name, path) in enumerate(paths):
        model = DeepMorphModel.load(path)
        locator = Locator(model, detector="universal")
        share = total // len(paths) + (k < total % len(paths))
        maker = SceneMaker(model, (640, 480), "medium" if k % 2 == 0 else "hard", seed=seed + 1000 + k)
        for i in range(share):
            scene = maker.make(
                drawings=0, distractors=1 + i % 3, aruco=i % 2 == 0, qr="DEEPMORPH" if i % 5 == 0 else None
            )
            t0 = time.perf_counter()
            dets = locator.locate(scene.image)
            times.append(time.perf_counter() - t0)
            out["scenes"] += 1
            out["detections"] += len(dets)
            out["wrong_ok"] += sum(bool(d.result.ok) for d in dets)
            out["alignments"] += [round(float(d.correlation), 4) for d in dets]
        print(f"negatives of {name}: {share} scenes, {out['detections']} detections so far", flush=True)
    out["frame_s_median"] = statistics.median(times) if times else None
    return out


def universal_alone(
    bundles: list[Path], n: int, seed: int, severities: list[str], threads: int, out: Path, tuned: bool = False
) -> None:
    """``--bundles``: each bundle's prints in :func:`compare`'s scenes, found by the universal
    detector alone (``tuned``: and by the fine-tuned detector of ``NAME-tuned.dmm`` beside it)."""
    rows, tuned_rows, found = [], [], {}
    for path in [b for b in bundles if not (tuned and b.stem.endswith("-tuned"))]:
        fine = path.with_name(f"{path.stem}-tuned.dmm") if tuned else None
        if fine is not None and not fine.is_file():
            raise SystemExit(f"--tuned: no {fine} (deepmorph train-detector {path} --out {fine})")
        res = compare(path.stem, path, n, seed, fine, own=False, severities=tuple(severities))
        found[str(path)] = res
        for sev in severities:
            r = res[f"{sev}/universal"]
            rows.append([path.stem, sev, r["prints"], r["read"], f"{r['read_share']:.1%}", r["wrong"],
                         f"{r['frame_s_median'] * 1000:.0f}"])  # fmt: skip
            if fine is not None:
                t = res[f"{sev}/tuned"]
                tuned_rows.append(
                    [path.stem, sev, *side_by_side(t, r), f"{t['frame_s_median'] / r['frame_s_median']:.2f}"]
                )
    print(f"\nThe universal detector alone, {n} scenes per bundle and severity, {threads} thread(s):")
    print(table(["bundle", "severity", "prints", "read", "share", "wrong", "frame ms"], rows))
    if tuned_rows:
        print("\nFine-tuned (train-detector at its defaults) / universal, the same scenes:")
        print(table(["bundle", "severity", *SIDE_BY_SIDE, "time ratio"], tuned_rows))
    write_json(out, {"benchmark": "universal_detector", "environment": environment(), "threads": threads, "n": n,
                     "seed": seed, "bundles": found})  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, help="folder of NAME-detector.dmm bundles")
    ap.add_argument("--n", type=int, default=200, help="scenes per drawing and severity")
    ap.add_argument("--negatives", type=int, default=10000, help="scenes without a print")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", help="comma-separated drawing names")
    ap.add_argument("--tuned", action="store_true", help="also NAME-tuned.dmm of --models, or beside each of --bundles")
    ap.add_argument("--bundles", type=Path, nargs="+", help="trained bundles read with the universal detector alone")
    ap.add_argument("--severities", default="medium,hard", help="of --bundles' scenes")
    ap.add_argument("--out", type=Path, default=RESULTS / "universal_detector.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)
    if args.bundles:
        universal_alone(args.bundles, args.n, args.seed, args.severities.split(","), threads, args.out, args.tuned)
        return
    from deepmorph.training.universal import held_out
    from deepmorph_detect.universal import UNIVERSAL_PATH, load_universal

    drawings = panel(args.models)
    if args.only:
        drawings = [d for d in drawings if d[0] in args.only.split(",")]
    trained_on = [name for name, _ in drawings if not held_out(name)]
    if trained_on:
        raise SystemExit(f"not held out of the universal detector's training: {trained_on}")
    t0 = time.perf_counter()
    tuned = args.models if args.tuned else None
    per_drawing = {
        name: compare(name, path, args.n, args.seed, tuned / f"{name}-tuned.dmm" if tuned else None)
        for name, path in (drawings if args.n else [])
    }
    neg = negatives(drawings, args.negatives, args.seed) if args.negatives else None
    rows = []
    for name, res in per_drawing.items():
        for sev in ("medium", "hard"):
            own, uni = res[f"{sev}/own"], res[f"{sev}/universal"]
            rows.append([name, sev, *side_by_side(own, uni), f"{uni['frame_s_median'] / own['frame_s_median']:.2f}"])
    print(f"\nOwn detector / universal detector, {args.n} scenes per drawing and severity, {threads} thread(s):")
    print(table(["drawing", "severity", *SIDE_BY_SIDE, "time ratio"], rows))
    tuned_rows = [
        [name, sev, f"{res[f'{sev}/tuned']['found_share']:.1%}", f"{res[f'{sev}/tuned']['read_share']:.1%}",
         res[f"{sev}/tuned"]["wrong"], f"{res[f'{sev}/tuned']['corner_error_px'] or 0:.2f}",
         f"{res[f'{sev}/tuned']['frame_s_median'] * 1000:.0f}"]
        for name, res in per_drawing.items() for sev in ("medium", "hard") if f"{sev}/tuned" in res
    ]  # fmt: skip
    if tuned_rows:
        print("\nThe universal detector fine-tuned (train-detector at its defaults), same scenes:")
        print(table(["drawing", "severity", "found", "read", "wrong", "corner px", "frame ms"], tuned_rows))
    for key in ("found_share", "read_share"):
        for sev in ("medium", "hard"):
            gaps = [res[f"{sev}/universal"][key] - res[f"{sev}/own"][key] for res in per_drawing.values()]
            if gaps:
                what = f"{sev} {key.split('_')[0]}: universal minus own"
                print(f"{what}, median {statistics.median(gaps):+.1%}, worst {min(gaps):+.1%}")
    if neg is not None:
        print(
            f"\nNegatives: {neg['detections']} detections ({neg['wrong_ok']} with a payload) in {neg['scenes']} scenes "
            f"without a print; median frame {neg['frame_s_median'] * 1000:.0f} ms"
        )
    meta = load_universal(UNIVERSAL_PATH)[2]
    write_json(
        args.out,
        {
            "benchmark": "universal_detector",
            "environment": environment(),
            "threads": threads,
            "n": args.n,
            "seed": args.seed,
            "universal": {"record": meta.record.model_dump(), "training_set": meta.training_set},
            "drawings": per_drawing,
            "negatives": neg,
            "unread_in_scenes": UNREAD,
            "wall_s": time.perf_counter() - t0,
        },
    )


if __name__ == "__main__":
    main()
