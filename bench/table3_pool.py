#!/usr/bin/env python3
"""Table 3's paired differences pooled over every (scene, training seed) pair measured so far.

The runs were made by `hgs ablate` in several sessions, on machines whose run folders are gone; their per-pair
mIoU is listed in docs/ablation.md and transcribed here (PAIRS), so the pooled tables of that file can be
recomputed and extended. The statistic is `hgs ablate`'s own (src/eval/paired_stats.h `paired_by_scene`): paired
by scene, seeds averaged within a scene. A pair's scene is its name without the training seed in brackets; each
scene's per-pair differences are averaged over its seeds first, and the mean and the half-width of the 95 %
interval are over the scenes (n = scenes, Student's t with n - 1 degrees of freedom): a scene's seeds share its
images, masks and features, so they are not independent runs.

The rows of one pair were not always trained on one machine (each session ran on the machine it was given, and
the single rows often came sessions after a pair's leave-one-out rows), and a pair's figures can move by a few
points between machines (docs/ablation.md, "OF alone on room s51"): the intervals include that spread.

Each pair: its noise level, name, and per row the mIoU (percent) of instances object / instances pixel /
3D-OVS object / 3D-OVS pixel (LangSplat's fixed windows, the `3d-ovs` protocol with the sky scored).

    python3 bench/table3_pool.py            # both noise levels, markdown tables
    python3 bench/table3_pool.py --show DIR...  # `hgs ablate` run folders: each run's figures, and PAIRS entries
"""
import json
import math
import sys

COLUMNS = ["inst. object", "inst. pixel", "3D-OVS object", "3D-OVS pixel"]
LOO = ["all off", "no OF", "no SCL", "no BRO", "full", "eq15"]  # --rows leave-one-out --eq15-row
MIDDLE = ["OF alone", "SCL alone", "BRO alone"]  # --rows middle


def row(s):
    return [float(x) for x in s.split("/")]


def pair(noise, name, loo, middle=None):
    rows = {r: row(s) for r, s in zip(LOO, loo)}
    if middle:
        rows.update({r: row(s) for r, s in zip(MIDDLE, middle)})
    return {"noise": noise, "name": name, "rows": rows}


PAIRS = [
    # medium noise: tabletop / room, seeds 51, 52, 53 (hgs synth --noise medium --width 160 --height 120 --views 32)
    pair("medium", "tabletop s51 (0)", ["70.64/65.72/62.80/12.78", "71.24/68.14/70.50/71.21", "92.60/77.28/76.71/23.52", "92.47/85.53/89.79/90.48", "92.64/85.72/89.82/90.41", "79.68/75.74/79.02/80.05"],
         ["92.59/77.31/76.46/23.81", "71.08/67.63/70.24/70.87", "72.27/68.81/64.57/13.14"]),
    pair("medium", "tabletop s52 (0)", ["38.33/42.06/32.28/13.57", "48.44/44.59/52.35/53.60", "88.69/73.71/75.91/14.81", "89.75/85.92/89.09/89.61", "89.80/86.08/89.12/89.59", "80.06/80.36/80.50/81.54"],
         ["86.29/70.34/72.99/14.79", "47.39/44.08/51.63/52.77", "40.09/41.76/37.34/13.25"]),
    pair("medium", "room s51 (0)", ["79.25/59.78/54.22/19.45", "77.62/69.01/69.11/69.35", "80.16/61.86/59.32/24.79", "84.18/77.54/73.79/73.99", "82.34/74.66/72.90/74.00", "77.80/73.11/70.23/69.56"],
         ["73.81/62.05/56.20/24.73", "76.24/69.61/68.04/68.61", "78.92/58.06/50.64/19.31"]),
    pair("medium", "room s52 (0)", ["53.96/48.35/44.89/19.37", "53.44/45.81/54.27/53.96", "79.27/63.93/58.98/19.57", "84.45/72.94/74.14/72.64", "83.96/71.48/73.97/72.27", "73.11/65.94/66.92/68.73"],
         ["77.57/62.36/57.49/19.55", "52.17/44.75/53.04/52.53", "53.82/48.60/44.99/19.56"]),
    pair("medium", "tabletop s51 (1)", ["70.95/63.16/64.09/13.30", "72.89/69.62/71.63/72.36", "92.55/77.36/76.62/23.35", "92.58/85.84/89.90/90.58", "92.57/85.83/89.70/90.45", "79.91/78.53/79.32/80.79"],
         ["92.68/76.96/76.75/22.97", "70.88/67.41/69.90/70.65", "71.46/68.10/64.60/13.18"]),
    pair("medium", "room s51 (1)", ["77.40/58.68/53.93/19.45", "77.36/69.68/68.68/68.57", "74.45/62.84/55.97/24.56", "82.48/74.91/72.56/73.74", "84.20/75.71/73.76/73.51", "80.73/74.15/71.29/69.64"],
         ["73.82/59.05/54.44/25.03", "76.32/69.26/67.92/68.10", "77.64/54.83/54.66/19.45"]),
    pair("medium", "tabletop s52 (1)", ["40.14/41.71/37.77/13.40", "47.23/45.12/51.55/52.57", "86.60/71.64/73.79/14.81", "90.27/86.00/89.18/89.73", "90.11/86.17/89.38/89.87", "79.90/80.18/80.23/81.60"],
         ["87.70/71.97/74.45/14.81", "46.48/43.77/50.84/52.06", "38.89/41.68/36.91/13.19"]),
    pair("medium", "room s52 (1)", ["54.89/46.13/42.21/19.56", "53.41/44.94/53.90/53.15", "77.02/63.38/57.30/19.55", "83.68/72.22/74.42/73.01", "83.92/70.20/74.02/72.17", "73.50/66.30/68.05/69.70"],
         ["77.06/64.28/57.21/19.55", "51.54/44.35/53.21/53.61", "55.31/49.76/45.60/19.42"]),
    pair("medium", "tabletop s53 (0)", ["68.07/65.34/69.34/13.56", "68.92/69.65/72.94/73.61", "84.02/79.09/77.81/15.43", "86.97/85.85/92.37/92.05", "86.99/85.85/92.37/91.89", "80.56/84.05/84.74/85.46"],
         ["83.72/78.61/78.07/15.42", "68.32/69.02/72.64/73.46", "68.90/67.13/70.35/13.59"]),
    pair("medium", "room s53 (0)", ["63.52/53.24/42.78/20.48", "63.32/56.71/50.43/51.00", "76.74/71.51/51.97/25.23", "83.17/79.38/61.84/61.74", "82.75/78.93/61.20/61.29", "76.72/76.35/57.85/59.35"],
         ["75.29/67.47/50.86/25.56", "61.62/57.09/49.41/50.14", "65.75/57.56/44.10/20.69"]),
    # session of 2026-11-28: all 8 rows and eq. 15 (--rows all --eq15-row)
    pair("medium", "tabletop s53 (1)", ["68.71/67.70/70.31/13.70", "68.43/70.25/72.51/73.36", "84.85/79.45/79.41/15.39", "87.73/86.05/92.84/92.44", "86.92/85.85/91.56/91.11", "79.43/82.24/84.05/84.91"],
         ["84.59/78.26/79.07/15.42", "67.67/68.16/72.05/73.01", "68.75/67.36/70.41/13.60"]),
    pair("medium", "room s53 (1)", ["61.79/55.62/43.46/20.82", "62.95/56.63/50.10/51.08", "75.55/68.58/51.34/25.55", "78.03/79.61/61.74/61.72", "82.61/79.00/61.25/61.36", "76.95/78.90/58.55/59.81"],
         ["79.05/69.98/51.90/27.33", "61.83/56.86/49.41/50.27", "63.64/57.73/43.73/20.83"]),
    # high noise (hgs synth --noise high): th = tabletop, rh = room
    pair("high", "th_s8081 (6029)", ["42.71/40.88/45.32/13.33", "42.96/43.62/50.16/50.34", "63.31/73.06/62.96/14.45", "72.05/85.85/88.60/88.39", "77.22/86.38/89.06/88.61", "71.89/84.17/83.13/83.06"],
         ["62.65/73.73/62.28/14.46", "41.41/41.29/47.89/47.99", "44.80/43.31/47.69/13.24"]),
    pair("high", "rh_s8083 (0)", ["47.06/46.56/46.76/24.67", "49.62/46.96/52.81/53.33", "63.81/64.52/54.74/24.86", "70.79/72.67/70.16/70.17", "71.31/70.57/70.00/69.56", "64.99/68.09/63.37/65.78"],
         ["64.04/64.19/54.95/24.82", "47.61/46.27/52.07/52.24", "46.42/43.68/46.79/24.58"]),
    pair("high", "th_s8085 (0)", ["67.93/65.09/66.51/13.28", "67.43/67.52/69.05/70.62", "77.19/72.41/72.29/15.31", "84.53/85.47/89.11/91.05", "84.23/85.51/89.41/91.01", "79.88/77.03/81.72/82.12"],
         ["77.63/71.87/72.52/15.14", "67.37/66.26/68.42/69.76", "64.62/65.06/56.45/13.22"]),
    pair("high", "th_s8081 (1)", ["43.84/41.56/44.68/13.17", "42.59/42.16/49.32/49.33", "62.65/73.98/62.40/14.44", "75.39/84.13/87.11/86.65", "76.10/86.03/88.39/87.71", "66.45/78.15/78.74/79.24"],
         ["62.28/72.74/62.16/14.46", "41.73/41.75/48.40/48.55", "31.72/42.06/39.79/13.48"]),
    pair("high", "rh_s8083 (1)", ["45.10/46.56/46.05/24.52", "49.22/44.94/52.76/53.25", "63.14/63.96/53.96/24.91", "70.96/72.15/69.79/69.54", "70.74/72.73/70.09/69.84", "64.21/69.45/62.90/65.37"],
         ["63.60/60.65/55.04/24.76", "48.82/46.90/50.46/51.55", "47.90/45.03/46.83/24.62"]),
    pair("high", "th_s8085 (1)", ["67.85/64.03/66.69/13.30", "66.16/65.82/67.86/68.95", "78.02/72.27/72.90/15.25", "85.16/85.51/89.20/90.98", "84.69/84.97/89.34/90.81", "80.04/79.96/82.00/82.29"],
         ["76.07/72.53/72.27/15.29", "66.79/66.59/68.73/69.67", "67.14/64.57/67.19/13.49"]),
    # session of 2026-11-28, later: a second high-noise room (hgs synth --preset room --noise high --seed 8087)
    pair("high", "rh_s8087 (0)", ["51.98/50.99/33.99/13.63", "36.20/35.33/43.99/41.96", "59.18/55.31/48.94/19.73", "76.91/73.88/72.37/64.90", "76.43/73.76/71.31/67.73", "69.55/73.48/66.41/61.92"],
         ["58.29/53.17/48.15/19.69", "35.38/35.34/42.92/38.31", "51.48/52.15/44.57/19.01"]),
    pair("high", "rh_s8087 (1)", ["50.82/46.93/41.18/18.64", "27.42/35.04/38.22/37.84", "59.67/55.31/49.09/19.74", "78.87/75.08/72.62/67.92", "67.78/70.26/64.38/63.94", "70.59/71.43/66.78/61.64"],
         ["59.42/53.28/47.78/19.71", "35.03/33.75/41.81/41.51", "51.29/45.70/38.18/19.10"]),
    # session of 2026-11-28, evening: a third high-noise scene per preset (hgs synth --noise high --seed 8089
    # --preset tabletop, --seed 8091 --preset room); the single rows on training seed 0
    pair("high", "th_s8089 (0)", ["37.74/49.38/39.52/14.46", "47.61/51.72/58.30/59.36", "73.16/76.79/71.90/14.90", "73.02/82.94/87.64/87.82", "72.90/83.07/87.36/87.21", "67.94/80.91/80.98/81.98"],
         ["73.16/75.67/71.99/14.90", "47.50/51.73/58.41/59.24", "47.40/50.73/45.33/14.22"]),
    pair("high", "rh_s8091 (0)", ["31.10/26.67/31.97/22.90", "32.04/25.84/43.37/43.39", "75.43/70.87/58.64/23.90", "78.66/71.51/76.05/73.92", "77.70/73.79/73.40/72.38", "72.62/73.69/71.26/71.71"],
         ["75.26/70.68/59.37/23.82", "30.12/24.00/41.12/40.52", "31.76/24.95/30.99/23.10"]),
    pair("high", "th_s8089 (1)", ["38.26/49.30/39.57/13.79", "46.92/51.81/57.48/58.45", "72.86/75.76/70.56/14.83", "73.05/82.73/87.60/87.32", "73.04/83.24/87.46/87.32", "67.94/80.49/81.08/81.91"],
         ["72.94/76.27/71.56/14.90", "47.10/51.42/58.30/58.92", "47.67/51.00/45.01/14.01"]),
    pair("high", "rh_s8091 (1)", ["28.54/28.12/30.24/23.13", "30.61/23.57/40.44/39.83", "76.96/74.30/61.31/23.84", "78.10/72.21/72.83/71.50", "78.69/71.86/75.59/73.22", "72.51/74.18/71.29/72.06"],
         ["75.52/71.18/58.35/23.88", "30.54/26.16/43.55/44.67", "32.62/28.44/31.35/23.24"]),
]

T975 = [12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
        2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042]


def scene_of(p):
    """A pair's scene: its name without the training seed, e.g. "room s51 (1)" -> "room s51"."""
    return p["name"].rsplit(" (", 1)[0]


def paired_by_scene(d):
    """d: [(scene, difference)] one per (scene, seed). Each scene's differences averaged over its seeds, then the
    mean over the scenes and the half-width of its 95 % interval (Student's t, n - 1 degrees of freedom, n =
    scenes; NaN with one scene). Returns (mean, half-width, scenes, runs)."""
    by_scene = {}
    for scene, x in d:
        by_scene.setdefault(scene, []).append(x)
    means = [sum(v) / len(v) for v in by_scene.values()]
    n = len(means)
    m = sum(means) / n
    if n < 2:
        return m, float("nan"), n, len(d)
    sd = math.sqrt(sum((x - m) ** 2 for x in means) / (n - 1))
    t = T975[n - 2] if n - 1 <= 30 else 1.96
    return m, t * sd / math.sqrt(n), n, len(d)


# Every row minus all off, each component added to the other two (full minus the row without it), and eq. 15.
DIFFS = ([(f"{r} - all off", r, "all off") for r in ["full", *MIDDLE, "no OF", "no SCL", "no BRO"]]
         + [(f"{c} added to the other two", "full", f"no {c}") for c in ("OF", "SCL", "BRO")]
         + [("eq. 15 alone - full", "eq15", "full")])


def middle_rows(pairs):
    """Each pair's single-component rows minus its all-off row (the pairs that have them)."""
    have = [p for p in pairs if "OF alone" in p["rows"]]
    if not have:
        return
    print("| pair | " + " | ".join(f"{r} - all off" for r in MIDDLE) + " |")
    print("|---|" + "---|" * len(MIDDLE))
    for p in have:
        off = p["rows"]["all off"]
        cells = [" / ".join(f"{p['rows'][r][c] - off[c]:+.2f}" for c in range(len(COLUMNS))) for r in MIDDLE]
        print(f"| {p['name']} ({p['noise']}) | " + " | ".join(cells) + " |")
    print()


def table(pairs, title):
    scenes = len({scene_of(p) for p in pairs})
    print(f"### {title}: {scenes} scenes, {len(pairs)} pairs (paired by scene, seeds averaged within a scene; "
          "n = scenes)\n")
    print("| difference | scenes | pairs | " + " | ".join(COLUMNS) + " |")
    print("|---|---|---|" + "---|" * len(COLUMNS))
    for name, a, b in DIFFS:
        have = [p for p in pairs if a in p["rows"] and b in p["rows"]]
        if not have:
            continue
        cells = []
        for c in range(len(COLUMNS)):
            m, h, n, _ = paired_by_scene([(scene_of(p), p["rows"][a][c] - p["rows"][b][c]) for p in have])
            cells.append(f"{m:+.2f} ± {h:.2f}" if n > 1 else f"{m:+.2f}")
        print(f"| {name} | {len({scene_of(p) for p in have})} | {len(have)} | " + " | ".join(cells) + " |")
    above = sum(p["rows"]["full"][c] > p["rows"]["all off"][c] for p in pairs for c in range(len(COLUMNS)))
    print(f"\nfull above all off in {above} of {len(COLUMNS) * len(pairs)} cells; pairs: "
          + ", ".join(p["name"] for p in pairs) + "\n")


KEYS = ["instances/object", "instances/pixel", "3d-ovs/object", "3d-ovs/pixel"]  # COLUMNS in ablation.json
ROW_NAMES = {"of0_scl0_bro0": "all off", "of0_scl1_bro1": "no OF", "of1_scl0_bro1": "no SCL", "of1_scl1_bro0": "no BRO",
             "of1_scl1_bro1": "full", "of1_scl1_bro1_eq15": "eq15", "of1_scl0_bro0": "OF alone",
             "of0_scl1_bro0": "SCL alone", "of0_scl0_bro1": "BRO alone"}  # hgs ablate's row names -> LOO / MIDDLE


def show(folders):
    """Each run of `hgs ablate` folders (ablation.json) as the row strings of PAIRS, and for every (scene, seed)
    whose leave-one-out rows are all there, its PAIRS entry (noise left as NOISE to fill in)."""
    rows = {}  # (scene, seed) -> {row name: "a/b/c/d"}
    for folder in folders:
        with open(f"{folder}/ablation.json") as f:
            runs = json.load(f)["runs"]
        for r in runs:
            res = r["run"]["results"]
            cells = [f"{100 * res[k]['miou']:.2f}" if k in res and res[k]["miou"] is not None else "nan"
                     for k in KEYS]
            print(f"{r['scene']} seed {r['seed']} {r['row']}: \"{'/'.join(cells)}\"")
            rows.setdefault((r["scene"], r["seed"]), {})[ROW_NAMES.get(r["row"], r["row"])] = "/".join(cells)
    for (scene, seed), have in rows.items():
        if not all(r in have for r in LOO):
            continue
        loo = ", ".join(f'"{have[r]}"' for r in LOO)
        middle = (", [" + ", ".join(f'"{have[r]}"' for r in MIDDLE) + "]") if all(r in have for r in MIDDLE) else ""
        print(f'    pair("NOISE", "{scene} ({seed})", [{loo}]{middle}),')


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "--show":
        show(sys.argv[2:])
        sys.exit(0)
    for noise in ("medium", "high"):
        table([p for p in PAIRS if p["noise"] == noise], f"{noise} noise")
    print("### The single-component rows, per pair (" + " / ".join(COLUMNS) + ")\n")
    middle_rows(PAIRS)
