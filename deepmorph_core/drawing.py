"""Parsing an SVG into a :class:`Drawing`: placed primitives, morphable groups, bounds.

The walk resolves transforms (CTMs), styles and ``dm:`` bound-specs, asks the registry which
primitive kind reads each element, and keeps the lxml tree so that a morph can be written back
with everything it does not touch left as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from deepmorph_core.bounds import DM_NS, BoundSpec, parse_bounds
from deepmorph_core.errors import BoundsError, SvgError
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.protocols import Primitive
from deepmorph_core.svg.reader import ElementReader
from deepmorph_core.svg.secure import SVG_NS, parse_svg_bytes, read_svg_bytes
from deepmorph_core.svg.style import Style, compute_style, declarations
from deepmorph_core.svg.values import parse_numbers, parse_transform

#: Elements that draw nothing and are passed over with their content.
NON_RENDERING = {"title", "desc", "metadata", "defs"}
#: Elements that would draw something DeepMorph cannot model: an error, not a silent skip.
CONTAINERS = {"g", "a"}


@dataclass
class PlacedPrimitive:
    """A primitive where it sits in the drawing.

    Attributes:
        index: position in document order.
        primitive: the kind instance (geometry in local user units).
        element: the element it was read from (in :attr:`Drawing.root`).
        style: its computed style.
        ctm: ``(3, 3)`` map from its local units to the root's user units (viewBox units).
        groups: indices of enclosing morphable groups, outermost first.
        bounds: effective bounds (own, enclosing ``dm:move``, root and caller defaults).
        fixed: whether nothing about it may morph.
        centre: ``(2,)`` centre of its control points (local units): element morphs act about it.
        line: source line.
    """

    index: int
    primitive: Primitive
    element: etree._Element
    style: Style
    ctm: np.ndarray
    groups: tuple[int, ...]
    bounds: BoundSpec
    fixed: bool
    centre: np.ndarray
    line: int | None


@dataclass
class MorphGroup:
    """A ``<g>`` with group-level bounds (shift/scale/rotate act on all it contains).

    Attributes:
        ctm: ``(3, 3)`` map from the group's content units to root user units.
        centre: ``(2,)`` centre of its content, in content units.
    """

    index: int
    element: etree._Element
    ctm: np.ndarray
    bounds: BoundSpec
    centre: np.ndarray
    line: int | None


@dataclass
class Drawing:
    """A parsed, morphable drawing.

    Attributes:
        source: label of where it came from.
        root: the lxml root element (kept to write morphs back).
        viewbox: ``(x, y, width, height)`` in user units.
        primitives: drawable primitives in document (paint) order.
        groups: morphable groups.
        skipped: ``(line, reason)`` for elements passed over (invisible ones).
    """

    source: str
    root: etree._Element
    viewbox: tuple[float, float, float, float]
    primitives: list[PlacedPrimitive] = field(default_factory=list)
    groups: list[MorphGroup] = field(default_factory=list)
    skipped: list[tuple[int | None, str]] = field(default_factory=list)

    def pixel_size(self, width: int) -> tuple[int, int]:
        """``(height, width)`` in pixels for a raster ``width`` pixels wide (aspect kept)."""
        vb_w, vb_h = self.viewbox[2], self.viewbox[3]
        return max(1, round(width * vb_h / vb_w)), width

    def pixel_matrix(self, width: int) -> np.ndarray:
        """``(3, 3)`` map from user units to pixel coordinates for a raster ``width`` wide."""
        h, w = self.pixel_size(width)
        x, y, vw, vh = self.viewbox
        sx, sy = w / vw, h / vh
        return np.array([[sx, 0.0, -x * sx], [0.0, sy, -y * sy], [0.0, 0.0, 1.0]])


def load_drawing(
    source: str | Path | bytes,
    *,
    defaults: BoundSpec | None = None,
    registry: Registry | None = None,
    label: str | None = None,
) -> Drawing:
    """Read an SVG file (path) or document (bytes) into a :class:`Drawing`.

    Args:
        source: a file path, or the SVG document as bytes.
        defaults: bounds for primitives that have none (below the root's own ``dm:`` defaults).
        registry: plugin registry (default: every installed plugin).
        label: name used in messages when ``source`` is bytes.

    Raises:
        SvgError: malformed, hostile or unsupported input, with file and line.
    """
    if isinstance(source, bytes):
        data, name = source, label or "<string>"
    else:
        data, name = read_svg_bytes(source), str(source)
    root = parse_svg_bytes(data, name)
    return _Walker(name, registry or default_registry(), defaults or BoundSpec()).run(root)


class _Walker:
    def __init__(self, source: str, registry: Registry, defaults: BoundSpec):
        self.reader = ElementReader(source, registry)
        self.source = source
        self.registry = registry
        self.cli_defaults = defaults

    def error(self, element: etree._Element, message: str) -> SvgError:
        return SvgError(message, self.source, element.sourceline)

    def run(self, root: etree._Element) -> Drawing:
        drawing = Drawing(self.source, root, self._viewbox(root))
        root_bounds = self._bounds(root)
        self.defaults = root_bounds.over(self.cli_defaults)
        style = self._style(root, Style())
        self._walk(root, drawing, style, np.eye(3), (), move=None, fixed=bool(self.defaults.fixed), depth=0)
        for group in drawing.groups:
            group.centre = self._group_centre(drawing, group)
        return drawing

    def _viewbox(self, root: etree._Element) -> tuple[float, float, float, float]:
        raw = root.get("viewBox")
        try:
            if raw is not None:
                nums = parse_numbers(raw)
                if len(nums) != 4 or nums[2] <= 0 or nums[3] <= 0:
                    raise ValueError("needs four numbers with positive width and height")
                return nums[0], nums[1], nums[2], nums[3]
            w, h = self.reader.length(root, "width", None), self.reader.length(root, "height", None)
        except ValueError as exc:
            raise self.error(root, f"viewBox={raw!r}: {exc}") from None
        except SvgError:
            raise self.error(root, "<svg> needs a viewBox, or numeric width and height") from None
        if w <= 0 or h <= 0:
            raise self.error(root, "<svg> width and height must be positive")
        return 0.0, 0.0, w, h

    def _bounds(self, element: etree._Element) -> BoundSpec:
        attrs = {}
        for key, value in element.attrib.items():
            q = etree.QName(key)
            if q.namespace == DM_NS:
                attrs[q.localname] = value
        try:
            return parse_bounds(attrs)
        except ValueError as exc:
            raise BoundsError(str(exc), self.source, element.sourceline) from None

    def _style(self, element: etree._Element, parent: Style) -> Style:
        try:
            return compute_style(declarations(dict(element.attrib), element.get("style")), parent)
        except ValueError as exc:
            raise self.error(element, str(exc)) from None

    def _transform(self, element: etree._Element) -> np.ndarray:
        raw = element.get("transform")
        if raw is None:
            return np.eye(3)
        try:
            return parse_transform(raw)
        except ValueError as exc:
            raise self.error(element, f"transform={raw!r}: {exc}") from None

    def _walk(
        self,
        parent: etree._Element,
        drawing: Drawing,
        parent_style: Style,
        ctm: np.ndarray,
        groups: tuple[int, ...],
        move: float | None,
        fixed: bool,
        depth: int,
    ) -> None:
        for el in parent:
            if not isinstance(el.tag, str):
                continue
            q = etree.QName(el)
            if q.namespace not in (SVG_NS, None):
                continue  # foreign metadata (editors' namespaces) draws nothing
            name = q.localname
            if name in NON_RENDERING:
                continue
            style = self._style(el, parent_style)
            bounds = self._bounds(el)
            el_ctm = ctm @ self._transform(el)
            el_fixed = fixed or bool(bounds.fixed)
            el_move = bounds.move if bounds.move is not None else move
            if name in CONTAINERS:
                if not style.displayed:
                    drawing.skipped.append((el.sourceline, f"<{name}> not displayed"))
                    continue
                inner = groups
                if not el_fixed and any(v is not None for v in (bounds.shift, bounds.scale, bounds.rotate)):
                    drawing.groups.append(
                        MorphGroup(len(drawing.groups), el, el_ctm, bounds, np.zeros(2), el.sourceline)
                    )
                    inner = groups + (len(drawing.groups) - 1,)
                self._walk(el, drawing, style, el_ctm, inner, el_move, el_fixed, depth + 1)
                continue
            kinds = self.registry.primitives_for_tag(name)
            if not kinds:
                self.reader.unsupported(el, f"element <{name}>")
            if not style.visible:
                drawing.skipped.append((el.sourceline, f"<{name}> invisible"))
                continue
            self.reader.style = style
            primitive = None
            for kind in kinds:
                primitive = kind.from_element(el, self.reader)
                if primitive is not None:
                    break
            if primitive is None:
                drawing.skipped.append((el.sourceline, f"<{name}> draws nothing"))
                continue
            primitive.evenodd = style.fill_rule == "evenodd"
            primitive.filled = any(mode == "fill" for mode, _ in style.paints)
            if el_fixed and groups:
                raise self.error(el, "a dm:fixed element cannot sit inside a group with dm:shift/scale/rotate")
            inherited = BoundSpec(move=el_move) if el_move is not None else BoundSpec()
            effective = bounds.over(inherited).over(self.defaults)
            pts = primitive.control_points().numpy()
            centre = (pts.min(0) + pts.max(0)) / 2
            drawing.primitives.append(
                PlacedPrimitive(
                    len(drawing.primitives),
                    primitive,
                    el,
                    style,
                    el_ctm,
                    groups,
                    effective,
                    el_fixed,
                    centre,
                    el.sourceline,
                )
            )

    @staticmethod
    def _group_centre(drawing: Drawing, group: MorphGroup) -> np.ndarray:
        inv = np.linalg.inv(group.ctm)
        pts = []
        for prim in drawing.primitives:
            if group.index in prim.groups:
                local = prim.primitive.control_points().numpy()
                m = inv @ prim.ctm
                pts.append(local @ m[:2, :2].T + m[:2, 2])
        if not pts:
            return np.zeros(2)
        allp = np.concatenate(pts)
        return (allp.min(0) + allp.max(0)) / 2
