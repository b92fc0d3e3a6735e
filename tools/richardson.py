"""Richardson extrapolation through three meshes with the observed order, for
every study and tool that extrapolates (tools/study.py's studies,
adapt_study.py, dbs_convergence.py, plot_cases.py).

    f_inf, C, p = richardson(k, f)          # f(k) = f∞ − C k^(−p), k increasing (nan: no order)
    p, f_inf = observed(h, f)               # in the cell size h, coarse first (p None: no order)
    ref, bar, p, sane = extrapolate(h, f, order=(1.0, 5.99))   # with an error bar
    ref, bar, p, sane = per_step_reference(h, F, order)        # the same at every step
    ref, bar, slope = ladder_reference(h, F)                   # a first-order fit over a ladder

The spacings need not have a constant ratio: the order is found by bisection
on p in (0.05, 6). When the differences change sign (not in the asymptotic
range) no order is observed.

Needs numpy (Debian's python3-numpy); use /usr/bin/python3.
"""
import numpy as np


def richardson(ks, ws):
    """W(k) = W∞ − C k^(−p) through three points (k increasing): (W∞, C, p), nan when no p in
    (0.05, 6) fits (bisection on p, so k need not grow by a constant ratio)."""
    (k1, k2, k3), (w1, w2, w3) = ks, ws

    def g(p):  # zero when the ratio of differences matches
        return (w2 - w1) * (k2 ** -p - k3 ** -p) - (w3 - w2) * (k1 ** -p - k2 ** -p)

    lo, hi = 0.05, 6.0
    if g(lo) * g(hi) > 0:
        return float("nan"), float("nan"), float("nan")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if g(lo) * g(mid) <= 0:
            hi = mid
        else:
            lo = mid
    p = 0.5 * (lo + hi)
    C = (w3 - w2) / (k2 ** -p - k3 ** -p)
    return w3 + C * k3 ** -p, C, p


def observed(h, J):
    """Observed order p and extrapolated value from three values J at spacings h (coarse to
    fine): richardson on k = 1/h; p = None (and J at the finest) when no order is observed."""
    w, _, p = richardson([1.0 / x for x in h], list(J))
    return (p, w) if np.isfinite(p) else (None, J[2])


def extrapolate(h, f, order):
    """The converged value of a quantity from three uniform meshes, with its error bar.
    h: cell sizes (coarse first); f: the quantity on those meshes. The observed order is sane
    when it lies in `order` = [lo, hi): p ≥ 1 bounds the extrapolation to 1/(r^p − 1) ≤ 2.5
    times the last difference at spacing ratios r ≥ 1.4, and an order at the bracket's top
    (6) is no root found inside it. Sane: the extrapolated value and its error bar
    |f∞ − f(finest)|; else (differences changing sign, order out of range, the same value on
    every mesh) the finest mesh's value with |f(finest) − f(middle)| as its error bar.
    Returns (reference, bar, order (nan where none), sane)."""
    ref, bar, p, sane = float(f[2]), abs(f[2] - f[1]), float("nan"), False
    if max(abs(f[1] - f[0]), abs(f[2] - f[1])) < 1e-15:
        return ref, bar, p, sane  # the same on every mesh (step 0)
    q, w = observed(h, f)
    if q is not None:
        p = q
        if order[0] <= q < order[1]:
            sane, ref, bar = True, w, abs(w - f[2])
    return ref, bar, p, sane


def per_step_reference(h, F, order):
    """The converged reference of a quantity at every step from three uniform runs.
    h: cell sizes (mm, coarse first); F: array (3, steps) of the quantity on those meshes.
    Per step, extrapolate. Returns (reference, bar, order (nan where none), sane: bool per
    step), arrays over the steps."""
    n = F.shape[1]
    ref, bar, p = np.array(F[2], float), np.abs(F[2] - F[1]), np.full(n, np.nan)
    sane = np.zeros(n, bool)
    for i in range(n):
        ref[i], bar[i], p[i], sane[i] = extrapolate(h, F[:, i], order)
    return ref, bar, p, sane


def ladder_reference(h, F):
    """The converged reference of a quantity at every step from a ladder of uniform runs, nested
    or not (tools/study.py convergence): per step the least-squares line f(h) = f∞ + a h
    through all of them (the order the immersed ladders show: docs/dbs.md, "Convergence on
    grids a reader picks"), f∞ the reference and twice the standard error of f∞ its error bar
    (the scatter between neighbouring grids, which no three-grid extrapolation sees).
    h: cell sizes (mm, at least three distinct); F: array (grids, steps). Returns (reference,
    bar, slope a), arrays over the steps."""
    h = np.asarray(h, float)
    F = np.asarray(F, float)
    if F.shape[0] != len(h) or len(h) < 3 or len(set(h)) < 3:
        raise ValueError("ladder_reference: at least three distinct cell sizes, one row each")
    A = np.column_stack([np.ones_like(h), h])
    coef, _, _, _ = np.linalg.lstsq(A, F, rcond=None)
    resid = F - A @ coef
    dof = len(h) - 2
    s2 = (resid ** 2).sum(axis=0) / dof if dof > 0 else np.zeros(F.shape[1])
    cov00 = np.linalg.inv(A.T @ A)[0, 0]
    return coef[0], 2.0 * np.sqrt(s2 * cov00), coef[1]
