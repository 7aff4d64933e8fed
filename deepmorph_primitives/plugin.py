"""The built-in primitives' plugin module, loaded through the ``deepmorph`` entry point
(``builtin_primitives``) exactly as third-party plugins are."""

from __future__ import annotations

from deepmorph_core import hookimpl
from deepmorph_core.plugins import Register
from deepmorph_primitives.circle import Circle, Ellipse
from deepmorph_primitives.line import Line
from deepmorph_primitives.path import HalfCircle, Path
from deepmorph_primitives.polyline import Polygon, Polyline
from deepmorph_primitives.rect import Rect
from deepmorph_primitives.segments import ArcSegment, LineSegment


@hookimpl
def deepmorph_register_primitives(register: Register) -> None:
    for kind in (Line, Polyline, Polygon, Rect, Circle, Ellipse, Path, HalfCircle):
        register.primitive(kind)
    register.path_segment(LineSegment)
    register.path_segment(ArcSegment)
