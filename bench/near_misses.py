"""How safe is the payload check, and how much could a looser one read? Near misses as stand-ins for CRC collisions.

A wrong payload needs two things: the decoder misreads so many bits that the error-correcting code
lands on another code word, and that word's CRC passes by chance (one in ``2**crc_bits``). The
second is independent of the photo, so the first can be studied on its own: decoded with the CRC
set aside, every misread close-up gives a *near miss*, a wrong code word exactly like the wrong
payloads the chain could give, about 256 times as often as they happen. Each near miss is asked
the payload check (``PayloadChecker.check``) as if its CRC had passed: as the code word the
correction reached, CRC bits as read (:func:`colliding`), and so is each right word.

One or more bundles; ``--samples`` close-ups of fresh payloads each
(``deepmorph_detect.photo_validation.close_ups``, the print about ``--width`` camera pixels
wide), 1 thread. At each close-up the photo chain reads as it does (the bundle's detector, else
the universal one); at the first drawing it aligned, the two first looks (the view as it is, and
framed by the template's ink) are decoded CRC-blind, and each word they give is checked there.
The table: close-ups, read by the chain; right words (the printed code word reached) checked and
withdrawn; near misses (a wrong payload), per close-up, and passed by the check; words that reached
the printed payload with other CRC bits (the real CRC refuses them; checked as collisions, they are
near misses whose payload is right), and passed; right words and near misses passed on a few of their bits
(``PayloadChecker.screens``); the wrong payloads per 10,000 close-ups that rate gives from
these looks (passed near misses x ``2**-crc_bits``); and, with the three bit bars loosened one
notch (``synthesis.MAX_CONTRADICTED`` + 1, ``MIN_WEAKEST_SUM`` down to 0, ``MAX_DEVIATION`` x 1.5,
the rival rule still asked), the right words and near misses that would pass besides. The JSON
keeps every word with its evidence.

    .venv/bin/python bench/near_misses.py reading.dmm pink-heart.dmm --severity hard --samples 600 --seed 41
"""

from __future__ import annotations

import argparse
import copy
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, add_close_up_options, environment, set_threads, table, write_json  # noqa: E402

LOOKS = ("as it is", "framed by the template")
# the bit bars loosened one notch (deepmorph_detect/synthesis.py's MAX_CONTRADICTED, MIN_WEAKEST_SUM, MAX_DEVIATION)
LOOSER_CONTRADICTED, LOOSER_WEAKEST_SUM, LOOSER_DEVIATION_FACTOR = 1, 0.0, 1.5


def crc_blind(codec: Any) -> Any:
    """A copy of ``codec`` whose CRC passes every word: it returns the code word the error
    correction reaches (the first the soft search finds), right or wrong, and keeps that word
    (its payload and CRC bits as read, before whitening) in ``reached``."""
    blind = copy.copy(codec)
    blind.reached = None

    def passes(word: Any) -> bool:
        if blind.reached is None:  # the first word asked is the one returned; rivals follow
            blind.reached = word.copy()
        return True

    def decode(probs: Any, soft: bool = True) -> Any:
        blind.reached = None
        return type(codec).decode(blind, probs, soft)

    blind._accepts = passes  # noqa: SLF001 - the one check this copy sets aside
    blind.decode = decode
    return blind


@contextmanager
def colliding(codec: Any, reached: Any) -> Iterator[None]:
    """``codec`` with the CRC bits of ``reached`` (a code word :func:`crc_blind` reached) taken
    as its payload's CRC: the collision a wrong payload needs. The word is then encoded, drawn
    and checked as the code word the correction reached. Re-encoded with its true CRC instead,
    a near miss would also differ from what the decoder read in about half its CRC and parity
    bits, which the photo contradicts and which no real collision has."""
    import numpy as np

    p, crc_bits = codec.spec.payload_bits, codec.spec.crc_bits
    payload, crc = reached[:p].copy(), reached[p : p + crc_bits].copy()
    own = codec._crc_bits_of  # noqa: SLF001

    def crc_of(bits: Any) -> Any:
        return crc.copy() if np.array_equal(bits, payload) else own(bits)

    codec._crc_bits_of = crc_of  # noqa: SLF001
    try:
        yield
    finally:
        del codec._crc_bits_of  # noqa: SLF001 - the class's own again


def word_record(locator: Any, aligned: Any, reading: Any, blind: Any, truth: Any) -> dict[str, Any] | None:
    """The word ``reading`` decodes to CRC-blind at ``aligned``, checked as if its CRC had passed
    (:func:`colliding`), with its per-bit evidence; ``None`` where the code reaches no word."""
    word = blind.decode(reading.probabilities, soft=True)
    if word.corrected_bits < 0:
        return None
    printed = locator.model.codec.encode(truth)  # outside the collision: the true CRC's code word
    with colliding(locator.model.codec, blind.reached):
        return _checked(locator, aligned, reading, word, truth, printed)


def _checked(locator: Any, aligned: Any, reading: Any, word: Any, truth: Any, printed: Any) -> dict[str, Any]:
    """:func:`word_record` of the decoded ``word``, its CRC passing; ``truth`` is the printed
    payload and ``printed`` its code word. A word is right where the correction reached the
    printed code word; one that reached the printed payload with other CRC bits is a near miss
    whose payload is right (the real CRC refuses it, and were it to collide, the payload told
    would still be right)."""
    import numpy as np

    from deepmorph_core.codec import DecodeResult
    from deepmorph_detect.check import DRAWING_LIKE_ALIGNMENT
    from deepmorph_detect.synthesis import broken_rules

    codec, checker = locator.model.codec, locator.checker
    code = codec.encode(word.payload)
    read_as = np.asarray(reading.probabilities) > 0.5
    if np.count_nonzero(code != read_as) != word.corrected_bits:
        raise AssertionError("the word checked is not the code word the correction reached")
    log_odds = codec.rival_log_odds(code, reading.probabilities) if word.corrected_bits else 0.0
    asked = DecodeResult(word.payload, True, word.corrected_bits, word.confidence, log_odds)
    pyramid, alignment = aligned.pyramid, aligned.alignment
    verdict = checker.check(pyramid, alignment.homography, asked, alignment, None, aligned.candidate.blind,
                            probabilities=reading.probabilities)  # fmt: skip
    record: dict[str, Any] = {
        **labels(code, word.payload, printed, truth),
        "payload": word.payload.tobytes().hex(),
        "code": code.tobytes().hex(),
        "corrected_bits": int(word.corrected_bits),
        "confidence": round(float(word.confidence), 5),
        "status": verdict.status,
        "screened": verdict.screened,
        "looser": False,
    }
    fit = checker.fit_morph(pyramid, alignment.homography, word.payload, alignment)
    if fit is None or not checker.morph_fits(fit, asked):
        return record
    in_colour = fit.unmorphed_correlation >= DRAWING_LIKE_ALIGNMENT
    bits = checker.synthesis.evidence(pyramid, fit.homography, code, in_colour, True, 0)
    rival = checker.rival_deviation(pyramid, alignment.homography, bits, fit.unmorphed_correlation, 0)
    record.update(
        morph_gain=round(float(fit.gain), 5),
        contradicted=bits.contradicted,
        weakest_sum=round(bits.weakest_sum, 3),
        deviation=round(bits.deviation, 3),
        rival_deviation=None if rival is None else round(rival, 3),
        broken=list(broken_rules(bits.contradicted, bits.weakest_sum, bits.deviation, rival)),
    )
    record["looser"] = looser_passes(record)
    return record


def labels(code: Any, payload: Any, printed: Any, truth: Any) -> dict[str, bool]:
    """Whether a word (its ``code`` word and ``payload``) is ``right``, the printed code word
    ``printed``, and whether its payload is ``truth``, the printed payload (``right_payload``)."""
    import numpy as np

    return {"right": bool(np.array_equal(code, printed)), "right_payload": bool(np.array_equal(payload, truth))}


def looser_passes(record: dict[str, Any]) -> bool:
    """Whether a word whose morph fits would pass with the three bit bars loosened one notch
    (the rival rule asked as it is)."""
    from deepmorph_detect.synthesis import MAX_CONTRADICTED, MAX_DEVIATION

    return (
        record["contradicted"] <= MAX_CONTRADICTED + LOOSER_CONTRADICTED
        and record["weakest_sum"] >= LOOSER_WEAKEST_SUM
        and record["deviation"] <= MAX_DEVIATION * LOOSER_DEVIATION_FACTOR
        and (record["rival_deviation"] is None or record["rival_deviation"] >= record["deviation"])
    )


def measure(bundle: Path, args: argparse.Namespace) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """One bundle's summary row and its word records."""
    import numpy as np

    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.photo_validation import close_ups

    model = DeepMorphModel.load(bundle)
    locator = Locator(model)
    blind = crc_blind(model.codec)
    words: list[dict[str, Any]] = []
    read = 0
    for index, shot in enumerate(close_ups(model, args.samples, args.seed, args.severity, args.width)):
        found = locator.locate(shot.photo)
        read += any(f.result.ok and np.array_equal(f.result.payload, shot.payload) for f in found)
        aligned = locator.alignments(shot.photo)
        if not aligned:
            continue
        first = aligned[0]
        gray = locator.frame(shot.photo, None)[0]
        view = locator._views(gray, first.pyramid, first.alignment.homography, first.candidate.source)[0]  # noqa: SLF001
        seen: set[str] = set()
        looks = (locator.reader.read(view, True), locator.reader.read_framed_by_template(view, True))
        for look, reading in zip(LOOKS, looks):
            record = None if reading is None else word_record(locator, first, reading, blind, shot.payload)
            if record is None or record["code"] in seen:
                continue
            seen.add(record["code"])
            words.append({"close_up": index, "look": look, **record})
    right = [w for w in words if w["right"]]
    near = [w for w in words if not w["right_payload"]]
    other_crc = [w for w in words if w["right_payload"] and not w["right"]]
    passed_near = sum(w["status"] == "passed" for w in near)
    row = {
        "bundle": bundle.stem,
        "close_ups": args.samples,
        "read": read,
        "right_words": len(right),
        "right_withdrawn": sum(w["status"] != "passed" for w in right),
        "near_misses": len(near),
        "near_per_close_up": round(len(near) / args.samples, 3),
        "near_passed": passed_near,
        "other_crc": len(other_crc),
        "other_crc_passed": sum(w["status"] == "passed" for w in other_crc),
        "right_screened": sum(w["screened"] for w in right),
        "near_screened": sum(w["screened"] for w in near),
        "wrong_per_10k": round(1e4 * passed_near / args.samples * 2.0**-model.codec.spec.crc_bits, 3),
        "looser_right_gained": sum(w["looser"] and w["status"] != "passed" for w in right),
        "looser_near_passed": sum(w["looser"] and w["status"] != "passed" for w in near),
    }
    return row, words


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", type=Path, nargs="+")
    add_close_up_options(ap, 600, 41, RESULTS / "near_misses.json")
    args = ap.parse_args()
    threads = set_threads(1)
    import cv2

    cv2.setNumThreads(1)
    rows, words = [], {}
    for bundle in args.bundles:
        row, words[bundle.stem] = measure(bundle, args)
        rows.append(row)
    columns = {"bundle": "bundle", "close_ups": "close-ups", "read": "read by the chain",
               "right_words": "right words", "right_withdrawn": "withdrawn", "near_misses": "near misses",
               "near_per_close_up": "per close-up", "near_passed": "passed",
               "other_crc": "right payload, other CRC bits", "other_crc_passed": "of them passed",
               "right_screened": "right passed on a few bits", "near_screened": "near passed on a few bits",
               "wrong_per_10k": "wrong per 10k close-ups", "looser_right_gained": "looser: right gained",
               "looser_near_passed": "near misses passed"}  # fmt: skip
    size = f", prints {args.width:g} px" if args.width else ""
    print(f"close-ups, {args.severity}{size}, seed {args.seed}, {threads} thread")
    print(table(list(columns.values()), [[row[k] for k in columns] for row in rows]))
    report = {"environment": environment(), "severity": args.severity, "width": args.width, "seed": args.seed,
              "summary": rows, "words": words}  # fmt: skip
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
