"""Seconds per frame and per view of the synthetic renderer, by stage, on one core.

    python benchmarks/synth_speed.py --frames 12
    python benchmarks/synth_speed.py --frames 12 --mvor ../shared/mvor/camma_mvor_2018.json  # twin frames too
    python benchmarks/synth_speed.py --frames 12 --looks twin random alt  # each look (default: all of them)
    python benchmarks/synth_speed.py --frames 8 --mvor $MVOR --looks twin random mesh --residual  # mesh bodies
    python benchmarks/synth_speed.py --frames 12 --looks twin random --hard-negatives 4  # random with and without

Stages: building the frame (poses, room; for the twin also the occluder placement), ray casting (z-buffer,
ids, normals), the sensor models (depth and colour), and PNG encoding (in memory, so the disk does not count).
Both wall-clock and CPU seconds are printed: on a shared machine the CPU time is the steadier figure. The last
line extrapolates to the 732-frame MVOR twin with 2 worker processes. ``--residual`` also measures how far the
posed mesh bodies' joint definitions lie from the target joints (posenet.synth.mesh_body), on MVOR's real poses
and on procedural ones. The first line names the machine (CPU model, torch's CPU capability).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import cv2
import numpy as np

from posenet.data.images import COLOR_PNG_PARAMS, DEPTH_PNG_PARAMS
from posenet.synth.looks import LOOKS, make_look
from posenet.synth.procedural import procedural_frame
from posenet.synth.raster import rasterize
from posenet.synth.rig import cam_to_world, intrinsics, random_rig, world_to_cam
from posenet.synth.scene import frame_primitives, render_frame
from posenet.synth.twin import load_twin, twin_frame


class Clock:
    """Accumulates wall and CPU seconds per stage."""

    def __init__(self) -> None:
        self.wall: dict[str, float] = {}
        self.cpu: dict[str, float] = {}

    def time(self, stage: str, fn, *args):
        w, c = time.perf_counter(), time.process_time()
        out = fn(*args)
        self.wall[stage] = self.wall.get(stage, 0.0) + time.perf_counter() - w
        self.cpu[stage] = self.cpu.get(stage, 0.0) + time.process_time() - c
        return out


def run(builder, rig, n: int, seed: int) -> dict:
    clock = Clock()
    views = 0
    for k in range(n):
        rng = np.random.default_rng([seed, k])
        frame = clock.time("build", builder, rng)
        renders = clock.time("render (raster + sensor)", render_frame, frame, rig, rng)
        # Ray casting alone, to split the render time into geometry and sensor.
        prims = frame_primitives(frame)
        T = world_to_cam(rig)
        for v in range(len(rig)):
            cam = [p.to_camera(T[v]) for p in prims]
            clock.time("raster only", rasterize, cam, intrinsics(rig)[v])
        for r in renders:
            clock.time(
                "png encode",
                lambda r=r: (
                    cv2.imencode(".png", r.color, COLOR_PNG_PARAMS),
                    cv2.imencode(".png", r.depth, DEPTH_PNG_PARAMS),
                ),
            )
        views += len(renders)
    total_wall = sum(v for k, v in clock.wall.items() if k != "raster only")
    total_cpu = sum(v for k, v in clock.cpu.items() if k != "raster only")
    return {
        "frames": n,
        "views": views,
        "seconds_per_frame_wall": round(total_wall / n, 3),
        "seconds_per_frame_cpu": round(total_cpu / n, 3),
        "seconds_per_view_cpu": round(total_cpu / views, 3),
        "cpu_seconds_per_frame_by_stage": {k: round(v / n, 3) for k, v in clock.cpu.items()},
    }


def machine() -> str:
    """The CPU model and torch's CPU capability (the kernels its matrix code picks)."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    import os

    import torch

    return f"{model}, {os.cpu_count()} cores, torch {torch.__version__} ({torch.backends.cpu.get_cpu_capability()})"


def mesh_residual(ctx, n_procedural: int = 200) -> dict:
    """mm between the posed mesh's joint definitions and the target joints: MVOR's real poses (legs completed as
    the twin does; the three whose head lies 3.7-4.3 m from the neck left out) and procedural ones."""
    from posenet.skeleton import JOINTS
    from posenet.synth.body import BodyShape
    from posenet.synth.mesh_body import joint_residual
    from posenet.synth.poses import build_pose, place, sample_params
    from posenet.synth.skeleton_full import complete_legs

    sets = {}
    if ctx is not None:
        pts = [complete_legs(ctx.world_points(p)) for f in ctx.frames for _, p, _ in f.poses]
        sets["MVOR's poses"] = [p for p in pts if np.linalg.norm(p[0] - p[1]) < 400]
    rng = np.random.default_rng(0)
    sets["procedural poses"] = [
        place(build_pose(sample_params(rng, None)[1]), np.zeros(2), float(rng.uniform(0, 2 * np.pi)))
        for _ in range(n_procedural)
    ]
    out = {}
    for name, pts in sets.items():
        t = time.process_time()
        res = np.stack([joint_residual(p, BodyShape(model="mesh", mesh=i)) for i, p in enumerate(pts)])
        out[name] = {
            "poses": len(pts),
            "mean_mm": round(float(res.mean()), 1),
            "median_mm": round(float(np.median(res)), 1),
            "p95_mm": round(float(np.percentile(res, 95)), 1),
            "max_mm": round(float(res.max()), 1),
            "mean_mm_per_joint": dict(zip(JOINTS, np.round(res.mean(0), 1).tolist(), strict=True)),
            "cpu_ms_per_pose": round(1000 * (time.process_time() - t) / len(pts), 1),
        }
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=12, help="frames per kind")
    p.add_argument("--mvor", default=None, help="MVOR json: also time twin frames (every 60th MVOR frame)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--looks", nargs="+", choices=LOOKS, default=list(LOOKS), help="looks to time")
    p.add_argument("--residual", action="store_true", help="also the mesh bodies' joint residual")
    p.add_argument("--hard-negatives", type=int, default=0, metavar="N",
                   help="also time the random and mesh looks with N hard negatives tried per frame")  # fmt: skip
    args = p.parse_args()
    cv2.setNumThreads(1)
    rng = np.random.default_rng(args.seed)
    rig = random_rig(rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), 3)
    enclose = cam_to_world(rig)[:, :3, 3]
    ctx = load_twin(json.loads(Path(args.mvor).read_text())) if args.mvor else None
    out = {"machine": machine()}
    if "mesh" in args.looks or args.residual:
        from posenet.synth.mesh_model import load

        load()  # build the mesh's arrays before any timing
    runs = [(name, 0) for name in args.looks]
    if args.hard_negatives:
        runs += [(name, args.hard_negatives) for name in args.looks if name in ("random", "mesh")]
    for name, negatives in runs:

        def procedural(r, name=name, negatives=negatives):
            # The look draws from its own generator, as in the writer.
            frame = procedural_frame(r, enclose=enclose)
            look = None
            if name != "twin":
                look = make_look(name, np.random.default_rng(r.integers(1 << 62)), hard_negatives=negatives)
            if look is not None:
                for person in frame.persons:
                    look.dress(person)
                look.finish(frame, rig)
            return frame

        if negatives:
            out[f"procedural, {name} + {negatives} hard negatives (3 views)"] = run(
                procedural, rig, args.frames, args.seed
            )
            continue
        out[f"procedural, {name} (3 views)"] = run(procedural, rig, args.frames, args.seed)
        if ctx is not None:
            infos = ctx.frames[:: max(len(ctx.frames) // args.frames, 1)][: args.frames]
            it = iter(infos)

            def twin(r, it=it, name=name):
                look = None if name == "twin" else make_look(name, np.random.default_rng(r.integers(1 << 62)))
                return twin_frame(ctx, next(it), r, look)[0]

            key = f"twin, {name} (3 views)"
            out[key] = run(twin, ctx.rig, len(infos), args.seed)
            per = out[key]["seconds_per_frame_cpu"]
            out[f"twin, {name}: 732 frames, 2 workers, minutes"] = round(732 * per / 2 / 60, 1)
    if args.residual:
        out["mesh joint residual"] = mesh_residual(ctx)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
