"""The differentiable model: U-Net per person and view -> inverse augmentation -> lifting -> aggregation.

``PoseNet(config)(scene) -> PoseOutput`` takes a :class:`posenet.net.inputs.SceneInput` (all persons x views of
one scene) and runs the U-Net once on every (person, view) pair that has a box, in one batch. The heatmaps are
brought back to original pixels (:mod:`posenet.net.augment`), lifted to 3D and aggregated with a softmax over all
views' points per joint (:mod:`posenet.net.lifting`). With ``aggregation="2d"`` the paper's 2D baseline is used
instead (per-view 2D centre of mass, depth look-up, softmax fusion of the views).
"""

from __future__ import annotations

import contextlib
import functools
from dataclasses import dataclass, field

import torch
from torch import nn

from posenet.net import augment as aug
from posenet.net import lifting
from posenet.net.inputs import InputConfig, SceneInput
from posenet.net.unet import UNet, UNetConfig
from posenet.runtime.execution import RUN_PRECISIONS, Precision, resolve_precision

Tensor = torch.Tensor


@dataclass
class ModelConfig:
    inputs: InputConfig = field(default_factory=InputConfig)
    base: int = 16  # U-Net width (channels of its first level)
    depth: int = 3  # U-Net downsamplings; 3 suits 96x96 crops (12x12 at the bottom), 4 the paper's 320x240
    aggregation: str = "3d"  # "3d": the paper's method; "2d": its 2D-loss baseline
    eps: float = lifting.EPS_LOGIT  # the logit given to points outside the box or without depth
    channels_last: bool = True  # faster on every CPU measured, AVX2 and AVX512 (benchmarks/posenet_speed.py)
    # U-Net precision: "auto" = bf16 autocast where the device computes bf16 natively, fp32 elsewhere
    # (posenet.runtime.execution); lifting stays float32. Loading a checkpoint replaces it with the loader's request, so
    # the machine that trained a checkpoint never decides how another machine runs it.
    precision: str = "auto"
    flip_test: bool = False  # inference: also run the mirrored inputs and average (2x the U-Net work)

    @classmethod
    def from_dict(cls, d: dict) -> ModelConfig:
        """A config saved by any version: the old ``bf16`` flag (the trainer's machine's choice) is dropped."""
        d = {k: v for k, v in d.items() if k != "bf16"}
        return cls(**d)

    def __post_init__(self) -> None:
        if isinstance(self.inputs, dict):
            self.inputs = InputConfig(**self.inputs)
        if self.precision not in RUN_PRECISIONS:
            raise ValueError(f"precision must be one of {RUN_PRECISIONS}, got {self.precision!r}")
        if self.aggregation not in ("3d", "2d"):
            raise ValueError(f"aggregation must be '3d' or '2d', got {self.aggregation!r}")
        stride = 2**self.depth
        sizes = [self.inputs.network_size(t) for t in (True, False)]
        if self.inputs.mode == "crop":
            sizes = sizes[:1]
        for w, h in sizes:
            if w % stride or h % stride:
                raise ValueError(f"network input {w}x{h} is not a multiple of the U-Net stride {stride}")

    @property
    def unet(self) -> UNetConfig:
        return UNetConfig(in_channels=self.inputs.in_channels, base=self.base, depth=self.depth)


@dataclass
class PoseOutput:
    """joints (P, J, 3) mm, spread_mm (P, J) mm (the joints' spread), logits (P, V, J, M) at the scene's points, has_points (P,),
    and for the 2D baseline uv_hat (P, V, J, 2) with view_valid (P, V)."""

    joints: Tensor
    spread_mm: Tensor
    has_points: Tensor
    logits: Tensor
    uv_hat: Tensor | None = None
    view_valid: Tensor | None = None


class PoseNet(nn.Module):
    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        self.unet = UNet(config.unet)
        if config.channels_last:
            self.unet = self.unet.to(memory_format=torch.channels_last)
        # An inference runtime's copy of the U-Net (posenet.runtime.graphs.OnnxRunner), used instead of it when no
        # gradient is needed; set by posenet.net.infer.PoseEstimator.
        self.runner = None

    def precision(self, device: torch.device | str | None = None) -> Precision:
        """The precision the U-Net runs at on ``device`` (default: where the weights are), and why."""
        device = torch.device(device) if device is not None else next(self.parameters()).device
        return _resolved(self.config.precision, str(device))

    def _autocast(self, device: torch.device):
        if self.precision(device).bf16:
            return torch.autocast(device.type, dtype=torch.bfloat16)
        return contextlib.nullcontext()

    def _unet(self, x: Tensor) -> Tensor:
        if self.runner is not None and not torch.is_grad_enabled():
            return self.runner(x=x)[0].to(x.device)
        with self._autocast(x.device):
            return self.unet(x)

    def heatmaps(self, scenes: list[SceneInput]) -> list[Tensor]:
        """U-Net logits ``(P*V, J, h, w)`` per scene, zeros for (person, view) pairs without a box.

        Every pair of every scene runs in one U-Net batch (scenes of one batch share the network input size).
        """
        device = next(self.parameters()).device
        runs = [s.has_box.reshape(-1).to(device) for s in scenes]  # (P*V,) per scene
        out = self.unet_logits(torch.cat([s.images.to(device)[r] for s, r in zip(scenes, runs, strict=True)]))
        J = self.config.unet.out_channels
        heats, start = [], 0
        for s, r in zip(scenes, runs, strict=True):
            n = int(r.sum())
            heat = out.new_zeros(r.shape[0], J, *s.images.shape[-2:])
            heat[r] = out[start : start + n]
            heats.append(heat)
            start += n
        return heats

    def unet_logits(self, x: Tensor) -> Tensor:
        """The U-Net (or the runtime that replaces it) on network inputs ``x (N, C, h, w)``: float32 logits
        ``(N, J, h, w)``."""
        x = x.to(next(self.parameters()).device)
        if self.config.channels_last and (self.runner is None or torch.is_grad_enabled()):
            # torch's convolutions only: an exported graph reads NCHW, and a channels_last tensor would be
            # copied there again on its way in (posenet.runtime.graphs)
            x = x.contiguous(memory_format=torch.channels_last)
        if not x.shape[0]:
            return x.new_zeros(0, self.config.unet.out_channels, *x.shape[-2:])
        return self._unet(x).float().contiguous()

    def forward(self, scenes: SceneInput | list[SceneInput]) -> PoseOutput | list[PoseOutput]:
        """One scene -> its :class:`PoseOutput`; a list of scenes -> a list (one U-Net pass for them all)."""
        single = isinstance(scenes, SceneInput)
        batch = [scenes] if single else list(scenes)
        outputs = [self._joints(s, h) for s, h in zip(batch, self.heatmaps(batch), strict=True)]
        return outputs[0] if single else outputs

    def _joints(self, scene: SceneInput, heat: Tensor) -> PoseOutput:
        dev = heat.device
        logits = self.logits(scene, heat)  # (P, V, J, M)
        uv, depth, valid = scene.uv.to(dev), scene.depth.to(dev), scene.valid.to(dev)
        return self.estimate(logits, uv, depth, valid, scene.cameras)

    def logits(self, scene: SceneInput, heat: Tensor) -> Tensor:
        """The U-Net's ``heat (P*V, J, h, w)`` of ``scene`` at its lifting points: ``(P, V, J, M)`` logits in
        original pixels with un-flipped channels."""
        P, V = scene.has_box.shape
        A, flipped = scene.A.to(heat.device), scene.flipped.to(heat.device)
        if scene.mode == "full":
            heat = aug.inverse_warp(heat, A, scene.image_size)  # (P*V, J, H, W)
        heat = aug.unflip_channels(heat, flipped)
        return heat.reshape(P, V, heat.shape[1], heat.shape[-2] * heat.shape[-1])  # (P, V, J, M); P may be 0

    def estimate(self, logits: Tensor, uv: Tensor, depth: Tensor, valid: Tensor, cameras) -> PoseOutput:
        """Joints from logits ``(P, S, J, M)`` at points ``uv (P or 1, S, M, 2)``, ``depth (P or 1, S, M)``,
        ``valid (P, S, M)`` seen by ``cameras`` of batch shape (S,) or (P, S), with this model's aggregation.

        S is the views of a scene, or any set of (view, box) slots per person (``posenet.net.box_poses``)."""
        if self.config.aggregation == "2d":
            est = lifting.fuse_2d(logits, uv, depth, valid, cameras, self.config.eps)
            uv_hat, view_valid = lifting.centre_of_mass_2d(logits, uv, valid, self.config.eps)
            return PoseOutput(est.joints, est.spread_mm, est.has_points, logits, uv_hat, view_valid)
        points = lifting.lift(cameras, uv, depth)  # (P or 1, S, M, 3)
        est = lifting.aggregate(logits, points, valid, self.config.eps)
        return PoseOutput(est.joints, est.spread_mm, est.has_points, logits)


@functools.cache
def _resolved(requested: str, device: str) -> Precision:
    return resolve_precision(requested, device)


def average_flips(plain: PoseOutput, mirrored: PoseOutput) -> PoseOutput:
    """Test-time flip averaging: the mean of the joints (and spreads) of a scene and of its mirrored copy.

    Both are already in original pixels and un-flipped channels, so they estimate the same joints."""
    return PoseOutput(
        (plain.joints + mirrored.joints) / 2,
        (plain.spread_mm + mirrored.spread_mm) / 2,
        plain.has_points & mirrored.has_points,
        plain.logits,
    )


def predict_scenes(model: PoseNet, build, count: int) -> list[PoseOutput]:
    """Inference on ``count`` scenes built by ``build(i, mirror) -> SceneInput``, in one U-Net pass, with the
    flip averaging of ``model.config.flip_test``."""
    scenes = [build(i, False) for i in range(count)]
    if model.config.flip_test:
        scenes += [build(i, True) for i in range(count)]
    outs = model(scenes)
    if model.config.flip_test:
        return [average_flips(a, b) for a, b in zip(outs[:count], outs[count:], strict=True)]
    return outs
