"""``<style>`` stylesheets: the rules design tools write, resolved onto elements as a browser does.

Stylesheets are parsed by tinycss2 and their selectors matched by cssselect2 (the CSS engine
of WeasyPrint): class, type, id, attribute, descendant and child selectors, and lists of them.
The cascade follows CSS: a declaration from a rule beats the element's presentation attribute;
among rules, higher specificity wins, then the later rule; ``style=""`` beats rules; an
``!important`` rule beats a plain ``style=""``.

What can reach outside the file or change the picture in ways DeepMorph does not model is
refused with its line: every at-rule (``@import`` is never fetched; ``@media`` and ``@font-face``
draw nothing DeepMorph can read), and ``url()`` to anything but a gradient in the same file.
Stylesheets longer than :data:`MAX_STYLESHEET_CHARS` are refused before they are parsed.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import cssselect2
import tinycss2
from lxml import etree

#: The most stylesheet text a drawing may hold: design tools write a few kilobytes.
MAX_STYLESHEET_CHARS = 200_000
#: The most rules: each is matched against every element.
MAX_RULES = 5_000

_LOCAL_URL = re.compile(r"url\(\s*(['\"]?)#[^'\")\s]+\1\s*\)", re.IGNORECASE)


class StylesheetError(ValueError):
    """What a stylesheet holds that DeepMorph refuses; ``line`` is the file's line."""

    def __init__(self, message: str, line: int | None):
        super().__init__(message)
        self.line = line


@dataclass
class Stylesheet:
    """The rules of every ``<style>`` in a document, ready to match elements.

    Attributes:
        rule_count: how many qualified rules were read.
        elements: the ``<style>`` elements read (they draw nothing themselves).
    """

    matcher: cssselect2.Matcher = field(default_factory=cssselect2.Matcher)
    rule_count: int = 0
    elements: list[etree._Element] = field(default_factory=list)
    _wrappers: dict[etree._Element, cssselect2.ElementWrapper] = field(default_factory=dict)

    @classmethod
    def from_root(cls, root: etree._Element) -> Stylesheet:
        """Read every ``<style>`` element under ``root`` (in document order).

        Raises:
            StylesheetError: an at-rule, an unreadable selector or declaration, an outside
                ``url()``, or too much CSS; with the line in the file.
        """
        sheet = cls()
        styles = [el for el in root.iter() if isinstance(el.tag, str) and etree.QName(el).localname == "style"]
        total = 0
        for order, element in enumerate(styles):
            text = "".join(element.itertext())
            total += len(text)
            if total > MAX_STYLESHEET_CHARS:
                raise StylesheetError(
                    f"unsupported: <style> holds more than {MAX_STYLESHEET_CHARS:,} characters of CSS"
                    " (design tools write a few thousand; inline the styles or simplify)",
                    element.sourceline,
                )
            media = (element.get("media") or "all").strip().lower()
            if media not in ("all", "screen", "print", ""):
                raise StylesheetError(f"unsupported: <style media={element.get('media')!r}>", element.sourceline)
            sheet._read(text, element.sourceline or 1, order)
            sheet.elements.append(element)
        if sheet.rule_count:
            wrapper = cssselect2.ElementWrapper.from_xml_root(root)
            sheet._wrappers = {w.etree_element: w for w in wrapper.iter_subtree()}
        return sheet

    def _read(self, text: str, first_line: int, order: int) -> None:
        rules = tinycss2.parse_stylesheet(text, skip_comments=True, skip_whitespace=True)
        for rule in rules:
            line = first_line + rule.source_line - 1
            if rule.type == "error":
                raise StylesheetError(f"<style>: cannot read CSS ({rule.message})", line)
            if rule.type == "at-rule":
                what = "(nothing is fetched)" if rule.lower_at_keyword == "import" else "(only plain rules are read)"
                raise StylesheetError(f"unsupported: CSS @{rule.at_keyword} in <style> {what}", line)
            self.rule_count += 1
            if self.rule_count > MAX_RULES:
                raise StylesheetError(f"unsupported: <style> holds more than {MAX_RULES:,} rules", line)
            prelude = tinycss2.serialize(rule.prelude).strip()
            try:
                selectors = cssselect2.compile_selector_list(rule.prelude)
            except Exception as exc:  # SelectorError, and what cssselect2's nth parser raises on nonsense
                why = str(exc) if isinstance(exc, cssselect2.SelectorError) else "cannot read it"
                raise StylesheetError(f"unsupported: CSS selector {prelude[:60]!r} ({why})", line) from None
            decls = self._declarations(rule.content, line)
            for selector in selectors:
                if selector.pseudo_element is not None:
                    raise StylesheetError(f"unsupported: CSS pseudo-element in {prelude!r}", line)
                self.matcher.add_selector(selector, (selector.specificity, order, self.rule_count, decls))

    @staticmethod
    def _declarations(content: list, line: int) -> list[tuple[str, str, bool]]:
        out = []
        for decl in tinycss2.parse_blocks_contents(content, skip_comments=True, skip_whitespace=True):
            if decl.type == "error":
                raise StylesheetError(f"<style>: cannot read CSS declaration ({decl.message})", line)
            if decl.type != "declaration":
                raise StylesheetError("unsupported: nested CSS rules in <style>", line)
            value = tinycss2.serialize(decl.value).strip()
            if "url(" in value.lower() and not _LOCAL_URL.fullmatch(value.split()[0] if value else ""):
                raise StylesheetError(
                    f"unsupported: {decl.lower_name}: {value[:60]!r} in <style> (only url(#id) of a gradient in"
                    " the same file is read; nothing is fetched)",
                    line,
                )
            out.append((decl.lower_name, value, bool(decl.important)))
        return out

    def declarations(self, element: etree._Element) -> tuple[dict[str, str], dict[str, str]]:
        """The declarations the rules give ``element``: ``(normal, important)``, each the
        winning value per property after specificity and order."""
        if not self.rule_count or element not in self._wrappers:
            return {}, {}
        matches = self.matcher.match(self._wrappers[element])
        normal: dict[str, str] = {}
        important: dict[str, str] = {}
        for _, _, _, (*_rank, decls) in sorted(matches, key=lambda m: m[3][:3]):
            for name, value, is_important in decls:
                (important if is_important else normal)[name] = value
        return normal, important
