"""Accuracy of the shipped weights on each backend and precision: do the runtimes change the answers?

    python benchmarks/backend_accuracy.py --data data/mvor_twin --days 4
    python benchmarks/backend_accuracy.py --data data/mvor_alt --days 4 --variants torch-fp32 openvino-auto

For each variant (backend x precision) it runs the pose network with the reference boxes on every frame of
``--days`` (posenet.evaluation.evaluate's MPJPE, per joint type and per support) and the detector on every view
(pycocotools AP50 / AP, detector.evaluate), and prints them beside the torch fp32 reference with the
difference. Issue 11's bounds: MPJPE within 0.1 cm and AP50 within 0.005 of torch fp32.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import torch
from tqdm import tqdm

from detector.evaluate import coco_ap
from detector.infer import PersonDetector
from detector.predict import predict_records
from pipeline.two_stage import ScenePipeline
from posenet.data.mvor import MvorDataset, load_annotations
from posenet.evaluation.evaluate import evaluate
from posenet.net.infer import PoseEstimator
from posenet.runtime.execution import machine_line

VARIANTS = {  # name: (backend, precision)
    "torch-fp32": ("torch", "fp32"),
    "torch-bf16": ("torch", "bf16"),
    "onnxruntime-fp32": ("onnxruntime", "fp32"),
    "openvino-fp32": ("openvino", "fp32"),
    "openvino-auto": ("openvino", "auto"),
    "openvino-int8": ("openvino", "int8"),
}


def run_variant(name: str, args, gt: dict, ds: MvorDataset) -> dict:
    from detector.data import load_records

    backend, precision = VARIANTS[name]
    pose = PoseEstimator.from_checkpoint(args.pose_checkpoint, "cpu", precision, backend, args.threads)
    det = PersonDetector.from_checkpoint(args.detector_checkpoint, "cpu", precision, backend, args.threads)
    pipe = ScenePipeline(pose)
    t0 = time.perf_counter()
    preds = []
    for i in tqdm(range(len(ds)), desc=f"{name} pose", leave=False):
        preds += pipe.run_sample(ds[i], reference_boxes=True)[1]
    pose_s = time.perf_counter() - t0
    result = evaluate(gt, preds, days=args.days)
    records = load_records(gt, args.days)
    t0 = time.perf_counter()
    dets = predict_records(det, records, args.data, progress=False)
    det_s = time.perf_counter() - t0
    ap = coco_ap(records, dets)
    return {
        "pose": f"{pose.backend.name} {pose.precision.name}",
        "detector": f"{det.backend.name} {det.precision.name}",
        "mpjpe_overall_cm": result["overall"],
        "mpjpe_average_cm": result["per_joint"]["average"],
        "per_joint": result["per_joint"],
        "per_support": {k: v.get("average") for k, v in result["per_support"].items()},
        "AP50": ap["AP50"],
        "AP": ap["AP"],
        "pose_seconds": round(pose_s, 1),
        "detector_seconds": round(det_s, 1),
    }


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--data", type=Path, default=Path("data/mvor_twin"), help="MVOR-format dataset")
    p.add_argument("--annotations", type=Path, help="its annotations (default: DATA/annotations.json)")
    p.add_argument("--days", type=int, nargs="+", default=[4], help="recording days to evaluate")
    p.add_argument("--pose-checkpoint", help="default: the shipped weights")
    p.add_argument("--detector-checkpoint", help="default: the shipped weights")
    p.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", type=Path, help="also write the results as JSON")
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    gt = load_annotations(args.annotations or args.data / "annotations.json")
    ds = MvorDataset(args.data, gt, 1, ("color", "depth"), days=args.days)
    print(machine_line())
    rows = {name: run_variant(name, args, gt, ds) for name in args.variants}
    ref = rows.get("torch-fp32")
    head = f"{'variant':<18}{'pose':>18}{'detector':>18}{'MPJPE cm':>10}{'d':>7}{'AP50':>8}{'d':>8}{'AP':>7}"
    print(head + f"{'pose s':>8}{'det s':>7}\n" + "-" * (len(head) + 15))
    for name, r in rows.items():
        dm = r["mpjpe_overall_cm"] - ref["mpjpe_overall_cm"] if ref else float("nan")
        da = r["AP50"] - ref["AP50"] if ref else float("nan")
        print(f"{name:<18}{r['pose']:>18}{r['detector']:>18}{r['mpjpe_overall_cm']:>10.2f}{dm:>+7.2f}"
              f"{r['AP50']:>8.3f}{da:>+8.3f}{r['AP']:>7.3f}{r['pose_seconds']:>8.1f}{r['detector_seconds']:>7.1f}")  # fmt: skip
    if args.out:
        args.out.write_text(json.dumps({"machine": machine_line(), "rows": rows}, indent=2))
    return rows


if __name__ == "__main__":
    main()
