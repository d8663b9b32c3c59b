"""DETR-family person detectors, built from configs through HF transformers (``DetrForObjectDetection``,
``ConditionalDetrForObjectDetection``, ``RTDetrForObjectDetection``).

Two presets (``PRESETS``):

- ``paper``: the paper's detector, DETR with a ResNet-101-DC5 backbone (60 M parameters), 100 queries, 6 + 6
  transformer layers. With ``pretrained`` it loads real DETR weights (a local ``save_pretrained`` folder, or a
  hub id where the hub is reachable) and replaces the class head with one class, "person". The stem and layer1
  of a pretrained backbone are frozen, as in the original DETR.
- ``cpu``: a small DETR-family detector that trains from random initialisation on two CPU cores: RT-DETR
  (transformers' ``RTDetrForObjectDetection``) on a timm resnet18's stages 2-4 (strides 8, 16, 32: a 160x120
  input, padded to 160x128, gives 20x16, 10x8 and 5x4 tokens), d_model 128, 2 attention layers on the coarsest
  scale, 2 decoder layers, 20 queries chosen from the encoder's best tokens (MVOR views hold at most ~6 people),
  20 denoising queries, auxiliary losses, and trainable batch norm in the backbone (DETR freezes it, which is right
  for a pretrained backbone but leaves a random one with no normalisation at all). It reads colour + depth. On
  this budget it reached AP50 0.80 on the held-out day in 6 epochs where Conditional DETR needed 16 for 0.51, and
  DETR was slower still (docs/detector.md); ``arch="detr"``, ``input_mode="rgb"``, ``backbone_stage=3`` give the
  paper's choices on the small model.

Inputs (``input_mode``): ``rgb`` as in the paper; ``depth`` (anonymous, which matters in hospitals) or
``rgbd``. The preprocessing lives in ``detector.inputs`` and is driven by the same config, which is saved with
every checkpoint (``detector.checkpoint``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import timm
import torch
from torch import nn
from transformers import (
    ConditionalDetrConfig,
    ConditionalDetrForObjectDetection,
    DetrConfig,
    DetrForObjectDetection,
    RTDetrConfig,
    RTDetrForObjectDetection,
)

from posenet.net.checkpoint_files import keep_input_channels

INPUT_CHANNELS = {"rgb": 3, "depth": 1, "rgbd": 4}
# The transformers classes of each ``arch`` (the key is also the config's ``model_type``): DETR (the paper's) and Conditional DETR (Meng et al. 2021: the
# same backbone, encoder and set loss, but queries that predict a reference point and a focal class loss; it
# converges several times faster from scratch, see docs/detector.md) and RT-DETR (Zhao et al. 2024: three backbone
# scales, a hybrid encoder, the decoder's queries picked from the encoder's best-scoring tokens, denoising queries
# and a varifocal loss; a DETR that trains like a dense detector).
ARCHS = {
    "detr": (DetrConfig, DetrForObjectDetection),
    "conditional_detr": (ConditionalDetrConfig, ConditionalDetrForObjectDetection),
    "rt_detr": (RTDetrConfig, RTDetrForObjectDetection),
}


@dataclass
class DetectorConfig:
    """Architecture and preprocessing of a detector. Training hyper-parameters live in ``detector.train``."""

    preset: str = "cpu"
    arch: str = "detr"  # "detr" (the paper's), "conditional_detr" or "rt_detr" (ARCHS)
    backbone: str = (
        "resnet18"  # a timm model name (timm builds offline; transformers' own ResNet calls the hub)
    )
    dilation: bool = False  # DC5: stride 16 in the last stage instead of 32 (the paper's ResNet-101-DC5)
    # Last timm stage used (4 = the whole ResNet). DETR and Conditional DETR read only that stage; RT-DETR reads it
    # and the two before it (stages 2-4 of a ResNet: strides 8, 16, 32).
    backbone_stage: int = 3
    trainable_norm: bool = (
        True  # swap DETR's frozen batch norm for trainable batch norm (training from scratch)
    )
    d_model: int = 128
    encoder_layers: int = 2
    decoder_layers: int = 2
    attention_heads: int = 8
    ffn_dim: int = 512
    num_queries: int = 16  # few queries converge faster; MVOR views hold at most ~6 people
    dropout: float = 0.0  # from scratch on little data, dropout slowed convergence more than it helped
    auxiliary_loss: bool = True  # a loss on every decoder layer's output: the largest help to convergence
    eos_coefficient: float = 0.1  # weight of the "no object" class (DETR's default)
    input_mode: str = "rgb"
    # Images are resized to this width (aspect kept). 160 (MVOR's 640x480 -> 160x120) for ``cpu``: at equal
    # wall time on 2 cores it reached a lower loss than 320x240 with a lighter backbone (docs/detector.md).
    input_width: int = 160
    # Boxes scoring below this are dropped at inference (PersonDetector.detect's default). Choose it on training
    # data: ``detector.evaluate`` reports the F1-best threshold (F1_50_threshold).
    score_threshold: float = 0.5
    # Non-maximum suppression at inference: drop a box that overlaps a higher-scored one by more than this IoU.
    # None (the paper's DETR): none, set prediction is meant to give one box per person. A detector trained
    # briefly from scratch still returns near-duplicates; ``detector.export`` chooses this on training days.
    nms_iou: float | None = None
    pretrained: str | None = None  # local folder or hub id of real DETR weights (``paper``)
    freeze_stem: bool = False  # freeze stem + layer1 (the original DETR's choice for a pretrained backbone)
    # Normalisation of the inputs: ImageNet statistics for colour, metres around 2.5 m for depth.
    rgb_mean: tuple[float, float, float] = (0.485, 0.456, 0.406)
    rgb_std: tuple[float, float, float] = (0.229, 0.224, 0.225)
    depth_mean_mm: float = 2500.0
    depth_std_mm: float = 1000.0
    extra: dict = field(default_factory=dict)  # free-form notes saved with the config

    def __post_init__(self) -> None:
        if self.arch not in ARCHS:
            raise ValueError(f"arch must be one of {sorted(ARCHS)}, got {self.arch!r}")
        if self.input_mode not in INPUT_CHANNELS:
            raise ValueError(f"input_mode must be one of {sorted(INPUT_CHANNELS)}, got {self.input_mode!r}")
        if not 1 <= self.backbone_stage <= 4:
            raise ValueError(f"backbone_stage must be in 1..4, got {self.backbone_stage}")
        if self.arch == "rt_detr" and self.backbone_stage < 3:
            raise ValueError(
                f"rt_detr reads three backbone stages: backbone_stage must be 3 or 4, got {self.backbone_stage}"
            )
        self.rgb_mean, self.rgb_std = tuple(self.rgb_mean), tuple(self.rgb_std)

    @property
    def num_channels(self) -> int:
        return INPUT_CHANNELS[self.input_mode]

    @property
    def pad_multiple(self) -> int:
        """Inputs are padded to a multiple of this. RT-DETR's feature pyramid needs sizes divisible by its
        coarsest stride (32), and its anchors span the padded grid, so its boxes are normalised by the padded size
        (``detector.inputs.box_frame``)."""
        return 32 if self.arch == "rt_detr" else 1


PRESETS: dict[str, DetectorConfig] = {
    # From scratch on 2 CPU cores (docs/detector.md, "what helped"): RT-DETR on colour + depth.
    "cpu": DetectorConfig(arch="rt_detr", backbone_stage=4, input_mode="rgbd", num_queries=20),
    "paper": DetectorConfig(
        preset="paper",
        backbone="resnet101",
        dilation=True,
        backbone_stage=4,
        trainable_norm=False,
        d_model=256,
        encoder_layers=6,
        decoder_layers=6,
        attention_heads=8,
        ffn_dim=2048,
        num_queries=100,
        dropout=0.1,
        auxiliary_loss=True,
        input_width=640,
        freeze_stem=True,
    ),
}


def preset(name: str, **overrides) -> DetectorConfig:
    """A copy of preset ``name`` with ``overrides`` applied (unknown names raise ``ValueError``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown detector preset {name!r}; choose one of {sorted(PRESETS)}")
    return replace(PRESETS[name], **{k: v for k, v in overrides.items() if v is not None})


def detr_config(cfg: DetectorConfig) -> DetrConfig | ConditionalDetrConfig:
    """The transformers config of ``cfg`` (offline: a timm backbone with random weights)."""
    backbone = {
        "model_type": "timm_backbone",
        "backbone": cfg.backbone,
        "num_channels": cfg.num_channels,
        "features_only": True,
        "use_pretrained_backbone": False,
        "out_indices": [cfg.backbone_stage],
    }
    if cfg.dilation:
        backbone["output_stride"] = 16
    if cfg.arch == "rt_detr":
        return _rt_detr_config(cfg, backbone)
    config_class = ARCHS[cfg.arch][0]
    extra = {"eos_coefficient": cfg.eos_coefficient} if cfg.arch == "detr" else {}
    return config_class(backbone_config=backbone, dilation=cfg.dilation, **_shared_config(cfg), **extra)


def _shared_config(cfg: DetectorConfig) -> dict:
    """The transformers config arguments that every arch takes from ``cfg`` alike."""
    return {
        "num_channels": cfg.num_channels,
        "num_labels": 1,
        "id2label": {0: "person"},
        "label2id": {"person": 0},
        "num_queries": cfg.num_queries,
        "d_model": cfg.d_model,
        "encoder_layers": cfg.encoder_layers,
        "decoder_layers": cfg.decoder_layers,
        "encoder_attention_heads": cfg.attention_heads,
        "decoder_attention_heads": cfg.attention_heads,
        "encoder_ffn_dim": cfg.ffn_dim,
        "decoder_ffn_dim": cfg.ffn_dim,
        "dropout": cfg.dropout,
        "auxiliary_loss": cfg.auxiliary_loss,
    }


def _rt_detr_config(cfg: DetectorConfig, backbone: dict) -> RTDetrConfig:
    """RT-DETR on the last three stages of the timm backbone; widths follow ``cfg`` (``encoder_layers`` counts
    the attention layers on the coarsest scale, RT-DETR's AIFI)."""
    stages = [cfg.backbone_stage - 2, cfg.backbone_stage - 1, cfg.backbone_stage]
    # The stages' channels and strides, from a throwaway timm model (random weights, offline).
    info = timm.create_model(
        cfg.backbone,
        pretrained=False,
        features_only=True,
        out_indices=stages,
        in_chans=cfg.num_channels,
        **({"output_stride": 16} if cfg.dilation else {}),
    ).feature_info
    return RTDetrConfig(
        backbone_config={**backbone, "out_indices": stages},
        freeze_backbone_batch_norms=not cfg.trainable_norm,
        encoder_in_channels=info.channels(),
        feat_strides=info.reduction(),
        encoder_hidden_dim=cfg.d_model,
        decoder_in_channels=[cfg.d_model] * 3,
        num_denoising=cfg.num_queries,  # denoising queries: noised copies of the true boxes (DN-DETR)
        **_shared_config(cfg),
    )


def _unfreeze_norm(module: nn.Module) -> None:
    """Replace DETR's frozen batch norms under ``module`` by trainable ``nn.BatchNorm2d`` with the same
    values."""
    for name, child in module.named_children():
        if type(child).__name__.endswith("FrozenBatchNorm2d"):
            bn = nn.BatchNorm2d(child.weight.numel())
            with torch.no_grad():
                bn.weight.copy_(child.weight)
                bn.bias.copy_(child.bias)
                bn.running_mean.copy_(child.running_mean)
                bn.running_var.copy_(child.running_var)
            setattr(module, name, bn)
        else:
            _unfreeze_norm(child)


def set_trainable(model: DetrForObjectDetection, cfg: DetectorConfig) -> None:
    """Set ``requires_grad`` explicitly: transformers 5.23's own backbone freezing is wrong (see
    ENVIRONMENT.md).

    Everything trains, except the stem and layer1 of the backbone when ``cfg.freeze_stem`` (a pretrained
    backbone).
    """
    for p in model.parameters():
        p.requires_grad_(True)
    if cfg.freeze_stem:
        for name, p in model.model.backbone.model.named_parameters():
            if not {"layer2", "layer3", "layer4"} & set(name.split(".")):
                p.requires_grad_(False)


def arch_classes(model_type: str) -> tuple[type, type]:
    """The transformers (config class, model class) of a DETR-family ``model_type``."""
    if model_type not in ARCHS:
        raise ValueError(f"unsupported detector model_type {model_type!r}; expected one of {sorted(ARCHS)}")
    return ARCHS[model_type]


def from_detr_config(config, cfg: DetectorConfig) -> DetrForObjectDetection:
    """A randomly initialised model of ``config``, with ``cfg``'s norm and freezing choices applied."""
    model = arch_classes(config.model_type)[1](config)
    if cfg.trainable_norm:
        _unfreeze_norm(model.model.backbone.model)
    set_trainable(model, cfg)
    return model


def build_detector(cfg: DetectorConfig) -> DetrForObjectDetection:
    """The detector of ``cfg``: random weights, or real DETR weights from ``cfg.pretrained`` with a new
    1-class head.

    A pretrained DETR keeps its own architecture (read from its folder); only the class head is replaced. Its
    backbone must read the same number of channels as ``cfg.input_mode`` gives.
    """
    if cfg.pretrained is None:
        return from_detr_config(detr_config(cfg), cfg)
    model = ARCHS[cfg.arch][1].from_pretrained(
        cfg.pretrained,
        num_labels=1,
        id2label={0: "person"},
        label2id={"person": 0},
        ignore_mismatched_sizes=True,  # the class head: N + 1 classes -> person + no-object
        auxiliary_loss=cfg.auxiliary_loss,
    )
    if model.config.num_channels != cfg.num_channels:
        raise ValueError(
            f"pretrained DETR {cfg.pretrained!r} reads {model.config.num_channels} channels, but input_mode "
            f"{cfg.input_mode!r} gives {cfg.num_channels}"
        )
    if cfg.trainable_norm:
        _unfreeze_norm(model.model.backbone.model)
    set_trainable(model, cfg)
    return model


def with_input_mode(
    model: nn.Module, cfg: DetectorConfig, input_mode: str
) -> tuple[nn.Module, DetectorConfig]:
    """``model`` (of ``cfg``) made to read ``input_mode`` instead: a model of the same architecture whose weights are
    ``model``'s, except that the first convolution keeps only the weights of the channels both inputs share (colour
    for rgbd -> rgb, depth for rgbd -> depth; channels are laid out colour first, then depth: ``detector.inputs``).
    A starting point for fine-tuning to the new input (``detector.train --init CKPT --input MODE``): the dropped
    channels' contribution is gone, so it needs training before use. The same mode returns ``model`` and ``cfg``."""
    if input_mode == cfg.input_mode:
        return model, cfg
    old, new = cfg.input_mode, input_mode
    keep = {"rgb": [0, 1, 2], "depth": [3]} if old == "rgbd" else None
    if keep is None or new not in keep:
        raise ValueError(
            f"a detector reading {old!r} cannot be turned into one reading {new!r}: only rgbd -> rgb or depth "
            "keeps weights for every channel it reads; train from a preset instead"
        )
    new_cfg = replace(cfg, input_mode=new, pretrained=None)
    converted = from_detr_config(detr_config(new_cfg), new_cfg)
    state, _ = keep_input_channels(model.state_dict(), INPUT_CHANNELS[old], keep[new])
    converted.load_state_dict(state)  # every other tensor must fit as it is (strict)
    return converted.train(model.training), new_cfg


def param_groups(model: nn.Module, lr: float, backbone_lr: float, weight_decay: float) -> list[dict]:
    """AdamW groups: the backbone at ``backbone_lr``, the rest at ``lr`` (DETR's recipe); norms get no
    decay."""
    groups = {(b, d): [] for b in (True, False) for d in (True, False)}
    for name, p in model.named_parameters():
        if not p.requires_grad:
            continue
        in_backbone = ".backbone." in f".{name}"
        decay = p.ndim > 1  # biases and norm scales are not decayed
        groups[(in_backbone, decay)].append(p)
    out = []
    for (in_backbone, decay), params in groups.items():
        if params:
            out.append(
                {
                    "params": params,
                    "lr": backbone_lr if in_backbone else lr,
                    "weight_decay": weight_decay if decay else 0.0,
                    "name": f"{'backbone' if in_backbone else 'transformer'}{'' if decay else '_nodecay'}",
                }
            )
    return out
