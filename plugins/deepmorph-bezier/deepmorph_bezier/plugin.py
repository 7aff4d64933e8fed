"""The plugin module behind the ``bezier`` entry point of the ``deepmorph`` group.

The segment kinds are declared by import path with what ``deepmorph list-primitives`` shows,
so listing them imports no torch; DeepMorph imports the classes when a drawing first needs them
and checks them against these declarations."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_primitives(register: Register) -> None:
    """Register the cubic and quadratic Bézier path-segment kinds."""
    register.path_segment(
        "deepmorph_bezier.segments:CubicBezierSegment",
        kind="cubic-bezier",
        commands="CcSs",
        morphable="both handles and end point (shared with the next segment)",
    )
    register.path_segment(
        "deepmorph_bezier.segments:QuadraticBezierSegment",
        kind="quadratic-bezier",
        commands="QqTt",
        morphable="handle and end point (shared with the next segment)",
    )
