#!/usr/bin/env bash
# Evaluates the models of a `bench/revalidate.sh` run folder again with another hgs binary (after a change to the
# evaluation or the query rules only), into a new folder, leaving the run as measured: the new folder gets copies
# of the small files and links to the models, then `hgs ablate --reevaluate` and the query sets run there.
# docs/ablation.md ("The query's anchor rule, re-evaluated on the same models") was made this way.
#   bench/reevaluate_copy.sh HGS RUN_OUT NEW_OUT GROUP [ROWS]     # GROUP e.g. room_high; ROWS as the run's (all)
#   (ROWS may list --rows values, e.g. single,ends: each is evaluated again, every row the run holds must be in one)
#   python3 bench/revalidate_report.py NEW_OUT                   # the tables, as for the run
# QUERY_ARGS="--anchor-support 0.1" passes query options to both the ablation's evaluation and the query sets.
set -euo pipefail
if [ $# -lt 4 ]; then sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 2; fi
read -r -a query_args <<<"${QUERY_ARGS:-}"
HGS="$(realpath "$1")" SRC="$(realpath "$2")" DST="$3" G="$4" ROWS="${5:-all}"
[ -x "$HGS" ] || { echo "reevaluate_copy.sh: $1 is not an executable" >&2; exit 2; }
[ -d "$SRC/ablate_$G" ] || { echo "reevaluate_copy.sh: no $SRC/ablate_$G (a group of bench/revalidate.sh)" >&2; exit 2; }
mkdir -p "$DST/scenes"
DST="$(realpath "$DST")"
[ "$DST" != "$SRC" ] || { echo "reevaluate_copy.sh: NEW_OUT must differ from RUN_OUT" >&2; exit 2; }
for s in "$SRC"/scenes/"$G"_*; do ln -sfn "$s" "$DST/scenes/$(basename "$s")"; done
(cd "$SRC" && find "ablate_$G" -type d) | while read -r d; do mkdir -p "$DST/$d"; done
(cd "$SRC" && find "ablate_$G" -type f ! -name point_cloud.ply ! -name 'queries_*' ! -name 'report.*') |
  while read -r f; do cp -p "$SRC/$f" "$DST/$f"; done
(cd "$SRC" && find "ablate_$G" -name point_cloud.ply) | while read -r f; do ln -sfn "$SRC/$f" "$DST/$f"; done
scenes=()
for s in "$DST"/scenes/"$G"_*; do scenes+=("$s"); done
IFS=, read -r -a row_sets <<<"$ROWS"
for rows in "${row_sets[@]}"; do
  "$HGS" ablate "${scenes[@]}" --out "$DST/ablate_$G" --rows "$rows" --iters 1500 --seed 3 \
    --protocol instances,3d-ovs --mode both --reevaluate --quiet "${query_args[@]}"
done
# The run's queries_*.json were not copied: all asked again.
QUERY_ARGS="${QUERY_ARGS:-}" "$(dirname "$0")/query_sets.sh" "$HGS" "$DST" "$G"
echo "bench/reevaluate_copy.sh: $DST/ablate_$G (python3 bench/revalidate_report.py $DST)"
