"""Average the weights of fine-tunes from one init (a uniform model soup): python logs/s30_soup.py OUT CKPT..."""
import shutil, sys
from pathlib import Path
import torch
from safetensors.torch import load_file, save_file

out, cks = Path(sys.argv[1]), [Path(c) for c in sys.argv[2:]]
sds = [load_file(str(c / "model.safetensors")) for c in cks]
soup = {}
for k, v in sds[0].items():
    if v.is_floating_point():
        soup[k] = torch.stack([sd[k].float() for sd in sds]).mean(0).to(v.dtype)
    else:
        soup[k] = v.clone()
out.mkdir(parents=True, exist_ok=True)
save_file(soup, str(out / "model.safetensors"))
shutil.copy(cks[0] / "config.json", out / "config.json")
print("soup of", len(cks), "->", out)
