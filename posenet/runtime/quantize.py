"""int8: both networks quantized for OpenVINO by NNCF's post-training quantization, calibrated on rendered scenes.

On a CPU without native bf16 (AVX2-only: AMD Zen 2/3, older Xeons) float32 is the fastest torch can do, and the
convolutions are ~90 % of both networks' time. OpenVINO runs int8 convolutions about 1.7-1.8x faster than float32
there, and 3.6-4x on a CPU with AMX (``benchmarks/RESULTS.md``), at a cost in accuracy that
``benchmarks/backend_accuracy.py`` measures (day 4, reference boxes, against bf16: +0.05 cm MPJPE on the twin,
+0.09 cm on the unseen alt look; detector AP50 unchanged / -0.001). ``--precision int8`` / ``ORPOSE_PRECISION=int8`` asks for it; it is
never chosen by ``auto``, since it trades accuracy, however little, for speed.

Post-training quantization needs inputs to measure each layer's range: **calibration scenes** that the package's
own renderer draws at first use (``CALIBRATION``: the randomised look on random three-camera rigs, a fixed seed,
so every machine builds the same graph, from the package alone; kept in the runtime cache), never a look or a day
that the figures are measured on. Each
network is run in float32 on them, its inputs recorded at the runtime's boundary (:class:`Recorder`), and
:func:`quantize_graph` writes the int8 graph beside the float32 one in the runtime cache, named by the float32
graph and the calibration, so it is built once per weights (``python -m service.export --int8`` builds it ahead
of time).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from posenet.runtime.execution import cache_dir

log = logging.getLogger(__name__)

# The rendered scenes that calibrate the int8 graphs: enough persons and views to cover each layer's range, few
# enough to render in seconds. Random rigs, so that the package needs no MVOR file: 12 such scenes cost +0.09 /
# +0.14 cm day-4 MPJPE against bf16 (twin / alt look), 36 cost +0.05 / +0.09 (benchmarks/RESULTS.md, 2026-12-06).
# ORPOSE_INT8_SCENES overrides the count (tests use fewer).
CALIBRATION = {"scenes": 36, "rig": "random", "views": 3, "days": 3, "look": "random", "seed": 20261206}


def calibration_config() -> dict:
    scenes = int(os.environ.get("ORPOSE_INT8_SCENES", CALIBRATION["scenes"]))
    if scenes < 1:
        raise ValueError(f"ORPOSE_INT8_SCENES must be at least 1, got {scenes}")
    return {**CALIBRATION, "scenes": scenes, "days": min(CALIBRATION["days"], scenes)}


def _rendered(config_json: str) -> Path:
    """The folder of the calibration scenes, rendered once into the runtime cache
    (``posenet.runtime.execution.cache_dir``, ~10 MB, named by the calibration) and reused by every later build and
    process; the samples are read from it when needed, so they do not stay in memory. The scenes need nothing
    but the package: procedural people on random rigs, never MVOR's annotation file."""
    from posenet.synth.writer import SynthConfig, generate

    cfg = json.loads(config_json)
    folder = cache_dir() / f"int8-calibration-{hashlib.sha256(config_json.encode()).hexdigest()[:12]}"
    if (folder / "annotations.json").is_file():
        return folder
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f"{folder.name}.", dir=folder.parent))
    try:
        generate(SynthConfig(out=str(tmp), mode="procedural", workers=1, **cfg), progress=False)
        try:
            tmp.rename(folder)  # whole or not at all; another process may have finished first
        except OSError:
            if not (folder / "annotations.json").is_file():
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return folder


def calibration_samples() -> Iterator:
    """The calibration scenes (``CALIBRATION``) as ``posenet.data.sample.Sample`` s, read one at a time."""
    from posenet.data.mvor import MvorDataset, load_annotations

    folder = _rendered(json.dumps(calibration_config(), sort_keys=True))
    dataset = MvorDataset(folder, load_annotations(folder / "annotations.json"), 1, ("color", "depth"))
    return (dataset[i] for i in range(len(dataset)))


class Recorder:
    """Wraps a runtime runner: records the (numpy) inputs of every call, then runs it."""

    def __init__(self, runner: Callable) -> None:
        self.runner = runner
        self.inputs: list[dict[str, np.ndarray]] = []

    def __call__(self, **inputs):
        names = getattr(self.runner, "input_names", list(inputs))
        self.inputs.append({k: v.detach().cpu().numpy().copy() for k, v in inputs.items() if k in names})
        return self.runner(**inputs)


_lock = threading.Lock()


def int8_path(graph: Path) -> Path:
    """Where the int8 graph of the float32 ONNX ``graph`` is cached: named by it and by the calibration."""
    import nncf

    key = json.dumps({"calibration": calibration_config(), "nncf": nncf.__version__}, sort_keys=True)
    return graph.with_name(f"{graph.stem}-int8-{hashlib.sha256(key.encode()).hexdigest()[:12]}.xml")


def quantize_graph(graph: Path, collect: Callable[[], list[dict]], transformer: bool = False) -> Path:
    """The int8 OpenVINO graph (``.xml``) of the float32 ONNX ``graph``, built unless cached.

    ``collect()`` returns the calibration inputs (one dict of named arrays per call); it runs only when the graph
    must be built. ``transformer`` selects NNCF's transformer scheme (the detector's attention layers)."""
    path = int8_path(graph)
    with _lock:
        if path.is_file():
            return path
        import nncf
        import openvino as ov

        inputs = collect()
        if not inputs:
            raise ValueError(
                "no calibration inputs: the calibration scenes gave the network nothing to run on"
            )
        kwargs = {"model_type": nncf.ModelType.TRANSFORMER} if transformer else {}
        model = ov.Core().read_model(str(graph))
        quantized = nncf.quantize(model, nncf.Dataset(inputs), subset_size=len(inputs), **kwargs)
        tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.xml")
        ov.save_model(quantized, str(tmp))
        # the .bin first, then the .xml that names it: a reader that sees the .xml finds its weights
        tmp.with_suffix(".bin").replace(path.with_suffix(".bin"))
        tmp.replace(path)
        log.info("quantized %s to %s on %d calibration inputs", graph.name, path.name, len(inputs))
        return path
