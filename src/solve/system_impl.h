/* system_impl.h — the layout of nh_system, private to the solve module. */
#ifndef NH_SYSTEM_IMPL_H
#define NH_SYSTEM_IMPL_H

#include "solve/solve.h"
#include <cholmod.h>

struct nh_system {
  const nh_tissue *tissue; /* borrowed; tissue->mesh is the mesh */
  int n_nodes;
  int n_free;
  int *free_of; /* 3 per node: free index, -1 if fixed or hanging */
  int *dof_of;  /* n_free: the nodal DOF of each unknown */

  /* u = P u_free, node by node: node v's value is Σ w u(exp_node) over
   * exp_start[v] .. exp_start[v+1] (itself for a free node, its non-fixed
   * masters for a hanging node, nothing for a fixed one). */
  int *exp_start, *exp_node;
  double *exp_w;

  /* Leaves with a hanging corner assemble Tᵀ Aₑ T over their effective
   * nodes eff_node[eff_start[l] .. eff_start[l+1]) (an empty range for a
   * plain leaf), with T (8 per effective node, T[a k + p]) and a map of
   * (3 k)² positions from emap_start[l]. */
  int *eff_start, *eff_node;
  double *eff_T;
  int *emap_start, *emap;

  /* A, upper triangle, CSC over free DOFs; values live in A->x. */
  cholmod_common cm;
  cholmod_sparse *A;
  cholmod_factor *L;
  /* Reuse across steps (reuse.c): L factorises the assembled A
   * (factor_current), or an earlier A and serves as a preconditioner. */
  int factor_current;
  int factor_age;          /* steps since the factorisation (0: factorised in this step) */
  int refactor_due;        /* the renewal rule asks for a factorisation at the next step */
  double cycle_cost;       /* flops: the last factorisation and the reuse's extra solves since */
  int cycle_steps;         /* steps of the cycle (nh_system_account) */
  double flops_factor;     /* one numeric factorisation (CHOLMOD's count at analysis) */
  double flops_solve;      /* one solve: two triangular solves with L */
  double flops_iteration;  /* one PCG iteration: a solve and a product with A */
  cholmod_factor *L_aside; /* benchmarks: the factor timed aside (NH_TIME_FACTOR) */
  /* What A was assembled from (u, and cM, cK), at the last assembly and at
   * the one the factor L factorises: a continued run assembles and factorises
   * that A again (nh_system_reuse_load), bit for bit the same L. */
  double *u_assembled, *u_factored; /* 3 per node */
  double c_assembled[2], c_factored[2];
  double *pcg[4]; /* n_free each: PCG work */

  int *scatter; /* 576 per plain leaf (leaf order): position in A->x of K_e[r][c], -1 if not stored
                 */
  int n_colours;
  int *colour_start; /* n_colours + 1 */
  int *colour_leaf;  /* leaf indices grouped by colour */

  /* Lazy element tangents (assemble.c): the tangent of leaf l in A is that
   * of frame[18 l ..] (its rotation R and, B-bar, cof F̄ when last updated);
   * frame_new and updated: the current assembly's frames and which leaves it
   * updates. A holds cM M + cK K̃ for a_cM, a_cK when a_valid. */
  double lazy_tolerance; /* solver.lazy_rotation (0: exact) */
  double *frame, *frame_new;
  unsigned char *updated;
  int a_valid;
  double a_cM, a_cK;
  int lazy_updates; /* leaves whose tangent the last assembly updated */
  int threads;      /* OpenMP threads of the last assembly (0: all), W's build uses them too */

  /* Constraint rows J (m x n_free, stored as Jᵀ: n_free x m) solved through
   * the compliance W = J A⁻¹ Jᵀ (Algorithm 1); W and its Cholesky factor are
   * rebuilt after each numeric factorisation. */
  int n_rows;
  cholmod_sparse *Jt;
  double *W; /* m x m, column-major; after the build, its Cholesky factor */
  int W_valid;
  double t_constraints; /* seconds spent on W and λ since the last reset */
  double *lambda_total; /* m: Σ λ since the last reset (the rows' reaction in Newton) */

  /* Work vectors for cholmod_solve2 and the integrators. */
  cholmod_dense *B, *X, *Y, *E;
  double *work[4];  /* 3 per node each */
  double *fwork[2]; /* n_free each */
};

/* Reuse of factorisations (reuse.c): a solve that misses its tolerance after
 * NH_PCG_MAX iterations, or constraint forces after NH_OUTER_MAX corrections,
 * factorise at once; a factor is renewed after NH_REFACTOR_MAX_AGE steps in
 * any case. */
enum { NH_PCG_MAX = 40, NH_OUTER_MAX = 10, NH_REFACTOR_MAX_AGE = 200 };

/* The time of one flop of a triangular solve or sparse product relative to
 * one flop of CHOLMOD's supernodal factorisation: measured 7.4 on the needle
 * phantom at 28611 DOFs and 7.5 on the skull case at 18786 (one BLAS
 * thread; docs/performance.md, "When to factorise", where 20 and 5 are
 * compared); the mean cost of a cycle is flat near its optimum. */
#define NH_SOLVE_FLOP_COST 8.0

/* After a step with reuse on: the renewal rule, by operation counts, from
 * the step's PCG iterations with the reused factor, its outer corrections
 * and their constraint solves (st: 0 on a step that factorised). */
void nh_system_account(nh_system *s, const nh_step_stats *st);

/* Before a step's solves, after assembly: factorise A unless in->reuse is on
 * and the current factor may still serve (see reuse.c); the time spent is
 * added to st->t_factor, and st->t_factor_reference (and t_aside) set.
 * Fails as nh_system_factor. */
int nh_system_prepare(nh_system *s, const nh_integrator *in, nh_step_stats *st);

/* Solve A x = b: directly when the factor is current, else by PCG with the
 * factor as preconditioner to `tolerance` (relative, in the M⁻¹-norm), and if
 * that fails in NH_PCG_MAX iterations, by a new factorisation (its time added
 * to *t_factor). iterations (may be NULL): the PCG iterations used. */
int nh_system_solve_reuse(nh_system *s, const double *b, double *x, double tolerance,
                          int *iterations, double *t_factor);

/* PCG on A x = b preconditioned by the factor (M), started from x₀ = M⁻¹ b,
 * or from x as given when guess != 0, stopped at √(rᵀM⁻¹r) <= tolerance ·
 * √(bᵀx₀) (≈ √(bᵀA⁻¹b) for a good start); at most max_iterations.
 * Fails with NH_ERR_NUMERIC (not converged, or A not positive definite
 * along a search direction). */
int nh_system_pcg(nh_system *s, const double *b, double *x, int guess, double tolerance,
                  int max_iterations, int *iterations);

/* W += J A⁻¹ Jᵀ (Algorithm 3) for rows given as Jᵀ (n_free x m, CSC, sorted);
 * W dense column-major m x m. A must be factorised. Fails with
 * NH_ERR_MEMORY, NH_ERR_NUMERIC (CHOLMOD) or a stop request. */
int nh_system_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W);
/* The same through CHOLMOD's sparse solves (cholmod_spsolve), for any
 * factor: the path of a simplicial factor, and an independent one for the
 * tests (tests/test_compliance.c). */
int nh_system_compliance_add_spsolve(nh_system *s, cholmod_sparse *Jt, double *W);

#endif
