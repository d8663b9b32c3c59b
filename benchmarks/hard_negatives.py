"""How often the shipped person detector fires on hard negatives: the same frames without and with them.

    python benchmarks/hard_negatives.py --scenes 40 --seed 131 --hard-negatives 4 --json runs/hard_negatives.json

Renders ``--scenes`` procedural frames of the random look on MVOR's rig (seed ``--seed``, in memory, exactly as
``python -m posenet.synth --scenes N --rig mvor --look random [--hard-negatives H]`` writes them) twice: without
hard negatives and with ``--hard-negatives`` tried per frame (``posenet.synth.hard_negatives``; drawn from their
own generator, so the two renders differ by them alone). The shipped detector (its served backend) runs on every
view; a box at or above its score threshold is a false positive when its IoU with every person's box of the view
(annotated or box-only, the patient included) is below 0.3. A false positive of the second render is put on the
hard negative whose pixels (the view's owner map) cover most of it, when they cover at least 25 % of the box;
else on ``other``. Prints, per kind, the views that see it (at least 500 pixels), the false positives on it and
their rate per view; then the false positives per frame without and with hard negatives, and the persons' boxes
found (recall at IoU 0.5) in both. The first line names the machine.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from detector.infer import PersonDetector
from posenet.boxes import box_iou
from posenet.runtime.execution import machine_line
from posenet.synth.hard_negatives import KINDS
from posenet.synth.primitives import OWNER_HARD_NEGATIVE
from posenet.synth.twin import load_twin
from posenet.synth.writer import SynthConfig, build_rigs, frame_views, plan_jobs

MVOR = Path(__file__).resolve().parents[1] / ".." / "shared" / "mvor" / "camma_mvor_2018.json"
FP_IOU = 0.3  # below this IoU with every person's box: a false positive
COVER = 0.25  # a false positive on a hard negative: its pixels cover at least this share of the box
SEEN_PX = 500  # a hard negative is seen in a view with at least this many pixels


def person_boxes(view) -> np.ndarray:
    """(P, 4) xyxy of the view's persons' boxes (the renderer's are inclusive pixel indices)."""
    boxes = [(b[0], b[1], b[2] + 1, b[3] + 1) for b in view.boxes if b is not None]
    return np.array(boxes, float).reshape(-1, 4)


def on_which(view, box: np.ndarray) -> int | None:
    """The owner id of the hard negative that covers most of ``box`` (at least COVER of it), or None."""
    x0, y0 = (int(max(np.floor(c), 0)) for c in box[:2])
    x1, y1 = int(np.ceil(box[2])), int(np.ceil(box[3]))
    owners = view.owner[y0:y1, x0:x1]
    ids, counts = np.unique(owners[owners <= OWNER_HARD_NEGATIVE], return_counts=True)
    if not len(ids) or counts.max() < COVER * max(owners.size, 1):
        return None
    return int(ids[counts.argmax()])


def score(detector: PersonDetector, cfg: SynthConfig, rigs, twin, jobs) -> dict:
    """Per kind: views seen, false positives; and in all: false positives, persons' boxes and those found."""
    seen, fp, found, persons, seconds = Counter(), Counter(), 0, 0, 0.0
    for job in tqdm(jobs, desc=f"hard negatives {cfg.hard_negatives}", unit="frame"):
        t0 = time.perf_counter()
        _, views, stats = frame_views(cfg, rigs, twin, job)
        seconds += time.perf_counter() - t0
        kinds = stats.get("hard_negative_kinds", [])
        dets = detector.detect([v.color for v in views], [v.depth for v in views])
        for view, det in zip(views, dets, strict=True):
            ids, counts = np.unique(view.owner[view.owner <= OWNER_HARD_NEGATIVE], return_counts=True)
            seen.update(
                kinds[OWNER_HARD_NEGATIVE - i] for i, c in zip(ids, counts, strict=True) if c >= SEEN_PX
            )
            truth = person_boxes(view)
            iou = box_iou(det.boxes[:, None].astype(float), truth[None]).reshape(len(det.boxes), len(truth))
            persons += len(truth)
            found += int((iou >= 0.5).any(0).sum())
            for box, best in zip(det.boxes, iou.max(1, initial=0.0), strict=True):
                if best < FP_IOU:
                    owner = on_which(view, box)
                    fp["other" if owner is None else kinds[OWNER_HARD_NEGATIVE - owner]] += 1
    return {"frames": len(jobs), "seen": dict(seen), "false_positives": dict(fp), "persons": persons,
            "found": found, "render_seconds_per_frame": seconds / max(len(jobs), 1)}  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--scenes", type=int, default=40, help="procedural frames (spread over MVOR's 4 days)")
    p.add_argument("--seed", type=int, default=131, help="the renderer's seed (use one no training set used)")
    p.add_argument("--hard-negatives", type=int, default=4, help="hard negatives tried per frame")
    p.add_argument("--mvor", type=Path, default=MVOR, help="MVOR's annotation file (its rig)")
    p.add_argument("--detector-checkpoint", type=Path, help="detector weights (default: the shipped ones)")
    p.add_argument("--backend", default="auto", help="the detector's backend (default: the served one)")
    p.add_argument("--threads", type=int, default=2, help="the detector's threads")
    p.add_argument("--json", type=Path, help="also write the results here")
    args = p.parse_args(argv)
    if args.scenes < 1 or args.hard_negatives < 1:
        p.error("--scenes and --hard-negatives must be at least 1")
    if not args.mvor.is_file():
        p.error(f"MVOR's annotation file not found at {args.mvor}: pass it with --mvor")
    twin = load_twin(json.loads(args.mvor.read_text()))
    detector = PersonDetector.from_checkpoint(
        args.detector_checkpoint, backend=args.backend, threads=args.threads
    )
    base = SynthConfig(out="", scenes=args.scenes, rig="mvor", seed=args.seed, look="random",
                       mvor_annotations=str(args.mvor))  # fmt: skip
    rigs, jobs = build_rigs(base, twin), plan_jobs(base, twin)
    runs = {}
    for n in (0, args.hard_negatives):
        cfg = replace(base, hard_negatives=n)
        runs[n] = score(detector, cfg, rigs, twin, jobs)
    without, with_ = runs[0], runs[args.hard_negatives]
    print(machine_line())
    print(f"detector threshold {detector.score_threshold:.3f}, backend {args.backend}; {args.scenes} random-look "
          f"frames on MVOR's rig, seed {args.seed}, {args.hard_negatives} hard negatives tried per frame")  # fmt: skip
    print(f"{'kind':<12} {'views seen':>10} {'false pos.':>10} {'per view':>9}")
    for kind in KINDS:
        s, f = with_["seen"].get(kind, 0), with_["false_positives"].get(kind, 0)
        print(f"{kind:<12} {s:>10} {f:>10} {f / s if s else float('nan'):>9.3f}")
    print(f"{'':<12} {'FP / frame':>10} {'other FP':>10} {'recall':>9} {'render s':>9}")
    for name, r in (("without", without), ("with", with_)):
        total = sum(r["false_positives"].values())
        print(f"{name:<12} {total / r['frames']:>10.3f} {r['false_positives'].get('other', 0):>10} "
              f"{r['found'] / max(r['persons'], 1):>9.3f} {r['render_seconds_per_frame']:>9.2f}")  # fmt: skip
    out = {"machine": machine_line(), "seed": args.seed, "scenes": args.scenes,
           "threshold": detector.score_threshold, "without": without, "with": with_}  # fmt: skip
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=2))
    return out


if __name__ == "__main__":
    main()
