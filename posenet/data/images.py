"""Reading and subsampling the image files of an MVOR-format dataset.

Layout: the colour image of a view is ``ROOT/<file_name>`` (e.g. ``day1/cam1/color/000000.png``, 8-bit, 3
channels) and its depth image lies beside it under ``depth/`` (``day1/cam1/depth/000000.png``, 16-bit,
millimetres along the camera's z axis, 0 = unknown). Every problem with a file raises an error that names the
file and the problem.

Subsampling by an integer factor ``s`` keeps pixel centres on the camera rule ``u' = (u + 0.5) / s - 0.5``:
each output pixel is one s x s block of input pixels.
- Colour: ``cv2.resize`` with ``INTER_AREA`` (the block mean).
- Depth: the *lower median of the valid pixels* in each block (0 when none is valid). Averaging would mix
  valid and unknown pixels, and at a silhouette it would mix the person with the wall behind, inventing a
  depth at which nothing exists (a "flying pixel"). The lower median is always one of the block's measured
  values, ignores unknown pixels, and with three or four valid pixels it also rejects a single outlier (sensor
  speckle).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

# Sorts invalid depths (0) after every valid uint16 depth.
_INVALID = np.int32(1 << 20)

# How the renderer writes its PNGs (cv2.imwrite parameters), chosen for the reader, who decodes each file far
# more often than it is written (training, the service). Colour: SUB filter + RLE deflate at level 1, as small
# as OpenCV's default on noisy sensor images and twice as fast to write. Depth: no filter, zlib level 3: on the
# twin's 640x480 depth (2026-11-30, one thread) 131 KB decoding in 1.9 ms, against 219 KB and 3.8 ms with the
# colour's settings; the service decodes three per frame (docs/service.md, "Sending depth").
COLOR_PNG_PARAMS = [
    cv2.IMWRITE_PNG_COMPRESSION, 1,
    cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
    cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_SUB,
]  # fmt: skip
DEPTH_PNG_PARAMS = [cv2.IMWRITE_PNG_COMPRESSION, 3, cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE]


def depth_file_name(color_file_name: str) -> str:
    """The depth image beside a colour image: ``.../color/NNNNNN.png`` -> ``.../depth/NNNNNN.png``."""
    parts = Path(color_file_name).parts
    if "color" not in parts:
        raise ValueError(
            f"cannot locate the depth image of {color_file_name!r}: its path has no 'color' folder"
        )
    i = len(parts) - 1 - parts[::-1].index("color")
    return str(Path(*parts[:i], "depth", *parts[i + 1 :]))


def _imread(path: Path) -> np.ndarray:
    if not path.is_file():
        raise FileNotFoundError(f"image file {path} does not exist")
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ValueError(f"image file {path} could not be decoded")
    return image


def _check_size(path: Path, image: np.ndarray, size: tuple[int, int] | None) -> None:
    if size is not None and (image.shape[1], image.shape[0]) != tuple(size):
        raise ValueError(
            f"image file {path} is {image.shape[1]}x{image.shape[0]} pixels, "
            f"but the annotations say {size[0]}x{size[1]}"
        )


def read_color(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Read an 8-bit colour image as (H, W, 3) uint8 RGB; ``size`` (width, height) is checked when given."""
    image = _imread(path)
    if image.dtype != np.uint8:
        raise ValueError(f"colour image {path} has dtype {image.dtype}, expected 8-bit (uint8)")
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    elif image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
    else:
        raise ValueError(f"colour image {path} has {image.shape[2]} channels, expected 3")
    _check_size(path, image, size)
    return image


def read_depth(path: Path, size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a 16-bit depth image as (H, W) uint16 mm; ``size`` (width, height) is checked when given."""
    image = _imread(path)
    if image.dtype != np.uint16:
        raise ValueError(
            f"depth image {path} has dtype {image.dtype} ({image.dtype.itemsize * 8}-bit), "
            "expected 16-bit millimetres (uint16); an 8-bit depth image has lost its range"
        )
    if image.ndim != 2:
        raise ValueError(f"depth image {path} has {image.shape[2]} channels, expected a single channel")
    _check_size(path, image, size)
    return image


def _crop_to_blocks(image: np.ndarray, factor: int) -> np.ndarray:
    # Dropping the last rows/columns that do not fill a block keeps the camera rule exact for the rest.
    h, w = image.shape[0] // factor * factor, image.shape[1] // factor * factor
    return image[:h, :w]


def subsample_color(image: np.ndarray, factor: int) -> np.ndarray:
    """(H, W, 3) -> (H // factor, W // factor, 3): the mean of each block (``cv2.INTER_AREA``)."""
    if factor == 1:
        return image
    image = _crop_to_blocks(image, factor)
    h, w = image.shape[0] // factor, image.shape[1] // factor
    return cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)


def subsample_depth(depth: np.ndarray, factor: int) -> np.ndarray:
    """(H, W) uint16 -> (H // factor, W // factor) uint16: the lower median of each block's valid pixels.

    A block without valid pixels (all 0) gives 0. See the module docstring for why.
    """
    if factor == 1:
        return depth
    depth = _crop_to_blocks(depth, factor)
    if factor == 2:
        return _lower_median_2x2(depth)
    h, w = depth.shape[0] // factor, depth.shape[1] // factor
    blocks = (
        depth.reshape(h, factor, w, factor).transpose(0, 2, 1, 3).reshape(h, w, factor * factor)
    )  # (h, w, s*s)
    values = np.where(blocks > 0, blocks.astype(np.int32), _INVALID)
    values.sort(axis=-1)
    n_valid = (blocks > 0).sum(axis=-1)  # (h, w)
    lower_median = np.take_along_axis(values, ((n_valid - 1) // 2).clip(min=0)[..., None], axis=-1)[..., 0]
    return np.where(n_valid > 0, lower_median, 0).astype(np.uint16)


def _lower_median_2x2(depth: np.ndarray) -> np.ndarray:
    """The 2x2 case of :func:`subsample_depth` with min/max networks instead of a sort (20x faster).

    Subtracting 1 in uint16 wraps unknown (0) to 65535, so unknown pixels sort last. Of the sorted valid
    values s0 <= s1 <= ..., the lower median is s0 for one or two valid pixels and s1 for three or four.
    """
    v = depth - np.uint16(1)  # wraps 0 -> 65535
    a, b, c, d = v[0::2, 0::2], v[0::2, 1::2], v[1::2, 0::2], v[1::2, 1::2]  # (H/2, W/2) each
    lo1, hi1 = np.minimum(a, b), np.maximum(a, b)
    lo2, hi2 = np.minimum(c, d), np.maximum(c, d)
    s0 = np.minimum(lo1, lo2)
    s1 = np.minimum(np.maximum(lo1, lo2), np.minimum(hi1, hi2))
    n_valid = (a != 65535).astype(np.uint8) + (b != 65535) + (c != 65535) + (d != 65535)
    return np.where(n_valid >= 3, s1, s0) + np.uint16(1)  # an all-unknown block wraps back to 0
