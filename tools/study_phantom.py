"""tools/study.py phantom (docs/phantom.md, seed 004 §3.1): speed against error
of uniform and adaptive meshes on the needle phantom.

cases/phantom/phantom.yaml on uniform 8×4×4, 16×8×8, 32×16×16 grids and
adaptive from 8×4×4 (θ = 0.3, one level of hex2, hex3 or hex4; Dörfler 0.5
with hex2). The error of a run is the displacement at the probes (1–7,
1A–1E) against a reference run on a 48×24×24 grid, finer than every run:
|u − u_ref| over all probes and all steps, its maximum and its root mean
square. The reference is computed once and cached in OUT/reference (with
run.json recording its command and cost); --fresh-reference runs it again.
Every other variant is run every time, since its timing is the point.
--check-reference: the runs and the reference itself measured again against
a 64×32×32 run (cached the same way), over all probe-steps and split by
whether the needle's tip is within 5 mm of the probe.

Output: OUT/report.md (the tables; also printed), plots in OUT/img (--img
DIR: in DIR; --docs: in docs/img, where the docs take them from):
phantom_axis.png, phantom_radial.png, phantom_fine.png, phantom_point3.png,
phantom_speed_error.png.
"""
import json
import os

import numpy as np

import study_engine as engine
from outputs import read_points, read_steps, speed
from plotstyle import FIGSIZE, MARKER, legend_outside, plt, save, save_loglog

ROOT = engine.ROOT


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


def probe_error(u, ref, names):
    """Max and RMS of |u − u_ref| over the probes `names` and all steps."""
    d = np.concatenate([np.linalg.norm(u[n][:, :3] - ref[n][:, :3], axis=1) for n in names])
    return float(d.max()), float(np.sqrt(np.mean(d ** 2)))


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
    save(fig, os.path.join(img, fname), legend=np.atleast_1d(axes)[-1])  # right of the last panel


def style(name):
    return {"reference": "k--", "uniform-8x4x4": "C0-", "uniform-16x8x8": "C1-",
            "uniform-32x16x16": "C2-", "adaptive-hex2": "C3-", "adaptive-hex3": "C4-",
            "adaptive-hex4": "C5-", "adaptive-hex2-dorfler": "C6-", "adaptive-hex2-theta0.1": "C7-",
            "adaptive-hex4-theta0.1": "C8-", "adaptive-hex2-l2": "C9-",
            # goal-oriented runs dashed: their colours repeat those of the SPR runs
            "goal-hex2-l2": "C4--", "goal-hex2-l2-every4": "C5--", "goal-hex2-l2-tol": "C6--",
            "goal-hex2-l2-resolve": "C3--", "goal-hex2-l3": "C0--",
            "goal-hex2-l3-every4": "C1--", "goal-hex2-l2-tol-coarsen": "C2--"}.get(name, "C7--")


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
        engine.run_variants(a, binary, st["scene"], out, [(cname, csets)])
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
    for line in engine.table_head("run", "error max µm", "error RMS µm", "tip within 5 mm: RMS µm",
                                  "tip farther: RMS µm", "RMS against %s µm" % ref["label"]):
        p(line)
    for r in [ref] + runs:
        emax, erms = probe_error(r["u"], chk, names)
        near, away = tip_split(r["u"], chk, names, ctimes, probe_x, tip_x)
        p("| %s | %.3f | %.3f | %.3f | %.3f | %s |" % (
            r["label"], 1e6 * emax, 1e6 * erms, 1e6 * near, 1e6 * away,
            "%.3f" % (1e6 * r["err_rms"]) if "err_rms" in r else "–"))


def run(a, binary):
    st = PHANTOM
    out = engine.out_dir(a, "phantom")
    img = engine.plot_dir(a, out)
    names = st["axis"] + st["radial"]

    rname, rlabel, rdir, infos = engine.run_with_reference(a, binary, st, out)
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
    lines += engine.table_head("run", "max dofs", "median ms/step", "p95 ms/step", "total s",
                               "factor", "constraints", "adapt", "error max µm", "error RMS µm",
                               "RMS / max|u_ref|")
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
    engine.write_report(out, lines)

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
            legend_outside(ax)  # the layout makes room for both legends
        save(fig, os.path.join(img, "phantom_fine.png"))
    plot_probes(img, allruns, ["3"], "phantom_point3.png", "point 3: every run")

    fig, ax = plt.subplots(figsize=FIGSIZE)  # the legend goes right of it
    for group, mk in ((uni, MARKER["uniform"] + "-"), (ada, MARKER["adaptive"]),
                      (gor, MARKER["goal"])):
        for r in group:
            ax.loglog(r["speed"]["median"], 1e6 * r["err_rms"], mk, color=r["style"][:2], ms=7,
                      label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]))
    if len(uni) > 1:
        ax.loglog([r["speed"]["median"] for r in uni], [1e6 * r["err_rms"] for r in uni], "k:",
                  lw=1)
    save_loglog(fig, ax, os.path.join(img, "phantom_speed_error.png"), "median time per step (ms)",
                "probe displacement error, RMS (µm)",
                "phantom: speed against error (reference %s)" % rlabel)
    return 0
