#!/bin/sh
# usage: sh logs/s28_tune_wt.sh W : the tuning sequences through the worktree /tmp/wt28's pipeline -> runs/detW_*, then IDF1
cd /tmp/wt28
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  PYTHONPATH=/tmp/wt28 /work/main/.venv/bin/python benchmarks/tracking.py --data data/$s --detections /work/main/runs/det$1_$s.jsonl --redetect > /work/main/runs/det$1_$s.txt 2>&1
done
cd /work/main
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=$1 .venv/bin/python logs/s25_sweep.py default
