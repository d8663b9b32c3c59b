#!/bin/sh
# The shipped pose weights fine-tuned at a 128-px person crop (the cpu preset reads 96), session 25's recipe
# and data; then day 4 with reference boxes on the twin, alt (unseen) and the random look.
. .venv/bin/activate
echo "$(date +%T) train start"
python -m posenet.train --data data/mvor_twin --holdout-day 4 \
  --extra-data data/mvor_rand123gd data/synth_mvorrig_randgd data/synth_randrig_randgd \
               data/mvor_rand123hd data/synth_mvorrig_randhd data/synth_randrig_randhd \
  --watch data/mvor_alt:4 data/mvor_rand4g:4 --out runs/s28_crop128 \
  --init posenet/weights/default.safetensors --crop-size 128 --box-noise 0.5 --lr 2e-4 --warmup 0.05 --decay-start 0.5 \
  --view-loss 1.0 --threads 2 --epochs 10 --val-every-minutes 60 > logs/s28_crop128_train.log 2>&1
echo "$(date +%T) train done rc=$?"
bash logs/s25_eval.sh runs/s28_crop128/last crop128 mvor_twin mvor_alt mvor_rand4g
echo EVAL_DONE
