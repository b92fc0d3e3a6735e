#!/usr/bin/python3
"""Benchmark: the time of a step against one numeric factorisation of the
same matrix, timed in the same run, by phase, with the factorisation
renewed at every step (solver.refactor: every) and reused (auto). Not a
test: it reports numbers (docs/performance.md).

    tools/bench_step.py [--binary build/needlehex] [--cases NAME ...] [--steps N]
                        [--modes every auto] [--set KEY=VALUE ...]
                        [--markdown] [--json FILE] [--plot FILE]

--set adds a scene override to every run (e.g. solver.lazy_rotation=1e-3).

Cases (--cases, default all but the tissue-only ones):
  needle-16, needle-32   cases/phantom/phantom.yaml (needle inserted) at 16×8×8, 32×16×16
  dbs-coarse, dbs-fine   cases/dbs/dbs.yaml uniform (never refined) at its grid and twice it,
                         the cannula inserted from t = 0.2 s (rows from step ~10)
  skull-7                cases/dbs/dbs-skull.yaml uniform at its 7 mm grid (20×25×19): the
                         brain sinks onto the skull (0 → ~750 rows in 20 steps)
  dbs-adaptive, skull-adaptive
                         cases/dbs/dbs.yaml and dbs-skull.yaml as written (adaptive), from
                         the start: steps per second (steps / Σ t_step) is the figure
  tissue-8/16/32         cases/phantom-tissue.yaml (no tool) at 8×4×4, 16×8×8, 32×16×16

Every run has NH_TIME_FACTOR=1: on a step that reuses a factorisation, one
numeric factorisation of that step's A is done aside and timed (its time is
excluded from t_step), so each step has its reference t_factor_reference.
The ratio reported is the median over steps of t_step / t_factor_reference;
phases are medians over steps (ms), and so is the assembly's share of the
step; `cpu` is the run's CPU time (user + system, all threads, the
factorisations timed aside included) per step, which the machine's load does
not inflate. The first step (CHOLMOD's symbolic analysis) is left out.
Runs are one after another, each with the default threads; the load average
is printed with each run, since the machine may be shared.
"""
import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile

from outputs import read_csv

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PHASES = ["t_assemble", "t_factor", "t_solve", "t_constraints", "t_compliance", "t_mcp",
          "t_adapt", "t_step", "t_factor_reference"]
PHANTOM = os.path.join(ROOT, "cases", "phantom", "phantom.yaml")
DBS = os.path.join(ROOT, "cases", "dbs", "dbs.yaml")
TISSUE = os.path.join(ROOT, "cases", "phantom-tissue.yaml")
SKULL = os.path.join(ROOT, "cases", "dbs", "dbs-skull.yaml")
DBS_SETS = ["adapt.every=1000000", "tools.0.motion=[{until: 0.2, speed: 0}, "
            "{until: target, speed: 0.02}]"]
CASES = {
    "needle-16": (PHANTOM, ["tissue.grid=[16,8,8]"]),
    "needle-32": (PHANTOM, ["tissue.grid=[32,16,16]"]),
    "dbs-coarse": (DBS, DBS_SETS),
    "dbs-fine": (DBS, DBS_SETS + ["tissue.grid=[20,24,16]"]),
    "skull-7": (SKULL, ["adapt.every=1000000"]),
    "dbs-adaptive": (DBS, []),
    "skull-adaptive": (SKULL, []),
    "tissue-8": (TISSUE, ["tissue.grid=[8,4,4]"]),
    "tissue-16": (TISSUE, ["tissue.grid=[16,8,8]"]),
    "tissue-32": (TISSUE, ["tissue.grid=[32,16,16]"]),
}
DEFAULT = ["needle-16", "needle-32", "dbs-coarse", "dbs-fine"]


def run(binary, case, mode, steps, out, extra=()):
    scene, sets = CASES[case]
    sets = list(sets) + list(extra)
    cmd = [binary, "run", scene, "--quiet", "--overwrite", "--out", out,
           "--set", "output.every=0", "--set", "solver.refactor=" + mode]
    if steps > 0:
        cmd += ["--set", "time.steps=%d" % steps]
    for s in sets:
        cmd += ["--set", s]
    load0 = os.getloadavg()[0]
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(cmd, check=True, env=dict(os.environ, NH_TIME_FACTOR="1"))
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    rows = read_csv(os.path.join(out, "steps.csv"))[1:]
    med = {p: 1e3 * statistics.median(float(r[p]) for r in rows) for p in PHASES}
    med["ratio"] = statistics.median(float(r["t_step"]) / float(r["t_factor_reference"])
                                     for r in rows)
    med["factorisations"] = sum(int(float(r["factorised"])) for r in rows)
    med["pcg"] = statistics.median(float(r["pcg_iterations"]) for r in rows)
    med["rows"] = statistics.median(float(r["constraints"]) for r in rows)
    # CPU (user + system, all threads) per step of the whole run, the factorisations
    # timed aside included: what the machine's load does not inflate
    cpu = ru1.ru_utime + ru1.ru_stime - ru0.ru_utime - ru0.ru_stime
    med["rate"] = len(rows) / sum(float(r["t_step"]) for r in rows)
    med.update(case=case, mode=mode, steps=len(rows), dofs=max(int(r["dofs"]) for r in rows),
               cpu=1e3 * cpu / (len(rows) + 1),
               share=statistics.median(float(r["t_assemble"]) / float(r["t_step"]) for r in rows),
               free=int(rows[-1]["free_dofs"]), load=0.5 * (load0 + os.getloadavg()[0]))
    return med


def plot(results, path):
    from plotstyle import FIGSIZE, plt, save
    fig, ax = plt.subplots(figsize=FIGSIZE)
    for mode, mk, label in (("every", "o", "factorise every step"), ("auto", "s", "reuse (auto)")):
        for fam, ls in (("needle", "-"), ("dbs", "--"), ("tissue", ":")):
            pts = sorted((r["free"], r["t_step"]) for r in results
                         if r["mode"] == mode and r["case"].startswith(fam))
            if pts:
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], mk + ls,
                          color="C0" if mode == "every" else "C3", label="%s, %s" % (label, fam))
    pts = sorted((r["free"], r["t_factor_reference"]) for r in results if r["mode"] == "auto")
    ax.loglog([p[0] for p in pts], [p[1] for p in pts], "k.", label="one factorisation")
    ax.set_xlabel("free DOFs")
    ax.set_ylabel("median ms per step")
    ax.grid(alpha=0.3, which="both")
    save(fig, path, legend=ax)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=os.path.join(ROOT, "build", "needlehex"))
    ap.add_argument("--cases", nargs="*", default=DEFAULT, choices=sorted(CASES))
    ap.add_argument("--steps", type=int, default=30, help="steps per run (0: the scene's own end)")
    ap.add_argument("--modes", nargs="*", default=["every", "auto"], choices=["every", "auto"])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a scene override for every run")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table")
    ap.add_argument("--json", help="write the results to this file")
    ap.add_argument("--plot", help="ms/step against DOFs (PNG)")
    a = ap.parse_args()
    results = []
    head = ("case", "mode", "dofs", "rows", "assemble", "factor", "solve", "constr", "W",
            "mcp/corr", "step", "1 factor", "step/factor", "factorisations", "pcg", "asm %",
            "cpu", "load", "steps/s", "adapt")
    print("%-10s %-5s %6s %4s %8s %8s %7s %7s %7s %8s %8s %8s %6s %3s %4s %5s %8s %5s %7s %7s"
          % head)
    with tempfile.TemporaryDirectory() as tmp:
        for case in a.cases:
            for mode in a.modes:
                r = run(a.binary, case, mode, a.steps, os.path.join(tmp, case + mode), a.set)
                results.append(r)
                print("%-10s %-5s %6d %4.0f %8.2f %8.2f %7.2f %7.2f %7.2f %8.2f %8.2f %8.2f %6.2f "
                      "%3d %4.0f %5.0f %8.1f %5.1f %7.2f %7.2f" % (
                          case, mode, r["dofs"], r["rows"], r["t_assemble"], r["t_factor"],
                          r["t_solve"], r["t_constraints"], r["t_compliance"], r["t_mcp"],
                          r["t_step"], r["t_factor_reference"], r["ratio"], r["factorisations"],
                          r["pcg"], 100 * r["share"], r["cpu"], r["load"], r["rate"],
                          r["t_adapt"]), flush=True)
    if a.markdown:
        print("\n| case | refactor | dofs | rows | assemble | factor | solve | constraints (W, "
              "λ) | step | one factorisation | step / factorisation | factorisations | PCG its "
              "| assembly share | CPU ms / step | steps / s | load |")
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in results:
            print("| %s | %s | %d | %.0f | %.2f | %.2f | %.2f | %.2f (%.2f, %.2f) | %.2f | %.2f | "
                  "%.2f | %d / %d | %.0f | %.0f %% | %.1f | %.2f | %.1f |" % (
                      r["case"], r["mode"], r["dofs"], r["rows"], r["t_assemble"], r["t_factor"],
                      r["t_solve"], r["t_constraints"], r["t_compliance"], r["t_mcp"], r["t_step"],
                      r["t_factor_reference"], r["ratio"], r["factorisations"], r["steps"],
                      r["pcg"], 100 * r["share"], r["cpu"], r["rate"], r["load"]))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    if a.plot:
        plot(results, a.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
