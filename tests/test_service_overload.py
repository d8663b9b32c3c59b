"""Slow uploads against a real uvicorn server: they hold receiving places, never the models.

The server takes one request in flight, 20 bodies arriving at once, and 3 s to receive a body; a token is
set and ``ORPOSE_PUBLIC_DOCS`` makes the docs public. Slow clients are raw sockets that send a request's head
and then trickle its body a byte at a time.
"""

from __future__ import annotations

import socket
import threading
import time

import httpx
import pytest
from conftest import write_tiny_mvor
from service_harness import Server, form_kwargs, tiny_checkpoints

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


class Tricklers:
    """``n`` connections that each send a /scenes head and then one body byte every ``every_s`` seconds."""

    def __init__(self, client: httpx.Client, n: int, every_s: float = 0.1) -> None:
        host, port = client.base_url.host, client.base_url.port
        self.socks = []
        for _ in range(n):
            sock = socket.create_connection((host, port))
            sock.sendall(
                f"POST /scenes HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {TOKEN}\r\n"
                "Content-Type: multipart/form-data; boundary=x\r\nContent-Length: 100000\r\n\r\n--x\r\n".encode()
            )
            self.socks.append(sock)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._trickle, args=(every_s,), daemon=True)
        self.thread.start()
        time.sleep(0.3)  # every head has been read and its route is waiting for the body

    def _trickle(self, every_s: float) -> None:
        while not self.stop.wait(every_s):
            for sock in self.socks:
                try:
                    sock.sendall(b"x")
                except OSError:
                    pass

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for sock in self.socks:
            sock.close()


def test_sixteen_slow_uploads_do_not_delay_a_valid_request(server, frame):
    slow = Tricklers(server, 16)
    try:
        t0 = time.monotonic()
        r = server.post("/scenes", **frame)
        elapsed = time.monotonic() - t0
        assert r.status_code == 200, r.text
        assert elapsed < 2.0, f"{elapsed:.2f} s"
    finally:
        slow.close()


def test_receiving_places_are_bounded_and_given_back(server, frame):
    slow = Tricklers(server, MAX_RECEIVING)
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
