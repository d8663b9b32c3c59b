#!/bin/sh
# after the alt detector-mode run: association on day 4 (both looks, gate 1500 and 2500), then served tracking
. .venv/bin/activate
while [ ! -f runs/s28_dm_alt_f.json ]; do sleep 5; done
for d in mvor_twin mvor_alt; do
  python -m detector.association --data data/$d --annotations data/$d/annotations.json --days 4 --predictions runs/s28_det4_$d.json \
     --score-threshold 0.495 --matcher skeletons --centre-gate-mm 1500 2500 --out runs/s28_assoc4b_$d.json > runs/s28_assoc4b_$d.txt 2>&1
done
bash logs/s25_served.sh s28b
echo CHAIN2_DONE
