"""Decoding: how much the codec's soft search leaves to the best possible decoder of the same code.

For each trained bundle: ``--samples`` fresh payloads rendered by resvg under the ``medium``
corruption (as ``deepmorph validate`` reads them), the decoder's bit probabilities decoded twice:

* by the codec (hard decisions, BCH, then the Chase-II soft search with its candidate budget);
* by **maximum likelihood within a budget**: the ``R`` words most likely under the read (the
  hard decisions, then flips in order of their summed ``|log-odds|``) are tried in turn, and the
  first that is a code word of the whole code (CRC and BCH parity together, ``r`` check bits)
  is the answer. A read no code word explains within ``R`` words is refused. Each word tried is
  a ``2^-r`` chance that an unrelated read passes, so ``R`` is set to the codec's own bound,
  ``(1 + soft_candidates) * 2^-C``: both decoders promise the same false-accept rate.

Then ``--garbage`` reads per bundle with the same reliabilities but every bit's side drawn at
random (pictures the decoder reads confidently and wrongly) count the false accepts each
decoder really makes. The probabilities are calibrated (docs/design-notes.md), so the budgeted
search is the most likely payload the read allows at that false-accept rate: what any stronger
decoder of this code could add.

    .venv/bin/python bench/decoding.py m1.dmm m2.dmm --samples 2000 --garbage 10000
"""

from __future__ import annotations

import argparse
import heapq
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402


class BudgetedML:
    """The most likely code word among the ``budget`` most likely words under a read, the
    budget set so that a read unrelated to the code passes with probability at most ``bound``."""

    def __init__(self, codec: Any, bound: float) -> None:
        self.k = codec.spec.payload_bits
        self.check_bits = codec.spec.code_bits - self.k
        self.budget = max(1, int(bound * 2**self.check_bits))  # words tried: each a 2^-r chance for garbage
        # each code bit's column of the parity checks, as an integer (the codec's own, for its syndromes)
        self.columns = codec._check_columns()
        self.offset = codec._zero_word  # the zero payload's word (the whitening), set with the columns
        self.target = self._syndrome(self.offset)

    def _syndrome(self, word: np.ndarray) -> int:
        out = 0
        for c in self.columns[word.astype(bool)]:
            out ^= int(c)
        return out

    def decode(self, probs: np.ndarray) -> np.ndarray | None:
        """The payload, or ``None`` when no code word is among the ``budget`` likeliest words."""
        p = np.clip(probs, 1e-12, 1 - 1e-12)
        hard = (p > 0.5).astype(np.uint8)
        cost = np.abs(np.log(p) - np.log1p(-p))
        order = np.argsort(cost, kind="stable")
        costs, cols = cost[order], self.columns[order]
        need = self._syndrome(hard) ^ self.target  # the flips' syndrome must cancel it
        if need == 0:
            return hard[: self.k] ^ self.offset[: self.k]
        # subsets of flips in order of summed cost: from (last index j) extend with j+1 or swap j for j+1
        heap = [(float(costs[0]), 0, int(cols[0]), (0,))]
        for _ in range(self.budget - 1):
            if not heap:
                break
            total, j, syn, flips = heapq.heappop(heap)
            if syn == need:
                word = hard.copy()
                word[order[list(flips)]] ^= 1
                return word[: self.k] ^ self.offset[: self.k]
            if j + 1 < len(costs):
                heapq.heappush(heap, (total + float(costs[j + 1]), j + 1, syn ^ int(cols[j + 1]), (*flips, j + 1)))
                heapq.heappush(
                    heap,
                    (total - float(costs[j]) + float(costs[j + 1]), j + 1, syn ^ int(cols[j]) ^ int(cols[j + 1]),
                     (*flips[:-1], j + 1)),
                )  # fmt: skip
        return None


def score(decode: Any, probs: np.ndarray, payloads: np.ndarray) -> tuple[int, int]:
    """``(read, wrong)``: payloads decoded right, and decoded but not the one sent."""
    read = wrong = 0
    for p, sent in zip(probs, payloads):
        got = decode(p)
        if got is not None:
            same = bool(np.array_equal(got, sent))
            read += same
            wrong += not same
    return read, wrong


def measure(path: Path, samples: int, garbage: int, seed: int) -> dict[str, Any]:
    from deepmorph.training.validation import read_renders
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.payload import random_payloads

    model = DeepMorphModel.load(path)
    codec = model.codec
    spec = codec.spec
    candidates = codec.soft_candidates
    bound = (1 + candidates) * 2.0**-spec.crc_bits
    t0 = time.perf_counter()
    payloads = random_payloads(samples, spec.payload_bits, np.random.default_rng(seed))
    codes = codec.encode(payloads)
    probs = read_renders(model, codes, "medium", seed)
    seconds_read = time.perf_counter() - t0

    def by_codec(p: np.ndarray) -> np.ndarray | None:
        result = codec.decode(p)
        return result.payload if result.ok else None

    ml = BudgetedML(codec, bound)
    rng = np.random.default_rng(seed + 2)
    rows = rng.integers(0, samples, garbage)
    sides = rng.integers(0, 2, (garbage, spec.code_bits)).astype(bool)
    junk = np.where(sides, probs[rows], 1 - probs[rows])  # the same reliabilities, random sides
    nobody = np.full((garbage, spec.payload_bits), 2, np.uint8)  # matches no payload: every accept is false
    out: dict[str, Any] = {
        "bundle": path.name,
        "payload_bits": spec.payload_bits,
        "code_bits": spec.code_bits,
        "check_bits": ml.check_bits,
        "budget": ml.budget,
        "bound": bound,
        "samples": samples,
        "garbage": garbage,
        "bit_accuracy": float(((probs > 0.5) == (codes == 1)).mean()),
        "seconds_reading": round(seconds_read, 1),
    }
    for name, decode in (("codec", by_codec), ("ml", ml.decode)):
        t0 = time.perf_counter()
        read, wrong = score(decode, probs, payloads)
        _, accepts = score(decode, junk, nobody)
        out[name] = {
            "read": read,
            "wrong": wrong,
            "false_accepts": accepts,
            "ms_per_read": round(1000 * (time.perf_counter() - t0) / (samples + garbage), 3),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", nargs="+", type=Path)
    ap.add_argument("--samples", type=int, default=2000, help="fresh payloads per bundle")
    ap.add_argument("--garbage", type=int, default=10000, help="reads with random sides per bundle")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=RESULTS / "decoding.json")
    args = ap.parse_args()
    set_threads(args.threads)
    results = []
    for path in args.bundles:
        r = measure(path, args.samples, args.garbage, args.seed)
        results.append(r)
        print(f"{path.name}: {r['codec']['read']} / {r['ml']['read']} of {args.samples}", flush=True)
    headers = ["bundle", "payload", "code", "check", "R", "bit acc", "codec read %", "ML read %", "wrong",
               "codec FA", "ML FA", "bound"]  # fmt: skip
    rows = [
        [r["bundle"], r["payload_bits"], r["code_bits"], r["check_bits"], r["budget"],
         round(100 * r["bit_accuracy"], 2),
         round(100 * r["codec"]["read"] / r["samples"], 2), round(100 * r["ml"]["read"] / r["samples"], 2),
         f"{r['codec']['wrong']} / {r['ml']['wrong']}", f"{r['codec']['false_accepts']} / {r['garbage']}",
         f"{r['ml']['false_accepts']} / {r['garbage']}", f"{r['bound']:.2%}"]
        for r in results
    ]  # fmt: skip
    print(table(headers, rows))
    write_json(args.out, {"environment": environment(), "samples": args.samples, "results": results})


if __name__ == "__main__":
    main()
