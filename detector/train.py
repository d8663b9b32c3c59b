"""Fine-tune (``paper``) or train from scratch (``cpu``) a DETR person detector on one cross-validation fold.

    python -m detector.train --data DIR --annotations A.json --holdout-day 4 --preset cpu --out RUN
    python -m detector.train --data DIR --annotations A.json --holdout-day 4 --preset paper \
        --pretrained facebook/detr-resnet-101-dc5 --out RUN          # a local folder works offline
    python -m detector.train ... --out RUN --resume                   # continue RUN where it stopped

Trains on every day but the held-out one. After each epoch it writes ``RUN/model.safetensors``,
``RUN/config.json`` (the resolved detector + training config, what it was trained on and the progress; the layout
of ``posenet.net.checkpoint_files``) and ``RUN/train_state.pt``
(optimiser, schedule, RNG, for ``--resume``), evaluates COCO AP on the held-out day, and appends a line to
``RUN/log.jsonl``. The ``paper`` preset's defaults are the paper's: 10 epochs, batch 2, lr 1e-4, backbone lr
1e-5, weight decay 1e-4.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

from detector.augment import AugmentConfig
from detector.checkpoint import load_checkpoint, read_config, save_checkpoint
from detector.checkpoint import trained_on as saved_trained_on
from detector.data import DetectionDataset, collate, load_records, worker_init
from detector.dense import DenseLoss
from detector.evaluate import coco_ap
from detector.infer import PersonDetector
from detector.model import ARCHS, DetectorConfig, build_detector, param_groups, preset, with_input_mode
from detector.predict import predict_records
from posenet.cli import (
    add_annotations,
    add_config_options,
    add_data,
    add_threads,
    annotations_path,
    config_options,
    set_threads,
)
from posenet.data.mvor import read_annotation_json
from posenet.net.checkpoint_files import train_state_file


@dataclass
class TrainConfig:
    epochs: int = 10
    batch_size: int = 2
    lr: float = 1e-4
    backbone_lr: float = 1e-5
    weight_decay: float = 1e-4
    grad_clip: float = 0.1  # DETR's gradient-norm clipping
    warmup_steps: int = 0
    schedule: str = "step"  # "step": lr / 10 for the last third (DETR's drop); "cosine"; "constant"
    num_workers: int = 0
    seed: int = 0
    max_minutes: float | None = None  # stop (after saving) when this much wall time has passed
    eval_every: int = 1  # evaluate the held-out day every this many epochs (0: only at the end)
    # Weight of the training-only dense loss on the encoder tokens (detector.dense; 0: off, as in the paper)
    dense_weight: float = 0.0
    cache: bool = False  # keep resized training views in memory (one process)
    augment: AugmentConfig = field(  # flips only: the paper names no augmentation for its detector
        default_factory=lambda: AugmentConfig(
            scale_min=1.0, scale_max=1.0, brightness=0.0, contrast=0.0, saturation=0.0, depth_noise_mm=0.0
        )
    )


TRAIN_PRESETS: dict[str, TrainConfig] = {
    # The paper's fine-tuning (section "Bounding Boxes from Detection Transformer"); flips only.
    "paper": TrainConfig(),
    # From scratch on 2 CPU cores: larger batches and a 2x higher lr than fine-tuning (nothing pretrained to
    # keep; 5e-4 collapsed), the random backbone at 1e-3, a short warm-up, cosine decay, flip + scale + colour
    # jitter, resized views cached in memory. 16 epochs of the 3,630-view fold take about 75 min of one core.
    "cpu": TrainConfig(
        epochs=16,
        batch_size=8,
        lr=2e-4,
        backbone_lr=1e-3,
        cache=True,
        weight_decay=1e-4,
        grad_clip=0.5,
        warmup_steps=100,
        schedule="cosine",
        augment=AugmentConfig(),
    ),
}


def lr_factor(step: int, total: int, cfg: TrainConfig) -> float:
    """Multiplier of the base learning rates at ``step`` of ``total``."""
    warm = min(1.0, (step + 1) / cfg.warmup_steps) if cfg.warmup_steps else 1.0
    if cfg.schedule == "cosine":
        return warm * 0.5 * (1 + math.cos(math.pi * min(step / max(total, 1), 1.0)))
    if cfg.schedule == "step":
        return warm * (0.1 if step >= total * 2 / 3 else 1.0)
    if cfg.schedule == "constant":
        return warm
    raise ValueError(f"unknown schedule {cfg.schedule!r}; use step, cosine or constant")


def train(
    model: torch.nn.Module,
    det_cfg: DetectorConfig,
    cfg: TrainConfig,
    train_set: DetectionDataset,
    out: Path,
    eval_fn=None,
    resume: bool = False,
    progress: bool = True,
    trained_on: dict | None = None,
) -> list[dict]:
    """Train ``model`` on ``train_set``; checkpoint into ``out`` each epoch (with ``trained_on``, the account of
    the training data that ``config.json`` carries); returns the per-epoch log."""
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    loader = DataLoader(
        train_set,
        batch_size=cfg.batch_size,
        shuffle=True,
        collate_fn=functools.partial(collate, multiple=det_cfg.pad_multiple),
        num_workers=cfg.num_workers,
        worker_init_fn=worker_init if cfg.num_workers else None,
        drop_last=len(train_set) > cfg.batch_size,
        generator=torch.Generator().manual_seed(cfg.seed),
    )
    groups = param_groups(model, cfg.lr, cfg.backbone_lr, cfg.weight_decay)
    dense = None
    if cfg.dense_weight > 0 and det_cfg.arch == "rt_detr":
        raise ValueError(
            "--dense-weight reads the single-scale encoder of detr / conditional_detr; rt_detr already trains "
            "its encoder densely (query selection): drop --dense-weight"
        )
    if cfg.dense_weight > 0:
        dense = DenseLoss(model.config.d_model)
        dense.attach(model)
        groups.append(
            {"params": list(dense.parameters()), "lr": cfg.lr, "weight_decay": 0.0, "name": "dense"}
        )
    base_lrs = [g["lr"] for g in groups]
    optimizer = torch.optim.AdamW(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)
    total = cfg.epochs * len(loader)
    start_epoch, step, log = 0, 0, []
    state_file = train_state_file(out) if resume else None  # an old run's training_state.pt too
    if state_file is not None:
        state = torch.load(state_file, weights_only=False)
        optimizer.load_state_dict(state["optimizer"])
        start_epoch, step, log = state["epoch"], state["step"], state["log"]
        if dense is not None and state.get("dense") is not None:
            dense.load_state_dict(state["dense"])
        torch.set_rng_state(state["torch_rng"])
        train_set.rng = state["data_rng"]
        loader.generator.set_state(state["loader_rng"])
        print(f"resumed {out} at epoch {start_epoch} (step {step})")
    t0 = time.time()
    deadline = None if cfg.max_minutes is None else t0 + cfg.max_minutes * 60

    def save(entry: dict, done: int, step: int) -> None:
        """Weights + configs (``config.json``) and the state that ``--resume`` needs."""
        state = {
            "optimizer": optimizer.state_dict(),
            "epoch": done,
            "step": step,
            "log": [*log, entry],
            "torch_rng": torch.get_rng_state(),
            "data_rng": train_set.rng,
            "loader_rng": loader.generator.get_state(),
            "dense": None if dense is None else dense.state_dict(),
        }
        done_so_far = {"epoch": done, "step": step, "metrics": entry}
        save_checkpoint(
            out, model, det_cfg, train_dict, done_so_far, trained_on=trained_on, train_state=state
        )

    train_dict = {**asdict(cfg), "train_images": len(train_set)}
    for epoch in range(start_epoch, cfg.epochs):
        model.train()
        sums, seen = {}, 0
        bar = tqdm(loader, desc=f"epoch {epoch + 1}/{cfg.epochs}", unit="batch", disable=not progress)
        for batch in bar:
            for g, base in zip(optimizer.param_groups, base_lrs, strict=True):
                g["lr"] = base * lr_factor(step, total, cfg)
            output = model(
                pixel_values=batch["pixel_values"], pixel_mask=batch["pixel_mask"], labels=batch["labels"]
            )
            loss, parts = output.loss, dict(output.loss_dict)
            if dense is not None:
                extra = dense(output.encoder_last_hidden_state, batch["pixel_mask"], batch["labels"])
                loss = loss + cfg.dense_weight * extra["loss_dense"]
                parts.update(extra)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            if cfg.grad_clip:
                torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            optimizer.step()
            step += 1
            seen += 1
            for k, v in {"loss": loss, **parts}.items():
                sums[k] = sums.get(k, 0.0) + float(v.detach() if torch.is_tensor(v) else v)
            bar.set_postfix(loss=f"{sums['loss'] / seen:.3f}")
            if deadline is not None and time.time() > deadline:
                break  # checked every step: one epoch may take longer than the whole budget
        out_of_time = deadline is not None and time.time() > deadline
        # An epoch cut short is not counted as done: --resume repeats it (the schedule goes on from `step`).
        done = epoch + 1 if seen == len(loader) else epoch
        entry = {"epoch": epoch + 1, "step": step, "minutes": round((time.time() - t0) / 60, 2)}
        if done == epoch:
            entry["partial"] = f"{seen}/{len(loader)} batches"
        entry.update({k: round(v / max(seen, 1), 4) for k, v in sums.items()})
        last = epoch + 1 == cfg.epochs or out_of_time

        save(entry, done, step)  # before the evaluation: a run killed while evaluating keeps its training
        if eval_fn is not None and (last or (cfg.eval_every and (epoch + 1) % cfg.eval_every == 0)):
            entry.update(eval_fn(model))
            save(entry, done, step)  # again, with the metrics in config.json
        log.append(entry)
        print(json.dumps(entry))
        with open(out / "log.jsonl", "a") as f:
            f.write(json.dumps(entry) + "\n")
        if out_of_time:
            print(f"stopping after {cfg.max_minutes} minutes (resume with --resume)")
            break
    return log


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m detector.train",
        description=__doc__.split("\n\n")[0] + " Resumable; checkpoints and logs go to --out.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    g = p.add_argument_group("data")
    add_data(g)
    add_annotations(g)
    g.add_argument("--holdout-day", type=int, help="recording day held out for evaluation (the fold)")
    g.add_argument(
        "--train-days", type=int, nargs="+", help="days to train on (default: all but the held-out)"
    )
    g.add_argument(
        "--extra-data",
        nargs="+",
        default=[],
        metavar="DIR",
        help="more MVOR-layout datasets (DIR/annotations.json), used whole for training (e.g. procedural scenes)",
    )
    g.add_argument(
        "--max-images", type=int, help="use only the first N training views (quick runs and tests)"
    )
    g = p.add_argument_group("model")
    g.add_argument(
        "--preset", choices=["cpu", "paper"], default="cpu", help="architecture + training defaults"
    )
    g.add_argument("--pretrained", help="local folder (or hub id) of real DETR weights to fine-tune")
    g.add_argument(
        "--init",
        metavar="CKPT",
        help="start from the weights and architecture of one of our checkpoints (a run folder or a .safetensors "
        "file, e.g. detector/weights/default.safetensors) with a fresh optimiser and schedule: fine-tune the "
        "shipped detector on your own recordings, or train a finished run for longer",
    )
    g.add_argument(
        "--input",
        choices=["rgb", "depth", "rgbd"],
        help="input channels (default: the preset's; cpu: rgbd, paper: rgb as in the paper). With --init: fine-tune "
        "the checkpoint to read these instead (rgbd -> depth: a detector that never sees colour; its first "
        "convolution keeps the depth channel's weights)",
    )
    g.add_argument(
        "--arch",
        choices=sorted(ARCHS),
        help="default: the preset's (cpu: rt_detr, paper: detr). detr and conditional_detr read one backbone "
        "stage: use them with --backbone-stage 3 for the small model (docs/detector.md)",
    )
    g.add_argument("--backbone", help="timm backbone name (e.g. resnet18, regnetx_002)")
    g.add_argument(
        "--backbone-stage",
        type=int,
        choices=[1, 2, 3, 4],
        help="last backbone stage used (RT-DETR reads it and the two before it)",
    )
    g.add_argument("--queries", type=int, help="number of DETR queries")
    g.add_argument(
        "--input-width",
        type=int,
        help="images are resized to this width (with --init: fine-tune the checkpoint at this width)",
    )
    g = p.add_argument_group("training (defaults come from the preset)")
    add_config_options(
        g,
        TrainConfig,
        {
            "epochs": "passes over the training views",
            "batch_size": "views per step",
            "lr": "AdamW learning rate of the transformer",
            "backbone_lr": "AdamW learning rate of the backbone",
            "weight_decay": "AdamW weight decay",
        },
    )
    g.add_argument("--schedule", choices=["step", "cosine", "constant"], help="learning-rate schedule")
    add_config_options(
        g,
        TrainConfig,
        {
            "warmup_steps": "steps with a linear LR warm-up",
            "num_workers": "DataLoader workers",
            "seed": "seed of the initialisation, order and augmentation",
            "dense_weight": "weight of the training-only dense loss on the encoder tokens (detector/dense.py; "
            "0 turns it off)",
            "cache": "keep resized training views in memory",
            "max_minutes": "stop (after saving a checkpoint) after this wall time",
            "eval_every": "evaluate the held-out day every N epochs (0: only at the end)",
        },
    )
    add_threads(g)
    g = p.add_argument_group("output")
    g.add_argument("--out", required=True, help="run folder for checkpoints, config and log")
    g.add_argument("--resume", action="store_true", help="continue the run in --out from its last checkpoint")
    g.add_argument("--no-progress", action="store_true", help="no progress bars (logs only)")
    return p


def main(argv: list[str] | None = None) -> list[dict]:
    args = build_parser().parse_args(argv)
    set_threads(args.threads)
    args.annotations = annotations_path(args)
    out = Path(args.out)
    base = TRAIN_PRESETS[args.preset]
    if args.resume and (out / "config.json").is_file():
        # Continue with the run's own hyper-parameters; the command line may still change them (e.g.
        # --epochs).
        saved = dict(read_config(out)["train"])
        saved.pop("train_images", None)
        base = TrainConfig(**{**saved, "augment": AugmentConfig(**saved["augment"])})
    cfg = replace(base, **config_options(args, TrainConfig))
    annotations = read_annotation_json(args.annotations)
    all_days = sorted({r.day for r in load_records(annotations)})
    if args.train_days:
        train_days = args.train_days
    elif args.holdout_day is not None:
        if args.holdout_day not in all_days:
            raise ValueError(f"--holdout-day {args.holdout_day} is not one of the annotated days {all_days}")
        train_days = [d for d in all_days if d != args.holdout_day]
    else:
        raise ValueError("give --holdout-day (the fold) or --train-days")
    records = load_records(annotations, train_days)[: args.max_images]
    for extra in args.extra_data:
        extra_records = load_records(Path(extra) / "annotations.json")
        for r in extra_records:
            r.root = str(extra)
        records += extra_records

    trained_on = {
        "data": str(args.data),
        "days": train_days,
        "extra_data": [str(e) for e in args.extra_data],
        "views": len(records),
    }
    if args.resume and (out / "config.json").is_file():
        model, det_cfg, meta = load_checkpoint(out)
        model.train()
        trained_on = saved_trained_on(meta)
        det_cfg.extra.pop("trained_on", None)  # (where runs from before the shared layout kept it)
    elif args.init:
        if args.pretrained or args.arch or args.backbone or args.queries or args.backbone_stage:
            raise ValueError(
                "--init takes the architecture of its checkpoint; drop --pretrained, --arch, "
                "--backbone, --backbone-stage and --queries"
            )
        model, det_cfg, meta = load_checkpoint(args.init)
        if args.input:  # e.g. colour + depth weights fine-tuned to read depth alone
            model, det_cfg = with_input_mode(model, det_cfg, args.input)
        # the networks are resolution-free (sine position codes): --input-width fine-tunes at another width
        if args.input_width:
            det_cfg = replace(det_cfg, input_width=args.input_width)
        model.float().train()
        trained_on = {"init": str(args.init), "init_trained_on": saved_trained_on(meta), **trained_on}
        det_cfg.extra.pop("trained_on", None)
    else:
        det_cfg = preset(
            args.preset,
            pretrained=args.pretrained,
            input_mode=args.input,
            arch=args.arch,
            backbone=args.backbone,
            num_queries=args.queries,
            input_width=args.input_width,
            backbone_stage=args.backbone_stage,
        )
        torch.manual_seed(cfg.seed)
        model = build_detector(det_cfg)
    train_set = DetectionDataset(records, args.data, det_cfg, cfg.augment, seed=cfg.seed, cache=cfg.cache)

    eval_fn = None
    if args.holdout_day is not None:
        test = load_records(annotations, [args.holdout_day])

        def eval_fn(m):
            det = PersonDetector(m, det_cfg)
            return coco_ap(test, predict_records(det, test, args.data, progress=False))

    n_params = sum(p.numel() for p in model.parameters() if p.requires_grad)
    print(
        f"training {args.preset} ({n_params / 1e6:.1f} M trainable) on days {train_days}: "
        f"{len(records)} views; "
        f"held out: {args.holdout_day}"
    )
    return train(model, det_cfg, cfg, train_set, out, eval_fn, args.resume, not args.no_progress, trained_on)


if __name__ == "__main__":
    main()
