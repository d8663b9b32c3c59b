# posenet.adapt's losses ablated again, from the shipped (session 25) weights: 10 wall-minutes each on 2 threads,
# alt's days 1-3 without poses; then day 4 of alt and the twin with reference boxes (logs/s25_eval.sh)
source .venv/bin/activate
run() { tag=$1; shift
  echo "$(date -u +%FT%T) adapt $tag $*"
  python -m posenet.adapt --data data/mvor_alt --days 1 2 3 --source-data data/mvor_rand123gd data/synth_mvorrig_randgd \
    --minutes 10 --threads 2 --out runs/s30_abl_$tag "$@" > logs/s30_abl_$tag.log 2>&1
  echo "$(date -u +%FT%T) adapt $tag rc=$?"
  bash logs/s25_eval.sh runs/s30_abl_$tag/last s30abl_$tag mvor_alt mvor_twin
}
run all
run nocons --consistency 0
run nopseudo --pseudo 0
run nobones --bones 0
run lr5 --lr 5e-5
echo ABLATE_DONE
