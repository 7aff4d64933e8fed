"""The photo chain's commands: ``decode``, ``synth``, ``bench-scenes``, ``bench-photos``,
``train-detector``, ``train-verifier``, ``export`` and ``demo``, added to the command line through the
``deepmorph_register_commands`` hook (:mod:`deepmorph.plugin`). Each parses its arguments and
calls the library (:mod:`deepmorph_detect`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from deepmorph.cli.frame import (
    EXIT_NOTHING_READ,
    PANEL_CODES,
    PANEL_MEASURE,
    PANEL_MODELS,
    DeviceOpt,
    JsonOpt,
    ModelArg,
    PhotoSeverityName,
    SeedOpt,
    ThreadsOpt,
    add_commands,
    err,
    out,
    print_json,
    progress_bar,
    setting_option,
    step_progress,
    training_result,
    write_text_atomic,
)
from deepmorph.training.detector_settings import DETECTOR_DEFAULTS, DetectorSettings
from deepmorph.training.verifier_settings import VERIFIER_DEFAULTS, VerifierSettings
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write, check_target, refuse_non_folder, refuse_to_overwrite
from deepmorph_core.threads import use_threads


def _progress(name: str):  # noqa: ANN202 - a rich Progress
    return progress_bar(name + " {task.description}")


CameraOpt = Annotated[
    Optional[str],
    typer.Option("--camera", help="Intrinsics fx,fy,cx,cy in pixels, or an OpenCV calibration file (YAML/XML)."),
]
DetectorOpt = Annotated[
    Optional[str],
    typer.Option(
        "--detector",
        help="The detector plugin to propose drawings (default: the one the model names, else 'universal';"
        " 'none': whole images only).",
    ),
]
HardOpt = Annotated[bool, typer.Option("--hard-decision", help="Skip soft-decision (Chase) decoding.")]


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise DeepMorphError(f"--size {text!r}: expected WIDTHxHEIGHT, e.g. 640x480") from None
    if not (64 <= w <= 8192 and 64 <= h <= 8192):
        raise DeepMorphError(f"--size {text!r}: width and height must be 64..8192 pixels")
    return w, h


def _fits_camera(camera: Any, path: Path, size: tuple[int, int]) -> None:
    """Check, before any work, that ``--camera`` describes an input of ``size`` (naming it)."""
    if camera is None:
        return
    try:
        camera.for_image(*size)
    except DeepMorphError as exc:
        raise DeepMorphError(f"{path}: {exc}") from None


def _overlay_targets(overlay: Path | None, inputs: list[Path], model: Path) -> dict[Path, Path]:
    """Where ``--overlay`` puts each input's annotated image: the file itself for one input,
    else ``<folder>/<input name>.overlay.png``. Checked before any work: no target may replace
    an input or the model, and no two inputs may share one (the first would be lost)."""
    if overlay is None:
        return {}
    if len(inputs) > 1 and overlay.suffix:
        raise DeepMorphError(f"--overlay {overlay}: with several inputs, give a folder for the annotated images")
    targets = {p: overlay if len(inputs) == 1 and overlay.suffix else overlay / f"{p.stem}.overlay.png" for p in inputs}
    claimed: dict[Path, Path] = {}
    for path, target in targets.items():
        refuse_to_overwrite(target, "--overlay", [("model file", model), *(("input", p) for p in inputs)])
        first = claimed.setdefault(target.resolve(), path)
        if first != path:
            raise DeepMorphError(
                f"--overlay {overlay}: {first} and {path} would both be annotated as {target}; rename one"
            )
    if len(inputs) == 1 and overlay.suffix:
        import cv2

        if not cv2.haveImageWriter(str(overlay)):
            raise DeepMorphError(f"--overlay {overlay}: cannot write this image format (use .png or .jpg)")
    return targets


def decode(
    model: ModelArg,
    inputs: Annotated[
        list[Path],
        typer.Argument(help="Images (each decoded on its own), folders of frames or videos (frames fused)."),
    ],
    as_json: JsonOpt = False,
    camera: CameraOpt = None,
    overlay: Annotated[
        Optional[Path],
        typer.Option("--overlay", help="Write an annotated image (a folder when there are several inputs)."),
    ] = None,
    every: Annotated[int, typer.Option("--every", min=1, help="Use every N-th frame of a video.")] = 1,
    first: Annotated[
        bool,
        typer.Option(
            "--first",
            help="Stop at the first drawing read in each image or frame and give it alone, as a scanner "
            "looking for one code does: faster where other drawings are in view.",
        ),
    ] = False,
    hard_only: HardOpt = False,
    detector: DetectorOpt = None,
    threads: ThreadsOpt = None,
    device: DeviceOpt = "auto",
    registry: Annotated[
        bool, typer.Option("--registry", help="Show each verified payload's entry in the payload registry.")
    ] = False,
    db: Annotated[Optional[Path], typer.Option("--db", help="The payload registry file (implies --registry).")] = None,
) -> None:
    """Find every drawing in photos, read its payload, and give its keypoints and camera pose.

    Exits with status 4 when an input (an image, or a folder or video as a whole) gave no
    verified payload, after printing every result (with --json, an empty "detections" list).
    """
    import cv2

    from deepmorph_core.image_io import read_image_bgr
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.camera import parse_camera
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.overlay import draw_overlay
    from deepmorph_detect.reading import FrameSource, read_sequence

    use_threads(threads)
    m = DeepMorphModel.load(model)
    look_up = None
    if registry or db is not None:
        from deepmorph.registry import PayloadRegistry, detection_lookup

        look_up = detection_lookup(PayloadRegistry(db), m)  # a missing or foreign registry: refused before any work
    locator = Locator(m, detector=detector, device=device)
    cam = parse_camera(camera) if camera else None
    jobs: list[tuple[str, Path, Any]] = []
    for path in inputs:  # every input is checked before any work
        source = FrameSource.open(path)
        if source is not None:
            if source.frame_size is not None:
                _fits_camera(cam, path, source.frame_size)
            jobs.append(("sequence", path, source))
        else:
            image = read_image_bgr(path)
            _fits_camera(cam, path, (image.shape[1], image.shape[0]))
            jobs.append(("image", path, image))
    targets = _overlay_targets(overlay, [path for _, path, _ in jobs], model)
    soft = not hard_only
    results: list[dict[str, Any]] = []

    def save_overlay(path: Path, image: Any, dets: list[Any]) -> None:
        target = targets.get(path)
        if target is None:
            return
        ok, buf = cv2.imencode(target.suffix or ".png", draw_overlay(image, dets))
        if not ok:
            raise DeepMorphError(f"--overlay {target}: cannot write this image format")
        atomic_write(target, buf.tobytes())

    images = sum(kind == "image" for kind, _, _ in jobs)
    with _progress("decode") as progress:
        image_task = progress.add_task("images", total=images) if images > 1 else None
        for kind, path, payload in jobs:
            if kind == "image":
                dets = locator.locate(payload, camera=cam, soft=soft, first=first)
                results.append({"image": str(path), "detections": [d.to_json() for d in dets]})
                save_overlay(path, payload, dets)
                if image_task is not None:
                    progress.advance(image_task)
                continue
            task = progress.add_task(path.name, total=payload.count(every))
            reading = read_sequence(
                locator, payload.frames(every), camera=cam, soft=soft, name=str(path),
                on_frame=lambda task=task: progress.advance(task),
                on_skip=lambda text: err.print(f"warning: {text}", markup=False, highlight=False), first=first,
            )  # fmt: skip
            entry = {"sequence": str(path), "frames": reading.frames, "detections": reading.detections}
            if reading.skipped:
                entry["skipped_frames"] = reading.skipped
            results.append(entry)
            save_overlay(path, *reading.last)
    for d in (d for r in results for d in r["detections"] if look_up is not None):
        d["registry"] = look_up(d)
    _print_decoded(results, as_json)
    if not all(any(d["ok"] for d in r["detections"]) for r in results):
        raise typer.Exit(EXIT_NOTHING_READ)


def _print_decoded(results: list[dict[str, Any]], as_json: bool) -> None:
    from deepmorph_detect.results import too_small_reason
    from deepmorph_detect.synthesis import disagreement_in

    if as_json:
        print_json(results)
        return
    for r in results:
        name = r.get("image") or f"{r['sequence']} ({r['frames']} frames)"
        if not r["detections"]:
            out.print(f"{name}: no drawing found")
        for d in r["detections"]:
            status = "ok" if d["ok"] else "NOT VERIFIED (integrity check failed)"
            if "too_small" in d:
                status = f"NOT READ: {too_small_reason(d['too_small'])}"
            elif d.get("morph_check") == "failed":
                status = "NOT VERIFIED (the CRC passed, but the decoded morph does not fit the photo)"
            elif d.get("morph_check") == "turn conflict":
                status = "NOT VERIFIED (the drawing looks the same turned, and two turns read two payloads)"
            elif d.get("morph_check") == "contradicted":
                why = disagreement_in(d)
                status = f"NOT VERIFIED (the CRC passed, but {why})"
            where = ""
            if "pose" in d:
                t = d["pose"]["tvec"]
                where = f", at {t[2]:.2f} drawing widths" + (
                    " (assumed camera)" if d["pose"]["camera"]["assumed"] else ""
                )
            frames = f", fused over {d['frames']} frames" if "frames" in d else ""
            out.print(
                f"{name}: {d['payload']['hex']} {status}, corrected {d['corrected_bits']} bits, "
                f"confidence {d['confidence']:.3f}{where}{frames}"
            )
            if d["ok"] and "registry" in d:
                entry = d["registry"]
                shown = f"{entry['kind']}: {entry['target']}".replace("\n", "\n  ") if entry else "not in the registry"
                out.print(f"  {shown}")


def synth(
    model: ModelArg,
    out_dir: Annotated[
        Path, typer.Option("--out", help="Folder for the scenes (PNG + JSON truth each, index.json, labels.csv).")
    ],
    n: Annotated[int, typer.Option("--n", min=1, max=1_000_000, help="Number of scenes.")] = 200,
    severity: Annotated[
        PhotoSeverityName, typer.Option("--severity", help="How rough the simulated capture is.")
    ] = "medium",
    seed: Annotated[int, typer.Option("--seed", help="Random seed (same seed, same scenes).")] = 0,
    size: Annotated[str, typer.Option("--size", help="Size of each photo, WIDTHxHEIGHT in pixels.")] = "640x480",
    drawings: Annotated[int, typer.Option("--drawings", min=0, max=8, help="Drawings of the model per scene.")] = 1,
    distractors: Annotated[int, typer.Option("--distractors", min=0, max=8, help="Other drawings per scene.")] = 0,
    aruco: Annotated[bool, typer.Option("--aruco/--no-aruco", help="Add an ArUco marker of the same size.")] = True,
    empty_share: Annotated[
        float, typer.Option("--empty-share", min=0, max=1, help="Share of scenes without the model's drawing.")
    ] = 0.0,
    threads: ThreadsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Make labelled synthetic photos of printed drawings (the capture simulator), with labels.csv."""
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.labels import LABELS_NAME
    from deepmorph_detect.scene_folders import check_scene_folder, write_scenes

    check_scene_folder(out_dir)
    dims = _size(size)
    use_threads(threads)
    m = DeepMorphModel.load(model)
    with _progress("synth") as progress:
        task = progress.add_task("", total=n)
        write_scenes(m, out_dir, n, severity, seed, dims, drawings, distractors, aruco, empty_share,
                     on_scene=lambda i: progress.update(task, completed=i))  # fmt: skip
    if as_json:
        print_json({"written": [str(out_dir)], "folder": str(out_dir), "scenes": n, "severity": severity,
                    "size": list(dims), "seed": seed, "labels": str(out_dir / LABELS_NAME),
                    "index": str(out_dir / "index.json")})  # fmt: skip
        return
    out.print(f"wrote {n} scenes ({severity}, {dims[0]}x{dims[1]}) and {LABELS_NAME} to {out_dir}")


def bench_scenes_cmd(
    model: ModelArg,
    scenes: Annotated[Path, typer.Argument(help="A folder written by `deepmorph synth`.")],
    as_json: JsonOpt = False,
    report_path: Annotated[Optional[Path], typer.Option("--out", help="Also write the report as JSON here.")] = None,
    first: Annotated[
        bool,
        typer.Option(
            "--first", help="Locate as `decode --first`: the first drawing read per scene (one code, as QR reads)."
        ),
    ] = False,
    threads: ThreadsOpt = None,
) -> None:
    """Recall, payload success, pose error and speed on synthetic scenes, beside ArUco and QR."""
    if report_path is not None:
        refuse_to_overwrite(report_path, "--out", [("model file", model), ("scene index", scenes / "index.json")])
    from deepmorph.measure.scene_bench import bench_scenes
    from deepmorph.measure.scene_report import format_report
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scene_folders import read_scenes

    n_threads = use_threads(threads)
    m = DeepMorphModel.load(model)
    _, listed = read_scenes(scenes)  # validates the folder before any work
    with _progress("bench") as progress:
        task = progress.add_task("", total=len(listed))
        report = bench_scenes(m, scenes, on_scene=lambda i: progress.update(task, completed=i), first=first)
    report["threads"] = n_threads
    if report_path is not None:
        atomic_write(report_path, json.dumps(report, indent=1).encode())
    if as_json:
        print_json(report)
    else:
        out.print(format_report(report))


def bench_photos_cmd(
    model: ModelArg,
    photos: Annotated[Path, typer.Argument(help="A folder of photos of printed codes (or one made by `synth`).")],
    labels: Annotated[
        Optional[Path],
        typer.Option(
            "--labels",
            help="CSV: file, expected payload in hex, optionally corners x0,y0,...,x3,y3 [default: PHOTOS/labels.csv].",
            show_default=False,
        ),
    ] = None,
    report_dir: Annotated[
        Optional[Path],
        typer.Option("--report", help="Write report.html, report.json and PNG plots into this folder."),
    ] = None,
    as_json: JsonOpt = False,
    camera: CameraOpt = None,
    detector: DetectorOpt = None,
    hard_only: HardOpt = False,
    threads: ThreadsOpt = None,
) -> None:
    """Score a model on your own labelled photos: read rate, wrong payloads, corner error, time, and a report."""
    from deepmorph.measure.photo_bench import bench_photos, photo_files
    from deepmorph.measure.photo_report import NO_PLOTS, format_summary, write_report
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.camera import parse_camera
    from deepmorph_detect.labels import LABELS_NAME

    labels_path = labels if labels is not None else photos / LABELS_NAME
    photo_files(photos)  # a folder, checked first
    if not labels_path.is_file():
        raise DeepMorphError(f"{labels_path}: no labels file (give one with --labels; see docs/detection.md)")
    if report_dir is not None:
        if report_dir.resolve() == photos.resolve():
            raise DeepMorphError(f"--report {report_dir}: the photos' folder; choose another (its plots are images)")
        refuse_non_folder(report_dir, "--report")
        for name in ("report.html", "report.json"):
            check_target(report_dir / name, f"--report {report_dir / name}")
    n_threads = use_threads(threads)
    m = DeepMorphModel.load(model)
    cam = parse_camera(camera) if camera else None
    with _progress("photos") as progress:
        task = progress.add_task("", total=None)
        report = bench_photos(
            m, photos, labels_path, camera=cam, detector=detector, soft=not hard_only,
            on_photo=lambda done, total: progress.update(task, completed=done, total=total),
            on_skip=lambda name, why: err.print(f"warning: skipped photo {why}"),
        )  # fmt: skip
    report["threads"] = n_threads
    if report_dir is not None:
        written, note = write_report(report, report_dir)
        if note == NO_PLOTS:
            err.print(f"note: {NO_PLOTS}")
        report["written"] = [str(p) for p in written]
    if as_json:
        print_json(report)
        return
    out.print(format_summary(report), soft_wrap=True)
    if report_dir is not None:
        out.print(f"report: {report_dir / 'report.html'}")


def train_detector_cmd(
    model: ModelArg,
    out_path: Annotated[Path, typer.Option("--out", help="Bundle to write with the detector (also the checkpoint).")],
    steps: Annotated[int, setting_option("steps", settings=DetectorSettings)] = DETECTOR_DEFAULTS.steps,
    batch: Annotated[int, setting_option("batch", settings=DetectorSettings)] = DETECTOR_DEFAULTS.batch,
    seed: SeedOpt = DETECTOR_DEFAULTS.seed,
    threads: ThreadsOpt = None,
    device: DeviceOpt = DETECTOR_DEFAULTS.device,
    workers: Annotated[int, setting_option("workers", settings=DetectorSettings)] = DETECTOR_DEFAULTS.workers,
    width: Annotated[int, setting_option("width", settings=DetectorSettings)] = DETECTOR_DEFAULTS.width,
    lr: Annotated[float, setting_option("lr", settings=DetectorSettings)] = DETECTOR_DEFAULTS.lr,
    fine_tune: Annotated[
        bool,
        typer.Option(
            "--fine-tune",
            help="Start from the model's trained detector (same --channels) instead of from scratch;"
            " use another --seed for new scenes and a lower --lr.",
        ),
    ] = DETECTOR_DEFAULTS.fine_tune,
    from_scratch: Annotated[
        bool,
        typer.Option(
            "--from-scratch",
            help="Start from random weights instead of the shipped universal detector"
            " (give about --steps 2000 --lr 2e-3).",
        ),
    ] = DETECTOR_DEFAULTS.start == "scratch",
    resume: Annotated[bool, typer.Option("--resume", help="Continue the checkpoint at --out.")] = False,
    as_json: JsonOpt = False,
) -> None:
    """Fine-tune a detector for one model, starting from the universal detector every model
    already has (about 2 minutes), and store it in the bundle. Worth it only where
    `bench/universal_detector.py` shows it finds more of the drawing."""
    from deepmorph.training.detector import DetectorConfig, train_detector

    config = (
        None
        if resume
        else DetectorConfig(
            steps=steps,
            batch=batch,
            seed=seed,
            threads=threads,
            workers=workers,
            device=device,
            width=width,
            lr=lr,
            fine_tune=fine_tune,
            start="scratch" if from_scratch else "universal",
        )
    )
    use_threads(threads)

    def describe(m: dict[str, Any]) -> str:
        return f"loss {m['loss']:.3f} centre recall {m['recall']:.3f} corner err {m['corner']:.1f}px"

    with step_progress("detector", describe) as bar:
        on_log = bar(steps, 0)
        summary = train_detector(out_path if resume else model, out_path, config, resume=resume, on_log=on_log)
    if as_json:
        print_json(training_result(summary, bar.last))
        return
    out.print(
        f"wrote {summary.bundle} ({summary.steps} detector steps in {summary.elapsed_s:.0f} s); log {summary.log}"
    )


def train_verifier_cmd(
    model: ModelArg,
    out_path: Annotated[Path, typer.Option("--out", help="Bundle to write with the verifier (may be the model).")],
    scenes: Annotated[int, setting_option("scenes", settings=VerifierSettings)] = VERIFIER_DEFAULTS.scenes,
    check_scenes: Annotated[
        int, setting_option("check_scenes", settings=VerifierSettings)
    ] = VERIFIER_DEFAULTS.check_scenes,
    steps: Annotated[int, setting_option("steps", settings=VerifierSettings)] = VERIFIER_DEFAULTS.steps,
    seed: SeedOpt = VERIFIER_DEFAULTS.seed,
    threads: ThreadsOpt = None,
    workers: Annotated[int, setting_option("workers", settings=VerifierSettings)] = VERIFIER_DEFAULTS.workers,
    as_json: JsonOpt = False,
) -> None:
    """Train a proposal verifier for a model read with the shipped universal detector (about 5
    minutes on 2 cores; `train --pixels` ends with one): photos with other drawings in them then
    take less time to read."""
    from deepmorph.training.verifier import VerifierConfig, train_verifier

    config = VerifierConfig(
        scenes=scenes, check_scenes=check_scenes, steps=steps, seed=seed, threads=threads, workers=workers
    )
    use_threads(threads)
    with step_progress("verifier", lambda m: f"loss {m['loss']:.3f}") as bar:
        on_log = None

        def on_step(step: int, loss: float) -> None:
            nonlocal on_log
            if on_log is None:
                on_log = bar(steps, 0)
            if step % 50 == 0 or step == steps:
                on_log({"step": step, "loss": loss})

        summary = train_verifier(model, out_path, config, on_stage=lambda text: err.print(text), on_step=on_step)
    if as_json:
        print_json(summary.as_json())
        return
    out.print(f"wrote {summary.bundle} (verifier {summary.text()})")


def _size_text(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 100_000 else f"{n / 1e3:.1f} kB"


def export_cmd(
    model: ModelArg,
    out_dir: Annotated[
        Optional[Path],
        typer.Option("--out", help="Folder for decoder.onnx, detector.onnx and manifest.json (docs/export.md)."),
    ] = None,
    bundle: Annotated[
        Optional[Path],
        typer.Option("--bundle", help="Also write the model with its ONNX graphs stored (may be the model itself)."),
    ] = None,
    as_json: JsonOpt = False,
) -> None:
    """Write the model's networks as ONNX graphs with a manifest, for apps that decode without Python."""
    if out_dir is None and bundle is None:
        raise typer.BadParameter("give --out (a folder for the files), --bundle, or both", param_hint="'--out'")
    from deepmorph.export import export_model

    summary = export_model(model, out_dir, bundle)
    if as_json:
        print_json(summary.to_json())
        return
    for note in summary.notes:
        out.print(note)
    if summary.files:
        listed = ", ".join(f"{name} ({_size_text(f['bytes'])})" for name, f in summary.files.items())
        out.print(f"wrote {listed} to {out_dir}")
    if summary.bundle:
        out.print(f"wrote {summary.bundle} with its ONNX graphs ({', '.join(summary.graphs)})")


def demo(
    out_dir: Annotated[Path, typer.Option("--out", help="Folder for the demo's files.")] = Path("deepmorph-demo"),
    seed: Annotated[int, typer.Option("--seed", help="Seed of the payload and the photo simulation.")] = 3,
    retrain: Annotated[
        bool, typer.Option("--train", help="Train a fresh model instead of loading the bundled one.")
    ] = False,
    steps: Annotated[int, typer.Option("--steps", min=1, help="Steps when training (--train).")] = 600,
) -> None:
    """Bundled drawing end to end: model, encode a payload, simulate print-and-photo, decode."""
    import numpy as np

    from deepmorph.training.codec import train_model
    from deepmorph_core.bundled import BUNDLED_DRAWING, BUNDLED_MODEL
    from deepmorph_core.fileio import output_folder
    from deepmorph_core.image_io import save_bgr, save_gray, save_rgb
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.payload import format_payload, random_payloads
    from deepmorph_core.render import overlay, render_svg, render_svg_ink
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scenes import close_up_photo

    output_folder(out_dir, f"--out {out_dir}")
    if retrain or not BUNDLED_MODEL.is_file():
        out.print(f"training a model for {BUNDLED_DRAWING.name} ({steps} steps) ...")
        with step_progress("training", lambda m: f"stage {m['stage']} bit acc {m['bit_acc']:.3f}") as bar:
            summary = train_model(BUNDLED_DRAWING, out_dir / "ghost.dmm", payload_bits=24, train={"steps": steps},
                                  on_start=bar)  # fmt: skip
        model_path = summary.bundle
    else:
        model_path = BUNDLED_MODEL
    m = DeepMorphModel.load(model_path)
    rng = np.random.default_rng(seed)
    payload = random_payloads(1, m.codec.spec.payload_bits, rng)[0]
    svg_text = m.encode(payload)
    write_text_atomic(out_dir / "code.svg", svg_text)
    render = render_svg(svg_text, 400)
    save_gray(render, out_dir / "code.png")
    base = render_svg_ink(m.drawing.to_svg(m.drawing.neutral_values()[0]), 400)
    save_rgb(overlay(base, 1.0 - render), out_dir / "overlay.png")
    out.print(f"model {model_path}: {m.codec.spec.payload_bits} payload bits in {m.codec.spec.code_bits} code bits")
    out.print(f"encoded {format_payload(payload)['hex']} into {out_dir}/code.svg (and code.png, overlay.png)")
    locator = Locator(m)
    for severity in ("easy", "medium", "hard"):
        photo = close_up_photo(render, severity, rng)
        save_bgr(photo, out_dir / f"photo-{severity}.png")
        dets = locator.locate(photo)
        if not dets:
            out.print(f"photo-{severity}.png: no drawing found")
            continue
        r = dets[0].result
        verdict = "ok" if r.ok and np.array_equal(r.payload, payload) else ("WRONG" if r.ok else "not verified")
        out.print(
            f"photo-{severity}.png: decoded {format_payload(r.payload)['hex']} ({verdict}; "
            f"corrected {r.corrected_bits} bits, confidence {r.confidence:.3f})"
        )
    if m.meta.detector is not None:
        _demo_scene(locator, out_dir, seed)


def _demo_scene(locator: Any, out_dir: Path, seed: int) -> None:
    """A cluttered synthetic photo with two prints: find, decode and pose both."""
    import numpy as np

    from deepmorph_core.image_io import save_bgr
    from deepmorph_core.payload import format_payload
    from deepmorph_detect.overlay import draw_overlay
    from deepmorph_detect.scenes import SceneMaker

    scene = SceneMaker(locator.model, severity="medium", seed=seed).make(drawings=2, distractors=1, aruco=True)
    save_bgr(scene.image, out_dir / "scene.png")
    dets = locator.locate(scene.image, camera=scene.camera)
    save_bgr(draw_overlay(scene.image, dets), out_dir / "scene-overlay.png")
    truths = [p for p in scene.placements if p.kind == "drawing"]
    out.print(f"scene.png: {len(truths)} printed codes among clutter, another icon and an ArUco marker")
    for d in dets:
        right = any(np.array_equal(d.result.payload, t.payload) for t in truths)
        verdict = "ok" if d.result.ok and right else ("WRONG" if d.result.ok else "not verified")
        t = d.tvec if d.tvec is not None else np.zeros(3)
        out.print(
            f"  found {format_payload(d.result.payload)['hex']} ({verdict}) at {t[2]:.2f} drawing widths, "
            f"alignment {d.correlation:.2f}"
        )
    out.print(f"  {len(dets)} of {len(truths)} found; annotated in {out_dir}/scene-overlay.png")


def register(cli: typer.Typer) -> None:
    """Add the photo chain's commands to ``cli``."""
    add_commands(
        cli,
        (
            ("train-detector", train_detector_cmd, PANEL_MODELS),
            ("train-verifier", train_verifier_cmd, PANEL_MODELS),
            ("export", export_cmd, PANEL_MODELS),
            ("decode", decode, PANEL_CODES),
            ("synth", synth, PANEL_MEASURE),
            ("bench-scenes", bench_scenes_cmd, PANEL_MEASURE),
            ("bench-photos", bench_photos_cmd, PANEL_MEASURE),
            ("demo", demo, None),
        ),
    )
