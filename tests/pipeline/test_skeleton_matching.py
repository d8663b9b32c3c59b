"""Association by single-view skeletons: per-box heatmaps reused for fusion, the grouping rule, the matcher option."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from conftest import write_tiny_mvor

from pipeline.association import evaluate_association
from pipeline.matching import match_boxes
from pipeline.skeleton_matching import SkeletonMatchConfig, group_skeletons, members_of, skeleton_distances
from pipeline.two_stage import PipelineConfig, ScenePipeline
from posenet.data.mvor import MvorDataset
from posenet.net.infer import PoseEstimator
from posenet.net.inputs import InputConfig
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import Scene

TEMPLATE = np.array(
    [[0, -700, 0], [0, -550, 0], [180, -500, 0], [-180, -500, 0], [120, 0, 0], [-120, 0, 0],
     [250, -260, 40], [-250, -260, 40], [270, -60, 160], [-270, -60, 160]], np.float64,
)  # fmt: skip


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    data = write_tiny_mvor(tmp_path_factory.mktemp("tiny"), days=(1,), frames_per_day=2)
    return data, MvorDataset(data.root, data.gt)


def estimator(**model) -> PoseEstimator:
    torch.manual_seed(0)
    cfg = ModelConfig(precision="fp32", **model)  # float32: batched and single runs agree to rounding
    return PoseEstimator(PoseNet(cfg), {"model": dataclasses.asdict(cfg)})


def frame(sample):
    views = sample.views
    boxes = [np.asarray(v.boxes, np.float32).reshape(-1, 4) for v in sample.views]
    return views, boxes


MODELS = {
    "crop": {},
    "crop+flip": {"flip_test": True},
    "2d": {"aggregation": "2d"},
    "full": {"inputs": InputConfig(mode="full", image_size=(64, 48), train_crop=(64, 48), source_size=None)},
}


@pytest.mark.parametrize("model", MODELS)
def test_fusion_from_box_heatmaps_equals_predict(tiny, model):
    """Grouped boxes fused from the per-box heatmaps give what a fresh ``predict`` on those boxes gives, and a
    box lifted alone gives the skeleton of a person seen in that view only."""
    est = estimator(**MODELS[model])
    views, boxes = frame(tiny[1][0])
    heat = est.box_heatmaps(views, boxes)
    starts = np.cumsum([0] + [len(b) for b in boxes])
    # Every box alone, and two groupings across views (one box per view; one view missing).
    alone = heat.single_view()
    assert alone.joints.shape == (heat.num_boxes, 10, 3) and alone.has_points.all()
    # Not in order: the general (gathering) path of estimate.
    backwards = heat.estimate(np.arange(heat.num_boxes)[::-1, None].copy())
    np.testing.assert_allclose(backwards.joints.numpy()[::-1], alone.joints.numpy(), atol=1e-3)
    for n in range(heat.num_boxes):
        v = int(heat.view[n])
        person = [[boxes[v][n - starts[v]] if w == v else None for w in range(3)]]
        ref = est.predict(Scene.from_person_boxes(views, person))
        np.testing.assert_allclose(alone.joints[n], ref.joints[0], atol=1e-2)
        np.testing.assert_allclose(alone.spread_mm[n], ref.spread_mm[0], atol=1e-2)
    members = np.array([[starts[0], starts[1], starts[2]], [starts[0] + 1, starts[1] + 1, -1]])
    fused = heat.estimate(members)
    persons = [[boxes[v][m - starts[v]] if m >= 0 else None for v, m in enumerate(row)] for row in members]
    ref = est.predict(Scene.from_person_boxes(views, persons))
    np.testing.assert_allclose(fused.joints, ref.joints, atol=1e-2)
    np.testing.assert_allclose(fused.spread_mm, ref.spread_mm, atol=1e-2)
    # A box lent to two views of the fusion is not the same as one view: the test can fail.
    assert not np.allclose(fused.joints[0], alone.joints[starts[0]], atol=1.0)


def test_box_heatmaps_run_the_unet_once_per_box(tiny):
    est = estimator()
    views, boxes = frame(tiny[1][0])
    calls = []
    unet = est.model.unet
    handle = unet.register_forward_hook(lambda _m, args, _out: calls.append(args[0].shape[0]))
    try:
        heat = est.box_heatmaps(views, boxes)
        heat.single_view()
        heat.estimate(np.arange(heat.num_boxes)[None, :])
    finally:
        handle.remove()
    assert calls == [sum(len(b) for b in boxes)]


def _scene(rng, noise_mm=40.0):
    """Synthetic single-view skeletons: per box (view, person, skeleton, centre)."""
    at = {
        "A": [0, 0, 3000],
        "B": [900, 0, 3200],
        "C": [-900, 0, 2800],
        "D": [0, 0, 4200],
        "E": [1800, 0, 2500],
    }
    # (view, person): A in 3 views and duplicated in view 1; B in views 0 and 2, split in two boxes in view 0;
    # C in view 2 only; D in views 0 and 1 with a box centre lifted 1.7 m onto the wall in view 1 (the centre
    # matcher splits it, and so did the skeleton matcher's 1.5 m centre bound before 2026-12-05); E in views 1 and 2.
    boxes = [(0, "A"), (0, "B"), (0, "B"), (0, "D"), (1, "A"), (1, "A"), (1, "D"), (1, "E"),
             (2, "A"), (2, "B"), (2, "C"), (2, "E")]  # fmt: skip
    joints, centres = [], []
    for i, (v, p) in enumerate(boxes):
        skeleton = TEMPLATE + at[p] + rng.normal(0, noise_mm, TEMPLATE.shape)
        skeleton[rng.integers(10)] += [0, 0, 900]  # one joint lifted onto the background
        joints.append(skeleton)
        centre = np.asarray(at[p], float) + rng.normal(0, 50, 3) + [0, -300, 0]
        if (v, p) == (1, "D"):
            centre += [0, 0, 1700]
        centres.append(centre)
        if i == 2:
            joints[-1][4:] += [0, 0, 150]  # the lower half of a split person is read less well
    order = rng.permutation(len(boxes))
    order = order[np.argsort([boxes[i][0] for i in order], kind="stable")]  # shuffled within each view
    view = np.array([boxes[i][0] for i in order])
    who = [boxes[i][1] for i in order]
    return view, np.stack(joints)[order], np.stack(centres)[order], who


@pytest.mark.parametrize("seed", range(5))
def test_grouping_recovers_persons_split_duplicated_and_single_view(seed):
    rng = np.random.default_rng(seed)
    view, joints, centres, who = _scene(rng)
    ok = np.ones(joints.shape[:2], bool)
    groups = group_skeletons(view, joints, ok, centres, 3)
    found = sorted(sorted(who[i] for i in m) for m, _ in groups)
    assert found == [["A", "A", "A", "A"], ["B", "B", "B"], ["C"], ["D", "D"], ["E", "E"]]
    assert [len(set(view[m])) for m, _ in groups] == [3, 2, 2, 2, 1]  # multi-view first
    # The paper's centre matcher on the same boxes splits D, whose centre fell on the wall in view 1.
    from pipeline.matching import choose_greedily, valid_combinations

    by_centre = choose_greedily(valid_combinations(centres, view, 750.0), len(view))
    assert any(sorted(who[i] for i in m) == ["D"] for m, _ in by_centre)


def test_skeleton_distance_is_a_median_over_joints_valid_in_both():
    a = np.zeros((1, 5, 3))
    b = np.zeros((1, 5, 3))
    b[0, :, 0] = [10, 20, 30, 5000, 5000]
    ok = np.ones((2, 5), bool)
    d = skeleton_distances(np.concatenate([a, b]), ok)
    assert d[0, 1] == d[1, 0] == 30 and d[0, 0] == 0
    ok[1, :3] = False  # only the far joints remain
    assert skeleton_distances(np.concatenate([a, b]), ok)[0, 1] == 5000
    ok[0, 3:] = False  # nothing valid in both
    assert np.isnan(skeleton_distances(np.concatenate([a, b]), ok)[0, 1])
    # A box without any valid joint stays alone.
    groups = group_skeletons(np.array([0, 1]), np.concatenate([a, a]), np.array([[True] * 5, [False] * 5]),
                             np.zeros((2, 3)), 2)  # fmt: skip
    assert [list(m) for m, _ in groups] == [[0], [1]]


def test_skeletons_are_the_default_and_centres_give_todays_groups(tiny):
    est = estimator()
    pipe = ScenePipeline(est, config=PipelineConfig(matcher="centres"))
    assert PipelineConfig().matcher == "skeletons"
    with pytest.raises(ValueError, match="matcher"):
        PipelineConfig(matcher="nearest")
    sample = tiny[1][0]
    views, boxes = frame(sample)
    result = pipe.run(views, boxes)
    groups = match_boxes(boxes, [v.depth for v in views], [v.camera for v in views])
    persons = [[None if k < 0 else boxes[v][k] for v, k in enumerate(g.indices)] for g in groups]
    ref = est.predict(Scene.from_person_boxes(views, persons))
    assert [p.support for p in result.persons] == [
        [v for v, k in enumerate(g.indices) if k >= 0] for g in groups
    ]
    np.testing.assert_array_equal(np.stack([p.joints for p in result.persons]), ref.joints.numpy())


def test_pipeline_with_the_skeleton_matcher(tiny):
    """Each person's joints are the fusion of the boxes it was given; timings keep their three stages; the
    association evaluation runs with either matcher."""
    est = estimator()
    pipe = ScenePipeline(est, config=PipelineConfig(matcher="skeletons"))
    sample = tiny[1][0]
    views, boxes = frame(sample)
    result = pipe.run(views, boxes)
    assert result.persons and set(result.timings) == {"detect", "match", "pose"}
    # boxes a user sent are never dropped (the outlier rule is for detected boxes): each is in one person
    held = sorted((v, k) for p in result.persons for v, ks in enumerate(p.box_indices) for k in ks)
    assert held == [(v, k) for v, b in enumerate(boxes) for k in range(len(b))]
    assert sum(len(p.support) for p in result.persons) <= sum(len(b) for b in boxes)
    single = 0
    for person in result.persons:
        if all((boxes[v] == person.boxes[v]).all(1).any() for v in person.support):
            single += 1  # one detected box per view (a person merged within a view reports the boxes' hull)
            alone = est.predict(Scene.from_person_boxes(views, result.boxes.select([person.row])))
            np.testing.assert_allclose(person.joints, alone.joints[0], atol=1e-2)
    assert single > 0
    greedy = ScenePipeline(est, config=PipelineConfig(matcher="skeletons-greedy")).run(views, boxes)
    assert greedy.persons and sum(len(p.support) for p in greedy.persons) <= sum(len(b) for b in boxes)
    with pytest.raises(ValueError, match="skeletons-greedy"):
        PipelineConfig(matcher="nearest")
    for matcher in ("centres", "skeletons"):
        m = evaluate_association(tiny[1], matcher=matcher, pose=est, progress=False)
        assert m["found"] + m["split"] + m["merged"] + m["missed"] == m["persons"] > 0
    with pytest.raises(ValueError, match="pose network"):
        evaluate_association(tiny[1], matcher="skeletons", progress=False)
    # A sweep scores every config from the same heatmaps: each row equals a run with that config alone.
    configs = [
        SkeletonMatchConfig(threshold_mm=t, same_view_mm=s)
        for t in (1.0, 600.0)
        for s in (1.0, SkeletonMatchConfig().same_view_mm)
    ]  # the last is the default
    rows = evaluate_association(
        tiny[1], matcher="skeletons", pose=est, skeleton_configs=configs, progress=False
    )
    assert rows[3] == evaluate_association(tiny[1], matcher="skeletons", pose=est, progress=False)
    # 1 mm across views groups no two views: nobody is found whole where a person has boxes in several views
    assert rows[0]["split"] >= rows[3]["split"] and rows[0]["groups"] >= rows[3]["groups"]


def test_members_of_lists_every_box_of_a_group():
    from pipeline.matching import Group

    boxes = [np.zeros((2, 4)), np.zeros((1, 4)), np.zeros((3, 4))]
    groups = [Group((1, -1, 0), np.zeros(3), 0.0, ((2, 2),)), Group((-1, 0, -1), np.zeros(3), 0.0)]
    np.testing.assert_array_equal(members_of(groups, boxes), [[1, 3, 5], [2, -1, -1]])


def test_served_detector_mode_with_the_skeleton_matcher(tmp_path, tiny):
    """A real uvicorn server with ORPOSE_MATCHER=skeletons answers a detector-mode frame and reference boxes
    without ids (a split box merged into its person's hull)."""
    import json

    import httpx
    from service_harness import Server, tiny_checkpoints

    from service.client import scene_request

    pose, det = tiny_checkpoints(tmp_path)
    env = {
        "ORPOSE_POSE_CHECKPOINT": str(pose),
        "ORPOSE_DETECTOR_CHECKPOINT": str(det),
        "ORPOSE_MATCHER": "skeletons",
    }
    data, ds = tiny
    scene, files = scene_request(ds[0], data.root, reference_boxes=False)
    with Server(env) as url, httpx.Client(base_url=url, timeout=120) as client:
        r = client.post("/scenes", data={"scene": json.dumps(scene)}, files=files)
        assert r.status_code == 200, r.text
        out = r.json()
        assert out["mode"] == "detector" and out["timings"]["detect"] > 0 and out["persons"]
        for person in out["persons"]:
            assert np.isfinite([j["position"] for j in person["joints"]]).all()
            assert all(0 <= s["score"] <= 1 for s in person["views"])
        # Reference boxes without ids, one person's box in view 0 also sent split in half: whatever the
        # grouping, a 200 whose boxes are the boxes as sent, or the hull of several of them (a merged split).
        ref, files = scene_request(ds[0], data.root, reference_boxes=True)
        for view in ref["views"]:
            del view["person_ids"]
        x0, y0, x1, y1 = ref["views"][0]["boxes"][0]
        ref["views"][0]["boxes"].append([x0, y0, (x0 + x1) / 2, y1])
        r = client.post("/scenes", data={"scene": json.dumps(ref)}, files=files)
        assert r.status_code == 200, r.text
        for person in r.json()["persons"]:
            for s in person["views"]:
                sent = np.asarray(ref["views"][s["view"]]["boxes"])
                assert all(np.isclose(s["box"][c], sent[:, c]).any() for c in range(4)), (s, sent)
        bad = {"ORPOSE_MATCHER": "nearest"}
    with pytest.raises(RuntimeError, match="matcher"), Server({**env, **bad}, startup_s=60):
        pass


def test_a_member_bonus_lets_a_close_pair_win_over_a_loose_triple():
    """Items 0 (view 0), 1 (view 1), 2 (view 2): 0-1 are 100 apart, 2 is 500 from both. The paper's order takes
    the triple; a bonus of 200 per extra member ranks the pair (100 - 200) before the triple (367 - 400),
    and a bonus of 300 keeps the triple first (367 - 600 < 100 - 300). None is the paper's rule."""
    from pipeline.matching import choose_greedily, combinations_within

    dist = np.array([[0, 100, 500], [100, 0, 500], [500, 500, 0]], float)
    view = np.array([0, 1, 2])
    combos = combinations_within(dist, view, 600.0)

    def groups(bonus):
        return [sorted(m.tolist()) for m, _ in choose_greedily(combos, 3, bonus)]

    assert groups(None) == [[0, 1, 2]]
    assert groups(300.0) == [[0, 1, 2]]
    assert groups(200.0) == [[0, 1], [2]]
    chosen = choose_greedily(combos, 3, 200.0)
    assert chosen[0][1] == pytest.approx(100.0)  # the real mean distance, not the ranking key


class MeanFusion:
    """Fusion as the mean of the member boxes' skeletons: the grouping steps only call ``estimate``, and this
    makes the fused skeleton of a test scene known exactly (the real fusion is tested above)."""

    def __init__(self, joints: np.ndarray):
        self.joints = torch.as_tensor(joints, dtype=torch.float32)

    def estimate(self, members):
        from posenet.net.lifting import JointEstimate

        members = torch.as_tensor(np.asarray(members))
        used = (members >= 0).float()[..., None, None]  # (P, S, 1, 1)
        joints = (self.joints[members.clamp_min(0)] * used).sum(1) / used.sum(1).clamp_min(1)
        return JointEstimate(joints, torch.zeros(joints.shape[:2]), (members >= 0).any(1))

    def single_view(self):
        from posenet.net.lifting import JointEstimate

        return JointEstimate(
            self.joints, torch.zeros(self.joints.shape[:2]), torch.ones(len(self.joints), dtype=torch.bool)
        )


def _groups(*rows):
    from pipeline.matching import Group

    return [Group(tuple(r), np.zeros(3), 0.0) for r in rows]


def test_unsure_boxes_complete_persons_but_never_start_one():
    from pipeline.skeleton_matching import admit_candidates

    rng = np.random.default_rng(0)
    A, B = TEMPLATE + [0, 0, 3000], TEMPLATE + [900, 0, 3200]
    # view 0: A, B (sure); view 1: A (sure), an unsure box of B, an unsure box of nobody; view 2: an unsure
    # box of A 20 cm off, an unsure box of B 50 cm off (too far)
    skeletons = [A, B, A, B, TEMPLATE + [-2000, 0, 5000], A + [200, 0, 0], B + [0, 0, 500]]
    joints = np.stack(skeletons) + rng.normal(0, 10, (7, 10, 3))
    ok = np.ones((7, 10), bool)
    boxes = [np.zeros((2, 4)), np.zeros((3, 4)), np.zeros((2, 4))]
    candidate = [np.array([False, False]), np.array([False, True, True]), np.array([True, True])]
    groups = admit_candidates(MeanFusion(joints), _groups((0, 0, -1), (1, -1, -1)), boxes, candidate, joints,
                              ok, within_mm=300.0)  # fmt: skip
    assert [g.indices for g in groups] == [(0, 0, 0), (1, 1, -1)]
    # with no person lacking a view, or no unsure box, nothing changes
    assert admit_candidates(MeanFusion(joints), _groups((0, 0, 0)), boxes, candidate, joints, ok, 300.0)[
        0
    ].indices == (0, 0, 0)


def test_a_box_far_from_the_rest_of_its_person_is_dropped():
    from pipeline.skeleton_matching import drop_outliers

    A = TEMPLATE + [0, 0, 3000]
    # a person of 4 boxes: views 0, 1, 2 and a second box in view 1 (a duplicate); view 2's box reads someone
    # 80 cm away. Another person of two boxes that disagree (too few to tell which is wrong).
    # box numbers in view order: view 0: 0, 1; view 1: 2, 3; view 2: 4, 5
    joints = np.stack([A, A, A + [10, 0, 0], A + [0, 5, 0], A + [0, 0, 800], A + [0, 0, 900]])
    ok = np.ones((6, 10), bool)
    boxes = [np.zeros((2, 4)), np.zeros((2, 4)), np.zeros((2, 4))]
    from pipeline.matching import Group

    groups = [Group((0, 0, 0), np.zeros(3), 0.0, ((1, 1),)), Group((1, -1, 1), np.zeros(3), 0.0)]
    out = drop_outliers(MeanFusion(joints), groups, boxes, joints, ok, within_mm=300.0)
    assert out[0].indices == (0, 0, -1) and out[0].extra == ((1, 1),)
    assert out[1] == groups[1]
    assert drop_outliers(MeanFusion(joints), groups, boxes, joints, ok, within_mm=None) == groups
    assert drop_outliers(MeanFusion(joints), groups, boxes, joints, ok, within_mm=1000.0) == groups
    # the dropped box was the view's first: its other box takes its place
    joints[4], joints[2] = A, A + [0, 0, 900]
    out = drop_outliers(MeanFusion(joints), groups, boxes, joints, ok, within_mm=300.0)
    assert out[0].indices == (0, 1, 0) and out[0].extra == ()


def test_detector_mode_uses_unsure_boxes_only_to_complete_persons(tmp_path, tiny):
    """Through the pipeline with a real (tiny, untrained) detector: every person holds at least one box the
    detector was sure of, and without unsure boxes (candidate_score None) only sure boxes are used."""
    from service_harness import tiny_checkpoints

    from detector.infer import PersonDetector

    _, path = tiny_checkpoints(tmp_path, detector=True)
    det = PersonDetector.from_checkpoint(path)
    est = estimator()
    views, _ = frame(tiny[1][0])
    scores = np.concatenate([d.scores for d in det.detect([v.color for v in views], score_threshold=0.0)])
    det.cfg.score_threshold = threshold = float(np.quantile(scores, 0.97))  # a few sure boxes, many unsure
    low = ScenePipeline(est, det, PipelineConfig(candidate_score=0.0))
    sure = ScenePipeline(est, det, PipelineConfig(candidate_score=None))
    boxes, scores, candidate = low._detect(views)
    assert all(
        (s[~c] >= threshold).all() and (s[c] < threshold).all()
        for s, c in zip(scores, candidate, strict=True)
    )
    result = low.run(views)
    for person in result.persons:
        assert np.nanmax(person.scores) >= threshold
    plain = sure.run(views)
    assert all(np.isnan(s) or s >= threshold for p in plain.persons for s in p.scores)
    # asked for them (a stream's tracker), the persons of unsure boxes alone follow the frame's own, unchanged
    both = low.run(views, unsure=True)
    n = len(result.persons)
    assert [p.unsure for p in both.persons] == [False] * n + [True] * (len(both.persons) - n)
    for a, b in zip(result.persons, both.persons[:n], strict=True):
        assert a.box_indices == b.box_indices
        np.testing.assert_allclose(a.joints, b.joints, atol=0.01)
    taken = {(v, k) for p in result.persons for v, ks in enumerate(p.box_indices) for k in ks}
    for p in both.persons[n:]:
        assert all(np.isnan(s) or s < threshold for s in p.scores)
        assert not taken & {(v, k) for v, ks in enumerate(p.box_indices) for k in ks}
    assert len(both.persons) > n, "the test frame should give a person of unsure boxes alone"
    # asked through a tracker's questions (TrackerQuestions, as a stream asks Tracker.unsure_targets): they see the
    # frame's persons as they are answered, and the answer (a track within reach of all, or none) decides whether
    # the unsure ones are found at all
    from pipeline.two_stage import TrackerQuestions

    seen = []

    def ask(answer):
        targets = np.zeros((int(answer), 10, 3))  # one track, or none
        return TrackerQuestions(
            targets=lambda joints, spread, within: seen.append((joints, spread, within)) or targets,
            gate_mm=np.inf,  # within reach of every person
        )

    yes, no = low.run(views, unsure=ask(True)), low.run(views, unsure=ask(False))
    np.testing.assert_array_equal(seen[0][0], np.array([p.joints for p in result.persons]).reshape(-1, 10, 3))
    np.testing.assert_array_equal(seen[0][1], np.array([p.spread_mm for p in result.persons]).reshape(-1, 10))
    assert [p.box_indices for p in yes.persons] == [p.box_indices for p in both.persons]
    # asked, the frame's own persons are fused once (for the question and the answer): the same joints
    np.testing.assert_array_equal(
        np.array([p.joints for p in yes.persons]), np.array([p.joints for p in both.persons])
    )
    np.testing.assert_array_equal(
        np.array([p.joints for p in no.persons]), np.array([p.joints for p in result.persons])
    )
    # what finding them cost is reported apart (SceneResult.unsure_ms, a stream's timings.unsure), inside match
    assert result.unsure_ms == 0 and 0 < yes.unsure_ms <= yes.timings["match"] and 0 < no.unsure_ms
    assert [p.box_indices for p in no.persons] == [p.box_indices for p in result.persons]
    assert not any(p.unsure for p in no.persons)
    # the box it is given holds every person of unsure boxes that the frame can give (BoxHeatmaps.joint_bounds)
    lo, hi = seen[0][2]
    for p in both.persons[n:]:
        assert ((p.joints >= lo - 1e-3) & (p.joints <= hi + 1e-3)).all()


def test_association_reads_unsure_detections_as_the_service_does(tiny):
    """COCO results with scores: below --score-threshold and without candidate_score they are left out (the
    same counts as a file without them); with it they may only complete persons (the counts still add up, and
    no person is found that was missed before: unsure boxes never start one)."""
    from posenet.boxes import xyxy_to_coco

    est = estimator()
    sure, unsure = [], []
    for sample in tiny[1]:
        for view in sample.views:
            for box in np.asarray(view.boxes, np.float64).reshape(-1, 4):
                record = {
                    "image_id": int(view.image_id),
                    "category_id": 1,
                    "bbox": xyxy_to_coco(box).tolist(),
                }
                sure.append({**record, "score": 0.9})
                shifted = xyxy_to_coco(box + [40, 0, 40, 0]).tolist()  # a poorer box beside it, less sure
                unsure.append({**record, "bbox": shifted, "score": 0.3})
    kwargs = {"matcher": "skeletons", "pose": est, "progress": False, "score_threshold": 0.5}
    alone = evaluate_association(tiny[1], sure, **kwargs)
    ignored = evaluate_association(tiny[1], sure + unsure, candidate_score=None, **kwargs)
    assert ignored == alone
    used = evaluate_association(tiny[1], sure + unsure, candidate_score=0.25, **kwargs)
    assert used["found"] + used["split"] + used["merged"] + used["missed"] == used["persons"]
    assert used["missed"] <= alone["missed"]


def test_a_person_one_view_saw_where_another_sees_free_space_is_dropped():
    """Step 7: view 0 has a box of a skeleton 3 m ahead; view 1 (identical camera) looks at it too. Behind the
    skeleton only background (free space) and no box there: nobody. An occluder in front of it, or a box of view
    1 over it, or the skeleton outside view 1's image: the person stays."""
    from pipeline.matching import Group
    from pipeline.skeleton_matching import drop_unseen, seen_from
    from posenet.cameras import Camera
    from posenet.scene import SceneView

    W, H = 160, 120
    cam = Camera.create(100.0, 100.0, (W - 1) / 2, (H - 1) / 2, size=(W, H))
    person = TEMPLATE + [0, 300, 3000]  # (J, 3) mm in the reference frame (view 0 = view 1 = the reference)
    joints, ok = person[None], np.ones((1, 10), bool)
    wall = np.full((H, W), 6000, np.uint16)

    def views(depth1):
        return [SceneView(None, wall, cam), SceneView(None, depth1, cam)]

    groups = [Group((0, -1), np.zeros(3), 0.0)]
    no_box = [np.array([[40.0, 10.0, 120.0, 110.0]]), np.zeros((0, 4))]
    assert seen_from(views(wall)[1:], person, 300.0)[0].all()
    assert drop_unseen(groups, views(wall), no_box, joints, ok, 300.0, 6) == []
    # the measured depth 20 cm in front of the joints (the body's surface, or the clutter itself): still seen
    assert drop_unseen(groups, views(np.full((H, W), 2800, np.uint16)), no_box, joints, ok, 300.0, 6) == []
    occluder = np.full((H, W), 1500, np.uint16)  # something 1.5 m from view 1 hides the person
    seen, inside, _ = seen_from(views(occluder)[1:], person, 300.0)
    assert inside.all() and not seen.any()
    assert drop_unseen(groups, views(occluder), no_box, joints, ok, 300.0, 6) == groups
    unknown = np.zeros((H, W), np.uint16)  # no depth: no evidence
    assert drop_unseen(groups, views(unknown), no_box, joints, ok, 300.0, 6) == groups
    boxed = [no_box[0], no_box[0]]  # view 1 has a box over the projection: a matching problem, not clutter
    assert drop_unseen(groups, views(wall), boxed, joints, ok, 300.0, 6) == groups
    aside = TEMPLATE + [5000, 300, 3000]  # outside both images
    assert not seen_from(views(wall)[1:], aside, 300.0)[1].any()
    assert drop_unseen(groups, views(wall), no_box, aside[None], ok, 300.0, 6) == groups
    # a person of two views, or the rule off, is never dropped
    two = [Group((0, 0), np.zeros(3), 0.0)]
    assert drop_unseen(two, views(wall), boxed, np.stack([person, person]), np.ones((2, 10), bool), 300.0, 6)
    assert drop_unseen(groups, views(wall), no_box, joints, ok, None, 6) == groups


def test_unsure_boxes_left_over_are_grouped_for_a_tracker():
    """Step 8: the unsure boxes no person took are grouped among themselves (a person unsure in both views is
    one), one that another view should have seen in free space is dropped, and sure or admitted boxes are never
    reused."""
    from pipeline.matching import Group
    from pipeline.skeleton_matching import group_unsure
    from posenet.cameras import Camera
    from posenet.scene import SceneView

    W, H = 320, 240
    cam = Camera.create(200.0, 200.0, (W - 1) / 2, (H - 1) / 2, size=(W, H))
    A, B, C = (TEMPLATE + [x, 300, 3000] for x in (-900, 300, 1400))  # (J, 3) mm, in front of a wall at 6 m

    def box(person):
        uv = cam.project(torch.as_tensor(person, dtype=cam.K.dtype)).numpy()
        return np.concatenate([uv.min(0) - 5, uv.max(0) + 5])

    # view 0: A (sure), B (unsure), C (unsure); view 1 (the same camera): A (sure), B (unsure)
    boxes = [np.stack([box(A), box(B), box(C)]), np.stack([box(A), box(B)])]
    joints = np.stack([A, B, C, A, B])
    wall = np.full((H, W), 6000, np.uint16)
    views = [SceneView(None, wall, cam), SceneView(None, wall, cam)]
    candidate = [np.array([False, True, True]), np.array([False, True])]
    persons = [Group((0, 0), np.zeros(3), 0.0)]
    unsure = group_unsure(MeanFusion(joints), views, boxes, persons, candidate)
    # B in both views; C, seen by view 0 only, lies in free space before view 1's wall with no box there: nobody
    assert [g.indices for g in unsure] == [(1, 1)]
    # told which of the persons are worth finishing (a tracker's reach, from their fused joints), only those are
    seen = []

    def reaches(answer):
        return lambda fused: seen.append(fused) or np.full(len(fused), answer)

    heat = MeanFusion(joints)
    kept = group_unsure(heat, views, boxes, persons, candidate, reaches=reaches(True))
    assert [g.indices for g in kept] == [g.indices for g in unsure]
    assert group_unsure(heat, views, boxes, persons, candidate, reaches=reaches(False)) == []
    np.testing.assert_allclose(seen[0][0], B, atol=1e-3)  # asked with each person's fused joints (B, then C)
    np.testing.assert_allclose(seen[0][1], C, atol=1e-3)
    # B's box in view 1 was admitted to a person: only view 0's B is left, and view 1 has a box over it
    taken = [Group((0, 0), np.zeros(3), 0.0), Group((-1, 1), np.zeros(3), 0.0)]
    assert [g.indices for g in group_unsure(MeanFusion(joints), views, boxes, taken, candidate)] == [(1, -1)]
    assert group_unsure(MeanFusion(joints), views, boxes, persons, None) == []
    assert (
        group_unsure(MeanFusion(joints), views, boxes, persons, [np.zeros_like(c) for c in candidate]) == []
    )
