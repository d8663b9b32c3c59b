"""Batch client: post each multi-view frame of an MVOR-format dataset to the service; one JSON line per frame.

    python -m service.client DATASET_DIR --annotations A.json --url http://localhost:8000
        --out results.jsonl [--concurrency 4] [--reference-boxes] [--days 4] [--evaluate] [--token T]
    python -m service.client RECORDING_DIR --url http://localhost:8000 --out results.jsonl   # rig.json + cam*/
    python -m service.client SEQUENCES_DIR --annotations A.json --out tracks.jsonl --track \
        [--export-easymocap DIR] [--export-csv tracks.csv]      # posenet.synth --sequence output

Each finished frame is appended to ``--out`` as one line, flushed and fsynced, so a killed run loses at most
the frames in flight. A restarted run skips the frames already in the file (a line cut short by the kill is
dropped first), so nothing is duplicated or lost. 503s, 429s, gateway errors and connection errors are retried
with exponential backoff (honouring Retry-After); a frame that still fails is not written, so the next run
retries it. A frame the server rejects (4xx) is written with its error and counted as a failure.

Image files are sent as they are on disk (no decoding or re-encoding): ``dayD/camC/color/N.png`` and the
16-bit depth beside it in ``depth/``. ``--color-format jpeg`` re-encodes colour as JPEG (``--jpeg-quality``, 95 by
default: 30 KB against 231 KB for a rendered 640x480 PNG, and the server decodes it at the models' resolution by DCT scaling), and
``--depth-format png-fast`` re-writes depth losslessly with no PNG filter and zlib level 3 (as the renderer
writes it; faster to decode than a maximally compressed PNG): cheaper transport, at the accuracy cost that
``docs/service.md`` records for JPEG (depth stays exact). ``--send-size read`` brings each view to the size the
networks read (GET /model's ``read_size``) before sending it, as the server would: with PNG colour the same
answers bit for bit, a quarter of the bytes, and a quarter of the pixels for the server to decode. With ``--reference-boxes`` the annotated boxes that have a person id are
sent with those ids (the paper's reference-box setting, detection skipped). ``--evaluate`` scores the whole
output file with ``posenet.evaluation.evaluate``; in detector mode each returned person is first given the ground-truth
id whose boxes it overlaps most (mean IoU over the views, as in the paper; MVOR's box-only people compete).

``--track`` sends each sequence's frames (the ``sequence``, ``frame_index`` and ``timestamp_s`` of each
multi-view frame) in time order through one stream per sequence (``POST /streams/{id}/frames``; up to
``--concurrency`` sequences at once); each line also holds ``sequence``, ``frame_index`` and ``timestamp_s``,
and each person its ``track_id`` and ``smoothed_joints``. A resumed run sends a partly done sequence again
from its first frame, so that its track ids go on as before (see :func:`track_sequence`). The exports
(``service.track_export``) are written from the whole output file at the end.
"""

from __future__ import annotations

import argparse
import fcntl
import hashlib
import json
import os
import random
import socket
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import cv2
import httpx
import numpy as np
from tqdm import tqdm

from posenet.boxes import ground_truth_ids, identified
from posenet.cli import add_days
from posenet.data.images import (
    COLOR_PNG_PARAMS,
    DEPTH_PNG_PARAMS,
    depth_file_name,
    subsample_color,
    subsample_depth,
)
from posenet.data.mvor import MvorDataset, load_annotations
from posenet.data.sample import Sample
from posenet.evaluation.evaluate import prediction_record
from posenet.net.inputs import reduction

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
    transport: Transport = field(default_factory=lambda: Transport())  # how the images travel


# ----------------------------------------------------------------------------------------------- requests
# colour: as on disk; JPEG re-encoded at --jpeg-quality; not sent (a depth-only server)
COLOR_FORMATS = ("png", "jpeg", "none")
DEPTH_FORMATS = ("png", "png-fast")  # as on disk; lossless PNG without filter at zlib level 3


@dataclass(frozen=True)
class Transport:
    """How a frame's images travel: colour as on disk (``png``) or re-encoded as JPEG at ``quality``; depth as on
    disk or re-written losslessly as ``posenet.data.images.DEPTH_PNG_PARAMS`` (``png-fast``).

    ``read_size`` (W, H), GET /model's: each view is brought to the size the networks read before it is sent,
    by the server's own rule (``posenet.net.inputs.reduction``; block mean colour, lower median depth), and
    re-encoded (colour PNG as ``COLOR_PNG_PARAMS`` or JPEG, depth as ``DEPTH_PNG_PARAMS``). The camera keeps
    its calibrated intrinsics and ``image_size``, so the server reads the view as the calibrated image reduced:
    with PNG colour the answers are the same bit for bit, with a quarter of the bytes to send and to decode."""

    color: str = "png"
    depth: str = "png"
    quality: int = 95
    read_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        if self.color not in COLOR_FORMATS or self.depth not in DEPTH_FORMATS:
            raise ValueError(f"colour must be one of {COLOR_FORMATS} and depth one of {DEPTH_FORMATS}")
        if not 1 <= self.quality <= 100:
            raise ValueError(f"the JPEG quality must be 1 to 100, got {self.quality}")

    def color_part(self, name: str, data: bytes) -> tuple[str, bytes, str] | None:
        """A colour image's file part (``name``: its file name, ``data``: its bytes as read); None with ``none``."""
        if self.color == "none":
            return None
        if self.color == "png":
            return name, data, "image/png"
        return self._encoded_color(name, cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR))

    def _encoded_color(self, name: str, bgr: np.ndarray) -> tuple[str, bytes, str]:
        if self.color == "png":
            return name, cv2.imencode(".png", bgr, COLOR_PNG_PARAMS)[1].tobytes(), "image/png"
        jpeg = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, self.quality])[1].tobytes()
        return str(Path(name).with_suffix(".jpg")), jpeg, "image/jpeg"

    def depth_part(self, name: str, data: bytes) -> tuple[str, bytes, str]:
        """A 16-bit depth image's file part."""
        if self.depth == "png-fast":
            depth = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
            data = cv2.imencode(".png", depth, DEPTH_PNG_PARAMS)[1].tobytes()
        return name, data, "image/png"

    def view_parts(self, color: Path, depth: Path) -> tuple[tuple | None, tuple, tuple[int, int] | None]:
        """A view's colour part (None with ``none``) and depth part from its files, and the (W, H) of the images
        as recorded when they were sent reduced (None: sent at that size)."""
        depth_bytes = depth.read_bytes()  # a missing file raises here, as recorded or reduced
        color_bytes = None if self.color == "none" else color.read_bytes()
        if self.read_size is not None:
            image = cv2.imdecode(np.frombuffer(depth_bytes, np.uint8), cv2.IMREAD_UNCHANGED)
            if image is not None and image.ndim == 2 and reduction(*image.shape[::-1], self.read_size) > 1:
                # the colour is decoded only for a view that is reduced
                bgr = (
                    None
                    if color_bytes is None
                    else cv2.imdecode(np.frombuffer(color_bytes, np.uint8), cv2.IMREAD_COLOR)
                )
                if color_bytes is None or bgr is not None:
                    return self.encode_view(bgr, image, color.name, depth.name)
        # as recorded (a file the client cannot read goes as it is, for the server to say why)
        color_part = None if color_bytes is None else self.color_part(color.name, color_bytes)
        return color_part, self.depth_part(depth.name, depth_bytes), None

    def encode_view(
        self,
        bgr: np.ndarray | None,
        depth: np.ndarray,
        color_name: str = "color.png",
        depth_name: str = "depth.png",
    ) -> tuple[tuple | None, tuple, tuple[int, int] | None]:
        """A view's file parts from images in memory (a live camera's frame): ``bgr (H, W, 3)`` uint8 (OpenCV's
        order; None: no colour) and ``depth (H, W)`` uint16 mm, reduced to ``read_size`` when it is set; returns
        as :meth:`view_parts`. Send the camera as calibrated, with ``image_size`` the recorded (W, H)."""
        k = 1 if self.read_size is None else reduction(depth.shape[1], depth.shape[0], self.read_size)
        depth_png = cv2.imencode(".png", subsample_depth(depth, k), DEPTH_PNG_PARAMS)[1].tobytes()
        color_part = None
        if self.color != "none" and bgr is not None:
            color_part = self._encoded_color(color_name, subsample_color(bgr, k))
        recorded = None if k == 1 else (depth.shape[1], depth.shape[0])
        return color_part, (depth_name, depth_png, "image/png"), recorded


def scene_request(
    sample: Sample, root: Path, reference_boxes: bool, transport: Transport | None = None
) -> tuple[dict, list[tuple]]:
    """The ``scene`` JSON and the file parts of one frame, images read as raw bytes (and re-encoded as
    ``transport`` says; default: sent as on disk)."""
    transport = transport or Transport()
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
            boxes, ids = identified(view.boxes, view.box_person_ids)  # no identity: no 3D pose to estimate
            entry["boxes"], entry["person_ids"] = boxes.tolist(), ids.tolist()
        views.append(entry)
        color = root / view.file_name
        color_part, depth_part, recorded = transport.view_parts(color, root / depth_file_name(view.file_name))
        if recorded is not None:  # sent reduced: the server reads it as the calibrated image brought to 1/k
            entry["camera"]["image_size"] = list(recorded)
        if color_part is not None:  # None: a depth-only server, no colour leaves the client
            files.append((f"color_{i}", color_part))
        files.append((f"depth_{i}", depth_part))
    scene = {"views": views}
    if sample.up is not None:  # the file knows the room: streams leave lying persons untracked
        scene["up"] = sample.up.tolist()
    return scene, files


def _backoff(cfg: ClientConfig, attempt: int, retry_after: str | None) -> float:
    delay = min(cfg.backoff_cap_s, cfg.backoff_s * 2**attempt) * (0.5 + random.random() / 2)  # jitter
    if retry_after is not None and retry_after.isdigit():
        delay = max(delay, float(retry_after))
    return delay


def _headers(cfg: ClientConfig) -> dict[str, str]:
    return {"Authorization": f"Bearer {cfg.token}"} if cfg.token else {}


def post_frame(
    client: httpx.Client,
    sample: Sample,
    root: Path,
    cfg: ClientConfig,
    path: str = "/scenes",
    fields: dict[str, str] | None = None,
) -> dict:
    """Post one frame to ``path`` (with the extra form ``fields``), retrying transient failures. Returns the
    output line's dict.

    Raises the last transient error when the retries are used up (the frame is then not written).
    """
    scene, files = scene_request(sample, root, cfg.reference_boxes, cfg.transport)
    headers = _headers(cfg)
    for attempt in range(cfg.retries + 1):
        t0 = time.perf_counter()
        try:
            r = client.post(
                path,
                data={"scene": json.dumps(scene), **(fields or {})},
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
    """The output's persons in ``posenet.evaluation.evaluate``'s format; detector-mode ids are associated by box IoU."""
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
                joints = person["joints"]
                xyz = [j["position"] for j in joints]
                spread, confidence = [j["spread_mm"] for j in joints], [j["confidence"] for j in joints]
                preds.append(prediction_record(frame_id, pid, xyz, spread, confidence))
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


class Output:
    """The output file of a run, written from the worker threads: each line appended, counted and shown."""

    def __init__(self, f, counts: dict, bar: tqdm) -> None:
        self.f, self.counts, self.bar = f, counts, bar
        self.lock = threading.Lock()

    def write(self, line: dict) -> None:
        with self.lock:
            append_line(self.f, line)
            self.counts["ok" if line["status"] == 200 else "rejected"] += 1
            if line["status"] != 200:
                tqdm.write(f"{line['id']}: {line['status']} {line.get('error')}")
            self.bar.update()

    def gave_up(self, what: str, exc: Exception, frames: int = 1) -> None:
        # Transient errors after all retries, or an unreadable image file: not written, so a rerun (after
        # fixing the file) retries the frames.
        with self.lock:
            self.counts["gave_up"] += frames
            tqdm.write(f"{what}: gave up ({exc}); a rerun will retry it")
            self.bar.update(frames)


def run(
    dataset: MvorDataset,
    root: Path,
    out: Path,
    cfg: ClientConfig,
    sequences: dict[int, list[SequenceFrame]] | None = None,
) -> dict:
    """Post every frame not yet in ``out``; returns the counts of the run.

    ``sequences`` (:func:`sequence_frames`): send each sequence's frames in order through a stream
    (:func:`track_sequence`), up to ``cfg.concurrency`` sequences at once; None: frames one by one to /scenes.
    """
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
        output = Output(f, counts, bar)
        if sequences is None:
            jobs = [pool.submit(_frame_job, client, dataset, i, root, cfg, output) for i in todo]
        else:
            prefix = stream_prefix(out)
            jobs = [
                pool.submit(
                    track_sequence, client, dataset, frames, f"{prefix}-seq{seq}", root, cfg, done, output
                )
                for seq, frames in sequences.items()
            ]
        for job in jobs:
            job.result()
    counts["seconds"] = time.perf_counter() - t0
    return counts


def _frame_job(
    client: httpx.Client, dataset: MvorDataset, i: int, root: Path, cfg: ClientConfig, output: Output
):
    try:
        line = post_frame(client, dataset[i], root, cfg)
    except (httpx.TransportError, RuntimeError, OSError) as exc:
        output.gave_up(dataset.ids[i], exc)
    else:
        output.write(line)


# ----------------------------------------------------------------------------------------------- tracking
class SequenceFrame(NamedTuple):
    index: int  # in the dataset
    sequence: int
    frame_index: int
    timestamp_s: float


def sequence_frames(gt: dict, dataset: MvorDataset) -> dict[int, list[SequenceFrame]]:
    """Per sequence, its frames of ``dataset`` in time order, from the ``sequence``, ``frame_index`` and
    ``timestamp_s`` of each multi-view frame (``posenet.synth --sequence`` writes them)."""
    index = {frame_id: i for i, frame_id in enumerate(dataset.ids)}
    out: dict[int, list[SequenceFrame]] = {}
    for mv in gt["multiview_images"]:
        if mv["id"] not in index:
            continue
        if not {"sequence", "frame_index", "timestamp_s"} <= mv.keys():
            raise SystemExit(
                f"error: frame {mv['id']} has no sequence, frame_index and timestamp_s, which --track needs: "
                "render sequences with python -m posenet.synth --sequence"
            )
        frame = SequenceFrame(
            index[mv["id"]], int(mv["sequence"]), int(mv["frame_index"]), float(mv["timestamp_s"])
        )
        out.setdefault(int(mv["sequence"]), []).append(frame)
    return {seq: sorted(frames, key=lambda f: f.timestamp_s) for seq, frames in sorted(out.items())}


def stream_prefix(out: Path) -> str:
    """The stream ids' prefix of the run writing ``out``: the same for a resumed run (which ends the streams a
    killed run left), and another for another output file or machine (two runs never share a stream)."""
    return hashlib.sha1(f"{socket.gethostname()}:{out.resolve()}".encode()).hexdigest()[:10]


class StreamLost(Exception):
    """The server's stream is not the one this run has been feeding (it expired, or the server restarted)."""


def end_stream(client: httpx.Client, stream_id: str, cfg: ClientConfig) -> None:
    r = client.delete(f"/streams/{stream_id}", headers=_headers(cfg), timeout=cfg.timeout_s)
    if r.status_code not in (200, 404):  # 404: no such stream, which is what we want
        raise RuntimeError(f"DELETE /streams/{stream_id}: {r.status_code} {r.text[:200]}")


def track_sequence(
    client: httpx.Client,
    dataset: MvorDataset,
    frames: list[SequenceFrame],
    stream_id: str,
    root: Path,
    cfg: ClientConfig,
    done: dict[str, dict],
    output: Output,
) -> None:
    """Send one sequence's ``frames`` in time order through the stream ``stream_id`` and write their lines.

    A sequence whose frames are all in ``done`` is skipped. Otherwise the stream is ended first and the whole
    sequence sent from its first frame, those already written included (their answers are not written again),
    so that the tracker has seen every frame before the first new one, and a resumed run's track ids go on
    from the killed run's (the pipeline and the tracker are deterministic). When the stream is lost on the way
    (a 409, or a stream that has taken another number of frames than were sent: it expired, or the server
    restarted), the sequence is sent once more from the start; then its frames not yet written are given up.
    """
    written = {dataset.ids[f.index] for f in frames if dataset.ids[f.index] in done}
    if len(written) == len(frames):
        return
    lost: Exception | None = None
    try:
        for _ in range(2):
            end_stream(client, stream_id, cfg)
            try:
                _send_sequence(client, dataset, frames, stream_id, root, cfg, written, output)
            except StreamLost as exc:
                lost = exc
                continue
            end_stream(client, stream_id, cfg)
            return
    except (httpx.TransportError, RuntimeError, OSError) as exc:
        lost = exc
    output.gave_up(f"stream {stream_id}", lost, len(frames) - len(written))


def _send_sequence(client, dataset, frames, stream_id, root, cfg, written: set[str], output: Output) -> None:
    path = f"/streams/{stream_id}/frames"
    taken = 0
    for frame in frames:
        sample = dataset[frame.index]
        line = post_frame(client, sample, root, cfg, path, {"timestamp_s": repr(frame.timestamp_s)})
        line = {
            "id": line.pop("id"),
            "day": line.pop("day"),
            "sequence": frame.sequence,
            "frame_index": frame.frame_index,
            "timestamp_s": frame.timestamp_s,
            **line,
        }
        if line["status"] == 409:
            raise StreamLost(line["error"])
        if line["status"] == 200:
            taken += 1
            if line["response"]["stream"]["frames"] != taken:
                raise StreamLost(
                    f"the server's stream {stream_id} has taken {line['response']['stream']['frames']} frames, "
                    f"but this run sent it {taken}: it expired (ORPOSE_STREAM_IDLE_S) or the server restarted"
                )
        if sample.id not in written:
            output.write(line)
            written.add(sample.id)


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
    add_days(parser)
    parser.add_argument(
        "--evaluate", action="store_true", help="print the MPJPE tables of the output at the end"
    )
    parser.add_argument(
        "--token", default=os.environ.get("ORPOSE_TOKEN"), help="bearer token (env ORPOSE_TOKEN)"
    )
    parser.add_argument(
        "--color-format", choices=COLOR_FORMATS, default="png",
        help="send colour as on disk (png), re-encoded as JPEG (an eighth of a rendered PNG's bytes), or not at all "
        "(none: depth only, for a server whose networks read depth alone, GET /model's modalities and "
        "detector_modalities; default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--jpeg-quality", type=int, default=95, help="JPEG quality, 1-100, with --color-format jpeg (default: %(default)s)"
    )  # fmt: skip
    parser.add_argument(
        "--depth-format", choices=DEPTH_FORMATS, default="png",
        help="send depth as on disk (png) or re-written losslessly without PNG filter at zlib level 3 (png-fast: "
        "faster for the server to decode; default: %(default)s)",
    )  # fmt: skip
    parser.add_argument(
        "--send-size", choices=("recorded", "read"), default="recorded",
        help="send each view at its recorded size, or reduced to the size the networks read (read: GET /model's "
        "read_size, by the server's own rule, with the calibrated camera; the same answers with PNG colour, a "
        "quarter of the bytes, and less for the server to decode; default: %(default)s)",
    )  # fmt: skip
    track = parser.add_argument_group("tracking (sequences rendered by posenet.synth --sequence)")
    track.add_argument(
        "--track",
        action="store_true",
        help="send each sequence's frames in time order through a stream (POST /streams/{id}/frames, one "
        "stream per sequence); each person of a line then carries its track_id",
    )
    track.add_argument(
        "--export-easymocap",
        type=Path,
        metavar="DIR",
        help="after the run, write the tracked persons of the whole output as EasyMocap keypoints3d: "
        "DIR/sequence_S/keypoints3d/NNNNNN.json",
    )
    track.add_argument(
        "--export-csv",
        type=Path,
        metavar="FILE",
        help="after the run, write them as CSV: sequence, frame, timestamp_s, track, joint, x, y, z, "
        "confidence, spread_mm",
    )
    parser.add_argument("--timeout", type=float, default=ClientConfig.timeout_s, help="seconds per request")
    parser.add_argument(
        "--retries", type=int, default=ClientConfig.retries, help="retries of a transient failure"
    )
    return parser


def read_size_of(model: dict) -> tuple[int, int] | None:
    """The ``read_size`` of a ``GET /model`` answer as ``Transport`` takes it (None: the server reads views as
    sent)."""
    size = model.get("read_size")
    return None if size is None else (int(size[0]), int(size[1]))


def served_read_size(url: str, token: str | None) -> tuple[int, int] | None:
    """GET /model's ``read_size`` (:func:`read_size_of`); exits with the reason when the server cannot say."""
    try:
        r = httpx.get(f"{url.rstrip('/')}/model", headers=_headers(ClientConfig(token=token)), timeout=30)
        r.raise_for_status()
    except httpx.HTTPError as exc:
        raise SystemExit(
            f"--send-size read asks the server for its read size (GET {url}/model): {exc}"
        ) from None
    size = read_size_of(r.json())
    if size is None:
        print("--send-size read: the server reads views as sent (no read_size); sending them as recorded")
    return size


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.concurrency < 1:
        raise SystemExit("--concurrency must be at least 1")
    read_size = served_read_size(args.url, args.token) if args.send_size == "read" else None
    try:
        transport = Transport(args.color_format, args.depth_format, args.jpeg_quality, read_size)
    except ValueError as exc:
        raise SystemExit(f"--jpeg-quality: {exc}") from None
    if args.annotations is None:  # a recording folder: frames and cameras only, nothing to evaluate against
        from posenet.data.recording import RecordingDataset

        if args.reference_boxes or args.evaluate or args.days:
            raise SystemExit("--reference-boxes, --evaluate and --days need --annotations")
        gt, dataset = None, RecordingDataset(args.dataset, modalities=())
    else:
        gt = load_annotations(args.annotations)
        dataset = MvorDataset(None, gt, days=args.days)  # annotations only: the images are sent as raw files
    if (args.export_easymocap or args.export_csv) and not args.track:
        raise SystemExit("--export-easymocap and --export-csv export tracks: they need --track")
    sequences = None
    if args.track:
        if gt is None:
            raise SystemExit(
                "--track needs --annotations (with each frame's sequence, frame_index, timestamp_s)"
            )
        sequences = sequence_frames(gt, dataset)
    cfg = ClientConfig(
        args.url, args.concurrency, args.reference_boxes, args.token, args.timeout, args.retries,
        transport=transport,
    )  # fmt: skip
    counts = run(dataset, args.dataset, args.out, cfg, sequences)
    new = counts["ok"] + counts["rejected"]
    print(
        f"frames: {counts['frames']} in scope, {counts['already_done']} already in {args.out}, "
        f"{new} done now "
        f"({counts['ok']} ok, {counts['rejected']} rejected by the server), {counts['gave_up']} failed after "
        f"retries; {counts['seconds']:.1f} s, {new / max(counts['seconds'], 1e-9):.2f} frames/s"
    )
    if args.export_easymocap or args.export_csv:
        from service.track_export import export_csv, export_easymocap, tracked_frames

        frames = tracked_frames(read_done(args.out).values())
        if args.export_easymocap:
            n = export_easymocap(frames, args.export_easymocap)
            print(f"EasyMocap keypoints3d: {n} frames under {args.export_easymocap}")
        if args.export_csv:
            n = export_csv(frames, args.export_csv)
            print(f"CSV: {n} rows in {args.export_csv}")
    if args.evaluate:
        from posenet.evaluation.evaluate import evaluate, format_tables

        preds = predictions(read_done(args.out), dataset)
        print(format_tables(evaluate(gt, preds, image_ids=set(dataset.ids))))
    return 1 if counts["gave_up"] or counts["rejected"] else 0


if __name__ == "__main__":
    sys.exit(main())
