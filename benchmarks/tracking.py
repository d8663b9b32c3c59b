"""Tracking over rendered sequences: the pose pipeline (detector mode) per frame, then posenet.track over time.

    python -m posenet.data.synth --out data/seq_eval --sequence --frames 120 --persons 3 --rig mvor --look twin
    python benchmarks/tracking.py --data data/seq_eval --detections runs/seq_eval_detections.jsonl

It runs ``service.pipeline.ScenePipeline.run(views)`` (detector mode: no boxes given, the shipped detector and
pose network) on every frame of the sequences, caching each frame's persons (joints, per-joint spread in mm) in
``--detections`` (reused when it exists, so the tracker can be tuned without the networks), then tracks each
sequence with :class:`posenet.track.Tracker` and prints :func:`posenet.track_eval.evaluate`'s figures (MOTA,
IDF1, id switches with a 3D gate; per-frame against smoothed MPJPE; acceleration error; per-track bone-length
standard deviation; the tracker's milliseconds per frame) against issue 15's goals.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from posenet.data.mvor import MvorDataset, load_annotations
from posenet.execution import machine_line
from posenet.track import Tracker, TrackerConfig
from posenet.track_eval import GOALS, SequenceFrame, evaluate, goal_lines


def detect(data: Path, gt: dict, out: Path, backend: str, threads: int | None) -> None:
    """Run the pipeline in detector mode on every frame of ``data`` and write one JSON line per frame."""
    from service.pipeline import FrameView, ScenePipeline

    pipe = ScenePipeline.from_checkpoints(backend=backend, threads=threads)
    ds = MvorDataset(data, gt)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w") as f:
        for i in tqdm(range(len(ds)), desc="pipeline", unit="frame"):
            sample = ds[i]
            t0 = time.perf_counter()
            result = pipe.run([FrameView(v.color, v.depth, v.camera) for v in sample.views])
            record = {
                "id": sample.id,
                "seconds": round(time.perf_counter() - t0, 3),
                "persons": [
                    {
                        "joints": p.joints.round(2).tolist(),
                        "spread_mm": p.spread_mm.round(2).tolist(),
                        "support": p.support,
                    }
                    for p in result.persons
                ],  # fmt: skip
            }
            f.write(json.dumps(record) + "\n")


def sequences(gt: dict, detections: dict[str, dict]) -> dict[int, list[SequenceFrame]]:
    """Per sequence, its frames in time order: ground truth (person ids and joints) and the pipeline's persons."""
    poses = defaultdict(list)
    for pose in gt["annotations3D"]:
        poses[pose["image_ids"]].append(pose)
    out = defaultdict(list)
    for mv in gt["multiview_images"]:
        if "sequence" not in mv:
            raise ValueError(f"frame {mv['id']} has no 'sequence': render with posenet.data.synth --sequence")
        gts = poses[mv["id"]]
        det = detections[mv["id"]]["persons"]
        out[mv["sequence"]].append(
            SequenceFrame(
                timestamp_s=float(mv["timestamp_s"]),
                gt_ids=np.array([p["person_id"] for p in gts], int),
                gt_joints=np.array([np.reshape(p["keypoints3D"], (-1, 4))[:10, :3] for p in gts]).reshape(
                    -1, 10, 3
                ),
                joints=np.array([p["joints"] for p in det], float).reshape(-1, 10, 3),
                spread=np.array([p["spread_mm"] for p in det], float).reshape(-1, 10),
            )
        )
    for frames in out.values():
        frames.sort(key=lambda f: f.timestamp_s)
    return dict(out)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument(
        "--data", type=Path, required=True, help="a rendered sequence (posenet.data.synth --sequence)"
    )
    p.add_argument("--annotations", type=Path, help="its annotations (default: DATA/annotations.json)")
    p.add_argument("--detections", type=Path, required=True, help="the pipeline's persons per frame (cache)")
    p.add_argument("--redetect", action="store_true", help="run the pipeline even when --detections exists")
    p.add_argument("--backend", default="torch", help="the networks' runtime (torch, openvino, onnxruntime)")
    p.add_argument("--threads", type=int, default=None, help="the runtimes' intra-op threads")
    p.add_argument("--json", type=Path, help="also write the figures here")
    args = p.parse_args(argv)
    gt = load_annotations(args.annotations or args.data / "annotations.json")
    if args.redetect or not args.detections.is_file():
        detect(args.data, gt, args.detections, args.backend, args.threads)
    with open(args.detections) as f:
        detections = {r["id"]: r for r in map(json.loads, f)}
    config = TrackerConfig()
    report = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"), "tracker": vars(config).copy()}
    seconds = [r["seconds"] for r in detections.values()]
    report["pipeline_seconds_per_frame"] = round(float(np.mean(seconds)), 3)
    report["sequences"] = {}
    for seq, frames in sequences(gt, detections).items():
        report["sequences"][seq] = evaluate(frames, Tracker(config))
    for seq, figures in report["sequences"].items():
        print(f"sequence {seq}: {len(frames)} frames")
        for line in goal_lines(figures):
            print("  " + line)
    print(report["machine"])
    report["goals"] = GOALS
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
