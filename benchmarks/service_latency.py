"""Latency and throughput of the service through real HTTP, per stage, on 3 views of 640x480.

    python benchmarks/service_latency.py                                  # the shipped weights
    python benchmarks/service_latency.py --pose-checkpoint RUN/best --detector-checkpoint DET
    python benchmarks/service_latency.py --tiny                           # random-init models (plumbing only)

It starts ``uvicorn service.app:app`` in a subprocess and posts frames of an MVOR-format dataset (by default
the first 12 frames of the MVOR twin, rendered into a temporary folder with ``posenet.synth``). Four
configurations: a frame with 1 person and one with 3 persons, each with reference boxes (detector off) and
with the detector on. For each it reports the client-side latency p50/p95 over ``--requests`` sequential
requests and the server's per-stage breakdown (decode, detect, match, pose, encode), then the throughput at
concurrency 1 and 4 (detector on, 3-person frame), and the server's peak RSS. ``--out`` also writes JSON,
``--plot`` a picture of the variants' stages (``--replot`` draws it again from ``--out`` files).

``--variants`` compares ways of running the same weights side by side in one run, one server each:
``default`` (the shipped settings: backend and precision ``auto``), ``default-jpeg`` (the same server, colour
sent as JPEG q95 and depth as fast PNG), ``default-read`` and ``default-read-jpeg`` (the views sent at the
server's read size, ``service.client --send-size read``, colour as PNG or JPEG q95), ``torch-bf16`` (torch with bf16 forced: what the shipped configs did
before precision became ``auto``),
``torch`` (precision ``auto``), ``onnxruntime`` and ``openvino``. Each variant's machine line comes from the
server's ``/model``. To see an AVX2-only CPU on a newer one, cap torch's instruction sets (the runtimes are
not capped by these)::

    ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 python benchmarks/service_latency.py --variants torch-bf16 torch

``--servers NAME=URL ...`` compares servers that are already running instead (two commits of the code, two
settings), on the 3-person frame in detector mode, sent as recorded and at the read size. Their requests are
interleaved, one to each server in turn (the order flipped every round), so that a shared machine's load falls on
all of them alike: runs of one server after the other on the development host differed by up to 40 %. For two
commits::

    git worktree add /tmp/before HEAD~1
    (cd /tmp/before && PYTHONPATH=. uvicorn service.app:app --port 8001 &)
    uvicorn service.app:app --port 8002 &
    python benchmarks/service_latency.py --data data/mvor_altmesh4 --servers before=http://127.0.0.1:8001 \
        after=http://127.0.0.1:8002 --requests 150
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the test harness starts and stops the server

from service_harness import Server, tiny_checkpoints  # noqa: E402

from pipeline.matching import match_boxes  # noqa: E402
from posenet.data.images import read_depth  # noqa: E402
from posenet.data.mvor import MvorDataset  # noqa: E402
from service.client import Transport, read_size_of, scene_request  # noqa: E402

MVOR_JSON = REPO.parent / "shared" / "mvor" / "camma_mvor_2018.json"
STAGES = ("decode", "detect", "match", "pose", "encode", "total")
VARIANTS = {  # name: the server's environment
    "default": {},  # the settings as shipped: backend auto, precision auto (int8 where auto_int8 measures it)
    "torch-bf16": {"ORPOSE_BACKEND": "torch", "ORPOSE_PRECISION": "bf16"},
    "torch": {"ORPOSE_BACKEND": "torch", "ORPOSE_PRECISION": "auto"},
    "onnxruntime": {"ORPOSE_BACKEND": "onnxruntime", "ORPOSE_PRECISION": "auto"},
    "openvino": {"ORPOSE_BACKEND": "openvino", "ORPOSE_PRECISION": "auto"},
    "openvino-bf16": {"ORPOSE_BACKEND": "openvino", "ORPOSE_PRECISION": "bf16"},  # float forced (native bf16)
    "openvino-fp32": {"ORPOSE_BACKEND": "openvino", "ORPOSE_PRECISION": "fp32"},  # float forced (AVX2-only)
    "openvino-int8": {"ORPOSE_BACKEND": "openvino", "ORPOSE_PRECISION": "int8"},
    "default-jpeg": {},  # the default server; colour sent as JPEG q95 and depth as fast PNG
    "default-read": {},  # the default server; views sent at its read size (PNG colour: the same answers)
    "default-read-jpeg": {},  # the same, colour as JPEG q95
}
# Variants that send the images otherwise than --color-format / --depth-format say (service.client.Transport;
# "read": at GET /model's read_size, as `service.client --send-size read`).
TRANSPORTS = {
    "default-jpeg": ("jpeg", "png-fast", False),
    "default-read": ("png", "png", True),
    "default-read-jpeg": ("jpeg", "png", True),
}


def render_twin(folder: Path, annotations: Path, frames: int) -> Path:
    cmd = [sys.executable, "-m", "posenet.synth", "--out", str(folder), "--from-mvor", str(annotations),
           "--limit", str(frames), "--quiet"]  # fmt: skip
    subprocess.run(cmd, cwd=REPO, check=True, stdout=subprocess.DEVNULL)
    return folder


def groups_of(sample, root: Path) -> list[list[int]]:
    """A frame's annotated boxes grouped into persons by the 3D matcher: per person, per view an index."""
    depths = [read_depth(root / v.file_name.replace("/color/", "/depth/")) for v in sample.views]
    groups = match_boxes([v.boxes for v in sample.views], depths, [v.camera for v in sample.views])
    return [list(g.indices) for g in groups]


def reference_request(
    sample, root: Path, persons: int, transport: Transport | None = None
) -> tuple[dict, list]:
    """A request with reference boxes for exactly ``persons`` persons (the largest groups of the frame)."""
    scene, files = scene_request(sample, root, False, transport)
    groups = sorted(groups_of(sample, root), key=lambda g: -sum(i >= 0 for i in g))[:persons]
    if len(groups) < persons:
        raise SystemExit(f"frame {sample.id} has only {len(groups)} persons, {persons} needed")
    for v, view in enumerate(scene["views"]):
        view["boxes"] = [sample.views[v].boxes[g[v]].tolist() for g in groups if g[v] >= 0]
        view["person_ids"] = [p for p, g in enumerate(groups) if g[v] >= 0]
    return scene, files


def pick_frames(ds: MvorDataset, root: Path) -> dict[int, int]:
    """Dataset indices of a frame with 1 person and one with at least 3 (by the matcher's groups)."""
    found = {}
    for i in range(len(ds)):
        n = len(groups_of(ds[i], root))
        if n == 1 and 1 not in found:
            found[1] = i
        if n >= 3 and 3 not in found:
            found[3] = i
    if len(found) < 2:
        raise SystemExit(f"need a 1-person and a 3-person frame in the dataset, found {found}")
    return found


def post(client: httpx.Client, scene: dict, files: list) -> tuple[float, dict]:
    t0 = time.perf_counter()
    r = client.post("/scenes", data={"scene": json.dumps(scene)}, files=files)
    latency = (time.perf_counter() - t0) * 1e3
    if r.status_code != 200:
        raise SystemExit(f"request failed: {r.status_code} {r.text}")
    return latency, r.json()


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def measure(client, scene, files, requests: int, warmup: int = 2) -> dict:
    for _ in range(warmup):
        post(client, scene, files)
    latencies, stages, persons = [], {s: [] for s in STAGES}, []
    for _ in range(requests):
        latency, out = post(client, scene, files)
        latencies.append(latency)
        persons.append(len(out["persons"]))
        for s in STAGES:
            stages[s].append(out["timings"][s])
    return {
        "latency_ms": {"p50": pct(latencies, 50), "p95": pct(latencies, 95)},
        "stages_ms_p50": {s: pct(v, 50) for s, v in stages.items()},
        "persons": statistics.mode(persons),
    }


def throughput(url: str, scene, files, concurrency: int, requests: int) -> float:
    limits = httpx.Limits(max_connections=concurrency)
    with (
        httpx.Client(base_url=url, limits=limits, timeout=300) as client,
        ThreadPoolExecutor(concurrency) as pool,
    ):
        t0 = time.perf_counter()
        list(pool.map(lambda _: post(client, scene, files), range(requests)))
        return requests / (time.perf_counter() - t0)


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def interleaved(urls: dict[str, str], ds: MvorDataset, root: Path, index: int, requests: int) -> dict:
    """``--servers``: frame ``index`` in detector mode posted to every server in turn, as recorded (PNG) and at the
    read size (PNG), ``requests`` times each: per transport and server the client's p25 / p50 / p75 and the server's
    stage p50s."""
    clients = {name: httpx.Client(base_url=url, timeout=300) for name, url in urls.items()}
    try:
        models = {name: c.get("/model").json() for name, c in clients.items()}
        sizes = {tuple(m["read_size"] or ()) for m in models.values()}
        if len(sizes) != 1:
            raise SystemExit(f"the servers read views at different sizes {sorted(sizes)}: not one frame for all")
        out = {"frame": ds[index].id, "machines": {n: m["machine"] for n, m in models.items()},
               "runtime": {n: m["runtime"] for n, m in models.items()}, "transports": {}}  # fmt: skip
        for transport_name, transport in (
            ("recorded", Transport("png", "png")),
            ("read", Transport("png", "png", read_size=read_size_of(next(iter(models.values()))))),
        ):
            scene, files = scene_request(ds[index], root, False, transport)
            for c in clients.values():  # warm-up
                post(c, scene, files)
                post(c, scene, files)
            got = {name: {"latency": [], **{s: [] for s in STAGES}} for name in clients}
            order = list(clients)
            for i in range(requests):
                for name in order if i % 2 == 0 else order[::-1]:
                    latency, answer = post(clients[name], scene, files)
                    got[name]["latency"].append(latency)
                    for s in STAGES:
                        got[name][s].append(answer["timings"][s])
            out["transports"][transport_name] = {
                name: {
                    "latency_ms": {q: pct(g["latency"], int(q[1:])) for q in ("p25", "p50", "p75")},
                    "stages_ms_p50": {s: pct(g[s], 50) for s in STAGES},
                    "requests": requests,
                }
                for name, g in got.items()
            }
    finally:
        for c in clients.values():
            c.close()
    return out


def plot_interleaved(result: dict, out: Path) -> None:
    """``--servers --plot``: :func:`plot_stages`' bars, one per transport and server."""
    rows = [
        (f"{name}, {transport}", {"model": {"machine": result["machines"][name]}, "configs": {"3p_detector": r}})
        for transport, servers in result["transports"].items()
        for name, r in servers.items()
    ]
    plot_stages(rows, out)


def format_interleaved(result: dict) -> str:
    head = f"{'sent as':<10}{'server':<14}{'p25':>8}{'p50':>8}{'p75':>8}" + "".join(f"{s:>9}" for s in STAGES)
    lines = [head, "-" * len(head)]
    for transport, servers in result["transports"].items():
        for name, r in servers.items():
            lat, st = r["latency_ms"], r["stages_ms_p50"]
            lines.append(f"{transport:<10}{name:<14}{lat['p25']:>8.1f}{lat['p50']:>8.1f}{lat['p75']:>8.1f}"
                         + "".join(f"{st[s]:>9.1f}" for s in STAGES))  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], epilog=__doc__.split("\n\n", 1)[1],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--pose-checkpoint", help="pose network checkpoint (default: the shipped weights)")
    parser.add_argument("--detector-checkpoint", help="detector checkpoint (default: the shipped weights)")
    parser.add_argument(
        "--tiny", action="store_true", help="random-init models instead (measures the plumbing)"
    )
    parser.add_argument("--data", type=Path, help="MVOR-format dataset (default: render 12 MVOR-twin frames)")
    parser.add_argument(
        "--annotations", type=Path, help="its annotation json (default: DATA/annotations.json)"
    )
    parser.add_argument("--mvor", type=Path, default=MVOR_JSON, help="MVOR json for the twin render")
    parser.add_argument("--requests", type=int, default=20, help="timed requests per configuration")
    parser.add_argument("--threads", type=int, default=2, help="ORPOSE_THREADS of the server")
    parser.add_argument("--device", default="cpu", help="ORPOSE_DEVICE of the server")
    parser.add_argument(
        "--variants", nargs="+", choices=sorted(VARIANTS), default=list(VARIANTS),
        help="ways of running the models, one server each (default: all)",
    )  # fmt: skip
    parser.add_argument(
        "--color-format", choices=("png", "jpeg"), default="png",
        help="colour as the dataset stores it (png) or re-encoded as JPEG q95, as cameras stream it",
    )  # fmt: skip
    parser.add_argument(
        "--depth-format", choices=("png", "png-fast"), default="png",
        help="depth as the dataset stores it (png) or re-written losslessly as the renderer now writes depth "
        "(png-fast: PNG filter NONE, zlib level 3), as a camera-side writer can send it",
    )  # fmt: skip
    parser.add_argument(
        "--servers", nargs="+", metavar="NAME=URL",
        help="instead of starting servers: compare these running ones, their requests interleaved (see above)",
    )  # fmt: skip
    parser.add_argument("--out", type=Path, help="also write the results as JSON here")
    parser.add_argument(
        "--plot", type=Path,
        help="also draw the variants' 3-person detector frame as stacked server stages beside the client p50 (PNG; "
        "with --servers one bar per transport and server)",
    )  # fmt: skip
    parser.add_argument(
        "--replot", type=Path, nargs="+", metavar="JSON",
        help="instead of measuring: draw --plot from these --out files (their variants side by side, in order)",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if args.replot:
        if not args.plot:
            raise SystemExit("--replot draws a picture: give --plot OUT.png")
        runs = [(p.stem, json.loads(p.read_text())) for p in args.replot]
        named = [
            (f"{name} ({stem})" if len(runs) > 1 else name, r)
            for stem, run in runs
            for name, r in run["variants"].items()
        ]
        plot_stages(named, args.plot)
        return {}
    if args.servers:
        if args.data is None:
            raise SystemExit("--servers needs --data: the frame goes to servers that are already running")
        urls = dict(pair.split("=", 1) for pair in args.servers)
        ds = MvorDataset(None, args.annotations or args.data / "annotations.json")
        result = interleaved(urls, ds, args.data, pick_frames(ds, args.data)[3], args.requests)
        print(f"frame {result['frame']}, detector mode; client ms (p25 / p50 / p75) and server stage p50s")
        from posenet.runtime.execution import machine_line

        for name, info in result["machines"].items():
            print(f"{name}: {machine_line(info)}")
        print(format_interleaved(result))
        if args.plot:
            plot_interleaved(result, args.plot)
        if args.out:
            args.out.write_text(json.dumps(result, indent=2))
        return result

    results = {"threads": args.threads, "color_format": args.color_format, "depth_format": args.depth_format,
               "variants": {}}  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        root = args.data or render_twin(tmp / "twin", args.mvor, 12)
        ds = MvorDataset(None, args.annotations or root / "annotations.json")
        pose, det = (
            tiny_checkpoints(tmp / "ckpt") if args.tiny else (args.pose_checkpoint, args.detector_checkpoint)
        )
        frames = pick_frames(ds, root)
        for variant in args.variants:
            env = {"ORPOSE_THREADS": str(args.threads), "ORPOSE_DEVICE": args.device, "ORPOSE_MAX_IN_FLIGHT": "16",
                   **VARIANTS[variant]}  # fmt: skip
            env.update({k: str(v) for k, v in (("ORPOSE_POSE_CHECKPOINT", pose),
                                                ("ORPOSE_DETECTOR_CHECKPOINT", det)) if v})  # fmt: skip
            results["variants"][variant] = run_variant(
                env,
                ds,
                root,
                frames,
                args.requests,
                *TRANSPORTS.get(variant, (args.color_format, args.depth_format, False)),
            )
            print(format_variant(variant, results["variants"][variant]), flush=True)
    print(side_by_side(results["variants"]))
    if args.out:
        args.out.write_text(json.dumps(results, indent=2))
    if args.plot:
        plot_stages(list(results["variants"].items()), args.plot)
    return results


def plot_stages(variants: list[tuple[str, dict]], out: Path, config: str = "3p_detector") -> None:
    """One horizontal bar per ``(name, result)``: the server's stage p50s stacked (decode, detect, match, pose,
    encode), and a tick at the client's p50 (the rest is HTTP and the client), with the machine line as title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from posenet.runtime.execution import machine_line

    stages = ("decode", "detect", "match", "pose", "encode")
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")
    fig, ax = plt.subplots(figsize=(8, 0.5 * len(variants) + 2.0))
    for row, (_, r) in enumerate(variants):
        c = r["configs"][config]
        left = 0.0
        for stage, colour in zip(stages, colours, strict=True):
            width = c["stages_ms_p50"][stage]
            ax.barh(row, width, left=left, color=colour, label=stage if row == 0 else None)
            left += width
        p50 = c["latency_ms"]["p50"]
        ax.plot(
            [p50, p50], [row - 0.4, row + 0.4], color="black", lw=2, label="client p50" if row == 0 else None
        )
        ax.text(p50 + 1, row, f"{p50:.0f} ms", va="center", fontsize=8)
    ax.set_yticks(range(len(variants)), [name for name, _ in variants], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel(f"ms per frame ({config.replace('_', ', ')}; server stages: p50 each)")
    machines = dict.fromkeys(machine_line(r["model"]["machine"]) for _, r in variants)
    fig.suptitle("\n".join(textwrap.fill(m, 110) for m in machines), fontsize=7)
    ax.legend(fontsize=7, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.1 - 0.3 / len(variants)))
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def side_by_side(variants: dict, config: str = "3p_detector") -> str:
    """The variants' ``config`` rows in one table: client p50 / p95 and the server's stages (p50 ms)."""
    head = f"{'variant (' + config + ')':<28}{'runtime':<34}{'p50 ms':>8}{'p95 ms':>8}" + "".join(
        f"{s:>9}" for s in STAGES
    )
    lines = [head, "-" * len(head)]
    for name, r in variants.items():
        c = r["configs"][config]
        runtime = ", ".join(
            f"{x['network'][:3]} {x['backend'][:8]} {x['precision']}" for x in r["model"]["runtime"]
        )
        lines.append(
            f"{name:<28}{runtime:<34}{c['latency_ms']['p50']:>8.1f}{c['latency_ms']['p95']:>8.1f}"
            + "".join(f"{c['stages_ms_p50'][s]:>9.1f}" for s in STAGES)
        )
    return "\n".join(lines)


def run_variant(
    env: dict,
    ds: MvorDataset,
    root: Path,
    frames: dict[int, int],
    requests: int,
    color_format: str = "png",
    depth_format: str = "png",
    at_read_size: bool = False,
) -> dict:
    server = Server(env)
    with server as url, httpx.Client(base_url=url, timeout=300) as client:
        model = client.get("/model").json()
        transport = Transport(
            color_format, depth_format, read_size=read_size_of(model) if at_read_size else None
        )
        result = {"model": model, "configs": {}}
        for persons, index in frames.items():
            sample = ds[index]
            for mode in ("reference_boxes", "detector"):
                scene, files = (reference_request(sample, root, persons, transport) if mode == "reference_boxes"
                                else scene_request(sample, root, False, transport))  # fmt: skip
                result["configs"][f"{persons}p_{mode}"] = {
                    "frame": sample.id,
                    **measure(client, scene, files, requests),
                }
        scene, files = scene_request(ds[frames[3]], root, False, transport)
        result["throughput_fps"] = {
            str(c): throughput(url, scene, files, c, max(8, requests)) for c in (1, 4)
        }
        result["peak_rss_mb"] = peak_rss_mb(server.proc.pid)
    return result


def format_variant(name: str, r: dict) -> str:
    from posenet.runtime.execution import machine_line

    runs = ", ".join(f"{x['network']} {x['backend']} {x['precision']}" for x in r["model"]["runtime"])
    lines = [f"== {name}: {runs}", machine_line(r["model"]["machine"]), ""]
    head = f"{'config':<22}{'persons':>8}{'p50 ms':>9}{'p95 ms':>9}" + "".join(f"{s:>9}" for s in STAGES)
    lines += [head + "   (stages: server-side p50, ms)", "-" * len(head)]
    for key, c in r["configs"].items():
        stages = "".join(f"{c['stages_ms_p50'][s]:>9.1f}" for s in STAGES)
        lines.append(
            f"{key:<22}{c['persons']:>8}{c['latency_ms']['p50']:>9.1f}{c['latency_ms']['p95']:>9.1f}{stages}"
        )
    tp = r["throughput_fps"]
    lines += ["", f"throughput (detector on, 3-person frame): {tp['1']:.2f} frames/s at concurrency 1, "
              f"{tp['4']:.2f} at concurrency 4; server peak RSS {r['peak_rss_mb']:.0f} MB", ""]  # fmt: skip
    return "\n".join(lines)


if __name__ == "__main__":
    main()
