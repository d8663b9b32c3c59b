"""Build the inference runtime's ONNX graphs of both networks ahead of time (the service builds them at first
start otherwise): the shipped weights by default, or the checkpoints the service will load.

    python -m service.export                                   # the shipped weights, into ~/.cache/or-pose
    python -m service.export --pose-checkpoint RUN/best --detector-checkpoint DET --cache-dir /models/onnx
    python -m service.export --int8                            # also the int8 graphs (ORPOSE_PRECISION=int8)
    ORPOSE_CACHE_DIR=/models/onnx uvicorn service.app:app      # then finds them there

Each graph is named by a hash of its weights, config and exporter (``posenet.runtime.graphs``), so the service only
ever picks up a graph built from the very weights it loads. Prints one JSON line per graph, with its
parity against torch on blank and random inputs.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import torch


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m service.export",
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--pose-checkpoint", help="pose network checkpoint (default: the shipped weights)")
    p.add_argument("--detector-checkpoint", help="detector checkpoint (default: the shipped weights)")
    p.add_argument("--no-detector", action="store_true", help="only the pose network")
    p.add_argument(
        "--int8", action="store_true",
        help="also the int8 OpenVINO graphs (ORPOSE_PRECISION=int8; posenet.runtime.quantize): renders the calibration "
        "scenes and quantizes, about a minute",
    )  # fmt: skip
    p.add_argument(
        "--cache-dir", type=Path, help="where the graphs go (default: $ORPOSE_CACHE_DIR or ~/.cache/or-pose)"
    )
    args = p.parse_args(argv)
    if args.cache_dir:
        os.environ["ORPOSE_CACHE_DIR"] = str(args.cache_dir)

    from detector.infer import PersonDetector
    from posenet.net.infer import PoseEstimator
    from posenet.runtime.graphs import OnnxRunner, cache_dir

    torch.manual_seed(0)
    pose = PoseEstimator.from_checkpoint(args.pose_checkpoint, precision="fp32")
    t0 = time.perf_counter()
    path = pose.export()
    cfg = pose.model.config
    w, h = cfg.inputs.network_size(False)
    x = torch.randn(3, cfg.inputs.in_channels, h, w)
    with torch.inference_mode():
        ref = pose.model.unet(x)
    diff = (OnnxRunner(path, "onnxruntime", 2, pose.precision)(x=x)[0] - ref).abs().max().item()
    report = {"network": "pose", "graph": str(path), "seconds": round(time.perf_counter() - t0, 1)}
    print(json.dumps({**report, "max_abs_diff_vs_torch": diff}))
    if not args.no_detector:
        det = PersonDetector.from_checkpoint(args.detector_checkpoint, precision="fp32")
        t0 = time.perf_counter()
        path = det.export()
        pixels, mask = det._example()
        pixels = torch.randn_like(pixels)
        with torch.inference_mode():
            ref = det._forward(pixels, mask)
        got = OnnxRunner(path, "onnxruntime", 2, det.precision)(pixel_values=pixels, pixel_mask=mask)
        diff = max((a - b).abs().max().item() for a, b in zip(got, ref, strict=True))
        report = {"network": "detector", "graph": str(path), "seconds": round(time.perf_counter() - t0, 1)}
        print(json.dumps({**report, "max_abs_diff_vs_torch": diff}))
    failed = []
    if args.int8:
        networks = [("pose", PoseEstimator, args.pose_checkpoint)]
        if not args.no_detector:
            networks.append(("detector", PersonDetector, args.detector_checkpoint))
        for name, cls, checkpoint in networks:
            t0 = time.perf_counter()
            net = cls.from_checkpoint(checkpoint, precision="int8", backend="openvino")
            runner = net.model.runner if name == "pose" else net.runner
            graph = str(runner.path) if runner is not None else None
            report = {"network": name, "graph": graph, "precision": net.precision.name}
            print(
                json.dumps(
                    {**report, "reason": net.precision.reason, "seconds": round(time.perf_counter() - t0, 1)}
                )
            )
            if not net.precision.int8:
                failed.append(f"{name}: {net.precision.reason}")
    print(json.dumps({"cache_dir": str(cache_dir())}))
    if failed:  # a build step (docker/Dockerfile) must not pass without the graphs it was asked for
        raise SystemExit("error: int8 graphs not built (" + "; ".join(failed) + ")")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
