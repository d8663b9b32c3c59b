"""The HTTP routes: ``/health``, ``/ready``, ``/model``, ``POST /scenes`` and the streams.

Routes stay thin: ``/scenes`` reads the multipart form into memory, hands the parts to ``service.validation``
(decoding, off the event loop), runs the pipeline on an inference worker thread, and serialises the result.
``POST /streams/{stream_id}/frames`` takes the same form through the same code (:func:`scene_result`) and
hands the result to its stream (``service.streams``); ``DELETE /streams/{stream_id}`` ends one. ``GET /metrics``
serves the app's Prometheus metrics (``service.metrics``), which both frame routes feed.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from contextlib import AsyncExitStack, asynccontextmanager
from functools import partial
from typing import Annotated

import anyio
import torch
from fastapi import APIRouter, Depends, HTTPException, Path, Request, Response
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html, get_swagger_ui_oauth2_redirect_html
from fastapi.responses import HTMLResponse, JSONResponse
from pydantic import Field
from python_multipart.multipart import parse_options_header
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser
from starlette.requests import ClientDisconnect

from pipeline.two_stage import Detected, ScenePipeline, SceneResult
from service.cancel import ClientGone, run_until_disconnected
from service.deps import PipelineDep, SettingsDep, StreamsDep, inference_slot, require_token
from service.errors import PAYLOAD_TOO_LARGE, UNSUPPORTED_MEDIA, InputError
from service.metrics import SCENES, STREAM_FRAMES, Metrics
from service.model_info import model_info
from service.openapi import MAX_TEXT_PARTS, RETRY_AFTER, SCENE_FORM, max_file_parts
from service.openapi import MULTIPART as _MULTIPART
from service.response import encode
from service.schemas import (
    Error,
    Health,
    ModelInfo,
    Ready,
    SceneOut,
    StreamEnded,
    StreamFrameDropped,
    StreamFrameOut,
)
from service.settings import Settings
from service.streams import STREAM_ID, Dropped, Frame, StreamRegistry, check_stream_id, parse_timestamp
from service.validation import Limits, ValidatedScene, parse_scene, validate_scene

public = APIRouter()
# The 401 of a protected operation, and its security requirement, are added by service.openapi when a token is set.
protected = APIRouter(dependencies=[Depends(require_token)])
_NOT_LOADED = {
    "model": Error,
    "description": "the models are not loaded yet (see Retry-After)",
    "headers": RETRY_AFTER,
}

_ERRORS = {
    400: {
        "model": Error,
        "description": "malformed multipart body (no boundary, cut short, a part without a name), a body that "
        "is not a form at all, or a client that left before the answer",
    },
    408: {"model": Error, "description": "the body did not arrive within ORPOSE_BODY_TIMEOUT_S"},
    413: {
        "model": Error,
        "description": "the body (ORPOSE_MAX_BODY_BYTES) or an image (ORPOSE_MAX_IMAGE_PIXELS) is beyond the "
        "server's limits",
    },
    415: {
        "model": Error,
        "description": "not multipart/form-data, or an image part that is neither PNG nor JPEG",
    },
    422: {
        "model": Error,
        "description": "the scene is wrong in a way the schema cannot say (images that do not decode, 8-bit "
        "depth, colour and depth of different sizes, a principal point outside the image, extrinsics that are "
        "not rigid, parts of views the scene does not have, depth that cannot be right); the message names "
        "the part and the problem",
    },
    503: {
        "model": Error,
        "description": "too many uploads arriving (ORPOSE_MAX_RECEIVING) or requests in flight "
        "(ORPOSE_MAX_IN_FLIGHT), or the models not loaded yet; see Retry-After",
        "headers": RETRY_AFTER,
    },
}


def docs_router(openapi: Callable[[], dict], protect: bool) -> APIRouter:
    """``/openapi.json``, ``/docs`` (with its OAuth2 redirect) and ``/redoc``; behind the token if ``protect``.

    With a token the pages cannot fetch the schema themselves (a browser sends no bearer header): read it
    with ``curl -H "Authorization: Bearer $T" .../openapi.json``, or make the docs public
    (ORPOSE_PUBLIC_DOCS=true).
    """
    router = APIRouter(include_in_schema=False, dependencies=[Depends(require_token)] if protect else [])
    title = "OR multi-view RGB-D 3D human pose"

    @router.get("/openapi.json")
    async def schema() -> JSONResponse:
        return JSONResponse(openapi())

    @router.get("/docs")
    async def swagger() -> HTMLResponse:
        return get_swagger_ui_html(
            openapi_url="/openapi.json", title=title, oauth2_redirect_url="/docs/oauth2-redirect"
        )

    @router.get("/docs/oauth2-redirect")
    async def swagger_redirect() -> HTMLResponse:
        return get_swagger_ui_oauth2_redirect_html()

    @router.get("/redoc")
    async def redoc() -> HTMLResponse:
        return get_redoc_html(openapi_url="/openapi.json", title=title)

    return router


def metrics_router(protect: bool) -> APIRouter:
    """``GET /metrics``; behind the token if ``protect`` (a token is set and ORPOSE_METRICS_OPEN is not)."""
    router = APIRouter(dependencies=[Depends(require_token)] if protect else [])

    @router.get(
        "/metrics",
        response_class=Response,
        responses={
            200: {
                "description": "the Prometheus text format, or OpenMetrics when the Accept header asks for it",
                "content": {
                    "text/plain": {"schema": {"type": "string"}},
                    "application/openmetrics-text": {"schema": {"type": "string"}},
                },
            }
        },
        summary="Prometheus metrics: latency per stage, requests by status, rejections, queues, streams, models",
    )
    async def metrics(request: Request) -> Response:
        body, content_type = request.app.state.metrics.exposition(request.headers.get("accept"))
        return Response(body, media_type=content_type)

    return router


@asynccontextmanager
async def _admitted(
    request: Request, settings: Settings, streams: StreamRegistry | None = None, slot: bool = True, **frame
) -> AsyncIterator[Frame | None]:
    """An inference slot (``inference_slot``; unless ``slot`` is False) and, for a stream's frame, the stream
    (``StreamRegistry.frame``, with ``frame``'s arguments), yielding the stream's frame or None; a refusal of
    either is counted in ``orpose_rejections_total``."""
    metrics: Metrics = request.app.state.metrics
    async with AsyncExitStack() as stack:
        try:
            if slot:
                await stack.enter_async_context(inference_slot(request, settings))
        except HTTPException:
            metrics.rejected("in_flight_full")
            raise
        if streams is None:
            yield None
            return
        try:
            taken = await stack.enter_async_context(streams.frame(**frame))
        except HTTPException as exc:
            if exc.status_code == 503:
                metrics.rejected("streams_full")
            raise
        yield taken


async def _result(request, pipeline, scene_text, files, t_start, unsure=None):
    """:func:`scene_result`, with an image over ORPOSE_MAX_IMAGE_PIXELS counted as a rejection."""
    try:
        return await scene_result(request, pipeline, scene_text, files, t_start, unsure)
    except InputError as exc:
        if exc.status == PAYLOAD_TOO_LARGE:
            request.app.state.metrics.rejected("image_too_large")
        raise


@public.get("/health", response_model=Health, summary="Liveness: the process answers")
async def health() -> Health:
    return Health()


@protected.get("/ready", response_model=Ready, responses={503: {"model": Ready}}, summary="Models loaded")
async def ready(request: Request, response: Response) -> Ready:
    loaded = getattr(request.app.state, "pipeline", None) is not None
    if not loaded:
        response.status_code = 503
    return Ready(ready=loaded)


@protected.get(
    "/model",
    response_model=ModelInfo,
    responses={503: _NOT_LOADED},
    summary="What the loaded models read and were trained on",
)
async def model(pipeline: PipelineDep, settings: SettingsDep) -> ModelInfo:
    return model_info(pipeline, settings.device)


def _boundary(content_type: str) -> bytes:
    """The multipart boundary of a ``multipart/form-data`` Content-Type; 415 for any other media type."""
    media, options = parse_options_header(content_type)
    if media != _MULTIPART.encode():  # exactly, case-insensitively: not multipart/form-dataX
        got = content_type or "no content type"
        raise InputError(
            f"expected Content-Type multipart/form-data, got {got!r}; send the scene and the images as a "
            "multipart form (curl -F)",
            UNSUPPORTED_MEDIA,
        )
    return options.get(b"boundary", b"")


async def _read_form(
    request: Request, settings: Settings, fields: tuple[str, ...] = ("scene",)
) -> tuple[dict[str, bytes], dict[str, bytes]]:
    """The text ``fields`` that are present and the file parts, all in memory (a spool that never rolls over to
    disk)."""
    boundary = _boundary(request.headers.get("content-type", ""))
    closing = b"--" + boundary + b"--"
    tail = b""

    async def body():  # keeps the body's last bytes, to check that the form was closed
        nonlocal tail
        async for chunk in request.stream():
            tail = (tail + chunk)[-(len(closing) + 8) :]
            yield chunk

    parser = MultiPartParser(
        request.headers, body(), max_files=max_file_parts(settings), max_fields=MAX_TEXT_PARTS,
        max_part_size=settings.max_body_bytes,
    )  # fmt: skip
    parser.spool_max_size = settings.max_body_bytes  # the body is capped: keep every part in memory
    try:
        form = await parser.parse()
    except MultiPartException as exc:
        if exc.message.startswith("Too many files"):
            raise InputError(
                f"the form has more than {parser.max_files} file parts: this server takes at most "
                f"{settings.max_views} views (ORPOSE_MAX_VIEWS), each with the parts color_<i> and depth_<i>"
            ) from None
        raise HTTPException(400, f"malformed multipart body: {exc.message}") from None
    except ClientDisconnect:  # nobody is left to answer; a 400 rather than a 500 traceback in the log
        raise HTTPException(400, "the client disconnected before the body was complete") from None
    try:
        if boundary and not tail.rstrip(b"\r\n").endswith(closing):
            raise HTTPException(
                400,
                f"malformed multipart body: it ends without the closing boundary {closing.decode(errors='replace')!r}, "
                "so the upload was cut short or the form was not finished",
            )
        return await _form_parts(form, fields)
    finally:
        await form.close()


async def _form_parts(form, fields: tuple[str, ...]) -> tuple[dict[str, bytes], dict[str, bytes]]:
    texts, files = {}, {}
    for name, value in form.multi_items():
        data = await value.read() if isinstance(value, UploadFile) else value.encode()
        if name in fields:
            if name in texts:
                raise InputError(f"the form has more than one {name!r} part")
            texts[name] = data
        elif name in files:
            raise InputError(f"the form has more than one {name!r} part")
        elif not isinstance(value, UploadFile):
            # A part without a filename arrives as text, and text decoding would corrupt image bytes.
            raise InputError(f"{name} must be a file part (with a filename), e.g. curl -F {name}=@image.png")
        else:
            files[name] = data
    return texts, files


@protected.post(
    "/scenes",
    response_model=SceneOut,
    responses=_ERRORS,
    summary="3D poses of everyone in one synchronised multi-view RGB-D frame",
    description="multipart/form-data with a `scene` JSON part (SceneIn) and, per view i, the file parts "
    "`color_i` (PNG/JPEG) and `depth_i` (16-bit PNG). With boxes in any view, detection is skipped "
    "(reference-box mode). Every 3D coordinate in the response is in mm in the reference frame.",
    openapi_extra={SCENE_FORM: "scene"},  # the form, as service.openapi.scene_form describes it
)
async def post_scene(request: Request, pipeline: PipelineDep, settings: SettingsDep) -> Response:
    t_start = time.perf_counter()
    # Receiving the body holds a receiving place (service.limits), never an inference slot.
    texts, files = await _read_form(request, settings)
    scene_text = _scene_part(texts)
    async with _admitted(request, settings):
        result, scene, decode_ms = await _result(request, pipeline, scene_text, files, t_start)
    t_encode = time.perf_counter()
    body = encode(result, scene, decode_ms, t_start)
    _observe(request, SCENES, result, decode_ms, t_encode, t_start)
    return Response(body, media_type="application/json")


def _observe(
    request: Request, route: str, result: SceneResult, decode_ms: float, t_encode: float, t_start: float
) -> None:
    """An answered frame's stage times into the histograms (``t_encode``, ``t_start``: perf_counter readings)."""
    t_end = time.perf_counter()
    request.app.state.metrics.frame(
        route, result.mode, result.timings, decode_ms, (t_end - t_encode) * 1e3, (t_end - t_start) * 1e3
    )


def _scene_part(texts: dict[str, bytes]) -> bytes:
    if "scene" not in texts:
        raise InputError("missing form part 'scene' (the JSON with the views' cameras)")
    return texts["scene"]


async def scene_result(
    request: Request,
    pipeline: ScenePipeline,
    scene_text: bytes,
    files: dict[str, bytes],
    t_start: float,
    unsure: Callable[[ValidatedScene], object] | None = None,
) -> tuple[SceneResult, ValidatedScene, float]:
    """Decode and validate a frame's form parts, then run the pipeline on it (called holding an inference slot).

    ``unsure``: a stream's hook, called with the validated scene in the pipeline's worker thread just before the
    pipeline; it returns ``ScenePipeline.run``'s ``unsure`` (whether, or when, to list the persons the detector
    was unsure of, for the stream's tracker). Returns the result, the validated scene and the decoding time in ms
    (since ``t_start``, a perf_counter).
    """
    scene, decode_ms = await decoded(request, pipeline, scene_text, files, t_start)
    result = await pipeline_result(request, pipeline, scene, unsure)
    return result, scene, decode_ms


async def decoded(
    request: Request, pipeline: ScenePipeline, scene_text: bytes, files: dict[str, bytes], t_start: float
) -> tuple[ValidatedScene, float]:
    """A frame's form parts decoded and validated (off the event loop), and the ms since ``t_start``."""
    settings: Settings = request.app.state.settings
    limits = Limits(
        settings.max_views, settings.max_image_pixels, settings.max_boxes_per_view, pipeline.read_size
    )
    need_color = "color" in pipeline.modalities
    detector_color = "color" in pipeline.detector_modalities or pipeline.detector is None

    def decode():
        return validate_scene(parse_scene(scene_text, limits), files, limits, need_color, detector_color)

    scene = await anyio.to_thread.run_sync(decode)
    decode_ms = (time.perf_counter() - t_start) * 1e3
    if scene.boxes is None and pipeline.detector is None:
        raise InputError(
            'this server runs without a detector (no detector weights loaded, or ORPOSE_LOAD_DETECTOR=false): send reference boxes (per view "boxes", optionally "person_ids")'
        )
    return scene, decode_ms


async def on_worker(request: Request, work: Callable[[], object], limiter: anyio.CapacityLimiter):
    """``work()`` on a worker thread of ``limiter``, stopped when the client leaves (a 400); the models' own
    checks on what validation let through (ValueError) become 422s that name them."""

    threads = getattr(request.app.state, "torch_threads", None)

    def run():
        if threads is not None and torch.get_num_threads() != threads:
            torch.set_num_threads(threads)  # service.app.torch_threads
        try:
            return work()
        except InputError:
            raise
        except ValueError as exc:
            raise InputError(f"the scene could not be processed: {exc}") from None

    try:
        return await run_until_disconnected(request.receive, run, limiter=limiter)
    except ClientGone as exc:  # nobody reads this answer; it keeps the access log truthful
        raise HTTPException(400, str(exc)) from None


async def pipeline_result(
    request: Request,
    pipeline: ScenePipeline,
    scene: ValidatedScene,
    unsure: Callable[[ValidatedScene], object] | None = None,
    detected: Detected | None = None,
) -> SceneResult:
    """``ScenePipeline.run`` on a validated scene, on the inference worker (``detected``: its detector stage,
    when it already ran)."""

    def infer() -> SceneResult:
        asked = False if unsure is None else unsure(scene)
        return pipeline.run(scene.views, scene.boxes, scene.person_ids, unsure=asked, detected=detected)

    return await on_worker(request, infer, request.app.state.inference_limiter)


# ----------------------------------------------------------------------------------------------- streams
# The pattern is the schema's word; check_stream_id enforces it with a message of its own (a 422 Error body).
_STREAM_ID = Path(
    description="the stream's name, chosen by the client: 1 to 64 letters, digits, '.', '_' or '-', starting "
    "with a letter or digit. A frame to a name the server does not hold starts a new stream",
    json_schema_extra={"pattern": f"^{STREAM_ID.pattern}$", "minLength": 1, "maxLength": 64},
)
_STREAM_ERRORS = {
    **_ERRORS,
    409: {
        "model": Error,
        "description": "the frame is not later than the stream's last frame (or mixes timestamp_s with the "
        "server's clock); the message says what was expected",
    },
    422: {
        **_ERRORS[422],
        "description": "the stream id is not valid, or " + _ERRORS[422]["description"],
    },
    503: {
        **_ERRORS[503],
        "description": _ERRORS[503]["description"].replace(
            "(ORPOSE_MAX_IN_FLIGHT)", "(ORPOSE_MAX_IN_FLIGHT) or streams held (ORPOSE_MAX_STREAMS)"
        ),
    },
}


_STREAM_FRAME = Annotated[StreamFrameOut | StreamFrameDropped, Field(discriminator="status")]


@protected.post(
    "/streams/{stream_id}/frames",
    response_model=_STREAM_FRAME,
    responses=_STREAM_ERRORS,
    summary="One frame of a stream: the persons of POST /scenes, each with its track over time",
    description="The same multipart form as POST /scenes, plus an optional `timestamp_s` field. Frames of one "
    "stream must arrive in time order (else 409). A frame is decoded and detected while the frame before it is "
    "in the pose stage; each person carries its `track_id` (stable from frame to frame) and its "
    "`smoothed_joints` beside the raw `joints` (`status` answered). When frames arrive faster than the server "
    "answers them, a frame still waiting when a newer one arrives is answered at once with `status` dropped "
    "and why, and the stream never takes it: the lag stays bounded, never a growing queue.",
    openapi_extra={SCENE_FORM: "stream"},
)
async def post_stream_frame(
    stream_id: Annotated[str, _STREAM_ID],
    request: Request,
    pipeline: PipelineDep,
    settings: SettingsDep,
    streams: StreamsDep,
) -> Response:
    t_start, received = time.perf_counter(), streams.now()
    check_stream_id(stream_id)
    texts, files = await _read_form(request, settings, ("scene", "timestamp_s"))
    scene_text = _scene_part(texts)
    timestamp_s = parse_timestamp(texts.get("timestamp_s"))
    frame_of = {"stream_id": stream_id, "timestamp_s": timestamp_s, "received": received}
    # A waiting frame holds no inference slot: it takes one when its front turn starts (a stream then holds at
    # most three: the front, a frame ready for the pose stage, and the pose stage).
    async with (
        _admitted(request, settings, streams, slot=False, **frame_of) as frame,
        AsyncExitStack() as slot,
    ):
        if frame.replay is not None:  # the last frame again, its answer lost on the way: the same answer
            return Response(frame.replay, media_type="application/json")
        try:
            async with frame.turn("front"):
                await slot.enter_async_context(_admitted(request, settings))  # held to the answer
                scene, decode_ms = await decoded(request, pipeline, scene_text, files, t_start)
                decode_ms -= frame.waited_ms
                detected = None
                if scene.boxes is None:
                    detect = partial(pipeline.detect, scene.views)
                    detected = await on_worker(request, detect, request.app.state.front_limiter)
            async with frame.turn("pose"):  # front's turn passed on: the next frame is decoded meanwhile
                result = await pipeline_result(request, pipeline, scene, frame.prepare, detected)
                t_encode = time.perf_counter()
                body = frame.answer(result, scene, decode_ms, t_start)
        except Dropped as drop:
            return Response(frame.dropped(drop, t_start), media_type="application/json")
    _observe(request, STREAM_FRAMES, result, decode_ms, t_encode, t_start)
    return Response(body, media_type="application/json")


@protected.delete(
    "/streams/{stream_id}",
    response_model=StreamEnded,
    responses={
        404: {"model": Error, "description": "no such stream (never started, ended, or expired)"},
        422: {"model": Error, "description": "the stream id is not valid; the message gives the rule"},
    },
    summary="End a stream: its tracks are forgotten, and a later frame to this id starts afresh",
)
async def delete_stream(stream_id: Annotated[str, _STREAM_ID], streams: StreamsDep) -> StreamEnded:
    check_stream_id(stream_id)
    return await streams.end(stream_id)
