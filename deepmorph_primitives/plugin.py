"""The built-in primitives' plugin module, loaded through the ``deepmorph`` entry point
(``builtin_primitives``) exactly as third-party plugins are.

Each kind is declared by import path with what ``deepmorph list-primitives`` shows, so that
listing them imports no torch; the registry imports a class when a drawing first needs it and
checks it against this declaration."""

from __future__ import annotations

from typing import TYPE_CHECKING

from deepmorph_core import hookimpl

if TYPE_CHECKING:
    from deepmorph_core.plugins import Register

#: (import path, kind, SVG elements read, what morphs)
PRIMITIVES = (
    ("deepmorph_primitives.line:Line", "line", ("line",), "2 end points"),
    ("deepmorph_primitives.polyline:Polyline", "polyline", ("polyline",), "every vertex"),
    ("deepmorph_primitives.polyline:Polygon", "polygon", ("polygon",), "every vertex"),
    ("deepmorph_primitives.rect:Rect", "rect", ("rect",), "2 opposite corners (stays a rectangle)"),
    ("deepmorph_primitives.circle:Circle", "circle", ("circle",), "centre (radius follows element scale)"),
    ("deepmorph_primitives.circle:Ellipse", "ellipse", ("ellipse",), "centre (radii follow element scale)"),
    ("deepmorph_primitives.path:Path", "path", ("path",), "every vertex and handle; arcs follow their chords"),
    ("deepmorph_primitives.path:HalfCircle", "half-circle", ("path",), "2 diameter end points (radius follows)"),
)
#: (import path, kind, path commands, what morphs)
SEGMENTS = (
    ("deepmorph_primitives.segments:LineSegment", "path-line", "LlHhVvZz", "end point (shared with the next segment)"),
    ("deepmorph_primitives.segments:ArcSegment", "path-arc", "Aa", "end point; the arc follows its chord"),
)


@hookimpl
def deepmorph_register_primitives(register: Register) -> None:
    """Declare the built-in kinds (each imported when first used: see hookspecs)."""
    for path, kind, tags, morphable in PRIMITIVES:
        register.primitive(path, kind=kind, tags=tags, morphable=morphable)
    for path, kind, commands, morphable in SEGMENTS:
        register.path_segment(path, kind=kind, commands=commands, morphable=morphable)
