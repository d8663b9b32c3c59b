"""Debug one frame in detector mode: boxes, scores, GT ids, groups, skeleton distances."""
import sys
from pathlib import Path
import numpy as np
from posenet.data.mvor import load_annotations
from posenet.predict import read_dataset
from posenet.scene import views_of
from posenet.boxes import iou_xyxy
from service.pipeline import ScenePipeline
from detector.skeleton_matching import _lifted, skeleton_distances, box_starts

data, frame = Path(sys.argv[1]), sys.argv[2]
gt = load_annotations(data / "annotations.json")
pipe = ScenePipeline.from_checkpoints(None, None, backend="auto", threads=2)
ds = read_dataset(data, gt, pipe.read_size, None)
i = next(k for k in range(len(ds)) if ds[k].id.endswith(frame) or frame in ds[k].id)
s = ds[i]
views = views_of(s)
print(s.id)
boxes, scores, cand = pipe._detect(views)
labels = []
for v, (b, sc, c) in enumerate(zip(boxes, scores, cand)):
    gb, gi = s.views[v].boxes, s.views[v].box_person_ids
    iou = iou_xyxy(b, np.asarray(gb).reshape(-1, 4)) if len(gb) else np.zeros((len(b), 0))
    for k in range(len(b)):
        j = int(iou[k].argmax()) if iou.shape[1] else -1
        lab = f"gt{gi[j]}@{iou[k, j]:.2f}" if j >= 0 else "-"
        labels.append(f"v{v}k{k}")
        print(f"view {v} box {k} score {sc[k]:.2f} unsure {bool(c[k])} {np.round(b[k]).astype(int)} best {lab}")
    print("  gt", list(zip(gi, np.round(np.asarray(gb)).astype(int).tolist())))
heat, ms, groups, centres = pipe._match_skeletons(boxes, views, cand, detected=True)
for g in groups:
    print("group", g.indices, g.extra)
j, ok = _lifted(heat.single_view())
d = skeleton_distances(j, ok)
np.set_printoptions(linewidth=250, precision=0, suppress=True)
print("      " + " ".join(f"{l:>6}" for l in labels))
for l, row in zip(labels, d):
    print(f"{l:>6} " + " ".join(f"{x:6.0f}" for x in row))
import detector.skeleton_matching as sm
from detector.skeleton_matching import match_skeletons, _in_full_lists, admit_candidates, drop_outliers, drop_unseen, SkeletonMatchConfig
cfg = pipe._skeleton_config()
sure = [~np.asarray(c, bool) for c in cand]
flat = np.concatenate(sure)
depths, cams = [v.depth for v in views], [v.camera for v in views]
g0 = match_skeletons([b[k] for b, k in zip(boxes, sure)], depths, cams, j[flat], ok[flat], cfg, None, centres[flat])
g0 = _in_full_lists(g0, sure)
print("grouped", [g.indices for g in g0])
g1 = admit_candidates(heat, g0, boxes, cand, j, ok, cfg.candidate_mm)
print("admitted", [g.indices for g in g1])
person, pok = _lifted(heat.estimate(sm.members_of(g0, boxes)))
st = box_starts(boxes)
for v in range(3):
    ks = np.flatnonzero(cand[v]); n = st[v] + ks
    c = sm.joint_median_distance(person[:, None], pok[:, None], j[n][None], ok[n][None])
    print("view", v, "cands", ks, "\n", np.round(c))
g2 = drop_outliers(heat, g1, boxes, j, ok, cfg.outlier_mm)
print("outliers", [g.indices for g in g2])
