"""The CSV outputs of a `needlehex run` folder (docs/outputs.md), read once for
every tool: steps.csv (one row per step), probes.csv and targets.csv (one row
per point and step), tools.csv (one row per tool and step).

    rows = read_csv(path)                   # [{column: text}], [] without the file if missing=True
    st = read_steps(run)                    # {column: array over the steps}
    rows = read_rows(path)                  # [{column: number}] (step an int), row by row
    u, steps, times = read_points(run)      # probes.csv: {name: array (steps + 1, 4)}
    x, steps, times = read_points(run, "targets.csv")
    u = target_shift(run, "STN")            # x(last step) − X of a target (m)
    tl = read_tools(run, "needle")          # {column: array over the tool's steps}, state, name
    s = speed(st)                           # median, p95, total of t_step, ... (ms)

Needs numpy (Debian's python3-numpy); use /usr/bin/python3.
"""
import csv
import os
import sys

import numpy as np


def read_csv(path, missing=False):
    """The rows of a CSV file as {column: text}; with missing=True, [] when there is no file."""
    if missing and not os.path.exists(path):
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def columns(rows):
    """{column: array of floats} of rows read by read_csv (every column numeric)."""
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def read_steps(run, missing=False):
    """steps.csv of the run folder as {column: array over the steps}; with missing=True, None
    when there is no file or no row."""
    rows = read_csv(os.path.join(run, "steps.csv"), missing)
    return columns(rows) if rows or not missing else None


def read_rows(path):
    """The rows of a numeric CSV file (steps.csv) as {column: float}, `step` an int."""
    return [{k: (int(v) if k == "step" else float(v)) for k, v in r.items()}
            for r in read_csv(path)]


def read_points(run, fname="probes.csv"):
    """{name: array (steps + 1, 4): displacement and error estimate (probes) or position and
    distance to the tool's tip (targets)}, the steps, their times (s)."""
    pts, steps, times = {}, [], []
    for r in read_csv(os.path.join(run, fname)):
        s = int(r["step"])
        if not steps or steps[-1] != s:
            steps.append(s)
            times.append(float(r["time"]))
        if fname == "probes.csv":
            v = [float(r["ux"]), float(r["uy"]), float(r["uz"]), float(r.get("error_estimate", "nan"))]
        else:
            v = [float(r["x"]), float(r["y"]), float(r["z"]), float(r["distance"])]
        pts.setdefault(r["name"], []).append(v)
    return {k: np.array(v) for k, v in pts.items()}, np.array(steps), np.array(times)


def target_shift(run, name):
    """The displacement of target NAME from its first to its last row of targets.csv (m):
    x(end) − X, an array of 3."""
    x = read_points(run, "targets.csv")[0][name]
    return x[-1, :3] - x[0, :3]


def read_series(run, fname, cols):
    """{name: array (rows of that name, len(cols))} of the columns cols of a per-point CSV
    (probes.csv, targets.csv, tools.csv); {} when the run has no such file."""
    out = {}
    for r in read_csv(os.path.join(run, fname), missing=True):
        out.setdefault(r["name"], []).append([float(r[c]) for c in cols])
    return {k: np.array(v) for k, v in out.items()}


def read_tools(run, tool=None):
    """The rows of tools.csv of one tool (default: the first) as {column: array over its
    steps} (step an int), with `state` (a list) and `name`; exits naming the tools there are
    when the tool has no row."""
    rows = read_csv(os.path.join(run, "tools.csv"))
    names = sorted({r["name"] for r in rows})
    if not names:
        sys.exit("%s: tools.csv has no rows" % run)
    if tool is None:
        tool = rows[0]["name"]
    if tool not in names:
        sys.exit("%s: no tool named '%s' in tools.csv (have %s)" % (run, tool, ", ".join(names)))
    rows = [r for r in rows if r["name"] == tool]
    d = {k: np.array([float(r[k]) for r in rows]) for k in rows[0] if k not in ("name", "state")}
    d["step"] = d["step"].astype(int)
    d["state"] = [r["state"] for r in rows]
    d["name"] = tool
    return d


def speed(st):
    """The cost of a run from its steps.csv columns st: the largest dofs, median and 95th
    percentile of t_step (ms) over the steps after the first (CHOLMOD's symbolic analysis), the
    total of t_step (s), and the median ms of the factorisation, constraints and adaptivity."""
    t = 1e3 * st["t_step"][1:] if len(st["t_step"]) > 1 else 1e3 * st["t_step"]
    return {"max_dofs": int(st["dofs"].max()), "median": float(np.median(t)),
            "p95": float(np.percentile(t, 95)), "total": float(st["t_step"].sum()),
            "t_factor": 1e3 * float(np.median(st["t_factor"][1:])),
            "t_constraints": 1e3 * float(np.median(st["t_constraints"][1:])),
            "t_adapt": 1e3 * float(np.median(st["t_adapt"][1:]))}
