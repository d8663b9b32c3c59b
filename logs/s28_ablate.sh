#!/bin/sh
# tuning sequences through the pipeline at HEAD (dup rule, gate 1500) from a worktree -> runs/det28g_*
cd /tmp/wt28
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  PYTHONPATH=/tmp/wt28 /work/main/.venv/bin/python benchmarks/tracking.py --data data/$s --detections /work/main/runs/det28g_$s.jsonl --redetect > /work/main/runs/det28g_$s.txt 2>&1
  echo "$(date +%T) $s"
done
cd /work/main
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=28g .venv/bin/python logs/s25_sweep.py default
