"""Codec training: the paper's two-stage schedule, and tuning a trained decoder further.

One step: random code bits -> encoder -> morph values -> soft rasterizer -> paper-white image
-> (a share of the batch replaced by real-renderer images of the same morphs) -> framing by
the ink's centre and spread (exactly as decoding frames a photo) -> capture corruptions -> decoder
-> sigmoid cross-entropy.

* **Stage 1** keeps the encoder at its initialisation and trains the decoder until its bit
  accuracy plateaus (or a share of the steps is spent).
* **Stage 2** trains both end to end.

The real-renderer share closes the gap between what the soft rasterizer draws and what
resvg (and so a printer) draws. Those rows carry no gradient to the encoder, so they only
teach the decoder to read real renders.

The steps, the log, checkpoints, resume and interrupts are :mod:`deepmorph.training.loop`'s; the
device and the processes of a torchrun (each drawing its shards of the batch, gradients summed
across them) are :mod:`deepmorph.training.distributed`'s.
Checkpoints are whole bundles plus optimiser and generator state, so ``resume`` continues a
run exactly. :func:`train_model` and :func:`tune_decoder` are what the command line calls.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import torch
import torch.nn.functional as F
from pydantic import BaseModel, ConfigDict, ValidationError
from torch import Tensor, nn

from deepmorph.training.code_shrink import (
    RENDER_ROUNDS,
    RENDER_SEED_OFFSET,
    CutRules,
    code_for_renders,
    describe,
    read_share,
    shrink_below,
    shrink_networks,
    smaller_code,
)
from deepmorph.training.distributed import (
    BatchNormShards,
    World,
    all_reduce_sum,
    broadcast_module,
    gather_objects,
    join,
    leave,
    rank_shards,
    shard_seed,
    shard_sizes,
    sum_gradients,
    world_from_env,
)
from deepmorph.training.loop import LoopSummary, Panel, TrainingLoop
from deepmorph.training.settings import PAYLOAD_BITS, SMALL_PRINT_SCALE, TUNE_DEFAULTS, TrainSettings
from deepmorph.training.validation import default_samples, validate, validation_warning
from deepmorph_core.bounds import format_validation_error
from deepmorph_core.bundle import AutoPayload, CodeShrink, TrainingRecord, TrustRecord, ValidationRecord
from deepmorph_core.capacity import predict, size_warning
from deepmorph_core.codec import CodecSpec, choose_codec, default_crc_bits
from deepmorph_core.corruption import build_pipeline
from deepmorph_core.device import resolve_device, torch_device
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import check_target
from deepmorph_core.heap import keep_freed_memory
from deepmorph_core.luminance import Channel
from deepmorph_core.model import DeepMorphModel, check_trainable
from deepmorph_core.morphable import MorphableDrawing, bound_defaults
from deepmorph_core.networks import Decoder, DecoderConfig, spread_weights
from deepmorph_core.plugins import default_registry
from deepmorph_core.raster import RasterSettings
from deepmorph_core.reading_channel import channel_for
from deepmorph_core.severity import LADDER
from deepmorph_core.svg.secure import read_svg_bytes
from deepmorph_core.threads import use_threads

if TYPE_CHECKING:
    from deepmorph.training.verifier import VerifierSummary


class TrainConfig(BaseModel, TrainSettings):
    """Training settings, validated (stored in the bundle): the fields, their defaults and
    bounds are :class:`~deepmorph.training.settings.TrainSettings`', declared there once for
    this model, the command line, :func:`deepmorph.train` and the studio."""

    model_config = ConfigDict(extra="forbid")


#: The plot of a codec training log.
CODEC_PANELS = (
    Panel("loss", ("loss",), log_scale=True),
    Panel("accuracy (training batches)", ("bit_acc", "word_acc", "read"), unit_range=True),
)


def variable_effects(model: DeepMorphModel) -> Tensor:
    """:meth:`MorphableDrawing.effects <deepmorph_core.morphable.MorphableDrawing.effects>` of
    the model's drawing with its own soft rasterizer."""
    return model.drawing.effects(model.rasterizer())


#: Renders :func:`fit_readout` fits to, the ridge of its least squares, and the logit it aims at.
READOUT_SAMPLES, READOUT_RIDGE, READOUT_MARGIN = 2048, 10.0, 3.0
#: Stage 1 ending below this bit accuracy means the CNN has stalled: the readout is fitted then.
READOUT_STALL = 0.9


def readout_fitted(decoder: Decoder) -> bool:
    """Whether the decoder's linear readout has been fitted (a dormant one is all zeros)."""
    return decoder.readout is not None and bool(decoder.readout.weight.detach().abs().sum() > 0)


def drop_dormant_readout(model: DeepMorphModel) -> None:
    """Take a readout that was never fitted out of a finished model: it adds nothing, and the
    bundle stays the CNN's alone."""
    if model.decoder.readout is not None and not readout_fitted(model.decoder):
        model.decoder.readout = None
        model.meta.decoder = model.meta.decoder.model_copy(update={"readout": False})


def fit_readout(
    decoder: Decoder,
    images: Callable[[Tensor, bool], Tensor],
    code_bits: int,
    generator: torch.Generator,
    device: torch.device,
    samples: int = READOUT_SAMPLES,
    batch: int = 256,
) -> None:
    """Set the decoder's linear readout to the least-squares map from pixels to code bits.

    Why: the CNN learns a code of up to about two thirds of a bit per readable variable, then
    stalls far below what the pictures allow (on the ghost's 57 variables, 52 code bits: 81 %
    of bits on clean renders after 1200 steps, where a linear map of the same renders tells
    99.9 % apart). Training fits it where stage 1 ends below :data:`READOUT_STALL`, and goes on
    from there. Fitted from the start where the CNN does learn, it made things worse: a linear
    map reads misaligned and blurred pictures poorly (``docs/design-notes.md``).

    How: ``samples`` random codes are drawn through ``images`` (the training's own renders at
    the curriculum's current rung); the ridge solution (dual form: the Gram matrix of the
    samples) maps centred pixels to ``+-READOUT_MARGIN`` logits.
    """
    readout = decoder.readout
    if readout is None:
        return
    xs, ys = [], []
    with torch.no_grad():
        for start in range(0, samples, batch):
            n = min(batch, samples - start)
            bits = torch.randint(0, 2, (n, code_bits), generator=generator).float().to(device)
            framed = images(bits, False)
            if decoder.align is not None:
                framed = decoder.align(framed)
            xs.append((framed - 0.5).flatten(1).double().cpu())
            ys.append((2.0 * bits - 1.0).double().cpu() * READOUT_MARGIN)
    x, y = torch.cat(xs), torch.cat(ys)
    mean_x, mean_y = x.mean(0), y.mean(0)
    xc = x - mean_x
    gram = xc @ xc.T
    gram.diagonal().add_(READOUT_RIDGE)
    weight = xc.T @ torch.linalg.solve(gram, y - mean_y)  # (D, N_b)
    with torch.no_grad():
        readout.weight.copy_(weight.T.to(readout.weight))
        readout.bias.copy_((mean_y - mean_x @ weight).to(readout.bias))


class CodecRun:
    """One codec training run (or its resumption) for the shared loop (:class:`~deepmorph.training.loop.Run`).

    Args:
        model: a fresh model (``DeepMorphModel.create``) or a loaded checkpoint.
        config: training settings (``device`` resolved: ``cpu`` or ``cuda``).
        out: the bundle path written at checkpoints and at the end (by rank 0 alone).
        world: this process's place in a data-parallel run (:func:`deepmorph.training.distributed.join`
            already called); it draws the shards :func:`~deepmorph.training.distributed.rank_shards` gives it.
    """

    panels = CODEC_PANELS

    def __init__(self, model: DeepMorphModel, config: TrainConfig, out: Path, world: World | None = None):
        self.model, self.cfg, self.out = model, config, Path(out)
        self.world = world or World()
        self.device = torch_device(config.device)
        self.shards = config.shards or 1
        self.mine = rank_shards(self.shards, self.world)
        if config.threads:
            use_threads(config.threads)
        if self.device.type == "cpu":
            keep_freed_memory()  # each step reuses the last one's pages (deepmorph_core/heap.py)
        model.encoder.to(self.device)
        model.decoder.to(self.device)
        # on the CPU, convolutions run channels-last: the decoder's full-resolution layers (one
        # input channel) take about a third of the time forward and backward, to float rounding
        self.memory_format = torch.channels_last if self.device.type == "cpu" else torch.contiguous_format
        model.decoder.to(memory_format=self.memory_format)
        self.raster = model.rasterizer()
        self.colour = model.drawing.colour  # renders in colour, through the colour corruptions
        self.print_px = model.print_px
        self.registered = model.registered  # and registered onto the unmorphed drawing as photos are
        self.channel = model.drawing.channel  # and read in the model's channel
        self._augments = {
            sev: build_pipeline(
                sev,
                model.width,
                colour=self.colour,
                print_px=self.print_px,
                channel=self.channel,
                registered=self.registered,
            ).to(self.device)
            for sev in LADDER[: LADDER.index(config.severity)]
        }
        stored = model.meta.augment or None
        self._augments[config.severity] = build_pipeline(config.severity, model.width, stored, channel=self.channel).to(
            self.device
        )
        self._small_augments: dict[tuple[str, int], nn.Module] = {}
        self.bce = nn.BCEWithLogitsLoss()
        # shard 0's stream is the run's seed (and draws the encoder's spread start on every rank)
        self._gens = {i: torch.Generator(device="cpu").manual_seed(shard_seed(config.seed, i)) for i in self.mine}
        self.gen = self._gens.get(0) or torch.Generator(device="cpu").manual_seed(shard_seed(config.seed, 0))
        torch.manual_seed(config.seed)
        fresh = model.meta.record.step == 0 and not model.extra_tensors
        if config.encoder_init == "spread" and fresh and not config.freeze_encoder:
            weights = spread_weights(variable_effects(model), model.codec.spec.code_bits, self.gen)
            with torch.no_grad():
                model.encoder.linear.weight.copy_(weights.to(self.device))
        self.opt_dec = torch.optim.Adam(model.decoder.parameters(), lr=config.lr)
        self.opt_enc = torch.optim.Adam(model.encoder.parameters(), lr=config.encoder_lr)
        self.record = model.meta.record
        # a code shrunk by its renders when training ended is trained on past the run's steps
        by_renders = [s for s in self.record.shrunk if s.measured_on == "renders"]
        self.record.total_steps = by_renders[-1].step + config.renders_tune if by_renders else config.steps
        self.record.device = self.device.type
        self.record.threads = torch.get_num_threads()
        self.record.world_size = self.world.size
        self.record.global_batch = config.batch
        self._window: list[float] = []
        self._prev_window: float | None = None
        self._reads: list[float] = []  # the early stop's window: code words read, per step at full corruption
        # an auto-sized code's window (deepmorph.training.code_shrink): per step at full corruption, the
        # code bits each capture of this rank's shards got wrong; and the steps since it was last sized
        self._errors: list[Tensor] = []
        self._settled = 0
        self._restore(model.extra_tensors)
        if model.decoder.readout is not None:  # dormant (all zero, untrained) until the CNN stalls
            model.decoder.readout.requires_grad_(readout_fitted(model.decoder))

    # -- state ----------------------------------------------------------------------------

    def _extra_state(self) -> dict[str, Tensor]:
        """Optimiser and generator state (every shard's stream, gathered from the ranks that draw
        them: a collective call, made by every rank)."""
        streams: dict[int, Tensor] = {}
        for part in gather_objects({i: g.get_state() for i, g in self._gens.items()}, self.world):
            streams.update(part)
        out: dict[str, Tensor] = {"rng.cpu": streams[0], "rng.torch": torch.get_rng_state()}
        out.update({f"rng.shard.{i}": state for i, state in streams.items() if i})
        for name, opt in (("opt_dec", self.opt_dec), ("opt_enc", self.opt_enc)):
            for pid, st in opt.state_dict()["state"].items():
                for key, val in st.items():
                    out[f"{name}.{pid}.{key}"] = val if torch.is_tensor(val) else torch.tensor(val)
        out["window"] = torch.tensor(self._window, dtype=torch.float64)
        out["reads"] = torch.tensor(self._reads, dtype=torch.float64)
        if self.record.payload_auto is not None:
            out["code_settled"] = torch.tensor([self._settled], dtype=torch.int64)
            if self._errors:
                out["code_errors"] = torch.stack(self._errors).to(torch.uint8)
        if self._prev_window is not None:
            out["prev_window"] = torch.tensor([self._prev_window], dtype=torch.float64)
        return out

    def _restore(self, extra: dict[str, Tensor]) -> None:
        if not extra:
            return
        for i, gen in self._gens.items():
            gen.set_state(extra["rng.cpu" if i == 0 else f"rng.shard.{i}"])
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
        self._reads = extra["reads"].tolist() if "reads" in extra else []
        self._errors = list(extra["code_errors"].bool()) if "code_errors" in extra else []
        self._settled = int(extra["code_settled"][0]) if "code_settled" in extra else 0
        self._prev_window = float(extra["prev_window"][0]) if "prev_window" in extra else None

    def checkpoint(self) -> None:
        """Write the bundle with optimiser and generator state (atomic); at the end, with the
        decoder's ONNX graph. Every rank calls it; rank 0 alone writes."""
        self.model.meta.record = self.record
        extra = None if self.record.finished else self._extra_state()
        if not self.world.main:
            return
        if self.record.finished:
            self.model.decoder.to(memory_format=torch.contiguous_format)
            drop_dormant_readout(self.model)
            self.model.store_decoder_graph()
        self.model.save(self.out, extra=extra)

    # -- one step -------------------------------------------------------------------------

    def images(self, bits: Tensor, train_encoder: bool) -> Tensor:
        """Decoder inputs for code bits: soft renders, part real renders, corrupted."""
        k = round(self.cfg.hard_fraction * bits.shape[0])
        with torch.set_grad_enabled(train_encoder):
            unit = self.model.encoder(bits)
            values = self.model.drawing.values_from_unit(unit)
            # the first k rows are drawn by the real renderer only (the soft raster would be thrown away)
            soft = values[k:]
            if not len(soft):
                images = values.new_empty((0, 3 if self.colour else 1, *self.model.image_size))
            else:
                images = self.raster.render_rgb(soft) if self.colour else 1.0 - self.raster(soft)
        if k:
            images = torch.cat([self.model.real_renders(values[:k], rgb=self.colour), images], 0)
        images = self.model.framed(images, self.registered and not self._clean_rung())
        small = round(self.cfg.small_prints * bits.shape[0])
        if not small:
            return self.augment_now()(images, generator=self.gen)
        full = self.augment_now()(images[: images.shape[0] - small], generator=self.gen)
        return torch.cat([full, self.small_prints(images[images.shape[0] - small :])], 0)

    def small_prints(self, images: Tensor) -> Tensor:
        """``(k, C, H, W)`` framed renders captured as one small print size: shrunk (area) to a
        width drawn from :data:`SMALL_PRINT_SCALE`, corrupted there by the current rung's
        preset scaled to that width, enlarged again (bilinear). Differentiable."""
        h, w = images.shape[-2:]
        lo, hi = (round(f * w) for f in SMALL_PRINT_SCALE)
        small_w = int(torch.randint(lo, hi + 1, (1,), generator=self.gen))
        small_h = max(8, round(small_w * h / w))
        key = (self._rung(), small_w)
        if key not in self._small_augments:
            # the same print, shrunk: a print_px-wide print seen at small_w of the frame's w pixels
            seen = None if self.print_px is None else self.print_px * small_w / w
            self._small_augments[key] = build_pipeline(
                key[0], small_w, colour=self.colour, print_px=seen, channel=self.channel, registered=self.registered
            ).to(self.device)
        shrunk = F.interpolate(images, size=(small_h, small_w), mode="area")
        captured = self._small_augments[key](shrunk, generator=self.gen)
        return F.interpolate(captured, size=(h, w), mode="bilinear", align_corners=False).clamp(0.0, 1.0)

    def _clean_rung(self) -> bool:
        """Whether the curriculum is on its clean first rung (no corruption) on the way to a
        corrupted one. A registered model's renders are registered from the next rung on: on the
        clean rung the decoder first learns the code's moves, which registering onto the
        unmorphed drawing partly takes up (on faint colour edges it then learnt nothing: bit
        accuracy stayed at chance; ``docs/design-notes.md``)."""
        return self._rung() == LADDER[0] and self.cfg.severity != LADDER[0]

    def augment_now(self) -> nn.Module:
        """The corruption of the curriculum's current rung: none, easy, ... up to ``severity``."""
        return self._augments[self._rung()]

    def _rung(self) -> str:
        rungs = LADDER[: LADDER.index(self.cfg.severity) + 1]
        ramp = self.cfg.curriculum * self.cfg.steps
        if ramp <= 0 or len(rungs) == 1:
            return self.cfg.severity
        return rungs[min(len(rungs) - 1, int(self.record.step / ramp * (len(rungs) - 1)))]

    def step(self) -> dict[str, float]:
        """One optimisation step; its loss, bit accuracy, whole-word accuracy and code words read
        (no more bit errors than the code corrects) over the global batch (every shard, on
        every rank), each measured before the step learns from the batch."""
        cfg, rec = self.cfg, self.record
        stage2 = rec.stage == 2
        full_corruption = self._rung() == cfg.severity
        self.model.encoder.train(stage2)
        self.model.decoder.train()
        self.opt_dec.zero_grad(set_to_none=True)
        self.opt_enc.zero_grad(set_to_none=True)
        sizes = shard_sizes(cfg.batch, self.shards)
        norms = BatchNormShards(self.model.decoder) if self.shards > 1 else None
        # loss x rows, right bits, right words, words read
        totals = torch.zeros(4, dtype=torch.float64, device=self.device)
        correctable = self.model.codec.spec.bch_t
        # the bits each capture read wrong, kept only where an auto-sized code may shrink
        wrong_bits: list[Tensor] | None = [] if self._sizing() else None
        for shard in self.mine:
            self.gen = self._gens[shard]
            bits = torch.randint(0, 2, (sizes[shard], self.model.codec.spec.code_bits), generator=self.gen).float()
            bits = bits.to(self.device)
            if norms:
                norms.start()
            images = self.images(bits, stage2).contiguous(memory_format=self.memory_format)
            logits = self.model.decoder(images)
            loss = self.bce(logits, bits)
            (loss * (sizes[shard] / cfg.batch) if self.shards > 1 else loss).backward()
            if norms:
                norms.add()
            with torch.no_grad():
                right = (logits > 0) == (bits > 0.5)
                read = ((~right).sum(1) <= correctable).sum()
                if wrong_bits is not None:
                    wrong_bits.append((~right).cpu())
                totals += torch.stack([loss.detach().double() * sizes[shard], right.sum(), right.all(1).sum(), read])
        if norms:
            norms.finish(self.shards, self.world)
        sum_gradients([*self.model.decoder.parameters(), *self.model.encoder.parameters()], self.world)
        all_reduce_sum([totals], self.world)
        self._set_learning_rates()
        self.opt_dec.step()
        if stage2:
            self.opt_enc.step()
        loss_sum, right_bits, right_words, words_read = totals.tolist()
        bit_acc = right_bits / (cfg.batch * self.model.codec.spec.code_bits)
        word_acc = right_words / cfg.batch
        read = words_read / cfg.batch
        self._update_stage(bit_acc, rec.step + 1)  # the loop counts this step once it returns
        self._update_early_stop(read, full_corruption)
        if wrong_bits is not None:
            self._update_code(torch.cat(wrong_bits), full_corruption)
        if self._sizing() and cfg.renders_tune and rec.step + 1 >= rec.total_steps:
            self._check_renders()
        return {"loss": loss_sum / cfg.batch, "bit_acc": bit_acc, "word_acc": word_acc, "read": read}

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

    def _update_early_stop(self, read: float, full_corruption: bool) -> None:
        """End the run at this step when the last ``early_stop_window`` steps, all at full
        corruption, read at least ``early_stop_rate`` of their code words (the same on every
        rank: the shares are over the global batch)."""
        cfg, rec = self.cfg, self.record
        if not cfg.early_stop or cfg.freeze_encoder:
            return
        if not full_corruption:
            self._reads = []
            return
        self._reads = [*self._reads, read][-cfg.early_stop_window :]
        if len(self._reads) == cfg.early_stop_window and float(np.mean(self._reads)) >= cfg.early_stop_rate:
            rec.total_steps = rec.step + 1  # the loop counts this step once it returns, then finishes
            rec.stopped_early = True

    def _sizing(self) -> bool:
        """Whether training may still shrink the code: sized by ``auto``, the encoder training."""
        return self.record.payload_auto is not None and not self.cfg.freeze_encoder

    def _update_code(self, wrong: Tensor, full_corruption: bool) -> None:
        """Shrink an auto-sized code that does not read (:mod:`deepmorph.training.code_shrink`):
        after a settling window at full corruption, when a window's captures (every rank's)
        read fewer than :func:`~deepmorph.training.code_shrink.shrink_below` of their code words,
        with a window's steps still to train; judged at the end of each window. ``wrong``: this
        step's ``(rows, N_b)`` code bits read wrong."""
        cfg, rec = self.cfg, self.record
        if not full_corruption:
            self._errors, self._settled = [], 0
            return
        window = cfg.early_stop_window
        self._settled += 1
        self._errors = [*self._errors, wrong][-window:]
        # judged at the end of each window after the settling one (the errors are gathered from
        # every rank only then)
        if (
            self._settled < 2 * window
            or self._settled % window
            or rec.stopped_early
            or rec.step + 1 + window > cfg.steps
        ):
            return
        errors = torch.cat([torch.cat(part) for part in gather_objects(self._errors, self.world)])
        spec = self.model.codec.spec
        read = read_share(errors, torch.arange(spec.code_bits), spec.bch_t)
        if read >= shrink_below(cfg.print_px):
            return
        smaller = smaller_code(errors, spec, CutRules.of(self.model, rec.payload_auto))
        if smaller is None:
            return
        new, keep, carried = smaller
        self._shrink(new, keep, read, carried, "batches")

    def _check_renders(self) -> None:
        """When training ends, judge an auto-sized code on fresh renders as validation will
        (:func:`~deepmorph.training.code_shrink.code_for_renders`, rank 0's finding given to
        every rank); one that reads too few is shrunk, halfway the first time, and trained on
        for ``renders_tune`` steps."""
        cfg, rec = self.cfg, self.record
        rounds = sum(s.measured_on == "renders" for s in rec.shrunk)
        if rounds >= RENDER_ROUNDS:
            return
        found = None
        if self.world.main:
            seed = cfg.seed + RENDER_SEED_OFFSET + len(rec.shrunk)
            found = code_for_renders(self.model, rec.payload_auto, seed, self.device.type, halfway=rounds == 0)
            self.model.encoder.to(self.device)  # reading the renders leaves the networks on the CPU
            self.model.decoder.to(self.device)
        found = gather_objects(found, self.world)[0]
        if found is None:
            return
        self._shrink(found.spec, found.keep, found.read, found.information, "renders")
        rec.total_steps = rec.step + 1 + cfg.renders_tune

    def _shrink(self, new: CodecSpec, keep: list[int], read: float, carried: float, measured_on: str) -> None:
        """Go on with the code ``new`` on the current code bits ``keep``, and record why."""
        cfg, rec, spec = self.cfg, self.record, self.model.codec.spec
        shrink_networks(self.model, keep, new)
        # fresh optimisers for the smaller networks (the step's learning rates are set each step)
        self.opt_dec = torch.optim.Adam(self.model.decoder.parameters(), lr=cfg.lr)
        self.opt_enc = torch.optim.Adam(self.model.encoder.parameters(), lr=cfg.encoder_lr)
        rec.shrunk = [
            *rec.shrunk,
            CodeShrink(
                step=rec.step + 1,
                payload_bits=(spec.payload_bits, new.payload_bits),
                code_bits=(spec.code_bits, new.code_bits),
                read=round(read, 4),
                information=round(carried, 2),
                measured_on=measured_on,
            ),
        ]
        self._errors, self._settled, self._reads = [], 0, []

    def _update_stage(self, bit_acc: float, step: int) -> None:
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
        if plateau or step >= limit:
            rec.stage, rec.stage2_start = 2, step
            stalled = self._prev_window is not None and self._prev_window < READOUT_STALL
            readout = self.model.decoder.readout
            if stalled and readout is not None and not readout_fitted(self.model.decoder):
                if self.world.main:  # fitted from shard 0's stream, then given to every rank
                    self.gen = self._gens[0]
                    fit_readout(self.model.decoder, self.images, self.model.codec.spec.code_bits, self.gen, self.device)
                broadcast_module(self.model.decoder, self.world)  # with the statistics the fit's batches moved
                readout.requires_grad_(True)


@dataclass
class TrainingSummary:
    """Where training wrote its files, and how it went."""

    bundle: Path
    log: Path
    plot: Path | None
    steps: int
    stage2_start: int | None
    elapsed_s: float
    validation: list[ValidationRecord] = field(default_factory=list)
    stopped_early: bool = False
    payload_bits: int = 0
    shrunk: list[CodeShrink] = field(default_factory=list)
    verifier: VerifierSummary | None = None
    trust: TrustRecord | None = None


def _settings_error(what: str, exc: ValidationError) -> DeepMorphError:
    problems = format_validation_error(exc, prefix="", known=TrainConfig.model_fields, kind="setting")
    return DeepMorphError(f"{what}: {problems}")


def train_model(
    svg: str | Path,
    out: str | Path,
    *,
    payload_bits: int | Literal["auto"] = PAYLOAD_BITS,
    crc_bits: int | None = None,
    ecc_t: int | None = None,
    bounds: dict[str, Any] | None = None,
    train: dict[str, Any] | None = None,
    resume: bool = False,
    overwrite: bool = False,
    on_start: Callable[[int, int], Callable[[dict[str, Any]], None]] | None = None,
    on_warning: Callable[[str], None] | None = None,
    drop_unsupported: bool = False,
    validation_samples: tuple[int, int] | None = None,
    on_validation: Callable[[], None] | None = None,
    world: World | None = None,
    on_verifier: Callable[[str], None] | None = None,
) -> TrainingSummary:
    """Train (or resume) a model for a drawing and write its bundle.

    Under torchrun each process calls it: they train together, rank 0 alone writes the
    checkpoints and the bundle, reports progress and warnings, and validates
    (:mod:`deepmorph.training.distributed`).

    Args:
        svg: the drawing.
        out: bundle path; it is also the checkpoint that ``resume`` continues.
        payload_bits, crc_bits, ecc_t: the payload and its code (:func:`deepmorph_core.codec.choose_codec`);
            ``payload_bits="auto"``: the largest size :func:`deepmorph_core.capacity.predict`
            predicts to read from 99 % of captures (with ``crc_bits`` and ``ecc_t`` where given).
        bounds: default bounds (``move``, ``shift``, ``scale``, ``rotate``) for unannotated elements.
        train: :class:`TrainConfig` fields (``steps``, ``batch``, ``seed`` ...).
        resume: continue the checkpoint at ``out``.
        overwrite: replace an existing bundle at ``out`` instead of refusing.
        on_start: ``on_start(total_steps, done_steps)`` returning a per-log callback (progress bars).
        on_warning: ``on_warning(text)`` for a warning before training starts (default:
            :func:`warnings.warn`), such as :func:`~deepmorph_core.capacity.size_warning`'s.
        drop_unsupported: train on the drawing with what DeepMorph cannot model left out (a
            warning names each part); the bundle holds that drawing.
        validation_samples: fresh payloads read from renders and from photos once training
            has finished (:mod:`deepmorph.training.validation`; default
            :func:`~deepmorph.training.validation.default_samples`); the records are stored in the
            bundle, and a model reading fewer than 99 % gets a warning. ``(0, 0)``: none.
        on_validation: called when validation starts (a progress message).
        world: this process's place in a data-parallel run (default: what torchrun's environment
            says; one process without it).
        on_verifier: called with each stage of the proposal verifier's training, where the
            settings ask for one (``verifier``; a progress message).
    """
    world = world or world_from_env()
    if not world.main:  # one process speaks: rank 0
        on_start, on_validation, on_warning = None, None, lambda text: None
    warn = on_warning or (lambda text: warnings.warn(text, stacklevel=3))
    model, config, label = open_model(
        svg, out, payload_bits, crc_bits, ecc_t, bounds, train, resume, overwrite, drop_unsupported, warn, world
    )
    out = Path(out)
    _, joined = join(world, config.device)
    try:
        run = CodecRun(model, config, out, world)
        loop = TrainingLoop(out, config, main=world.main, checkpoint_on_interrupt=not world.distributed)
        on_log = on_start(config.steps, model.meta.record.step) if on_start else None
        shrunk_before = len(model.meta.record.shrunk)
        summary: LoopSummary = loop.run(run, on_log)
        for shrink in run.record.shrunk[shrunk_before:]:
            warn(f"{label}: {describe(shrink)}")
    finally:
        if joined:
            leave()
    model.encoder.cpu()  # validated (and used after training) on the CPU, as the photo chain runs
    model.decoder.cpu()
    records: list[ValidationRecord] = []
    verifier = trust = None
    if world.main:  # rank 0 alone validates (the others have no plot either)
        device = resolve_device(config.device)
        weak: list[str] = []  # the validation's warning, said once it is known to be about the final code
        seed = config.seed
        records = _validate_and_store(model, out, label, validation_samples, seed, weak.append, on_validation, device)
        trust = _count_wrong_payloads(model, out, config, records, label, warn)
        if trust is not None and trust.crc_bits[0] != trust.crc_bits[1]:  # a new code: validated again
            records = _validate_and_store(model, out, label, validation_samples, seed, warn, None, device)
        else:
            for text in weak:
                warn(text)
        if wants_verifier(config):
            verifier = _add_verifier(out, config, warn, on_verifier)
    return TrainingSummary(
        out, summary.log, summary.plot, summary.steps, run.record.stage2_start, summary.elapsed_s, records,
        run.record.stopped_early, model.codec.spec.payload_bits, list(run.record.shrunk), verifier, trust,
    )  # fmt: skip


def _count_wrong_payloads(
    model: DeepMorphModel,
    out: Path,
    config: TrainSettings,
    records: list[ValidationRecord],
    label: str,
    warn: Callable[[str], None],
) -> TrustRecord | None:
    """Count the validated model's wrong payloads (:mod:`deepmorph.training.trust`), lengthen an
    ``auto`` payload's CRC where they call for it, and store the count in the bundle at ``out``:
    where ``trust_samples`` asks, else (a colour drawing) where its close-ups read at least
    :data:`~deepmorph.training.trust.COUNTED_FROM` (a model that reads fewer has its warning,
    and the close-ups of one that misreads take long to count)."""
    close_ups = [r for r in records if r.name == "close-ups"]
    if not close_ups:
        return None
    from deepmorph.training.trust import COUNTED_FROM, check_trust, trust_samples  # the photo chain, here only
    from deepmorph_detect.close_up_pool import one_per_thread

    samples = trust_samples(config.trust_samples, model.drawing.colour)
    if config.trust_samples is None and close_ups[0].rate < COUNTED_FROM:
        return None
    trust = check_trust(model, samples, config.seed, label, warn, workers=one_per_thread())
    if trust is not None:
        model.save(out)
    return trust


def wants_verifier(config: TrainSettings) -> bool:
    """Whether a training ends by training the model's proposal verifier: as ``verifier`` says,
    by default (``None``, and in bundles from before it was stored) with ``print_px``."""
    return config.verifier if config.verifier is not None else config.print_px is not None


def _add_verifier(
    out: Path, config: TrainSettings, warn: Callable[[str], None], on_stage: Callable[[str], None] | None
) -> VerifierSummary | None:
    """Train the proposal verifier of the bundle just written at ``out`` and store it there, on
    the training's threads and seed. A verifier that cannot be trained (its held-out prints
    scored too low, say) is a warning, and so is an interrupt before it is stored: the codec is
    written and reads without one."""
    from deepmorph.training.verifier import VerifierConfig, train_verifier

    try:
        return train_verifier(out, out, VerifierConfig(seed=config.seed, threads=config.threads), on_stage=on_stage)
    except DeepMorphError as exc:
        warn(f"{out}: written without a proposal verifier: {exc}")
        return None
    except KeyboardInterrupt:
        warn(f"{out}: written without a proposal verifier (deepmorph train-verifier {out} --out {out} adds one)")
        raise


def open_model(
    svg: str | Path | bytes,
    out: str | Path,
    payload_bits: int | Literal["auto"] = PAYLOAD_BITS,
    crc_bits: int | None = None,
    ecc_t: int | None = None,
    bounds: dict[str, Any] | None = None,
    train: dict[str, Any] | None = None,
    resume: bool = False,
    overwrite: bool = False,
    drop_unsupported: bool = False,
    warn: Callable[[str], None] = lambda text: warnings.warn(text, stacklevel=3),
    world: World | None = None,
) -> tuple[DeepMorphModel, TrainConfig, str]:
    """The model a training starts from and its settings, as :func:`train_model` takes them:
    a fresh one (seeded), or the checkpoint at ``out`` with ``resume``; and the drawing's label.
    The settings' device is resolved (``auto``: CUDA where present) and their shards set (a
    fresh run: one per process of ``world``; a checkpoint: its own, one where it has none).

    Raises:
        DeepMorphError: unreadable input, an ``out`` that may not be written, settings out of range.
    """
    out = check_target(out, f"--out {out}")  # before any work: a folder that cannot be written, say
    overrides = {k: v for k, v in (train or {}).items() if v is not None}
    if isinstance(svg, bytes):
        data, label = svg, "<drawing>"
    else:
        data, label = read_svg_bytes(svg), str(svg)
    # the bundle holds the drawing as DeepMorph writes it: what it models, nothing else (read
    # first, so that hostile or unsupported input is refused before anything else)
    md = MorphableDrawing.load(data, label=label, drop_unsupported=drop_unsupported and not resume)
    for line, what in md.drawing.dropped:
        warn(f"{label}:{line}: left out {what}")
    svg_text = md.to_svg(md.neutral_values()[0])
    try:
        if resume:
            model = DeepMorphModel.load(out)
            if model.meta.drawing_svg not in (svg_text, data.decode("utf-8", "replace")):
                raise DeepMorphError(f"{out}: the checkpoint was trained on another drawing than {svg}")
            if model.meta.record.finished:
                raise DeepMorphError(f"{out}: training already finished; nothing to resume")
            config = TrainConfig(
                **{
                    **model.meta.train,
                    # the checkpoint's decoder decides (one without a transformer keeps none)
                    "spatial_transformer": model.meta.decoder.spatial_transformer,
                    "readout": model.meta.decoder.readout,
                    **{k: v for k, v in overrides.items() if k in ("steps", "threads", "checkpoint_every", "device")},
                }
            )
            config = _resolved(config, config.shards or 1)
        else:
            if out.exists() and not overwrite:
                raise DeepMorphError(f"{out}: already exists; pass --resume to continue it or choose another --out")
            config = _resolved(TrainConfig(**overrides), (world or World()).size)
            if config.registered is None:
                config = config.model_copy(update={"registered": config.print_px is not None})
            if config.verifier is None:
                config = config.model_copy(update={"verifier": wants_verifier(config)})
            defaults = bound_defaults(**{k: v for k, v in (bounds or {}).items() if v is not None})
            augment = build_pipeline(
                config.severity,
                config.width,
                colour=md.colour,
                print_px=config.print_px,
                registered=bool(config.registered),
            )
            settings = RasterSettings(width=config.width)
            given_bounds = {k: v for k, v in (bounds or {}).items() if v is not None}
            channel = md.read_in(channel_for(config.read_in)).channel  # chosen once, for capacity and model
            spec = _payload_code(payload_bits, crc_bits, ecc_t, svg_text, given_bounds, config, label, warn, channel)
            torch.manual_seed(config.seed)  # the networks' initial weights are part of the seeded run
            model = DeepMorphModel.create(
                svg_text,
                Path(label).name,
                defaults.model_dump(exclude_none=True),
                spec,
                config.width,
                {k: getattr(settings, k) for k in ("sharpness", "squash", "blend", "flat_fills")},
                augment.config.model_dump(),
                config.model_dump(),
                decoder_config=DecoderConfig(spatial_transformer=config.spatial_transformer, readout=config.readout),
                label=label,
                reading_channel=channel,
            )
            if payload_bits == "auto":  # training may make the code smaller (deepmorph.training.code_shrink)
                model.meta.record.payload_auto = AutoPayload(crc_bits=crc_bits, ecc_t=ecc_t)
    except ValidationError as exc:
        raise _settings_error("training settings", exc) from None
    return model, config, label


def _resolved(config: TrainConfig, shards: int) -> TrainConfig:
    """``config`` with its device resolved and its shards set (``shards`` unless it names its own)."""
    return config.model_copy(update={"device": resolve_device(config.device), "shards": config.shards or shards})


def _payload_code(
    payload_bits: int | Literal["auto"],
    crc_bits: int | None,
    ecc_t: int | None,
    svg_text: str,
    bounds: dict[str, Any],
    config: TrainConfig,
    label: str,
    warn: Callable[[str], None],
    channel: Channel,
) -> CodecSpec:
    """The code of a new model: the requested payload's (with a warning when the drawing is
    predicted to carry less), or for ``"auto"`` the largest the drawing is predicted to carry,
    read in ``channel``, by a model of ``config`` (its frame width, and the print width it is
    trained for). Where ``crc_bits`` is ``None`` a colour drawing's CRC is at least
    :data:`~deepmorph_core.codec.COLOUR_CRC` bits, in the payload's bits for ``"auto"``."""
    drawing = MorphableDrawing.load(svg_text.encode(), label=label, **bounds).read_in(channel)
    check_trainable(drawing, Path(label).name)  # before the prediction, which renders every variable
    report = predict(drawing, config.width, crc_bits, (ecc_t,) if ecc_t is not None else None, config.print_px)
    if payload_bits == "auto":
        if report.codec is None:
            raise DeepMorphError(
                f"{label}: no payload is predicted to read from 99 % of captures ({report.readable_groups} readable "
                f"variables carry about {report.code_bits} code bits); let more of the drawing morph (dm: bounds, "
                "--move); `deepmorph capacity` says what limits it"
            )
        return report.codec
    if crc_bits is None:  # a colour drawing's photos need a longer CRC (docs/training.md)
        crc_bits = default_crc_bits(payload_bits, bool(drawing.colour))
    spec = choose_codec(payload_bits, crc_bits, ecc_t)
    warning = size_warning(spec, report, label)
    if warning:
        warn(warning)
    return spec


def _validate_and_store(
    model: DeepMorphModel,
    out: Path,
    label: str,
    samples: tuple[int, int] | None,
    seed: int,
    warn: Callable[[str], None],
    on_validation: Callable[[], None] | None,
    device: str = "cpu",
) -> list[ValidationRecord]:
    """Validate a trained (or tuned) model (its networks on ``device``), store the records in its
    bundle and warn when weak."""
    renders, photos = samples if samples is not None else default_samples()
    if renders <= 0:
        return []
    if on_validation:
        on_validation()
    records = validate(model, default_registry(), renders, photos, seed=seed, device=device)
    model.meta.validation = records
    model.save(out)
    warning = validation_warning(records, label, own_detector=model.meta.detector is not None)
    if warning:
        warn(warning)
    return records


class TuningRun(CodecRun):
    """Training a trained bundle's decoder further, its encoder frozen (:func:`tune_decoder`).

    Its progress is a record of its own; the bundle keeps its training record, and this run is
    the last entry of ``meta.tuning``, written at each checkpoint (``finished`` false until the
    last step).
    """

    panels = (Panel("decoder bit accuracy (training batches)", ("bit_acc",)),)

    def __init__(self, model: DeepMorphModel, config: TrainConfig, out: Path):
        if not config.freeze_encoder:
            raise ValueError("a tuning run trains the decoder alone: config.freeze_encoder must be set")
        self.trained_record = model.meta.record
        self._earlier = list(model.meta.tuning)
        model.meta.record = TrainingRecord()
        super().__init__(model, config, out)
        self.entry: dict[str, Any] = {
            "steps": 0,
            "total_steps": config.steps,
            **{k: getattr(config, k) for k in ("small_prints", "severity", "lr", "batch", "hard_fraction", "seed")},
            "threads": self.record.threads,
            "device": self.device.type,
        }
        self._window: list[float] = []

    def step(self) -> dict[str, float]:
        metrics = super().step()
        self._window = (self._window + [metrics["bit_acc"]])[-self.cfg.log_every :]
        return metrics

    def checkpoint(self) -> None:
        rec = self.record
        self.entry.update(steps=rec.step, finished=rec.finished, elapsed_s=round(rec.elapsed_s, 1))
        if self._window:
            self.entry["bit_acc"] = round(float(np.mean(self._window)), 5)
        self.model.meta.record = self.trained_record
        self.model.meta.tuning = [*self._earlier, self.entry]
        self.model.decoder.eval()
        if rec.finished:
            self.model.store_decoder_graph()
        self.model.save(self.out)
        self.model.meta.record = rec


def tune_decoder(
    model_path: str | Path,
    out: str | Path,
    *,
    steps: int = TUNE_DEFAULTS.steps,
    small_prints: float = TUNE_DEFAULTS.small_prints,
    lr: float = TUNE_DEFAULTS.lr,
    seed: int = 0,
    threads: int | None = None,
    device: str = "auto",
    overwrite: bool = False,
    on_start: Callable[[int, int], Callable[[dict[str, Any]], None]] | None = None,
    validation_samples: tuple[int, int] | None = None,
    on_validation: Callable[[], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Train a trained bundle's decoder further, encoder frozen, and write the result to ``out``.

    The morphs do not change, so printed codes still decode and the bundle's detector stays
    valid. The run uses the bundle's own corruption, batch and real-render share, at full
    corruption from the first step, with ``small_prints`` of each batch captured as small
    prints (:class:`TrainConfig`); the learning rate decays from ``lr`` by a cosine to 10 %.
    The run is recorded in the bundle's ``tuning`` list; Ctrl-C writes the decoder tuned so
    far, recorded as not finished.

    Args:
        model_path: a bundle whose training has finished.
        out: where to write the tuned bundle (may be ``model_path`` itself).
        device: where it trains (``auto``: CUDA where present), wherever the bundle was trained.
        on_start: ``on_start(total_steps, done_steps)`` returning a per-log callback.
        validation_samples, on_validation, on_warning: the tuned decoder is validated as after
            training (:func:`train_model`).

    Returns:
        The bundle's new ``tuning`` entry.
    """
    model_path, out = Path(model_path), Path(out)
    model = DeepMorphModel.load(model_path)
    if not model.meta.record.finished:
        raise DeepMorphError(f"{model_path}: its training has not finished; resume it before tuning")
    if out.exists() and not overwrite and out.resolve() != model_path.resolve():
        raise DeepMorphError(f"{out}: already exists; choose another --out")
    kept = {
        k: model.meta.train[k]
        for k in ("batch", "hard_fraction", "severity", "print_px", "registered")
        if k in model.meta.train
    }
    try:
        config = TrainConfig(
            **kept,
            width=model.width,
            steps=steps,
            small_prints=small_prints,
            lr=lr,
            seed=seed,
            threads=threads,
            device=resolve_device(device),
            curriculum=0.0,
            freeze_encoder=True,
        )
    except ValidationError as exc:
        raise _settings_error("tuning settings", exc) from None
    run = TuningRun(model, config, out)
    loop = TrainingLoop(out, config, ".tune.log.jsonl", f"the decoder tuned so far is in {out}")
    loop.run(run, on_start(config.steps, 0) if on_start else None)
    model.encoder.cpu()
    model.decoder.cpu()
    model.meta.record = run.trained_record
    warn = on_warning or (lambda text: warnings.warn(text, stacklevel=3))
    _validate_and_store(model, out, str(model_path), validation_samples, seed, warn, on_validation, config.device)
    return run.entry
