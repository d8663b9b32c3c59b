"""How well a tracker follows people over a sequence: identities, smoothness, plausible bones, cost.

:func:`evaluate` runs a :class:`pipeline.track.Tracker` over a sequence's frames (the pose pipeline's persons
and the ground truth) and :func:`score` measures its tracks, or tracks made elsewhere (a served stream's):

- **Identities** with ``motmetrics`` (CLEAR MOT and IDF1): a confirmed track and a ground-truth person can match
  when their mean joint distance is at most ``gate_mm`` (3D, mm). MOTA, IDF1, id switches, and switches per 1,000
  ground-truth person-frames. Persons in view that the ground truth does not annotate (a frame's
  ``ignore_joints``: a rendered sequence's ``unannotated3D``, people MVOR's convention leaves box-only) count
  neither way, as MOTChallenge treats its distractors: a track that the optimal assignment under the gate gives
  to one of them rather than to an annotated person is left out of that frame.
- **Per-frame against smoothed MPJPE** (cm), on the same matched pairs: the pipeline's joints as they came, and
  the tracker's.
- **Acceleration error** (mm/frame^2): the mean over joints of ``|a_pred - a_gt|``, with ``a = x[t+1] - 2 x[t] +
  x[t-1]``, wherever a person is matched in three consecutive frames (the usual jitter figure of video pose
  estimation); per-frame against smoothed.
- **Bone lengths**: per track, the standard deviation over time of each bone's length (mm); the mean over
  tracks of each bone's, and the largest of those. Beside it the same for the per-frame joints (per ground-truth
  person) and for the ground truth itself (a twisting trunk changes the shoulder-to-hip sides by ~1 cm).
- **HOTA** (Luiten et al. 2021, ``trackeval``'s implementation) on a similarity built from 3D joint distances:
  ``max(0, 1 - d / gate_mm)`` with ``d`` the mean joint distance (mm) between a track and a person, so HOTA's
  thresholds alpha = 0.05 ... 0.95 are distances of 475 ... 25 mm at the default 500 mm gate (HOTA at alpha 0.5:
  within 250 mm). Beside it DetA and AssA, and the persons left out as for MOTA/IDF1.
- **Phantom tracks**: a track-frame is *on nobody* when no person in view (annotated or not) lies within
  ``gate_mm`` of it; a phantom is a confirmed track most of whose frames are on nobody. Their count, and the
  longest time any track spent on nobody (s, from its first to its last such frame with no frame on somebody
  between, plus one frame period).
- **Cost**: the tracker's milliseconds per frame (mean and 95th percentile).
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from pipeline.track import Tracker, bone_lengths, mean_joint_distance
from posenet.skeleton import BONES, NUM_JOINTS

MM_PER_CM = 10.0
# Issue 15's goals: (figure, comparison, bound).
GOALS = {
    "idf1": (">=", 0.95),
    "switches_per_1000": ("<=", 1.0),
    "mpjpe_ratio": ("<=", 0.9),
    "accel_ratio": ("<=", 0.5),
    "bone_std_max_mm": ("<=", 10.0),
    "track_ms_mean": ("<=", 2.0),
    "longest_on_nobody_s": ("<=", 1.0),  # no track on nobody longer than 1 s
    "background_ms_mean": ("<=", 3.0),  # the room's static depth, part of track_ms (given views)
}


# A track within this mean joint distance of a ground-truth person can be that person (the 3D gate of MOTA/IDF1).
GATE_MM = 500.0


@dataclass
class SequenceFrame:
    """One frame of a sequence: its time, the ground truth and the pipeline's persons.

    gt_ids: (G,) person ids; gt_joints: (G, J, 3) mm; joints: (P, J, 3) mm; spread: (P, J) mm; unsure: (P,)
    bool, persons that may only continue a track (``pipeline.track.Tracker.update``), or None; up: (3,) the
    room's up direction in the joints' frame, or None; ignore_joints: (I, J, 3) mm, persons in view whom the
    ground truth does not annotate (the module docstring), or None; views: the frame's
    ``posenet.scene.SceneView`` s, from which the tracker learns the room's static depth, or None.
    """

    timestamp_s: float
    gt_ids: np.ndarray
    gt_joints: np.ndarray
    joints: np.ndarray
    spread: np.ndarray
    unsure: np.ndarray | None = None
    up: np.ndarray | None = None
    ignore_joints: np.ndarray | None = None
    views: list | None = None  # the frame's views (depth and cameras) for the tracker's background, or None


def gated_pairs(people: np.ndarray, tracks: dict, gate_mm: float = GATE_MM) -> list[tuple[int, int]]:
    """``(person index, track id)`` pairs of the optimal assignment on the mean joint distance between ``people
    (G, J, 3)`` and the smoothed joints of ``tracks`` (``{track_id: person}``), pairs beyond ``gate_mm`` left out:
    the evaluation's gate."""
    people = np.asarray(people, float).reshape(-1, NUM_JOINTS, 3)
    if not tracks or not len(people):
        return []
    ids = list(tracks)
    dist = mean_joint_distance(people, np.array([tracks[t].joints for t in ids]))  # (G, T)
    rows, cols = linear_sum_assignment(np.where(dist <= gate_mm, dist, 1e9))
    return [(int(g), ids[t]) for g, t in zip(rows, cols, strict=True) if dist[g, t] <= gate_mm]


def _ignored(frame: SequenceFrame, tracks: dict, gate_mm: float) -> set:
    """The track ids of a frame's ``tracks`` (``{track_id: person}``) that :func:`gated_pairs` gives to a person of
    ``frame.ignore_joints`` rather than to an annotated one."""
    ignore = frame.ignore_joints
    if ignore is None or not len(ignore):
        return set()
    people = np.concatenate([frame.gt_joints.reshape(-1, NUM_JOINTS, 3), ignore.reshape(-1, NUM_JOINTS, 3)])
    return {t for g, t in gated_pairs(people, tracks, gate_mm) if g >= len(frame.gt_ids)}


def _bone_std(lengths: dict) -> tuple[list[float], float]:
    """Per bone, the mean over tracks of the std over time (mm), and its largest, from ``{track: [(B,), ...]}``."""
    per_track = [np.std(np.array(v), axis=0) for v in lengths.values() if len(v) >= 2]
    if not per_track:
        return [float("nan")] * len(BONES), float("nan")
    mean = np.mean(per_track, axis=0)
    return [round(float(x), 2) for x in mean], round(float(mean.max()), 2)


def _accel_error(series: dict) -> float:
    """Mean acceleration error (mm/frame^2) over ``{gt id: {frame: (pred (J, 3), gt (J, 3))}}``."""
    errors = []
    for frames in series.values():
        for f in frames:
            if f - 1 in frames and f + 1 in frames:
                pred = frames[f + 1][0] - 2 * frames[f][0] + frames[f - 1][0]
                gt = frames[f + 1][1] - 2 * frames[f][1] + frames[f - 1][1]
                errors.append(np.linalg.norm(pred - gt, axis=-1).mean())
    return round(float(np.mean(errors)), 2) if errors else float("nan")


def _on_nobody(frame: SequenceFrame, tracks: dict, gate_mm: float) -> set:
    """The track ids of a frame's ``tracks`` (``{track_id: person}``) with no person in view, annotated or not,
    within ``gate_mm`` (mean joint distance of the smoothed joints)."""
    people = [frame.gt_joints.reshape(-1, NUM_JOINTS, 3)]
    if frame.ignore_joints is not None:
        people.append(frame.ignore_joints.reshape(-1, NUM_JOINTS, 3))
    people = np.concatenate(people)
    if not tracks:
        return set()
    if not len(people):
        return set(tracks)
    ids = list(tracks)
    dist = mean_joint_distance(np.array([tracks[t].joints for t in ids]), people)  # (T, G)
    return {t for t, d in zip(ids, dist.min(1), strict=True) if d > gate_mm}


def phantoms(frames: list[SequenceFrame], hyps: list[dict], gate_mm: float = GATE_MM) -> dict:
    """Tracks on nobody (module docstring): ``phantom_tracks`` (confirmed tracks with more than half of their
    frames on nobody), ``on_nobody_track_frames``, and ``longest_on_nobody_s`` with the track it was."""
    times = np.array([f.timestamp_s for f in frames])
    period = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    frames_of, nobody_of = defaultdict(int), defaultdict(int)
    run_start: dict = {}  # track -> the first time of its current run on nobody
    longest, longest_track = 0.0, None
    for fr, hyp in zip(frames, hyps, strict=True):
        nobody = _on_nobody(fr, hyp, gate_mm)
        for t in hyp:
            frames_of[t] += 1
            if t in nobody:
                nobody_of[t] += 1
                start = run_start.setdefault(t, fr.timestamp_s)
                if fr.timestamp_s - start + period > longest:
                    longest, longest_track = fr.timestamp_s - start + period, t
            else:
                run_start.pop(t, None)
    return {
        "phantom_tracks": sum(nobody_of[t] > frames_of[t] / 2 for t in frames_of),
        "on_nobody_track_frames": int(sum(nobody_of.values())),
        "longest_on_nobody_s": round(longest, 3),
        "longest_on_nobody_track": longest_track,
    }


def hota(frames: list[SequenceFrame], hyps: list[dict], gate_mm: float = GATE_MM) -> dict:
    """HOTA, DetA and AssA (means over trackeval's alpha thresholds) and HOTA at alpha 0.5, with the similarity
    ``max(0, 1 - d / gate_mm)`` of the mean joint distance ``d`` (module docstring). ``hyps`` as :func:`score`
    reads them, the persons the ground truth leaves unannotated already left out."""
    try:
        from trackeval.metrics import HOTA
    except ImportError as exc:
        raise ImportError(
            "HOTA needs trackeval: pip install 'or-pose[eval]' (or pip install trackeval)"
        ) from exc

    gt_index, track_index = {}, {}  # trackeval counts ids from 0 with no gaps
    data: dict = {"gt_ids": [], "tracker_ids": [], "similarity_scores": []}
    for fr, hyp in zip(frames, hyps, strict=True):
        ids = list(hyp)
        smoothed = np.array([hyp[t].joints for t in ids]).reshape(len(ids), NUM_JOINTS, 3)
        dist = mean_joint_distance(fr.gt_joints.reshape(-1, NUM_JOINTS, 3), smoothed)  # (G, H)
        data["gt_ids"].append(np.array([gt_index.setdefault(int(g), len(gt_index)) for g in fr.gt_ids], int))
        data["tracker_ids"].append(np.array([track_index.setdefault(t, len(track_index)) for t in ids], int))
        data["similarity_scores"].append(np.maximum(0.0, 1.0 - dist / gate_mm))
    data["num_gt_ids"], data["num_tracker_ids"] = len(gt_index), len(track_index)
    data["num_gt_dets"] = sum(len(g) for g in data["gt_ids"])
    data["num_tracker_dets"] = sum(len(t) for t in data["tracker_ids"])
    metric = HOTA()
    res = metric.eval_sequence(data)
    half = int(np.argmin(np.abs(metric.array_labels - 0.5)))
    return {
        "hota": round(float(np.mean(res["HOTA"])), 4),
        "deta": round(float(np.mean(res["DetA"])), 4),
        "assa": round(float(np.mean(res["AssA"])), 4),
        "hota_at_half": round(float(res["HOTA"][half]), 4),
        "hota_similarity": f"max(0, 1 - mean joint distance / {gate_mm:g} mm)",
    }


@dataclass
class TrackedPerson:
    """A confirmed track's person in one frame: raw (J, 3) and smoothed (J, 3) joints, mm (as
    ``pipeline.track.Tracker.update`` gives them, or as the service's stream answered them)."""

    track_id: int
    raw: np.ndarray
    joints: np.ndarray


def run_tracker(
    frames: list[SequenceFrame], tracker: Tracker, background_ms: list | None = None
) -> tuple[list[dict], list[float]]:
    """Track the frames' persons: per frame ``{track_id: person}`` of the confirmed tracks, and the tracker's
    milliseconds per frame (``background_ms``, when given, gets the part its background model took)."""
    ms, hyps = [], []
    for fr in frames:
        t0 = time.perf_counter()
        out = tracker.update(fr.joints, fr.spread, fr.timestamp_s, fr.unsure, fr.up, fr.views)
        ms.append((time.perf_counter() - t0) * 1e3)
        if background_ms is not None:
            background_ms.append(tracker.background_ms)
        hyps.append({p.track_id: p for p in out if p.track_id is not None})
    return hyps, ms


def evaluate(
    frames: list[SequenceFrame], tracker: Tracker, gate_mm: float = GATE_MM, switch_events: bool = False
) -> dict:
    """Track one sequence's ``frames`` (in time order) with ``tracker`` and measure it (module docstring;
    ``switch_events``: as :func:`score`)."""
    background_ms: list[float] = []
    hyps, ms = run_tracker(frames, tracker, background_ms)
    figures = score(frames, hyps, ms, gate_mm, switch_events)
    if any(fr.views is not None for fr in frames):  # part of track_ms: the room's static depth
        figures["background_ms_mean"] = round(float(np.mean(background_ms)), 3)
    return figures


def _accumulate(frames: list[SequenceFrame], hyps: list[dict], gate_mm: float):
    """The ``motmetrics`` accumulator of ``hyps`` (per frame ``{track_id: person}``) against ``frames``' ground
    truth under the gate, the frames' tracks as scored (those on persons the ground truth leaves out dropped) and
    how many were dropped."""
    try:
        import motmetrics as mm  # imported here: pandas takes a while, and only the evaluation needs it
    except ImportError as exc:
        raise ImportError(
            "the tracking evaluation needs motmetrics: pip install 'or-pose[eval]' (or pip install motmetrics)"
        ) from exc

    if len(hyps) != len(frames):
        raise ValueError(f"{len(hyps)} frames of tracks for {len(frames)} frames of ground truth")
    acc = mm.MOTAccumulator(auto_id=True)
    ignored, kept = 0, []
    for fr, hyp in zip(frames, hyps, strict=True):
        left_out = _ignored(fr, hyp, gate_mm)
        ignored += len(left_out)
        hyp = {t: p for t, p in hyp.items() if t not in left_out}
        kept.append(hyp)
        confirmed = list(hyp.values())
        smoothed = np.array([p.joints for p in confirmed]).reshape(len(confirmed), NUM_JOINTS, 3)
        dist = mean_joint_distance(fr.gt_joints.reshape(-1, NUM_JOINTS, 3), smoothed)  # (G, H)
        acc.update(fr.gt_ids.tolist(), list(hyp), np.where(dist <= gate_mm, dist, np.nan))
    return acc, kept, ignored


def _switch_events(acc, frames: list[SequenceFrame], hyps: list[dict]) -> list[dict]:
    """:func:`switches` from the accumulator :func:`_accumulate` made of ``hyps``."""
    out, track_of, person_of, last_frame = [], {}, {}, {}
    for (f, _), ev in acc.mot_events.iterrows():
        if ev["Type"] not in ("MATCH", "SWITCH"):
            continue
        person, track = int(ev["OId"]), int(ev["HId"])
        if ev["Type"] == "SWITCH":
            out.append({
                "frame": int(f), "time_s": round(float(frames[f].timestamp_s), 3), "person": person,
                "from_track": track_of.get(person), "to_track": track, "to_track_was": person_of.get(track),
                "from_track_reported": track_of.get(person) in hyps[f],
                "unmatched_frames": int(f - last_frame[person] - 1) if person in last_frame else None,
            })  # fmt: skip
        track_of[person], person_of[track], last_frame[person] = track, person, int(f)
    return out


def switches(frames: list[SequenceFrame], hyps: list[dict], gate_mm: float = GATE_MM) -> list[dict]:
    """Each id switch that :func:`score` counts (``motmetrics``' SWITCH events), with what led to it: the frame
    and its time, the ``person``, the track it had (``from_track``) and the one it has now (``to_track``), whom
    ``to_track`` followed before (``to_track_was``: a person id, or None for a track new to the evaluation), whether
    ``from_track`` is still reported in that frame (on someone else, or on nobody), and for how many frames before
    it the person had no track (``unmatched_frames``: a lost track and a new one, against a swap on the spot)."""
    return _switch_events(_accumulate(frames, hyps, gate_mm)[0], frames, hyps)


def score(
    frames: list[SequenceFrame],
    hyps: list[dict],
    ms: list[float],
    gate_mm: float = GATE_MM,
    switch_events: bool = False,
) -> dict:
    """Measure tracks against the ground truth (module docstring).

    Args:
        frames: the sequence in time order (only the ground truth and the time are read).
        hyps: per frame, ``{track_id: person}`` of the confirmed tracks; a person has ``raw`` and ``joints``
            (smoothed), (J, 3) mm: :func:`run_tracker`'s, or :class:`TrackedPerson` s of a served stream.
        ms: the tracker's milliseconds per frame.
        switch_events: also list each id switch (``"switch_events"``: :func:`switches`, from the same matching).
    """
    acc, kept, ignored = _accumulate(frames, hyps, gate_mm)
    import motmetrics as mm

    mh = mm.metrics.create()
    summary = mh.compute(acc, metrics=["mota", "idf1", "num_switches", "num_objects", "num_false_positives",
                                       "num_misses", "num_frames"], name="s")  # fmt: skip
    row = summary.loc["s"]
    # The matched pairs (frame, gt id, track id), as motmetrics matched them.
    events = acc.mot_events
    pairs = events[events["Type"].isin(["MATCH", "SWITCH"])]
    raw_err, smooth_err = [], []
    raw_series, smooth_series = defaultdict(dict), defaultdict(dict)
    raw_bones, smooth_bones, gt_bones = defaultdict(list), defaultdict(list), defaultdict(list)
    for (f, _), ev in pairs.iterrows():
        fr, gid, tid = frames[f], int(ev["OId"]), int(ev["HId"])
        gt = fr.gt_joints[list(fr.gt_ids).index(gid)]
        person = hyps[f][tid]
        raw_err.append(np.linalg.norm(person.raw - gt, axis=-1).mean())
        smooth_err.append(np.linalg.norm(person.joints - gt, axis=-1).mean())
        raw_series[gid][f] = (person.raw, gt)
        smooth_series[gid][f] = (person.joints, gt)
        raw_bones[gid].append(bone_lengths(person.raw))
        smooth_bones[tid].append(bone_lengths(person.joints))
        gt_bones[gid].append(bone_lengths(gt))
    objects = int(row["num_objects"])
    mpjpe_raw = float(np.mean(raw_err)) / MM_PER_CM if raw_err else float("nan")
    mpjpe_smooth = float(np.mean(smooth_err)) / MM_PER_CM if smooth_err else float("nan")
    accel_raw, accel_smooth = _accel_error(raw_series), _accel_error(smooth_series)
    bones_smooth, bones_smooth_max = _bone_std(smooth_bones)
    bones_raw, bones_raw_max = _bone_std(raw_bones)
    bones_gt, bones_gt_max = _bone_std(gt_bones)
    return {
        "frames": len(frames),
        "gt_person_frames": objects,
        "tracks": len({t for h in hyps for t in h}),
        "gt_persons": len({int(i) for fr in frames for i in fr.gt_ids}),
        "mota": round(float(row["mota"]), 4),
        "idf1": round(float(row["idf1"]), 4),
        "id_switches": int(row["num_switches"]),
        "switches_per_1000": round(1000 * int(row["num_switches"]) / max(objects, 1), 2),
        "false_positives": int(row["num_false_positives"]),
        "ignored_track_frames": ignored,  # tracks on persons in view that the ground truth does not annotate
        "misses": int(row["num_misses"]),
        "mpjpe_per_frame_cm": round(mpjpe_raw, 2),
        "mpjpe_smoothed_cm": round(mpjpe_smooth, 2),
        "mpjpe_ratio": round(mpjpe_smooth / mpjpe_raw, 3),
        "accel_per_frame_mm": accel_raw,
        "accel_smoothed_mm": accel_smooth,
        "accel_ratio": round(accel_smooth / accel_raw, 3),
        "bone_std_mm": bones_smooth,
        "bone_std_max_mm": bones_smooth_max,
        "bone_std_per_frame_max_mm": bones_raw_max,
        "bone_std_per_frame_mm": bones_raw,
        "bone_std_ground_truth_max_mm": bones_gt_max,
        "bone_std_ground_truth_mm": bones_gt,
        **hota(frames, kept, gate_mm),
        **phantoms(frames, hyps, gate_mm),
        "track_ms_mean": round(float(np.mean(ms)), 3),
        "track_ms_p95": round(float(np.percentile(ms, 95)), 3),
        "gate_mm": gate_mm,
        **({"switch_events": _switch_events(acc, frames, hyps)} if switch_events else {}),
    }


# Why an annotated person-frame has no confirmed track on it (:func:`breakdown`), in the order they are tested.
MISSED = (
    "no skeleton within the gate",  # the pipeline gave nobody there: the detector, or the pose network
    "only a neighbour's skeleton",  # one skeleton for two people close together: it went to the other
    "own skeleton not tracked: spread",  # the tracker's filters (TrackerConfig.max_spread_mm,
    "own skeleton not tracked: torso",  # min_torso_mm, min_height_mm)
    "own skeleton not tracked: height",
    "own skeleton on a tentative track",  # birth_hits, the phantom cues or the lying rule not yet met
    "own skeleton on a parked track",  # no sign of life for park_s (TrackerConfig.park_suspends)
    "own skeleton near a neighbour's track",  # within duplicate_mm of a track another person's skeleton took
    "own unsure skeleton near a neighbour's track",
    "own unsure skeleton, no track within reach",  # no confirmed track left within unsure_gate_mm
    "own skeleton, its track went to another person",  # or its smoothed joints lie beyond the gate
    "own skeleton, no track took it",
)
FALSE = (
    "on nobody",  # no person in view within the gate: a phantom's frames
    "second track on a person, or too far from them",
)


def breakdown(frames: list[SequenceFrame], tracker: Tracker, gate_mm: float = GATE_MM) -> dict:
    """Where the tracks lose person-frames: ``tracker`` over ``frames`` (in time order), then per frame the optimal
    assignment under the gate (:func:`gated_pairs`, as the evaluation matches; tracks on persons the ground truth
    leaves out are left out) between the annotated persons and the confirmed tracks.

    Every annotated person-frame that no confirmed track matches is given the first reason of :data:`MISSED` that
    holds. Its "own skeleton" is the pipeline's person that the optimal assignment under the gate between the
    annotated persons and all the frame's pipeline persons (sure and unsure) gives it. Every confirmed track-frame
    left unmatched is a false positive of :data:`FALSE`.

    Returns ``{"person_frames", "tracked", "missed": {reason: count}, "false_positives": {reason: count}}`` with
    every reason listed, zero or not."""
    c = tracker.config
    missed, false = dict.fromkeys(MISSED, 0), dict.fromkeys(FALSE, 0)
    person_frames = tracked = 0
    for fr in frames:
        out = tracker.update(fr.joints, fr.spread, fr.timestamp_s, fr.unsure, fr.up, fr.views)
        hyp = {p.track_id: p for p in out if p.track_id is not None}
        left_out = _ignored(fr, hyp, gate_mm)
        hyp = {t: p for t, p in hyp.items() if t not in left_out}
        gt = fr.gt_joints.reshape(-1, NUM_JOINTS, 3)
        matched = dict(gated_pairs(gt, hyp, gate_mm))  # person -> track
        person_frames += len(gt)
        tracked += len(matched)
        persons = {p.detection: p for p in out}
        own = dict(
            gated_pairs(gt, {p.detection: TrackedPerson(p.detection, p.raw, p.raw) for p in out}, gate_mm)
        )
        refused = tracker._refused(fr.joints, *tracker._measures(fr.joints, fr.spread, fr.up))  # (3, P)
        taken = [p for p in out if p.track_id is not None or p.tentative or p.parked]
        for g in range(len(gt)):
            if g in matched:
                continue
            if g not in own:
                near = len(out) and mean_joint_distance(gt[g : g + 1], fr.joints).min() <= gate_mm
                missed[MISSED[1] if near else MISSED[0]] += 1
                continue
            p = persons[own[g]]
            unsure = fr.unsure is not None and bool(fr.unsure[p.detection])
            neighbours = [q.joints for q in taken if q.detection != p.detection]
            if refused[:, p.detection].any():  # the first filter that refuses it: spread, torso, height
                reason = MISSED[2 + int(np.argmax(refused[:, p.detection]))]
            elif p.tentative:
                reason = MISSED[5]
            elif p.parked:
                reason = MISSED[6]
            elif p.track_id is not None:
                reason = MISSED[10]
            elif neighbours and mean_joint_distance(p.raw[None], np.array(neighbours)).min() < c.duplicate_mm:
                reason = MISSED[8] if unsure else MISSED[7]
            elif unsure:
                reason = MISSED[9]
            else:
                reason = MISSED[11]
            missed[reason] += 1
        people = (
            gt
            if fr.ignore_joints is None
            else np.concatenate([gt, fr.ignore_joints.reshape(-1, NUM_JOINTS, 3)])
        )
        for t in set(hyp) - set(matched.values()):
            near = len(people) and mean_joint_distance(hyp[t].joints[None], people).min() <= gate_mm
            false[FALSE[1] if near else FALSE[0]] += 1
    return {"person_frames": person_frames, "tracked": tracked, "missed": missed, "false_positives": false}


def goal_lines(figures: dict) -> list[str]:
    """One line per goal of :data:`GOALS`: the figure, the bound and whether it is met."""
    lines = []
    for key, (op, bound) in GOALS.items():
        if key not in figures:  # background_ms_mean: only when the tracker was given views
            continue
        value = figures[key]
        met = value >= bound if op == ">=" else value <= bound
        lines.append(f"{key:>20} {value:>8} (goal {op} {bound}) {'met' if met else 'NOT met'}")
    return lines
