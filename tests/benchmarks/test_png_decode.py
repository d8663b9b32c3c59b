"""benchmarks/png_decode.py on a two-camera frame written as the renderer lays a dataset out: the service's
decoder and each other one installed give rows (their pixels checked equal to the service's), a decoder that
disagrees stops the run, and a missing frame is named."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
import png_decode  # noqa: E402
from png_decode import main  # noqa: E402


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("png")
    rng = np.random.default_rng(0)
    for cam in (1, 2):
        for kind, image in (("color", rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)),
                            ("depth", rng.integers(0, 8000, (48, 64), dtype=np.uint16))):  # fmt: skip
            folder = root / "day4" / f"cam{cam}" / kind
            folder.mkdir(parents=True)
            for i in range(2):
                cv2.imwrite(str(folder / f"{i:06d}.png"), image)
    return root


def test_both_decoders_are_timed_on_the_same_pixels(dataset, tmp_path, capsys):
    out = tmp_path / "png.json"
    rows = main(
        ["--data", str(dataset), "--index", "1", "--repeats", "2", "--rounds", "2", "--json", str(out)]
    )
    assert [r["decoder"] for r in rows] == list(png_decode.decoders())
    assert rows[0]["decoder"] == "service" and "pillow" in png_decode.decoders()  # torchvision needs Pillow
    for row in rows:
        assert all(
            row[k] > 0
            for k in ("color_ms_r1", "color_ms_r2", "depth_ms_r1", "depth_ms_r2", "frame_ms_2threads")
        )
    assert json.loads(out.read_text())["rows"] == rows
    printed = capsys.readouterr().out
    assert "bit for bit" in printed and "machine:" in printed


def test_a_missing_frame_is_named(dataset, capsys):
    with pytest.raises(SystemExit, match="--index 5"):
        main(["--data", str(dataset), "--index", "5"])
    with pytest.raises(SystemExit, match="day3"):
        main(["--data", str(dataset), "--day", "3"])


def test_a_decoder_that_disagrees_stops_the_run(dataset, monkeypatch):
    found = png_decode.decoders()
    color, depth = found["service"]
    found["off by one"] = (lambda d, r: color(d, r) + 1, depth)
    monkeypatch.setattr(png_decode, "decoders", lambda: found)
    with pytest.raises(AssertionError, match="off by one"):
        main(["--data", str(dataset), "--index", "0", "--repeats", "1", "--rounds", "1"])
