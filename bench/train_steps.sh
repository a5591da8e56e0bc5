#!/usr/bin/env bash
# The training step as `hgs train` runs it on a synthetic capture, for one or more builds side by side
# (docs/performance.md, "Issue 61, session twelve"). bench_hybrid and bench_scale time the step on a box of random
# Gaussians seen by two cameras with clean grid masks: most Gaussians are hidden, q is one-hot, and the object
# channels and f's row updates have a fraction of the work they have on a capture. This script times the real
# thing: `hgs synth` makes the scene once (cached in OUT; the room preset at 1000x700 with 300k points is the
# paper's LERF scale, the default tabletop 320x240 / 30k is bench_hybrid's size), then each build trains it for
# ITERS iterations without densification (the Gaussian count stays fixed), builds alternating, REPS rounds, and
# the script prints each run's median ms / iteration and mean and median ms per part from train_stats.json.
# Iteration 100's observation-table rebuild is in the mean, not in the median.
# Each run's train_stats.json stays in OUT/run_SIZE_METHOD_tTHREADS_bBUILD (run_SIZE_dense_... with DENSIFIED=1):
# with runs at THREADS=1 and 2,
#   bench/amdahl.py OUT/run_paper_full_t1_b1/train_stats.json OUT/run_paper_full_t2_b1/train_stats.json [--median]
# projects each part to more threads.
# DENSIFIED=1 times the step on a densified model instead: the first build trains the scene once with
# densification for DITERS iterations (default 3000; the schedule, scaled to the run, densifies in its first half)
# and saves a checkpoint ITERS before the end (kept in OUT/dense_SIZE_METHOD); each build then resumes from it and
# runs the last ITERS iterations. Densification appends its clones at the end of the arrays, so the Gaussians a view
# sees cluster by index: loops over the Gaussians split statically into one range per thread leave threads idle
# there, which the undensified scene does not show (docs/performance.md, session sixteen).
#   bench/train_steps.sh OUT HGS [HGS2 ...]
#   env: SIZE=paper|small (default small), METHOD=full|rgb|both (default both), ITERS (120), REPS (2), THREADS (2),
#        DENSIFIED=0|1 (0), DITERS (3000)
set -uo pipefail
[ $# -ge 2 ] || { echo "usage: bench/train_steps.sh OUT HGS_BINARY [HGS_BINARY ...]" >&2; exit 2; }
O="$1"
shift
SIZE="${SIZE:-small}" METHOD="${METHOD:-both}" ITERS="${ITERS:-120}" REPS="${REPS:-2}" THREADS="${THREADS:-2}"
DENSIFIED="${DENSIFIED:-0}" DITERS="${DITERS:-3000}"
case "$DENSIFIED" in 0 | 1) ;; *) echo "DENSIFIED must be 0 or 1, not '$DENSIFIED'" >&2; exit 2 ;; esac
[ "$DENSIFIED" = 0 ] || [ "$DITERS" -gt "$ITERS" ] 2>/dev/null || {
  echo "DITERS ($DITERS) must be a number above ITERS ($ITERS)" >&2
  exit 2
}
for b in "$@"; do [ -x "$b" ] || { echo "$b: not an executable" >&2; exit 2; }; done
case "$SIZE" in
  paper) synth=(--preset room --width 1000 --height 700 --points 300000) ;;
  small) synth=() ;;
  *) echo "SIZE must be paper or small, not '$SIZE'" >&2; exit 2 ;;
esac
case "$METHOD" in
  both) methods=(rgb full) ;;
  rgb | full) methods=("$METHOD") ;;
  *) echo "METHOD must be full, rgb or both, not '$METHOD'" >&2; exit 2 ;;
esac
mkdir -p "$O"
S="$O/scene_$SIZE"
[ -f "$S/sparse/0/points3D.bin" ] || "$1" synth --out "$S" "${synth[@]}" --quiet || exit 1
echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), nproc $(nproc); scene $S; $ITERS iterations, $THREADS thread(s)" \
  "$([ "$DENSIFIED" = 1 ] && echo "after $((DITERS - ITERS)) densified ones")"
unset OMP_WAIT_POLICY # passive waiting slows the steps (docs/performance.md): time the default
# The densified model of a method: trained once by the first build, a checkpoint ITERS iterations before the end.
dense_checkpoint() {
  local m="$1" base="$O/dense_${SIZE}_$1" opt=()
  local ckpt="$base/checkpoints/iter_$((DITERS - ITERS)).ckpt"
  [ "$m" = rgb ] && opt=(--method rgb)
  if [ ! -f "$ckpt" ]; then
    rm -rf "$base"
    "$first" train "$S" --out "$base" --iters "$DITERS" --save-every "$((DITERS - ITERS))" --threads "$THREADS" \
      --seed 0 --quiet "${opt[@]}" >"$base.log" 2>&1 || {
      echo "densified training failed, see $base.log" >&2
      return 1
    }
  fi
  echo "$ckpt"
}
first="$1"
for rep in $(seq 1 "$REPS"); do
  for m in "${methods[@]}"; do
    i=0
    for H in "$@"; do
      i=$((i + 1))
      run="$O/run_${SIZE}$([ "$DENSIFIED" = 1 ] && echo _dense)_${m}_t${THREADS}_b${i}"
      rm -rf "$run"
      opt=()
      [ "$m" = rgb ] && opt=(--method rgb)
      if [ "$DENSIFIED" = 1 ]; then
        ckpt="$(dense_checkpoint "$m")" || exit 1
        opt+=(--iters "$DITERS" --resume "$ckpt")
      else
        opt+=(--iters "$ITERS" --no-densify)
      fi
      "$H" train "$S" --out "$run" --threads "$THREADS" --seed 0 --quiet "${opt[@]}" \
        >"$run.log" 2>&1 || { echo "$H: training failed, see $run.log" >&2; continue; }
      python3 - "$run/train_stats.json" "$rep" "$m" "$H" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
parts = ", ".join(f"{k} {v:.1f}" for k, v in d["mean_ms_per_part"].items() if v >= 0.05)
med = d.get("median_ms_per_part", {})
med = ", ".join(f"{k} {v:.1f}" for k, v in med.items() if v >= 0.05)
print(f"round {sys.argv[2]}, {sys.argv[3]}, {sys.argv[4]}: median {d['median_ms_per_iter']:.1f} ms, "
      f"mean {d['mean_ms_per_iter']:.1f}; parts (mean ms): {parts}" + (f"; (median ms): {med}" if med else "") +
      f"; peak RSS {d['peak_rss_mb']:.0f} MB")
EOF
    done
  done
done
