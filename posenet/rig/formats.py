"""Camera rigs in the formats users already have, read into a :class:`~posenet.rig.rigfile.Rig` and written back.

Each reader converts to ``posenet.cameras``'s conventions (mm, OpenCV axes, T(v->ref)) in the input's own world
frame and appends one report line per convention or unit it applied, with the evidence for it:

- ``mvor``: MVOR's ``cameras_info`` (a whole annotation file, or the block alone). Extrinsics are T(v->0) in mm;
  distortion is stored (k1, k2, k3, p1, p2) and MVOR's own 3D annotations ignore it, so it is dropped unless
  ``distortion="keep"``. The world frame is the room frame of ``firstCamToRoomRef`` (T(cam0->room)).
- ``opencv-yaml``: OpenCV FileStorage YAML as EasyMocap writes it: ``intri.yml`` (``names``, ``K_<name>``,
  ``dist_<name>`` in OpenCV order, optional ``H_<name>`` / ``W_<name>``) and ``extri.yml`` (``R_<name>`` a
  rotation vector or ``Rot_<name>`` a matrix, ``T_<name>`` in metres, ``x_cam = R x_world + T``).
- ``4d-or``: 4D-OR's ``camera0N.json`` (``value0.color_parameters``: ``fov_x`` / ``fov_y`` hold fx / fy in
  pixels, ``c_x``, ``c_y``, ``width``, ``height``; ``camera_pose``: T(depth camera -> world), metres, quaternion
  x, y, z, w; ``color2depth_transform``: T(colour -> depth camera)). 4D-OR's camera frames have y up and z
  backwards (its loaders flip y and z after ``inv(camera_pose @ color2depth)``), so the OpenCV colour camera is
  ``camera_pose @ color2depth @ diag(1, -1, -1, 1)``. Its loaders project without distortion; so does this.
- ``json``: one plain JSON file per camera: ``fx fy cx cy`` (or ``K`` 3x3), optional ``distortion`` (OpenCV
  order), ``image_size`` [w, h], ``unit`` ("mm", "cm" or "m"), and exactly one of ``camera_to_world`` or
  ``world_to_camera`` (4x4): the direction is never guessed.

Writers take a rig in whatever frame it is and write that frame as the format's world (MVOR: re-based on camera
0, with the rig's frame as ``firstCamToRoomRef`` when it is not camera 0's).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import torch
from scipy.spatial.transform import Rotation

from posenet.cameras import Camera, is_rigid, rigid_inverse
from posenet.rig.geometry import UNITS_MM, check_direction, check_unit
from posenet.rig.rigfile import Rig

FORMATS = ("mvor", "opencv-yaml", "4d-or", "json", "rig")
# 4D-OR's camera frames (y up, z backwards) to OpenCV's (y down, z forward), and back: its own inverse.
GL_TO_CV = torch.diag(torch.tensor([1.0, -1.0, -1.0, 1.0], dtype=torch.float64))


def _T(R, t) -> torch.Tensor:
    T = torch.eye(4, dtype=torch.float64)
    T[:3, :3] = torch.as_tensor(np.asarray(R, np.float64).reshape(3, 3))
    T[:3, 3] = torch.as_tensor(np.asarray(t, np.float64).reshape(3))
    return T


def _scaled(T: torch.Tensor, factor: float) -> torch.Tensor:
    out = T.clone()
    out[:3, 3] *= factor
    return out


def _check_rigid(T: torch.Tensor, where: str) -> None:
    if not bool(is_rigid(T, atol=1e-6)):
        R = T[:3, :3]
        raise ValueError(
            f"{where} is not a rigid transform: |R R^T - I| = {float((R @ R.T - torch.eye(3, dtype=R.dtype)).abs().max()):.2e}, "
            f"det R = {float(torch.linalg.det(R)):.6f}, last row {T[3].tolist()}"
        )


def _finish(rig: Rig, source: str, meaning: str, unit: str, declared: bool) -> Rig:
    """The unit and direction checks every reader ends with."""
    rig.report.append(check_unit(rig.cameras, unit, source, declared))
    rig.report.append(check_direction(rig.cameras, source, meaning))
    return rig


# ----------------------------------------------------------------------------------------------- mvor
def read_mvor(path: Path, distortion: str = "drop", unit: str | None = None) -> Rig:
    data = json.loads(Path(path).read_text())
    info = data.get("cameras_info", data)
    params = info.get("camParams", info)
    if "intrinsics" not in params or "extrinsics" not in params:
        raise ValueError(f"{path}: no MVOR cameras_info.camParams (intrinsics + extrinsics) in this file")
    keep = distortion == "keep"
    cameras = Camera.from_mvor({"camParams": params}, use_distortion=keep)
    factor = UNITS_MM[unit or "mm"]
    cameras = [Camera(c.intrinsics, _scaled(c.extrinsics, factor), c.distortion, c.size) for c in cameras]
    for i, c in enumerate(cameras):
        _check_rigid(c.extrinsics, f"{path.name}: camParams.extrinsics[{i}]")
    names = [str(s) for s in params.get("ids") or [f"cam{i + 1}" for i in range(len(cameras))]]
    to_room = None
    if params.get("firstCamToRoomRef") is not None:
        to_room = _scaled(
            torch.tensor(params["firstCamToRoomRef"], dtype=torch.float64).reshape(4, 4), factor
        )
    rig = Rig(cameras, names, "camera 0", to_room=to_room)
    has_dist = any(i.get("distortion") for i in params["intrinsics"])
    rig.report.append(
        f"{path.name}: MVOR cameras_info, {len(cameras)} cameras; extrinsics are T(v->0) (MVOR's convention)"
        + ("; room frame from firstCamToRoomRef" if to_room is not None else "")
    )
    rig.report.append(
        f"{path.name}: distortion "
        + ("kept, reordered from MVOR's (k1, k2, k3, p1, p2) to OpenCV's (k1, k2, p1, p2, k3)" if keep
           else "dropped (MVOR's 3D annotations were made without it; --distortion keep to keep it)"
           if has_dist else "none in the file")
    )  # fmt: skip
    return _finish(rig, path.name, "T(v->0)", unit or "mm", unit is not None)


def write_mvor(rig: Rig, path: Path) -> None:
    """MVOR's ``cameras_info`` block (``{"cameras_info": {...}}``), re-based on camera 0."""
    first = rig.to_first_camera()
    intrinsics = []
    for name, c in zip(first.names, first.cameras, strict=True):
        fx, fy, cx, cy = (float(x) for x in c.intrinsics)
        entry = {"serialnumber": name, "skew_value": 0, "focallength": [fx, fy], "principalpoint": [cx, cy],
                 "imagesize": None if c.size is None else list(c.size)}  # fmt: skip
        if c.distortion is not None:
            k1, k2, p1, p2, k3 = (float(x) for x in c.distortion)
            entry["distortion"] = [k1, k2, k3, p1, p2]
        intrinsics.append(entry)
    params = {
        "intrinsics": intrinsics,
        "extrinsics": [c.extrinsics.reshape(-1).tolist() for c in first.cameras],
        "ids": list(first.names),
    }
    room = first.to_room
    if room is None and not rig.first_is_reference:  # the rig's own frame becomes MVOR's room frame
        room = rig.cameras[0].extrinsics
    if room is not None:
        params["firstCamToRoomRef"] = room.reshape(-1).tolist()
    Path(path).write_text(json.dumps({"cameras_info": {"camParams": params}}, indent=1) + "\n")


# ----------------------------------------------------------------------------------------------- opencv yaml
def _yaml_names(fs: cv2.FileStorage, path: Path) -> list[str]:
    node = fs.getNode("names")
    if node.empty():
        raise ValueError(f"{path}: no 'names' list (EasyMocap's intri.yml/extri.yml start with one)")
    return [node.at(i).string() or str(int(node.at(i).real())) for i in range(node.size())]


def _mat(fs: cv2.FileStorage, key: str) -> np.ndarray | None:
    node = fs.getNode(key)
    return None if node.empty() else np.asarray(node.mat(), np.float64)


def read_opencv_yaml(intri: Path, extri: Path, distortion: str = "keep", unit: str | None = None) -> Rig:
    fi, fe = (
        cv2.FileStorage(str(intri), cv2.FILE_STORAGE_READ),
        cv2.FileStorage(str(extri), cv2.FILE_STORAGE_READ),
    )
    if not fi.isOpened() or not fe.isOpened():
        raise FileNotFoundError(f"cannot open {intri if not fi.isOpened() else extri} as OpenCV YAML")
    names = _yaml_names(fi, intri)
    ext_names = _yaml_names(fe, extri)
    if set(names) != set(ext_names):
        raise ValueError(
            f"{intri.name} names {names} but {extri.name} names {ext_names}: they must describe the same cameras"
        )
    factor = UNITS_MM[unit or "m"]
    cameras, rot_sources = [], set()
    for name in names:
        K = _mat(fi, f"K_{name}")
        if K is None or K.shape != (3, 3):
            raise ValueError(f"{intri.name}: K_{name} is missing or not 3x3")
        if abs(K[0, 1]) > 1e-9 * K[0, 0]:
            raise ValueError(f"{intri.name}: K_{name} has skew {K[0, 1]}; the camera model has none")
        dist = _mat(fi, f"dist_{name}")
        D = None
        if dist is not None and distortion == "keep":
            flat = dist.reshape(-1)
            if flat.size > 5 and np.abs(flat[5:]).max() > 0:
                raise ValueError(
                    f"{intri.name}: dist_{name} has {flat.size} non-zero terms; only (k1, k2, p1, p2, k3) are supported"
                )
            D = np.zeros(5)
            D[: min(5, flat.size)] = flat[:5]
            D = None if not np.any(D) else D
        H, W = fi.getNode(f"H_{name}"), fi.getNode(f"W_{name}")
        size = None if H.empty() or W.empty() else (int(W.real()), int(H.real()))
        Rot, rvec, t = _mat(fe, f"Rot_{name}"), _mat(fe, f"R_{name}"), _mat(fe, f"T_{name}")
        if t is None or (Rot is None and rvec is None):
            raise ValueError(f"{extri.name}: camera {name!r} needs T_{name} and R_{name} or Rot_{name}")
        if (
            Rot is not None
            and rvec is not None
            and np.abs(cv2.Rodrigues(rvec.reshape(3))[0] - Rot).max() > 1e-6
        ):
            raise ValueError(f"{extri.name}: R_{name} (rotation vector) and Rot_{name} (matrix) disagree")
        R = Rot if Rot is not None else cv2.Rodrigues(rvec.reshape(3))[0]
        rot_sources.add("Rot_ (matrix)" if Rot is not None else "R_ (rotation vector)")
        world_to_cam = _T(R, t.reshape(3) * factor)
        _check_rigid(world_to_cam, f"{extri.name}: [Rot_{name} | T_{name}]")
        cameras.append(
            Camera.create(K[0, 0], K[1, 1], K[0, 2], K[1, 2], rigid_inverse(world_to_cam), D, size)
        )
    rig = Rig(cameras, names, "world (EasyMocap)")
    rig.report.append(
        f"{extri.name}: x_cam = R x_world + T (EasyMocap), rotations from {', '.join(sorted(rot_sources))}; "
        f"distortion {'kept (OpenCV order)' if distortion == 'keep' else 'dropped'}"
        + ("" if all(c.size for c in cameras) else "; no H_/W_ entries, so image sizes are unknown")
    )
    return _finish(rig, extri.name, "T(cam->world) = [R | T]^-1", unit or "m", unit is not None)


def write_opencv_yaml(rig: Rig, folder: Path) -> list[Path]:
    """``folder/intri.yml`` and ``folder/extri.yml`` (EasyMocap), the rig's frame as world, T in metres."""
    folder.mkdir(parents=True, exist_ok=True)
    intri, extri = folder / "intri.yml", folder / "extri.yml"
    fi, fe = (
        cv2.FileStorage(str(intri), cv2.FILE_STORAGE_WRITE),
        cv2.FileStorage(str(extri), cv2.FILE_STORAGE_WRITE),
    )
    for fs in (fi, fe):
        fs.startWriteStruct("names", cv2.FileNode_SEQ)
        for name in rig.names:
            fs.write("", name)
        fs.endWriteStruct()
    for name, c in zip(rig.names, rig.cameras, strict=True):
        fi.write(f"K_{name}", c.K.numpy())
        dist = np.zeros((1, 5)) if c.distortion is None else c.distortion.numpy().reshape(1, 5)
        fi.write(f"dist_{name}", dist)
        if c.size is not None:
            fi.write(f"H_{name}", int(c.size[1]))
            fi.write(f"W_{name}", int(c.size[0]))
        to_cam = c.ref_to_camera.numpy()
        R, t = to_cam[:3, :3], to_cam[:3, 3:] / 1000.0
        fe.write(f"R_{name}", cv2.Rodrigues(R)[0])
        fe.write(f"Rot_{name}", R)
        fe.write(f"T_{name}", t)
    fi.release()
    fe.release()
    return [intri, extri]


# ----------------------------------------------------------------------------------------------- 4D-OR
def _pose(entry: dict, where: str) -> torch.Tensor:
    t, q = entry["translation"], entry["rotation"]
    R = Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]]).as_matrix()
    T = _T(R, [t["m00"], t["m10"], t["m20"]])
    _check_rigid(T, where)
    return T


def read_4dor(paths: list[Path], distortion: str = "drop", unit: str | None = None) -> Rig:
    factor = UNITS_MM[unit or "m"]
    cameras, names, fx_notes, dist_notes, baselines = [], [], [], [], []
    for path in paths:
        value = json.loads(path.read_text())["value0"]
        cp = value["color_parameters"]
        fx, fy, cx, cy = (float(cp[k]) for k in ("fov_x", "fov_y", "c_x", "c_y"))
        K = cp.get("intrinsics_matrix")
        if K is not None and (abs(K["m00"] - fx) > 1e-6 * fx or abs(K["m20"] - cx) > 1e-3):
            fx_notes.append(
                f"{path.name}: intrinsics_matrix (fx {K['m00']}, cx {K['m20']}) differs from fov_x/c_x; used fov_x/c_x as 4D-OR's loaders do"
            )
        radial = [float(v) for v in (cp.get("radial_distortion") or {}).values()]
        tangential = [float(v) for v in (cp.get("tangential_distortion") or {}).values()]
        D = None
        if any(radial + tangential):
            dist_notes.append(path.name)
            if distortion == "keep":
                if any(radial[3:]):
                    raise ValueError(
                        f"{path.name}: radial terms k4..k6 are non-zero (rational model), not supported"
                    )
                r = (radial + [0.0] * 3)[:3]
                p = (tangential + [0.0] * 2)[:2]
                D = [r[0], r[1], p[0], p[1], r[2]]
        depth_to_world = _scaled(_pose(value["camera_pose"], f"{path.name}: camera_pose"), factor)
        color_to_depth = _scaled(
            _pose(value["color2depth_transform"], f"{path.name}: color2depth_transform"), factor
        )
        size = (int(cp["width"]), int(cp["height"])) if "width" in cp and "height" in cp else None
        cameras.append(Camera.create(fx, fy, cx, cy, depth_to_world @ color_to_depth @ GL_TO_CV, D, size))
        baselines.append(float(color_to_depth[:3, 3].norm()))
        names.append(path.stem)
    rig = Rig(cameras, names, "world (4D-OR)")
    rig.report += fx_notes
    rig.report.append(
        f"4D-OR: colour camera = camera_pose (T(depth->world)) @ color2depth_transform @ diag(1, -1, -1) "
        f"(4D-OR's frames are y up, z back); {len(paths)} cameras"
    )
    # A second unit check: an Azure Kinect's colour camera sits about 32 mm from its depth camera.
    lo, hi = min(baselines), max(baselines)
    if hi == 0:
        rig.report.append(
            "4D-OR: color2depth_transform is the identity in every file (colour = depth camera)"
        )
    else:
        plausible = 5 <= lo and hi <= 100
        rig.report.append(
            f"4D-OR: colour-to-depth offsets {lo:.1f} to {hi:.1f} mm with translations read as {unit or 'm'}"
            + (
                " (plausible for a Kinect: about 32 mm)"
                if plausible
                else " (a Kinect's is about 32 mm: check the unit)"
            )
        )
    if dist_notes:
        rig.report.append(
            f"4D-OR: distortion in {', '.join(dist_notes)} "
            + (
                "kept as (k1, k2, p1, p2, k3)"
                if distortion == "keep"
                else "dropped, as 4D-OR's own loaders project without it"
            )
        )
    return _finish(rig, "4D-OR camera_pose", "T(colour->world)", unit or "m", unit is not None)


def write_4dor(rig: Rig, folder: Path) -> list[Path]:
    """``folder/camera0N.json`` in 4D-OR's layout (colour = depth camera: ``color2depth_transform`` = identity)."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    identity = {
        "translation": {"m00": 0.0, "m10": 0.0, "m20": 0.0},
        "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
    }
    for i, c in enumerate(rig.cameras):
        T = (c.extrinsics @ GL_TO_CV).numpy()
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        fx, fy, cx, cy = (float(v) for v in c.intrinsics)
        d = [0.0] * 5 if c.distortion is None else [float(v) for v in c.distortion]
        cp = {"fov_x": fx, "fov_y": fy, "c_x": cx, "c_y": cy,
              "intrinsics_matrix": {"m00": fx, "m10": 0.0, "m20": cx, "m01": 0.0, "m11": fy, "m21": cy,
                                    "m02": 0.0, "m12": 0.0, "m22": 1.0},
              "radial_distortion": {f"m{k}0": v for k, v in enumerate([d[0], d[1], d[4], 0.0, 0.0, 0.0])},
              "tangential_distortion": {"m00": d[2], "m10": d[3]}}  # fmt: skip
        if c.size is not None:
            cp["width"], cp["height"] = int(c.size[0]), int(c.size[1])
        pose = {"translation": {"m00": T[0, 3] / 1000, "m10": T[1, 3] / 1000, "m20": T[2, 3] / 1000},
                "rotation": {"x": x, "y": y, "z": z, "w": w}}  # fmt: skip
        path = folder / f"camera{i + 1:02d}.json"
        path.write_text(json.dumps({"value0": {"color_parameters": cp, "camera_pose": pose,
                                               "color2depth_transform": identity}}, indent=1))  # fmt: skip
        out.append(path)
    return out


# ----------------------------------------------------------------------------------------------- plain json
def read_json_cameras(paths: list[Path], distortion: str = "keep", unit: str | None = None) -> Rig:
    cameras, names, units = [], [], set()
    for path in paths:
        e = json.loads(path.read_text())
        if "K" in e:
            K = np.asarray(e["K"], np.float64).reshape(3, 3)
            fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        else:
            fx, fy, cx, cy = (float(e[k]) for k in ("fx", "fy", "cx", "cy"))
        file_unit = e.get("unit")
        if unit is None and file_unit is None:
            raise ValueError(
                f"{path.name}: no 'unit' (mm, cm or m) in the file and no --unit given; the unit is never guessed"
            )
        if unit is not None and file_unit is not None and unit != file_unit:
            raise ValueError(f"{path.name} says unit {file_unit!r} but --unit {unit} was given")
        u = unit or file_unit
        if u not in UNITS_MM:
            raise ValueError(f"{path.name}: unknown unit {u!r}; use one of {list(UNITS_MM)}")
        units.add(u)
        keys = [k for k in ("camera_to_world", "world_to_camera") if k in e]
        if len(keys) != 1:
            raise ValueError(
                f"{path.name}: give exactly one of 'camera_to_world' or 'world_to_camera' (4x4), found {keys}"
            )
        T = _scaled(torch.tensor(e[keys[0]], dtype=torch.float64).reshape(4, 4), UNITS_MM[u])
        _check_rigid(T, f"{path.name}: {keys[0]}")
        if keys[0] == "world_to_camera":
            T = rigid_inverse(T)
        D = e.get("distortion") if distortion == "keep" else None
        size = tuple(e["image_size"]) if e.get("image_size") else None
        cameras.append(Camera.create(fx, fy, cx, cy, T, D, size))
        names.append(str(e.get("name", path.stem)))
    rig = Rig(cameras, names, "world (json)")
    rig.report.append(
        f"json: {len(paths)} camera files, unit {'/'.join(sorted(units))}, direction as each file names it"
    )
    return _finish(rig, "json", "T(cam->world)", units.pop() if len(units) == 1 else "mm", True)


def write_json_cameras(rig: Rig, folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    for name, c in zip(rig.names, rig.cameras, strict=True):
        fx, fy, cx, cy = (float(v) for v in c.intrinsics)
        entry = {"name": name, "fx": fx, "fy": fy, "cx": cx, "cy": cy, "unit": "mm",
                 "distortion": None if c.distortion is None else c.distortion.tolist(),
                 "image_size": None if c.size is None else list(c.size),
                 "camera_to_world": c.extrinsics.tolist()}  # fmt: skip
        path = folder / f"{re.sub(r'[^A-Za-z0-9_.-]', '_', name)}.json"
        path.write_text(json.dumps(entry, indent=1) + "\n")
        out.append(path)
    return out
