"""The checkpoint layout that both stages share (``posenet.net.checkpoint`` and ``detector.checkpoint`` use it).

A checkpoint is a folder ``CKPT/`` holding

- ``model.safetensors``: the weights;
- ``config.json``: ``{"model": the model config, "train": the training config, "trained_on": what the weights
  were trained on (a dict, or a one-line string for shipped weights), ...}`` plus any stage-specific sections
  (the pose network's ``"calibration"``, the detector's ``"detr"`` and ``"progress"``);
- ``train_state.pt`` (optional): what ``--resume`` needs (optimiser, schedule, progress).

or a bare ``NAME.safetensors`` with ``NAME.json`` beside it (the shipped ``*/weights/default.*``). Files are
written beside and then renamed, so an interrupted save never leaves a half-written checkpoint.

Configs written before this layout are still read: pose configs kept the training config at the top level (with
the model config under ``"model"``), detector configs kept the model config under ``"detector"``, and detector
runs saved their resume state as ``training_state.pt``.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import save_file

WEIGHTS, CONFIG, STATE = "model.safetensors", "config.json", "train_state.pt"
OLD_STATE = "training_state.pt"  # detector runs from before the shared layout


def checkpoint_config(model: dict, train: dict | None, trained_on: dict | str | None, **sections) -> dict:
    """The ``config.json`` of a checkpoint: the three sections every checkpoint carries, then ``sections``."""
    return {"model": model, "train": train, "trained_on": trained_on, **sections}


def files(path: str | Path) -> tuple[Path, Path]:
    """The ``(weights, config)`` files of a checkpoint folder (existing or to be), a ``NAME.safetensors`` file or
    its ``NAME.json``."""
    path = Path(path)
    if path.is_dir() or (not path.exists() and path.suffix == ""):
        return path / WEIGHTS, path / CONFIG
    if path.suffix == ".safetensors":
        return path, path.with_suffix(".json")
    if path.suffix == ".json":
        return path.with_suffix(".safetensors"), path
    raise ValueError(f"checkpoint {path} is neither a folder nor a .safetensors/.json file")


def stored(path: str | Path) -> Path:
    """The checkpoint that ``path`` names, for reading: a checkpoint folder or file as it is; a training or
    adaptation run's folder (no weights of its own) its ``best/``, else its ``last/`` checkpoint."""
    path = Path(path)
    if path.is_dir() and not (path / WEIGHTS).is_file():
        for sub in (path / "best", path / "last"):
            if (sub / WEIGHTS).is_file():
                return sub
    return path


def _replace(target: Path, write) -> None:
    tmp = target.with_name(target.name + ".tmp")
    write(tmp)
    tmp.replace(target)


def write_checkpoint(
    path: str | Path,
    weights: dict[str, torch.Tensor],
    config: dict,
    train_state: dict | None = None,
    metadata: dict[str, str] | None = None,
) -> Path:
    """Write ``weights`` (safetensors, with ``metadata``), ``config`` (json) and, for a folder, ``train_state``
    (``train_state.pt``) to the checkpoint ``path`` (a folder or ``NAME.safetensors``); returns the weights file."""
    weights_file, config_file = files(path)
    weights_file.parent.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().contiguous() for k, v in weights.items()}
    _replace(weights_file, lambda f: save_file(tensors, str(f), metadata=metadata))
    _replace(config_file, lambda f: f.write_text(json.dumps(config, indent=2, default=str)))
    if train_state is not None:
        _replace(weights_file.parent / STATE, lambda f: torch.save(train_state, f))
    return weights_file


def read_config(path: str | Path) -> dict:
    """The ``config.json`` dict of a checkpoint (folder, run folder, ``.safetensors`` or ``.json``)."""
    _, config = files(stored(path))
    if not config.is_file():
        raise FileNotFoundError(f"checkpoint config {config} does not exist")
    return json.loads(config.read_text())


def train_state_file(folder: str | Path) -> Path | None:
    """The resume state of the checkpoint ``folder``: ``train_state.pt``, else an old detector run's
    ``training_state.pt``; None when it has neither."""
    for name in (STATE, OLD_STATE):
        if (Path(folder) / name).is_file():
            return Path(folder) / name
    return None


def keep_input_channels(state: dict, in_channels: int, keep: list[int]) -> tuple[dict, str]:
    """``state`` with the one 4-D weight that reads ``in_channels`` input channels (the network's first convolution)
    reduced to the channels ``keep`` (their indices, in the new order), every other tensor shared: the weights of a
    network that reads fewer inputs (colour + depth -> depth alone), which on inputs whose dropped channels are 0
    computes what ``state`` computes. Returns the new dict and the reduced tensor's name; ValueError unless exactly
    one tensor reads ``in_channels`` channels."""
    first = [name for name, value in state.items() if value.ndim == 4 and value.shape[1] == in_channels]
    if len(first) != 1:
        raise ValueError(f"expected one first convolution reading {in_channels} channels, found {first}")
    state = dict(state)
    state[first[0]] = state[first[0]][:, keep].clone()
    return state, first[0]
