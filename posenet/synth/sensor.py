"""RGB-D sensor models: what a Kinect-like camera makes of the ideal z-buffer and surface colours.

Depth (uint16 mm, 0 = unknown), following the structured-light sensors MVOR was recorded with:
  - axial noise that grows with the square of the distance (Khoshelham & Elberink 2012: ~1.5 mm at 1 m,
    ~4 cm at 5 m), plus a smooth low-frequency wobble;
  - disparity quantisation to 1/8 pixel with a 75 mm baseline, so depth steps grow as z^2 (~2 cm at 3 m);
  - projector shadows: surfaces that the IR projector, beside the camera, cannot see return nothing;
  - holes on depth edges (mixed pixels), on dark or shiny surfaces (per-material dropout) and random specks;
  - a range limit, and the invalid band on the left border of registered Kinect depth.
Colour (uint8 RGB): Lambertian shading from a key light above, a fill light and ambient, Blinn-Phong
highlights on metal and screens, per-frame exposure and white balance, vignetting, fabric texture, sensor
shot and read noise and a slight blur. Colour is deliberately harder than depth: exposure, white balance and
noise change from frame to frame, while the depth of a surface does not.

The defaults of :class:`DepthSensorConfig`, :class:`ColourSensorConfig` and :class:`Lighting` are the ``twin``
look; the other looks (:mod:`posenet.synth.looks`) set the further options: flying pixels, clustered and
specular holes, multipath near walls, a time-of-flight model (noise linear in z and growing on dark surfaces,
no projector shadows, a circular field of view), more lights, another diffuse model and tone curve, JPEG.
Every option is off at its default, so the twin's images, random draws included, stay byte for byte the same.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np

from posenet.synth.raster import GBuffer, Intrinsics


@dataclass
class DepthSensorConfig:
    noise_k: float = 1.5e-6  # sigma(z) = noise_k * z^2 mm (Khoshelham & Elberink 2012)
    baseline: float = 75.0  # mm between IR projector and IR camera (Kinect v1)
    disparity_step: float = 1 / 8  # px, Kinect v1 sub-pixel disparity resolution
    min_range: float = 500.0
    max_range: float = 6500.0
    far_dropout_start: float = 4500.0  # beyond this, returns get sparse
    edge_jump: float = 0.04  # relative depth jump that makes an edge pixel a hole
    edge_dropout: float = 0.6
    speckle: float = 0.004
    left_band: int = 8  # invalid columns on the left border
    # Options of the other looks (off here; see the module docstring).
    model: str = "structured_light"  # or "tof": no projector shadows, noise from noise_const/noise_lin
    white: float = 0.7  # weight of the white part of the noise
    wobble: float = 0.7  # weight of the smooth part
    noise_const: float = 0.0  # mm, added to sigma
    noise_lin: float = 0.0  # sigma grows by this many mm per mm of z
    dark_noise: float = 0.0  # sigma *= 1 + dark_noise * (1 - albedo brightness): weak returns are noisier
    dark_absorb: float = 4.0  # surface dropout += dark_absorb * max(dark_threshold - albedo brightness, 0)
    dark_threshold: float = 0.08
    projector_side: int = 1  # +1: projector to the right of the IR camera (shadows left of objects), -1 left
    quantisation: str = "disparity"  # or "mm": steps of quant_mm along z
    quant_mm: float = 1.0
    flying: float = 0.0  # share of the depth-edge pixels left by edge_dropout that get a mixed depth
    blob_holes: float = 0.0  # area share of clustered holes (smooth random field over a threshold)
    specular_holes: float = 0.0  # dropout on shiny surfaces seen head-on (saturated returns)
    multipath: float = (
        0.0  # walls: depth += multipath * 100 mm * exp(-distance to the room's nearest edge / 400 mm)
    )
    fov_radius: float = 0.0  # > 0: pixels further than this share of the half diagonal are invalid


@dataclass
class ColourSensorConfig:
    read_noise: float = 2.0  # DN (0-255), sigma
    shot_noise: float = 0.025  # relative, sigma at full scale
    blur_sigma: float = 0.7
    vignetting: float = 0.25
    # Options of the other looks.
    gamma: float = 2.2
    diffuse: str = "lambert"  # or "half_lambert" ((n.l / 2 + 1 / 2)^2, wrapping light round the body)
    hemisphere: float = 0.0  # ambient from above brighter than from below: ambient * (1 + h * n.up)
    tonemap: str = "clip"  # or "reinhard": x (1 + x / w^2) / (1 + x) with w = 1.6
    jpeg_quality: int = 0  # > 0: the image goes through a JPEG round trip at this quality


def simulate_depth(
    g: GBuffer,
    K: Intrinsics,
    dropout: np.ndarray,
    rng: np.random.Generator,
    cfg: DepthSensorConfig | None = None,
    albedo: np.ndarray | None = None,
    specular: np.ndarray | None = None,
    edge_distance: np.ndarray | None = None,
) -> np.ndarray:
    """Sensor depth ``(H, W)`` uint16 mm from a G-buffer; ``dropout (H, W)`` is the per-pixel surface
    dropout. ``albedo (H, W, 3)``, ``specular (H, W)`` and ``edge_distance (H, W)`` (mm from a wall, floor or
    ceiling pixel to the room's nearest edge or corner, inf elsewhere) feed the options that need them
    (dark-surface noise, specular holes, multipath)."""
    cfg = cfg or DepthSensorConfig()
    z = g.depth.copy()
    H, W = z.shape
    valid = np.isfinite(z) & (z > cfg.min_range) & (z < cfg.max_range)
    z[~valid] = cfg.max_range
    fb = K.fx * cfg.baseline
    if cfg.model == "tof":  # the emitter sits at the lens: no projector shadows
        shadow = np.zeros((H, W), bool)
    elif cfg.projector_side < 0:  # the mirror image of a projector on the right
        shadow = projector_shadow(z[:, ::-1], valid[:, ::-1], fb, cfg.min_range)[:, ::-1]
    else:
        shadow = projector_shadow(z, valid, fb, cfg.min_range)
    # Mixed pixels at depth discontinuities.
    zmax = cv2.dilate(z.astype(np.float32), np.ones((3, 3), np.uint8))
    zmin = cv2.erode(z.astype(np.float32), np.ones((3, 3), np.uint8))
    edge = (zmax - zmin) > cfg.edge_jump * z
    far = np.clip((z - cfg.far_dropout_start) / (cfg.max_range - cfg.far_dropout_start), 0, 1)
    if cfg.specular_holes > 0 and specular is not None:  # shiny surfaces facing the camera saturate
        dropout = dropout + cfg.specular_holes * specular * np.clip(-g.normal[2], 0, 1) ** 8
    p_hole = edge * cfg.edge_dropout + dropout + cfg.speckle + far * 0.7  # one draw for every random cause
    draw = rng.random((H, W), dtype=np.float32)
    holes = shadow | (draw < p_hole)
    if cfg.blob_holes > 0:  # clustered dropouts: a smooth random field above its (1 - blob_holes) quantile
        blob = cv2.resize(
            rng.standard_normal((H // 12, W // 12), dtype=np.float32), (W, H), interpolation=cv2.INTER_CUBIC
        )
        holes |= blob > np.quantile(blob[::8, ::8], 1 - cfg.blob_holes)
    # Noise: white, plus a smooth wobble of the same order (structured light correlates neighbouring pixels).
    sigma = cfg.noise_k * z * z
    if cfg.noise_const or cfg.noise_lin:
        sigma = sigma + cfg.noise_const + cfg.noise_lin * z
    if cfg.dark_noise > 0 and albedo is not None:
        sigma = sigma * (1 + cfg.dark_noise * np.clip(1 - albedo.mean(-1) * 2, 0, 1))
    wobble = cv2.resize(
        rng.normal(0, 1, (H // 16, W // 16)).astype(np.float32), (W, H), interpolation=cv2.INTER_CUBIC
    )
    zn = z + sigma * (noise_field(rng, H, W) * cfg.white + wobble * cfg.wobble)
    if cfg.flying > 0:  # edge pixels that survived: a depth between the two surfaces they straddle
        fly = edge & (draw >= p_hole) & (rng.random((H, W), dtype=np.float32) < cfg.flying)
        mix = rng.random(int(fly.sum())).astype(np.float32)
        zn[fly] = zmin[fly] + mix * (zmax[fly] - zmin[fly])
    if (
        cfg.multipath > 0 and edge_distance is not None
    ):  # light bouncing off the other wall lengthens the path
        zn = zn + cfg.multipath * 100.0 * np.exp(-edge_distance / 400.0)
    if cfg.quantisation == "mm":
        zq = np.round(zn / cfg.quant_mm) * cfg.quant_mm
    else:  # disparity quantisation
        d = np.round(fb / zn / cfg.disparity_step) * cfg.disparity_step
        zq = fb / np.maximum(d, 1e-6)
    in_range = (zq >= cfg.min_range) & (zq <= cfg.max_range)
    out = np.where(valid & ~holes & in_range, np.round(zq), 0)
    out[:, : cfg.left_band] = 0
    if cfg.fov_radius > 0:
        out[fov_mask(W, H, cfg.fov_radius)] = 0
    return np.clip(out, 0, 65535).astype(np.uint16)


def projector_shadow(z: np.ndarray, valid: np.ndarray, fb: float, min_range: float) -> np.ndarray:
    """``(H, W)`` bool: pixels that a projector ``fb / fx`` mm to the camera's right cannot see.

    A z-buffer seen from the projector, one row at a time (same row, shifted column)."""
    H, W = z.shape
    up = np.round(np.arange(W)[None, :] + fb / z).astype(np.int64)  # projector column of every pixel
    up = np.clip(up, 0, W + int(fb / min_range) + 1)
    Wp = W + int(fb / min_range) + 2
    key = (np.arange(H)[:, None] * Wp + up).ravel()
    proj = np.full(H * Wp, np.inf)
    np.minimum.at(proj, key[valid.ravel()], z.ravel()[valid.ravel()])
    return z > proj[key].reshape(H, W) * 1.03


@functools.lru_cache(maxsize=8)
def fov_mask(W: int, H: int, radius: float) -> np.ndarray:
    """``(H, W)`` bool: pixels outside a circle of ``radius`` times the half diagonal (a ToF's round FOV)."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    r = np.sqrt((xx - W / 2) ** 2 + (yy - H / 2) ** 2) / np.hypot(W / 2, H / 2)
    return r > radius


@dataclass
class Lighting:
    """Per-frame lighting (world frame, z up)."""

    key_dir: np.ndarray  # (3,) unit vector from the surface toward the key light
    key: float
    fill: float
    ambient: float
    white_balance: np.ndarray  # (3,) RGB gains
    exposure: float
    extra: tuple[tuple[np.ndarray, float], ...] = ()  # further lights: (unit direction (3,), intensity)
    shininess: float = 40.0  # Blinn-Phong exponent
    specular_gain: float = 1.0  # scales every material's highlight


def sample_lighting(rng: np.random.Generator) -> Lighting:
    tilt, az = rng.uniform(0, 0.6), rng.uniform(0, 2 * np.pi)
    key_dir = np.array([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    wb = np.array([rng.uniform(0.85, 1.15), 1.0, rng.uniform(0.8, 1.2)])
    return Lighting(
        key_dir,
        rng.uniform(0.5, 0.9),
        rng.uniform(0.15, 0.35),
        rng.uniform(0.15, 0.35),
        wb,
        rng.uniform(0.75, 1.3),
    )


_NOISE_BANK: np.ndarray | None = None


def noise_field(rng: np.random.Generator, H: int, W: int) -> np.ndarray:
    """``(H, W)`` float32 white Gaussian noise: a random window of a fixed bank (drawing ~1M normals per view
    would cost as much as the rest of the sensor model; a window at a random offset is as good for images)."""
    global _NOISE_BANK
    if _NOISE_BANK is None:
        _NOISE_BANK = np.random.default_rng(20261122).standard_normal((1536, 2048), dtype=np.float32)
    if H > 1024 or W > 1024:
        return rng.standard_normal((H, W), dtype=np.float32)
    y0, x0 = rng.integers(0, _NOISE_BANK.shape[0] - H), rng.integers(0, _NOISE_BANK.shape[1] - W)
    field = _NOISE_BANK[y0 : y0 + H, x0 : x0 + W]
    return field if rng.random() < 0.5 else field[::-1, ::-1]


# sRGB-like gamma as a lookup table (a power over every pixel costs more than the rest of the shading).
_GAMMA = (np.linspace(0, 1, 4096, dtype=np.float32) ** (1 / 2.2)).astype(np.float32)


@functools.lru_cache(maxsize=32)
def _tone_curve(gamma: float, tonemap: str) -> np.ndarray:
    """The 4096-entry lookup table from linear radiance in [0, 1] (or [0, 2] with Reinhard) to display."""
    if gamma == 2.2 and tonemap == "clip":
        return _GAMMA
    x = np.linspace(0, 1, 4096, dtype=np.float64)
    if tonemap == "reinhard":  # the table spans radiance 0..2, highlights roll off instead of clipping
        x = 2 * x
        x = x * (1 + x / 1.6**2) / (1 + x)
    return (np.clip(x, 0, 1) ** (1 / gamma)).astype(np.float32)


@functools.lru_cache(maxsize=16)
def _view_geometry(fx, fy, cx, cy, W, H, vignetting) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel unit vectors toward the camera ``(3, H, W)`` and the vignetting gain ``(H, W, 1)``."""
    du = (np.arange(W, dtype=np.float32) - cx) / fx
    dv = (np.arange(H, dtype=np.float32) - cy) / fy
    norm = np.sqrt(du[None, :] ** 2 + dv[:, None] ** 2 + 1)
    view = np.stack([-du[None, :] / norm, -dv[:, None] / norm, -1 / norm])  # (3, H, W)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    r2 = ((xx - W / 2) ** 2 + (yy - H / 2) ** 2) / ((W / 2) ** 2 + (H / 2) ** 2)
    return view.astype(np.float32), (1 - vignetting * r2).astype(np.float32)


def shade_colour(
    g: GBuffer,
    K: Intrinsics,
    albedo: np.ndarray,
    texture: np.ndarray,
    specular: np.ndarray,
    world_to_cam: np.ndarray,
    light: Lighting,
    rng: np.random.Generator,
    cfg: ColourSensorConfig | None = None,
) -> np.ndarray:
    """Colour image ``(H, W, 3)`` uint8 RGB.

    Args:
        g: the view's G-buffer.
        albedo: (H, W, 3) linear reflectance of the visible surface.
        texture: (H, W) texture amplitude; specular: (H, W) highlight strength.
        world_to_cam: (4, 4) T(world->cam), to bring the lights into the camera frame.
    """
    cfg = cfg or ColourSensorConfig()
    H, W = g.depth.shape
    n = g.normal
    l_key = (world_to_cam[:3, :3] @ light.key_dir).astype(np.float32)
    view, vignette = _view_geometry(K.fx, K.fy, K.cx, K.cy, W, H, cfg.vignetting)
    nx, ny, nz = n[0], n[1], n[2]

    def lit(d: np.ndarray) -> np.ndarray:
        cos = nx * d[0] + ny * d[1] + nz * d[2]
        if cfg.diffuse == "half_lambert":
            return (cos * 0.5 + 0.5) ** 2
        return np.maximum(cos, 0)

    diffuse = lit(l_key)
    n_dot_v = np.maximum(nx * view[0] + ny * view[1] + nz * view[2], 0)  # a fill light near the camera
    ambient = light.ambient
    if cfg.hemisphere:  # more light from the ceiling than from the floor
        up = (world_to_cam[:3, :3] @ np.array([0.0, 0.0, 1.0])).astype(np.float32)
        ambient = light.ambient * (1 + cfg.hemisphere * (nx * up[0] + ny * up[1] + nz * up[2]))
    shade = ambient + light.key * diffuse + light.fill * n_dot_v
    for d, intensity in light.extra:
        shade = shade + intensity * lit((world_to_cam[:3, :3] @ d).astype(np.float32))
    # Fabric/grain texture: a fresh noise field at two scales.
    grain = noise_field(rng, H, W)
    blotch = cv2.resize(
        rng.standard_normal((H // 8, W // 8), dtype=np.float32), (W, H), interpolation=cv2.INTER_LINEAR
    )
    shade *= 1 + texture * (0.6 * grain + 0.8 * blotch)
    shade *= vignette * light.exposure
    radiance = albedo * shade[..., None]
    shiny = specular > 0
    if shiny.any():  # Blinn-Phong highlights, only where a surface can shine
        nv = np.stack([n[i][shiny] for i in range(3)], 1)
        half = np.stack([view[i][shiny] for i in range(3)], 1) + l_key
        half /= np.maximum(np.linalg.norm(half, axis=1, keepdims=True), 1e-6)
        spec = specular[shiny] * np.maximum((nv * half).sum(1), 0) ** light.shininess * light.exposure
        if light.specular_gain != 1.0:
            spec = spec * light.specular_gain
        radiance[shiny] += spec[:, None]
    radiance *= (light.white_balance).astype(np.float32)
    curve = _tone_curve(cfg.gamma, cfg.tonemap)
    scale = (len(curve) - 1) / (2.0 if cfg.tonemap == "reinhard" else 1.0)
    img = curve[np.clip(radiance * scale, 0, len(curve) - 1).astype(np.int32)]
    img += np.stack([noise_field(rng, H, W) for _ in range(3)], -1) * np.sqrt(
        (cfg.read_noise / 255) ** 2 + cfg.shot_noise**2 * img
    )
    if cfg.blur_sigma > 0:
        img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma)
    out = np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8)
    if cfg.jpeg_quality > 0:  # block artefacts and chroma subsampling of a compressed stream
        ok, buf = cv2.imencode(".jpg", out[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(cfg.jpeg_quality)])
        out = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()
    return out
