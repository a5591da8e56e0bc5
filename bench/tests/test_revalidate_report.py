"""bench/revalidate_report.py on a made-up run folder: rows asked in separate `hgs ablate` calls are all counted
(every run.json on disk, not the last call's ablation.json), and the rows with one component give the
"alone - all off" table with the interval paired by scene."""
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPORT = os.path.join(HERE, "..", "revalidate_report.py")
sys.path.insert(0, os.path.join(HERE, ".."))
from revalidate_report import t95  # noqa: E402


def write_run(out, group, scene, row, miou, placeholder=False):
    d = os.path.join(out, f"ablate_{group}", scene, "seed3", row)
    os.makedirs(d)
    results = {k: {"acc": 1.0, "miou": miou, "mbiou": miou, "records": 10}
               for k in ("instances/object", "3d-ovs/object")}
    with open(os.path.join(d, "run.json"), "w") as f:
        json.dump({"iters": 1500, "results": results, **({"placeholder": True} if placeholder else {})}, f)


def test_alone_rows_from_separate_calls_are_paired_by_scene():
    off = [0.50, 0.60, 0.70]
    of_alone = [0.58, 0.61, 0.79]  # differences 8, 1, 9 points
    with tempfile.TemporaryDirectory() as out:
        for i, (o, a) in enumerate(zip(off, of_alone)):
            s = f"room_medium_{i}"
            write_run(out, "room_medium", s, "of0_scl0_bro0", o)
            write_run(out, "room_medium", s, "of1_scl0_bro0", a)
            write_run(out, "room_medium", s, "of1_scl1_bro1", o + 0.1)
        # A placeholder (a row held back from training) must not count as a scene's figures.
        write_run(out, "room_medium", "room_medium_9", "of0_scl0_bro0", 0.0)
        write_run(out, "room_medium", "room_medium_9", "of1_scl1_bro1", 0.0, placeholder=True)
        # A stale ablation.json naming only one row must not hide the others.
        with open(os.path.join(out, "ablate_room_medium", "ablation.json"), "w") as f:
            json.dump({"runs": []}, f)
        text = subprocess.run([sys.executable, REPORT, out], check=True, capture_output=True, text=True).stdout
    d = [100 * (a - o) for o, a in zip(off, of_alone)]
    h = t95(3) * statistics.stdev(d) / math.sqrt(3)
    alone = [line for line in text.splitlines() if line.startswith("| instances, object |") and "(n = 3)" in line]
    assert any(f"+{statistics.mean(d):.2f} ± {h:.2f} (n = 3)" in line for line in alone), text
    assert "each component alone - all off" in text
    full_minus_off = "+10.00 ± 0.00 **clear of 0** (n = 3)"
    assert full_minus_off in text, text


def test_no_runs_is_an_error_naming_the_folder():
    with tempfile.TemporaryDirectory() as out:
        r = subprocess.run([sys.executable, REPORT, out], capture_output=True, text=True)
    assert r.returncode != 0 and out in r.stderr


if __name__ == "__main__":
    test_alone_rows_from_separate_calls_are_paired_by_scene()
    test_no_runs_is_an_error_naming_the_folder()
    print("ok")
