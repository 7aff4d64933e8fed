"""The universal detector: one network, trained once on many drawings, that proposes the printed
drawings in a photo for any model (registered as ``universal``).

A per-drawing detector (``centrenet``, ``deepmorph train-detector``) learns the frame of one
drawing: its viewBox, which no photo shows. The universal detector learns what every print
shows: the **ink square**, the square around the box of a drawing's ink, centred on it, as wide
as its longer side (:func:`ink_square`). It is :class:`~deepmorph_detect.network.DetectorNet`
trained on scenes of the shared line and colour sets (``python -m
deepmorph.training.universal``), shipped in ``deepmorph_detect/data``. For a model, each
proposed square is mapped to the model's viewBox through the model's own ink square; alignment,
reading and the checks then decide which proposals are that drawing, as for any detector.

The file is a safetensors file: the network's weights under ``detector.``, its ONNX graph under
``graph.detector``, and :class:`UniversalMeta` (how it was trained) as its metadata.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar, Literal

import cv2
import numpy as np
import torch
from pydantic import BaseModel, ConfigDict, Field

from deepmorph_core.bundle import GraphMeta, TrainingRecord, check_weights, load_tagged, save_tagged, versions
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.graphs import StoredGraph, read_graphs
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.photo import to_gray
from deepmorph_core.protocols import Candidate
from deepmorph_core.render import render_svg_rgb
from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.centrenet import MAX_WIDTH, MIN_WIDTH, CentreNetDetector, Runner, detector_runner
from deepmorph_detect.network import DetectorNet, detector_tensors, stored_weights
from deepmorph_detect.propose import quad_bbox

FORMAT = "deepmorph-universal-detector/1"
DETECTOR_FILE = "DeepMorph detector file"
MAX_DETECTOR_BYTES = 64 * 1024 * 1024
#: The universal detector shipped with the package.
UNIVERSAL_PATH = Path(__file__).parent / "data" / "universal-detector.safetensors"
#: Render width at which a drawing's ink is found, and the luminance below which a pixel is ink
#: (any colour darker or more saturated than a pale tint).
INK_RENDER_WIDTH = 256
INK_LEVEL = 0.9
#: a peak of the photo mirrored within this share of a print's side from a peak of the photo
#: itself is the same print (:func:`merged_with_mirrored`)
SAME_PRINT = 0.35


class UniversalMeta(BaseModel):
    """What a universal detector file records besides its weights.

    Attributes:
        width: the network's channel width.
        config: the training settings (:class:`~deepmorph.training.universal.UniversalConfig`).
        record: steps, time and threads of the training.
        training_set: the drawing sets it was trained on, how many of each, and the rule that
            held drawings out for benchmarks.
        graphs: the stored ONNX graph (``detector``).
    """

    model_config = ConfigDict(extra="forbid")

    format: Literal["deepmorph-universal-detector/1"] = FORMAT
    versions: dict[str, str] = Field(default_factory=versions)
    width: int = Field(ge=MIN_WIDTH, le=MAX_WIDTH)
    config: dict[str, Any]
    record: TrainingRecord
    training_set: dict[str, Any] = Field(default_factory=dict)
    graphs: dict[str, GraphMeta] = Field(default_factory=dict, max_length=1)


def save_universal(
    path: str | Path, net: DetectorNet, meta: UniversalMeta, graph: StoredGraph | None, extra: dict[str, torch.Tensor]
) -> None:
    """Write a universal detector file atomically (``extra``: a checkpoint's optimiser state)."""
    tensors = detector_tensors(net)
    meta = meta.model_copy(update={"graphs": {"detector": graph.meta} if graph is not None else {}})
    if graph is not None:
        tensors["graph.detector"] = torch.frombuffer(bytearray(graph.data), dtype=torch.uint8)
    save_tagged(path, meta, {**tensors, **extra})


def load_universal(path: str | Path) -> tuple[DetectorNet, StoredGraph | None, UniversalMeta, dict[str, torch.Tensor]]:
    """The network (eval mode), its stored graph when whole, the metadata, and every tensor of
    the file (a checkpoint's optimiser state among them).

    Raises:
        DeepMorphError: a missing, corrupt or foreign file, or weights that do not fit.
    """
    meta, tensors = load_tagged(path, UniversalMeta, FORMAT, DETECTOR_FILE, MAX_DETECTOR_BYTES)
    net = DetectorNet(meta.width)
    weights = stored_weights({k: v for k, v in tensors.items() if k.startswith("detector.")})
    check_weights(path, "detector", net.state_dict(), weights, DETECTOR_FILE)
    net.load_state_dict(weights)
    graphs = read_graphs(path, meta.graphs, tensors)
    return net.eval(), graphs.get("detector"), meta, tensors


@functools.lru_cache(maxsize=4)
def shared_runner(path: str = str(UNIVERSAL_PATH), device: str = "cpu") -> Runner:
    """The universal network of ``path``, loaded once per process and device and run as the
    per-drawing detector runs (ONNX Runtime from its stored graph, else PyTorch; PyTorch on a
    device other than the CPU)."""
    net, graph, _, _ = load_universal(path)
    return detector_runner(net, None, graph, device)


def ink_square(svg: str, viewbox: tuple[float, float, float, float]) -> np.ndarray:
    """``(4, 2)`` corners (TL, TR, BR, BL, in SVG units) of the square around the box of the
    drawing's ink, centred on the box, as wide as its longer side: what the universal detector
    finds. A drawing with no ink gets its viewBox's corners.

    Ink is any pixel of the render on white whose darkest channel is below :data:`INK_LEVEL`.
    """
    return ink_square_of(render_svg_rgb(svg, INK_RENDER_WIDTH), viewbox)


def ink_square_of(rgb: np.ndarray, viewbox: tuple[float, float, float, float]) -> np.ndarray:
    """:func:`ink_square` from the drawing's render ``(H, W, 3)`` on white, in ``[0, 1]``."""
    x0, y0, vw, vh = viewbox
    ys, xs = np.nonzero(rgb.min(-1) < INK_LEVEL)
    if len(xs) == 0:
        return viewbox_corners(viewbox)
    h, w = rgb.shape[:2]
    sx, sy = vw / w, vh / h
    left, right = x0 + xs.min() * sx, x0 + (xs.max() + 1) * sx
    top, bottom = y0 + ys.min() * sy, y0 + (ys.max() + 1) * sy
    cx, cy, half = (left + right) / 2, (top + bottom) / 2, max(right - left, bottom - top) / 2
    return np.array([[cx - half, cy - half], [cx + half, cy - half], [cx + half, cy + half], [cx - half, cy + half]])


class UniversalDetector(CentreNetDetector):
    """The universal detector for one model: its ink squares, mapped to the model's viewBox.

    Args:
        square: the model's :func:`ink_square` (SVG units).
        viewbox: the model's viewBox.
        runner: the shared network (:func:`shared_runner`).
        threshold: minimum centre probability of a peak.
        max_detections: proposals kept per photo (highest first).
        flip_test: also read the photo mirrored left to right and merge the two readings, as
            CenterNet tests: the network is not quite symmetric, and a print one reading
            scores under the threshold the other may not (:func:`merged_with_mirrored`).
    """

    name: ClassVar[str] = "universal"

    def __init__(  # noqa: PLR0913
        self,
        square: np.ndarray,
        viewbox: tuple[float, float, float, float],
        runner: Runner,
        threshold: float = 0.2,
        max_detections: int = 12,
        flip_test: bool = True,
    ) -> None:
        self.net = runner
        self.threshold = threshold
        self.max_detections = max_detections
        self.flip_test = flip_test
        self.square = np.asarray(square, dtype=np.float64)
        self.frame = viewbox_corners(viewbox)

    @classmethod
    def from_model(cls, model: DeepMorphModel, device: str = "cpu") -> UniversalDetector:
        """The universal detector for ``model`` (every model has one), its network on ``device``.

        Raises:
            DeepMorphError: the shipped detector file is missing or damaged.
        """
        if not UNIVERSAL_PATH.is_file():
            raise DeepMorphError(
                f"{UNIVERSAL_PATH}: the universal detector is not installed with this copy of DeepMorph"
                " (reinstall it, or train one: python -m deepmorph.training.universal)"
            )
        md = model.drawing
        viewbox = md.drawing.viewbox
        return cls(ink_square(md.to_svg(md.neutral_values()[0]), viewbox), viewbox, shared_runner(device=device))

    @classmethod
    def graph(cls, model: DeepMorphModel) -> StoredGraph | None:
        """The shipped network's ONNX graph (the same for every model)."""
        return load_universal(UNIVERSAL_PATH)[1]

    def detect(self, image: np.ndarray) -> list[Candidate]:
        """The network's ink squares mapped to the model's viewBox corners (TL, TR, BR, BL as
        far as the square's order tells; alignment tries the other cyclic orders). With
        :attr:`flip_test`, the photo is read mirrored too and the readings merged
        (:func:`merged_with_mirrored`): the last of :meth:`detect_in_stages`."""
        *_, every = self.detect_in_stages(image)
        return every

    def detect_in_stages(self, image: np.ndarray) -> Iterator[list[Candidate]]:
        """:meth:`detect`'s proposals as they come: the photo's own reading first, then (with
        :attr:`flip_test`) every proposal, merged with the mirrored reading's. A caller content
        with the first print that reads (:meth:`Locator.locate
        <deepmorph_detect.locate.Locator.locate>` with ``first``) tries the first list before
        the network runs again; a proposal the merge leaves as it was is the same in both."""
        gray = to_gray(image)
        h, w = gray.shape
        small, scale = self._shrunk(gray)
        found = self._peaks(small, scale)
        yield self._candidates(found, w, h)
        if self.flip_test:
            in_mirror = self._peaks(np.ascontiguousarray(small[:, ::-1]), scale)
            mirrored = [(unmirrored(quad, small.shape[1] / scale), score) for quad, score in in_mirror]
            yield self._candidates(merged_with_mirrored(found, mirrored)[: self.max_detections], w, h)

    def _candidates(self, found: list[tuple[np.ndarray, float]], w: int, h: int) -> list[Candidate]:
        """Peaks ``(quad, score)`` in a ``w`` x ``h`` photo as blind candidates of this drawing."""
        out = []
        for quad, score in found:
            to_image = cv2.getPerspectiveTransform(self.square.astype(np.float32), quad.astype(np.float32))
            corners = project(to_image, self.frame)
            out.append(Candidate(corners, score, quad_bbox(corners, w, h), source=self.name, sized=True, blind=True))
        return out


def unmirrored(quad: np.ndarray, width: float) -> np.ndarray:
    """A ``(4, 2)`` quad found in a photo mirrored left to right (``width`` pixels wide), in the
    photo itself, its corners in the same roles (the mirrored top-left is the top-right)."""
    out = np.array(quad, dtype=np.float64)
    out[:, 0] = width - out[:, 0]
    return out[[1, 0, 3, 2]]


def merged_with_mirrored(
    found: list[tuple[np.ndarray, float]], mirrored: list[tuple[np.ndarray, float]]
) -> list[tuple[np.ndarray, float]]:
    """Peaks of a photo and of its mirror image (:func:`unmirrored`), as ``(quad, score)``, merged:
    a mirrored peak whose centre lies within :data:`SAME_PRINT` of a print's side from a peak of
    the photo is that print, its quad the two averaged by score and its score the higher; the
    others are added. Best first."""
    merged = [(np.asarray(quad, dtype=np.float64), score) for quad, score in found]
    taken = [False] * len(found)  # the photo's peaks, each merged with one mirrored peak at most
    for quad, score in sorted(mirrored, key=lambda peak: -peak[1]):
        centre = quad.mean(0)
        near = [
            i for i in range(len(found))
            if not taken[i] and np.linalg.norm(merged[i][0].mean(0) - centre) < SAME_PRINT * _side(merged[i][0])
        ]  # fmt: skip
        if not near:
            merged.append((quad, score))
            continue
        i = min(near, key=lambda k: np.linalg.norm(merged[k][0].mean(0) - centre))
        other, other_score = merged[i]
        quad = min((np.roll(quad, k, 0) for k in range(4)), key=lambda rolled: np.abs(rolled - other).sum())
        merged[i] = ((other * other_score + quad * score) / (other_score + score), max(score, other_score))
        taken[i] = True
    return sorted(merged, key=lambda peak: -peak[1])


def _side(quad: np.ndarray) -> float:
    """The mean side of a ``(4, 2)`` quad, in pixels."""
    return float(np.linalg.norm(quad - np.roll(quad, 1, 0), axis=1).mean())


__all__ = [
    "UNIVERSAL_PATH",
    "UniversalDetector",
    "UniversalMeta",
    "ink_square",
    "ink_square_of",
    "SAME_PRINT",
    "load_universal",
    "merged_with_mirrored",
    "save_universal",
    "shared_runner",
    "unmirrored",
]
