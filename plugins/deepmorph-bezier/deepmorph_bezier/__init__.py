"""DeepMorph plugin adding cubic (``C S``) and quadratic (``Q T``) Bézier path segments.

The plugin module registered under the ``deepmorph`` entry-point group is
:mod:`deepmorph_bezier.plugin`; the segment kinds live in :mod:`deepmorph_bezier.segments`
(imported only when DeepMorph asks for primitives, so loading the plugin stays cheap).
"""

from __future__ import annotations

__version__ = "0.1.0"

__all__ = ["__version__"]
