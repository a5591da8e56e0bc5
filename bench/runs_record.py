#!/usr/bin/env python3
"""The finished runs of a `bench/revalidate.sh` folder as one small JSON record, and back (issue 59).

A re-validation takes hours of training on 2 cores, and a session's scratch folders do not outlive it. `save`
writes every OUT/ablate_<group>/<scene>/seed<N>/<row>/run.json (the row's figures, not its model) into RECORD,
keyed by its path under OUT; `restore` writes them back under a new OUT, where `hgs ablate` reuses each one
instead of training the row again (a run.json with the same iterations, protocols and modes is enough) and
bench/revalidate_report.py reads them. Rows restored this way have no model: `--reevaluate` and the query sets
skip them.

    python3 bench/runs_record.py save OUT RECORD.json [NOTE]
    python3 bench/runs_record.py restore RECORD.json OUT
"""
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from revalidate_report import finished_runs  # noqa: E402  (the same run files the report reads)


def save(out, record, note=""):
    runs = {os.path.relpath(f, out): run for f, run in finished_runs(out)}
    if not runs:
        sys.exit(f"runs_record: no ablate_*/<scene>/seed*/<row>/run.json under {out}")
    tmp = record + ".tmp"
    with open(tmp, "w") as fh:
        json.dump({"note": note, "runs": runs}, fh, indent=1, sort_keys=True)
        fh.write("\n")
    os.replace(tmp, record)
    print(f"runs_record: {len(runs)} runs -> {record}")


def restore(record, out):
    with open(record) as fh:
        runs = json.load(fh)["runs"]
    written = 0
    for rel, run in runs.items():
        if os.path.isabs(rel) or ".." in rel.split(os.sep):
            sys.exit(f"runs_record: {record}: path {rel!r} leaves the output folder")
        f = os.path.join(out, rel)
        if os.path.exists(f):
            continue
        os.makedirs(os.path.dirname(f), exist_ok=True)
        with open(f + ".tmp", "w") as fh:
            json.dump(run, fh, indent=2)
        os.replace(f + ".tmp", f)
        written += 1
    print(f"runs_record: {written} of {len(runs)} runs written under {out} (the others were there)")


if __name__ == "__main__":
    if len(sys.argv) >= 4 and sys.argv[1] == "save":
        save(sys.argv[2], sys.argv[3], sys.argv[4] if len(sys.argv) > 4 else "")
    elif len(sys.argv) == 4 and sys.argv[1] == "restore":
        restore(sys.argv[2], sys.argv[3])
    else:
        print(__doc__.strip().splitlines()[-2].strip() + "\n" + __doc__.strip().splitlines()[-1].strip(),
              file=sys.stderr)
        sys.exit(2)
