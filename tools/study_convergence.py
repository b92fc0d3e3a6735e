"""tools/study.py convergence SCENE --grids NXxNYxNZ,... (docs/dbs.md, "Convergence
on grids a reader picks"): a scene's brain shift (the run until --end, 3 s by
default: drained over 1 s, settled until 3 s, the tools still) on uniform grids
the reader lists, nested or not, with the scene's own settings and --set
KEY=VAL overrides (e.g. tissue.cut_cells=integrated).

Per grid: h (mm) = the longest cell edge, the scene's bounding box (as
`needlehex check` prints it) over the grid; dofs, cells, the target's shift
|x(end) − X| (targets.csv; --target, default the scene's first target), the
cortical shift |u(end)| of a probe added to the scene (--cortex X,Y,Z in m;
default 3 mm behind the anterior pole of the right hemisphere of the analytic
brain, in the frontal lobe that drains: (cx + 0.45a, cy + b − 3 mm, cz + 0.3c)
with a, b, c the box's half sizes, docs/theory.md §5b; other shapes need
--cortex), wall and CPU time (the sum of t_step), the skull contact rows at
the end, the largest count of inverted cells (steps.csv), and the status:
ok; unsolved (the run reached its end but steps.csv's `unsolved` marks steps
whose equations were left unsolved: a Newton failure, the shifts still
tabulated and the grid flagged); or failed with needlehex's reason (Newton,
inverted cells, diverged: an implausible step, other) and its message. A
failed run is a row of the table, not a failure of the study.

For every three consecutive grids (in h, coarse first) that reached their end
(the grids not ok among them named): the spread (max − min)/mean and the
largest deviation from the mean max|f − mean|/mean of the STN shifts (the goal
of issue 25: within 2 %), whether the three grids are nested (each refines the
previous by a whole factor per axis), and the observed order with the
extrapolated value (tools/richardson.py: f(h) = f∞ − C h^p through the three
(h, f), bisection on p, so the ratios need not be constant; "none" when the
differences change sign or no p in (0.05, 6) fits); and the change between
every two grids of which one refines the other (nested pairs).

--estimate MM adds the goal-oriented estimate (adapt.estimator=goal with
adapt.max_level=0: estimated at every step, never refined) on the grids with
h ≥ MM, and judges it against the ladder: per step the least-squares line
x(h) = x∞ + a h of the target's position through every grid that ran ok
to the same number of steps (richardson.py, ladder_reference; its bar twice x∞'s standard error, the
components' bars combined), the true error |x_h − x∞| of each estimated grid,
its error_estimate (targets.csv) and their ratio, the effectivity. A step is
judged (issue 25's goal: effectivity in [0.5, 2]) where the true error
exceeds 3 × the bar; the others are tabulated, not judged. The grids'
shifts and the triples are those of the runs with the estimate, which leaves
the solution unchanged (no refinement).

Output (TAG: the scene's name and the values of the --set overrides, e.g.
dbs-skull-integrated): OUT/GRID/ (one run each; OUT by default
out/study/convergence-TAG), OUT/report.md (also printed), and in OUT/img (or
--img DIR, docs/img with --docs) a PNG named after OUT (convergence-TAG.png
by default): the shifts against h; with --estimate, NAME-effectivity.png:
the effectivity against h per step. --reuse reports on the runs already in
OUT; --restart runs only the missing ones.
"""
import os
import re
import subprocess

import numpy as np

import study_engine as engine
from outputs import read_csv, read_points, read_steps
from richardson import ladder_reference, observed

POSITIONAL = ("SCENE", "a scene file (convergence)")
WORKERS = 1
# the options only this study takes (tools/study.py refuses them for the others)
OPTIONS = {"--grids": "grids", "--end": "end", "--target": "target", "--cortex": "cortex",
           "--estimate": "estimate"}
GOAL = 0.02  # issue 25: three consecutive STN shifts within 2 % of their mean
# --estimate: the goal estimate without refinement; judged where the true error > RESOLVED bars
ESTIMATE = ["adapt.estimator=goal", "adapt.max_level=0", "adapt.every=1"]
RESOLVED = 3.0
BAND = (0.5, 2.0)


def add_arguments(ap):
    g = ap.add_argument_group("convergence")
    g.add_argument("--grids", default=None,
                   help="convergence: the grids, NXxNYxNZ separated by commas (any order)")
    g.add_argument("--end", type=float, default=None,
                   help="convergence: time.end of every run (s; default 3, the brain shift)")
    g.add_argument("--target", default=None,
                   help="convergence: the target whose shift is tabulated (default the first)")
    g.add_argument("--cortex", default=None, metavar="X,Y,Z",
                   help="convergence: the cortical probe (m; default in the frontal lobe)")
    g.add_argument("--estimate", type=float, default=None, metavar="MM",
                   help="convergence: the goal estimate on the grids with h >= MM, its "
                   "effectivity against the ladder")


def parse_grids(text):
    """'10x12x9,14x17x13' -> [(10, 12, 9), (14, 17, 13)]; exits on a malformed entry."""
    grids = []
    for g in text.split(","):
        m = re.fullmatch(r"\s*(\d+)x(\d+)x(\d+)\s*", g)
        if not m or min(int(v) for v in m.groups()) < 1:
            raise SystemExit("--grids: '%s' is not NXxNYxNZ" % g)
        grids.append(tuple(int(v) for v in m.groups()))
    return grids


def scene_box(binary, scene, sets):
    """The grid's box (lo, hi) in m and the first target's name, from `needlehex check`."""
    cmd = [binary, "check", scene]
    for s in sets:
        cmd += ["--set", s]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit("needlehex check %s: %s" % (scene, (p.stderr or p.stdout).strip()))
    num = r"\[([-0-9.e+]+), ([-0-9.e+]+), ([-0-9.e+]+)\]"
    m = re.search(r"bounding box %s \.\. %s m" % (num, num), p.stdout) or \
        re.search(r"box %s \.\. %s m" % (num, num), p.stdout)
    if not m:
        raise SystemExit("needlehex check %s: no grid box in its output" % scene)
    v = np.array([float(x) for x in m.groups()])
    t = re.search(r"^targets\s+\d+\s*\n\s+(\S+)", p.stdout, re.M)
    return v[:3], v[3:], (t.group(1) if t else None)


def grid_h(lo, hi, grid):
    """The longest cell edge (mm) of a uniform grid over the box."""
    return 1e3 * float(np.max((hi - lo) / np.array(grid, float)))


def nested(a, b):
    """Whether grid b refines grid a by one whole factor on every axis."""
    return all(y % x == 0 for x, y in zip(a, b)) and len({y // x for x, y in zip(a, b)}) == 1


def status(info, st):
    """ok; unsolved (the run reached its end, but steps.csv marks steps whose equations
    Newton left unsolved: a Newton failure, warned about, exit 0); or failed with the reason
    from needlehex's message."""
    if info.get("returncode", 0) == 0:
        bad = np.nonzero(st["unsolved"])[0] if st is not None and "unsolved" in st else []
        if len(bad):
            return "unsolved (Newton): %d of %d steps, the first step %d (residual %.2f)" % (
                len(bad), len(st["step"]), int(st["step"][bad[0]]), st["residual"][bad[0]])
        return "ok" if st is None or st.get("inverted", np.zeros(1)).max() == 0 else \
            "ok (inverted cells reported)"
    msg = info.get("message", "")
    kind = [k for k, pat in (("Newton", r"Newton|did not converge|no progress|relative residual"),
                             ("inverted", r"invert"), ("diverged", r"implausible step"))
            if re.search(pat, msg)] or ["other"]
    return "failed (%s): %s" % (", ".join(kind), msg)


def ran(r):
    """Whether the run reached its end (ok, or with unsolved steps): its shifts are tabulated."""
    return not r["status"].startswith("failed")


def measure(d, info, target, probe):
    """One grid's row from its run folder (complete, or failed: exit 1)."""
    st = read_steps(d, missing=True)
    r = {"status": status(info, st), "wall": info.get("wall", float("nan")),
         "dofs": int(st["dofs"].max()) if st else 0, "cells": int(st["cells"].max()) if st else 0,
         "cpu": float(st["t_step"].sum()) if st else float("nan"),
         "inverted": int(st["inverted"].max()) if st and "inverted" in st else 0,
         "skull": int(st["skull_contacts"][-1]) if st and "skull_contacts" in st else 0,
         "stn": float("nan"), "cortex": float("nan"), "t": float(st["time"][-1]) if st else 0.0}
    if ran(r):
        r["x"] = read_points(d, "targets.csv")[0][target][:, :3]  # per step (m)
        r["stn"] = 1e3 * float(np.linalg.norm(r["x"][-1] - r["x"][0]))  # |x(end) − X|
        r["est"] = np.array([float(t.get("error_estimate", "nan"))
                             for t in read_csv(os.path.join(d, "targets.csv"))
                             if t["name"] == target])
        u = read_points(d, "probes.csv")[0]
        r["cortex"] = 1e3 * float(np.linalg.norm(u[probe][-1, :3]))
    return r


def triples(rows):
    """For every three consecutive rows that ran (coarse first): their names, hs, the STN
    spread (max − min)/mean, the largest |f − mean|/mean, nested or not, the observed order
    and extrapolated value of the STN and cortical shifts (order None: not observed)."""
    ok = [r for r in rows if ran(r)]
    out = []
    for a, b, c in zip(ok, ok[1:], ok[2:]):
        h = [a["h"], b["h"], c["h"]]
        t = {"names": [a["name"], b["name"], c["name"]], "h": h,
             "nested": nested(a["grid"], b["grid"]) and nested(b["grid"], c["grid"]),
             "flagged": [r["name"] for r in (a, b, c) if r["status"] != "ok"]}
        for key in ("stn", "cortex"):
            f = np.array([a[key], b[key], c[key]])
            mean = float(f.mean())
            t[key + "_spread"] = float((f.max() - f.min()) / mean)
            t[key + "_dev"] = float(np.max(np.abs(f - mean)) / mean)
            t[key + "_order"], t[key + "_inf"] = observed(h, list(f))
        out.append(t)
    return out


def effectivity(rows):
    """--estimate: the per-step reference of the target's position from every grid that ran
    ok to the same number of steps (ladder_reference per component; the bar the components'
    bars combined), and for every estimated grid and step with an estimate: the true error
    |x − x∞|, the bar, error_estimate, their ratio and whether the step is judged (true
    error > RESOLVED bars). None with fewer than three distinct h."""
    L = [r for r in rows if r["status"].startswith("ok") and "x" in r]
    n = max((len(r["x"]) for r in L), default=0)
    L = [r for r in L if len(r["x"]) == n]
    if len({r["h"] for r in L}) < 3:
        return None
    h = [r["h"] for r in L]
    comp = [ladder_reference(h, np.array([r["x"][:, k] for r in L])) for k in range(3)]
    ref = np.array([c[0] for c in comp]).T
    bar = np.linalg.norm(np.array([c[1] for c in comp]).T, axis=1)
    pairs = []
    for r in L:
        if not r["estimated"]:
            continue
        for i in range(n):
            if not np.isfinite(r["est"][i]):
                continue
            err = float(np.linalg.norm(r["x"][i] - ref[i]))
            pairs.append({"name": r["name"], "h": r["h"], "step": i, "err": err,
                          "bar": float(bar[i]), "est": float(r["est"][i]),
                          "eff": r["est"][i] / err if err > 0 else float("inf"),
                          "judged": err > RESOLVED * bar[i]})
    return {"grids": [r["name"] for r in L], "ref": ref, "bar": bar, "pairs": pairs}


def effectivity_report(E, target):
    """The report's lines for --estimate: one row per (grid, step), then the summary."""
    if E is None:
        return ["Effectivity: fewer than three grids of distinct h ran ok to the same step; "
                "no reference."]
    P = E["pairs"]
    lines = ["Effectivity of the goal estimate of %s against the ladder's reference (the line "
             "x∞ + a h per step through the %d grids that ran ok: %s); judged where |x − x∞| > "
             "%g × the bar:" % (target, len(E["grids"]), ", ".join(E["grids"]), RESOLVED), ""]
    lines += engine.table_head("grid", "step", "\\|x − x∞\\| mm", "bar mm", "error_estimate mm",
                               "effectivity", "judged")
    for q in P:
        lines.append("| %s | %d | %.4f | %.4f | %.4f | %.2f | %s |" % (
            q["name"], q["step"], 1e3 * q["err"], 1e3 * q["bar"], 1e3 * q["est"], q["eff"],
            "yes" if q["judged"] else "no"))
    lines.append("")
    if not P:
        lines.append("No estimated step (--estimate MM selects the grids with h ≥ MM).")
        return lines
    eff = np.array([q["eff"] for q in P])
    inside = (eff >= BAND[0]) & (eff <= BAND[1])
    J = [q for q in P if q["judged"]]
    jin = [q for q in J if BAND[0] <= q["eff"] <= BAND[1]]
    lines.append(
        "Effectivity over the %d estimated (grid, step) pairs: median %.2f, %.2f–%.2f, %d in "
        "[%g, %g]. Judged (true error > %g bars): %d pairs, %d of them in [%g, %g]%s. The "
        "reference's bar: %.4f–%.4f mm over the estimated steps." % (
            len(P), float(np.median(eff)), eff.min(), eff.max(), int(inside.sum()), *BAND,
            RESOLVED, len(J), len(jin), *BAND,
            " (median %.2f)" % float(np.median([q["eff"] for q in J])) if J else "",
            1e3 * min(q["bar"] for q in P), 1e3 * max(q["bar"] for q in P)))
    return lines


def plot_effectivity(E, path, title):
    from plotstyle import plt, save
    fig, ax = plt.subplots(figsize=(5.6, 3.8))
    ax.axhspan(*BAND, color="tab:green", alpha=0.12, label="[%g, %g]" % BAND)
    steps = sorted({q["step"] for q in E["pairs"]})
    if len(steps) <= 8:  # one line per step
        for s in steps:
            Q = [q for q in E["pairs"] if q["step"] == s]
            line, = ax.plot([q["h"] for q in Q], [q["eff"] for q in Q], "o-", mfc="none", lw=1,
                            label="step %d" % s)
            J = [q for q in Q if q["judged"]]
            ax.plot([q["h"] for q in J], [q["eff"] for q in J], "o", color=line.get_color())
    else:  # every step a dot, the judged ones filled, the median per grid
        P = E["pairs"]
        ax.plot([q["h"] for q in P], [q["eff"] for q in P], ".", color="0.6", ms=3,
                label="every step (%d)" % len(steps))
        J = [q for q in P if q["judged"]]
        if J:
            ax.plot([q["h"] for q in J], [q["eff"] for q in J], "o", color="tab:red",
                    label="judged")
        hs = sorted({q["h"] for q in P}, reverse=True)
        ax.plot(hs, [np.median([q["eff"] for q in P if q["h"] == h]) for h in hs], "s-",
                color="tab:blue", label="median per grid")
    ax.set_yscale("log")
    lo, hi = ax.get_ylim()
    ticks = [t for t in (0.05, 0.1, 0.2, 0.5, 1, 2, 3, 5, 10, 20) if lo <= t <= hi]
    ax.set_yticks(ticks, ["%g" % t for t in ticks])
    ax.minorticks_off()
    ax.set_xlabel("h (mm): the longest cell edge")
    ax.set_ylabel("effectivity: error_estimate / |x − x∞|")
    ax.invert_xaxis()
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, frameon=False, title="filled: judged" if len(steps) <= 8 else None,
              title_fontsize=8)
    fig.suptitle(title, fontsize=10)
    return save(fig, path)


def plot(rows, path, title):
    from plotstyle import plt, save
    fig, axes = plt.subplots(1, 2, figsize=(9.6, 3.8))
    ok = [r for r in rows if ran(r)]
    bad = [r for r in rows if not ran(r)]
    for ax, key, what in zip(axes, ("stn", "cortex"), ("STN shift", "cortical shift")):
        ax.plot([r["h"] for r in ok], [r[key] for r in ok], "o-", label="ran")
        flag = [r for r in ok if r["status"] != "ok"]
        if flag:
            ax.plot([r["h"] for r in flag], [r[key] for r in flag], "s", mfc="none",
                    color="tab:orange", ms=10, label="steps unsolved")
        for r in bad:
            ax.axvline(r["h"], color="tab:red", ls=":", lw=1)
        if bad:
            ax.plot([], [], color="tab:red", ls=":", label="failed grid")
        ax.set_xlabel("h (mm): the longest cell edge")
        ax.set_ylabel(what + " (mm)")
        ax.invert_xaxis()
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, frameon=False)
    fig.suptitle(title, fontsize=10)
    return save(fig, path)


def report(scene, sets, rows, tri):
    """The report's lines: the grid table, the triples' table, the verdict against the goal."""
    lines = ["Scene %s, overrides: %s." % (scene, " ".join(sets) or "none"), ""]
    p = lines.append
    lines += engine.table_head("grid", "h mm", "dofs", "cells", "skull contacts",
                               "STN shift mm", "cortical shift mm", "wall s", "CPU s (steps)",
                               "status")
    for r in rows:
        okr = ran(r)
        p("| %s | %.2f | %d | %d | %d | %s | %s | %.1f | %.1f | %s |" % (
            r["name"], r["h"], r["dofs"], r["cells"], r["skull"],
            "%.4f" % r["stn"] if okr else "–",
            "%.3f" % r["cortex"] if okr else "–", r["wall"], r["cpu"],
            r["status"] if okr else "%s (%s)" % (r["status"], "last step written at t = %.2f s"
                                                 % r["t"] if r["dofs"] else "no step written")))
    p("")
    lines += engine.table_head("grids (coarse first)", "h mm", "nested", "STN spread",
                               "STN max dev.", "STN order", "STN f∞ mm", "cortex spread",
                               "cortex order", "grids not ok")
    for t in tri:
        p("| %s | %s | %s | %.2f %% | %.2f %% | %s | %s | %.2f %% | %s | %s |" % (
            ", ".join(t["names"]), ", ".join("%.2f" % h for h in t["h"]),
            "yes" if t["nested"] else "no", 100 * t["stn_spread"], 100 * t["stn_dev"],
            "%.2f" % t["stn_order"] if t["stn_order"] else "none",
            "%.4f" % t["stn_inf"] if t["stn_order"] else "–", 100 * t["cortex_spread"],
            "%.2f" % t["cortex_order"] if t["cortex_order"] else "none",
            ", ".join(t["flagged"]) or "–"))
    ok = [r for r in rows if ran(r)]
    pairs = [(a, b) for i, a in enumerate(ok) for b in ok[i + 1:] if nested(a["grid"], b["grid"])]
    if pairs:
        p("")
        p("Nested pairs (the finer grid refines the coarser by a whole factor): " + "; ".join(
            "%s → %s: STN %.4f → %.4f mm (%+.2f %%), cortex %.3f → %.3f mm (%+.2f %%)" % (
                a["name"], b["name"], a["stn"], b["stn"], 100 * (b["stn"] / a["stn"] - 1),
                a["cortex"], b["cortex"], 100 * (b["cortex"] / a["cortex"] - 1))
            for a, b in pairs) + ".")
    p("")
    within = [t for t in tri if t["stn_dev"] <= GOAL]
    failed = [r for r in rows if not ran(r)]
    unsolved = [r for r in rows if r["status"].startswith("unsolved")]
    inverted = [r for r in rows if r["inverted"] > 0]
    met = tri and len(within) == len(tri) and not failed and not inverted and not unsolved

    def names(rs):
        return " (%s)" % ", ".join(r["name"] for r in rs) if rs else ""
    p("Goal (issue 25: every three consecutive STN shifts within %g %% of their mean, no "
      "inverted cell, no Newton failure): **%s** — %d of %d triples within, %d grid(s) "
      "failed%s, %d ran with steps unsolved%s, %d complete run(s) with inverted cells." % (
          100 * GOAL, "met" if met else "missed", len(within), len(tri), len(failed),
          names(failed), len(unsolved), names(unsolved), len(inverted)))
    return lines


def run(a, binary):
    if not a.grids:
        raise SystemExit("convergence needs --grids NXxNYxNZ,...")
    scene = os.path.abspath(a.spec)
    base = os.path.splitext(os.path.basename(scene))[0]
    out = engine.out_dir(a, "convergence-" + base)  # with the overrides' values
    # checked as the estimated grids run it (a key of the goal estimate, adapt.memory, is
    # refused without adapt.estimator=goal: with --estimate 0 every grid takes it)
    lo, hi, first = scene_box(binary, scene, (ESTIMATE if a.estimate is not None else []) + a.sets)
    target = a.target or first
    if target is None:
        raise SystemExit("%s has no target: the STN shift needs one (--target)" % scene)
    if a.cortex:
        cortex = [float(v) for v in a.cortex.split(",")]
    else:
        c, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        cortex = [c[0] + 0.45 * half[0], c[1] + half[1] - 0.003, c[2] + 0.3 * half[2]]
    probe = "convergence-cortex"
    end = 3.0 if a.end is None else a.end
    common = ["time.end=%g" % end, "output.every=0", "adapt.every=1000000",
              "probes=[{name: %s, point: [%.6g, %.6g, %.6g]}]" % ((probe,) + tuple(cortex))]
    grids = sorted(parse_grids(a.grids), key=lambda g: -grid_h(lo, hi, g))

    def estimated(g):
        return a.estimate is not None and grid_h(lo, hi, g) >= a.estimate - 1e-9

    jobs = []
    for g in grids:
        name = "%dx%dx%d" % g
        if a.only and name not in a.only:
            continue
        cmd = [binary, "run", scene, "--quiet"]
        for s in common + ["tissue.grid=[%d,%d,%d]" % g] + \
                (ESTIMATE if estimated(g) else []) + a.sets:
            cmd += ["--set", s]
        # exit 1 (the simulation failed: inverted cells, Newton) is a result, a row
        jobs.append(engine.Job(name, os.path.join(out, name), cmd, (0, 1)))
    done, failed = engine.run_jobs(jobs, workers=a.workers, scheduler=a.scheduler,
                                   skip_complete=a.reuse or a.restart,
                                   same_command=not a.reuse, threads=a.threads)
    rows = []
    for g in grids:
        name = "%dx%dx%d" % g
        if name not in done:
            continue
        r = measure(os.path.join(out, name), done[name], target, probe)
        r.update(name=name, grid=g, h=grid_h(lo, hi, g), estimated=estimated(g))
        rows.append(r)
    tri = triples(rows)
    lines = report(os.path.relpath(scene, engine.ROOT), a.sets, rows, tri)
    E = effectivity(rows) if a.estimate is not None else None
    if a.estimate is not None:
        lines += [""] + effectivity_report(E, target)
    lines.append("")
    lines.append("Target %s; cortical probe at [%s] m; %.0f s of wall time in the runs above "
                 "(the sum of their run.json; a shared machine)." % (
                     target, ", ".join("%.4g" % v for v in cortex), sum(r["wall"] for r in rows)))
    img = engine.plot_dir(a, out)
    name = os.path.basename(os.path.normpath(out))  # the plot is named after the folder
    name = name if name.startswith("convergence") else "convergence-" + name
    plot(rows, os.path.join(img, name + ".png"), "%s %s" % (base, " ".join(a.sets)))
    if E is not None and E["pairs"]:
        plot_effectivity(E, os.path.join(img, name + "-effectivity.png"),
                         "%s: goal estimate of %s, h ≥ %g mm" % (base, target, a.estimate))
    engine.write_report(out, lines)
    return engine.report_failures(failed)
