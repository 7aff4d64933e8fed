"""Bounds hold in the ink: no morph moves any drawn point further than ``dm:move``.

Measured on real renders (resvg) with a distance transform: every ink pixel of a morph lies
within the bound (plus a pixel of anti-aliasing) of the unmorphed drawing's ink, and the other
way round. The morphs are each variable at both ends of its range (all others at rest) and
random morphs at the corners of the unit cube, where the disk map pushes points furthest.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from deepmorph_core.morphable import MorphableDrawing
from deepmorph_core.render import render_svg_ink
from tests.conftest import FEATHER

PX_PER_UNIT = 10  # renders of 24-unit icons at 240 px
ANTIALIAS_PX = 1.0
MOVE = 0.5

# Rounded triangle: straight sides joined by arcs of radius 0.7, the shape on which an arc that
# keeps its radius moved ink by 0.75 units at dm:move 0.5.
ROUNDED_TRIANGLE = (
    '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24" fill="none" stroke="black" '
    'stroke-width="2"><path d="M10.6 3.8 A0.7 0.7 0 0 1 13.4 3.8 L21.2 17.4 A0.7 0.7 0 0 1 19.8 19.8 '
    'L4.2 19.8 A0.7 0.7 0 0 1 2.8 17.4 Z"/></svg>'
)


def _arc_icons(count: int = 6) -> list[Path]:
    """The first ``count`` test-data Feather icons (alphabetically) whose paths hold arcs (with
    Bezier curves beside them, read by the example plugin: a curve stays in its points' hull)."""
    return [path for path in sorted(FEATHER.glob("*.svg")) if _has_arc(path.read_text())][:count]


def _has_arc(text: str) -> bool:
    """Whether any ``d`` attribute holds an arc command."""
    return any(ch in part.split('"', 1)[0] for part in text.split(' d="')[1:] for ch in "Aa")


def _morphs(md: MorphableDrawing, seed: int = 0, corners: int = 8) -> torch.Tensor:
    """Each variable at either end of its range (others at rest), and random unit-cube corners."""
    rest = md.space.neutral_unit(1, dtype=torch.float64)[0]
    rows = []
    for k in range(md.n_variables):
        for end in (0.0, 1.0):
            u = rest.clone()
            u[k] = end
            rows.append(u)
    gen = torch.Generator().manual_seed(seed)
    rows.extend(torch.randint(0, 2, (corners, md.n_variables), generator=gen).double())
    return md.values_from_unit(torch.stack(rows))


def _worst_ink_move(md: MorphableDrawing, width: int) -> float:
    """The furthest any ink pixel of any morph lies from the drawing's ink (either way), in pixels."""
    base = render_svg_ink(md.to_svg(md.neutral_values()[0].double()), width) > 0.5
    from_base = cv2.distanceTransform((~base).astype(np.uint8), cv2.DIST_L2, 5)
    worst = 0.0
    for values in _morphs(md):
        ink = render_svg_ink(md.to_svg(values), width) > 0.5
        from_morph = cv2.distanceTransform((~ink).astype(np.uint8), cv2.DIST_L2, 5)
        worst = max(worst, float(from_base[ink].max(initial=0.0)), float(from_morph[base].max(initial=0.0)))
    return worst


@pytest.mark.parametrize("icon", _arc_icons(), ids=lambda p: p.stem)
def test_feather_morphs_keep_ink_within_the_bound(icon: Path, with_bezier) -> None:
    md = MorphableDrawing.load(icon, move=MOVE)
    assert md.n_variables > 0
    width = round(md.drawing.viewbox[2] * PX_PER_UNIT)
    assert _worst_ink_move(md, width) <= MOVE * PX_PER_UNIT + ANTIALIAS_PX


def test_arcs_follow_their_chord_and_their_ends_move_less() -> None:
    md = MorphableDrawing.load(ROUNDED_TRIANGLE.encode(), move=MOVE)
    radii = {round(v.hi, 4) for v in md.variables}
    assert min(radii) < MOVE  # the arc ends' disks shrink so that their bulges stay inside
    assert _worst_ink_move(md, 24 * PX_PER_UNIT) <= MOVE * PX_PER_UNIT + ANTIALIAS_PX


def test_geometry_1_arcs_keep_their_radius_and_overshoot() -> None:
    """What bundles trained before geometry 2 still do (they load with their own geometry)."""
    md = MorphableDrawing.load(ROUNDED_TRIANGLE.encode(), move=MOVE, geometry=1)
    assert {round(v.hi, 4) for v in md.variables} == {MOVE}
    assert _worst_ink_move(md, 24 * PX_PER_UNIT) > MOVE * PX_PER_UNIT + 1.5
