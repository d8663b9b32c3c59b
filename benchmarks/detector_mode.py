"""Detector mode against reference boxes, matcher variants side by side: MPJPE per support and the cost per stage.

    python benchmarks/detector_mode.py --data data/mvor_twin --days 4
    python benchmarks/detector_mode.py --data data/mvor_alt --days 4 --json runs/detector_mode_alt.json
    python benchmarks/detector_mode.py --data data/mvor_twin --days 4 --pose-checkpoint OLD.safetensors  # other weights

Runs the service's pipeline (``pipeline.two_stage.ScenePipeline``, the shipped weights, the service's default
backend) offline on every frame of ``--days``: once with the reference boxes and their ids (the paper's
setting), and in detector mode once per variant of the skeleton matcher:

- ``sure``: only boxes at or above the detector's threshold, every box kept in its person (before 2026-12-03);
- ``+unsure``: boxes scored from ``PipelineConfig.candidate_score`` up may complete a person seen in other
  views (``pipeline.skeleton_matching``, step 5);
- ``+unsure+outliers``: and a box far from the rest of its person leaves it (step 6);
- ``+unsure+outliers+unseen`` (the default): and a person of one view that another view sees in free space,
  without a box there, is dropped (step 7).

The detector runs once per frame (at the lowest score any variant reads); the variants then run one after
another on the same frame, so that a loaded machine slows them alike. Prints per variant the MVOR per-support
average (shoulders, hips, elbows, wrists) at 1 / 2 / 3 views and the overall MPJPE (10 joints, cm;
``posenet.evaluation.evaluate``), the ratio to the reference boxes, the annotated poses that no returned person was
matched to (``missed``; persons are matched by ``posenet.boxes.ground_truth_ids``, the paper's mean IoU over the
views, with MVOR's box-only people competing), the persons returned that are no annotated person (``nobody``:
false persons, or persons MVOR boxed without a pose, such as the patient), and the median / p95
milliseconds of the matcher
(``match``: lifting each box alone, grouping, fusing) and of the U-Net (``pose``).

``--single-view`` also scores each reference box's single-view skeleton (the box lifted alone: what the
skeleton matcher compares across views) against its person's annotated pose.

``--worst N`` also lists, per number of supporting views, the N poses that the last variant (the default unless
``--variants`` says otherwise) answers worst against reference boxes (each pose's mean over the per-support
joints) and their share of the excess: on the twin's day 4 (2026-12-05) one frame of five clinicians in a
cluster holds most of the three-view excess.

``--picture PNG`` also draws the frame where the default took the most unsure boxes (``--picture-frame ID``: that
frame instead, its multi-view id or a unique part of it): every detected box of each view, coloured by the person
it ended in (solid: sure, dashed: unsure and taken), unsure boxes that completed nobody dotted grey, sure boxes in
no person (dropped as outliers, or by the free-space rule) in red, and the annotated boxes thin and white with
their person id ("-": box-only).
"""

from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from pipeline.skeleton_matching import CANDIDATE_SCORE, SkeletonMatchConfig, _lifted
from pipeline.two_stage import PipelineConfig, ScenePipeline
from posenet.boxes import ground_truth_ids
from posenet.data.mvor import image_day, load_annotations
from posenet.evaluation.evaluate import MM_PER_CM, evaluate, match_predictions, prediction_record
from posenet.evaluation.predict import read_dataset
from posenet.runtime.execution import machine_line
from posenet.skeleton import JOINT_TYPES, SUPPORT_TYPES

VARIANTS = {  # name: (candidate_score, the outlier rule at its default, the free-space rule at its default)
    "sure": (None, False, False),
    "+unsure": (CANDIDATE_SCORE, False, False),
    "+unsure+outliers": (CANDIDATE_SCORE, True, False),
    "+unsure+outliers+unseen": (CANDIDATE_SCORE, True, True),
}


class FrameDetections:
    """The detector's boxes of one frame at the lowest score asked for, handed out at any higher score."""

    def __init__(self, detector, views, lowest: float):
        self.detector = detector
        self.backend = detector.backend
        self.found = detector.detect([v.color for v in views], depths=[v.depth for v in views],
                                     score_threshold=lowest)  # fmt: skip

    # the rest of detector.protocol.Detector, as the real detector answers it
    score_threshold = property(lambda self: self.detector.score_threshold)
    input_width = property(lambda self: self.detector.input_width)
    needs_depth = property(lambda self: self.detector.needs_depth)
    precision = property(lambda self: self.detector.precision)

    def detect(self, images, depths=None, score_threshold=None):
        from detector.protocol import Detections

        keep = self.score_threshold if score_threshold is None else score_threshold
        return [Detections(d.boxes[d.scores >= keep], d.scores[d.scores >= keep]) for d in self.found]


def _used_unsure(pipe: ScenePipeline, views, result) -> int:
    """How many unsure boxes the persons of ``result`` hold (``pipe._detect`` gives the same boxes again)."""
    _, _, candidate = pipe._detect(views)
    if candidate is None:
        return 0
    return sum(
        bool(candidate[v][k]) for p in result.persons for v, ks in enumerate(p.box_indices) for k in ks
    )


def single_view_errors(pipe: ScenePipeline, sample, views) -> np.ndarray:
    """``(B, 2)`` mm for each annotated reference box of ``sample``: the mean and the median over the annotated
    joints the box lifts (finite, with depth points) of the distance between that box's single-view skeleton (the box lifted alone, what the skeleton
    matcher compares across views, ``BoxHeatmaps.single_view``) and the person's annotated pose."""
    boxes = [np.asarray(v.boxes, np.float32).reshape(-1, 4) for v in sample.views]
    joints, usable = _lifted(pipe.pose.box_heatmaps(views, boxes).single_view())  # as the matcher reads them
    row = {int(pid): n for n, pid in enumerate(sample.person_ids)}
    ids = np.concatenate([np.asarray(v.box_person_ids, int).reshape(-1) for v in sample.views])
    out = []
    for k, pid in enumerate(ids):
        n = row.get(int(pid))
        if n is None or not (ok := sample.valid[n] & usable[k]).any():
            continue
        d = np.linalg.norm(joints[k] - sample.poses[n], axis=-1)[ok]
        out.append((d.mean(), np.median(d)))
    return np.asarray(out, float).reshape(-1, 2)


def draw_frame(pipe: ScenePipeline, sample, out: Path) -> None:
    """The frame's views with every detected box, coloured by the person it ended in (module docstring)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    colours = (
        "tab:orange",
        "tab:blue",
        "tab:green",
        "tab:purple",
        "tab:brown",
        "tab:pink",
        "tab:olive",
        "tab:cyan",
    )
    views = sample.views
    boxes, _, candidate = pipe._detect(views)
    candidate = candidate or [np.zeros(len(b), bool) for b in boxes]
    result = pipe.run(views)
    owner = {(v, k): p for p, person in enumerate(result.persons) for v, ks in enumerate(person.box_indices)
             for k in ks}  # fmt: skip
    fig, axes = plt.subplots(1, len(views), figsize=(4.2 * len(views), 3.4))
    for v, (ax, view) in enumerate(zip(np.atleast_1d(axes), views, strict=True)):
        ax.imshow(view.color)
        ax.set_axis_off()
        ax.set_title(f"view {v + 1}", fontsize=9)
        for k, (x0, y0, x1, y1) in enumerate(boxes[v]):
            p, unsure = owner.get((v, k)), bool(candidate[v][k])
            if p is not None:
                style = {"edgecolor": colours[p % len(colours)], "linestyle": "--" if unsure else "-",
                         "linewidth": 2.2}  # fmt: skip
            elif unsure:
                style = {"edgecolor": "0.6", "linestyle": ":", "linewidth": 1.2}
            else:
                style = {"edgecolor": "red", "linestyle": "-", "linewidth": 2.2}
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, **style))
        truth = sample.views[v]
        for (x0, y0, x1, y1), pid in zip(
            np.asarray(truth.boxes).reshape(-1, 4), truth.box_person_ids, strict=True
        ):
            ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, edgecolor="white", linewidth=0.8))
            ax.text(x0 + 2, y1 - 3, str(pid) if pid >= 0 else "-", color="white", fontsize=7, va="bottom")
    fig.suptitle(f"{sample.id}: solid = sure box, dashed = unsure box that completed its person, dotted grey = "
                 "unsure box left out,\nred = sure box in no person (an outlier, or nobody by free space); colour = "
                 "person; thin white = annotated box and its id", fontsize=8)  # fmt: skip
    fig.tight_layout()
    fig.savefig(out, dpi=72)
    plt.close(fig)
    from PIL import Image

    Image.open(out).convert("RGB").quantize(colors=256).save(out, optimize=True)  # a third of the bytes


def worst_poses(gt: dict, reference: list[dict], detected: list[dict], days, n: int) -> dict:
    """Per number of supporting views, where detector mode loses against reference boxes: each annotated pose's
    mean error over the per-support joints (shoulders, hips, elbows, wrists; cm) with either boxes, the share of
    the excess held by the ``n`` poses that lose most, and those poses (frame, person, reference, detected)."""
    ref, det = (match_predictions(gt, p, days=days) for p in (reference, detected))
    types = [j for t in SUPPORT_TYPES for j in JOINT_TYPES[t]]

    def per_pose(m):
        e = np.where(m.valid & m.matched[:, None], m.errors, np.nan)[:, types]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a pose without any of those joints
            return np.nanmean(e, axis=1) / MM_PER_CM

    er, ed = per_pose(ref), per_pose(det)
    out = {}
    for s in sorted(set(ref.support.tolist())):
        rows = np.flatnonzero((ref.support == s) & np.isfinite(er) & np.isfinite(ed))
        excess = ed[rows] - er[rows]
        order = rows[np.argsort(-excess)][:n]
        total = float(excess.sum())
        out[str(s)] = {
            "poses": len(rows), "excess_cm": total,
            "share_of_worst": float((ed[order] - er[order]).sum() / total) if total > 0 else float("nan"),
            "worst": [{"frame": ref.records[i]["image_ids"], "person_id": ref.records[i]["person_id"],
                       "reference_cm": float(er[i]), "detected_cm": float(ed[i])} for i in order],
        }  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--data", type=Path, default=Path("data/mvor_twin"), help="MVOR-format dataset")
    p.add_argument("--annotations", type=Path, help="its annotations (default: DATA/annotations.json)")
    p.add_argument("--days", type=int, nargs="+", help="recording days (default: all)")
    p.add_argument("--threads", type=int, default=2, help="runtime threads")
    p.add_argument("--pose-checkpoint", type=Path,
                   help="pose weights (NAME.safetensors with NAME.json, or a run folder; default: the shipped ones)")  # fmt: skip
    p.add_argument("--flip-test", action=argparse.BooleanOptionalAction, default=None,
                   help="average the pose network with the mirrored inputs (default: the checkpoint's setting)")  # fmt: skip
    p.add_argument("--detector-checkpoint", type=Path, help="detector weights (default: the shipped ones)")
    p.add_argument("--variants", nargs="+", choices=list(VARIANTS), default=list(VARIANTS))
    p.add_argument("--json", type=Path, help="also write the results here")
    p.add_argument("--predictions", type=Path,
                   help="also write each variant's poses here (DIR/NAME.json, posenet.evaluation.evaluate's input)")  # fmt: skip
    p.add_argument(
        "--picture", type=Path, help="draw the frame where the default took most unsure boxes (PNG)"
    )
    p.add_argument("--picture-frame", metavar="ID",
                   help="with --picture: draw this frame instead (its multi-view id, or a unique part of it)")  # fmt: skip
    p.add_argument("--worst", type=int, default=0, metavar="N",
                   help="also list, per number of supporting views, the N poses that the last of --variants (the "
                   "served default unless chosen) answers worst against reference boxes, and their share of its excess")  # fmt: skip
    p.add_argument("--single-view", action="store_true",
                   help="also score each reference box's single-view skeleton (the box lifted alone, what the "
                   "skeleton matcher compares): mean error, and the median / 90th percentile of its median joint")  # fmt: skip
    args = p.parse_args(argv)
    gt = load_annotations(args.annotations or args.data / "annotations.json")
    days = args.days or sorted({image_day(mv["images"][0]) for mv in gt["multiview_images"]})
    pipe = ScenePipeline.from_checkpoints(
        args.pose_checkpoint, args.detector_checkpoint, backend="auto", threads=args.threads,
        flip_test=args.flip_test,
    )  # fmt: skip
    # The views as the service decodes them (at the networks' read size, tests/pipeline/test_parity.py): the detector then
    # sees the pixels it sees when served, and the figures are the served ones.
    ds = read_dataset(args.data, gt, pipe.read_size, days)
    best = (-1, None)  # (unsure boxes taken, frame index) for --picture; a named frame: (None, its index)
    if args.picture_frame:
        hits = [i for i, name in enumerate(ds.ids) if args.picture_frame in name]
        if len(hits) != 1:
            p.error(
                f"--picture-frame {args.picture_frame!r} names {len(hits)} frames of {args.data} days {days}"
            )
        best = (None, hits[0])
    default = SkeletonMatchConfig()
    lowest = min([pipe.detector.score_threshold] + [v[0] for v in VARIANTS.values() if v[0] is not None])
    pipes = {}
    for name in args.variants:
        candidate, outlier, unseen = VARIANTS[name]
        match = SkeletonMatchConfig(outlier_mm=default.outlier_mm if outlier else None,
                                    free_space_mm=default.free_space_mm if unseen else None)  # fmt: skip
        config = replace(PipelineConfig(), candidate_score=candidate, skeleton_match=match)
        pipes[name] = ScenePipeline(pipe.pose, pipe.detector, config)
    preds = {"reference": [], **{n: [] for n in pipes}}
    times = {n: {"match": [], "pose": []} for n in pipes}
    nobody = dict.fromkeys(pipes, 0)
    alone = []  # --single-view: (B, 2) mm per frame
    for i in tqdm(range(len(ds)), desc="frames", unit="frame"):
        sample = ds[i]
        views = sample.views
        preds["reference"] += pipe.run_sample(sample, reference_boxes=True)[1]
        if args.single_view:
            alone.append(single_view_errors(pipe, sample, views))
        frame = FrameDetections(pipe.detector, views, lowest)
        for name, variant in pipes.items():
            variant.detector = frame
            result = variant.run(views)
            ids = ground_truth_ids(sample, result.boxes)
            preds[name] += [prediction_record(sample.id, pid, q.joints, q.spread_mm, q.confidence)
                            for q, pid in zip(result.persons, ids, strict=True) if pid is not None]  # fmt: skip
            nobody[name] += sum(pid is None for pid in ids)
            for k in ("match", "pose"):
                times[name][k].append(result.timings[k])
            if name == args.variants[-1] and args.picture and best[0] is not None:
                taken = _used_unsure(variant, views, result)
                if taken > best[0]:
                    best = (taken, i)
    if args.predictions:
        args.predictions.mkdir(parents=True, exist_ok=True)
        for name, pr in preds.items():
            (args.predictions / f"{name.strip('+').replace('+', '_')}.json").write_text(json.dumps(pr))
    rows = {}
    for name, pr in preds.items():
        r = evaluate(gt, pr, days=days)
        rows[name] = {
            "support": {k: v.get("average") for k, v in r["per_support"].items()},
            "poses": {k: v.get("count") for k, v in r["per_support"].items()},
            "missing": {k: v.get("missing") for k, v in r["per_support"].items()},
            "overall": r["overall"],
        }
        if name in times:
            rows[name]["nobody"] = nobody[name]
            rows[name]["ms"] = {
                k: [float(np.median(v)), float(np.percentile(v, 95))] for k, v in times[name].items()
            }
    ref = rows["reference"]["support"]
    print(f"{args.data} days {days}; {machine_line()}")
    print("| boxes | 1 view | 2 views | 3 views | overall | ratio to reference (1 / 2 / 3) | missed (1 / 2 / 3) | "
          "nobody | match ms (median / p95) | pose ms |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, row in rows.items():
        sup = [row["support"].get(k) for k in ("1", "2", "3")]
        cells = " | ".join("-" if v is None else f"{v:.2f}" for v in sup)
        ratio = " / ".join("-" if v is None or ref.get(k) is None else f"{v / ref[k]:.2f}"
                           for v, k in zip(sup, ("1", "2", "3"), strict=True))  # fmt: skip
        ms = row.get("ms")
        timing = (
            ""
            if ms is None
            else f"{ms['match'][0]:.1f} / {ms['match'][1]:.1f} | {ms['pose'][0]:.1f} / {ms['pose'][1]:.1f}"
        )
        missed = " / ".join(str(row["missing"].get(k, 0) or 0) for k in ("1", "2", "3"))
        print(
            f"| {name} | {cells} | {row['overall']:.2f} | {ratio if name != 'reference' else ''} | {missed} | "
            f"{row.get('nobody', '')} | {timing or ' | '} |"
        )
    if alone:
        err = np.concatenate(alone) / 10
        rows["reference"]["single_view_cm"] = {
            "boxes": len(err), "mean": float(err[:, 0].mean()), "median_joint_median": float(np.median(err[:, 1])),
            "median_joint_p90": float(np.percentile(err[:, 1], 90)),
        }  # fmt: skip
        sv = rows["reference"]["single_view_cm"]
        print(f"single-view skeletons of {sv['boxes']} reference boxes: mean {sv['mean']:.2f} cm; median joint: "
              f"median {sv['median_joint_median']:.2f}, 90th percentile {sv['median_joint_p90']:.2f} cm")  # fmt: skip
    if args.worst:
        last = args.variants[-1]
        found = worst_poses(gt, preds["reference"], preds[last], days, args.worst)
        rows[last]["worst"] = found
        for s, w in found.items():
            share = w["share_of_worst"]
            held = f"{100 * share:.0f} % of the excess" if np.isfinite(share) else "no excess (none in all)"
            print(
                f"{last}, {s} view(s): the {len(w['worst'])} poses that lose most hold {held} "
                f"({w['excess_cm']:.1f} cm over {w['poses']} poses)"
            )
            for q in w["worst"]:
                print(
                    f"    {q['frame']} person {q['person_id']}: {q['reference_cm']:.1f} -> {q['detected_cm']:.1f} cm"
                )
    if args.picture and best[1] is not None:
        variant = pipes[args.variants[-1]]
        sample = ds[best[1]]
        variant.detector = FrameDetections(pipe.detector, sample.views, lowest)
        draw_frame(variant, sample, args.picture)
        taken = "" if best[0] is None else f" ({best[0]} unsure boxes taken)"
        print(f"picture of frame {sample.id}{taken}: {args.picture}")
    out = {"data": str(args.data), "days": days, "machine": machine_line(), "rows": rows,
           "pose_checkpoint": str(args.pose_checkpoint or "shipped"), "flip_test": pipe.pose.model.config.flip_test}  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
