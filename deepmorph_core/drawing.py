"""Parsing an SVG into a :class:`Drawing`: placed primitives, morphable groups, bounds.

The walk resolves transforms (CTMs), styles and ``dm:`` bound-specs, asks the registry which
primitive kind reads each element, and holds every element to the allow-list of
:mod:`deepmorph_core.svg.policy`: what DeepMorph cannot model is an ``unsupported:`` error with
its line (or, with ``drop_unsupported``, left out and listed in :attr:`Drawing.dropped`), and
scripts and event handlers are errors always. The lxml tree is kept so that a morph can be
written back into a fresh copy of the modelled parts only (:meth:`Drawing.sanitized`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from deepmorph_core.bounds import BoundSpec, parse_bounds
from deepmorph_core.errors import BoundsError, DeepMorphError, SvgError
from deepmorph_core.plugins import Registry, default_registry
from deepmorph_core.protocols import Primitive
from deepmorph_core.render import raster_size
from deepmorph_core.svg import policy
from deepmorph_core.svg.css import Stylesheet, StylesheetError
from deepmorph_core.svg.gradients import GRADIENT_TAGS, STOP_ATTRIBUTES, GradientError, Gradients
from deepmorph_core.svg.policy import DM_NS
from deepmorph_core.svg.reader import GEOMETRY_VERSION, GEOMETRY_VERSIONS, ElementReader, viewbox_of
from deepmorph_core.svg.secure import SVG_NS, parse_svg_bytes, read_svg_bytes
from deepmorph_core.svg.style import Paint, Style, compute_style, style_declarations
from deepmorph_core.svg.values import parse_transform

#: The largest ratio of a viewBox's longer side to its shorter: what renders at a sane size.
MAX_ASPECT = 20.0
#: Limits that keep every accepted drawing quick to read and to train: primitives and control
#: points (a morph variable pair each).
MAX_PRIMITIVES = 2_000
MAX_CONTROL_POINTS = 10_000
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


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
        dropped: ``(line, what)`` for what DeepMorph cannot model and left out
            (``drop_unsupported``); empty otherwise, since such input is an error.
        styles: every kept element's ``style=""`` reduced to the properties DeepMorph reads,
            with what stylesheet rules give it written in (the output holds no ``<style>``).
        gradients: the document's gradients; those the paints use are written back.
        geometry: the morph geometry version it was read for
            (:data:`~deepmorph_core.svg.reader.GEOMETRY_VERSION`).
    """

    source: str
    root: etree._Element
    viewbox: tuple[float, float, float, float]
    primitives: list[PlacedPrimitive] = field(default_factory=list)
    groups: list[MorphGroup] = field(default_factory=list)
    skipped: list[tuple[int | None, str]] = field(default_factory=list)
    dropped: list[tuple[int | None, str]] = field(default_factory=list)
    styles: dict[etree._Element, str] = field(default_factory=dict)
    gradients: Gradients = field(default_factory=Gradients)
    geometry: int = GEOMETRY_VERSION

    @property
    def palette(self) -> list[Paint]:
        """Every distinct paint the drawing lays down, in paint order of first use."""
        seen: list[Paint] = []
        for prim in self.primitives:
            for paint in prim.style.palette:
                if paint not in seen:
                    seen.append(paint)
        return seen

    @property
    def black_and_white(self) -> bool:
        """Whether every paint is opaque black or white (the paper's drawings)."""
        return all(paint.black_or_white for paint in self.palette)

    def sanitized(self, copies: dict[etree._Element, etree._Element] | None = None) -> etree._ElementTree:
        """A fresh tree of this drawing holding only what DeepMorph models
        (:func:`deepmorph_core.svg.policy.sanitized`); ``copies``, where given, is filled with
        each of its primitives' and groups' elements (and the root) mapped to its copy in it."""
        shapes = {}
        for prim in self.primitives:
            tag = etree.QName(prim.element).localname
            shapes[prim.element] = (*policy.GEOMETRY.get(tag, ()), *getattr(prim.primitive, "attributes", ()))
        definitions = [self.gradients.elements[i] for i in self.gradients.used]
        return policy.sanitized(self.root, shapes, self.styles, definitions, copies)

    def pixel_size(self, width: int) -> tuple[int, int]:
        """``(height, width)`` in pixels for a raster ``width`` pixels wide (aspect kept).

        Raises:
            DeepMorphError: a raster larger than DeepMorph makes (:func:`~deepmorph_core.render.raster_size`).
        """
        return raster_size(self.viewbox, width)

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
    drop_unsupported: bool = False,
    geometry: int = GEOMETRY_VERSION,
) -> Drawing:
    """Read an SVG file (path) or document (bytes) into a :class:`Drawing`.

    Args:
        source: a file path, or the SVG document as bytes.
        defaults: bounds for primitives that have none (below the root's own ``dm:`` defaults).
        registry: plugin registry (default: every installed plugin).
        label: name used in messages when ``source`` is bytes.
        drop_unsupported: leave out what DeepMorph cannot model (CSS, filters, patterns, text,
            images ...) and list it in :attr:`Drawing.dropped`, instead of refusing the file.
            Scripts and event handlers are refused either way.
        geometry: the morph geometry version (:data:`~deepmorph_core.svg.reader.GEOMETRY_VERSION`;
            older bundles name an older one).

    Raises:
        SvgError: malformed, hostile or unsupported input, with file and line.
    """
    if isinstance(source, bytes):
        data, name = source, label or "<string>"
    else:
        data, name = read_svg_bytes(source), str(source)
    if geometry not in GEOMETRY_VERSIONS:
        raise DeepMorphError(f"{name}: unknown morph geometry version {geometry} (known: {list(GEOMETRY_VERSIONS)})")
    root = parse_svg_bytes(data, name)
    walker = _Walker(name, registry or default_registry(), defaults or BoundSpec(), drop_unsupported, geometry)
    return walker.run(root)


class _Walker:
    def __init__(
        self,
        source: str,
        registry: Registry,
        defaults: BoundSpec,
        drop_unsupported: bool = False,
        geometry: int = GEOMETRY_VERSION,
    ):
        self.reader = ElementReader(source, registry, geometry=geometry)
        self.geometry = geometry
        self.source = source
        self.registry = registry
        self.cli_defaults = defaults
        self.drop = drop_unsupported
        self.control_points = 0

    def unsupported(self, drawing: Drawing, element: etree._Element, what: str) -> None:
        """Refuse what cannot be modelled, or (``drop_unsupported``) record that it is left out."""
        if not self.drop:
            self.reader.unsupported(element, what)
        drawing.dropped.append((element.sourceline, what))

    def check_attributes(self, drawing: Drawing, element: etree._Element) -> None:
        """Event handlers and script links are errors; conditional processing is unsupported."""
        for key, value in element.attrib.items():
            q = etree.QName(key)
            if policy.is_event_handler(q.localname):
                raise self.error(
                    element, f"unsupported: event handler attribute {q.localname} (scripts are never kept)"
                )
            if policy.is_script_url(value) and q.localname in ("href", "src", "action", "formaction", "values", "to"):
                raise self.error(element, f"unsupported: {q.localname}={value[:40]!r} (script links are never kept)")
            if q.namespace is None and q.localname in policy.CONDITIONAL:
                self.unsupported(drawing, element, f"conditional attribute {q.localname}")

    def error(self, element: etree._Element, message: str) -> SvgError:
        return SvgError(message, self.source, element.sourceline)

    def run(self, root: etree._Element) -> Drawing:
        drawing = Drawing(self.source, root, viewbox_of(root, self.source), geometry=self.geometry)
        try:
            self.sheet = Stylesheet.from_root(root)
        except StylesheetError as exc:
            if not self.drop:
                raise SvgError(str(exc), self.source, exc.line) from None
            drawing.dropped.append((exc.line, f"CSS <style> ({exc})"))
            self.sheet = Stylesheet()
        drawing.gradients = Gradients.from_root(root, stop_style=self._sheet_declarations)
        self.gradients = drawing.gradients
        self._frame(root, drawing.viewbox)
        root_bounds = self._bounds(root)
        self.defaults = root_bounds.over(self.cli_defaults)
        self.check_attributes(drawing, root)
        style = self._style(drawing, root, Style())
        self._walk(root, drawing, style, np.eye(3), (), move=None, fixed=bool(self.defaults.fixed), depth=0)
        for group in drawing.groups:
            group.centre = self._group_centre(drawing, group)
        for gradient_id in drawing.gradients.used:  # stops keep the colours their rules give them
            for stop in drawing.gradients.elements[gradient_id]:
                if isinstance(stop.tag, str):
                    decls = {**self._sheet_declarations(stop), **style_declarations(stop.get("style"))}
                    kept = {k: v for k, v in decls.items() if k in STOP_ATTRIBUTES}
                    if kept:
                        drawing.styles[stop] = "; ".join(f"{k}: {v}" for k, v in kept.items())
        return drawing

    def _frame(self, root: etree._Element, viewbox: tuple[float, float, float, float]) -> None:
        """Refuse a frame no render can hold: one side over :data:`MAX_ASPECT` times the other."""
        w, h = viewbox[2], viewbox[3]
        if max(w / h, h / w) > MAX_ASPECT:
            raise self.error(
                root, f"the drawing's frame is {w:g} x {h:g}: one side is more than {MAX_ASPECT:g} times the other"
            )

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

    def _sheet_declarations(self, element: etree._Element) -> dict[str, str]:
        normal, important = self.sheet.declarations(element)
        return {**normal, **important}

    def _style(self, drawing: Drawing, element: etree._Element, parent: Style) -> Style:
        """The element's computed style, its properties held to the policy; records the
        ``style=""`` that will be written (the modelled properties only).

        The cascade: presentation attributes, then stylesheet rules, then ``style=""``, then
        ``!important`` rules (:mod:`deepmorph_core.svg.css`)."""
        try:
            inline = style_declarations(element.get("style"))
        except ValueError as exc:
            raise self.error(element, str(exc)) from None
        normal, important = self.sheet.declarations(element)
        own = {**normal, **inline, **important}
        props = {**{k: v for k, v in element.attrib.items() if "}" not in k}, **own}
        kept = {}
        for name, value in props.items():
            verdict = policy.property_verdict(name, value)
            if verdict == "unsupported" and (name in own or name in policy.DEFAULT_ONLY):
                self.unsupported(drawing, element, f"{name}={value!r}{policy.advice(name)}")
                continue
            missing = self.gradients.missing_paint(value) if name in ("fill", "stroke") else None
            if missing is not None:
                self.unsupported(drawing, element, f"{name}={value!r}: {missing}")
                continue
            if verdict == "modelled":
                kept[name] = value
        if own:
            drawing.styles[element] = "; ".join(f"{k}: {v}" for k, v in own.items() if k in kept)
        try:
            return compute_style(kept, parent, self._gradient)
        except GradientError as exc:
            raise SvgError(str(exc), self.source, exc.line) from None
        except ValueError as exc:
            raise self.error(element, str(exc)) from None

    def _gradient(self, gradient_id: str) -> Paint | None:
        return self.gradients.paint(gradient_id)

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
            if name in policy.HOSTILE_ELEMENTS:
                raise self.error(el, f"unsupported: element <{name}> (scripts are never kept)")
            if name in policy.TEXT_ELEMENTS or name in policy.INERT_ELEMENTS:
                continue
            if name == "defs":  # gradients and stylesheets are read where they are used
                for child in el:
                    if isinstance(child.tag, str) and etree.QName(child).namespace in (SVG_NS, None):
                        inner = etree.QName(child).localname
                        if inner in policy.HOSTILE_ELEMENTS:
                            raise self.error(child, f"unsupported: element <{inner}> (scripts are never kept)")
                        if inner not in GRADIENT_TAGS and inner != "style":
                            why = policy.advice(inner) or ": drawn only through <use>; expand the references"
                            self.unsupported(drawing, child, f"<{inner}> in <defs>{why}")
                continue
            if name == "style" or name in GRADIENT_TAGS:  # read before the walk (css.py, gradients.py)
                continue
            self.check_attributes(drawing, el)
            style = self._style(drawing, el, parent_style)
            bounds = self._bounds(el)
            el_ctm = ctm @ self._transform(el)
            el_fixed = fixed or bool(bounds.fixed)
            el_move = bounds.move if bounds.move is not None else move
            if name in policy.CONTAINERS:
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
                self.unsupported(drawing, el, f"element <{name}>{policy.advice(name)}")
                continue
            self._check_size(el)
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
            self.control_points += len(pts)
            if len(drawing.primitives) >= MAX_PRIMITIVES or self.control_points > MAX_CONTROL_POINTS:
                raise self.error(
                    el,
                    f"the drawing has more than {MAX_PRIMITIVES} shapes or {MAX_CONTROL_POINTS} control points;"
                    " simplify it (a code needs far fewer)",
                )
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

    def _check_size(self, element: etree._Element) -> None:
        """Refuse a shape whose geometry alone exceeds the control-point limit, before it is
        parsed: every control point takes at most 7 numbers (an arc), so a ``d`` or ``points``
        with more than 7 numbers per allowed point cannot fit (a 7 MB path fails in well under
        a second instead of after the whole parse)."""
        for attr in ("d", "points"):
            raw = element.get(attr)
            if raw is None or len(raw) < 7 * (MAX_CONTROL_POINTS - self.control_points):
                continue
            numbers = len(_NUMBER.findall(raw))
            if numbers > 7 * (MAX_CONTROL_POINTS - self.control_points):
                raise self.error(
                    element,
                    f"the {attr} of <{etree.QName(element).localname}> holds {numbers:,} numbers: more than the"
                    f" {MAX_CONTROL_POINTS} control points a drawing may have; simplify it (a code needs far fewer)",
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
