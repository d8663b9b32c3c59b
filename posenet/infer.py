"""Batched inference: all persons x views of a scene in one forward pass (the API the service calls).

Usage::

    est = PoseEstimator.from_checkpoint("runs/fold4/best")          # None -> the shipped default weights
    pred = est.predict(views, person_boxes)                        # views: V x (color, depth, Camera)
    pred.joints      # (P, J, 3) mm, reference (camera 0) frame
    pred.spread_mm   # (P, J) mm: the spread of each joint's 3D point cloud (see posenet.lifting)
    pred.confidence  # (P, J) in [0, 1]: calibrated P(error <= 10 cm) (see posenet.calibration)
    heat = est.box_heatmaps(views, boxes)                          # boxes: V x (K_v, 4); see posenet.box_poses

Any image size works: the input pipeline crops and resizes internally (:mod:`posenet.inputs`) and keeps the
cameras right. Runs under ``torch.inference_mode``, at the precision chosen for this machine
(:mod:`posenet.execution`), with the U-Net on torch or on an inference runtime (``backend``,
:mod:`posenet.runtime`); the cropping, lifting and aggregation stay in torch, in float32.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from posenet.box_poses import BoxHeatmaps, box_heatmaps
from posenet.calibration import Calibration
from posenet.cameras import Camera
from posenet.checkpoint import load_checkpoint
from posenet.inputs import build_scene
from posenet.model import PoseNet, predict_scenes
from posenet.runtime import Backend, export_onnx, load_runner

Tensor = torch.Tensor


@dataclass
class PosePrediction:
    """joints (P, J, 3) mm reference frame; spread_mm (P, J) mm (smaller = more certain); has_points (P,)
    whether any pixel could vote (else joints are meaningless); confidence (P, J) in [0, 1], the checkpoint's
    calibration of the spread (``posenet.calibration``); heatmaps (P, V, J, M) logits at the points,
    with their uv (P or 1, V, M, 2), depth and valid mask, when asked for (visualisation)."""

    joints: Tensor
    spread_mm: Tensor
    has_points: Tensor
    confidence: Tensor
    heatmaps: Tensor | None = None
    uv: Tensor | None = None
    depth: Tensor | None = None
    valid: Tensor | None = None


class PoseEstimator:
    def __init__(
        self, model: PoseNet, config: dict | None = None, device: str | torch.device = "cpu"
    ) -> None:
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.config = config or {}
        self.calibration = Calibration.from_config(self.config)  # spread -> confidence
        self.backend = Backend("torch", "the default of PoseEstimator")

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path | None = None,
        device: str | torch.device = "cpu",
        precision: str = "auto",
        backend: str = "torch",
        threads: int | None = None,
    ) -> PoseEstimator:
        """Load a checkpoint folder or ``.safetensors`` file; None -> ``posenet/weights/default.safetensors``
        (raises FileNotFoundError saying how to train or point to one when it is missing).

        ``precision`` and ``backend`` say how this machine runs it (``posenet.execution``, ``posenet.runtime``).
        """
        model, config = load_checkpoint(path, device, precision)
        est = cls(model, config, device)
        est.use_backend(backend, threads)
        return est

    def use_backend(self, backend: str = "auto", threads: int | None = None) -> Backend:
        """Run the U-Net on ``backend`` from now on (exported to ONNX on first use; see ``posenet.runtime``).

        A failing export or runtime falls back to torch; ``self.backend.reason`` then says why."""
        self.model.runner, self.backend = load_runner(
            backend, self.device, self.export, threads, self.model.precision()
        )
        return self.backend

    def export(self, folder: Path | None = None) -> Path:
        """The U-Net as an ONNX graph (cached by a hash of its weights; see ``posenet.runtime``)."""
        cfg = self.model.config
        w, h = cfg.inputs.network_size(False)
        example = torch.zeros(2, cfg.inputs.in_channels, h, w)
        return export_onnx(
            self.model.unet.float(), [example], ["x"], ["heatmaps"], {"x": {0: "n"}, "heatmaps": {0: "n"}},
            "unet", {"unet": str(cfg.unet), "size": [w, h]}, folder,
        )  # fmt: skip

    @property
    def precision(self):
        """The precision the U-Net runs at here (the runtime's, when one runs it)."""
        return self.model.runner.precision if self.model.runner is not None else self.model.precision()

    @staticmethod
    def _boxes(person_boxes: Sequence[Sequence], V: int) -> tuple[Tensor, Tensor]:
        P = len(person_boxes)
        boxes = torch.zeros(P, V, 4)
        has = torch.zeros(P, V, dtype=torch.bool)
        for p, per_view in enumerate(person_boxes):
            if len(per_view) != V:
                raise ValueError(f"person {p} has {len(per_view)} box entries, expected one per view ({V})")
            for v, box in enumerate(per_view):
                if box is None:
                    continue
                b = torch.as_tensor(np.asarray(box, np.float32)).reshape(-1)
                if b.shape != (4,) or not torch.isfinite(b).all() or b[2] <= b[0] or b[3] <= b[1]:
                    raise ValueError(
                        f"person {p}, view {v}: box must be finite xyxy with x1 > x0, y1 > y0, got {box}"
                    )
                boxes[p, v], has[p, v] = b, True
        return boxes, has

    def predict(
        self,
        views: Sequence[tuple[np.ndarray | None, np.ndarray, Camera]],
        person_boxes: Sequence[Sequence],
        return_heatmaps: bool = False,
    ) -> PosePrediction:
        """3D poses of P persons in one scene.

        Args:
            views: V tuples ``(color (H, W, 3) uint8 RGB or None, depth (H, W) uint16 mm, Camera)``.
            person_boxes: P lists of V entries, each an xyxy box (pixels of that view) or None.
            return_heatmaps: also return the logits at the lifted points (for pictures).
        """
        V = len(views)
        boxes, has_box = self._boxes(person_boxes, V)
        J = self.model.config.unet.out_channels
        if boxes.shape[0] == 0:
            z = torch.zeros(0, J)
            return PosePrediction(torch.zeros(0, J, 3), z, torch.zeros(0, dtype=torch.bool), z)
        views = list(views)
        scenes = {}

        def build(_: int, mirror: bool):
            scenes[mirror] = build_scene(views, boxes, has_box, self.model.config.inputs, mirror=mirror)
            return scenes[mirror]

        with torch.inference_mode():
            out = predict_scenes(self.model, build, 1)[0]  # with flip averaging if the config asks for it
        scene = scenes[False]
        pred = PosePrediction(
            out.joints.cpu(),
            out.confidence.cpu(),  # the lifting's spread, mm
            (out.has_points & has_box.any(1).to(out.has_points.device)).cpu(),
            self.calibration(out.confidence.cpu(), has_box.sum(1)),
        )
        if return_heatmaps:
            pred.heatmaps, pred.uv, pred.depth, pred.valid = (
                out.logits.cpu(),
                scene.uv,
                scene.depth,
                scene.valid,
            )
        return pred

    def box_heatmaps(
        self, views: Sequence[tuple[np.ndarray | None, np.ndarray, Camera]], boxes: Sequence[np.ndarray]
    ) -> BoxHeatmaps:
        """The U-Net once on every box of a scene, before the boxes are grouped into persons.

        Args:
            views: as :meth:`predict`.
            boxes: V arrays ``(K_v, 4)`` xyxy pixels of each view (K_v may be 0).

        Returns:
            a :class:`posenet.box_poses.BoxHeatmaps`: each box lifted alone (``single_view()``) or any grouping
            of the boxes into persons (``estimate(members)``, equal to :meth:`predict` on those boxes).
        """
        for v, b in enumerate(boxes):
            b = np.asarray(b, np.float32).reshape(-1, 4)
            if not np.isfinite(b).all() or (b[:, 2] <= b[:, 0]).any() or (b[:, 3] <= b[:, 1]).any():
                raise ValueError(f"view {v}: boxes must be finite xyxy with x1 > x0, y1 > y0")
        with torch.inference_mode():
            return box_heatmaps(self.model, list(views), boxes, self.model.config.inputs)
