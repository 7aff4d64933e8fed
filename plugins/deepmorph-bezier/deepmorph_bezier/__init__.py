"""DeepMorph plugin adding cubic (``C S``) and quadratic (``Q T``) Bézier path segments.

The plugin module registered under the ``deepmorph`` entry-point group is
:mod:`deepmorph_bezier.plugin`; the segment kinds live in :mod:`deepmorph_bezier.segments`.
"""

from __future__ import annotations

from deepmorph_bezier.segments import CubicBezierSegment, QuadraticBezierSegment

__version__ = "0.1.0"

__all__ = ["CubicBezierSegment", "QuadraticBezierSegment", "__version__"]
