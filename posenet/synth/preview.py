"""A contact sheet of rendered views: colour with its boxes and keypoints beside the colour-mapped depth.

    python -m posenet.synth.preview --data /tmp/mvor_twin --frames 0 40 --out docs/img/synth_twin.png

Reads any MVOR-format dataset (rendered or real). Boxes are drawn in yellow with their person id; visible
keypoints as dots; depth in a jet colour map from 0.5 to 6 m, black where the sensor returned nothing.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import cv2
import numpy as np

from posenet.cli import add_data


def depth_colour(depth: np.ndarray, near: float = 500.0, far: float = 6000.0) -> np.ndarray:
    """(H, W, 3) BGR visualisation of uint16 mm depth (0 = unknown, drawn black)."""
    scaled = np.clip((depth.astype(np.float32) - near) / (far - near) * 255, 0, 255).astype(np.uint8)
    out = cv2.applyColorMap(scaled, cv2.COLORMAP_JET)
    out[depth == 0] = 0
    return out


def view_panel(root: Path, image: dict, annotations: list[dict]) -> np.ndarray:
    """(H, 2W, 3) BGR: the annotated colour image beside its depth image."""
    color = cv2.imread(str(root / image["file_name"]), cv2.IMREAD_COLOR)
    depth = cv2.imread(str(root / image["file_name"].replace("/color/", "/depth/")), cv2.IMREAD_UNCHANGED)
    if color is None or depth is None:
        raise FileNotFoundError(f"missing colour or depth image for {image['file_name']} under {root}")
    for a in annotations:
        x, y, w, h = (int(round(v)) for v in a["bbox"])
        cv2.rectangle(color, (x, y), (x + w, y + h), (0, 230, 255), 2)
        cv2.putText(
            color, str(a["person_id"]), (x + 3, y + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 230, 255), 2
        )
        kp = np.asarray(a["keypoints"]).reshape(-1, 3)
        for u, v, flag in kp:
            if flag == 2:
                cv2.circle(color, (int(round(u)), int(round(v))), 3, (60, 60, 255), -1)
    return np.concatenate([color, depth_colour(depth)], axis=1)


def contact_sheet(root: Path, frames: list[int], scale: float = 0.5) -> np.ndarray:
    """Rows of frames (multi-view indices), each row all its views side by side."""
    ann = json.loads((root / "annotations.json").read_text())
    by_image: dict[int, list[dict]] = {}
    for a in ann["annotations"]:
        by_image.setdefault(a["image_id"], []).append(a)
    rows = []
    for f in frames:
        if not 0 <= f < len(ann["multiview_images"]):
            raise ValueError(f"frame {f} out of range: the dataset has {len(ann['multiview_images'])} frames")
        mv = ann["multiview_images"][f]
        panels = [view_panel(root, im, by_image.get(im["id"], [])) for im in mv["images"]]
        rows.append(np.concatenate(panels, axis=1))
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows]
    sheet = np.concatenate(rows, axis=0)
    return cv2.resize(sheet, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_data(p)
    p.add_argument("--frames", type=int, nargs="+", default=[0], help="multi-view frame indices, one per row")
    p.add_argument("--scale", type=float, default=0.5, help="resize factor of the sheet")
    p.add_argument("--out", required=True, help="PNG to write")
    args = p.parse_args()
    sheet = contact_sheet(Path(args.data), args.frames, args.scale)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, sheet)
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]})")


if __name__ == "__main__":
    main()
