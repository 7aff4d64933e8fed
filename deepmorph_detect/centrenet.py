"""The built-in detector: peaks of :class:`~deepmorph_detect.network.DetectorNet`'s centre heatmap,
each with the quadrilateral its corner offsets give (registered as ``centrenet``)."""

from __future__ import annotations

from typing import ClassVar

import cv2
import numpy as np
import torch

from deepmorph_core.bundle import check_weights
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.kernels import SQUARE_3X3, area_resize
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_core.protocols import Candidate
from deepmorph_detect.network import INPUT_SIZE, STRIDE, DetectorNet, fused_for_inference, standardise, stored_weights
from deepmorph_detect.propose import quad_bbox
from deepmorph_detect.runtime import detector_graph, onnx_or_torch

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

    def __init__(self, net: DetectorNet, threshold: float = 0.3, max_detections: int = 12) -> None:
        # where ONNX Runtime cannot run it: channels-last, with batch norms folded into their
        # convolutions, runs this small convolution stack about a quarter faster on CPU
        eager = fused_for_inference(net).to(memory_format=torch.channels_last)
        W, H = INPUT_SIZE
        example = torch.randn(1, 1, H, W, generator=torch.Generator().manual_seed(0))
        # ONNX Runtime where it gives the same outputs (deepmorph_detect.runtime): 0.75x the time
        self.net = onnx_or_torch(eager, lambda: detector_graph(eager, H, W), example)
        self.threshold = threshold
        self.max_detections = max_detections

    @classmethod
    def from_model(cls, model: DeepMorphModel) -> CentreNetDetector | None:
        """The detector stored in a bundle, or ``None`` when it has none (or one of another kind)."""
        meta = model.meta.detector
        if meta is None or meta.name != cls.name:
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
        return cls(net)

    def detect(self, image: np.ndarray) -> list[Candidate]:
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
            quad = quad * STRIDE / scale
            out.append(Candidate(quad, float(p_np[y, x]), quad_bbox(quad, w, h), source="detector"))
        return out


_ROLLS = np.array([[(i - k) % 4 for i in range(4)] for k in range(4)])  # row k: corner order rolled by k


def _same_order(quads: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Each of ``(n, 4, 2)`` quads cyclically rolled to match ``ref`` corner by corner."""
    rolled = quads[:, _ROLLS]  # (n, 4 rolls, 4 corners, 2)
    best = np.abs(rolled - ref).sum((2, 3)).argmin(1)
    return rolled[np.arange(len(quads)), best]
