source .venv/bin/activate
export ORPOSE_DETECTOR_CHECKPOINT=runs/det_s29_crowd/export.safetensors
SEQS="seq_eval seq_alt seq_long" bash logs/s25_served.sh s29crowd 2>&1 | grep -E "==|idf1|switches|mpjpe|accel|bone|track_ms"
unset ORPOSE_DETECTOR_CHECKPOINT
for look in twin alt; do
  python benchmarks/detector_mode.py --data data/mvor_$look --days 4 --variants +unsure+outliers+unseen --detector-checkpoint runs/det_s29_crowd/export.safetensors --json runs/s29_dm_${look}_crowd.json 2>&1 | grep -v "frames:" | tail -8
done
echo CHECK_DONE
