"""Every word that passed the CRC, with its truth: what the per-bit check was spared and what it caught.

One bundle, ``--samples`` photos read by the photo chain (the bundle's detector, else the shipped
universal one), 1 thread: close-ups of fresh payloads with the print about ``--width`` camera
pixels wide (``deepmorph_detect.photo_validation.close_ups``), or ``--frame WxH`` scenes with one
print, another drawing and an ArUco marker, or ``--unrelated`` images that show none of the
drawing (other icons from ``--icons``, clutter, noise). Every payload that passed the CRC and
reached the payload check is recorded with whether it is the photo's payload: its corrections,
confidence, how much the decoder's probabilities prefer it to its nearest rival code word (total
log-odds, ``DecodeResult.rival_log_odds``, computed here for every word), its morph's fit, and
the verdict (passed with or without the per-bit check, or withdrawn).

``--crc-checked K`` reads as training's count of wrong payloads does
(``deepmorph_detect.photo_validation.count_wrong_payloads``): the CRC checked on its first K bits
only, so that wrong words reach the payload check ``2**(crc_bits - K)`` times as often. In
close-ups, where the simulator's pose is known, each wrong word the check passed is asked again
there: whether its bits, and the printed word's, agree with the photo at the pose, each refined
to its own morph; and how far the alignment it passed at was from that pose (the mean distance
of the drawing's corners, a share of the print's width), beside the right words'.

The table: photos read, photos that gave a wrong payload, wrong words that reached the check
with their highest log-odds and confidence, wrong words the check passed, right words passed
without the per-bit check although the code corrected them
(``PayloadChecker.vouches_for_repair``), and right and wrong words passed on a few of their bits
(``PayloadChecker.screens``). The JSON keeps every record.

    .venv/bin/python bench/repair_trust.py model.dmm --severity hard --width 240 --samples 5000 --seed 41
    .venv/bin/python bench/repair_trust.py model.dmm --severity hard --frame 1280x720 --samples 400
    .venv/bin/python bench/repair_trust.py model.dmm --unrelated --icons ../shared/data/drawings/feather
    .venv/bin/python bench/repair_trust.py model.dmm --crc-checked 4 --samples 300 --seed 4217
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import (  # noqa: E402
    RESULTS,
    add_close_up_options,
    environment,
    frame_size,
    pose_error,
    set_threads,
    table,
    write_json,
)

NOT_A_PAYLOAD = 2  # a bit value no payload has: the truth of an unrelated image


def photos(args: argparse.Namespace, model: Any) -> Iterator[tuple[Any, Any, Any, Any]]:
    """``(image, camera or None, true payload, close-up or None)`` for each photo asked."""
    import numpy as np

    if args.unrelated:
        from capacity import unrelated_images

        nothing = np.full(model.codec.spec.payload_bits, NOT_A_PAYLOAD, dtype=np.uint8)
        for _, image in unrelated_images(args.samples, args.icons, {model.meta.drawing_name}, args.seed):
            yield image, None, nothing, None
    elif args.frame is not None:
        from deepmorph_detect.scenes import SceneMaker

        maker = SceneMaker(model, args.frame, args.severity, seed=args.seed)
        for _ in range(args.samples):
            scene = maker.make(drawings=1, distractors=1, aruco=True)
            (truth,) = [p for p in scene.placements if p.kind == "drawing"]
            yield scene.image, scene.camera, truth.payload, None
    else:
        from deepmorph_detect.photo_validation import close_ups

        for shot in close_ups(model, args.samples, args.seed, args.severity, args.width):
            yield shot.photo, None, shot.payload, shot


def agrees_at_pose(checker: Any, pyramid: Any, code: Any, pose: Any) -> bool | None:
    """Whether the photo's bits (``pyramid``: the close-up as it is, not relit as the chain may
    have asked) agree with the code word ``code`` at the simulator's ``pose``, refined to
    ``code``'s morph (``None``: the alignment diverged)."""
    from deepmorph_detect.check import MORPH_WIDTH
    from deepmorph_detect.refine import refine_at

    aligned = refine_at(pyramid, pose, checker.morphs.of_code(code), MORPH_WIDTH)
    return None if aligned is None else checker.synthesis.evidence(pyramid, aligned.homography, code).agrees


def recorded(locator: Any, records: list[dict[str, Any]], photo: dict[str, Any]) -> None:
    """Wrap ``locator``'s payload check (and its reader's looks, for the probabilities read) so
    that each verdict is appended to ``records`` with ``photo``'s index and truth; a word passed
    in a close-up (``photo["shot"]``) also with how far its alignment was from the simulator's
    pose (``pose_error``), and a wrong one with whether its bits and the printed word's agree at
    the pose (:func:`agrees_at_pose`)."""
    import numpy as np

    codec = locator.model.codec
    checker, reader = locator.checker, locator.reader
    verdict, looks = checker._verdict, reader.looks
    read: dict[str, Any] = {}

    def looks_noting(*args: Any, **kwargs: Any) -> Iterator[Any]:
        for reading, bitwise in looks(*args, **kwargs):
            read["probabilities"] = reading.probabilities
            yield reading, bitwise

    def verdict_noting(pyramid: Any, homography: Any, result: Any, *rest: Any, **keywords: Any) -> Any:
        out = verdict(pyramid, homography, result, *rest, **keywords)
        # rest: unmorphed, bitwise, blind, whole_frame, relit_from and (a cast shadow's retry) light_grid
        light_grid = rest[5] if len(rest) > 5 else keywords.get("light_grid", 0)
        code = codec.encode(np.asarray(result.payload, dtype=np.uint8))
        right = bool(np.array_equal(result.payload, photo["truth"]))
        shot = photo.get("shot")
        posed: dict[str, Any] = {}
        if shot is not None and out.status == "passed":
            posed["alignment_error"] = round(
                pose_error(checker.template.viewbox, out.fit.homography, shot.homography), 4
            )
            if not right:
                as_it_is = checker.pyramid(shot.photo)
                posed["agrees_at_pose"] = agrees_at_pose(checker, as_it_is, code, shot.homography)
                posed["printed_agrees_at_pose"] = agrees_at_pose(checker, as_it_is, shot.code, shot.homography)
        records.append(
            {
                "photo": photo["index"],
                "right": right,
                "corrected_bits": int(result.corrected_bits),
                "confidence": round(float(result.confidence), 5),
                "rival_log_odds": round(codec.rival_log_odds(code, read["probabilities"]), 3),
                "morph_fit": None if out.fit is None else round(float(out.fit.correlation), 4),
                "light_grid": int(light_grid),
                "relit": (rest[4] if len(rest) > 4 else keywords.get("relit_from")) is not None,
                "status": out.status,
                "bit_by_bit": out.bits is not None,
                "screened": out.screened,
                **posed,
            }
        )
        return out

    checker._verdict, reader.looks = verdict_noting, looks_noting


def summary(records: list[dict[str, Any]], read: int, wrong_payloads: int, samples: int) -> dict[str, Any]:
    """The table's row: the first verdict on each word (not its retries in a cast shadow's light),
    and the photos whose chain gave a wrong payload (a word that passed its check can still be
    withdrawn later, by a reading at another turn)."""
    first = [r for r in records if r["light_grid"] == 0]
    wrong = [r for r in first if not r["right"]]
    spared = [r for r in first if r["right"] and r["corrected_bits"] > 0 and r["status"] == "passed"]
    return {
        "photos": samples,
        "read": read,
        "wrong_payloads": wrong_payloads,
        "words_checked": len(first),
        "wrong_words": len(wrong),
        "wrong_max_log_odds": max((r["rival_log_odds"] for r in wrong), default=None),
        "wrong_max_confidence": max((r["confidence"] for r in wrong), default=None),
        "wrong_passed": sum(1 for r in records if not r["right"] and r["status"] == "passed"),
        "repaired_right_passed": len(spared),
        "repaired_right_spared": sum(1 for r in spared if not r["bit_by_bit"] and not r["screened"]),
        "right_screened": sum(1 for r in first if r["right"] and r["screened"]),
        "wrong_screened": sum(1 for r in first if not r["right"] and r["screened"]),
        **posed_summary(records),
    }


def posed_summary(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Of the wrong words passed that were asked at the simulator's pose (:func:`agrees_at_pose`):
    how many, how many the photo contradicts there, how many the printed word agrees with there,
    and their alignments' median distance from it (``pose_error``), beside the right
    words passed."""
    import numpy as np

    posed = [r for r in records if "agrees_at_pose" in r]
    right = [r["alignment_error"] for r in records if r["right"] and "alignment_error" in r]
    if not posed:
        return {}
    return {
        "wrong_passed_posed": len(posed),
        "contradicted_at_pose": sum(1 for r in posed if r["agrees_at_pose"] is False),
        "printed_agrees_at_pose": sum(1 for r in posed if r["printed_agrees_at_pose"]),
        "median_alignment_error": round(float(np.median([r["alignment_error"] for r in posed])), 4),
        "right_median_alignment_error": round(float(np.median(right)), 4) if right else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundle", type=Path)
    add_close_up_options(ap, 1000, 0, RESULTS / "repair_trust.json")
    ap.add_argument("--frame", type=frame_size, default=None, help="scenes of this size, WxH, instead of close-ups")
    ap.add_argument("--unrelated", action="store_true", help="images that show none of the drawing instead")
    ap.add_argument("--icons", type=Path, default=None, help="other drawings for --unrelated")
    ap.add_argument(
        "--crc-checked", type=int, default=None, help="check only the CRC's first K bits, as the count does"
    )
    args = ap.parse_args()
    threads = set_threads(1)
    import cv2
    import numpy as np

    from deepmorph_core.errors import DeepMorphError
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator

    cv2.setNumThreads(1)
    model = DeepMorphModel.load(args.bundle)
    if args.crc_checked is not None:
        try:
            model = replace(model, codec=model.codec.narrowed(args.crc_checked))
        except DeepMorphError as exc:
            ap.error(f"--crc-checked: {exc}")
    locator = Locator(model)
    records: list[dict[str, Any]] = []
    photo: dict[str, Any] = {}
    recorded(locator, records, photo)
    read = wrong_payloads = 0
    for index, (image, camera, truth, shot) in enumerate(photos(args, model)):
        photo.update(index=index, truth=truth, shot=shot)
        model.codec.forget()
        found = locator.locate(image, camera) if camera is not None else locator.locate(image)
        read += any(f.result.ok and np.array_equal(f.result.payload, truth) for f in found)
        wrong_payloads += any(f.result.ok and not np.array_equal(f.result.payload, truth) for f in found)
    kind = "unrelated" if args.unrelated else f"scenes {args.frame[0]}x{args.frame[1]}" if args.frame else "close-ups"
    size = "" if args.unrelated or args.frame else f" {args.width:g} px" if args.width else ""
    row = summary(records, read, wrong_payloads, args.samples)
    columns = {"photos": "photos", "read": "read", "wrong_payloads": "wrong payloads",
               "words_checked": "words checked", "wrong_words": "wrong words",
               "wrong_max_log_odds": "their max log-odds", "wrong_max_confidence": "their max confidence",
               "wrong_passed": "wrong passed", "repaired_right_passed": "right repaired passed",
               "repaired_right_spared": "of them spared the bits", "right_screened": "right passed on a few bits",
               "wrong_screened": "wrong passed on a few bits", "wrong_passed_posed": "wrong passed asked at the pose",
               "contradicted_at_pose": "contradicted there", "printed_agrees_at_pose": "printed word agrees there",
               "median_alignment_error": "their alignments off (median)",
               "right_median_alignment_error": "right words' alignments off (median)"}  # fmt: skip
    print(f"{kind}{size}, {'' if args.unrelated else args.severity + ', '}seed {args.seed}, {threads} thread")
    shown = {k: v for k, v in columns.items() if k in row}
    print(table(["bundle", *shown.values()], [[args.bundle.stem, *(row[k] for k in shown)]]))
    report = {
        "environment": environment(),
        "bundle": str(args.bundle),
        "kind": kind,
        "severity": args.severity,
        "width": args.width,
        "seed": args.seed,
        "crc_checked": args.crc_checked,
        "summary": row,
        "records": records,
    }
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
