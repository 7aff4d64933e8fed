"""Wrong payloads in photos, with the print-size rule and without it: what the rule stops, what it costs.

A colour drawing's reading that needed corrections is refused where the print is narrower than
the decoder's frame along any direction (``locate.refuses_narrow_reading``: its width head-on,
and along its tilt), and the chain looks on for a reading without corrections there
(``Locator.keeps_only_uncorrected``). Here every model reads ``--scenes`` photos made from one
seed (640x480 by default, one or two payload morphs, another drawing, an ArUco marker in every
other scene: the scenes of ``bench/universal_detector.py``) with the shipped universal detector,
twice: as shipped, and with the size rule switched off so that every reading is seen. Each
reading that passed every check is put against the truth, and counted under four rules:

* **none**: every reading of the chain without the rule kept;
* **head-on**: of those, the ones a rule counting only the print's head-on width keeps (the rule
  before it asked the tilt);
* **every way**: of those, the ones the shipped rule keeps, without looking on;
* **as shipped**: what the chain as shipped reads.

For each, the right and wrong payloads kept. A wrong payload is one reported ``ok`` that is not
the payload of the print it was found on (or found on no print). Each reading's widths,
corrections and check figures go to the JSON, so another rule can be weighed on the same reads,
with the photo the shipped chain read it in (:data:`READ_IN`). ``--shipped-only`` reads each
scene once, as shipped, and counts the payloads read in the light the print's template shows
apart.

    .venv/bin/python bench/size_rule_trust.py bench/results/colour_models/*.dmm --scenes 1000 --seed 7
    .venv/bin/python bench/size_rule_trust.py bench/results/colour_models/*.dmm --seed 11 --shipped-only
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, frame_size, set_threads, table, write_json  # noqa: E402

RULES = ("none", "head-on", "every way", "as shipped")
#: where the shipped chain read a payload (``Locator.decode_drawing``): the photo itself, the photo
#: lit by the template's light, a grid of light, or the first looks alone (a print too narrow)
READ_IN = ("photo", "template's light", "grid of light", "first looks")


def traced(locator: Any) -> list[tuple[str, bytes]]:
    """Record where ``locator`` reads each payload: every ``_decode_at`` that passed appends the
    photo it read in (:data:`READ_IN`) and the payload's bytes to the list returned."""
    import inspect

    import numpy as np

    calls: list[tuple[str, bytes]] = []
    decode_at = locator._decode_at
    signature = inspect.signature(decode_at)

    def recorded(*args: Any, **kwargs: Any) -> Any:
        located = decode_at(*args, **kwargs)
        asked = signature.bind(*args, **kwargs).arguments
        where = (
            READ_IN[1] if asked.get("relit_from") is not None
            else READ_IN[2] if asked.get("in_shadow")
            else READ_IN[3] if asked.get("first_looks_only")
            else READ_IN[0]
        )  # fmt: skip
        if located.result.ok:
            calls.append((where, np.asarray(located.result.payload, np.uint8).tobytes()))
        return located

    locator._decode_at = recorded
    return calls


def readings(
    model_path: Path, scenes: int, seed: int, severity: str, frame: tuple[int, int], free_too: bool = True
) -> list[dict[str, Any]]:
    """Every reading of ``model_path``'s prints that passed every check in ``scenes`` photos, by
    the chain without the size rule (``chain``: "free"; unless not ``free_too``) and as shipped
    ("shipped")."""
    from dataclasses import replace

    import numpy as np

    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.locate import Locator, refuses_narrow_reading
    from deepmorph_detect.metrics import matched_detections
    from deepmorph_detect.scenes import SceneMaker

    model = DeepMorphModel.load(model_path)
    shipped = Locator(model, detector="universal")
    read_in = traced(shipped)
    chains: list[tuple[str, Any]] = [("shipped", shipped)]
    if free_too:
        free = Locator(model, detector="universal")
        free.refuses_reading = lambda located: False  # every reading seen; the rules asked below
        free.keeps_only_uncorrected = lambda homography: False
        if model.print_px is None:  # nor a colour print under the floor read by its first looks alone
            free.aligned_too_narrow = lambda alignment: False
        chains.insert(0, ("free", free))
    trained_px, colour = model.print_px, model.drawing.colour
    maker = SceneMaker(model, frame, severity, seed=seed)
    rows = []
    for i in range(scenes):
        scene = maker.make(drawings=1 + i % 2, distractors=1, aruco=i % 2 == 0)
        drawings = [p for p in scene.placements if p.kind == "drawing"]
        for chain, locator in chains:
            read_in.clear()
            for det, _, right in matched_detections(locator.locate(scene.image), drawings):
                if not det.result.ok:
                    continue
                bits = det.bits
                payload = np.asarray(det.result.payload, np.uint8).tobytes()
                where = next((w for w, p in reversed(read_in) if p == payload), None)
                rows.append({
                    "scene": i,
                    "chain": chain,
                    "right": bool(right),
                    "width_px": round(float(det.width_px), 1),
                    "along_tilt_px": round(float(det.along_tilt_px), 1),
                    "corrected": int(det.result.corrected_bits),
                    "confidence": round(float(det.result.confidence), 4),
                    "morph_gain": None if det.morph is None else round(float(det.morph.gain), 5),
                    "deviation": None if bits is None else round(float(bits.deviation), 3),
                    "read_in": where,
                    "kept": {
                        "none": True,
                        "head-on": not refused_head_on(replace(det, needs_every_way=False), trained_px, colour),
                        "every way": not refuses_narrow_reading(det, trained_px, colour),
                    },
                })  # fmt: skip
    return rows


def refused_head_on(located: Any, trained_px: int | None, colour: bool) -> bool:
    """The size rule before it asked the tilt: a reading of a print narrower head-on than its
    model needs refused where the model was trained for a width, or is in colour and the
    reading needed corrections; no floor."""
    if not (located.result.ok and located.too_narrow):
        return False
    return trained_px is not None or (colour and located.result.corrected_bits > 0)


def counted(rows: list[dict[str, Any]], rule: str) -> dict[str, int]:
    """Right and wrong payloads kept under ``rule`` (:data:`RULES`)."""
    if rule == "as shipped":
        return _right_and_wrong([r for r in rows if r["chain"] == "shipped"])
    return _right_and_wrong([r for r in rows if r["chain"] == "free" and r["kept"][rule]])


def counted_in(rows: list[dict[str, Any]], where: str) -> dict[str, int]:
    """Right and wrong payloads the shipped chain read in the photo ``where`` (:data:`READ_IN`)."""
    return _right_and_wrong([r for r in rows if r["chain"] == "shipped" and r["read_in"] == where])


def _right_and_wrong(kept: list[dict[str, Any]]) -> dict[str, int]:
    """How many of the readings ``kept`` are right and how many wrong."""
    return {"right": sum(r["right"] for r in kept), "wrong": sum(not r["right"] for r in kept)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+", type=Path, help="trained bundles (.dmm)")
    ap.add_argument("--scenes", type=int, default=1000, help="photos per model")
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--severity", default="hard")
    ap.add_argument("--frame", type=frame_size, default=(640, 480), help="the photos' size, WxH (640x480)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "size_rule_trust.json")
    ap.add_argument("--shipped-only", action="store_true", help="read each scene as shipped only")
    args = ap.parse_args()
    set_threads(args.threads)
    import cv2

    cv2.setNumThreads(args.threads)
    report: dict[str, Any] = {"environment": environment(), "scenes": args.scenes, "seed": args.seed,
                              "severity": args.severity, "frame": list(args.frame), "models": {}}  # fmt: skip
    lines = []
    rules = ("as shipped",) if args.shipped_only else RULES
    for path in args.models:
        t0 = time.perf_counter()
        rows = readings(path, args.scenes, args.seed, args.severity, args.frame, free_too=not args.shipped_only)
        counts = {rule: counted(rows, rule) for rule in rules}
        counts |= {f"read in {where}": counted_in(rows, where) for where in READ_IN}
        report["models"][path.stem] = {"counts": counts, "readings": rows, "wall_s": round(time.perf_counter() - t0)}
        lines.append([path.stem, *(f"{c['right']} / {c['wrong']}" for c in counts.values())])
        print(f"{path.stem}: {counts}", flush=True)
    print(table(["model", *(f"{name}: right / wrong" for name in counts)], lines))
    print(f"{args.scenes} {args.severity} scenes of {args.frame[0]}x{args.frame[1]} per model, seed {args.seed}, "
          f"universal detector, {args.threads} thread(s)")  # fmt: skip
    print(f"wrote {write_json(args.out, report)}")


if __name__ == "__main__":
    main()
