"""tools/study.py cube (docs/adaptivity.md, "Goal-oriented refinement"): the
localized-load block, probe P's displacement on uniform, SPR-driven and
goal-driven meshes against the goal-oriented sequence continued to 250 000
dofs, whose last three meshes give the observed order and the extrapolated
reference.

Output: OUT/report.md (also printed) and cube_goal_error.png in --img
(default docs/img).
"""
import os

import numpy as np

import study_engine as engine
from outputs import read_points, read_steps
from plotstyle import FIGSIZE, MARKER, plt, save_loglog
from richardson import richardson

ROOT = engine.ROOT

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


def run(a, binary):
    """The localized-load block (docs/adaptivity.md): probe P's displacement
    on SPR-driven, goal-driven and uniform meshes against a converged value."""
    st = CUBE
    out = engine.out_dir(a, "cube")
    img = a.img or os.path.join(ROOT, "docs", "img")
    os.makedirs(img, exist_ok=True)

    def series(d):
        u = read_points(d)[0]
        sr = read_steps(d)
        return {"dofs": sr["dofs"], "uz": u[st["probe"]][1:, 2], "est": u[st["probe"]][1:, 3],
                "iterations": sr["iterations"], "t_step": sr["t_step"]}

    rname, rlabel, rdir, infos = engine.run_with_reference(a, binary, st, out)
    ref = series(rdir)
    # Convergence of the reference: the last three meshes, u(N) = u_inf + C N^-q (nan: no q).
    u_inf, _, q = richardson(ref["dofs"][-3:], ref["uz"][-3:])
    u3 = ref["uz"][-1]
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
    lines += engine.table_head("run", "mesh", "dofs", "u_z(P) µm", "error µm", "estimate µm",
                               "effectivity")
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
    engine.write_report(out, lines)

    fig, ax = plt.subplots(figsize=FIGSIZE)
    for r in runs:
        if r["kind"] == "uniform":
            continue
        ax.loglog(r["dofs"], 1e6 * r["err"], MARKER[r["kind"]] + "-", label="%s: error" % r["label"])
        if r["kind"] == "goal":
            ax.loglog(r["dofs"], 1e6 * r["est"], MARKER["goal"] + ":", color="C1",
                      label="goal: its estimate")
    uni = [r for r in runs if r["kind"] == "uniform"]
    if uni:
        ax.loglog([r["dofs"][0] for r in uni], [1e6 * r["err"][0] for r in uni],
                  "k" + MARKER["uniform"] + "-", label="uniform: error")
    save_loglog(fig, ax, os.path.join(img, "cube_goal_error.png"), "dofs", "|u_z(P) − u_ref| (µm)",
                "localized load: error of the probe displacement")
    return 0
