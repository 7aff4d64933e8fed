"""From a photo to decoded drawings: the photo chain's stages, in order.

:class:`Locator` only sequences the stages, each a module with one job:

1. **propose** (:mod:`~deepmorph_detect.propose`): the detector plugin's candidates; when none
   of them is the drawing or is read, the whole image framed by its ink, then the same in flat
   light;
2. **align** (:mod:`~deepmorph_detect.align`): each candidate aligned to the unmorphed drawing,
   kept when it correlates and its outline can be a print (a photo without the drawing gives an
   empty list, not a guess);
3. **read** (:mod:`~deepmorph_detect.read`): rectified views read by the decoder, then second
   looks and a last look by synthesis for a drawing no first look reads;
4. **check** (:mod:`~deepmorph_detect.check`): a payload that passes the CRC must also be shown
   by the photo (its morph fits better than none; bit by bit when it needed corrections);
5. **pose** (:mod:`~deepmorph_detect.pose`): corners, keypoints and the camera pose, from the
   alignment to the decoded morph once it is confirmed;
6. **track** (:mod:`~deepmorph_detect.track`): drawings followed from frame to frame in videos.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from collections.abc import Callable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from deepmorph_core.codec import DecodeResult
from deepmorph_core.device import resolve_device
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.image_io import MIN_IMAGE_SIDE
from deepmorph_core.luminance import is_luma
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.protocols import Candidate, Detector
from deepmorph_detect.align import MIN_CORRELATION, Aligned, Aligner, QuickLook, ink_thickness
from deepmorph_detect.camera import Camera, project
from deepmorph_detect.check import RELIT_MAX_CORRECTIONS, MorphTemplates, PayloadCheck, PayloadChecker
from deepmorph_detect.fastrender import stretched_renderer, template_renderer
from deepmorph_detect.light_field import realign_in_light_field
from deepmorph_detect.pose import Placer
from deepmorph_detect.propose import (
    WHOLE_FRAME,
    InkFrame,
    whole_frame,
    whole_frame_in_flat_light,
    whole_frame_on_paper,
)
from deepmorph_detect.read import RECTIFY_WIDTH_FACTOR, Reader, Reading
from deepmorph_detect.refine import LEVELS, Alignment, ImagePyramid, Template
from deepmorph_detect.results import Located, across_px, along_tilt_px, measure_width, refused_result
from deepmorph_detect.synthesis import CHECK_WIDTH, MorphSynthesis
from deepmorph_detect.template_light import TemplateLight
from deepmorph_detect.verifier import verifier_for

# a drawing whose payload is not read must align this much better to be reported: no payload
# vouches for it, so another drawing aligning just above the bar is not reported
UNREAD_MARGIN = 0.05
#: ... and one from the whole image framed by its ink (which does not know the drawing) at least
#: this well: other drawings align to simple ones (a bar chart) up to 0.75. An unread print aligned
#: this well is also aligned again at its frame's other turns (:meth:`Locator.decode_drawing`):
#: every print that read there had aligned at 0.85 or better, most below it were other drawings
UNREAD_BLIND_CORRELATION = 0.8
#: A drawing that looks the same at several turns takes its later looks (50-400 ms a turn) at
#: this many of them, those whose first looks read most confidently: on 60 hard 1280x720 scenes
#: each of the cube (3 turns) and the chip (4), the same prints read with frames 0.7-0.8x as
#: long on average; at one turn, the codepen diamond (2) lost a print
LATER_LOOK_TURNS = 2
#: The verdict of a drawing that looks the same turned whose readings at two of its turns passed
#: every check with two payloads, neither of them read without corrections and confidently: read
#: at the wrong turn, its true morph turned is a morph too and can pass the checks; the photo does
#: not say which turn is right, so neither payload is given (a `--pixels 200` codepen diamond:
#: twice in 10,000 240-px close-ups, the wrong word beside the right one, 2 and 3 corrections
#: against 1)
TURN_CONFLICT = "turn conflict"
#: A weak reading (not :attr:`~deepmorph_detect.check.PayloadCheck.settled`) aligned that well is compared with the
#: reading at the best other turn of its frame where that turn aligns at most this much worse: a
#: drawing that nearly looks the same half turned (a battery) aligned at 0.832 at either turn of a
#: print, and read another word at the wrong one, with 4 corrections against the true one's 1
TURN_TIE_MARGIN = 0.02
#: ... and only where the print's frame is between this share of the image's width and its
#: inverse (half to twice the image), what framing the whole image is for: a scan, a print
#: filling the frame. In 10,000 scenes without any print, whole-image framing reported six
#: unread alignments (0.63-0.89) of patches of other drawings' ink 2-34 % of the image wide, and
#: of one frame 8.6 times as wide; 64-px close-ups of the ghost too small to read fill 55-66 %
FILLS_FRAME = 0.5
#: ... and where the photo shows it whole (:meth:`Locator.shown_whole`): its ink in the image, at
#: most this share of the ink's width out, and its outline one a flat print makes. Colour drawings
#: framed from the whole image of scenes without any print were reported at 0.80-0.86 with their
#: ink running off the image or their outline 0.68 of its width from any a flat print makes. Of
#: nine unread reports in 400 close-ups of one, three stay (0.012-0.022 from a flat print's outline)
INK_OUTSIDE = 0.1
#: A blind proposer's drawing (the universal detector's) aligned below this is read by the first
#: looks only: on 360 scenes of three colour models every print read had aligned at 0.81 or better,
#: while the later looks at other drawings aligned at 0.55-0.7 took a third of the reading's time.
#: A drawing aligned this well and not read is also aligned and read again in the light its
#: template shows (:mod:`~deepmorph_detect.template_light`)
BLIND_READ_CORRELATION = 0.7
#: ... and for a black-and-white drawing: in 200 1280x720 scenes of the `--pixels 200` codepen every
#: print read had aligned at 0.85 or better, while 6 of the 8 other drawings aligned at 0.7-0.78
#: took 0.6-1.1 s each with the later looks, the template's light and the grid of light
BLIND_READ_CORRELATION_BW = 0.8


#: A print trained for a smallest width (``print_px``) that aligns narrower than this share of it
#: is read by the first looks only (:meth:`Locator.aligned_too_narrow`): it is refused as too
#: small whatever it reads, and the later looks took 50-400 ms of a 1280x720 frame. The share
#: leaves room for the alignment's width to differ from the payload's morph fit's.
NARROW_SHARE = 0.97
#: A colour print narrower than this share of the decoder's frame along any direction keeps no
#: reading at all, not even one without corrections (:func:`refuses_narrow_reading`): in hard
#: 640x480 scenes a bar chart's print 26 px along its tilt gave a wrong payload read without
#: corrections, confident enough to skip the per-bit rules; below half the frame, 1 % of the
#: right readings of four colour models (62 of 5761 in 7000 scenes)
COLOUR_FLOOR_SHARE = 0.5


#: The detector of a bundle that stores none of its own (``universal``: shipped, for any drawing).
DEFAULT_DETECTOR = "universal"
#: The name that asks for no detector: only whole images framed by their ink are tried.
NO_DETECTOR = "none"


def detector_for(
    model: DeepMorphModel, detector: Detector | str | None, registry: Registry, device: str = "cpu"
) -> Detector | None:
    """The detector a locator uses: ``detector`` itself, the registered detector of that name,
    or (``None``) the one the bundle names, else :data:`DEFAULT_DETECTOR`; ``None`` for
    :data:`NO_DETECTOR`. Its network runs on ``device`` where its ``from_model`` takes a
    ``device`` (the built-in ones do); a plugin's that does not runs where it chooses, and a
    warning says so.

    Raises:
        PluginError: no detector of that name is installed.
        DeepMorphError: the named detector has nothing trained for this model.
    """
    if detector is not None and not isinstance(detector, str):
        return detector
    name = detector if detector is not None else (model.meta.detector.name if model.meta.detector else DEFAULT_DETECTOR)
    if name == NO_DETECTOR:
        return None
    kind = registry.detector(name)
    if device == "cpu":
        found = kind.from_model(model)
    elif "device" in inspect.signature(kind.from_model).parameters:
        found = kind.from_model(model, device=device)
    else:
        warnings.warn(DeepMorphWarning(f"detector {name!r} takes no device: it runs where it chooses, not on {device}"),
                      stacklevel=3)  # fmt: skip
        found = kind.from_model(model)
    if found is None and detector is not None:
        raise DeepMorphError(f"detector {name!r} has nothing trained for this model")
    return found


class Locator:
    """Finds and decodes every instance of one model's drawing in photos.

    Args:
        model: the trained model.
        detector: a detector, the name of a registered one, or ``None`` for the one the bundle
            names (else the universal detector); ``"none"``: only whole images framed by their
            ink are tried.
        min_correlation: the bar an alignment must reach to be this drawing.
        registry: where detector names are looked up (default: every installed plugin).
        device: where the detector and decoder networks run (``auto``, ``cpu``, ``cuda``:
            :func:`~deepmorph_core.device.resolve_device`); alignment, reading by synthesis and
            the checks run on the CPU whatever it is.
        use_verifier: use the model's proposal verifier where it stores one
            (:mod:`~deepmorph_detect.verifier`; ``False``: as a model without one, to compare).
    """

    def __init__(
        self,
        model: DeepMorphModel,
        detector: Detector | str | None = None,
        min_correlation: float = MIN_CORRELATION,
        registry: Registry | None = None,
        device: str = "cpu",
        use_verifier: bool = True,
    ) -> None:
        self.model = model
        self.device = resolve_device(device)
        self.detector = detector_for(model, detector, registry or default_registry(), self.device)
        self.min_correlation = min_correlation
        md = model.drawing
        self.viewbox = md.drawing.viewbox
        unmorphed = md.to_svg(md.neutral_values()[0])
        # Skia when it draws this drawing as resvg does: the morph check renders a morph per
        # payload read, and resvg's PNG round trip makes that render slow
        self.renderer_name, renderer = template_renderer(unmorphed, self.viewbox, LEVELS, md.channel)
        self._reflectance_renderer = renderer
        # renders contrast-stretched as photos are (a drawing whose darkest paint is light)
        self.renderer = stretched_renderer(renderer, md.ink_level)
        self.template = Template.from_svg(unmorphed, self.viewbox, LEVELS, self.renderer)
        self.ink = InkFrame.of(self.template)
        self.morphs = MorphTemplates(model, self.viewbox, self.renderer)
        self.synthesis = MorphSynthesis(model, self.template, renderer=self.renderer)
        view_width = model.width * RECTIFY_WIDTH_FACTOR
        thickness = ink_thickness(self.template, view_width)
        self.ink_share = thickness / view_width
        # the flat sheet read more close-ups of colour drawings, none of black-and-white ones, and
        # OpenCV's fallback in flat light's quick path one more colour print, no black-and-white
        # one; a colour print's ink square can frame its darkest part alone (a shifted sweep)
        self.aligner = Aligner(
            self.template, min_correlation, thickness, view_width, flat_sheet=md.colour, blind_fallback=md.colour,
            verifier=verifier_for(model, self.device) if use_verifier else None, shifted_sweep=md.colour,
        )  # fmt: skip
        # a light that hides a faint colour fill does not hide black ink (decode_on_edges)
        self.realigns_on_edges = md.colour
        #: a blind proposer's drawing aligned below this is read by its first looks only
        self.blind_read_bar = BLIND_READ_CORRELATION if md.colour else BLIND_READ_CORRELATION_BW
        self.reader = Reader(model, self.template, self.morphs, self.synthesis, thickness, self.device)
        # the per-bit check asks at a finer width than the last look reads
        checks = MorphSynthesis(model, self.template, CHECK_WIDTH, renderer=self.renderer)
        self.checker = PayloadChecker(model, self.template, self.morphs, checks)
        self.placer = Placer(self.viewbox)
        self.frame_corners = self.aligner.frame_corners

    @functools.cached_property
    def light(self) -> TemplateLight:
        """The light on a print, estimated from the unmorphed drawing's render (what its print
        reflects, in the channel the model reads): made when a drawing first needs it."""
        md = self.model.drawing
        unmorphed = md.to_svg(md.neutral_values()[0])
        width = self.model.width * RECTIFY_WIDTH_FACTOR
        return TemplateLight(self.template, self._reflectance_renderer(unmorphed, width, self.viewbox))

    def frame(self, image: np.ndarray, camera: Camera | None) -> tuple[np.ndarray, Camera, ImagePyramid]:
        """The photo as gray (in the channel the model reads), its camera (the default one when
        none is given) and its pyramid."""
        gray = to_gray(image, self.model.drawing.channel)
        h, w = gray.shape
        if min(h, w) < MIN_IMAGE_SIDE:
            raise DeepMorphError(
                f"image of {w}x{h} pixels is too small to hold a drawing (at least {MIN_IMAGE_SIDE} pixels each way)"
            )
        return gray, camera.for_image(w, h) if camera is not None else Camera.default(w, h), ImagePyramid(gray)

    def _proposed(
        self, image: np.ndarray, camera: Camera | None
    ) -> tuple[np.ndarray, Camera, ImagePyramid, list[Aligned]]:
        """:meth:`frame`, and the detector's proposals in ``image`` that align to the drawing."""
        gray, cam, pyramid = self.frame(image, camera)
        return gray, cam, pyramid, self.aligner.verify(pyramid, self.proposals(image, gray), gray)

    def proposals(self, image: np.ndarray, gray: np.ndarray) -> list[Candidate]:
        """The detector's proposals in ``image`` (``gray``: it in the channel the model reads)."""
        *_, every = self._candidate_stages(image, gray)
        return every

    def _candidate_stages(self, image: np.ndarray, gray: np.ndarray) -> Iterator[list[Candidate]]:
        """The detector's proposals in ``image`` as they come: one list, or, from a detector that
        proposes in stages (the universal detector's photo, then its mirror image:
        :meth:`UniversalDetector.detect_in_stages <deepmorph_detect.universal.UniversalDetector.detect_in_stages>`),
        each stage's, the last holding them all."""
        # detectors read luminance: a model read in another channel hands them the photo itself
        seen = gray if is_luma(self.model.drawing.channel) else image
        if self.detector is None:
            yield []
        elif hasattr(self.detector, "detect_in_stages"):
            yield from self.detector.detect_in_stages(seen)
        else:
            yield self.detector.detect(seen)

    def aligns(self, image: np.ndarray) -> bool:
        """Whether the detector's proposals in ``image`` align to the drawing at all, read or
        not: a blind proposer's unread prints are never reported (:meth:`reports_unread`), so an
        empty :meth:`locate` alone does not say whether the print was found."""
        return bool(self.alignments(image))

    def alignments(self, image: np.ndarray) -> list[Aligned]:
        """The detector's proposals in ``image`` aligned to the unmorphed drawing, before any
        reading: the homographies the first looks rectify by."""
        return self._proposed(image, None)[3]

    def locate(
        self, image: np.ndarray, camera: Camera | None = None, soft: bool = True, first: bool = False
    ) -> list[Located]:
        """Every instance of the drawing in ``image`` (``(H, W)`` or ``(H, W, 3)``), decoded.

        A drawing whose payload is not read (``ok`` false) is reported only when it aligns at
        least :data:`UNREAD_MARGIN` above ``min_correlation``: with no payload to vouch for it,
        a weak alignment is as likely another drawing.

        Args:
            camera: intrinsics for the pose; ``None`` assumes the default field of view.
            first: stop at the first print whose payload reads, and give it alone, as a scanner
                looking for one code does (OpenCV's QR ``detectAndDecode`` reads one code). The
                proposals that align at once (:meth:`Aligner.quick_prints
                <deepmorph_detect.align.Aligner.quick_prints>`) are read first, best aligned
                first, before any proposal's wider searches: most other drawings in a photo
                take those searches to be turned away. A detector that proposes in stages
                (the universal detector: the photo, then its mirror image) has each stage's
                read before its next runs. Where none of them reads, the rest follows as
                without ``first``, each drawing read once.
        """
        gray, cam, pyramid = self.frame(image, camera)
        decoded: dict[int, tuple[Alignment, Located, bool]] = {}
        if first:
            # each stage's quick prints read before the detector's next stage runs; a proposal
            # a later stage repeats keeps its quick look, and a print read there is not read again
            taken: dict[bytes, tuple[Candidate, QuickLook | None]] = {}
            for stage in self._candidate_stages(image, gray):
                candidates, looks = self._quick_looks(pyramid, stage, gray, taken)
                for aligned in self.aligner.quick_prints(pyramid, candidates, looks):
                    if id(aligned.alignment) in decoded:
                        continue
                    located, reported = self.decode_aligned(gray, aligned, cam, soft)
                    if located.result.ok:
                        return [located]
                    decoded[id(aligned.alignment)] = (aligned.alignment, located, reported)
        else:
            candidates = self.proposals(image, gray)
            looks = self.aligner.quick_looks(pyramid, candidates, gray)
        found = self.aligner.verify(pyramid, candidates, gray, looks)
        results = self.decode_each(gray, found, cam, soft, decoded)
        if any(located.result.ok or _read_too_small(located) for located in results):
            return _first_read(results) if first else results
        # Nothing read (nor read and refused as too small): the whole image framed by its ink, a
        # scan or a print filling the frame.
        # Also where the detector's outline aligned but did not read: on a close-up of a drawing
        # whose every point may move, the alignment from that outline can absorb part of the
        # morph into the homography, and the morph check then cannot confirm a right payload.
        photo = gray
        gray, whole = self.whole_image(gray, pyramid)
        whole_results = self.decode_each(gray, whole, cam, soft)
        if not any(located.result.ok for located in whole_results):
            on_sheet = self.decode_each(photo, self.on_sheet(photo, pyramid), cam, soft)
            if any(located.result.ok for located in on_sheet) or not whole_results:
                whole_results = on_sheet
        if not found:
            return _first_read(whole_results) if first else whole_results
        read = [located for located in whole_results if located.result.ok]
        # a drawing the whole image read replaces the detector's unread reading of it
        every = read + [r for r in results if not self.aligner.seen(r.homography, [o.homography for o in read])]
        return _first_read(every) if first else every

    def whole_image(self, gray: np.ndarray, pyramid: ImagePyramid) -> tuple[np.ndarray, list[Aligned]]:
        """The whole image framed by its ink and aligned (a scan, a print filling the frame), or,
        where that does not align, framed in flat light (a sharp shadow across such a print); and
        the photo it was aligned in (``gray`` or it in flat light)."""
        whole = self.aligner.verify(pyramid, whole_frame(gray, self.ink, self.template, self.frame_corners))
        if not whole:
            flat, framed = whole_frame_in_flat_light(gray, self.ink, self.template, self.frame_corners, self.ink_share)
            if framed:
                return flat, self.aligner.verify(ImagePyramid(flat), framed)
        return gray, whole

    def on_sheet(self, gray: np.ndarray, pyramid: ImagePyramid) -> list[Aligned]:
        """The ink on the photo's paper sheet alone, framed and aligned: a print in light colours
        on a desk about as dark as its ink."""
        return self.aligner.verify(pyramid, whole_frame_on_paper(gray, self.ink, self.template, self.frame_corners))

    def every_alignment(self, image: np.ndarray) -> list[Aligned]:
        """Every alignment :meth:`locate` reads from where nothing reads: the detector's
        proposals aligned (:meth:`alignments`), the whole image framed by its ink
        (:meth:`whole_image`) and the ink on the sheet alone (:meth:`on_sheet`)."""
        gray, _, pyramid, found = self._proposed(image, None)
        return [*found, *self.whole_image(gray, pyramid)[1], *self.on_sheet(gray, pyramid)]

    def _quick_looks(
        self,
        pyramid: ImagePyramid,
        candidates: list[Candidate],
        gray: np.ndarray,
        taken: dict[bytes, tuple[Candidate, QuickLook | None]],
    ) -> tuple[list[Candidate], list[QuickLook | None]]:
        """A detector stage's ``candidates`` with their :meth:`Aligner.quick_looks
        <deepmorph_detect.align.Aligner.quick_looks>`, each outline looked at once: ``taken``
        holds the earlier stages' candidates and looks, by outline and score, and gains this
        stage's. A candidate at the place of an earlier one whose quick look aligned it (the
        universal detector's proposal averaged with its mirror image's) is that earlier one: its
        print was read there already, and is not read again."""
        # the earlier outlines aligned at once, each with its outline's homography (asked per candidate)
        aligned = [
            ((c, look), self.aligner.homography(c.corners))
            for c, look in taken.values()
            if look is not None and look.final and self.aligner.accepts(look.alignment)
        ]
        out: list[tuple[Candidate, QuickLook | None]] = []
        for cand in candidates:
            key = np.asarray(cand.corners, np.float64).tobytes() + np.float64(cand.score).tobytes()
            if key not in taken:
                H = self.aligner.homography(cand.corners)
                there = [earlier for earlier, outline in aligned if self.aligner.seen(H, [outline])]
                taken[key] = there[0] if there else (cand, self.aligner.quick_looks(pyramid, [cand], gray)[0])
            out.append(taken[key])
        return [c for c, _ in out], [look for _, look in out]

    def decode_each(
        self,
        gray: np.ndarray,
        found: list[Aligned],
        cam: Camera,
        soft: bool,
        decoded: dict[int, tuple[Alignment, Located, bool]] | None = None,
    ) -> list[Located]:
        """Each aligned drawing decoded (:meth:`decode_aligned`), those reported kept.
        ``decoded``: what was decoded already, by the alignment's ``id`` (with the alignment, so
        that the id stays its own): each of those is taken from there, not decoded again."""
        results = []
        for aligned in found:
            known = decoded.get(id(aligned.alignment)) if decoded else None
            located, reported = known[1:] if known else self.decode_aligned(gray, aligned, cam, soft)
            if reported:
                results.append(located)
        return results

    def decode_aligned(self, gray: np.ndarray, aligned: Aligned, cam: Camera, soft: bool) -> tuple[Located, bool]:
        """An aligned drawing decoded (:meth:`decode_drawing`), a detector's outline not read
        there aligned again on the print's edges and decoded (:meth:`decode_on_edges`), and
        whether it is reported: a payload read or refused as too small, or one not read where
        :meth:`reports_unread` says so."""
        cand, alignment = aligned.candidate, aligned.alignment
        located = self.decode_drawing(
            gray, aligned.pyramid, alignment, cand.score, cam, cand.source, soft, blind=cand.blind
        )
        if not located.result.ok and self.aligns_on_edges(cand, alignment):
            located = self.decode_on_edges(gray, aligned, cam, soft) or located
        located.needs_px = float(self.model.smallest_print_px)  # narrower prints lose detail
        located.needs_every_way = self.needs_every_way
        refused = self.refuses_reading(located)
        if refused:  # a reading not vouched for at its print's size: too small, never a payload
            located.result = refused_result(located.result)
        return located, located.result.ok or refused or self.reports_unread(located, cand, gray.shape[:2])

    def aligns_on_edges(self, cand: Candidate, alignment: Alignment) -> bool:
        """Whether a detector's outline whose print was not read is aligned again on the print's
        edges (:meth:`decode_on_edges`): for a colour drawing (:attr:`realigns_on_edges`), whose
        fills can differ from the paper as little as the light falls off across the sheet; not
        for a black-and-white one, whose black ink no such light hides (in 200 1280x720 scenes of
        the `--pixels 200` codepen it read no print there), nor for a print aligned too narrow to
        read."""
        return self.realigns_on_edges and cand.homography is None and not self.aligned_too_narrow(alignment)

    def decode_on_edges(self, gray: np.ndarray, aligned: Aligned, cam: Camera, soft: bool) -> Located | None:
        """A detector's outline whose print :meth:`decode_drawing` did not read, aligned again from
        that outline on the print's edges alone (:meth:`Aligner.on_edges
        <deepmorph_detect.align.Aligner.on_edges>`: the slow light subtracted from the photo and
        the template) and decoded there in the light it was decoded in before (its readings,
        turns and checks as at any alignment); ``None`` where it aligns so below the bar or does
        not read. The photo's own ECC fits one light to the whole print, and a colour drawing
        whose fills differ little from its paper, under a light that falls off across the sheet
        about as much, aligns there into a bent outline even from its true pose."""
        cand = aligned.candidate
        edged = self.aligner.on_edges(gray, cand)
        if edged is None:
            return None
        located = self._decode_at(gray, aligned.pyramid, edged, cand.score, cam, cand.source, soft, cand.blind)
        return located if located.result.ok else None

    def reports_unread(self, located: Located, candidate: Candidate, image_size: tuple[int, int]) -> bool:
        """Whether a drawing whose payload is not read is reported: with no payload to vouch for
        it, only its alignment does.

        * A blind proposer's (``Candidate.blind``, the universal detector): never. It proposes
          every drawing, and other ones align to complex drawings at 0.80-0.89.
        * The whole image's, framed by its ink (which does not know the drawing): only where the
          print's frame is :data:`FILLS_FRAME` to ``1 / FILLS_FRAME`` of the image's width and
          the photo shows it whole (:meth:`shown_whole`), what that framing is for (a scan, a
          print filling the frame), and aligns at
          :data:`UNREAD_BLIND_CORRELATION` or better, or :data:`UNREAD_MARGIN` above
          ``min_correlation`` when too small to read (a tiny scan: the answer the user needs is
          its size).
        * A detector's that knows the drawing: :data:`UNREAD_MARGIN` above ``min_correlation``.

        ``image_size`` is the photo's ``(height, width)``.
        """
        if candidate.blind:
            return False
        bar = self.min_correlation + UNREAD_MARGIN
        if candidate.homography is not None:
            image_width = image_size[1]
            width = located.width_px
            if width is None or not FILLS_FRAME * image_width <= width <= image_width / FILLS_FRAME:
                return False
            if located.homography is None or not self.shown_whole(located.homography, image_size):
                return False
            if not located.too_small:
                bar = UNREAD_BLIND_CORRELATION
        return located.correlation >= bar

    def refuses_reading(self, located: Located) -> bool:
        """Whether the payload read at ``located`` (its own, or one fused over frames) is refused
        for the print's width in the photo (:func:`refuses_narrow_reading`, by this model)."""
        return refuses_narrow_reading(located, self.model.print_px, self.model.drawing.colour)

    @property
    def needs_every_way(self) -> bool:
        """Whether a print's width counts along its tilt too (:attr:`Located.needs_every_way`): a
        colour drawing's (:func:`refuses_narrow_reading`). A ``--pixels`` model's width is the
        head-on one it was trained and validated for."""
        return self.model.print_px is None and self.model.drawing.colour

    def keeps_only_uncorrected(self, homography: np.ndarray) -> bool:
        """Whether a print at ``homography`` keeps only a reading without corrections
        (:func:`refuses_narrow_reading`): a colour print narrower than the decoder's frame along
        any direction."""
        return self.needs_every_way and along_tilt_px(homography, self.frame_corners) < self.model.smallest_print_px

    def relights(self, alignment: Alignment) -> bool:
        """Whether a print at ``alignment`` not read in the photo is read again in the light its
        template shows (:class:`~deepmorph_detect.template_light.TemplateLight`): not a colour
        print narrower than the decoder's frame along any direction (:meth:`keeps_only_uncorrected`).
        There the light read off the drawing itself, smoothed over a few pixels, takes up the
        morph's edges, and the photo so lit reads wrong words the per-bit check passes: in 8000
        hard 640x480 scenes of four colour models, 10 of the 67 readings so lit from such prints
        that passed every check were wrong (one without corrections, which the size rule keeps),
        none of the 88 from wider prints."""
        return not self.keeps_only_uncorrected(alignment.homography)

    def aligned_too_narrow(self, alignment: Alignment) -> bool:
        """Whether ``alignment`` puts a print in the photo too narrow to keep any reading
        (:func:`refuses_narrow_reading`), by :data:`NARROW_SHARE` of the width: one trained for a
        smallest width (``print_px``) at under that width, a colour one at under
        :data:`COLOUR_FLOOR_SHARE` of the decoder's frame along its tilt. It is too small
        whatever it reads, so only its first looks are tried, enough to tell that it is the
        drawing."""
        needs = self.model.print_px
        if needs is not None:
            return across_px(alignment.homography, self.frame_corners) < NARROW_SHARE * needs
        if not self.needs_every_way:
            return False
        floor = COLOUR_FLOOR_SHARE * self.model.smallest_print_px
        return along_tilt_px(alignment.homography, self.frame_corners) < NARROW_SHARE * floor

    def shown_whole(self, homography: np.ndarray, image_size: tuple[int, int]) -> bool:
        """Whether ``homography`` puts the drawing in the photo of ``image_size`` ``(height,
        width)`` as a print the photo shows whole: its ink inside the photo, at most
        :data:`INK_OUTSIDE` of its width out, and its outline one a flat print makes
        (:meth:`~deepmorph_detect.align.Aligner.bent`)."""
        ink = project(homography, self.ink.box)
        slack = INK_OUTSIDE * measure_width(ink)
        height, width = image_size
        inside = bool((ink >= -slack).all() and (ink <= np.array([width, height]) + slack).all())
        return inside and not self.aligner.bent(homography, image_size)

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
        """Read and check one aligned drawing, and place it: the first reading whose payload
        passes every check wins; without one, the first that passed the CRC (its ``ok``
        withdrawn by its check), else the most confident reading. ``blind``: proposed by a
        detector that does not know the drawing (``Candidate.blind``): a confident reading is
        also asked whether the print is the drawing at all, unless its morph fits the photo as
        no other drawing does (:meth:`PayloadChecker.check
        <deepmorph_detect.check.PayloadChecker.check>`).

        A print aligned too narrow to read (:meth:`aligned_too_narrow`) is read by the first looks
        alone, at each symmetric turn, and nothing below is tried.
        A drawing that looks the same turned (``Template.symmetric_turns``: a print aligns as
        well at each of those turns, and which one the alignment ended at is chance) is read
        again at each such turn until a reading passes, the first looks at every turn before the
        later looks at any; the turn that reads also gives the pose.
        A weak reading there (not :attr:`PayloadCheck.settled <deepmorph_detect.check.PayloadCheck.settled>`:
        read with corrections or unsure, and not vouched for) is compared with those
        at the other turns: read at the wrong turn, such a drawing shows its true morph turned,
        which can land on another code word with corrections; the reading with the fewest
        corrections, then the most confident, wins.
        A print still not read but aligned at :data:`UNREAD_BLIND_CORRELATION` or better is
        aligned again from each other turn of its frame and read at the best
        (:meth:`Aligner.other_turn <deepmorph_detect.align.Aligner.other_turn>`): a drawing that
        nearly looks the same turned can align at the wrong turn well enough to be found. A weak
        reading aligned that well is compared likewise with the reading at the best other turn
        aligning at most :data:`TURN_TIE_MARGIN` worse (its first looks; only a stronger reading
        is checked there, and wins): at the wrong turn such a drawing can read another word, with
        more corrections than the true one at the right turn.
        A print still not read is aligned again as a flat sheet (:meth:`Aligner.as_flat_sheet
        <deepmorph_detect.align.Aligner.as_flat_sheet>`: no perspective, so a cast shadow's edge
        cannot bend a corner of its outline), and where that aligns at
        :data:`BLIND_READ_CORRELATION` or better, all of the above is done there; the flat
        sheet's outline then replaces the bent one for what follows.
        A print still not read but aligned at :data:`BLIND_READ_CORRELATION` or better is aligned
        again in the light its template shows (:class:`~deepmorph_detect.template_light.TemplateLight`:
        a cast shadow bends the alignment and reads as ink; not on a colour print too narrow for
        it, :meth:`relights`), and all of the above is done again
        in the photo so lit; a reading there never skips the per-bit check (the light came from
        the drawing itself, so any morph near it fits that photo well), which a weak one (read
        with corrections, or not confident) is asked in full.
        A print still not read is aligned again in a grid of light
        (:func:`~deepmorph_detect.light_field.realign_in_light_field`: a cast shadow's edge bends
        ECC's alignment, which fits one light for the whole print) and all of the above is done
        there, each reading checked in the shadow's light alone and bit by bit
        (``in_shadow`` of :meth:`PayloadChecker.check <deepmorph_detect.check.PayloadChecker.check>`):
        ECC's morph fit, started there, slides back to the bent pose, where a wrong word can
        pass the smooth light's rules.
        """
        if self.aligned_too_narrow(alignment):
            return self._decode_at(gray, pyramid, alignment, score, cam, source, soft, blind, first_looks_only=True)
        located = self._decode_at(gray, pyramid, alignment, score, cam, source, soft, blind)
        if located.result.ok:
            return located
        sheet = self.aligner.as_flat_sheet(pyramid, alignment)
        if sheet is not None and sheet.correlation >= BLIND_READ_CORRELATION:
            again = self._decode_at(gray, pyramid, sheet, score, cam, source, soft, blind)
            if again.result.ok:
                return again
            alignment = sheet
        if alignment.correlation < (self.blind_read_bar if blind else BLIND_READ_CORRELATION):
            return located
        lit = self.light.align(gray, alignment.homography, self.aligner.accepts) if self.relights(alignment) else None
        if lit is not None:
            again = self._decode_at(gray, lit[0], lit[1], score, cam, source, soft, blind, alignment.correlation)
            if again.result.ok:
                return again
        in_field = realign_in_light_field(pyramid, alignment, self.template)
        if in_field is None:
            return located
        again = self._decode_at(gray, pyramid, in_field, score, cam, source, soft, blind, in_shadow=True)
        return again if again.result.ok else located

    def _decode_at(
        self,
        gray: np.ndarray,
        pyramid: ImagePyramid,
        alignment: Alignment,
        score: float,
        cam: Camera,
        source: str,
        soft: bool,
        blind: bool,
        relit_from: float | None = None,
        in_shadow: bool = False,
        first_looks_only: bool = False,
    ) -> Located:
        """:meth:`decode_drawing` in one photo (the photo itself, or the photo lit by the
        template's light, ``relit_from`` the alignment in the photo itself): the readings at the
        alignment, at the symmetric turns and at the other turns. ``in_shadow``: the alignment is
        in a grid of light, and every reading is checked in the shadow's light alone.
        ``first_looks_only``: the first looks at each symmetric turn, and nothing else."""
        turned = [replace(alignment, homography=alignment.homography @ t) for t in self.template.symmetric_turns]
        turns = [alignment, *turned]
        # The first looks at every turn before the later looks at any: which turn the alignment
        # ended at is chance, and a first look at the right turn reads most prints.
        readings: dict[int, tuple[np.ndarray, PayloadCheck, np.ndarray]] = {}
        looked: dict[int, tuple[list[np.ndarray], list[Reading]]] = {}  # each turn's views, first looks

        def first_looks(k: int) -> tuple[list[np.ndarray], list[Reading]]:
            if k not in looked:
                views = self._views(gray, pyramid, turns[k].homography, source)
                looked[k] = views, self.reader.first_looks(views, soft)
            return looked[k]

        def unrivalled(k: int) -> bool:
            # no other turn's first look reads a word that passes the CRC (PayloadChecker.check)
            return not any(r.result.ok for j in range(len(turns)) if j != k for r in first_looks(j)[1])

        for first_only in (True, False) if len(turns) > 1 and not first_looks_only else (first_looks_only,):
            order = list(enumerate(turns))
            if not first_only and len(turns) > LATER_LOOK_TURNS:
                # the later looks at the turns whose first looks read most confidently
                order = sorted(order, key=lambda kt: -_confidence(readings.get(kt[0])))[:LATER_LOOK_TURNS]
            for k, at in order:
                if any(r[1].settled for r in readings.values()):
                    break
                if k in readings and readings[k][1].status == "passed":
                    continue  # its later looks would end at the same passing reading
                readings[k] = self._read_and_check(
                    gray,
                    pyramid,
                    at,
                    source,
                    soft,
                    blind,
                    relit_from,
                    in_shadow=in_shadow,
                    first_only=first_only,
                    looked=first_looks(k),
                    unrivalled=functools.partial(unrivalled, k),
                )
        H, checked, probs = readings[0]
        for k in sorted(readings)[1:]:
            other = readings[k]
            if other[1].result.ok and (not checked.result.ok or _stronger(other[1].result, checked.result)):
                H, checked, probs = other
        if not checked.settled and _turns_disagree([r[1] for r in readings.values()], checked.result):
            checked = replace(checked, result=replace(checked.result, ok=False), status=TURN_CONFLICT)
        if first_looks_only:
            return self.placer.place(gray.shape, H, checked, probs, alignment.correlation, score, cam, source)
        if (
            not checked.settled
            and checked.status != TURN_CONFLICT
            and alignment.correlation >= UNREAD_BLIND_CORRELATION
        ):
            margin = TURN_TIE_MARGIN if checked.result.ok else 0.0
            realigned = self.aligner.other_turn(pyramid, alignment, margin)
            if realigned is not None:
                # a weak reading gives way only to a stronger one: only those are checked there
                than = checked.result if checked.result.ok else None
                other = self._read_and_check(
                    gray, pyramid, realigned, source, soft, blind, relit_from, stronger_than=than, in_shadow=in_shadow
                )
                if other[1].result.ok:
                    (H, checked, probs), alignment = other, realigned
        return self.placer.place(gray.shape, H, checked, probs, alignment.correlation, score, cam, source)

    def _read_and_check(
        self,
        gray: np.ndarray,
        pyramid: ImagePyramid,
        alignment: Alignment,
        source: str,
        soft: bool,
        blind: bool,
        relit_from: float | None = None,
        stronger_than: DecodeResult | None = None,
        in_shadow: bool = False,
        first_only: bool = False,
        looked: tuple[list[np.ndarray], list[Reading]] | None = None,
        unrivalled: Callable[[], bool] | None = None,
    ) -> tuple[np.ndarray, PayloadCheck, np.ndarray]:
        """:meth:`decode_drawing`'s readings and checks at one alignment: the homography to
        place the drawing by (the passed payload's morph fit, else the alignment's), the
        verdict, and the code bits' probabilities. ``relit_from``: in a photo lit by the
        template's light, the alignment in the photo itself (:meth:`PayloadChecker.check
        <deepmorph_detect.check.PayloadChecker.check>`); a reading there that needed more than
        :data:`~deepmorph_detect.check.RELIT_MAX_CORRECTIONS` corrections is not checked and
        counts as not read. ``stronger_than``: only readings
        stronger than this one are checked (and can pass); the others count as not read.
        ``in_shadow``: checked in the shadow's light alone (:meth:`_decode_at`). ``first_only``:
        the first looks alone. ``looked``: the views at this alignment and their first looks,
        where already read. ``unrivalled``: asked for a reading the code corrected, whether no
        other symmetric turn's first look reads a word that passes the CRC (a drawing that looks
        the same turned may then be vouched for, ``unrivalled_turn`` of
        :meth:`PayloadChecker.check <deepmorph_detect.check.PayloadChecker.check>`)."""
        H = alignment.homography
        whole = source == WHOLE_FRAME
        views, firsts = looked if looked is not None else (self._views(gray, pyramid, H, source), None)
        readings: list[Reading] = []
        checked: PayloadCheck | None = None  # the verdict on the first payload that passed the CRC
        probs = np.full(self.model.codec.spec.code_bits, 0.5, dtype=np.float32)
        # a reading asked only whether it beats another: the first looks are enough
        weakly_blind = blind and alignment.correlation < self.blind_read_bar
        first_only = first_only or weakly_blind or stronger_than is not None
        # a print whose readings with corrections are refused (keeps_only_uncorrected): a passing
        # one is kept aside while the looks go on for one without; without such a one, it is
        # what is returned, and refused as too small
        only_uncorrected = self.keeps_only_uncorrected(H)
        aside: tuple[np.ndarray, PayloadCheck, np.ndarray] | None = None
        for reading, bitwise in self.reader.looks(pyramid, H, views, readings, soft, first_only, firsts):
            readings.append(reading)
            if not reading.result.ok or (stronger_than is not None and not _stronger(reading.result, stronger_than)):
                continue
            if relit_from is not None and reading.result.corrected_bits > RELIT_MAX_CORRECTIONS:
                continue  # repaired too far to vouch for in a light read off the drawing itself
            repaired = only_uncorrected and reading.result.corrected_bits > 0
            if repaired and aside is not None:
                continue  # refused too were it to pass
            attempt = self.checker.check(
                pyramid,
                H,
                reading.result,
                alignment,
                bitwise,
                blind,
                whole_frame=whole,
                relit_from=relit_from,
                in_shadow=in_shadow,
                probabilities=reading.probabilities,
                unrivalled_turn=bool(reading.result.corrected_bits and unrivalled is not None and unrivalled()),
            )
            if attempt.status == "passed" and repaired:
                aside = (attempt.fit.homography, attempt, reading.probabilities)
                continue
            if checked is None or attempt.status == "passed":
                checked, probs = attempt, reading.probabilities
            if attempt.status == "passed":
                H = attempt.fit.homography
                break
        if aside is not None and (checked is None or checked.status != "passed"):
            return aside
        if checked is None:  # none passed the CRC (and beat ``stronger_than``): report the most confident
            if readings:
                best = max(readings, key=lambda r: r.result.confidence)
                result, probs = best.result, best.probabilities
            else:
                result = self.model.codec.decode(probs, soft=soft)
            checked = PayloadCheck(replace(result, ok=False) if result.ok else result, None, "not run")
        return H, checked, probs

    def _views(self, gray: np.ndarray, pyramid: ImagePyramid, H: np.ndarray, source: str) -> list[np.ndarray]:
        """The views a drawing aligned at ``H`` is read in: rectified, and a drawing that fills
        the frame (``source`` :data:`WHOLE_FRAME`) also as it is, framed by its ink: a full
        homography fitted to the unmorphed drawing can absorb part of a morph whose every point
        moves (no fixed elements); the better-verified reading wins."""
        views = [self.reader.rectify(pyramid, H)]
        if source == WHOLE_FRAME:
            views.append(gray)
        return views

    def check_payload(
        self,
        image: np.ndarray | ImagePyramid,
        homography: np.ndarray,
        result: DecodeResult,
        unmorphed: Alignment | None = None,
        bitwise: bool | None = None,
    ) -> PayloadCheck:
        """The checks of a decoded payload (:meth:`PayloadChecker.check
        <deepmorph_detect.check.PayloadChecker.check>`): what frame fusion asks of a payload
        fused over frames, and what benchmarks ask of given payloads."""
        return self.checker.check(image, homography, result, unmorphed, bitwise)

    def __repr__(self) -> str:
        detector: Any = getattr(self.detector, "name", None)
        return f"Locator({self.model.meta.drawing_name!r}, detector={detector!r}, renderer={self.renderer_name!r})"


def refuses_narrow_reading(located: Located, trained_px: int | None, colour: bool) -> bool:
    """Whether the payload read from a print narrower than its model reads well
    (:attr:`Located.too_narrow`) is refused, the print reported too small instead.

    * A model trained for prints ``trained_px`` wide (``train --pixels``): always. It was never
      validated on narrower ones.
    * A ``colour`` drawing: where its reading needed corrections, and the print is narrower than
      the decoder's frame along any direction (:attr:`Located.needs_every_way`: a tilt
      foreshortens it along one); and any reading, where the print is narrower than
      :data:`COLOUR_FLOOR_SHARE` of the frame so. There a colour print's edges (fainter than
      black ink's) leave readings whose corrections the code lends to noise, and the per-bit
      check cannot tell them apart. In 7000 hard 640x480 scenes of four colour models all but
      one of the wrong payloads came from such prints (57-135 px wide head-on, 22-83 px along
      their tilt), read with 1-5 corrections but one (26 px along its tilt, none). Right words
      from prints that narrow deviate as far (up to 0.94) as the wrong ones (0.30-1.00). Black
      ink reads there without a wrong payload (``bench/print_pixels.py``).
    """
    if not (located.result.ok and located.too_narrow):
        return False
    if trained_px is not None:
        return True
    if not colour:
        return False
    return located.result.corrected_bits > 0 or located.along_tilt_px < COLOUR_FLOOR_SHARE * located.needs_px


def _first_read(results: list[Located]) -> list[Located]:
    """The first of ``results`` whose payload reads, alone; all of them where none reads."""
    read = [located for located in results if located.result.ok]
    return read[:1] or results


def _read_too_small(located: Located) -> bool:
    """Whether ``located`` was read, and its payload passed every check, but is refused as too
    small: the drawing is found, and a whole image framed by its ink would not find it again."""
    return located.too_small and located.morph_check == "passed"


def _turns_disagree(checks: list[PayloadCheck], chosen: DecodeResult) -> bool:
    """Whether the ``chosen`` reading passed and a reading at another turn passed every check
    with another payload (:data:`TURN_CONFLICT`)."""
    return chosen.ok and any(c.result.ok and not np.array_equal(c.result.payload, chosen.payload) for c in checks)


def _confidence(reading: tuple[np.ndarray, PayloadCheck, np.ndarray] | None) -> float:
    """A turn's first-look confidence (``-1`` for a turn not read)."""
    return -1.0 if reading is None else float(reading[1].result.confidence)


def _stronger(a: DecodeResult, b: DecodeResult) -> bool:
    """Whether reading ``a`` is stronger than ``b``: fewer corrected bits, then more confident."""
    return (a.corrected_bits, -a.confidence) < (b.corrected_bits, -b.confidence)


__all__ = [
    "DEFAULT_DETECTOR",
    "NO_DETECTOR",
    "UNREAD_MARGIN",
    "UNREAD_BLIND_CORRELATION",
    "TURN_TIE_MARGIN",
    "TURN_CONFLICT",
    "FILLS_FRAME",
    "NARROW_SHARE",
    "COLOUR_FLOOR_SHARE",
    "INK_OUTSIDE",
    "BLIND_READ_CORRELATION",
    "BLIND_READ_CORRELATION_BW",
    "Locator",
    "detector_for",
    "refuses_narrow_reading",
]
