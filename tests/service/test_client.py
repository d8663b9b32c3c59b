"""The batch client: its resumable output file, the detector-mode identity association, and a
killed-and-resumed
run against a real server (uvicorn subprocess, tiny random-init models, the tiny MVOR-format dataset)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import write_tiny_mvor
from service_harness import REPO_ROOT, Server, free_port, tiny_checkpoints

from posenet.boxes import PersonBoxes, assign, mean_view_iou
from posenet.data.mvor import MvorDataset
from service.client import ClientConfig, append_line, lock_output, predictions, read_done, run


def test_read_done_drops_a_torn_last_line_and_appends_cleanly(tmp_path):
    out = tmp_path / "results.jsonl"
    assert read_done(out) == {}
    with open(out, "a") as f:
        append_line(f, {"id": "a", "status": 200})
        append_line(f, {"id": "b", "status": 422})
        f.write('{"id": "c", "sta')  # a kill in the middle of a write
    assert set(read_done(out)) == {"a", "b"}
    with open(out, "a") as f:
        append_line(f, {"id": "c", "status": 200})
    lines = out.read_text().splitlines()
    assert [json.loads(x)["id"] for x in lines] == ["a", "b", "c"]


def test_association_recovers_a_permutation_and_respects_missing_views():
    rng = np.random.default_rng(0)
    xy = rng.uniform(0, 500, (5, 3, 2))
    gt = np.concatenate([xy, xy + rng.uniform(40, 120, (5, 3, 2))], axis=-1)  # (G, V, 4)
    perm = rng.permutation(5)
    pred = [[list(b + rng.normal(0, 2, 4)) for b in gt[g]] for g in perm]
    pred[0][1] = None  # a person the detector missed in one view still matches
    gt_list = [[list(b) for b in person] for person in gt]
    assert assign(pred, gt_list) == perm.tolist()
    # A view where only one side has a box scores 0: the mean over 3 views of (1, 1, 0) is 2/3.
    one = PersonBoxes.from_lists([[[0, 0, 10, 10], [0, 0, 10, 10], None]], 3)
    two = PersonBoxes.from_lists([[[0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, 10]]], 3)
    np.testing.assert_allclose(mean_view_iou(one, two), [[2 / 3]])
    assert assign([[[0, 0, 1, 1], None, None]], gt_list) == [None]  # no overlap: no identity
    with pytest.raises(ValueError, match="same views"):
        mean_view_iou(one, PersonBoxes.from_lists([[None, None]], 2))


def client_cmd(data, url, out, *extra) -> list[str]:
    return [sys.executable, "-m", "service.client", str(data.root), "--annotations", str(data.annotations),
            "--url", url, "--out", str(out), *extra]  # fmt: skip


@pytest.mark.slow
def test_client_resumes_after_being_killed(tmp_path):
    data = write_tiny_mvor(tmp_path / "tiny", days=(1, 2), frames_per_day=4)
    ids = [mv["id"] for mv in data.gt["multiview_images"]]
    pose, _ = tiny_checkpoints(tmp_path / "ckpt", detector=False)  # reference boxes: no detector needed
    # One request in flight on the server and three from the client: the client must retry the 503s.
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_LOAD_DETECTOR": "false", "ORPOSE_MAX_IN_FLIGHT": "1"}
    out = tmp_path / "results.jsonl"
    with Server(env) as url:
        cmd = client_cmd(data, url, out, "--reference-boxes", "--concurrency", "3")
        first = subprocess.Popen(cmd, cwd=REPO_ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out.exists() and out.read_bytes().count(b"\n") >= 1):
            time.sleep(0.02)
        os.kill(first.pid, signal.SIGKILL)
        first.wait()
        written = out.read_bytes().count(b"\n")
        assert 1 <= written < len(ids), "the first run should have been killed mid-way"
        with open(out, "a") as f:
            f.write('{"id": "' + ids[-1][:10])  # and as if the kill had cut a line short

        second = subprocess.run(
            [*cmd, "--evaluate"], cwd=REPO_ROOT, capture_output=True, text=True, timeout=120
        )
    assert second.returncode == 0, second.stdout + second.stderr
    lines = [json.loads(x) for x in out.read_text().splitlines()]
    assert sorted(x["id"] for x in lines) == sorted(ids)  # every frame once: nothing lost, nothing duplicated
    assert all(x["status"] == 200 and x["response"]["mode"] == "reference_boxes" for x in lines)
    assert f"{written} already in" in second.stdout and f"{len(ids) - written} done now" in second.stdout
    assert "MPJPE (cm) per number of supporting views" in second.stdout
    assert "0 without a prediction" in second.stdout  # every annotated pose got a prediction


def test_detector_mode_predictions_get_ground_truth_ids_by_iou(tiny_mvor_dataset):
    data = tiny_mvor_dataset
    ds = MvorDataset(None, data.gt)
    sample = ds[0]
    gt_ids = sorted(set(sample.person_ids.tolist()))
    # A detector-mode response whose persons are the annotated ones, shuffled, boxes jittered by a few pixels.
    rng = np.random.default_rng(1)
    persons = []
    for n, pid in enumerate(reversed(gt_ids)):
        views = [{"view": v, "box": (np.asarray(b) + rng.normal(0, 3, 4)).tolist(), "score": 0.9}
                 for v, b in enumerate(sample.person_boxes(pid)) if b is not None]  # fmt: skip
        joints = [{"name": "j", "position": [float(n), 0.0, 0.0], "confidence": 0.8, "spread_mm": 50.0}] * 10
        persons.append({"id": n, "joints": joints, "views": views})
    stray = {"view": 0, "box": [0, 0, 5, 5], "score": 0.6}  # overlaps no annotated box: no identity
    persons.append({"id": 9, "joints": persons[0]["joints"], "views": [stray]})
    lines = {
        sample.id: {"id": sample.id, "status": 200, "response": {"mode": "detector", "persons": persons}}
    }
    preds = predictions(lines, ds)
    expected = [(pid, float(n)) for n, pid in enumerate(reversed(gt_ids))]
    assert [(p["person_id"], p["keypoints3D"][0]) for p in preds] == expected
    assert all(p["confidence"] == [0.8] * 10 and p["spread_mm"] == [50.0] * 10 for p in preds)


def test_unreachable_server_and_missing_files_are_failures_not_lines(tiny_mvor_dataset, tmp_path):
    data = tiny_mvor_dataset
    ds = MvorDataset(None, data.gt)
    (data.root / ds[0].views[1].file_name).unlink()  # one frame cannot be read
    out = tmp_path / "out.jsonl"
    cfg = ClientConfig(url=f"http://127.0.0.1:{free_port()}", retries=0)  # nothing listens there
    counts = run(ds, data.root, out, cfg)
    assert counts["gave_up"] == len(ds) and counts["ok"] == counts["rejected"] == 0
    assert read_done(out) == {}  # a later run retries every frame


def test_a_second_client_on_the_same_output_file_refuses(tiny_mvor_dataset, tmp_path):
    # The first client holds the lock for as long as it writes; the second opens the file afresh, as another
    # process would, and cannot take it.
    out = tmp_path / "results.jsonl"
    dataset = MvorDataset(None, tiny_mvor_dataset.gt)
    with open(out, "a") as first:
        lock_output(first, out)
        with pytest.raises(SystemExit, match=f"{out} is in use by another batch client"):
            run(dataset, tiny_mvor_dataset.root, out, ClientConfig(url="http://127.0.0.1:9"))
    assert out.read_text() == ""  # the refused client wrote nothing and posted nothing
