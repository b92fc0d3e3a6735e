"""tools/study.py dbs (docs/dbs.md): the whole procedure of cases/dbs/dbs.yaml on
the uniform coarse and fine grids, adaptive (SPR, θ = 0.6) and goal-driven
for the STN: dofs, time per step, the STN's shift and the electrode tip–STN
distance; dbs_distance.png, dbs_stn.png, dbs_dofs.png, dbs_ms_step.png.

Also the procedure's phases (phases, phase_lines) for dbs-goal and
tools/dbs_convergence.py.
"""
import os

import numpy as np

import study_engine as engine
from outputs import read_points, read_steps, read_tools, speed
from plotstyle import legend_outside, plt, save

ROOT = engine.ROOT

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


def phases(out, cannula):
    """The procedure's phases from tools.csv (row indices, step 0 = index 0): the last step
    before the cannula touches the brain (the shift is over), the first at the target depth
    (the depth in the tissue stops growing there; to 1 µm), the last before the retraction.
    A run that ends before the cannula touches the brain (tools/study.py --steps: the shift
    alone) is all shift: the three are its last row."""
    tools = read_tools(out, cannula)
    n = len(tools["state"])
    touched = [i for i, s in enumerate(tools["state"]) if s != "outside"]
    if not touched:
        return n - 1, n - 1, n - 1
    i_shift = max(touched[0] - 1, 0)
    depth = np.asarray(tools["depth"])
    i_top = int(np.nonzero(depth >= depth.max() - 1e-6)[0][0])
    back = [i for i, s in enumerate(tools["state"]) if s == "retracting"]
    i_back = back[0] - 1 if back else n - 1
    return i_shift, i_top, i_back


# the phases of the procedure (phases()): the key of their row index, line style, what happens
PHASES = (("i_shift", "--", "cannula reaches the brain"),
          ("i_top", ":", "cannula at the target depth"),
          ("i_back", "-.", "retraction starts"))


def phase_lines(ax, run, times, keep=lambda i, t: True):
    """A vertical line, labelled, at each phase of `run` (a dict with PHASES' keys) that
    keep(row index, time) accepts; times: the run's times (s)."""
    for key, ls, what in PHASES:
        i = run[key]
        t = times[i]
        if keep(i, t):
            ax.axvline(t, color="0.45", ls=ls, lw=1, label="%s (%.2f s)" % (what, t))


def run(a, binary):
    st = DBS
    out = engine.out_dir(a, "dbs")
    img = engine.plot_dir(a, out)
    g = scene_grid(st["scene"])
    runs = []
    infos = engine.run_variants(a, binary, st["scene"], out, [
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
    lines += engine.table_head("run", "max dofs", "median ms/step", "p95 ms/step", "total s",
                               "wall s", "STN shift mm", "final electrode–STN mm")
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
    engine.write_report(out, lines)

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
            phase_lines(ax, ph, ph["times"], lambda i, t: vlines and (
                not from_shift or i >= ph["i_shift"]) and (not k or t >= zoom))
            ax.set_xlabel("time (s)")
            ax.set_ylabel(ylabel)
            ax.set_title(title if not k else "from %g s on" % zoom, fontsize=10)
            ax.grid(alpha=0.3)
        handles, labels = axes[0][0].get_legend_handles_labels()  # every curve and phase
        legend_outside(axes[0][-1], handles, labels)
        save(fig, os.path.join(img, fname))

    lines_plot("dbs_distance.png", "electrode tip to STN (mm)", "distance",
               "electrode tip–STN distance", zoom=7.6)
    lines_plot("dbs_stn.png", "STN displacement since the shift (mm)", "stn",
               "STN displacement relative to its post-shift position", from_shift=True)
    lines_plot("dbs_dofs.png", "dofs", "dofs", "degrees of freedom", scale=1, vlines=False)
    lines_plot("dbs_ms_step.png", "ms per step", "t_step", "time per step", vlines=False,
               logy=True)
    return 0
