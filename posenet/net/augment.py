"""Invertible multi-view augmentation as per-view affine warps (paper, Sec. 2.3).

Every geometric operation on a view is one 3x3 affine ``A`` that maps *original* pixels to *network* pixels
(both in :mod:`posenet.cameras`' convention, origin at the top-left pixel's centre). The input is warped with
``A``; the network's output is brought back with ``A^-1`` before lifting, so the 3D geometry (cameras,
depth) never sees the augmentation and the loss's gradient flows through the inverse. Two exact inverses:

- :func:`inverse_warp` resamples the heatmaps onto the original pixel grid with ``grid_sample`` (pixels the
  network never saw are zero-padded, as the paper does for random crops).
- :func:`network_pixels_in_original` maps every network pixel to the original pixel it came from, so each
  network pixel is lifted at that location with the original depth found there (nearest). For a crop, resize,
  flip or rotation this is the same mapping read the other way round: instead of resampling the heatmap on
  the original grid, the points keep the network's grid and carry their original coordinates. No heatmap
  value is interpolated, so it is exact; the only difference from the warp-back is the density of points
  (one per network pixel instead of one per original pixel), i.e. a constant per-view factor on the
  softmax mass that the network absorbs into its logits.

A horizontal flip also mirrors the person, so the network's "left" channels fire on the right limbs: after
inverting, the channels are permuted with :data:`posenet.skeleton.FLIP_PERMUTATION` (:func:`unflip_channels`).

Colour jitter (brightness, contrast, saturation) needs no inverse.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch.nn import functional as F

from posenet.skeleton import FLIP_PERMUTATION

Tensor = torch.Tensor


@dataclass
class AugmentConfig:
    flip: bool = True  # horizontal flip with probability 0.5 (left/right channels swapped back)
    rotate_deg: float = 15.0  # uniform rotation in [-r, r] about the network image's centre; 0 disables
    crop: bool = True  # full-image mode: random crop window; person-crop mode: shift/scale jitter of the crop
    shift: float = 0.08  # person-crop mode: centre shift, as a fraction of the crop side
    scale: float = 0.15  # person-crop mode: the crop side is multiplied by 2**U(-scale, scale)
    color: bool = True  # colour jitter
    brightness: float = 0.25  # factor 1 + U(-b, b)
    contrast: float = 0.25
    saturation: float = 0.25
    # Colour dropout (issue 12; an extension, paper: none): probability per network image that its colour is
    # replaced by mid grey, so that the network also learns people from depth alone, the modality that
    # transfers best to a look it never saw (docs/RESULTS.md, "Look transfer per modality"); 0 disables.
    color_drop: float = 0.0
    occlude: float = 0.0  # probability per network image of one random occluder (an extension; paper: none)
    # Detector-like boxes (issue 13; an extension, paper: none): probability per (person, view) box of replacing
    # the reference box by one as a detector might give it (see detector_like_boxes); 0 keeps reference boxes.
    box_noise: float = 0.0
    box_side_std: float = 0.08  # each side moves by N(0, std x the box's width or height)
    box_truncate: float = 0.25  # share of the noisy boxes with one side cut by 10-40 % (a partly seen person)
    box_merge: float = 0.1  # share of the noisy boxes grown to hold another person's box of that view too


# ----------------------------------------------------------------------------- affine building blocks
def _eye(n: int, dtype=torch.float32, device=None) -> Tensor:
    return torch.eye(3, dtype=dtype, device=device).expand(n, 3, 3).clone()


def translation(tx: Tensor, ty: Tensor) -> Tensor:
    """(N, 3, 3) translations by ``tx, ty (N,)``."""
    A = _eye(tx.shape[0], tx.dtype, tx.device)
    A[:, 0, 2], A[:, 1, 2] = tx, ty
    return A


def scaling(sx: Tensor, sy: Tensor) -> Tensor:
    """(N, 3, 3) scalings about the origin."""
    A = _eye(sx.shape[0], sx.dtype, sx.device)
    A[:, 0, 0], A[:, 1, 1] = sx, sy
    return A


def rotation(theta: Tensor) -> Tensor:
    """(N, 3, 3) rotations by ``theta (N,)`` radians about the origin (clockwise on screen, y is down)."""
    c, s = torch.cos(theta), torch.sin(theta)
    A = _eye(theta.shape[0], theta.dtype, theta.device)
    A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1] = c, -s, s, c
    return A


def resize_affine(in_size: tuple[int, int], out_size: tuple[int, int], n: int = 1) -> Tensor:
    """(n, 3, 3) the resize of a ``(W, H)`` image to ``(W', H')``: u' = (u + 0.5) W'/W - 0.5."""
    fx, fy = out_size[0] / in_size[0], out_size[1] / in_size[1]
    A = torch.tensor([[fx, 0, 0.5 * fx - 0.5], [0, fy, 0.5 * fy - 0.5], [0, 0, 1]], dtype=torch.float32)
    return A.expand(n, 3, 3).clone()


def box_crop_affine(boxes: Tensor, out_size: int, margin: float = 1.1) -> Tensor:
    """(N, 3, 3) square crops around ``boxes (N, 4)`` xyxy, of side ``margin * max(w, h)``, resized to
    ``out_size``.

    The crop's continuous extent [c - s/2, c + s/2] (pixel edges) maps onto [-0.5, out_size - 0.5].
    """
    if boxes.ndim != 2 or boxes.shape[-1] != 4:
        raise ValueError(f"boxes must have shape (N, 4), got {tuple(boxes.shape)}")
    cx, cy = (boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2
    side = margin * torch.maximum(boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]).clamp_min(1.0)
    k = out_size / side
    # u' = (u - cx + s/2) k - 0.5
    half = torch.full_like(k, -0.5)
    return translation(half, half) @ scaling(k, k) @ translation(side / 2 - cx, side / 2 - cy)


def about_centre(M: Tensor, size: tuple[int, int]) -> Tensor:
    """Conjugate ``M (N, 3, 3)`` so that it acts about the centre of a ``(W, H)`` image, not the origin."""
    n = M.shape[0]
    cx = torch.full((n,), (size[0] - 1) / 2, dtype=M.dtype, device=M.device)
    cy = torch.full((n,), (size[1] - 1) / 2, dtype=M.dtype, device=M.device)
    return translation(cx, cy) @ M @ translation(-cx, -cy)


def hflip(flipped: Tensor, width: int) -> Tensor:
    """(N, 3, 3) u' = W - 1 - u where ``flipped (N,)`` is True, identity elsewhere."""
    A = _eye(flipped.shape[0])
    A[flipped, 0, 0] = -1
    A[flipped, 0, 2] = width - 1
    return A


# ----------------------------------------------------------------------------- random draws
def random_jitter(
    n: int,
    config: AugmentConfig,
    out_size: tuple[int, int],
    person_crop: bool,
    generator: torch.Generator | None = None,
) -> tuple[Tensor, Tensor]:
    """Draw ``n`` network-space augmentations: ``(J (n, 3, 3), flipped (n,) bool)``; compose as ``J @ base``.

    Person-crop mode: a shift/scale jitter of the crop (the "random crop" of a crop) and the rotation, about
    the network image's centre. Full-image mode: the random crop window is drawn by the caller (it is part of
    the base affine); here only the rotation. The flip comes last, so it mirrors the final network image.
    """

    def uniform(lo: float, hi: float) -> Tensor:
        return lo + (hi - lo) * torch.rand(n, generator=generator)

    M = _eye(n)
    if person_crop and config.crop:
        s = 2.0 ** uniform(-config.scale, config.scale)
        side = float(max(out_size))
        shift = uniform(-config.shift, config.shift) * side, uniform(-config.shift, config.shift) * side
        M = translation(*shift) @ scaling(s, s) @ M
    if config.rotate_deg > 0:
        M = rotation(uniform(-config.rotate_deg, config.rotate_deg) * math.pi / 180) @ M
    M = about_centre(M, out_size)
    flipped = (torch.rand(n, generator=generator) < 0.5) if config.flip else torch.zeros(n, dtype=torch.bool)
    return hflip(flipped, out_size[0]) @ M, flipped


def random_crop_window(
    n: int, in_size: tuple[int, int], out_size: tuple[int, int], generator: torch.Generator | None = None
) -> Tensor:
    """(n, 3, 3) translations that cut a random ``out_size`` window from an ``in_size`` image (paper)."""
    if out_size[0] > in_size[0] or out_size[1] > in_size[1]:
        raise ValueError(f"crop {out_size} larger than the image {in_size}")
    x0 = torch.randint(0, in_size[0] - out_size[0] + 1, (n,), generator=generator).float()
    y0 = torch.randint(0, in_size[1] - out_size[1] + 1, (n,), generator=generator).float()
    return translation(-x0, -y0)


def occluders(images: Tensor, probability: float, generator: torch.Generator | None = None) -> Tensor:
    """Paste one random rectangle of noise (10-40 % of each side) over each image of ``images (N, C, H, W)``
    with ``probability``, in every channel except the last (the box mask stays: the person is still there).

    This hides body parts from the network only; the points that are lifted keep their real depth, so, like
    colour jitter, it needs no inverse. It imitates the occlusion by staff and equipment that dominates the
    error tail on MVOR-like scenes."""
    N, C, H, W = images.shape
    u = torch.rand(N, 5, generator=generator)
    h, w = (0.1 + 0.3 * u[:, 0]) * H, (0.1 + 0.3 * u[:, 1]) * W
    y0, x0 = u[:, 2] * (H - h), u[:, 3] * (W - w)
    on = u[:, 4] < probability
    ys = torch.arange(H).view(1, H, 1)
    xs = torch.arange(W).view(1, 1, W)
    inside = (
        (ys >= y0.view(N, 1, 1))
        & (ys < (y0 + h).view(N, 1, 1))
        & (xs >= x0.view(N, 1, 1))
        & (xs < (x0 + w).view(N, 1, 1))
    )
    inside = (inside & on.view(N, 1, 1)).unsqueeze(1).to(images.device)  # (N, 1, H, W)
    noise = (torch.rand(N, C - 1, 1, 1, generator=generator) * 2 - 1).to(
        images
    )  # a flat random value per channel
    out = images.clone()
    out[:, :-1] = torch.where(inside, noise.expand(N, C - 1, H, W), images[:, :-1])
    return out


def detector_like_boxes(
    boxes: Tensor,
    has_box: Tensor,
    sizes: list[tuple[int, int]],
    config: AugmentConfig,
    generator: torch.Generator | None = None,
) -> Tensor:
    """Reference boxes made to look like a detector's, so that the network learns to tolerate them.

    Each box is, with probability ``config.box_noise``, moved side by side (N(0, ``box_side_std`` x its width or
    height): shifted, too large or too small); a share of those loses 10-40 % on one side (truncated), and a
    share grows to the hull of itself and another person's box in the same view (two persons in one box). Boxes
    stay within their image and at least 2 px wide and high.

    Args:
        boxes: (P, V, 4) xyxy pixels; has_box: (P, V) bool; sizes: V (width, height) of the views' images.

    Returns:
        (P, V, 4): the new boxes (the others, and those without ``has_box``, unchanged).
    """
    P, V = has_box.shape
    if config.box_noise <= 0 or P == 0:
        return boxes
    u = lambda *shape: torch.rand(*shape, generator=generator)  # noqa: E731
    noisy = has_box & (u(P, V) < config.box_noise)
    wh = (boxes[..., 2:] - boxes[..., :2]).repeat(1, 1, 2)  # (P, V, 4): w, h, w, h
    out = boxes + torch.randn(P, V, 4, generator=generator) * config.box_side_std * wh * noisy[..., None]
    # truncation: one side (x0, y0, x1 or y1) moves inwards by 10-40 % of the box
    cut = noisy & (u(P, V) < config.box_truncate)
    side = torch.randint(0, 4, (P, V), generator=generator)
    inwards = torch.tensor([1.0, 1.0, -1.0, -1.0])[side] * (0.1 + 0.3 * u(P, V))  # (P, V)
    amount = inwards * wh.gather(-1, side[..., None])[..., 0] * cut
    out.scatter_add_(-1, side[..., None], amount[..., None])
    # two persons in one box: the hull with a random other person's box of the same view
    if P > 1:
        merge = noisy & (u(P, V) < config.box_merge)
        other = (
            torch.arange(P)[:, None] + torch.randint(1, P, (P, V), generator=generator)
        ) % P  # (P, V) != p
        other_box = boxes.gather(0, other[..., None].expand(P, V, 4))
        merge &= has_box.gather(0, other)
        hull = torch.cat([torch.minimum(out[..., :2], other_box[..., :2]),
                          torch.maximum(out[..., 2:], other_box[..., 2:])], -1)  # fmt: skip
        out = torch.where(merge[..., None], hull, out)
    limit = torch.tensor([[w - 1.0, h - 1.0] for w, h in sizes]).repeat(1, 2)  # (V, 4)
    out = torch.minimum(out.clamp(min=0.0), limit)
    # keep boxes valid: at least 2 px each way (a box pushed off the image keeps a sliver at its edge)
    out[..., 2:] = torch.maximum(out[..., 2:], out[..., :2] + 2.0)
    out[..., :2] = torch.minimum(out[..., :2], out[..., 2:] - 2.0)
    return torch.where(noisy[..., None], out, boxes)


def color_jitter(rgb: Tensor, config: AugmentConfig, generator: torch.Generator | None = None) -> Tensor:
    """Random brightness, contrast and saturation per image of ``rgb (N, 3, H, W)`` in [0, 1]."""
    n = rgb.shape[0]

    def factor(amount: float) -> Tensor:
        return (1 + amount * (2 * torch.rand(n, generator=generator) - 1)).to(rgb).view(n, 1, 1, 1)

    x = rgb * factor(config.brightness)
    grey = (0.299 * x[:, 0:1] + 0.587 * x[:, 1:2] + 0.114 * x[:, 2:3]).clamp(0, 1)  # (N, 1, H, W)
    x = (x - grey.mean((2, 3), keepdim=True)) * factor(config.contrast) + grey.mean((2, 3), keepdim=True)
    x = (x - grey) * factor(config.saturation) + grey
    return x.clamp(0, 1)


def color_dropout(rgb: Tensor, probability: float, generator: torch.Generator | None = None) -> Tensor:
    """``rgb (N, 3, H, W)`` in [0, 1] with each image replaced by mid grey (0.5) with ``probability``."""
    dropped = torch.rand(rgb.shape[0], generator=generator) < probability  # (N,)
    return torch.where(dropped.to(rgb.device).view(-1, 1, 1, 1), torch.full_like(rgb, 0.5), rgb)


# ----------------------------------------------------------------------------- warps
def _apply(A: Tensor, uv: Tensor) -> Tensor:
    """Apply ``A (N, 3, 3)`` to points ``uv (N, M, 2)`` (or ``(1, M, 2)``, shared by the N maps).

    Written out per column: a batched matmul with an inner size of 2 costs about 4x more on the CPU (2 ms for a
    frame's 21 crops of 96x96 at one thread, three times per frame)."""
    return uv[..., :1] * A[:, None, :2, 0] + uv[..., 1:] * A[:, None, :2, 1] + A[:, None, :2, 2]


def _grid(height: int, width: int, device, dtype) -> Tensor:
    v, u = torch.meshgrid(
        torch.arange(height, device=device, dtype=dtype),
        torch.arange(width, device=device, dtype=dtype),
        indexing="ij",
    )
    return torch.stack([u, v], -1).reshape(1, height * width, 2)  # (1, H*W, 2)


def affine_inverse(A: Tensor) -> Tensor:
    """Exact inverse of affine maps ``A (N, 3, 3)`` (last row 0, 0, 1), in closed form: torch.linalg.inv's
    batched LU costs more than the whole lifting for these 3x3s on CPU."""
    a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
    det = a * d - b * c
    L = torch.stack([torch.stack([d, -b], -1), torch.stack([-c, a], -1)], -2) / det.view(
        -1, 1, 1
    )  # (N, 2, 2)
    t = -(L @ A[:, :2, 2:])  # (N, 2, 1)
    bottom = torch.zeros_like(A[:, 2:, :])
    bottom[:, 0, 2] = 1
    return torch.cat([torch.cat([L, t], -1), bottom], -2)


def network_pixels_in_original(A: Tensor, out_size: tuple[int, int]) -> Tensor:
    """``(N, h*w, 2)`` original pixel coordinates of every network pixel (row-major): ``A^-1 (u', v')``."""
    w, h = out_size
    return _apply(affine_inverse(A), _grid(h, w, A.device, A.dtype))


def _normalise(uv: Tensor, size: tuple[int, int]) -> Tensor:
    """Pixels to grid_sample's [-1, 1] (align_corners=False: -1 and 1 are the outer pixel edges)."""
    scale = torch.tensor([2.0 / size[0], 2.0 / size[1]], dtype=uv.dtype, device=uv.device)
    return (uv + 0.5) * scale - 1


def warp(images: Tensor, A: Tensor, out_size: tuple[int, int], mode: str = "bilinear") -> Tensor:
    """Warp ``images (N, C, H, W)`` with ``A (N, 3, 3)`` into ``(N, C, h, w)``; outside the image -> 0.

    Use ``mode="nearest"`` for depth and masks, so that no unknown (0) depth is blended into a valid one.
    """
    if images.ndim != 4 or A.shape != (images.shape[0], 3, 3):
        raise ValueError(
            f"warp expects images (N, C, H, W) and A (N, 3, 3), got {tuple(images.shape)}, {tuple(A.shape)}"
        )
    w, h = out_size
    src = network_pixels_in_original(A.to(torch.float32), out_size)  # (N, h*w, 2)
    grid = _normalise(src, (images.shape[-1], images.shape[-2])).view(-1, h, w, 2).to(images.dtype)
    return F.grid_sample(images, grid, mode=mode, padding_mode="zeros", align_corners=False)


def inverse_warp(heatmaps: Tensor, A: Tensor, in_size: tuple[int, int]) -> Tensor:
    """Bring network outputs ``(N, J, h, w)`` back onto the original ``(W, H)`` grid: ``(N, J, H, W)``.

    Original pixel p takes the (bilinear) heatmap value at ``A p``; pixels outside the network image get 0
    (the paper's zero-padding of random crops). Differentiable with respect to ``heatmaps``.
    """
    W, H = in_size
    h, w = heatmaps.shape[-2:]
    dst = _apply(A.to(torch.float32), _grid(H, W, A.device, torch.float32))  # (N, H*W, 2)
    grid = _normalise(dst, (w, h)).view(-1, H, W, 2).to(heatmaps.dtype)
    return F.grid_sample(heatmaps, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def unflip_channels(x: Tensor, flipped: Tensor) -> Tensor:
    """Swap left/right joint channels (dim 1 of ``x (N, J, ...)``) of the samples where ``flipped (N,)``."""
    perm = torch.tensor(FLIP_PERMUTATION, device=x.device)
    if x.shape[1] != len(FLIP_PERMUTATION):
        raise ValueError(f"expected {len(FLIP_PERMUTATION)} joint channels, got {x.shape[1]}")
    flipped = flipped.to(x.device)
    if not bool(flipped.any()):
        return x  # nothing mirrored (always at test time): no copy
    # one gather with a per-sample channel order, instead of a full swapped copy plus a select
    order = torch.where(
        flipped.view(-1, 1), perm.view(1, -1), torch.arange(x.shape[1], device=x.device)
    )  # (N, J)
    return x.gather(1, order.view(*order.shape, *([1] * (x.ndim - 2))).expand_as(x))
