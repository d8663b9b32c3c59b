set -e
M=../shared/mvor/camma_mvor_2018.json
source .venv/bin/activate
r() { out=$1; shift; if [ -f data/$out/.done ]; then echo "skip $out"; return; fi; echo "$(date +%T) start $out"; python -m posenet.data.synth --out data/$out "$@" --workers 2 --quiet >/dev/null; touch data/$out/.done; echo "$(date +%T) done $out"; }
r mvor_rand123g --from-mvor $M --look random --mvor-days 1 2 3 --seed 11
r synth_mvorrig_randg --scenes 600 --rig mvor --days 3 --seed 12
r synth_randrig_randg --scenes 300 --rig random --days 3 --seed 13
r mvor_rand123h --from-mvor $M --look random --mvor-days 1 2 3 --seed 21 --grammar-share 0.8
r synth_mvorrig_randh --scenes 600 --rig mvor --days 3 --seed 22 --grammar-share 0.8
r synth_randrig_randh --scenes 300 --rig random --days 3 --seed 23 --grammar-share 0.8
echo "$(date +%T) train start"
python -m posenet.train --data data/mvor_twin --holdout-day 4 \
  --extra-data data/mvor_rand123g data/synth_mvorrig_randg data/synth_randrig_randg \
               data/mvor_rand123h data/synth_mvorrig_randh data/synth_randrig_randh \
  --watch data/mvor_alt:4 data/mvor_rand4g:4 --out runs/ft25_ctrl \
  --init posenet/weights/default.safetensors --box-noise 0.5 --lr 2e-4 --warmup 0.05 --decay-start 0.5 \
  --view-loss 1.0 --threads 2 --epochs 10 --val-every-minutes 20 > logs/s25_ctrl_train.log 2>&1
echo "$(date +%T) train done"
bash logs/s25_eval.sh runs/ft25_ctrl/last ctrl mvor_twin mvor_alt mvor_rand4g s24_alt_gown s24_alt_body
echo CTRL_DONE
