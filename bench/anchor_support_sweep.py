#!/usr/bin/env python3
"""`--anchor-support R` swept over the kept models of a `bench/revalidate.sh` run folder (issue 59,
docs/ablation.md, "The anchor's support, chosen on the development seeds").

The option changes only the instances protocol's object mode (3D-OVS object mode classifies every label and pixel
mode renders them all), so each model is evaluated there alone, once per R (0 = off), with `hgs eval`; the
evaluations are cached beside the run as OUT/anchor_sweep/<group>/<scene>/<row>/R.json. Prints, per group and row,
the mIoU at each R and its difference from off with the 95 % interval paired by scene (the statistic of
bench/revalidate_report.py), and every (scene, row) that falls at some R (by 0.01 or more).

    python3 bench/anchor_support_sweep.py HGS OUT R [R...]      # e.g. build/hgs dev-run 0.05 0.1 0.25
"""
import json
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from revalidate_report import cell, finished_runs  # noqa: E402  (the same run files and statistic)


def evaluate(hgs, scene, model, r, out):
    """instances object-mode mIoU (percent) of one model at anchor support r (0 = off), cached in out."""
    if not os.path.exists(out):
        os.makedirs(os.path.dirname(out), exist_ok=True)
        extra = ["--anchor-support", str(r)] if r > 0 else []
        subprocess.run([hgs, "eval", scene, model, "--protocol", "instances", "--mode", "object", "--no-png",
                        "--quiet", "--out", out + ".tmp.json"] + extra, check=True, stdout=subprocess.DEVNULL)
        os.replace(out + ".tmp.json", out)
        md = out + ".tmp.md"
        if os.path.exists(md):
            os.remove(md)
    with open(out) as fh:
        return 100 * json.load(fh)["reports"][0]["summary"]["mIoU"]


def main(hgs, out, rs):
    rs = [0.0] + [r for r in rs if r > 0]
    table = {}  # {group: {row: {scene: [mIoU per R]}}}
    for f, _ in finished_runs(out):
        row_dir = os.path.dirname(f)
        if not os.path.exists(os.path.join(row_dir, "point_cloud.ply")):
            continue  # a restored run without its model
        row = os.path.basename(row_dir)
        scene = os.path.basename(os.path.dirname(os.path.dirname(row_dir)))
        group = os.path.basename(os.path.dirname(os.path.dirname(os.path.dirname(row_dir)))).replace("ablate_", "")
        scene_dir = os.path.join(out, "scenes", scene)
        cache = os.path.join(out, "anchor_sweep", group, scene, row)
        table.setdefault(group, {}).setdefault(row, {})[scene] = [
            evaluate(hgs, scene_dir, row_dir, r, os.path.join(cache, f"{r:g}.json")) for r in rs]
    falls = []
    for group, rows in sorted(table.items()):
        print(f"\n{group}, instances object mode (mIoU; R - off with the 95 % interval paired by scene)\n")
        print("| row | scenes | off | " + " | ".join(f"R = {r:g}" for r in rs[1:]) + " |")
        print("|---|---|---|" + "---|" * (len(rs) - 1))
        for row, scenes in sorted(rows.items()):
            n = len(scenes)
            cells = [f"{sum(v[0] for v in scenes.values()) / n:.2f}"]
            for j in range(1, len(rs)):
                d = [v[j] - v[0] for v in scenes.values()]
                cells.append(f"{sum(v[j] for v in scenes.values()) / n:.2f}, {cell(d)}")
                falls += [(group, s, row, rs[j], v[j] - v[0]) for s, v in scenes.items() if v[j] - v[0] < -0.005]
            print(f"| {row} | {n} | " + " | ".join(cells) + " |")
    print("\nfalls (any scene and row that loses at some R):" + ("" if falls else " none"))
    for group, s, row, r, d in falls:
        print(f"  {s} {row} R = {r:g}: {d:+.2f}")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(os.path.realpath(sys.argv[1]), sys.argv[2], [float(x) for x in sys.argv[3:]])
