"""The client's cheaper transport (``service.client.Transport``): JPEG colour of the same size and close to the
original, depth re-written losslessly, and the server answering the re-encoded frame like the original one."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from posenet.data.images import DEPTH_PNG_PARAMS
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
