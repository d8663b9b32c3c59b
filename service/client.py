"""Batch client: post each multi-view frame of an MVOR-format dataset to the service; one JSON line per frame.

    python -m service.client DATASET_DIR --annotations A.json --url http://localhost:8000
        --out results.jsonl [--concurrency 4] [--reference-boxes] [--days 4] [--evaluate] [--token T]
    python -m service.client RECORDING_DIR --url http://localhost:8000 --out results.jsonl   # rig.json + cam*/

Each finished frame is appended to ``--out`` as one line, flushed and fsynced, so a killed run loses at most
the frames in flight. A restarted run skips the frames already in the file (a line cut short by the kill is
dropped first), so nothing is duplicated or lost. 503s, 429s, gateway errors and connection errors are retried
with exponential backoff (honouring Retry-After); a frame that still fails is not written, so the next run
retries it. A frame the server rejects (4xx) is written with its error and counted as a failure.

Image files are sent as they are on disk (no decoding or re-encoding): ``dayD/camC/color/N.png`` and the
16-bit depth beside it in ``depth/``. With ``--reference-boxes`` the annotated boxes that have a person id are
sent with those ids (the paper's reference-box setting, detection skipped). ``--evaluate`` scores the whole
output file with ``posenet.evaluate``; in detector mode each returned person is first given the ground-truth
id whose boxes it overlaps most (mean IoU over the views, as in the paper).
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import random
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import httpx
from tqdm import tqdm

from posenet.data.images import depth_file_name
from posenet.data.mvor import MvorDataset, load_annotations
from posenet.data.sample import Sample

RETRY_STATUSES = {429, 502, 503, 504}


@dataclass
class ClientConfig:
    url: str = "http://localhost:8000"
    concurrency: int = 1
    reference_boxes: bool = False
    token: str | None = None
    timeout_s: float = 120.0  # per request; a detector + pose pass on 2 CPU cores takes about a second
    retries: int = 8  # 8 doublings from 0.5 s reach the 30 s cap: about 2 minutes of patience per frame
    backoff_s: float = 0.5
    backoff_cap_s: float = 30.0


# ----------------------------------------------------------------------------------------------- requests
def scene_request(sample: Sample, root: Path, reference_boxes: bool) -> tuple[dict, list[tuple]]:
    """The ``scene`` JSON and the file parts of one frame, images read as raw bytes."""
    views, files = [], []
    for i, view in enumerate(sample.views):
        cam = view.camera
        fx, fy, cx, cy = (float(x) for x in cam.intrinsics)
        entry = {
            "camera": {
                "fx": fx, "fy": fy, "cx": cx, "cy": cy,
                "distortion": None if cam.distortion is None else cam.distortion.tolist(),
                "extrinsics": cam.extrinsics.tolist(),
                "image_size": None if cam.size is None else list(cam.size),
            },
            "depth_scale_mm": 1.0,
        }  # fmt: skip
        if reference_boxes:
            keep = view.box_person_ids >= 0  # boxes without an identity have no 3D pose to estimate
            entry["boxes"] = view.boxes[keep].tolist()
            entry["person_ids"] = view.box_person_ids[keep].tolist()
        views.append(entry)
        color = root / view.file_name
        depth = root / depth_file_name(view.file_name)
        files.append((f"color_{i}", (color.name, color.read_bytes(), "image/png")))
        files.append((f"depth_{i}", (depth.name, depth.read_bytes(), "image/png")))
    return {"views": views}, files


def _backoff(cfg: ClientConfig, attempt: int, retry_after: str | None) -> float:
    delay = min(cfg.backoff_cap_s, cfg.backoff_s * 2**attempt) * (0.5 + random.random() / 2)  # jitter
    if retry_after is not None and retry_after.isdigit():
        delay = max(delay, float(retry_after))
    return delay


def post_frame(client: httpx.Client, sample: Sample, root: Path, cfg: ClientConfig) -> dict:
    """Post one frame, retrying transient failures. Returns the output line's dict.

    Raises the last transient error when the retries are used up (the frame is then not written).
    """
    scene, files = scene_request(sample, root, cfg.reference_boxes)
    headers = {"Authorization": f"Bearer {cfg.token}"} if cfg.token else {}
    for attempt in range(cfg.retries + 1):
        t0 = time.perf_counter()
        try:
            r = client.post(
                "/scenes",
                data={"scene": json.dumps(scene)},
                files=files,
                headers=headers,
                timeout=cfg.timeout_s,
            )
        except httpx.TransportError:
            if attempt == cfg.retries:
                raise
            time.sleep(_backoff(cfg, attempt, None))
            continue
        if r.status_code in RETRY_STATUSES and attempt < cfg.retries:
            time.sleep(_backoff(cfg, attempt, r.headers.get("retry-after")))
            continue
        line = {
            "id": sample.id,
            "day": sample.day,
            "status": r.status_code,
            "latency_ms": (time.perf_counter() - t0) * 1e3,
        }
        if r.status_code == 200:
            line["response"] = r.json()
        elif r.status_code in RETRY_STATUSES:
            raise RuntimeError(f"frame {sample.id}: still {r.status_code} after {cfg.retries} retries")
        else:
            try:
                line["error"] = r.json().get("detail", r.text)
            except ValueError:
                line["error"] = r.text
        return line
    raise AssertionError("unreachable")


# ----------------------------------------------------------------------------------------------- output file
def read_done(path: Path) -> dict[str, dict]:
    """The frames already in the output, by id; a last line cut short by a kill is removed from the file."""
    if not path.exists():
        return {}
    data = path.read_bytes()
    end = data.rfind(b"\n") + 1
    if end < len(data):  # a partial last line: truncate it so the next append starts on a fresh line
        with open(path, "r+b") as f:
            f.truncate(end)
    done = {}
    for raw in data[:end].splitlines():
        try:
            line = json.loads(raw)
        except ValueError:
            continue
        if isinstance(line, dict) and "id" in line:
            done[line["id"]] = line
    return done


def append_line(f, line: dict) -> None:
    f.write(json.dumps(line) + "\n")
    f.flush()
    os.fsync(f.fileno())  # the line survives a kill or a power cut once this returns


# ----------------------------------------------------------------------------------------------- evaluation
def predictions(lines: dict[str, dict], dataset: MvorDataset) -> list[dict]:
    """The output's persons in ``posenet.evaluate``'s format; detector-mode ids are associated by box IoU."""
    from service.association import ground_truth_ids

    by_id = {sample_id: i for i, sample_id in enumerate(dataset.ids)}
    preds = []
    for frame_id, line in lines.items():
        if line.get("status") != 200 or frame_id not in by_id:
            continue
        response = line["response"]
        persons = response["persons"]
        if response["mode"] == "detector":
            sample = dataset[by_id[frame_id]]
            pred_boxes = [[None] * len(sample.views) for _ in persons]
            for p, person in enumerate(persons):
                for support in person["views"]:
                    pred_boxes[p][support["view"]] = support["box"]
            ids = ground_truth_ids(sample, pred_boxes)
        else:
            ids = [p["id"] for p in persons]
        for person, pid in zip(persons, ids, strict=True):
            if pid is not None:
                xyz = [c for joint in person["joints"] for c in joint["position"]]
                preds.append({"image_ids": frame_id, "person_id": pid, "keypoints3D": xyz})
    return preds


# ----------------------------------------------------------------------------------------------- main
def lock_output(f, path: Path) -> None:
    """Hold an exclusive lock on the open output file ``f`` until it is closed, or exit with a message.

    Two clients appending to one file would interleave their lines and post the same frames twice. The lock
    is ``flock`` (advisory, released by the kernel when the process dies), so a killed run never leaves a
    stale lock behind.
    """
    try:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        f.close()
        raise SystemExit(
            f"error: {path} is in use by another batch client (it holds a lock on the file); wait for that "
            "run to finish, or give this one another --out"
        ) from None


def run(dataset: MvorDataset, root: Path, out: Path, cfg: ClientConfig) -> dict:
    """Post every frame not yet in ``out``; returns the counts of the run."""
    f = open(out, "a")  # closed by the with block below; the lock lasts as long
    lock_output(f, out)
    done = read_done(out)  # only once the lock is held: it may truncate a torn last line
    todo = [i for i, frame_id in enumerate(dataset.ids) if frame_id not in done]
    counts = {
        "frames": len(dataset),
        "already_done": len(dataset) - len(todo),
        "ok": 0,
        "rejected": 0,
        "gave_up": 0,
    }
    t0 = time.perf_counter()
    limits = httpx.Limits(max_connections=cfg.concurrency, max_keepalive_connections=cfg.concurrency)
    with (
        httpx.Client(base_url=cfg.url, limits=limits) as client,
        ThreadPoolExecutor(cfg.concurrency) as pool,
        f,
        tqdm(total=len(todo), desc="frames", unit="frame", dynamic_ncols=True) as bar,
    ):
        futures = {pool.submit(post_frame, client, dataset[i], root, cfg): dataset.ids[i] for i in todo}
        for future in as_completed(futures):
            try:
                line = future.result()
            except (httpx.TransportError, RuntimeError, OSError) as exc:
                # Transient errors after all retries, or an unreadable image file: not written, so a rerun
                # (after fixing the file) retries the frame.
                counts["gave_up"] += 1
                tqdm.write(f"{futures[future]}: gave up ({exc}); a rerun will retry it")
            else:
                append_line(f, line)
                counts["ok" if line["status"] == 200 else "rejected"] += 1
                if line["status"] != 200:
                    tqdm.write(f"{line['id']}: {line['status']} {line.get('error')}")
            bar.update()
    counts["seconds"] = time.perf_counter() - t0
    return counts


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m service.client",
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 2)[2],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("dataset", type=Path, help="dataset root holding dayD/camC/{color,depth}/NNNNNN.png")
    parser.add_argument(
        "--annotations",
        type=Path,
        help="MVOR-format annotation json; without it DATASET_DIR is a recording folder (rig.json + "
        "<camera>/{color,depth}/, posenet.data.recording)",
    )
    parser.add_argument(
        "--url", default=ClientConfig.url, help="the service's base URL (default: %(default)s)"
    )
    parser.add_argument(
        "--out", type=Path, required=True, help="output JSON lines; appended to and resumed from"
    )
    parser.add_argument(
        "--concurrency", type=int, default=1, help="requests in flight (default: %(default)s)"
    )
    parser.add_argument(
        "--reference-boxes", action="store_true", help="send the annotated boxes (no detection)"
    )
    parser.add_argument("--days", type=int, nargs="+", help="only these recording days (default: all)")
    parser.add_argument(
        "--evaluate", action="store_true", help="print the MPJPE tables of the output at the end"
    )
    parser.add_argument(
        "--token", default=os.environ.get("ORPOSE_TOKEN"), help="bearer token (env ORPOSE_TOKEN)"
    )
    parser.add_argument("--timeout", type=float, default=ClientConfig.timeout_s, help="seconds per request")
    parser.add_argument(
        "--retries", type=int, default=ClientConfig.retries, help="retries of a transient failure"
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.concurrency < 1:
        raise SystemExit("--concurrency must be at least 1")
    if args.annotations is None:  # a recording folder: frames and cameras only, nothing to evaluate against
        from posenet.data.recording import RecordingDataset

        if args.reference_boxes or args.evaluate or args.days:
            raise SystemExit("--reference-boxes, --evaluate and --days need --annotations")
        gt, dataset = None, RecordingDataset(args.dataset, modalities=())
    else:
        gt = load_annotations(args.annotations)
        dataset = MvorDataset(None, gt, days=args.days)  # annotations only: the images are sent as raw files
    cfg = ClientConfig(
        args.url, args.concurrency, args.reference_boxes, args.token, args.timeout, args.retries
    )
    counts = run(dataset, args.dataset, args.out, cfg)
    new = counts["ok"] + counts["rejected"]
    print(
        f"frames: {counts['frames']} in scope, {counts['already_done']} already in {args.out}, "
        f"{new} done now "
        f"({counts['ok']} ok, {counts['rejected']} rejected by the server), {counts['gave_up']} failed after "
        f"retries; {counts['seconds']:.1f} s, {new / max(counts['seconds'], 1e-9):.2f} frames/s"
    )
    if args.evaluate:
        from posenet.evaluate import evaluate, format_tables

        preds = predictions(read_done(args.out), dataset)
        print(format_tables(evaluate(gt, preds, image_ids=set(dataset.ids))))
    return 1 if counts["gave_up"] or counts["rejected"] else 0


if __name__ == "__main__":
    sys.exit(main())
