"""``deepmorph capacity --pixels``'s plan for ``train --pixels``, checked by training on a panel
fixed by rule.

**Drawings**, by rule: ``bench/time_to_print.py``'s (the first ``--drawings`` Feather icons,
alphabetically, with 30 to 60 variables at 2 % of the viewBox width, that the universal detector
never saw). The plan's share of the channel was fitted on two of them (``battery-charging`` and
``codepen``, ``bench/README.md``); the rest check it.

**The plan**: :func:`deepmorph_core.capacity.for_print` at ``--pixels`` (a share of the drawing's
channel, :mod:`deepmorph_core.channel`, in BCH codes correcting two errors), trained as a user does with
``--payload-bits auto``: training may make the code smaller, by its batches or by fresh renders
when it ends (:mod:`deepmorph.training.code_shrink`), and the table says where it did. Or, to try
another plan, ``--bits-per-group`` code bits per readable group up to ``--largest-code``, in BCH
codes correcting ``--ecc-t`` errors, trained at that size. For each drawing: a model trained for
prints ``--pixels`` wide and otherwise the default settings (kept in ``--models`` as
``<icon>.dmm`` and reused when there, if it started from the planned code); read back with fresh
payloads from ``--samples`` close-ups at ``medium`` and at ``hard`` whose print spans each of
``--widths`` camera pixels (``deepmorph_detect.photo_validation.validate_close_ups``). A drawing
*passes* when every width reads >= 99 % medium and >= 95 % hard with no wrong payload. Also
reported: the payload over the visible variables (the issue's 0.8 target), and the share of code
words the training batches read over their last ten logs.

**False accepts**: with ``--unrelated N``, each model also locates and reads ``N`` images that show
none of the panel's drawings (``bench/capacity.py``'s set: other Feather icons rendered and
photographed, noise, near-blank paper, clutter; the same images for every model, made
``UNRELATED_CHUNK`` at a time), each enlarged where needed so that its shorter side is
``UNRELATED_SCALE`` times the model's smallest print (a smaller image could only be refused as
too small), and every payload it accepts from them is counted, and the detections refused as too
small.
``--samples 0`` reads no close-ups (false accepts only).

**Photos**: with ``--scenes N``, each model also reads ``N`` medium and ``N`` hard scenes of
``--frame`` pixels (``bench/time_to_print.py``'s: one or two prints, another drawing, an ArUco
marker in every other scene; the universal detector), and the prints at least ``--pixels`` wide
seen head-on (``deepmorph_detect.results.across_px``) are counted: read, and any wrong payload.
Scenes tilt prints as far as their severity allows (45° medium, 60° hard), three times as far as
close-ups.

    .venv/bin/python bench/pixels_panel.py /work/shared/data/drawings/feather --models /tmp/panel
    .venv/bin/python bench/pixels_panel.py ... --models /tmp/panel --only coffee,cpu --out half.json
    .venv/bin/python bench/pixels_panel.py ... --models /tmp/p52 --only cpu --largest-code 52 \
        --bits-per-group 1.3
    .venv/bin/python bench/pixels_panel.py ... --models /tmp/panel --samples 0 --unrelated 5000
    .venv/bin/python bench/pixels_panel.py ... --models /tmp/panel --samples 0 --scenes 60 --frame 1280x720
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, frame_size, parse_ints, set_threads, table, write_json  # noqa: E402
from time_to_print import pick_drawings, read_scenes, wide_read  # noqa: E402

BARS = {"medium": 0.99, "hard": 0.95}
FITTED_ON = ("battery-charging", "codepen")  # the plan was chosen on these two (the rule's first and third)
LAST_LOGS = 10
DRAWINGS = 6  # the panel's size (--drawings)
UNRELATED_CHUNK = 500  # unrelated images made (and held in memory) at a time
UNRELATED_SCALE = 1.5  # an unrelated image's shorter side at least this many times the smallest print


def width_passes(close_ups: dict[str, dict[Any, Any]], width: Any) -> bool:
    """Whether the close-ups of one width (``close_ups[severity][width]``, validation records as
    dicts) read at least each severity's bar in :data:`BARS` with no wrong payload."""
    return all(
        close_ups[s][width]["read"] >= bar * close_ups[s][width]["samples"] and not close_ups[s][width]["wrong"]
        for s, bar in BARS.items()
    )


def batch_read(log: Path) -> float | None:
    """The mean share of code words the training batches read over the last :data:`LAST_LOGS`
    lines of a training log (``None`` without one)."""
    from deepmorph.training.loop import read_log

    reads = [line["read"] for line in read_log(log) if "read" in line][-LAST_LOGS:]
    return statistics.fmean(reads) if reads else None


def planned_code(report: Any, args: argparse.Namespace) -> Any:
    """The code of the largest payload the plan gives the drawing of ``report`` (its
    :func:`~deepmorph_core.capacity.predict`)."""
    from deepmorph_core.capacity import for_print, largest_payload, plan_ecc

    if args.bits_per_group is None:
        return for_print(report, args.pixels).codec
    code_bits = math.floor(args.bits_per_group * report.readable_groups + 1e-9)
    if args.largest_code is not None:
        code_bits = min(code_bits, args.largest_code)
    return largest_payload(code_bits, None, plan_ecc(args.pixels) if args.ecc_t is None else (args.ecc_t,))


def false_accepts(model: Any, n: int, feather: Path, panel: set[str], seed: int) -> dict[str, Any]:
    """Payloads ``model`` accepts from ``n`` images that show none of the ``panel`` drawings (as
    :func:`capacity.unrelated_images` makes them, :data:`UNRELATED_CHUNK` at a time, chunk ``k``
    from ``seed + k``; enlarged to :data:`UNRELATED_SCALE` times ``model.print_px``), by kind of
    image; the detections refused as too small, and the seconds it took."""
    import cv2
    from capacity import unrelated_images

    from deepmorph_detect.locate import Locator

    locator = Locator(model)
    shortest = UNRELATED_SCALE * (model.print_px or 0)
    accepts: dict[str, int] = {}
    read = too_small = 0
    t0 = time.perf_counter()
    for k, start in enumerate(range(0, n, UNRELATED_CHUNK)):
        for kind, img in unrelated_images(min(UNRELATED_CHUNK, n - start), feather, panel, seed + k):
            if min(img.shape[:2]) < shortest:
                scale = shortest / min(img.shape[:2])
                img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
            found = locator.locate(img)
            accepts[kind] = accepts.get(kind, 0) + sum(bool(d.result.ok) for d in found)
            too_small += sum(d.too_small for d in found)
            read += 1
    return {"n": read, "false_accepts": sum(accepts.values()), "by_kind": accepts, "too_small": too_small,
            "seconds": round(time.perf_counter() - t0, 1)}  # fmt: skip


def train(svg: Path, move: float, out: Path, spec: Any, pixels: int, threads: int, auto: bool) -> float:
    """Train ``svg`` for prints ``pixels`` wide on ``threads`` threads, with ``--payload-bits
    auto`` (whose plan is ``spec``) or with the code ``spec``; the seconds it took."""
    from deepmorph.training.codec import train_model

    t0 = time.perf_counter()
    train_model(
        svg,
        out,
        payload_bits="auto" if auto else spec.payload_bits,
        crc_bits=None if auto else spec.crc_bits,
        ecc_t=None if auto else spec.bch_t,
        bounds={"move": move},
        train={"print_px": pixels, "threads": threads},
        overwrite=True,
        validation_samples=(0, 0),
        on_warning=lambda text: print(f"  warning: {text}", file=sys.stderr, flush=True),
    )
    return time.perf_counter() - t0


def started_from(model: Any) -> tuple[int, int]:
    """``(payload bits, code bits)`` a bundle's training started from (before any shrink)."""
    shrunk = model.meta.record.shrunk
    spec = model.codec.spec
    return (shrunk[0].payload_bits[0], shrunk[0].code_bits[0]) if shrunk else (spec.payload_bits, spec.code_bits)


def sizing(model: Any) -> str:
    """How training sized the code: ``-`` (kept) or each shrink, ``40->36 renders``."""
    shrunk = model.meta.record.shrunk
    return ", ".join(f"{s.code_bits[0]}->{s.code_bits[1]} {s.measured_on}" for s in shrunk) or "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("feather", type=Path, help="the Feather icons folder")
    ap.add_argument("--drawings", type=int, default=DRAWINGS)
    ap.add_argument("--pixels", type=int, default=200)
    ap.add_argument("--bits-per-group", type=float, help="another plan: code bits per readable group")
    ap.add_argument("--largest-code", type=int, help="with --bits-per-group: at most this many code bits")
    ap.add_argument("--ecc-t", type=int, help="with --bits-per-group: bit errors the BCH code corrects (2)")
    ap.add_argument("--models", type=Path, required=True, help="where the trained bundles are kept")
    ap.add_argument("--widths", type=parse_ints, default=[240, 330])
    ap.add_argument("--samples", type=int, default=200, help="close-ups per width and severity (0: none)")
    ap.add_argument("--unrelated", type=int, default=0, help="unrelated images each model reads (false accepts)")
    ap.add_argument("--scenes", type=int, default=0, help="medium and hard scenes each model reads (photos)")
    ap.add_argument("--frame", type=frame_size, default=(1280, 720), help="the scenes' size, WxH (1280x720)")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--only", default="", help="comma-separated icons of the panel to run (default: all)")
    ap.add_argument("--out", type=Path, default=RESULTS / "pixels_panel.json")
    args = ap.parse_args()
    threads = set_threads(args.threads)

    from deepmorph_core.capacity import predict
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_detect.photo_validation import validate_close_ups

    args.models.mkdir(parents=True, exist_ok=True)
    rows, results, ratios, scene_rows = [], [], [], []
    only = {name for name in args.only.split(",") if name}
    panel = pick_drawings(args.feather, args.drawings)
    for svg, move, n in panel:
        if only and svg.stem not in only:
            continue
        drawing = MorphableDrawing.load(svg, move=move)
        report = predict(drawing, print_px=None if args.bits_per_group is not None else args.pixels)
        code = planned_code(report, args)
        if code is None:
            raise SystemExit(f"{svg.stem}: no payload fits the plan")
        bundle = args.models / f"{svg.stem}.dmm"
        train_s = None
        if not bundle.is_file():
            print(f"training {svg.stem} ({code.payload_bits} bits) ...", file=sys.stderr, flush=True)
            train_s = train(svg, move, bundle, code, args.pixels, threads, auto=args.bits_per_group is None)
        model = DeepMorphModel.load(bundle)
        if started_from(model) != (code.payload_bits, code.code_bits) or model.print_px != args.pixels:
            raise SystemExit(f"{bundle}: not trained from the planned code ({code}) for {args.pixels}-px prints")
        trained = model.codec.spec
        reads: dict[str, dict[int, Any]] = {s: {} for s in BARS}
        for severity in BARS:
            for width in args.widths if args.samples else ():
                rec = validate_close_ups(model, args.samples, args.seed, severity, print_px=width)
                reads[severity][width] = rec.model_dump()
                print(f"{svg.stem} {severity} {width} px: {rec.read}/{rec.samples}", file=sys.stderr, flush=True)
        passed = all(width_passes(reads, w) for w in args.widths) if args.samples else None
        unrelated = None
        if args.unrelated:
            names = {p.stem for p, _, _ in panel}
            unrelated = false_accepts(model, args.unrelated, args.feather, names, args.seed + 99)
            print(f"{svg.stem} unrelated: {unrelated}", file=sys.stderr, flush=True)
        scenes = read_scenes(bundle, args.scenes, args.seed, args.frame) if args.scenes else None
        if scenes is not None:
            print(f"{svg.stem} scenes: {scenes}", file=sys.stderr, flush=True)
            scene_rows.append([svg.stem, *(wide_read(scenes[s]) for s in BARS), sum(scenes[s]["wrong"] for s in BARS)])
        batches = batch_read(bundle.with_suffix(".log.jsonl"))
        ratio = trained.payload_bits / report.visible
        role = "fitted" if svg.stem in FITTED_ON else "checked"
        if role == "checked":
            ratios.append(ratio)
        wrong = sum(r["wrong"] for by_width in reads.values() for r in by_width.values())
        rows.append(
            [svg.stem, role, n, report.visible, report.readable_groups, f"{code.payload_bits} ({code.code_bits})",
             sizing(model), f"{trained.payload_bits} ({trained.code_bits})", f"{ratio:.2f}",
             *(" / ".join(f"{100 * reads[s][w]['read'] / reads[s][w]['samples']:.1f}" for w in reads[s]) or "-"
               for s in BARS),
             wrong, "-" if unrelated is None else f"{unrelated['false_accepts']} / {unrelated['n']}",
             "-" if batches is None else f"{batches:.2f}", {True: "yes", False: "no", None: "-"}[passed]]
        )  # fmt: skip
        results.append(
            {"drawing": svg.stem, "role": role, "move": move, "variables": n, "visible": report.visible,
             "readable": report.readable_groups, "planned_payload_bits": code.payload_bits,
             "planned_code_bits": code.code_bits, "payload_bits": trained.payload_bits,
             "code_bits": trained.code_bits, "auto": model.meta.record.payload_auto is not None,
             "shrunk": [s.model_dump() for s in model.meta.record.shrunk],
             "predicted_96px": report.payload_bits, "payload_per_visible": ratio, "close_ups": reads,
             "unrelated": unrelated, "scenes": scenes, "batch_read": batches, "passed": passed, "train_s": train_s}
        )  # fmt: skip
    px = "/".join(map(str, args.widths))
    headers = ["drawing", "role", "variables", "visible", "readable", "plan: payload (code bits)", "training cut",
               "payload (code bits)", "payload / visible",
               f"medium % ({px} px)", f"hard % ({px} px)", "wrong", "false accepts", "batch read",
               "passes"]  # fmt: skip
    print(table(headers, rows))
    if scene_rows:
        frame = "x".join(map(str, args.frame))
        print(f"\n{args.scenes} scenes of {frame} per severity: prints at least {args.pixels} px wide seen head-on")
        print(table(["drawing", "medium read", "hard read", "wrong (all prints)"], scene_rows))
    tried = [r["unrelated"] for r in results if r["unrelated"]]
    if tried:
        fa, fa_n = sum(u["false_accepts"] for u in tried), sum(u["n"] for u in tried)
        print(f"false accepts: {fa} in {fa_n} reads of unrelated images ({len(tried)} models)")
    if ratios:
        print(f"checked drawings: payload / visible median {statistics.median(ratios):.2f}, worst {min(ratios):.2f}")
    write_json(
        args.out,
        {"environment": {**environment(), "threads": threads}, "pixels": args.pixels, "samples": args.samples,
         "seed": args.seed, "widths": args.widths, "bits_per_group": args.bits_per_group,
         "largest_code": args.largest_code, "ecc_t": args.ecc_t, "unrelated": args.unrelated,
         "scenes": args.scenes, "frame": list(args.frame),
         "results": results},
    )  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
