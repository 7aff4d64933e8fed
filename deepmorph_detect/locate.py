"""From a photo to decoded drawings: detect, refine, verify, rectify, decode, pose.

:class:`Locator` runs the whole chain for one model:

1. the model's detector (:class:`CentreNetDetector`) proposes a quadrilateral per drawing;
   when it proposes none, the whole frame is tried as one candidate framed by its ink (a scan
   or a cropped photo in which the drawing fills the frame);
2. :func:`~deepmorph_detect.refine.refine` aligns each candidate to the unmorphed drawing to
   sub-pixel accuracy (around a detector outline, in flat light when a shadow defeats it);
   candidates that do not correlate with the drawing are dropped, so a photo without the
   drawing gives an empty list, not a guess;
3. the drawing is rectified (perspective removed) and decoded by the model's decoder;
4. a payload that passes the integrity check is checked once more, by synthesis: the drawing
   morphed with that payload is rendered and aligned to the photo, and must fit it better than
   the unmorphed drawing does (:meth:`Locator.fit_morph`), else its ``ok`` is withdrawn. A
   payload unrelated to the print (what a CRC collision on clutter gives) fails this almost
   always; a near miss next to the true payload fails it only sometimes. A payload read with
   corrections, or with low confidence, is then checked bit by bit
   (:mod:`deepmorph_detect.synthesis`), which catches near misses. The alignment to the
   decoded morph is also exact where the unmorphed one absorbed the morph, so the pose comes
   from it. A drawing whose readings all fail gets more
   looks: second looks, then a reading by synthesis;
5. the homography gives keypoints and, through PnP, the camera pose.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import cv2
import numpy as np
import torch

from deepmorph_core.codec import DecodeResult
from deepmorph_core.codemodel import DeepMorphModel, Detection
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fastrender import template_renderer
from deepmorph_core.imaging import (
    MIN_IMAGE_SIDE,
    align_to_frame,
    area_resize,
    flatten_illumination,
    ink_mask,
    normalise_contrast,
    to_gray,
)
from deepmorph_detect.camera import Camera, project, solve_pose, viewbox_corners, viewbox_to_frame
from deepmorph_detect.network import (
    INPUT_SIZE,
    STRIDE,
    DetectorNet,
    fused_for_inference,
    standardise,
    stored_weights,
)
from deepmorph_detect.refine import LEVELS, Alignment, ImagePyramid, Template, refine, refine_at, warp_to_template
from deepmorph_detect.runtime import decoder_graph, detector_graph, onnx_or_torch
from deepmorph_detect.synthesis import BitEvidence, MorphSynthesis, morph_template

MIN_CORRELATION = 0.55  # ECC correlation below which a candidate is not this drawing
# a drawing whose payload is not read must align this much better to be reported: no payload
# vouches for it (another icon with a face aligned at 0.56 in 1 of 4000 photos without the
# drawing; the lowest unread true print in 600 hard scenes aligned at 0.60)
UNREAD_MARGIN = 0.05
# a detector outline aligned in the photo below this is aligned in flat light too, and the better
# kept: a print cut by a sharp shadow aligned at 0.58 with its corners 7 px off, bent to the edge
WEAK_ALIGNMENT = 0.65
RECTIFY_WIDTH_FACTOR = 2  # the rectified drawing is this many decoder widths wide
MORPH_WIDTH = LEVELS[-1]  # template width of the alignment to the decoded morph
MIN_MORPH_GAIN = 0.0  # the decoded morph must correlate better than the unmorphed drawing by more
RECHECK_ITERATIONS = 20  # ECC iterations of the longer refit when the decoded morph does not win at once
TRACK_ITERATIONS = 10  # ECC iterations following a read drawing's morph from the previous frame
MORPH_CACHE = 64  # rendered morph templates kept (a video shows the same payloads again and again)
# a payload read without corrections but less confident than this is checked bit by bit too. Of
# 433 right readings without corrections in 600 hard scenes (seeds 9802/9812), 15 were below it
# (lowest 0.944) and all passed the per-bit check; the one wrong payload read without
# corrections (4 payload bits off, a CRC-8 collision) had 0.921 and 7 code bits contradicted
CHECK_BELOW_CONFIDENCE = 0.97


@dataclass
class MorphFit:
    """The photo aligned to the drawing morphed with a decoded payload.

    Attributes:
        homography: SVG units -> image pixels, aligned to the morphed drawing.
        correlation: ECC correlation with the morphed drawing.
        unmorphed_correlation: ECC correlation with the unmorphed drawing, same start and width.
    """

    homography: np.ndarray
    correlation: float
    unmorphed_correlation: float

    @classmethod
    def between(cls, plain: Alignment | None, morphed: Alignment | None) -> MorphFit | None:
        """The fit from the unmorphed and the morphed alignments (``None`` when one diverged)."""
        if plain is None or morphed is None:
            return None
        return cls(morphed.homography, morphed.correlation, plain.correlation)

    @property
    def gain(self) -> float:
        """How much better the decoded morph explains the photo than no morph at all."""
        return self.correlation - self.unmorphed_correlation

    @property
    def confirms(self) -> bool:
        """Whether the photo shows this payload's morph (the payload check by synthesis)."""
        return self.gain > MIN_MORPH_GAIN


@dataclass
class PayloadCheck:
    """The verdict of the morph check on one decoded payload.

    Attributes:
        result: the decode, with ``ok`` withdrawn when the check failed.
        fit: the alignment to the payload's morph (``None`` when not run or diverged).
        status: ``passed``, ``failed`` (the morph fits no better than the unmorphed drawing),
            ``contradicted`` (it does, but the photo does not show its code bits:
            :attr:`~deepmorph_detect.synthesis.BitEvidence.agrees` is false) or ``not run``
            (the CRC had failed).
        bits: the per-bit evidence, when it was asked for (:meth:`Locator.check_payload`).
    """

    result: DecodeResult
    fit: MorphFit | None
    status: str
    bits: BitEvidence | None = None


# x, y of the centres of a 3x3 block of heatmap cells, from its top-left cell
_CELL_CENTRES = np.stack(np.mgrid[0:3, 0:3][::-1], -1).astype(np.float64) + 0.5
_BLOCK = np.ones((3, 3), np.uint8)


class CentreNetDetector:
    """The built-in detector: :class:`~deepmorph_detect.network.DetectorNet` peaks.

    Args:
        net: trained network (eval mode).
        threshold: minimum centre probability of a peak.
        max_detections: peaks kept per image (highest first).
    """

    name: ClassVar[str] = "centrenet"

    def __init__(self, net: DetectorNet, threshold: float = 0.3, max_detections: int = 12) -> None:
        # where ONNX Runtime cannot run it: channels-last runs this small convolution stack
        # about 20 % faster on CPU, and batch norms folded into their convolutions 5 % more
        eager = fused_for_inference(net).to(memory_format=torch.channels_last)
        W, H = INPUT_SIZE
        example = torch.randn(1, 1, H, W, generator=torch.Generator().manual_seed(0))
        # ONNX Runtime where it gives the same outputs (deepmorph_detect.runtime): 0.75x the time
        self.net = onnx_or_torch(eager, lambda: detector_graph(eager, H, W), example)
        self.threshold = threshold
        self.max_detections = max_detections

    @classmethod
    def from_model(cls, model: DeepMorphModel) -> CentreNetDetector | None:
        """The detector stored in a bundle, or ``None`` when it has none."""
        if model.meta.detector is None:
            return None
        net = DetectorNet(int(model.meta.detector.config.get("width", 32)))
        net.load_state_dict(stored_weights(model.detector_state))
        return cls(net)

    def detect(self, image: np.ndarray) -> list[dict[str, Any]]:
        """Quadrilaterals (corners TL, TR, BR, BL in pixels) and scores, best first."""
        gray = to_gray(image)
        h, w = gray.shape
        W, H = INPUT_SIZE
        scale = min(W / w, H / h)
        rw, rh = max(1, round(w * scale)), max(1, round(h * scale))
        small = area_resize(gray, (rw, rh))
        small = cv2.copyMakeBorder(small, 0, H - rh, 0, W - rw, cv2.BORDER_REPLICATE)
        with torch.inference_mode():
            x = torch.from_numpy(standardise(small))[None, None].contiguous(memory_format=torch.channels_last)
            heat, corners = self.net(x)
            p_np, c_np = torch.sigmoid(heat)[0, 0].numpy(), corners[0].numpy()
        # local maxima over 3x3 cells (the border counts as lower than any cell)
        peaks = (p_np == cv2.dilate(p_np, _BLOCK)) & (p_np > self.threshold)
        ys, xs = np.nonzero(peaks)
        order = np.argsort(-p_np[ys, xs])[: self.max_detections]
        out = []
        gh, gw = p_np.shape
        for i in order:
            y, x = int(ys[i]), int(xs[i])
            y0, y1, x0, x1 = max(0, y - 1), min(gh, y + 2), max(0, x - 1), min(gw, x + 2)
            wts = p_np[y0:y1, x0:x1]
            cells = _CELL_CENTRES[: y1 - y0, : x1 - x0] + (x0, y0)  # (h, w, 2) x, y
            quads = c_np[:, y0:y1, x0:x1].transpose(1, 2, 0).reshape(-1, 4, 2) + cells.reshape(-1, 1, 2)
            ref = c_np[:, y, x].reshape(4, 2) + np.array([x + 0.5, y + 0.5])
            # neighbours may list the corners in another cyclic order: bring each to the peak's
            quads = _same_order(quads, ref)
            quad = (quads * wts.reshape(-1, 1, 1)).sum(0) / wts.sum()
            quad = quad * STRIDE / scale
            out.append({"score": float(p_np[y, x]), "corners": quad, "bbox": _bbox(quad, w, h)})
        return out


_NEXT_CORNER = np.array([1, 2, 3, 0])


def plausible_outline(quad: np.ndarray, frame: np.ndarray) -> bool:
    """Whether ``quad`` (the drawing's frame corners in the photo) can be a print seen from the
    front: convex, and turning the same way as ``frame``. ECC on clutter can converge to a
    folded (self-crossing) or mirrored outline that still correlates; no print looks like that.
    """

    def turns(q: np.ndarray) -> np.ndarray:
        edges = q[_NEXT_CORNER] - q  # np.roll(q, -1, axis=0) - q, without np.roll's overhead
        nxt = edges[_NEXT_CORNER]
        return edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0]

    want = np.sign(turns(np.asarray(frame, np.float64)))
    got = turns(np.asarray(quad, np.float64))
    return bool(np.all(np.sign(got) == want))


_ROLLS = np.array([[(i - k) % 4 for i in range(4)] for k in range(4)])  # row k: corner order rolled by k


def _same_order(quads: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Each of ``(n, 4, 2)`` quads cyclically rolled to match ``ref`` corner by corner."""
    rolled = quads[:, _ROLLS]  # (n, 4 rolls, 4 corners, 2)
    best = np.abs(rolled - ref).sum((2, 3)).argmin(1)
    return rolled[np.arange(len(quads)), best]


def _bbox(quad: np.ndarray, w: int, h: int) -> tuple[int, int, int, int]:
    x0, y0 = np.floor(quad.min(0)).astype(int)
    x1, y1 = np.ceil(quad.max(0)).astype(int)
    return int(max(0, x0)), int(max(0, y0)), int(min(w, x1)), int(min(h, y1))


@dataclass
class Located(Detection):
    """A decoded drawing with where it is: corners, homography, keypoints and pose."""

    corners: np.ndarray | None = None
    homography: np.ndarray | None = None  # SVG units -> image pixels
    correlation: float = 0.0
    score: float = 0.0
    rvec: np.ndarray | None = None
    tvec: np.ndarray | None = None
    camera: Camera | None = None
    keypoints: dict[str, list[float]] = field(default_factory=dict)
    source: str = "detector"
    morph: MorphFit | None = None
    bits: BitEvidence | None = None  # the per-bit check, when it ran (Locator.check_payload)
    # "passed", "failed" (ok withdrawn), "contradicted" (the photo does not show its code bits,
    # BitEvidence.agrees: ok withdrawn), "not run" (CRC failed); from Locator.track also
    # "tracked" (the payload its track confirmed in an earlier frame, read again from its morph)
    # and "track conflict" (another payload than the track's passed: ok withdrawn)
    morph_check: str = "not run"

    @property
    def confirmed(self) -> bool:
        """Whether the payload is read and confirmed on the print: ``ok``, and its morph check
        passed in this frame or in an earlier one of its track (what :meth:`Locator.track`
        follows)."""
        return bool(self.result.ok) and self.aligned_to_morph

    @property
    def aligned_to_morph(self) -> bool:
        """Whether the homography (and so the pose) comes from the alignment to the decoded
        payload's morph: its check passed in this frame, or it was followed on its track."""
        return self.morph_check in ("passed", "tracked")

    def to_json(self) -> dict[str, Any]:
        out = super().to_json()
        out["score"] = round(self.score, 4)
        out["alignment"] = round(self.correlation, 4)
        out["found_by"] = self.source
        out["morph_check"] = self.morph_check
        if self.morph is not None:
            out["morph_fit"] = round(self.morph.gain, 4)
        if self.bits is not None:
            out.update(self.bits.to_json())
        out["pose_aligned_to"] = "decoded morph" if self.aligned_to_morph else "unmorphed drawing"
        if self.corners is not None:
            out["corners"] = np.round(self.corners, 2).tolist()
        if self.homography is not None:
            inv = np.linalg.inv(self.homography)
            out["homography"] = (inv / inv[2, 2]).round(8).tolist()  # image -> drawing (SVG units)
        out["keypoints"] = self.keypoints
        if self.rvec is not None and self.tvec is not None and self.camera is not None:
            out["pose"] = {
                "rvec": [round(float(v), 6) for v in self.rvec],
                "tvec": [round(float(v), 6) for v in self.tvec],
                "units": "drawing widths",
                "camera": self.camera.to_json(),
            }
        return out


class Locator:
    """Finds and decodes every instance of one model's drawing in photos."""

    def __init__(self, model: DeepMorphModel, detector: Any | None = None, min_correlation: float = MIN_CORRELATION):
        self.model = model
        self.detector = detector if detector is not None else CentreNetDetector.from_model(model)
        self.min_correlation = min_correlation
        md = model.drawing
        self.viewbox = md.drawing.viewbox
        unmorphed = md.to_svg(md.neutral_values()[0])
        # Skia when it draws this drawing as resvg does: the morph check renders a morph per
        # payload read, and resvg's PNG round trip made that the slowest stage of a frame
        self.renderer_name, self.renderer = template_renderer(unmorphed, self.viewbox, LEVELS)
        self.template = Template.from_svg(unmorphed, self.viewbox, LEVELS, self.renderer)
        self.to_frame = viewbox_to_frame(self.viewbox)  # SVG units -> pose frame
        self.frame_corners = viewbox_corners(self.viewbox)
        # where the unmorphed drawing's ink lies in the finest template (whole-frame framing)
        finest = max(self.template.images)
        tys, txs = np.nonzero(self.template.images[finest] < 0.5)
        self._ink_centre = np.array([txs.mean(), tys.mean()])
        self._ink_spread = float(txs.var() + tys.var())
        self._ink_level = finest
        # the thickest ink feature, in pixels of a rectified view (for flatten_illumination)
        depth = cv2.distanceTransform((self.template.images[finest] < 0.5).astype(np.uint8), cv2.DIST_L2, 3)
        self._ink_thickness = 2.0 * float(depth.max()) * model.width * RECTIFY_WIDTH_FACTOR / finest
        self._morphed: OrderedDict[bytes, Template] = OrderedDict()
        # the decoder with its batch norms folded in: about 15 % less time in it per reading
        # and run by ONNX Runtime where it gives the same outputs: 0.6x the time again
        decoder = fused_for_inference(model.decoder)
        example = torch.rand(1, 1, *model.image_size, generator=torch.Generator().manual_seed(0))
        self._decoder = onnx_or_torch(decoder, lambda: decoder_graph(decoder), example)
        self.synthesis = MorphSynthesis(model, self.template, renderer=self.renderer)

    # -- candidates -----------------------------------------------------------------------

    def _whole_frame(self, gray: np.ndarray) -> list[dict[str, Any]]:
        """The ink of the whole image as one candidate, framed by its moments (no rotation)."""
        norm = normalise_contrast(gray)
        found = None if norm is None else ink_mask(norm)
        if found is None:
            return []
        mask, box = found
        ys, xs = np.nonzero(mask)
        if len(xs) < 10:
            return []
        s = float(np.sqrt((xs.var() + ys.var()) / max(self._ink_spread, 1e-9)))
        cx, cy = self._ink_centre
        # template px -> image px: scale s about the centroids
        T = np.array([[s, 0, xs.mean() - s * cx], [0, s, ys.mean() - s * cy], [0, 0, 1]])
        H = T @ np.linalg.inv(self.template.to_svg_units(self._ink_level))
        corners = project(H, self.frame_corners)
        return [{"score": 0.0, "corners": corners, "bbox": box, "homography": H}]

    def _homography(self, corners: np.ndarray) -> np.ndarray:
        return cv2.getPerspectiveTransform(
            self.frame_corners.astype(np.float32), np.asarray(corners, np.float32)
        ).astype(np.float64)

    # -- the decoded morph ----------------------------------------------------------------

    def morphed_template(self, payload: np.ndarray) -> Template:
        """The drawing morphed with ``payload``, rendered at :data:`MORPH_WIDTH` (cached)."""
        return self.code_template(self.model.codec.encode(np.asarray(payload, dtype=np.uint8)))

    def code_template(self, code_bits: np.ndarray) -> Template:
        """The drawing morphed by ``(N_b,)`` code bits (a code word, or a misread one), rendered
        at :data:`MORPH_WIDTH`; the last :data:`MORPH_CACHE` are kept."""
        code = np.asarray(code_bits, dtype=np.uint8)
        key = code.tobytes()
        template = self._morphed.get(key)
        if template is None:
            template = morph_template(self.model, self.viewbox, code, MORPH_WIDTH, self.renderer)
            self._morphed[key] = template
            if len(self._morphed) > MORPH_CACHE:
                self._morphed.popitem(last=False)
        self._morphed.move_to_end(key)
        return template

    def fit_morph(
        self,
        image: np.ndarray | ImagePyramid,
        homography: np.ndarray,
        payload: np.ndarray,
        unmorphed: Alignment | None = None,
    ) -> MorphFit | None:
        """Align the photo to the drawing morphed with ``payload`` and compare with the unmorphed
        drawing aligned at the same width (``unmorphed`` when it was reached at that width and
        ``homography`` is its result, else aligned here from ``homography``); ``None`` when an
        alignment diverges.

        A short ECC solve at :data:`MORPH_WIDTH` is noisy on small or blurred prints. When the
        morph does not win, both are aligned again from ``homography`` with
        :data:`RECHECK_ITERATIONS`, and that fit is the verdict. Measured on the drawings found
        in 400 scenes: right payloads rejected 4 -> 1 of 385; random payloads passed 16 -> 19
        and one-bit-off payloads 213 -> 214 (the CRC, before this check, is what stops them).
        """
        pyramid = image if isinstance(image, ImagePyramid) else ImagePyramid(to_gray(image))
        plain = unmorphed if unmorphed is not None and unmorphed.width == MORPH_WIDTH else None
        if plain is None:
            plain = refine_at(pyramid, homography, self.template, MORPH_WIDTH)
        template = self.morphed_template(payload)
        fit = MorphFit.between(plain, refine_at(pyramid, homography, template, MORPH_WIDTH))
        if fit is not None and fit.confirms:
            return fit
        recheck = MorphFit.between(
            refine_at(pyramid, homography, self.template, MORPH_WIDTH, RECHECK_ITERATIONS),
            refine_at(pyramid, homography, template, MORPH_WIDTH, RECHECK_ITERATIONS),
        )
        return fit if recheck is None else recheck

    def check_payload(
        self,
        image: np.ndarray | ImagePyramid,
        homography: np.ndarray,
        result: DecodeResult,
        unmorphed: Alignment | None = None,
        bitwise: bool | None = None,
    ) -> PayloadCheck:
        """The morph check of a decoded payload (one frame's, or one fused over frames): a
        payload that passed the CRC keeps its ``ok`` only when its morph fits the photo better
        than the unmorphed drawing (:meth:`fit_morph`); a failed CRC is not checked.

        A payload that needed corrections, or was read with a confidence below
        :data:`CHECK_BELOW_CONFIDENCE` (``bitwise`` None), or any when ``bitwise`` is True, is
        then checked bit by bit (:class:`~deepmorph_detect.synthesis.MorphSynthesis`): the
        photo must show its code bits (:attr:`~deepmorph_detect.synthesis.BitEvidence.agrees`:
        few contradicted, the weakest still supported). A CRC collision near the true payload
        differs from it in six code bits or more; one correlation over the whole drawing passes
        such near misses about half the time, the bits rarely. Confident readings without
        corrections skip it (about 50 ms): a misread that lands on a valid word without
        corrections has several bits wrong, and those pull its confidence down.
        """
        if not result.ok:
            return PayloadCheck(result, None, "not run")
        pyramid = image if isinstance(image, ImagePyramid) else ImagePyramid(to_gray(image))
        fit = self.fit_morph(pyramid, homography, result.payload, unmorphed)
        if fit is None or not fit.confirms:
            return PayloadCheck(replace(result, ok=False), fit, "failed")
        if bitwise is None:
            bitwise = result.corrected_bits > 0 or result.confidence < CHECK_BELOW_CONFIDENCE
        if not bitwise:
            return PayloadCheck(result, fit, "passed")
        code = self.model.codec.encode(np.asarray(result.payload, dtype=np.uint8))
        bits = self.synthesis.evidence(pyramid, fit.homography, code)
        if bits.agrees:
            return PayloadCheck(result, fit, "passed", bits)
        return PayloadCheck(replace(result, ok=False), fit, "contradicted", bits)

    # -- the chain ------------------------------------------------------------------------

    @staticmethod
    def _frame(image: np.ndarray, camera: Camera | None) -> tuple[np.ndarray, Camera, ImagePyramid]:
        """The photo as gray, its camera (the default one when none is given) and its pyramid."""
        gray = to_gray(image)
        h, w = gray.shape
        if min(h, w) < MIN_IMAGE_SIDE:
            raise DeepMorphError(
                f"image of {w}x{h} pixels is too small to hold a drawing (at least {MIN_IMAGE_SIDE} pixels each way)"
            )
        return gray, camera.for_image(w, h) if camera is not None else Camera.default(w, h), ImagePyramid(gray)

    def locate(self, image: np.ndarray, camera: Camera | None = None, soft: bool = True) -> list[Located]:
        """Every instance of the drawing in ``image`` (``(H, W)`` or ``(H, W, 3)``), decoded.

        A drawing whose payload is not read (``ok`` false) is reported only when it aligns at
        least :data:`UNREAD_MARGIN` above ``min_correlation``: with no payload to vouch for it,
        a weak alignment is as likely another drawing.

        Args:
            camera: intrinsics for the pose; ``None`` assumes the default field of view.
        """
        gray, cam, pyramid = self._frame(image, camera)
        candidates = self.detector.detect(gray) if self.detector is not None else []
        source = "detector"
        found = self._verify(pyramid, candidates, gray)
        if not found:
            found = self._verify(pyramid, self._whole_frame(gray))
            source = "whole-frame"
        results = []
        for cand, alignment, seen_in in found:
            located = self._decode(gray, seen_in, cand, alignment, cam, source, soft)
            if located.result.ok or alignment.correlation >= self.min_correlation + UNREAD_MARGIN:
                results.append(located)
        return results

    def track(
        self, image: np.ndarray, previous: list[Located], camera: Camera | None = None, soft: bool = True
    ) -> list[Located]:
        """The read drawings of ``previous`` (the last frame's results) followed into ``image``,
        the next frame of a video: no detector, and no second payload check. Only drawings
        whose payload is confirmed (``ok``, ``morph_check`` ``passed`` or ``tracked``) are
        followed. A drawing not found again is left out, and one that newly entered the view
        is not looked for: :class:`~deepmorph_detect.tracking.SequenceLocator` runs
        :meth:`locate` then.

        Each drawing is aligned straight to its payload's morph from its last homography
        (:data:`TRACK_ITERATIONS` of ECC at :data:`MORPH_WIDTH`). When the correlation clears
        the bar and the rectified view reads the same payload with a passing CRC, that is the
        result (``morph_check`` ``tracked``): the morph was confirmed on this print before, and
        a payload read twice is no CRC collision. Otherwise the drawing goes the whole way of
        :meth:`locate` from there, without the detector, and a payload other than the track's
        loses its ``ok`` (``morph_check`` ``track conflict``): a print does not change.

        Drawings whose payload was not read are not followed: every poor frame in which an
        unread drawing is aligned is one more chance for a wrong reading to pass CRC-8 and the
        morph check. Following them too let one wrong payload through in 120 hard frames of a
        trial; :meth:`locate` found nothing in that frame.
        """
        gray, cam, pyramid = self._frame(image, camera)
        found: list[Located] = []
        for prev in previous:
            if prev.homography is None or not prev.confirmed:
                continue
            located = self._follow(gray, pyramid, prev.homography, prev.result.payload, prev.score, cam, soft)
            if located is None or located.homography is None:
                continue
            if self._seen(located.homography, [f.homography for f in found]):
                continue  # two tracks converged on one drawing
            found.append(located)
        return found

    def _follow(
        self,
        gray: np.ndarray,
        pyramid: ImagePyramid,
        start: np.ndarray,
        confirmed: np.ndarray,
        score: float,
        cam: Camera,
        soft: bool,
    ) -> Located | None:
        """The drawing last seen at ``start`` with payload ``confirmed``, in this frame
        (:meth:`track`), or ``None``."""
        fit = refine_at(pyramid, start, self.morphed_template(confirmed), MORPH_WIDTH, TRACK_ITERATIONS)
        if self._accepts(fit):
            reading = self._read(self.rectify(pyramid, fit.homography), soft)
            if reading is not None and reading[0].ok and np.array_equal(reading[0].payload, confirmed):
                checked = PayloadCheck(reading[0], None, "tracked")
                return self._place(gray, fit.homography, checked, reading[1], fit.correlation, score, cam, "tracked")
            start = fit.homography
        alignment = refine(pyramid, start, self.template)
        if not self._accepts(alignment):
            return None
        located = self._decode(gray, pyramid, {"score": score}, alignment, cam, "tracked", soft)
        if located.result.ok and not np.array_equal(located.result.payload, confirmed):
            # a CRC collision on a poor frame; the next full search reads the drawing afresh
            located.result = replace(located.result, ok=False)
            located.morph_check = "track conflict"
        return located

    def _accepts(self, alignment: Alignment | None) -> bool:
        """Whether an alignment shows this drawing: it correlates well enough, and its outline
        can be a print (:func:`plausible_outline`)."""
        if alignment is None or alignment.correlation < self.min_correlation:
            return False
        return plausible_outline(project(alignment.homography, self.frame_corners), self.frame_corners)

    def _seen(self, H: np.ndarray, others: list[np.ndarray]) -> bool:
        """Whether the drawing at ``H`` is one already at one of ``others`` (centres closer
        than 0.3 of its diagonal)."""
        corners = project(H, self.frame_corners)
        centre, size = self._centre(H), float(np.linalg.norm(corners[2] - corners[0]))
        return any(np.linalg.norm(centre - self._centre(other)) < 0.3 * size for other in others)

    def _verify(
        self, pyramid: ImagePyramid, candidates: list[dict[str, Any]], gray: np.ndarray | None = None
    ) -> list[tuple[dict[str, Any], Alignment, ImagePyramid]]:
        """Refined, verified candidates, duplicates (same drawing twice) removed; each with the
        pyramid it was verified in (the photo, or with ``gray`` given, the photo with the light
        divided out around a detector outline that did not align in the photo itself)."""
        kept: list[tuple[dict[str, Any], Alignment, ImagePyramid]] = []
        for cand in candidates:
            H0 = cand.get("homography")
            seen_in = pyramid
            if H0 is None:  # a detector's outline: its turn and size may be off, search wider
                start = self._homography(cand["corners"])
                alignment = refine(pyramid, start, self.template, orders=4, accept=self.min_correlation)
                missed = not self._accepts(alignment)
                # a shadow edge across the print can make the alignment fail, or bend it and
                # still leave it above the bar, or leave only a wider search's start to align
                # (a tilted, blurred print reached 0.74 so and 0.87 in flat light): then it is
                # aligned in flat light too, and that one is kept when the photo's failed or
                # correlates worse
                if gray is not None and (missed or alignment.correlation < WEAK_ALIGNMENT or alignment.searched):
                    flat = self._in_flat_light(gray, cand["corners"])
                    in_flat = refine(flat, start, self.template, orders=4, accept=self.min_correlation)
                    if missed or (self._accepts(in_flat) and in_flat.correlation > alignment.correlation):
                        seen_in, alignment = flat, in_flat
            else:  # the whole frame, framed by its ink: on every photo without a detection, keep it quick
                alignment = refine(pyramid, H0, self.template)
            if not self._accepts(alignment) or self._seen(alignment.homography, [a.homography for _, a, _ in kept]):
                continue
            kept.append((cand, alignment, seen_in))
        return kept

    def _in_flat_light(self, gray: np.ndarray, corners: np.ndarray) -> ImagePyramid:
        """The photo with shadows and light gradients divided out around a detector outline.

        A shadow edge across a print is an edge the drawing does not have: ECC bends to it or
        diverges. Of 10 prints in 400 medium scenes that the detector outlined but alignment
        missed, 7 aligned once the light was divided out (``flatten_illumination``, sized to
        the thickest ink feature at the outline's scale).
        """
        quad = np.asarray(corners, dtype=np.float64)
        size = max(np.linalg.norm(quad[1] - quad[0]), np.linalg.norm(quad[2] - quad[1]), 1.0)
        h, w = gray.shape
        x0, y0 = np.clip(np.floor(quad.min(0) - 0.3 * size), 0, [w, h]).astype(int)
        x1, y1 = np.clip(np.ceil(quad.max(0) + 0.3 * size), 0, [w, h]).astype(int)
        flat = gray.copy()
        if x1 - x0 >= 16 and y1 - y0 >= 16:
            feature_px = self._ink_thickness * size / (self.model.width * RECTIFY_WIDTH_FACTOR)
            flat[y0:y1, x0:x1] = flatten_illumination(gray[y0:y1, x0:x1], max(feature_px, 1.0))
        return ImagePyramid(flat)

    def _centre(self, H: np.ndarray) -> np.ndarray:
        return project(H, self.frame_corners.mean(0, keepdims=True))[0]

    def rectify(self, pyramid: ImagePyramid, H: np.ndarray) -> np.ndarray:
        """The drawing's viewBox seen head-on, ``RECTIFY_WIDTH_FACTOR`` decoder widths wide."""
        return warp_to_template(pyramid, H, self.template, self.model.width * RECTIFY_WIDTH_FACTOR)

    def _read(self, view: np.ndarray, soft: bool) -> tuple[DecodeResult, np.ndarray] | None:
        """The payload reading of one view (framed by its ink as in training), or ``None``."""
        model = self.model
        aligned = align_to_frame(view, model.image_size, model.canonical_moments())
        if aligned is None:
            return None
        with torch.inference_mode():
            logits = self._decoder(torch.from_numpy(aligned[0])[None, None])
        probs = torch.sigmoid(logits)[0].numpy()
        return model.codec.decode(probs, soft=soft), probs

    def _looks(
        self,
        pyramid: ImagePyramid,
        H: np.ndarray,
        views: list[np.ndarray],
        readings: list[tuple[DecodeResult, np.ndarray]],
        soft: bool,
    ) -> Iterator[tuple[tuple[DecodeResult, np.ndarray], bool | None]]:
        """Readings of one drawing, each with the ``bitwise`` argument its check takes, in the
        order they are tried; the caller stops at the first payload that passes every check
        and appends each reading to ``readings`` before asking for the next.

        1. the first looks: each of ``views`` (the most confident passing reading first);
        2. second looks (:meth:`_read_again`), decoded with hard decisions;
        3. the last look by synthesis (:meth:`_read_by_synthesis`), always checked bit by bit.

        A reading that passes the CRC but not the checks does not end the search: a near miss
        caught by the per-bit check at the first look is often read right by a later one.
        """
        firsts = [r for r in (self._read(view, soft) for view in views) if r is not None]
        firsts.sort(key=lambda r: (r[0].ok, r[0].confidence), reverse=True)
        for reading in firsts:
            yield reading, None
        for reading in self._read_again(pyramid, H, views[0], firsts):
            yield reading, None
        if readings:
            yield self._read_by_synthesis(pyramid, H, readings), True

    def _read_again(
        self,
        pyramid: ImagePyramid,
        H: np.ndarray,
        view: np.ndarray,
        readings: list[tuple[DecodeResult, np.ndarray]],
    ) -> Iterator[tuple[DecodeResult, np.ndarray]]:
        """Second looks at a drawing whose first readings did not pass:

        1. the same view with shadows and light gradients divided out (a shadow edge reads as
           ink and drags the framing off);
        2. the photo aligned again to the morph that the failed reading describes (its hard
           decisions, a few of them wrong): most of its points sit where the photo's do, so the
           alignment no longer bends to absorb the morph. Then both views are read again.

        Second looks decode with hard decisions only (BCH, no soft search): every extra look is
        another chance for a garbage reading to pass the CRC, and the soft search multiplies that
        chance (``docs/codec.md``). With the soft search, one wrong payload in 300 benchmark
        scenes passed both the CRC and the morph check; without it, none did.

        Measured on 100 medium scenes with the spread-start ghost (previous detector): 94 of the
        98 drawings found were read at the first look, 97 with these.
        """
        for attempt in self._second_looks(pyramid, H, view, readings):
            reading = self._read(attempt, soft=False)
            if reading is not None:
                yield reading

    def _read_by_synthesis(
        self, pyramid: ImagePyramid, H: np.ndarray, readings: list[tuple[DecodeResult, np.ndarray]]
    ) -> tuple[DecodeResult, np.ndarray]:
        """The last look: the most confident reading's probabilities with the photo's own
        evidence on each bit (:meth:`MorphSynthesis.read`), decoded with hard decisions.

        Its payload, when one passes the CRC, is always checked bit by bit. Measured on 22
        drawings found but not read in 250 hard scenes: 11 read, none wrong; 40 read drawings
        given to it stayed right (``docs/detection.md``).
        """
        best = max(readings, key=lambda r: r[0].confidence)[1]
        probs = self.synthesis.read(pyramid, H, best)
        return self.model.codec.decode(probs, soft=False), probs

    def _second_looks(
        self, pyramid: ImagePyramid, H: np.ndarray, view: np.ndarray, readings: list[tuple[DecodeResult, np.ndarray]]
    ) -> Iterator[np.ndarray]:
        yield flatten_illumination(view, self._ink_thickness)
        if not readings:
            return
        best = max(readings, key=lambda r: r[0].confidence)[1]
        realigned = refine_at(pyramid, H, self.code_template(best > 0.5), MORPH_WIDTH)
        if realigned is None:
            return
        again = self.rectify(pyramid, realigned.homography)
        yield again
        yield flatten_illumination(again, self._ink_thickness)

    def _decode(
        self,
        gray: np.ndarray,
        pyramid: ImagePyramid,
        cand: dict[str, Any],
        alignment: Alignment,
        cam: Camera,
        source: str,
        soft: bool,
    ) -> Located:
        model = self.model
        H = alignment.homography
        views = [self.rectify(pyramid, H)]
        if source == "whole-frame":
            # A drawing that fills the frame is also read as it is, framed by its ink: a full
            # homography fitted to the unmorphed drawing can absorb part of a morph whose every
            # point moves (no fixed elements); the better-verified reading wins.
            views.append(gray)
        readings: list[tuple[DecodeResult, np.ndarray]] = []
        checked: PayloadCheck | None = None  # the verdict on the first payload that passed the CRC
        probs = np.full(model.codec.spec.code_bits, 0.5, dtype=np.float32)
        for (reading, reading_probs), bitwise in self._looks(pyramid, H, views, readings, soft):
            readings.append((reading, reading_probs))
            if not reading.ok:
                continue
            attempt = self.check_payload(pyramid, H, reading, alignment, bitwise)
            if checked is None or attempt.status == "passed":
                checked, probs = attempt, reading_probs
            if attempt.status == "passed":
                H = attempt.fit.homography
                break
        if checked is None:  # no reading passed the CRC: report the most confident one
            if readings:
                result, probs = max(readings, key=lambda r: r[0].confidence)
            else:
                result = model.codec.decode(probs, soft=soft)
            checked = PayloadCheck(result, None, "not run")
        return self._place(gray, H, checked, probs, alignment.correlation, float(cand.get("score", 0.0)), cam, source)

    def _place(
        self,
        gray: np.ndarray,
        H: np.ndarray,
        checked: PayloadCheck,
        probs: np.ndarray,
        correlation: float,
        score: float,
        cam: Camera,
        source: str,
    ) -> Located:
        """A decoded drawing at homography ``H``: its corners, keypoints and camera pose."""
        h, w = gray.shape
        corners = project(H, self.frame_corners)
        grid = np.array([[fx, fy] for fy in (0.0, 0.5, 1.0) for fx in (0.0, 0.5, 1.0)])
        x, y, vw, vh = self.viewbox
        svg_pts = np.column_stack([x + grid[:, 0] * vw, y + grid[:, 1] * vh])
        img_pts = project(H, svg_pts)
        obj = project(self.to_frame, svg_pts)
        rvec, tvec = solve_pose(cam, np.column_stack([obj, np.zeros(len(obj))]), img_pts)
        names = ("top_left", "top_right", "bottom_right", "bottom_left")
        keypoints = {n: [round(float(v), 2) for v in c] for n, c in zip(names, corners)}
        keypoints["centre"] = [round(float(v), 2) for v in project(H, np.array([[x + vw / 2, y + vh / 2]]))[0]]
        return Located(
            checked.result,
            probs,
            _bbox(corners, w, h),
            corners=corners,
            homography=H,
            correlation=correlation,
            score=score,
            rvec=rvec,
            tvec=tvec,
            camera=cam,
            keypoints=keypoints,
            source=source,
            morph=checked.fit,
            bits=checked.bits,
            morph_check=checked.status,
        )


__all__ = [
    "CHECK_BELOW_CONFIDENCE",
    "MIN_CORRELATION",
    "MIN_MORPH_GAIN",
    "TRACK_ITERATIONS",
    "UNREAD_MARGIN",
    "WEAK_ALIGNMENT",
    "CentreNetDetector",
    "Located",
    "Locator",
    "MorphFit",
    "PayloadCheck",
    "plausible_outline",
]
