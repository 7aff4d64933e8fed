"""Where a model's close-ups fail: the same close-ups ``bench/colour_reading.py`` reads (by
``--seed``: medium at the seed, hard at the seed + 1), each failure put in one class.

    .venv/bin/python bench/close_up_failures.py bench/results/colour_models/*.dmm

A close-up that is not read is:

* **not aligned**: no proposal of the detector aligned to the drawing;
* **no word**: aligned, but no look read a payload that passed the CRC;
* **right word withdrawn**: the right payload passed the CRC and its check withdrew it; the
  check's first reason is counted (the morph fit no better than the unmorphed drawing's; more
  than two bits shown flipped; the weakest bits barely shown; the morph leaving the photo
  unexplained; the nearest rival explaining it better), from the attempt that broke fewest rules;
* **other words only**: payloads that passed the CRC, none of them right, all withdrawn;
* **wrong**: a wrong payload reported (never expected; the check exists to stop it);
* **narrower**: a print narrower than a ``--pixels`` model reads, which the simulator makes now
  and then (no pose of the asked size fitted the frame) and the chain rightly refuses as too
  small (``validate_close_ups`` does not count them either).

``--at-truth`` also reads each missed close-up at the pose the simulator photographed it at
(``CloseUp.homography``), by the chain's own reading from an alignment (every look, turn, light
and check; :meth:`Locator.decode_drawing <deepmorph_detect.locate.Locator.decode_drawing>`), and
counts the misses that read there (*read at the truth*: the chain's alignment is to blame) apart
from those that do not (the reading and its checks are). With it goes the chain's alignment
error: the mean distance of its best alignment's frame corners from the truth, as a share of
the frame's width; and, for each right word withdrawn, whether its morph fits the photo better
than the unmorphed drawing there (each refined from that pose as the morph check refines): where
it does not, the photo does not show the morph to template matching even at the truth.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, pose_error, set_threads, table, write_json  # noqa: E402

KINDS = ("read", "not aligned", "no word", "right word withdrawn", "other words only", "wrong", "narrower")


def _reasons(check: Any) -> tuple[str, ...]:
    """The rules a withdrawn attempt broke (:class:`~deepmorph_detect.check.PayloadCheck`): the
    morph fit, else :attr:`BitEvidence.broken <deepmorph_detect.synthesis.BitEvidence.broken>`."""
    if check.status == "failed" or check.bits is None:
        return ("morph fit",)
    return check.bits.broken


def read_at_truth(locator: Any, shot: Any) -> tuple[bool, float | None, float | None]:
    """Whether ``shot`` reads its payload at the simulator's pose, by the chain's reading from an
    alignment; the chain's best alignment's corner error (``None``: none aligned); and how much
    better the true payload's morph fits the photo than the unmorphed drawing, each refined by
    the morph check's longer ECC solve from that pose (:meth:`PayloadChecker.fit_morph
    <deepmorph_detect.check.PayloadChecker.fit_morph>`; ``None``: a solve diverged). At or
    below 0 the photo does not show the morph to template matching even there."""
    from dataclasses import replace

    from deepmorph_detect.check import MORPH_WIDTH, RECHECK_ITERATIONS, MorphFit
    from deepmorph_detect.refine import LEVELS, aligned_at, refine_at

    gray, camera, pyramid = locator.frame(shot.photo, None)
    # reached at no level of ECC (width 0): the morph check aligns the unmorphed drawing afresh
    truth = replace(aligned_at(pyramid, shot.homography, locator.template, LEVELS[-1]), width=0)
    located = locator.decode_drawing(gray, pyramid, truth, 1.0, camera, "truth", True, True)
    read = bool(located.result.ok and np.array_equal(located.result.payload, shot.payload))
    checked = locator.checker.pyramid(shot.photo)
    fit = MorphFit.between(
        refine_at(checked, shot.homography, locator.template, MORPH_WIDTH, RECHECK_ITERATIONS),
        refine_at(
            checked, shot.homography, locator.checker.morphs.of_payload(shot.payload), MORPH_WIDTH, RECHECK_ITERATIONS
        ),
    )
    gain = None if fit is None else fit.gain
    aligned = locator.alignments(shot.photo)
    if not aligned:
        return read, None, gain
    best = max(aligned, key=lambda a: a.alignment.correlation).alignment.homography
    return read, pose_error(locator.template.viewbox, best, shot.homography), gain


def classify(
    model: Any, samples: int, seed: int, severity: str, detector: str, at_truth: bool = False
) -> tuple[Counter, Counter, list[dict[str, Any]]]:
    """Counts of :data:`KINDS` over ``samples`` close-ups, of the withdrawn right words' reasons,
    and (``at_truth``) each miss read again at the simulator's pose (:func:`read_at_truth`)."""
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import close_ups

    locator = Locator(model, detector=detector)
    attempts: list[tuple[bool, Any]] = []  # (the right payload?, its check) of every payload checked
    truth: list[np.ndarray] = []
    check = locator.checker.check

    def recorded(image, homography, result, *args, **kwargs):  # noqa: ANN001, ANN202
        verdict = check(image, homography, result, *args, **kwargs)
        if result.ok:
            attempts.append((bool(np.array_equal(result.payload, truth[0])), verdict))
        return verdict

    locator.checker.check = recorded
    kinds: Counter = Counter()
    reasons: Counter = Counter()
    misses: list[dict[str, Any]] = []
    for index, shot in enumerate(close_ups(model, samples, seed, severity)):
        truth[:] = [shot.payload]
        attempts.clear()
        found = [f for f in locator.locate(shot.photo) if f.result.ok]
        right = [check for is_right, check in attempts if is_right]
        if any(np.array_equal(f.result.payload, shot.payload) for f in found):
            kind = "read"
        elif found:
            kind = "wrong"
        elif shot.narrower_than_read(model):
            kind = "narrower"
        elif right:
            kind = "right word withdrawn"
            reasons[min((_reasons(c) or ("?",) for c in right), key=len)[0]] += 1
        elif attempts:
            kind = "other words only"
        else:
            kind = "no word" if locator.aligns(shot.photo) else "not aligned"
        kinds[kind] += 1
        if at_truth and kind not in ("read", "narrower"):
            read, error, gain = read_at_truth(locator, shot)
            misses.append({"close_up": index, "kind": kind, "read_at_truth": read,
                           "alignment_error": None if error is None else round(error, 4),
                           "morph_gain_at_truth": None if gain is None else round(gain, 5)})  # fmt: skip
    return kinds, reasons, misses


def _median(values: list[float | None]) -> str:
    """The median of the known values, as a table cell ("-": none)."""
    known = [v for v in values if v is not None]
    return f"{float(np.median(known)):.3f}" if known else "-"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("models", nargs="+", type=Path, help="trained bundles (.dmm)")
    p.add_argument("--close-ups", type=int, default=200, help="per severity")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--detector", default="universal")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--at-truth", action="store_true", help="also read each miss at the simulator's pose")
    p.add_argument("--out", type=Path, default=RESULTS / "close_up_failures.json")
    args = p.parse_args(argv)
    set_threads(args.threads)
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.synthesis import BIT_RULES

    reasons_in_order = ("morph fit", *BIT_RULES)
    start = time.perf_counter()
    rows = []
    for path in args.models:
        model = DeepMorphModel.load(path).eval()
        for severity, seed in (("medium", args.seed), ("hard", args.seed + 1)):
            kinds, reasons, misses = classify(model, args.close_ups, seed, severity, args.detector, args.at_truth)
            rows.append({"model": path.stem, "severity": severity, **{k: kinds[k] for k in KINDS},
                         "withdrawn_because": {r: reasons[r] for r in reasons_in_order if reasons[r]}})  # fmt: skip
            if args.at_truth:
                rows[-1]["misses"] = misses
                rows[-1]["read_at_truth"] = sum(m["read_at_truth"] for m in misses)
            print(f"{path.stem} {severity}: {dict(kinds)}", flush=True)
    headers = ["model", "severity", *KINDS, "withdrawn because"]
    body = [
        [
            r["model"],
            r["severity"],
            *(r[k] for k in KINDS),
            ", ".join(f"{k} {v}" for k, v in r["withdrawn_because"].items()),
        ]
        for r in rows
    ]
    print(f"\nClose-ups of {args.close_ups} per model and severity, {args.detector} detector:")
    print(table(headers, body))
    if args.at_truth:
        print("\nMisses read at the simulator's pose (the chain's alignment to blame), and the chain's")
        print("alignment error (its best alignment's corners from the truth, share of the frame's width):")
        print("Right words withdrawn whose morph fits the photo no better than the unmorphed drawing even at")
        print("that pose (each refined from it as the morph check refines):")
        headers = ["model", "severity", "misses", "read at the truth", "error median, read there", "not read",
                   "right word withdrawn", "no morph gain at the truth"]  # fmt: skip
        at_truth = []
        for r in rows:
            there = [m["alignment_error"] for m in r["misses"] if m["read_at_truth"]]
            not_there = [m["alignment_error"] for m in r["misses"] if not m["read_at_truth"]]
            withdrawn = [m for m in r["misses"] if m["kind"] == "right word withdrawn"]
            unseen = sum(m["morph_gain_at_truth"] is None or m["morph_gain_at_truth"] <= 0 for m in withdrawn)
            at_truth.append([r["model"], r["severity"], len(r["misses"]), r["read_at_truth"], _median(there),
                             _median(not_there), len(withdrawn), unseen])  # fmt: skip
        print(table(headers, at_truth))
    write_json(args.out, {"benchmark": "close_up_failures", "environment": environment(), "rows": rows,
                          "wall_s": round(time.perf_counter() - start, 1)})  # fmt: skip
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
