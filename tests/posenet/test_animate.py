"""posenet.viz.animate on a sequence rendered by posenet.synth --sequence (3 frames, 2 persons, 2 views).

The tracks are the client's ``--track`` lines built from the sequence's ground truth, with the person ids as
track ids (no service needed): the GIF must have a frame per line, and each track's colour where its skeleton
projects.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from PIL import Image, ImageSequence

from posenet.data.mvor import MvorDataset
from posenet.skeleton import BONES, JOINTS
from posenet.synth.__main__ import main as synth
from posenet.viz.animate import Floor, Layout, main, project, track_colour

FRAMES = 3
VIEW_WIDTH = 200


def tracked_line(sample, sequence: int, frame_index: int, timestamp_s: float, untracked=()) -> dict:
    """One line of ``service.client --track`` for ``sample``: its ground-truth persons, track id = person id."""
    persons = []
    for pid, pose in zip(sample.person_ids.tolist(), sample.poses, strict=True):
        joints = [{"name": n, "position": xyz.tolist(), "confidence": 0.9, "spread_mm": 30.0}
                  for n, xyz in zip(JOINTS, pose, strict=True)]  # fmt: skip
        boxes = [{"view": v, "box": box.tolist(), "score": None}
                 for v, box in enumerate(sample.person_boxes(pid)) if box is not None]  # fmt: skip
        persons.append({
            "id": pid, "joints": joints, "views": boxes,
            "track_id": None if pid in untracked else pid,
            "smoothed_joints": [{"name": j["name"], "position": j["position"]} for j in joints],
        })  # fmt: skip
    response = {"mode": "reference_boxes", "frame": sample.id, "notes": [], "persons": persons,
                "stream": {"id": "s", "frames": frame_index + 1, "timestamp_s": timestamp_s, "clock": "client"}}  # fmt: skip
    return {"id": sample.id, "day": sample.day, "sequence": sequence, "frame_index": frame_index,
            "timestamp_s": timestamp_s, "status": 200, "latency_ms": 1.0, "response": response}  # fmt: skip


@pytest.fixture(scope="module")
def sequence(tmp_path_factory):
    root = tmp_path_factory.mktemp("seq")
    synth(["--out", str(root), "--sequence", "--frames", str(FRAMES), "--persons", "2", "--views", "2",
           "--fps", "10", "--seed", "1", "--quiet"])  # fmt: skip
    ann = json.loads((root / "annotations.json").read_text())
    ds = MvorDataset(root, ann, modalities=("color",))
    samples = [ds[k] for k in range(len(ds))]
    mv = ann["multiview_images"]
    # the last frame's person 1 has no track (yet): it must be grey
    lines = [tracked_line(s, m["sequence"], m["frame_index"], m["timestamp_s"], (1,) if k == FRAMES - 1 else ())
             for k, (s, m) in enumerate(zip(samples, mv, strict=True))]  # fmt: skip
    tracks = root / "tracks.jsonl"
    tracks.write_text("".join(json.dumps(line) + "\n" for line in reversed(lines)))  # any order
    return root, tracks, samples, lines


def frames_of(gif) -> list[np.ndarray]:
    with Image.open(gif) as im:
        return [np.asarray(f.convert("RGB"), np.float64) for f in ImageSequence.Iterator(im)]


def rgb(colour) -> np.ndarray:
    return np.array(to_rgb(colour)) * 255


def nearest_pixel(image: np.ndarray, xy: np.ndarray, colour, radius: int = 2) -> np.ndarray:
    """The RGB (3,) of the pixel within ``radius`` of ``xy`` (x, y) whose colour is nearest to ``colour``."""
    x, y = np.round(xy).astype(int)
    patch = image[y - radius : y + radius + 1, x - radius : x + radius + 1].reshape(-1, 3)
    return patch[np.linalg.norm(patch - rgb(colour), axis=-1).argmin()]


def bone_middles(sample, lines_person, view: int, layout: Layout) -> np.ndarray:
    """GIF pixels (B', 2) of the middles of one person's bones that lie inside the image of ``view``."""
    uv, in_front = project(sample, np.array([[j["position"] for j in lines_person["smoothed_joints"]]]))
    ends = uv[0, view][np.array(BONES)]  # (B, 2, 2)
    middles = ends.mean(1)  # (B, 2)
    size = (sample.views[view].width, sample.views[view].height)
    inside = (
        (middles > 5).all(-1)
        & (middles < np.array(size) - 5).all(-1)
        & in_front[0, view][np.array(BONES)].all(-1)
    )
    return layout.to_pixels(view, middles[inside], size)


def test_one_frame_per_line_and_each_track_in_its_colour(sequence, tmp_path):
    root, tracks, samples, lines = sequence
    gif = tmp_path / "anim.gif"
    assert main(["--data", str(root), "--tracks", str(tracks), "--truth", "--out", str(gif),
                 "--view-width", str(VIEW_WIDTH), "--quiet"]) == 0  # fmt: skip
    frames = frames_of(gif)
    assert len(frames) == FRAMES
    sizes = [(v.width, v.height) for v in samples[0].views]
    layout = Layout.of(sizes, VIEW_WIDTH)
    assert frames[0].shape == (layout.height, layout.width, 3)
    with Image.open(gif) as im:
        assert im.info["duration"] == 100  # real time: 10 fps from the timestamps
    checked = 0
    for k, (image, sample, line) in enumerate(zip(frames, samples, lines, strict=True)):
        for person in line["response"]["persons"]:
            colour = track_colour(person["track_id"])
            others = [track_colour(t) for t in (0, 1, None) if t != person["track_id"]]
            for v in range(len(sizes)):
                for xy in bone_middles(sample, person, v, layout):
                    pixel = nearest_pixel(image, xy, colour)
                    near = np.linalg.norm(pixel - rgb(colour))
                    assert near < 40, (k, person["id"], v, xy, pixel)
                    assert all(near < np.linalg.norm(pixel - rgb(o)) for o in others)
                    checked += 1
        if k == FRAMES - 1:
            assert [p["track_id"] for p in line["response"]["persons"]].count(None) == 1
    assert checked >= 10
    # two tracks, two colours, both in the picture (GIF palettes keep them within a few levels)
    assert track_colour(0) != track_colour(1)
    for colour in (track_colour(0), track_colour(1)):
        close = np.linalg.norm(frames[0] - rgb(colour), axis=-1) < 30
        assert close.sum() > 50


def test_sequences_are_chosen_and_max_frames_and_stride_apply(sequence, tmp_path):
    root, tracks, _, _ = sequence
    gif = tmp_path / "two.gif"
    assert main(["--data", str(root), "--tracks", str(tracks), "--out", str(gif), "--sequence", "1",
                 "--stride", "2", "--max-frames", "5", "--view-width", "96", "--fps", "4", "--quiet"]) == 0  # fmt: skip
    assert len(frames_of(gif)) == 2  # frames 0 and 2


def test_a_rejected_line_is_a_frame_of_its_own(sequence, tmp_path):
    root, _, _, lines = sequence
    rejected = {k: v for k, v in lines[1].items() if k != "response"} | {"status": 422, "error": "bad depth"}
    tracks = tmp_path / "tracks.jsonl"
    tracks.write_text("".join(json.dumps(line) + "\n" for line in (lines[0], rejected, lines[2])))
    gif = tmp_path / "rejected.gif"
    assert (
        main(
            ["--data", str(root), "--tracks", str(tracks), "--out", str(gif), "--view-width", "96", "--quiet"]
        )
        == 0
    )
    assert len(frames_of(gif)) == 3


def test_clear_errors(sequence, tmp_path):
    root, tracks, _, lines = sequence
    out = str(tmp_path / "x.gif")
    with pytest.raises(SystemExit, match="no line for sequence 7; it holds sequences 1"):
        main(["--data", str(root), "--tracks", str(tracks), "--sequence", "7", "--out", out])
    plain = tmp_path / "scenes.jsonl"  # the client without --track: no sequence in the lines
    plain.write_text(json.dumps({k: v for k, v in lines[0].items() if k != "sequence"}) + "\n")
    with pytest.raises(SystemExit, match="--track"):
        main(["--data", str(root), "--tracks", str(plain), "--out", out])
    other = tmp_path / "other.jsonl"  # tracks of another dataset
    other.write_text(json.dumps({**lines[0], "id": "10090000000_10090000001"}) + "\n")
    with pytest.raises(SystemExit, match="not in the annotations"):
        main(["--data", str(root), "--tracks", str(other), "--out", out])
    with pytest.raises(SystemExit, match="does not exist"):
        main(["--data", str(root), "--tracks", str(tmp_path / "none.jsonl"), "--out", out])
    with pytest.raises(SystemExit, match=r"\.gif"):
        main(["--data", str(root), "--tracks", str(tracks), "--out", str(tmp_path / "x.png")])


@pytest.mark.parametrize("room", [True, False])
def test_the_floor_is_level(sequence, room):
    root, _, samples, _ = sequence
    ann = json.loads((root / "annotations.json").read_text())
    params = ann["cameras_info"]["camParams"]
    if not room:  # no room frame: up is the opposite of the cameras' mean image-down axis
        params.pop("firstCamToRoomRef")
    floor = Floor.of(ann, MvorDataset(None, ann).cameras)
    R = floor.rotation
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    if room:  # a point and the point 1 m above it in the room lie at one place on the floor, 1 m higher
        to_room = np.array(params["firstCamToRoomRef"]).reshape(4, 4)
        up = to_room[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        assert floor.up == "the room's"
    else:
        cameras = MvorDataset(None, ann).cameras
        up = -np.mean([c.extrinsics[:3, 1].double().numpy() for c in cameras], 0)
        up /= np.linalg.norm(up)
    points = samples[0].poses.reshape(-1, 3).astype(np.float64)  # (N, 3)
    np.testing.assert_allclose(floor.plan(points + 1000 * up), floor.plan(points), atol=1e-6)
    np.testing.assert_allclose(
        (points + 1000 * up) @ R.T - points @ R.T, np.broadcast_to([0, -1000, 0], points.shape), atol=1e-6
    )
