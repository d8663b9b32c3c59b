# usage: SEQS="seq_eval seq_alt seq_long" bash logs/s25_served.sh TAG [POSE_CKPT]
# a real uvicorn server (detector mode, service defaults), service.client --track, benchmarks/tracking.py --served
source .venv/bin/activate
tag=$1; ck=${2:-}
port=8765
if [ -n "$ck" ]; then export ORPOSE_POSE_CHECKPOINT=$ck; fi
uvicorn service.app:app --port $port > runs/served_$tag.server.log 2>&1 &
srv=$!
until curl -sf http://127.0.0.1:$port/ready > /dev/null; do sleep 2; done
for s in ${SEQS:-seq_eval seq_alt seq_long}; do
  rm -f runs/${s}_$tag.jsonl
  python -m service.client data/$s --annotations data/$s/annotations.json --url http://127.0.0.1:$port \
     --out runs/${s}_$tag.jsonl --track > /dev/null 2>&1
  python benchmarks/tracking.py --data data/$s --served runs/${s}_$tag.jsonl --json runs/${s}_$tag.track.json > runs/${s}_$tag.track.txt 2>&1
  echo "== $tag $s"; tail -25 runs/${s}_$tag.track.txt
done
kill $srv
