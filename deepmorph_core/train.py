"""Training: the paper's two-stage schedule, with checkpoints, resume, logs and plots.

One step: random code bits -> encoder -> morph values -> soft rasterizer -> paper-white image
-> (a share of the batch replaced by real-renderer images of the same morphs) -> framing by
the ink's centre and spread (exactly as decoding frames a photo) -> capture corruptions -> decoder
-> sigmoid cross-entropy.

* **Stage 1** keeps the encoder at its random initialisation and trains the decoder until its
  bit accuracy plateaus (or a share of the steps is spent).
* **Stage 2** trains both end to end.

The real-renderer share closes the gap between what the soft rasterizer draws and what
resvg (and so a printer) draws. Those rows carry no gradient to the encoder, so they only
teach the decoder to read real renders.

Checkpoints are whole bundles plus optimiser and generator state, written atomically every
``checkpoint_every`` steps and on Ctrl-C. ``resume`` continues one exactly.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch
import torch.nn.functional as F
from pydantic import BaseModel, ConfigDict, Field
from torch import Tensor, nn

from deepmorph_core.bundle import TrainingRecord
from deepmorph_core.codemodel import DeepMorphModel
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.imaging import canonicalize, render_moments
from deepmorph_core.model import spread_weights
from deepmorph_core.render import render_svg


class TrainConfig(BaseModel):
    """Training settings (stored in the bundle).

    Attributes:
        steps: total optimisation steps (both stages).
        batch: perturbations per step.
        width: image width in pixels (decoder input; the height follows the drawing).
        lr, encoder_lr: Adam learning rates of the decoder and the encoder (decayed by a cosine
            to 10 % over stage 2).
        stage1_max_fraction: stage 1 ends at this share of ``steps`` at the latest.
        plateau_window, plateau_gain: stage 1 also ends when the bit accuracy (averaged over a
            window) gains less than ``plateau_gain`` from one window to the next.
        hard_fraction: share of each batch rendered by the real renderer (resvg).
        small_prints: share of each batch captured as a small print: shrunk to
            :data:`SMALL_PRINT_SCALE` of the decoder's width, corrupted at that size (the
            preset scaled to it), and enlarged again. A print 60 px wide in a photo is blurred,
            noised and compressed at 60 px, not at the decoder's width. The bundled ghost's
            decoder tuned so (:func:`tune_decoder`) read more payloads from photo scenes, and
            also let 2 wrong ones through CRC-8 in 300 hard scenes (``docs/training.md``).
        severity: capture-corruption preset (``none``, ``easy``, ``medium``, ``hard``) reached
            at the end of the curriculum.
        curriculum: share of ``steps`` over which corruption ramps up through the milder presets
            (a decoder facing full corruption from a random start learns nothing: measured at
            chance after 350 steps at ``medium``, against 82 % bit accuracy without corruption).
        encoder_init: the encoder's start. ``spread`` (default): each code bit drives its own
            variables at full range (:func:`deepmorph_core.model.spread_weights`; on the bundled
            ghost, bit errors under medium corruption fall from about 4 % to 0.5 %).
            ``random``: the paper's dense random matrix.
        spatial_transformer: put a learned homography in front of the decoder
            (:mod:`deepmorph_core.spatial`), trained with it end to end; it undoes the
            perspective and turn that framing by ink moments leaves (``docs/training.md``).
        freeze_encoder: train the decoder alone, the encoder as it is (no spread start, no
            stage 2), learning rate decaying by a cosine to 10 % over all steps: what
            :func:`tune_decoder` runs on a trained bundle.
        seed: makes a run reproducible (same seed, same threads: same model).
        device: ``cpu`` or ``cuda``.
        threads: torch CPU threads (``None``: torch's default).
        checkpoint_every, log_every: in steps.
    """

    model_config = ConfigDict(extra="forbid")

    steps: int = Field(default=3000, ge=1, le=10_000_000)
    batch: int = Field(default=32, ge=2, le=4096)
    width: int = Field(default=96, ge=32, le=512)
    lr: float = Field(default=2e-3, gt=0, le=1)
    encoder_lr: float = Field(default=1e-2, gt=0, le=10)
    stage1_max_fraction: float = Field(default=0.35, ge=0, le=1)
    plateau_window: int = Field(default=150, ge=10)
    plateau_gain: float = Field(default=0.004, ge=0)
    hard_fraction: float = Field(default=0.25, ge=0, le=1)
    small_prints: float = Field(default=0.0, ge=0, le=1)
    severity: Literal["none", "easy", "medium", "hard"] = "medium"
    curriculum: float = Field(default=0.5, ge=0, le=1)
    encoder_init: Literal["spread", "random"] = "spread"
    spatial_transformer: bool = True
    freeze_encoder: bool = False
    seed: int = 0
    device: Literal["cpu", "cuda"] = "cpu"
    threads: int | None = Field(default=None, ge=1, le=256)
    checkpoint_every: int = Field(default=250, ge=1)
    log_every: int = Field(default=25, ge=1)


_LADDER = ["none", "easy", "medium", "hard"]
SMALL_PRINT_SCALE = (0.55, 0.95)  # small prints: shrunk to this share of the decoder width


@dataclass
class StepMetrics:
    """What one logged step reports."""

    step: int
    stage: int
    loss: float
    bit_acc: float
    word_acc: float
    elapsed_s: float

    def to_json(self) -> dict[str, Any]:
        return {k: (round(v, 5) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


class Interrupted(DeepMorphError):
    """Training stopped by Ctrl-C after writing a checkpoint."""


def interrupted(
    record: Any, started: float, checkpoint: Callable[[], None], out: Path, total_steps: int
) -> Interrupted:
    """After Ctrl-C: record the time, write the checkpoint, and return the error saying how to
    go on (shared by every trainer, so they all stop the same way)."""
    record.elapsed_s = time.perf_counter() - started
    checkpoint()
    return Interrupted(
        f"interrupted at step {record.step}/{total_steps}; checkpoint written to {out} (continue with --resume)"
    )


def build_augment(severity: str, width: int, config: dict[str, Any] | None = None) -> nn.Module:
    """The capture-corruption pipeline for a preset at an image width (or a stored config)."""
    from deepmorph_augment.pipeline import AugmentConfig, AugmentPipeline

    cfg = AugmentConfig.parse(config) if config else AugmentConfig.preset(severity, size=width)
    return AugmentPipeline(cfg)


def real_renders(model: DeepMorphModel, values: Tensor) -> Tensor:
    """resvg renders ``(k, 1, H, W)`` (paper white) of ``(k, N_v)`` morph values."""
    h, w = model.image_size
    out = np.empty((values.shape[0], 1, h, w), dtype=np.float32)
    for i in range(values.shape[0]):
        out[i, 0] = render_svg(model.drawing.to_svg(values[i].detach().cpu()), w)
    return torch.from_numpy(out).to(values.device)


def variable_effects(model: DeepMorphModel, chunk: int = 64) -> Tensor:
    """What each variable does to the picture, as a Gram matrix ``(N_v, N_v)``.

    Each variable sweeps its whole range with every other variable neutral (soft raster at the
    model's width); entry ``(i, k)`` is the dot product of the pixel changes of ``i`` and ``k``.
    The diagonal is how visible a variable is; the correlations show variables that look alike.
    """
    space = model.drawing.space
    raster = model.rasterizer()
    neutral = space.neutral_unit(1)[0]
    changes = []
    with torch.no_grad():
        for start in range(0, space.n_variables, chunk):
            idx = torch.arange(start, min(start + chunk, space.n_variables))
            unit = neutral.repeat(2 * len(idx), 1)
            rows = torch.arange(len(idx))
            unit[2 * rows, idx] = 0.0
            unit[2 * rows + 1, idx] = 1.0
            images = raster(space.values_from_unit(unit))
            changes.append((images[1::2] - images[0::2]).flatten(1).double())
    change = torch.cat(changes)
    return change @ change.T


class Trainer:
    """Runs (or resumes) training of one model.

    Args:
        model: a fresh model (``DeepMorphModel.create``) or a loaded checkpoint.
        config: training settings.
        out: the bundle path written at checkpoints and at the end.
        log_path: JSONL log (one line per ``log_every`` steps); a PNG plot is written beside it.
    """

    def __init__(self, model: DeepMorphModel, config: TrainConfig, out: Path, log_path: Path | None = None):
        self.model, self.cfg, self.out = model, config, Path(out)
        self.log_path = Path(log_path) if log_path else self.out.with_suffix(".log.jsonl")
        self.device = torch.device(config.device)
        if config.device == "cuda" and not torch.cuda.is_available():
            raise DeepMorphError("--device cuda was asked for but no CUDA device is available")
        if config.threads:
            torch.set_num_threads(config.threads)
        model.encoder.to(self.device)
        model.decoder.to(self.device)
        self.raster = model.rasterizer()
        self.target = model.canonical_moments()
        self._augments = {
            sev: build_augment(sev, model.width).to(self.device) for sev in _LADDER[: _LADDER.index(config.severity)]
        }
        self._augments[config.severity] = build_augment(config.severity, model.width, model.meta.augment or None).to(
            self.device
        )
        self._small_augments: dict[tuple[str, int], nn.Module] = {}
        self.bce = nn.BCEWithLogitsLoss()
        self.gen = torch.Generator(device="cpu").manual_seed(config.seed)
        torch.manual_seed(config.seed)
        fresh = model.meta.record.step == 0 and not model.extra_tensors
        if config.encoder_init == "spread" and fresh and not config.freeze_encoder:
            weights = spread_weights(variable_effects(model), model.codec.spec.code_bits, self.gen)
            with torch.no_grad():
                model.encoder.linear.weight.copy_(weights.to(self.device))
        self.opt_dec = torch.optim.Adam(model.decoder.parameters(), lr=config.lr)
        self.opt_enc = torch.optim.Adam(model.encoder.parameters(), lr=config.encoder_lr)
        self.record = model.meta.record
        self.record.total_steps = config.steps
        self.record.device = config.device
        self.record.threads = torch.get_num_threads()
        self._window: list[float] = []
        self._prev_window: float | None = None
        self._restore(model.extra_tensors)

    # -- state ----------------------------------------------------------------------------

    def _extra_state(self) -> dict[str, Tensor]:
        out: dict[str, Tensor] = {"rng.cpu": self.gen.get_state(), "rng.torch": torch.get_rng_state()}
        for name, opt in (("opt_dec", self.opt_dec), ("opt_enc", self.opt_enc)):
            for pid, st in opt.state_dict()["state"].items():
                for key, val in st.items():
                    out[f"{name}.{pid}.{key}"] = val if torch.is_tensor(val) else torch.tensor(val)
        out["window"] = torch.tensor(self._window, dtype=torch.float64)
        if self._prev_window is not None:
            out["prev_window"] = torch.tensor([self._prev_window], dtype=torch.float64)
        return out

    def _restore(self, extra: dict[str, Tensor]) -> None:
        if not extra:
            return
        self.gen.set_state(extra["rng.cpu"])
        torch.set_rng_state(extra["rng.torch"])
        for name, opt in (("opt_dec", self.opt_dec), ("opt_enc", self.opt_enc)):
            sd = opt.state_dict()
            state: dict[int, dict[str, Any]] = {}
            for key, val in extra.items():
                if key.startswith(name + "."):
                    _, pid, field_name = key.split(".", 2)
                    state.setdefault(int(pid), {})[field_name] = val.to(self.device) if field_name != "step" else val
            sd["state"] = state
            opt.load_state_dict(sd)
        self._window = extra["window"].tolist() if "window" in extra else []
        self._prev_window = float(extra["prev_window"][0]) if "prev_window" in extra else None

    def checkpoint(self) -> None:
        """Write the bundle with optimiser and generator state (atomic)."""
        self.model.meta.record = self.record
        self.model.save(self.out, extra=None if self.record.finished else self._extra_state())

    # -- one step -------------------------------------------------------------------------

    def images(self, bits: Tensor, train_encoder: bool) -> Tensor:
        """Decoder inputs for code bits: soft renders, part real renders, corrupted."""
        k = round(self.cfg.hard_fraction * bits.shape[0])
        with torch.set_grad_enabled(train_encoder):
            unit = self.model.encoder(bits)
            values = self.model.drawing.values_from_unit(unit)
            # the first k rows are drawn by the real renderer only (the soft raster would be thrown away)
            soft = values[k:]
            images = 1.0 - self.raster(soft) if len(soft) else values.new_empty((0, 1, *self.model.image_size))
        if k:
            images = torch.cat([real_renders(self.model, values[:k]), images], 0)
        images = canonicalize(images, render_moments(images), self.target, self.model.image_size)
        small = round(self.cfg.small_prints * bits.shape[0])
        if not small:
            return self.augment_now()(images, generator=self.gen)
        full = self.augment_now()(images[: images.shape[0] - small], generator=self.gen)
        return torch.cat([full, self.small_prints(images[images.shape[0] - small :])], 0)

    def small_prints(self, images: Tensor) -> Tensor:
        """``(k, 1, H, W)`` framed renders captured as one small print size: shrunk (area) to a
        width drawn from :data:`SMALL_PRINT_SCALE`, corrupted there by the current rung's
        preset scaled to that width, enlarged again (bilinear). Differentiable."""
        h, w = images.shape[-2:]
        lo, hi = (round(f * w) for f in SMALL_PRINT_SCALE)
        small_w = int(torch.randint(lo, hi + 1, (1,), generator=self.gen))
        small_h = max(8, round(small_w * h / w))
        key = (self._rung(), small_w)
        if key not in self._small_augments:
            self._small_augments[key] = build_augment(key[0], small_w).to(self.device)
        shrunk = F.interpolate(images, size=(small_h, small_w), mode="area")
        captured = self._small_augments[key](shrunk, generator=self.gen)
        return F.interpolate(captured, size=(h, w), mode="bilinear", align_corners=False).clamp(0.0, 1.0)

    def augment_now(self) -> nn.Module:
        """The corruption of the curriculum's current rung: none, easy, ... up to ``severity``."""
        return self._augments[self._rung()]

    def _rung(self) -> str:
        rungs = _LADDER[: _LADDER.index(self.cfg.severity) + 1]
        ramp = self.cfg.curriculum * self.cfg.steps
        if ramp <= 0 or len(rungs) == 1:
            return self.cfg.severity
        return rungs[min(len(rungs) - 1, int(self.record.step / ramp * (len(rungs) - 1)))]

    def step(self) -> StepMetrics:
        cfg, rec = self.cfg, self.record
        stage2 = rec.stage == 2
        self.model.encoder.train(stage2)
        self.model.decoder.train()
        bits = torch.randint(0, 2, (cfg.batch, self.model.codec.spec.code_bits), generator=self.gen).float()
        bits = bits.to(self.device)
        logits = self.model.decoder(self.images(bits, stage2))
        loss = self.bce(logits, bits)
        self.opt_dec.zero_grad(set_to_none=True)
        self.opt_enc.zero_grad(set_to_none=True)
        loss.backward()
        self._set_learning_rates()
        self.opt_dec.step()
        if stage2:
            self.opt_enc.step()
        with torch.no_grad():
            right = (logits > 0) == (bits > 0.5)
            bit_acc = right.float().mean().item()
            word_acc = right.all(1).float().mean().item()
        rec.step += 1
        self._update_stage(bit_acc)
        return StepMetrics(rec.step, rec.stage, loss.item(), bit_acc, word_acc, rec.elapsed_s)

    def _set_learning_rates(self) -> None:
        """Full rates in stage 1; in stage 2 a cosine decay to 10 % by the last step (over every
        step when the encoder is frozen).

        A function of the step alone, so a resumed run follows the same schedule.
        """
        rec, cfg = self.record, self.cfg
        # the decay runs over stage 2, or over every step when only the decoder trains
        decay_start = 0 if cfg.freeze_encoder else rec.stage2_start if rec.stage == 2 else None
        factor = 1.0
        if decay_start is not None and cfg.steps > decay_start:
            progress = min(1.0, (rec.step - decay_start) / (cfg.steps - decay_start))
            factor = 0.1 + 0.9 * 0.5 * (1.0 + math.cos(math.pi * progress))
        for opt, base in ((self.opt_dec, cfg.lr), (self.opt_enc, cfg.encoder_lr)):
            for group in opt.param_groups:
                group["lr"] = base * factor

    def _update_stage(self, bit_acc: float) -> None:
        rec, cfg = self.record, self.cfg
        if rec.stage == 2 or cfg.freeze_encoder:
            return
        self._window.append(bit_acc)
        limit = math.ceil(cfg.stage1_max_fraction * cfg.steps)
        plateau = False
        if len(self._window) >= cfg.plateau_window:
            mean = float(np.mean(self._window))
            if self._prev_window is not None and mean - self._prev_window < cfg.plateau_gain:
                plateau = True
            self._prev_window, self._window = mean, []
        if plateau or rec.step >= limit:
            rec.stage, rec.stage2_start = 2, rec.step

    # -- the loop -------------------------------------------------------------------------

    def run(self, on_log: Callable[[StepMetrics], None] | None = None) -> TrainingRecordSummary:
        """Train until ``steps``; checkpoint on schedule and on Ctrl-C.

        Raises:
            Interrupted: after Ctrl-C, once the checkpoint is written.
        """
        cfg, rec = self.cfg, self.record
        history = _read_log(self.log_path) if rec.step else []
        if not rec.step:
            self.log_path.parent.mkdir(parents=True, exist_ok=True)
            self.log_path.write_text("")
        start = time.perf_counter() - rec.elapsed_s
        acc = {"loss": 0.0, "bit_acc": 0.0, "word_acc": 0.0, "n": 0}
        try:
            while rec.step < cfg.steps:
                m = self.step()
                rec.elapsed_s = time.perf_counter() - start
                for k in ("loss", "bit_acc", "word_acc"):
                    acc[k] += getattr(m, k)
                acc["n"] += 1
                if rec.step % cfg.log_every == 0 or rec.step == cfg.steps:
                    n = acc.pop("n")
                    logged = StepMetrics(
                        rec.step, rec.stage, acc["loss"] / n, acc["bit_acc"] / n, acc["word_acc"] / n, rec.elapsed_s
                    )
                    acc = {"loss": 0.0, "bit_acc": 0.0, "word_acc": 0.0, "n": 0}
                    history.append(logged.to_json())
                    with self.log_path.open("a") as fh:
                        fh.write(json.dumps(logged.to_json()) + "\n")
                    rec.metrics = {"bit_acc": logged.bit_acc, "word_acc": logged.word_acc, "loss": logged.loss}
                    if on_log:
                        on_log(logged)
                if rec.step % cfg.checkpoint_every == 0 and rec.step < cfg.steps:
                    self.checkpoint()
        except KeyboardInterrupt:
            raise interrupted(rec, start, self.checkpoint, self.out, cfg.steps) from None
        rec.finished = True
        self.model.encoder.eval()
        self.model.decoder.eval()
        self.checkpoint()
        plot = plot_history(history, self.log_path.with_suffix(".png"))
        return TrainingRecordSummary(self.out, self.log_path, plot, rec.step, rec.stage2_start, rec.elapsed_s)


def tune_decoder(
    model: DeepMorphModel,
    config: TrainConfig,
    out: Path,
    on_log: Callable[[StepMetrics], None] | None = None,
) -> dict[str, Any]:
    """Train a trained bundle's decoder further, its encoder frozen, and write it to ``out``.

    The morphs stay exactly as they were, so codes already printed still decode and the
    bundle's detector stays valid. The bundle's training record is kept; this run is appended
    to ``meta.tuning``. Ctrl-C writes the decoder tuned so far, recorded as not finished.

    Returns:
        The ``meta.tuning`` entry of this run.

    Raises:
        Interrupted: after Ctrl-C, once the bundle is written.
    """
    if not config.freeze_encoder:
        raise ValueError("tune_decoder trains the decoder alone: config.freeze_encoder must be set")
    trained = model.meta.record
    model.meta.record = TrainingRecord()
    trainer = Trainer(model, config, out)
    rec = trainer.record
    entry: dict[str, Any] = {
        "steps": 0,
        "total_steps": config.steps,
        **{k: getattr(config, k) for k in ("small_prints", "severity", "lr", "batch", "hard_fraction", "seed")},
        "threads": rec.threads,
    }
    window: list[float] = []

    def finish(finished: bool) -> None:
        entry.update(steps=rec.step, finished=finished, elapsed_s=round(time.perf_counter() - start, 1))
        if window:
            entry["bit_acc"] = round(float(np.mean(window)), 5)
        model.meta.record = trained
        model.meta.tuning.append(entry)
        model.decoder.eval()
        model.save(out)

    start = time.perf_counter()
    try:
        while rec.step < config.steps:
            m = trainer.step()
            window = (window + [m.bit_acc])[-config.log_every :]
            if on_log and (rec.step % config.log_every == 0 or rec.step == config.steps):
                on_log(replace(m, bit_acc=float(np.mean(window)), elapsed_s=time.perf_counter() - start))
    except KeyboardInterrupt:
        finish(False)
        raise Interrupted(
            f"interrupted at step {rec.step}/{config.steps}; the decoder tuned so far is in {out}"
        ) from None
    finish(True)
    return entry


@dataclass
class TrainingRecordSummary:
    """Where training wrote its files, and how it went."""

    bundle: Path
    log: Path
    plot: Path | None
    steps: int
    stage2_start: int | None
    elapsed_s: float


def _read_log(path: Path) -> list[dict[str, Any]]:
    if not path.is_file():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue  # a line cut by a crash
    return out


def plot_history(history: list[dict[str, Any]], path: Path) -> Path | None:
    """Loss and bit accuracy against steps, with the stage switch marked (PNG)."""
    if not history:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    steps = [h["step"] for h in history]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.2))
    ax1.plot(steps, [h["loss"] for h in history])
    ax1.set(xlabel="step", ylabel="BCE loss", yscale="log", title="loss")
    ax2.plot(steps, [h["bit_acc"] for h in history], label="bit accuracy")
    ax2.plot(steps, [h["word_acc"] for h in history], label="all bits right")
    ax2.set(xlabel="step", ylim=(0, 1.01), title="accuracy (training batches)")
    switch = next((h["step"] for h in history if h["stage"] == 2), None)
    for ax in (ax1, ax2):
        if switch is not None:
            ax.axvline(switch, color="grey", linestyle=":", label="stage 2")
    ax2.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
