"""Cancelling a request's work from another thread: torch layers, the ops between them, and runtime calls."""

from __future__ import annotations

import threading
import time

import pytest
import torch

from posenet.runtime.execution import Precision
from posenet.runtime.graphs import OnnxRunner, export_onnx, installed
from service.cancel import Cancelled, CancelToken


def slow_net() -> torch.nn.Module:
    torch.manual_seed(0)
    return torch.nn.Sequential(*[torch.nn.Conv2d(16, 16, 3, padding=1) for _ in range(40)]).eval()


def stopped_after(work, cancel_at_s: float = 0.2) -> float:
    """Seconds from ``token.cancel()`` (``cancel_at_s`` into ``work(token)``) until the work has raised."""
    token = CancelToken()
    threading.Timer(cancel_at_s, token.cancel).start()
    t0 = time.perf_counter()
    with pytest.raises(Exception) as err:  # Cancelled, or the runtime's own error
        token.run(work)
    assert (
        isinstance(err.value, Cancelled)
        or "cancel" in str(err.value).lower()
        or "terminate" in str(err.value)
    )
    return time.perf_counter() - t0 - cancel_at_s


def test_torch_work_stops_at_the_next_layer_or_op():
    net, x = slow_net(), torch.randn(32, 16, 96, 96)

    def work():
        with torch.inference_mode():
            for _ in range(100):  # far longer than the test waits
                net(x)

    assert stopped_after(work) < 0.5
    assert net(torch.zeros(1, 16, 8, 8)).shape == (1, 16, 8, 8)  # the thread and the module are unharmed


def test_python_work_between_layers_stops():
    def work():
        while True:
            torch.ones(100).sum()

    assert stopped_after(work) < 0.5


@pytest.mark.parametrize("backend", ["onnxruntime", "openvino"])
def test_a_runtime_call_stops(tmp_path, backend):
    if not installed(backend):
        pytest.skip(f"{backend} is not installed")
    net, x = slow_net(), torch.randn(48, 16, 96, 96)
    path = export_onnx(net, [x[:1]], ["x"], ["y"], {"x": {0: "b"}}, "slow", {}, folder=tmp_path)
    runner = OnnxRunner(path, backend, threads=1, precision=Precision("fp32", "test"))
    t0 = time.perf_counter()
    runner(x=x)
    if time.perf_counter() - t0 < 0.6:
        pytest.skip("the runtime is too fast here for a cancellation 0.2 s in to mean anything")
    assert stopped_after(lambda: runner(x=x)) < 0.5
    assert runner(x=x[:1])[0].shape == (1, 16, 96, 96)  # the runner works again afterwards
