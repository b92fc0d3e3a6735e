"""tools/study.py dbs-goal (docs/dbs.md, "Goal-oriented refinement of the whole
procedure"): the whole procedure of cases/dbs/dbs-skull.yaml (270 steps) on
uniform 14, 10, 7, 5, 4 mm grids, whose per-step Richardson extrapolation
through the finest three (observed order per step; the 4 mm value with the
5 → 4 mm difference as its error bar where the order is not sane; the
previous triple, 10, 7, 5 mm, reported beside it; the bar per phase) is the
reference, and on goal-driven and
SPR-driven meshes from 14 mm: the electrode tip–STN distance's error at every
step after the target is reached, the effectivity of error_estimate and
distance_error_estimate, median ms/step against the 7 mm mesh's; the goal
estimate on the uniform 14 and 10 mm meshes (not refined), and per phase
(shift, insertion, hold, retraction) the estimate, its geometry part G
(targets.csv geometry_estimate) and its constraint-data part C
(constraint_estimate) against the true error;
dbs_goal_error.png, dbs_goal_cost.png, dbs_goal_effectivity.png.
--base NXxNYxNZ starts the SPR and goal runs from another grid (named
NAME-from-NXxNYxNZ; the uniform and estimate runs are unchanged, so --restart
into the same folder reuses them; report and plots in OUT/from-NXxNYxNZ);
--steps N ends every run early (the shift alone for N ≤ 64: the report then
cuts one phase). --ladder DIR takes the reference from a ladder of uniform
runs instead (tools/study.py convergence cases/dbs/dbs-skull.yaml --end 13.5
--grids ... --out DIR: the whole procedure on grids nested or not): per step
the least-squares line f∞ + a h through all of its complete runs
(richardson.py, ladder_reference), its bar twice f∞'s standard error; the
Richardson reference of the finest three uniform meshes is then reported
beside it.
"""
import json
import os
import re

import numpy as np

import study_engine as engine
from outputs import read_csv, read_points, read_steps, read_tools, speed
from plotstyle import FIGSIZE, MARKER, plt, save, save_loglog
from richardson import ladder_reference, observed, per_step_reference
from study_convergence import grid_h, scene_box
from study_dbs import phase_lines, phases

ROOT = engine.ROOT

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
        ("uniform-4mm", "uniform 35×43×33 (4 mm)",
         ["adapt.every=1000000", "tissue.grid=[35,43,33]"], 4.0),
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
        # the estimate (and the refinement) every 4th step: the steps between reuse the
        # factorisation (issue 26; docs/performance.md, "Goal-oriented runs")
        ("goal-l1-every4", "goal from 14 mm, 1 level, every 4",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1", "adapt.every=4"],
         "goal"),
        ("goal-l1-theta0.3", "goal from 14 mm, 1 level, θ = 0.3",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.marking={strategy: max, theta: 0.3}"], "goal"),
        # tolerance mode: marks among the cells that can still be refined (θ = 0.6 alone stops
        # at 4236 dofs: its marked cells are all at max_level), until the budget
        ("goal-l1-tol", "goal from 14 mm, 1 level, tolerance 2 µm, ≤ 8000 dofs",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.tolerance=2e-6", "adapt.max_dofs=8000"], "goal"),
        # failed at step 163 with scaled cut cells (a 3.5 mm cell at the channel inverted at
        # the hand-over); with the hand-over allowance and integrated cut cells it finishes
        ("goal-l2", "goal from 14 mm, 2 levels",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=2"], "goal"),
        # tolerance mode with a tolerance the reference can judge (about its bar), two levels
        ("goal-tol50", "goal from 14 mm, 2 levels, tolerance 50 µm, ≤ 20000 dofs",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=2",
          "adapt.tolerance=5e-5", "adapt.max_dofs=20000"], "goal"),
        # the goal estimate on the uniform 14 and 10 mm meshes, which it does not refine (a
        # budget of the initial dofs; the functional's box that of 1 level, as goal-l1's): its
        # effectivity and its parts against the true error of a mesh in the reference's family
        ("estimate-14mm", "goal estimate on uniform 14 mm, no refinement",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.max_dofs=3039"], "estimate"),
        ("estimate-10mm", "goal estimate on uniform 10 mm, no refinement",
         ["adapt.estimator=goal", "tissue.grid=[14,17,13]", "adapt.max_level=1",
          "adapt.max_dofs=7248"], "estimate"),
        # the local enriched dual where the STN's leaf holds the cannula's tip rows
        # (adapt.local_dual, off by default; docs/dbs.md "The hold with a local enriched dual")
        ("goal-l1-local", "goal from 14 mm, 1 level, local dual",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.local_dual=true"], "goal"),
        ("estimate-14mm-local", "goal estimate on uniform 14 mm, local dual",
         ["adapt.estimator=goal", "tissue.grid=[10,12,9]", "adapt.max_level=1",
          "adapt.max_dofs=3039", "adapt.local_dual=true"], "estimate"),
    ],
    "target": "STN",
    "cannula": "cannula",
    "electrode": "electrode",
    # a step is on another branch of the tools' model (the electrode released past the
    # cannula's tip, docs/dbs.md) when the electrode tip's distance from the cannula's tip
    # differs from the finest mesh's by more than this (m): on one branch the meshes differ by
    # at most 0.006–0.019 mm, across branches by 1.2 mm
    "branch": 5e-5,
    "order": (1.0, 5.99),  # a per-step order is used inside [1, 6): per_step_reference
    "resolved": 3.0,  # effectivity only where the true error exceeds 3× the reference's bar
}


# the options only this study takes (tools/study.py refuses them for the others)
OPTIONS = {"--base": "base", "--ladder": "ladder"}
BASE = "tissue.grid=[10,12,9]"  # the grid the refining runs start from (the 14 mm mesh)


def add_arguments(ap):
    g = ap.add_argument_group("dbs-goal")
    g.add_argument("--base", default=None, metavar="NXxNYxNZ",
                   help="dbs-goal: the grid the SPR and goal runs start from (default 10x12x9, "
                   "the 14 mm mesh; the uniform and estimate runs keep theirs)")
    g.add_argument("--ladder", default=None, metavar="DIR",
                   help="dbs-goal: the reference from the complete runs of a convergence "
                   "ladder of the whole procedure in DIR (tools/study.py convergence "
                   "--end 13.5 --out DIR) instead of the finest three uniform meshes")


def adaptive_variants(base):
    """st["adaptive"], the SPR and goal runs starting from the grid BASE (NXxNYxNZ; None: the
    14 mm mesh), named NAME-from-BASE and labelled after it."""
    if base is None:
        return DBS_GOAL["adaptive"]
    m = re.fullmatch(r"(\d+)x(\d+)x(\d+)", base)
    if not m or min(int(v) for v in m.groups()) < 1:
        raise SystemExit("--base: '%s' is not NXxNYxNZ" % base)
    grid = "tissue.grid=[%s]" % ",".join(m.groups())
    out = []
    for name, label, sets, kind in DBS_GOAL["adaptive"]:
        if kind in ("spr", "goal"):
            name = "%s-from-%s" % (name, base)
            label = label.replace("from 14 mm", "from %s" % base.replace("x", "×"))
            sets = [grid if x == BASE else x for x in sets]
        out.append((name, label, sets, kind))
    return out


def step_ranges(steps):
    """Sorted steps as ranges: [1, 4, 5, 6, 9] -> "1, 4–6, 9" ("none" if empty)."""
    out, i = [], 0
    while i < len(steps):
        j = i
        while j + 1 < len(steps) and steps[j + 1] == steps[j] + 1:
            j += 1
        out.append("%d" % steps[i] if j == i else "%d–%d" % (steps[i], steps[j]))
        i = j + 1
    return ", ".join(out) or "none"


def phase_slices(r, n):
    """The non-empty phases of a run r (its tools.csv's i_shift, i_top, i_back; n steps) as
    (name, slice of step indices), step 0 left out: shift, insertion, hold, retraction (a run
    that ends before the cannula touches the brain: the shift alone)."""
    cuts = (("shift", 1, r["i_shift"] + 1), ("insertion", r["i_shift"] + 1, r["i_top"]),
            ("hold", max(r["i_top"], r["i_shift"] + 1), r["i_back"] + 1),
            ("retraction", r["i_back"] + 1, n))
    return [(w, slice(lo, hi)) for w, lo, hi in cuts if hi > lo]


# each goal-estimated run again with the dynamic steps' memory term (adapt.memory, off by
# default; docs/dbs.md "The dynamic steps' memory"): name-memory
DBS_GOAL["adaptive"] += [
    (name + "-memory", label + ", memory", sets + ["adapt.memory=true"], kind)
    for name, label, sets, kind in list(DBS_GOAL["adaptive"])
    if kind in ("goal", "estimate") and "adapt.local_dual=true" not in sets]


def ladder_runs(a, binary, scene, n, load):
    """The complete runs of the convergence ladder in a.ladder (folders NXxNYxNZ with exit 0
    in run.json and n steps, the uniform runs' count), coarse first, each with its h (mm, the
    longest cell edge, as study_convergence reports it)."""
    done = []
    for name in sorted(os.listdir(a.ladder)) if os.path.isdir(a.ladder) else []:
        m = re.fullmatch(r"(\d+)x(\d+)x(\d+)", name)
        path = os.path.join(a.ladder, name, "run.json")
        if m and os.path.exists(path):
            with open(path) as f:
                if json.load(f).get("returncode") == 0:
                    done.append((name, [int(v) for v in m.groups()]))
    if len(done) < 3:
        raise SystemExit("--ladder: %s holds %d complete runs (NXxNYxNZ folders with exit 0), "
                         "fewer than three" % (a.ladder, len(done)))
    lo, hi, _ = scene_box(binary, scene, [])
    L = []
    for name, grid in done:
        r = load(name, name, "ladder", a.ladder)
        if len(r["d"]) != n:
            raise SystemExit("--ladder: %s has %d steps, the uniform runs %d (run the ladder "
                             "with --end %g)" % (name, len(r["d"]), n, r["times"][-1]))
        L.append(dict(r, h=grid_h(lo, hi, grid)))
    L.sort(key=lambda r: -r["h"])
    if len({r["h"] for r in L}) < 3:
        raise SystemExit("--ladder: %s holds fewer than three complete runs of distinct h"
                         % a.ladder)
    return L


def reference_ladder(L):
    """The per-step reference from the ladder's runs L (coarse first): ladder_reference of the
    distance and of each component of the STN's position."""
    h = [r["h"] for r in L]
    d, d_bar, d_a = ladder_reference(h, np.array([r["d"] for r in L]))
    xs = [ladder_reference(h, np.array([r["x"][:, k] for r in L])) for k in range(3)]
    ok = np.ones(len(d), bool)
    return {"ladder": True, "h": h, "d": d, "d_bar": d_bar, "d_a": d_a,
            "d_p": np.full(len(d), np.nan), "d_ok": ok,
            "x": np.array([c[0] for c in xs]).T,
            "x_bar": np.linalg.norm(np.array([c[1] for c in xs]).T, axis=1), "x_ok": ok}


def run(a, binary):
    """The whole procedure of cases/dbs/dbs-skull.yaml (docs/dbs.md, "Goal-oriented
    refinement of the whole procedure"): the electrode tip–STN distance and the STN's
    position at every step on goal-driven, SPR-driven and uniform meshes against the per-step
    Richardson reference of the finest three uniform meshes; effectivity of the goal
    estimates; cost per step against the 7 mm mesh's."""
    st = dict(DBS_GOAL, adaptive=adaptive_variants(a.base))
    out = engine.out_dir(a, "dbs-goal")
    # the report and plots of runs from another base grid go beside the base run's, into
    # OUT/from-BASE, which the same folder's runs then share
    rep = os.path.join(out, "from-" + a.base) if a.base else out
    os.makedirs(rep, exist_ok=True)
    img = engine.plot_dir(a, rep)
    sel = [(n, sets + st["common"]) for n, _, sets, *_ in st["uniform"] + st["adaptive"]
           if not a.only or n in a.only or n in [u[0] for u in st["uniform"]]]
    infos = engine.run_variants(a, binary, st["scene"], out, sel)
    if any(n not in infos for n, *_ in st["uniform"]):
        raise SystemExit("dbs-goal needs every uniform run (the reference)")

    def load(name, label, kind, where=out):
        d = os.path.join(where, name)
        pos, steps, times = read_points(d, "targets.csv")
        rows = [r for r in read_csv(os.path.join(d, "targets.csv")) if r["name"] == st["target"]]
        sr = read_steps(d)
        i_shift, i_top, i_back = phases(d, st["cannula"])
        can, ele = read_tools(d, st["cannula"]), read_tools(d, st["electrode"])
        sep = np.linalg.norm(np.array([ele["tip_" + k] - can["tip_" + k] for k in "xyz"]), axis=0)
        return {"name": name, "label": label, "kind": kind, "times": times, "steps": steps,
                "x": pos[st["target"]][:, :3], "d": pos[st["target"]][:, 3],
                "est": np.array([float(r.get("error_estimate", "nan")) for r in rows]),
                "dest": np.array([float(r.get("distance_error_estimate", "nan")) for r in rows]),
                "geo": np.array([float(r.get("geometry_estimate", "nan")) for r in rows]),
                "dgeo": np.array([float(r.get("distance_geometry_estimate", "nan"))
                                  for r in rows]),
                "con": np.array([float(r.get("constraint_estimate", "nan")) for r in rows]),
                "dcon": np.array([float(r.get("distance_constraint_estimate", "nan"))
                                  for r in rows]),
                "speed": speed(sr), "rows": int(sr["constraints"].max()), "st": sr,
                "i_shift": i_shift, "i_top": i_top, "i_back": i_back, "sep": sep,
                "load": infos.get(name, {}).get("load", [])}

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

    L = ladder_runs(a, binary, st["scene"], n, load) if a.ladder else None
    if L:
        ref = reference_ladder(L)
        prev = reference(U[-3:])  # the uniform Richardson, for comparison
    else:
        ref = reference(U[-3:])  # the finest three
        prev = reference(U[-4:-1]) if len(U) > 3 else None  # the next coarser triple
    d_ref, d_bar, x_ref, x_bar = ref["d"], ref["d_bar"], ref["x"], ref["x_bar"]
    runs = U + [dict(load(nm, l, k), sets=sets) for nm, l, sets, k in st["adaptive"]
                if nm in infos]
    # the tools' branch (st["branch"]): steps where a reference mesh or the run itself is on
    # another branch than the finest mesh are not judged (their error is not a discretisation
    # error of the tissue)
    fam = L if L else U[-3:]  # the reference's meshes
    finest = fam[-1]["sep"]
    ref_off = np.any([np.abs(r["sep"] - finest) > st["branch"] for r in fam], axis=0)
    for r in runs:
        r["off"] = ref_off | (np.abs(r["sep"] - finest) > st["branch"])
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
        on = r["err"][after & ~r["off"]]  # on the reference's branch
        r["max_on"] = float(on.max()) if len(on) else float("nan")
        r["ratio"] = r["speed"]["median"] / ref_ms

    def eff(est, err, bar, off, sl=slice(1, None)):
        """Effectivity est / err over the steps in sl (default: ≥ 1) with an estimate whose
        true error the reference resolves (err > st["resolved"] × its bar) on the reference's
        branch (not off): (median, min, max, steps, of, the steps outside [0.5, 2])."""
        ok = np.zeros(n, dtype=bool)
        ok[sl] = True
        ok &= np.isfinite(est)
        use = ok & (err > st["resolved"] * bar) & ~off
        if not use.any():
            return None
        v = est[use] / err[use]
        return (float(np.median(v)), float(v.min()), float(v.max()), int(use.sum()), int(ok.sum()),
                [int(i) for i in np.nonzero(use)[0][(v < 0.5) | (v > 2.0)]])

    lines = []
    p = lines.append
    if not any(r["i_top"] > r["i_shift"] for r in U):
        p("The runs end before the cannula touches the brain (%d steps, t ≤ %.2f s: the shift "
          "alone, --steps): the distance's figures \"after the target\" below are those of the "
          "last step, and the phases are the shift." % (n - 1, U[0]["times"][-1]))
        p("")
    for R, what in ((ref, "the reference"),
                    (prev, "the uniform meshes' Richardson" if L else "the next coarser triple")):
        if R is None:
            continue
        if R.get("ladder"):
            p("The reference: per step, the least-squares line f∞ + a h through the %d complete "
              "runs of the ladder %s (h %s mm; richardson.py, ladder_reference), its error bar "
              "twice f∞'s standard error. Electrode tip–STN distance after the target (step %d, "
              "t = %.2f s, on; %d steps): bar median %.4f mm, max %.4f mm; slope a median %.4f "
              "mm per mm of h. "
              "STN position: bar (norm) median %.4f mm, max %.4f mm." % (
                  len(R["h"]), a.ladder, ", ".join("%.2f" % h for h in R["h"]), i0,
                  U[0]["times"][i0], after.sum(), 1e3 * np.median(R["d_bar"][after]),
                  1e3 * R["d_bar"][after].max(), 1e3 * np.median(R["d_a"][after]),
                  1e3 * np.median(R["x_bar"][1:]), 1e3 * R["x_bar"][1:].max()))
            p("")
            continue
        pa = R["d_p"][after & R["d_ok"]]
        q = (np.median(pa), *np.percentile(pa, [25, 75]), pa.min(), pa.max()) if len(pa) else \
            (np.nan,) * 5
        p("%s: per step, Richardson through the uniform %s mm meshes (richardson.py, "
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
        dx = np.linalg.norm(prev["x"] - x_ref, axis=1)[1:]
        p("%s distance reference against %s after the target: max difference %.4f mm "
          "(t = %.2f s), median %.4f mm; STN position: max %.4f mm, median %.4f mm." % (
              "The uniform meshes' Richardson" if L else "The next coarser triple's",
              "the ladder's" if L else "the finest three's", 1e3 * dd.max(),
              U[0]["times"][i0 + int(np.argmax(dd))], 1e3 * np.median(dd), 1e3 * dx.max(),
              1e3 * np.median(dx)))
        p("")
    fit = "fitted steps" if L else "sane orders"
    lines += engine.table_head(
        "phase (steps)", "d: " + fit, "d: bar median, max (mm)", "x: " + fit,
        "x: bar median, max (mm)")
    for what, sl in phase_slices(U[-1], n):
        p("| %s (%d–%d) | %d | %.4f, %.4f | %d | %.4f, %.4f |" % (
            what, sl.start, sl.stop - 1, ref["d_ok"][sl].sum(), 1e3 * np.median(d_bar[sl]),
            1e3 * d_bar[sl].max(), ref["x_ok"][sl].sum(), 1e3 * np.median(x_bar[sl]),
            1e3 * x_bar[sl].max()))
    p("")
    p("(the reference's bar per phase of the finest mesh's tools.csv; %s)" % (
        "fitted: every step, the ladder's line" if L else
        "sane: an observed order in [%g, 6), for x in all three components." % st["order"][0]))
    p("")
    i_s = base["i_shift"]
    shift = [float(np.linalg.norm(r["x"][i_s] - r["x"][0])) for r in U]
    ps, s_ref = observed([r["h"] for r in U[-3:]], shift[-3:])  # as dbs_convergence.py
    p("Whole procedure (tools/dbs_convergence.py's quantities): final distance %s mm on %s mm "
      "→ %.4f mm (%s); STN shift |x(t_s) − X| at t_s = %.2f s %s mm → %.4f mm (%s)." % (
          ", ".join("%.4f" % (1e3 * r["d"][-1]) for r in U),
          ", ".join("%g" % h for *_, h in st["uniform"]), 1e3 * d_ref[-1],
          "the ladder's line, bar %.4f mm" % (1e3 * d_bar[-1]) if L else
          "order %.2f" % ref["d_p"][-1] if ref["d_ok"][-1] else
          "fallback, bar %.4f mm" % (1e3 * d_bar[-1]), base["times"][i_s],
          ", ".join("%.4f" % (1e3 * v) for v in shift), 1e3 * s_ref,
          "order %.2f" % ps if ps else "no order"))
    p("")
    lines += engine.table_head(
        "run", "max dofs", "max rows", "median ms/step", "/ 7 mm", "total s",
        "max \\|d − d_ref\\| mm (t s)", "RMS mm", "final d mm",
        "effectivity of error_estimate: median (range; judged steps), the judged steps outside "
        "[0.5, 2]", "of distance_error_estimate")
    for r in runs:
        s = r["speed"]
        cells = []
        for est, err, bar in ((r["est"], r["xerr"], x_bar), (r["dest"], r["err"], d_bar)):
            e = eff(est, err, bar, r["off"])
            r.setdefault("eff", []).append(e)
            cells.append("%.2f (%.2f–%.2f; %d of %d), outside [0.5, 2]: %s" % (
                *e[:5], step_ranges(e[5])) if e else "–")
        p("| %s | %d | %d | %.1f | %.3f | %.1f | %.4f (%.2f) | %.4f | %.4f | %s | %s |" % (
            r["label"], s["max_dofs"], r["rows"], s["median"], r["ratio"], s["total"],
            1e3 * r["max"], r["times"][r["at"]], 1e3 * r["rms"], 1e3 * r["d"][-1], *cells))
    p("")
    p("(d: the electrode tip–STN distance; max and RMS over the steps from %d on, t ≥ %.2f s; "
      "rows: constraint rows, skull and tools; effectivity: the estimate over the true error "
      "|run − reference| at the steps where that error exceeds %g× the reference's bar.)" % (
          i0, U[0]["times"][i0], st["resolved"]))
    p("")
    for r in [r for r in runs[len(U):] if r["kind"] != "estimate"]:
        p("- %s: max |d − d_ref| %.4f mm after the target (issue 14's goal ≤ 0.3 mm: %s; "
          "issue 26's ≤ 0.1 mm: %s), %.4f mm over its steps on the reference's branch (≤ 0.1 "
          "mm: %s); median ms/step %.1f, %.3f of the 7 mm mesh's %.1f (goal "
          "≤ 1/4: %s); %.1f steps/s over Σ t_step (issue 26's goal ≥ 25: %s)." % (
              r["label"], 1e3 * r["max"], "met" if r["max"] <= 3e-4 else "missed",
              "met" if r["max"] <= 1e-4 else "missed", 1e3 * r["max_on"],
              "met" if r["max_on"] <= 1e-4 else "missed", r["speed"]["median"], r["ratio"],
              ref_ms, "met" if r["ratio"] <= 0.25 else "missed", n / r["speed"]["total"],
              "met" if n / r["speed"]["total"] >= 25 else "missed"))
    off = np.nonzero(ref_off)[0]
    p("- The tools' branch: the reference's meshes are on different branches at %d steps%s; "
      "those steps, and a run's steps on another branch than the %g mm mesh's, are not judged "
      "(effectivity, tolerance)." % (len(off), " (%d–%d)" % (off[0], off[-1]) if len(off) else "",
                                     U[-1]["h"]))
    for r in runs[len(U):]:
        tol = [float(x.split("=")[1]) for x in r["sets"] if x.startswith("adapt.tolerance=")]
        if not tol:
            continue
        judged = (np.arange(n) >= 1) & ~r["off"]
        below = r["xerr"] <= tol[0]
        sure = judged & (np.abs(r["xerr"] - tol[0]) > x_bar)
        p("- %s: the true STN error below the tolerance %.3g mm at %d of %d judged steps "
          "(%.0f %%; goal ≥ 90 %%); certain (|error − tolerance| > the bar) at %d of them, %d "
          "below; per phase %s." % (
              r["label"], 1e3 * tol[0], int((below & judged).sum()), int(judged.sum()),
              100.0 * (below & judged).sum() / max(judged.sum(), 1), int(sure.sum()),
              int((sure & below).sum()), ", ".join(
                  "%s %d/%d" % (w, int((below & judged)[sl].sum()), int(judged[sl].sum()))
                  for w, sl in phase_slices(r, n))))
    lost = [nm for nm, *_ in st["adaptive"] if nm not in infos and (not a.only or nm in a.only)]
    if lost:
        p("- not complete (the reason above, on stderr): %s." % ", ".join(lost))
    est_runs = [r for r in runs if r["kind"] in ("goal", "estimate")]
    if est_runs:
        p("")
        p("The estimate, its geometry part G and its constraint-data part C against the true "
          "error, per phase (medians over "
          "the phase's steps, mm; the phases of the run's own tools.csv: the shift until the "
          "cannula touches the brain, the insertion until the target depth, the hold, the "
          "retraction; ratio: the median of estimate / true error over the phase's steps; "
          "judged: its median over the judged steps, the effectivity's, and their number):")
        p("")
        lines.extend(engine.table_head(
            "run", "phase (steps)", "\\|x − x_ref\\|", "error_estimate", "of it G", "of it C",
            "ratio", "judged (steps)", "\\|d − d_ref\\|", "distance_error_estimate", "of it G",
            "of it C", "ratio", "judged (steps)"))
        for r in est_runs:
            for what, sl in phase_slices(r, n):
                cells = []
                for err, est, geo, con, bar in (
                        (r["xerr"], r["est"], r["geo"], r["con"], x_bar),
                        (r["err"], r["dest"], r["dgeo"], r["dcon"], d_bar)):
                    e = eff(est, err, bar, r["off"], sl)
                    cells += ["%.4f" % (1e3 * np.median(err[sl])),
                              "%.4f" % (1e3 * np.nanmedian(est[sl])),
                              "%.4f" % (1e3 * np.nanmedian(geo[sl])),
                              "%.4f" % (1e3 * np.nanmedian(con[sl])),
                              "%.2f" % np.nanmedian(est[sl] / err[sl]),
                              "%.2f (%d)" % (e[0], e[3]) if e else "– (0)"]
                p("| %s | %s (%d–%d) | %s |" % (r["label"], what, sl.start, sl.stop - 1,
                                               " | ".join(cells)))
        p("")
    loads = [x for r in runs for x in r["load"]]
    if loads:
        p("- 1-minute load average at the runs' starts and ends: %.1f–%.1f (2 cores)." % (
            min(loads), max(loads)))
    engine.write_report(rep, lines)

    def band(ax, bar):
        """The reference's error bar (mm) as a grey band from 1 nm up."""
        ax.fill_between(t, 1e-6, np.maximum(1e3 * bar, 1e-6), color="0.85", step="mid",
                        label="reference's error bar")

    colors = {r["name"]: "C%d" % k for k, r in enumerate(runs)}
    t = U[0]["times"]
    fig, ax = plt.subplots(figsize=(11, 4.8))
    band(ax, d_bar)
    meshes = [r for r in runs if r["kind"] != "estimate"]  # the estimate runs are U's meshes
    for r in meshes:  # goal solid and thick, SPR dashed, uniform thin
        ax.semilogy(t[1:], np.maximum(1e3 * r["err"][1:], 1e-6),
                    {"uniform": "-", "spr": "--", "goal": "-"}[r["kind"]], color=colors[r["name"]],
                    lw={"uniform": 0.9, "spr": 1.1, "goal": 1.6}[r["kind"]],
                    label="%s: %.1f ms/step" % (r["label"], r["speed"]["median"]))
    ax.axhline(0.3, color="k", ls="--", lw=1, label="goal 0.3 mm")
    phase_lines(ax, base, t)
    ax.set_ylim(1e-4, None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|d − d_ref| (mm)")
    ax.set_title("dbs-skull: error of the electrode tip–STN distance against the per-step "
                 "%s reference" % ("ladder's" if L else "Richardson"), fontsize=9)
    ax.grid(alpha=0.3, which="both")
    save(fig, os.path.join(img, "dbs_goal_error.png"), legend=ax)

    fig, ax = plt.subplots(figsize=FIGSIZE)
    for r in meshes:
        ax.loglog(r["speed"]["median"], 1e3 * r["max"], MARKER[r["kind"]], color=colors[r["name"]],
                  ms=8,
                  label="%s (%d dofs)" % (r["label"], r["speed"]["max_dofs"]))
    ax.loglog([r["speed"]["median"] for r in U], [1e3 * r["max"] for r in U], "k:", lw=1)
    ax.axhline(0.3, color="k", ls="--", lw=1, label="goal: 0.3 mm")
    ax.axvline(0.25 * ref_ms, color="0.4", ls="-.", lw=1,
               label="goal: 1/4 of %s's ms/step" % base["label"])
    save_loglog(fig, ax, os.path.join(img, "dbs_goal_cost.png"), "median time per step (ms)",
                "max |d − d_ref| after the target (mm)",
                "dbs-skull, whole procedure: error against cost")

    gor = [r for r in runs if r["kind"] in ("goal", "estimate")]
    if gor:
        fig, axes = plt.subplots(1, 2, figsize=(13, 4.2))
        for ax, key, ekey, bar, title in (
                (axes[0], "xerr", "est", x_bar,
                 "STN displacement: |x − x_ref| and error_estimate"),
                (axes[1], "err", "dest", d_bar,
                 "tip–STN distance: |d − d_ref| and distance_error_estimate")):
            band(ax, bar)
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
        save(fig, os.path.join(img, "dbs_goal_effectivity.png"), legend=axes[1])
    return 0
