"""The OpenAPI schema at ``/openapi.json``: what the server accepts and answers, built from its settings.

FastAPI writes the routes and the response models; this module adds what no route parameter declares, so that
the schema is the server's truth (a client generated from it, or schemathesis, sends only what is accepted):

- **Authentication.** An HTTP bearer security scheme, with ``security`` and a 401 on each protected operation,
  only when ``ORPOSE_TOKEN`` is set. Without a token the schema names no Authorization header at all. The
  check itself is :func:`service.deps.require_token`, which reads the header without declaring a parameter.
- **The multipart forms** of ``POST /scenes`` and ``POST /streams/{stream_id}/frames``: the ``scene`` part
  (application/json, ``SceneIn``), ``color_0..color_{N-1}`` (image/png or image/jpeg) and ``depth_0..
  depth_{N-1}`` (image/png, 16-bit) for N = ``ORPOSE_MAX_VIEWS``, ``timestamp_s`` for streams, and no other
  part (``additionalProperties: false``, ``maxProperties``).
- **The bounds that depend on the settings**: views per scene (``ORPOSE_MAX_VIEWS``), boxes and ids per view
  (``ORPOSE_MAX_BOXES_PER_VIEW``), beside the fixed ones of the pydantic models (``service.schemas``,
  ``posenet.rig.rigfile``).
- **Every status** a route can answer, each with the error body ``Error`` and its headers (Retry-After with a
  503, WWW-Authenticate with a 401).

What the schema cannot say is checked by ``service.validation`` and answered 422 (or 413 / 415 for an image):
that each view's images decode, are 16-bit depth and colour of one size, that the principal point lies inside
them, that extrinsics are rigid, that a scene of N views has exactly the parts of views 0..N-1.
"""

from __future__ import annotations

import copy

from fastapi import FastAPI, routing
from fastapi.openapi.utils import get_openapi

from service.deps import require_token
from service.schemas import SceneIn
from service.settings import Settings
from service.streams import MAX_TIMESTAMP_S

BEARER = "bearerAuth"
MULTIPART = "multipart/form-data"
SCENE_FORM = "x-orpose-scene-form"  # an operation's openapi_extra marker: "scene" or "stream"
COLOR_TYPES = "image/png, image/jpeg"
# What the multipart parser reads (service.routes._read_form) before it stops: text parts (scene, timestamp_s, and
# room to name a stray one in a 422; beyond: 400 "Too many fields") and file parts (the views' and one more, to
# name an unexpected part; beyond: a 422 that names ORPOSE_MAX_VIEWS). The schema allows less: its own parts.
MAX_TEXT_PARTS = 4


def max_file_parts(settings: Settings) -> int:
    return 2 * settings.max_views + 1


_ERROR = {"$ref": "#/components/schemas/Error"}
RETRY_AFTER = {
    "Retry-After": {"description": "seconds to wait before retrying", "schema": {"type": "string"}}
}
_WWW_AUTHENTICATE = {
    "WWW-Authenticate": {
        "description": "Bearer: the scheme to authenticate with",
        "schema": {"type": "string"},
    }
}


def error(description: str, headers: dict | None = None) -> dict:
    """An error response: ``{"detail": "..."}`` (``Error``), with ``headers``."""
    out = {"description": description, "content": {"application/json": {"schema": _ERROR}}}
    if headers:
        out["headers"] = headers
    return out


def scene_form(settings: Settings, stream: bool) -> dict:
    """The requestBody of ``POST /scenes`` (``stream`` False) or of a stream's frame."""
    n = settings.max_views
    last = n - 1
    properties: dict = {
        "scene": {
            "$ref": "#/components/schemas/SceneIn",
            "description": "the scene as JSON (application/json): per view the camera, depth_scale_mm, and "
            f"optional reference boxes / person_ids; 1 to {n} views (ORPOSE_MAX_VIEWS)",
        }
    }
    encoding: dict = {"scene": {"contentType": "application/json"}}
    for i in range(n):
        properties[f"color_{i}"] = {
            "type": "string",
            "format": "binary",
            "description": f"view {i}'s colour image, a PNG or JPEG file part (8-bit, at most "
            f"{settings.max_image_pixels} pixels, ORPOSE_MAX_IMAGE_PIXELS); the same size as depth_{i}. "
            "Required unless the pose network reads depth only and the scene gives boxes",
        }
        encoding[f"color_{i}"] = {"contentType": COLOR_TYPES}
        properties[f"depth_{i}"] = {
            "type": "string",
            "format": "binary",
            "description": f"view {i}'s depth, a 16-bit single-channel PNG file part (value x depth_scale_mm = "
            f"mm, 0 = unknown; at most {settings.max_image_pixels} pixels)",
        }
        encoding[f"depth_{i}"] = {"contentType": "image/png"}
    if stream:
        properties["timestamp_s"] = {
            "type": "number",
            "minimum": 0,
            "maximum": MAX_TIMESTAMP_S,
            "description": "optional: the frame's time in seconds (any clock the client keeps for the whole "
            "stream, e.g. since the recording started, or Unix time); later than the stream's last frame. "
            "Without it the server's receive time is used (and then for every frame of the stream)",
        }
        encoding["timestamp_s"] = {"contentType": "text/plain"}
    schema = {
        "type": "object",
        "description": f"a scene of N views (1 to {n}) takes the parts scene, color_0..color_N-1 and depth_0.."
        f"depth_N-1 (color_0..color_{last} and depth_0..depth_{last} at most), "
        + ("optionally timestamp_s, " if stream else "")
        + "each at most once; any other part, or a part of a view the scene does not have, is a 422. Image "
        f"parts are file parts (with a filename). The server stops reading a form beyond {max_file_parts(settings)} "
        f"file parts (422) or {MAX_TEXT_PARTS} text parts (400)",
        "required": ["scene", "depth_0"],
        "properties": properties,
        "additionalProperties": False,
        "maxProperties": len(properties),
    }
    return {"required": True, "content": {MULTIPART: {"schema": schema, "encoding": encoding}}}


def _bounded(components: dict, settings: Settings) -> None:
    """The settings' bounds in the scene's schemas (the models hold the fixed ones)."""
    scene = components["SceneIn"]
    scene["properties"]["views"]["maxItems"] = settings.max_views
    scene["properties"]["views"]["description"] += f" (this server: at most {settings.max_views})"
    # up: not all three 0 (service.validation._up) stays a 422 that the description names. A `not` here would
    # say it, but schemathesis 4.32's coverage phase cannot judge a `not` inside a form with file parts.
    scene["properties"]["up"]["description"] += "; not all three 0"
    view = components["ViewIn"]
    for name in ("boxes", "person_ids"):
        for branch in view["properties"][name].get("anyOf", []):
            if branch.get("type") == "array":
                branch["maxItems"] = settings.max_boxes_per_view
        view["properties"][name]["description"] += (
            f" At most {settings.max_boxes_per_view} per view (ORPOSE_MAX_BOXES_PER_VIEW)."
        )


def _protected(route) -> bool:
    return any(
        getattr(dep, "dependency", None) is require_token for dep in getattr(route, "dependencies", [])
    )


def build(app: FastAPI, settings: Settings) -> dict:
    """The app's OpenAPI schema (module docstring)."""
    schema = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    components = schema.setdefault("components", {})
    schemas = components.setdefault("schemas", {})
    scene = SceneIn.model_json_schema(ref_template="#/components/schemas/{model}")
    schemas.update(copy.deepcopy(scene.pop("$defs", {})))
    schemas["SceneIn"] = scene
    _bounded(schemas, settings)
    # No route takes a body FastAPI validates: its own 422 body (HTTPValidationError) is never answered.
    schemas.pop("HTTPValidationError", None)
    schemas.pop("ValidationError", None)
    token = settings.token is not None
    if token:
        components["securitySchemes"] = {
            BEARER: {
                "type": "http",
                "scheme": "bearer",
                "description": "ORPOSE_TOKEN: every operation but /health needs Authorization: Bearer <token> "
                "(GET /metrics not with ORPOSE_METRICS_OPEN=true)",
            }
        }
    for route in routing.iter_route_contexts(app.routes):  # the routes of the included routers, as served
        if not getattr(route, "include_in_schema", False) or route.path_format not in schema["paths"]:
            continue
        for method in route.methods:
            operation = schema["paths"][route.path_format][method.lower()]
            form = operation.pop(SCENE_FORM, None)
            if form is not None:
                operation["requestBody"] = scene_form(settings, stream=form == "stream")
            responses = operation["responses"]
            for status, response in responses.items():
                if status != "200" and response.get("content", {}).get("application/json", {}).get(
                    "schema"
                ) == {"$ref": "#/components/schemas/HTTPValidationError"}:
                    responses[status] = error(response["description"])
            if token and _protected(route):
                operation["security"] = [{BEARER: []}]
                responses["401"] = error(
                    "missing or wrong bearer token (Authorization: Bearer <ORPOSE_TOKEN>)", _WWW_AUTHENTICATE
                )
    return schema
