"""How fast the command line answers: wall time of ``python -m deepmorph`` commands that should
not wait for torch (``--help``, ``--version``, ``list-primitives``; target 0.3 s each), beside
``inspect`` (which builds a drawing, so imports torch), bare Python and ``import torch``.

Each round runs every command once, in turn, as a fresh process from the checkout's root, so
that background load falls on all of them alike; the table gives the median and the fastest of
``--repeats`` rounds, and whether the command imported torch (checked once, in a process that
reports ``sys.modules`` on exit).

    .venv/bin/python bench/cli_start.py --repeats 9
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _common import RESULTS, environment, table, write_json

ROOT = Path(__file__).resolve().parent.parent
GHOST = "deepmorph_core/data/ghost.svg"
TARGET_S = 0.3

#: (label, argv after the interpreter, whether the 0.3 s target applies)
COMMANDS = (
    ("python -c pass", ["-c", "pass"], False),
    ("python -c 'import torch'", ["-c", "import torch"], False),
    ("deepmorph --help", ["-m", "deepmorph", "--help"], True),
    ("deepmorph --version", ["-m", "deepmorph", "--version"], True),
    ("deepmorph list-primitives", ["-m", "deepmorph", "list-primitives"], True),
    ("deepmorph list-primitives --json", ["-m", "deepmorph", "list-primitives", "--json"], True),
    ("deepmorph inspect ghost.svg", ["-m", "deepmorph", "inspect", GHOST], False),
)

#: Runs the command line in-process, then says on stderr whether torch was imported.
_PROBE = (
    "import sys\nfrom deepmorph.cli import main\nsys.argv = ['deepmorph', *sys.argv[1:]]\n"
    "try:\n    main()\nexcept SystemExit:\n    pass\nprint('TORCH', 'torch' in sys.modules, file=sys.stderr)\n"
)


def wall_time(argv: list[str], root: Path) -> float | None:
    """Seconds the command took, or ``None`` when it failed (an older checkout may lack it)."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *argv], cwd=root, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    elapsed = time.perf_counter() - t0
    return elapsed if done.returncode == 0 else None


def imports_torch(argv: list[str], root: Path) -> bool:
    if argv[:2] != ["-m", "deepmorph"]:
        return "torch" in " ".join(argv)
    done = subprocess.run([sys.executable, "-c", _PROBE, *argv[2:]], cwd=root, capture_output=True, text=True)
    return "TORCH True" in done.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=9, help="rounds (each runs every command once)")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout to time (default: this one)")
    ap.add_argument("--json", type=Path, default=RESULTS / "cli_start.json")
    args = ap.parse_args()

    # a first run warms the file cache (and Python's bytecode cache) and leaves out what fails
    commands = [c for c in COMMANDS if wall_time(c[1], args.root) is not None]
    times: dict[str, list[float]] = {label: [] for label, _, _ in commands}
    for _ in range(args.repeats):
        for label, argv, _ in commands:
            times[label].append(wall_time(argv, args.root) or float("nan"))
    rows, records = [], []
    for label, argv, targeted in COMMANDS:
        if label not in times:
            rows.append([label, None, None, "-", "fails"])
            records.append({"command": label, "failed": True})
            continue
        median = statistics.median(times[label])
        torch = imports_torch(argv, args.root)
        verdict = ("ok" if median <= TARGET_S else "SLOW") if targeted else "-"
        rows.append([label, median, min(times[label]), "yes" if torch else "no", verdict])
        records.append({"command": label, "median_s": median, "min_s": min(times[label]), "times_s": times[label],
                        "imports_torch": torch, "target_s": TARGET_S if targeted else None})  # fmt: skip
    print(table(["command", "median s", "fastest s", "imports torch", f"<= {TARGET_S} s"], rows))
    record = {"environment": environment(), "root": str(args.root), "repeats": args.repeats, "commands": records}
    path = write_json(args.json, record)
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()
