/* mcp_newton.c — the exact method of the constraint solver: semismooth
 * Newton on the natural map of the mixed complementarity problem
 * (docs/interaction.md "Constraint solver"; called by nh_mcp_solve, mcp.c,
 * which owns the problem, its scaling and the break-away loop).
 *
 * Every law says λ̃_i = P_K(λ̃_i − w̃_i) (mcp.c), so λ̃ solves the problem iff
 *   F(λ̃) = λ̃ − P_K(λ̃ − w̃(λ̃)) = 0,   w̃ = W̃ λ̃ + r̃,
 * row by row in the scaled variables (a disc pair's two components in its
 * isotropically scaled coordinates: the same map the stopping residual
 * measures). F is piecewise smooth, hence semismooth, and Newton's method
 * with an element H of its generalised Jacobian converges locally
 * quadratically (Qi & Sun, "A nonsmooth version of Newton's method"; for
 * contact, Alart & Curnier, "A mixed formulation for frictional contact
 * problems prone to Newton like solution methods"). Where the law is linear
 * in λ̃ (no friction coupling, no disc sliding) the map is piecewise linear:
 * once the active pieces are right, one step lands on the solution, whatever
 * the condition of W̃ — the projected sweeps converge at a rate that tends
 * to 1 as cond(W̃) grows.
 *
 * H row by row, from the piece the current point lies on (y = λ̃ − w̃):
 *   bilateral, unilateral inside [0, c̃], friction inside its bound, disc
 *     inside its disc: F = w̃, H = W̃(i, :) (a "W row");
 *   unilateral with y ≤ 0 or y ≥ c̃: F = λ̃ − 0 or λ̃ − c̃, H = e_i (fixed);
 *   friction with |y| > b̃: F = λ̃ ∓ b̃(λ̃), H = e_i ∓ ∂b̃/∂λ̃ (b̃ = (μ N + c)/d_i
 *     moves with the normal force N = |λ_n| or |(λ_n, λ_n2)|);
 *   disc pair sliding (|y| > b): F = x − b ŷ, x, v the pair's force and
 *     violation, y = x − v, ŷ = y/|y|, α = b/|y| < 1, P = I − ŷŷᵀ:
 *     dF = (I − αP) dx + αP dv − ŷ db.
 * Fixed rows give their component of the step at once (δ_i = −F_i); the
 * others form the reduced system H_RR δ_R = −F_R − H_RA δ_A, solved by LU
 * with partial pivoting (LAPACK dgetrf; not symmetric once friction couples
 * to normals). When its estimated reciprocal condition is below 1e-15 (rows
 * that W̃ does not separate: dependent bilateral rows, a row W does not see)
 * it is regularised with ε I, ε from 1e-14 up by factors 100, which gives a
 * step of bounded size along the null directions.
 *
 * Globalisation: the merit φ = ½|F|²; a step is accepted with the Armijo
 * rule φ(λ̃ + tδ) ≤ (1 − 2σt) φ(λ̃), σ = 1e-4, t halved from 1 up to 30
 * times. If no t is accepted (F not differentiable where δ points, or a
 * regularised step) the method returns: the caller then runs the projected
 * sweeps from here (docs/interaction.md, "Method and fallback").
 *
 * Workspace O(m²) (H and its reduced block), allocated per call. */
#include "solve/mcp_impl.h"

#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Block steps without progress before single pivots (Júdice & Pires use a
 * few); steps on unchanged pieces without halving the residual before
 * giving up (a round-off floor above the tolerance); the reciprocal
 * condition below which the reduced system is regularised. */
#define NH_NEWTON_CHANCES  3
#define NH_NEWTON_STALLS   3
#define NH_NEWTON_RCOND    1e-15
#define NH_TRESCA_MAX      50
#define NH_NEWTON_ARMIJO   1e-4
#define NH_NEWTON_HALVINGS 20

/* The piece of a row's law (see the top of this file). */
enum { NH_PIECE_FREE, NH_PIECE_LOW, NH_PIECE_CAP, NH_PIECE_PLUS, NH_PIECE_MINUS, NH_PIECE_SLIDE };

typedef struct {
  double *F, *Ft, *l0, *H, *HR, *dir, *rhs, *z;
  int *piece, *next, *unit, *red, *ipiv;
} nh_newton_work;

/* The bound of a friction law on its piece, and ∂b/∂λ̃ (up to two entries)
 * into idx, g. The normal force size N is |(λ_n, λ_n2)| (two normals) or
 * |λ_n|; a unilateral normal's force is ≥ 0 at any solution, so on a piece
 * its N is λ_n itself: linear, without the kink of |λ_n| at 0 that a step
 * through 0 would meet. Where N is |.| at 0 (a point that just joined, an
 * open contact) the gradient is that of N's derivative along `hint` (the
 * step computed without it; NULL: 0), |D δ_n| = g · δ_n. */
static double nh_piece_bound(const nh_mcp_work *ws, const nh_row_law *laws, const nh_row_law *l,
                             const double *hint, int idx[2], double g[2], int *ng) {
  *ng = 0;
  if (l->normal < 0) return l->threshold;
  const int a = l->normal, b = l->normal2;
  double xa = ws->d[a] * ws->lt[a], xb = b >= 0 ? ws->d[b] * ws->lt[b] : 0.0;
  idx[0] = a, idx[1] = b, *ng = b >= 0 ? 2 : 1;
  if (b < 0 && laws[a].kind == NH_ROW_UNILATERAL) {
    g[0] = ws->d[a];
    return l->mu * xa + l->threshold;
  }
  const double N = hypot(xa, xb);
  if (N == 0.0 && hint) xa = ws->d[a] * hint[a], xb = b >= 0 ? ws->d[b] * hint[b] : 0.0;
  const double Nd = hypot(xa, xb);
  g[0] = Nd > 0.0 ? ws->d[a] * xa / Nd : 0.0;
  g[1] = Nd > 0.0 && b >= 0 ? ws->d[b] * xb / Nd : 0.0;
  return l->mu * N + l->threshold;
}

/* Whether a friction law's bound has the kink of |.| at a normal force 0. */
static int nh_normal_kink(const nh_mcp_work *ws, const nh_row_law *laws, const nh_row_law *l) {
  return l->normal >= 0 && ws->lt[l->normal] == 0.0 &&
         (l->normal2 < 0 || ws->lt[l->normal2] == 0.0) &&
         !(l->normal2 < 0 && laws[l->normal].kind == NH_ROW_UNILATERAL);
}

/* A disc pair in its coordinates (x = D λ̃ / s, v = s D⁻¹ w̃, bound b / s):
 * x, v, the scale s and the bound. */
static double nh_pair(const nh_mcp_work *ws, const double *W, const nh_row_law *l, int g,
                      double x[2], double v[2], double *s) {
  const int h = g + 1;
  *s = nh_mcp_pair_scale(W, ws->m, g);
  x[0] = ws->d[g] * ws->lt[g] / *s, x[1] = ws->d[h] * ws->lt[h] / *s;
  v[0] = *s * ws->wt[g] / ws->d[g], v[1] = *s * ws->wt[h] / ws->d[h];
  return nh_mcp_bound(ws, l) / *s;
}

/* The piece the natural map puts each row on at the current λ̃ (w̃ current). */
static void nh_newton_pieces(const nh_mcp_work *ws, const double *W, const nh_row_law *laws,
                             int *piece) {
  for (int i = 0; i < ws->m; i++) {
    const nh_row_law *l = &laws[i];
    double y = ws->lt[i] - ws->wt[i];
    int pc = NH_PIECE_FREE;
    if (l->kind == NH_ROW_UNILATERAL) {
      pc = y <= 0.0 ? NH_PIECE_LOW : y >= nh_mcp_cap(ws, l, i) ? NH_PIECE_CAP : NH_PIECE_FREE;
    } else if (l->kind == NH_ROW_FRICTION && l->group < 0) {
      double b = nh_mcp_bound(ws, l) / ws->d[i];
      if (l->one_sided && y <= 0.0)
        pc = NH_PIECE_LOW; /* it does not pull: λ = 0 */
      else
        pc = fabs(y) <= b ? NH_PIECE_FREE : y > 0.0 ? NH_PIECE_PLUS : NH_PIECE_MINUS;
    } else if (l->kind == NH_ROW_FRICTION && l->group == i) {
      double x[2], v[2], s, b = nh_pair(ws, W, l, i, x, v, &s);
      pc = hypot(x[0] - v[0], x[1] - v[1]) <= b ? NH_PIECE_FREE : NH_PIECE_SLIDE;
      piece[i + 1] = pc;
    } else if (l->kind == NH_ROW_FRICTION) {
      continue; /* the pair's second row: set with the first */
    }
    piece[i] = pc;
  }
}

/* H(i, :) += f W̃(q, :): W̃'s row q (the column q of a symmetric W̃, read
 * contiguously; an unsymmetric one's row). */
static void nh_add_w_row(const nh_mcp_work *ws, double *H, int i, int q, double f) {
  const int m = ws->m;
  if (ws->unsym) {
    for (int j = 0; j < m; j++) H[(size_t)j * m + i] += f * nh_mcp_w(ws, q, j);
    return;
  }
  const double *c = ws->Wt + (size_t)q * m;
  for (int j = 0; j < m; j++) H[(size_t)j * m + i] += f * c[j];
}

/* The equations G_P(λ̃) = 0 of the pieces P at the current λ̃ (w̃ current)
 * into F, their Jacobian into H (column-major, H[j m + i] = ∂G_i/∂λ̃_j) and
 * unit[i] = 1 where H's row is e_i. *kinks counts bounds whose normal force
 * is 0 (their gradient then follows `hint`). */
static void nh_newton_system(nh_mcp_work *ws, const double *W, const nh_row_law *laws,
                             const int *piece, const double *hint, nh_newton_work *nw, int *kinks,
                             double *F, int jacobian) {
  const int m = ws->m;
  double *H = jacobian ? nw->H : NULL;
  if (H) memset(H, 0, sizeof(double) * (size_t)m * m), ws->flops += (double)m * m;
  for (int i = 0; i < m; i++) {
    const nh_row_law *l = &laws[i];
    const double lam = ws->lt[i];
    int idx[2], ng = 0;
    double g[2];
    nw->unit[i] = 0;
    if (H && (piece[i] == NH_PIECE_LOW || piece[i] == NH_PIECE_CAP || piece[i] == NH_PIECE_PLUS ||
              piece[i] == NH_PIECE_MINUS))
      H[(size_t)i * m + i] = 1.0;
    switch (piece[i]) {
    case NH_PIECE_FREE:
      F[i] = ws->wt[i];
      if (H) nh_add_w_row(ws, H, i, i, 1.0);
      break;
    case NH_PIECE_LOW:
      F[i] = lam, nw->unit[i] = 1;
      break;
    case NH_PIECE_CAP:
      F[i] = lam - nh_mcp_cap(ws, l, i), nw->unit[i] = 1;
      break;
    case NH_PIECE_PLUS:
    case NH_PIECE_MINUS: {
      const double sg = piece[i] == NH_PIECE_PLUS ? 1.0 : -1.0;
      F[i] = lam - sg * nh_piece_bound(ws, laws, l, hint, idx, g, &ng) / ws->d[i];
      nw->unit[i] = 1;
      if (!H) break;
      *kinks += nh_normal_kink(ws, laws, l);
      for (int k = 0; k < ng; k++)
        if (l->mu * g[k] != 0.0) {
          H[(size_t)idx[k] * m + i] -= sg * l->mu * g[k] / ws->d[i];
          nw->unit[i] = 0;
        }
      break;
    }
    case NH_PIECE_SLIDE: { /* the pair (i, i+1), on its circle: x = b ŷ, y = x − v */
      double x[2], v[2], s;
      nh_pair(ws, W, l, i, x, v, &s);
      const double b = nh_piece_bound(ws, laws, l, hint, idx, g, &ng) / s;
      double y[2] = {x[0] - v[0], x[1] - v[1]}, ny = hypot(y[0], y[1]), alpha = 0.0;
      double yh[2] = {1.0, 0.0}, nx = hypot(x[0], x[1]);
      if (ny > 0.0)
        yh[0] = y[0] / ny, yh[1] = y[1] / ny, alpha = b / ny;
      else if (nx > 0.0) /* no slip direction yet: the force's */
        yh[0] = x[0] / nx, yh[1] = x[1] / nx;
      F[i] = x[0] - b * yh[0], F[i + 1] = x[1] - b * yh[1];
      nw->unit[i] = nw->unit[i + 1] = 0;
      if (!H) {
        i++;
        break;
      }
      *kinks += nh_normal_kink(ws, laws, l);
      const double dd[2] = {ws->d[i], ws->d[i + 1]};
      for (int k = 0; k < 2; k++) {
        for (int q = 0; q < 2; q++) {
          const double P = (k == q) - yh[k] * yh[q]; /* dG = (I − αP) dx + αP dv − ŷ db */
          H[(size_t)(i + q) * m + i + k] += ((k == q) - alpha * P) * dd[q] / s;
          if (alpha * P != 0.0) nh_add_w_row(ws, H, i + k, i + q, alpha * P * s / dd[q]);
        }
        for (int e = 0; e < ng; e++) H[(size_t)idx[e] * m + i + k] -= yh[k] * l->mu * g[e] / s;
      }
      i++;
      break;
    }
    }
  }
}

/* The Newton step G_P + H dir = 0: unit rows directly, the rest by LU of
 * the reduced block, regularised if it is near singular. Returns 0, or 1 if
 * no regularisation gave a finite step. */
static int nh_newton_direction(nh_mcp_work *ws, nh_newton_work *nw) {
  const int m = ws->m;
  int nr = 0;
  for (int i = 0; i < m; i++) {
    if (nw->unit[i])
      nw->dir[i] = -nw->F[i];
    else
      nw->red[nr++] = i;
  }
  if (nr == 0) return 0;
  for (int a = 0; a < nr; a++) {
    const int i = nw->red[a];
    double v = -nw->F[i];
    for (int j = 0; j < m; j++)
      if (nw->unit[j]) v -= nw->H[(size_t)j * m + i] * nw->dir[j];
    nw->rhs[a] = v;
  }
  ws->flops += 2.0 * (double)m * nr;
  for (double eps = 0.0; eps <= 1.0; eps = eps > 0.0 ? eps * 100.0 : 1e-14) {
    for (int b = 0; b < nr; b++)
      for (int a = 0; a < nr; a++)
        nw->HR[(size_t)b * nr + a] =
            nw->H[(size_t)nw->red[b] * m + nw->red[a]] + (a == b ? eps : 0.0);
    double anorm = LAPACKE_dlange(LAPACK_COL_MAJOR, '1', nr, nr, nw->HR, nr), rcond = 0.0;
    ws->flops += 6.0 * (double)nr * nr;
    ws->flops_dense += 2.0 * (double)nr * nr * nr / 3.0;
    int info = LAPACKE_dgetrf_work(LAPACK_COL_MAJOR, nr, nr, nw->HR, nr, nw->ipiv);
    if (info == 0) LAPACKE_dgecon(LAPACK_COL_MAJOR, '1', nr, nw->HR, nr, anorm, &rcond);
    if (info != 0 || !(rcond >= NH_NEWTON_RCOND)) continue;
    memcpy(nw->z, nw->rhs, sizeof(double) * (size_t)nr);
    LAPACKE_dgetrs_work(LAPACK_COL_MAJOR, 'N', nr, 1, nw->HR, nr, nw->ipiv, nw->z, nr);
    int finite = 1;
    for (int a = 0; a < nr; a++) finite &= isfinite(nw->z[a]);
    if (!finite) continue;
    for (int a = 0; a < nr; a++) nw->dir[nw->red[a]] = nw->z[a];
    return 0;
  }
  return 1;
}

/* The Newton step of the pieces P at the current λ̃, taken in full. */
static int nh_newton_step(nh_mcp_work *ws, const double *W, const nh_row_law *laws,
                          nh_newton_work *nw) {
  const int m = ws->m;
  int kinks = 0;
  nh_newton_system(ws, W, laws, nw->piece, NULL, nw, &kinks, nw->F, 1);
  if (nh_newton_direction(ws, nw)) return 1;
  if (kinks) { /* a bound whose normal force is 0: again, with its derivative along the step */
    memcpy(nw->rhs + m, nw->dir, sizeof(double) * (size_t)m);
    nh_newton_system(ws, W, laws, nw->piece, nw->rhs + m, nw, &kinks, nw->F, 1);
    if (nh_newton_direction(ws, nw)) return 1;
  }
  /* Damped on the pieces' own equations: a step that does not reduce |G_P|
   * (Armijo) is halved. Where the pieces are linear the full step solves
   * them (G_P = 0 there) and is taken; the halving acts only where they are
   * not (a Coulomb bound, a disc), far from their solution. */
  double g0 = 0.0;
  for (int i = 0; i < m; i++) g0 += nw->F[i] * nw->F[i];
  memcpy(nw->l0, ws->lt, sizeof(double) * (size_t)m);
  double t = 1.0;
  for (int k = 0; k <= NH_NEWTON_HALVINGS; k++, t *= 0.5) {
    if (k == 1) { /* the full step left the pieces: a pivot, taken in full */
      nh_newton_pieces(ws, W, laws, nw->next);
      if (memcmp(nw->next, nw->piece, sizeof(int) * (size_t)m)) {
        for (int i = 0; i < m; i++) ws->lt[i] = nw->l0[i] + nw->dir[i];
        nh_mcp_recompute_w(ws);
        return 0;
      }
    }
    for (int i = 0; i < m; i++) ws->lt[i] = nw->l0[i] + t * nw->dir[i];
    nh_mcp_recompute_w(ws);
    nh_newton_system(ws, W, laws, nw->piece, NULL, nw, &kinks, nw->Ft, 0);
    double g = 0.0;
    for (int i = 0; i < m; i++) g += nw->Ft[i] * nw->Ft[i];
    if (g <= (1.0 - 2.0 * NH_NEWTON_ARMIJO * t) * g0) return t < 1.0 ? 2 : 0;
  }
  for (int i = 0; i < m; i++) ws->lt[i] = nw->l0[i] + nw->dir[i]; /* none: the full step */
  nh_mcp_recompute_w(ws);
  return 3;
}

int nh_mcp_newton(nh_mcp_work *ws, const double *W, const nh_row_law *laws, double tolerance,
                  int max_steps, int *steps, double *residual) {
  const int m = ws->m;
  const size_t mm = (size_t)m * m;
  nh_newton_work nw = {0};
  nw.F = nh_calloc((size_t)m, sizeof(double));
  nw.dir = nh_calloc((size_t)m, sizeof(double));
  nw.Ft = nh_calloc((size_t)m, sizeof(double));
  nw.l0 = nh_calloc((size_t)m, sizeof(double));
  nw.rhs = nh_calloc(2 * (size_t)m, sizeof(double));
  nw.z = nh_calloc((size_t)m, sizeof(double));
  nw.H = nh_calloc(mm, sizeof(double));
  nw.HR = nh_calloc(mm, sizeof(double));
  nw.piece = nh_calloc((size_t)m, sizeof(int));
  nw.next = nh_calloc((size_t)m, sizeof(int));
  nw.unit = nh_calloc((size_t)m, sizeof(int));
  nw.red = nh_calloc((size_t)m, sizeof(int));
  nw.ipiv = nh_calloc((size_t)m, sizeof(int));
  int rc = nw.F && nw.Ft && nw.l0 && nw.dir && nw.rhs && nw.z && nw.H && nw.HR && nw.piece &&
                   nw.next && nw.unit && nw.red && nw.ipiv
               ? NH_OK
               : NH_ERR_MEMORY;
  nh_mcp_recompute_w(ws);
  double res = nh_mcp_residual(ws, W, laws), best = res;
  memcpy(ws->best, ws->lt, sizeof(double) * (size_t)m);
  if (!rc) nh_newton_pieces(ws, W, laws, nw.piece);
  int n = 0, fewest = m + 1, chances = NH_NEWTON_CHANCES, stalls = 0;
  while (!rc && !(best <= tolerance) && n < max_steps && !nh_stop_requested()) {
    const double before = res;
    const int how = nh_newton_step(ws, W, laws, &nw);
    if (how == 1) break;
    n++;
    res = nh_mcp_residual(ws, W, laws);
    if (!isfinite(res)) break;
    if (res <= best) best = res, memcpy(ws->best, ws->lt, sizeof(double) * (size_t)m);
    if (best <= tolerance) break;
    /* the rows whose piece the step left (block principal pivoting's
     * infeasible set), the last of them for a single pivot */
    nh_newton_pieces(ws, W, laws, nw.next);
    int changed = 0, last = -1;
    for (int i = 0; i < m; i++)
      if (nw.next[i] != nw.piece[i] &&
          !(i > 0 && laws[i].kind == NH_ROW_FRICTION && laws[i].group == i - 1))
        changed++, last = i;
    if (changed == 0) { /* the pieces hold: Newton on a smooth system (friction, discs) */
      stalls = res <= 0.5 * before || how == 2 ? 0 : stalls + 1;
      if (stalls >= NH_NEWTON_STALLS) break;
      continue;
    }
    stalls = 0;
    if (changed < fewest) {
      fewest = changed, chances = NH_NEWTON_CHANCES;
      memcpy(nw.piece, nw.next, sizeof(int) * (size_t)m);
    } else if (chances > 0) {
      chances--;
      memcpy(nw.piece, nw.next, sizeof(int) * (size_t)m);
    } else { /* Murty's rule: only the last row that left its piece */
      nw.piece[last] = nw.next[last];
      if (laws[last].kind == NH_ROW_FRICTION && laws[last].group == last)
        nw.piece[last + 1] = nw.next[last + 1];
    }
  }
  memcpy(ws->lt, ws->best, sizeof(double) * (size_t)m);
  nh_mcp_recompute_w(ws);
  free(nw.F), free(nw.Ft), free(nw.l0), free(nw.dir), free(nw.rhs), free(nw.z), free(nw.H),
      free(nw.HR);
  free(nw.piece), free(nw.next), free(nw.unit), free(nw.red), free(nw.ipiv);
  *steps += n;
  *residual = best;
  return rc;
}

int nh_mcp_tresca(nh_mcp_work *ws, const double *W, const nh_row_law *laws, double tolerance,
                  int max_steps, int *steps, double *residual) {
  const int m = ws->m;
  int coulomb = 0;
  for (int i = 0; i < m; i++) coulomb |= laws[i].kind == NH_ROW_FRICTION && laws[i].mu > 0.0;
  if (!coulomb) { /* nothing to freeze: the Newton method's answer stands */
    nh_mcp_recompute_w(ws);
    *residual = nh_mcp_residual(ws, W, laws);
    return NH_OK;
  }
  nh_row_law *fixed = nh_calloc((size_t)m, sizeof *fixed);
  double *keep = nh_calloc((size_t)m, sizeof(double));
  if (!fixed || !keep) {
    free(fixed), free(keep);
    return NH_ERR_MEMORY;
  }
  memcpy(fixed, laws, sizeof *fixed * (size_t)m);
  nh_mcp_recompute_w(ws);
  double best = nh_mcp_residual(ws, W, laws);
  memcpy(keep, ws->lt, sizeof(double) * (size_t)m);
  int rc = NH_OK, worse = 0;
  for (int outer = 0; outer < NH_TRESCA_MAX && !(best <= tolerance) && *steps < max_steps;
       outer++) {
    for (int i = 0; i < m; i++)
      if (laws[i].kind == NH_ROW_FRICTION)
        fixed[i].mu = 0.0, fixed[i].threshold = nh_mcp_bound(ws, &laws[i]);
    double inner;
    if ((rc = nh_mcp_newton(ws, W, fixed, 0.1 * tolerance, max_steps - *steps, steps, &inner)))
      break;
    double r = nh_mcp_residual(ws, W, laws);
    if (r < best)
      best = r, worse = 0, memcpy(keep, ws->lt, sizeof(double) * (size_t)m);
    else if (++worse >= 3)
      break;
  }
  memcpy(ws->lt, keep, sizeof(double) * (size_t)m);
  memcpy(ws->best, keep, sizeof(double) * (size_t)m);
  nh_mcp_recompute_w(ws);
  free(fixed), free(keep);
  *residual = best;
  return rc;
}
