"""Tracking persons over time: ids that persist, smoothed joints, bones of constant length.

Each frame's persons (3D skeletons ``(P, J, 3)`` in mm, reference frame, with the pose network's per-joint spread
``(P, J)`` in mm) are linked to tracks in three steps:

1. **Predict and assign.** Persons whose median joint spread is above ``max_spread_mm`` are not tracked, nor
   skeletons with a torso (neck to mid-hip) shorter than ``min_torso_mm``, which no adult has, nor, when the
   frame comes with the room's up direction, skeletons spanning less than ``min_height_mm`` along it (lying). Every
   track predicts its skeleton at the frame's time with a constant-velocity Kalman
   filter per joint (the three axes share one 2x2 covariance, since the measurement noise is isotropic). The cost
   of giving person p to track t is the mean distance between p's joints and t's prediction; pairs beyond a gate
   (``gate_mm``, widened by ``coast_speed_mm_s`` for each second a track has gone unseen) are forbidden, and
   scipy's ``linear_sum_assignment`` picks the cheapest assignment.
   Persons the detector was unsure of (``unsure``: every box scored below its threshold,
   ``pipeline.skeleton_matching.group_unsure``) come second: they may only continue a confirmed track that no
   sure person took in this frame, within ``unsure_gate_mm`` of its prediction, and never start one
   (ByteTrack's second association). One within ``duplicate_mm`` of a track a sure person took is that person
   seen again, and continues nothing. A person half behind a monitor, boxed with a score of 0.3, keeps their
   track.
2. **Hysteresis.** A person that no track takes starts a *tentative* track, unless it lies within
   ``duplicate_mm`` of a track already seen in this frame (a second detection of the same person), or of another
   person starting one in this frame (one person that the matcher split: the one with the lower spread starts
   it; ``births_apart``). A tentative
   track is *confirmed*, and gets its id, after ``birth_hits`` consecutive frames, unless over those frames it looks
   like a person lying down under a drape (with the room's up: the medians of its skeleton's height along up below
   ``lying_height_mm`` and of its joints' spread above ``lying_spread_mm``); such a track stays tentative and is
   judged again on its last ``birth_hits`` frames at each frame. A tentative track dies at its first miss. A
   confirmed track coasts (predicted, not reported) for up to ``max_coast_s`` without a detection, so it picks
   its person up again after a short occlusion; then it ends. Given the frames' views (depth and cameras), a
   tentative track is confirmed only once its person was seen to move, to stand in front of the room's static
   depth (``pipeline.background``) or to hold a sure upright pose; a confirmed track whose person shows none of
   these for ``park_s`` (unseen frames count) is *parked*: answered without its id until they do again
   (``TrackerConfig.move_mm`` and ``park_s`` say how).
3. **Smooth and keep the bones.** The Kalman update weighs each joint by its measurement variance
   ``(spread_scale x spread)^2``, so uncertain joints move less. Each track keeps the recent lengths of every
   bone of ``posenet.skeleton.BONES`` as measured; its bone-length prior is an adult's proportions
   (``posenet.skeleton.BONE_TEMPLATE_MM``) scaled to the person (the median of its per-frame scales, pulled
   towards the average adult while it has few frames). From the first frame on, the filtered joints are projected
   (Jacobi passes) so that no bone is more than ``bone_tolerance_mm`` longer or shorter than its prior, each end
   moving in proportion to its variance.
   The corrected joints become the filter's state.

Usage::

    tracker = Tracker()
    for t, (joints, spread) in frames:            # (P, J, 3) mm and (P, J) mm, time in seconds
        for person in tracker.update(joints, spread, t):
            person.detection, person.track_id, person.joints   # track_id None while tentative or parked
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import MISSING, dataclass, field, fields

import numpy as np
from scipy.optimize import linear_sum_assignment

from pipeline.background import TORSO, BackgroundConfig, DepthBackground
from posenet.scene import SceneView
from posenet.skeleton import BONE_TEMPLATE_MM, BONES, JOINT_INDEX, NUM_JOINTS

_A = np.array([a for a, _ in BONES])
_B = np.array([b for _, b in BONES])
RELAXATION = 0.5
_TO_A = np.eye(NUM_JOINTS)[:, _A]  # (J, B): bone b starts at joint j
_TO_B = np.eye(NUM_JOINTS)[:, _B]
_BONE_OF = np.eye(NUM_JOINTS)[_B] - np.eye(NUM_JOINTS)[_A]  # (B, J): bone b = joint B[b] - joint A[b]


@dataclass
class TrackerConfig:
    # Association. Persons are >= 48 cm apart (pelvis to pelvis) and the pose network's joints are off by ~9 cm,
    # so a skeleton 40 cm from a track's prediction is someone else.
    gate_mm: float = 400.0
    coast_speed_mm_s: float = 1500.0  # how fast an unseen person may have walked on (widens the gate)
    duplicate_mm: float = 300.0  # an unclaimed person this close to a claimed track is the same person again
    # A person the detector was unsure of continues a confirmed track no sure person took when it lies within
    # this of the track's prediction (not widened while the track is unseen). None: unsure persons are ignored.
    # Chosen on six tuning sequences (seeds 1-6, 2,768 person-frames; offline with the views read as the service
    # decodes them, detector mode, 2026-12-03): none / 150 / 200 / 250 / 300 mm gave an IDF1 (weighted by
    # person-frames) of 0.696 / 0.705 / 0.708 / 0.714 / 0.714, misses 979 / 938 / 897 / 887 / 882, id switches
    # 9 / 9 / 8 / 7 / 7. Without the duplicate rule (below) 250 mm gave 0.675: unsure second skeletons of a
    # tracked person kept a vanished neighbour's track alive, which then took someone else.
    unsure_gate_mm: float | None = 250.0
    # Persons whose median joint spread is above this are not tracked at all (reported without a track): badly
    # grouped boxes, and (before min_torso_mm) the draped patient. 400 mm until 2026-12-03; with the torso filter
    # and the partition matcher, chosen again on the tuning sequences (seed 1, 120 frames, and seed 2, 300 frames
    # with 4 persons; offline, detector mode): 400 / 500 / 600 / 800 / 1200 mm gave IDF1 0.619 / 0.625 / 0.625 /
    # 0.643 / 0.641 and 0.590 / 0.641 / 0.651 / 0.547 / 0.519, with 3 / 4 / 2 / 4 / 8 id switches on the second
    # (at 400 mm, 163 of its person-frames with a skeleton within 50 cm were dropped here, spread 400-490 mm).
    max_spread_mm: float = 600.0
    # Skeletons whose torso (neck to the middle of the hips) is shorter than this are not tracked either: an
    # adult's is ~45-55 cm. On the rendered sequences the pose network gives the draped patient on the table
    # (no pose of MVOR's ground truth) a folded skeleton with a torso of 10-40 cm and a spread below
    # max_spread_mm. Chosen on the tuning sequence (seed 1, detector mode): at 38 cm it drops 103 of the 105
    # skeletons within max_spread_mm that are nobody's, and none of the 146 within 30 cm of a clinician.
    # Lowered to 25 cm on 2026-12-04, since the lying rules below keep the patient untracked: with
    # two pose weight sets of 2026-12-04 (A, then B) the rule cost more clinicians' frames than it saved (clinicians seen
    # by one camera or half hidden get a short torso), on five tuning sequences (seeds 1, 3-6, 1,825 person-frames,
    # offline, detector mode) 38 / 34 / 30 / 27.5 / 25 / 22.5 / 0 cm gave an IDF1 (weighted) of 0.688 / 0.703 /
    # 0.709 / 0.710 / 0.747 / 0.746 / 0.747 with weights B (misses 630 -> 546, false positives 43 -> 66,
    # switches 15 -> 9 at 25 cm), 0.702 / - / 0.730 / - / 0.734 / - / 0.740 with weights A.
    min_torso_mm: float = 250.0
    # Given the room's up direction with a frame, skeletons that span less than this along it are not tracked: a
    # person lying down, on the rendered sequences the draped patient on the table (MVOR annotates no patient),
    # whose skeleton the pose network sometimes unfolds to an adult's torso that min_torso_mm lets through.
    # Chosen on the six tuning sequences (seeds 1-6, detector mode, the per-frame skeletons that pass the two
    # filters above): the 5th / 50th / 95th percentile of the height spanned is 411 / 568 / 710 mm for skeletons
    # within 50 cm of a clinician, 101 / 136 / 366 mm for those more than 1 m from anyone; below 200 / 250 / 300 /
    # 350 mm lie 3 / 6 / 6 / 49 of the 1,888 clinicians' and 115 / 119 / 119 / 121 of the 128 nobody's. Raised
    # from 250 to 300 with the first pose weights of 2026-12-04, which unfold the patient further: on five
    # of them (seeds 1, 3-6) their clinicians span 434 / 569 / 697 mm (5th / 50th / 95th percentile), and below
    # 250 / 300 / 350 mm lie 17 / 18 / 25 of their 1,831 clinicians' and 125 / 131 / 132 of their 246 nobody's
    # skeletons; the tracks' IDF1 (weighted) is 0.721 from 250 to 350 mm (docs/tracking.md, "The patient again").
    min_height_mm: float = 300.0
    # A tentative track is not confirmed while, over its last birth_hits frames, its skeleton's median height along
    # the room's up is below lying_height_mm AND its median joint spread above lying_spread_mm: the draped patient
    # whose skeleton the pose network unfolds to more than min_height_mm but cannot place (weights A of 2026-12-04
    # tracked it on the evaluation sequence for 32 frames, heights 302-330 mm, spread 552 mm). Chosen on five
    # tuning sequences (seeds 1, 3-6; detector mode, offline, with weights A and B of 2026-12-04; both
    # rules off so that the patient is tracked there; `benchmarks/tracking.py --births`): over their first 3
    # frames the 6 tracks of the patient spanned 71-268 mm with spreads 424-550 mm; the 7 clinicians' tracks lower
    # than 450 mm (381-443) had spreads of 236-374 mm, and the 8 with spreads above 400 mm (457-531) spanned
    # 480-666 mm. Both thresholds sit in those gaps. With min_height_mm at 300 the tuning sequences' IDF1 moves
    # 0.703 -> 0.702 (3 clinician frames wait) and 0.688 -> 0.688; with it off, this rule alone cuts their false
    # positives 273 -> 103 and 303 -> 107 (IDF1 0.654 -> 0.683, 0.634 -> 0.663). None: off.
    lying_height_mm: float | None = 450.0
    lying_spread_mm: float = 400.0
    # Hysteresis: births need consecutive hits; a confirmed track survives short occlusions.
    birth_hits: int = 3
    # Phantoms: given the frames' views (depth and cameras), a tentative track is confirmed only once
    # the stream has seen its person move (its torso's filtered centre more than move_mm from where the track was
    # born), stand where the room's static depth is not (over its last birth_hits frames, a median share of at least
    # foreground_share of its seen torso joints in front of pipeline.background's model), or hold a pose no static
    # object explains (a median joint spread of at most pose_spread_mm and, with the room's up, a height along it of
    # at least pose_height_mm: an upright skeleton the pose network is sure of). Without views nothing changes.
    # The pose cue, chosen on the tuning sequence seed 50 (twin look, 5 persons, 200 frames; shipped weights,
    # detector mode, 2026-12-06): of the skeletons within 50 cm of a clinician 53 % pass at 400 / 450 mm, of the 192
    # on nobody none (at 450 mm of spread, 0.5 %); at 150 mm none of either passes, and people still since the
    # stream's first frame wait until they move (its misses 102 -> 201). move_mm and foreground_share changed
    # nothing there between 100 and 300 mm and in 0.5 +- 0.1.
    move_mm: float = 300.0
    foreground_share: float = 0.5
    # The same cues keep a confirmed track reported: one whose person shows none of them for park_s (its detections
    # all behind the background's margin, a torso that stays within move_mm, no sure upright pose), as when a track
    # passes from its person to the draped table, is parked (None: never). Half the 1 s a track may spend on nobody
    # (the goal); a confirmed person standing still stays in front of the background (its pixels are never absorbed).
    # The stillness clock (static_s) runs while the track's person shows no cue and, with park_suspends, while the
    # track is unseen; each second with a cue takes park_recovery seconds off it (inf: a cue resets it).
    # park_suspends: a parked track is not ended but suspended: its persons are answered without a track id until
    # the clock is back under park_s, and it ends as any track does, after max_coast_s unseen; without it (before
    # 2026-12-07) a parked track ended and its person, once alive again, got a new id. A phantom on a static
    # object is seen every other frame and its skeleton jumps (a "move" now and then): before, the clock stopped
    # while it was unseen and any single cue reset it. Chosen on six tuning sequences (seeds 50-55, 200 frames,
    # 4-5 persons, two of them with hard negatives; twin, random and mesh looks; shipped weights, detector mode,
    # 2026-12-07): as before (ended; a cue resets the clock) / suspended, the clock running unseen, recovery inf /
    # 1 / 2 / 4 gave an IDF1 (weighted) of 0.821 / 0.823 / 0.814 / 0.828 / 0.830, switches 15 / 15 / 9 / 10 / 13,
    # false positives 168 / 152 / 44 / 64 / 97, misses 414 / 412 / 589 / 488 / 439, longest on nobody 2.47 / 4.80 /
    # 1.13 / 2.13 / 2.13 s: 2 has 4's IDF1 and HOTA (0.629) with a third fewer false positives. Ended, with the clock
    # running unseen: IDF1 0.750 (people coasting behind others lost their ids).
    park_s: float | None = 0.5
    park_recovery: float = 2.0
    park_suspends: bool = True
    pose_spread_mm: float | None = 400.0  # None: no pose cue
    pose_height_mm: float = 450.0
    background: BackgroundConfig = field(default_factory=BackgroundConfig)
    # Identity by the body: a multi-view RGB-D rig measures each person's size. A person's signature is
    # their skeleton's scale against the average adult (frame_scales: the median over bones of length / template,
    # which also carries the body's width: shoulders and hips), per frame; a track's is the median of its frames'.
    # signature_mm adds this many mm to the association cost per 1.0 of difference between a person's scale and a
    # track's with at least signature_min_frames frames (0: off). reid_s: a confirmed track that ended (no
    # detection for max_coast_s), or one coasting unseen, gives its id to a new track confirmed within reid_s
    # whose scale over its first frames lies within reid_scale_tol of its own, and nearer by reid_margin than any
    # other's (0: off). Both off: the per-frame scale of the pose network's skeletons is no signature yet (a
    # clinician's varies by 0.03-0.15 interquartile within a track, partly seen people shrink by up to 0.23,
    # statures by 0.05); on the tuning sequences (seeds 50, 51) signature_mm 300 gave IDF1 0.558 / 0.916 -> 0.562 /
    # 0.676, reid_s 60 no change (docs/tracking.md, "Identity: the body's size").
    signature_mm: float = 0.0
    signature_min_frames: int = 10
    reid_s: float = 0.0
    reid_scale_tol: float = 0.05
    reid_margin: float = 0.03
    # Two persons born in one frame within duplicate_mm of each other are one person that the matcher split: only
    # the one with the lower median spread starts a track (the other is then "near a seen track" from the next frame
    # on, and starts none). Before 2026-12-04 both started one, and both were confirmed: on the tuning
    # sequence (seed 1) one clinician split into two persons 18 cm apart in frame 0 kept two tracks for 54 frames,
    # with 6 id switches between them. On five tuning sequences (seeds 1, 3-6, 1,825 person-frames, offline, detector
    # mode, weights B of 2026-12-04) off / on gave an IDF1 (weighted) of 0.747 / 0.766, false positives 66 / 26, id
    # switches 9 / 3, misses 546 / 546.
    births_apart: bool = True
    # A confirmed track coasts this long unseen before it ends. 1.5 s until 2026-12-05; chosen again on eight
    # tuning sequences (seeds 1, 3-9: five of 120-150 frames, three of 300 frames with 4 persons rendered for it;
    # offline, the shipped weights' pipeline persons, `benchmarks/tracking.py`): 1.5 / 2 / 2.5 / 3 / 5 s gave an IDF1
    # (weighted) of 0.765 / 0.781 / 0.786 / 0.762 / 0.762, false positives 29 / 29 / 29 / 40 / 42, switches 7 / 7 /
    # 6 / 9 / 9 (3 s with the gate widening at 750 instead of 1,500 mm/s: 0.785). 2.5 s is at least 1.5 s's IDF1 on
    # seven of the eight; a longer coast lets a track's widening gate take someone else (seed 8). Through the
    # service on the held-out sequences: evaluation and alt unchanged (0.910, 0.882), long 0.749 -> 0.799
    # (switches 4 -> 3, false positives 5 -> 7 person-frames).
    max_coast_s: float = 2.5
    coast_velocity_decay: float = 0.7  # per unseen frame: a coasting person is assumed to slow down
    # Smoothing: constant velocity with white acceleration noise, measurement std = spread_scale * spread.
    accel_noise_mm_s2: float = 4000.0  # q of Q = q^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]]
    spread_scale: float = 1.0
    min_measurement_std_mm: float = 10.0
    initial_speed_std_mm_s: float = 1000.0
    # Bone-length prior: an adult's proportions (posenet.skeleton.BONE_TEMPLATE_MM) scaled to the person, from
    # the first frame on. Chosen on the tuning sequence (seed 1, detector mode, 2026-12-03): per-bone medians
    # gave a worst bone std of 26 mm there, mostly from a track's first frames (uncorrected until 5 lengths were
    # in, then a prior that moved as it filled); one scale for the whole body, corrected from the first frame
    # and pulled towards the average adult while young, 6.6 mm, at a lower smoothed MPJPE (0.93x against 0.96x).
    bone_history: int = 150  # frames of measured lengths kept per track (10 s at 15 fps)
    bone_min_frames: int = 1
    bone_tolerance_mm: float = 2.0
    bone_iterations: int = 20  # Jacobi passes: 20 take 0.4 ms per frame; 15 / 20 / 30 gave 6.9 / 6.7 / 6.6 mm
    # How many frames' worth of trust the template's proportions get: a bone's prior is (n median + k scaled
    # template) / (n + k) after n measured lengths of it. inf: one scale for the whole body (the default); 0:
    # each bone's own median alone.
    bone_template_frames: float = math.inf
    # How many frames' worth of trust the average adult's scale (1.0: the template itself) gets against the
    # median of the track's per-frame scales (each the median over bones of length / template). 10 until
    # 2026-12-03; with the detector of that day, which also boxes people cut by the image edge, the measured
    # scales wandered (one track's shoulder-to-hip length drifted 400 -> 350 mm over 42 frames; truth 426 mm),
    # and so did every corrected bone.
    # Chosen again offline on the two tuning sequences (seeds 1 and 2): 10 / 30 / 100 / 300 / inf gave a worst
    # bone std of 11.2 / 8.6 / 5.3 / 3.3 / 2.2 and 16.6 / 14.2 / 9.6 / 5.5 / 1.9 mm, smoothed / per-frame MPJPE
    # 0.924 / 0.918 / 0.913 / 0.911 / 0.910 and 1.068 / 1.045 / 1.007 / 0.983 / 0.981. 300 (20 s at 15 fps)
    # keeps a per-person scale for long tracks at nearly the average adult's accuracy.
    bone_scale_prior_frames: float = 300.0

    def __setstate__(self, state: dict) -> None:
        """Unpickle, the fields a pickle of an older version lacks at their defaults (a stream's tracker kept in the
        Redis store across an upgrade of the service)."""
        for f in fields(self):
            if f.name not in state:
                state[f.name] = f.default_factory() if f.default is MISSING else f.default
        self.__dict__.update(state)


@dataclass
class TrackedPerson:
    """One person of a frame, as the tracker reports it.

    Attributes:
        detection: the person's index in the frame's input.
        track_id: its track's id (ids count up from 0 in order of confirmation), None while tentative.
        joints: (J, 3) mm, smoothed and bone-corrected.
        raw: (J, 3) mm, the input joints.
        tentative: a track took the person but is not confirmed yet (``track_id`` None); False when no track took
            it or its track is confirmed.
        parked: a confirmed track took the person but is parked (``TrackerConfig.park_suspends``: ``track_id``
            None until it shows a sign of life again).
    """

    detection: int
    track_id: int | None
    joints: np.ndarray
    raw: np.ndarray
    tentative: bool = False
    parked: bool = False


def _norm(x: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(x, axis=-1)`` of real ``x``, the same sums without its checks (a tracker's frame makes
    dozens of small calls, where the checks cost more than the sums)."""
    return np.sqrt((x * x).sum(-1))


def _middle(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """``np.median(x, axis)``, the same values (the two middle ones averaged for an even count; NaN where a slice
    holds a NaN) without its partition's overhead on small arrays."""
    s = np.sort(x, axis=axis)
    n = s.shape[axis]
    lo, hi = np.take(s, (n - 1) // 2, axis=axis), np.take(s, n // 2, axis=axis)
    return np.where(np.isnan(np.take(s, n - 1, axis=axis)), np.nan, (lo + hi) / 2)  # NaN sorts last


def _taken(track_of: np.ndarray, n_tracks: int) -> np.ndarray:
    """``(T,)`` which of ``n_tracks`` tracks a person takes, from each person's track ``track_of (P,)`` (-1: none);
    ``np.isin(np.arange(n_tracks), track_of)`` without its overhead."""
    taken = np.zeros(n_tracks, bool)
    taken[track_of[track_of >= 0]] = True
    return taken


def mean_joint_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(N, M)`` mean distance over joints between skeletons ``a (N, J, 3)`` and ``b (M, J, 3)``."""
    return _norm(a[:, None] - b[None]).mean(-1)


def bone_lengths(joints: np.ndarray) -> np.ndarray:
    """``(..., B)`` lengths of :data:`posenet.skeleton.BONES` in skeletons ``(..., J, 3)``."""
    return _norm(joints[..., _B, :] - joints[..., _A, :])


def torso_length(joints: np.ndarray) -> np.ndarray:
    """``(...)`` mm from the neck to the middle of the hips, in skeletons ``(..., J, 3)``."""
    hips = (joints[..., JOINT_INDEX["left_hip"], :] + joints[..., JOINT_INDEX["right_hip"], :]) / 2
    return _norm(joints[..., JOINT_INDEX["neck"], :] - hips)


def reaching(targets: np.ndarray, persons: np.ndarray, gate_mm: float) -> np.ndarray:
    """``(Q,)`` which ``persons (Q, J, 3)`` lie within ``gate_mm`` (mean joint distance, 1 mm more for float32
    rounding) of one of ``targets (K, J, 3)`` (``Tracker.unsure_targets``): the persons of unsure boxes that may
    continue a track."""
    persons = np.asarray(persons, float).reshape(-1, NUM_JOINTS, 3)
    if not len(targets) or not len(persons):
        return np.zeros(len(persons), bool)
    return (mean_joint_distance(np.asarray(targets, float), persons) <= gate_mm + 1.0).any(0)


def skeleton_height(joints: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``(...)`` mm the skeletons ``(..., J, 3)`` span along the direction ``up (3,)`` (any length)."""
    h = joints @ (np.asarray(up, float) / np.linalg.norm(up))  # (..., J)
    return h.max(-1) - h.min(-1)


def project_bones(
    joints: np.ndarray, prior: np.ndarray, variance: np.ndarray, tolerance: float, iterations: int
) -> np.ndarray:
    """Move joints so that each bone's length is within ``tolerance`` mm of ``prior``.

    Args:
        joints: (T, J, 3) mm; prior: (T, B) mm (NaN: no prior, that bone is left alone); variance: (T, J) mm^2,
            how freely each joint may move (a bone's correction is shared between its ends in this proportion).
    Jacobi passes: every bone's correction is computed at once and each joint moves by half the sum of its
    bones' (the half keeps a joint shared by three bones from overshooting). Each pass is two small products:
    the bones from the joints, and the joints' moves from the bones' corrections (half the time of gathers).
    """
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ValueError(f"joints must be (T, {NUM_JOINTS}, 3), got {joints.shape}")
    x = joints.copy()
    wa = variance[:, _A] / np.maximum(variance[:, _A] + variance[:, _B], 1e-9)  # (T, B)
    # (T, J, B): how joint j moves with bone b's step, its start by wa of it, its end by -(1 - wa)
    move = _TO_A[None] * wa[:, None, :] - _TO_B[None] * (1 - wa)[:, None, :]
    known = np.isfinite(prior)
    target = np.where(known, prior, 0.0)
    high = np.where(known, float(tolerance), np.inf)  # a bone without a prior is never out of its band
    low = -high
    for _ in range(iterations):
        d = _BONE_OF @ x  # (T, B, 3)
        length = np.maximum(np.sqrt((d * d).sum(-1)), 1e-6)  # (T, B)
        excess = length - target
        err = excess - np.minimum(np.maximum(excess, low), high)  # np.clip's values, without its overhead
        if not err.any():
            break
        x += move @ ((RELAXATION * err / length)[..., None] * d)  # shortens (err > 0) or lengthens each bone
    return x


def _median(values: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """The median along ``axis`` ignoring NaN (NaN where there is no value), and the count of values."""
    count = np.isfinite(values).sum(axis)
    ordered = np.sort(values, axis=axis)  # NaN sorts last
    lo = np.take_along_axis(ordered, np.expand_dims(np.maximum((count - 1) // 2, 0), axis), axis)
    hi = np.take_along_axis(ordered, np.expand_dims(np.maximum(count // 2, 0), axis), axis)
    median = np.squeeze((lo + hi) / 2, axis)
    return np.where(count > 0, median, np.nan), count


def frame_scales(lengths: np.ndarray) -> np.ndarray:
    """``(...)`` each skeleton's scale against the average adult: the median over bones of its bone ``lengths
    (..., B)`` over ``BONE_TEMPLATE_MM`` (NaN ignored; NaN without any)."""
    return _median(lengths / np.asarray(BONE_TEMPLATE_MM), -1)[0]


def robust_prior(
    history: np.ndarray,
    min_count: int,
    template_frames: float = 0.0,
    scale_prior_frames: float = 0.0,
    scales: np.ndarray | None = None,
) -> np.ndarray:
    """``(T, B)`` each bone's length prior from ``history (T, H, B)`` of measured lengths (NaN: none yet).

    The median of the bone's lengths, pulled towards ``BONE_TEMPLATE_MM`` scaled to the person with the weight of
    ``template_frames`` measured frames (inf: the scaled template alone). The person's scale is the median over
    frames of each frame's median over bones of length / template (:func:`frame_scales`; ``scales (T, H)`` when
    already known, as a tracker keeps them beside the history), pulled towards 1 (the average adult) with the
    weight of ``scale_prior_frames`` frames. NaN where fewer than ``min_count`` lengths of a bone are known."""
    if math.isinf(template_frames):  # the scaled template alone: only how many lengths are known matters
        median, count = None, np.isfinite(history).sum(1)  # (T, B)
    else:
        median, count = _median(history, 1)  # (T, B)
    if template_frames > 0:
        template = np.asarray(BONE_TEMPLATE_MM)
        per_frame = frame_scales(history) if scales is None else scales  # (T, H) each frame's scale
        scale, frames = _median(per_frame, 1)  # (T,)
        scale = (frames * np.nan_to_num(scale) + scale_prior_frames) / np.maximum(
            frames + scale_prior_frames, 1e-9
        )
        scaled = scale[:, None] * template
        if median is None:
            median = scaled
        else:
            w = template_frames / (count + template_frames)
            median = np.where(count > 0, w * scaled + (1 - w) * np.nan_to_num(median), scaled)
    return np.where(count >= max(min_count, 1), median, np.nan)


class Tracker:
    """Online multi-person tracker over one stream of frames (see the module docstring)."""

    # the per-track arrays, first axis T
    _PER_TRACK = (
        "pos", "vel", "cov", "ids", "hits", "unseen_s", "unseen", "bones", "scales", "frames_seen", "recent",
        "origin", "evidence", "static_s",
    )  # fmt: skip

    def __init__(self, config: TrackerConfig | None = None) -> None:
        self.config = config or TrackerConfig()
        c = self.config
        J = NUM_JOINTS
        self.pos = np.zeros((0, J, 3))  # (T, J, 3) filtered joints
        self.vel = np.zeros((0, J, 3))  # (T, J, 3) mm/s
        self.cov = np.zeros((0, J, 2, 2))  # (T, J, 2, 2) covariance of (position, velocity), per axis
        self.ids = np.zeros(0, int)  # -1 while tentative
        self.hits = np.zeros(0, int)  # consecutive frames with a detection
        self.unseen_s = np.zeros(0)  # seconds since the last detection
        self.unseen = np.zeros(0, int)  # frames since the last detection
        self.bones = np.zeros((0, c.bone_history, len(BONES)))  # (T, H, B) measured lengths, NaN: none yet
        self.scales = np.zeros((0, c.bone_history))  # (T, H) frame_scales of those lengths, kept beside them
        self.frames_seen = np.zeros(0, int)  # frames with a detection, over the track's life
        # (T, birth_hits, 3): height along up (NaN without an up), median spread and share of the torso in front of
        # the background (NaN without views) of its last frames, by frames_seen
        self.recent = np.zeros((0, c.birth_hits, 3))
        self.origin = np.zeros((0, 3))  # (T, 3) the torso's centre at birth, or when last seen alive
        self.evidence = np.zeros(
            0, bool
        )  # seen to move, in front of the background, or in a sure upright pose
        self.static_s = np.zeros(0)  # (T,) seconds seen without any of those cues since (the park rule)
        self.background = DepthBackground(c.background)
        self.background_ms = 0.0  # what the background model took in the last update (part of it)
        self.time: float | None = None
        self.next_id = 0
        # Ended confirmed tracks whose id may come back (reid_s): id, scale, end time
        self.ended: list[tuple[int, float, float]] = []

    @property
    def num_tracks(self) -> int:
        return len(self.ids)

    def _keep(self, keep: np.ndarray) -> None:
        if keep.all():
            return
        for name in self._PER_TRACK:
            setattr(self, name, getattr(self, name)[keep])

    def _moved(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """The tracks' velocities and joints ``dt`` s on (an unseen track slows down), without changing them."""
        vel = self.vel * np.where(self.unseen > 0, self.config.coast_velocity_decay, 1.0)[:, None, None]
        return vel, self.pos + vel * dt

    def _predict(self, dt: float) -> None:
        c = self.config
        self.vel, self.pos = self._moved(dt)
        F = np.array([[1.0, dt], [0.0, 1.0]])
        q = c.accel_noise_mm_s2**2
        Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
        self.cov = F @ self.cov @ F.T + Q

    def _measurement_var(self, spread: np.ndarray) -> np.ndarray:
        c = self.config
        return np.maximum(c.spread_scale * spread, c.min_measurement_std_mm) ** 2

    def _update(self, tracks: np.ndarray, joints: np.ndarray, spread: np.ndarray) -> None:
        """Kalman update of ``tracks (M,)`` with their persons' ``joints (M, J, 3)`` and ``spread (M, J)``."""
        P = self.cov[tracks]  # (M, J, 2, 2)
        S = P[..., 0, 0] + self._measurement_var(spread)  # (M, J)
        K = P[..., :, 0] / S[..., None]  # (M, J, 2)
        innovation = joints - self.pos[tracks]  # (M, J, 3)
        self.pos[tracks] += K[..., 0, None] * innovation
        self.vel[tracks] += K[..., 1, None] * innovation
        self.cov[tracks] = P - K[..., :, None] * P[..., None, 0, :]  # (I - K H) P

    def _births(self, joints: np.ndarray, spread: np.ndarray) -> None:
        c = self.config
        n = len(joints)
        if not n:
            return
        var = self._measurement_var(spread)
        cov = np.zeros((n, NUM_JOINTS, 2, 2))
        cov[..., 0, 0] = var
        cov[..., 1, 1] = c.initial_speed_std_mm_s**2
        self.pos = np.concatenate([self.pos, joints])
        self.vel = np.concatenate([self.vel, np.zeros_like(joints)])
        self.cov = np.concatenate([self.cov, cov])
        self.ids = np.concatenate([self.ids, np.full(n, -1)])
        self.hits = np.concatenate([self.hits, np.zeros(n, int)])
        self.unseen_s = np.concatenate([self.unseen_s, np.zeros(n)])
        self.unseen = np.concatenate([self.unseen, np.zeros(n, int)])
        self.bones = np.concatenate([self.bones, np.full((n, c.bone_history, len(BONES)), np.nan)])
        self.scales = np.concatenate([self.scales, np.full((n, c.bone_history), np.nan)])
        self.frames_seen = np.concatenate([self.frames_seen, np.zeros(n, int)])
        self.recent = np.concatenate([self.recent, np.full((n, c.birth_hits, 3), np.nan)])
        self.origin = np.concatenate([self.origin, joints[:, TORSO].mean(1)])
        self.evidence = np.concatenate([self.evidence, np.zeros(n, bool)])
        self.static_s = np.concatenate([self.static_s, np.zeros(n)])

    @staticmethod
    def _persons(joints, spread) -> tuple[np.ndarray, np.ndarray]:
        """A frame's persons as ``(P, J, 3)`` joints and ``(P, J)`` spreads, float; ValueError when not finite."""
        joints = (
            np.asarray(joints, float).reshape(-1, NUM_JOINTS, 3)
            if np.size(joints)
            else np.zeros((0, NUM_JOINTS, 3))
        )
        spread = np.asarray(spread, float).reshape(len(joints), NUM_JOINTS)
        if not (np.isfinite(joints).all() and np.isfinite(spread).all()):
            raise ValueError("joints and spread must be finite")
        return joints, spread

    @staticmethod
    def _measures(
        joints: np.ndarray, spread: np.ndarray, up: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(P,)`` each person's median joint spread and ``(P,)`` height along ``up`` (NaN without one): what the
        rules of steps 1 and 2 read."""
        height = np.full(len(joints), np.nan) if up is None else skeleton_height(joints, up)
        return _middle(spread, 1), height

    def _refused(self, joints: np.ndarray, spread_median: np.ndarray, height: np.ndarray) -> np.ndarray:
        """``(3, P)`` the persons each filter of step 1 refuses, from :meth:`_measures`: a median spread above
        ``max_spread_mm``, a torso shorter than ``min_torso_mm``, a height along the room's up below
        ``min_height_mm`` (a NaN height, without an up, is refused by none)."""
        c = self.config
        return np.stack(
            [spread_median > c.max_spread_mm, torso_length(joints) < c.min_torso_mm, height < c.min_height_mm]
        )

    def _usable(self, joints: np.ndarray, spread_median: np.ndarray, height: np.ndarray) -> np.ndarray:
        """``(P,)`` the persons a track may take (no filter of :meth:`_refused` refuses them; step 1)."""
        return ~self._refused(joints, spread_median, height).any(0)

    def _apart(self, new: np.ndarray, joints: np.ndarray, spread_median: np.ndarray) -> np.ndarray:
        """The persons ``new (N,)`` (indices into the frame's ``joints``) that may start tracks when no two of them
        may lie within ``duplicate_mm``: greedily, lowest median spread first, each kept unless near one kept."""
        order = new[np.argsort(spread_median[new], kind="stable")]
        dist = mean_joint_distance(joints[order], joints[order])  # (N, N)
        kept: list[int] = []
        for i in range(len(order)):
            if not kept or dist[i, kept].min() >= self.config.duplicate_mm:
                kept.append(i)
        return np.sort(order[kept])

    def _lying(self) -> np.ndarray:
        """``(T,)`` the tracks whose last ``birth_hits`` frames look like a person lying down (step 2)."""
        c = self.config
        lying = np.zeros(self.num_tracks, bool)
        if c.lying_height_mm is None:
            return lying
        with np.errstate(invalid="ignore"):  # NaN heights (no up) compare False: not lying
            height, spread = _middle(self.recent[..., :2], 1).T  # (T,) each
            return (height < c.lying_height_mm) & (spread > c.lying_spread_mm)

    def _scale(self) -> tuple[np.ndarray, np.ndarray]:
        """``(T,)`` each track's signature (the median of its frames' scales, NaN without any) and ``(T,)`` how
        many frames it holds."""
        return _median(self.scales, 1)

    def _signature_cost(self, joints: np.ndarray) -> np.ndarray | float:
        """``(T, P)`` mm added to the association cost for the difference between each person's scale and each
        track's (``signature_mm``; 0 where a track has fewer than ``signature_min_frames`` frames)."""
        c = self.config
        if not c.signature_mm or not self.num_tracks or not len(joints):
            return 0.0
        scale, count = self._scale()
        person = frame_scales(bone_lengths(joints))  # (P,)
        diff = np.abs(scale[:, None] - person[None])  # (T, P)
        known = (count >= c.signature_min_frames)[:, None] & np.isfinite(diff)
        return c.signature_mm * np.where(known, diff, 0.0)

    def _name(self, confirm: np.ndarray) -> np.ndarray:
        """Give the tracks ``confirm (N,)`` their ids: that of an ended track, or of a confirmed one coasting
        unseen, whose scale theirs matches (``reid_s``), else new ones. Returns ``(T,)`` the coasting tracks whose
        id a new track took (they end)."""
        c = self.config
        taken_over = np.zeros(self.num_tracks, bool)
        if c.reid_s > 0 and len(confirm):
            self.ended = [e for e in self.ended if self.time - e[2] <= c.reid_s]
            scale = self._scale()[0]
            coasting = np.flatnonzero((self.ids >= 0) & (self.unseen > 0))
            # (id, scale, coasting track or -1) of every identity a new track may take
            gallery = [(e[0], e[1], -1) for e in self.ended] + [
                (int(self.ids[t]), scale[t], t) for t in coasting
            ]
            for i in confirm:
                if not gallery or not np.isfinite(scale[i]):
                    continue
                d = np.abs(np.array([g[1] for g in gallery]) - scale[i])
                d[~np.isfinite(d)] = np.inf
                best = int(np.argmin(d))
                others = np.delete(d, best)
                if d[best] <= c.reid_scale_tol and (
                    not len(others) or others.min() - d[best] >= c.reid_margin
                ):
                    identity, _, track = gallery.pop(best)
                    self.ids[i] = identity
                    if track >= 0:
                        taken_over[track] = True
                        self.ids[track] = -2  # ends below, its id now another track's
                    else:
                        self.ended = [e for e in self.ended if e[0] != identity]
        new = confirm[self.ids[confirm] < 0]
        self.ids[new] = np.arange(self.next_id, self.next_id + len(new))
        self.next_id += len(new)
        return taken_over

    def _seen_alive(self) -> np.ndarray:
        """``(T,)`` the tracks the stream has seen move, stand in front of the background or hold a sure upright
        pose (the phantom rule of :class:`TrackerConfig`), from their state after this frame's update."""
        c = self.config
        moved = _norm(self.pos[:, TORSO].mean(1) - self.origin) > c.move_mm
        with np.errstate(invalid="ignore"):  # NaN (no up, no view of the torso) compares False
            height, spread, front = _middle(self.recent, 1).T  # (T,) each
            posed = (
                np.zeros_like(moved)
                if c.pose_spread_mm is None
                else (spread <= c.pose_spread_mm) & ~(height < c.pose_height_mm)
            )
            return moved | (front >= c.foreground_share) | posed

    def _park(
        self, rows: np.ndarray, spread: np.ndarray, height: np.ndarray, front: np.ndarray, dt: float
    ) -> np.ndarray:
        """``(T,)`` the confirmed tracks parked: whose stillness clock is above ``park_s`` (:class:`TrackerConfig`),
        after this frame's persons of the tracks ``rows (M,)``: their median ``spread``, ``height`` along up and
        share ``front`` in front of the background (NaN: no view saw the torso, which counts as alive). A track alive
        in this frame winds its clock back and measures its next move from where it is."""
        c = self.config
        if c.park_suspends:  # the clock runs for confirmed tracks unseen in this frame
            unseen = np.ones(self.num_tracks, bool)
            unseen[rows] = False
            self.static_s[unseen & (self.ids >= 0)] += dt
        centre = self.pos[rows][:, TORSO].mean(1)  # (M, 3)
        with np.errstate(invalid="ignore"):
            posed = (spread <= c.pose_spread_mm) & ~(height < c.pose_height_mm) if c.pose_spread_mm else False
            alive = ~(front < c.foreground_share) | posed | (_norm(centre - self.origin[rows]) > c.move_mm)
        self.origin[rows[alive]] = centre[alive]
        recovered = (
            np.maximum(self.static_s[rows] - c.park_recovery * dt, 0.0)
            if np.isfinite(c.park_recovery)
            else 0.0
        )
        self.static_s[rows] = np.where(alive, recovered, self.static_s[rows] + dt)
        if c.park_s is None:
            return np.zeros(self.num_tracks, bool)
        return (self.ids >= 0) & (self.static_s > c.park_s)

    def _claims(self, cost: np.ndarray, eligible: np.ndarray) -> np.ndarray:
        """``(P,)`` the track each of the ``eligible`` persons takes (-1: none): optimal assignment on ``cost (T,
        P)`` (mm, to the tracks' predicted joints) under each track's gate, widened while it coasts."""
        c = self.config
        track_of = np.full(cost.shape[1], -1)
        gate = c.gate_mm + c.coast_speed_mm_s * self.unseen_s  # (T,)
        ok_pair = (cost <= gate[:, None]) & eligible[None]
        if ok_pair.any():
            rows, cols = linear_sum_assignment(np.where(ok_pair, cost, 1e9))
            ok = ok_pair[rows, cols]
            track_of[cols[ok]] = rows[ok]
        return track_of

    def unsure_targets(
        self,
        joints: np.ndarray,
        spread: np.ndarray,
        timestamp_s: float,
        up: np.ndarray | None = None,
        within: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """``(K, J, 3)`` the predicted joints of the tracks that a person the detector was unsure of could continue
        in :meth:`update` at ``timestamp_s``, when the frame's sure persons are ``joints (P, J, 3)`` / ``spread (P,
        J)``: the confirmed tracks that none of them takes (the first pass of :meth:`update`, on the predicted
        joints; the tracker does not change) and, given ``within`` (per joint the box ``(lo (J, 3), hi (J, 3))``
        that every unsure person's joints lie in, ``BoxHeatmaps.joint_bounds``), that come within
        ``unsure_gate_mm`` of it (the mean over joints of each joint's distance to its box is a lower bound of the
        distance to any unsure person). An unsure person further than the gate from all of them (:func:`reaching`)
        changes nothing: it never starts a track; with none left, a caller may skip finding unsure persons."""
        c = self.config
        confirmed = self.ids >= 0
        if c.unsure_gate_mm is None or not confirmed.any():
            return np.zeros((0, NUM_JOINTS, 3))
        pos = self._moved(timestamp_s - self.time)[1]  # where update will predict the tracks
        if not timestamp_s > self.time:
            return pos[confirmed]  # update will refuse the frame; nothing to save
        if within is not None:  # first the tracks the unsure persons could reach at all: often none
            lo, hi = (np.asarray(b, float) for b in within)
            nearest = np.clip(pos[confirmed], lo, hi)  # (T', J, 3): each joint's nearest point of its box
            bound = _norm(pos[confirmed] - nearest).mean(-1)  # (T',) mm
            confirmed[confirmed] = bound <= c.unsure_gate_mm + 1.0  # 1 mm for the persons' float32 rounding
            if not confirmed.any():
                return np.zeros((0, NUM_JOINTS, 3))
        joints, spread = self._persons(joints, spread)
        usable = self._usable(joints, *self._measures(joints, spread, up))
        track_of = self._claims(mean_joint_distance(pos, joints) + self._signature_cost(joints), usable)
        return pos[confirmed & ~_taken(track_of, self.num_tracks)]

    def update(
        self,
        joints: np.ndarray,
        spread: np.ndarray,
        timestamp_s: float,
        unsure: np.ndarray | None = None,
        up: np.ndarray | None = None,
        views: Sequence[SceneView] | None = None,
    ) -> list[TrackedPerson]:
        """Take one frame's persons and return them with their tracks, in input order.

        Args:
            joints: (P, J, 3) mm; spread: (P, J) mm (the pose network's per-joint spread; larger is less
                certain); timestamp_s: the frame's time, later than the previous frame's.
            unsure: (P,) bool, persons that may only continue a confirmed track (step 1 of the module
                docstring); an unsure person no track takes is returned with ``track_id`` None.
            up: (3,) the room's up direction in the joints' frame, when known: skeletons spanning less than
                ``min_height_mm`` along it (a person lying down) are not tracked.
            views: the frame's views (depth images and cameras, the joints' reference frame; the same cameras and
                sizes over the stream), when known: the tracker learns the room's static depth from them
                (``pipeline.background``) and confirms no track whose person it has not seen move, stand in front
                of it, or hold a sure upright pose (``TrackerConfig.move_mm``).
        """
        c = self.config
        joints, spread = self._persons(joints, spread)
        if self.time is not None and not timestamp_s > self.time:
            raise ValueError(
                f"timestamp {timestamp_s} s is not later than the previous frame's {self.time} s"
            )
        dt = 0.0 if self.time is None else float(timestamp_s - self.time)
        self.time = float(timestamp_s)
        if dt > 0:
            self._predict(dt)
        # 1. assignment under the gate
        n_tracks, n_dets = self.num_tracks, len(joints)
        unsure = np.zeros(n_dets, bool) if unsure is None else np.asarray(unsure, bool).reshape(n_dets)
        spread_median, height = self._measures(joints, spread, up)  # (P,) each
        usable = self._usable(joints, spread_median, height)  # (P,)
        t_background = time.perf_counter()
        front = (
            np.full(n_dets, np.nan) if views is None else self.background.foreground(joints, views)
        )  # (P,)
        self.background_ms = (time.perf_counter() - t_background) * 1e3
        track_of = np.full(n_dets, -1)
        if n_tracks and n_dets:
            cost = mean_joint_distance(self.pos, joints) + self._signature_cost(joints)  # (T, P)
            track_of = self._claims(cost, usable & ~unsure)  # sure persons first
            if c.unsure_gate_mm is not None and unsure.any():  # then unsure ones, for confirmed tracks left
                claimed = _taken(track_of, n_tracks)
                # an unsure person near a track a sure person took is that person seen again
                again = (cost[claimed] < c.duplicate_mm).any(0) if claimed.any() else np.zeros(n_dets, bool)
                gated = (cost <= c.unsure_gate_mm) & (usable & ~again)[None]
                ok_pair = gated & (~claimed & (self.ids >= 0))[:, None] & unsure[None]
                if ok_pair.any():
                    rows, cols = linear_sum_assignment(np.where(ok_pair, cost, 1e9))
                    ok = ok_pair[rows, cols]
                    track_of[cols[ok]] = rows[ok]
        matched = track_of >= 0
        tracks = track_of[matched]
        self._update(tracks, joints[matched], spread[matched])
        seen = np.zeros(n_tracks, bool)
        seen[tracks] = True
        self.hits = np.where(seen, self.hits + 1, 0)
        self.unseen = np.where(seen, 0, self.unseen + 1)
        self.unseen_s = np.where(seen, 0.0, self.unseen_s + dt)
        # 2. births (not of a second detection of a person already claimed) and deaths
        new = np.flatnonzero(~matched & usable & ~unsure)
        if len(new) and seen.any():
            near = mean_joint_distance(joints[new], self.pos[seen]).min(1) < c.duplicate_mm
            new = new[~near]
        if len(new) > 1 and c.births_apart:  # nor twice of one person in this frame
            new = self._apart(new, joints, spread_median)
        track_of[new] = np.arange(n_tracks, n_tracks + len(new))
        self._births(joints[new], spread[new])
        self.hits[n_tracks:] = 1
        have = np.flatnonzero(track_of >= 0)
        rows = track_of[have]
        self.recent[rows, self.frames_seen[rows] % c.birth_hits] = np.stack(
            [height[have], spread_median[have], front[have]], axis=-1
        )
        confirm = (self.ids < 0) & (self.hits >= c.birth_hits) & ~self._lying()
        parked = np.zeros(self.num_tracks, bool)
        if views is not None:
            self.evidence |= self._seen_alive()
            confirm &= self.evidence
            parked = self._park(rows, spread_median[have], height[have], front[have], dt)
        taken_over = self._name(np.flatnonzero(confirm))
        # 3. bone-length prior and correction, for the tracks seen in this frame
        lengths, slot = bone_lengths(joints[have]), self.frames_seen[rows] % c.bone_history  # (M, B), (M,)
        self.bones[rows, slot] = lengths
        self.scales[rows, slot] = frame_scales(lengths)
        self.frames_seen[rows] += 1
        if len(rows):
            prior = robust_prior(
                self.bones[rows], c.bone_min_frames, c.bone_template_frames, c.bone_scale_prior_frames,
                self.scales[rows],
            )  # fmt: skip
            self.pos[rows] = project_bones(
                self.pos[rows], prior, self.cov[rows, :, 0, 0], c.bone_tolerance_mm, c.bone_iterations
            )
        quiet = parked if c.park_suspends else np.zeros(self.num_tracks, bool)
        out = [
            TrackedPerson(
                int(p), None if self.ids[track_of[p]] < 0 or quiet[track_of[p]] else int(self.ids[track_of[p]]),
                self.pos[track_of[p]].copy(), joints[p].copy(), tentative=bool(self.ids[track_of[p]] < 0),
                parked=bool(self.ids[track_of[p]] >= 0 and quiet[track_of[p]]),
            )
            if track_of[p] >= 0
            else TrackedPerson(int(p), None, joints[p].copy(), joints[p].copy())
            for p in range(n_dets)
        ]  # fmt: skip
        dead = (
            ((self.ids < 0) & (self.unseen > 0))
            | (self.unseen_s > c.max_coast_s)
            | taken_over
            | (parked & ~quiet)
        )
        if c.reid_s > 0 and (dead & (self.ids >= 0)).any():
            ended = np.flatnonzero(dead & (self.ids >= 0))
            scale = self._scale()[0][ended]
            self.ended += [(int(self.ids[i]), float(s), self.time) for i, s in zip(ended, scale, strict=True)]
        self._keep(~dead)
        if views is not None:  # learn the frame's depth, where no confirmed person stands
            t_background = time.perf_counter()
            self.background.update(views, timestamp_s, self.pos[(self.ids >= 0) & (self.unseen == 0)])
            self.background_ms += (time.perf_counter() - t_background) * 1e3
        return out
