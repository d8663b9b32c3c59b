set -e
M=../shared/mvor/camma_mvor_2018.json
S="python -m posenet.data.synth"
source .venv/bin/activate
r() { out=$1; shift; if [ -f data/$out/.done ]; then echo "skip $out"; return; fi; echo "$(date +%T) start $out"; $S --out data/$out "$@" --workers 2 --quiet; touch data/$out/.done; echo "$(date +%T) done $out"; }
r mvor_twin --from-mvor $M --seed 0
r mvor_alt --from-mvor $M --look alt
r mvor_rand4g --from-mvor $M --look random --mvor-days 4 --seed 4
r mvor_rand123gd --from-mvor $M --look random --mvor-days 1 2 3 --seed 11 --grammar-share 0.5 --drawn-gowns 0.5
r synth_mvorrig_randgd --scenes 600 --rig mvor --days 3 --seed 12 --grammar-share 0.5 --drawn-gowns 0.5
r synth_randrig_randgd --scenes 300 --rig random --days 3 --seed 13 --grammar-share 0.5 --drawn-gowns 0.5
r mvor_rand123hd --from-mvor $M --look random --mvor-days 1 2 3 --seed 21 --grammar-share 0.8 --drawn-gowns 0.5
r synth_mvorrig_randhd --scenes 600 --rig mvor --days 3 --seed 22 --grammar-share 0.8 --drawn-gowns 0.5
r synth_randrig_randhd --scenes 300 --rig random --days 3 --seed 23 --grammar-share 0.8 --drawn-gowns 0.5
r s24_alt_gown --from-mvor $M --look alt --mvor-days 4 --look-parts body:gown
r s24_alt_body --from-mvor $M --look alt --mvor-days 4 --look-parts body
echo ALL_RENDERED
