"""The report of ``deepmorph bench-photos``: a text summary, and a folder with ``report.html``
(summary, plots, one row per code), ``report.json`` and PNG plots of the codes read by printed
width, tilt and sharpness.

The plots need matplotlib, imported only here and only when a report is written; without it
the report holds the tables and a one-line note saying why there are no plots.
"""

from __future__ import annotations

import html
import io
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from deepmorph.measure.photo_bench import STATUSES
from deepmorph_core.fileio import atomic_write_all, output_folder

#: (file stem, key of a code's measure, title, fixed bin edges or None for quartiles)
PLOTS = (
    ("width", "width_px", "printed width (pixels)", (0, 40, 60, 80, 120, 160, 240, float("inf"))),
    ("tilt", "tilt_deg", "tilt to the camera (degrees)", (0, 10, 20, 30, 40, 50, 60, 90)),
    ("sharpness", "sharpness", "sharpness (variance of the Laplacian; higher is sharper)", None),
)
COLOURS = {"read": "#2e7d32", "wrong": "#c62828", "not verified": "#ef6c00", "missed": "#9e9e9e"}
NO_PLOTS = "No plots: they need matplotlib (pip install matplotlib); the tables below are complete."


def _label(lo: float, hi: float, fmt: Callable[[float], str]) -> str:
    if hi == float("inf"):
        return f"≥ {fmt(lo)}"
    return f"{fmt(lo)}–{fmt(hi)}"


def bins(values: list[float], edges: tuple[float, ...] | None) -> tuple[list[float], list[str]]:
    """Bin edges and their labels: ``edges`` when fixed, else the quartiles of ``values``."""
    if edges is None:
        qs = np.unique(np.quantile(np.asarray(values, dtype=np.float64), [0, 0.25, 0.5, 0.75, 1]))
        found = [float(v) for v in qs] if len(qs) > 1 else [float(qs[0]), float(qs[0]) + 1]
        found[-1] = float(np.nextafter(found[-1], np.inf))
        return found, [_label(a, b, lambda v: f"{v:.3g}") for a, b in zip(found, found[1:])]
    return list(edges), [_label(a, b, lambda v: f"{v:g}") for a, b in zip(edges, edges[1:])]


def binned(codes: list[dict[str, Any]], key: str, edges: tuple[float, ...] | None) -> list[dict[str, Any]]:
    """Per bin of ``key`` (bins holding no code left out): its label and each status's count."""
    measured = [c for c in codes if c.get(key) is not None]
    if not measured:
        return []
    limits, labels = bins([c[key] for c in measured], edges)
    rows = []
    for lo, hi, label in zip(limits, limits[1:], labels):
        inside = [c for c in measured if lo <= c[key] < hi]
        if inside:
            rows.append({"bin": label, **{s: sum(c["status"] == s for c in inside) for s in STATUSES}})
    return rows


def plot_png(rows: list[dict[str, Any]], title: str) -> bytes:
    """A stacked bar chart (PNG) of the codes per bin by status, with each bin's read rate."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=100)
    x = np.arange(len(rows))
    bottom = np.zeros(len(rows))
    for status in STATUSES:
        heights = np.array([r[status] for r in rows], dtype=float)
        ax.bar(x, heights, bottom=bottom, color=COLOURS[status], label=status, width=0.7)
        bottom += heights
    for i, r in enumerate(rows):
        total = sum(r[s] for s in STATUSES)
        ax.text(i, bottom[i], f"{r['read'] / total:.0%}", ha="center", va="bottom", fontsize=8)
    ax.set_xticks(x, [r["bin"] for r in rows], fontsize=8)
    ax.set_xlabel(title)
    ax.set_ylabel("codes")
    ax.set_ylim(0, max(bottom.max(), 1) * 1.18)
    ax.legend(fontsize=8, ncols=4, loc="upper left", frameon=False)
    ax.set_title(f"codes read by {title.split(' (')[0]} (read rate above each bar)", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()


def _fmt(value: Any, digits: int = 1) -> str:
    if value is None:
        return "–"
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def _stats_text(stats: dict[str, float] | None, unit: str, digits: int) -> str:
    if stats is None:
        return "–"
    median, mean, p90 = (f"{stats[k]:.{digits}f}" for k in ("median", "mean", "p90"))
    return f"median {median} {unit}, mean {mean}, 90th percentile {p90} (n = {stats['n']})"


def summary_rows(report: dict[str, Any]) -> list[tuple[str, str]]:
    """The summary as ``(what, value)`` rows (text and HTML share them)."""
    rate = report["read_rate"]
    rows = [
        ("photos", f"{report['photos']} ({report['photos_without_code']} labelled without a code)"),
        ("codes labelled", str(report["codes"])),
        ("read", f"{report['read']}" + ("" if rate is None else f" ({rate:.1%})")),
        (
            "wrong payloads",
            f"{report['wrong_payloads']} ({report['wrong']} on codes, {report['false_reads']} elsewhere)",
        ),
        ("found, not verified", str(report["not_verified"])),
        ("missed", str(report["missed"])),
        ("corner error", _stats_text(report["corner_error_px"], "px", 2)),
        ("time per photo", _stats_text(report["time_ms"], "ms", 1) + f" on {report.get('threads', '?')} thread(s)"),
        ("camera", report["camera"]),
    ]
    if report["skipped"]:
        rows.append(("skipped (unreadable)", ", ".join(s["file"] for s in report["skipped"])))
    return rows


def format_summary(report: dict[str, Any]) -> str:
    """The summary as text lines."""
    rows = summary_rows(report)
    width = max(len(k) for k, _ in rows)
    return "\n".join(f"{k.ljust(width)}  {v}" for k, v in rows)


def _table(head: list[str], rows: list[list[str]]) -> str:
    th = "".join(f"<th>{html.escape(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{th}</tr></thead><tbody>{body}</tbody></table>"


def _code_row(c: dict[str, Any]) -> list[str]:
    return [c["file"], str(c["line"]), c["expected"], c["status"], _fmt(c["payload"]), _fmt(c["corner_error_px"], 2),
            _fmt(c["width_px"]), _fmt(c["tilt_deg"]), _fmt(c["sharpness"], 0), _fmt(c["corners_from"])]  # fmt: skip


def render_html(report: dict[str, Any], images: list[tuple[str, str]], note: str | None) -> str:
    """``report.html``: the summary, the plots (``(file, title)``) or ``note``, every code."""
    codes = [c for photo in report["results"] for c in photo["codes"]]
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>deepmorph bench-photos</title><style>"
        "body{font-family:sans-serif;margin:2em;max-width:70em}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left;font-size:90%}"
        ".read{color:#2e7d32}.wrong{color:#c62828}</style></head><body>",
        f"<h1>{html.escape(report['model'])}: {html.escape(report['folder'])}</h1>",
        _table(["", ""], [list(r) for r in summary_rows(report)]),
    ]
    if note:
        parts.append(f"<p>{html.escape(note)}</p>")
    parts += [f"<img src='{html.escape(name)}' alt='{html.escape(title)}'>" for name, title in images]
    parts.append("<h2>Every code</h2>")
    head = ["photo", "line", "expected", "status", "read", "corner error px", "width px", "tilt °", "sharpness",
            "corners from"]  # fmt: skip
    parts.append(_table(head, [_code_row(c) for c in codes]))
    false = [[p["file"], h] for p in report["results"] for h in p["false_reads"]]
    if false:
        parts.append("<h2>Verified payloads no label accounts for</h2>")
        parts.append(_table(["photo", "payload"], false))
    parts.append("<h2>Time per photo</h2>")
    times = [[p["file"], f"{p['time_ms']:.1f}", str(p["detections"])] for p in report["results"]]
    parts.append(_table(["photo", "ms", "detections"], times))
    parts.append("</body></html>\n")
    return "\n".join(parts)


def write_report(report: dict[str, Any], folder: Path) -> tuple[list[Path], str | None]:
    """Write ``report.html``, ``report.json`` and the plots into ``folder``, all or none.

    Returns:
        The files written, and the note shown instead of the plots (``None`` when drawn).
    """
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        note: str | None = NO_PLOTS
    else:
        note = None
    codes = [c for photo in report["results"] for c in photo["codes"]]
    files: list[tuple[Path, bytes]] = []
    images: list[tuple[str, str]] = []
    if note is None:
        for stem, key, title, edges in PLOTS:
            rows = binned(codes, key, edges)
            if rows:
                files.append((folder / f"{stem}.png", plot_png(rows, title)))
                images.append((f"{stem}.png", title))
        if not images:
            note = "No plots: no code has corners (label them, or the chain found none)."
    folder = output_folder(folder, "--report")
    files = [(folder / path.name, data) for path, data in files]
    files.insert(0, (folder / "report.json", (json.dumps(report, indent=1) + "\n").encode()))
    files.insert(0, (folder / "report.html", render_html(report, images, note).encode("utf-8")))
    atomic_write_all(files)
    return [path for path, _ in files], note


__all__ = ["NO_PLOTS", "PLOTS", "binned", "format_summary", "render_html", "write_report"]
