"""``GET /metrics``: the service's Prometheus metrics, one :class:`Metrics` (and one ``CollectorRegistry``) per app.

What is measured, and where (docs/service.md, "Metrics", lists the names):

- **Latency per stage** of every answered ``POST /scenes`` and stream frame (``orpose_request_stage_seconds``,
  labelled by route, mode and stage) and its total (``orpose_request_duration_seconds``): observed by the route
  from the timings it already takes (``SceneResult.timings``, the decoding time, the encoding measured around it).
- **Requests by route and status** (``orpose_requests_total``): counted by :class:`RequestCounter`, an ASGI
  middleware outside every other one, so that what the body limit answers before routing (413, 408, 503) is
  counted too. The route label is the route's path template (``/streams/{stream_id}/frames``), never the path as
  sent; a path no route takes counts as ``unmatched``.
- **Rejections by reason** (``orpose_rejections_total``): counted where each limit refuses (``service.limits``,
  the routes).
- **Gauges** (requests in flight, waiting for an inference worker, running on one, receiving their body; active
  streams): read from the limiters' and the stream registry's own counters when Prometheus scrapes, so the
  requests pay nothing for them.
- **The models**: load time per network and an info metric with each network's backend and precision, set once
  at start-up.

A request pays for a counter increment and, when answered, a handful of histogram observations (each O(1): a
walk over a fixed list of buckets); the labelled children are resolved once, at start-up.
"""

from __future__ import annotations

from collections.abc import Callable

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, Info
from prometheus_client.exposition import choose_encoder
from starlette.routing import Match
from starlette.types import ASGIApp, Message, Receive, Scope, Send

SCENES = "/scenes"
STREAM_FRAMES = "/streams/{stream_id}/frames"
MODES = ("reference_boxes", "detector")
STAGES = ("decode", "detect", "match", "pose", "encode")
# Seconds: from a box match (0.1 ms) to the largest admitted frame on a loaded machine (several s).
BUCKETS = (0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0)

# orpose_rejections_total's reasons: the limit that refused, and the status it answered with.
REJECTIONS = {
    "body_too_large": 413,  # ORPOSE_MAX_BODY_BYTES (declared or streamed)
    "image_too_large": 413,  # ORPOSE_MAX_IMAGE_PIXELS
    "body_timeout": 408,  # ORPOSE_BODY_TIMEOUT_S
    "receiving_full": 503,  # ORPOSE_MAX_RECEIVING
    "in_flight_full": 503,  # ORPOSE_MAX_IN_FLIGHT
    "streams_full": 503,  # ORPOSE_MAX_STREAMS
}


class Metrics:
    """The metrics of one app, in a registry of their own (several apps in one process do not clash)."""

    def __init__(self) -> None:
        self.registry = registry = CollectorRegistry(auto_describe=True)
        self.stage_seconds = Histogram(
            "orpose_request_stage_seconds",
            "Server time of one stage of an answered frame (POST /scenes, stream frames), by route, mode "
            "(reference_boxes, detector) and stage (decode: receiving and decoding the form; detect; match; pose; "
            "encode: the response body, for stream frames with the tracker's update)",
            ["route", "mode", "stage"],
            buckets=BUCKETS,
            registry=registry,
        )
        self.duration_seconds = Histogram(
            "orpose_request_duration_seconds",
            "Server time of an answered frame from the route's start to its encoded body, waits for an inference "
            "worker included, by route and mode",
            ["route", "mode"],
            buckets=BUCKETS,
            registry=registry,
        )
        self.requests = Counter(
            "orpose_requests",
            "HTTP requests answered, by route (path template; 'unmatched' for paths no route takes) and status",
            ["route", "status"],
            registry=registry,
        )
        self.rejections = Counter(
            "orpose_rejections",
            "Requests refused by a limit, by reason: body_too_large (413, ORPOSE_MAX_BODY_BYTES), image_too_large "
            "(413, ORPOSE_MAX_IMAGE_PIXELS), body_timeout (408, ORPOSE_BODY_TIMEOUT_S), receiving_full (503, "
            "ORPOSE_MAX_RECEIVING), in_flight_full (503, ORPOSE_MAX_IN_FLIGHT), streams_full (503, "
            "ORPOSE_MAX_STREAMS)",
            ["reason"],
            registry=registry,
        )
        self.in_flight = Gauge(
            "orpose_requests_in_flight",
            "Requests holding an inference slot (ORPOSE_MAX_IN_FLIGHT): decoding, waiting for a worker or running",
            registry=registry,
        )
        self.waiting = Gauge(
            "orpose_inference_waiting",
            "Requests waiting for a free inference worker (ORPOSE_INFERENCE_WORKERS): the queue's depth",
            registry=registry,
        )
        self.running = Gauge(
            "orpose_inference_running", "Frames running through the models now", registry=registry
        )
        self.receiving = Gauge(
            "orpose_requests_receiving",
            "Requests still receiving their body (ORPOSE_MAX_RECEIVING)",
            registry=registry,
        )
        self.streams = Gauge(
            "orpose_streams_active", "Streams held and not expired (ORPOSE_MAX_STREAMS)", registry=registry
        )
        self.load_seconds = Gauge(
            "orpose_model_load_seconds",
            "Time the network took to load at start-up (weights, graph export or cache, calibration)",
            ["network"],
            registry=registry,
        )
        self.model = Info(
            "orpose_model", "The runtime of each loaded network", ["network"], registry=registry
        )
        # Resolved once: a request then looks its children up in a plain dict.
        self._stages = {
            (route, mode): (
                tuple(self.stage_seconds.labels(route, mode, stage) for stage in STAGES),
                self.duration_seconds.labels(route, mode),
            )
            for route in (SCENES, STREAM_FRAMES)
            for mode in MODES
        }
        self._reasons = {reason: self.rejections.labels(reason) for reason in REJECTIONS}
        self._counts: dict[tuple[str, int], Callable[[], None]] = {}

    # ---------------------------------------------------------------------------------- the hot path
    def frame(
        self,
        route: str,
        mode: str,
        timings: dict[str, float],
        decode_ms: float,
        encode_ms: float,
        total_ms: float,
    ) -> None:
        """An answered frame: ``timings`` are the pipeline's (ms: detect, match, pose)."""
        stages, duration = self._stages[route, mode]
        decode, detect, match, pose, encode = stages
        decode.observe(decode_ms * 1e-3)
        detect.observe(timings.get("detect", 0.0) * 1e-3)
        match.observe(timings.get("match", 0.0) * 1e-3)
        pose.observe(timings.get("pose", 0.0) * 1e-3)
        encode.observe(encode_ms * 1e-3)
        duration.observe(total_ms * 1e-3)

    def rejected(self, reason: str) -> None:
        self._reasons[reason].inc()

    def answered(self, route: str, status: int) -> None:
        inc = self._counts.get((route, status))
        if inc is None:  # once per (route, status) seen
            inc = self._counts[route, status] = self.requests.labels(route, str(status)).inc
        inc()

    # ---------------------------------------------------------------------------------- start-up, scrape
    def watch(
        self,
        in_flight: Callable[[], float],
        waiting: Callable[[], float],
        running: Callable[[], float],
        receiving: Callable[[], float],
        streams: Callable[[], float],
    ) -> None:
        """Where the gauges read their values when Prometheus scrapes."""
        for gauge, read in (
            (self.in_flight, in_flight),
            (self.waiting, waiting),
            (self.running, running),
            (self.receiving, receiving),
            (self.streams, streams),
        ):
            gauge.set_function(read)

    def models(self, pipeline) -> None:
        """The loaded networks' runtimes (``pipeline``: a ``ScenePipeline``) and, when it loaded them, their load
        times (``ScenePipeline.load_seconds``)."""
        for network, net in (("pose", pipeline.pose), ("detector", pipeline.detector)):
            if net is None:
                continue
            self.model.labels(network).info({"backend": net.backend.name, "precision": net.precision.name})
        for network, seconds in pipeline.load_seconds.items():
            self.load_seconds.labels(network).set(seconds)

    def exposition(self, accept: str | None) -> tuple[bytes, str]:
        """The body and content type of a scrape (the text format, or OpenMetrics when ``accept`` asks for it)."""
        encoder, content_type = choose_encoder(accept or "")
        return encoder(self.registry), content_type


class RequestCounter:
    """ASGI middleware: every HTTP request's route and status into ``orpose_requests_total``.

    It sits outside the other middleware, so answers that never reach a route (the body limit's 413 from
    Content-Length) are counted as well; an exception that escapes the app counts as 500.
    """

    def __init__(self, app: ASGIApp, metrics: Metrics, routes: list) -> None:
        """``routes``: the app's routes (starlette ``BaseRoute`` with a ``path``), to name a request that no route
        took (one answered by the middleware)."""
        self.app = app
        self.metrics = metrics
        self.routes = routes

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        status = 500

        async def sending(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, sending)
        finally:
            self.metrics.answered(self._route(scope), status)

    def _route(self, scope: Scope) -> str:
        route = scope.get("route")
        if route is not None:
            return getattr(route, "path", "unmatched")
        # Answered before routing (or by no route): find the route that would have taken it.
        for candidate in self.routes:
            if candidate.matches(scope)[0] == Match.FULL:
                return getattr(candidate, "path", "unmatched")
        return "unmatched"
