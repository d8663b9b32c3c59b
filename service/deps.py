"""FastAPI dependencies, as ``Annotated`` aliases: settings, the loaded pipeline, the streams, the bearer token;
and the admission to an inference slot."""

from __future__ import annotations

import secrets
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Annotated

from fastapi import Depends, HTTPException, Request

from pipeline.two_stage import ScenePipeline
from service.settings import Settings
from service.streams import StreamRegistry


def get_settings(request: Request) -> Settings:
    return request.app.state.settings


SettingsDep = Annotated[Settings, Depends(get_settings)]


def require_token(request: Request) -> None:
    """401 unless the request carries ``Authorization: Bearer <ORPOSE_TOKEN>`` (when a token is configured).

    It reads the header itself rather than declaring it as a parameter: the OpenAPI schema then names the
    header only through the bearer security scheme, and only when a token is set (``service.openapi``)."""
    settings: Settings = request.app.state.settings
    if settings.token is None:
        return
    expected = settings.token.get_secret_value().encode()
    scheme, _, credentials = request.headers.get("authorization", "").strip().partition(" ")
    given = credentials.strip().encode() if scheme.lower() == "bearer" else b""
    if not secrets.compare_digest(given, expected):  # constant time: the token cannot be guessed byte by byte
        raise HTTPException(401, "missing or wrong bearer token", headers={"WWW-Authenticate": "Bearer"})


def get_pipeline(request: Request) -> ScenePipeline:
    pipeline = getattr(request.app.state, "pipeline", None)
    if pipeline is None:
        raise HTTPException(503, "the models are not loaded yet", headers={"Retry-After": "5"})
    return pipeline


PipelineDep = Annotated[ScenePipeline, Depends(get_pipeline)]


def get_streams(request: Request) -> StreamRegistry:
    return request.app.state.streams


StreamsDep = Annotated[StreamRegistry, Depends(get_streams)]


@asynccontextmanager
async def inference_slot(request: Request, settings: Settings) -> AsyncIterator[None]:
    """Hold one of the ``max_in_flight`` inference slots (decoding and the models), or answer 503 with
    Retry-After at once. The route takes it only once the body has arrived, so a slow upload never holds one.
    """
    limiter = request.app.state.in_flight
    if not limiter.try_acquire():
        raise HTTPException(
            503,
            f"the server is busy ({limiter.capacity} requests in flight, ORPOSE_MAX_IN_FLIGHT); retry after "
            f"{settings.retry_after_s} s",
            headers={"Retry-After": str(settings.retry_after_s)},
        )
    try:
        yield
    finally:
        limiter.release()
