"""The payload registry (``deepmorph.registry``, ``deepmorph registry ...``, ``decode --registry``):
entries round trip, duplicates and payloads that do not fit are refused, only http(s) URLs are
stored, a file that is not a registry is one clear error, processes write at once without losing
a row, and exports are written whole."""

from __future__ import annotations

import csv
import io
import json
import multiprocessing
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import typer
from typer.testing import CliRunner

import deepmorph
import deepmorph.plugin
import deepmorph_detect.plugin
from deepmorph.registry import (
    MAX_TARGET_CHARS,
    ModelKey,
    PayloadRegistry,
    default_path,
    detection_lookup,
    model_key,
)
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.model import DeepMorphModel
from deepmorph_core.plugins import load_registry

ROOT = Path(__file__).resolve().parents[2]
URL = "https://example.com/offer"
runner = CliRunner()


@pytest.fixture(scope="module")
def key() -> ModelKey:
    return model_key(BUNDLED_MODEL)


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    """A command line with the photo commands and the registry's, registered through their hooks."""
    cli = typer.Typer(no_args_is_help=True, pretty_exceptions_enable=False, add_completion=False)
    cli.callback()(lambda: None)
    load_registry([deepmorph_detect.plugin, deepmorph.plugin], entry_points=False).register_commands(cli)
    return cli


def run(app: typer.Typer, *args: object):
    return runner.invoke(app, [str(a) for a in args])


def one_error(res, *words: str) -> None:
    """Exit status 1 and one ``error:`` line on stderr saying ``words``; nothing on stdout."""
    assert res.exit_code == 1, (res.exit_code, res.output, res.exception)
    assert res.stdout == "" and res.stderr.startswith("error: ") and res.stderr.count("\n") == 1, res.stderr
    assert "Traceback" not in res.stderr and all(w in res.stderr for w in words), res.stderr


# ---- the store


def test_add_get_list_remove_round_trip(key: ModelKey, tmp_path: Path) -> None:
    db = tmp_path / "new" / "folder" / "registry.sqlite3"
    registry = PayloadRegistry(db)
    assert registry.list() == [] and registry.get(key, 1) is None and not db.exists()  # reading makes nothing
    added = registry.add(key, 0xA1B2C3, URL, note="spring campaign")
    assert (added.payload, added.kind, added.target, added.note, added.updated) == ("0xA1B2C3", "url", URL,
                                                                                     "spring campaign", None)  # fmt: skip
    text = registry.add(key, "000000000000000000000001", "  Hello\nthere  ", kind="text")
    assert text.payload == "0x000001" and text.target == "Hello\nthere"  # binary digits read; blanks dropped
    assert db.is_file()
    # every payload form reads the same entry, a decoded Payload included
    for form in (0xA1B2C3, "0xa1b2c3", b"\xa1\xb2\xc3", deepmorph.Payload.of(0xA1B2C3, 24)):
        assert PayloadRegistry(db).get(key, form) == added
    assert added.to_json()["payload"] == {"hex": "0xA1B2C3", "bits": "101000011011001011000011"}
    assert added.payload_value.int == 0xA1B2C3
    assert [e.payload for e in registry.list()] == ["0x000001", "0xA1B2C3"] == [e.payload for e in registry.list(key)]
    assert registry.count(key) == 2
    assert registry.remove(key, 0xA1B2C3) == added
    assert registry.remove(key, 0xA1B2C3) is None and registry.get(key, 0xA1B2C3) is None
    assert registry.list() == [text]


def test_entries_of_two_models_never_mix(key: ModelKey, tmp_path: Path) -> None:
    other = ModelKey("0" * 64, "other.svg", 24)
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    registry.add(key, 7, URL)
    registry.add(other, 7, "https://example.org/other")
    assert registry.get(key, 7).target == URL and registry.get(other, 7).target == "https://example.org/other"
    assert [e.drawing for e in registry.list()] == ["ghost.svg", "other.svg"]
    assert len(registry.list(key)) == len(registry.list(other)) == 1


def test_a_model_is_known_by_what_decides_its_codes() -> None:
    """The same id from the bundle's path, the loaded bundle and ``deepmorph.Model``; the
    decoder (tuning, a detector) does not change it, the encoder's weights do."""
    model = DeepMorphModel.load(BUNDLED_MODEL)
    by_path = model_key(BUNDLED_MODEL)
    assert model_key(model) == by_path == model_key(deepmorph.Model(model)) == model_key(str(BUNDLED_MODEL))
    assert len(by_path.id) == 64 and by_path.payload_bits == 24 and by_path.drawing == "ghost.svg"
    with torch.no_grad():
        next(model.decoder.parameters()).add_(0.01)
        assert model_key(model) == by_path
        next(model.encoder.parameters()).add_(0.01)
        assert model_key(model).id != by_path.id
    with pytest.raises(DeepMorphError, match="not a usable DeepMorph model file"):
        model_key(Path(__file__))
    with pytest.raises(DeepMorphError, match="not int"):
        model_key(3)  # type: ignore[arg-type]


def test_a_duplicate_is_refused_unless_replaced(key: ModelKey, tmp_path: Path) -> None:
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    first = registry.add(key, 5, URL)
    with pytest.raises(DeepMorphError, match=r"0x000005 of ghost.svg \(model [0-9a-f]{12}\) already stands for url"):
        registry.add(key, "0x000005", "https://example.com/other")
    assert registry.get(key, 5) == first  # untouched
    replaced = registry.add(key, 5, "Now a text", kind="text", replace=True)
    assert (replaced.kind, replaced.target, replaced.created) == ("text", "Now a text", first.created)
    assert replaced.updated is not None and registry.get(key, 5) == replaced and registry.count() == 1


@pytest.mark.parametrize(
    ("payload", "message"),
    [
        (1 << 24, "does not fit in 24 bits"),
        (-1, "does not fit in 24 bits"),
        ("0x1000000", "has 7 hex digits"),
        ("0x1234", "has 4 hex digits"),
        ("1" * 25, "has 25 binary digits"),
        (b"\x01\x02\x03\x04", "payload of 4 bytes"),
        ("ghost", "neither 0x-prefixed hex, a 0d-prefixed number nor binary digits"),
        (None, "cannot be None"),
    ],
)
def test_a_payload_that_does_not_fit_the_model_is_refused(key: ModelKey, tmp_path: Path, payload: object,
                                                          message: str) -> None:  # fmt: skip
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    with pytest.raises(DeepMorphError, match=message):
        registry.add(key, payload, URL)  # type: ignore[arg-type]
    with pytest.raises(DeepMorphError, match=message):
        registry.get(key, payload)  # type: ignore[arg-type]
    assert registry.list() == []
    with pytest.raises(DeepMorphError, match="does not fit in 8 bits"):
        registry.add(ModelKey("1" * 64, "small.svg", 8), 0x100, URL)


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("javascript:alert(1)", "not javascript:"),
        ("JavaScript:alert(1)", "not javascript:"),
        ("data:text/html,<script>alert(1)</script>", "not data:"),
        ("file:///etc/passwd", "not file:"),
        ("ftp://example.com/a", "not ftp:"),
        ("example.com/offer", "has no scheme"),
        ("https://", "names no host"),
        ("https://bank.example@evil.example/", "user name or password"),
        ("https://example.com/a b", "no spaces"),
        ("https:\\\\evil.example", "no spaces or backslashes"),
        ("https://example.com/\x1b[31m", "control character U+001B"),
        ("https://example.com:port/", "not a URL"),
        ("https://example.com/" + "a" * MAX_TARGET_CHARS, f"at most {MAX_TARGET_CHARS}"),
        ("   ", "an empty url"),
    ],
)
def test_only_http_urls_are_stored(key: ModelKey, tmp_path: Path, target: str, message: str) -> None:
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    with pytest.raises(DeepMorphError, match=re.escape(message)):
        registry.add(key, 1, target)
    assert registry.list() == []
    for ok in ("http://example.com", "HTTPS://Example.com:8443/a?b=c#d", "https://[::1]/x"):
        assert registry.add(key, 2, ok, replace=True).target == ok


def test_texts_and_notes_are_limited(key: ModelKey, tmp_path: Path) -> None:
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    assert registry.add(key, 1, "x" * MAX_TARGET_CHARS, kind="text").target == "x" * MAX_TARGET_CHARS
    for target, kind, message in (
        ("x" * (MAX_TARGET_CHARS + 1), "text", "at most 2000"),
        ("evil\u202egnp.exe", "text", "U+202E"),
        ("a\x00b", "text", "U+0000"),
        ("hello", "link", "kind is 'url' or 'text'"),
    ):
        with pytest.raises(DeepMorphError, match=re.escape(message)):
            registry.add(key, 2, target, kind=kind)  # type: ignore[arg-type]
    with pytest.raises(DeepMorphError, match="at most 200"):
        registry.add(key, 2, URL, note="n" * 201)
    with pytest.raises(DeepMorphError, match=re.escape("U+000A")):
        registry.add(key, 2, URL, note="two\nlines")
    assert registry.count() == 1


@pytest.mark.parametrize(
    "content",
    [b"this is not a database at all\n" * 40, b"SQLite format 3\x00" + b"\xff" * 200],
    ids=["text", "damaged-header"],
)
def test_a_file_that_is_not_a_registry_is_one_clear_error(key: ModelKey, tmp_path: Path, app: typer.Typer,
                                                          content: bytes) -> None:  # fmt: skip
    db = tmp_path / "r.sqlite3"
    db.write_bytes(content)
    for call in (lambda r: r.add(key, 1, URL), lambda r: r.list(), lambda r: r.get(key, 1), lambda r: r.count()):
        with pytest.raises(DeepMorphError, match=rf"^{re.escape(str(db))}: not a DeepMorph registry \(.+\)$"):
            call(PayloadRegistry(db))
    assert db.read_bytes() == content  # never "repaired"
    for args in (("add", BUNDLED_MODEL, "0x000001", URL), ("list",), ("show", BUNDLED_MODEL, "0x000001"),
                 ("export", "--out", tmp_path / "e.csv")):  # fmt: skip
        one_error(run(app, "registry", *args, "--db", db), str(db), "not a DeepMorph registry (")
    assert not (tmp_path / "e.csv").exists()


def test_an_sqlite_database_of_something_else_is_refused(key: ModelKey, tmp_path: Path) -> None:
    import sqlite3

    db = tmp_path / "other.sqlite3"
    with sqlite3.connect(db) as conn:
        conn.execute("CREATE TABLE entries (x)")
    conn.close()
    with pytest.raises(DeepMorphError, match="not a DeepMorph registry .an SQLite database of something else"):
        PayloadRegistry(db).add(key, 1, URL)
    empty = tmp_path / "empty.sqlite3"
    empty.write_bytes(b"")  # an empty file becomes a registry on the first write
    assert PayloadRegistry(empty).list() == [] and PayloadRegistry(empty).add(key, 1, URL).payload == "0x000001"


def test_a_folder_or_an_unwritable_place_is_one_clear_error(key: ModelKey, tmp_path: Path) -> None:
    with pytest.raises(DeepMorphError, match="a folder, not a registry file"):
        PayloadRegistry(tmp_path).add(key, 1, URL)
    (tmp_path / "file").write_text("x")
    with pytest.raises(DeepMorphError, match="cannot make the registry's folder"):
        PayloadRegistry(tmp_path / "file" / "r.sqlite3").add(key, 1, URL)
    if os.geteuid() == 0:
        pytest.skip("root writes into read-only folders")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        with pytest.raises(DeepMorphError, match="cannot create the registry: permission denied"):
            PayloadRegistry(locked / "r.sqlite3").add(key, 1, URL)
    finally:
        locked.chmod(0o755)


def test_the_default_place_follows_deepmorph_home(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("DEEPMORPH_HOME", str(tmp_path))
    assert default_path() == tmp_path / "registry.sqlite3" == PayloadRegistry().path
    monkeypatch.delenv("DEEPMORPH_HOME")
    assert default_path() == Path.home() / ".deepmorph" / "registry.sqlite3"


def test_processes_writing_at_once_lose_no_row(key: ModelKey, tmp_path: Path) -> None:
    """4 processes x 25 adds into a registry none of them has made yet, then all four race for
    one payload: every row lands, exactly one wins the race, and nobody sees "database is locked"."""
    from tests.project.registry_worker import add_many

    workers, count = 4, 25
    db = tmp_path / "shared" / "registry.sqlite3"
    ctx = multiprocessing.get_context("spawn")
    start, results = ctx.Event(), ctx.Queue()
    procs = [ctx.Process(target=add_many, args=(str(db), key, w, count, start, results)) for w in range(workers)]
    for p in procs:
        p.start()
    start.set()
    try:
        reports = sorted(results.get(timeout=120) for _ in procs)
    finally:
        for p in procs:
            p.join(timeout=30)
            if p.is_alive():
                p.terminate()
    assert [p.exitcode for p in procs] == [0] * workers
    assert [failures for _, failures, _ in reports] == [[]] * workers
    assert sum(won for *_, won in reports) == 1
    entries = PayloadRegistry(db).list(key)
    assert len(entries) == workers * count + 1
    assert {e.payload for e in entries} == {f"0x{i:06X}" for i in range(workers * count)} | {"0xFFFFFF"}


# ---- export


def test_export_csv_and_json_whole(key: ModelKey, tmp_path: Path) -> None:
    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    registry.add(key, 1, URL, note='a, "quoted" note')
    registry.add(key, 2, "=cmd|' /C calc'!A0\nsecond line", kind="text")
    registry.add(ModelKey("0" * 64, "other.svg", 24), 1, "https://example.org/")
    assert registry.export(tmp_path / "all.csv") == 3
    rows = list(csv.DictReader(io.StringIO((tmp_path / "all.csv").read_text())))
    assert [(r["drawing"], r["payload"], r["kind"]) for r in rows] == [
        ("ghost.svg", "0x000001", "url"), ("ghost.svg", "0x000002", "text"), ("other.svg", "0x000001", "url")]  # fmt: skip
    assert rows[0]["note"] == 'a, "quoted" note' and rows[1]["target"] == "=cmd|' /C calc'!A0\nsecond line"
    assert registry.export(tmp_path / "ghost.json", model=key) == 2
    data = json.loads((tmp_path / "ghost.json").read_text())
    assert data["format"] == "deepmorph-registry/1"
    assert data["entries"] == [e.to_json() for e in registry.list(key)]
    stream = io.StringIO()
    assert registry.export(stream, "json") == 3 and len(json.loads(stream.getvalue())["entries"]) == 3
    with pytest.raises(DeepMorphError, match="written as .csv or .json"):
        registry.export(tmp_path / "all.txt")
    with pytest.raises(DeepMorphError, match="refusing to overwrite the registry itself"):
        registry.export(registry.path, "csv")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".dm-")] == []  # no temporary file left


def test_a_failed_export_leaves_the_old_file_whole(key: ModelKey, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   app: typer.Typer) -> None:  # fmt: skip
    import deepmorph_core.fileio as fileio

    registry = PayloadRegistry(tmp_path / "r.sqlite3")
    for i in range(50):
        registry.add(key, i, f"https://example.com/{i}")
    target = tmp_path / "out.csv"
    target.write_text("the old export\n")

    def fail(src: object, dst: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(fileio.os, "replace", fail)
    with pytest.raises(DeepMorphError, match="No space left on device"):
        registry.export(target)
    one_error(run(app, "registry", "export", "--out", target, "--db", registry.path), "No space left on device")
    monkeypatch.undo()
    assert target.read_text() == "the old export\n"
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".dm-")] == []  # no temporary file left


# ---- the command line


def test_cli_add_list_show_remove_export(app: typer.Typer, tmp_path: Path) -> None:
    db = tmp_path / "home" / "registry.sqlite3"
    res = run(app, "registry", "add", BUNDLED_MODEL, "0xA1B2C3", URL, "--note", "spring", "--db", db, "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["written"] == [str(db)] and data["replaced"] is False
    assert data["entry"]["payload"]["hex"] == "0xA1B2C3" and data["entry"]["target"] == URL
    res = run(app, "registry", "add", BUNDLED_MODEL, "0x000002", "Ask at the desk", "--text", "--db", db)
    assert res.exit_code == 0 and res.stdout.startswith('added 0x000002  text  "Ask at the desk"  ghost.svg')
    one_error(run(app, "registry", "add", BUNDLED_MODEL, "0xA1B2C3", "https://example.com/b", "--db", db),
              "already stands for", "--replace")  # fmt: skip
    res = run(app, "registry", "add", BUNDLED_MODEL, "0xA1B2C3", "https://example.com/b", "--replace", "--db", db,
              "--json")  # fmt: skip
    assert res.exit_code == 0 and json.loads(res.stdout)["replaced"] is True
    one_error(run(app, "registry", "add", BUNDLED_MODEL, "0x1000000", URL, "--db", db), "has 7 hex digits")
    one_error(run(app, "registry", "add", BUNDLED_MODEL, "0x000003", "javascript:alert(1)", "--db", db),
              "http:// or https://", "not javascript:")  # fmt: skip
    one_error(run(app, "registry", "add", tmp_path / "missing.dmm", "0x000003", URL, "--db", db), "missing.dmm")

    res = run(app, "registry", "list", "--db", db, "--json")
    listed = json.loads(res.stdout)
    assert res.exit_code == 0 and [(e["payload"]["hex"], e["kind"]) for e in listed] == [("0x000002", "text"),
                                                                                          ("0xA1B2C3", "url")]  # fmt: skip
    assert json.loads(run(app, "registry", "list", BUNDLED_MODEL, "--db", db, "--json").stdout) == listed
    text = run(app, "registry", "list", "--db", db).stdout.splitlines()
    assert len(text) == 2 and text[1].startswith("0xA1B2C3  url   https://example.com/b  ghost.svg (model ")
    assert run(app, "registry", "list", "--db", tmp_path / "none.sqlite3").stdout.startswith("no entries in ")

    res = run(app, "registry", "show", BUNDLED_MODEL, "101000011011001011000011", "--db", db, "--json")
    assert res.exit_code == 0 and json.loads(res.stdout) == listed[1]
    one_error(run(app, "registry", "show", BUNDLED_MODEL, "0x000009", "--db", db), "0x000009 of ghost.svg", "no entry")

    res = run(app, "registry", "export", "--out", tmp_path / "e.json", "--db", db, "--json")
    assert res.exit_code == 0 and json.loads(res.stdout) == {"written": [str(tmp_path / "e.json")], "entries": 2,
                                                             "format": "json"}  # fmt: skip
    assert json.loads((tmp_path / "e.json").read_text())["entries"] == listed
    res = run(app, "registry", "export", BUNDLED_MODEL, "--out", tmp_path / "e.csv", "--db", db)
    assert res.exit_code == 0 and res.stdout.strip() == f"wrote {tmp_path / 'e.csv'} (2 entries, CSV)"
    assert len(list(csv.DictReader(io.StringIO((tmp_path / "e.csv").read_text())))) == 2
    one_error(run(app, "registry", "export", "--out", tmp_path / "e.txt", "--db", db), "name it so")
    one_error(run(app, "registry", "export", "--out", db.with_suffix(".csv"), "--db", db.with_suffix(".csv")),
              "refusing to overwrite the registry")  # fmt: skip

    res = run(app, "registry", "remove", BUNDLED_MODEL, "0x000002", "--db", db, "--json")
    assert res.exit_code == 0 and json.loads(res.stdout)["removed"]["target"] == "Ask at the desk"
    one_error(run(app, "registry", "remove", BUNDLED_MODEL, "0x000002", "--db", db), "no entry")
    assert run(app, "registry", "add", BUNDLED_MODEL).exit_code == 2  # a usage error


def test_cli_uses_deepmorph_home(app: typer.Typer, tmp_path: Path) -> None:
    res = runner.invoke(app, ["registry", "add", str(BUNDLED_MODEL), "0x000001", URL],
                        env={"DEEPMORPH_HOME": str(tmp_path / "home")})  # fmt: skip
    assert res.exit_code == 0, res.output
    assert PayloadRegistry(tmp_path / "home" / "registry.sqlite3").count() == 1


def test_decode_shows_each_verified_payloads_entry(app: typer.Typer, tmp_path: Path) -> None:
    ghost = deepmorph.load(BUNDLED_MODEL)
    db = tmp_path / "registry.sqlite3"
    PayloadRegistry(db).add(ghost, 0xA1B2C3, URL)
    ghost.encode(0xA1B2C3).save(tmp_path / "a.png", width_mm=30)
    ghost.encode(0x00000F).save(tmp_path / "b.png", width_mm=30)
    res = run(app, "decode", BUNDLED_MODEL, tmp_path / "a.png", tmp_path / "b.png", "--db", db, "--json")
    assert res.exit_code == 0, res.output
    found = [r["detections"][0] for r in json.loads(res.stdout)]
    assert [(d["payload"]["hex"], d["ok"]) for d in found] == [("0xA1B2C3", True), ("0x00000F", True)]
    assert found[0]["registry"]["target"] == URL and found[1]["registry"] is None
    res = runner.invoke(app, ["decode", str(BUNDLED_MODEL), str(tmp_path / "a.png"), "--registry"],
                        env={"DEEPMORPH_HOME": str(tmp_path)})  # fmt: skip
    assert res.exit_code == 0 and res.stdout.splitlines()[1] == f"  url: {URL}", res.output
    plain = run(app, "decode", BUNDLED_MODEL, tmp_path / "a.png", "--json")
    assert "registry" not in json.loads(plain.stdout)[0]["detections"][0]  # only when asked
    # a missing or foreign registry is refused before any work: no overlay written
    one_error(run(app, "decode", BUNDLED_MODEL, tmp_path / "a.png", "--db", tmp_path / "none.sqlite3", "--overlay",
                  tmp_path / "o.png"), "no payload registry there")  # fmt: skip
    one_error(run(app, "decode", BUNDLED_MODEL, tmp_path / "a.png", "--db", tmp_path / "a.png", "--overlay",
                  tmp_path / "o.png"), "not a DeepMorph registry")  # fmt: skip
    assert not (tmp_path / "o.png").exists()


def test_one_lookup_for_decoded_payloads(key: ModelKey, tmp_path: Path) -> None:
    """``detection_lookup``, what ``decode --registry`` and the studio's Scan tab both run: a
    verified payload's entry, nothing for a misread; the registry checked before any work."""
    registry = PayloadRegistry(tmp_path / "registry.sqlite3")
    with pytest.raises(DeepMorphError, match="no payload registry there"):
        detection_lookup(registry, key)
    assert detection_lookup(registry, key, missing_ok=True)({"ok": True, "payload": {"hex": "0xA1B2C3"}}) is None
    registry.add(key, 0xA1B2C3, URL)
    look_up = detection_lookup(registry, key)
    assert look_up({"ok": True, "payload": {"hex": "0xA1B2C3"}}) == registry.get(key, 0xA1B2C3).to_json()
    assert look_up({"ok": False, "payload": {"hex": "0xA1B2C3"}}) is None  # a misread never shows a URL
    assert look_up({"ok": True, "payload": {"hex": "0x000001"}}) is None
    foreign = tmp_path / "notes.txt"
    foreign.write_text("not a database, but long enough to be read as one " * 20)
    for missing_ok in (False, True):
        with pytest.raises(DeepMorphError, match="not a DeepMorph registry"):
            detection_lookup(PayloadRegistry(foreign), key, missing_ok=missing_ok)


def test_the_installed_command_line_has_the_registry_and_lists_without_torch(tmp_path: Path) -> None:
    """Through the entry point, as installed: ``registry list`` of a registry imports no torch."""
    PayloadRegistry(tmp_path / "r.sqlite3").add(ModelKey("0" * 64, "other.svg", 24), 1, URL)
    probe = (
        "import sys\nfrom deepmorph.cli import main\nsys.argv = ['deepmorph', *sys.argv[1:]]\n"
        "try:\n    main()\nexcept SystemExit as e:\n    assert not e.code, e.code\n"
        "print('TORCH', 'torch' in sys.modules, file=sys.stderr)\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", probe, "registry", "list", "--db", str(tmp_path / "r.sqlite3"),
                           "--json"], cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0 and "TORCH False" in done.stderr, done.stderr
    assert [e["target"] for e in json.loads(done.stdout)] == [URL]
