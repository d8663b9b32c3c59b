"""Decoding at the resolution the models read: the same pixels as the reader's subsampling, and every
coordinate of the API still in the pixels of the images as sent."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from pipeline.two_stage import PersonResult, SceneResult
from posenet.boxes import PersonBoxes
from posenet.data.images import subsample_color, subsample_depth
from posenet.net.inputs import reduction
from service.decode import decode_color, decode_depth
from service.errors import InputError
from service.response import _sent_boxes
from service.validation import Limits, parse_scene, validate_scene

FRAME = Path(__file__).resolve().parents[2] / "examples" / "frame"


def _files(color_format: str = "jpg") -> dict[str, bytes]:
    files = {}
    for i in range(3):
        color = (FRAME / f"color_{i}.jpg").read_bytes()
        if color_format == "png":
            bgr = cv2.imdecode(np.frombuffer(color, np.uint8), cv2.IMREAD_COLOR)
            color = cv2.imencode(".png", bgr)[1].tobytes()
        files[f"color_{i}"] = color
        files[f"depth_{i}"] = (FRAME / f"depth_{i}.png").read_bytes()
    return files


def test_reduction_factor():
    assert reduction(640, 480, (320, 240)) == 2 and reduction(1280, 960, (320, 240)) == 4
    assert reduction(640, 480, None) == 1 and reduction(641, 480, (320, 240)) == 1
    assert reduction(320, 240, (320, 240)) == 1 and reduction(640, 480, (400, 240)) == 1


def test_reduced_decoding_is_the_readers_subsampling():
    files = _files("png")
    full = decode_color(files["color_0"])
    np.testing.assert_array_equal(decode_color(files["color_0"], reduce=2), subsample_color(full, 2))
    depth = decode_depth(files["depth_0"])
    np.testing.assert_array_equal(decode_depth(files["depth_0"], reduce=2), subsample_depth(depth, 2))
    # A JPEG is decoded at half size by libjpeg's DCT scaling: close to the block mean, not equal.
    jpeg = _files("jpg")["color_0"]
    small = decode_color(jpeg, reduce=2)
    assert small.shape == (240, 320, 3)
    assert np.abs(small.astype(int) - subsample_color(decode_color(jpeg), 2).astype(int)).mean() < 2.0


def test_cameras_and_boxes_follow_and_answers_keep_the_pixels_as_sent():
    text = (FRAME / "scene_boxes.json").read_text()
    limits = Limits(read_size=(320, 240))
    full = validate_scene(parse_scene(text, Limits()), _files(), Limits(), True)
    half = validate_scene(parse_scene(text, limits), _files(), limits, True)
    assert half.reduced == [2, 2, 2] and full.reduced == [1, 1, 1]
    assert half.views[0].depth.shape == (240, 320) and half.views[0].color.shape == (240, 320, 3)
    point = torch.tensor([[150.0, -80.0, 2500.0]], dtype=torch.float64)
    for a, b in zip(full.views, half.views, strict=True):
        uv_full, uv_half = a.camera.project(point), b.camera.project(point)
        torch.testing.assert_close(uv_half, (uv_full + 0.5) / 2 - 0.5)
    for a, b in zip(full.boxes, half.boxes, strict=True):
        np.testing.assert_allclose(b, (a + 0.5) / 2 - 0.5, atol=1e-4)
    # Detector mode: boxes found in the reduced images are answered in the pixels of the images as sent.
    detect = validate_scene(parse_scene((FRAME / "scene.json").read_text(), limits), _files(), limits, True)
    found = PersonBoxes.from_lists([[[10.0, 20.0, 60.0, 120.0], None, None]], 3, scores=[[0.9, None, None]])
    person = PersonResult(np.zeros((10, 3)), np.zeros(10), np.zeros(10), id=0, person_boxes=found, row=0)
    sent = _sent_boxes(SceneResult("detector", [person], found), detect)
    np.testing.assert_allclose(sent.boxes[0, 0], [20.5, 40.5, 120.5, 240.5])
    assert sent.support(0) == person.support == [0] and sent.score(0, 0) == pytest.approx(0.9)
    np.testing.assert_array_equal(person.boxes[0], [10.0, 20.0, 60.0, 120.0])  # the pipeline's own are kept


@pytest.mark.parametrize("color_format", ["png", "jpg"])
def test_served_frame_meets_the_network_as_offline(color_format):
    """Reference boxes: the reduced decode gives the offline (full-resolution) joints; exactly for PNG colour,
    where it runs the reader's own subsampling, and within 5 mm for JPEG's DCT-scaled decode."""
    from pipeline.two_stage import ScenePipeline

    pipe = ScenePipeline.from_checkpoints(precision="fp32", backend="torch", load_detector=False)
    text = (FRAME / "scene_boxes.json").read_text()
    limits = Limits(read_size=pipe.read_size)
    assert pipe.read_size == (320, 240)
    full = validate_scene(parse_scene(text, Limits()), _files(color_format), Limits(), True)
    half = validate_scene(parse_scene(text, limits), _files(color_format), limits, True)
    a = pipe.run(full.views, full.boxes, full.person_ids)
    b = pipe.run(half.views, half.boxes, half.person_ids)
    assert [p.id for p in a.persons] == [p.id for p in b.persons] and a.persons
    tol = 0.1 if color_format == "png" else 5.0  # mm (measured: 0.0 and 1.7)
    for p, q in zip(a.persons, b.persons, strict=True):
        np.testing.assert_allclose(q.joints, p.joints, atol=tol)


def _sent_reduced(files: dict[str, bytes], k: int = 2) -> dict[str, bytes]:
    """The views brought to 1/k by the client before sending (``service.client.Transport`` with a read size)."""
    out = {}
    for name, data in files.items():
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        small = subsample_depth(image, k) if name.startswith("depth") else subsample_color(image, k)
        out[name] = cv2.imencode(".png", small)[1].tobytes()
    return out


def _calibrated(text: str, size: list[int] | None) -> str:
    scene = json.loads(text)
    for view in scene["views"]:
        view["camera"]["image_size"] = size
    return json.dumps(scene)


@pytest.mark.parametrize("scene_file", ["scene_boxes.json", "scene.json"])
def test_views_sent_reduced_are_read_as_the_calibrated_views(scene_file):
    """Views sent at 1/2 of their camera's image_size are what the server makes of the calibrated views: the
    same pixels, cameras and boxes, bit for bit, and coordinates in the calibrated pixels."""
    text = _calibrated((FRAME / scene_file).read_text(), [640, 480])
    limits = Limits(read_size=(320, 240))
    full = validate_scene(parse_scene(text, limits), _files("png"), limits, True)
    sent = validate_scene(parse_scene(text, limits), _sent_reduced(_files("png")), limits, True)
    assert full.reduced == sent.reduced == [2, 2, 2]
    for a, b in zip(full.views, sent.views, strict=True):
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.depth, b.depth)
        assert torch.equal(a.camera.intrinsics, b.camera.intrinsics) and a.camera.size == b.camera.size
    if full.boxes is not None:
        for a, b, c, d in zip(full.boxes, sent.boxes, full.sent_boxes, sent.sent_boxes, strict=True):
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(c, d)
    # A server that reads 640x480 in full decodes nothing smaller: the reduced views are scaled up in
    # coordinates only (their pixels as sent).
    wide = Limits(read_size=(640, 480))
    small = validate_scene(parse_scene(text, wide), _sent_reduced(_files("png")), wide, True)
    assert small.reduced == [2, 2, 2]


def test_views_of_another_size_than_the_calibration_are_refused_with_the_sizes_it_takes():
    limits = Limits(read_size=(320, 240))
    text = _calibrated((FRAME / "scene_boxes.json").read_text(), [640, 480])
    with pytest.raises(InputError, match=r"images are 160x120.*or exactly 1/2, 1/4 or 1/8 of it"):
        # 1/4 of the images sent against a calibration of 4/3 of 480x360: not an exact fraction
        scene = parse_scene(_calibrated(text, [480, 360]), limits)
        validate_scene(scene, _sent_reduced(_files("png"), 4), limits, True)
    # Without image_size the views are taken as sent, and the calibrated intrinsics do not fit them.
    plain = (FRAME / "scene.json").read_text()
    with pytest.raises(InputError, match="outside view 0's 320x240 image.*need the camera's image_size"):
        validate_scene(parse_scene(plain, limits), _sent_reduced(_files("png")), limits, True)
