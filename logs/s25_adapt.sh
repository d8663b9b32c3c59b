source .venv/bin/activate
python -m posenet.adapt --data data/mvor_alt --days 1 2 3 --source-data data/mvor_rand123gd data/synth_mvorrig_randgd \
  --minutes 15 --threads 2 --out runs/adapt25_alt > logs/s25_adapt_run.log 2>&1
echo "adapt rc=$?"
bash logs/s25_eval.sh runs/adapt25_alt/last adapt25 mvor_alt mvor_twin
echo ADAPT_DONE
