"""Loading SVG bytes into an lxml tree without trusting them.

Nothing here touches the network or the file system beyond the one file asked for: no DTD is
loaded and no entity is expanded. A document that declares entities ("billion laughs",
external entities) or has an internal DTD subset is refused outright, whatever its encoding; a
public DOCTYPE that only names the SVG DTD (older editors write one) is never fetched, and
nothing DeepMorph writes carries it. Size, element count and nesting depth are capped.
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

# an entity declaration in UTF-8/ASCII, UTF-16 (either byte order) or UTF-32: refused
# before the parser sees it (the parse below also refuses any DOCTYPE it finds)
_DECLARATIONS = [
    re.compile(re.escape(word.encode(codec)), re.IGNORECASE)
    for word in ("<!ENTITY",)
    for codec in ("ascii", "utf-16-le", "utf-16-be", "utf-32-le", "utf-32-be")
]


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
    for pattern in _DECLARATIONS:
        m = pattern.search(data)
        if m:
            raise SvgError(
                "entity declarations are not allowed (they can expand without bound or read files)",
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
    subset = root.getroottree().docinfo.internalDTD
    if subset is not None and (any(True for _ in subset.iterentities()) or any(True for _ in subset.iterelements())):
        raise SvgError("an internal DTD subset is not allowed (it can declare entities)", label, 1)
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
