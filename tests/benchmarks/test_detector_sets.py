"""benchmarks/detector_sets.py on a tiny MVOR-format dataset: every detector scored on every set, its AP the one that
detector.predict + detector.evaluate give for the same views, the differences to the first detector, and clear errors
for a malformed --detectors or a missing set."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
import torch
from conftest import write_tiny_mvor

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from detector_sets import main  # noqa: E402

from detector.checkpoint import save_checkpoint  # noqa: E402
from detector.data import load_records  # noqa: E402
from detector.evaluate import evaluate_file  # noqa: E402
from detector.infer import PersonDetector  # noqa: E402
from detector.model import build_detector, preset  # noqa: E402
from detector.predict import predict_records  # noqa: E402


def tiny_checkpoint(path: Path, seed: int, box: list[float] | None = None) -> Path:
    """A tiny random DETR; with ``box`` (cx, cy, w, h as fractions of the image) its output heads are set so that
    every query says "person" at that box, whatever the image: a detector with a known, nonzero AP."""
    cfg = preset("cpu", arch="detr", input_mode="rgbd", backbone_stage=3, input_width=64, d_model=32,
                 ffn_dim=64, num_queries=6, score_threshold=0.0)  # fmt: skip
    torch.manual_seed(seed)
    model = build_detector(cfg)
    if box is not None:
        with torch.no_grad():
            last = model.bbox_predictor.layers[-1]
            last.weight.zero_()
            last.bias.copy_(torch.logit(torch.tensor(box)))
            model.class_labels_classifier.weight.zero_()
            model.class_labels_classifier.bias.copy_(torch.tensor([4.0, -4.0]))  # person, no object
    save_checkpoint(path, model, cfg, train={"data": "random init (tests)"})
    return path


def test_detectors_side_by_side_per_set(tmp_path, capsys):
    data = write_tiny_mvor(tmp_path / "tiny").root
    first = load_records(data / "annotations.json", [2])[0]
    (x0, y0, x1, y1), w, h = first.boxes[0], first.width, first.height
    box = [(x0 + x1) / 2 / w, (y0 + y1) / 2 / h, (x1 - x0) / w, (y1 - y0) / h]
    a, b = tiny_checkpoint(tmp_path / "a", 0), tiny_checkpoint(tmp_path / "b", 1, box)
    out = tmp_path / "sets.json"
    result = main(["--detectors", f"a={a}", f"b={b}", f"again={a}", "--sets", f"{data}:2", str(data),
                   "--threads", "1", "--json", str(out), "--no-progress"])  # fmt: skip
    assert json.loads(out.read_text()) == json.loads(json.dumps(result))
    assert list(result["sets"]) == ["tiny:2", "tiny"]
    day2, every = result["sets"]["tiny:2"], result["sets"]["tiny"]
    assert day2["a"]["views"] == len(load_records(data / "annotations.json", [2])) < every["a"]["views"]
    assert day2["again"] == day2["a"]  # the same weights under another name score the same
    # the AP of the offline tools on the same views
    records = load_records(data / "annotations.json", [2])
    results = predict_records(
        PersonDetector.from_checkpoint(b, precision="fp32"), records, data, progress=False
    )
    expected = evaluate_file(data / "annotations.json", results, [2])
    assert day2["b"]["AP50"] == pytest.approx(expected["AP50"])
    assert day2["b"]["AP"] == pytest.approx(expected["AP"])
    assert day2["b"]["AP50"] > day2["a"]["AP50"]  # b finds day 2's first person, a (random) nobody
    printed = capsys.readouterr().out
    assert result["machine"] in printed and "tiny:2" in printed and "again AP50 / AP" in printed
    assert f"{day2['b']['AP50'] - day2['a']['AP50']:+.3f}" in printed.splitlines()[2]


def test_bad_arguments_are_named(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--detectors", "runs/det", "--sets", str(tmp_path)])
    assert e.value.code == 2 and "give NAME=PATH" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--sets", str(tmp_path / "nowhere")])
    assert e.value.code == 2 and "annotations.json does not exist" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["--detectors", "x=a", "x=b", "--sets", str(tmp_path)])
    assert e.value.code == 2 and "its own name" in capsys.readouterr().err


def test_sets_in_folders_of_the_same_name_stay_apart(tmp_path):
    from detector_sets import score_sets

    one, other = (
        write_tiny_mvor(tmp_path / "a" / "tiny").root,
        write_tiny_mvor(tmp_path / "b" / "tiny", seed=1).root,
    )
    detector = {"a": PersonDetector.from_checkpoint(tiny_checkpoint(tmp_path / "ck", 0), precision="fp32")}
    scores = score_sets(detector, [(one, [2]), (other, [2])], progress=False)
    assert list(scores) == [f"{one}:2", f"{other}:2"]
