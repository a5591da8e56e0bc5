#!/usr/bin/env bash
# bench/tracks_check.sh HGS REVAL_OUT OUT [NOISE]: the full method trained on masks associated with
# `hgs masks associate --tracks` against the same method on SAM2's tracks as given (docs/association.md, "SAM2
# tracks"). For every scene REVAL_OUT/scenes/{room,tabletop}_NOISE_* of a bench/revalidate.sh run (NOISE: high by
# default): a copy in OUT with its masks associated, `hgs train` (1500 iterations, training seed 3, the defaults),
# and `hgs eval --protocol instances --mode object` of it and of the run's own full model
# (ablate_PRESET_NOISE/SCENE/seed3/of1_scl1_bro1), both by HGS. Prints one line per scene (as given, --tracks) and
# the mean change. Reruns reuse what is finished. About 2 minutes per scene on 2 idle cores.
set -euo pipefail
if [ $# -lt 3 ]; then sed -n '2,8p' "$0" | sed 's/^# \{0,1\}//'; exit 2; fi
HGS="$(realpath "$1")" RUN="$(realpath "$2")" OUT="$3" NOISE="${4:-high}"
mkdir -p "$OUT"
miou() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['reports'][0]['summary']['mIoU'] * 100)" "$1"; }
lines=()
for src in "$RUN"/scenes/{room,tabletop}_"$NOISE"_*; do
  [ -d "$src" ] || continue
  s="$(basename "$src")" preset="${s%%_*}"
  base_model="$RUN/ablate_${preset}_$NOISE/$s/seed3/of1_scl1_bro1"
  [ -d "$base_model" ] || { echo "$base_model: no full model (run bench/revalidate.sh first)" >&2; exit 1; }
  if [ ! -d "$OUT/$s" ]; then
    rm -rf "$OUT/$s.tmp" && cp -r "$src" "$OUT/$s.tmp"
    "$HGS" masks associate "$OUT/$s.tmp" --tracks --quiet > "$OUT/$s.associate.log"
    mv "$OUT/$s.tmp" "$OUT/$s"
  fi
  if [ ! -f "$OUT/${s}_model/eval.json" ]; then
    rm -rf "$OUT/${s}_model"
    "$HGS" train "$OUT/$s" --out "$OUT/${s}_model" --iters 1500 --seed 3 --quiet
    "$HGS" eval "$OUT/$s" "$OUT/${s}_model" --protocol instances --mode object --out "$OUT/${s}_model/eval.json" \
      --no-png --quiet > /dev/null
  fi
  [ -f "$OUT/${s}_given.json" ] || "$HGS" eval "$src" "$base_model" --protocol instances --mode object \
    --out "$OUT/${s}_given.json" --no-png --quiet > /dev/null
  lines+=("$s $(miou "$OUT/${s}_given.json") $(miou "$OUT/${s}_model/eval.json")")
done
printf '%s\n' "${lines[@]}" | PYTHONPATH="$(dirname "$0")" python3 -c '
import statistics, sys
from revalidate_report import t95  # one table of Student t quantiles for the bench scripts
rows = [l.split() for l in sys.stdin if l.strip()]
print("scene                 as given  --tracks   change")
for s, a, b in rows:
    print(f"{s:20s} {float(a):9.2f} {float(b):9.2f} {float(b) - float(a):+8.2f}")
d = [float(b) - float(a) for _, a, b in rows]
if len(d) > 1:
    h = t95(len(d)) * statistics.stdev(d) / len(d) ** 0.5
    print(f"mean change {statistics.mean(d):+.2f} +- {h:.2f} (95 %, t over {len(d)} scenes)")'
