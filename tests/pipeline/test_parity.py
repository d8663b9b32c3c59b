"""Parity of the two ways to run the pose network on a dataset frame: offline (``python -m posenet.evaluation.predict``) and
served (a real ``uvicorn service.app:app`` over HTTP, reference boxes). The same frames, sent at their full
resolution, must give the same joints to 0.1 mm. Both run the U-Net on torch (``ORPOSE_BACKEND=torch``) in
float32, so the only way they can differ is in what they feed the network: above all the resolution the views
are read at, which the model config records once (``InputConfig.read_size``).
"""

from __future__ import annotations

import dataclasses
import json

import httpx
import numpy as np
import pytest
import torch
from conftest import write_tiny_mvor
from service_harness import Server, form_kwargs

from posenet.data.mvor import MvorDataset
from posenet.evaluation import predict
from posenet.net.checkpoint import DEFAULT_WEIGHTS, save_checkpoint
from posenet.net.inputs import InputConfig, record_read_size, reduction
from posenet.net.model import ModelConfig, PoseNet
from service.client import scene_request

TOLERANCE_MM = 0.1


def _checkpoint(folder, case: str):
    """The checkpoint of a case: None for the shipped weights, else a tiny random-init one."""
    if case == "shipped":
        if not DEFAULT_WEIGHTS.is_file():
            pytest.skip(f"no shipped weights at {DEFAULT_WEIGHTS}")
        return None
    torch.manual_seed(0)
    # "half": crops from views reduced to 320x240 (the shipped weights' setting). "legacy": a config that
    # records no read size beside a training reader that subsampled by 2, as checkpoints before issue 13 did.
    # "flip": "half" with heatmaps 30x sharper, so that the mirrored pass moves the joints by millimetres.
    inputs = InputConfig(source_size=(320, 240)) if case in ("half", "flip") else InputConfig()
    cfg = ModelConfig(inputs=inputs, precision="fp32")
    model = PoseNet(cfg)
    if case == "flip":
        with torch.no_grad():
            model.unet.head.weight.mul_(30.0)
    save_checkpoint(folder, model, {"model": dataclasses.asdict(cfg), "subsample": 2})
    return folder


def _served(url: str, data) -> dict[tuple[str, int], np.ndarray]:
    ds = MvorDataset(data.root, data.gt, modalities=())  # full resolution: the files are sent as they are
    out = {}
    with httpx.Client(base_url=url, timeout=120.0) as client:
        for sample in ds:
            scene, files = scene_request(sample, data.root, reference_boxes=True)
            r = client.post("/scenes", **form_kwargs(scene, files))
            assert r.status_code == 200, r.text
            body = r.json()
            assert body["mode"] == "reference_boxes"
            for person in body["persons"]:
                xyz = [joint["position"] for joint in person["joints"]]
                out[(sample.id, int(person["id"]))] = np.asarray(xyz, np.float64)
    return out


@pytest.mark.parametrize("case", ["half", "legacy", "shipped", "flip"])
def test_offline_and_served_joints_agree(tmp_path, case):
    """"flip": a tiny checkpoint with the mirrored pass asked for on both sides (``predict --flip-test``,
    ``ORPOSE_FLIP_TEST``), which must change the joints."""
    data = write_tiny_mvor(tmp_path / "tiny", days=(1,), frames_per_day=2)
    ckpt = _checkpoint(tmp_path / "pose", case)

    def offline_joints(*extra: str) -> dict:
        out = tmp_path / "pred.json"
        argv = ["--data", str(data.root), "--annotations", str(data.annotations), "--out", str(out)]
        argv += [] if ckpt is None else ["--checkpoint", str(ckpt)]
        assert predict.main([*argv, "--threads", "1", "--precision", "fp32", *extra]) == 0
        return {
            (p["image_ids"], p["person_id"]): np.reshape(p["keypoints3D"], (-1, 3))
            for p in json.loads(out.read_text())
        }

    offline = offline_joints(*(["--flip-test"] if case == "flip" else []))

    env = {"ORPOSE_BACKEND": "torch", "ORPOSE_PRECISION": "fp32", "ORPOSE_LOAD_DETECTOR": "false"}
    if ckpt is not None:
        env["ORPOSE_POSE_CHECKPOINT"] = str(ckpt)
    if case == "flip":
        env["ORPOSE_FLIP_TEST"] = "true"
    with Server(env) as url:
        served = _served(url, data)

    assert len(offline) >= 4 and set(served) == set(offline)
    if case == "flip":
        plain = offline_joints()
        assert max(float(np.abs(served[k] - plain[k]).max()) for k in plain) > 10 * TOLERANCE_MM
    worst = max(float(np.abs(served[k] - offline[k]).max()) for k in offline)
    assert worst <= TOLERANCE_MM, f"offline and served joints differ by up to {worst:.3f} mm"


def test_training_records_the_resolution_it_reads():
    legacy = InputConfig()  # crop mode without a read size: training records its reader's
    record_read_size(legacy, (640, 480), 2)
    assert legacy.read_size == (320, 240) and reduction(640, 480, legacy.read_size) == 2
    shipped = InputConfig(source_size=(320, 240))
    record_read_size(shipped, (640, 480), 2)  # agrees: nothing to record
    assert shipped.read_size == (320, 240)
    with pytest.raises(ValueError, match="use subsample 2"):
        record_read_size(shipped, (640, 480), 4)  # would train on 160x120 views that serving never sends
    full = InputConfig(mode="full")
    assert full.read_size == full.image_size
    with pytest.raises(ValueError, match="use subsample 2"):
        record_read_size(full, (640, 480), 1)
