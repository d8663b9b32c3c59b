#!/bin/sh
# Sweep the skeleton matcher's centre gate on the eight tuning sequences (never the day-4 test).
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  [ -f runs/s28_det_$s.json ] || .venv/bin/python -m detector.predict --data data/$s --annotations data/$s/annotations.json --score-threshold 0.2 --out runs/s28_det_$s.json
  .venv/bin/python -m detector.association --data data/$s --annotations data/$s/annotations.json --predictions runs/s28_det_$s.json \
     --score-threshold 0.495 --matcher skeletons --centre-gate-mm 1500 2000 2500 1000000 --out runs/s28_gate_$s.json
done
