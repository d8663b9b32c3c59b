# renderer 1.2 through the CLI (writes synth_config.json too), then the old convention of the held-out ones in /tmp
source .venv/bin/activate
for s in seq_eval seq_alt seq_long seq_tune seq_t3 seq_t4 seq_t5 seq_t6 seq_t7 seq_t8 seq_t9; do
  args=$(python -c "
import json; c = json.load(open('data/$s/annotations.json'))['dataset_info']['synthetic']
print(f\"--sequence --frames {c['frames']} --persons {c['persons']} --rig {c['rig']} --look {c['look']} --seed {c['seed']} --fps {c['fps']}\")")
  rm -rf data/$s.new
  python -m posenet.data.synth --out data/$s.new $args --workers 2 --quiet > /dev/null
  cmp -s data/$s/annotations.json data/$s.new/annotations.json && echo "$s same annotations" || { echo "$s DIFFERS"; continue; }
  rm -rf data/$s; mv data/$s.new data/$s; touch data/$s/.done
done
for s in seq_eval seq_alt seq_long; do
  args=$(python -c "
import json; c = json.load(open('data/$s/synth_config.json'))['config']
print(f\"--sequence --frames {c['frames']} --persons {c['persons']} --rig {c['rig']} --look {c['look']} --seed {c['seed']} --fps {c['fps']}\")")
  rm -rf /tmp/all_$s
  python -m posenet.data.synth --out /tmp/all_$s $args --workers 2 --quiet --annotate all > /dev/null
  python benchmarks/tracking.py --data /tmp/all_$s --served runs/${s}_s27mvor.jsonl --json runs/${s}_s27mvor_all.track.json | grep -E "sequence|idf1|switches"
done
echo CLI_DONE
