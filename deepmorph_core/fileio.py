"""Writing files so that a crash, a kill or a full disk never leaves a half-written one behind.

Every output is written to a temporary file beside its target, flushed to disk, then renamed
over it (atomic on POSIX): readers see the old file or the new one, never a mix. Outputs that
belong together (an SVG and its PNG) are written as a group, all or none. A target that exists
but is not a regular file (a folder, a device, a pipe, a link) is never replaced. A missing
parent folder is created. Temporary files are named ``.dm-<pid>-<random>.tmp``; one left behind
by a killed process is removed by the next write into that folder, once its process is gone.

Every failure is one :class:`~deepmorph_core.errors.DeepMorphError` naming the path and the
reason (no space left, permission denied, a name too long ...).
"""

from __future__ import annotations

import os
import re
import secrets
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path

from deepmorph_core.errors import DeepMorphError

_TEMP = re.compile(r"^\.dm-(\d+)-[0-9a-z_]+\.tmp$")
MAX_NAME_BYTES = 255  # a file name's length on the usual file systems


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def check_target(path: str | Path, label: str | None = None) -> Path:
    """``path`` as a place a file may be written: refused, before any work, when it exists and is
    not a regular file, or its name is too long, or its folder cannot be made or written.

    Returns:
        ``path`` as a :class:`Path`.

    Raises:
        DeepMorphError: naming ``label`` (default: the path) and why.
    """
    path = Path(path)
    name = label or str(path)
    if len(os.fsencode(path.name)) > MAX_NAME_BYTES:
        raise DeepMorphError(f"{name}: the file name is longer than {MAX_NAME_BYTES} bytes")
    try:
        info = path.lstat()
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise DeepMorphError(f"{name}: cannot write: {_reason(exc)}") from None
    if info is not None and not stat.S_ISREG(info.st_mode):
        what = "a folder" if stat.S_ISDIR(info.st_mode) else "a link" if stat.S_ISLNK(info.st_mode) else "not a file"
        raise DeepMorphError(f"{name}: exists and is {what}; refusing to replace it")
    folder = path.parent
    existing = next((p for p in (folder, *folder.parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        raise DeepMorphError(f"{name}: cannot write: {existing} is not a folder")
    if existing is not None and not os.access(existing, os.W_OK | os.X_OK):
        raise DeepMorphError(f"{name}: cannot write: permission denied in {existing}")
    return path


def _clean_stray_temps(folder: Path) -> None:
    """Remove temporary files of processes that no longer run (a ``kill -9`` mid-write)."""
    try:
        with os.scandir(folder) as listing:
            entries = list(listing)
    except OSError:
        return
    for entry in entries:
        m = _TEMP.match(entry.name)
        if not m or int(m.group(1)) == os.getpid():
            continue
        try:
            os.kill(int(m.group(1)), 0)
        except ProcessLookupError:
            Path(entry.path).unlink(missing_ok=True)
        except (PermissionError, OverflowError, ValueError):
            continue  # another user's process, or no such pid at all: leave the file alone


def _temp_beside(path: Path) -> tuple[int, Path]:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".dm-{os.getpid()}-{secrets.token_hex(3)}", suffix=".tmp")
    return fd, Path(tmp)


def _write_temp(path: Path, data: bytes) -> Path:
    """``data`` in a flushed temporary file beside ``path`` (ordinary permissions); its path."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _clean_stray_temps(path.parent)
        fd, tmp = _temp_beside(path)
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot write: {_reason(exc)}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise DeepMorphError(f"{path}: cannot write: {_reason(exc)}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return tmp


def atomic_write(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all (see the module).

    Raises:
        DeepMorphError: the target is not a regular file, or the folder cannot be created or
            written (full disk, read-only, permissions, a name too long).
    """
    atomic_write_all([(path, data)])


def atomic_write_all(files: Iterable[tuple[str | Path, bytes]]) -> None:
    """Write several files as one: every one whole, or (on any failure) none of them changed.

    All are written to temporary files first; then each existing target is moved aside, the new
    files are renamed into place, and the old ones are deleted. A failure at any point puts the
    old files back and removes the new ones.

    Raises:
        DeepMorphError: as :func:`atomic_write`, naming the file that failed.
    """
    jobs = [(check_target(path), data) for path, data in files]
    temps: list[tuple[Path, Path]] = []
    try:
        for path, data in jobs:
            temps.append((path, _write_temp(path, data)))
    except BaseException:
        for _, tmp in temps:
            tmp.unlink(missing_ok=True)
        raise
    moved: list[tuple[Path, Path]] = []  # (target, its old file set aside)
    placed: list[Path] = []
    try:
        for path, tmp in temps:
            if len(temps) > 1 and path.exists():
                fd, aside = _temp_beside(path)
                os.close(fd)
                os.replace(path, aside)
                moved.append((path, aside))
            os.replace(tmp, path)
            placed.append(path)
    except BaseException as exc:
        for path in placed:
            if not any(path == target for target, _ in moved):
                path.unlink(missing_ok=True)
        for target, aside in moved:
            os.replace(aside, target)
        for _, tmp in temps:
            tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise DeepMorphError(f"{placed[-1] if placed else temps[0][0]}: cannot write: {_reason(exc)}") from None
        raise
    for _, aside in moved:
        aside.unlink(missing_ok=True)


def append_line(path: str | Path, line: str) -> None:
    """Append one line to a log file (a line cut by a crash is what log readers skip).

    Raises:
        DeepMorphError: the file cannot be written (full disk, permissions).
    """
    try:
        with open(path, "a") as fh:
            fh.write(line + "\n")
    except OSError as exc:
        raise DeepMorphError(f"{path}: cannot write: {_reason(exc)}") from None


def refuse_non_folder(path: str | Path, label: str | None = None) -> None:
    """One clear error when ``path`` exists but is not a folder (``label`` names it, default
    the path), before any work goes into what would be written there."""
    if Path(path).exists() and not Path(path).is_dir():
        raise DeepMorphError(f"{label or path}: exists and is not a folder")


def output_folder(path: str | Path, label: str | None = None) -> Path:
    """``path`` as a folder to write into, created when missing.

    Raises:
        DeepMorphError: it is a file, or cannot be created or written.
    """
    path = Path(path)
    refuse_non_folder(path, label)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeepMorphError(f"{label or path}: cannot create the folder: {_reason(exc)}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise DeepMorphError(f"{label or path}: cannot write into the folder: permission denied")
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
    replace one of a command's inputs (``inputs``: pairs of what it is and its path), or cannot
    be written at all (:func:`check_target`).

    Raises:
        DeepMorphError: ``target`` is one of ``inputs``, or not a place a file may be written.
    """
    for what, path in inputs:
        if path is not None and same_file(target, path):
            raise DeepMorphError(f"{option} {target}: refusing to overwrite the {what} ({path})")
    check_target(target, f"{option} {target}")


__all__ = [
    "MAX_NAME_BYTES",
    "append_line",
    "atomic_write",
    "atomic_write_all",
    "check_target",
    "output_folder",
    "refuse_non_folder",
    "refuse_to_overwrite",
    "same_file",
]
