"""The studio's scan tab reading a camera: a clip for headless Chromium's fake camera and the
scan tab driven over it. Shared by ``bench/studio.py --camera`` (how fast) and
``tests/studio`` (that it reads the print's payload, and only that)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

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
LOOPS = 4  # the scan tab is watched for this many loops of the clip


def camera_args(clip: Path) -> list[str]:
    """Chromium's arguments for a headless browser whose camera plays ``clip`` (allowed unasked)."""
    return [
        *CHROMIUM_ARGS,
        "--use-fake-ui-for-media-stream",
        "--use-fake-device-for-media-stream",
        f"--use-file-for-fake-video-capture={clip}",
    ]


def write_camera_clip(path: Path) -> Path:
    """A 640x480 YUV4MPEG2 clip at :data:`CLIP_FPS`: :data:`CLIP_EMPTY` frames of a bare desk,
    then :data:`CLIP_PRINT` simulated close-up photos (easy) of a print of the bundled ghost
    carrying :data:`CAMERA_PAYLOAD`, each a fresh photo placed on the same desk. Chromium loops
    it, so the print comes into view every ``(CLIP_EMPTY + CLIP_PRINT) / CLIP_FPS`` seconds."""
    import cv2
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scenes import close_up_photo

    art = DeepMorphModel.load(BUNDLED_MODEL).code(CAMERA_PAYLOAD).render(360)
    rng = np.random.default_rng(5)
    desk = np.full((480, 640, 3), 153, np.uint8)  # 0.6 grey, as close_up_photo's desk below
    frames = [desk] * CLIP_EMPTY
    for _ in range(CLIP_PRINT):
        frame = desk.copy()
        frame[20:460, 100:540] = close_up_photo(art, "easy", rng, size=440, desk=0.6)
        frames.append(frame)
    with path.open("wb") as f:
        f.write(f"YUV4MPEG2 W640 H480 F{CLIP_FPS}:1 Ip A1:1 C420jpeg\n".encode())
        for frame in frames:
            f.write(b"FRAME\n")
            f.write(cv2.cvtColor(frame, cv2.COLOR_BGR2YUV_I420).tobytes())
    return path


@dataclass
class LiveScan:
    """What the scan tab showed reading the fake camera: the page's frame rate, and per frame
    (``log``) when it was grabbed and shown (ms), how many prints it found and which payloads
    it read."""

    fps: float
    log: list[dict[str, Any]]

    @property
    def payloads(self) -> list[str]:
        """Every payload read, one per reading."""
        return [hex_ for frame in self.log for hex_ in frame["read"]]

    @property
    def delays_s(self) -> list[float]:
        """Each time the print came into view: from the last frame grabbed without it to its
        payload on the page (an upper bound: it came into view later)."""
        log, delays = self.log, []
        for i in range(1, len(log)):
            if log[i - 1]["found"] == 0 and log[i]["found"] > 0:
                shown = next((f["shown"] for f in log[i:] if f["ok"]), None)
                if shown is not None:
                    delays.append((shown - log[i - 1]["grabbed"]) / 1000)
        return delays

    @property
    def print_fps(self) -> float:
        """Frames per second over the frames that show the print (a bare desk is quicker)."""
        with_print = [(f["shown"] - f["grabbed"]) / 1000 for f in self.log if f["found"] > 0]
        return len(with_print) / sum(with_print) if with_print else float("nan")


def scan_live(page: Any, url: str, model: str = "ghost") -> LiveScan:
    """Open the studio at ``url`` (its printed address) on the scan tab in ``page`` (a Playwright
    page of a browser with :func:`camera_args`), start the camera with ``model`` and watch
    :data:`LOOPS` loops of the clip after its payload first shows; the camera is stopped."""
    page.goto(url + "#scan")
    page.wait_for_selector("body[data-ready='1']")
    page.wait_for_function("() => document.querySelector('#scan-model').options.length > 0")
    page.select_option("#scan-model", model)
    page.click("#camera-start")
    page.wait_for_function(
        f"() => document.querySelector('#scan-result').dataset.payload === '{CAMERA_PAYLOAD}'", timeout=30_000
    )
    loop_ms = 1000 * LOOPS * (CLIP_EMPTY + CLIP_PRINT) / CLIP_FPS
    watched = f"state.live.log.at(-1).grabbed - state.live.log[0].grabbed > {loop_ms}"
    page.wait_for_function(f"() => state.live && state.live.log.length > 0 && {watched}", timeout=60_000)
    scan = LiveScan(float(page.get_attribute("#scan-rate", "data-fps")), page.evaluate("() => state.live.log"))
    page.click("#camera-stop")
    return scan
