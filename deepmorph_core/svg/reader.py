"""Reading one element's attributes with errors that name the file and line."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NoReturn, TypeVar

import numpy as np
from lxml import etree

from deepmorph_core.errors import SvgError, UnsupportedFeatureError
from deepmorph_core.svg import values
from deepmorph_core.svg.style import Style

if TYPE_CHECKING:
    from deepmorph_core.plugins import Registry

T = TypeVar("T")

#: How drawings are morphed. 1: per-point moves bound the control points only, and arcs keep
#: their radii (except arcs of half an ellipse, which follow their chord). 2: every arc follows
#: its chord (it moves as the similarity taking its chord onto the morphed chord), and each
#: point's move radius shrinks by how far its primitive's ink can move per unit of the point's
#: move, so that no ink moves further than the artist's bound. Bundles record the version their
#: model was trained with; new drawings use the newest.
GEOMETRY_VERSION = 2
GEOMETRY_VERSIONS = (1, 2)


def viewbox_of(root: etree._Element, source: str) -> tuple[float, float, float, float]:
    """The drawing's frame in user units: ``<svg viewBox>``, else ``(0, 0, width, height)``.

    Raises:
        SvgError: at the ``<svg>`` line of ``source``, saying which attribute is wrong.
    """
    raw = root.get("viewBox")
    try:
        if raw is not None:
            nums = values.parse_numbers(raw)
            if len(nums) != 4 or nums[2] <= 0 or nums[3] <= 0:
                raise ValueError("needs four numbers with positive width and height")
            return nums[0], nums[1], nums[2], nums[3]
    except ValueError as exc:
        raise SvgError(f"viewBox={raw!r}: {exc}", source, root.sourceline) from None
    try:
        w, h = (values.parse_length(root.get(name) or "") for name in ("width", "height"))
    except ValueError:
        raise SvgError("<svg> needs a viewBox, or numeric width and height", source, root.sourceline) from None
    if w <= 0 or h <= 0:
        raise SvgError("<svg> width and height must be positive", source, root.sourceline)
    return 0.0, 0.0, w, h


@dataclass
class ElementReader:
    """What a primitive gets to read its element: typed attribute access and error reporting.

    Attributes:
        source: label of the SVG (a path, or ``<string>``).
        registry: the plugin registry (paths use it to find segment kinds).
        style: the computed style of the element being read (caps, fill rule).
        geometry: the morph geometry version (:data:`GEOMETRY_VERSION`) the drawing is read for.
    """

    source: str
    registry: Registry
    style: Style = Style()
    geometry: int = GEOMETRY_VERSION

    def error(self, element: etree._Element | None, message: str) -> NoReturn:
        """Raise an :class:`SvgError` at ``element``'s line."""
        raise SvgError(message, self.source, element.sourceline if element is not None else None)

    def unsupported(self, element: etree._Element | None, message: str) -> NoReturn:
        """Raise an :class:`UnsupportedFeatureError` (``unsupported: ...``) at ``element``'s line."""
        raise UnsupportedFeatureError(
            f"unsupported: {message}", self.source, element.sourceline if element is not None else None
        )

    def _attr(self, element: etree._Element, name: str, parse: Callable[[str], T], default: T | None) -> T:
        raw = element.get(name)
        if raw is None:
            if default is None:
                self.error(element, f"<{etree.QName(element).localname}> needs attribute {name}")
            return default
        try:
            return parse(raw)
        except ValueError as exc:
            self.error(element, f"{name}={raw!r}: {exc}")

    def number(self, element: etree._Element, name: str, default: float | None = None) -> float:
        """A numeric attribute (``default`` when absent; required when ``default`` is None)."""
        return self._attr(element, name, values.parse_number, default)

    def length(self, element: etree._Element, name: str, default: float | None = None) -> float:
        """A length attribute in user units (``px`` allowed)."""
        return self._attr(element, name, values.parse_length, default)

    def points(self, element: etree._Element, name: str = "points") -> np.ndarray:
        """A point list attribute as ``(n, 2)``."""
        return self._attr(element, name, values.parse_points, None)

    def text(self, element: etree._Element, name: str) -> str:
        """A required string attribute."""
        return self._attr(element, name, str, None)
