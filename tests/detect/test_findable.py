"""How often the photo chain finds a drawing's prints, simulated before training
(:mod:`deepmorph_detect.findable`), and how ``capacity`` reports it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.protocols import Candidate
from deepmorph_detect import findable as findable_module
from deepmorph_detect.align import Aligned
from deepmorph_detect.findable import findability, frame_error
from deepmorph_detect.refine import Alignment, ImagePyramid

#: a blue speech bubble with a white "i", drawn in lines (the Icons8 `about`, its corners cut)
CLEAR = (
    b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 48 48"><path fill="#2196F3" d="M11 6h26l6 6v22l-6 6H17'
    b'l-6 6z"/><rect x="22" y="20" width="4" height="11" fill="#fff"/><circle cx="24" cy="15" r="2" fill="#fff"/></svg>'
)
#: a disc and a box barely off the paper's white: nothing a detector or an alignment can hold
NEAR_WHITE = (
    b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 48 48"><circle cx="24" cy="24" r="18" fill="#fbfbf8"/>'
    b'<rect x="10" y="30" width="10" height="8" fill="#fafbfb"/></svg>'
)


def _found(svg: bytes, shots: int) -> int:
    drawing = MorphableDrawing.load(svg, move=0.5)
    drawing.read_in(None)
    return findability(drawing, {"move": 0.5}, shots=shots).found


def test_a_clear_colour_drawing_is_found_and_one_as_white_as_its_paper_is_not() -> None:
    """A blue speech bubble is found in hard close-ups; a drawing a shade off the paper's white is
    not."""
    assert _found(CLEAR, 6) >= 5
    assert _found(NEAR_WHITE, 6) <= 1


def test_a_print_aligned_in_any_corner_order_is_at_the_truth() -> None:
    """A drawing that looks the same turned is read at each turn: its frame found a quarter turn
    round is no error; one moved by a tenth of its width is a tenth off; nothing aligned is None."""
    truth = np.array([[10.0, 10], [110, 10], [110, 110], [10, 110]])
    frame = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])

    def aligned(corners: np.ndarray) -> Aligned:
        import cv2

        homography = cv2.getPerspectiveTransform(frame.astype(np.float32), corners.astype(np.float32))
        candidate = Candidate(corners, 1.0, (0, 0, 1, 1), source="test")
        return Aligned(candidate, Alignment(homography.astype(np.float64), 0.9), ImagePyramid(np.zeros((8, 8))))

    assert frame_error(frame, [aligned(np.roll(truth, 1, axis=0))], truth) == pytest.approx(0.0, abs=1e-6)
    assert frame_error(frame, [aligned(truth + [10.0, 0.0])], truth) == pytest.approx(0.1)
    assert frame_error(frame, [], truth) is None


def test_capacity_says_how_often_a_colour_drawing_is_found(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """`capacity` simulates hard photos of a colour drawing and reports how many found it."""
    monkeypatch.setattr(findable_module, "SHOTS", 3)
    svg = tmp_path / "bubble.svg"
    svg.write_bytes(CLEAR)
    shown = CliRunner().invoke(application(), ["capacity", str(svg), "--move", "0.5", "--json"])
    found, shots = json.loads(shown.output)["found"]
    assert shots == 3 and found >= 2
