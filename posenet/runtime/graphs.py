"""Inference runtimes: a torch module exported once to ONNX, then run by ONNX Runtime or OpenVINO.

Both networks of the service (the pose network's U-Net, the detector) are plain convolution/attention graphs
that an inference runtime runs faster on a CPU than eager torch does (fused batch norm, tuned kernels, no
Python between layers): ``benchmarks/service_latency.py`` and ``benchmarks/RESULTS.md`` compare them. torch
stays the fallback, and the only choice for training and for GPUs.

Backends (``ORPOSE_BACKEND`` for the service, ``--backend`` on the command lines):

- ``torch``: eager torch, channels_last, bf16 autocast where :mod:`posenet.runtime.execution` chooses bf16;
- ``onnxruntime``: ONNX Runtime's CPU provider, float32;
- ``openvino``: OpenVINO's CPU plugin, float32, or bf16 where the CPU computes bf16 natively, or int8 when asked
  for (``posenet.runtime.quantize``: quantized graphs, cached beside the float32 ones);
- ``auto`` (default): ``openvino`` if it is installed, else ``onnxruntime``, else ``torch``; torch on a GPU.

The ONNX files are **built at first use** from the weights being loaded and cached under
``$ORPOSE_CACHE_DIR`` (default ``~/.cache/or-pose``), named by a hash of the weights, the config and the
exporter, so a changed checkpoint can never meet a stale graph. They are not shipped: the float32 graph of the
detector alone is 60 MB, more than the repository's budget for weights, and an export takes a few seconds.
``python -m service.export`` builds them ahead of time (the Docker image does, so containers start warm).
If an export or a runtime fails, the model runs on torch and the reason is logged and reported by ``/model``.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import json
import logging
import os
import threading
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from posenet.runtime.execution import Precision, cache_dir

BACKENDS = ("auto", "torch", "onnxruntime", "openvino")
# Bumped whenever the export itself changes, so that cached graphs of an older exporter are rebuilt.
EXPORT_VERSION = 1
OPSET = 17
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Backend:
    """A resolved backend: ``name`` (``torch``, ``onnxruntime`` or ``openvino``) and why it was chosen."""

    name: str
    reason: str


def installed(backend: str) -> bool:
    module = {"onnxruntime": "onnxruntime", "openvino": "openvino", "torch": "torch"}[backend]
    return importlib.util.find_spec(module) is not None


def resolve_backend(requested: str | None = "auto", device: str | torch.device = "cpu") -> Backend:
    """The backend to run on: ``requested`` (one of ``BACKENDS``; None = ``auto``) on ``device``."""
    requested = requested or "auto"
    if requested not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {requested!r}")
    device = torch.device(device)
    if requested == "torch":
        return Backend("torch", "torch was asked for")
    if device.type != "cpu":
        return Backend("torch", f"the ONNX runtimes here run on the CPU, and the device is {device}")
    if requested != "auto":
        if not installed(requested):
            raise ValueError(f"backend {requested!r} is not installed: pip install {requested}")
        return Backend(requested, f"{requested} was asked for")
    for name in ("openvino", "onnxruntime"):
        if installed(name):
            return Backend(name, f"auto: {name} is installed (fastest measured here, benchmarks/RESULTS.md)")
    return Backend("torch", "auto: neither openvino nor onnxruntime is installed")


def load_runner(
    backend: str | None,
    device: str | torch.device,
    export: Callable[[], Path],
    threads: int | None,
    precision: Precision,
    calibrate: Callable[[OnnxRunner], list[dict]] | None = None,
    transformer: bool = False,
    static_batch: bool = False,
) -> tuple[OnnxRunner | None, Backend]:
    """The runner of ``backend`` for the graph that ``export()`` builds, or None for torch; and the backend that
    runs. Any failure of an export or a runtime falls back to torch, with the reason, so a model always runs.

    At ``int8`` precision on OpenVINO the graph is quantized (``posenet.runtime.quantize``): ``calibrate(runner)`` runs
    a float32 ``runner`` on the calibration scenes and returns its recorded inputs (called only when the int8
    graph is not cached yet); ``transformer`` selects NNCF's scheme for attention layers. If quantizing fails,
    the float32 graph runs, and its precision's reason says why. At ``auto`` precision on OpenVINO the int8 graph
    runs where ``posenet.runtime.auto_int8`` finds its cost on record and this machine measures it faster.
    ``static_batch``: :class:`OnnxRunner`'s, for every OpenVINO runner built here."""
    chosen = resolve_backend(backend, device)
    if chosen.name == "torch":
        return None, chosen
    threads = threads or torch.get_num_threads()
    try:
        graph = export()
        if precision.auto and not precision.int8 and chosen.name == "openvino" and calibrate is not None:
            from posenet.runtime.auto_int8 import choose

            runner, precision = choose(
                graph, threads, precision,
                functools.partial(OnnxRunner, graph, "openvino", threads, precision, static_batch),
                lambda: _int8_runner(graph, threads, calibrate, transformer, static_batch=static_batch),
            )  # fmt: skip
            return runner, chosen
        if precision.int8 and chosen.name == "openvino":
            try:
                return _int8_runner(graph, threads, calibrate, transformer, precision, static_batch), chosen
            except (Exception, SystemExit) as exc:  # whatever calibration raises, float32 still runs
                log.warning("int8 quantization failed, running float32: %s", exc)
                precision = Precision("fp32", f"int8 failed ({type(exc).__name__}: {exc}); float32")
        return OnnxRunner(graph, chosen.name, threads, precision, static_batch), chosen
    except (Exception, SystemExit) as exc:  # a broken runtime must leave a working (torch) model
        return None, Backend("torch", f"{chosen.name} failed ({type(exc).__name__}: {exc}); using torch")


def _int8_runner(
    graph: Path,
    threads: int,
    calibrate,
    transformer: bool,
    precision: Precision | None = None,
    static_batch: bool = False,
) -> OnnxRunner:
    """OpenVINO's runner of the int8 graph of ``graph`` (quantized now unless cached; ``load_runner``'s
    ``calibrate`` runs the float32 graph on the calibration scenes)."""
    from posenet.runtime.quantize import quantize_graph

    fp32 = Precision("fp32", "the float32 graph that int8 is calibrated from")
    float32 = functools.partial(OnnxRunner, graph, "openvino", threads, fp32)
    precision = precision or Precision("int8", "int8")
    int8 = quantize_graph(graph, lambda: calibrate(float32()), transformer)
    return OnnxRunner(int8, "openvino", threads, precision, static_batch)


def graph_key(module: torch.nn.Module, extra: dict) -> str:
    """A hash of ``module``'s weights, ``extra`` (its config, input shapes) and the exporter's versions."""
    h = hashlib.sha256()
    for name, tensor in module.state_dict().items():
        h.update(name.encode())
        h.update(tensor.detach().cpu().contiguous().numpy().tobytes())
    h.update(json.dumps(extra, sort_keys=True, default=str).encode())
    h.update(f"{torch.__version__}/{EXPORT_VERSION}/{OPSET}".encode())
    return h.hexdigest()[:20]


def export_onnx(
    module: torch.nn.Module,
    example: Sequence[torch.Tensor],
    input_names: Sequence[str],
    output_names: Sequence[str],
    dynamic_axes: dict,
    name: str,
    extra: dict,
    folder: Path | None = None,
) -> Path:
    """Export ``module`` (float32, eval) to ``FOLDER/NAME-<key>.onnx`` unless that file exists; its path.

    The graph is traced on ``example``; ``dynamic_axes`` names the axes that may change size (the batch).
    Written beside and renamed, so a crash mid-export never leaves a half-written graph in the cache.
    """
    folder = Path(folder or cache_dir())
    path = folder / f"{name}-{graph_key(module, extra)}.onnx"
    if path.is_file():
        return path
    folder.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".{os.getpid()}.{threading.get_ident()}.tmp")
    # Every submodule's own mode, restored exactly: the exporter restores only the top module's mode, which
    # for a fresh wrapper (training=True) would switch the wrapped network's batch norms to training.
    modes = {m: m.training for m in module.modules()}
    module.eval()
    try:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore")  # tracer warnings about Python control flow on shapes
            torch.onnx.export(
                module,
                tuple(example),
                str(tmp),
                input_names=list(input_names),
                output_names=list(output_names),
                dynamic_axes=dynamic_axes,
                opset_version=OPSET,
                dynamo=False,
            )
        tmp.replace(path)
    finally:
        for m, training in modes.items():
            m.training = training
        tmp.unlink(missing_ok=True)
    log.info("exported %s to %s", name, path)
    return path


# The batch sizes that an OnnxRunner(static_batch=True) compiles at fixed shapes: a rig's views, and one camera
# fewer. Each is a copy of the graph in memory (OnnxRunner).
MAX_STATIC_BATCHES = 2

# A call that a thread is running, and how to end it early from another thread (it then raises in the caller):
# the service stops the work of a client that has disconnected (service/cancel.py).
_stoppers: dict[int, Callable[[], object]] = {}


def stop_call(thread: int) -> bool:
    """End the runtime call that ``thread`` (a ``threading.get_ident()``) is running, if any: it raises there.
    Returns whether there was one."""
    stop = _stoppers.get(thread)
    if stop is not None:
        stop()
    return stop is not None


class OnnxRunner:
    """An exported graph called like the module it came from: torch tensors in, a tuple of tensors out.

    Args:
        path: the ``.onnx`` file, or OpenVINO's ``.xml`` (the int8 graphs of ``posenet.runtime.quantize``).
        backend: ``onnxruntime`` or ``openvino``.
        threads: intra-op threads (the service's ``ORPOSE_THREADS``).
        precision: bf16 is used by OpenVINO only (ONNX Runtime's CPU provider computes float32); int8 means
            ``path`` is a quantized graph.
        static_batch: OpenVINO compiles the graph once per batch size it is called with, each with every shape
            fixed, instead of once with a dynamic batch (:meth:`prepare` compiles one ahead). For a graph whose
            batch takes few values (the detector's: one image per view): its int8 graph ran 12.0 against 14.2
            ms per 3-view frame (p50 of 400 alternating calls; AMD EPYC Zen 4, 2 threads, 2026-12-07;
            benchmarks/RESULTS.md, "Fixed shapes for the detector"). Each new batch size costs a compilation
            (1.1-1.9 s) on its first call and holds its own copy of the graph (73 MB for the detector's int8
            graph), so only the first ``MAX_STATIC_BATCHES`` batch sizes are compiled so; any other runs on the
            graph with a dynamic batch, compiled when first needed.
    """

    def __init__(
        self, path: str | Path, backend: str, threads: int, precision: Precision, static_batch: bool = False
    ) -> None:
        self.path = Path(path)
        self.backend = backend
        self.threads = threads
        self.precision = precision if backend == "openvino" else Precision("fp32", "ONNX Runtime runs fp32")
        self.static_batch = static_batch and backend == "openvino"
        self._static: dict[int, object] = {}  # batch size -> the graph compiled for it (static_batch)
        if backend == "onnxruntime":
            import onnxruntime as ort

            options = ort.SessionOptions()
            options.intra_op_num_threads = threads
            options.inter_op_num_threads = 1
            options.log_severity_level = 3
            self._session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
            self.input_names = [i.name for i in self._session.get_inputs()]
        elif backend == "openvino":
            import openvino as ov

            self._compiled = None  # the dynamic-batch graph: compiled now, or with static_batch when first needed
            # the inputs as the graph declares them: from the compiled graph, or the file when nothing is compiled yet
            ports = ov.Core().read_model(str(self.path)).inputs if self.static_batch else self._compile().inputs
            # names and shapes (None: a dynamic dimension)
            self.input_shapes = {
                port.get_any_name(): [d.get_length() if d.is_static else None for d in port.get_partial_shape()]
                for port in ports
            }
            self.input_names = list(self.input_shapes)
            self._local = threading.local()  # an infer request per thread: requests are not thread-safe
        else:
            raise ValueError(f"OnnxRunner runs onnxruntime or openvino, not {backend!r}")

    def _compile(self, batch: int | None = None):
        """Compile the graph with its batch dynamic (``batch`` None: kept as ``_compiled``) or fixed to ``batch``
        (returned)."""
        import openvino as ov

        hint = "bf16" if self.precision.bf16 else "f32"
        model = str(self.path)
        if batch is not None:
            model = ov.Core().read_model(model)
            model.reshape({
                port.get_any_name(): ov.PartialShape([batch, *list(port.get_partial_shape())[1:]])
                for port in model.inputs
            })  # fmt: skip
        # No CPU pinning: the detector's and the U-Net's graphs each pin their threads to the same cores, and a
        # stream runs them at once (the front stage of frame t+1 beside the pose stage of frame t). Unpinned, a
        # 3-camera stream sent at 15 fps was answered at 13.1 against 11.9 frames/s with PNG colour (3 runs each)
        # and 14.4 against 14.1 with JPEG, lag p95 204 against 221 ms (9 runs each; medians of alternating runs,
        # AMD EPYC Zen 4, 2 cores, 2026-12-06; benchmarks/RESULTS.md); a single request's latency did not change.
        compiled = ov.Core().compile_model(
            model,
            "CPU",
            {"INFERENCE_NUM_THREADS": self.threads, "INFERENCE_PRECISION_HINT": hint, "NUM_STREAMS": 1,
             "ENABLE_CPU_PINNING": False},
        )  # fmt: skip
        if batch is None:
            self._compiled = compiled
        return compiled

    def prepare(self, batch: int) -> None:
        """Compile the graph for calls of ``batch`` now rather than at the first (``static_batch`` only, within
        ``MAX_STATIC_BATCHES``)."""
        if self.static_batch and batch not in self._static and len(self._static) < MAX_STATIC_BATCHES:
            self._static[batch] = self._compile(batch)

    def _compiled_for(self, arrays: dict[str, np.ndarray]) -> tuple[object, int | None]:
        """The compiled graph that runs ``arrays``, and its batch size (None: the dynamic graph)."""
        if self.static_batch:
            batch = int(next(iter(arrays.values())).shape[0])
            self.prepare(batch)
            if batch in self._static:
                return self._static[batch], batch
        if self._compiled is None:
            self._compile()
        return self._compiled, None

    def __call__(self, **inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Run on named inputs; inputs that the graph does not use (pruned by the export) are ignored."""
        arrays = {
            k: np.ascontiguousarray(v.detach().cpu().numpy())
            for k, v in inputs.items()
            if k in self.input_names
        }
        missing = set(self.input_names) - set(arrays)
        if missing:
            raise ValueError(f"the graph {self.path.name} needs inputs {sorted(missing)}")
        thread = threading.get_ident()
        if self.backend == "onnxruntime":
            import onnxruntime as ort

            options = ort.RunOptions()
            _stoppers[thread] = lambda: setattr(options, "terminate", True)
            try:
                outs = self._session.run(None, arrays, options)
            finally:
                _stoppers.pop(thread, None)
        else:
            compiled, batch = self._compiled_for(arrays)
            requests = self._local.__dict__.setdefault("requests", {})  # batch -> (compiled, its request)
            held = requests.get(batch)
            if held is None or held[0] is not compiled:
                held = requests[batch] = (compiled, compiled.create_infer_request())
            request = held[1]
            # Asynchronous start and wait rather than infer(): only an asynchronous request can be cancelled.
            _stoppers[thread] = request.cancel
            try:
                request.start_async(arrays)
                request.wait()
            except BaseException:
                # Cancelled, or interrupted (service.cancel raises in this thread). A cancelled run leaves the
                # compiled model's shapes half-updated: the next run with another batch size then fails shape
                # inference inside OpenVINO 2026.4 ("Concat ... {96,...},{5,...}"). So wait for this run to end
                # and compile the graph afresh (a fraction of a second, paid once after a disconnect).
                try:
                    request.cancel()
                    request.wait()
                except Exception:
                    pass
                requests.pop(batch, None)
                if batch is None:
                    self._compile()
                else:
                    self._static.pop(batch, None)
                raise
            finally:
                _stoppers.pop(thread, None)
            outs = [request.results[o] for o in compiled.outputs]
        return tuple(torch.from_numpy(np.array(o, dtype=np.float32, copy=True)) for o in outs)
