"""Runnable example of the Python API: train a small model, hide a payload, print it at 30 mm
as SVG, PNG and PDF, and read it back from the PNG, from the PDF and from a simulated photo.

    .venv/bin/python examples/encode_decode.py [FOLDER]   # about a minute on one core

Its files (drawing, model, codes) go to ``FOLDER``, created if missing, or to a new temporary
folder whose path it prints.

It trains on a tiny drawing for a few hundred steps (a real model trains for thousands; see
``deepmorph train --help``), so expect most but not all payloads to come back.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import deepmorph
from deepmorph_core.pdf import render_pdf
from deepmorph_detect.scenes import close_up_photo

DRAWING = """<svg xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1" viewBox="0 0 24 24"
  fill="none" stroke="black" stroke-width="2.5" stroke-linecap="round" dm:move="2.5">
  <polyline points="4 6 12 4 20 6"/><line x1="4" y1="12" x2="20" y2="12"/>
  <polyline points="4 18 12 20 20 18"/><circle cx="12" cy="12" r="3" dm:move="1.5"/>
</svg>"""


def main(folder: str | None = None) -> None:
    work = Path(folder) if folder else Path(tempfile.mkdtemp(prefix="deepmorph-example-"))
    work.mkdir(parents=True, exist_ok=True)
    svg = work / "drawing.svg"
    svg.write_text(DRAWING)

    # 1. Train: 8 payload bits, CRC-8, BCH correcting one bit error. A model this small is
    #    validated on 200 renders and 20 photos (a real one on 1000 and 200, the default,
    #    which would take this one four times as long as its training).
    model = deepmorph.train(
        svg, work / "model.dmm", payload_bits=8, crc_bits=8, ecc_t=1,
        steps=600, threads=1, image_width=48, batch=16, severity="easy", validation=(200, 20),
    )  # fmt: skip
    print(f"trained in {model.info()['record']['elapsed_s']:.0f} s -> {work / 'model.dmm'}")

    # 2. Encode: a payload (an int here; hex text, bytes or bits work too) becomes a code,
    #    saved at its printed size as the extension says (the PNG at 300 dpi).
    code = model.encode(0xA5)
    files = [code.save(work / name, width_mm=30) for name in ("code.svg", "code.png", "code.pdf")]
    print(f"wrote {', '.join(f.name for f in files)} ({code.payload.hex}, 30 x {code.height_mm(30):g} mm)")

    # 3. Decode: the PNG by its path, a render of the PDF (an RGB array, as PIL gives), and a
    #    simulated phone photo of the print (OpenCV's BGR order, said with bgr=True).
    pdf_render = render_pdf((work / "code.pdf").read_bytes(), 300)
    rgb = np.repeat((pdf_render * 255).astype(np.uint8)[..., None], 3, axis=2)
    photo = close_up_photo(pdf_render, "easy", np.random.default_rng(0))
    for name, image, bgr in (("png", work / "code.png", False), ("pdf", rgb, False), ("photo", photo, True)):
        for found in model.decode(image, bgr=bgr):
            r = found.result
            print(
                f"{name}: {found.payload.hex} ok={found.ok} corrected={r.corrected_bits} confidence={r.confidence:.2f}"
            )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
