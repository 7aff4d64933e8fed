"""Fixtures shared by the photo chain's tests: colour drawings' templates and aligners, made as the
photo chain makes them for a model trained with ``--move 0.5``. Module-scoped: made before each
test's own registry of built-ins (``isolated_plugins``), with the plugins the test environment
installs found by their entry points (the pink heart's curves need the Bézier plugin)."""

from __future__ import annotations

from pathlib import Path

import pytest

from deepmorph_detect.align import Aligner
from deepmorph_detect.refine import Template
from tests.detect.colour_close_ups import colour_aligner

DATA = Path(__file__).parents[1] / "data"


@pytest.fixture(scope="module")
def heart() -> tuple[Template, Aligner]:
    """The Fluent Emoji pink heart."""
    return colour_aligner(DATA / "fluent-emoji-flat" / "pink-heart.svg")


@pytest.fixture(scope="module")
def crystal() -> tuple[Template, Aligner]:
    """The Icons8 crystal oscillator."""
    return colour_aligner(DATA / "flat-color-icons" / "crystal-oscillator.svg")


@pytest.fixture(scope="module")
def reading() -> tuple[Template, Aligner]:
    """The Icons8 reading figure."""
    return colour_aligner(DATA / "flat-color-icons" / "reading.svg")


@pytest.fixture(scope="module")
def add_row() -> tuple[Template, Aligner]:
    """The Icons8 add-row: a pale blue row and a dark green badge at its corner."""
    return colour_aligner(DATA / "flat-color-icons" / "add-row.svg")
