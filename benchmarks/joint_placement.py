"""How much of a look's error is where its joints sit inside the body? A constant offset per joint type, removed.

    python -m posenet.evaluation.predict --data data/mvor_alt --annotations data/mvor_alt/annotations.json --out P.json
    python benchmarks/joint_placement.py --annotations data/mvor_alt/annotations.json --predictions P.json \
        --fit-days 1 2 3 --days 4

Renderers (and annotators) disagree on where a joint lies inside the flesh: MVOR's hips sit near the top of the
pelvis, its shoulders inside the deltoid, and our ``alt`` look places them elsewhere on purpose
(``posenet.synth.body_alt``). A network trained on other bodies then errs by a constant amount along the body's
own axes, which no amount of unlabelled data can teach it. This measures that share of the error.

Each prediction's residual (ground truth minus prediction) is written in the predicted skeleton's own frame
(forward, outward, up: ``posenet.synth.skeleton_full.body_frame``; outward mirrored for the right side, so
that left and right share one offset). The median residual per joint type over ``--fit-days`` is that type's
offset; adding it back (turned into each pose's frame) to the predictions of ``--days`` gives the corrected
error. The table prints, per joint type and overall (MPJPE, cm, ``posenet.evaluation.evaluate``'s matching): the raw error,
the error with the offsets fitted on ``--fit-days`` (what a few labelled frames of a new OR would give), and with
offsets fitted on ``--days`` themselves (an oracle: all the error that a constant placement could explain).
If the oracle stays near the raw error, the look's error is not a matter of convention.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from posenet.data.mvor import load_annotations
from posenet.evaluation.evaluate import MM_PER_CM, match_predictions
from posenet.runtime.execution import machine_line
from posenet.skeleton import JOINT_TYPES, JOINTS
from posenet.synth.skeleton_full import body_frame

TYPE_OF = np.array(
    [next(i for i, js in enumerate(JOINT_TYPES.values()) if j in js) for j in range(len(JOINTS))]
)
SIDE = np.array(
    [-1.0 if name.startswith("right_") else 1.0 for name in JOINTS]
)  # outward: mirrored on the right


def frames(poses: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` rows forward, left, up of each skeleton ``(N, J, 3)`` (the synthetic bodies' frame)."""
    return np.array([np.stack(body_frame(p)) for p in poses]).reshape(-1, 3, 3)


def residuals(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``(N, J, 3)`` truth minus prediction in each prediction's body frame (forward, outward, up), mm."""
    local = np.einsum("nab,njb->nja", frames(pred), truth - pred)
    local[..., 1] *= SIDE
    return local


def fit_offsets(pred: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``(T, 3)`` the median residual per joint type (forward, outward, up; mm) over the valid joints ``(N, J)``."""
    local = residuals(pred, truth)
    out = np.zeros((len(JOINT_TYPES), 3))
    for t in range(len(JOINT_TYPES)):
        rows = local[valid & (TYPE_OF == t)[None]]
        out[t] = np.median(rows, 0) if len(rows) else 0.0
    return out


def corrected(pred: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The predictions ``(N, J, 3)`` moved by the per-type ``offsets (T, 3)``, each in its own body frame."""
    local = offsets[TYPE_OF][None].repeat(len(pred), 0)  # (N, J, 3)
    local[..., 1] *= SIDE
    return pred + np.einsum("nab,nja->njb", frames(pred), local)


def errors(pred: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """Per joint type (mean of the per-joint means, as ``posenet.evaluation.evaluate``) and overall MPJPE, cm."""
    e = np.linalg.norm(pred - truth, axis=-1)
    out = {
        name: float(np.mean([e[valid[:, j], j].mean() for j in js if valid[:, j].any()]) / MM_PER_CM)
        for name, js in JOINT_TYPES.items()
    }
    out["overall"] = float(e[valid].mean() / MM_PER_CM)
    return out


def measure(gt: dict, predictions: list[dict], fit_days, days) -> dict:
    fit, test = (
        match_predictions(gt, predictions, days=fit_days),
        match_predictions(gt, predictions, days=days),
    )
    fv, tv = fit.valid & fit.matched[:, None], test.valid & test.matched[:, None]
    fp, tp = fit.pred_joints[fit.matched], test.pred_joints[test.matched]
    own = fit_offsets(fp, fit.gt_joints[fit.matched], fv[fit.matched])
    oracle = fit_offsets(tp, test.gt_joints[test.matched], tv[test.matched])
    truth, valid = test.gt_joints[test.matched], tv[test.matched]
    return {
        "poses": {"fit": int(fit.matched.sum()), "test": int(test.matched.sum())},
        "offsets_mm": {name: [round(float(x), 1) for x in own[t]] for t, name in enumerate(JOINT_TYPES)},
        "oracle_offsets_mm": {
            name: [round(float(x), 1) for x in oracle[t]] for t, name in enumerate(JOINT_TYPES)
        },
        "raw": errors(tp, truth, valid),
        "offsets fitted on --fit-days": errors(corrected(tp, own), truth, valid),
        "offsets fitted on --days (oracle)": errors(corrected(tp, oracle), truth, valid),
    }


def table(result: dict) -> str:
    names = [*JOINT_TYPES, "overall"]
    lines = ["| predictions | " + " | ".join(names) + " |", "| --- |" + " --- |" * len(names)]
    for row in ("raw", "offsets fitted on --fit-days", "offsets fitted on --days (oracle)"):
        lines.append(f"| {row} | " + " | ".join(f"{result[row][n]:.2f}" for n in names) + " |")
    lines.append("")
    lines.append("offsets fitted on --fit-days (forward, outward, up; mm): " + ", ".join(
        f"{n} ({', '.join(f'{x:+.0f}' for x in v)})" for n, v in result["offsets_mm"].items()))  # fmt: skip
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[2], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--annotations", required=True, help="MVOR-format annotation json with annotations3D")
    p.add_argument("--predictions", required=True, help="posenet.evaluation.predict's output for the same file")
    p.add_argument(
        "--fit-days", type=int, nargs="+", default=[1, 2, 3], help="days the offsets are fitted on"
    )
    p.add_argument("--days", type=int, nargs="+", default=[4], help="days the errors are measured on")
    p.add_argument("--json", type=Path, help="also write the numbers here")
    return p


def main(argv: list[str] | None = None) -> dict:
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()
    gt = load_annotations(args.annotations)
    result = measure(gt, json.loads(Path(args.predictions).read_text()), args.fit_days, args.days)
    result.update(machine=machine_line(), date=time.strftime("%Y-%m-%d"), seconds=time.perf_counter() - t0)
    print(table(result))
    print(f"{result['poses']['fit']} poses fitted, {result['poses']['test']} measured; {result['machine']}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
