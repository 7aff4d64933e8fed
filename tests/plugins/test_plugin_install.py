"""A real third-party plugin, built and pip-installed into a folder, shows up in
``deepmorph list-primitives`` and makes its element readable — no test-only registration."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from tests.plugins.installing import install_plugin, run_python

PLUGIN_PYPROJECT = """
[build-system]
requires = ["setuptools>=68"]
build-backend = "setuptools.build_meta"

[project]
name = "deepmorph-square-test"
version = "0.3.1"
dependencies = []

[project.entry-points.deepmorph]
square_test = "deepmorph_square_test"
"""

PLUGIN_CODE = '''
"""A toy primitive: <square x y size> drawn as a closed polygon."""
import numpy as np
from deepmorph_core import hookimpl
from deepmorph_primitives.polyline import Polygon


class Square(Polygon):
    kind = "square"
    tags = ("square",)
    morphable = "4 corners"

    @classmethod
    def from_element(cls, element, reader):
        x, y, s = (reader.number(element, k) for k in ("x", "y", "size"))
        return cls(np.array([[x, y], [x + s, y], [x + s, y + s], [x, y + s]]), 0)


@hookimpl
def deepmorph_register_primitives(register):
    register.primitive(Square)
'''


@pytest.fixture(scope="module")
def installed_plugin(tmp_path_factory) -> Path:
    return install_plugin(tmp_path_factory, PLUGIN_PYPROJECT, "deepmorph_square_test", PLUGIN_CODE)


def run_cli(site: Path, *args: str) -> subprocess.CompletedProcess:
    code = "import sys; from deepmorph.cli import main; sys.argv = ['deepmorph', *sys.argv[1:]]; main()"
    return run_python(site, "-c", code, *args)


def test_installed_plugin_is_listed_and_used(installed_plugin: Path, tmp_path: Path) -> None:
    listing = run_cli(installed_plugin, "list-primitives", "--json")
    assert listing.returncode == 0, listing.stderr
    rows = {row["kind"]: row for row in json.loads(listing.stdout)}
    assert rows["square"]["plugin"] == "square_test"
    assert rows["square"]["distribution"] == "deepmorph-square-test 0.3.1"
    assert rows["circle"]["distribution"].startswith("deepmorph ")

    svg = tmp_path / "sq.svg"
    svg.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10"><square x="2" y="2" size="5" fill="black"/></svg>'
    )
    info = run_cli(installed_plugin, "inspect", str(svg), "--json", "--move", "0.5")
    assert info.returncode == 0, info.stderr
    prims = json.loads(info.stdout)["primitives"]
    assert prims[0]["kind"] == "square" and prims[0]["variables"] == 8

    without = run_cli(tmp_path, "inspect", str(svg))
    assert without.returncode == 1
    assert "unsupported: element <square>" in without.stderr
    assert "Traceback" not in without.stderr
