/* trust.c — the steering planner's iteration on q (steer.c): Broyden's
 * method on F(q) = 0 made globally convergent by a trust region on the
 * step's length (docs/cases.md, "Planning the steering").
 *
 * Jacobian: J = I (the bicycle model's change of variables makes it the
 * exact Jacobian in the model's limit) updated by Broyden's rank-one
 * formula with the secants (s_i, y_i) = (q_i − q_b, F_i − F_b) of every run
 * that has a residual, taken nearest the best point b first, each direction
 * orthogonalised against the earlier ones (u_i = s_i minus its projections
 * on u_1 .. u_{i−1}):
 *     J ← J + (y_i − J s_i) u_iᵀ / (u_iᵀ s_i),
 * so the later updates keep the earlier secant equations J s = y. A secant
 * whose new direction is less than a fifth of its length (|u_i| < |s_i|/5:
 * within 11.5° of the span of the earlier ones; `skip`) is skipped: along it, y_i's
 * error over |u_i| would enter J. For an affine F every secant equation is
 * exact (y = A s), so once the secants span R^n, J = A and the next step
 * lands on the root: with no secant skipped the n + 2-th point is the root (n = 2 to 4 unknowns;
 * tests/test_steer.c).
 *
 * Step: d solves J d = −F_b (d = −F_b when J is singular), and the step
 * taken is q = q_b + t d with the largest t in (0, 1] (bisection) whose
 * length, measured by the caller (the planner: the largest change of a
 * turn depth or of the final depth, in m), is at most the radius Δ.
 *
 * Radius: the run at the step either fails (its simulation stopped), or has
 * a merit φ (the planner's: |miss| + clearance deficit); the linear model
 * predicts that the fraction t of the full step lowers φ_b by t φ_b, and
 *     ρ = (φ_b − φ) / (t φ_b).
 * ρ < 1/4 or a failed run: Δ = max(Δ_min, |step| / 2); ρ > 3/4 with the
 * step at the radius (|step| ≥ 0.8 Δ): Δ = min(Δ_max, 2 Δ); else Δ stays.
 * A bad step already at the floor Δ_min discredits the secants there: the
 * next step is the model's own (J = I), not the same step again.
 * The caller keeps the best point (the least φ) and always steps from it,
 * so the best merit never rises. */
#include "plan/plan_impl.h"

#include <math.h>
#include <string.h>

/* Solve J d = F (n x n, n <= NH_TRUST_Q) by Gaussian elimination with pivoting; −1 if singular. */
static int nh_solve_small(int n, const double J[NH_TRUST_Q * NH_TRUST_Q],
                          const double F[NH_TRUST_Q], double d[NH_TRUST_Q]) {
  double A[NH_TRUST_Q][NH_TRUST_Q + 1];
  for (int i = 0; i < n; i++) {
    for (int j = 0; j < n; j++) A[i][j] = J[NH_TRUST_Q * i + j];
    A[i][n] = F[i];
  }
  for (int c = 0; c < n; c++) {
    int p = c;
    for (int i = c + 1; i < n; i++)
      if (fabs(A[i][c]) > fabs(A[p][c])) p = i;
    if (!(fabs(A[p][c]) > 1e-12)) return -1;
    for (int j = 0; j <= n; j++) {
      double x = A[c][j];
      A[c][j] = A[p][j], A[p][j] = x;
    }
    for (int i = 0; i < n; i++)
      if (i != c) {
        double f = A[i][c] / A[c][c];
        for (int j = c; j <= n; j++) A[i][j] -= f * A[c][j];
      }
  }
  for (int i = 0; i < n; i++) d[i] = A[i][n] / A[i][i];
  return 0;
}

static void nh_identity(double J[NH_TRUST_Q * NH_TRUST_Q]) {
  memset(J, 0, sizeof(double) * NH_TRUST_Q * NH_TRUST_Q);
  for (int i = 0; i < NH_TRUST_Q; i++) J[NH_TRUST_Q * i + i] = 1.0;
}

static double nh_dist(int n, const double *a, const double *b) {
  double s = 0;
  for (int i = 0; i < n; i++) s += (a[i] - b[i]) * (a[i] - b[i]);
  return sqrt(s);
}

void nh_trust_jacobian(int n, int m, const double *q, const double *F, const int *ok, int best,
                       double skip, double J[NH_TRUST_Q * NH_TRUST_Q]) {
  const double *qb = q + NH_TRUST_Q * best, *Fb = F + NH_TRUST_Q * best;
  double U[NH_TRUST_Q][NH_TRUST_Q];
  int used = 0, done[NH_TRUST_MAX_POINTS] = {0};
  nh_identity(J);
  if (m > NH_TRUST_MAX_POINTS) m = NH_TRUST_MAX_POINTS;
  for (int pass = 0; pass < m && used < n; pass++) {
    int k = -1; /* the nearest point not yet used */
    for (int i = 0; i < m; i++)
      if (i != best && ok[i] && !done[i] &&
          (k < 0 || nh_dist(n, q + NH_TRUST_Q * i, qb) < nh_dist(n, q + NH_TRUST_Q * k, qb)))
        k = i;
    if (k < 0) break;
    done[k] = 1;
    double s[NH_TRUST_Q], y[NH_TRUST_Q], u[NH_TRUST_Q], Js[NH_TRUST_Q];
    for (int i = 0; i < n; i++)
      s[i] = q[NH_TRUST_Q * k + i] - qb[i], y[i] = F[NH_TRUST_Q * k + i] - Fb[i];
    memcpy(u, s, sizeof u);
    for (int j = 0; j < used; j++) {
      double su = 0, ss = 0;
      for (int i = 0; i < n; i++) su += U[j][i] * u[i], ss += U[j][i] * U[j][i];
      for (int i = 0; i < n; i++) u[i] -= su / ss * U[j][i];
    }
    double us = 0, uu = 0, sn = 0;
    for (int i = 0; i < n; i++) us += u[i] * s[i], uu += u[i] * u[i], sn += s[i] * s[i];
    if (!(sn > 0) || !(uu > skip * skip * sn)) continue; /* no new direction */
    for (int i = 0; i < n; i++) {
      Js[i] = 0;
      for (int j = 0; j < n; j++) Js[i] += J[NH_TRUST_Q * i + j] * s[j];
    }
    for (int i = 0; i < n; i++)
      for (int j = 0; j < n; j++) J[NH_TRUST_Q * i + j] += (y[i] - Js[i]) * u[j] / us;
    memcpy(U[used++], u, sizeof u);
  }
}

void nh_trust_init(nh_trust *tr, double radius, double radius_min, double radius_max) {
  memset(tr, 0, sizeof *tr);
  tr->radius = radius, tr->radius_min = radius_min, tr->radius_max = radius_max;
  tr->skip = 0.2;
}

int nh_trust_step(nh_trust *tr, int n, int m, const double *q, const double *F, const int *ok,
                  int best, nh_trust_length length, void *ctx, double out[NH_TRUST_Q]) {
  double J[NH_TRUST_Q * NH_TRUST_Q], d[NH_TRUST_Q] = {0}, mF[NH_TRUST_Q];
  const double *qb = q + NH_TRUST_Q * best;
  if (tr->model_only)
    nh_identity(J);
  else
    nh_trust_jacobian(n, m, q, F, ok, best, tr->skip, J);
  for (int i = 0; i < n; i++) mF[i] = -F[NH_TRUST_Q * best + i];
  if (nh_solve_small(n, J, mF, d)) memcpy(d, mF, sizeof d); /* singular: the fixed-point step */
  memcpy(tr->J, J, sizeof J);
  double lo = 0, hi = 1, len = length(ctx, qb, d, 1.0);
  if (len <= tr->radius) {
    lo = 1;
  } else {
    for (int it = 0; it < 30; it++) {
      double mid = 0.5 * (lo + hi), l = length(ctx, qb, d, mid);
      if (l <= tr->radius)
        lo = mid, len = l;
      else
        hi = mid;
    }
    if (lo == 0) return -1;
  }
  for (int i = 0; i < NH_TRUST_Q; i++) out[i] = qb[i] + (i < n ? lo * d[i] : 0.0);
  tr->t = lo, tr->length = len, tr->pending = 1, tr->model_only = 0;
  return 0;
}

void nh_trust_judge(nh_trust *tr, double merit_best, double merit) {
  if (!tr->pending) return;
  tr->pending = 0;
  double rho =
      isfinite(merit) && merit_best > 0 ? (merit_best - merit) / (tr->t * merit_best) : -INFINITY;
  tr->rho = rho;
  if (rho < 0.25 && tr->length <= tr->radius_min * (1 + 1e-9))
    tr->model_only = 1; /* at the floor: the secants have failed, the model's step next */
  if (rho < 0.25)
    tr->radius = fmax(tr->radius_min, 0.5 * tr->length);
  else if (rho > 0.75 && tr->length >= 0.8 * tr->radius)
    tr->radius = fmin(tr->radius_max, 2 * tr->radius);
}
