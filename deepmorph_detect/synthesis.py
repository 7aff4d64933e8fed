"""Code bits read and checked by synthesis: which morph does the photo show, bit by bit?

The decoder CNN reads a rectified print in one pass. On small, blurred prints it errs on a few
bits, and a reading that lands near the wrong code word can pass the CRC. This module asks the
photo directly instead. For a code word ``c`` it renders, with the model's soft rasterizer, the
drawing morphed by ``c`` and by each of its one-bit variants ``c ^ e_j``, blurs them as much as
the print is blurred, fits the light on the print (contrast and brightness as linear fields; a
colour drawing's renders in colour, one contrast field per colour channel, since printing and
capture change each ink differently; a cast shadow's sharp edge, read off the flat of the print,
divided out first), discounts what a small misalignment explains, and compares:

    evidence_j = (|P - T(c ^ e_j)|^2 - |P - T(c)|^2) / |T(c ^ e_j) - T(c)|^2

``+1`` means the photo shows bit ``j`` as ``c`` has it, ``-1`` that it shows the flipped bit;
noise spreads it around these. Every bit of the spread encoder moves its own points, so the
evidence of one bit hardly depends on the others.

Two uses (:class:`~deepmorph_detect.locate.Locator`):

* :meth:`MorphSynthesis.evidence` -- a per-bit morph check for a payload that passed the CRC
  only after corrections, or with low confidence. A wrong code word differs from the true one
  in six bits or more, most of them contradicted. The morph check of the whole drawing (one
  correlation) passes such near misses about half the time.
* :meth:`MorphSynthesis.read` -- the last look at a drawing no view of which passes the CRC:
  the CNN's log-odds plus the evidence decide every bit again. A colour drawing's bits are asked
  there in its reading channel's one gray, not in colour: the per-bit check of the word this look
  reads then asks the photo in a way that did not choose it (asked in colour both times, a hard
  close-up under a cast shadow gave a wrong payload that its own evidence vouched for).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import cv2
import numpy as np
import torch

from deepmorph_core.model import DeepMorphModel
from deepmorph_core.registration import motion_images
from deepmorph_detect.fastrender import Renderer, render_svg_resvg
from deepmorph_detect.light_field import grid_fields
from deepmorph_detect.refine import ImagePyramid, Template, correlation, refine_at, warp_to_template
from deepmorph_detect.tall_solves import least_squares, orthonormal_columns
from deepmorph_detect.template_light import DARKEST_REFLECTANCE, far_from_edges, smoothed_light

SYNTH_WIDTH = 64  # width (px) of the rectified photo and of the renders (wider reads fewer small prints, slower)
# ... of the per-bit check, which asks about a word rather than reading one: at 64 px the evidence of
# a drawing with many variables per bit contradicts bits of right words (2-8 of 23 on a 98-variable
# colour icon, medium close-ups: 16 % of its right words agreed, 34 % at 96 px)
CHECK_WIDTH = 96
BLUR_SIGMAS = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0)  # print blur tried, in pixels at the render's width
MAX_CONTRADICTED = 2  # a checked code word may have at most this many bits the photo contradicts
# ... and the evidence of its WEAKEST_BITS weakest bits must add up to MIN_WEAKEST_SUM or more:
# on a blurred, steeply tilted print the evidence is noise of about +-0.6, and a wrong word can
# show only two bits flipped and several barely supported
WEAKEST_BITS = 5
MIN_WEAKEST_SUM = 0.5
# ... and its bits' evidence must sit near +1: at most this median distance from it. A print of the
# word leaves the photo's evidence within about half of a bit's own change of +1 (at most 0.52
# on 358 right readings of six drawings, medium and hard); a photo of something else, aligned
# well enough to be checked, leaves residuals many times a bit's change (8.9 on the one wrong
# payload a negative scene gave), which the two rules above can miss on a short code
MAX_DEVIATION = 1.0
# a bit whose evidence on the word's own real-renderer render falls below this is one the soft
# rasterizer models wrongly (MorphSynthesis.evidence); its evidence is corrected by that error
MIN_OWN_EVIDENCE = 0.5
EVIDENCE_WEIGHT = 100.0  # evidence (+-1 scale) against the CNN's logits when reading
READ_ROUNDS = 4  # rounds of reading: a print with several confident misreadings needs more than two
# ... but none after one whose word leaves the photo this unexplained (deviation): that is another
# drawing, not this one misread. Right readings by synthesis began at 0.93 at most (13 of them, four
# drawings, hard and medium scenes); proposals of other drawings at 1.3-10, a median 3.7
HOPELESS_DEVIATION = 2.0
ALIGN_ITERATIONS = 5  # ECC iterations of the alignment to the CNN's morph before reading
LIGHT_DEGREE = 1  # degree of the smooth light fields (0: one contrast and brightness for the print)
# the light on the print, divided out before asking: a cast shadow's sharp edge across a fill is
# something no smooth field fits, and it swamps the small changes of the bits near it. It is read
# off the photo where the word's render is flat: farther than SHADOW_MARGIN px (at the render's width)
# from its edges, where the morph acts, smoothed over SHADOW_SMOOTHING px, in LIGHT_ROUNDS rounds
# of fitting the render's inks to the photo so lit and the light to the inks so fitted. Right
# words the per-bit check refused on close-ups that aligned (an icon, medium, and two drawings,
# hard): 10 of 53 -> 8, 23 of 65 -> 16 and 31 of 71 -> 27, with no more near words agreeing
SHADOW_SMOOTHING = 1.0
SHADOW_MARGIN = 1
LIGHT_ROUNDS = 3
LIGHT_READ_SHARE = 0.3  # the light is read on paper and inks at least this share as bright as the brightest
SHADOW_RENDER_BLUR = 1.0  # blur (px at the render's width) of the render the light is read against
SHADOW_LIGHT_RANGE = (0.1, 10.0)  # a light outside it is an estimate gone wrong, not a shadow: held to it
VARIANT_CACHE = 16  # code words whose one-bit variants stay rendered (videos repeat payloads)
GRID_EDGE_MARGIN = 2  # a grid light (GridLight) is read this many px beyond the blur's reach of the word's edges
GRID_RIDGE = 1e-3  # ... and its knots held towards no shade by this share of the fit's mean weight
# the smooth light and the grid's shade are fitted in turn this many times: at the true pose of the
# 218 close-ups of the seven colour models the chain missed, right words asked in the shade passed
# 107 times, against 77 with contrast and brightness fields of the grid's own; 0 of 654 words one
# payload bit away passed either way
SHADE_ROUNDS = 2


#: the per-bit check's fields of a detection's JSON (:meth:`BitEvidence.to_json`), each only
#: where the check asked it
BIT_FIELDS = (
    "bits_contradicted",
    "weakest_bits_support",
    "bits_deviation",
    "nearest_rival_deviation",
    "rival_margin",
)


@dataclass(frozen=True)
class BitEvidence:
    """What the photo says about each bit of one code word.

    Attributes:
        code: ``(N_b,)`` the code word asked about.
        evidence: ``(N_b,)`` about +1 where the photo shows the word's bit, -1 where it shows
            the flipped bit.
        fit: correlation of the blurred render of ``code`` with the photo.
        blur_px: the blur (Gaussian sigma, pixels at the render's width) that fitted best.
        unlit: ``(N_b,)`` the evidence with no shadow divided out, where :attr:`evidence` had
            one divided out (:meth:`MorphSynthesis.shadows`): whether the word's morph explains
            the photo at all (:attr:`deviation`) is judged on it, as dividing out a light read
            off the photo also takes up another drawing's strokes.
        rival_deviation: the :attr:`deviation` of the code word :attr:`evidence` prefers least
            to this one (:meth:`PayloadCodec.nearest_rival
            <deepmorph_core.codec.PayloadCodec.nearest_rival>`), asked at the alignment to its
            own morph, where the photo shows that word's bits where the two differ (their
            evidence adding up above 0; :meth:`PayloadChecker.rival_deviation
            <deepmorph_detect.check.PayloadChecker.rival_deviation>`); ``None`` where it was not
            asked or the photo shows this word's bits there.
        rival_margin: how many times :attr:`deviation` the rival's must reach for the word to
            pass: 1, or more where the photo cannot tell near words apart as well
            (:data:`~deepmorph_detect.check.RELIT_RIVAL_MARGIN`).
        runner_up_passes: the decoder's runner-up word passes every other rule too
            (:meth:`PayloadChecker.runner_up_passes <deepmorph_detect.check.PayloadChecker.runner_up_passes>`).
        realigned_disagrees: asked again at a second alignment to its morph, in a grid of light,
            the photo does not show the word (:meth:`PayloadChecker.shown_realigned
            <deepmorph_detect.check.PayloadChecker.shown_realigned>`).
    """

    code: np.ndarray
    evidence: np.ndarray
    fit: float
    blur_px: float
    unlit: np.ndarray | None = None
    rival_deviation: float | None = None
    rival_margin: float = 1.0
    runner_up_passes: bool = False
    realigned_disagrees: bool = False

    @property
    def contradicted(self) -> int:
        """How many bits the photo shows flipped."""
        return int((self.evidence < 0).sum())

    @property
    def weakest_sum(self) -> float:
        """The evidence of the :data:`WEAKEST_BITS` least supported bits, added up: about
        ``+WEAKEST_BITS`` when the photo clearly shows every bit, negative when it shows several
        flipped, near zero when it cannot tell."""
        return float(np.sort(self.evidence)[:WEAKEST_BITS].sum())

    @property
    def deviation(self) -> float:
        """The median distance of the bits' evidence from +1, in units of a bit's own change:
        how much of the photo the word's morph leaves unexplained where its bits act (about
        0.1-0.5 on a print of the word, several on a photo of something else); on the photo as
        it is (:attr:`unlit`, where a shadow was divided out)."""
        asked = self.evidence if self.unlit is None else self.unlit
        return float(np.median(np.abs(asked - 1.0)))

    @property
    def explained(self) -> bool:
        """Whether the word's morph explains the photo where its bits act (:attr:`deviation` at
        most :data:`MAX_DEVIATION`): the part of :attr:`agrees` that tells a print of the drawing
        from a photo of something else, whichever word it shows."""
        return self.deviation <= MAX_DEVIATION

    @property
    def agrees(self) -> bool:
        """Whether the photo shows this code word: at most :data:`MAX_CONTRADICTED` bits
        contradicted, its weakest bits still supported (:attr:`weakest_sum` at least
        :data:`MIN_WEAKEST_SUM`), its morph explaining the photo where its bits act
        (:attr:`deviation` at most :data:`MAX_DEVIATION`), and its nearest rival word, whose bits
        the photo shows where the two differ, not explaining the photo better
        (:attr:`rival_deviation` below :attr:`rival_margin` times :attr:`deviation`), and the
        decoder's runner-up word not passing all of this too (:attr:`runner_up_passes`), nor the
        photo failing to show it at a second alignment (:attr:`realigned_disagrees`)."""
        return not self.reason

    def to_json(self) -> dict[str, Any]:
        """The per-bit check's fields of a detection's JSON (``docs/detection.md``)."""
        fields = {
            "bits_contradicted": self.contradicted,
            "weakest_bits_support": round(self.weakest_sum, 3),
            "bits_deviation": round(self.deviation, 3),
        }
        if self.rival_deviation is not None:
            fields["nearest_rival_deviation"] = round(self.rival_deviation, 3)
            if self.rival_margin != 1.0:
                fields["rival_margin"] = self.rival_margin
        if self.runner_up_passes:
            fields["runner_up_passes"] = True
        if self.realigned_disagrees:
            fields["realigned_disagrees"] = True
        return fields

    @property
    def _rule_inputs(self) -> tuple[int, float, float, float | None, float, bool, bool]:
        """What the bit rules are asked of (:func:`broken_rules`, :func:`disagreement`), in their order."""
        return (
            self.contradicted, self.weakest_sum, self.deviation, self.rival_deviation, self.rival_margin,
            self.runner_up_passes, self.realigned_disagrees,
        )  # fmt: skip

    @property
    def broken(self) -> tuple[str, ...]:
        """The :data:`BIT_RULES` this word breaks, in the order they are asked (empty when it
        :attr:`agrees`): :func:`broken_rules` of its fields."""
        return broken_rules(*self._rule_inputs)

    @property
    def reason(self) -> str:
        """Why :attr:`agrees` is false, in words (empty when it is true)."""
        return disagreement(*self._rule_inputs)


#: The per-bit check's rules (:attr:`BitEvidence.agrees`), by name, in the order they are asked.
BIT_RULES = ("bits flipped", "weakest bits", "unexplained", "rival", "runner-up", "realigned")


def broken_rules(
    contradicted: int,
    weakest_sum: float,
    deviation: float,
    rival_deviation: float | None = None,
    rival_margin: float = 1.0,
    runner_up_passes: bool = False,
    realigned_disagrees: bool = False,
) -> tuple[str, ...]:
    """The :data:`BIT_RULES` a code word breaks (empty when it agrees): too many bits shown
    flipped, its weakest bits barely shown, a photo its morph does not explain, or a photo that
    the nearest rival word explains better, or not ``rival_margin`` times worse, its bits shown
    where the two differ (``rival_deviation``), the decoder's runner-up word passing every
    rule too (``runner_up_passes``), or the photo not showing the word at a second alignment to
    its morph (``realigned_disagrees``)."""
    broken = (
        contradicted > MAX_CONTRADICTED,
        weakest_sum < MIN_WEAKEST_SUM,
        deviation > MAX_DEVIATION,
        rival_deviation is not None and rival_deviation < rival_margin * deviation,
        runner_up_passes,
        realigned_disagrees,
    )
    return tuple(rule for rule, hit in zip(BIT_RULES, broken) if hit)


def disagreement(
    contradicted: int,
    weakest_sum: float,
    deviation: float,
    rival_deviation: float | None = None,
    rival_margin: float = 1.0,
    runner_up_passes: bool = False,
    realigned_disagrees: bool = False,
) -> str:
    """The first of :func:`broken_rules` a code word breaks, in words (empty when none)."""
    broken = broken_rules(
        contradicted, weakest_sum, deviation, rival_deviation, rival_margin, runner_up_passes, realigned_disagrees
    )
    first = next(iter(broken), "")
    if first == "bits flipped":
        return f"the photo shows {contradicted} of its code bits flipped"
    if first == "weakest bits":
        return (
            f"the photo barely shows its {WEAKEST_BITS} weakest code bits "
            f"(support {weakest_sum:.2f}, at least {MIN_WEAKEST_SUM} needed)"
        )
    if first == "unexplained":
        return (
            f"its morph does not explain the photo where its bits act "
            f"(deviation {deviation:.2f}, at most {MAX_DEVIATION})"
        )
    if first == "rival":
        how, needed = ("better", "") if rival_margin == 1.0 else ("nearly as well", f"; {rival_margin:g} times needed")
        return (
            f"the nearest other code word explains the photo {how}, its bits shown where the two differ "
            f"(deviation {rival_deviation:.2f} against {deviation:.2f}{needed})"
        )
    if first == "runner-up":
        return "the code word the decoder read next passes the check too: the photo does not tell them apart"
    if first == "realigned":
        return "aligned again to its morph in a grid of light, the photo does not show its bits"
    return ""


def disagreement_in(fields: dict[str, Any]) -> str:
    """:func:`disagreement` from a detection's JSON fields (:meth:`BitEvidence.to_json`)."""
    return disagreement(
        fields["bits_contradicted"], fields["weakest_bits_support"], fields["bits_deviation"],
        fields.get("nearest_rival_deviation"), fields.get("rival_margin", 1.0),
        fields.get("runner_up_passes", False), fields.get("realigned_disagrees", False),
    )  # fmt: skip


@dataclass(frozen=True)
class GridLight:
    """A cast shadow's shade, for asking a word's bits: a field that multiplies the smooth
    light, bilinear on a grid of knots over the print
    (:func:`~deepmorph_detect.light_field.grid_fields`), fitted only where the word's render is
    flat, away from the bits' own edges. A shadow takes the same share of the light from paper
    and ink, so a cell of bare paper says what light its ink gets too: a line drawing's ink lies
    all near its edges, where nothing is fitted. Contrast and brightness fields of the grid's
    own cannot be told apart on bare paper, and failed a ghost's right word in a clean photo.

    Attributes:
        fields: ``(h * w, knots)`` the grid's fields.
        flat: ``(h * w,)`` 1 where the word's render is flat, else 0.
    """

    fields: np.ndarray
    flat: np.ndarray

    @classmethod
    def of(cls, render: np.ndarray, blur: float, grid: int) -> GridLight:
        """The grid light for ``render`` (``(C, h, w)``, the word's, unblurred) printed with a
        blur of ``blur`` px: flat beyond the blur's reach plus :data:`GRID_EDGE_MARGIN` px of
        its edges."""
        h, w = render.shape[-2:]
        flat = far_from_edges(render, GRID_EDGE_MARGIN + math.ceil(2 * blur))
        return cls(grid_fields(h, w, grid), flat.ravel().astype(np.float64))

    def shade(self, photo: np.ndarray, lit: np.ndarray) -> np.ndarray:
        """``(h * w,)`` the shade that takes ``lit`` (``(h * w,)``, the word's render in the
        smooth light) to ``photo`` (``(h * w,)``) where the render is flat, least squares, each
        knot held towards no shade (1) by :data:`GRID_RIDGE` and the whole to
        :data:`SHADOW_LIGHT_RANGE`."""
        design = self.fields * lit[:, None]
        normal = design.T @ (design * self.flat[:, None])
        ridge = GRID_RIDGE * float(np.diagonal(normal).mean())
        rhs = design.T @ (photo * self.flat) + ridge
        knots = np.linalg.lstsq(normal + ridge * np.eye(len(normal)), rhs, rcond=None)[0]
        return np.clip(self.fields @ knots, *SHADOW_LIGHT_RANGE)


class MorphSynthesis:
    """Renders a model's morphs with the soft rasterizer and compares them with photos."""

    def __init__(
        self, model: DeepMorphModel, template: Template, width: int = SYNTH_WIDTH, renderer: Renderer = render_svg_resvg
    ) -> None:
        """``template`` is the unmorphed drawing (its viewBox frames the rectified photo);
        ``renderer`` is the real renderer of its morphs (the one that rendered ``template``)."""
        self.model = model
        self.template = template
        self.width = width
        self.renderer = renderer
        self.rasterizer = model.rasterizer(width)
        # a colour drawing's renders stay in colour: printing and capture change each paint's
        # colour differently (faded ink, white balance), so no one gray of the render is the photo's
        self.colour = model.drawing.colour
        self._variants: OrderedDict[bytes, tuple[np.ndarray, np.ndarray]] = OrderedDict()

    def variants(self, code: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The renders :meth:`evidence` compares (1 = paper): ``(N_b + 1, C, h, w)`` of ``code``
        and each of its one-bit variants by the soft rasterizer (``C`` = 3, sRGB, for a colour
        drawing; 1, gray, for a black-and-white one), and ``(h, w)`` of ``code`` by the real
        renderer in the model's reading channel."""
        code = np.asarray(code, dtype=np.uint8)
        key = code.tobytes()
        renders = self._variants.get(key)
        if renders is None:
            renders = self._rendered(code, np.arange(len(code)))
            self._variants[key] = renders
            if len(self._variants) > VARIANT_CACHE:
                self._variants.popitem(last=False)
        self._variants.move_to_end(key)
        return renders

    def _rendered(self, code: np.ndarray, bits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`variants` of only the one-bit variants of ``bits`` (indices into ``code``):
        ``(len(bits) + 1, C, h, w)`` and ``(h, w)``."""
        values = self._variant_values(code, bits)
        with torch.no_grad():
            soft = (self.rasterizer.render_rgb(values) if self.colour else 1.0 - self.rasterizer(values)).numpy()
        real = self.renderer(self.model.drawing.to_svg(values[0]), soft.shape[3], self.template.viewbox)
        if real.shape != soft.shape[2:]:
            real = cv2.resize(real, soft.shape[:1:-1], interpolation=cv2.INTER_AREA)
        return soft, real

    def _variant_values(self, code: np.ndarray, bits: np.ndarray) -> torch.Tensor:
        """``(len(bits) + 1, n_vars)`` the morph values of ``code`` and of each of its one-bit
        variants at ``bits``, in that order."""
        codes = np.repeat(np.asarray(code, dtype=np.uint8)[None], len(bits) + 1, axis=0)
        codes[np.arange(1, len(bits) + 1), np.asarray(bits, dtype=np.int64)] ^= 1
        return self.model.morph_values(torch.from_numpy(codes.astype(np.float32)))

    def _light_fields(self, shape: tuple[int, int]) -> np.ndarray:
        """``(h * w, k)`` smooth basis functions (polynomials in x, y up to degree
        :data:`LIGHT_DEGREE`) for the light's contrast and brightness across the print."""
        return _light_fields_of(tuple(shape))

    def _motion_basis(self, model: np.ndarray) -> np.ndarray:
        """``(h * w, 8)`` orthonormal basis of the changes that a small motion (the eight
        parameters of a homography, linearised) makes to ``model``."""
        return orthonormal_columns(motion_images(model).reshape(8, -1).T)

    def rectified(self, pyramid: ImagePyramid, homography: np.ndarray) -> np.ndarray:
        """The photo through ``homography`` (SVG units -> image px), at :attr:`width`."""
        return warp_to_template(pyramid, homography, self.template, self.width).astype(np.float32)

    def evidence(
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        code: np.ndarray,
        in_colour: bool = True,
        lit: bool = True,
        light_grid: int = 0,
    ) -> BitEvidence:
        """The photo's evidence on every bit of ``code``; ``homography`` must already be aligned
        to the morph of ``code`` (an alignment to another morph bends towards that one).

        The evidence is checked against the word's own real-renderer render, blurred like the
        print: ideally that shows every bit at +1, and what it shows instead is the soft
        rasterizer's error on the bit. Where it shows less than :data:`MIN_OWN_EVIDENCE`, that
        error is taken off the photo's evidence (which is linear in the picture); above, the
        difference is within the measurement's noise and is left alone. It matters where a
        bit's change hides under another stroke, where the soft union and a renderer's painting
        differ (pins of a chip pushed along themselves into its outline).

        ``in_colour``: a colour drawing's renders are fitted in colour (:meth:`_in_light`); false,
        in its reading channel's gray, as :meth:`read` asks. ``lit``: the bits are asked with the
        light of a cast shadow divided out (:meth:`shadows`), and the photo as it is says how much
        the word's morph leaves unexplained (:attr:`BitEvidence.unlit`); false, as :meth:`read`
        asks, only the photo as it is. ``light_grid``: the smooth light is also shaded by a
        ``light_grid x light_grid`` grid of knots (:class:`GridLight`: a cast shadow's
        darkening); the print's blur is still fitted in the smooth light alone.
        """
        photo, soft, real, colour = self._asked_in(pyramid, homography, self.variants(code), in_colour)
        code = np.asarray(code, dtype=np.uint8)
        # both passes mostly find the same blur
        at_blur: dict[float, tuple[np.ndarray, np.ndarray, GridLight | None]] = {}
        evidence, fit, sigma = self._asked(photo, soft, real, colour, at_blur, light_grid)
        if not lit:
            return BitEvidence(code, evidence, fit, sigma)
        shown, fit, sigma = self._asked(photo / self.shadows(photo, soft[0]), soft, real, colour, at_blur, light_grid)
        return BitEvidence(code, shown, fit, sigma, unlit=evidence)

    def shown_on(
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        code: np.ndarray,
        bits: np.ndarray,
        in_colour: bool = True,
        light_grid: int = 0,
    ) -> np.ndarray:
        """``(len(bits),)`` what :meth:`evidence` (``lit``) says of the bits ``bits`` of ``code``
        alone, rendering only their variants: a bit's evidence compares the photo with the word's
        render and its own variant, in the light and blur fitted to the word's render, so it does
        not depend on the other bits. The check asks a rival word's differing bits first and the
        rest only where those show the rival's (:meth:`PayloadChecker.rival_deviation
        <deepmorph_detect.check.PayloadChecker.rival_deviation>`)."""
        code = np.asarray(code, dtype=np.uint8)
        renders = self._rendered(code, np.asarray(bits, dtype=np.int64))
        return self._shown(pyramid, homography, renders, in_colour, light_grid)

    def drawn_on(self, pyramid: ImagePyramid, homography: np.ndarray, code: np.ndarray, bits: np.ndarray) -> np.ndarray:
        """``(len(bits),)`` what :meth:`shown_on` says of the bits ``bits`` of ``code``, with the
        word and its one-bit variants drawn by the real renderer instead of the soft rasterizer:
        about three quarters of the time for ten bits (Skia draws one in about 0.5 ms with its
        SVG, where the soft rasterizer's fixed cost is about 8 ms a batch), and with nothing of
        the soft rasterizer's error to correct, the word's own render being the first of them. A
        variant the renderer draws no differently from the word shows 0. Black-and-white drawings
        only: the renderer draws in one gray (:meth:`PayloadChecker.screens
        <deepmorph_detect.check.PayloadChecker.screens>`)."""
        if self.colour:
            raise ValueError("a colour drawing's bits are asked in its colours, which the real renderer does not give")
        viewbox = self.template.viewbox
        values = self._variant_values(code, bits)
        drawn = np.stack([self.renderer(svg, self.width, viewbox) for svg in self.model.drawing.to_svgs(values)])
        return self._shown(pyramid, homography, (drawn[:, None], drawn[0]), False, exact=True)

    def _shown(
        self,
        pyramid: ImagePyramid,
        homography: np.ndarray,
        renders: tuple[np.ndarray, np.ndarray],
        in_colour: bool,
        light_grid: int = 0,
        exact: bool = False,
    ) -> np.ndarray:
        """:meth:`shown_on`'s and :meth:`drawn_on`'s evidence from ``renders`` (the word's and its
        variants', and the word's real render): asked with a cast shadow's light divided out."""
        photo, soft, real, colour = self._asked_in(pyramid, homography, renders, in_colour)
        shown, _, _ = self._asked(photo / self.shadows(photo, soft[0]), soft, real, colour, {}, light_grid, exact)
        return shown

    def _asked_in(
        self, pyramid: ImagePyramid, homography: np.ndarray, renders: tuple[np.ndarray, np.ndarray], in_colour: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """The rectified photo and ``renders`` (:meth:`variants`) sized as it and in the colours
        asked (``in_colour``: a colour drawing's in colour, else in its reading channel's gray),
        and whether they are in colour."""
        photo = self.rectified(pyramid, homography)
        soft, real = renders
        colour = self.colour and in_colour
        if self.colour and not colour:  # the renders in the reading channel's one gray
            soft = self._gray(soft)
        if soft.shape[2:] != photo.shape:
            size = photo.shape[::-1]
            soft = np.stack([[cv2.resize(c, size, interpolation=cv2.INTER_AREA) for c in r] for r in soft])
            real = cv2.resize(real, size, interpolation=cv2.INTER_AREA)
        return photo, soft, real, colour

    def _asked(
        self,
        photo: np.ndarray,
        soft: np.ndarray,
        real: np.ndarray,
        colour: bool,
        at_blur: dict[float, tuple[np.ndarray, np.ndarray, GridLight | None]],
        light_grid: int = 0,
        exact: bool = False,
    ) -> tuple[np.ndarray, float, float]:
        """:meth:`evidence` of ``photo`` from the renders :meth:`variants` gives (``soft`` in the
        colours asked, ``colour``), sized as the photo: ``(N_b,)`` evidence, the fit of the word's
        render and the print's blur. ``at_blur`` keeps, per blur, the blurred renders and the
        evidence of the word's own real render and the grid light, none of which depend on the
        photo (one dict per ``light_grid``). ``light_grid``: the bits are asked in a light of
        that grid's fields. ``exact``: ``real`` is ``soft``'s first render, so no error of the
        soft rasterizer is corrected."""
        fields = self._light_fields(photo.shape)

        def looks(render: np.ndarray) -> np.ndarray:
            """``(C, h, w)`` as the photo would show it: a colour one in its fitted light."""
            if not colour:
                return render[0]
            return self._in_light(photo, render.reshape(1, len(render), -1), fields)[0].reshape(photo.shape)

        # the print's blur: the one whose render looks most like it
        fit, sigma = max((correlation(looks(_blurred(soft[0], s)), photo), s) for s in BLUR_SIGMAS)
        if sigma not in at_blur:
            blurred = _blurred(soft, sigma).reshape(*soft.shape[:2], -1)
            grid = GridLight.of(soft[0], sigma, light_grid) if light_grid else None
            own = (
                np.ones(len(soft) - 1)
                if exact
                else self._ask(cv2.GaussianBlur(real, (0, 0), sigma), blurred, fields, grid)
            )
            at_blur[sigma] = blurred, own, grid
        blurred, own, grid = at_blur[sigma]
        said = self._ask(photo, blurred, fields, grid)
        evidence = said - np.where(own < MIN_OWN_EVIDENCE, own - 1.0, 0.0)
        return evidence.astype(np.float32), float(fit), float(sigma)

    def shadows(self, photo: np.ndarray, render: np.ndarray) -> np.ndarray:
        """``(h, w)`` the light on the print in ``photo`` (``(h, w)``, rectified) that no smooth
        field follows, such as a cast shadow's edge across a fill. ``render`` (``(C, h, w)``) is
        the word's render in the colours asked. The light is the photo over the render's inks
        fitted to it, read where the render is flat (away from its edges, where the morph acts)
        and light (at least :data:`LIGHT_READ_SHARE` of the brightest: a dark fill's ratio is
        mostly noise and black level), and smoothed
        (:func:`~deepmorph_detect.template_light.smoothed_light`); inks and light are fitted in
        turn, :data:`LIGHT_ROUNDS` times. Dividing it out leaves the bits' edges to the per-bit
        comparison."""
        h, w = photo.shape
        inks = np.concatenate([_blurred(render, SHADOW_RENDER_BLUR).reshape(len(render), -1), np.ones((1, h * w))])
        flat = far_from_edges(render, SHADOW_MARGIN)
        light = np.ones_like(photo, dtype=np.float32)
        for _ in range(LIGHT_ROUNDS):
            # a colour render's channels and the constant can be collinear (few inks): the
            # fitted picture is unique all the same
            mix = least_squares(inks.T, (photo / light).ravel())
            model = (mix @ inks).reshape(h, w)
            weight = (flat * (model > LIGHT_READ_SHARE * float(model.max()))).astype(np.float32)
            ratio = (photo / np.maximum(model, DARKEST_REFLECTANCE) * weight).astype(np.float32)
            light = np.clip(smoothed_light(ratio, weight, SHADOW_SMOOTHING), *SHADOW_LIGHT_RANGE)
        return light

    def _gray(self, renders: np.ndarray) -> np.ndarray:
        """``(N, C, ...)`` colour renders as ``(N, 1, ...)`` in the reading channel's gray."""
        return np.einsum("ncyx,c->nyx", renders, np.asarray(self.rasterizer.channel, dtype=renders.dtype))[:, None]

    @staticmethod
    def _light(photo: np.ndarray, render: np.ndarray, fields: np.ndarray) -> np.ndarray:
        """The light on the print as coefficients: for each of the render's ``C`` channels
        (``(C, h * w)``) a contrast field, then one brightness field, each a combination of the
        smooth ``fields`` (``(h * w, k)``), least squares against ``photo``: ``(C + 1, k)``.

        One contrast field per colour channel: the photo's gray is a linear mix of the printed
        colours that the capture changed (faded ink, white balance, the camera's tint), so a
        colour print is fitted as its own mix rather than as one fixed gray."""
        design = np.concatenate([fields * channel[:, None] for channel in render] + [fields], axis=1)
        coef = least_squares(design, photo.ravel())
        return coef.reshape(len(render) + 1, fields.shape[1])

    def _in_light(
        self, photo: np.ndarray, renders: np.ndarray, fields: np.ndarray, grid: GridLight | None = None
    ) -> np.ndarray:
        """``renders`` (``(n, C, h * w)``) in the light :meth:`_light` fits between the first of
        them and ``photo``: ``(n, h * w)``, what each would look like in the photo. ``grid``:
        also in its shade (:meth:`GridLight.shade`), the smooth light fitted to the photo with
        the shade divided out, in turn, :data:`SHADE_ROUNDS` times."""
        light = fields @ self._light(photo, renders[0], fields).T
        if grid is None:
            return np.einsum("pc,ncp->np", light[:, :-1], renders) + light[:, -1]
        asked = photo.ravel().astype(np.float64)
        shade = grid.shade(asked, np.einsum("pc,cp->p", light[:, :-1], renders[0]) + light[:, -1])
        for _ in range(SHADE_ROUNDS - 1):
            light = fields @ self._light(photo / shade.reshape(photo.shape), renders[0], fields).T
            shade = grid.shade(asked, np.einsum("pc,cp->p", light[:, :-1], renders[0]) + light[:, -1])
        return shade[None] * (np.einsum("pc,ncp->np", light[:, :-1], renders) + light[:, -1])

    def _ask(
        self, photo: np.ndarray, blurred: np.ndarray, fields: np.ndarray, grid: GridLight | None = None
    ) -> np.ndarray:
        """``(N_b,)`` evidence of ``photo`` (``(h, w)``) on each bit, from ``blurred``: the
        word's render and its one-bit variants, blurred like the print, ``(N_b + 1, C, h * w)``;
        ``fields``: the light's smooth basis (:meth:`_light_fields`); ``grid``: a cast shadow's shade
        on top of it (:class:`GridLight`)."""
        # the light on the print: contrast and brightness as smooth fields over the drawing
        # (a gradient or a broad shadow), fitted on the word's own render
        models = self._in_light(photo, blurred, fields, grid)
        residual = photo.ravel() - models[0]
        changes = models[1:] - models[0]
        # a small misalignment: what a small motion of the word's render explains is evidence
        # for no bit (projected out of residual and changes alike by the projector P = I - B B^T)
        basis = self._motion_basis(models[0].reshape(photo.shape))
        residual_moved = residual @ basis
        changes_moved = changes @ basis
        # |P(r - d)|^2 - |P r|^2 = |P d|^2 - 2 (P r).(P d), each from products with B, never
        # projecting the (N_b, h * w) changes themselves, which took three times as long
        change = np.einsum("ij,ij->i", changes, changes) - np.einsum("ij,ij->i", changes_moved, changes_moved)
        cross = changes @ residual - changes_moved @ residual_moved
        return (change - 2.0 * cross) / np.maximum(change, 1e-9)

    def read(self, pyramid: ImagePyramid, homography: np.ndarray, probabilities: np.ndarray) -> np.ndarray:
        """Refined ``(N_b,)`` bit probabilities: the CNN's, plus the photo's evidence.

        The photo is aligned once to the morph of the CNN's probabilities (soft bits give a
        morph between the two values of an uncertain bit, which bends the alignment least);
        what misalignment is left, :meth:`evidence` discounts. Then each round asks the photo
        about every bit of the current hard decisions and decides again, until nothing changes.
        The alignment is not redone each round: that reads no more drawings and takes longer.
        The photo is asked as it is, with no shadow divided out: that freedom also takes up
        another drawing's strokes where this one would be (an icon printed in the ghost's place
        left a ghost's word unexplained by 1.2-1.6 instead of over :data:`HOPELESS_DEVIATION`),
        which would cost rounds and bend the reading towards a word.
        A round whose word leaves the photo unexplained by more than :data:`HOPELESS_DEVIATION` is
        the last: another drawing than this one, which further rounds would not read (each costs
        about 12 ms).
        """
        p = np.clip(np.asarray(probabilities, dtype=np.float64), 1e-4, 1 - 1e-4)
        cnn = np.log(p / (1 - p))
        bits = (p > 0.5).astype(np.uint8)
        soft = p
        width = max(self.template.images)
        soft_morph = morph_template(self.model, self.template.viewbox, p, width, self.renderer)
        # OpenCV's ECC rather than the faster inverse-compositional solve: its wider basin reads
        # more hard prints against this blurry soft morph
        aligned = refine_at(pyramid, homography, soft_morph, width, ALIGN_ITERATIONS, wide_basin=True)
        H = homography if aligned is None else aligned.homography
        for _ in range(READ_ROUNDS):
            asked = self.evidence(pyramid, H, bits, False, False)  # in the reading channel's gray, unlit
            said = asked.evidence
            logits = cnn + EVIDENCE_WEIGHT * np.where(bits == 1, said, -said)
            # as probabilities, on a scale where evidence of +-1 gives about 0.993 and the CNN
            # still counts: what is reported
            soft = 1.0 / (1.0 + np.exp(-np.clip(logits / (EVIDENCE_WEIGHT / 5), -30, 30)))
            new = (logits > 0).astype(np.uint8)
            if np.array_equal(new, bits) or asked.deviation > HOPELESS_DEVIATION:
                break
            bits = new
        return soft.astype(np.float32)


@lru_cache(maxsize=8)
def _light_fields_of(shape: tuple[int, int]) -> np.ndarray:
    """:meth:`MorphSynthesis._light_fields` of ``shape``, made once per size (read-only): every
    ask of a photo rectified to the same size uses the same fields."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    x = (2 * x / max(w - 1, 1) - 1).ravel()
    y = (2 * y / max(h - 1, 1) - 1).ravel()
    fields = np.stack([x**i * y**j for i in range(LIGHT_DEGREE + 1) for j in range(LIGHT_DEGREE + 1 - i)], axis=1)
    fields.flags.writeable = False
    return fields


def _blurred(renders: np.ndarray, sigma: float) -> np.ndarray:
    """``renders`` (``(..., h, w)``) each blurred by a Gaussian of ``sigma`` pixels."""
    flat = renders.reshape(-1, *renders.shape[-2:])
    return np.stack([cv2.GaussianBlur(r, (0, 0), sigma) for r in flat]).reshape(renders.shape)


def morph_template(
    model: DeepMorphModel,
    viewbox: tuple[float, float, float, float],
    code_bits: np.ndarray,
    width: int,
    renderer: Renderer = render_svg_resvg,
) -> Template:
    """The drawing morphed by ``(N_b,)`` code bits, rendered by a real renderer (``renderer``,
    resvg unless given) at ``width``. Soft bits (between 0 and 1) give a morph between the two
    values of each uncertain bit."""
    values = torch.from_numpy(model.morph_values_one(code_bits))
    return Template.from_svg(model.drawing.to_svg(values), viewbox, (width,), renderer)


__all__ = [
    "BIT_FIELDS",
    "BLUR_SIGMAS",
    "CHECK_WIDTH",
    "HOPELESS_DEVIATION",
    "MAX_CONTRADICTED",
    "MAX_DEVIATION",
    "MIN_OWN_EVIDENCE",
    "MIN_WEAKEST_SUM",
    "SHADOW_MARGIN",
    "SHADOW_SMOOTHING",
    "SYNTH_WIDTH",
    "WEAKEST_BITS",
    "BitEvidence",
    "GridLight",
    "MorphSynthesis",
    "BIT_RULES",
    "broken_rules",
    "disagreement",
    "disagreement_in",
    "morph_template",
]
