"""Every Feather icon either parses or fails with a clear unsupported-feature error."""

from __future__ import annotations

import pytest

from deepmorph_core.drawing import load_drawing
from deepmorph_core.errors import UnsupportedFeatureError
from tests.conftest import FEATHER

ICONS = sorted(FEATHER.glob("*.svg"))


def parse_share(registry) -> tuple[int, list[str]]:
    parsed, failures = 0, []
    for icon in ICONS:
        try:
            drawing = load_drawing(icon, registry=registry)
        except UnsupportedFeatureError as exc:
            msg = str(exc)
            assert msg.startswith(f"{icon}:1: unsupported: "), msg
            failures.append(msg)
            continue
        assert drawing.primitives, icon
        parsed += 1
    return parsed, failures


def test_feather_without_bezier_plugin(builtin_registry, capsys) -> None:
    assert len(ICONS) == 287
    parsed, failures = parse_share(builtin_registry)
    with capsys.disabled():
        print(f"\nFeather icons parsed without the Bézier plugin: {parsed}/{len(ICONS)}")
    assert parsed == 268
    assert all("path command" in f for f in failures)


def test_feather_with_bezier_plugin(bezier_registry, capsys) -> None:
    parsed, failures = parse_share(bezier_registry)
    with capsys.disabled():
        print(f"\nFeather icons parsed with the Bézier plugin: {parsed}/{len(ICONS)}")
    assert parsed == len(ICONS), failures


@pytest.mark.parametrize("icon", ["mail", "smile", "database"])
def test_curve_icons_name_the_command(icon: str, builtin_registry) -> None:
    with pytest.raises(UnsupportedFeatureError, match=r"unsupported: path command [CcSs]"):
        load_drawing(FEATHER / f"{icon}.svg", registry=builtin_registry)


def test_what_deepmorph_writes_renders_as_the_file_did(with_bezier) -> None:
    """Every Feather icon, written back unmorphed (the modelled parts only), renders exactly as
    the icon itself: the allow-list drops nothing the icons draw. So does the bundled ghost."""
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_DRAWING
    from deepmorph_core.morph import MorphSpace
    from deepmorph_core.render import render_svg

    for icon in [*ICONS, BUNDLED_DRAWING]:
        drawing = load_drawing(icon, registry=with_bezier)
        space = MorphSpace(drawing)
        written = space.write_svg(space.values_from_unit(space.neutral_unit(1))[0])
        original = icon.read_text().replace("currentColor", "black")
        assert np.array_equal(render_svg(written.replace("currentColor", "black"), 64), render_svg(original, 64)), icon
