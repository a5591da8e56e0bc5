#!/usr/bin/env bash
# SAM's scaling with threads on a machine with more cores (docs/sam.md "Threads"): the machine's facts (CPUs
# visible, a container's CPU quota, the CPU model and whether it has AMX), then bench_sam in float32 at each
# thread count of THREADS (default 1,2,4,8,16): the first binary every float32 benchmark, each further one
# (e.g. an older build to compare with) the embedding, the decoder and the sgemm reference; last, the first
# binary's bf16 embedding at 1 thread and at the most.
#   bench/run_multicore.sh build/bench_sam [OLD/bench_sam ...]
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: bench/run_multicore.sh BENCH_SAM [OLDER_BENCH_SAM ...]" >&2; exit 2; }
THREADS="${THREADS:-1,2,4,8,16}"
unset OMP_WAIT_POLICY  # passive waiting made a 16-thread step 4x slower (docs/performance.md): time the default
echo "== machine"
echo "nproc $(nproc) (all $(nproc --all)), cgroup cpu.max: $(cat /sys/fs/cgroup/cpu.max 2>/dev/null || echo none)"
lscpu | grep -E '^(Model name|Thread\(s\) per core|Core\(s\) per socket|Socket\(s\)|NUMA node\(s\)):' || true
grep -o -w -E 'amx_tile|amx_bf16|avx512_bf16|avx512f' /proc/cpuinfo | sort -u | tr '\n' ' '
echo
first=1
for b in "$@"; do
  echo "== $b"
  filter='bf16:0|Sgemm'
  [ $first = 1 ] || filter='(Embedding|Decoder).*bf16:0|Sgemm'
  HGS_BENCH_THREADS="$THREADS" "$b" --benchmark_filter="$filter"
  first=0
done
echo "== $1 bf16"
HGS_BENCH_THREADS="1,${THREADS##*,}" "$1" --benchmark_filter='Embedding.*bf16:1'
