# AP of the shipped and the crowd-tuned detector, same run; then the tuning sequences through the pipeline with the new one
source .venv/bin/activate
for w in shipped crowd; do
  ck=""; [ $w = crowd ] && ck="--checkpoint runs/det_s29_crowd/export.safetensors"
  for d in mvor_twin mvor_alt; do
    python -m detector.predict --data data/$d --annotations data/$d/annotations.json --days 4 --score-threshold 0.05 $ck --out runs/s29_ap_${w}_$d.json > /dev/null 2>&1
    echo "$w $d $(python -m detector.evaluate --annotations data/$d/annotations.json --predictions runs/s29_ap_${w}_$d.json --days 4 | python -c 'import json,sys; d=json.load(sys.stdin); print(round(d["AP"],3), round(d["AP50"],3), round(d["AP75"],3), "F1", round(d.get("F1_50",0),3))')"
  done
  for s in seq_t10 seq_t11 seq_t12 seq_t7 seq_t8; do
    [ $w = shipped ] && [ -f runs/s29_boxes_$s.json ] && cp runs/s29_boxes_$s.json runs/s29_ap_${w}_$s.json
    [ -f runs/s29_ap_${w}_$s.json ] || python -m detector.predict --data data/$s --annotations data/$s/annotations.json --score-threshold 0.05 $ck --out runs/s29_ap_${w}_$s.json > /dev/null 2>&1
    echo "$w $s $(python -m detector.evaluate --annotations data/$s/annotations.json --predictions runs/s29_ap_${w}_$s.json | python -c 'import json,sys; d=json.load(sys.stdin); print(round(d["AP"],3), round(d["AP50"],3), round(d["AP75"],3), "F1", round(d.get("F1_50",0),3))')"
  done
done
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9 seq_t10 seq_t11 seq_t12; do
  python benchmarks/tracking.py --data data/$s --detections runs/det29c_$s.jsonl --redetect \
      --detector-checkpoint runs/det_s29_crowd/export.safetensors > runs/det29c_$s.txt 2>&1
done
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9 seq_t10 seq_t11 seq_t12" W=29c python logs/s25_sweep.py default
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9 seq_t10 seq_t11 seq_t12" W=28n python logs/s25_sweep.py default
echo EVAL_DONE
