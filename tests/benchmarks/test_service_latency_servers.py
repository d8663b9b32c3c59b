"""benchmarks/service_latency.py --servers: running servers compared with their requests interleaved, on a real
uvicorn process with tiny random-init models that read 320x240 and the tiny 640x480 MVOR-format dataset."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from conftest import write_tiny_mvor
from service_harness import Server, tiny_checkpoints

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from service_latency import STAGES, format_interleaved, interleaved, main, plot_interleaved  # noqa: E402

from posenet.data.mvor import MvorDataset  # noqa: E402


@pytest.mark.slow
def test_servers_are_compared_request_by_request_on_both_transports(tmp_path):
    data = write_tiny_mvor(tmp_path / "tiny", days=(1,), frames_per_day=1)
    pose, det = tiny_checkpoints(tmp_path / "ckpt", read_size=(320, 240))
    env = {"ORPOSE_POSE_CHECKPOINT": str(pose), "ORPOSE_DETECTOR_CHECKPOINT": str(det)}
    ds = MvorDataset(None, data.annotations)
    with Server(env) as url:
        result = interleaved({"a": url, "b": url}, ds, data.root, 0, requests=3)
    assert result["frame"] == ds[0].id and set(result["machines"]) == {"a", "b"}
    assert list(result["transports"]) == ["recorded", "read"]
    for servers in result["transports"].values():
        assert list(servers) == ["a", "b"]
        for r in servers.values():
            lat = r["latency_ms"]
            assert r["requests"] == 3 and 0 < lat["p25"] <= lat["p50"] <= lat["p75"]
            assert set(r["stages_ms_p50"]) == set(STAGES) and r["stages_ms_p50"]["total"] > 0
    table = format_interleaved(result)
    assert len(table.splitlines()) == 2 + 4 and "read" in table and "recorded" in table
    plot_interleaved(result, tmp_path / "stages.png")
    assert (tmp_path / "stages.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_servers_need_the_frame_to_send():
    with pytest.raises(SystemExit, match="--servers needs --data"):
        main(["--servers", "a=http://127.0.0.1:9"])
