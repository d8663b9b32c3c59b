"""What the rest of the system needs of a person detector: the contract that ``detector.infer.PersonDetector``
fulfils and that another detector (a user's own, another architecture) implements to be served.

The pipeline (``pipeline.two_stage``) reads only this: the boxes and scores per view, the threshold above which a
box is sure, the width it resizes views to (which bounds how small views may be decoded), and how it runs on
this machine (for ``GET /model``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from posenet.runtime.execution import Precision
from posenet.runtime.graphs import Backend


@dataclass
class Detections:
    """The persons found in one view.

    Attributes:
        boxes: (K, 4) float32 xyxy pixels of the view's image (``posenet.boxes``' convention).
        scores: (K,) float32 probability of "person", sorted from high to low.
    """

    boxes: np.ndarray
    scores: np.ndarray


@runtime_checkable
class Detector(Protocol):
    """A person detector as the pipeline calls it.

    ``detect(images, depths, score_threshold)`` returns one :class:`Detections` per view: ``images`` are V colour
    images ``(H, W, 3)`` uint8 RGB (None where a depth-only detector has none), ``depths`` V uint16 depth images
    in mm (or None); boxes at or above ``score_threshold`` (default: :attr:`score_threshold`) are returned."""

    @property
    def score_threshold(self) -> float:
        """The lowest score of a sure box, chosen on training data."""
        ...

    @property
    def input_width(self) -> int:
        """The width (px) that views are resized to before the network reads them."""
        ...

    @property
    def needs_depth(self) -> bool: ...

    @property
    def precision(self) -> Precision: ...

    backend: Backend

    def detect(
        self,
        images: Sequence[np.ndarray | None],
        depths: Sequence[np.ndarray | None] | None = None,
        score_threshold: float | None = None,
    ) -> list[Detections]: ...
