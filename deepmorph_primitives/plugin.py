"""The built-in primitives' plugin module, loaded through the ``deepmorph`` entry point
(``builtin_primitives``) exactly as third-party plugins are."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register


@hookimpl
def deepmorph_register_primitives(register: Register) -> None:
    """Register the built-in kinds (imported here, not at load: see hookspecs)."""
    from deepmorph_primitives.circle import Circle, Ellipse
    from deepmorph_primitives.line import Line
    from deepmorph_primitives.path import HalfCircle, Path
    from deepmorph_primitives.polyline import Polygon, Polyline
    from deepmorph_primitives.rect import Rect
    from deepmorph_primitives.segments import ArcSegment, LineSegment

    for kind in (Line, Polyline, Polygon, Rect, Circle, Ellipse, Path, HalfCircle):
        register.primitive(kind)
    register.path_segment(LineSegment)
    register.path_segment(ArcSegment)
