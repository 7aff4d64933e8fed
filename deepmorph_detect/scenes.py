"""Synthetic photos with exact ground truth: DeepMorph's one capture simulator.

A scene is a photo of one or more printed drawings. Each drawing is a payload morph rendered by
the real renderer (resvg), printed on paper with a margin, placed in 3-D in front of a pinhole
camera (tilt up to 60 degrees, any in-plane rotation, 10-70 % of the frame width) that averages
the print over each of its pixels, composited over a real photo or procedural clutter, then
captured: lit, shadowed, blurred, noised and JPEG-compressed by the severity's capture steps
(:attr:`deepmorph_core.severity.Severity.capture`), which are the registered augmentation
plugins that training uses, applied to the whole RGB photo. Steps a model's training added to
its preset (a third-party plugin) join them. Because the pose is sampled in 3-D, the truth holds
the homography, the corners and the camera pose of every drawing exactly.

Scenes can also hold other drawings (bundled Feather icons, printed the same way), an ArUco
marker and a QR code at the same printed size: the negatives and baselines of
``deepmorph bench-scenes``. The same generator, at a smaller size, feeds detector training.

A close-up (:func:`close_up_photo`) is the same print and the same camera, framed so that the
print fills most of the photo: a scan, or a phone held close. The ranges of every severity are
:mod:`deepmorph_core.severity`'s.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
import torch

from deepmorph_core.corruption import AugmentationSpec, AugmentPipeline, added_steps, build_pipeline, capture_pipeline
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.kernels import area_resize
from deepmorph_core.luminance import LUMA_WEIGHTS, Channel, is_luma
from deepmorph_core.render import render_svg, render_svg_rgb
from deepmorph_core.severity import photo_ranges
from deepmorph_detect.backgrounds import random_background
from deepmorph_detect.camera import Camera, homography_from_pose, project, viewbox_corners, viewbox_to_frame

if TYPE_CHECKING:
    from deepmorph_core.model import DeepMorphModel

DISTRACTOR_DIR = Path(__file__).parent / "data" / "distractors"
ARUCO_DICT = cv2.aruco.DICT_6X6_250
#: A print's art (1 = white; gray ``(H, W)`` or RGB ``(H, W, 3)``) and its paper, which the
#: sheet's margin takes (gray, or RGB for RGB art; 1: white): :func:`colour_print`.
Art = tuple[np.ndarray, float | np.ndarray]


@dataclass
class Placement:
    """One printed thing in a scene and its exact truth.

    Attributes:
        kind: ``drawing`` (the model's), ``distractor`` (another drawing), ``aruco`` or ``qr``.
        rvec, tvec: camera pose of its frame (centre origin, units of its printed width).
        homography: ``(3, 3)`` map from its own coordinates (SVG user units for drawings; the
            unit square ``[0, 1]^2`` for markers) to image pixels.
        corners: ``(4, 2)`` image positions of its frame's corners (TL, TR, BR, BL).
        payload: the payload bits of a ``drawing``.
        label: the icon name, the ArUco id or the QR text.
    """

    kind: str
    rvec: np.ndarray
    tvec: np.ndarray
    homography: np.ndarray
    corners: np.ndarray
    payload: np.ndarray | None = None
    label: str = ""

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "kind": self.kind,
            "rvec": [float(v) for v in self.rvec],
            "tvec": [float(v) for v in self.tvec],
            "homography": np.asarray(self.homography).tolist(),
            "corners": np.round(self.corners, 3).tolist(),
        }
        if self.payload is not None:
            out["payload"] = "".join(str(int(b)) for b in self.payload)
        if self.label:
            out["label"] = self.label
        return out

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> Placement:
        payload = data.get("payload")
        return cls(
            data["kind"],
            np.asarray(data["rvec"], dtype=np.float64),
            np.asarray(data["tvec"], dtype=np.float64),
            np.asarray(data["homography"], dtype=np.float64),
            np.asarray(data["corners"], dtype=np.float64),
            None if payload is None else np.array([int(c) for c in payload], dtype=np.uint8),
            str(data.get("label", "")),
        )


@dataclass
class Scene:
    """A synthetic photo (``(H, W, 3)`` uint8 BGR) with its camera and placements."""

    image: np.ndarray
    camera: Camera
    placements: list[Placement] = field(default_factory=list)
    frames: list[np.ndarray] = field(default_factory=list)  # more photos of the same layout
    # per frame, image pixels of ``image`` -> that frame's pixels (the camera's shake; identity when still)
    frame_warps: list[np.ndarray] = field(default_factory=list)

    def corners_in_frame(self, placement: Placement, k: int) -> np.ndarray:
        """``(4, 2)`` corners of ``placement`` in frame ``k`` (the placements hold frame 0's)."""
        return project(self.frame_warps[k] if k < len(self.frame_warps) else np.eye(3), placement.corners)

    def truth_json(self) -> dict[str, Any]:
        h, w = self.image.shape[:2]
        return {
            "width": w,
            "height": h,
            "camera": {"fx": self.camera.fx, "fy": self.camera.fy, "cx": self.camera.cx, "cy": self.camera.cy},
            "placements": [p.to_json() for p in self.placements],
        }


@functools.lru_cache(maxsize=1)
def distractor_svgs() -> tuple[tuple[str, str], ...]:
    """The bundled Feather icons used as other drawings: ``(name, svg text)``."""
    return tuple((p.stem, p.read_text()) for p in sorted(DISTRACTOR_DIR.glob("*.svg")))


class SceneMaker:
    """Makes scenes of one model's drawing.

    Args:
        model: the trained model whose drawing is printed (payloads through its encoder).
        size: ``(width, height)`` of the photos.
        severity: ``easy``, ``medium`` or ``hard`` (:data:`deepmorph_core.severity.SEVERITIES`).
        seed: the random stream (same seed, same scenes).
        payload_pool: when set, payloads come from a fixed pool of this many random payloads
            whose renders are cached (detector training: fast); otherwise each is fresh.
        camera_width: the width of the camera's frame when the photos are that frame shrunk
            (the detector's input, say): the capture's pixel parameters shrink with it. By
            default the photos are the camera's frame (:mod:`deepmorph_core.severity`).
    """

    def __init__(
        self,
        model: DeepMorphModel,
        size: tuple[int, int] = (640, 480),
        severity: str = "medium",
        seed: int = 0,
        payload_pool: int | None = None,
        camera_width: int | None = None,
    ) -> None:
        self.model = model
        md = model.drawing
        self._set_up(size, severity, seed, camera_width, model_added_steps(model), md.colour, md.channel)
        self.viewbox = model.drawing.drawing.viewbox
        self._pool: list[np.ndarray] | None = None
        if payload_pool:
            bits = model.codec.spec.payload_bits
            self._pool = [self.rng.integers(0, 2, bits).astype(np.uint8) for _ in range(payload_pool)]
        self._svg_cache: dict[int, str] = {}

    def _set_up(
        self,
        size: tuple[int, int],
        severity: str,
        seed: int,
        camera_width: int | None,
        added: list[AugmentationSpec],
        colour: bool,
        channel: Channel = LUMA_WEIGHTS,
    ) -> None:
        """The capture, the random stream and the render cache (shared with subclasses that
        print other drawings); colour prints become the gray of ``channel``, the one the model
        reads (the simulated photo is that gray)."""
        self.severity = photo_ranges(severity)
        shrink = size[0] / camera_width if camera_width else 1.0
        self._capture = capture_pipeline(severity, shrink, added)
        self.size = size
        self.rng = np.random.default_rng(seed)
        self._render_cache: dict[tuple[str, int], np.ndarray] = {}
        # a colour drawing is printed in colour through the colour plugins of the capture
        self._colours = build_pipeline(severity, 64, colour=True, channel=channel) if colour else None

    # -- sampling ------------------------------------------------------------------------

    def camera(self) -> Camera:
        """A random phone-like camera for this scene (60-75 degrees horizontal FOV)."""
        return _camera(self.size, self.rng)

    def _pose(
        self, cam: Camera, half_extent: np.ndarray, taken: list[np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """A pose whose printed sheet (``half_extent`` in width units) lies inside the frame and
        clear of the sheets already placed; ``None`` when none is found."""
        sv = self.severity
        framing = _Framing(sv.size, sv.tilt_deg, (0.0, 2 * math.pi), (0.1, 0.9))
        return _pose(cam, self.size, half_extent, framing, self.rng, taken)

    def _next_drawing(self) -> tuple[float, float, float, float]:
        """Choose the next drawing to print (before its pose); its viewBox. Here always the
        model's; a subclass may choose among several."""
        return self.viewbox

    def _drawing_art(self, width: int) -> tuple[Art, np.ndarray | None, np.ndarray]:
        """The drawing chosen last, printed ``width`` pixels wide: its art (1 = white) and paper
        (:meth:`_render`), its payload bits, and the corners (SVG units; TL, TR, BR, BL) its truth
        names: here a fresh payload morph and its viewBox's corners."""
        idx, payload = self._payload()
        if idx >= 0 and idx not in self._svg_cache:
            self._svg_cache[idx] = self.model.encode(payload)
        svg = self._svg_cache[idx] if idx >= 0 else self.model.encode(payload)
        return self._render(f"p{idx}", svg, width, idx >= 0, colour=True), payload, viewbox_corners(self.viewbox)

    def _payload(self) -> tuple[int, np.ndarray]:
        if self._pool is not None:
            i = int(self.rng.integers(len(self._pool)))
            return i, self._pool[i]
        bits = self.model.codec.spec.payload_bits
        return -1, self.rng.integers(0, 2, bits).astype(np.uint8)

    def _render(self, key: str, svg: str, width: int, cache: bool, colour: bool = False) -> Art:
        """The print's luminance ``(H, W)`` and its paper (1: white); a colour code (``colour``,
        for a colour model) put through the colour plugins afresh each time it is printed
        (:func:`colour_print`)."""
        in_colour = colour and self._colours is not None
        if cache and (key, width) in self._render_cache:
            img = self._render_cache[(key, width)]
        else:
            img = render_svg_rgb(svg, width) if in_colour else render_svg(svg, width)
            if cache:
                self._render_cache[(key, width)] = img
        return colour_print(img, self._colours, self.rng) if in_colour else (img, 1.0)

    # -- making ---------------------------------------------------------------------------

    def make(
        self,
        drawings: int = 1,
        distractors: int = 0,
        aruco: bool = False,
        qr: str | None = None,
        frames: int = 1,
        shake_px: float = 0.0,
    ) -> Scene:
        """One scene holding ``drawings`` payload morphs, ``distractors`` other icons, and
        optionally an ArUco marker and a QR code (each at the drawing's printed size).

        With ``frames`` > 1, ``Scene.frames`` holds that many photos of the same layout, each
        with its own light, blur, noise and compression (a held phone filming a still scene).
        With ``shake_px`` > 0 the camera also moves between frames: each frame is the last one
        shifted, turned and zoomed by a random step that moves the image corners by about
        ``shake_px`` pixels (``Scene.frame_warps`` holds the motion, for the truth).
        """
        W, H = self.size
        rng = self.rng
        cam = self.camera()
        img = random_background(rng, self.size)
        taken: list[np.ndarray] = []
        placements: list[Placement] = []
        jobs: list[str] = ["drawing"] * drawings + ["distractor"] * distractors
        if aruco:
            jobs.append("aruco")
        if qr is not None:
            jobs.append("qr")
        for kind in jobs:
            margin = rng.uniform(0.08, 0.3)
            viewbox = self._next_drawing() if kind == "drawing" else self.viewbox
            _, _, vw, vh = viewbox
            aspect = vh / vw if kind in ("drawing", "distractor") else 1.0
            pose = self._pose(cam, np.array([0.5 + margin, aspect / 2 + margin]), taken)
            if pose is None:
                continue
            rvec, tvec = pose
            plane = homography_from_pose(cam, rvec, tvec)  # frame units -> pixels
            width_px = _projected_width(plane)
            rw = int(np.clip(2 ** math.ceil(math.log2(max(width_px * 1.2, 32))), 32, 1024))
            payload, label, corners_src = None, "", None
            if kind == "drawing":
                (art, paper), payload, corners_src = self._drawing_art(rw)
            elif kind == "distractor":
                icons = distractor_svgs()
                label, svg = icons[int(rng.integers(len(icons)))]
                art, paper = self._render(label, svg.replace("currentColor", "#000"), rw, True)
            else:
                (art, label), paper = _marker_art(kind, rw, rng, qr), 1.0
            ah, aw = art.shape[:2]
            # art pixels -> frame units -> image pixels
            art_to_frame = np.array([[1 / aw, 0, -0.5], [0, 1 / aw, -ah / (2 * aw)], [0, 0, 1]])
            _print_and_place(img, art, plane @ art_to_frame, margin, aw, rng, paper)
            if kind == "drawing":  # truth in SVG units (drawing -> pose frame -> pixels)
                truth = plane @ viewbox_to_frame(viewbox)
            elif kind == "distractor":  # truth in the icon's art pixels
                truth = plane @ art_to_frame
            else:  # truth on the unit square
                truth = plane @ np.array([[1.0, 0, -0.5], [0, 1.0, -0.5], [0, 0, 1]])
            if corners_src is None:
                corners_src = _frame_corners(kind, art.shape[:2])
            placements.append(Placement(kind, rvec, tvec, truth, project(truth, corners_src), payload, label))
        warps = [np.eye(3)]
        for _ in range(1, max(1, frames)):
            warps.append(_shake(rng, self.size, shake_px) @ warps[-1] if shake_px > 0 else warps[-1])
        shots = [_photograph(_moved(img, M), self._capture, rng) for M in warps]
        return Scene(shots[0], cam, placements, shots, warps)


def model_added_steps(model: DeepMorphModel) -> list[AugmentationSpec]:
    """The corruptions ``model``'s training added to its severity's preset
    (:func:`~deepmorph_core.corruption.added_steps`), for its photos' capture."""
    meta = model.meta
    return added_steps(str(meta.train.get("severity", "medium")), meta.augment, meta.image_width)


def _camera(size: tuple[int, int], rng: np.random.Generator) -> Camera:
    """A random phone-like camera (60-75 degrees horizontal field of view)."""
    W, H = size
    f = (W / 2) / math.tan(math.radians(rng.uniform(60, 75)) / 2)
    return Camera(f, f, W / 2 + rng.uniform(-0.01, 0.01) * W, H / 2 + rng.uniform(-0.01, 0.01) * H)


@dataclass(frozen=True)
class _Framing:
    """Where a print may lie in a photo: its width as a share of the frame's, its tilt (degrees,
    at most), its in-plane turn (radians) and its centre (shares of the frame)."""

    size: tuple[float, float]
    tilt_deg: float
    spin: tuple[float, float]
    centre: tuple[float, float]


def _pose(
    cam: Camera,
    size: tuple[int, int],
    half_extent: np.ndarray,
    framing: _Framing,
    rng: np.random.Generator,
    taken: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray] | None:
    """A pose (``rvec``, ``tvec``) whose printed sheet (``half_extent`` in drawing widths) lies
    inside the frame and clear of the boxes in ``taken`` (its own is added); ``None`` when none
    is found in 80 tries."""
    W, H = size
    hx, hy = half_extent
    sheet = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    for attempt in range(80):
        # crowded scenes: after every 20 failed tries, prints get smaller
        frac = rng.uniform(*framing.size) * 0.75 ** (attempt // 20)
        dist = cam.fx / (frac * W)
        tilt = math.radians(rng.uniform(0, framing.tilt_deg))
        axis = rng.uniform(0, 2 * math.pi)
        spin = rng.uniform(*framing.spin)
        R_tilt, _ = cv2.Rodrigues(np.array([math.cos(axis), math.sin(axis), 0.0]) * tilt)
        R_spin, _ = cv2.Rodrigues(np.array([0.0, 0.0, spin]))
        R = R_tilt @ R_spin
        px, py = rng.uniform(*framing.centre) * W, rng.uniform(*framing.centre) * H
        ray = np.linalg.solve(cam.matrix, np.array([px, py, 1.0]))
        tvec = ray / ray[2] * dist
        rvec, _ = cv2.Rodrigues(R)
        Hm = homography_from_pose(cam, rvec.reshape(3), tvec)
        pts = np.column_stack([sheet, np.ones(4)]) @ Hm.T
        if (pts[:, 2] <= 0).any():
            continue
        quad = pts[:, :2] / pts[:, 2:3]
        if quad[:, 0].min() < 1 or quad[:, 1].min() < 1 or quad[:, 0].max() > W - 2 or quad[:, 1].max() > H - 2:
            continue
        box = np.array([quad[:, 0].min(), quad[:, 1].min(), quad[:, 0].max(), quad[:, 1].max()])
        if any(_overlap(box, other) for other in taken):
            continue
        taken.append(box)
        return rvec.reshape(3), tvec
    return None


#: A close-up's print: the drawing 60-80 % of the frame's width, near its centre, tilted at most
#: a third as much as a scene's prints, turned at most the severity's ``spin_deg``.
CLOSE_UP_SIZE = (0.6, 0.8)
CLOSE_UP_TILT_SHARE = 1 / 3
#: White rows a colour print's paper is read from (:func:`colour_print`).
PAPER_STRIP = 2


def colour_print(rgb: np.ndarray, colours: AugmentPipeline, rng: np.random.Generator) -> Art:
    """A colour render ``(H, W, 3)`` as the camera simulation takes it: through the colour
    stage of ``colours`` (the registered ``colour`` plugins: ink, paper, white balance, chroma),
    then luminance ``(H, W)``, 1 = white. A model read in another channel
    (``colours.channel``) keeps its print in colour, ``(H, W, 3)`` RGB: its photo is taken in
    colour, the detector reads its luminance and the rest that channel, as in a real photo.
    The draws come from ``rng``.

    Also returns the paper's value after the same draws (gray, or ``(3,)`` RGB): the
    whole sheet is that paper, so the print's margin takes it (:func:`_print_and_place`). A
    sheet left white around tinted or white-balanced art shows the art's square as an edge no
    real print has, which alignment and framing then follow."""
    h = rgb.shape[0]
    # white rows below the art, whole 2x2 blocks of their own for the chroma subsampling (whose
    # upsampling blends the first of them with the art's last block)
    strip = PAPER_STRIP + h % 2
    padded = np.concatenate([rgb, np.ones((strip, *rgb.shape[1:]), rgb.dtype)], 0)
    image = torch.from_numpy(np.ascontiguousarray(padded.transpose(2, 0, 1), dtype=np.float32))[None]
    generator = torch.Generator().manual_seed(int(rng.integers(2**62)))
    with torch.no_grad():
        if not is_luma(colours.channel):
            out = colours.colour_stage(image, generator)[0].clamp(0.0, 1.0).numpy().transpose(1, 2, 0)
        else:
            out = colours.colour_only(image, generator)[0, 0].numpy()
    return np.ascontiguousarray(out[:h]), out[-1].mean(0)  # the last row's chroma is the paper's alone


def close_up_photo(
    art: np.ndarray,
    severity: str,
    rng: np.random.Generator,
    size: int = 240,
    desk: float | None = None,
    extra: list[AugmentationSpec] | None = None,
    paper: float | np.ndarray = 1.0,
) -> np.ndarray:
    """:func:`close_up_placed`'s photo alone."""
    return close_up_placed(art, severity, rng, size, desk, extra, paper)[0]


def close_up_placed(
    art: np.ndarray,
    severity: str,
    rng: np.random.Generator,
    size: int = 240,
    desk: float | None = None,
    extra: list[AugmentationSpec] | None = None,
    paper: float | np.ndarray = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """A photo in which one print fills most of the frame: a scan or a close phone photo.

    ``art`` (``(H, W)`` float, 1 = white, or ``(H, W, 3)`` RGB; a render of a code, or anything else) is printed on a
    sheet with a margin and photographed as scenes are (:class:`SceneMaker`), but near-frontal,
    filling the frame (:data:`CLOSE_UP_SIZE`), barely turned, over a plain desk. The photo is
    ``size`` pixels of the camera (blur, motion and noise in those pixels): a small ``size``
    is a print seen small, as far away. ``extra`` capture steps (:func:`model_added_steps`)
    join the severity's. ``paper``: the art's paper, the whole sheet's (:func:`colour_print`).

    Returns:
        ``(size, size, 3)`` uint8 BGR photo, and the ``(3, 3)`` homography from ``art``'s pixels
        to the photo's (where the print truly lies, for measuring an alignment).
    """
    sv = photo_ranges(severity)
    frame = (size, size)
    cam = _camera(frame, rng)
    ah, aw = art.shape[:2]
    margin = rng.uniform(0.08, 0.15)
    spin = math.radians(sv.spin_deg)
    framing = _Framing(CLOSE_UP_SIZE, sv.tilt_deg * CLOSE_UP_TILT_SHARE, (-spin, spin), (0.47, 0.53))
    pose = _pose(cam, frame, np.array([0.5 + margin, ah / (2 * aw) + margin]), framing, rng, [])
    if pose is None:  # pragma: no cover - a frontal print of 60-80 % always fits after a few tries
        raise DeepMorphError("no close-up pose fits the frame")
    plane = homography_from_pose(cam, *pose)
    tone = rng.uniform(0.55, 0.8) if desk is None else desk  # a desk darker than the paper
    img = np.full((size, size, 3), tone, np.float32)
    art_to_frame = np.array([[1 / aw, 0, -0.5], [0, 1 / aw, -ah / (2 * aw)], [0, 0, 1]])
    art_to_image = plane @ art_to_frame
    _print_and_place(img, np.asarray(art, np.float32), art_to_image, margin, aw, rng, paper)
    capture = capture_pipeline(severity, 1.0, extra) if extra else _plain_capture(severity)
    return _photograph(img, capture, rng), art_to_image


@functools.lru_cache(maxsize=8)
def _plain_capture(severity: str) -> AugmentPipeline:
    """The severity's own capture (built once: close-ups come in thousands)."""
    return capture_pipeline(severity)


def _shake(rng: np.random.Generator, size: tuple[int, int], px: float) -> np.ndarray:
    """One random step of a hand-held camera: a shift, turn and zoom about the image centre
    that moves the corners by about ``px`` pixels."""
    W, H = size
    reach = 0.5 * math.hypot(W, H)
    angle = rng.normal(0, 0.5 * px / reach)
    zoom = 1.0 + rng.normal(0, 0.5 * px / reach)
    tx, ty = rng.normal(0, px / math.sqrt(2), 2)
    c, s = zoom * math.cos(angle), zoom * math.sin(angle)
    cx, cy = W / 2, H / 2
    return np.array([[c, -s, cx - c * cx + s * cy + tx], [s, c, cy - s * cx - c * cy + ty], [0, 0, 1]])


def _moved(img: np.ndarray, M: np.ndarray) -> np.ndarray:
    if np.allclose(M, np.eye(3)):
        return img
    h, w = img.shape[:2]
    return cv2.warpPerspective(img, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def _frame_corners(kind: str, art_shape: tuple[int, int]) -> np.ndarray:
    if kind == "distractor":
        h, w = art_shape
        return viewbox_corners((0, 0, w, h))
    return viewbox_corners((0, 0, 1, 1))


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    return not (a[2] < b[0] or b[2] < a[0] or a[3] < b[1] or b[3] < a[1])


def _projected_width(plane: np.ndarray) -> float:
    pts = np.array([[-0.5, 0, 1], [0.5, 0, 1], [0, -0.5, 1], [0, 0.5, 1]]) @ plane.T
    xy = pts[:, :2] / pts[:, 2:3]
    return float(max(np.linalg.norm(xy[1] - xy[0]), np.linalg.norm(xy[3] - xy[2])))


def _marker_art(kind: str, width: int, rng: np.random.Generator, qr: str | None) -> tuple[np.ndarray, str]:
    """An ArUco marker (DICT_6X6_250) or a QR code filling a ``width`` square, 1 = white."""
    if kind == "aruco":
        marker_id = int(rng.integers(250))
        dictionary = cv2.aruco.getPredefinedDictionary(ARUCO_DICT)
        img = cv2.aruco.generateImageMarker(dictionary, marker_id, 8 * 16)
        return cv2.resize(img, (width, width), interpolation=cv2.INTER_NEAREST).astype(np.float32) / 255, str(marker_id)
    code = cv2.QRCodeEncoder.create().encode(qr or "DEEPMORPH")
    # the encoder adds a quiet zone of modules; the frame is the code's own square
    ys, xs = np.nonzero(code < 128)
    code = code[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    return cv2.resize(code, (width, width), interpolation=cv2.INTER_NEAREST).astype(np.float32) / 255, qr or "DEEPMORPH"


def _print_and_place(
    img: np.ndarray,
    art: np.ndarray,
    art_to_image: np.ndarray,
    margin: float,
    art_width: int,
    rng: np.random.Generator,
    paper: float | np.ndarray = 1.0,
) -> None:
    """Print ``art`` (1 = white; gray ``(h, w)`` or RGB ``(h, w, 3)``) on a sheet with
    ``margin`` (share of the art width) and composite the sheet into ``img`` (BGR) through
    ``art_to_image``. ``paper``: the art's paper (gray, or RGB for RGB art), which the margin
    takes too (:func:`colour_print`)."""
    H, W = img.shape[:2]
    m = int(round(margin * art_width))
    ah, aw = art.shape[:2]
    paper_tone = rng.uniform(0.85, 1.0) * rng.uniform(0.94, 1.0, 3).astype(np.float32)
    ink_tone = rng.uniform(0.0, 0.15)
    bgr = art.ndim == 3  # RGB art into the BGR photo
    sheet = np.empty((ah + 2 * m, aw + 2 * m) + art.shape[2:], np.float32)
    sheet[...] = np.broadcast_to(np.asarray(paper, np.float32), (3,))[::-1] if bgr else paper
    sheet[m : m + ah, m : m + aw] = art[..., ::-1] if bgr else art
    shift = np.array([[1, 0, -m], [0, 1, -m], [0, 0, 1]], dtype=np.float64)  # sheet px -> art px
    # the tones are affine in the sheet's value, so averaging before tinting is the same
    sheet, M = _captured_scale(sheet, art_to_image @ shift)
    toned = ink_tone + (1 - ink_tone) * sheet
    sheet_rgb = (toned if toned.ndim == 3 else toned[..., None]) * paper_tone[None, None, :]
    warped = cv2.warpPerspective(sheet_rgb, M, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
    mask = cv2.warpPerspective(np.ones(sheet.shape[:2], np.float32), M, (W, H), flags=cv2.INTER_LINEAR)
    img *= 1 - mask[..., None]
    img += warped * mask[..., None]


def _captured_scale(sheet: np.ndarray, sheet_to_image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sheet area-averaged to about the size it has in the photo, and its map to the photo.

    A camera pixel integrates the light that falls on it; a bilinear warp from a much finer
    sheet only samples it, and the edges it leaves jump with the sampling phase by up to a
    fraction of a pixel, which is what morphs are made of. Averaged first to its mean scale in
    the photo (the square root of the area ratio; one scale for the whole sheet, so a steeply
    tilted print's far side is still sampled at up to about twice), the sheet is warped at about
    one sheet pixel per photo pixel.

    Args:
        sheet: ``(h, w)`` or ``(h, w, 3)`` float32 image.
        sheet_to_image: ``(3, 3)`` homography from sheet pixels to photo pixels.

    Returns:
        The sheet, averaged when it is larger in pixels than its image in the photo, and the
        homography from its pixels to the photo's.
    """
    h, w = sheet.shape[:2]
    quad = project(sheet_to_image, np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64))
    scale = math.sqrt(cv2.contourArea(quad.astype(np.float32)) / (w * h))
    if scale >= 1.0:
        return sheet, sheet_to_image
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    small = area_resize(sheet, size)
    fx, fy = w / size[0], h / size[1]
    # a pixel centre of the small sheet sits at (x + 0.5) * f - 0.5 in sheet pixels
    small_to_sheet = np.array([[fx, 0, 0.5 * fx - 0.5], [0, fy, 0.5 * fy - 0.5], [0, 0, 1]], dtype=np.float64)
    return small, sheet_to_image @ small_to_sheet


def _photograph(img: np.ndarray, capture: AugmentPipeline, rng: np.random.Generator) -> np.ndarray:
    """The camera's capture steps (:meth:`AugmentPipeline.capture`: light, shadow, contrast,
    blur, motion, noise, JPEG) on a float BGR photo, drawn from ``rng``; uint8 BGR out."""
    rgb = torch.from_numpy(np.ascontiguousarray(img[..., ::-1].transpose(2, 0, 1), dtype=np.float32))[None]
    generator = torch.Generator().manual_seed(int(rng.integers(2**62)))
    with torch.no_grad():
        out = capture.capture(rgb, generator)[0].numpy()
    return np.ascontiguousarray(np.rint(out[::-1].transpose(1, 2, 0) * 255.0)).astype(np.uint8)


__all__ = [
    "CLOSE_UP_SIZE",
    "PAPER_STRIP",
    "Art",
    "Placement",
    "Scene",
    "SceneMaker",
    "close_up_photo",
    "close_up_placed",
    "colour_print",
    "distractor_svgs",
    "model_added_steps",
]
