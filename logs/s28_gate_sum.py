import json, glob, collections
tot = collections.defaultdict(lambda: collections.Counter())
for f in sorted(glob.glob("runs/s28_gate_seq_*.json")):
    for r in json.load(open(f)):
        g = r["config"]["centre_gate_mm"]
        for k in ("persons", "found", "missed", "split", "merged", "nobody", "groups"):
            tot[g][k] += r[k]
    print(f, [(r["config"]["centre_gate_mm"], r["found"], r["split"], r["merged"]) for r in json.load(open(f))])
for g, c in tot.items():
    print(g, dict(c), "found %.3f split %.3f merged %.3f" % (c["found"]/c["persons"], c["split"]/c["persons"], c["merged"]/c["persons"]))
