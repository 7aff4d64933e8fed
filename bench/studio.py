"""How fast ``deepmorph studio`` serves its first page and reads a camera, and the memory it holds.

Each round starts ``python -m deepmorph studio --no-browser`` as a user would (a fresh process,
a fresh data folder, a free port) and times, from the process's start: the first page
(``GET /?token=`` followed to ``/``, what the browser opens), then the bundled ghost's drawing
and its first photo decoded (``POST /api/models/ghost/scan``: the model and the photo chain load
on first use). The resident memory (VmRSS) is read idle after the first page and idle again
after that first scan. The table gives the median of ``--repeats`` rounds.

With ``--camera``, each round also opens the scan tab in headless Chromium (Playwright, Debian's
``chromium``) whose fake camera loops a clip of a ghost print coming into view on a desk
(``bench/_camera.py``: 15 frames/s, 640x480), starts the camera with the ghost and watches four
loops: the page's frames per second, those over the frames showing the print, and the longest
time from the print coming into view to its payload on the page. Targets: 10 frames/s, 1 s.

    .venv/bin/python bench/studio.py --repeats 5
    .venv/bin/python bench/studio.py --repeats 3 --camera
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

from _camera import CHROMIUM, camera_args, scan_live, write_camera_clip
from _common import RESULTS, environment, table, write_json
from _studio import studio_process

TARGET_FIRST_PAGE_S = 2.0
TARGET_CAMERA_FPS = 10.0
TARGET_PAYLOAD_SHOWN_S = 1.0


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _photo() -> bytes:
    """A simulated close-up photo of a ghost print, as PNG bytes."""
    import cv2
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scenes import close_up_photo

    art = DeepMorphModel.load(BUNDLED_MODEL).code("0xA1B2C3").render(360)
    ok, buf = cv2.imencode(".png", close_up_photo(art, "medium", np.random.default_rng(0)))
    assert ok
    return buf.tobytes()


def _camera_round(url: str, clip: Path) -> dict[str, float]:
    """The scan tab over the fake camera (``clip``) at the studio's printed ``url``."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=camera_args(clip))
        try:
            page = browser.new_context(viewport={"width": 1200, "height": 860}).new_page()
            scan = scan_live(page, url)
        finally:
            browser.close()
    shown_s = max(scan.delays_s, default=float("nan"))  # nan: the print never left the view and came back
    return {"camera_fps": scan.fps, "camera_print_fps": scan.print_fps, "payload_shown_s": shown_s}


def one_round(photo: bytes, clip: Path | None = None) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as data, studio_process(Path(data)) as studio:
        browser = urllib.request.build_opener(urllib.request.HTTPCookieProcessor())  # keeps the token's cookie
        while True:
            try:
                with browser.open(studio.url, timeout=5) as response:
                    assert b"DeepMorph studio" in response.read()
                break
            except urllib.error.HTTPError:
                raise
            except OSError:
                if studio.process.poll() is not None:
                    raise RuntimeError("the studio stopped") from None
                time.sleep(0.02)
        first_page = time.perf_counter() - studio.started
        time.sleep(1.0)
        idle = _rss_mb(studio.process.pid)
        scan = urllib.request.Request(
            f"{studio.base}/api/models/ghost/scan", data=photo, headers={"X-DeepMorph-Token": studio.token}
        )
        t0 = time.perf_counter()
        with urllib.request.urlopen(scan, timeout=120) as response:
            assert b'"ok":true' in response.read()
        first_scan = time.perf_counter() - t0
        with urllib.request.urlopen(scan, timeout=120) as response:
            response.read()
        time.sleep(1.0)
        loaded = _rss_mb(studio.process.pid)
        camera = _camera_round(studio.url, clip) if clip is not None else {}
    started_up = {"first_page_s": first_page, "idle_rss_mb": idle, "first_scan_s": first_scan, "loaded_rss_mb": loaded}
    return {**started_up, **camera}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--camera", action="store_true", help="also read a fake camera in the scan tab (Chromium)")
    ap.add_argument("--out", type=Path, default=RESULTS / "studio.json")
    args = ap.parse_args()
    if args.camera and not Path(CHROMIUM).is_file():
        raise SystemExit(f"--camera needs Chromium at {CHROMIUM} (apt-get install chromium, or DEEPMORPH_CHROMIUM)")
    photo = _photo()
    with tempfile.TemporaryDirectory() as folder:
        clip = write_camera_clip(Path(folder) / "ghost.y4m") if args.camera else None
        rounds = [one_round(photo, clip) for _ in range(args.repeats)]
    med = {k: statistics.median(r[k] for r in rounds) for k in rounds[0]}
    rows = [
        ["start to first page", f"{med['first_page_s']:.2f} s", f"target {TARGET_FIRST_PAGE_S:g} s"],
        ["idle memory (RSS) after the first page", f"{med['idle_rss_mb']:.0f} MB", "no torch loaded"],
        ["first photo decoded (loads the model)", f"{med['first_scan_s']:.2f} s", "ghost, 240 px close-up"],
        ["idle memory after a decode", f"{med['loaded_rss_mb']:.0f} MB", "torch, model, photo chain"],
    ]
    if args.camera:
        fps_target, shown_target = f"target {TARGET_CAMERA_FPS:g}", f"target {TARGET_PAYLOAD_SHOWN_S:g} s"
        rows += [
            ["scan tab, fake camera", f"{med['camera_fps']:.1f} frames/s", fps_target],
            ["... over frames showing the print", f"{med['camera_print_fps']:.1f} frames/s", fps_target],
            ["print in view to payload shown (longest)", f"{med['payload_shown_s']:.2f} s", shown_target],
        ]
    print(table(["what", f"median of {args.repeats}", "note"], rows))
    path = write_json(args.out, {"environment": environment(), "median": med, "rounds": rounds})
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
