"""Capacity: train models for drawings at several payload sizes and measure how well they read back.

Per (drawing, payload size) cell: train a model (or ``--reuse`` a kept bundle), then encode
``--samples`` freshly drawn random payloads and decode them under

* **soft**: the soft rasterizer's renders, framed as in training (``canonicalize`` + ``render_moments``);
* **real**: resvg renders (``DeepMorphModel.real_renders``) of the same morphs, clean, framed the same way;
* **real+aug**: those framed real renders through the differentiable training corruption at ``medium``;
* **r400**: resvg at 400 px decoded through the photo chain (``Locator.locate``, the user's path), clean;
* **photo**: ``close_up_photo(render_at_400px, "medium")`` decoded through the photo chain;

reporting code-bit accuracy (the network's hard decisions against the sent code bits) and
whole-payload success (codec ``ok`` and the payload equal to the one sent). ``ok`` with a wrong
payload is a misdecode and is counted separately. Finally each model decodes the same set of
``--unrelated`` (>= 300) images that are not its drawing -- other Feather icons rendered by resvg
(clean and photo-simulated), noise and near-blank textures, and procedural clutter -- and every
``ok=True`` among them is a false accept.

    .venv/bin/python bench/capacity.py --feather /work/shared/data/drawings/feather \\
        --payload-bits 16,24,32,48 --other-payload-bits 24 --icons camera --steps 1500 \\
        --models-dir bench/results/capacity_models

    # evaluate kept bundles again without training
    .venv/bin/python bench/capacity.py ... --reuse
"""

from __future__ import annotations

import argparse
import hashlib
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, parse_ints, set_threads, table, write_json  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
GHOST = REPO / "deepmorph_core" / "data" / "ghost.svg"
DEFAULT_ICONS = "camera,umbrella,anchor"
TARGET = (
    "24-bit payload recovered whole from >= 99 % of real-renderer images under medium corruption, "
    "trained in <= 10 minutes on 2 CPU cores"
)
CONDITIONS = ("soft", "real", "real_aug", "r400", "photo")


# -- drawings --------------------------------------------------------------------------------------


def has_own_bounds(path: Path) -> bool:
    """Whether the SVG carries any ``dm:`` bounds (then no default bounds are passed)."""
    text = path.read_text()
    return any(f"dm:{k}" in text for k in ("move", "shift", "scale", "rotate"))


def default_move(path: Path, share: float) -> float:
    """``share`` of the drawing's viewBox width (0.02 * 24 = 0.48 for Feather icons)."""
    from deepmorph_core.morphable import MorphableDrawing

    return round(share * MorphableDrawing.load(path, move=1.0).drawing.viewbox[2], 4)


def plan_cells(args: argparse.Namespace) -> list[dict[str, Any]]:
    drawings = [Path(p) for p in args.drawings] if args.drawings else [GHOST]
    if not args.drawings and args.feather:
        drawings += [Path(args.feather) / f"{name.strip()}.svg" for name in args.icons.split(",") if name.strip()]
    bits_first = parse_ints(args.payload_bits)
    bits_other = parse_ints(args.other_payload_bits) if args.other_payload_bits else bits_first
    cells = []
    for i, path in enumerate(drawings):
        if not path.is_file():
            raise SystemExit(f"capacity: {path}: no such drawing")
        own = has_own_bounds(path)
        move = None if own else (args.move if args.move is not None else default_move(path, args.move_share))
        for rank, bits in enumerate(bits_first if i == 0 else bits_other):
            cells.append({"drawing": path, "payload_bits": bits, "move": move, "own_bounds": own, "order": (rank, i)})
    # run order: every drawing's first payload size, then every drawing's second, ... (so a run cut
    # short has covered each drawing); the table is sorted by drawing and payload size
    return sorted(cells, key=lambda c: c["order"])


# -- unrelated images ------------------------------------------------------------------------------


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


# -- evaluation ------------------------------------------------------------------------------------


def _score(results: list[Any], probs: Any, code: Any, payloads: Any) -> dict[str, Any]:
    """Bit accuracy over the images where a drawing was found; success/misdecodes over all."""
    import numpy as np

    n = len(results)
    found = [i for i, r in enumerate(results) if r is not None]
    bit_acc = float(((probs[found] > 0.5) == (code[found] > 0.5)).mean()) if found else float("nan")
    ok = [r is not None and r.ok and np.array_equal(r.payload, payloads[i]) for i, r in enumerate(results)]
    wrong = [r is not None and r.ok and not np.array_equal(r.payload, payloads[i]) for i, r in enumerate(results)]
    return {
        "n": n,
        "found": len(found),
        "bit_acc": bit_acc,
        "success": int(sum(ok)),
        "success_rate": sum(ok) / n,
        "misdecoded_ok": int(sum(wrong)),
    }


def evaluate(model: Any, samples: int, seed: int, unrelated: list[tuple[str, Any]]) -> dict[str, Any]:
    import numpy as np
    import torch

    from deepmorph_core.corruption import build_pipeline
    from deepmorph_core.framing import canonicalize, render_moments
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import close_up_photo

    model.eval()
    locator = Locator(model)
    codec = model.codec
    rng = np.random.default_rng(seed)
    payloads = random_payloads(samples, codec.spec.payload_bits, rng)
    code = codec.encode(payloads).astype(np.float32)
    values = model.morph_values(torch.from_numpy(code))
    target, size = model.canonical_moments(), model.image_size

    def framed(images: torch.Tensor) -> torch.Tensor:
        return canonicalize(images, render_moments(images), target, size)

    def net(images: torch.Tensor) -> Any:
        return model.probabilities(images).numpy().astype(np.float64)

    out: dict[str, Any] = {}
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    with torch.no_grad():
        soft = framed(1.0 - model.rasterizer()(values))
    p = net(soft)
    out["soft"] = _score(codec.decode_batch(p), p, code, payloads)
    timings["soft"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    real = framed(model.real_renders(values))
    p = net(real)
    out["real"] = _score(codec.decode_batch(p), p, code, payloads)
    timings["real"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    augment = build_pipeline("medium", model.width)
    gen = torch.Generator().manual_seed(seed + 1)
    with torch.no_grad():
        p = net(augment(real, generator=gen))
    out["real_aug"] = _score(codec.decode_batch(p), p, code, payloads)
    timings["real_aug"] = time.perf_counter() - t0

    # the user's path: a larger render (clean, then print-and-photo) through the photo chain
    photo_rng = np.random.default_rng(seed + 2)
    res400, p400, res_photo, p_photo = [], [], [], []
    t0 = time.perf_counter()
    t_photo = 0.0
    for i in range(samples):
        render = render_svg(model.drawing.to_svg(values[i]), 400)
        for img, results, probs in ((render, res400, p400), (None, res_photo, p_photo)):
            t1 = time.perf_counter()
            if img is None:
                img = close_up_photo(render, "medium", photo_rng)
            dets = locator.locate(img)
            results.append(dets[0].result if dets else None)
            probs.append(dets[0].probabilities if dets else np.full(codec.spec.code_bits, 0.5))
            if results is res_photo:
                t_photo += time.perf_counter() - t1
    out["r400"] = _score(res400, np.array(p400), code, payloads)
    out["photo"] = _score(res_photo, np.array(p_photo), code, payloads)
    timings["r400+photo"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    fa: dict[str, dict[str, int]] = {}
    for kind, img in unrelated:
        dets = locator.locate(img)
        d = fa.setdefault(kind, {"n": 0, "found": 0, "ok": 0})
        d["n"] += 1
        d["found"] += bool(dets)
        d["ok"] += sum(bool(det.result.ok) for det in dets)
    total = sum(d["n"] for d in fa.values())
    accepts = sum(d["ok"] for d in fa.values())
    out["unrelated"] = {
        "n": total,
        "found": sum(d["found"] for d in fa.values()),
        "false_accepts": accepts,
        "rate": accepts / max(total, 1),
        "by_kind": fa,
    }
    timings["unrelated"] = time.perf_counter() - t0
    out["eval_s"] = {k: round(v, 2) for k, v in timings.items()}
    return out


# -- one cell --------------------------------------------------------------------------------------


def bundle_path(models_dir: Path, cell: dict[str, Any], args: argparse.Namespace) -> Path:
    stem = cell["drawing"].stem
    extra = ("" if args.width == 96 else f"-w{args.width}") + ("" if args.spatial_transformer else "-nost")
    return models_dir / f"{stem}-p{cell['payload_bits']}-s{args.steps}-b{args.batch}{extra}-seed{args.seed}.dmm"


def run_cell(cell: dict[str, Any], args: argparse.Namespace, unrelated: list, models_dir: Path) -> dict[str, Any]:
    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.train import train_model

    path = bundle_path(models_dir, cell, args)
    label = f"{cell['drawing'].name} @ {cell['payload_bits']} bits"
    reused = False
    wall = None
    if args.reuse and path.is_file():
        try:
            model = DeepMorphModel.load(path)
        except DeepMorphError as exc:
            print(f"[{label}] cannot reuse {path} ({exc}): training again", flush=True)
            model = None
        if model is None:
            pass
        elif model.meta.drawing_svg != cell["drawing"].read_text():
            print(f"[{label}] {path} was trained on another version of the drawing: training again", flush=True)
        elif not model.meta.record.finished:
            print(f"[{label}] {path} is an unfinished checkpoint: training again", flush=True)
        elif model.meta.decoder.spatial_transformer != args.spatial_transformer or model.width != args.width:
            print(f"[{label}] {path} has another decoder (transformer or width): training again", flush=True)
        else:
            reused = True
    if not reused:
        bounds = {"move": cell["move"]} if cell["move"] is not None else None
        train = {
            "steps": args.steps,
            "batch": args.batch,
            "seed": args.seed,
            "threads": args.threads,
            "width": args.width,
            "spatial_transformer": args.spatial_transformer,
        }
        print(f"[{label}] training {args.steps} steps -> {path}", flush=True)
        t0 = time.perf_counter()
        train_model(
            cell["drawing"],
            path,
            payload_bits=cell["payload_bits"],
            crc_bits=args.crc_bits,
            ecc_t=args.ecc_t,
            bounds=bounds,
            train=train,
            overwrite=True,
        )
        wall = time.perf_counter() - t0
        model = DeepMorphModel.load(path)
    rec = model.meta.record
    spec = model.codec.spec
    print(
        f"[{label}] {'reused' if reused else 'trained'}: N_b={spec.code_bits} N_v={model.meta.n_variables} "
        f"train {rec.elapsed_s:.0f} s on {rec.threads} thread(s), stage 2 from step {rec.stage2_start}, "
        f"last training batches bit acc {rec.metrics.get('bit_acc', float('nan')):.3f}; evaluating ...",
        flush=True,
    )
    t0 = time.perf_counter()
    ev = evaluate(model, args.samples, args.seed + 1000 * cell["payload_bits"], unrelated)
    result = {
        "drawing": cell["drawing"].name,
        "drawing_path": str(cell["drawing"]),
        "drawing_sha256": hashlib.sha256(model.meta.drawing_svg.encode()).hexdigest()[:16],
        "bounds": "own dm: bounds" if cell["own_bounds"] else {"move": cell["move"]},
        "payload_bits": spec.payload_bits,
        "crc_bits": spec.crc_bits,
        "bch_t": spec.bch_t,
        "code_bits": spec.code_bits,
        "n_variables": model.meta.n_variables,
        "image_size": list(model.image_size),
        "bundle": str(path),
        "reused": reused,
        "train": {
            "steps": rec.step,
            "stage2_start": rec.stage2_start,
            "elapsed_s": rec.elapsed_s,
            "wall_s": wall,
            "threads": rec.threads,
            "final_batch_metrics": rec.metrics,
            "config": model.meta.train,
        },
        "samples": args.samples,
        **ev,
        "eval_wall_s": time.perf_counter() - t0,
    }
    rates = ", ".join(f"{cond} {pct(ev[cond]['success_rate'])}" for cond in CONDITIONS)
    u = ev["unrelated"]
    print(
        f"[{label}] whole-payload success %: {rates}; false accepts {u['false_accepts']}/{u['n']} "
        f"(eval {result['eval_wall_s']:.0f} s)",
        flush=True,
    )
    return result


def pct(x: float) -> str:
    return "-" if x != x else f"{100 * x:.1f}"


def summary_rows(cells: list[dict[str, Any]]) -> list[list[Any]]:
    rows = []
    first_seen = {c["drawing"]: i for i, c in reversed(list(enumerate(cells)))}
    for c in sorted(cells, key=lambda c: (first_seen[c["drawing"]], c["payload_bits"])):
        row = [
            c["drawing"],
            c["payload_bits"],
            c["code_bits"],
            c["n_variables"],
            round(c["train"]["elapsed_s"]),
            c["train"]["threads"],
        ]
        for cond in CONDITIONS:
            s = c[cond]
            row.append(f"{pct(s['bit_acc'])} / {pct(s['success_rate'])}")
        u = c["unrelated"]
        row.append(f"{u['false_accepts']}/{u['n']}")
        rows.append(row)
    return rows


HEADERS = [
    "drawing",
    "P",
    "N_b",
    "N_v",
    "train s",
    "thr",
    "soft bit/ok %",
    "real bit/ok %",
    "real+aug bit/ok %",
    "r400 bit/ok %",
    "photo bit/ok %",
    "false acc.",
]


def main() -> None:
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--drawings", nargs="+", help="SVG files (default: the bundled ghost, plus --icons from --feather)")
    ap.add_argument("--feather", type=Path, help="Feather icon folder: benchmark icons and unrelated images")
    ap.add_argument("--icons", default=DEFAULT_ICONS, help=f"icons of --feather to train on (default {DEFAULT_ICONS})")
    ap.add_argument("--payload-bits", default="16,24,32,48", help="payload sizes (for every drawing)")
    ap.add_argument("--other-payload-bits", help="payload sizes for drawings after the first (default: --payload-bits)")
    ap.add_argument("--crc-bits", type=int, help="CRC width (default: the codec's choice)")
    ap.add_argument("--ecc-t", type=int, help="BCH t (default: the codec's choice)")
    ap.add_argument("--move", type=float, help="default move bound for drawings without dm: bounds")
    ap.add_argument("--move-share", type=float, default=0.02, help="default --move as a share of the viewBox width")
    ap.add_argument("--steps", type=int, default=1500)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--width", type=int, default=96, help="decoder image width in pixels")
    ap.add_argument(
        "--no-spatial-transformer",
        dest="spatial_transformer",
        action="store_false",
        help="train decoders without the spatial transformer (as before 2026-11-22)",
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--samples", type=int, default=200, help="random payloads per cell")
    ap.add_argument("--unrelated", type=int, default=320, help="unrelated images per model (>= 300 asked)")
    ap.add_argument("--models-dir", type=Path, default=RESULTS / "capacity_models", help="where bundles are kept")
    ap.add_argument("--reuse", action="store_true", help="evaluate kept bundles instead of training them again")
    ap.add_argument("--out", type=Path, default=RESULTS / "capacity.json")
    ap.add_argument("--show", type=Path, help="only print the table of a saved JSON report")
    args = ap.parse_args()
    if args.show:
        print_saved(args.show)
        return

    threads = set_threads(args.threads)
    import warnings

    warnings.filterwarnings("ignore", message="Converting a tensor with requires_grad")
    cells = plan_cells(args)
    args.models_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    exclude = {c["drawing"].stem for c in cells}
    unrelated = unrelated_images(args.unrelated, args.feather, exclude, args.seed + 7)
    kinds: dict[str, int] = {}
    for kind, _ in unrelated:
        kinds[kind] = kinds.get(kind, 0) + 1
    print(
        f"{len(cells)} cells, {threads} torch thread(s); {len(unrelated)} unrelated images "
        f"({', '.join(f'{k} {v}' for k, v in kinds.items())}) in {time.perf_counter() - t0:.0f} s",
        flush=True,
    )
    report: dict[str, Any] = {
        "environment": {**environment(), "git_commit": git_commit()},
        "target": TARGET,
        "settings": {
            "steps": args.steps,
            "batch": args.batch,
            "width": args.width,
            "spatial_transformer": args.spatial_transformer,
            "seed": args.seed,
            "threads": threads,
            "samples": args.samples,
            "unrelated": kinds,
            "conditions": {
                "soft": "soft rasterizer render, framed by canonicalize+render_moments",
                "real": "resvg render (DeepMorphModel.real_renders), framed the same way, clean",
                "real_aug": "framed resvg render through the training augmentation at 'medium'",
                "r400": "resvg at 400 px through the photo chain, clean",
                "photo": "close_up_photo(resvg at 400 px, 'medium') through the photo chain",
            },
            "bit_acc": "code-bit accuracy of the network's hard decisions, over images where a drawing was found",
            "success": "codec ok and payload equal to the one sent, over all images",
        },
        "cells": [],
    }
    for cell in cells:
        report["cells"].append(run_cell(cell, args, unrelated, args.models_dir))
        write_json(args.out, report)  # after every cell, so a cut-short run keeps what it measured
    report["total_wall_s"] = time.perf_counter() - t0
    write_json(args.out, report)
    print()
    print(table(HEADERS, summary_rows(report["cells"])))
    print(f"\nwrote {args.out} (total {report['total_wall_s']:.0f} s)")


def git_commit() -> str | None:
    """The checkout's HEAD (the working tree may differ; bundles keep the drawing they were trained on)."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True)
    except OSError:
        return None
    return out.stdout.strip() or None


def print_saved(path: Path) -> None:
    """The table of a saved (possibly cut-short) run."""
    import json

    report = json.loads(path.read_text())
    print(table(HEADERS, summary_rows(report["cells"])))


if __name__ == "__main__":
    main()
