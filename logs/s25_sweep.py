"""IDF1 over the five tuning sequences (weighted by person-frames) for tracker settings; cached detections."""
import json, subprocess, sys, tempfile
import os
W = os.environ.get("W", "25")
SEQS = os.environ.get("SEQS", "seq_tune seq_t3 seq_t4 seq_t5 seq_t6").split()
for setting in sys.argv[1:]:
    sets = [] if setting == "default" else sum((["--set", kv] for kv in setting.split(",")), [])
    tot = dict(pf=0, idf=0.0, miss=0, fp=0, sw=0)
    per = []
    for s in SEQS:
        with tempfile.NamedTemporaryFile(suffix=".json") as f:
            subprocess.run([".venv/bin/python", "benchmarks/tracking.py", "--data", f"data/{s}", "--detections",
                            f"runs/det{W}_{s}.jsonl".replace("{W}", W), "--json", f.name, *sets], check=True, capture_output=True)
            d = json.load(open(f.name))
        for q in d["sequences"].values():
            tot["pf"] += q["gt_person_frames"]; tot["idf"] += q["idf1"] * q["gt_person_frames"]
            tot["miss"] += q["misses"]; tot["fp"] += q["false_positives"]; tot["sw"] += q["id_switches"]
            per.append(round(q["idf1"], 3))
    print(f"{setting:40s} IDF1 {tot['idf']/tot['pf']:.3f} misses {tot['miss']} FP {tot['fp']} switches {tot['sw']} per-seq {per}", flush=True)
