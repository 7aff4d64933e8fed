"""The studio end to end: requests without the token fail; runs queue one after another; in
headless Chromium, a dropped drawing opens and its morphs stay inside its bounds, bounds set by
clicking reach the downloaded SVG, capacity is predicted and its limiting shapes outlined, a
registry entry shows when an uploaded photo is decoded and an unread one says why, a PDF of the
bundled ghost is printed in a counted number of clicks and seconds, a payload typed as a number
or hex or picked from the registry is printed as an SVG and a PNG that read back to it, a short
training run's progress reaches the page (and survives a reload, and a run can be cancelled),
and the scan tab reads a fake camera (how fast: ``bench/studio.py --camera``). Each tab's screenshot is taken (to docs/studio/ with ``DEEPMORPH_SCREENSHOTS``)."""

from __future__ import annotations

import http.client
import json
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from lxml import etree

from tests.studio.conftest import CAMERA_PAYLOAD, Server, open_studio, scan_live, screenshot

ROOT = Path(__file__).resolve().parents[2]
GHOST = ROOT / "deepmorph_core" / "data" / "ghost.svg"
DM = "{urn:deepmorph:1}"
TOO_LARGE = "payload '16777216' is too large for 24 bits: the largest is 16777215 (0xFFFFFF)"  # a ghost's payload
TINY = b"""<svg xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1" viewBox="0 0 24 24">
<g stroke="black" stroke-width="2.5" stroke-linecap="round" stroke-linejoin="round" fill="none" dm:move="2.5">
  <polyline points="4 6 12 4 20 6"/>
  <line x1="4" y1="12" x2="20" y2="12"/>
  <polyline points="4 18 12 20 20 18"/>
  <circle cx="12" cy="12" r="3" dm:move="1.5"/>
</g>
</svg>"""


def request(server: Server, path: str, *, token: str | None = None, data: bytes | None = None,
            headers: dict[str, str] | None = None) -> tuple[int, bytes]:  # fmt: skip
    """One HTTP request; the status and body (errors included)."""
    req = urllib.request.Request(server.base + path, data=data, headers=dict(headers or {}))
    if token is not None:
        req.add_header("X-DeepMorph-Token", token)
    try:
        with urllib.request.urlopen(req, timeout=60) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


# -- without a browser ------------------------------------------------------------------------


def test_no_request_without_the_token_succeeds(server: Server) -> None:
    routes = [
        ("/", None),
        ("/static/studio.js", None),
        ("/api/check", None),
        ("/api/drawing.svg", None),
        ("/api/models", None),
        ("/api/jobs/events", None),
        ("/api/models/ghost/print?payload=0xA1B2C3&format=pdf", None),
        ("/api/drawing", GHOST.read_bytes()),
        ("/api/jobs", b"{}"),
        ("/api/models/ghost/entries", b'{"payload": "0x000001", "target": "https://example.com"}'),
    ]
    for path, data in routes:
        for token in (None, "wrong-" + server.token, server.token[:-1]):
            status, body = request(server, path, token=token, data=data)
            assert status == 403, (path, token, status)
            assert b"token" in body
    assert request(server, "/api/check", token=server.token) == (200, b'{"ok":true}')
    # a page of another site may not use a token it learnt, nor a foreign Host name (DNS rebinding)
    status, _ = request(server, "/api/jobs", token=server.token, data=b"{}", headers={"Origin": "http://evil.example"})
    assert status == 403
    status, _ = request(server, "/api/check", token=server.token, headers={"Host": "evil.example"})
    assert status == 403


def test_capacity_says_how_often_a_colour_drawing_is_found(server: Server) -> None:
    """The capacity tab of a colour drawing simulates hard photos of it in the background, with
    its channel, and names a drawing found too seldom: the Icons8 add-row, its pale row morphing,
    is found in fewer than 32 of 40 (27 when measured)."""
    svg = (ROOT / "tests" / "data" / "flat-color-icons" / "add-row.svg").read_bytes()
    svg = svg.replace(
        b'xmlns="http://www.w3.org/2000/svg"', b'xmlns="http://www.w3.org/2000/svg" xmlns:dm="urn:deepmorph:1"'
    )
    svg = svg.replace(b'<path fill="#90CAF9"', b'<path dm:move="0.5" fill="#90CAF9"')
    assert request(server, "/api/drawing", token=server.token, data=svg)[0] == 200
    try:
        deadline = time.monotonic() + 240
        while True:
            status, answer = request(server, "/api/capacity", token=server.token)
            assert status == 200
            data = json.loads(answer)
            if data["channel_measured"] or time.monotonic() > deadline:
                break
            time.sleep(2)
        found, shots = data["found"]
        assert shots == 40 and found < 32
        assert any(f"found the print in only {found} of 40" in line for line in data["limits"])
    finally:
        request(server, "/api/drawing/bundled", token=server.token, data=b"{}")


def test_bad_input_is_one_clear_message(server: Server) -> None:
    status, body = request(server, "/api/drawing", token=server.token, data=b"<svg><script>alert(1)</script>")
    assert status == 400 and "Traceback" not in body.decode()
    assert json.loads(body)["error"]
    # a huge upload is refused from its declared length, before its bytes are read
    conn = http.client.HTTPConnection(server.base.removeprefix("http://"), timeout=30)
    conn.putrequest("POST", "/api/drawing")
    conn.putheader("X-DeepMorph-Token", server.token)
    conn.putheader("Content-Length", str(3 * 1024 * 1024))
    conn.endheaders()
    response = conn.getresponse()
    assert response.status == 413 and "more than the studio accepts" in json.loads(response.read())["error"]
    conn.close()
    status, body = request(server, "/api/models/ghost/scan", token=server.token, data=b"not an image")
    assert status == 400 and "not an image" in json.loads(body)["error"]
    status, body = request(server, "/api/models/ghost/print?payload=0x12&format=pdf", token=server.token)
    assert status == 400 and "0x12" in json.loads(body)["error"]


def test_the_print_routes_read_payloads_as_the_user_chose(server: Server) -> None:
    """``payload_as`` says what the Print tab's payload text is; without it the text is read as
    ``deepmorph encode --payload`` reads it (``0x`` hex, ``0d`` a number, else bits)."""

    def printed(query: str) -> tuple[int, str]:
        req = urllib.request.Request(f"{server.base}/api/models/ghost/print?format=svg&{query}",
                                     headers={"X-DeepMorph-Token": server.token})  # fmt: skip
        try:
            with urllib.request.urlopen(req, timeout=60) as response:
                return response.status, response.headers["X-DeepMorph-Payload"]
        except urllib.error.HTTPError as exc:
            return exc.code, json.loads(exc.read())["error"]

    for query in ("payload=10597059&payload_as=number", "payload=0d10597059", "payload=A1B2C3&payload_as=hex",
                  "payload=0xA1B2C3"):  # fmt: skip
        assert printed(query) == (200, "0xA1B2C3"), query
    assert printed("payload=0101&payload_as=number") == (200, "0x000065")  # a number, never bits
    assert printed("payload=16777216&payload_as=number") == (400, TOO_LARGE)
    status, error = printed("payload=12&payload_as=octal")
    assert status == 400 and error == "payload_as: 'octal'; a payload is typed as hex, number, bits"
    sheet = {"payload_as": "number", "start": "16777214", "count": 3}
    status, body = request(server, "/api/models/ghost/sheet", token=server.token, data=json.dumps(sheet).encode())
    assert status == 400 and "3 payloads from 0xFFFFFE pass the model's largest payload" in json.loads(body)["error"]


def test_served_svgs_are_inert(server: Server) -> None:
    status, _ = request(server, "/api/drawing/bundled", token=server.token, data=b"{}")
    assert status == 200
    req = urllib.request.Request(server.base + "/api/drawing.svg", headers={"X-DeepMorph-Token": server.token})
    with urllib.request.urlopen(req) as response:
        assert response.headers["Content-Type"] == "image/svg+xml"
        assert "sandbox" in response.headers["Content-Security-Policy"]
        assert "default-src 'none'" in response.headers["Content-Security-Policy"]
        assert response.headers["X-Content-Type-Options"] == "nosniff"


def test_a_training_run_is_refused_when_the_disk_is_full(tmp_path: Path) -> None:
    from deepmorph.studio.jobs import JobQueue
    from deepmorph_core.errors import DeepMorphError

    queue = JobQueue(tmp_path / "jobs", tmp_path / "models", min_free_bytes=2**62)
    with pytest.raises(DeepMorphError, match="MiB free on this disk"):
        queue.submit("tiny.svg", TINY.decode(), {"payload_bits": 4, "train": {}, "validation": [0, 0]})
    assert queue.list() == []


def test_a_runs_steps_grow_when_training_goes_on_past_them(tmp_path: Path) -> None:
    """An ``auto`` code cut when training ends trains on past the run's steps: the job's total
    follows, so its progress never passes its end."""
    from deepmorph.studio.jobs import Job, JobQueue

    queue = JobQueue(tmp_path / "jobs", tmp_path / "models")
    job = Job(id="j", drawing="tiny.svg", svg="", out="tiny.dmm", settings={})
    queue._apply(job, {"event": "start", "total": 40, "done": 0})
    queue._apply(job, {"event": "log", "line": {"step": 30, "stage": 2, "elapsed_s": 1.0}})
    assert (job.step, job.total) == (30, 40)
    queue._apply(job, {"event": "log", "line": {"step": 55, "stage": 2, "elapsed_s": 2.0}})
    assert (job.step, job.total) == (55, 55)


def test_listening_beyond_this_machine_warns(tmp_path: Path) -> None:
    import subprocess
    import sys

    from tests.studio.conftest import free_port

    process = subprocess.Popen(
        [sys.executable, "-m", "deepmorph", "studio", "--no-browser", "--host", "0.0.0.0",
         "--port", str(free_port()), "--data", str(tmp_path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        warning = process.stderr.readline()
        address = process.stdout.readline()
    finally:
        process.terminate()
        process.wait(timeout=30)
    assert warning.startswith("warning: --host 0.0.0.0: the studio is reachable from other machines")
    assert "?token=" in address


def test_a_run_cancelled_as_it_starts_says_cancelled(tmp_path: Path) -> None:
    from deepmorph.studio.jobs import JobQueue
    from deepmorph_core.errors import DeepMorphError

    queue = JobQueue(tmp_path / "jobs", tmp_path / "models", min_free_bytes=0)
    settings = {"payload_bits": 4, "validation": [0, 0],
                "train": {"steps": 100_000, "batch": 8, "width": 40, "log_every": 25, "threads": 1}}  # fmt: skip
    job = queue.submit("tiny.svg", TINY.decode(), settings)
    deadline = time.monotonic() + 30
    while queue.list()[0]["status"] != "running" and time.monotonic() < deadline:
        time.sleep(0.01)
    queue.cancel(job["id"])  # while the worker still imports torch, or just after
    while queue.list()[0]["status"] == "running" and time.monotonic() < deadline + 30:
        time.sleep(0.05)
    run = queue.list()[0]
    assert run["status"] == "cancelled", run
    # a run that has ended cannot be cancelled again, and says why
    with pytest.raises(DeepMorphError, match="already ended"):
        queue.cancel(job["id"])


def test_a_second_drawing_waits_for_the_first_run(tmp_path: Path) -> None:
    from deepmorph.studio.jobs import JobQueue

    def now(job: dict) -> dict:
        return next(j for j in queue.list() if j["id"] == job["id"])

    def status(job: dict) -> str:
        return now(job)["status"]

    def wait(job: dict, wanted: tuple[str, ...]) -> str:
        deadline = time.monotonic() + 60
        while status(job) not in wanted and time.monotonic() < deadline:
            time.sleep(0.05)
        return status(job)

    queue = JobQueue(tmp_path / "jobs", tmp_path / "models", min_free_bytes=0)
    train = {"batch": 8, "width": 40, "log_every": 1, "threads": 1}
    first = queue.submit("first.svg", TINY.decode(), {"payload_bits": 4, "validation": [0, 0],
                                                      "train": {**train, "steps": 100_000}})  # fmt: skip
    second = queue.submit("second.svg", TINY.decode(), {"payload_bits": 4, "validation": [0, 0],
                                                        "train": {**train, "steps": 3}})  # fmt: skip
    assert wait(first, ("running",)) == "running"
    deadline = time.monotonic() + 60
    while not now(first)["step"] and time.monotonic() < deadline:  # the first run trains ...
        time.sleep(0.05)
    assert status(second) == "queued"  # ... and the second waits
    queue.cancel(first["id"])
    assert wait(first, ("cancelled", "failed")) == "cancelled"
    assert wait(second, ("finished", "failed", "cancelled")) == "finished", queue.list()
    assert Path(second["out"]).is_file()


def test_the_validation_is_said_in_plain_words() -> None:
    from deepmorph.studio.jobs import validation_words

    records = [
        {"name": "renders", "samples": 1000, "read": 994, "wrong": 0},
        {"name": "close-ups", "samples": 200, "read": 199, "wrong": 1},
    ]
    assert validation_words(records) == (
        "reads 99.4 % of 1000 fresh renders; reads 99.5 % of 200 simulated phone photos, 1 wrong"
    )
    assert validation_words([]) == "finished (no validation asked for)"


# -- in the browser ---------------------------------------------------------------------------


def _click_shape(page, index: int) -> None:  # noqa: ANN001
    """A real mouse click on a shape's first control point, where the page draws it."""
    info = page.evaluate("() => state.drawing")
    x0, y0, w, h = info["viewbox"]
    px, py = info["primitives"][index]["points"][0]
    box = page.locator("#overlay").bounding_box()
    scale = min(box["width"] / w, box["height"] / h)
    left = box["x"] + (box["width"] - w * scale) / 2
    top = box["y"] + (box["height"] - h * scale) / 2
    page.mouse.click(left + (px - x0) * scale, top + (py - y0) * scale)


def test_bounds_set_by_clicking_are_in_the_downloaded_svg(page, server: Server, tmp_path: Path) -> None:
    open_studio(page, server)
    broken = tmp_path / "broken.svg"
    broken.write_bytes(b'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 10 10"><text>hi</text></svg>')
    page.set_input_files("#svg-file", str(broken))
    page.wait_for_selector("#error:not([hidden])")
    assert "broken.svg" in page.text_content("#error") and "Traceback" not in page.text_content("#error")
    with page.expect_response("**/api/drawing"):
        page.set_input_files("#svg-file", str(GHOST))
    page.wait_for_function("() => state.drawing && state.drawing.name === 'ghost.svg' && state.selected === null")
    # the left arm (primitive 4): wider movement; the right arm (5): fixed
    _click_shape(page, 4)
    page.wait_for_selector("#bounds-form:not([hidden])")
    assert page.text_content("#sel-index") == "#4"
    page.fill("#bounds-form input[name=move]", "2.2")
    with page.expect_response("**/api/drawing/bounds"):
        page.click("#apply-bounds")
    _click_shape(page, 5)
    page.wait_for_function("() => document.querySelector('#sel-index').textContent === '#5'")
    page.check("#bounds-form input[name=fixed]")
    with page.expect_response("**/api/drawing/bounds"):
        page.click("#apply-bounds")
    page.wait_for_function("() => state.drawing.primitives[5].fixed")
    # the eyes' group (fixed in the ghost): may now move a little, set once on the <g>
    _click_shape(page, 1)
    page.wait_for_function("() => document.querySelector('#sel-index').textContent === '#1'")
    page.check("#bounds-form input[name=group]")
    page.uncheck("#bounds-form input[name=fixed]")
    page.fill("#bounds-form input[name=move]", "0.6")
    with page.expect_response("**/api/drawing/bounds"):
        page.click("#apply-bounds")
    page.wait_for_function("() => !state.drawing.primitives[2].fixed")
    assert page.evaluate("() => state.drawing.primitives[4].move_radius") == pytest.approx(2.2)
    _click_shape(page, 4)
    assert "2.2 units" in page.text_content("#sel-mm")
    screenshot(page, "drawing")
    with page.expect_download() as download:
        page.click("#download-svg")
    path = tmp_path / "annotated.svg"
    download.value.save_as(path)
    shapes = [e for e in etree.parse(str(path)).getroot().iter() if etree.QName(e).localname == "polyline"]
    assert shapes[0].get(f"{DM}move") == "2.2"  # the left arm
    assert shapes[1].get(f"{DM}fixed") == "true"  # the right arm
    eyes = next(e for e in etree.parse(str(path)).getroot().iter() if etree.QName(e).localname == "g")
    assert eyes.get(f"{DM}move") == "0.6" and eyes.get(f"{DM}fixed") is None
    assert b"<script" not in path.read_bytes()


def test_shift_scale_and_rotation_set_by_clicking_are_in_the_downloaded_svg(page, server: Server,
                                                                          tmp_path: Path) -> None:  # fmt: skip
    """``dm:shift``, ``dm:scale`` and ``dm:rotate`` set in the shape panel: drawn (the shift's
    box), read back by the reader (a range it refuses is refused at once) and downloaded."""
    open_studio(page, server)
    with page.expect_response("**/api/drawing"):
        page.set_input_files("#svg-file", str(GHOST))
    page.wait_for_function("() => state.drawing && state.drawing.name === 'ghost.svg' && state.selected === null")

    def apply(index: int, **fields: str) -> None:
        _click_shape(page, index)
        page.wait_for_function("(i) => document.querySelector('#sel-index').textContent === `#${i}`", arg=index)
        for name in ("shift", "scale", "rotate"):
            page.fill(f"#bounds-form input[name={name}]", fields.get(name, ""))
        with page.expect_response("**/api/drawing/bounds"):
            page.click("#apply-bounds")

    apply(4, shift="1.5 0.5")  # the left arm
    apply(5, scale="0.9 1.1")  # the right arm
    apply(3, rotate="-8 8")  # the mouth
    page.wait_for_function("() => state.drawing.primitives[3].own && state.drawing.primitives[3].own.rotate")
    assert page.evaluate("() => state.drawing.primitives[4].shift") == [1.5, 0.5]
    assert page.locator("#overlay .shape[data-index='4'] rect.shift").count() == 1  # the shift's box
    own = page.evaluate("() => [4, 5, 3].map(i => state.drawing.primitives[i].own)")
    assert [o.get(k) for o, k in zip(own, ("shift", "scale", "rotate"), strict=True)] == ["1.5 0.5", "0.9 1.1", "-8 8"]
    _click_shape(page, 5)  # the panel shows what is set
    page.wait_for_function("() => document.querySelector('#sel-index').textContent === '#5'")
    assert page.input_value("#bounds-form input[name=scale]") == "0.9 1.1"

    # a range the reader refuses is one line in the red bar, and nothing is written
    page.fill("#bounds-form input[name=scale]", "1.1 0.9")
    page.click("#apply-bounds")
    page.wait_for_selector("#error:not([hidden])")
    assert "lower bound 1.1 is above upper bound 0.9" in page.text_content("#error")
    assert "Traceback" not in page.text_content("#error")

    with page.expect_download() as download:
        page.click("#download-svg")
    path = tmp_path / "annotated.svg"
    download.value.save_as(path)
    root = etree.parse(str(path)).getroot()
    arms = [e for e in root.iter() if etree.QName(e).localname == "polyline"][:2]
    mouth = [e for e in root.iter() if etree.QName(e).localname == "path"][1]
    assert arms[0].get(f"{DM}shift") == "1.5 0.5" and arms[0].get(f"{DM}scale") is None
    assert arms[1].get(f"{DM}scale") == "0.9 1.1"
    assert mouth.get(f"{DM}rotate") == "-8 8" and mouth.get(f"{DM}move") == "0.9"


def _drop_file(page, selector: str, name: str, text: str) -> None:  # noqa: ANN001
    """A file dropped on an element, as a file dragged from the desktop arrives."""
    page.evaluate(
        """([selector, name, text]) => {
             const files = new DataTransfer();
             files.items.add(new File([text], name, { type: "image/svg+xml" }));
             const target = document.querySelector(selector);
             for (const type of ["dragover", "drop"]) {
               target.dispatchEvent(new DragEvent(type, { dataTransfer: files, bubbles: true, cancelable: true }));
             }
           }""",
        [selector, name, text],
    )


def _moves(server: Server, src: str) -> list[float]:
    """How far each point of the ghost's lines and polylines is from its place in the morph the
    page shows at ``src``; the fixed eyes must be where they are."""
    status, svg = request(server, src, token=server.token)
    assert status == 200, svg

    def points(root: etree._Element) -> list[tuple[float, float]]:
        found = []
        for e in root.iter():
            name = etree.QName(e).localname
            if name == "polyline":
                numbers = [float(n) for n in e.get("points").replace(",", " ").split()]
                found += list(zip(numbers[::2], numbers[1::2], strict=True))
            elif name == "line":
                found += [(float(e.get("x1")), float(e.get("y1"))), (float(e.get("x2")), float(e.get("y2")))]
        return found

    def eyes(root: etree._Element) -> list[tuple[str | None, ...]]:
        return [(e.get("cx"), e.get("cy"), e.get("r")) for e in root.iter() if etree.QName(e).localname == "circle"]

    base, morphed = etree.parse(str(GHOST)).getroot(), etree.fromstring(svg)
    assert eyes(morphed) == eyes(base) and len(eyes(base)) == 2
    pairs = list(zip(points(base), points(morphed), strict=True))
    return [((x - u) ** 2 + (y - v) ** 2) ** 0.5 for (x, y), (u, v) in pairs]


def test_a_dropped_drawing_morphs_inside_its_bounds(page, server: Server) -> None:
    """An SVG dropped on the Drawing tab opens; Random morph, Extremes and Animate show morphs
    that keep every point within its ``dm:move`` (1.4 units in the ghost), the extremes on it."""
    open_studio(page, server)
    _drop_file(page, "#stage", "dropped-ghost.svg", GHOST.read_text())
    page.wait_for_function("() => state.drawing && state.drawing.name === 'dropped-ghost.svg'")
    assert page.is_hidden("#error")

    def shown(click: str, seed: int) -> str:
        page.click(click)
        page.wait_for_function(
            "(seed) => { const i = document.querySelector('#drawing-img');"
            " return i.src.includes(`morph.svg?seed=${seed}&`) && i.complete && i.naturalWidth > 0; }",
            arg=seed,
        )
        return page.get_attribute("#drawing-img", "src")

    first, second = _moves(server, shown("#morph-random", 1)), _moves(server, shown("#morph-random", 2))
    assert first != second  # each click a new morph
    for moves in (first, second):
        assert max(moves) <= 1.4 + 1e-3 and sum(m > 0.1 for m in moves) > len(moves) / 2, moves
    extremes = _moves(server, shown("#morph-extreme", 3))
    assert all(abs(m - 1.4) < 1e-3 for m in extremes), extremes  # every point on the edge of its disk

    # Animate: morphs follow each other with no more clicks, until Stop
    page.click("#morph-animate")
    page.wait_for_function("() => /morph.svg\\?seed=7&extreme=1/.test(document.querySelector('#drawing-img').src)",
                           timeout=10_000)  # fmt: skip
    assert page.text_content("#morph-animate") == "Stop"
    page.click("#morph-animate")
    assert page.text_content("#morph-animate") == "Animate"
    page.wait_for_function("() => document.querySelector('#drawing-img').src.includes('/api/drawing.svg')")
    time.sleep(1.0)  # longer than a frame of the animation: it has stopped
    assert "/api/drawing.svg" in page.get_attribute("#drawing-img", "src")


def test_capacity_tab_predicts_the_ghosts_payload(page, server: Server) -> None:
    request(server, "/api/drawing/bundled", token=server.token, data=b"{}")
    open_studio(page, server, "capacity")  # opening the tab predicts, for the bounds as they are
    page.wait_for_selector("#capacity-bits")
    assert "bits read from 99 % of captures" in page.text_content("#capacity-bits")
    screenshot(page, "capacity")


def test_the_limiting_shapes_are_highlighted_as_the_bounds_change(page, server: Server) -> None:
    """A mouth that may barely move limits what the ghost carries: the Capacity tab says so and the
    Drawing tab outlines it; given room to move, it is no longer outlined."""
    request(server, "/api/drawing/bundled", token=server.token, data=b"{}")
    open_studio(page, server)
    page.wait_for_function("() => state.drawing && state.drawing.name === 'ghost.svg'")

    def weak_after_move(move: str) -> tuple[list[str], str]:
        page.click("#tabs button[data-tab=drawing]")
        _click_shape(page, 3)  # the mouth
        page.wait_for_function("() => document.querySelector('#sel-index').textContent === '#3'")
        page.fill("#bounds-form input[name=move]", move)
        with page.expect_response("**/api/drawing/bounds"):
            page.click("#apply-bounds")
        page.evaluate("clearCapacity()")  # the last view's table is not mistaken for this one
        with page.expect_response("**/api/capacity?**"):
            page.click("#tabs button[data-tab=capacity]")
        page.wait_for_selector("#capacity-sizes tr.yours")
        limits = page.text_content("#capacity-limits")
        page.click("#tabs button[data-tab=drawing]")
        return page.eval_on_selector_all("#overlay .shape.weak", "gs => gs.map(g => g.dataset.index)"), limits

    weak, limits = weak_after_move("0.25")
    assert weak == ["3"] and "shape 3 (" in limits and "2 of its 2 visible variables show only a little" in limits
    weak, limits = weak_after_move("3")
    assert weak == [] and "shape 3" not in limits


def test_an_unread_or_too_small_print_says_so(page, server: Server, tmp_path: Path) -> None:
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.image_io import save_bgr
    from deepmorph_core.model import DeepMorphModel
    from tests.detect.test_too_small import small_prints

    blank = tmp_path / "desk.png"
    save_bgr(np.full((240, 320, 3), 150, np.uint8), blank)
    open_studio(page, server, "scan")
    page.wait_for_function("() => document.querySelector('#scan-model').options.length > 0")
    page.set_input_files("#photo-file", str(blank))
    page.wait_for_function("() => document.querySelector('#scan-result').textContent.length > 0")
    assert "no drawing found: is the print in view" in page.text_content("#scan-result")
    notes = []
    for photo, _ in small_prints(DeepMorphModel.load(BUNDLED_MODEL)):  # prints about 40 px wide
        path = tmp_path / "small.png"
        save_bgr(photo, path)
        status, body = request(server, "/api/models/ghost/scan", token=server.token, data=path.read_bytes())
        assert status == 200, body
        result = json.loads(body)
        read = any(d["ok"] for d in result["detections"])
        assert bool(result["note"]) != read, result  # a note exactly where nothing was read
        notes.append(result["note"])
    small = [n for n in notes if "too small to read (needs 96): move closer" in n]
    assert len(small) >= 3, notes


def test_a_registry_entry_appears_when_an_uploaded_photo_is_decoded(page, server: Server, tmp_path: Path) -> None:
    import numpy as np

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.image_io import save_bgr
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scenes import close_up_photo

    payload, target = "0x1F2E3D", "https://example.com/ghost-offer"
    open_studio(page, server, "payloads")
    page.wait_for_function("() => document.querySelector('#payloads-model').options.length > 0")
    page.fill("#entry-form input[name=payload]", payload)
    page.fill("#entry-form input[name=target]", target)
    page.fill("#entry-form input[name=note]", "the studio test")
    page.click("#entry-add")
    page.wait_for_function(
        f"() => [...document.querySelectorAll('#entries td')].some(td => td.textContent === '{payload}')"
        " || !document.querySelector('#error').hidden"
    )
    assert page.is_hidden("#error"), page.text_content("#error")
    screenshot(page, "payloads")

    art = DeepMorphModel.load(BUNDLED_MODEL).code(payload).render(360)
    photo = tmp_path / "photo.png"
    save_bgr(close_up_photo(art, "medium", np.random.default_rng(2)), photo)
    page.click("#tabs button[data-tab=scan]")
    page.set_input_files("#photo-file", str(photo))
    page.wait_for_function("() => document.querySelector('#scan-result').textContent.length > 0")
    text = page.text_content("#scan-result")
    assert f"{payload} read" in text and target in text, text
    # the pose is drawn as a cube over the photo: its top's edges in blue, its uprights in green
    blue = page.evaluate(
        """() => { const c = document.querySelector('#scan-canvas');
                   const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
                   let n = 0; for (let i = 0; i < d.length; i += 4) n += d[i] < 40 && d[i + 1] < 40 && d[i + 2] > 200;
                   return n; }"""
    )
    assert blue > 50, blue
    screenshot(page, "scan-photo")


def test_an_iphone_heic_photo_is_scanned(page, server: Server, tmp_path: Path) -> None:
    """An iPhone's photos are HEIC: the upload button offers them and the scan reads one."""
    import numpy as np
    from PIL import Image

    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_detect.scenes import close_up_photo

    open_studio(page, server, "scan")
    assert ".heic" in page.get_attribute("#photo-file", "accept").split(",")
    art = DeepMorphModel.load(BUNDLED_MODEL).code("0x1F2E3D").render(360)
    photo = tmp_path / "IMG_0042.HEIC"
    Image.fromarray(close_up_photo(art, "medium", np.random.default_rng(2))[..., ::-1]).save(photo, format="HEIF")
    status, body = request(server, "/api/models/ghost/scan", token=server.token, data=photo.read_bytes())
    assert status == 200, body
    assert [d["payload"]["hex"] for d in json.loads(body)["detections"] if d["ok"]] == ["0x1F2E3D"], body


def test_a_printed_pdf_of_the_ghost_in_two_clicks(page, server: Server, tmp_path: Path) -> None:
    clicks = 0

    def click(selector: str) -> None:
        nonlocal clicks
        clicks += 1
        page.click(selector)

    started = time.monotonic()  # the studio is up: server.ready_s after `deepmorph studio`
    open_studio(page, server)
    click("#tabs button[data-tab=print]")
    page.wait_for_function("() => document.querySelector('#print-payload').value.startsWith('0x')")
    payload = page.input_value("#print-payload")
    with page.expect_download() as download:
        click("#print-pdf")
    path = tmp_path / "ghost.pdf"
    download.value.save_as(path)
    seconds = server.ready_s + time.monotonic() - started
    assert path.read_bytes().startswith(b"%PDF")
    assert payload in download.value.suggested_filename
    print(f"studio to a printed PDF of the ghost: {clicks} clicks, {seconds:.1f} s "
          f"({server.ready_s:.1f} s of it the studio starting)")  # fmt: skip
    assert clicks == 2, clicks  # the target: under 10
    assert seconds < 120, seconds
    page.wait_for_function("() => document.querySelector('#print-preview').complete")
    screenshot(page, "print")


def test_the_page_fetches_nothing_beyond_the_studio(page, server: Server) -> None:
    """The page works offline: every tab, opened in turn, asks the studio alone (no CDN, no font
    or script from elsewhere)."""
    asked: list[str] = []
    page.on("request", lambda r: asked.append(r.url))
    open_studio(page, server)
    for tab in ("capacity", "train", "payloads", "print", "scan", "drawing"):
        page.click(f"#tabs button[data-tab={tab}]")
        page.wait_for_load_state("networkidle")
    elsewhere = [url for url in asked if not url.startswith((server.base + "/", "data:", "blob:"))]
    assert asked and not elsewhere, elsewhere
    assert any(url.endswith("/static/studio.js") for url in asked) and any("/api/models" in url for url in asked)


def test_the_train_form_starts_at_the_training_defaults(page, server: Server) -> None:
    """The page keeps no copy of the training defaults: its form shows the server's (the
    training settings', :func:`deepmorph.studio.app.train_form`), ranges included."""
    from deepmorph.studio.app import train_form

    open_studio(page, server, "train")
    form = train_form()
    for name in ("steps", "batch", "image_width", "validation"):
        shown = page.eval_on_selector(f"#train-form input[name={name}]", "e => [e.value, e.min, e.max]")
        assert shown == [str(form[name][k]) for k in ("default", "min", "max")], name
    assert page.input_value("#train-form input[name=payload_bits]") == form["payload_bits"]["default"] == "auto"


def tiny_run(page, steps: int) -> None:  # noqa: ANN001
    """The Train form filled for a tiny, fast run (typing only: no clicks)."""
    for name, value in (("payload_bits", "4"), ("steps", str(steps)), ("batch", "8"), ("image_width", "40"),
                        ("validation", "0")):  # fmt: skip
        page.fill(f"#train-form input[name={name}]", value)


def test_a_short_training_runs_progress_reaches_the_page(page, server: Server, tmp_path: Path) -> None:
    drawing = tmp_path / "tiny.svg"
    drawing.write_bytes(TINY)
    open_studio(page, server)
    with page.expect_response("**/api/drawing"):
        page.set_input_files("#svg-file", str(drawing))
    page.wait_for_function("() => state.drawing && state.drawing.name === 'tiny.svg'")
    page.click("#tabs button[data-tab=train]")
    tiny_run(page, 40)
    page.click("#train-start")
    # progress arrives while it trains (the bar moves before the end) ...
    page.wait_for_function(
        "() => { const b = document.querySelector('.job progress'); return b && b.value > 0 && b.value < b.max; }",
        timeout=60_000,
    )
    page.reload()  # ... and a reload finds the run again
    page.click("#tabs button[data-tab=train]")
    page.wait_for_selector(".job.finished", timeout=60_000)
    assert "step 40 / 40" in page.text_content(".job.finished .job-progress")
    screenshot(page, "train")
    # the trained model is offered for printing
    page.click("#tabs button[data-tab=print]")
    page.wait_for_function(
        "() => [...document.querySelector('#print-model').options].some(o => o.value.startsWith('tiny-'))"
    )

    # a long run is cancelled: the loop writes its checkpoint and the run says so
    page.click("#tabs button[data-tab=train]")
    tiny_run(page, 100_000)
    page.click("#train-start")
    page.wait_for_function("() => { const j = document.querySelector('.job.running progress'); return j && j.value > 0; }",
                           timeout=60_000)  # fmt: skip
    page.click(".job.running button")
    page.wait_for_selector(".job.cancelled", timeout=60_000)
    assert "interrupted at step" in page.text_content(".job.cancelled .job-message")


def test_the_scan_tab_reads_the_fake_camera(page, server: Server) -> None:
    import cv2
    import numpy as np

    # the model and its photo chain load on their first scan, so the ghost is loaded first; how
    # fast the tab reads a live camera is bench/studio.py --camera's measure, not this test's
    blank = cv2.imencode(".jpg", np.full((480, 640, 3), 200, np.uint8))[1].tobytes()
    assert request(server, "/api/models/ghost/scan", token=server.token, data=blank)[0] == 200
    scan = scan_live(page, server.url)
    screenshot(page, "scan-camera")
    print(f"scan tab, fake camera: {scan.fps:.1f} frames/s, payload shown within "
          f"{max(scan.delays_s, default=float('nan')):.2f} s of the print coming into view")  # fmt: skip
    assert scan.payloads and set(scan.payloads) == {CAMERA_PAYLOAD}, set(scan.payloads)  # only the print's
    assert sum(f["found"] == 0 for f in scan.log) > 0  # the bare desk was seen too, and read as nothing
    assert len(scan.delays_s) >= 2  # each time the print came into view, its payload was shown


def _capacity_rows(page) -> list[list[str]]:  # noqa: ANN001
    return page.evaluate(
        "() => [...document.querySelectorAll('#capacity-sizes tr')].slice(1)"
        ".map(tr => [...tr.children].map(td => td.textContent))"
    )


def _wait_for_the_channel(page) -> None:  # noqa: ANN001
    """Until the capacity table is drawn with the payloads from 200 px up, which wait for the
    drawing's channel, measured in the background (about half a minute a drawing and bounds)."""
    page.wait_for_selector("#capacity-sizes tr.yours")
    page.wait_for_function(
        "() => ![...document.querySelectorAll('#capacity-sizes td')].some(td => td.textContent.startsWith('measuring'))",
        timeout=240_000,
    )


def _expected_rows(
    server: Server, print_mm: float, distance_cm: float, measured: bool = True
) -> tuple[float, list[list[str]]]:
    """The travel and payload table the CLI prints for the studio's drawing as it is now, from
    the library, with the channel the studio measured (``measured``: it must have been;
    ``tests/core/test_channel.py`` tests the measurement)."""
    from dataclasses import replace

    from deepmorph.studio import drawing as drawings
    from deepmorph_core.capacity import predict
    from deepmorph_core.print_size import pixels_across, plan, plan_sizes

    status, svg = request(server, "/api/drawing.svg", token=server.token)
    assert status == 200
    status, answer = request(server, f"/api/capacity?print_mm={print_mm}&distance_cm={distance_cm}", token=server.token)
    assert status == 200 and (json.loads(answer)["channel_measured"] or not measured)
    md = drawings.load(svg, "drawing.svg")
    pixels = pixels_across(print_mm, distance_cm)
    report = replace(predict(md), channel_payload=json.loads(answer)["channel_payload"])
    rows = plan(md, report.visible_mask, plan_sizes(pixels), report)
    return pixels, [
        [f"{r.pixels:.0f} px" + (" ←" if abs(r.pixels - pixels) < 0.5 else ""), f"{r.median_move:.1f} px",
         f"{r.smallest_move:.1f} px", str(r.sub_pixel), r.payload_text]
        for r in rows
    ]  # fmt: skip


def test_capacity_at_a_print_size_and_reading_distance(page, server: Server) -> None:
    request(server, "/api/drawing/bundled", token=server.token, data=b"{}")
    open_studio(page, server, "capacity")
    _wait_for_the_channel(page)
    pixels, rows = _expected_rows(server, 50, 30)
    assert page.text_content("#capacity-span") == (
        f"a 50 mm print at 30 cm spans {pixels:.0f} px of a 1920-px, 65° frame"
    )
    assert _capacity_rows(page) == rows and [r[0] for r in rows].count(f"{pixels:.0f} px ←") == 1
    assert (
        page.text_content("#capacity-reads")
        == "wide enough to read: 251 px across, 96 needed; it reads up to 78 cm away"
    )
    assert "bits read from 99 % of captures" in page.text_content("#capacity-bits")
    assert "reads every print at least 96 px wide in its decoder's 96-px frame" in page.text_content("#capacity-note")
    assert "carries the payload the table gives there" in page.text_content("#capacity-note")

    # another size and distance: the table follows
    page.fill("#capacity-form input[name=print_mm]", "80")
    page.fill("#capacity-form input[name=distance_cm]", "20")
    with page.expect_response("**/api/capacity?print_mm=80&distance_cm=20"):
        page.click("#capacity-run")
    page.wait_for_function("() => document.querySelector('#capacity-span').textContent.startsWith('a 80 mm')")
    pixels, rows = _expected_rows(server, 80, 20)
    assert f"spans {pixels:.0f} px" in page.text_content("#capacity-span")
    assert _capacity_rows(page) == rows

    # too far for the print's size: no payload at that distance, and how near to come
    page.fill("#capacity-form input[name=print_mm]", "20")
    page.fill("#capacity-form input[name=distance_cm]", "100")
    with page.expect_response("**/api/capacity?print_mm=20&distance_cm=100"):
        page.click("#capacity-run")
    page.wait_for_function("() => document.querySelector('#capacity-span').textContent.startsWith('a 20 mm')")
    assert page.text_content("#capacity-reads") == (
        "too small to read: 30 px across, needs 96; hold the camera within 31 cm, or print it wider"
    )
    assert page.get_attribute("#capacity-reads", "class") == "warn"
    assert page.text_content("#capacity-bits") == "none at this print size and distance: too small to read"
    page.fill("#capacity-form input[name=print_mm]", "80")
    page.fill("#capacity-form input[name=distance_cm]", "20")
    with page.expect_response("**/api/capacity?print_mm=80&distance_cm=20"):
        page.click("#capacity-run")
    page.wait_for_function("() => document.querySelector('#capacity-span').textContent.startsWith('a 80 mm')")

    # a wider move for the ghost's mouth (the least-moving shape), set in the Drawing tab: the
    # smallest move grows
    before = _capacity_rows(page)
    page.click("#tabs button[data-tab=drawing]")
    _click_shape(page, 3)
    page.wait_for_function("() => document.querySelector('#sel-index').textContent === '#3'")
    page.fill("#bounds-form input[name=move]", "3")
    with page.expect_response("**/api/drawing/bounds"):
        page.click("#apply-bounds")
    page.evaluate("clearCapacity()")  # the last view's table is not mistaken for this one
    with page.expect_response("**/api/capacity?**"):
        page.click("#tabs button[data-tab=capacity]")
    page.wait_for_selector("#capacity-sizes tr.yours")
    _, rows = _expected_rows(server, 80, 20, measured=False)  # the moves: no need to wait for the channel
    travel = [row[:4] for row in _capacity_rows(page)]
    assert travel == [row[:4] for row in rows] and travel != [row[:4] for row in before]
    assert float(rows[-1][2].split()[0]) > float(before[-1][2].split()[0])

    # bad input: one line in the red bar, no table, no traceback
    for field, value, words in (("print_mm", "-5", "-5.0 mm"), ("distance_cm", "0", "0.0 cm")):
        page.fill("#capacity-form input[name=print_mm]", "50")
        page.fill("#capacity-form input[name=distance_cm]", "30")
        page.fill(f"#capacity-form input[name={field}]", value)
        page.click("#capacity-run")
        page.wait_for_selector("#error:not([hidden])")
        error = page.text_content("#error")
        assert error.startswith("print size, distance and frame width must be positive") and words in error, error
        assert "\n" not in error and "Traceback" not in error
        assert _capacity_rows(page) == []
    status, body = request(server, "/api/capacity?print_mm=fifty", token=server.token)
    assert status == 400 and json.loads(body)["error"] == "print width (mm): expected a number, got 'fifty'"


def _download(page, selector: str, path: Path) -> Path:  # noqa: ANN001
    with page.expect_download() as download:
        page.click(selector)
    download.value.save_as(path)
    return path


def _type_payloads_as(page, form: str) -> None:  # noqa: ANN001
    """Choose how the Print tab's payload is typed, once the previews and downloads the steps
    before it started have finished. Their answers showed or hid the red bar, which used to move
    the form under the pointer; the bar now keeps its line (``studio.css``), and the wait keeps
    the switch apart from answers still in flight all the same."""
    page.wait_for_load_state("networkidle")
    page.check(f"#print-form input[name=payload_as][value={form}]")


def _reads(image) -> list[tuple[str, bool]]:  # noqa: ANN001 - a gray uint8 array
    """What the bundled ghost reads in a code's image, given a white margin."""
    import numpy as np

    import deepmorph
    from deepmorph_core.bundled import BUNDLED_MODEL

    return [(f.payload.hex, f.ok) for f in deepmorph.load(BUNDLED_MODEL).decode(np.pad(image, 40, constant_values=255))]


def _png_reads(path: Path) -> list[tuple[str, bool]]:
    import numpy as np
    from PIL import Image

    return _reads(np.asarray(Image.open(path).convert("L")))


def _svg_reads(path: Path) -> list[tuple[str, bool]]:
    import numpy as np

    from deepmorph_core.render import render_svg

    return _reads((render_svg(path.read_text(), 400) * 255).astype(np.uint8))


def test_a_payload_typed_as_a_number_or_hex_or_picked_from_the_registry(page, server: Server,
                                                                       tmp_path: Path) -> None:  # fmt: skip
    """The Print tab's payload is a number, hex, or one of the model's registry entries (listed
    by what they stand for); each code downloaded as SVG or PNG reads back to it."""
    entries = [("0x00BEEF", "url", "https://example.com/menu", "menu"), ("0x0C0FFE", "text", "Ask at the desk", "")]
    for payload, kind, target, note in entries:
        entry = {"payload": payload, "kind": kind, "target": target, "note": note, "replace": True}
        status, body = request(server, "/api/models/ghost/entries", token=server.token,
                               data=json.dumps(entry).encode(), headers={"Content-Type": "application/json"})  # fmt: skip
        assert status == 200, body
    open_studio(page, server, "print")
    page.wait_for_function("() => document.querySelector('#print-payload').value.startsWith('0x')")
    drawn = page.input_value("#print-payload")

    # a number: the payload above is shown as one, and a number typed is printed
    _type_payloads_as(page, "number")
    assert page.input_value("#print-payload") == str(int(drawn, 16))
    page.click("#print-random")
    page.wait_for_function("(v) => /^[0-9]+$/.test(document.querySelector('#print-payload').value) && "
                           "document.querySelector('#print-payload').value !== v", arg=str(int(drawn, 16)))  # fmt: skip
    page.fill("#print-payload", "10597059")
    png = _download(page, "#print-png", tmp_path / "number.png")
    assert _png_reads(png) == [("0xA1B2C3", True)]
    page.fill("#print-payload", "101")  # a number, never bits
    assert _svg_reads(_download(page, "#print-svg", tmp_path / "101.svg")) == [("0x000065", True)]
    # too large for the model's 24 bits: one line
    page.fill("#print-payload", "16777216")
    page.click("#print-svg")
    page.wait_for_selector("#error:not([hidden])")
    assert page.text_content("#error") == TOO_LARGE
    # a sheet from a number: the payloads typed as numbers too
    page.fill("#sheet-form input[name=start]", "10597059")
    page.fill("#sheet-form input[name=count]", "2")
    sheet = etree.parse(str(_download(page, "#sheet-svg", tmp_path / "numbers.svg"))).getroot()
    assert [e.text for e in sheet if etree.QName(e).localname == "text"] == ["0xA1B2C3", "0xA1B2C4"]
    page.fill("#sheet-form input[name=start]", "")

    # hex: the number shown in hex; the 0x may be left out
    page.fill("#print-payload", "10597059")
    _type_payloads_as(page, "hex")
    assert page.input_value("#print-payload") == "0xA1B2C3"
    page.fill("#print-payload", "5A3C96")
    svg = _download(page, "#print-svg", tmp_path / "hex.svg")
    assert etree.parse(str(svg)).getroot().get("width") == "50mm"
    assert _svg_reads(svg) == [("0x5A3C96", True)]

    # a registry entry, picked by what it stands for
    _type_payloads_as(page, "registry")
    page.wait_for_selector("#print-entry-field:not([hidden])")
    assert page.is_hidden("#print-payload-field")
    labels = page.eval_on_selector_all("#print-entry option", "os => os.map(o => o.textContent)")
    assert {"https://example.com/menu (menu): 0x00BEEF", "Ask at the desk: 0x0C0FFE"} <= set(labels), labels
    page.select_option("#print-entry", label="Ask at the desk: 0x0C0FFE")
    png = _download(page, "#print-png", tmp_path / "entry.png")
    assert _png_reads(png) == [("0x0C0FFE", True)]
    screenshot(page, "print-payload")
    # a sheet of every entry, each labelled with what it stands for
    page.check("#sheet-form input[value=registry]")
    _, listed = request(server, "/api/models/ghost/entries", token=server.token)
    hexes = [e["payload"]["hex"] for e in json.loads(listed)]
    sheet = etree.parse(str(_download(page, "#sheet-svg", tmp_path / "entries.svg"))).getroot()
    texts = [e.text for e in sheet if etree.QName(e).localname == "text"]
    assert [t for t in texts if t.startswith("0x")] == hexes and "Ask at the desk" in texts


def test_a_sheet_of_labelled_codes(page, server: Server, tmp_path: Path) -> None:

    import numpy as np
    from PIL import Image

    import deepmorph
    from deepmorph_core.bundled import BUNDLED_MODEL
    from deepmorph_core.pdf import page_size_points

    menu = "Table 7: the autumn menu, with every dish and its allergens"
    entry = {"payload": "0x5A3C97", "kind": "text", "target": menu, "replace": True}
    status, body = request(server, "/api/models/ghost/entries", token=server.token, data=json.dumps(entry).encode(),
                           headers={"Content-Type": "application/json"})  # fmt: skip
    assert status == 200, body
    open_studio(page, server, "print")
    page.wait_for_function("() => document.querySelector('#print-payload').value.startsWith('0x')")
    page.fill("#sheet-form input[name=start]", "0x5A3C96")
    page.fill("#sheet-form input[name=count]", "6")
    page.press("#sheet-form input[name=count]", "Tab")  # a change: the preview follows
    page.wait_for_function("() => { const i = document.querySelector('#sheet-preview'); "
                           "return !i.hidden && i.complete && i.naturalWidth > 0; }")  # fmt: skip

    # SVG: the page in mm, six nested codes in mm, labelled with the payload (and the entry, cut to fit)
    svg = etree.parse(str(_download(page, "#sheet-svg", tmp_path / "sheet.svg"))).getroot()
    assert (svg.get("width"), svg.get("height")) == ("210mm", "297mm")
    nested = [e for e in svg if etree.QName(e).localname == "svg"]
    assert len(nested) == 6 and all(e.get("width") == "40" for e in nested)
    texts = [e.text for e in svg if etree.QName(e).localname == "text"]
    hexes = [f"0x{0x5A3C96 + i:06X}" for i in range(6)]
    assert [t for t in texts if t.startswith("0x")] == hexes
    label = next(t for t in texts if t.startswith("Table 7"))
    assert label.endswith("…") and menu.startswith(label[:-1]), label
    assert b"<script" not in etree.tostring(svg)

    # PNG: a code cropped from the sheet reads back, with the model, to its payload
    png = Image.open(_download(page, "#sheet-png", tmp_path / "sheet.png"))
    assert png.info["dpi"] == pytest.approx((300, 300), abs=0.01)
    pixels = np.asarray(png.convert("L"))
    mm = png.size[0] / 210
    model = deepmorph.load(BUNDLED_MODEL)
    for index in (1, 4):
        x, y, w, h = (float(nested[index].get(k)) for k in ("x", "y", "width", "height"))
        crop = pixels[round((y - 3) * mm) : round((y + h + 3) * mm), round((x - 3) * mm) : round((x + w + 3) * mm)]
        assert [(f.payload.hex, f.ok) for f in model.decode(crop)] == [(hexes[index], True)]

    # PDF: one A4 page
    pdf = _download(page, "#sheet-pdf", tmp_path / "sheet.pdf").read_bytes()
    assert pdf.startswith(b"%PDF")
    assert page_size_points(pdf) == pytest.approx((210 / 25.4 * 72, 297 / 25.4 * 72), abs=0.01)
    screenshot(page, "print-sheet")

    # a list, one a line
    page.check("#sheet-form input[value=list]")
    page.fill("#sheet-form textarea[name=lines]", "0x000001\n\n0xABCDEF\n")
    svg = etree.parse(str(_download(page, "#sheet-svg", tmp_path / "list.svg"))).getroot()
    assert [e.text for e in svg if etree.QName(e).localname == "text"] == ["0x000001", "0xABCDEF"]

    # what cannot be made says why, in one line
    page.check("#sheet-form input[value=range]")
    cases = [
        ({"count": "0"}, "no payloads: a sheet holds 1 to 100 codes (got 0)"),
        ({"count": "101"}, "101 payloads: a sheet holds at most 100 codes"),
        ({"count": "5", "start": "0xFFFFFE"}, "5 payloads from 0xFFFFFE pass the model's largest payload, 0xFFFFFF"),
        ({"count": "5", "start": "0x0000010"}, "0x0000010"),
        ({"count": "5", "start": "0x000001", "code_mm": "300"}, "a 300 mm code (306 mm tall with its label) does "
         "not fit on A4 with 10 mm margins"),
        ({"count": "40", "code_mm": "40"}, "40 codes 40 mm wide do not fit on A4 with 10 mm margins (20 do)"),
    ]  # fmt: skip
    for fields, message in cases:
        page.fill("#sheet-form input[name=code_mm]", fields.get("code_mm", "40"))
        page.fill("#sheet-form input[name=start]", fields.get("start", "0x000001"))
        page.fill("#sheet-form input[name=count]", fields["count"])
        page.click("#sheet-svg")
        page.wait_for_function(
            "(m) => document.querySelector('#error').textContent.includes(m)", arg=message, timeout=10_000
        )
        error = page.text_content("#error")
        assert "\n" not in error and "Traceback" not in error, error
    page.fill("#sheet-form input[name=code_mm]", "40")
    page.fill("#sheet-form input[name=count]", "3")
    page.click("#sheet-svg")
    page.wait_for_selector("#error", state="hidden")
    status, body = request(server, "/api/models/ghost/sheet", token=server.token,
                           data=b'{"count": 2, "start": "0x000001", "code_mm": "wide"}')  # fmt: skip
    assert status == 400 and json.loads(body)["error"] == "code width (mm): expected a number, got 'wide'"


def test_a_refused_sheet_answered_late_does_not_cover_a_newer_one(page, server: Server) -> None:
    """The studio answers sheet requests on a pool of threads, so a busy machine can answer them
    out of order. A refusal that arrives after a newer sheet was made must not put its stale
    error in the red bar; held back here, it arrives last on purpose."""
    held = []

    def hold_refused_downloads(route) -> None:  # noqa: ANN001
        body = json.loads(route.request.post_data or "{}")
        if body.get("count") == "40" and not body.get("preview"):
            held.append(route)  # answered below, after the newer sheet
        else:
            route.continue_()

    open_studio(page, server, "print")
    page.wait_for_function("() => document.querySelector('#print-payload').value.startsWith('0x')")
    page.route("**/api/models/ghost/sheet", hold_refused_downloads)
    page.fill("#sheet-form input[name=code_mm]", "40")
    page.fill("#sheet-form input[name=start]", "0x000001")
    page.fill("#sheet-form input[name=count]", "40")
    page.click("#sheet-svg")  # a refused download, held back
    for _ in range(50):  # the route handler runs as Playwright dispatches the page's events
        if held:
            break
        page.wait_for_timeout(100)
    assert len(held) == 1
    page.fill("#sheet-form input[name=count]", "3")
    with page.expect_download():
        page.click("#sheet-svg")
    page.wait_for_selector("#error", state="hidden")
    with page.expect_response(lambda r: r.request.post_data == held[0].request.post_data) as late:
        held[0].continue_()
    assert late.value.status == 400
    page.wait_for_timeout(300)  # the page has handled the late answer
    assert page.is_hidden("#error"), page.text_content("#error")
