"""Decoding the uploaded images: colour (PNG/JPEG, 8-bit) and depth (16-bit PNG), checked before and after.

Sizes are read from the file header *before* decoding, so that a small, highly compressed image cannot make
the server allocate gigabytes. Frames are decoded in memory only; nothing is written to disk or logged.

**At the resolution the models read** (``reduce`` k, from ``posenet.net.inputs.reduction``): when a view is an exact
multiple k of what the networks read (640x480 against the pose network's 320x240), it is brought to 1/k right here, in the
decoding threads, with the reader's own functions (block mean for colour, lower median of the valid depths), so
that every later stage handles a quarter of the pixels and a served frame meets the network exactly as in
training. A JPEG colour image is decoded at 1/k directly by libjpeg's DCT scaling (``IMREAD_REDUCED_COLOR_k``),
several times faster than a full decode. Coordinates in the API stay in the pixels of the image as sent
(``service.validation`` scales cameras and boxes; ``service.response`` scales detections back).
"""

from __future__ import annotations

import struct

import cv2
import numpy as np

from posenet.data.images import subsample_color, subsample_depth
from service.errors import PAYLOAD_TOO_LARGE, UNSUPPORTED_MEDIA, InputError

_REDUCED_COLOR = {2: cv2.IMREAD_REDUCED_COLOR_2, 4: cv2.IMREAD_REDUCED_COLOR_4, 8: cv2.IMREAD_REDUCED_COLOR_8}


PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
JPEG_MAGIC = b"\xff\xd8\xff"
# JPEG start-of-frame markers carry the image size; C4 (DHT), C8 (JPG) and CC (DAC) share the range but do
# not.
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def image_format(data: bytes) -> str | None:
    """'png', 'jpeg' or None, from the magic bytes."""
    if data.startswith(PNG_MAGIC):
        return "png"
    if data.startswith(JPEG_MAGIC):
        return "jpeg"
    return None


def header_size(data: bytes, name: str) -> tuple[int, int]:
    """(width, height) of a PNG or JPEG from its header, without decoding. Raises InputError if unreadable."""
    fmt = image_format(data)
    if fmt == "png":
        # The IHDR chunk always comes first: 8-byte magic, 4-byte length, b"IHDR", then width and height.
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise InputError(f"{name} is a truncated or corrupt PNG (no IHDR header)")
        width, height = struct.unpack(">II", data[16:24])
        return width, height
    if fmt == "jpeg":
        i = 2
        while i + 9 <= len(data):
            if data[i] != 0xFF:
                raise InputError(f"{name} is a corrupt JPEG (bad marker at byte {i})")
            marker = data[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
                continue
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
                i += 2
                continue
            (length,) = struct.unpack(">H", data[i + 2 : i + 4])
            if marker in _JPEG_SOF:
                height, width = struct.unpack(">HH", data[i + 5 : i + 9])
                return width, height
            i += 2 + length
        raise InputError(f"{name} is a truncated or corrupt JPEG (no frame header)")
    raise InputError(f"{name} is neither a PNG nor a JPEG image", UNSUPPORTED_MEDIA)


def _checked_size(data: bytes, name: str, max_pixels: int) -> tuple[int, int]:
    if not data:
        raise InputError(f"{name} is empty")
    width, height = header_size(data, name)
    if width <= 0 or height <= 0:
        raise InputError(f"{name} has an invalid size {width}x{height}")
    if width * height > max_pixels:
        raise InputError(
            f"{name} is {width}x{height} = {width * height} pixels, more than the server's limit of {max_pixels} "
            "(ORPOSE_MAX_IMAGE_PIXELS): send the camera's native resolution, or raise the limit on the server",
            PAYLOAD_TOO_LARGE,
        )
    return width, height


def _decode(data: bytes, name: str, flags: int, size: tuple[int, int]) -> np.ndarray:
    image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if image is None:
        raise InputError(f"{name} could not be decoded: the file is corrupt or truncated")
    if (image.shape[1], image.shape[0]) != size:
        raise InputError(
            f"{name} decodes to {image.shape[1]}x{image.shape[0]} but its header says {size[0]}x{size[1]}"
        )
    return image


def decode_color(
    data: bytes, name: str = "color", max_pixels: int = 1920 * 1200, reduce: int = 1
) -> np.ndarray:
    """A colour PNG or JPEG to ``(H / reduce, W / reduce, 3)`` uint8 RGB (grey images are expanded to three
    channels). ``reduce`` must divide both sides (``posenet.net.inputs.reduction``)."""
    size = _checked_size(data, name, max_pixels)
    if reduce > 1 and image_format(data) == "jpeg":
        bgr = _decode(data, name, _REDUCED_COLOR[reduce], (size[0] // reduce, size[1] // reduce))
    else:
        bgr = _decode(data, name, cv2.IMREAD_COLOR, size)
        bgr = subsample_color(bgr, reduce)
    if bgr.dtype != np.uint8:
        raise InputError(f"{name} must be an 8-bit colour image, got {bgr.dtype}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def decode_depth(
    data: bytes, name: str = "depth", scale_mm: float = 1.0, max_pixels: int = 1920 * 1200, reduce: int = 1
) -> np.ndarray:
    """A single-channel 16-bit depth PNG to ``(H / reduce, W / reduce)`` uint16 millimetres (0 = unknown).

    ``scale_mm`` is the number of millimetres per stored unit; values are rounded to whole mm, and depths
    beyond 65535 mm become unknown rather than wrapping around. ``reduce`` takes the lower median of each
    block's valid depths (the reader's ``subsample_depth``).
    """
    if image_format(data) == "jpeg":
        raise InputError(
            f"{name} is a JPEG; depth must be a lossless single-channel 16-bit PNG", UNSUPPORTED_MEDIA
        )
    size = _checked_size(data, name, max_pixels)
    depth = _decode(data, name, cv2.IMREAD_UNCHANGED, size)
    if depth.ndim != 2:
        raise InputError(
            f"{name} has {depth.shape[2]} channels; depth must be a single-channel 16-bit PNG (one value "
            f"per pixel)"
        )
    if depth.dtype == np.uint8:
        raise InputError(
            f"{name} is an 8-bit image; depth must be a 16-bit PNG of millimetres (0 = unknown). An 8-bit "
            f"depth has "
            "lost its range: save the raw sensor depth with cv2.imwrite('d.png', "
            "depth.astype(np.uint16)), and set "
            "depth_scale_mm if its unit is not 1 mm"
        )
    if depth.dtype != np.uint16:
        raise InputError(f"{name} must be uint16, got {depth.dtype}")
    if scale_mm != 1.0:
        mm = np.rint(depth.astype(np.float64) * scale_mm)
        mm[mm > np.iinfo(np.uint16).max] = 0  # out of range: unknown, never a wrapped-around wrong depth
        depth = mm.astype(np.uint16)
    return subsample_depth(depth, reduce)
