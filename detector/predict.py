"""Detect persons in every view of an MVOR-format dataset and write COCO results.

    python -m detector.predict --data DIR --annotations A.json [--checkpoint CKPT] [--days 4] --out BOXES.json

Output: a COCO results list, ``{"image_id", "category_id": 1, "bbox": [x, y, w, h], "score"}`` in full-image
pixels (``posenet.boxes``), which ``detector.evaluate`` scores. Every query
above ``--score-threshold`` is kept (a low threshold is what COCO AP expects).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from detector.data import ImageRecord, load_records, read_record
from detector.infer import PersonDetector
from posenet.boxes import xyxy_to_coco
from posenet.cli import add_annotations, add_data, add_days, add_threads, annotations_path, set_threads


def predict_records(
    detector: PersonDetector,
    records: list[ImageRecord],
    root: str | Path | None,
    score_threshold: float = 0.01,
    batch_size: int = 6,
    progress: bool = True,
) -> list[dict]:
    """COCO results of ``detector`` on ``records`` (read from ``root`` unless held in memory)."""
    results = []
    use_color = detector.cfg.input_mode in ("rgb", "rgbd")
    for start in tqdm(range(0, len(records), batch_size), desc="detect", unit="batch", disable=not progress):
        batch = records[start : start + batch_size]
        views = [read_record(r, root, use_color, detector.needs_depth) for r in batch]
        dets = detector.detect(
            [c for c, _ in views], [d for _, d in views] if detector.needs_depth else None, score_threshold
        )
        for rec, det in zip(batch, dets, strict=True):
            for box, score in zip(xyxy_to_coco(det.boxes.astype(np.float64)), det.scores, strict=True):
                results.append(
                    {
                        "image_id": rec.image_id,
                        "category_id": 1,
                        "bbox": [round(float(x), 2) for x in box],
                        "score": round(float(score), 5),
                    }
                )
    return results


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(
        prog="python -m detector.predict",
        description="Run a trained person detector on every view of an MVOR-format dataset; "
        "write COCO results.",
    )
    add_data(parser)
    add_annotations(parser, help="MVOR-format annotation json listing the images (default: DATA/annotations.json)")
    parser.add_argument(
        "--checkpoint",
        help="run folder or .safetensors of detector.train (default: detector/weights/default)",
    )
    add_days(parser)
    parser.add_argument("--out", required=True, help="COCO results json to write")
    parser.add_argument("--score-threshold", type=float, default=0.01, help="lowest person probability kept")
    parser.add_argument("--batch-size", type=int, default=6, help="views per forward pass")
    nms = parser.add_mutually_exclusive_group()
    nms.add_argument(
        "--nms-iou",
        type=float,
        help="non-maximum suppression at this IoU (default: the checkpoint's setting)",
    )
    nms.add_argument(
        "--no-nms", action="store_true", help="no non-maximum suppression, whatever the checkpoint says"
    )
    parser.add_argument("--device", default="cpu")
    add_threads(parser)
    args = parser.parse_args(argv)

    set_threads(args.threads)
    args.annotations = annotations_path(args)
    detector = PersonDetector.from_checkpoint(args.checkpoint, args.device)
    if args.no_nms or args.nms_iou is not None:
        detector.cfg = replace(detector.cfg, nms_iou=None if args.no_nms else args.nms_iou)
    records = load_records(args.annotations, args.days)
    results = predict_records(detector, records, args.data, args.score_threshold, args.batch_size)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results))
    print(f"wrote {len(results)} boxes of {len(records)} images to {out}")
    return results


if __name__ == "__main__":
    main()
