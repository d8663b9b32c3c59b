"""Draw one scene's prediction to PNG, like the paper's Figures 3 and 4.

Usage::

    python -m posenet.viz.visualize --data DIR --annotations A.json --checkpoint RUN/best --frame 0 \\
        --out scene.png

The picture has three rows:
1. the V views with the reference boxes (one colour per person);
2. the 10 per-joint heatmaps of one person (``--person``) in the view where its box is largest, cut out around
   the box (the paper's Figure 3), as softmax weights within that view;
3. a 3D plot (reference frame, mm) of the lifted point clouds of every person (the points that carry the
   weight of each joint, coloured by joint), the predicted skeletons in colour and the ground truth in black
   (the paper's Figure 4).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

from posenet.cli import add_annotations, add_data, add_days, annotations_path
from posenet.net.infer import PoseEstimator, PosePrediction
from posenet.net.lifting import lift, masked_logits
from posenet.skeleton import BONES, JOINT_COLOURS, JOINTS, NUM_JOINTS

PERSON_COLOURS = ("tab:orange", "tab:blue", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink")


def _cloud(pred: PosePrediction, cameras, top: int = 300) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``top`` heaviest points of each person's joint clouds: points (K, 3), joints (K,), weights (K,)."""
    P, V, J, M = pred.heatmaps.shape
    points = lift(cameras, pred.uv.float(), pred.depth.float()).expand(P, V, M, 3).reshape(P, V * M, 3)
    logits = masked_logits(pred.heatmaps, pred.valid.expand(P, V, M))
    w = torch.softmax(logits.permute(0, 2, 1, 3).reshape(P, J, V * M), dim=-1)  # (P, J, V*M)
    k = min(top, V * M)
    wt, idx = w.topk(k, dim=-1)  # (P, J, k)
    pts = torch.gather(points.unsqueeze(1).expand(P, J, V * M, 3), 2, idx.unsqueeze(-1).expand(P, J, k, 3))
    joint = torch.arange(J).view(1, J, 1).expand(P, J, k)
    keep = pred.has_points.view(P, 1, 1).expand(P, J, k)
    return pts[keep].numpy(), joint[keep].numpy(), wt[keep].numpy()


def draw_box(ax, box, colour, label: str) -> None:
    """One person box ``(x0, y0, x1, y1)`` (pixels) on image axes, with ``label`` above its top-left corner (inside
    it when the box touches the image's top)."""
    from matplotlib.patches import Rectangle

    x0, y0, x1, y1 = box
    ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec=colour, lw=2))
    inside = y0 < 0.06 * ax.get_ylim()[0]  # near the image's top (ylim: from the bottom row up to -0.5)
    y, va = (y0 + 3, "top") if inside else (y0 - 3, "baseline")
    ax.text(x0 + 3 * inside, y, label, color=colour, fontsize=8, va=va)


def draw(sample, pred: PosePrediction, boxes, person_ids, person: int, out: str | Path, mode: str) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    V = len(sample.views)
    fig = plt.figure(figsize=(4 * max(V, 3), 11))
    grid = fig.add_gridspec(3, 1, height_ratios=[1.0, 0.9, 1.6])
    # 1. the views and their boxes
    top = grid[0].subgridspec(1, V)
    for v, view in enumerate(sample.views):
        ax = fig.add_subplot(top[v])
        img = view.color if view.color is not None else view.depth
        ax.imshow(img, cmap=None if view.color is not None else "viridis")
        for p in range(len(person_ids)):
            if boxes[p][v] is not None:
                draw_box(ax, boxes[p][v], PERSON_COLOURS[p % len(PERSON_COLOURS)], f"id {person_ids[p]}")
        ax.set_title(f"view {v} ({view.file_name})", fontsize=8)
        ax.axis("off")
    # 2. heatmaps of one person in its largest view
    mid = grid[1].subgridspec(2, NUM_JOINTS // 2)
    areas = [0 if b is None else (b[2] - b[0]) * (b[3] - b[1]) for b in boxes[person]]
    v = int(np.argmax(areas))
    logits = pred.heatmaps[person, v]  # (J, M)
    valid = pred.valid.expand(pred.heatmaps.shape[0], -1, -1)[person, v]
    w = torch.softmax(masked_logits(logits[None, None], valid[None, None])[0, 0], dim=-1)
    if mode == "crop":
        side = int(round(w.shape[-1] ** 0.5))
        maps = w.view(NUM_JOINTS, side, side)
    else:
        H, W = sample.views[v].height, sample.views[v].width
        x0, y0, x1, y1 = (int(round(c)) for c in boxes[person][v])
        maps = w.view(NUM_JOINTS, H, W)[:, max(y0, 0) : y1 + 1, max(x0, 0) : x1 + 1]
    for j in range(NUM_JOINTS):
        ax = fig.add_subplot(mid[j // (NUM_JOINTS // 2), j % (NUM_JOINTS // 2)])
        ax.imshow(maps[j].numpy(), cmap="magma")
        ax.set_title(f"{JOINTS[j]} (view {v})", fontsize=8)
        ax.axis("off")
    # 3. point clouds and skeletons in 3D
    ax = fig.add_subplot(grid[2], projection="3d")
    index = {int(pid): k for k, pid in enumerate(sample.person_ids)}
    skeletons = []  # (joints (J, 3), valid (J,), colour, line width)
    for p, pid in enumerate(person_ids):
        if bool(pred.has_points[p]):
            skeletons.append((pred.joints[p].numpy(), np.ones(NUM_JOINTS, bool), PERSON_COLOURS[p % 7], 2.0))
        if pid in index:
            skeletons.append((sample.poses[index[pid]], sample.valid[index[pid]], "black", 1.5))
    # the plotted volume: every skeleton plus 40 cm; cloud points outside it are left out (matplotlib's 3D
    # axes do not clip, and a few stray background points would squash the people into a corner)
    shown = np.concatenate([j[ok] for j, ok, _, _ in skeletons]) if skeletons else np.zeros((1, 3))
    lo, hi = shown.min(0) - 400, shown.max(0) + 400
    pts, joint, wt = _cloud(pred, sample.cameras)
    inside = ((pts >= lo) & (pts <= hi)).all(1) if len(pts) else np.zeros(0, bool)
    if inside.any():
        colours = np.array(JOINT_COLOURS)[joint[inside]] / 255.0
        alpha = np.clip(wt[inside] / wt[inside].max(), 0.05, 1.0)
        q = pts[inside]
        ax.scatter(q[:, 0], q[:, 2], -q[:, 1], s=2, c=np.concatenate([colours, alpha[:, None]], 1))
    for joints, ok, colour, lw in skeletons:
        for a, b in BONES:
            if ok[a] and ok[b]:
                ax.plot(
                    *[[joints[a, i], joints[b, i]] for i in (0, 2)],
                    [-joints[a, 1], -joints[b, 1]],
                    c=colour,
                    lw=lw,
                )
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[2], hi[2])
    ax.set_zlim(-hi[1], -lo[1])
    ax.set_box_aspect((hi[0] - lo[0], hi[2] - lo[2], hi[1] - lo[1]))
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("z (mm)")
    ax.set_zlabel("-y (mm)")
    ax.set_title("lifted point clouds, predicted skeletons (colour) and ground truth (black); camera-0 frame")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    plt.close(fig)
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m posenet.viz.visualize",
        description="Draw one frame of an MVOR-format dataset to PNG: the views with their reference boxes, "
        "the per-joint heatmaps of one person, and a 3D plot of the lifted point clouds with the predicted "
        "skeletons (colour) and the ground truth (black), like the paper's Figures 3 and 4.",
    )
    add_data(p)
    add_annotations(p)
    p.add_argument(
        "--checkpoint", default=None, help="checkpoint folder or .safetensors (default: shipped weights)"
    )
    p.add_argument("--frame", default="0", help="frame index in the dataset, or a multi-view id")
    add_days(p, nargs="*", help="only these days (indexing follows)")
    p.add_argument("--person", type=int, default=0, help="which boxed person (0-based) gets the heatmap row")
    p.add_argument("--out", required=True, help="output PNG")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from posenet.evaluation.predict import read_dataset
    from posenet.scene import Scene

    est = PoseEstimator.from_checkpoint(args.checkpoint)
    data = read_dataset(args.data, annotations_path(args), est.model.config.inputs, args.days)
    index = data.ids.index(args.frame) if args.frame in data.ids else int(args.frame)
    if not 0 <= index < len(data):
        raise ValueError(f"--frame {args.frame}: the dataset has {len(data)} frames")
    sample = data[index]
    scene = Scene.from_sample(sample, "boxed")
    if scene.num_persons == 0:
        raise ValueError(f"frame {sample.id} has no boxed person to draw")
    boxes = [
        [b.tolist() if h else None for b, h in zip(pb, ph, strict=True)]
        for pb, ph in zip(scene.boxes, scene.has_box, strict=True)
    ]
    pred = est.predict(scene, return_heatmaps=True)
    person = min(max(args.person, 0), len(boxes) - 1)
    out = draw(sample, pred, boxes, scene.person_ids.tolist(), person, args.out, est.model.config.inputs.mode)
    print(f"wrote {out} (frame {sample.id}, {len(boxes)} persons)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
