"""The 4D-OR reader (Özsoy et al., MICCAI 2022; layout and conversions from github.com/egeozsoy/4D-OR).

Layout, one folder per take (the recording unit, used as ``Sample.day`` for the folds)::

    ROOT/export_holistic_take<T>_processed/
        camera01.json ... camera06.json               calibration (read by posenet.rig.formats.read_4dor)
        colorimage/camera0<c>_colorimage-<idx>.jpg    colour, 2048x1536 in the real data
        depthimage/camera0<c>_depthimage-<idx>.tiff   16-bit depth aligned to colour, mm
        timestamp_to_pcd_and_frames_list.json         [[timestamp, {"color_1": idx, "depth_1": idx, ..., "pcd": idx}]]
        annotations/<pcd>.json                        {"labels": [{"humanName", "jointName", "point3d":
                                                        {"location": {"x", "y", "z"}}}, ...]}

Conversions (as 4D-OR's own loaders, ``helpers/utils.py`` and the VoxelPose dataset):
- a label's location is in the annotation tool's frame; 4D-OR's ``coord_transform_human_pose_tool_to_OR_4D``
  maps it to ``(25 x, 25 z + 1000, -25 y)`` in its point-cloud ("x500") space, which its loaders divide by 500
  to reach the cameras' world frame in metres. So a joint in mm is 2 x that (``X500_TO_MM``).
- cameras: ``posenet.rig.formats.read_4dor`` (colour camera = ``camera_pose @ color2depth_transform`` with y and
  z flipped into OpenCV's axes; no distortion, as 4D-OR's loaders). Everything is then moved to camera 0's frame,
  the project's reference frame.
- joints: 4D-OR's 14 named joints; the first ten are MVOR's ten in MVOR's order, and ``leftknee, rightknee,
  leftfoot, rightfoot`` are kept in :class:`Or4dSample`. ``humanName == "Patient"`` sets ``is_patient``.
- 4D-OR has no 2D person boxes. A view's box of a person is the box around the projections of its 3D joints
  (padded by ``BOX_PAD`` of its size, clipped to the image), given when at least ``MIN_JOINTS_IN_VIEW`` joints
  project inside the image; so ``support`` counts views by geometry, not by visibility (occlusion is unknown).
  The 2D keypoints are the joints' projections (flag 2 inside the image, else 0).

Training, prediction and evaluation read MVOR's layout; ``python -m posenet.data.or4d ROOT --export-mvor OUT``
writes ``OUT/annotations.json`` in MVOR's schema and links every image into ``OUT/take<T>/cam<c>/{color,depth}/``
(OpenCV decodes by content, so a ``.png`` link to a ``.jpg`` or ``.tiff`` reads as it is), after which
``posenet.training.train --data OUT``, ``posenet.evaluation.predict`` and ``posenet.evaluation.evaluate`` run unchanged.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import re
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch

from posenet.cameras import Camera, rigid_inverse, transform_points
from posenet.data.images import read_color, read_depth, subsample_color, subsample_depth
from posenet.data.mvor import MODALITIES, check_reader_options, subsampled_camera
from posenet.data.sample import Sample, View
from posenet.rig.formats import read_4dor
from posenet.skeleton import JOINTS, NUM_JOINTS

OR4D_JOINTS = (
    "head", "neck", "leftshoulder", "rightshoulder", "lefthip", "righthip", "leftelbow", "rightelbow",
    "leftwrist", "rightwrist", "leftknee", "rightknee", "leftfoot", "rightfoot",
)  # fmt: skip
EXTRA_JOINTS = OR4D_JOINTS[NUM_JOINTS:]
X500_TO_MM = 2.0  # 4D-OR's point-cloud space is metres x 500
BOX_PAD = 0.1
MIN_JOINTS_IN_VIEW = 4
TAKE_RE = re.compile(r"export_holistic_take(\d+)_processed$")
assert tuple(j.replace("_", "") for j in JOINTS) == OR4D_JOINTS[:NUM_JOINTS]


def tool_to_mm(points: np.ndarray) -> np.ndarray:
    """(..., 3) annotation-tool locations to 4D-OR's world frame in mm (see the module docstring)."""
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    return np.stack([25 * x, 25 * z + 1000, -25 * y], -1) * X500_TO_MM


@dataclasses.dataclass
class Or4dSample(Sample):
    """A :class:`Sample` plus what 4D-OR has beyond MVOR's ten joints.

    Attributes:
        extra_joints: (N, 4, 3) float32 knees and feet (``EXTRA_JOINTS``), mm, reference frame.
        extra_valid: (N, 4) bool.
        is_patient: (N,) bool, ``humanName == "Patient"``.
        human_names: N names (``Patient``, ``human_0``, ...), sorted; ``person_ids`` index them.
    """

    extra_joints: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4, 3), np.float32))
    extra_valid: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4), bool))
    is_patient: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0,), bool))
    human_names: list[str] = dataclasses.field(default_factory=list)


def read_labels(path: Path) -> tuple[list[str], np.ndarray, np.ndarray]:
    """One annotation file: sorted human names, (N, 14, 3) mm world joints, (N, 14) validity."""
    labels = json.loads(path.read_text()).get("labels", [])
    names = sorted({lab["humanName"] for lab in labels})
    joints = np.zeros((len(names), len(OR4D_JOINTS), 3))
    valid = np.zeros((len(names), len(OR4D_JOINTS)), bool)
    index = {j: k for k, j in enumerate(OR4D_JOINTS)}
    for lab in labels:
        k = index.get(lab["jointName"])
        if k is None:
            continue
        loc = lab["point3d"]["location"]
        n = names.index(lab["humanName"])
        joints[n, k] = tool_to_mm(np.array([loc["x"], loc["y"], loc["z"]], np.float64))
        valid[n, k] = True
    return names, joints, valid


@dataclasses.dataclass(frozen=True)
class _Frame:
    take: int
    folder: Path
    channels: dict  # color_<c> / depth_<c> / pcd -> file index string
    names: list
    joints: np.ndarray  # (N, 14, 3) float64, reference frame
    valid: np.ndarray  # (N, 14)


class Or4dDataset(torch.utils.data.Dataset):
    """4D-OR frames as :class:`Or4dSample`\\ s, in the same conventions as :class:`~posenet.data.mvor.MvorDataset`.

    Args:
        root: the folder holding ``export_holistic_take*_processed``.
        subsample: integer factor (cameras, boxes and 2D keypoints follow, as in the MVOR reader).
        modalities: a subset of ``("color", "depth")``; ``()`` reads no images.
        takes: the takes to keep (None: all found).
        cameras: the 1-based camera numbers to use, in view order (default: every ``camera0N.json``).
        annotated_only: keep only frames with an annotation file (False also yields unannotated frames).
    """

    def __init__(
        self,
        root: str | Path,
        subsample: int = 1,
        modalities: Sequence[str] = MODALITIES,
        takes: Iterable[int] | None = None,
        cameras: Sequence[int] | None = None,
        annotated_only: bool = True,
    ) -> None:
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"4D-OR root {self.root} is not a folder")
        self.subsample, self.modalities = check_reader_options(subsample, modalities)
        found = {int(TAKE_RE.match(p.name).group(1)): p for p in self.root.iterdir() if TAKE_RE.match(p.name)}
        if not found:
            raise FileNotFoundError(f"{self.root} holds no export_holistic_take<T>_processed folder")
        if takes is not None:
            missing = sorted(set(takes) - set(found))
            if missing:
                raise ValueError(f"takes {missing} are not in {self.root}; found takes {sorted(found)}")
            found = {t: found[t] for t in takes}
        self.cameras: dict[int, list[Camera]] = {}
        self.report: list[str] = []
        self._frames: list[_Frame] = []
        for take in sorted(found):
            self._index_take(take, found[take], cameras, annotated_only)
        self.days = sorted({f.take for f in self._frames})

    def _index_take(
        self, take: int, folder: Path, numbers: Sequence[int] | None, annotated_only: bool
    ) -> None:
        files = (
            sorted(folder.glob("camera0*.json"))
            if numbers is None
            else [folder / f"camera{n:02d}.json" for n in numbers]
        )
        if not files or not all(f.is_file() for f in files):
            raise FileNotFoundError(
                f"{folder}: camera files {[f.name for f in files if not f.is_file()] or 'camera0N.json'} missing"
            )
        rig = read_4dor(files)
        self.report += [f"take {take}: {line}" for line in rig.report]
        world_to_ref = rigid_inverse(rig.cameras[0].extrinsics)
        self.cameras[take] = [
            dataclasses.replace(c, extrinsics=world_to_ref @ c.extrinsics) for c in rig.cameras
        ]
        self._numbers = [int(f.stem[-2:]) for f in files]
        index = json.loads((folder / "timestamp_to_pcd_and_frames_list.json").read_text())
        for _, channels in index:
            ann = folder / "annotations" / f"{channels['pcd']}.json"
            if not ann.is_file():
                if annotated_only:
                    continue
                names, joints, valid = (
                    [],
                    np.zeros((0, len(OR4D_JOINTS), 3)),
                    np.zeros((0, len(OR4D_JOINTS)), bool),
                )
            else:
                names, joints, valid = read_labels(ann)
            ref = transform_points(world_to_ref, torch.as_tensor(joints)).numpy() if len(joints) else joints
            self._frames.append(_Frame(take, folder, channels, names, ref, valid))

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def ids(self) -> list[str]:
        return [f"take{f.take}_{f.channels['pcd']}" for f in self._frames]

    def _file(self, frame: _Frame, n: int, kind: str) -> Path:
        idx = frame.channels.get(f"{kind}_{n}", frame.channels.get(f"color_{n}"))
        ext = "jpg" if kind == "color" else "tiff"
        return frame.folder / f"{kind}image" / f"camera{n:02d}_{kind}image-{idx}.{ext}"

    def __getitem__(self, index: int) -> Or4dSample:
        frame = self._frames[index]
        n_persons = len(frame.names)
        boxed = np.zeros(n_persons, np.int64)
        views = []
        for v, (n, full) in enumerate(zip(self._numbers, self.cameras[frame.take], strict=True)):
            camera = subsampled_camera(full, self.subsample)
            color = depth = None
            color_path = self._file(frame, n, "color")
            if "color" in self.modalities:
                color = subsample_color(read_color(color_path, full.size), self.subsample)
            if "depth" in self.modalities:
                depth = subsample_depth(read_depth(self._file(frame, n, "depth"), full.size), self.subsample)
            boxes, ids, kps = self._project(camera, frame)
            boxed[ids] += 1
            views.append(View(color, depth, camera, boxes, ids, image_id=v, cam_index=v, keypoints2d=kps,
                              file_name=str(color_path.relative_to(self.root))))  # fmt: skip
        j = frame.joints.astype(np.float32)
        return Or4dSample(
            id=self.ids[index],
            day=frame.take,
            views=views,
            poses=j[:, :NUM_JOINTS].copy(),
            valid=frame.valid[:, :NUM_JOINTS].copy(),
            person_ids=np.arange(n_persons, dtype=np.int64),
            support=boxed,
            extra_joints=j[:, NUM_JOINTS:].copy(),
            extra_valid=frame.valid[:, NUM_JOINTS:].copy(),
            is_patient=np.array([name == "Patient" for name in frame.names], bool),
            human_names=list(frame.names),
        )

    @staticmethod
    def _project(camera: Camera, frame: _Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes (K, 4), person ids (K,) and 2D keypoints (K, 10, 3) from the 3D joints (module docstring)."""
        if not len(frame.names):
            return (
                np.zeros((0, 4), np.float32),
                np.zeros(0, np.int64),
                np.zeros((0, NUM_JOINTS, 3), np.float32),
            )
        w, h = camera.size
        points = torch.as_tensor(frame.joints)  # (N, 14, 3)
        uv = camera.project(points).numpy()  # (N, 14, 2)
        z = camera.to_camera(points)[..., 2].numpy()
        inside = (
            frame.valid & (z > 0) & (uv >= -0.5).all(-1) & (uv[..., 0] <= w - 0.5) & (uv[..., 1] <= h - 0.5)
        )
        boxes, ids, kps = [], [], []
        for p in np.flatnonzero(inside.sum(-1) >= MIN_JOINTS_IN_VIEW):
            lo, hi = uv[p][inside[p]].min(0), uv[p][inside[p]].max(0)
            pad = BOX_PAD * (hi - lo)
            box = np.concatenate([np.maximum(lo - pad, -0.5), np.minimum(hi + pad, [w - 0.5, h - 0.5])])
            k = np.zeros((NUM_JOINTS, 3), np.float32)
            seen = inside[p, :NUM_JOINTS]
            k[seen, :2], k[seen, 2] = uv[p, :NUM_JOINTS][seen], 2
            boxes.append(box)
            ids.append(p)
            kps.append(k)
        return (np.array(boxes, np.float32).reshape(-1, 4), np.array(ids, np.int64),
                np.array(kps, np.float32).reshape(-1, NUM_JOINTS, 3))  # fmt: skip

    # ----------------------------------------------------------------- MVOR-format export
    def to_mvor(self, out: str | Path, link: bool = True) -> dict:
        """Write ``out/annotations.json`` (MVOR schema) and link the images into MVOR's layout; returns the dict.

        MVOR's schema has one calibration, so every take must share the first take's cameras (to 1e-6).
        """
        from posenet.rig.formats import write_mvor
        from posenet.rig.rigfile import Rig

        out = Path(out)
        first = self.cameras[self.days[0]]
        for take, cams in self.cameras.items():
            diff = max(
                float((a.extrinsics - b.extrinsics).abs().max()) for a, b in zip(cams, first, strict=True)
            )
            if diff > 1e-3:
                raise ValueError(f"take {take}'s cameras differ from take {self.days[0]}'s by {diff:.3g} mm; "
                                 "MVOR's schema has one calibration: export the takes separately (takes=[...])")  # fmt: skip
        out.mkdir(parents=True, exist_ok=True)
        write_mvor(Rig(first, [f"camera{n:02d}" for n in self._numbers]), out / "cameras.json")
        cameras_info = json.loads((out / "cameras.json").read_text())["cameras_info"]
        (out / "cameras.json").unlink()
        gt = {"info": {"description": f"4D-OR {self.root} exported to MVOR's schema by posenet.data.or4d"},
              "categories": [{"id": "1", "name": "person", "keypoints": list(JOINTS)}],
              "cameras_info": cameras_info, "multiview_images": [], "images": [], "annotations": [],
              "annotations3D": []}  # fmt: skip
        (modalities, subsample), (self.modalities, self.subsample) = (
            (self.modalities, self.subsample),
            ((), 1),
        )
        try:
            for i, frame in enumerate(self._frames):
                sample = self[i]
                images = []
                for v, (view, n) in enumerate(zip(sample.views, self._numbers, strict=True)):
                    image_id = (frame.take * 100 + v + 1) * 10**7 + i
                    name = f"take{frame.take}/cam{v + 1}/color/{i:06d}.png"
                    images.append({"id": image_id, "file_name": name, "cam_id": v + 1, "day_id": frame.take,
                                   "width": view.width, "height": view.height})  # fmt: skip
                    for kind, src in (
                        ("color", self._file(frame, n, "color")),
                        ("depth", self._file(frame, n, "depth")),
                    ):
                        dst = out / f"take{frame.take}/cam{v + 1}/{kind}/{i:06d}.png"
                        dst.parent.mkdir(parents=True, exist_ok=True)
                        if link and not dst.exists():
                            dst.symlink_to(src.resolve())
                    for box, pid, kp in zip(view.boxes, view.box_person_ids, view.keypoints2d, strict=True):
                        x0, y0, x1, y1 = (float(b) for b in box)
                        gt["annotations"].append({"id": len(gt["annotations"]), "image_id": image_id, "category_id": "1",
                                                  "person_id": int(pid), "bbox": [x0, y0, x1 - x0, y1 - y0],
                                                  "keypoints": kp.ravel().tolist(), "only_bbox": 0})  # fmt: skip
                mv_id = "_".join(str(im["id"]) for im in images)
                gt["multiview_images"].append({"id": mv_id, "images": images})
                gt["images"] += images
                for p in range(len(sample.person_ids)):
                    pts = np.concatenate([sample.poses[p], 2.0 * sample.valid[p][:, None]], 1)
                    gt["annotations3D"].append({"id": str(len(gt["annotations3D"])), "image_ids": mv_id,
                                                "person_id": int(p), "ref_camera": 0,
                                                "keypoints3D": pts.ravel().tolist(),
                                                "is_patient": bool(sample.is_patient[p])})  # fmt: skip
        finally:
            self.modalities, self.subsample = modalities, subsample
        (out / "annotations.json").write_text(json.dumps(gt))
        return gt


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m posenet.data.or4d",
        description="Summarise a 4D-OR dataset or export it to MVOR's layout.",
    )
    p.add_argument("root", type=Path, help="folder holding export_holistic_take*_processed")
    p.add_argument("--takes", type=int, nargs="+", help="only these takes")
    p.add_argument(
        "--export-mvor", type=Path, help="write OUT/annotations.json and link the images in MVOR's layout"
    )
    args = p.parse_args(argv)
    ds = Or4dDataset(args.root, modalities=(), takes=args.takes)
    for line in ds.report:
        print(line)
    print(f"{len(ds)} annotated frames in takes {ds.days}, {len(ds.cameras[ds.days[0]])} cameras")
    if args.export_mvor:
        gt = ds.to_mvor(args.export_mvor)
        print(
            f"wrote {args.export_mvor / 'annotations.json'}: {len(gt['annotations3D'])} poses, {len(gt['annotations'])} boxes"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
