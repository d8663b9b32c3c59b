"""Render sequences again with renderer 1.2 (MVOR's annotation convention); check that images and boxes are the
same bytes, then replace the folder."""
import json, shutil, sys
from pathlib import Path
from posenet.data.synth.writer import SynthConfig, generate

for name in sys.argv[1:]:
    old = Path("data") / name
    new = Path("data") / (name + ".new")
    shutil.rmtree(new, ignore_errors=True)
    c = json.loads((old / "synth_config.json").read_text())["config"]
    c.pop("version"); c["out"] = str(new); c["workers"] = 2
    s = generate(SynthConfig(**c), progress=False)
    a, b = json.loads((old / "annotations.json").read_text()), json.loads((new / "annotations.json").read_text())
    same_boxes = [x["bbox"] for x in a["annotations"]] == [x["bbox"] for x in b["annotations"]]
    pngs = sorted(old.rglob("*.png"))
    same_png = all((new / p.relative_to(old)).read_bytes() == p.read_bytes() for p in pngs)
    print(name, "boxes same", same_boxes, "pngs same", same_png, len(pngs), "poses", len(a["annotations3D"]), "->", len(b["annotations3D"]), flush=True)
    if not (same_boxes and same_png):
        raise SystemExit(f"{name}: differs")
    done = (old / ".done").exists()
    shutil.rmtree(old); new.rename(old)
    if done:
        (old / ".done").touch()
