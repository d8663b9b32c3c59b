#!/bin/sh
# usage: sh logs/s28_tune.sh W : the eight tuning sequences through the working tree's pipeline -> runs/detW_*, then the tracker's IDF1
. .venv/bin/activate
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  python benchmarks/tracking.py --data data/$s --detections runs/det$1_$s.jsonl --redetect > runs/det$1_$s.txt 2>&1
done
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=$1 python logs/s25_sweep.py default
