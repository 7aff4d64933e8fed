"""A trained DeepMorph model: drawing + codec + encoder + decoder, and what it does.

:class:`DeepMorphModel` encodes payloads into morphed SVG, reads the bits of an image in
which the drawing fills the frame, and saves and loads itself as a bundle
(:mod:`deepmorph_core.bundle`). Training lives in :mod:`deepmorph.training.codec`; finding and
reading drawings in photos is the photo chain's (:mod:`deepmorph_detect`), which builds on this.
The networks' ONNX graphs travel with the model (:attr:`DeepMorphModel.graphs`): the decoder's
is exported when training ends (:meth:`DeepMorphModel.store_decoder_graph`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from deepmorph_core.bundle import BundleMeta, TrainingRecord, check_weights, load_bundle, save_bundle, versions
from deepmorph_core.code import Code
from deepmorph_core.codec import CodecSpec, DecodeResult, PayloadCodec
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning, SvgError
from deepmorph_core.framing import frame_renders
from deepmorph_core.graphs import GraphError, StoredGraph, make_graph, read_graphs, weights_fingerprint
from deepmorph_core.luminance import Channel, stretch_ink
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.networks import Decoder, DecoderConfig, Encoder, decoder_parameters, fused_for_inference
from deepmorph_core.payload import Payload, PayloadLike
from deepmorph_core.raster import RasterSettings, SoftRasterizer
from deepmorph_core.reading_channel import channel_name
from deepmorph_core.registration import UnmorphedRegistration
from deepmorph_core.svg.reader import GEOMETRY_VERSION

#: What a drawing to train on may have: the analysis before training renders every variable's
#: extremes (its time grows with variables times shapes), and a step renders every shape. At
#: these limits it takes about 15 s and a step about 3 times a Feather icon's.
MAX_TRAIN_PRIMITIVES = 200
MAX_TRAIN_VARIABLES = 400
#: No DeepMorph decoder comes near this many weights (the default one at 96 px has about 0.4
#: million): a bundle asking for more is refused before anything is allocated.
MAX_DECODER_PARAMETERS = 50_000_000


@dataclass
class Detection:
    """One decoded drawing in an image: the decode, its per-bit probabilities and where it is."""

    result: DecodeResult
    probabilities: np.ndarray
    bbox: tuple[int, int, int, int] | None = None

    @property
    def payload(self) -> Payload:
        """The payload read (the best guess even when :attr:`ok` is false)."""
        return Payload(self.result.payload)

    @property
    def ok(self) -> bool:
        """Whether the payload is vouched for (its CRC, and any check the reader adds)."""
        return bool(self.result.ok)

    def to_json(self) -> dict[str, Any]:
        out = self.result.to_json()
        out["bit_probabilities"] = [round(float(p), 4) for p in self.probabilities]
        if self.bbox is not None:
            out["bbox"] = list(self.bbox)
        return out


def check_trainable(md: MorphableDrawing, name: str) -> None:
    """Refuse a drawing no model can be trained on: no variables, or more shapes or variables
    than training handles.

    Raises:
        DeepMorphError: naming the drawing and what to do.
    """
    if md.n_variables == 0:
        raise DeepMorphError(
            f"{name}: the drawing has 0 variables, so nothing can carry bits; add dm: bounds or pass --move"
        )
    shapes = len(md.drawing.primitives)
    if shapes > MAX_TRAIN_PRIMITIVES or md.n_variables > MAX_TRAIN_VARIABLES:
        raise DeepMorphError(
            f"{name}: {shapes} shapes and {md.n_variables} variables; a drawing to train on may have at "
            f"most {MAX_TRAIN_PRIMITIVES} shapes and {MAX_TRAIN_VARIABLES} variables (mark the elements that "
            'need not morph dm:fixed="true", or simplify the drawing)'
        )


@dataclass
class DeepMorphModel:
    """Everything needed to hide payloads in one drawing and read them back.

    Attributes:
        drawing: the morphable drawing (with the bound defaults it was trained with).
        codec: payload <-> code bits.
        encoder, decoder: the networks.
        width: image width (pixels) the decoder reads; height follows the drawing's aspect.
        meta: the bundle metadata (configuration, versions, training record).
        graphs: ONNX graphs of the networks by name (``decoder``, ``detector``, ``verifier``), each checked
            against PyTorch when it was made; saved with the bundle while their weights stay.
        source: the file the model was loaded from (named in messages), if any.
    """

    drawing: MorphableDrawing
    codec: PayloadCodec
    encoder: Encoder
    decoder: Decoder
    width: int
    meta: BundleMeta
    extra_tensors: dict[str, Tensor] = field(default_factory=dict)
    detector_state: dict[str, Tensor] = field(default_factory=dict)
    verifier_state: dict[str, Tensor] = field(default_factory=dict)
    graphs: dict[str, StoredGraph] = field(default_factory=dict)
    source: str | None = None

    # -- construction and files -----------------------------------------------------------

    @classmethod
    def create(
        cls,
        drawing_svg: str,
        drawing_name: str,
        bounds_defaults: dict[str, Any],
        codec: CodecSpec,
        width: int,
        raster: dict[str, Any],
        augment: dict[str, Any],
        train: dict[str, Any],
        decoder_config: DecoderConfig | None = None,
        label: str | None = None,
        reading_channel: Channel | None = None,
    ) -> DeepMorphModel:
        """A fresh (untrained) model for a drawing (``label`` names it in SVG errors), read in
        ``reading_channel`` (``None``: the one :func:`~deepmorph_core.reading_channel.choose_channel`
        picks for a colour drawing, luminance for black and white)."""
        md = MorphableDrawing.load(
            drawing_svg.encode(),
            label=label or drawing_name,
            geometry=GEOMETRY_VERSION,
            **_bound_kwargs(bounds_defaults),
        )
        md.read_in(reading_channel)
        check_trainable(md, drawing_name)
        height, _ = md.drawing.pixel_size(width)
        dcfg = decoder_config or DecoderConfig()
        meta = BundleMeta(
            versions=versions(),
            drawing_name=drawing_name,
            drawing_svg=drawing_svg,
            bounds_defaults=bounds_defaults,
            geometry=GEOMETRY_VERSION,
            n_variables=md.n_variables,
            reading_channel=md.channel,
            codec=codec,
            image_width=width,
            raster=raster,
            decoder=dcfg,
            augment=augment,
            train=train,
            record=TrainingRecord(),
        )
        return cls(
            md,
            PayloadCodec(codec),
            Encoder(codec.code_bits, md.n_variables),
            Decoder(codec.code_bits, (height, width), dcfg),
            width,
            meta,
        )

    @classmethod
    def load(cls, path: str | Path) -> DeepMorphModel:
        """Load a bundle (``.dmm``); one clear error for anything unusable."""
        meta, tensors = load_bundle(path)
        try:
            md = MorphableDrawing.load(
                meta.drawing_svg.encode(), geometry=meta.geometry, **_bound_kwargs(meta.bounds_defaults)
            )
        except SvgError as exc:
            raise DeepMorphError(f"{path}: the drawing inside the model cannot be read: {exc.message}") from None
        md.channel = tuple(meta.reading_channel)
        if md.n_variables != meta.n_variables:
            raise DeepMorphError(
                f"{path}: the drawing now has {md.n_variables} variables but the model was trained with "
                f"{meta.n_variables} (a primitive plugin is missing or changed?)"
            )
        height, _ = md.drawing.pixel_size(meta.image_width)
        size = decoder_parameters(meta.codec.code_bits, (height, meta.image_width), meta.decoder)
        if size > MAX_DECODER_PARAMETERS:
            raise DeepMorphError(
                f"{path}: not a usable DeepMorph model file (its decoder would have {size:,} weights, "
                f"more than any DeepMorph decoder: {MAX_DECODER_PARAMETERS:,})"
            )
        model = cls(
            md,
            PayloadCodec(meta.codec),
            Encoder(meta.codec.code_bits, md.n_variables),
            Decoder(meta.codec.code_bits, (height, meta.image_width), meta.decoder),
            meta.image_width,
            meta,
        )
        nets = {k: v for k, v in tensors.items() if k.startswith(("encoder.", "decoder."))}
        model.detector_state = {k: v for k, v in tensors.items() if k.startswith("detector.")}
        model.verifier_state = {k: v for k, v in tensors.items() if k.startswith("verifier.")}
        model.extra_tensors = {
            k: v for k, v in tensors.items() if k not in nets and not k.startswith(("detector.", "verifier.", "graph."))
        }
        for name, state in (("detector", model.detector_state), ("verifier", model.verifier_state)):
            if getattr(meta, name) is not None and not state:
                raise DeepMorphError(f"{path}: not a usable DeepMorph model file ({name} weights are missing)")
        for name, network in (("encoder", model.encoder), ("decoder", model.decoder)):
            given = {k[len(name) + 1 :]: v for k, v in nets.items() if k.startswith(name + ".")}
            check_weights(path, name, network.state_dict(), given)
            network.load_state_dict(given)
        model.graphs = read_graphs(path, meta.graphs, tensors)
        model.source = str(path)
        model.eval()
        return model

    def tensors(self) -> dict[str, Tensor]:
        """The networks' weights as the bundle files them (``encoder.``, ``decoder.``, ``detector.``,
        ``verifier.``)."""
        tensors = {f"encoder.{k}": v for k, v in self.encoder.state_dict().items()}
        tensors.update({f"decoder.{k}": v for k, v in self.decoder.state_dict().items()})
        tensors.update(self.detector_state)
        tensors.update(self.verifier_state)
        return tensors

    def save(self, path: str | Path, extra: dict[str, Tensor] | None = None) -> None:
        """Write the bundle atomically (``extra``: optimiser/RNG state in checkpoints), with the
        graphs of :attr:`graphs` whose network has not changed since they were exported (a
        graph of weights trained further is dropped)."""
        tensors = self.tensors()
        self.graphs = {
            name: graph
            for name, graph in self.graphs.items()
            if graph.meta.weights_sha256 == weights_fingerprint(tensors, name)
        }
        self.meta.graphs = {name: graph.meta for name, graph in self.graphs.items()}
        for name, graph in self.graphs.items():
            tensors[f"graph.{name}"] = torch.from_numpy(np.frombuffer(graph.data, dtype=np.uint8).copy())
        tensors.update(extra or {})
        save_bundle(path, self.meta, tensors)

    def decoder_graph(self) -> StoredGraph:
        """The decoder (batch norms folded) exported to ONNX for one ``(1, 1, H, W)`` image
        (input ``image``, 1 = white paper; output ``logits``) and checked against PyTorch.

        Raises:
            GraphError: export failed or the graph does not give PyTorch's outputs.
        """
        generator = torch.Generator().manual_seed(0)
        examples = [torch.rand(1, 1, *self.image_size, generator=generator) for _ in range(3)]
        fingerprint = weights_fingerprint(self.tensors(), "decoder")
        return make_graph(fused_for_inference(self.decoder), examples, "image", ["logits"], fingerprint)

    def store_decoder_graph(self) -> bool:
        """Export the decoder's graph into :attr:`graphs` (saved with the bundle); when that
        fails, warn (:class:`~deepmorph_core.errors.DeepMorphWarning`) and go on: PyTorch runs
        the decoder. Returns whether a graph was stored."""
        try:
            self.graphs["decoder"] = self.decoder_graph()
        except GraphError as exc:
            self.graphs.pop("decoder", None)
            warnings.warn(DeepMorphWarning(f"the decoder's ONNX graph was not stored: {exc}"), stacklevel=2)
            return False
        return True

    def use_code(self, spec: CodecSpec) -> None:
        """Read and write payloads with the code ``spec`` from now on: the codec and the bundle's
        metadata, which must agree (a cut code, a lengthened CRC)."""
        self.codec = PayloadCodec(spec)
        self.meta.codec = spec

    def eval(self) -> DeepMorphModel:
        self.encoder.eval()
        self.decoder.eval()
        return self

    @property
    def image_size(self) -> tuple[int, int]:
        """``(H, W)`` of decoder inputs."""
        return self.decoder.image_size

    @property
    def print_px(self) -> int | None:
        """The smallest width in camera pixels its prints were trained to be read at (``train
        --pixels``; the capture's blur in those pixels), or ``None`` for a model trained the
        96-pixel way (its frame stands for any print)."""
        value = self.meta.train.get("print_px")
        return None if value is None else int(value)

    @property
    def registered(self) -> bool:
        """Whether its training registered each render onto the unmorphed drawing, as the photo
        chain aligns its photos (:mod:`deepmorph_core.registration`; ``train --pixels``). Models
        trained before that was stored were not."""
        return bool(self.meta.train.get("registered"))

    @property
    def smallest_print_px(self) -> int:
        """The narrowest print in a photo the model reads: its :attr:`print_px`, or its decoder's
        frame (a print narrower than either loses the detail its bits are in)."""
        return self.print_px or self.width

    def raster_settings(self, width: int | None = None) -> RasterSettings:
        """The soft rasterizer's settings the model was trained with, at ``width`` (``None``: the
        model's). A bundle that records no ``flat_fills`` was written before black-and-white
        fills went flat, and renders them over their whole box as it was trained."""
        return RasterSettings(**{"flat_fills": None, **self.meta.raster, "width": width or self.width})

    def rasterizer(self, width: int | None = None) -> SoftRasterizer:
        """The soft rasterizer at the model's settings, at ``width`` (``None``: the model's)."""
        return SoftRasterizer(self.drawing.space, self.raster_settings(width), channel=self.drawing.channel)

    # -- encoding -------------------------------------------------------------------------

    def morph_values(self, code_bits: Tensor) -> Tensor:
        """Morph values for ``(B, N_b)`` code bits (no gradient)."""
        with torch.no_grad():
            return self.drawing.values_from_unit(self.encoder(code_bits.float()))

    def morph_values_one(self, code_bits: np.ndarray) -> np.ndarray:
        """:meth:`morph_values` of one ``(N_b,)`` code word (or soft bits), in numpy float64:
        ``(N_v,)``, the same numbers to float rounding, for the morph the photo chain renders
        for each payload it checks."""
        bits = np.asarray(code_bits, dtype=np.float64).reshape(-1)
        weight = self.encoder.linear.weight.detach().numpy()  # (N_v, N_b), a view
        if bits.shape[0] != weight.shape[1]:
            raise ValueError(f"expected {weight.shape[1]} code bits, got shape {bits.shape}")
        unit = 1.0 / (1.0 + np.exp(-(weight.astype(np.float64) @ (2.0 * bits - 1.0))))
        return self.drawing.space.values_from_unit_one(unit)

    def encode(self, payload: PayloadLike) -> str:
        """The morphed SVG document carrying ``payload`` (any form :meth:`Payload.of
        <deepmorph_core.payload.Payload.of>` takes: an int, hex or binary text, bytes, bits)."""
        bits = Payload.of(payload, self.codec.spec.payload_bits).bits
        code = self.codec.encode(bits)
        values = self.morph_values(torch.from_numpy(code.astype(np.float32))[None])
        return self.drawing.to_svg(values[0])

    def code(self, payload: PayloadLike) -> Code:
        """``payload`` hidden in the drawing, as a :class:`~deepmorph_core.code.Code` (its SVG,
        and renders of it for print)."""
        value = Payload.of(payload, self.codec.spec.payload_bits)
        return Code(value, self.encode(value), self.drawing.drawing.viewbox)

    def real_renders(self, values: Tensor, rgb: bool = False) -> Tensor:
        """resvg renders ``(k, 1, H, W)`` (paper white; ``(k, 3, H, W)`` colour with ``rgb``) of
        ``(k, N_v)`` morph values at the decoder's width."""
        return self.drawing.render_real(values, self.width, rgb=rgb).to(values.device)

    def framed(self, renders: Tensor, registered: bool | None = None) -> Tensor:
        """Clean renders ``(B, C, h, w)`` (paper white) as the decoder meets them before the
        capture's corruption, as training and validation frame theirs: ink stretched as photos
        are, framed by their ink (:func:`~deepmorph_core.framing.frame_renders`), and for a
        :attr:`registered` model registered onto the unmorphed drawing and framed again, as the
        photo chain's view is. ``registered``: whether to register, where not as the model
        says (training's clean first rung does not). ``(B, C, H, W)``."""
        framed = self._framed_by_ink(stretch_ink(renders, self.drawing.ink_level))
        if not (self.registered if registered is None else registered):
            return framed
        return self._framed_by_ink(self.registration(framed.device)(framed))

    def registration(self, device: torch.device | str = "cpu") -> UnmorphedRegistration:
        """The registration onto the unmorphed drawing's resvg render, framed as renders are
        (built once per device)."""
        device = torch.device(device)
        cached = getattr(self, "_registration", None)
        if cached is None or cached[0] != device:
            neutral = self.real_renders(self.drawing.neutral_values(), rgb=self.drawing.colour)
            template = self._framed_by_ink(stretch_ink(neutral, self.drawing.ink_level))
            cached = (device, UnmorphedRegistration(template, self.drawing.channel).to(device))
            self._registration = cached
        return cached[1]

    def _framed_by_ink(self, images: Tensor) -> Tensor:
        return frame_renders(images, self.canonical_moments(), self.image_size, self.drawing.channel)

    # -- decoding -------------------------------------------------------------------------

    def canonical_moments(self) -> Tensor:
        """Ink moments (cx, cy, sx, sy) of the unmorphed drawing in the decoder's frame."""
        if not hasattr(self, "_moments"):
            self._moments = self.drawing.neutral_moments(self.width)
        return self._moments

    def probabilities(self, images: Tensor) -> Tensor:
        """Per-bit probabilities for decoder-ready images ``(B, 1, H, W)``."""
        with torch.no_grad():
            return torch.sigmoid(self.decoder(images))

    def info(self) -> dict[str, Any]:
        """A JSON-ready description of the bundle."""
        m = self.meta
        return {
            "drawing": m.drawing_name,
            "payload_bits": m.codec.payload_bits,
            "code_bits": m.codec.code_bits,
            "codec": {**m.codec.model_dump(), "ecc_bits": m.codec.ecc_bits},
            "n_variables": m.n_variables,
            "image_size": list(self.image_size),
            # narrower prints in a photo lose detail; decode calls them too small
            "smallest_print_px": self.smallest_print_px,
            # the gray its colour prints are read in: luminance, red, green or blue
            "reading_channel": channel_name(m.reading_channel),
            "decoder": m.decoder.model_dump(),
            "bounds_defaults": m.bounds_defaults,
            "augment": m.augment,
            "train": m.train,
            "record": m.record.model_dump(),
            "versions": m.versions,
            "detector": None if m.detector is None else m.detector.model_dump(),
            "verifier": None if m.verifier is None else m.verifier.model_dump(),
            "tuning": m.tuning,
            "validation": [r.model_dump() for r in m.validation],
            "trust": None if m.trust is None else {**m.trust.model_dump(), "text": m.trust.describe()},
            "graphs": {name: graph.meta.model_dump() for name, graph in self.graphs.items()},
        }


def _bound_kwargs(defaults: dict[str, Any]) -> dict[str, Any]:
    return {
        k: (tuple(v) if isinstance(v, list) else v)
        for k, v in defaults.items()
        if k in ("move", "shift", "scale", "rotate")
    }


__all__ = ["DeepMorphModel", "Detection"]
