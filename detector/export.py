"""Export a trained detector as a single-file checkpoint (``NAME.safetensors`` + ``NAME.json``), e.g. the
shipped default weights.

    python -m detector.export RUN --out detector/weights/default.safetensors \
        --data data/mvor_twin --annotations data/mvor_twin/annotations.json --threshold-days 1 2 3 \
        --trained-on "what the weights saw"

With ``--threshold-days``, the score threshold that the service applies (``DetectorConfig.score_threshold``)
is set to the F1-best threshold at IoU 0.5 on those days' views (``detector.evaluate``): choose training
days, never the held-out one. Before it, the same views choose the non-maximum suppression IoU
(``DetectorConfig.nms_iou``) among none and ``--nms-choices`` by AP50 (``--nms-iou`` / ``--no-nms`` fix it
instead). ``--precision float16`` (``--half``) stores the weights as float16 (half the
size), ``--precision int8`` as weight-only int8 with per-output-channel scales (a quarter; check the AP of the
exported file with ``detector.predict`` + ``detector.evaluate``); both are cast back to float32 on loading.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from torchvision.ops import nms

from detector.checkpoint import PRECISIONS, load_checkpoint, save_checkpoint
from detector.checkpoint import trained_on as saved_trained_on
from detector.data import load_records
from detector.evaluate import coco_ap
from detector.infer import PersonDetector
from detector.predict import predict_records
from posenet.boxes import coco_to_xyxy
from posenet.cli import add_annotations, add_data, add_threads, annotations_path, set_threads


def nms_results(results: list[dict], iou: float | None) -> list[dict]:
    """COCO results after per-image non-maximum suppression at ``iou`` (None: unchanged)."""
    if iou is None:
        return results
    by_image: dict[int, list[dict]] = {}
    for r in results:
        by_image.setdefault(int(r["image_id"]), []).append(r)
    out = []
    for rows in by_image.values():
        boxes = torch.as_tensor(
            coco_to_xyxy(np.array([r["bbox"] for r in rows], np.float64)), dtype=torch.float32
        )
        keep = nms(boxes, torch.tensor([float(r["score"]) for r in rows]), iou)
        out += [rows[i] for i in keep.tolist()]
    return out


def choose_threshold(
    detector: PersonDetector,
    data: str,
    annotations: str,
    days: list[int],
    max_views: int,
    seed: int = 0,
    nms_choices: list[float] | None = None,
) -> dict:
    """COCO metrics, with the F1-best score threshold, of ``detector`` on (a seeded sample of) ``days``.

    The detector's own non-maximum suppression (``cfg.nms_iou``) applies; with ``nms_choices``, the IoU is chosen first, among no suppression and those IoUs, by
    AP50 on the same views (a choice needs 0.002 more AP50 than no suppression, or than a looser IoU, to win);
    ``nms_iou`` and every candidate's AP50 (``nms_candidates``) are in the result.
    """
    records = load_records(annotations, days)
    if max_views and len(records) > max_views:
        pick = np.random.default_rng(seed).choice(len(records), max_views, replace=False)
        records = [records[i] for i in sorted(pick)]
    raw = predict_records(
        PersonDetector(detector.model, replace(detector.cfg, nms_iou=None)), records, data, progress=True
    )
    # Without choices: the detector's own setting. With them: no suppression first, then each IoU.
    best_iou = None if nms_choices else detector.cfg.nms_iou
    best = coco_ap(records, nms_results(raw, best_iou))
    candidates = {"none" if best_iou is None else str(best_iou): best["AP50"]}
    for iou in sorted(nms_choices or [], reverse=True):  # from the loosest suppression to the strictest
        metrics = coco_ap(records, nms_results(raw, iou))
        candidates[str(iou)] = metrics["AP50"]
        if metrics["AP50"] > best["AP50"] + 0.002:
            best_iou, best = iou, metrics
    return {**best, "nms_iou": best_iou, "nms_candidates": candidates}


def export(
    run: str | Path,
    out: str | Path,
    threshold: float | None = None,
    precision: str = "float32",
    nms_iou: float | None | str = "keep",
    trained_on: str | None = None,
    threshold_metrics: dict | None = None,
) -> Path:
    """Write ``run``'s weights and config to ``out`` (a ``.safetensors`` path or a folder); ``threshold`` and
    ``nms_iou`` (a float, None for no suppression, "keep" for the run's own) replace the run's settings, and
    ``trained_on`` (a line) the run's own account of its training data."""
    model, cfg, meta = load_checkpoint(run)
    if threshold is not None:
        cfg = replace(cfg, score_threshold=float(threshold))
    if nms_iou != "keep":
        cfg = replace(cfg, nms_iou=nms_iou)
    if threshold_metrics is not None:
        cfg = replace(cfg, extra={**cfg.extra, "threshold_chosen_on": threshold_metrics})
    trained_on = trained_on or saved_trained_on(meta)
    return save_checkpoint(
        out, model, cfg, meta.get("train"), meta.get("progress"), precision=precision, trained_on=trained_on
    )


def main(argv: list[str] | None = None) -> Path:
    p = argparse.ArgumentParser(
        prog="python -m detector.export",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument("checkpoint", help="run folder (or checkpoint) written by detector.train")
    p.add_argument(
        "--out", required=True, help="NAME.safetensors (NAME.json is written beside it) or a folder"
    )
    add_data(p, required=False, help="dataset root, for --threshold-days")
    add_annotations(p, help="MVOR-format annotation json, for --threshold-days (default: DATA/annotations.json)")
    p.add_argument(
        "--threshold-days", type=int, nargs="+", help="set the score threshold on these (training) days"
    )
    p.add_argument("--threshold-views", type=int, default=400, help="views sampled from those days (0: all)")
    p.add_argument("--threshold", type=float, help="set this score threshold instead")
    p.add_argument(
        "--nms-choices",
        type=float,
        nargs="*",
        default=[0.5, 0.6, 0.7, 0.8],
        help="with --threshold-days: non-maximum suppression IoUs to choose from (with none) by AP50 on those days",
    )
    nms_group = p.add_mutually_exclusive_group()
    nms_group.add_argument("--nms-iou", type=float, help="set this non-maximum suppression IoU instead")
    nms_group.add_argument("--no-nms", action="store_true", help="no non-maximum suppression")
    p.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="float32",
        help="stored weights: float32, float16 or weight-only int8 (per-output-channel scales)",
    )
    p.add_argument(
        "--half", dest="precision", action="store_const", const="float16", help="same as --precision float16"
    )
    p.add_argument(
        "--trained-on", help="a line saying what the weights were trained on (shown by GET /model)"
    )
    add_threads(p)
    args = p.parse_args(argv)
    set_threads(args.threads)
    args.annotations = annotations_path(args)
    threshold, metrics = args.threshold, None
    nms_iou = None if args.no_nms else args.nms_iou if args.nms_iou is not None else "keep"
    if args.threshold_days:
        if not (args.data and args.annotations):
            p.error("--threshold-days needs --data and --annotations")
        detector = PersonDetector.from_checkpoint(args.checkpoint)
        choose_nms = nms_iou == "keep"
        if not choose_nms:
            detector.cfg = replace(detector.cfg, nms_iou=nms_iou)
        metrics = choose_threshold(
            detector,
            args.data,
            args.annotations,
            args.threshold_days,
            args.threshold_views,
            nms_choices=args.nms_choices if choose_nms else None,
        )
        metrics["days"] = args.threshold_days
        threshold = metrics["F1_50_threshold"]
        if choose_nms:
            nms_iou = metrics["nms_iou"]
        print(json.dumps(metrics, indent=2))
    weights = export(args.checkpoint, args.out, threshold, args.precision, nms_iou, args.trained_on, metrics)
    print(f"wrote {weights} ({weights.stat().st_size / 1e6:.1f} MB), score threshold {threshold}")
    return weights


if __name__ == "__main__":
    main()
