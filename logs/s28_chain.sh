#!/bin/sh
# association on day 4 (both looks), then the tracking tuning sequences through the new pipeline, then served
. .venv/bin/activate
for d in mvor_twin mvor_alt; do
  [ -f runs/s28_det4_$d.json ] || python -m detector.predict --data data/$d --annotations data/$d/annotations.json --days 4 --score-threshold 0.2 --out runs/s28_det4_$d.json
  python -m detector.association --data data/$d --annotations data/$d/annotations.json --days 4 --predictions runs/s28_det4_$d.json \
     --score-threshold 0.495 --matcher skeletons --centre-gate-mm 1500 2500 --out runs/s28_assoc4_$d.json > runs/s28_assoc4_$d.txt 2>&1
  echo "$(date +%T) assoc $d"
done
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  python benchmarks/tracking.py --data data/$s --detections runs/det28_$s.jsonl --redetect > runs/det28_$s.txt 2>&1
  echo "$(date +%T) $s"
done
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=28 python logs/s25_sweep.py default
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=26 python logs/s25_sweep.py default
bash logs/s25_served.sh s28
echo CHAIN_DONE
