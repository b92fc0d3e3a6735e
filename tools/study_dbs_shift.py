"""tools/study.py dbs-shift (docs/dbs.md, "Goal-oriented refinement on the
brain shift"): the brain-shift phase of cases/dbs/dbs-skull.yaml (t ≤ 3 s) on
uniform 14, 10, 7 mm grids, whose Richardson extrapolation (per component,
observed orders) is the reference, and goal-driven from 14 mm with 1–3
levels: STN displacement error, effectivity of its estimate, the electrode
tip–STN distance against the reference, median ms/step against the 7 mm
mesh's. Output: OUT/report.md (also printed).
"""
import os

import numpy as np

import study_engine as engine
from outputs import read_csv, read_points, read_steps, speed, target_shift
from richardson import observed

ROOT = engine.ROOT

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


def run(a, binary):
    """The brain-shift phase of cases/dbs/dbs-skull.yaml (docs/dbs.md, "Goal-oriented
    refinement on the brain shift"): the STN's displacement and the electrode tip–STN distance
    at t = 3 s on three uniform meshes (Richardson: observed order, extrapolated reference) and
    on goal-driven meshes from the coarsest; effectivity of the goal estimate, cost per step."""
    st = DBS_SHIFT
    out = engine.out_dir(a, "dbs-shift")
    sel = [(n, sets + st["common"]) for n, _, sets, *_ in st["uniform"] + st["goal"]
           if not a.only or n in a.only]
    infos = engine.run_variants(a, binary, st["scene"], out, sel)

    def final(name):
        d = os.path.join(out, name)
        pos = read_points(d, "targets.csv")[0]
        rows = [r for r in read_csv(os.path.join(d, "targets.csv")) if r["name"] == st["target"]]
        tip = [r for r in read_csv(os.path.join(d, "tools.csv")) if r["name"] == st["tool"]][-1]
        x = pos[st["target"]]
        return {"u": target_shift(d, st["target"]), "x": x[-1, :3], "distance": x[-1, 3],
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
    comp = [observed(hs, [U[n]["u"][k] for n, _, _ in uni]) for k in range(3)]
    pm, mag = observed(hs, [np.linalg.norm(U[n]["u"]) for n, _, _ in uni])
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
    lines += engine.table_head("run", "max dofs", "median ms/step", "total s", "wall s",
                               "STN shift mm", "error mm", "estimate mm", "effectivity",
                               "distance mm", "distance error mm", "its estimate mm")
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
    engine.write_report(out, lines)
    return 0
