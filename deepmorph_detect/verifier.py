"""A model's proposal verifier: a small CNN that tells its own prints from other drawings
before a blind proposal's wider searches.

The universal detector proposes every printed drawing in a photo. Each other drawing it proposes
whose outline does not align at once takes the wider searches to be turned away
(:meth:`Aligner.align_outline <deepmorph_detect.align.Aligner.align_outline>`), and those were
most of a 1280x720 frame's time. A verifier trained for one drawing
(``deepmorph train-verifier``, :mod:`deepmorph.training.verifier`) looks at the proposal's crop
once (0.4 ms with ONNX Runtime) and lets the searches go ahead only where it may be this drawing.

The crop is the proposal's quadrilateral grown by :data:`CROP_GROWTH` about its centre, warped
to :data:`CROP_SIZE` pixels square and stretched between its 2nd and 98th percentiles. The
detector does not know which corner is the drawing's top left, so the score is the best over
the crop's four quarter turns, run as one batch. Its ONNX graph is stored with it and run by
ONNX Runtime (:mod:`deepmorph_detect.runtime`).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor, nn

from deepmorph_core.bundle import check_weights
from deepmorph_core.graphs import StoredGraph, make_graph, weights_fingerprint
from deepmorph_core.model import DeepMorphModel
from deepmorph_detect.network import fused_for_inference
from deepmorph_detect.runtime import onnx_or_torch

#: pixels across a proposal's crop
CROP_SIZE = 64
#: the crop spans the proposal's quadrilateral grown by this factor about its centre: a print's
#: outline from the detector may fall short of its ink by a tenth of its width
CROP_GROWTH = 1.3
#: the crop's gray is stretched between these percentiles and clipped to this range around [0, 1]
CROP_PERCENTILES = (2.0, 98.0)
CROP_RANGE = (-0.5, 1.5)
#: the network's channels, first layer to last (each a stride-2 convolution)
CHANNELS = (16, 32, 64, 64)

# the outer edges of the crop's corner pixels (pixel centres are whole numbers), so that the
# proposal's corners rolled by one give the crop turned by a quarter turn, pixel for pixel
_EDGE = CROP_SIZE - 0.5
_CROP_CORNERS = np.float32([[-0.5, -0.5], [_EDGE, -0.5], [_EDGE, _EDGE], [-0.5, _EDGE]])


def proposal_crop(gray: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """The ``(CROP_SIZE, CROP_SIZE)`` float32 crop the verifier reads for a proposal whose
    frame lies on ``corners`` (``(4, 2)`` pixels) in ``gray`` (``(H, W)``, any scale)."""
    quad = np.asarray(corners, np.float32)
    centre = quad.mean(0)
    grown = centre + CROP_GROWTH * (quad - centre)
    warp = cv2.getPerspectiveTransform(grown, _CROP_CORNERS)
    crop = cv2.warpPerspective(
        gray, warp, (CROP_SIZE, CROP_SIZE), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE
    ).astype(np.float32)
    lo, hi = np.percentile(crop, CROP_PERCENTILES)
    stretched = (crop - np.float32(lo)) / np.float32(max(hi - lo, 1e-3))
    return np.clip(stretched, *CROP_RANGE).astype(np.float32, copy=False)


def quarter_turns(crops: Tensor) -> Tensor:
    """``(B, 1, S, S)`` crops -> ``(4 B, 1, S, S)``: each batch turned by 0, 1, 2 and 3 quarter
    turns, in that order."""
    return torch.cat([torch.rot90(crops, k, (2, 3)) for k in range(4)])


class VerifierNet(nn.Module):
    """``(B, 1, CROP_SIZE, CROP_SIZE)`` crops -> ``(B,)`` logits that each is this drawing:
    four stride-2 convolutions with batch norm and ReLU, averaged over the crop, one linear
    layer."""

    def __init__(self) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        for cin, cout in zip((1, *CHANNELS), CHANNELS, strict=False):
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.BatchNorm2d(cout), nn.ReLU()]
        self.features = nn.Sequential(*layers)
        self.logit = nn.Linear(CHANNELS[-1], 1)

    def forward(self, crops: Tensor) -> Tensor:
        return self.logit(self.features(crops).mean((2, 3))).reshape(-1)


class TurnedProbabilities(nn.Module):
    """What the verifier's ONNX graph computes: ``(4, 1, S, S)``, one crop at its four quarter
    turns (:func:`quarter_turns`) -> ``(4,)``, the probability that each is this drawing."""

    def __init__(self, net: nn.Module) -> None:
        super().__init__()
        self.net = net

    def forward(self, turned: Tensor) -> Tensor:
        return torch.sigmoid(self.net(turned))


def verifier_tensors(net: nn.Module) -> dict[str, Tensor]:
    """The network's state dict as a bundle files it: ``verifier.*``, on the CPU."""
    return {f"verifier.{k}": v.detach().cpu() for k, v in net.state_dict().items()}


def stored_verifier(model: DeepMorphModel) -> VerifierNet | None:
    """The verifier a bundle stores, weights checked and loaded (eval mode); ``None`` when it
    stores none.

    Raises:
        DeepMorphError: the stored weights do not fit the network.
    """
    if model.meta.verifier is None:
        return None
    net = VerifierNet()
    weights = {k.removeprefix("verifier."): v for k, v in model.verifier_state.items()}
    check_weights(model.source or model.meta.drawing_name, "verifier", net.state_dict(), weights)
    net.load_state_dict(weights)
    return net.eval()


def _examples(n: int) -> list[Tensor]:
    generator = torch.Generator().manual_seed(0)
    return [quarter_turns(torch.rand(1, 1, CROP_SIZE, CROP_SIZE, generator=generator)) for _ in range(n)]


def verifier_graph(net: nn.Module) -> StoredGraph:
    """The verifier exported to ONNX as :class:`TurnedProbabilities` (batch norms folded; input
    ``crops``, output ``probability``), checked against PyTorch.

    Raises:
        GraphError: export failed or the graph does not give PyTorch's outputs.
    """
    module = TurnedProbabilities(fused_for_inference(net.eval()))
    fingerprint = weights_fingerprint(verifier_tensors(net), "verifier")
    return make_graph(module, _examples(3), "crops", ["probability"], fingerprint)


class ProposalVerifier:
    """Scores a proposal: whether it may be this model's drawing.

    Args:
        net: the trained network (eval mode).
        threshold: a proposal scored below it is not this drawing.
        model: the model it belongs to (where its ONNX graph is stored and kept).
        device: where it runs (another device than the CPU: PyTorch there).
    """

    def __init__(self, net: VerifierNet, threshold: float, model: DeepMorphModel | None = None, device: str = "cpu"):
        self.threshold = threshold
        eager = TurnedProbabilities(fused_for_inference(net.eval()))
        self.run = onnx_or_torch(model, "verifier", eager, _examples(2), lambda: verifier_graph(net), device=device)

    def score(self, gray: np.ndarray, corners: np.ndarray) -> float:
        """The probability that the proposal on ``corners`` in ``gray`` is this drawing (the best
        over its crop's quarter turns)."""
        crop = torch.from_numpy(proposal_crop(gray, corners))[None, None]
        with torch.inference_mode():
            return float(self.run(quarter_turns(crop)).max())

    def turns_away(self, gray: np.ndarray, corners: np.ndarray) -> bool:
        """Whether the proposal on ``corners`` scores below the threshold: not this drawing."""
        return self.score(gray, corners) < self.threshold


def verifier_for(model: DeepMorphModel, device: str = "cpu") -> ProposalVerifier | None:
    """The verifier ``model`` stores, ready to score proposals; ``None`` when it stores none."""
    net = stored_verifier(model)
    if net is None or model.meta.verifier is None:
        return None
    return ProposalVerifier(net, model.meta.verifier.threshold, model, device)


__all__ = [
    "CROP_GROWTH",
    "CROP_PERCENTILES",
    "CROP_RANGE",
    "CROP_SIZE",
    "ProposalVerifier",
    "TurnedProbabilities",
    "VerifierNet",
    "proposal_crop",
    "quarter_turns",
    "stored_verifier",
    "verifier_for",
    "verifier_graph",
    "verifier_tensors",
]
