"""Loading SVG bytes into an lxml tree without trusting them.

Nothing here touches the network or the file system beyond the one file asked for: no DTD is
loaded, no entity is expanded (documents that declare entities are refused outright, which
stops "billion laughs" and external-entity attacks before the parser sees them), and size,
element count and nesting depth are capped.
"""

from __future__ import annotations

import re
from pathlib import Path

from lxml import etree

from deepmorph_core.errors import SvgError

SVG_NS = "http://www.w3.org/2000/svg"
MAX_BYTES = 8 * 1024 * 1024
MAX_ELEMENTS = 20_000
MAX_DEPTH = 64

_ENTITY = re.compile(rb"<!ENTITY", re.IGNORECASE)


def _line_of(data: bytes, offset: int) -> int:
    return data.count(b"\n", 0, offset) + 1


def read_svg_bytes(source: str | Path) -> bytes:
    """Read an SVG file, refusing huge files before reading them."""
    path = Path(source)
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise SvgError(f"cannot read file: {exc.strerror or exc}", path) from None
    if not path.is_file():
        raise SvgError("not a regular file", path)
    if size > MAX_BYTES:
        raise SvgError(f"file is {size} bytes; the limit is {MAX_BYTES} bytes", path)
    return path.read_bytes()


def parse_svg_bytes(data: bytes, label: str) -> etree._Element:
    """Parse SVG bytes into the root element, or raise one :class:`SvgError` saying where.

    Args:
        data: the document.
        label: what to call the source in messages (usually its path).
    """
    if len(data) > MAX_BYTES:
        raise SvgError(f"document is {len(data)} bytes; the limit is {MAX_BYTES} bytes", label)
    m = _ENTITY.search(data)
    if m:
        raise SvgError(
            "entity declarations are not allowed (they can expand without bound or read external files)",
            label,
            _line_of(data, m.start()),
        )
    parser = etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,
        remove_comments=False,
        remove_pis=True,
    )
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        msg = re.sub(r",? line \d+, column \d+.*$", "", str(exc.msg or exc))
        if "Excessive depth" in msg:
            raise SvgError("elements nested too deeply (over 256 levels)", label, exc.lineno) from None
        raise SvgError(f"malformed XML: {msg}", label, exc.lineno) from None
    except ValueError as exc:
        raise SvgError(f"malformed XML: {exc}", label) from None
    if root is None:
        raise SvgError("empty document", label)
    if etree.QName(root).localname != "svg" or etree.QName(root).namespace not in (SVG_NS, None):
        raise SvgError(f"root element is <{etree.QName(root).localname}>, not <svg>", label, root.sourceline)
    count = 0
    for el in root.iter():
        count += 1
        if count > MAX_ELEMENTS:
            raise SvgError(f"more than {MAX_ELEMENTS} elements", label, el.sourceline)
    _check_depth(root, label)
    return root


def _check_depth(root: etree._Element, label: str) -> None:
    stack = [(root, 1)]
    while stack:
        el, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise SvgError(f"elements nested deeper than {MAX_DEPTH} levels", label, el.sourceline)
        stack.extend((child, depth + 1) for child in el)
