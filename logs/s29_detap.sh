# detector AP on tuning sequences: crowded (5 persons) vs 4 persons
source .venv/bin/activate
for s in seq_t10 seq_t11 seq_t12 seq_t7 seq_t8; do
  python -m detector.predict --data data/$s --annotations data/$s/annotations.json --score-threshold 0.05 --out runs/s29_boxes_$s.json > /dev/null 2>&1
  echo "== $s"; python -m detector.evaluate --help >/dev/null 2>&1 && python -m detector.evaluate --annotations data/$s/annotations.json --predictions runs/s29_boxes_$s.json 2>&1 | tail -4
done
echo DETAP_DONE
