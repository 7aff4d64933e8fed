"""The docs stay a manual: every module is on the architecture's map, every hook is documented
(datasette's habit), and the README stays short enough to read."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from deepmorph_core import hookspecs

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("deepmorph", "deepmorph_core", "deepmorph_primitives", "deepmorph_augment", "deepmorph_detect")
README_MAX_LINES = 250


def _sections(text: str) -> dict[str, str]:
    """The architecture doc's module-map sections, by the package each one is headed with."""
    parts = re.split(r"^### `([a-z_]+)`.*$", text, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def test_every_module_is_on_the_architecture_map() -> None:
    sections = _sections((ROOT / "docs" / "architecture.md").read_text())
    missing = []
    for package in PACKAGES:
        listed = set(re.findall(r"`([\w/]+\.py)`", sections.get(package, "")))
        for path in sorted((ROOT / package).rglob("*.py")):
            module = path.relative_to(ROOT / package).as_posix()
            if module not in listed:
                missing.append(f"{package}/{module}")
    assert not missing, f"docs/architecture.md does not list: {', '.join(missing)}"


def test_the_map_lists_no_module_that_is_gone() -> None:
    sections = _sections((ROOT / "docs" / "architecture.md").read_text())
    gone = [
        f"{package}/{name}"
        for package in PACKAGES
        for name in re.findall(r"`([\w/]+\.py)`", sections.get(package, ""))
        if not (ROOT / package / name).is_file()
    ]
    assert not gone, f"docs/architecture.md lists modules that do not exist: {', '.join(gone)}"


def test_every_hook_is_documented() -> None:
    text = (ROOT / "docs" / "plugins.md").read_text()
    hooks = [name for name, _ in inspect.getmembers(hookspecs, inspect.isfunction) if name.startswith("deepmorph_")]
    assert hooks, "no hooks found"
    undocumented = [name for name in hooks if f"`{name}(" not in text]
    assert not undocumented, f"docs/plugins.md does not document: {', '.join(undocumented)}"


def test_the_readme_is_a_short_manual() -> None:
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines; at most {README_MAX_LINES}"
