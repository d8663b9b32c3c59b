"""Training, checkpoints, prediction and evaluation of the detector on a tiny rendered dataset (seconds,
CPU)."""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest
import torch

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from detector import predict as predict_cli  # noqa: E402
from detector import train as train_cli  # noqa: E402
from detector.data import DetectionDataset, collate, load_records  # noqa: E402
from detector.evaluate import coco_ap, evaluate_file  # noqa: E402
from detector.infer import PersonDetector  # noqa: E402
from detector.model import build_detector, preset, with_input_mode  # noqa: E402
from posenet.boxes import xyxy_to_coco  # noqa: E402

W, H = 128, 96


def write_dataset(root, days=(1, 2), per_day=4, seed=0) -> str:
    """A tiny MVOR-layout dataset: upright ellipses ("people") on a noisy background, with depth and boxes."""
    rng = np.random.default_rng(seed)
    images, anns = [], []
    for day in days:
        for i in range(per_day):
            color = rng.integers(60, 120, (H, W, 3), dtype=np.uint8)
            depth = np.full((H, W), 4000, np.uint16)
            for _ in range(rng.integers(1, 3)):
                cx, cy = rng.uniform(20, W - 20), rng.uniform(25, H - 25)
                ax, ay = rng.uniform(8, 14), rng.uniform(18, 24)
                cv2.ellipse(color, (int(cx), int(cy)), (int(ax), int(ay)), 0, 0, 360, (230, 40, 40), -1)
                cv2.ellipse(depth, (int(cx), int(cy)), (int(ax), int(ay)), 0, 0, 360, 2000, -1)
                x0, y0 = int(cx) - int(ax) - 0.5, int(cy) - int(ay) - 0.5  # pixel-centre convention
                anns.append(
                    {
                        "id": len(anns),
                        "image_id": day * 1000 + i,
                        "category_id": "1",
                        "person_id": -1,
                        "bbox": [x0, y0, 2 * int(ax) + 1, 2 * int(ay) + 1],
                    }
                )
            name = f"day{day}/cam1/color/{i:06d}.png"
            for sub, img in (("color", cv2.cvtColor(color, cv2.COLOR_RGB2BGR)), ("depth", depth)):
                path = root / name.replace("color", sub)
                path.parent.mkdir(parents=True, exist_ok=True)
                cv2.imwrite(str(path), img)
            images.append({"id": day * 1000 + i, "file_name": name, "width": W, "height": H, "day_id": day})
    ann_path = root / "annotations.json"
    ann_path.write_text(json.dumps({"images": images, "annotations": anns}))
    return str(ann_path)


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """Tiny models: thread overheads on a shared 2-core machine cost more than they give."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("tiny")
    return root, write_dataset(root)


def tiny_cpu_cfg(**kw):
    # The cpu preset, narrowed further so that tests take seconds; DETR on colour unless a test says otherwise.
    kw = {
        "arch": "detr",
        "input_mode": "rgb",
        "backbone_stage": 3,
        "input_width": W,
        "d_model": 64,
        "ffn_dim": 128,
        "num_queries": 6,
        **kw,
    }
    return preset("cpu", **kw)


def few_steps(dataset, cfg, lr: float, steps: int) -> list[float]:
    """The training losses of ``steps`` AdamW steps of a fresh ``cfg`` model on 4 views of day 1."""
    root, ann = dataset
    torch.manual_seed(0)
    model = build_detector(cfg)
    items = [DetectionDataset(load_records(ann, [1]), root, cfg)[i] for i in range(4)]
    batch = collate(items, cfg.pad_multiple)
    opt = torch.optim.AdamW(model.parameters(), lr=lr)
    losses = []
    for _ in range(steps):
        model.train()
        out = model(
            pixel_values=batch["pixel_values"], pixel_mask=batch["pixel_mask"], labels=batch["labels"]
        )
        opt.zero_grad()
        out.loss.backward()
        opt.step()
        losses.append(out.loss.item())
    assert np.isfinite(losses).all()
    return losses


def test_few_steps_lower_the_loss(dataset):
    losses = few_steps(dataset, tiny_cpu_cfg(), lr=2e-3, steps=20)
    assert losses[-1] < 0.8 * losses[0], losses


def test_cli_checkpoint_gives_identical_predictions(dataset, tmp_path):
    root, ann = dataset
    run = tmp_path / "run"
    argv = [
        "--data",
        str(root),
        "--annotations",
        ann,
        "--holdout-day",
        "2",
        "--preset",
        "cpu",
        "--input-width",
        str(W),
        "--queries",
        "6",
        "--epochs",
        "1",
        "--batch-size",
        "2",
        "--no-progress",
        "--out",
        str(run),
    ]
    log = train_cli.main(argv)
    assert {"AP", "AP50", "AP75", "loss"} <= set(log[-1])
    saved = json.loads((run / "config.json").read_text())
    assert saved["model"]["num_queries"] == 6 and saved["train"]["epochs"] == 1
    assert (run / "model.safetensors").is_file() and (run / "train_state.pt").is_file()

    # Resume: a second epoch continues from the saved state.
    log2 = train_cli.main([*argv[:-2], "--epochs", "2", "--out", str(run), "--resume"])
    assert [e["epoch"] for e in log2] == [1, 2]

    detector = PersonDetector.from_checkpoint(run)
    records = load_records(ann, [2])
    a = predict_cli.predict_records(detector, records, root, progress=False)
    out = tmp_path / "boxes.json"
    b = predict_cli.main(
        [
            "--data",
            str(root),
            "--annotations",
            ann,
            "--checkpoint",
            str(run),
            "--days",
            "2",
            "--out",
            str(out),
        ]
    )
    assert a == b == json.loads(out.read_text())
    # Batched detection equals one view at a time.
    assert detector.cfg.input_mode == "rgbd"  # the cpu preset reads colour + depth
    views = [cv2.cvtColor(cv2.imread(str(root / r.file_name)), cv2.COLOR_BGR2RGB) for r in records]
    depths = [
        cv2.imread(str(root / r.file_name.replace("color", "depth")), cv2.IMREAD_UNCHANGED) for r in records
    ]
    together = detector.detect(views, depths, score_threshold=0.0)
    for view, depth, det in zip(views, depths, together, strict=True):
        alone = detector.detect([view], [depth], score_threshold=0.0)[0]
        np.testing.assert_allclose(alone.boxes, det.boxes, atol=1e-4)
        np.testing.assert_allclose(alone.scores, det.scores, atol=1e-5)

    # --init at another input width: the same network (resolution-free), fine-tuned on views resized to it.
    wider = tmp_path / "wider"
    common = [*argv[:6], "--epochs", "1", "--batch-size", "2", "--no-progress", "--init", str(run)]
    train_cli.main([*common, "--input-width", str(W + 32), "--out", str(wider)])
    assert json.loads((wider / "config.json").read_text())["model"]["input_width"] == W + 32
    assert PersonDetector.from_checkpoint(wider).cfg.input_width == W + 32
    with pytest.raises(ValueError, match="--init takes the architecture"):
        train_cli.main([*common, "--queries", "8", "--out", str(tmp_path / "refused")])

    # --init with --input depth: the colour + depth detector fine-tuned to read depth alone, then run without colour.
    depth_run = tmp_path / "depth"
    train_cli.main([*common, "--input", "depth", "--out", str(depth_run)])
    depth_only = PersonDetector.from_checkpoint(depth_run)
    assert depth_only.cfg.input_mode == "depth" and not depth_only.needs_color
    assert depth_only.detect([None] * len(depths), depths, score_threshold=0.0)[0].boxes.shape[1] == 4


def test_input_mode_conversion_keeps_the_shared_channels():
    """rgbd -> depth keeps every weight but the first convolution's colour part: on inputs whose colour channels
    are 0 the two models agree exactly; conversions that would invent weights are refused."""
    cfg = tiny_cpu_cfg(input_mode="rgbd")
    torch.manual_seed(0)
    model = build_detector(cfg).eval()
    for mode, keep in (("depth", [3]), ("rgb", [0, 1, 2])):
        converted, new_cfg = with_input_mode(model, cfg, mode)
        assert new_cfg.input_mode == mode and not converted.training
        x = torch.randn(2, 4, 64, 96)
        x[:, [c for c in range(4) if c not in keep]] = 0
        with torch.no_grad():
            a, b = model(pixel_values=x), converted(pixel_values=x[:, keep])
        torch.testing.assert_close(a.logits, b.logits, rtol=0, atol=1e-5)
        torch.testing.assert_close(a.pred_boxes, b.pred_boxes, rtol=0, atol=1e-5)
    assert with_input_mode(model, cfg, "rgbd")[0] is model
    depth_model, depth_cfg = with_input_mode(model, cfg, "depth")
    with pytest.raises(ValueError, match="cannot be turned into"):
        with_input_mode(depth_model, depth_cfg, "rgbd")


def test_pretrained_folder_gets_a_person_head(tmp_path):
    """A DETR saved with save_pretrained, with 5 labels, loads with a 1-class head and keeps its other
    weights."""
    from transformers import DetrForObjectDetection

    from detector.model import detr_config

    src_cfg = detr_config(tiny_cpu_cfg())
    src_cfg.num_labels = 5
    src_cfg.id2label = {i: f"c{i}" for i in range(5)}
    src_cfg.label2id = {v: k for k, v in src_cfg.id2label.items()}
    torch.manual_seed(1)
    src = DetrForObjectDetection(src_cfg)
    src.save_pretrained(tmp_path / "detr")
    cfg = tiny_cpu_cfg(pretrained=str(tmp_path / "detr"), trainable_norm=False, freeze_stem=True)
    model = build_detector(cfg)
    assert model.class_labels_classifier.out_features == 2  # person + no-object
    assert model.config.id2label == {0: "person"}
    torch.testing.assert_close(model.bbox_predictor.layers[0].weight, src.bbox_predictor.layers[0].weight)
    frozen = {n for n, p in model.model.backbone.model.named_parameters() if not p.requires_grad}
    assert frozen and all(not n.startswith(("layer2", "layer3", "layer4")) for n in frozen)
    assert any(n.startswith("layer1") for n in frozen) and "conv1.weight" in frozen


def test_paper_preset_architecture():
    """The paper's DETR-R101-DC5 builds offline: dilated last stage (stride 16), 100 queries, 6 + 6 layers."""
    cfg = preset("paper")
    model = build_detector(cfg)
    n = sum(p.numel() for p in model.parameters())
    assert 55e6 < n < 65e6
    assert model.config.num_queries == 100 and model.config.encoder_layers == 6
    with torch.inference_mode():
        feats = model.model.backbone(torch.zeros(1, 3, 64, 64), torch.ones(1, 64, 64, dtype=torch.long))
    assert feats[-1][0].shape[-2:] == (4, 4)  # DC5: stride 16, not 32


def test_coco_ap_perfect_and_shifted(dataset):
    _, ann = dataset
    records = load_records(ann)
    perfect = [
        {"image_id": r.image_id, "category_id": 1, "bbox": [float(x) for x in xyxy_to_coco(b)], "score": 1.0}
        for r in records
        for b in r.boxes
    ]
    assert coco_ap(records, perfect)["AP"] == pytest.approx(1.0)
    # Shifting every box by half its width gives IoU 1/3: not a hit at 0.5.
    shifted = [dict(p, bbox=[p["bbox"][0] + p["bbox"][2] / 2, *p["bbox"][1:]]) for p in perfect]
    assert coco_ap(records, shifted)["AP50"] == pytest.approx(0.0)
    assert evaluate_file(ann, perfect, days=[1])["AP75"] == pytest.approx(1.0)
    assert coco_ap(records, [])["AP"] == 0.0
    # F1 at IoU 0.5 and its threshold: true boxes score 0.9, one false box per image scores 0.4 -> the best
    # threshold keeps the true boxes only (F1 1), and it lies above the false boxes' score.
    false = [dict(p, bbox=[0.0, 0.0, 5.0, 5.0], score=0.4) for p in perfect[: len(records)]]
    m = coco_ap(records, [dict(p, score=0.9) for p in perfect] + false)
    assert m["F1_50"] == pytest.approx(1.0) and m["F1_50_threshold"] > 0.4
    assert m["F1_50_precision"] == pytest.approx(1.0) and m["F1_50_recall"] == pytest.approx(1.0)


def test_depth_inputs_and_errors(dataset):
    """A colour+depth detector reads 4 channels; a depth-only one needs depth; bad inputs raise clearly."""
    root, ann = dataset
    records = load_records(ann, [1])
    for mode, channels in (("rgbd", 4), ("depth", 1)):
        cfg = tiny_cpu_cfg(input_mode=mode)
        torch.manual_seed(0)
        detector = PersonDetector(build_detector(cfg), cfg)
        x, labels, _ = DetectionDataset(records, root, cfg)[0]
        assert x.shape == (channels, H, W) and labels["boxes"].shape[1] == 4
        color = cv2.cvtColor(cv2.imread(str(root / records[0].file_name)), cv2.COLOR_BGR2RGB)
        depth = cv2.imread(str(root / records[0].file_name.replace("color", "depth")), cv2.IMREAD_UNCHANGED)
        det = detector.detect([color], [depth], score_threshold=0.0)[0]
        assert det.boxes.shape == (cfg.num_queries, 4) and (np.diff(det.scores) <= 0).all()
        assert (det.boxes[:, [0, 1]] >= -0.5).all() and (det.boxes[:, 2] <= W - 0.5).all()
        with pytest.raises(ValueError, match="depth"):
            detector.detect([color])
    with pytest.raises(ValueError, match="input_mode"):
        preset("cpu", input_mode="thermal")
    with pytest.raises(ValueError, match="preset"):
        preset("huge")


def test_missing_checkpoint_says_how_to_get_one(tmp_path):
    with pytest.raises(FileNotFoundError, match="not exist"):
        PersonDetector.from_checkpoint(tmp_path / "nothing")
    from detector.infer import DEFAULT_WEIGHTS

    if DEFAULT_WEIGHTS.is_file():
        assert PersonDetector.from_checkpoint().cfg.num_queries > 0
    else:
        with pytest.raises(FileNotFoundError, match="detector.train"):
            PersonDetector.from_checkpoint()
