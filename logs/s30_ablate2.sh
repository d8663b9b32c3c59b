# after logs/s30_ablate.sh: the labelled source alone (no target loss), the control for what the target losses add
source .venv/bin/activate
while ! grep -q ABLATE_DONE logs/s30_ablate.log; do sleep 20; done
echo "$(date -u +%FT%T) adapt srconly"
python -m posenet.adapt --data data/mvor_alt --days 1 2 3 --source-data data/mvor_rand123gd data/synth_mvorrig_randgd \
  --minutes 10 --threads 2 --out runs/s30_abl_srconly --consistency 0 --pseudo 0 --bones 0 > logs/s30_abl_srconly.log 2>&1
echo "$(date -u +%FT%T) adapt srconly rc=$?"
bash logs/s25_eval.sh runs/s30_abl_srconly/last s30abl_srconly mvor_alt mvor_twin
echo ABLATE2_DONE
