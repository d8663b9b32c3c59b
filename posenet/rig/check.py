"""Sanity checks of a rig, and a calibration check from one depth frame per view that needs no target.

``sanity_checks(rig)`` returns ``(level, message)`` pairs, level ``OK`` / ``WARN`` / ``FAIL``:
- rigid extrinsics (rotation orthonormal with det +1, last row 0 0 0 1);
- plausible intrinsics: fx, fy > 0, fx / fy near 1, the principal point inside the image, a field of view of
  30 to 140 degrees (where the image size is known);
- units: a camera spacing that is plausible in mm (``posenet.rig.geometry``);
- a common volume: the point nearest all optical axes is in front of every camera and inside its image.

``depth_agreement(rig, depths)`` lifts every view's depth pixels to 3D (``Camera.unproject``), moves them into each
other view and compares their depth there with what that view measured. Where two views see the same surface the
difference is the calibration error plus sensor noise; points hidden behind something in the other view differ by a
lot and only by a positive amount (the other view sees something nearer), so the robust numbers are the median
absolute difference and the share within 50 mm, over the points visible to both.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import torch

from posenet.cameras import Camera, is_rigid, pixel_grid, transform_points
from posenet.rig.geometry import PLAUSIBLE_SPACING_MM, camera_spacing, common_view, image_up
from posenet.rig.rigfile import Rig

FOV_RANGE_DEG = (30.0, 140.0)
AGREE_MM = 50.0
# floor_of_frame's default sampling: within 0.3 degrees of the room frame on rendered frames.
FLOOR_POINTS_PER_VIEW = 3000


def field_of_view(camera: Camera) -> tuple[float, float] | None:
    """Horizontal and vertical field of view in degrees of an unbatched camera, or None without an image size."""
    if camera.size is None:
        return None
    w, h = camera.size
    fx, fy = float(camera.fx), float(camera.fy)
    return 2 * math.degrees(math.atan(w / 2 / fx)), 2 * math.degrees(math.atan(h / 2 / fy))


def sanity_checks(rig: Rig) -> list[tuple[str, str]]:
    out = []
    for i, (name, c) in enumerate(zip(rig.names, rig.cameras, strict=True)):
        tag = f"camera {i} ({name})"
        if not bool(is_rigid(c.extrinsics)):
            out.append(("FAIL", f"{tag}: extrinsics are not a rigid transform"))
        fx, fy, cx, cy = (float(v) for v in c.intrinsics)
        if fx <= 0 or fy <= 0:
            out.append(("FAIL", f"{tag}: focal lengths must be positive, got fx {fx}, fy {fy}"))
            continue
        if not 0.8 <= fx / fy <= 1.25:
            out.append(("WARN", f"{tag}: fx / fy = {fx / fy:.2f}: pixels are rarely that far from square"))
        fov = field_of_view(c)
        if fov is None:
            out.append(
                ("WARN", f"{tag}: no image size, so the principal point and field of view are unchecked")
            )
            continue
        w, h = c.size
        if not (0 <= cx <= w and 0 <= cy <= h):
            out.append(("FAIL", f"{tag}: principal point ({cx:.1f}, {cy:.1f}) outside the {w}x{h} image"))
        elif abs(cx - (w - 1) / 2) > 0.1 * w or abs(cy - (h - 1) / 2) > 0.1 * h:
            out.append(
                ("WARN", f"{tag}: principal point ({cx:.1f}, {cy:.1f}) is far from the centre of {w}x{h}")
            )
        lo, hi = FOV_RANGE_DEG
        level = "OK" if lo <= fov[0] <= hi and lo <= fov[1] <= hi else "WARN"
        out.append(
            (
                level,
                f"{tag}: {w}x{h}, fx {fx:.1f} fy {fy:.1f} px, field of view {fov[0]:.0f} x {fov[1]:.0f} deg",
            )
        )
    spacing = camera_spacing(rig.cameras)
    if spacing is not None:
        lo, hi = PLAUSIBLE_SPACING_MM
        ok = lo <= spacing <= hi
        out.append(("OK" if ok else "FAIL", f"units: cameras a median {spacing:.0f} mm apart"
                    + ("" if ok else f"; outside {lo:.0f}..{hi:.0f} mm: are the translations in mm?")))  # fmt: skip
        view = common_view(rig.stacked)
        n = int(view["in_view"].sum())
        p = view["point"].tolist()
        dist = ", ".join(f"{float(d):.0f}" for d in view["axis_distance_mm"])
        out.append(
            ("OK" if n == len(rig) else "WARN" if n >= 2 else "FAIL",
             f"common volume: the point nearest all optical axes, ({p[0]:.0f}, {p[1]:.0f}, {p[2]:.0f}) mm, is in "
             f"view of {n}/{len(rig)} cameras; axes pass it at {dist} mm")
        )  # fmt: skip
    if rig.first_is_reference:
        out.append(("OK", "reference frame: camera 0 (its extrinsics are the identity)"))
    else:
        out.append(("OK", f"reference frame: {rig.frame} (camera 0's extrinsics are not the identity)"))
    return out


DEPTH_RANGE_MM = (300.0, 15_000.0)  # the median valid depth of an OR camera's frame, in millimetres


def median_depth(depth: np.ndarray) -> tuple[float | None, bool]:
    """The median of a uint16 depth frame's valid (non-zero) pixels, or None without any; and whether it lies in
    ``DEPTH_RANGE_MM`` (a frame in mm, not in metres, centimetres or 0.1 mm)."""
    if depth.dtype == np.uint16:  # np.median's value from a histogram of the 65,536 depths: no sort
        counts = np.bincount(depth.ravel())
        counts[0] = 0
        cum = np.cumsum(counts)
        n = int(cum[-1])
        if not n:
            return None, False
        median = float(np.searchsorted(cum, (n - 1) // 2 + 1) + np.searchsorted(cum, n // 2 + 1)) / 2
    else:
        valid = depth[depth > 0]
        if not valid.size:
            return None, False
        median = float(np.median(valid))
    return median, DEPTH_RANGE_MM[0] <= median <= DEPTH_RANGE_MM[1]


def depth_checks(depths: list[np.ndarray]) -> list[tuple[str, str]]:
    """Whether each uint16 depth frame looks like millimetres: its median valid depth is 0.3 to 15 m."""
    out = []
    for i, d in enumerate(depths):
        median, ok = median_depth(d)
        if median is None:
            out.append(("FAIL", f"depth frame {i}: no valid (non-zero) pixel"))
            continue
        valid = d[d > 0]
        hint = "" if ok else " (are the units mm? 0.1 mm or cm units would read 10x too far or too near)"
        out.append(
            (
                "OK" if ok else "WARN",
                f"depth frame {i}: median {median:.0f} mm, {100 * valid.size / d.size:.0f} % valid{hint}",
            )
        )
    return out


def lift_depth(camera: Camera, depth: np.ndarray, stride: int = 4) -> torch.Tensor:
    """(N, 3) reference-frame points of every ``stride``-th valid pixel of a (H, W) uint16 mm depth image."""
    sub = depth[::stride, ::stride]
    grid = (pixel_grid(*sub.shape, dtype=torch.float64) * stride).reshape(-1, 2)  # (N, 2): pixels of the image
    d = torch.as_tensor(sub.astype(np.float64)).reshape(-1)
    keep = d > 0
    return camera.unproject(grid[keep], d[keep])[1]


def camera_agreement(results: list[dict], V: int) -> list[float]:
    """Per camera, the mean share of agreeing points over the pairs it is part of (the odd one out scores lowest)."""
    out = []
    for v in range(V):
        shares = [r["within"] for r in results if v in r["pair"] and r["within"] == r["within"]]
        out.append(sum(shares) / len(shares) if shares else float("nan"))
    return out


def depth_agreement(rig: Rig, depths: list[np.ndarray], stride: int = 4) -> list[dict]:
    """Per ordered view pair (i, j): how view i's depth points agree with view j's depth where j sees them.

    Returns dicts with ``pair`` (i, j), ``overlap`` (share of i's valid points that fall inside j's image, in
    front of it, on a valid depth pixel), ``median_abs_mm`` and ``median_mm`` (j's measured depth minus the point's
    depth in j, over points within 4 x AGREE_MM, i.e. not occluded), ``within`` (share of overlapping points within
    AGREE_MM).
    """
    if len(depths) != len(rig):
        raise ValueError(
            f"{len(depths)} depth frames for {len(rig)} cameras: give one per camera, in rig order"
        )
    for i, (c, d) in enumerate(zip(rig.cameras, depths, strict=True)):
        if c.size is not None and (d.shape[1], d.shape[0]) != tuple(c.size):
            raise ValueError(
                f"depth frame {i} is {d.shape[1]}x{d.shape[0]} but camera {i} is {c.size[0]}x{c.size[1]}"
            )
    clouds = [lift_depth(c, d, stride) for c, d in zip(rig.cameras, depths, strict=True)]
    to_camera = [c.ref_to_camera for c in rig.cameras]  # each inverted once, not once per pair
    found = {}
    for j, (cam, depth) in enumerate(zip(rig.cameras, depths, strict=True)):
        sources = [i for i, points in enumerate(clouds) if i != j and len(points)]
        if not sources:
            continue
        # every other view's points moved into camera j at once (one transform and projection per camera)
        in_j = transform_points(to_camera[j], torch.cat([clouds[i] for i in sources]))  # cam.to_camera(points)
        uv = cam.project_camera(in_j).round().long().numpy()
        z = in_j[:, 2].numpy()
        h, w = depth.shape
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        measured = np.zeros(len(z))
        measured[inside] = depth[uv[inside, 1], uv[inside, 0]]
        seen_all, diff_all = inside & (measured > 0), measured - z
        start = 0
        for i in sources:
            part = slice(start, start + len(clouds[i]))
            start = part.stop
            seen = seen_all[part]
            diff = diff_all[part][seen]
            near = diff[np.abs(diff) < 4 * AGREE_MM]
            found[i, j] = {
                "pair": (i, j),
                "overlap": float(seen.mean()),
                "median_abs_mm": _lower_median(np.abs(near)),
                "median_mm": _lower_median(near),
                "within": float((np.abs(diff) < AGREE_MM).mean()) if len(diff) else float("nan"),
            }  # fmt: skip
    return [found[pair] for pair in sorted(found)]


def _lower_median(values: np.ndarray) -> float:
    """The lower of the two middle values (torch.median's convention), NaN without any."""
    if not len(values):
        return float("nan")
    return float(np.partition(values, (len(values) - 1) // 2)[(len(values) - 1) // 2])


def find_floor(
    points: torch.Tensor, up: torch.Tensor, tries: int = 400, seed: int = 0
) -> tuple[torch.Tensor, float, float] | None:
    """The floor in reference-frame points ``(N, 3)``: (unit normal (3,), height along it, share of inliers).

    RANSAC over planes through three of the lower half of the points (along the guessed ``up``) whose normal is
    within 40 degrees of ``up``: the plane with the most points within 40 mm wins and is refitted to them. None when
    no such plane holds 5 % of the points.
    """
    up = up / up.norm()
    low = points[(points @ up) <= (points @ up).median()]
    if len(low) < 3:
        return None
    g = torch.Generator().manual_seed(seed)
    tri = low[torch.randint(len(low), (tries, 3), generator=g)]  # (T, 3, 3)
    normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-9)
    normal = normal * torch.sign(normal @ up).unsqueeze(-1)  # (T, 3), pointing up
    offset = (normal * tri[:, 0]).sum(-1)  # (T,)
    inliers = ((points @ normal.T) - offset).abs() < 40  # (N, T)
    score = inliers.sum(0) * ((normal @ up) > math.cos(math.radians(40)))
    best = int(score.argmax())
    if int(score[best]) < 0.05 * len(points):
        return None
    near = points[inliers[:, best]]
    centre = near.mean(0)
    n = torch.linalg.svd(near - centre, full_matrices=False).Vh[-1]
    n = n if float(n @ up) > 0 else -n
    height = float(centre @ n)
    return n, height, float((((points @ n) - height).abs() < 40).float().mean())


def floor_of_frame(
    cameras: list[Camera],
    depths: list[np.ndarray],
    guess: torch.Tensor | None = None,
    stride: int | None = None,
) -> tuple[torch.Tensor, float, float] | None:
    """The floor seen in one synchronised frame's depth images (uint16 mm, each at its camera's resolution):
    :func:`find_floor` on every view's points (:func:`lift_depth`), around ``guess`` (default: the cameras' mean
    image-up axis, ``posenet.rig.geometry.image_up``). ``stride``: every how many pixels (default: about
    ``FLOOR_POINTS_PER_VIEW`` points per view, whatever the resolution). Returns (the room's up (3,), unit, in the
    reference frame; the floor's height along it, mm; share of the points on it), or None when no floor is seen."""
    guess = image_up(cameras) if guess is None else guess.to(torch.float64)
    clouds = []
    for c, d in zip(cameras, depths, strict=True):
        step = stride or max(1, round(math.sqrt(d.size / FLOOR_POINTS_PER_VIEW)))
        clouds.append(lift_depth(c.to(dtype=torch.float64), d, step))
    return find_floor(torch.cat(clouds), guess)


# What a request's cameras and depth images must satisfy for its answer to be right (``scene_findings``).
# Views of a calibrated rig that see the same surfaces agree on 0.19-0.6 of them (day 4 of the twin, alt and
# alt-mesh looks, sequences: p5 0.28-0.59), random rigs' wide baselines down to 0.11; swapped views 0.01-0.05.
AGREE_SHARE_MIN = 0.08
OVERLAP_MIN = 0.1  # pairs that share less are not compared
SCENE_STRIDE = 16  # every 16th pixel: a few thousand points per 640x480 view, a few ms per frame


@dataclass(frozen=True)
class Finding:
    """One named problem of a scene: ``error`` when its answer cannot be right (the service refuses it), else a
    note that goes with the answer."""

    name: str
    error: bool
    message: str


def scene_findings(cameras: list[Camera], depths: list[np.ndarray]) -> list[Finding]:
    """What is wrong with one frame's views, from what they carry: each depth image's range (millimetres?), the
    cameras' spacing (translations in millimetres?), two views with one and the same camera, and whether the
    views' depth points agree under the rig (swapped images, a camera that moved)."""
    out = []
    for i, d in enumerate(depths):
        median, ok = median_depth(d)
        if median is not None and not ok:
            out.append(Finding("depth_range", True, (
                    f"depth_{i}'s valid pixels have a median of {median:.0f} mm; an OR camera sees 0.3-15 m: check "
                    "the unit (depth_scale_mm: 1000 for metres, 10 for centimetres, 0.1 for 0.1 mm units)")))  # fmt: skip
    if len(cameras) < 2:
        return out
    for i, j in itertools.combinations(range(len(cameras)), 2):
        a, b = cameras[i], cameras[j]
        if torch.allclose(a.extrinsics, b.extrinsics, atol=1e-6) and torch.allclose(a.intrinsics, b.intrinsics):
            out.append(Finding("identical_cameras", True, (
                f"views[{j}].camera is identical to views[{i}].camera: each view needs its own camera's "
                "calibration (a copied block?)")))  # fmt: skip
    if any(f.name == "identical_cameras" for f in out):
        return out
    spacing = camera_spacing(cameras)
    lo, hi = PLAUSIBLE_SPACING_MM
    if spacing is not None and not lo <= spacing <= hi:
        out.append(Finding("translation_units", True, (
            f"the cameras are a median {spacing:.1f} mm apart; a rig spans {lo:.0f}-{hi:.0f} mm: the extrinsics' "
            "translations must be in millimetres (metres need x 1000)")))  # fmt: skip
        return out
    if any(f.error for f in out):
        return out
    rig = Rig(list(cameras), [str(v) for v in range(len(cameras))])
    pairs = {r["pair"]: r for r in depth_agreement(rig, depths, SCENE_STRIDE)}
    for (i, j), r in pairs.items():
        back = pairs.get((j, i))  # absent when view j has no valid depth pixel
        if i > j or back is None or min(r["overlap"], back["overlap"]) < OVERLAP_MIN:
            continue
        share = max(r["within"], back["within"])
        if share < AGREE_SHARE_MIN:
            out.append(Finding("views_disagree", False, (
                f"views {i} and {j} disagree: where both see the same surfaces, only {share:.0%} of their depth "
                f"points lie within {AGREE_MM:.0f} mm of each other (a calibrated rig agrees on about a quarter to a "
                "half): a camera may have moved since its calibration, or two views' images or cameras are swapped")))  # fmt: skip
    return out
