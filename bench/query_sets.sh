#!/usr/bin/env bash
# The query sets (gt/queries.json: names, synonyms, hypernyms, attributes) asked of the full model of every scene
# of a `bench/revalidate.sh` run folder (or of one GROUP, e.g. room_high), instances protocol, object mode; each
# report is written beside the model as queries_<set>.json unless it is there already.
#   bench/query_sets.sh HGS OUT [GROUP]
# QUERY_ARGS (e.g. "--anchor-support 0.1") is passed to every `hgs eval`.
set -euo pipefail
if [ $# -lt 2 ]; then sed -n '2,6p' "$0" | sed 's/^# \{0,1\}//'; exit 2; fi
HGS="$1" OUT="$2" G="${3:-*}"
read -r -a query_args <<<"${QUERY_ARGS:-}"
for model in "$OUT"/ablate_$G/*/seed3/of1_scl1_bro1; do
  [ -f "$model/point_cloud.ply" ] || continue
  scene="$OUT/scenes/$(basename "$(dirname "$(dirname "$model")")")"
  for q in names synonyms hypernyms attributes; do
    [ -f "$model/queries_$q.json" ] || "$HGS" eval "$scene" "$model" --protocol instances --mode object --queries "$q" \
      --no-png --quiet --out "$model/queries_$q.json" "${query_args[@]}" >/dev/null
  done
done
