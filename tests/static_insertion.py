#!/usr/bin/python3
"""Tools in the quasi-static mode (docs/interaction.md, "Quasi-static mode").

Runs the binary ($NH_BINARY) on scenes written by this script into
$NH_WORK/static_insertion: the block and needle of
cases/needle-phantom.yaml (4 x 2 x 2 cm, E 10 MPa, nu 0.4, 8 x 4 x 4 cells,
clamped at x = 4 cm; needle L 32 mm, r 1 mm, E 50 MPa, 16 elements).
Silent on success, one line per failure (expected, actual, tolerance), exit 1.

 1. The needle under its own weight, static, clamped at its base and
    outside the tissue: tip deflection q L^4 / (8 E I) within 0.5 %
    (q = rho A g). The beam's nodal loads are lumped (M g, no end moments):
    with Hermite elements that leaves out only the tip moment q l^2 / 12 of
    the last element, a relative error of 1/(3 n^2) = 0.13 % for n = 16;
    the geometric nonlinearity at w/L = 2.5 % is below 1e-3 (the
    corotational beam's own test, tests/test_beam.c).
 2. A static insertion (9.5 mm at 0.2 mm per pseudo-step) against slow,
    heavily damped dynamic insertions with the same travel per step and
    k = 4, 16, 64 times the step (speed / k): backward Euler's step is, in
    displacements, (M/h^2 + C/h + K) du = f - f_int + ..., so the dynamic
    run tends to the static one as 1/k (damping and inertia forces scale
    with the speed):
    a. the probes' displacement difference falls by at least 3x per 4x in k
       (order 1) and is below 1e-3 of the largest probe displacement at
       k = 64;
    b. the tool tip: the dynamic step applies each shaft point's friction
       force f = friction_per_length x spacing at the tool point where the
       tissue point was at the start of the step, one step's travel d
       towards the tip from where it is at the end (one linearisation per
       step), so its needle is shorter by N f d / (E A) (N shaft points):
       tip_dynamic - tip_static -> -N f d / (E A), checked at k = 64
       within 10 % of that lag;
    c. the axial force agrees to 1e-6 relative and the states are the same
       at every step;
    d. with a 5x larger friction_per_length the lag grows 5x (the same
       check as b).
"""
import math
import os

from nh_run import fail, finish, run as run_scene, work

WORK = work("static_insertion")

E_NEEDLE, R, L, RHO, N_EL = 50.0e6, 0.001, 0.032, 7800.0, 16

BLOCK = """tissue:
  domain:
    box: {min: [0, 0, 0], max: [0.04, 0.02, 0.02]}
  grid: [8, 4, 4]
  material: {young: 10.0e6, poisson: 0.4, density: 1000}
  damping: {mass: %(alpha)r, stiffness: 0.001}
  fixed:
    - {box: {min: [0.0399, -1, -1], max: [1, 1, 1]}}
tools:
  - name: needle
    length: %(L)r
    radius: %(R)r
    elements: %(n)d
    material: {young: %(E)r, poisson: 0.3, density: %(rho)r}
    damping: {mass: 0.0, stiffness: 0.001}
    base: [-0.0325, 0.01, 0.01]
    direction: [1, 0, 0]
    motion:
      - {until: %(T)r, speed: %(v)r}
    interaction: {puncture_force: 0.2, cutting_force: 0.2, friction: 0.1,
                  friction_per_length: %(fpl)r, spacing: 0.0025}
probes:
  - {name: "1", point: [0.005, 0.01, 0.01]}
  - {name: "4", point: [0.020, 0.01, 0.01]}
  - {name: "1C", point: [0.005, 0.01, 0.015]}
output: {every: 0}
"""


def run(name, text):
    path = os.path.join(WORK, name + ".yaml")
    with open(path, "w") as f:
        f.write(text)
    return run_scene(path, os.path.join(WORK, name))


def gravity():
    scene = "name: gravity\ntime: {mode: static, step: 1.0, steps: 1}\n" \
            "gravity: [0, 0, -9.81]\n" + BLOCK % dict(
                alpha=0.0, L=L, R=R, n=N_EL, E=E_NEEDLE, rho=RHO, T=1.0, v=0.0, fpl=5.0)
    r = run("gravity", scene)
    if not r:
        return
    q = RHO * math.pi * R**2 * 9.81
    EI = E_NEEDLE * math.pi * R**4 / 4
    expected = q * L**4 / (8 * EI)
    tip = r["tools"][-1]
    w = 0.01 - float(tip["tip_z"])
    if not abs(w - expected) <= 5e-3 * expected:
        fail("needle under its weight: tip deflection %.6e m, expected q L^4/8EI = %.6e m, "
             "tolerance 0.5 %% (off by %.3f %%)" % (w, expected, 100 * (w / expected - 1)))
    if tip["state"] != "outside" or float(tip["axial_force"]) != 0.0:
        fail("needle under its weight: state %s, axial force %s; expected outside, 0"
             % (tip["state"], tip["axial_force"]))


def insertion(fpl, ks):
    def scene(mode, k):
        h, v, T = 0.01 * k, 0.02 / k, 0.5 * k  # 50 steps of 0.2 mm
        return "name: insertion\ntime: {mode: %s, step: %r, end: %r}\n" % (mode, h, T) + \
            BLOCK % dict(alpha=50.0, L=L, R=R, n=N_EL, E=E_NEEDLE, rho=RHO, T=T, v=v, fpl=fpl)

    st = run("static_fpl%g" % fpl, scene("static", 1))
    dyn = {k: run("dynamic_fpl%g_k%d" % (fpl, k), scene("dynamic", k)) for k in ks}
    if not st or not all(dyn.values()):
        return
    last = len(st["tools"]) - 1

    def probes(r):
        return {p["name"]: [float(p[c]) for c in ("ux", "uy", "uz")]
                for p in r["probes"] if int(p["step"]) == last}

    ps = probes(st)
    umax = max(math.sqrt(sum(c * c for c in u)) for u in ps.values())
    diff = {}
    for k in ks:
        pd = probes(dyn[k])
        diff[k] = max(math.sqrt(sum((a - b)**2 for a, b in zip(pd[n], ps[n]))) for n in ps)
        if [t["state"] for t in dyn[k]["tools"]] != [t["state"] for t in st["tools"]]:
            fail("fpl %g, k = %d: the states differ from the static run's" % (fpl, k))
        fa, fs = float(dyn[k]["tools"][-1]["axial_force"]), float(st["tools"][-1]["axial_force"])
        if not abs(fa - fs) <= 1e-6 * abs(fs):
            fail("fpl %g, k = %d: axial force %.9g N, static %.9g N, tolerance 1e-6 relative"
                 % (fpl, k, fa, fs))
    for a, b in zip(ks, ks[1:]):
        if not diff[a] >= 3.0 * diff[b]:
            fail("fpl %g: probe difference to static %.3e m at k = %d and %.3e m at k = %d: "
                 "expected a fall by >= 3x (order 1 in 1/k)" % (fpl, diff[a], a, diff[b], b))
    if not diff[ks[-1]] <= 1e-3 * umax:
        fail("fpl %g: probe difference to static %.3e m at k = %d, tolerance 1e-3 of %.3e m"
             % (fpl, diff[ks[-1]], ks[-1], umax))
    # b. the tool tip: the dynamic step's lag of the shaft forces
    n_rows = int(dyn[ks[-1]]["steps"][-1]["constraints"])
    n_shaft = n_rows // 3 - 1  # three rows per tied point, the tip's among them
    d = 0.02 * 0.01  # travel per step
    EA = E_NEEDLE * math.pi * R**2
    lag = n_shaft * fpl * 0.0025 * d / EA
    dtip = float(dyn[ks[-1]]["tools"][-1]["tip_x"]) - float(st["tools"][-1]["tip_x"])
    if not abs(dtip + lag) <= 0.1 * lag:
        fail("fpl %g: tip_x dynamic (k = %d) - static = %.4e m, expected -N f d/(EA) = %.4e m "
             "(N = %d shaft points), tolerance 10 %%" % (fpl, ks[-1], dtip, -lag, n_shaft))


gravity()
insertion(5.0, [4, 16, 64])
insertion(25.0, [64])
finish()
