"""What DeepMorph accepts in an SVG and what it writes out: an allow-list.

A drawing is read and written as DeepMorph models it, nothing more. Every element and attribute
falls in one of four classes:

* **modelled**: what the drawing's geometry, style and bounds are made of (shapes, ``<g>``,
  the style properties :mod:`deepmorph_core.svg.style` reads, ``transform``, ``dm:`` bounds);
  kept.
* **inert**: what draws nothing and means nothing to a renderer of the shapes (``id``,
  ``class``, text titles, editors' metadata, font properties on shapes); dropped from what is
  written.
* **unsupported**: what changes the picture in ways DeepMorph does not model (CSS ``<style>``,
  filters, patterns, masks, clip paths, dashes, images, markers, conditional processing); a
  clear ``unsupported:`` error with its line, or with ``drop=True`` dropped and reported.
* **hostile**: scripts, event handlers, ``javascript:`` links: an error always.

:func:`sanitized` builds what is written: a fresh tree of the modelled elements and
attributes only, so no DOCTYPE, entity, script, handler, link, stylesheet or external
reference reaches a renderer or a reader of the file, whatever the input held.
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from lxml import etree

SVG_NS = "http://www.w3.org/2000/svg"
DM_NS = "urn:deepmorph:1"  # the namespace of the dm: bound-spec attributes
XML_NS = "http://www.w3.org/XML/1998/namespace"
XLINK_NS = "http://www.w3.org/1999/xlink"

#: Containers: ``<a>`` is written as ``<g>`` (its link dropped).
CONTAINERS = frozenset({"g", "a"})
#: Elements that draw nothing: titles and descriptions are written (as plain text), the rest dropped.
TEXT_ELEMENTS = frozenset({"title", "desc"})
INERT_ELEMENTS = frozenset({"metadata"})
#: Elements whose presence is an attack, not a drawing.
HOSTILE_ELEMENTS = frozenset({"script", "foreignObject", "handler", "listener"})
#: Geometry attributes of the SVG shapes (what primitives read and write).
GEOMETRY = {
    "line": ("x1", "y1", "x2", "y2"),
    "polyline": ("points",),
    "polygon": ("points",),
    "rect": ("x", "y", "width", "height", "rx", "ry"),
    "circle": ("cx", "cy", "r"),
    "ellipse": ("cx", "cy", "rx", "ry"),
    "path": ("d",),
}
#: Style properties (as attributes or in ``style=""``) that style.py reads.
MODELLED_PROPERTIES = frozenset(
    {
        "fill",
        "stroke",
        "stroke-width",
        "stroke-linecap",
        "stroke-linejoin",
        "fill-rule",
        "visibility",
        "display",
        "opacity",
        "fill-opacity",
        "stroke-opacity",
        "color",
        "paint-order",
    }
)
#: Properties that cannot change how the shapes are drawn here (text, fonts,
#: interaction, colour management, editors' own): dropped.
INERT_PROPERTIES = frozenset(
    {
        "stroke-miterlimit",  # joins are drawn round
        "font",
        "font-family",
        "font-size",
        "font-size-adjust",
        "font-stretch",
        "font-style",
        "font-variant",
        "font-weight",
        "font-feature-settings",
        "font-variation-settings",
        "font-kerning",
        "text-anchor",
        "text-decoration",
        "text-rendering",
        "text-align",
        "text-indent",
        "text-transform",
        "letter-spacing",
        "word-spacing",
        "line-height",
        "writing-mode",
        "direction",
        "unicode-bidi",
        "dominant-baseline",
        "alignment-baseline",
        "baseline-shift",
        "color-interpolation",
        "color-interpolation-filters",
        "color-rendering",
        "color-profile",
        "image-rendering",
        "enable-background",
        "overflow",
        "cursor",
        "pointer-events",
        "user-select",
        "clip-rule",
        "flood-color",
        "flood-opacity",
        "lighting-color",
        "stop-color",
        "stop-opacity",
        "solid-color",
        "solid-opacity",
        "marker",
    }
)
#: Properties whose default value draws as DeepMorph models; any other value is unsupported.
DEFAULT_ONLY = {
    "stroke-dasharray": ("none",),
    "stroke-dashoffset": ("0", "0px"),
    "clip-path": ("none",),
    "clip": ("auto",),
    "mask": ("none",),
    "filter": ("none",),
    "marker-start": ("none",),
    "marker-mid": ("none",),
    "marker-end": ("none",),
    "vector-effect": ("none",),
    "mix-blend-mode": ("normal",),
    "isolation": ("auto",),
    "shape-rendering": ("auto", "geometricprecision"),
    "transform-origin": ("0 0", "0px 0px", "0 0 0", "left top"),
    "transform-box": ("view-box",),
}
#: Attributes that draw nothing (dropped): identities, accessibility, editors' and documents' own.
INERT_ATTRIBUTES = frozenset(
    {
        "id",
        "class",
        "role",
        "tabindex",
        "focusable",
        "lang",
        "version",
        "baseProfile",
        "x",
        "y",  # on the root <svg> only (shapes read their own x, y)
        "preserveAspectRatio",
        "zoomAndPan",
        "contentScriptType",
        "contentStyleType",
        "enable-background",
        "pathLength",
        "href",
        "target",
        "download",
        "rel",
        "type",
    }
)
#: Conditional processing: a renderer may skip the element. Not modelled.
CONDITIONAL = frozenset({"requiredFeatures", "requiredExtensions", "systemLanguage"})
#: Root attributes that are modelled (the frame of the drawing).
ROOT_ATTRIBUTES = ("viewBox", "width", "height")

#: What to do about elements DeepMorph cannot model, by tag.
ADVICE = {
    "text": "outline the text (convert it to paths) in the design tool",
    "tspan": "outline the text (convert it to paths) in the design tool",
    "textPath": "outline the text (convert it to paths) in the design tool",
    "image": "trace the bitmap into shapes, or leave it out",
    "use": "expand the reference into plain shapes (unlink the symbol or clone)",
    "symbol": "expand the symbol into plain shapes",
    "filter": "flatten the effect (expand the appearance) in the design tool",
    "clipPath": "flatten the effect (release the clipping path, then expand) in the design tool",
    "pattern": "expand the pattern into shapes, or fill with a colour",
    "marker": "expand the markers into shapes",
    "clip-path": "flatten the effect (release the clipping path, then expand) in the design tool",
    "mask": "flatten the effect (release the mask, then expand) in the design tool",
    "stroke-dasharray": "expand the dashed stroke into shapes (outline stroke)",
}


def advice(tag: str) -> str:
    """``": what to do"`` for an element DeepMorph cannot model, or ``""``."""
    return f": {ADVICE[tag]}" if tag in ADVICE else ""


_SCRIPT_URL = re.compile(r"^\s*(javascript|vbscript|data)\s*:", re.IGNORECASE)


def is_event_handler(name: str) -> bool:
    """``onload``, ``onclick`` ...: script run by a browser showing the file."""
    return name.lower().startswith("on")


def is_script_url(value: str) -> bool:
    """A ``javascript:`` (or ``vbscript:``, ``data:``) URL."""
    return bool(_SCRIPT_URL.match(value.replace("\x00", "")))


def property_verdict(name: str, value: str) -> str:
    """``modelled``, ``inert`` or ``unsupported`` for one style property with its value."""
    name = name.strip().lower()
    if name in MODELLED_PROPERTIES:
        return "modelled"
    if name in INERT_PROPERTIES or name.startswith("-") or name.startswith("--"):
        return "inert"  # vendor-prefixed and custom properties do nothing without CSS
    if name in DEFAULT_ONLY:
        plain = " ".join(value.strip().lower().split())
        return "inert" if plain in DEFAULT_ONLY[name] else "unsupported"
    return "unsupported"


def sanitized(
    root: etree._Element,
    shapes: dict[etree._Element, Iterable[str]],
    style_of: dict[etree._Element, str],
    gradients: Iterable[etree._Element] = (),
    copies: dict[etree._Element, etree._Element] | None = None,
) -> etree._ElementTree:
    """A fresh document holding only what DeepMorph models of ``root``.

    Args:
        root: the (morphed) ``<svg>`` root.
        shapes: every element read as a primitive, with the geometry attributes it keeps (for
            its tag in :data:`GEOMETRY`, or declared by its primitive kind).
        style_of: for every kept element, its ``style=""`` reduced to the modelled properties
            (empty: none written).
        gradients: the gradients the shapes' paints use, written first in a ``<defs>`` with
            their geometry, stops and ``#id`` links only.
        copies: filled, where given, with each kept shape, container and ``root`` itself mapped
            to its copy in the new tree (to write morphs into the copy).

    Returns:
        The new tree: ``<svg>`` (its frame, namespaces for SVG and ``dm:``), ``<g>`` for every
        container, the shapes, ``<title>``/``<desc>`` text and comments; every other element
        and attribute left out.
    """
    gradients = list(gradients)
    nsmap = {None: SVG_NS, "dm": DM_NS, **({"xlink": XLINK_NS} if gradients else {})}
    out_root = etree.Element(f"{{{SVG_NS}}}svg", nsmap=nsmap)
    for name in ROOT_ATTRIBUTES:
        if root.get(name) is not None:
            out_root.set(name, root.get(name))
    _copy_modelled_attributes(root, out_root, (), style_of.get(root, ""))
    if copies is not None:
        copies[root] = out_root
    if gradients:
        defs = etree.SubElement(out_root, f"{{{SVG_NS}}}defs")
        for gradient in gradients:
            _copy_gradient(gradient, defs, style_of)
    _copy_children(root, out_root, shapes, style_of, copies)
    return etree.ElementTree(out_root)


def _layout(text: str | None) -> str | None:
    """Whitespace between elements is kept (the file keeps its layout); text is not."""
    return text if text is not None and not text.strip() else None


def _copy_children(
    src: etree._Element,
    dst: etree._Element,
    shapes: dict[etree._Element, Iterable[str]],
    style_of: dict[etree._Element, str],
    copies: dict[etree._Element, etree._Element] | None = None,
) -> None:
    dst.text = _layout(src.text)
    last = None
    for child in src:
        if isinstance(child, etree._Comment):
            text = (child.text or "").replace("--", "- -")
            node = etree.Comment(text)
            dst.append(node)
            node.tail, last = _layout(child.tail), node
            continue
        if not isinstance(child.tag, str):
            continue  # processing instructions, entities
        q = etree.QName(child)
        if q.namespace not in (SVG_NS, None):
            continue
        name = q.localname
        if child in shapes:
            node = etree.SubElement(dst, f"{{{SVG_NS}}}{name}")
            _copy_modelled_attributes(child, node, shapes[child], style_of.get(child, ""))
            if copies is not None:
                copies[child] = node
        elif name in CONTAINERS:
            node = etree.SubElement(dst, f"{{{SVG_NS}}}g")
            _copy_modelled_attributes(child, node, (), style_of.get(child, ""))
            if copies is not None:
                copies[child] = node
            _copy_children(child, node, shapes, style_of, copies)
        elif name in TEXT_ELEMENTS and child.text and child.text.strip():
            node = etree.SubElement(dst, f"{{{SVG_NS}}}{name}")
            node.text = "".join(child.itertext())  # text only, any markup inside dropped
        else:
            if last is not None and last.tail is None:
                last.tail = _layout(child.tail)
            continue
        node.tail, last = _layout(child.tail), node


def _copy_gradient(gradient: etree._Element, defs: etree._Element, style_of: dict[etree._Element, str]) -> None:
    """A gradient with its geometry attributes, its ``#id`` link and its stops' colours only
    (a stop's ``style=""`` as ``style_of`` gives it: its stylesheet rules written in)."""
    from deepmorph_core.svg.gradients import GRADIENT_ATTRIBUTES, STOP_ATTRIBUTES, href_of

    node = etree.SubElement(defs, f"{{{SVG_NS}}}{etree.QName(gradient).localname}")
    for key, value in gradient.attrib.items():
        if etree.QName(key).namespace is None and key in GRADIENT_ATTRIBUTES:
            node.set(key, value)
    target = href_of(gradient)
    if target is not None:
        node.set(f"{{{XLINK_NS}}}href", f"#{target}")
    for stop in gradient:
        if not isinstance(stop.tag, str) or etree.QName(stop).localname != "stop":
            continue
        out = etree.SubElement(node, f"{{{SVG_NS}}}stop")
        for key, value in stop.attrib.items():
            if etree.QName(key).namespace is None and key in STOP_ATTRIBUTES:
                out.set(key, value)
        if style_of.get(stop):
            out.set("style", style_of[stop])


def _copy_modelled_attributes(src: etree._Element, dst: etree._Element, geometry: Iterable[str], style: str) -> None:
    keep = set(geometry) | MODELLED_PROPERTIES | {"transform"}
    for key, value in src.attrib.items():
        q = etree.QName(key)
        if q.namespace == DM_NS:
            dst.set(f"{{{DM_NS}}}{q.localname}", value)
        elif q.namespace is None and q.localname in keep:
            dst.set(q.localname, value)
    if style:
        dst.set("style", style)


__all__ = [
    "CONDITIONAL",
    "CONTAINERS",
    "GEOMETRY",
    "HOSTILE_ELEMENTS",
    "INERT_ATTRIBUTES",
    "INERT_ELEMENTS",
    "MODELLED_PROPERTIES",
    "TEXT_ELEMENTS",
    "is_event_handler",
    "is_script_url",
    "property_verdict",
    "sanitized",
]
