"""Which part of an unseen look costs the accuracy? The twin with one part of another look at a time.

    python benchmarks/look_factors.py --look alt --twin data/mvor_twin --full data/mvor_alt --work data/lf

A look is body shapes and joint placement, clothing, light and colour camera, depth sensor and occluders
(``posenet.synth.looks.PARTS``). For each part this renders MVOR's ``--days`` as the twin with only that part
taken from ``--look`` (``python -m posenet.synth --from-mvor ... --look L --look-parts PART``; same poses,
rig and room: only the part changes), predicts them with ``--checkpoint`` and reference boxes
(``posenet.evaluation.predict``) and scores them (``posenet.evaluation.evaluate``). The table gives per joint type and overall MPJPE
(cm) for the twin, each one-part look and the whole look, with the share of the whole look's extra error that the
part alone costs. Parts interact, so the shares need not add up to 100 %.

Rendered sets are kept under ``--work`` and reused when present (delete a folder to render it again).
Prints the table and writes ``--json`` with the machine.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

from posenet.data.mvor import load_annotations
from posenet.evaluation.evaluate import evaluate
from posenet.evaluation.predict import predict_samples, read_dataset
from posenet.net.infer import PoseEstimator
from posenet.runtime.execution import machine_line
from posenet.skeleton import JOINT_TYPES
from posenet.synth import __main__ as synth
from posenet.synth.looks import BODY_PARTS, LOOKS, PARTS

DEFAULT_MVOR = os.environ.get("MVOR_ANNOTATIONS", "../shared/mvor/camma_mvor_2018.json")


def render(out: Path, look: str, parts: list[str] | None, days: list[int], mvor: str, workers: int) -> Path:
    """Render MVOR's ``days`` into ``out`` (the twin with ``parts`` of ``look``), unless it is there already."""
    if not (out / "annotations.json").is_file():
        argv = ["--out", str(out), "--from-mvor", mvor, "--look", look, "--mvor-days", *map(str, days)]
        argv += ["--workers", str(workers), "--quiet"] + (["--look-parts", *parts] if parts else [])
        synth.main(argv)
    return out


def score(estimator: PoseEstimator, root: Path, days: list[int]) -> dict:
    """MPJPE per joint type and overall (cm) of ``estimator`` with reference boxes on ``root``'s ``days``."""
    annotations = root / "annotations.json"
    data = read_dataset(root, annotations, estimator.model.config.inputs, days)
    result = evaluate(load_annotations(annotations), predict_samples(estimator, data), days=days)
    row = {name: result["per_joint"][name] for name in JOINT_TYPES}
    row["overall"] = result["overall"]
    row["support"] = {s: v["average"] for s, v in result["per_support"].items()}
    return row


def table(rows: dict[str, dict]) -> str:
    names = [*JOINT_TYPES, "overall"]
    base, full = rows["twin"]["overall"], rows[list(rows)[-1]]["overall"]
    lines = ["| day 4 as | " + " | ".join(names) + " | extra over the twin | share of the whole look's |"]
    lines.append("| --- |" + " --- |" * (len(names) + 2))
    for label, row in rows.items():
        extra = row["overall"] - base
        share = f"{100 * extra / (full - base):.0f} %" if full != base else "-"
        cells = " | ".join(f"{row[n]:.2f}" for n in names)
        lines.append(f"| {label} | {cells} | {extra:+.2f} | {share} |")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )  # fmt: skip
    p.add_argument("--look", choices=[k for k in LOOKS if k != "twin"], default="alt", help="the other look")
    p.add_argument(
        "--parts",
        nargs="+",
        choices=PARTS + BODY_PARTS,
        default=list(PARTS),
        help="parts to take one at a time (body:REGION: one region of the look's body on the twin's, "
        f"{', '.join(BODY_PARTS)})",
    )
    p.add_argument(
        "--twin", type=Path, help="the twin of the same MVOR days (default: rendered under --work)"
    )
    p.add_argument("--full", type=Path, help="the whole other look (default: rendered under --work)")
    p.add_argument(
        "--work", type=Path, default=Path("data/look_factors"), help="where rendered sets are kept"
    )
    p.add_argument("--days", type=int, nargs="+", default=[4], help="MVOR days rendered and scored")
    p.add_argument("--checkpoint", default=None, help="pose checkpoint (default: the shipped weights)")
    p.add_argument("--mvor", default=DEFAULT_MVOR, help="MVOR's annotation file (real rig and poses)")
    p.add_argument("--workers", type=int, default=2, help="render processes")
    p.add_argument("--threads", type=int, default=2, help="torch threads for the predictions")
    p.add_argument("--json", type=Path, help="also write the numbers here")
    return p


def main(argv: list[str] | None = None) -> dict:
    args = build_parser().parse_args(argv)
    import torch

    torch.set_num_threads(args.threads)
    t0 = time.perf_counter()
    estimator = PoseEstimator.from_checkpoint(args.checkpoint)
    sets = {"twin": args.twin or render(args.work / "twin", "twin", None, args.days, args.mvor, args.workers)}
    for part in args.parts:
        sets[f"twin + {args.look} {part}"] = render(
            args.work / f"{args.look}_{part.replace(':', '_')}",
            args.look,
            [part],
            args.days,
            args.mvor,
            args.workers,
        )
    sets[f"{args.look} (whole look)"] = args.full or render(
        args.work / args.look, args.look, None, args.days, args.mvor, args.workers
    )
    rows = {}
    for label, root in sets.items():
        rows[label] = score(estimator, root, args.days)
        print(f"{label}: {rows[label]['overall']:.2f} cm", flush=True)
    print(table(rows))
    result = {"rows": rows, "sets": {k: str(v) for k, v in sets.items()}, "checkpoint": args.checkpoint,
              "machine": machine_line(), "date": time.strftime("%Y-%m-%d %H:%M"),
              "seconds": time.perf_counter() - t0}  # fmt: skip
    print(f"{result['machine']}; {result['seconds']:.0f} s")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
