"""Adapt the person detector to a new OR from its unlabelled multi-view RGB-D recordings (no box, no pose).

From the shipped weights, on days 1-3 of a recording, 30 minutes, with labelled rendered views in every step::

    python -m detector.adapt --data DIR --days 1 2 3 --source-data data/mvor_twin123 --out runs/detadapt \\
        --minutes 30 --threads 2
    python -m detector.adapt --data DIR --out runs/detadapt --resume --minutes 45      # continue the run
    python -m detector.predict --data DIR --days 4 --checkpoint runs/detadapt/last --out boxes.json

Teacher-student self-training. An EMA teacher (a copy of the weights that follows the student, ``--ema`` per
step) labels every target view at the start of each epoch; ``pipeline.pseudo_boxes`` turns its boxes into
training boxes with what multi-view RGB-D video gives for free: a confident box (``--high``, the confidence
gate) that another view or a neighbouring frame confirms; a weaker box that a confident one of another view
confirms; a person fused in two or more views projected, with depth, into a view where the teacher missed
them; and nothing on the static scene (each camera's per-pixel depth over the day: the table, its drape,
lamps and monitors never move). Each step trains the student on ``--target-per-step`` target views with those
boxes and ``--source-per-step`` labelled rendered views of ``--source-data`` (so it cannot drift off), with
``detector.train``'s augmentation.

Of the target's annotation file only the frames and the cameras are read (``detector.adapt_data``): its boxes
and poses never are, and a file without them gives bit-identical weights. The run folder gets ``config.json``,
``log.jsonl`` (per epoch: losses, pseudo-boxes by kind, minutes) and ``last/`` (``detector.checkpoint``'s
format with the teacher's weights; ``train_state.pt`` holds the student and the optimiser for ``--resume``),
which ``detector.predict --checkpoint RUN/last`` and the service (``ORPOSE_DETECTOR_CHECKPOINT=RUN/last``) load.
See docs/detector.md.
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

import numpy as np
import torch
from tqdm import tqdm

from detector.adapt_data import TargetFrames, read_frames_and_cameras
from detector.augment import AugmentConfig
from detector.checkpoint import load_checkpoint, read_config, save_checkpoint
from detector.checkpoint import trained_on as saved_trained_on
from detector.data import DetectionDataset, collate, load_records
from detector.infer import DEFAULT_WEIGHTS, PersonDetector
from detector.model import param_groups

# The one module of `detector` that imports `pipeline` (tests/test_layering.py): the pseudo-labels need the
# cross-view matcher. The detector that the pipeline runs never does.
from pipeline.pseudo_boxes import PseudoBoxConfig, background_depth, pseudo_boxes
from posenet.cli import (
    add_annotations,
    add_config_options,
    add_data,
    add_days,
    add_threads,
    config_options,
)
from posenet.training.adapt_losses import ema_update
from posenet.training.schedule import Schedule
from posenet.training.train import run_config


@dataclass
class DetectorAdaptConfig:
    data: str
    out: str
    annotations: str | None = None  # default DATA/annotations.json; only its frames and cameras are read
    days: list[int] | None = None  # target days to adapt on (default: all in the file)
    init: str | None = None  # detector checkpoint to adapt; None: the shipped detector/weights/default
    source_data: list[str] = field(default_factory=list)  # labelled rendered datasets (DIR/annotations.json)
    epochs: int = 4
    minutes: float | None = None  # a budget of minutes (labelling included); overrides epochs
    # A fine-tune of a converged detector at a tenth of the peak rates it was trained with (1e-4 / 5e-4): on the
    # alt look (days 1-3 to adapt, day 4 to check) half the peak lowered day-4 AP50 from 0.948 to 0.925 in 12
    # minutes, a tenth kept it at 0.944-0.946 (docs/detector.md)
    lr: float = 1e-5
    backbone_lr: float = 5e-5
    weight_decay: float = 1e-4
    grad_clip: float = 0.5  # detector.train's cpu preset
    warmup: float = 0.05
    decay_start: float = 0.5
    # Frames labelled by the teacher at a time, then trained on: the teacher's labels stay fresh, and a time budget
    # or an interruption loses at most one round (a checkpoint follows each)
    frames_per_round: int = 64
    # Target views (pseudo-labelled) per step. 0: a control run on the source views alone, without labelling the
    # target: with epochs, the steps (and learning-rate schedule) of a run at 4 target views per step; with
    # minutes, as many as the time allows (about twice as many). What the fine-tune itself does to the detector,
    # against which an adaptation's gain is judged
    target_per_step: int = 4
    source_per_step: int = 4  # labelled rendered views per step
    # Teacher momentum per step: 0.999 averages the student over ~1,000 steps. A teacher that follows the student
    # fast (0.99, ~100 steps) took on its growing over-confidence and day-4 AP fell; slowly, it rose (on the alt
    # look, 14 minutes: AP50 0.948 -> 0.955 against 0.953 unadapted; docs/detector.md)
    ema: float = 0.999
    background: bool = True  # each camera's static depth over the day (pipeline.pseudo_boxes)
    pseudo: PseudoBoxConfig = field(default_factory=PseudoBoxConfig)
    augment: AugmentConfig = field(default_factory=AugmentConfig)  # detector.train's cpu preset
    seed: int = 0
    threads: int | None = None
    max_frames: int | None = None  # only the first N target frames (smoke runs)
    progress: bool = True
    data_description: dict = field(default_factory=dict)

    @staticmethod
    def from_dict(d: dict) -> DetectorAdaptConfig:
        d = dict(d.get("train", d))
        d["pseudo"] = PseudoBoxConfig(**d.get("pseudo") or {})
        d["augment"] = AugmentConfig(**d.get("augment") or {})
        return DetectorAdaptConfig(**d)


# ----------------------------------------------------------------------------- pseudo-labels
def label_target(
    teacher: PersonDetector,
    target: TargetFrames,
    frames: list[int],
    cfg: DetectorAdaptConfig,
    progress: bool = True,
) -> tuple[dict[str, int], list[bool]]:
    """Set the records' ``boxes`` of the target ``frames`` to the teacher's pseudo-labels (the teacher also runs
    on their neighbouring frames, which confirm boxes over time); return the boxes by kind and, per view of the
    frames in order, whether it is unsettled (``pipeline.pseudo_boxes``)."""
    needed = sorted({j for i in frames for j in (i, *target.neighbours(i))})
    floor = cfg.pseudo.low
    if cfg.pseudo.unsettled_floor is not None:
        floor = min(floor, cfg.pseudo.unsettled_floor)
    dets = {}
    for i in tqdm(needed, desc="teacher", unit="frame", leave=False, disable=not progress):
        records = target.frames[i].records
        dets[i] = teacher.detect([r.color for r in records], [r.depth for r in records], floor)
    counts: dict[str, int] = {}
    unsettled: list[bool] = []
    for i in frames:
        frame = target.frames[i]
        V = len(frame.records)
        near = [
            [dets[j][v].boxes[dets[j][v].scores >= cfg.pseudo.low] for j in target.neighbours(i)]
            for v in range(V)
        ]
        backgrounds = None
        if cfg.background:
            backgrounds = [target.backgrounds[(frame.day, v)] for v in range(V)]
        result = pseudo_boxes(
            [d.boxes for d in dets[i]],
            [d.scores for d in dets[i]],
            [r.depth for r in frame.records],
            frame.cameras,
            backgrounds,
            near,
            cfg.pseudo,
        )
        for rec, boxes in zip(frame.records, result.boxes, strict=True):
            rec.boxes = boxes
        unsettled += result.unsettled
        for k, n in result.counts.items():
            counts[k] = counts.get(k, 0) + n
    counts["views"] = sum(len(target.frames[i].records) for i in frames)
    counts["boxes"] = sum(len(r.boxes) for i in frames for r in target.frames[i].records)
    return counts, unsettled


def steps_for(views: int, cfg: DetectorAdaptConfig) -> int:
    """The steps ``views`` target views take: one per ``target_per_step`` of them (the control run, at 0, takes
    the steps of the default 4 per step)."""
    return -(-views // (cfg.target_per_step or DetectorAdaptConfig.target_per_step))


def rounds(num_frames: int, size: int, seed: int) -> list[list[int]]:
    """An epoch's rounds: runs of ``size`` consecutive frames (neighbours confirm each other), in a seeded order."""
    runs = [list(range(i, min(i + size, num_frames))) for i in range(0, num_frames, size)]
    order = torch.randperm(len(runs), generator=torch.Generator().manual_seed(seed)).tolist()
    return [runs[i] for i in order]


# ----------------------------------------------------------------------------- the run
class Draw:
    """Items of a dataset (or of a subset of its indices) in a seeded order, cycling when a step asks for more than
    are left; a resumed run draws what an uninterrupted one would."""

    def __init__(self, dataset) -> None:
        self.dataset = dataset
        self.indices: list[int] = list(range(len(dataset)))
        self.order: list[int] = []
        self.generator = torch.Generator()

    def restart(self, seed: int, indices: list[int] | None = None) -> None:
        self.generator.manual_seed(seed)
        self.dataset.rng = np.random.default_rng(seed)  # the augmentation's stream
        self.indices = list(range(len(self.dataset))) if indices is None else indices
        self.order = []

    def take(self, n: int) -> list:
        out = []
        while len(out) < n and self.indices:
            if not self.order:
                perm = torch.randperm(len(self.indices), generator=self.generator).tolist()
                self.order = [self.indices[i] for i in perm]
            out.append(self.dataset[self.order.pop()])
        return out


def _state_of(model: torch.nn.Module) -> dict:
    return {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}


def adapt(cfg: DetectorAdaptConfig) -> dict:
    """Run (or resume) an adaptation; return ``{"history": [per-epoch records]}``."""
    t_start = time.perf_counter()
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    if not cfg.source_data:
        raise ValueError(
            "--source-data is required: labelled rendered views in every step keep the detector from drifting "
            "(e.g. data/mvor_twin123, rendered with `python -m posenet.synth`)"
        )
    torch.manual_seed(cfg.seed)
    out = Path(cfg.out)
    state_file = out / "last" / "train_state.pt"
    resume = state_file.is_file()
    init = cfg.init or str(DEFAULT_WEIGHTS)
    student, det_cfg, init_meta = load_checkpoint(out / "last" if resume else init)
    student.float().train()

    annotations = cfg.annotations or str(Path(cfg.data) / "annotations.json")
    target = TargetFrames(
        cfg.data, read_frames_and_cameras(annotations), det_cfg, cfg.days, cfg.max_frames, cfg.progress
    )
    if cfg.background:
        for day in sorted({f.day for f in target.frames}):
            for v in range(len(target.frames[0].records)):
                target.backgrounds[(day, v)] = background_depth(
                    target.depths_of(day, v), cfg.pseudo.background_quantile
                )
    source_records = []
    for root in cfg.source_data:
        records = load_records(Path(root) / "annotations.json")
        for r in records:
            r.root = str(root)
        source_records += records
    target_set = DetectionDataset(target.records, None, det_cfg, cfg.augment, cfg.seed)
    source_set = DetectionDataset(source_records, None, det_cfg, cfg.augment, cfg.seed + 1, cache=True)
    target_draw, source_draw = Draw(target_set), Draw(source_set)

    groups = param_groups(student, cfg.lr, cfg.backbone_lr, cfg.weight_decay)
    base_lrs = [g["lr"] for g in groups]
    optimiser = torch.optim.AdamW(groups, lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = steps_for(len(target_set), cfg)  # the rounds' steps: one per target_per_step views
    schedule = Schedule(cfg.lr, cfg.epochs * steps_per_epoch, cfg.decay_start, cfg.warmup, cfg.minutes)
    teacher_model = copy.deepcopy(student).eval().requires_grad_(False)
    start_epoch = start_round = 0
    if resume:
        state = torch.load(state_file, map_location="cpu", weights_only=False)
        student.load_state_dict(state["student"])
        optimiser.load_state_dict(state["optimiser"])
        start_epoch, schedule.step, schedule.elapsed = state["epoch"], state["step"], state["elapsed_s"]
        start_round = state["round"]
        print(f"resuming {out} at epoch {start_epoch}", file=sys.stderr)
    else:
        schedule.elapsed = time.perf_counter() - t_start  # reading the target counts against --minutes
    teacher = PersonDetector(teacher_model, det_cfg, precision="fp32")

    cfg.data_description = {
        "init": str(init),
        "annotations": f"{annotations}: frames and cameras only (no box, no pose read)",
        "target_days": cfg.days,
        "target_frames": len(target),
        "target_views": len(target_set),
        "source_views": len(source_set),
    }
    if resume:
        trained_on = read_config(out)["trained_on"]
    else:
        trained_on = {
            "init": str(init),
            "init_trained_on": saved_trained_on(init_meta),
            "data": cfg.data,
            "days": cfg.days,
            "frames": len(target),
            "labels": "none of the target's (pseudo-labels of an EMA teacher, pipeline.pseudo_boxes)",
            "source_data": list(cfg.source_data),
        }
    config = {"train": dataclasses.asdict(cfg), "trained_on": trained_on}
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(config, indent=2, default=str))

    history = []
    view_index, first = {}, 0  # frame -> its views' indices in target_set
    for i, frame in enumerate(target.frames):
        view_index[i] = list(range(first, first + len(frame.records)))
        first += len(frame.records)
    epochs = cfg.epochs if cfg.minutes is None else 10**9  # with a budget, as many epochs as the time allows
    for epoch in range(start_epoch, epochs):
        if schedule.spent:
            break
        plan = rounds(len(target), cfg.frames_per_round, cfg.seed * 100003 + epoch * 1009)
        for r, frames in enumerate(plan):
            if epoch == start_epoch and r < start_round:
                continue  # done before the run was interrupted
            if schedule.spent:
                break
            t0 = time.perf_counter()
            views = [j for i in frames for j in view_index[i]]
            counts: dict[str, int] = {}
            if cfg.target_per_step:
                counts, unsettled = label_target(teacher, target, frames, cfg, cfg.progress)
                views = [j for j, doubt in zip(views, unsettled, strict=True) if not doubt]
            steps_this = steps_for(len(views), cfg)
            schedule.elapsed += time.perf_counter() - t0
            seed = cfg.seed * 100003 + epoch * 1009 + r * 7919
            target_draw.restart(seed, views)
            source_draw.restart(seed + 17)
            desc = f"epoch {epoch + 1} round {r + 1}/{len(plan)}"
            bar = tqdm(range(steps_this), desc=desc, leave=False, disable=not cfg.progress)
            loss_sum, steps = 0.0, 0
            student.train()
            for _ in bar:
                items = target_draw.take(cfg.target_per_step) + source_draw.take(cfg.source_per_step)
                batch = collate(items, det_cfg.pad_multiple)
                lr = schedule.begin(optimiser)
                for g, base in zip(optimiser.param_groups, base_lrs, strict=True):
                    g["lr"] = base * lr / cfg.lr  # the schedule's factor on each group's own rate
                output = student(
                    pixel_values=batch["pixel_values"], pixel_mask=batch["pixel_mask"], labels=batch["labels"]
                )
                optimiser.zero_grad(set_to_none=True)
                output.loss.backward()
                if cfg.grad_clip:
                    torch.nn.utils.clip_grad_norm_(student.parameters(), cfg.grad_clip)
                optimiser.step()
                ema_update(teacher.model, student, cfg.ema)
                schedule.end()
                steps += 1
                loss_sum += float(output.loss.detach())
                bar.set_postfix(
                    loss=f"{loss_sum / steps:.3f}", lr=f"{lr:.1e}", min=f"{schedule.elapsed / 60:.1f}"
                )
                if schedule.spent:
                    break
            done_epoch, done_round = (epoch + 1, 0) if r + 1 == len(plan) else (epoch, r + 1)
            record = {
                "epoch": epoch + 1,
                "round": r + 1,
                "rounds": len(plan),
                "loss": round(loss_sum / max(steps, 1), 4),
                "pseudo": counts,
                "steps": schedule.step,
                "seconds": round(time.perf_counter() - t0, 1),
                "minutes": round(schedule.elapsed / 60.0, 2),
            }
            train_state = {
                "epoch": done_epoch,
                "round": done_round,
                "student": _state_of(student),
                "optimiser": optimiser.state_dict(),
                "step": schedule.step,
                "elapsed_s": schedule.elapsed,
            }
            progress = {"epoch": done_epoch, "round": done_round, "step": schedule.step, "metrics": record}
            save_checkpoint(
                out / "last",
                teacher.model,
                det_cfg,
                config["train"],
                progress,
                "float32",
                trained_on,
                train_state,
            )
            with open(out / "log.jsonl", "a") as f:
                f.write(json.dumps(record) + "\n")
            print(json.dumps(record), file=sys.stderr)
            history.append(record)
    return {"history": history}


# ----------------------------------------------------------------------------- command line
def build_parser() -> argparse.ArgumentParser:
    d, q = DetectorAdaptConfig("", ""), PseudoBoxConfig()
    p = argparse.ArgumentParser(
        prog="python -m detector.adapt",
        description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Examples:\n"
        + "\n".join(line for line in __doc__.splitlines() if line.startswith("    python")),
    )
    g = p.add_argument_group("target data (no box or pose is read)")
    add_data(g, help="recordings in MVOR's layout: dayD/camC/{color,depth}/NNNNNN.png")
    add_annotations(g, help="MVOR-format json: its frames and cameras only (default: DATA/annotations.json)")
    add_days(g, help="days to adapt on (default: all in the file)")
    g.add_argument("--max-frames", type=int, help="only the first N target frames (smoke runs)")
    g = p.add_argument_group("model and source data")
    g.add_argument(
        "--init", help="detector checkpoint to adapt (default: the shipped detector/weights/default)"
    )
    g.add_argument(
        "--source-data",
        nargs="+",
        default=[],
        metavar="DIR",
        help="labelled rendered datasets (DIR/annotations.json)",
    )
    g.add_argument("--out", required=True, help="run folder: config.json, log.jsonl, last/")
    g = p.add_argument_group("pseudo-labels (pipeline.pseudo_boxes)")
    add_config_options(
        g,
        q,
        {
            "high": "the confidence gate: a box this sure is kept once confirmed",
            "low": "weaker boxes only confirm, or are promoted by another view",
            "unsettled_floor": "a view with a teacher box scored from this up to --high that no rule settled is "
            "left out of its round, so that its person is not taught as background",
        },
    )
    g.add_argument(
        "--no-background", dest="background", action="store_false", help="no static-scene model from depth"
    )
    g = p.add_argument_group("optimisation")
    g.add_argument(
        "--epochs",
        type=int,
        help=f"pseudo-labelling rounds, each a pass over the target (default {d.epochs})",
    )
    g.add_argument(
        "--minutes", type=float, help="a budget of minutes instead of --epochs (the LR follows it)"
    )
    add_config_options(
        g,
        d,
        {
            "ema": "teacher momentum per step",
            "lr": "AdamW learning rate of the transformer",
            "backbone_lr": "AdamW learning rate of the backbone",
            "warmup": "fraction with a linear LR warm-up",
            "decay_start": "fraction after which the LR decays",
            "frames_per_round": "frames the teacher labels at a time",
            "target_per_step": "target views per step (0: a control on the source views alone, as many steps as "
            "at 4)",
            "source_per_step": "labelled views per step",
            "seed": "seed of the order and the augmentation",
        },
    )
    g = p.add_argument_group("runtime")
    add_threads(g)
    g.add_argument("--resume", action="store_true", help="continue the run in --out from last/")
    g.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bars")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)

    def fresh() -> DetectorAdaptConfig:
        cfg = DetectorAdaptConfig(**config_options(args, DetectorAdaptConfig))
        cfg.pseudo = dataclasses.replace(cfg.pseudo, **config_options(args, PseudoBoxConfig))
        if not 0.0 <= cfg.pseudo.low <= cfg.pseudo.high <= 1.0:
            raise ValueError(f"need 0 <= --low <= --high <= 1, got --low {args.low} --high {args.high}")
        return cfg

    try:
        cfg = run_config(
            args, DetectorAdaptConfig.from_dict, ("epochs", "minutes", "threads", "progress"), fresh
        )
        adapt(cfg)
    except (FileNotFoundError, FileExistsError, ValueError) as e:
        print(f"python -m detector.adapt: error: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
