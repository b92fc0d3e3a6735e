#!/usr/bin/python3
"""The adaptivity study of docs/adaptivity.md: error in the energy norm and
SPR estimate η versus DOFs for uniform and adaptive meshes of
cases/adapt-localized.yaml, and the cost of the two hanging-node
enforcements.

    tools/adapt_study.py [--binary PATH] [--cache DIR] [--img DIR] [--quick]
                         [--force] [--no-bench]

The error measure. The case is linear in practice (static, strains ~1e-5,
one Newton iteration from a transferred state); for conforming Galerkin
approximations of a linear elastic problem with a fixed load functional f,
Galerkin orthogonality gives

    ‖u − u_h‖²_E = ‖u‖²_E − ‖u_h‖²_E = W − W_h,    W_h = f·u_h = ‖u_h‖²_E

(the `work` column of steps.csv). That identity needs the conforming
displacement element: every run of this study sets
tissue.material.formulation=full. Under B-bar (the scene's default) the
discrete problem is a mixed one whose projected dilatation changes with the
mesh, so W_h is neither ‖u_h‖²_E nor monotone under refinement (measured:
max θ=0.3, hex2, W_h fell from 9.5343e-14 to 9.5194e-14 J between its
meshes 2 and 3, and the best adaptive W_h exceeded the uniform Richardson
W_∞). Hanging nodes are constrained to the
coarse side's trilinear interpolation, so every adaptive space is conforming
and a subspace of the next one, and W_h ≤ W for every mesh. W itself is
estimated two ways: W_ref, the work of the finest uniform mesh run here (the
"reference"), and W_∞, the Richardson extrapolation W(k) = W_∞ − C k^(−p)
through the three finest uniform meshes (k: the refinement factor of the
8×4×4 grid). Errors are reported against both.

Runs (cached, with their steps.csv, in --cache, default out/adapt-study;
delete a run's folder or pass --force to run it again):
  uniform  k = 1, 2, 3, 4, 5, 6, 8 and the reference k = 12 (96×48×48,
           0.7 M DOFs) — `--set adapt.max_level=0 --set tissue.grid=[8k,4k,4k]`
  adaptive marking max (θ = 0.3) and dorfler (fraction 0.5), templates hex2,
           hex3, hex4, `adapt.max_dofs` = 250 000. The static case re-solves
           the same problem every step on the mesh refined after the previous
           step; a run is stopped (SIGTERM to the process this script
           started) as soon as a step's mesh equals the previous one (the
           budget or max_level is reached), so its rows are distinct meshes.
  bench    adapt.hanging = eliminate vs lagrange, same adaptive run in
           dynamic mode with adapt.every = 3 (each mesh is solved 3 times,
           timings are medians over those steps).
--quick: uniform k ≤ 4 with reference k = 6, adaptive budget 30 000, a small
bench; a couple of minutes.

Output: Markdown tables on stdout (also written to CACHE/report.md) and
docs/img/adapt_error.png, adapt_eta.png, adapt_effectivity.png (quick mode:
CACHE/img/ unless --img is given). Needs numpy and matplotlib (Debian's
python3-numpy, python3-matplotlib); use /usr/bin/python3.
"""
import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np

from outputs import read_rows
from plotstyle import FIGSIZE, plt, save
from richardson import richardson
from study_engine import find_binary

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASE = os.path.join(ROOT, "cases", "adapt-localized.yaml")

# A whole mapping replaces the case's (a theta left over would be refused with dorfler).
STRATEGIES = [("max", ["adapt.marking={strategy: max, theta: 0.3}"], "max θ=0.3"),
              ("dorfler", ["adapt.marking={strategy: dorfler, fraction: 0.5}"], "dörfler 0.5")]
TEMPLATES = [("hex2", 6), ("hex3", 4), ("hex4", 3)]  # template, max_level
# The conforming element, for W − W_h = ‖u − u_h‖²_E (the docstring); ν = 0.3 does not lock.
ELEMENT = ["tissue.material.formulation=full"]


def log(msg):
    print(msg, file=sys.stderr, flush=True)


def drop_repeat(rows):
    """Without a last row that repeats the previous mesh (not a new point)."""
    if len(rows) >= 2 and rows[-1]["dofs"] == rows[-2]["dofs"]:
        return rows[:-1]
    return rows


def run_case(binary, cache, name, sets, steps, force=False, stop_when_static=False):
    """Runs the case with --set overrides into CACHE/name unless a finished
    run with the same command is there. Returns the rows of steps.csv."""
    out = os.path.join(cache, name)
    stamp = os.path.join(out, "run.json")
    cmd = [binary, "run", CASE, "--quiet", "--overwrite", "--out", out, "--set", "time.steps=%d" % steps]
    for s in ELEMENT + sets:
        cmd += ["--set", s]
    key = [os.path.basename(c) if i == 0 else c for i, c in enumerate(cmd)]
    if not force and os.path.exists(stamp):
        with open(stamp) as f:
            info = json.load(f)
        if info.get("cmd") == key:
            return drop_repeat(read_rows(os.path.join(out, "steps.csv"))), info
    os.makedirs(out, exist_ok=True)
    log("run %s: %s" % (name, " ".join(cmd)))
    t0 = time.time()
    p = subprocess.Popen(cmd)
    stopped = False
    csv_path = os.path.join(out, "steps.csv")
    while p.poll() is None:
        time.sleep(0.1)
        if stop_when_static and os.path.exists(csv_path):
            try:
                rows = read_rows(csv_path)
            except (ValueError, KeyError):
                continue  # a row being written
            if len(rows) >= 2 and rows[-1]["dofs"] == rows[-2]["dofs"]:
                p.send_signal(signal.SIGTERM)
                p.wait()
                stopped = True
    wall = time.time() - t0
    if p.returncode != 0 and not stopped:
        raise SystemExit("needlehex failed (exit %d): %s" % (p.returncode, " ".join(cmd)))
    rows = drop_repeat(read_rows(csv_path))
    info = {"cmd": key, "wall": wall, "stopped": stopped}
    with open(stamp, "w") as f:
        json.dump(info, f)
    return rows, info


def fmt_e(x, d=3):
    return "–" if x is None or not math.isfinite(x) else ("%%.%de" % d) % x


def median(a):
    return float(np.median(a)) if len(a) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--binary", default=None, help="needlehex (default: build/needlehex)")
    ap.add_argument("--cache", default=os.path.join(ROOT, "out", "adapt-study"))
    ap.add_argument("--img", default=None, help="where the PNGs go (default docs/img, quick: CACHE/img)")
    ap.add_argument("--quick", action="store_true", help="a smaller set (about two minutes)")
    ap.add_argument("--force", action="store_true", help="run everything again")
    ap.add_argument("--no-bench", action="store_true", help="skip the lagrange/eliminate timing")
    a = ap.parse_args()
    binary = find_binary(a.binary)
    cache = os.path.join(a.cache, "quick") if a.quick else a.cache
    img = a.img or (os.path.join(cache, "img") if a.quick else os.path.join(ROOT, "docs", "img"))
    os.makedirs(cache, exist_ok=True)
    os.makedirs(img, exist_ok=True)

    uniform_k = [1, 2, 3, 4] if a.quick else [1, 2, 3, 4, 5, 6, 8]
    ref_k = 6 if a.quick else 12
    budget = 30000 if a.quick else 250000
    max_steps = 12

    # ---- uniform ----
    uni = []  # (k, row, info)
    for k in uniform_k + [ref_k]:
        rows, info = run_case(binary, cache, "uniform-k%d" % k,
                              ["adapt.max_level=0", "tissue.grid=[%d,%d,%d]" % (8 * k, 4 * k, 4 * k)],
                              1, a.force)
        uni.append((k, rows[-1], info))
    W_ref = uni[-1][1]["work"]
    ks = [u[0] for u in uni[-3:]]
    W_inf, C_inf, p_inf = richardson(ks, [u[1]["work"] for u in uni[-3:]])
    ks4 = [u[0] for u in uni[-4:-1]]
    W_inf_prev, _, p_prev = richardson(ks4, [u[1]["work"] for u in uni[-4:-1]])

    # ---- adaptive ----
    adapt = []  # (label, strategy, template, rows, info)
    for sname, ssets, slabel in STRATEGIES:
        for tmpl, lvl in TEMPLATES:
            sets = ssets + ["adapt.template=%s" % tmpl, "adapt.max_level=%d" % lvl,
                            "adapt.max_dofs=%d" % budget]
            rows, info = run_case(binary, cache, "adapt-%s-%s" % (sname, tmpl), sets, max_steps,
                                  a.force, stop_when_static=True)
            # A step whose transferred state already met the Newton tolerance
            # (a refinement adding a handful of cells) was not re-solved: its
            # W_h is not the Galerkin solution's. Left out (and reported).
            skipped = [r["step"] for r in rows if r["iterations"] < 1]
            rows = [r for r in rows if r["iterations"] >= 1]
            adapt.append(("%s, %s" % (slabel, tmpl), sname, tmpl, rows, info))
            if skipped:
                log("%s: steps %s not re-solved (0 Newton iterations), left out" % (
                    adapt[-1][0], skipped))
                info["skipped"] = skipped

    W_best = max([r["work"] for _, _, _, rows, _ in adapt for r in rows] + [W_ref])
    best_run = max(adapt, key=lambda x: x[3][-1]["work"])
    # Extrapolation of the adaptive sequence of the best run in N (dofs):
    # W(N) = W∞ − C N^(−q), through its last three meshes.
    # The last steps of a run near its budget add few DOFs each; take the
    # last mesh and, going back, meshes with at least 1.5× fewer DOFs.
    br = [best_run[3][-1]]
    for r in reversed(best_run[3][:-1]):
        if len(br) < 3 and r["dofs"] * 1.5 <= br[0]["dofs"]:
            br.insert(0, r)
    W_inf_ad, _, q_ad = richardson([r["dofs"] for r in br], [r["work"] for r in br])

    def err(w, W):
        d = W - w
        return math.sqrt(d) if d > 0 else float("nan")

    out = []
    P = out.append
    P("## Reference\n")
    P("Case `cases/adapt-localized.yaml`; binary `%s`.\n" % binary)
    P("| mesh | dofs | W = f·u (J) | wall time (s) | t_factor (s) |")
    P("|---|---|---|---|---|")
    for k, r, info in uni:
        P("| uniform %d×%d×%d%s | %d | %.10e | %.2f | %.2f |" % (
            8 * k, 4 * k, 4 * k, " (reference)" if k == ref_k else "", r["dofs"], r["work"],
            info["wall"], r["t_factor"]))
    P("")
    P("- W_ref (uniform k = %d): %.10e J" % (ref_k, W_ref))
    P("- Richardson through k = %s: W_∞ = %.10e J, order p = %.3f in k (W_∞ − W_ref = %.3e, "
      "%.3f %% of W_∞)" % (ks, W_inf, p_inf, W_inf - W_ref, 100 * (W_inf - W_ref) / W_inf))
    P("- Richardson through k = %s: W_∞ = %.10e J, p = %.3f (the previous triple: the spread "
      "of W_∞ is %.2e relative)" % (ks4, W_inf_prev, p_prev, abs(W_inf - W_inf_prev) / W_inf))
    P("- largest W_h of all runs (a lower bound of W, Galerkin): %.10e J (%s)" % (
        W_best, "uniform reference" if W_best == W_ref else best_run[0]))
    P("- extrapolation of the best adaptive run (%s) in N through its meshes of %s DOFs: "
      "W_∞ = %.10e J, order q = %.3f in N" % (best_run[0], [r["dofs"] for r in br], W_inf_ad, q_ad))
    W_main, W_main_name = W_inf, "the uniform Richardson W_∞"
    if not W_inf > W_best:  # below a Galerkin lower bound: cannot be W
        P("- the uniform Richardson W_∞ is below the largest W_h: not usable")
        if W_inf_ad > W_best:
            W_main, W_main_name = W_inf_ad, "the adaptive extrapolation W_∞"
        else:
            W_main, W_main_name = float("nan"), "no usable estimate (errors are nan)"
    odd = [(label, r["step"]) for label, _, _, rows, _ in adapt for r in rows if r["iterations"] != 1]
    if odd:
        P("- WARNING: steps with more than one Newton iteration: %s" % odd)
    skipped = [(label, info["skipped"]) for label, _, _, _, info in adapt if info.get("skipped")]
    if skipped:
        P("- left out, not re-solved after a tiny refinement (0 Newton iterations): %s" % skipped)
    P("\nErrors below: ‖e‖_E = sqrt(W_∞ − W_h) with %s (primary) and "
      "sqrt(W_ref − W_h) (\"vs ref\"; – where W_h ≥ W_ref). Relative: ‖e‖_E / sqrt(W_∞).\n"
      % W_main_name)

    # ---- per-run summary ----
    def run_stats(rows):
        e = [err(r["work"], W_main) for r in rows]
        e_ref = [err(r["work"], W_ref) for r in rows]
        return e, e_ref

    uni_rows = [u[1] for u in uni[:-1]]
    uni_dofs = np.array([r["dofs"] for r in uni_rows], float)
    uni_err = np.array([err(r["work"], W_main) for r in uni_rows])
    fin = uni_rows[-1]
    fin_k = uni[-2][0]
    e_fin = uni_err[-1]

    def dofs_to_reach(rows, target_w):
        """DOFs at which the run's W_h reaches target_w, i.e. its error that
        of the mesh with W_h = target_w, whatever W is: W_h interpolated
        linearly in log N between the two steps around it."""
        w = [r["work"] for r in rows]
        n = [r["dofs"] for r in rows]
        for i in range(len(rows)):
            if w[i] >= target_w:
                if i == 0:
                    return float(n[0])
                t = (target_w - w[i - 1]) / (w[i] - w[i - 1])
                return math.exp(math.log(n[i - 1]) + t * (math.log(n[i]) - math.log(n[i - 1])))
        return float("nan")

    P("## Summary per run\n")
    P("Final mesh of each run; effectivity = η / ‖e‖_E; time: sum of `t_step` over the run's "
      "steps; ms/step: median `t_step`; N(e_uni): DOFs at which the run reaches the error of the "
      "uniform %d×%d×%d mesh (%d DOFs, ‖e‖_E = %.3e): where the run's W_h reaches that mesh's "
      "W_h (interpolated linearly in log N between steps), which does not depend on the "
      "estimate of W.\n" % (
          8 * fin_k, 4 * fin_k, 4 * fin_k, fin["dofs"], e_fin))
    P("| run | steps | final dofs | ‖e‖_E | rel. | ‖e‖_E vs ref | η | η_rel | effectivity | "
      "time (s) | ms/step | N(e_uni) | DOF ratio |")
    P("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for k, r, info in uni[:-1]:
        e = err(r["work"], W_main)
        P("| uniform %d×%d×%d | 1 | %d | %.3e | %.2f %% | %s | %.3e | %.2f %% | %.2f | %.2f | %.0f | – | – |" % (
            8 * k, 4 * k, 4 * k, r["dofs"], e, 100 * e / math.sqrt(W_main),
            fmt_e(err(r["work"], W_ref)), r["eta"], 100 * r["eta_rel"], r["eta"] / e,
            r["t_step"], 1e3 * r["t_step"]))
    headline = []
    for label, sname, tmpl, rows, info in adapt:
        r = rows[-1]
        e = err(r["work"], W_main)
        n_reach = dofs_to_reach(rows, fin["work"])
        ratio = fin["dofs"] / n_reach if math.isfinite(n_reach) else float("nan")
        headline.append((label, n_reach, ratio))
        P("| %s | %d | %d | %.3e | %.2f %% | %s | %.3e | %.2f %% | %.2f | %.2f | %.0f | %s | %s |" % (
            label, len(rows), r["dofs"], e, 100 * e / math.sqrt(W_main),
            fmt_e(err(r["work"], W_ref)), r["eta"], 100 * r["eta_rel"], r["eta"] / e,
            sum(x["t_step"] for x in rows), 1e3 * median([x["t_step"] for x in rows]),
            "%.0f" % n_reach if math.isfinite(n_reach) else "not reached",
            "%.1f×" % ratio if math.isfinite(ratio) else "–"))

    P("\n## Every step\n")
    P("| run | step | dofs | free dofs | cells | hanging | W_h (J) | ‖e‖_E | ‖e‖_E vs ref | η | "
      "effectivity | t_step (s) | t_adapt (s) |")
    P("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for label, sname, tmpl, rows, info in adapt:
        for r in rows:
            e = err(r["work"], W_main)
            P("| %s | %d | %d | %d | %d | %d | %.8e | %.3e | %s | %.3e | %.2f | %.3f | %.3f |" % (
                label, r["step"], r["dofs"], r["free_dofs"], r["cells"], r["hanging"], r["work"],
                e, fmt_e(err(r["work"], W_ref)), r["eta"], r["eta"] / e, r["t_step"],
                r["t_adapt"]))
    # cost of estimate + mark + refine relative to the step's solve
    frac = [r["t_adapt"] / (r["t_step"] - r["t_adapt"] - r["t_output"])
            for _, _, _, rows, _ in adapt for r in rows[:-1] if r["dofs"] > 5000]
    P("\nt_adapt (SPR estimate + marking + refinement + rebuild) / (t_step − t_adapt − t_output) "
      "over the adaptive steps with more than 5000 DOFs: median %.2f, range %.2f–%.2f." % (
          median(frac), min(frac), max(frac)) if frac else "")

    eff = [r["eta"] / err(r["work"], W_main) for _, _, _, rows, _ in adapt for r in rows]
    eff = [x for x in eff if math.isfinite(x)]
    eff_u = [r["eta"] / e for r, e in zip(uni_rows, uni_err)]
    P("\n## Headline\n")
    best = min((h for h in headline if math.isfinite(h[1])), key=lambda h: h[1], default=None)
    P("Finest uniform mesh (reference excluded): %d×%d×%d, %d DOFs, ‖e‖_E = %.3e (%.2f %%)." % (
        8 * fin_k, 4 * fin_k, 4 * fin_k, fin["dofs"], e_fin, 100 * e_fin / math.sqrt(W_main)))
    for label, n, ratio in headline:
        P("- %s: %s" % (label, "reaches it at %.0f DOFs, %.1f× fewer" % (n, ratio)
                        if math.isfinite(n) else "does not reach it within its budget"))
    if best:
        P("\nBest: %s, %.0f DOFs, %.1f× fewer than uniform." % best)
    eff_uf = [x for x in eff_u if math.isfinite(x)]
    if eff and eff_uf:
        P("Effectivity η/‖e‖_E: uniform %.2f–%.2f, adaptive %.2f–%.2f (median %.2f)." % (
            min(eff_uf), max(eff_uf), min(eff), max(eff), median(eff)))
    n_bad = sum(1 for _, _, _, rows, _ in adapt for r in rows if r["work"] >= W_main)
    if n_bad:
        P("\nWARNING: %d adaptive meshes have W_h ≥ W_∞: the extrapolated W_∞ is too low "
          "(the uniform sequence is not in its asymptotic range)." % n_bad)

    # ---- plots ----
    colors = {"hex2": "tab:blue", "hex3": "tab:orange", "hex4": "tab:green"}
    styles = {"max": "-o", "dorfler": "--s"}

    def plot(ykey, fname, ylabel, title, ylog=True):
        fig, ax = plt.subplots(figsize=FIGSIZE)
        if ykey == "err":
            yu = uni_err
        elif ykey == "eta":
            yu = np.array([r["eta"] for r in uni_rows])
        else:
            yu = np.array(eff_u)
        ax.plot(uni_dofs, yu, "k-^", lw=2, label="uniform 8k×4k×4k, k = %s" % ",".join(
            str(u[0]) for u in uni[:-1]))
        for label, sname, tmpl, rows, info in adapt:
            n = [r["dofs"] for r in rows]
            if ykey == "err":
                y = [err(r["work"], W_main) for r in rows]
            elif ykey == "eta":
                y = [r["eta"] for r in rows]
            else:
                y = [r["eta"] / err(r["work"], W_main) for r in rows]
            ax.plot(n, y, styles[sname], color=colors[tmpl], ms=4, label=label)
        if ykey == "err":
            ax.axhline(e_fin, color="grey", ls=":", lw=1,
                       label="error of uniform %d×%d×%d" % (8 * fin_k, 4 * fin_k, 4 * fin_k))
            x0 = uni_dofs[1]
            ax.plot([x0, x0 * 100], [uni_err[1] * 0.5, uni_err[1] * 0.5 * 100 ** (-1 / 3)], "k:",
                    lw=1, label="slope −1/3 (O(h), uniform)")
        ax.set_xscale("log")
        if ylog and not np.any(np.isfinite(yu) & (yu > 0)) and ykey != "eta":
            plt.close(fig)
            log("%s: no finite errors, not plotted" % fname)
            return
        if ylog:
            ax.set_yscale("log")
        ax.set_xlabel("DOFs (3 × nodes)")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        save(fig, os.path.join(img, fname), legend=ax)

    plot("err", "adapt_error.png", "‖u − u_h‖_E = sqrt(W_∞ − W_h)  (√J)",
         "adapt-localized: energy-norm error vs DOFs")
    plot("eta", "adapt_eta.png", "SPR estimate η  (√J)", "adapt-localized: η vs DOFs")
    plot("eff", "adapt_effectivity.png", "effectivity η / ‖e‖_E", "adapt-localized: effectivity index",
         ylog=False)

    # ---- hanging: eliminate vs lagrange ----
    if not a.no_bench:
        bench_budget = 8000 if a.quick else 30000
        res = {}
        for mode in ("eliminate", "lagrange"):
            sets = ["time.mode=dynamic", "time.step=0.001", "adapt.every=3", "adapt.template=hex2",
                    "adapt.max_level=5", "adapt.max_dofs=%d" % bench_budget,
                    "adapt.hanging=%s" % mode]
            # 13 steps: meshes of 675 ... 2 295 DOFs three times each, then one
            # step on the next mesh (12 477 DOFs): lagrange takes minutes per
            # step there, and much longer beyond.
            rows, info = run_case(binary, cache, "bench-%s" % mode, sets, 7 if a.quick else 13,
                                  a.force)
            res[mode] = rows
        P("\n## Hanging nodes: eliminate vs lagrange\n")
        P("Dynamic mode (`time.mode=dynamic`, step 1 ms), hex2, max θ = 0.3, `adapt.every=3`: each "
          "mesh is stepped 3 times (the last mesh once); medians over those steps (s). `t_step` includes the "
          "refinement of the third step, so its median is a step without refinement.\n")
        P("| dofs | free dofs (elim.) | hanging | constraint rows (lagr.) | mode | t_assemble | "
          "t_factor | t_solve | t_constraints | t_step | lagrange / eliminate |")
        P("|---|---|---|---|---|---|---|---|---|---|---|")
        sizes = sorted(set(r["dofs"] for r in res["eliminate"]))
        for d in sizes:
            grp = {m: [r for r in res[m] if r["dofs"] == d] for m in res}
            if not grp["lagrange"]:
                P("| %d | – | – | – | lagrange: mesh differs | | | | | | |" % d)
                continue
            ts = {m: median([r["t_step"] for r in grp[m]]) for m in grp}
            for m in ("eliminate", "lagrange"):
                g = grp[m]
                P("| %d | %d | %d | %d | %s | %.4f | %.4f | %.4f | %.4f | %.4f | %s |" % (
                    d, grp["eliminate"][0]["free_dofs"], g[0]["hanging"],
                    grp["lagrange"][0]["constraints"], m,
                    median([r["t_assemble"] for r in g]), median([r["t_factor"] for r in g]),
                    median([r["t_solve"] for r in g]), median([r["t_constraints"] for r in g]),
                    ts[m], "%.2f" % (ts["lagrange"] / ts["eliminate"]) if m == "lagrange" else ""))
        # agreement of the two enforcements on the same steps
        same = [(x, y) for x, y in zip(res["lagrange"], res["eliminate"]) if x["dofs"] == y["dofs"]]
        de = max(abs(x["eta"] - y["eta"]) / y["eta"] for x, y in same if y["eta"] > 0)
        dw = max(abs(x["work"] - y["work"]) / abs(y["work"]) for x, y in same if y["work"])
        P("\nAgreement over the %d steps (identical meshes): η to %.1e relative (printed with 7 "
          "digits), W = f·u to %.1e relative." % (len(same), de, dw))

    text = "\n".join(out) + "\n"
    with open(os.path.join(cache, "report.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
