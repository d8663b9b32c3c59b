"""The detector as the service calls it: views in, person boxes out.

    detector = PersonDetector.from_checkpoint()            # shipped weights, or a path
    detections = detector.detect([rgb0, rgb1, rgb2], [depth0, depth1, depth2])
    detections[v].boxes   # (K, 4) xyxy pixels of view v's image
    detections[v].scores  # (K,)

All views go through DETR in one batched forward pass under ``torch.inference_mode``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torchvision.ops import nms

from detector.boxes import clip_xyxy, cxcywh_norm_to_xyxy, scale_xyxy
from detector.checkpoint import load_checkpoint
from detector.inputs import prepare_views
from detector.model import DetectorConfig

DEFAULT_WEIGHTS = Path(__file__).parent / "weights" / "default.safetensors"


@dataclass
class Detections:
    """The persons found in one view.

    Attributes:
        boxes: (K, 4) float32 xyxy pixels of the view's image (``detector.boxes``' convention).
        scores: (K,) float32 probability of "person", sorted from high to low.
    """

    boxes: np.ndarray
    scores: np.ndarray


def decode(
    logits: torch.Tensor,
    pred_boxes: torch.Tensor,
    sizes: Sequence[tuple[int, int]],
    factors: Sequence[float],
    full_sizes: Sequence[tuple[int, int]],
    score_threshold: float,
    nms_iou: float | None = None,
) -> list[Detections]:
    """DETR outputs to per-view detections in full-image pixels.

    Args:
        logits: (B, Q, 2) class logits (person, no-object) of DETR, or (B, Q, 1) of Conditional DETR / RT-DETR.
        pred_boxes: (B, Q, 4) normalised (cx, cy, w, h) of each view's resized, unpadded image.
        sizes: (width, height) of each resized view; ``factors`` the resize factor of each;
            ``full_sizes`` the (width, height) of each original view.
        score_threshold: keep queries whose person probability is at least this.
        nms_iou: drop a box overlapping a higher-scored one by more than this IoU (None: no suppression).
    """
    if logits.shape[-1] == 1:  # Conditional DETR, RT-DETR: one sigmoid (focal loss), no "no-object" class
        scores = logits[..., 0].sigmoid()
    else:  # DETR: softmax over person and no-object, as DETR's post-processing
        scores = logits.softmax(-1)[..., 0]
    out = []
    for b in range(logits.shape[0]):
        (w, h), f, (fw, fh) = sizes[b], factors[b], full_sizes[b]
        boxes = cxcywh_norm_to_xyxy(pred_boxes[b].float(), w, h)  # (Q, 4) resized pixels
        boxes = clip_xyxy(scale_xyxy(boxes, 1.0 / f), fw, fh)  # (Q, 4) full-image pixels
        keep = scores[b] >= score_threshold
        s, order = scores[b][keep].sort(descending=True)
        kept = boxes[keep][order]
        if nms_iou is not None and len(s):
            survivors = nms(kept.float(), s.float(), nms_iou)  # indices, highest score first
            kept, s = kept[survivors], s[survivors]
        out.append(Detections(kept.cpu().numpy().astype(np.float32), s.cpu().numpy().astype(np.float32)))
    return out


class PersonDetector:
    """A trained DETR with its preprocessing; see the module docstring."""

    def __init__(
        self, model: torch.nn.Module, cfg: DetectorConfig, device: str | torch.device = "cpu"
    ) -> None:
        self.model = model.to(device).eval()
        self.cfg = cfg
        self.device = torch.device(device)

    @classmethod
    def from_checkpoint(
        cls, path: str | Path | None = None, device: str | torch.device = "cpu"
    ) -> PersonDetector:
        """Load a checkpoint folder or ``.safetensors`` file; None loads the shipped ``weights/default``."""
        if path is None:
            path = DEFAULT_WEIGHTS
            if not path.is_file():
                raise FileNotFoundError(
                    f"no shipped detector weights at {path}. Train one with `python -m detector.train "
                    "--data DIR --annotations A.json --holdout-day 4 --preset cpu --out RUN` and pass RUN "
                    "as the checkpoint, or copy RUN/model.safetensors and RUN/config.json to "
                    f"{path} and {path.with_suffix('.json')}."
                )
        model, cfg, _ = load_checkpoint(path, device)
        return cls(model, cfg, device)

    @property
    def needs_depth(self) -> bool:
        return self.cfg.input_mode in ("depth", "rgbd")

    def detect(
        self,
        images: Sequence[np.ndarray | None],
        depths: Sequence[np.ndarray | None] | None = None,
        score_threshold: float | None = None,
    ) -> list[Detections]:
        """Person boxes in each view.

        Args:
            images: V colour images ``(H, W, 3)`` uint8 RGB (None allowed for a depth-only detector).
            depths: V depth images ``(H, W)`` uint16 mm, or None; needed by ``depth``/``rgbd`` detectors.
            score_threshold: the lowest person probability kept (default: the checkpoint's
                ``score_threshold``, chosen on training data). Boxes then go through the checkpoint's
                non-maximum suppression (``cfg.nms_iou``) when it has one.
        """
        if depths is None:
            if self.needs_depth:
                raise ValueError(f"this detector reads {self.cfg.input_mode!r} input: pass the depth images")
            depths = [None] * len(images)
        if len(images) != len(depths):
            raise ValueError(f"got {len(images)} images but {len(depths)} depth images")
        if not images:
            return []
        full_sizes = []
        for i, (c, d) in enumerate(zip(images, depths, strict=True)):
            ref = c if c is not None else d
            if ref is None:
                raise ValueError(f"view {i} has neither a colour nor a depth image")
            full_sizes.append((ref.shape[1], ref.shape[0]))
        if score_threshold is None:
            score_threshold = self.cfg.score_threshold
        pixels, mask, factors, sizes = prepare_views(images, depths, self.cfg)
        with torch.inference_mode():
            out = self.model(pixel_values=pixels.to(self.device), pixel_mask=mask.to(self.device))
        return decode(
            out.logits, out.pred_boxes, sizes, factors, full_sizes, score_threshold, self.cfg.nms_iou
        )
