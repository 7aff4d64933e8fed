"""DeepMorph core: plugin spine, SVG reading and writing, bound-specs, morphs and the soft
rasterizer. ``hookimpl`` is what plugins decorate their hook functions with."""

from deepmorph_core.hookspecs import hookimpl

__version__ = "0.1.0"

__all__ = ["hookimpl", "__version__"]
