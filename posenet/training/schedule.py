"""The learning-rate schedule of the pose network's trainers, over steps or over a budget of minutes.

``posenet.training.train`` (supervised) and ``posenet.training.adapt`` (unsupervised adaptation) share it: a linear warm-up,
a constant stretch, then a cosine down to 0. With a time budget (``minutes``) the schedule follows the
elapsed seconds of the steps instead of their count: "the best model in 30 minutes". What the budget counts
is the ``clock``: ``wall`` (seconds of the steps, as a user waits for them) or ``cpu`` (this process's CPU
seconds, which a shared, loaded machine does not inflate).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import torch

CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}


def lr_factor(step: float, total: float, decay_start: float, warmup: float = 0.0) -> float:
    """A linear warm-up from 0.1 over the first ``warmup`` of the training, 1 until ``decay_start`` of it, then a
    cosine down to 0 at the end. ``step`` / ``total`` are steps, or seconds of a time budget."""
    if warmup > 0 and step < warmup * total:
        return 0.1 + 0.9 * step / (warmup * total)
    start = decay_start * total
    if step < start or total <= start:
        return 1.0
    return 0.5 * (1 + math.cos(math.pi * min(1.0, (step - start) / (total - start))))


@dataclass
class Schedule:
    """The optimiser's learning rate and the training clock: call :meth:`begin` before a step's work (it sets
    the LR) and :meth:`end` after ``optimiser.step()`` (it counts the step and its seconds).

    ``step`` and ``elapsed`` (seconds of training, validation excluded) are what a resumed run restores.
    """

    lr: float
    total_steps: int
    decay_start: float = 0.75
    warmup: float = 0.0
    minutes: float | None = None  # a budget of training minutes; None follows the steps
    clock: str = "wall"
    step: int = 0
    elapsed: float = 0.0
    _t0: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.clock not in CLOCKS:
            raise ValueError(f"clock must be 'wall' or 'cpu', got {self.clock!r}")

    @property
    def budget_s(self) -> float | None:
        return None if self.minutes is None else 60.0 * self.minutes

    @property
    def spent(self) -> bool:
        """Whether the time budget is used up (never, without one)."""
        return self.budget_s is not None and self.elapsed >= self.budget_s

    def current_lr(self) -> float:
        done, total = (
            (self.elapsed, self.budget_s) if self.minutes is not None else (self.step, self.total_steps)
        )
        return self.lr * lr_factor(done, total, self.decay_start, self.warmup)

    def begin(self, optimiser: torch.optim.Optimizer) -> float:
        """Start timing a step and set its learning rate on every parameter group; return it."""
        self._t0 = CLOCKS[self.clock]()
        lr = self.current_lr()
        for group in optimiser.param_groups:
            group["lr"] = lr
        return lr

    def end(self) -> None:
        """Count the step begun by :meth:`begin` and add its seconds to ``elapsed``."""
        if self._t0 is None:
            raise RuntimeError("Schedule.end() without a Schedule.begin()")
        self.elapsed += CLOCKS[self.clock]() - self._t0
        self.step += 1
        self._t0 = None
