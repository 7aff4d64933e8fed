"""Sub-pixel alignment of a detected drawing, and its verification.

The detector's quadrilateral is good to a few pixels. Refinement aligns the photo to the
unmorphed drawing itself by ECC (enhanced correlation coefficient) maximisation over a full
homography, coarse to fine: OpenCV's solver from the detector's rough outline, then our
inverse-compositional one (:mod:`~deepmorph_detect.icalign`) for the finer solves. Every ink
pixel of the drawing acts as a keypoint, so no point has to be singled out, and the
correlation it reaches doubles as a check that the thing found really is this drawing
(another icon, a marker or clutter does not correlate).
A morph moves points by at most a few percent, so the unmorphed drawing is a faithful enough
template to find, verify and decode the drawing. It is not faithful enough for the pose: the
alignment absorbs part of the morph (about 2 px of corner error). Once the payload is read, the
locator aligns the photo once more, to the drawing morphed with that payload
(:func:`refine_at` with a template of the decoded morph), which brings the corners to a
fraction of a pixel.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.fastrender import Renderer, render_svg_resvg
from deepmorph_detect.icalign import InverseECC, inverse3
from deepmorph_detect.inkstart import ink_starts, point_moments

LEVELS = (48, 128)  # template widths, coarse to fine
COARSE_ITERATIONS = 15  # ECC iterations at the coarsest level (from the detector's rough outline)
FINE_ITERATIONS = 4  # at each finer level: 6 give the same payloads and corners at 1.1x the time
REFIT_ITERATIONS = 4  # refine_at: one level, from an alignment that is already close
AFFINE_ITERATIONS = (15, 10)  # refine_affine's ECC iterations at each level, coarse to fine
ECC_EPS = 1e-5  # ECC stops early when the correlation gains less than this in one iteration
ORDER_MARGIN = 0.15  # a corner order this far behind the best in plain correlation is not tried
SWEEP_TURNS = 24  # outline_sweep: turns of the detector's outline in 15-degree steps ...
# ... each at these scales: the detector outlines some prints (cut by a shadow) at about 0.6x
# their size, so most scales enlarge the outline
SWEEP_SCALES = (0.85, 1.0, 1.15, 1.35, 1.6, 1.85)
SWEEP_TRIES = 3  # starts of the sweep carried through ECC (the best by plain correlation)
#: an ink square's sweep (``refine(sized=True)``): its four corner orders at these scales. Prints
#: tilted 45-60 degrees, 200-300 px wide in 1280x720 scenes, were outlined at 0.75-0.9 of their
#: size, where ECC diverged from every corner order; enlarged, 4 of 6 aligned
SIZED_SWEEP_SCALES = (1.15, 1.3)
#: a colour drawing's ink square (``refine(sized=True, shifted=True)``), where nothing else aligned,
#: is swept at these scales with its centre moved by each pair of these shares of its size: the
#: universal detector squares a colour print's darkest part (a dark badge beside a pale outline),
#: a quarter of its size off its centre (``bench/README.md``, *Finding colour prints*)
SHIFTED_SWEEP_SCALES = (1.15, 1.3, 1.6)
SHIFTED_SWEEP_SHIFTS = (-0.25, 0.0, 0.25)
WIDE_SEARCH_MARGIN = 0.05  # what the wider searches find must beat ``accept`` by this much
#: a wider search's coarse solve below this is not carried through the finer levels, where it
#: cannot reach what a wider search must (``accept`` plus the margin, 0.6 for a detector's
#: outline): over 1,200 medium and hard 1280x720 scenes of six drawings, of the 407 solves on
#: prints carried none from below 0.5 reached more than 0.56, and 5 of the 4,400 on other drawings
#: 0.6-0.66; nine in ten solves carried were other drawings'
WIDE_CARRY_FROM = 0.5
# a coarse solve by inverse composition that reaches this correlation is kept; below it, OpenCV's
# wider-basin solve runs from the same start (:func:`_coarse_steps`)
COARSE_FAST_BAR = 0.7
#: A turn of the unmorphed drawing whose render correlates with the render this well maps the
#: drawing onto itself (:attr:`Template.symmetric_turns`): 79 of the 287 Feather icons reach it
SYMMETRY_CORRELATION = 0.9
#: Turns other than quarter turns (:attr:`Template.symmetric_turns`: a triangle's thirds, a star's
#: fifths, an octagon's eighths) are found by turning the coarsest level about the ink's centre in
#: steps of this many degrees, each peak that correlates at least ``SYMMETRY_SCAN_BAR`` refined at
#: the finest level in steps of 0.2 degrees; angles within ``QUARTER_CLEARANCE`` degrees of a
#: quarter turn are the quarter turns' own
SYMMETRY_SCAN_STEP, SYMMETRY_SCAN_BAR, QUARTER_CLEARANCE = 2.0, 0.8, 8.0
#: A drawing that maps onto itself at more turns than this (a circle, a target: at every angle)
#: has no turn a print could tell; only its quarter turns are kept
MAX_SYMMETRIC_TURNS = 11
#: ... and so has one that maps onto itself at each of these turns (no polygon of up to 11 sides does)
ROUND_CHECK_ANGLES = (13.0, 29.0, 47.0, 71.0, 103.0, 157.0, 199.0)


@dataclass
class Template:
    """The unmorphed drawing rendered at each refinement level.

    Attributes:
        viewbox: ``(x, y, w, h)`` of the drawing in SVG units.
        images: template width -> ``(h, w)`` float32 render (1 = white).
    """

    viewbox: tuple[float, float, float, float]
    images: dict[int, np.ndarray]
    _solvers: dict[tuple[int, int], InverseECC] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_svg(
        cls,
        svg: str,
        viewbox: tuple[float, float, float, float],
        levels: tuple[int, ...] = LEVELS,
        renderer: Renderer = render_svg_resvg,
    ) -> Template:
        """``svg`` rendered at each width in ``levels`` by ``renderer`` (resvg unless given;
        :func:`~deepmorph_detect.fastrender.template_renderer` picks one for a drawing)."""
        return cls(viewbox, {w: renderer(svg, w, viewbox) for w in levels})

    @functools.cached_property
    def symmetric_turns(self) -> tuple[np.ndarray, ...]:
        """The turns that map the unmorphed drawing onto itself, as ``(3, 3)`` SVG -> SVG
        matrices: its render turned correlates with itself at least
        :data:`SYMMETRY_CORRELATION`. A print of such a drawing (a hexagon, a star) aligns
        as well at each of these turns; only its morph, so only its reading, tells them apart.
        They are the quarter turns about the frame's centre (90, 180 and 270 degrees; 90 and 270
        only in a square frame), then any other turns about the ink's centre
        (:attr:`symmetric_angles`: the codesandbox cube's thirds, whose prints seen steeply from
        the side aligned at the wrong third at 0.93-0.97 and read nothing there).
        The set is closed under inverses, so the direction each is taken in does not matter."""
        x, y, w, h = self.viewbox
        cx, cy = self.ink_moments[0]
        quarters = tuple(quarter_turn(k, x + w / 2, y + h / 2) for k in self._symmetric_quarters)
        return quarters + tuple(turn_about(angle, cx, cy) for angle in self.symmetric_angles)

    @functools.cached_property
    def symmetric_angles(self) -> tuple[float, ...]:
        """The turns (degrees, counter-clockwise as seen) other than quarter turns about which the
        drawing, turned about its ink's centre, correlates with itself at least
        :data:`SYMMETRY_CORRELATION`: scanned at the coarsest level (:data:`SYMMETRY_SCAN_STEP`),
        refined at the finest. None for a round drawing, which does so at every turn
        (:data:`ROUND_CHECK_ANGLES`) or at more than :data:`MAX_SYMMETRIC_TURNS`: a circle has no
        turn to tell apart."""
        coarse, finest = self._turned_correlation(min(self.images)), self._turned_correlation(max(self.images))
        if all(finest(a) >= SYMMETRY_CORRELATION for a in ROUND_CHECK_ANGLES):
            return ()
        angles = np.arange(SYMMETRY_SCAN_STEP, 360.0, SYMMETRY_SCAN_STEP)
        scores = np.array([coarse(float(a)) for a in angles])
        padded = np.concatenate([[-1.0], scores, [-1.0]])
        found: list[float] = []
        for i in np.nonzero(scores >= SYMMETRY_SCAN_BAR)[0]:
            if not padded[i] <= scores[i] >= padded[i + 2]:
                continue
            fine = np.arange(angles[i] - SYMMETRY_SCAN_STEP, angles[i] + SYMMETRY_SCAN_STEP + 1e-9, 0.2)
            refined = [(finest(float(a)), round(float(a), 1)) for a in fine]
            rho, angle = max(refined)
            if rho >= SYMMETRY_CORRELATION and all(abs(angle - other) > SYMMETRY_SCAN_STEP for other in found):
                found.append(angle)
        if len(found) > MAX_SYMMETRIC_TURNS:
            return ()
        return tuple(a for a in found if abs((a + 45.0) % 90.0 - 45.0) > QUARTER_CLEARANCE)

    def _turned_correlation(self, width: int) -> Callable[[float], float]:
        """How well the level at ``width``, turned by a number of degrees about the ink's centre,
        correlates with itself (both blurred as candidates are): the level, its blur and its ink's
        centre taken once for every turn asked."""
        image = self.images[width]
        reference = cv2.GaussianBlur(image, (5, 5), 0)
        cx, cy = project(np.linalg.inv(self.to_svg_units(width)), self.ink_moments[0][None])[0]

        def at(degrees: float) -> float:
            matrix = cv2.getRotationMatrix2D((float(cx), float(cy)), degrees, 1.0)
            turned = cv2.warpAffine(image, matrix, image.shape[::-1], flags=cv2.INTER_LINEAR, borderValue=1.0)
            return correlation(reference, cv2.GaussianBlur(turned, (5, 5), 0))

        return at

    @functools.cached_property
    def other_turns(self) -> tuple[np.ndarray, ...]:
        """The turns within the frame (half first, then the quarters in a square frame) that are
        not :attr:`symmetric_turns`, about the ink's centre, as ``(3, 3)`` SVG -> SVG matrices.

        A drawing that nearly maps onto itself turned (a battery: its body and bolt do, its
        small terminal does not) can align to a print at the wrong turn, shifted by however far
        its ink sits from the frame's centre, well enough to pass as found; its reading then
        fails. Aligned again from each of these turns, the print is found at the right one."""
        cx, cy = self.ink_moments[0]
        return tuple(quarter_turn(k, cx, cy) for k in self._turnable_quarters if k not in self._symmetric_quarters)

    @property
    def _turnable_quarters(self) -> tuple[int, ...]:
        """The quarter turns (1-3) that keep the frame's outline: all three in a square frame,
        the half turn alone otherwise."""
        image = self.images[max(self.images)]
        return (2, 1, 3) if image.shape[0] == image.shape[1] else (2,)

    @functools.cached_property
    def _symmetric_quarters(self) -> tuple[int, ...]:
        """The quarter turns (1-3) of :attr:`symmetric_turns`."""
        image = self.images[max(self.images)]
        return tuple(
            k for k in sorted(self._turnable_quarters) if correlation(image, np.rot90(image, k)) >= SYMMETRY_CORRELATION
        )

    @functools.cached_property
    def coarse_blurred(self) -> np.ndarray:
        """The coarsest level, blurred as candidates are before their corner order is scored."""
        return cv2.GaussianBlur(self.images[min(self.images)], (5, 5), 0)

    @functools.cached_property
    def ink_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``(2,)`` and covariance ``(2, 2)`` of the drawing's ink in SVG units (finest level)."""
        finest = max(self.images)
        ys, xs = np.nonzero(self.images[finest] < 0.5)
        points = np.stack([xs, ys, np.ones_like(xs)], 0).astype(np.float64)
        moments = point_moments((self.to_svg_units(finest) @ points)[:2].T, min_points=2)
        if moments is None:  # a drawing of a single ink pixel: no spread to match
            return np.asarray(self.viewbox[:2], np.float64), np.eye(2)
        return moments

    def solver(self, width: int, smooth: int) -> InverseECC:
        """The inverse-compositional ECC solver for the level at ``width`` (made once)."""
        key = (width, smooth)
        if key not in self._solvers:
            self._solvers[key] = InverseECC(self.images[width], smooth)
        return self._solvers[key]

    def shape(self, width: int) -> tuple[int, int]:
        """``(h, w)`` of the drawing's viewBox at ``width`` pixels."""
        _, _, vw, vh = self.viewbox
        return max(1, round(width * vh / vw)), width

    def to_svg_units(self, width: int) -> np.ndarray:
        """``(3, 3)`` map from template pixels (at ``width``) to SVG units."""
        return pixels_to_svg_units(self.viewbox, width)


def pixels_to_svg_units(viewbox: tuple[float, float, float, float], width: int) -> np.ndarray:
    """``(3, 3)`` map from the pixels of the viewBox rendered ``width`` pixels wide (a template
    level, a render of the drawing) to SVG units."""
    x, y, vw, _ = viewbox
    s = vw / width
    return np.array([[s, 0, x], [0, s, y], [0, 0, 1]], dtype=np.float64)


@dataclass
class Alignment:
    """A refined homography (SVG units -> image pixels), the correlation it reached, and the
    template width it was reached at; ``searched`` when :func:`refine`'s wider searches reached
    it (the outline it started from did not align as it was)."""

    homography: np.ndarray
    correlation: float
    width: int = 0
    searched: bool = False


class ImagePyramid:
    """Halvings of a grayscale photo, made on demand, so warps never alias."""

    def __init__(self, gray: np.ndarray) -> None:
        self.levels = [np.ascontiguousarray(gray, dtype=np.float32)]

    def at_most(self, factor: float) -> tuple[np.ndarray, float]:
        """The level whose downscaling leaves at most a 2x shrink to the warp; and its scale."""
        k = 0
        while factor / (2 ** (k + 1)) >= 1.5 and min(self.levels[-1].shape) > 16:
            k += 1
            if len(self.levels) <= k:
                self.levels.append(cv2.pyrDown(self.levels[-1]))
        return self.levels[k], 0.5**k


def warp_to_template(pyramid: ImagePyramid, homography: np.ndarray, template: Template, width: int) -> np.ndarray:
    """The photo resampled into the template's frame at ``width`` through ``homography``."""
    th, tw = template.shape(width)
    M = homography @ template.to_svg_units(width)  # template px -> image px
    corners = np.array([[0, 0, 1], [tw, 0, 1], [tw, th, 1], [0, th, 1]], dtype=np.float64) @ M.T
    xy = corners[:, :2] / corners[:, 2:3]
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = xy.tolist()
    span = max(math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x3, y2 - y3), 1e-6)
    img, scale = pyramid.at_most(span / tw)
    S = np.diag([scale, scale, 1.0])
    return cv2.warpPerspective(
        img, S @ M, (tw, th), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE
    )


def _ecc_step(
    pyramid: ImagePyramid,
    H: np.ndarray,
    template: Template,
    width: int,
    iterations: int,
    smooth: int,
    crop: np.ndarray | None = None,
    wide_basin: bool = False,
    affine: bool = False,
) -> tuple[np.ndarray, float] | None:
    """One ECC solve at one template width: the improved homography and its correlation
    (``crop``: the photo already warped through ``H`` at ``width``, when the caller has it).

    Solves start close and take the inverse-compositional form
    (:mod:`~deepmorph_detect.icalign`), about 3x faster, unless ``wide_basin``: then OpenCV's
    forward-additive ECC, whose basin is wider (the coarsest level, from a detector's rough
    outline). ``affine``: OpenCV's, solving an affine correction only (:func:`refine_affine`).
    """
    if crop is None:
        crop = warp_to_template(pyramid, H, template, width)
    if wide_basin or affine:
        motion, rows = (cv2.MOTION_AFFINE, 2) if affine else (cv2.MOTION_HOMOGRAPHY, 3)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, iterations, ECC_EPS)
        try:
            rho, W = cv2.findTransformECC(
                template.images[width], crop, np.eye(rows, 3, dtype=np.float32), motion, criteria, None, smooth
            )
        except cv2.error:  # diverged, or a degenerate warp
            return None
        if affine:
            W = np.vstack([W, [0.0, 0.0, 1.0]])
    else:
        solved = template.solver(width, smooth).align(crop, iterations, ECC_EPS)
        if solved is None:
            return None
        rho, W = solved
    S = template.to_svg_units(width)
    out = H @ S @ np.asarray(W, dtype=np.float64) @ inverse3(S)
    return out / out[2, 2], float(rho)


def _coarse_steps(
    pyramid: ImagePyramid,
    starts: list[tuple[np.ndarray, np.ndarray]],
    template: Template,
    width: int,
    iterations: int,
    smooth: int,
    wide: int | None = None,
) -> list[tuple[np.ndarray, float] | None]:
    """The coarsest level's solves from a detector's outline in one or two corner orders, or
    from a wider search's starts (``(homography, crop)`` each): by inverse composition, and
    when none of them reaches :data:`COARSE_FAST_BAR`, again by OpenCV's forward-additive ECC
    from the same start (a wider basin, at about 4x the time): from each start (``wide``
    None), or from the ``wide`` whose fast solves correlate best (none at ``wide`` 0).

    On prints the fast solve almost always gets there; what falls back is mostly clutter and
    other drawings. Once one order clears the bar, the runner-up is not solved by OpenCV: a
    quarter turn off correlates below the right turn's fast solve.
    """
    fast = [_ecc_step(pyramid, H, template, width, iterations, smooth, crop) for H, crop in starts]
    if any(step is not None and step[1] >= COARSE_FAST_BAR for step in fast):
        return fast
    ranked = sorted(range(len(fast)), key=lambda i: -1.0 if fast[i] is None else fast[i][1], reverse=True)
    for i in ranked if wide is None else ranked[:wide]:
        H, crop = starts[i]
        fast[i] = _ecc_step(pyramid, H, template, width, iterations, smooth, crop, wide_basin=True)
    return fast


def aligned_at(pyramid: ImagePyramid, homography: np.ndarray, template: Template, width: int) -> Alignment:
    """``homography`` (SVG units -> image pixels) as it is, with no ECC step: the photo's
    correlation there with the template at ``width`` (ECC's own measure)."""
    H = np.asarray(homography, np.float64)
    return Alignment(H, correlation(warp_to_template(pyramid, H, template, width), template.images[width]), width)


def refine_at(
    pyramid: ImagePyramid,
    homography: np.ndarray,
    template: Template,
    width: int,
    iterations: int = REFIT_ITERATIONS,
    wide_basin: bool = False,
) -> Alignment | None:
    """One ECC solve against ``template`` at ``width`` (which it must hold), from ``homography``;
    ``None`` when ECC diverges. ``wide_basin``: by OpenCV's ECC (:func:`_ecc_step`)."""
    H = np.asarray(homography, np.float64)
    step = _ecc_step(pyramid, H, template, width, iterations, 3, wide_basin=wide_basin)
    return None if step is None else Alignment(*step, width)


def nearest_affine(homography: np.ndarray, template: Template) -> np.ndarray:
    """The affine map (SVG units -> image pixels) whose outline of the drawing's frame lies
    nearest, in least squares, to ``homography``'s: the parallelogram closest to its quad."""
    frame = viewbox_corners(template.viewbox).astype(np.float64)
    quad = project(homography, frame)
    affine, *_ = np.linalg.lstsq(np.hstack([frame, np.ones((4, 1))]), quad, rcond=None)
    return np.vstack([affine.T, [0.0, 0.0, 1.0]])


def refine_affine(
    pyramid: ImagePyramid,
    homography: np.ndarray | list[np.ndarray],
    template: Template,
    iterations: tuple[int, ...] = AFFINE_ITERATIONS,
) -> Alignment | None:
    """The print aligned again as a flat sheet seen nearly head-on: from the parallelogram
    nearest ``homography``'s outline (:func:`nearest_affine`), an affine ECC solve at each
    template level (OpenCV's, forward-additive), perspective kept out.

    A cast shadow's edge across a light fill is an edge the drawing does not have: a full
    homography can bend a corner of the outline out to lay the drawing's edge on it, and
    correlate well. An affine map cannot bend, so the print's own edges decide. Given several
    starts (a list), each is solved at the coarsest level and only the best there is solved on:
    the finer levels cost most. ``None`` when ECC diverges."""
    starts = homography if isinstance(homography, list) else [homography]
    widths = sorted(template.images)
    coarse = [
        _ecc_step(pyramid, nearest_affine(H, template), template, widths[0], iterations[0], 3, affine=True)
        for H in starts
    ]
    solved = [step for step in coarse if step is not None]
    if not solved:
        return None
    H, rho = max(solved, key=lambda step: step[1])
    reached = Alignment(H, rho, widths[0])
    for width, n in zip(widths[1:], iterations[1:]):
        step = _ecc_step(pyramid, H, template, width, n, 3, affine=True)
        if step is None:
            return None
        H, rho = step
        reached = Alignment(H, rho, width)
    return reached


def corner_orders(homography: np.ndarray, template: Template) -> list[np.ndarray]:
    """The homography with the frame's corners taken in each of the four cyclic orders
    (the drawing turned by 0, 90, 180 and 270 degrees within the same outline)."""
    frame = viewbox_corners(template.viewbox).astype(np.float32)
    quad = project(homography, frame).astype(np.float32)
    return [cv2.getPerspectiveTransform(frame, np.roll(quad, k, axis=0)).astype(np.float64) for k in range(4)]


def turn_about(degrees: float, cx: float, cy: float) -> np.ndarray:
    """``(3, 3)`` the turn by ``degrees`` (counter-clockwise as seen, y down) about ``(cx, cy)``
    (SVG -> SVG)."""
    return np.vstack([cv2.getRotationMatrix2D((float(cx), float(cy)), float(degrees), 1.0), [0.0, 0.0, 1.0]])


def quarter_turn(k: int, cx: float, cy: float) -> np.ndarray:
    """``(3, 3)`` the turn by ``k`` quarters about ``(cx, cy)`` (SVG -> SVG)."""
    c, s = round(math.cos(k * math.pi / 2)), round(math.sin(k * math.pi / 2))
    return np.array([[c, -s, cx - c * cx + s * cy], [s, c, cy - s * cx - c * cy], [0, 0, 1]], float)


def correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Zero-mean normalised cross-correlation of two same-size images (ECC's own measure)."""
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 1e-12 else 0.0


def outline_sweep(
    homography: np.ndarray,
    template: Template,
    turns: int = SWEEP_TURNS,
    scales: tuple[float, ...] = SWEEP_SCALES,
    shifts: tuple[float, ...] = (0.0,),
    centred: bool = True,
) -> list[np.ndarray]:
    """The homography with its outline in the photo turned about its centre in ``turns`` equal
    steps, scaled by each of ``scales`` and its centre moved across and down by each pair of
    ``shifts`` (shares of the outline's mean side; ``centred`` false: the pair that leaves it in
    place left out): starts for a drawing the detector outlined loosely (turned by a fraction of
    a quarter, too large or too small, or off its centre)."""
    frame = viewbox_corners(template.viewbox).astype(np.float32)
    quad = project(homography, frame)
    centre = quad.mean(0)
    side = float(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1).mean())
    out = []
    for scale in scales:
        for dx in shifts:
            for dy in shifts:
                if not centred and dx == dy == 0:
                    continue
                for k in range(turns):
                    a = 2 * np.pi * k / turns
                    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * scale
                    moved = ((quad - centre) @ rot.T + centre + side * np.array([dx, dy])).astype(np.float32)
                    out.append(cv2.getPerspectiveTransform(frame, moved).astype(np.float64))
    return out


def refine(
    pyramid: ImagePyramid,
    homography: np.ndarray,
    template: Template,
    iterations: tuple[int, ...] | None = None,
    orders: int = 1,
    min_start: float = 0.1,
    accept: float | None = None,
    sized: bool = False,
    aim: float | None = None,
    ink: bool = True,
    fallback: bool = True,
    sweep_fallback: bool = True,
    shifted: bool = False,
) -> Alignment | None:
    """Refine ``homography`` (SVG units -> image pixels) by ECC, coarse to fine over the
    template's levels.

    Args:
        iterations: ECC iterations at each level (most converge in fewer); by default
            :data:`COARSE_ITERATIONS` at the coarsest and :data:`FINE_ITERATIONS` at the others.
        orders: 4 to also try the frame's corners in the other cyclic orders (the detector
            outlines a drawing but may miss its turn); the order that correlates best with the
            template before any iteration is kept.
        min_start: candidates correlating less than this before refinement are dropped at
            once (clutter and other drawings: no iterations spent on them), unless
            ``accept`` is given: then the wider searches still run.
        accept: the correlation a caller accepts. When the quick path ends below it, wider
            searches follow, each only if the one before also fell short: every other corner
            order carried through all levels, then the best few of :func:`outline_sweep` by
            plain correlation, then the best few starts from the print's ink moments
            (:func:`~deepmorph_detect.inkstart.ink_starts`). What they find must reach
            ``accept`` plus :data:`WIDE_SEARCH_MARGIN`, else the quick path's result is
            returned. ``None``: the quick path only.
        aim: with ``accept``, the correlation below which the quick path's result, though
            accepted, is searched beyond (a blind proposal's: it can end at a wrong pose); the
            wider searches then look on until one reaches ``aim`` plus the margin, and replace
            an accepted quick result only then. ``None``: ``accept``.
        sized: the outline's size comes from the print's own ink (the universal detector's ink
            square): the wider searches then sweep only its corner orders, enlarged
            (:data:`SIZED_SWEEP_SCALES`: a square falls short of a print seen steeply from the
            side), not its turns (which found no print the corner orders and the ink starts
            missed, in 400 scenes of two drawings, and took about a quarter of the time spent on
            other drawings); the starts from the print's ink still follow.
        ink: the wider searches end with the starts from the print's ink; ``False`` where the
            pyramid shows no paper to find the ink on (the edges of
            :mod:`~deepmorph_detect.edge_align`).
        fallback: the quick path's coarse solves fall back on OpenCV's wider basin when none
            reaches :data:`COARSE_FAST_BAR` (:func:`_coarse_steps`). ``False``: the quick path
            ends there instead, short of a result, where the caller searches wider elsewhere
            (a blind proposal's photo, searched again in flat light), so that proposals of other
            drawings, which fall short almost always, do not pay for both searches.
        sweep_fallback: the sweep's best start falls back on OpenCV's wider basin too;
            ``False``: the sweep goes without it, as the ink's starts do (a blind proposal of a
            black-and-white drawing's: over 2,000 scenes of four such drawings it aligned no
            print, while each other drawing paid for it).
        shifted: where all else fell short, a ``sized`` outline is swept once more with its
            centre moved (:data:`SHIFTED_SWEEP_SHIFTS`, at :data:`SHIFTED_SWEEP_SCALES`): a
            colour drawing's, whose ink square can frame its darkest part alone.

    Returns:
        The best alignment reached, or ``None`` when the candidate is rejected or ECC diverges
        at the coarsest level of every start tried.
    """
    levels = sorted(template.images)
    its = iterations or (COARSE_ITERATIONS,) + (FINE_ITERATIONS,) * (len(levels) - 1)
    starts = corner_orders(homography, template)[:orders] if orders > 1 else [np.asarray(homography, np.float64)]

    def from_outlines(
        tries: list[tuple[np.ndarray, np.ndarray]], fallbacks: int = 1
    ) -> list[tuple[np.ndarray, float] | None]:
        """A wider search's coarsest solves: OpenCV's only from the start whose fast solve
        correlates best (from every start it finds nothing more for its time; from none, the
        prints only OpenCV reaches from an outline are lost), or from none (``fallbacks`` 0)."""
        return _coarse_steps(pyramid, tries, template, levels[0], its[0], 5, wide=fallbacks)

    scored = _plain_scores(pyramid, starts, template, levels[0])
    coarse: list[tuple[np.ndarray, float] | None] = []
    chosen, best = -1, None
    if scored[0][0] >= min_start:
        # the best two orders by plain correlation hold the right one almost always; ECC decides
        # between them at the coarsest level unless the best is ahead by a clear margin
        close = [r for r in scored[:2] if scored[0][0] - r[0] < ORDER_MARGIN]
        tries = [(H, crop) for _, H, crop in close]
        coarse = _coarse_steps(pyramid, tries, template, levels[0], its[0], 5, wide=None if fallback else 0)
        chosen = max(range(len(coarse)), key=lambda i: -1.0 if coarse[i] is None else coarse[i][1])
        short = coarse[chosen] is None or (not fallback and coarse[chosen][1] < COARSE_FAST_BAR)
        best = None if short else _finish(pyramid, coarse[chosen], template, levels, its)
    elif accept is None:
        return None
    # else: an outline so far off that no corner order correlates at all (a detector's outline
    # of the ink alone, turned and at 0.6-0.7x the frame): the wider searches below may still
    # find the print

    aim = accept if accept is None or aim is None else max(aim, accept)
    if accept is None or (best is not None and best.correlation >= aim):
        return best
    quick = best
    # every wider start is one more chance to fit clutter: what they find must clear a higher bar
    bar = aim + WIDE_SEARCH_MARGIN

    def good(a: Alignment | None) -> bool:
        return a is not None and a.correlation >= bar

    def searched(a: Alignment) -> Alignment:
        """``a`` marked as a wider search's (what ``good`` passes is never the quick path's:
        that one ended below ``accept``)."""
        return replace(a, searched=True)

    def carried(step: tuple[np.ndarray, float] | None) -> Alignment | None:
        """A wider search's coarse solve carried through the finer levels, where it reaches
        :data:`WIDE_CARRY_FROM` at the coarsest."""
        return None if step is None or step[1] < WIDE_CARRY_FROM else _finish(pyramid, step, template, levels, its)

    def best_few(starts: list[np.ndarray], best: Alignment | None, fallbacks: int = 1) -> Alignment | None:
        """``best``, or better: the :data:`SWEEP_TRIES` best of ``starts`` by plain correlation,
        each solved from its outline (:func:`from_outlines`) and carried through all levels
        (:func:`carried`)."""
        scored = _plain_scores(pyramid, starts, template, levels[0])[:SWEEP_TRIES]
        for step in from_outlines([(H, crop) for start, H, crop in scored if start >= min_start], fallbacks):
            best = _better(best, carried(step))
        return best

    # the detector's corner order may be a quarter turn off, with plain correlation ranking the
    # right order third or fourth: carry every other order through all levels
    others = [i for i, (start, _, _) in enumerate(scored) if i != chosen and start >= min_start]
    fresh = iter(from_outlines([scored[i][1:] for i in others if i >= len(coarse)]))
    for i in others:
        best = _better(best, carried(coarse[i] if i < len(coarse) else next(fresh)))
    if good(best):
        return searched(best)
    # the outline itself is off: turned or scaled starts; an ink square is turned as its ink, but
    # falls short of a print seen steeply from the side: only its corner orders, enlarged
    sweep = outline_sweep(homography, template, 4, SIZED_SWEEP_SCALES) if sized else outline_sweep(homography, template)
    best = best_few(sweep, best, 1 if sweep_fallback else 0)
    if good(best):
        return searched(best)
    if ink:
        # the outline's shape is off (a print seen steeply from the side, outlined with the wrong
        # shear): starts from the print's own ink (:mod:`~deepmorph_detect.inkstart`)
        quad = project(homography, viewbox_corners(template.viewbox))
        # without OpenCV's fallback: these starts fit the print's shear already, and over 800
        # scenes of four drawings it reached 0.7 from 5 of 700 starts on other drawings, on no print
        best = best_few(ink_starts(pyramid.levels[0], quad, template.ink_moments, SWEEP_TURNS), best, 0)
        if good(best):
            return searched(best)
    if sized and shifted:
        # a colour print's ink square can frame its darkest part alone: the square moved off its
        # centre, last (among the centred starts, the best few by plain correlation were these
        # often enough to crowd out the right one)
        moved = outline_sweep(homography, template, 4, SHIFTED_SWEEP_SCALES, SHIFTED_SWEEP_SHIFTS, centred=False)
        best = best_few(moved, best, 1 if sweep_fallback else 0)
        if good(best):
            return searched(best)
    # short of the aim, a wider search still beats a quick path that was not accepted at all
    failed = quick is None or quick.correlation < accept
    return searched(best) if failed and best is not None and best.correlation >= accept + WIDE_SEARCH_MARGIN else quick


def _plain_scores(
    pyramid: ImagePyramid, starts: list[np.ndarray], template: Template, width: int
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """``(correlation, homography, crop)`` per start, best first: the photo warped through each
    start at ``width`` and correlated, blurred, with the template before any ECC iteration."""
    scored = []
    for H in starts:
        crop = warp_to_template(pyramid, H, template, width)
        scored.append((correlation(template.coarse_blurred, cv2.GaussianBlur(crop, (5, 5), 0)), H, crop))
    scored.sort(key=lambda r: -r[0])
    return scored


def _better(a: Alignment | None, b: Alignment | None) -> Alignment | None:
    if a is None:
        return b
    return b if b is not None and b.correlation > a.correlation else a


def _finish(
    pyramid: ImagePyramid,
    coarse: tuple[np.ndarray, float],
    template: Template,
    levels: list[int],
    its: tuple[int, ...],
) -> Alignment:
    """An alignment reached at the coarsest level carried through the finer ones."""
    (H, rho), reached = coarse, levels[0]
    for width, n in zip(levels[1:], its[1:]):
        step = _ecc_step(pyramid, H, template, width, n, 3)
        if step is None:
            break
        (H, rho), reached = step, width
    return Alignment(H, rho, reached)


__all__ = [
    "LEVELS",
    "SYMMETRY_CORRELATION",
    "Alignment",
    "ImagePyramid",
    "Template",
    "aligned_at",
    "corner_orders",
    "nearest_affine",
    "refine_affine",
    "correlation",
    "outline_sweep",
    "pixels_to_svg_units",
    "quarter_turn",
    "refine",
    "refine_at",
    "turn_about",
    "warp_to_template",
]
