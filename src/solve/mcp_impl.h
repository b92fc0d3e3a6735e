/* mcp_impl.h — the constraint solver's workspace and the helpers shared by
 * its two methods, projected Gauss-Seidel (mcp.c) and semismooth Newton
 * (mcp_newton.c); private to the solve module. */
#ifndef NH_MCP_IMPL_H
#define NH_MCP_IMPL_H

#include "solve/solve.h"

typedef struct {
  int m, nb, block_ok;
  int unsym;    /* W is not symmetric (beyond round-off): LU blocks, rows read as rows */
  double *Wt;   /* W̃ = D W D, column-major */
  double *d;    /* D = diag(W)^{-1/2} (1 for a zero diagonal) */
  double *rt;   /* r̃ */
  double *lt;   /* λ̃ */
  double *wt;   /* w̃ = W̃ λ̃ + r̃ */
  double *best; /* λ̃ of the smallest residual so far */
  double *L;    /* factor of W̃_BB (column-major, nb×nb): Cholesky, or LU if unsym */
  double *tmp;  /* m */
  int *bil;     /* indices of bilateral rows */
  double *Lf;   /* subspace step: factor of W̃_FF (m×m), saved λ̃ and w̃ */
  double *save_l, *save_w;
  int *free_rows;
  int *lf_rows; /* the free set Lf factorises (lf_n rows; −1: none yet) */
  int lf_n, lf_ok;
  int *piv, *pivf;           /* unsym: the LU pivots of L (nb) and of Lf (m) */
  double flops, flops_dense; /* operations so far (nh_mcp_stats) */
} nh_mcp_work;

/* W̃(i, j) of the scaled compliance (column-major). */
static inline double nh_mcp_w(const nh_mcp_work *ws, int i, int j) {
  return ws->Wt[(size_t)j * ws->m + i];
}

/* Unscaled Coulomb bound μ N + c of a friction row from the current normal
 * force(s) N = |λ_n| or |(λ_n, λ_n2)|. */
double nh_mcp_bound(const nh_mcp_work *ws, const nh_row_law *l);
/* Scaled cap of unilateral row i: threshold / d_i, or ∞ for threshold 0. */
double nh_mcp_cap(const nh_mcp_work *ws, const nh_row_law *l, int i);
/* A disc pair's isotropic scale 1/√((W_gg + W_g+1,g+1)/2). */
double nh_mcp_pair_scale(const double *W, int m, int g);
/* Project λ̃ onto every row's set (normals first, so the bounds are current). */
void nh_mcp_project(nh_mcp_work *ws, const double *W, const nh_row_law *laws);
/* w̃ = W̃ λ̃ + r̃ from scratch. */
void nh_mcp_recompute_w(nh_mcp_work *ws);
/* The dimensionless natural-map residual of the current iterate (w̃ current). */
double nh_mcp_residual(const nh_mcp_work *ws, const double *W, const nh_row_law *laws);

/* Semismooth Newton on the natural map from the current λ̃ (mcp_newton.c):
 * at most max_steps steps (*steps counts them), stopping at `tolerance` or
 * when the line search fails; λ̃ is left at the best iterate, w̃ current, its
 * residual in *residual. NH_ERR_MEMORY, else NH_OK (converged or not). */
int nh_mcp_newton(nh_mcp_work *ws, const double *W, const nh_row_law *laws, double tolerance,
                  int max_steps, int *steps, double *residual);

/* The outer fixed point on the Coulomb bounds (each Tresca problem, bounds
 * frozen at the current normal forces, solved by nh_mcp_newton); arguments
 * and result as there, max_steps the Newton steps of all inner solves. */
int nh_mcp_tresca(nh_mcp_work *ws, const double *W, const nh_row_law *laws, double tolerance,
                  int max_steps, int *steps, double *residual);

#endif
