"""Reading a drawing's payload: rectified views, first looks, second looks, a last look by synthesis.

The aligned drawing is rectified (perspective removed) :data:`RECTIFY_WIDTH_FACTOR` decoder
widths wide, framed by its ink as training frames its renders, and read by the model's decoder
(run by ONNX Runtime from the graph the bundle stores). :meth:`Reader.looks` yields readings of
one drawing in the order they are tried; the caller stops at the first payload that passes
every check (:mod:`deepmorph_detect.check`):

1. the first looks: each view (the most confident passing reading first);
2. the rectified view framed where the alignment puts the unmorphed drawing's ink rather than
   by the photo's ink (:meth:`Reader.read_framed_by_template`);
3. second looks (:meth:`Reader.read_again`), decoded with hard decisions;
4. the last look by synthesis (:meth:`Reader.read_by_synthesis`), always checked bit by bit.

A reading that passes the CRC but not the checks does not end the search: a near miss caught by
the per-bit check at the first look is often read right by a later one.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch

from deepmorph_core.codec import DecodeResult
from deepmorph_core.framing import align_to_frame, mask_moments_one
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.networks import fused_for_inference
from deepmorph_core.photo import flatten_illumination
from deepmorph_detect.check import MORPH_WIDTH, MorphTemplates
from deepmorph_detect.refine import ImagePyramid, Template, refine_at, warp_to_template
from deepmorph_detect.runtime import onnx_or_torch
from deepmorph_detect.synthesis import MorphSynthesis

RECTIFY_WIDTH_FACTOR = 2  # the rectified drawing is this many decoder widths wide
TEMPLATE_INK = 0.5  # ink of the unmorphed drawing's render (contrast-stretched as photos are)


@dataclass(frozen=True)
class Reading:
    """One reading of a drawing: the codec's decode and the decoder's per-bit probabilities."""

    result: DecodeResult
    probabilities: np.ndarray


class Reader:
    """Reads one model's drawing from aligned photos.

    Args:
        model: the trained model.
        template: the unmorphed drawing's template (the rectified views' frame).
        morphs: the drawing's morph templates (second looks align to a misread's morph).
        synthesis: reading by synthesis, for the last look.
        ink_thickness: the thickest ink feature in pixels of a rectified view (flat light).
        device: where the decoder runs (a resolved torch device name; the CPU by ONNX Runtime).
    """

    def __init__(
        self,
        model: DeepMorphModel,
        template: Template,
        morphs: MorphTemplates,
        synthesis: MorphSynthesis,
        ink_thickness: float,
        device: str = "cpu",
    ) -> None:
        self.model = model
        self.template = template
        self.morphs = morphs
        self.synthesis = synthesis
        self.ink_thickness = ink_thickness
        self.view_width = model.width * RECTIFY_WIDTH_FACTOR
        # the decoder's graph run by ONNX Runtime (PyTorch, batch norms folded, where there is
        # none): about half the time per reading
        generator = torch.Generator().manual_seed(0)
        examples = [torch.rand(1, 1, *model.image_size, generator=generator) for _ in range(2)]
        self.decoder = onnx_or_torch(
            model, "decoder", fused_for_inference(model.decoder), examples, model.decoder_graph, device=device
        )

    @functools.cached_property
    def template_moments(self) -> np.ndarray:
        """Where the unmorphed drawing's ink lies in a rectified view (its moments, for
        :meth:`read_framed_by_template`): rendered once, when a reading first needs it, not for
        every locator (4 ms for the largest panel drawing)."""
        unmorphed = self.model.drawing.to_svg(self.model.drawing.neutral_values()[0])
        return mask_moments_one(
            self.synthesis.renderer(unmorphed, self.view_width, self.template.viewbox) < TEMPLATE_INK
        )

    def rectify(self, pyramid: ImagePyramid, H: np.ndarray) -> np.ndarray:
        """The drawing's viewBox seen head-on, :attr:`view_width` pixels wide."""
        return warp_to_template(pyramid, H, self.template, self.view_width)

    def read(self, view: np.ndarray, soft: bool, moments: np.ndarray | None = None) -> Reading | None:
        """The payload reading of one view, or ``None`` when the view shows no ink. The view is
        framed by its ink as in training, or by ``moments`` (the ink's moments in the view)
        where given."""
        model = self.model
        aligned = align_to_frame(view, model.image_size, model.canonical_moments(), moments)
        if aligned is None:
            return None
        with torch.inference_mode():
            logits = self.decoder(torch.from_numpy(aligned[0])[None, None])
        probs = torch.sigmoid(logits)[0].numpy()
        return Reading(model.codec.decode(probs, soft=soft), probs)

    def looks(
        self,
        pyramid: ImagePyramid,
        H: np.ndarray,
        views: list[np.ndarray],
        readings: list[Reading],
        soft: bool,
        first_only: bool = False,
        firsts: list[Reading] | None = None,
    ) -> Iterator[tuple[Reading, bool | None]]:
        """Readings of one drawing, each with the ``bitwise`` argument its check takes, in the
        order they are tried (see the module); the caller appends each reading to ``readings``
        before asking for the next. ``first_only``: the first looks alone (a drawing that
        aligned too poorly to be worth the later ones). ``firsts``: the :meth:`first_looks` of
        ``views``, where the caller already read them."""
        if firsts is None:
            firsts = self.first_looks(views, soft)
        for reading in firsts:
            yield reading, None
        if first_only:
            return
        framed = self.read_framed_by_template(views[0], soft)
        if framed is not None:
            yield framed, None
        for reading in self.read_again(pyramid, H, views[0], firsts):
            yield reading, None
        if readings:
            yield self.read_by_synthesis(pyramid, H, readings), True

    def first_looks(self, views: list[np.ndarray], soft: bool) -> list[Reading]:
        """The first looks: each view read as it is, the most confident passing reading first."""
        firsts = [r for r in (self.read(view, soft) for view in views) if r is not None]
        firsts.sort(key=lambda r: (r.result.ok, r.result.confidence), reverse=True)
        return firsts

    def read_framed_by_template(self, view: np.ndarray, soft: bool) -> Reading | None:
        """The rectified view framed where the alignment puts the unmorphed drawing's ink
        (:attr:`template_moments`), not where the photo's ink is: a shadow across a light fill,
        or a fill as dark as the ink threshold, changes the photo's ink mask and with it the
        framing the decoder was trained on. Decoded as the first looks are, and tried only when
        none of them passed (``docs/design-notes.md``)."""
        return self.read(view, soft, self.template_moments)

    def read_again(
        self, pyramid: ImagePyramid, H: np.ndarray, view: np.ndarray, readings: list[Reading]
    ) -> Iterator[Reading]:
        """Second looks at a drawing whose first readings did not pass:

        1. the same view with shadows and light gradients divided out (a shadow edge reads as
           ink and drags the framing off);
        2. the photo aligned again to the morph that the failed reading describes (its hard
           decisions, a few of them wrong): most of its points sit where the photo's do, so the
           alignment no longer bends to absorb the morph. Then both views are read again.

        Second looks decode with hard decisions only (BCH, no soft search): every extra look is
        another chance for a garbage reading to pass the CRC, and the soft search multiplies that
        chance (``docs/codec.md``).
        """
        for attempt in self.second_looks(pyramid, H, view, readings):
            reading = self.read(attempt, soft=False)
            if reading is not None:
                yield reading

    def second_looks(
        self, pyramid: ImagePyramid, H: np.ndarray, view: np.ndarray, readings: list[Reading]
    ) -> Iterator[np.ndarray]:
        """The views :meth:`read_again` reads."""
        yield flatten_illumination(view, self.ink_thickness)
        if not readings:
            return
        best = max(readings, key=lambda r: r.result.confidence).probabilities
        realigned = refine_at(pyramid, H, self.morphs.of_code(best > 0.5), MORPH_WIDTH)
        if realigned is None:
            return
        again = self.rectify(pyramid, realigned.homography)
        yield again
        yield flatten_illumination(again, self.ink_thickness)

    def read_by_synthesis(self, pyramid: ImagePyramid, H: np.ndarray, readings: list[Reading]) -> Reading:
        """The last look: the most confident reading's probabilities with the photo's own
        evidence on each bit (:meth:`MorphSynthesis.read`), decoded with hard decisions.

        Its payload, when one passes the CRC, is always checked bit by bit.
        """
        best = max(readings, key=lambda r: r.result.confidence).probabilities
        probs = self.synthesis.read(pyramid, H, best)
        return Reading(self.model.codec.decode(probs, soft=False), probs)


__all__ = ["RECTIFY_WIDTH_FACTOR", "Reader", "Reading"]
