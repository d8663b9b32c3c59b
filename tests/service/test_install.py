"""The package as a hospital installs it: the built wheel, outside the repository, with no ``../shared`` beside it.

The wheel is built from the source tree, installed (without its dependencies, which this environment has) into
an empty folder, and served from another empty folder with ``ORPOSE_PRECISION=int8``: the int8 calibration must
render its scenes from the package alone, and the server must answer the example frame with the shipped weights.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import httpx
import pytest
from service_harness import REPO_ROOT, Server

from posenet.runtime.graphs import installed

FRAME = REPO_ROOT / "examples" / "frame"


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The project's wheel, built from a copy of its sources (the checkout is left as it was)."""
    src = tmp_path_factory.mktemp("src")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO_ROOT / name, src / name)
    for package in ("posenet", "detector", "pipeline", "service"):
        shutil.copytree(REPO_ROOT / package, src / package, ignore=shutil.ignore_patterns("__pycache__"))
    out = tmp_path_factory.mktemp("dist")
    cmd = [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(out), str(src)]
    subprocess.run(cmd, check=True, capture_output=True, cwd=src)
    (whl,) = out.glob("or_pose-*.whl")
    return whl


@pytest.fixture(scope="module")
def site(wheel, tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("site")
    cmd = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target), str(wheel)]
    subprocess.run(cmd, check=True, capture_output=True)
    return target


def test_the_wheel_carries_the_shipped_weights(site):
    assert (site / "posenet" / "weights" / "default.safetensors").is_file()
    assert list((site / "detector" / "weights").glob("*.safetensors"))


@pytest.mark.slow
@pytest.mark.skipif(not installed("openvino"), reason="int8 runs on OpenVINO, which is not installed")
def test_the_installed_wheel_starts_int8_without_shared_and_answers_the_example_frame(site, tmp_path):
    run_dir = tmp_path / "elsewhere"  # no repository, no ../shared around it
    run_dir.mkdir()
    env = {
        "PYTHONPATH": str(site),  # before the editable checkout on sys.path
        "MVOR_ANNOTATIONS": "",
        "ORPOSE_PRECISION": "int8",
        "ORPOSE_BACKEND": "openvino",
        "ORPOSE_INT8_SCENES": "1",
        "ORPOSE_CACHE_DIR": str(tmp_path / "cache"),
        "ORPOSE_THREADS": "2",
    }
    where = subprocess.run(
        [sys.executable, "-c", "import pipeline, posenet, service; print(pipeline.__file__); print(posenet.__file__); print(service.__file__)"],
        env={**os.environ, **env}, cwd=run_dir, capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    assert all(Path(p).is_relative_to(site) for p in where), where
    with Server(env, startup_s=300, cwd=run_dir) as url:
        info = httpx.get(f"{url}/model", timeout=30).json()
        frame = {f"{k}_{i}": (f"{k}_{i}.{ext}", (FRAME / f"{k}_{i}.{ext}").read_bytes())
                 for i in range(3) for k, ext in (("color", "jpg"), ("depth", "png"))}  # fmt: skip
        r = httpx.post(f"{url}/scenes", data={"scene": (FRAME / "scene.json").read_text()}, files=frame, timeout=120)
    assert r.status_code == 200, r.text
    assert r.json()["persons"], r.text
    runtime = {n["network"]: n for n in info["runtime"]}
    assert {n["precision"] for n in runtime.values()} == {"int8"}, runtime  # calibrated, not fallen back
    assert list((tmp_path / "cache").glob("int8-calibration-*/annotations.json"))
