#!/usr/bin/python3
"""Speed against error: runs the variants of a study, collects their
steps.csv / probes.csv / targets.csv and writes plots and a Markdown report.

    tools/study.py phantom [--binary PATH] [--out DIR] [--img DIR | --docs] [--only NAME ...]
                           [--fresh-reference] [--steps N] [--reuse | --restart]
                           [--workers N | --scheduler tcp://HOST:PORT] [--threads T]
    tools/study.py dbs     [the same options]
    tools/study.py cube    [the same options]
    tools/study.py dbs-shift [the same options]
    tools/study.py dbs-goal  [the same options] [--base NXxNYxNZ]
    (every study: --set KEY=VAL ..., a scene override for each of its runs)
    tools/study.py sweep SPEC.yaml [--out DIR] [--fresh] [--workers N | --scheduler ...]
    tools/study.py plan SPEC.yaml  [the same]: one `needlehex plan` per variant
    tools/study.py convergence SCENE --grids NXxNYxNZ,... [--set KEY=VAL ...] [--out DIR]
                           [--end S] [--target NAME] [--cortex X,Y,Z] [--estimate MM]

This is the command line; each study is one module, named in STUDIES below,
whose docstring says what it runs and writes: study_phantom.py (docs/phantom.md),
study_dbs.py, study_dbs_shift.py, study_dbs_goal.py (docs/dbs.md),
study_cube.py (docs/adaptivity.md), study_sweep.py (sweep and plan,
docs/performance.md), study_convergence.py (a scene's brain shift on the
grids the reader lists, docs/dbs.md). They share the study engine (study_engine.py: runs the
variants, the folders, the report), outputs.py (reading steps.csv,
probes.csv, targets.csv, tools.csv), richardson.py (extrapolation with the
observed order) and plotstyle.py (the figures' style). A new study is a
module with run(a, binary) and one line in STUDIES.

Variants run through dask.distributed (study_engine.py): a LocalCluster of
--workers processes on this machine (default 1 for phantom and dbs, whose
timings are the point; the number of cores for a sweep), or an existing
cluster given by --scheduler (docs/performance.md: a SLURM cluster through
dask-jobqueue). A failed variant is reported and left out; the others go
on. sweep: a base scene, lists of --set values, one table and plots; plan:
the same with one `needlehex plan` per variant (different targets,
stiffnesses, ...: one table of aims, misses, runs and times).

Speed: median and 95th percentile of t_step (ms) over the steps after the
first (the first includes CHOLMOD's symbolic analysis), and the total of
t_step. Timings depend on the machine's load: run the study on a quiet
machine.

Output: OUT/report.md (the tables; also printed), plots in OUT/img (--img
DIR: in DIR; --docs: in docs/img, where the docs take them from). Needs
numpy and matplotlib (Debian's python3-numpy, python3-matplotlib); use
/usr/bin/python3.
"""
import argparse
import importlib
import sys

import study_engine as engine

# subcommand: its module (tools/<module>.py). The module's run(a, binary) returns the exit
# status; optional: WORKERS (the default --workers, else 1: one run at a time, since runs in
# parallel share the cores and timings are the point), POSITIONAL (metavar, help) when it
# takes the positional argument, add_arguments(ap) for options of its own.
STUDIES = {
    "phantom": "study_phantom",
    "dbs": "study_dbs",
    "dbs-shift": "study_dbs_shift",
    "dbs-goal": "study_dbs_goal",
    "sweep": "study_sweep",
    "plan": "study_sweep",
    "cube": "study_cube",
    "convergence": "study_convergence",
}


def main():
    mods = {name: importlib.import_module(m) for name, m in STUDIES.items()}
    positional = {}  # (metavar, help): the studies that take it
    for name, mod in mods.items():
        if hasattr(mod, "POSITIONAL"):
            positional.setdefault(mod.POSITIONAL, []).append(name)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("study", choices=list(STUDIES))
    ap.add_argument("spec", nargs="?", help="; ".join(
        "%s: %s" % (", ".join(names), what) for (_, what), names in positional.items()))
    ap.add_argument("--binary", default=None, help="needlehex (default build/needlehex)")
    ap.add_argument("--out", default=None, help="run folders and report (default out/study/STUDY)")
    ap.add_argument("--img", default=None, help="where the PNGs go (default OUT/img)")
    ap.add_argument("--docs", action="store_true",
                    help="write the PNGs to docs/img (the plots the docs show)")
    ap.add_argument("--only", nargs="*", help="run only these variants (names as in the report)")
    ap.add_argument("--fresh-reference", action="store_true",
                    help="run the reference (its cached runs) again")
    ap.add_argument("--steps", type=int, default=None, help="fewer steps (a quick look)")
    ap.add_argument("--reuse", action="store_true",
                    help="report on the runs already in OUT instead of running them again")
    ap.add_argument("--fresh", action="store_true", help="sweep: run complete variants again")
    ap.add_argument("--set", action="append", default=[], dest="sets", metavar="KEY=VAL",
                    help="a scene override for every run of the study, after the study's own "
                    "(repeatable; without --out the folder's name gets the values)")
    engine.add_arguments(ap, default_workers=None)
    for mod in dict.fromkeys(mods.values()):
        if hasattr(mod, "add_arguments"):
            mod.add_arguments(ap)
    a = ap.parse_args()
    mod = mods[a.study]
    # a study's own options (OPTIONS: option -> attribute, default None) given to another
    foreign = [o for m in dict.fromkeys(mods.values()) if m is not mod
               for o, attr in getattr(m, "OPTIONS", {}).items() if getattr(a, attr) is not None]
    if foreign:
        ap.error("%s: not an option of the %s study" % (", ".join(sorted(set(foreign))), a.study))
    if a.workers is None:
        a.workers = getattr(mod, "WORKERS", 1)
    binary = engine.find_binary(a.binary)
    if hasattr(mod, "POSITIONAL") and not a.spec:
        ap.error("%s needs %s" % (a.study, mod.POSITIONAL[0]))
    return mod.run(a, binary)


if __name__ == "__main__":
    sys.exit(main())
