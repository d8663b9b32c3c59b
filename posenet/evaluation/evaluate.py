"""MPJPE evaluation of 3D poses against MVOR-format ground truth: the paper's two kinds of table.

Usage::

    python -m posenet.evaluation.evaluate --annotations GT.json --predictions PRED.json [--json OUT.json]
    python -m posenet.evaluation.evaluate --annotations GT.json --predictions f1.json ... --predictions f4.json --folds

``PRED.json`` is a list of
``{"image_ids": "<multi-view id>", "person_id": <int>, "keypoints3D": [J*3 floats]}``
(mm, reference = camera 0 frame, MVOR's joint order). A prediction is matched to the ground-truth
pose in ``annotations3D`` with the same ``(image_ids, person_id)``. When several ground-truth poses share that
key (the real file has four such frames), the k-th prediction with the key is matched to the k-th pose with
it, in file order.

What is counted, never silently dropped:
- ground-truth joints with flag 0 (not annotated): left out of every mean, counted as ``unannotated_joints``;
- ground-truth poses without a prediction: left out of the means, counted as ``missing`` (overall and per
  row);
- predictions without a ground-truth pose: counted as ``unmatched_predictions``.

The numbers (centimetres, as the paper prints them):
- ``per_joint``: MPJPE per joint type over all 10 joints; left and right are averaged (the mean of the left
  mean and the right mean, as MVOR's ``eval_mpjp_error_3dpose.m`` does). ``average`` is the mean of the six
  types, the "Average" column of the paper's tables.
- ``per_support``: MVOR's convention (Kadkhodamohammadi 2017): shoulder, hip, elbow and wrist per number of
  supporting views (``posenet.data.support``), each row with the mean of its four types (``average``), the
  number of evaluated poses (``count``) and of poses without a prediction (``missing``).
- ``overall``: the plain MPJPE (the paper's Eq. 1) over every annotated joint of every evaluated pose.

``--folds`` evaluates each recording day on its own (each day is the held-out set of one cross-validation
fold) and reports the mean and the standard deviation over the days, as in the paper's last table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections import defaultdict
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posenet.cli import add_annotations, add_days
from posenet.data.mvor import check_annotations, image_day, load_annotations, pose_joints
from posenet.data.support import pose_support
from posenet.skeleton import JOINT_TYPES, NUM_JOINTS, SUPPORT_TYPES

MM_PER_CM = 10.0


def _nanmean(values: Iterable[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else float("nan")


def _type_means(errors: np.ndarray, mask: np.ndarray, types: Iterable[str]) -> dict[str, float]:
    """Per joint type, the mean over sides of the per-joint means (cm). errors, mask: (N, J)."""
    counts = mask.sum(axis=0)  # (J,)
    sums = np.where(mask, errors, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        joint_means = np.where(counts > 0, sums / np.maximum(counts, 1), np.nan) / MM_PER_CM  # (J,)
    return {t: _nanmean(joint_means[list(JOINT_TYPES[t])].tolist()) for t in types}


def prediction_record(image_ids: str, person_id: int, joints, spread_mm=None, confidence=None) -> dict:
    """One prediction in this module's format, as every producer writes it (``posenet.evaluation.predict``, the service's
    pipeline and batch client).

    Args:
        image_ids: the multi-view frame id; person_id: the ground-truth person id it is matched by.
        joints: (J, 3) mm, reference frame.
        spread_mm: (J,) mm, the pose network's spread per joint (smaller is more certain), or None.
        confidence: (J,) in [0, 1], the calibrated confidence per joint (``posenet.net.calibration``), or None.
        Both are extra keys that the evaluator ignores. (Files written before the rename hold the spread under
        ``"confidence"``; nothing here reads it.)

    Numbers are rounded to 0.01 mm (far below any error measured here; it keeps the files small) and the
    confidence to 1e-4.
    """
    joints = np.asarray(joints, np.float64)
    if joints.shape != (NUM_JOINTS, 3):
        raise ValueError(f"joints must be ({NUM_JOINTS}, 3), got {joints.shape}")
    record = {
        "image_ids": str(image_ids),
        "person_id": int(person_id),
        "keypoints3D": [round(float(x), 2) for x in joints.reshape(-1)],
    }
    if spread_mm is not None:
        record["spread_mm"] = [round(float(x), 2) for x in np.asarray(spread_mm, np.float64).reshape(-1)]
    if confidence is not None:
        record["confidence"] = [round(float(x), 4) for x in np.asarray(confidence, np.float64).reshape(-1)]
    return record


def _parse_prediction(pred: dict, index: int) -> tuple[tuple[str, int], np.ndarray]:
    missing = [k for k in ("image_ids", "person_id", "keypoints3D") if k not in pred]
    if missing:
        raise ValueError(f"prediction {index}: missing keys {missing}")
    joints = np.asarray(pred["keypoints3D"], np.float64).reshape(-1)
    if joints.size != NUM_JOINTS * 3:
        raise ValueError(
            f"prediction {index} ({pred['image_ids']}, person {pred['person_id']}): keypoints3D has "
            f"{joints.size} numbers, expected {NUM_JOINTS}*3 = {NUM_JOINTS * 3} (x, y, z per joint, mm)"
        )
    if not np.isfinite(joints).all():
        raise ValueError(
            f"prediction {index} ({pred['image_ids']}, person {pred['person_id']}) is not finite"
        )
    return (str(pred["image_ids"]), int(pred["person_id"])), joints.reshape(NUM_JOINTS, 3)


@dataclass
class Matched:
    """The in-scope ground-truth poses (N of them) and the prediction matched to each (module docstring).

    gt_joints, pred_joints: (N, J, 3) mm (NaN where no prediction); valid: (N, J) annotated joints; matched: (N,)
    whether a prediction was found; support: (N,) supporting views; records: N prediction dicts or None;
    errors: (N, J) mm (NaN where no prediction). unmatched / out_of_scope: counts of predictions."""

    gt_joints: np.ndarray
    pred_joints: np.ndarray
    valid: np.ndarray
    matched: np.ndarray
    support: np.ndarray
    records: list[dict | None]
    unmatched: int
    out_of_scope: int

    @property
    def errors(self) -> np.ndarray:
        return np.linalg.norm(self.pred_joints - self.gt_joints, axis=-1)  # (N, J)


def match_predictions(
    gt: dict,
    predictions: list[dict],
    image_ids: set[str] | None = None,
    days: Iterable[int] | None = None,
) -> Matched:
    """Match ``predictions`` to the ground-truth poses of ``gt`` in scope (arguments as :func:`evaluate`)."""
    check_annotations(gt)
    support = pose_support(gt)
    frame_day = {mv["id"]: image_day(mv["images"][0]) for mv in gt["multiview_images"]}
    days = None if days is None else {int(d) for d in days}

    def in_scope(frame: str) -> bool:
        if image_ids is not None and frame not in image_ids:
            return False
        return days is None or frame_day.get(frame) in days

    preds = defaultdict(list)
    out_of_scope = 0
    for i, pred in enumerate(predictions):
        key, joints = _parse_prediction(pred, i)
        if key[0] in frame_day and not in_scope(key[0]):
            out_of_scope += 1
        else:
            preds[key].append((joints, pred))

    gt_joints, gt_valid, gt_support, pred_joints, records = [], [], [], [], []
    used = defaultdict(int)
    for i, (pose, s) in enumerate(zip(gt["annotations3D"], support, strict=True)):
        if not in_scope(pose["image_ids"]):
            continue
        key = (str(pose["image_ids"]), int(pose["person_id"]))
        joints, valid = pose_joints(pose, i)
        gt_joints.append(joints)
        gt_valid.append(valid)
        gt_support.append(s)
        k = used[key]
        used[key] += 1
        found = preds[key][k] if k < len(preds.get(key, ())) else None
        records.append(None if found is None else found[1])
        pred_joints.append(np.full((NUM_JOINTS, 3), np.nan) if found is None else found[0])
    n = len(gt_joints)
    return Matched(
        np.asarray(gt_joints, np.float64).reshape(n, NUM_JOINTS, 3),
        np.asarray(pred_joints, np.float64).reshape(n, NUM_JOINTS, 3),
        np.asarray(gt_valid, bool).reshape(n, NUM_JOINTS),
        np.asarray([r is not None for r in records], bool),
        np.asarray(gt_support, np.int64),
        records,
        sum(max(0, len(v) - used.get(key, 0)) for key, v in preds.items()),
        out_of_scope,
    )


def evaluate(
    gt: dict,
    predictions: list[dict],
    image_ids: set[str] | None = None,
    days: Iterable[int] | None = None,
) -> dict:
    """Score ``predictions`` against the MVOR-format ground truth ``gt`` (see the module docstring).

    Args:
        gt: the annotation dict (``load_annotations``).
        predictions: ``[{"image_ids", "person_id", "keypoints3D"}]``.
        image_ids: evaluate only these multi-view frames (None: all).
        days: evaluate only the frames of these recording days (None: all).

    Returns:
        ``{"per_joint": {type: cm, "average": cm}, "per_support": {"1": {...}, ...}, "overall": cm,
        "counts": {...}}``. Means over nothing are NaN.
    """
    m = match_predictions(gt, predictions, image_ids, days)
    n, valid, matched, support_arr = len(m.records), m.valid, m.matched, m.support
    unmatched, out_of_scope = m.unmatched, m.out_of_scope
    errors = m.errors  # (N, J) mm, NaN where no prediction
    mask = valid & matched[:, None]  # (N, J)

    per_joint = _type_means(errors, mask, JOINT_TYPES)
    per_joint["average"] = _nanmean(per_joint.values())
    per_support = {}
    for s in sorted(set(support_arr.tolist())):
        rows = support_arr == s
        row = _type_means(errors[rows], mask[rows], SUPPORT_TYPES)
        row["average"] = _nanmean(row.values())
        row["count"] = int((matched & rows).sum())
        row["missing"] = int((~matched & rows).sum())
        per_support[str(s)] = row
    overall = float(errors[mask].mean() / MM_PER_CM) if mask.any() else float("nan")
    return {
        "per_joint": per_joint,
        "per_support": per_support,
        "overall": overall,
        "counts": {
            "poses": n,
            "evaluated_poses": int(matched.sum()),
            "missing": int((~matched).sum()),
            "unmatched_predictions": unmatched,
            "out_of_scope_predictions": out_of_scope,
            "evaluated_joints": int(mask.sum()),
            "unannotated_joints": int((~valid[matched]).sum()),
        },
    }


_COUNT_KEYS = ("count", "missing")


def _reduce_numbers(results: list[dict], reduce) -> dict:
    """Apply ``reduce`` over folds to every number of per_joint/per_support/overall (NaNs skipped)."""

    def combine(values: list):
        if isinstance(values[0], dict):
            keys = dict.fromkeys(
                k for v in values for k in v if k not in _COUNT_KEYS
            )  # union, first-seen order
            return {k: combine([v[k] for v in values if k in v]) for k in keys}
        finite = np.asarray([v for v in values if not math.isnan(v)], np.float64)
        return reduce(finite) if finite.size else float("nan")

    return combine([{k: r[k] for k in ("per_joint", "per_support", "overall")} for r in results])


def evaluate_folds(gt: dict, predictions: list[dict], days: Iterable[int] | None = None) -> dict:
    """Evaluate each recording day on its own (one cross-validation fold each), then mean and std over days.

    Returns ``{"folds": {"<day>": evaluate(...)}, "mean": {...}, "std": {...}, "counts": {...}}``; ``mean``
    and ``std`` have the ``per_joint``/``per_support``/``overall`` layout. ``std`` is the population standard
    deviation over the folds that have a value. Pose counts are summed over the folds (``mean``, ``counts``).
    """
    all_days = sorted({image_day(mv["images"][0]) for mv in gt["multiview_images"]})
    days = all_days if days is None else sorted({int(d) for d in days})
    per_fold = {str(d): evaluate(gt, predictions, days=[d]) for d in days}
    results = list(per_fold.values())
    mean = _reduce_numbers(results, lambda x: float(x.mean()))
    std = _reduce_numbers(results, lambda x: float(x.std()))
    for key, row in mean["per_support"].items():
        for name in _COUNT_KEYS:
            row[name] = sum(r["per_support"].get(key, {}).get(name, 0) for r in results)
    counts = {k: sum(r["counts"][k] for r in results) for k in results[0]["counts"]}
    return {"folds": per_fold, "mean": mean, "std": std, "counts": counts}


def to_json(result):
    """``result`` with NaN (a mean over nothing) written as null, so the file is valid JSON."""
    if isinstance(result, dict):
        return {k: to_json(v) for k, v in result.items()}
    if isinstance(result, float) and math.isnan(result):
        return None
    return result


# --------------------------------------------------------------------- tables
def _cell(value: float, spread: float | None) -> str:
    text = "  -  " if math.isnan(value) else f"{value:5.1f}"
    if spread is not None:
        text += "        " if math.isnan(spread) else f" (±{spread:4.1f})"
    return text


def format_tables(result: dict) -> str:
    """The paper's two tables as text, from :func:`evaluate` or :func:`evaluate_folds` output (mean ± std)."""
    folded = "folds" in result
    numbers, spread = (result["mean"], result["std"]) if folded else (result, None)
    width = 16 if folded else 10
    lines = []
    title = f"MPJPE (cm) per joint type, all {NUM_JOINTS} joints"
    if folded:
        title += f", mean (± std) over {len(result['folds'])} folds (days {', '.join(result['folds'])})"
    lines += [title]
    names = [*JOINT_TYPES, "average"]
    lines.append("".join(f"{n.capitalize():>{width}}" for n in names))
    lines.append(
        "".join(
            f"{_cell(numbers['per_joint'][n], None if spread is None else spread['per_joint'][n]):>{width}}"
            for n in names
        )
    )
    overall = _cell(numbers["overall"], None if spread is None else spread["overall"])
    lines += [f"Overall MPJPE (all annotated joints): {overall.strip()} cm", ""]

    lines.append("MPJPE (cm) per number of supporting views (MVOR convention: no head or neck)")
    names = [*SUPPORT_TYPES, "average"]
    lines.append(
        f"{'Views':>6}" + "".join(f"{n.capitalize():>{width}}" for n in names) + f"{'Poses':>8}{'Missing':>9}"
    )
    for key, row in numbers["per_support"].items():
        srow = None if spread is None else spread["per_support"].get(key, {})
        cells = "".join(
            f"{_cell(row[n], None if srow is None else srow.get(n, math.nan)):>{width}}" for n in names
        )
        lines.append(f"{key:>6}{cells}{row['count']:>8}{row['missing']:>9}")
    c = result["counts"]
    lines += [
        "",
        f"Poses: {c['poses']} ground truth, {c['evaluated_poses']} evaluated, "
        f"{c['missing']} without a prediction; "
        f"{c['unmatched_predictions']} predictions without a ground-truth pose.",
        f"Joints: {c['evaluated_joints']} evaluated, "
        f"{c['unannotated_joints']} unannotated (flag 0) left out.",
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------- CLI
def load_predictions(paths: Iterable[str | Path]) -> list[dict]:
    """Concatenate prediction files (each a JSON list of prediction dicts)."""
    out = []
    for path in paths:
        with open(path) as f:
            preds = json.load(f)
        if not isinstance(preds, list):
            raise ValueError(
                f"prediction file {path}: expected a JSON list of predictions, got {type(preds).__name__}"
            )
        out += preds
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m posenet.evaluation.evaluate",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=(
            'Predictions: a JSON list of {"image_ids": str, "person_id": int, "keypoints3D": [30 floats]}\n'
            "(mm, camera-0 frame, MVOR joint order), matched to the ground truth by\n"
            "(image_ids, person_id). Ground-truth joints with flag 0 and poses without a prediction\n"
            "are left out of the means and reported as counts.\n\n"
            "Tables (cm): MPJPE per joint type over all 10 joints (left and right averaged; Average =\n"
            "mean of the six types; Overall = MPJPE over all annotated joints), and MVOR's per-support\n"
            "table (shoulder, hip, elbow, wrist by the number of views with a box of the person).\n\n"
            "Cross-validation: train one model per held-out day, predict its held-out day, and pass\n"
            "all the prediction files (or one file covering every day) with --folds. Each day is then\n"
            "scored on its own and the tables show the mean (± population std) over the days, as in\n"
            "the paper's last table."
        ),
    )
    add_annotations(parser, required=True, help="MVOR-format ground-truth json (annotations3D)")
    parser.add_argument(
        "--predictions",
        required=True,
        action="append",
        help="prediction json list; repeat to concatenate files (e.g. one per fold)",
    )
    parser.add_argument("--json", help="also write the numbers to this file (machine-readable)")
    add_days(parser, help="evaluate only these recording days (default: all days)")
    parser.add_argument(
        "--folds", action="store_true", help="score each day as one fold; report mean and std over the days"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    gt = load_annotations(args.annotations)
    predictions = load_predictions(args.predictions)
    if args.folds:
        result = evaluate_folds(gt, predictions, days=args.days)
    else:
        result = evaluate(gt, predictions, days=args.days)
    print(format_tables(result))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(to_json(result), f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
