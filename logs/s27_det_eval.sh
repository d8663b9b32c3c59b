# evaluate the 224-px detector against the shipped one (issues 13, 15)
source .venv/bin/activate
set -e
R=runs/det_s27_w224
python -m detector.export $R --out $R/export.safetensors --data data/mvor_twin --annotations data/mvor_twin/annotations.json --threshold-days 1 2 3 --precision int8 2>&1 | tail -5
python logs/s27_ap.py runs/s27_ap.json shipped $R/export.safetensors
for look in twin alt; do
  python benchmarks/detector_mode.py --data data/mvor_$look --days 4 --variants +unsure+outliers+unseen --detector-checkpoint $R/export.safetensors --json runs/s27_dm_${look}_w224.json 2>&1 | grep -v "^{" | tail -12
done
echo DET_EVAL_DONE
