"""posenet.net.checkpoint_files: the checkpoint layout both stages share, and what /model reads from it."""

import json

import pytest
import torch
from service_harness import tiny_checkpoints

from detector.checkpoint import load_checkpoint as load_detector
from posenet.net.checkpoint import load_checkpoint, save_checkpoint, sectioned, training_config
from posenet.net.checkpoint_files import (
    OLD_STATE,
    STATE,
    files,
    read_config,
    stored,
    train_state_file,
    write_checkpoint,
)
from posenet.net.model import ModelConfig, PoseNet
from service.model_info import summarise_training


def test_write_checkpoint_files_folder_and_single_file(tmp_path):
    tensors = {"w": torch.arange(6.0).view(2, 3)}
    weights = write_checkpoint(tmp_path / "run", tensors, {"model": {}, "trained_on": "x"}, {"epoch": 3})
    assert weights == tmp_path / "run" / "model.safetensors"
    assert torch.load(tmp_path / "run" / STATE)["epoch"] == 3
    assert read_config(tmp_path / "run")["trained_on"] == "x"
    single = write_checkpoint(tmp_path / "ship" / "default.safetensors", tensors, {"model": {}})
    assert files(single) == (single, single.with_suffix(".json")) == files(single.with_suffix(".json"))
    assert not list(tmp_path.rglob("*.tmp"))  # written beside, then renamed
    with pytest.raises(ValueError, match="neither a folder"):
        files(tmp_path / "run" / STATE)


def test_old_detector_resume_state_is_still_found(tmp_path):
    assert train_state_file(tmp_path) is None
    torch.save({"epoch": 1}, tmp_path / OLD_STATE)  # a detector run from before the shared layout
    assert train_state_file(tmp_path) == tmp_path / OLD_STATE
    torch.save({"epoch": 2}, tmp_path / STATE)
    assert train_state_file(tmp_path) == tmp_path / STATE


def test_pose_configs_in_sections_and_flat_load_alike(tmp_path):
    cfg = ModelConfig(base=8, depth=2)
    flat = {"model": {"base": 8, "depth": 2}, "data": "d", "preset": "cpu"}
    config = sectioned(flat, {"data": "d", "days": [1]})
    assert set(config) == {"model", "train", "trained_on"} and config["train"] == {
        "data": "d",
        "preset": "cpu",
    }
    assert training_config(config) == flat and training_config(flat) == flat  # old flat configs as they are
    save_checkpoint(tmp_path / "new", PoseNet(cfg), config)
    _, loaded = load_checkpoint(tmp_path / "new")
    assert loaded["trained_on"]["days"] == [1] and loaded["model"]["base"] == 8


def test_model_info_reads_trained_on_first(tmp_path):
    assert summarise_training({"trained_on": "rendered scenes", "data": "elsewhere"}) == "rendered scenes"
    line = summarise_training({"trained_on": {"data": "d", "days": [1, 2], "init": None, "extra_data": []}})
    assert line == "data=d, days=[1, 2]"
    old = json.loads(json.dumps({"data": "d", "holdout_day": 4, "model": {"base": 8}}))  # an old flat config
    assert summarise_training(old) == "data=d, holdout_day=4"


def test_a_run_folder_reads_as_its_best_else_last_checkpoint_for_both_stages(tmp_path):
    pose, det = tiny_checkpoints(tmp_path / "made")
    assert stored(det) == det  # a checkpoint folder, as it is
    (tmp_path / "adapt").mkdir()
    det.rename(tmp_path / "adapt" / "last")
    assert stored(tmp_path / "adapt") == tmp_path / "adapt" / "last"  # detector.adapt's run: RUN/last
    a, _, meta = load_detector(tmp_path / "adapt")
    b, _, _ = load_detector(tmp_path / "adapt" / "last")
    assert meta == read_config(tmp_path / "adapt")
    for (ka, va), (kb, vb) in zip(a.state_dict().items(), b.state_dict().items(), strict=True):
        assert ka == kb and torch.equal(va, vb)
    (tmp_path / "train").mkdir()
    pose.rename(tmp_path / "train" / "best")  # posenet.training.train's run: RUN/best, else RUN/last
    assert stored(tmp_path / "train") == tmp_path / "train" / "best"
    assert load_checkpoint(tmp_path / "train")[1] == read_config(tmp_path / "train" / "best")
    with pytest.raises(FileNotFoundError, match="do not exist"):
        load_detector(tmp_path / "train" / "nothing")
