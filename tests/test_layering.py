"""Imports flow one way (docs/INTERFACES.md): service -> pipeline -> detector, posenet; detector -> posenet."""

from __future__ import annotations

import ast

import pytest
from service_harness import REPO_ROOT

MAY_IMPORT = {
    "posenet": {"posenet"},
    "detector": {"detector", "posenet"},
    "pipeline": {"pipeline", "detector", "posenet"},
    "service": {"service", "pipeline", "detector", "posenet"},
}
# Modules allowed one import beyond their package's rule, each with its reason.
EXCEPTIONS = {
    # The training CLI that adapts the detector from unlabelled video needs the cross-view matcher for its
    # pseudo-labels (pipeline.pseudo_boxes); the detector that the pipeline runs never imports pipeline.
    "detector/adapt.py": {"pipeline"},
}


def imported(path) -> list[str]:
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
        elif isinstance(node, ast.Import):
            names += [a.name for a in node.names]
    return names


@pytest.mark.parametrize("package", list(MAY_IMPORT))
def test_no_import_goes_the_wrong_way(package):
    wrong = [
        f"{path.relative_to(REPO_ROOT)} imports {name}"
        for path in sorted((REPO_ROOT / package).rglob("*.py"))
        for name in imported(path)
        if name.split(".")[0] in MAY_IMPORT
        and name.split(".")[0]
        not in MAY_IMPORT[package] | EXCEPTIONS.get(str(path.relative_to(REPO_ROOT)), set())
    ]
    assert not wrong, "\n".join(wrong)
