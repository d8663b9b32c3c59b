"""The service's settings: one pydantic-settings class, read from ``ORPOSE_*`` environment variables.

Example: ``ORPOSE_TOKEN=secret ORPOSE_MAX_IN_FLIGHT=2 uvicorn service.app:app``. Nothing is read at import
time: :func:`service.app.create_app` builds a :class:`Settings` when it is called without one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from pipeline.skeleton_matching import CANDIDATE_SCORE, SkeletonMatchConfig
from pipeline.track import TrackerConfig


class Settings(BaseSettings):
    """Every knob of the service. Each field is also the env var ``ORPOSE_<FIELD NAME IN CAPITALS>``."""

    model_config = SettingsConfigDict(env_prefix="ORPOSE_", extra="ignore")

    # None means the default weights shipped with the package (see posenet.net.infer / detector.infer).
    pose_checkpoint: Path | None = Field(
        None, description="pose network checkpoint; unset = the shipped weights"
    )
    detector_checkpoint: Path | None = Field(None, description="DETR checkpoint; unset = the shipped weights")
    device: str = Field("cpu", description="torch device for both models, e.g. 'cpu' or 'cuda:0'")
    # Chosen for the machine that serves, never by the one that trained (posenet.runtime.execution): bf16 only where it is
    # native (AVX512-BF16, AMX, a GPU); on AVX2-only CPUs bf16 is emulated and 7-20x slower than fp32.
    # int8 (posenet.runtime.quantize): both networks quantized for OpenVINO, the fastest on AVX2-only CPUs; never auto.
    precision: Literal["auto", "fp32", "bf16", "int8"] = Field(
        "auto",
        description="model precision: auto (bf16 only where the device computes it natively), fp32, bf16, or "
        "int8 (OpenVINO's quantized graphs, calibrated on rendered scenes at first start)",
    )
    # posenet.runtime.graphs: the ONNX graphs are exported from the loaded weights at start-up and cached in
    # $ORPOSE_CACHE_DIR (default ~/.cache/or-pose); `python -m service.export` builds them ahead of time.
    backend: Literal["auto", "torch", "onnxruntime", "openvino"] = Field(
        "auto",
        description="inference runtime of both networks: auto (openvino, else onnxruntime, else torch)",
    )
    # The runtimes' threads per network call. torch's own small ops of the pose stage run on one thread once both
    # networks run on a runtime (service.app.torch_threads: two OpenMP threads stall there on a shared machine).
    threads: int = Field(
        2,
        ge=1,
        le=256,
        description="intra-op threads of the inference runtimes (OpenVINO, ONNX Runtime), and of torch where a "
        "network runs on torch; with both networks on a runtime, torch's own small ops run on one thread",
    )
    # posenet.net.infer.PoseEstimator.from_checkpoint(flip_test=): on the unseen alt look's day 4 the mirrored pass
    # gained 0.3 cm (7.52 -> 7.21), on the twin 0.1 (docs/RESULTS.md); it doubles the pose stage's U-Net work.
    flip_test: bool | None = Field(
        None,
        description="average the pose network's estimates with those of the mirrored inputs (2x the pose "
        "network's work; better on looks it was not trained on); unset: the checkpoint's setting (off for the "
        "shipped weights)",
    )
    # One inference at a time by default: torch already uses `threads` cores inside one forward pass, and two
    # concurrent passes on the same cores only add latency to both.
    inference_workers: int = Field(1, ge=1, le=64, description="frames processed concurrently by the models")
    # Requests admitted at once (running + waiting for a worker). Beyond it: 503 with Retry-After, never a
    # queue.
    max_in_flight: int = Field(4, ge=1, le=1024, description="requests to /scenes admitted at once")
    # Connections still sending their body are bounded apart from the in-flight requests: a slow upload holds
    # one of these, never an inference slot. Worst-case memory: max_receiving x max_body_bytes.
    max_receiving: int = Field(
        32, ge=1, le=4096, description="requests receiving their body at once (beyond it: 503)"
    )
    # The pose network runs every person x view crop, so its time and memory grow with persons x views x crop
    # pixels. 96 crops of 96x96 take at most 3.5 s and 1.9 GB (server RSS, both models) on 2 CPU cores; see
    # docs/service.md. In detector mode the best-supported persons that fit are kept.
    max_pose_pixels: int = Field(
        96 * 96 * 96,
        ge=1,
        description="most persons x views x network-input pixels per frame (beyond it: 422 with boxes, "
        "the best-supported persons that fit in detector mode)",
    )
    # pipeline.skeleton_matching: group boxes by each box's single-view skeleton from the pose network instead
    # of the paper's box centres (measured better on day 4 of both looks, docs/detector.md); centres for the
    # paper's ablation.
    matcher: Literal["centres", "skeletons", "skeletons-greedy"] = Field(
        "skeletons",
        description="how boxes without person_ids are grouped across views: centres (the paper's 3D box "
        "centres, 75 cm), skeletons (each box's single-view 3D skeleton, one optimal partition per frame) or "
        "skeletons-greedy (the same skeletons, the paper's greedy rule)",
    )
    # pipeline.skeleton_matching, step 5: boxes the detector was unsure of may complete a person seen in other
    # views (never start one). 1 (or any value at or above the detector's threshold) uses sure boxes only.
    candidate_score: float = Field(
        CANDIDATE_SCORE,
        ge=0,
        le=1,
        description="detector mode, skeleton matcher: boxes scored from this up to the detector's threshold "
        "may complete a person seen in other views (1: only the detector's sure boxes)",
    )
    # pipeline.skeleton_matching, step 7: a person only one view saw is dropped when another view sees its
    # joints in free space with no box there. 0 turns it off (depth that cannot be trusted to show free space).
    free_space_mm: float = Field(
        SkeletonMatchConfig.free_space_mm,
        ge=0,
        description="detector mode, skeleton matcher: drop a person only one view saw when another view measures "
        "depth at most this many mm in front of 6 or more of its joints and has no box there (0: never)",
    )
    retry_after_s: int = Field(1, ge=1, le=3600, description="Retry-After seconds sent with a 503")
    # 3 views of 640x480 PNG colour + depth are about 2-3 MB; 64 MiB leaves room for 8 large views.
    max_body_bytes: int = Field(64 * 2**20, ge=1024, description="largest accepted request body, bytes")
    body_timeout_s: float = Field(30.0, gt=0, description="time allowed to receive the whole body (else 408)")
    max_views: int = Field(8, ge=1, le=64, description="most views in one scene")
    # Checked on the image header before decoding, so a small compressed bomb cannot allocate gigabytes.
    max_image_pixels: int = Field(1920 * 1200, ge=1, description="largest accepted image, width x height")
    max_boxes_per_view: int = Field(64, ge=1, description="most reference boxes in one view")
    # Streams (POST /streams/{id}/frames): each holds a tracker (a few KB per person) and answers its frames one
    # at a time. The bound keeps forgotten streams from piling up; the idle time frees the place of a client that
    # left without DELETE. A tracker ends every track after track_max_coast_s unseen anyway (2.5 s by default, at
    # most 60), so a stream idle for a minute has nothing left worth keeping.
    max_streams: int = Field(
        16, ge=1, le=4096, description="streams held at once (a new stream beyond it: 503 with Retry-After)"
    )
    stream_idle_s: float = Field(
        60.0, gt=0, le=86400, description="a stream that gets no frame for this long ends (expires)"
    )
    # service.stream_store: replicas behind a load balancer share their streams through Redis (docs/deploy.md).
    redis_url: str | None = Field(
        None,
        description="Redis URL (redis://host:6379/0) where streams keep their state, so that any replica can take "
        "a stream's next frame; unset: streams live in this process",
    )
    # pipeline.track.TrackerConfig.max_spread_mm, chosen on rendered sequences with the shipped weights; another
    # checkpoint spreads its joints differently (random weights: ~1000 mm) and may need another value.
    track_max_spread_mm: float = Field(
        TrackerConfig.max_spread_mm,
        gt=0,
        description="persons whose median joint spread is above this many mm are answered without a track",
    )
    # pipeline.track.TrackerConfig.min_torso_mm: shorter torsos (neck to mid-hip) are no adult's; on rendered
    # sequences they are the pose network's folded guess at the draped patient.
    track_min_torso_mm: float = Field(
        TrackerConfig.min_torso_mm,
        ge=0,
        le=2000,
        description="persons whose torso (neck to the middle of the hips) is shorter than this many mm are "
        "answered without a track (0 tracks every torso)",
    )
    # pipeline.track.TrackerConfig.min_height_mm: with the room's up direction sent in the scene ("up"), a skeleton
    # spanning less than this along it lies down (on rendered sequences, the patient on the table).
    track_min_height_mm: float = Field(
        TrackerConfig.min_height_mm,
        ge=0,
        le=2000,
        description="streams, for scenes that give the room's up direction: persons whose skeleton spans less "
        "than this many mm along it (lying down, e.g. the patient) are answered without a track (0 tracks all)",
    )
    # pipeline.track.TrackerConfig.lying_height_mm / lying_spread_mm: a track whose first frames both span little
    # along up and are unsure (the draped patient, half unfolded by the pose network) waits for confirmation.
    track_lying_height_mm: float = Field(
        TrackerConfig.lying_height_mm,
        ge=0,
        le=2000,
        description="streams, with the room's up: a new track whose skeleton spans less than this many mm along "
        "it AND whose joints' median spread is above ORPOSE_TRACK_LYING_SPREAD_MM (medians over its first "
        "frames) gets no id until that changes: the patient on the table (0: off)",
    )
    track_lying_spread_mm: float = Field(
        TrackerConfig.lying_spread_mm,
        ge=0,
        description="streams: the spread (mm) above which a low new track counts as lying "
        "(ORPOSE_TRACK_LYING_HEIGHT_MM)",
    )
    # pipeline.track.TrackerConfig.max_coast_s: a confirmed track whose person no frame shows coasts this long, and
    # takes the person back when they reappear near where it predicts them; after it, they get a new id.
    track_max_coast_s: float = Field(
        TrackerConfig.max_coast_s,
        gt=0,
        le=60,
        description="streams: seconds a track waits, unseen, for its person to reappear before it ends (longer "
        "keeps ids across longer occlusions, and risks giving one person's id to another who comes close)",
    )
    # Scenes without "up": a stream finds the floor in its first frame's depth images (posenet.rig.check.
    # floor_of_frame: within 0.3 degrees of the room frame on rendered MVOR-rig frames, some tens of ms once).
    # pipeline.background: each stream learns its cameras' static depth, and a new track is confirmed only once its
    # person moved, stood in front of it, or held a sure upright pose (docs/tracking.md, "An OR it never saw").
    track_static_scene: bool = Field(
        True,
        description="learn each camera's static depth and confirm no track on what never moves (the draped "
        "table, a coat, a monitor); false: confirm tracks on hits alone",
    )
    track_floor_up: bool = Field(
        True,
        description="streams, for scenes that give no up: take the room's up from the floor seen in the depth "
        "images (found once per stream and rig), so that persons lying down are left untracked there too",
    )
    # pipeline.track.TrackerConfig.unsure_gate_mm: persons of boxes the detector was unsure of in every view
    # (pipeline.skeleton_matching.group_unsure) may continue a track this close to it, never start one.
    track_unsure_gate_mm: float = Field(
        TrackerConfig.unsure_gate_mm,
        ge=0,
        le=2000,
        description="streams: a person the detector was unsure of in every view (scores from "
        "ORPOSE_CANDIDATE_SCORE up to its threshold) continues a confirmed track that no other person took "
        "when it lies within this many mm of it, and is then answered with unsure true (0: never used)",
    )
    token: SecretStr | None = Field(
        None,
        description="bearer token; when set every route but /health needs it (the docs too, unless "
        "public_docs)",
    )
    # With a token the docs and the schema need it too, unless this says they are public.
    public_docs: bool = Field(
        False, description="serve /docs, /redoc and /openapi.json without the token (when a token is set)"
    )
    # Prometheus scrapers often carry no token: this serves GET /metrics without one (it tells request counts,
    # latencies and the models' runtimes, never a request's content).
    metrics_open: bool = Field(
        False,
        description="serve GET /metrics without the token (when a token is set), for Prometheus scrapers",
    )
    # Unset: load the detector when a checkpoint is given or shipped weights exist; otherwise serve reference-box
    # mode only (detector-mode requests then get a 422 that says so) rather than refusing to start.
    load_detector: bool | None = Field(
        None,
        description="load the detector: true = required, false = reference-box mode only, "
        "unset = load it when its weights exist",
    )

    @field_validator("token", mode="before")
    @classmethod
    def _empty_token_is_none(cls, value):
        # compose passes ORPOSE_TOKEN="" when the shell has none: that means no token, not the empty token.
        return None if value in ("", None) else value
