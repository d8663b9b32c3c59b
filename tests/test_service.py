"""End-to-end tests of the service: a real uvicorn process on localhost, real HTTP, tiny random-init models.

One server serves the whole module, configured tightly so that every limit can be reached: a token, one
request in flight, a 2 s body timeout, 4 views at most and an 8 MB body cap. Frames come from the tiny
MVOR-format dataset (``conftest.write_tiny_mvor``) and are sent exactly as the batch client sends them.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import time

import cv2
import httpx
import numpy as np
import pytest
from conftest import write_tiny_mvor
from service_harness import REPO_ROOT, Server, tiny_checkpoints

from posenet.data.mvor import MvorDataset
from posenet.skeleton import JOINTS
from service.client import scene_request

TOKEN = "s3cret"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
MAX_BODY = 8 * 2**20


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny_mvor"), days=(1,), frames_per_day=2)
    return data, MvorDataset(None, data.gt)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    pose, det = tiny_checkpoints(tmp_path_factory.mktemp("ckpt"))
    env = {
        "ORPOSE_POSE_CHECKPOINT": str(pose),
        "ORPOSE_DETECTOR_CHECKPOINT": str(det),
        "ORPOSE_TOKEN": TOKEN,
        "ORPOSE_MAX_IN_FLIGHT": "1",
        "ORPOSE_BODY_TIMEOUT_S": "2",
        "ORPOSE_MAX_VIEWS": "4",
        "ORPOSE_MAX_BODY_BYTES": str(MAX_BODY),
    }
    srv = Server(env)
    with srv as url, httpx.Client(base_url=url, headers=AUTH, timeout=60) as client:
        client.server_log = srv.log  # the server's stdout and stderr, for checks that it logged no traceback
        yield client


def post(client, scene: dict, files: list, **kw) -> httpx.Response:
    return client.post("/scenes", data={"scene": json.dumps(scene)}, files=files, **kw)


def frame(tiny, index=0, reference_boxes=True):
    data, ds = tiny
    return scene_request(ds[index], data.root, reference_boxes)


def check_person_shape(person: dict, width=640, height=480) -> None:
    assert [j["name"] for j in person["joints"]] == list(JOINTS)
    assert np.isfinite([j["position"] for j in person["joints"]]).all()
    assert all(j["confidence"] >= 0 for j in person["joints"])
    for support in person["views"]:
        x0, y0, x1, y1 = support["box"]
        assert 0 <= x0 < x1 <= width - 1 and 0 <= y0 < y1 <= height - 1


# ----------------------------------------------------------------------------------------------- routes
def test_health_ready_model_and_token(server):
    bare = {"Authorization": ""}
    assert server.get("/health", headers=bare).json() == {"status": "ok"}  # /health never needs the token
    assert server.get("/ready", headers=bare).status_code == 401
    assert server.get("/ready", headers={"Authorization": "Bearer wrong"}).status_code == 401
    r = server.get("/ready")
    assert r.status_code == 200 and r.json() == {"ready": True}
    info = server.get("/model").json()
    assert info["joints"] == list(JOINTS) and info["modalities"] == ["color", "depth"]
    assert info["detector_loaded"] and "random" in info["pose_trained_on"]
    r = server.post("/scenes", headers=bare, files={"depth_0": b"x"})
    assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    schema = server.get("/openapi.json").json()
    assert "in mm in the reference frame" in json.dumps(schema["components"]["schemas"]["Joint"])
    undocumented = [
        f"{name}.{prop}"
        for name, model in schema["components"]["schemas"].items()
        for prop, field in model.get("properties", {}).items()
        if "description" not in field
    ]
    assert undocumented == [], "every field of the API says what it means"


def test_reference_box_mode_gives_each_annotated_person(server, tiny):
    data, ds = tiny
    sample = ds[0]
    scene, files = frame(tiny)
    r = post(server, scene, files)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["mode"] == "reference_boxes" and out["timings"]["detect"] == 0
    assert out["timings"]["pose"] > 0 and out["timings"]["total"] >= out["timings"]["pose"]
    assert sorted(p["id"] for p in out["persons"]) == sorted(sample.person_ids.tolist())
    for person in out["persons"]:
        check_person_shape(person)
        sent = sample.person_boxes(person["id"])
        assert [s["view"] for s in person["views"]] == [v for v, b in enumerate(sent) if b is not None]
        for s in person["views"]:
            np.testing.assert_allclose(s["box"], sent[s["view"]], atol=1e-3)
            assert s["score"] is None
        # Joints are softmax-weighted means of points lifted from this person's boxes, so even with random
        # weights they lie near the person (the dataset paints each box at the person's depth).
        truth = sample.poses[list(sample.person_ids).index(person["id"])]
        joints = np.array([j["position"] for j in person["joints"]])
        assert np.linalg.norm(joints - truth.mean(0), axis=1).max() < 1000.0

    # Without ids the boxes are grouped by the 3D matcher: the same persons, by their supporting views.
    for view in scene["views"]:
        del view["person_ids"]
    matched = post(server, scene, files).json()["persons"]
    assert sorted(tuple(s["view"] for s in p["views"]) for p in matched) == sorted(
        tuple(s["view"] for s in p["views"]) for p in out["persons"]
    )


def test_detector_mode(server, tiny):
    scene, files = frame(tiny, reference_boxes=False)
    r = post(server, scene, files)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["mode"] == "detector" and out["timings"]["detect"] > 0
    for person in out["persons"]:
        check_person_shape(person)
        assert all(0 <= s["score"] <= 1 for s in person["views"])


# ----------------------------------------------------------------------------------------------- bad input
def _png(image) -> bytes:
    return cv2.imencode(".png", image)[1].tobytes()


def bad_requests(tiny):
    """(name, request kwargs, status, words in the message): every bad input of the issue."""
    scene, files = frame(tiny)
    parts = dict(files)

    def with_parts(**replace):
        return [(k, v) for k, v in {**parts, **replace}.items() if v is not None]

    def with_camera(**camera):
        s = json.loads(json.dumps(scene))
        s["views"][1]["camera"].update(camera)
        return s

    def form(s=scene, f=None, **kw):
        return {"data": {"scene": s if isinstance(s, str) else json.dumps(s)}, "files": f or files, **kw}

    def with_boxes(boxes):
        s = json.loads(json.dumps(scene))
        s["views"][1].update(boxes=boxes, person_ids=list(range(len(boxes))))
        return s

    eye = np.eye(4).tolist()
    depth8 = ("d.png", _png(np.zeros((480, 640), np.uint8)))
    small = ("d.png", _png(np.ones((240, 320), np.uint16)))
    nan = json.dumps(with_camera()).replace("-0.9827532061654909", "NaN")
    return [
        ("json body", {"json": scene}, 415, "multipart/form-data"),
        ("missing scene", {"files": files}, 422, "missing form part 'scene'"),
        ("invalid scene json", form("{"), 422, "scene JSON is invalid"),
        ("0 views", form({"views": []}, [("x", b"")]), 422, "0 views"),
        ("too many views", form({"views": scene["views"] * 2}), 422, "6 views"),
        ("missing depth", form(f=with_parts(depth_2=None)), 422, "missing file part depth_2"),
        ("missing colour", form(f=with_parts(color_0=None)), 422, "missing file part color_0"),
        ("corrupt colour", form(f=with_parts(color_1=("c.png", parts["color_1"][1][:500]))), 422, "color_1"),
        ("not an image", form(f=with_parts(color_1=("c.gif", b"GIF89a"))), 415, "neither a PNG nor a JPEG"),
        ("image as a text field", {"data": {"scene": json.dumps(scene), "depth_0": "abc"},
                                   "files": with_parts(depth_0=None)}, 422, "must be a file part"),
        ("8-bit depth", form(f=with_parts(depth_0=depth8)), 422, "8-bit"),
        ("colour/depth sizes", form(f=with_parts(depth_1=small)), 422, "colour and depth"),
        ("image vs intrinsics", form(with_camera(image_size=[320, 240])), 422, "image_size is 320x240"),
        ("principal point", form(with_camera(cx=900.0, image_size=None)), 422, "principal point"),
        ("NaN extrinsics", form(nan), 422, "finite number"),
        ("non-rigid extrinsics", form(with_camera(extrinsics=[[2 * x for x in row] for row in eye])), 422,
         "not a rigid"),
        ("box outside", form(with_boxes([[700.0, 10.0, 800.0, 50.0]])), 422, "outside the 640x480"),
        ("multipart without boundary", {"content": b"--x\r\n", "headers": {
            **AUTH, "content-type": "multipart/form-data"}}, 400, "boundary"),
    ]  # fmt: skip


def test_every_bad_input_gets_its_4xx(server, tiny):
    for name, kwargs, status, words in bad_requests(tiny):
        r = server.post("/scenes", **kwargs)
        assert r.status_code == status, f"{name}: {r.status_code} {r.text}"
        if status != 200:
            assert words in r.json()["detail"], f"{name}: {r.json()['detail']}"


def raw_head(server, length: int) -> socket.socket:
    """Open a connection and send only the head of a /scenes request declaring ``length`` body bytes."""
    host, port = server.base_url.host, server.base_url.port
    sock = socket.create_connection((host, port))
    sock.settimeout(10)
    sock.sendall(
        f"POST /scenes HTTP/1.1\r\nHost: {host}\r\nAuthorization: Bearer {TOKEN}\r\n"
        f"Content-Type: multipart/form-data; boundary=x\r\nContent-Length: {length}\r\n\r\n--x\r\n".encode()
    )
    return sock


def test_declared_oversized_body_is_refused_before_reading(server):
    with raw_head(server, MAX_BODY + 1) as sock:
        answer = b""
        while chunk := sock.recv(4096):  # the server closes the connection after its answer
            answer += chunk
    assert answer.startswith(b"HTTP/1.1 413") and b"exceeds the limit" in answer


def test_streamed_oversized_body_is_cut_off(server):
    # No Content-Length (chunked): the cap is enforced while the body streams in, not after it has all
    # arrived.
    def chunks():
        yield b'--x\r\nContent-Disposition: form-data; name="depth_0"; filename="d.png"\r\n\r\n'
        for _ in range(MAX_BODY // 2**20 + 2):
            yield b"\0" * 2**20

    r = server.post("/scenes", content=chunks(), headers={"content-type": "multipart/form-data; boundary=x"})
    assert r.status_code == 413 and "exceeds the limit" in r.json()["detail"]


def test_overload_gets_503_and_a_slow_body_408(server, tiny):
    # A client that sends its headers and then stalls holds the only in-flight slot...
    slow = raw_head(server, 100_000)
    try:
        time.sleep(0.5)
        # ... so another request is turned away at once with Retry-After, not queued.
        scene, files = frame(tiny)
        t0 = time.monotonic()
        r = post(server, scene, files)
        assert r.status_code == 503 and int(r.headers["retry-after"]) >= 1, r.text
        assert time.monotonic() - t0 < 1.5
        # The stalled body times out (ORPOSE_BODY_TIMEOUT_S=2) with a 408, which frees the slot.
        assert slow.recv(4096).startswith(b"HTTP/1.1 408")
    finally:
        slow.close()
    assert post(server, scene, files).status_code == 200


@pytest.mark.skipif(shutil.which("curl") is None, reason="the example script needs curl on PATH")
@pytest.mark.parametrize("scene", ["scene.json", "scene_boxes.json"])
def test_example_frame_and_curl_script(server, scene):
    env = {**os.environ, "URL": str(server.base_url).rstrip("/"), "ORPOSE_TOKEN": TOKEN}
    run = subprocess.run(
        ["bash", str(REPO_ROOT / "examples" / "curl.sh"), scene],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    out = json.loads(run.stdout)
    assert out["mode"] == ("reference_boxes" if scene == "scene_boxes.json" else "detector")
    for person in out["persons"]:
        check_person_shape(person)
    if scene == "scene_boxes.json":
        truth = json.loads((REPO_ROOT / "examples" / "frame" / "truth.json").read_text())
        assert [p["id"] for p in out["persons"]] == truth["person_ids"]


def test_client_disconnect_mid_body_is_harmless(server, tiny):
    with raw_head(server, 100_000) as sock:
        sock.sendall(
            b'Content-Disposition: form-data; name="depth_0"; filename="d.png"\r\n\r\n' + b"\0" * 1000
        )
    time.sleep(0.5)
    scene, files = frame(tiny)
    assert post(server, scene, files).status_code == 200
    server.server_log.seek(0)
    log = server.server_log.read()
    assert "Traceback" not in log and "Exception" not in log, log[-3000:]
