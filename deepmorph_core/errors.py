"""Error types: every user-facing failure is one of these, with a location when there is one.

The CLI prints ``str(error)`` and exits non-zero; it never shows a traceback for these.
"""

from __future__ import annotations

from pathlib import Path


class DeepMorphError(Exception):
    """Base class of every error DeepMorph reports to a user."""


class DeepMorphWarning(UserWarning):
    """Something a user should know that does not stop the work (an optional output left out, a
    stored ONNX graph that cannot be used); the command line prints it as one ``warning:`` line."""


class SvgError(DeepMorphError):
    """A drawing that cannot be read or used, with the file and line it comes from.

    Args:
        message: what is wrong, in words a user understands.
        source: the file (or a label such as ``<string>``) the SVG came from.
        line: the 1-based source line of the offending element, when known.
    """

    def __init__(self, message: str, source: str | Path | None = None, line: int | None = None):
        self.message = message
        self.source = str(source) if source is not None else None
        self.line = line
        super().__init__(self._format())

    def _format(self) -> str:
        where = self.source or "<svg>"
        if self.line is not None:
            where = f"{where}:{self.line}"
        return f"{where}: {self.message}"


class UnsupportedFeatureError(SvgError):
    """A valid SVG feature that DeepMorph (with the plugins loaded) cannot morph or render."""


class BoundsError(SvgError):
    """A ``dm:`` bound-spec attribute that is malformed or out of range."""


class PluginError(DeepMorphError):
    """A plugin that registers something invalid, or a hook implementation that matches no hook."""
