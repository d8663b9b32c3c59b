# three more tuning sequences (never evaluation ones): 300 frames, 5 persons, seeds 10-12; then the pipeline cached (W=28n settings = shipped)
source .venv/bin/activate
for n in 10 11 12; do
  s=seq_t$n
  [ -f data/$s/.done ] || { rm -rf data/$s; python -m posenet.data.synth --out data/$s --sequence --frames 300 --persons 5 --rig mvor --look twin --seed $n --workers 2 --quiet > /dev/null && touch data/$s/.done; }
  echo "$(date +%T) rendered $s"
  python benchmarks/tracking.py --data data/$s --detections runs/det28n_$s.jsonl --redetect > runs/det28n_$s.txt 2>&1
  echo "$(date +%T) $s $(grep idf1 runs/det28n_$s.txt)"
done
echo RENDER_DONE
