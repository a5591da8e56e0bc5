#!/usr/bin/env python3
"""The re-validation's tables from `bench/revalidate.sh`'s run folder (issue 59, docs/ablation.md).

Reads every finished run of each group (OUT/ablate_<preset>_<noise>/<scene>/seed<N>/<row>/run.json) and prints, as
markdown:

1. per group, instances protocol, object mode: each scene's all-off and full mIoU and their mean;
2. per group, per noise level pooled over the presets (groups <preset>_<noise>) and for all groups pooled:
   full - all off and each component added to the other two (the full row minus the full row without it), per
   protocol and mode, and where the rows with one component were run each component alone (that row minus all
   off), with the 95 % interval paired by scene (seeds averaged
   within a scene first; n = scenes; Student's t with n - 1 degrees of freedom), the statistic of `hgs ablate`
   (src/eval/paired_stats.h, `paired_by_scene`);
3. per group: the full method's pixel mode (the default rule and the paper's map) against object mode.

Only scenes that have every row a difference needs are counted in it.

    python3 bench/revalidate_report.py OUT
"""
import glob
import json
import math
import os
import statistics
import sys

# Two-sided 95 % quantiles of Student's t, df = 1..30.
T95 = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
       2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042]
FULL, OFF = "of1_scl1_bro1", "of0_scl0_bro0"
WITHOUT = {"OF": "of0_scl1_bro1", "SCL": "of1_scl0_bro1", "BRO": "of1_scl1_bro0"}
ALONE = {"OF": "of1_scl0_bro0", "SCL": "of0_scl1_bro0", "BRO": "of0_scl0_bro1"}
KEYS = ["instances/object", "instances/pixel", "instances/pixel-paper-map", "3d-ovs/object", "3d-ovs/pixel",
        "3d-ovs/pixel-paper-map"]
NAMES = {"object": "object", "pixel": "pixel (default rule)", "pixel-paper-map": "pixel (the paper's map)"}


def t95(n):
    return T95[min(n - 1, len(T95)) - 1] if n >= 2 else float("nan")


def finished_runs(out):
    """(path, run) for every finished run on disk, OUT/ablate_<group>/<scene>/seed<N>/<row>/run.json, in path
    order; a placeholder (a run.json marked "placeholder", which makes `hgs ablate` skip a row) is left out."""
    for f in sorted(glob.glob(os.path.join(out, "ablate_*", "*", "seed*", "*", "run.json"))):
        with open(f) as fh:
            run = json.load(fh)
        if not run.get("placeholder"):
            yield f, run


def load(out):
    """{group: {scene: {row: {key: [mIoU percent per training seed]}}}} from every finished run on disk
    (finished_runs), so that rows asked in separate `hgs ablate` calls (whose ablation.json covers only the rows
    of the last call) are all counted."""
    groups = {}
    for f, run in finished_runs(out):
        row_dir = os.path.dirname(f)
        seed_dir = os.path.dirname(row_dir)
        scene_dir = os.path.dirname(seed_dir)
        group = os.path.basename(os.path.dirname(scene_dir)).replace("ablate_", "")
        scene, row = os.path.basename(scene_dir), os.path.basename(row_dir)
        for k, v in run.get("results", {}).items():
            if v.get("miou") is not None:
                groups.setdefault(group, {}).setdefault(scene, {}).setdefault(row, {}).setdefault(k, []).append(
                    100 * v["miou"])
    return groups


def diffs(scenes, key, a, b):
    """Per scene: mean over seeds of row a minus mean over seeds of row b (scenes with both)."""
    d = []
    for rows in scenes.values():
        if a in rows and b in rows and key in rows[a] and key in rows[b]:
            d.append(statistics.mean(rows[a][key]) - statistics.mean(rows[b][key]))
    return d


def cell(d):
    if not d:
        return "-"
    m = statistics.mean(d)
    if len(d) < 2:
        return f"{m:+.2f} (n = 1)"
    h = t95(len(d)) * statistics.stdev(d) / math.sqrt(len(d))
    clear = " **clear of 0**" if m - h > 0 else (" below 0" if m + h < 0 else "")
    return f"{m:+.2f} ± {h:.2f}{clear} (n = {len(d)})"


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip().splitlines()[-1].strip(), file=sys.stderr)
        sys.exit(2)
    groups = load(sys.argv[1])
    if not groups:
        sys.exit(f"revalidate_report: no ablate_*/<scene>/seed*/<row>/run.json under {sys.argv[1]}")
    print("## Instances, object mode: each scene\n\n| group | scene | all off | full | full - all off |\n|---|---|---|---|---|")
    for g, scenes in groups.items():
        fulls, offs = [], []
        for s, rows in scenes.items():
            f = statistics.mean(rows[FULL]["instances/object"]) if FULL in rows else None
            o = statistics.mean(rows[OFF]["instances/object"]) if OFF in rows else None
            fulls += [f] if f is not None else []
            offs += [o] if o is not None else []
            fmt = lambda v: f"{v:.2f}" if v is not None else "-"
            dd = f"{f - o:+.2f}" if f is not None and o is not None else "-"
            print(f"| {g} | {s} | {fmt(o)} | {fmt(f)} | {dd} |")
        print(f"| {g} | mean | {statistics.mean(offs) if offs else float('nan'):.2f} | "
              f"{statistics.mean(fulls) if fulls else float('nan'):.2f} | |")
    pooled = {f"{g}/{s}": rows for g, scenes in groups.items() for s, rows in scenes.items()}
    noises = sorted({g.rsplit("_", 1)[-1] for g in groups})
    by_noise = [(f"{n} noise, presets pooled", {k: v for k, v in pooled.items() if k.split("/")[0].endswith("_" + n)})
                for n in noises] if len(noises) > 1 else []
    for title, scenes_of in [(g, groups[g]) for g in groups] + by_noise + [("all groups pooled", pooled)]:
        print(f"\n## {title}: paired differences (mIoU points, 95 % interval paired by scene)\n")
        print("| protocol / mode | full - all off | OF added | SCL added | BRO added |\n|---|---|---|---|---|")
        for k in KEYS:
            proto, mode = k.split("/", 1)
            row = [cell(diffs(scenes_of, k, FULL, OFF))]
            row += [cell(diffs(scenes_of, k, FULL, WITHOUT[c])) for c in ("OF", "SCL", "BRO")]
            print(f"| {proto}, {NAMES[mode]} | " + " | ".join(row) + " |")
        if any(r in rows for rows in scenes_of.values() for r in ALONE.values()):
            print(f"\n## {title}: each component alone - all off (the rows with one component)\n")
            print("| protocol / mode | OF alone | SCL alone | BRO alone |\n|---|---|---|---|")
            for k in KEYS:
                proto, mode = k.split("/", 1)
                row = [cell(diffs(scenes_of, k, ALONE[c], OFF)) for c in ("OF", "SCL", "BRO")]
                print(f"| {proto}, {NAMES[mode]} | " + " | ".join(row) + " |")
    print("\n## The full method: pixel mode against object mode (mean over scenes, mIoU)\n")
    print("| group | protocol | object | pixel (default rule) | pixel - object | paper's map | paper's map - default rule |")
    print("|---|---|---|---|---|---|---|")
    for g, scenes in groups.items():
        for proto in ("instances", "3d-ovs"):
            v = {m: [statistics.mean(r[FULL][f"{proto}/{m}"]) for r in scenes.values()
                     if FULL in r and f"{proto}/{m}" in r[FULL]] for m in NAMES}
            if not all(v.values()):
                continue
            o, p, pm = (statistics.mean(v[m]) for m in ("object", "pixel", "pixel-paper-map"))
            print(f"| {g} | {proto} | {o:.2f} | {p:.2f} | {p - o:+.2f} | {pm:.2f} | {pm - p:+.2f} |")


if __name__ == "__main__":
    main()
