# the shipped detector fine-tuned with crowded sequences (6 persons), same width; exported with the shipped threshold and NMS
source .venv/bin/activate
python -m detector.train --data data/mvor_twin --annotations data/mvor_twin/annotations.json --holdout-day 4 \
    --extra-data data/mvor_rand123g data/seqtrain_mvor data/seqtrain_rand data/seqcrowd_mvor data/seqcrowd_rand \
    --init detector/weights/default.safetensors --lr 1e-4 --backbone-lr 5e-4 --epochs 4 --eval-every 0 \
    --threads 2 --max-minutes 40 --out runs/det_s29_crowd --no-progress
echo "$(date +%T) trained"
python -m detector.export runs/det_s29_crowd --out runs/det_s29_crowd/export.safetensors --threshold 0.49533 --nms-iou 0.8 --precision int8 \
    --trained-on "session 29 trial: the shipped detector + 4 epochs with crowded sequences"
echo "$(date +%T) exported"
echo TRAIN_DONE
