#!/usr/bin/python3
"""The per-step converged reference of tools/study.py dbs-goal and phantom
(per_step_reference, tools/richardson.py): Richardson through three meshes
with a sanity range on the observed order, else the finest value with the
last difference as its error bar. Silent on success, one line per failure,
exit 1.

Expected values from the closed form f(h) = f∞ − C h^p at h = 14, 10, 7:
 1. p = 2 and p = 4.5 (inside [1, 6)): the extrapolated value is f∞, the
    order p, the error bar C·7^p = |f∞ − f(7)|.
 2. p = 0.5 (outside): the 7 mm value, bar |f(7) − f(10)|, order 0.5
    reported but not used.
 3. Differences changing sign (1.0, 1.2, 1.1): no order, 1.1 ± 0.1.
 4. The same value on every mesh (step 0): that value, bar 0, no order.
 5. The phantom study's reference (tools/study_phantom.py) on probes whose
    components follow u(h) = u∞ + C h^2 at h = 1.25, 0.833, 0.625 mm (its
    three finest meshes), different u∞, C per component and step: u∞, order
    2, sane, bar |C| 0.625²; the order of the RMS differences between
    successive meshes (u(h) = u∞ + h^1.5 v, a fixed vector v, on 2.5, 1.25,
    0.833 mm): 1.5.
 6. The ladder reference (ladder_reference: the least-squares line
    f∞ + a h over any number of grids): on f = f∞ + a h exactly, at
    h = 14.4, 12.1, 10, 8.95, 8.24, 7.78 (not nested), f∞ and a to
    round-off, bar 0; with a scatter ±δ alternating over the grids, the
    closed form of the fit: f∞, a of the exact line plus the fit of the
    scatter (computed here by the normal equations, independently of
    lstsq), the bar twice the intercept's standard error.
 7. dbs-goal --ladder (tools/study_dbs_goal.py): reference_ladder on runs
    whose distance and STN position follow exact lines in h per step gives
    those lines' values at h = 0 with bars 0; a folder with fewer than
    three complete runs is refused with a message naming it.
"""
import math
import os
import sys

import numpy as np

SRC = os.environ.get("NH_SOURCE_DIR", os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(SRC, "tools"))
from richardson import ladder_reference, per_step_reference  # noqa: E402

failures = []


def check(what, got, want, tol):
    if not (abs(got - want) <= tol or (math.isnan(got) and math.isnan(want))):
        print("FAIL: %s = %.15g, expected %.15g (tolerance %g)" % (what, got, want, tol),
              file=sys.stderr)
        failures.append(what)


h = [14.0, 10.0, 7.0]
cols, want = [], []
for f_inf, C, p in ((2.0, 0.01, 2.0), (1.0, 1e-6, 4.5), (3.0, 0.2, 0.5)):
    cols.append([f_inf - C * x ** p for x in h])
    if 1.0 <= p < 6.0:
        want.append((f_inf, C * 7.0 ** p, p, True))
    else:
        want.append((cols[-1][2], abs(cols[-1][2] - cols[-1][1]), p, False))
cols.append([1.0, 1.2, 1.1])
want.append((1.1, 0.1, float("nan"), False))
cols.append([0.5, 0.5, 0.5])
want.append((0.5, 0.0, float("nan"), False))
ref, bar, order, sane = per_step_reference(h, np.array(cols).T, (1.0, 5.99))
for i, (r, b, p, ok) in enumerate(want):
    check("column %d: reference" % i, ref[i], r, 1e-10)
    check("column %d: error bar" % i, bar[i], b, 1e-10)
    check("column %d: order" % i, order[i], p, 1e-8)
    if bool(sane[i]) != ok:
        print("FAIL: column %d: sane %s, expected %s" % (i, bool(sane[i]), ok), file=sys.stderr)
        failures.append("sane %d" % i)

from study_phantom import converged_reference, difference_order  # noqa: E402

hp = [1.25, 0.8333333333333334, 0.625]
rng = np.random.default_rng(1)
uinf = {n: rng.normal(size=(5, 3)) * 1e-6 for n in ("1", "1A")}
coef = {n: rng.normal(size=(5, 3)) * 1e-7 for n in ("1", "1A")}
runs = [{n: uinf[n] + coef[n] * x ** 2 for n in uinf} for x in hp]
conv = converged_reference(runs, hp, list(uinf), (1.0, 5.99))
for n in uinf:
    for i in range(5):
        for c in range(3):
            what = "phantom probe %s step %d component %d" % (n, i, c)
            check(what + ": reference", conv[n]["u"][i, c], uinf[n][i, c], 1e-15)
            check(what + ": order", conv[n]["order"][i, c], 2.0, 1e-6)
            check(what + ": bar", conv[n]["bar"][i, c], abs(coef[n][i, c]) * 0.625 ** 2, 1e-15)
            check(what + ": sane", float(conv[n]["sane"][i, c]), 1.0, 0)
hd = [2.5, 1.25, 0.8333333333333334]
v = np.array([0.3, -0.1, 0.7])
d = [np.linalg.norm(v) * abs(hd[i] ** 1.5 - hd[i + 1] ** 1.5) for i in range(2)]
check("phantom: order of the RMS differences", difference_order(hd, d), 1.5, 1e-6)

# 6. the ladder reference
hl = [14.44, 12.14, 10.0, 8.95, 8.24, 7.78]
finf, slope, delta = [1.75, -2.0], [-0.004, 0.01], 0.003
F = np.array([[finf[j] + slope[j] * x for j in range(2)] for x in hl])
ref, bar, a = ladder_reference(hl, F)
for j in range(2):
    check("ladder, exact line %d: reference" % j, ref[j], finf[j], 1e-13)
    check("ladder, exact line %d: slope" % j, a[j], slope[j], 1e-13)
    check("ladder, exact line %d: bar" % j, bar[j], 0.0, 1e-12)
sc = np.array([delta * (-1) ** i for i in range(len(hl))])
ref, bar, a = ladder_reference(hl, F + sc[:, None])
n_l, sh, shh = len(hl), sum(hl), sum(x * x for x in hl)
sy, shy = sc.sum(), sum(x * y for x, y in zip(hl, sc))
det = n_l * shh - sh * sh
b0, b1 = (shh * sy - sh * shy) / det, (n_l * shy - sh * sy) / det  # the scatter's own line
res2 = sum((y - b0 - b1 * x) ** 2 for x, y in zip(hl, sc))
se = math.sqrt(res2 / (n_l - 2) * shh / det)
for j in range(2):
    check("ladder, scattered line %d: reference" % j, ref[j], finf[j] + b0, 1e-13)
    check("ladder, scattered line %d: slope" % j, a[j], slope[j] + b1, 1e-13)
    check("ladder, scattered line %d: bar" % j, bar[j], 2 * se, 1e-13)

import tempfile  # noqa: E402
import types  # noqa: E402

from study_dbs_goal import ladder_runs, reference_ladder  # noqa: E402

steps = 7
d0, dA = np.linspace(0.09, 0.001, steps), np.linspace(0.0, 2e-4, steps)
x0 = np.outer(np.linspace(0, 1, steps), [0.012, -0.005, -0.01])
xA = np.outer(np.linspace(0, 1, steps), [1e-5, -2e-5, 3e-5])
L = [{"h": x, "d": d0 + dA * x, "x": x0 + xA * x} for x in hl]
R = reference_ladder(L)
for i in range(steps):
    check("ladder runs, step %d: distance" % i, R["d"][i], d0[i], 1e-15)
    check("ladder runs, step %d: distance bar" % i, R["d_bar"][i], 0.0, 1e-15)
    check("ladder runs, step %d: STN position error" % i,
          float(np.linalg.norm(R["x"][i] - x0[i])), 0.0, 1e-15)
    check("ladder runs, step %d: STN bar" % i, R["x_bar"][i], 0.0, 1e-15)
with tempfile.TemporaryDirectory() as tmp:
    os.mkdir(os.path.join(tmp, "10x12x9"))
    try:
        ladder_runs(types.SimpleNamespace(ladder=tmp), "needlehex", "scene.yaml", steps, None)
        print("FAIL: --ladder with no complete run accepted", file=sys.stderr)
        failures.append("ladder refusal")
    except SystemExit as e:
        if "fewer than three" not in str(e) or tmp not in str(e):
            print("FAIL: --ladder refusal: %s" % e, file=sys.stderr)
            failures.append("ladder refusal message")
sys.exit(1 if failures else 0)
