"""The evaluator: hand-computed cases, perfect predictions, missing and unannotated joints, folds, the CLI."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO_ROOT, write_tiny_mvor

from posenet.evaluation.evaluate import evaluate, evaluate_folds, format_tables, main
from posenet.skeleton import JOINT_TYPES, SUPPORT_TYPES


@pytest.fixture(scope="module")
def gt(tmp_path_factory) -> dict:
    """The tiny dataset's annotations: 4 frames (days 1, 2) of 2 poses, supports 3/2 and 3/1.

    Poses 3 and 7 (person 1 in each day's second frame) have support 1 and an unannotated right wrist.
    """
    return write_tiny_mvor(tmp_path_factory.mktemp("tiny")).gt


def truth(pose: dict) -> np.ndarray:
    return np.asarray(pose["keypoints3D"], np.float64).reshape(-1, 4)[:10, :3]


def predict(gt: dict, offset=None, skip=()) -> list[dict]:
    """Predictions = truth + ``offset(pose_index, pose)`` ((10, 3) mm), leaving out the poses in ``skip``."""
    preds = []
    for i, pose in enumerate(gt["annotations3D"]):
        if i in skip:
            continue
        joints = truth(pose) + (0 if offset is None else offset(i, pose))
        preds.append(
            {
                "image_ids": pose["image_ids"],
                "person_id": pose["person_id"],
                "keypoints3D": joints.ravel().tolist(),
            }
        )
    return preds


def test_perfect_predictions_score_zero(gt: dict) -> None:
    result = evaluate(gt, predict(gt))
    assert result["overall"] == 0.0
    assert all(v == 0.0 for v in result["per_joint"].values())
    assert result["per_support"].keys() == {"1", "2", "3"}
    assert {k: row["count"] for k, row in result["per_support"].items()} == {"1": 2, "2": 2, "3": 4}
    assert all(row[t] == 0.0 for row in result["per_support"].values() for t in [*SUPPORT_TYPES, "average"])
    c = result["counts"]
    assert (c["poses"], c["evaluated_poses"], c["missing"], c["unmatched_predictions"]) == (8, 8, 0, 0)
    assert (c["evaluated_joints"], c["unannotated_joints"]) == (78, 2)  # one flag-0 right wrist per day


def test_constant_offset_is_its_length_everywhere(gt: dict) -> None:
    result = evaluate(gt, predict(gt, lambda i, p: np.array([30.0, 40.0, 0.0])))  # 50 mm
    assert result["overall"] == pytest.approx(5.0)
    assert all(v == pytest.approx(5.0) for v in result["per_joint"].values())
    assert all(row["average"] == pytest.approx(5.0) for row in result["per_support"].values())


def test_hand_computed_case(gt: dict) -> None:
    # Left joints off by 10 mm, right ones by 30 mm along x; head 40 mm; neck exact; one pose's wrists 110 mm.
    offsets = np.zeros((10, 3))
    offsets[[2, 4, 6, 8], 0] = 10.0
    offsets[[3, 5, 7, 9], 0] = 30.0
    offsets[0, 2] = 40.0

    def offset(i, pose):
        o = offsets.copy()
        if i == 3:  # frame 1 of day 1, person 1: support 1, right wrist unannotated
            o[[8, 9], 0] = 110.0
        return o

    result = evaluate(gt, predict(gt, offset))
    pj = result["per_joint"]
    assert pj["head"] == pytest.approx(4.0) and pj["neck"] == 0.0
    # Left mean 1 cm and right mean 3 cm, averaged: 2 cm (not weighted by joint counts).
    for t in ("shoulder", "hip", "elbow"):
        assert pj[t] == pytest.approx(2.0)
    # Wrists: left = (7 * 1 + 11) / 8 = 2.25 cm; right: poses 3 and 7 unannotated, the other six 3 cm.
    assert pj["wrist"] == pytest.approx((2.25 + 3.0) / 2)
    assert pj["average"] == pytest.approx((4.0 + 0 + 2 + 2 + 2 + 2.625) / 6)
    # Overall: every annotated joint alike. A pose sums 4 + 0 + 4 * 1 + 4 * 3 = 20 cm over 10 joints; pose 3
    # swaps its left wrist's 1 for 11 and drops the right wrist, pose 7 drops the right wrist: 78 joints.
    assert result["overall"] == pytest.approx((8 * 20 - 3 - 1 + 11 - 3) / 78)
    # Support 1 holds poses 3 and 7: left wrists 11 and 1 cm, no annotated right wrist: the type is the left.
    one = result["per_support"]["1"]
    assert one["wrist"] == pytest.approx(6.0)
    assert one["shoulder"] == pytest.approx(2.0)
    assert one["average"] == pytest.approx((2 + 2 + 2 + 6) / 4)
    assert result["per_support"]["3"]["wrist"] == pytest.approx(2.0)


def test_missing_predictions_and_unannotated_joints_are_counted(gt: dict) -> None:
    result = evaluate(
        gt, predict(gt, skip={3, 4})
    )  # pose 3: support 1 with a flag-0 joint; pose 4: support 3
    c = result["counts"]
    assert (c["poses"], c["evaluated_poses"], c["missing"]) == (8, 6, 2)
    assert c["unannotated_joints"] == 1  # pose 7's; pose 3's flag-0 joint belongs to a missing pose
    assert c["evaluated_joints"] == 59
    assert result["per_support"]["1"]["missing"] == 1 and result["per_support"]["1"]["count"] == 1
    assert result["per_support"]["3"]["missing"] == 1 and result["per_support"]["3"]["count"] == 3
    text = format_tables(result)
    assert "2 without a prediction" in text and "1 unannotated" in text


def test_unmatched_and_duplicate_keys(gt: dict) -> None:
    extra = {"image_ids": gt["annotations3D"][0]["image_ids"], "person_id": 9, "keypoints3D": [0.0] * 30}
    assert evaluate(gt, [*predict(gt), extra])["counts"]["unmatched_predictions"] == 1
    # Two ground-truth poses with the same key (as in the real file) are matched to predictions in order.
    dup = copy.deepcopy(gt)
    dup["annotations3D"][1]["person_id"] = 0
    result = evaluate(dup, predict(dup))
    assert result["overall"] == 0.0 and result["counts"]["evaluated_poses"] == 8
    swapped = predict(dup)
    swapped[0], swapped[1] = swapped[1], swapped[0]
    assert evaluate(dup, swapped)["overall"] > 1.0


def test_scope_by_image_ids_and_days(gt: dict) -> None:
    preds = predict(gt, lambda i, p: np.full(3, 10.0 * (1 + (i >= 4))))  # day 2 poses twice as far off
    day2 = evaluate(gt, preds, days=[2])
    assert day2["counts"]["poses"] == 4 and day2["counts"]["out_of_scope_predictions"] == 4
    assert day2["counts"]["unmatched_predictions"] == 0
    assert day2["overall"] == pytest.approx(2 * math.sqrt(3))
    first = gt["multiview_images"][0]["id"]
    one = evaluate(gt, preds, image_ids={first})
    assert one["counts"]["poses"] == 2 and one["overall"] == pytest.approx(math.sqrt(3))


def test_folds_mean_and_std(gt: dict) -> None:
    preds = predict(gt, lambda i, p: np.array([50.0 * (1 + (i >= 4)), 0, 0]))  # day 1: 5 cm, day 2: 10 cm
    result = evaluate_folds(gt, preds)
    assert list(result["folds"]) == ["1", "2"]
    assert result["mean"]["overall"] == pytest.approx(7.5) and result["std"]["overall"] == pytest.approx(2.5)
    assert result["mean"]["per_joint"]["wrist"] == pytest.approx(7.5)
    assert result["mean"]["per_support"]["1"]["average"] == pytest.approx(7.5)
    assert result["mean"]["per_support"]["3"]["count"] == 4  # counts add up over the folds
    assert "count" not in result["std"]["per_support"]["3"]
    assert result["counts"]["evaluated_poses"] == 8
    assert "7.5 (± 2.5)" in format_tables(result)


def test_bad_predictions_raise(gt: dict) -> None:
    good = predict(gt)[0]
    with pytest.raises(ValueError, match=r"prediction 0 .*keypoints3D has 27 numbers, expected 10\*3 = 30"):
        evaluate(gt, [{**good, "keypoints3D": good["keypoints3D"][:27]}])
    with pytest.raises(ValueError, match=r"prediction 0: missing keys \['person_id'\]"):
        evaluate(gt, [{"image_ids": "x", "keypoints3D": [0.0] * 30}])
    with pytest.raises(ValueError, match="not finite"):
        evaluate(gt, [{**good, "keypoints3D": [math.nan] * 30}])
    nested = {
        **good,
        "keypoints3D": np.reshape(good["keypoints3D"], (10, 3)).tolist(),
    }  # (J, 3) lists work too
    assert evaluate(gt, [nested])["counts"]["evaluated_poses"] == 1


def test_tables_layout(gt: dict) -> None:
    text = format_tables(evaluate(gt, predict(gt, lambda i, p: np.array([0, 0, 50.0]))))
    lines = text.splitlines()
    header = lines[1].split()
    assert header == [t.capitalize() for t in JOINT_TYPES] + ["Average"]
    assert lines[2].split() == ["5.0"] * 7
    assert "Overall MPJPE (all annotated joints): 5.0 cm" in text
    support = lines[lines.index(next(x for x in lines if x.strip().startswith("Views"))) + 1 :][:3]
    assert [row.split()[0] for row in support] == ["1", "2", "3"]


def test_cli_round_trip(gt: dict, tmp_path, capsys) -> None:
    gt_path, pred_path, out = tmp_path / "gt.json", tmp_path / "pred.json", tmp_path / "out" / "result.json"
    gt_path.write_text(json.dumps(gt))
    preds = predict(gt, lambda i, p: np.array([0, 40.0, 0]))
    pred_path.write_text(json.dumps(preds))
    assert main(["--annotations", str(gt_path), "--predictions", str(pred_path), "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "MPJPE (cm) per joint type" in printed and "supporting views" in printed
    written = json.loads(out.read_text())
    assert written["overall"] == pytest.approx(4.0)
    assert set(written["per_joint"]) == {*JOINT_TYPES, "average"}
    assert set(written["per_support"]["1"]) == {*SUPPORT_TYPES, "average", "count", "missing"}
    assert written == json.loads(json.dumps(evaluate(gt, preds)))
    # One file per fold, concatenated, with --folds; the real entry point in a fresh process.
    day1, day2 = tmp_path / "fold1.json", tmp_path / "fold2.json"
    day1.write_text(json.dumps(preds[:4]))
    day2.write_text(json.dumps(preds[4:]))
    folds_out = tmp_path / "folds.json"
    files = ["--predictions", str(day1), "--predictions", str(day2)]
    cmd = [sys.executable, "-m", "posenet.evaluation.evaluate", "--annotations", str(gt_path), *files, "--folds"]
    cmd += ["--json", str(folds_out)]
    proc = subprocess.run(cmd, cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "mean (± std) over 2 folds" in proc.stdout
    folded = json.loads(folds_out.read_text())
    assert folded["mean"]["overall"] == pytest.approx(4.0) and folded["std"]["overall"] == pytest.approx(0.0)


def test_nan_is_written_as_null(gt: dict, tmp_path) -> None:
    # A day without predictions has no means: the json holds null, not the invalid token NaN.
    gt_path, pred_path, out = tmp_path / "gt.json", tmp_path / "pred.json", tmp_path / "r.json"
    gt_path.write_text(json.dumps(gt))
    pred_path.write_text(json.dumps(predict(gt)[:4]))
    main(["--annotations", str(gt_path), "--predictions", str(pred_path), "--days", "2", "--json", str(out)])
    written = json.loads(out.read_text())
    assert written["overall"] is None and written["counts"]["missing"] == 4


def test_real_mvor_perfect_predictions(mvor_annotations: dict) -> None:
    result = evaluate(mvor_annotations, predict(mvor_annotations))
    assert result["overall"] == 0.0
    assert {k: row["count"] for k, row in result["per_support"].items()} == {"1": 132, "2": 426, "3": 503}
    assert result["counts"]["missing"] == 0 and result["counts"]["unmatched_predictions"] == 0
