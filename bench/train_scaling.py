"""Training throughput on the CPU: 1 process against 2 gloo processes at the same global batch.

The drawing is :mod:`train_profile`'s (the first Feather icon with 30 to 60 variables at the
capacity panel's move), at its predicted payload size and the default settings (batch 32,
96 px, medium corruption, a quarter of each batch drawn by resvg). Each configuration runs
real training steps (:class:`~deepmorph.training.codec.CodecRun`, stage 2 at full corruption, the
heavier stage): ``--warmup`` steps, then ``--steps`` timed between two barriers. Rows:

* 1 process, 1 thread (the batch from one random stream);
* 1 process, 2 threads (the other way to use two cores);
* 2 processes of 1 thread each under gloo (torchrun's layout; 16 rows each, gradients summed by
  an all-reduce every step).

Wall time per step is what a run takes; the CPU time of rank 0's process per step is the work
one process does, so a row whose wall time is well above its CPU time waited for a core (other
work on the machine: the 1-minute load average is recorded with each row).

    .venv/bin/python bench/train_scaling.py               # table + bench/results/train_scaling.json
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, free_port, set_threads, table, write_json  # noqa: E402
from train_profile import FEATHER, pick_drawing  # noqa: E402


def worker(rank: int, world_size: int, port: int, args: dict[str, Any], results: Any) -> None:
    """One process: build the run, step, report seconds per step (rank 0)."""
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port), RANK=str(rank), WORLD_SIZE=str(world_size))
    threads = set_threads(args["threads"])
    import torch.distributed as dist

    from deepmorph.training.codec import CodecRun, open_model
    from deepmorph.training.distributed import World, join, leave

    world = World(rank, world_size, rank)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "m.dmm"
        train = {"threads": threads, "seed": args["seed"], "device": "cpu", "shards": world_size}
        model, config, _ = open_model(
            args["svg"], out, args["payload_bits"], args["crc_bits"], args["ecc_t"], {"move": args["move"]}, train,
            world=world,
        )  # fmt: skip
        _, joined = join(world, "cpu")
        run = CodecRun(model, config, out, world)
        ramp_end = int(config.curriculum * config.steps)
        run.record.step, run.record.stage, run.record.stage2_start = ramp_end, 2, ramp_end
        for _ in range(args["warmup"]):
            run.step()
        if joined:
            dist.barrier()
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(args["steps"]):
            run.step()
        cpu = (time.process_time() - cpu) / args["steps"]
        if joined:
            dist.barrier()
        seconds = (time.perf_counter() - start) / args["steps"]
        if rank == 0:
            results.put(
                {"processes": world_size, "threads": threads, "batch": config.batch, "step_s": seconds, "cpu_s": cpu}
            )
        if joined:
            leave()


def measure(processes: int, threads: int, args: dict[str, Any]) -> dict[str, Any]:
    import torch.multiprocessing as mp

    context = mp.get_context("spawn")
    results = context.Queue()
    settings = {**args, "threads": threads}
    mp.spawn(worker, (processes, free_port(), settings, results), nprocs=processes, join=True)
    row = results.get()
    row["load_average_1min"] = os.getloadavg()[0]  # other work on the machine slows every row
    row["steps_per_s"] = 1.0 / row["step_s"]
    row["samples_per_s"] = row["batch"] / row["step_s"]
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--feather", type=Path, default=FEATHER)
    ap.add_argument("--steps", type=int, default=30, help="steps timed per configuration")
    ap.add_argument("--warmup", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=RESULTS / "train_scaling.json")
    args = ap.parse_args(argv)
    set_threads(1)

    from deepmorph.training.codec import TrainConfig
    from deepmorph_core.capacity import predict
    from deepmorph_core.morphable import MorphableDrawing

    svg, move, n_variables = pick_drawing(args.feather)
    codec = predict(MorphableDrawing.load(svg, move=move), TrainConfig().width).codec
    if codec is None:
        raise SystemExit(f"{svg.name}: no payload is predicted to read")
    shared = {"svg": str(svg), "move": move, "payload_bits": codec.payload_bits, "crc_bits": codec.crc_bits,
              "ecc_t": codec.bch_t, "seed": args.seed, "steps": args.steps, "warmup": args.warmup}  # fmt: skip
    rows = [measure(1, 1, shared), measure(1, 2, shared), measure(2, 1, shared)]
    base = rows[0]["step_s"]
    print(
        f"{svg.name}: {n_variables} variables, {codec.payload_bits} payload bits; global batch {rows[0]['batch']}, "
        f"stage 2 at medium, {args.steps} steps timed; {os.cpu_count()} CPUs"
    )
    headers = ("processes", "threads each", "ms / step", "CPU ms / step", "steps / s", "samples / s", "speed-up",
               "load (1 min)")  # fmt: skip
    cells = [(r["processes"], r["threads"], 1000 * r["step_s"], 1000 * r["cpu_s"], r["steps_per_s"], r["samples_per_s"],
              base / r["step_s"], r["load_average_1min"]) for r in rows]  # fmt: skip
    print(table(headers, cells))
    write_json(
        args.out,
        {
            "environment": environment(),
            "drawing": svg.name,
            "n_variables": n_variables,
            "move": move,
            "codec": codec.model_dump(),
            "steps_timed": args.steps,
            "rows": rows,
        },  # fmt: skip
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
