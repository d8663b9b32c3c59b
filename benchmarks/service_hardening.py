"""Overload figures of the service (issue 14): slow uploads, the largest admitted frame, a client that leaves.

    python benchmarks/service_hardening.py [--threads 2] [--slow 16]

Starts ``uvicorn service.app:app`` on 127.0.0.1 with the shipped weights and the default limits (the harness
of the tests), then measures over real HTTP:

1. the latency of the example frame while ``--slow`` clients trickle their bodies a byte every 0.1 s;
2. the largest frames that the default ``ORPOSE_MAX_POSE_PIXELS`` admits (persons x views = 96 crops: 3 x 32
   at 640x480, 8 x 12 at 640x480 and at 1920x1200) and one crop more, refused: wall time, and the server's
   RSS (VmRSS sampled every 20 ms, and VmHWM) while each runs;
3. how long after a client disconnects its frame's work stops (the server's own log line), and how soon the
   next frame is served.

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import re
import socket
import sys
import threading
import time
from pathlib import Path

import cv2
import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from service_harness import REPO_ROOT, Server, Tricklers, form_kwargs, raw_request  # noqa: E402

FRAME = REPO_ROOT / "examples" / "frame"


def example() -> tuple[dict, list]:
    scene = json.loads((FRAME / "scene_boxes.json").read_text())
    files = [(p.stem, (p.name, p.read_bytes(), "application/octet-stream")) for p in sorted(FRAME.iterdir())
             if p.stem.startswith(("color_", "depth_"))]  # fmt: skip
    return scene, files


def big_frame(views: int, persons: int, size: tuple[int, int]) -> tuple[dict, list]:
    """``views`` copies of the example's view 0 (resized to ``size``), each with ``persons`` boxes and ids."""
    scene, files = example()
    parts = dict(files)
    color = cv2.imdecode(np.frombuffer(parts["color_0"][1], np.uint8), cv2.IMREAD_COLOR)
    depth = cv2.imdecode(np.frombuffer(parts["depth_0"][1], np.uint8), cv2.IMREAD_UNCHANGED)
    w, h = size
    s = w / color.shape[1]
    color = cv2.imencode(".jpg", cv2.resize(color, size))[1].tobytes()
    depth = cv2.imencode(".png", cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST))[1].tobytes()
    cam = dict(scene["views"][0]["camera"], image_size=[w, h])
    for k in ("fx", "fy", "cx", "cy"):
        cam[k] = cam[k] * s
    boxes = [[(20 + 12 * p) * s, 60 * s, (300 + 12 * p) * s, 440 * s] for p in range(persons)]
    views_out, files_out = [], []
    for v in range(views):
        views_out.append(
            {"camera": cam, "depth_scale_mm": 1.0, "boxes": boxes, "person_ids": list(range(persons))}
        )
        files_out += [
            (f"color_{v}", ("c.jpg", color, "image/jpeg")),
            (f"depth_{v}", ("d.png", depth, "image/png")),
        ]
    return {"views": views_out}, files_out


class Rss:
    """Samples the server's VmRSS every 20 ms while in use; ``peak`` in GB."""

    def __init__(self, pid: int) -> None:
        self.pid, self.peak, self.stop = pid, 0.0, threading.Event()

    def field(self, name: str) -> float:
        text = Path(f"/proc/{self.pid}/status").read_text()
        return int(re.search(rf"{name}:\s+(\d+) kB", text).group(1)) / 1e6

    def __enter__(self):
        self.before = self.field("VmRSS")
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()
        return self

    def _run(self) -> None:
        while not self.stop.wait(0.02):
            self.peak = max(self.peak, self.field("VmRSS"))

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--threads", type=int, default=2, help="ORPOSE_THREADS (default: %(default)s)")
    parser.add_argument("--slow", type=int, default=16, help="slow-body clients (default: %(default)s)")
    args = parser.parse_args()
    server = Server({"ORPOSE_THREADS": str(args.threads)})
    out: dict = {}
    with server as url, httpx.Client(base_url=url, timeout=120) as client:
        scene, files = example()
        client.post("/scenes", **form_kwargs(scene, files)).raise_for_status()  # warm-up
        rss = Rss(server.proc.pid)
        out["rss_idle_gb"] = round(rss.field("VmRSS"), 3)

        slow = Tricklers(client.base_url, args.slow)
        t0 = time.perf_counter()
        r = client.post("/scenes", **form_kwargs(scene, files))
        out["slow_clients"] = {"clients": args.slow, "status": r.status_code,
                               "valid_request_s": round(time.perf_counter() - t0, 3)}  # fmt: skip
        slow.close()
        time.sleep(0.5)

        out["largest"] = []
        for views, persons, size in [(3, 32, (640, 480)), (8, 12, (640, 480)), (8, 12, (1920, 1200)),
                                     (8, 13, (640, 480))]:  # fmt: skip
            big = big_frame(views, persons, size)
            with Rss(server.proc.pid) as m:
                t0 = time.perf_counter()
                r = client.post("/scenes", **form_kwargs(*big))
                wall = time.perf_counter() - t0
            row = {"views": views, "persons": persons, "size": f"{size[0]}x{size[1]}", "status": r.status_code,
                   "wall_s": round(wall, 3), "rss_before_gb": round(m.before, 3), "rss_peak_gb": round(m.peak, 3)}  # fmt: skip
            if r.status_code == 200:
                row["timings_ms"] = {k: round(v) for k, v in r.json()["timings"].items()}
            else:
                row["detail"] = r.json()["detail"]
            out["largest"].append(row)
        out["rss_hwm_gb"] = round(rss.field("VmHWM"), 3)

        # A client that leaves 0.3 to 2 s into the largest frame (8 x 1920x1200: decoding, then the network).
        heavy = raw_request(client, **form_kwargs(*big_frame(8, 12, (1920, 1200))))
        out["disconnect"] = []
        for after_s in (0.3, 0.8, 1.2, 1.6, 2.0):
            server.log.seek(0, 2)
            log_at = server.log.tell()
            sock = socket.create_connection((client.base_url.host, client.base_url.port))
            sock.sendall(heavy)
            time.sleep(after_s)
            sock.close()
            t0 = time.perf_counter()
            r = client.post("/scenes", **form_kwargs(scene, files))  # waits for the only inference worker
            served = time.perf_counter() - t0
            server.log.seek(log_at)
            stopped = re.findall(r"its work stopped (\d+) ms later", server.log.read())
            out["disconnect"].append({
                "after_s": after_s, "stopped_ms": int(stopped[0]) if stopped else None, "next_status": r.status_code,
                # from the close to the next frame's answer, less that frame's own decode + pose + encode
                "freed_after_s": round(served - sum(r.json()["timings"][k] for k in ("decode", "detect", "match", "pose", "encode")) / 1e3, 3),
            })  # fmt: skip
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
