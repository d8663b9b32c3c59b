# tuning sequences (never the evaluation ones), detections cached with the shipped (session 25) weights
source .venv/bin/activate
S="python -m posenet.data.synth"
[ -d data/seq_tune ] || $S --out data/seq_tune --sequence --frames 120 --persons 3 --rig mvor --look twin --seed 1 --workers 1 --quiet >/dev/null
for sd in 3 4 5 6; do p=$(( 3 + sd % 2 )); [ -d data/seq_t$sd ] || $S --out data/seq_t$sd --sequence --frames 150 --persons $p --rig mvor --look twin --seed $sd --workers 1 --quiet >/dev/null; done
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6; do
  python benchmarks/tracking.py --data data/$s --detections runs/det25_$s.jsonl --json runs/tune25_$s.json > /dev/null 2>&1
  echo "$s cached"
done
echo TUNE_READY
