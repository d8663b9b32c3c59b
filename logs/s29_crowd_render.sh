# crowded random-look sequences for a detector fine-tune (never evaluation/tuning seeds): 6 persons
source .venv/bin/activate
python -m posenet.data.synth --out data/seqcrowd_mvor --sequence --days 8 --frames 40 --fps 2 --persons 6 --rig mvor --look random --seed 60 --workers 2 --quiet > /dev/null && echo "$(date +%T) mvor done"
python -m posenet.data.synth --out data/seqcrowd_rand --sequence --days 8 --frames 30 --fps 2 --persons 6 --rig random --look random --seed 61 --workers 2 --quiet > /dev/null && echo "$(date +%T) rand done"
echo RENDER_DONE
