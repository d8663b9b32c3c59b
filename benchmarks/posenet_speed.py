"""Pose-network speed on this machine: inference per scene against persons, training per scene, U-Net FLOP/s.

Usage::

    nice python benchmarks/posenet_speed.py --threads 2 [--json OUT.json]

For each preset (``cpu``: 96x96 person crops, U-Net base 16; ``cpu-wide``: the same at base 24; ``paper``: full
320x240 images, base 64) and each execution setting (fp32 / bf16 autocast x contiguous / channels_last; ``auto``:
the precision this machine gets, channels_last, as the service and training run by default; ``onnxruntime`` /
``openvino``: the U-Net on an inference runtime, inference only), it times on random 3-view scenes of 320x240 (the
reader's ``subsample=2``):
- inference: ms per scene for 1, 3 and 6 persons, all persons x views in one forward pass under
  ``torch.inference_mode`` (input building, U-Net, inverse warp, lifting and aggregation included);
- training: seconds per scene for one forward + backward + Adam step, with augmentation, 3 persons;
- the U-Net's forward FLOPs per person-view and the achieved GFLOP/s of the U-Net forward alone.
Medians of ``--repeats`` runs after a warm-up. Input data are random (speed does not depend on the content).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
import torch

from posenet.cameras import Camera
from posenet.net.augment import AugmentConfig
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig, build_scene
from posenet.net.loss import mpjpe
from posenet.net.model import ModelConfig, PoseNet
from posenet.runtime.execution import machine_line
from posenet.runtime.graphs import installed

PRESETS = {
    "cpu": dict(inputs=InputConfig(mode="crop", crop_size=96, extra_depth=True), base=16, depth=3),
    "paper": dict(inputs=InputConfig(mode="full", extra_depth=False), base=64, depth=4),
}
# the cpu preset widened (posenet.training.train --base 24 --init a base-16 checkpoint; docs/RESULTS.md, "What we tried")
PRESETS["cpu-wide"] = {**PRESETS["cpu"], "base": 24}
SETTINGS = {  # name: (precision, channels_last, backend)
    "fp32": ("fp32", False, "torch"),
    "fp32+channels_last": ("fp32", True, "torch"),
    "bf16": ("bf16", False, "torch"),
    "bf16+channels_last": ("bf16", True, "torch"),
    "auto": ("auto", True, "torch"),
    "onnxruntime": ("auto", True, "onnxruntime"),
    "openvino": ("auto", True, "openvino"),
}


def random_scene(persons: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    views = []
    for v in range(3):
        T = np.eye(4)
        T[0, 3] = 800.0 * v
        color = rng.integers(0, 255, (240, 320, 3)).astype(np.uint8)
        depth = rng.integers(1500, 4000, (240, 320)).astype(np.uint16)
        views.append((color, depth, Camera.create(270.0, 270.0, 159.5, 119.5, T)))
    x0 = rng.uniform(0, 240, (persons, 3))
    y0 = rng.uniform(0, 100, (persons, 3))
    boxes = np.stack([x0, y0, x0 + 70, y0 + 130], -1).astype(np.float32)  # (P, V, 4)
    return views, torch.from_numpy(boxes), torch.ones(persons, 3, dtype=torch.bool)


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up (allocator, oneDNN kernels)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bench(preset: str, setting: str, repeats: int, persons_list=(1, 3, 6)) -> dict:
    precision, cl, backend = SETTINGS[setting]
    cfg = ModelConfig(**PRESETS[preset], precision=precision, channels_last=cl)
    torch.manual_seed(0)
    model = PoseNet(cfg).eval()
    est = PoseEstimator(model)
    est.use_backend(backend)
    row: dict = {"preset": preset, "setting": setting, "backend": est.backend.name,
                 "precision": est.precision.name}  # fmt: skip
    for P in persons_list:
        views, boxes, has = random_scene(P)

        def infer(views=views, boxes=boxes, has=has) -> None:
            with torch.inference_mode():
                model(build_scene(views, boxes, has, cfg.inputs))

        row[f"infer_ms_{P}p"] = round(1000 * median_time(infer, repeats), 1)

    # the U-Net alone on one scene's 3 persons x 3 views: FLOPs and FLOP/s
    views, boxes, has = random_scene(3)
    scene = build_scene(views, boxes, has, cfg.inputs)
    w, h = scene.images.shape[-1], scene.images.shape[-2]
    flops = model.unet.flops(h, w)
    x = scene.images.contiguous(memory_format=torch.channels_last) if cl else scene.images

    def unet() -> None:
        with torch.inference_mode():
            model._unet(x)

    t = median_time(unet, repeats)
    row.update(
        unet_input=f"{w}x{h}",
        unet_gflops_per_view=round(flops / 1e9, 3),
        unet_ms_9_views=round(1000 * t, 1),
        achieved_gflops_per_s=round(flops * x.shape[0] / t / 1e9, 1),
    )

    if backend != "torch":
        return row  # the runtimes run inference only
    # one training step per scene (3 persons, augmentation on)
    model.train()
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    gt = torch.randn(3, 10, 3) * 200 + torch.tensor([400.0, 0.0, 2500.0])
    gen = torch.Generator().manual_seed(0)

    def step() -> None:
        s = build_scene(views, boxes, has, cfg.inputs, AugmentConfig(), gen)
        loss = mpjpe(model(s).joints, gt, torch.ones(3, 10, dtype=torch.bool))
        opt.zero_grad()
        loss.backward()
        opt.step()

    row["train_s_per_scene_3p"] = round(median_time(step, max(2, repeats // 2)), 3)
    return row


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per measurement (median)")
    p.add_argument("--presets", nargs="*", default=list(PRESETS), choices=list(PRESETS))
    p.add_argument("--settings", nargs="*", default=list(SETTINGS), choices=list(SETTINGS))
    p.add_argument("--persons", type=int, nargs="*", default=[1, 3, 6], help="persons per inference scene")
    p.add_argument("--json", help="also write the rows to this json file")
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    print(machine_line())
    rows = []
    for preset in args.presets:
        for setting in args.settings:
            if SETTINGS[setting][2] != "torch" and not installed(SETTINGS[setting][2]):
                continue
            row = bench(preset, setting, args.repeats, tuple(args.persons))
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"threads": args.threads, "machine": machine_line(), "rows": rows}, f, indent=2)


if __name__ == "__main__":
    main()
