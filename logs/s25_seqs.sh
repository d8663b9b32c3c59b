source .venv/bin/activate
S="python -m posenet.data.synth"
$S --out data/seq_eval --sequence --frames 120 --persons 3 --rig mvor --look twin --seed 0 --workers 1 --quiet > /dev/null
$S --out data/seq_alt --sequence --frames 120 --persons 3 --rig mvor --look alt --seed 0 --workers 1 --quiet > /dev/null
$S --out data/seq_long --sequence --frames 300 --persons 4 --rig mvor --look twin --seed 2 --workers 1 --quiet > /dev/null
echo SEQS_DONE
