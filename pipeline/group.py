"""Group the detector's boxes into persons across views: the boxes that ``posenet.training.adapt --boxes detector`` reads.

    python -m pipeline.group --data DIR --annotations A.json [--days 1 2 3] [--checkpoint CKPT] --out BOXES.json
    python -m pipeline.group --data DIR --annotations A.json --predictions DETS.json --out BOXES.json

Runs the person detector on every view (or reads ``detector.predict``'s COCO results with ``--predictions``),
keeps the boxes whose score reaches ``--score-threshold`` (default: the detector checkpoint's, the one the
service applies), and groups each frame's boxes across views with the 3D box-centre matcher
(``pipeline.matching``, 75 cm), as the service's detector mode does. Output: one entry per kept box,
``{"image_id", "bbox": [x, y, w, h], "person_id", "score"}`` in the file's pixels: MVOR's ``annotations``
entries, with the matcher's group as the person id (unique within a frame, not across frames).

``posenet`` never imports ``detector``, so ``posenet.training.adapt`` reads this file instead of running the detector:
``python -m posenet.training.adapt --data DIR --annotations A.json --boxes detector --detector-boxes BOXES.json ...``.
The annotation file's 3D poses are never read (``poses=False``).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pipeline.matching import match_boxes
from posenet.cli import add_data, add_days, add_threads
from posenet.data.mvor import MvorDataset, load_annotations


def group_detections(samples, predictions: list[dict], score_threshold: float, threshold_mm: float = 750.0):
    """Entries ``{"image_id", "bbox", "person_id", "score"}`` of the detections of ``samples`` (``Sample``s with
    depth, at the pixels of ``predictions``) that reach ``score_threshold``, grouped across views per frame."""
    by_image: dict[int, list[dict]] = defaultdict(list)
    for p in predictions:
        if p.get("score", 1.0) >= score_threshold:
            by_image[int(p["image_id"])].append(p)
    out = []
    for sample in tqdm(samples, desc="group", unit="frame"):
        kept = [by_image.get(int(v.image_id), []) for v in sample.views]
        coco = [np.asarray([d["bbox"] for d in k], np.float64).reshape(-1, 4) for k in kept]  # (K_v, 4) xywh
        xyxy = [np.concatenate([b[:, :2], b[:, :2] + b[:, 2:]], axis=1) for b in coco]
        groups = match_boxes(xyxy, [v.depth for v in sample.views], sample.cameras, threshold_mm)
        for person, group in enumerate(groups):
            for v, k in enumerate(group.indices):
                if k >= 0:
                    d = kept[v][k]
                    out.append(
                        {
                            "image_id": d["image_id"],
                            "bbox": d["bbox"],
                            "person_id": person,
                            "score": d.get("score", 1.0),
                        }
                    )
    return out


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(
        prog="python -m pipeline.group",
        description="Detect persons in every view and group the boxes across views into persons (3D box-centre "
        "matcher); write them with person ids for `posenet.training.adapt --boxes detector`.",
    )
    add_data(p)
    p.add_argument(
        "--annotations", required=True, help="MVOR-format json: frames and cameras (no 3D poses read)"
    )
    add_days(p)
    p.add_argument("--checkpoint", help="detector checkpoint (default: detector/weights/default)")
    p.add_argument("--predictions", help="detector.predict's COCO results instead of running the detector")
    p.add_argument("--score-threshold", type=float, help="lowest score kept (default: the checkpoint's)")
    p.add_argument("--threshold-mm", type=float, default=750.0, help="the matcher's largest centre distance")
    p.add_argument("--device", default="cpu")
    add_threads(p)
    p.add_argument("--out", required=True, help="json list of {image_id, bbox, person_id, score}")
    args = p.parse_args(argv)

    gt = load_annotations(args.annotations, poses=False)
    threshold = args.score_threshold
    if args.predictions:
        predictions = json.loads(Path(args.predictions).read_text())
        if threshold is None:
            from detector.checkpoint import model_config, read_config
            from detector.infer import DEFAULT_WEIGHTS

            threshold = model_config(read_config(args.checkpoint or DEFAULT_WEIGHTS))["score_threshold"]
    else:
        from detector.data import load_records
        from detector.infer import PersonDetector
        from detector.predict import predict_records

        if args.threads:
            import torch

            torch.set_num_threads(args.threads)
        detector = PersonDetector.from_checkpoint(args.checkpoint, args.device)
        threshold = detector.score_threshold if threshold is None else threshold
        predictions = predict_records(detector, load_records(gt, args.days), args.data, threshold)
    samples = MvorDataset(args.data, gt, modalities=("depth",), days=args.days, poses=False)
    entries = group_detections(samples, predictions, threshold, args.threshold_mm)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(entries))
    print(f"wrote {len(entries)} boxes of {len(samples)} frames (score >= {threshold:g}), grouped, to {out}")
    return entries


if __name__ == "__main__":
    main()
