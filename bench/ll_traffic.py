#!/usr/bin/env python3
"""Bytes a training step moves past a core's private cache, per function: the part of the 16-thread picture that
bench/project_threads.py cannot see (docs/performance.md).

Runs `bench_scale --case METHOD SCALE SCALE --steps N --threads 1` under valgrind's callgrind with its cache
simulation (D1 48 KiB, LL 2 MiB: a core's own caches, so an LL miss is a line fetched from the shared L3 or memory)
collecting inside bench_scale's timed steps only (`hgs::bench::timed_step`, the steady state its medians time; with
--with-warmup inside every `Trainer::step()`, its warm-up steps, one per view of its scene, included: their first
touches of the buffers, zero-filled by the allocator and the page faults, are then in the figures, as they were
before 2026-12-06), for the RGB and the hybrid step; prints each function's misses times 64 bytes per step, RGB and
hybrid side by side, and the hybrid's extra. A bench_scale without `timed_step` (a build before it) is run as with
--with-warmup, and the header says so. The simulated CPU is valgrind's (no
AVX-512: the AVX2 rasterizer runs), and the cache is simulated, not measured. About 10 minutes at SCALE 0.25 on one
core. With --plan-threads T the code that cuts its work by the thread count (the object losses' bands, SSIM's
bands) cuts it as for T threads while one thread runs (bench/omp_regions, as project_threads.py does): the pieces a
16-thread step moves are smaller than one thread's.

  bench/ll_traffic.py --build build --scale 0.25 [--plan-threads 16] [--methods hybrid]
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
from collections import Counter

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from project_threads import plan_ranges, short_name  # noqa: E402  (the same names in both tables)

VIEWS = 2  # bench_scale's scene (bench/bench_hybrid_scene.h kViews): its warm-up steps


def run(binary, method, scale, steps, out, plan_threads, toggle):
    env = dict(os.environ)
    if plan_threads > 0:  # the work cut as for T threads (bench/omp_regions, as project_threads.py does)
        env.update(LD_PRELOAD=os.path.join(os.path.dirname(binary), 'libhgs_omp_regions.so'),
                   HGS_PLAN_THREADS=str(plan_threads), HGS_PLAN_RANGES=plan_ranges(binary),
                   HGS_REGIONS_OUT=out + '.regions')
    cmd = ['valgrind', '--tool=callgrind', '--cache-sim=yes', '--I1=32768,8,64', '--D1=49152,12,64',
           '--LL=2097152,16,64', '--collect-atstart=no', f'--toggle-collect={toggle}',
           f'--callgrind-out-file={out}', binary, '--case', method, str(scale), str(scale), '--steps', str(steps),
           '--threads', '1']
    res = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if res.returncode != 0 or not os.path.exists(out):
        sys.exit(f'll_traffic: {" ".join(cmd)} failed: {res.stderr.strip()[-400:]}')


def per_function(out, steps):
    """{function: MB per step} from callgrind_annotate's inclusive-free (self) LL misses."""
    text = subprocess.run(['callgrind_annotate', '--show=DLmr,DLmw', '--sort=DLmr,DLmw', '--threshold=100', out],
                          capture_output=True, text=True, check=True).stdout
    mb = Counter()
    for line in text.splitlines():
        m = re.match(r'^\s*([\d,]+)\s+(?:\([^)]*\)\s+)?([\d,]+)\s+(?:\([^)]*\)\s+)?(\S.*)$', line)
        if not m or 'PROGRAM TOTALS' in line:
            continue
        name = short_name(re.sub(r'^(\?\?\?|[^:]*\.(S|c|cc|h)):', '', m.group(3).strip()))  # without the file
        mb[name] += (int(m.group(1).replace(',', '')) + int(m.group(2).replace(',', ''))) * 64 / steps / 1e6
    return mb


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--build', default='build')
    ap.add_argument('--scale', type=float, default=0.25, help="bench_scale's pixel and Gaussian scale")
    ap.add_argument('--steps', type=int, default=2, help='timed steps (after one warm-up step per view)')
    ap.add_argument('--top', type=int, default=30)
    ap.add_argument('--plan-threads', type=int, default=0, help='cut the work that follows the thread count (the '
                    "object losses' bands, SSIM's bands) as for T threads while one runs (needs "
                    'libhgs_omp_regions.so beside bench_scale); 0: as for one')
    ap.add_argument('--methods', default='rgb,hybrid', help='the steps to simulate (rgb,hybrid; one alone halves '
                    'the time, its columns of the other are then 0)')
    ap.add_argument('--with-warmup', action='store_true', help="count bench_scale's warm-up steps too (their first "
                    'touches of the buffers)')
    a = ap.parse_args()
    binary = os.path.join(a.build, 'bench_scale')
    if not os.path.exists(binary):
        sys.exit(f'll_traffic: {binary} not found (build the benchmarks: scripts/build)')
    for tool in ('valgrind', 'callgrind_annotate'):
        if subprocess.run(['sh', '-c', f'command -v {tool}'], capture_output=True).returncode != 0:
            sys.exit(f'll_traffic: {tool} not found (Debian package valgrind)')
    for method in a.methods.split(','):
        if method not in ('rgb', 'hybrid'):
            sys.exit(f'll_traffic: --methods: {method!r} is not rgb or hybrid')
    if a.plan_threads > 0 and not os.path.exists(os.path.join(a.build, 'libhgs_omp_regions.so')):
        sys.exit(f'll_traffic: --plan-threads needs {a.build}/libhgs_omp_regions.so (built with the benchmarks)')
    has_timed = b'timed_step' in subprocess.run(['nm', '-C', binary], capture_output=True).stdout
    warm = a.with_warmup or not has_timed
    steps = a.steps + VIEWS if warm else a.steps
    toggle = 'hgs::train::Trainer::step()' if warm else 'hgs::bench::timed_step*'
    with tempfile.TemporaryDirectory() as tmp:
        res = {'rgb': {}, 'hybrid': {}}
        for method in a.methods.split(','):
            out = os.path.join(tmp, method + '.out')
            run(binary, method, a.scale, a.steps, out, a.plan_threads, toggle)
            res[method] = per_function(out, steps)
    h, r = res['hybrid'], res['rgb']
    cut = f', work cut as for {a.plan_threads} threads' if a.plan_threads > 0 else ''
    which = (f'{steps} steps, the {VIEWS} warm-up steps included' + ('' if a.with_warmup else
             ' (this bench_scale has no timed_step)')) if warm else f'{steps} timed steps'
    print(f'bench_scale at {a.scale}x pixels and Gaussians, one thread{cut}: MB per step past a 2 MiB private cache '
          f'(callgrind LL misses x 64 B, {which})')
    print(f"{'function':60s} {'hybrid':>8} {'RGB':>8} {'extra':>8}")
    both = len(a.methods.split(',')) > 1  # the hybrid's extra first; one method alone: its own figures first
    order = (lambda k: -(h.get(k, 0) - r.get(k, 0))) if both else (lambda k: -(h.get(k, 0) + r.get(k, 0)))
    for k in sorted(set(h) | set(r), key=order)[:a.top]:
        print(f'{k[:60]:60s} {h.get(k, 0):8.1f} {r.get(k, 0):8.1f} {h.get(k, 0) - r.get(k, 0):8.1f}')
    print(f"{'total':60s} {sum(h.values()):8.1f} {sum(r.values()):8.1f} {sum(h.values()) - sum(r.values()):8.1f}")


if __name__ == '__main__':
    main()
