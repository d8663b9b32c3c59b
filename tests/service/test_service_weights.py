"""The shipped weights through the real service: the example frame's skeleton lies near its truth.

Runs only once the default weights are in the package (``posenet/weights/default.safetensors``, and for the
detector-mode check ``detector/weights/default.safetensors``); until then it skips and says why.
"""

from __future__ import annotations

import json

import httpx
import numpy as np
import pytest
from service_harness import REPO_ROOT, Server

from detector.infer import DEFAULT_WEIGHTS as DETECTOR_WEIGHTS
from posenet.net.checkpoint import DEFAULT_WEIGHTS as POSE_WEIGHTS

FRAME = REPO_ROOT / "examples" / "frame"
# A held-out (day-4) MVOR-twin frame; the shipped weights are about 4 cm off on it and 6.8 cm on all of day 4.
MAX_MPJPE_MM = 100.0

pytestmark = pytest.mark.skipif(
    not POSE_WEIGHTS.is_file(), reason=f"no shipped pose weights at {POSE_WEIGHTS} yet"
)


def post_example(client: httpx.Client, scene_file: str) -> dict:
    files = [(f"{kind}_{v}", open(FRAME / f"{kind}_{v}.{ext}", "rb"))
             for v in range(3) for kind, ext in (("color", "jpg"), ("depth", "png"))]  # fmt: skip
    try:
        r = client.post("/scenes", data={"scene": (FRAME / scene_file).read_text()}, files=files)
    finally:
        for _, f in files:
            f.close()
    assert r.status_code == 200, r.text
    return r.json()


def test_example_frame_skeleton_is_near_the_truth():
    truth = json.loads((FRAME / "truth.json").read_text())
    gt = dict(zip(truth["person_ids"], np.asarray(truth["joints_mm"]), strict=True))
    with_detector = DETECTOR_WEIGHTS.is_file()
    env = {"ORPOSE_LOAD_DETECTOR": str(with_detector).lower()}
    with Server(env) as url, httpx.Client(base_url=url, timeout=120) as client:
        out = post_example(client, "scene_boxes.json")
        assert [p["id"] for p in out["persons"]] == list(gt)
        for person in out["persons"]:
            joints = np.array([j["position"] for j in person["joints"]])
            mpjpe = np.linalg.norm(joints - gt[person["id"]], axis=1).mean()
            assert mpjpe < MAX_MPJPE_MM, f"person {person['id']}: MPJPE {mpjpe:.0f} mm"
        if with_detector:
            # Detector mode finds the annotated person too: some returned skeleton lies near its truth.
            out = post_example(client, "scene.json")
            errors = [np.linalg.norm(np.array([j["position"] for j in p["joints"]]) - gt[0], axis=1).mean()
                      for p in out["persons"]]  # fmt: skip
            assert errors and min(errors) < MAX_MPJPE_MM, (
                f"detector mode: best MPJPE {min(errors or [np.inf]):.0f} mm"
            )


DEPTH_POSE = POSE_WEIGHTS.with_name("depth.safetensors")
DEPTH_DETECTOR = DETECTOR_WEIGHTS.with_name("depth.safetensors")


@pytest.mark.skipif(
    not (DEPTH_POSE.is_file() and DEPTH_DETECTOR.is_file()), reason="no shipped depth-only weights yet"
)
def test_depth_only_weights_answer_the_example_frame_without_colour():
    """The shipped colourless pair: the example frame sent without any colour part, in detector mode and with
    reference boxes, gives the annotated person's skeleton near its truth."""
    truth = json.loads((FRAME / "truth.json").read_text())
    gt = dict(zip(truth["person_ids"], np.asarray(truth["joints_mm"]), strict=True))
    env = {"ORPOSE_POSE_CHECKPOINT": str(DEPTH_POSE), "ORPOSE_DETECTOR_CHECKPOINT": str(DEPTH_DETECTOR)}
    with Server(env) as url, httpx.Client(base_url=url, timeout=120) as client:
        info = client.get("/model").json()
        assert info["modalities"] == info["detector_modalities"] == ["depth"]
        for scene_file in ("scene_boxes.json", "scene.json"):
            files = [(f"depth_{v}", (FRAME / f"depth_{v}.png").read_bytes()) for v in range(3)]
            r = client.post("/scenes", data={"scene": (FRAME / scene_file).read_text()}, files=files)
            assert r.status_code == 200, r.text
            errors = [np.linalg.norm(np.array([j["position"] for j in p["joints"]]) - gt[0], axis=1).mean()
                      for p in r.json()["persons"]]  # fmt: skip
            assert errors and min(errors) < MAX_MPJPE_MM, (
                f"{scene_file}: best MPJPE {min(errors or [np.inf]):.0f} mm"
            )
