"""What ``GET /model`` says: the joints, what the pose network reads, its input size, and the training data.

The training data is read from the checkpoints' own configs (the resolved config saved beside the weights), so
the answer describes the weights actually loaded rather than what a deployment claims: their ``"trained_on"``
section (``posenet.net.checkpoint_files``), written by ``posenet.training.train``, ``posenet.training.adapt`` and ``detector.train``.
"""

from __future__ import annotations

from pipeline.two_stage import ScenePipeline
from posenet.runtime.execution import machine
from posenet.skeleton import JOINTS
from service.schemas import ModelInfo, Runtime

# Checkpoints from before the shared layout (no "trained_on" section): the config keys that say what a model saw
# in training, in the order they are reported.
_DATA_KEYS = (
    "trained_on", "data", "extra_data", "dataset", "annotations", "days", "train_days", "holdout_day", "test_day",
    "train_frames", "extra_train_frames", "val_frames", "train_images", "subsample", "epochs", "steps", "preset",
)  # fmt: skip
# Where the training scripts put them: top level, or a section of the saved config.
_SECTIONS = ("train", "data", "data_description")


def _line(trained_on: dict | str) -> str:
    if isinstance(trained_on, str):
        return trained_on
    return ", ".join(f"{key}={_line(value) if isinstance(value, dict) else value}" for key, value in trained_on.items()
                     if value not in (None, [], ""))  # fmt: skip


def summarise_training(config: dict) -> str:
    """A one-line account of the training data in a checkpoint config: its ``"trained_on"`` section, else (an old
    checkpoint) whichever known keys it holds."""
    trained_on = config.get("trained_on")
    if trained_on:
        return _line(trained_on)
    # Old checkpoints only: search the keys where the training scripts used to put the account.
    found = {}
    for section in (config, *(config.get(name) for name in _SECTIONS)):
        if isinstance(section, dict):
            for key in _DATA_KEYS:
                value = section.get(key)
                if value is not None and not isinstance(value, dict) and key not in found:
                    found[key] = value
    if not found:
        return "not recorded in the checkpoint's config"
    return ", ".join(f"{key}={value}" for key, value in found.items())


def model_info(pipeline: ScenePipeline, device: str) -> ModelInfo:
    inputs = pipeline.pose.model.config.inputs
    return ModelInfo(
        joints=list(JOINTS),
        modalities=list(pipeline.modalities),
        detector_modalities=list(pipeline.detector_modalities),
        input_size=inputs.network_size(False),
        read_size=None if pipeline.read_size is None else list(pipeline.read_size),
        pose_trained_on=summarise_training(pipeline.pose.config),
        detector_trained_on=None if pipeline.detector is None else summarise_training(pipeline.detector_meta),
        detector_loaded=pipeline.detector is not None,
        device=device,
        runtime=[
            Runtime(
                network=name,
                backend=net.backend.name,
                backend_reason=net.backend.reason,
                precision=net.precision.name,
                precision_reason=net.precision.reason,
            )
            for name, net in (("pose", pipeline.pose), ("detector", pipeline.detector))
            if net is not None
        ],
        machine=machine(),
    )
