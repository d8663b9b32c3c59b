"""benchmarks/look_transfer.py end to end on two tiny datasets standing in for two looks: one posenet.training.train run per
modality on the first, its held-out day validated (in-look) and the second's same day watched (cross-look)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import write_tiny_mvor

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_look_transfer_reports_in_and_cross_look_per_modality(tmp_path):
    one = write_tiny_mvor(tmp_path / "look_a", seed=0)
    other = write_tiny_mvor(tmp_path / "look_b", seed=1)
    out = tmp_path / "lt"
    tiny = "--crop-size 32 --base 8"
    cmd = [sys.executable, "benchmarks/look_transfer.py", "--data", str(one.root), "--cross", str(other.root),
           "--holdout-day", "2", "--modalities", "depth", "rgbd", "--minutes", "0.02", "--every", "0.01",
           "--threads", "1", "--no-detector", "--train-args", tiny, "--out", str(out)]  # fmt: skip
    done = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((out / "look_transfer.json").read_text())
    assert [r["model"] for r in result["rows"]] == ["pose network, depth", "pose network, rgbd"]
    for row, modality in zip(result["rows"], ("depth", "rgbd"), strict=True):
        log = [json.loads(line) for line in (out / modality / "log.jsonl").read_text().splitlines()]
        last = [r for r in log if "val_mpjpe_cm" in r][-1]
        assert row["in_look"] == last["val_mpjpe_cm"] and row["cross_look"] == last["watch_look_b_cm"]
        assert abs(row["ratio"] - row["cross_look"] / row["in_look"]) < 1e-12
        config = json.loads((out / modality / "config.json").read_text())
        assert config["model"]["inputs"]["modality"] == modality and config["model"]["base"] == 8
    assert "pose network, depth" in done.stdout and result["machine"] in done.stdout
