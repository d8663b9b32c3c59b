"""What keeping streams in Redis adds to a stream frame (``ORPOSE_REDIS_URL``, service.stream_store).

    python -m posenet.synth --out data/seq_eval --sequence --frames 120 --persons 3 --rig mvor --look twin
    python benchmarks/stream_store.py --data data/seq_eval
    python benchmarks/stream_store.py --data data/seq_eval --frames 60 --out store.json

With a shared store, a stream frame's pose turn does three things a single process does not: it takes the stream's
Redis lock, reads the stream's state (``StreamRegistry.pull``) and writes it back with the frame's answer
(``StreamRegistry.push``: pickle, a version-checked Lua write, the last-use set). This benchmark runs exactly those
calls, against a real ``redis-server`` on loopback (Debian's package, started here), around a real tracker
(``pipeline.track.Tracker`` with the served ``ORPOSE_TRACK_*`` defaults and the static-scene model fed the frames'
depth, as the service gives it) that tracks the sequence's ground-truth poses. Per frame it times the lock, the read,
the write and their sum; the tracker's own update is timed beside them (a single process pays it too).

Two placements, side by side in one run:
- ``one replica``: every frame of the stream reaches the same replica (the balancer keeps it there); the read finds
  the version it holds.
- ``two replicas``: the frames alternate between two replicas (the worst placement): every read unpickles the state
  the other replica wrote.

It prints a table of p50 / p95 ms and the state's size, with the machine, and writes ``--out`` as JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the Redis harness starts and stops the server

from redis_harness import redis_server  # noqa: E402

from pipeline.track import Tracker  # noqa: E402
from posenet.data.mvor import MvorDataset, load_annotations, pose_joints  # noqa: E402
from posenet.scene import SceneView  # noqa: E402
from service.app import tracker_config  # noqa: E402
from service.settings import Settings  # noqa: E402
from service.stream_store import RedisStreams  # noqa: E402
from service.streams import Stream, StreamRegistry  # noqa: E402

PARTS = ("lock", "read", "write", "store", "track")


def machine() -> str:
    model = platform.processor() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores, torch {torch.__version__} ({torch.backends.cpu.get_cpu_capability()})"


def frames(data: Path, count: int) -> list[tuple[float, np.ndarray, list[SceneView]]]:
    """(time s, ground-truth joints (N, 10, 3) mm, depth views as the service decodes them) per frame."""
    gt = load_annotations(data / "annotations.json")
    ds = MvorDataset(data, gt, subsample=2, modalities=("depth",))
    poses: dict[int, list] = {}
    for a in gt["annotations3D"]:
        poses.setdefault(a["image_ids"], []).append(a)
    out = []
    for i in tqdm(range(min(count, len(ds))), desc="frames", unit="frame"):
        mv = gt["multiview_images"][i]
        joints = np.array([pose_joints(p, k)[0] for k, p in enumerate(poses.get(mv["id"], []))], float)
        views = [SceneView(None, v.depth, v.camera) for v in ds[i].views]
        out.append((float(mv["timestamp_s"]), joints.reshape(-1, 10, 3), views))
    return out


async def run(url: str, sequence: list, replicas: int, answer_bytes: int) -> list[dict]:
    """Time the shared store's calls per frame, the stream's frames spread over ``replicas`` replicas in turn."""
    config = tracker_config(Settings())
    store = RedisStreams(url, idle_s=60.0)
    registry = StreamRegistry(4, 60.0, lambda: Tracker(config), 1.0, store=store)
    stream_id = f"bench-{replicas}"
    await store.delete(stream_id)
    held = [Stream(stream_id, Tracker(config), 0.0) for _ in range(replicas)]  # each replica's copy
    rng = np.random.default_rng(0)
    rows = []
    for k, (t, joints, views) in enumerate(sequence):
        stream = held[k % replicas]
        t0 = time.perf_counter()
        async with store.hold(stream_id, wait_s=5.0):
            t1 = time.perf_counter()
            await registry.pull(stream)
            t2 = time.perf_counter()
            noisy = joints + rng.normal(0, 15, joints.shape)
            spread = np.full(joints.shape[:2], 30.0)
            stream.tracker.update(noisy, spread, t, np.zeros(len(joints), bool), None, views=views)
            t3 = time.perf_counter()
            stream.frames += 1
            stream.clock, stream.last_time = "client", t
            stream.last_answer = os.urandom(answer_bytes)  # the answer JSON's size; bytes pickle as they are
            await registry.push(stream)
            t4 = time.perf_counter()
        t5 = time.perf_counter()
        lock = (t1 - t0) + (t5 - t4)  # acquire, and release after the write
        rows.append({
            "lock": lock * 1e3, "read": (t2 - t1) * 1e3, "write": (t4 - t3) * 1e3,
            "store": (t5 - t0 - (t3 - t2)) * 1e3, "track": (t3 - t2) * 1e3,
            "state_kb": len(await store.client.hget(store._key(stream_id), "state")) / 1024,
        })  # fmt: skip
    await store.delete(stream_id)
    await store.aclose()
    return rows


def summary(rows: list[dict], skip: int) -> dict:
    rows = rows[skip:]  # the first frames: no tracks yet, the background not yet learnt
    out = {}
    for part in PARTS:
        values = sorted(r[part] for r in rows)
        out[part] = {"p50": statistics.median(values), "p95": values[int(0.95 * (len(values) - 1))]}
    out["state_kb"] = statistics.median(r["state_kb"] for r in rows)
    out["frames"] = len(rows)
    return out


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument(
        "--data", type=Path, default=Path("data/seq_eval"), help="a rendered sequence (see above)"
    )
    parser.add_argument("--frames", type=int, default=120, help="frames of it to stream (default 120)")
    parser.add_argument(
        "--skip", type=int, default=10, help="first frames left out of the figures (default 10)"
    )
    parser.add_argument("--answer-kb", type=float, default=12.0,
                        help="the stored answer's size, KB (a 3-person stream answer is about 12 KB)")  # fmt: skip
    parser.add_argument("--out", type=Path, help="write the figures here as JSON")
    args = parser.parse_args(argv)
    if not (args.data / "annotations.json").exists():
        parser.error(f"{args.data}/annotations.json not found: render the sequence first (see --help)")
    sequence = frames(args.data, args.frames)
    report = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
              "load_before": os.getloadavg()[0], "data": str(args.data), "placements": {}}  # fmt: skip
    with tempfile.TemporaryDirectory() as folder, redis_server(Path(folder)) as url:
        for name, replicas in (("one replica", 1), ("two replicas", 2)):
            rows = asyncio.run(run(url, sequence, replicas, int(args.answer_kb * 1024)))
            report["placements"][name] = summary(rows, args.skip)
    report["load_after"] = os.getloadavg()[0]
    print(
        f"\n{report['machine']}; {report['date']}; load {report['load_before']:.1f} -> {report['load_after']:.1f}"
    )
    print(f"{len(sequence)} frames of {args.data}, first {args.skip} left out; ms p50 / p95")
    print(f"| placement | state KB | {' | '.join(PARTS)} |")
    print(f"| --- | --- | {' | '.join('---' for _ in PARTS)} |")
    for name, s in report["placements"].items():
        cells = " | ".join(f"{s[p]['p50']:.2f} / {s[p]['p95']:.2f}" for p in PARTS)
        print(f"| {name} | {s['state_kb']:.0f} | {cells} |")
    if args.out:
        args.out.write_text(json.dumps(report, indent=2))
    return report


if __name__ == "__main__":
    main()
