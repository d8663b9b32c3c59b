"""Does a stream keep up? A 3-camera stream sent at camera rate through a real uvicorn, in detector mode.

    python benchmarks/stream_rate.py                                   # 15 and 30 fps, 20 s each, the variants
    python benchmarks/stream_rate.py --rates 15 --seconds 10 --variants default int8
    python benchmarks/stream_rate.py --data data/seq_eval --out rate.json

It starts ``uvicorn service.app:app`` per variant and sends the frames of a rendered sequence (default
``data/seq_eval``: 3 cameras, 640x480 PNG, 3 persons) to one stream at a fixed rate, each frame at its tick
whether or not the one before it was answered (as a camera does), with ``timestamp_s`` its tick. The images are
read and encoded once, before timing, so the sender costs the server's cores little. Per variant and rate it
prints the frames answered per second over the run, the frames the stream dropped (``status`` dropped: a newer
frame came while it waited) and any refused, the lag of the answered frames (from the send to the answer, p50 /
p95 / max), and the server's stages (p50 ms: decode, detect, match, pose, track, the wait for the stream's
turns), with the machine line from ``/model`` and the load average before and after.

Variants (one server each, side by side in one run): ``default`` (ORPOSE_* defaults, ``ORPOSE_THREADS=2``),
``threads1`` (one intra-op thread per stage: the front and the pose stage then each keep a core), ``int8``
(``ORPOSE_PRECISION=int8``), ``jpeg`` (the default server, colour sent as JPEG q95 and depth as fast PNG,
``service.client.Transport``), ``threads1-jpeg`` (both), ``read`` and ``read-jpeg`` (the default server, each view
sent at its read size, ``service.client --send-size read``, colour as PNG or JPEG q95).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the test harness starts and stops the server

from service_harness import Server  # noqa: E402

from posenet.data.mvor import MvorDataset  # noqa: E402
from service.client import Transport, read_size_of, scene_request  # noqa: E402

VARIANTS = {  # name: (the server's environment, the transport)
    "default": ({}, Transport()),
    "threads1": ({"ORPOSE_THREADS": "1"}, Transport()),
    "int8": ({"ORPOSE_PRECISION": "int8"}, Transport()),
    "jpeg": ({}, Transport("jpeg", "png-fast")),
    "threads1-jpeg": ({"ORPOSE_THREADS": "1"}, Transport("jpeg", "png-fast")),
    "read": ({}, Transport()),  # at the read size (below)
    "read-jpeg": ({}, Transport("jpeg")),
}
AT_READ_SIZE = {"read", "read-jpeg"}  # views sent at GET /model's read_size (service.client --send-size read)
STAGES = ("decode", "detect", "match", "pose", "track", "wait")


def forms(root: Path, frames: int, transport: Transport) -> list[tuple[dict, list]]:
    """The first ``frames`` frames of the dataset at ``root`` as detector-mode forms (scene JSON, file parts)."""
    ds = MvorDataset(None, root / "annotations.json")
    out = []
    for i in range(min(frames, len(ds))):
        scene, files = scene_request(ds[i], root, False, transport)
        out.append(({"scene": json.dumps(scene)}, files))
    return out


def send_stream(url: str, frames: list, fps: float, seconds: float, stream: str) -> dict:
    """Send ``frames`` (cycled) to ``stream`` at ``fps`` for ``seconds``, each at its tick; the answers' record."""
    n = int(round(fps * seconds))
    records: list[dict | None] = [None] * n
    client = httpx.Client(base_url=url, timeout=60, limits=httpx.Limits(max_connections=64))

    def post(k: int, sent: float) -> None:
        data, files = frames[k % len(frames)]
        r = client.post(f"/streams/{stream}/frames", data={**data, "timestamp_s": repr(k / fps)}, files=files)
        body = r.json()
        records[k] = {
            "k": k,
            "sent": sent,
            "answered": time.perf_counter(),
            "status": r.status_code,
            "body": body,
        }

    threads = []
    t0 = time.perf_counter()
    for k in range(n):
        wait = t0 + k / fps - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        t = threading.Thread(target=post, args=(k, time.perf_counter()), daemon=True)
        t.start()
        threads.append(t)
    for t in threads:
        t.join()
    span = max(r["answered"] for r in records) - t0
    client.delete(f"/streams/{stream}")
    client.close()
    return summarise(records, span, fps)


def summarise(records: list[dict], span_s: float, fps: float) -> dict:
    answered = [r for r in records if r["status"] == 200 and r["body"].get("status") == "answered"]
    dropped = [r for r in records if r["status"] == 200 and r["body"].get("status") == "dropped"]
    refused = [r for r in records if r["status"] != 200]
    lag = [(r["answered"] - r["sent"]) * 1e3 for r in answered]
    stages = (
        {s: statistics.median(r["body"]["timings"][s] for r in answered) for s in STAGES} if answered else {}
    )
    return {
        "sent_fps": fps,
        "sent": len(records),
        "answered": len(answered),
        "answered_fps": len(answered) / span_s,
        "dropped": len(dropped),
        "refused": {str(s): sum(r["status"] == s for r in refused) for s in {r["status"] for r in refused}},
        "lag_ms": {
            "p50": float(np.percentile(lag, 50)),
            "p95": float(np.percentile(lag, 95)),
            "max": max(lag),
        }
        if lag
        else {},
        "stages_ms_p50": stages,
        "persons_p50": statistics.median(len(r["body"]["persons"]) for r in answered) if answered else 0,
    }


def run_variant(name: str, root: Path, rates: list[float], seconds: float, frames: int, threads: int) -> dict:
    env, transport = VARIANTS[name]
    env = {"ORPOSE_THREADS": str(threads), "ORPOSE_MAX_IN_FLIGHT": "16", **env}
    with Server(env, startup_s=900) as url, httpx.Client(base_url=url, timeout=60) as client:
        model = client.get("/model").json()
        if name in AT_READ_SIZE:
            transport = dataclasses.replace(transport, read_size=read_size_of(model))
        prepared = forms(root, frames, transport)
        for k in range(3):  # warm-up: first calls compile kernels
            client.post(
                "/streams/warm/frames", data={**prepared[k][0], "timestamp_s": str(k)}, files=prepared[k][1]
            )
        client.delete("/streams/warm")
        out = {"model": model, "load_before": os.getloadavg()[0], "rates": {}}
        for fps in rates:
            out["rates"][str(fps)] = send_stream(url, prepared, fps, seconds, f"rate-{fps:g}")
        out["load_after"] = os.getloadavg()[0]
    return out


def format_table(results: dict) -> str:
    from posenet.runtime.execution import machine_line

    first = next(iter(results.values()))
    lines = [machine_line(first["model"]["machine"]), ""]
    head = (f"{'variant':<15}{'runtime':<34}{'sent fps':>9}{'answered/s':>11}{'dropped':>8}{'refused':>8}"
            f"{'lag p50':>9}{'p95':>8}{'max':>8}" + "".join(f"{s:>8}" for s in STAGES) + f"{'load':>11}")  # fmt: skip
    lines += [head + "   (ms; stages: server p50)", "-" * len(head)]
    for name, r in results.items():
        runtime = ", ".join(f"{x['network'][:3]} {x['precision']}" for x in r["model"]["runtime"])
        for fps, s in r["rates"].items():
            lag = s["lag_ms"]
            stages = "".join(f"{s['stages_ms_p50'].get(x, float('nan')):>8.1f}" for x in STAGES)
            refused = sum(s["refused"].values())
            lines.append(
                f"{name:<15}{runtime:<34}{float(fps):>9.0f}{s['answered_fps']:>11.2f}{s['dropped']:>8}{refused:>8}"
                f"{lag.get('p50', float('nan')):>9.0f}{lag.get('p95', float('nan')):>8.0f}"
                f"{lag.get('max', float('nan')):>8.0f}{stages}{r['load_before']:>6.1f}/{r['load_after']:<4.1f}"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--data", type=Path, default=REPO / "data" / "seq_eval",
                        help="an MVOR-format sequence (default: %(default)s; posenet.synth --sequence renders one)")  # fmt: skip
    parser.add_argument("--rates", type=float, nargs="+", default=[15.0, 30.0], help="frames per second sent")
    parser.add_argument("--seconds", type=float, default=20.0, help="how long each rate is sent")
    parser.add_argument("--frames", type=int, default=60, help="distinct frames, sent in a loop")
    parser.add_argument("--threads", type=int, default=2, help="ORPOSE_THREADS of the server (threads1: 1)")
    parser.add_argument("--variants", nargs="+", choices=sorted(VARIANTS), default=list(VARIANTS))
    parser.add_argument("--out", type=Path, help="also write the results as JSON here")
    args = parser.parse_args(argv)
    if not (args.data / "annotations.json").is_file():
        parser.error(f"{args.data}/annotations.json not found: render a sequence with python -m posenet.synth "
                     "--sequence --out DIR, or pass --data")  # fmt: skip
    if min(args.rates) <= 0 or args.seconds <= 0:
        parser.error("--rates and --seconds must be positive")
    results = {}
    for name in args.variants:
        results[name] = run_variant(name, args.data, args.rates, args.seconds, args.frames, args.threads)
        print(f"{name} done", file=sys.stderr, flush=True)
    print(format_table(results))
    if args.out:
        args.out.write_text(json.dumps(results, indent=1))
    return results


if __name__ == "__main__":
    main()
