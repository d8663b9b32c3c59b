"""Detector speed: milliseconds per view of each preset, all views of a frame in one forward pass.

    HF_HUB_OFFLINE=1 nice python benchmarks/detector_speed.py [--presets cpu cpu_detr_rgb paper] [--views 3] [--threads 2]

Random weights (speed does not depend on them), 640x480 RGB(-D) views resized by each variant's own
preprocessing, ``PersonDetector.detect`` end to end (preprocessing, DETR, decoding). Prints the machine, then one
JSON line per variant and runtime: the presets ``cpu`` and ``paper`` and the variants in ``VARIANTS`` (a preset
with overrides), each on ``--runtimes``: ``torch-nchw`` (torch's default layout, as before issue 11),
``torch-fp32`` and ``torch`` (channels_last; precision fp32 / auto), ``onnxruntime``, ``openvino`` (precision
auto) and ``openvino-fp32``. ``ONEDNN_MAX_CPU_ISA=AVX2`` caps OpenVINO's convolutions as it caps torch's (with
``ATEN_CPU_CAPABILITY=avx2``): the way to time an AVX2-only CPU on a newer one.

    python benchmarks/detector_speed.py --presets cpu --runtimes torch-nchw torch-fp32 torch onnxruntime openvino
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import torch

from detector.infer import PersonDetector
from detector.model import PRESETS, build_detector, preset
from posenet.runtime.execution import machine_line
from posenet.runtime.graphs import installed

RUNTIMES = {  # name: (backend, precision)
    "torch-nchw": ("torch", "fp32"),
    "torch-fp32": ("torch", "fp32"),
    "torch": ("torch", "auto"),
    "onnxruntime": ("onnxruntime", "fp32"),
    "openvino": ("openvino", "auto"),
    "openvino-fp32": ("openvino", "fp32"),
}


def nchw(detector: PersonDetector) -> PersonDetector:
    """The detector as it ran before channels_last: weights and inputs in torch's default layout."""
    detector.model = detector.model.to(memory_format=torch.contiguous_format)

    def forward(pixels, mask):
        out = detector.model(pixel_values=pixels, pixel_mask=mask)
        return out.logits, out.pred_boxes

    detector._forward = forward
    return detector


# Variants compared beside the presets: (preset, overrides).
VARIANTS = {
    "cpu_detr_rgb": ("cpu", {"arch": "detr", "backbone_stage": 3, "input_mode": "rgb", "num_queries": 16}),
    "cpu_conditional_rgbd": ("cpu", {"arch": "conditional_detr", "backbone_stage": 3, "input_mode": "rgbd"}),
}


def main(argv: list[str] | None = None) -> list[dict]:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--presets", nargs="+", default=["cpu", *VARIANTS, "paper"], choices=[*PRESETS, *VARIANTS])
    p.add_argument("--views", type=int, default=3, help="views per forward pass (one MVOR frame: 3)")
    p.add_argument("--repeats", type=int, default=5, help="timed passes (the median is reported)")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--device", default="cpu")
    p.add_argument("--runtimes", nargs="+", default=["torch"], choices=list(RUNTIMES))
    args = p.parse_args(argv)
    torch.set_num_threads(args.threads)
    print(machine_line())
    rng = np.random.default_rng(0)
    views = [rng.integers(0, 255, (480, 640, 3), dtype=np.uint8) for _ in range(args.views)]
    depths = [rng.integers(500, 6000, (480, 640), dtype=np.uint16) for _ in range(args.views)]
    rows = []
    for name, runtime in [(n, r) for n in args.presets for r in args.runtimes]:
        backend, precision = RUNTIMES[runtime]
        if backend != "torch" and not installed(backend):
            continue
        base, overrides = VARIANTS.get(name, (name, {}))
        cfg = preset(base, **overrides)
        torch.manual_seed(0)
        detector = PersonDetector(build_detector(cfg), cfg, args.device, precision, backend, args.threads)
        if runtime == "torch-nchw":
            detector = nchw(detector)
        detector.detect(views, depths)  # warm-up (allocations, lazy init)
        times = []
        for _ in range(args.repeats):
            if args.device.startswith("cuda"):
                torch.cuda.synchronize()
            t = time.perf_counter()
            detector.detect(views, depths)
            if args.device.startswith("cuda"):
                torch.cuda.synchronize()
            times.append(time.perf_counter() - t)
        n_params = sum(q.numel() for q in detector.model.parameters())
        row = {
            "preset": name,
            "runtime": runtime,
            "backend": detector.backend.name,
            "precision": detector.precision.name,
            "arch": cfg.arch,
            "input_mode": cfg.input_mode,
            "params_M": round(n_params / 1e6, 1),
            "input": f"{cfg.input_width}x{cfg.input_width * 3 // 4}",
            "views": args.views,
            "threads": args.threads,
            "device": args.device,
            "ms_per_frame": round(1000 * float(np.median(times)), 1),
            "ms_per_view": round(1000 * float(np.median(times)) / args.views, 1),
        }
        print(json.dumps(row))
        rows.append(row)
    return rows


if __name__ == "__main__":
    main()
