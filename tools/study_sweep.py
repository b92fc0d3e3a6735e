"""`tools/study.py sweep SPEC.yaml`: one scene run over a grid (or a list) of
--set values through the execution engine (study_engine.py), reduced to one
table and plots of the chosen outputs (docs/performance.md, "Sweeps").

A spec (YAML; paths relative to the spec file):

    scene: ../cases/cantilever.yaml
    out: ../out/sweep/cantilever        # optional: default out/sweep/<spec name>
    set: ["time.steps=1"]               # optional: given to every variant
    grid:                               # the full grid: every combination
      tissue.material.young: [1.0e6, 2.0e6]
      tissue.material.poisson: [0.3, 0.45]
    # or, instead of grid, listed combinations:
    # combinations:
    #   - {tissue.material.young: 1.0e6, tissue.material.poisson: 0.3}
    outputs:                            # the table's columns
      - {name: tip_uz, file: probes.csv, row: tip, column: uz, at: last}
      - {name: ms_step, file: steps.csv, column: t_step, at: median, scale: 1000}
    plots:                              # y against x, one curve per value of series
      - {x: tissue.material.young, y: tip_uz, series: tissue.material.poisson,
         xlabel: "Young's modulus (Pa)", ylabel: "tip u_z (m)"}   # labels: optional

Plans instead of runs (`command: plan`): each variant is `needlehex plan`
(target compensation, docs/dbs.md) with the variant's --set values, e.g.
different targets or brain stiffnesses, and

    command: plan
    plan: {tolerance: 0.5e-3, max_runs: 6}   # optional: needlehex plan's defaults

The table then has, per variant, the plan's outcome from OUT/vNNN/plan.yaml:
`converged` (true/false), `runs`, `misses_mm` (|miss| of each run, mm),
`miss_mm` (the last), `aim_mm` (the compensated aim, mm), `time_s` (the
plan's wall time: all its runs); `outputs` read the CSVs of the last run
(OUT/vNNN/final). A plan that does not converge within max_runs is a
result (status `not converged`, the sweep exits 1), not a failure: it is
not run again on a restart; nor is a plan one of whose runs failed (status
`failed: <needlehex's message>`, the runs before it in the table); --fresh
runs them again.

An output reads one column of one CSV of the run (steps.csv, probes.csv,
targets.csv, tools.csv), keeps the rows whose `name` is `row` (probes,
targets and tools have one row per name and step), and reduces the column
over the steps with `at`: last, first, max, min, absmax, median, mean, or an
integer step. `scale` multiplies it (default 1). Values of a --set are
written as YAML scalars (numbers as given, lists as [a, b, c]).

Variant folders are OUT/v000, OUT/v001, ... in grid order (the last key
varies fastest); complete variants with the same command are skipped
(restart), so the sweep can be run again after an interruption or with
more values. Outputs: OUT/sweep.csv (one row per variant: the parameter
values, status, the outputs), OUT/report.md (the same as a table, also
printed), OUT/sweep_<y>_<x>.png per plot.

    tools/study.py sweep SPEC.yaml [--out DIR] [--fresh] [--workers N | --scheduler ...]
    tools/study.py plan SPEC.yaml  [the same]    # the same, `command: plan` implied
"""
import csv
import itertools
import math
import os
import sys

import yaml

import study_engine as engine
from outputs import read_csv

# tools/study.py: sweeps run as many variants at once as there are cores (--workers), and
# take a spec
WORKERS = os.cpu_count() or 1
POSITIONAL = ("SPEC.yaml", "the spec (YAML, see study_sweep.py)")


def load_spec(path, command=None):
    """The spec of PATH, checked; command: the command implied by the caller (plan), which the
    spec's `command` may repeat but not contradict."""
    with open(path) as f:
        spec = yaml.safe_load(f)
    where = os.path.dirname(os.path.abspath(path))

    def bad(msg):
        raise SystemExit("%s: %s" % (path, msg))

    if not isinstance(spec, dict) or "scene" not in spec:
        bad("a sweep spec is a mapping with at least `scene`")
    for k in spec:
        if k not in ("scene", "out", "set", "grid", "combinations", "outputs", "plots", "command",
                     "plan"):
            bad("unknown key `%s`" % k)
    if command and spec.setdefault("command", command) != command:
        bad("`command: %s`, but run as `%s`" % (spec["command"], command))
    spec.setdefault("command", "run")
    if spec["command"] not in ("run", "plan"):
        bad("`command` is run or plan, got `%s`" % spec["command"])
    plan = spec.setdefault("plan", {})
    if not isinstance(plan, dict) or any(k not in ("tolerance", "max_runs") for k in plan):
        bad("`plan` is a mapping with tolerance (m) and max_runs")
    if plan and spec["command"] != "plan":
        bad("`plan` needs `command: plan`")
    if ("grid" in spec) == ("combinations" in spec):
        bad("give exactly one of `grid` and `combinations`")
    spec["scene"] = os.path.normpath(os.path.join(where, spec["scene"]))
    if not os.path.exists(spec["scene"]):
        bad("scene %s not found" % spec["scene"])
    name = os.path.splitext(os.path.basename(path))[0]
    spec["out"] = os.path.normpath(os.path.join(where, spec["out"])) if "out" in spec else \
        os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "out", "sweep",
                     name)
    if "grid" in spec:
        g = spec["grid"]
        if not isinstance(g, dict) or not g or not all(isinstance(v, list) and v
                                                       for v in g.values()):
            bad("`grid` maps each key to a non-empty list of values")
        keys = list(g)
        spec["variants"] = [dict(zip(keys, vals)) for vals in itertools.product(*g.values())]
    else:
        c = spec["combinations"]
        if not isinstance(c, list) or not c or not all(isinstance(v, dict) for v in c):
            bad("`combinations` is a non-empty list of mappings key: value")
        spec["variants"] = c
    spec["keys"] = []
    for v in spec["variants"]:
        spec["keys"] += [k for k in v if k not in spec["keys"]]
    for i, o in enumerate(spec.get("outputs", [])):
        for k in ("name", "file", "column"):
            if k not in o:
                bad("outputs[%d] needs `%s`" % (i, k))
    for i, p in enumerate(spec.get("plots", [])):
        for k in ("x", "y"):
            if k not in p:
                bad("plots[%d] needs `%s`" % (i, k))
    return spec


def yaml_value(v):
    """A --set value as needlehex reads it (YAML flow)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float, str)):
        return str(v)
    return yaml.safe_dump(v, default_flow_style=True).strip()


def jobs_of(spec, binary, sets=()):
    """One job per variant: the spec's `set`, the variant's values, then `sets` (--set)."""
    jobs = []
    plan = spec["command"] == "plan"
    for i, v in enumerate(spec["variants"]):
        cmd = [binary, spec["command"], spec["scene"], "--quiet"]
        if plan and "tolerance" in spec["plan"]:
            cmd += ["--tolerance", repr(float(spec["plan"]["tolerance"]))]
        if plan and "max_runs" in spec["plan"]:
            cmd += ["--max-runs", str(int(spec["plan"]["max_runs"]))]
        for s in (list(spec.get("set", [])) + ["%s=%s" % (k, yaml_value(x)) for k, x in v.items()]
                  + list(sets)):
            cmd += ["--set", s]
        # a plan that did not converge exits 1 with its plan.yaml: a result
        jobs.append(engine.Job("v%03d" % i, os.path.join(spec["out"], "v%03d" % i), cmd,
                               (0, 1) if plan else (0,)))
    return jobs


PLAN_COLUMNS = ["converged", "runs", "misses_mm", "miss_mm", "aim_mm", "time_s"]


def plan_outcome(out, info):
    """The plan columns and status of the plan variant in OUT (run.json record `info`)."""
    try:
        with open(os.path.join(out, "plan.yaml")) as f:
            doc = yaml.safe_load(f)
    except OSError:
        doc = None
    if not doc:  # its first run failed: no plan.yaml
        return {}, "failed: %s" % info.get("message", "no plan.yaml")
    mm = lambda v: "[%s]" % ", ".join("%.3f" % (1e3 * x) for x in v)  # noqa: E731
    r = {"converged": "true" if doc["converged"] else "false", "runs": doc["runs"],
         "misses_mm": "[%s]" % ", ".join("%.4g" % (1e3 * it["miss"]) for it in doc["iterations"]),
         "miss_mm": 1e3 * float(doc["miss"]), "aim_mm": mm(doc["aim"]),
         "time_s": float(doc["time"])}
    if doc["converged"]:
        return r, "ok"
    if doc["runs"] < doc["max_runs"]:  # a run failed before max_runs
        return r, "failed: %s" % info.get("message", "")
    return r, "not converged"


def reduce_output(out, o):
    """The value of output `o` for the run in OUT (nan if the run has no such rows)."""
    rows = [r for r in read_csv(os.path.join(out, o["file"]))
            if "row" not in o or r.get("name") == str(o["row"])]
    vals = [float(r[o["column"]]) for r in rows]
    if not vals:
        return math.nan
    at = o.get("at", "last")
    if isinstance(at, int):
        steps = [int(r["step"]) for r in rows]
        v = vals[steps.index(at)] if at in steps else math.nan
    else:
        s = sorted(vals)
        v = {"last": vals[-1], "first": vals[0], "max": s[-1], "min": s[0],
             "absmax": max(abs(x) for x in vals), "mean": sum(vals) / len(vals),
             "median": 0.5 * (s[(len(s) - 1) // 2] + s[len(s) // 2])}.get(at)
        if v is None:
            raise SystemExit("output %s: unknown `at: %s`" % (o["name"], at))
    return v * float(o.get("scale", 1.0))


def table(spec, jobs, done, failed):
    """Rows of the sweep table: parameters, status, (plan columns,) outputs."""
    rows = []
    plan = spec["command"] == "plan"
    for j, v in zip(jobs, spec["variants"]):
        r = {"variant": j.name}
        r.update({k: yaml_value(v[k]) if k in v else "" for k in spec["keys"]})
        r["status"] = "ok" if j.name in done else "failed"
        run_dir = j.out
        if plan:
            r.update({k: "" for k in PLAN_COLUMNS})
            if j.name in done:
                cols, r["status"] = plan_outcome(j.out, done[j.name])
                r.update(cols)
            run_dir = os.path.join(j.out, "final")
        for o in spec.get("outputs", []):
            ok = j.name in done and os.path.isdir(run_dir)
            r[o["name"]] = reduce_output(run_dir, o) if ok else math.nan
        rows.append(r)
    return rows


def write_table(spec, rows):
    cols = ["variant"] + spec["keys"] + ["status"] + (
        PLAN_COLUMNS if spec["command"] == "plan" else []) + [o["name"] for o in
                                                             spec.get("outputs", [])]
    with open(os.path.join(spec["out"], "sweep.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: repr(r[k]) if isinstance(r[k], float) else r[k] for k in cols})
    lines = engine.table_head(*cols)
    for r in rows:
        lines.append("| " + " | ".join("%.6g" % r[k] if isinstance(r[k], float) else str(r[k])
                                       for k in cols) + " |")
    what = "Plans" if spec["command"] == "plan" else "Sweep"
    report = "\n".join(["%s of %s: %d variants." % (what, spec["scene"], len(rows)), ""] + lines)
    print(report)
    with open(os.path.join(spec["out"], "report.md"), "w") as f:
        f.write(report + "\n")


def plot(spec, rows):
    from plotstyle import FIGSIZE, plt, save
    for p in spec.get("plots", []):
        series = p.get("series")
        fig, ax = plt.subplots(figsize=FIGSIZE)
        groups = sorted({r[series] for r in rows}, key=str) if series else [None]
        for k, g in enumerate(groups):
            pts = sorted((float(r[p["x"]]), r[p["y"]]) for r in rows
                         if r["status"] == "ok" and (g is None or r[series] == g))
            if pts:  # markers smaller curve by curve: coinciding curves stay visible
                ax.plot([a for a, _ in pts], [b for _, b in pts], "osD^v<>"[k % 7] + "-",
                        ms=max(9 - 2 * k, 3), lw=max(2.4 - 0.6 * k, 1),
                        label=("%s = %s" % (series, g)) if g is not None else None)
        ax.set_xlabel(p.get("xlabel", p["x"]))
        ax.set_ylabel(p.get("ylabel", p["y"]))
        if p.get("logx"):
            ax.set_xscale("log")
        ax.grid(alpha=0.3)
        save(fig, os.path.join(spec["out"], "sweep_%s_%s.png" % (p["y"], p["x"].replace(".", "_"))),
             legend=ax if series and ax.get_legend_handles_labels()[0] else None)


def run(a, binary):
    """Runs the sweep of a.spec with the engine options of a; returns the exit status (1 if a
    variant failed or a plan did not converge). `tools/study.py plan`: the spec's `command`
    must be plan or absent."""
    spec = load_spec(a.spec, "plan" if a.study == "plan" else None)
    if a.out:
        spec["out"] = os.path.abspath(a.out)
    os.makedirs(spec["out"], exist_ok=True)
    jobs = jobs_of(spec, binary, a.sets)
    done, failed = engine.run_jobs(jobs, workers=a.workers, scheduler=a.scheduler,
                                   skip_complete=not a.fresh, threads=a.threads)
    rows = table(spec, jobs, done, failed)
    write_table(spec, rows)
    plot(spec, rows)
    bad = [r for r in rows if r["status"] not in ("ok", "failed")]  # plans: see plan_outcome
    for r in bad:
        print("variant %s: %s" % (r["variant"], r["status"]), file=sys.stderr)
    rc = engine.report_failures(failed)
    return 1 if rc or bad else 0
