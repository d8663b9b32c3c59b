"""Predict 3D poses for an MVOR-format dataset with reference boxes, in the evaluator's prediction format.

Usage::

    python -m posenet.evaluation.predict --data DIR --annotations A.json --checkpoint RUN/best --days 4 --out PRED.json
    python -m posenet.evaluation.evaluate --annotations A.json --predictions PRED.json

Every person id (>= 0) with a box in some view of a frame gets a prediction, from the reference boxes of the
annotation file. Output: a json list of ``{"image_ids", "person_id", "keypoints3D": [J*3 floats, mm]}`` plus
``"spread_mm": [J floats, mm]`` (the network's spread) and ``"confidence": [J floats in [0, 1]]`` (calibrated by the
checkpoint's ``posenet.net.calibration``); the evaluator ignores extra keys.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

from posenet.cli import add_annotations, add_data, add_days, add_threads, annotations_path, set_threads
from posenet.evaluation.evaluate import prediction_record
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig, reduction
from posenet.runtime.execution import PRECISIONS
from posenet.scene import Scene


def predict_samples(estimator: PoseEstimator, samples, scenes_per_batch: int = 4, which: str = "boxed",
                    progress: bool = True) -> list[dict]:  # fmt: skip
    """Predictions (evaluator format) for an iterable of ``Sample``\\ s, by ``estimator.predict``:
    ``scenes_per_batch`` scenes share one U-Net pass, and the estimator's calibration gives the confidences.
    ``which``: ``"boxed"`` predicts every boxed person, ``"annotated"`` those with a 3D pose
    (:meth:`posenet.scene.Scene.from_sample`)."""
    preds: list[dict] = []
    pending: list[Scene] = []

    def flush() -> None:
        for scene, pred in zip(pending, estimator.predict(pending), strict=True):
            for pid, pose, ok in zip(scene.person_ids.tolist(), pred.persons(), pred.has_points, strict=True):
                if not bool(ok):
                    continue  # no pixel with depth in any of its boxes: nothing to lift
                preds.append(prediction_record(scene.id, pid, pose.joints, pose.spread_mm, pose.confidence))
        pending.clear()

    for sample in tqdm(samples, desc="predict", disable=not progress, leave=False):
        scene = Scene.from_sample(sample, which)
        if scene.num_persons:
            pending.append(scene)
        if len(pending) >= scenes_per_batch:
            flush()
    flush()
    return preds


def read_subsample(annotations: dict, inputs: InputConfig | tuple[int, int] | None, days=None) -> int:
    """The reader's subsampling that brings an annotation file's views to the resolution the model reads
    (``InputConfig.read_size``, or a ``(W, H)`` such as ``ScenePipeline.read_size``; :func:`posenet.net.inputs.reduction`),
    as the service decodes a frame sent at full size; 1 for a file without frames. Only the cameras are read: a
    file without ``annotations3D`` works."""
    from posenet.data.mvor import MvorDataset  # the reader pulls in image I/O

    if "annotations3D" in annotations:
        annotations = {k: v for k, v in annotations.items() if k != "annotations3D"}
    meta = MvorDataset(None, annotations, modalities=(), days=days, poses=False)
    if len(meta) == 0:
        return 1
    W, H = meta[0].views[0].camera.size  # full size (subsample 1)
    return reduction(W, H, inputs.read_size if isinstance(inputs, InputConfig) else inputs)


def read_dataset(root, annotations, inputs: InputConfig | tuple[int, int] | None, days=None):
    """The ``MvorDataset`` of ``root`` read at the resolution the model reads (:func:`read_subsample`)."""
    from posenet.data.mvor import MvorDataset, load_annotations  # the reader pulls in image I/O

    if not isinstance(annotations, dict):
        annotations = load_annotations(annotations)
    return MvorDataset(root, annotations, subsample=read_subsample(annotations, inputs, days), days=days)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m posenet.evaluation.predict",
        description="Predict 3D poses (mm, camera-0 frame) for the frames of an MVOR-format dataset, using "
        "the "
        "reference person boxes of the annotation file, and write them in posenet.evaluation.evaluate's format.",
    )
    add_data(p)
    add_annotations(
        p, help="MVOR-format annotation json: boxes, cameras, frames (default: DATA/annotations.json)"
    )
    p.add_argument(
        "--checkpoint",
        default=None,
        help="checkpoint folder (RUN/best, RUN/last or a run folder) or NAME.safetensors with NAME.json "
        "beside "
        "it; default: the shipped posenet/weights/default.safetensors",
    )
    add_days(p, nargs="*", help="recording days to predict (default: all)")
    p.add_argument("--out", required=True, help="output json of predictions")
    p.add_argument("--scenes-per-batch", type=int, default=4, help="scenes that share one U-Net forward pass")
    add_threads(p)
    p.add_argument("--device", default="cpu", help="torch device, e.g. cpu or cuda")
    p.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="auto",
        help="how this machine runs it (posenet.runtime.execution)",
    )
    p.add_argument(
        "--flip-test",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="average with the horizontally mirrored inputs (2x the work; default: the checkpoint's setting)",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    set_threads(args.threads)
    estimator = PoseEstimator.from_checkpoint(
        args.checkpoint, args.device, args.precision, flip_test=args.flip_test
    )
    data = read_dataset(args.data, annotations_path(args), estimator.model.config.inputs, args.days)
    preds = predict_samples(estimator, data, args.scenes_per_batch)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(preds))
    print(f"wrote {len(preds)} predictions for {len(data)} frames to {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
