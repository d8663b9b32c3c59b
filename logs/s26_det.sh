source .venv/bin/activate
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6; do
  python benchmarks/tracking.py --data data/$s --detections runs/det26_$s.jsonl --redetect > runs/det26_$s.txt 2>&1
  echo "$(date +%T) $s $(grep idf1 runs/det26_$s.txt)"
done
echo DET_DONE
