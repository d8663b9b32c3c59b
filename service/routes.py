"""The HTTP routes: ``/health``, ``/ready``, ``/model`` and ``POST /scenes``.

Routes stay thin: ``/scenes`` reads the multipart form into memory, hands the parts to ``service.validation``
(decoding, off the event loop), runs the pipeline on an inference worker thread, and serialises the result.
"""

from __future__ import annotations

import time

import anyio
from fastapi import APIRouter, Depends, HTTPException, Request, Response
from starlette.datastructures import UploadFile
from starlette.formparsers import MultiPartException, MultiPartParser
from starlette.requests import ClientDisconnect

from posenet.skeleton import JOINTS
from service.deps import Admitted, PipelineDep, SettingsDep, require_token
from service.errors import UNSUPPORTED_MEDIA, InputError
from service.model_info import model_info
from service.pipeline import SceneResult
from service.schemas import Error, Health, Joint, ModelInfo, Person, Ready, SceneOut, Support, Timings
from service.settings import Settings
from service.validation import Limits, parse_scene, validate_scene

public = APIRouter()
_UNAUTHORIZED = {
    401: {"model": Error, "description": "missing or wrong bearer token (when ORPOSE_TOKEN is set)"}
}
protected = APIRouter(dependencies=[Depends(require_token)], responses=_UNAUTHORIZED)

_ERRORS = {
    400: {"model": Error, "description": "malformed multipart body"},
    401: {"model": Error, "description": "missing or wrong bearer token (only when ORPOSE_TOKEN is set)"},
    408: {"model": Error, "description": "the body did not arrive in time"},
    413: {"model": Error, "description": "the body or an image is beyond the server's limits"},
    415: {"model": Error, "description": "not multipart/form-data, or an image that is neither PNG nor JPEG"},
    422: {"model": Error, "description": "the scene is wrong; the message names the part and the problem"},
    503: {
        "model": Error,
        "description": "too many requests in flight (see Retry-After), or models not loaded",
    },
}

_MULTIPART = "multipart/form-data"
_SCENE_FORM = {
    "type": "object",
    "required": ["scene", "depth_0"],
    "properties": {
        "scene": {
            "$ref": "#/components/schemas/SceneIn",
            "description": "the scene as JSON: per view the camera, depth_scale_mm, and optional reference "
            "boxes / person_ids",
        },
        **{
            f"{kind}_{i}": {
                "type": "string",
                "format": "binary",
                "description": f"view {i}'s "
                + (
                    "colour image, PNG or JPEG, 8-bit"
                    if kind == "color"
                    else "depth, 16-bit PNG (mm x scale)"
                ),
            }
            for i in range(3)
            for kind in ("color", "depth")
        },
    },
    "patternProperties": {
        "^(color|depth)_[0-9]+$": {
            "type": "string",
            "format": "binary",
            "description": "color_<i> / depth_<i> for views beyond the third",
        }
    },
    "additionalProperties": False,
}
# The scene part is JSON (its schema is SceneIn); the images are binary file parts.
_SCENE_BODY = {"schema": _SCENE_FORM, "encoding": {"scene": {"contentType": "application/json"}}}


@public.get("/health", response_model=Health, summary="Liveness: the process answers")
async def health() -> Health:
    return Health()


@protected.get("/ready", response_model=Ready, responses={503: {"model": Ready}}, summary="Models loaded")
async def ready(request: Request, response: Response) -> Ready:
    loaded = getattr(request.app.state, "pipeline", None) is not None
    if not loaded:
        response.status_code = 503
    return Ready(ready=loaded)


@protected.get("/model", response_model=ModelInfo, summary="What the loaded models read and were trained on")
async def model(pipeline: PipelineDep, settings: SettingsDep) -> ModelInfo:
    return model_info(pipeline, settings.device)


async def _read_form(request: Request, settings: Settings) -> tuple[bytes | None, dict[str, bytes]]:
    """The ``scene`` text and the file parts, all in memory (a spool that never rolls over to disk)."""
    content_type = request.headers.get("content-type", "")
    if not content_type.startswith("multipart/form-data"):
        got = content_type or "no content type"
        raise InputError(f"expected multipart/form-data, got {got!r}", UNSUPPORTED_MEDIA)
    parser = MultiPartParser(
        request.headers,
        request.stream(),
        max_files=2 * settings.max_views + 1,
        max_fields=4,
        max_part_size=settings.max_body_bytes,
    )
    parser.spool_max_size = settings.max_body_bytes  # the body is capped: keep every part in memory
    try:
        form = await parser.parse()
    except MultiPartException as exc:
        raise HTTPException(400, f"malformed multipart body: {exc.message}") from None
    except ClientDisconnect:  # nobody is left to answer; a 400 rather than a 500 traceback in the log
        raise HTTPException(400, "the client disconnected before the body was complete") from None
    scene, files = None, {}
    try:
        for name, value in form.multi_items():
            data = await value.read() if isinstance(value, UploadFile) else value.encode()
            if name == "scene":
                if scene is not None:
                    raise InputError("the form has more than one 'scene' part")
                scene = data
            elif name in files:
                raise InputError(f"the form has more than one {name!r} part")
            elif not isinstance(value, UploadFile):
                # A part without a filename arrives as text, and text decoding would corrupt image bytes.
                raise InputError(
                    f"{name} must be a file part (with a filename), e.g. curl -F {name}=@image.png"
                )
            else:
                files[name] = data
    finally:
        await form.close()
    return scene, files


def _person(p) -> Person:
    return Person(
        id=p.id,
        joints=[
            Joint(name=name, position=tuple(map(float, xyz)), confidence=float(c))
            for name, xyz, c in zip(JOINTS, p.joints, p.confidence, strict=True)
        ],
        views=[Support(view=v, box=tuple(map(float, p.boxes[v])), score=p.scores[v]) for v in p.support],
    )


def _encode(result: SceneResult, decode_ms: float, t_start: float) -> bytes:
    t0 = time.perf_counter()
    out = SceneOut(
        mode=result.mode,
        persons=[_person(p) for p in result.persons],
        timings=Timings(decode=decode_ms, encode=0.0, total=0.0, **result.timings),
    )
    out.model_dump_json()
    # The encode time is measured on a first serialisation; the response carries it in the second.
    out.timings.encode = (time.perf_counter() - t0) * 1e3
    out.timings.total = (time.perf_counter() - t_start) * 1e3
    return out.model_dump_json().encode()


@protected.post(
    "/scenes",
    response_model=SceneOut,
    responses=_ERRORS,
    summary="3D poses of everyone in one synchronised multi-view RGB-D frame",
    description="multipart/form-data with a `scene` JSON part (SceneIn) and, per view i, the file parts "
    "`color_i` (PNG/JPEG) and `depth_i` (16-bit PNG). With boxes in any view, detection is skipped "
    "(reference-box mode). Every 3D coordinate in the response is in mm in the reference frame.",
    openapi_extra={"requestBody": {"required": True, "content": {_MULTIPART: _SCENE_BODY}}},
)
async def post_scene(request: Request, pipeline: PipelineDep, settings: SettingsDep, _: Admitted) -> Response:
    t_start = time.perf_counter()
    scene_text, files = await _read_form(request, settings)
    if scene_text is None:
        raise InputError("missing form part 'scene' (the JSON with the views' cameras)")
    limits = Limits(settings.max_views, settings.max_image_pixels, settings.max_boxes_per_view)
    need_color = "color" in pipeline.modalities

    def decode():
        return validate_scene(parse_scene(scene_text, limits), files, limits, need_color)

    scene = await anyio.to_thread.run_sync(decode)
    decode_ms = (time.perf_counter() - t_start) * 1e3
    if scene.boxes is None and pipeline.detector is None:
        raise InputError(
            'this server runs without a detector (no detector weights loaded, or ORPOSE_LOAD_DETECTOR=false): send reference boxes (per view "boxes", optionally "person_ids")'
        )

    def infer() -> SceneResult:
        try:
            return pipeline.run(scene.views, scene.boxes, scene.person_ids)
        except InputError:
            raise
        except ValueError as exc:  # the models' own checks on what validation let through
            raise InputError(f"the scene could not be processed: {exc}") from None

    result = await anyio.to_thread.run_sync(infer, limiter=request.app.state.inference_limiter)
    return Response(_encode(result, decode_ms, t_start), media_type="application/json")
