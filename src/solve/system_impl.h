/* system_impl.h — the layout of nh_system, private to the solve module. */
#ifndef NH_SYSTEM_IMPL_H
#define NH_SYSTEM_IMPL_H

#include "solve/solve.h"
#include <cholmod.h>

struct nh_system {
  double residual_floor; /* the last nh_dynamic_residual's round-off level (relative) */
  int residual_dof;      /* the last nh_dynamic_residual's largest entry: its nodal DOF, or −1 */
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
   * plain leaf), ascending, T (8 x k) kept as its nonzeros below. */
  int *eff_start, *eff_node;
  /* T's nonzeros, leaf by leaf [nz_start[l], nz_start[l+1]) in corner
   * order (T is fixed while the system lives, so assemble.c's Tᵀ Aₑ T does
   * not search T at every assembly): corner nz_corner of effective node
   * nz_node (its index in the leaf's list) with weight nz_w; nz_first marks
   * the node's first nonzero. */
  int *nz_start, *nz_corner, *nz_node, *nz_first;
  double *nz_w;

  /* A, upper triangle, CSC over free DOFs; values live in A->x. */
  cholmod_common cm;
  cholmod_sparse *A;
  cholmod_factor *L;
  /* Reuse across steps (reuse.c): L factorises the assembled A
   * (factor_current), or an earlier A and serves as a preconditioner. */
  int factor_current;
  int not_posdef;         /* the last nh_system_factor stopped at a pivot <= 0 */
  int factor_age;         /* steps since the factorisation (0: factorised in this step) */
  int refactor_due;       /* the renewal rule asks for a factorisation at the next step */
  double cycle_cost;      /* flops: the last factorisation and the reuse's extra solves since */
  int cycle_steps;        /* steps of the cycle (nh_system_account) */
  double flops_factor;    /* one numeric factorisation (CHOLMOD's count at analysis) */
  double flops_solve;     /* one solve: two triangular solves with L */
  double flops_iteration; /* one PCG iteration: a solve and a product with A */
  /* factorisations after the step (nh_system_solve_rows: the goal
   * estimate's duals), until nh_system_take_later_factorisations */
  int later_factorised;
  /* nh_system_expect_factor_later: this step's solution will be factorised
   * (the goal estimate's duals), which renews the cycle; a renewal due at
   * the step's start is left to it */
  int factor_follows;
  /* Across a mesh change (inherit.c): the old mesh's factor extended to the
   * new unknowns, the preconditioner while L is NULL; rows_hint: the
   * constraint rows of the coming step (coupled.c), whose W₀ it would cost */
  struct nh_inherited *inh;
  int rows_hint;
  /* the PCG iterations of the last step that solved with an inherited
   * factor (0: none yet), carried from system to system across mesh
   * changes: the gate's estimate of what the next one costs (reuse.c);
   * inh_step: this step solves with it (nh_system_account records it) */
  int inherit_its, inh_step;
  cholmod_factor *L_aside; /* benchmarks: the factor timed aside (NH_TIME_FACTOR) */
  /* What A was assembled from (u, and cM, cK), at the last assembly and at
   * the one the factor L factorises: a continued run assembles and factorises
   * that A again (nh_system_reuse_load), bit for bit the same L. */
  double *u_assembled, *u_factored; /* 3 per node */
  double c_assembled[2], c_factored[2];
  double *pcg[4]; /* n_free each: PCG work */

  /* Where a leaf's matrix goes (Aₑ, 24 x 24, of a plain leaf; Tᵀ Aₑ T,
   * 3k x 3k, of one with a hanging corner): the stored entries only, as
   * pairs (r, position in A->x) of the row-major index r, ascending, for
   * leaf l from pair[2 pair_start[l]] to pair[2 pair_start[l + 1]]. */
  size_t *pair_start;
  int *pair;
  int n_colours;
  int *colour_start; /* n_colours + 1 */
  int *colour_leaf;  /* leaf indices grouped by colour */

  /* Lazy element tangents (assemble.c): the tangent of leaf l in A is that
   * of frame[NH_HEX_FRAME l ..] (its rotation R and, B-bar, cof F̄ when last updated);
   * frame_new and updated: the current assembly's frames and which leaves it
   * updates. A holds cM M + cK K̃ for a_cM, a_cK when a_valid. */
  double lazy_tolerance; /* solver.lazy_rotation (0: exact) */
  int consistent; /* nh_system_set_tangent: A holds the consistent tangent's symmetric part */
  double *skew;   /* consistent, when kept: the skew part's upper triangle on A's pattern */
  double *frame, *frame_new;
  unsigned char *updated;
  int a_valid;
  double a_cM, a_cK;
  /* nh_system_set_jacobian: the dynamic Newton's exact Jacobian (jac_v the
   * nodal velocities of the damping force's variation, NULL: unset) */
  const double *jac_v;
  double jac_cG, jac_cD;
  int lazy_updates; /* leaves whose tangent the last assembly updated */
  /* The serial group's work (assemble.c): its leaves' results computed in
   * parallel into `group` (group_cap doubles), then added in leaf order;
   * `expand` holds each thread's expansion work (expand_slot doubles). */
  double *group, *expand;
  size_t group_cap, expand_slot;
  int expand_threads;
  /* The last assembly's u, v, f_int and K̃ v (assemble.c): one repeated at
   * the same u and v (a step's first, after the previous step's residual
   * assembly) hands them back. kept: 0 none, 1 f_int, 2 f_int and K̃ v. */
  double *last_u, *last_v, *last_f, *last_kv; /* 3 per node each */
  int last_kept;
  double last_tolerance;
  /* The tissue part of W₀ = J A₀⁻¹ Jᵀ last built (coupled.c), with the
   * factorisation it came from (factor_serial, counted by nh_system_factor)
   * and its rows' tissue nodes and tool elements: a reused factor's outer
   * corrections take it again while those are the same. */
  int factor_serial;
  double *w0;
  int w0_m, w0_slots, w0_serial; /* w0_serial 0: none kept */
  int *w0_key;                   /* m + 1 starts, the nodes, 4 per row (tool, elem, tool2, elem2) */
  int threads; /* OpenMP threads of the last assembly (0: all), W's build uses them too */

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

/* ---- where and why a solve failed (diagnose.c) ---- */
/* nh_rigid (solve.h) of the assembled A at displacements u; b: the
 * step's residual (NULL: turn not computed). Uses the PCG work vectors 0
 * and 1. */
nh_rigid nh_system_rigid(nh_system *s, const double *u, const double *b);
/* The likely causes of a failed solve, as nh_system_diagnose names them. */
typedef enum {
  NH_CAUSE_NONE,
  NH_CAUSE_NOT_HELD, /* a rigid mode meets no stiffness: A is singular */
  NH_CAUSE_WEAK,     /* a rigid mode is held by a support far softer than the tissue */
  NH_CAUSE_INVERTED, /* an inverted cell at the node */
  NH_CAUSE_SLIVER    /* a cut cell with a tiny tissue fraction at the node */
} nh_cause;
/* Append to the message in buf (size bytes in all) where a failure sits:
 * " at node N, c, rest position (...)" for the nodal DOF `dof` (-1: none),
 * the cells around it (tissue fraction, the fixed region tying it,
 * inverted at displacements u), the step's constraint rows at the node
 * (rows may be NULL: not named), the smallest tissue fraction, the softest
 * rigid mode (rigid: as measured at the step's start, NULL: of the
 * assembled A now) and the likely cause, which it returns. Uses the PCG
 * work vectors 0 and 1. */
nh_cause nh_system_diagnose(nh_system *s, const double *u, int dof, const nh_rigid *rigid,
                            const nh_rows *rows, char *buf, size_t size);
/* nh_system_where (solve.h) with the rigid modes as measured at the step's
 * start (rigid; NULL: of the assembled A now), returning the cause. */
nh_cause nh_system_where_field(nh_system *s, const double *u, const double *f, const nh_rows *rows,
                               const nh_rigid *rigid, char *msg, size_t size);

/* ---- the preconditioner across a mesh change (inherit.c) ---- */
typedef struct nh_inherited nh_inherited;
void nh_inherit_free(nh_system *s);
/* Before the first solve on the mesh: factorise the new unknowns' block of
 * the assembled A; a block that is not positive definite drops the
 * inherited preconditioner (the caller then factorises A). NH_ERR_MEMORY. */
int nh_inherit_ready(nh_system *s);
/* z = B r, the two-level preconditioner (inherit.c's header). */
int nh_inherit_apply(nh_system *s, const double *r, double *z);
/* W += J B Jᵀ for rows given as Jᵀ (n_free x m): one application per row. */
int nh_inherit_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W);

/* Reuse of factorisations (reuse.c): a solve that misses its tolerance after
 * NH_PCG_MAX iterations, or constraint forces after NH_OUTER_MAX corrections,
 * factorise at once; a factor is renewed after NH_REFACTOR_MAX_AGE steps in
 * any case. */
enum { NH_PCG_MAX = 40, NH_OUTER_MAX = 10, NH_REFACTOR_MAX_AGE = 200 };

/* ρ, the time of one flop of a triangular solve or sparse product relative
 * to one flop of CHOLMOD's supernodal factorisation, for a factorisation of
 * F flops (reuse.c): the factorisation's dense blocks grow with the system
 * and run faster per flop, the streamed solves do not. Measured (one BLAS
 * thread; docs/performance.md, "When to factorise"): about 1 at F ≈ 6e6
 * (the phantom's 650–855 unknowns), 2.9–3.5 at F ≈ 1.15e8 (dbs-skull's
 * goal mesh, 2100–2500 unknowns), 7.4–7.5 at 5.3e9 and 1.2e10 (18786 and
 * 28611 unknowns; 8 is used there, as before); linear in log F between
 * those points, constant beyond them. */
double nh_solve_flop_cost(double flops_factor);

/* After a step with reuse on: the renewal rule, by operation counts, from
 * the step's PCG iterations with the reused factor, its outer corrections
 * and their constraint solves (st: 0 on a step that factorised). */
void nh_system_account(nh_system *s, const nh_step_stats *st);

/* Factorise or reuse (reuse.c): THE place where a step decides, after its
 * assembly, whether A is factorised (the rules: reuse.c's header).
 * NH_FACTOR_STEP: a step of nh_step_coupled, every time or, with in->reuse
 * (solver.refactor: auto), while a recent factor may serve; NH_FACTOR_NEWTON:
 * an iteration of the static Newton, unless the factor is already this A's.
 * The time spent is added to st->t_factor, a factorisation counted in
 * st->factorised and timed in st->t_factor_reference (and t_aside set).
 * Fails as nh_system_factor. */
typedef enum { NH_FACTOR_STEP, NH_FACTOR_NEWTON } nh_factor_rule;
int nh_system_factor_or_reuse(nh_system *s, const nh_integrator *in, nh_factor_rule rule,
                              nh_step_stats *st);

/* Factorise the step's A after the step (counted in later_factorised) and
 * start a new cycle of the renewal rule. Fails as nh_system_factor. */
int nh_system_factor_later(nh_system *s);

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

/* The threads of a team whose tasks call BLAS on one thread each (the
 * compliance W's build, many-column solves): solver.threads, else every
 * core; 1 when the BLAS has threads of its own (OPENBLAS_NUM_THREADS > 1). */
int nh_system_blas_team(const nh_system *s);
/* nh_system_solve_many of two blocks as one of ncol1 + ncol2 columns
 * (b1 -> x1, then b2 -> x2), in the chunks of their total. */
int nh_system_solve_two(nh_system *s, int ncol1, const double *b1, double *x1, int ncol2,
                        const double *b2, double *x2);
/* W += J A⁻¹ Jᵀ (Algorithm 3) for rows given as Jᵀ (n_free x m, CSC, sorted);
 * W dense column-major m x m. A must be factorised. Fails with
 * NH_ERR_MEMORY, NH_ERR_NUMERIC (CHOLMOD) or a stop request. */
int nh_system_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W);
/* The same through CHOLMOD's sparse solves (cholmod_spsolve), for any
 * factor: the path of a simplicial factor, and an independent one for the
 * tests (tests/test_compliance.c). */
int nh_system_compliance_add_spsolve(nh_system *s, cholmod_sparse *Jt, double *W);

/* ---- constraint rows, their tissue and tool parts (rows.c) ---- */

/* Row i's tool parts: side 0 the tool (rows->tool), side 1 the second tool
 * of a row between two tools (rows->tool2). Its element on that side. */
int nh_row_elem(const nh_rows *rows, int i, int side);
/* The part of side `side` as 12 coefficients on the element's DOFs: −nᵀ J
 * (side 0), +nᵀ J2 (side 1). */
void nh_row_tool_coef(const nh_rows *rows, int i, int side, double c[12]);
/* That part applied to its tool's velocities v (all DOFs). */
double nh_row_tool_rate(const nh_rows *rows, int i, int side, const double *v);
/* Add that part's coefficients to a free-DOF column of its tool (base
 * dropped). */
void nh_row_tool_column(const nh_rows *rows, int i, int side, double *col);
/* The tissue part of the rows as J_tᵀ over the unknowns (CSC, n_free x m,
 * sorted); mark: n_free ints, all −1 on entry and on return. NULL when out
 * of memory. */
cholmod_sparse *nh_rows_tissue_jt(nh_system *s, const nh_rows *rows, int *mark);
/* col = J_tᵀ λ (n_free values): the rows' forces on the tissue's unknowns. */
void nh_rows_tissue_force(const cholmod_sparse *Jt, const double *lambda, double *col, int n_free);
/* The tissue's end-of-step rates of the rows for a velocity update dv (free
 * DOFs), plus `base` (the tools' rates and g/h): out_i = base_i +
 * n_i · Σ_a N_a (v + P dv)_a; full: 3 per node scratch. */
void nh_rows_tissue_rates(const nh_system *s, const nh_rows *rows, const double *v,
                          const double *dv, const double *base, double *full, double *out);

/* ---- the tissue's phases of one step (step.c) ----
 * Shared by the coupled step (coupled.c: dynamic, and each iteration of the
 * quasi-static coupled Newton), the dynamic step's Newton corrections and
 * the static Newton (integrate.c). */

/* Begin: this step's hanging-node reactions, constraint time and lazy
 * tangents' count start from zero; the lazy tolerance is in->lazy_rotation. */
void nh_step_begin(nh_system *s, const nh_integrator *in);
/* Assemble A and the right-hand side b over the unknowns at (u, v):
 * dynamic, A = (1 + hα) M + (hβ + h²) K(u) and
 * b = Pᵀ [h (f_ext − f_int(u) − α M v − β K v) − h² K v] (the seed's Eq. 13);
 * statics (v unused, may be NULL), A = K(u), b = Pᵀ (f_ext − f_int(u)) and
 * *f_scale = max(|f_ext|, |f_int|) (the residual's scale). Uses the
 * system's work vectors 0-2. A stop request leaves A partial: callers ask
 * nh_stop_check. */
void nh_step_assemble(nh_system *s, const nh_integrator *in, int statics, const double *f_ext,
                      const double *u, const double *v, double *b, double *f_scale);
/* Free solve: x = A⁻¹ b with the step's factor (PCG when it is an earlier
 * A's; the hanging-node rows' multipliers, Algorithm 1, when the system
 * carries them). Adds the PCG iterations and any factorisation time to st.
 * Fails as nh_system_solve_reuse / nh_system_solve_constrained. */
int nh_step_free_solve(nh_system *s, const nh_integrator *in, const double *b, double *x,
                       nh_step_stats *st);
/* Update the tissue by x over the unknowns (prolonged into the work vector
 * 3, where the step's nodal update stays): statics, u ← u + P x; dynamic,
 * v ← v + P x, u ← u + h v. */
void nh_step_update(nh_system *s, int statics, double h, const double *x, double *u, double *v);

/* ---- the consistent tangent (assemble.c) and its LU path (unsymmetric.c) ---- */

/* The element tangent in A: NH_TANGENT_COROTATIONAL (the default of a new
 * system: dynamic steps, the coupled quasi-static step) R K₀ Rᵀ (+ κ V b bᵀ),
 * symmetric positive semi-definite; or NH_TANGENT_CONSISTENT (the static
 * Newton, nh_solve_static), the exact derivative of the internal force with
 * the variations of R and of B-bar's b (fem/hex.c, docs/theory.md §2), of
 * which A holds the symmetric part S (and skew, when kept, the rest). A
 * change starts the next assembly afresh. */
typedef enum { NH_TANGENT_COROTATIONAL = 0, NH_TANGENT_CONSISTENT = 1 } nh_tangent;
void nh_system_set_tangent(nh_system *s, nh_tangent tangent);

/* The dynamic step's exact Jacobian (docs/theory.md §3, "Newton iterations
 * in the dynamic step"): while v != NULL, an assembly with the consistent
 * tangent puts into A, per leaf,
 *     cM Mₑ + cK Kₑ,corot + cG (Kₑ − Kₑ,corot) + cD ∂(Kₑ,corot(u) vₑ)/∂u
 * (cK = hβ + h², cG = h², cD = h²β: the damping force β K(u) v with the
 * corotational K, and its variation, over the nodal velocities v, 3 per
 * node, which the caller keeps alive) instead of cM Mₑ + cK Kₑ; every such
 * assembly is afresh. v = NULL: back to the plain assembly. */
void nh_system_set_jacobian(nh_system *s, double cG, double cD, const double *v);

/* Keep the skew-symmetric part N of the consistent tangent beside A (on A's
 * upper-triangle pattern) from the next assembly on; A holds the symmetric
 * part S, so the tangent is S + N. */
int nh_system_keep_skew(nh_system *s);
/* x = (S + N)⁻¹ b by UMFPACK's LU of the full matrix (no multiplier rows);
 * *t_factor (may be NULL) receives the factorisation's time. */
int nh_system_solve_lu(nh_system *s, const double *b, double *x, double *t_factor);
/* Factorise or reuse (nh_system_factor_or_reuse) A as assembled; when A
 * holds the consistent tangent's symmetric part S and S is not positive
 * definite, the corotational tangent at u instead (assembled here; the
 * system stays set to the consistent tangent). Used by the static Newton
 * with hanging-node rows and the coupled quasi-static step (integrate.c). */
int nh_system_factor_symmetric(nh_system *s, const nh_integrator *in, const double *u,
                               nh_factor_rule mode, nh_step_stats *st);

#endif
