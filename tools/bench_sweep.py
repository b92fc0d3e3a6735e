#!/usr/bin/python3
"""Benchmark: sweep throughput of the execution engine (study_engine.py) with
1 and 2 Dask workers against the serial engine (no Dask), and the Dask
overhead per variant. Not a test: it reports numbers (docs/performance.md).

    tools/bench_sweep.py [--binary build/needlehex] [--variants 8] [--grid 60,6,6] [--steps 3]

The variants are the cantilever (cases/cantilever.yaml) with Young's moduli
1, 2, ... MPa on the given grid (static, --steps load steps), each run
single-threaded (OMP_NUM_THREADS=1). Throughput: variants per second of
wall time of the whole sweep, cluster start and stop included. Overhead
per variant: (wall − sum of the runs' own walls / workers) / variants, the
time the engine adds (cluster start and stop, scheduling, transfers). Runs are timed
one configuration after another; the load average is printed.
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import study_engine as engine  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "needlehex"))
    ap.add_argument("--variants", type=int, default=8)
    ap.add_argument("--grid", default="60,6,6")
    ap.add_argument("--steps", type=int, default=3)
    a = ap.parse_args()
    scene = os.path.join(ROOT, "cases", "cantilever.yaml")
    walls = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, workers in (("serial", 0), ("1 worker", 1), ("2 workers", 2)):
            jobs = [engine.Job("v%03d" % i, os.path.join(tmp, label.replace(" ", ""), "v%03d" % i),
                               [a.binary, "run", scene, "--quiet", "--set",
                                "tissue.grid=[%s]" % a.grid, "--set", "time.steps=%d" % a.steps,
                                "--set", "tissue.material.young=%g" % (1e6 * (i + 1))])
                    for i in range(a.variants)]
            load0 = os.getloadavg()[0]
            t0 = time.time()
            done, failed = engine.run_jobs(jobs, workers=workers, quiet=True)
            wall = time.time() - t0
            if failed:
                raise SystemExit("%s: variants failed: %s" % (label, failed))
            walls[label] = wall
            runs = sum(d["wall"] for d in done.values())
            over = (wall - runs / max(workers, 1)) / a.variants
            print("%-9s wall %6.2f s, %5.2f variants/s, sum of run walls %6.2f s, engine overhead "
                  "%.2f s/variant, load %.1f" % (label, wall, a.variants / wall, runs, over,
                                                 0.5 * (load0 + os.getloadavg()[0])), flush=True)
    print("throughput 2 workers / 1 worker: %.2f (goal >= 1.7)" % (walls["1 worker"] /
                                                                   walls["2 workers"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
