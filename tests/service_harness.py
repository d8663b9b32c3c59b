"""Test support for the service: tiny random-init checkpoints and a real uvicorn server on a free port.

The checkpoints are written with the packages' own save functions, so the server loads them exactly as it
loads trained weights. The server is a separate ``uvicorn service.app:app`` process configured by
``ORPOSE_*`` env vars, and tests talk to it over real HTTP on localhost.
"""

from __future__ import annotations

import dataclasses
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]


def tiny_checkpoints(folder: Path, seed: int = 0, detector: bool = True) -> tuple[Path, Path | None]:
    """A random-init pose network and (if ``detector``) a small random-init DETR, saved under ``folder``.

    Returns the (pose, detector or None) checkpoint paths."""
    from detector.checkpoint import save_checkpoint as save_detector
    from detector.model import build_detector, preset
    from posenet.checkpoint import save_checkpoint as save_pose
    from posenet.model import ModelConfig, PoseNet

    torch.manual_seed(seed)
    pose_cfg = ModelConfig()
    pose = save_pose(
        folder / "pose", PoseNet(pose_cfg), {"model": dataclasses.asdict(pose_cfg), "data": "random"}
    )
    if not detector:
        return pose, None
    # DETR on colour: with random weights its softmax scores straddle 0.5, so detector mode returns boxes (a
    # random Conditional DETR starts at the focal prior, 0.01, and would find nobody).
    det_cfg = preset(
        "cpu",
        arch="detr",
        input_mode="rgb",
        backbone_stage=3,
        d_model=32,
        encoder_layers=1,
        decoder_layers=1,
        ffn_dim=64,
        num_queries=8,
    )
    det = folder / "detector"
    save_detector(det, build_detector(det_cfg), det_cfg, train={"data": "random init (tests)"})
    return pose, det


def form_kwargs(scene: dict, files: list) -> dict:
    """httpx keyword arguments of a /scenes form: the ``scene`` JSON part and the file parts."""
    return {"data": {"scene": json.dumps(scene)}, "files": files}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``uvicorn service.app:app`` in a subprocess; ``with Server(env) as url: ...``."""

    def __init__(self, env: dict[str, str], startup_s: float = 120.0) -> None:
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.env = {**os.environ, "HF_HUB_OFFLINE": "1", "ORPOSE_THREADS": "1", **env}
        self.startup_s = startup_s
        self.proc: subprocess.Popen | None = None

    def __enter__(self) -> str:
        cmd = [
            sys.executable,
            "-m",
            "uvicorn",
            "service.app:app",
            "--host",
            "127.0.0.1",
            "--port",
            str(self.port),
        ]
        # The log goes to a file: a pipe that nobody reads fills up and then blocks the server's writes.
        self.log = tempfile.TemporaryFile("w+")
        self.proc = subprocess.Popen(
            cmd, cwd=REPO_ROOT, env=self.env, stdout=self.log, stderr=subprocess.STDOUT
        )
        deadline = time.monotonic() + self.startup_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                self.log.seek(0)
                raise RuntimeError(f"the server exited during startup:\n{self.log.read()}")
            try:
                if httpx.get(f"{self.url}/health", timeout=1.0).status_code == 200:
                    return self.url
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        self.__exit__()
        raise RuntimeError(f"the server did not answer /health within {self.startup_s} s")

    def __exit__(self, *exc) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.proc is not None:
            self.log.close()
