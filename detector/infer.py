"""The detector as the service calls it: views in, person boxes out.

    detector = PersonDetector.from_checkpoint()            # shipped weights, or a path
    detections = detector.detect([rgb0, rgb1, rgb2], [depth0, depth1, depth2])
    detections[v].boxes   # (K, 4) xyxy pixels of view v's image
    detections[v].scores  # (K,)

All views go through DETR in one batched forward pass under ``torch.inference_mode``: on torch (channels_last,
bf16 autocast only where this machine computes bf16 natively, ``posenet.runtime.execution``) or on an inference runtime
(``backend``, ``posenet.runtime.graphs``), which runs a graph exported from the same weights.

Where the time went (``torch.profiler``, RT-DETR ``cpu`` preset, 3 views of 160x120): 70 % in the ResNet's 62
convolutions, then max-pool and batch norm. channels_last removes oneDNN's reorders of NCHW activations (20.2 ->
17.2 ms per view with torch capped to AVX2, 22.2 -> 21.5 ms with AVX512, benchmarks/RESULTS.md); an inference
runtime also folds the batch norms into the convolutions (OpenVINO: 12.2 ms per view, ``benchmarks/detector_speed.py``).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torchvision.ops import nms

from detector.checkpoint import load_checkpoint
from detector.inputs import prepare_views
from detector.model import DetectorConfig
from detector.protocol import Detections
from posenet.boxes import clip_xyxy, cxcywh_norm_to_xyxy, scale_xyxy
from posenet.runtime.auto_int8 import FRAME_BATCH
from posenet.runtime.execution import Precision, resolve_precision
from posenet.runtime.graphs import Backend, OnnxRunner, export_onnx, load_runner

DEFAULT_WEIGHTS = Path(__file__).parent / "weights" / "default.safetensors"


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


class _Outputs(torch.nn.Module):
    """The detector as a graph of tensors only: (pixel_values, pixel_mask) -> (logits, pred_boxes)."""

    def __init__(self, model: torch.nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, pixel_values: torch.Tensor, pixel_mask: torch.Tensor):
        out = self.model(pixel_values=pixel_values, pixel_mask=pixel_mask)
        return out.logits, out.pred_boxes


class PersonDetector:
    """A trained DETR with its preprocessing; see the module docstring.

    Args:
        precision: ``auto`` (bf16 only where this machine computes it natively), ``fp32``, ``bf16``, or ``int8``
            (OpenVINO only: ``posenet.runtime.quantize``).
        backend: ``torch`` (default), ``onnxruntime``, ``openvino`` or ``auto`` (``posenet.runtime.graphs``).
        threads: the runtime's intra-op threads (default: torch's).
    """

    def __init__(
        self,
        model: torch.nn.Module,
        cfg: DetectorConfig,
        device: str | torch.device = "cpu",
        precision: str = "auto",
        backend: str = "torch",
        threads: int | None = None,
    ) -> None:
        self.device = torch.device(device)
        self.model = model.to(self.device).eval().to(memory_format=torch.channels_last)
        self.cfg = cfg
        self._precision = resolve_precision(precision, self.device)
        self.runner: OnnxRunner | None = None
        self.backend = self.use_backend(backend, threads)

    @property
    def precision(self) -> Precision:
        return self.runner.precision if self.runner is not None else self._precision.on_torch()

    def use_backend(self, backend: str = "auto", threads: int | None = None) -> Backend:
        """Run the network on ``backend`` from now on; a failing export or runtime falls back to torch."""
        self._graph_shape = tuple(self._example()[0].shape[1:])  # (C, H, W) of the exported graph's input
        self.runner, self.backend = load_runner(
            backend,
            self.device,
            self.export,
            threads,
            self._precision,
            self._calibration_inputs,
            transformer=True,
            static_batch=True,  # a batch is one image per view: a few sizes, each compiled with fixed shapes
        )
        if self.runner is not None:  # MVOR's three views: compiled now rather than at the first frame
            self.runner.prepare(FRAME_BATCH["detector"])
        return self.backend

    def _calibration_inputs(self, runner) -> list[dict]:
        """The network's inputs on the int8 calibration scenes (``posenet.runtime.quantize``), run by ``runner``."""
        from posenet.runtime.quantize import Recorder, calibration_samples

        recorder = self.runner = Recorder(runner)
        try:
            for sample in calibration_samples():
                self.detect([v.color for v in sample.views], [v.depth for v in sample.views])
        finally:
            self.runner = None
        return recorder.inputs

    def _example(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Inputs of two blank 4:3 views (MVOR's aspect): the shape that the exported graph takes."""
        w = self.cfg.input_width
        blank = [np.zeros((w * 3 // 4, w, 3), np.uint8)] * 2, [np.zeros((w * 3 // 4, w), np.uint16)] * 2
        pixels, mask, _, _ = prepare_views(*blank, self.cfg)
        return pixels, mask

    def export(self, folder: Path | None = None) -> Path:
        """The network as an ONNX graph for views of ``_example``'s size, any batch (cached by a hash of the
        weights). Views of another size run on torch."""
        pixels, mask = self._example()
        axes = {name: {0: "b"} for name in ("pixel_values", "pixel_mask", "logits", "pred_boxes")}
        return export_onnx(
            _Outputs(self.model).float(), [pixels, mask], ["pixel_values", "pixel_mask"],
            ["logits", "pred_boxes"], axes, "detector", {"config": vars(self.cfg), "input": list(pixels.shape)},
            folder,
        )  # fmt: skip

    def _forward(self, pixels: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.runner is not None and tuple(pixels.shape[1:]) == self._graph_shape:
            return self.runner(pixel_values=pixels, pixel_mask=mask)
        pixels = pixels.to(self.device).contiguous(memory_format=torch.channels_last)
        bf16 = self._precision.bf16
        with torch.autocast(self.device.type, torch.bfloat16) if bf16 else contextlib.nullcontext():
            out = self.model(pixel_values=pixels, pixel_mask=mask.to(self.device))
        return out.logits.float(), out.pred_boxes.float()

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path | None = None,
        device: str | torch.device = "cpu",
        precision: str = "auto",
        backend: str = "torch",
        threads: int | None = None,
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
        return cls(model, cfg, device, precision, backend, threads)

    @property
    def score_threshold(self) -> float:
        return self.cfg.score_threshold

    @property
    def input_width(self) -> int:
        return self.cfg.input_width

    @property
    def needs_depth(self) -> bool:
        return self.cfg.input_mode in ("depth", "rgbd")

    @property
    def needs_color(self) -> bool:
        return self.cfg.input_mode in ("rgb", "rgbd")

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
            logits, boxes = self._forward(pixels, mask)
        return decode(logits, boxes, sizes, factors, full_sizes, score_threshold, self.cfg.nms_iou)
