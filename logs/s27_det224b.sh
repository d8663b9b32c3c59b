# second stage: the 224-px detector fine-tuned 2 more epochs with the sequence sets the shipped detector saw
source .venv/bin/activate
set -e
[ -f data/seqtrain_mvor/.done ] || { python -m posenet.data.synth --out data/seqtrain_mvor --sequence --days 4 --frames 50 --fps 2 --persons 4 --rig mvor --look random --seed 10 --workers 2 --quiet > /dev/null; touch data/seqtrain_mvor/.done; }
[ -f data/seqtrain_rand/.done ] || { python -m posenet.data.synth --out data/seqtrain_rand --sequence --days 4 --frames 30 --fps 2 --persons 4 --rig random --look random --seed 11 --workers 2 --quiet > /dev/null; touch data/seqtrain_rand/.done; }
echo "$(date +%T) rendered"
python -m detector.train --data data/mvor_twin --annotations data/mvor_twin/annotations.json --holdout-day 4 \
    --extra-data data/mvor_rand123gd data/mvor_rand123hd data/seqtrain_mvor data/seqtrain_rand \
    --init runs/det_s27_w224 --lr 1e-4 --backbone-lr 5e-4 --epochs 2 --eval-every 2 --threads 2 --cache \
    --max-minutes 30 --no-progress --out runs/det_s27_w224b
R=runs/det_s27_w224b
python -m detector.export $R --out $R/export.safetensors --data data/mvor_twin --annotations data/mvor_twin/annotations.json --threshold-days 1 2 3 --precision int8 2>&1 | tail -1
python logs/s27_ap.py runs/s27_ap_b.json $R/export.safetensors
for look in twin alt; do
  python benchmarks/detector_mode.py --data data/mvor_$look --days 4 --variants +unsure+outliers+unseen --detector-checkpoint $R/export.safetensors --json runs/s27_dm_${look}_w224b.json 2>&1 | grep -v "frames:" | tail -4
done
echo DET_B_DONE
