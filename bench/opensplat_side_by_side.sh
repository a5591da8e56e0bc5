#!/usr/bin/env bash
# hgs's RGB training step against OpenSplat's CPU build on the same scene (docs/performance.md, "Against
# OpenSplat's CPU build"): a synthetic 320x240 scene whose 30k SfM points both take as the initial Gaussians,
# densification off, full resolution from the first iteration, SH degree 3, N iterations, the two programs
# alternating, REPS rounds, at 1 and 2 threads (pinned with taskset). OpenSplat is not part of hgs: bring your
# own binary (built against LibTorch; on Debian 12, `apt-get install libtorch-dev libopencv-dev`).
# OpenSplat has no timer, so its time is the marginal one from the timestamps of its per-iteration "Step k:"
# lines ((last - first) / (steps between)); hgs's is the median ms / iteration that `hgs train` prints.
# Both OpenSplat lines run as released: the options are read from the binary's --help. The 1.1.x line calls the
# start of densification --warmup-length, 1.2.0 --densify-from; 1.2.0 reads a masks/ folder beside the images as
# validity masks (hgs's scenes have one: its label PNGs) unless given --no-masks, which would make its steps
# cheaper than a plain training step, so the flag is passed wherever the binary has it.
#   bench/opensplat_side_by_side.sh OPENSPLAT HGS [OUT]        (N=400 REPS=2 THREADS="1 2" by default)
set -uo pipefail
[ $# -ge 2 ] || { echo "usage: bench/opensplat_side_by_side.sh OPENSPLAT_BINARY HGS_BINARY [OUT]" >&2; exit 2; }
OS="$1" H="$2" O="${3:-/tmp/opensplat_side_by_side}"
N="${N:-400}" REPS="${REPS:-2}" THREADS="${THREADS:-1 2}"
for b in "$OS" "$H"; do [ -x "$b" ] || { echo "$b: not an executable" >&2; exit 2; }; done
mkdir -p "$O"
S="$O/scene"
[ -f "$S/sparse/0/points3D.bin" ] || "$H" synth --out "$S" --quiet || exit 1
help="$("$OS" --help 2>&1)"
os_opts=()
if grep -q -- '--densify-from' <<<"$help"; then os_opts+=(--densify-from 100000000)
elif grep -q -- '--warmup-length' <<<"$help"; then os_opts+=(--warmup-length 100000000)
else echo "$OS: --help names neither --densify-from (1.2.x) nor --warmup-length (1.1.x): not an OpenSplat binary?" >&2; exit 2
fi
grep -q -- '--no-masks' <<<"$help" && os_opts+=(--no-masks)
echo "machine: $(lscpu | sed -n 's/^Model name: *//p'), nproc $(nproc); OpenSplat options: ${os_opts[*]}"
for rep in $(seq 1 "$REPS"); do
  for T in $THREADS; do
    cpus=0-$((T - 1))
    out="$O/os_r${rep}_t${T}"
    mkdir -p "$out"
    OMP_NUM_THREADS=$T OPENBLAS_NUM_THREADS=$T MKL_NUM_THREADS=$T taskset -c "$cpus" "$OS" "$S" -n "$N" -d 1 \
      --num-downscales 0 --sh-degree 3 --sh-degree-interval 1 --refine-every 100000000 \
      "${os_opts[@]}" -s -1 -o "$out/splat.ply" 2>&1 |
      perl -MTime::HiRes=time -ne 'BEGIN { $| = 1; $t0 = time } printf("%.4f %s", time - $t0, $_)' >"$out/log.txt"
    awk -v r="$rep" -v t="$T" '/ Step [0-9]+:/ { s = $3; sub(":", "", s); if (!n++) { f = $1; fs = s } l = $1; ls = s }
      END { if (ls > fs) printf("round %d, %d thread(s): OpenSplat %.1f ms / iteration (steps %d..%d)\n", r, t,
            1000 * (l - f) / (ls - fs), fs, ls); else printf("round %d, %d thread(s): OpenSplat printed no steps\n", r, t) }' \
      "$out/log.txt"
    rm -rf "$O/hgs_r${rep}_t${T}"
    OMP_NUM_THREADS=$T taskset -c "$cpus" "$H" train "$S" --out "$O/hgs_r${rep}_t${T}" --method rgb --no-densify \
      --iters "$N" --threads "$T" --seed 0 >"$O/hgs_r${rep}_t${T}.log" 2>&1
    sed -n "s/^trained .*(\([0-9.]*\) ms\/it median).*/round $rep, $T thread(s): hgs \1 ms \/ iteration/p" \
      "$O/hgs_r${rep}_t${T}.log"
  done
done
