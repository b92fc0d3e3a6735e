#!/usr/bin/python3
"""Speed against error: runs the variants of a study, collects their
steps.csv / probes.csv / targets.csv and writes plots and a Markdown report.

    tools/study.py phantom [--binary PATH] [--out DIR] [--img DIR | --docs] [--only NAME ...]
                           [--fresh-reference] [--steps N] [--reuse | --restart]
                           [--workers N | --scheduler tcp://HOST:PORT] [--threads T]
    tools/study.py dbs     [the same options]
    tools/study.py sweep SPEC.yaml [--out DIR] [--fresh] [--workers N | --scheduler ...]

Variants run through dask.distributed (study_engine.py): a LocalCluster of
--workers processes on this machine (default 1 for phantom and dbs, whose
timings are the point; the number of cores for a sweep), or an existing
cluster given by --scheduler (docs/performance.md: a SLURM cluster through
dask-jobqueue). A failed variant is reported and left out; the others go
on. sweep: study_sweep.py (a base scene, lists of --set values, one table
and plots).

phantom (docs/phantom.md, seed 004 §3.1): cases/phantom/phantom.yaml on
uniform 8×4×4, 16×8×8, 32×16×16 grids and adaptive from 8×4×4 (θ = 0.3,
one level of hex2, hex3 or hex4; Dörfler 0.5 with hex2). The error of a run
is the displacement at the probes (1–7, 1A–1E) against a reference run on a
48×24×24 grid, finer than every run: |u − u_ref| over all probes and all
steps, its maximum and its root mean square. The reference is computed once
and cached in OUT/reference (with run.json recording its command and cost);
--fresh-reference runs it again. Every other variant is run every time,
since its timing is the point.

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
import math
import os
import subprocess
import sys
import time

import numpy as np
import matplotlib

import study_engine as engine
import study_sweep

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def adaptive(template, marking=None):
    sets = ["adapt.template=%s" % template, "adapt.max_level=1"]
    if marking:
        sets.append("adapt.marking=%s" % marking)
    return sets


PHANTOM = {
    "scene": os.path.join(ROOT, "cases", "phantom", "phantom.yaml"),
    "reference": ("reference", "uniform 48×24×24", ["tissue.grid=[48,24,24]"]),
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
    ],
    "axis": ["1", "2", "3", "4", "5", "6", "7"],
    "radial": ["1A", "1B", "1C", "1D", "1E"],
}


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def find_binary(given):
    for b in ([given] if given else [os.path.join(ROOT, "build", "needlehex")]):
        if b and os.path.exists(b):
            return os.path.abspath(b)
    raise SystemExit("no needlehex binary (build it: tools/run-case.sh, or pass --binary)")


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
    """{name: array (steps + 1, 3) of displacement (probes) or position}, steps."""
    pts, steps = {}, []
    for r in read_csv(os.path.join(out, fname)):
        s = int(r["step"])
        if not steps or steps[-1] != s:
            steps.append(s)
        if fname == "probes.csv":
            v = [float(r["ux"]), float(r["uy"]), float(r["uz"])]
        else:
            v = [float(r["x"]), float(r["y"]), float(r["z"]), float(r["distance"])]
        pts.setdefault(r["name"], []).append(v)
    return {k: np.array(v) for k, v in pts.items()}, np.array(steps)


def speed(st):
    t = 1e3 * st["t_step"][1:] if len(st["t_step"]) > 1 else 1e3 * st["t_step"]
    return {"max_dofs": int(st["dofs"].max()), "median": float(np.median(t)),
            "p95": float(np.percentile(t, 95)), "total": float(st["t_step"].sum()),
            "t_factor": 1e3 * float(np.median(st["t_factor"][1:])),
            "t_constraints": 1e3 * float(np.median(st["t_constraints"][1:])),
            "t_adapt": 1e3 * float(np.median(st["t_adapt"][1:]))}


def probe_error(u, ref, names):
    """Max and RMS of |u − u_ref| over the probes `names` and all steps."""
    d = np.concatenate([np.linalg.norm(u[n] - ref[n], axis=1) for n in names])
    return float(d.max()), float(np.sqrt(np.mean(d ** 2)))


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
            ax.plot(r["steps"], 1e6 * np.linalg.norm(r["u"][n], axis=1), r.get("style", "-"),
                    label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]), lw=1.2)
        ax.set_title("point %s" % n)
        ax.set_xlabel("step")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("|u| (µm)")
    legend_outside(np.atleast_1d(axes)[-1])
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(img, fname), dpi=110, bbox_inches="tight")
    plt.close(fig)
    log("wrote %s" % os.path.join(img, fname))


def style(name):
    return {"reference": "k--", "uniform-8x4x4": "C0-", "uniform-16x8x8": "C1-",
            "uniform-32x16x16": "C2-", "adaptive-hex2": "C3-", "adaptive-hex3": "C4-",
            "adaptive-hex4": "C5-", "adaptive-hex2-dorfler": "C6-", "adaptive-hex2-theta0.1": "C7-",
            "adaptive-hex4-theta0.1": "C8-"}.get(name, "-")


def plot_dir(a, out):
    """Where the PNGs go: --img, else docs/img with --docs, else OUT/img."""
    img = a.img or (os.path.join(ROOT, "docs", "img") if a.docs else os.path.join(out, "img"))
    os.makedirs(img, exist_ok=True)
    return img


def phantom(a, binary):
    st = PHANTOM
    out = a.out or os.path.join(ROOT, "out", "study", "phantom")
    img = plot_dir(a, out)
    names = st["axis"] + st["radial"]

    rname, rlabel, rsets = st["reference"]
    rdir = os.path.join(out, rname)
    selected = [(name, sets) for name, _, sets, _ in st["variants"] if not a.only or name in a.only]
    if a.fresh_reference or not os.path.exists(os.path.join(rdir, "run.json")):
        selected.insert(0, (rname, rsets))  # the longest run first
    infos = run_variants(a, binary, st["scene"], out, selected)
    if not os.path.exists(os.path.join(rdir, "run.json")):
        raise SystemExit("no reference run in %s" % rdir)
    with open(os.path.join(rdir, "run.json")) as f:
        rinfo = json.load(f)
    ref_u, ref_steps = read_points(rdir)
    ref = {"name": rname, "label": rlabel, "u": ref_u, "steps": ref_steps,
           "speed": speed(read_steps(rdir)), "style": "k--"}

    runs = []
    for name, label, sets, kind in st["variants"]:
        if name not in infos:
            continue
        d = os.path.join(out, name)
        info = infos[name]
        u, steps = read_points(d)
        if len(steps) != len(ref_steps):
            raise SystemExit("%s has %d steps, the reference %d: run the reference with the "
                             "same steps (--fresh-reference)" % (name, len(steps), len(ref_steps)))
        r = {"name": name, "label": label, "kind": kind, "u": u, "steps": steps,
             "speed": speed(read_steps(d)), "wall": info["wall"], "style": style(name)}
        r["err_max"], r["err_rms"] = probe_error(u, ref_u, names)
        runs.append(r)

    umax = max(float(np.linalg.norm(ref_u[n], axis=1).max()) for n in names)
    uni = [r for r in runs if r["kind"] == "uniform"]
    ada = [r for r in runs if r["kind"] == "adaptive"]
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
                ax.plot(fine["steps"], 1e6 * np.linalg.norm(fine["u"][n], axis=1), label=n)
            ax.set_title("32×16×16: " + title, fontsize=10)
            ax.set_xlabel("step")
            ax.set_ylabel("|u| (µm)")
            ax.grid(alpha=0.3)
            legend_outside(ax)
        fig.tight_layout()
        fig.savefig(os.path.join(img, "phantom_fine.png"), dpi=110, bbox_inches="tight")
        plt.close(fig)
    plot_probes(img, allruns, ["3"], "phantom_point3.png",
                "point 3: every run (templates hex2, hex3, hex4)")

    fig, ax = plt.subplots(figsize=(6, 4.2))
    for group, mk in ((uni, "o-"), (ada, "s")):
        for r in group:
            ax.loglog(r["speed"]["median"], 1e6 * r["err_rms"], mk, color=r["style"][:2], ms=7,
                      label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]))
    if len(uni) > 1:
        ax.loglog([r["speed"]["median"] for r in uni], [1e6 * r["err_rms"] for r in uni], "k:",
                  lw=1)
    ax.set_xlabel("median time per step (ms)")
    ax.set_ylabel("probe displacement error, RMS (µm)")
    ax.set_title("phantom: speed against error (reference %s)" % rlabel, fontsize=10)
    ax.grid(alpha=0.3, which="both")
    legend_outside(ax)
    fig.tight_layout()
    fig.savefig(os.path.join(img, "phantom_speed_error.png"), dpi=110, bbox_inches="tight")
    plt.close(fig)
    log("wrote %s" % os.path.join(img, "phantom_speed_error.png"))
    return 0


DBS = {
    "scene": os.path.join(ROOT, "cases", "dbs", "dbs.yaml"),
    # the scene is adaptive; the uniform runs never estimate (adapt.every beyond the last step)
    "variants": [
        ("coarse", "uniform coarse", ["adapt.every=1000000"], "uniform"),
        ("fine", "uniform fine", ["adapt.every=1000000", "tissue.grid=%s"], "uniform"),
        ("adaptive", "adaptive θ = 0.6", [], "adaptive"),
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
        pos, steps = read_points(d, "targets.csv")
        tgt = pos[st["target"]]
        tools = read_tools(d, st["cannula"])
        touched = [i for i, s in enumerate(tools["state"]) if s != "outside"]
        i_shift = max(touched[0] - 1, 0) if touched else len(steps) - 1  # last step before contact
        i_top = int(np.argmax(tools["depth"]))  # the cannula's deepest step: target reached
        r = {"name": name, "label": label, "kind": kind, "steps": steps, "wall": info["wall"],
             "distance": tgt[:, 3], "shift": float(np.linalg.norm(tgt[i_shift, :3] - tgt[0, :3])),
             "stn": np.linalg.norm(tgt[:, :3] - tgt[i_shift, :3], axis=1), "i_shift": i_shift,
             "i_top": i_top, "st": read_steps(d), "style": {"coarse": "C0-", "fine": "C2-",
                                                            "adaptive": "C3-"}[name]}
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
        p("- adaptive vs uniform fine: max dofs %d vs %d (ratio %.2f, goal ≤ 1/3); median ms/step "
          "%.1f vs %.1f (%.1f× faster, goal ≥ 5×); electrode–STN distance after the target is "
          "reached (step %d on): max difference %.3f mm at step %d, RMS %.3f mm, at the end %.3f mm "
          "(goal ≤ 0.3 mm)." % (
              A["speed"]["max_dofs"], F["speed"]["max_dofs"],
              A["speed"]["max_dofs"] / F["speed"]["max_dofs"], A["speed"]["median"],
              F["speed"]["median"], F["speed"]["median"] / A["speed"]["median"], i0,
              1e3 * dd.max(), i0 + int(np.argmax(dd)), 1e3 * np.sqrt(np.mean(dd ** 2)),
              1e3 * dd[-1]))
    if A:
        p("- adaptive whole procedure: %.1f s of steps (%.1f s wall; goal < 30 s)." % (
            A["speed"]["total"], A["wall"]))
    write_report(out, lines)

    def lines_plot(fname, ylabel, key, title, scale=1e3, vlines=True, from_shift=False,
                   logy=False):
        """One curve per run of r[key], or of steps.csv's column `key`."""
        fig, ax = plt.subplots(figsize=(6.4, 3.8))
        for r in runs:
            y = r["st"][key] if key in r["st"] else r[key]
            x = r["st"]["step"] if key in r["st"] else r["steps"]
            if from_shift:
                x, y = x[r["i_shift"]:], y[r["i_shift"]:]
            ax.plot(x, scale * np.asarray(y), r["style"], lw=1.3,
                    label="%s (max %d dofs)" % (r["label"], r["speed"]["max_dofs"]))
        if logy:
            ax.set_yscale("log")
        if vlines and runs:
            ax.axvline(runs[0]["i_top"], color="0.5", ls=":", lw=1)
            ax.axvline(runs[0]["i_shift"], color="0.5", ls="--", lw=1)
        ax.set_xlabel("step")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        legend_outside(ax)
        fig.tight_layout()
        fig.savefig(os.path.join(img, fname), dpi=110, bbox_inches="tight")
        plt.close(fig)
        log("wrote %s" % os.path.join(img, fname))

    lines_plot("dbs_distance.png", "electrode tip to STN (mm)", "distance",
               "electrode tip–STN distance (dashed: shift done; dotted: retraction starts)")
    lines_plot("dbs_stn.png", "STN displacement since the shift (mm)", "stn",
               "STN displacement relative to its post-shift position", from_shift=True)
    lines_plot("dbs_dofs.png", "dofs", "dofs", "degrees of freedom", scale=1, vlines=False)
    lines_plot("dbs_ms_step.png", "ms per step", "t_step", "time per step", vlines=False,
               logy=True)
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("study", choices=["phantom", "dbs", "sweep"])
    ap.add_argument("spec", nargs="?", help="sweep: the spec (YAML, see study_sweep.py)")
    ap.add_argument("--binary", default=None, help="needlehex (default build/needlehex)")
    ap.add_argument("--out", default=None, help="run folders and report (default out/study/STUDY)")
    ap.add_argument("--img", default=None, help="where the PNGs go (default OUT/img)")
    ap.add_argument("--docs", action="store_true",
                    help="write the PNGs to docs/img (the plots the docs show)")
    ap.add_argument("--only", nargs="*", help="run only these variants (names as in the report)")
    ap.add_argument("--fresh-reference", action="store_true", help="run the reference again")
    ap.add_argument("--steps", type=int, default=None, help="fewer steps (a quick look)")
    ap.add_argument("--reuse", action="store_true",
                    help="report on the runs already in OUT instead of running them again")
    ap.add_argument("--fresh", action="store_true", help="sweep: run complete variants again")
    # timing studies: one run at a time unless asked (runs in parallel share the cores)
    engine.add_arguments(ap, default_workers=None)
    a = ap.parse_args()
    if a.workers is None:
        a.workers = (os.cpu_count() or 1) if a.study == "sweep" else 1
    binary = find_binary(a.binary)
    if a.study == "sweep":
        if not a.spec:
            ap.error("sweep needs SPEC.yaml")
        return study_sweep.sweep(a, binary)
    return phantom(a, binary) if a.study == "phantom" else dbs(a, binary)


if __name__ == "__main__":
    sys.exit(main())
