"""The nearest rival of a long payload's code word, searched by BCH decoding and by syndromes.

Above 16 payload bits :meth:`PayloadCodec.nearest_rival
<deepmorph_core.codec.PayloadCodec.nearest_rival>` flips every subset of the 10 least supported
bits and takes each flip to the code word within ``t`` bits of it: by BCH decoding each flip
(bchlib, one call per flip), or by looking each flip's syndrome up among every correction's
(codes correcting up to 2 bits). For each code: ``--draws`` code words with support drawn as a
photo's evidence (about +1, noise of 0.3-1.5, half of them with a near word's bits shown weakly
flipped), both searches timed on the same draws, and whether they found the same word.

    .venv/bin/python bench/rival_search.py
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

#: (payload bits, CRC bits, BCH t): the bundled ghost's code, the colour panel's longest, and
#: longer ones with stronger codes
CODES = ((24, 8, 1), (29, 8, 1), (24, 8, 2), (32, 16, 1), (40, 16, 2), (64, 16, 2))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=100, help="code words per code")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--out", type=Path, default=RESULTS / "rival_search.json")
    args = p.parse_args(argv)
    set_threads(args.threads)
    from deepmorph_core.codec import RIVAL_SEARCH_BITS, PayloadCodec, choose_codec

    rng = np.random.default_rng(args.seed)
    rows = []
    for payload_bits, crc_bits, bch_t in CODES:
        codec = PayloadCodec(choose_codec(payload_bits, crc_bits=crc_bits, bch_t=bch_t))
        n = codec.spec.code_bits
        codec._check_columns(), codec._corrections()  # the tables, built once per codec
        times = {"bch": [], "syndrome": []}
        same = found = 0
        for draw in range(args.draws):
            word = codec.encode(rng.integers(0, 2, payload_bits).astype(np.uint8))
            shown = rng.normal(1.0, (0.3, 0.8, 1.5)[draw % 3], n)
            if draw % 2:
                near = codec.encode(rng.integers(0, 2, payload_bits).astype(np.uint8))
                shown = np.where(near == word, shown, 0.2 * shown - 0.2)
            searched = np.argsort(shown, kind="stable")[:RIVAL_SEARCH_BITS]
            start = time.perf_counter()
            by_bch = codec._nearest_by_bch(word, shown, searched)
            times["bch"].append(time.perf_counter() - start)
            start = time.perf_counter()
            by_syndrome = codec._nearest_by_syndrome(word, shown, searched)
            times["syndrome"].append(time.perf_counter() - start)
            found += by_bch is not None
            same += (by_bch is None and by_syndrome is None) or (
                by_bch is not None and by_syndrome is not None and np.array_equal(by_bch[1], by_syndrome[1])
            )
        bch_ms, syndrome_ms = (1e3 * float(np.median(times[k])) for k in ("bch", "syndrome"))
        rows.append({"payload_bits": payload_bits, "crc_bits": crc_bits, "bch_t": bch_t, "code_bits": n,
                     "draws": args.draws, "rivals_found": found, "same": same,
                     "bch_ms": round(bch_ms, 2), "syndrome_ms": round(syndrome_ms, 3),
                     "speedup": round(bch_ms / syndrome_ms, 1)})  # fmt: skip
    headers = ["payload", "CRC", "t", "code bits", "rivals found", "same word", "BCH ms", "syndromes ms", "×"]
    print(f"Nearest rival of {args.draws} code words per code, median time, {environment()['threads']} thread(s):")
    body = [
        [r["payload_bits"], r["crc_bits"], r["bch_t"], r["code_bits"], r["rivals_found"], f"{r['same']}/{r['draws']}",
         r["bch_ms"], r["syndrome_ms"], r["speedup"]]
        for r in rows
    ]  # fmt: skip
    print(table(headers, body))
    write_json(args.out, {"benchmark": "rival_search", "environment": environment(), "rows": rows})
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
