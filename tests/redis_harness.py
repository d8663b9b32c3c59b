"""Real servers for the streams' scale-out: Debian's ``redis-server`` on a free localhost port (no persistence),
and nginx as the balancer in front of replicas (``docker/nginx.conf`` with the caller's ports and folders).

Tests that need them skip where a binary is missing (``apt-get install redis-server nginx``; ``.ci/run`` installs
them); benchmarks/scale_out.py uses them too.
"""

from __future__ import annotations

import os
import re
import shutil
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def redis_server(folder: Path) -> Iterator[str]:
    """Start ``redis-server`` in ``folder``; yields its URL, stops it on exit."""
    binary = shutil.which("redis-server")
    if binary is None:
        pytest.skip("redis-server is not installed (apt-get install redis-server)")
    port = free_port()
    args = [binary, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no",
            "--dir", str(folder)]  # fmt: skip
    process = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=0.2) as s:
                    s.sendall(b"PING\r\n")
                    if s.recv(16).startswith(b"+PONG"):
                        break
            except OSError:
                pass
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"redis-server did not start on port {port}")
            time.sleep(0.05)
        yield f"redis://127.0.0.1:{port}/0"
    finally:
        process.terminate()
        process.wait(10)


def nginx_conf(folder, port: int, replicas: list[str]) -> str:
    """docker/nginx.conf with this test's ports and folders."""
    text = (REPO_ROOT / "docker" / "nginx.conf").read_text()
    servers = "".join(f"        server {r} max_fails=1 fail_timeout=10s;\n" for r in replicas)
    text = re.sub(
        r"(upstream orpose \{\n)(?:.*\n)*?(?=        keepalive)", lambda m: m.group(1) + servers, text
    )
    text = text.replace("listen 8080;", f"listen 127.0.0.1:{port};").replace(
        "/tmp/orpose-nginx", str(folder / "n")
    )
    assert f"listen 127.0.0.1:{port};" in text and replicas[0] in text
    if os.geteuid() == 0:  # nginx's workers would run as nobody, who cannot write the test's folders
        text = "user root;\n" + text
    return text


@contextmanager
def balancer(folder: Path, replicas: list[str]) -> Iterator[str]:
    """nginx in front of ``replicas`` (host:port each), as docker/nginx.conf configures it; yields its URL."""
    if shutil.which("nginx") is None:
        pytest.skip("nginx is not installed (apt-get install nginx)")
    port = free_port()
    conf = folder / "nginx.conf"
    conf.write_text(nginx_conf(folder, port, replicas))
    nginx = subprocess.Popen(["nginx", "-c", str(conf), "-g", "daemon off;"], stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10
        while True:
            try:
                httpx.get(f"http://127.0.0.1:{port}/health", timeout=1)
                break
            except httpx.TransportError:
                if nginx.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"nginx did not start: {nginx.stderr.read().decode()}") from None
                time.sleep(0.1)
        yield f"http://127.0.0.1:{port}"
    finally:
        nginx.terminate()
        nginx.wait(10)
