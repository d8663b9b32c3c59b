"""Decoding and validation of /scenes inputs, without HTTP: every bad input raises InputError with its 4xx."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from service.decode import decode_color, decode_depth, header_size
from service.errors import InputError
from service.validation import Limits, parse_scene, validate_scene

W, H = 64, 48
LIMITS = Limits(max_views=4, max_image_pixels=W * H * 4, max_boxes_per_view=8)


def png(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", image)
    assert ok
    return buf.tobytes()


def jpeg(image: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".jpg", image)
    assert ok
    return buf.tobytes()


def frame(seed: int = 0, w: int = W, h: int = H) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (h, w, 3), dtype=np.uint8), rng.integers(500, 6000, (h, w), dtype=np.uint16)


def camera(**overrides) -> dict:
    cam = {"fx": 50.0, "fy": 50.0, "cx": W / 2, "cy": H / 2, "extrinsics": np.eye(4).tolist()}
    return {**cam, **overrides}


def scene_json(views: list[dict]) -> str:
    return json.dumps({"views": views})


def parts(n: int, **replace: bytes) -> dict[str, bytes]:
    files = {}
    for i in range(n):
        color, depth = frame(i)
        files[f"color_{i}"] = png(cv2.cvtColor(color, cv2.COLOR_RGB2BGR))
        files[f"depth_{i}"] = png(depth)
    files.update(replace)
    return {k: v for k, v in files.items() if v is not None}


def validate(
    views: list[dict], files: dict[str, bytes], need_color: bool = True, detector_color: bool = True
):
    return validate_scene(parse_scene(scene_json(views), LIMITS), files, LIMITS, need_color, detector_color)


# ----------------------------------------------------------------------------------------------- decoding
def test_decode_round_trips_png_and_reads_headers():
    color, depth = frame(1, 70, 30)
    assert np.array_equal(decode_color(png(cv2.cvtColor(color, cv2.COLOR_RGB2BGR))), color)  # RGB out
    assert np.array_equal(decode_depth(png(depth)), depth)
    assert header_size(png(depth), "d") == (70, 30)
    assert header_size(jpeg(color), "c") == (70, 30)
    assert decode_color(jpeg(color)).shape == (30, 70, 3)


def test_depth_scale_converts_to_mm_and_drops_overflow():
    depth = np.array([[0, 10, 1000, 60000]], np.uint16)
    mm = decode_depth(png(depth), scale_mm=2.0)
    assert mm.tolist() == [[0, 20, 2000, 0]]  # 120000 mm does not fit uint16: unknown, not wrapped


@pytest.mark.parametrize(
    ("data", "status", "words"),
    [
        (b"", 422, "empty"),
        (b"GIF89a....", 415, "neither a PNG nor a JPEG"),
        (png(np.zeros((4, 4), np.uint16))[:30], 422, "could not be decoded"),
        (png(np.zeros((4, 4), np.uint16))[:20], 422, "truncated"),
        (png(np.zeros((4, 4), np.uint8)), 422, "8-bit"),
        (png(np.zeros((4, 4, 3), np.uint16)), 422, "3 channels"),
        (jpeg(np.zeros((4, 4), np.uint8)), 415, "JPEG"),
        (png(np.zeros((100, 100), np.uint16)), 413, "ORPOSE_MAX_IMAGE_PIXELS"),
    ],
)
def test_bad_depth_images_are_named(data, status, words):
    with pytest.raises(InputError) as err:
        decode_depth(data, "depth_1", max_pixels=50 * 50)
    assert err.value.status == status
    assert "depth_1" in err.value.message and words in err.value.message


def test_size_limit_is_checked_before_decoding():
    # A 4000x4000 PNG of zeros compresses to a few kB; it must be refused from its header alone.
    bomb = png(np.zeros((4000, 4000), np.uint16))
    assert len(bomb) < 200_000
    with pytest.raises(InputError) as err:
        decode_depth(bomb, "depth_0", max_pixels=1000 * 1000)
    assert err.value.status == 413


# ----------------------------------------------------------------------------------------------- validation
def test_valid_scene_gives_views_and_boxes():
    beside = np.eye(4)
    beside[0, 3] = 500.0  # a second camera half a metre along x: two views never share one camera
    views = [{"camera": camera()}, {"camera": camera(extrinsics=beside.tolist()), "boxes": [[1, 2, 30, 40]],
                                    "person_ids": [7]}]  # fmt: skip
    views[0]["boxes"], views[0]["person_ids"] = [], []
    scene = validate(views, parts(2))
    assert len(scene.views) == 2 and scene.views[1].depth.dtype == np.uint16
    assert scene.views[1].camera.size == (W, H)
    assert scene.boxes[1].tolist() == [[1, 2, 30, 40]] and scene.person_ids[1].tolist() == [7]
    assert validate([{"camera": camera()}], parts(1)).boxes is None  # no boxes anywhere: detector mode
    assert scene.up is None


def test_up_is_a_unit_direction_or_named():
    """The scene's optional up direction comes back as a unit vector, however long or tiny it was sent; one with
    no direction is a 422 that says so."""
    views = [{"camera": camera()}]
    for up, unit in (
        ([0, -2, 0], [0, -1, 0]),
        ([3e-300, 4e-300, 0], [0.6, 0.8, 0]),
        ([1e308, 1e308, 0], None),
    ):
        got = validate_scene(
            parse_scene(json.dumps({"views": views, "up": up}), LIMITS), parts(1), LIMITS, True
        ).up
        assert np.linalg.norm(got) == pytest.approx(1.0)
        if unit is not None:
            np.testing.assert_allclose(got, unit, atol=1e-12)
    with pytest.raises(InputError, match="has no direction"):
        validate_scene(
            parse_scene(json.dumps({"views": views, "up": [0, 0, 0]}), LIMITS), parts(1), LIMITS, True
        )
    with pytest.raises(InputError, match="up"):
        parse_scene(json.dumps({"views": views, "up": [0, 1]}), LIMITS)


@pytest.mark.parametrize(
    ("views", "files", "status", "words"),
    [
        ([], parts(0), 422, "0 views"),
        ([{"camera": camera()}] * 5, parts(5), 422, "5 views"),
        ([{"camera": camera()}], parts(1, depth_0=None), 422, "missing file part depth_0"),
        ([{"camera": camera()}], parts(1, color_0=None), 422, "missing file part color_0"),
        ([{"camera": camera()}], parts(1, color_1=b"x"), 422, "unexpected file part"),
        ([{"camera": camera()}], parts(1, depth_0=png(np.zeros((H, W), np.uint8))), 422, "8-bit"),
        ([{"camera": camera()}], parts(1, depth_0=png(np.zeros((H, W + 2), np.uint16))), 422, "same size"),
        ([{"camera": camera(image_size=[640, 480])}], parts(1), 422, "image_size is 640x480"),
        ([{"camera": camera(cx=320.0)}], parts(1), 422, "principal point"),
        ([{"camera": camera(extrinsics=(2 * np.eye(4)).tolist())}], parts(1), 422, "not a rigid"),
        ([{"camera": camera(extrinsics=np.eye(3).tolist())}], parts(1), 422, "extrinsics"),
        ([{"camera": camera(fx=-1.0)}], parts(1), 422, "fx"),
        ([{"camera": camera(), "boxes": [[5, 5, 2, 9]]}], parts(1), 422, "is empty"),
        ([{"camera": camera(), "boxes": [[500, 5, 600, 9]]}], parts(1), 422, "outside"),
        ([{"camera": camera(), "boxes": [[1, 1, 5, 5]] * 9}], parts(1), 422, "more than 8"),
        ([{"camera": camera(), "boxes": [[1, 1, 5, 5]], "person_ids": [1, 2]}], parts(1), 422, "2 entries"),
        ([{"camera": camera(), "person_ids": [1]}], parts(1), 422, "without boxes"),
        ([{"camera": camera(), "foo": 1}], parts(1), 422, "foo"),
    ],
)
def test_bad_scenes_are_named(views, files, status, words):
    with pytest.raises(InputError) as err:
        validate(views, files)
    assert err.value.status == status, err.value.message
    assert words in err.value.message


def test_nan_extrinsics_are_rejected():
    text = scene_json([{"camera": camera()}]).replace("1.0", "NaN", 1)
    with pytest.raises(InputError) as err:
        parse_scene(text, LIMITS)
    assert "extrinsics" in err.value.message and "finite" in err.value.message


@pytest.mark.parametrize("text", ["not json", "[]", '{"views": "x"}', "{}"])
def test_malformed_scene_json(text):
    with pytest.raises(InputError, match="scene JSON is invalid"):
        parse_scene(text, LIMITS)


def test_colour_optional_only_where_no_network_reads_it():
    views = [{"camera": camera(), "boxes": [[1, 1, 20, 20]]}]
    assert validate(views, parts(1, color_0=None), need_color=False).views[0].color is None
    with pytest.raises(InputError, match="detection needs colour"):
        validate([{"camera": camera()}], parts(1, color_0=None), need_color=False)
    # a depth-only detector and pose network: a frame without boxes needs no colour either
    depth_only = {k: v for k, v in parts(1).items() if k.startswith("depth")}
    got = validate([{"camera": camera()}], depth_only, need_color=False, detector_color=False)
    assert got.views[0].color is None and got.boxes is None
    # a depth-only detector before a pose network that reads colour: the message names the pose network
    with pytest.raises(InputError, match="pose network reads colour"):
        validate([{"camera": camera()}], parts(1, color_0=None), need_color=True, detector_color=False)


def test_a_non_finite_estimate_is_never_sent_as_null():
    # The inputs are bounded so that this should not happen; if the models still give NaN, the client gets a
    # 422 that says what to check rather than a 200 whose numbers are null.
    from pipeline.two_stage import PersonResult, SceneResult
    from posenet.boxes import PersonBoxes
    from service.response import encode

    scene = validate([{"camera": camera(), "boxes": [[1, 2, 30, 40]], "person_ids": [7]}], parts(1))
    joints = np.zeros((10, 3))
    joints[3, 1] = np.nan
    boxes = PersonBoxes.from_lists([[scene.boxes[0][0]]], 1, ids=[7])
    person = PersonResult(joints, np.full(10, 40.0), np.ones(10), id=7, person_boxes=boxes, row=0,
                          box_indices=[(0,)])  # fmt: skip
    result = SceneResult("reference_boxes", [person], boxes, {"detect": 0.0, "match": 0.0, "pose": 1.0})
    with pytest.raises(InputError, match="person 7 is not finite: check the cameras") as err:
        encode(result, scene, 1.0, 0.0)
    assert err.value.status == 422
    person.joints = np.zeros((10, 3))
    out = json.loads(encode(result, scene, 1.0, 0.0))
    assert out["persons"][0]["views"][0]["box"] == [1, 2, 30, 40]
    # a one-view skeleton collapsed to a point has no person's size: a note names it (posenet.net.plausibility)
    assert len(out["notes"]) == 1 and out["notes"][0].startswith("person 7 is seen by one view only")


def test_boxes_partly_outside_are_clipped_and_kept_as_sent():
    sent = [-20.5, 5.0, 80.25, 40.0]  # the image is 64 wide
    scene = validate([{"camera": camera(), "boxes": [sent], "person_ids": [2]}], parts(1))
    assert scene.boxes[0].tolist() == [[0, 5, W - 1, 40]] and scene.sent_boxes[0].tolist() == [sent]


def test_all_zero_depth_says_why_nobody_can_be_found():
    with pytest.raises(InputError, match="every depth image holds only 0"):
        validate([{"camera": camera()}], parts(1, depth_0=png(np.zeros((H, W), np.uint16))))
