/* mcp.c — the constraint forces λ of one step: a mixed complementarity
 * problem on the compliance W = J A⁻¹ Jᵀ (the seed's Algorithm 1, line 3,
 * with the laws of its Eqs. 5-9; docs/interaction.md "Constraint solver").
 *
 * Given W (m×m, symmetric positive semi-definite, dense, column-major), the
 * free violation r = J x_free and one law per row, find λ such that
 * w = W λ + r obeys
 *   bilateral   w_i = 0, λ_i free;
 *   unilateral  w_i ≥ 0, λ_i ≥ 0, w_i λ_i = 0                 (Eq. 5);
 *               with a cap c_i > 0 the set is [0, c_i]: at λ_i = c_i the
 *               row yields, w_i ≤ 0 (the puncture normal, Eq. 6);
 *   friction    |λ_i| ≤ b_i = μ_i |λ_n(i)| + c_i, and w_i = 0 inside the
 *               bound (stick), w_i λ_i ≤ 0 on it (slide)       (Eqs. 7-9);
 *   disc pair   rows g, g+1 share one bound on |(λ_g, λ_g+1)|; inside it
 *               w = 0, on it w = −ν λ with ν ≥ 0 (slip opposite to force);
 *   static      a friction row that stuck at the previous step has the bound
 *               μ_s |λ_n| + c until its force reaches it; then it breaks away
 *               and the solve is repeated, warm, with μ_k (break-away loop
 *               below; Nienhuys's stick/slip rearrangement within a step).
 * Every law is the variational inequality "λ_i is the projection of
 * λ_i − w_i onto its set K_i" (ℝ, ℝ₊ or [0, c], [−b, b], the disc), so one residual
 * serves all rows: the natural map |λ − P_K(λ − w)|.
 *
 * Scaling. Stiff-needle rows have tiny W_ii next to soft-tissue rows, so W's
 * diagonal spans 1e-6..1e6. With D = diag(W)^{-1/2} the solver works on
 * W̃ = D W D (unit diagonal), r̃ = D r, λ̃ = D⁻¹ λ, w̃ = D w; λ̃ and w̃ then
 * carry the same unit (√energy), which is what makes min(w̃, λ̃) and the
 * relative residual meaningful. Bounds scale as b̃_i = b_i / d_i. A disc
 * pair is projected in unscaled coordinates, where the disc is round.
 *
 * Algorithm: projected block Gauss-Seidel, warm-started from the given λ.
 * One sweep solves, in order,
 *   1. the bilateral block exactly with the other rows frozen,
 *      λ̃_B ← λ̃_B − W̃_BB⁻¹ w̃_B (W̃_BB factorised once by dense Cholesky);
 *   2. each unilateral row, λ̃_i ← clamp(λ̃_i − w̃_i, 0, c̃_i) (c̃ = ∞ without a cap);
 *   3. each friction row, λ̃_i ← clamp(λ̃_i − w̃_i, ±b̃_i) with b̃ from the
 *      current normal force, and each disc pair exactly: the 2×2
 *      trust-region problem min ½xᵀBx + qᵀx, |x| ≤ b, solved by the
 *      stick candidate −B⁻¹q or, outside the disc, by bisection on the
 *      multiplier ν of (B + νI) x = −q, |x| = b;
 *   4. if the sweep reduced the residual by less than a factor 2, a subspace
 *      step: the rows strictly inside their sets (bilateral, unilateral with
 *      0 < λ < c, friction inside the bound) form F, λ̃_F ← λ̃_F − W̃_FF⁻¹ w̃_F,
 *      then every row is projected; kept only if the residual drops. Plain
 *      sweeps on coupled shaft rows took 500-1600 sweeps where this takes
 *      7-12 (measured, docs/interaction.md). The factor of W̃_FF (LAPACK)
 *      is kept while F does not change (hundreds of skull rows: F settles
 *      long before the residual does).
 * w̃ is updated after each change (a column of W̃ per row) and recomputed
 * from scratch every NH_MCP_RECOMPUTE sweeps and before a residual is
 * accepted, so round-off does not accumulate (with 1000 skull rows the
 * recomputation every sweep was 44 % of the solve's time). The
 * exact bilateral block (versus treating bilateral rows as unbounded GS
 * rows) was chosen by measurement, docs/interaction.md: with coupled
 * bilateral rows plain GS needs tens to hundreds of sweeps where the block
 * solve needs one (all-bilateral) or a few. If W̃_BB is singular (dependent
 * bilateral rows) the bilateral rows fall back to GS rows (which converge
 * for a consistent positive semi-definite system, slowly).
 *
 * Stopping: residual = max_i |λ̃_i − P_K(λ̃_i − w̃_i)| (the disc pair's in
 * its isotropically scaled unscaled coordinates) divided by
 * max|r̃| + max|W̃λ̃| (0 if every e_i is 0), checked before the first sweep
 * (so a warm start at the solution costs 0 sweeps) and after every sweep. The best
 * iterate is kept and returned if max_iterations is reached.
 *
 * Proximal fallback (nh_mcp_proximal; docs/interaction.md): where the
 * sweeps and Newton both stop short of the tolerance within NH_MCP_PROX_AFTER
 * sweeps (nearly dependent rows: the weighted-gap skull rows of a fine
 * mesh), the regularised problems W + ρ diag(W), r − ρ diag(W) λ_k,
 * strictly monotone, by Newton, each from the last solution λ_k, ρ from
 * 1e-3 down to 1e-9, ÷10 after a regularised problem is solved and ×10
 * (the same centre, up to 1e-1) after one is not, until λ_k solves the original
 * problem (Rockafellar, "Monotone operators and the proximal point
 * algorithm"); kept only if it converges, and if it does not, the plain
 * solve goes on from its best iterate with the rest of its budget.
 *
 * Unsymmetric W (nh_mcp_solve_unsymmetric; the quasi-static step's beam
 * blocks with their full tangent): the blocks by LU with partial pivoting,
 * W̃'s rows read as rows (Newton's Jacobian, a disc pair's block); the
 * symmetric path is unchanged (docs/interaction.md "Unsymmetric compliance").
 *
 * Workspace: O(m²) doubles (W̃, the bilateral and the subspace factors),
 * freed on return.
 * Failures: NH_ERR_INPUT (inconsistent laws or arguments), NH_ERR_NUMERIC
 * (non-finite data, a negative diagonal, no convergence), NH_ERR_MEMORY. */
#include "solve/mcp_impl.h"

#include <float.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* 1: bilateral rows as one exact block per sweep (default, measured in
 * docs/interaction.md); 0: as unbounded Gauss-Seidel rows (for comparison). */
#ifndef NH_MCP_BILATERAL_BLOCK
#define NH_MCP_BILATERAL_BLOCK 1
#endif
/* 1: after each sweep, try an exact solve on the rows the sweep left free
 * (subspace minimisation, kept only if it lowers the residual); 0: plain sweeps. */
#ifndef NH_MCP_SUBSPACE
#define NH_MCP_SUBSPACE 1
#endif
/* Rows up to which the exact method (semismooth Newton) goes first; above,
 * the sweeps go first, with Newton probes between their rounds (the
 * crossover measured in docs/interaction.md, "Method and fallback"). 0:
 * sweeps first always. */
#ifndef NH_MCP_EXACT_ROWS
#define NH_MCP_EXACT_ROWS 200
#endif
/* Newton steps per attempt (with max_iterations, the lower of the two), and
 * the multiple of it the Tresca fixed point may spend. */
#define NH_MCP_NEWTON_MAX 100
/* Sweeps-first solves: the first round of sweeps before a Newton probe
 * (the rounds double), and the probe's Newton steps. */
#define NH_MCP_PROBE_SWEEPS 100
#define NH_MCP_PROBE_STEPS  10
/* Sweeps between two recomputations of w̃ = W̃ λ̃ + r̃ from scratch (the
 * sweeps update it row by row; the recomputation bounds the round-off). */
#ifndef NH_MCP_RECOMPUTE
#define NH_MCP_RECOMPUTE 8
#endif
#define NH_MCP_TRESCA_STEPS 10
/* The proximal fallback's regularisations ρ (relative to W's diagonal):
 * from the first down to the last, ÷10 each. */
#define NH_MCP_PROX_FIRST 1e-3
#define NH_MCP_PROX_LAST  1e-9
/* The largest ρ the fallback goes back up to where a regularised problem
 * is not solved within its budget. */
#define NH_MCP_PROX_MAX 1e-1
/* The budget of one regularised problem (Newton steps, then sweeps). */
#define NH_MCP_PROX_STEPS 30
/* Sweeps (or Newton steps) of the plain solve before the proximal fallback
 * is tried; the rest of the budget follows if it fails. */
#define NH_MCP_PROX_AFTER 100

static void nh_mcp_work_free(nh_mcp_work *ws) {
  free(ws->Wt), free(ws->d), free(ws->rt), free(ws->lt), free(ws->wt), free(ws->best);
  free(ws->L), free(ws->tmp), free(ws->bil), free(ws->Lf), free(ws->save_l), free(ws->save_w);
  free(ws->free_rows), free(ws->lf_rows), free(ws->piv), free(ws->pivf);
}

static int nh_mcp_check_laws(int m, const nh_row_law *laws) {
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    NH_CHECK(l->kind == NH_ROW_BILATERAL || l->kind == NH_ROW_UNILATERAL ||
                 l->kind == NH_ROW_FRICTION,
             NH_ERR_INPUT, "constraint row %d: unknown law kind %d", i, (int)l->kind);
    if (l->kind == NH_ROW_UNILATERAL)
      NH_CHECK(l->threshold >= 0.0 && isfinite(l->threshold), NH_ERR_INPUT,
               "unilateral row %d: cap threshold = %g must be finite and >= 0", i, l->threshold);
    if (l->kind != NH_ROW_FRICTION) continue;
    NH_CHECK(l->normal >= -1 && l->normal < m, NH_ERR_INPUT,
             "friction row %d: normal row %d is not in [-1, %d)", i, l->normal, m);
    NH_CHECK(l->normal < 0 || laws[l->normal].kind != NH_ROW_FRICTION, NH_ERR_INPUT,
             "friction row %d: its normal row %d is itself a friction row", i, l->normal);
    NH_CHECK(l->normal2 == -1 ||
                 (l->normal >= 0 && l->normal2 >= 0 && l->normal2 < m && l->normal2 != l->normal &&
                  laws[l->normal2].kind != NH_ROW_FRICTION),
             NH_ERR_INPUT,
             "friction row %d: second normal row %d must be -1 or a non-friction row other than "
             "the first normal row %d",
             i, l->normal2, l->normal);
    NH_CHECK(l->mu >= 0.0 && l->threshold >= 0.0 && l->mu_static >= 0.0 && isfinite(l->mu) &&
                 isfinite(l->threshold) && isfinite(l->mu_static),
             NH_ERR_INPUT,
             "friction row %d: mu = %g, mu_static = %g and threshold = %g must be finite and >= 0",
             i, l->mu, l->mu_static, l->threshold);
    NH_CHECK(!l->one_sided || l->group < 0, NH_ERR_INPUT,
             "friction row %d: a one-sided row must not be in a disc pair", i);
    if (l->group < 0) continue;
    int g = l->group;
    NH_CHECK(g == i || g == i - 1, NH_ERR_INPUT,
             "friction row %d: group %d must be the row itself or the row before", i, g);
    NH_CHECK(g + 1 < m, NH_ERR_INPUT, "friction row %d: disc pair (%d, %d) runs past row %d", i, g,
             g + 1, m - 1);
    const nh_row_law *a = &laws[g], *b = &laws[g + 1];
    NH_CHECK(a->kind == NH_ROW_FRICTION && b->kind == NH_ROW_FRICTION && a->group == g &&
                 b->group == g && a->normal == b->normal && a->normal2 == b->normal2 &&
                 a->mu == b->mu && a->mu_static == b->mu_static && a->sliding == b->sliding &&
                 a->threshold == b->threshold,
             NH_ERR_INPUT,
             "friction rows %d and %d: a disc pair needs two friction rows with group %d and the "
             "same normal, mu and threshold",
             g, g + 1, g);
  }
  return NH_OK;
}

/* Unscaled Coulomb bound of a friction row from the current normal force. */
double nh_mcp_bound(const nh_mcp_work *ws, const nh_row_law *l) {
  double n = l->normal >= 0 ? fabs(ws->d[l->normal] * ws->lt[l->normal]) : 0.0;
  if (l->normal2 >= 0) n = hypot(n, ws->d[l->normal2] * ws->lt[l->normal2]);
  return l->mu * n + l->threshold;
}

static double nh_clamp(double x, double b) {
  return x > b ? b : (x < -b ? -b : x);
}

/* Projection onto a one-dimensional friction row's set: [−b, b], or [0, b] one-sided. */
static double nh_mcp_friction_clamp(const nh_row_law *l, double x, double b) {
  return l->one_sided ? (x < 0.0 ? 0.0 : (x > b ? b : x)) : nh_clamp(x, b);
}

/* Scaled upper bound of a unilateral row: threshold / d_i, or none (∞) for
 * threshold 0. */
double nh_mcp_cap(const nh_mcp_work *ws, const nh_row_law *l, int i) {
  return l->threshold > 0.0 ? l->threshold / ws->d[i] : INFINITY;
}

/* Projection onto a unilateral row's set [0, cap]. */
static double nh_mcp_unilateral(double x, double cap) {
  return x < 0.0 ? 0.0 : (x > cap ? cap : x);
}

/* λ̃_i += delta, and w̃ += delta W̃(:, i). */
static void nh_mcp_move(nh_mcp_work *ws, int i, double delta) {
  if (delta == 0.0) return;
  const double *c = ws->Wt + (size_t)i * ws->m;
  ws->flops += 2.0 * ws->m;
  ws->lt[i] += delta;
  for (int k = 0; k < ws->m; k++) ws->wt[k] += delta * c[k];
}

void nh_mcp_recompute_w(nh_mcp_work *ws) {
  int m = ws->m;
  memcpy(ws->wt, ws->rt, sizeof(double) * (size_t)m);
  for (int j = 0; j < m; j++) {
    double l = ws->lt[j];
    if (l == 0.0) continue;
    ws->flops += 2.0 * m;
    const double *c = ws->Wt + (size_t)j * m;
    for (int k = 0; k < m; k++) ws->wt[k] += l * c[k];
  }
}

/* Disc pair (g, g+1) in unscaled coordinates: B the 2×2 block of W
 * (B[0] = W_gg, B[1] = W_g+1,g, B[2] = W_g+1,g+1, B[3] = W_g,g+1), x the
 * current forces, w the current violations. Returns the new forces in x: the
 * y with |y| ≤ b and v = B y + q (q = w − Bx) zero inside the disc, −ν y
 * (ν ≥ 0) on its circle; for a symmetric B the minimiser of ½ yᵀBy + qᵀy
 * over the disc. */
static void nh_mcp_disc(const double B[4], double q0, double q1, double b, double x[2]) {
  if (!(b > 0.0)) {
    x[0] = x[1] = 0.0;
    return;
  }
  double det = B[0] * B[2] - B[3] * B[1];
  if (det > 1e-14 * (B[0] * B[2] + DBL_MIN)) { /* the stick candidate */
    double y0 = -(B[2] * q0 - B[3] * q1) / det, y1 = -(-B[1] * q0 + B[0] * q1) / det;
    if (y0 * y0 + y1 * y1 <= b * b) {
      x[0] = y0, x[1] = y1;
      return;
    }
  }
  double qn = sqrt(q0 * q0 + q1 * q1);
  if (qn == 0.0) { /* singular B, q = 0: any point of the null space; keep none */
    x[0] = x[1] = 0.0;
    return;
  }
  /* |(B + νI)⁻¹ q| is ≤ |q|/ν (B + Bᵀ ⪰ 0), decreasing in ν ≥ 0 for a
   * symmetric B: bisection on the bracket [0, |q|/b]. */
  double lo = 0.0, hi = qn / b, y0 = 0.0, y1 = 0.0;
  for (int it = 0; it < 200 && hi - lo > 1e-15 * hi; it++) {
    double nu = 0.5 * (lo + hi);
    double a = B[0] + nu, c = B[2] + nu, dt = a * c - B[3] * B[1];
    y0 = -(c * q0 - B[3] * q1) / dt, y1 = -(-B[1] * q0 + a * q1) / dt;
    if (y0 * y0 + y1 * y1 > b * b)
      lo = nu;
    else
      hi = nu;
  }
  double a = B[0] + hi, c = B[2] + hi, dt = a * c - B[3] * B[1];
  y0 = -(c * q0 - B[3] * q1) / dt, y1 = -(-B[1] * q0 + a * q1) / dt;
  double n = sqrt(y0 * y0 + y1 * y1);
  if (n > 0.0) y0 *= b / n, y1 *= b / n; /* onto the circle exactly */
  x[0] = y0, x[1] = y1;
}

/* The pair's isotropic scale: 1/√(mean of the two diagonals). */
double nh_mcp_pair_scale(const double *W, int m, int g) {
  double s = 0.5 * (W[(size_t)g * m + g] + W[(size_t)(g + 1) * m + g + 1]);
  return s > 0.0 ? 1.0 / sqrt(s) : 1.0;
}

/* Dimensionless natural-map residual of the current iterate (w̃ must be current). */
double nh_mcp_residual(const nh_mcp_work *ws, const double *W, const nh_row_law *laws) {
  int m = ws->m;
  double res = 0.0, rmax = 0.0, wlmax = 0.0;
  for (int i = 0; i < m; i++) {
    /* fmax drops a NaN: a non-finite iterate is no solution */
    if (!isfinite(ws->lt[i]) || !isfinite(ws->wt[i])) return NAN;
    rmax = fmax(rmax, fabs(ws->rt[i]));
    wlmax = fmax(wlmax, fabs(ws->wt[i] - ws->rt[i]));
  }
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    double lam = ws->lt[i], w = ws->wt[i], e;
    if (l->kind == NH_ROW_BILATERAL) {
      e = fabs(w);
    } else if (l->kind == NH_ROW_UNILATERAL) {
      /* |min(w, λ)| without a cap */
      e = fabs(lam - nh_mcp_unilateral(lam - w, nh_mcp_cap(ws, l, i)));
    } else if (l->group < 0) {
      double b = nh_mcp_bound(ws, l) / ws->d[i];
      e = fabs(lam - nh_mcp_friction_clamp(l, lam - w, b));
    } else {
      if (l->group != i) continue; /* the pair is measured at its first row */
      /* Unscaled x, w, then the isotropic scale s: x/s, w·s. */
      double s = nh_mcp_pair_scale(W, m, i);
      double x0 = ws->d[i] * lam / s, x1 = ws->d[i + 1] * ws->lt[i + 1] / s;
      double w0 = w / ws->d[i] * s, w1 = ws->wt[i + 1] / ws->d[i + 1] * s;
      double b = nh_mcp_bound(ws, l) / s;
      double y0 = x0 - w0, y1 = x1 - w1, n = sqrt(y0 * y0 + y1 * y1);
      if (n > b) y0 *= b / n, y1 *= b / n;
      e = hypot(x0 - y0, x1 - y1);
    }
    res = fmax(res, e);
  }
  double scale = rmax + wlmax;
  if (!(scale > 0.0)) return res > 0.0 ? HUGE_VAL : 0.0;
  return res / scale;
}

/* Dense Cholesky of W̃(idx, idx) into L (nb×nb, lower triangle; the upper
 * one keeps W̃'s entries); 0 if it is not numerically positive definite.
 * LAPACK's blocked dpotrf: with hundreds of free skull rows this factor is
 * O(nb³) per subspace step and was most of the step written as a loop.
 * An unsymmetric W̃ (ws->unsym): LU with partial pivoting (dgetrf, pivots
 * into piv), 0 if a pivot of U is below 1e-12 (dependent rows). */
static int nh_mcp_factor(nh_mcp_work *ws, int nb, const int *idx, double *L, int *piv) {
  int m = ws->m;
  ws->flops += (double)nb * nb, ws->flops_dense += (double)nb * nb * nb / 3.0;
  for (int j = 0; j < nb; j++)
    for (int i = 0; i < nb; i++) L[(size_t)j * nb + i] = ws->Wt[(size_t)idx[j] * m + idx[i]];
  if (ws->unsym) {
    ws->flops_dense += (double)nb * nb * nb / 3.0; /* LU: 2 nb³/3 */
    if (LAPACKE_dgetrf_work(LAPACK_COL_MAJOR, nb, nb, L, nb, piv) != 0) return 0;
    for (int j = 0; j < nb; j++)
      if (!(fabs(L[(size_t)j * nb + j]) > 1e-12)) return 0;
    return 1;
  }
  if (LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'L', nb, L, nb) != 0) return 0;
  /* W̃ has unit diagonal: a pivot below 1e-12 (L_jj below 1e-6) means dependent rows. */
  for (int j = 0; j < nb; j++)
    if (!(L[(size_t)j * nb + j] > 1e-6)) return 0;
  return 1;
}

/* λ̃_idx ← λ̃_idx − W̃(idx, idx)⁻¹ w̃_idx with the factor L (step 1 of a sweep for the
 * bilateral rows; the subspace step for the free rows). */
static void nh_mcp_solve_block(nh_mcp_work *ws, int nb, const int *idx, const double *L,
                               const int *piv) {
  double *z = ws->tmp;
  for (int j = 0; j < nb; j++) z[j] = ws->wt[idx[j]];
  ws->flops += 2.0 * nb * nb;
  if (ws->unsym)
    LAPACKE_dgetrs_work(LAPACK_COL_MAJOR, 'N', nb, 1, L, nb, piv, z, nb); /* P L U δ = w̃_B */
  else
    LAPACKE_dpotrs_work(LAPACK_COL_MAJOR, 'L', nb, 1, L, nb, z, nb); /* L Lᵀ δ = w̃_B */
  for (int j = 0; j < nb; j++) nh_mcp_move(ws, idx[j], -z[j]);
}

static void nh_mcp_sweep(nh_mcp_work *ws, const double *W, const nh_row_law *laws) {
  int m = ws->m;
  if (ws->nb > 0 && ws->block_ok) nh_mcp_solve_block(ws, ws->nb, ws->bil, ws->L, ws->piv);
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    double diag = ws->Wt[(size_t)i * m + i];
    if (!(diag > 0.0)) continue; /* a row W does not see: nothing to move */
    if (l->kind == NH_ROW_BILATERAL && !(ws->nb > 0 && ws->block_ok))
      nh_mcp_move(ws, i, -ws->wt[i] / diag);
    else if (l->kind == NH_ROW_UNILATERAL)
      nh_mcp_move(
          ws, i, nh_mcp_unilateral(ws->lt[i] - ws->wt[i] / diag, nh_mcp_cap(ws, l, i)) - ws->lt[i]);
  }
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    if (l->kind != NH_ROW_FRICTION) continue;
    if (l->group < 0) {
      double diag = ws->Wt[(size_t)i * m + i];
      if (!(diag > 0.0)) continue;
      double b = nh_mcp_bound(ws, l) / ws->d[i];
      nh_mcp_move(ws, i, nh_mcp_friction_clamp(l, ws->lt[i] - ws->wt[i] / diag, b) - ws->lt[i]);
    } else if (l->group == i) {
      int j = i + 1;
      double di = ws->d[i], dj = ws->d[j];
      double B[4] = {W[(size_t)i * m + i], W[(size_t)i * m + j], W[(size_t)j * m + j],
                     W[(size_t)(ws->unsym ? j : i) * m + (ws->unsym ? i : j)]};
      double x[2] = {di * ws->lt[i], dj * ws->lt[j]};
      double w0 = ws->wt[i] / di, w1 = ws->wt[j] / dj;
      double q0 = w0 - B[0] * x[0] - B[3] * x[1], q1 = w1 - B[1] * x[0] - B[2] * x[1];
      nh_mcp_disc(B, q0, q1, nh_mcp_bound(ws, l), x);
      nh_mcp_move(ws, i, x[0] / di - ws->lt[i]);
      nh_mcp_move(ws, j, x[1] / dj - ws->lt[j]);
    }
  }
}

/* Project λ̃ onto every row's set (normals first, so the bounds are current). */
void nh_mcp_project(nh_mcp_work *ws, const double *W, const nh_row_law *laws) {
  int m = ws->m;
  for (int i = 0; i < m; i++)
    if (laws[i].kind == NH_ROW_UNILATERAL)
      ws->lt[i] = nh_mcp_unilateral(ws->lt[i], nh_mcp_cap(ws, &laws[i], i));
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    if (l->kind != NH_ROW_FRICTION) continue;
    if (l->group < 0) {
      ws->lt[i] = nh_mcp_friction_clamp(l, ws->lt[i], nh_mcp_bound(ws, l) / ws->d[i]);
    } else if (l->group == i) { /* radially, in unscaled coordinates */
      double x0 = ws->d[i] * ws->lt[i], x1 = ws->d[i + 1] * ws->lt[i + 1];
      double b = nh_mcp_bound(ws, l), n = hypot(x0, x1);
      if (n > b) {
        double f = n > 0.0 ? b / n : 0.0;
        ws->lt[i] *= f, ws->lt[i + 1] *= f;
      }
    }
  }
  (void)W;
}

/* Subspace step: the rows the sweep left strictly inside their sets (bilateral,
 * unilateral with λ > 0, friction inside the bound) form F; solve W̃_FF δ = −w̃_F
 * exactly, project, and keep the result only if the residual drops below
 * `res` (the residual after the sweep). Returns the residual of the kept iterate. */
/* Size of friction row i's force in unscaled units: |λᵢ|, or |(λ_g, λ_g+1)|
 * for a disc pair starting at row g. */
static double nh_mcp_friction_size(const nh_mcp_work *ws, const nh_row_law *l, int i) {
  if (l->group < 0) return fabs(ws->d[i] * ws->lt[i]);
  int g = l->group;
  return hypot(ws->d[g] * ws->lt[g], ws->d[g + 1] * ws->lt[g + 1]);
}

static double nh_mcp_subspace(nh_mcp_work *ws, const double *W, const nh_row_law *laws,
                              double res) {
  int m = ws->m, nf = 0;
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    int in;
    if (l->kind == NH_ROW_BILATERAL) {
      in = 1;
    } else if (l->kind == NH_ROW_UNILATERAL) {
      in = ws->lt[i] > 0.0 && ws->lt[i] < nh_mcp_cap(ws, l, i) * (1.0 - 1e-12);
    } else {
      double b = nh_mcp_bound(ws, l), f = nh_mcp_friction_size(ws, l, i);
      in = f < b * (1.0 - 1e-12) && !(l->one_sided && ws->lt[i] <= 0.0);
    }
    if (in && ws->Wt[(size_t)i * m + i] > 0.0) ws->free_rows[nf++] = i;
  }
  if (nf == 0) return res;
  /* Near convergence the free set stops changing: W̃ is fixed for the whole
   * solve, so the factor of the same set is the same and is kept. */
  if (nf != ws->lf_n || memcmp(ws->free_rows, ws->lf_rows, sizeof(int) * (size_t)nf)) {
    ws->lf_ok = nh_mcp_factor(ws, nf, ws->free_rows, ws->Lf, ws->pivf);
    ws->lf_n = nf;
    memcpy(ws->lf_rows, ws->free_rows, sizeof(int) * (size_t)nf);
  }
  if (!ws->lf_ok) return res;
  memcpy(ws->save_l, ws->lt, sizeof(double) * (size_t)m);
  memcpy(ws->save_w, ws->wt, sizeof(double) * (size_t)m);
  nh_mcp_solve_block(ws, nf, ws->free_rows, ws->Lf, ws->pivf);
  nh_mcp_project(ws, W, laws);
  nh_mcp_recompute_w(ws);
  double r2 = nh_mcp_residual(ws, W, laws);
  if (r2 < res) return r2;
  memcpy(ws->lt, ws->save_l, sizeof(double) * (size_t)m);
  memcpy(ws->wt, ws->save_w, sizeof(double) * (size_t)m);
  return res;
}

static void nh_mcp_count(const nh_mcp_work *ws, const nh_row_law *laws, nh_mcp_stats *st) {
  st->n_stick = st->n_slide = st->n_open = 0;
  for (int i = 0; i < ws->m; i++) {
    const nh_row_law *l = &laws[i];
    if (l->kind == NH_ROW_UNILATERAL) {
      st->n_open += ws->lt[i] <= 0.0;
    } else if (l->kind == NH_ROW_FRICTION) {
      double b = nh_mcp_bound(ws, l), f = nh_mcp_friction_size(ws, l, i);
      /* On the bound (to round-off) is sliding; a zero bound slides freely. */
      if (f >= b * (1.0 - 1e-9))
        st->n_slide++;
      else
        st->n_stick++;
    }
  }
}

/* Sweeps from the current λ̃ until the residual of `laws` is below tolerance
 * or max_iterations more sweeps were made (*it counts them); λ̃ is left at the
 * best iterate, whose residual is returned. */
static double nh_mcp_run(nh_mcp_work *ws, const double *W, const nh_row_law *laws, double tolerance,
                         int max_iterations, int *it) {
  int m = ws->m, n = 0;
  nh_mcp_recompute_w(ws);
  double res = nh_mcp_residual(ws, W, laws), best_res = res;
  memcpy(ws->best, ws->lt, sizeof(double) * (size_t)m);
  while (!(best_res <= tolerance) && n < max_iterations) {
    if (nh_stop_requested()) break; /* SIGINT/SIGTERM: within one sweep (see nh_mcp_solve) */
    double prev = res;
    nh_mcp_sweep(ws, W, laws);
    n++;
    /* w̃ as the sweep updated it, made again from scratch every
     * NH_MCP_RECOMPUTE sweeps and before a residual is accepted */
    if (n % NH_MCP_RECOMPUTE == 0) nh_mcp_recompute_w(ws);
    res = nh_mcp_residual(ws, W, laws);
    if (res <= tolerance && n % NH_MCP_RECOMPUTE) {
      nh_mcp_recompute_w(ws);
      res = nh_mcp_residual(ws, W, laws);
    }
    /* The subspace step costs O(|F|³): only when the sweeps contract slowly. */
    if (NH_MCP_SUBSPACE && !(res <= tolerance) && !(res < 0.5 * prev))
      res = nh_mcp_subspace(ws, W, laws, res);
    if (!isfinite(res)) break;
    if (res <= best_res || !(best_res <= HUGE_VAL)) {
      best_res = res;
      memcpy(ws->best, ws->lt, sizeof(double) * (size_t)m);
    }
  }
  memcpy(ws->lt, ws->best, sizeof(double) * (size_t)m);
  nh_mcp_recompute_w(ws);
  *it += n;
  return best_res;
}

/* One solve of the laws `lw` from the current λ̃ (docs/interaction.md,
 * "Method and fallback"): up to NH_MCP_EXACT_ROWS rows the semismooth Newton
 * method first (mcp_newton.c), its converged λ̃ projected onto the sets
 * (kept if still within tolerance), and the sweeps from its best iterate if
 * it stopped short; above (unless newton_first > 0), the sweeps in doubling
 * rounds, each followed by a Newton probe from their iterate, the last
 * one with Newton's whole budget (newton_first 0) or a probe too
 * (newton_first < 0: the proximal fallback follows). λ̃ is
 * left at the best iterate (also in ws->best), its residual in *res;
 * st->newton_steps, st->sweeps and the methods used (bits 1: exact, 2:
 * sweeps, in *used) accumulate. */
static int nh_mcp_attempt(nh_mcp_work *ws, const double *W, const nh_row_law *lw, double tolerance,
                          int max_iterations, int newton_first, nh_mcp_stats *st, int *used,
                          double *res) {
  const int m = ws->m;
  const int newton_max = max_iterations < NH_MCP_NEWTON_MAX ? max_iterations : NH_MCP_NEWTON_MAX;
  double r = HUGE_VAL;
  if (m <= NH_MCP_EXACT_ROWS || newton_first > 0) {
    NH_TRY(nh_mcp_newton(ws, W, lw, tolerance, newton_max, &st->newton_steps, &r));
    *used |= 1;
    if (r <= tolerance) { /* feasible forces (the natural map allows a round-off outside) */
      memcpy(ws->tmp, ws->lt, sizeof(double) * (size_t)m);
      nh_mcp_project(ws, W, lw);
      nh_mcp_recompute_w(ws);
      double rp = nh_mcp_residual(ws, W, lw);
      if (rp <= tolerance) {
        r = rp;
      } else {
        memcpy(ws->lt, ws->tmp, sizeof(double) * (size_t)m);
        nh_mcp_recompute_w(ws);
      }
      memcpy(ws->best, ws->lt, sizeof(double) * (size_t)m);
    } else {
      NH_TRY(nh_mcp_tresca(ws, W, lw, tolerance,
                           st->newton_steps + NH_MCP_TRESCA_STEPS * newton_max, &st->newton_steps,
                           &r));
      if (!(r <= tolerance)) {
        r = nh_mcp_run(ws, W, lw, tolerance, max_iterations, &st->sweeps);
        *used |= 2;
      }
    }
  } else {
    /* Sweeps in rounds of NH_MCP_PROBE_SWEEPS, doubling, each followed by
     * a short Newton probe from the sweeps' best iterate: once the sweeps
     * have found the active set, Newton ends the solve in a few steps
     * where the sweeps' linear rate would take thousands (nearly dependent
     * skull rows, docs/interaction.md "Method and fallback"). A probe that
     * does not converge leaves its best iterate, no worse than the
     * sweeps'; after the last round, Newton with its whole budget. */
    int swept = 0, round = NH_MCP_PROBE_SWEEPS;
    for (;;) {
      const int before = st->sweeps;
      const int n = max_iterations - swept < round ? max_iterations - swept : round;
      r = nh_mcp_run(ws, W, lw, tolerance, n, &st->sweeps);
      *used |= 2;
      swept += n;
      if (r <= tolerance || !isfinite(r) || nh_stop_requested()) break;
      const int last = swept >= max_iterations || st->sweeps - before < n;
      const int steps = (last && newton_first == 0) || newton_max < NH_MCP_PROBE_STEPS
                            ? newton_max
                            : NH_MCP_PROBE_STEPS;
      NH_TRY(nh_mcp_newton(ws, W, lw, tolerance, steps, &st->newton_steps, &r));
      *used |= 1;
      if (r <= tolerance || last) break;
      round *= 2;
    }
  }
  *res = r;
  return NH_OK;
}

/* One solve of the problem (the header's method); newton_first > 0: the
 * exact method first whatever m (the proximal fallback's regularised
 * problems); < 0: no long Newton after the sweeps (nh_mcp_attempt). */
static int nh_mcp_solve_once(int m, const double *W, int unsym, const double *r, nh_row_law *laws,
                             double tolerance, int max_iterations, int newton_first, double *lambda,
                             nh_mcp_stats *stats) {
  nh_mcp_stats dummy;
  if (!stats) stats = &dummy;
  memset(stats, 0, sizeof *stats);
  NH_CHECK(m >= 0, NH_ERR_INPUT, "constraint solve: %d rows", m);
  NH_CHECK(tolerance > 0.0 && max_iterations >= 0, NH_ERR_INPUT,
           "constraint solve: tolerance %g must be > 0 and max_iterations %d >= 0", tolerance,
           max_iterations);
  if (m == 0) return NH_OK;
  NH_CHECK(W && r && laws && lambda, NH_ERR_INPUT, "constraint solve: a NULL argument");
  NH_TRY(nh_mcp_check_laws(m, laws));
  for (size_t k = 0; k < (size_t)m * m; k++)
    NH_CHECK(isfinite(W[k]), NH_ERR_NUMERIC, "constraint solve: W(%d, %d) = %g",
             (int)(k % (size_t)m), (int)(k / (size_t)m), W[k]);
  for (int i = 0; i < m; i++) {
    NH_CHECK(isfinite(r[i]) && isfinite(lambda[i]), NH_ERR_NUMERIC,
             "constraint solve: row %d has r = %g, warm-start lambda = %g", i, r[i], lambda[i]);
    NH_CHECK(W[(size_t)i * m + i] >= 0.0, NH_ERR_NUMERIC,
             "constraint solve: W(%d, %d) = %g < 0: the compliance is not positive semi-definite",
             i, i, W[(size_t)i * m + i]);
  }

  nh_mcp_work ws = {.m = m, .unsym = unsym, .flops = 3.0 * (double)m * m}; /* W checked, scaled */
  size_t mm = (size_t)m * m;
  int nb = 0;
  for (int i = 0; i < m; i++) nb += laws[i].kind == NH_ROW_BILATERAL;
  ws.nb = nb;
  ws.Wt = nh_calloc(mm, sizeof(double));
  ws.d = nh_calloc((size_t)m, sizeof(double));
  ws.rt = nh_calloc((size_t)m, sizeof(double));
  ws.lt = nh_calloc((size_t)m, sizeof(double));
  ws.wt = nh_calloc((size_t)m, sizeof(double));
  ws.best = nh_calloc((size_t)m, sizeof(double));
  ws.L = nh_calloc(((size_t)nb * nb + 1), sizeof(double));
  ws.tmp = nh_calloc((size_t)m, sizeof(double));
  if (NH_MCP_SUBSPACE) {
    ws.Lf = nh_calloc(mm, sizeof(double));
    ws.save_l = nh_calloc((size_t)m, sizeof(double));
    ws.save_w = nh_calloc((size_t)m, sizeof(double));
    ws.free_rows = nh_calloc((size_t)m, sizeof(int));
    ws.lf_rows = nh_calloc((size_t)m, sizeof(int));
  }
  ws.lf_n = -1;
  ws.bil = nh_calloc(((size_t)nb + 1), sizeof(int));
  if (unsym) {
    ws.piv = nh_calloc((size_t)nb + 1, sizeof(int));
    ws.pivf = nh_calloc((size_t)m, sizeof(int));
  }
  nh_row_law *lw = nh_calloc((size_t)m, sizeof *lw);
  if (!lw || !ws.Wt || !ws.d || !ws.rt || !ws.lt || !ws.wt || !ws.best || !ws.L || !ws.tmp ||
      !ws.bil || (unsym && (!ws.piv || !ws.pivf)) ||
      (NH_MCP_SUBSPACE && (!ws.Lf || !ws.save_l || !ws.save_w || !ws.free_rows || !ws.lf_rows))) {
    nh_mcp_work_free(&ws);
    free(lw);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint solve (%d rows)", m);
  }
  for (int i = 0; i < m; i++) {
    double wii = W[(size_t)i * m + i];
    ws.d[i] = wii > 0.0 ? 1.0 / sqrt(wii) : 1.0;
  }
  for (int j = 0; j < m; j++)
    for (int i = 0; i < m; i++) ws.Wt[(size_t)j * m + i] = ws.d[i] * W[(size_t)j * m + i] * ws.d[j];
  for (int i = 0; i < m; i++) {
    ws.rt[i] = ws.d[i] * r[i];
    ws.lt[i] = lambda[i] / ws.d[i];
  }
  /* A warm start outside its set (e.g. the bound shrank since the last step) is
   * left to the first sweep, which projects it. */
  nb = 0;
  for (int i = 0; i < m; i++)
    if (laws[i].kind == NH_ROW_BILATERAL) ws.bil[nb++] = i;
  ws.block_ok = NH_MCP_BILATERAL_BLOCK && nb > 0 ? nh_mcp_factor(&ws, nb, ws.bil, ws.L, ws.piv) : 0;

  /* The laws as solved: a row that stuck at the previous step starts with its
   * static coefficient. */
  for (int i = 0; i < m; i++) {
    lw[i] = laws[i];
    if (laws[i].kind == NH_ROW_FRICTION && !laws[i].sliding)
      lw[i].mu = fmax(laws[i].mu, laws[i].mu_static);
  }
  int used = 0, rc = NH_OK;
  double best_res = HUGE_VAL;
  rc = nh_mcp_attempt(&ws, W, lw, tolerance, max_iterations, newton_first, stats, &used, &best_res);
  /* Break-away: a row on its static bound slides, at the kinetic bound;
   * solve again from here until no row breaks away (at most once per row). */
  for (int broke = 1; !rc && broke && best_res <= tolerance && !nh_stop_requested();) {
    broke = 0;
    for (int i = 0; i < m; i++) {
      nh_row_law *l = &lw[i];
      if (l->kind != NH_ROW_FRICTION || (l->group >= 0 && l->group != i) || !(l->mu > laws[i].mu) ||
          nh_mcp_friction_size(&ws, l, i) < nh_mcp_bound(&ws, l) * (1.0 - 1e-9))
        continue;
      l->mu = laws[i].mu;
      if (l->group == i) lw[i + 1].mu = laws[i + 1].mu;
      broke = 1;
    }
    if (broke)
      rc = nh_mcp_attempt(&ws, W, lw, tolerance, max_iterations, newton_first, stats, &used,
                          &best_res);
  }
  memcpy(ws.lt, ws.best, sizeof(double) * (size_t)m);
  for (int i = 0; i < m; i++) lambda[i] = ws.d[i] * ws.lt[i];
  const int it = stats->newton_steps + stats->sweeps;
  stats->iterations = it;
  stats->method = used == 3 ? NH_MCP_FALLBACK : used == 1 ? NH_MCP_EXACT : NH_MCP_SWEEPS;
  stats->residual = best_res;
  stats->flops = ws.flops, stats->flops_dense = ws.flops_dense;
  nh_mcp_count(&ws, lw, stats);
  for (int i = 0; i < m; i++)
    if (laws[i].kind == NH_ROW_FRICTION) {
      int g = laws[i].group < 0 ? i : laws[i].group;
      laws[i].sliding =
          nh_mcp_friction_size(&ws, &lw[g], g) >= nh_mcp_bound(&ws, &lw[g]) * (1.0 - 1e-9);
    }
  free(lw);
  int block_ok = ws.block_ok;
  nh_mcp_work_free(&ws);
  if (rc) return rc;
  if (nh_stop_requested()) return nh_stop_check();
  if (!(best_res <= tolerance))
    return NH_ERROR(NH_ERR_NUMERIC,
                    "constraint solve: residual %.3g > tolerance %.3g after %d Newton steps and %d "
                    "sweeps (%d rows, %d bilateral%s)",
                    best_res, tolerance, stats->newton_steps, stats->sweeps, m, nb,
                    NH_MCP_BILATERAL_BLOCK && nb > 0 && !block_ok ? ", dependent: solved row by row"
                                                                  : "");
  return NH_OK;
}

/* The counts of a solve that followed `earlier` made its own: Newton
 * steps, sweeps, their sum and the operations added (method, residual and
 * the rows' states stay the later solve's). */
static void nh_mcp_stats_after(nh_mcp_stats *later, const nh_mcp_stats *earlier) {
  later->newton_steps += earlier->newton_steps, later->sweeps += earlier->sweeps;
  later->iterations = later->newton_steps + later->sweeps;
  later->flops += earlier->flops, later->flops_dense += earlier->flops_dense;
}

/* The proximal fallback (header, "Proximal fallback"): the stalled solve's best λ
 * in lambda, its statistics in *stats; laws: as given to it, out: its laws.
 * Solves w = (W + ρD) λ + r − ρD λ_k (at most NH_MCP_PROX_STEPS Newton
 * steps and sweeps each) from ρ = NH_MCP_PROX_FIRST: a solved one is the
 * next centre λ_k+1 and ρ ÷ 10, down to NH_MCP_PROX_LAST; an unsolved one
 * keeps the centre and ρ × 10 (none above NH_MCP_PROX_MAX: the
 * fallback stops). Until λ_k solves the original problem within
 * tolerance, then the original problem from there (which sets the laws'
 * outputs); Newton steps and sweeps all within the caller's
 * max_iterations. Only a converged result is kept: *converged = 1 with λ,
 * out and *stats replaced; else nothing changes. NH_ERR_MEMORY. */
static int nh_mcp_proximal(int m, const double *W, int unsym, const double *r,
                           const nh_row_law *laws, nh_row_law *out, double tolerance,
                           int max_iterations, double *lambda, nh_mcp_stats *stats,
                           int *converged) {
  *converged = 0;
  double *Wr = nh_calloc((size_t)m * m, sizeof(double)), *rr = nh_calloc((size_t)m, sizeof(double));
  double *lam = nh_calloc((size_t)m, sizeof(double)), *probe = nh_calloc((size_t)m, sizeof(double));
  nh_row_law *lw = nh_calloc((size_t)m, sizeof *lw);
  if (!Wr || !rr || !lam || !probe || !lw) {
    free(Wr), free(rr), free(lam), free(probe), free(lw);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint solve's proximal fallback (%d rows)",
                    m);
  }
  memcpy(Wr, W, sizeof(double) * (size_t)m * m);
  memcpy(lam, lambda, sizeof(double) * (size_t)m);
  int newton = 0, sweeps = 0, left = max_iterations, rc = NH_OK;
  double flops = 0.0, flops_dense = 0.0, rho = NH_MCP_PROX_FIRST;
  int reached = 0;
  while (rho >= NH_MCP_PROX_LAST * 0.5 && left > 0) {
    for (int i = 0; i < m; i++) {
      const double d = W[(size_t)i * m + i];
      Wr[(size_t)i * m + i] = d * (1.0 + rho);
      rr[i] = r[i] - rho * d * lam[i];
    }
    nh_mcp_stats st;
    memcpy(lw, laws, sizeof *lw * (size_t)m);
    memcpy(probe, lam, sizeof(double) * (size_t)m);
    const int budget = left < NH_MCP_PROX_STEPS ? left : NH_MCP_PROX_STEPS;
    rc = nh_mcp_solve_once(m, Wr, unsym, rr, lw, tolerance, budget, 1, probe, &st);
    newton += st.newton_steps, sweeps += st.sweeps, left -= st.newton_steps + st.sweeps;
    flops += st.flops, flops_dense += st.flops_dense;
    if (rc == NH_ERR_NUMERIC) nh_error_clear(), rc = NH_OK;
    if (rc || nh_stop_requested()) break;
    if (!(st.residual <= tolerance)) { /* not solved: a larger ρ, the same centre */
      if (rho >= NH_MCP_PROX_MAX) break;
      rho *= 10.0;
      continue;
    }
    memcpy(lam, probe, sizeof(double) * (size_t)m); /* the next centre */
    memcpy(lw, laws, sizeof *lw * (size_t)m);       /* the original residual at it */
    rc = nh_mcp_solve_once(m, W, unsym, r, lw, tolerance, 0, 0, probe, &st);
    if (rc == NH_ERR_NUMERIC) nh_error_clear(), rc = NH_OK;
    flops += st.flops;
    if (rc || (reached = st.residual <= tolerance)) break;
    rho *= 0.1;
  }
  if (!rc && !nh_stop_requested()) {
    /* reached: the laws' outputs and the break-away loop at λ; else a
     * short Newton from the last centre (the caller's plain solve has the
     * rest of the budget) */
    nh_mcp_stats fin;
    const int budget = reached || left < NH_MCP_PROX_STEPS ? left : NH_MCP_PROX_STEPS;
    memcpy(lw, laws, sizeof *lw * (size_t)m);
    rc = nh_mcp_solve_once(m, W, unsym, r, lw, tolerance, budget > 0 ? budget : 0, 1, lam, &fin);
    if (rc == NH_OK) {
      *converged = 1;
      memcpy(lambda, lam, sizeof(double) * (size_t)m);
      memcpy(out, lw, sizeof *lw * (size_t)m);
      fin.newton_steps += newton, fin.sweeps += sweeps;
      fin.flops += flops, fin.flops_dense += flops_dense;
      nh_mcp_stats_after(&fin, stats);
      fin.method = NH_MCP_FALLBACK;
      *stats = fin;
    } else if (rc == NH_ERR_NUMERIC) {
      nh_error_clear(), rc = NH_OK;
    }
  }
  free(Wr), free(rr), free(lam), free(probe), free(lw);
  return rc;
}

/* nh_mcp_solve_once with at most NH_MCP_PROX_AFTER of max_iterations and,
 * where it stalls short of tolerance, the proximal fallback, whose result
 * is kept if it converges; if it does not, the plain solve again from its
 * best iterate with the rest of max_iterations. */
static int nh_mcp_solve_any(int m, const double *W, int unsym, const double *r, nh_row_law *laws,
                            double tolerance, int max_iterations, double *lambda,
                            nh_mcp_stats *stats) {
  nh_mcp_stats dummy;
  if (!stats) stats = &dummy;
  nh_row_law *given = m > 0 && laws ? nh_calloc((size_t)m, sizeof *given) : NULL;
  if (given) memcpy(given, laws, sizeof *given * (size_t)m); /* (without memory: no fallback) */
  const int first =
      given && max_iterations > NH_MCP_PROX_AFTER ? NH_MCP_PROX_AFTER : max_iterations;
  int rc = nh_mcp_solve_once(m, W, unsym, r, laws, tolerance, first,
                             first < max_iterations ? -1 : 0, lambda, stats);
  if (!given || rc != NH_ERR_NUMERIC || !(stats->residual > tolerance) ||
      !isfinite(stats->residual) || nh_stop_requested()) {
    free(given);
    return rc;
  }
  char stalled[1024];
  snprintf(stalled, sizeof stalled, "%s", nh_error_message());
  nh_error_clear();
  int converged = 0, prc = nh_mcp_proximal(m, W, unsym, r, given, laws, tolerance, max_iterations,
                                           lambda, stats, &converged);
  if (!prc && !converged && first < max_iterations && !nh_stop_requested()) {
    /* the rest of the budget to the plain solve, from its best iterate
     * (its error, if it stalls too, is the one reported) */
    nh_mcp_stats more;
    memcpy(laws, given, sizeof *given * (size_t)m);
    rc = nh_mcp_solve_once(m, W, unsym, r, laws, tolerance, max_iterations - first, 0, lambda,
                           &more);
    nh_mcp_stats_after(&more, stats);
    *stats = more;
    free(given);
    return rc;
  }
  free(given);
  if (prc) return prc;
  return converged ? NH_OK : NH_ERROR(NH_ERR_NUMERIC, "%s", stalled);
}

int nh_mcp_solve(int m, const double *W, const double *r, nh_row_law *laws, double tolerance,
                 int max_iterations, double *lambda, nh_mcp_stats *stats) {
  return nh_mcp_solve_any(m, W, 0, r, laws, tolerance, max_iterations, lambda, stats);
}

int nh_mcp_solve_unsymmetric(int m, const double *W, const double *r, nh_row_law *laws,
                             double tolerance, int max_iterations, double *lambda,
                             nh_mcp_stats *stats) {
  return nh_mcp_solve_any(m, W, 1, r, laws, tolerance, max_iterations, lambda, stats);
}
