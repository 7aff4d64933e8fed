"""Training a model's proposal verifier (``deepmorph train-verifier``).

The verifier (:mod:`deepmorph_detect.verifier`) learns to tell this drawing's prints from the
other things the universal detector proposes. Its examples are the detector's own proposals in
synthetic 1280x720 photos (:class:`~deepmorph_detect.scenes.SceneMaker`, half medium, half hard):
one print of the drawing, another drawing and an ArUco marker among clutter in each. A proposal
is a print when its centre lies within :data:`SAME_PLACE` of the print's diagonal from the
print's; anything else is not. Scenes are made by ``workers`` processes, each scene seeded by
``(seed, part, severity, index)``, so a run is reproducible whatever the number of workers.

The threshold follows a fixed rule (:func:`threshold_for`) from scenes held out of training,
whose figures the bundle keeps (:class:`~deepmorph_core.bundle.VerifierCheck`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from pydantic import BaseModel, ConfigDict
from torch import Tensor

from deepmorph.training.verifier_settings import MAX_THRESHOLD, VerifierSettings
from deepmorph_core.bundle import VerifierCheck, VerifierMeta
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import same_file
from deepmorph_core.graphs import GraphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.threads import use_threads
from deepmorph_detect.locate import Locator
from deepmorph_detect.scenes import Scene, SceneMaker
from deepmorph_detect.verifier import (
    CROP_SIZE,
    VerifierNet,
    proposal_crop,
    quarter_turns,
    verifier_graph,
    verifier_tensors,
)

#: a proposal whose centre lies within this share of a print's diagonal from the print's is that print
SAME_PLACE = 0.35
#: the frame the training scenes are photographed in: a phone's 720p video
SCENE_FRAME = (1280, 720)
#: the threshold is at least this: a verifier that must go lower to keep its prints is not used at all
MIN_THRESHOLD = 1e-3
_SEVERITIES = ("medium", "hard")
_TRAINING, _CHECK = 0, 1


class VerifierConfig(BaseModel, VerifierSettings):
    """A proposal verifier's training settings, validated (stored in the bundle): the fields,
    defaults and bounds are :class:`~deepmorph.training.verifier_settings.VerifierSettings`'."""

    model_config = ConfigDict(extra="forbid")


@dataclass
class Crops:
    """Proposals' crops and what each was: ``(N, S, S)`` crops, ``(N,)`` print labels, whether
    each one's quick look was not final (the verifier decides on it), and the scenes seen."""

    crops: np.ndarray
    prints: np.ndarray
    searched: np.ndarray
    scenes: int

    @classmethod
    def joined(cls, parts: list[Crops]) -> Crops:
        """The crops of several scenes as one."""
        return cls(
            np.concatenate([p.crops for p in parts] or [np.zeros((0, CROP_SIZE, CROP_SIZE), np.float32)]),
            np.concatenate([p.prints for p in parts] or [np.zeros(0, bool)]),
            np.concatenate([p.searched for p in parts] or [np.zeros(0, bool)]),
            sum(p.scenes for p in parts),
        )


def print_labels(centres: np.ndarray, scene: Scene) -> np.ndarray:
    """Whether each proposal centre (``(N, 2)`` pixels) is one of the scene's prints of the
    drawing: the placement nearest it, relative to each placement's diagonal, is a print and lies
    within :data:`SAME_PLACE` of its diagonal."""
    labels = np.zeros(len(centres), bool)
    if not scene.placements or not len(centres):
        return labels
    middles = np.stack([np.asarray(p.corners, np.float64).mean(0) for p in scene.placements])
    diagonals = np.array([np.linalg.norm(np.subtract(p.corners[2], p.corners[0])) for p in scene.placements])
    relative = np.linalg.norm(centres[:, None] - middles[None], axis=2) / np.maximum(diagonals, 1e-6)[None]
    nearest = relative.argmin(1)
    kinds = np.array([p.kind == "drawing" for p in scene.placements])
    return kinds[nearest] & (relative[np.arange(len(centres)), nearest] < SAME_PLACE)


class SceneCrops(torch.utils.data.IterableDataset):
    """Each scene's proposals as :class:`Crops`, scenes ``(severity, index)`` of one part
    (training or check) in order; in a DataLoader with workers, worker ``k`` of ``n`` makes
    every ``n``-th scene from the ``k``-th, and the loader takes them in turn (in order)."""

    def __init__(self, model_path: Path, config: VerifierConfig, part: int, per_severity: int) -> None:
        super().__init__()
        self.model_path, self.cfg, self.part, self.n = model_path, config, part, per_severity

    def __iter__(self) -> Iterator[Crops]:
        torch.set_num_threads(1)
        model = DeepMorphModel.load(self.model_path)
        locator = Locator(model, detector="universal", use_verifier=False)
        makers = [SceneMaker(model, SCENE_FRAME, sev, seed=self.cfg.seed, payload_pool=64) for sev in _SEVERITIES]
        worker = torch.utils.data.get_worker_info()
        first, every = (0, 1) if worker is None else (worker.id, worker.num_workers)
        for item in range(first, self.n * len(makers), every):
            severity, index = divmod(item, self.n)
            maker = makers[severity]
            maker.rng = np.random.default_rng([self.cfg.seed, self.part, severity, index])
            yield self.crops_of(locator, maker.make(drawings=1, distractors=1, aruco=True))

    def crops_of(self, locator: Locator, scene: Scene) -> Crops:
        """The universal detector's proposals in ``scene``: crops, labels, and (check scenes
        only) whether each one's quick look is not final."""
        gray, _, pyramid = locator.frame(scene.image, scene.camera)
        candidates = [c for c in locator.proposals(scene.image, gray) if c.homography is None]
        crops = [proposal_crop(gray, c.corners) for c in candidates]
        centres = np.array([np.asarray(c.corners, np.float64).mean(0) for c in candidates]).reshape(-1, 2)
        if self.part == _CHECK:
            searched = [not locator.aligner.quick_look(pyramid, c, gray).final for c in candidates]
        else:
            searched = [False] * len(candidates)
        return Crops(
            np.stack(crops) if crops else np.zeros((0, CROP_SIZE, CROP_SIZE), np.float32),
            print_labels(centres, scene),
            np.array(searched, bool),
            1,
        )


def collect(model_path: Path, config: VerifierConfig, part: int, per_severity: int) -> Crops:
    """Every proposal's crop in ``per_severity`` medium and as many hard scenes of ``part``."""
    data = SceneCrops(model_path, config, part, per_severity)
    workers = config.workers
    loader = torch.utils.data.DataLoader(
        data, batch_size=None, num_workers=workers, multiprocessing_context="fork" if workers else None
    )
    return Crops.joined(list(loader))


def turned(crops: Tensor, angles: np.ndarray) -> Tensor:
    """``(B, 1, S, S)`` crops each turned by its angle (radians) about its centre, the edge
    pixels repeated where the turn brings in what the crop did not hold."""
    a = torch.from_numpy(np.asarray(angles, np.float32))
    cos, sin, zero = a.cos(), a.sin(), torch.zeros_like(a)
    theta = torch.stack([torch.stack([cos, -sin, zero], 1), torch.stack([sin, cos, zero], 1)], 1)
    grid = torch.nn.functional.affine_grid(theta, list(crops.shape), align_corners=False)
    return torch.nn.functional.grid_sample(crops, grid, padding_mode="border", align_corners=False)


def train_net(crops: Crops, config: VerifierConfig, on_step: Callable[[int, float], None] | None = None) -> VerifierNet:
    """The verifier trained on ``crops``: batches drawn at random (seeded), each crop turned by a
    random angle with Gaussian noise added, prints weighted by how much rarer they are than the
    rest. A detector's outline says nothing of the print's turn: a verifier trained with quarter
    turns alone scored a clear print whose outline lay 45° off its ink 0.0002."""
    if not crops.prints.any() or crops.prints.all():
        raise DeepMorphError(
            f"the training scenes gave {int(crops.prints.sum())} proposals of the drawing and "
            f"{int((~crops.prints).sum())} of anything else: the verifier needs both (more --scenes?)"
        )
    torch.manual_seed(config.seed)
    net = VerifierNet()
    opt = torch.optim.Adam(net.parameters(), config.lr)
    x = torch.from_numpy(crops.crops)[:, None]
    y = torch.from_numpy(crops.prints.astype(np.float32))
    pos_weight = torch.tensor(float((~crops.prints).sum() / crops.prints.sum()))
    rng = np.random.default_rng([config.seed, 2])
    net.train()
    for step in range(config.steps):
        idx = torch.from_numpy(rng.integers(0, len(y), config.batch))
        batch = turned(x[idx], rng.uniform(0, 2 * np.pi, config.batch))
        batch = batch + config.noise * torch.randn_like(batch)
        loss = torch.nn.functional.binary_cross_entropy_with_logits(net(batch), y[idx], pos_weight=pos_weight)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if on_step is not None:
            on_step(step + 1, float(loss.detach()))
    return net.eval()


def scores(net: VerifierNet, crops: np.ndarray) -> np.ndarray:
    """Each crop's score: the best probability over its four quarter turns."""
    if not len(crops):
        return np.zeros(0, np.float32)
    with torch.inference_mode():
        probabilities = torch.sigmoid(net(quarter_turns(torch.from_numpy(crops)[:, None])))
    return probabilities.reshape(4, len(crops)).amax(0).numpy()


def threshold_for(print_scores: np.ndarray, most: float = MAX_THRESHOLD) -> float:
    """The threshold: half the lowest score of a held-out print's proposal (at least one),
    at most ``most`` (most other drawings score below 0.01; the margin keeps prints the check
    did not see)."""
    return min(most, float(print_scores.min()) / 2)


def check_of(net: VerifierNet, crops: Crops, threshold: float) -> VerifierCheck:
    """How ``net`` at ``threshold`` does on held-out ``crops``."""
    s = scores(net, crops.crops)
    kept = s >= threshold
    p, o = crops.prints, ~crops.prints
    sp, so = p & crops.searched, o & crops.searched
    return VerifierCheck(
        scenes=crops.scenes,
        prints=int(p.sum()),
        prints_kept=int((kept & p).sum()),
        others=int(o.sum()),
        others_turned_away=int((~kept & o).sum()),
        searched_prints=int(sp.sum()),
        searched_prints_kept=int((kept & sp).sum()),
        searched_others=int(so.sum()),
        searched_others_turned_away=int((~kept & so).sum()),
        lowest_print_score=float(s[p].min()) if p.any() else None,
    )


@dataclass
class VerifierSummary:
    """Where a verifier was written, its threshold, its held-out check and the run's seconds."""

    bundle: Path
    threshold: float
    check: VerifierCheck
    elapsed_s: float

    def text(self) -> str:
        """The run in one line, as the commands print it."""
        c = self.check
        return (
            f"threshold {self.threshold:.3g}, {self.elapsed_s:.0f} s; held out: {c.prints_kept}/{c.prints} "
            f"prints kept, {c.others_turned_away}/{c.others} other proposals turned away"
        )

    def as_json(self) -> dict[str, object]:
        """The run as the commands' ``--json`` gives it."""
        return {
            "bundle": str(self.bundle),
            "threshold": self.threshold,
            "check": self.check.model_dump(),
            "elapsed_s": round(self.elapsed_s, 1),
        }


def train_verifier(
    model_path: str | Path,
    out: str | Path,
    config: VerifierConfig | None = None,
    on_stage: Callable[[str], None] | None = None,
    on_step: Callable[[int, float], None] | None = None,
) -> VerifierSummary:
    """Train a proposal verifier for the model at ``model_path`` and write the bundle ``out``
    with it (``out`` new, or the model itself; it replaces any verifier the model had).

    Raises:
        DeepMorphError: ``out`` is another existing file, the model's detector is its own (not
            the universal detector, whose proposals the verifier sorts), or the scenes gave no
            print or nothing else to learn from, or the held-out prints scored too low to keep.
    """
    started = time.perf_counter()
    config = config or VerifierConfig()
    model_path, out = Path(model_path), Path(out)
    if out.exists() and not same_file(out, model_path):
        raise DeepMorphError(
            f"{out}: already exists; choose another --out, or the model itself to add the verifier in place"
        )
    model = DeepMorphModel.load(model_path)
    if model.meta.detector is not None:
        raise DeepMorphError(
            f"{model_path}: the model has its own detector, which proposes this drawing alone; the verifier "
            "sorts the universal detector's proposals"
        )
    if config.threads:
        use_threads(config.threads)
    stage = on_stage or (lambda _: None)
    stage(f"collecting proposals in {2 * config.scenes} training scenes")
    training = collect(model_path, config, _TRAINING, config.scenes)
    stage(f"training on {len(training.prints)} crops ({int(training.prints.sum())} of the drawing)")
    net = train_net(training, config, on_step)
    stage(f"checking on {2 * config.check_scenes} held-out scenes")
    held_out = collect(model_path, config, _CHECK, config.check_scenes)
    if not held_out.prints.any():
        raise DeepMorphError(
            f"the universal detector proposed no print of the drawing in {held_out.scenes} held-out scenes: "
            "a verifier cannot be checked (more --check-scenes?); the model was not changed"
        )
    threshold = threshold_for(scores(net, held_out.crops[held_out.prints]), config.max_threshold)
    if threshold < MIN_THRESHOLD:
        raise DeepMorphError(
            f"a held-out print of the drawing scored {2 * threshold:.2g}: the verifier cannot keep every print "
            "(more --scenes or --steps?); the model was not changed"
        )
    check = check_of(net, held_out, threshold)
    model.verifier_state = verifier_tensors(net)
    model.meta.verifier = VerifierMeta(
        threshold=threshold,
        config=config.model_dump(),
        check=check,
        crops=len(training.prints),
        print_crops=int(training.prints.sum()),
        threads=torch.get_num_threads(),
        elapsed_s=round(time.perf_counter() - started, 1),
    )
    model.graphs.pop("verifier", None)
    try:
        model.graphs["verifier"] = verifier_graph(net)
    except GraphError:
        pass  # PyTorch runs it (deepmorph_detect.runtime warns when it loads)
    model.save(out)
    return VerifierSummary(out, threshold, check, time.perf_counter() - started)


__all__ = [
    "Crops",
    "SceneCrops",
    "VerifierConfig",
    "VerifierSummary",
    "check_of",
    "collect",
    "print_labels",
    "scores",
    "threshold_for",
    "train_net",
    "train_verifier",
]
