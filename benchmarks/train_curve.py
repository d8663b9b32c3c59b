"""Learning curves per CPU-minute: held-out MPJPE against minutes of training, for recipes side by side.

    python benchmarks/train_curve.py --data data/mvor_twin --minutes 30 --threads 1 --out runs/curve_twin
    python benchmarks/train_curve.py --data data/mvor_alt --minutes 30 \\
        --variant cpu= --variant lr3e-3="--lr 3e-3" --variant base24="--base 24"
    python benchmarks/train_curve.py --from-runs runs/ship2 --out runs/ship2_curve   # draw finished runs

Minutes are CPU-minutes (``--clock cpu``: the training process's CPU time, so a loaded, shared machine slows
the run but does not bend its curve; with ``--threads 1``, minutes of one core). Each variant is one
``python -m posenet.training.train --minutes N`` run on ``--data``'s days other than
``--holdout-day`` (validated on that day every ``--every`` minutes of training), run one after another so
that they never share the cores. A variant is ``NAME=ARGS``: the extra ``posenet.training.train`` options of that
recipe (empty: the ``cpu`` preset as it is). Runs that exist are resumed, so an interrupted curve continues.
Prints minutes x variant MPJPE (cm, overall), the final training loss and crops per second, writes
``OUT/curve.json`` and a picture ``OUT/curve.png``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def run(variant: str, extra: list[str], args) -> list[dict]:
    out = args.out / variant
    cmd = [sys.executable, "-m", "posenet.training.train", "--data", str(args.data), "--holdout-day", str(args.holdout_day),
           "--out", str(out), "--minutes", str(args.minutes), "--val-every-minutes", str(args.every),
           "--threads", str(args.threads), "--clock", "cpu"]  # fmt: skip
    cmd += ["--resume"] if (out / "last" / "train_state.pt").is_file() else extra
    with open(args.out / f"{variant}.log", "a") as log:
        subprocess.run(cmd, cwd=REPO, check=True, stdout=log, stderr=log)
    return [json.loads(line) for line in (out / "log.jsonl").read_text().splitlines()]


def picture(
    curves: dict[str, list[dict]], path: Path, title: str, xlabel: str = "CPU-minutes of training"
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for name, log in curves.items():
        pts = [(r["minutes"], r["val_mpjpe_cm"]) for r in log if "val_mpjpe_cm" in r]
        if pts:
            line = ax.plot(*zip(*pts, strict=True), marker="o", label=f"{name}: held-out day")[0]
        # posenet.training.train --watch sets (e.g. the unseen look), dashed in the same colour
        watched = sorted({k for r in log for k in r if k.startswith("watch_") and k.endswith("_cm")})
        for k, style in zip(watched, ("--", ":", "-."), strict=False):
            pts = [(r["minutes"], r[k]) for r in log if k in r]
            ax.plot(*zip(*pts, strict=True), style, marker=".", color=line.get_color(),
                    label=f"{name}: {k[len('watch_'):-len('_cm')]} (watched)")  # fmt: skip
    ax.set_xlabel(xlabel)
    ax.set_ylabel("held-out MPJPE, cm (overall)")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    p.add_argument("--data", type=Path, help="MVOR-format dataset (train days + held-out day)")
    p.add_argument("--from-runs", type=Path, nargs="+", metavar="RUN",
                   help="instead of training: print and draw the logs of these posenet.training.train run folders "
                   "(e.g. a --minutes run with --watch sets)")  # fmt: skip
    p.add_argument("--holdout-day", type=int, default=4)
    p.add_argument("--minutes", type=float, default=30.0, help="training budget of each variant")
    p.add_argument("--every", type=float, default=5.0, help="minutes of training between validations")
    p.add_argument("--threads", type=int, default=1, help="torch threads of each run")
    p.add_argument("--variant", action="append", metavar="NAME=ARGS", help="a recipe (default: cpu=)")
    p.add_argument("--out", type=Path, required=True, help="folder of the runs, curve.json and curve.png")
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    variants = dict(v.split("=", 1) for v in (args.variant or ["cpu="]))

    from posenet.net.checkpoint import training_config
    from posenet.runtime.execution import machine_line

    if args.from_runs:
        curves = {
            r.name: [json.loads(t) for t in (r / "log.jsonl").read_text().splitlines()]
            for r in args.from_runs
        }
        config = training_config(json.loads((args.from_runs[0] / "config.json").read_text()))
        args.data, args.threads, args.holdout_day = (
            Path(config["data"]),
            config["threads"],
            config["holdout_day"],
        )
        clock = config.get("clock", "wall")
    elif args.data is None:
        p.error("give --data (to train the variants) or --from-runs")
    else:
        curves = {name: run(name, shlex.split(extra), args) for name, extra in variants.items()}
        clock = "cpu"
    steps = sorted({r["minutes"] for log in curves.values() for r in log if "val_mpjpe_cm" in r})
    print(machine_line(), f"(threads {args.threads})")
    print(f"{'variant':<16}" + "".join(f"{m:>8.1f}" for m in steps) + f"{'loss mm':>9}{'crops/s':>9}")
    for name, log in curves.items():
        keys = ["val_mpjpe_cm"] + sorted(
            {k for r in log for k in r if k.startswith("watch_") and k.endswith("_cm")}
        )
        crops = sum(r.get("crops", 0) for r in log) / max(1e-9, 60 * log[-1]["minutes"])
        for k in keys:
            at = {r["minutes"]: r[k] for r in log if k in r}
            row = "".join(f"{at[m]:>8.2f}" if m in at else f"{'':>8}" for m in steps)
            label = name if k == "val_mpjpe_cm" else f"  {k[len('watch_') : -len('_cm')]}"
            tail = f"{log[-1]['train_loss']:>9.1f}{crops:>9.1f}" if k == "val_mpjpe_cm" else ""
            print(f"{label:<16}{row}{tail}")
    result = {"machine": machine_line(), "threads": args.threads, "data": str(args.data), "curves": curves}
    (args.out / "curve.json").write_text(json.dumps(result, indent=2))
    xlabel = (
        "CPU-minutes of training"
        if clock == "cpu"
        else f"minutes of training (wall clock, {args.threads} threads)"
    )
    picture(curves, args.out / "curve.png", f"{args.data.name}, day {args.holdout_day} held out", xlabel)
    return result


if __name__ == "__main__":
    main()
