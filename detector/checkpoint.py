"""Detector checkpoints: ``model.safetensors`` + ``config.json`` (+ ``training_state.pt`` for resuming).

``config.json`` holds the resolved ``DetectorConfig`` (architecture and preprocessing), the exact transformers
``DetrConfig`` the weights belong to (so a fine-tuned pretrained DETR rebuilds without its original folder),
and the training config and progress when written by ``detector.train``. A checkpoint is either a folder
holding those files, or a ``NAME.safetensors`` file with ``NAME.json`` beside it (the shipped
``detector/weights/default.*``).
"""

from __future__ import annotations

import json
from dataclasses import asdict, replace
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file
from transformers import DetrForObjectDetection

from detector.model import DetectorConfig, arch_classes, from_detr_config

WEIGHTS, CONFIG, STATE = "model.safetensors", "config.json", "training_state.pt"
PRECISIONS = ("float32", "float16", "int8")
INT8_SCALE = ".int8_scale"  # key suffix of the per-output-channel scales of an int8 weight


def quantize_int8(state: dict[str, torch.Tensor], min_numel: int = 4096) -> dict[str, torch.Tensor]:
    """Weight-only int8: every floating weight matrix / conv kernel of ``min_numel`` or more values becomes int8
    with one float32 scale per output channel (symmetric, ``w ~ q * scale``, ``|q| <= 127``); the rest (biases,
    norms, running statistics) is stored as float16. ``dequantize`` inverts it."""
    out = {}
    for k, v in state.items():
        if v.is_floating_point() and v.ndim >= 2 and v.numel() >= min_numel:
            w = v.float()
            scale = w.abs().amax(dim=tuple(range(1, w.ndim)), keepdim=True).clamp(min=1e-12) / 127.0
            out[k] = torch.round(w / scale).clamp(-127, 127).to(torch.int8)
            out[k + INT8_SCALE] = scale.flatten()
        else:
            out[k] = v.half() if v.is_floating_point() else v
    return out


def dequantize(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The float32 weights of a ``quantize_int8`` state (other states pass through)."""
    out = {k: v for k, v in state.items() if not k.endswith(INT8_SCALE)}
    for k, scale in state.items():
        if k.endswith(INT8_SCALE):
            q = out[k[: -len(INT8_SCALE)]]
            out[k[: -len(INT8_SCALE)]] = q.float() * scale.view(-1, *([1] * (q.ndim - 1)))
    return out


def checkpoint_files(path: str | Path) -> tuple[Path, Path]:
    """The (weights, config) files of a checkpoint folder or ``.safetensors`` file."""
    path = Path(path)
    if path.is_dir() or (not path.exists() and path.suffix == ""):
        return path / WEIGHTS, path / CONFIG
    if path.suffix == ".safetensors":
        return path, path.with_suffix(".json")
    if path.suffix == ".json":
        return path.with_suffix(".safetensors"), path
    raise ValueError(f"checkpoint {path} is neither a folder nor a .safetensors/.json file")


def save_checkpoint(
    path: str | Path,
    model: DetrForObjectDetection,
    cfg: DetectorConfig,
    train: dict | None = None,
    progress: dict | None = None,
    precision: str = "float32",
    top: dict | None = None,
) -> Path:
    """Write ``model``'s weights and the resolved configs to ``path`` (a folder or ``NAME.safetensors``).

    ``precision``: ``float32`` (as trained), ``float16`` (half the size) or ``int8`` (weight-only, per-output-
    channel scales: a quarter of the size; ``quantize_int8``); loading casts back to float32. ``top`` adds keys at
    the top of ``config.json`` (e.g. the shipped weights' ``trained_on`` line).
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    path = Path(path)
    if path.suffix != ".safetensors":
        path.mkdir(parents=True, exist_ok=True)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    weights, config = checkpoint_files(path)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    if precision == "float16":
        state = {k: v.half() if v.is_floating_point() else v for k, v in state.items()}
    elif precision == "int8":
        state = quantize_int8(state)
    state = {k: v.contiguous() for k, v in state.items()}
    save_file(state, str(weights), metadata={"format": "pt", "dtype": precision})
    meta = {
        **(top or {}),
        "detector": asdict(cfg),
        "detr": model.config.to_dict(),
        "train": train,
        "progress": progress,
    }
    config.write_text(json.dumps(meta, indent=2, default=str))
    return weights


def read_config(path: str | Path) -> dict:
    """The ``config.json`` dict of a checkpoint."""
    _, config = checkpoint_files(path)
    if not config.is_file():
        raise FileNotFoundError(f"checkpoint config {config} does not exist")
    return json.loads(config.read_text())


def load_checkpoint(
    path: str | Path, device: str | torch.device = "cpu"
) -> tuple[DetrForObjectDetection, DetectorConfig, dict]:
    """Rebuild the model of a checkpoint and load its weights; returns ``(model in eval mode, cfg, meta)``."""
    weights, _ = checkpoint_files(path)
    if not weights.is_file():
        raise FileNotFoundError(f"checkpoint weights {weights} do not exist")
    meta = read_config(path)
    cfg = DetectorConfig(**meta["detector"])
    # The weights are in the file: rebuild the architecture from the saved DetrConfig, never from the hub.
    cfg = replace(cfg, pretrained=None)
    detr = dict(meta["detr"])
    detr.pop("transformers_version", None)
    config_class = arch_classes(detr.get("model_type", "detr"))[0]
    model = from_detr_config(config_class.from_dict(detr), cfg)
    missing, unexpected = model.load_state_dict(dequantize(load_file(str(weights))), strict=False)
    if missing or unexpected:
        raise ValueError(
            f"checkpoint {weights} does not fit its config: "
            f"missing {missing[:5]}, unexpected {unexpected[:5]}"
        )
    return model.to(device).eval(), cfg, meta
