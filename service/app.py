"""The FastAPI app: ``uvicorn service.app:app`` (settings from ``ORPOSE_*`` env vars, see
service/settings.py).

``create_app(settings, pipeline)`` builds an app; the module attribute ``app`` is built on first access, so
that importing this module reads no environment and loads no model. The models load once, in the lifespan,
into ``app.state.pipeline``, unless a ready pipeline is passed in (tests, offline tools).
"""

from __future__ import annotations

import time
from contextlib import asynccontextmanager

import anyio
import torch
from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse

from pipeline.skeleton_matching import SkeletonMatchConfig
from pipeline.track import Tracker, TrackerConfig
from pipeline.two_stage import PipelineConfig, ScenePipeline
from service import openapi
from service.errors import InputError
from service.limits import BodyLimitMiddleware, InFlightLimiter
from service.metrics import Metrics, RequestCounter
from service.routes import docs_router, metrics_router, protected, public
from service.settings import Settings
from service.stream_store import RedisStreams
from service.streams import StreamRegistry


def pipeline_config(settings: Settings) -> PipelineConfig:
    """The pipeline's knobs from the service's settings."""
    return PipelineConfig(
        max_pose_pixels=settings.max_pose_pixels,
        matcher=settings.matcher,
        candidate_score=settings.candidate_score,
        skeleton_match=SkeletonMatchConfig(free_space_mm=settings.free_space_mm or None),
    )


def load_pipeline(settings: Settings) -> ScenePipeline:
    """Both models from ``settings``' checkpoints (``ScenePipeline.from_checkpoints``; it records the seconds
    each took to load, ``orpose_model_load_seconds``)."""
    return ScenePipeline.from_checkpoints(
        settings.pose_checkpoint,
        settings.detector_checkpoint,
        settings.device,
        settings.load_detector,
        pipeline_config(settings),
        settings.precision,
        settings.backend,
        settings.threads,
        settings.flip_test,
    )


def torch_threads(threads: int, pipeline: ScenePipeline) -> int:
    """torch's intra-op threads while serving: ``threads`` where a network runs on torch, else 1.

    With both networks on an inference runtime (which keeps ``threads`` of its own), torch computes only the pose
    stage's small tensor ops (crops, lifting, softmax moments). Two OpenMP threads there wait at every op for a
    core that the runtime's threads or another process hold: on a 2-core machine with a load average of 3, the
    pose stage took 750-850 ms per 4-person frame at 2 torch threads against 50-110 ms at 1, with the runtimes at
    2 threads either way (2026-12-06, Intel Xeon with AMX; docs/service.md, "Settings")."""
    networks = [pipeline.pose] + ([pipeline.detector] if pipeline.detector is not None else [])
    on_torch = any(getattr(n, "backend", None) is None or n.backend.name == "torch" for n in networks)
    return threads if on_torch else 1


@asynccontextmanager
async def lifespan(app: FastAPI):
    settings: Settings = app.state.settings
    torch.set_num_threads(settings.threads)
    app.state.inference_limiter = anyio.CapacityLimiter(settings.inference_workers)
    # A stream's front stage (decoding, the detector) runs here while its previous frame is in the pose stage.
    app.state.front_limiter = anyio.CapacityLimiter(1)
    metrics: Metrics = app.state.metrics
    if app.state.pipeline is None:
        app.state.pipeline = await anyio.to_thread.run_sync(lambda: load_pipeline(settings))
    # set in every worker thread before its work (service.routes.on_worker): a thread keeps the OpenMP team size
    # it first ran torch with, whatever the main thread sets later
    app.state.torch_threads = torch_threads(settings.threads, app.state.pipeline)
    metrics.models(app.state.pipeline)
    yield
    app.state.pipeline = None


async def _input_error(request: Request, exc: InputError) -> JSONResponse:
    return JSONResponse({"detail": exc.message}, status_code=exc.status)


def _openapi(app: FastAPI) -> dict:
    """The app's schema (``service.openapi.build``), built once."""
    if app.openapi_schema is None:
        app.openapi_schema = openapi.build(app, app.state.settings)
    return app.openapi_schema


def tracker_config(settings: Settings) -> TrackerConfig:
    """The ``ORPOSE_TRACK_*`` settings as every stream's tracker configuration (0 turns a rule off where the
    setting says so)."""
    return TrackerConfig(
        max_spread_mm=settings.track_max_spread_mm,
        min_torso_mm=settings.track_min_torso_mm,
        min_height_mm=settings.track_min_height_mm,
        lying_height_mm=settings.track_lying_height_mm or None,
        lying_spread_mm=settings.track_lying_spread_mm,
        unsure_gate_mm=settings.track_unsure_gate_mm or None,
        max_coast_s=settings.track_max_coast_s,
    )


def create_app(settings: Settings | None = None, pipeline: ScenePipeline | None = None) -> FastAPI:
    """The app; ``pipeline`` (already loaded) skips loading the models from ``settings``' checkpoints."""
    settings = settings or Settings()
    app = FastAPI(
        title="OR multi-view RGB-D 3D human pose",
        version="0.1.0",
        description="3D upper-body poses (10 MVOR joints, mm) of everyone in a synchronised multi-view "
        "RGB-D frame, "
        "after Gerats et al., 'Differentiable projections'. See docs/service.md.",
        lifespan=lifespan,
        # Served by routes.docs_router instead, so that the token covers them (unless ORPOSE_PUBLIC_DOCS).
        docs_url=None,
        redoc_url=None,
        openapi_url=None,
    )
    app.state.settings = settings
    app.state.pipeline = pipeline
    app.state.in_flight = InFlightLimiter(settings.max_in_flight)
    app.state.metrics = metrics = Metrics()
    receiving = InFlightLimiter(settings.max_receiving)
    tracker = tracker_config(settings)
    app.state.streams = StreamRegistry(
        settings.max_streams,
        settings.stream_idle_s,
        lambda: Tracker(tracker),
        settings.retry_after_s,
        floor_up=settings.track_floor_up,
        static_scene=settings.track_static_scene,
        unsure=bool(settings.track_unsure_gate_mm),
        store=None
        if settings.redis_url is None
        else RedisStreams(settings.redis_url, settings.stream_idle_s),
        # the replicas sharing a store share a clock too: wall time for streams without timestamp_s
        **({} if settings.redis_url is None else {"now": time.time}),
    )
    _watch(app, metrics, receiving)
    app.add_middleware(
        BodyLimitMiddleware,
        max_bytes=settings.max_body_bytes,
        timeout_s=settings.body_timeout_s,
        max_receiving=settings.max_receiving,
        retry_after_s=settings.retry_after_s,
        receiving=receiving,
        rejected=metrics.rejected,
    )
    app.add_exception_handler(InputError, _input_error)
    routers = [
        public,
        protected,
        metrics_router(protect=settings.token is not None and not settings.metrics_open),
        docs_router(lambda: app.openapi(), protect=settings.token is not None and not settings.public_docs),
    ]
    for router in routers:
        app.include_router(router)
    # Added last, so outermost: it also counts what the body limit answers before any route.
    routes = [route for router in routers for route in router.routes]
    app.add_middleware(RequestCounter, metrics=metrics, routes=routes)
    app.openapi = lambda: _openapi(app)
    return app


def _watch(app: FastAPI, metrics: Metrics, receiving: InFlightLimiter) -> None:
    """The gauges read the limiters' and the streams' own counters when Prometheus scrapes (on the event loop,
    like every change to them)."""

    def inference(field: str):
        def read() -> float:
            limiter = getattr(app.state, "inference_limiter", None)  # made in the lifespan
            return 0.0 if limiter is None else getattr(limiter.statistics(), field)

        return read

    metrics.watch(
        in_flight=lambda: app.state.in_flight.in_flight,
        waiting=inference("tasks_waiting"),
        running=inference("borrowed_tokens"),
        receiving=lambda: receiving.in_flight,
        streams=app.state.streams.active,
    )


def __getattr__(name: str):
    # `uvicorn service.app:app` looks the attribute up; building it here (once) keeps imports free of side
    # effects.
    if name == "app":
        globals()["app"] = create_app()
        return globals()["app"]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
