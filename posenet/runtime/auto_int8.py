"""``auto`` precision on OpenVINO: int8 where this machine runs it measurably faster and its accuracy cost is known.

int8 trades accuracy for speed, so ``auto`` picks it only where both sides are known:

- **the cost**, measured offline for these very weights (``KNOWN_COST``: day-4 MPJPE and detector AP50 against
  the float graph, ``benchmarks/backend_accuracy.py``, reference boxes, on the twin and on the unseen alt look),
  and within the bounds that every accuracy claim of the project uses (``MAX_MPJPE_CM``, ``MAX_AP50``). A graph of
  other weights (a user's checkpoint, the tests' random ones) has no recorded cost: ``auto`` never quantizes it;
- **the gain**, measured here, at start-up, on this machine's CPU and thread count: the float graph (bf16 where
  the CPU computes bf16 natively, else float32) against the int8 graph on a frame's batch (``FRAME_BATCH``), in
  alternating rounds; int8 wins when it is at least ``MIN_SPEEDUP`` faster. The machine that trained a checkpoint
  never decides: only the one that runs it.

The int8 graph is built at the first start (``posenet.runtime.quantize``: the calibration scenes are rendered and
run, a minute or two) unless ``python -m service.export --int8`` built it ahead; the decision is cached beside the
graphs (``decision_path``: per graph, CPU, capability, thread count and OpenVINO version), so later starts only
read it. Any failure keeps the float graph, and the precision's reason says why: a start-up never crashes on it.
"""

from __future__ import annotations

import hashlib
import json
import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posenet.runtime.execution import Precision, cpu_model, machine

log = logging.getLogger(__name__)

# The accuracy bounds of every "accuracy unchanged" claim: day-4 MPJPE within 0.1 cm, AP50 within 0.005.
MAX_MPJPE_CM = 0.1
MAX_AP50 = 0.005
# int8 must beat the float graph by this factor: below it the noise of a shared machine could decide.
MIN_SPEEDUP = 1.15
# Inputs per call of a 4-person, 3-view frame: a crop per box (about 12 detected boxes) and an image per view.
FRAME_BATCH = {"unet": 12, "detector": 3}
ROUNDS = 7


@dataclass(frozen=True)
class Cost:
    """int8's measured accuracy cost for one graph: the worst day-4 MPJPE (cm) and AP50 change over the twin and
    the unseen alt look, and where it was measured."""

    mpjpe_cm: float
    ap50: float
    source: str

    @property
    def small(self) -> bool:
        return self.mpjpe_cm <= MAX_MPJPE_CM and -self.ap50 <= MAX_AP50


# Keyed by the float graph's name (``posenet.runtime.graphs.export_onnx``: a hash of the weights, the config, torch
# and the exporter): the shipped weights. The pose network's U-Net moves MPJPE, the detector AP50 (its boxes then
# move MPJPE in detector mode, which the pose network's row already includes with reference boxes).
KNOWN_COST = {
    # posenet/weights/frames (2026-12-08: the default weights trained 85 more minutes with the mesh-body sets with
    # hard negatives; an option for single frames), the same 36 scenes: day 4 twin 4.529 -> 4.548 cm, alt 6.368 ->
    # 6.372, alt-mesh 5.838 -> 5.857 (OpenVINO bf16 -> int8, benchmarks/backend_accuracy.py; benchmarks/RESULTS.md,
    # "Per-frame pose weights", 2026-12-08).
    "unet-b83264a74cc10401eb26": Cost(
        0.019, 0.0, "benchmarks/RESULTS.md 2026-12-08, frames weights, day 4 twin, alt and alt-mesh"
    ),
    # posenet/weights/default (2026-12-07, fine-tuned at 64x64 crops), the same 36 scenes: day 4 twin 4.561 -> 4.592
    # cm, alt 6.482 -> 6.507, alt-mesh 6.350 -> 6.365 (benchmarks/RESULTS.md, "64x64 crops", 2026-12-07).
    "unet-63560a736fd45ba97c3b": Cost(
        0.031, 0.0, "benchmarks/RESULTS.md 2026-12-07, 64x64 weights, day 4 twin, alt and alt-mesh"
    ),
    # the 96x96 mesh-body weights (commit 7517ca7, 2026-12-07), 36 random-rig calibration scenes: day 4 twin
    # 4.56 -> 4.57 cm, alt 6.69 -> 6.77, alt-mesh 6.69 -> 6.74 (benchmarks/RESULTS.md, "int8 for the mesh-body pose
    # weights", 2026-12-07).
    "unet-b16460610c56df806233": Cost(
        0.073, 0.0, "benchmarks/RESULTS.md 2026-12-07, day 4 twin, alt and alt-mesh"
    ),
    # detector/weights/default of commit 716bd7b (2026-12-06, fine-tuned with hard negatives), the same scenes:
    # day-4 AP50 twin 0.966 -> 0.968, alt 0.953 -> 0.954, alt-mesh 0.950 -> 0.949 (benchmarks/RESULTS.md, "int8
    # for the hard-negative detector"). With reference boxes the detector moves no MPJPE (0.0 here); the pose
    # network's row covers the U-Net.
    "detector-c6b90ae9889618b1640b": Cost(
        0.0, -0.001, "benchmarks/RESULTS.md 2026-12-06, day 4 twin, alt and alt-mesh"
    ),
    # The depth-only pair (posenet/weights/depth, detector/weights/depth; 2026-12-07), the same scenes: day 4 twin
    # 5.276 -> 5.320 cm, alt 7.421 -> 7.517, alt-mesh 6.718 -> 6.767; AP50 0.948 -> 0.947, 0.912 -> 0.916, 0.914 ->
    # 0.916 (benchmarks/RESULTS.md, "Depth only against colour + depth").
    "unet-44c61e0ce84329b26e11": Cost(
        0.096, 0.0, "benchmarks/RESULTS.md 2026-12-07, depth-only weights, day 4 twin, alt and alt-mesh"
    ),
    "detector-c913caa690b03d7b5442": Cost(
        0.0, -0.001, "benchmarks/RESULTS.md 2026-12-07, depth-only weights, day 4 twin, alt and alt-mesh"
    ),
}


def decision_path(graph: Path, threads: int) -> Path:
    """Where the decision for ``graph`` on this machine at ``threads`` threads is cached."""
    m = machine()
    key = f"{cpu_model()}|{m['torch_capability']}|{m['openvino']}|{threads}"
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    return graph.with_name(f"{graph.stem}-auto-{digest}.json")


def _batch(runner) -> dict[str, np.ndarray]:
    """Random inputs of a frame's size for ``runner``'s graph (the graphs' sizes are fixed but for the batch)."""
    name = runner.path.stem.split("-")[0]
    rng = np.random.default_rng(0)
    out = {}
    for port, dims in runner.input_shapes.items():
        shape = [FRAME_BATCH.get(name, 4) if d is None else d for d in dims]
        out[port] = rng.standard_normal(shape).astype(np.float32)
    return out


def time_runners(runners: list, rounds: int = ROUNDS) -> list[float]:
    """The median ms of one call of each runner on a frame's batch, measured in alternating rounds (so that a
    change in the machine's load falls on all of them alike)."""
    import torch

    inputs = {k: torch.from_numpy(v) for k, v in _batch(runners[0]).items()}
    for r in runners:  # warm-up: first calls compile kernels
        r(**inputs)
        r(**inputs)
    times: list[list[float]] = [[] for _ in runners]
    for _ in range(rounds):
        for r, ts in zip(runners, times, strict=True):
            t0 = time.perf_counter()
            r(**inputs)
            ts.append((time.perf_counter() - t0) * 1e3)
    return [statistics.median(ts) for ts in times]


def choose(
    graph: Path,
    threads: int,
    precision: Precision,
    float_runner: Callable[[], object],
    int8_runner: Callable[[], object],
) -> tuple[object, Precision]:
    """The runner ``auto`` runs ``graph`` with, and its precision with the reason (module docstring), which the
    runner carries too.

    ``precision``: the float precision ``auto`` resolved (bf16 or fp32); ``float_runner()`` and ``int8_runner()``
    build the two runners (the second quantizes the graph when it is not cached yet)."""
    runner, chosen = _choose(graph, threads, precision, float_runner, int8_runner)
    runner.precision = chosen
    return runner, chosen


def _choose(graph, threads, precision, float_runner, int8_runner):
    cost = KNOWN_COST.get(graph.stem)
    if cost is None:
        return float_runner(), _keep(precision, "int8's accuracy cost for these weights is not on record")
    if not cost.small:
        return float_runner(), _keep(
            precision, f"int8 costs {cost.mpjpe_cm:+.2f} cm / {cost.ap50:+.3f} AP50 here"
        )
    path = decision_path(graph, threads)
    try:
        decided = json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError):
        decided = None
    try:
        if decided is None:
            fast, slow = int8_runner(), float_runner()
            int8_ms, float_ms = time_runners([fast, slow])
            decided = {"int8_ms": int8_ms, "float_ms": float_ms, "float": precision.name, "threads": threads,
                       "measured": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}  # fmt: skip
            path.write_text(json.dumps(decided, indent=1))
        else:
            fast = slow = None
        speedup = decided["float_ms"] / decided["int8_ms"]
        measured = (
            f"measured on this machine ({decided['measured']}, {threads} threads, a frame's batch): int8 "
            f"{decided['int8_ms']:.1f} ms against {decided['float']} {decided['float_ms']:.1f} ms ({speedup:.2f}x)"
        )
        if speedup >= MIN_SPEEDUP:
            reason = (
                f"auto: int8, {measured}, at least the {MIN_SPEEDUP}x auto asks for; its accuracy cost is known "
                f"and small ({cost.mpjpe_cm:+.2f} cm day-4 MPJPE, {cost.ap50:+.3f} AP50; {cost.source})"
            )
            return fast or int8_runner(), Precision("int8", reason, auto=True)
        return slow or float_runner(), _keep(precision, f"{measured}, below the {MIN_SPEEDUP}x auto asks for")
    except (Exception, SystemExit) as exc:  # int8 must never stop a start: the float graph runs
        log.warning("auto int8 failed, running %s: %s", precision.name, exc)
        return float_runner(), _keep(
            precision, f"int8 could not be built or measured ({type(exc).__name__}: {exc})"
        )


def _keep(precision: Precision, why: str) -> Precision:
    """``precision`` (the float one) with why ``auto`` did not take int8."""
    return Precision(precision.name, f"{precision.reason}; not int8: {why}", auto=True)
