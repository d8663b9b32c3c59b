"""Slow uploads against a real uvicorn server: they hold receiving places, never the models.

The server takes one request in flight, 20 bodies arriving at once, and 3 s to receive a body; a token is
set and ``ORPOSE_PUBLIC_DOCS`` makes the docs public. Slow clients are raw sockets that send a request's head
and then trickle its body a byte at a time.
"""

from __future__ import annotations

import time

import httpx
import pytest
from conftest import write_tiny_mvor
from service_harness import Server, Tricklers, form_kwargs, tiny_checkpoints

from posenet.data.mvor import MvorDataset
from service.client import scene_request

TOKEN = "tok"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
MAX_RECEIVING = 20


@pytest.fixture(scope="module")
def frame(tmp_path_factory):
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny_mvor"), days=(1,), frames_per_day=1)
    return form_kwargs(*scene_request(MvorDataset(None, data.gt)[0], data.root, True))


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    pose, _ = tiny_checkpoints(tmp_path_factory.mktemp("ckpt"), detector=False)
    env = {
        "ORPOSE_POSE_CHECKPOINT": str(pose),
        "ORPOSE_LOAD_DETECTOR": "false",
        "ORPOSE_TOKEN": TOKEN,
        "ORPOSE_PUBLIC_DOCS": "true",
        "ORPOSE_MAX_IN_FLIGHT": "1",
        "ORPOSE_MAX_RECEIVING": str(MAX_RECEIVING),
        "ORPOSE_BODY_TIMEOUT_S": "3",
    }
    with Server(env) as url, httpx.Client(base_url=url, headers=AUTH, timeout=60) as client:
        yield client


def test_sixteen_slow_uploads_do_not_delay_a_valid_request(server, frame):
    slow = Tricklers(server.base_url, 16, TOKEN)
    try:
        t0 = time.monotonic()
        r = server.post("/scenes", **frame)
        elapsed = time.monotonic() - t0
        assert r.status_code == 200, r.text
        assert elapsed < 2.0, f"{elapsed:.2f} s"
    finally:
        slow.close()


def test_receiving_places_are_bounded_and_given_back(server, frame):
    slow = Tricklers(server.base_url, MAX_RECEIVING, TOKEN)
    try:
        r = server.post("/scenes", **frame)
        assert r.status_code == 503 and r.headers["retry-after"] == "1", r.text
        assert "ORPOSE_MAX_RECEIVING" in r.json()["detail"]
    finally:
        slow.close()
    t0 = time.monotonic()  # the server notices the closed connections and frees their places
    while (r := server.post("/scenes", **frame)).status_code == 503 and time.monotonic() - t0 < 5:
        time.sleep(0.05)
    assert r.status_code == 200, r.text


def test_public_docs_setting_serves_the_docs_without_the_token(server):
    for path in ("/docs", "/redoc", "/openapi.json", "/docs/oauth2-redirect"):
        assert server.get(path, headers={"Authorization": ""}).status_code == 200, path
    assert server.get("/ready", headers={"Authorization": ""}).status_code == 401  # the API still needs it
