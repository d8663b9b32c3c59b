"""How faithful is the MVOR twin? Compares a rendered twin with the real MVOR annotations.

    MVOR=../shared/mvor/camma_mvor_2018.json
    python -m posenet.synth --out /tmp/mvor_twin --from-mvor $MVOR --workers 2
    python benchmarks/synth_twin_fidelity.py --twin /tmp/mvor_twin --mvor $MVOR

Reports, for the people with a 3D pose:
  - the IoU between each rendered box and MVOR's real box of the same person in the same image (mean per
    camera and overall; a box present in only one of the two is listed separately);
  - the support histogram (number of views with a box per 3D pose) of the twin next to MVOR's
    (132 / 426 / 503);
  - the fraction of visible joints (2D flag 2) whose projection lies inside their person's rendered box;
  - how the hidden people were hidden (from the twin's ``synth_config.json``).
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np

from posenet.boxes import box_iou, coco_to_xyxy
from posenet.data.support import pose_support


def _boxes(ann: dict) -> dict[tuple[int, int], np.ndarray]:
    """(image id, person id) -> xyxy for boxes of people with an id."""
    return {
        (a["image_id"], a["person_id"]): coco_to_xyxy(np.array(a["bbox"], np.float64))
        for a in ann["annotations"]
        if a["person_id"] >= 0
    }


def support_histogram(ann: dict) -> Counter:
    """Supporting views per 3D pose, counted by the project's own rule (``posenet.data.support``)."""
    return Counter(pose_support(ann))


def fidelity(twin: dict, real: dict) -> dict:
    """All the figures above, as a dict."""
    tb, rb = _boxes(twin), _boxes(real)
    cam_of = {im["id"]: im["cam_id"] for im in real["images"]}
    posed = {(int(i), p["person_id"]) for p in real["annotations3D"] for i in p["image_ids"].split("_")}
    rendered_images = {im["id"] for im in twin["images"]}
    per_cam: dict[int, list[float]] = {}
    only_real = only_twin = 0
    for key in posed:
        if key[0] not in rendered_images:
            continue
        if key in tb and key in rb:
            per_cam.setdefault(cam_of[key[0]], []).append(float(box_iou(tb[key], rb[key])))
        elif key in rb:
            only_real += 1
        elif key in tb:
            only_twin += 1
    inside = total = 0
    for a in twin["annotations"]:
        if a["person_id"] < 0:
            continue
        kp = np.array(a["keypoints"]).reshape(-1, 3)
        vis = kp[:, 2] == 2
        x, y, w, h = a["bbox"]
        ok = (
            (kp[vis, 0] >= x - 0.5)
            & (kp[vis, 0] <= x + w - 0.5)
            & (kp[vis, 1] >= y - 0.5)
            & (kp[vis, 1] <= y + h - 0.5)
        )
        inside += int(ok.sum())
        total += int(vis.sum())
    # Box-only clinicians (no 3D pose): how many, and how well the twin's bystanders cover MVOR's boxes.
    posed_ids = {(i, pid) for i, pid in posed}
    only = {}
    for name, ann in (("twin", twin), ("mvor", real)):
        only[name] = {}
        for a in ann["annotations"]:
            key = (a["image_id"], a["person_id"])
            if a["person_role"] == "clinician" and key not in posed_ids and a["image_id"] in rendered_images:
                box = coco_to_xyxy(np.array(a["bbox"], np.float64))
                only[name].setdefault(a["image_id"], []).append(box)
    best = [
        max((float(box_iou(b, t)) for t in only["twin"].get(img, [])), default=0.0)
        for img, boxes in only["mvor"].items()
        for b in boxes
    ]
    mv_ids = {mv["id"] for mv in twin["multiview_images"]}
    real_sub = dict(
        real,
        annotations3D=[p for p in real["annotations3D"] if p["image_ids"] in mv_ids],
        multiview_images=[mv for mv in real["multiview_images"] if mv["id"] in mv_ids],
    )
    all_iou = [v for vals in per_cam.values() for v in vals]
    return {
        "frames": len(twin["multiview_images"]),
        "iou_mean": round(float(np.mean(all_iou)), 3) if all_iou else None,
        "iou_median": round(float(np.median(all_iou)), 3) if all_iou else None,
        "iou_per_camera": {f"cam{c}": round(float(np.mean(v)), 3) for c, v in sorted(per_cam.items())},
        "matched_boxes": len(all_iou),
        "box_only_in_mvor": only_real,
        "box_only_in_twin": only_twin,
        "support_twin": dict(sorted(support_histogram(twin).items())),
        "support_mvor": dict(sorted(support_histogram(real_sub).items())),
        "visible_joints_in_box": round(inside / max(total, 1), 4),
        "box_only_clinician_boxes": {
            "twin": sum(map(len, only["twin"].values())),
            "mvor": sum(map(len, only["mvor"].values())),
            "mvor_boxes_matched_iou_0.5": round(float(np.mean(np.array(best) >= 0.5)), 3) if best else None,
        },
    }


def dataset_stats(ann: dict) -> dict:
    """Statistics comparable across datasets: people, boxes and their sizes, support shares."""
    frames = max(len(ann["multiview_images"]), 1)
    images = max(len(ann["images"]), 1)
    heights = np.array([a["bbox"][3] for a in ann["annotations"] if a["person_role"] == "clinician"])
    sup = Counter(pose_support(ann))
    n = max(sum(sup.values()), 1)
    return {
        "frames": frames,
        "3d_poses_per_frame": round(len(ann["annotations3D"]) / frames, 2),
        "boxes_per_image": round(len(ann["annotations"]) / images, 2),
        "clinician_box_height_px_q25_q50_q75": np.percentile(heights, [25, 50, 75]).round(0).tolist(),
        "support_share_1_2_3": [round(sup[k] / n, 3) for k in (1, 2, 3)],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--twin", required=True, help="folder written by python -m posenet.synth --from-mvor")
    default = Path(__file__).resolve().parents[1] / ".." / "shared" / "mvor" / "camma_mvor_2018.json"
    p.add_argument("--mvor", default=str(default), help="the real MVOR annotation file")
    p.add_argument(
        "--compare", nargs="*", default=[], help="other datasets (e.g. procedural): statistics only"
    )
    args = p.parse_args()
    twin = json.loads((Path(args.twin) / "annotations.json").read_text())
    real = json.loads(Path(args.mvor).read_text())
    out = fidelity(twin, real)
    cfg = Path(args.twin) / "synth_config.json"
    if cfg.is_file():
        out["render_summary"] = json.loads(cfg.read_text())["summary"]
    out["statistics"] = {"mvor": dataset_stats(real), "twin": dataset_stats(twin)}
    for other in args.compare:
        out["statistics"][other] = dataset_stats(json.loads((Path(other) / "annotations.json").read_text()))
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
