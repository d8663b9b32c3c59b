# detector mode (served default) and served tracking, shipped against ft24, same machine, one after another
source .venv/bin/activate
until grep -q CTRL_DONE logs/s25_ctrl.log; do sleep 20; done
until grep -q SEQS_DONE logs/s25_seqs.log; do sleep 10; done
for tag in shipped ft24; do
  ck=""; [ $tag = ft24 ] && ck=runs/ft24_gowns/last
  for s in mvor_twin mvor_alt; do
    python benchmarks/detector_mode.py --data data/$s --days 4 --variants +unsure+outliers+unseen \
      ${ck:+--pose-checkpoint $ck} --json runs/detmode_${tag}_$s.json > runs/detmode_${tag}_$s.txt 2>&1
    echo "== detmode $tag $s"; tail -20 runs/detmode_${tag}_$s.txt
  done
  bash logs/s25_served.sh $tag $ck
done
echo CHECKS_DONE
