"""The layering holds: core imports nothing above it, at run time included, and no package's
modules import each other in a circle (import-linter's contracts in ``pyproject.toml``)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[2]


def _lint_imports(cwd: Path, extra_path: Path | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(extra_path)} if extra_path else None
    code = "import sys; from importlinter.cli import lint_imports; sys.exit(lint_imports(no_cache=True, no_logo=True))"
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=120, env=env)


def test_the_packages_keep_their_layers_and_have_no_import_cycles() -> None:
    result = _lint_imports(ROOT)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "0 broken" in result.stdout


def test_the_contracts_catch_an_upward_import_hidden_in_a_function(tmp_path: Path) -> None:
    """The same contracts, on a copy of the layout whose core imports the photo chain inside a
    function (as core once did from 16 places): they fail, naming the import."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    for package in config["root_packages"]:
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / "deepmorph_detect" / "locate.py").write_text("class Locator: ...\n")
    (tmp_path / "deepmorph_core" / "model.py").write_text(
        "def decode_image(image):\n    from deepmorph_detect.locate import Locator\n\n    return Locator\n"
    )
    lines = [f"root_packages = {config['root_packages']!r}", "exclude_type_checking_imports = true"]
    for contract in config["contracts"]:
        lines += ["", "[[tool.importlinter.contracts]]", *(f"{k} = {v!r}" for k, v in contract.items())]
    (tmp_path / "pyproject.toml").write_text("[tool.importlinter]\n" + "\n".join(lines).replace("'", '"') + "\n")
    result = _lint_imports(tmp_path, tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "deepmorph_core.model -> deepmorph_detect.locate" in result.stdout
