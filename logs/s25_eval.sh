# usage: bash logs/s25_eval.sh CKPT TAG SET...   (day 4, reference boxes)
source .venv/bin/activate
ck=$1; tag=$2; shift 2
mkdir -p runs/eval
for s in "$@"; do
  ann=$(ls data/$s/*.json | head -1)
  python -m posenet.predict --data data/$s --annotations $ann --checkpoint $ck --days 4 --out runs/eval/${tag}_$s.pred.json --threads 2 >/dev/null 2>&1
  python -m posenet.evaluate --annotations $ann --predictions runs/eval/${tag}_$s.pred.json --days 4 --json runs/eval/${tag}_$s.json > runs/eval/${tag}_$s.txt
  echo "$(date +%T) $tag $s $(python -c "import json;d=json.load(open('runs/eval/${tag}_$s.json'));print({k:v for k,v in d.items() if not isinstance(v,(dict,list))})")"
done
