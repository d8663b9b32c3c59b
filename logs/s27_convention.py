"""Simulate MVOR's annotation convention on rendered sequences: re-score served runs.
A person-frame keeps its 3D pose when one of its boxes has >= 5 of 10 keypoints in the image and >= 4 visible;
else it is ignored (hypotheses matched to it are dropped, MOTChallenge's distractor rule)."""
import json, sys
from collections import defaultdict
from pathlib import Path
import numpy as np
from scipy.optimize import linear_sum_assignment
sys.path.insert(0, "benchmarks")
from tracking import sequences, served_lines, served_tracks
from posenet.track_eval import score, GATE_MM
from posenet.track import mean_joint_distance

def passes(kp):
    f = kp[2::3]
    return sum(q > 0 for q in f) >= 5 and sum(q == 2 for q in f) >= 4

seq, run = sys.argv[1], sys.argv[2]
gt = json.load(open(f"data/{seq}/annotations.json"))
img2mv = {}
for mv in gt["multiview_images"]:
    for i in mv["id"].split("_"):
        img2mv[int(i)] = mv["id"]
ok = defaultdict(bool)
for a in gt["annotations"]:
    if a["person_id"] >= 0:
        ok[(img2mv[a["image_id"]], a["person_id"])] |= passes(a["keypoints"])
lines = served_lines(Path(f"runs/{seq}_{run}.jsonl"))
for mode in ("all", "mvor"):
    frames, hyps, ms = [], [], []
    for s, rows in sequences(gt).items():
        for fid, fr in rows:
            tracks, t = served_tracks(lines, fid)
            if mode == "mvor":
                keep = np.array([ok[(fid, int(i))] for i in fr.gt_ids], bool)
                ign = fr.gt_joints[~keep]
                fr.gt_ids, fr.gt_joints = fr.gt_ids[keep], fr.gt_joints[keep]
                if len(ign) and tracks:
                    ids = list(tracks)
                    allgt = np.concatenate([fr.gt_joints, ign])
                    d = mean_joint_distance(allgt, np.array([tracks[t].joints for t in ids]))
                    r, c = linear_sum_assignment(np.where(d <= GATE_MM, d, 1e9))
                    for g, h in zip(r, c):
                        if d[g, h] <= GATE_MM and g >= len(fr.gt_ids):
                            tracks.pop(ids[h])
            frames.append(fr); hyps.append(tracks); ms.append(t)
    m = score(frames, hyps, ms)
    print(seq, run, mode, {k: m[k] for k in ("gt_person_frames", "idf1", "mota", "id_switches", "switches_per_1000", "false_positives", "misses", "mpjpe_ratio", "accel_ratio", "bone_std_max_mm")})
