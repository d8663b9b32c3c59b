"""``GET /metrics`` against a real uvicorn server: the Prometheus text parsed back with prometheus_client's own
parser, after answered frames, 4xx and a rejection; the token, and ``ORPOSE_METRICS_OPEN``.

The server runs a tiny random-init pose network (no detector), with a token and a small body cap.
"""

from __future__ import annotations

import socket
import time

import httpx
import pytest
from conftest import write_tiny_mvor
from prometheus_client.parser import text_string_to_metric_families
from service_harness import Server, Tricklers, form_kwargs, tiny_checkpoints

from posenet.data.mvor import MvorDataset
from service.app import create_app
from service.client import scene_request
from service.settings import Settings

TOKEN = "tok"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
MAX_BODY = 4 * 2**20
SCENES = "/scenes"
FRAMES = "/streams/{stream_id}/frames"


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny_mvor"), days=(1,), frames_per_day=1)
    return form_kwargs(*scene_request(MvorDataset(None, data.gt)[0], data.root, True))


@pytest.fixture(scope="module")
def pose(tmp_path_factory):
    return tiny_checkpoints(tmp_path_factory.mktemp("ckpt"), detector=False)[0]


def _env(pose, **extra) -> dict[str, str]:
    return {
        "ORPOSE_POSE_CHECKPOINT": str(pose),
        "ORPOSE_LOAD_DETECTOR": "false",
        "ORPOSE_TOKEN": TOKEN,
        "ORPOSE_MAX_BODY_BYTES": str(MAX_BODY),
        **extra,
    }


@pytest.fixture(scope="module")
def server(pose):
    with Server(_env(pose)) as url, httpx.Client(base_url=url, headers=AUTH, timeout=60) as client:
        yield client


def scrape(client: httpx.Client, **kw) -> dict:
    """``/metrics`` parsed: {family name: family}; asserts the 200 and the text format's content type."""
    r = client.get("/metrics", **kw)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain; version=0.0.4")
    return {family.name: family for family in text_string_to_metric_families(r.text)}


def value(families: dict, family: str, sample: str | None = None, **labels) -> float:
    """The value of the one sample of ``family`` named ``sample`` (default: the family's name) whose labels include
    ``labels``; 0 when there is none."""
    found = [
        s.value
        for s in families[family].samples
        if s.name == (sample or family) and labels.items() <= s.labels.items()
    ]
    assert len(found) <= 1, (family, labels, found)
    return found[0] if found else 0.0


def declared_oversized(client: httpx.Client) -> bytes:
    """A /scenes head declaring a body over the cap: answered 413 before any route."""
    host, port = client.base_url.host, client.base_url.port
    with socket.create_connection((host, port)) as sock:
        sock.settimeout(10)
        sock.sendall(
            f"POST /scenes HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {TOKEN}\r\n"
            f"Content-Type: multipart/form-data; boundary=x\r\nContent-Length: {MAX_BODY + 1}\r\n\r\n".encode()
        )
        answer = b""
        while chunk := sock.recv(4096):
            answer += chunk
    return answer


def test_metrics_need_the_token(server):
    r = server.get("/metrics", headers={"Authorization": ""})
    assert r.status_code == 401, r.text
    assert server.get("/metrics", headers={"Authorization": "Bearer wrong"}).status_code == 401


def test_frames_statuses_and_rejections_move_their_metrics(server, frame):
    before = scrape(server)
    assert server.post(SCENES, **frame).status_code == 200
    assert server.post(SCENES, files=frame["files"]).status_code == 422  # no scene part
    assert declared_oversized(server).startswith(b"HTTP/1.1 413")
    stream = {**frame, "data": {**frame["data"], "timestamp_s": "0.5"}}
    assert server.post("/streams/m-1/frames", **stream).status_code == 200, "stream frame"
    after = scrape(server)

    types = {name: family.type for name, family in after.items() if name.startswith("orpose_")}
    assert types == {
        "orpose_request_stage_seconds": "histogram",
        "orpose_request_duration_seconds": "histogram",
        "orpose_requests": "counter",
        "orpose_rejections": "counter",
        "orpose_requests_in_flight": "gauge",
        "orpose_inference_waiting": "gauge",
        "orpose_inference_running": "gauge",
        "orpose_requests_receiving": "gauge",
        "orpose_streams_active": "gauge",
        "orpose_model_load_seconds": "gauge",
        "orpose_model_info": "gauge",  # an info metric, which the text format writes as a gauge of 1
    } | {name: "gauge" for name in types if name.endswith("_created")}

    def moved(family, sample, **labels):
        return value(after, family, sample, **labels) - value(before, family, sample, **labels)

    # Every stage of both frame routes: one observation each, in a bucket, the +Inf bucket and the count.
    stage, total = "orpose_request_stage_seconds", "orpose_request_duration_seconds"
    for route in (SCENES, FRAMES):
        mode = {"route": route, "mode": "reference_boxes"}
        for name in ("decode", "detect", "match", "pose", "encode"):
            labels = {**mode, "stage": name}
            assert moved(stage, f"{stage}_count", **labels) == 1, labels
            assert moved(stage, f"{stage}_bucket", **labels, le="+Inf") == 1, labels
            assert moved(stage, f"{stage}_bucket", **labels, le="30.0") == 1, labels
        assert moved(total, f"{total}_count", **mode) == 1, route
        seconds = moved(total, f"{total}_sum", **mode)
        assert 0 < seconds < 30, (route, seconds)
        assert moved(stage, f"{stage}_sum", **mode, stage="pose") <= seconds
        # The smallest bucket that holds the total moved, and every larger one with it (cumulative buckets).
        buckets = sorted(
            (float(s.labels["le"]), s.value - value(before, total, s.name, **s.labels))
            for s in after[total].samples
            if s.name == f"{total}_bucket" and mode.items() <= s.labels.items()
        )
        assert [n for le, n in buckets if le >= seconds] == [1] * sum(le >= seconds for le, _ in buckets)
    assert moved(stage, f"{stage}_count", route=SCENES, mode="detector", stage="pose") == 0

    requests = "orpose_requests"
    assert moved(requests, "orpose_requests_total", route=SCENES, status="200") == 1
    assert moved(requests, "orpose_requests_total", route=SCENES, status="422") == 1
    assert (
        moved(requests, "orpose_requests_total", route=SCENES, status="413") == 1
    )  # answered before routing
    assert moved(requests, "orpose_requests_total", route=FRAMES, status="200") == 1
    assert value(after, requests, "orpose_requests_total", route="/metrics", status="200") >= 1
    assert moved("orpose_rejections", "orpose_rejections_total", reason="body_too_large") == 1
    assert moved("orpose_rejections", "orpose_rejections_total", reason="in_flight_full") == 0

    for gauge in ("orpose_requests_in_flight", "orpose_inference_waiting", "orpose_inference_running"):
        assert value(after, gauge) == 0, gauge  # nothing in flight while /metrics answers
    assert value(after, "orpose_requests_receiving") == 0
    assert value(after, "orpose_streams_active") == 1
    assert server.delete("/streams/m-1").status_code == 200
    assert value(scrape(server), "orpose_streams_active") == 0

    assert value(after, "orpose_model_load_seconds", network="pose") > 0
    info = [s.labels for s in after["orpose_model_info"].samples if s.value == 1]
    assert [labels["network"] for labels in info] == ["pose"]  # no detector loaded
    assert info[0]["backend"] in {"torch", "onnxruntime", "openvino"} and info[0]["precision"], info


def test_receiving_gauge_counts_bodies_on_their_way(server):
    slow = Tricklers(server.base_url, 3, TOKEN)
    try:
        assert value(scrape(server), "orpose_requests_receiving") == 3
    finally:
        slow.close()
    deadline = time.monotonic() + 5  # the server notices the closed connections and frees their places
    while value(scrape(server), "orpose_requests_receiving") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert value(scrape(server), "orpose_requests_receiving") == 0


def test_metrics_open_serves_them_without_the_token(pose):
    with (
        Server(_env(pose, ORPOSE_METRICS_OPEN="true")) as url,
        httpx.Client(base_url=url, timeout=60) as client,
    ):
        families = scrape(client)
        assert "orpose_requests" in families and "orpose_request_stage_seconds" in families
        assert client.get("/ready").status_code == 401  # everything else still needs it
        assert client.get("/ready", headers=AUTH).status_code == 200


def test_each_app_has_its_own_registry():
    first, second = create_app(Settings()), create_app(Settings())  # no model is loaded by create_app
    assert first.state.metrics.registry is not second.state.metrics.registry
    first.state.metrics.answered("/health", 200)
    text = {
        m.name: m for m in text_string_to_metric_families(second.state.metrics.exposition(None)[0].decode())
    }
    assert value(text, "orpose_requests", "orpose_requests_total", route="/health") == 0


def test_each_limit_counts_its_rejections(pose, frame):
    # In process (the limits are filled by hand, which a real server's clients cannot do in a bounded time).
    from fastapi.testclient import TestClient

    settings = Settings(
        pose_checkpoint=pose, load_detector=False, threads=1, max_streams=1, max_image_pixels=640 * 480 - 1
    )
    with TestClient(create_app(settings)) as client:
        app = client.app

        def rejections() -> dict[str, float]:
            family = scrape(client)["orpose_rejections"]
            return {
                s.labels["reason"]: s.value for s in family.samples if s.name == "orpose_rejections_total"
            }

        assert set(rejections().values()) == {0}
        r = client.post(SCENES, **frame)
        assert r.status_code == 413, r.text  # an image over ORPOSE_MAX_IMAGE_PIXELS
        app.state.settings.max_image_pixels = 1920 * 1200
        app.state.in_flight.in_flight = app.state.in_flight.capacity  # every slot taken
        assert client.post(SCENES, **frame).status_code == 503
        app.state.in_flight.in_flight = 0
        assert client.post("/streams/a/frames", **frame).status_code == 200
        assert client.post("/streams/b/frames", **frame).status_code == 503  # ORPOSE_MAX_STREAMS = 1
        assert rejections() == {
            "body_too_large": 0,
            "image_too_large": 1,
            "body_timeout": 0,
            "receiving_full": 0,
            "in_flight_full": 1,
            "streams_full": 1,
        }
