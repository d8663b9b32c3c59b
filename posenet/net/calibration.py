"""A calibrated per-joint confidence: the probability that a joint lies within ``radius_mm`` of the truth.

The pose network's own uncertainty is a *spread* in mm (``posenet.net.lifting``: the softmax-weighted RMS distance
of a joint's lifted pixels from its estimate; larger is less certain). It ranks joints well but is no
probability. :class:`Calibration` maps it, per joint, to ``confidence`` in [0, 1]:

    logit P(error <= radius_mm) = intercept[type] + log_spread[type] * log(spread_mm) + views * (V_support - 1)

one logistic curve per joint type (``posenet.skeleton.JOINT_TYPES``: left and right share one), plus a shared
term for the number of views that support the person (1 to 4 counted). The fit keeps every ``log_spread <= 0``,
so the confidence never rises with the spread. Its parameters live in the checkpoint's json under
``"calibration"`` (written by ``python -m posenet.evaluation.calibrate --write``).

**Fallback** (a checkpoint without a ``"calibration"`` section): a fixed curve that reads the spread as the
joint's RMS 3D error, isotropic and Gaussian (per-axis std ``spread / sqrt(3)``), so the confidence is the
Maxwell CDF at ``radius_mm``. It is monotone and in [0, 1] but not fitted; ``docs/MODEL_CARD.md`` reports how
far off it is (its expected calibration error) next to the fitted curve's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from posenet.net.plausibility import ONE_VIEW_CAP, implausible
from posenet.skeleton import JOINT_TYPES, NUM_JOINTS

Tensor = torch.Tensor

TYPE_NAMES: tuple[str, ...] = tuple(JOINT_TYPES)
# TYPE_OF_JOINT[j]: the index in TYPE_NAMES of joint j's type.
TYPE_OF_JOINT: tuple[int, ...] = tuple(
    next(t for t, joints in enumerate(JOINT_TYPES.values()) if j in joints) for j in range(NUM_JOINTS)
)
MAX_VIEWS = 4  # support beyond this counts as 4: the rigs rendered here have at most 4 cameras
MIN_SPREAD_MM = 1.0  # log(spread) below this would only extrapolate; no joint measured comes near it


@dataclass
class Calibration:
    """``kind`` ``"logistic"`` (fitted; ``intercept``, ``log_spread`` per joint type, ``views`` shared) or
    ``"default"`` (the fallback curve of the module docstring). ``info``: how and on what it was fitted."""

    kind: str = "default"
    radius_mm: float = 100.0
    intercept: list[float] = field(default_factory=lambda: [0.0] * len(TYPE_NAMES))
    log_spread: list[float] = field(default_factory=lambda: [0.0] * len(TYPE_NAMES))
    views: float = 0.0
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.kind not in ("logistic", "default"):
            raise ValueError(f"calibration kind must be 'logistic' or 'default', got {self.kind!r}")
        if not self.radius_mm > 0:
            raise ValueError(f"calibration radius_mm must be > 0, got {self.radius_mm}")
        T = len(TYPE_NAMES)
        if len(self.intercept) != T or len(self.log_spread) != T:
            raise ValueError(
                f"calibration needs {T} intercepts and log_spread slopes ({', '.join(TYPE_NAMES)})"
            )
        if any(b > 0 for b in self.log_spread):
            raise ValueError(f"calibration log_spread slopes must be <= 0 (monotone), got {self.log_spread}")

    @classmethod
    def from_config(cls, config: dict | None) -> Calibration:
        """The checkpoint config's ``"calibration"`` section, or the fallback curve when it has none."""
        section = (config or {}).get("calibration")
        if not section:
            return cls()
        keys = ("kind", "radius_mm", "intercept", "log_spread", "views", "info")
        return cls(**{k: section[k] for k in keys if k in section})

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "radius_mm": self.radius_mm,
            "joint_types": list(TYPE_NAMES),
            "intercept": [round(float(x), 5) for x in self.intercept],
            "log_spread": [round(float(x), 5) for x in self.log_spread],
            "views": round(float(self.views), 5),
            "info": self.info,
        }

    def __call__(self, spread_mm: Tensor, support: Tensor, joints: Tensor | None = None) -> Tensor:
        """Confidence (..., J) in [0, 1] of joints with spreads ``spread_mm (..., J)`` mm, of persons supported
        by ``support (...)`` views. Any device and float dtype; the result has ``spread_mm``'s. With the
        persons' ``joints (..., J, 3)``, a one-view skeleton without a person's size (``posenet.net.plausibility``)
        is capped at ``ONE_VIEW_CAP``."""
        if spread_mm.shape[-1:] != (NUM_JOINTS,) or support.shape != spread_mm.shape[:-1]:
            raise ValueError(
                f"spread_mm must be (..., {NUM_JOINTS}) and support (...), got {tuple(spread_mm.shape)} and "
                f"{tuple(support.shape)}"
            )
        joint = torch.arange(NUM_JOINTS, device=spread_mm.device).expand(spread_mm.shape)  # (..., J)
        confidence = self.per_joint(spread_mm, joint, support.unsqueeze(-1).expand(spread_mm.shape))
        if joints is None or not confidence.numel():
            return confidence
        bad = torch.as_tensor(implausible(joints.detach().cpu(), support.cpu()), device=confidence.device)
        return torch.where(bad.unsqueeze(-1), confidence.clamp_max(ONE_VIEW_CAP), confidence)

    def per_joint(self, spread_mm: Tensor, joint: Tensor, support: Tensor) -> Tensor:
        """Confidence of single joints: ``spread_mm``, ``joint`` (indices, MVOR order) and ``support`` (views)
        all of one shape (...); the result is (...) with ``spread_mm``'s dtype."""
        spread = spread_mm.clamp_min(MIN_SPREAD_MM)
        if self.kind == "default":
            x = self.radius_mm * math.sqrt(3.0) / spread  # radius over the per-axis std
            cdf = torch.erf(x / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * x * torch.exp(-0.5 * x * x)
            return cdf.clamp(0.0, 1.0)
        types = torch.tensor(TYPE_OF_JOINT, device=spread.device)[joint]  # (...)
        a = torch.tensor(self.intercept, dtype=spread.dtype, device=spread.device)[types]
        b = torch.tensor(self.log_spread, dtype=spread.dtype, device=spread.device)[types]
        views = support.to(spread.dtype).clamp(1, MAX_VIEWS) - 1
        return torch.sigmoid(a + b * spread.log() + self.views * views)


def _design(spread_mm: np.ndarray, joint: np.ndarray, support: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """Columns: one intercept per type, log(spread) per type where ``slopes[t]`` is free, (views - 1)."""
    T = len(TYPE_NAMES)
    onehot = np.eye(T)[np.asarray(TYPE_OF_JOINT)[joint]]  # (N, T)
    log_s = np.log(np.maximum(spread_mm, MIN_SPREAD_MM))[:, None] * onehot[:, slopes]  # (N, free)
    views = (np.clip(support, 1, MAX_VIEWS) - 1)[:, None].astype(np.float64)  # (N, 1)
    return np.concatenate([onehot, log_s, views], axis=1)


def _logistic(X: np.ndarray, y: np.ndarray, ridge: float, iterations: int = 100) -> np.ndarray:
    """Newton's method (IRLS) for L2-penalised logistic regression (the first T columns, the intercepts,
    unpenalised; the penalty keeps a type whose joints all hit or all miss finite)."""
    w = np.zeros(X.shape[1])
    penalty = np.full(X.shape[1], float(ridge))
    penalty[: len(TYPE_NAMES)] = ridge * 1e-3
    for _ in range(iterations):
        p = 1.0 / (1.0 + np.exp(-np.clip(X @ w, -30.0, 30.0)))
        grad = X.T @ (p - y) + penalty * w
        hess = (X * (p * (1 - p))[:, None]).T @ X + np.diag(penalty)
        step = np.linalg.solve(hess, grad)
        w -= step
        if np.abs(step).max() < 1e-8:
            break
    return w


def fit(
    spread_mm: np.ndarray,
    joint: np.ndarray,
    support: np.ndarray,
    error_mm: np.ndarray,
    radius_mm: float = 100.0,
    ridge: float = 1.0,
) -> Calibration:
    """Fit the logistic calibration on N measured joints.

    Args:
        spread_mm: (N,) the network's spreads; joint: (N,) joint indices (MVOR order); support: (N,) the
            number of views supporting each joint's person; error_mm: (N,) the joints' 3D errors.
        radius_mm: the confidence is P(error <= radius_mm). ridge: L2 weight on the slopes.
    """
    arrays = [np.asarray(a).reshape(-1) for a in (spread_mm, joint, support, error_mm)]
    if len({a.size for a in arrays}) != 1 or arrays[0].size == 0:
        raise ValueError(
            f"spread_mm, joint, support and error_mm must be (N,) with N > 0, got {[a.shape for a in arrays]}"
        )
    spread_mm, joint, support, error_mm = arrays
    y = (error_mm <= radius_mm).astype(np.float64)
    T = len(TYPE_NAMES)
    slopes = np.ones(T, bool)
    while True:  # a type whose slope comes out positive gets none (a flat curve), and the rest is refitted
        w = _logistic(_design(spread_mm, joint, support, slopes), y, ridge)
        b = np.zeros(T)
        b[slopes] = w[T : T + slopes.sum()]
        if (b <= 0).all():
            break
        slopes &= b <= 0
    return Calibration("logistic", float(radius_mm), w[:T].tolist(), b.tolist(), float(w[-1]))


def reliability(confidence: np.ndarray, hit: np.ndarray, bins: int = 10) -> dict:
    """The reliability diagram's numbers: per equal-width confidence bin its mean confidence, observed hit
    rate and count, and the expected calibration error (the count-weighted mean |rate - confidence|)."""
    confidence, hit = np.asarray(confidence, np.float64).reshape(-1), np.asarray(hit, np.float64).reshape(-1)
    if confidence.shape != hit.shape or confidence.size == 0:
        raise ValueError(
            f"confidence and hit must be (N,) with N > 0, got {confidence.shape} and {hit.shape}"
        )
    which = np.minimum((confidence * bins).astype(int), bins - 1)  # (N,)
    count = np.bincount(which, minlength=bins)
    with np.errstate(invalid="ignore"):
        mean_conf = np.bincount(which, confidence, bins) / count
        rate = np.bincount(which, hit, bins) / count
    gap = np.where(count > 0, np.abs(rate - mean_conf), 0.0)
    return {
        "confidence": mean_conf.tolist(),
        "rate": rate.tolist(),
        "count": count.tolist(),
        "ece": float((gap * count).sum() / count.sum()),
        "brier": float(((confidence - hit) ** 2).mean()),
        "hit_rate": float(hit.mean()),
        "joints": int(hit.size),
    }
