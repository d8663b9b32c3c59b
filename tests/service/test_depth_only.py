"""The colourless path end to end: a server whose detector and pose network read depth alone answers frames that
carry no colour image, in detector mode too, and says so in ``GET /model``; the batch client sends such frames with
``--color-format none``. A real uvicorn process, real HTTP, tiny random-init depth-only models."""

from __future__ import annotations

import json

import httpx
import pytest
from conftest import write_tiny_mvor
from service_harness import Server, tiny_checkpoints

from posenet.data.mvor import MvorDataset
from service.client import Transport, main, scene_request


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny_mvor"), days=(1,), frames_per_day=2)
    return data, MvorDataset(None, data.gt)


@pytest.fixture(scope="module")
def depth_server(tmp_path_factory):
    pose, det = tiny_checkpoints(tmp_path_factory.mktemp("ckpt"), depth_only=True)
    env = {
        "ORPOSE_POSE_CHECKPOINT": str(pose),
        "ORPOSE_DETECTOR_CHECKPOINT": str(det),
        "ORPOSE_MATCHER": "centres",
    }
    with Server(env) as url, httpx.Client(base_url=url, timeout=60) as client:
        yield client


def test_model_says_what_each_network_reads(depth_server):
    info = depth_server.get("/model").json()
    assert info["modalities"] == ["depth"] and info["detector_modalities"] == ["depth"]


@pytest.mark.parametrize("reference_boxes", [False, True])
def test_frames_without_colour_are_answered(depth_server, tiny, reference_boxes):
    data, ds = tiny
    scene, files = scene_request(ds[0], data.root, reference_boxes, Transport(color="none"))
    assert not any(name.startswith("color_") for name, _ in files)
    r = depth_server.post("/scenes", data={"scene": json.dumps(scene)}, files=files)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["mode"] == ("reference_boxes" if reference_boxes else "detector")
    if not reference_boxes:
        assert out["timings"]["detect"] > 0


def test_the_batch_client_sends_depth_only(depth_server, tiny, tmp_path):
    data, _ = tiny
    out = tmp_path / "pred.jsonl"
    url = str(depth_server.base_url)
    args = [
        str(data.root),
        "--annotations",
        str(data.annotations),
        "--url",
        url,
        "--out",
        str(out),
        "--color-format",
        "none",
    ]
    assert main(args) == 0
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(lines) == 2 and all(line["status"] == 200 for line in lines), lines
    assert all(line["response"]["mode"] == "detector" for line in lines)


def test_a_colour_server_names_what_needs_colour(tmp_path, tiny):
    """The default models read colour: a colourless frame without boxes gets a 422 that says why."""
    data, ds = tiny
    pose, det = tiny_checkpoints(tmp_path)
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(det)}
    scene, files = scene_request(ds[0], data.root, False, Transport(color="none"))
    with Server(env) as url, httpx.Client(base_url=url, timeout=60) as client:
        assert client.get("/model").json()["detector_modalities"] == ["color"]
        r = client.post("/scenes", data={"scene": json.dumps(scene)}, files=files)
    assert r.status_code == 422 and "missing file part color_0" in r.json()["detail"], r.text


def test_send_size_read_sends_as_recorded_where_the_server_reads_views_as_sent(
    depth_server, tiny, tmp_path, capsys
):
    """These tiny models have no read size (GET /model's read_size is null): --send-size read says so and sends
    the views as recorded."""
    data, _ = tiny
    assert depth_server.get("/model").json()["read_size"] is None
    out = tmp_path / "pred.jsonl"
    args = [str(data.root), "--annotations", str(data.annotations), "--url", str(depth_server.base_url)]
    assert main([*args, "--out", str(out), "--color-format", "none", "--send-size", "read"]) == 0
    assert "the server reads views as sent" in capsys.readouterr().out
    assert all(json.loads(line)["status"] == 200 for line in out.read_text().splitlines())
