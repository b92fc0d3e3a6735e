#!/usr/bin/python3
"""Benchmark: lazy element tangents (solver.lazy_rotation) against the exact
path (τ = 0): tangents rebuilt, factorisations, PCG iterations, phase times,
and the error the laziness introduces in the outputs. Not a test: it
reports numbers (docs/performance.md, "Lazy tangents").

    tools/bench_lazy.py [--binary build/needlehex] [--cases NAME ...]
                        [--tolerances 1e-4 1e-3 1e-2] [--steps N] [--markdown]

Cases (tools/bench_step.py's): needle-16, needle-32 (the needle phantom at
16×8×8 and 32×16×16), dbs-coarse, dbs-fine (the DBS case uniform, the
cannula inserted from t = 0.2 s). Each case runs once per tolerance, τ = 0
first, with solver.refactor: auto (the default).

Errors, each the largest over all steps and points, relative to the largest
value of the exact run: `probe u` (probes.csv displacements, and
targets.csv positions for the DBS target: their motion from step 0), `tip`
(tools.csv tip positions' motion from step 0) and `force` (tools.csv axial
and lateral force). Times are medians over steps (ms; the first step, with
CHOLMOD's analysis, left out), and the least over steps of the assembly and
of the step (`min`: on a shared machine, the closest to the cost on an idle
one); `cpu` is the run's CPU time (user + system, all threads) per step, which
the machine's load does not inflate. The load average is printed.
"""
import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_step import CASES  # noqa: E402
from outputs import read_csv  # noqa: E402

DEFAULT = ["needle-16", "needle-32", "dbs-coarse", "dbs-fine"]


def motion(table, cols):
    """Per (name, step): the values of cols minus those at the name's first row."""
    first, out = {}, {}
    for r in table:
        v = [float(r[c]) for c in cols]
        f = first.setdefault(r["name"], v)
        out[(r["name"], r["step"])] = [a - b for a, b in zip(v, f)]
    return out


def rel_error(exact, lazy):
    scale = max((abs(x) for v in exact.values() for x in v), default=0.0)
    diff = max((abs(a - b) for k in exact if k in lazy for a, b in zip(exact[k], lazy[k])),
               default=0.0)
    return diff / scale if scale > 0 else 0.0


def run(binary, case, tol, steps, out):
    scene, sets = CASES[case]
    cmd = [binary, "run", scene, "--quiet", "--overwrite", "--out", out, "--set",
           "time.steps=%d" % steps, "--set", "output.every=0", "--set",
           "solver.lazy_rotation=%g" % tol]
    for s in sets:
        cmd += ["--set", s]
    load0 = os.getloadavg()[0]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True)
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime
    st = read_csv(os.path.join(out, "steps.csv"), missing=True)[1:]
    med = lambda k: 1e3 * statistics.median(float(r[k]) for r in st)  # noqa: E731
    res = dict(case=case, tol=tol, dofs=int(st[-1]["dofs"]), cells=int(st[-1]["cells"]),
               updates=statistics.mean(float(r["tangent_updates"]) for r in st),
               factorisations=sum(int(float(r["factorised"])) for r in st), steps=len(st),
               pcg=sum(int(float(r["pcg_iterations"])) for r in st),
               t_assemble=med("t_assemble"), t_factor=med("t_factor"),
               t_constraints=med("t_constraints"), t_step=med("t_step"),
               min_assemble=1e3 * min(float(r["t_assemble"]) for r in st),
               min_step=1e3 * min(float(r["t_step"]) for r in st), cpu=1e3 * cpu / (len(st) + 1),
               share=statistics.median(float(r["t_assemble"]) / float(r["t_step"]) for r in st),
               load=0.5 * (load0 + os.getloadavg()[0]))
    table = lambda name: read_csv(os.path.join(out, name + ".csv"), missing=True)  # noqa: E731
    probes = motion(table("probes"), ["ux", "uy", "uz"])
    probes.update(motion(table("targets"), ["x", "y", "z"]))
    tools = table("tools")
    res["_probe"] = probes
    res["_tip"] = motion(tools, ["tip_x", "tip_y", "tip_z"])
    res["_force"] = {(r["name"], r["step"]): [float(r["axial_force"]), float(r["lateral_force"])]
                     for r in tools}
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=os.path.join(os.path.dirname(
        os.path.dirname(os.path.abspath(__file__))), "build", "needlehex"))
    ap.add_argument("--cases", nargs="*", default=DEFAULT, choices=sorted(CASES))
    ap.add_argument("--tolerances", nargs="*", type=float, default=[1e-4, 1e-3, 1e-2])
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args()
    results = []
    head = ("case", "tau", "dofs", "upd/step", "fact", "pcg", "assemble", "min", "factor",
            "constr", "step", "min", "cpu", "asm share", "probe u", "tip", "force", "load")
    print("%-10s %7s %6s %8s %4s %4s %8s %8s %8s %8s %8s %8s %8s %9s %9s %9s %9s %5s" % head)
    with tempfile.TemporaryDirectory() as tmp:
        for case in a.cases:
            exact = None
            for tol in [0.0] + a.tolerances:
                r = run(a.binary, case, tol, a.steps, os.path.join(tmp, "%s-%g" % (case, tol)))
                exact = exact or r
                for k in ("probe", "tip", "force"):
                    r[k] = rel_error(exact["_" + k], r["_" + k])
                results.append(r)
                print("%-10s %7.0e %6d %8.1f %4d %4d %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f %8.2f "
                      "%8.0f%% %9.2e %9.2e %9.2e %5.1f" % (
                          case, tol, r["dofs"], r["updates"], r["factorisations"], r["pcg"],
                          r["t_assemble"], r["min_assemble"], r["t_factor"], r["t_constraints"],
                          r["t_step"], r["min_step"], r["cpu"], 100 * r["share"], r["probe"],
                          r["tip"], r["force"], r["load"]), flush=True)
    if a.markdown:
        print("\n| case | τ | dofs | tangents rebuilt / step (of cells) | factorisations | PCG its "
              "| assemble (min) | factor | constraints | step (min) | CPU / step | assembly share "
              "| probe u | tip | force | load |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in results:
            print("| %s | %g | %d | %.1f (%d) | %d / %d | %d | %.2f (%.2f) | %.2f | %.2f | "
                  "%.2f (%.2f) | %.1f | %.0f %% | %.1e | %.1e | %.1e | %.1f |" % (
                      r["case"], r["tol"], r["dofs"], r["updates"], r["cells"],
                      r["factorisations"], r["steps"], r["pcg"], r["t_assemble"],
                      r["min_assemble"], r["t_factor"], r["t_constraints"], r["t_step"],
                      r["min_step"], r["cpu"], 100 * r["share"], r["probe"], r["tip"],
                      r["force"], r["load"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
