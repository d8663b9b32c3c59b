# the shipped detector fine-tuned at a 224-px input (was 160): crowds and slivers (issues 13, 15)
source .venv/bin/activate
python -m detector.train --data data/mvor_twin --annotations data/mvor_twin/annotations.json --holdout-day 4 \
    --extra-data data/mvor_rand123gd data/mvor_rand123hd --init detector/weights/default.safetensors \
    --input-width 224 --lr 1e-4 --backbone-lr 5e-4 --epochs 4 --eval-every 2 --threads 2 --cache \
    --max-minutes 55 --no-progress --out runs/det_s27_w224
echo TRAIN_DONE
