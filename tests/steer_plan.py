#!/usr/bin/python3
"""`needlehex plan` for a bevel-tip needle (docs/cases.md, "Planning the
steering") in the kinematic limit, against the bicycle model's closed form.

Runs the binary ($NH_BINARY) on cases/needle-phantom.yaml with --set
overrides, into $NH_WORK/steer_plan. The kinematic limit: a tissue far
stiffer than the needle bends (E = 1e9 Pa against a 50 MPa needle of
r = 1 mm): the tissue does not yield to the needle, the tip goes where the
bevel's anchor is, and the path is a chain of circular arcs of one
curvature kappa (docs/interaction.md, "Rigid limit: a bicycle"). A small
bevel (0.5 deg), path points every 1 mm and 0.05 mm of advance per step
keep the wheelbase l1 = tan(psi)/kappa (the lag of the curvature behind the
bevel) near 0.4 mm. No friction; the planner keeps the motion's speed
(1 cm/s) and its turn time (0.1 s).

Derived expectations:
 0. kappa: a one-bend insertion of 20 mm, a circle fitted to the tip path
    beyond 3 mm (the bicycle model's circle); its error dk: the larger
    difference of the curvatures fitted to the two halves of that path; the
    lead L0: the x at which that circle touches the line of insertion (the
    path is straight until the channel's first points hold it: about one
    spacing, measured 0.75 mm, where the wheelbase l1 is 0.2 mm).
 (a) the planner given plan.curvature = kappa, target T = (18, 2) mm in the
    bevel's plane (x along the insertion from the entry, y towards the
    bevel): its first iterate is the bicycle model's one-turn solution:
        rho = |T - (0, R)|, beta = atan2(R - Y, X),
        phi = asin((rho^2 + 3R^2)/(4 R rho)) - beta  (the smaller root),
        turn depth d1 = R phi, depth D = R (phi + sweep), sweep the
        clockwise angle from the turn point to T about the second circle's
        centre (2R sin phi, R - 2R cos phi)
    (equal to the C code's to 1e-9 m: an independent implementation of the
    same closed form), and it converges in one run with the tolerance
        tol_a = kappa L0 D + 2 tan(psi) (D - d1),
    the first-order error of the model's lags: the curvature sets in L0
    after the entry and changes sign l1 = tan(psi)/kappa after the turn,
    which turns the heading by kappa L0 and 2 kappa l1 = 2 tan(psi) over the
    D and D - d1 that follow.
 (b) the planner without plan.curvature (kappa estimated, then fitted to its
    first run) on T = (18, 3) mm, tolerance 0.1 mm, on 2 workers: it
    converges within 12 runs, with one turn, at a turn depth within
        |dd1/dkappa| dk + L0 + l1
    of the closed form's with the measured kappa (the curvature's error
    propagated, and the lags at the entry and at the turn, which shift the
    turn by up to L0 and l1); plan.yaml records each iteration's
    schedule and the clearance (+inf written as .inf: no obstacles); the
    final link is the converged run.
 (c) out of the plane: plan.curvature = kappa, T = (18, 2, 1) mm, 1 mm off
    the bevel's plane towards z = x × y. The bicycle model in 3-D: the first
    arc (in the plane) ends at P(d1) with heading t; a half turn of the base
    by pi + theta (right-handed about the heading) points the bevel along
    n = -m cos(theta) - z sin(theta) (m: the heading's left normal in the
    plane, towards the first arc's centre), so the second arc of radius R
    lies in the plane through P spanned by t and n, and reaches T when T's
    coordinates u = (T - P).t, v = |T - P - u t| in it satisfy
        u^2 + v^2 = 2 R v   (the circle through P tangent to t),
    solved for d1 by bisection (the smaller root), then
        theta = atan2(-Tz, -(T - P).m),  D = d1 + R atan2(u, R - v).
    The planner's first iterate has one turn at d1, depth D and roll theta
    (to 1e-9), and it converges in one run within tol_a of this case (the
    same lags, in the tilted plane of the second arc).
"""
import math
import os
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nh_run import BIN, fail, finish, run as nh_run, work  # noqa: E402

VERBOSE = "--verbose" in sys.argv
PHANTOM = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "needle-phantom.yaml")
PSI = 0.5
ENTRY = np.array([0.0, 0.01, 0.01])  # where the needle's axis enters the block
BASE = ["tissue.material.young=1.0e9", "tools.0.bevel={angle: %r, toward: [0, 1, 0]}" % PSI,
        "tools.0.interaction.friction=0", "tools.0.interaction.friction_per_length=0",
        "tools.0.interaction.spacing=0.001", "time.step=0.005", "output.every=1000"]
MOTION = ("tools.0.motion=[{until: 1.0, speed: 0.01}, {until: 1.1, speed: 0, spin: %r}, "
          "{until: 2.5, speed: 0.01}]" % (math.pi / 0.1))


def say(*a):
    if VERBOSE:
        print(*a)


def circle(x, y):
    """Algebraic (Kasa) circle fit: centre, radius."""
    A = np.c_[x, y, np.ones_like(x)]
    c = np.linalg.lstsq(A, x * x + y * y, rcond=None)[0]
    xc, yc = c[0] / 2, c[1] / 2
    return xc, yc, math.sqrt(c[2] + xc * xc + yc * yc)


def one_turn(kappa, X, Y):
    """The bicycle model's one-turn path to (X, Y): turn depth and depth."""
    R = 1.0 / kappa
    rho, beta = math.hypot(X, R - Y), math.atan2(R - Y, X)
    a = math.asin((rho * rho + 3 * R * R) / (4 * R * rho))
    phi = min((a - beta) % (2 * math.pi), (math.pi - a - beta) % (2 * math.pi))
    cx, cy = 2 * R * math.sin(phi), R - 2 * R * math.cos(phi)
    sweep = (phi + math.pi / 2 - math.atan2(Y - cy, X - cx)) % (2 * math.pi)
    return R * phi, R * (phi + sweep)


def one_turn_rolled(kappa, X, Y, Z):
    """The bicycle model's one-turn path to (X, Y, Z) in 3-D: turn depth,
    depth and roll theta (the turn's spin beyond pi)."""
    R = 1.0 / kappa

    def g(d):
        h = d / R
        P = np.array([R * math.sin(h), R * (1 - math.cos(h)), 0.0])
        t = np.array([math.cos(h), math.sin(h), 0.0])
        w = np.array([X, Y, Z]) - P
        u = w @ t
        v = np.linalg.norm(w - u * t)
        return w @ w - 2 * R * v, t, w, u, v

    ds = np.linspace(1e-9, math.hypot(X, Y), 4001)
    gs = [g(d)[0] for d in ds]
    i = next(i for i in range(len(ds) - 1) if gs[i] * gs[i + 1] <= 0)
    lo, hi = ds[i], ds[i + 1]
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if g(lo)[0] * g(mid)[0] <= 0 else (mid, hi)
    d = 0.5 * (lo + hi)
    _, t, w, u, v = g(d)
    m = np.array([-t[1], t[0], 0.0])
    return d, d + R * (math.atan2(u, R - v) % (2 * math.pi)), math.atan2(-Z, -(w @ m))


def read_plan(path):
    """The plan.yaml the planner wrote (YAML, flow mappings per iteration)."""
    import yaml
    with open(path) as f:
        return yaml.safe_load(f)


def plan(name, target, extra, options):
    out = os.path.join(work("steer_plan"), name)
    cmd = [BIN, "plan", PHANTOM, "--out", out, "--quiet"] + options
    for s in BASE + [MOTION, "name=" + name, "targets.0.point=[%r, %r, %r]" % tuple(target)] + extra:
        cmd += ["--set", s]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode not in (0, 1) or not os.path.exists(os.path.join(out, "plan.yaml")):
        fail("%s: exit %d and no plan.yaml: %s" % (name, p.returncode, p.stderr.strip()))
        return None, out
    return read_plan(os.path.join(out, "plan.yaml")), out


# 0. the curvature of a one-bend insertion
res = nh_run(PHANTOM, os.path.join(work("steer_plan"), "one-bend"),
             BASE + ["name=one-bend", "time.end=2.05", "tools.0.motion=[{until: 2.05, speed: 0.01}]"],
             tables=("tools",))
if res is None:
    finish()
tip = np.array([[float(r["tip_x"]), float(r["tip_y"]), float(r["depth"])] for r in res["tools"]])
tip = tip[tip[:, 2] > 0.003]
x, y = tip[:, 0] - ENTRY[0], tip[:, 1] - ENTRY[1]
xc, yc, R = circle(x, y)
kappa, L0 = 1.0 / R, xc
half = len(x) // 2
k_halves = [1.0 / circle(x[s], y[s])[2] for s in (slice(0, half), slice(half, None))]
dk = max(abs(k - kappa) for k in k_halves)
l1 = math.tan(math.radians(PSI)) / kappa
say("0. kappa %.5g 1/m (halves %.5g, %.5g: dk %.3g), wheelbase %.3g mm, lead %.3g mm" %
    (kappa, k_halves[0], k_halves[1], dk, 1e3 * l1, 1e3 * L0))

# (a) given kappa: the first iterate is the closed form, one run
Ta = (0.018, 0.002)
d1, D = one_turn(kappa, *Ta)
tol_a = kappa * L0 * D + 2 * math.tan(math.radians(PSI)) * (D - d1)
doc, out = plan("given-kappa", ENTRY + [Ta[0], Ta[1], 0], ["plan.curvature=%r" % kappa],
                ["--tolerance", repr(tol_a), "--max-runs", "3"])
if doc is not None:
    it = doc["iterations"][0]
    turns, depth = it["schedule"]["turns"], it["schedule"]["depth"]
    say("(a) closed form: turn %.6f mm, depth %.6f mm; planner's first: %s mm, %.6f mm; miss "
        "%.4g mm (tolerance %.4g mm), runs %d" % (1e3 * d1, 1e3 * D, [1e3 * t for t in turns],
                                                  1e3 * depth, 1e3 * it["miss"], 1e3 * tol_a,
                                                  doc["runs"]))
    if len(turns) != 1 or abs(turns[0] - d1) > 1e-9 or abs(depth - D) > 1e-9:
        fail("(a) first iterate: turns %s depth %r, expected [%r] and %r (the bicycle closed "
             "form; tolerance 1e-9 m)" % (turns, depth, d1, D))
    if not (doc["converged"] and doc["runs"] == 1):
        fail("(a) expected convergence in one run (miss <= %.4g m), got runs %d, converged %s, "
             "miss %.4g m" % (tol_a, doc["runs"], doc["converged"], it["miss"]))

# (c) out of the plane: the roll
Tc = (0.018, 0.002, 0.001)
d1, D, theta = one_turn_rolled(kappa, *Tc)
tol_c = kappa * L0 * D + 2 * math.tan(math.radians(PSI)) * (D - d1)
doc, out = plan("rolled", ENTRY + list(Tc), ["plan.curvature=%r" % kappa],
                ["--tolerance", repr(tol_c), "--max-runs", "3"])
if doc is not None:
    it = doc["iterations"][0]
    sch = it["schedule"]
    say("(c) closed form: turn %.6f mm, depth %.6f mm, roll %.6f deg; planner's first: %s mm, "
        "%.6f mm, %.6f deg; miss %.4g mm (%s mm; tolerance %.4g mm), runs %d" %
        (1e3 * d1, 1e3 * D, math.degrees(theta), [1e3 * x for x in sch["turns"]],
         1e3 * sch["depth"], math.degrees(sch["roll"]), 1e3 * it["miss"],
         ["%.3g" % (1e3 * x) for x in it["miss_vector"]], 1e3 * tol_c, doc["runs"]))
    if (len(sch["turns"]) != 1 or abs(sch["turns"][0] - d1) > 1e-9 or abs(sch["depth"] - D) > 1e-9
            or abs(sch["roll"] - theta) > 1e-9):
        fail("(c) first iterate: turns %s depth %r roll %r, expected [%r], %r and %r (the 3-D "
             "bicycle closed form; tolerance 1e-9)" % (sch["turns"], sch["depth"], sch["roll"],
                                                       d1, D, theta))
    if not (doc["converged"] and doc["runs"] == 1):
        fail("(c) expected convergence in one run (miss <= %.4g m), got runs %d, converged %s, "
             "miss %.4g m" % (tol_c, doc["runs"], doc["converged"], it["miss"]))

# (b) kappa estimated and fitted: the turn depth against the closed form
Tb = (0.018, 0.003)
doc, out = plan("fitted-kappa", ENTRY + [Tb[0], Tb[1], 0], [],
                ["--tolerance", "1e-4", "--max-runs", "12", "--workers", "2"])
if doc is not None:
    d1, D = one_turn(kappa, *Tb)
    eps = 1e-6 * kappa
    dd1 = (one_turn(kappa + eps, *Tb)[0] - one_turn(kappa - eps, *Tb)[0]) / (2 * eps)
    bound = abs(dd1) * dk + L0 + l1
    fin = doc["schedule"]
    say("(b) converged %s in %d runs (misses %s mm), curvature %.5g 1/m (initial %.5g); final "
        "turn %s mm vs closed form %.4f mm (bound %.3g mm), depth %.4f vs %.4f mm" %
        (doc["converged"], doc["runs"], ["%.3g" % (1e3 * i["miss"]) for i in doc["iterations"]],
         doc["curvature"][0], doc["curvature_initial"], [1e3 * t for t in fin["turns"]], 1e3 * d1,
         1e3 * bound, 1e3 * fin["depth"], 1e3 * D))
    if not doc["converged"]:
        fail("(b) not converged in %d runs: misses %s m" %
             (doc["runs"], [i["miss"] for i in doc["iterations"]]))
    elif len(fin["turns"]) != 1 or abs(fin["turns"][0] - d1) > bound:
        fail("(b) final turn depths %s, expected one at %.6g m (closed form with the measured "
             "kappa) within %.3g m" % (fin["turns"], d1, bound))
    if not math.isinf(float(doc["clearance"])):
        fail("(b) clearance %r, expected .inf without obstacles" % doc["clearance"])
    if len(doc["iterations"]) != doc["runs"] or any("schedule" not in i for i in doc["iterations"]):
        fail("(b) plan.yaml: %d iterations with schedules for %d runs" %
             (len(doc["iterations"]), doc["runs"]))
    if os.path.realpath(os.path.join(out, "final")) != os.path.realpath(
            os.path.join(out, doc["final_run"])):
        fail("(b) final does not link to %s" % doc["final_run"])

finish()
