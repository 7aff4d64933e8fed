"""The plugin module behind the ``bezier`` entry point of the ``deepmorph`` group."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_primitives(register: Register) -> None:
    """Register the cubic and quadratic Bézier path-segment kinds."""
    from deepmorph_bezier.segments import CubicBezierSegment, QuadraticBezierSegment

    register.path_segment(CubicBezierSegment)
    register.path_segment(QuadraticBezierSegment)
