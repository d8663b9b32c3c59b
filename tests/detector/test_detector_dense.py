"""The training-only dense loss on DETR's encoder tokens (detector/dense.py)."""

from __future__ import annotations

import json
import os
from dataclasses import replace

import pytest
import torch

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from test_detector_train import W, tiny_cpu_cfg, write_dataset  # noqa: E402

from detector import train as train_cli  # noqa: E402
from detector.data import DetectionDataset, collate, load_records  # noqa: E402
from detector.dense import DenseLoss, dense_targets, token_centres  # noqa: E402
from detector.model import build_detector, preset  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny_dense")
    return root, write_dataset(root)


def test_token_centres_of_a_padded_batch():
    # Two images padded to 64x32 (W x H); the second is 32x32 of real pixels. A 2x4 grid: stride 16 px.
    mask = torch.zeros(2, 32, 64)
    mask[0] = 1
    mask[1, :, :32] = 1
    centres, strides = token_centres(mask, (2, 4))
    assert centres.shape == (2, 8, 2)
    # Token (row 1, col 2) centre is pixel (40, 24): normalised by each image's own size.
    torch.testing.assert_close(centres[0, 6], torch.tensor([40 / 64, 24 / 32]))
    torch.testing.assert_close(centres[1, 6], torch.tensor([40 / 32, 24 / 32]))
    torch.testing.assert_close(strides[1], torch.tensor([0.5, 0.5]))


def test_targets_centre_sampling_and_tiny_boxes():
    mask = torch.ones(1, 80, 160)
    grid = (5, 10)  # stride 16 px
    centres, strides = token_centres(mask, grid)
    big = torch.tensor([[0.5, 0.5, 0.8, 0.9]])  # a large box in the middle
    tiny = torch.tensor([[0.13, 0.31, 0.01, 0.01]])  # smaller than a token, off every token centre
    target, boxes = dense_targets([{"boxes": torch.cat([big, tiny])}], centres, strides)
    pos = target[0] > 0
    # The big box's centre is pixel (80, 40); token centres lie at 8, 24, 40, ... px. Within 1.5 strides
    # (24 px, inclusive): columns at 56, 72, 88, 104 and rows at 24, 40, 56 -> 4 x 3 tokens.
    big_tokens = (boxes[0] == big).all(-1)
    assert int(big_tokens.sum()) == 12
    # The tiny box still gets its nearest token, and nothing else.
    tiny_tokens = (boxes[0] == tiny).all(-1)
    assert int(tiny_tokens.sum()) == 1
    assert int(pos.sum()) == 13
    # No boxes: no positives.
    target, _ = dense_targets([{"boxes": torch.zeros(0, 4)}], centres, strides)
    assert target.sum() == 0


def model_dense_batch(dataset, views: int):
    """A tiny seeded DETR with a dense loss attached, and a batch of ``views`` training views."""
    root, ann = dataset
    cfg = tiny_cpu_cfg()
    torch.manual_seed(0)
    model = build_detector(cfg)
    dense = DenseLoss(cfg.d_model)
    dense.attach(model)
    batch = collate([DetectionDataset(load_records(ann, [1]), root, cfg)[i] for i in range(views)])
    return model, dense, batch


def test_dense_loss_has_gradients_into_the_detector(dataset):
    model, dense, batch = model_dense_batch(dataset, 2)
    out = model(pixel_values=batch["pixel_values"], pixel_mask=batch["pixel_mask"], labels=batch["labels"])
    parts = dense(out.encoder_last_hidden_state, batch["pixel_mask"], batch["labels"])
    assert torch.isfinite(parts["loss_dense"])
    parts["loss_dense"].backward()
    backbone_grad = sum(p.grad.abs().sum() for p in model.model.backbone.parameters() if p.grad is not None)
    assert backbone_grad > 0  # the dense signal reaches the backbone through the encoder


def test_dense_loss_alone_learns_objectness(dataset):
    model, dense, batch = model_dense_batch(dataset, 4)
    opt = torch.optim.AdamW([*model.parameters(), *dense.parameters()], lr=2e-3)
    losses = []
    for _ in range(20):
        out = model(pixel_values=batch["pixel_values"], pixel_mask=batch["pixel_mask"])
        loss = dense(out.encoder_last_hidden_state, batch["pixel_mask"], batch["labels"])["loss_dense"]
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.7 * losses[0], losses


def test_cli_dense_weight_and_extra_data_resume(dataset, tmp_path):
    root, ann = dataset
    extra = tmp_path / "extra"
    extra.mkdir()
    write_dataset(extra, days=(7,), per_day=2, seed=1)
    run = tmp_path / "run"
    argv = [
        "--data", str(root), "--annotations", ann, "--holdout-day", "2", "--extra-data", str(extra),
        "--input-width", str(W), "--queries", "6", "--epochs", "1", "--batch-size", "2",
        "--arch", "conditional_detr", "--backbone-stage", "3", "--dense-weight", "1", "--cache", "--no-progress", "--out", str(run),
    ]  # fmt: skip
    log = train_cli.main(argv)
    assert log[-1]["loss_dense"] > 0 and "dense_focal" in log[-1]
    saved = json.loads((run / "config.json").read_text())
    assert saved["train"]["dense_weight"] == 1.0
    trained_on = saved["trained_on"]
    assert trained_on["days"] == [1] and trained_on["extra_data"] == [str(extra)]
    assert trained_on["views"] == 4 + 2
    state = torch.load(run / "train_state.pt", weights_only=False)
    assert state["dense"] is not None  # the dense head resumes too
    log2 = train_cli.main([*argv[:-2], "--epochs", "2", "--out", str(run), "--resume"])
    assert [e["epoch"] for e in log2] == [1, 2] and log2[-1]["loss_dense"] > 0
    # The shipped model is a plain DETR: no dense head in the saved weights.
    from safetensors.torch import load_file

    assert not any("dense" in k or "objectness" in k for k in load_file(run / "model.safetensors"))
    assert preset("cpu").input_mode == "rgbd" and preset("cpu").arch == "rt_detr"


def test_conditional_detr_trains_saves_and_reloads(dataset, tmp_path):
    """``--arch conditional_detr``: a sigmoid class head, trainable norms, and a checkpoint that reloads to the
    same detections."""
    import cv2
    import numpy as np

    from detector.checkpoint import load_checkpoint
    from detector.infer import PersonDetector

    root, ann = dataset
    run = tmp_path / "run"
    argv = [
        "--data", str(root), "--annotations", ann, "--holdout-day", "2", "--arch", "conditional_detr", "--input", "rgb",
        "--backbone-stage", "3",
        "--input-width", str(W), "--queries", "6", "--epochs", "1", "--batch-size", "2", "--no-progress",
        "--out", str(run),
    ]  # fmt: skip
    log = train_cli.main(argv)
    assert np.isfinite(log[-1]["loss"]) and "AP50" in log[-1]
    model, cfg, meta = load_checkpoint(run)
    assert cfg.arch == "conditional_detr" and meta["detr"]["model_type"] == "conditional_detr"
    assert type(model).__name__ == "ConditionalDetrForObjectDetection"
    assert not any(type(m).__name__.endswith("FrozenBatchNorm2d") for m in model.modules())
    records = load_records(ann, [2])
    images = [cv2.cvtColor(cv2.imread(str(root / r.file_name)), cv2.COLOR_BGR2RGB) for r in records]
    a = PersonDetector(model, cfg).detect(images, score_threshold=0.0)
    b = PersonDetector.from_checkpoint(run).detect(images, score_threshold=0.0)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.boxes, y.boxes)
        assert (x.scores >= 0).all() and (x.scores <= 1).all() and len(x.scores) == 6  # sigmoid scores


def test_export_sets_the_threshold_and_halves_the_file(dataset, tmp_path):
    import numpy as np

    from detector import export as export_cli
    from detector.checkpoint import read_config
    from detector.infer import PersonDetector

    root, ann = dataset
    run = tmp_path / "run"
    train_cli.main(
        [
            "--data", str(root), "--annotations", ann, "--holdout-day", "2", "--input-width", str(W),
            "--queries", "6", "--epochs", "1", "--batch-size", "2", "--no-progress", "--out", str(run),
            "--arch", "conditional_detr", "--backbone-stage", "3",
        ]
    )  # fmt: skip
    out = tmp_path / "ship" / "default.safetensors"
    export_cli.main(
        [
            str(run), "--out", str(out), "--data", str(root), "--annotations", ann, "--threshold-days", "1",
            "--half", "--trained-on", "tiny ellipses",
        ]
    )  # fmt: skip
    meta = read_config(out)
    chosen = meta["model"]["extra"]["threshold_chosen_on"]
    assert chosen["days"] == [1] and meta["trained_on"] == "tiny ellipses"
    assert meta["model"]["score_threshold"] == chosen["F1_50_threshold"]
    assert out.stat().st_size < 0.6 * (run / "model.safetensors").stat().st_size  # float16
    # The suppression IoU was chosen on the same days, among none and the default choices.
    assert set(chosen["nms_candidates"]) == {"none", "0.8", "0.7", "0.6", "0.5"}
    assert meta["model"]["nms_iou"] == chosen["nms_iou"]
    full, half = PersonDetector.from_checkpoint(run), PersonDetector.from_checkpoint(out)
    full.cfg = replace(full.cfg, nms_iou=half.cfg.nms_iou)
    assert half.cfg.score_threshold == chosen["F1_50_threshold"]
    records = load_records(ann, [2])
    import cv2

    images = [cv2.cvtColor(cv2.imread(str(root / r.file_name)), cv2.COLOR_BGR2RGB) for r in records]
    depths = [
        cv2.imread(str(root / r.file_name.replace("color", "depth")), cv2.IMREAD_UNCHANGED) for r in records
    ]
    pairs = zip(
        full.detect(images, depths, score_threshold=0.0),
        half.detect(images, depths, score_threshold=0.0),
        strict=True,
    )
    for a, b in pairs:
        np.testing.assert_allclose(a.boxes, b.boxes, atol=0.5)  # pixels; float16 weights
