"""Detectors side by side on several rendered sets: AP50 and AP per set and detector (pycocotools).

    python benchmarks/detector_sets.py --detectors shipped new=runs/det_new \
        --sets data/mvor_twin4:4 data/mvor_alt4:4 data/mvor_altmesh4:4 data/seq_h43 data/seq_h45 --json out.json

MVOR's day 4 alone, with 2-4 large people per view, can make a detector look better than it is: fine-tuned at input
width 128, the shipped detector gained AP50 there and lost 0.005-0.042 on the tracking sequences' frames, where 4-5
people walk and stand close, and the tracker lost identities with it (docs/detector.md, "Fine-tuned at input width
128"). So detectors are compared on the sets that matter in one run: day 4 of each look and the tracking sequences.

``--detectors``: ``NAME=PATH`` (a checkpoint folder or ``.safetensors``), or ``shipped`` for the shipped weights.
``--sets``: ``PATH[:DAY,DAY...]``, datasets in MVOR's layout (``posenet.synth`` writes them), all days unless given.
Each detector runs on torch float32 from its file (the weights, not the runtime: ``backend_accuracy.py`` compares
runtimes), keeping every detection down to score 0.01 so that AP does not depend on a threshold, on every view of
the set's days (a view without a detection counts its misses). The last columns give each detector's difference to
the first. Prints one table, writes ``--json`` with the machine.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def parse_detector(text: str) -> tuple[str, str | None]:
    """``NAME=PATH`` -> (NAME, PATH); ``shipped`` -> ("shipped", None)."""
    if text == "shipped":
        return "shipped", None
    name, sep, path = text.partition("=")
    if not sep or not name or not path:
        raise argparse.ArgumentTypeError(f"{text!r}: give NAME=PATH (e.g. new=runs/det/last) or 'shipped'")
    return name, path


def parse_set(text: str) -> tuple[Path, list[int] | None]:
    """``PATH[:DAY,DAY...]`` -> (PATH, days or None for all)."""
    path, _, days = text.partition(":")
    try:
        return Path(path), [int(d) for d in days.split(",")] if days else None
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: days are integers, e.g. data/mvor_twin4:4") from None


def score_sets(detectors: dict, sets: list[tuple[Path, list[int] | None]], progress: bool = True) -> dict:
    """{set: {detector: {"AP50", "AP", "views"}}} of every detector on every set; a set is named by its folder and
    days (by its path where two folders share a name)."""
    from detector.data import load_records
    from detector.evaluate import coco_ap
    from detector.predict import predict_records

    days_of = ["" if days is None else f":{','.join(map(str, days))}" for _, days in sets]
    keys = [root.name + d for (root, _), d in zip(sets, days_of, strict=True)]
    if len(set(keys)) < len(keys):  # sets in folders of the same name: their paths tell them apart
        keys = [str(root) + d for (root, _), d in zip(sets, days_of, strict=True)]
    out = {}
    for (root, days), key in zip(sets, keys, strict=True):
        records = load_records(root / "annotations.json", days)
        if not records:
            raise SystemExit(f"{root}: no views on days {days}")
        out[key] = {}
        for name, detector in detectors.items():
            results = predict_records(detector, records, root, progress=progress)
            m = coco_ap(records, results)
            out[key][name] = {"AP50": m["AP50"], "AP": m["AP"], "views": len(records)}
    return out


def table(scores: dict) -> list[str]:
    names = list(next(iter(scores.values())))
    head = f"{'set':<24}{'views':>6}" + "".join(f"{n + ' AP50 / AP':>26}" for n in names)
    head += "".join(f"{'d ' + n:>18}" for n in names[1:])
    lines = [head]
    for key, row in scores.items():
        first = row[names[0]]
        line = f"{key:<24}{first['views']:>6}" + "".join(
            f"{r['AP50']:>17.3f} / {r['AP']:.3f}" for r in row.values()
        )
        line += "".join(
            f"{row[n]['AP50'] - first['AP50']:>+10.3f} / {row[n]['AP'] - first['AP']:+.3f}" for n in names[1:]
        )
        lines.append(line)
    return lines


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--detectors", nargs="+", type=parse_detector, default=[("shipped", None)],
                   help="NAME=PATH or 'shipped' (default: the shipped weights alone)")  # fmt: skip
    p.add_argument(
        "--sets", nargs="+", type=parse_set, required=True, help="PATH[:DAY,DAY...] in MVOR's layout"
    )
    p.add_argument("--threads", type=int, default=2, help="torch's CPU threads")
    p.add_argument("--json", type=Path, help="also write the results here")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = p.parse_args(argv)
    names = [n for n, _ in args.detectors]
    if len(set(names)) != len(names):
        p.error(f"--detectors: each needs its own name, got {names}")
    for root, _ in args.sets:
        if not (root / "annotations.json").is_file():
            p.error(
                f"--sets: {root}/annotations.json does not exist (render one with python -m posenet.synth)"
            )

    import torch

    from detector.infer import PersonDetector
    from posenet.runtime.execution import machine_line

    torch.set_num_threads(args.threads)
    detectors = {n: PersonDetector.from_checkpoint(path, precision="fp32") for n, path in args.detectors}
    scores = score_sets(detectors, args.sets, progress=not args.no_progress)
    print(machine_line(), f"(torch float32, {args.threads} threads; every detection down to score 0.01)")
    print("\n".join(table(scores)))
    result = {"machine": machine_line(), "date": time.strftime("%Y-%m-%d"),
              "detectors": {n: path or "shipped" for n, path in args.detectors}, "sets": scores}  # fmt: skip
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
