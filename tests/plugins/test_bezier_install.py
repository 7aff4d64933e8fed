"""The ``deepmorph-bezier`` distribution, when installed, is found through the ``deepmorph``
entry-point group like any third-party plugin.

Skipped when the distribution is not installed (install it with
``pip install -e plugins/deepmorph-bezier --no-deps``).
"""

from __future__ import annotations

import importlib.metadata

import pytest

import deepmorph_primitives.plugin as builtin
from deepmorph_core.plugins import ENTRY_POINT_GROUP, load_registry

DISTRIBUTION = "deepmorph-bezier"


@pytest.fixture(scope="module")
def dist() -> importlib.metadata.Distribution:
    try:
        return importlib.metadata.distribution(DISTRIBUTION)
    except importlib.metadata.PackageNotFoundError:
        pytest.skip(
            f"distribution {DISTRIBUTION!r} is not installed "
            "(pip install -e plugins/deepmorph-bezier --no-deps to run this test)"
        )


def test_entry_point_is_registered(dist: importlib.metadata.Distribution) -> None:
    eps = {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}
    assert "bezier" in eps, f"installed {DISTRIBUTION} {dist.version} but no 'bezier' entry point"
    ep = eps["bezier"]
    assert ep.value == "deepmorph_bezier.plugin"
    assert ep.dist is not None and ep.dist.metadata["Name"] == DISTRIBUTION


def test_distribution_metadata(dist: importlib.metadata.Distribution) -> None:
    assert dist.version == "0.1.0"
    requires = dist.requires or []
    names = [r.split(";")[0].strip() for r in requires]
    assert names == ["deepmorph"], requires  # unpinned, and nothing else (no torch)


def test_entry_point_loads_a_working_plugin(dist: importlib.metadata.Distribution) -> None:
    (ep,) = [ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if ep.name == "bezier"]
    plugin = ep.load()
    reg = load_registry([builtin, plugin], entry_points=False)
    assert {"cubic-bezier", "quadratic-bezier"} <= set(reg.path_segments)
