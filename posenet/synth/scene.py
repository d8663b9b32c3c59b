"""One synthetic frame: people and room in, per-view RGB-D images and annotations out.

A :class:`Frame` is a world (z up, floor at 0, mm) made of :class:`Person` s and room primitives.
:func:`render_frame` ray-casts it into every camera of a :class:`~posenet.rig.Rig`, runs the
sensor models and measures, per person and view, the visible pixels: their box (none when a person is hidden
or almost hidden), the 2D keypoints with MVOR's visibility flags (2 visible, 1 occluded, 0 outside the
image) and the visible pixel count.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from posenet.rig import Rig
from posenet.synth.body import TWIN_SHAPE, BodyShape, Outfit, body_primitives, primitive_regions
from posenet.synth.body_alt import alt_body_primitives
from posenet.synth.body_grammar import grammar_primitives
from posenet.synth.mesh_body import mesh_primitives
from posenet.synth.primitives import SHELL, Primitive
from posenet.synth.raster import GBuffer, Intrinsics, rasterize
from posenet.synth.rig import intrinsics, world_to_cam
from posenet.synth.sensor import (
    ColourSensorConfig,
    DepthSensorConfig,
    Lighting,
    shade_colour,
    simulate_depth,
)

NUM_JOINTS_2D = 10


@dataclass
class Person:
    """A person in the world.

    Attributes:
        points: (NUM_FULL, 3) full skeleton, world frame, mm.
        outfit: clothing and skin.
        person_id: MVOR person id (>= 0 for people with a 3D annotation, -1 for box-only people such as the
        patient).
        role: ``"clinician"`` or ``"patient"``.
        extra: further primitives that belong to this person's silhouette (the patient's drape).
        shape: body sizes and joint placement (the twin look's by default; see
        :mod:`posenet.synth.looks`).
    """

    points: np.ndarray
    outfit: Outfit
    person_id: int
    role: str = "clinician"
    extra: list[Primitive] = field(default_factory=list)
    shape: BodyShape = TWIN_SHAPE


@dataclass
class Frame:
    """Everything in one synchronised multi-view frame.

    Attributes:
        hidden: (view, person index) pairs in which the person is not drawn at all (a last resort of the
        twin).
        look: the sensors and material gains of the frame's look
        (:class:`~posenet.synth.looks.SceneLook`); None is the twin look.
    """

    persons: list[Person]
    room: list[Primitive]
    lighting: Lighting
    hidden: set[tuple[int, int]] = field(default_factory=set)
    look: object | None = None


@dataclass
class VisibilityConfig:
    min_pixels: int = 350  # fewer visible pixels than this at 640x480: no box ("almost hidden")
    min_fraction: float = 0.12  # or less than this fraction of the person's unoccluded silhouette
    # mm per joint (MVOR order): a joint is visible if the surface at its pixel is at most this far in
    # front of it, i.e. about the thickness of the body part around it (the head point sits inside the
    # head, the hips inside the pelvis or a gown); a nearer surface, even of the same person, occludes it.
    kp_depth_tol: tuple[float, ...] = (170, 120, 130, 130, 230, 230, 110, 110, 100, 100)


@dataclass
class ViewRender:
    """One camera's output.

    Attributes:
        color: (H, W, 3) uint8 RGB; depth: (H, W) uint16 mm; ideal_depth: (H, W) float64 noise-free z
        (np.inf: none).
        owner: (H, W) int32 person index of each pixel (negative: room).
        boxes: per person, the xyxy box of its visible pixels (inclusive pixel indices), or None.
        keypoints: per person, (10, 3) u, v, flag.
        pixels: per person, the number of visible pixels.
    """

    color: np.ndarray
    depth: np.ndarray
    ideal_depth: np.ndarray
    owner: np.ndarray
    boxes: list[tuple[int, int, int, int] | None]
    keypoints: list[np.ndarray]
    pixels: list[int]


BUILDERS = {
    "alt": alt_body_primitives,
    "grammar": grammar_primitives,
    "mesh": mesh_primitives,
}  # BodyShape.model -> its body model


def hybrid_primitives(points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape) -> list[Primitive]:
    """One body built by two models: the regions ``shape.regions`` by ``shape``'s own body model, the rest by the
    twin's construction at the twin's sizes (``--look-parts body:REGION``: which region of a look's body costs,
    ``benchmarks/look_factors.py``). Each model builds the whole body and keeps its regions'
    primitives (:func:`~posenet.synth.body.primitive_regions`)."""
    own = person_primitives(points, outfit, owner, replace(shape, regions=None))
    twin = body_primitives(points, outfit, owner, TWIN_SHAPE)
    keep = [
        p
        for p, r in zip(twin, primitive_regions(twin, points, outfit.gown), strict=True)
        if r not in shape.regions
    ]
    take = [
        p for p, r in zip(own, primitive_regions(own, points, outfit.gown), strict=True) if r in shape.regions
    ]
    return keep + take


def person_primitives(points: np.ndarray, outfit: Outfit, owner: int, shape: BodyShape) -> list[Primitive]:
    """The primitives of one person's body, by ``shape``'s body model (or two of them, ``shape.regions``)."""
    if shape.regions is not None:
        return hybrid_primitives(points, outfit, owner, shape)
    return BUILDERS.get(shape.model, body_primitives)(points, outfit, owner, shape)


def frame_primitives(frame: Frame) -> list[Primitive]:
    """All primitives of a frame, the persons' owned by their index."""
    prims = list(frame.room)
    for i, person in enumerate(frame.persons):
        prims += person_primitives(person.points, person.outfit, i, person.shape)
        prims += [replace(p, owner=i) for p in person.extra]
    return prims


def _material_tables(prims: list[Primitive], look=None) -> tuple[np.ndarray, ...]:
    """Per primitive: albedo (N, 3), depth dropout, texture, specular, owner (look: a ``SceneLook``)."""
    depth_cfg = look.depth if look is not None else DepthSensorConfig()
    owner = np.array([p.owner for p in prims], np.int32)
    albedo = np.array([p.material.albedo for p in prims], np.float32)
    if look is not None and look.room_gain is not None:
        albedo[owner < 0] = np.clip(albedo[owner < 0] * np.asarray(look.room_gain, np.float32), 0, 1)
    dropout = np.array([p.material.ir_dropout for p in prims], np.float32)
    # Very dark cloth absorbs the IR pattern.
    dropout = dropout + np.clip(depth_cfg.dark_threshold - albedo.mean(1), 0, None) * depth_cfg.dark_absorb
    if look is not None and look.dropout_gain != 1.0:
        dropout = dropout * look.dropout_gain
    texture = np.array([p.material.texture for p in prims], np.float32)
    specular = np.array([p.material.specular for p in prims], np.float32)
    return albedo, dropout, texture, specular, owner


def _downscaled(K: Intrinsics, factor: int) -> Intrinsics:
    """The intrinsics of the image subsampled by ``factor`` (pixel centres stay centres, as posenet.cameras)."""
    return Intrinsics(
        K.fx / factor,
        K.fy / factor,
        (K.cx + 0.5) / factor - 0.5,
        (K.cy + 0.5) / factor - 0.5,
        K.width // factor,
        K.height // factor,
    )


def unoccluded_pixels(prims_cam: list[Primitive], owner: int, K: Intrinsics, factor: int = 4) -> int:
    """Pixels that person ``owner`` would cover with nothing in front, counted at 1/factor resolution."""
    small = _downscaled(K, factor)
    g = rasterize([p for p in prims_cam if p.owner == owner], small)
    return int((g.prim >= 0).sum()) * factor * factor


def silhouettes(
    frame: Frame, rig: Rig, factor: int = 4
) -> dict[tuple[int, int], tuple[np.ndarray, float, int]]:
    """Per (view, person): unoccluded silhouette box (xyxy, full-res pixels), nearest depth, pixel count."""
    prims = frame_primitives(frame)
    T = world_to_cam(rig)
    out = {}
    for v, K in enumerate(intrinsics(rig)):
        small = _downscaled(K, factor)
        for i in range(len(frame.persons)):
            g = rasterize([p.to_camera(T[v]) for p in prims if p.owner == i], small)
            hit = g.prim >= 0
            if not hit.any():
                continue
            rows, cols = np.flatnonzero(hit.any(1)), np.flatnonzero(hit.any(0))
            b = np.array([cols[0], rows[0], cols[-1] + 1, rows[-1] + 1], float) * factor
            out[(v, i)] = (b, float(g.depth[hit].min()), int(hit.sum()) * factor * factor)
    return out


def visible_pixels(frame: Frame, rig: Rig, factor: int = 4) -> dict[tuple[int, int], int]:
    """Per (view, person): visible pixels in the whole scene, counted at 1/factor resolution (full-res
    units)."""
    prims = frame_primitives(frame)
    T = world_to_cam(rig)
    out = {}
    for v, K in enumerate(intrinsics(rig)):
        keep = [p for p in prims if (v, p.owner) not in frame.hidden]
        g = rasterize([p.to_camera(T[v]) for p in keep], _downscaled(K, factor))
        owners = np.array([p.owner for p in keep], np.int32)
        own = np.where(g.prim >= 0, owners[np.maximum(g.prim, 0)], -3)
        counts = np.bincount(own[own >= 0].ravel(), minlength=len(frame.persons))
        out.update({(v, i): int(c) * factor * factor for i, c in enumerate(counts)})
    return out


def room_edge_distance(
    g: GBuffer, K: Intrinsics, world_to_cam: np.ndarray, room: list[Primitive], touch: float = 30.0
) -> np.ndarray | None:
    """``(H, W)`` mm from each pixel that lies on the room's shell (walls, ceiling, floor: within ``touch`` mm
    of it) to the shell's nearest edge or corner, where two faces meet; inf elsewhere (None: no shell)."""
    shell = next((p for p in room if p.kind == SHELL), None)
    if shell is None:
        return None
    H, W = g.depth.shape
    z = np.where(np.isfinite(g.depth), g.depth, 0.0)
    du = (np.arange(W) - K.cx) / K.fx
    dv = (np.arange(H) - K.cy) / K.fy
    cam = np.stack([du[None, :] * z, dv[:, None] * z, z], -1)  # (H, W, 3)
    R, t = world_to_cam[:3, :3], world_to_cam[:3, 3]
    world = (cam - t) @ R  # R^T (p - t), row vectors
    inside = np.sort(
        shell.size - np.abs(world - shell.center), axis=-1
    )  # (H, W, 3) distance to each face pair
    on_shell = np.isfinite(g.depth) & (inside[..., 0] < touch)
    return np.where(on_shell, inside[..., 1], np.inf)


def render_view(
    frame: Frame,
    prims: list[Primitive],
    rig: Rig,
    v: int,
    rng: np.random.Generator,
    vis: VisibilityConfig | None = None,
) -> ViewRender:
    """Render view ``v`` of ``frame`` (``prims`` from :func:`frame_primitives`)."""
    vis = vis or VisibilityConfig()
    K = intrinsics(rig)[v]
    T = world_to_cam(rig)[v]
    keep = [p for p in prims if (v, p.owner) not in frame.hidden]
    cam = [p.to_camera(T) for p in keep]
    g = rasterize(cam, K)
    look = frame.look
    albedo, dropout, texture, specular, owners = _material_tables(keep, look)
    hit = g.prim >= 0
    idx = np.where(hit, g.prim, 0)
    owner = np.where(hit, owners[idx], -3)
    if look is None:  # the twin look
        depth = simulate_depth(g, K, np.where(hit, dropout[idx], 0), rng)
        color = shade_colour(g, K, albedo[idx], texture[idx], specular[idx], T, frame.lighting, rng)
    else:
        depth_cfg: DepthSensorConfig = look.depth
        colour_cfg: ColourSensorConfig = look.colour
        edges = room_edge_distance(g, K, T, frame.room) if depth_cfg.multipath > 0 else None
        depth = simulate_depth(
            g, K, np.where(hit, dropout[idx], 0), rng, depth_cfg, albedo[idx], specular[idx], edges
        )
        color = shade_colour(
            g, K, albedo[idx], texture[idx], specular[idx], T, frame.lighting, rng, colour_cfg
        )

    n = len(frame.persons)
    counts = np.bincount(owner[owner >= 0].ravel(), minlength=n)
    boxes, keypoints = [], []
    for i, person in enumerate(frame.persons):  # a handful of persons per frame
        box = None
        if counts[i] >= vis.min_pixels:
            enough = counts[i] >= 8000 or counts[i] >= vis.min_fraction * unoccluded_pixels(cam, i, K)
            if enough:
                rows = np.flatnonzero((owner == i).any(axis=1))
                cols = np.flatnonzero((owner == i).any(axis=0))
                box = (int(cols[0]), int(rows[0]), int(cols[-1]), int(rows[-1]))
        boxes.append(box)
        keypoints.append(project_keypoints(person.points[:NUM_JOINTS_2D], T, K, owner, g.depth, i, vis))
    return ViewRender(color, depth, g.depth, owner, boxes, keypoints, [int(c) for c in counts])


def project_keypoints(
    points: np.ndarray,
    world_to_cam: np.ndarray,
    K: Intrinsics,
    owner: np.ndarray,
    zbuf: np.ndarray,
    index: int,
    vis: VisibilityConfig,
) -> np.ndarray:
    """``(J, 3)`` u, v, flag of world joints ``points (J, 3)``: 2 visible, 1 occluded, 0 outside the image."""
    pc = points @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]
    z = np.maximum(pc[:, 2], 1e-6)
    u = K.fx * pc[:, 0] / z + K.cx
    v = K.fy * pc[:, 1] / z + K.cy
    ui, vi = np.round(u).astype(int), np.round(v).astype(int)
    inside = (pc[:, 2] > 0) & (ui >= 0) & (ui < K.width) & (vi >= 0) & (vi < K.height)
    uc, vc = np.clip(ui, 0, K.width - 1), np.clip(vi, 0, K.height - 1)
    near = zbuf[vc, uc] > pc[:, 2] - np.asarray(vis.kp_depth_tol)
    flag = np.where(inside, np.where(near, 2, 1), 0)
    out = np.stack([u, v, flag], axis=1)
    out[flag == 0, :2] = 0  # MVOR writes (0, 0, 0) for joints it does not annotate
    return out


def render_frame(
    frame: Frame, rig: Rig, rng: np.random.Generator, vis: VisibilityConfig | None = None
) -> list[ViewRender]:
    """Render every view of the rig."""
    prims = frame_primitives(frame)
    return [render_view(frame, prims, rig, v, rng, vis) for v in range(len(rig))]
