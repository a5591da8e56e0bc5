"""bench/amdahl.py on made-up train_stats.json files: the projection from the means, from the medians with
--median, and a one-line refusal of --median on a run that has no per-part medians."""
import json
import os
import subprocess
import sys
import tempfile

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "amdahl.py")


def stats(threads, mean, median, with_median=True):
    d = {"threads": threads, "num_gaussians": 1000, "mean_ms_per_iter": sum(mean.values()),
         "median_ms_per_iter": sum(median.values()), "mean_ms_per_part": mean}
    if with_median:
        d["median_ms_per_part"] = median
    return d


def run(paths, *extra):
    return subprocess.run([sys.executable, TOOL, *paths, "--threads", "4", *extra], capture_output=True, text=True)


def row(out, part):
    for line in out.splitlines():
        cells = [c.strip() for c in line.split("|")]
        if len(cells) > 2 and cells[1] == part:
            return cells
    raise AssertionError(f"no row {part} in:\n{out}")


def test_means_and_medians():
    with tempfile.TemporaryDirectory() as tmp:
        # forward: perfectly parallel in the medians (100 -> 50), half serial in the means (100 -> 75, a slowed
        # step); backward serial both ways.
        runs = [stats(1, {"forward": 100.0, "backward": 40.0}, {"forward": 100.0, "backward": 40.0}),
                stats(2, {"forward": 75.0, "backward": 40.0}, {"forward": 50.0, "backward": 40.0})]
        paths = []
        for i, d in enumerate(runs):
            paths.append(os.path.join(tmp, f"t{i}.json"))
            json.dump(d, open(paths[-1], "w"))
        mean = run(paths)
        assert mean.returncode == 0, mean.stderr
        # p = 2 (1 - 75 / 100) = 0.5: at 4 threads 100 (0.5 + 0.5 / 4) = 62.5
        assert row(mean.stdout, "forward")[5] == "0.500" and row(mean.stdout, "forward")[6] == "62.50", mean.stdout
        med = run(paths, "--median")
        assert med.returncode == 0, med.stderr
        assert row(med.stdout, "forward")[5] == "1.000" and row(med.stdout, "forward")[6] == "25.00", med.stdout
        assert row(med.stdout, "backward")[6] == "40.00", med.stdout
        # A run written before the medians existed: --median refuses it in one line naming the file.
        json.dump(stats(2, runs[1]["mean_ms_per_part"], {}, with_median=False), open(paths[1], "w"))
        old = run(paths, "--median")
        assert old.returncode != 0 and paths[1] in old.stderr and "median_ms_per_part" in old.stderr, old.stderr
        assert run(paths).returncode == 0


if __name__ == "__main__":
    test_means_and_medians()
    print("ok")
