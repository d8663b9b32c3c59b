"""How well boxes are grouped into persons across views, as in the paper's evaluation of its matcher.

    python -m pipeline.association --data DIR --annotations A.json [--predictions BOXES.json] [--days 4]
        [--matcher centres|skeletons] [--pose-checkpoint CKPT]
    python -m pipeline.association ... --matcher skeletons --skeleton-mm 300 400 500 --same-view-mm 150 250
        # a sweep of the skeleton matcher's thresholds: one table row per combination, the network run once

Without ``--predictions`` the matcher groups the reference boxes; with it, the detected boxes (score at least
``--score-threshold``). ``--matcher centres`` is the paper's 3D box-centre matcher (``pipeline.matching``);
``--matcher skeletons`` groups boxes by the single-view skeletons of the pose network (the shipped weights, or
``--pose-checkpoint``; ``pipeline.skeleton_matching``), and needs the colour images when that network reads them. For every annotated person (``person_id >= 0``) in every frame:
- the paper's score: match persons to groups by IoU averaged over the V views (IoU 0 where the person or the
  group has no box), one to one (Hungarian); ``mean_iou`` averages the matched scores over persons.
- counts: in each view, detected boxes are paired with annotated boxes (Hungarian, IoU >= 0.5). A person is
  **missed** when none of its boxes is detected, **split** when its detected boxes lie in two or more groups,
  **merged** when its group also holds another person's box, and **found** otherwise (``complete`` when that
  group also has a box in every view where the person has one). missed + split + merged + found = persons.
  Groups none of whose boxes pairs with an annotated box are **nobody**'s: false persons (or someone the file
  does not annotate).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.optimize import linear_sum_assignment
from tqdm import tqdm

from pipeline.matching import Group, match_boxes
from pipeline.skeleton_matching import (
    CANDIDATE_SCORE,
    MATCHERS,
    SkeletonMatchConfig,
    match_heatmaps,
    split_unsure,
)
from posenet.boxes import PersonBoxes, boxes_of_person, coco_to_xyxy, iou_xyxy, match_persons, person_ids
from posenet.cli import add_annotations, add_data, add_days, add_threads, annotations_path, set_threads

# As pipeline.two_stage.PipelineConfig.max_match_combinations: frames beyond it are refused, not enumerated.
PAIRS_LIMIT = 300_000
COUNTS = ("persons", "found", "complete", "missed", "split", "merged", "groups", "nobody")


def frame_association(
    gt_boxes: list[np.ndarray],
    gt_ids: list[np.ndarray],
    pred_boxes: list[np.ndarray],
    groups: list[Group],
    iou_threshold: float = 0.5,
) -> dict:
    """Counts and the paper's IoU score of one frame.

    Args:
        gt_boxes: per view, ``(G_v, 4)`` annotated boxes (xyxy); gt_ids: per view ``(G_v,)`` person ids
            (-1: a box without identity, which may absorb a detection but is not a person).
        pred_boxes: per view, ``(K_v, 4)`` boxes that were grouped; groups: the matcher's groups.
    """
    V = len(gt_boxes)
    persons = person_ids(gt_ids)
    # Which group holds each predicted box: owner[v][k] (-1: an unsure box that completed nobody, not a person).
    owner = [np.full(len(b), -1) for b in pred_boxes]
    for gi, g in enumerate(groups):
        for v, k in [*enumerate(g.indices), *g.extra]:
            if k >= 0:
                owner[v][k] = gi
    # Per view, pair detections with annotated boxes; record the group of each person's detected boxes.
    person_groups: dict[int, set] = defaultdict(set)
    group_persons: dict[int, set] = defaultdict(set)
    annotated = set()  # groups with a box paired to an annotated box (of a person or not)
    for v in range(V):
        if len(gt_boxes[v]) == 0 or len(pred_boxes[v]) == 0:
            continue
        iou = iou_xyxy(gt_boxes[v], pred_boxes[v]) * (owner[v] >= 0)  # (G_v, K_v)
        rows, cols = linear_sum_assignment(-iou)
        for r, c in zip(rows, cols, strict=True):
            pid = int(gt_ids[v][r])
            if iou[r, c] < iou_threshold:
                continue
            annotated.add(int(owner[v][c]))
            if pid >= 0:
                person_groups[pid].add(int(owner[v][c]))
                group_persons[int(owner[v][c])].add(pid)
    out = dict.fromkeys(COUNTS, 0)
    out["persons"], out["groups"] = len(persons), len(groups)
    out["nobody"] = len(groups) - len(annotated)
    for p in persons:
        gs = person_groups.get(p, set())
        if not gs:
            out["missed"] += 1
        elif len(gs) > 1:
            out["split"] += 1
        elif len(group_persons[next(iter(gs))]) > 1:
            out["merged"] += 1
        else:
            out["found"] += 1
            g = groups[next(iter(gs))]
            views = [v for v in range(V) if p in set(gt_ids[v].tolist())]
            out["complete"] += all(g.indices[v] >= 0 for v in views)
    out["iou_sum"] = _paper_score(gt_boxes, gt_ids, pred_boxes, groups, persons)
    return out


def _paper_score(gt_boxes, gt_ids, pred_boxes, groups, persons) -> float:
    """Sum over persons of the IoU, averaged over all V views, of the group matched to each (Hungarian)."""
    if not persons or not groups:
        return 0.0
    V = len(gt_boxes)
    gt = [boxes_of_person(gt_boxes, gt_ids, p) for p in persons]
    found = [[None if k < 0 else pred_boxes[v][k] for v, k in enumerate(g.indices)] for g in groups]
    _, _, scores = match_persons(PersonBoxes.from_lists(gt, V), PersonBoxes.from_lists(found, V))
    return float(scores.sum())


def results_by_image(
    predictions: list[dict], score_threshold: float
) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """COCO results to ``{image_id: ((K, 4) xyxy, (K,) scores)}`` keeping scores >= ``score_threshold``."""
    out: dict[int, list] = defaultdict(list)
    for p in predictions:
        if p.get("score", 1.0) >= score_threshold:
            out[int(p["image_id"])].append([*p["bbox"], p.get("score", 1.0)])
    return {
        k: (coco_to_xyxy(np.asarray(v, np.float64)[:, :4]), np.asarray(v, np.float64)[:, 4])
        for k, v in out.items()
    }


def evaluate_association(
    samples,
    predictions: list[dict] | None = None,
    score_threshold: float = 0.5,
    threshold_mm: float = 750.0,
    progress: bool = True,
    matcher: str = "centres",
    pose=None,
    skeleton_configs: list[SkeletonMatchConfig] | None = None,
    candidate_score: float | None = None,
) -> dict | list[dict]:
    """Association metrics over ``samples`` (``Sample``s with depth); see the module docstring.

    ``predictions`` None groups the reference boxes; else the COCO results' boxes of each view. ``matcher``
    "skeletons" groups them with ``pose`` (a ``posenet.net.infer.PoseEstimator``) instead of the box centres, with
    the default :class:`SkeletonMatchConfig`; given ``skeleton_configs``, with each of them from the same
    heatmaps (the pose network runs once per frame), and the result is one metrics dict per config.
    ``candidate_score`` (skeleton matcher, detected boxes): boxes scored from it up to ``score_threshold`` may
    complete persons, as in the service (``pipeline.two_stage.PipelineConfig.candidate_score``).
    """
    if matcher not in MATCHERS:
        raise ValueError(f"matcher must be one of {MATCHERS}, got {matcher!r}")
    if matcher == "skeletons" and pose is None:
        raise ValueError("the skeleton matcher needs the pose network: pass pose=PoseEstimator(...)")
    configs = skeleton_configs or [SkeletonMatchConfig()]
    if skeleton_configs and matcher != "skeletons":
        raise ValueError("skeleton_configs are thresholds of the skeleton matcher: pass matcher='skeletons'")
    unsure = matcher == "skeletons" and candidate_score is not None and candidate_score < score_threshold
    lowest = candidate_score if unsure else score_threshold
    detected = None if predictions is None else results_by_image(predictions, lowest)
    runs = len(configs) if matcher == "skeletons" else 1
    totals = [{**dict.fromkeys(COUNTS, 0), "iou_sum": 0.0} for _ in range(runs)]
    for sample in tqdm(samples, desc="associate", unit="frame", disable=not progress):
        gt_boxes = [np.asarray(v.boxes, np.float64).reshape(-1, 4) for v in sample.views]
        gt_ids = [np.asarray(v.box_person_ids) for v in sample.views]
        candidate = None
        if detected is None:
            pred = gt_boxes
        else:
            found = [detected.get(int(v.image_id), (np.zeros((0, 4)), np.zeros(0))) for v in sample.views]
            pred = [b for b, _ in found]
            if unsure:
                pred, _, candidate = split_unsure(pred, [s for _, s in found], score_threshold)
        depths = []
        for v in sample.views:
            if v.depth is None:
                raise ValueError(f"frame {sample.id} has no depth image: load the dataset with depth")
            depths.append(v.depth)
        if matcher == "skeletons":
            views = sample.views
            heat = pose.box_heatmaps(views, pred)
            groupings = [
                match_heatmaps(
                    heat,
                    views,
                    pred,
                    c,
                    max_combinations=PAIRS_LIMIT,
                    candidate=candidate,
                    detected=detected is not None,
                )  # fmt: skip
                for c in configs
            ]
        else:
            groupings = [match_boxes(pred, depths, sample.cameras, threshold_mm)]
        for total, groups in zip(totals, groupings, strict=True):
            for k, val in frame_association(gt_boxes, gt_ids, pred, groups).items():
                total[k] += val
    for total in totals:
        n = max(total["persons"], 1)
        total["mean_iou"] = round(total.pop("iou_sum") / n, 4)
        for k in ("found", "complete", "missed", "split", "merged"):
            total[f"{k}_rate"] = round(total[k] / n, 4)
    return totals if skeleton_configs else totals[0]


def _mm_or_none(text: str) -> float | None:
    """A command-line millimetre value, or 'none'."""
    return None if text.lower() == "none" else float(text)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(
        prog="python -m pipeline.association",
        description="Group boxes across views with the 3D matcher and count persons found, split and merged.",
    )
    add_data(parser)
    add_annotations(parser)
    parser.add_argument(
        "--predictions", help="COCO results of detector.predict (default: the reference boxes)"
    )
    add_days(parser)
    parser.add_argument("--score-threshold", type=float, default=0.5, help="lowest detection score used")
    parser.add_argument("--threshold-mm", type=float, default=750.0, help="the matcher's t (paper: 75 cm)")
    parser.add_argument(
        "--candidate-score", type=_mm_or_none, default=CANDIDATE_SCORE,
        help="skeleton matcher: detected boxes scored from this up to --score-threshold may complete a person "
        f"seen in other views, as in the service (default {CANDIDATE_SCORE}; 'none': sure boxes only)",
    )  # fmt: skip
    parser.add_argument(
        "--matcher", choices=MATCHERS, default="centres",
        help="centres: the paper's 3D box centres; skeletons: each box's single-view skeleton (pose network)",
    )  # fmt: skip
    parser.add_argument("--pose-checkpoint", help="the skeleton matcher's pose weights (default: shipped)")
    add_threads(parser, help="torch threads for the skeleton matcher's pose network")
    sweep = parser.add_argument_group(
        "skeleton matcher thresholds (several values: every combination is scored from the same heatmaps)"
    )
    default = SkeletonMatchConfig()
    sweep.add_argument(
        "--skeleton-mm",
        type=float,
        nargs="+",
        default=[default.threshold_mm],
        help="across views: single-view skeletons within this median joint distance",
    )
    sweep.add_argument(
        "--same-view-mm",
        type=float,
        nargs="+",
        default=[default.same_view_mm],
        help="within a view: boxes whose skeletons lie this close are one person",
    )
    sweep.add_argument("--centre-gate-mm", type=float, nargs="+", default=[default.centre_gate_mm],
                       help="box centres farther apart than this never match")  # fmt: skip
    mm_or_none = (  # flag, field, help: 'none' switches each off
        ("--member-bonus-mm", "member_bonus_mm", "'none': the paper's order (more views first); a number: all "
         "combinations by mean distance minus this per view beyond the first"),
        ("--link-reward-mm", "link_reward_mm", "'none': the greedy rule; a number: one optimal partition per "
         "frame, each pair of grouped boxes earning this much against its skeleton distance "
         "(pipeline.matching.choose_optimally)"),
        ("--candidate-mm", "candidate_mm", "an unsure box joins a person whose fused skeleton lies within this "
         "('none': never)"),
        ("--outlier-mm", "outlier_mm", "a detected box this far from the rest of its person (>= 3 boxes) "
         "leaves it ('none': never)"),
        ("--free-space-mm", "free_space_mm", "a detected person of one view is dropped when another view sees "
         "its joints in free space (depth at most this in front), with no box there ('none': never)"),
    )  # fmt: skip
    for flag, name, text in mm_or_none:
        sweep.add_argument(flag, nargs="+", default=[getattr(default, name)], type=_mm_or_none, help=text)
    parser.add_argument("--out", help="also write the metrics to this json file")
    args = parser.parse_args(argv)

    from posenet.data.mvor import MvorDataset

    pose, modalities = None, ("depth",)
    if args.matcher == "skeletons":

        from posenet.net.infer import PoseEstimator

        set_threads(args.threads)
        pose = PoseEstimator.from_checkpoint(args.pose_checkpoint, threads=args.threads)
        if pose.model.config.inputs.modality != "depth":
            modalities = ("color", "depth")
    samples = MvorDataset(args.data, annotations_path(args), subsample=1, modalities=modalities, days=args.days)
    predictions = None
    if args.predictions:
        predictions = json.loads(Path(args.predictions).read_text())
    configs = [
        SkeletonMatchConfig(
            threshold_mm=t,
            centre_gate_mm=g,
            same_view_mm=s,
            member_bonus_mm=b,
            link_reward_mm=r,
            candidate_mm=c,
            outlier_mm=o,
            free_space_mm=f,
        )  # fmt: skip
        for t in args.skeleton_mm
        for f in args.free_space_mm
        for c in args.candidate_mm
        for o in args.outlier_mm
        for s in args.same_view_mm
        for g in args.centre_gate_mm
        for b, r in dict.fromkeys(  # a member bonus orders the greedy rule: it goes without a link reward
            (b, None if b is not None else r) for b in args.member_bonus_mm for r in args.link_reward_mm
        )
    ]
    sweeping = args.matcher == "skeletons" and len(configs) > 1
    if len(configs) > 1 and not sweeping:
        parser.error("several thresholds are a sweep of the skeleton matcher: add --matcher skeletons")
    metrics = evaluate_association(
        samples, predictions, args.score_threshold, args.threshold_mm, matcher=args.matcher, pose=pose,
        skeleton_configs=configs if sweeping else None, candidate_score=args.candidate_score,
    )  # fmt: skip
    boxes = "detected" if predictions is not None else "reference"
    if sweeping:
        print(
            "| across views, mm | same view, mm | centre gate, mm | member bonus, mm | link reward, mm | unsure, mm "
            "| outlier, mm | free space, mm | found | split | merged | missed | nobody | mean IoU |"
        )
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for c, m in zip(configs, metrics, strict=True):
            m.update(boxes=boxes, matcher=args.matcher, config=dataclasses.asdict(c))
            switches = " | ".join("none" if x is None else f"{x:g}"
                                  for x in (getattr(c, name) for _, name, _ in mm_or_none))  # fmt: skip
            print(f"| {c.threshold_mm:g} | {c.same_view_mm:g} | {c.centre_gate_mm:g} | {switches} | "
                  f"{m['found_rate']:.3f} | {m['split_rate']:.3f} | {m['merged_rate']:.3f} | "
                  f"{m['missed_rate']:.3f} | {m['nobody']} | {m['mean_iou']:.3f} |")  # fmt: skip
    else:
        metrics["boxes"] = boxes
        metrics["matcher"] = args.matcher
        if args.matcher == "skeletons":
            metrics["config"] = dataclasses.asdict(configs[0])
        print(json.dumps(metrics, indent=2))
    if args.out:
        Path(args.out).write_text(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    main()
