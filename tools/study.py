#!/usr/bin/python3
"""Speed against error: runs the variants of a study, collects their
steps.csv / probes.csv / targets.csv and writes plots and a Markdown report.

    tools/study.py phantom [--binary PATH] [--out DIR] [--img DIR | --docs] [--only NAME ...]
                           [--fresh-reference] [--check-reference] [--steps N] [--reuse | --restart]
                           [--workers N | --scheduler tcp://HOST:PORT] [--threads T]
    tools/study.py dbs     [the same options]
    tools/study.py cube    [the same options]
    tools/study.py dbs-shift [the same options]
    tools/study.py dbs-goal  [the same options]
    tools/study.py sweep SPEC.yaml [--out DIR] [--fresh] [--workers N | --scheduler ...]
    tools/study.py plan SPEC.yaml  [the same]: one `needlehex plan` per variant

Variants run through dask.distributed (study_engine.py): a LocalCluster of
--workers processes on this machine (default 1 for phantom and dbs, whose
timings are the point; the number of cores for a sweep), or an existing
cluster given by --scheduler (docs/performance.md: a SLURM cluster through
dask-jobqueue). A failed variant is reported and left out; the others go
on. sweep: study_sweep.py (a base scene, lists of --set values, one table
and plots); plan: the same with one `needlehex plan` per variant (different
targets, stiffnesses, ...: one table of aims, misses, runs and times).

cube (docs/adaptivity.md, "Goal-oriented refinement"): the localized-load
block, probe P's displacement on uniform, SPR-driven and goal-driven meshes
against the goal-oriented sequence continued to 250 000 dofs, whose last
three meshes give the observed order and the extrapolated reference.

dbs-shift (docs/dbs.md, "Goal-oriented refinement on the brain shift"): the
brain-shift phase of cases/dbs/dbs-skull.yaml (t ≤ 3 s) on uniform 14, 10, 7 mm
grids, whose Richardson extrapolation (per component, observed orders) is the
reference, and goal-driven from 14 mm with 1–3 levels: STN displacement error,
effectivity of its estimate, the electrode tip–STN distance against the
reference, median ms/step against the 7 mm mesh's.

dbs-goal (docs/dbs.md, "Goal-oriented refinement of the whole procedure"): the
whole procedure of cases/dbs/dbs-skull.yaml (270 steps) on uniform 14, 10, 7, 5 mm
grids, whose per-step Richardson extrapolation through the finest three (observed
order per step; the 5 mm value with the 7 → 5 mm difference as its error bar where
the order is not sane; the 14, 10, 7 mm triple reported beside it) is the
reference, and on goal-driven and SPR-driven meshes from 14 mm: the
electrode tip–STN distance's error at every step after the target is reached,
the effectivity of error_estimate and distance_error_estimate, median ms/step
against the 7 mm mesh's; dbs_goal_error.png, dbs_goal_cost.png,
dbs_goal_effectivity.png.

phantom (docs/phantom.md, seed 004 §3.1): cases/phantom/phantom.yaml on
uniform 8×4×4, 16×8×8, 32×16×16 grids and adaptive from 8×4×4 (θ = 0.3,
one level of hex2, hex3 or hex4; Dörfler 0.5 with hex2). The error of a run
is the displacement at the probes (1–7, 1A–1E) against a reference run on a
48×24×24 grid, finer than every run: |u − u_ref| over all probes and all
steps, its maximum and its root mean square. The reference is computed once
and cached in OUT/reference (with run.json recording its command and cost);
--fresh-reference runs it again. Every other variant is run every time,
since its timing is the point. --check-reference: the runs and the reference
itself measured again against a 64×32×32 run (cached the same way), over all
probe-steps and split by whether the needle's tip is within 5 mm of the probe.

Speed: median and 95th percentile of t_step (ms) over the steps after the
first (the first includes CHOLMOD's symbolic analysis), and the total of
t_step. Timings depend on the machine's load: run the study on a quiet
machine.

Output: OUT/report.md (the tables; also printed), plots in OUT/img (--img
DIR: in DIR; --docs: in docs/img, where the docs take them from):
phantom_axis.png, phantom_radial.png, phantom_fine.png, phantom_point3.png,
phantom_speed_error.png. Needs numpy and matplotlib (Debian's python3-numpy,
python3-matplotlib); use /usr/bin/python3.
"""
import argparse
import csv
import json
import os
import sys

import numpy as np
import matplotlib

import study_engine as engine
import study_sweep

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def adaptive(template, marking=None, levels=1):
    sets = ["adapt.template=%s" % template, "adapt.max_level=%d" % levels]
    if marking:
        sets.append("adapt.marking=%s" % marking)
    return sets


def goal(template="hex2", levels=2, extra=()):
    """Goal-oriented (dual-weighted residual) refinement for every probe."""
    return ["adapt.estimator=goal"] + adaptive(template, levels=levels) + list(extra)


PHANTOM = {
    "scene": os.path.join(ROOT, "cases", "phantom", "phantom.yaml"),
    "reference": ("reference", "uniform 48×24×24", ["tissue.grid=[48,24,24]"]),
    # --check-reference: a finer mesh against which the runs and the reference itself are
    # measured again (how far the 48×24×24 reference is from converged at the probes)
    "check": ("reference-64x32x32", "uniform 64×32×32", ["tissue.grid=[64,32,32]"]),
    # name, label, overrides, kind
    "variants": [
        ("uniform-8x4x4", "uniform 8×4×4", [], "uniform"),
        ("uniform-16x8x8", "uniform 16×8×8", ["tissue.grid=[16,8,8]"], "uniform"),
        ("uniform-32x16x16", "uniform 32×16×16", ["tissue.grid=[32,16,16]"], "uniform"),
        ("adaptive-hex2", "adaptive hex2", adaptive("hex2"), "adaptive"),
        ("adaptive-hex3", "adaptive hex3", adaptive("hex3"), "adaptive"),
        ("adaptive-hex4", "adaptive hex4", adaptive("hex4"), "adaptive"),
        ("adaptive-hex2-dorfler", "adaptive hex2 Dörfler 0.5",
         adaptive("hex2", "{strategy: dorfler, fraction: 0.5}"), "adaptive"),
        # beyond the seed: a wider refined zone (θ = 0.1) against the far-field pollution
        ("adaptive-hex2-theta0.1", "adaptive hex2 θ = 0.1",
         adaptive("hex2", "{strategy: max, theta: 0.1}"), "adaptive"),
        ("adaptive-hex4-theta0.1", "adaptive hex4 θ = 0.1",
         adaptive("hex4", "{strategy: max, theta: 0.1}"), "adaptive"),
        # issue 14: SPR and goal-oriented refinement with two levels of hex2 (locally 32×16×16)
        ("adaptive-hex2-l2", "SPR hex2, 2 levels", adaptive("hex2", levels=2), "adaptive"),
        ("goal-hex2-l2", "goal hex2, 2 levels", goal(), "goal"),
        ("goal-hex2-l2-every4", "goal hex2, 2 levels, every 4", goal(extra=["adapt.every=4"]),
         "goal"),
        ("goal-hex2-l2-tol", "goal hex2, 2 levels, tolerance 0.03 µm, ≤ 9000 dofs",
         goal(extra=["adapt.tolerance=3e-8", "adapt.max_dofs=9000"]), "goal"),
        ("goal-hex2-l2-tol-coarsen", "goal hex2, 2 levels, tolerance 0.03 µm, ≤ 9000 dofs, coarsen 0.05",
         goal(extra=["adapt.tolerance=3e-8", "adapt.max_dofs=9000", "adapt.coarsen={fraction: 0.05}"]),
         "goal"),
        # each step re-solved once on the mesh its estimate asked for (no one-step lag)
        ("goal-hex2-l2-resolve", "goal hex2, 2 levels, resolve 1", goal(extra=["adapt.resolve=1"]),
         "goal"),
        # a third level (locally 64×32×32) where the goal estimate asks for it: probes 1–4 lie
        # 2 mm from the shaft's constraint points, which 2 levels (h = 1.25 mm) do not resolve
        ("goal-hex2-l3", "goal hex2, 3 levels", goal(levels=3), "goal"),
        ("goal-hex2-l3-every4", "goal hex2, 3 levels, every 4", goal(levels=3, extra=["adapt.every=4"]),
         "goal"),
    ],
    "axis": ["1", "2", "3", "4", "5", "6", "7"],
    "radial": ["1A", "1B", "1C", "1D", "1E"],
    # x of the probes (m) and of the needle's tip at time t (s): cases/phantom/phantom.yaml
    "probe_x": dict([(str(i), 0.005 * i) for i in range(1, 8)]
                    + [(n, 0.005) for n in ("1A", "1B", "1C", "1D", "1E")]),
    "tip_x": lambda t: -0.0005 + 0.02 * min(t, 1.0),
}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def find_binary(given):
    for b in ([given] if given else [os.path.join(ROOT, "build", "needlehex")]):
        if b and os.path.exists(b):
            return os.path.abspath(b)
    raise SystemExit("no needlehex binary (build it: tools/run-case.sh, or pass --binary)")


def run_with_reference(a, binary, st, out):
    """Runs the study's selected variants (--only) and, when missing or with
    --fresh-reference, its reference first (the longest run); returns the
    reference's name, label and folder and the runs' records."""
    rname, rlabel, rsets = st["reference"]
    rdir = os.path.join(out, rname)
    selected = [(name, sets) for name, _, sets, _ in st["variants"] if not a.only or name in a.only]
    if a.fresh_reference or not os.path.exists(os.path.join(rdir, "run.json")):
        selected.insert(0, (rname, rsets))  # the longest run first
    infos = run_variants(a, binary, st["scene"], out, selected)
    if not os.path.exists(os.path.join(rdir, "run.json")):
        raise SystemExit("no reference run in %s" % rdir)
    return rname, rlabel, rdir, infos


def run_variants(a, binary, scene, out, variants):
    """Runs the variants [(name, sets)] of a study into OUT/NAME through the execution engine
    (study_engine.py: --workers, --scheduler, --threads); with --reuse a variant already
    complete in OUT is reported on, not run again (--restart: only if its command is the
    same). Returns {name: run.json record} of the complete ones; failed ones are reported."""
    jobs = []
    for name, sets in variants:
        cmd = [binary, "run", scene, "--quiet"]
        for s in sets + (["time.steps=%d" % a.steps] if a.steps else []):
            cmd += ["--set", s]
        jobs.append(engine.Job(name, os.path.join(out, name), cmd))
    done, failed = engine.run_jobs(jobs, workers=a.workers, scheduler=a.scheduler,
                                   skip_complete=a.reuse or a.restart, same_command=not a.reuse,
                                   threads=a.threads)
    engine.report_failures(failed)
    return done


def write_report(out, lines):
    """Prints the report and writes it to OUT/report.md."""
    report = "\n".join(lines)
    print(report)
    with open(os.path.join(out, "report.md"), "w") as f:
        f.write(report + "\n")


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def read_steps(out):
    rows = read_csv(os.path.join(out, "steps.csv"))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def read_points(out, fname="probes.csv"):
    """{name: array (steps + 1, 4): displacement and error estimate (probes) or position and
    distance to the tool's tip (targets)}, the steps, their times (s)."""
    pts, steps, times = {}, [], []
    for r in read_csv(os.path.join(out, fname)):
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


def speed(st):
    t = 1e3 * st["t_step"][1:] if len(st["t_step"]) > 1 else 1e3 * st["t_step"]
    return {"max_dofs": int(st["dofs"].max()), "median": float(np.median(t)),
            "p95": float(np.percentile(t, 95)), "total": float(st["t_step"].sum()),
            "t_factor": 1e3 * float(np.median(st["t_factor"][1:])),
            "t_constraints": 1e3 * float(np.median(st["t_constraints"][1:])),
            "t_adapt": 1e3 * float(np.median(st["t_adapt"][1:]))}


def probe_error(u, ref, names):
    """Max and RMS of |u − u_ref| over the probes `names` and all steps."""
    d = np.concatenate([np.linalg.norm(u[n][:, :3] - ref[n][:, :3], axis=1) for n in names])
    return float(d.max()), float(np.sqrt(np.mean(d ** 2)))


def save_loglog(fig, ax, img, fname, xlabel, ylabel, title):
    """Labels, grid and legend of a log-log plot; writes IMG/FNAME."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()  # before the legend: tight_layout would shrink the axes to fit it in
    legend_outside(ax)
    fig.savefig(os.path.join(img, fname), dpi=110, bbox_inches="tight")
    plt.close(fig)
    log("wrote %s" % os.path.join(img, fname))


def effectivity(u, ref, names):
    """Median, quartiles of estimate / true error and the share in [0.7, 1.5]."""
    vals = []
    for n in names:
        est = u[n][:, 3]
        err = np.linalg.norm(u[n][:, :3] - ref[n][:, :3], axis=1)
        ok = np.isfinite(est) & (err > 0)
        vals.extend(est[ok] / err[ok])
    if not vals:
        return None
    v = np.array(vals)
    return (float(np.median(v)), float(np.percentile(v, 25)), float(np.percentile(v, 75)),
            int(round(100 * np.mean((v >= 0.7) & (v <= 1.5)))))


def pareto(points):
    """Indices of runs that no other run beats in both coordinates."""
    keep = []
    for i, (a, b) in enumerate(points):
        if not any((c <= a and d <= b and (c < a or d < b)) for j, (c, d) in enumerate(points) if j != i):
            keep.append(i)
    return keep


def legend_outside(ax):
    """The legend right of the axes, never over the curves (saved with bbox_inches="tight")."""
    ax.legend(fontsize=8, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)


def plot_probes(img, runs, names, fname, title):
    fig, axes = plt.subplots(1, len(names), figsize=(4.2 * len(names), 3.4), sharey=False)
    for ax, n in zip(np.atleast_1d(axes), names):
        for r in runs:
            ax.plot(r["times"], 1e6 * np.linalg.norm(r["u"][n][:, :3], axis=1), r.get("style", "-"),
                    label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]), lw=1.2)
        ax.set_title("point %s" % n if len(names) > 1 else title, fontsize=10)
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("|u| (µm)")
    if len(names) > 1:  # one panel: its title says it all (a suptitle would overlap it)
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    legend_outside(np.atleast_1d(axes)[-1])  # right of the last panel, after the layout
    fig.savefig(os.path.join(img, fname), dpi=110, bbox_inches="tight")
    plt.close(fig)
    log("wrote %s" % os.path.join(img, fname))


def style(name):
    return {"reference": "k--", "uniform-8x4x4": "C0-", "uniform-16x8x8": "C1-",
            "uniform-32x16x16": "C2-", "adaptive-hex2": "C3-", "adaptive-hex3": "C4-",
            "adaptive-hex4": "C5-", "adaptive-hex2-dorfler": "C6-", "adaptive-hex2-theta0.1": "C7-",
            "adaptive-hex4-theta0.1": "C8-", "adaptive-hex2-l2": "C9-",
            # goal-oriented runs dashed: their colours repeat those of the SPR runs
            "goal-hex2-l2": "C4--", "goal-hex2-l2-every4": "C5--", "goal-hex2-l2-tol": "C6--",
            "goal-hex2-l2-resolve": "C3--", "goal-hex2-l3": "C0--",
            "goal-hex2-l3-every4": "C1--", "goal-hex2-l2-tol-coarsen": "C2--"}.get(name, "C7--")


def plot_dir(a, out):
    """Where the PNGs go: --img, else docs/img with --docs, else OUT/img."""
    img = a.img or (os.path.join(ROOT, "docs", "img") if a.docs else os.path.join(out, "img"))
    os.makedirs(img, exist_ok=True)
    return img


def tip_split(u, ref, names, times, probe_x, tip_x):
    """RMS of |u − u_ref| over the probe-steps with the tool's tip within 5 mm (along x) of the
    probe, and over the others; x and tip in mm."""
    near, away = [], []
    for n in names:
        e = np.linalg.norm(u[n][:, :3] - ref[n][:, :3], axis=1)
        close = np.abs(tip_x - probe_x[n]) <= 5.0
        near.append(e[close])
        away.append(e[~close])
    rms = lambda v: float(np.sqrt(np.mean(np.concatenate(v) ** 2)))  # noqa: E731
    return rms(near), rms(away)


def check_reference(a, binary, st, out, ref, runs, names, p):
    """--check-reference: runs (once, cached like the reference) the finer uniform mesh of
    st["check"] and reports every run's error and the reference's own against it, in all, with
    the tip within 5 mm of the probe and away from it."""
    cname, clabel, csets = st["check"]
    cdir = os.path.join(out, cname)
    if a.fresh_reference or not os.path.exists(os.path.join(cdir, "run.json")):
        run_variants(a, binary, st["scene"], out, [(cname, csets)])
    if not os.path.exists(os.path.join(cdir, "run.json")):
        raise SystemExit("no check reference run in %s" % cdir)
    chk, csteps, ctimes = read_points(cdir)
    if len(csteps) != len(ref["steps"]):
        raise SystemExit("%s has %d steps, the reference %d" % (cname, len(csteps),
                                                                   len(ref["steps"])))
    probe_x = {n: 1e3 * st["probe_x"][n] for n in names}
    tip_x = 1e3 * np.array([st["tip_x"](t) for t in ctimes])
    cspeed = speed(read_steps(cdir))
    p("")
    p("Against the finer %s (%d dofs, median %.0f ms/step): error RMS over all probe-steps, over "
      "those with the needle's tip within 5 mm (along x) of the probe, and over the others; "
      "the reference %s measured the same way." % (clabel, cspeed["max_dofs"], cspeed["median"],
                                                     ref["label"]))
    p("")
    p("| run | error max µm | error RMS µm | tip within 5 mm: RMS µm | tip farther: RMS µm "
      "| RMS against %s µm |" % ref["label"])
    p("|---|---|---|---|---|---|")
    for r in [ref] + runs:
        emax, erms = probe_error(r["u"], chk, names)
        near, away = tip_split(r["u"], chk, names, ctimes, probe_x, tip_x)
        p("| %s | %.3f | %.3f | %.3f | %.3f | %s |" % (
            r["label"], 1e6 * emax, 1e6 * erms, 1e6 * near, 1e6 * away,
            "%.3f" % (1e6 * r["err_rms"]) if "err_rms" in r else "–"))


def phantom(a, binary):
    st = PHANTOM
    out = a.out or os.path.join(ROOT, "out", "study", "phantom")
    img = plot_dir(a, out)
    names = st["axis"] + st["radial"]

    rname, rlabel, rdir, infos = run_with_reference(a, binary, st, out)
    with open(os.path.join(rdir, "run.json")) as f:
        rinfo = json.load(f)
    ref_u, ref_steps, ref_times = read_points(rdir)
    ref = {"name": rname, "label": rlabel, "u": ref_u, "steps": ref_steps, "times": ref_times,
           "speed": speed(read_steps(rdir)), "style": "k--"}

    runs = []
    for name, label, sets, kind in st["variants"]:
        if name not in infos:
            continue
        d = os.path.join(out, name)
        info = infos[name]
        u, steps, times = read_points(d)
        if len(steps) != len(ref_steps):
            raise SystemExit("%s has %d steps, the reference %d: run the reference with the "
                             "same steps (--fresh-reference)" % (name, len(steps), len(ref_steps)))
        r = {"name": name, "label": label, "kind": kind, "u": u, "steps": steps, "times": times,
             "speed": speed(read_steps(d)), "wall": info["wall"], "style": style(name)}
        r["err_max"], r["err_rms"] = probe_error(u, ref_u, names)
        runs.append(r)

    umax = max(float(np.linalg.norm(ref_u[n][:, :3], axis=1).max()) for n in names)
    uni = [r for r in runs if r["kind"] == "uniform"]
    ada = [r for r in runs if r["kind"] == "adaptive"]
    gor = [r for r in runs if r["kind"] == "goal"]
    lines = []
    p = lines.append
    p("Reference: %s, %d dofs, %d steps, %.0f s in all (median %.0f ms/step); "
      "largest probe displacement %.2f µm." % (rlabel, ref["speed"]["max_dofs"], len(ref_steps) - 1,
                                                 rinfo["wall"], ref["speed"]["median"], 1e6 * umax))
    p("")
    p("| run | max dofs | median ms/step | p95 ms/step | total s | factor | constraints | adapt "
      "| error max µm | error RMS µm | RMS / max|u_ref| |")
    p("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        s = r["speed"]
        p("| %s | %d | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %.3f | %.3f | %.1f %% |" % (
            r["label"], s["max_dofs"], s["median"], s["p95"], s["total"], s["t_factor"],
            s["t_constraints"], s["t_adapt"], 1e6 * r["err_max"], 1e6 * r["err_rms"],
            100 * r["err_rms"] / umax))
    p("")
    p("(factor, constraints, adapt: median ms/step of that phase; error over probes "
      "1–7, 1A–1E and all steps.)")
    p("")
    byname = {r["name"]: r for r in runs}
    goals = [("adaptive-hex2", "uniform-16x8x8"), ("adaptive-hex4", "uniform-32x16x16")]
    for an, un in goals:
        if an in byname and un in byname:
            A, U = byname[an], byname[un]
            ok = A["err_rms"] <= U["err_rms"] and A["err_max"] <= U["err_max"]
            ratio = U["speed"]["median"] / A["speed"]["median"]
            p("- %s vs %s: error RMS %.3f vs %.3f µm, max %.3f vs %.3f µm (error goal: %s); "
              "median ms/step %.2f vs %.2f, %.1f× faster (speed goal ≥ 5×: %s)." % (
                  A["label"], U["label"], 1e6 * A["err_rms"], 1e6 * U["err_rms"],
                  1e6 * A["err_max"], 1e6 * U["err_max"],
                  "met" if ok else "missed", A["speed"]["median"], U["speed"]["median"],
                  ratio, "met" if ratio >= 5 else "missed"))
    for r in gor:
        if "uniform-32x16x16" not in byname:
            break
        U = byname["uniform-32x16x16"]
        ratio = U["speed"]["median"] / r["speed"]["median"]
        p("- %s vs uniform 32×16×16: error RMS %.3f vs %.3f µm (%s), max %.3f vs %.3f µm; "
          "median ms/step %.2f vs %.2f, %.1f× faster (goal ≥ 10× at no larger RMS error: %s)." % (
              r["label"], 1e6 * r["err_rms"], 1e6 * U["err_rms"],
              "reached" if r["err_rms"] <= U["err_rms"] else "not reached",
              1e6 * r["err_max"], 1e6 * U["err_max"], r["speed"]["median"], U["speed"]["median"],
              ratio, "met" if ratio >= 10 and r["err_rms"] <= U["err_rms"] else "missed"))
        eff = effectivity(r["u"], ref_u, names)
        if eff is not None:
            p("  Effectivity |estimate| / |u_ref − u| of its error_estimate over probes and "
              "estimated steps: median %.2f, quartiles %.2f–%.2f, %d %% of the values in "
              "[0.7, 1.5] (estimate: the mean over a box of half-width r at the probe; error: "
              "the point value)." % eff)
    front = pareto([(r["speed"]["median"], r["err_rms"]) for r in runs])
    p("- Pareto front of (median ms/step, RMS error) over all runs: %s." % (
        ", ".join(runs[i]["label"] for i in front)))
    beaten = []
    for r in ada:
        by = [q["label"] for q in uni if q["speed"]["median"] < r["speed"]["median"]
              and q["err_rms"] < r["err_rms"]]
        if by:
            beaten.append("%s (by %s)" % (r["label"], ", ".join(by)))
    p("- Adaptive runs beaten by a uniform run that is both faster and more accurate: %s." % (
        "; ".join(beaten) if beaten else "none"))
    if a.check_reference:
        check_reference(a, binary, st, out, ref, runs, names, p)
    write_report(out, lines)

    allruns = runs + [ref]
    plot_probes(img, [r for r in allruns if r["name"] in
                      ("uniform-8x4x4", "uniform-16x8x8", "uniform-32x16x16", "adaptive-hex2",
                       "reference")],
                ["1", "3", "5"], "phantom_axis.png",
                "points along the needle: uniform and adaptive (hex2, θ = 0.3)")
    plot_probes(img, [r for r in allruns if r["name"] in
                      ("uniform-8x4x4", "uniform-16x8x8", "uniform-32x16x16", "adaptive-hex2",
                       "reference")],
                ["1A", "1C", "1E"], "phantom_radial.png",
                "points normal to the needle: uniform and adaptive (hex2, θ = 0.3)")
    fine = byname.get("uniform-32x16x16")
    if fine:
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.4))
        for ax, group, title in ((axes[0], st["axis"], "along the needle"),
                                 (axes[1], st["radial"], "normal to the needle")):
            for n in group:
                ax.plot(fine["times"], 1e6 * np.linalg.norm(fine["u"][n][:, :3], axis=1), label=n)
            ax.set_title("32×16×16: " + title, fontsize=10)
            ax.set_xlabel("time (s)")
            ax.set_ylabel("|u| (µm)")
            ax.grid(alpha=0.3)
            legend_outside(ax)
        fig.tight_layout()
        fig.savefig(os.path.join(img, "phantom_fine.png"), dpi=110, bbox_inches="tight")
        plt.close(fig)
    plot_probes(img, allruns, ["3"], "phantom_point3.png", "point 3: every run")

    fig, ax = plt.subplots(figsize=(6.5, 4.6))  # the legend goes right of it
    for group, mk in ((uni, "o-"), (ada, "s"), (gor, "^")):
        for r in group:
            ax.loglog(r["speed"]["median"], 1e6 * r["err_rms"], mk, color=r["style"][:2], ms=7,
                      label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]))
    if len(uni) > 1:
        ax.loglog([r["speed"]["median"] for r in uni], [1e6 * r["err_rms"] for r in uni], "k:",
                  lw=1)
    save_loglog(fig, ax, img, "phantom_speed_error.png", "median time per step (ms)",
                "probe displacement error, RMS (µm)",
                "phantom: speed against error (reference %s)" % rlabel)
    return 0


DBS = {
    "scene": os.path.join(ROOT, "cases", "dbs", "dbs.yaml"),
    # the scene is adaptive; the uniform runs never estimate (adapt.every beyond the last step)
    "variants": [
        ("coarse", "uniform coarse", ["adapt.every=1000000"], "uniform"),
        ("fine", "uniform fine", ["adapt.every=1000000", "tissue.grid=%s"], "uniform"),
        ("adaptive", "adaptive θ = 0.6", [], "adaptive"),
        # issue 14: goal-oriented refinement for the STN (θ = 0.6, one level of hex2 as the
        # adaptive run: with two levels a 3.5 mm cell inverts at step 163, docs/dbs.md)
        ("goal", "goal θ = 0.6", ["adapt.estimator=goal"], "goal"),
    ],
    "target": "STN",
    "cannula": "cannula",
}


def scene_grid(scene):
    """tissue.grid of a scene file (a flow list on one line)."""
    with open(scene) as f:
        for line in f:
            t = line.split("#")[0].strip()
            if t.startswith("grid:"):
                return [int(v) for v in t[5:].strip(" []").split(",")]
    raise SystemExit("%s: no tissue.grid line" % scene)


def read_tools(out, name):
    rows = [r for r in read_csv(os.path.join(out, "tools.csv")) if r["name"] == name]
    return {"step": np.array([int(r["step"]) for r in rows]),
            "time": np.array([float(r["time"]) for r in rows]),
            "depth": np.array([float(r["depth"]) for r in rows]),
            "state": [r["state"] for r in rows]}


def phases(out, cannula):
    """The procedure's phases from tools.csv (row indices, step 0 = index 0): the last step
    before the cannula touches the brain (the shift is over), the first at the target depth
    (the depth in the tissue stops growing there; to 1 µm), the last before the retraction."""
    tools = read_tools(out, cannula)
    n = len(tools["state"])
    touched = [i for i, s in enumerate(tools["state"]) if s != "outside"]
    i_shift = max(touched[0] - 1, 0) if touched else n - 1
    depth = np.asarray(tools["depth"])
    i_top = int(np.nonzero(depth >= depth.max() - 1e-6)[0][0])
    back = [i for i, s in enumerate(tools["state"]) if s == "retracting"]
    i_back = back[0] - 1 if back else n - 1
    return i_shift, i_top, i_back


CUBE = {
    "scene": os.path.join(ROOT, "cases", "adapt-localized.yaml"),
    "probe": "P",
    # name, label, overrides, kind; every run static, one mesh per step
    "variants": [
        ("uniform-8x4x4", "uniform 8×4×4", ["adapt.max_level=0", "time.steps=1"], "uniform"),
        ("uniform-16x8x8", "uniform 16×8×8",
         ["adapt.max_level=0", "time.steps=1", "tissue.grid=[16,8,8]"], "uniform"),
        ("uniform-24x12x12", "uniform 24×12×12",
         ["adapt.max_level=0", "time.steps=1", "tissue.grid=[24,12,12]"], "uniform"),
        ("uniform-32x16x16", "uniform 32×16×16",
         ["adapt.max_level=0", "time.steps=1", "tissue.grid=[32,16,16]"], "uniform"),
        ("spr", "SPR (max θ = 0.3)", ["time.steps=10", "adapt.max_dofs=60000"], "adaptive"),
        ("goal", "goal (max θ = 0.3)",
         ["adapt.estimator=goal", "time.steps=10", "adapt.max_dofs=60000"], "goal"),
    ],
    # the reference: the goal-oriented sequence continued to 250 000 dofs
    "reference": ("reference", "goal-adaptive to 250 000 dofs",
                  ["adapt.estimator=goal", "time.steps=11", "adapt.max_dofs=250000"]),
}


def cube(a, binary):
    """The localized-load block (docs/adaptivity.md): probe P's displacement
    on SPR-driven, goal-driven and uniform meshes against a converged value."""
    st = CUBE
    out = a.out or os.path.join(ROOT, "out", "study", "cube")
    img = a.img or os.path.join(ROOT, "docs", "img")
    os.makedirs(img, exist_ok=True)

    def series(d):
        u = read_points(d)[0]
        sr = read_steps(d)
        return {"dofs": sr["dofs"], "uz": u[st["probe"]][1:, 2], "est": u[st["probe"]][1:, 3],
                "iterations": sr["iterations"], "t_step": sr["t_step"]}

    rname, rlabel, rdir, infos = run_with_reference(a, binary, st, out)
    ref = series(rdir)
    # Convergence of the reference: the last three meshes, u(N) = u_inf + C N^-q.
    (n1, n2, n3), (u1, u2, u3) = ref["dofs"][-3:], ref["uz"][-3:]
    lo, hi = 0.05, 5.0
    for _ in range(200):  # q solving (u1 - u2)/(u2 - u3) = (n1^-q - n2^-q)/(n2^-q - n3^-q)
        q = 0.5 * (lo + hi)
        g = (n1 ** -q - n2 ** -q) / (n2 ** -q - n3 ** -q)
        if g < (u1 - u2) / (u2 - u3):
            lo = q
        else:
            hi = q
    u_inf = u3 + (u3 - u2) * n3 ** -q / (n2 ** -q - n3 ** -q)
    runs = []
    for name, label, sets, kind in st["variants"]:
        if name not in infos:
            continue
        d = os.path.join(out, name)
        r = dict(series(d), name=name, label=label, kind=kind)
        r["err"] = np.abs(r["uz"] - u_inf)
        runs.append(r)
    lines = []
    p = lines.append
    p("Reference (%s): u_z(P) on its last three meshes %s µm at %s dofs; observed order in N "
      "%.2f (≈ %.2f in h), extrapolated u_z(P) = %.6f µm; |u_inf − u(last)| = %.2e µm; its own "
      "estimate on the last mesh %.2e µm." % (
          rlabel, ", ".join("%.6f" % (1e6 * v) for v in ref["uz"][-3:]),
          ", ".join("%d" % v for v in ref["dofs"][-3:]), q, 3 * q, 1e6 * u_inf,
          1e6 * abs(u_inf - u3), 1e6 * ref["est"][-1]))
    p("")
    p("| run | mesh | dofs | u_z(P) µm | error µm | estimate µm | effectivity |")
    p("|---|---|---|---|---|---|---|")
    for r in runs:
        for i in range(len(r["dofs"])):
            est = r["est"][i]
            p("| %s | %d | %d | %.6f | %.3e | %s | %s |" % (
                r["label"], i + 1, r["dofs"][i], 1e6 * r["uz"][i], 1e6 * r["err"][i],
                "%.3e" % (1e6 * est) if est == est else "–",
                "%.2f" % (est / r["err"][i]) if est == est and r["err"][i] > 0 else "–"))
    byname = {r["name"]: r for r in runs}
    if "spr" in byname and "goal" in byname:
        S, G = byname["spr"], byname["goal"]
        p("")
        p("At equal dofs (the SPR error interpolated log-log in dofs at each goal mesh's dofs):")
        for i in range(len(G["dofs"])):
            N = G["dofs"][i]
            if N < S["dofs"][0] or N > S["dofs"][-1]:
                continue
            e_s = float(np.exp(np.interp(np.log(N), np.log(S["dofs"]), np.log(S["err"]))))
            p("- %d dofs: goal %.3e µm, SPR %.3e µm, ratio %.2f (goal ≤ 1/2: %s)" % (
                N, 1e6 * G["err"][i], 1e6 * e_s, G["err"][i] / e_s,
                "met" if G["err"][i] <= 0.5 * e_s else "missed"))
    write_report(out, lines)

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for r in runs:
        mk = {"uniform": "o-", "adaptive": "s-", "goal": "^-"}[r["kind"]]
        if r["kind"] == "uniform":
            continue
        ax.loglog(r["dofs"], 1e6 * r["err"], mk, label="%s: error" % r["label"])
        if r["kind"] == "goal":
            ax.loglog(r["dofs"], 1e6 * r["est"], "^:", color="C1", label="goal: its estimate")
    uni = [r for r in runs if r["kind"] == "uniform"]
    if uni:
        ax.loglog([r["dofs"][0] for r in uni], [1e6 * r["err"][0] for r in uni], "ko-",
                  label="uniform: error")
    save_loglog(fig, ax, img, "cube_goal_error.png", "dofs", "|u_z(P) − u_ref| (µm)",
                "localized load: error of the probe displacement")
    return 0


def dbs(a, binary):
    st = DBS
    out = a.out or os.path.join(ROOT, "out", "study", "dbs")
    img = plot_dir(a, out)
    g = scene_grid(st["scene"])
    runs = []
    infos = run_variants(a, binary, st["scene"], out, [
        (name, [s % ("[%d,%d,%d]" % tuple(2 * v for v in g)) if "%s" in s else s for s in sets])
        for name, _, sets, _ in st["variants"] if not a.only or name in a.only])
    for name, label, sets, kind in st["variants"]:
        if name not in infos:
            continue
        d = os.path.join(out, name)
        info = infos[name]
        pos, steps, times = read_points(d, "targets.csv")
        tgt = pos[st["target"]]
        i_shift, i_top, i_back = phases(d, st["cannula"])
        r = {"name": name, "label": label, "kind": kind, "steps": steps, "times": times,
             "wall": info["wall"], "i_back": i_back,
             "distance": tgt[:, 3], "shift": float(np.linalg.norm(tgt[i_shift, :3] - tgt[0, :3])),
             "stn": np.linalg.norm(tgt[:, :3] - tgt[i_shift, :3], axis=1), "i_shift": i_shift,
             "i_top": i_top, "st": read_steps(d), "style": {"coarse": "C0-", "fine": "C2-",
                                                            "adaptive": "C3-", "goal": "C1-"}[name]}
        r["speed"] = speed(r["st"])
        runs.append(r)
    byname = {r["name"]: r for r in runs}
    lines = []
    p = lines.append
    p("| run | max dofs | median ms/step | p95 ms/step | total s | wall s | STN shift mm "
      "| final electrode–STN mm |")
    p("|---|---|---|---|---|---|---|---|")
    for r in runs:
        s = r["speed"]
        p("| %s | %d | %.1f | %.1f | %.1f | %.1f | %.2f | %.2f |" % (
            r["label"], s["max_dofs"], s["median"], s["p95"], s["total"], r["wall"],
            1e3 * r["shift"], 1e3 * r["distance"][-1]))
    p("")
    A, F = byname.get("adaptive"), byname.get("fine")
    if A and F and len(A["distance"]) == len(F["distance"]):
        i0 = max(A["i_top"], F["i_top"])
        dd = np.abs(A["distance"][i0:] - F["distance"][i0:])
        im = i0 + int(np.argmax(dd))
        p("- adaptive vs uniform fine: max dofs %d vs %d (ratio %.2f, goal ≤ 1/3); median ms/step "
          "%.1f vs %.1f (%.1f× faster, goal ≥ 5×); electrode–STN distance after the target is "
          "reached (step %d, t = %.2f s, on): max difference %.3f mm at step %d (t = %.2f s), RMS "
          "%.3f mm, at the end %.3f mm (goal ≤ 0.3 mm)." % (
              A["speed"]["max_dofs"], F["speed"]["max_dofs"],
              A["speed"]["max_dofs"] / F["speed"]["max_dofs"], A["speed"]["median"],
              F["speed"]["median"], F["speed"]["median"] / A["speed"]["median"], i0,
              A["times"][i0], 1e3 * dd.max(), im, A["times"][im],
              1e3 * np.sqrt(np.mean(dd ** 2)), 1e3 * dd[-1]))
    G = byname.get("goal")
    if G and F and len(G["distance"]) == len(F["distance"]):
        i0 = max(G["i_top"], F["i_top"])
        dd = np.abs(G["distance"][i0:] - F["distance"][i0:])
        p("- goal vs uniform fine (not converged: docs/dbs.md): max dofs %d vs %d; median ms/step "
          "%.1f vs %.1f; electrode–STN distance from step %d: max difference %.3f mm, RMS %.3f mm, "
          "at the end %.3f mm." % (
              G["speed"]["max_dofs"], F["speed"]["max_dofs"], G["speed"]["median"],
              F["speed"]["median"], i0, 1e3 * dd.max(), 1e3 * np.sqrt(np.mean(dd ** 2)),
              1e3 * dd[-1]))
    if A:
        p("- adaptive whole procedure: %.1f s of steps (%.1f s wall; goal < 30 s)." % (
            A["speed"]["total"], A["wall"]))
    loads = [x for n in infos for x in infos[n].get("load", [])]
    if loads:  # timings under load are not those of a quiet machine
        p("- 1-minute load average at the runs' starts and ends: %.1f–%.1f (2 cores)." % (
            min(loads), max(loads)))
    write_report(out, lines)

    def lines_plot(fname, ylabel, key, title, scale=1e3, vlines=True, from_shift=False,
                   logy=False, zoom=None):
        """One curve per run of r[key], or of steps.csv's column `key`, against time; zoom: a
        second panel from that time on (the end of the procedure, on its own scale)."""
        fig, axes = plt.subplots(1, 2 if zoom else 1, figsize=(10.5 if zoom else 7.5, 3.8),
                                 squeeze=False)
        ph = byname.get("adaptive", runs[0])  # the phases: the scene as written
        for k, ax in enumerate(axes[0]):
            for r in runs:
                y = scale * np.asarray(r["st"][key] if key in r["st"] else r[key])
                x = r["st"]["time"] if key in r["st"] else r["times"]
                keep = x >= (zoom if k else (x[r["i_shift"]] if from_shift else -1))
                ax.plot(x[keep], y[keep], r["style"], lw=1.3,
                        label="%s (max %d dofs)" % (r["label"], r["speed"]["max_dofs"]))
            if logy:
                ax.set_yscale("log")
            for i, ls, what in ((ph["i_shift"], "--", "cannula reaches the brain"),
                                (ph["i_top"], ":", "cannula at the target depth"),
                                (ph["i_back"], "-.", "retraction starts")):
                t = ph["times"][i]
                if vlines and (not from_shift or i >= ph["i_shift"]) and (not k or t >= zoom):
                    ax.axvline(t, color="0.45", ls=ls, lw=1, label="%s (%.2f s)" % (what, t))
            ax.set_xlabel("time (s)")
            ax.set_ylabel(ylabel)
            ax.set_title(title if not k else "from %g s on" % zoom, fontsize=10)
            ax.grid(alpha=0.3)
        handles, labels = axes[0][0].get_legend_handles_labels()  # every curve and phase
        axes[0][-1].legend(handles, labels, fontsize=8, loc="center left",
                           bbox_to_anchor=(1.01, 0.5), frameon=False)
        fig.tight_layout()
        fig.savefig(os.path.join(img, fname), dpi=110, bbox_inches="tight")
        plt.close(fig)
        log("wrote %s" % os.path.join(img, fname))

    lines_plot("dbs_distance.png", "electrode tip to STN (mm)", "distance",
               "electrode tip–STN distance", zoom=7.6)
    lines_plot("dbs_stn.png", "STN displacement since the shift (mm)", "stn",
               "STN displacement relative to its post-shift position", from_shift=True)
    lines_plot("dbs_dofs.png", "dofs", "dofs", "degrees of freedom", scale=1, vlines=False)
    lines_plot("dbs_ms_step.png", "ms per step", "t_step", "time per step", vlines=False,
               logy=True)
    return 0


DBS_SHIFT = {
    "scene": os.path.join(ROOT, "cases", "dbs", "dbs-skull.yaml"),
    # the brain shift only (drained over 1 s, settled until 3 s; the tools still)
    "common": ["time.end=3", "output.every=0"],
    # name, label, overrides, kind, h (mm: the uniform grids' cell size)
    "uniform": [
        ("uniform-10x12x9", "uniform 10×12×9", ["adapt.every=1000000", "tissue.grid=[10,12,9]"], 14.0),
        ("uniform-14x17x13", "uniform 14×17×13", ["adapt.every=1000000", "tissue.grid=[14,17,13]"],
         10.0),
        ("uniform-20x25x19", "uniform 20×25×19", ["adapt.every=1000000", "tissue.grid=[20,25,19]"],
         7.0),
    ],
    "goal": [
        ("goal-l1", "goal from 10×12×9, 1 level",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1"]),
        ("goal-l2", "goal from 10×12×9, 2 levels",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=2"]),
        ("goal-l3", "goal from 10×12×9, 3 levels",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=3"]),
    ],
    "target": "STN",
    "tool": "electrode",
}


def richardson(h, J):
    """Observed order p and extrapolated value from three values J at spacings h (coarse to
    fine): adapt_study.richardson on k = 1/h; p = None (and J at the finest) when no order is
    observed."""
    from adapt_study import richardson as through_three
    w, _, p = through_three([1.0 / x for x in h], list(J))
    return (p, w) if np.isfinite(p) else (None, J[2])


def dbs_shift(a, binary):
    """The brain-shift phase of cases/dbs/dbs-skull.yaml (docs/dbs.md, "Goal-oriented
    refinement on the brain shift"): the STN's displacement and the electrode tip–STN distance
    at t = 3 s on three uniform meshes (Richardson: observed order, extrapolated reference) and
    on goal-driven meshes from the coarsest; effectivity of the goal estimate, cost per step."""
    st = DBS_SHIFT
    out = a.out or os.path.join(ROOT, "out", "study", "dbs-shift")
    sel = [(n, sets + st["common"]) for n, _, sets, *_ in st["uniform"] + st["goal"]
           if not a.only or n in a.only]
    infos = run_variants(a, binary, st["scene"], out, sel)

    def final(name):
        d = os.path.join(out, name)
        pos = read_points(d, "targets.csv")[0]
        rows = [r for r in read_csv(os.path.join(d, "targets.csv")) if r["name"] == st["target"]]
        tip = [r for r in read_csv(os.path.join(d, "tools.csv")) if r["name"] == st["tool"]][-1]
        x = pos[st["target"]]
        return {"u": x[-1, :3] - x[0, :3], "x": x[-1, :3], "distance": x[-1, 3],
                "tip": np.array([float(tip[k]) for k in ("tip_x", "tip_y", "tip_z")]),
                "est": float(rows[-1].get("error_estimate", "nan")),
                "dest": float(rows[-1].get("distance_error_estimate", "nan")),
                "speed": speed(read_steps(d)), "wall": infos[name]["wall"]}

    uni = [(n, l, h) for n, l, _, h in st["uniform"] if n in infos]
    if len(uni) < 3:
        raise SystemExit("dbs-shift needs the three uniform runs")
    U = {n: final(n) for n, _, _ in uni}
    hs = [h for _, _, h in uni]
    X0 = U[uni[0][0]]["x"] - U[uni[0][0]]["u"]
    comp = [richardson(hs, [U[n]["u"][k] for n, _, _ in uni]) for k in range(3)]
    pm, mag = richardson(hs, [np.linalg.norm(U[n]["u"]) for n, _, _ in uni])
    u_ref = np.array([c[1] for c in comp])
    unc = np.abs(u_ref - U[uni[2][0]]["u"])  # per component: |u_ref − u(finest)|
    tip = U[uni[2][0]]["tip"]
    d_ref = float(np.linalg.norm(tip - (X0 + u_ref)))
    lines = []
    p = lines.append
    p("Reference (Richardson from h = %s mm): STN displacement per component %s mm (observed "
      "orders %s); |u_ref| = %.4f mm (order of the magnitude %s: %.4f mm); its uncertainty "
      "|u_ref − u(7 mm)| = %.4f mm; electrode tip–STN distance %.4f mm." % (
          ", ".join("%g" % h for h in hs), ", ".join("%.4f" % (1e3 * v) for v in u_ref),
          ", ".join("%.2f" % c[0] if c[0] else "none" for c in comp), 1e3 * np.linalg.norm(u_ref),
          "%.2f" % pm if pm else "none", 1e3 * mag, 1e3 * np.linalg.norm(unc), 1e3 * d_ref))
    p("")
    p("| run | max dofs | median ms/step | total s | wall s | STN shift mm | error mm | estimate mm "
      "| effectivity | distance mm | distance error mm | its estimate mm |")
    p("|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = [(n, l) for n, l, _ in uni] + [(n, l) for n, l, _ in st["goal"] if n in infos]
    R = {}
    for n, l in rows:
        r = U.get(n) or final(n)
        R[n] = r
        e = float(np.linalg.norm(r["u"] - u_ref))
        de = abs(r["distance"] - d_ref)
        s = r["speed"]
        p("| %s | %d | %.1f | %.1f | %.1f | %.4f | %.4f | %s | %s | %.4f | %.4f | %s |" % (
            l, s["max_dofs"], s["median"], s["total"], r["wall"], 1e3 * np.linalg.norm(r["u"]),
            1e3 * e, "%.4f" % (1e3 * r["est"]) if r["est"] == r["est"] else "–",
            "%.2f" % (r["est"] / e) if r["est"] == r["est"] else "–", 1e3 * r["distance"],
            1e3 * de, "%.4f" % (1e3 * r["dest"]) if r["dest"] == r["dest"] else "–"))
    ref_ms = R[uni[2][0]]["speed"]["median"]
    p("")
    for n, l, _ in st["goal"]:
        if n not in R:
            continue
        r = R[n]
        de = abs(r["distance"] - d_ref)
        p("- %s: distance within %.4f mm of the reference (goal ≤ 0.3 mm: %s) at %.1f ms/step, "
          "%.2f of the 7 mm mesh's %.1f (goal ≤ 1/4: %s)." % (
              l, 1e3 * de, "met" if de <= 3e-4 else "missed", r["speed"]["median"],
              r["speed"]["median"] / ref_ms, ref_ms,
              "met" if r["speed"]["median"] <= 0.25 * ref_ms else "missed"))
    write_report(out, lines)
    return 0


DBS_GOAL = {
    "scene": os.path.join(ROOT, "cases", "dbs", "dbs-skull.yaml"),
    "common": ["output.every=0"],  # no frames: the cost is the steps'
    # name, label, overrides, h (mm): the reference's three meshes, coarse first
    "uniform": [
        ("uniform-14mm", "uniform 10×12×9 (14 mm)",
         ["adapt.every=1000000", "tissue.grid=[10,12,9]"], 14.0),
        ("uniform-10mm", "uniform 14×17×13 (10 mm)",
         ["adapt.every=1000000", "tissue.grid=[14,17,13]"], 10.0),
        ("uniform-7mm", "uniform 20×25×19 (7 mm)",
         ["adapt.every=1000000", "tissue.grid=[20,25,19]"], 7.0),
        ("uniform-5mm", "uniform 28×34×26 (5 mm)",
         ["adapt.every=1000000", "tissue.grid=[28,34,26]"], 5.0),
    ],
    "baseline": "uniform-7mm",  # the goal's cost is measured against this mesh's ms/step
    # name, label, overrides, kind: adaptive runs from the 14 mm grid (hex2, max θ = 0.6 as the
    # scene; the goal is the scene's target, the STN)
    "adaptive": [
        ("spr-l1", "SPR from 14 mm, 1 level", ["tissue.grid=[10,12,9]", "adapt.max_level=1"],
         "spr"),
        ("spr-l2", "SPR from 14 mm, 2 levels", ["tissue.grid=[10,12,9]", "adapt.max_level=2"],
         "spr"),
        ("spr-l1-4300", "SPR from 14 mm, 1 level, ≤ 4300 dofs",
         ["tissue.grid=[10,12,9]", "adapt.max_level=1", "adapt.max_dofs=4300"], "spr"),
        ("goal-l1", "goal from 14 mm, 1 level",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1"], "goal"),
        ("goal-l1-theta0.3", "goal from 14 mm, 1 level, θ = 0.3",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.marking={strategy: max, theta: 0.3}"], "goal"),
        # tolerance mode: marks among the cells that can still be refined (θ = 0.6 alone stops
        # at 4236 dofs: its marked cells are all at max_level), until the budget
        ("goal-l1-tol", "goal from 14 mm, 1 level, tolerance 2 µm, ≤ 8000 dofs",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.tolerance=2e-6", "adapt.max_dofs=8000"], "goal"),
        # fails at step 163 (t = 8.15 s, the retraction's first steps): a 3.5 mm cell at the
        # channel inverts (docs/dbs.md; so does the same with tolerance 2 µm and ≤ 8000 dofs);
        # kept so that the study shows it
        ("goal-l2", "goal from 14 mm, 2 levels",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=2"], "goal"),
    ],
    "target": "STN",
    "cannula": "cannula",
    "order": (1.0, 5.99),  # a per-step order is used inside [1, 6): per_step_reference
    "resolved": 3.0,  # effectivity only where the true error exceeds 3× the reference's bar
}


def per_step_reference(h, F, order):
    """The converged reference of a quantity at every step from three uniform runs.
    h: cell sizes (mm, coarse first); F: array (3, steps) of the quantity on those meshes.
    Per step, Richardson (richardson above: observed order p and extrapolated value); the
    order is sane when it lies in `order` = [lo, hi): p ≥ 1 bounds the extrapolation to
    1/(r^p − 1) ≤ 2.5 times the last difference at the spacing ratios r = 1.4–1.43 used here,
    and the bracket's top (6) means no root was found inside it. Where it is sane the reference is the extrapolated value and its error bar
    |f∞ − f(finest)|; elsewhere (differences changing sign, order out of range) the finest
    mesh's value with |f(finest) − f(middle)| as its error bar. Returns (reference, bar,
    order (nan where none), sane: bool per step)."""
    n = F.shape[1]
    ref, bar, p = np.array(F[2], float), np.abs(F[2] - F[1]), np.full(n, np.nan)
    sane = np.zeros(n, bool)
    for i in range(n):
        if max(abs(F[1, i] - F[0, i]), abs(F[2, i] - F[1, i])) < 1e-15:
            continue  # the same on every mesh (step 0)
        q, w = richardson(h, F[:, i])
        if q is not None:
            p[i] = q
            if order[0] <= q < order[1]:
                sane[i], ref[i], bar[i] = True, w, abs(w - F[2, i])
    return ref, bar, p, sane


def dbs_goal(a, binary):
    """The whole procedure of cases/dbs/dbs-skull.yaml (docs/dbs.md, "Goal-oriented
    refinement of the whole procedure"): the electrode tip–STN distance and the STN's
    position at every step on goal-driven, SPR-driven and uniform meshes against the per-step
    Richardson reference of the finest three uniform meshes; effectivity of the goal
    estimates; cost per step against the 7 mm mesh's."""
    st = DBS_GOAL
    out = a.out or os.path.join(ROOT, "out", "study", "dbs-goal")
    img = plot_dir(a, out)
    sel = [(n, sets + st["common"]) for n, _, sets, *_ in st["uniform"] + st["adaptive"]
           if not a.only or n in a.only or n in [u[0] for u in st["uniform"]]]
    infos = run_variants(a, binary, st["scene"], out, sel)
    if any(n not in infos for n, *_ in st["uniform"]):
        raise SystemExit("dbs-goal needs every uniform run (the reference)")

    def load(name, label, kind):
        d = os.path.join(out, name)
        pos, steps, times = read_points(d, "targets.csv")
        rows = [r for r in read_csv(os.path.join(d, "targets.csv")) if r["name"] == st["target"]]
        sr = read_steps(d)
        i_shift, i_top, i_back = phases(d, st["cannula"])
        return {"name": name, "label": label, "kind": kind, "times": times, "steps": steps,
                "x": pos[st["target"]][:, :3], "d": pos[st["target"]][:, 3],
                "est": np.array([float(r.get("error_estimate", "nan")) for r in rows]),
                "dest": np.array([float(r.get("distance_error_estimate", "nan")) for r in rows]),
                "speed": speed(sr), "rows": int(sr["constraints"].max()), "st": sr,
                "i_shift": i_shift, "i_top": i_top, "i_back": i_back,
                "load": infos[name].get("load", [])}

    U = [dict(load(nm, l, "uniform"), h=h) for nm, l, _, h in st["uniform"]]
    n = len(U[0]["d"])
    if any(len(r["d"]) != n for r in U):
        raise SystemExit("the uniform runs have different numbers of steps")
    i0 = max(r["i_top"] for r in U)  # the target reached on every uniform mesh
    after = np.arange(n) >= i0

    def reference(R):
        """The per-step reference from three uniform runs R (coarse first)."""
        h = [r["h"] for r in R]
        d = per_step_reference(h, np.array([r["d"] for r in R]), st["order"])
        xs = [per_step_reference(h, np.array([r["x"][:, k] for r in R]), st["order"])
              for k in range(3)]
        return {"h": h, "d": d[0], "d_bar": d[1], "d_p": d[2], "d_ok": d[3],
                "x": np.array([c[0] for c in xs]).T,
                "x_bar": np.linalg.norm(np.array([c[1] for c in xs]).T, axis=1),
                "x_ok": xs[0][3] & xs[1][3] & xs[2][3]}

    ref = reference(U[-3:])  # the finest three
    prev = reference(U[:3]) if len(U) > 3 else None  # the coarser triple, for comparison
    d_ref, d_bar, x_ref, x_bar = ref["d"], ref["d_bar"], ref["x"], ref["x_bar"]
    runs = U + [load(nm, l, k) for nm, l, _, k in st["adaptive"] if nm in infos]
    base = [r for r in U if r["name"] == st["baseline"]][0]
    ref_ms = base["speed"]["median"]
    for r in runs:
        if len(r["d"]) != n:
            raise SystemExit("%s has %d steps, the reference %d" % (r["name"], len(r["d"]), n))
        r["err"] = np.abs(r["d"] - d_ref)
        r["xerr"] = np.linalg.norm(r["x"] - x_ref, axis=1)
        e = r["err"][after]
        r["max"], r["at"] = float(e.max()), i0 + int(np.argmax(e))
        r["rms"] = float(np.sqrt(np.mean(e ** 2)))
        r["ratio"] = r["speed"]["median"] / ref_ms

    def eff(est, err, bar):
        """Effectivity est / err over the steps ≥ 1 with an estimate whose true error the
        reference resolves (err > st["resolved"] × its bar): (median, min, max, steps, of)."""
        ok = np.isfinite(est) & (np.arange(n) >= 1)
        use = ok & (err > st["resolved"] * bar)
        if not use.any():
            return None
        v = est[use] / err[use]
        return float(np.median(v)), float(v.min()), float(v.max()), int(use.sum()), int(ok.sum())

    lines = []
    p = lines.append
    for R, what in ((ref, "the reference"), (prev, "the coarser triple")):
        if R is None:
            continue
        pa = R["d_p"][after & R["d_ok"]]
        q = (np.median(pa), *np.percentile(pa, [25, 75]), pa.min(), pa.max()) if len(pa) else \
            (np.nan,) * 5
        p("%s: per step, Richardson through the uniform %s mm meshes (study.py richardson, "
          "observed order; used where it lies in [%g, 6), else the finest mesh's value with its "
          "difference to the middle one as its error bar). Electrode tip–STN distance after the "
          "target is reached (step %d, t = %.2f s, on; %d steps): order sane at %d steps "
          "(median %.2f, quartiles %.2f–%.2f, range %.2f–%.2f), fallback at %d (%d with "
          "differences changing sign); error bar median %.4f mm, max %.4f mm. STN position: "
          "%d steps of %d with all three components' orders sane; error bar (norm) median "
          "%.4f mm, max %.4f mm." % (
              what[0].upper() + what[1:], ", ".join("%g" % h for h in R["h"]), st["order"][0],
              i0, U[0]["times"][i0], after.sum(), len(pa), *q,
              int((after & ~R["d_ok"]).sum()), int((after & ~np.isfinite(R["d_p"])).sum()),
              1e3 * np.median(R["d_bar"][after]), 1e3 * R["d_bar"][after].max(),
              int(R["x_ok"][1:].sum()), n - 1, 1e3 * np.median(R["x_bar"][1:]),
              1e3 * R["x_bar"][1:].max()))
        p("")
    if prev is not None:
        dd = np.abs(prev["d"] - d_ref)[after]
        p("The coarser triple's distance reference against the finest three's after the target: "
          "max difference %.4f mm (t = %.2f s), median %.4f mm." % (
              1e3 * dd.max(), U[0]["times"][i0 + int(np.argmax(dd))], 1e3 * np.median(dd)))
        p("")
    i_s = base["i_shift"]
    shift = [float(np.linalg.norm(r["x"][i_s] - r["x"][0])) for r in U]
    ps, s_ref = richardson(ref["h"], shift[-3:])  # of the magnitude, as dbs_convergence.py
    p("Whole procedure (tools/dbs_convergence.py's quantities): final distance %s mm on %s mm "
      "→ %.4f mm (%s); STN shift |x(t_s) − X| at t_s = %.2f s %s mm → %.4f mm (%s)." % (
          ", ".join("%.4f" % (1e3 * r["d"][-1]) for r in U),
          ", ".join("%g" % h for *_, h in st["uniform"]), 1e3 * d_ref[-1],
          "order %.2f" % ref["d_p"][-1] if ref["d_ok"][-1] else
          "fallback, bar %.4f mm" % (1e3 * d_bar[-1]), base["times"][i_s],
          ", ".join("%.4f" % (1e3 * v) for v in shift), 1e3 * s_ref,
          "order %.2f" % ps if ps else "no order"))
    p("")
    p("| run | max dofs | max rows | median ms/step | / 7 mm | total s | max \\|d − d_ref\\| mm "
      "(t s) | RMS mm | final d mm | effectivity of error_estimate: median (range; steps) "
      "| of distance_error_estimate |")
    p("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in runs:
        s = r["speed"]
        cells = []
        for est, err, bar in ((r["est"], r["xerr"], x_bar), (r["dest"], r["err"], d_bar)):
            e = eff(est, err, bar)
            r.setdefault("eff", []).append(e)
            cells.append("%.2f (%.2f–%.2f; %d of %d)" % e if e else "–")
        p("| %s | %d | %d | %.1f | %.3f | %.1f | %.4f (%.2f) | %.4f | %.4f | %s | %s |" % (
            r["label"], s["max_dofs"], r["rows"], s["median"], r["ratio"], s["total"],
            1e3 * r["max"], r["times"][r["at"]], 1e3 * r["rms"], 1e3 * r["d"][-1], *cells))
    p("")
    p("(d: the electrode tip–STN distance; max and RMS over the steps from %d on, t ≥ %.2f s; "
      "rows: constraint rows, skull and tools; effectivity: the estimate over the true error "
      "|run − reference| at the steps where that error exceeds %g× the reference's bar.)" % (
          i0, U[0]["times"][i0], st["resolved"]))
    p("")
    for r in runs[len(U):]:
        p("- %s: max |d − d_ref| %.4f mm after the target (goal ≤ 0.3 mm: %s); median ms/step "
          "%.1f, %.3f of the 7 mm mesh's %.1f (goal ≤ 1/4: %s)." % (
              r["label"], 1e3 * r["max"], "met" if r["max"] <= 3e-4 else "missed",
              r["speed"]["median"], r["ratio"], ref_ms, "met" if r["ratio"] <= 0.25 else "missed"))
    lost = [nm for nm, *_ in st["adaptive"] if nm not in infos and (not a.only or nm in a.only)]
    if lost:
        p("- not complete (the reason above, on stderr): %s." % ", ".join(lost))
    loads = [x for r in runs for x in r["load"]]
    if loads:
        p("- 1-minute load average at the runs' starts and ends: %.1f–%.1f (2 cores)." % (
            min(loads), max(loads)))
    write_report(out, lines)

    def style(r):
        return {"uniform": "o", "spr": "s", "goal": "^"}[r["kind"]]

    colors = {r["name"]: "C%d" % k for k, r in enumerate(runs)}
    t = U[0]["times"]
    fig, ax = plt.subplots(figsize=(11, 4.8))
    ax.fill_between(t, 1e-6, np.maximum(1e3 * d_bar, 1e-6), color="0.85", step="mid",
                    label="reference's error bar")
    for r in runs:  # goal solid and thick, SPR dashed, uniform thin
        ax.semilogy(t[1:], np.maximum(1e3 * r["err"][1:], 1e-6),
                    {"uniform": "-", "spr": "--", "goal": "-"}[r["kind"]], color=colors[r["name"]],
                    lw={"uniform": 0.9, "spr": 1.1, "goal": 1.6}[r["kind"]],
                    label="%s: %.1f ms/step" % (r["label"], r["speed"]["median"]))
    ax.axhline(0.3, color="k", ls="--", lw=1, label="goal 0.3 mm")
    for i, ls, what in ((base["i_shift"], "--", "cannula reaches the brain"),
                        (base["i_top"], ":", "cannula at the target depth"),
                        (base["i_back"], "-.", "retraction starts")):
        ax.axvline(t[i], color="0.45", ls=ls, lw=1, label="%s (%.2f s)" % (what, t[i]))
    ax.set_ylim(1e-4, None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|d − d_ref| (mm)")
    ax.set_title("dbs-skull: error of the electrode tip–STN distance against the per-step "
                 "Richardson reference", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    legend_outside(ax)
    fig.tight_layout()
    fig.savefig(os.path.join(img, "dbs_goal_error.png"), dpi=110, bbox_inches="tight")
    plt.close(fig)
    log("wrote %s" % os.path.join(img, "dbs_goal_error.png"))

    fig, ax = plt.subplots(figsize=(9, 5))
    for r in runs:
        ax.loglog(r["speed"]["median"], 1e3 * r["max"], style(r), color=colors[r["name"]], ms=8,
                  label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]))
    ax.loglog([r["speed"]["median"] for r in U], [1e3 * r["max"] for r in U], "k:", lw=1)
    ax.axhline(0.3, color="k", ls="--", lw=1, label="goal: 0.3 mm")
    ax.axvline(0.25 * ref_ms, color="0.4", ls="-.", lw=1,
               label="goal: 1/4 of %s's ms/step" % base["label"])
    save_loglog(fig, ax, img, "dbs_goal_cost.png", "median time per step (ms)",
                "max |d − d_ref| after the target (mm)",
                "dbs-skull, whole procedure: error against cost")

    gor = [r for r in runs if r["kind"] == "goal"]
    if gor:
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
        for ax, key, ekey, bar, title in (
                (axes[0], "xerr", "est", x_bar,
                 "STN displacement: |x − x_ref| and error_estimate"),
                (axes[1], "err", "dest", d_bar,
                 "tip–STN distance: |d − d_ref| and distance_error_estimate")):
            ax.fill_between(t, 1e-6, np.maximum(1e3 * bar, 1e-6), color="0.85", step="mid",
                            label="reference's error bar")
            for r in gor:
                c = colors[r["name"]]
                ax.semilogy(t[1:], np.maximum(1e3 * r[key][1:], 1e-6), "-", color=c, lw=1.1,
                            label="%s: true error" % r["label"])
                ax.semilogy(t[1:], 1e3 * r[ekey][1:], ":", color=c, lw=1.4,
                            label="%s: its estimate" % r["label"])
            ax.set_ylim(1e-4, None)
            ax.set_xlabel("time (s)")
            ax.set_ylabel("mm")
            ax.set_title(title, fontsize=10)
            ax.grid(alpha=0.3, which="both")
        legend_outside(axes[1])
        fig.tight_layout()
        fig.savefig(os.path.join(img, "dbs_goal_effectivity.png"), dpi=110, bbox_inches="tight")
        plt.close(fig)
        log("wrote %s" % os.path.join(img, "dbs_goal_effectivity.png"))
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("study", choices=["phantom", "dbs", "dbs-shift", "dbs-goal", "sweep", "plan",
                                      "cube"])
    ap.add_argument("spec", nargs="?",
                    help="sweep, plan: the spec (YAML, see study_sweep.py)")
    ap.add_argument("--binary", default=None, help="needlehex (default build/needlehex)")
    ap.add_argument("--out", default=None, help="run folders and report (default out/study/STUDY)")
    ap.add_argument("--img", default=None, help="where the PNGs go (default OUT/img)")
    ap.add_argument("--docs", action="store_true",
                    help="write the PNGs to docs/img (the plots the docs show)")
    ap.add_argument("--only", nargs="*", help="run only these variants (names as in the report)")
    ap.add_argument("--fresh-reference", action="store_true", help="run the reference again")
    ap.add_argument("--check-reference", action="store_true",
                    help="phantom: measure the runs and the reference against a finer mesh too "
                    "(64×32×32, cached in OUT like the reference)")
    ap.add_argument("--steps", type=int, default=None, help="fewer steps (a quick look)")
    ap.add_argument("--reuse", action="store_true",
                    help="report on the runs already in OUT instead of running them again")
    ap.add_argument("--fresh", action="store_true", help="sweep: run complete variants again")
    # timing studies: one run at a time unless asked (runs in parallel share the cores)
    engine.add_arguments(ap, default_workers=None)
    a = ap.parse_args()
    if a.workers is None:
        a.workers = (os.cpu_count() or 1) if a.study in ("sweep", "plan") else 1
    binary = find_binary(a.binary)
    if a.study in ("sweep", "plan"):
        if not a.spec:
            ap.error("%s needs SPEC.yaml" % a.study)
        return study_sweep.sweep(a, binary, "plan" if a.study == "plan" else None)
    return {"phantom": phantom, "dbs": dbs, "dbs-shift": dbs_shift, "dbs-goal": dbs_goal,
            "cube": cube}[a.study](a, binary)


if __name__ == "__main__":
    sys.exit(main())
