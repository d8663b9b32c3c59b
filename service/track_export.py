"""Tracks that users can take elsewhere: EasyMocap ``keypoints3d`` files and a CSV, from the client's output.

Both are written from the JSON lines of ``python -m service.client --track`` (every frame of the output file,
so a resumed run exports the whole of it). Only persons with a ``track_id`` are exported, each with its
*smoothed* joints (``smoothed_joints``: the tracker's estimate, bones held at the track's lengths), in mm in
the reference frame (camera 0's with MVOR's calibration), in MVOR's joint order (``posenet.skeleton.JOINTS``).

- **EasyMocap:** ``DIR/sequence_S/keypoints3d/NNNNNN.json`` per frame (NNNNNN: the frame's ``frame_index``),
  each ``[{"id": track_id, "keypoints3d": [[x, y, z, c], ...]}]`` with the 10 joints. ``c`` is the service's
  calibrated ``confidence`` of the raw joint in this frame (the probability that it lies within 10 cm, in
  [0, 1]; EasyMocap weighs joints by it and reads 0 as missing). A frame with nobody tracked is an empty list.
  Note that EasyMocap's body models expect their own joint sets (body25, ...): map MVOR's 10 joints before
  fitting.
- **CSV:** one row per joint: ``sequence, frame, timestamp_s, track, joint, x, y, z, confidence, spread_mm``.
  ``confidence`` is that calibrated confidence and ``spread_mm`` the pose network's spread of the raw joint in
  this frame (larger is less certain).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable
from pathlib import Path
from typing import NamedTuple

CSV_COLUMNS = (
    "sequence", "frame", "timestamp_s", "track", "joint", "x", "y", "z", "confidence", "spread_mm",
)  # fmt: skip


class TrackedFrame(NamedTuple):
    sequence: int
    frame_index: int
    timestamp_s: float
    persons: list[dict]  # the response's persons that have a track_id


def tracked_frames(lines: Iterable[dict]) -> list[TrackedFrame]:
    """The answered frames of a ``--track`` output (its lines, in any order), sorted by sequence and time."""
    frames = []
    for line in lines:
        if line.get("status") != 200:
            continue
        if "sequence" not in line or "stream" not in line["response"]:
            raise ValueError(
                f"frame {line.get('id')} of the output was not sent through a stream: export the output of "
                "python -m service.client --track"
            )
        persons = [p for p in line["response"]["persons"] if p["track_id"] is not None]
        frames.append(TrackedFrame(line["sequence"], line["frame_index"], line["timestamp_s"], persons))
    return sorted(frames, key=lambda f: (f.sequence, f.timestamp_s))


def export_easymocap(frames: list[TrackedFrame], folder: Path) -> int:
    """Write ``folder/sequence_S/keypoints3d/NNNNNN.json`` per frame (module docstring); returns the count."""
    for frame in frames:
        path = Path(folder) / f"sequence_{frame.sequence}" / "keypoints3d" / f"{frame.frame_index:06d}.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        people = [
            {
                "id": p["track_id"],
                "keypoints3d": [
                    [*s["position"], raw["confidence"]]
                    for s, raw in zip(p["smoothed_joints"], p["joints"], strict=True)
                ],
            }
            for p in frame.persons
        ]
        path.write_text(json.dumps(people))
    return len(frames)


def export_csv(frames: list[TrackedFrame], path: Path) -> int:
    """Write every tracked joint as a CSV row (module docstring); returns the number of rows."""
    rows = 0
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(CSV_COLUMNS)
        for frame in frames:
            for p in frame.persons:
                for smoothed, raw in zip(p["smoothed_joints"], p["joints"], strict=True):
                    writer.writerow(
                        [frame.sequence, frame.frame_index, frame.timestamp_s, p["track_id"], smoothed["name"],
                         *smoothed["position"], raw["confidence"], raw["spread_mm"]]
                    )  # fmt: skip
                    rows += 1
    return rows
