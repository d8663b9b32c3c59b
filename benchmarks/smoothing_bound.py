"""How far could any smoother go? The served raw joints of each track, smoothed after the fact (future known).

    python -m service.client data/seq_eval --annotations data/seq_eval/annotations.json --url URL --out S.jsonl --track
    python benchmarks/smoothing_bound.py --data data/seq_eval --served S.jsonl

Each ground-truth person of each frame is paired with the confirmed track the service answered nearest to it
(optimal assignment on the mean joint distance of the smoothed joints, gated at 50 cm as ``pipeline.track_eval``).
Along each track, the raw joints (``joints``) are then smoothed by non-causal filters that see the whole track:
centred means and Savitzky-Golay fits of several lengths (scipy), and, as an oracle, the raw joints minus the
track's mean error against the ground truth (what remains when each person's constant offset is known). The table
gives each one's MPJPE as a ratio to the raw one, beside the service's own causal smoothing (``smoothed_joints``).
If even the oracle stays near 1, the per-frame error is a bias that changes with the pose, which no smoother removes.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter
from tracking import sequences, served_lines, served_tracks

from pipeline.track_eval import gated_pairs
from posenet.data.mvor import load_annotations
from posenet.runtime.execution import machine_line

MEANS = (3, 5, 9, 15)
SAVGOL = ((9, 2), (15, 2), (31, 2))


def paired_tracks(gt: dict, lines: dict) -> dict[tuple[int, int], list[tuple]]:
    """Per (sequence, track), its frames in order: (raw (J, 3), smoothed (J, 3), ground truth (J, 3))."""
    out = defaultdict(list)
    for seq, rows in sequences(gt).items():
        for frame_id, frame in rows:
            tracks, _ = served_tracks(lines, frame_id)
            for g, t in gated_pairs(frame.gt_joints, tracks):
                out[(seq, t)].append((tracks[t].raw, tracks[t].joints, frame.gt_joints[g]))
    return out


def ratios(tracks: dict[tuple[int, int], list[tuple]]) -> dict[str, float]:
    """Each smoother's MPJPE over all paired person-frames, as a ratio to the raw joints'."""
    err = defaultdict(list)
    for frames in tracks.values():
        raw, smooth, truth = (np.array(x) for x in zip(*frames, strict=True))  # (N, J, 3) each

        def e(x, truth=truth):
            return list(np.linalg.norm(x - truth, axis=-1).mean(-1))

        err["raw joints"] += e(raw)
        err["the service's smoothed joints (causal)"] += e(smooth)
        for w in MEANS:
            h = w // 2
            err[f"centred mean of {w} frames"] += e(
                np.array([raw[max(0, i - h) : i + h + 1].mean(0) for i in range(len(raw))])
            )
        for w, order in SAVGOL:
            fit = savgol_filter(raw, w, order, axis=0, mode="interp") if len(raw) > w else raw
            err[f"Savitzky-Golay, {w} frames, order {order}"] += e(fit)
        err["oracle: each track's mean error removed"] += e(raw - (raw - truth).mean(0))
    base = float(np.mean(err["raw joints"]))
    return {name: float(np.mean(v)) / base for name, v in err.items()} | {"raw MPJPE cm": base / 10}


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument(
        "--data", type=Path, required=True, help="a rendered sequence (posenet.synth --sequence)"
    )
    p.add_argument(
        "--served", type=Path, required=True, help="the JSON lines of `service.client DATA --track`"
    )
    p.add_argument("--json", type=Path, help="also write the figures here")
    args = p.parse_args(argv)
    gt = load_annotations(args.data / "annotations.json")
    tracks = paired_tracks(gt, served_lines(args.served))
    figures = ratios(tracks)
    print(f"{args.data}: {sum(len(v) for v in tracks.values())} person-frames on {len(tracks)} tracks, "
          f"raw MPJPE {figures['raw MPJPE cm']:.2f} cm")  # fmt: skip
    print(f"{'smoother':48s} MPJPE / raw")
    for name, value in figures.items():
        if name != "raw MPJPE cm":
            print(f"{name:48s} {value:.3f}x")
    report = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"), "data": str(args.data),
              "served": str(args.served), "figures": figures}  # fmt: skip
    print(report["machine"])
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
