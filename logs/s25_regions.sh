source .venv/bin/activate
until grep -q CHECKS_DONE logs/s25_checks.log; do sleep 20; done
for t in shipped:posenet/weights/default.safetensors ctrl:runs/ft25_ctrl/last ft24:runs/ft24_gowns/last; do
  tag=${t%%:*}; ck=${t#*:}
  python benchmarks/look_factors.py --look alt --twin data/mvor_twin --full data/mvor_alt --work data/look_regions \
    --days 4 --parts body body:head body:trunk body:arms body:legs body:gown --checkpoint $ck --threads 2 \
    --json runs/look_regions_$tag.json > runs/look_regions_$tag.txt 2>&1
  echo "== $tag"; tail -14 runs/look_regions_$tag.txt
done
echo REGIONS_DONE
