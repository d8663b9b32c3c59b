"""benchmarks/tracker_sweep.py on a sequence rendered by posenet.synth --sequence (12 frames, 2 persons, 2 views).

The cached persons are the sequence's own poses with a few mm of noise, so the default tracker follows both
people without a switch; a gate of 1 mm lets no track take its person again, so no track is ever confirmed.
The figures pooled over two copies of the sequence are those of one, and the spawned workers give the rows the
in-process run gives.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from pipeline.track import Tracker
from pipeline.track_eval import evaluate
from posenet.data.mvor import load_annotations
from posenet.synth.__main__ import main as synth

sys.path.insert(0, str(Path(__file__).parents[2] / "benchmarks"))
from tracker_sweep import main  # noqa: E402
from tracking import sequences, tracker_config  # noqa: E402

FRAMES = 12


@pytest.fixture(scope="module")
def sequence(tmp_path_factory) -> tuple[Path, Path]:
    """A rendered sequence and its persons cached as ``benchmarks/tracking.py`` writes them."""
    root = tmp_path_factory.mktemp("seq")
    synth(["--out", str(root), "--sequence", "--frames", str(FRAMES), "--persons", "2", "--views", "2",
           "--fps", "10", "--seed", "3", "--quiet"])  # fmt: skip
    gt = load_annotations(root / "annotations.json")
    rng = np.random.default_rng(0)
    lines = []
    for _, rows in sequences(gt).items():
        for frame_id, frame in rows:
            persons = [
                {
                    "joints": (j + rng.normal(0, 5, j.shape)).tolist(),
                    "spread_mm": [40.0] * len(j),
                    "unsure": False,
                }
                for j in frame.gt_joints
            ]
            lines.append(json.dumps({"id": frame_id, "seconds": 0.01, "persons": persons}))
    det = root / "persons.jsonl"
    det.write_text("\n".join(lines) + "\n")
    return root, det


def test_the_rows_are_the_tracker_on_each_configuration(sequence, tmp_path):
    root, det = sequence
    out = tmp_path / "sweep.json"
    report = main(["--seq", f"{root}:{det}", "--try", "gate_mm=1", "--no-background", "--workers", "1",
                   "--json", str(out)])  # fmt: skip
    base, tight = report["rows"]
    assert base["overrides"] == [] and tight["overrides"] == ["gate_mm=1"]
    gt = load_annotations(root / "annotations.json")
    with open(det) as f:
        detections = {r["id"]: r for r in map(json.loads, f)}
    (rows,) = sequences(gt, detections).values()
    direct = evaluate([f for _, f in rows], Tracker(tracker_config([])))
    assert base["idf1"] == round(direct["idf1"], 4) and base["id_switches"] == direct["id_switches"] == 0
    assert base["idf1"] > 0.9 and base["person_frames"] == direct["gt_person_frames"]
    # no track takes its person again, so none is ever confirmed (TrackerConfig.birth_hits)
    assert tight["misses"] == tight["person_frames"] and tight["idf1"] == 0.0 < base["idf1"]
    assert json.loads(out.read_text())["rows"][1]["idf1"] == tight["idf1"]


def test_pooled_over_copies_and_across_workers_the_figures_hold(sequence, tmp_path):
    root, det = sequence
    copy = tmp_path / "copy"
    shutil.copytree(root, copy)
    args = ["--try", "gate_mm=1", "--try", "max_spread_mm=30", "--no-background"]
    one = main(["--seq", f"{root}:{det}", *args, "--workers", "1"])["rows"]
    two = main(["--seq", f"{root}:{det}", "--seq", f"{copy}:{det}", *args, "--workers", "2"])["rows"]
    for a, b in zip(one, two, strict=True):
        assert b["person_frames"] == 2 * a["person_frames"] and b["id_switches"] == 2 * a["id_switches"]
        assert (b["idf1"], b["idf1_min"], b["mota"]) == (a["idf1"], a["idf1"], a["mota"])
    assert two[2]["misses"] == two[2]["person_frames"]  # a 30 mm spread gate tracks nobody


def test_a_missing_cache_or_field_is_named(sequence, capsys):
    root, det = sequence
    with pytest.raises(SystemExit):
        main(["--seq", f"{root}:{root / 'absent.jsonl'}"])
    assert "benchmarks/tracking.py" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--seq", f"{root}:{det}", "--try", "no_such_field=1"])
    assert "no_such_field" in capsys.readouterr().err
