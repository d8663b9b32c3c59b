"""pipeline.group: detections grouped across views into persons, the boxes of `posenet.training.adapt --boxes detector`."""

import dataclasses
import json

import torch
from tiny_scenes import write_dataset

from pipeline.group import main as group_main
from posenet.net.augment import AugmentConfig
from posenet.net.checkpoint import save_checkpoint
from posenet.net.inputs import InputConfig
from posenet.net.model import ModelConfig, PoseNet
from posenet.training.adapt import main as adapt_main


def test_grouped_detections_feed_adaptation(tmp_path):
    root = tmp_path / "target"
    ann = write_dataset(root, {1: 2}, persons=1, seed=3)
    gt = json.loads(ann.read_text())
    # detector.predict's format: the reference boxes as confident detections, and one weak stray box per image
    images = [im["id"] for mv in gt["multiview_images"] for im in mv["images"]]
    dets = [
        {"image_id": a["image_id"], "category_id": 1, "bbox": a["bbox"], "score": 0.9}
        for a in gt["annotations"]
    ]
    dets += [{"image_id": i, "category_id": 1, "bbox": [1.0, 1.0, 5.0, 5.0], "score": 0.2} for i in images]
    (tmp_path / "dets.json").write_text(json.dumps(dets))
    boxes = tmp_path / "boxes.json"
    entries = group_main(["--data", str(root), "--annotations", str(ann), "--predictions", str(tmp_path / "dets.json"),
                          "--score-threshold", "0.5", "--out", str(boxes)])  # fmt: skip
    assert len(entries) == len(gt["annotations"]) and all(e["score"] == 0.9 for e in entries)
    frame_of = {im["id"]: mv["id"] for mv in gt["multiview_images"] for im in mv["images"]}
    ids = {(frame_of[e["image_id"]], e["person_id"]) for e in entries}
    assert len(ids) == 2 and {pid for _, pid in ids} == {
        0
    }  # one person per frame, seen by every view in one group
    assert json.loads(boxes.read_text()) == entries

    model = ModelConfig(inputs=InputConfig(crop_size=32), base=8, depth=2, precision="fp32")
    torch.manual_seed(0)
    init = save_checkpoint(
        tmp_path / "init",
        PoseNet(model),
        {"model": dataclasses.asdict(model), "augment": dataclasses.asdict(AugmentConfig())},
    )
    run = tmp_path / "run"
    assert adapt_main(["--data", str(root), "--annotations", str(ann), "--boxes", "detector", "--detector-boxes",
                       str(boxes), "--init", str(init), "--out", str(run), "--source", "0", "--bones", "0",
                       "--subsample", "1", "--threads", "1", "--epochs", "1"]) == 0  # fmt: skip
    config = json.loads((run / "config.json").read_text())
    assert (
        config["train"]["data_description"]["boxes"].startswith("detector")
        and (run / "last" / "model.safetensors").is_file()
    )
