"""Choosing the tracker's thresholds: several tracker configurations side by side over several tuning sequences.

    python benchmarks/tracking.py --data data/seq_t50 --detections runs/det_seq_t50.jsonl   # caches the persons
    python benchmarks/tracker_sweep.py --seq data/seq_t50:runs/det_seq_t50.jsonl \\
        --seq data/seq_t51:runs/det_seq_t51.jsonl --try max_spread_mm=500 --try max_spread_mm=700 \\
        --try duplicate_mm=250,unsure_gate_mm=200 --json runs/sweep.json

Each ``--seq`` is a rendered sequence and the pipeline's persons per frame cached by ``benchmarks/tracking.py``
(detector mode, the weights to tune for). Each ``--try`` is one configuration: comma-separated ``KEY=VALUE``
overrides of :class:`pipeline.track.TrackerConfig` on top of ``--base`` (the same syntax as ``tracking.py --set``).
The first row is always ``--base`` alone. The tracker runs as a stream runs it (given each frame's depth views: the
room's static depth and parked tracks) unless ``--no-background``.

Per configuration it prints the figures summed or weighted over all sequences: IDF1 weighted by annotated
person-frames, id switches and their rate per 1,000 person-frames, MOTA weighted likewise, misses, false positives,
the longest track on nobody (the worst sequence), and the lowest sequence's IDF1. Choose on tuning sequences only:
the held-out and evaluation sequences then say what the choice is worth. The configurations run in ``--workers``
processes (default 2; each loads the sequences once).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from tracking import depth_views, sequences, tracker_config

from pipeline.track import Tracker
from pipeline.track_eval import evaluate
from posenet.data.mvor import load_annotations
from posenet.runtime.execution import machine_line

_ROWS: dict[str, list] = {}  # sequence name -> its frames, loaded once per process


def load(spec: str, background: bool) -> dict[str, list]:
    """The frames of one ``DATA:DETECTIONS`` pair, per sequence in it, named ``DATA[/sequence]``."""
    data, _, det = spec.partition(":")
    if not det:
        raise ValueError(f"--seq {spec}: give DATA:DETECTIONS (the persons cached by benchmarks/tracking.py)")
    data, det = Path(data), Path(det)
    if not det.is_file():
        raise ValueError(f"--seq {spec}: {det} does not exist; run benchmarks/tracking.py --data {data} "
                         f"--detections {det} first")  # fmt: skip
    gt = load_annotations(data / "annotations.json")
    with open(det) as f:
        detections = {r["id"]: r for r in map(json.loads, f)}
    views = depth_views(data, gt) if background else {}
    out = {}
    seqs = sequences(gt, detections)
    for seq, rows in seqs.items():
        for frame_id, f in rows:
            f.views = views.get(frame_id)
        out[data.name if len(seqs) == 1 else f"{data.name}/{seq}"] = [f for _, f in rows]
    return out


def _load_all(specs: list[str], background: bool) -> None:
    """A worker's start: one torch thread (the workers share the cores), then every sequence."""
    torch.set_num_threads(1)
    for spec in specs:
        _ROWS.update(load(spec, background))


def run(overrides: tuple[str, ...]) -> dict:
    """Figures per sequence for one configuration, and their totals."""
    config = tracker_config(list(overrides))
    per = {name: evaluate(frames, Tracker(config)) for name, frames in _ROWS.items()}
    n = np.array([f["gt_person_frames"] for f in per.values()], float)
    weighted = lambda key: round(float(np.dot(n, [f[key] for f in per.values()]) / n.sum()), 4)  # noqa: E731
    switches = int(sum(f["id_switches"] for f in per.values()))
    return {
        "overrides": list(overrides),
        "idf1": weighted("idf1"),
        "idf1_min": round(min(f["idf1"] for f in per.values()), 4),
        "mota": weighted("mota"),
        "id_switches": switches,
        "switches_per_1000": round(1000 * switches / n.sum(), 2),
        "misses": int(sum(f["misses"] for f in per.values())),
        "false_positives": int(sum(f["false_positives"] for f in per.values())),
        "longest_on_nobody_s": max(f["longest_on_nobody_s"] for f in per.values()),
        "person_frames": int(n.sum()),
        "per_sequence": {
            k: {m: f[m] for m in ("idf1", "mota", "id_switches", "longest_on_nobody_s")}
            for k, f in per.items()
        },  # fmt: skip
    }


COLUMNS = ("idf1", "idf1_min", "mota", "id_switches", "switches_per_1000", "misses", "false_positives",
           "longest_on_nobody_s")  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--seq", action="append", required=True, metavar="DATA:DETECTIONS",
                   help="a rendered sequence and its cached persons (benchmarks/tracking.py --detections)")  # fmt: skip
    p.add_argument("--try", dest="tries", action="append", default=[], metavar="KEY=VALUE[,KEY=VALUE...]",
                   help="one configuration: TrackerConfig overrides on top of --base")  # fmt: skip
    p.add_argument("--base", default="", metavar="KEY=VALUE[,...]", help="overrides every row starts from")
    p.add_argument("--no-background", action="store_true", help="track without the frames' depth views")
    p.add_argument("--workers", type=int, default=2, help="processes that run the configurations")
    p.add_argument("--json", type=Path, help="also write the rows here")
    args = p.parse_args(argv)
    base = tuple(s for s in args.base.split(",") if s)
    rows = [base] + [base + tuple(s for s in t.split(",") if s) for t in args.tries]
    background = not args.no_background
    # spawned workers load the sequences themselves (torch is not fork-safe): here only their persons, to check them
    parallel = args.workers > 1 and len(rows) > 1
    try:
        for r in rows:
            tracker_config(list(r))
        _load_all(args.seq, background and not parallel)
    except ValueError as err:
        p.error(str(err))
    started = time.perf_counter()
    if parallel:
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.workers, spawn, _load_all, (args.seq, background)) as pool:
            results = list(pool.map(run, rows))
    else:
        results = [run(r) for r in rows]
    total = sum(len(f) for f in _ROWS.values())
    print(f"{len(_ROWS)} sequences, {total} frames, {results[0]['person_frames']} annotated person-frames; "
          f"{len(rows)} configurations in {time.perf_counter() - started:.0f} s")  # fmt: skip
    print("| configuration | " + " | ".join(COLUMNS) + " |")
    print("| --- " * (len(COLUMNS) + 1) + "|")
    for r in results:
        name = ", ".join(r["overrides"][len(base) :]) or ("base: " + ", ".join(base) if base else "default")
        print(f"| {name} | " + " | ".join(str(r[c]) for c in COLUMNS) + " |")
    print(machine_line())
    report = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"), "sequences": sorted(_ROWS),
              "default": asdict(tracker_config([])), "rows": results}  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
