"""Installing a real plugin package for a test: built by pip from its source into a folder of
its own (no test-only registration), and Python run with that folder on its path."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest


def install_plugin(tmp: pytest.TempPathFactory, pyproject: str, module: str, code: str) -> Path:
    """``pip install --target`` a package of ``pyproject`` and one ``module`` holding ``code``;
    returns the folder it is installed in."""
    src = tmp.mktemp(f"{module}-src")
    (src / "pyproject.toml").write_text(pyproject)
    (src / f"{module}.py").write_text(textwrap.dedent(code))
    target = tmp.mktemp(f"{module}-site")
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--no-index",
         "--target", str(target), str(src)],
        check=True,
        capture_output=True,
    )  # fmt: skip
    return target


def run_python(site: Path, *args: str) -> subprocess.CompletedProcess:
    """``python *args`` with ``site`` first on its path, output captured as text."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True)
