"""Frame-filling prints: each bundle's codes read from scans at print resolution, beside its medium close-ups.

A print that fills the image (a flatbed scan, a photo taken so close that the sheet fills the
frame) gives the decoder far more pixels than it was trained on: a 50 mm print scanned at 300 dpi
is 591 px across, at 600 dpi 1181. It must read at least as well as a medium photo of the same
model. For each bundle and each ``--dpi``, ``--n`` random payloads are encoded as a user encodes
them (``Model.encode(payload).png(width_mm, dpi)``, what ``deepmorph encode --png --dpi`` writes)
and read by ``Model.decode`` twice:

* **render**: the PNG as it is, the print filling the whole image (no paper around it);
* **scan**: the print on a sheet with paper around it (a fifth of its width each side), blurred
  as a scanner's optics blur it (Gaussian, ``--blur-mm`` on the sheet), with sensor noise
  (``--noise``, a share of full scale) and saved as JPEG (``--jpeg`` quality).

Beside them, ``--n`` medium close-ups (:func:`~deepmorph_detect.photo_validation.validate_close_ups`,
what ``deepmorph validate`` reads; the print 60-80 % of the photo's width) give the figure
each scan must reach. Counted per row: payloads read right, wrong payloads, the median
number of corrected bits of the right ones, and the median decode time.

    .venv/bin/python bench/scans.py MODEL.dmm... --n 100 --dpi 300,600 --threads 1
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, environment, set_threads, table, write_json  # noqa: E402

#: paper around a scanned print, each side, as a share of the print's width
MARGIN = 0.2


def png_rgb(png: bytes) -> Any:
    """``png`` as the ``(H, W, 3)`` RGB uint8 array a user's file gives ``Model.decode``."""
    import io

    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def scanned(rgb: Any, dpi: int, blur_mm: float, noise: float, jpeg: int, seed: int) -> Any:
    """The print ``rgb`` (``(H, W, 3)`` uint8, at ``dpi``) as a flatbed scan shows it: on paper
    (:data:`MARGIN` each side), blurred by ``blur_mm`` (sigma, on the sheet), with Gaussian noise
    of ``noise`` (share of full scale), through JPEG at quality ``jpeg``: an ``(H, W, 3)`` RGB
    uint8 array."""
    import cv2
    import numpy as np

    pad = round(MARGIN * rgb.shape[1])
    sheet = cv2.copyMakeBorder(rgb, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=(255, 255, 255)).astype(np.float32)
    sheet = cv2.GaussianBlur(sheet, (0, 0), blur_mm / 25.4 * dpi)
    sheet += np.random.default_rng(seed).normal(0.0, 255.0 * noise, sheet.shape).astype(np.float32)
    # OpenCV's JPEG codec takes and gives BGR: a colour scan's chroma is compressed as a scanner's
    bgr = np.clip(sheet, 0, 255).astype(np.uint8)[..., ::-1]
    ok, buf = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, jpeg])
    assert ok
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()


class Tally:
    """Reads of one kind of image: right, wrong, corrected bits of the right ones, times."""

    def __init__(self) -> None:
        self.n = self.right = self.wrong = 0
        self.corrected: list[int] = []
        self.ms: list[float] = []

    def add(self, found: list[Any], payload: int, ms: float) -> None:
        self.n += 1
        self.ms.append(ms)
        read = [d for d in found if d.ok]
        self.wrong += any(d.payload.int != payload for d in read)
        right = [d for d in read if d.payload.int == payload]
        if right:
            self.right += 1
            self.corrected.append(int(right[0].result.corrected_bits))

    def report(self) -> dict[str, Any]:
        import numpy as np

        return {
            "n": self.n,
            "read": self.right,
            "read_share": round(self.right / max(self.n, 1), 4),
            "wrong": self.wrong,
            "corrected_median": float(np.median(self.corrected)) if self.corrected else None,
            "ms_median": round(float(np.median(self.ms)), 1) if self.ms else None,
        }


def read_scans(path: Path, args: argparse.Namespace) -> dict[str, Any]:
    """One bundle's close-ups, renders and scans (see the module docstring)."""
    import random

    import deepmorph
    from deepmorph_detect.photo_validation import validate_close_ups

    model = deepmorph.load(path)
    close = validate_close_ups(model.bundle, args.n, args.seed, "medium")
    out: dict[str, Any] = {
        "bundle": path.name,
        "payload_bits": model.payload_bits,
        "close_ups_medium": {"n": close.samples, "read": close.read, "wrong": close.wrong},
        "dpi": {},
    }
    rng = random.Random(args.seed)
    for dpi in args.dpi:
        render, scan = Tally(), Tally()
        for i in range(args.n):
            payload = rng.getrandbits(model.payload_bits)
            rgb = png_rgb(model.encode(payload).png(args.width_mm, dpi))
            for tally, image in ((render, rgb), (scan, scanned(rgb, dpi, args.blur_mm, args.noise, args.jpeg, i))):
                start = time.perf_counter()
                found = model.decode(image)
                tally.add(found, payload, 1000 * (time.perf_counter() - start))
        out["dpi"][str(dpi)] = {"render": render.report(), "scan": scan.report()}
    return out


def rows(results: list[dict[str, Any]], width_mm: float) -> list[list[Any]]:
    """The table's rows: one per bundle and dpi."""
    from deepmorph_core.code import print_pixels

    out = []
    for r in results:
        close = r["close_ups_medium"]
        for dpi, kinds in r["dpi"].items():
            render, scan = kinds["render"], kinds["scan"]
            out.append(
                [
                    r["bundle"],
                    r["payload_bits"],
                    f"{close['read']}/{close['n']}",
                    f"{dpi} ({print_pixels(width_mm, int(dpi))} px)",
                    f"{render['read']}/{render['n']}",
                    f"{scan['read']}/{scan['n']}",
                    render["wrong"] + scan["wrong"] + close["wrong"],
                    f"{render['corrected_median']} / {scan['corrected_median']}",
                    f"{render['ms_median']} / {scan['ms_median']}",
                ]
            )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bundles", nargs="+", type=Path, help="trained bundles (.dmm)")
    ap.add_argument("--n", type=int, default=100, help="payloads per bundle and dpi (and medium close-ups)")
    ap.add_argument("--dpi", type=lambda s: [int(v) for v in s.split(",")], default=[300, 600])
    ap.add_argument("--width-mm", type=float, default=50.0, help="the printed width")
    ap.add_argument("--blur-mm", type=float, default=0.085, help="the scanner's blur (sigma) on the sheet")
    ap.add_argument("--noise", type=float, default=0.01, help="sensor noise, a share of full scale")
    ap.add_argument("--jpeg", type=int, default=90, help="JPEG quality of the scan")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=RESULTS / "scans.json")
    args = ap.parse_args(argv)
    set_threads(args.threads)
    results = [read_scans(path, args) for path in args.bundles]
    headers = [
        "bundle",
        "payload bits",
        "medium close-ups",
        "dpi (print px)",
        "render",
        "scan",
        "wrong",
        "corrected, median (render / scan)",
        "ms median (render / scan)",
    ]
    print(table(headers, rows(results, args.width_mm)))
    settings = {k: v for k, v in vars(args).items() if k not in ("bundles", "out")}
    write_json(args.out, {"environment": environment(), "settings": settings, "results": results})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
