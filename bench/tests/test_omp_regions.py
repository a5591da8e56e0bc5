"""bench/omp_regions (the LD_PRELOAD library of bench/project_threads.py) on a program of known regions
(bench/omp_regions/regions_demo.cpp): the chunks of a dynamic loop, their makespan handed to 2 and 4 threads, the
serial gap after a region and a `single` block's time, within the sleeps' tolerance (a sleep never ends early; a
busy machine may end it late); and its wall-time mode (HGS_REGIONS_WALL=1) at two threads.
Usage: test_omp_regions.py LIBRARY DEMO."""
import glob
import os
import subprocess
import sys
import tempfile


def main(lib, demo):
    with tempfile.TemporaryDirectory() as tmp:
        prefix = os.path.join(tmp, "regions")
        env = dict(os.environ, LD_PRELOAD=os.path.abspath(lib), HGS_REGIONS_OUT=prefix, OMP_NUM_THREADS="1")
        subprocess.run([os.path.abspath(demo)], env=env, check=True)
        files = glob.glob(prefix + ".*")
        assert len(files) == 1, files
        rows = [line.split() for line in open(files[0])]
    assert len(rows) == 2, rows  # two regions, in the order they first ran
    first, second = rows
    ms = lambda x: float(x) * 1e3
    late = 25  # ms a loaded machine may add to one sleep
    # offset calls seconds single dynamic chunks makespan_T2 T4 T8 T16 T32 after symbol
    assert first[1] == "1" and first[5] == "4", first
    assert 60 <= ms(first[4]) <= 60 + 4 * late, first  # the four chunks
    assert 30 <= ms(first[6]) <= 30 + 3 * late, first  # 2 threads: 30 | 10 + 10 + 10
    assert 30 <= ms(first[7]) <= 30 + late, first  # 4 threads: the longest chunk
    assert ms(first[6]) < ms(first[4]) - 20, first  # the simulation did hand chunks to two threads
    assert 8 <= ms(first[11]) <= 8 + late, first  # the serial gap after it
    assert second[5] == "0" and 5 <= ms(second[3]) <= 5 + late, second  # no dynamic loop; the single block
    # Wall times at two threads (HGS_REGIONS_WALL=1): the regions' own, no chunks or single blocks recorded, the
    # nested regions started by the team's threads not recorded at all.
    with tempfile.TemporaryDirectory() as tmp:
        prefix = os.path.join(tmp, "regions")
        env = dict(os.environ, LD_PRELOAD=os.path.abspath(lib), HGS_REGIONS_OUT=prefix, OMP_NUM_THREADS="2",
                   HGS_REGIONS_WALL="1")
        subprocess.run([os.path.abspath(demo)], env=env, check=True)
        files = glob.glob(prefix + ".*")
        assert len(files) == 1, files
        rows = [line.split() for line in open(files[0])]
    assert len(rows) == 2, rows
    first, second = rows
    assert first[1] == "1" and first[5] == "0" and ms(first[4]) == 0, first
    assert 30 <= ms(first[2]) < 58, first  # 30 | 10 + 10 + 10 on two threads, not the 60 of one
    assert 8 <= ms(first[11]) <= 8 + late, first
    assert 5 <= ms(second[2]) <= 5 + late and ms(second[3]) == 0, second
    print("ok")


if __name__ == "__main__":
    main(*sys.argv[1:3])
