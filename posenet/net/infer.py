"""Batched inference: all persons x views of a scene in one forward pass (the API the service calls).

Usage::

    est = PoseEstimator.from_checkpoint("runs/fold4/best")          # None -> the shipped default weights
    scene = Scene.from_person_boxes(views, person_boxes)            # views: V SceneViews; posenet.scene
    pred = est.predict(scene)                                      # or a list of scenes, in one U-Net pass
    pred.joints      # (P, J, 3) mm, reference (camera 0) frame
    pred.spread_mm   # (P, J) mm: the spread of each joint's 3D point cloud (see posenet.net.lifting)
    pred.confidence  # (P, J) in [0, 1]: calibrated P(error <= 10 cm) (see posenet.net.calibration)
    heat = est.box_heatmaps(views, boxes)                          # boxes: V x (K_v, 4); see posenet.net.box_poses

Any image size works: the input pipeline crops and resizes internally (:mod:`posenet.net.inputs`) and keeps the
cameras right. Runs under ``torch.inference_mode``, at the precision chosen for this machine
(:mod:`posenet.runtime.execution`), with the U-Net on torch or on an inference runtime (``backend``,
:mod:`posenet.runtime.graphs`); the cropping, lifting and aggregation stay in torch, in float32.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from posenet.net.box_poses import BoxHeatmaps, box_heatmaps
from posenet.net.calibration import Calibration
from posenet.net.checkpoint import load_checkpoint
from posenet.net.inputs import SceneInput, build_scene
from posenet.net.model import PoseNet, predict_scenes
from posenet.runtime.graphs import Backend, export_onnx, load_runner
from posenet.scene import PersonPose, Scene, SceneView

Tensor = torch.Tensor


@dataclass
class PosePrediction:
    """The pose network's estimates of a scene's P persons, batched (:meth:`persons` gives one record each).
    joints (P, J, 3) mm reference frame; spread_mm (P, J) mm (smaller = more certain); has_points (P,)
    whether any pixel could vote (else joints are meaningless); confidence (P, J) in [0, 1], the checkpoint's
    calibration of the spread (``posenet.net.calibration``); heatmaps (P, V, J, M) logits at the points,
    with their uv (P or 1, V, M, 2), depth and valid mask, when asked for (visualisation)."""

    joints: Tensor
    spread_mm: Tensor
    has_points: Tensor
    confidence: Tensor
    heatmaps: Tensor | None = None
    uv: Tensor | None = None
    depth: Tensor | None = None
    valid: Tensor | None = None

    def persons(self) -> list[PersonPose]:
        """The P persons as :class:`posenet.scene.PersonPose` records (float64 NumPy), in order; check
        ``has_points`` before trusting one."""
        rows = (
            np.asarray(x.detach().cpu(), np.float64) for x in (self.joints, self.spread_mm, self.confidence)
        )
        return [PersonPose(j, s, c) for j, s, c in zip(*rows, strict=True)]


class PoseEstimator:
    def __init__(
        self, model: PoseNet, config: dict | None = None, device: str | torch.device | None = "cpu"
    ) -> None:
        """``model`` in eval mode on ``device`` (None: where it is, e.g. a model being trained); ``config``: its
        checkpoint config, whose ``"calibration"`` turns spreads into confidences (``posenet.net.calibration``)."""
        self.device = next(model.parameters()).device if device is None else torch.device(device)
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
        flip_test: bool | None = None,
    ) -> PoseEstimator:
        """Load a checkpoint folder or ``.safetensors`` file; None -> ``posenet/weights/default.safetensors``
        (raises FileNotFoundError saying how to train or point to one when it is missing).

        ``precision`` and ``backend`` say how this machine runs it (``posenet.runtime.execution``, ``posenet.runtime.graphs``).
        ``flip_test``: average every estimate with the mirrored inputs' (2x the U-Net work); None: the
        checkpoint's ``flip_test``.
        """
        model, config = load_checkpoint(path, device, precision)
        if flip_test is not None:
            model.config.flip_test = bool(flip_test)
        est = cls(model, config, device)
        est.use_backend(backend, threads)
        return est

    def use_backend(self, backend: str = "auto", threads: int | None = None) -> Backend:
        """Run the U-Net on ``backend`` from now on (exported to ONNX on first use; see ``posenet.runtime.graphs``).

        A failing export or runtime falls back to torch; ``self.backend.reason`` then says why."""
        self.model.runner, self.backend = load_runner(
            backend, self.device, self.export, threads, self.model.precision(), self._calibration_inputs
        )
        return self.backend

    def _calibration_inputs(self, runner) -> list[dict]:
        """The U-Net's inputs on the int8 calibration scenes (``posenet.runtime.quantize``), run by ``runner``."""
        from posenet.runtime.quantize import Recorder, calibration_samples

        recorder = self.model.runner = Recorder(runner)
        try:
            for sample in calibration_samples():
                self.predict(Scene.from_sample(sample, "boxed"))
        finally:
            self.model.runner = None
        return recorder.inputs

    def export(self, folder: Path | None = None) -> Path:
        """The U-Net as an ONNX graph (cached by a hash of its weights; see ``posenet.runtime.graphs``)."""
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
        return (
            self.model.runner.precision
            if self.model.runner is not None
            else self.model.precision().on_torch()
        )

    def predict(self, scenes: Scene | Sequence[Scene], return_heatmaps: bool = False):
        """3D poses of the persons of one scene, or of several scenes in one U-Net pass.

        Args:
            scenes: a :class:`posenet.scene.Scene` (its views, and its persons as boxes ``(P, V, 4)`` with the
                ``(P, V)`` mask), or a sequence of them (batched together: one forward pass for all).
            return_heatmaps: also return the logits at the lifted points (for pictures).

        Returns:
            a :class:`PosePrediction` for one scene, a list of them (in order) for a sequence.
        """
        single = isinstance(scenes, Scene)
        batch = [scenes] if single else list(scenes)
        run = [s for s in batch if s.num_persons]  # scenes without persons need no pass
        inputs = self.model.config.inputs
        kept: dict[int, SceneInput] = {}  # the network inputs, for return_heatmaps

        def build(i: int, mirror: bool) -> SceneInput:
            built = build_scene(run[i].views, run[i].boxes, run[i].has_box, inputs, mirror=mirror)
            if return_heatmaps and not mirror:
                kept[i] = built
            return built

        with torch.inference_mode():  # with flip averaging if the config asks for it
            outs = iter(enumerate(predict_scenes(self.model, build, len(run)) if run else []))
        preds = []
        for scene in batch:
            if scene.num_persons:
                i, out = next(outs)
                preds.append(self._prediction(scene, out, kept.get(i)))
            else:
                preds.append(self._empty())
        return preds[0] if single else preds

    def _empty(self) -> PosePrediction:
        J = self.model.config.unet.out_channels
        z = torch.zeros(0, J)
        return PosePrediction(torch.zeros(0, J, 3), z, torch.zeros(0, dtype=torch.bool), z)

    def _prediction(self, scene: Scene, out, inputs: SceneInput | None) -> PosePrediction:
        """The prediction of ``scene`` from its network output ``out``; with its network ``inputs``, the
        heatmaps at the lifted points too."""
        spread = out.spread_mm.cpu()  # (P, J) mm: the lifting's spread
        pred = PosePrediction(
            out.joints.cpu(),
            spread,
            (out.has_points & scene.has_box.any(1).to(out.has_points.device)).cpu(),
            self.calibration(spread, scene.support, out.joints.cpu()),  # (P, J) in [0, 1]
        )
        if inputs is not None:
            pred.heatmaps, pred.uv, pred.depth, pred.valid = (
                out.logits.cpu(),
                inputs.uv,
                inputs.depth,
                inputs.valid,
            )
        return pred

    def box_heatmaps(self, views: Sequence[SceneView], boxes: Sequence[np.ndarray]) -> BoxHeatmaps:
        """The U-Net once on every box of a scene, before the boxes are grouped into persons.

        Args:
            views: V :class:`posenet.scene.SceneView`\\ s of one image size.
            boxes: V arrays ``(K_v, 4)`` xyxy pixels of each view (K_v may be 0).

        Returns:
            a :class:`posenet.net.box_poses.BoxHeatmaps`: each box lifted alone (``single_view()``) or any grouping
            of the boxes into persons (``estimate(members)``, equal to :meth:`predict` on those boxes).
        """
        for v, b in enumerate(boxes):
            b = np.asarray(b, np.float32).reshape(-1, 4)
            if not np.isfinite(b).all() or (b[:, 2] <= b[:, 0]).any() or (b[:, 3] <= b[:, 1]).any():
                raise ValueError(f"view {v}: boxes must be finite xyxy with x1 > x0, y1 > y0")
        with torch.inference_mode():
            return box_heatmaps(self.model, list(views), boxes, self.model.config.inputs)
