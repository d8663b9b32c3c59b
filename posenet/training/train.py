"""Train the pose network end to end through the cameras (MPJPE in mm as the loss), one fold at a time.

Single process (the CPU preset, the default)::

    python -m posenet.training.train --data DIR --holdout-day 4 --out runs/fold4
    python -m posenet.training.train --data DIR --holdout-day 4 --out runs/fold4 --resume      # continue a run

The paper's settings (full 320x240 images, 288x208 random crops, batch of 1 scene, Adam 1e-3, 200 epochs)::

    python -m posenet.training.train --preset paper --data DIR --holdout-day 4 --out runs/paper4

Distributed data-parallel (gloo on CPU, nccl on GPUs)::

    torchrun --nproc_per_node 2 -m posenet.training.train --data DIR --holdout-day 4 --out runs/fold4

``--annotations`` defaults to ``DIR/annotations.json`` (the renderer's layout); for MVOR pass
``camma_mvor_2018.json``. The run folder gets ``config.json`` (the resolved config), ``log.jsonl`` (one line
per epoch: loss, validation MPJPE), and the checkpoints ``last/`` and ``best/`` (lowest validation MPJPE on
the held-out day), each ``model.safetensors`` + ``config.json`` + ``train_state.pt``. See ``docs/posenet.md``
for the presets and how the CPU preset differs from the paper.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
import torch.distributed as dist
from tqdm import tqdm

from posenet.boxes import person_ids
from posenet.cli import add_annotations, add_config_options, add_data, add_threads, config_options
from posenet.net.augment import AugmentConfig, detector_like_boxes
from posenet.net.checkpoint import save_checkpoint, sectioned, training_config
from posenet.net.checkpoint_files import keep_input_channels
from posenet.net.inputs import InputConfig, build_scene, record_read_size
from posenet.net.loss import mpjpe, reprojection_2d
from posenet.net.model import ModelConfig, PoseNet
from posenet.net.unet import UNetConfig, widen_state_dict
from posenet.runtime.execution import PRECISIONS
from posenet.scene import Scene
from posenet.training.adapt_losses import scene_view_estimates
from posenet.training.schedule import Schedule, lr_factor  # noqa: F401  (lr_factor: posenet.training.train's public name)


@dataclass
class TrainConfig:
    data: str
    out: str
    annotations: str | None = None  # default: DATA/annotations.json
    # More datasets (MVOR layout, each with its own annotations.json) whose every day is used for training, e.g.
    # procedural scenes beside the MVOR twin. The held-out day only ever refers to --data.
    extra_data: list[str] = field(default_factory=list)
    # Start from these weights (a run folder, checkpoint folder or NAME.safetensors, e.g. the shipped
    # posenet/weights/default.safetensors) with a fresh optimiser and schedule; the model config must match.
    init: str | None = None
    # Datasets watched during training, never trained on and never used to choose a checkpoint: "DIR" (its
    # --holdout-day) or "DIR:D,D" (those days), e.g. the unseen look's day 4 beside the held-out day of --data.
    # Each is evaluated whenever the held-out day is, logged as watch_NAME_cm (overall MPJPE).
    watch: list[str] = field(default_factory=list)
    holdout_day: int | None = (
        None  # the fold's test day (validation); None trains on every day, no validation
    )
    preset: str = "cpu"
    subsample: int = 2  # image subsampling of the reader: 2 gives the paper's 320x240
    epochs: int = 60
    # A wall-clock budget of training minutes (validation not counted): when set, training runs until it is
    # spent whatever ``epochs`` says, and the LR schedule (warm-up, cosine decay) follows the elapsed fraction
    # of the budget instead of the step count: "the best model in 30 minutes".
    minutes: float | None = None
    # What the budget counts: "wall" (seconds of the steps, as a user waits for them) or "cpu" (this process's
    # CPU seconds: CPU-minutes, which a shared, loaded machine does not inflate; with --threads 1 one core's).
    clock: str = "wall"
    warmup: float = 0.0  # fraction of training (steps or budget) with a linear LR warm-up from 10 %
    # Weight of a second MPJPE on each view's own estimate (the softmax over that view's points only: what the
    # skeleton matcher compares across views, pipeline.skeleton_matching) beside the paper's loss on the fused
    # estimate. 0 (default): the paper's loss alone.
    view_loss: float = 0.0
    lr: float = 1e-3  # Adam, as the paper
    scenes_per_step: int = 4  # scenes per optimiser step (the paper: 1)
    decay_start: float = 0.75  # cosine decay of the LR to 0 over the last quarter; 1.0 keeps it constant
    val_every: int = 5  # epochs between validations (and always after the last epoch)
    val_every_minutes: float | None = (
        None  # with --minutes: validate after the epoch that passes each N minutes
    )
    threads: int | None = None  # torch CPU threads (default: torch's choice)
    seed: int = 0
    cache: bool = True  # keep decoded frames in memory (num_workers must then be 0)
    num_workers: int = 0  # DataLoader workers for image decoding (without cache)
    max_frames: int | None = None  # use only the first N training frames (smoke runs)
    device: str | None = None  # default: cuda if available, else cpu
    model: ModelConfig = field(default_factory=ModelConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)
    data_description: dict = field(default_factory=dict)  # filled in at run time: days, frames, poses

    @staticmethod
    def from_dict(d: dict) -> TrainConfig:
        d = dict(training_config(d))
        d["model"] = (
            ModelConfig.from_dict(d["model"])
            if isinstance(d.get("model"), dict)
            else d.get("model", ModelConfig())
        )
        d["augment"] = (
            AugmentConfig(**d["augment"]) if isinstance(d.get("augment"), dict) else d.get("augment")
        )
        return TrainConfig(**d)


# The presets live in posenet/configs/NAME.json; anything given on the command line overrides them.
PRESET_DIR = Path(__file__).parents[1] / "configs"
PRESETS: dict[str, dict] = {
    f.stem: {k: v for k, v in json.loads(f.read_text()).items() if k != "description"}
    for f in sorted(PRESET_DIR.glob("*.json"))
}


def resolve_config(args: argparse.Namespace) -> TrainConfig:
    """Preset defaults, overridden by every command-line option that was given."""
    if args.preset not in PRESETS:
        raise ValueError(f"unknown preset {args.preset!r}; choose from {sorted(PRESETS)}")
    preset = json.loads(json.dumps(PRESETS[args.preset]))  # a deep copy
    inputs = preset["model"].pop("inputs")
    for key in ("modality", "crop_size", "extra_depth"):
        if getattr(args, key) is not None:
            inputs[key] = getattr(args, key)
    model = preset.pop("model")
    for key in ("base", "depth", "precision", "channels_last"):
        if getattr(args, key) is not None:
            model[key] = getattr(args, key)
    if args.precision is None and os.environ.get("ORPOSE_PRECISION"):
        model["precision"] = os.environ["ORPOSE_PRECISION"]
    if args.loss is not None:
        model["aggregation"] = args.loss
    augment = {**preset.pop("augment"), **config_options(args, AugmentConfig)}
    nested = ("model", "augment", "data_description", "preset")
    given = {k: v for k, v in config_options(args, TrainConfig).items() if k not in nested}
    cfg = {**preset, **given, "preset": args.preset}
    return TrainConfig(
        **cfg, model=ModelConfig(inputs=InputConfig(**inputs), **model), augment=AugmentConfig(**augment)
    )


# ----------------------------------------------------------------------------- data
class CachedFrames(torch.utils.data.Dataset):
    """Decoded frames kept in memory after their first read (uint8 colour, uint16 depth: ~0.4 MB per view at
    320x240), so later epochs skip PNG decoding."""

    def __init__(self, dataset) -> None:
        self.dataset = dataset
        self.cache: dict[int, object] = {}

    def __len__(self) -> int:
        return len(self.dataset)

    def __getitem__(self, i: int):
        if i not in self.cache:
            self.cache[i] = self.dataset[i]
        return self.cache[i]


def trainable_frames(annotations: dict, subsample: int, days, which: str = "annotated") -> list[int]:
    """Indices of the frames with someone to train on, read from the annotations (no images): ``"annotated"``,
    a 3D pose that has a box; ``"boxed"``, a person id (>= 0) with a box (never reads 3D poses)."""
    from posenet.data.mvor import MvorDataset

    if which not in ("annotated", "boxed"):
        raise ValueError(f"which must be 'annotated' or 'boxed', got {which!r}")
    poses = which == "annotated"
    meta = MvorDataset(None, annotations, subsample=subsample, modalities=(), days=days, poses=poses)
    keep = []
    for i in range(len(meta)):
        s = meta[i]
        if poses:
            found = any(any(b is not None for b in s.person_boxes(int(p))) for p in s.person_ids)
        else:
            found = bool(person_ids([v.box_person_ids for v in s.views]))
        if found:
            keep.append(i)
    return keep


# ----------------------------------------------------------------------------- distributed
def setup_distributed(device: str) -> tuple[int, int]:
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1 and not dist.is_initialized():
        dist.init_process_group("nccl" if device.startswith("cuda") else "gloo")
    return (dist.get_rank(), dist.get_world_size()) if dist.is_initialized() else (0, 1)


def scene_loss(model_config: ModelConfig, out, persons, cameras) -> torch.Tensor:
    if model_config.aggregation == "2d":
        return reprojection_2d(out.uv_hat, persons.poses, persons.valid, out.view_valid, cameras)
    return mpjpe(out.joints, persons.poses.to(out.joints.device), persons.valid.to(out.joints.device))


def single_view_loss(model_config: ModelConfig, out, persons, scene) -> torch.Tensor:
    """MPJPE (mm) of every (person, view) estimate from that view's points alone, over the views that box the
    person: ``out`` of the network on ``scene`` (``posenet.net.inputs.SceneInput``), ``persons`` its annotations."""
    views = scene_view_estimates(out, scene, model_config.eps)
    dev = views.joints.device
    P, V, J, _ = views.joints.shape
    target = persons.poses.to(dev)[:, None].expand(P, V, J, 3)
    valid = persons.valid.to(dev)[:, None] & views.has_points[..., None]  # (P, V, J)
    return mpjpe(views.joints.reshape(P * V, J, 3), target.reshape(P * V, J, 3), valid.reshape(P * V, J))


def validate(model: PoseNet, annotations: dict, dataset, days) -> dict:
    """MPJPE on the held-out day with posenet.evaluation.evaluate (cm), plus the plain mean in mm."""
    from posenet.evaluation.evaluate import evaluate
    from posenet.evaluation.predict import predict_samples
    from posenet.net.infer import PoseEstimator

    preds = predict_samples(PoseEstimator(model, device=None), dataset, which="annotated", progress=False)
    result = evaluate(annotations, preds, days=days)
    return {
        "val_mpjpe_cm": result["overall"],
        "val_average_cm": result["per_joint"]["average"],
        "result": result,
    }


def watch_sets(specs: list[str], holdout_day: int | None, subsample: int, modalities) -> list[tuple]:
    """``(name, annotations, dataset, days)`` for each ``--watch DIR[:D,D]``, read without training on it."""
    from posenet.data.mvor import MvorDataset, load_annotations

    sets = []
    for spec in specs:
        root, _, days_text = spec.partition(":")
        days = [int(d) for d in days_text.split(",") if d] or (
            [holdout_day] if holdout_day is not None else []
        )
        if not days:
            raise ValueError(f"--watch {spec}: give its days (DIR:4) or a --holdout-day")
        annotations = load_annotations(Path(root) / "annotations.json")
        have = MvorDataset(None, annotations, modalities=()).days
        if missing := sorted(set(days) - set(have)):
            raise ValueError(f"--watch {spec}: day(s) {missing} not among the dataset's days {sorted(have)}")
        dataset = MvorDataset(root, annotations, subsample, modalities, days=days)
        sets.append((Path(root).name, annotations, dataset, days))
    return sets


def load_init_weights(model: PoseNet, path: str) -> None:
    """Load the weights of checkpoint ``path`` into ``model``; a clear error when they do not fit its config."""
    from safetensors.torch import load_file

    from posenet.net.checkpoint import checkpoint_files

    weights, config = checkpoint_files(path)
    fix = (
        "give the same --preset, --depth, --modality and --extra-depth as the run that made it, and its --base "
        "or a larger one"
    )
    state = load_file(weights, device="cpu")
    state = _kept_input_channels(state, config, model, path)
    small = _narrower_unet(config, model)
    if small is not None:  # --base above the checkpoint's: widen it, computing what it computed
        state = widen_state_dict(state, small, model.unet, prefix="unet.")
        print(
            f"widened {path} from U-Net base {small.base} to {model.config.base}: the new channels start "
            "disconnected (the network computes what the checkpoint computed) and training connects them",
            file=sys.stderr,
        )
    try:
        missing, unexpected = model.load_state_dict(state, strict=False)
    except RuntimeError as e:  # a tensor of another shape
        raise ValueError(
            f"--init {path} does not fit this run's model ({str(e).splitlines()[-1].strip()}): {fix}"
        ) from None
    if missing or unexpected:
        raise ValueError(
            f"--init {path} does not fit this run's model (missing {missing[:3]}, unexpected {unexpected[:3]}): {fix}"
        )


def _kept_input_channels(state: dict, config_file: Path, model: PoseNet, path: str) -> dict:
    """``state`` for ``model`` when the checkpoint reads more input channels than it (e.g. rgbd weights fine-tuned
    to read depth alone, ``--modality depth``): the first convolution keeps the weights of the channels both read
    (``InputConfig.channels``), every other tensor is unchanged. ``state`` itself when the inputs agree."""
    if not config_file.is_file():
        return state
    saved = json.loads(config_file.read_text()).get("model")
    try:
        old = ModelConfig.from_dict(saved).inputs.channels
    except (TypeError, ValueError, AttributeError):
        return state
    new = model.config.inputs.channels
    if old == new:
        return state
    if not set(new) <= set(old):
        return state  # load_state_dict reports the mismatch
    try:
        state, _ = keep_input_channels(state, len(old), [old.index(c) for c in new])
    except ValueError:
        return state  # load_state_dict reports the mismatch
    print(
        f"--init {path} reads {', '.join(old)}; this run reads {', '.join(new)}: its first convolution keeps "
        "the weights of those channels",
        file=sys.stderr,
    )
    return state


def _narrower_unet(config_file: Path, model: PoseNet) -> UNetConfig | None:
    """The U-Net config of the checkpoint whose config is ``config_file`` when it is ``model``'s but narrower
    (a smaller ``base``, all else equal), else None."""
    if not config_file.is_file():
        return None
    saved = json.loads(config_file.read_text()).get("model")
    if not isinstance(saved, dict):
        return None
    try:
        small = ModelConfig.from_dict(saved).unet
    except (TypeError, ValueError):
        return None
    big = model.config.unet

    def shape(c: UNetConfig) -> tuple[int, int, int]:
        return c.depth, c.in_channels, c.out_channels

    return small if shape(small) == shape(big) and small.base < big.base else None


# ----------------------------------------------------------------------------- training
def train(cfg: TrainConfig) -> dict:
    from posenet.data.mvor import MvorDataset, collate_samples, load_annotations

    device = cfg.device or ("cuda" if torch.cuda.is_available() else "cpu")
    rank, world = setup_distributed(device)
    if device.startswith("cuda") and world > 1:
        device = f"cuda:{int(os.environ.get('LOCAL_RANK', rank))}"
        torch.cuda.set_device(device)  # so that NCCL's collectives of each rank use its own GPU
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    out = Path(cfg.out)
    ann_path = cfg.annotations or str(Path(cfg.data) / "annotations.json")
    annotations = load_annotations(ann_path)

    all_days = sorted(MvorDataset(None, annotations, modalities=()).days)
    if cfg.holdout_day is not None and cfg.holdout_day not in all_days:
        raise ValueError(f"--holdout-day {cfg.holdout_day} is not among the dataset's days {all_days}")
    train_days = [d for d in all_days if d != cfg.holdout_day]
    if not train_days:
        raise ValueError(f"no training days left after holding out day {cfg.holdout_day}")
    modalities = ("depth",) if cfg.model.inputs.modality == "depth" else ("color", "depth")
    full_size = MvorDataset(None, annotations, modalities=(), days=train_days)[0].views[0].camera.size
    record_read_size(cfg.model.inputs, full_size, cfg.subsample)  # the model config records the resolution
    train_set = MvorDataset(cfg.data, annotations, cfg.subsample, modalities, days=train_days)
    frames = trainable_frames(annotations, cfg.subsample, train_days)
    if cfg.max_frames:
        frames = frames[: cfg.max_frames]
    if not frames:
        raise ValueError(f"no training frame with an annotated, boxed pose in days {train_days}")
    train_parts = [torch.utils.data.Subset(CachedFrames(train_set) if cfg.cache else train_set, frames)]
    extra_frames = 0
    for root in cfg.extra_data:
        extra_ann = load_annotations(Path(root) / "annotations.json")
        extra_set = MvorDataset(root, extra_ann, cfg.subsample, modalities)
        extra = trainable_frames(extra_ann, cfg.subsample, None)
        train_parts.append(
            torch.utils.data.Subset(CachedFrames(extra_set) if cfg.cache else extra_set, extra)
        )
        extra_frames += len(extra)
    val_set = None
    if cfg.holdout_day is not None:
        val_set = MvorDataset(cfg.data, annotations, cfg.subsample, modalities, days=[cfg.holdout_day])
    watched = watch_sets(cfg.watch, cfg.holdout_day, cfg.subsample, modalities)
    cfg.data_description = {
        "annotations": str(ann_path),
        "train_days": train_days,
        "holdout_day": cfg.holdout_day,
        "train_frames": len(frames),
        "extra_data": list(cfg.extra_data),
        "extra_train_frames": extra_frames,
        "val_frames": 0 if val_set is None else len(val_set),
        "watched": {name: {"days": days, "frames": len(ds)} for name, _, ds, days in watched},
    }
    if cfg.cache and cfg.num_workers:
        raise ValueError("--cache keeps frames in this process: use it with --num-workers 0")
    subset = torch.utils.data.ConcatDataset(train_parts)
    sampler = torch.utils.data.distributed.DistributedSampler(
        subset, num_replicas=world, rank=rank, shuffle=True, seed=cfg.seed, drop_last=False
    )
    loader = torch.utils.data.DataLoader(
        subset,
        batch_size=cfg.scenes_per_step,
        sampler=sampler,
        collate_fn=collate_samples,
        num_workers=cfg.num_workers,
        persistent_workers=cfg.num_workers > 0,
    )

    model = PoseNet(cfg.model).to(device)
    precision = model.precision()
    cfg.data_description["precision"] = f"{precision.name} ({precision.reason})"
    if rank == 0:
        print(f"precision: {precision.name}: {precision.reason}", file=sys.stderr)
    optimiser = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    # optimiser steps and seconds of training (validation excluded) so far, and the LR they give
    schedule = Schedule(cfg.lr, cfg.epochs * len(loader), cfg.decay_start, cfg.warmup, cfg.minutes, cfg.clock)
    budget_s = schedule.budget_s

    start_epoch, best = 0, float("inf")
    state_file = out / "last" / "train_state.pt"
    if cfg.init and not state_file.is_file():
        load_init_weights(model, cfg.init)
        if rank == 0:
            print(f"initialised from {cfg.init}", file=sys.stderr)
    if state_file.is_file():
        from safetensors.torch import load_file

        state = torch.load(state_file, map_location="cpu", weights_only=False)
        model.load_state_dict(load_file(out / "last" / "model.safetensors"))
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, best = state["epoch"], state["best"]
        # (runs from before the time budget saved a LambdaLR, whose last_epoch is the step count)
        schedule.step = state.get("step", state.get("scheduler", {}).get("last_epoch", 0))
        schedule.elapsed = state.get("elapsed_s", 0.0)
        if rank == 0:
            print(f"resuming {out} at epoch {start_epoch} (best {best:.2f} cm)", file=sys.stderr)
    net = torch.nn.parallel.DistributedDataParallel(model) if world > 1 else model
    trained_on = {
        "data": cfg.data,
        "days": train_days,
        "frames": len(frames),
        "extra_data": list(cfg.extra_data),
        "extra_frames": extra_frames,
        "subsample": cfg.subsample,
        "init": cfg.init,
    }
    config_dict = sectioned(dataclasses.asdict(cfg), trained_on)
    if rank == 0:
        out.mkdir(parents=True, exist_ok=True)
        (out / "config.json").write_text(json.dumps(config_dict, indent=2, default=str))

    history = []
    last_val_minute = schedule.elapsed / 60.0
    epochs = cfg.epochs if budget_s is None else 10**9  # with a budget, as many epochs as the time allows
    for epoch in range(start_epoch, epochs):
        if schedule.spent:
            break
        model.train()
        sampler.set_epoch(epoch)
        gen = torch.Generator().manual_seed(cfg.seed * 100003 + epoch * 1009 + rank)
        desc = f"epoch {epoch + 1}" + (
            f"/{cfg.epochs}" if budget_s is None else f", {cfg.minutes:g} min budget"
        )
        bar = tqdm(loader, desc=desc, disable=rank != 0, leave=False)
        running, seen, crops, t0 = None, 0, 0, time.time()
        for samples in bar:
            persons = [Scene.from_sample(s, "annotated") for s in samples]
            persons = [p for p in persons if p.num_persons]
            if not persons:
                continue
            lr = schedule.begin(optimiser)
            scenes = [
                build_scene(
                    p.views, detector_like(p, cfg.augment, gen), p.has_box, cfg.model.inputs, cfg.augment, gen
                )
                for p in persons
            ]
            outs = net(scenes)
            losses = [
                scene_loss(cfg.model, o, p, s.cameras) for o, p, s in zip(outs, persons, scenes, strict=True)
            ]
            if cfg.view_loss > 0:
                losses = [
                    loss + cfg.view_loss * single_view_loss(cfg.model, o, p, s)
                    for loss, o, p, s in zip(losses, outs, persons, scenes, strict=True)
                ]
            loss = torch.stack(losses).mean()
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            schedule.end()
            seen += len(persons)
            crops += sum(int(sc.has_box.sum()) for sc in scenes)  # person-view crops run
            value = float(loss.detach())
            running = value if running is None else 0.95 * running + 0.05 * value
            bar.set_postfix(loss=f"{running:.1f}", lr=f"{lr:.1e}", min=f"{schedule.elapsed / 60:.1f}")
            if schedule.spent:
                break
        record = {
            "epoch": epoch + 1,
            "train_loss": running,
            "scenes": seen,
            "crops": crops,
            "seconds": round(time.time() - t0, 1),
            "minutes": round(schedule.elapsed / 60.0, 2),
            "steps": schedule.step,
            "lr": lr if seen else None,
        }
        if budget_s is None:
            last = epoch + 1 == cfg.epochs
            due = (epoch + 1) % cfg.val_every == 0
        else:
            last = schedule.spent
            every = cfg.val_every_minutes or cfg.minutes / 6
            due = schedule.elapsed / 60.0 - last_val_minute >= every
        if rank == 0 and val_set is not None and (due or last):
            last_val_minute = schedule.elapsed / 60.0
            metrics = validate(model, annotations, val_set, [cfg.holdout_day])
            record.update({k: v for k, v in metrics.items() if k != "result"})
            for name, watch_annotations, watch_set, days in watched:
                record[f"watch_{name}_cm"] = validate(model, watch_annotations, watch_set, days)[
                    "val_mpjpe_cm"
                ]
        if rank == 0:
            score = record.get("val_mpjpe_cm")
            improved = score is not None and score < best
            best = score if improved else best
            train_state = {
                "epoch": epoch + 1,
                "best": best,
                "optimiser": optimiser.state_dict(),
                "step": schedule.step,
                "elapsed_s": schedule.elapsed,
            }
            save_checkpoint(out / "last", model, config_dict, train_state)
            if improved or (val_set is None and last):
                save_checkpoint(out / "best", model, config_dict, train_state)
            with open(out / "log.jsonl", "a") as f:
                f.write(json.dumps(record) + "\n")
            print(json.dumps(record), file=sys.stderr)
        history.append(record)
        if world > 1:
            dist.barrier()
    if world > 1:
        dist.destroy_process_group()
    return {"history": history, "best_val_mpjpe_cm": best, "rank": rank}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m posenet.training.train",
        description=__doc__.split("\n\n")[0]
        + " Options left out take the preset's value (see --preset); the resolved config is saved in the "
        "run "
        "folder and beside every checkpoint.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Examples:\n"
        + "\n".join(line for line in __doc__.splitlines() if line.strip().startswith(("python", "torchrun"))),
    )
    g = p.add_argument_group("data")
    add_data(g)
    add_annotations(g)
    g.add_argument(
        "--extra-data",
        nargs="+",
        metavar="DIR",
        help="more MVOR-layout datasets (DIR/annotations.json) used whole for training, e.g. procedural scenes",
    )
    g.add_argument(
        "--holdout-day", type=int, help="the fold's held-out day, used for validation (default: none)"
    )
    g.add_argument(
        "--watch",
        nargs="+",
        metavar="DIR[:D,D]",
        help="also evaluate on these datasets whenever the held-out day is evaluated (logged as watch_NAME_cm; "
        "never trained on, never used to choose a checkpoint), e.g. --watch data/mvor_alt:4 for the unseen look",
    )
    g.add_argument(
        "--out", required=True, help="run folder: config.json, log.jsonl, last/ and best/ checkpoints"
    )
    g.add_argument("--subsample", type=int, help="reader subsampling (2: the paper's 320x240 from 640x480)")
    g.add_argument("--max-frames", type=int, help="only the first N training frames (smoke runs)")
    g.add_argument(
        "--init",
        metavar="CKPT",
        help="start from these weights (run folder, checkpoint folder or NAME.safetensors such as "
        "posenet/weights/default.safetensors) with a fresh optimiser and schedule: fine-tuning",
    )
    g.add_argument(
        "--no-cache", dest="cache", action="store_false", default=None, help="do not keep frames in RAM"
    )
    g.add_argument("--num-workers", type=int, help="DataLoader workers (needs --no-cache)")
    g = p.add_argument_group("preset and model")
    g.add_argument(
        "--preset",
        default="cpu",
        choices=sorted(PRESETS),
        help="cpu (default): 96x96 person crops, U-Net base 16, precision auto, 4 scenes per step, cosine decay; "
        "paper: full 320x240 images, 288x208 random crops, batch 1 scene, 200 epochs "
        "(posenet/configs/NAME.json)",
    )
    g.add_argument("--modality", choices=("rgbd", "rgb", "depth"), help="network input (paper: rgbd)")
    g.add_argument(
        "--extra-depth", action=argparse.BooleanOptionalAction, help="relative depth + valid channels"
    )
    g.add_argument("--crop-size", type=int, help="cpu preset: side of the person crop fed to the U-Net")
    g.add_argument(
        "--base",
        type=int,
        help="U-Net width (channels of its first level); above an --init checkpoint's, its weights are widened "
        "so that training starts from what it computes (the new channels start disconnected)",
    )
    g.add_argument("--depth", type=int, help="U-Net downsamplings")
    g.add_argument(
        "--loss", choices=("3d", "2d"), help="3d: MPJPE through the cameras (paper); 2d: the baseline"
    )
    g.add_argument(
        "--precision",
        choices=PRECISIONS,
        help="U-Net precision: auto (default; bf16 only where this machine computes it natively, else fp32), "
        "fp32 or bf16; also $ORPOSE_PRECISION",
    )
    g.add_argument("--bf16", dest="precision", action="store_const", const="bf16", help="= --precision bf16")
    g.add_argument(
        "--no-bf16", dest="precision", action="store_const", const="fp32", help="= --precision fp32"
    )
    g.add_argument(
        "--channels-last", action=argparse.BooleanOptionalAction, help="channels_last memory format"
    )
    g = p.add_argument_group("optimisation")
    add_config_options(
        g,
        TrainConfig,
        {
            "epochs": "passes over the training frames",
            "minutes": "a budget of training minutes instead of --epochs: the LR schedule follows the elapsed "
            "time",
            "warmup": "fraction of training with a linear LR warm-up (default 0)",
            "view_loss": "weight of an extra MPJPE on each view's own estimate (the single-view skeletons the "
            "skeleton matcher compares) beside the fused one (default 0: the paper's loss alone; extension)",
        },
    )
    g.add_argument(
        "--clock",
        choices=("wall", "cpu"),
        help="what --minutes counts: wall (default) or cpu (this process's CPU time; immune to a loaded machine)",
    )
    add_config_options(
        g,
        TrainConfig,
        {
            "lr": "Adam learning rate (paper: 1e-3)",
            "scenes_per_step": "scenes per optimiser step (paper: 1)",
            "decay_start": "fraction of training after which the LR decays to 0 (cosine)",
            "val_every": "epochs between validations on the held-out day",
            "val_every_minutes": "with --minutes: minutes between validations (default budget/6)",
            "seed": "seed of the initialisation, shuffling and augmentation",
        },
    )
    g = p.add_argument_group("augmentation (each switchable)")
    add_config_options(
        g,
        AugmentConfig,
        {
            "flip": "horizontal flip, p = 0.5",
            "crop": "random crop (cpu: crop shift/scale)",
            "rotate_deg": "max rotation in degrees (0 disables; paper: 15)",
            "color": "brightness/contrast/saturation jitter",
            "occlude": "probability of an occluder per crop (extension; 0: off)",
            "color_drop": "probability per person-view image of replacing its colour by mid grey, so that the "
            "network also learns from depth alone (extension for looks it never saw; 0: off)",
            "box_noise": "probability per box of a detector-like box instead of the reference one: shifted, too "
            "large or small, truncated, or holding a second person (extension for detector mode; 0: off)",
        },
        flags={"rotate_deg": "--rotate"},
    )
    g = p.add_argument_group("runtime")
    add_threads(g)
    g.add_argument("--device", help="cpu or cuda (default: cuda if available)")
    g.add_argument(
        "--resume", action="store_true", help="continue the run in --out from last/ (else a fresh run)"
    )
    return p


def run_config(args: argparse.Namespace, from_dict, resume_keys: tuple[str, ...], fresh):
    """The config of the run in ``args.out``: with ``--resume`` the saved ``config.json`` (``from_dict``), with the
    options of ``resume_keys`` that were given applied; else ``fresh()``, refusing to overwrite a run."""
    out = Path(args.out)
    if args.resume:
        saved = out / "config.json"
        if not saved.is_file():
            raise FileNotFoundError(f"--resume: {saved} does not exist; start the run without --resume")
        cfg = from_dict(json.loads(saved.read_text()))
        for key in resume_keys:
            if getattr(args, key, None) is not None:
                setattr(cfg, key, getattr(args, key))
        return cfg
    if (out / "last").exists():
        raise FileExistsError(
            f"{out} already holds a run; pass --resume to continue it or choose another --out"
        )
    return fresh()


def detector_like(scene, augment: AugmentConfig, generator: torch.Generator) -> torch.Tensor:
    """The scene's (P, V, 4) boxes, made detector-like with ``augment.box_noise`` (``posenet.net.augment``)."""
    sizes = [(v.depth.shape[1], v.depth.shape[0]) for v in scene.views]
    return detector_like_boxes(scene.boxes, scene.has_box, sizes, augment, generator)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    resume_keys = ("epochs", "minutes", "val_every", "val_every_minutes", "threads", "num_workers", "device")
    cfg = run_config(args, TrainConfig.from_dict, resume_keys, lambda: resolve_config(args))
    result = train(cfg)
    if result["history"] and result["rank"] == 0:
        print(json.dumps({"best_val_mpjpe_cm": result["best_val_mpjpe_cm"]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
