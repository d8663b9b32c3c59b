import math

import numpy as np
import torch

from posenet.cameras import Camera
from posenet.net import augment as aug
from posenet.net.box_poses import slot_layout
from posenet.net.inputs import InputConfig, build_box_crops, build_scene
from posenet.skeleton import FLIP_PERMUTATION, JOINTS


def _smooth_image(n=2, c=3, h=40, w=56):
    v, u = torch.meshgrid(
        torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij"
    )
    chans = [torch.sin(u / 7 + k) * torch.cos(v / 9 - k) for k in range(c)]
    return torch.stack(chans).expand(n, c, h, w).clone()


def test_affine_round_trip_of_pixels():
    g = torch.Generator().manual_seed(0)
    J, _ = aug.random_jitter(5, aug.AugmentConfig(), (32, 32), person_crop=True, generator=g)
    A = J @ aug.box_crop_affine(torch.tensor([[10.0, 20, 60, 90]]).expand(5, 4), 32)
    src = aug.network_pixels_in_original(A, (32, 32))  # (5, 1024, 2)
    back = src @ A[:, :2, :2].transpose(1, 2) + A[:, None, :2, 2]
    grid = aug._grid(32, 32, None, torch.float32).expand(5, -1, -1)
    torch.testing.assert_close(back, grid, atol=1e-3, rtol=0)


def test_flip_and_integer_crop_invert_exactly():
    img = _smooth_image()
    flipped = torch.tensor([True, False])
    A = aug.hflip(flipped, 40) @ aug.translation(torch.tensor([-7.0, -3.0]), torch.tensor([-5.0, 0.0]))
    net = aug.warp(img, A, (40, 32))
    torch.testing.assert_close(net[0], img[0, :, 5:37, 7:47].flip(-1))
    back = aug.inverse_warp(net, A, (56, 40))
    torch.testing.assert_close(back[0, :, 5:37, 7:47], img[0, :, 5:37, 7:47])
    torch.testing.assert_close(back[1, :, 0:32, 3:43], img[1, :, 0:32, 3:43])
    assert (back[0, :, :5] == 0).all() and (back[0, :, :, 48:] == 0).all()  # zero padding outside the crop


def test_rotation_round_trip_interior():
    img = _smooth_image(n=1)
    A = aug.about_centre(aug.rotation(torch.tensor([12 * math.pi / 180])), (56, 40))
    back = aug.inverse_warp(aug.warp(img, A, (56, 40)), A, (56, 40))
    inner = (slice(None), slice(None), slice(12, 28), slice(16, 40))
    assert (back[inner] - img[inner]).abs().max() < 0.02  # two bilinear resamplings of a smooth image


def test_inverse_warp_is_differentiable():
    A = aug.about_centre(aug.rotation(torch.tensor([0.2])), (8, 8))
    heat = torch.randn(1, 2, 8, 8, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda h: aug.inverse_warp(h, A, (10, 9)), (heat,))


def test_flip_swaps_left_and_right():
    assert JOINTS[FLIP_PERMUTATION[JOINTS.index("left_wrist")]] == "right_wrist"
    # A mirror-equivariant "network": on the flipped image, the person's left shoulder looks like a right one.
    heat = torch.zeros(1, 10, 12, 16)
    heat[0, JOINTS.index("left_shoulder"), 4, 3] = 1.0
    heat[0, JOINTS.index("head"), 2, 8] = 1.0
    A = aug.hflip(torch.tensor([True]), 16)
    network_out = aug.warp(heat, A, (16, 12))[:, list(FLIP_PERMUTATION)]
    assert network_out[0, JOINTS.index("right_shoulder"), 4, 12] == 1.0
    back = aug.unflip_channels(aug.inverse_warp(network_out, A, (16, 12)), torch.tensor([True]))
    torch.testing.assert_close(back, heat)
    kept = aug.unflip_channels(heat, torch.tensor([False]))
    torch.testing.assert_close(kept, heat)


def test_color_jitter_range_and_identity():
    g = torch.Generator().manual_seed(1)
    x = torch.rand(4, 3, 8, 8, generator=g)
    y = aug.color_jitter(x, aug.AugmentConfig(), g)
    assert y.min() >= 0 and y.max() <= 1 and not torch.allclose(x, y)
    none = aug.AugmentConfig(brightness=0, contrast=0, saturation=0)
    torch.testing.assert_close(aug.color_jitter(x, none, g), x)


def test_box_crop_maps_box_to_crop():
    A = aug.box_crop_affine(torch.tensor([[100.0, 50, 140, 130]]), 64, margin=1.0)
    # the square crop of side 80 spans u in [80, 160] (continuous): it must land on the network's outer edges
    edges = torch.tensor([[[80.0, 90.0], [160.0, 90.0], [120.0, 50.0]]])
    mapped = edges @ A[:, :2, :2].transpose(1, 2) + A[:, None, :2, 2]
    expected = torch.tensor([[-0.5, 31.5], [63.5, 31.5], [31.5, -0.5]])
    torch.testing.assert_close(mapped[0], expected, atol=1e-4, rtol=0)


def test_crop_points_carry_original_pixels_and_depth():
    rng = np.random.default_rng(0)
    H, W = 60, 80
    depth = rng.integers(1000, 4000, (H, W)).astype(np.uint16)
    depth[:, :5] = 0
    color = rng.integers(0, 255, (H, W, 3)).astype(np.uint8)
    views = [(color, depth, Camera.create(50, 50, 40, 30))] * 2
    boxes = torch.tensor([[[2.0, 10, 40, 50], [20, 5, 60, 55]]])
    cfg = InputConfig(mode="crop", crop_size=32)
    scene = build_scene(
        views,
        boxes,
        torch.ones(1, 2, dtype=torch.bool),
        cfg,
        aug.AugmentConfig(),
        torch.Generator().manual_seed(3),
    )
    uv = scene.uv.reshape(-1, 2)
    inside = (uv[:, 0] > -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] > -0.5) & (uv[:, 1] < H - 0.5)
    iu, iv = uv[inside].round().long().unbind(-1)
    torch.testing.assert_close(
        scene.depth.reshape(-1)[inside], torch.from_numpy(depth.astype(np.float32))[iv, iu]
    )
    assert (scene.depth.reshape(-1)[~inside] == 0).all()
    assert not scene.valid.reshape(-1)[scene.depth.reshape(-1) == 0].any()
    assert scene.images.shape == (2, cfg.in_channels, 32, 32)


def test_packed_box_crops_equal_the_scene_crops_bit_for_bit():
    """build_box_crops (inference: one crop per box) against build_scene's (slot, view) pairs that hold a box:
    3 views with 2 / 0 / 3 boxes, read at half size (the resize inside), plain and mirrored."""
    rng = np.random.default_rng(1)
    H, W = 60, 80
    views = []
    for i in range(3):
        depth = rng.integers(800, 5000, (H, W)).astype(np.uint16)
        depth[rng.random((H, W)) < 0.1] = 0
        color = rng.integers(0, 255, (H, W, 3)).astype(np.uint8)
        views.append((color, depth, Camera.create(50 + i, 52, 40, 30)))
    boxes = [
        np.array([[2.0, 10, 40, 50], [30.5, 5, 78, 58]], np.float32),
        np.zeros((0, 4), np.float32),
        np.array([[0.0, 0, 20, 30], [10, 12.5, 70, 59], [50, 20, 79, 40]], np.float32),
    ]
    cfg = InputConfig(mode="crop", crop_size=32, source_size=(40, 30))
    dense, has, view, index = slot_layout(boxes)
    slot = index * 3 + view  # each box's row of the (slot, view) grid
    for mirror in (False, True):
        scene = build_scene(views, dense, has, cfg, mirror=mirror)
        crops = build_box_crops(views, boxes, cfg, mirror=mirror)
        assert torch.equal(crops.view, view)
        assert torch.equal(crops.images, scene.images[slot])
        assert torch.equal(crops.A, scene.A[slot]) and torch.equal(crops.flipped, scene.flipped[slot])
        assert torch.equal(crops.uv, scene.uv.flatten(0, 1)[slot])
        assert torch.equal(crops.depth, scene.depth.flatten(0, 1)[slot])
        assert torch.equal(crops.valid, scene.valid.flatten(0, 1)[slot])
    empty = build_box_crops(views, [np.zeros((0, 4), np.float32)] * 3, cfg)
    assert empty.images.shape == (0, cfg.in_channels, 32, 32) and empty.uv.shape == (0, 32 * 32, 2)


def test_affine_inverse_matches_linalg():
    g = torch.Generator().manual_seed(5)
    J, _ = aug.random_jitter(6, aug.AugmentConfig(), (48, 32), person_crop=True, generator=g)
    A = J @ aug.box_crop_affine(torch.rand(6, 4, generator=g).sort(-1).values * 100, 48)
    torch.testing.assert_close(aug.affine_inverse(A), torch.linalg.inv(A), atol=1e-4, rtol=1e-4)


def test_occluders_cover_one_rectangle_and_keep_the_mask():
    g = torch.Generator().manual_seed(2)
    x = torch.randn(8, 5, 20, 24)
    y = aug.occluders(x, 1.0, g)
    torch.testing.assert_close(y[:, -1], x[:, -1])
    changed = (y != x)[:, :-1].any(1)  # (N, H, W)
    for n in range(8):
        rows, cols = changed[n].any(1).nonzero(), changed[n].any(0).nonzero()
        area = (rows.max() - rows.min() + 1) * (cols.max() - cols.min() + 1)
        assert changed[n].sum() == area  # exactly one filled rectangle
        assert 0.01 * 20 * 24 <= area <= 0.41 * 0.41 * 20 * 24 + 25
    torch.testing.assert_close(aug.occluders(x, 0.0, g), x)


def test_unflip_mixed_batch_matches_per_sample_permutation():
    x = torch.randn(3, 10, 4, 5)
    out = aug.unflip_channels(x, torch.tensor([True, False, True]))
    torch.testing.assert_close(out[0], x[0, list(FLIP_PERMUTATION)])
    torch.testing.assert_close(out[1], x[1])
    torch.testing.assert_close(out[2], x[2, list(FLIP_PERMUTATION)])
    torch.testing.assert_close(
        aug.unflip_channels(out, torch.tensor([True, False, True])), x
    )  # an involution


def test_detector_like_boxes_stay_valid_and_leave_the_rest_alone():
    detector_like_boxes = aug.detector_like_boxes
    g = torch.Generator().manual_seed(3)
    P, V, sizes = 6, 3, [(640, 480), (320, 240), (640, 480)]
    x0 = torch.rand(P, V, 2, generator=g) * 200
    boxes = torch.cat([x0, x0 + 40 + torch.rand(P, V, 2, generator=g) * 150], -1)
    has = torch.rand(P, V, generator=g) < 0.7
    assert torch.equal(
        detector_like_boxes(boxes, has, sizes, aug.AugmentConfig(), g), boxes
    )  # off by default
    cfg = aug.AugmentConfig(box_noise=1.0, box_truncate=0.5, box_merge=0.3)
    outs = [detector_like_boxes(boxes, has, sizes, cfg, torch.Generator().manual_seed(s)) for s in range(50)]
    again = detector_like_boxes(boxes, has, sizes, cfg, torch.Generator().manual_seed(0))
    assert torch.equal(outs[0], again)  # deterministic for a seed
    limit = torch.tensor([[w - 1.0, h - 1.0] for w, h in sizes]).repeat(1, 2)
    merged = 0
    for out in outs:
        assert torch.equal(out[~has], boxes[~has])  # persons without a box in a view keep none
        b = out[has]
        assert (b[:, 2:] - b[:, :2] >= 2 - 1e-4).all() and (b >= 0).all()
        assert (b <= limit.expand(P, V, 4)[has]).all()  # within the image
        assert not torch.equal(out, boxes)
        # two persons in one box: some box now holds another person's whole box of its view
        for p in range(P):
            for v in range(V):
                others = [q for q in range(P) if q != p and has[q, v]]
                merged += has[p, v] and any(
                    (out[p, v, :2] <= boxes[q, v, :2]).all() and (out[p, v, 2:] >= boxes[q, v, 2:]).all()
                    for q in others
                )
    assert merged > 0


def test_color_dropout_greys_whole_images_and_leaves_the_rest():
    rgb = torch.rand(64, 3, 8, 8, generator=torch.Generator().manual_seed(0))
    assert torch.equal(aug.color_dropout(rgb, 0.0, torch.Generator().manual_seed(1)), rgb)
    assert torch.equal(
        aug.color_dropout(rgb, 1.0, torch.Generator().manual_seed(1)), torch.full_like(rgb, 0.5)
    )
    out = aug.color_dropout(rgb, 0.5, torch.Generator().manual_seed(1))
    assert torch.equal(out, aug.color_dropout(rgb, 0.5, torch.Generator().manual_seed(1)))  # seeded
    grey = (out == 0.5).flatten(1).all(1)
    kept = (out == rgb).flatten(1).all(1)
    assert torch.equal(grey, ~kept) and 16 < int(grey.sum()) < 48  # whole images, about half of them


def test_color_drop_in_build_scene_greys_colour_only():
    H, W = 60, 80
    rng = np.random.default_rng(0)
    color = rng.integers(0, 255, (H, W, 3), dtype=np.uint8)
    depth = rng.integers(1500, 4000, (H, W), dtype=np.uint16)
    views = [(color, depth, Camera.create(50, 50, 40, 30))] * 2
    boxes = torch.tensor([[[2.0, 10, 40, 50], [20, 5, 60, 55]]])
    cfg = InputConfig(mode="crop", crop_size=32)

    def scene(drop: float):
        augment = aug.AugmentConfig(color_drop=drop)
        return build_scene(
            views, boxes, torch.ones(1, 2, dtype=torch.bool), cfg, augment, torch.Generator().manual_seed(3)
        )

    kept, dropped = scene(0.0), scene(1.0)
    assert torch.equal(dropped.images[:, :3], torch.zeros_like(dropped.images[:, :3]))  # mid grey, normalised
    assert not torch.equal(kept.images[:, :3], dropped.images[:, :3])
    assert torch.equal(kept.images[:, 3:], dropped.images[:, 3:])  # depth channels and box mask untouched
    assert torch.equal(kept.A, dropped.A) and torch.equal(kept.valid, dropped.valid)
