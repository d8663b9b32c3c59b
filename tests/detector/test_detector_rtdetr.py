"""RT-DETR (``--arch rt_detr``), padded inputs, and ``--init`` (continue from one of our checkpoints)."""

from __future__ import annotations

import os

import numpy as np
import pytest
import torch

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from test_detector_train import (  # noqa: E402, F401 (one_thread: the same autouse fixture here)
    W,
    few_steps,
    one_thread,
    tiny_cpu_cfg,
    write_dataset,
)

from detector import train as train_cli  # noqa: E402
from detector.checkpoint import load_checkpoint, read_config  # noqa: E402
from detector.data import DetectionDataset, load_records, read_record  # noqa: E402
from detector.infer import PersonDetector, decode  # noqa: E402
from detector.inputs import batch_inputs, box_frame, prepare_views  # noqa: E402
from detector.model import build_detector  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny_rt")
    return root, write_dataset(root)


def tiny_rt_cfg(**kw):
    return tiny_cpu_cfg(arch="rt_detr", backbone_stage=4, encoder_layers=1, **kw)


def test_padding_to_a_multiple_and_the_box_frame():
    pixels, mask = batch_inputs([torch.ones(3, 84, 112), torch.ones(3, 60, 80)], multiple=32)
    assert pixels.shape == (2, 3, 96, 128) and mask.shape == (2, 96, 128)
    assert mask[0].sum() == 84 * 112 and mask[1].sum() == 60 * 80
    assert pixels[0, :, 84:].abs().sum() == 0 and pixels[0, :, :, 112:].abs().sum() == 0
    assert box_frame(112, 84, tiny_rt_cfg()) == (128, 96)  # RT-DETR: the padded grid
    assert box_frame(112, 84, tiny_cpu_cfg()) == (112, 84)  # DETR: the view itself
    with pytest.raises(ValueError, match="three backbone stages"):
        tiny_cpu_cfg(arch="rt_detr", backbone_stage=2)


@pytest.mark.parametrize("arch", ["detr", "rt_detr"])
def test_training_targets_decode_back_to_the_annotated_boxes(dataset, arch):
    """The normalised training targets, read as predictions, decode to the annotation's pixel boxes: training
    and inference agree on the box frame, also when RT-DETR pads a 112x84 input to 128x96."""
    root, ann = dataset
    cfg = (tiny_rt_cfg if arch == "rt_detr" else tiny_cpu_cfg)(input_width=112)
    rec = next(r for r in load_records(ann, [1]) if len(r.boxes) == 2)
    _, labels, _ = DetectionDataset([rec], root, cfg)[0]
    color, depth = read_record(rec, root, True, False)
    pixels, _, factors, sizes = prepare_views([color], [depth], cfg)
    assert pixels.shape[2:] == ((96, 128) if arch == "rt_detr" else (84, 112))
    logits = torch.full((1, 2, 1), 10.0)
    dets = decode(logits, labels["boxes"][None], sizes, factors, [(W, 96)], 0.5)
    np.testing.assert_allclose(dets[0].boxes, np.asarray(rec.boxes, np.float32), atol=1e-3)


def test_rt_detr_few_steps_lower_the_loss(dataset):
    cfg = tiny_rt_cfg()
    assert type(build_detector(cfg)).__name__ == "RTDetrForObjectDetection"
    assert not any(type(m).__name__.endswith("FrozenBatchNorm2d") for m in build_detector(cfg).modules())
    losses = few_steps(dataset, cfg, lr=1e-3, steps=15)
    assert losses[-1] < 0.8 * losses[0], losses


def test_rt_detr_cli_trains_saves_reloads_and_init_continues(dataset, tmp_path):
    root, ann = dataset
    run = tmp_path / "rt"
    common = ["--data", str(root), "--annotations", ann, "--holdout-day", "2", "--epochs", "1", "--batch-size", "2",
              "--no-progress"]  # fmt: skip
    arch = [
        "--arch",
        "rt_detr",
        "--backbone-stage",
        "4",
        "--input",
        "rgbd",
        "--input-width",
        "112",
        "--queries",
        "6",
    ]
    log = train_cli.main([*common, *arch, "--out", str(run)])
    assert np.isfinite(log[-1]["loss"]) and "AP50" in log[-1]
    model, cfg, meta = load_checkpoint(run)
    assert cfg.arch == "rt_detr" and meta["detr"]["model_type"] == "rt_detr"
    records = load_records(ann, [2])
    views = [read_record(r, root, True, True) for r in records]
    images, depths = [c for c, _ in views], [d for _, d in views]
    # fp32 whatever the machine: the comparisons below are exact (bf16 would round a short fine-tune away)
    a = PersonDetector(model, cfg, precision="fp32").detect(images, depths, score_threshold=0.0)
    b = PersonDetector.from_checkpoint(run, precision="fp32").detect(images, depths, score_threshold=0.0)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x.boxes, y.boxes)
        assert len(x.scores) == 6 and (x.scores >= 0).all() and (x.scores <= 1).all()
        assert (x.boxes[:, 2] <= W).all() and (x.boxes[:, 3] <= 96).all()  # clipped to the full view

    # --init: the architecture and weights of `run`, a fresh optimiser, and the origin recorded.
    cont = tmp_path / "cont"
    train_cli.main([*common, "--init", str(run), "--lr", "1e-5", "--out", str(cont)])
    saved = read_config(cont)
    assert saved["model"]["arch"] == "rt_detr" and saved["progress"]["step"] == log[-1]["step"]
    assert saved["trained_on"]["init"] == str(run)
    c = PersonDetector.from_checkpoint(cont, precision="fp32").detect(images, depths, score_threshold=0.0)
    assert any(not np.array_equal(x.boxes, y.boxes) for x, y in zip(a, c, strict=True))  # it trained on
    with pytest.raises(ValueError, match="--init takes the architecture"):
        train_cli.main([*common, "--init", str(run), "--arch", "detr", "--out", str(tmp_path / "bad")])


def test_init_from_a_half_precision_export(dataset, tmp_path):
    """The shipped weights are float16 files: ``--init`` from one trains in float32."""
    root, ann = dataset
    cfg = tiny_cpu_cfg()
    from detector.checkpoint import save_checkpoint

    torch.manual_seed(0)
    save_checkpoint(tmp_path / "w.safetensors", build_detector(cfg), cfg, precision="float16")
    log = train_cli.main(
        ["--data", str(root), "--annotations", ann, "--holdout-day", "2", "--epochs", "1", "--batch-size", "2",
         "--no-progress", "--init", str(tmp_path / "w.safetensors"), "--out", str(tmp_path / "run")]
    )  # fmt: skip
    assert np.isfinite(log[-1]["loss"])
    model, _, _ = load_checkpoint(tmp_path / "run")
    assert all(p.dtype == torch.float32 for p in model.parameters())


def test_int8_weights_round_trip_within_half_a_step():
    from detector.checkpoint import INT8_SCALE, dequantize, quantize_int8

    g = torch.Generator().manual_seed(0)
    state = {
        "conv.weight": torch.randn(32, 16, 3, 3, generator=g) * torch.linspace(0.01, 2, 32).view(-1, 1, 1, 1),
        "linear.weight": torch.randn(128, 64, generator=g),
        "linear.bias": torch.randn(128, generator=g),
        "bn.num_batches_tracked": torch.tensor(7),
    }
    q = quantize_int8(state)
    assert q["conv.weight"].dtype == torch.int8 and q["conv.weight" + INT8_SCALE].shape == (32,)
    assert q["linear.bias"].dtype == torch.float16 and q["bn.num_batches_tracked"].dtype == torch.int64
    back = dequantize(q)
    assert set(back) == set(state)
    for k in ("conv.weight", "linear.weight"):
        w = state[k]
        step = w.abs().amax(dim=tuple(range(1, w.ndim)), keepdim=True) / 127
        assert (
            (back[k] - w).abs() <= step / 2 + 1e-7
        ).all()  # per output channel: small channels stay precise
    assert back["bn.num_batches_tracked"] == 7


def test_int8_export_keeps_the_outputs(dataset, tmp_path):
    """Per query, the int8 file's boxes and scores stay close to the float32 run's (DETR: fixed queries, so the
    outputs compare one to one; an untrained RT-DETR's query selection is a near-tie that any rounding reorders)."""
    from detector import export as export_cli
    from detector.inputs import prepare_views

    root, ann = dataset
    run = tmp_path / "run"
    train_cli.main(
        ["--data", str(root), "--annotations", ann, "--holdout-day", "2", "--epochs", "1", "--batch-size", "2",
         "--no-progress", "--arch", "detr", "--backbone-stage", "3", "--input", "rgbd", "--queries", "6",
         "--input-width", str(W), "--out", str(run)]
    )  # fmt: skip
    out = tmp_path / "w8.safetensors"
    export_cli.main([str(run), "--out", str(out), "--precision", "int8", "--threshold", "0.3"])
    assert out.stat().st_size < 0.3 * (run / "model.safetensors").stat().st_size
    assert read_config(out)["model"]["score_threshold"] == 0.3
    records = load_records(ann, [2])
    views = [read_record(r, root, True, True) for r in records]
    full, small = PersonDetector.from_checkpoint(run), PersonDetector.from_checkpoint(out)
    pixels, mask, _, _ = prepare_views([c for c, _ in views], [d for _, d in views], full.cfg)
    with torch.inference_mode():
        a = full.model(pixel_values=pixels, pixel_mask=mask)
        b = small.model(pixel_values=pixels, pixel_mask=mask)
    torch.testing.assert_close(b.pred_boxes, a.pred_boxes, atol=2.0 / W, rtol=0)  # within 2 px
    torch.testing.assert_close(b.logits.softmax(-1), a.logits.softmax(-1), atol=0.03, rtol=0)


def test_dense_loss_is_refused_for_rt_detr(dataset, tmp_path):
    root, ann = dataset
    with pytest.raises(ValueError, match="drop --dense-weight"):
        train_cli.main(
            ["--data", str(root), "--annotations", ann, "--holdout-day", "2", "--epochs", "1", "--no-progress",
             "--input-width", str(W), "--queries", "6", "--dense-weight", "1", "--out", str(tmp_path / "run")]
        )  # fmt: skip


def test_nms_in_decode_and_on_coco_results():
    from detector.export import nms_results

    # Two queries on one person (IoU 0.9) and one on another; scores 0.9, 0.8, 0.7. Boxes are normalised
    # (cx, cy, w, h) of a 100x100 view, shown at full size (factor 1).
    boxes = torch.tensor([[[0.30, 0.5, 0.2, 0.6], [0.31, 0.5, 0.2, 0.6], [0.7, 0.5, 0.2, 0.6]]])
    logits = torch.logit(torch.tensor([[[0.9], [0.8], [0.7]]]))
    args = (logits, boxes, [(100, 100)], [1.0], [(100, 100)], 0.5)
    plain, suppressed = decode(*args)[0], decode(*args, nms_iou=0.7)[0]
    np.testing.assert_allclose(plain.scores, [0.9, 0.8, 0.7], atol=1e-6)
    np.testing.assert_allclose(suppressed.scores, [0.9, 0.7], atol=1e-6)
    np.testing.assert_array_equal(suppressed.boxes, plain.boxes[[0, 2]])
    assert len(decode(*args, nms_iou=0.95)[0].scores) == 3  # IoU 0.9 < 0.95: both kept

    results = [
        {"image_id": 1, "bbox": [20, 20, 20, 60], "score": 0.9},
        {"image_id": 1, "bbox": [21, 20, 20, 60], "score": 0.8},
        {"image_id": 2, "bbox": [21, 20, 20, 60], "score": 0.8},  # another image: never suppressed by image 1
    ]
    assert nms_results(results, None) == results
    assert [r["score"] for r in nms_results(results, 0.7)] == [0.9, 0.8]
    assert sorted(r["image_id"] for r in nms_results(results, 0.7)) == [1, 2]
