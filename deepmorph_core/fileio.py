"""Writing files so that a crash or Ctrl-C never leaves a half-written one behind."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from deepmorph_core.errors import DeepMorphError


def atomic_write(path: str | Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, flush it to disk, then rename it.

    The file gets ordinary permissions (0666 less the umask), not the temporary file's 0600.

    Raises:
        DeepMorphError: the folder cannot be created or written.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot write: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def refuse_non_folder(path: str | Path, label: str | None = None) -> None:
    """One clear error when ``path`` exists but is not a folder (``label`` names it, default
    the path), before any work goes into what would be written there."""
    if Path(path).exists() and not Path(path).is_dir():
        raise DeepMorphError(f"{label or path}: exists and is not a folder")


def output_folder(path: str | Path, label: str | None = None) -> Path:
    """``path`` as a folder to write into, created when missing.

    Raises:
        DeepMorphError: it is a file, or cannot be created.
    """
    path = Path(path)
    refuse_non_folder(path, label)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeepMorphError(f"{label or path}: cannot create the folder: {exc.strerror or exc}") from None
    return path


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name the same file (the same path resolved, or one linked to the other)."""
    a, b = Path(a), Path(b)
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def refuse_to_overwrite(target: str | Path, option: str, inputs: Iterable[tuple[str, str | Path | None]]) -> None:
    """One clear error, before any work, when the output ``target`` (given with ``option``) would
    replace one of a command's inputs (``inputs``: pairs of what it is and its path): the model
    file or the photo it names would be lost.

    Raises:
        DeepMorphError: ``target`` is one of ``inputs``.
    """
    for what, path in inputs:
        if path is not None and same_file(target, path):
            raise DeepMorphError(f"{option} {target}: refusing to overwrite the {what} ({path})")
