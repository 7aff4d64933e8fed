"""The studio's drawing: an artist's SVG read through the same hardened reader as the command
line, described for the page (each primitive, its control points and its allowed movement in
the drawing's units), and annotated with ``dm:`` bounds set by clicking.

The drawing is kept as DeepMorph writes it (:meth:`MorphableDrawing.to_svg` of the unmorphed
drawing): only what DeepMorph models, with the ``dm:`` attributes, so what the page shows and
what it downloads are already sanitized.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from deepmorph_core.errors import DeepMorphError

if TYPE_CHECKING:
    from deepmorph_core.morphable import MorphableDrawing

DM_NS = "urn:deepmorph:1"
MAX_SVG_BYTES = 2 * 1024 * 1024  # an upload larger than this is refused before it is parsed
BOUND_NAMES = ("move", "shift", "scale", "rotate", "fixed")


@dataclass(frozen=True)
class BoundsEdit:
    """What a click sets on one primitive (``None``: leave that attribute out, so the element
    takes its group's or the root's default).

    Attributes:
        move: ``dm:move`` radius in the drawing's units.
        shift: ``dm:shift`` as ``(rx, ry)``.
        scale: ``dm:scale`` as ``(lo, hi)``.
        rotate: ``dm:rotate`` in degrees as ``(lo, hi)``.
        fixed: ``dm:fixed="true"``.
    """

    move: float | None = None
    shift: tuple[float, float] | None = None
    scale: tuple[float, float] | None = None
    rotate: tuple[float, float] | None = None
    fixed: bool = False

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> BoundsEdit:
        """An edit from the page's JSON; a value that is not a number is one clear error."""

        def number(key: str) -> float | None:
            value = data.get(key)
            if value in (None, ""):
                return None
            try:
                return float(value)
            except (TypeError, ValueError):
                raise DeepMorphError(f"{key}: expected a number, got {value!r}") from None

        def pair(key: str) -> tuple[float, float] | None:
            value = data.get(key)
            if value in (None, ""):
                return None
            parts = value if isinstance(value, list) else str(value).replace(",", " ").split()
            try:
                lo, hi = (float(v) for v in parts)
            except (TypeError, ValueError):
                raise DeepMorphError(f"{key}: expected two numbers, got {value!r}") from None
            return lo, hi

        return cls(number("move"), pair("shift"), pair("scale"), pair("rotate"), bool(data.get("fixed")))

    def attributes(self) -> dict[str, str | None]:
        """The ``dm:`` attributes to set (``None``: remove)."""

        def text(v: float | tuple[float, float] | None) -> str | None:
            if v is None:
                return None
            return f"{v:g}" if isinstance(v, float) else f"{v[0]:g} {v[1]:g}"

        if self.fixed:
            return {"fixed": "true", "move": None, "shift": None, "scale": None, "rotate": None}
        return {
            "fixed": None,
            "move": text(self.move),
            "shift": text(self.shift),
            "scale": text(self.scale),
            "rotate": text(self.rotate),
        }


def load(data: bytes, label: str) -> MorphableDrawing:
    """Read an uploaded SVG through DeepMorph's hardened reader (:func:`MorphableDrawing.load`).

    Raises:
        DeepMorphError: too large, hostile, broken or unsupported, in one line.
    """
    from deepmorph_core.morphable import MorphableDrawing

    if len(data) > MAX_SVG_BYTES:
        raise DeepMorphError(f"{label}: {len(data)} bytes is larger than the studio reads ({MAX_SVG_BYTES} bytes)")
    return MorphableDrawing.load(data, label=label)


def written(md: MorphableDrawing) -> str:
    """The unmorphed drawing as DeepMorph writes it: what it models, with its ``dm:`` bounds."""
    return md.to_svg(md.neutral_values()[0])


def _group_of(element: Any) -> Any:
    """The ``<g>`` an element sits in, or ``None`` (the root is not a group)."""
    from lxml import etree

    parent = element.getparent()
    if parent is None or parent.getparent() is None or etree.QName(parent).localname != "g":
        return None
    return parent


def annotate(svg: str, label: str, index: int, edit: BoundsEdit, group: bool = False) -> str:
    """``svg`` with primitive ``index``'s ``dm:`` attributes set by ``edit`` (``group``: those of
    the ``<g>`` it sits in, which its shapes inherit), written again.

    Raises:
        DeepMorphError: no such primitive, one in no group, or bounds the reader refuses (a
            negative move ...).
    """
    md = load(svg.encode(), label)
    if not 0 <= index < len(md.drawing.primitives):
        raise DeepMorphError(f"{label}: no primitive {index} (it has {len(md.drawing.primitives)})")
    element = md.drawing.primitives[index].element
    if group:
        element = _group_of(element)
        if element is None:
            raise DeepMorphError(f"{label}: primitive {index} is not in a <g>")
    for name, value in edit.attributes().items():
        key = f"{{{DM_NS}}}{name}"
        if value is None:
            element.attrib.pop(key, None)
        else:
            element.set(key, value)
    out = written(md)
    load(out.encode(), label)  # bounds the reader refuses are refused here, not in a later step
    return out


def describe(md: MorphableDrawing) -> dict[str, Any]:
    """The drawing for the page: its viewBox and, per primitive, its control points in the
    root's user units, its own and effective bounds, and how far each point may move there."""
    import numpy as np

    info = md.describe()
    prims = []
    for p, row in zip(md.drawing.primitives, info["primitives"]):
        local = p.primitive.control_points().detach().cpu().numpy().astype(float)
        ctm = np.asarray(p.ctm, float)
        points = local @ ctm[:2, :2].T + ctm[:2, 2]
        unit = float(np.sqrt(abs(np.linalg.det(ctm[:2, :2])))) or 1.0  # local units -> root units
        own = {
            q.split("}")[1]: v for q, v in p.element.attrib.items() if q.startswith(f"{{{DM_NS}}}")
        }  # what a click set here, as opposed to what it inherits
        group = _group_of(p.element)
        bounds = row["bounds"]
        prims.append(
            {
                "index": p.index,
                "kind": row["kind"],
                "line": row["line"],
                "fixed": bool(row["fixed"]),
                "variables": row["variables"],
                "bounds": bounds,
                "own": own,
                "group": None
                if group is None
                else {
                    "line": group.sourceline,
                    "own": {q.split("}")[1]: v for q, v in group.attrib.items() if q.startswith(f"{{{DM_NS}}}")},
                },
                "points": np.round(points, 4).tolist(),
                "move_radius": 0.0 if row["fixed"] else round(float(bounds.get("move") or 0.0) * unit, 5),
                "shift": None if row["fixed"] or not bounds.get("shift") else [v * unit for v in bounds["shift"]],
            }
        )
    return {
        "source": info["source"],
        "viewbox": info["viewbox"],
        "n_variables": info["n_variables"],
        "primitives": prims,
        "groups": info["groups"],
        "skipped": info["skipped"],
    }


def random_morph(md: MorphableDrawing, seed: int, extreme: bool = False) -> str:
    """A random morph inside the bounds (``extreme``: every variable at one end of its range)."""
    unit = md.random_unit(1, seed)
    if extreme:
        unit = (unit > 0.5).to(unit.dtype)
    return md.to_svg(md.values_from_unit(unit)[0])


__all__ = ["MAX_SVG_BYTES", "BoundsEdit", "annotate", "describe", "load", "random_morph", "written"]
