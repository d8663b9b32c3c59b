"""Adapt the pose network to a new OR from its recordings, without any 3D pose (unsupervised).

From the shipped weights, on days 1-3 of a recording with reference boxes, 30 minutes, with labelled rendered
scenes in every step::

    python -m posenet.training.adapt --data DIR --annotations A.json --days 1 2 3 --out runs/adapt \\
        --source-data data/mvor_twin data/synth_mvorrig --minutes 30
    python -m posenet.training.adapt --data DIR --out runs/adapt --resume --minutes 45       # continue the run

With the shipped detector's boxes instead of the file's (``pipeline.group`` runs the detector and the
cross-view matcher and writes the boxes with person ids; ``posenet`` never imports ``detector``)::

    python -m pipeline.group --data DIR --annotations A.json --days 1 2 3 --out DIR/detector_boxes.json
    python -m posenet.training.adapt --data DIR --annotations A.json --days 1 2 3 --boxes detector \\
        --detector-boxes DIR/detector_boxes.json --source-data data/mvor_twin --out runs/adapt

The target annotation file gives the frames, cameras and (with ``--boxes annotations``) the 2D boxes with person
ids; its ``annotations3D`` are dropped as it is parsed and never reach the reader (``poses=False``). Each step
runs ``--scenes-per-step`` target scenes and ``--source-per-step`` labelled scenes of ``--source-data`` and
sums, each weighted by its flag (0 switches it off, for an ablation):

- ``--consistency``: each view's own estimate of a person seen in >= 2 views against the fused estimate;
- ``--pseudo``: the paper's MPJPE against the flip-tested fused estimates of an EMA teacher, where certain;
- ``--bones``: bone lengths within the source data's per-bone mean +- std;
- ``--source``: the paper's supervised MPJPE on the labelled rendered scenes, so the network cannot collapse.

The run folder gets ``config.json``, ``log.jsonl`` (per epoch: each loss, the share of joints pseudo-labelled,
minutes) and ``last/`` (``posenet.net.checkpoint``'s format, the teacher's weights; ``train_state.pt`` holds the
student and the optimiser for ``--resume``). ``python -m posenet.evaluation.predict --checkpoint RUN`` and the service
(``ORPOSE_POSE_CHECKPOINT=RUN``) load it. See ``docs/posenet.md``.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from safetensors.torch import load_file
from tqdm import tqdm

from posenet.cli import (
    add_annotations,
    add_config_options,
    add_data,
    add_days,
    add_threads,
    config_options,
)
from posenet.evaluation.predict import read_subsample
from posenet.net.augment import AugmentConfig
from posenet.net.checkpoint import (
    DEFAULT_WEIGHTS,
    checkpoint_files,
    load_checkpoint,
    save_checkpoint,
    sectioned,
    training_config,
)
from posenet.net.inputs import build_scene
from posenet.net.loss import mpjpe
from posenet.net.model import ModelConfig, PoseNet
from posenet.scene import Scene
from posenet.training.adapt_losses import (
    bone_loss,
    bone_statistics,
    ema_update,
    mean_or_zero,
    pseudo_labels,
    scene_view_estimates,
    view_consistency,
)
from posenet.training.schedule import Schedule
from posenet.training.train import CachedFrames, run_config, scene_loss, trainable_frames

LOSSES = ("consistency", "pseudo", "bones", "source")


@dataclass
class AdaptConfig:
    data: str
    out: str
    annotations: str | None = None  # default: DATA/annotations.json; its annotations3D are never read
    days: list[int] | None = None  # target days to adapt on (default: all in the file)
    init: str | None = None  # checkpoint to start from; None: the shipped weights
    boxes: str = "annotations"  # "annotations": the file's boxes and ids; "detector": --detector-boxes
    detector_boxes: str | None = None  # with boxes="detector": pipeline.group's output
    source_data: list[str] = field(default_factory=list)  # labelled rendered datasets (DIR/annotations.json)
    # Reader subsampling; None: what the network reads (its InputConfig.read_size, as posenet.evaluation.predict and the
    # service read), e.g. 2 for 640x480 views and the shipped 320x240 network.
    subsample: int | None = None
    epochs: int = 5
    minutes: float | None = (
        None  # a budget of adaptation minutes (posenet.training.schedule); overrides epochs
    )
    clock: str = "wall"
    lr: float = (
        2e-4  # a fine-tune: a fifth of training's 1e-3, so that the first noisy targets do little harm
    )
    warmup: float = 0.05
    decay_start: float = 0.75
    scenes_per_step: int = 4  # target scenes per step
    source_per_step: int = 2  # labelled rendered scenes per step
    # loss weights (0 switches a loss off); all losses are in mm, so 1 weighs them like the paper's MPJPE
    consistency: float = 1.0
    pseudo: float = 1.0
    bones: float = 1.0
    source: float = 1.0
    ema: float = 0.99  # teacher momentum per step: it averages the student over ~100 steps
    # mm: spread + half the flip disagreement of a kept pseudo-label. With the shipped weights on 6 rendered alt-look
    # frames it keeps 26 % of the joints, whose error is 6.7 cm against 15.0 cm for the others (docs/posenet.md)
    pseudo_max_uncertainty: float = 300.0
    bone_tolerance: float = 1.0  # bones may leave the source mean by this many std before they cost anything
    min_views: int = 2  # views a person needs for the consistency loss
    seed: int = 0
    threads: int | None = None
    device: str | None = None
    precision: str = "auto"
    cache: bool = True  # keep decoded frames in memory
    max_frames: int | None = None  # only the first N target frames (smoke runs)
    model: ModelConfig | None = None  # filled in from --init
    augment: AugmentConfig | None = None  # filled in from --init's config (its training augmentation)
    bone_stats: dict | None = None  # filled in from the source data: {"mean": [B], "std": [B]} mm
    data_description: dict = field(default_factory=dict)

    @staticmethod
    def from_dict(d: dict) -> AdaptConfig:
        d = dict(training_config(d))
        if isinstance(d.get("model"), dict):
            d["model"] = ModelConfig.from_dict(d["model"])
        if isinstance(d.get("augment"), dict):
            d["augment"] = AugmentConfig(**d["augment"])
        return AdaptConfig(**d)


# ----------------------------------------------------------------------------- data
def load_target_annotations(cfg: AdaptConfig) -> dict:
    """The target's annotation dict without ``annotations3D``; with ``--boxes detector`` its boxes replaced by
    ``pipeline.group``'s (person ids from the matcher)."""
    from posenet.data.mvor import load_annotations

    path = cfg.annotations or str(Path(cfg.data) / "annotations.json")
    gt = load_annotations(path, poses=False)
    if cfg.boxes == "detector":
        if not cfg.detector_boxes or not Path(cfg.detector_boxes).is_file():
            raise FileNotFoundError(
                f"--boxes detector reads the detector's boxes grouped into persons from --detector-boxes "
                f"(got {cfg.detector_boxes!r}); write them with `python -m pipeline.group --data {cfg.data} "
                f"--annotations {path} --out BOXES.json`"
            )
        boxes = json.loads(Path(cfg.detector_boxes).read_text())
        if not isinstance(boxes, list) or any(
            not isinstance(b, dict) or {"image_id", "bbox", "person_id"} - b.keys() for b in boxes
        ):
            raise ValueError(
                f"{cfg.detector_boxes}: expected a list of {{image_id, bbox, person_id}} (pipeline.group's output)"
            )
        gt["annotations"] = boxes
    elif cfg.boxes != "annotations":
        raise ValueError(f"boxes must be 'annotations' or 'detector', got {cfg.boxes!r}")
    return gt


def source_bone_statistics(roots: list[str]) -> dict:
    """Per-bone mean and std (mm) of the 3D poses of the labelled source datasets (never the target's)."""
    from posenet.data.mvor import MvorDataset

    poses, valid = [], []
    for root in roots:
        meta = MvorDataset(None, Path(root) / "annotations.json", modalities=())
        for i in range(len(meta)):
            s = meta[i]
            poses.append(torch.from_numpy(s.poses))
            valid.append(torch.from_numpy(s.valid))
    if not poses:
        raise ValueError(
            "--bones > 0 needs --source-data with 3D poses for the bone statistics; or pass --bones 0"
        )
    mean, std = bone_statistics(torch.cat(poses), torch.cat(valid))
    return {"mean": [round(x, 3) for x in mean.tolist()], "std": [round(x, 3) for x in std.tolist()]}


class Frames:
    """A dataset's usable frames, drawn in a seeded order that restarts from the seed every epoch (so a resumed
    run draws what an uninterrupted one would), cycling when a step asks for more than are left."""

    def __init__(self, dataset, indices: list[int]) -> None:
        self.dataset, self.indices = dataset, indices
        self.order: list[int] = []
        self.generator = torch.Generator()

    def __len__(self) -> int:
        return len(self.indices)

    def restart(self, seed: int) -> None:
        self.generator.manual_seed(seed)
        self.order = []

    def take(self, n: int) -> list:
        out = []
        while len(out) < n and self.indices:
            if not self.order:
                self.order = torch.randperm(len(self.indices), generator=self.generator).tolist()
            out.append(self.dataset[self.indices[self.order.pop()]])
        return out


def target_frames(cfg: AdaptConfig, gt: dict) -> Frames:
    """The target's frames with a boxed, identified person (no 3D poses: ``poses=False``); ``gt`` is
    :func:`load_target_annotations`' answer."""
    from posenet.data.mvor import MvorDataset

    dataset = MvorDataset(cfg.data, gt, cfg.subsample, _modalities(cfg), days=cfg.days, poses=False)
    frames = trainable_frames(gt, cfg.subsample, cfg.days, "boxed")  # indices into the days kept
    return Frames(CachedFrames(dataset) if cfg.cache else dataset, frames[: cfg.max_frames or None])


def source_frames(cfg: AdaptConfig) -> Frames:
    """The frames with an annotated, boxed pose of every ``--source-data`` folder, as one dataset."""
    from posenet.data.mvor import MvorDataset, load_annotations

    parts, indices = [], []
    for root in cfg.source_data:
        gt = load_annotations(Path(root) / "annotations.json")
        dataset = MvorDataset(root, gt, cfg.subsample, _modalities(cfg))
        offset = sum(len(p) for p in parts)
        indices += [offset + i for i in trainable_frames(gt, cfg.subsample, None)]
        parts.append(CachedFrames(dataset) if cfg.cache else dataset)
    return Frames(torch.utils.data.ConcatDataset(parts) if parts else [], indices)


def _modalities(cfg: AdaptConfig) -> tuple[str, ...]:
    return ("depth",) if cfg.model.inputs.modality == "depth" else ("color", "depth")


# ----------------------------------------------------------------------------- one step
@dataclass
class StepLosses:
    total: torch.Tensor
    parts: dict[str, float]  # each loss (mm) before weighting
    pseudo_share: float  # share of the target joints kept as pseudo-labels


def adapt_step(
    student: PoseNet,
    teacher: PoseNet,
    targets: list[Scene],
    sources: list[Scene],
    cfg: AdaptConfig,
    generator: torch.Generator,
) -> StepLosses:
    """The weighted loss of one step: ``targets`` (boxed persons, no poses) and ``sources`` (annotated)."""
    inputs = student.config.inputs
    weights = {k: getattr(cfg, k) for k in LOSSES}
    labels = []
    if weights["pseudo"] > 0 and targets:
        n = len(targets)
        with torch.no_grad():
            plain = [build_scene(p.views, p.boxes, p.has_box, inputs) for p in targets]
            mirrored = [build_scene(p.views, p.boxes, p.has_box, inputs, mirror=True) for p in targets]
            outs = teacher(plain + mirrored)
        labels = [
            pseudo_labels(a, b, cfg.pseudo_max_uncertainty) for a, b in zip(outs[:n], outs[n:], strict=True)
        ]
    if weights["source"] <= 0:
        sources = []
    scenes = [
        build_scene(p.views, p.boxes, p.has_box, inputs, cfg.augment, generator) for p in targets + sources
    ]
    outs = student(scenes)
    t_outs, t_scenes = outs[: len(targets)], scenes[: len(targets)]
    like = outs[0].joints
    eps = student.config.eps
    parts: dict[str, torch.Tensor] = {}
    if weights["consistency"] > 0:
        dists = []
        for o, s in zip(t_outs, t_scenes, strict=True):
            views = scene_view_estimates(o, s, eps)
            dists.append(view_consistency(views.joints, views.has_points, o.joints, cfg.min_views))
        parts["consistency"] = mean_or_zero(dists, like)
    share = 0.0
    if labels:
        keep = torch.cat([lab.keep for lab in labels]).to(like.device)
        parts["pseudo"] = mpjpe(
            torch.cat([o.joints for o in t_outs]), torch.cat([lab.joints for lab in labels]).to(like), keep
        )
        share = float(keep.float().mean()) if keep.numel() else 0.0
    if weights["bones"] > 0 and targets:
        mean, std = (torch.tensor(cfg.bone_stats[k]) for k in ("mean", "std"))
        parts["bones"] = mean_or_zero(
            [bone_loss(o.joints, o.has_points, mean, std, cfg.bone_tolerance) for o in t_outs], like
        )
    if sources:
        s_out = zip(outs[len(targets) :], sources, scenes[len(targets) :], strict=True)
        parts["source"] = torch.stack(
            [scene_loss(student.config, o, p, s.cameras) for o, p, s in s_out]
        ).mean()
    total = sum((weights[k] * v for k, v in parts.items()), like.sum() * 0.0)
    return StepLosses(total, {k: float(v.detach()) for k, v in parts.items()}, share)


# ----------------------------------------------------------------------------- the run
def _state_of(model: PoseNet) -> dict:
    return {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}


def adapt(cfg: AdaptConfig) -> dict:
    """Run (or resume) an adaptation; return ``{"history": [per-epoch records]}``."""
    device = cfg.device or ("cuda" if torch.cuda.is_available() else "cpu")
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    out = Path(cfg.out)
    state_file = out / "last" / "train_state.pt"
    resume = state_file.is_file()
    if resume:
        student = PoseNet(dataclasses.replace(cfg.model, precision=cfg.precision))
    else:
        student, init_config = load_checkpoint(cfg.init, "cpu", cfg.precision)
        cfg.model = dataclasses.replace(student.config, precision="auto")
        if cfg.augment is None:
            cfg.augment = AugmentConfig(**training_config(init_config).get("augment") or {})
    if cfg.model.aggregation != "3d":
        raise ValueError(
            "posenet.training.adapt needs a network with the paper's 3D aggregation (model.aggregation '3d')"
        )
    if cfg.source > 0 and not cfg.source_data:
        raise ValueError("--source > 0 needs --source-data (labelled rendered scenes); or pass --source 0")
    if cfg.bones > 0 and cfg.bone_stats is None:
        cfg.bone_stats = source_bone_statistics(cfg.source_data)

    gt = load_target_annotations(cfg)  # read once: for the default read size and the frames
    if cfg.subsample is None:
        cfg.subsample = read_subsample(gt, cfg.model.inputs, cfg.days)
    target = target_frames(cfg, gt)
    if not len(target):
        raise ValueError(f"no target frame with a boxed, identified person in days {cfg.days or 'all'}")
    source = source_frames(cfg) if cfg.source > 0 else Frames([], [])
    cfg.data_description = {
        "init": str(cfg.init or DEFAULT_WEIGHTS),
        "annotations": str(cfg.annotations or Path(cfg.data) / "annotations.json"),
        "target_days": cfg.days,
        "target_frames": len(target),
        "boxes": cfg.boxes if cfg.boxes == "annotations" else f"detector ({cfg.detector_boxes})",
        "source_frames": len(source),
        "annotations3D": "never read (posenet.data.mvor poses=False)",
    }

    student = student.to(device).train()
    teacher = copy.deepcopy(student).eval().requires_grad_(False)
    optimiser = torch.optim.Adam(student.parameters(), lr=cfg.lr)
    steps_per_epoch = -(-len(target) // cfg.scenes_per_step)
    schedule = Schedule(
        cfg.lr, cfg.epochs * steps_per_epoch, cfg.decay_start, cfg.warmup, cfg.minutes, cfg.clock
    )
    start_epoch = 0
    if resume:
        state = torch.load(state_file, map_location="cpu", weights_only=False)
        student.load_state_dict(state["student"])
        teacher.load_state_dict(load_file(out / "last" / "model.safetensors"))
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, schedule.step, schedule.elapsed = state["epoch"], state["step"], state["elapsed_s"]
        print(f"resuming {out} at epoch {start_epoch}", file=sys.stderr)
    init = json.loads(checkpoint_files(cfg.init)[1].read_text())
    trained_on = {
        "init": cfg.data_description["init"],
        "init_trained_on": init.get("trained_on"),
        "data": cfg.data,
        "days": cfg.days,
        "frames": len(target),
        "boxes": cfg.data_description["boxes"],
        "source_data": list(cfg.source_data or []),
        "poses": "none of the target's (adapted without 3D labels)",
    }
    config_dict = sectioned(dataclasses.asdict(cfg), trained_on)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(config_dict, indent=2, default=str))
    print(f"precision: {student.precision().name}: {student.precision().reason}", file=sys.stderr)

    history = []
    epochs = cfg.epochs if cfg.minutes is None else 10**9  # with a budget, as many epochs as the time allows
    for epoch in range(start_epoch, epochs):
        if schedule.spent:
            break
        target.restart(cfg.seed * 100003 + epoch * 1009)
        source.restart(cfg.seed * 100003 + epoch * 1009 + 17)
        gen = torch.Generator().manual_seed(cfg.seed * 100003 + epoch * 1009 + 1)
        desc = f"adapt {epoch + 1}" + (f"/{cfg.epochs}" if cfg.minutes is None else f", {cfg.minutes:g} min")
        bar = tqdm(range(steps_per_epoch), desc=desc, leave=False)
        sums: dict[str, float] = {}
        steps, t0 = 0, time.time()
        for _ in bar:
            targets = [Scene.from_sample(x, "boxed") for x in target.take(cfg.scenes_per_step)]
            targets = [p for p in targets if p.num_persons]
            labelled = [Scene.from_sample(x, "annotated") for x in source.take(cfg.source_per_step)]
            labelled = [p for p in labelled if p.num_persons]
            if not targets:
                continue
            lr = schedule.begin(optimiser)
            losses = adapt_step(student, teacher, targets, labelled, cfg, gen)
            optimiser.zero_grad(set_to_none=True)
            losses.total.backward()
            optimiser.step()
            ema_update(teacher, student, cfg.ema)
            schedule.end()
            steps += 1
            for k, v in {
                **losses.parts,
                "pseudo_share": losses.pseudo_share,
                "total": float(losses.total.detach()),
            }.items():
                sums[k] = sums.get(k, 0.0) + v
            bar.set_postfix(
                {k: f"{v:.1f}" for k, v in losses.parts.items()},
                lr=f"{lr:.1e}",
                min=f"{schedule.elapsed / 60:.1f}",
            )
            if schedule.spent:
                break
        record = {
            "epoch": epoch + 1,
            **{k: round(v / max(steps, 1), 4) for k, v in sums.items()},
            "steps": schedule.step,
            "seconds": round(time.time() - t0, 1),
            "minutes": round(schedule.elapsed / 60.0, 2),
        }
        train_state = {
            "epoch": epoch + 1,
            "student": _state_of(student),
            "optimiser": optimiser.state_dict(),
            "step": schedule.step,
            "elapsed_s": schedule.elapsed,
        }
        save_checkpoint(out / "last", teacher, config_dict, train_state)
        with open(out / "log.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        print(json.dumps(record), file=sys.stderr)
        history.append(record)
    return {"history": history}


# ----------------------------------------------------------------------------- command line
def build_parser() -> argparse.ArgumentParser:
    d = AdaptConfig("", "")
    p = argparse.ArgumentParser(
        prog="python -m posenet.training.adapt",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Examples:\n"
        + "\n".join(line for line in __doc__.splitlines() if line.startswith("    python")),
    )
    g = p.add_argument_group("target data (no 3D poses are read)")
    add_data(g, help="recordings in MVOR's layout: dayD/camC/{color,depth}/NNNNNN.png")
    add_annotations(g, help="MVOR-format json: frames, cameras, boxes (default: DATA/annotations.json)")
    add_days(g, help="days to adapt on (default: all in the file)")
    g.add_argument(
        "--boxes",
        choices=("annotations", "detector"),
        default=d.boxes,
        help="annotations: the file's 2D boxes and person ids; detector: --detector-boxes (pipeline.group)",
    )
    g.add_argument(
        "--detector-boxes", help="with --boxes detector: the json that `python -m pipeline.group` wrote"
    )
    g.add_argument(
        "--subsample",
        type=int,
        default=d.subsample,
        help="reader subsampling (default: the network's own read size, e.g. 2 for 640x480 views)",
    )
    g.add_argument("--max-frames", type=int, help="only the first N target frames (smoke runs)")
    g.add_argument("--no-cache", dest="cache", action="store_false", help="do not keep frames in RAM")
    g = p.add_argument_group("model and source data")
    g.add_argument(
        "--init", help="checkpoint to adapt (default: the shipped posenet/weights/default.safetensors)"
    )
    g.add_argument(
        "--source-data",
        nargs="+",
        default=[],
        metavar="DIR",
        help="labelled rendered datasets (DIR/annotations.json)",
    )
    g.add_argument("--out", required=True, help="run folder: config.json, log.jsonl, last/")
    g = p.add_argument_group("losses (weights; 0 switches one off)")
    add_config_options(
        g,
        d,
        {
            "consistency": "each view's estimate vs the fused one",
            "pseudo": "MPJPE to the EMA teacher's confident estimates",
            "bones": "bone lengths within the source's mean +- std",
            "source": "the paper's MPJPE on the --source-data scenes",
            "ema": "teacher momentum per step",
            "pseudo_max_uncertainty": "mm: a teacher joint is a target when its spread + half its flip "
            "disagreement is at most this",
            "bone_tolerance": "free band, in source std",
            "min_views": "views a person needs for --consistency",
        },
    )
    g = p.add_argument_group("optimisation")
    g.add_argument("--epochs", type=int, help=f"passes over the target frames (default {d.epochs})")
    g.add_argument(
        "--minutes", type=float, help="a budget of minutes instead of --epochs (the LR follows it)"
    )
    g.add_argument("--clock", choices=("wall", "cpu"), default=d.clock, help="what --minutes counts")
    add_config_options(
        g,
        d,
        {
            "lr": "Adam learning rate",
            "warmup": "fraction with a linear LR warm-up",
            "decay_start": "fraction after which the LR decays",
            "scenes_per_step": "target scenes per step",
            "source_per_step": "labelled scenes per step",
            "seed": "seed of the order and the augmentation",
        },
    )
    g = p.add_argument_group("runtime")
    add_threads(g)
    g.add_argument("--device", help="cpu or cuda (default: cuda if available)")
    g.add_argument("--precision", default=d.precision, help="U-Net precision here: auto, fp32 or bf16")
    g.add_argument("--resume", action="store_true", help="continue the run in --out from last/")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)

    def fresh() -> AdaptConfig:
        return AdaptConfig(**config_options(args, AdaptConfig))

    adapt(run_config(args, AdaptConfig.from_dict, ("epochs", "minutes", "threads", "device"), fresh))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
