"""Does a detector adaptation grow over-confident? Pseudo-label counts of detectors on the same unlabelled frames.

    python benchmarks/adapt_confidence.py --data data/mvor_alt123 --days 3 --max-frames 150 \\
        --checkpoints shipped runs/da_alt_ctrl/last runs/da_alt_slowema/last --labels shipped "EMA 0.99" "EMA 0.999"

Each detector labels the same target frames as ``detector.adapt``'s teacher would (``detector.adapt.label_target``:
its boxes from ``--low`` up, confirmed across views and neighbouring frames, filled in from other views, the static
scene learnt from the frames' depth; ``pipeline.pseudo_boxes``). No label of the frames is read. A self-trained
detector that keeps far more boxes above the gate than the weights it started from has grown over-confident, and
its own boxes come back to it as labels (docs/detector.md, "Why it lowered AP"). ``shipped`` names the shipped
weights. It prints one row per detector (boxes kept, filled in, dropped as unconfirmed or static) with the machine,
and writes ``--out`` as JSON.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch
from tqdm import tqdm

from detector.adapt import DetectorAdaptConfig, label_target
from detector.adapt_data import TargetFrames, read_frames_and_cameras
from detector.checkpoint import load_checkpoint
from detector.infer import DEFAULT_WEIGHTS, PersonDetector
from pipeline.pseudo_boxes import background_depth
from posenet.cli import add_annotations, add_data, add_days, add_threads, annotations_path, set_threads
from posenet.runtime.execution import machine_line

KINDS = ("kept", "filled", "unconfirmed", "static")


def counts_of(checkpoint: str, args: argparse.Namespace, annotations: str) -> dict:
    """The pseudo-label counts of one detector on the frames of ``args``."""
    model, det_cfg, _ = load_checkpoint(DEFAULT_WEIGHTS if checkpoint == "shipped" else checkpoint)
    model.float().eval()
    cfg = DetectorAdaptConfig(
        data=args.data, out="", days=args.days, max_frames=args.max_frames, progress=False
    )
    target = TargetFrames(
        args.data, read_frames_and_cameras(annotations), det_cfg, args.days, args.max_frames, False
    )
    for day in sorted({f.day for f in target.frames}):
        for v in range(len(target.frames[0].records)):
            target.backgrounds[(day, v)] = background_depth(
                target.depths_of(day, v), cfg.pseudo.background_quantile
            )
    teacher = PersonDetector(model, det_cfg, precision="fp32")
    counts, _ = label_target(teacher, target, list(range(len(target))), cfg, False)
    return {"frames": len(target), **{k: counts.get(k, 0) for k in (*KINDS, "views")}}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_data(p, help="unlabelled recordings in MVOR's layout (only frames and cameras are read)")
    add_annotations(p)
    add_days(p, help="days whose frames are labelled (default: all)")
    p.add_argument("--max-frames", type=int, default=150, help="the first N frames (default %(default)s)")
    p.add_argument(
        "--checkpoints", nargs="+", required=True, help="detector checkpoints; 'shipped': the default"
    )
    p.add_argument("--labels", nargs="+", help="a name per checkpoint (default: the paths)")
    p.add_argument("--out", help="write the rows as JSON here")
    add_threads(p, default=1)
    args = p.parse_args(argv)
    set_threads(args.threads)
    torch.manual_seed(0)
    labels = args.labels or args.checkpoints
    if len(labels) != len(args.checkpoints):
        p.error(f"--labels needs one name per checkpoint ({len(args.checkpoints)}), got {len(labels)}")
    annotations = annotations_path(args)
    rows = []
    for label, ckpt in tqdm(
        list(zip(labels, args.checkpoints, strict=True)), desc="detectors", unit="detector"
    ):
        rows.append({"detector": label, "checkpoint": ckpt, **counts_of(ckpt, args, annotations)})
    print(f"\n{machine_line()}; {args.data}, days {args.days or 'all'}, {rows[0]['frames']} frames")
    print("| detector | boxes kept (confirmed) | filled in | unconfirmed | static |")
    print("| --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['detector']} | {r['kept']} | {r['filled']} | {r['unconfirmed']} | {r['static']} |")
    if args.out:
        Path(args.out).write_text(json.dumps({"machine": machine_line(), "rows": rows}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
