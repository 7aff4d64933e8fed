"""DeepMorph core, the bottom layer the other packages build on: the plugin spine, SVG reading
and writing, bound-specs, morphs and the soft rasterizer, the payload codec, the networks and
their training, model bundles and photo preprocessing. The command line is the application's
(:mod:`deepmorph.cli`). ``hookimpl`` is what plugins decorate their hook functions with."""

import os

from deepmorph_core.hookspecs import hookimpl

# OpenCV refuses an image whose header claims more pixels than this before decoding it, for every
# format it reads; it reads the setting once, when it is first imported (image_io.MAX_IMAGE_PIXELS)
os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", "80000000")

__version__ = "0.1.0"

__all__ = ["hookimpl", "__version__"]
