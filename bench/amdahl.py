#!/usr/bin/env python3
"""Per-phase scaling of a training step and its Amdahl projection to more threads (docs/performance.md).

Reads the JSON of a bench_hybrid run at 1 and 2 threads (the step benchmarks report the mean ms of each part of
the step as counters ms_<part>) and prints, per part, the 1- and 2-thread times, the speed-up, the parallel
fraction p that speed-up implies under Amdahl's law (S_2 = 1 / ((1 - p) + p / 2), so p = 2 (1 - 1 / S_2)), and
the part's projected time at each target thread count; then the step's projected totals. Medians over the
repetitions when the run has them.

  HGS_BENCH_THREADS=1,2 build/bench_hybrid --benchmark_filter='BM_RgbStep|BM_HybridStep/objects_per_step:0/sparse:1' \\
      --benchmark_repetitions=5 --benchmark_enable_random_interleaving=true --benchmark_out=steps.json
  bench/amdahl.py steps.json --threads 16

or from the step as `hgs train` runs it (bench/train_steps.sh at THREADS=1 and 2; each run leaves its
train_stats.json, median ms per iteration and mean ms per part):
  bench/amdahl.py run_t1/train_stats.json run_t2/train_stats.json --threads 16 [--median]

The projection is an upper bound of what the 2-thread figures allow: it assumes a part's serial share stays
serial and its parallel share divides perfectly, and ignores memory bandwidth and the barriers of more threads.
Where the run also measured a target thread count (HGS_BENCH_THREADS=1,2,4,8,16 on a machine with the cores),
each projected column is followed by the measured one ("meas.").
"""
import argparse
import json
import re
import statistics
import sys
from collections import defaultdict


def parse_train_stats(data, path, rows, median=False):
    """One `hgs train` run's train_stats.json: its thread count, mean ms per iteration and per part (the mean, so
    that the parts add up to the step; the median step leaves out the slow steps the means include), or with
    median the median step and each part's median over the steps (median_ms_per_part: robust to steps a busy
    machine slowed, and to a short run's first steps; the parts need not add up to the step)."""
    threads = data.get("threads")
    if not isinstance(threads, int) or threads < 1:
        sys.exit(f"{path}: train_stats.json without a thread count")
    if median and "median_ms_per_part" not in data:
        sys.exit(f"{path}: train_stats.json without median_ms_per_part (written by hgs train since 2026-12-07)")
    key = (f"hgs train, {data.get('num_gaussians', '?')} Gaussians", threads)
    rows[key]["step"].append(float(data["median_ms_per_iter" if median else "mean_ms_per_iter"]))
    for k, v in data["median_ms_per_part" if median else "mean_ms_per_part"].items():
        if isinstance(v, (int, float)) and v > 0:
            rows[key][k].append(float(v))


def parse(paths, median=False):
    """{(benchmark family, threads): {counter: [values]}} from Google Benchmark's JSON (iteration rows only), or
    from `hgs train` runs' train_stats.json (one row per file: bench/train_steps.sh at THREADS=1 and 2)."""
    rows = defaultdict(lambda: defaultdict(list))
    for path in paths:
        with open(path) as f:
            data = json.load(f)
        if "mean_ms_per_part" in data:
            parse_train_stats(data, path, rows, median)
        else:
            parse_benchmarks(data, rows)
    return rows


def parse_benchmarks(data, rows):
    for b in data.get("benchmarks", []):
        if b.get("run_type") == "aggregate":
            continue
        name = b["name"]
        m = re.search(r"/threads:(\d+)", name)
        if not m:
            continue
        family = re.sub(r"/threads:\d+", "", name).replace("/real_time", "")
        key = (family, int(m.group(1)))
        unit = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}[b.get("time_unit", "ns")]
        rows[key]["step"].append(b["real_time"] * unit)
        for k, v in b.items():
            if k.startswith("ms_") and isinstance(v, (int, float)):
                rows[key][k[3:]].append(float(v))


def project(t1, t2, n):
    """Amdahl: time at n threads from the 1- and 2-thread times (p clamped to [0, 1])."""
    if t1 <= 0:
        return 0.0, 0.0
    s2 = t1 / t2 if t2 > 0 else 2.0
    p = min(1.0, max(0.0, 2.0 * (1.0 - 1.0 / s2)))
    return p, t1 * ((1.0 - p) + p / n)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("json", nargs="+", help="Google Benchmark JSON (--benchmark_out) of a run at 1 and 2 threads, "
                    "or the train_stats.json of `hgs train` runs at 1 and 2 threads (--threads)")
    ap.add_argument("--threads", type=int, nargs="+", default=[16], help="thread counts to project to")
    ap.add_argument("--median", action="store_true",
                    help="train_stats.json inputs: the median step and each part's median instead of the means")
    ap.add_argument("--min-share", type=float, default=0.0,
                    help="list only the parts above this share of the 1-thread step (e.g. 0.05)")
    a = ap.parse_args()
    rows = parse(a.json, a.median)
    families = sorted({f for f, _ in rows})
    if not families:
        sys.exit(f"{' '.join(a.json)}: no benchmark with a threads argument")
    for fam in families:
        if (fam, 1) not in rows or (fam, 2) not in rows:
            print(f"{fam}: needs both 1 and 2 threads, skipped")
            continue
        r1, r2 = rows[(fam, 1)], rows[(fam, 2)]
        med = lambda r, k: statistics.median(r[k]) if r.get(k) else 0.0
        step1, step2 = med(r1, "step"), med(r2, "step")
        parts = [k for k in r1 if k != "step" and k in r2 and not k.startswith("method_loss_")]
        print(f"\n{fam}: step {step1:.2f} ms at 1 thread, {step2:.2f} ms at 2 ({step1 / step2:.2f}x)")
        measured = {n: rows[(fam, n)] for n in a.threads if (fam, n) in rows}
        head = "| part | 1 thr ms | 2 thr ms | speed-up | parallel p |" + "".join(
            f" {n} thr ms |" + (f" {n} thr meas. |" if n in measured else "") for n in a.threads)
        print(head)
        print("|---" * (5 + len(a.threads) + len(measured)) + "|")
        totals = defaultdict(float)
        rest = lambda r: med(r, "step") - sum(med(r, k) for k in parts)
        for k in parts + ["(rest of the step)"]:
            part = (lambda r: rest(r)) if k == "(rest of the step)" else (lambda r, k=k: med(r, k))
            t1, t2 = part(r1), part(r2)
            p, _ = project(t1, t2, 2)
            proj = [project(t1, t2, n)[1] for n in a.threads]
            for n, t in zip(a.threads, proj):
                totals[n] += t
            if t1 < a.min_share * step1:
                continue
            sp = f"{t1 / t2:.2f}x" if t2 > 0 else "-"
            cols = "".join(f" {t:.2f} |" + (f" {part(measured[n]):.2f} |" if n in measured else "")
                           for n, t in zip(a.threads, proj))
            print(f"| {k} | {t1:.2f} | {t2:.2f} | {sp} | {p:.3f} |" + cols)
        for n in a.threads:
            line = f"projected step at {n} threads: {totals[n]:.2f} ms ({step1 / totals[n]:.1f}x the 1-thread step)"
            if n in measured:
                t = med(measured[n], "step")
                line += f"; measured {t:.2f} ms ({step1 / t:.1f}x)"
            print(line)


if __name__ == "__main__":
    main()
