"""Issue 4: detection, alignment, pose, fusion and scenes, on the bundled model and real scenes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

import deepmorph_detect.locate as locate_module
from deepmorph.cli import application
from deepmorph.measure.scene_bench import morph_check_rates
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.codec import DecodeResult, PayloadCodec
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_detect.align import BENT_OUTLINE, WEAK_ALIGNMENT, Aligned
from deepmorph_detect.camera import (
    Camera,
    homography_from_pose,
    parse_camera,
    project,
    rigid_misfit,
    rotation_error_deg,
    solve_pose,
    translation_error,
    viewbox_corners,
)
from deepmorph_detect.check import PayloadCheck
from deepmorph_detect.locate import Locator
from deepmorph_detect.metrics import SceneTally
from deepmorph_detect.propose import whole_frame
from deepmorph_detect.read import Reader
from deepmorph_detect.refine import Alignment, ImagePyramid, Template, correlation, refine
from deepmorph_detect.results import Located, Pose
from deepmorph_detect.scene_folders import write_scenes
from deepmorph_detect.scenes import Placement, SceneMaker, close_up_photo
from tests.conftest import easy_print_aligned, shaken_clip

app = application()  # the command line's own commands and every installed plugin's

runner = CliRunner()


def _matches(det, placement) -> bool:
    size = np.linalg.norm(placement.corners[2] - placement.corners[0])
    return bool(np.linalg.norm(det.corners.mean(0) - placement.corners.mean(0)) < 0.25 * size)


# -- camera ---------------------------------------------------------------------------------


def test_camera_parsing_numbers_and_errors() -> None:
    cam = parse_camera("500, 510, 320, 240")
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (500, 510, 320, 240) and not cam.assumed
    for bad in ("500,510,320", "a,b,c,d", "-5,5,1,1", "nan,1,1,1"):
        with pytest.raises(DeepMorphError, match="--camera"):
            parse_camera(bad)
    default = Camera.default(640, 480)
    assert default.assumed and default.cx == 320 and "assumed" in default.to_json()["note"]


def test_camera_calibration_file(tmp_path: Path) -> None:
    path = tmp_path / "calib.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", np.array([[600.0, 0, 330], [0, 605, 250], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[0.1, -0.05, 0, 0, 0]]))
    fs.release()
    cam = parse_camera(str(path))
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (600, 605, 330, 250) and len(cam.dist) == 5
    broken = tmp_path / "broken.yaml"
    broken.write_text("%YAML:1.0\nnot: [a calibration")
    with pytest.raises(DeepMorphError, match="broken.yaml"):
        parse_camera(str(broken))
    with pytest.raises(DeepMorphError, match="no such calibration file"):
        parse_camera(str(tmp_path / "missing.yml"))
    # a matrix whose data is not rows x cols numbers: OpenCV asserts while reading it
    short = tmp_path / "short.yaml"
    short.write_text("%YAML:1.0\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1, 0 ]\n")
    with pytest.raises(DeepMorphError, match="short.yaml: camera_matrix is not a well-formed matrix"):
        parse_camera(str(short))


def test_pnp_recovers_a_known_pose() -> None:
    cam = Camera(700, 700, 320, 240)
    rvec, tvec = np.array([0.4, -0.3, 1.2]), np.array([0.2, -0.1, 3.0])
    grid = np.array([[x, y, 0.0] for y in (-0.5, 0, 0.5) for x in (-0.5, 0, 0.5)])
    pixels = project(homography_from_pose(cam, rvec, tvec), grid[:, :2])
    r, t = solve_pose(cam, grid, pixels)
    assert rotation_error_deg(r, rvec) < 1e-3 and translation_error(t, tvec) < 1e-5


@pytest.mark.parametrize("fov", [52.0, 66.0, 78.0])
def test_a_flat_print_seen_by_a_phone_fits_a_rigid_pose_and_a_bent_outline_does_not(fov: float) -> None:
    """``rigid_misfit``: any pose of a flat print (tilted up to 60 degrees, anywhere in a 640 x
    480 photo, a field of view from 52 to 78 degrees) fits within half a percent of the print's
    width. One corner pulled out along its diagonal by a fifth of the width fits no pose for
    most poses (a pose tilted towards that corner explains some of it), and a kite none."""
    w, h = 640, 480
    f = (w / 2) / np.tan(np.radians(fov) / 2)
    cam = Camera(f, f, w / 2, h / 2)
    corners = np.array([[0.0, 0.0], [24.0, 0.0], [24.0, 18.0], [0.0, 18.0]])  # a 4:3 viewBox
    to_drawing = np.array([[1 / 24, 0, -0.5], [0, 1 / 24, -18 / 48], [0, 0, 1]])  # centred, width 1
    rng = np.random.default_rng(int(fov))
    pulled = []
    for _ in range(40):
        axis = rng.uniform(0, 2 * np.pi)
        R_tilt, _ = cv2.Rodrigues(np.array([np.cos(axis), np.sin(axis), 0.0]) * np.radians(rng.uniform(0, 60)))
        R_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, rng.uniform(-np.pi, np.pi)]))
        rvec, _ = cv2.Rodrigues(R_tilt @ R_spin)
        tvec = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4), rng.uniform(2.5, 5.0)])
        H = homography_from_pose(cam, rvec.ravel(), tvec) @ to_drawing
        assert rigid_misfit(H, corners, (w, h)) < 0.005
        quad = project(H, corners)
        out = quad[2] - quad.mean(0)
        quad[2] += 0.2 * np.linalg.norm(quad[1] - quad[0]) * out / np.linalg.norm(out)
        bent = cv2.getPerspectiveTransform(corners.astype(np.float32), quad.astype(np.float32))
        pulled.append(rigid_misfit(bent, corners, (w, h)))
    assert np.median(pulled) > BENT_OUTLINE
    kite = np.array([[300.0, 200.0], [380.0, 200.0], [420.0, 320.0], [300.0, 260.0]])
    H = cv2.getPerspectiveTransform(corners.astype(np.float32), kite.astype(np.float32))
    assert rigid_misfit(H, corners, (w, h)) > 0.05


def test_the_pose_cube_stands_on_the_drawing() -> None:
    """:meth:`Pose.cube`'s base is the square half a drawing wide around the drawing's centre,
    where the plane's homography puts it, and its top is nearer the camera."""
    cam = Camera(700, 700, 320, 240)
    rvec, tvec = np.array([0.5, -0.2, 0.3]), np.array([0.1, 0.05, 2.5])
    cube = Pose(rvec, tvec, cam).cube(0.5)
    base = np.array([[-0.25, -0.25], [0.25, -0.25], [0.25, 0.25], [-0.25, 0.25]])
    assert cube.shape == (8, 2)
    np.testing.assert_allclose(cube[:4], project(homography_from_pose(cam, rvec, tvec), base), atol=1e-6)
    rotation, _ = cv2.Rodrigues(rvec)
    depth = lambda z: (rotation @ np.array([0.25, 0.25, z]) + tvec)[2]  # noqa: E731
    assert depth(-0.5) < depth(0.0)  # the top (z = -0.5, out of the paper) is nearer the camera


def test_a_scene_tally_counts_what_the_benchmarks_count() -> None:
    """:class:`SceneTally`, the one count of the scene benchmarks: a right read, an unread
    print, a wrong payload on a print, a second detection of a print, and one of nothing."""
    square = np.array([[0, 0], [100, 0], [100, 100], [0, 100]], dtype=np.float64)

    def placed(dx: float, payload: list[int]) -> Placement:
        return Placement("drawing", np.zeros(3), np.zeros(3), np.eye(3), square + dx, np.array(payload))

    def found(dx: float, ok: bool, payload: list[int]) -> SimpleNamespace:
        return SimpleNamespace(corners=square + dx, result=SimpleNamespace(ok=ok, payload=np.array(payload)))

    a, b, c = placed(0, [1, 0]), placed(300, [0, 1]), placed(600, [1, 1])
    tally = SceneTally()
    scored = tally.add([found(0, True, [1, 0]), found(300, False, [0, 0]), found(600, True, [0, 0]),
                        found(2, True, [1, 0]), found(900, True, [1, 1])], [a, b, c])  # fmt: skip
    assert [(p is not None, right) for _, p, right in scored] == [(True, True), (True, False), (True, False),
                                                                   (False, False), (False, False)]  # fmt: skip
    assert tally == SceneTally(prints=3, found=3, read=1, unread=1, wrong=3, false=2)
    tally.add([], [a])
    assert tally.prints == 4 and tally.found == 3


# -- scenes ---------------------------------------------------------------------------------


def test_scene_truth_is_exact_and_seeded(model: DeepMorphModel) -> None:
    a = SceneMaker(model, seed=11).make(drawings=2, distractors=1, aruco=True)
    b = SceneMaker(model, seed=11).make(drawings=2, distractors=1, aruco=True)
    assert np.array_equal(a.image, b.image)
    assert a.image.shape == (480, 640, 3)
    kinds = [p.kind for p in a.placements]
    assert kinds.count("drawing") == 2 and "aruco" in kinds
    x, y, w, h = model.drawing.drawing.viewbox
    for p in a.placements:
        if p.kind == "drawing":
            # the homography, the pose and the corners all tell the same story
            corners = project(p.homography, np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]]))
            assert np.allclose(corners, p.corners, atol=1e-6)
            plane = homography_from_pose(a.camera, p.rvec, p.tvec)
            assert np.allclose(project(plane, np.array([[-0.5, -h / w / 2]])), corners[:1], atol=1e-6)
            assert p.payload is not None and p.payload.shape == (model.codec.spec.payload_bits,)
        assert (p.corners >= 0).all() and (p.corners[:, 0] < 640).all() and (p.corners[:, 1] < 480).all()


# -- the chain on scenes -------------------------------------------------------------------


def test_detects_decodes_and_poses_drawings_in_scenes(model: DeepMorphModel, locator: Locator) -> None:
    maker = SceneMaker(model, severity="easy", seed=21)
    found = decoded = total = 0
    corner_err, rot_err = [], []
    for _ in range(12):
        scene = maker.make(drawings=1, distractors=1, aruco=True)
        truth = next(p for p in scene.placements if p.kind == "drawing")
        total += 1
        dets = locator.locate(scene.image, camera=scene.camera)
        hits = [d for d in dets if _matches(d, truth)]
        assert len(dets) == len(hits), "a detection on something that is not the drawing"
        if hits:
            d = hits[0]
            found += 1
            right = bool(d.result.ok and np.array_equal(d.result.payload, truth.payload))
            decoded += right
            # an ok payload has passed the check by synthesis, and the pose comes from its morph
            assert d.morph_check == ("passed" if d.result.ok else "not run")
            if right:
                corner_err.append(np.linalg.norm(d.corners - truth.corners, axis=1).mean())
                rot_err.append(rotation_error_deg(d.rvec, truth.rvec))
    assert found >= 10, f"recall {found}/{total}"
    assert decoded >= 9, f"decoded {decoded}/{found}"
    # aligned to the decoded morph, corners are sub-pixel (ArUco's are about 0.5 px here)
    assert np.median(corner_err) < 0.8, corner_err
    assert np.median(rot_err) < 0.8, rot_err


def test_alignment_to_the_decoded_morph_beats_the_unmorphed_drawing(model: DeepMorphModel, locator: Locator) -> None:
    maker = SceneMaker(model, severity="medium", seed=4)
    plain, morphed = [], []
    for _ in range(6):
        scene = maker.make(drawings=1)
        truth = scene.placements[0]
        dets = locator.locate(scene.image, camera=scene.camera)
        d = next(d for d in dets if d.result.ok)
        corners = lambda H: project(H, viewbox_corners(locator.viewbox))  # noqa: E731
        aligned = refine(ImagePyramid(to_gray(scene.image)), d.homography, locator.template)
        plain.append(np.linalg.norm(corners(aligned.homography) - truth.corners, axis=1).mean())
        morphed.append(np.linalg.norm(d.corners - truth.corners, axis=1).mean())
    assert np.median(morphed) < 0.5 * np.median(plain), (morphed, plain)


def test_a_wrong_payload_that_passes_the_crc_is_withdrawn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    scene = SceneMaker(model, severity="easy", seed=21).make(drawings=1)
    truth = scene.placements[0]
    (det,) = locator.locate(scene.image, camera=scene.camera)
    assert det.result.ok and det.morph_check == "passed" and det.morph.gain > 0
    # a CRC collision on a misread drawing: the codec reports some other payload as ok
    wrong = np.random.default_rng(0).integers(0, 2, truth.payload.shape).astype(np.uint8)
    fit = locator.checker.fit_morph(scene.image, det.homography, wrong)
    assert fit is not None and not fit.confirms and fit.gain < det.morph.gain
    real_decode = model.codec.decode
    monkeypatch.setattr(
        model.codec, "decode", lambda probs, soft=True: replace(real_decode(probs, soft=soft), payload=wrong, ok=True)
    )
    (det,) = locator.locate(scene.image, camera=scene.camera)
    data = det.to_json()
    assert not det.result.ok and data["ok"] is False and data["morph_check"] == "failed"
    assert data["pose_aligned_to"] == "unmorphed drawing"
    # and the command line says why
    cv2.imwrite(str(tmp_path / "photo.png"), scene.image)
    monkeypatch.setattr(
        PayloadCodec,
        "decode",
        lambda self, probs, soft=True: replace(real_decode(probs, soft=soft), payload=wrong, ok=True),
    )
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(tmp_path / "photo.png")])
    assert res.exit_code == 4 and "decoded morph does not fit the photo" in " ".join(res.output.split()), res.output


def test_several_drawings_in_one_photo(model: DeepMorphModel, locator: Locator) -> None:
    maker = SceneMaker(model, severity="easy", seed=5)
    best = 0
    for _ in range(4):
        scene = maker.make(drawings=3)
        truths = [p for p in scene.placements if p.kind == "drawing"]
        dets = locator.locate(scene.image, camera=scene.camera)
        right = sum(
            any(_matches(d, t) and d.result.ok and np.array_equal(d.result.payload, t.payload) for d in dets)
            for t in truths
        )
        best = max(best, right)
        assert all(any(_matches(d, t) for t in truths) for d in dets)
    assert best >= 2


def test_photos_without_the_drawing_give_nothing(model: DeepMorphModel, locator: Locator) -> None:
    maker = SceneMaker(model, severity="medium", seed=8)
    for _ in range(8):
        scene = maker.make(drawings=0, distractors=2, aruco=True)
        assert locator.locate(scene.image) == []
    assert locator.locate(np.full((300, 400), 255, np.uint8)) == []
    noise = np.random.default_rng(0).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    assert locator.locate(noise) == []


# -- CLI --------------------------------------------------------------------------------------


def _scene_file(model: DeepMorphModel, path: Path, seed: int = 3, **kw) -> object:
    scene = SceneMaker(model, severity="easy", seed=seed).make(**kw)
    cv2.imwrite(str(path), scene.image)
    return scene


def test_cli_decode_json_pose_and_overlay(model: DeepMorphModel, tmp_path: Path) -> None:
    scene = _scene_file(model, tmp_path / "street.png", drawings=1)
    truth = next(p for p in scene.placements if p.kind == "drawing")
    cam = scene.camera
    res = runner.invoke(
        app,
        ["decode", str(BUNDLED_MODEL), str(tmp_path / "street.png"), "--json",
         "--camera", f"{cam.fx},{cam.fy},{cam.cx},{cam.cy}", "--overlay", str(tmp_path / "out.png")],
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    (det,) = data[0]["detections"]
    assert det["ok"] and det["payload"]["bits"] == "".join(map(str, truth.payload))
    for key in ("bbox", "corners", "keypoints", "homography", "pose", "confidence", "bit_probabilities"):
        assert key in det
    assert det["morph_check"] == "passed" and det["morph_fit"] > 0 and det["pose_aligned_to"] == "decoded morph"
    assert det["pose"]["camera"]["assumed"] is False
    assert rotation_error_deg(np.array(det["pose"]["rvec"]), truth.rvec) < 2
    # image -> drawing homography takes the detected corners to the viewBox corners
    H = np.array(det["homography"])
    x, y, w, h = model.drawing.drawing.viewbox
    assert np.allclose(
        project(H, np.array(det["corners"])), [[x, y], [x + w, y], [x + w, y + h], [x, y + h]], atol=0.05
    )
    assert cv2.imread(str(tmp_path / "out.png")).shape == scene.image.shape
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(tmp_path / "street.png"), "--json"])
    assert json.loads(res.output)[0]["detections"][0]["pose"]["camera"]["assumed"] is True


def test_cli_decode_video_and_folder_fuse_frames(model: DeepMorphModel, tmp_path: Path) -> None:
    maker = SceneMaker(model, severity="medium", seed=14)
    scene = maker.make(drawings=1)
    frames = tmp_path / "frames"
    shaken_clip(scene.image, 5, np.random.default_rng(1), frames, tmp_path / "clip.mp4")  # the same print, shaken
    truth = "".join(map(str, scene.placements[0].payload))
    for target in (frames, tmp_path / "clip.mp4"):
        res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(target), "--json"])
        assert res.exit_code == 0, res.output
        (entry,) = json.loads(res.output)
        assert entry["frames"] == 5
        (det,) = entry["detections"]
        assert det["frames"] >= 4 and det["ok"] and det["payload"]["bits"] == truth
        assert det["morph_check"] == "passed"
        assert "skipped_frames" not in entry

    # a frame cut short while copying is skipped with a warning; the others still count
    whole = (frames / "f02.png").read_bytes()
    (frames / "f02.png").write_bytes(whole[: len(whole) // 3])
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(frames), "--json"])
    assert res.exit_code == 0, res.output
    (entry,) = json.loads(res.stdout)
    assert entry["frames"] == 4 and [s["frame"] for s in entry["skipped_frames"]] == ["f02.png"]
    assert entry["detections"][0]["ok"] and entry["detections"][0]["payload"]["bits"] == truth
    assert "warning: skipped frame" in res.stderr and "f02.png" in res.stderr
    # a folder of nothing but unreadable files is one clear error
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "a.png").write_bytes(whole[:100])
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(broken), "--json"])
    assert res.exit_code == 1 and "no frame could be read" in res.output and "Traceback" not in res.output


def test_cli_bad_inputs_are_one_clear_error(tmp_path: Path) -> None:
    (tmp_path / "notes.png").write_text("not an image")
    (tmp_path / "clip.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 64)
    (tmp_path / "empty").mkdir()
    cv2.imwrite(str(tmp_path / "tiny.png"), np.full((1, 1), 255, np.uint8))
    cv2.imwrite(str(tmp_path / "blank.png"), np.full((480, 640), 255, np.uint8))
    writer = cv2.VideoWriter(str(tmp_path / "tiny.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 10, (8, 8))
    for _ in range(3):
        writer.write(np.full((8, 8, 3), 200, np.uint8))
    writer.release()
    cases = [
        # checked before any work: the blank photo's result is not printed and then lost
        ([str(tmp_path / "blank.png"), str(tmp_path / "tiny.png")], "tiny.png: 1x1 pixels is too small"),
        ([str(tmp_path / "tiny.avi")], "tiny.avi: frames of 8x8 pixels are too small"),
        ([str(tmp_path / "notes.png")], "not an image"),
        ([str(tmp_path / "clip.mp4")], "not a video"),
        ([str(tmp_path / "empty")], "no image files"),
        ([str(tmp_path / "missing.jpg")], "no such image file"),
        ([str(tmp_path / "notes.png"), "--camera", "1,2,3"], "--camera"),
    ]
    for args, message in cases:
        res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), *args])
        assert res.exit_code == 1, res.output
        assert message in res.output and "Traceback" not in res.output


def test_a_corrupt_video_prints_our_error_and_nothing_of_ffmpegs(tmp_path: Path) -> None:
    # FFmpeg logs from native code, past Python's streams: only a real process shows it
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"\x00" * 64)
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    run = subprocess.run(
        [sys.executable, "-c", "from deepmorph.cli import main; main()", "decode", str(BUNDLED_MODEL), str(clip)],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert run.returncode == 1
    assert run.stdout.strip() == "" and run.stderr.strip().splitlines() == [
        f"error: {clip}: not a video OpenCV can read (corrupt, or an unsupported codec)"
    ]


def test_cli_synth_and_bench_scenes(tmp_path: Path) -> None:
    res = runner.invoke(
        app, ["synth", str(BUNDLED_MODEL), "--n", "3", "--severity", "easy", "--out", str(tmp_path / "s"), "--json"]
    )
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {
        "written": [str(tmp_path / "s")], "folder": str(tmp_path / "s"), "scenes": 3, "severity": "easy",
        "size": [640, 480], "seed": 0, "labels": str(tmp_path / "s" / "labels.csv"),
        "index": str(tmp_path / "s" / "index.json"),
    }  # fmt: skip
    index = json.loads((tmp_path / "s" / "index.json").read_text())
    assert len(index["scenes"]) == 3 and (tmp_path / "s" / "scene_00002.png").is_file()
    res = runner.invoke(app, ["bench-scenes", str(BUNDLED_MODEL), str(tmp_path / "s"), "--json"])
    assert res.exit_code == 0, res.output
    report = json.loads(res.output[res.output.index("{") :])
    assert report["scenes"] == 3 and report["drawings"] == 3
    assert report["recall"] >= 2 / 3 and report["wrong_ok"] == 0
    assert {"deepmorph", "aruco"} <= set(report["pose"]) and report["speed_ms"]["qr_detect_and_decode_median"] > 0
    assert report["first"] is False
    res = runner.invoke(app, ["bench-scenes", str(BUNDLED_MODEL), str(tmp_path / "s"), "--json", "--first"])
    first = json.loads(res.output[res.output.index("{") :])  # one print per scene: the same prints read
    assert first["first"] is True and (first["found"], first["decoded"]) == (report["found"], report["decoded"])
    res = runner.invoke(app, ["bench-scenes", str(BUNDLED_MODEL), str(tmp_path)])
    assert res.exit_code == 1 and "not a scene folder" in res.output
    # the same folder through bench-photos, by the labels.csv synth wrote beside the scenes
    res = runner.invoke(app, ["bench-photos", str(BUNDLED_MODEL), str(tmp_path / "s"), "--json"])
    assert res.exit_code == 0, res.output
    photos = json.loads(res.stdout)
    assert photos["photos"] == 3 and photos["codes"] == 3 and photos["read"] >= 2 and photos["wrong_payloads"] == 0
    assert photos["corner_error_px"]["n"] == photos["read"] and photos["corner_error_px"]["max"] < 3
    # a second set is not written over the first (it would replace some scenes, leave others
    # stale), nor into a file; the first set is left whole
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    for target, message in [(tmp_path / "s", "already holds scenes"), (BUNDLED_MODEL, "is not a folder")]:
        res = runner.invoke(app, ["synth", str(BUNDLED_MODEL), "--n", "2", "--out", str(target)])
        assert res.exit_code == 1 and message in res.output and "Traceback" not in res.output, res.output
    assert {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()} == before
    res = runner.invoke(app, ["bench-scenes", str(BUNDLED_MODEL), str(tmp_path / "s"), "--out", str(BUNDLED_MODEL)])
    assert res.exit_code == 1 and "refusing to overwrite the model file" in " ".join(res.output.split())


def test_morph_check_rates_on_a_scene_folder(model: DeepMorphModel, tmp_path: Path) -> None:
    write_scenes(model, tmp_path / "s", 6, "easy", seed=2)
    rates = morph_check_rates(model, tmp_path / "s")
    assert rates["right"]["n"] >= 5
    assert rates["right"]["rejected"] == 0 and rates["random"]["rejected"] >= rates["random"]["n"] - 1
    assert rates["right"]["gain_median"] > rates["one_bit_off"]["gain_median"] > rates["random"]["gain_median"]
    # with the per-bit check, near misses are caught too, and right payloads still pass
    assert rates["right"]["rejected_with_bits"] == 0
    assert rates["one_bit_off"]["rejected_with_bits"] >= max(rates["one_bit_off"]["rejected"], rates["right"]["n"] - 1)


def test_a_shadow_across_the_print_is_read_framed_by_the_template_or_at_the_second_look(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A shadow (penumbra 8 px) over part of a print reads as ink and drags the framing by the
    photo's ink off: the first looks fail the CRC on most such prints (two of these three).
    Framed where the alignment puts the drawing's ink, they all read; so they do at the second
    look, with the light divided out."""
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg

    payloads = random_payloads(3, model.codec.spec.payload_bits, np.random.default_rng(5))
    photos = []
    for payload in payloads:
        page = np.ones((320, 320), np.float32)
        page[64:256, 64:256] = render_svg(model.encode(payload), 192)
        page *= 1 - 0.55 / (1 + np.exp(-(np.arange(320) - 200) / 8))[None, :]
        photos.append((page * 255).astype(np.uint8))

    def reads(photo: np.ndarray, payload: np.ndarray) -> bool:
        (det,) = locator.locate(photo)
        return bool(det.result.ok and np.array_equal(det.result.payload, payload))

    assert all(reads(photo, payload) for photo, payload in zip(photos, payloads))
    monkeypatch.setattr(Reader, "read_by_synthesis", lambda self, pyramid, H, readings: readings[0])
    monkeypatch.setattr(locate_module, "whole_frame", lambda *args: [])  # nor the whole image, framed
    monkeypatch.setattr(locate_module, "whole_frame_in_flat_light", lambda gray, *args: (gray, []))
    with monkeypatch.context() as m:
        m.setattr(Reader, "read_framed_by_template", lambda self, view, soft: None)
        assert all(reads(photo, payload) for photo, payload in zip(photos, payloads))  # the second looks
        m.setattr(Reader, "read_again", lambda self, *args: [])
        m.setattr(locator.light, "align", lambda *args: None)  # nor in the light its template shows
        first_looks = [locator.locate(photo) for photo in photos]
        assert sum(d.result.ok for dets in first_looks for d in dets) <= 1
    monkeypatch.setattr(Reader, "read_again", lambda self, *args: [])
    assert all(reads(photo, payload) for photo, payload in zip(photos, payloads))  # framed by the template


@pytest.mark.parametrize("seed", [20, 5])
def test_a_print_cut_by_a_sharp_shadow_is_aligned_in_flat_light(
    model: DeepMorphModel, locator: Locator, seed: int
) -> None:
    """A shadow edge through the middle of a print (half of it 50 % darker): ECC in the photo
    bends to the edge (corners several pixels off, at a weak correlation) or diverges; with the
    light divided out around the detector's outline the print is found, read and placed."""
    scene = SceneMaker(model, severity="easy", seed=seed).make(drawings=1)
    truth = scene.placements[0]
    centre = truth.corners.mean(0)
    h, w = scene.image.shape[:2]
    y, x = np.mgrid[0:h, 0:w]
    for turn in (0.3, 1.2):
        side = (x - centre[0]) * np.cos(turn) + (y - centre[1]) * np.sin(turn)
        shade = 1 - 0.5 / (1 + np.exp(-side / 1.5))
        photo = np.clip(scene.image * shade[..., None], 0, 255).astype(np.uint8)
        gray = to_gray(photo)
        assert locator.detector.detect(gray), "the detector outlines the print"
        # the photo alone: missed, or bent to the shadow's edge
        for alignment in [
            a.alignment for a in locator.aligner.verify(ImagePyramid(gray), locator.detector.detect(gray))
        ]:
            assert alignment.correlation < WEAK_ALIGNMENT
            assert np.abs(project(alignment.homography, locator.frame_corners) - truth.corners).max() > 3.0
        (det,) = locator.locate(photo, camera=scene.camera)
        assert det.result.ok and np.array_equal(det.result.payload, truth.payload)
        assert np.abs(det.corners - truth.corners).max() < 2.0


@pytest.mark.parametrize("size", [240, 480])
def test_a_close_up_cut_by_a_sharp_shadow_is_framed_in_flat_light(model: DeepMorphModel, size: int) -> None:
    """Without a detector a close-up is framed by the ink of the whole image. A sharp shadow
    across a corner of the print (60 % darker, 1.5 px penumbra) is ink to Otsu, and ECC in the
    photo bends to its edge: the whole frame does not align in any of these photos. In flat
    light it is framed, aligned and read in every one (at 480 px the light is estimated on the
    photo shrunk to half)."""
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg

    locator = Locator(DeepMorphModel.load(BUNDLED_MODEL), detector="none")
    assert locator.detector is None
    for seed, payload in enumerate(random_payloads(3, model.codec.spec.payload_bits, np.random.default_rng(3))):
        photo = close_up_photo(render_svg(model.encode(payload), 400), "easy", np.random.default_rng(seed), size)
        h, w = photo.shape[:2]
        y, x = np.mgrid[0:h, 0:w]
        for turn in (0.5, 2.0):
            side = (x - 0.62 * w) * np.cos(turn) + (y - 0.62 * h) * np.sin(turn)
            shaded = np.clip(photo * (1 - 0.6 / (1 + np.exp(-side / 1.5)))[..., None], 0, 255).astype(np.uint8)
            gray = to_gray(shaded)
            whole = whole_frame(gray, locator.ink, locator.template, locator.frame_corners)
            assert locator.aligner.verify(ImagePyramid(gray), whole) == []
            (found,) = locator.locate(shaded)
            assert found.result.ok and np.array_equal(found.result.payload, payload), (seed, turn)


class DetectorUnread(Locator):
    """A locator whose readings from the detector's outlines fail their check, as they can on a
    close-up when the alignment from an outline takes part of the morph for the pose."""

    def decode_drawing(
        self,
        gray: np.ndarray,
        pyramid: ImagePyramid,
        alignment: Alignment,
        score: float,
        cam: Camera,
        source: str,
        soft: bool,
        blind: bool = False,
    ) -> Located:
        located = super().decode_drawing(gray, pyramid, alignment, score, cam, source, soft, blind)
        if source == "detector":
            located.result = replace(located.result, ok=False)
            located.morph_check = "failed"
        return located

    def decode_on_edges(self, gray: np.ndarray, aligned: Aligned, cam: Camera, soft: bool) -> Located | None:
        return None  # nor aligned on the print's edges


def test_a_close_up_the_detector_aligns_but_does_not_read_is_read_from_the_whole_frame(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a close-up of a drawing whose every point may move, the alignment from a detector's
    outline can absorb part of the morph into the homography, so that the morph check cannot
    confirm a right payload. A drawing the detector's outline aligns but does not read is then read from
    the whole frame too, which replaces the unread reading; one the outline reads costs no more."""
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg

    (payload,) = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(5))
    photo = close_up_photo(render_svg(model.encode(payload), 400), "medium", np.random.default_rng(5))
    framings: list[int] = []
    monkeypatch.setattr(locate_module, "whole_frame", lambda *args: framings.append(1) or whole_frame(*args))
    (read,) = Locator(model).locate(photo)
    assert read.source == "detector" and read.result.ok and np.array_equal(read.result.payload, payload)
    assert framings == []

    (found,) = DetectorUnread(model).locate(photo)
    assert framings == [1] and found.source == "whole-frame" and found.morph_check == "passed"
    assert found.result.ok and np.array_equal(found.result.payload, payload)


def test_a_large_photo_is_framed_by_its_ink_on_the_image_shrunk(model: DeepMorphModel, locator: Locator) -> None:
    """A photo wider than :data:`WHOLE_FRAME_SIDE` has its whole-frame candidate framed on the
    image shrunk to that width, mapped back pixel centre to pixel centre: where framing the full
    image puts it (within a pixel of the shrunk image), and the print filling it reads from it.
    A photo no wider is framed as it is."""
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg
    from deepmorph_detect.propose import WHOLE_FRAME_SIDE, _framed_by_ink, at_most

    (payload,) = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(9))
    photo = close_up_photo(render_svg(model.encode(payload), 1000), "easy", np.random.default_rng(9), 1400)
    gray = to_gray(photo)
    assert max(gray.shape) > WHOLE_FRAME_SIDE
    (shrunk,) = whole_frame(gray, locator.ink, locator.template, locator.frame_corners)
    (full,) = _framed_by_ink(gray, locator.ink, locator.template, locator.frame_corners)
    pixel = max(gray.shape) / WHOLE_FRAME_SIDE
    assert np.abs(shrunk.corners - full.corners).max() < pixel
    assert np.abs(np.subtract(shrunk.bbox, full.bbox)).max() <= 2 * pixel
    (found,) = DetectorUnread(model).locate(photo)  # the detector's outline not read: the whole frame is
    assert found.source == "whole-frame" and found.result.ok and np.array_equal(found.result.payload, payload)
    small, to_photo = at_most(gray[:480, :640], WHOLE_FRAME_SIDE)
    assert small.shape == (480, 640) and np.array_equal(to_photo, np.eye(3))


def test_folded_or_mirrored_outlines_are_not_prints() -> None:
    from deepmorph_detect.align import plausible_outline

    frame = np.array([[0, 0], [64, 0], [64, 64], [0, 64]], float)
    tilted = np.array([[100, 50], [300, 80], [280, 260], [90, 240]], float)
    assert plausible_outline(tilted, frame)
    assert plausible_outline(np.roll(tilted, 1, axis=0), frame)  # turned: still a print
    assert not plausible_outline(tilted[::-1], frame)  # mirrored: a print seen from behind
    folded = np.array([[407, 95], [511, 177], [522, 92], [520, 174]], float)  # ECC on clutter (hard scene 51)
    assert not plausible_outline(folded, frame)


def _loose_outlines(
    model: DeepMorphModel, locator: Locator, degrees: float, scale: float, n: int = 4
) -> Iterator[tuple[Placement, ImagePyramid, np.ndarray]]:
    """``n`` medium scenes of one print, each with its placement, photo pyramid, and a start
    homography whose outline is the print's frame turned by ``degrees`` and scaled by
    ``scale`` about its centre (a detector's loose outline)."""
    maker = SceneMaker(model, severity="medium", seed=8)
    a = np.deg2rad(degrees)
    turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * scale
    for _ in range(n):
        scene = maker.make(drawings=1)
        truth = scene.placements[0]
        centre = truth.corners.mean(0)
        start = locator.aligner.homography((truth.corners - centre) @ turn.T + centre)
        yield truth, ImagePyramid(to_gray(scene.image)), start


def test_an_outline_no_corner_order_fits_still_gets_the_wider_search(model: DeepMorphModel, locator: Locator) -> None:
    """The detector sometimes outlines only the ink, turned, at 0.6x the drawing's frame: no
    corner order of that outline correlates at all. Such a start is dropped at once when no
    bar is given (clutter costs no iterations), but a detector's candidate (``accept``) still
    gets the turned and scaled outlines, which find the print (4 of 500 medium prints were
    lost before)."""
    for truth, pyramid, start in _loose_outlines(model, locator, 40, 0.6):
        assert refine(pyramid, start, locator.template, orders=4) is None
        found = refine(pyramid, start, locator.template, orders=4, accept=locator.min_correlation)
        assert found is not None and found.correlation >= locator.min_correlation
        err = np.linalg.norm(project(found.homography, viewbox_corners(locator.viewbox)) - truth.corners, axis=1)
        assert err.mean() < 0.06 * np.linalg.norm(truth.corners[1] - truth.corners[0]), err


def test_a_loose_outline_is_found_by_the_wider_search(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The detector's outline turned by 35 degrees and 15 % too large: the quick path (best
    corner orders by plain correlation, then ECC) does not converge from it; the wider search
    (every order, then turned and scaled outlines) finds the drawing."""
    from deepmorph_detect.refine import outline_sweep

    wide = quick = 0
    for truth, pyramid, start in _loose_outlines(model, locator, 35, 1.15):

        def err(al, truth=truth) -> float:
            if al is None:
                return np.inf
            return np.linalg.norm(
                project(al.homography, viewbox_corners(locator.viewbox)) - truth.corners, axis=1
            ).mean()

        found_quick = refine(pyramid, start, locator.template, orders=4)
        found_wide = refine(pyramid, start, locator.template, orders=4, accept=locator.min_correlation)
        # the unmorphed fit absorbs some morph: on one of these prints both ECC forms stop
        # 0.049-0.050 of the side from the truth at the same correlation
        close = 0.06 * np.linalg.norm(truth.corners[1] - truth.corners[0])
        quick += err(found_quick) < close and found_quick.correlation >= locator.min_correlation
        wide += err(found_wide) < close and found_wide.correlation >= locator.min_correlation
        # the locator aligns what only a wider search reached in flat light too: it is marked
        assert found_quick is None or not found_quick.searched
        if found_quick is None or found_quick.correlation < locator.min_correlation:
            assert found_wide is None or found_wide.searched or found_wide.correlation == found_quick.correlation
    assert wide == 4 and quick <= 1, (wide, quick)
    # what the wider search finds must clear a higher bar than the quick path's, or it is not used
    import deepmorph_detect.refine as refine_module

    monkeypatch.setattr(refine_module, "WIDE_SEARCH_MARGIN", 1.0)
    unreachable = refine(pyramid, start, locator.template, orders=4, accept=locator.min_correlation)
    assert err(unreachable) == err(found_quick)
    sweep = outline_sweep(start, locator.template, turns=24, scales=(0.85, 1.0))
    assert len(sweep) == 24 * 2
    np.testing.assert_allclose(sweep[24] / sweep[24][2, 2], start / start[2, 2], atol=1e-6)  # no turn, scale 1


def test_a_morph_fit_that_loses_at_once_is_checked_again_longer(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A short ECC solve on the decoded morph can lose to the unmorphed drawing by noise; the
    longer refit of both is the verdict. When it loses too, and in a grid of light as well,
    ``ok`` is withdrawn."""
    import deepmorph_detect.check as check_module

    scene = SceneMaker(model, severity="easy", seed=12).make(drawings=1)
    truth = scene.placements[0]
    real_refine_at, real_in_light = check_module.refine_at, check_module.align_in_light_field

    def losing(pyramid, homography, template, width, iterations=5, *, always=False):
        found = real_refine_at(pyramid, homography, template, width, iterations)
        short = iterations < check_module.RECHECK_ITERATIONS
        if found is not None and template is not locator.template and (short or always):
            return replace(found, correlation=found.correlation - 0.5)  # the morph lost
        return found

    monkeypatch.setattr(check_module, "refine_at", losing)
    (det,) = [d for d in locator.locate(scene.image) if _matches(d, truth)]
    assert det.morph_check == "passed" and det.result.ok
    assert np.array_equal(det.result.payload, truth.payload)

    monkeypatch.setattr(check_module, "refine_at", lambda *a, **k: losing(*a, **k, always=True))
    (det,) = [d for d in locator.locate(scene.image) if _matches(d, truth)]
    assert det.result.ok  # the morph wins in a grid of light

    def losing_in_light(pyramid, homography, template, width):
        found = real_in_light(pyramid, homography, template, width)
        if found is not None and template is not locator.template:
            return replace(found, correlation=found.correlation - 0.5)
        return found

    monkeypatch.setattr(check_module, "align_in_light_field", losing_in_light)
    (det,) = [d for d in locator.locate(scene.image) if _matches(d, truth)]
    assert det.morph_check == "failed" and not det.result.ok


def test_a_phone_photo_is_decoded_as_it_is_shown(model: DeepMorphModel, tmp_path: Path) -> None:
    """Phones store the sensor's pixels and the turn in the EXIF orientation tag: corners,
    keypoints and the pose must come out in the frame a viewer shows (where a calibration for
    that frame applies), not the stored one."""
    from PIL import Image

    scene = SceneMaker(model, severity="easy", seed=14).make(drawings=1)
    truth = scene.placements[0]
    stored = np.rot90(scene.image, 1)  # the sensor's pixels: the scene turned a quarter left
    exif = Image.Exif()
    exif[0x0112] = 6  # "turn a quarter right to show"
    Image.fromarray(np.ascontiguousarray(stored[..., ::-1])).save(
        tmp_path / "phone.jpg", exif=exif.tobytes(), quality=95
    )
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(tmp_path / "phone.jpg"), "--json"])
    assert res.exit_code == 0, res.output
    (det,) = json.loads(res.output)[0]["detections"]
    assert det["ok"] and det["payload"]["bits"] == "".join(map(str, truth.payload))
    assert np.abs(np.array(det["corners"]) - truth.corners).max() < 2.0


def test_a_calibration_is_scaled_to_the_image_or_refused(tmp_path: Path) -> None:
    """A calibration records the image size it was made at (OpenCV writes image_width and
    image_height): a photo of the same shape at another resolution gets scaled intrinsics;
    another shape (a crop, a turned photo) or a principal point off the image is an error,
    not a silently wrong pose."""
    path = tmp_path / "calib.yaml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 960)
    fs.write("camera_matrix", np.array([[1000.0, 0, 650], [0, 1002, 470], [0, 0, 1]]))
    fs.release()
    cam = parse_camera(str(path))
    assert cam.size == (1280, 960) and cam.for_image(1280, 960) == cam
    half = cam.for_image(640, 480)
    assert (half.fx, half.fy, half.cx, half.cy, half.size) == (500, 501, 325, 235, (640, 480))
    for size in [(480, 640), (640, 400)]:
        with pytest.raises(DeepMorphError, match="calibration is for 1280x960 images"):
            cam.for_image(*size)
    with pytest.raises(DeepMorphError, match="principal point"):
        parse_camera("500,500,900,240").for_image(640, 480)

    scene = SceneMaker(DeepMorphModel.load(BUNDLED_MODEL), severity="easy", seed=14).make(drawings=1)
    photo = tmp_path / "photo.png"
    cv2.imwrite(str(photo), scene.image)  # 640x480
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(photo), "--camera", str(path), "--json"])
    assert res.exit_code == 0, res.output
    (det,) = json.loads(res.output)[0]["detections"]
    assert det["pose"]["camera"]["fx"] == 500 and det["pose"]["camera"]["image_size"] == [640, 480]
    turned = tmp_path / "turned.png"
    cv2.imwrite(str(turned), np.rot90(scene.image).copy())  # 480x640
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(photo), str(turned), "--camera", str(path)])
    text = " ".join(res.output.split())
    assert res.exit_code == 1 and "turned.png: the camera calibration is for 1280x960 images" in text, text


def _steep_print(locator: Locator, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 480x360 photo of one print seen steeply from the side (a thin parallelogram), over
    dark stripes, and the drawing frame's true corners in it."""
    from deepmorph_core.render import render_svg

    md = locator.model.drawing
    drawing = render_svg(md.to_svg(md.neutral_values()[0]), 160)
    paper = np.pad(drawing, 30, constant_values=1.0)  # white margin around the frame
    side = paper.shape[1]
    rng = np.random.default_rng(seed)
    photo = np.full((360, 480), 0.45, np.float32)
    for x in range(0, 480, 24):
        photo[:, x : x + 6] = 0.25  # dark stripes: clutter near the print
    photo = cv2.GaussianBlur(photo + rng.normal(0, 0.03, photo.shape).astype(np.float32), (3, 3), 0)
    # paper square -> a parallelogram with sides of 300 and 150 px (foreshortened by half, as
    # at 60 degrees from head-on) and sheared by 0.9 across (a steep perspective), at 35 degrees
    a = np.deg2rad(35)
    along, across = np.array([np.cos(a), np.sin(a)]), np.array([-np.sin(a), np.cos(a)])
    centre = np.array([240.0, 180.0])
    A = np.stack([along * 300 / side + across * 0.9 * 150 / side, across * 150 / side], 1)
    M = np.hstack([A, (centre - A @ np.array([side / 2, side / 2]))[:, None]])
    mask = cv2.warpAffine(np.ones_like(paper), M, (480, 360))
    seen = cv2.warpAffine(paper, M, (480, 360))
    photo = np.where(mask > 0.5, seen * 0.9 + 0.05, photo).astype(np.float32)
    frame = viewbox_corners(locator.viewbox)
    scale = 160 / locator.viewbox[2]
    corners = (np.asarray(frame) - np.array(locator.viewbox[:2])) * scale + 30
    return np.clip(photo, 0, 1), corners @ A.T + M[:, 2]


def test_an_outline_of_the_wrong_shear_is_found_from_the_prints_ink(
    locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A print seen steeply from the side, outlined by the detector as an upright square of
    the right centre and area (medium scenes: the misses left after the outline sweep): no
    turn or scale of that square fits, the starts from the print's ink moments do."""
    import deepmorph_detect.refine as refine_module
    from deepmorph_detect.inkstart import ink_starts, print_ink

    photo, truth = _steep_print(locator)
    centre, half = truth.mean(0), 0.5 * np.sqrt(cv2.contourArea(truth.astype(np.float32)))
    square = centre + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    start = locator.aligner.homography(square)
    close = 0.06 * np.linalg.norm(truth[1] - truth[0])

    def err(found) -> float:
        if found is None or found.correlation < locator.min_correlation:
            return np.inf
        return float(np.linalg.norm(project(found.homography, viewbox_corners(locator.viewbox)) - truth, axis=1).mean())

    pyramid = ImagePyramid(photo)
    found = refine(pyramid, start, locator.template, orders=4, accept=locator.min_correlation)
    assert err(found) < close, (err(found), close)
    monkeypatch.setattr(refine_module, "ink_starts", lambda *a, **k: [])
    without = refine(pyramid, start, locator.template, orders=4, accept=locator.min_correlation)
    assert err(without) > close
    # no paper, no ink: no starts
    blank = np.full((120, 160), 0.5, np.float32)
    assert print_ink(blank, square * 0.3) is None
    assert ink_starts(blank, square * 0.3, locator.template.ink_moments, 8) == []


def test_another_icon_that_barely_aligns_and_does_not_read_is_not_reported(locator: Locator) -> None:
    """A photo without the ghost: the Feather smile's face aligns to it at 0.56, just over the
    bar (1 photo in 4000 without the drawing). No payload reads there, so it is not reported:
    an unread drawing must align :data:`UNREAD_MARGIN` better."""
    from deepmorph_detect.align import MIN_CORRELATION
    from deepmorph_detect.locate import UNREAD_MARGIN

    image = cv2.imread(str(Path(__file__).parent.parent / "data" / "photos" / "smile_not_ghost.png"))
    gray = to_gray(image)
    pyramid = ImagePyramid(gray)
    assert locator.aligner.verify(pyramid, locator.detector.detect(gray), gray) == []
    # the ink of the whole photo
    aligned = [
        (a.candidate, a.alignment, a.pyramid)
        for a in locator.aligner.verify(
            pyramid, whole_frame(gray, locator.ink, locator.template, locator.frame_corners)
        )
    ]
    assert [round(a.correlation, 2) for _, a, _ in aligned] == [0.56]  # what the fixture is for
    assert MIN_CORRELATION <= aligned[0][1].correlation < MIN_CORRELATION + UNREAD_MARGIN
    assert locator.locate(image) == []


def test_qr_clock_times_qr_decoding_real_codes_frame_by_frame() -> None:
    """The speed baseline: QR's detect-and-decode on frames that hold a readable code, one call
    per tick, the frames taken in turn."""
    from deepmorph_detect.baselines import QR_TEXT, QrClock

    model = DeepMorphModel.load(BUNDLED_MODEL)
    clock = QrClock(model, (640, 480), frames=3)
    assert clock.median_ms() is None
    decoded = [cv2.QRCodeDetector().detectAndDecode(frame)[0] for frame in clock.frames]
    # at medium severity QR reads about half its frames (20 of 40 here); these hold a code
    assert decoded.count(QR_TEXT) >= 1 and all(f.shape[:2] == (480, 640) for f in clock.frames)
    seen = []
    real = clock.detector

    class Spy:
        def detectAndDecode(self, frame):  # noqa: N802 (OpenCV's name)
            seen.append(next(i for i, f in enumerate(clock.frames) if f is frame))
            return real.detectAndDecode(frame)

    clock.detector = Spy()
    clock.warm()
    for _ in range(4):
        assert clock.tick() > 0
    assert seen == [0, 0, 1, 2, 0] and len(clock.times) == 4
    assert clock.median_ms() == round(1000 * float(np.median(clock.times)), 2)


def _template_of(name: str) -> Template:
    from deepmorph_core.morphable import MorphableDrawing

    md = MorphableDrawing.load(Path(__file__).parents[1] / "data" / "feather" / f"{name}.svg", move=0.5)
    return Template.from_svg(md.to_svg(md.neutral_values()[0]), md.drawing.viewbox)


def _half_turn(viewbox: tuple[float, float, float, float]) -> np.ndarray:
    x, y, w, h = viewbox
    return np.array([[-1.0, 0.0, 2 * x + w], [0.0, -1.0, 2 * y + h], [0.0, 0.0, 1.0]])


def test_turns_that_map_a_drawing_onto_itself_are_found() -> None:
    """Feather icons: the codepen diamond looks the same half turned, the plus sign at every
    quarter turn, a battery at none."""
    turns = {name: _template_of(name).symmetric_turns for name in ("codepen", "plus", "battery-charging")}
    assert {name: len(found) for name, found in turns.items()} == {"codepen": 1, "plus": 3, "battery-charging": 0}
    np.testing.assert_allclose(turns["codepen"][0], _half_turn(_template_of("codepen").viewbox), atol=1e-9)


def test_turns_other_than_quarter_turns_that_map_a_drawing_onto_itself_are_found() -> None:
    """The codesandbox cube looks the same turned by a third, a star by a fifth, an octagon by
    an eighth (its quarter turns are the quarter turns'); a circle at every angle, so no turn of
    it can be told and none is listed. Each turn is about the ink's centre and maps the
    template onto itself."""
    templates = {name: _template_of(name) for name in ("codesandbox", "star", "octagon", "circle", "battery-charging")}
    assert {name: t.symmetric_angles for name, t in templates.items()} == {
        "codesandbox": (120.0, 240.0),
        "star": (72.0, 144.0, 216.0, 288.0),
        "octagon": (45.0, 135.0, 225.0, 315.0),
        "circle": (),
        "battery-charging": (),
    }
    assert len(templates["octagon"].symmetric_turns) == 7
    cube = templates["codesandbox"]
    finest = max(cube.images)
    to_pixels = np.linalg.inv(cube.to_svg_units(finest))
    for turn in cube.symmetric_turns:
        centre = np.append(cube.ink_moments[0], 1.0)
        np.testing.assert_allclose(turn @ centre, centre, atol=1e-9)
        in_pixels = (to_pixels @ turn @ cube.to_svg_units(finest))[:2]
        image = cube.images[finest]
        turned = cv2.warpAffine(image, in_pixels, image.shape[::-1], borderValue=1.0)
        assert correlation(cv2.GaussianBlur(image, (5, 5), 0), cv2.GaussianBlur(turned, (5, 5), 0)) > 0.9


def test_the_other_turns_of_a_frame_are_those_that_do_not_map_the_drawing_onto_itself() -> None:
    """A battery in its square frame can be aligned again at three turns, the codepen diamond at
    the two quarter turns (its half turn maps it onto itself), the plus sign at none; each turn
    is about the ink's centre, which it keeps in place."""
    templates = {name: _template_of(name) for name in ("battery-charging", "codepen", "plus")}
    assert {name: len(t.other_turns) for name, t in templates.items()} == {
        "battery-charging": 3,
        "codepen": 2,
        "plus": 0,
    }
    battery = templates["battery-charging"]
    centre = np.append(battery.ink_moments[0], 1.0)
    for turn in battery.other_turns:
        np.testing.assert_allclose(turn @ centre, centre, atol=1e-9)
    np.testing.assert_allclose(battery.other_turns[0][:2, :2], -np.eye(2), atol=1e-12)  # the half turn first


def test_a_print_aligned_at_the_wrong_turn_is_aligned_again_and_read(model: DeepMorphModel, locator: Locator) -> None:
    """The ghost aligned half turned about its ink (as a drawing that nearly looks the same turned
    can be) reads nothing there; decoding aligns it again from its other turns, where it
    correlates better, and reads its payload, with its true outline."""
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    # aligned at the wrong turn, it correlates less than at the right one
    wrong = replace(
        right, homography=right.homography @ locator.template.other_turns[0], correlation=right.correlation - 0.05
    )
    _, at_the_wrong_turn, _ = locator._read_and_check(gray, pyramid, wrong, "detector", True, False)
    assert not at_the_wrong_turn.result.ok
    read = locator.decode_drawing(gray, pyramid, wrong, 1.0, cam, "detector", True)
    assert read.result.ok and np.array_equal(read.result.payload, placed.payload)
    assert np.abs(read.corners - placed.corners).max() < 3.0


def test_a_weak_reading_of_a_symmetric_drawing_gives_way_to_a_stronger_one_at_another_turn(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Read at the wrong turn, a symmetric drawing can land on another code word with
    corrections. Such a weak reading is compared with the readings at the other turns, and the
    one with fewer corrections wins; a strong first reading is not read again."""
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    symmetric = Locator(model)
    symmetric.template.__dict__["symmetric_turns"] = (_half_turn(locator.viewbox),)
    H, strong, probs = symmetric._read_and_check(gray, pyramid, right, "detector", True, False)
    assert strong.result.ok and strong.result.corrected_bits == 0
    other_payload = 1 - strong.result.payload
    weak = replace(strong, result=replace(strong.result, payload=other_payload, corrected_bits=2, confidence=0.95))
    for first, expected_calls, expected_payload in (
        (weak, 2, strong.result.payload),
        (strong, 1, strong.result.payload),
    ):
        calls = []

        def scripted(*args: object, first: PayloadCheck = first, calls: list[int] = calls, **kwargs: object) -> tuple:
            calls.append(1)
            return (H, first if len(calls) == 1 else strong, probs)

        monkeypatch.setattr(symmetric, "_read_and_check", scripted)
        read = symmetric.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
        assert len(calls) == expected_calls
        assert read.result.ok and np.array_equal(read.result.payload, expected_payload)


def test_two_weak_readings_of_a_symmetric_drawing_at_two_turns_give_no_payload(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Read at the wrong turn, a symmetric drawing's true morph turned is a morph too, and a word
    read there with corrections can pass every check. Where the readings at two turns pass with two
    payloads and neither is strong, the photo does not say which turn is right: neither is given
    (``turn conflict``). Two weak readings of one payload are given."""
    from deepmorph_detect.locate import TURN_CONFLICT

    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    symmetric = Locator(model)
    symmetric.template.__dict__["symmetric_turns"] = (_half_turn(locator.viewbox),)
    H, strong, probs = symmetric._read_and_check(gray, pyramid, right, "detector", True, False)
    assert strong.result.ok
    weak = replace(strong, result=replace(strong.result, corrected_bits=1, confidence=0.96))
    other = replace(weak, result=replace(weak.result, payload=1 - strong.result.payload, corrected_bits=2))
    for at_the_other_turn, ok in ((other, False), (weak, True)):
        calls: list[int] = []

        def scripted(*args: object, turned: PayloadCheck = at_the_other_turn, calls: list[int] = calls, **kw: object):
            calls.append(1)
            return (H, weak if len(calls) == 1 else turned, probs)

        monkeypatch.setattr(symmetric, "_read_and_check", scripted)
        read = symmetric._decode_at(gray, pyramid, right, 1.0, cam, "detector", True, False)
        assert read.result.ok is ok and (read.morph_check == TURN_CONFLICT) is not ok
        assert np.array_equal(read.result.payload, strong.result.payload)  # the stronger, withdrawn or given


def test_a_symmetric_drawing_s_repair_is_vouched_for_only_where_no_other_turn_reads_a_word(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Read at the wrong turn, a symmetric drawing's true morph turned can read as another word
    as surely as a right one. A repair the decoder is sure of skips the per-bit check only where
    the first looks at every other turn read no word that passes the CRC; where one does, the
    repair goes bit by bit and the other turn is read too."""
    from deepmorph_detect.check import TRUSTED_REPAIR_LOG_ODDS
    from deepmorph_detect.read import Reading

    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    monkeypatch.setattr(type(model), "print_px", property(lambda self: 200))  # as if trained with --pixels 200
    for other_turn_reads, expected in ((False, [True]), (True, [False, False])):
        symmetric = Locator(model)
        symmetric.template.__dict__["symmetric_turns"] = (_half_turn(locator.viewbox),)
        real_first_looks, real_check = symmetric.reader.first_looks, symmetric.checker.check
        turns_read: list[int] = []

        def first_looks(views, soft, turns_read=turns_read, reads=other_turn_reads, real=real_first_looks):
            turns_read.append(1)
            firsts = real(views, soft)
            if len(turns_read) == 1:  # the print's own turn: its word, as a repair the decoder is sure of
                sure = {"corrected_bits": 1, "confidence": 0.99, "rival_log_odds": TRUSTED_REPAIR_LOG_ODDS + 5}
                return [replace(r, result=replace(r.result, **sure)) for r in firsts]
            other = DecodeResult(1 - placed.payload, True, 2, 0.9)
            return [Reading(other, firsts[0].probabilities)] if reads else []

        asked: list[bool] = []
        vouched: list[bool] = []

        def check(*args, asked=asked, vouched=vouched, real=real_check, **kwargs):
            asked.append(bool(kwargs["unrivalled_turn"]))
            verdict = real(*args, **kwargs)
            vouched.append(verdict.vouched)
            return verdict

        monkeypatch.setattr(symmetric.reader, "first_looks", first_looks)
        monkeypatch.setattr(symmetric.checker, "check", check)
        read = symmetric._decode_at(gray, pyramid, right, 1.0, cam, "detector", True, False)
        assert read.result.ok and np.array_equal(read.result.payload, placed.payload)
        assert asked[: len(expected)] == expected and vouched[0] is expected[0]
        assert len(asked) == 1 if expected[0] else len(asked) >= len(expected)  # vouched: nothing else asked


def test_a_weak_reading_is_compared_with_the_reading_at_another_turn_that_aligns_as_well(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A drawing that nearly looks the same half turned can align as well at the wrong turn and
    read another word there, with corrections. A weak reading is therefore compared with the
    reading at the best other turn aligning at most ``TURN_TIE_MARGIN`` worse: only a stronger
    one is asked for there, and wins. A strong reading is not read again."""
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    assert right.correlation >= locate_module.UNREAD_BLIND_CORRELATION
    turned = replace(right, homography=right.homography @ locator.template.other_turns[0])
    H, strong, probs = locator._read_and_check(gray, pyramid, right, "detector", True, False)
    assert strong.result.ok and strong.result.corrected_bits == 0
    weak = replace(strong, result=replace(strong.result, payload=1 - strong.result.payload, corrected_bits=4))
    cases = (  # first reading -> margins asked, what the other turn's reading must beat, payload read
        (weak, [locate_module.TURN_TIE_MARGIN], [weak.result], strong.result.payload),
        (strong, [], [], strong.result.payload),
    )
    for first, expected_margins, expected_bars, expected_payload in cases:
        margins: list[float] = []
        bars: list[object] = []

        def other_turn(
            pyramid: ImagePyramid, alignment: Alignment, margin: float = 0.0, margins: list[float] = margins
        ) -> Alignment:
            margins.append(margin)
            return turned

        def scripted(gray, pyramid, alignment, *args, first=first, bars=bars, **kwargs) -> tuple:
            if alignment is right:
                return (H, first, probs)
            bars.append(kwargs["stronger_than"])
            return (H, strong, probs)

        monkeypatch.setattr(locator.aligner, "other_turn", other_turn)
        monkeypatch.setattr(locator, "_read_and_check", scripted)
        read = locator.decode_drawing(gray, pyramid, right, 1.0, cam, "detector", True)
        assert margins == expected_margins and bars == expected_bars
        assert read.result.ok and np.array_equal(read.result.payload, expected_payload)


def test_a_reading_asked_to_beat_another_passes_only_when_stronger(model: DeepMorphModel, locator: Locator) -> None:
    """Read at a print's alignment and asked to beat a reading with corrections, the print's own
    reading (none) passes; asked to beat itself, nothing passes, and no payload is vouched for."""
    placed, gray, _, pyramid, right = easy_print_aligned(model, locator)
    _, strong, _ = locator._read_and_check(gray, pyramid, right, "detector", True, False)
    assert strong.result.ok and strong.result.corrected_bits == 0
    weak = replace(strong.result, corrected_bits=2)
    _, beats_weak, _ = locator._read_and_check(gray, pyramid, right, "detector", True, False, stronger_than=weak)
    assert beats_weak.result.ok and np.array_equal(beats_weak.result.payload, placed.payload)
    _, beats_itself, _ = locator._read_and_check(
        gray, pyramid, right, "detector", True, False, stronger_than=strong.result
    )
    assert not beats_itself.result.ok and beats_itself.status == "not run"


def test_a_symmetric_drawing_aligned_at_the_wrong_turn_is_read_at_the_right_one(
    model: DeepMorphModel, locator: Locator
) -> None:
    """A print of a drawing that looks the same half turned aligns as well at either turn. Read
    at the wrong one it gives no payload; read again at the turn the drawing maps onto itself by
    (the ghost is given one here), its payload and its true outline come back."""
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    assert right.correlation > 0.7
    half = _half_turn(locator.viewbox)
    wrong = replace(right, homography=right.homography @ half)
    _, as_it_was, _ = locator._read_and_check(gray, pyramid, wrong, "detector", True, False)
    assert not as_it_was.result.ok

    symmetric = Locator(model)
    symmetric.template.__dict__["symmetric_turns"] = (half,)  # as if the ghost looked the same half turned
    read = symmetric.decode_drawing(gray, pyramid, wrong, 1.0, cam, "detector", True)
    assert read.result.ok and np.array_equal(read.result.payload, placed.payload)
    assert np.abs(read.corners - placed.corners).max() < 3.0


def test_a_symmetric_drawing_is_read_by_the_first_looks_at_every_turn_before_the_later_looks_at_any(
    model: DeepMorphModel, locator: Locator
) -> None:
    """Which turn a symmetric drawing's alignment ends at is chance: aligned at the wrong one, its
    first looks there fail, and the first looks at the right turn read it before any later look
    (second looks, the last look by synthesis: 50-400 ms a turn) is tried at the wrong one."""
    placed, gray, cam, pyramid, right = easy_print_aligned(model, locator)
    half = _half_turn(locator.viewbox)
    wrong = replace(right, homography=right.homography @ half)
    symmetric = Locator(model)
    symmetric.template.__dict__["symmetric_turns"] = (half,)
    real = symmetric._read_and_check
    asked: list[tuple[bool, bool]] = []  # (at the right turn, first looks only) per call

    def recorded(gray, pyramid, alignment, *args, **kwargs) -> tuple:
        at_right = bool(np.abs(alignment.homography - right.homography).max() < 1e-6 * np.abs(right.homography).max())
        asked.append((at_right, kwargs.get("first_only", False)))
        return real(gray, pyramid, alignment, *args, **kwargs)

    symmetric._read_and_check = recorded  # type: ignore[method-assign]
    read = symmetric.decode_drawing(gray, pyramid, wrong, 1.0, cam, "detector", True)
    assert read.result.ok and np.array_equal(read.result.payload, placed.payload)
    assert asked == [(False, True), (True, True)]


def test_a_whole_frame_reading_whose_morph_fits_poorly_must_explain_the_photo(
    model: DeepMorphModel, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The whole image framed by its ink does not know the drawing: clutter there can align to a
    simple drawing at 0.6 and pass the CRC without corrections. A confident whole-frame reading
    skips the per-bit check where its morph fits at ``WHOLE_FRAME_TRUSTED_FIT`` or better; below
    it, the morph must explain the photo where its bits act (``BitEvidence.explained``)."""
    import deepmorph_detect.check as check_module
    from deepmorph_core.payload import random_payloads
    from deepmorph_core.render import render_svg
    from deepmorph_detect.synthesis import BitEvidence

    locator = Locator(model, detector="none")
    (payload,) = random_payloads(1, model.codec.spec.payload_bits, np.random.default_rng(11))
    photo = close_up_photo(render_svg(model.encode(payload), 400), "easy", np.random.default_rng(11))
    evidence = locator.checker.synthesis.evidence
    asked: list[float] = []

    def shifted(by: float) -> None:
        """The photo's evidence moved ``by`` away from every bit: 1.5 leaves the morph unexplained."""

        def evidence_of(*args: object) -> BitEvidence:
            real = evidence(*args)
            asked.append(real.deviation)
            return BitEvidence(real.code, real.evidence - by, real.fit, real.blur_px)

        monkeypatch.setattr(locator.checker.synthesis, "evidence", evidence_of)

    shifted(1.5)
    (found,) = locator.locate(photo)
    assert found.source == "whole-frame" and found.result.ok and np.array_equal(found.result.payload, payload)
    assert found.result.corrected_bits == 0 and found.result.confidence >= check_module.CHECK_BELOW_CONFIDENCE
    assert found.morph.correlation >= check_module.WHOLE_FRAME_TRUSTED_FIT and asked == [] and found.bits is None

    monkeypatch.setattr(check_module, "WHOLE_FRAME_TRUSTED_FIT", found.morph.correlation + 0.001)
    shifted(0.0)  # asked, and explained: read
    (found,) = locator.locate(photo)
    assert asked and found.result.ok and found.bits is not None and found.bits.explained
    asked.clear()
    shifted(1.5)  # asked, and not explained: no payload
    assert [d for d in locator.locate(photo) if d.result.ok] == [] and asked


def test_a_blind_proposal_aligned_poorly_gets_the_first_looks_only(
    model: DeepMorphModel, locator: Locator, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A blind proposer's drawing (the universal detector proposes every drawing) aligned below
    its bar (``BLIND_READ_CORRELATION_BW`` for a black-and-white drawing, ``BLIND_READ_CORRELATION``
    for a colour one) is read by the first looks alone: no second looks, no last look by
    synthesis. A drawing's own detector's, or a blind one aligned above the bar, gets them all."""
    from deepmorph_detect.locate import BLIND_READ_CORRELATION, BLIND_READ_CORRELATION_BW

    assert locator.blind_read_bar == BLIND_READ_CORRELATION_BW > BLIND_READ_CORRELATION  # the ghost is black

    placed, gray, _, pyramid, right = easy_print_aligned(model, locator)
    # at the wrong turn the first looks read nothing, so every later look would be tried
    wrong = replace(right, homography=right.homography @ _half_turn(locator.viewbox))
    later: list[str] = []
    for name in ("read_framed_by_template", "read_again", "read_by_synthesis"):
        real = getattr(locator.reader, name)
        monkeypatch.setattr(locator.reader, name, lambda *a, _real=real, _name=name: later.append(_name) or _real(*a))

    def looks_taken(correlation: float, blind: bool) -> list[str]:
        later.clear()
        low = replace(wrong, correlation=correlation)
        _, checked, _ = locator._read_and_check(gray, pyramid, low, "universal", True, blind)
        assert not checked.result.ok
        return list(later)

    bar = locator.blind_read_bar
    assert looks_taken(bar - 0.01, blind=True) == []
    assert "read_by_synthesis" in looks_taken(bar + 0.01, blind=True)
    assert "read_by_synthesis" in looks_taken(bar - 0.01, blind=False)
