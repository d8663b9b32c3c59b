"""The U-Net that turns one view of one person into J joint heatmaps (the paper's per-view network).

One network is shared by every view and every person: the caller stacks all persons x views of a scene into
the batch dimension, so a whole scene runs in one forward pass. The last layer is a linear 1x1 convolution
with J outputs, as in the paper: its values are logits for the 3D softmax in :mod:`posenet.net.lifting`, not
probabilities, so no activation follows it.

Input channels follow the modality (see :mod:`posenet.net.inputs`): ``rgbd`` = RGB + depth + box mask (5),
``depth`` = depth + mask (2), ``rgb`` = RGB + mask (4), plus 2 optional extra depth channels.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn
from torch.nn import functional as F

from posenet.skeleton import NUM_JOINTS


@dataclass
class UNetConfig:
    in_channels: int = 5  # the paper's RGB + depth + box mask
    out_channels: int = NUM_JOINTS  # one heatmap per joint
    base: int = 16  # channels of the first level; doubles at each level down. 16 keeps CPU training fast
    depth: int = 4  # number of 2x downsamplings; the input's sides must be divisible by 2**depth

    @property
    def stride(self) -> int:
        return 2**self.depth

    @property
    def widths(self) -> list[int]:
        """Channels of each level, from the first (``base``) to the bottom; each level down doubles them."""
        return [self.base * 2**i for i in range(self.depth + 1)]


class DoubleConv(nn.Sequential):
    """(conv 3x3 -> BatchNorm -> ReLU) x 2, the U-Net's basic block."""

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__(
            nn.Conv2d(in_channels, out_channels, 3, padding=1, bias=False),
            nn.BatchNorm2d(out_channels),
            nn.ReLU(inplace=True),
            nn.Conv2d(out_channels, out_channels, 3, padding=1, bias=False),
            nn.BatchNorm2d(out_channels),
            nn.ReLU(inplace=True),
        )


class Up(nn.Module):
    """Bilinear 2x upsampling, concatenation with the skip connection, then a :class:`DoubleConv`."""

    def __init__(self, in_channels: int, skip_channels: int, out_channels: int) -> None:
        super().__init__()
        self.conv = DoubleConv(in_channels + skip_channels, out_channels)

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
        return self.conv(torch.cat([x, skip], dim=1))


class UNet(nn.Module):
    """U-Net (Ronneberger et al. 2015) with bilinear upsampling and a linear head.

    ``forward(x (N, C, H, W)) -> (N, J, H, W)`` logits, where H and W are multiples of ``config.stride``.
    """

    def __init__(self, config: UNetConfig) -> None:
        super().__init__()
        if config.depth < 1 or config.base < 1 or config.in_channels < 1:
            raise ValueError(f"invalid UNetConfig {config}")
        self.config = config
        widths = config.widths
        self.stem = DoubleConv(config.in_channels, widths[0])
        self.downs = nn.ModuleList(DoubleConv(widths[i], widths[i + 1]) for i in range(config.depth))
        self.ups = nn.ModuleList(
            Up(widths[i + 1], widths[i], widths[i]) for i in reversed(range(config.depth))
        )
        self.head = nn.Conv2d(widths[0], config.out_channels, 1)  # linear: logits for the 3D softmax

    def forward_features(self, x: torch.Tensor) -> torch.Tensor:
        """``(N, C, H, W)`` -> ``(N, base, H, W)`` features at full resolution."""
        if x.ndim != 4 or x.shape[1] != self.config.in_channels:
            raise ValueError(f"UNet expects (N, {self.config.in_channels}, H, W), got {tuple(x.shape)}")
        s = self.config.stride
        if x.shape[-1] % s or x.shape[-2] % s:
            raise ValueError(f"UNet input sides must be multiples of {s}, got {tuple(x.shape[-2:])}")
        skips = [self.stem(x)]
        for down in self.downs:
            skips.append(down(F.max_pool2d(skips[-1], 2)))
        y = skips.pop()
        for up in self.ups:
            y = up(y, skips.pop())
        return y

    def forward_head(self, features: torch.Tensor) -> torch.Tensor:
        return self.head(features)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.forward_head(self.forward_features(x))

    def flops(self, height: int, width: int) -> int:
        """Multiply-adds x 2 of one forward pass on one ``height x width`` input (convolutions only)."""
        total = 0

        def hook(module: nn.Conv2d, _inp, out) -> None:
            nonlocal total
            k = module.kernel_size[0] * module.kernel_size[1] * module.in_channels // module.groups
            total += 2 * k * out.numel()

        handles = [m.register_forward_hook(hook) for m in self.modules() if isinstance(m, nn.Conv2d)]
        was_training = self.training
        self.eval()  # so counting does not touch the BatchNorm running statistics
        try:
            with torch.no_grad():
                p = next(self.parameters())
                self.forward(
                    torch.zeros(1, self.config.in_channels, height, width, dtype=p.dtype, device=p.device)
                )
        finally:
            for h in handles:
                h.remove()
            self.train(was_training)
        return total


def _convolutions(depth: int) -> dict:
    """Each convolution of a U-Net of this depth (its key prefix) -> ``(level in, level out)``: a level's width
    is ``base * 2**level``; ``"in"`` is the network's input, ``"joints"`` the heatmaps, ``("up", i)`` the
    concatenation of the upsampled level i + 1 and the skip of level i."""
    convs = {"stem.0": ("in", 0), "stem.3": (0, 0)}
    for i in range(depth):
        convs[f"downs.{i}.0"] = (i, i + 1)
        convs[f"downs.{i}.3"] = (i + 1, i + 1)
    for k, i in enumerate(reversed(range(depth))):
        convs[f"ups.{k}.conv.0"] = (("up", i), i)
        convs[f"ups.{k}.conv.3"] = (i, i)
    convs["head"] = (0, "joints")
    return convs


def _width(level, cfg: UNetConfig) -> int:
    if level == "in":
        return cfg.in_channels
    if level == "joints":
        return cfg.out_channels
    return cfg.widths[level]


def widen_state_dict(small_state: dict, small: UNetConfig, wide: UNet, prefix: str = "") -> dict:
    """The weights of the wider U-Net ``wide`` that compute exactly what ``small_state`` (a U-Net of config
    ``small``: the same depth and channels in and out, a smaller ``base``) computes.

    Each of the small network's channels keeps its place (the first channels of its level) and its weights; the
    new channels keep ``wide``'s fresh initialisation for what flows into them, but every weight from a new
    channel into an old one (and into the head) is zero, and BatchNorm normalises per channel, so the old
    channels, and the logits, are the small network's in training and in evaluation mode alike. Training then
    connects the new channels (their outgoing weights get gradients at once): more capacity, started from what
    the small network has learnt. ``prefix`` is the U-Net's key prefix in both state dicts (``"unet."`` in a
    :class:`posenet.net.model.PoseNet`).
    """
    big = wide.config
    if (big.depth, big.in_channels, big.out_channels) != (small.depth, small.in_channels, small.out_channels):
        raise ValueError(f"widening keeps the depth and the channels in and out: got {small} -> {big}")
    if big.base < small.base:
        raise ValueError(f"cannot widen base {small.base} to a narrower {big.base}")
    out = {prefix + k: v.clone() for k, v in wide.state_dict().items()}
    if unknown := sorted(set(small_state) - set(out)):
        raise ValueError(f"weights that a U-Net of depth {big.depth} does not have: {unknown[:3]}")
    if missing := sorted(set(out) - set(small_state)):
        raise ValueError(f"weights of a U-Net of depth {big.depth} that the small one lacks: {missing[:3]}")
    for conv, (level_in, level_out) in _convolutions(small.depth).items():
        if isinstance(level_in, tuple):  # concatenation: [upsampled level i + 1, skip of level i]
            i = level_in[1]
            cols = torch.cat(
                [torch.arange(_width(i + 1, small)), _width(i + 1, big) + torch.arange(_width(i, small))]
            )
        else:
            cols = torch.arange(_width(level_in, small))
        rows = _width(level_out, small)
        w = out[f"{prefix}{conv}.weight"]
        w[:rows] = 0  # the old channels take nothing from the new ones ...
        w[:rows, cols] = small_state[f"{prefix}{conv}.weight"].to(w.dtype)  # ... their own as before
        if f"{prefix}{conv}.bias" in small_state:
            out[f"{prefix}{conv}.bias"][:rows] = small_state[f"{prefix}{conv}.bias"]
        if conv != "head":  # the BatchNorm right after each convolution of a DoubleConv
            bn = f"{prefix}{conv[:-1]}{int(conv[-1]) + 1}"
            for name in ("weight", "bias", "running_mean", "running_var"):
                out[f"{bn}.{name}"][:rows] = small_state[f"{bn}.{name}"]
            out[f"{bn}.num_batches_tracked"] = small_state[f"{bn}.num_batches_tracked"].clone()
    return out
