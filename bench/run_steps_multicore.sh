#!/usr/bin/env bash
# The training steps' scaling with threads on a machine with more cores (docs/performance.md "Measured on 16
# cores"): the machine's facts, then bench_hybrid's RGB step, exact hybrid step (the object terms) and full step
# (with SCL's language term; builds before 9b62f8e lack it), with their per-part counters, at each thread count of
# THREADS (default 1,2,4,8,16) for each build folder given, alternating (a second round in
# the opposite order at the counts above 2), then bench_scale at the most threads for each (also with a table
# rebuild in every step: issue 61's goal 3), then (first build) the one-thread step alone and as one copy per
# core at once (bench/shared_report.py) and bench/project_threads.py's projection with each region's time measured
# at the most threads beside it (--measure: which regions fall short of what their tasks allow), for the hybrid
# step and the full step; last, the step as `hgs train` runs it on a synthetic capture at the paper's scale
# (bench/train_steps.sh: RGB and the full method, each build, at the most threads; the box scene above
# understates the method's step, docs/performance.md "Issue 61, session twelve"), and the tabletop's full step on
# a densified model (DENSIFIED=1, "Issue 61, session sixteen"). JSON and text
# under OUT (default /tmp/steps_multicore); `bench/amdahl.py OUT/<tag>.json --threads 4 16` prints projection and
# measurement side by side.
#   bench/run_steps_multicore.sh NEW_BUILD_DIR [OLD_BUILD_DIR]
set -uo pipefail
[ $# -ge 1 ] || { echo "usage: bench/run_steps_multicore.sh NEW_BUILD_DIR [OLD_BUILD_DIR]" >&2; exit 2; }
THREADS="${THREADS:-1,2,4,8,16}"
unset OMP_WAIT_POLICY  # passive waiting made a 16-thread step 4x slower (docs/performance.md): time the default
O="${OUT:-/tmp/steps_multicore}"
mkdir -p "$O"
F='BM_RgbStep|BM_HybridStep/objects_per_step:0/sparse:1|BM_FullStep'
echo "== machine"
echo "nproc $(nproc), cgroup cpu.max: $(cat /sys/fs/cgroup/cpu.max 2>/dev/null || echo none)"
lscpu | grep -E '^(Model name|Thread\(s\) per core|Core\(s\) per socket|Socket\(s\)|L3)' || true
hb() {  # tag build threads
  HGS_BENCH_THREADS="$3" "$2/bench_hybrid" --benchmark_filter="$F" --benchmark_repetitions=3 \
    --benchmark_min_time=0.3 --benchmark_display_aggregates_only=true --benchmark_out="$O/$1.json" 2>&1 |
    grep -E 'median|error' | sed "s/^/$1 /" | tee -a "$O/hybrid.txt"
}
tags=(new) dirs=("$1")
[ $# -ge 2 ] && tags+=(old) dirs+=("$2")
above2="${THREADS#1,2,}"
for i in "${!dirs[@]}"; do hb "${tags[$i]}1" "${dirs[$i]}" "$THREADS"; done
if [ $# -ge 2 ]; then
  for i in 1 0; do hb "${tags[$i]}2" "${dirs[$i]}" "$above2"; done
fi
for i in "${!dirs[@]}"; do
  "${dirs[$i]}/bench_scale" --steps 3 --threads "${THREADS##*,}" --json "$O/scale_${tags[$i]}.json" 2>&1 |
    sed "s/^/${tags[$i]} /" | tee "$O/scale_${tags[$i]}.txt"
done
# Issue 61's goal 3 (the observation-table rebuild): the 1000x700 / 300k hybrid step with a rebuild in every step
# (--fusion-every 1; the part densify, 2 views) for each build. A capture's 42 training views every 100 steps add
# 42 / 2 / 100 of that part to the mean step; printed as the mean / median step it makes.
for i in "${!dirs[@]}"; do
  "${dirs[$i]}/bench_scale" --case hybrid 1 1 --steps 3 --threads "${THREADS##*,}" --fusion-every 1 | grep '^{' |
    tee "$O/rebuild_${tags[$i]}.json" | python3 -c 'import json, sys
j = json.loads(sys.stdin.read()); r = j["parts_ms"]["densify"]; step = j["ms_median"] - r
print("%s rebuild %.1f ms per view; 42 views every 100 steps: mean / median step %.3f" % (sys.argv[1], r / 2,
      (step + r / 2 * 42 / 100) / step))' "${tags[$i]}" | tee -a "$O/rebuild.txt"
done
# What the cores share (memory bandwidth, the L3, the clock under load): the one-thread 1000x700 / 300k step of the
# first build alone, then as many copies at once as the most threads, one per core. Each copy does the work of the
# one alone, so a part that slows beside its neighbours is bound by what they share, not by its tasks; what its
# tasks allow at that thread count is bench/project_threads.py's projection (from one thread, run here too).
NT="${THREADS##*,}"
for m in rgb hybrid; do
  "$1/bench_scale" --case "$m" 1 1 --steps 3 --threads 1 | grep '^{' >"$O/shared_${m}_alone.json"
  for ((c = 0; c < NT; c++)); do
    taskset -c "$c" "$1/bench_scale" --case "$m" 1 1 --steps 3 --threads 1 | grep '^{' >"$O/shared_${m}_copy$c.json" &
  done
  wait
done
if command -v python3 >/dev/null; then
  python3 "$(dirname "$0")/shared_report.py" "$O" | tee "$O/shared.txt"
  python3 "$(dirname "$0")/project_threads.py" --build "$1" --threads "$NT" --min-ms 2 --measure |
    tee "$O/projection.txt"
  python3 "$(dirname "$0")/project_threads.py" --build "$1" --threads "$NT" --min-ms 2 --measure --case full 1 1 |
    tee "$O/projection_full.txt"
fi
# The real step (bench/train_steps.sh): the room at 1000x700 with 300k points, 60 iterations, each build's hgs.
train_builds=()
for d in "${dirs[@]}"; do train_builds+=("$d/hgs"); done
SIZE=paper METHOD=both ITERS=60 REPS=1 THREADS="$NT" "$(dirname "$0")/train_steps.sh" "$O/train" "${train_builds[@]}" |
  tee "$O/train_steps.txt"
# The same on a densified model (the tabletop after 2900 densified iterations, then 100 timed ones per build): the
# Gaussians a view sees cluster by index there, which loops split statically into one range per thread did not
# survive (docs/performance.md, "Issue 61, session sixteen").
SIZE=small METHOD=full DENSIFIED=1 ITERS=100 REPS=2 THREADS="$NT" "$(dirname "$0")/train_steps.sh" "$O/train" \
  "${train_builds[@]}" | tee "$O/train_steps_dense.txt"
