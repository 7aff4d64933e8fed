"""The studio under test: ``deepmorph studio`` started as a user starts it (a child process on a
free port with its own data folder), and a headless Debian Chromium driven by Playwright, with a
fake camera playing a clip of simulated close-up photos of a ghost print."""

from __future__ import annotations

import os
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: Where the tabs' screenshots go: docs/studio/ only when asked (``DEEPMORPH_SCREENSHOTS=docs/studio``,
#: docs/studio.md), so that running the tests leaves the repository as it was.
SHOTS = Path(os.environ.get("DEEPMORPH_SCREENSHOTS") or Path(tempfile.gettempdir()) / "deepmorph-studio-shots")
sys.path.insert(0, str(ROOT / "bench"))
from _camera import CAMERA_PAYLOAD, CHROMIUM, camera_args, scan_live, write_camera_clip  # noqa: E402
from _common import free_port  # noqa: E402
from _studio import StudioProcess, studio_process  # noqa: E402

__all__ = ["CAMERA_PAYLOAD", "Server", "free_port", "open_studio", "scan_live", "screenshot"]


@dataclass
class Server(StudioProcess):
    """The studio the tests share: its data folder, and how long it took from the command's
    start to answer."""

    data: Path
    ready_s: float


@pytest.fixture(scope="session")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    data = tmp_path_factory.mktemp("studio-data")
    with studio_process(data) as studio:
        deadline = time.monotonic() + 30
        while True:
            try:
                urllib.request.urlopen(f"{studio.base}/api/check?token={studio.token}", timeout=2)
                break
            except OSError:
                if time.monotonic() > deadline or studio.process.poll() is not None:
                    raise
                time.sleep(0.1)
        ready_s = time.perf_counter() - studio.started
        yield Server(studio.base, studio.token, studio.process, studio.started, data, ready_s)


@pytest.fixture(scope="session")
def camera_clip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The fake camera's clip of a ghost print coming into view (``bench/_camera.py``)."""
    return write_camera_clip(tmp_path_factory.mktemp("camera") / "ghost.y4m")


@pytest.fixture(scope="session")
def browser(camera_clip: Path) -> Iterator[object]:
    playwright_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (the test extra)")
    if not Path(CHROMIUM).is_file():
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium)")
    with playwright_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=camera_args(camera_clip))
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
