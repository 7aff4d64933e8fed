"""DeepMorph core, the bottom layer the other packages build on: the plugin spine, SVG reading
and writing, bound-specs, morphs and the soft rasterizer, the payload codec, the networks and
their training, model bundles, photo preprocessing and the command-line frame. ``hookimpl`` is
what plugins decorate their hook functions with."""

from deepmorph_core.hookspecs import hookimpl

__version__ = "0.1.0"

__all__ = ["hookimpl", "__version__"]
