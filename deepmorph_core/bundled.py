"""The drawing and the trained model shipped with DeepMorph (the demo's and the tests')."""

from __future__ import annotations

from pathlib import Path

#: The ghost drawing (58 variables), with its ``dm:`` bounds.
BUNDLED_DRAWING = Path(__file__).parent / "data" / "ghost.svg"
#: Its trained model (24-bit payloads) with a photo detector.
BUNDLED_MODEL = Path(__file__).parent / "data" / "ghost.dmm"
