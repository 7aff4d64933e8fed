"""The scene benchmark's report as a plain-text table (``deepmorph bench-scenes``)."""

from __future__ import annotations

from typing import Any


def format_report(report: dict[str, Any]) -> str:
    """The report as a plain-text table."""
    p, s = report["pose"], report["speed_ms"]
    rows = [
        ("scenes", report["scenes"], "the first print read (--first)" if report.get("first") else ""),
        ("drawings / found (recall)", f"{report['drawings']} / {report['found']} ({report['recall']:.1%})", ""),
        ("precision", f"{report['precision']:.1%}", ""),
        ("whole-payload success", f"{report['payload_success']:.1%}", ""),
        ("wrong payloads reported ok", report["wrong_ok"], f"over {report['scenes']} images"),
        ("", "DeepMorph", "ArUco 6x6"),
        ("found", report["found"], f"{report['aruco_found']}/{report['aruco_markers']}"),
        ("rotation error, median (deg)", p["deepmorph"]["rotation_deg_median"], p["aruco"]["rotation_deg_median"]),
        (
            "translation error, median (rel)",
            p["deepmorph"]["translation_rel_median"],
            p["aruco"]["translation_rel_median"],
        ),
        ("corner error, median (px)", p["deepmorph"]["corner_px_median"], p["aruco"]["corner_px_median"]),
        ("time per frame, median (ms)", s["deepmorph_locate_decode_median"], s["aruco_detect_median"]),
        ("time per frame, mean (ms)", s["deepmorph_locate_decode_mean"], ""),
        ("QR detectAndDecode (ms)", s["qr_detect_and_decode_median"], ""),
    ]
    width = max(len(r[0]) for r in rows)
    return "\n".join(f"{a:<{width}}  {b!s:>20}  {c!s:>16}" for a, b, c in rows)


__all__ = ["format_report"]
