"""The recording-folder reader (rig.json + per-camera colour/depth folders, no annotations) and the batch client's
use of it: samples, frame matching across cameras, subsampling, errors, and requests the service accepts."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
from conftest import MVOR_CAMERAS_INFO

from posenet.data.recording import RecordingDataset
from posenet.data.sample import Sample
from posenet.rig.__main__ import main as rig_main
from service import client
from service.schemas import SceneIn

W, H = 160, 120


@pytest.fixture
def recording(tmp_path):
    """3 cameras (MVOR's rig at quarter size), frames 000000..000002; camera 3 lacks frame 000002's depth."""
    root = tmp_path / "rec"
    root.mkdir()
    (tmp_path / "mvor.json").write_text(json.dumps({"cameras_info": MVOR_CAMERAS_INFO}))
    assert (
        rig_main(["convert", "--from", "mvor", str(tmp_path / "mvor.json"), "--out", str(root / "rig.json")])
        == 0
    )
    rig = json.loads((root / "rig.json").read_text())
    for cam in rig:  # the images are 160x120: scale the calibration the way Camera.scale does
        for k in ("fx", "fy"):
            cam[k] *= 0.25
        for k in ("cx", "cy"):
            cam[k] = (cam[k] + 0.5) * 0.25 - 0.5
        cam["image_size"] = [W, H]
    (root / "rig.json").write_text(json.dumps(rig))
    for c in (1, 2, 10):  # natural order: cam10 is the third camera
        for f in range(3):
            for kind, image in (
                ("color", np.full((H, W, 3), 20 * c, np.uint8)),
                ("depth", np.full((H, W), 2000 + c, np.uint16)),
            ):
                if c == 10 and f == 2 and kind == "depth":
                    continue
                path = root / f"cam{c}/{kind}/{f:06d}.png"
                path.parent.mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(path), image)
    return root


def test_recording_samples(recording):
    ds = RecordingDataset(recording)
    assert ds.camera_folders == ["cam1", "cam2", "cam10"] and ds.ids == ["000000", "000001"]
    assert "1 frames missing from some camera were left out" in ds.report[0]
    sample = ds[1]
    assert isinstance(sample, Sample) and len(sample.views) == 3 and len(sample.poses) == 0
    for v, view in enumerate(sample.views):
        assert view.color.shape == (H, W, 3) and view.depth.dtype == np.uint16 and len(view.boxes) == 0
        assert view.file_name == f"{ds.camera_folders[v]}/color/000001.png" and view.camera.size == (W, H)
    assert int(sample.views[2].depth[0, 0]) == 2010
    torch.testing.assert_close(sample.views[0].camera.extrinsics, torch.eye(4, dtype=torch.float64))
    half = RecordingDataset(recording, subsample=2)[0]
    assert half.views[1].color.shape == (H // 2, W // 2, 3)
    torch.testing.assert_close(half.views[1].camera.intrinsics, sample.views[1].camera.scale(0.5).intrinsics)


def test_recording_errors(recording):
    with pytest.raises(ValueError, match=r"2 camera folders .* but the rig has 3 cameras"):
        RecordingDataset(recording, cameras=["cam1", "cam2"])
    cv2.imwrite(str(recording / "cam2/color/000000.png"), np.zeros((60, 80, 3), np.uint8))
    with pytest.raises(
        ValueError, match=r"cam2/color/000000\.png is 80x60 pixels, but the annotations say 160x120"
    ):
        RecordingDataset(recording)[0]
    with pytest.raises(FileNotFoundError, match="rig file .* does not exist"):
        RecordingDataset(recording, rig=recording / "nope.json")


def test_client_posts_a_recording_as_the_service_expects(recording, monkeypatch):
    ds = RecordingDataset(recording, modalities=())
    scene, files = client.scene_request(ds[0], recording, reference_boxes=False)
    from service.validation import Limits, validate_scene

    # The request passes the service's schema and its validation of cameras against the decoded images.
    checked = validate_scene(
        SceneIn.model_validate(scene), {k: v[1] for k, v in files}, Limits(), need_color=True
    )
    assert [v.depth.shape for v in checked.views] == [(H, W)] * 3 and checked.boxes is None
    torch.testing.assert_close(checked.views[2].camera.extrinsics, ds[0].views[2].camera.extrinsics)
    assert [name for name, _ in files] == ["color_0", "depth_0", "color_1", "depth_1", "color_2", "depth_2"]
    assert files[5][1][1] == (recording / "cam10/depth/000000.png").read_bytes()
    seen = {}

    def fake_run(dataset, root, out, cfg, sequences=None):
        seen.update(ids=dataset.ids, root=root)
        return {
            "frames": len(dataset),
            "already_done": 0,
            "ok": len(dataset),
            "rejected": 0,
            "gave_up": 0,
            "seconds": 1.0,
        }

    monkeypatch.setattr(client, "run", fake_run)
    assert client.main([str(recording), "--out", str(recording / "out.jsonl")]) == 0
    assert seen == {"ids": ["000000", "000001"], "root": recording}
    with pytest.raises(SystemExit, match="need --annotations"):
        client.main([str(recording), "--out", "x.jsonl", "--evaluate"])
