"""Tracking over rendered sequences: the pose pipeline (detector mode) per frame, then pipeline.track over time.

    python -m posenet.synth --out data/seq_eval --sequence --frames 120 --persons 3 --rig mvor --look twin
    python benchmarks/tracking.py --data data/seq_eval --detections runs/seq_eval_detections.jsonl
    python benchmarks/tracking.py --data data/seq_eval --served runs/seq_eval_tracks.jsonl   # through the service

It runs ``pipeline.two_stage.ScenePipeline.run(views)`` (detector mode: no boxes given, the shipped detector and
pose network) on every frame of the sequences, caching each frame's persons (joints, per-joint spread in mm) in
``--detections`` (reused when it exists, so the tracker can be tuned without the networks), then tracks each
sequence with :class:`pipeline.track.Tracker` (persons the detector was unsure of only continue tracks; ``--set
unsure_gate_mm=none`` ignores them) and prints :func:`pipeline.track_eval.evaluate`'s figures (MOTA,
IDF1, id switches with a 3D gate; per-frame against smoothed MPJPE; acceleration error; per-track bone-length
standard deviation; the tracker's milliseconds per frame) against issue 15's goals. Persons in view whom the
sequence does not annotate (a frame's ``unannotated3D``: renderer 1.2 annotates people as MVOR does) count neither
way: a track on one of them is left out of that frame, and the count of such track-frames is printed.

With ``--served`` it scores instead what the service answered: the JSON lines of ``python -m service.client DATA
--track`` (each person's ``track_id``, raw ``joints`` and ``smoothed_joints``; the tracking time is the
response's ``timings.track`` + ``timings.unsure``), the same figures, as a user of the stream routes gets them.

With ``--cost`` it measures instead what tracking adds to a stream frame, offline and without a server: each
sequence's frames in time order through the pipeline with a tracker asked as a stream asks it (the persons of
unsure boxes grouped only when it can use them, ``SceneResult.unsure_ms``), then ``Tracker.update``.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pipeline.track import Tracker, TrackerConfig, mean_joint_distance, skeleton_height
from pipeline.track_eval import (
    GOALS,
    SequenceFrame,
    TrackedPerson,
    breakdown,
    evaluate,
    goal_lines,
    score,
)
from posenet.data.mvor import load_annotations, pose_joints, room_up
from posenet.runtime.execution import machine_line
from posenet.skeleton import NUM_JOINTS


def detect(
    data: Path,
    gt: dict,
    out: Path,
    backend: str,
    threads: int | None,
    detector: Path | None = None,
    flip_test: bool | None = None,
    pose: Path | None = None,
) -> None:
    """Run the pipeline in detector mode on every frame of ``data`` and write one JSON line per frame."""
    from pipeline.track import Tracker
    from pipeline.two_stage import ScenePipeline
    from posenet.evaluation.predict import read_dataset
    from service.streams import Stream, find_up
    from service.validation import ValidatedScene

    pipe = ScenePipeline.from_checkpoints(
        pose_checkpoint=pose,
        detector_checkpoint=detector,
        backend=backend,
        threads=threads,
        flip_test=flip_test,
    )
    # The views as the service decodes them (tests/pipeline/test_parity.py): the persons equal the served ones.
    ds = read_dataset(data, gt, pipe.read_size)
    # Without a room frame in the file, the room's up comes from the floor, looked for as a stream does it (once
    # per sequence and rig, again later when none was seen; service.streams.find_up).
    looks = {} if room_up(gt) is None else None
    sequence_of = {mv["id"]: mv.get("sequence") for mv in gt["multiview_images"]}
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w") as f:
        for i in tqdm(range(len(ds)), desc="pipeline", unit="frame"):
            sample = ds[i]
            t0 = time.perf_counter()
            result = pipe.run(sample.views, unsure=True)
            up = None
            if looks is not None:
                stream = looks.setdefault(sequence_of.get(sample.id), Stream("offline", Tracker(), 0.0))
                up, look, _ = find_up(stream, ValidatedScene(sample.views, None, None))
                stream.floor, stream.frames = look or stream.floor, stream.frames + 1
            record = {
                "id": sample.id,
                "seconds": round(time.perf_counter() - t0, 3),
                **({} if looks is None else {"up": None if up is None else up.tolist()}),
                "persons": [
                    {
                        "joints": p.joints.round(2).tolist(),
                        "spread_mm": p.spread_mm.round(2).tolist(),
                        "support": p.support,
                        "unsure": p.unsure,
                    }
                    for p in result.persons
                ],  # fmt: skip
            }
            f.write(json.dumps(record) + "\n")


def stream_cost(data: Path, gt: dict, backend: str, threads: int | None) -> dict[int, dict]:
    """Per sequence, what tracking adds to each frame of a stream, in ms: finding the persons of unsure boxes for
    the tracker (asking it, and grouping them when it can use them: ``SceneResult.unsure_ms``) and its update."""
    from pipeline.two_stage import ScenePipeline, TrackerQuestions
    from posenet.evaluation.predict import read_dataset

    pipe = ScenePipeline.from_checkpoints(backend=backend, threads=threads)
    ds = read_dataset(data, gt, pipe.read_size)
    index = {ds[i].id: i for i in range(len(ds))}
    up = room_up(gt)  # as the client sends it
    out = {}
    for seq, rows in sequences(gt).items():
        tracker, unsure_ms, update_ms = Tracker(), [], []
        for frame_id, frame in tqdm(rows, desc=f"sequence {seq}", unit="frame"):
            t = frame.timestamp_s
            questions = TrackerQuestions.asking(tracker, t, up)  # as a stream asks (streams.Frame.prepare)
            result = pipe.run(ds[index[frame_id]].views, unsure=questions)
            joints = np.array([p.joints for p in result.persons], float).reshape(-1, 10, 3)
            spread = np.array([p.spread_mm for p in result.persons], float).reshape(-1, 10)
            unsure = np.array([p.unsure for p in result.persons], bool)
            t0 = time.perf_counter()
            tracker.update(joints, spread, t, unsure, up)
            update_ms.append((time.perf_counter() - t0) * 1e3)
            unsure_ms.append(result.unsure_ms)
        u, k = np.array(unsure_ms), np.array(update_ms)
        out[seq] = {
            "frames": len(rows),
            **{f"{name}_ms_mean": round(float(x.mean()), 3) for name, x in (("unsure", u), ("update", k))},
            "adds_ms_mean": round(float((u + k).mean()), 3),
            "adds_ms_p95": round(float(np.percentile(u + k, 95)), 3),
        }
    return out


def tracker_config(overrides: list[str]) -> TrackerConfig:
    """The default :class:`TrackerConfig` with ``--set`` overrides ``KEY=VALUE``: ``none`` for None, ``true`` /
    ``false`` for a flag, else a number of the field's type (a field that is None by default takes a float);
    ``background.KEY`` sets a field of its ``BackgroundConfig``. ValueError names a field that does not exist or a
    value it cannot take."""
    config = TrackerConfig()
    for item in overrides:
        key, _, value = item.partition("=")
        part, _, key = key.rpartition(".")
        if part not in ("", "background"):
            raise ValueError(f"--set {item}: TrackerConfig has no part {part!r} (background)")
        target = config.background if part else config
        if not hasattr(target, key):
            raise ValueError(f"--set {item}: {type(target).__name__} has no field {key!r}")
        current = getattr(target, key)
        if value.lower() == "none":
            setattr(target, key, None)
        elif isinstance(current, bool):
            if value.lower() not in ("true", "false"):
                raise ValueError(f"--set {item}: {key} takes true or false")
            setattr(target, key, value.lower() == "true")
        else:
            try:
                setattr(target, key, float(value) if current is None else type(current)(value))
            except ValueError:
                raise ValueError(f"--set {item}: {key} takes a number") from None
    return config


# The tracker's cues against phantoms and for identity, one configuration per row of --ablation: (name, gives the tracker views, --set overrides).
# "parked tracks end" is the background rule before 2026-12-07 (a parked track ended; its stillness clock stopped
# while it was unseen and restarted at any cue); "signature" weighs the body's scale in the association cost, "re-id"
# lets a new track take an ended or coasting track's id by it (TrackerConfig.park_suspends, park_recovery,
# signature_mm, reid_s).
ABLATION = (
    ("as before (no views)", False, []),
    ("+ background, parked tracks end", True, ["park_suspends=false", "park_recovery=inf"]),
    ("+ background rule", True, []),
    ("+ background + signature cost", True, ["signature_mm=300"]),
    ("+ background + re-id", True, ["reid_s=60"]),
    ("+ background + signature + re-id", True, ["signature_mm=300", "reid_s=60"]),
)


def ablation(rows: list, views: dict, base: list[str]) -> list[dict]:
    """One row of figures per configuration of :data:`ABLATION` (each on top of the ``--set`` overrides ``base``)
    over one sequence's ``rows`` ((frame id, frame) pairs); ``views`` by frame id."""
    out = []
    for name, with_views, sets in ABLATION:
        frames = [replace(f, views=views[i] if with_views else None) for i, f in rows]
        figures = evaluate(frames, Tracker(tracker_config(base + sets)))
        out.append({"cues": name, **{k: figures[k] for k in ABLATION_FIGURES if k in figures}})
    return out


ABLATION_FIGURES = ("gt_person_frames", "idf1", "hota", "mota", "id_switches", "switches_per_1000", "misses", "false_positives",
                    "phantom_tracks", "longest_on_nobody_s", "track_ms_mean", "background_ms_mean")  # fmt: skip


def depth_views(data: Path, gt: dict) -> dict[str, list]:
    """Per frame id its views as the tracker's background reads them: depth (at half size, 320 x 240 for MVOR's
    640 x 480, as the service decodes them for the shipped networks) and cameras, no colour."""
    from posenet.data.mvor import MvorDataset
    from posenet.scene import SceneView

    ds = MvorDataset(data, gt, subsample=2, modalities=("depth",))
    return {
        ds[i].id: [SceneView(None, v.depth, v.camera) for v in ds[i].views]
        for i in tqdm(range(len(ds)), desc="depth", unit="frame")
    }


def _joints(poses: list[dict]) -> np.ndarray:
    """``(N, J, 3)`` mm: the joints of ``annotations3D``-style entries (``posenet.data.mvor.pose_joints``)."""
    return np.array([pose_joints(p, i)[0] for i, p in enumerate(poses)], float).reshape(-1, NUM_JOINTS, 3)


def sequences(
    gt: dict, detections: dict[str, dict] | None = None
) -> dict[int, list[tuple[str, SequenceFrame]]]:
    """Per sequence, its frames in time order, each ``(frame id, frame)``: ground truth (person ids and joints)
    and the pipeline's persons (``detections``; none without them, e.g. to score the service's own tracks),
    among them those the detector was unsure of (tracked only with ``TrackerConfig.unsure_gate_mm``)."""
    up = room_up(gt)  # as the client sends it; else the floor the pipeline's run found (detect)
    poses = defaultdict(list)
    for pose in gt["annotations3D"]:
        poses[pose["image_ids"]].append(pose)
    out = defaultdict(list)
    for mv in gt["multiview_images"]:
        if "sequence" not in mv:
            raise ValueError(f"frame {mv['id']} has no 'sequence': render with posenet.synth --sequence")
        gts = poses[mv["id"]]
        det = [] if detections is None else detections[mv["id"]]["persons"]
        frame = SequenceFrame(
            timestamp_s=float(mv["timestamp_s"]),
            gt_ids=np.array([p["person_id"] for p in gts], int),
            gt_joints=_joints(gts),
            joints=np.array([p["joints"] for p in det], float).reshape(-1, 10, 3),
            spread=np.array([p["spread_mm"] for p in det], float).reshape(-1, 10),
            unsure=np.array([p.get("unsure", False) for p in det], bool),
            up=up
            if up is not None or detections is None or detections[mv["id"]].get("up") is None
            else np.asarray(detections[mv["id"]]["up"], float),
            ignore_joints=_joints(mv.get("unannotated3D", [])),
        )
        out[mv["sequence"]].append((mv["id"], frame))
    for rows in out.values():
        rows.sort(key=lambda r: r[1].timestamp_s)
    return dict(out)


def served_lines(path: Path) -> dict[str, dict]:
    """The JSON lines of ``python -m service.client DATA --track``, by frame id."""
    with open(path) as f:
        return {r["id"]: r for r in (json.loads(t) for t in f if t.strip())}


def served_tracks(lines: dict[str, dict], frame_id: str) -> tuple[dict[int, TrackedPerson], float]:
    """The confirmed tracks that the service answered for one frame, and what tracking added to it in ms: the
    tracker's update (``timings.track``) and the persons of unsure boxes found for it (``timings.unsure``;
    responses of before it was reported count the update alone)."""
    if frame_id not in lines:
        raise ValueError(
            f"frame {frame_id} is not in the --served output: finish the client run (it resumes)"
        )
    line = lines[frame_id]
    if line.get("status") != 200:
        raise ValueError(f"frame {frame_id} was answered {line.get('status')}: {line.get('error')}")
    response = line["response"]
    tracks = {}
    for p in response["persons"]:
        if p.get("track_id") is not None:
            raw = np.array([j["position"] for j in p["joints"]], float)
            smooth = np.array([j["position"] for j in p["smoothed_joints"]], float)
            tracks[int(p["track_id"])] = TrackedPerson(int(p["track_id"]), raw, smooth)
    timings = response.get("timings", {})
    return tracks, float(timings.get("track", float("nan"))) + float(timings.get("unsure", 0.0))


def births(frames: list[SequenceFrame], tracker: Tracker, near_mm: float = 500.0) -> list[dict]:
    """Per track the tracker confirms on ``frames``: its first frames' medians (the ``birth_hits`` frames the
    lying rule of ``TrackerConfig`` judges: height along the frame's up, or None without one, and median joint
    spread), its frame count, and the share of its frames whose raw skeleton lies within ``near_mm`` (mean joint
    distance) of an annotated person."""
    seen = defaultdict(lambda: {"height": [], "spread": [], "near": []})
    for f in frames:
        for p in tracker.update(f.joints, f.spread, f.timestamp_s, f.unsure, f.up, f.views):
            if p.track_id is None:
                continue
            t = seen[p.track_id]
            t["height"].append(np.nan if f.up is None else float(skeleton_height(p.raw, f.up)))
            t["spread"].append(float(np.median(f.spread[p.detection])))
            d = mean_joint_distance(p.raw[None], f.gt_joints).min() if len(f.gt_joints) else np.inf
            t["near"].append(bool(d < near_mm))
    k = tracker.config.birth_hits
    out = []
    for track, t in sorted(seen.items()):
        h = float(np.median(t["height"][:k]))
        out.append({"track": track, "frames": len(t["near"]), "near_share": round(float(np.mean(t["near"])), 2),
                    "first_height_mm": None if np.isnan(h) else round(h), "first_spread_mm": round(float(
                    np.median(t["spread"][:k])))})  # fmt: skip
    return out


def print_switches(seq, events: list[dict]) -> list[dict]:
    """Print a sequence's id switches (:func:`pipeline.track_eval.switches`), one line each, and return them."""
    for e in events:
        was = "a new track" if e["to_track_was"] is None else f"the track of person {e['to_track_was']}"
        gap = (
            "" if e["unmatched_frames"] is None else f", after {e['unmatched_frames']} frames without a track"
        )
        old = "still reported" if e["from_track_reported"] else "not reported"
        print(f"sequence {seq} frame {e['frame']} ({e['time_s']} s): person {e['person']}, track {e['from_track']} -> "
              f"{e['to_track']} ({was}{gap}; track {e['from_track']} {old})")  # fmt: skip
    return events


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--data", type=Path, required=True, help="a rendered sequence (posenet.synth --sequence)")
    p.add_argument("--annotations", type=Path, help="its annotations (default: DATA/annotations.json)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--detections", type=Path, help="the pipeline's persons per frame (cache), tracked here")
    src.add_argument(
        "--served",
        type=Path,
        help="instead: the JSON lines of `service.client DATA --track` (the service's own tracks and timings)",
    )
    src.add_argument(
        "--cost",
        action="store_true",
        help="instead: what tracking adds to a stream frame (finding the unsure persons for the tracker, and its "
        "update), offline through the pipeline, no server",
    )
    p.add_argument("--redetect", action="store_true", help="run the pipeline even when --detections exists")
    p.add_argument(
        "--backend",
        default="auto",
        help="the networks' runtime (auto: the service's choice, so that offline persons equal the served ones; "
        "torch, openvino, onnxruntime)",
    )
    p.add_argument("--threads", type=int, default=None, help="the runtimes' intra-op threads")
    p.add_argument(
        "--pose-checkpoint",
        type=Path,
        help="the pipeline's pose network (default: the shipped weights), e.g. posenet/weights/frames.safetensors",
    )
    p.add_argument(
        "--detector-checkpoint", type=Path, help="the pipeline's detector (default: the shipped weights)"
    )
    p.add_argument("--flip-test", action=argparse.BooleanOptionalAction, default=None,
                   help="the pose network averaged with the mirrored inputs (ORPOSE_FLIP_TEST in the service; "
                   "default: the checkpoint's setting)")  # fmt: skip
    p.add_argument("--json", type=Path, help="also write the figures here")
    p.add_argument("--births", action="store_true",
                   help="also list each confirmed track's first frames (median height along up and spread, the "
                   "lying rule's inputs) and whether it follows an annotated person (offline tracking)")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override a TrackerConfig field (offline tracking), e.g. --set max_spread_mm=500, or of its "
                   "background model, e.g. --set background.margin_mm=200")  # fmt: skip
    p.add_argument("--ablation", action="store_true",
                   help="instead of one configuration, compare the tracker's cues side by side (offline tracking): "
                   "as before, + the background rule, + the body signature in the cost, + re-identification")  # fmt: skip
    p.add_argument("--breakdown", action="store_true",
                   help="also say where the person-frames without a track go (no skeleton, a neighbour's skeleton, "
                   "the tracker's filters, tentative tracks, the duplicate rule, ...) and what the false positives are "
                   "(pipeline.track_eval.breakdown; offline tracking)")  # fmt: skip
    p.add_argument("--switches", action="store_true",
                   help="also list each id switch: the person, the track it had and the one it took, whom that track "
                   "followed before, and how long the person went without a track first (pipeline.track_eval.switches)")  # fmt: skip
    p.add_argument("--background", action="store_true",
                   help="give the tracker each frame's depth images and cameras (offline tracking), as a stream "
                   "does: it learns the room's static depth and confirms no track on what never moved "
                   "(pipeline.background)")  # fmt: skip
    args = p.parse_args(argv)
    gt = load_annotations(args.annotations or args.data / "annotations.json")
    try:
        config = tracker_config(args.set)
    except ValueError as err:
        p.error(str(err))
    report = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"), "tracker": asdict(config)}
    report["sequences"] = {}
    if args.cost:
        report["source"] = "offline, as a stream asks its tracker"
        report["sequences"] = stream_cost(args.data, gt, args.backend, args.threads)
        for seq, ms in report["sequences"].items():
            print(f"sequence {seq}: {ms['frames']} frames; ms per frame: unsure persons {ms['unsure_ms_mean']:.2f}, "
                  f"tracker update {ms['update_ms_mean']:.2f}; tracking adds {ms['adds_ms_mean']:.2f} (p95 "
                  f"{ms['adds_ms_p95']:.2f}; goal <= 2.0 {'met' if ms['adds_ms_mean'] <= 2.0 else 'NOT met'})")  # fmt: skip
        print(report["machine"])
        if args.json:
            args.json.write_text(json.dumps(report, indent=2))
        return report
    if args.served:
        lines = served_lines(args.served)
        report["source"] = f"served: {args.served}"
        report["pipeline_seconds_per_frame"] = round(
            float(np.mean([r["latency_ms"] for r in lines.values()])) / 1e3, 3
        )
        for seq, rows in sequences(gt).items():
            hyps, ms = zip(*(served_tracks(lines, frame_id) for frame_id, _ in rows), strict=True)
            report["sequences"][seq] = figures = score(
                [f for _, f in rows], list(hyps), list(ms), switch_events=args.switches
            )
            background = [lines[i]["response"]["timings"].get("background") for i, _ in rows]
            if all(b is not None for b in background):  # answered since timings.background exists
                figures["background_ms_mean"] = round(float(np.mean(background)), 3)
    else:
        if args.redetect or not args.detections.is_file():
            detect(args.data, gt, args.detections, args.backend, args.threads, args.detector_checkpoint,
                   args.flip_test, args.pose_checkpoint)  # fmt: skip
        with open(args.detections) as f:
            detections = {r["id"]: r for r in map(json.loads, f)}
        report["source"] = f"offline: {args.detections}"
        seconds = [r["seconds"] for r in detections.values()]
        report["pipeline_seconds_per_frame"] = round(float(np.mean(seconds)), 3)
        report["background"] = args.background
        views = depth_views(args.data, gt) if args.background or args.ablation else {}
        for seq, rows in sequences(gt, detections).items():
            if args.ablation:
                report.setdefault("ablation", {})[seq] = table = ablation(rows, views, args.set)
                print(f"sequence {seq}: " + " | ".join(ABLATION_FIGURES))
                for row in table:
                    print(
                        f"  {row['cues']:<34} " + " | ".join(str(row.get(k, "-")) for k in ABLATION_FIGURES)
                    )
                continue
            for frame_id, frame in rows:
                frame.views = views.get(frame_id)
            report["sequences"][seq] = evaluate(
                [f for _, f in rows], Tracker(config), switch_events=args.switches
            )
            if args.breakdown:
                report["sequences"][seq]["breakdown"] = b = breakdown([f for _, f in rows], Tracker(config))
                print(
                    f"sequence {seq}: {b['tracked']} of {b['person_frames']} annotated person-frames tracked; the rest:"
                )
                for name, n in b["missed"].items():
                    print(f"  {n:>5}  {name}")
                print("  false positives (confirmed track-frames on no annotated person):")
                for name, n in b["false_positives"].items():
                    print(f"  {n:>5}  {name}")
            if args.births:
                report["sequences"][seq]["births"] = rows_of = births([f for _, f in rows], Tracker(config))
                for b in rows_of:
                    print(f"sequence {seq} track {b['track']}: {b['frames']} frames, {b['near_share']:.0%} near a "
                          f"person; first frames {b['first_height_mm']} mm along up, spread {b['first_spread_mm']} mm")  # fmt: skip
    for seq, figures in report["sequences"].items():
        print_switches(seq, figures.get("switch_events", []))
        print(
            f"sequence {seq}: {figures['frames']} frames, {figures['gt_person_frames']} annotated person-frames; "
            f"{figures['ignored_track_frames']} track-frames on persons in view but not annotated left out"
        )
        print(f"  MOTA {figures['mota']}, HOTA {figures['hota']} (DetA {figures['deta']}, AssA {figures['assa']}; "
              f"{figures['hota_similarity']}), misses {figures['misses']}, false positives "
              f"{figures['false_positives']}, phantom tracks {figures['phantom_tracks']}")  # fmt: skip
        for line in goal_lines(figures):
            print("  " + line)
    print(
        "(track_ms: offline, the tracker's update alone; --served, what tracking adds to a stream frame: the update "
        "and the persons of unsure boxes found for it, timings.track + timings.unsure; docs/tracking.md, 'What "
        "tracking costs a stream frame')"
    )
    print(report["machine"])
    report["goals"] = GOALS
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
