#!/bin/sh
# association on the tuning sequences: the working tree (TAG main) against the worktree /tmp/wt28 (TAG wt)
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  /work/main/.venv/bin/python -m detector.association --data data/$s --annotations data/$s/annotations.json --predictions runs/s28_det_$s.json \
     --score-threshold 0.495 --matcher skeletons --out runs/s28_assoc_main_$s.json > /dev/null 2>&1
  (cd /tmp/wt28 && PYTHONPATH=/tmp/wt28 /work/main/.venv/bin/python -m detector.association --data data/$s --annotations data/$s/annotations.json --predictions /work/main/runs/s28_det_$s.json \
     --score-threshold 0.495 --matcher skeletons --out /work/main/runs/s28_assoc_wt_$s.json > /dev/null 2>&1)
done
python3 - <<'PY'
import json, collections
for tag in ("main", "wt"):
    c = collections.Counter()
    for s in "seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9".split():
        r = json.load(open(f"runs/s28_assoc_{tag}_{s}.json"))
        r = r[0] if isinstance(r, list) else r
        for k in ("persons", "found", "missed", "split", "merged", "nobody"):
            c[k] += r[k]
    print(tag, dict(c), "found %.4f split %.4f merged %.4f" % (c["found"]/c["persons"], c["split"]/c["persons"], c["merged"]/c["persons"]))
PY
