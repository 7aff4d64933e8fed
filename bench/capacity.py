"""Capacity on a panel of drawings fixed by a rule: how many payload bits each carries at 99 %.

The panel (:func:`panel`), fixed before any tuning: 12 Feather icons picked by their variable
count at the default move (2 % of the viewBox width): for 12 targets evenly spaced from 20 to 100
variables, in order, the icon not yet picked whose count is nearest (ties: alphabetical); plus
the bundled ghost with its own bounds. The Feather set has few icons above 54 variables, so the
upper targets take the nearest there are. The **held-out** icons (``--held-out``), for checking
the prediction on drawings no constant was fitted on: the same rule run again without the panel's
icons (the runner-up at every target; no ghost).

For each drawing: ``deepmorph capacity``'s prediction ``P``; a model trained at ``P`` (4 bits
where ``P`` is 0) with the predicted code and otherwise the default settings (``deepmorph train
--payload-bits auto``), then at ``P + 4`` while that passes or at ``P - 4`` while it fails (at
most three sizes, ``--sizes``); each model read back with fresh payloads:

* **renders**: 1000 resvg renders under the training corruption at ``medium``
  (:func:`deepmorph.training.validation.validate_renders`);
* **close-ups**: 1000 simulated photos of prints filling the frame at ``medium`` through the
  photo chain, and 200 at ``hard`` (:func:`deepmorph_detect.photo_validation.validate_close_ups`);
* **unrelated**: images that are not the drawing (other icons, noise, clutter): false accepts.

A size *passes* when renders and medium close-ups both read >= 99 % and no payload is wrong.
Reported per drawing: variables, visible ones, the prediction, the largest size that passed, its
ratio to the visible variables, and the training time; over the panel, the median and the worst.

    .venv/bin/python bench/capacity.py --feather /work/shared/data/drawings/feather --threads 2
    .venv/bin/python bench/capacity.py --feather ... --reuse      # evaluate kept bundles again
    .venv/bin/python bench/capacity.py --feather ... --only ghost,bold
    .venv/bin/python bench/capacity.py --feather ... --measured earlier.json   # continue a search
    .venv/bin/python bench/capacity.py --feather ... --held-out --only bell-off --sizes 1
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
GHOST = REPO / "deepmorph_core" / "data" / "ghost.svg"
PANEL_SIZE = 12
TARGETS = (20.0, 100.0)
MOVE_SHARE = 0.02
STEP_BITS = 4
PASS_RATE = 0.99


# -- the panel ---------------------------------------------------------------------------------


def panel(feather: Path, held_out: bool = False) -> list[tuple[str, Path, float | None]]:
    """``(name, svg, move)`` of the panel drawings, by the rule in the module docstring; with
    ``held_out``, the held-out icons instead (no ghost)."""
    counts = _variable_counts(feather)
    picked = _pick_by_targets(counts, set())
    if held_out:
        return _pick_by_targets(counts, {name for name, _, _ in picked})
    return [*picked, ("ghost", GHOST, None)]


def _variable_counts(feather: Path) -> dict[str, tuple[int, Path, float]]:
    """``name -> (variables, svg, move)`` of every Feather icon that loads, at the default move."""
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.morphable import MorphableDrawing

    counts: dict[str, tuple[int, Path, float]] = {}
    for path in sorted(feather.glob("*.svg")):
        try:
            probe = MorphableDrawing.load(path, move=1.0)
            move = round(MOVE_SHARE * probe.drawing.viewbox[2], 4)
            counts[path.stem] = (MorphableDrawing.load(path, move=move).n_variables, path, move)
        except DeepMorphError:
            continue
    return counts


def _pick_by_targets(
    counts: dict[str, tuple[int, Path, float]], excluded: set[str]
) -> list[tuple[str, Path, float | None]]:
    """For each target in order, the icon not yet picked nor ``excluded`` nearest in variables."""
    picked: list[tuple[str, Path, float | None]] = []
    lo, hi = TARGETS
    for i in range(PANEL_SIZE):
        target = lo + i * (hi - lo) / (PANEL_SIZE - 1)
        taken = excluded | {name for name, _, _ in picked}
        name = min((n for n in counts if n not in taken), key=lambda n: (abs(counts[n][0] - target), n))
        picked.append((name, counts[name][1], counts[name][2]))
    return picked


def unrelated_images(n: int, feather: Path | None, exclude: set[str], seed: int) -> list[tuple[str, Any]]:
    """``n`` images that show none of the benchmarked drawings, as ``(kind, image)`` pairs.

    With a Feather folder: about 1/3 clean resvg renders of other icons (random size, margin),
    1/6 photo simulations of them; the rest (all of it without icons) noise and near-blank
    textures and procedural clutter (lines, circles, polygons, scribbles; some photographed).
    """
    import cv2
    import numpy as np

    from deepmorph_core.render import render_svg
    from deepmorph_detect.scenes import close_up_photo

    rng = np.random.default_rng(seed)
    out: list[tuple[str, Any]] = []
    icons = sorted(p for p in feather.glob("*.svg") if p.stem not in exclude) if feather else []
    if icons:
        order = rng.permutation(len(icons))
        n_clean, n_photo = n // 3, n // 6
        for j in range(n_clean):
            path = icons[order[j % len(icons)]]
            img = render_svg(path.read_text(), int(rng.integers(64, 401)))
            pad = int(rng.integers(0, img.shape[1] // 4 + 1))
            out.append(("icon", np.pad(img, pad, constant_values=1.0)))
        for j in range(n_photo):
            path = icons[order[(n_clean + j) % len(icons)]]
            out.append(("icon_photo", close_up_photo(render_svg(path.read_text(), 400), "medium", rng)))
    rest = n - len(out)
    n_noise = rest // 3
    for j in range(n_noise):
        size = int(rng.integers(64, 321))
        kind = j % 5
        if kind == 0:  # uniform noise
            img = rng.uniform(0, 1, (size, size))
        elif kind == 1:  # blurred noise: blobs
            img = cv2.GaussianBlur(
                rng.uniform(0, 1, (size, size)).astype(np.float32), (0, 0), float(rng.uniform(2, 10))
            )
        elif kind == 2:  # near-blank paper with a little sensor noise and a light gradient
            yy, xx = np.mgrid[0:size, 0:size] / size
            img = 0.9 + 0.05 * (xx * rng.uniform(-1, 1) + yy * rng.uniform(-1, 1)) + rng.normal(0, 0.02, (size, size))
        elif kind == 3:  # paper with a few faint specks
            img = np.ones((size, size)) - rng.normal(0, 0.01, (size, size))
            for _ in range(int(rng.integers(1, 6))):
                c = tuple(int(v) for v in rng.integers(0, size, 2))
                cv2.circle(img, c, int(rng.integers(1, 4)), float(rng.uniform(0.3, 0.8)), -1)
        else:  # stripes / checks at a random angle and period
            yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
            a, period = rng.uniform(0, np.pi), rng.uniform(4, 30)
            img = 0.5 + 0.5 * np.sign(np.sin((xx * np.cos(a) + yy * np.sin(a)) * 2 * np.pi / period))
            if rng.uniform() < 0.5:
                img = img * (0.5 + 0.5 * np.sign(np.sin((xx * np.sin(a) - yy * np.cos(a)) * 2 * np.pi / period)))
        out.append(("noise", np.clip(img, 0, 1).astype(np.float32)))
    for j in range(n - len(out)):
        size = int(rng.integers(96, 321))
        img = np.ones((size, size), np.float32)
        width = int(rng.integers(1, 5))
        for _ in range(int(rng.integers(2, 15))):
            shade = float(rng.uniform(0, 0.4))
            p = [tuple(int(v) for v in rng.integers(size // 8, size - size // 8, 2)) for _ in range(3)]
            kind = int(rng.integers(0, 5))
            if kind == 0:
                cv2.line(img, p[0], p[1], shade, width, cv2.LINE_AA)
            elif kind == 1:
                cv2.circle(img, p[0], int(rng.integers(3, size // 4)), shade, width, cv2.LINE_AA)
            elif kind == 2:
                cv2.polylines(img, [np.array(p, np.int32)], bool(rng.integers(0, 2)), shade, width, cv2.LINE_AA)
            elif kind == 3:
                cv2.rectangle(img, p[0], p[1], shade, width, cv2.LINE_AA)
            else:  # a scribble: a random walk
                pts = np.cumsum(rng.normal(0, size / 25, (12, 2)), 0) + np.array(p[0])
                cv2.polylines(img, [np.clip(pts, 0, size - 1).astype(np.int32)], False, shade, width, cv2.LINE_AA)
        if j % 3 == 2:
            out.append(("clutter_photo", close_up_photo(img, "medium", rng)))
        else:
            out.append(("clutter", img))
    return out


# -- one drawing -------------------------------------------------------------------------------


def evaluate(model: Any, args: argparse.Namespace, unrelated: list[tuple[str, Any]], seed: int) -> dict[str, Any]:
    """Renders, close-ups (medium and hard) and unrelated images, as in the module docstring."""
    from deepmorph.training.validation import validate_renders
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import validate_close_ups

    out: dict[str, Any] = {}
    out["renders"] = validate_renders(model, args.samples, seed).model_dump()
    out["close_ups"] = validate_close_ups(model, args.photos, seed, "medium").model_dump()
    out["hard_close_ups"] = validate_close_ups(model, args.hard, seed + 1, "hard").model_dump()
    t0 = time.perf_counter()
    locator = Locator(model)
    accepts = sum(bool(d.result.ok) for _, img in unrelated for d in locator.locate(img))
    out["unrelated"] = {"n": len(unrelated), "false_accepts": accepts, "seconds": round(time.perf_counter() - t0, 1)}
    reads = [out[k] for k in ("renders", "close_ups", "hard_close_ups")]
    out["reads"] = sum(r["samples"] for r in reads)
    out["wrong"] = sum(r["wrong"] for r in reads)
    out["passed"] = all(out[k]["read"] >= PASS_RATE * out[k]["samples"] for k in ("renders", "close_ups"))
    out["passed"] = out["passed"] and out["wrong"] == 0
    return out


def train_size(
    name: str, svg: Path, move: float | None, bits: int, code: tuple[int | None, int | None], args: argparse.Namespace
) -> Any:
    """A model of ``svg`` at ``bits`` payload bits with the predicted code ``(crc_bits, bch_t)``
    and otherwise the default settings (kept in ``--models-dir``; reused with ``--reuse`` when
    finished)."""
    from deepmorph.training.codec import train_model
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.model import DeepMorphModel

    path = args.models_dir / f"{name}-p{bits}-seed{args.seed}.dmm"
    if args.reuse and path.is_file():
        try:
            model = DeepMorphModel.load(path)
            if model.meta.record.finished:
                return model, path, False
        except DeepMorphError:
            pass
    print(f"[{name} @ {bits}] training -> {path}", flush=True)
    train_model(
        svg,
        path,
        payload_bits=bits,
        crc_bits=code[0],
        ecc_t=code[1],
        bounds={"move": move},
        train={"seed": args.seed, "threads": args.threads},
        overwrite=True,
        validation_samples=(0, 0),
    )
    return DeepMorphModel.load(path), path, True


def measure_size(
    name: str,
    svg: Path,
    move: float | None,
    bits: int,
    code: tuple[int | None, int | None],
    args: argparse.Namespace,
    unrelated: list,
) -> dict[str, Any]:
    """One size of one drawing: its model (trained or kept) read back as in :func:`evaluate`."""
    model, path, trained = train_size(name, svg, move, bits, code, args)
    rec = model.meta.record
    ev = evaluate(model.eval(), args, unrelated, args.seed + 7919 * bits)
    r, c, h = ev["renders"], ev["close_ups"], ev["hard_close_ups"]
    print(
        f"[{name} @ {bits}] renders {r['read']}/{r['samples']}, close-ups {c['read']}/{c['samples']}, "
        f"hard {h['read']}/{h['samples']}, wrong {ev['wrong']}, false accepts "
        f"{ev['unrelated']['false_accepts']}/{ev['unrelated']['n']}: {'pass' if ev['passed'] else 'fail'}",
        flush=True,
    )
    return {
        "payload_bits": bits,
        "code_bits": model.codec.spec.code_bits,
        "bch_t": model.codec.spec.bch_t,
        "crc_bits": model.codec.spec.crc_bits,
        "bundle": str(path),
        "trained_now": trained,
        "train_s": round(rec.elapsed_s, 1),
        "threads": rec.threads,
        "steps": rec.step,
        **ev,
    }


def run_drawing(name: str, svg: Path, move: float | None, args: argparse.Namespace, unrelated: list) -> dict[str, Any]:
    from deepmorph_core.capacity import predict
    from deepmorph_core.morphable import MorphableDrawing

    t0 = time.perf_counter()
    report = predict(MorphableDrawing.load(svg, move=move))
    predict_s = time.perf_counter() - t0
    start = report.payload_bits or STEP_BITS  # as auto; a drawing predicted nothing is tried at 4
    code = (report.codec.crc_bits, report.codec.bch_t) if report.codec else (None, None)  # as train --payload-bits auto
    sizes: list[dict[str, Any]] = []
    bits, direction = start, 0
    while 1 <= bits and len(sizes) < args.sizes:
        size = args.measured_sizes.get((name, bits))
        if size is None:
            size = measure_size(name, svg, move, bits, code, args, unrelated)
        else:
            print(f"[{name} @ {bits}] measured before: {'pass' if size['passed'] else 'fail'}", flush=True)
        sizes.append(size)
        if direction == 0:
            direction = 1 if size["passed"] else -1
        elif (direction == 1) != size["passed"]:
            break
        bits += direction * STEP_BITS
    passing = [s["payload_bits"] for s in sizes if s["passed"]]
    best = max(passing) if passing else 0
    return {
        "drawing": name,
        "svg": str(svg),
        "move": move,
        "n_variables": report.n_variables,
        "visible": report.visible,
        "readable_groups": report.readable_groups,
        "predicted_code_bits": report.code_bits,
        "predicted_payload_bits": report.payload_bits,
        "predict_s": round(predict_s, 2),
        "largest_passing": best,
        "ratio": best / report.visible if report.visible else 0.0,
        "off_by": best - report.payload_bits,
        "sizes": sizes,
    }


def measured_sizes(paths: list[Path]) -> dict[tuple[str, int], dict[str, Any]]:
    """``(drawing, payload bits) -> size`` from the JSON of earlier runs (later files win).

    Raises:
        SystemExit: a file that cannot be read or is not this benchmark's JSON, naming it.
    """
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for path in paths:
        try:
            for drawing in json.loads(path.read_text())["drawings"]:
                for size in drawing["sizes"]:
                    if not {"passed", "renders", "close_ups"} <= size.keys():
                        raise KeyError("passed, renders or close_ups")
                    out[drawing["drawing"], int(size["payload_bits"])] = size
        except (OSError, ValueError, KeyError, TypeError) as exc:
            why = f"{type(exc).__name__}: {exc}"
            raise SystemExit(f"--measured {path}: not a capacity benchmark result ({why})") from None
    return out


# -- report ------------------------------------------------------------------------------------

HEADERS = ["drawing", "N_v", "visible", "predicted", "largest at 99 %", "ratio", "hard %", "train min",
           "sizes tried: renders / close-ups % (prints not found)"]  # fmt: skip


def _rates(size: dict[str, Any]) -> str:
    """Renders and medium close-ups read, in %, and the close-ups where no print was found."""
    r, c = size["renders"], size["close_ups"]
    missed = c.get("missed")
    return f"{100 * r['read'] / r['samples']:.1f} / {100 * c['read'] / c['samples']:.1f}" + (
        f" ({missed})" if missed else ""
    )


def rows(drawings: list[dict[str, Any]]) -> list[list[Any]]:
    out = []
    for d in drawings:
        best = [s for s in d["sizes"] if s["payload_bits"] == d["largest_passing"]]
        hard = best[0]["hard_close_ups"] if best else None
        tried = ", ".join(f"{s['payload_bits']}: {_rates(s)}" for s in d["sizes"])
        out.append(
            [
                d["drawing"],
                d["n_variables"],
                d["visible"],
                d["predicted_payload_bits"],
                d["largest_passing"],
                round(d["ratio"], 2),
                None if hard is None else round(100 * hard["read"] / hard["samples"], 1),
                round(max(s["train_s"] for s in d["sizes"]) / 60, 1),
                tried,
            ]
        )
    return out


def summary(drawings: list[dict[str, Any]]) -> dict[str, Any]:
    ratios = [d["ratio"] for d in drawings]
    off = [abs(d["off_by"]) for d in drawings]
    wrong = sum(s["wrong"] for d in drawings for s in d["sizes"])
    reads = sum(s["reads"] for d in drawings for s in d["sizes"])
    fa = sum(s["unrelated"]["false_accepts"] for d in drawings for s in d["sizes"])
    fa_n = sum(s["unrelated"]["n"] for d in drawings for s in d["sizes"])
    return {
        "drawings": len(drawings),
        "ratio_median": statistics.median(ratios) if ratios else None,
        "ratio_worst": min(ratios) if ratios else None,
        "prediction_within_4_bits": sum(o <= STEP_BITS for o in off),
        "wrong_payloads": wrong,
        "reads": reads,
        "false_accepts": fa,
        "unrelated_reads": fa_n,
        "train_minutes_max": max((s["train_s"] for d in drawings for s in d["sizes"]), default=0) / 60,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--feather", type=Path, required=True, help="the Feather icon folder")
    ap.add_argument("--models-dir", type=Path, default=RESULTS / "capacity_models")
    ap.add_argument("--reuse", action="store_true", help="evaluate finished bundles in --models-dir again")
    ap.add_argument("--only", help="comma-separated drawing names of the panel to run")
    ap.add_argument("--held-out", action="store_true", help="the held-out icons instead of the panel")
    ap.add_argument("--samples", type=int, default=1000, help="payloads read from renders")
    ap.add_argument("--photos", type=int, default=1000, help="payloads read from medium close-ups")
    ap.add_argument("--hard", type=int, default=200, help="payloads read from hard close-ups")
    ap.add_argument("--unrelated", type=int, default=320, help="unrelated images per model")
    ap.add_argument("--sizes", type=int, default=3, help="the most sizes trained per drawing")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "capacity.json")
    ap.add_argument(
        "--measured", type=Path, nargs="*", default=[],
        help="JSON of earlier runs: sizes measured there are taken as they are (the last file wins) and the "
        "search goes on from them",
    )  # fmt: skip
    args = ap.parse_args()
    args.measured_sizes = measured_sizes(args.measured)
    threads = set_threads(args.threads)
    args.models_dir.mkdir(parents=True, exist_ok=True)
    drawings = panel(args.feather, args.held_out)
    print("held-out icons:" if args.held_out else "panel:", ", ".join(name for name, _, _ in drawings), flush=True)
    if args.only:
        keep = set(args.only.split(","))
        drawings = [d for d in drawings if d[0] in keep]
    names = {name for name, _, _ in drawings}
    unrelated = unrelated_images(args.unrelated, args.feather, names, args.seed + 99)
    done: list[dict[str, Any]] = []
    for name, svg, move in drawings:
        done.append(run_drawing(name, svg, move, args, unrelated))
        write_json(args.out, {"environment": {**environment(), "threads": threads}, "drawings": done,
                              "summary": summary(done)})  # fmt: skip
        print(table(HEADERS, rows(done)), flush=True)
    s = summary(done)
    print(
        f"payload bits / visible variables: median {s['ratio_median']:.2f}, worst {s['ratio_worst']:.2f}; "
        f"prediction within 4 bits on {s['prediction_within_4_bits']}/{s['drawings']}; wrong payloads "
        f"{s['wrong_payloads']} in {s['reads']} reads; false accepts {s['false_accepts']}/{s['unrelated_reads']}"
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
