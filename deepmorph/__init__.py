"""DeepMorph: hide bitstrings in vector drawings, and read them back from photos.

This package is the public API, a facade over ``deepmorph_core`` (drawings, codec, networks,
training) and ``deepmorph_detect`` (the photo chain)::

    import deepmorph

    model = deepmorph.load("model.dmm")
    code = model.encode(0xA1B2C3)          # an int, hex text, bytes or bits -> deepmorph.Code
    code.save("code.pdf", width_mm=50)     # or .svg / .png; code.pdf(), code.png(), code.svg
    for found in model.decode("photo.jpg"):   # a path, a PIL image or an RGB array (bgr=True)
        print(found.payload.hex, found.ok, found.pose)
    reading = model.decode_sequence("clip.mp4")   # a video or a folder of frames, readings fused

Names are imported on first use, so ``import deepmorph`` (and ``python -m deepmorph --help``)
does not wait for torch.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from deepmorph_core import __version__

if TYPE_CHECKING:
    from deepmorph.model import Model, load, train
    from deepmorph_core.code import Code
    from deepmorph_core.errors import (
        DeepMorphError,
        DeepMorphWarning,
        PluginError,
        SvgError,
        UnsupportedFeatureError,
    )
    from deepmorph_core.image_io import ImageLike
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_core.payload import Payload, PayloadLike
    from deepmorph_detect.camera import Camera
    from deepmorph_detect.reading import SequenceReading
    from deepmorph_detect.results import Located, Pose

_WHERE = {
    "Model": "deepmorph.model",
    "load": "deepmorph.model",
    "train": "deepmorph.model",
    "Code": "deepmorph_core.code",
    "DeepMorphError": "deepmorph_core.errors",
    "DeepMorphWarning": "deepmorph_core.errors",
    "PluginError": "deepmorph_core.errors",
    "SvgError": "deepmorph_core.errors",
    "UnsupportedFeatureError": "deepmorph_core.errors",
    "ImageLike": "deepmorph_core.image_io",
    "MorphableDrawing": "deepmorph_core.morphable",
    "Payload": "deepmorph_core.payload",
    "PayloadLike": "deepmorph_core.payload",
    "Camera": "deepmorph_detect.camera",
    "SequenceReading": "deepmorph_detect.reading",
    "Located": "deepmorph_detect.results",
    "Pose": "deepmorph_detect.results",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'deepmorph' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])


__all__ = [
    "Camera",
    "Code",
    "DeepMorphError",
    "DeepMorphWarning",
    "ImageLike",
    "Located",
    "Model",
    "MorphableDrawing",
    "Payload",
    "PayloadLike",
    "PluginError",
    "Pose",
    "SequenceReading",
    "SvgError",
    "UnsupportedFeatureError",
    "__version__",
    "load",
    "train",
]
