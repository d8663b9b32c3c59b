"""The client's cheaper transport (``service.client.Transport``): JPEG colour of the same size and close to the
original, depth re-written losslessly, and the server answering the re-encoded frame like the original one."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from posenet.data.images import DEPTH_PNG_PARAMS, subsample_color, subsample_depth
from service.client import Transport


@pytest.fixture
def images():
    rng = np.random.default_rng(0)
    color = cv2.GaussianBlur(rng.integers(0, 255, (48, 64, 3), dtype=np.uint8), (15, 15), 5)
    depth = rng.integers(500, 6000, (48, 64)).astype(np.uint16)
    depth[::7] = 0  # unknown depth stays unknown
    png = cv2.imencode(".png", color)[1].tobytes()
    slow = cv2.imencode(".png", depth, [cv2.IMWRITE_PNG_COMPRESSION, 9])[1].tobytes()
    return color, depth, png, slow


def test_as_on_disk_by_default(images):
    _, _, png, slow = images
    t = Transport()
    assert t.color_part("0.png", png) == ("0.png", png, "image/png")
    assert t.depth_part("0.png", slow) == ("0.png", slow, "image/png")


def test_jpeg_colour_and_fast_depth(images):
    color, depth, png, slow = images
    t = Transport("jpeg", "png-fast", 95)
    name, data, mime = t.color_part("000012.png", png)
    assert (name, mime) == ("000012.jpg", "image/jpeg") and data[:2] == b"\xff\xd8"
    back = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert back.shape == color.shape and np.abs(back.astype(int) - color).mean() < 3
    name, data, mime = t.depth_part("000012.png", slow)
    assert (name, mime) == ("000012.png", "image/png")
    assert np.array_equal(
        cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED), depth
    )  # lossless
    assert data == cv2.imencode(".png", depth, DEPTH_PNG_PARAMS)[1].tobytes()


@pytest.mark.parametrize("bad", [dict(color="webp"), dict(depth="jpeg"), dict(quality=0), dict(quality=101)])
def test_bad_choices_are_refused(bad):
    with pytest.raises(ValueError):
        Transport(**bad)


def test_views_reduced_to_the_read_size_before_sending(tmp_path):
    rng = np.random.default_rng(1)
    color = rng.integers(0, 255, (96, 128, 3), dtype=np.uint8)
    depth = rng.integers(500, 6000, (96, 128)).astype(np.uint16)
    depth[::5] = 0
    cv2.imwrite(str(tmp_path / "c.png"), color)
    cv2.imwrite(str(tmp_path / "d.png"), depth)
    for t in (Transport(read_size=(32, 24)), Transport("jpeg", read_size=(32, 24))):
        color_part, depth_part, recorded = t.view_parts(tmp_path / "c.png", tmp_path / "d.png")
        assert recorded == (128, 96)  # 1/4 of it is the largest reduction still at least 32x24
        sent_depth = cv2.imdecode(np.frombuffer(depth_part[1], np.uint8), cv2.IMREAD_UNCHANGED)
        np.testing.assert_array_equal(sent_depth, subsample_depth(depth, 4))  # lossless, the server's rule
        sent_color = cv2.imdecode(np.frombuffer(color_part[1], np.uint8), cv2.IMREAD_COLOR)
        err = np.abs(sent_color.astype(int) - subsample_color(color, 4)).max()
        assert (err == 0) if t.color == "png" else (sent_color.shape == (24, 32, 3))
    # Nothing to reduce: sent as recorded, bytes untouched; no colour leaves a depth-only client.
    as_is = Transport(read_size=(128, 96)).view_parts(tmp_path / "c.png", tmp_path / "d.png")
    assert as_is == (
        ("c.png", (tmp_path / "c.png").read_bytes(), "image/png"),
        ("d.png", (tmp_path / "d.png").read_bytes(), "image/png"),
        None,
    )
    assert Transport("none", read_size=(32, 24)).view_parts(tmp_path / "c.png", tmp_path / "d.png")[0] is None


def test_a_live_cameras_arrays_make_the_same_parts_as_its_files(tmp_path):
    rng = np.random.default_rng(2)
    color = rng.integers(0, 255, (96, 128, 3), dtype=np.uint8)
    depth = rng.integers(500, 6000, (96, 128)).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "c.png"), color)
    cv2.imwrite(str(tmp_path / "d.png"), depth)
    t = Transport(read_size=(64, 48))
    assert t.encode_view(color, depth, "c.png", "d.png") == t.view_parts(tmp_path / "c.png", tmp_path / "d.png")
    # Without a read size the arrays are encoded as they are.
    color_part, depth_part, recorded = Transport().encode_view(color, depth)
    assert recorded is None and color_part[2] == "image/png"
    back = cv2.imdecode(np.frombuffer(depth_part[1], np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(back, depth)


def test_views_the_client_cannot_read_go_as_recorded_for_the_server_to_say_why(tmp_path):
    depth = np.full((96, 128), 2000, np.uint16)
    cv2.imwrite(str(tmp_path / "d.png"), depth)
    (tmp_path / "c.png").write_bytes(b"not an image")
    t = Transport(read_size=(32, 24))
    color_part, depth_part, recorded = t.view_parts(tmp_path / "c.png", tmp_path / "d.png")
    assert recorded is None and color_part[1] == b"not an image"
    assert depth_part[1] == (tmp_path / "d.png").read_bytes()
    with pytest.raises(FileNotFoundError):  # a missing file is the client's failure, as when sent as recorded
        t.view_parts(tmp_path / "missing.png", tmp_path / "d.png")
