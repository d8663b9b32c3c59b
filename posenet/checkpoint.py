"""Saving and loading pose-network checkpoints: safetensors weights, the resolved config in json beside them.

A checkpoint is a folder ``CKPT/`` holding ``model.safetensors`` (the :class:`posenet.model.PoseNet` weights),
``config.json`` (the resolved training config: preset, modality, input size, model, augmentation, data)
and, for resuming, ``train_state.pt`` (epoch, optimiser, scheduler, best score). A run folder holds ``last/``
and ``best/`` (by validation MPJPE). A bare ``NAME.safetensors`` with ``NAME.json`` beside it (the shipped
default weights, ``posenet/weights/default.safetensors``) loads the same way.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file

from posenet.model import ModelConfig, PoseNet

DEFAULT_WEIGHTS = Path(__file__).parent / "weights" / "default.safetensors"


def save_checkpoint(
    folder: str | Path, model: PoseNet, config: dict, train_state: dict | None = None
) -> Path:
    """Write ``model.safetensors`` + ``config.json`` (+ ``train_state.pt``) into ``folder`` and return it.

    ``config`` must hold the model's resolved config under ``"model"`` (as ``dataclasses.asdict`` gives it).
    Files are written beside and then renamed, so an interrupted save never leaves a half-written checkpoint.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if "model" not in config:
        raise ValueError("the checkpoint config must hold the model's config under 'model'")
    weights = {k: v.detach().cpu().contiguous() for k, v in model.state_dict().items()}
    save_file(weights, folder / "model.safetensors.tmp")
    (folder / "model.safetensors.tmp").replace(folder / "model.safetensors")
    (folder / "config.json.tmp").write_text(json.dumps(config, indent=2, default=str))
    (folder / "config.json.tmp").replace(folder / "config.json")
    if train_state is not None:
        torch.save(train_state, folder / "train_state.pt.tmp")
        (folder / "train_state.pt.tmp").replace(folder / "train_state.pt")
    return folder


def checkpoint_files(path: str | Path | None) -> tuple[Path, Path]:
    """The ``(weights, config)`` files of a checkpoint folder, a run folder (its ``best/``, else ``last/``),
    or a ``NAME.safetensors`` file; None means the shipped default weights."""
    if path is None:
        path = DEFAULT_WEIGHTS
        if not path.is_file():
            raise FileNotFoundError(
                f"no default pose weights at {path}. Train a model with `python -m posenet.train --data DIR "
                "--holdout-day 4 --out RUN` and pass `--checkpoint RUN/best` (or copy "
                "RUN/best/model.safetensors "
                "and RUN/best/config.json to posenet/weights/default.safetensors and default.json)"
            )
    path = Path(path)
    if path.is_dir():
        for sub in (path, path / "best", path / "last"):
            if (sub / "model.safetensors").is_file():
                return sub / "model.safetensors", sub / "config.json"
        raise FileNotFoundError(f"{path} holds no model.safetensors (nor best/ or last/ with one)")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    return path, path.with_suffix(".json")


def load_checkpoint(
    path: str | Path | None, device: str | torch.device = "cpu", precision: str = "auto"
) -> tuple[PoseNet, dict]:
    """The :class:`PoseNet` of a checkpoint (in eval mode, on ``device``) and its config dict.

    ``precision`` (``auto``, ``fp32``, ``bf16``) is how *this* machine runs it (``posenet.execution``); whatever
    the training machine used is ignored."""
    weights, config_file = checkpoint_files(path)
    if not config_file.is_file():
        raise FileNotFoundError(f"checkpoint {weights} has no config beside it ({config_file} is missing)")
    config = json.loads(config_file.read_text())
    if "model" not in config:
        raise ValueError(f"{config_file} has no 'model' section: not a pose-network checkpoint config")
    model = PoseNet(ModelConfig.from_dict({**config["model"], "precision": precision}))
    state = load_file(weights, device="cpu")
    missing, unexpected = model.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise ValueError(
            f"{weights} does not fit its config: missing {missing[:5]}, unexpected {unexpected[:5]}"
        )
    return model.to(device).eval(), config
