#!/usr/bin/python3
"""Plots of needle-insertion runs for docs/interaction.md and docs/cases.md:
reads the CSV files of one or more run folders and writes PNGs.

    tools/plot_needle.py RUN [RUN ...] [--out docs/img] [--no-states] [--tool NAME]

RUN is an output folder of `needlehex run` (tools.csv, probes.csv,
steps.csv, scene.yaml). For each run, named after the folder's last
component with '-' turned into '_' (needle-phantom -> needle_phantom):

- NAME_force_depth.png: the tissue's axial force on the tool (tools.csv
  axial_force, N, positive resists insertion) versus depth (m), points
  coloured by the contact state;
- NAME_force_time.png: axial force and depth versus time, the contact
  states shaded (omit the shading with --no-states);
- NAME_probes.png: probe displacements versus time (probes.csv): the axial
  component ux and the lateral magnitude (uy² + uz²)^½, in µm.

With two or more runs it also writes needle_force_compare.png (axial force
versus time of every run on one axis).

It prints the measured numbers (Markdown) that docs/cases.md quotes: the
force at puncture, the force-depth slope while cutting (least squares and
end points), the force at the end of insertion, while holding and while
retracting, the steps per state, and the largest probe displacements.
Needs numpy and matplotlib (Debian's python3-numpy, python3-matplotlib).
"""
import argparse
import os
import sys

import numpy as np
from matplotlib.patches import Patch

from outputs import read_series, read_steps, read_tools
from plotstyle import FIGSIZE, plt, save

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STATES = ["outside", "contact", "punctured", "cutting", "retracting"]
STATE_COLOURS = {
    "outside": "#ffffff",
    "contact": "#fde0c5",
    "punctured": "#c6dbef",
    "cutting": "#fcbba1",
    "retracting": "#c7e9c0",
}
STATE_MARKERS = {
    "outside": "#999999",
    "contact": "#e6550d",
    "punctured": "#3182bd",
    "cutting": "#de2d26",
    "retracting": "#31a354",
}


def segments(states, t):
    """Contiguous runs of one state: (state, t_start, t_end). A sample at
    time t_k describes the step that ended at t_k, i.e. (t_{k-1}, t_k]."""
    out = []
    for k, s in enumerate(states):
        t0 = t[k - 1] if k > 0 else t[k]
        if out and out[-1][0] == s:
            out[-1][2] = t[k]
        else:
            out.append([s, t0, t[k]])
    return out


def shade(ax, tl):
    present = []
    for s, t0, t1 in segments(tl["state"], tl["time"]):
        if s != "outside":
            ax.axvspan(t0, t1, color=STATE_COLOURS[s], lw=0, zorder=0)
        if s not in present:
            present.append(s)
    return [Patch(facecolor=STATE_COLOURS[s], edgecolor="#bbbbbb", label=s)
            for s in STATES if s in present]


def measure(tl, steps, probes):
    """The numbers docs/cases.md quotes, as a dict."""
    st = np.array(tl["state"])
    f, d, t = tl["axial_force"], tl["depth"], tl["time"]
    m = {"states": {s: int(np.sum(st == s)) for s in STATES}}
    pun = np.nonzero(np.isin(st, ["punctured", "cutting"]))[0]
    if len(pun):
        k = pun[0]
        m["puncture"] = (t[k], f[k], d[k], f[k - 1] if k > 0 else 0.0)
    cut = np.nonzero(st == "cutting")[0]
    if len(cut) >= 3:
        # least squares over every cutting sample, and the end points
        A = np.vstack([d[cut], np.ones(len(cut))]).T
        slope, icpt = np.linalg.lstsq(A, f[cut], rcond=None)[0]
        k0, k1 = cut[0], cut[-1]
        m["cut_fit"] = (slope, icpt, len(cut))
        m["cut_ends"] = ((f[k1] - f[k0]) / (d[k1] - d[k0]), d[k0], f[k0], d[k1], f[k1])
        # the distinct force levels while cutting (one per path point)
        lv = np.unique(np.round(f[cut], 6))
        m["cut_levels"] = lv
        m["end_insert"] = (t[k1], d[k1], f[k1])
    after = np.nonzero((st == "punctured") & (np.arange(len(st)) > (cut[-1] if len(cut) else -1)))[0]
    if len(after):
        k = after[-1]
        m["hold"] = (t[k], d[k], f[k])
    ret = np.nonzero(st == "retracting")[0]
    if len(ret):
        m["retract_first"] = (t[ret[0]], d[ret[0]], f[ret[0]])
        m["retract_levels"] = np.unique(np.round(f[ret], 6))
        A = np.vstack([d[ret], np.ones(len(ret))]).T
        m["retract_fit"] = np.linalg.lstsq(A, f[ret], rcond=None)[0][0]
        m["retract_end"] = t[ret[-1]]
    m["f_max"] = (f.max(), t[np.argmax(f)])
    m["lateral_max"] = tl["lateral_force"].max()
    if steps is not None:
        m["constraints_max"] = int(steps["constraints"].max())
        m["sweeps_max"] = int(steps["constraint_iterations"].max())
        m["residual_max"] = float(np.nanmax(steps["constraint_residual"]))
        m["path_points_max"] = int(steps["path_points"].max())
        m["t_compliance"] = float(steps["t_compliance"].sum())
        m["t_mcp"] = float(steps["t_mcp"].sum())
        m["t_step"] = float(steps["t_step"].sum())
        m["cut_steps"] = int(np.sum(steps["cut"] > 0))
        rows = steps["constraints"] > 0
        m["stick_rows"] = int(steps["stick"][rows].sum())
        m["slide_rows"] = int(steps["slide"][rows].sum())
    m["probes"] = {}
    for name, a in probes.items():
        lat = np.hypot(a[:, 2], a[:, 3])
        k = np.argmax(np.abs(a[:, 1]))
        m["probes"][name] = (a[k, 1], a[k, 0], lat.max(), a[-1, 1])
    return m


def report(run, tl, m):
    print("## %s (tool %s)\n" % (run, tl["name"]))
    print("| quantity | value |")
    print("|---|---|")
    print("| steps per state | %s |" % ", ".join("%s %d" % (s, n) for s, n in m["states"].items() if n))
    if "puncture" in m:
        t, f, d, fprev = m["puncture"]
        print("| puncture: first punctured step | t = %.3f s, axial force %.6g N, depth %.4g mm (step before: %.6g N) |"
              % (t, f, 1e3 * d, fprev))
    if "cut_fit" in m:
        s, c, n = m["cut_fit"]
        print("| cutting: least-squares force-depth slope | %.4f N/m (intercept %.5f N, %d samples) |" % (s, c, n))
        s, d0, f0, d1, f1 = m["cut_ends"]
        print("| cutting: end-point slope | %.4f N/m (%.6g N at %.3f mm to %.6g N at %.3f mm) |"
              % (s, f0, 1e3 * d0, f1, 1e3 * d1))
        lv = m["cut_levels"]
        steps_ = np.diff(lv)
        print("| cutting: force levels | %s N (increments %s N) |"
              % (", ".join("%.4f" % x for x in lv), ", ".join("%.4f" % x for x in steps_)))
        t, d, f = m["end_insert"]
        print("| last cutting step | t = %.3f s, depth %.3f mm, %.6g N |" % (t, 1e3 * d, f))
    if "hold" in m:
        t, d, f = m["hold"]
        print("| holding (last punctured step) | t = %.3f s, depth %.3f mm, %.6g N |" % (t, 1e3 * d, f))
    if "retract_first" in m:
        t, d, f = m["retract_first"]
        print("| retraction: first step | t = %.3f s, depth %.3f mm, %.6g N |" % (t, 1e3 * d, f))
        print("| retraction: force levels | %s N |" % ", ".join("%.4f" % x for x in m["retract_levels"]))
        print("| retraction: least-squares force-depth slope | %.4f N/m |" % m["retract_fit"])
        print("| retraction: last retracting step | t = %.3f s |" % m["retract_end"])
    print("| largest axial force | %.6g N at t = %.3f s |" % m["f_max"])
    print("| largest lateral force | %.3g N |" % m["lateral_max"])
    if "constraints_max" in m:
        print("| rows (max), path points (max) | %d, %d |" % (m["constraints_max"], m["path_points_max"]))
        print("| constraint sweeps (max), residual (max) | %d, %.3g |" % (m["sweeps_max"], m["residual_max"]))
        print("| friction rows over all steps: stick, slide | %d, %d |" % (m["stick_rows"], m["slide_rows"]))
        print("| steps with a cut | %d |" % m["cut_steps"])
        print("| time: t_compliance, t_mcp, t_step (sums) | %.4f s, %.4f s, %.4f s |"
              % (m["t_compliance"], m["t_mcp"], m["t_step"]))
    for name, (ux, t, lat, last) in m["probes"].items():
        print("| probe %s: largest \\|ux\\|, largest lateral, final ux | %.4g µm at t = %.2f s, %.3g µm, %.3g µm |"
              % (name, 1e6 * ux, t, 1e6 * lat, 1e6 * last))
    print()


def plot_run(run, tl, probes, m, out, name, states):
    f, d, t = tl["axial_force"], tl["depth"], tl["time"]
    st = np.array(tl["state"])

    # force versus depth, coloured by state
    fig, ax = plt.subplots(figsize=FIGSIZE)
    for s in STATES:
        k = st == s
        if k.any():
            ax.plot(1e3 * d[k], f[k], ".", ms=4, color=STATE_MARKERS[s], label=s)
    if "cut_fit" in m:
        s_, c_, _ = m["cut_fit"]
        dd = np.array([d[st == "cutting"].min(), d[st == "cutting"].max()])
        ax.plot(1e3 * dd, c_ + s_ * dd, "k--", lw=0.8,
                label="fit while cutting: %.2f N/m" % s_)
    ax.axhline(0, color="#888888", lw=0.5)
    ax.set_xlabel("depth (mm)")
    ax.set_ylabel("axial force on the tool (N)")
    ax.set_title("%s: insertion force versus depth" % os.path.basename(run))
    ax.grid(alpha=0.3)
    save(fig, os.path.join(out, "%s_force_depth.png" % name), legend=ax)

    # force and depth versus time, states shaded
    fig, ax = plt.subplots(figsize=FIGSIZE)
    handles = shade(ax, tl) if states else []
    (l1,) = ax.plot(t, f, "-", color="#b2182b", lw=1.2, label="axial force")
    ax.axhline(0, color="#888888", lw=0.5)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("axial force on the tool (N)")
    ax2 = ax.twinx()
    (l2,) = ax2.plot(t, 1e3 * d, "-", color="#2166ac", lw=1.0, label="depth")
    ax2.set_ylabel("depth (mm)")
    ax.set_title("%s: insertion force and depth versus time" % os.path.basename(run))
    ax.legend(handles=[l1, l2] + handles, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14),
              ncol=3, frameon=False)  # below: the right axis is the depth's
    ax.set_xlim(t[0], t[-1])
    save(fig, os.path.join(out, "%s_force_time.png" % name))

    # probes
    if probes:
        fig, (a1, a2) = plt.subplots(2, 1, figsize=(6.4, 5.6), sharex=True)
        if states:
            shade(a1, tl), shade(a2, tl)
        for pname, a in probes.items():
            a1.plot(a[:, 0], 1e6 * a[:, 1], label="probe %s" % pname)
            a2.plot(a[:, 0], 1e6 * np.hypot(a[:, 2], a[:, 3]), label="probe %s" % pname)
        a1.set_ylabel("ux (µm)")
        a2.set_ylabel("(uy² + uz²)^½ (µm)")
        a2.set_xlabel("time (s)")
        a1.axhline(0, color="#888888", lw=0.5)
        a1.set_title("%s: probe displacements" % os.path.basename(run))
        for a in (a1, a2):
            a.grid(alpha=0.3)
            a.set_xlim(t[0], t[-1])
        save(fig, os.path.join(out, "%s_probes.png" % name), legend=a1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="output folders of needlehex run")
    ap.add_argument("--out", default=os.path.join(ROOT, "docs", "img"), help="folder for the PNGs")
    ap.add_argument("--no-states", dest="states", action="store_false",
                    help="do not shade the contact states")
    ap.add_argument("--tool", help="the tool to plot (default: the first in tools.csv)")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    all_tl = []
    for run in a.runs:
        run = os.path.normpath(run)
        if not os.path.exists(os.path.join(run, "tools.csv")):
            sys.exit("%s: no tools.csv (not the output folder of a run with tools)" % run)
        tl = read_tools(run, a.tool)
        probes = read_series(run, "probes.csv", ["time", "ux", "uy", "uz"])
        m = measure(tl, read_steps(run, missing=True), probes)
        name = os.path.basename(run).replace("-", "_")
        report(run, tl, m)
        plot_run(run, tl, probes, m, a.out, name, a.states)
        all_tl.append((run, tl))
    if len(all_tl) > 1:
        fig, ax = plt.subplots(figsize=FIGSIZE)
        for run, tl in all_tl:
            ax.plot(tl["time"], tl["axial_force"], label=os.path.basename(run))
        ax.axhline(0, color="#888888", lw=0.5)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("axial force on the tool (N)")
        ax.grid(alpha=0.3)
        save(fig, os.path.join(a.out, "needle_force_compare.png"), legend=ax)


if __name__ == "__main__":
    main()
