"""Fit the calibrated per-joint confidence of a pose checkpoint (``posenet.net.calibration``) and report it.

Usage (the shipped weights since 2026-12-06; the fit data is rendered in the training look family with seeds no
training run used: procedural scenes and sequences on MVOR's rig and on random rigs, with and without mesh bodies;
docs/MODEL_CARD.md)::

    python -m posenet.synth --out data/calib_rr_mesh --scenes 120 --rig random --look random --mesh-share 0.5 \
        --seed 151 --workers 1
    python -m posenet.synth --out data/calib_seq_rr_rand --sequence --frames 120 --persons 3 --rig random \
        --look random --seed 156 --workers 1   # ... and the four others of the model card
    python -m posenet.evaluation.calibrate --data data/calib_rr_mesh ... --data data/calib_seq_rr_rand \
        --cache runs/calibrate_cache --test data/mvor_alt4:4 --test data/mvor_altmesh4:4 --test data/rig77_alt \
        --plot docs/img/calibration.png --write

It predicts every annotated person of the ``--data`` sets (``DIR[:DAY,DAY...]``, pooled) with its reference
boxes, measures each joint's 3D error, fits P(error <= ``--radius-mm``) from the spread, the joint type and the number of supporting views,
and prints the expected calibration error (ECE) of the fallback curve, of the checkpoint's own calibration
(``shipped``) and of the fit on the fit data and on each ``--test`` set (``DIR[:DAY,DAY...]``). Every confidence
is the one served: a one-view skeleton without a person's size is capped (``posenet.net.plausibility``).
``--write`` stores the fit under ``"calibration"`` in the checkpoint's json (``posenet/weights/default.json`` for
the shipped weights), where ``posenet.net.infer`` and ``posenet.evaluation.predict`` read it. Fit on data the
checkpoint never trained on, and rerun it for new weights.

Without ``--data`` it only measures: the ECE of the fallback and of the checkpoint's calibration on each
``--test`` set. ``--served DIR[:DAY,DAY...]=PREDICTIONS.json`` scores the confidences that a prediction file holds
as they are (e.g. detector mode's, ``benchmarks/detector_mode.py --predictions``, whose supports are the
detected ones)::

    python -m posenet.evaluation.calibrate --test data/mvor_alt4:4 --test data/rig77_alt \
        --served data/mvor_alt4:4=runs/detmode_alt4/unsure_outliers_unseen.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import textwrap
from pathlib import Path

import numpy as np
import torch

from posenet.cli import add_days, add_threads, set_threads
from posenet.evaluation.evaluate import match_predictions
from posenet.net.calibration import Calibration, fit, reliability
from posenet.net.checkpoint import checkpoint_files, load_checkpoint
from posenet.net.plausibility import ONE_VIEW_CAP, implausible
from posenet.skeleton import NUM_JOINTS

CACHE_VERSION = 2  # 2: the one-view cap's flag per joint (``capped``)
KEYS = ("spread_mm", "joint", "support", "error_mm", "capped")  # what measure() returns


def measure(model, data: Path, annotations: Path | None, days: list[int] | None, cache: Path | None) -> dict:
    """Per annotated, predicted joint of ``data``'s ``days``: ``spread_mm``, ``joint``, ``support``, ``error_mm``,
    ``capped`` (its person is a one-view skeleton without a person's size, whose confidence is capped; all (N,)).
    Cached in ``cache`` (keyed by the weights, the data and the days) when given."""
    from posenet.data.mvor import load_annotations
    from posenet.evaluation.predict import predict_samples, read_dataset
    from posenet.net.infer import PoseEstimator

    annotations = annotations or data / "annotations.json"
    key = None
    if cache is not None:
        weights = {k: v.float().sum().item() for k, v in model.state_dict().items()}
        text = json.dumps(
            [sorted(weights.items()), str(data.resolve()), days, annotations.stat().st_mtime, CACHE_VERSION]
        )
        key = cache / f"calib_{data.name}_{hashlib.sha1(text.encode()).hexdigest()[:12]}.npz"
        if key.is_file():
            return dict(np.load(key))
    gt = load_annotations(annotations)
    dataset = read_dataset(data, gt, model.config.inputs, days)
    preds = predict_samples(PoseEstimator(model, device=None), dataset, which="annotated")
    return joints_of(match_predictions(gt, preds, days=days), key)


def joints_of(m, key: Path | None = None) -> dict:
    """The per-joint arrays of :func:`measure` from matched predictions ``m`` (``evaluate.Matched``), saved to
    ``key`` when given."""
    spread = np.full((len(m.records), NUM_JOINTS), np.nan)  # (N, J)
    for i, record in enumerate(m.records):
        if record is not None:
            spread[i] = record["spread_mm"]
    keep = m.valid & m.matched[:, None]  # (N, J)
    joint = np.broadcast_to(np.arange(NUM_JOINTS), keep.shape)
    support = np.broadcast_to(m.support[:, None], keep.shape)
    capped = np.zeros(len(m.records), bool)
    if m.matched.any():
        capped[m.matched] = implausible(m.pred_joints[m.matched], m.support[m.matched])
    out = {
        "spread_mm": spread[keep],
        "joint": joint[keep],
        "support": support[keep],
        "error_mm": m.errors[keep],
        "capped": np.broadcast_to(capped[:, None], keep.shape)[keep],
    }
    if key is not None:
        key.parent.mkdir(parents=True, exist_ok=True)
        np.savez(key, **out)
    return out


def served(data: Path, days: list[int] | None, predictions: Path) -> dict:
    """Per annotated, predicted joint of ``data``'s ``days``: ``error_mm`` and the ``confidence`` that the prediction
    file ``predictions`` holds (the records of ``posenet.evaluation.evaluate.prediction_record``)."""
    from posenet.data.mvor import load_annotations

    if not predictions.is_file():
        raise SystemExit(f"error: no prediction file at {predictions} (benchmarks/detector_mode.py --predictions DIR "
                         "writes DIR/NAME.json)")  # fmt: skip
    records = json.loads(predictions.read_text())
    if not records or any("confidence" not in r for r in records):
        raise SystemExit(f"error: {predictions} holds predictions without a 'confidence' per joint")
    m = match_predictions(load_annotations(data / "annotations.json"), records, days=days)
    confidence = np.full((len(m.records), NUM_JOINTS), np.nan)  # (N, J)
    for i, record in enumerate(m.records):
        if record is not None:
            confidence[i] = record["confidence"]
    keep = m.valid & m.matched[:, None]  # (N, J)
    return {"confidence": confidence[keep], "error_mm": m.errors[keep]}


def report(calibrations: dict[str, Calibration], joints: dict, radius_mm: float) -> dict:
    """Reliability numbers (``posenet.net.calibration.reliability``) of each calibration on ``joints``, the
    one-view cap applied where ``joints["capped"]``; joints that carry their served ``confidence`` are scored
    as they are (under the name ``served``)."""
    hit = joints["error_mm"] <= radius_mm
    if "confidence" in joints:
        return {"served": reliability(joints["confidence"], hit)}
    spread = torch.as_tensor(joints["spread_mm"], dtype=torch.float64)  # (N,)
    joint, support = torch.as_tensor(joints["joint"]), torch.as_tensor(joints["support"])
    capped = np.asarray(joints.get("capped", np.zeros(hit.shape, bool)))
    out = {}
    for name, cal in calibrations.items():
        confidence = cal.per_joint(spread, joint, support).numpy()
        out[name] = reliability(np.where(capped, np.minimum(confidence, ONE_VIEW_CAP), confidence), hit)
    return out


def plot(results: dict[str, dict], path: Path) -> None:
    """The reliability diagram: one panel per data set, the fallback curve and the fit, with bin counts."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 4.4), squeeze=False)
    for ax, (name, by_cal) in zip(axes[0], results.items(), strict=True):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, ls="--")
        for (cal, rel), colour in zip(by_cal.items(), ("tab:orange", "tab:green", "tab:blue"), strict=False):
            conf, rate, count = (np.asarray(rel[k], float) for k in ("confidence", "rate", "count"))
            shown = count >= 10  # bins of a handful of joints say nothing
            ax.plot(conf[shown], rate[shown], "o-", color=colour, label=f"{cal}: ECE {rel['ece']:.3f}")
        ax.set(xlim=(0, 1), ylim=(0, 1), xlabel="confidence (predicted P(error <= 10 cm))")
        ax.set_title(  # a fit over many sets has a long name: wrapped to the panel
            f"{textwrap.fill(name, 52)}\n{rel['joints']} joints, {100 * rel['hit_rate']:.0f} % within 10 cm",
            fontsize=9,
        )
        ax.legend(loc="upper left", fontsize=8)
    axes[0][0].set_ylabel("observed share within 10 cm")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def write_section(config_file: Path, calibration: Calibration) -> None:
    """Set ``"calibration"`` in the checkpoint's json (written beside and renamed: never half-written)."""
    config = json.loads(config_file.read_text())
    config["calibration"] = calibration.to_dict()
    tmp = config_file.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(config, indent=2) + "\n")
    tmp.replace(config_file)


def data_set(text: str) -> tuple[Path, list[int] | None]:
    """``DIR[:DAY,DAY...]`` -> (DIR, days or None for all)."""
    folder, _, days = text.partition(":")
    return Path(folder), [int(d) for d in days.split(",")] if days else None


def served_set(text: str) -> tuple[Path, list[int] | None, Path]:
    """``DIR[:DAY,DAY...]=PREDICTIONS.json`` -> (DIR, days or None, PREDICTIONS.json)."""
    data, sep, predictions = text.partition("=")
    if not sep or not predictions:
        raise argparse.ArgumentTypeError(f"expected DIR[:D,D]=PREDICTIONS.json, got {text!r}")
    return (*data_set(data), Path(predictions))


def _days(days: list[int] | None) -> str:
    return "all" if days is None else ",".join(map(str, days))


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m posenet.evaluation.calibrate", description=__doc__.split("\n")[0])
    p.add_argument(
        "--checkpoint", default=None, help="checkpoint folder or NAME.safetensors (default: shipped)"
    )
    p.add_argument(
        "--data",
        type=data_set,
        action="append",
        default=[],
        metavar="DIR[:D,D]",
        help="fit data: MVOR-format dataset roots (DIR/annotations.json), repeatable; pooled (none: only measure "
        "the fallback and the checkpoint's calibration on the --test and --served sets)",
    )
    add_days(p, nargs="*", help="fit days of a --data without its own")
    p.add_argument(
        "--test", type=data_set, action="append", default=[], metavar="DIR[:D,D]", help="test sets"
    )
    p.add_argument(
        "--served",
        type=served_set,
        action="append",
        default=[],
        metavar="DIR[:D,D]=PREDICTIONS.json",
        help="also score the confidences a prediction file holds, as they are, against DIR's annotations (e.g. "
        "detector mode's: benchmarks/detector_mode.py --predictions)",
    )
    p.add_argument("--radius-mm", type=float, default=100.0, help="confidence = P(error <= this)")
    p.add_argument("--ridge", type=float, default=1.0, help="L2 weight on the fitted slopes")
    p.add_argument("--write", action="store_true", help="store the fit in the checkpoint's json")
    p.add_argument("--plot", type=Path, default=None, help="reliability diagram PNG")
    p.add_argument("--json", type=Path, default=None, help="write the fit and the reliability numbers here")
    p.add_argument("--cache", type=Path, default=Path("runs/calibrate_cache"), help="measured joints cache")
    add_threads(p)
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    if args.write and not args.data:
        p.error("--write stores a fit: give its fit data with --data")
    if not (args.data or args.test or args.served):
        p.error("give fit data (--data) or sets to measure (--test, --served)")
    set_threads(args.threads)
    _, config_file = checkpoint_files(args.checkpoint)
    model, config = load_checkpoint(args.checkpoint, "cpu", "fp32")
    calibrations = {"fallback": Calibration(radius_mm=args.radius_mm)}
    if config.get("calibration"):
        calibrations["shipped"] = Calibration.from_config(config)
    sets, cal = {}, None
    if args.data:
        fit_sets = [(folder, args.days if days is None else days) for folder, days in args.data]
        measured = [measure(model, folder, None, days, args.cache) for folder, days in fit_sets]
        fit_joints = {k: np.concatenate([m[k] for m in measured]) for k in KEYS}
        cal = fit(
            fit_joints["spread_mm"], fit_joints["joint"], fit_joints["support"], fit_joints["error_mm"],
            args.radius_mm, args.ridge,
        )  # fmt: skip
        calibrations["fitted"] = cal
        sets["fit: " + " + ".join(f"{f.name} {_days(d)}" for f, d in fit_sets)] = fit_joints
    for folder, test_days in args.test:
        sets[f"test: {folder.name} days {_days(test_days)}"] = measure(
            model, folder, None, test_days, args.cache
        )
    for folder, test_days, predictions in args.served:
        sets[f"served: {folder.name} days {_days(test_days)} ({predictions.stem})"] = served(
            folder, test_days, predictions
        )
    results = {name: report(calibrations, joints, args.radius_mm) for name, joints in sets.items()}
    columns = list(calibrations) + ["served"] * bool(args.served)
    print(f"{'data':<52} {'joints':>7} {'within':>7} " + " ".join(f"{'ECE ' + c:>13}" for c in columns))
    for name, by in results.items():
        r = next(iter(by.values()))
        cells = " ".join(f"{by[c]['ece']:>13.3f}" if c in by else f"{'':>13}" for c in columns)
        print(f"{name:<52} {r['joints']:>7} {r['hit_rate']:>7.2f} {cells}")
    if cal is not None:
        cal.info = {
            "fit_data": " + ".join(f"{folder} days {_days(days)}" for folder, days in fit_sets),
            "fit_joints": int(len(fit_joints["error_mm"])),
            "ridge": args.ridge,
            "ece": {name: {k: round(r["ece"], 4) for k, r in by.items() if k != "shipped"}
                    for name, by in results.items()},
        }  # fmt: skip
        print(json.dumps(cal.to_dict()))
    if args.plot:
        plot(results, args.plot)
        print(f"wrote {args.plot}", file=sys.stderr)
    if args.json:
        args.json.write_text(
            json.dumps({"calibration": cal.to_dict() if cal else None, "reliability": results}, indent=2)
        )
    if args.write:
        write_section(config_file, cal)
        print(f"wrote the calibration into {config_file}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
