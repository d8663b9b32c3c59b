"""An animated GIF of a tracked sequence: the camera views and the skeletons on the floor, coloured by track id.

Usage::

    python -m posenet.viz.animate --data data/seq_eval --tracks runs/seq_eval_tracks.jsonl --truth \\
        --out runs/seq_eval.gif

``--tracks`` is the JSON-lines output of ``python -m service.client DATA --annotations A.json --track``
(``docs/service.md``): one line per frame with its ``sequence``, ``frame_index``, ``timestamp_s`` and ``status``,
and the stream's ``response``, whose ``persons`` each carry ``track_id`` (null: not tracked), ``smoothed_joints``
(mm, reference frame, MVOR's joint order) and their boxes (``views``: ``{"view", "box"}``, pixels of the images
sent, which are the dataset's files as they are). It is read as plain JSON; the frames and cameras come from the
dataset (``posenet.data.mvor``), so the service is not needed to draw.

Each GIF frame is one line of the sequence, in time order:

- the V colour views side by side, downscaled to ``--view-width`` pixels, each with every person's smoothed
  skeleton projected into it (``Camera.project``) and its boxes, in one fixed colour per track id
  (``posenet.viz.visualize.PERSON_COLOURS``); persons without a track are grey;
- under them, the floor seen from above: the same skeletons in the reference (camera 0) frame turned level
  (:class:`Floor`), each track's path over the last ``TRAIL_S`` seconds, the cameras, and with ``--truth`` the
  ground-truth skeletons in black. Its extent is fixed for the whole sequence.

A top-down floor view rather than a 3D plot: at a GIF's size, matplotlib's 3D axes left the persons a few pixels
tall in a room-sized box, while from above who is where, and where each track has been, reads at a glance.
A line the server rejected (status other than 200) shows the views only, with its status in the title.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from tqdm import tqdm

from posenet.cameras import Camera
from posenet.data.mvor import MvorDataset, room_up
from posenet.data.sample import Sample
from posenet.skeleton import BONES, NUM_JOINTS
from posenet.viz.visualize import PERSON_COLOURS, draw_box

UNTRACKED = "0.55"  # grey: a person the tracker has not (yet) given an id
DPI = 100  # figure inches * DPI = GIF pixels; the layout is computed in pixels
TITLE_PX = 26  # the band above the panels that holds the title
FLOOR_HEIGHT = 1.5  # the floor panel's height, in tallest views (a room is wider than a view strip is tall)
MARGIN_MM = 500.0  # around everything drawn on the floor
TRAIL_S = 2.0  # how far back each track's path is drawn
NECK = 1  # the joint whose path is drawn (posenet.skeleton.JOINTS)


def track_colour(track_id: int | None) -> str:
    """The fixed colour of a track id (the same in every frame and view); grey for None."""
    return UNTRACKED if track_id is None else PERSON_COLOURS[track_id % len(PERSON_COLOURS)]


class Person(NamedTuple):
    """One person of a line: its track id (None: not tracked), smoothed joints (J, 3) mm, boxes by view."""

    track_id: int | None
    joints: np.ndarray
    boxes: dict[int, list[float]]


def persons_of(line: dict) -> list[Person]:
    """The persons of an answered line (none for a rejected one)."""
    if line.get("status") != 200:
        return []
    return [
        Person(
            p.get("track_id"),
            np.array([j["position"] for j in p.get("smoothed_joints", p["joints"])], np.float64),
            {s["view"]: s["box"] for s in p["views"]},
        )
        for p in line["response"]["persons"]
    ]


# ----------------------------------------------------------------------------------------------- input
def read_sequence(path: Path, sequence: int | None) -> tuple[int, list[dict]]:
    """The lines of one sequence of a ``--track`` output, in time order, and that sequence's number.

    ``sequence`` None takes the lowest one in the file. A frame written twice counts once (the last line).
    Raises SystemExit naming the problem: no such file, a line that was not sent through a stream, no line for
    ``sequence`` (with the sequences the file holds).
    """
    if not path.is_file():
        raise SystemExit(f"error: --tracks {path} does not exist")
    by_sequence: dict[int, dict[str, dict]] = {}
    torn = 0
    for n, raw in enumerate(path.read_text().splitlines(), 1):
        if not raw.strip():
            continue
        try:
            line = json.loads(raw)
        except ValueError:  # a line cut short by a killed client: the client drops it too
            torn += 1
            continue
        if not isinstance(line, dict) or "sequence" not in line:
            raise SystemExit(
                f"error: {path}, line {n}: no sequence; draw the output of python -m service.client ... --track "
                "(one stream per sequence), not that of /scenes"
            )
        by_sequence.setdefault(int(line["sequence"]), {})[line["id"]] = line
    if torn:
        print(f"{path}: left out {torn} line(s) that are not JSON", file=sys.stderr)
    if not by_sequence:
        raise SystemExit(f"error: {path} holds no frames")
    held = ", ".join(str(s) for s in sorted(by_sequence))
    if sequence is None:
        sequence = min(by_sequence)
        if len(by_sequence) > 1:
            print(f"drawing sequence {sequence} of {held} (choose one with --sequence)", file=sys.stderr)
    elif sequence not in by_sequence:
        raise SystemExit(f"error: {path} has no line for sequence {sequence}; it holds sequences {held}")
    return sequence, sorted(by_sequence[sequence].values(), key=lambda line: line["timestamp_s"])


@dataclass(frozen=True)
class Floor:
    """The floor panel's frame: the reference frame turned level, seen from above.

    ``rotation (3, 3)`` maps reference-frame points to levelled ones, with ``rotation @ up = (0, -1, 0)``: x is
    camera 0's right made horizontal, y points down, z is camera 0's forward along the floor; the origin stays at
    camera 0. A point's place on the floor is its levelled (x, z). Up is the room frame's z axis when the
    annotations have one (MVOR's ``firstCamToRoomRef``), else the opposite of the cameras' mean image-down axis,
    as ``posenet.rig.picture`` takes it (ceiling cameras are mounted roughly upright).
    """

    rotation: np.ndarray
    up: str  # where "up" came from

    @classmethod
    def of(cls, annotations: dict, cameras: list[Camera]) -> Floor:
        up, source = room_up(annotations), "the room's"
        if up is None:
            up = -np.mean([c.extrinsics[:3, 1].double().numpy() for c in cameras], 0)
            source = "the cameras'"
        down = -up / np.linalg.norm(up)
        right = np.array([1.0, 0.0, 0.0]) - down[0] * down  # camera 0's x, made horizontal
        right /= np.linalg.norm(right)
        return cls(np.stack([right, down, np.cross(right, down)]), source)

    def plan(self, points: np.ndarray) -> np.ndarray:
        """Reference-frame points ``(..., 3)`` mm -> their places on the floor ``(..., 2)`` mm."""
        return (points @ self.rotation.T)[..., [0, 2]]


def floor_extent(
    frames: list[tuple[dict, Sample]], floor: Floor, truth: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The floor panel's ``lo, hi (2,)`` mm, fixed for the sequence: the tracked persons' joints (every person's
    when nobody is tracked) and, with ``truth``, the ground truth, plus a margin. Neither the cameras (drawn when
    inside) nor an untracked person far off (a badly grouped one) stretch it; with nobody at all, the cameras
    set it."""
    persons = [p for line, _ in frames for p in persons_of(line)]
    shown = [p.joints for p in persons if p.track_id is not None] or [p.joints for p in persons]
    if truth:
        shown += [s.poses[s.valid] for _, s in frames]
    points = np.concatenate([np.zeros((0, 3)), *[j.reshape(-1, 3) for j in shown]])  # (N, 3)
    if len(points) == 0:
        points = torch.stack([v.camera.position for v in frames[0][1].views]).double().numpy()
    points = floor.plan(points)  # (N, 2)
    return points.min(0) - MARGIN_MM, points.max(0) + MARGIN_MM


# ----------------------------------------------------------------------------------------------- drawing
@dataclass(frozen=True)
class Layout:
    """Where each panel lies in a GIF frame, in pixels ``(x0, y0, width, height)`` from the top-left corner.

    The views keep their aspect at ``view_width`` pixels wide, side by side under the title; the floor panel lies
    under them, as wide as they are together and ``FLOOR_HEIGHT`` times as tall as the tallest.
    """

    width: int
    height: int
    views: tuple[tuple[int, int, int, int], ...]
    floor: tuple[int, int, int, int]

    @classmethod
    def of(cls, sizes: list[tuple[int, int]], view_width: int) -> Layout:
        """``sizes``: each view's image (width, height) in pixels."""
        heights = [round(view_width * h / w) for w, h in sizes]
        views = tuple((v * view_width, TITLE_PX, view_width, h) for v, h in enumerate(heights))
        width = len(sizes) * view_width
        floor = (0, TITLE_PX + max(heights), width, round(FLOOR_HEIGHT * max(heights)))
        return cls(width, floor[1] + floor[3], views, floor)

    def to_pixels(self, view: int, uv: np.ndarray, size: tuple[int, int]) -> np.ndarray:
        """Image pixels ``uv (..., 2)`` of a view whose image is ``size`` (width, height) -> GIF pixels (x, y)."""
        x0, y0, w, h = self.views[view]
        return np.stack([x0 + (uv[..., 0] + 0.5) * w / size[0], y0 + (uv[..., 1] + 0.5) * h / size[1]], -1)

    def fraction(self, box: tuple[int, int, int, int]) -> list[float]:
        """A pixel box as matplotlib's ``[left, bottom, width, height]`` figure fractions."""
        x0, y0, w, h = box
        return [x0 / self.width, 1 - (y0 + h) / self.height, w / self.width, h / self.height]


def project(sample: Sample, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Skeletons ``joints (P, J, 3)`` mm (reference frame) in every view: pixels ``(P, V, J, 2)`` and whether
    each joint lies in front of the camera ``(P, V, J)``."""
    cameras = sample.cameras  # batch (V,)
    points = torch.as_tensor(joints, dtype=cameras.intrinsics.dtype)[:, None]  # (P, 1, J, 3)
    in_front = cameras.to_camera(points)[..., 2] > 1.0  # (P, V, J)
    return cameras.project(points).numpy(), in_front.numpy()


class Canvas:
    """The figure that every GIF frame is drawn on: V image axes and the floor's axes at fixed pixel positions.

    Frames must be drawn in time order: the canvas keeps each track's path for the floor panel.
    """

    def __init__(
        self, layout: Layout, floor: Floor, extent: tuple[np.ndarray, np.ndarray], truth: bool
    ) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        self.layout, self.floor, self.truth = layout, floor, truth
        self.extent = fit_extent(*extent, layout.floor[2] / layout.floor[3])
        self.fig = plt.figure(figsize=(layout.width / DPI, layout.height / DPI), dpi=DPI)
        self.views = [self.fig.add_axes(layout.fraction(box)) for box in layout.views]
        self.ax_floor = self.fig.add_axes(layout.fraction(layout.floor))
        self.title = self.fig.text(0.5, 1 - TITLE_PX / 2 / layout.height, "", ha="center", va="center")
        # track id -> its last TRAIL_S seconds: (time s, the neck's place on the floor (2,))
        self.paths: dict[int, list[tuple[float, np.ndarray]]] = {}

    def close(self) -> None:
        import matplotlib.pyplot as plt

        plt.close(self.fig)

    def draw(self, line: dict, sample: Sample) -> None:
        persons = persons_of(line)
        colours = [track_colour(p.track_id) for p in persons]
        joints = np.stack([p.joints for p in persons]) if persons else np.zeros((0, NUM_JOINTS, 3))
        uv, in_front = project(sample, joints)  # (P, V, J, 2), (P, V, J)
        for v, (ax, view) in enumerate(zip(self.views, sample.views, strict=True)):
            ax.clear()
            ax.imshow(view.color)
            ax.set_xlim(-0.5, view.width - 0.5)
            ax.set_ylim(view.height - 0.5, -0.5)
            ax.axis("off")
            ax.text(6, 6, f"view {v}", color="white", fontsize=7, va="top", backgroundcolor=(0, 0, 0, 0.4))
            for p, person in enumerate(persons):
                draw_bones(ax, uv[p, v], in_front[p, v], colours[p], 2.0)
                if v in person.boxes:
                    label = "untracked" if person.track_id is None else f"track {person.track_id}"
                    draw_box(ax, person.boxes[v], colours[p], label)
        self._draw_floor(line["timestamp_s"], persons, colours, sample)
        status = "" if line.get("status") == 200 else f"; no answer (status {line.get('status')})"
        tracked = sum(p.track_id is not None for p in persons)
        self.title.set_text(
            f"sequence {line['sequence']}, frame {line['frame_index']}, {line['timestamp_s']:.2f} s: "
            f"{tracked} tracked, {len(persons) - tracked} untracked{status}"
        )

    def _draw_floor(self, t: float, persons: list[Person], colours: list[str], sample: Sample) -> None:
        from matplotlib.ticker import MultipleLocator

        ax, floor = self.ax_floor, self.floor
        ax.clear()
        (x0, z0), (x1, z1) = self.extent
        ax.set_xlim(x0, x1)
        ax.set_ylim(z0, z1)
        ax.xaxis.set_major_locator(MultipleLocator(1000.0))
        ax.yaxis.set_major_locator(MultipleLocator(1000.0))
        ax.tick_params(which="both", length=0, labelbottom=False, labelleft=False)
        ax.grid(True, lw=0.5, color="0.85")
        for v, view in enumerate(sample.views):
            x, z = floor.plan(view.camera.position.double().numpy())
            ax.plot(x, z, marker="s", color="0.3", ms=4)
            ax.text(x, z, f" view {v}", color="0.3", fontsize=6, va="center", clip_on=True)
        if self.truth:
            for pose, valid in zip(floor.plan(sample.poses), sample.valid, strict=True):
                draw_bones(ax, pose, valid, "black", 1.0)
        for person, colour in zip(persons, colours, strict=True):
            plan = floor.plan(person.joints)  # (J, 2)
            draw_bones(ax, plan, np.ones(NUM_JOINTS, bool), colour, 2.0)
            if person.track_id is None:
                continue
            path = [(s, xz) for s, xz in self.paths.get(person.track_id, []) if t - s <= TRAIL_S]
            self.paths[person.track_id] = path = [*path, (t, plan[NECK])]
            ax.plot(*np.array([xz for _, xz in path]).T, color=colour, lw=1.0, alpha=0.6)  # (2, T)
            ax.text(
                *plan[0], f" {person.track_id}", color=colour, fontsize=8, fontweight="bold", clip_on=True
            )
        title = (
            f"the floor from above ({floor.up} up, camera 0 looking up the page, grid 1 m), paths of {TRAIL_S:g} s"
            + (", truth in black" if self.truth else "")
        )
        ax.text(
            0.005, 0.98, title, transform=ax.transAxes, fontsize=7, va="top", backgroundcolor=(1, 1, 1, 0.7)
        )


def fit_extent(lo: np.ndarray, hi: np.ndarray, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """The box ``lo, hi (2,)`` widened about its centre to the panel's ``aspect`` (width / height), so that a mm
    is as long across the panel as up it."""
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    half = np.maximum(half, half[::-1] * np.array([aspect, 1 / aspect]))
    return centre - half, centre + half


def draw_bones(ax, points: np.ndarray, valid: np.ndarray, colour, lw: float) -> None:
    """The bones of one skeleton on 2D axes: ``points (J, 2)`` in the axes' units, a bone drawn when both its
    ends are ``valid (J,)``."""
    from matplotlib.collections import LineCollection

    bones = np.array(BONES)  # (B, 2)
    segments = points[bones[valid[bones].all(-1)]]  # (B', 2, 2)
    ax.add_collection(LineCollection(segments, colors=colour, linewidths=lw, capstyle="round"))


# ----------------------------------------------------------------------------------------------- main
def animate(
    lines: list[dict],
    dataset: MvorDataset,
    out: Path,
    fps: float,
    view_width: int = 320,
    truth: bool = False,
    progress: bool = True,
) -> Layout:
    """Draw each of ``lines`` (one sequence, in time order) on its frame of ``dataset`` (read with colour) into
    the GIF ``out``; returns the frames' layout."""
    from matplotlib.animation import PillowWriter

    index = {frame_id: i for i, frame_id in enumerate(dataset.ids)}
    missing = [line["id"] for line in lines if line["id"] not in index]
    if missing:
        raise SystemExit(
            f"error: {len(missing)} frame(s) of the tracks are not in the annotations (first: {missing[0]}): "
            "give the --data and --annotations that the client sent"
        )
    bare = MvorDataset(None, dataset.annotations)  # poses and cameras without pixels, for the fixed extent
    frames = [(line, bare[index[line["id"]]]) for line in lines]
    layout = Layout.of([(view.width, view.height) for view in frames[0][1].views], view_width)
    floor = Floor.of(dataset.annotations, dataset.cameras)
    canvas = Canvas(layout, floor, floor_extent(frames, floor, truth), truth)
    out.parent.mkdir(parents=True, exist_ok=True)
    writer = PillowWriter(fps=fps)
    try:
        with writer.saving(canvas.fig, str(out), dpi=DPI):
            for line in tqdm(lines, desc="frames", unit="frame", disable=not progress):
                canvas.draw(line, dataset[index[line["id"]]])  # one frame's images in memory at a time
                writer.grab_frame()
    finally:
        canvas.close()
    return layout


def real_time_fps(lines: list[dict]) -> float:
    """The frame rate that plays ``lines`` at their own pace (the median time step), within GIF's limits."""
    steps = np.diff([line["timestamp_s"] for line in lines])
    if len(steps) == 0 or np.median(steps) <= 0:
        return 10.0
    return float(np.clip(1.0 / np.median(steps), 1.0, 50.0))  # browsers slow frames under 20 ms down to 100


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m posenet.viz.animate",
        description="Draw a tracked sequence (the JSON lines of python -m service.client --track) as an "
        "animated GIF: the colour views with each person's smoothed skeleton and boxes, and the floor seen from "
        "above with the skeletons and each track's path, coloured by track id (grey: not tracked).",
        epilog="example (a rendered sequence, tracked through the service, then drawn):\n"
        "  python -m posenet.synth --out data/seq_eval --sequence --frames 120 --persons 3 --rig mvor "
        "--look twin\n"
        "  python -m service.client data/seq_eval --annotations data/seq_eval/annotations.json \\\n"
        "      --url http://127.0.0.1:8000 --out runs/seq_eval_tracks.jsonl --track\n"
        "  python -m posenet.viz.animate --data data/seq_eval --tracks runs/seq_eval_tracks.jsonl --truth \\\n"
        "      --out runs/seq_eval.gif --stride 2 --view-width 240\n"
        "A frame of three views weighs about 0.2 MB at the default --view-width and 0.1 MB at 240: --stride and "
        "--max-frames keep a GIF for a web page small.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--data", type=Path, required=True, help="dataset root (dayD/camC/color/NNNNNN.png)")
    p.add_argument(
        "--annotations", type=Path, help="MVOR-format annotation json (default: DATA/annotations.json)"
    )
    p.add_argument(
        "--tracks", type=Path, required=True, help="JSON lines of python -m service.client --track"
    )
    p.add_argument("--sequence", type=int, help="which sequence to draw (default: the lowest in --tracks)")
    p.add_argument(
        "--truth", action="store_true", help="also draw the ground-truth skeletons (black) on the floor"
    )
    p.add_argument("--out", type=Path, required=True, help="the animated GIF to write (.gif)")
    p.add_argument("--fps", type=float, help="frames per second (default: real time, from the timestamps)")
    p.add_argument("--max-frames", type=int, help="draw at most this many frames (from the sequence's start)")
    p.add_argument("--stride", type=int, default=1, help="draw every K-th frame (default: %(default)s)")
    p.add_argument(
        "--view-width",
        type=int,
        default=320,
        help="each view's width in the GIF, pixels (default: %(default)s)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.out.suffix.lower() != ".gif":
        raise SystemExit(f"error: --out {args.out} must end in .gif")
    for name, value, low in (("--stride", args.stride, 1), ("--max-frames", args.max_frames, 1),
                             ("--view-width", args.view_width, 64), ("--fps", args.fps, 0.1)):  # fmt: skip
        if value is not None and value < low:
            raise SystemExit(f"error: {name} must be at least {low}, got {value}")
    sequence, lines = read_sequence(args.tracks, args.sequence)
    lines = lines[:: args.stride][: args.max_frames]
    annotations = args.annotations or args.data / "annotations.json"
    dataset = MvorDataset(args.data, annotations, modalities=("color",))
    fps = args.fps or real_time_fps(lines)
    layout = animate(lines, dataset, args.out, fps, args.view_width, args.truth, not args.quiet)
    print(
        f"wrote {args.out}: sequence {sequence}, {len(lines)} frames at {fps:.3g} fps, "
        f"{layout.width}x{layout.height} px, {args.out.stat().st_size / 1e6:.1f} MB",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
