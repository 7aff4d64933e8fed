"""Aligning candidates to the drawing: which proposals are the drawing, and where exactly.

Each candidate is aligned to the unmorphed drawing by ECC (:func:`~deepmorph_detect.refine.refine`):
a detector's outline with every cyclic corner order and, when that falls short, wider searches;
the whole image framed by its ink with one quick solve. A candidate is kept when its alignment
correlates well enough and its outline can be a print (:func:`plausible_outline`); the same
drawing found twice is kept once. A detector's outline that aligns poorly in the photo, or into
an outline no flat print makes (:meth:`Aligner.bent`), is aligned again in flat light (shadows
divided out), and the better alignment is kept; one aligned in neither is aligned as a flat
sheet (:meth:`Aligner.outline_as_flat_sheet`). A drawing aligned but not read can be aligned
again as a flat sheet, without perspective (:meth:`Aligner.as_flat_sheet`), or from its
detector's outline on the print's edges alone (:meth:`Aligner.on_edges`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from deepmorph_core.photo import flatten_illumination
from deepmorph_core.protocols import Candidate
from deepmorph_detect.camera import around_outline, outline_size, project, rigid_misfit, viewbox_corners
from deepmorph_detect.edge_align import align_on_edges, edge_template
from deepmorph_detect.refine import (
    WIDE_SEARCH_MARGIN,
    Alignment,
    ImagePyramid,
    Template,
    corner_orders,
    refine,
    refine_affine,
)
from deepmorph_detect.verifier import ProposalVerifier

MIN_CORRELATION = 0.55  # ECC correlation below which a candidate is not this drawing
# a detector outline aligned in the photo below this is aligned in flat light too, and the better
# kept: a sharp shadow across a print can bend the alignment to its edge and still pass the bar
WEAK_ALIGNMENT = 0.65
#: a blind proposal (the universal detector's) aligned below this takes the wider searches in flat
#: light, and what they find replaces its alignment where it reaches this (plus their margin): an
#: ink square is a square, and a print seen steeply from the side can align from it at the wrong
#: corner order at 0.6-0.7, where the right pose correlates at 0.93-0.97
BLIND_SEARCH_BELOW = 0.8
#: a blind proposal scored below this (the universal detector proposes from 0.2) takes the quick
#: path alone: the clear prints it finds there align at once (0.96), and clutter found there is
#: not worth a wider search
FAINT_PROPOSAL = 0.3
#: ... and so is one whose outline lies further than this share of its width from any a flat print
#: can make (:func:`~deepmorph_detect.camera.rigid_misfit`): on 200 medium close-ups of a colour
#: drawing and 200 hard ones of another, alignments within 5 % of the truth were at most 0.031
#: from one; three in four of those over 10 % off were further
BENT_OUTLINE = 0.035
#: an alignment without perspective (:meth:`Aligner.as_flat_sheet`) that moves the outline's corners
#: less than this share of its width on average reads as the one it came from: not read again
SHEET_MOVE = 0.02
SAME_DRAWING = 0.3  # two alignments whose centres are closer than this share of the diagonal

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


@dataclass
class Aligned:
    """A candidate that is the drawing: its alignment, and the photo it was aligned in (the
    photo itself, or the photo in flat light around the candidate)."""

    candidate: Candidate
    alignment: Alignment
    pyramid: ImagePyramid


@dataclass(frozen=True)
class QuickLook:
    """A detector's outline aligned by the photo's quick path (:meth:`Aligner.quick_look`)."""

    alignment: Alignment | None
    #: it is the outline's alignment: no wider search follows
    final: bool
    #: failed, weak, found only by a wider start, or bent: flat light searches again
    weak: bool


class Aligner:
    """Aligns candidates to one drawing's template and keeps those that are the drawing.

    Args:
        template: the unmorphed drawing rendered at the alignment levels.
        min_correlation: the bar an alignment must reach.
        ink_thickness: the drawing's thickest ink feature, in pixels of a view ``view_width``
            wide (sizes the flat-light filter).
        view_width: the width of the rectified views the thickness is measured in.
        flat_sheet: an outline neither the photo nor flat light aligns is aligned as a flat
            sheet (:meth:`outline_as_flat_sheet`): a colour drawing's, where it read more close-ups.
        blind_fallback: a blind proposer's outline falls back on OpenCV's wider basin in flat
            light's quick path and in its sweep (:func:`~deepmorph_detect.refine.refine`'s
            ``fallback`` and ``sweep_fallback``): a colour drawing's, where the quick path's read
            one print more in 200 scenes. Over 1,500 scenes of four black-and-white drawings
            the quick path's read none the wider searches missed, the sweep's none in 2,000,
            and each other drawing paid for both.
        verifier: the model's proposal verifier (:mod:`~deepmorph_detect.verifier`), where it
            stores one: a blind outline it turns away skips the wider searches.
        shifted_sweep: an ink square's sweep also moves its centre (:func:`~deepmorph_detect.refine.refine`'s
            ``shifted``): a colour drawing's, whose ink square can frame its darkest part alone.
    """

    def __init__(
        self,
        template: Template,
        min_correlation: float,
        ink_thickness: float,
        view_width: int,
        flat_sheet: bool = True,
        blind_fallback: bool = True,
        verifier: ProposalVerifier | None = None,
        shifted_sweep: bool = False,
    ) -> None:
        self.template = template
        self.shifted_sweep = shifted_sweep
        self.verifier = verifier
        self.flat_sheet = flat_sheet
        self.blind_fallback = blind_fallback
        self.min_correlation = min_correlation
        self.frame_corners = viewbox_corners(template.viewbox)
        self._ink_thickness = ink_thickness
        self._view_width = view_width

    def homography(self, corners: np.ndarray) -> np.ndarray:
        """The homography (SVG units -> pixels) putting the drawing's frame on ``corners``."""
        return cv2.getPerspectiveTransform(
            self.frame_corners.astype(np.float32), np.asarray(corners, np.float32)
        ).astype(np.float64)

    def accepts(self, alignment: Alignment | None) -> bool:
        """Whether an alignment shows this drawing: it correlates well enough, and its outline
        can be a print (:func:`plausible_outline`)."""
        if alignment is None or alignment.correlation < self.min_correlation:
            return False
        return plausible_outline(project(alignment.homography, self.frame_corners), self.frame_corners)

    def centre(self, H: np.ndarray) -> np.ndarray:
        """The drawing's centre in the photo under ``H``."""
        return project(H, self.frame_corners.mean(0, keepdims=True))[0]

    def seen(self, H: np.ndarray, others: list[np.ndarray]) -> bool:
        """Whether the drawing at ``H`` is one already at one of ``others`` (centres closer
        than :data:`SAME_DRAWING` of its diagonal)."""
        corners = project(H, self.frame_corners)
        centre, size = self.centre(H), float(np.linalg.norm(corners[2] - corners[0]))
        return any(np.linalg.norm(centre - self.centre(other)) < SAME_DRAWING * size for other in others)

    def verify(
        self,
        pyramid: ImagePyramid,
        candidates: list[Candidate],
        gray: np.ndarray | None = None,
        looks: list[QuickLook | None] | None = None,
    ) -> list[Aligned]:
        """The candidates that are the drawing, aligned, duplicates (the same drawing twice)
        removed: a later alignment whose centre is within :data:`SAME_DRAWING` of its own
        diagonal from a kept one's is that drawing again (:meth:`seen`), and replaces it where it
        correlates better in an outline a flat print makes (not :meth:`bent`) centred in the
        photo (:meth:`replaces`). A detector can outline part of a print (the head of a blurred
        figure) above the whole print: the drawing squeezed into the part can still pass the
        bar, while the whole print's outline aligns much better (0.79 against 0.92). With
        ``gray`` given, a detector outline that does not align well in the photo itself is also
        aligned in flat light around it. ``looks``: the candidates' :meth:`quick_looks`, where
        they were taken already."""
        kept: list[Aligned] = []
        for cand, look in zip(candidates, looks or [None] * len(candidates), strict=True):
            seen_in = pyramid
            if cand.homography is None:  # a detector's outline: its turn and size may be off, search wider
                seen_in, alignment = self.align_outline(pyramid, cand, gray, look)
            else:  # the whole frame, framed by its ink: on every photo without a detection, keep it quick
                alignment = refine(pyramid, cand.homography, self.template)
            if not self.accepts(alignment):
                continue
            same = [k for k, a in enumerate(kept) if self.seen(alignment.homography, [a.alignment.homography])]
            if not same:
                kept.append(Aligned(cand, alignment, seen_in))
            elif self.replaces(alignment, [kept[k].alignment for k in same], pyramid.levels[0].shape):
                kept[same[0]] = Aligned(cand, alignment, seen_in)
                kept = [a for k, a in enumerate(kept) if k not in same[1:]]
        return kept

    def replaces(self, alignment: Alignment, same: list[Alignment], image_shape: tuple[int, ...]) -> bool:
        """Whether ``alignment`` replaces the alignments of the same drawing kept before it: it
        correlates better than each, its outline is one a flat print makes (a drawing stretched
        from half a heart over the sheet correlated at 0.83, the whole heart's bent one at 0.60
        and read), and its centre lies in the photo (another drawing aligned into an outline
        centred far outside a 640x480 photo, its diagonal so long that every print seemed to be
        it)."""
        if alignment.correlation <= max(a.correlation for a in same):
            return False
        x, y = self.centre(alignment.homography)
        height, width = image_shape[:2]
        return 0 <= x < width and 0 <= y < height and not self.bent(alignment.homography, image_shape)

    def quick_look(self, pyramid: ImagePyramid, cand: Candidate, gray: np.ndarray | None) -> QuickLook:
        """A detector's outline aligned by the photo's quick path, the first step of
        :meth:`align_outline`, and whether that is its alignment (``final``: nothing wider
        follows). The photo alone (no ``gray``) and a faint blind proposal take this path
        alone; a blind outline that flat light searches again when it falls short takes it
        without OpenCV's slower fallback."""
        photo_only = gray is None or (cand.blind and cand.score < FAINT_PROPOSAL)
        alignment = self._search(pyramid, cand, gray is None or not cand.blind, fallback=photo_only or not cand.blind)
        if photo_only:
            return QuickLook(alignment, final=True, weak=False)
        weak = (
            not self.accepts(alignment)
            or alignment.correlation < WEAK_ALIGNMENT
            or alignment.searched
            or self.bent(alignment.homography, gray.shape)
        )
        if weak:
            return QuickLook(alignment, final=False, weak=True)
        return QuickLook(alignment, final=not (cand.blind and alignment.correlation < BLIND_SEARCH_BELOW), weak=False)

    def quick_looks(
        self, pyramid: ImagePyramid, candidates: list[Candidate], gray: np.ndarray | None
    ) -> list[QuickLook | None]:
        """:meth:`quick_look` of each detector outline among ``candidates`` (``None`` for a
        whole image framed by its ink, which has a homography already)."""
        return [self.quick_look(pyramid, cand, gray) if cand.homography is None else None for cand in candidates]

    def quick_prints(
        self, pyramid: ImagePyramid, candidates: list[Candidate], looks: list[QuickLook | None]
    ) -> list[Aligned]:
        """The candidates whose quick look is final and accepted, best correlated first, each
        drawing once: the prints that align at once, to read before any wider search
        (:meth:`~deepmorph_detect.locate.Locator.locate` with ``first``). Their alignments are
        the very ones :meth:`verify` keeps from these ``looks``."""
        quick = [(cand, look.alignment) for cand, look in zip(candidates, looks, strict=True)
                 if look is not None and look.final and self.accepts(look.alignment)]  # fmt: skip
        kept: list[Aligned] = []
        for cand, alignment in sorted(quick, key=lambda found: -found[1].correlation):
            if not self.seen(alignment.homography, [a.alignment.homography for a in kept]):
                kept.append(Aligned(cand, alignment, pyramid))
        return kept

    def _search(self, seen_in: ImagePyramid, cand: Candidate, wide: bool, fallback: bool) -> Alignment | None:
        """A detector's outline aligned in ``seen_in`` from each of its corner orders
        (:func:`~deepmorph_detect.refine.refine`), with the wider searches where ``wide``."""
        return refine(
            seen_in,
            self.homography(cand.corners),
            self.template,
            orders=4,
            accept=self.min_correlation if wide else None,
            sized=cand.sized,
            aim=BLIND_SEARCH_BELOW if cand.blind else None,
            fallback=fallback,
            sweep_fallback=self._falls_back(cand),
            shifted=self.shifted_sweep,
        )

    def _falls_back(self, cand: Candidate) -> bool:
        """Whether OpenCV's fallback runs in flat light for ``cand``: in its quick path and its
        sweep (:attr:`blind_fallback`; always for an outline from a detector that knows the drawing)."""
        return self.blind_fallback or not cand.blind

    def align_outline(
        self, pyramid: ImagePyramid, cand: Candidate, gray: np.ndarray | None, look: QuickLook | None = None
    ) -> tuple[ImagePyramid, Alignment | None]:
        """A detector's outline aligned: the photo it was aligned in, and the alignment.

        A shadow edge across the print can make the alignment fail, or bend it and still leave it
        above the bar, or leave only a wider search's start to align: then (``gray`` given) it is
        aligned in flat light too, and that one is kept when the photo's failed or correlates
        worse. A bend that keeps the correlation above :data:`WEAK_ALIGNMENT` shows in the
        outline's shape: no flat print makes it (:meth:`bent`). A blind proposer's outline
        (``Candidate.blind``: most of them are other drawings, each turned away in 7-10 ms, most
        of it the wider searches) takes the wider searches in flat light only, after the photo's
        quick path (which goes without OpenCV's fallback, :func:`refine`'s ``fallback``, as do
        flat light's quick path and sweep unless :attr:`blind_fallback`):
        away from shadows flat light is the photo, and on 200 scenes of the ghost it read the
        same prints in half the frame time. It goes there also when it aligns in the photo
        below :data:`BLIND_SEARCH_BELOW`, and the flat light's alignment replaces that one only
        where it reaches that bar plus the wider searches' margin; one scored below
        :data:`FAINT_PROPOSAL` takes the photo's quick path alone. A detector that knows
        the drawing takes them in both, which finds a few more prints that do not read. An
        outline (not a faint blind one) aligned in neither is aligned as a flat sheet
        (:meth:`outline_as_flat_sheet`), where this aligner does that (:attr:`flat_sheet`).
        A blind outline the model's :attr:`verifier` turns away keeps its quick look: it is
        another drawing, and those searches were most of a frame's time.
        ``look``: the outline's :meth:`quick_look`, where it was taken already.
        """
        look = look or self.quick_look(pyramid, cand, gray)
        alignment = look.alignment
        if look.final:
            return pyramid, alignment
        # weak, or a blind outline below the aim: flat light searches again (a look without gray is final)
        assert gray is not None
        if cand.blind and self.verifier is not None and self.verifier.turns_away(gray, cand.corners):
            return pyramid, alignment
        seen_in, missed = pyramid, not self.accepts(alignment)
        flat = self.in_flat_light(gray, cand.corners)
        # the wider searches follow: a blind outline's quick path here ends short of OpenCV's
        # fallback too, and its sweep goes without it, unless this aligner keeps it
        in_flat = self._search(flat, cand, True, fallback=self._falls_back(cand))
        better = self.accepts(in_flat) and (missed or in_flat.correlation > alignment.correlation)
        # a blind outline aligned well enough in the photo gives way only to one that reaches the aim
        if better and (look.weak or in_flat.correlation >= BLIND_SEARCH_BELOW + WIDE_SEARCH_MARGIN):
            seen_in, alignment = flat, in_flat
        if self.accepts(alignment) or not self.flat_sheet:
            return seen_in, alignment
        sheet = self.outline_as_flat_sheet(pyramid, cand)
        return (pyramid, sheet) if sheet is not None else (seen_in, alignment)

    def outline_as_flat_sheet(self, pyramid: ImagePyramid, cand: Candidate) -> Alignment | None:
        """A detector's outline aligned as a flat sheet (:func:`~deepmorph_detect.refine.refine_affine`)
        from each of its corner orders, the best of them at the coarsest level solved on; where
        this aligner accepts it, else ``None``. For an outline neither the photo nor flat light
        aligned: on a clear print in soft light ECC ran off to a bent outline from every start,
        and an affine map cannot bend."""
        sheet = refine_affine(pyramid, corner_orders(self.homography(cand.corners), self.template), self.template)
        return sheet if self.accepts(sheet) else None

    def bent(self, homography: np.ndarray, image_shape: tuple[int, ...]) -> bool:
        """:func:`bent_outline` of this drawing's frame."""
        return bent_outline(homography, self.frame_corners, image_shape)

    def other_turn(self, pyramid: ImagePyramid, alignment: Alignment, margin: float = 0.0) -> Alignment | None:
        """The print aligned again from each of the drawing's other turns
        (:attr:`~deepmorph_detect.refine.Template.other_turns`): the best of them, where this
        aligner accepts it and it correlates better than ``alignment`` less ``margin``; else
        ``None``. For a print aligned but not read, which may have been aligned at the wrong turn
        of a drawing that nearly looks the same turned: the right turn then aligns better, while
        a print aligned at the right turn and not read for other reasons gains nothing here. With
        a ``margin``, for a print read weakly: both turns can align about as well."""
        best, bar = None, alignment.correlation - margin
        for turn in self.template.other_turns:
            again = refine(pyramid, alignment.homography @ turn, self.template)
            if self.accepts(again) and again.correlation > bar:
                best, bar = again, again.correlation
        return best

    def as_flat_sheet(self, pyramid: ImagePyramid, alignment: Alignment) -> Alignment | None:
        """The print aligned again without perspective (:func:`~deepmorph_detect.refine.refine_affine`),
        where this aligner accepts that and its outline moved by at least
        :data:`SHEET_MOVE` of the frame's width; else ``None``. For a print aligned but not
        read: a cast shadow's edge can bend a full homography away from the print."""
        again = refine_affine(pyramid, alignment.homography, self.template)
        if not self.accepts(again):
            return None
        before, after = project(alignment.homography, self.frame_corners), project(again.homography, self.frame_corners)
        width = max(float(np.linalg.norm(before[1] - before[0])), 1.0)
        moved = float(np.linalg.norm(after - before, axis=1).mean())
        return again if moved >= SHEET_MOVE * width else None

    @functools.cached_property
    def edges(self) -> Template:
        """The template's edges (:func:`~deepmorph_detect.edge_align.edge_template`), made when a
        print first needs them."""
        return edge_template(self.template)

    def on_edges(self, gray: np.ndarray, cand: Candidate) -> Alignment | None:
        """A detector's outline aligned again on the print's edges alone
        (:func:`~deepmorph_detect.edge_align.align_on_edges`), where its outline can be a print;
        else ``None``. For a print aligned but not read: a light that changes across the sheet as
        much as the drawing's fills differ from its paper bends ECC's alignment."""
        again = align_on_edges(gray, self.homography(cand.corners), cand.corners, self.edges, cand.sized)
        if again is None or not plausible_outline(project(again.homography, self.frame_corners), self.frame_corners):
            return None
        return again

    def in_flat_light(self, gray: np.ndarray, corners: np.ndarray) -> ImagePyramid:
        """The photo with shadows and light gradients divided out around a detector outline.

        A shadow edge across a print is an edge the drawing does not have: ECC bends to it or
        diverges. The light is divided out by ``flatten_illumination``, sized to the thickest
        ink feature at the outline's scale.
        """
        x0, y0, x1, y1 = around_outline(corners, gray.shape, 0.3)
        flat = gray.copy()
        if x1 - x0 >= 16 and y1 - y0 >= 16:
            feature_px = self._ink_thickness * outline_size(corners) / self._view_width
            flat[y0:y1, x0:x1] = flatten_illumination(gray[y0:y1, x0:x1], max(feature_px, 1.0))
        return ImagePyramid(flat)


def bent_outline(homography: np.ndarray, frame_corners: np.ndarray, image_shape: tuple[int, ...]) -> bool:
    """Whether the outline ``homography`` (SVG units -> pixels) gives a drawing's frame
    ``frame_corners`` is one no flat print makes in an uncropped photo of ``image_shape``
    (:func:`~deepmorph_detect.camera.rigid_misfit` over :data:`BENT_OUTLINE`): a cast shadow's
    edge bent it."""
    size = (int(image_shape[1]), int(image_shape[0]))
    return rigid_misfit(homography, frame_corners, size) > BENT_OUTLINE


def ink_thickness(template: Template, view_width: int) -> float:
    """The drawing's thickest ink feature (twice the largest distance from paper inside its
    ink) in pixels of a view ``view_width`` wide, from the finest template level."""
    finest = max(template.images)
    depth = cv2.distanceTransform((template.images[finest] < 0.5).astype(np.uint8), cv2.DIST_L2, 3)
    return 2.0 * float(depth.max()) * view_width / finest


__all__ = ["BENT_OUTLINE", "MIN_CORRELATION", "SAME_DRAWING", "WEAK_ALIGNMENT", "Aligned", "Aligner", "bent_outline",
           "ink_thickness", "plausible_outline"]  # fmt: skip
