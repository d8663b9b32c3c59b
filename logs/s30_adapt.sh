source .venv/bin/activate
echo "$(date -u +%FT%T) adapt start"
python -m posenet.adapt --data data/mvor_alt --days 1 2 3 --source-data data/mvor_rand123gd data/synth_mvorrig_randgd \
  --minutes 15 --threads 2 --out runs/adapt30_alt > logs/s30_adapt_run.log 2>&1
echo "$(date -u +%FT%T) adapt rc=$?"
bash logs/s25_eval.sh posenet/weights/default.safetensors shipped30 mvor_twin mvor_alt mvor_rand4g
bash logs/s25_eval.sh runs/adapt30_alt/last adapt30 mvor_alt mvor_twin
echo ADAPT_DONE
