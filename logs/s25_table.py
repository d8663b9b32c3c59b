import json, sys
from pathlib import Path
tags = sys.argv[1:] or ["shipped", "ctrl", "ft24"]
sets = ["mvor_twin", "mvor_alt", "mvor_rand4g", "s24_alt_gown", "s24_alt_body"]
print("| weights | " + " | ".join(sets) + " |")
for t in tags:
    row = []
    for s in sets:
        p = Path(f"runs/eval/{t}_{s}.json")
        if not p.exists():
            row.append("-"); continue
        d = json.loads(p.read_text())
        pj = d["per_joint"]; ps = d["per_support"]
        joints = " / ".join("%.1f" % pj[k] for k in ["head", "neck", "shoulder", "hip", "elbow", "wrist"])
        support = " / ".join("%.1f" % ps[v]["average"] for v in "123")
        row.append("%.2f (%s; %s)" % (d["overall"], joints, support))
    print(f"| {t} | " + " | ".join(row) + " |")
