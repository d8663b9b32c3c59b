"""detector.adapt and pipeline.pseudo_boxes: pseudo-labels from views, frames and the static scene; the adaptation
never reads the target's boxes or poses; resume; the result loads in detector.predict and in the service.

Tiny rendered frames (tests/tiny_scenes.py: 3 RGB-D cameras of 80x60), a tiny random DETR, one thread: seconds.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import torch
from tiny_scenes import write_dataset

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from detector.adapt import main as adapt_main  # noqa: E402
from detector.checkpoint import save_checkpoint  # noqa: E402
from detector.infer import PersonDetector  # noqa: E402
from detector.model import build_detector, preset  # noqa: E402
from pipeline.pseudo_boxes import (  # noqa: E402
    PseudoBoxConfig,
    background_depth,
    foreground_share,
    pseudo_boxes,
)
from posenet.boxes import iou_xyxy  # noqa: E402
from posenet.data.mvor import MvorDataset, load_annotations  # noqa: E402

RUN = [
    "--threads",
    "1",
    "--target-per-step",
    "2",
    "--source-per-step",
    "2",
    "--frames-per-round",
    "4",
    "--no-progress",
]


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """A target (2 days of 3 frames, 2 persons; its file holds boxes and 3D poses), the same file with neither, a
    labelled source (with the per-image list that detector.data reads) and a tiny random detector."""
    root = tmp_path_factory.mktemp("detadapt")
    target = root / "target"
    ann = write_dataset(target, {1: 3, 2: 3}, persons=2, seed=1)
    gt = json.loads(ann.read_text())
    gt["images"] = [im for mv in gt["multiview_images"] for im in mv["images"]]  # MVOR's per-image list
    ann.write_text(json.dumps(gt))
    assert gt["annotations"] and gt["annotations3D"]
    bare = root / "frames_only.json"
    bare.write_text(json.dumps({k: v for k, v in gt.items() if k not in ("annotations", "annotations3D")}))
    source = root / "source"
    src = write_dataset(source, {1: 2}, persons=1, seed=2)
    s = json.loads(src.read_text())
    s["images"] = [im for mv in s["multiview_images"] for im in mv["images"]]
    src.write_text(json.dumps(s))
    cfg = preset(
        "cpu", arch="detr", input_mode="rgbd", backbone_stage=3, input_width=80, d_model=32,
        encoder_layers=1, decoder_layers=1, ffn_dim=64, num_queries=6,
    )  # fmt: skip
    torch.manual_seed(0)
    init = save_checkpoint(root / "init", build_detector(cfg), cfg, train={"data": "random init (tests)"})
    return {
        "root": root,
        "target": target,
        "labelled": ann,
        "bare": bare,
        "source": source,
        "init": init.parent,
    }


def _args(tiny, out, annotations="bare", *extra):
    return ["--data", str(tiny["target"]), "--annotations", str(tiny[annotations]), "--init", str(tiny["init"]),
            "--source-data", str(tiny["source"]), "--out", str(out), *RUN, *extra]  # fmt: skip


# ----------------------------------------------------------------------------- pseudo-boxes
def _frame(tiny, index=0):
    """A target frame's views (depth, cameras) and its true boxes per person and view."""
    ds = MvorDataset(tiny["target"], load_annotations(tiny["labelled"]), modalities=("depth",))
    sample = ds[index]
    return (
        sample,
        [v.boxes.astype(np.float64) for v in sample.views],
        [v.box_person_ids for v in sample.views],
    )


def _cameras(sample):
    from posenet.cameras import Camera

    return Camera.stack([v.camera for v in sample.views])


def test_a_person_missed_in_one_view_is_projected_there_from_the_others(tiny):
    """One person boxed in views 0 and 2 (the other person left out: the two stand close in these frames) is
    lifted with depth and projected into view 1: the box of its visible pixels, close to the true one."""
    sample, truth, ids = _frame(tiny)
    person = int(ids[1][0])
    mine = [b[i == person] for b, i in zip(truth, ids, strict=True)]
    boxes = [mine[0], np.zeros((0, 4)), mine[2]]
    scores = [np.full(len(b), 0.9) for b in boxes]
    depths = [v.depth for v in sample.views]
    out = pseudo_boxes(boxes, scores, depths, _cameras(sample), None, [[]] * 3, PseudoBoxConfig(min_points=5))
    assert out.counts == {**out.counts, "kept": 2, "filled": 1}
    assert len(out.boxes[1]) == 1 and iou_xyxy(mine[1], out.boxes[1])[0, 0] >= 0.7, (out.boxes[1], mine[1])
    for v in (0, 2):  # the views that had the box keep exactly it
        np.testing.assert_allclose(out.boxes[v], mine[v].astype(np.float32))
    # A weak teacher box where the person was projected replaces the projection (snapped)
    weak = [mine[0], mine[1] + 0.5, mine[2]]
    snapped = pseudo_boxes(weak, [np.array([0.9]), np.array([0.1]), np.array([0.9])], depths, _cameras(sample),
                           None, [[]] * 3, PseudoBoxConfig(min_points=5, low=0.05, high=0.5))  # fmt: skip
    np.testing.assert_allclose(snapped.boxes[1], (mine[1] + 0.5).astype(np.float32))


def test_a_box_that_nothing_confirms_is_dropped_and_a_neighbour_confirms_it(tiny):
    sample, truth, _ = _frame(tiny)
    depths = [v.depth for v in sample.views]
    lone = [truth[0][:1], np.zeros((0, 4)), np.zeros((0, 4))]
    scores = [np.array([0.6]), np.zeros(0), np.zeros(0)]
    cfg = PseudoBoxConfig(certain=0.7)
    alone = pseudo_boxes(lone, scores, depths, _cameras(sample), None, [[]] * 3, cfg)
    assert len(alone.boxes[0]) == 0 and alone.counts["unconfirmed"] == 1
    moved = lone[0] + 1.0  # the same person one frame later
    near = pseudo_boxes(lone, scores, depths, _cameras(sample), None, [[moved], [], []], cfg)
    assert len(near.boxes[0]) == 1
    sure = pseudo_boxes(lone, [np.array([0.8]), np.zeros(0), np.zeros(0)], depths, _cameras(sample), None,
                        [[]] * 3, cfg)  # fmt: skip
    assert len(sure.boxes[0]) == 1  # above `certain` a box stands on its own


def test_the_static_scene_is_learnt_from_depth_and_never_becomes_a_box():
    """A wall at 4 m; a person passes in 3 of 10 frames; a static block (a draped table) is in all of them."""
    frames = np.full((10, 60, 80), 4000, np.uint16)
    frames[:, 40:55, 5:35] = 3000  # the table, always there
    for t, x in enumerate((40, 50, 60)):
        frames[t, 10:50, x : x + 10] = 2000  # the person, somewhere else each time
    frames[:, 0, :] = 0  # a row that never has depth
    bg = background_depth(frames)
    assert np.isnan(bg[0]).all()
    np.testing.assert_allclose(bg[40:55, 5:35], 3000)
    np.testing.assert_allclose(bg[10:40, 40:70], 4000)
    table, person = np.array([[5.0, 40, 34, 54]]), np.array([[40.0, 10, 49, 49]])
    assert foreground_share(table, frames[0], bg, 150.0)[0] == 0.0
    assert foreground_share(person, frames[0], bg, 150.0)[0] > 0.9
    # The table, boxed in a view and confirmed by nothing but itself over time, is dropped below static_certain
    cfg = PseudoBoxConfig(certain=0.5)
    from posenet.cameras import Camera

    cam = Camera.stack([Camera.create(75.0, 75.0, 39.5, 29.5, size=(80, 60))])
    both = np.concatenate([table, person])
    out = pseudo_boxes([both], [np.array([0.6, 0.6])], [frames[0]], cam, [bg], [[both]], cfg)
    np.testing.assert_allclose(out.boxes[0], person.astype(np.float32))
    assert out.counts["static"] == 1
    sure = pseudo_boxes([both], [np.array([0.9, 0.6])], [frames[0]], cam, [bg], [[both]], cfg)
    assert len(sure.boxes[0]) == 2  # the detector's certainty outweighs the background (static_certain)


def test_a_view_with_a_box_no_rule_settled_is_marked_unsettled():
    """A weak box (0.3) on someone in front of the static scene that no kept box overlaps leaves its view
    unsettled; one that overlaps a kept box, one on the static scene and one below the floor do not."""
    from posenet.cameras import Camera

    frames = np.full((4, 60, 80), 4000, np.uint16)
    frames[:, 40:55, 5:35] = 3000  # the table, always there
    frames[0, 10:50, 40:50] = 2000  # a person
    frames[0, 10:50, 60:70] = 2000  # another person
    bg = background_depth(frames)
    cam = Camera.stack([Camera.create(75.0, 75.0, 39.5, 29.5, size=(80, 60))])
    table, a, b = np.array([5.0, 40, 34, 54]), np.array([40.0, 10, 49, 49]), np.array([60.0, 10, 69, 49])
    cfg = PseudoBoxConfig(certain=0.5, unsettled_floor=0.1)

    def run(boxes, scores, c=cfg):
        out = pseudo_boxes([np.array(boxes)], [np.array(scores)], [frames[0]], cam, [bg], [[]], c)
        return out.unsettled[0], out.counts["unsettled"]

    assert run([a, b], [0.9, 0.3]) == (True, 1)  # b: neither kept nor rejected
    assert run([a, b], [0.9, 0.05]) == (False, 0)  # below the floor
    assert run([a, a + 1.0], [0.9, 0.3]) == (False, 0)  # the weak box is the kept person's
    assert run([a, table], [0.9, 0.3]) == (False, 0)  # the weak box lies on the static scene: background
    assert run([b], [0.3]) == (True, 1)  # nothing kept at all
    assert run([a, b], [0.9, 0.3], PseudoBoxConfig(certain=0.5, unsettled_floor=None)) == (False, 0)
    # without a background model, the weak box on the table is unsettled too
    out = pseudo_boxes([np.array([a, table])], [np.array([0.9, 0.3])], [frames[0]], cam, None, [[]], cfg)
    assert out.unsettled == [True]


# ----------------------------------------------------------------------------- the CLI
def _same_weights(a, b) -> bool:
    """Bit-identical tensors (the file's header may order its metadata differently)."""
    from safetensors.torch import load_file

    x, y = (load_file(str(r / "last" / "model.safetensors")) for r in (a, b))
    return x.keys() == y.keys() and all(torch.equal(x[k], y[k]) and x[k].dtype == y[k].dtype for k in x)


def test_weights_are_bit_identical_without_the_targets_boxes_and_poses(tiny, tmp_path):
    assert adapt_main(_args(tiny, tmp_path / "a", "labelled", "--epochs", "1")) == 0
    assert adapt_main(_args(tiny, tmp_path / "b", "bare", "--epochs", "1")) == 0
    assert _same_weights(tmp_path / "a", tmp_path / "b")
    log = [json.loads(line) for line in (tmp_path / "b" / "log.jsonl").read_text().splitlines()]
    assert sum(r["pseudo"]["views"] for r in log) == 18 and np.isfinite([r["loss"] for r in log]).all()
    config = json.loads((tmp_path / "b" / "last" / "config.json").read_text())
    assert "no box, no pose" in config["train"]["data_description"]["annotations"]
    # ... and the weights moved: the student learnt and the teacher followed it
    init = PersonDetector.from_checkpoint(tiny["init"]).model.state_dict()
    adapted = PersonDetector.from_checkpoint(tmp_path / "b" / "last").model.state_dict()
    assert any(not torch.equal(init[k], adapted[k]) for k in init if init[k].is_floating_point())


def test_a_control_on_the_source_alone_takes_the_same_steps_and_labels_nothing(tiny, tmp_path):
    """``--target-per-step 0``: the steps a run at 4 target views per step takes (18 views in rounds of 4 frames:
    12 and 6 views, 3 + 2 steps), on source views only; the teacher labels nothing."""
    assert adapt_main(_args(tiny, tmp_path / "c", "bare", "--epochs", "1", "--target-per-step", "0")) == 0
    log = [json.loads(line) for line in (tmp_path / "c" / "log.jsonl").read_text().splitlines()]
    assert all(r["pseudo"] == {} for r in log)
    views_per_round = [12, 6]  # 6 frames of 3 views in rounds of 4 frames
    assert sorted(r["steps"] for r in log)[-1] == sum(-(-v // 4) for v in views_per_round)
    init = PersonDetector.from_checkpoint(tiny["init"]).model.state_dict()
    control = PersonDetector.from_checkpoint(tmp_path / "c" / "last").model.state_dict()
    assert any(not torch.equal(init[k], control[k]) for k in init if init[k].is_floating_point())


def test_the_over_confidence_benchmark_counts_what_the_teacher_would_keep(tiny, tmp_path):
    """benchmarks/adapt_confidence.py: a detector's pseudo-label counts on unlabelled frames, as a table and JSON."""
    import subprocess
    import sys

    out = tmp_path / "counts.json"
    run = subprocess.run(
        [sys.executable, str(Path(__file__).resolve().parents[2] / "benchmarks" / "adapt_confidence.py"),
         "--data", str(tiny["target"]), "--annotations", str(tiny["bare"]), "--max-frames", "2",
         "--checkpoints", str(tiny["init"]), str(tiny["init"]), "--labels", "a", "b", "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-2000:]
    rows = json.loads(out.read_text())["rows"]
    assert [r["detector"] for r in rows] == ["a", "b"] and rows[0]["frames"] == 2 and rows[0]["views"] == 6
    assert {k: v for k, v in rows[0].items() if k != "detector"} == {
        k: v for k, v in rows[1].items() if k != "detector"
    }
    assert "| a |" in run.stdout and "machine:" in run.stdout


def test_resume_continues_where_it_stopped(tiny, tmp_path):
    constant = ["--decay-start", "1.0", "--warmup", "0"]  # the LR does not depend on the planned length
    assert adapt_main(_args(tiny, tmp_path / "whole", "bare", "--epochs", "2", *constant)) == 0
    assert adapt_main(_args(tiny, tmp_path / "split", "bare", "--epochs", "1", *constant)) == 0
    assert adapt_main(_args(tiny, tmp_path / "split", "bare", "--epochs", "2")) == 2  # a run is there
    assert (
        adapt_main(
            [
                "--data",
                str(tiny["target"]),
                "--out",
                str(tmp_path / "split"),
                "--resume",
                "--epochs",
                "2",
                "--no-progress",
            ]
        )
        == 0
    )
    assert _same_weights(tmp_path / "whole", tmp_path / "split")
    log = (tmp_path / "split" / "log.jsonl").read_text().splitlines()
    assert [(json.loads(line)["epoch"], json.loads(line)["round"]) for line in log] == [
        (1, 1),
        (1, 2),
        (2, 1),
        (2, 2),
    ]


def test_clear_errors(tiny, tmp_path, capsys):
    no_source = [a for a in _args(tiny, tmp_path / "x") if a not in ("--source-data", str(tiny["source"]))]
    assert adapt_main(no_source) == 2
    assert "--source-data is required" in capsys.readouterr().err
    assert adapt_main(_args(tiny, tmp_path / "y", "bare", "--days", "7")) == 2
    assert "no frames of days [7]" in capsys.readouterr().err
    assert adapt_main(["--data", str(tiny["target"]), "--out", str(tmp_path / "nothing"), "--resume"]) == 2
    assert "start the run without --resume" in capsys.readouterr().err
    assert adapt_main(_args(tiny, tmp_path / "z", "bare", "--low", "0.8", "--high", "0.5")) == 2
    assert "--low" in capsys.readouterr().err


def test_the_result_loads_in_predict_and_in_the_service(tiny, tmp_path):
    import httpx
    from service_harness import Server, tiny_checkpoints

    from detector import predict as predict_cli

    run = tmp_path / "run"
    assert adapt_main(_args(tiny, run, "bare", "--epochs", "1")) == 0
    results = predict_cli.main(
        ["--data", str(tiny["target"]), "--annotations", str(tiny["labelled"]), "--checkpoint", str(run / "last"),
         "--days", "2", "--out", str(tmp_path / "boxes.json"), "--threads", "1"]
    )  # fmt: skip
    assert {r["image_id"] for r in results} <= {im["id"] for mv in json.loads(
        tiny["labelled"].read_text())["multiview_images"] for im in mv["images"]}  # fmt: skip
    pose, _ = tiny_checkpoints(tmp_path, detector=False)
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(run / "last")}
    with Server(env) as url:
        info = httpx.get(f"{url}/model", timeout=30).json()
    assert info["detector_loaded"] is True
