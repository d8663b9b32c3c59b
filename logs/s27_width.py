"""Shipped detector run at other input widths without retraining: AP per set."""
import json, sys, time
from dataclasses import replace
from detector.infer import PersonDetector
from detector.predict import predict_records
from detector.data import load_records
from detector.evaluate import coco_ap

sets = [("twin4", "data/mvor_twin", [4]), ("alt4", "data/mvor_alt", [4]), ("t7", "data/seq_t7", None), ("t8", "data/seq_t8", None)]
widths = [int(w) for w in sys.argv[1:]] or [160, 224, 288]
rows = []
for w in widths:
    det = PersonDetector.from_checkpoint(None)
    det.cfg = replace(det.cfg, input_width=w)
    for name, root, days in sets:
        recs = load_records(f"{root}/annotations.json", days)
        t = time.perf_counter()
        res = predict_records(det, recs, root, progress=False)
        dt = (time.perf_counter() - t) / len(recs) * 1000
        m = coco_ap(recs, res)
        row = dict(width=w, set=name, views=len(recs), ms_per_view=round(dt, 1), **{k: round(v, 3) for k, v in m.items() if isinstance(v, float)})
        print(json.dumps(row), flush=True)
        rows.append(row)
json.dump(rows, open("runs/s27_width.json", "w"))
