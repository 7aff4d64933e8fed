"""Data-parallel training: two gloo processes under torchrun train the model one process trains
from the same random streams, rank 0 alone writes, and a checkpoint resumes on another number
of processes.

Tolerance: the weights agree to ``atol=1e-6, rtol=1e-5``. Two processes each draw one shard
and sum their gradients by an all-reduce; one process draws the same two shards and adds
their gradients in autograd; a sum of two floats is the same either way, so the runs agree to
rounding (in practice exactly). Each torchrun takes about 10 s on 2 cores (1 thread per process).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from deepmorph.training.codec import train_model
from deepmorph.training.distributed import World, rank_shards, shard_sizes, world_from_env
from deepmorph.training.loop import Interrupted, read_log
from deepmorph_core.device import resolve_device
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from tests.app.test_training import TINY

#: A few steps of both stages (stage 2 from step 3, with the readout fitted: the CNN stalls),
#: with real renders, corruption and batch norm, so that every part of a step is shared.
CFG = {
    "steps": 6,
    "batch": 8,
    "width": 32,
    "severity": "easy",
    "hard_fraction": 0.25,
    "threads": 1,
    "checkpoint_every": 3,
    "seed": 5,
    "device": "cpu",
}
CODE = {"payload_bits": 4, "crc_bits": 8, "ecc_t": 0}
CLI = ["--payload-bits", "4", "--crc", "8", "--ecc-t", "0", "--steps", "6", "--batch", "8", "--image-width", "32",
       "--severity", "easy", "--real-render-share", "0.25", "--threads", "1", "--seed", "5", "--validation", "0",
       "--checkpoint-every", "3", "--device", "cpu"]  # fmt: skip


def torchrun(nproc: int, args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """``torchrun --standalone --nproc_per_node nproc -m deepmorph ARGS`` (1 thread per process)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    for key in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT"):
        env.pop(key, None)
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", str(nproc)]
    return subprocess.run(
        [*command, "-m", "deepmorph", *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=240
    )


def assert_same_networks(a: Path, b: Path) -> None:
    one, two = DeepMorphModel.load(a), DeepMorphModel.load(b)
    for net in ("encoder", "decoder"):
        sa, sb = getattr(one, net).state_dict(), getattr(two, net).state_dict()
        assert sa.keys() == sb.keys()
        for key in sa:
            torch.testing.assert_close(sa[key], sb[key], atol=1e-6, rtol=1e-5, msg=f"{net}.{key}")


@pytest.fixture(scope="module")
def drawing(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("dist") / "tiny.svg"
    path.write_bytes(TINY)
    return path


@pytest.fixture(scope="module")
def one_process(drawing: Path) -> Path:
    """One process drawing the batch from two shards: the reference."""
    out = drawing.parent / "one.dmm"
    train_model(drawing, out, **CODE, train={**CFG, "shards": 2}, validation_samples=(0, 0))
    return out


def test_two_gloo_processes_train_what_one_process_trains(drawing: Path, one_process: Path) -> None:
    done = torchrun(2, ["train", drawing.name, "--out", "two.dmm", *CLI, "--json"], drawing.parent)
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout)  # rank 0 alone prints: one JSON document
    assert result["steps"] == 6 and result["stage2_start"] == 3
    two = drawing.parent / "two.dmm"
    assert_same_networks(one_process, two)
    # one log, written once, with the global batch's metrics: the reference's
    log_one, log_two = read_log(one_process.with_suffix(".log.jsonl")), read_log(two.with_suffix(".log.jsonl"))
    assert [line["step"] for line in log_two] == [6]
    assert {k: v for k, v in log_one[0].items() if k != "elapsed_s"} == {
        k: v for k, v in log_two[0].items() if k != "elapsed_s"
    }
    info = subprocess.run(
        [sys.executable, "-m", "deepmorph", "info", str(two), "--json"], capture_output=True, text=True, timeout=120
    )
    record = json.loads(info.stdout)
    assert record["trained_on"] == {"device": "cpu", "world_size": 2, "global_batch": 8}
    assert record["train"]["shards"] == 2


def test_a_checkpoint_of_one_process_resumes_on_two(drawing: Path) -> None:
    """Interrupted at step 12 of 24 on one process, resumed on two: the model of an
    uninterrupted run. The stage switch and the readout's least-squares fit (rank 0 fits, then
    gives it to rank 1) fall in the resumed half: the CNN stalls and plateaus at step 20."""
    train = {**CFG, "steps": 24, "shards": 2, "log_every": 4, "checkpoint_every": 6, "plateau_window": 10,
             "plateau_gain": 1.0, "stage1_max_fraction": 1.0}  # fmt: skip
    straight = drawing.parent / "straight.dmm"
    train_model(drawing, straight, **CODE, train=train, validation_samples=(0, 0))
    broken = drawing.parent / "broken.dmm"

    def stop_at_12(total: int, done: int):
        def on_log(m):
            if m["step"] == 12:
                raise KeyboardInterrupt

        return on_log

    with pytest.raises(Interrupted, match="interrupted at step 12/24"):
        train_model(drawing, broken, **CODE, train=train, on_start=stop_at_12, validation_samples=(0, 0))
    assert DeepMorphModel.load(broken).meta.record.step == 12
    done = torchrun(
        2,
        ["train", drawing.name, "--out", broken.name, "--resume", "--steps", "24", "--validation", "0"],
        drawing.parent,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    resumed = DeepMorphModel.load(broken)
    assert resumed.meta.record.finished and resumed.meta.record.world_size == 2
    assert resumed.meta.record.stage2_start == 20 and resumed.decoder.readout is not None
    assert_same_networks(straight, broken)
    assert [line["step"] for line in read_log(broken.with_suffix(".log.jsonl"))] == [4, 8, 12, 16, 20, 24]


#: Rank 0 of a torchrun of this script stops at step 16, after the checkpoint of step 12 (a run
#: of several processes writes none on an interrupt); the other rank then fails with it.
STOP_AT_16 = """
import sys
from deepmorph.training.codec import train_model
train = {train!r}

def stop_at_16(total, done):
    def on_log(m):
        if m["step"] == 16:
            raise KeyboardInterrupt
    return on_log

train_model("tiny.svg", "broken2.dmm", payload_bits=4, crc_bits=8, ecc_t=0, train=train, on_start=stop_at_16,
            validation_samples=(0, 0))
"""


def test_a_checkpoint_of_two_processes_resumes_on_one(drawing: Path) -> None:
    """The checkpoint holds both processes' random streams (gathered to rank 0): one process
    resumes it to the model of the uninterrupted run."""
    train = {**CFG, "steps": 24, "shards": 2, "log_every": 4, "checkpoint_every": 12, "plateau_window": 10,
             "plateau_gain": 1.0, "stage1_max_fraction": 1.0}  # fmt: skip
    straight = drawing.parent / "straight.dmm"
    if not straight.exists():  # the previous test's reference, with other checkpoints
        train_model(drawing, straight, **CODE, train={**train, "checkpoint_every": 6}, validation_samples=(0, 0))
    script = drawing.parent / "stop.py"
    script.write_text(STOP_AT_16.format(train=train))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script)]
    subprocess.run(command, cwd=drawing.parent, env=env, capture_output=True, text=True, timeout=240)
    broken = drawing.parent / "broken2.dmm"
    checkpoint = DeepMorphModel.load(broken)
    assert checkpoint.meta.record.step == 12 and not checkpoint.meta.record.finished
    assert {"rng.cpu", "rng.shard.1"} <= set(checkpoint.extra_tensors)
    train_model(drawing, broken, resume=True, validation_samples=(0, 0), world=World())
    assert DeepMorphModel.load(broken).meta.record.world_size == 1
    assert_same_networks(straight, broken)


#: A torchrun of this script trains an auto-sized code that does not read at once at ``hard``:
#: both processes must shrink it the same way, from both ranks' captures. Each then checks that
#: it left the process group whole: no gloo thread outlives training (one that did freed its
#: last collective's tensors while the interpreter exited, and aborted the process now and then).
AUTO_SHRINK = """
import gc, os, sys
from deepmorph.training.codec import train_model
train_model("tiny.svg", {out!r}, payload_bits="auto", train={train!r}, validation_samples=(0, 0))
gc.collect()
names = [open(f"/proc/self/task/{{t}}/comm").read().strip() for t in os.listdir("/proc/self/task")]
if any("gloo" in name for name in names):
    sys.exit(f"gloo threads outlived training: {{names}}")
"""


@pytest.mark.parametrize(("severity", "window", "measured_on"), [("hard", 10, "batches"), ("none", 250, "renders")])
def test_two_processes_shrink_an_auto_code_as_one_process_does(
    drawing: Path, severity: str, window: int, measured_on: str
) -> None:
    """An ``auto`` code shrunk under torchrun (:mod:`deepmorph.training.code_shrink`) is shrunk at
    the same step to the same bits as by one process drawing the same two shards: the decision
    is made on every rank from every rank's captures (``hard``: its batches do not read), or on
    rank 0's renders and given to every rank (``none``, with no batch check in 32 steps: its
    renders do not read)."""
    train = {**CFG, "steps": 32, "shards": 2, "severity": severity, "curriculum": 0.0, "early_stop_window": window,
             "checkpoint_every": 32, "renders_tune": 8}  # fmt: skip
    one, two = drawing.parent / f"auto1-{severity}.dmm", drawing.parent / f"auto2-{severity}.dmm"
    train_model(drawing, one, payload_bits="auto", train=train, validation_samples=(0, 0))
    script = drawing.parent / "auto.py"
    script.write_text(AUTO_SHRINK.format(train=train, out=two.name))
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2", str(script)]
    done = subprocess.run(command, cwd=drawing.parent, env=env, capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr[-3000:]
    a, b = DeepMorphModel.load(one), DeepMorphModel.load(two)
    assert a.meta.record.shrunk and a.meta.record.shrunk == b.meta.record.shrunk
    assert measured_on in {s.measured_on for s in a.meta.record.shrunk}
    assert a.codec.spec == b.codec.spec
    assert_same_networks(one, two)


def test_shards_split_the_batch_and_the_ranks_share_them() -> None:
    assert shard_sizes(8, 2) == [4, 4] and shard_sizes(10, 4) == [3, 3, 2, 2] and shard_sizes(5, 1) == [5]
    assert rank_shards(4, World(1, 2)) == [1, 3] and rank_shards(3, World(0, 2)) == [0, 2]
    assert rank_shards(3, World(1, 2)) == [1]
    with pytest.raises(DeepMorphError, match="3 processes but the batch is drawn from 2 random streams"):
        rank_shards(2, World(0, 3))


def test_the_world_comes_from_torchruns_environment() -> None:
    assert world_from_env({}) == World(0, 1, 0)
    assert world_from_env({"RANK": "3", "WORLD_SIZE": "4", "LOCAL_RANK": "1"}) == World(3, 4, 1)
    with pytest.raises(DeepMorphError, match="whole numbers"):
        world_from_env({"RANK": "x"})
    with pytest.raises(DeepMorphError, match="do not describe"):
        world_from_env({"RANK": "2", "WORLD_SIZE": "2"})
    assert resolve_device("cpu") == "cpu"
