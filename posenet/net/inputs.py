"""Turning a scene (V RGB-D views + per-person boxes) into the U-Net's input and the points to lift.

Two modes, one mechanism (a per-person, per-view affine ``A``: original pixels -> network pixels, see
:mod:`posenet.net.augment`):

- ``full`` (the paper): the network sees the whole image (``image_size``, 320x240; random ``train_crop``
  windows of 288x208 when training) and its heatmaps are warped back onto the image grid, where every pixel is
  lifted with its own depth. One input per person and view, because the box mask channel differs.
- ``crop`` (the CPU preset): the network sees a square crop of ``crop_margin`` times the person's box, resized
  to ``crop_size``. Each network pixel is lifted at the original pixel it came from (``A^-1``), with the
  depth found there. This is the exact inverse of the crop warp (see :mod:`posenet.net.augment`): the method is
  unchanged, but the network runs on a few thousand pixels per person instead of the whole image.

Input channels: colour (3, in [-1, 1]) for ``rgb``/``rgbd``; depth (1) for ``depth``/``rgbd`` as
``(D - 3 m) / 2 m`` with unknown depth marked by -2 (outside the range of any real depth); the box mask (1).
With ``extra_depth`` two more channels: depth relative to the person's median depth in the box (metres,
clipped to +-1.5, 0 where unknown) and a depth-valid flag. The paper's counts are 5 / 2 / 4 without them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
import torch

from posenet.cameras import Camera, rescale_pixels
from posenet.net import augment as aug
from posenet.scene import SceneView, scene_views

Tensor = torch.Tensor
MODALITIES = ("rgbd", "rgb", "depth")
MODES = ("crop", "full")


@dataclass
class InputConfig:
    modality: str = "rgbd"  # rgbd (paper: 5 channels), rgb (4) or depth (2)
    mode: str = "crop"  # "crop": person crops (CPU preset); "full": whole image (paper)
    crop_size: int = 96  # crop mode: network input side; a multiple of the U-Net's stride
    crop_margin: float = 1.1  # crop mode: crop side = margin x the box's longer side
    image_size: tuple[int, int] = (320, 240)  # full mode: (W, H) the views are resized to (paper: MVOR / 2)
    train_crop: tuple[int, int] = (288, 208)  # full mode: (W, H) random training windows (paper)
    extra_depth: bool = True  # + relative depth and depth-valid channels (an extension; paper: False)
    # crop mode: views are first resized to fit this (W, H), so that crops at inference come from images of
    # the training data's resolution whatever the camera delivers; None crops from the views as given
    source_size: tuple[int, int] | None = None
    depth_centre: float = 3000.0  # mm: depth normalisation (D - centre) / range
    depth_range: float = 2000.0

    def __post_init__(self) -> None:
        if self.modality not in MODALITIES:
            raise ValueError(f"modality must be one of {MODALITIES}, got {self.modality!r}")
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {self.mode!r}")
        self.image_size = tuple(self.image_size)
        self.train_crop = tuple(self.train_crop)
        self.source_size = None if self.source_size is None else tuple(self.source_size)

    @property
    def read_size(self) -> tuple[int, int] | None:
        """(W, H) that the network reads views at: ``image_size`` in full mode, ``source_size`` in crop mode (None:
        views as given). The one record of the input resolution: training (:func:`record_read_size`), offline
        prediction and the service all read views by it (:func:`reduction`), so they feed the network alike."""
        return self.image_size if self.mode == "full" else self.source_size

    @property
    def in_channels(self) -> int:
        return len(self.channels)

    @property
    def channels(self) -> tuple[str, ...]:
        """The network input's channels in order (:func:`_network_channels` writes them so)."""
        colour = ("red", "green", "blue") if self.modality in ("rgb", "rgbd") else ()
        depth = ()
        if self.modality in ("depth", "rgbd"):
            depth = ("depth", "relative_depth", "depth_valid") if self.extra_depth else ("depth",)
        return (*colour, *depth, "box_mask")

    def network_size(self, training: bool) -> tuple[int, int]:
        """(W, H) of the network's input."""
        if self.mode == "crop":
            return (self.crop_size, self.crop_size)
        return self.train_crop if training else self.image_size


@dataclass
class SceneInput:
    """Everything the model needs for one scene: ``N = P x V`` network inputs and the points to lift.

    Attributes:
        images: (N, C, h, w) network inputs, person-major (n = p V + v).
        A: (N, 3, 3) original pixels -> network pixels.
        flipped: (N,) whether the network image is mirrored.
        has_box: (P, V) whether the person has a box in that view (others are not run and get no points).
        cameras: batch shape (V,), of the (possibly resized) images that ``uv`` refers to.
        uv: (P or 1, V, M, 2) original pixel coordinates of the points.
        depth: (P or 1, V, M) mm at the points (0 = unknown).
        valid: (P, V, M) points that may vote (in the box, known depth, view has a box).
        image_size: (W, H) of the original (possibly resized) images.
    """

    images: Tensor
    A: Tensor
    flipped: Tensor
    has_box: Tensor
    cameras: Camera
    uv: Tensor
    depth: Tensor
    valid: Tensor
    image_size: tuple[int, int]
    mode: str = "crop"
    extras: dict = field(default_factory=dict)

    @property
    def num_persons(self) -> int:
        return self.has_box.shape[0]


def reduction(width: int, height: int, read_size: tuple[int, int] | None) -> int:
    """The largest k of 8, 4, 2 that divides a ``width`` x ``height`` image into one still at least ``read_size``
    (W, H) in both axes; 1 when none does (or ``read_size`` is None: keep the image as given). Readers subsample
    by it (``posenet.evaluation.predict``) and the service decodes by it, then :func:`build_scene` resizes the rest."""
    if read_size is None:
        return 1
    for k in (8, 4, 2):
        if width % k == 0 and height % k == 0 and width // k >= read_size[0] and height // k >= read_size[1]:
            return k
    return 1


def record_read_size(config: InputConfig, image_size: tuple[int, int], subsample: int) -> None:
    """Check or record the input resolution for training on ``image_size`` (W, H) views subsampled by ``subsample``.

    A crop-mode config without ``source_size`` records the training reader's size, so that predicting and serving
    later crop from views of that resolution too. A config that records one must be read with the subsampling
    that prediction and serving will use (:func:`reduction`), else the network would train on other pixels than
    it meets later: ValueError naming the factor to use.
    """
    W, H = image_size
    if config.read_size is None:
        config.source_size = (W // subsample, H // subsample)
        return
    k = reduction(W, H, config.read_size)
    if subsample != k:
        raise ValueError(
            f"subsample {subsample} reads the {W}x{H} views at {W // subsample}x{H // subsample}, but the model "
            f"reads them at {config.read_size} (subsampled by {k}) when predicting and serving: use subsample {k}"
        )


def resize_view(
    color: np.ndarray | None, depth: np.ndarray, camera: Camera, size: tuple[int, int]
) -> tuple[np.ndarray | None, np.ndarray, Camera, tuple[float, float]]:
    """Resize one view to fit inside ``size (W, H)``, keeping its aspect ratio (the network pads the rest).

    An integer subsampling uses the MVOR reader's functions (colour block mean, depth lower median of the valid
    pixels); other sizes use colour INTER_AREA, depth nearest (no blending of unknown 0s into known depths). The camera
    follows exactly, per axis, with the rule u' = (u + 0.5) s - 0.5 of ``Camera.scale``. Returns the new
    colour, depth, camera and the factors ``(sx, sy)`` to apply to boxes.
    """
    H, W = depth.shape
    f = min(size[0] / W, size[1] / H)
    new = (max(1, round(W * f)), max(1, round(H * f)))
    if new == (W, H):
        return color, depth, camera, (1.0, 1.0)
    sx, sy = new[0] / W, new[1] / H
    k = W // new[0]
    if W == k * new[0] and H == k * new[1]:
        # An integer subsampling (640x480 -> 320x240): the reader's own functions, so that a frame served over
        # HTTP at full resolution meets the network exactly as it did in training and offline evaluation.
        from posenet.data.images import subsample_color, subsample_depth

        color = None if color is None else subsample_color(color, k)
        depth = subsample_depth(depth, k)
    else:
        if color is not None:
            color = cv2.resize(color, new, interpolation=cv2.INTER_AREA)
        depth = cv2.resize(depth, new, interpolation=cv2.INTER_NEAREST)
    K = camera.intrinsics.clone()
    K[..., 0], K[..., 2] = K[..., 0] * sx, rescale_pixels(K[..., 2], sx)
    K[..., 1], K[..., 3] = K[..., 1] * sy, rescale_pixels(K[..., 3], sy)
    return color, depth, Camera(K, camera.extrinsics, camera.distortion, new), (sx, sy)


def _input_views(views: Sequence[SceneView], config: InputConfig) -> list[SceneView]:
    """``views`` as :class:`posenet.scene.SceneView` s (``(color, depth, camera)`` tuples too), checked: at least one,
    and colour in each where the config's modality reads it."""
    if not views:
        raise ValueError("a scene needs at least one view")
    views = scene_views(views)
    if config.modality != "depth" and any(v.color is None for v in views):
        raise ValueError(f"modality {config.modality!r} needs colour images, but a view has none")
    return views


def _at_read_size(
    views: Sequence[SceneView], config: InputConfig
) -> tuple[Sequence[SceneView], Tensor | None]:
    """The views resized to ``config.read_size`` (:func:`resize_view`) and each view's box factors ``(V, 4)``
    (sx, sy, sx, sy); the views as given and None when the config reads them as given."""
    if config.read_size is None:
        return views, None
    resized = [resize_view(v.color, v.depth, v.camera, config.read_size) for v in views]
    factors = torch.tensor([r[3] for r in resized], dtype=torch.float32).repeat(1, 2)
    return [SceneView(*r[:3]) for r in resized], factors


def _stack_views(
    views: Sequence[SceneView],
) -> tuple[Tensor | None, Tensor, Camera]:
    shapes = {v.depth.shape for v in views}
    if len(shapes) != 1:
        raise ValueError(f"all views must have the same image size, got {sorted(shapes)}")
    for i, (color, depth, _cam) in enumerate(views):
        if depth.ndim != 2:
            raise ValueError(f"view {i}: depth must be (H, W), got {depth.shape}")
        if color is not None and color.shape != (*depth.shape, 3):
            raise ValueError(
                f"view {i}: colour must be {(*depth.shape, 3)} like its depth, got {color.shape}"
            )
    depth = torch.from_numpy(np.stack([v.depth.astype(np.float32) for v in views]))[:, None]  # (V, 1, H, W)
    colors = [v.color for v in views]
    color = None
    if all(c is not None for c in colors):
        color = torch.from_numpy(np.stack(colors)).permute(0, 3, 1, 2).float() / 255  # (V, 3, H, W)
    return color, depth, Camera.stack([v.camera for v in views])


def _in_box(uv: Tensor, boxes: Tensor) -> Tensor:
    """uv (N, M, 2) inside boxes (N, 4) xyxy (pixel centres on the edge count as inside)."""
    u, v = uv[..., 0], uv[..., 1]
    b = boxes[:, None, :]
    return (u >= b[..., 0] - 0.5) & (u <= b[..., 2] + 0.5) & (v >= b[..., 1] - 0.5) & (v <= b[..., 3] + 0.5)


def _view_grids(src: Tensor, P: int, V: int, size: tuple[int, int], image_size: tuple[int, int]) -> Tensor:
    """``src (P*V, h*w, 2)``, every network pixel's original pixel (``augment.network_pixels_in_original``), as
    grid_sample's grids ``(V, h, P*w, 2)`` on images of ``image_size (W, H)``: the P persons' grids of one view
    side by side along the width, so that grid_sample runs once per view (:func:`_sample_per_view`)."""
    w, h = size
    src = src.view(P, V, h, w, 2).permute(1, 2, 0, 3, 4)  # (V, h, P, w, 2)
    return aug._normalise(src.reshape(V, h, P * w, 2), image_size)


def _sample_per_view(images: Tensor, grids: Tensor, P: int, size: tuple[int, int], mode: str) -> Tensor:
    """Sample ``images (V, C, H, W)`` at :func:`_view_grids`' ``grids`` into ``(P*V, C, h, w)``, without P
    copies of the images."""
    V, C = images.shape[:2]
    w, h = size
    out = torch.nn.functional.grid_sample(images, grids, mode=mode, padding_mode="zeros", align_corners=False)
    # (with V or P = 1 reshape may return a strided view; later .view calls need contiguous memory)
    return (
        out.view(V, C, h, P, w).permute(3, 0, 1, 2, 4).reshape(P * V, C, h, w).contiguous()
    )  # (P*V, C, h, w)


def _network_channels(rgb: Tensor | None, d_net: Tensor, mask: Tensor, config: InputConfig) -> Tensor:
    """The U-Net's input ``(N, C, h, w)`` from each crop's sampled colour ``rgb (N, 3, h, w)`` in [0, 1] (None
    without colour), depth ``d_net (N, 1, h, w)`` mm and box mask ``mask (N, h*w)`` (the channel list of the
    module docstring). Each channel is written into its place of one tensor (no list of channels concatenated)."""
    N, h, w = d_net.shape[0], *d_net.shape[-2:]
    out = d_net.new_empty(N, config.in_channels, h, w)
    known = d_net > 0
    c = 0
    if config.modality in ("rgb", "rgbd"):
        torch.mul(rgb, 2, out=out[:, :3]).sub_(1)
        c = 3
    if config.modality in ("depth", "rgbd"):
        norm = (d_net - config.depth_centre) / config.depth_range
        torch.where(known, norm, torch.full_like(norm, -2.0), out=out[:, c : c + 1])
        c += 1
        if config.extra_depth:
            in_box = mask.view(-1, 1, h, w) & known
            med = torch.nanmedian(torch.where(in_box, d_net, torch.nan).flatten(1), dim=1).values  # (N,)
            med = torch.nan_to_num(med, nan=config.depth_centre).view(-1, 1, 1, 1)
            rel = ((d_net - med) / 1000).clamp(-1.5, 1.5)
            torch.where(known, rel, torch.zeros_like(rel), out=out[:, c : c + 1])
            out[:, c + 1 : c + 2].copy_(known)
            c += 2
    out[:, c : c + 1].copy_(mask.view(-1, 1, h, w))
    return out


@dataclass
class BoxCrops:
    """The network inputs and lifting points of every box of a frame, one crop per box (crop mode, inference):
    what :func:`build_scene` gives for the (slot, view) pairs that hold a box, without the empty pairs.

    Attributes:
        images: (N, C, h, w) network inputs of the N boxes, in view order.
        A: (N, 3, 3) original pixels -> network pixels.
        flipped: (N,) whether the network image is mirrored.
        view: (N,) each box's view.
        cameras: batch shape (V,), of the (possibly resized) images that ``uv`` refers to.
        uv: (N, M, 2) original pixel coordinates of the crop's points; depth (N, M) mm there (0 = unknown);
            valid (N, M) the points that may vote (in the box, known depth).
    """

    images: Tensor
    A: Tensor
    flipped: Tensor
    view: Tensor
    cameras: Camera
    uv: Tensor
    depth: Tensor
    valid: Tensor


def build_box_crops(
    views: Sequence[SceneView], boxes: Sequence[np.ndarray], config: InputConfig, mirror: bool = False
) -> BoxCrops:
    """:func:`build_scene` at test time in crop mode for V lists of boxes ``(K_v, 4)`` xyxy (K_v may be 0), packed:
    the crop of box i equals ``build_scene``'s for its (slot, view) pair bit for bit, and no crop is computed for a
    pair without a box (``posenet.net.box_poses.box_heatmaps``: 17 boxes of 3 views make 17 crops, not 8 x 3)."""
    if config.mode != "crop":
        raise ValueError("build_box_crops is for crop mode; use build_scene in full mode")
    views = _input_views(views, config)
    V = len(views)
    if len(boxes) != V:
        raise ValueError(f"got {len(boxes)} box lists for {V} views")
    per_view = [torch.as_tensor(np.asarray(b, np.float32).reshape(-1, 4)) for b in boxes]
    counts = [len(b) for b in per_view]
    view = torch.repeat_interleave(torch.arange(V), torch.tensor(counts, dtype=torch.long))  # (N,)
    flat = torch.cat(per_view) if per_view else torch.zeros(0, 4)
    views, factors = _at_read_size(views, config)
    if factors is not None:
        flat = rescale_pixels(flat, factors[view])
    color, depth, cameras = _stack_views(views)
    H, W = depth.shape[-2:]
    size = config.network_size(False)
    w, h = size
    N = flat.shape[0]
    A = aug.box_crop_affine(flat, config.crop_size, config.crop_margin)
    flipped = torch.full((N,), mirror, dtype=torch.bool)
    if mirror:
        A = aug.hflip(flipped, size[0]) @ A
    src = aug.network_pixels_in_original(A, size)  # (N, h*w, 2)
    mask = _in_box(src, flat)  # (N, h*w)
    grids = aug._normalise(src, (W, H))

    def sample(images: Tensor, mode: str) -> Tensor:  # one grid_sample per view, its crops side by side
        out, start = [], 0
        for v, n in enumerate(counts):
            if n:
                grid = grids[start : start + n].view(n, h, w, 2).permute(1, 0, 2, 3).reshape(1, h, n * w, 2)
                got = torch.nn.functional.grid_sample(
                    images[v : v + 1], grid, mode=mode, padding_mode="zeros", align_corners=False
                )
                out.append(got.view(images.shape[1], h, n, w).permute(2, 0, 1, 3))
            start += n
        if not out:
            return images.new_zeros(0, images.shape[1], h, w)
        return torch.cat(out).contiguous()

    d_net = sample(depth, "nearest")  # (N, 1, h, w)
    rgb = sample(color, "bilinear") if config.modality in ("rgb", "rgbd") else None
    images = _network_channels(rgb, d_net, mask, config)
    d = d_net.reshape(N, h * w)
    return BoxCrops(images, A, flipped, view, cameras, src, d, mask & (d > 0))


def build_scene(
    views: Sequence[SceneView],
    boxes: Tensor,
    has_box: Tensor,
    config: InputConfig,
    augment: aug.AugmentConfig | None = None,
    generator: torch.Generator | None = None,
    mirror: bool = False,
) -> SceneInput:
    """The network inputs and lifting points of one scene.

    Args:
        views: V :class:`posenet.scene.SceneView`\\ s (color (H, W, 3) uint8 or None, depth (H, W) uint16 mm,
            camera) of one size: a :class:`posenet.scene.Scene`'s views.
        boxes: (P, V, 4) xyxy boxes in those images' pixels (ignored where ``has_box`` is False).
        has_box: (P, V) bool.
        config: the input configuration.
        augment: None at test time; else the random augmentation to draw (per person and view).
        mirror: flip every network image horizontally (test-time flip averaging; undone like any flip).
    """
    views = _input_views(views, config)
    V = len(views)
    boxes = torch.as_tensor(boxes, dtype=torch.float32)
    has_box = torch.as_tensor(has_box, dtype=torch.bool)
    if boxes.ndim != 3 or boxes.shape[1:] != (V, 4) or has_box.shape != boxes.shape[:2]:
        raise ValueError(
            f"boxes must be (P, {V}, 4) and has_box (P, {V}), "
            f"got {tuple(boxes.shape)}, {tuple(has_box.shape)}"
        )
    views, factors = _at_read_size(views, config)
    if factors is not None:
        boxes = rescale_pixels(boxes, factors.view(1, V, 4))
    color, depth, cameras = _stack_views(views)
    H, W = depth.shape[-2:]
    P = boxes.shape[0]
    training = augment is not None
    size = config.network_size(training)

    # ---- the per (person, view) affine: base (crop or window) then the random jitter and flip
    flat_boxes = boxes.reshape(P * V, 4)  # (P*V, 4)
    safe = torch.where(has_box.reshape(-1, 1), flat_boxes, torch.tensor([0.0, 0.0, W - 1.0, H - 1.0]))
    if config.mode == "crop":
        A = aug.box_crop_affine(safe, config.crop_size, config.crop_margin)
    elif training and augment.crop:
        A = aug.random_crop_window(P * V, (W, H), size, generator)
    else:
        # Full mode without the random window: centre the network image on the original one.
        off = torch.tensor([(size[0] - W) / 2, (size[1] - H) / 2])
        A = aug.translation(off[0].expand(P * V), off[1].expand(P * V))
    flipped = torch.zeros(P * V, dtype=torch.bool)
    if training:
        J, flipped = aug.random_jitter(P * V, augment, size, config.mode == "crop", generator)
        A = J @ A
    if mirror:
        flipped = ~flipped
        A = aug.hflip(torch.ones(P * V, dtype=torch.bool), size[0]) @ A

    # ---- network input
    src = aug.network_pixels_in_original(A, size)  # (P*V, h*w, 2)
    w, h = size
    mask = _in_box(src, safe) & has_box.reshape(-1, 1)  # (P*V, h*w)
    grids = _view_grids(src, P, V, size, (W, H))  # colour and depth share the image size
    d_net = _sample_per_view(depth, grids, P, size, "nearest")  # (P*V, 1, h, w)
    rgb = None
    if config.modality in ("rgb", "rgbd"):
        rgb = _sample_per_view(color, grids, P, size, "bilinear")
        if training and augment.color:
            rgb = aug.color_jitter(rgb, augment, generator)
        if training and augment.color_drop > 0:
            rgb = aug.color_dropout(rgb, augment.color_drop, generator)
    images = _network_channels(rgb, d_net, mask, config)  # (P*V, C, h, w)
    if training and augment.occlude > 0:
        images = aug.occluders(images, augment.occlude, generator)

    # ---- the points to lift
    if config.mode == "crop":
        uv = src.reshape(P, V, h * w, 2)
        d = d_net.reshape(P, V, h * w)
        valid = mask.reshape(P, V, h * w) & (d > 0)
    else:
        uv = aug._grid(H, W, None, torch.float32).view(1, 1, H * W, 2).expand(1, V, H * W, 2)
        d = depth.view(1, V, H * W)
        grid_in_box = _in_box(uv.expand(P, V, H * W, 2).reshape(P * V, H * W, 2), safe)  # (P*V, H*W)
        valid = grid_in_box.view(P, V, H * W) & has_box.view(P, V, 1) & (d > 0)
    return SceneInput(images, A, flipped, has_box, cameras, uv, d, valid, (W, H), config.mode)
