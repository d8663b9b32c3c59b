import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from tiny_scenes import write_dataset

from posenet.data.mvor import MvorDataset
from posenet.evaluation.predict import main as predict_main
from posenet.net.augment import AugmentConfig
from posenet.net.inputs import InputConfig, build_scene
from posenet.net.loss import mpjpe
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import Scene
from posenet.training.train import lr_factor, single_view_loss
from posenet.training.train import main as train_main
from posenet.viz.visualize import main as visualize_main

REPO = Path(__file__).resolve().parents[2]
TINY = ["--subsample", "1", "--crop-size", "32", "--base", "8", "--threads", "1"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    return root, write_dataset(root, {1: 4, 2: 3}, persons=2, seed=0)


@pytest.mark.parametrize("mode,aggregation", [("crop", "3d"), ("full", "3d"), ("crop", "2d")])
def test_one_training_step_lowers_the_loss(tiny, mode, aggregation):
    torch.manual_seed(0)
    root, ann = tiny
    sample = MvorDataset(root, ann, days=[1])[0]
    inputs = InputConfig(mode=mode, crop_size=32, image_size=(80, 60), train_crop=(64, 48))
    cfg = ModelConfig(inputs=inputs, base=8, depth=2, aggregation=aggregation, precision="fp32")
    model = PoseNet(cfg)
    persons = Scene.from_sample(sample)
    g = torch.Generator().manual_seed(0)
    scene = build_scene(persons.views, persons.boxes, persons.has_box, inputs, AugmentConfig(), g)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)

    def loss_now():
        return mpjpe(model(scene).joints, persons.poses, persons.valid)

    before = loss_now()
    opt.zero_grad()
    before.backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters() if p.grad is not None)
    opt.step()
    after = loss_now()
    assert after.item() < before.item()


def test_single_view_loss_is_the_fused_loss_where_one_view_boxes_the_person(tiny):
    """--view-loss: each view's own estimate; with one boxed view it is the fused estimate, and it trains."""
    torch.manual_seed(0)
    root, ann = tiny
    sample = MvorDataset(root, ann, days=[1])[0]
    inputs = InputConfig(mode="crop", crop_size=32, image_size=(80, 60), train_crop=(64, 48))
    cfg = ModelConfig(inputs=inputs, base=8, depth=2, precision="fp32")
    model = PoseNet(cfg)
    persons = Scene.from_sample(sample)
    g = torch.Generator().manual_seed(0)
    only_first = persons.has_box.clone()
    only_first[:, 1:] = False
    keep = only_first[:, 0]
    assert keep.any() and persons.has_box[:, 1:].any()
    one = build_scene(persons.views, persons.boxes, only_first, inputs, AugmentConfig(), g)
    out = model(one)
    sub = Scene.__new__(Scene)  # the annotations of the persons that view 0 boxes
    sub.poses, sub.valid = persons.poses, persons.valid & keep[:, None]
    fused = mpjpe(out.joints[keep], persons.poses[keep], persons.valid[keep])
    torch.testing.assert_close(single_view_loss(cfg, out, sub, one), fused, rtol=1e-5, atol=1e-3)
    # all views: a gradient everywhere it should be, and one step lowers it
    scene = build_scene(persons.views, persons.boxes, persons.has_box, inputs, AugmentConfig(), g)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    before = single_view_loss(cfg, model(scene), persons, scene)
    opt.zero_grad()
    before.backward()
    assert all(torch.isfinite(p.grad).all() for p in model.parameters() if p.grad is not None)
    opt.step()
    assert single_view_loss(cfg, model(scene), persons, scene).item() < before.item()


def test_lr_schedule():
    assert lr_factor(0, 100, 0.75) == 1.0 and lr_factor(74, 100, 0.75) == 1.0
    assert 0.4 < lr_factor(87, 100, 0.75) < 0.6 and lr_factor(100, 100, 0.75) == 0.0
    assert lr_factor(99, 100, 1.0) == 1.0
    # warm-up from 10 % over the first 10 %; the same curve over seconds of a budget as over steps
    assert lr_factor(0, 100, 0.75, 0.1) == pytest.approx(0.1) and lr_factor(
        5, 100, 0.75, 0.1
    ) == pytest.approx(0.55)
    assert lr_factor(30.0, 60.0, 0.75, 0.1) == 1.0 and lr_factor(75, 60.0, 0.75) == 0.0  # past the budget: 0


def _run(args, **kw):
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}
    r = subprocess.run(args, cwd=REPO, env=env, capture_output=True, text=True, timeout=120, **kw)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def test_cli_train_resume_predict(tiny, tmp_path):
    # in-process through the CLIs' main(argv), to keep the test fast; the subprocess path is tested with
    # torchrun
    root, ann = tiny
    run = tmp_path / "run"
    base = ["--data", str(root), "--holdout-day", "2", "--out", str(run)]
    watch = ["--watch", f"{root}:2"]  # the held-out day itself, watched: the same figure under its own key
    assert (
        train_main([*base, *TINY[:-2], "--epochs", "1", "--val-every", "1", "--view-loss", "0.5", *watch])
        == 0
    )
    for ckpt in ("last", "best"):
        assert (run / ckpt / "model.safetensors").is_file()
        saved = json.loads((run / ckpt / "config.json").read_text())
        assert saved["train"]["preset"] == "cpu" and saved["model"]["inputs"]["crop_size"] == 32
        assert saved["train"]["data_description"]["train_days"] == [1] and saved["train"]["view_loss"] == 0.5
        assert saved["trained_on"]["days"] == [1] and saved["trained_on"]["data"] == str(root)
    assert train_main([*base, "--resume", "--epochs", "2"]) == 0
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in log] == [1, 2] and all("val_mpjpe_cm" in r for r in log)
    assert all(r[f"watch_{root.name}_cm"] == r["val_mpjpe_cm"] for r in log)  # the watch survives --resume
    with pytest.raises(ValueError, match=r"--watch .*:9: day\(s\) \[9\] not among"):
        train_main([*base[:-1], str(tmp_path / "w"), *TINY[:-2], "--epochs", "1", "--watch", f"{root}:9"])
    pred = tmp_path / "pred.json"
    args = ["--data", str(root), "--annotations", str(ann), "--checkpoint", str(run / "best"), "--days", "2"]
    assert predict_main([*args, "--out", str(pred)]) == 0
    preds = json.loads(pred.read_text())
    assert len(preds) == 6 and all(len(p["keypoints3D"]) == 30 for p in preds)
    png = tmp_path / "scene.png"
    assert visualize_main(["--data", str(root), "--annotations", str(ann), "--checkpoint", str(run),
                           "--days", "2", "--frame", "1", "--out", str(png)]) == 0  # fmt: skip
    assert png.read_bytes()[:4] == b"\x89PNG"
    # a fresh run into an existing folder must not silently overwrite it
    with pytest.raises(FileExistsError, match="--resume"):
        train_main([*base, *TINY[:-2]])


def test_cli_time_budget_stops_and_resumes(tiny, tmp_path):
    root, _ = tiny
    run = tmp_path / "budget"
    base = ["--data", str(root), "--holdout-day", "2", "--out", str(run)]
    budget = ["--minutes", "0.02", "--warmup", "0.1", "--decay-start", "0.1", "--box-noise", "0.5",
              "--color-drop", "0.3"]  # fmt: skip
    assert train_main([*base, *TINY[:-2], *budget]) == 0
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    augment = json.loads((run / "config.json").read_text())["train"]["augment"]
    assert augment["box_noise"] == 0.5 and augment["color_drop"] == 0.3
    assert log[-1]["minutes"] >= 0.02 and "val_mpjpe_cm" in log[-1]  # spent, then validated
    # warm-up then decay from 10 % of the budget on: below the base LR however few steps a loaded machine makes
    assert all(r["steps"] > 0 for r in log) and log[-1]["lr"] < 1e-3
    # resuming with a larger budget continues the clock (and the step count) where it stopped
    # (the larger budget counts from what the first run spent: one step may outlast 0.02 min on a loaded machine)
    larger = round(log[-1]["minutes"] + 0.02, 3)
    assert train_main([*base, "--resume", "--minutes", str(larger)]) == 0
    more = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()][len(log) :]
    assert more and more[0]["steps"] > log[-1]["steps"] and more[-1]["minutes"] >= larger


def test_torchrun_ddp_gloo_two_processes(tiny, tmp_path):
    root, _ = tiny
    run = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2", "-m", "posenet.training.train",
           "--data", str(root), "--holdout-day", "2", "--out", str(run), *TINY,
           "--epochs", "1", "--device", "cpu"]  # fmt: skip
    _run(cmd)
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert len(log) == 1  # only rank 0 logs and saves
    # 4 training frames split over 2 processes: rank 0 saw 2 of them
    assert log[0]["scenes"] == 2
    assert (run / "last" / "model.safetensors").is_file()


def test_cli_init_starts_from_given_weights(tiny, tmp_path):
    from safetensors.torch import load_file

    from posenet.training.train import load_init_weights

    root, _ = tiny
    first, second = tmp_path / "first", tmp_path / "second"
    base = ["--data", str(root), "--holdout-day", "2", *TINY[:-2]]
    assert train_main([*base, "--out", str(first), "--epochs", "1", "--val-every", "1"]) == 0
    start = load_file(first / "last" / "model.safetensors")
    model = PoseNet(ModelConfig(inputs=InputConfig(crop_size=32), base=8))
    load_init_weights(model, str(first / "last"))
    assert all(torch.equal(model.state_dict()[k], v) for k, v in start.items())
    # a zero-length budget: the run saves the weights it started from, and records where they came from
    assert train_main([*base, "--out", str(second), "--init", str(first / "last"), "--minutes", "0"]) == 0
    saved = json.loads((second / "config.json").read_text())
    assert saved["train"]["init"] == str(first / "last") == saved["trained_on"]["init"]
    for other in ({"base": 4}, {"base": 16, "depth": 2}):  # narrower, or another depth: no way to fit
        with pytest.raises(ValueError, match="does not fit"):
            load_init_weights(
                PoseNet(ModelConfig(inputs=InputConfig(crop_size=32), **other)), str(first / "last")
            )
    # a wider --base: the checkpoint widened, computing the same logits in training and in evaluation mode
    wide = PoseNet(ModelConfig(inputs=InputConfig(crop_size=32), base=12))
    load_init_weights(wide, str(first / "last"))
    x = torch.randn(3, model.config.unet.in_channels, 32, 32, generator=torch.Generator().manual_seed(0))
    x = x.contiguous(memory_format=torch.channels_last)
    for training in (False, True):
        model.train(training), wide.train(training)
        torch.testing.assert_close(wide.unet(x), model.unet(x), rtol=0, atol=1e-5)
    # --modality depth from rgbd weights: the first convolution keeps the depth channels' weights, so on inputs
    # without colour (its channels 0) both compute the same logits; a modality the weights never read is refused
    rgbd = PoseNet(
        ModelConfig(inputs=InputConfig(crop_size=32), base=8)
    )  # (model's norms moved in training mode)
    depth = PoseNet(ModelConfig(inputs=InputConfig(crop_size=32, modality="depth"), base=8))
    load_init_weights(rgbd, str(first / "last"))
    load_init_weights(depth, str(first / "last"))
    keep = [rgbd.config.inputs.channels.index(c) for c in depth.config.inputs.channels]
    assert keep == [3, 4, 5, 6]
    x[:, :3] = 0
    rgbd.eval(), depth.eval()
    torch.testing.assert_close(depth.unet(x[:, keep]), rgbd.unet(x), rtol=0, atol=1e-5)
    from dataclasses import asdict

    from posenet.net.checkpoint import save_checkpoint

    saved_depth = save_checkpoint(tmp_path / "depth_ckpt", depth, {"model": asdict(depth.config)})
    with pytest.raises(ValueError, match="does not fit"):  # depth weights cannot start an rgbd run
        load_init_weights(rgbd, str(saved_depth))
