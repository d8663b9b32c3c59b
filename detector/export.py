"""Export a trained detector as a single-file checkpoint (``NAME.safetensors`` + ``NAME.json``), e.g. the
shipped default weights.

    python -m detector.export RUN --out detector/weights/default.safetensors \
        --data data/mvor_twin --annotations data/mvor_twin/annotations.json --threshold-days 1 2 3 \
        --trained-on "what the weights saw"

With ``--threshold-days``, the score threshold that the service applies (``DetectorConfig.score_threshold``)
is set to the F1-best threshold at IoU 0.5 on those days' views (``detector.evaluate``): choose training
days, never the held-out one. ``--precision float16`` (``--half``) stores the weights as float16 (half the
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

from detector.checkpoint import PRECISIONS, load_checkpoint, save_checkpoint
from detector.data import load_records
from detector.evaluate import coco_ap
from detector.infer import PersonDetector
from detector.predict import predict_records


def choose_threshold(
    detector: PersonDetector, data: str, annotations: str, days: list[int], max_views: int, seed: int = 0
) -> dict:
    """COCO metrics, with the F1-best score threshold, of ``detector`` on (a seeded sample of) ``days``."""
    records = load_records(annotations, days)
    if max_views and len(records) > max_views:
        pick = np.random.default_rng(seed).choice(len(records), max_views, replace=False)
        records = [records[i] for i in sorted(pick)]
    return coco_ap(records, predict_records(detector, records, data, progress=True))


def export(
    run: str | Path,
    out: str | Path,
    threshold: float | None = None,
    precision: str = "float32",
    trained_on: str | None = None,
    threshold_metrics: dict | None = None,
) -> Path:
    """Write ``run``'s weights and config to ``out`` (a ``.safetensors`` path or a folder)."""
    model, cfg, meta = load_checkpoint(run)
    if threshold is not None:
        cfg = replace(cfg, score_threshold=float(threshold))
    if threshold_metrics is not None:
        cfg = replace(cfg, extra={**cfg.extra, "threshold_chosen_on": threshold_metrics})
    top = {"trained_on": trained_on} if trained_on else None
    return save_checkpoint(
        out, model, cfg, meta.get("train"), meta.get("progress"), precision=precision, top=top
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
    p.add_argument("--data", help="dataset root, for --threshold-days")
    p.add_argument("--annotations", help="MVOR-format annotation json, for --threshold-days")
    p.add_argument(
        "--threshold-days", type=int, nargs="+", help="set the score threshold on these (training) days"
    )
    p.add_argument("--threshold-views", type=int, default=400, help="views sampled from those days (0: all)")
    p.add_argument("--threshold", type=float, help="set this score threshold instead")
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
    p.add_argument("--threads", type=int, help="torch CPU threads")
    args = p.parse_args(argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    threshold, metrics = args.threshold, None
    if args.threshold_days:
        if not (args.data and args.annotations):
            p.error("--threshold-days needs --data and --annotations")
        detector = PersonDetector.from_checkpoint(args.checkpoint)
        metrics = choose_threshold(
            detector, args.data, args.annotations, args.threshold_days, args.threshold_views
        )
        metrics["days"] = args.threshold_days
        threshold = metrics["F1_50_threshold"]
        print(json.dumps(metrics, indent=2))
    weights = export(args.checkpoint, args.out, threshold, args.precision, args.trained_on, metrics)
    print(f"wrote {weights} ({weights.stat().st_size / 1e6:.1f} MB), score threshold {threshold}")
    return weights


if __name__ == "__main__":
    main()
