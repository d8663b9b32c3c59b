"""Saving and loading pose-network checkpoints, in the layout both stages share (``posenet.net.checkpoint_files``).

A checkpoint is a folder ``CKPT/`` holding ``model.safetensors`` (the :class:`posenet.net.model.PoseNet` weights),
``config.json`` (``"model"``: the model config; ``"train"``: the resolved training config (preset, data,
augmentation, data description); ``"trained_on"``; ``"calibration"`` once ``posenet.evaluation.calibrate`` has fitted one)
and, for resuming, ``train_state.pt`` (epoch, optimiser, schedule, best score). A run folder holds ``last/``
and ``best/`` (by validation MPJPE). A bare ``NAME.safetensors`` with ``NAME.json`` beside it (the shipped
default weights, ``posenet/weights/default.safetensors``) loads the same way.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import load_file

from posenet.net.checkpoint_files import CONFIG, WEIGHTS, checkpoint_config, stored, write_checkpoint
from posenet.net.model import ModelConfig, PoseNet

DEFAULT_WEIGHTS = Path(__file__).parents[1] / "weights" / "default.safetensors"


def save_checkpoint(
    folder: str | Path, model: PoseNet, config: dict, train_state: dict | None = None
) -> Path:
    """Write ``model.safetensors`` + ``config.json`` (+ ``train_state.pt``) into ``folder`` and return it.

    ``config`` must hold the model's resolved config under ``"model"`` (as ``dataclasses.asdict`` gives it); the
    training scripts build it with ``posenet.net.checkpoint_files.checkpoint_config``.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if "model" not in config:
        raise ValueError("the checkpoint config must hold the model's config under 'model'")
    write_checkpoint(folder, model.state_dict(), config, train_state)
    return folder


def sectioned(flat: dict, trained_on: dict | str | None) -> dict:
    """A training script's resolved config (``dataclasses.asdict`` of a ``TrainConfig`` or ``AdaptConfig``, its
    model config under ``"model"``) as a checkpoint config: ``{"model", "train", "trained_on"}``."""
    train = dict(flat)
    return checkpoint_config(train.pop("model"), train, trained_on)


def training_config(config: dict) -> dict:
    """The inverse of :func:`sectioned`: the flat dict a ``TrainConfig`` or ``AdaptConfig`` is built from.

    Pose configs from before the shared layout (``posenet/weights/default.json``) are flat already."""
    train = config.get("train")
    return {**train, "model": config.get("model")} if isinstance(train, dict) else config


def checkpoint_files(path: str | Path | None) -> tuple[Path, Path]:
    """The ``(weights, config)`` files of a checkpoint folder, a run folder (its ``best/``, else ``last/``),
    or a ``NAME.safetensors`` file; None means the shipped default weights."""
    if path is None:
        path = DEFAULT_WEIGHTS
        if not path.is_file():
            raise FileNotFoundError(
                f"no default pose weights at {path}. Train a model with `python -m posenet.training.train --data DIR "
                "--holdout-day 4 --out RUN` and pass `--checkpoint RUN/best` (or copy "
                "RUN/best/model.safetensors "
                "and RUN/best/config.json to posenet/weights/default.safetensors and default.json)"
            )
    path = stored(path)
    if path.is_dir():
        if (path / WEIGHTS).is_file():
            return path / WEIGHTS, path / CONFIG
        raise FileNotFoundError(f"{path} holds no model.safetensors (nor best/ or last/ with one)")
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint {path} does not exist")
    return path, path.with_suffix(".json")


def load_checkpoint(
    path: str | Path | None, device: str | torch.device = "cpu", precision: str = "auto"
) -> tuple[PoseNet, dict]:
    """The :class:`PoseNet` of a checkpoint (in eval mode, on ``device``) and its config dict.

    ``precision`` (``auto``, ``fp32``, ``bf16``) is how *this* machine runs it (``posenet.runtime.execution``); whatever
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
