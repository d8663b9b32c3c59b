"""How a model runs on *this* machine: its numeric precision, and the facts about the machine behind the choice.

A checkpoint never decides its own precision: the machine that trained it may have computed bf16 natively while
the machine that runs it emulates bf16 7-20x slower than float32 (AMD Zen 2/3, most AVX2-only CPUs). So the
precision is resolved where the model runs, at load time:

- ``auto`` (the default): bf16 on a CUDA GPU that supports it, and on a CPU that computes bf16 natively
  (AVX512-BF16 or AMX, with torch's kernels allowed to use it); float32 everywhere else.
- ``fp32`` / ``bf16`` force a choice (``--precision`` on the command lines, ``ORPOSE_PRECISION`` for the service).
- ``int8`` (inference only): both networks quantized for OpenVINO (``posenet.runtime.quantize``), the fastest choice on a
  CPU without native bf16; torch and ONNX Runtime then compute float32. On OpenVINO ``auto`` picks it for a graph
  whose accuracy cost is on record and small, where this machine measures it faster
  (``posenet.runtime.auto_int8``).

``machine()`` describes the machine in the terms a speed figure needs (CPU model, cores, torch's CPU capability,
native bf16, library versions), so that every benchmark can record it beside its numbers.

To see what an AVX2-only machine does on a newer one, cap both torch's and oneDNN's instruction sets::

    ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 python benchmarks/posenet_speed.py

``auto`` then resolves to float32 here too, since torch's capability is no longer AVX512.
"""

from __future__ import annotations

import functools
import os
import platform
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import torch

PRECISIONS = ("auto", "fp32", "bf16")  # what torch computes at (training, and inference on torch)
RUN_PRECISIONS = (*PRECISIONS, "int8")  # what inference may ask for: int8 runs on OpenVINO
# CPU flags (as /proc/cpuinfo spells them) that make bf16 arithmetic native rather than emulated.
NATIVE_BF16_FLAGS = frozenset({"amx_bf16", "avx512_bf16"})


@dataclass(frozen=True)
class Precision:
    """A resolved precision: ``name`` is ``fp32``, ``bf16`` or ``int8``; ``reason`` says why, in one sentence."""

    name: str
    reason: str
    auto: bool = (
        False  # resolved by ``auto``: on OpenVINO, int8 may still be chosen (posenet.runtime.auto_int8)
    )

    @property
    def bf16(self) -> bool:
        return self.name == "bf16"

    @property
    def int8(self) -> bool:
        return self.name == "int8"

    def on_torch(self) -> Precision:
        """What torch computes when asked for this precision: int8 graphs are OpenVINO's, torch runs float32."""
        if self.int8:
            return Precision(
                "fp32", "int8 was asked for, but it runs on OpenVINO only: torch computes float32"
            )
        return self


@functools.cache
def cpu_flags() -> frozenset[str]:
    """The CPU's feature flags from /proc/cpuinfo (empty where there is none, e.g. macOS)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return frozenset()
    for line in text.splitlines():
        if line.startswith("flags"):
            return frozenset(line.split(":", 1)[1].split())
    return frozenset()


@functools.cache
def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def cpu_capability() -> str:
    """torch's CPU kernel level: ``DEFAULT``, ``AVX2``, ``AVX512`` (lowered by ``ATEN_CPU_CAPABILITY``)."""
    return torch.backends.cpu.get_cpu_capability()


def native_bf16(device: str | torch.device = "cpu") -> tuple[bool, str]:
    """Whether ``device`` computes bf16 natively, and why (or why not)."""
    device = torch.device(device)
    if device.type == "cuda":
        ok = torch.cuda.is_available() and torch.cuda.is_bf16_supported()
        return ok, f"CUDA device {'supports' if ok else 'does not support'} bf16"
    if device.type != "cpu":
        return False, f"no bf16 policy for device type {device.type!r}"
    flags = sorted(NATIVE_BF16_FLAGS & cpu_flags())
    capability = cpu_capability()
    if not flags:
        return False, (
            f"the CPU ({cpu_model()}, {capability}) has no native bf16 (neither AVX512-BF16 nor AMX): "
            "bf16 would be emulated, several times slower than fp32"
        )
    if not capability.startswith("AVX512"):
        return False, (
            f"the CPU has {'/'.join(flags)}, but torch's CPU capability is {capability} "
            "(ATEN_CPU_CAPABILITY caps it), so bf16 kernels would be emulated"
        )
    if not torch.backends.mkldnn.is_available() or not torch.ops.mkldnn._is_mkldnn_bf16_supported():
        return False, "oneDNN has no bf16 kernels here (ONEDNN_MAX_CPU_ISA may cap it)"
    return True, f"the CPU computes bf16 natively ({'/'.join(flags)}, torch capability {capability})"


def resolve_precision(requested: str | None = "auto", device: str | torch.device = "cpu") -> Precision:
    """The precision to run at on ``device``: ``requested`` (one of ``RUN_PRECISIONS``; None = ``auto``)."""
    requested = requested or "auto"
    if requested not in RUN_PRECISIONS:
        raise ValueError(f"precision must be one of {RUN_PRECISIONS}, got {requested!r}")
    if requested == "int8":
        return Precision(
            "int8", "int8 was asked for: OpenVINO runs quantized graphs (posenet.runtime.quantize)"
        )
    if requested != "auto":
        return Precision(requested, f"{requested} was asked for")
    ok, why = native_bf16(device)
    return Precision("bf16" if ok else "fp32", why, auto=True)


def default_precision() -> str:
    """``$ORPOSE_PRECISION`` or ``auto``: the default of every ``--precision`` option."""
    return os.environ.get("ORPOSE_PRECISION", "auto")


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def machine() -> dict:
    """What a speed figure needs beside it: CPU model, cores, capability, native bf16, library versions."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    flags = cpu_flags()
    return {
        "cpu": cpu_model(),
        "cores": cores,
        "torch_capability": cpu_capability(),
        "avx512": "avx512f" in flags,
        "native_bf16": native_bf16("cpu")[0],
        "amx": "amx_tile" in flags,
        "torch": torch.__version__,
        "onnxruntime": _version("onnxruntime"),
        "openvino": _version("openvino"),
        "threads": torch.get_num_threads(),
    }


def machine_line(info: dict | None = None) -> str:
    """``machine()`` as the one line that benchmarks print above their tables."""
    m = info or machine()
    runtimes = ", ".join(f"{k} {m[k]}" for k in ("onnxruntime", "openvino") if m.get(k))
    return (
        f"machine: {m['cpu']}, {m['cores']} cores, torch capability {m['torch_capability']}, native bf16 "
        f"{'yes' if m['native_bf16'] else 'no'}; torch {m['torch']}{', ' + runtimes if runtimes else ''}"
    )


def cache_dir() -> Path:
    """Where this machine keeps what it builds from the loaded weights (exported graphs, int8 calibration):
    ``$ORPOSE_CACHE_DIR``, else ``~/.cache/or-pose``."""
    return Path(os.environ.get("ORPOSE_CACHE_DIR", Path.home() / ".cache" / "or-pose"))
