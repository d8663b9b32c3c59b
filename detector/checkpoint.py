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
    half: bool = False,
    top: dict | None = None,
) -> Path:
    """Write ``model``'s weights and the resolved configs to ``path`` (a folder or ``NAME.safetensors``).

    ``half`` stores floating-point weights as float16 (loading casts them back); ``top`` adds keys at the top of
    ``config.json`` (e.g. the shipped weights' ``trained_on`` line).
    """
    path = Path(path)
    if path.suffix != ".safetensors":
        path.mkdir(parents=True, exist_ok=True)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    weights, config = checkpoint_files(path)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    if half:
        state = {k: v.half() if v.is_floating_point() else v for k, v in state.items()}
    state = {k: v.contiguous() for k, v in state.items()}
    save_file(state, str(weights), metadata={"format": "pt", "dtype": "float16" if half else "as trained"})
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
    missing, unexpected = model.load_state_dict(load_file(str(weights)), strict=False)
    if missing or unexpected:
        raise ValueError(
            f"checkpoint {weights} does not fit its config: "
            f"missing {missing[:5]}, unexpected {unexpected[:5]}"
        )
    return model.to(device).eval(), cfg, meta
