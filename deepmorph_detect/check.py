"""Checking a decoded payload against the photo: does the payload's morph explain the print?

A payload that passes the CRC is checked once more, by synthesis. The drawing morphed with that
payload is rendered and aligned to the photo, and must fit it better than the unmorphed drawing
does (:meth:`PayloadChecker.fit_morph`); else its ``ok`` is withdrawn. A payload unrelated to
the print (what a CRC collision on clutter gives) fails this almost always; a near miss next to
the true payload fails it only sometimes. A payload read with corrections, or with low
confidence, is then checked bit by bit (:mod:`deepmorph_detect.synthesis`), which catches near
misses; where the decoder is trusted (:meth:`PayloadChecker.screens`), first on the few bits
where a near miss would differ. The alignment to the decoded morph is also exact where the
unmorphed one absorbed the morph, so the pose comes from it.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from deepmorph_core.codec import DecodeResult
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_detect.align import bent_outline
from deepmorph_detect.camera import viewbox_corners
from deepmorph_detect.fastrender import Renderer
from deepmorph_detect.light_field import align_in_light_field
from deepmorph_detect.refine import LEVELS, Alignment, ImagePyramid, Template, refine_at
from deepmorph_detect.synthesis import MAX_DEVIATION, BitEvidence, MorphSynthesis, morph_template

MORPH_WIDTH = LEVELS[-1]  # template width of the alignment to the decoded morph
MIN_MORPH_GAIN = 0.0  # the decoded morph must correlate better than the unmorphed drawing by more
# ... and a colour drawing's payload the code had to correct by at least this: faint edges let
# the decoder's noise reach a word the CRC passes, and two such wrong payloads in hard scenes
# gained 0.00002 and 0.00015, where 629 of 637 right corrected words of three colour models
# gained 0.0005 or more (``pink-heart``: 0.0011 and more)
REPAIRED_COLOUR_MORPH_GAIN = 0.0005
RECHECK_ITERATIONS = 20  # ECC iterations of the longer refit when the decoded morph does not win at once
MORPH_CACHE = 64  # rendered morph templates kept (a video shows the same payloads again and again)
# a payload read without corrections but less confident than this is checked bit by bit too:
# few right readings fall below it, while a CRC collision read without corrections has several
# bits wrong, which pull its confidence under it
CHECK_BELOW_CONFIDENCE = 0.97
# a reading of a blind proposer's drawing (the universal detector's, which proposes every drawing)
# skips the per-bit check only where, besides not being weak, its morph fits the photo at least
# this well: prints of the drawing fit a median 0.985 (medium) and 0.947 (hard), while other
# drawings and clutter align to it at 0.89 at most (10,000 scenes without a print)
TRUSTED_MORPH_FIT = 0.95
# ... and below it is asked only whether its morph explains the photo where its bits act where the
# drawing aligned at least this well (unmorphed): other drawings align to a bar chart at up to 0.75,
# and where they do, the whole per-bit check stays (the deviation alone was measured on too few
# CRC passes of other drawings to stand alone there)
DRAWING_LIKE_ALIGNMENT = 0.8
# a black-and-white drawing's reading of the whole image framed by its ink that the code had to
# correct is refused where the unmorphed drawing aligned to the photo below this: a `--pixels 200`
# chip accepted a payload so from a photo of another icon filling the frame (aligned at 0.675, 2
# corrections; 1 in 30,000 unrelated images), where the 190 such right readings of six models'
# 2400 close-ups aligned at 0.843 or better (every whole-frame one at 0.804 or better); colour
# drawings are not held to it: in 12,000 close-ups of two colour models 2 right ones passed below
# it (0.727, 0.749) and the other rules refused all 41 wrong ones there
WHOLE_FRAME_REPAIRED_ALIGNMENT = 0.8
# a confident reading of the whole image framed by its ink (which does not know the drawing either)
# is asked whether its morph explains the photo where its morph fits below this: in 10,000 scenes
# without a print, CRC passes of other drawings and clutter fitted a bar chart's morph at 0.72 at
# most, and one there (0.60) passed; of 2,400 close-ups read, 4 whole-frame readings fitted below
# it, 2 of them not explained (a face, hard)
WHOLE_FRAME_TRUSTED_FIT = 0.8
# a nearest rival differing in at most this share of the code bits has those asked first, the rest
# only where they show the rival's (:meth:`PayloadChecker.rival_deviation`): the ghost's rivals
# (5-8 of 38 bits) cost 21 ms that way against 54 ms for the whole word, none going on to it; the
# bar chart's (5 of 16) cost about as much as the whole word, and 17 of 43 went on to it
RIVAL_BITS_FIRST_SHARE = 0.25
# a word the check withdraws is asked again in a cast shadow's light (:meth:`PayloadChecker.check`):
# its morph fits aligned in a grid of light (:mod:`~deepmorph_detect.light_field`),
# its bits asked in a SHADOW_GRID x SHADOW_GRID one. From the simulator's pose on reading's 18
# medium close-ups the chain missed, 0 right words passed the check as it is, 9 asked so (the grid
# was chosen with the grid's own contrast and brightness, where 4 and 6 passed 8 each)
SHADOW_GRID = 4
# a word read with corrections in a photo lit by the drawing's own light (``relit_from``) passes the
# rival rule only where its nearest rival leaves at least this many times as much of the photo
# unexplained: that light, read off the drawing at its alignment, fits every morph near it. There a
# wrong word beat its rival by 1.08x (a crystal oscillator's print 273 px wide under a cast shadow,
# aligned 7 % off); of 17 right corrected words so lit in 8000 hard scenes of four colour models,
# 2 beat theirs by less (1.11x, 1.13x; a later look read one of them again), the rest by 1.20x or more
RELIT_RIVAL_MARGIN = 1.15
# a reading in such a photo that needed more corrections than this is not checked there at all
# (:meth:`Locator._read_and_check <deepmorph_detect.locate.Locator._read_and_check>`): a crystal
# oscillator's wrong word, read there with 4 corrections (confidence 0.86, its morph's gain 0.0005,
# its nearest rival not shown), passed every rule in hard scenes; of 127 right words read there in
# 11,000 hard scenes of four colour models (seeds 8-12), 2 needed 4 and none more
RELIT_MAX_CORRECTIONS = 3
# a word the code corrected skips the per-bit check, as a confident word read without corrections
# does, only where the decoder's own probabilities still prefer it to every other code word by at
# least this (``DecodeResult.rival_log_odds``, total log-odds; :meth:`PayloadChecker.vouches_for_repair`
# says for which models): the 284 wrong words that passed the CRC in 47,800 close-ups, scenes and
# unrelated images of three `--pixels 200` models showed at most 12.7 (56 of them read at 0.97 or
# more), while 65-69 % of the right words corrected within t in hard 240-px close-ups meet every bar.
# Near misses checked as CRC collisions (`bench/near_misses.py`) can meet them: 2 of cloud-snow's 168
# that reached the bits in 2000 hard close-ups, both of which the per-bit check contradicts (about
# 0.04 wrong payloads per 10,000 such close-ups with CRC-8)
TRUSTED_REPAIR_LOG_ODDS = 20.0
# a weak word of a model the decoder is trusted for (:meth:`PayloadChecker.trusts_its_decoder`) is
# first asked about a few bits only (:meth:`PayloadChecker.screens`): those the code corrected and
# the SCREEN_LEAST_SURE the decoder was least sure of, where a near miss differs from the true word
# (it differs where the code corrected and where the decoder misread); it passes where the photo
# shows each of them by at least SCREEN_MIN_EVIDENCE, else the whole per-bit check decides. Of the
# 797 near misses in 4000 hard 240-px close-ups of two `--pixels 200` models decoded CRC-blind and
# checked as CRC collisions (`bench/near_misses.py`), 716 reached the bits and 2 passed on it, both
# of which the whole check withdraws (it passes 1 itself); in 30,000 close-ups read by the chain,
# 20,609 of 28,684 weak right words passed on it, 0 wrong payloads; their 1280x720 frames took
# 0.45-0.76x as long
SCREEN_LEAST_SURE = 8
SCREEN_MIN_EVIDENCE = 0.3


def is_weak(result: DecodeResult) -> bool:
    """Whether a payload that passed the CRC was read with corrections or with less confidence
    than :data:`CHECK_BELOW_CONFIDENCE`: where CRC collisions are, so it is checked bit by bit
    (unless :func:`is_trusted_repair`)."""
    return result.corrected_bits > 0 or result.confidence < CHECK_BELOW_CONFIDENCE


def is_trusted_repair(result: DecodeResult, morph_fit: float, max_corrections: int) -> bool:
    """Whether a payload the code corrected is as trusted as a confident one read without
    corrections: corrected within ``max_corrections`` (the code's own ``t``: words Chase's search
    found beyond it are where near misses come from), read as confidently
    (:data:`CHECK_BELOW_CONFIDENCE`), preferred by the decoder's own probabilities to every other
    code word by :data:`TRUSTED_REPAIR_LOG_ODDS`, and its morph fitting the photo
    (``morph_fit``) as only prints of the drawing do (:data:`TRUSTED_MORPH_FIT`)."""
    return (
        0 < result.corrected_bits <= max_corrections
        and result.confidence >= CHECK_BELOW_CONFIDENCE
        and result.rival_log_odds >= TRUSTED_REPAIR_LOG_ODDS
        and morph_fit >= TRUSTED_MORPH_FIT
    )


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
        status: ``passed``, ``failed`` (the morph fits no better than the unmorphed drawing, a
            repaired whole-frame reading is not this drawing: :meth:`PayloadChecker.repaired_off_the_drawing`,
            or a repaired word lies on an outline no flat print makes: :func:`repaired_on_a_bent_outline`),
            ``contradicted`` (it does, but the photo does not show its code bits:
            :attr:`~deepmorph_detect.synthesis.BitEvidence.agrees` is false), ``not run``
            (the CRC had failed), or ``turn conflict`` (another turn of a drawing that looks the
            same turned passed with another payload: :data:`~deepmorph_detect.locate.TURN_CONFLICT`).
        bits: the per-bit evidence, when it was asked for.
        vouched: a payload the code corrected, passed without the per-bit check because the
            decoder is as sure of it as of a confident word read without corrections
            (:meth:`PayloadChecker.vouches_for_repair`).
        screened: a weak payload passed on the few bits where a near miss would differ
            (:meth:`PayloadChecker.screens`), without the whole per-bit check.
    """

    result: DecodeResult
    fit: MorphFit | None
    status: str
    bits: BitEvidence | None = None
    vouched: bool = False
    screened: bool = False

    @property
    def settled(self) -> bool:
        """Whether the payload passed and is not weak (:func:`is_weak`), or was vouched for: no
        reading at another turn of the print can beat it."""
        return self.result.ok and (self.vouched or not is_weak(self.result))


class MorphTemplates:
    """The drawing morphed by code words, rendered at :data:`MORPH_WIDTH`; the last
    :data:`MORPH_CACHE` are kept (a video shows the same payloads again and again)."""

    def __init__(self, model: DeepMorphModel, viewbox: tuple[float, float, float, float], renderer: Renderer) -> None:
        self.model = model
        self.viewbox = viewbox
        self.renderer = renderer
        self._cache: OrderedDict[bytes, Template] = OrderedDict()

    def of_payload(self, payload: np.ndarray) -> Template:
        """The drawing morphed with ``payload``."""
        return self.of_code(self.model.codec.encode(np.asarray(payload, dtype=np.uint8)))

    def of_code(self, code_bits: np.ndarray) -> Template:
        """The drawing morphed by ``(N_b,)`` code bits (a code word, or a misread one)."""
        code = np.asarray(code_bits, dtype=np.uint8)
        key = code.tobytes()
        template = self._cache.get(key)
        if template is None:
            template = morph_template(self.model, self.viewbox, code, MORPH_WIDTH, self.renderer)
            self._cache[key] = template
            if len(self._cache) > MORPH_CACHE:
                self._cache.popitem(last=False)
        self._cache.move_to_end(key)
        return template


def repaired_on_a_bent_outline(homography: np.ndarray, template: Template, pyramid: ImagePyramid) -> bool:
    """Whether a word the code corrected was read at an outline no flat print makes in the photo
    (:func:`~deepmorph_detect.align.bent_outline`, as :meth:`Aligner.bent
    <deepmorph_detect.align.Aligner.bent>` asks of alignments). A cast shadow's edge can bend the alignment,
    and a bent homography takes up part of a wrong word's morph: the code's corrections then
    complete the wrong word, and the per-bit check, asked at the same bent outline, agrees (a
    `reading` at 5 bits, hard close-up, 17 % of the print's width off). Of 1499 right words reported
    from 1600 colour close-ups none lay on such an outline (the furthest at 0.034); where a right
    word did and failed so, another alignment of the same print read it. A word read
    without corrections still passes there: a photo cropped around a steeply tilted print moves
    the principal point, and the misfit with it."""
    return bent_outline(homography, viewbox_corners(template.viewbox), pyramid.levels[0].shape)


class PayloadChecker:
    """The morph check and the per-bit check of decoded payloads, for one drawing.

    Args:
        model: the trained model.
        template: the unmorphed drawing's template.
        morphs: its morph templates (shared with the reader's second looks).
        synthesis: the per-bit evidence.
    """

    def __init__(
        self, model: DeepMorphModel, template: Template, morphs: MorphTemplates, synthesis: MorphSynthesis
    ) -> None:
        self.model = model
        self.template = template
        self.morphs = morphs
        self.synthesis = synthesis

    def pyramid(self, image: np.ndarray | ImagePyramid) -> ImagePyramid:
        """``image`` as the checks compare it: a pyramid of its gray in the model's channel."""
        return image if isinstance(image, ImagePyramid) else ImagePyramid(to_gray(image, self.model.drawing.channel))

    def fit_morph(
        self,
        image: np.ndarray | ImagePyramid,
        homography: np.ndarray,
        payload: np.ndarray,
        unmorphed: Alignment | None = None,
        in_light_field: bool = False,
    ) -> MorphFit | None:
        """Align the photo to the drawing morphed with ``payload`` and compare with the unmorphed
        drawing aligned at the same width (``unmorphed`` when it was reached at that width and
        ``homography`` is its result, else aligned here from ``homography``); ``None`` when an
        alignment diverges.

        A short ECC solve at :data:`MORPH_WIDTH` is noisy on small or blurred prints. When the
        morph does not win, both are aligned again from ``homography`` with
        :data:`RECHECK_ITERATIONS`, and that fit is the verdict: it rejects fewer right
        payloads, and the CRC, checked first, is what stops wrong ones.
        ``in_light_field``: both are aligned in a grid of light
        (:func:`~deepmorph_detect.light_field.align_in_light_field`), once each.
        """
        pyramid = self.pyramid(image)
        if in_light_field:
            return MorphFit.between(
                align_in_light_field(pyramid, homography, self.template, MORPH_WIDTH),
                align_in_light_field(pyramid, homography, self.morphs.of_payload(payload), MORPH_WIDTH),
            )
        plain = unmorphed if unmorphed is not None and unmorphed.width == MORPH_WIDTH else None
        if plain is None:
            plain = refine_at(pyramid, homography, self.template, MORPH_WIDTH)
        template = self.morphs.of_payload(payload)
        fit = MorphFit.between(plain, refine_at(pyramid, homography, template, MORPH_WIDTH))
        if fit is not None and fit.confirms:
            return fit
        recheck = MorphFit.between(
            refine_at(pyramid, homography, self.template, MORPH_WIDTH, RECHECK_ITERATIONS),
            refine_at(pyramid, homography, template, MORPH_WIDTH, RECHECK_ITERATIONS),
        )
        return fit if recheck is None else recheck

    def check(
        self,
        image: np.ndarray | ImagePyramid,
        homography: np.ndarray,
        result: DecodeResult,
        unmorphed: Alignment | None = None,
        bitwise: bool | None = None,
        blind: bool = False,
        whole_frame: bool = False,
        relit_from: float | None = None,
        in_shadow: bool = False,
        probabilities: np.ndarray | None = None,
        unrivalled_turn: bool = False,
    ) -> PayloadCheck:
        """The morph check of a decoded payload (one frame's, or one fused over frames): a
        payload that passed the CRC keeps its ``ok`` only when its morph fits the photo better
        than the unmorphed drawing (:meth:`fit_morph`); a failed CRC is not checked.

        A payload that needed corrections, or was read with a confidence below
        :data:`CHECK_BELOW_CONFIDENCE` (``bitwise`` None), or any when ``bitwise`` is True, is
        then checked bit by bit (:class:`~deepmorph_detect.synthesis.MorphSynthesis`): the
        photo must show its code bits (:attr:`~deepmorph_detect.synthesis.BitEvidence.agrees`:
        few contradicted, the weakest still supported, the photo explained where they act). A
        CRC collision near the true payload differs from it in six code bits or more; one
        correlation over the whole drawing passes such near misses about half the time, the bits
        rarely. Confident readings without
        corrections skip it (about 55 ms a print): a misread that lands on a valid word without
        corrections has several bits wrong, and those pull its confidence down. So do repairs
        the decoder is as sure of, where the model vouches for them (:meth:`vouches_for_repair`);
        its other weak words are first asked about the few bits where a near miss would differ,
        and pass there without the rest (:meth:`screens`). A drawing a
        blind proposer found (``blind``: the universal detector, which proposes other drawings
        too) skips it only where its morph also fits the photo at :data:`TRUSTED_MORPH_FIT` or
        better, as no other drawing does; below it, where the unmorphed drawing aligned at
        :data:`DRAWING_LIKE_ALIGNMENT` or better, such a reading is asked only whether its morph
        explains the photo where its bits act
        (:attr:`~deepmorph_detect.synthesis.BitEvidence.explained`), which another drawing's
        does not: the bits of a drawing whose morphs a homography nearly absorbs (the bars of a
        bar chart) are too faint for the rest of the per-bit check, which rejects many right
        readings of such prints. A reading of the whole image framed by its ink (``whole_frame``,
        which does not know the drawing either) is asked the same where its morph fits below
        :data:`WHOLE_FRAME_TRUSTED_FIT`, whatever the alignment; one the code had to correct is
        refused where the photo is not this drawing (:meth:`repaired_off_the_drawing`). A reading
        in a photo whose light was estimated from the drawing's own template
        (:mod:`~deepmorph_detect.template_light`;
        ``relit_from``: the unmorphed drawing's alignment in the photo itself) never skips the
        per-bit check: there the drawing and any morph near it fit better than in the photo, so
        no fit measured there vouches for it. It is asked only whether its morph explains the
        photo where the photo itself aligned at :data:`DRAWING_LIKE_ALIGNMENT` or better.
        A word the bit rules pass is withdrawn where its nearest rival explains the photo better
        (:meth:`rival_deviation`); read with corrections in a photo relit from the template, where
        the rival does not leave :data:`RELIT_RIVAL_MARGIN` times as much unexplained; and,
        given the decoder's ``probabilities`` of the reading, a colour drawing's word where the code
        word they prefer next passes every bit rule too (:meth:`runner_up_passes`); and a colour
        drawing's word the code corrected where the photo aligned again to its morph in a grid of
        light does not show it (:meth:`shown_realigned`).
        A colour drawing's bits are asked in its colours (one contrast field per colour channel,
        :meth:`MorphSynthesis.evidence <deepmorph_detect.synthesis.MorphSynthesis.evidence>`)
        only where the unmorphed drawing aligned at :data:`DRAWING_LIKE_ALIGNMENT` or better,
        else in its reading channel's gray.
        A word withdrawn so is asked again in a cast shadow's light, always in full, bit by bit:
        its morph fits aligned in a grid of light (:func:`~deepmorph_detect.light_field.align_in_light_field`;
        ECC's one light bends them to a shadow's edge) and its bits asked in a
        :data:`SHADOW_GRID` grid of light; it passes where that verdict passes. ``in_shadow``:
        ``homography`` is an alignment in a grid of light
        (:func:`~deepmorph_detect.light_field.realign_in_light_field`), and the word is asked
        only so: from there ECC's morph fit slides back to where a shadow's edge bent it and
        compares with an alignment ECC did not make (a crystal oscillator's wrong word passed
        in hard scenes that way).
        """
        if not result.ok:
            return PayloadCheck(result, None, "not run")
        pyramid = self.pyramid(image)
        verdict = None
        if not in_shadow:
            verdict = self._verdict(
                pyramid,
                homography,
                result,
                unmorphed,
                bitwise,
                blind,
                whole_frame,
                relit_from,
                0,
                probabilities,
                unrivalled_turn=unrivalled_turn,
            )
            if verdict.status == "passed":
                return verdict
        shadowed = self._verdict(
            pyramid,
            homography,
            result,
            None,
            bitwise is not False,
            blind,
            whole_frame,
            relit_from,
            SHADOW_GRID,
            probabilities,
        )
        return shadowed if verdict is None or shadowed.status == "passed" else verdict

    def _verdict(  # noqa: PLR0913
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        result: DecodeResult,
        unmorphed: Alignment | None,
        bitwise: bool | None,
        blind: bool,
        whole_frame: bool,
        relit_from: float | None,
        light_grid: int = 0,
        probabilities: np.ndarray | None = None,
        unrivalled_turn: bool = False,
    ) -> PayloadCheck:
        """:meth:`check`'s verdict on a payload that passed the CRC, in the light asked:
        ``light_grid`` 0, ECC's and the per-bit check's smooth light; else the morph fits aligned
        in a grid of light and the bits asked in a ``light_grid`` grid."""
        fit = self.fit_morph(pyramid, homography, result.payload, unmorphed, in_light_field=light_grid > 0)
        if not self.morph_fits(fit, result, light_grid):
            return PayloadCheck(replace(result, ok=False), fit, "failed")
        if whole_frame and self.repaired_off_the_drawing(result, fit):
            return PayloadCheck(replace(result, ok=False), fit, "failed")
        if result.corrected_bits and repaired_on_a_bent_outline(fit.homography, self.template, pyramid):
            return PayloadCheck(replace(result, ok=False), fit, "failed")
        vouched = False
        if bitwise is None:
            vouched = self.vouches_for_repair(result, fit, relit_from, unrivalled_turn)  # only a corrected word
            bitwise = is_weak(result) and not vouched
            if (
                bitwise
                and not light_grid
                and self.screens(pyramid, fit, result, probabilities, relit_from, unrivalled_turn)
            ):
                return PayloadCheck(result, fit, "passed", screened=True)
        # a confident reading of a drawing a blind proposer found, whose morph fits no better
        # than other drawings can align: where it aligned as other drawings do not, is it this
        # drawing at all? (``explained``); elsewhere the whole per-bit check
        is_it_the_drawing = False
        if not bitwise and relit_from is not None:
            is_it_the_drawing = relit_from >= DRAWING_LIKE_ALIGNMENT
            bitwise = not is_it_the_drawing
        elif not bitwise and blind and fit.correlation < TRUSTED_MORPH_FIT:
            is_it_the_drawing = fit.unmorphed_correlation >= DRAWING_LIKE_ALIGNMENT
            bitwise = not is_it_the_drawing
        elif not bitwise and whole_frame:
            is_it_the_drawing = fit.correlation < WHOLE_FRAME_TRUSTED_FIT
        if not bitwise and not is_it_the_drawing:
            return PayloadCheck(result, fit, "passed", vouched=vouched)
        code = self.model.codec.encode(np.asarray(result.payload, dtype=np.uint8))
        # a colour print is asked in its own colours only where the photo shows the drawing:
        # their extra freedom also explains stripes of clutter that a bar chart's whole frame
        # aligned to at 0.56
        aligned = fit.unmorphed_correlation if relit_from is None else relit_from
        # asked only whether it is the drawing, the photo is asked as it is: the pass with a
        # cast shadow divided out serves the bits, which are not asked then
        bits = self.synthesis.evidence(
            pyramid, fit.homography, code, aligned >= DRAWING_LIKE_ALIGNMENT, not is_it_the_drawing, light_grid
        )
        if not is_it_the_drawing and bits.agrees:
            rival = self.rival_deviation(pyramid, homography, bits, aligned, light_grid)
            margin = RELIT_RIVAL_MARGIN if relit_from is not None and result.corrected_bits > 0 else 1.0
            bits = replace(bits, rival_deviation=rival, rival_margin=margin)
        if bits.explained if is_it_the_drawing else bits.agrees:
            if (
                not is_it_the_drawing
                and self.asks_runner_up
                and self.runner_up_passes(
                    pyramid, homography, code, probabilities, unmorphed, blind, whole_frame, relit_from, light_grid
                )
            ):
                bits = replace(bits, runner_up_passes=True)
                return PayloadCheck(replace(result, ok=False), fit, "contradicted", bits)
            if (
                not is_it_the_drawing
                and result.corrected_bits
                and self.asks_realigned
                and not self.shown_realigned(pyramid, fit, code, aligned, light_grid)
            ):
                bits = replace(bits, realigned_disagrees=True)
                return PayloadCheck(replace(result, ok=False), fit, "contradicted", bits)
            return PayloadCheck(result, fit, "passed", bits)
        return PayloadCheck(replace(result, ok=False), fit, "contradicted", bits)

    @property
    def asks_runner_up(self) -> bool:
        """Whether a word the bit rules pass is withdrawn where the decoder's runner-up passes
        too (:meth:`runner_up_passes`): a colour drawing's. Its decoder read wrong words the bit
        rules passed, with the true word as runner-up; black-and-white models read 0 wrong
        payloads without the rule (``bench/README.md``), and the runner-up's per-bit check took
        a `--pixels` model's mean frame 1.4 times as long."""
        return self.model.drawing.colour

    @property
    def asks_realigned(self) -> bool:
        """Whether a word the code corrected that the bit rules pass is asked again at a second
        alignment (:meth:`shown_realigned`): a colour drawing's, whose wrong words pass where a
        cast shadow bent the alignment."""
        return self.model.drawing.colour

    def shown_realigned(
        self, pyramid: ImagePyramid, fit: MorphFit, code: np.ndarray, aligned: float, light_grid: int
    ) -> bool:
        """Whether the photo still shows the code word ``code`` once the photo is aligned to its
        morph again from ``fit``, in a grid of light
        (:func:`~deepmorph_detect.light_field.align_in_light_field`): its bits asked there as they
        were at ``fit`` (in colour where the drawing ``aligned`` at :data:`DRAWING_LIKE_ALIGNMENT`
        or better, in a ``light_grid`` grid of light), by the rules that need no other word. An
        alignment a cast shadow's edge bent takes up part of a wrong word's morph; the light
        field, free to shade the print, lets it slide back, and there the wrong word's bits are
        not shown. False where that alignment diverges.

        In ``part-alternation-mark``'s count of wrong payloads (600 hard close-ups at 234 px, 6
        CRC bits unchecked) the wrong words passed lay 3-15 % of the print's width from the
        simulator's pose; asked so, the count fell from 9 wrong payloads to 5, and 400 medium and
        400 hard close-ups read as many as without it (``bench/README.md``)."""
        again = align_in_light_field(pyramid, fit.homography, self.morphs.of_code(code), MORPH_WIDTH)
        if again is None:
            return False
        in_colour = aligned >= DRAWING_LIKE_ALIGNMENT
        return self.synthesis.evidence(pyramid, again.homography, code, in_colour, True, light_grid).agrees

    def runner_up_passes(  # noqa: PLR0913
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        code: np.ndarray,
        probabilities: np.ndarray | None,
        unmorphed: Alignment | None,
        blind: bool,
        whole_frame: bool,
        relit_from: float | None,
        light_grid: int,
    ) -> bool:
        """Whether the decoder's runner-up to the code word ``code`` (the other code word its
        ``probabilities`` prefer most, :meth:`PayloadCodec.runner_up`) also passes the whole
        per-bit check in the same light: two code words the photo both shows leave the payload
        undecided."""
        if probabilities is None:
            return False
        codec = self.model.codec
        runner = codec.runner_up(code, probabilities)
        if runner is None:
            return False
        decoded = codec.decode(runner.astype(np.float32), soft=False)
        if not decoded.ok or decoded.corrected_bits:
            return False
        asked = DecodeResult(decoded.payload, True, 0, 0.5)
        verdict = self._verdict(pyramid, homography, asked, unmorphed, True, blind, whole_frame, relit_from, light_grid)
        return verdict.status == "passed"

    def vouches_for_repair(
        self, result: DecodeResult, fit: MorphFit, relit_from: float | None = None, unrivalled_turn: bool = False
    ) -> bool:
        """Whether a payload the code corrected skips the per-bit check (:func:`is_trusted_repair`):
        only for a black-and-white drawing trained for the print's pixels (``train --pixels``),
        and never in a photo lit by the drawing's own template (``relit_from``: there no fit
        vouches for it). A drawing that looks the same turned (:attr:`Template.symmetric_turns
        <deepmorph_detect.refine.Template.symmetric_turns>`) only where no other such turn's
        first look reads a word that passes the CRC (``unrivalled_turn``, asked by the locator).
        Other decoders read wrong words as surely as right ones: a colour drawing's at 96 px
        (a crystal oscillator's with one correction, confidence 0.981, log-odds 36), and a
        black-and-white one's from a 96-px frame (a codepen diamond's in hard 640x480 scenes,
        three corrections, 0.971, 26.9, its morph fitting at 0.969). So does a drawing that looks
        the same turned, read at the wrong turn, where its true morph turned is a morph too: the
        `--pixels 200` codepen diamond at its half turn: in 10,000 240-px close-ups two wrong
        words met every bar (2 corrections each, 0.992-0.994, 25.1-28.5 in log-odds), each
        where the first look at the right turn read the right word."""
        return self.trusts_its_decoder(relit_from, unrivalled_turn) and is_trusted_repair(
            result, fit.correlation, self.model.codec.spec.bch_t
        )

    def trusts_its_decoder(self, relit_from: float | None = None, unrivalled_turn: bool = False) -> bool:
        """Whether a reading's own probabilities may spare it part of the per-bit check
        (:meth:`vouches_for_repair`, :meth:`screens`): a black-and-white drawing trained for the
        print's pixels, not in a photo lit by its own template (``relit_from``), and for a drawing
        that looks the same turned only where no other turn's first look read a word that passes
        the CRC (``unrivalled_turn``); the figures at :meth:`vouches_for_repair`."""
        model = self.model
        if model.drawing.colour or model.print_px is None or relit_from is not None:
            return False
        return not self.template.symmetric_turns or unrivalled_turn

    def screens(
        self,
        pyramid: ImagePyramid,
        fit: MorphFit,
        result: DecodeResult,
        probabilities: np.ndarray | None,
        relit_from: float | None = None,
        unrivalled_turn: bool = False,
    ) -> bool:
        """Whether a weak word passes on a few of its bits, without the whole per-bit check
        (about a third of its time): the bits the code corrected and the
        :data:`SCREEN_LEAST_SURE` its decoder's ``probabilities`` were least sure of, where a near
        miss differs from the true word, must each be shown by the photo by at least
        :data:`SCREEN_MIN_EVIDENCE` (:meth:`MorphSynthesis.drawn_on
        <deepmorph_detect.synthesis.MorphSynthesis.drawn_on>`: their variants drawn by the real
        renderer), with the morph explaining the photo
        there (:data:`~deepmorph_detect.synthesis.MAX_DEVIATION`). Asked only of a model whose
        decoder is trusted (:meth:`trusts_its_decoder`), where the unmorphed drawing aligned as
        other drawings do not (:data:`DRAWING_LIKE_ALIGNMENT`); a word it does not pass takes the
        whole check. A near miss shows the true word's bits where it differs from it: where the
        code corrected a bit the decoder read right, and where the decoder misread one, which it
        is seldom sure of. Every correction is asked, so one found beyond the code's ``t`` is
        asked more, not less."""
        if probabilities is None or not self.trusts_its_decoder(relit_from, unrivalled_turn):
            return False
        if fit.unmorphed_correlation < DRAWING_LIKE_ALIGNMENT:
            return False
        code = self.model.codec.encode(np.asarray(result.payload, dtype=np.uint8))
        sure = np.abs(np.asarray(probabilities, dtype=np.float64) - 0.5)
        corrected = np.flatnonzero(code != (np.asarray(probabilities) > 0.5))
        asked = np.union1d(corrected, np.argsort(sure, kind="stable")[:SCREEN_LEAST_SURE])
        shown = self.synthesis.drawn_on(pyramid, fit.homography, code, asked)
        return bool(shown.min() >= SCREEN_MIN_EVIDENCE and np.median(np.abs(shown - 1.0)) <= MAX_DEVIATION)

    def morph_fits(self, fit: MorphFit | None, result: DecodeResult, light_grid: int = 0) -> bool:
        """Whether the photo shows ``result``'s morph at ``fit`` (:meth:`fit_morph`): the alignment
        converged and the morph gains over the unmorphed drawing (:attr:`MorphFit.confirms`), in
        ECC's one light (``light_grid`` 0) by at least :meth:`least_gain`. The first thing
        :meth:`check` asks; a word that fails it is withdrawn as ``failed``."""
        if fit is None or not fit.confirms:
            return False
        return bool(light_grid) or fit.gain >= self.least_gain(result)

    def least_gain(self, result: DecodeResult) -> float:
        """The least morph gain a reading must show in ECC's one light beyond
        :data:`MIN_MORPH_GAIN`: a colour drawing's reading that needed corrections,
        :data:`REPAIRED_COLOUR_MORPH_GAIN`. Fits aligned in a grid of light are not held to it:
        there a right word under a cast shadow gains less (``tests/detect/test_light_field.py``)."""
        repaired = result.corrected_bits > 0 and self.model.drawing.colour  # colour walks the palette: asked last
        return REPAIRED_COLOUR_MORPH_GAIN if repaired else MIN_MORPH_GAIN

    def repaired_off_the_drawing(self, result: DecodeResult, fit: MorphFit) -> bool:
        """Whether a reading of the whole frame is refused whatever its bits show: the code had to
        correct it, and the photo is not this black-and-white drawing (the unmorphed drawing
        aligned below :data:`WHOLE_FRAME_REPAIRED_ALIGNMENT`). A frame filled by another drawing
        can still show a repaired word's bits; right readings of a frame-filling print align
        better. Colour drawings are not held to it: right ones of theirs pass below it, and the
        other rules refuse their wrong ones there (the figures at the constant)."""
        return (
            result.corrected_bits > 0
            and not self.model.drawing.colour
            and fit.unmorphed_correlation < WHOLE_FRAME_REPAIRED_ALIGNMENT
        )

    def rival_deviation(
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        bits: BitEvidence,
        aligned: float,
        light_grid: int = 0,
    ) -> float | None:
        """How much of the photo the word's nearest rival leaves unexplained where its bits act
        (:attr:`BitEvidence.deviation <deepmorph_detect.synthesis.BitEvidence.deviation>`), asked
        as the word was, at the alignment to the rival's own morph; ``None`` where the code has no
        rival near, that alignment diverges, or the photo shows the word's bits rather than the
        rival's where the two differ (the rival's evidence there adds up to 0 or less).

        The nearest rival is the code word the word's own evidence prefers least to it
        (:meth:`PayloadCodec.nearest_rival <deepmorph_core.codec.PayloadCodec.nearest_rival>`).
        Evidence is measured around one word's morph, so on a print too small or blurred for its
        code a wrong word can pass the bit rules; its true word, asked in turn, explains the photo
        better. Measured on a bar chart's 3-bit code in hard scenes (the universal detector's
        proposals): in each of the 7 wrong payloads examined the true word was the nearest rival,
        explaining the photo better with its bits shown where the two differ.
        """
        codec = self.model.codec
        rival = codec.nearest_rival(bits.code, bits.evidence)
        if rival is None:
            return None
        morph = self.morphs.of_code(rival)
        if light_grid:
            fit = align_in_light_field(pyramid, homography, morph, MORPH_WIDTH)
        else:
            fit = refine_at(pyramid, homography, morph, MORPH_WIDTH)
        if fit is None:
            return None
        in_colour = aligned >= DRAWING_LIKE_ALIGNMENT
        differ = np.flatnonzero(rival != bits.code)
        if len(differ) <= RIVAL_BITS_FIRST_SHARE * len(rival):
            # the differing bits first: on a right word they show its bits, and the rival's
            # other bits are never rendered
            shown = self.synthesis.shown_on(pyramid, fit.homography, rival, differ, in_colour, light_grid)
            if float(shown.sum()) <= 0:
                return None
            # its deviation is asked of the photo as it is: the pass with a shadow divided out
            # would serve its bits, which are not asked
            return self.synthesis.evidence(pyramid, fit.homography, rival, in_colour, False, light_grid).deviation
        theirs = self.synthesis.evidence(pyramid, fit.homography, rival, in_colour, True, light_grid)
        return theirs.deviation if float(theirs.evidence[differ].sum()) > 0 else None


__all__ = ["CHECK_BELOW_CONFIDENCE", "DRAWING_LIKE_ALIGNMENT", "MIN_MORPH_GAIN", "MORPH_WIDTH",
           "RELIT_MAX_CORRECTIONS", "RELIT_RIVAL_MARGIN", "RIVAL_BITS_FIRST_SHARE", "SCREEN_LEAST_SURE",
           "SCREEN_MIN_EVIDENCE", "SHADOW_GRID", "TRUSTED_MORPH_FIT",
           "TRUSTED_REPAIR_LOG_ODDS", "repaired_on_a_bent_outline",
           "WHOLE_FRAME_REPAIRED_ALIGNMENT", "WHOLE_FRAME_TRUSTED_FIT", "MorphFit", "MorphTemplates",
           "PayloadCheck", "PayloadChecker", "is_trusted_repair", "is_weak"]  # fmt: skip
