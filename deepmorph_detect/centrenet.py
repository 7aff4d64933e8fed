"""The built-in detector: peaks of :class:`~deepmorph_detect.network.DetectorNet`'s centre heatmap,
each with the quadrilateral its corner offsets give (registered as ``centrenet``). Its ONNX
graph (:func:`detector_graph`) is stored in the bundle when its training ends and run by ONNX
Runtime (:mod:`deepmorph_detect.runtime`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import cv2
import numpy as np
import torch
from torch import Tensor, nn

from deepmorph_core.bundle import check_weights
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.graphs import StoredGraph, make_graph, weights_fingerprint
from deepmorph_core.kernels import SQUARE_3X3, area_resize
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_core.protocols import Candidate
from deepmorph_detect.network import (
    INPUT_SIZE,
    STRIDE,
    DetectorGraph,
    DetectorNet,
    detector_tensors,
    fused_for_inference,
    standardise,
    stored_weights,
)
from deepmorph_detect.propose import quad_bbox
from deepmorph_detect.runtime import onnx_or_torch

# x, y of the centres of a 3x3 block of heatmap cells, from its top-left cell
MIN_WIDTH, MAX_WIDTH = 8, 256  # the detector's channel widths (DetectorConfig's bounds)
_CELL_CENTRES = np.stack(np.mgrid[0:3, 0:3][::-1], -1).astype(np.float64) + 0.5


class CentreNetDetector:
    """The built-in detector: :class:`~deepmorph_detect.network.DetectorNet` peaks.

    Args:
        net: trained network (eval mode).
        threshold: minimum centre probability of a peak.
        max_detections: peaks kept per image (highest first).
    """

    name: ClassVar[str] = "centrenet"

    def __init__(
        self,
        net: DetectorNet,
        threshold: float = 0.3,
        max_detections: int = 12,
        model: DeepMorphModel | None = None,
        device: str = "cpu",
    ) -> None:
        self.net = detector_runner(net, model, device=device)
        self.threshold = threshold
        self.max_detections = max_detections

    @classmethod
    def from_model(cls, model: DeepMorphModel, device: str = "cpu") -> CentreNetDetector | None:
        """The detector stored in a bundle, or ``None`` when it has none (or one of another kind);
        its network runs on ``device`` (a resolved torch device name)."""
        net = stored_net(model)
        return None if net is None else cls(net, model=model, device=device)

    @classmethod
    def graph(cls, model: DeepMorphModel) -> StoredGraph | None:
        """The ONNX graph of the detector a bundle stores (:func:`detector_graph`), the stored one
        when it has one; ``None`` when it has no detector of this kind.

        Raises:
            GraphError: no graph could be made.
        """
        net = stored_net(model)
        if net is None:
            return None
        return model.graphs.get("detector") or detector_graph(net)

    def detect(self, image: np.ndarray) -> list[Candidate]:
        """Quadrilaterals (corners TL, TR, BR, BL in pixels) and scores, best first."""
        gray = to_gray(image)
        h, w = gray.shape
        found = self._peaks(*self._shrunk(gray))
        return [Candidate(quad, score, quad_bbox(quad, w, h), source="detector") for quad, score in found]

    @staticmethod
    def _shrunk(gray: np.ndarray) -> tuple[np.ndarray, float]:
        """``gray`` area-shrunk to fit :data:`~deepmorph_detect.network.INPUT_SIZE` (not yet
        padded), and the scale it was shrunk by."""
        h, w = gray.shape
        W, H = INPUT_SIZE
        scale = min(W / w, H / h)
        return area_resize(gray, (max(1, round(w * scale)), max(1, round(h * scale)))), scale

    def _peaks(self, small: np.ndarray, scale: float) -> list[tuple[np.ndarray, float]]:
        """``(4, 2)`` quads (pixels of the photo ``small`` was shrunk from by ``scale``, corners
        in the network's order) and their centre probabilities, for every peak above
        :attr:`threshold`, best first."""
        W, H = INPUT_SIZE
        rh, rw = small.shape
        small = cv2.copyMakeBorder(small, 0, H - rh, 0, W - rw, cv2.BORDER_REPLICATE)
        with torch.inference_mode():
            heat, corners = self.net(torch.from_numpy(np.ascontiguousarray(small, dtype=np.float32))[None, None])
            p_np, c_np = torch.sigmoid(heat)[0, 0].numpy(), corners[0].numpy()
        # local maxima over 3x3 cells (the border counts as lower than any cell)
        peaks = (p_np == cv2.dilate(p_np, SQUARE_3X3)) & (p_np > self.threshold)
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
            out.append((quad * STRIDE / scale, float(p_np[y, x])))
        return out


#: The detector network as the photo chain calls it: ``(1, 1, H, W)`` gray -> heat, corners.
Runner = Callable[[Tensor], Any]


def detector_runner(
    net: DetectorNet, model: DeepMorphModel | None, graph: StoredGraph | None = None, device: str = "cpu"
) -> Runner:
    """``net`` run by ONNX Runtime from the graph ``model`` stores (or ``graph``, or one exported
    now): 0.75x PyTorch's time; by PyTorch where no graph can be had; on another ``device``, by
    PyTorch there."""
    # where ONNX Runtime cannot run it: channels-last, with batch norms folded into their
    # convolutions, runs this small convolution stack about a quarter faster on CPU
    eager = fused_for_inference(net).to(memory_format=torch.channels_last)
    generator = torch.Generator().manual_seed(0)
    W, H = INPUT_SIZE
    examples = [torch.rand(1, 1, H, W, generator=generator) for _ in range(2)]
    return onnx_or_torch(
        model, "detector", TorchDetector(eager), examples, lambda: detector_graph(net), graph, device,
        lambda: DetectorGraph(fused_for_inference(net)),
    )  # fmt: skip


_ROLLS = np.array([[(i - k) % 4 for i in range(4)] for k in range(4)])  # row k: corner order rolled by k


def _same_order(quads: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Each of ``(n, 4, 2)`` quads cyclically rolled to match ``ref`` corner by corner."""
    rolled = quads[:, _ROLLS]  # (n, 4 rolls, 4 corners, 2)
    best = np.abs(rolled - ref).sum((2, 3)).argmin(1)
    return rolled[np.arange(len(quads)), best]


class TorchDetector:
    """The PyTorch detector (batch norms folded) called as its ONNX graph is, on gray: what runs
    where no graph can be had. The standardisation is numpy's (:func:`~deepmorph_detect.network.standardise`),
    four times faster here than torch's reductions."""

    def __init__(self, net: nn.Module) -> None:
        self.net = net

    def __call__(self, gray: Tensor) -> tuple[Tensor, Tensor]:
        x = torch.from_numpy(standardise(gray[0, 0].numpy()))[None, None]
        with torch.inference_mode():
            return self.net(x.contiguous(memory_format=torch.channels_last))


def stored_net(model: DeepMorphModel) -> DetectorNet | None:
    """The built-in detector network a bundle stores, weights loaded and checked; ``None`` when
    the bundle has no detector or one of another kind.

    Raises:
        DeepMorphError: the stored detector does not fit the network.
    """
    meta = model.meta.detector
    if meta is None or meta.name != CentreNetDetector.name:
        return None
    width = meta.config.get("width", 32)
    if not isinstance(width, int) or not MIN_WIDTH <= width <= MAX_WIDTH:
        raise DeepMorphError(
            f"{model.meta.drawing_name}: the model's detector has width {width!r} "
            f"(a detector is {MIN_WIDTH} to {MAX_WIDTH} channels wide)"
        )
    net = DetectorNet(width)
    weights = stored_weights(model.detector_state)
    check_weights(model.meta.drawing_name, "detector", net.state_dict(), weights)
    net.load_state_dict(weights)
    return net.eval()


def detector_graph(net: nn.Module) -> StoredGraph:
    """The detector exported to ONNX as :class:`~deepmorph_detect.network.DetectorGraph` (batch
    norms folded) for one photo at :data:`~deepmorph_detect.network.INPUT_SIZE` (input
    ``image``; outputs ``heat`` and ``corners``), checked against PyTorch.

    Raises:
        GraphError: export failed or the graph does not give PyTorch's outputs.
    """
    W, H = INPUT_SIZE
    generator = torch.Generator().manual_seed(0)
    examples = [torch.rand(1, 1, H, W, generator=generator) for _ in range(3)]
    weights = detector_tensors(net)
    module = DetectorGraph(fused_for_inference(net))
    return make_graph(module, examples, "image", ["heat", "corners"], weights_fingerprint(weights, "detector"))


__all__ = ["CentreNetDetector", "TorchDetector", "detector_graph", "stored_net"]
