# the held-out sequences' files with --annotate all (renderer 1.1's convention), to score a served run both ways
source .venv/bin/activate
for s in seq_eval seq_alt seq_long; do
  python - <<PY
import json
from posenet.data.synth.writer import SynthConfig, generate
c = json.load(open("data/$s/synth_config.json"))["config"]; c.pop("version")
c.update(out="/tmp/all_$s", workers=2, annotate="all")
generate(SynthConfig(**c), progress=False)
PY
  python benchmarks/tracking.py --data /tmp/all_$s --served runs/${s}_s27mvor.jsonl --json runs/${s}_s27mvor_all.track.json | grep -E "sequence|idf1|switches"
done
