"""COCO box AP of person detections, with pycocotools (not a hand-written AP).

    python -m detector.evaluate --annotations A.json --predictions BOXES.json [--days 4] [--out METRICS.json]

``BOXES.json`` is a COCO results list (``detector.predict`` writes one): ``{"image_id", "category_id": 1,
"bbox": [x, y, w, h], "score"}``. Ground truth is every person box of the evaluated images (the images of
``--days``, else every image that has a prediction entry or belongs to the predicted days).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
from pathlib import Path

import numpy as np
from pycocotools.coco import COCO
from pycocotools.cocoeval import COCOeval

from detector.data import ImageRecord, load_records
from posenet.boxes import xyxy_to_coco


def coco_ground_truth(records: list[ImageRecord]) -> dict:
    """A clean COCO ground-truth dict (one "person" category, id 1) of ``records``' boxes."""
    images, anns = [], []
    for rec in records:
        images.append(
            {"id": rec.image_id, "width": rec.width, "height": rec.height, "file_name": rec.file_name}
        )
        for box in xyxy_to_coco(np.asarray(rec.boxes, np.float64).reshape(-1, 4)):
            anns.append(
                {
                    "id": len(anns) + 1,
                    "image_id": rec.image_id,
                    "category_id": 1,
                    "bbox": [float(x) for x in box],
                    "area": float(box[2] * box[3]),
                    "iscrowd": 0,
                }
            )
    return {"images": images, "annotations": anns, "categories": [{"id": 1, "name": "person"}]}


def coco_ap(records: list[ImageRecord], results: list[dict]) -> dict:
    """COCO AP, AP50 and AP75 (IoU 0.5:0.95, 0.5, 0.75; all areas; 100 detections) of ``results`` on
    ``records``."""
    if not records:
        raise ValueError("coco_ap needs at least one ground-truth image")
    ids = {r.image_id for r in records}
    results = [dict(r, category_id=1) for r in results if int(r["image_id"]) in ids]
    metrics = {
        "images": len(records),
        "boxes": int(sum(len(r.boxes) for r in records)),
        "detections": len(results),
    }
    if not results:
        # pycocotools cannot load an empty result list; nothing detected is AP 0.
        return {"AP": 0.0, "AP50": 0.0, "AP75": 0.0, "F1_50": 0.0, "F1_50_threshold": 1.0, **metrics}
    with contextlib.redirect_stdout(io.StringIO()):  # pycocotools prints its progress
        gt = COCO()
        gt.dataset = coco_ground_truth(records)
        gt.createIndex()
        dt = gt.loadRes(results)
        ev = COCOeval(gt, dt, iouType="bbox")
        ev.evaluate()
        ev.accumulate()
        ev.summarize()
    f1, threshold, precision, recall = best_f1(ev)
    return {
        "AP": float(ev.stats[0]),
        "AP50": float(ev.stats[1]),
        "AP75": float(ev.stats[2]),
        "F1_50": f1,
        "F1_50_threshold": threshold,
        "F1_50_precision": precision,
        "F1_50_recall": recall,
        **metrics,
    }


def best_f1(ev: COCOeval) -> tuple[float, float, float, float]:
    """The best F1 at IoU 0.5 on COCOeval's recall grid, and the score threshold, precision and recall there.

    Read from ``ev.eval`` (IoU 0.5, all areas, 100 detections): at each recall level COCO stores the
    interpolated precision and the score of the detection that reaches it. The threshold is what a service
    should keep boxes above; choose it on training data, not on the held-out day.
    """
    precision = ev.eval["precision"][0, :, 0, 0, -1]  # (R,) over ev.params.recThrs
    scores = ev.eval["scores"][0, :, 0, 0, -1]
    recall = ev.params.recThrs
    valid = precision > 0
    if not valid.any():
        return 0.0, 1.0, 0.0, 0.0
    f1 = np.where(valid, 2 * precision * recall / np.maximum(precision + recall, 1e-12), 0.0)
    i = int(np.argmax(f1))
    return float(f1[i]), float(scores[i]), float(precision[i]), float(recall[i])


def evaluate_file(annotations: str | Path | dict, predictions: str | Path | list, days=None) -> dict:
    """AP metrics of a results file (or list) against an annotation file, on ``days`` (else predicted
    images)."""
    if not isinstance(predictions, list):
        path = Path(predictions)
        if not path.is_file():
            raise FileNotFoundError(f"predictions file {path} does not exist")
        predictions = json.loads(path.read_text())
        if not isinstance(predictions, list):
            raise ValueError(f"predictions file {path} is not a COCO results list")
    records = load_records(annotations, days)
    if days is None:
        predicted = {int(p["image_id"]) for p in predictions}
        records = [r for r in records if r.image_id in predicted]
    return coco_ap(records, predictions)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        prog="python -m detector.evaluate",
        description="COCO AP / AP50 / AP75 of person boxes (pycocotools) against MVOR-format annotations.",
    )
    parser.add_argument(
        "--annotations", required=True, help="MVOR-format annotation json (ground-truth boxes)"
    )
    parser.add_argument(
        "--predictions", required=True, help="COCO results json, as written by detector.predict"
    )
    parser.add_argument(
        "--days",
        type=int,
        nargs="+",
        help="evaluate every image of these days (default: the predicted images)",
    )
    parser.add_argument("--out", help="also write the metrics to this json file")
    args = parser.parse_args(argv)
    metrics = evaluate_file(args.annotations, args.predictions, args.days)
    print(json.dumps(metrics, indent=2))
    if args.out:
        Path(args.out).write_text(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    main()
