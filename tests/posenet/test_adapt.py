"""posenet.training.adapt: unsupervised adaptation never reads the target's 3D poses, its losses, the EMA teacher, resume,
and that its checkpoint loads where every other pose checkpoint does. Tiny rendered scenes (tests/tiny_scenes.py),
a tiny U-Net, one thread: seconds."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_scenes import write_dataset

from posenet.data.mvor import MvorDataset, load_annotations
from posenet.net import lifting
from posenet.net.augment import AugmentConfig
from posenet.net.checkpoint import save_checkpoint
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig, build_scene
from posenet.net.loss import mpjpe
from posenet.net.model import ModelConfig, PoseNet, PoseOutput
from posenet.scene import Scene
from posenet.skeleton import BONES
from posenet.training.adapt import AdaptConfig, adapt_step, load_target_annotations
from posenet.training.adapt import main as adapt_main
from posenet.training.adapt_losses import (
    bone_lengths,
    bone_loss,
    bone_statistics,
    ema_update,
    per_view_estimates,
    pseudo_labels,
    view_consistency,
)

TINY_MODEL = ModelConfig(inputs=InputConfig(crop_size=32), base=8, depth=2, precision="fp32")
RUN = ["--subsample", "1", "--threads", "1", "--scenes-per-step", "2", "--source-per-step", "1"]


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A target (2 days, 2 persons, with 3D poses in its file), the same file without them, a labelled source,
    and a tiny initial checkpoint."""
    root = tmp_path_factory.mktemp("adapt")
    target = root / "target"
    ann = write_dataset(target, {1: 3, 2: 2}, persons=2, seed=1)
    gt = json.loads(ann.read_text())
    assert gt["annotations3D"]
    no3d = root / "no3d.json"
    no3d.write_text(json.dumps({k: v for k, v in gt.items() if k != "annotations3D"}))
    source = root / "source"
    write_dataset(source, {1: 3}, persons=1, seed=2)
    torch.manual_seed(0)
    init = save_checkpoint(
        root / "init",
        PoseNet(TINY_MODEL),
        {"model": dataclasses.asdict(TINY_MODEL), "augment": dataclasses.asdict(AugmentConfig())},
    )
    return {"target": target, "with3d": ann, "no3d": no3d, "source": source, "init": init}


def _args(tiny, out, annotations="no3d", *extra):
    return ["--data", str(tiny["target"]), "--annotations", str(tiny[annotations]), "--init", str(tiny["init"]),
            "--source-data", str(tiny["source"]), "--out", str(out), *RUN, *extra]  # fmt: skip


def _weights(run: Path) -> bytes:
    return (run / "last" / "model.safetensors").read_bytes()


# ----------------------------------------------------------------------------- never the target's 3D poses
def test_the_reader_drops_annotations3d_when_told(tiny):
    gt = load_annotations(tiny["with3d"], poses=False)
    assert "annotations3D" not in gt
    ds = MvorDataset(tiny["target"], gt, modalities=(), poses=False)
    assert all(ds[i].poses.shape[0] == 0 for i in range(len(ds)))
    with pytest.raises(ValueError, match="holds annotations3D"):
        MvorDataset(None, load_annotations(tiny["with3d"]), modalities=(), poses=False)
    with pytest.raises(ValueError, match="annotations3D"):  # the default still requires them
        load_annotations(tiny["no3d"])


def test_a_file_without_3d_poses_adapts_and_gives_the_same_weights(tiny, tmp_path):
    assert adapt_main(_args(tiny, tmp_path / "no3d", "no3d", "--epochs", "1")) == 0
    assert adapt_main(_args(tiny, tmp_path / "with3d", "with3d", "--epochs", "1")) == 0
    assert _weights(tmp_path / "no3d") == _weights(tmp_path / "with3d")  # bit-identical
    log = [json.loads(line) for line in (tmp_path / "no3d" / "log.jsonl").read_text().splitlines()]
    assert log[0]["steps"] == 3 and all(
        np.isfinite(log[0][k]) for k in ("consistency", "pseudo", "bones", "source")
    )
    saved = json.loads((tmp_path / "no3d" / "config.json").read_text())
    assert saved["model"]["base"] == 8 and len(saved["train"]["bone_stats"]["mean"]) == len(BONES)
    assert _weights(tmp_path / "no3d") != (tiny["init"] / "model.safetensors").read_bytes()  # it did learn


def test_the_default_read_size_needs_no_3d_poses(tiny, tmp_path):
    """Without --subsample the read size comes from the file's cameras alone; it used to need annotations3D."""
    from posenet.evaluation.predict import read_subsample

    args = _args(tiny, tmp_path / "run", "no3d", "--epochs", "1")
    del args[args.index("--subsample") : args.index("--subsample") + 2]
    assert adapt_main(args) == 0
    saved = json.loads((tmp_path / "run" / "config.json").read_text())
    expected = read_subsample(load_annotations(tiny["with3d"]), TINY_MODEL.inputs)
    assert (
        saved["train"]["subsample"]
        == expected
        == read_subsample(load_annotations(tiny["no3d"], poses=False), TINY_MODEL.inputs)
    )


# ----------------------------------------------------------------------------- the losses
def test_per_view_estimates_mix_into_the_fused_one():
    """The fused joint is the views' own estimates weighted by each view's share of the softmax mass."""
    g = torch.Generator().manual_seed(0)
    P, V, J, M = 2, 3, 10, 50
    logits = torch.randn(P, V, J, M, generator=g, dtype=torch.float64)
    points = torch.randn(1, V, M, 3, generator=g, dtype=torch.float64) * 300 + 3000
    valid = torch.rand(P, V, M, generator=g) > 0.3
    fused = lifting.aggregate(logits, points, valid)
    views = per_view_estimates(logits, points, valid)
    mass = torch.where(valid.unsqueeze(2), logits.exp(), 0).sum(-1)  # (P, V, J)
    share = mass / mass.sum(1, keepdim=True)
    torch.testing.assert_close((share.unsqueeze(-1) * views.joints).sum(1), fused.joints)
    # one view alone is its own fused estimate
    one = lifting.aggregate(logits[:, :1], points[:, :1], valid[:, :1])
    torch.testing.assert_close(views.joints[:, 0], one.joints)


def test_view_consistency_is_zero_when_views_agree_and_its_gradient_is_finite():
    g = torch.Generator().manual_seed(1)
    fused = torch.randn(3, 10, 3, generator=g) * 500
    agree = fused.unsqueeze(1).expand(3, 4, 10, 3).clone().requires_grad_()
    ok = torch.tensor([[1, 1, 0, 0], [1, 0, 0, 0], [1, 1, 1, 1]], dtype=torch.bool)
    d = view_consistency(agree, ok, fused)
    assert d.numel() == (2 + 4) * 10 and d.sum().item() == 0.0  # person 1 (one view) does not count
    d.mean().backward()
    assert torch.isfinite(agree.grad).all()
    # views that disagree: positive, finite gradient into the views only (the fused target is detached)
    fused = fused.clone().requires_grad_()
    views = (agree.detach() + torch.randn(3, 4, 10, 3, generator=g) * 30).requires_grad_()
    loss = view_consistency(views, ok, fused).mean()
    loss.backward()
    assert loss.item() > 0 and torch.isfinite(views.grad).all() and fused.grad is None
    view_consistency(views, ok, fused, stop_gradient=False).mean().backward()
    assert torch.isfinite(fused.grad).all() and fused.grad.abs().sum() > 0


def test_gradcheck_through_per_view_estimates_and_consistency():
    g = torch.Generator().manual_seed(2)
    logits = torch.randn(1, 2, 10, 12, generator=g, dtype=torch.float64, requires_grad=True)
    points = torch.randn(1, 2, 12, 3, generator=g, dtype=torch.float64) * 100
    valid = torch.ones(1, 2, 12, dtype=torch.bool)

    def loss(x):
        views = per_view_estimates(x, points, valid)
        return view_consistency(
            views.joints, views.has_points, lifting.aggregate(x, points, valid).joints
        ).sum()

    assert torch.autograd.gradcheck(loss, (logits,))


def _output(joints, spread):
    P, J, _ = joints.shape
    return PoseOutput(
        joints, torch.full((P, J), float(spread)), torch.ones(P, dtype=torch.bool), torch.zeros(0)
    )


def test_pseudo_labels_keep_certain_joints_and_their_loss_is_zero_at_the_target():
    g = torch.Generator().manual_seed(3)
    joints = torch.randn(2, 10, 3, generator=g) * 400
    mirrored = joints.clone()
    mirrored[0, 8] += torch.tensor([300.0, 0, 0])  # a flip test that disagrees on one wrist
    labels = pseudo_labels(_output(joints, 40.0), _output(mirrored, 40.0), max_uncertainty=120.0)
    assert labels.keep.sum() == 19 and not labels.keep[0, 8]
    assert torch.allclose(labels.uncertainty[0, 8], torch.tensor(40.0 + 150.0))
    assert pseudo_labels(_output(joints, 200.0), _output(joints, 200.0), 120.0).keep.sum() == 0
    student = labels.joints.clone().requires_grad_()
    loss = mpjpe(student, labels.joints, labels.keep)
    loss.backward()
    assert loss.item() == 0.0 and torch.isfinite(student.grad).all()
    moved = (labels.joints + 10).requires_grad_()
    loss = mpjpe(moved, labels.joints, labels.keep)
    loss.backward()
    assert loss.item() == pytest.approx(10 * 3**0.5, rel=1e-5) and torch.isfinite(moved.grad).all()


def test_bone_statistics_and_loss():
    rng = np.random.default_rng(0)
    poses = torch.from_numpy(rng.normal(0, 300, (40, 10, 3))).float()
    valid = torch.ones(40, 10, dtype=torch.bool)
    valid[0, 0] = False  # the head-neck bone of pose 0 is left out
    mean, std = bone_statistics(poses, valid)
    ref = np.array([[np.linalg.norm(p[a] - p[b]) for a, b in BONES] for p in poses.numpy()])  # (N, B) loop
    ok = np.ones_like(ref, bool)
    ok[0, 0] = False
    ref_mean = np.array([ref[ok[:, k], k].mean() for k in range(len(BONES))])
    ref_std = np.array([ref[ok[:, k], k].std(ddof=1) for k in range(len(BONES))])
    np.testing.assert_allclose(mean.numpy(), ref_mean, rtol=1e-5)
    np.testing.assert_allclose(std.numpy(), ref_std, rtol=1e-5)
    # a skeleton whose bones are exactly the source means costs nothing; stretched beyond a std it costs the excess
    joints = poses[:2].clone().requires_grad_()
    lengths = bone_lengths(joints).detach()
    zero = bone_loss(joints, torch.ones(2, dtype=torch.bool), lengths[0], torch.zeros(len(BONES)))
    assert zero[0].abs().max().item() < 1e-3 and zero[1].abs().max().item() > 1  # pose 1 is another skeleton
    excess = bone_loss(joints, torch.tensor([True, False]), lengths[0] - 50, torch.full((len(BONES),), 20.0))
    assert excess.shape == (1, len(BONES)) and torch.allclose(
        excess, torch.full_like(excess, 30.0), atol=1e-3
    )
    excess.mean().backward()
    assert torch.isfinite(joints.grad).all() and joints.grad[1].abs().sum() == 0


def test_ema_update_is_the_moving_average_of_every_weight_and_buffer(tiny):
    torch.manual_seed(0)
    teacher, student = PoseNet(TINY_MODEL), PoseNet(TINY_MODEL)
    p = Scene.from_sample(MvorDataset(tiny["source"], tiny["source"] / "annotations.json")[0])
    student.train()(
        build_scene(p.views, p.boxes, p.has_box, TINY_MODEL.inputs)
    )  # moves BatchNorm's statistics
    before = {k: v.clone() for k, v in teacher.state_dict().items()}
    ema_update(teacher, student, 0.9)
    for name, t in teacher.state_dict().items():
        s = student.state_dict()[name]
        if t.is_floating_point():
            torch.testing.assert_close(t, 0.9 * before[name] + 0.1 * s, rtol=1e-6, atol=1e-7)
        else:
            assert torch.equal(t, s)  # num_batches_tracked
    assert any(not torch.equal(before[k], v) for k, v in teacher.state_dict().items())
    ema_update(teacher, student, 0.0)
    assert all(torch.equal(t, student.state_dict()[k]) for k, t in teacher.state_dict().items())


def test_one_step_has_every_loss_and_finite_gradients(tiny):
    torch.manual_seed(0)
    student = PoseNet(TINY_MODEL).train()
    teacher = PoseNet(TINY_MODEL).eval()
    teacher.load_state_dict(student.state_dict())
    cfg = AdaptConfig(
        str(tiny["target"]), "unused", annotations=str(tiny["no3d"]), model=TINY_MODEL, augment=AugmentConfig(),
        bone_stats={"mean": [150.0] * len(BONES), "std": [20.0] * len(BONES)}, pseudo_max_uncertainty=1e9,
    )  # fmt: skip
    gt = load_target_annotations(cfg)
    targets = [Scene.from_sample(s, "boxed") for s in MvorDataset(tiny["target"], gt, poses=False, days=[1])]
    sources = [Scene.from_sample(MvorDataset(tiny["source"], tiny["source"] / "annotations.json")[0])]
    assert all(p.poses.abs().sum() == 0 for p in targets)  # nothing to supervise with
    losses = adapt_step(student, teacher, targets, sources, cfg, torch.Generator().manual_seed(0))
    assert set(losses.parts) == {"consistency", "pseudo", "bones", "source"}
    assert all(np.isfinite(v) and v > 0 for v in losses.parts.values()) and losses.pseudo_share == 1.0
    losses.total.backward()
    grads = [p.grad for p in student.parameters() if p.grad is not None]
    assert grads and all(torch.isfinite(g).all() for g in grads)
    assert all(p.grad is None for p in teacher.parameters())  # the teacher gets no gradient
    # each loss alone also reaches the weights with a finite gradient
    for name in ("consistency", "pseudo", "bones", "source"):
        student.zero_grad()
        alone = dataclasses.replace(
            cfg, **{k: float(k == name) for k in ("consistency", "pseudo", "bones", "source")}
        )
        one = adapt_step(student, teacher, targets, sources, alone, torch.Generator().manual_seed(0))
        assert set(one.parts) == {name}
        one.total.backward()
        norm = sum(float(p.grad.abs().sum()) for p in student.parameters() if p.grad is not None)
        assert np.isfinite(norm) and norm > 0, name


# ----------------------------------------------------------------------------- the run
def test_resume_continues_where_an_uninterrupted_run_would_be(tiny, tmp_path):
    constant = ["--decay-start", "1.0", "--warmup", "0"]  # the LR does not depend on the planned length
    assert adapt_main(_args(tiny, tmp_path / "straight", "no3d", "--epochs", "2", *constant)) == 0
    assert adapt_main(_args(tiny, tmp_path / "split", "no3d", "--epochs", "1", *constant)) == 0
    with pytest.raises(FileExistsError, match="--resume"):
        adapt_main(_args(tiny, tmp_path / "split", "no3d", "--epochs", "2"))
    assert (
        adapt_main(
            ["--data", str(tiny["target"]), "--out", str(tmp_path / "split"), "--resume", "--epochs", "2"]
        )
        == 0
    )
    log = [json.loads(line) for line in (tmp_path / "split" / "log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in log] == [1, 2] and log[1]["steps"] == 6
    assert _weights(tmp_path / "split") == _weights(tmp_path / "straight")


def test_time_budget_stops_the_run(tiny, tmp_path):
    run = tmp_path / "budget"
    assert adapt_main(_args(tiny, run, "no3d", "--minutes", "0.01")) == 0  # 0.6 s, epochs not limited
    state = torch.load(run / "last" / "train_state.pt", weights_only=False)
    log = [json.loads(line) for line in (run / "log.jsonl").read_text().splitlines()]
    assert state["elapsed_s"] >= 0.6 and log[-1]["steps"] == state["step"] > 0
    # resuming with a larger budget continues the clock and the steps
    assert (
        adapt_main(["--data", str(tiny["target"]), "--out", str(run), "--resume", "--minutes", "0.02"]) == 0
    )
    later = torch.load(run / "last" / "train_state.pt", weights_only=False)
    assert later["elapsed_s"] >= 1.2 and later["step"] > state["step"]


def test_the_result_loads_like_any_pose_checkpoint(tiny, tmp_path, monkeypatch):
    run = tmp_path / "run"
    assert adapt_main(_args(tiny, run, "no3d", "--epochs", "1", "--consistency", "0", "--bones", "0")) == 0
    sample = MvorDataset(tiny["target"], tiny["no3d"], poses=False)[0]
    scene = Scene.from_person_boxes(sample.views, [sample.person_boxes(0)])
    pred = PoseEstimator.from_checkpoint(run, precision="fp32").predict(scene)
    assert pred.joints.shape == (1, 10, 3) and torch.isfinite(pred.joints).all()
    # the service: ORPOSE_POSE_CHECKPOINT=RUN
    from pipeline.two_stage import ScenePipeline
    from service.settings import Settings

    monkeypatch.setenv("ORPOSE_POSE_CHECKPOINT", str(run))
    pipeline = ScenePipeline.from_checkpoints(
        Settings().pose_checkpoint, load_detector=False, precision="fp32"
    )
    served = pipeline.pose.predict(scene)
    torch.testing.assert_close(served.joints, pred.joints)
    # posenet.evaluation.predict
    from posenet.evaluation.predict import main as predict_main

    out = tmp_path / "pred.json"
    assert predict_main(["--data", str(tiny["target"]), "--annotations", str(tiny["with3d"]), "--checkpoint", str(run),
                         "--days", "2", "--out", str(out)]) == 0  # fmt: skip
    assert len(json.loads(out.read_text())) == 4


def test_detector_boxes_replace_the_files_boxes(tiny, tmp_path):
    gt = load_annotations(tiny["no3d"], poses=False)
    boxes = [
        dict(b, person_id=b["person_id"] + 7) for b in gt["annotations"]
    ]  # other ids, as a matcher gives
    path = tmp_path / "boxes.json"
    path.write_text(json.dumps(boxes))
    cfg = AdaptConfig(str(tiny["target"]), "unused", annotations=str(tiny["no3d"]), boxes="detector")
    with pytest.raises(FileNotFoundError, match="pipeline.group"):
        load_target_annotations(cfg)
    cfg.detector_boxes = str(path)
    assert {b["person_id"] for b in load_target_annotations(cfg)["annotations"]} == {7, 8}
    path.write_text(json.dumps([{"image_id": 1, "bbox": [0, 0, 1, 1]}]))
    with pytest.raises(ValueError, match="person_id"):
        load_target_annotations(cfg)


def test_reader_subsampling_defaults_to_what_the_network_reads(mvor_annotations):
    """Without --subsample, posenet.training.adapt reads views as posenet.evaluation.predict and the service do: at the network's
    recorded read size (MVOR's 640x480 views at 320x240: every 2nd pixel), not at a default of its own."""
    from posenet.evaluation.predict import read_subsample

    assert read_subsample(mvor_annotations, InputConfig(source_size=(320, 240))) == 2
    assert read_subsample(mvor_annotations, InputConfig(source_size=(160, 120))) == 4
    assert read_subsample(mvor_annotations, InputConfig(source_size=None)) == 1  # views as given
    assert AdaptConfig(data="d", out="o").subsample is None
