set -e
M=../shared/mvor/camma_mvor_2018.json
S="python -m posenet.data.synth"
source .venv/bin/activate
r() { out=$1; shift; if [ -f data/$out/.done ]; then echo "skip $out"; return; fi; echo "$(date +%T) start $out"; rm -rf data/$out.new; $S --out data/$out.new "$@" --workers 2 --quiet; rm -rf data/$out; mv data/$out.new data/$out; touch data/$out/.done; echo "$(date +%T) done $out"; }
for d in mvor_twin mvor_alt mvor_rand4g; do rm -f data/$d/.done; done
r mvor_twin --from-mvor $M --seed 0
r mvor_alt --from-mvor $M --look alt
r mvor_rand4g --from-mvor $M --look random --mvor-days 4 --seed 4
echo ALL_RENDERED
