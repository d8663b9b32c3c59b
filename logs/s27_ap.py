"""AP per set for detector checkpoints side by side (each at its own input width)."""
import json, sys, time
from detector.infer import PersonDetector
from detector.predict import predict_records
from detector.data import load_records
from detector.evaluate import coco_ap

sets = [("twin4", "data/mvor_twin", [4]), ("alt4", "data/mvor_alt", [4]), ("t7", "data/seq_t7", None), ("t8", "data/seq_t8", None)]
rows = []
for ck in sys.argv[2:]:
    det = PersonDetector.from_checkpoint(None if ck == "shipped" else ck, backend="auto")
    for name, root, days in sets:
        recs = load_records(f"{root}/annotations.json", days)
        t = time.perf_counter()
        res = predict_records(det, recs, root, progress=False)
        dt = (time.perf_counter() - t) / len(recs) * 1000
        m = coco_ap(recs, res)
        row = dict(ckpt=ck, width=det.cfg.input_width, backend=str(det.backend), set=name, ms_per_view=round(dt, 1), **{k: round(v, 3) for k, v in m.items() if isinstance(v, float)})
        print(json.dumps(row), flush=True)
        rows.append(row)
json.dump(rows, open(sys.argv[1], "w"))
