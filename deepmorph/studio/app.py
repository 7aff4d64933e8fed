"""The studio's web app: a Starlette application whose handlers parse a request, call the library
(the drawing reader, :func:`deepmorph_core.capacity.predict` and
:mod:`deepmorph_core.print_size`, the training queue, the payload registry,
:class:`deepmorph_core.code.Code`, :func:`deepmorph.sheet.make_sheet`, the photo chain and
:func:`deepmorph_detect.reading.read_sequence`), and answer JSON or a file.

Security (docs/studio.md): every request carries the studio's token (``?token=``, then a
cookie, or the ``X-DeepMorph-Token`` header) or is refused with 403; the Host header must name
the studio (DNS rebinding); a write from another origin is refused; uploads have size limits;
SVGs are only ever served as DeepMorph writes them, as images, under a CSP that forbids
everything; uploaded photos are never served back; every page has a restrictive CSP.
"""

from __future__ import annotations

import contextlib
import hmac
import json
import math
import secrets
import tempfile
import threading
import time
from collections.abc import AsyncIterator, Awaitable, Callable
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import MutableHeaders
from starlette.middleware import Middleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, RedirectResponse, Response, StreamingResponse
from starlette.routing import Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from deepmorph.studio import drawing as drawings
from deepmorph.studio.jobs import JobQueue
from deepmorph.training.settings import DEFAULTS, PHOTO_SAMPLES, RENDER_SAMPLES, exposed
from deepmorph_core.errors import DeepMorphError

if TYPE_CHECKING:
    from deepmorph.registry import PayloadRegistry
    from deepmorph.sheet import Sheet
    from deepmorph_core.capacity import CapacityReport
    from deepmorph_core.code import FileFormat
    from deepmorph_core.model import DeepMorphModel
    from deepmorph_core.morphable import MorphableDrawing
    from deepmorph_core.payload import Payload, TextForm
    from deepmorph_detect.locate import Locator
    from deepmorph_detect.reading import SequenceReader

STATIC = Path(__file__).parent / "static"
TOKEN_COOKIE = "deepmorph_studio_token_{port}"  # cookies ignore ports: one name per studio's port
TOKEN_HEADER = "x-deepmorph-token"
MAX_PHOTO_BYTES = 20 * 1024 * 1024
MAX_JSON_BYTES = 64 * 1024
MAX_PRINT_MM = 1000.0
LIVE_FRAMES = 300  # frames a camera stream fuses before it starts afresh (about 15 s at 20 frames/s)
PAGE_CSP = (
    "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; "
    "media-src 'self' blob: mediastream:; connect-src 'self'; form-action 'self'; "
    "base-uri 'none'; frame-ancestors 'none'"
)
#: what an SVG the studio serves may do: nothing (no script, no fetch, no navigation).
SVG_CSP = "default-src 'none'; style-src 'unsafe-inline'; sandbox"
STATIC_FILES = {
    "index.html": "text/html; charset=utf-8",
    "studio.js": "text/javascript; charset=utf-8",
    "studio.css": "text/css; charset=utf-8",
}
BUNDLED_ID = "ghost"


class HttpError(Exception):
    """A request refused, with its status and a one-line message for the page."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class Studio:
    """What the handlers share: the data folder, the token, the current drawing, the models.

    Attributes:
        data: the data folder (``--data``): ``registry.sqlite3`` and ``studio/``.
        token: the secret every request must carry.
        hosts: the names the Host header may give (DNS rebinding is refused).
    """

    data: Path
    token: str = field(default_factory=lambda: secrets.token_urlsafe(24))
    hosts: set[str] = field(default_factory=lambda: {"127.0.0.1", "localhost", "[::1]"})
    jobs: JobQueue | None = None
    _models: dict[str, DeepMorphModel] = field(default_factory=dict)
    _locators: dict[str, Locator] = field(default_factory=dict)
    _live: dict[str, SequenceReader] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def __post_init__(self) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        self.jobs = JobQueue(self.folder / "jobs", self.folder / "models")

    @property
    def folder(self) -> Path:
        return self.data / "studio"

    @property
    def drawing_path(self) -> Path:
        return self.folder / "drawing.svg"

    @property
    def drawing_name_path(self) -> Path:
        return self.folder / "drawing.name"

    def registry(self) -> PayloadRegistry:
        from deepmorph.registry import PayloadRegistry

        return PayloadRegistry(self.data / "registry.sqlite3")

    # -- models: the bundled ghost and every bundle trained here --------------------------------
    def model_files(self) -> dict[str, Path]:
        from deepmorph_core.bundled import BUNDLED_MODEL

        files = {BUNDLED_ID: BUNDLED_MODEL}
        for path in sorted(self.folder.joinpath("models").glob("*.dmm")):
            files[path.stem] = path
        return files

    def model(self, model_id: str) -> DeepMorphModel:
        from deepmorph_core.model import DeepMorphModel

        path = self.model_files().get(model_id)
        if path is None:
            raise HttpError(404, f"no model {model_id!r}")
        with self._lock:
            if model_id not in self._models:
                m = DeepMorphModel.load(path)
                if not m.meta.record.finished:
                    raise DeepMorphError(f"{path.name}: its training has not finished")
                self._models[model_id] = m
            return self._models[model_id]

    def locator(self, model_id: str) -> Locator:
        from deepmorph_detect.locate import Locator

        m = self.model(model_id)
        with self._lock:
            if model_id not in self._locators:
                self._locators[model_id] = Locator(m)
            return self._locators[model_id]

    def live(self, model_id: str, restart: bool = False) -> SequenceReader:
        """The camera's stream for one model: drawings read in a frame are followed into the next
        and their readings fused (:class:`~deepmorph_detect.reading.SequenceReader`, what
        ``deepmorph decode`` reads videos with). A new stream, or one of :data:`LIVE_FRAMES`
        frames, starts afresh."""
        from deepmorph_detect.reading import SequenceReader

        locator = self.locator(model_id)
        with self._lock:
            reader = self._live.get(model_id)
            if reader is None or restart or reader.frames >= LIVE_FRAMES:
                reader = self._live[model_id] = SequenceReader(locator)
            return reader


# -- requests ---------------------------------------------------------------------------------


async def body(request: Request, limit: int, what: str) -> bytes:
    """The request's body, refused with 413 as soon as it passes ``limit`` bytes."""
    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > limit:
        raise HttpError(413, f"{what}: {int(declared)} bytes is more than the studio accepts ({limit} bytes)")
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > limit:
            raise HttpError(413, f"{what}: more than the studio accepts ({limit} bytes)")
        chunks.append(chunk)
    return b"".join(chunks)


async def json_body(request: Request) -> dict[str, Any]:
    try:
        data = json.loads(await body(request, MAX_JSON_BYTES, "request"))
    except ValueError:
        raise HttpError(400, "the request is not JSON") from None
    if not isinstance(data, dict):
        raise HttpError(400, "the request is not a JSON object")
    return data


def upload_name(request: Request, default: str) -> str:
    name = Path(request.headers.get("x-file-name", "") or default).name
    return "".join(c for c in name if c.isprintable())[:80] or default


def attachment(data: bytes, name: str, media: str) -> Response:
    """A download: never shown inline, never sniffed, and inert if opened anyway."""
    return Response(
        data,
        media_type=media,
        headers={"Content-Disposition": f'attachment; filename="{name}"', "Content-Security-Policy": SVG_CSP},
    )


def svg_image(text: str) -> Response:
    """An SVG DeepMorph wrote, served as an image under a CSP that forbids everything."""
    return Response(
        text.encode(),
        media_type="image/svg+xml",
        headers={"Content-Security-Policy": SVG_CSP, "Cache-Control": "no-store"},
    )


# -- handlers ---------------------------------------------------------------------------------

Handler = Callable[[Request], Awaitable[Response]]


def handlers(studio: Studio) -> list[Route]:  # noqa: C901 - one closure per route
    def current() -> tuple[str, str]:
        if not studio.drawing_path.is_file():
            raise HttpError(404, "no drawing yet: upload an SVG in the Drawing tab")
        name = studio.drawing_name_path.read_text() if studio.drawing_name_path.is_file() else "drawing.svg"
        return studio.drawing_path.read_text(), name

    def keep(svg: str, name: str) -> None:
        from deepmorph_core.fileio import atomic_write

        atomic_write(studio.drawing_path, svg.encode())
        atomic_write(studio.drawing_name_path, name.encode())

    async def index(request: Request) -> Response:
        if request.query_params.get("token"):  # the token leaves the address bar; the cookie stays
            return RedirectResponse("/", status_code=303)
        return FileResponse(STATIC / "index.html", media_type=STATIC_FILES["index.html"])

    async def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in STATIC_FILES:
            raise HttpError(404, "no such file")
        return FileResponse(STATIC / name, media_type=STATIC_FILES[name])

    # drawing
    async def drawing_upload(request: Request) -> Response:
        data = await body(request, drawings.MAX_SVG_BYTES, "drawing")
        name = upload_name(request, "drawing.svg")

        def work() -> dict[str, Any]:
            md = drawings.load(data, name)
            svg = drawings.written(md)
            keep(svg, name)
            return {"name": name, **drawings.describe(drawings.load(svg.encode(), name))}

        return JSONResponse(await run_in_threadpool(work))

    async def drawing_bundled(request: Request) -> Response:
        from deepmorph_core.bundled import BUNDLED_DRAWING

        def work() -> dict[str, Any]:
            md = drawings.load(BUNDLED_DRAWING.read_bytes(), BUNDLED_DRAWING.name)
            svg = drawings.written(md)
            keep(svg, BUNDLED_DRAWING.name)
            return {"name": BUNDLED_DRAWING.name, **drawings.describe(md)}

        return JSONResponse(await run_in_threadpool(work))

    async def drawing_info(request: Request) -> Response:
        svg, name = current()
        return JSONResponse(
            {"name": name, **await run_in_threadpool(lambda: drawings.describe(drawings.load(svg.encode(), name)))}
        )

    async def drawing_svg(request: Request) -> Response:
        svg, _ = current()
        return svg_image(svg)

    async def drawing_download(request: Request) -> Response:
        svg, name = current()
        stem = Path(name).stem
        return attachment(svg.encode(), f"{stem}-bounds.svg", "image/svg+xml")

    async def drawing_bounds(request: Request) -> Response:
        data = await json_body(request)
        svg, name = current()
        try:
            index = int(data.get("index"))
        except (TypeError, ValueError):
            raise HttpError(400, "index: expected a primitive's number") from None
        edit = drawings.BoundsEdit.from_json(data)

        def work() -> dict[str, Any]:
            out = drawings.annotate(svg, name, index, edit, group=bool(data.get("group")))
            keep(out, name)
            return {"name": name, **drawings.describe(drawings.load(out.encode(), name))}

        return JSONResponse(await run_in_threadpool(work))

    async def drawing_morph(request: Request) -> Response:
        svg, name = current()
        try:
            seed = int(request.query_params.get("seed", "0"))
        except ValueError:
            raise HttpError(400, "seed: expected an integer") from None
        extreme = request.query_params.get("extreme") == "1"
        return svg_image(
            await run_in_threadpool(lambda: drawings.random_morph(drawings.load(svg.encode(), name), seed, extreme))
        )

    # the drawings' channels (about half a minute each), and for a colour drawing how often its
    # prints are found (a few seconds), measured one at a time beside the requests, on daemon
    # threads: quitting the studio does not wait for a measurement
    channels_measuring: dict[str, Future[Any]] = {}
    one_measurement = threading.Lock()
    found_in_photos: dict[str, tuple[int, int]] = {}  # by channel_key

    def measure_later(report: CapacityReport, md: MorphableDrawing, key: str) -> Future[Any]:
        from deepmorph_core.capacity import with_channel

        future: Future[Any] = Future()

        def run() -> None:
            with one_measurement:
                try:
                    measured = with_channel(report, md)
                    if md.colour and measured.readable_groups and key not in found_in_photos:
                        from deepmorph_detect.findable import findability

                        found = findability(md, {})  # its bounds are in the SVG
                        found_in_photos[key] = (found.found, found.shots)
                    future.set_result(measured)
                except BaseException as exc:  # noqa: BLE001 - handed to the request that asks next
                    future.set_exception(exc)

        threading.Thread(target=run, name="deepmorph-channel", daemon=True).start()
        return future

    async def capacity(request: Request) -> Response:
        from dataclasses import replace

        from deepmorph_core.capacity import channel_key, predict, with_channel
        from deepmorph_core.reading_channel import channel_name

        svg, name = current()
        q = request.query_params
        print_mm = number(q.get("print_mm"), "print width (mm)", 50.0)
        distance_cm = number(q.get("distance_cm"), "reading distance (cm)", 30.0)

        def work() -> dict[str, Any]:
            md = drawings.load(svg.encode(), name).read_in()  # what training will read
            # the plan from 200 px up starts from the drawing's channel, and a colour drawing's
            # prints may be hard to find: each measured once, in the background
            report = with_channel(predict(md), md, measure=False)
            key = channel_key(md)
            if key in found_in_photos:
                report = replace(report, found=found_in_photos[key])
            unmeasured = report.channel_payload is None or (
                md.colour and report.readable_groups > 0 and report.found is None
            )
            if unmeasured:
                measuring = channels_measuring.get(key)
                if measuring is not None and measuring.done():
                    del channels_measuring[key]
                    measuring.result()  # its error, if it failed; a later request measures again
                    measuring = None  # measured, and since forgotten: measure again
                if measuring is None:
                    channels_measuring[key] = measure_later(report, md, key)
            return {
                "name": name,
                "reading_channel": channel_name(md.channel),
                **report.to_json(),
                "limits": report.limits(),
                "print_size": print_size(md, report, print_mm, distance_cm),
                "channel_measured": not unmeasured,
            }

        return JSONResponse(await run_in_threadpool(work))

    # training
    async def jobs_list(request: Request) -> Response:
        return JSONResponse(studio.jobs.list())

    async def jobs_form(request: Request) -> Response:
        return JSONResponse(train_form())

    async def jobs_submit(request: Request) -> Response:
        data = await json_body(request)
        svg, name = current()
        settings = training_settings(data)
        return JSONResponse(studio.jobs.submit(name, svg, settings))

    async def jobs_cancel(request: Request) -> Response:
        studio.jobs.cancel(request.path_params["job"])
        return JSONResponse({"cancelled": request.path_params["job"]})

    async def jobs_events(request: Request) -> Response:
        async def stream():  # noqa: ANN202 - server-sent events
            import anyio

            seen = -1
            last_sent = 0.0
            while not await request.is_disconnected():
                version = studio.jobs.version
                if version != seen or time.monotonic() - last_sent > 15:
                    seen, last_sent = version, time.monotonic()
                    yield f"data: {json.dumps(studio.jobs.list())}\n\n"
                await anyio.sleep(0.25)

        return StreamingResponse(stream(), media_type="text/event-stream", headers={"Cache-Control": "no-store"})

    # models and payloads
    async def models(request: Request) -> Response:
        def work() -> list[dict[str, Any]]:
            rows = []
            for model_id in studio.model_files():
                try:
                    m = studio.model(model_id)
                except DeepMorphError:
                    continue  # a run still training, or a file that is not a finished bundle
                rows.append({"id": model_id, "drawing": m.meta.drawing_name, "payload_bits": m.codec.spec.payload_bits})
            return rows

        return JSONResponse(await run_in_threadpool(work))

    async def random_payload(request: Request) -> Response:
        import numpy as np

        from deepmorph_core.payload import Payload, random_payloads

        m = await run_in_threadpool(studio.model, request.path_params["model"])
        payload = Payload(random_payloads(1, m.codec.spec.payload_bits, np.random.default_rng())[0])
        return JSONResponse({**payload.to_json(), "number": str(payload.int)})

    async def entries(request: Request) -> Response:
        m = await run_in_threadpool(studio.model, request.path_params["model"])
        registry = studio.registry()
        rows = await run_in_threadpool(lambda: registry.list(m) if registry.path.exists() else [])
        return JSONResponse([e.to_json() for e in rows])

    async def entry_add(request: Request) -> Response:
        data = await json_body(request)
        m = await run_in_threadpool(studio.model, request.path_params["model"])
        kind = "text" if data.get("kind") == "text" else "url"
        entry = await run_in_threadpool(
            lambda: studio.registry().add(
                m,
                str(data.get("payload", "")).strip(),
                str(data.get("target", "")),
                kind,
                str(data.get("note") or "") or None,
                replace=bool(data.get("replace")),
            )
        )
        return JSONResponse(entry.to_json())

    async def entry_remove(request: Request) -> Response:
        m = await run_in_threadpool(studio.model, request.path_params["model"])
        payload = request.path_params["payload"]
        entry = await run_in_threadpool(lambda: studio.registry().remove(m, payload))
        if entry is None:
            raise HttpError(404, f"{payload} has no entry")
        return JSONResponse(entry.to_json())

    # print
    async def print_code(request: Request) -> Response:
        from deepmorph_core.code import print_pixels

        q = request.query_params
        fmt = q.get("format", "svg").lower()
        if fmt not in ("svg", "pdf", "png"):
            raise HttpError(400, f"format: {fmt!r}; a code is written as svg, pdf or png")
        try:
            width_mm = float(q.get("width_mm", "50"))
            dpi = int(q.get("dpi", "300"))
        except ValueError:
            raise HttpError(400, "width_mm and dpi: expected numbers") from None
        if not 1 <= width_mm <= MAX_PRINT_MM or not 50 <= dpi <= 2400:
            raise HttpError(400, f"width_mm: 1 to {MAX_PRINT_MM:g} mm; dpi: 50 to 2400")
        if fmt == "png":
            print_pixels(width_mm, dpi)  # refused before any work when too large
        m = await run_in_threadpool(studio.model, request.path_params["model"])
        payload = typed_payload(q.get("payload", ""), m.codec.spec.payload_bits, q.get("payload_as"))
        code = await run_in_threadpool(m.code, payload)
        data = await run_in_threadpool(lambda: code.file(fmt.upper(), width_mm, dpi))
        if q.get("preview") == "1" and fmt == "svg":
            return svg_image(data.decode())
        media = {"svg": "image/svg+xml", "pdf": "application/pdf", "png": "image/png"}[fmt]
        name = f"{request.path_params['model']}-{code.payload.hex}-{width_mm:g}mm.{fmt}"
        response = attachment(data, name, media)
        response.headers["X-DeepMorph-Payload"] = code.payload.hex
        return response

    async def print_sheet(request: Request) -> Response:
        data = await json_body(request)
        model_id = request.path_params["model"]
        fmt = str(data.get("format", "svg")).lower()
        if fmt not in ("svg", "pdf", "png"):
            raise HttpError(400, f"format: {fmt!r}; a sheet is written as svg, pdf or png")
        code_mm = number(data.get("code_mm"), "code width (mm)", 40.0)
        margin_mm = number(data.get("margin_mm"), "margins (mm)", 10.0)
        dpi = number(data.get("dpi"), "dpi", 300.0)
        if not 1 <= code_mm <= MAX_PRINT_MM or not 0 <= margin_mm <= MAX_PRINT_MM or not 50 <= dpi <= 2400:
            raise HttpError(
                400, f"code width: 1 to {MAX_PRINT_MM:g} mm; margins: 0 to {MAX_PRINT_MM:g} mm; dpi: 50 to 2400"
            )
        data_out, sheet = await run_in_threadpool(
            lambda: sheet_file(studio, model_id, data, fmt.upper(), code_mm, margin_mm, int(dpi))
        )
        if data.get("preview") and fmt == "svg":
            return svg_image(data_out.decode())
        media = {"svg": "image/svg+xml", "pdf": "application/pdf", "png": "image/png"}[fmt]
        page = str(data.get("page") or "A4")
        response = attachment(data_out, f"{model_id}-sheet-{len(sheet.placed)}-codes-{page}.{fmt}", media)
        response.headers["X-DeepMorph-Codes"] = str(len(sheet.placed))
        return response

    # scan
    async def scan(request: Request) -> Response:
        data = await body(request, MAX_PHOTO_BYTES, "photo")
        model_id = request.path_params["model"]
        live = request.query_params.get("live") == "1"
        restart = request.query_params.get("first") == "1"
        name = upload_name(request, "photo")
        started = time.perf_counter()
        result = await run_in_threadpool(lambda: read_photo(studio, model_id, data, name, live, restart))
        result["ms"] = round(1000 * (time.perf_counter() - started), 1)
        return JSONResponse(result)

    async def token_check(request: Request) -> Response:
        return JSONResponse({"ok": True})

    return [
        Route("/", index),
        Route("/static/{name}", static),
        Route("/api/check", token_check),
        Route("/api/drawing", drawing_info),
        Route("/api/drawing", drawing_upload, methods=["POST"]),
        Route("/api/drawing/bundled", drawing_bundled, methods=["POST"]),
        Route("/api/drawing/bounds", drawing_bounds, methods=["POST"]),
        Route("/api/drawing.svg", drawing_svg),
        Route("/api/drawing/download", drawing_download),
        Route("/api/drawing/morph.svg", drawing_morph),
        Route("/api/capacity", capacity),
        Route("/api/jobs", jobs_list),
        Route("/api/jobs", jobs_submit, methods=["POST"]),
        Route("/api/jobs/{job}/cancel", jobs_cancel, methods=["POST"]),
        Route("/api/jobs/events", jobs_events),
        Route("/api/jobs/form", jobs_form),
        Route("/api/models", models),
        Route("/api/models/{model}/random", random_payload),
        Route("/api/models/{model}/entries", entries),
        Route("/api/models/{model}/entries", entry_add, methods=["POST"]),
        Route("/api/models/{model}/entries/{payload}/remove", entry_remove, methods=["POST"]),
        Route("/api/models/{model}/print", print_code),
        Route("/api/models/{model}/sheet", print_sheet, methods=["POST"]),
        Route("/api/models/{model}/scan", scan, methods=["POST"]),
    ]


def number(value: object, what: str, default: float) -> float:
    """A finite number from a form field (``default`` when empty), or one clear error."""
    if value in (None, ""):
        return default
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise HttpError(400, f"{what}: expected a number, got {value!r}") from None
    if not math.isfinite(x):
        raise HttpError(400, f"{what}: expected a number, got {value!r}")
    return x


def payload_form(value: object) -> TextForm | None:
    """How the Print tab's user chose to type payloads (``payload_as``): ``number``, ``hex`` or
    ``bits``; none: as ``deepmorph encode --payload`` reads them (``0x`` hex, ``0d`` a number,
    or bits). An entry picked from the registry is sent as its hex."""
    from deepmorph_core.payload import TEXT_FORMS

    if value in (None, ""):
        return None
    if value not in TEXT_FORMS:
        raise HttpError(400, f"payload_as: {value!r}; a payload is typed as {', '.join(TEXT_FORMS)}")
    return value  # type: ignore[return-value]


def typed_payload(text: str, payload_bits: int, form: object) -> Payload:
    """The payload the Print tab's user typed, read in the form they chose (:func:`payload_form`):
    a number too large for the model, or text that is not that form, is one clear error."""
    from deepmorph_core.payload import Payload

    return Payload.parse(text, payload_bits, payload_form(form))


def print_size(md: MorphableDrawing, report: CapacityReport, print_mm: float, distance_cm: float) -> dict[str, Any]:
    """What ``deepmorph capacity --print-mm --distance-cm`` adds to the prediction ``report``:
    the print's width in a 1080p phone's photo (:func:`~deepmorph_core.print_size.pixels_across`),
    how far the visible variables move there and at 96, 150, 200 and 300 px and the payload each
    width carries (:func:`~deepmorph_core.print_size.plan`), and whether a print that wide reads
    (:func:`~deepmorph_core.print_size.legibility`), in the command's words."""
    from deepmorph.training.settings import DEFAULTS
    from deepmorph_core.print_size import (
        PHONE_FOV_DEG,
        PHONE_FRAME_PX,
        READING_NOTE,
        legibility,
        pixels_across,
        plan,
        plan_sizes,
        rows_to_json,
    )

    pixels = pixels_across(print_mm, distance_cm)
    # a model reads prints at least as wide as its decoder's frame (the default one before training)
    legible = legibility(pixels, DEFAULTS.width, print_mm)
    return {
        "print_mm": print_mm,
        "distance_cm": distance_cm,
        "frame_px": PHONE_FRAME_PX,
        "fov_deg": PHONE_FOV_DEG,
        "pixels": pixels,
        "sizes": rows_to_json(plan(md, report.visible_mask, plan_sizes(pixels), report, DEFAULTS.width)),
        "span": f"a {print_mm:g} mm print at {distance_cm:g} cm spans {pixels:.0f} px of a {PHONE_FRAME_PX}-px, "
        f"{PHONE_FOV_DEG:g}° frame",
        "legibility": legible.to_json(),
        "verdict": legible.sentence(),
        "note": READING_NOTE,
    }


def sheet_file(
    studio: Studio, model_id: str, data: dict[str, Any], fmt: FileFormat, code_mm: float, margin_mm: float, dpi: int
) -> tuple[bytes, Sheet]:
    """The Print tab's sheet: its payloads (``count`` from ``start``, or ``lines``, one a line),
    each code labelled with its registry entry's text when it has one, laid out by
    :func:`deepmorph.sheet.make_sheet` and written as ``fmt``."""
    from deepmorph.registry import model_key
    from deepmorph.sheet import batch_payloads, make_sheet

    m = studio.model(model_id)
    bits = m.codec.spec.payload_bits
    form = payload_form(data.get("payload_as"))
    if data.get("mode") == "list":
        payloads = batch_payloads(bits, lines=str(data.get("lines") or ""), form=form)
    else:
        count = data.get("count", 12)
        try:
            n = int(str(count).strip())
        except ValueError:
            raise HttpError(400, f"number of codes: expected a whole number, got {count!r}") from None
        payloads = batch_payloads(bits, start=str(data.get("start") or "").strip(), count=n, form=form)
    registry = studio.registry()
    texts: list[str | None] = [None] * len(payloads)
    if registry.path.exists():
        key = model_key(m)
        for i, p in enumerate(payloads):
            entry = registry.get(key, p.hex)
            texts[i] = entry.target if entry else None
    sheet = make_sheet(
        [m.code(p) for p in payloads],
        texts=texts,
        page=str(data.get("page") or "A4"),
        code_mm=code_mm,
        margin_mm=margin_mm,
    )
    return sheet.file(fmt, dpi), sheet


#: A run queued from the page trains within these (below the training settings' own limits: a
#: page is no place for a week-long run) ...
STUDIO_CAPS = {"steps": 200_000, "batch": 1024, "threads": 64}
#: ... and on one CPU thread unless asked (it shares the machine with the page).
STUDIO_DEFAULTS = {"threads": 1}
MAX_VALIDATION_PHOTOS = 10_000


def train_form() -> dict[str, dict[str, Any]]:
    """The Train form's inputs by name: each one's ``default``, ``min`` and ``max``.

    The training settings are named by their :func:`deepmorph.train` keywords, with the defaults
    and bounds of :mod:`deepmorph.training.settings`, capped by :data:`STUDIO_CAPS` (and the
    studio's own defaults, :data:`STUDIO_DEFAULTS`, where it has them). A new model hides the
    payload ``deepmorph capacity`` predicts to read (``auto``) and is validated on photos, as
    many by default as the command line reads (and five times as many renders, its share). The
    page fills its form from this, and :func:`training_settings` checks what it sends against it."""
    from deepmorph_core.payload import MAX_PAYLOAD_BITS

    form: dict[str, dict[str, Any]] = {"payload_bits": {"default": "auto", "min": 1, "max": MAX_PAYLOAD_BITS}}
    for name in ("steps", "batch", "width", "threads"):
        setting = exposed()[name]
        limits = [x for x in (setting.le, STUDIO_CAPS.get(name)) if x is not None]
        default = STUDIO_DEFAULTS.get(name, getattr(DEFAULTS, name))
        form[setting.keyword] = {"default": default, "min": setting.ge, "max": min(limits)}
    form["validation"] = {"default": PHOTO_SAMPLES, "min": 0, "max": MAX_VALIDATION_PHOTOS}
    return form


def training_settings(data: dict[str, Any]) -> dict[str, Any]:
    """The worker's settings from the Train form (:func:`train_form`); out-of-range values are
    one clear error."""
    form = train_form()

    def integer(key: str) -> int:
        value, default = data.get(key), form[key]["default"]
        try:
            n = int(value if value not in (None, "") else default)
        except (TypeError, ValueError):
            raise HttpError(400, f"{key}: expected an integer, got {value!r}") from None
        if not form[key]["min"] <= n <= form[key]["max"]:
            raise HttpError(400, f"{key}: {n} is outside {form[key]['min']}..{form[key]['max']}")
        return n

    bits_text = str(data.get("payload_bits", form["payload_bits"]["default"])).strip().lower()
    payload_bits: int | str = "auto" if bits_text in ("", "auto") else integer("payload_bits")
    steps = integer("steps")
    validation = integer("validation")
    return {
        "payload_bits": payload_bits,
        "train": {
            "steps": steps,
            "batch": integer("batch"),
            "width": integer("image_width"),
            "log_every": max(1, min(DEFAULTS.log_every, steps // 40)),
            "threads": integer("threads"),
        },
        "validation": [RENDER_SAMPLES * validation // PHOTO_SAMPLES, validation],
    }


def read_photo(
    studio: Studio, model_id: str, data: bytes, name: str, live: bool = False, restart: bool = False
) -> dict[str, Any]:
    """Every drawing of a model in an uploaded photo (``live``: a camera frame, followed from the
    previous one; ``restart``: the first of a new stream), with each verified payload's registry
    entry. The photo goes through the same
    reader as ``deepmorph decode`` (a temporary file: size, pixel and format checks)."""
    from deepmorph.registry import detection_lookup
    from deepmorph_core.image_io import read_image_bgr
    from deepmorph_detect.results import seen_too_steeply

    m = studio.model(model_id)
    look_up = detection_lookup(studio.registry(), m, missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="deepmorph-studio-") as tmp:
        path = Path(tmp) / "upload"
        path.write_bytes(data)
        try:
            image = read_image_bgr(path)
        except DeepMorphError as exc:
            raise DeepMorphError(str(exc).replace(str(path), name)) from None
    if live:
        reader = studio.live(model_id, restart)
        dets = reader.add(str(reader.frames), image)
    else:
        dets = studio.locator(model_id).locate(image)
    found = []
    for d in dets:
        row = d.to_json()
        row["registry"] = look_up(row)
        cube = [[float(x), float(y)] for x, y in d.pose.cube()] if d.pose is not None else []
        if cube and all(math.isfinite(v) and abs(v) < 1e6 for point in cube for v in point):  # drawn over the photo
            row["cube"] = [[round(x, 1), round(y, 1)] for x, y in cube]
        found.append(row)
    height, width = image.shape[:2]
    note = ""
    if not found:
        note = "no drawing found: is the print in view, lit, and larger than about 80 pixels?"
    elif not any(d["ok"] for d in found):
        small = [d["too_small"] for d in found if "too_small" in d]
        if small and len(small) == len(found):
            widest = max(small, key=lambda t: t["width_px"])
            if seen_too_steeply(widest):
                note = (
                    f"the print is seen too steeply: {widest['along_tilt_px']:.0f} pixels along its tilt "
                    f"(needs {widest['needs_px']:.0f}): face it squarely"
                )
            else:
                note = (
                    f"the print is {widest['width_px']:.0f} pixels wide in the image, too small to read "
                    f"(needs {widest['needs_px']:.0f}): move closer"
                )
        else:
            note = "a drawing was found but not read: hold it steadier, in even light"
    return {"width": width, "height": height, "detections": found, "note": note}


# -- the application --------------------------------------------------------------------------


class Guard:
    """ASGI middleware in front of every route: the Host header, the origin of writes and the
    token are checked before anything runs, and every answer gets the security headers (and the
    token's cookie, so that a page opened with ``?token=`` keeps working without it)."""

    def __init__(self, app: ASGIApp, studio: Studio) -> None:
        self.app = app
        self.studio = studio

    def refusal(self, request: Request) -> str | None:
        studio = self.studio
        host = request.headers.get("host", "").rsplit(":", 1)[0]
        if "*" not in studio.hosts and host not in studio.hosts:
            return f"host {host!r} is not this studio's"
        origin = request.headers.get("origin")
        if request.method != "GET" and origin and origin != f"{request.url.scheme}://{request.headers['host']}":
            return "a request from another site is refused"
        given = (
            request.query_params.get("token")
            or request.headers.get(TOKEN_HEADER)
            or request.cookies.get(cookie_name(request.scope))
            or ""
        )
        if not hmac.compare_digest(given.encode(), studio.token.encode()):
            return "this studio needs its token: open the address `deepmorph studio` printed"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        request = Request(scope)
        why = self.refusal(request)
        if why is not None:
            await JSONResponse({"error": why}, status_code=403, headers=security_headers(PAGE_CSP))(
                scope, receive, send
            )
            return
        cookie = cookie_name(scope)
        set_cookie = request.cookies.get(cookie) != self.studio.token

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = MutableHeaders(scope=message)
                for key, value in security_headers(headers.get("content-security-policy", PAGE_CSP)).items():
                    headers[key] = value
                if set_cookie:
                    headers.append("set-cookie", f"{cookie}={self.studio.token}; HttpOnly; SameSite=Strict; Path=/")
            await send(message)

        await self.app(scope, receive, send_with_headers)


def cookie_name(scope: Scope) -> str:
    """The token's cookie for the port this studio listens on."""
    server = scope.get("server") or ("", 0)
    return TOKEN_COOKIE.format(port=server[1] or 0)


def security_headers(csp: str) -> dict[str, str]:
    return {
        "Content-Security-Policy": csp,
        "X-Content-Type-Options": "nosniff",
        "Referrer-Policy": "no-referrer",
        "X-Frame-Options": "DENY",
        "Cross-Origin-Resource-Policy": "same-origin",
    }


def create_app(studio: Studio) -> Starlette:
    """The studio's ASGI application, locked by ``studio.token``."""

    async def refused(request: Request, exc: Exception) -> Response:
        status = exc.status if isinstance(exc, HttpError) else 400
        return JSONResponse({"error": str(exc)}, status_code=status)

    async def crashed(request: Request, exc: Exception) -> Response:
        import traceback

        traceback.print_exception(exc)  # on the studio's terminal; the page gets one line
        return JSONResponse({"error": f"unexpected error ({type(exc).__name__}): {exc}"[:400]}, status_code=500)

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        yield
        studio.jobs.close()  # a running training writes its checkpoint before the studio stops

    return Starlette(
        routes=handlers(studio),
        middleware=[Middleware(Guard, studio=studio)],
        exception_handlers={HttpError: refused, DeepMorphError: refused, Exception: crashed},
        lifespan=lifespan,
    )


__all__ = ["Studio", "create_app", "print_size", "read_photo", "sheet_file", "train_form", "training_settings"]
