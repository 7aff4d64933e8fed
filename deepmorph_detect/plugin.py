"""The built-in detector's plugin module, loaded through the ``deepmorph`` entry point
(``builtin_detectors``) exactly as third-party plugins are."""

from __future__ import annotations

from deepmorph_core import hookimpl
from deepmorph_core.plugins import Register
from deepmorph_detect.locate import CentreNetDetector


@hookimpl
def deepmorph_register_detectors(register: Register) -> None:
    register.detector(CentreNetDetector)
