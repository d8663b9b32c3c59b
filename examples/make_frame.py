"""Export one multi-view frame of an MVOR-format dataset as a ready-to-post example for ``POST /scenes``.

    python examples/make_frame.py --data data/mvor_twin --image-ids 40010000012_40020000012_40030000012 \
        --out examples/frame

Writes ``color_V.jpg`` (JPEG, quality 90), ``depth_V.png`` (16-bit PNG, mm), ``scene.json`` (detector mode: cameras
only), ``scene_boxes.json`` (reference-box mode: the annotated boxes of the persons with a 3D pose, with their ids)
and ``truth.json`` (their 3D joints, mm, camera 0's frame). The shipped example is a day-4 frame of the MVOR twin:
day 4 is never used to train the shipped weights.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from posenet.data.mvor import MvorDataset, load_annotations


def camera_json(camera) -> dict:
    fx, fy, cx, cy = (round(float(x), 4) for x in camera.intrinsics)
    return {
        "fx": fx,
        "fy": fy,
        "cx": cx,
        "cy": cy,
        "distortion": None,
        "extrinsics": [[round(float(x), 6) for x in row] for row in camera.extrinsics],
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", required=True, help="dataset root (MVOR layout)")
    p.add_argument("--annotations", help="annotation json (default: DATA/annotations.json)")
    p.add_argument("--image-ids", required=True, help="the multi-view id of the frame to export")
    p.add_argument("--out", required=True, help="output folder")
    args = p.parse_args()

    annotations = load_annotations(args.annotations or Path(args.data) / "annotations.json")
    dataset = MvorDataset(args.data, annotations)
    index = [i for i in range(len(dataset)) if dataset.ids[i] == args.image_ids]
    if not index:
        raise SystemExit(f"no frame {args.image_ids!r} in {args.data}")
    sample = dataset[index[0]]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    posed = [int(p) for p in sample.person_ids]
    plain, boxed = [], []
    for v, view in enumerate(sample.views):
        cv2.imwrite(str(out / f"color_{v}.jpg"), view.color[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
        cv2.imwrite(str(out / f"depth_{v}.png"), view.depth)
        plain.append({"camera": camera_json(view.camera), "depth_scale_mm": 1.0})
        keep = [k for k, pid in enumerate(view.box_person_ids) if int(pid) in posed]
        boxed.append(
            {
                **plain[-1],
                "boxes": [[round(float(x), 1) for x in view.boxes[k]] for k in keep],
                "person_ids": [int(view.box_person_ids[k]) for k in keep],
            }
        )
    (out / "scene.json").write_text(json.dumps({"views": plain}, indent=1))
    (out / "scene_boxes.json").write_text(json.dumps({"views": boxed}, indent=1))
    truth = {
        "image_ids": sample.id,
        "person_ids": posed,
        "joints_mm": np.round(sample.poses.astype(float), 1).tolist(),
        "source": f"{args.data} (day {sample.day})",
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    print(f"wrote {out}: {len(sample.views)} views, persons {posed}")


if __name__ == "__main__":
    main()
