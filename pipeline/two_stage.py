"""The two-stage pipeline: person boxes per view (detected or given), grouped across views, then 3D poses.

This is the object that the app and the offline evaluation share. It knows nothing of HTTP: it takes decoded
numpy views with their cameras (and optionally reference boxes) and returns persons with their joints in mm
in the reference frame, per-joint spread and calibrated confidence, the supporting views and boxes, and
per-stage timings.

Offline use::

    pipe = ScenePipeline.from_checkpoints()            # the shipped weights
    result = pipe.run(views)                            # detector mode
    result = pipe.run(views, boxes, person_ids)         # reference-box mode (the paper's evaluation setting)
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np
import torch

from detector.protocol import Detector
from pipeline.matching import box_centres_3d, combination_bound
from pipeline.skeleton_matching import (
    CANDIDATE_SCORE,
    SkeletonMatchConfig,
    group_unsure,
    match_heatmaps,
    members_of,
    split_unsure,
    unsure_left,
    view_members,
)
from pipeline.track import reaching
from posenet.boxes import PersonBoxes, ground_truth_ids, hull, identified
from posenet.data.sample import Sample
from posenet.evaluation.evaluate import prediction_record
from posenet.net.lifting import JointEstimate
from posenet.scene import PersonPose, Scene, SceneView


@dataclass
class PipelineConfig:
    # The paper's matching threshold t = 75 cm, chosen there by visual inspection.
    match_threshold_mm: float = 750.0
    # The matcher enumerates every combination of mutually close boxes. Many boxes at one 3D spot in many
    # views make that exponential (4 views x 64 identical boxes: 17 M combinations, gigabytes); 300 k take
    # about 2 s here.
    max_match_combinations: int = 300_000
    # Persons per frame run through the pose network (its memory grows with persons x views x crop pixels).
    # MVOR frames hold at most about 6; in detector mode the best-supported groups are kept, beyond it.
    max_persons: int = 32
    # The service's cost bound (ORPOSE_MAX_POSE_PIXELS): persons x views x network-input pixels (x 2 with flip
    # averaging) per frame. None: no bound beyond max_persons (offline evaluation).
    max_pose_pixels: int | None = None
    # How boxes without ids are grouped across views (ORPOSE_MATCHER): "centres", the paper's 3D box-centre
    # matcher, or "skeletons", each box's single-view skeleton from the pose network (pipeline.skeleton_matching;
    # the U-Net still runs once per box). Skeletons by default: on day 4 of the twin and of the unseen alt look
    # it splits and merges fewer persons and gives lower two-stage MPJPE than the centres (docs/detector.md).
    # "skeletons-greedy" groups the same skeletons by the paper's greedy rule instead of one optimal partition
    # per frame (pipeline.matching.choose_optimally), for the ablation.
    matcher: str = "skeletons"
    # Detector mode with the skeleton matcher: boxes scored from this up to the detector's threshold may complete
    # a person seen confidently in other views (pipeline.skeleton_matching, step 5); they never start one.
    # None: only the detector's confident boxes are used.
    candidate_score: float | None = CANDIDATE_SCORE
    # The skeleton matcher's thresholds (None: its defaults; "skeletons-greedy" always takes the greedy rule).
    skeleton_match: SkeletonMatchConfig | None = None

    def __post_init__(self) -> None:
        if self.matcher not in ("centres", "skeletons", "skeletons-greedy"):
            raise ValueError(
                f"matcher must be 'centres', 'skeletons' or 'skeletons-greedy', got {self.matcher!r}"
            )


@dataclass(kw_only=True)
class PersonResult(PersonPose):
    """One person of a scene: its pose (:class:`posenet.scene.PersonPose`: ``joints`` (J, 3) mm in the reference
    frame, ``spread_mm`` (J,), ``confidence`` (J,) calibrated from the spread and the number of supporting views)
    and where the pipeline found it: its row ``row`` of the scene's persons' boxes (``SceneResult.boxes``, a
    ``posenet.boxes.PersonBoxes``).

    Attributes:
        id: the client's person id (reference-box mode with ids) or an index within the scene.
        person_boxes: the scene's persons' boxes, in the pixels the pipeline was given; this person is ``row``.
        box_indices: V entries: the indices, among the boxes of that view given to (or found by) the pipeline, of
            the person's boxes there (one, several when the skeleton matcher merged a split person, or none).
        unsure: every box of this person scored below the detector's threshold: not a person of the frame on
            its own, listed (after the others) only when :meth:`ScenePipeline.run` is asked for such persons,
            for a tracker that may continue a track with it (``pipeline.skeleton_matching.group_unsure``).
    """

    id: int
    person_boxes: PersonBoxes = field(repr=False)
    row: int
    box_indices: list[tuple[int, ...]] = field(default_factory=list)
    unsure: bool = False

    @property
    def boxes(self) -> np.ndarray:
        """(V, 4) xyxy: the person's box in each view (the hull of its boxes there; zeros in a view outside
        :attr:`support`)."""
        return self.person_boxes.boxes[self.row]

    @property
    def scores(self) -> np.ndarray:
        """(V,): the best detector score of the person's boxes in each view; NaN for reference boxes and where
        it has none."""
        return self.person_boxes.scores[self.row]

    @property
    def support(self) -> list[int]:
        """The views in which this person has a box."""
        return self.person_boxes.support(self.row)


@dataclass
class SceneResult:
    """The persons of one frame, their boxes (row p of ``boxes`` is ``persons[p]``'s), and the milliseconds spent
    in each stage (detect, match, pose)."""

    mode: str  # "reference_boxes" or "detector"
    persons: list[PersonResult]
    boxes: PersonBoxes
    timings: dict[str, float] = field(default_factory=dict)
    # ms of timings["match"] spent on the persons of unsure boxes for a tracker (``run(unsure=...)``): asking it
    # whether it can use them, and grouping them when it can; what a stream adds beside the tracker's update
    unsure_ms: float = 0.0


def _ms(t0: float) -> float:
    return (time.perf_counter() - t0) * 1e3


@dataclass
class Detected:
    """The detector's work on one frame (:meth:`ScenePipeline.detect`), for :meth:`ScenePipeline.run`: per view
    the boxes ``(K_v, 4)`` xyxy px, their scores ``(K_v,)``, which of them are unsure (``(K_v,)`` bool, or None
    when unsure boxes are not used), and the milliseconds it took. A stream detects frame t+1 while frame t is
    in the pose stage (``service.streams``)."""

    boxes: list[np.ndarray]
    scores: list[np.ndarray]
    candidate: list[np.ndarray] | None
    ms: float


@dataclass
class TrackerQuestions:
    """What a stream's tracker tells :meth:`ScenePipeline.run` about the persons of boxes the detector was unsure
    of, so that only those it can use are found (``pipeline.track.Tracker.unsure_targets``)."""

    # (joints (P, J, 3), spreads (P, J) of the frame's persons, the box the unsure persons lie in) -> (K, J, 3):
    # the predicted joints of the tracks a person of unsure boxes could continue; none: they are not looked for
    targets: Callable
    # how near one of them (mean joint distance) such a person must lie (pipeline.track.reaching)
    gate_mm: float

    @classmethod
    def asking(cls, tracker, timestamp_s: float, up: np.ndarray | None) -> TrackerQuestions:
        """The questions of ``tracker`` (a ``pipeline.track.Tracker``) about its frame at ``timestamp_s``, whose
        room's up is ``up``, as a stream asks them."""
        return cls(
            targets=lambda joints, spread, within: tracker.unsure_targets(
                joints, spread, timestamp_s, up, within
            ),
            gate_mm=tracker.config.unsure_gate_mm or 0.0,
        )


def fused(heat, matched: list, unsure: list, boxes: list[np.ndarray], sure=None) -> JointEstimate:
    """``heat.estimate`` of the persons ``matched + unsure`` (``pipeline.matching.Group`` s of ``boxes``); with
    ``sure``, the estimate of ``matched`` already made, only the ``unsure`` ones are fused (each person is fused
    from its own boxes alone, so the result is the same)."""
    if sure is None:
        return heat.estimate(members_of(matched + unsure, boxes))
    if not unsure:
        return sure
    more = heat.estimate(members_of(unsure, boxes))
    return JointEstimate(
        torch.cat([sure.joints, more.joints]),
        torch.cat([sure.spread_mm, more.spread_mm]),
        torch.cat([sure.has_points, more.has_points]),
    )


def group_by_ids(person_ids: list[np.ndarray]) -> tuple[list[int], list[list[int]]]:
    """Group boxes by the client's ids: the sorted ids and, per id, per view the box index or -1."""
    ids = sorted({int(i) for per_view in person_ids for i in per_view})
    lookup = [{int(pid): k for k, pid in enumerate(per_view)} for per_view in person_ids]
    return ids, [[view.get(pid, -1) for view in lookup] for pid in ids]


class ScenePipeline:
    """Detector (optional) + cross-view matcher + pose network, run on one frame at a time.

    Args:
        pose: a ``posenet.net.infer.PoseEstimator`` (anything with its ``predict(scene)``, ``box_heatmaps`` and
            ``calibration``).
        detector: any ``detector.protocol.Detector`` (the shipped ``detector.infer.PersonDetector``), or None for
            reference-box mode only.
        config: matching settings.
    """

    def __init__(
        self,
        pose,
        detector: Detector | None = None,
        config: PipelineConfig | None = None,
        detector_meta: dict | None = None,
    ) -> None:
        if detector is not None and not isinstance(detector, Detector):
            raise TypeError(f"{type(detector).__name__} is not a detector.protocol.Detector")
        self.pose = pose
        self.detector = detector
        self.config = config or PipelineConfig()
        # The detector checkpoint's config.json: /model reports what the detector was trained on from it.
        self.detector_meta = detector_meta or {}
        self.load_seconds: dict[str, float] = {}  # per network, when from_checkpoints loaded it

    @property
    def read_size(self) -> tuple[int, int] | None:
        """(W, H) of the largest views that the networks read: views an exact multiple of it larger can be
        decoded smaller without changing what the networks see (``posenet.net.inputs.reduction``). None when the
        pose network crops from views as they are given (no ``source_size``)."""
        size = self.pose.model.config.inputs.read_size
        if size is None:
            return None
        if self.detector is not None:  # the detector resizes to its input width, keeping the aspect
            size = (max(size[0], self.detector.input_width), size[1])
        return size

    @property
    def modalities(self) -> tuple[str, ...]:
        """The images the pose network reads: ("color", "depth"), ("color",) or ("depth",)."""
        modality = self.pose.model.config.inputs.modality
        return {"rgbd": ("color", "depth"), "rgb": ("color",), "depth": ("depth",)}[modality]

    @property
    def detector_modalities(self) -> tuple[str, ...]:
        """The images the detector reads (empty without a detector): a frame in detector mode needs these and the
        pose network's (:attr:`modalities`); with a depth-only detector and pose network, depth alone."""
        if self.detector is None:
            return ()
        return tuple(
            m
            for m, needed in (
                ("color", getattr(self.detector, "needs_color", True)),  # optional in detector.protocol
                ("depth", self.detector.needs_depth),
            )
            if needed
        )

    @classmethod
    def from_checkpoints(
        cls,
        pose_checkpoint: str | Path | None = None,
        detector_checkpoint: str | Path | None = None,
        device: str = "cpu",
        load_detector: bool | None = True,
        config: PipelineConfig | None = None,
        precision: str = "auto",
        backend: str = "torch",
        threads: int | None = None,
        flip_test: bool | None = None,
    ) -> ScenePipeline:
        """Load both models; ``None`` paths mean the weights shipped with the package.

        ``precision`` and ``backend`` say how this machine runs both networks (``posenet.runtime.execution``,
        ``posenet.runtime.graphs``); ``threads`` is the runtimes' intra-op thread count; ``flip_test`` averages the pose
        network's estimates with the mirrored inputs' (None: the checkpoint's setting).

        ``load_detector=None`` loads the detector only when ``detector_checkpoint`` is given or shipped detector
        weights exist, and otherwise serves reference-box mode only (with a warning in the log).
        """
        from posenet.net.infer import PoseEstimator

        t0 = time.perf_counter()
        pose = PoseEstimator.from_checkpoint(pose_checkpoint, device, precision, backend, threads, flip_test)
        seconds = {"pose": time.perf_counter() - t0}
        if load_detector is None:
            from detector.infer import DEFAULT_WEIGHTS

            load_detector = detector_checkpoint is not None or DEFAULT_WEIGHTS.is_file()
            if not load_detector:
                logging.getLogger(__name__).warning(
                    "no detector weights at %s and ORPOSE_DETECTOR_CHECKPOINT unset: serving reference-box mode "
                    "only (requests must carry boxes)",
                    DEFAULT_WEIGHTS,
                )
        detector, meta = None, None
        if load_detector:
            # Imported only when needed: transformers takes seconds to import.
            from detector.checkpoint import read_config
            from detector.infer import DEFAULT_WEIGHTS, PersonDetector

            t0 = time.perf_counter()
            detector = PersonDetector.from_checkpoint(
                detector_checkpoint, device, precision, backend, threads
            )
            seconds["detector"] = time.perf_counter() - t0
            meta = read_config(detector_checkpoint or DEFAULT_WEIGHTS)
        pipeline = cls(pose, detector, config, meta)
        pipeline.load_seconds = seconds
        return pipeline

    # ----------------------------------------------------------------------------------------- stages
    def _combination_bound(self, boxes: list[np.ndarray], views: list[SceneView]) -> float:
        """An upper bound on the combinations the centre matcher will enumerate (``combination_bound``)."""
        centres, view = box_centres_3d(boxes, [v.depth for v in views], [v.camera for v in views])
        dist = np.linalg.norm(centres[:, None] - centres[None, :], axis=-1)  # (N, N), NaN without depth
        return combination_bound(dist, view, len(views), self.config.match_threshold_mm)

    def _person_limit(self, num_views: int) -> tuple[int, str]:
        """The most persons a frame of ``num_views`` views may run through the pose network, and why."""
        limit, why = self.config.max_persons, f"the limit of {self.config.max_persons}"
        if self.config.max_pose_pixels is not None:
            model = self.pose.model.config
            w, h = model.inputs.network_size(False)
            per_person = num_views * w * h * (2 if model.flip_test else 1)
            if self.config.max_pose_pixels // per_person < limit:
                limit = self.config.max_pose_pixels // per_person
                why = (
                    f"the {limit} that fit in this server's budget of {self.config.max_pose_pixels} "
                    f"network-input pixels per frame (persons x {num_views} views x {w}x{h} crops"
                    f"{' x 2 flips' if model.flip_test else ''}; ORPOSE_MAX_POSE_PIXELS): send fewer persons "
                    "or views per request"
                )
        return limit, why

    def _match(self, boxes: list[np.ndarray], views: list[SceneView]) -> list[list[int]]:
        """Group boxes across views by their 3D centres: per person, per view a box index or -1."""
        from pipeline.matching import match_boxes

        bound = self._combination_bound(boxes, views)
        if bound > self.config.max_match_combinations:
            raise ValueError(
                f"the boxes are too crowded to group across views (up to {bound:.3g} combinations of boxes "
                f"within {self.config.match_threshold_mm:g} mm, more than "
                f"{self.config.max_match_combinations}); give person_ids with the boxes, or fewer boxes"
            )
        groups = match_boxes(
            boxes,
            [v.depth for v in views],
            [v.camera for v in views],
            threshold_mm=self.config.match_threshold_mm,
        )
        return [list(group.indices) for group in groups]

    def run(
        self,
        views: list[SceneView],
        boxes: list[np.ndarray] | None = None,
        person_ids: list[np.ndarray] | None = None,
        unsure: bool | TrackerQuestions = False,
        detected: Detected | None = None,
    ) -> SceneResult:
        """Estimate every person's 3D pose in one frame.

        Args:
            views: V views (colour may be None when the pose network does not read it and boxes are given).
            boxes: per view (K_v, 4) xyxy reference boxes; None runs the detector instead.
            person_ids: per view (K_v,) identities of the reference boxes; None groups them with the matcher.
            unsure: also list, after the frame's persons, those of boxes the detector was unsure of in every
                view (``PersonResult.unsure``; detector mode with the skeleton matcher and unsure boxes on),
                for a tracker: they are no persons of the frame on their own. :class:`TrackerQuestions` (a
                stream's) asks its tracker first, told the frame's persons as they will be answered and the box
                their joints would lie in (``BoxHeatmaps.joint_bounds`` of the unsure boxes left over), where the
                tracks are that they could continue: none, and they are not looked for; else only those within
                reach of one are finished (the others are left out before step 7).
            detected: the frame's :meth:`detect`, when it already ran (detector mode: ``boxes`` None).
        """
        if not views:
            raise ValueError("a scene needs at least one view")
        timings = {"detect": 0.0, "match": 0.0, "pose": 0.0}
        scores: list[np.ndarray | None] = [None] * len(views)
        candidate = None  # per view (K_v,) bool: detected boxes below the detector's threshold
        if boxes is None:
            detected = detected or self.detect(views)
            boxes, scores, candidate = detected.boxes, detected.scores, detected.candidate
            timings["detect"] = detected.ms
            person_ids = None
        elif len(boxes) != len(views):
            raise ValueError(f"boxes has {len(boxes)} entries for {len(views)} views")
        t0 = time.perf_counter()
        limit, why = self._person_limit(len(views))
        heat, matched, unsure_groups = None, [], []  # the skeleton matcher's groups (pipeline.matching.Group)
        all_matched = matched  # its persons before the person limit
        if person_ids is not None:
            ids, groups = group_by_ids(person_ids)
        elif any(len(b) for b in boxes) and self.config.matcher.startswith("skeletons"):
            boxes, scores, candidate = self._fit_boxes(boxes, scores, limit, why, candidate)
            heat, timings["match"], matched, centres = self._match_skeletons(
                boxes, views, candidate, detected=scores[0] is not None
            )
            all_matched = matched
            timings["pose"] += _ms(t0) - timings["match"]
            groups = [view_members(g) for g in matched]
            ids = list(range(len(groups)))
        elif any(len(b) for b in boxes):
            groups = self._match(boxes, views)
            ids = list(range(len(groups)))
        else:
            ids, groups = [], []
        if len(groups) > limit:
            if scores[0] is None:
                raise ValueError(f"the boxes make {len(groups)} persons, more than {why}")
            # Detector mode: the matcher lists multi-view groups first; the best-supported persons are kept.
            ids, groups, matched = ids[:limit], groups[:limit], matched[:limit]
        left = (
            None if not unsure or heat is None or scores[0] is None else unsure_left(all_matched, candidate)
        )
        sure = None  # the fusion of the frame's own persons, when the tracker's question needs it first
        unsure_ms = 0.0
        if left is not None:  # unsure boxes no person took: their persons, for a tracker (when it asks)
            t1, fuse_ms = time.perf_counter(), 0.0
            reaches, go = None, True  # asked nothing: every person of unsure boxes is found
            if isinstance(unsure, TrackerQuestions):
                # the frame's own persons as they will be answered (those with points), for the question; their
                # fusion is the pose stage's work, asked or not: made once, counted there
                t2 = time.perf_counter()
                sure = heat.estimate(members_of(matched, boxes))
                fuse_ms = _ms(t2)
                has = np.asarray(sure.has_points, dtype=bool)
                joints, spread = (np.asarray(x, np.float64)[has] for x in (sure.joints, sure.spread_mm))
                # the tracks they could continue: whether any is worth finding, and which
                targets = unsure.targets(joints, spread, heat.joint_bounds(np.concatenate(left)))
                reaches, go = partial(reaching, targets, gate_mm=unsure.gate_mm), len(targets) > 0
            if go:
                unsure_groups = group_unsure(
                    heat, views, boxes, all_matched, candidate,
                    self._skeleton_config(), self.config.max_match_combinations, centres, reaches,
                )  # fmt: skip
            unsure_ms = _ms(t1) - fuse_ms
            timings["match"] += unsure_ms
            timings["pose"] += fuse_ms
        if unsure_groups:  # after the frame's persons, within the same limit
            unsure_groups = unsure_groups[: max(limit - len(groups), 0)]
            ids = ids + list(range(len(groups), len(groups) + len(unsure_groups)))
            groups = groups + [view_members(g) for g in unsure_groups]
        if heat is None:
            timings["match"] = _ms(t0)
        if heat is None:  # ids and the centre matcher give per view one box index, or -1
            groups = [[() if k < 0 else (k,) for k in group] for group in groups]
        first_unsure = len(groups) - len(unsure_groups)
        found = self._person_boxes(groups, boxes, scores, ids)
        kept = found  # no person: no row
        persons = []
        t0 = time.perf_counter()
        if groups:
            # The skeleton matcher's heatmaps: fuse its groups without another U-Net pass.
            if heat is not None:
                prediction = fused(heat, matched, unsure_groups, boxes, sure)
            else:
                prediction = self.pose.predict(Scene.from_person_boxes(views, found))
            joints = np.asarray(prediction.joints, dtype=np.float64)  # (P, J, 3)
            spread = torch.as_tensor(prediction.spread_mm, dtype=torch.float64).cpu()  # (P, J) mm
            support = torch.from_numpy(found.has_box.sum(1))
            confidence = self.pose.calibration(
                spread, support, torch.as_tensor(joints)
            ).numpy()  # (P, J) in [0, 1]
            # A person whose boxes hold no valid depth has no lifted points: its joints mean nothing.
            rows = np.flatnonzero(np.asarray(prediction.has_points, dtype=bool))
            kept = found.select(rows)
            persons = [
                PersonResult(
                    joints[p], spread[p].numpy(), confidence[p], id=ids[p], person_boxes=kept, row=r,
                    box_indices=groups[p], unsure=p >= first_unsure,
                )
                for r, p in enumerate(rows.tolist())
            ]  # fmt: skip
        timings["pose"] += _ms(t0)
        mode = "detector" if scores[0] is not None else "reference_boxes"
        return SceneResult(mode, persons, kept, timings, unsure_ms)

    @staticmethod
    def _person_boxes(groups: list[list[tuple[int, ...]]], boxes, scores, ids) -> PersonBoxes:
        """The persons ``groups`` (per view the indices of their boxes there): per view the person's box (the hull
        of those boxes) and their best detector score."""
        P, V = len(groups), len(boxes)
        out = PersonBoxes(np.zeros((P, V, 4)), np.zeros((P, V), bool), np.asarray(ids, np.int64).reshape(P))
        for p, members in enumerate(groups):
            for v, ks in enumerate(members):
                if ks:
                    out.boxes[p, v], out.has_box[p, v] = hull(boxes[v][list(ks)]), True
                    if scores[v] is not None:
                        out.scores[p, v] = max(float(scores[v][k]) for k in ks)
        return out

    def _fit_boxes(
        self, boxes, scores, limit: int, why: str, candidate=None
    ) -> tuple[list, list, list | None]:
        """The skeleton matcher runs the U-Net on every box, laid out as max_v K_v persons: keep that within the
        person limit (detector mode: each view's best-scored boxes; reference boxes: refuse)."""
        if max(len(b) for b in boxes) <= limit:
            return boxes, scores, candidate
        if scores[0] is None:
            raise ValueError(f"a view holds {max(len(b) for b in boxes)} boxes, more persons than {why}")
        keep = [np.sort(np.argsort(-s, kind="stable")[:limit]) for s in scores]
        boxes = [b[k] for b, k in zip(boxes, keep, strict=True)]
        if candidate is not None:
            candidate = [c[k] for c, k in zip(candidate, keep, strict=True)]
        return boxes, [s[k] for s, k in zip(scores, keep, strict=True)], candidate

    def detect(self, views: list[SceneView]) -> Detected:
        """The detector's boxes ``(K_v, 4)`` and scores ``(K_v,)`` per view, and which of them are unsure
        (``PipelineConfig.candidate_score`` up to the detector's threshold; None when unsure ones are not used;
        ``pipeline.skeleton_matching.split_unsure``): the first stage of :meth:`run` in detector mode."""
        if self.detector is None:
            raise ValueError("no detector is loaded: give reference boxes")
        t0 = time.perf_counter()
        boxes, scores, candidate = self._detect(views)
        return Detected(boxes, scores, candidate, _ms(t0))

    def _detect(self, views: list[SceneView]) -> tuple[list, list, list | None]:
        """:meth:`detect`'s boxes, scores and unsure masks."""
        threshold = self.detector.score_threshold
        low = self.config.candidate_score
        use_low = self.config.matcher.startswith("skeletons") and low is not None and low < threshold
        detections = self.detector.detect(
            [v.color for v in views],
            depths=[v.depth for v in views],
            score_threshold=low if use_low else None,
        )
        boxes = [np.asarray(d.boxes, np.float32).reshape(-1, 4) for d in detections]  # (K_v, 4) each
        scores = [np.asarray(d.scores, np.float32).reshape(-1) for d in detections]  # (K_v,) each
        if not use_low:
            return boxes, scores, None
        return split_unsure(boxes, scores, threshold)

    def _skeleton_config(self) -> SkeletonMatchConfig:
        """The skeleton matcher's thresholds (``skeletons-greedy``: its greedy rule)."""
        config = self.config.skeleton_match or SkeletonMatchConfig()
        return replace(config, link_reward_mm=None) if self.config.matcher == "skeletons-greedy" else config

    def _match_skeletons(
        self,
        boxes: list[np.ndarray],
        views: list[SceneView],
        candidate=None,
        detected: bool = False,
    ):
        """The U-Net once on every box, each box lifted alone, the boxes grouped by their skeletons.

        Returns ``(heat, match_ms, groups, centres)``: the heatmaps to fuse from, the milliseconds of the
        association (after the U-Net and each box's softmax moments, which the fusion needs with any grouping),
        the persons (``pipeline.matching.Group``), and every box's 3D centre (N, 3) (``group_unsure`` reads
        them again)."""
        heat = self.pose.box_heatmaps(list(views), boxes)
        heat.reduce()  # the fusion's per-box softmax, needed whatever groups the boxes: the pose stage's
        t0 = time.perf_counter()
        centres = box_centres_3d(boxes, [v.depth for v in views], [v.camera for v in views])[0]
        groups = match_heatmaps(
            heat,
            views,
            boxes,
            self._skeleton_config(),
            max_combinations=self.config.max_match_combinations,
            candidate=candidate,
            detected=detected,
            centres=centres,
        )
        return heat, _ms(t0), groups, centres

    # ----------------------------------------------------------------------------------------- offline
    def run_sample(self, sample: Sample, reference_boxes: bool = True) -> tuple[SceneResult, list[dict]]:
        """Run on a dataset :class:`Sample`; also return its predictions in ``posenet.evaluation.evaluate``'s format.

        With ``reference_boxes`` the sample's annotated boxes and person ids are used (the paper's ablation
        setting), so each prediction carries the ground truth's person id. In detector mode each person gets
        the id of the annotated person whose boxes it overlaps most (the paper's rule,
        ``posenet.boxes.ground_truth_ids``); persons that overlap nobody are left out of the predictions.
        """
        views = sample.views
        if reference_boxes:
            boxes, ids = zip(*(identified(v.boxes, v.box_person_ids) for v in sample.views), strict=True)
            result = self.run(views, list(boxes), list(ids))
            ids = [p.id for p in result.persons]
        else:
            result = self.run(views)
            ids = ground_truth_ids(sample, result.boxes)
        predictions = [
            prediction_record(sample.id, pid, p.joints, p.spread_mm, p.confidence)
            for p, pid in zip(result.persons, ids, strict=True)
            if pid is not None
        ]
        return result, predictions
