"""Detector checkpoints, in the layout both stages share (``posenet.net.checkpoint_files``): ``model.safetensors`` +
``config.json`` (+ ``train_state.pt`` for resuming).

``config.json`` holds ``"model"``: the resolved ``DetectorConfig`` (architecture and preprocessing); ``"train"``:
the training config (when written by ``detector.train``); ``"trained_on"``; ``"detr"``: the exact transformers
``DetrConfig`` the weights belong to (so a fine-tuned pretrained DETR rebuilds without its original folder); and
``"progress"``. A checkpoint is either a folder holding those files, or a ``NAME.safetensors`` file with
``NAME.json`` beside it (the shipped ``detector/weights/default.*``, written before the shared layout: its model
config is under ``"detector"``, which :func:`model_config` still reads).
"""

from __future__ import annotations

from dataclasses import asdict, replace
from pathlib import Path

import torch
from safetensors.torch import load_file
from transformers import DetrForObjectDetection

from detector.model import DetectorConfig, arch_classes, from_detr_config
from posenet.net.checkpoint_files import checkpoint_config, files, read_config, stored, write_checkpoint

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


def save_checkpoint(
    path: str | Path,
    model: DetrForObjectDetection,
    cfg: DetectorConfig,
    train: dict | None = None,
    progress: dict | None = None,
    precision: str = "float32",
    trained_on: dict | str | None = None,
    train_state: dict | None = None,
) -> Path:
    """Write ``model``'s weights and the resolved configs to ``path`` (a folder or ``NAME.safetensors``), and in a
    folder the ``train_state`` that ``--resume`` needs.

    ``precision``: ``float32`` (as trained), ``float16`` (half the size) or ``int8`` (weight-only, per-output-
    channel scales: a quarter of the size; ``quantize_int8``); loading casts back to float32. ``trained_on``: what
    the weights were trained on (``detector.train``'s data description, or the shipped weights' line).
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    path = Path(path)
    if path.suffix != ".safetensors":
        path.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() for k, v in model.state_dict().items()}
    if precision == "float16":
        state = {k: v.half() if v.is_floating_point() else v for k, v in state.items()}
    elif precision == "int8":
        state = quantize_int8(state)
    meta = checkpoint_config(asdict(cfg), train, trained_on, detr=model.config.to_dict(), progress=progress)
    return write_checkpoint(path, state, meta, train_state, metadata={"format": "pt", "dtype": precision})


def model_config(meta: dict) -> dict:
    """The ``DetectorConfig`` dict of a checkpoint config (under ``"detector"`` in configs from before the
    shared layout, such as the shipped ``detector/weights/default.json``)."""
    return meta["model"] if "model" in meta else meta["detector"]


def trained_on(meta: dict) -> dict | str | None:
    """What a detector checkpoint was trained on; configs from before the shared layout kept a run's account in
    the model config's ``extra``."""
    return meta.get("trained_on") or model_config(meta).get("extra", {}).get("trained_on")


def load_checkpoint(
    path: str | Path, device: str | torch.device = "cpu"
) -> tuple[DetrForObjectDetection, DetectorConfig, dict]:
    """Rebuild the model of a checkpoint (a folder or ``NAME.safetensors``; a ``detector.adapt`` run's folder
    reads its ``last/``) and load its weights; returns ``(model in eval mode, cfg, meta)``."""
    path = stored(path)
    weights, _ = files(path)
    if not weights.is_file():
        raise FileNotFoundError(f"checkpoint weights {weights} do not exist")
    meta = read_config(path)
    cfg = DetectorConfig(**model_config(meta))
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
