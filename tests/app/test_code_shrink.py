"""Training shrinks a ``--payload-bits auto`` code its drawing does not carry
(:mod:`deepmorph.training.code_shrink`), and never a size the user gave."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph.training.code_shrink import (
    RENDER_FIT,
    RENDER_ROUNDS,
    CutRules,
    code_fitting,
    information,
    read_share,
    shrink_networks,
    simulated_read,
    smaller_code,
)
from deepmorph.training.codec import train_model
from deepmorph.training.loop import Interrupted
from deepmorph_core.bundle import AutoPayload
from deepmorph_core.capacity import default_crc_code, plan_code
from deepmorph_core.codec import choose_codec
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.payload import random_payloads
from tests.app.test_training import FAST, TINY, _interrupt_at
from tests.conftest import table_text

#: Full corruption from the first step at ``hard``, a short window: an untrained decoder reads
#: almost no code word of the first windows, so an auto-sized code is shrunk at step 20.
HARD_AT_ONCE = {**FAST, "steps": 60, "severity": "hard", "curriculum": 0.0, "early_stop_window": 10,
                "checkpoint_every": 5, "log_every": 5, "seed": 2, "renders_tune": 0}  # fmt: skip


@pytest.fixture(scope="module")
def tiny_svg(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("d") / "tiny.svg"
    path.write_bytes(TINY)
    return path


def test_the_smaller_code_is_halfway_to_the_information_its_bits_carried() -> None:
    """Of a code's bits, 14 read always and the rest at chance (no information): the code
    kept is the largest payload's that fits halfway between the code (less one bit) and 14
    bits, on the best-read bits; the user's CRC and BCH stay; below the smallest code, nothing."""
    spec = choose_codec(20, 8, 2)
    gen = torch.Generator().manual_seed(0)
    errors = torch.rand(4000, spec.code_bits, generator=gen) < 0.5
    good = torch.randperm(spec.code_bits, generator=gen)[:14]
    errors[:, good] = False
    assert information(errors) == pytest.approx(14, abs=0.2)
    assert information(torch.zeros(10, 7, dtype=torch.bool)) == 7.0
    new, keep, carried = smaller_code(errors, spec, CutRules())
    size = math.ceil((carried + spec.code_bits - 1) / 2)
    assert (
        new.code_bits <= size < min(c.code_bits for c in (choose_codec(new.payload_bits + 1, None, t) for t in (1, 2)))
    )
    assert len(keep) == new.code_bits and set(good.tolist()) <= set(keep)
    assert read_share(errors, good, 0) == 1.0 > read_share(errors, torch.tensor(keep), new.bch_t)
    fixed, _, _ = smaller_code(errors, spec, CutRules(AutoPayload(crc_bits=16, ecc_t=1)))
    assert (fixed.crc_bits, fixed.bch_t) == (16, 1)
    at_pixels, _, _ = smaller_code(errors, spec, CutRules(print_px=200))
    assert at_pixels.bch_t == 2  # the --pixels plan's strength
    # nothing carried: halfway is below the smallest code, which is taken; below it, nothing
    noise = torch.rand(4000, 24, generator=gen) < 0.5
    small = choose_codec(4, None, 1)
    smallest, _, _ = smaller_code(noise[:, : small.code_bits], small, CutRules())
    assert smallest == min((choose_codec(1, None, t) for t in (1, 2)), key=lambda c: c.code_bits)
    assert smaller_code(noise[:, : smallest.code_bits], smallest, CutRules()) is None


def test_shrunk_networks_are_the_kept_bits_of_the_old_ones(tiny_svg: Path, tmp_path: Path) -> None:
    """The smaller networks compute what the old ones did on the kept bits: the decoder's
    logits are the old logits of those bits, and the encoder drives the variables with the kept
    bits' columns."""
    out = tmp_path / "m.dmm"
    train_model(
        tiny_svg, out, payload_bits=8, crc_bits=8, ecc_t=1, train={**FAST, "steps": 5}, validation_samples=(0, 0)
    )
    model = DeepMorphModel.load(out).eval()
    images = torch.rand(3, 1, *model.image_size, generator=torch.Generator().manual_seed(1))
    old_weight = model.encoder.linear.weight.detach().clone()
    with torch.no_grad():
        before = model.decoder(images)
    new = choose_codec(2, 8, 1)
    keep = list(range(1, 1 + new.code_bits))
    shrink_networks(model, keep, new)
    with torch.no_grad():
        torch.testing.assert_close(model.decoder(images), before[:, keep])
    torch.testing.assert_close(model.encoder.linear.weight, old_weight[:, keep])
    assert model.codec.spec == model.meta.codec == new and not model.graphs
    model.save(tmp_path / "small.dmm")
    again = DeepMorphModel.load(tmp_path / "small.dmm")
    payload = random_payloads(1, 2, np.random.default_rng(0))[0]
    assert again.encode(payload) == model.encode(payload)


def test_an_auto_code_that_does_not_read_is_shrunk_and_a_given_one_is_not(tiny_svg: Path, tmp_path: Path) -> None:
    """At auto, the code its batches do not read is made smaller at step 20 (after a settling
    window and a watched one), the user is told, the bundle records it and ``info`` shows it;
    the run resumed across it is the same run; a size the user gave stays."""
    warnings: list[str] = []
    auto = tmp_path / "auto.dmm"
    summary = train_model(tiny_svg, auto, payload_bits="auto", train=HARD_AT_ONCE, validation_samples=(0, 0),
                          on_warning=warnings.append)  # fmt: skip
    model = DeepMorphModel.load(auto)
    rec = model.meta.record
    assert summary.shrunk == rec.shrunk and summary.payload_bits == model.codec.spec.payload_bits
    assert rec.payload_auto == AutoPayload() and rec.finished
    first = rec.shrunk[0]
    assert first.step == 20 and first.read < 0.9 and first.payload_bits[1] < first.payload_bits[0]
    last = rec.shrunk[-1]
    assert model.codec.spec.payload_bits == last.payload_bits[1] and model.codec.spec.code_bits == last.code_bits[1]
    assert model.encoder.linear.weight.shape[1] == model.decoder.head[-1].out_features == last.code_bits[1]
    assert any(f"{first.payload_bits[0]}-bit payload read" in w and "training went on with" in w for w in warnings)
    shown = table_text(CliRunner().invoke(application(), ["info", str(auto)]).stdout)
    assert f"sized by training: {first.payload_bits[0]} -> " in shown, shown

    resumed = tmp_path / "resumed.dmm"  # interrupted after the first shrink, with a window half full
    with pytest.raises(Interrupted, match="interrupted at step 25/60"):
        train_model(tiny_svg, resumed, payload_bits="auto", train=HARD_AT_ONCE, validation_samples=(0, 0),
                    on_start=_interrupt_at(25))  # fmt: skip
    train_model(tiny_svg, resumed, resume=True, validation_samples=(0, 0))
    again = DeepMorphModel.load(resumed)
    assert again.meta.record.shrunk == rec.shrunk
    for key, value in model.decoder.state_dict().items():
        torch.testing.assert_close(value, again.decoder.state_dict()[key], msg=key)
    torch.testing.assert_close(model.encoder.linear.weight, again.encoder.linear.weight)

    given = tmp_path / "given.dmm"
    train_model(tiny_svg, given, payload_bits=first.payload_bits[0], train=HARD_AT_ONCE, validation_samples=(0, 0))
    kept = DeepMorphModel.load(given)
    assert kept.codec.spec.payload_bits == first.payload_bits[0] and not kept.meta.record.shrunk
    assert kept.meta.record.payload_auto is None


def _reliabilities(error_rates: np.ndarray, rows: int, rng: np.random.Generator) -> np.ndarray:
    """``(rows, N)`` probabilities of each bit's right value, as a decoder gives them: 0.9 where
    a capture read the bit right, 0.1 where it read it wrong (bit ``i`` with ``error_rates[i]``)."""
    return np.where(rng.random((rows, len(error_rates))) < error_rates, 0.1, 0.9)


def test_the_code_fitted_to_measured_reliabilities_keeps_the_reliable_bits() -> None:
    """Of a 20-bit payload's code, 26 bits are read wrong in 1 capture of 2000 and the rest at
    chance: the code kept is the largest payload's whose best bits read :data:`RENDER_FIT` of
    the captures, on the most reliable bits; one payload bit more does not fit; the user's CRC
    and BCH stay; below the smallest code, nothing."""
    spec = choose_codec(20, 8, 2)
    rng = np.random.default_rng(0)
    rates = np.full(spec.code_bits, 0.5)
    reliable = rng.permutation(spec.code_bits)[:26]
    rates[reliable] = 0.0005
    right = _reliabilities(rates, 1000, rng)
    assert simulated_read(_reliabilities(np.zeros(spec.code_bits), 300, rng), spec, rng) == 1.0
    assert simulated_read(_reliabilities(np.full(spec.code_bits, 0.5), 300, rng), spec, rng) < 0.05
    new, keep = code_fitting(right, spec, CutRules(), rng)
    assert new.payload_bits < spec.payload_bits and len(keep) == new.code_bits
    assert set(keep) <= set(reliable.tolist()) or set(reliable.tolist()) <= set(keep)  # the best bits
    assert simulated_read(right[:, keep], new, rng) >= RENDER_FIT
    order = np.argsort(-right.mean(0), kind="stable")
    for bigger in (choose_codec(new.payload_bits + 1, None, t) for t in (2, 1)):
        assert simulated_read(right[:, order[: bigger.code_bits]], bigger, rng) < RENDER_FIT
    fixed, _ = code_fitting(right, spec, CutRules(AutoPayload(crc_bits=16, ecc_t=1)), rng)
    assert (fixed.crc_bits, fixed.bch_t) == (16, 1)
    assert new.bch_t == 1  # the 96-px plan's strengths: a t = 1 code fits more here
    at_pixels, _ = code_fitting(right, spec, CutRules(print_px=200), rng)
    assert at_pixels.bch_t == 2 and at_pixels.payload_bits < new.payload_bits  # --pixels plans t = 2 alone
    smallest = min((choose_codec(1, None, t) for t in (1, 2)), key=lambda c: c.code_bits)
    noise = _reliabilities(np.full(smallest.code_bits, 0.5), 100, rng)
    assert code_fitting(noise, smallest, CutRules(), rng) is None


def test_the_first_cut_goes_halfway_to_the_code_the_reliabilities_fit() -> None:
    """``halfway``: the largest payload whose code fits halfway (in code bits) between the code
    now (less one) and the one the reliabilities fit, on the most reliable bits; never smaller
    than that one, and nothing where nothing is smaller."""
    spec = choose_codec(24, None, 2)
    rng = np.random.default_rng(1)
    rates = np.full(spec.code_bits, 0.5)
    rates[rng.permutation(spec.code_bits)[:30]] = 0.0005
    right = _reliabilities(rates, 1000, rng)
    fitted, _ = code_fitting(right, spec, CutRules(print_px=200), np.random.default_rng(2))
    half, keep = code_fitting(right, spec, CutRules(print_px=200), np.random.default_rng(2), halfway=True)
    size = math.ceil((spec.code_bits - 1 + fitted.code_bits) / 2)
    assert fitted.payload_bits < half.payload_bits < spec.payload_bits and half.code_bits <= size
    assert choose_codec(half.payload_bits + 1, None, 2).code_bits > size and half.bch_t == 2
    order = np.argsort(-right.mean(0), kind="stable")
    assert keep == sorted(int(k) for k in order[: half.code_bits])  # the most reliable bits
    smallest = choose_codec(1, None, 2)
    noise = _reliabilities(np.full(smallest.code_bits, 0.5), 100, rng)
    assert code_fitting(noise, smallest, CutRules(print_px=200), rng, halfway=True) is None


#: A few steps with no corruption: the batches read, and the renders, read at ``medium``, do not.
def test_a_colour_codes_cut_keeps_the_colour_crc_and_loses_what_the_black_codes_cut_loses() -> None:
    """A colour drawing's planned code (CRC-12) is cut as the code it was planned from (CRC-8)
    and planned again: the same code bits kept, the same information bits, CRC-12 while the
    payload has the bits; a CRC the user fixed is left as it is."""
    black = choose_codec(20, 8, 2)
    colour = plan_code(black, colour=True)
    gen = torch.Generator().manual_seed(0)
    errors = torch.rand(4000, black.code_bits, generator=gen) < 0.5
    errors[:, torch.randperm(black.code_bits, generator=gen)[:14]] = False
    cut_black, keep_black, _ = smaller_code(errors, black, CutRules())
    cut_colour, keep_colour, _ = smaller_code(errors, colour, CutRules(colour=True))
    assert keep_colour == keep_black and cut_colour.code_bits == cut_black.code_bits
    assert cut_colour == plan_code(cut_black, colour=True) and cut_colour.crc_bits > 8
    assert cut_colour.payload_bits + cut_colour.crc_bits == cut_black.payload_bits + cut_black.crc_bits
    fixed, _, _ = smaller_code(errors, choose_codec(20, 12, 2), CutRules(AutoPayload(crc_bits=12), colour=True))
    assert fixed.crc_bits == 12


EASY_THEN_RENDERS = {**FAST, "steps": 30, "renders_tune": 20, "checkpoint_every": 10, "seed": 2}


@pytest.mark.parametrize("stroke", ["black", "#c03020"])
def test_the_first_renders_cut_goes_halfway_in_black_and_white_and_in_colour(
    stroke: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The cuts when training ends ask for halfway on their first round alone, for a
    black-and-white drawing and a colour one alike."""
    import deepmorph.training.codec as codec_module

    asked: list[bool] = []
    real = codec_module.code_for_renders

    def spy(*args: object, halfway: bool = False, **kwargs: object) -> object:
        asked.append(halfway)
        return real(*args, halfway=halfway, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(codec_module, "code_for_renders", spy)
    svg = tmp_path / "tiny.svg"
    svg.write_bytes(TINY.replace(b'stroke="black"', f'stroke="{stroke}"'.encode()))
    train_model(svg, tmp_path / "m.dmm", payload_bits="auto", train=EASY_THEN_RENDERS, validation_samples=(0, 0))
    model = DeepMorphModel.load(tmp_path / "m.dmm")
    colour = model.drawing.colour
    assert colour == (stroke != "black") and asked
    assert asked == [True] + [False] * (len(asked) - 1)
    spec = model.codec.spec  # cut as planned: a colour code keeps the plan's longer CRC where it can
    assert spec == plan_code(default_crc_code(spec), colour) and (colour or spec.crc_bits == 8)


def test_an_auto_code_that_reads_too_few_renders_is_shrunk_when_training_ends(tiny_svg: Path, tmp_path: Path) -> None:
    """When training ends, an auto code is read from fresh renders; one that reads too few is
    shrunk on its most reliable bits and trained on for ``renders_tune`` steps, at most
    :data:`RENDER_ROUNDS` times; the user is told and ``info`` shows it; a run resumed in the
    extra steps is the same run; a size the user gave is not checked."""
    warnings: list[str] = []
    auto = tmp_path / "auto.dmm"
    train_model(tiny_svg, auto, payload_bits="auto", train=EASY_THEN_RENDERS, validation_samples=(0, 0),
                on_warning=warnings.append)  # fmt: skip
    model = DeepMorphModel.load(auto)
    rec = model.meta.record
    by_renders = [s for s in rec.shrunk if s.measured_on == "renders"]
    assert by_renders and len(by_renders) <= RENDER_ROUNDS and rec.finished
    first, last = by_renders[0], by_renders[-1]
    assert first.step == 30 and first.read < 0.99 and first.payload_bits[1] < first.payload_bits[0]
    assert rec.step == last.step + 20 and model.codec.spec.code_bits == last.code_bits[1]
    assert model.encoder.linear.weight.shape[1] == model.decoder.head[-1].out_features == last.code_bits[1]
    assert any("of fresh renders when training ended at step 30" in w for w in warnings), warnings
    shown = table_text(CliRunner().invoke(application(), ["info", str(auto)]).stdout)
    assert f"{first.payload_bits[0]} -> {first.payload_bits[1]} at step 30 (it read" in shown, shown

    resumed = tmp_path / "resumed.dmm"  # interrupted in the steps after the first check
    with pytest.raises(Interrupted, match="interrupted at step 40/50"):
        train_model(tiny_svg, resumed, payload_bits="auto", train=EASY_THEN_RENDERS, validation_samples=(0, 0),
                    on_start=_interrupt_at(40))  # fmt: skip
    train_model(tiny_svg, resumed, resume=True, validation_samples=(0, 0))
    again = DeepMorphModel.load(resumed)
    assert again.meta.record.shrunk == rec.shrunk and again.meta.record.step == rec.step
    for key, value in model.decoder.state_dict().items():
        torch.testing.assert_close(value, again.decoder.state_dict()[key], msg=key)

    given = tmp_path / "given.dmm"
    train_model(tiny_svg, given, payload_bits=first.payload_bits[0], train=EASY_THEN_RENDERS, validation_samples=(0, 0))
    kept = DeepMorphModel.load(given)
    assert kept.codec.spec.payload_bits == first.payload_bits[0] and not kept.meta.record.shrunk
    assert kept.meta.record.step == 30
