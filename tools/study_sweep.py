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
      - {x: tissue.material.young, y: tip_uz, series: tissue.material.poisson}

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
"""
import csv
import itertools
import math
import os
import sys

import yaml

import study_engine as engine


def load_spec(path):
    with open(path) as f:
        spec = yaml.safe_load(f)
    where = os.path.dirname(os.path.abspath(path))

    def bad(msg):
        raise SystemExit("%s: %s" % (path, msg))

    if not isinstance(spec, dict) or "scene" not in spec:
        bad("a sweep spec is a mapping with at least `scene`")
    for k in spec:
        if k not in ("scene", "out", "set", "grid", "combinations", "outputs", "plots"):
            bad("unknown key `%s`" % k)
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


def jobs_of(spec, binary):
    jobs = []
    for i, v in enumerate(spec["variants"]):
        cmd = [binary, "run", spec["scene"], "--quiet"]
        for s in list(spec.get("set", [])) + ["%s=%s" % (k, yaml_value(x)) for k, x in v.items()]:
            cmd += ["--set", s]
        jobs.append(engine.Job("v%03d" % i, os.path.join(spec["out"], "v%03d" % i), cmd))
    return jobs


def reduce_output(out, o):
    """The value of output `o` for the run in OUT (nan if the run has no such rows)."""
    path = os.path.join(out, o["file"])
    with open(path) as f:
        rows = [r for r in csv.DictReader(f) if "row" not in o or r.get("name") == str(o["row"])]
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
    """Rows of the sweep table: parameters, status, outputs."""
    rows = []
    for j, v in zip(jobs, spec["variants"]):
        r = {"variant": j.name}
        r.update({k: yaml_value(v[k]) if k in v else "" for k in spec["keys"]})
        r["status"] = "ok" if j.name in done else "failed"
        for o in spec.get("outputs", []):
            r[o["name"]] = reduce_output(j.out, o) if j.name in done else math.nan
        rows.append(r)
    return rows


def write_table(spec, rows):
    cols = ["variant"] + spec["keys"] + ["status"] + [o["name"] for o in spec.get("outputs", [])]
    with open(os.path.join(spec["out"], "sweep.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: repr(r[k]) if isinstance(r[k], float) else r[k] for k in cols})
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join("%.6g" % r[k] if isinstance(r[k], float) else str(r[k])
                                       for k in cols) + " |")
    report = "\n".join(["Sweep of %s: %d variants." % (spec["scene"], len(rows)), ""] + lines)
    print(report)
    with open(os.path.join(spec["out"], "report.md"), "w") as f:
        f.write(report + "\n")


def plot(spec, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    for p in spec.get("plots", []):
        fig, ax = plt.subplots(figsize=(6, 4))
        series = p.get("series")
        groups = sorted({r[series] for r in rows}, key=str) if series else [None]
        for g in groups:
            pts = sorted((float(r[p["x"]]), r[p["y"]]) for r in rows
                         if r["status"] == "ok" and (g is None or r[series] == g))
            if pts:
                ax.plot([a for a, _ in pts], [b for _, b in pts], "o-",
                        label=("%s = %s" % (series, g)) if g is not None else None)
        ax.set_xlabel(p["x"])
        ax.set_ylabel(p["y"])
        if p.get("logx"):
            ax.set_xscale("log")
        ax.grid(alpha=0.3)
        if series and ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        fig.tight_layout()
        name = os.path.join(spec["out"], "sweep_%s_%s.png" % (p["y"], p["x"].replace(".", "_")))
        fig.savefig(name, dpi=110)
        plt.close(fig)
        print("wrote %s" % name, file=sys.stderr)


def sweep(a, binary):
    """Runs the sweep of a.spec with the engine options of a; returns the exit status."""
    spec = load_spec(a.spec)
    if a.out:
        spec["out"] = os.path.abspath(a.out)
    os.makedirs(spec["out"], exist_ok=True)
    jobs = jobs_of(spec, binary)
    done, failed = engine.run_jobs(jobs, workers=a.workers, scheduler=a.scheduler,
                                   skip_complete=not a.fresh, threads=a.threads)
    rows = table(spec, jobs, done, failed)
    write_table(spec, rows)
    plot(spec, rows)
    return engine.report_failures(failed)
