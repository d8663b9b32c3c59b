"""Pose-network speed on this machine: inference per scene against persons, training per scene, U-Net FLOP/s.

Usage::

    nice python benchmarks/posenet_speed.py --threads 2 [--json OUT.json]

For each preset (``cpu``: 96x96 person crops, U-Net base 16; ``cpu-wide``: the same at base 24; ``cpu-narrow`` and
``cpu-8``: at base 12 and 8; ``paper``: full
320x240 images, base 64) and each execution setting (fp32 / bf16 autocast x contiguous / channels_last; ``auto``:
the precision this machine gets, channels_last, as the service and training run by default; ``onnxruntime`` /
``openvino``: the U-Net on an inference runtime, inference only), it times on random 3-view scenes of 320x240 (the
reader's ``subsample=2``):
- inference: ms per scene for 1, 3 and 6 persons, all persons x views in one forward pass under
  ``torch.inference_mode`` (input building, U-Net, inverse warp, lifting and aggregation included);
- training: seconds per scene for one forward + backward + Adam step, with augmentation, 3 persons;
- the U-Net's forward FLOPs per person-view and the achieved GFLOP/s of the U-Net forward alone.
Medians of ``--repeats`` runs after a warm-up. Input data are random (speed does not depend on the content).

``--frame DATA [--index I]`` profiles instead the serving pose stage on one real frame in detector mode (the
shipped weights, ``auto`` precision and backend, as the service runs them): the boxes per view and how many
are unsure, how many end in a person, the crops the U-Net runs (x 2 with flips), and the milliseconds of each
part (crops, the U-Net with its FLOPs and achieved GFLOP/s, lifting, each box's softmax moments, the
association, the fusion and calibration, the rest: Python between them), at 1 and at ``--threads`` threads::

    python benchmarks/posenet_speed.py --frame data/mvor_altmesh4 --index 2 --threads 2
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
from posenet.net.inputs import InputConfig, build_box_crops, build_scene
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
# narrower, for serving (issue 47's "a smaller U-Net"): what the pose stage would save, measured before training one
PRESETS["cpu-narrow"] = {**PRESETS["cpu"], "base": 12}
PRESETS["cpu-8"] = {**PRESETS["cpu"], "base": 8}
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


def profile_frame(root, index: int, threads: int, repeats: int) -> dict:
    """The pose stage of frame ``index`` of the MVOR-format dataset ``root``, part by part (module docstring)."""
    from pathlib import Path

    from pipeline.skeleton_matching import match_heatmaps, members_of
    from pipeline.two_stage import ScenePipeline
    from posenet.data.mvor import MvorDataset
    from posenet.net.box_poses import slot_layout

    torch.set_num_threads(threads)
    root = Path(root)
    pipe = ScenePipeline.from_checkpoints(backend="auto", threads=threads)
    views = MvorDataset(root, root / "annotations.json")[index].views
    model, cfg = pipe.pose.model, pipe.pose.model.config
    detected = pipe.detect(views)
    boxes, candidate = detected.boxes, detected.candidate
    dense, has, _, _ = slot_layout(boxes)
    mirrors = (False, True) if cfg.flip_test else (False,)
    result = pipe.run(views, detected=detected)
    held = sum(len(k) for p in result.persons for k in p.box_indices)
    heat = pipe.pose.box_heatmaps(views, boxes)
    heat.reduce()
    groups = pipe._match_skeletons(boxes, views, candidate, detected=True)[2]
    members = members_of(groups, boxes)
    crop = cfg.inputs.mode == "crop"

    def inputs():  # what box_heatmaps builds: one crop per box in crop mode, the (slot, view) grid in full mode
        if crop:
            return [build_box_crops(views, boxes, cfg.inputs, mirror=m) for m in mirrors]
        return [build_scene(views, dense, has, cfg.inputs, mirror=m) for m in mirrors]

    with torch.inference_mode():
        scenes = inputs()
        flops = model.unet.flops(*scenes[0].images.shape[-2:]) * int(has.sum()) * len(mirrors)
        batch = torch.cat([s.images for s in scenes]) if crop else None

        parts = {
            "detect (for scale)": lambda: pipe.detect(views),
            "crops (build_box_crops)" if crop else "crops (build_scene)": inputs,
            "U-Net": (lambda: model.unet_logits(batch)) if crop else (lambda: model.heatmaps(scenes)),
            "box heatmaps (crops + U-Net + lifting)": lambda: pipe.pose.box_heatmaps(views, boxes),
            "softmax moments per box": lambda: [
                p.__setattr__("_moments", None) or p.moments(heat.eps) for p in heat.passes
            ],  # fmt: skip
            "association (match_heatmaps)": lambda: match_heatmaps(
                heat, views, boxes, pipe._skeleton_config(), candidate=candidate, detected=True
            ),
            "fusion + calibration": lambda: pipe.pose.calibration(
                heat.estimate(members).spread_mm.double(),
                torch.ones(len(members), dtype=torch.long) * 3,
                heat.estimate(members).joints.double(),
            ),  # fmt: skip
            "run(): match + pose stages": lambda: pipe.run(views, detected=detected),
        }
        ms = {name: 1e3 * median_time(fn, repeats) for name, fn in parts.items()}
    crops_ms = ms["crops (build_box_crops)" if crop else "crops (build_scene)"]
    ms["lifting (box heatmaps - crops - U-Net)"] = (
        ms["box heatmaps (crops + U-Net + lifting)"] - crops_ms - ms["U-Net"]
    )
    ms["rest: Python between the parts"] = ms["run(): match + pose stages"] - sum(
        ms[k] for k in ("box heatmaps (crops + U-Net + lifting)", "softmax moments per box",
                        "association (match_heatmaps)", "fusion + calibration")
    )  # fmt: skip
    unsure = int(sum(c.sum() for c in candidate)) if candidate is not None else 0
    return {
        "threads": threads,
        "runtime": f"U-Net {pipe.pose.backend.name} {pipe.pose.precision.name}",
        "boxes_per_view": [len(b) for b in boxes],
        "unsure_boxes": unsure,
        "boxes_in_persons": held,
        "persons": len(result.persons),
        "crops_run": int(has.sum()) * len(mirrors),
        "unet_gflops": round(flops / 1e9, 2),
        "unet_gflop_per_s": round(flops / 1e9 / (ms["U-Net"] / 1e3), 1),
        "ms": {k: round(v, 1) for k, v in ms.items()},
    }


def format_profile(rows: list[dict]) -> str:
    r0 = rows[0]
    lines = [
        f"pose stage of one frame, detector mode: boxes per view {r0['boxes_per_view']} ({r0['unsure_boxes']} unsure), "
        f"{r0['boxes_in_persons']} of them in the {r0['persons']} persons answered; the U-Net runs {r0['crops_run']} "
        f"crops ({r0['unet_gflops']} GFLOP)",
        f"{'part (ms, median)':<44}" + "".join(f"{r['threads']:>3} thr {r['runtime']:<22}" for r in rows),
    ]
    for k in r0["ms"]:
        lines.append(f"{k:<44}" + "".join(f"{r['ms'][k]:>32.1f}" for r in rows))
    lines.append(f"{'U-Net achieved GFLOP/s':<44}" + "".join(f"{r['unet_gflop_per_s']:>32.1f}" for r in rows))
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    p.add_argument("--repeats", type=int, default=5, help="timed runs per measurement (median)")
    p.add_argument("--presets", nargs="*", default=list(PRESETS), choices=list(PRESETS))
    p.add_argument("--settings", nargs="*", default=list(SETTINGS), choices=list(SETTINGS))
    p.add_argument("--persons", type=int, nargs="*", default=[1, 3, 6], help="persons per inference scene")
    p.add_argument("--json", help="also write the rows to this json file")
    p.add_argument(
        "--frame", help="profile the serving pose stage on a frame of this MVOR-format dataset instead"
    )
    p.add_argument(
        "--index", type=int, default=2, help="--frame: which frame of the dataset (default: %(default)s)"
    )
    args = p.parse_args()
    if args.frame:
        print(machine_line())
        rows = [profile_frame(args.frame, args.index, t, args.repeats) for t in sorted({1, args.threads})]
        print(format_profile(rows))
        if args.json:
            with open(args.json, "w") as f:
                json.dump({"machine": machine_line(), "rows": rows}, f, indent=2)
        return
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
