"""Check the camera convention on real MVOR: project the 3D joints, compare with MVOR's 2D keypoints.

Run from the repository root (the annotation file lies in ``../shared/mvor/`` by default)::

    .venv/bin/python benchmarks/mvor_convention.py [--annotations PATH] [--subsample 1] [--json OUT.json]

For every box with an identity whose person has exactly one 3D pose in the frame, each joint annotated in both
2D (flag > 0) and 3D is projected with ``posenet.cameras.Camera`` and compared with MVOR's 2D keypoint. It
prints the median pixel error per joint and per camera for three models:
- ``pinhole``: ``extrinsics[v]`` read as T(v->0) (this project's convention), no distortion;
- ``distorted``: the same with MVOR's distortion coefficients (reordered to OpenCV's order);
- ``T(0->v)``: ``extrinsics[v]`` read the other way round, to show that the direction matters.
The table goes into ``docs/CONVENTIONS.md``.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from posenet.cameras import Camera, rigid_inverse
from posenet.data.mvor import MvorDataset, load_annotations
from posenet.skeleton import JOINTS

DEFAULT_ANNOTATIONS = Path(__file__).resolve().parents[2] / "shared" / "mvor" / "camma_mvor_2018.json"
MODELS = ("pinhole", "distorted", "T(0->v)")


def camera_models(cameras_info: dict, subsample: int) -> dict[str, list[Camera]]:
    """The three camera models of the module docstring, one camera per view, at the given subsampling."""
    plain = Camera.from_mvor(cameras_info)
    distorted = Camera.from_mvor(cameras_info, use_distortion=True)
    flipped = [Camera(c.intrinsics, rigid_inverse(c.extrinsics), None, c.size) for c in plain]
    return {
        name: [c.scale(1 / subsample) for c in cams]
        for name, cams in zip(MODELS, (plain, distorted, flipped), strict=True)
    }


def collect_errors(dataset: MvorDataset, models: dict[str, list[Camera]]) -> dict[str, np.ndarray]:
    """Per model, an (M, 3) array of (camera index, joint index, pixel error) over all usable joints."""
    rows = defaultdict(list)
    for sample in dataset:
        for view in sample.views:
            for pid, kps in zip(view.box_person_ids, view.keypoints2d, strict=True):
                hits = np.flatnonzero(sample.person_ids == pid)
                if pid < 0 or len(hits) != 1:  # no identity, or an ambiguous id (day 4, frame 38)
                    continue
                seen = np.flatnonzero((kps[:, 2] > 0) & sample.valid[hits[0]])
                joints = torch.as_tensor(sample.poses[hits[0]][seen], dtype=torch.float64)  # (n, 3)
                for name, cams in models.items():
                    uv = cams[view.cam_index].project(joints).numpy()
                    err = np.linalg.norm(uv - kps[seen, :2], axis=1)
                    rows[name].append(np.stack([np.full(len(seen), view.cam_index), seen, err], axis=1))
    return {name: np.concatenate(r) for name, r in rows.items()}


def table(errors: dict[str, np.ndarray], num_cameras: int) -> str:
    """A markdown table of median pixel errors: one row per joint plus one per camera and the total."""
    header = "| | " + " | ".join(f"{m} (px)" for m in errors) + " | joints |"
    lines = [header, "|" + " --- |" * (len(errors) + 2)]
    first = next(iter(errors.values()))

    def row(label: str, select) -> str:
        cells = [f"{np.median(e[select(e), 2]):.1f}" for e in errors.values()]
        return f"| {label} | " + " | ".join(cells) + f" | {int(select(first).sum())} |"

    for j, name in enumerate(JOINTS):
        lines.append(row(name, lambda e, j=j: e[:, 1] == j))
    for v in range(num_cameras):
        lines.append(row(f"camera {v + 1} (index {v})", lambda e, v=v: e[:, 0] == v))
    lines.append(row("all", lambda e: np.ones(len(e), bool)))
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--annotations", type=Path, default=DEFAULT_ANNOTATIONS, help="MVOR annotation json")
    parser.add_argument("--subsample", type=int, default=1, help="image subsampling factor (2: 320x240)")
    parser.add_argument("--json", type=Path, help="also write the medians to this file")
    args = parser.parse_args()
    gt = load_annotations(args.annotations)
    dataset = MvorDataset(None, gt, subsample=args.subsample)
    models = camera_models(gt["cameras_info"], args.subsample)
    errors = collect_errors(dataset, models)
    n_cams = len(models["pinhole"])
    print(f"Median pixel error of projected 3D joints vs MVOR's 2D keypoints, subsample {args.subsample}:\n")
    print(table(errors, n_cams))
    if args.json:
        medians = {
            name: {
                "per_joint": {j: float(np.median(e[e[:, 1] == i, 2])) for i, j in enumerate(JOINTS)},
                "per_camera": {str(v): float(np.median(e[e[:, 0] == v, 2])) for v in range(n_cams)},
                "all": float(np.median(e[:, 2])),
            }
            for name, e in errors.items()
        }
        args.json.write_text(json.dumps(medians, indent=2))


if __name__ == "__main__":
    main()
