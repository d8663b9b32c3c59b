"""Rig import/export (``python -m posenet.rig``): round trips through every format, projections with converted rigs,
the unit and direction checks, the service schema, the sanity checks, the picture and the depth agreement."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch
from conftest import MVOR_CAMERAS_INFO

from posenet.cameras import Camera, rigid_inverse
from posenet.rig import formats
from posenet.rig.__main__ import main, read_rig
from posenet.rig.check import (
    camera_agreement,
    depth_agreement,
    depth_checks,
    floor_of_frame,
    median_depth,
    sanity_checks,
)
from posenet.rig.geometry import check_direction
from posenet.rig.rigfile import Rig, read_rig_json, rig_difference
from service.schemas import CameraIn


@pytest.fixture
def mvor_file(tmp_path):
    path = tmp_path / "mvor.json"
    path.write_text(json.dumps({"cameras_info": MVOR_CAMERAS_INFO}))
    return path


def _convert(*args) -> None:
    assert main(["convert", *map(str, args)]) == 0


@pytest.mark.parametrize("distortion", ["keep", "drop"])
def test_mvor_yaml_rigjson_mvor_round_trip(mvor_file, tmp_path, distortion):
    # MVOR -> rig.json -> EasyMocap YAML -> rig.json -> MVOR reproduces MVOR's cameras.
    _convert("--from", "mvor", mvor_file, "--out", tmp_path / "a.json", "--distortion", distortion)
    _convert("--to", "opencv-yaml", tmp_path / "a.json", "--out", tmp_path / "yaml")
    _convert(
        "--from",
        "opencv-yaml",
        tmp_path / "yaml/intri.yml",
        tmp_path / "yaml/extri.yml",
        "--out",
        tmp_path / "b.json",
    )
    _convert("--to", "mvor", tmp_path / "b.json", "--out", tmp_path / "back.json")
    original = formats.read_mvor(mvor_file, distortion)
    back = formats.read_mvor(tmp_path / "back.json", distortion)
    assert rig_difference(back, original) <= 1e-6
    assert rig_difference(read_rig_json(tmp_path / "b.json"), read_rig_json(tmp_path / "a.json")) <= 1e-6
    if distortion == "keep":  # MVOR's (k1, k2, k3, p1, p2) order survives the trip
        stored = json.loads((tmp_path / "back.json").read_text())["cameras_info"]["camParams"]["intrinsics"]
        for got, want in zip(stored, MVOR_CAMERAS_INFO["camParams"]["intrinsics"], strict=True):
            np.testing.assert_allclose(got["distortion"], want["distortion"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("fmt", ["opencv-yaml", "4d-or", "json", "mvor"])
def test_every_format_round_trips_in_the_world_frame(mvor_file, tmp_path, fmt):
    rig = formats.read_mvor(
        mvor_file, "keep" if fmt in ("opencv-yaml", "json", "mvor") else "drop"
    ).to_room_frame()
    out = tmp_path / ("rig_mvor.json" if fmt == "mvor" else fmt)
    from posenet.rig.__main__ import write_rig

    written = write_rig(rig, fmt, out)
    back = read_rig(fmt, written if fmt != "opencv-yaml" else written, None if fmt != "mvor" else "keep")
    if fmt == "mvor":  # MVOR re-bases on camera 0 and keeps the room frame as firstCamToRoomRef
        back = back.to_room_frame()
    assert rig_difference(back, rig) <= 1e-6


def _projection_parity(gt: dict, path, tmp_path) -> None:
    """MVOR's 3D joints projected with rigs converted from ``path`` land where ``Camera.from_mvor`` puts them."""
    _convert("--from", "mvor", path, "--out", tmp_path / "rig.json")
    _convert("--to", "opencv-yaml", tmp_path / "rig.json", "--out", tmp_path / "yaml")
    _convert("--to", "4d-or", tmp_path / "rig.json", "--out", tmp_path / "4dor")
    original = Camera.stack(Camera.from_mvor(gt["cameras_info"]))
    joints = torch.as_tensor(
        np.array([np.asarray(p["keypoints3D"]).reshape(-1, 4)[:10, :3] for p in gt["annotations3D"]])
    ).reshape(-1, 3)  # (N, 3) camera-0 frame, mm
    want = original.project(joints.expand(3, -1, -1))  # (V, N, 2)
    for fmt, inputs in (
        ("opencv-yaml", [tmp_path / "yaml"]),
        ("4d-or", [tmp_path / "4dor"]),
        ("rig", [tmp_path / "rig.json"]),
    ):
        rig = read_rig(fmt, inputs).to_first_camera()
        got = rig.stacked.project(joints.expand(3, -1, -1))
        assert float((got - want).abs().max()) < 1e-6, fmt


def test_converted_rig_projects_mvor_joints_where_the_original_does(mvor_annotations, tmp_path, mvor_json):
    _projection_parity(mvor_annotations, mvor_json, tmp_path)  # the real file's 1,061 poses


def test_converted_rig_projects_tiny_mvor_joints_where_the_original_does(tiny_mvor_dataset, tmp_path):
    _projection_parity(
        tiny_mvor_dataset.gt, tiny_mvor_dataset.annotations, tmp_path
    )  # runs without the real file


def test_rig_json_is_what_post_scenes_takes(mvor_file, tmp_path):
    _convert("--from", "mvor", mvor_file, "--out", tmp_path / "rig.json")
    entries = json.loads((tmp_path / "rig.json").read_text())
    assert len(entries) == 3
    for entry in entries:
        CameraIn.model_validate(entry)  # extra="forbid": exactly the schema's fields
    assert entries[0]["extrinsics"] == np.eye(4).tolist() and entries[0]["distortion"] is None
    np.testing.assert_allclose(
        np.array(entries[2]["extrinsics"]).ravel(), MVOR_CAMERAS_INFO["camParams"]["extrinsics"][2]
    )


def test_ref_world_keeps_mvor_room_frame(mvor_file, tmp_path):
    _convert("--from", "mvor", mvor_file, "--out", tmp_path / "room.json", "--ref", "world")
    rig = read_rig_json(tmp_path / "room.json")
    room = torch.tensor(MVOR_CAMERAS_INFO["camParams"]["firstCamToRoomRef"], dtype=torch.float64).reshape(
        4, 4
    )
    torch.testing.assert_close(rig.cameras[0].extrinsics, room)
    assert not rig.first_is_reference
    torch.testing.assert_close(rig.to_first_camera().cameras[2].extrinsics,
                               torch.tensor(MVOR_CAMERAS_INFO["camParams"]["extrinsics"][2], dtype=torch.float64).reshape(4, 4))  # fmt: skip


def test_units_are_checked_not_guessed(mvor_file, tmp_path, capsys):
    rig = formats.read_mvor(mvor_file)
    formats.write_opencv_yaml(rig, tmp_path / "yaml")
    # Read the metre file as if it were mm: the spacing is implausible and the error names the right unit.
    with pytest.raises(ValueError, match=r"3\.42 mm apart.*read as m they would be 3\.42 m apart.*--unit m"):
        formats.read_opencv_yaml(tmp_path / "yaml/intri.yml", tmp_path / "yaml/extri.yml", unit="mm")
    # A plain json file without a unit is refused; with one, the report says what was read.
    cam = {"fx": 500, "fy": 500, "cx": 319.5, "cy": 239.5, "camera_to_world": np.eye(4).tolist()}
    (tmp_path / "a.json").write_text(json.dumps(cam))
    with pytest.raises(ValueError, match="no 'unit'.*never guessed"):
        formats.read_json_cameras([tmp_path / "a.json"])
    assert (
        main(
            [
                "convert",
                "--from",
                "opencv-yaml",
                str(tmp_path / "yaml"),
                "--out",
                str(tmp_path / "r.json"),
                "--unit",
                "mm",
            ]
        )
        == 2
    )
    assert "--unit m" in capsys.readouterr().err


def test_inverted_transforms_are_reported(mvor_file, tmp_path):
    rig = formats.read_mvor(mvor_file)
    for c, name in zip(rig.to_room_frame().cameras, ("a", "b", "c"), strict=True):
        # world_to_camera matrices written under the camera_to_world key: the wrong direction.
        entry = {"fx": float(c.fx), "fy": float(c.fy), "cx": float(c.cx), "cy": float(c.cy), "unit": "mm",
                 "image_size": [640, 480], "camera_to_world": rigid_inverse(c.extrinsics).tolist()}  # fmt: skip
        (tmp_path / f"{name}.json").write_text(json.dumps(entry))
    wrong = formats.read_json_cameras(sorted(tmp_path.glob("?.json")))
    assert any("WARNING" in line and "inverse" in line for line in wrong.report)
    assert any("consistent" in line for line in rig.report)
    right = rig.to_room_frame()
    assert "WARNING" not in check_direction(right.cameras, "room", "T(v->room)")


def test_4dor_camera_files_follow_4dor_loaders(tmp_path):
    # 4D-OR's own loader math, re-done here in numpy: world (m) -> inv(camera_pose @ color2depth) -> flip y, z.
    from tiny_or4d import write_camera_json

    rng = np.random.default_rng(1)
    paths, poses = [], []
    for i in range(3):
        pose, c2d = write_camera_json(tmp_path / f"camera0{i + 1}.json", rng, index=i, n=3)
        paths.append(tmp_path / f"camera0{i + 1}.json")
        poses.append(pose @ c2d)
    rig = formats.read_4dor(paths)
    assert rig.frame == "world (4D-OR)"
    assert any("colour-to-depth offsets 32." in line and "plausible" in line for line in rig.report)
    points_m = rng.uniform(-1, 1, (20, 3)) + [0, 0, 0.9]
    for camera, E, path in zip(rig.cameras, poses, paths, strict=True):
        cp = json.loads(path.read_text())["value0"]["color_parameters"]
        cam = (np.linalg.inv(E) @ np.c_[points_m, np.ones(20)].T).T[:, :3] * [1, -1, -1]
        uv = np.c_[
            cam[:, 0] / cam[:, 2] * cp["fov_x"] + cp["c_x"], cam[:, 1] / cam[:, 2] * cp["fov_y"] + cp["c_y"]
        ]
        got = camera.project(torch.as_tensor(points_m * 1000))
        np.testing.assert_allclose(got.numpy(), uv, atol=1e-6)


# --------------------------------------------------------------------------- check
def test_sanity_checks_pass_mvor_and_catch_problems(mvor_file):
    rig = formats.read_mvor(mvor_file)
    assert all(level == "OK" for level, _ in sanity_checks(rig))
    bad_units = Rig(
        [Camera(c.intrinsics, _scaled(c.extrinsics, 1e-3), None, c.size) for c in rig.cameras], rig.names
    )
    assert any(level == "FAIL" and "units" in m for level, m in sanity_checks(bad_units))
    away = [rig.cameras[0], Camera(rig.cameras[1].intrinsics, rig.cameras[1].extrinsics @ torch.diag(
        torch.tensor([-1.0, 1, -1, 1], dtype=torch.float64)), None, (640, 480))]  # fmt: skip
    assert any(level != "OK" and "common volume" in m for level, m in sanity_checks(Rig(away, ["a", "b"])))
    odd = Camera.create(900, 500, 600, 240, size=(640, 480))
    problems = [m for level, m in sanity_checks(Rig([odd], ["x"])) if level != "OK"]
    assert any("fx / fy" in m for m in problems) and any("principal point" in m for m in problems)


def _scaled(T, f):
    T = T.clone()
    T[:3, 3] *= f
    return T


def _render_room(rig: Rig) -> list[np.ndarray]:
    """Depth images (uint16 mm) of a floor and two walls seen by the rig (ray-plane intersections)."""
    planes = [
        (np.array([0, 0, 1.0]), -1000.0),
        (np.array([1.0, 0, 0]), -4500.0),
        (np.array([0, 1.0, 0]), -4500.0),
    ]
    depths = []
    for c in rig.cameras:
        w, h = c.size
        v, u = np.mgrid[0:h, 0:w]
        xy = c.normalised(torch.as_tensor(np.stack([u, v], -1).reshape(-1, 2), dtype=torch.float64)).numpy()
        rays = np.c_[xy, np.ones(len(xy))] @ c.extrinsics[:3, :3].numpy().T  # per unit z, reference frame
        o = c.position.numpy()
        best = np.full(len(rays), np.inf)
        for n, d in planes:  # plane n . p = d
            t = (d - n @ o) / (rays @ n)
            best = np.where((t > 0) & (t < best), t, best)
        depths.append(np.where(np.isfinite(best), best, 0).reshape(h, w).astype(np.uint16))
    return depths


def test_depth_agreement_finds_a_miscalibrated_camera(mvor_file):
    rig = formats.read_mvor(mvor_file).to_room_frame()
    small = Rig([c.scale(0.25) for c in rig.cameras], rig.names)  # 160x120, fast
    depths = _render_room(small)
    good = depth_agreement(small, depths, stride=2)
    assert all(r["overlap"] > 0.05 and r["median_abs_mm"] < 15 and r["within"] > 0.8 for r in good)
    shift = torch.eye(4, dtype=torch.float64)
    shift[2, 3] = 150.0  # camera 2 believed 15 cm higher than it is (a shift along the floor would not show)
    moved = Rig([*small.cameras[:2], Camera(small.cameras[2].intrinsics, shift @ small.cameras[2].extrinsics, None,
                                            small.cameras[2].size)], small.names)  # fmt: skip
    pairs = depth_agreement(moved, depths, stride=2)
    bad = {r["pair"]: r for r in pairs}
    assert bad[(0, 1)]["median_abs_mm"] < 15
    assert bad[(0, 2)]["median_abs_mm"] > 30 and bad[(2, 0)]["within"] < 0.7
    per_camera = camera_agreement(pairs, 3)
    assert per_camera[2] == min(per_camera)  # the moved camera is the odd one out
    # every ordered pair once, in order; each pair's figures are those of the two views alone
    assert [r["pair"] for r in pairs] == [(0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1)]
    for i, j in ((0, 2), (2, 1)):
        alone = depth_agreement(Rig([moved.cameras[i], moved.cameras[j]], ["a", "b"]), [depths[i], depths[j]], 2)
        assert {**alone[0], "pair": (i, j)} == bad[(i, j)] and {**alone[1], "pair": (j, i)} == bad[(j, i)]
    blind = [depths[0], np.zeros_like(depths[1]), depths[2]]  # a view without valid depth: no points of its own
    pairs = {r["pair"]: r for r in depth_agreement(small, blind, stride=2)}
    assert list(pairs) == [(0, 1), (0, 2), (2, 0), (2, 1)] and pairs[0, 1]["overlap"] == pairs[2, 1]["overlap"] == 0


def test_median_depth_is_numpys_median_of_the_valid_pixels():
    rng = np.random.default_rng(0)
    for shape in ((1, 1), (2, 2), (3, 5), (48, 64)):
        for _ in range(20):
            d = rng.integers(0, 9000, shape).astype(np.uint16)
            d[rng.random(shape) < 0.3] = 0
            valid = d[d > 0]
            assert median_depth(d)[0] == (float(np.median(valid)) if valid.size else None)
    assert median_depth(np.zeros((4, 4), np.uint16)) == (None, False)
    assert median_depth(np.full((4, 4), 20_000, np.uint16)) == (20_000.0, False)  # beyond 15 m: not mm?


def test_floor_is_found_in_the_depth_frames(mvor_file):
    # In camera 0's frame, with only the cameras' image-up axes as a guess, the floor (room z = -1000) is recovered.
    room = formats.read_mvor(mvor_file).to_room_frame()
    small = Rig([c.scale(0.25) for c in room.cameras], room.names)
    depths = _render_room(small)
    first = small.to_first_camera()
    normal, height, share = floor_of_frame(first.cameras, depths, stride=2)
    room_z = small.cameras[0].extrinsics[:3, :3].T @ torch.tensor(
        [0, 0, 1.0], dtype=torch.float64
    )  # in camera 0
    assert float(normal @ room_z) > 0.9999 and share > 0.3
    camera_height = float(first.cameras[0].position @ normal) - height
    assert abs(camera_height - (float(small.cameras[0].position[2]) + 1000)) < 5


def test_check_cli_writes_the_picture(mvor_file, tmp_path, capsys):
    assert main(["check", str(mvor_file), "--format", "mvor", "--picture", str(tmp_path / "p.png")]) == 0
    out = capsys.readouterr().out
    assert "common volume" in out and "up: room frame z" in out
    assert (tmp_path / "p.png").stat().st_size > 10_000
    assert ">=3 views 5.4 m2" in out  # of the working plane, seen by all three MVOR cameras


def test_check_cli_with_depth_frames(mvor_file, tmp_path, capsys):
    from posenet.rig.rigfile import write_rig_json

    room = formats.read_mvor(mvor_file).to_room_frame()
    small = Rig([c.scale(0.25) for c in room.cameras], room.names)
    frames = []
    for v, d in enumerate(_render_room(small)):
        frames.append(tmp_path / f"d{v}.png")
        cv2.imwrite(str(frames[-1]), d)
    write_rig_json(small.to_first_camera(), tmp_path / "rig.json")
    argv = [
        "check",
        str(tmp_path / "rig.json"),
        "--picture",
        str(tmp_path / "p.png"),
        "--stride",
        "2",
        "--depth-frames",
    ]
    assert main(argv + [str(f) for f in frames]) == 0
    out = capsys.readouterr().out
    assert (
        "OK   floor:" in out
        and "up: floor fitted to the depth frames" in out
        and "per camera, mean within" in out
    )
    assert "OK   depth frame 2: median" in out
    levels = [
        level for level, _ in depth_checks([np.full((4, 4), 250, np.uint16), np.zeros((4, 4), np.uint16)])
    ]
    assert levels == ["WARN", "FAIL"]  # 2.5 m in cm units reads as 250 mm; an all-unknown frame
    inverse = Rig(
        [
            Camera(c.intrinsics, rigid_inverse(c.extrinsics), None, c.size)
            for c in small.to_first_camera().cameras
        ],
        small.names,
    )
    write_rig_json(inverse, tmp_path / "inverse.json")
    assert (
        main(["check", str(tmp_path / "inverse.json"), "--no-picture", *argv[2:]] + [str(f) for f in frames])
        == 1
    )
    assert "the rig file probably holds the inverse transforms" in capsys.readouterr().out
    assert main(argv + [str(frames[0])]) == 2  # one frame for three cameras is refused
    assert "1 depth frames for 3 cameras" in capsys.readouterr().err


def test_reads_yaml_as_easymocap_writes_it(tmp_path):
    # EasyMocap's own writer: %YAML:1.0, quoted names, rotation vectors only (no Rot_), no image sizes, T in metres.
    def mat(name, rows, cols, data):
        return f"{name}: !!opencv-matrix\n  rows: {rows}\n  cols: {cols}\n  dt: d\n  data: [{', '.join(map(str, data))}]\n"

    rvec = [0.1, -0.2, 0.05]
    R = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
    head = '%YAML:1.0\n---\nnames:\n  - "01"\n  - "02"\n'
    intri = head + "".join(
        mat(f"K_{n}", 3, 3, [1000, 0, 960, 0, 1001, 540, 0, 0, 1])
        + mat(f"dist_{n}", 1, 5, [0.01, -0.02, 0, 0, 0])
        for n in ("01", "02")
    )
    extri = head + mat("R_01", 3, 1, [0, 0, 0]) + mat("T_01", 3, 1, [0, 0, 0])
    extri += mat("R_02", 3, 1, rvec) + mat("T_02", 3, 1, [1.5, 0.0, 0.2])
    (tmp_path / "intri.yml").write_text(intri)
    (tmp_path / "extri.yml").write_text(extri)
    rig = read_rig("opencv-yaml", [tmp_path])
    assert rig.names == ["01", "02"] and rig.cameras[0].size is None
    assert any("R_ (rotation vector)" in line for line in rig.report)
    assert any("image sizes are unknown" in line for line in rig.report)
    # x_cam = R x_world + T (metres): camera 02's centre is -R^T T, in mm.
    np.testing.assert_allclose(
        rig.cameras[1].position.numpy(), -R.T @ np.array([1.5, 0.0, 0.2]) * 1000, atol=1e-9
    )
    np.testing.assert_allclose(rig.cameras[1].distortion.numpy(), [0.01, -0.02, 0, 0, 0])


def test_depth_agreement_tells_the_direction_where_geometry_cannot(mvor_file):
    # The inverse of a camera-referenced rig is itself a valid-looking rig (the direction check only reports);
    # depth frames decide: nearly every point agrees with the right direction, few with the inverse.
    room = formats.read_mvor(mvor_file).to_room_frame()
    small = Rig([c.scale(0.25) for c in room.cameras], room.names)
    depths = _render_room(small)
    first = small.to_first_camera()
    inverted = Rig(
        [Camera(c.intrinsics, rigid_inverse(c.extrinsics), None, c.size) for c in first.cameras], first.names
    )
    assert "WARNING" not in check_direction(inverted.cameras, "inverted", "T(v->0)")
    assert min(camera_agreement(depth_agreement(first, depths, stride=2), 3)) > 0.95
    assert max(camera_agreement(depth_agreement(inverted, depths, stride=2), 3)) < 0.3
