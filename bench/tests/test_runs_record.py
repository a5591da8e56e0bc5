"""bench/runs_record.py: a run folder's run.json files saved into one record and restored under a new folder as
they were; placeholders are not saved; a record whose paths leave the folder is refused."""
import json
import os
import subprocess
import sys
import tempfile

TOOL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "runs_record.py")


def run(*args, check=True):
    return subprocess.run([sys.executable, TOOL, *args], check=check, capture_output=True, text=True)


def test_save_then_restore_gives_the_same_run_files():
    with tempfile.TemporaryDirectory() as tmp:
        out, back, rec = os.path.join(tmp, "out"), os.path.join(tmp, "back"), os.path.join(tmp, "rec.json")
        runs = {"ablate_room_medium/room_medium_1/seed3/of0_scl0_bro0/run.json": {"iters": 1500, "results": {"a": 1}},
                "ablate_room_medium/room_medium_1/seed3/of1_scl1_bro1/run.json": {"iters": 1500, "results": {"a": 2}}}
        for rel, r in runs.items():
            os.makedirs(os.path.dirname(os.path.join(out, rel)))
            json.dump(r, open(os.path.join(out, rel), "w"))
        skipped = "ablate_room_medium/room_medium_2/seed3/of1_scl1_bro1/run.json"
        os.makedirs(os.path.dirname(os.path.join(out, skipped)))
        json.dump({"iters": 1500, "placeholder": True, "results": {}}, open(os.path.join(out, skipped), "w"))
        run("save", out, rec, "a note")
        assert json.load(open(rec))["note"] == "a note"
        run("restore", rec, back)
        for rel, r in runs.items():
            assert json.load(open(os.path.join(back, rel))) == r
        assert not os.path.exists(os.path.join(back, skipped))


def test_a_record_leaving_the_folder_is_refused():
    with tempfile.TemporaryDirectory() as tmp:
        rec = os.path.join(tmp, "rec.json")
        json.dump({"note": "", "runs": {"../escape/run.json": {"iters": 1}}}, open(rec, "w"))
        r = run("restore", rec, os.path.join(tmp, "out"), check=False)
        assert r.returncode != 0 and "leaves the output folder" in r.stderr
        assert not os.path.exists(os.path.join(tmp, "escape"))


if __name__ == "__main__":
    test_save_then_restore_gives_the_same_run_files()
    test_a_record_leaving_the_folder_is_refused()
    print("ok")
