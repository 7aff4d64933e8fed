"""Training the detector on synthetic scenes (``deepmorph train-detector``).

Every step draws a fresh batch of scenes from :class:`~deepmorph_detect.scenes.SceneMaker` at
the network's input size: zero to three payload morphs of the model's drawing, other drawings
(bundled Feather icons) and ArUco markers as negatives, over photos and clutter, at medium and
hard severity. Batches are seeded by ``(seed, step)`` and made in a worker process (the other
core), so a run is reproducible and ``--resume`` continues exactly where a checkpoint stopped.

The steps, the log, checkpoints, resume and interrupts are :mod:`deepmorph.training.loop`'s;
checkpoints are the bundle itself plus optimiser state, written atomically.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from pydantic import BaseModel, ConfigDict
from torch import Tensor

from deepmorph.training.detector_settings import DetectorSettings, SceneSettings
from deepmorph.training.loop import Panel, TrainingLoop
from deepmorph_core.bundle import DetectorMeta, TrainingRecord
from deepmorph_core.device import torch_device
from deepmorph_core.errors import DeepMorphError, DeepMorphWarning
from deepmorph_core.fileio import same_file
from deepmorph_core.graphs import GraphError
from deepmorph_core.heap import keep_freed_memory
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.severity import PHOTO_SIZE
from deepmorph_core.threads import use_threads
from deepmorph_detect.centrenet import CentreNetDetector, detector_graph
from deepmorph_detect.network import (
    INPUT_SIZE,
    STRIDE,
    DetectorNet,
    detector_tensors,
    focal_loss,
    normalise_input,
    stored_weights,
)
from deepmorph_detect.scenes import Placement, Scene, SceneMaker
from deepmorph_detect.universal import UNIVERSAL_PATH, load_universal


class SceneTrainingConfig(BaseModel, SceneSettings):
    """Settings of a detector network trained on scenes, validated (stored with it): the fields,
    defaults and bounds are :class:`~deepmorph.training.detector_settings.SceneSettings`'."""

    model_config = ConfigDict(extra="forbid")


class DetectorConfig(BaseModel, DetectorSettings):
    """A model's own detector's training settings, validated (stored in the bundle): the
    fields, defaults and bounds are :class:`~deepmorph.training.detector_settings.DetectorSettings`',
    which ``deepmorph train-detector`` reads too."""

    model_config = ConfigDict(extra="forbid")


def targets_for(placements: list[Placement], size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Training targets on the stride-8 grid for the model's drawings in a scene.

    Returns:
        heat ``(1, h, w)`` (Gaussian splats, 1 at each centre cell), corner offsets
        ``(8, h, w)`` in cells from each cell centre, and their weight mask ``(1, h, w)``
        (the 3x3 cells around each centre).
    """
    W, H = size
    w, h = W // STRIDE, H // STRIDE
    heat = np.zeros((1, h, w), np.float32)
    corners = np.zeros((8, h, w), np.float32)
    mask = np.zeros((1, h, w), np.float32)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    for p in placements:
        if p.kind != "drawing":
            continue
        c = _centre(p) / STRIDE
        size_cells = float(np.linalg.norm(p.corners[2] - p.corners[0])) / STRIDE / math.sqrt(2)
        sigma = max(0.6, size_cells / 8)
        cx, cy = int(np.clip(np.floor(c[0]), 0, w - 1)), int(np.clip(np.floor(c[1]), 0, h - 1))
        g = np.exp(-((xs + 0.5 - c[0]) ** 2 + (ys + 0.5 - c[1]) ** 2) / (2 * sigma**2))
        heat[0] = np.maximum(heat[0], g)
        heat[0, cy, cx] = 1.0
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                x, y = cx + dx, cy + dy
                if 0 <= x < w and 0 <= y < h:
                    corners[:, y, x] = (p.corners / STRIDE - np.array([x + 0.5, y + 0.5])).ravel()
                    mask[0, y, x] = 1.0
    return heat, corners, mask


def _centre(p: Placement) -> np.ndarray:
    """Image position of the centre of a placement's frame (projective, not the corner mean)."""
    a, b, c, d = p.corners
    # intersection of the diagonals a-c and b-d
    x1, y1, x2, y2, x3, y3, x4, y4 = *a, *c, *b, *d
    den = (x1 - x2) * (y3 - y4) - (y1 - y2) * (x3 - x4)
    if abs(den) < 1e-9:
        return p.corners.mean(0)
    t = ((x1 - x3) * (y3 - y4) - (y1 - y3) * (x3 - x4)) / den
    return np.array([x1 + t * (x2 - x1), y1 + t * (y2 - y1)])


class SceneBatches(torch.utils.data.IterableDataset):
    """Batches of ``(image, heat, corners, mask)`` for steps ``[start, stop)``, each seeded by
    ``(seed, step)``: the same step always gets the same scenes.

    In a :class:`~torch.utils.data.DataLoader` with workers, worker ``k`` of ``n`` makes steps
    ``start + k``, ``start + k + n``, ...; the loader takes them from its workers in turn, so the
    steps arrive once each and in order, as with no workers (without the split, every worker
    would make every step and each batch would be trained on once per worker).
    """

    def __init__(self, model: DeepMorphModel | None, config: Any, start: int, stop: int) -> None:
        super().__init__()
        self.model, self.cfg, self.start, self.stop = model, config, start, stop

    def makers(self) -> dict[str, SceneMaker]:
        """The scene makers by severity (made in each worker)."""
        return {
            sev: SceneMaker(self.model, INPUT_SIZE, sev, seed=self.cfg.seed, payload_pool=96, camera_width=PHOTO_SIZE)
            for sev in ("medium", "hard")
        }

    def make(self, maker: SceneMaker, rng: np.random.Generator) -> Scene:
        """One training scene: up to three of the model's prints, other icons, an ArUco marker."""
        n = int(rng.choice([0, 1, 1, 1, 1, 2, 2, 3]))
        return maker.make(drawings=n, distractors=int(rng.integers(0, 3)), aruco=bool(rng.random() < 0.2))

    def __iter__(self) -> Iterator[tuple[Tensor, Tensor, Tensor, Tensor]]:
        torch.set_num_threads(1)
        makers = self.makers()
        worker = torch.utils.data.get_worker_info()
        first, every = (0, 1) if worker is None else (worker.id, worker.num_workers)
        for step in range(self.start + first, self.stop, every):
            rng = np.random.default_rng([self.cfg.seed, step])
            imgs, heats, corners, masks = [], [], [], []
            for _ in range(self.cfg.batch):
                maker = makers["hard" if rng.random() < 0.5 else "medium"]
                maker.rng = np.random.default_rng(rng.integers(2**63))
                scene = self.make(maker, rng)
                gray = scene.image.astype(np.float32).mean(-1) / 255.0
                h, c, m = targets_for(scene.placements, INPUT_SIZE)
                imgs.append(gray[None])
                heats.append(h)
                corners.append(c)
                masks.append(m)
            yield (
                torch.from_numpy(np.stack(imgs)),
                torch.from_numpy(np.stack(heats)),
                torch.from_numpy(np.stack(corners)),
                torch.from_numpy(np.stack(masks)),
            )


#: The plot of a detector training log.
DETECTOR_PANELS = (
    Panel("loss", ("loss",), log_scale=True),
    Panel("centre recall (training batches)", ("recall",), unit_range=True),
    Panel("corner error (px at 256x192)", ("corner",)),
)


@dataclass
class DetectorSummary:
    bundle: Path
    log: Path
    plot: Path | None
    steps: int
    elapsed_s: float


class DetectorRun:
    """Training (or resuming) the detector of a bundle, for the shared loop
    (:class:`~deepmorph.training.loop.Run`); every checkpoint writes the bundle ``out``."""

    panels = DETECTOR_PANELS

    def __init__(self, model: DeepMorphModel, config: DetectorConfig, out: Path):
        self.model = model
        self.set_up(config, out)
        meta = model.meta.detector
        resuming = meta is not None and not meta.record.finished and "dtrain.step" in model.extra_tensors
        self.record = meta.record if resuming and meta else TrainingRecord(total_steps=config.steps)
        self.earlier = list(meta.earlier) if meta is not None and (resuming or config.fine_tune) else []
        if config.fine_tune and not resuming:
            if meta is None or not meta.record.finished:
                raise DeepMorphError("--fine-tune needs a model whose detector training has finished")
            stored_width = int(meta.config.get("width", 32))
            if stored_width != config.width:
                raise DeepMorphError(f"--fine-tune: the model's detector has width {stored_width}, not {config.width}")
            self.net.load_state_dict(stored_weights(model.detector_state))
            self.earlier.append({"config": meta.config, "record": meta.record.model_dump()})
        elif config.start == "universal" and not resuming:
            universal, _, meta_u, _ = load_universal(UNIVERSAL_PATH)
            if meta_u.width != config.width:
                raise DeepMorphError(
                    f"the universal detector has width {meta_u.width}, not {config.width}: "
                    f"use --channels {meta_u.width}, or start from scratch"
                )
            self.net.load_state_dict(universal.state_dict())
            self.earlier.append({"config": {"universal": meta_u.config}, "record": meta_u.record.model_dump()})
        self.record.total_steps = config.steps
        self.record.threads = torch.get_num_threads()
        self.record.device = self.device.type
        if resuming:
            self.net.load_state_dict(stored_weights(model.detector_state))
            restore_optimiser(self.opt, model.extra_tensors)
        self._batches: Iterator[tuple[Tensor, Tensor, Tensor, Tensor]] | None = None

    def set_up(self, config: SceneSettings, out: Path) -> None:
        """Threads, seed, the device, a fresh network on it and its optimiser."""
        self.cfg, self.out = config, Path(out)
        if config.threads:
            use_threads(config.threads)
        keep_freed_memory()  # each step reuses the last one's pages (deepmorph_core/heap.py)
        self.device = torch_device(config.device)
        torch.manual_seed(config.seed)  # the weights are drawn on the CPU, the same on either device
        self.net = DetectorNet(config.width).to(self.device)
        self.opt = torch.optim.Adam(self.net.parameters(), lr=config.lr)

    def dataset(self) -> SceneBatches:
        """The scenes of the steps still to train."""
        return SceneBatches(self.model, self.cfg, self.record.step, self.cfg.steps)

    def checkpoint(self) -> None:
        """Write the bundle with the detector (and optimiser state until finished; at the end,
        with the detector's ONNX graph)."""
        self.model.detector_state = detector_tensors(self.net)
        self.model.meta.detector = DetectorMeta(
            name=CentreNetDetector.name, config=self.cfg.model_dump(), record=self.record, earlier=self.earlier
        )
        extra: dict[str, Tensor] = {}
        if not self.record.finished:
            extra = optimiser_tensors(self.opt, self.record.step)
        else:
            self.net.eval()
            try:
                self.model.graphs["detector"] = detector_graph(self.net)
            except GraphError as exc:
                warnings.warn(DeepMorphWarning(f"the detector's ONNX graph was not stored: {exc}"), stacklevel=2)
        self.model.extra_tensors = {}
        self.model.save(self.out, extra=extra)

    def _lr(self) -> float:
        progress = min(1.0, self.record.step / max(1, self.cfg.steps))
        return self.cfg.lr * (0.05 + 0.95 * 0.5 * (1 + math.cos(math.pi * progress)))

    def step(self) -> dict[str, float]:
        """One optimisation step on the next batch of scenes; its losses, centre recall and
        corner error (pixels at the network's input size)."""
        if self._batches is None:  # scene workers start with the first step
            data = self.dataset()
            workers = self.cfg.workers
            self._batches = iter(
                torch.utils.data.DataLoader(
                    data,
                    batch_size=None,
                    num_workers=workers,
                    multiprocessing_context="fork" if workers else None,
                    prefetch_factor=4 if workers else None,
                )
            )
            self.net.train()
        img, heat, corners, mask = (t.to(self.device) for t in next(self._batches))
        hl, cl = self.net(normalise_input(img))
        lh = focal_loss(hl, heat)
        lc = quad_loss(cl, corners, mask)
        loss = lh + 0.5 * lc
        for group in self.opt.param_groups:
            group["lr"] = self._lr()
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        return {"loss": loss.item(), "heat": lh.item(), "corner": lc.item() * STRIDE,
                "recall": _peak_recall(hl.detach(), heat)}  # fmt: skip


def optimiser_tensors(opt: torch.optim.Optimizer, step: int) -> dict[str, Tensor]:
    """A checkpoint's resume state: the step, torch's random state and the optimiser's state,
    as tensors named ``dtrain.*``."""
    extra = {"dtrain.step": torch.tensor([step]), "dtrain.rng": torch.get_rng_state()}
    for pid, st in opt.state_dict()["state"].items():
        for key, val in st.items():
            extra[f"dtrain.opt.{pid}.{key}"] = val.cpu() if torch.is_tensor(val) else torch.tensor(val)
    return extra


def restore_optimiser(opt: torch.optim.Optimizer, tensors: dict[str, Tensor]) -> None:
    """Put back what :func:`optimiser_tensors` saved (the optimiser's state, torch's random state)."""
    sd = opt.state_dict()
    state: dict[int, dict[str, Any]] = {}
    for key, val in tensors.items():
        if key.startswith("dtrain.opt."):
            _, _, pid, name = key.split(".", 3)
            state.setdefault(int(pid), {})[name] = val
    sd["state"] = state
    opt.load_state_dict(sd)
    torch.set_rng_state(tensors["dtrain.rng"])


def quad_loss(pred: Tensor, target: Tensor, mask: Tensor) -> Tensor:
    """L1 between predicted and true corner offsets, under the best cyclic order of the corners.

    Which corner is "top left" depends on the drawing's in-plane rotation, which a small
    network at low resolution reads poorly; the outline of the frame is what it can learn well.
    The order is settled afterwards by alignment (:mod:`deepmorph_detect.refine`), which tries
    the four cyclic orders, so the loss does not ask the network for it.
    """
    B, _, h, w = pred.shape
    t = target.view(B, 4, 2, h, w)
    errs = torch.stack(
        [torch.abs(pred - torch.roll(t, k, dims=1).reshape(B, 8, h, w)).sum(1) for k in range(4)], 0
    )  # (4, B, h, w)
    best = errs.min(0).values
    return (best * mask[:, 0]).sum() / (mask.sum() * 8).clamp_min(1.0)


def _peak_recall(logits: Tensor, heat: Tensor) -> float:
    """Share of true centres with a predicted peak (p > 0.3) within one cell (training batch)."""
    p = torch.sigmoid(logits)
    peaks = (p == torch.nn.functional.max_pool2d(p, 3, 1, 1)) & (p > 0.3)
    near = torch.nn.functional.max_pool2d(peaks.float(), 3, 1, 1) > 0
    truth = heat >= 0.999
    n = truth.sum().item()
    return 1.0 if n == 0 else float((near & truth).sum().item() / n)


def train_detector(
    model_path: str | Path,
    out: str | Path,
    config: DetectorConfig | None = None,
    resume: bool = False,
    on_log: Callable[[dict[str, Any]], None] | None = None,
) -> DetectorSummary:
    """Add a trained detector to the bundle at ``model_path``, writing ``out``.

    With ``resume``, ``model_path`` is an interrupted checkpoint and its stored configuration
    is used (``config`` must then be ``None`` or equal). Without it, ``out`` must be new or the
    model itself (the detector added in place): another existing file is refused before any
    work, as ``deepmorph train`` refuses one.
    """
    if not resume and Path(out).exists() and not same_file(out, model_path):
        raise DeepMorphError(
            f"{out}: already exists; choose another --out, the model itself to add the detector in place,"
            " or pass --resume to continue an interrupted run there"
        )
    model = DeepMorphModel.load(model_path)
    if resume:
        meta = model.meta.detector
        if meta is None or meta.record.finished or "dtrain.step" not in model.extra_tensors:
            raise DeepMorphError(f"{model_path}: no interrupted detector training to resume")
        config = DetectorConfig(**meta.config)
    config = config or DetectorConfig()
    run = DetectorRun(model, config, Path(out))
    loop = TrainingLoop(out, config, ".detector.log.jsonl")
    summary = loop.run(run, on_log)
    _validate_close_ups_again(Path(out), config.seed)
    return DetectorSummary(Path(out), summary.log, summary.plot, summary.steps, summary.elapsed_s)


def _validate_close_ups_again(out: Path, seed: int) -> None:
    """Replace the bundle's close-up validation by one through the chain as it now is, with its
    detector (the one stored after training found prints by framing the whole image), and warn
    when it is weak. A bundle never validated (``--validation 0``) is left so."""
    from deepmorph.training import validation
    from deepmorph_detect.close_up_pool import one_per_thread
    from deepmorph_detect.photo_validation import validate_close_ups

    photos = validation.default_samples()[1]
    model = DeepMorphModel.load(out)
    if photos <= 0 or not model.meta.validation:
        return
    record = validate_close_ups(model, photos, seed, workers=one_per_thread())
    model.meta.validation = [r for r in model.meta.validation if r.name != record.name] + [record]
    model.save(out)
    warning = validation.validation_warning(model.meta.validation, str(out), own_detector=True)
    if warning:
        warnings.warn(DeepMorphWarning(warning), stacklevel=3)


__all__ = [
    "DetectorConfig",
    "SceneTrainingConfig",
    "DetectorSummary",
    "DetectorRun",
    "SceneBatches",
    "optimiser_tensors",
    "restore_optimiser",
    "quad_loss",
    "targets_for",
    "train_detector",
]
