"""Views sent at the size the networks read (``service.client --send-size read``): a real uvicorn process with
tiny random-init models that read 320x240, and the tiny 640x480 MVOR-format dataset. The server answers the
reduced frames as it answers the recorded ones, bit for bit, in the calibrated pixels."""

from __future__ import annotations

import json

import httpx
import pytest
from conftest import write_tiny_mvor
from service_harness import Server, tiny_checkpoints

from service.client import main


def _answers(path) -> dict[str, dict]:
    out = {}
    for line in path.read_text().splitlines():
        x = json.loads(line)
        assert x["status"] == 200, x
        response = x["response"]
        out[x["id"]] = {"mode": response["mode"], "persons": response["persons"], "notes": response["notes"]}
    return out


@pytest.mark.slow
@pytest.mark.parametrize("reference_boxes", [False, True])
def test_views_sent_at_the_read_size_get_the_same_answers(tmp_path, reference_boxes):
    data = write_tiny_mvor(tmp_path / "tiny", days=(1,), frames_per_day=2)
    pose, det = tiny_checkpoints(tmp_path / "ckpt", read_size=(320, 240))
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(det)}
    extra = ["--reference-boxes"] if reference_boxes else []
    with Server(env) as url:
        assert httpx.get(f"{url}/model").json()["read_size"] == [320, 240]
        for size in ("recorded", "read"):
            args = [str(data.root), "--annotations", str(data.annotations), "--url", url]
            assert main([*args, "--out", str(tmp_path / f"{size}.jsonl"), "--send-size", size, *extra]) == 0
    recorded, read = _answers(tmp_path / "recorded.jsonl"), _answers(tmp_path / "read.jsonl")
    assert recorded == read and len(read) == 2
    assert any(r["persons"] for r in read.values())
    boxes = [s["box"] for r in read.values() for p in r["persons"] for s in p["views"]]
    assert max(b[2] for b in boxes) > 320 or max(b[3] for b in boxes) > 240  # the calibrated 640x480 pixels
