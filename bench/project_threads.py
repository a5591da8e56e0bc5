#!/usr/bin/env python3
"""What a training step on one thread says about T threads, parallel region by region (docs/performance.md).

Runs `bench_scale --case METHOD PIXELS GAUSSIANS --steps N --threads 1` under the LD_PRELOAD library
bench/omp_regions (built as <build>/libhgs_omp_regions.so with the benchmarks), whose tables bench_scale resets
after its warm-up step, so that they hold the N timed steps. The code that cuts its work by the thread count (the
object losses' bands, SSIM's bands, the tile walks' runs of tiles) is made to cut it as for T threads while it runs
on one (HGS_PLAN_THREADS, the functions' address ranges from nm). Per region (an OpenMP parallel region, named by
the function it is in):

  ms/step   its wall time per step on one thread
  single    the part of it in `omp single` blocks (serial at any T)
  dynamic   the part in chunks of dynamic loops, and their count
  dyn@T     the makespan of those chunks handed out as schedule(dynamic) would to T threads, in order
  proj@T    single + dyn@T + (the rest) / T + one fork/join (--overhead-us, an assumption) per call
  x         ms/step / proj@T

The step's time outside every region (serial code between them, timed from each region's end to the next one's
start) is added unchanged. What the projection sees: serial code, tasks fewer than threads, unequal tasks in a dynamic
schedule. What it cannot see: memory bandwidth and shared caches, the clock under load, barriers' cost beyond the
assumed fork/join, and static loops' imbalance (their split is taken as perfect). Where a measured T-thread step is
far slower than this projection, the difference is in that second list.

With --measure it also runs the step on T threads (the library's wall-time mode, HGS_REGIONS_WALL=1) and lists
each region's measured time beside its projection, the regions that lose most first: on a machine with T cores,
where the T-thread step's shortfall is.

  bench/project_threads.py --build build --threads 16 --case hybrid 1 1 [--measure]
"""
import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from glob import glob

SIMS = [2, 4, 8, 16, 32]  # the thread counts omp_regions simulates (its kSimThreads)
PLANNED = [r'hgs::hybrid::ObjectLosses::box_path\(', r'hgs::train::ssim_map<float>\(']
# The tile walks' run of tiles per chunk (render::detail::tile_run), in each rasterizer compilation.
PLANNED += [rf'hgs::render::{isa}::rasterize_{f}<float>\(' for isa in ('avx2', 'avx512')
            for f in ('forward', 'backward', 'depth_at')]


def plan_ranges(binary):
    """hex 'lo-hi' offsets of the functions that cut their work by omp_get_max_threads()."""
    out = subprocess.run(['nm', '-C', '-S', binary], capture_output=True, text=True, check=True).stdout
    ranges = []
    for pattern in PLANNED:
        for line in out.splitlines():
            parts = line.split(None, 3)
            if len(parts) == 4 and parts[2] in 'tTwW' and 'clone' not in parts[3] and re.search(pattern, parts[3]):
                lo, size = int(parts[0], 16), int(parts[1], 16)
                ranges.append(f'{lo:x}-{lo + size:x}')
                break
        else:
            print(f'project_threads: no symbol matches {pattern} in {binary}; its work is cut for one thread',
                  file=sys.stderr)
    return ','.join(ranges)


def run(binary, lib, case, steps, threads, ranges, out_prefix, measure=False):
    """bench_scale's JSON line and the regions' totals over the timed steps, {offset: {...}}: on one thread with the
    work cut as for `threads`, or (measure) on `threads` threads, the regions' wall times alone."""
    env = dict(os.environ, LD_PRELOAD=lib, HGS_REGIONS_OUT=out_prefix)
    if measure:
        env['HGS_REGIONS_WALL'] = '1'
    else:
        env.update(HGS_PLAN_THREADS=str(threads), HGS_PLAN_RANGES=ranges)
    env.pop('OMP_WAIT_POLICY', None)
    cmd = [binary, '--case', *case, '--steps', str(steps), '--threads', str(threads if measure else 1)]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if res.returncode != 0:
        sys.exit(f'project_threads: {" ".join(cmd)} failed ({res.returncode}): {res.stderr.strip()[-300:]}')
    js = [json.loads(l) for l in res.stdout.splitlines() if l.startswith('{')]
    files = glob(out_prefix + '.*')
    if not js or len(files) != 1:
        sys.exit(f'project_threads: no result from {" ".join(cmd)} (is {lib} the omp_regions library?)')
    regions = {}
    for line in open(files[0]):
        a = line.split()
        n = 6 + len(SIMS)
        regions[a[0]] = dict(calls=int(a[1]), s=float(a[2]), single=float(a[3]), dyn=float(a[4]), chunks=int(a[5]),
                             mk=[float(x) for x in a[6:n]], after=float(a[n]))
    return js[-1], regions


def short_name(name):
    """A demangled function name without its return type, argument list, clone suffix, anonymous namespaces, the
    rasterizer's ISA namespace and the tile kernels' template arguments (bench/ll_traffic.py uses it too)."""
    name = name.replace('(anonymous namespace)::', '').replace('avx2::', '').replace('avx512::', '')
    name = re.sub(r'\s*\[[^]]*\]\s*$', '', name)  # a clone (or file) suffix
    name = re.sub(r'\((?!\)).*', '', name)  # the argument list (not operator()'s)
    name = re.sub(r'^(void|float|int|auto|bool) ', '', name)
    return re.sub(r'(forward_tile|backward_tile)<.*>', r'\1', name)


def names(binary, offsets):
    if not offsets:
        return {}
    out = subprocess.run(['addr2line', '-f', '-C', '-e', binary] + offsets, capture_output=True, text=True).stdout
    lines = out.splitlines()
    return {o: short_name(lines[2 * i]) if 2 * i < len(lines) else o for i, o in enumerate(offsets)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--build', default='build')
    ap.add_argument('--threads', type=int, default=16, choices=SIMS)
    ap.add_argument('--case', nargs=3, default=['hybrid', '1', '1'], metavar=('METHOD', 'PIXELS', 'GAUSSIANS'))
    ap.add_argument('--steps', type=int, default=4, help='timed steps (after one warm-up)')
    ap.add_argument('--overhead-us', type=float, default=5.0, help='fork/join per region at T threads (assumed)')
    ap.add_argument('--min-ms', type=float, default=0.3, help='list regions above this many ms per step')
    ap.add_argument('--measure', action='store_true',
                    help='also run the step on --threads threads and put each region\'s measured wall time beside '
                    'its projection (on a machine with that many cores)')
    a = ap.parse_args()
    binary = os.path.join(a.build, 'bench_scale')
    lib = os.path.abspath(os.path.join(a.build, 'libhgs_omp_regions.so'))
    for f in (binary, lib):
        if not os.path.exists(f):
            sys.exit(f'project_threads: {f} not found (build the benchmarks: scripts/build)')
    ranges = plan_ranges(binary)
    k = SIMS.index(a.threads)
    with tempfile.TemporaryDirectory() as tmp:
        result, regions = run(binary, lib, a.case, a.steps, a.threads, ranges, os.path.join(tmp, 'r'))
    measured = None
    if a.measure:
        with tempfile.TemporaryDirectory() as tmp:
            measured = run(binary, lib, a.case, a.steps, a.threads, ranges, os.path.join(tmp, 'm'), measure=True)
    steps = a.steps
    rows = []
    for off, b in regions.items():
        calls = b['calls'] / steps
        if calls <= 0:
            continue
        ms = b['s'] / steps * 1e3
        single = b['single'] / steps * 1e3
        dyn = b['dyn'] / steps * 1e3
        chunks = b['chunks'] / steps
        mk = [m / steps * 1e3 for m in b['mk']]
        rest = max(0.0, ms - single - dyn)
        proj = [single + mk[i] + rest / t + calls * a.overhead_us * 1e-3 for i, t in enumerate(SIMS)]
        after = b['after'] / steps * 1e3
        rows.append(dict(off=off, calls=calls, ms=ms, single=single, dyn=dyn, chunks=chunks, mk=mk, proj=proj,
                         after=after))
    rows.sort(key=lambda r: -r['ms'])
    nm = names(binary, [r['off'] for r in rows])
    inside = sum(r['ms'] for r in rows)
    outside = sum(r['after'] for r in rows)  # between regions (includes the benchmark's loop between steps)
    step = inside + outside
    T = a.threads
    print(f"bench_scale --case {' '.join(a.case)}, one thread, work cut for {T} threads; per step ({steps} steps):")
    print(f"{'ms/step':>8} {'calls':>6} {'single':>7} {'dynamic':>8} {'chunks':>7} {f'dyn@{T}':>8} {f'proj@{T}':>8} "
          f"{'x':>5}  region")
    for r in rows:
        if r['ms'] >= a.min_ms:
            print(f"{r['ms']:8.2f} {r['calls']:6.1f} {r['single']:7.2f} {r['dyn']:8.2f} {r['chunks']:7.0f} "
                  f"{r['mk'][k]:8.2f} {r['proj'][k]:8.2f} {r['ms'] / r['proj'][k]:5.1f}  {nm.get(r['off'], r['off'])}")
    print(f"\nstep {step:.1f} ms at one thread (mean; the benchmark's median {result['ms_median']:.1f}): {inside:.1f} in "
          f"{sum(r['calls'] for r in rows):.0f} regions, {outside:.1f} between them (serial). Largest gaps, after:")
    for r in sorted(rows, key=lambda r: -r['after'])[:5]:
        print(f"  {r['after']:7.2f} ms  {nm.get(r['off'], r['off'])}")
    for i, t in enumerate(SIMS):
        p = outside + sum(r['proj'][i] for r in rows)
        print(f"projected at {t:2d} threads: {p:7.1f} ms ({step / p:4.1f}x)")
    print(f"(fork/join assumed {a.overhead_us:g} us per region; memory bandwidth, shared caches and the clock under "
          f"load are not in it)")
    if measured:
        report_measured(a, rows, nm, measured, step, outside, binary)


def report_measured(a, rows, nm, measured, step, outside, binary):
    """Each region's wall time measured on T threads beside its one-thread time and its projection: where the
    measured step falls short of the projection, the regions that lose the most say where."""
    T, k, steps = a.threads, SIMS.index(a.threads), a.steps
    result, regions = measured
    meas = {off: dict(ms=b['s'] / steps * 1e3, calls=b['calls'] / steps, after=b['after'] / steps * 1e3)
            for off, b in regions.items() if b['calls'] > 0}
    print(f"\nmeasured on {T} threads (bench_scale --threads {T}, the regions' wall times; median step "
          f"{result['ms_median']:.1f} ms), regions by their loss against the projection:")
    print(f"{'ms/step':>8} {f'proj@{T}':>8} {f'meas@{T}':>8} {'x':>6} {'lost':>7}  region")
    known = {r['off'] for r in rows}
    table = []
    for r in rows:
        m = meas.get(r['off'])
        if m:
            table.append((m['ms'] - r['proj'][k], r['ms'], r['proj'][k], m['ms'], nm.get(r['off'], r['off'])))
    extra = [o for o in meas if o not in known]
    extra_names = names(binary, extra)
    for o in extra:  # regions the one-thread run did not start
        table.append((meas[o]['ms'], 0.0, 0.0, meas[o]['ms'], extra_names.get(o, o) + ' (not on one thread)'))
    table.sort(key=lambda t: -t[0])
    for lost, one, proj, m, name in table:
        if max(one, m) >= a.min_ms:
            x = f"{one / m:6.1f}" if m > 0 and one > 0 else f"{'-':>6}"
            print(f"{one:8.2f} {proj:8.2f} {m:8.2f} {x} {lost:7.2f}  {name}")
    inside = sum(m['ms'] for m in meas.values())
    between = sum(m['after'] for m in meas.values())
    p = outside + sum(r['proj'][k] for r in rows)
    print(f"measured step on {T} threads: {inside + between:.1f} ms ({inside:.1f} in regions, {between:.1f} between "
          f"them), {step / (inside + between):.1f}x the one-thread step; projected {p:.1f} ms")


if __name__ == '__main__':
    main()
