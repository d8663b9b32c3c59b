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
import threading
import time
from pathlib import Path

import httpx
import torch

REPO_ROOT = Path(__file__).resolve().parents[1]


def tiny_checkpoints(
    folder: Path,
    seed: int = 0,
    detector: bool = True,
    depth_only: bool = False,
    read_size: tuple[int, int] | None = None,
) -> tuple[Path, Path | None]:
    """A random-init pose network and (if ``detector``) a small random-init DETR, saved under ``folder``; with
    ``depth_only`` both read depth alone (the colourless path: no colour image is needed); ``read_size`` (W, H):
    the pose network crops from views read at that size (``InputConfig.source_size``; None: views as given).

    Returns the (pose, detector or None) checkpoint paths."""
    from detector.checkpoint import save_checkpoint as save_detector
    from detector.model import build_detector, preset
    from posenet.net.checkpoint import save_checkpoint as save_pose
    from posenet.net.inputs import InputConfig
    from posenet.net.model import ModelConfig, PoseNet

    torch.manual_seed(seed)
    inputs = InputConfig(modality="depth" if depth_only else "rgbd", source_size=read_size)
    pose_cfg = ModelConfig(inputs=inputs)
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
        input_mode="depth" if depth_only else "rgb",
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


def reference_box_env(folder: Path) -> dict[str, str]:
    """``ORPOSE_*`` settings of a server with a tiny pose network (written under ``folder``) and no detector."""
    pose, _ = tiny_checkpoints(folder, detector=False)
    return {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_LOAD_DETECTOR": "false"}


def form_kwargs(scene: dict, files: list) -> dict:
    """httpx keyword arguments of a /scenes form: the ``scene`` JSON part and the file parts."""
    return {"data": {"scene": json.dumps(scene)}, "files": files}


def raw_request(client: httpx.Client, **kwargs) -> bytes:
    """A whole ``POST /scenes`` request (head and body) as bytes, to send over a socket of one's own."""
    request = client.build_request("POST", "/scenes", **kwargs)
    body = request.read()
    head = "".join(f"{k}: {v}\r\n" for k, v in request.headers.items())
    return f"POST /scenes HTTP/1.1\r\n{head}\r\n".encode() + body


class Tricklers:
    """``n`` connections that each send a /scenes head and then one body byte every ``every_s`` seconds (slow
    uploads); ``close()`` ends them."""

    def __init__(self, url: httpx.URL, n: int, token: str | None = None, every_s: float = 0.1) -> None:
        auth = f"Authorization: Bearer {token}\r\n" if token else ""
        self.socks = []
        for _ in range(n):
            sock = socket.create_connection((url.host, url.port))
            sock.sendall(
                f"POST /scenes HTTP/1.1\r\nHost: {url.host}\r\n{auth}Content-Type: multipart/form-data; "
                "boundary=x\r\nContent-Length: 100000\r\n\r\n--x\r\n".encode()
            )
            self.socks.append(sock)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._trickle, args=(every_s,), daemon=True)
        self.thread.start()
        time.sleep(0.3)  # every head has been read and its route is waiting for the body

    def _trickle(self, every_s: float) -> None:
        while not self.stop.wait(every_s):
            for sock in self.socks:
                try:
                    sock.sendall(b"x")
                except OSError:
                    pass

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for sock in self.socks:
            sock.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Server:
    """``uvicorn service.app:app`` in a subprocess; ``with Server(env) as url: ...``."""

    def __init__(self, env: dict[str, str], startup_s: float = 120.0, cwd: Path = REPO_ROOT) -> None:
        self.port = free_port()
        self.cwd = cwd
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
            cmd, cwd=self.cwd, env=self.env, stdout=self.log, stderr=subprocess.STDOUT
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
