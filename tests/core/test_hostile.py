"""Hostile input, every class of it: one clean ``error:`` line and exit status 1, no traceback,
bounded time and memory, nothing written half, and no byte of a secret file in any output.

The files are made here. Commands run in-process (typer's runner) except where a resource
limit is the point: those run in a child process under ``resource`` limits.
"""

from __future__ import annotations

import json
import os
import resource
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save_file
from typer.testing import CliRunner

from deepmorph.cli import application
from deepmorph_core.bundled import BUNDLED_MODEL
from deepmorph_core.errors import DeepMorphError
from deepmorph_core.fileio import atomic_write, atomic_write_all

SECRET = b"TOP-SECRET-7f3a9c"  # what must never reach an output
LINE = '<line x1="2" y1="2" x2="20" y2="20" stroke="black" stroke-width="2"/>'


def svg(body: str, head: str = "", root: str = "") -> str:
    return (
        f'{head}<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
        f'xmlns:dm="urn:deepmorph:1" viewBox="0 0 24 24" dm:move="1" {root}>{body}</svg>'
    )


def run(*args: object) -> tuple[int, str]:
    result = CliRunner().invoke(application(), [str(a) for a in args])
    text = result.output
    assert "Traceback" not in text, text
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, text


def one_error(text: str, *needles: str) -> None:
    lines = [line for line in text.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith("error: ")]
    assert len(errors) == 1, text
    for needle in needles:
        assert needle in errors[0], errors[0]


@pytest.fixture
def secret(tmp_path: Path) -> Path:
    path = tmp_path / "secret.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + SECRET * 20)
    return path


def no_secret_anywhere(folder: Path) -> None:
    for path in folder.rglob("*"):
        if path.is_file() and path.name != "secret.png":
            assert SECRET not in path.read_bytes(), path


HOSTILE_SVGS = {
    "utf16-entity": (
        svg(LINE, '<?xml version="1.0" encoding="UTF-16"?>\n<!DOCTYPE svg [<!ENTITY x SYSTEM "file:///etc/passwd">]>\n')
        .replace("</svg>", "<desc>&x;</desc></svg>")
        .encode("utf-16"),
        "entity declarations are not allowed",
    ),
    "utf8-entity": (svg(LINE, '<!DOCTYPE svg [<!ENTITY a "aaaa">]>').encode(), "entity declarations are not allowed"),
    "style-import": (svg("<style>@import url(SECRET_PATH);</style>" + LINE).encode(), "unsupported: CSS @import"),
    "style-url": (
        svg("<style>line { stroke: url(SECRET_PATH#p) }</style>" + LINE).encode(),
        "only url(#id) of a gradient in the same file is read; nothing is fetched",
    ),
    "pattern-image": (
        svg(
            '<defs><pattern id="p"><image href="SECRET_PATH" width="24" height="24"/></pattern></defs>' + LINE
        ).encode(),
        "unsupported: <pattern> in <defs>",
    ),
    "image": (
        svg('<image href="SECRET_PATH" width="24" height="24"/>' + LINE).encode(),
        "unsupported: element <image>",
    ),
    "script": (svg("<script>alert(1)</script>" + LINE).encode(), "element <script>"),
    "onload": (svg(LINE, root='onload="alert(1)"').encode(), "event handler attribute onload"),
    "javascript-link": (svg(f'<a xlink:href="javascript:alert(3)">{LINE}</a>').encode(), "script links are never kept"),
    "unicode-digits": (svg('<line x1="١٢" y1="2" x2="20" y2="20" stroke="black"/>').encode(), "not a number"),
    "filter": (svg(LINE.replace("/>", ' filter="url(#f)"/>')).encode(), "unsupported: filter="),
    "style-property": (svg(LINE.replace("/>", ' style="mix-blend-mode: multiply"/>')).encode(), "mix-blend-mode"),
    "extreme-viewbox": (
        svg(LINE).replace('viewBox="0 0 24 24"', 'viewBox="0 0 0.001 1000000"').encode(),
        "more than 20 times the other",
    ),
    "deep": (svg("<g>" * 300 + LINE + "</g>" * 300).encode(), "nested"),
    "foreign-object": (svg("<foreignObject><div/></foreignObject>" + LINE).encode(), "element <foreignObject>"),
}


@pytest.mark.parametrize("name", sorted(HOSTILE_SVGS))
def test_hostile_svgs_are_one_clear_error_in_every_command(name: str, tmp_path: Path, secret: Path) -> None:
    data, message = HOSTILE_SVGS[name]
    path = tmp_path / f"{name}.svg"
    path.write_bytes(data.replace(b"SECRET_PATH", str(secret).encode()))
    for args in (
        ["inspect", path],
        ["morph", path, "--random", "--out", tmp_path / "m.svg"],
        ["render", path, "--out", tmp_path / "r.png"],
        ["train", path, "--out", tmp_path / "t.dmm", "--steps", "1"],
    ):
        code, text = run(*args)
        assert code == 1, (args, text)
        one_error(text, message)
    assert not any(tmp_path.glob("[mrt].*")), "nothing is written for a refused drawing"
    no_secret_anywhere(tmp_path)


def test_what_cannot_be_modelled_is_dropped_on_request_and_never_written(tmp_path: Path, secret: Path) -> None:
    body = (
        f'<defs><style>line {{ stroke: url(#p) }}</style><pattern id="p"><image href="{secret}"/></pattern></defs>'
        f'<a href="https://example.com"><line x1="2" y1="2" x2="20" y2="20" stroke="black" stroke-width="2" '
        f'class="x" id="y" style="stroke-dasharray: 2 1; font-family: serif"/></a><text>hi</text>'
    )
    path = tmp_path / "mixed.svg"
    path.write_text(svg(body, '<!DOCTYPE svg PUBLIC "-//W3C//DTD SVG 1.1//EN" "http://www.w3.org/TR/svg11.dtd">'))
    code, text = run("morph", path, "--random", "--seed", "1", "--out", tmp_path / "m.svg", "--drop-unsupported")
    assert code == 0, text
    assert text.count("warning:") == 4  # <style>, <pattern>, the dash, <text>
    written = (tmp_path / "m.svg").read_text()
    for banned in ("DOCTYPE", "style", "pattern", "image", "href", "class", "id=", "text", "dasharray", "font"):
        assert banned not in written, banned
    code, text = run("render", path, "--out", tmp_path / "r.png", "--drop-unsupported", "--width-px", "64")
    assert code == 0, text
    no_secret_anywhere(tmp_path)


def test_huge_drawings_are_refused_quickly(tmp_path: Path) -> None:
    many = tmp_path / "many.svg"
    many.write_text(svg(LINE * 2500))
    long_path = tmp_path / "long.svg"
    long_path.write_text(svg('<path d="M1 1 ' + "L5 5 " * 12000 + '" stroke="black"/>'))
    for path, message in ((many, "more than 2000 shapes"), (long_path, "10000 control points")):
        t0 = time.perf_counter()
        code, text = run("inspect", path, "--json")
        assert code == 1 and time.perf_counter() - t0 < 2.0
        one_error(text, message)
    busy = tmp_path / "busy.svg"
    busy.write_text(svg(LINE * 250))
    code, text = run("train", busy, "--out", tmp_path / "busy.dmm", "--steps", "1")
    assert code == 1 and not (tmp_path / "busy.dmm").exists()
    one_error(text, "at most 200 shapes and 400 variables")
    big = tmp_path / "big.svg"
    big.write_bytes(svg(" " * (8 * 1024 * 1024) + LINE).encode())
    code, text = run("inspect", big)
    assert code == 1
    one_error(text, "limit is")


def _bundle_with(tmp_path: Path, name: str, meta_edit=None, tensor_edit=None) -> Path:
    """A copy of the bundled model with its metadata and tensors edited."""
    tensors = load_file(str(BUNDLED_MODEL))
    from safetensors import safe_open

    with safe_open(str(BUNDLED_MODEL), "pt") as fh:
        meta = json.loads(fh.metadata()["deepmorph"])
    if meta_edit:
        meta = meta_edit(meta)
    if tensor_edit:
        tensor_edit(tensors)
    path = tmp_path / f"{name}.dmm"
    text = meta if isinstance(meta, str) else json.dumps(meta)
    save_file(tensors, str(path), metadata={"deepmorph": text})
    return path


def _set(path_keys: tuple[str, ...], value: object):
    def edit(meta: dict) -> dict:
        node = meta
        for key in path_keys[:-1]:
            node = node[key]
        node[path_keys[-1]] = value
        return meta

    return edit


def test_hostile_bundles_are_one_clear_error(tmp_path: Path) -> None:
    def nan_encoder(t: dict) -> None:
        t["encoder.linear.weight"] = torch.full_like(t["encoder.linear.weight"], float("nan"))

    def int8_decoder(t: dict) -> None:
        key = next(k for k in t if k.startswith("decoder.") and k.endswith("weight"))
        t[key] = t[key].to(torch.int8)

    css = '<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 24 24"><style>@import url(x.css);</style></svg>'
    cases = {
        "deep": (lambda m: '{"format": "deepmorph-model/1", "x": ' + "[" * 50000 + "]" * 50000 + "}", "nested"),
        "huge-channels": (_set(("decoder", "channels"), [100000, 100000]), "less than or equal to 512"),
        "negative-channels": (_set(("decoder", "channels"), [-4, 8]), "greater than or equal to 1"),
        "wide-detector": (_set(("detector", "config", "width"), 1 << 20), None),
        "css-drawing": (_set(("drawing_svg",), css), "unsupported: CSS @import"),
    }
    for name, (edit, message) in cases.items():
        path = _bundle_with(tmp_path, name, meta_edit=edit)
        code, text = run(
            "encode", path, "--payload", "0xA1B2C3", "--out", tmp_path / "c.svg", "--png", tmp_path / "c.png"
        )
        if name == "wide-detector":  # encoding needs no detector; decoding refuses it
            assert code == 0, text
            img = tmp_path / "c.png"
            code, text = run("decode", path, img)
            message = "detector has width"
        assert code == 1, (name, text)
        one_error(text, message)
    for name, edit, message in (("nan", nan_encoder, "not finite"), ("int8", int8_decoder, "torch.int8")):
        path = _bundle_with(tmp_path, name, tensor_edit=edit)
        code, text = run("info", path)
        assert code == 1
        one_error(text, message)


def test_bundle_metadata_is_printed_not_obeyed(tmp_path: Path) -> None:
    path = _bundle_with(tmp_path, "ansi", meta_edit=_set(("drawing_name",), "\x1b[31mred\x1b[0m [bold]x[/bold]"))
    code, text = run("info", path)
    assert code == 0 and "\x1b" not in text
    assert "\\x1b[31mred" in text and "[bold]x[/bold]" in text


def test_images_over_the_pixel_limit_are_refused_from_the_header(tmp_path: Path) -> None:
    for name in ("huge.hdr", "huge.png"):
        path = tmp_path / name
        path.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 12000 +X 12000\n" + os.urandom(20000))
        t0 = time.perf_counter()
        code, text = run("decode", BUNDLED_MODEL, path)
        assert code == 1 and time.perf_counter() - t0 < 2.0
        one_error(text, "too large to decode")


def test_unreadable_and_corrupt_images(tmp_path: Path) -> None:
    locked = tmp_path / "locked.png"
    locked.write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 100)
    locked.chmod(0)
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n" + os.urandom(300))
    for path, message in ((corrupt, "not an image"),) + (((locked, "cannot read"),) if os.geteuid() != 0 else ()):
        code, text = run("decode", BUNDLED_MODEL, path)
        assert code == 1
        one_error(text, message)
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "a.png").write_bytes(corrupt.read_bytes())
    code, text = run("decode", BUNDLED_MODEL, folder)
    assert code == 1 and "warning: skipped frame" in text
    one_error(text, "no frame could be read")


def test_outputs_are_never_half_written_and_never_replace_what_is_not_a_file(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.svg"
    os.mkfifo(fifo)
    link = tmp_path / "link.svg"
    link.symlink_to(tmp_path / "elsewhere.svg")
    for target, message in ((fifo, "not a file"), (link, "is a link"), (tmp_path, "is a folder")):
        code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", target)
        assert code == 1, text
        one_error(text, message)
    assert stat.S_ISFIFO(fifo.lstat().st_mode) and link.is_symlink()
    long_name = tmp_path / ("x" * 250 + ".svg")
    code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", long_name)
    assert code == 0 and long_name.is_file(), text  # the temporary name is short
    too_long = tmp_path / ("x" * 260 + ".svg")
    code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", too_long)
    assert code == 1
    one_error(text, "longer than 255 bytes")
    # the documented maximum print is refused before anything is written
    svg_out, png_out = tmp_path / "max.svg", tmp_path / "max.png"
    code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", svg_out, "--png", png_out,
                     "--width-mm", "2000", "--dpi", "2400")  # fmt: skip
    assert code == 1 and not svg_out.exists() and not png_out.exists()
    one_error(text, "pixels across")
    odd = tmp_path / "[red]odd[/red].svg"
    code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", odd)
    assert code == 0 and odd.is_file() and "[red]odd[/red]" in text


def test_a_group_of_outputs_is_all_or_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    first, second = tmp_path / "a.svg", tmp_path / "b.png"
    first.write_bytes(b"old a")
    real_replace = os.replace
    calls = []

    def failing_replace(src, dst):
        calls.append(dst)
        if str(dst) == str(second):
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", failing_replace)
    with pytest.raises(DeepMorphError, match="No space left on device"):
        atomic_write_all([(first, b"new a"), (second, b"new b")])
    monkeypatch.setattr(os, "replace", real_replace)
    assert first.read_bytes() == b"old a" and not second.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.svg"]  # no temporary file left


def test_a_full_disk_and_a_read_only_folder_are_one_clear_error(tmp_path: Path, tiny_disk: Path | None) -> None:
    if Path("/dev/full").exists():
        with pytest.raises(DeepMorphError, match="exists and is not a file"):
            atomic_write("/dev/full", b"x")
    if tiny_disk is not None:
        with pytest.raises(DeepMorphError, match="No space left on device"):
            atomic_write(tiny_disk / "big.bin", b"x" * (4 << 20))
        assert not any(tiny_disk.iterdir())  # no half file, no temporary file
        code, text = run("encode", BUNDLED_MODEL, "--payload", "0xA1B2C3", "--out", tiny_disk / "c.svg",
                         "--png", tiny_disk / "c.png", "--width-mm", "100", "--dpi", "1200")  # fmt: skip
        assert code == 1 and not any(tiny_disk.iterdir())
        one_error(text, "No space left on device")
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        code, text = run("train", BUNDLED_MODEL.with_suffix(".svg").with_name("ghost.svg"), "--out", ro / "m.dmm")
        assert code == 1
        one_error(text, "permission denied")


@pytest.fixture
def tiny_disk(tmp_path: Path):
    """A 64 KiB tmpfs to fill, where the machine lets a test mount one (else ``None``)."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)], capture_output=True)
    if done.returncode != 0:
        yield None
        return
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], capture_output=True)


def test_stray_temporary_files_of_killed_writers_are_cleaned(tmp_path: Path) -> None:
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stray = tmp_path / f".dm-{dead.pid}-abc123.tmp"
    stray.write_bytes(b"half")
    mine = tmp_path / f".dm-{os.getpid()}-def456.tmp"
    mine.write_bytes(b"mine")
    atomic_write(tmp_path / "out.txt", b"whole")
    assert not stray.exists() and mine.exists() and (tmp_path / "out.txt").read_bytes() == b"whole"


def test_memory_stays_bounded_on_hostile_files(tmp_path: Path) -> None:
    """Under a 3 GiB address-space limit (the rest of the process needs about 2), the extreme
    viewBox and the huge image header fail cleanly instead of allocating hundreds of GB."""
    hdr = tmp_path / "huge.hdr"
    hdr.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 60000 +X 60000\n" + b"\0" * 1000)
    extreme = tmp_path / "extreme.svg"
    extreme.write_text(svg(LINE).replace('viewBox="0 0 24 24"', 'viewBox="0 0 0.001 1000000"'))
    code = (
        "import resource, sys\n"
        "resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))\n"
        "from deepmorph.cli import main\n"
        "sys.argv = ['deepmorph'] + sys.argv[1:]\n"
        "main()\n"
    )
    for args in (
        ["render", extreme, "--out", tmp_path / "x.png", "--width-px", "4096"],
        ["decode", BUNDLED_MODEL, hdr],
    ):
        done = subprocess.run(
            [sys.executable, "-c", code, *map(str, args)], capture_output=True, text=True, timeout=120
        )
        assert done.returncode == 1, done.stderr
        assert "Traceback" not in done.stderr and done.stderr.count("error:") == 1, done.stderr
    assert resource.getrlimit(resource.RLIMIT_AS)  # the limit applied to the children only


def test_renders_are_refused_when_too_large(tmp_path: Path) -> None:
    tall = tmp_path / "tall.svg"
    tall.write_text(svg(LINE).replace('viewBox="0 0 24 24"', 'viewBox="0 0 24 470"'))
    code, text = run("render", tall, "--out", tmp_path / "t.png", "--width-px", "4096")
    assert code == 1
    one_error(text, "larger than DeepMorph makes")
    assert np.isfinite(1.0)
