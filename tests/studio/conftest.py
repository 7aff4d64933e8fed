"""The studio under test: ``deepmorph studio`` started as a user starts it (a child process on a
free port with its own data folder), and a headless Debian Chromium driven by Playwright, with a
fake camera playing a clip of simulated close-up photos of a ghost print."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Where the tabs' screenshots go: docs/studio/ only when asked (``DEEPMORPH_SCREENSHOTS=docs/studio``,
#: docs/studio.md), so that running the tests leaves the repository as it was.
SHOTS = Path(os.environ.get("DEEPMORPH_SCREENSHOTS") or Path(tempfile.gettempdir()) / "deepmorph-studio-shots")
CHROMIUM = os.environ.get("DEEPMORPH_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
CAMERA_PAYLOAD = "0x5A3C96"  # what the fake camera's print carries
CLIP_FPS = 15
CLIP_EMPTY = 8  # frames of the bare desk, then the print comes into view ...
CLIP_PRINT = 16  # ... for this many frames; the clip loops


@dataclass
class Server:
    """A running studio: its address, token and data folder, and how long it took from the
    command's start to answer."""

    base: str
    token: str
    data: Path
    process: subprocess.Popen[str]
    ready_s: float

    @property
    def url(self) -> str:
        return f"{self.base}/?token={self.token}"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    data = tmp_path_factory.mktemp("studio-data")
    port = free_port()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    started = time.monotonic()
    process = subprocess.Popen(
        [sys.executable, "-m", "deepmorph", "studio", "--no-browser", "--port", str(port), "--data", str(data)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )
    assert process.stdout is not None
    line = process.stdout.readline()
    match = re.search(r"(http://127\.0\.0\.1:\d+)/\?token=(\S+)", line)
    assert match, f"the studio printed {line!r}"
    base, token = match.group(1), match.group(2)
    deadline = time.monotonic() + 30
    while True:
        try:
            urllib.request.urlopen(f"{base}/api/check?token={token}", timeout=2)
            break
        except OSError:
            if time.monotonic() > deadline or process.poll() is not None:
                raise
            time.sleep(0.1)
    server = Server(base, token, data, process, time.monotonic() - started)
    yield server
    process.terminate()
    try:
        process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()


def _write_y4m(frames: list[np.ndarray], path: Path, fps: int = 15) -> None:
    """BGR frames as a YUV4MPEG2 clip (4:2:0), what Chromium's fake camera plays."""
    import cv2

    h, w = frames[0].shape[:2]
    with path.open("wb") as f:
        f.write(f"YUV4MPEG2 W{w} H{h} F{fps}:1 Ip A1:1 C420jpeg\n".encode())
        for frame in frames:
            f.write(b"FRAME\n")
            f.write(cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420).tobytes())


@pytest.fixture(scope="session")
def camera_clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 640x480 clip at :data:`CLIP_FPS`: :data:`CLIP_EMPTY` frames of a bare desk, then
    :data:`CLIP_PRINT` simulated close-up photos (easy) of a print of the bundled ghost carrying
    :data:`CAMERA_PAYLOAD`, each a fresh photo placed on the same desk. Chromium loops it, so the
    print comes into view every ``(CLIP_EMPTY + CLIP_PRINT) / CLIP_FPS`` seconds."""
    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scenes import close_up_photo

    code = DeepMorphModel.load(BUNDLED_MODEL).code(CAMERA_PAYLOAD)
    art = code.render(360)
    rng = np.random.default_rng(5)
    desk = np.full((480, 640, 3), 153, np.uint8)  # 0.6 grey, as close_up_photo's desk below
    frames = [desk] * CLIP_EMPTY
    for _ in range(CLIP_PRINT):
        photo = close_up_photo(art, "easy", rng, size=440, desk=0.6)
        frame = desk.copy()
        frame[20:460, 100:540] = photo
        frames.append(frame)
    path = tmp_path_factory.mktemp("camera") / "ghost.y4m"
    _write_y4m(frames, path, CLIP_FPS)
    return path


@pytest.fixture(scope="session")
def browser(camera_clip: Path) -> Iterator[object]:
    playwright_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (the test extra)")
    if not Path(CHROMIUM).is_file():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(
            executable_path=CHROMIUM,
            args=[
                *CHROMIUM_ARGS,
                "--use-fake-ui-for-media-stream",
                "--use-fake-device-for-media-stream",
                f"--use-file-for-fake-video-capture={camera_clip}",
            ],
        )
        yield browser
        browser.close()


@pytest.fixture
def page(browser, server: Server, tmp_path: Path):  # noqa: ANN201 - a Playwright page
    context = browser.new_context(viewport={"width": 1200, "height": 860}, accept_downloads=True)
    page = context.new_page()
    page.set_default_timeout(30_000)
    yield page
    context.close()


def open_studio(page, server: Server, tab: str = "") -> None:  # noqa: ANN001
    """Open the printed address (``#tab`` to start on a tab) and wait for the page to be set up."""
    page.goto(server.url + (f"#{tab}" if tab else ""))
    page.wait_for_selector("body[data-ready='1']")


def screenshot(page, name: str) -> None:  # noqa: ANN001
    """A screenshot of the page, ``<name>.png`` in :data:`SHOTS` (for docs/studio.md when asked)."""
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"))
