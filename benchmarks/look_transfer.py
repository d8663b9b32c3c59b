"""Look transfer: train on one look, test on the same look and on another, same poses and rig (issue 12).

    python benchmarks/look_transfer.py --data data/mvor_twin --cross data/mvor_alt --minutes 10 --threads 2 \
        --out runs/look_transfer

For each modality (``--modalities``, default rgb, depth and rgbd) one ``python -m posenet.training.train --modality M
--minutes N --clock cpu`` run on ``--data``'s days other than ``--holdout-day``, validated on that day (in-look)
and watching the same day of ``--cross`` (cross-look, never trained on: ``posenet.training.train --watch``). Both figures
are the overall MPJPE with reference boxes at the end of the budget, from the run's log; the ratio is cross / in.
The detector is not retrained per look (80 CPU-minutes each): ``--detector`` (default: the shipped weights) is
scored with pycocotools on the held-out day of both looks, AP50 and AP, with their ratio.

The runs are ``benchmarks/train_curve.py``'s, so an interrupted benchmark resumes them. Prints one table, writes
``OUT/look_transfer.json`` with the machine.
"""

from __future__ import annotations

import argparse
import json
import shlex
import time
from pathlib import Path

from train_curve import run


def pose_rows(args) -> list[dict]:
    """In-look and cross-look MPJPE of one run per modality."""
    rows = []
    for modality in args.modalities:
        extra = [
            "--modality",
            modality,
            "--watch",
            f"{args.cross}:{args.holdout_day}",
            *shlex.split(args.train_args),
        ]
        log = run(modality, extra, args)
        last = [r for r in log if "val_mpjpe_cm" in r][-1]
        cross = next(v for k, v in last.items() if k.startswith("watch_") and k.endswith("_cm"))
        rows.append({"model": f"pose network, {modality}", "metric": "MPJPE cm", "in_look": last["val_mpjpe_cm"],
                     "cross_look": cross, "ratio": cross / last["val_mpjpe_cm"], "minutes": last["minutes"]})  # fmt: skip
    return rows


def detector_rows(args) -> list[dict]:
    """AP50 and AP of one detector on the held-out day of both looks."""
    from detector_sets import score_sets

    from detector.infer import PersonDetector

    detector = {"detector": PersonDetector.from_checkpoint(args.detector)}
    scores = {
        look: next(iter(score_sets(detector, [(root, [args.holdout_day])]).values()))["detector"]
        for look, root in (("in", args.data), ("cross", args.cross))
    }
    return [
        {"model": f"detector ({args.detector or 'shipped'})", "metric": metric, "in_look": scores["in"][metric],
         "cross_look": scores["cross"][metric], "ratio": scores["cross"][metric] / scores["in"][metric]}
        for metric in ("AP50", "AP")
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--data", type=Path, required=True, help="the look trained on (MVOR layout, all days)")
    p.add_argument("--cross", type=Path, required=True, help="another look of the same poses and rig")
    p.add_argument(
        "--holdout-day", type=int, default=4, help="the day tested in both looks, never trained on"
    )
    p.add_argument(
        "--modalities", nargs="+", default=["rgb", "depth", "rgbd"], choices=["rgb", "depth", "rgbd"]
    )
    p.add_argument("--minutes", type=float, default=10.0, help="CPU-minutes of training per modality")
    p.add_argument("--every", type=float, default=5.0, help="CPU-minutes between validations")
    p.add_argument("--threads", type=int, default=2, help="torch threads of each training run")
    p.add_argument(
        "--train-args", default="", help="more posenet.training.train options for every run, e.g. '--base 24'"
    )
    p.add_argument("--detector", help="detector checkpoint to score on both looks (default: the shipped one)")
    p.add_argument("--no-detector", action="store_true", help="only the pose network")
    p.add_argument("--out", type=Path, required=True, help="folder of the runs and look_transfer.json")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)

    from posenet.runtime.execution import machine_line

    rows = pose_rows(args) + ([] if args.no_detector else detector_rows(args))
    print(machine_line(), f"(threads {args.threads}, {args.minutes:g} CPU-minutes per modality)")
    print(f"trained on {args.data.name} (days but {args.holdout_day}); day {args.holdout_day} of "
          f"{args.data.name} (in-look) and {args.cross.name} (cross-look)")  # fmt: skip
    print(f"{'model':<34}{'metric':<10}{'in-look':>9}{'cross':>9}{'ratio':>8}")
    for r in rows:
        print(
            f"{r['model']:<34}{r['metric']:<10}{r['in_look']:>9.3f}{r['cross_look']:>9.3f}{r['ratio']:>8.2f}"
        )
    result = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"), "data": str(args.data),
              "cross": str(args.cross), "holdout_day": args.holdout_day, "rows": rows}  # fmt: skip
    (args.out / "look_transfer.json").write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
