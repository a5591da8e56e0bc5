#!/usr/bin/env python3
"""The one-thread step alone and beside copies of itself (bench/run_steps_multicore.sh's last part), per part.

Reads OUT/shared_<method>_alone.json and OUT/shared_<method>_copy<i>.json (bench_scale JSON lines) and prints, for
the RGB and the hybrid step and each of their parts, the time alone, the median over the copies that ran at once
(one per core) and their ratio. Every copy does the work of the one alone, so a ratio above 1 is what the cores
share (memory bandwidth, the L3, the clock with every core busy) costing that part; a part that scales worse than
bench/project_threads.py projects and also slows here is bound by those, not by its tasks.

  bench/shared_report.py /tmp/steps_multicore
"""
import glob
import json
import os
import statistics
import sys

PARTS = ['forward', 'backward', 'method_loss', 'method_ms_app_boxes', 'method_ms_app_pieces', 'method_ms_app_finish',
         'method_ms_app_scatter', 'loss', 'prepare', 'param_grads', 'update']


def load(path):
    with open(path) as f:
        lines = [l for l in f if l.startswith('{')]
    return json.loads(lines[-1]) if lines else None


def main():
    if len(sys.argv) != 2:
        sys.exit('usage: bench/shared_report.py OUT')
    out = sys.argv[1]
    for method in ('rgb', 'hybrid'):
        alone_path = os.path.join(out, f'shared_{method}_alone.json')
        alone = load(alone_path) if os.path.exists(alone_path) else None
        copies = [c for c in (load(p) for p in sorted(glob.glob(os.path.join(out, f'shared_{method}_copy*.json')))) if c]
        if not alone or not copies:
            print(f'{method}: no results in {out}')
            continue
        size = f"{alone['width']}x{alone['height']} / {alone['gaussians']}"
        print(f'{method} step at one thread, {size}: alone, and the median of {len(copies)} copies at once')
        print(f"  {'part':24s} {'alone ms':>9} {'copies ms':>10} {'ratio':>6}")
        rows = [('step (median)', alone['ms_median'], statistics.median(c['ms_median'] for c in copies))]
        for p in PARTS:
            if alone['parts_ms'].get(p, 0) >= 0.05:
                rows.append((p, alone['parts_ms'][p], statistics.median(c['parts_ms'].get(p, 0) for c in copies)))
        for name, a, c in rows:
            print(f'  {name:24s} {a:9.1f} {c:10.1f} {c / a:6.2f}')


if __name__ == '__main__':
    main()
