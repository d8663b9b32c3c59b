source .venv/bin/activate
M=../shared/mvor/camma_mvor_2018.json
# the two random-look sets of MVOR's days 1-3 poses again, with the twin writer's id fix (2 frames change)
for spec in "mvor_rand123gd --seed 11 --grammar-share 0.5" "mvor_rand123hd --seed 21 --grammar-share 0.8"; do
  set -- $spec; out=$1; shift
  echo "$(date +%T) render $out"
  rm -rf data/$out.new; python -m posenet.data.synth --out data/$out.new --from-mvor $M --look random --mvor-days 1 2 3 "$@" --drawn-gowns 0.5 --workers 2 --quiet > /dev/null && rm -rf data/$out && mv data/$out.new data/$out
done
run() { tag=$1; shift
  echo "$(date +%T) train $tag start"
  python -m posenet.train --data data/mvor_twin --holdout-day 4 \
    --extra-data data/mvor_rand123gd data/synth_mvorrig_randgd data/synth_randrig_randgd \
                 data/mvor_rand123hd data/synth_mvorrig_randhd data/synth_randrig_randhd \
    --watch data/mvor_alt:4 --out runs/s26_$tag \
    --init posenet/weights/default.safetensors --box-noise 0.5 --lr 2e-4 --warmup 0.05 --decay-start 0.5 \
    --view-loss 1.0 --threads 2 --epochs 4 --val-every-minutes 30 "$@" > logs/s26_train_$tag.log 2>&1
  echo "$(date +%T) train $tag done rc=$?"
  bash logs/s25_eval.sh runs/s26_$tag/last s26$tag mvor_twin mvor_alt mvor_rand4g
}
run occl --occlude 0.5
run ctrl
echo ALL_DONE
