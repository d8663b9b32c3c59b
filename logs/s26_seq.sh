source .venv/bin/activate
for seed in 7 8 9; do
  s=seq_t$seed
  [ -f data/$s/.done ] || { python -m posenet.data.synth --out data/$s --sequence --frames 300 --persons 4 --rig mvor --look twin --seed $seed --workers 2 --quiet > /dev/null && touch data/$s/.done; }
  python benchmarks/tracking.py --data data/$s --detections runs/det26_$s.jsonl --redetect > runs/det26_$s.txt 2>&1
  echo "$(date +%T) $s $(grep idf1 runs/det26_$s.txt)"
done
echo SEQ_DONE
