"""Simulated colour close-ups kept as fixtures (``tests/data/photos``, each PNG with a JSON of
the print's true corners and the universal detector's proposal), and the aligner the photo chain
makes for a colour drawing."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.photo import to_gray
from deepmorph_core.protocols import Candidate
from deepmorph_detect.align import MIN_CORRELATION, Aligner, ink_thickness
from deepmorph_detect.camera import project, viewbox_corners
from deepmorph_detect.fastrender import stretched_renderer, template_renderer
from deepmorph_detect.refine import LEVELS, Template

#: The width of the rectified views the aligner sizes its flat light by.
VIEW_WIDTH = 192


def colour_aligner(svg: Path) -> tuple[Template, Aligner]:
    """The unmorphed drawing's template and aligner, made as the photo chain makes them for its
    model (``--move 0.5``)."""
    md = MorphableDrawing.load(svg, move=0.5)
    unmorphed = md.to_svg(md.neutral_values()[0])
    _, renderer = template_renderer(unmorphed, md.drawing.viewbox, LEVELS, md.channel)
    template = Template.from_svg(unmorphed, md.drawing.viewbox, LEVELS, stretched_renderer(renderer, md.ink_level))
    thickness = ink_thickness(template, VIEW_WIDTH)
    aligner = Aligner(template, MIN_CORRELATION, thickness, VIEW_WIDTH, flat_sheet=md.colour, shifted_sweep=md.colour)
    return template, aligner


def _candidate(proposal: dict) -> Candidate:
    return Candidate(
        corners=np.array(proposal["corners"]),
        score=proposal["score"],
        bbox=tuple(proposal["bbox"]),
        source=proposal["source"],
        sized=proposal["sized"],
        blind=proposal["blind"],
    )


def close_up(photo: Path) -> tuple[np.ndarray, np.ndarray, Candidate]:
    """A fixture photo's gray, its print's true corners and the universal detector's proposal."""
    fixture = json.loads(photo.with_suffix(".json").read_text())
    return to_gray(cv2.imread(str(photo))), np.array(fixture["truth_corners"]), _candidate(fixture["candidate"])


def close_up_proposals(photo: Path) -> tuple[np.ndarray, np.ndarray, list[Candidate]]:
    """A fixture photo's gray, its print's true corners and every proposal of the universal
    detector, in its order."""
    fixture = json.loads(photo.with_suffix(".json").read_text())
    candidates = [_candidate(proposal) for proposal in fixture["candidates"]]
    return to_gray(cv2.imread(str(photo))), np.array(fixture["truth_corners"]), candidates


def corner_error(homography: np.ndarray, template: Template, truth: np.ndarray) -> float:
    """Mean distance of the frame's corners from the truth, as a share of the frame's width."""
    quad = project(homography, viewbox_corners(template.viewbox))
    return float(np.linalg.norm(quad - truth, axis=1).mean() / np.linalg.norm(truth[1] - truth[0]))
