#!/usr/bin/python3
"""Torsional friction between needle and channel (interaction.torsion_per_length;
docs/interaction.md, "Torsional friction").

Runs the binary ($NH_BINARY) on cases/needle-phantom.yaml with --set
overrides, into $NH_WORK/torsion: the 4 x 2 x 2 cm block (E 10 MPa), the
straight needle (L = 32 mm, r = 1 mm, E = 50 MPa, nu = 0.3) inserted
L_in ~ 20 mm at 2 cm/s, no axial friction, path points every s = 1 mm; then
the insertion stops and the base spins at omega = 2 rad/s for 0.5 s.
Silent on success, one line per failure (expected, actual, tolerance),
exit 1. `--verbose` prints the measured numbers.

Derived expectations (tools.csv `twist`: the tip's rotation about the axis
relative to the base's, the sum of the elements' torsion):
 0. torsion_per_length = 0: tools.csv has no `twist` column (the outputs
    of scenes without torsion are as before it existed: docs/outputs.md).
 1. torsion_per_length -> 0 (1e-12 N m/m: the column is written, the drag's
    own lag, 2. below, is ~1e-11 rad): nothing resists the spin, the tip
    turns with the base: |twist| at the end of the spin <= 1e-6 rad. The
    only torque is the needle's rotary inertia spinning up within a step,
    I_p * omega / h at most, I_p = rho * J * L (J = pi r^4 / 2): it twists
    the needle by at most I_p omega / h * L / GJ ~ 1e-8 rad.
 2. torsion_per_length = tau > 0: in steady spin every channel point slides,
    so point i (arc length s_i from the base, share of length s) carries the
    torque tau * s against the spin. The beam's torsion is GJ/l0 per element
    (docs/beam.md) with the torque distributed linearly to the element's
    nodes, for which linear elements are nodally exact: a torque M at s_i
    turns the tip by M s_i / GJ relative to the clamped base, so
        twist = -(tau s / GJ) * sum_i s_i,
    with s_i = L - L_in + i s for the points covered by the shaft
    (s_i <= L - s / 2: the last half spacing belongs to the tip), L_in the
    inserted length (tools.csv depth). Checked to 1e-3 relative (the
    constraint solve's tolerance and the step's one linearisation).
 3. the same against the continuous closed form of a drag tau per length
    over the inserted part of a rod of length L clamped in rotation at the
    base, free at the tip: the torque at s is tau * L_in outside the tissue
    and tau (L - s) inside, so
        lag = tau L_in (L - L_in) / GJ + tau L_in^2 / (2 GJ).
    The points' shares cover [L - L_in - s/2, L - s/2 + e] with |e| <= s,
    so the two differ by at most tau s L / GJ (+ the rounding of the
    points' coverage): checked within that bound.
 4. the lag grows with the inserted length: the lag at L_in ~ 10 mm is below
    the one at 20 mm, and each matches its closed form (2.) to 1e-3.
"""
import math
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nh_run import fail, finish, run as nh_run, work  # noqa: E402

VERBOSE = "--verbose" in sys.argv
PHANTOM = os.path.join(os.environ["NH_SOURCE_DIR"], "cases", "needle-phantom.yaml")

L, R, E, NU, RHO = 0.032, 0.001, 50.0e6, 0.3, 7800.0
G = E / (2 * (1 + NU))
J = math.pi * R ** 4 / 2
GJ = G * J
SPACING = 0.001
OMEGA = 2.0


def say(*a):
    if VERBOSE:
        print(*a)


def run(name, tau, t_insert):
    """Insert for t_insert s at 2 cm/s, then spin at OMEGA for 0.5 s; the tool rows."""
    motion = "[{until: %r, speed: 0.02}, {until: %r, speed: 0.0, spin: %r}]" % (
        t_insert, t_insert + 0.5, OMEGA)
    sets = ["name=" + name, "time.end=%r" % (t_insert + 0.5), "tools.0.motion=" + motion,
            "tools.0.interaction.friction=0", "tools.0.interaction.friction_per_length=0",
            "tools.0.interaction.spacing=%r" % SPACING,
            "tools.0.interaction.torsion_per_length=%r" % tau, "output.every=1000"]
    result = nh_run(PHANTOM, os.path.join(work("torsion"), name), sets, tables=("tools",))
    return None if result is None else result["tools"]


def discrete_lag(tau, depth):
    """tau s / GJ * sum of the covered points' arc lengths."""
    s0, total, i = L - depth, 0.0, 0
    while s0 + i * SPACING <= L - 0.5 * SPACING + 1e-12:
        total += s0 + i * SPACING
        i += 1
    return tau * SPACING * total / GJ, i


def closed_lag(tau, depth):
    return tau * depth * (L - depth) / GJ + tau * depth ** 2 / (2 * GJ)


# 0. no torsional friction: no twist column
rows = run("none", 0.0, 1.0)
if rows is not None and "twist" in rows[-1]:
    fail("tau = 0: tools.csv has a twist column, expected none (docs/outputs.md)")

# 1. a vanishing torsional friction
rows = run("free", 1.0e-12, 1.0)
if rows is not None:
    twist = float(rows[-1]["twist"])
    bound = RHO * J * L * OMEGA / 0.01 * L / GJ
    say("1. tau = 0: twist at the end of the spin %.3g rad (inertia bound %.2g rad)" %
        (twist, bound))
    if not abs(twist) <= 1e-6:
        fail("tau = 0: twist %.3g rad, expected 0 (the tip turns with the base; tolerance "
             "1e-6 rad)" % twist)

# 2.-4. drag tau per length
TAU = 5.0e-3
lags = {}
for t_insert in (1.0, 0.5):
    rows = run("drag-%g" % t_insert, TAU, t_insert)
    if rows is None:
        continue
    last = rows[-1]
    twist, depth = float(last["twist"]), float(last["depth"])
    expect, n = discrete_lag(TAU, depth)
    cont = closed_lag(TAU, depth)
    lags[t_insert] = -twist
    say("2./3. L_in = %.5g m: twist %.6g rad, discrete %.6g rad (%d points, %.2g relative), "
        "closed form %.6g rad (difference %.3g rad, bound %.3g rad)" %
        (depth, twist, -expect, n, abs(-twist - expect) / expect, cont, abs(-twist - cont),
         TAU * SPACING * L / GJ))
    if not abs(-twist - expect) <= 1e-3 * expect:
        fail("L_in = %.5g m: twist %.6g rad, expected %.6g rad (the sliding points' torques "
             "over GJ; tolerance 1e-3 relative)" % (depth, twist, -expect))
    if not abs(-twist - cont) <= TAU * SPACING * L / GJ:
        fail("L_in = %.5g m: lag %.6g rad, expected tau L_in (L - L_in)/GJ + tau L_in^2/(2 GJ) "
             "= %.6g rad within tau s L / GJ = %.3g rad" % (depth, -twist, cont,
                                                            TAU * SPACING * L / GJ))
if len(lags) == 2 and not lags[0.5] < lags[1.0]:
    fail("lag %.4g rad at the shallower depth, expected below the deeper one's %.4g rad" %
         (lags[0.5], lags[1.0]))

finish()
