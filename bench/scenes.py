"""Scenes: the whole photo chain on synthetic scenes, side by side with ArUco and QR codes.

For each severity, ``--n`` labelled scenes (640x480, one payload morph, one ArUco marker of the
same printed size, and ``--distractors`` other drawings) are made by ``deepmorph synth``'s
generator and scored by ``deepmorph bench-scenes``'s code: detection recall and precision,
whole-payload success, pose error against the truth next to ArUco's on the same images,
and time per frame on ``--threads`` (default 1) next to ArUco detection and OpenCV's QR
detect-and-decode on same-size frames. Then ``--negatives`` scenes holding no drawing of the
model (other drawings, an ArUco marker, photos and clutter) count wrong payloads reported ok.
Last, the morph check's rejection rates for right, random and one-bit-off payloads on the
drawings found, frame fusion over ``--sequences`` hard 5-frame sequences, and ``--tracking``
10-frame videos per severity (medium, hard) of a moving camera, every frame searched against
drawings followed from frame to frame, with QR's time in the same run.

    .venv/bin/python bench/scenes.py --n 200 --negatives 1000
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, add_scene_options, environment, load_scene_model, table, write_json  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_scene_options(ap, n=200, out=RESULTS / "scenes.json")
    ap.add_argument("--distractors", type=int, default=1)
    ap.add_argument("--negatives", type=int, default=1000, help="scenes without the drawing")
    ap.add_argument("--sequences", type=int, default=50, help="hard 5-frame sequences for frame fusion")
    ap.add_argument("--tracking", type=int, default=12, help="moving 10-frame videos per severity (medium, hard)")
    args = ap.parse_args()
    model_path, model = load_scene_model(args)
    from deepmorph.measure.scene_bench import bench_scenes, morph_check_rates, tracking_rates
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.scene_folders import write_scenes
    from deepmorph_detect.scenes import SceneMaker

    reports = {}
    with tempfile.TemporaryDirectory() as tmp:
        for sev in args.severities.split(","):
            folder = Path(tmp) / sev
            t0 = time.perf_counter()
            write_scenes(model, folder, args.n, sev, args.seed, distractors=args.distractors, aruco=True)
            reports[sev] = bench_scenes(model, folder)
            reports[sev]["morph_check"] = morph_check_rates(model, folder, args.seed)
            print(f"{sev}: {args.n} scenes in {time.perf_counter() - t0:.0f} s", flush=True)
    # negatives: no drawing of the model, only other drawings, markers, photos and clutter
    locator = Locator(model)
    maker = SceneMaker(model, (640, 480), "medium", seed=args.seed + 1000)
    neg = {"images": args.negatives, "detections": 0, "wrong_ok": 0}
    for i in range(args.negatives):
        scene = maker.make(drawings=0, distractors=1 + i % 3, aruco=i % 2 == 0)
        dets = locator.locate(scene.image)
        neg["detections"] += len(dets)
        neg["wrong_ok"] += sum(bool(d.result.ok) for d in dets)

    # frame fusion: the same print filmed over 5 frames (fresh light, blur, noise, JPEG each)
    from deepmorph_detect.fusion import FrameFuser

    fmaker = SceneMaker(model, (640, 480), "hard", seed=args.seed + 2000)
    fusion = {"sequences": args.sequences, "frames": 0, "single_ok": 0, "fused_ok": 0, "fused_wrong_ok": 0}
    for _ in range(args.sequences):
        scene = fmaker.make(drawings=1, frames=5)
        truth = scene.placements[0].payload
        fuser = FrameFuser(model.codec, locator.check_payload, locator.refuses_reading)
        for k, frame in enumerate(scene.frames):
            dets = locator.locate(frame, camera=scene.camera)
            fusion["frames"] += 1
            fusion["single_ok"] += any(d.result.ok and (d.result.payload == truth).all() for d in dets)
            fuser.add(str(k), dets, frame)
        fused = fuser.results()
        right = "".join(map(str, truth))
        fusion["fused_ok"] += any(e["ok"] and e["payload"]["bits"] == right for e in fused)
        fusion["fused_wrong_ok"] += sum(e["ok"] and e["payload"]["bits"] != right for e in fused)

    tracking = (
        [tracking_rates(model, sev, args.tracking, seed=args.seed + 3000) for sev in ("medium", "hard")]
        if args.tracking
        else []
    )

    rows = []
    for sev, r in reports.items():
        d, a = r["pose"]["deepmorph"], r["pose"]["aruco"]
        rows.append(
            [sev, r["scenes"], f"{r['recall']:.1%}", f"{r['precision']:.1%}", f"{r['payload_success']:.1%}",
             r["wrong_ok"], d["rotation_deg_median"], a["rotation_deg_median"], d["translation_rel_median"],
             a["translation_rel_median"], d["corner_px_median"], a["corner_px_median"], f"{r['aruco_recall']:.1%}"]
        )  # fmt: skip
    print(table(["severity", "scenes", "recall", "precision", "payload ok", "wrong ok", "rot° ours", "rot° ArUco",
                 "trans ours", "trans ArUco", "corner px ours", "corner px ArUco", "ArUco found"], rows))  # fmt: skip
    speed = [[sev, r["speed_ms"]["deepmorph_locate_decode_median"], r["speed_ms"]["deepmorph_locate_decode_mean"],
              r["speed_ms"]["aruco_detect_median"],
              r["speed_ms"]["qr_detect_and_decode_median"],
              round(r["speed_ms"]["deepmorph_locate_decode_median"] / r["speed_ms"]["qr_detect_and_decode_median"], 2)]
             for sev, r in reports.items()]  # fmt: skip
    print()
    print(
        table(
            [
                "severity",
                f"ours ms median ({args.threads} thread)",
                "ours ms mean",
                "ArUco ms",
                "QR detect+decode ms",
                "ours median / QR",
            ],
            speed,
        )
    )
    checks = [[sev] + [f"{r['morph_check'][k]['rejected']}/{r['morph_check'][k]['n']}"
                       for k in ("right", "random", "one_bit_off")]
              + [f"{r['morph_check'][k]['rejected_with_bits']}/{r['morph_check'][k]['n']}"
                 for k in ("right", "random", "one_bit_off")] for sev, r in reports.items()]  # fmt: skip
    print()
    print(table(["checks reject", "right (morph)", "random (morph)", "one bit off (morph)",
                 "right (morph + bits)", "random (morph + bits)", "one bit off (morph + bits)"], checks))  # fmt: skip
    print(f"\nnegatives: {neg['images']} scenes without the drawing -> {neg['detections']} detections, "
          f"{neg['wrong_ok']} wrong payloads reported ok")  # fmt: skip
    if args.sequences:
        print(
            f"frame fusion (hard, 5 frames): single frames {fusion['single_ok'] / max(fusion['frames'], 1):.1%}, "
            f"fused sequences {fusion['fused_ok'] / args.sequences:.1%} ({fusion['fused_wrong_ok']} wrong ok)"
        )
    if tracking:
        rows = []
        for t in tracking:
            qr = t["qr_detect_and_decode_median"]
            for mode in ("every frame searched", "tracked"):
                r = t[mode]
                rows.append([t["severity"], mode, f"{r['read']}/{t['frames']}", r["wrong_ok"], r["corner_px_median"],
                             r["ms_median"], r["ms_mean"], qr, round(r["ms_mean"] / qr, 2)])  # fmt: skip
        print()
        print(table(["video (8 px shake)", "frames", "read", "wrong ok", "corner px", "ms median", "ms mean",
                     "QR ms", "mean / QR"], rows))  # fmt: skip
    out = {"environment": environment(), "model": str(model_path), "severities": reports, "negatives": neg}
    write_json(args.out, {**out, "fusion": fusion, "tracking": tracking})
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
