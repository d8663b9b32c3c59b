source .venv/bin/activate
until grep -q ALL_RENDERED logs/s25_render.log; do sleep 20; done
while pgrep -f "pytest -q -p no:cacheprovider" >/dev/null; do sleep 20; done
bash logs/s25_eval.sh posenet/weights/default.safetensors shipped mvor_twin mvor_alt mvor_rand4g s24_alt_gown s24_alt_body
echo "$(date +%T) train start"
python -m posenet.train --data data/mvor_twin --holdout-day 4 \
  --extra-data data/mvor_rand123gd data/synth_mvorrig_randgd data/synth_randrig_randgd \
               data/mvor_rand123hd data/synth_mvorrig_randhd data/synth_randrig_randhd \
  --watch data/mvor_alt:4 data/mvor_rand4g:4 --out runs/ft24_gowns \
  --init posenet/weights/default.safetensors --box-noise 0.5 --lr 2e-4 --warmup 0.05 --decay-start 0.5 \
  --view-loss 1.0 --threads 2 --epochs 10 --val-every-minutes 20 > logs/s25_ft24.log 2>&1
echo "$(date +%T) train done rc=$?"
bash logs/s25_eval.sh runs/ft24_gowns/last ft24 mvor_twin mvor_alt mvor_rand4g s24_alt_gown s24_alt_body
echo EVAL_DONE
