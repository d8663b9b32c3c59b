"""Precision chosen by the machine, and the inference runtimes against torch.

The parity test runs the shipped weights of both stages on the example frame (examples/frame) through the
whole pipeline, once on torch (fp32) and once on each installed runtime: joints within 1 mm, boxes within
0.5 px, scores within 1e-3 (issue 11's bounds).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

import posenet.runtime.execution as execution
from posenet.runtime.execution import machine, machine_line, resolve_precision
from posenet.runtime.graphs import BACKENDS, export_onnx, installed, resolve_backend

REPO = Path(__file__).resolve().parents[2]
FRAME = REPO / "examples" / "frame"
RUNTIMES = [b for b in ("onnxruntime", "openvino") if installed(b)]


def test_precision_is_chosen_by_the_machine(monkeypatch):
    assert resolve_precision("fp32").name == "fp32" and resolve_precision("bf16").bf16
    with pytest.raises(ValueError, match="precision must be one of"):
        resolve_precision("fp16")
    # An AVX2-only CPU (AMD Zen 2/3): emulated bf16 is 7-20x slower, so auto is fp32, and says why.
    monkeypatch.setattr(execution, "cpu_flags", lambda: frozenset({"avx2", "fma"}))
    p = resolve_precision("auto")
    assert p.name == "fp32" and "no native bf16" in p.reason
    # Native bf16 flags but torch capped to AVX2 (ATEN_CPU_CAPABILITY): still fp32.
    monkeypatch.setattr(execution, "cpu_flags", lambda: frozenset({"avx512f", "avx512_bf16"}))
    monkeypatch.setattr(execution, "cpu_capability", lambda: "AVX2")
    assert resolve_precision("auto").name == "fp32"
    monkeypatch.setattr(execution, "cpu_capability", lambda: "AVX512")
    if torch.backends.mkldnn.is_available() and torch.ops.mkldnn._is_mkldnn_bf16_supported():
        p = resolve_precision("auto")
        assert p.name == "bf16" and "natively" in p.reason


def test_machine_is_described():
    m = machine()
    assert m["cores"] >= 1 and m["torch_capability"] and m["torch"] == torch.__version__
    assert m["cpu"] in machine_line(m) and "capability" in machine_line(m)


def test_backend_choice():
    assert resolve_backend("torch").name == "torch"
    assert resolve_backend("auto", "cuda").name == "torch"  # the runtimes here are CPU-only
    assert resolve_backend("auto").name == (RUNTIMES[-1] if RUNTIMES else "torch")
    with pytest.raises(ValueError, match="backend must be one of"):
        resolve_backend("tensorrt")
    assert set(BACKENDS) == {"auto", "torch", "onnxruntime", "openvino"}


def test_export_is_cached_by_weights_and_leaves_the_module_as_it_was(tmp_path):
    net = torch.nn.Sequential(torch.nn.Conv2d(3, 4, 3), torch.nn.BatchNorm2d(4)).eval()
    wrapper = torch.nn.Sequential(net)  # a fresh wrapper is in training mode, the network is not
    x = torch.randn(2, 3, 8, 8)
    axes = {"x": {0: "n"}, "y": {0: "n"}}
    a = export_onnx(wrapper, [x], ["x"], ["y"], axes, "t", {}, tmp_path)
    assert not net[1].training  # the exporter must not switch the wrapped batch norm to training
    assert export_onnx(wrapper, [x], ["x"], ["y"], axes, "t", {}, tmp_path) == a  # cached
    with torch.no_grad():
        net[0].weight.add_(1.0)
    assert export_onnx(wrapper, [x], ["x"], ["y"], axes, "t", {}, tmp_path) != a  # new weights, new graph


@pytest.fixture(scope="module")
def example_frame():
    from service.validation import Limits, parse_scene, validate_scene

    files = {}
    for i in range(3):
        files[f"color_{i}"] = (FRAME / f"color_{i}.jpg").read_bytes()
        files[f"depth_{i}"] = (FRAME / f"depth_{i}.png").read_bytes()
    detect = validate_scene(parse_scene((FRAME / "scene.json").read_text(), Limits()), files, Limits(), True)
    boxed = validate_scene(
        parse_scene((FRAME / "scene_boxes.json").read_text(), Limits()), files, Limits(), True
    )
    return detect, boxed


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("onnx")
    mp = pytest.MonkeyPatch()
    mp.setenv("ORPOSE_CACHE_DIR", str(folder))
    yield folder
    mp.undo()


@pytest.mark.skipif(not RUNTIMES, reason="neither onnxruntime nor openvino is installed")
@pytest.mark.parametrize("backend", RUNTIMES)
def test_runtime_matches_torch_on_the_example_frame(backend, example_frame, cache):
    from pipeline.two_stage import ScenePipeline

    detect, boxed = example_frame
    ref = ScenePipeline.from_checkpoints(precision="fp32", backend="torch")
    run = ScenePipeline.from_checkpoints(precision="fp32", backend=backend, threads=2)
    assert run.pose.backend.name == backend and run.detector.backend.name == backend
    # Detector mode: the same persons, boxes and scores.
    a, b = ref.run(detect.views), run.run(detect.views)
    assert len(a.persons) == len(b.persons) > 0
    for p, q in zip(a.persons, b.persons, strict=True):
        assert p.support == q.support
        np.testing.assert_allclose(q.boxes, p.boxes, atol=0.5)  # pixels (zeros where neither has a box)
        np.testing.assert_allclose(q.scores, p.scores, atol=1e-3)  # NaN where neither has one
    # Pose: the same joints from the same boxes (the frame's reference boxes, and torch's detections). Joints
    # from the two detectors' own boxes may differ by more: a box moved by 1e-4 px can move a crop pixel onto
    # another depth pixel at a depth edge (nearest sampling), which once moved a joint by 1.2 mm.
    detected = [
        [
            a.boxes.boxes[a.boxes.has_box[:, v], v].astype(np.float32) for v in range(3)
        ],
        [
            np.flatnonzero(a.boxes.has_box[:, v]) for v in range(3)
        ],
    ]
    for views, boxes, ids in ((boxed.views, boxed.boxes, boxed.person_ids), (detect.views, *detected)):
        a, b = ref.run(views, boxes, ids), run.run(views, boxes, ids)
        assert len(a.persons) == len(b.persons) > 0
        for p, q in zip(a.persons, b.persons, strict=True):
            np.testing.assert_allclose(q.joints, p.joints, atol=1.0)  # mm


def test_a_failing_runtime_falls_back_to_torch(monkeypatch, tmp_path):
    import posenet.runtime.graphs
    from posenet.net.infer import PoseEstimator

    def broken(*args, **kwargs):
        raise RuntimeError("no such runtime here")

    monkeypatch.setattr(posenet.runtime.graphs, "OnnxRunner", broken)
    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    est = PoseEstimator.from_checkpoint(None, precision="fp32", backend=RUNTIMES[0] if RUNTIMES else "torch")
    assert est.backend.name == "torch"
    if RUNTIMES:
        assert "no such runtime here" in est.backend.reason


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_model_route_says_how_each_network_runs_and_on_what(tmp_path, precision):
    import httpx
    from service_harness import Server, tiny_checkpoints

    if precision == "int8" and not installed("openvino"):
        pytest.skip("int8 runs on OpenVINO, which is not installed")
    pose, det = tiny_checkpoints(tmp_path / "ckpt")
    backend = "openvino" if precision == "int8" else RUNTIMES[0] if RUNTIMES else "torch"
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(det), "ORPOSE_INT8_SCENES": "1",
           "ORPOSE_PRECISION": precision, "ORPOSE_BACKEND": backend, "ORPOSE_CACHE_DIR": str(tmp_path / "onnx")}  # fmt: skip
    with Server(env, startup_s=120) as url:
        info = httpx.get(f"{url}/model", timeout=30).json()
        if precision == "int8":  # the quantized graphs answer a real frame
            frame = {f"{k}_{i}": (f"{k}_{i}.{ext}", (FRAME / f"{k}_{i}.{ext}").read_bytes())
                     for i in range(3) for k, ext in (("color", "jpg"), ("depth", "png"))}  # fmt: skip
            r = httpx.post(f"{url}/scenes", data={"scene": (FRAME / "scene_boxes.json").read_text()},
                           files=frame, timeout=60)  # fmt: skip
            assert r.status_code == 200 and r.json()["persons"], r.text
    runtime = {r["network"]: r for r in info["runtime"]}
    assert set(runtime) == {"pose", "detector"}
    for r in runtime.values():
        assert r["backend"] == backend and r["precision"] == precision and r["precision_reason"]
    if precision == "int8":
        assert list((tmp_path / "onnx").glob("*-int8-*.xml"))  # built at first start, in the cache
    assert info["machine"]["torch_capability"] and info["machine"]["cores"] >= 1


@pytest.mark.skipif(not installed("openvino"), reason="openvino is not installed")
@pytest.mark.parametrize("static_batch", [False, True])
def test_a_cancelled_openvino_call_leaves_the_runner_usable(tmp_path, monkeypatch, static_batch):
    """OpenVINO 2026.4 keeps a cancelled run's shapes: the next run at another batch size failed shape inference
    (Concat {96,...} against {5,...}) until the runner compiled its graph afresh after a cancel. A runner compiled
    per batch size (``static_batch``) drops the cancelled batch's graph."""
    import threading
    import time

    from posenet.net.infer import PoseEstimator
    from posenet.runtime.graphs import OnnxRunner, stop_call

    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    est = PoseEstimator.from_checkpoint(None, precision="fp32", backend="openvino", threads=2)
    if static_batch:
        runner = est.model.runner
        est.model.runner = OnnxRunner(runner.path, "openvino", 2, runner.precision, static_batch=True)
    cfg = est.model.config
    side = cfg.inputs.crop_size  # the shipped weights' crops; the big batch holds 96 crops' worth of 96x96 pixels
    big = torch.randn(96 * 96 * 96 // side**2, cfg.inputs.in_channels, side, side)
    small = torch.randn(5, cfg.inputs.in_channels, side, side)
    outcome = {}

    def work():
        try:
            outcome["out"] = est.model.runner(x=big)
        except RuntimeError as exc:
            outcome["error"] = str(exc)

    for _ in range(3):  # a cancel lands mid-run on at least one try
        t = threading.Thread(target=work)
        t.start()
        time.sleep(0.02)
        stop_call(t.ident)
        t.join()
    with torch.inference_mode():
        ref = est.model.unet(small)
    torch.testing.assert_close(est.model.runner(x=small)[0], ref, atol=1e-3, rtol=1e-3)


def test_openvino_graphs_keep_the_thread_count_and_do_not_pin_cores(tmp_path, monkeypatch):
    """Both networks' graphs run at once in a stream: pinned to the same cores they slowed each other
    (posenet.runtime.graphs.OnnxRunner._compile)."""
    from posenet.net.infer import PoseEstimator

    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    runner = PoseEstimator.from_checkpoint(None, precision="fp32", backend="openvino", threads=2).model.runner
    assert runner._compiled.get_property("ENABLE_CPU_PINNING") is False
    assert runner._compiled.get_property("INFERENCE_NUM_THREADS") == 2


def test_int8_is_asked_for_and_never_auto(monkeypatch):
    assert resolve_precision("int8").int8 and "OpenVINO" in resolve_precision("int8").reason
    assert resolve_precision("auto").name in ("fp32", "bf16")
    torch_side = resolve_precision("int8").on_torch()  # what torch computes when int8 is asked for
    assert torch_side.name == "fp32" and "OpenVINO" in torch_side.reason


@pytest.mark.slow
@pytest.mark.skipif(not installed("openvino"), reason="openvino is not installed")
def test_int8_graphs_are_calibrated_once_and_stay_near_float32(example_frame, tmp_path, monkeypatch):
    """The shipped weights quantized on 3 rendered calibration scenes: on the example frame, the detector's
    confident boxes within 8 px (of 640) and 0.1 in score of float32, the joints within a few cm from the reference
    boxes; a second load finds the cached int8 graphs and renders nothing; torch and ONNX Runtime, asked for int8,
    say that they compute float32. (3 scenes keep the test fast; with so few a confident box's score moves by up to
    0.07 and a weak box's by 0.2, which the default 36 do not: benchmarks/backend_accuracy.py measures the shipped
    calibration.)"""
    import posenet.runtime.quantize as quantize
    from pipeline.two_stage import ScenePipeline

    monkeypatch.setenv("ORPOSE_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("ORPOSE_INT8_SCENES", "3")
    detect, boxed = example_frame
    ref = ScenePipeline.from_checkpoints(precision="fp32", backend="openvino", threads=2)
    run = ScenePipeline.from_checkpoints(precision="int8", backend="openvino", threads=2)
    for net, runner in ((run.pose, run.pose.model.runner), (run.detector, run.detector.runner)):
        assert net.precision.int8 and net.backend.name == "openvino" and runner.path.suffix == ".xml"
    images, depths = [v.color for v in detect.views], [v.depth for v in detect.views]
    confident = 0
    ours, theirs = ref.detector.detect(images, depths, 0.05), run.detector.detect(images, depths, 0.05)
    for a, b in zip(ours, theirs, strict=True):
        for box, score in zip(a.boxes, a.scores, strict=True):
            if score >= 0.6:  # a confident person: int8 finds it where float32 does
                near = np.abs(b.boxes - box).max(axis=1)
                assert near.min() <= 8.0 and abs(b.scores[near.argmin()] - score) <= 0.1  # px of 640x480
                confident += 1
    assert confident >= 6
    a = ref.run(boxed.views, boxed.boxes, boxed.person_ids)
    b = run.run(boxed.views, boxed.boxes, boxed.person_ids)
    assert len(a.persons) == len(b.persons) > 0
    err = np.concatenate(
        [np.linalg.norm(q.joints - p.joints, axis=-1) for p, q in zip(a.persons, b.persons, strict=True)]
    )
    assert np.median(err) < 20 and err.max() < 100  # mm

    def no_render():  # a SystemExit too (as a CLI's error would be): whatever calibration raises, float32 runs
        raise SystemExit("the int8 graphs are cached: nothing should be rendered")

    monkeypatch.setattr(quantize, "calibration_samples", no_render)
    again = ScenePipeline.from_checkpoints(precision="int8", backend="openvino", threads=2)
    assert again.pose.precision.int8 and again.detector.precision.int8
    # Quantization that fails leaves the float32 graph running, and says why.
    monkeypatch.setenv("ORPOSE_INT8_SCENES", "4")  # another calibration: not cached
    fallback = ScenePipeline.from_checkpoints(precision="int8", backend="openvino", threads=2)
    assert fallback.pose.backend.name == "openvino" and fallback.pose.precision.name == "fp32"
    assert "int8 failed" in fallback.pose.precision.reason
    for backend in RUNTIMES + ["torch"]:
        if backend != "openvino":
            other = ScenePipeline.from_checkpoints(precision="int8", backend=backend, threads=2)
            assert other.pose.precision.name == other.detector.precision.name == "fp32"


@pytest.mark.skipif(not installed("openvino"), reason="openvino is not installed")
def test_the_detector_graph_compiled_per_batch_size_finds_what_the_dynamic_graph_finds(example_frame, cache):
    """The detector's OpenVINO graph is compiled with every shape fixed for its first ``MAX_STATIC_BATCHES`` batch
    sizes (``static_batch``; the frame's batch at load), other batch sizes run the dynamic-batch graph, compiled
    when first needed: the boxes and scores are the dynamic graph's at each number of views."""
    from detector.infer import PersonDetector
    from posenet.runtime.auto_int8 import FRAME_BATCH
    from posenet.runtime.graphs import MAX_STATIC_BATCHES, OnnxRunner

    assert MAX_STATIC_BATCHES == 2
    detect, _ = example_frame
    det = PersonDetector.from_checkpoint(None, precision="fp32", backend="openvino", threads=2)
    fixed = det.runner
    assert fixed.static_batch and set(fixed._static) == {FRAME_BATCH["detector"]} and fixed._compiled is None
    dynamic = OnnxRunner(fixed.path, "openvino", 2, fixed.precision)
    assert not dynamic.static_batch and dynamic._compiled.inputs[0].get_partial_shape().is_dynamic
    assert fixed.input_shapes == dynamic.input_shapes and fixed.input_shapes["pixel_values"][0] is None
    views = detect.views
    for n in (1, 3, 2):
        colors, depths = [v.color for v in views[:n]], [v.depth for v in views[:n]]
        det.runner = dynamic
        want = det.detect(colors, depths, score_threshold=0.25)
        det.runner = fixed
        got = det.detect(colors, depths, score_threshold=0.25)
        assert len(got) == n and sum(len(d.boxes) for d in want) > 0
        for a, b in zip(want, got, strict=True):
            np.testing.assert_allclose(b.boxes, a.boxes, atol=0.5)  # pixels
            np.testing.assert_allclose(b.scores, a.scores, atol=1e-3)
    assert set(fixed._static) == {3, 1} and all(g.inputs[0].get_partial_shape().is_static for g in fixed._static.values())
    assert fixed._compiled is not None and fixed._compiled.inputs[0].get_partial_shape().is_dynamic  # 2 views
