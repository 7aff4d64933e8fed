"""The payload registry: what each payload of a model means, kept in a local SQLite file.

A model hides an integer; the registry maps ``(model, payload)`` to a URL or a short text that
``deepmorph decode --registry`` shows beside the payload it read. Entries of different models
never mix: a model is known by :func:`model_key`, a SHA-256 of what decides the codes it prints
(the drawing, its bound defaults, the codec and the encoder's weights), so a model whose decoder
was tuned or that gained a detector keeps its entries, and a model trained again does not
inherit another's.

The file (default ``~/.deepmorph/registry.sqlite3``, or ``$DEEPMORPH_HOME/registry.sqlite3``)
is in WAL mode with a busy timeout, and every write is one ``BEGIN IMMEDIATE`` transaction:
processes may add entries at the same time, and each waits its turn instead of failing. Every
failure (a payload that does not fit the model, a URL that is not http(s), a duplicate, a file
that is not a registry, a folder that cannot be written) is one
:class:`~deepmorph_core.errors.DeepMorphError`, never a traceback.

Nothing here imports torch until a model's bundle has to be read.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import os
import sqlite3
import time
import urllib.parse
from collections.abc import Callable, Iterator, Mapping
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal, Union

from deepmorph_core.errors import DeepMorphError
from deepmorph_core.payload import Payload

if TYPE_CHECKING:
    from torch import Tensor

    from deepmorph.model import Model
    from deepmorph_core.bundle import BundleMeta
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.payload import PayloadLike

Kind = Literal["url", "text"]
ExportFormat = Literal["csv", "json"]

KINDS: tuple[str, ...] = ("url", "text")
EXPORT_FORMATS: dict[str, ExportFormat] = {".csv": "csv", ".json": "json"}
MAX_TARGET_CHARS = 2000  # a URL or a text
MAX_NOTE_CHARS = 200
BUSY_TIMEOUT_S = 30.0  # how long a write waits for another process's transaction
APPLICATION_ID = 0x444D5247  # "DMRG" in the SQLite header: this file is a DeepMorph registry
SCHEMA_VERSION = 1
FORMAT = "deepmorph-registry/1"  # the JSON export
CSV_FIELDS = ("model", "drawing", "payload_bits", "payload", "kind", "target", "note", "created", "updated")

_SCHEMA = """
CREATE TABLE models (
    id TEXT PRIMARY KEY,
    drawing TEXT NOT NULL,
    payload_bits INTEGER NOT NULL
);
CREATE TABLE entries (
    model TEXT NOT NULL REFERENCES models(id),
    payload TEXT NOT NULL,
    kind TEXT NOT NULL CHECK (kind IN ('url', 'text')),
    target TEXT NOT NULL,
    note TEXT,
    created TEXT NOT NULL,
    updated TEXT,
    UNIQUE (model, payload)
);
"""
_HEADER = (
    "SELECT (SELECT application_id FROM pragma_application_id), (SELECT user_version FROM pragma_user_version), "
    "(SELECT count(*) FROM sqlite_master)"
)
_SELECT = (
    "SELECT e.model, m.drawing, m.payload_bits, e.payload, e.kind, e.target, e.note, e.created, e.updated "
    "FROM entries e JOIN models m ON m.id = e.model"
)
# control characters and the bidirectional overrides that make text read other than it is
_REFUSED = {*map(chr, range(0x20)), *map(chr, range(0x7F, 0xA0)), *map(chr, range(0x202A, 0x202F))}
_REFUSED |= set(map(chr, range(0x2066, 0x206A)))


def default_path() -> Path:
    """Where the registry lives unless told: ``$DEEPMORPH_HOME/registry.sqlite3`` when that
    variable is set, else ``~/.deepmorph/registry.sqlite3``."""
    home = os.environ.get("DEEPMORPH_HOME")
    return (Path(home) if home else Path.home() / ".deepmorph") / "registry.sqlite3"


@dataclass(frozen=True)
class ModelKey:
    """A model as the registry knows it.

    Attributes:
        id: 64 hex digits, :func:`model_key`'s fingerprint.
        drawing: the drawing's name (shown, not part of the identity).
        payload_bits: the size of the model's payloads.
    """

    id: str
    drawing: str
    payload_bits: int

    @property
    def short(self) -> str:
        """The first 12 digits of :attr:`id`, as text output shows it."""
        return self.id[:12]

    def __str__(self) -> str:
        return f"{self.drawing} (model {self.short})"


#: What registry methods accept as a model: a key, a loaded model (``deepmorph.Model`` or
#: ``DeepMorphModel``), or the path of its bundle.
ModelLike = Union[ModelKey, "Model", "DeepMorphModel", str, Path]


def _fingerprint(meta: BundleMeta, tensors: dict[str, Tensor]) -> str:
    from deepmorph_core.graphs import weights_fingerprint

    printed = {
        "drawing_svg": meta.drawing_svg,
        "bounds_defaults": meta.bounds_defaults,
        "geometry": meta.geometry,
        "codec": meta.codec.model_dump(mode="json"),
    }
    digest = hashlib.sha256(b"deepmorph-registry-model/1\0")
    digest.update(json.dumps(printed, sort_keys=True, separators=(",", ":")).encode())
    digest.update(b"\0" + weights_fingerprint(tensors, "encoder").encode())
    return digest.hexdigest()


def model_key(model: ModelLike) -> ModelKey:
    """The registry's key of a model: its bundle's path, a loaded model, or a key (returned as is).

    The id is a SHA-256 of the drawing's SVG, its bound defaults and geometry version, the codec
    and the encoder's weights: what decides the code printed for a payload. Training a
    detector or tuning the decoder keeps it; training again changes it.

    Raises:
        DeepMorphError: a path that is not a usable model bundle, or another type.
    """
    if isinstance(model, ModelKey):
        return model
    if isinstance(model, (str, Path)):
        from deepmorph_core.bundle import load_bundle

        meta, tensors = load_bundle(model)
        if not any(k.startswith("encoder.") for k in tensors):
            raise DeepMorphError(f"{model}: not a usable DeepMorph model file (no encoder weights)")
        return ModelKey(_fingerprint(meta, tensors), meta.drawing_name, meta.codec.payload_bits)
    bundle = getattr(model, "bundle", model)  # deepmorph.Model wraps a DeepMorphModel
    meta, tensors = getattr(bundle, "meta", None), getattr(bundle, "tensors", None)
    if meta is None or not callable(tensors):
        raise DeepMorphError(
            f"a model for the registry is a bundle's path or a loaded model, not {type(model).__name__}"
        )
    return ModelKey(_fingerprint(meta, tensors()), meta.drawing_name, meta.codec.payload_bits)


@dataclass(frozen=True)
class Entry:
    """One payload's meaning.

    Attributes:
        model: the model's id (:attr:`ModelKey.id`).
        drawing: the model's drawing name.
        payload_bits: the model's payload size.
        payload: the payload in hex (``0x`` and upper-case digits, as ``Payload.hex``).
        kind: ``url`` or ``text``.
        target: the URL or the text.
        note: a note for whoever keeps the registry, or ``None``.
        created: when it was added (UTC, ISO 8601).
        updated: when it was last replaced, or ``None``.
    """

    model: str
    drawing: str
    payload_bits: int
    payload: str
    kind: Kind
    target: str
    note: str | None
    created: str
    updated: str | None

    @property
    def payload_value(self) -> Payload:
        """The payload as a :class:`~deepmorph_core.payload.Payload` (``.int``, ``.bits`` ...)."""
        return Payload.of(self.payload, self.payload_bits)

    def to_json(self) -> dict[str, Any]:
        """The entry as JSON values; the payload as ``{"hex", "bits"}``, as ``encode`` and ``decode`` give it."""
        data = asdict(self)
        data["payload"] = self.payload_value.to_json()
        return data


def check_target(target: str, kind: str) -> str:
    """``target`` checked for its kind: a URL must be ``http`` or ``https`` with a host (no
    ``javascript:``, ``data:`` or ``file:``, no user name or password before the host, no
    spaces); a text must be non-empty. Both hold at most :data:`MAX_TARGET_CHARS` characters and
    no control characters (a text may hold line breaks and tabs). Surrounding blanks are dropped.

    Raises:
        DeepMorphError: saying what is wrong.
    """
    if kind not in KINDS:
        raise DeepMorphError(f"an entry's kind is 'url' or 'text', not {kind!r}")
    if not isinstance(target, str):
        raise DeepMorphError(f"a registry {kind} is text, not {type(target).__name__}")
    value = target.strip()
    shown = repr(value[:60] + ("..." if len(value) > 60 else ""))
    if not value:
        raise DeepMorphError(f"an empty {kind}; give the {'URL' if kind == 'url' else 'text'} the payload stands for")
    if len(value) > MAX_TARGET_CHARS:
        raise DeepMorphError(f"{shown}: {len(value)} characters; a registry {kind} holds at most {MAX_TARGET_CHARS}")
    allowed = {"\n", "\t"} if kind == "text" else set()
    bad = next((c for c in value if c in _REFUSED - allowed), None)
    if bad is not None:
        raise DeepMorphError(f"{shown}: holds the control character U+{ord(bad):04X}")
    if kind == "text":
        return value
    if any(c.isspace() for c in value) or "\\" in value:
        raise DeepMorphError(f"{shown}: a URL holds no spaces or backslashes (write them %-encoded)")
    try:
        parts = urllib.parse.urlsplit(value)
        parts.port  # noqa: B018 - raises ValueError on a port that is not a number
    except ValueError as exc:
        raise DeepMorphError(f"{shown}: not a URL ({exc})") from None
    if parts.scheme.lower() not in ("http", "https"):
        what = f"not {parts.scheme.lower()}:" if parts.scheme else "and this has no scheme"
        raise DeepMorphError(
            f"{shown}: a registry URL starts with http:// or https://, {what} (store text with --text)"
        )
    if not parts.hostname:
        raise DeepMorphError(f"{shown}: the URL names no host")
    if "@" in parts.netloc:
        raise DeepMorphError(f"{shown}: a user name or password before the host is refused (it hides the real host)")
    return value


def _check_note(note: str | None) -> str | None:
    if note is None:
        return None
    if not isinstance(note, str):
        raise DeepMorphError(f"a note is text, not {type(note).__name__}")
    value = note.strip()
    if len(value) > MAX_NOTE_CHARS:
        raise DeepMorphError(f"a note holds at most {MAX_NOTE_CHARS} characters, not {len(value)}")
    bad = next((c for c in value if c in _REFUSED), None)
    if bad is not None:
        raise DeepMorphError(f"the note holds the control character U+{ord(bad):04X}")
    return value or None


def _now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def _busy(exc: sqlite3.OperationalError) -> bool:
    text = str(exc).lower()
    return "locked" in text or "busy" in text


class PayloadRegistry:
    """The payload registry in the SQLite file at ``path`` (default :func:`default_path`).

    The file and its folders are made on the first write; reading a registry that does not
    exist yet finds nothing. Each call opens the file, does its work in one transaction and
    closes it: a registry may be shared by processes, and by threads through their own objects.

    Args:
        path: the registry file.
        timeout: seconds a write waits for the others before it gives up (one clear error).
    """

    def __init__(self, path: str | Path | None = None, *, timeout: float = BUSY_TIMEOUT_S) -> None:
        self.path = Path(path) if path is not None else default_path()
        self.timeout = timeout

    def __repr__(self) -> str:
        return f"PayloadRegistry({str(self.path)!r})"

    # ---- reading

    def get(self, model: ModelLike, payload: PayloadLike) -> Entry | None:
        """The entry of ``payload`` (any form :meth:`Payload.of` reads, a decoded ``found.payload``
        too) for ``model``, or ``None``.

        Raises:
            DeepMorphError: the payload does not fit the model, or the file is not a registry.
        """
        key = model_key(model)
        hex_payload = Payload.of(payload, key.payload_bits).hex
        rows = self._read(f"{_SELECT} WHERE e.model = ? AND e.payload = ?", (key.id, hex_payload))
        return rows[0] if rows else None

    def list(self, model: ModelLike | None = None) -> list[Entry]:  # noqa: A003 - the registry's verb
        """Every entry (of ``model`` only, when given), by drawing, model and payload."""
        if model is None:
            return self._read(f"{_SELECT} ORDER BY m.drawing, e.model, e.payload", ())
        key = model_key(model)
        return self._read(f"{_SELECT} WHERE e.model = ? ORDER BY e.payload", (key.id,))

    def count(self, model: ModelLike | None = None) -> int:
        """How many entries there are (of ``model`` only, when given); checks the file is a registry."""
        where, args = ("", ()) if model is None else (" WHERE model = ?", (model_key(model).id,))
        with self._connection(write=False) as conn:
            return 0 if conn is None else int(conn.execute(f"SELECT count(*) FROM entries{where}", args).fetchone()[0])

    # ---- writing

    def add(
        self,
        model: ModelLike,
        payload: PayloadLike,
        target: str,
        kind: Kind = "url",
        note: str | None = None,
        *,
        replace: bool = False,
    ) -> Entry:
        """Give ``payload`` of ``model`` a meaning: a URL (``kind="url"``, http or https) or a text.

        Returns:
            The entry as stored (``updated`` is set when it replaced one).

        Raises:
            DeepMorphError: the payload does not fit the model's payload bits, the URL or text
                is refused (:func:`check_target`), the payload already has an entry and
                ``replace`` is false, or the file cannot be written.
        """
        key = model_key(model)
        hex_payload = Payload.of(payload, key.payload_bits).hex
        target = check_target(target, kind)
        note = _check_note(note)
        now = _now()
        with self._transaction() as conn:
            conn.execute(
                "INSERT OR IGNORE INTO models (id, drawing, payload_bits) VALUES (?, ?, ?)",
                (key.id, key.drawing, key.payload_bits),
            )
            old = conn.execute(
                "SELECT kind, target, created FROM entries WHERE model = ? AND payload = ?", (key.id, hex_payload)
            ).fetchone()
            if old is not None and not replace:
                raise DeepMorphError(
                    f"{self.path}: {hex_payload} of {key} already stands for {old[0]} {old[1][:80]!r}; "
                    "replace it with --replace (replace=True)"
                )
            if old is None:
                conn.execute(
                    "INSERT INTO entries (model, payload, kind, target, note, created) VALUES (?, ?, ?, ?, ?, ?)",
                    (key.id, hex_payload, kind, target, note, now),
                )
            else:
                conn.execute(
                    "UPDATE entries SET kind = ?, target = ?, note = ?, updated = ? WHERE model = ? AND payload = ?",
                    (kind, target, note, now, key.id, hex_payload),
                )
        created, updated = (now, None) if old is None else (old[2], now)
        return Entry(key.id, key.drawing, key.payload_bits, hex_payload, kind, target, note, created, updated)

    def remove(self, model: ModelLike, payload: PayloadLike) -> Entry | None:
        """Remove the entry of ``payload`` for ``model``; returns it, or ``None`` when there was none."""
        key = model_key(model)
        hex_payload = Payload.of(payload, key.payload_bits).hex
        if not self.path.exists():
            return None
        with self._transaction() as conn:
            rows = conn.execute(f"{_SELECT} WHERE e.model = ? AND e.payload = ?", (key.id, hex_payload)).fetchall()
            conn.execute("DELETE FROM entries WHERE model = ? AND payload = ?", (key.id, hex_payload))
        return _entry(rows[0]) if rows else None

    # ---- export

    def export(
        self, destination: str | Path | IO[str], format: ExportFormat | None = None, model: ModelLike | None = None
    ) -> int:
        """Write every entry (of ``model`` only, when given) as CSV or JSON.

        Args:
            destination: a file, written whole or not at all (its format from its extension,
                ``.csv`` or ``.json``, unless ``format`` says), or a text stream (CSV unless
                ``format`` says).
            format: ``csv`` (a header, then :data:`CSV_FIELDS`; the payload in hex) or ``json``
                (``{"format": "deepmorph-registry/1", "entries": [...]}``, as :meth:`Entry.to_json`).
            model: only this model's entries.

        Returns:
            How many entries were written.

        Raises:
            DeepMorphError: an unknown format, a file that cannot be written or that is the
                registry itself.
        """
        from deepmorph_core.fileio import atomic_write, same_file
        from deepmorph_core.fileio import check_target as check_writable

        is_path = isinstance(destination, (str, Path))
        if format is None:
            format = EXPORT_FORMATS.get(Path(destination).suffix.lower()) if is_path else "csv"  # type: ignore[arg-type]
            if format is None:
                raise DeepMorphError(f"{destination}: an export is written as .csv or .json; name it so")
        if format not in ("csv", "json"):
            raise DeepMorphError(f"an export's format is 'csv' or 'json', not {format!r}")
        if is_path:
            if same_file(destination, self.path):  # type: ignore[arg-type]
                raise DeepMorphError(f"{destination}: refusing to overwrite the registry itself")
            check_writable(destination)  # type: ignore[arg-type]
        entries = self.list(model)
        text = _as_json(entries) if format == "json" else _as_csv(entries)
        if is_path:
            atomic_write(destination, text.encode("utf-8"))  # type: ignore[arg-type]
        else:
            destination.write(text)  # type: ignore[union-attr]
        return len(entries)

    # ---- the file

    def _read(self, sql: str, args: tuple[Any, ...]) -> list[Entry]:
        with self._connection(write=False) as conn:
            return [] if conn is None else [_entry(row) for row in conn.execute(sql, args).fetchall()]

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """One ``BEGIN IMMEDIATE`` transaction (the write lock taken at once, so that no reader
        has to be upgraded under contention): committed, or rolled back on any failure."""
        with self._connection(write=True) as conn:
            assert conn is not None
            conn.execute("BEGIN IMMEDIATE")  # waits up to the busy timeout for the other writers
            try:
                yield conn
            except BaseException:
                conn.rollback()
                raise
            conn.commit()

    @contextlib.contextmanager
    def _connection(self, write: bool) -> Iterator[sqlite3.Connection | None]:
        """A connection to a checked registry (``None`` when reading one that does not exist),
        with every SQLite failure turned into one clear error naming the file."""
        path = self.path
        if path.is_dir():
            raise DeepMorphError(f"{path}: a folder, not a registry file")
        if not write and not path.exists():
            yield None
            return
        if write:
            self._make_folder()
        try:
            conn = sqlite3.connect(str(path), timeout=self.timeout, isolation_level=None)
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        try:
            try:
                ready = self._check(conn, write)
            except sqlite3.Error as exc:
                raise self._error(exc) from None
            try:
                yield conn if ready else None
            except sqlite3.Error as exc:
                raise self._error(exc) from None
        finally:
            conn.close()

    def _make_folder(self) -> None:
        folder = self.path.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DeepMorphError(f"{self.path}: cannot make the registry's folder: {exc.strerror or exc}") from None
        if not self.path.exists() and not os.access(folder, os.W_OK | os.X_OK):
            raise DeepMorphError(f"{self.path}: cannot create the registry: permission denied in {folder}")

    def _check(self, conn: sqlite3.Connection, write: bool) -> bool:
        """Refuse a file that is not a registry; make an empty one into a registry (when
        writing), in WAL mode. Several processes may do this at once: the first one's
        transaction makes the tables, the others find them made. Returns whether the file is a
        registry (an empty file read is not one yet)."""
        deadline = time.monotonic() + self.timeout
        while True:
            try:
                app_id, version, tables = conn.execute(_HEADER).fetchone()  # one statement: one snapshot
                if app_id == APPLICATION_ID:
                    if version > SCHEMA_VERSION:
                        raise DeepMorphError(
                            f"{self.path}: a registry of a newer DeepMorph (schema {version}; this one reads "
                            f"{SCHEMA_VERSION})"
                        )
                    return True
                if app_id != 0 or tables:
                    raise self._foreign("an SQLite database of something else")
                if not write:
                    return False  # an empty file: no entries yet
                conn.execute("PRAGMA journal_mode = WAL")
                conn.execute("BEGIN IMMEDIATE")
                try:
                    app_id, _, tables = conn.execute(_HEADER).fetchone()
                    if app_id != APPLICATION_ID:  # else another process made it meanwhile
                        if app_id != 0 or tables:
                            raise self._foreign("an SQLite database of something else")
                        for statement in filter(str.strip, _SCHEMA.split(";")):
                            conn.execute(statement)
                        conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
                        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
                except BaseException:
                    conn.rollback()
                    raise
                conn.commit()
                return True
            except sqlite3.OperationalError as exc:
                # switching to WAL takes the file alone; another process may be doing the same
                if not _busy(exc) or time.monotonic() > deadline:
                    raise
                time.sleep(0.01)

    def _foreign(self, why: str) -> DeepMorphError:
        return DeepMorphError(f"{self.path}: not a DeepMorph registry ({why})")

    def _error(self, exc: sqlite3.Error) -> DeepMorphError:
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if isinstance(exc, sqlite3.OperationalError) and _busy(exc):
            return DeepMorphError(
                f"{self.path}: the registry is busy: another program held it for over {self.timeout:g} s"
            )
        if type(exc) is sqlite3.DatabaseError:  # "file is not a database", "database disk image is malformed"
            return self._foreign(text)
        return DeepMorphError(f"{self.path}: cannot use the registry ({text})")


#: A detection as ``Detection.to_json()`` writes it, to its payload's entry (``Entry.to_json()``)
#: or ``None``: what :func:`detection_lookup` returns.
DetectionLookup = Callable[[Mapping[str, Any]], "dict[str, Any] | None"]


def detection_lookup(registry: PayloadRegistry, model: ModelLike, *, missing_ok: bool = False) -> DetectionLookup:
    """What decoded payloads mean: the lookup ``deepmorph decode --registry`` and the studio's
    Scan tab run on each detection of ``model``.

    The registry is checked once, before any photo is read: a file that is not a registry is
    one clear error, and so is a registry that does not exist unless ``missing_ok`` (then
    nothing is found). The lookup gives a verified detection's entry; a detection that is not
    verified (``ok`` false) is never looked up, since a misread must not show a URL.

    Args:
        registry: the payload registry.
        model: the model that decoded the detections (:data:`ModelLike`).
        missing_ok: a registry that does not exist yet finds nothing instead of failing.

    Returns:
        A function from a detection's JSON (``{"ok", "payload": {"hex", ...}, ...}``) to its
        entry's JSON, or ``None`` when it is not verified or has no entry.

    Raises:
        DeepMorphError: no registry at ``registry.path`` (unless ``missing_ok``), a file that is
            not a registry, or a model that is not usable.
    """
    if not registry.path.exists():
        if missing_ok:
            return lambda detection: None
        raise DeepMorphError(f"{registry.path}: no payload registry there (add entries with `deepmorph registry add`)")
    key = model_key(model)
    registry.count(key)  # a file that is not a registry fails here, before any work

    def look_up(detection: Mapping[str, Any]) -> dict[str, Any] | None:
        if not detection.get("ok"):
            return None
        entry = registry.get(key, detection["payload"]["hex"])
        return None if entry is None else entry.to_json()

    return look_up


def _entry(row: tuple[Any, ...]) -> Entry:
    return Entry(*row)


def _as_csv(entries: list[Entry]) -> str:
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_FIELDS)
    for e in entries:
        writer.writerow(["" if v is None else v for v in (getattr(e, f) for f in CSV_FIELDS)])
    return buffer.getvalue()


def _as_json(entries: list[Entry]) -> str:
    return json.dumps({"format": FORMAT, "entries": [e.to_json() for e in entries]}, indent=2) + "\n"


__all__ = [
    "CSV_FIELDS",
    "KINDS",
    "MAX_NOTE_CHARS",
    "MAX_TARGET_CHARS",
    "DetectionLookup",
    "Entry",
    "ModelKey",
    "ModelLike",
    "PayloadRegistry",
    "check_target",
    "default_path",
    "detection_lookup",
    "model_key",
]
