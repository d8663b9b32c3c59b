"""Frames where the dup rule changes step 5's admissions: the blocked unsure box, its best annotated box, the person's."""
import sys
from pathlib import Path
import numpy as np
from posenet.data.mvor import load_annotations
from posenet.predict import read_dataset
from posenet.scene import views_of
from posenet.boxes import iou_xyxy
from service.pipeline import ScenePipeline
from detector.skeleton_matching import (_lifted, match_skeletons, _in_full_lists, admit_candidates, free_unsure,
                                        box_starts, joint_median_distance)

data = Path(sys.argv[1])
gt = load_annotations(data / "annotations.json")
pipe = ScenePipeline.from_checkpoints(None, None, backend="auto", threads=2)
ds = read_dataset(data, gt, pipe.read_size, None)
cfg = pipe._skeleton_config()

def label(s, v, b):
    gb, gi = np.asarray(s.views[v].boxes).reshape(-1, 4), s.views[v].box_person_ids
    if not len(gb): return "-"
    iou = iou_xyxy(b[None], gb)[0]; j = int(iou.argmax())
    return f"{gi[j]}@{iou[j]:.2f}"

for i in range(len(ds)):
    s = ds[i]; views = views_of(s)
    boxes, scores, cand = pipe._detect(views)
    if not any(c.any() for c in cand): continue
    heat = pipe.pose.box_heatmaps(list(views), boxes); heat.reduce()
    j, ok = _lifted(heat.single_view())
    sure = [~c for c in cand]; flat = np.concatenate(sure)
    from detector.matching import box_centres_3d
    centres = box_centres_3d(boxes, [v.depth for v in views], [v.camera for v in views])[0]
    g0 = _in_full_lists(match_skeletons([b[k] for b, k in zip(boxes, sure)], [v.depth for v in views],
                        [v.camera for v in views], j[flat], ok[flat], cfg, None, centres[flat]), sure)
    if not g0: continue
    a = admit_candidates(heat, g0, boxes, cand, j, ok, cfg.candidate_mm)
    free = free_unsure(g0, boxes, cand, j, ok, cfg.same_view_mm)
    b_ = admit_candidates(heat, g0, boxes, free, j, ok, cfg.candidate_mm)
    st = box_starts(boxes)
    for p, (ga, gb) in enumerate(zip(a, b_)):
        for v in range(len(views)):
            if ga.indices[v] != gb.indices[v]:
                k = ga.indices[v]
                own = [label(s, u, boxes[u][ga.indices[u]]) for u in range(len(views)) if ga.indices[u] >= 0 and u != v]
                n = st[v] + k
                sures = st[v] + np.flatnonzero(sure[v])
                d = joint_median_distance(j[n][None], ok[n][None], j[sures], ok[sures])
                m = int(np.nanargmin(d))
                print(f"frame {s.id} view {v}: unsure box {k} ({label(s, v, boxes[v][k])}) blocked from person of {own}; "
                      f"near sure box {np.flatnonzero(sure[v])[m]} ({label(s, v, boxes[v][np.flatnonzero(sure[v])[m]])}) at {d[m]:.0f} mm; now {gb.indices[v]}")
