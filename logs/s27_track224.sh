# tuning sequences through the pipeline with the 224-px detector, then the tracker's figures (defaults)
source .venv/bin/activate
for s in seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  python benchmarks/tracking.py --data data/$s --detections runs/det27b_$s.jsonl --redetect \
      --detector-checkpoint runs/det_s27_w224b/export.safetensors > runs/det27b_$s.txt 2>&1
  echo "$(date +%T) $s"
done
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=27b python logs/s25_sweep.py default
SEQS="seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9" W=26 python logs/s25_sweep.py default
echo TRACK224_DONE
