/* solve — the tissue's linear system and its time integrators
 * (docs/theory.md §3-4, the seed's Eqs. 11-14).
 *
 * nh_system owns the map from nodal DOFs to free unknowns (fixed DOFs are
 * eliminated), the sparsity pattern of A (upper triangle, CSC, free DOFs
 * only), a per-cell scatter map, a colouring of the cells for race-free
 * parallel assembly, and the CHOLMOD factor. The symbolic analysis is done
 * once per pattern (nh_system_create); every nh_system_factor is numeric
 * only. */
#ifndef NH_SOLVE_H
#define NH_SOLVE_H

#include "beam/beam.h"
#include "core/core.h"
#include "fem/fem.h"
#include "mesh/mesh.h"

typedef struct nh_system nh_system;

/* fixed[i] of a node: 0 free; otherwise all three components are fixed,
 * unless the bit NH_FIX_AXES is set: then bit k (1 << k) fixes component k
 * (tissue.fixed's `axes`). */
#define NH_FIX_AXES 8
static inline int nh_fixed_component(const unsigned char *fixed, int i, int k) {
  return fixed && fixed[i] && (!(fixed[i] & NH_FIX_AXES) || (fixed[i] >> k) & 1);
}

/* How the nodes of a changed mesh relate to those before the change (the
 * refinement's Eq. 17 and the coarsening's injection, adapt/refine.c): the
 * new node v's values are Σ weight[q] · (old values of node[q]) over q in
 * start[v] .. start[v+1]. A linear map of nodal fields, old → new. */
typedef struct {
  int n_old, n_new;
  int *start; /* n_new + 1 */
  int *node;  /* old node indices */
  double *weight;
  int cap; /* room of node and weight */
} nh_node_transfer;
void nh_node_transfer_free(nh_node_transfer *t);

/* After a mesh change with solver.refactor auto: let the new system `sys`
 * (created, not yet assembled) precondition with the factor of `old`, the
 * system of the mesh before the change, through the nodal transfer t
 * (solve/inherit.c): its first steps solve by PCG instead of factorising.
 * The factor moves from old to sys (old is then only to be destroyed), with
 * the renewal rule's state. Does nothing (the first step factorises) when old
 * has no factor of its own, either system has hanging-node rows, or t does
 * not fit. NH_ERR_MEMORY. */
int nh_system_inherit(nh_system *sys, nh_system *old, const nh_node_transfer *t);
/* Whether sys preconditions with an inherited factor. */
int nh_system_inherited(const nh_system *sys);
/* Drop an inherited preconditioner: the next step factorises (a checkpoint
 * cannot hold the old mesh's factor, so one is not carried past it). */
void nh_system_inherit_drop(nh_system *sys);

/* Build the DOF map, pattern, scatter maps and colouring of the leaves of
 * `tissue->mesh`; fixed[i] fixes components of node i (above). Hanging
 * nodes (may be NULL) are eliminated: u = P u_free, A = Pᵀ A P.
 * Fails with NH_ERR_INPUT if every DOF is fixed, NH_ERR_MEMORY. */
int nh_system_create(const nh_tissue *tissue, const unsigned char *fixed, const nh_hanging *hanging,
                     nh_system **out);
void nh_system_destroy(nh_system **sys);

int nh_system_free_dofs(const nh_system *sys);
/* Number of colours of the cell colouring. */
int nh_system_colours(const nh_system *sys);

/* Assemble A = cM M + cK K̃ (K̃ the corotational tangent at nodal
 * displacements u, each leaf's kept from an earlier assembly while its
 * rotation changed by at most the lazy tolerance: solve/assemble.c) into the
 * system, the internal force f_int (3 per node, all DOFs, always at u) and,
 * if v != NULL, the product Kv = K̃ v (3 per node). A keeps its values, and a
 * factorisation of it stays current, when no leaf's tangent changed and cM,
 * cK are those of the last assembly. threads: 0 = OpenMP default, 1 =
 * serial (in the same colour order, so the result is bitwise that of any
 * thread count), n = n threads. */
void nh_system_assemble(nh_system *sys, const double *u, const double *v, double cM, double cK,
                        double *f_int, double *Kv, int threads);
/* The lazy tolerance τ (solver.lazy_rotation, >= 0; 0 = exact, the default
 * of a new system): a leaf's tangent is rebuilt when its rotation (or
 * B-bar's cof F̄) moved by more than τ in the Frobenius norm. */
void nh_system_set_lazy(nh_system *sys, double tolerance);
/* Leaves whose tangent the assemblies since nh_system_lazy_reset rebuilt. */
int nh_system_lazy_updates(const nh_system *sys);
void nh_system_lazy_reset(nh_system *sys);
/* The frames (NH_HEX_FRAME doubles per leaf, in leaf order; fem.h) of the
 * last computed assembly if it was of this tissue at this u (bitwise), else
 * NULL (also for sys NULL): their rotations R are then those
 * nh_hex_corotated gives every leaf at u (its centre gradients
 * nh_tissue_g0). sys must be the system of the tissue's current mesh (a
 * mesh change builds a new one; counts are checked, not the leaves). Valid
 * until the next assembly. */
const double *nh_system_frames_at(const nh_system *sys, const nh_tissue *tissue, const double *u);

/* cholmod_factorize(A, L, cm) with the OpenMP teams CHOLMOD opens inside it
 * (its per-supernode loops) on one thread: with the BLAS on one thread
 * those loops only copy and clear, and waking a sleeping team for each cost
 * up to 3x the factorisation (docs/performance.md, "Threads"). Returns
 * cholmod_factorize's result; inside a parallel region it only calls it. */
struct cholmod_sparse_struct;
struct cholmod_factor_struct;
struct cholmod_common_struct;
int nh_cholmod_factorize(struct cholmod_sparse_struct *A, struct cholmod_factor_struct *L,
                         struct cholmod_common_struct *cm);

/* Numeric Cholesky factorisation of the assembled A (symbolic analysis on
 * first use). Fails with NH_ERR_NUMERIC if A is not positive definite
 * (CHOLMOD's common->status is checked) — message names the column. */
int nh_system_factor(nh_system *sys);

/* The state of factor reuse (solver.refactor: auto; solve/reuse.c) for a
 * checkpoint: appended to b (a failed allocation is left in b->failed). */
void nh_system_reuse_save(const nh_system *sys, nh_bytes *b);
/* Restore what nh_system_reuse_save wrote, into a system built on the same
 * mesh: a saved factor is made again from the A it factorised (assembled
 * with `threads`), then A is assembled at the last assembly's u (the lazy
 * tangents' frames), so the continued run assembles, renews and reuses
 * factors exactly as the uninterrupted one. NH_ERR_INPUT (malformed), NH_ERR_NUMERIC (as
 * nh_system_factor), NH_ERR_INTERRUPTED, NH_ERR_MEMORY. */
int nh_system_reuse_load(nh_system *sys, const unsigned char *data, size_t size, int threads);

/* Solve A x = b for free-DOF vectors (length nh_system_free_dofs). */
int nh_system_solve(nh_system *sys, const double *b, double *x);
/* Solve A X = B for ncol free-DOF vectors at once (column-major, n_free x
 * ncol each) with the factor of the last nh_system_factor: the columns in
 * chunks of at least 16 (up to 4, fixed by ncol alone: the same bits on any
 * number of threads), each chunk one pass of the triangular solves, the
 * chunks on the solver's threads (cholesky.c). NH_ERR_MEMORY,
 * NH_ERR_NUMERIC. */
int nh_system_solve_many(nh_system *sys, int ncol, const double *b, double *x);

/* Constraint rows tying each hanging node to its masters, u_h = Σ w u_m,
 * enforced by Lagrange multipliers through the compliance W = J A⁻¹ Jᵀ
 * (Algorithms 1-3) instead of elimination: create the system with
 * hanging = NULL, then set the rows. h = NULL removes them. */
int nh_system_set_hanging_rows(nh_system *sys, const nh_hanging *h);
/* Number of constraint rows. */
int nh_system_constraint_rows(const nh_system *sys);
/* Solve A x = b + Jᵀλ with J x = 0 (plain solve without rows); λ is added
 * to the running total of multipliers. */
int nh_system_solve_constrained(nh_system *sys, const double *b, double *x);
/* Zero the running total of multipliers / add its reaction Jᵀ Σλ to a
 * free-DOF vector (the constrained residual of a Newton iteration is
 * r + Jᵀ Σλ). */
void nh_system_reset_multipliers(nh_system *sys);
void nh_system_add_reactions(const nh_system *sys, double *b);

/* y = A x for free-DOF vectors, with the assembled A. */
void nh_system_apply(const nh_system *sys, const double *x, double *y);

/* Restrict a nodal vector (3 per node) to the unknowns, b = Pᵀ full (a
 * hanging node's entry goes to its masters); and prolong, full = P part
 * (every entry: fixed ones become 0, hanging ones their masters'
 * interpolation). Without hanging nodes these are gather and scatter. */
void nh_system_gather(const nh_system *sys, const double *full, double *free_part);
void nh_system_scatter(const nh_system *sys, const double *free_part, double *full);

/* Timings and counts of one step. */
typedef struct {
  double t_assemble, t_factor, t_solve; /* s (t_solve excludes t_constraints) */
  double t_constraints;                 /* s: compliance W and multipliers */
  int iterations;                       /* Newton iterations (static), 1 (dynamic) */
  double residual;       /* relative residual reached: static Newton; dynamic: of the implicit-Euler
                            equations at the end of the step (nh_dynamic_residual) */
  double residual_floor; /* dynamic: the round-off level of that residual
                            (nh_system_residual_floor), 0 static */
  int residual_dof;      /* dynamic: the nodal DOF (3 node + axis) of that residual's largest
                            entry, −1 when unknown */
  int factorised;        /* numeric factorisations of A in the step */
  int pcg_iterations;    /* PCG iterations of the step's solves with a reused factor */
  int corrections;       /* outer constraint corrections with a reused factor (0: exact W) */
  int tangent_updates;   /* leaves whose tangent the step's assemblies rebuilt (solve/assemble.c) */
  int load_steps; /* static: the equal load steps the step was solved in (1, or 2, 4, ... after
                     a split: sim.c, nh_sim_solve_static); 1 dynamic */
  /* s: one numeric factorisation of this step's A — the one done, or with
   * nh_integrator.time_factor one done aside (and discarded) on a step that
   * reused the factor; 0 otherwise. t_aside: the time that aside cost (copy
   * included), excluded from the phases and to be excluded from the step. */
  double t_factor_reference, t_aside;
  /* the operations of the constraint solves of the corrections after the
   * first (nh_mcp_stats.flops, flops_dense): what reuse costs on top of the
   * exact path's one constraint solve */
  double correction_flops, correction_flops_dense;
  /* static: the step failed with a diagnosis (a singular tangent, no
   * progress: nh_solve_static) that solving it again in load steps cannot
   * change */
  int diagnosed;
} nh_step_stats;

/* Integrator settings. */
typedef struct {
  double dt;          /* time step h, s */
  double alpha, beta; /* Rayleigh damping C = α M + β K */
  double
      tolerance; /* static: relative residual; dynamic with reuse: each solve's (nh_system_pcg) */
  int max_iterations;      /* static: Newton iterations */
  int threads;             /* assembly threads (0 = all) */
  int reuse;               /* dynamic: 1 = reuse a recent factorisation as a preconditioner
                              (solver.refactor: auto, docs/performance.md), 0 = factorise every step;
                              the solves then stop at `tolerance` (relative, see nh_system_pcg) */
  int time_factor;         /* benchmarks: also time a factorisation of A on steps that reuse one
                              (nh_step_stats.t_factor_reference; env NH_TIME_FACTOR=1) */
  int newton_iterations;   /* dynamic (solver.newton): Newton iterations after the linearised
                              step while the residual exceeds newton_tolerance (0: none);
                              < 0: only a step left above NH_UNSOLVED_LINEAR iterates, at most
                              NH_DYNAMIC_NEWTON_MAX times (nh_step_coupled) */
  double newton_tolerance; /* dynamic: relative residual */
  double lazy_rotation;    /* lazy tangents' tolerance τ (solver.lazy_rotation; 0 = exact) */
  int quasi_static;        /* nh_step_coupled: one Newton iteration of the static problem with
                              constraint rows instead of a backward-Euler step (see there) */
  int consistent_tangent;  /* quasi_static: the tissue's block is the consistent tangent's
                              symmetric part S (Cholesky; the corotational one where S is
                              indefinite), not R K₀ Rᵀ (docs/theory.md §3) */
  int measure_supports;    /* quasi_static without rows: measure the supports at the
                              iteration's start (nh_coupled_stats.supports) */
} nh_integrator;

/* A dynamic step whose relative residual (below) stays above this bound
 * after its one linearisation did not solve its equations (docs/outputs.md,
 * `unsolved`): with in->newton_iterations < 0 (no solver.newton), such a
 * step takes Newton iterations (nh_step_coupled), at most
 * NH_DYNAMIC_NEWTON_MAX, towards newton_tolerance. */
#define NH_UNSOLVED_LINEAR    0.5
#define NH_DYNAMIC_NEWTON_MAX 8
/* The relative residual below which a Newton iteration (the static Newton,
 * the dynamic step's, the quasi-static step with constraint rows) takes the
 * consistent tangent (docs/theory.md §3, "Quasi-static Newton"): from far
 * off the corotational one does not diverge where the exact one may. */
#define NH_NEWTON_CONSISTENT 0.1

/* The relative residual of the implicit-Euler equations of the step just
 * taken (docs/theory.md §3): with v the end velocity, dv = v − v_start (3
 * per node), R = h (f_ext − f_int(u) − α M v − β K(u) v) − M dv + reactions
 * (the hanging-node rows' and `reaction`, the tools' Jᵀλ over the unknowns,
 * may be NULL), |R| / max(h |f_ext|, h |f_int|, |M dv|). Zero to round-off
 * for a linear problem; what the one linearisation missed otherwise.
 * Assembles A = (1 + hα) M + (hβ + h²) K(u) (ready to factor for a Newton
 * correction A δv = R) and leaves R over the unknowns in b. Uses the
 * system's work vectors 0-2 (dv must not be one of them). */
double nh_dynamic_residual(nh_system *sys, const nh_integrator *in, const double *f_ext,
                           const double *u, const double *v, const double *dv,
                           const double *reaction, double *b);
/* The round-off level of the last nh_dynamic_residual, relative like it: a
 * residual below it is as solved as the arithmetic allows (0 before any). */
double nh_system_residual_floor(const nh_system *sys);

/* One backward-Euler step with one linearisation (seed Eq. 13):
 *   A = (1 + hα) M + (hβ + h²) K,
 *   A dv = h (f_ext − f_int(u) − α M v − β K v) − h² K v,
 *   v ← v + dv,  u ← u + h v.
 * u (displacements), v: 3 per node (fixed DOFs keep their values, their v
 * stays 0);
 * f_ext: 3 per node. Fails with NH_ERR_NUMERIC (A not positive definite, or
 * a non-finite value). */
int nh_step_dynamic(nh_system *sys, const nh_integrator *in, const double *f_ext, double *u,
                    double *v, nh_step_stats *stats);

/* Quasi-static equilibrium f_int(u) = f_ext by Newton's method on
 * K du = f_ext − f_int(u), starting from u (fixed DOFs keep their values, so
 * prescribed boundary displacements are imposed by setting them in u). Converged
 * when |r| <= tolerance · max(|f_ext|, |f_int| over all DOFs, tiny).
 * Fails with NH_ERR_NUMERIC if it does not converge in max_iterations. */
int nh_solve_static(nh_system *sys, const nh_integrator *in, const double *f_ext, double *u,
                    nh_step_stats *stats);

/* ---- constraint forces: the mixed complementarity solve on W (mcp.c) ----
 * docs/interaction.md "Constraint solver"; the seed's Eqs. 5-9. */

/* The law of one constraint row i, with w = W λ + r:
 *   BILATERAL   w_i = 0, λ_i free;
 *   UNILATERAL  w_i ≥ 0, λ_i ≥ 0, w_i λ_i = 0 (contact normal, Eq. 5); with
 *               threshold > 0 also λ_i ≤ threshold, and w_i ≤ 0 once λ_i
 *               reaches it: the row yields (puncture normal, Eq. 6);
 *               threshold 0: no cap;
 *   FRICTION    |λ_i| ≤ mu |λ_normal| + threshold; stick (w_i = 0) inside the
 *               bound, slide (λ_i = ±bound, w_i λ_i ≤ 0) on it (Eqs. 7-9).
 * normal: index of a non-friction row whose force sets the Coulomb bound, or
 * -1 (bound = threshold); normal2: a second one (or -1), the bound then uses
 * the size |(λ_normal, λ_normal2)| of the two (a needle point's lateral
 * force: the tip and shaft rows of docs/interaction.md). threshold ≥ 0: cutting force or friction
 * per length × spacing. group: -1 for a one-dimensional friction row; for a disc pair (two tangent
 * rows g, g+1 sharing a normal, same mu and threshold) both rows have group = g and the bound
 * applies to |(λ_g, λ_g+1)|, with w = −ν λ, ν ≥ 0, on it.
 * Static and kinetic friction: mu is the kinetic coefficient; mu_static (a
 * value below mu, such as the 0 of a zero-initialised law, means mu) the
 * static one. sliding: in, whether the row slid at the previous step; a row
 * that did not starts with the static bound mu_static |λ_normal| + threshold
 * and, if its force reaches it, breaks away: its bound drops to the kinetic
 * one within the same solve. out: whether the row slides at the solution (on
 * its bound; a disc pair's two rows alike). one_sided: see the field. Fields other than kind (and
 * threshold, for a unilateral row) are ignored for non-friction rows. */
typedef enum { NH_ROW_BILATERAL = 0, NH_ROW_UNILATERAL = 1, NH_ROW_FRICTION = 2 } nh_row_kind;
typedef struct {
  nh_row_kind kind;
  int normal, normal2;
  double mu;
  double threshold;
  int group;
  double mu_static;
  int sliding;
  int one_sided; /* FRICTION, group -1: λ_i ∈ [0, bound] (w_i ≥ 0 at λ_i = 0): the row resists
                    one way only (a cutting tip resists advance, it does not pull) */
} nh_row_law;

/* The method that solved the constraints (nh_mcp_stats.method; steps.csv
 * constraint_method): none (no rows), the exact semismooth Newton method
 * alone, the projected sweeps alone, or both (the first method fell short
 * and the other one finished from its best iterate). */
typedef enum {
  NH_MCP_NONE = 0,
  NH_MCP_EXACT = 1,
  NH_MCP_SWEEPS = 2,
  NH_MCP_FALLBACK = 3
} nh_mcp_method;

/* What one constraint solve did. */
typedef struct {
  int iterations;   /* newton_steps + sweeps (0: the warm start was already converged) */
  int newton_steps; /* semismooth Newton steps (each one LU of the reduced Jacobian) */
  int sweeps;       /* projected Gauss-Seidel sweeps */
  nh_mcp_method method;
  double residual; /* dimensionless law violation of the returned λ (see nh_mcp_solve) */
  int n_stick;     /* friction rows strictly inside their bound */
  int n_slide;     /* friction rows on their bound (a zero bound counts as sliding) */
  int n_open;      /* unilateral rows with λ = 0 */
  /* its operations: streamed over the m x m W̃ (setup, Gauss-Seidel moves,
   * w̃ recomputed, block solves) and in dense Cholesky factorisations (LAPACK,
   * n³/3 each); counts, not times (the renewal rule of reuse.c uses them) */
  double flops, flops_dense;
} nh_mcp_stats;

/* Solve for the constraint forces λ of m rows: w = W λ + r obeys laws[i] for
 * every row (a mixed complementarity problem), by projected block Gauss-Seidel
 * on the diagonally scaled problem D W D (D = diag(W)^{-1/2}), the bilateral
 * rows as one exactly solved block.
 *   W: m×m compliance, symmetric positive semi-definite, dense, column-major;
 *   r: free violation J x_free (length m); laws: one per row;
 *   tolerance: on the residual max_i |λ̃_i − P_i(λ̃_i − w̃_i)| (scaled variables,
 *     P_i the projection onto row i's admissible set) divided by
 *     max|r̃| + max|W̃λ̃|; e.g. 1e-10;
 *   max_iterations: sweeps (0 only checks the warm start);
 *   lambda: in, the warm start (previous step, or zeros); out, the solution;
 *   stats (may be NULL): sweeps, residual, stick/slide/open counts;
 *   laws[i].sliding: in, the previous step's state; out, this solution's.
 * Fails with NH_ERR_INPUT (bad laws: a normal index out of range or pointing to
 * a friction row, negative or non-finite mu/threshold, an inconsistent disc pair; m < 0,
 * tolerance <= 0), NH_ERR_NUMERIC (non-finite W, r or warm start, a negative
 * diagonal of W, or not converged in max_iterations: λ then holds the best
 * iterate and stats says how far it got), NH_ERR_MEMORY. m = 0 succeeds. */
int nh_mcp_solve(int m, const double *W, const double *r, nh_row_law *laws, double tolerance,
                 int max_iterations, double *lambda, nh_mcp_stats *stats);
/* The same for a W that need not be symmetric (W = J A⁻¹ Jᵀ with an
 * unsymmetric A: the quasi-static step's beam blocks with their consistent
 * tangent), its symmetric part positive semi-definite: every row of W is
 * read as a row, the exact blocks (bilateral, subspace) are factorised by
 * LU with partial pivoting instead of Cholesky. On a symmetric W it returns
 * what nh_mcp_solve does up to round-off (docs/interaction.md, "Unsymmetric
 * compliance"). */
int nh_mcp_solve_unsymmetric(int m, const double *W, const double *r, nh_row_law *laws,
                             double tolerance, int max_iterations, double *lambda,
                             nh_mcp_stats *stats);

/* ---- tissue and tools in one step: Algorithm 1 across blocks (coupled.c) ----
 * docs/interaction.md "The coupled step". The rows below are this module's
 * interface to constraints: the contact module (above solve) writes the
 * needle's rows in this format; nothing here knows needles, only tissue
 * points, beam points, directions and laws. */

/* Constraint rows between tissue points and tool points. Row i reads
 *   g_i = n_i · (x_tissue(P_i) − x_tool(s_i)),
 * P_i a point of a tissue cell (its 8 nodes and shape values N; or a weighted
 * average of such points over any nodes: a widened row), s_i a point
 * of a tool element (the 3x12 Hermite Jacobian of nh_beam_point), n_i a unit
 * direction. Its force λ_i acts on the tissue point along +n_i and on the
 * tool point along −n_i. A row without a tool part (tool = −1) ties the
 * tissue point to a fixed position. The step enforces each row's law on the
 * end-of-step rate w_i = n_i · (v_tissue − v_tool) + g_i / h (w = 0 for
 * bilateral rows and sticking friction, w ≥ 0 for contact), i.e. the
 * position-level violation g is removed within the step. */
typedef struct {
  int m, cap;
  int *start;       /* m + 1: row i's tissue part is node[k], N[k], start[i] <= k < start[i + 1] */
  int n_slots;      /* allocated length of node and N */
  int *node;        /* tissue nodes (−1: unused); 8 per row unless a row was widened */
  double *N;        /* their weights: the shape values at the point (or averaged over a disc) */
  double *dir;      /* 3 per row: n */
  int *tool, *elem; /* tool index (−1: none) and element */
  double *J;        /* 36 per row: d x_tool / d (element DOFs), row-major 3 x 12 */
  /* A row between two tools (tool2 >= 0; −1 otherwise): a point of tool2 in
   * place of the tissue point (the row's tissue slots stay unused),
   *   g_i = n_i · (x_tool2(s2_i) − x_tool(s_i)),
   * its force λ_i on tool2's point along +n_i (a nested tool held by its
   * host: contact/nest.c). Element and Jacobian as tool's. */
  int *tool2, *elem2;
  double *J2;
  double *gap; /* g */
  /* 10 per row: a disc row's rule (nh_disc_points: rest centre X, normal,
   * ring reference, radius ρ; written by the contact module with the
   * weights), ρ = 0 for a point row: what a finer discretisation samples
   * again (the goal estimate's local dual, adapt/dwr_local.c) */
  double *disc;
  nh_row_law *law; /* law; normal indices refer to rows of this set */
  double *lambda;  /* in: warm start; out: the forces of the step */
} nh_rows;

void nh_rows_clear(nh_rows *rows);
void nh_rows_free(nh_rows *rows);
/* Append a row (law BILATERAL, λ = 0, no tool part, 8 unused tissue slots);
 * returns its index, or −1 when out of memory. The caller fills the fields
 * of row i. */
int nh_rows_add(nh_rows *rows);
/* Give the last row `count` unused tissue slots instead of its 8 (a tissue
 * part spread over more nodes than one cell's: the tip's disc,
 * docs/interaction.md "Tip disc"). NH_ERR_MEMORY. */
int nh_rows_widen(nh_rows *rows, int count);

/* The long no-progress rule of a Newton iteration (docs/reliability.md,
 * "Failures diagnosed"; the static Newton's and the quasi-static step's with
 * constraint rows): NH_NEWTON_STALL_LONG iterations in a row, none with a
 * relative residual below the best before them, end the solve whatever
 * the diagnosis says (as the iteration limit would: sim.c solves the step
 * again in load steps). Measured over the 255 static solves of the test
 * suite: every one that converged went at most 6 iterations without a new
 * best (the DBS brain under its weight, 0.28, 1, 0.84, 0.63, 0.56, 0.4,
 * 0.34, then 0.24 and converged at the 15th; test_patch's large rotation,
 * 0.69 … 0.91 for 5, then 0.11); the two that did not cycled at 1.2 for all
 * 30. */
#define NH_NEWTON_STALL_LONG 10
typedef struct {
  double best;
  int best_it;
} nh_newton_watch;
/* Call at iteration it = 0, 1, … with its relative residual rel: 1 when
 * the rule ends the solve. */
int nh_newton_stalled(nh_newton_watch *w, int it, double rel);
/* The no-progress rule of a Newton iteration (docs/reliability.md,
 * "Failures diagnosed"; the static Newton's, integrate.c, and the
 * quasi-static step's while no constraint row is active, contact.c): after
 * NH_NEWTON_STALL_ITERATIONS iterations no relative residual has fallen
 * below NH_NEWTON_STALL times the first, and the diagnosis names a cause. */
#define NH_NEWTON_STALL_ITERATIONS 3
#define NH_NEWTON_STALL            0.5
/* The supports as a Newton step's start measured them (diagnose.c): the
 * softest rigid mode of the assembled A, the six rigid fields at
 * displacements u restricted to the unknowns: mode 0-2 translations along
 * x, y, z, 3-5 rotations about them (-1: no unknown), rho its Rayleigh
 * quotient over A's mean diagonal, loose a bit per mode with rho at
 * round-off (not held at all). */
typedef struct {
  int mode;
  double rho;
  int loose;
  int turn_mode; /* with a load b: the rotation the linearised step turns most (-1: none) */
  double turn;   /* its angle |rᵀb| / rᵀAr, rad (r the unit-angle rotation, best centre) */
} nh_rigid;
/* The no-progress rule for a Newton that runs its own iterations (the
 * quasi-static step with tools, contact.c, while no constraint row has been
 * active, so that A alone holds the body): rel[0..it] the relative
 * residuals of iterations 0..it, the last at u; du (3 per node) the last
 * increment, whose largest entry names where; start the supports at the
 * step's start. NH_OK to go on; else the failure, its message naming
 * `what`, and stats->diagnosed set when the cause is final (a rigid mode
 * not held or weakly held; an inverted cell is a load step too large). */
int nh_newton_progress(nh_system *s, const char *what, const double *u, const double *du,
                       const nh_rigid *start, const double *rel, int it, nh_step_stats *stats);
/* Append to msg (size bytes in all) where the nodal field f (3 per node,
 * e.g. the last Newton increment) is largest: that node, the cells around
 * it, the constraint rows there (rows may be NULL), the rigid modes of the
 * assembled matrix and the likely cause (diagnose.c). */
void nh_system_where(nh_system *sys, const double *u, const double *f, const nh_rows *rows,
                     char *msg, size_t size);
/* The same for the nodal DOF `dof` (3 node + axis; e.g. a step's
 * nh_step_stats.residual_dof): " at node …", its cells and rows, the rigid
 * modes and the likely cause. */
void nh_system_where_dof(nh_system *sys, const double *u, int dof, const nh_rows *rows, char *msg,
                         size_t size);

/* The dual of a constrained step: ncol problems
 *     A x + J_tᵀ μ = b,   J_t x = 0
 * with A the step's matrix and J_t the tissue part of the rows with
 * active[i] != 0 (active NULL: every row); the tools' parts are held (a
 * rigid tool). x = A⁻¹ b − A⁻¹ J_tᵀ μ with W μ = J_t A⁻¹ b,
 * W = J_t A⁻¹ J_tᵀ (nh_system_compliance_add; with fewer active rows m
 * than columns, J_t G and the correction G μ from G = A⁻¹ J_tᵀ, its m
 * columns solved with A⁻¹ b's ncol in one pass, instead of a second solve
 * of ncol), solved by a pivoted
 * Cholesky factorisation of the diagonally scaled W truncated at relative
 * pivots below 1e-12 (dependent rows: J_tᵀ μ is still unique, μ is not:
 * the truncated rows get 0). A is the matrix as the step left it, assembled
 * at the step's solution (its closing residual): the tangent at the state
 * the goal estimate integrates at. When the factor is not A's (a reused or
 * inherited one, or the step's own of the A at its start), A is factorised
 * here first, which starts a new cycle of the renewal rule: the next step,
 * assembling at the same state, takes it as A's own factor (PCG on the
 * reused factor was measured 1.7–3.5 × dearer, docs/performance.md
 * "Goal-oriented runs"). b, x: column-major n_free x ncol. mu (may be
 * NULL): the multipliers, rows->m per column (0 on the inactive rows).
 * *n_used (may be NULL): the active rows. NH_ERR_MEMORY, NH_ERR_NUMERIC. */
int nh_system_solve_rows(nh_system *sys, const nh_rows *rows, const unsigned char *active, int ncol,
                         const double *b, double *x, double *mu, int *n_used);
/* nh_system_solve_rows of n_sets sets of columns at once, set k its next
 * set_ncol[k] columns of b and x with the rows set_active[k] (NULL: every
 * row): one solve for all of them, and W and G over the union of their
 * rows, each set's multipliers from its own rows' block of W (the goals'
 * duals and the fronts' in one pass, adapt/dwr.c). *n_used: set 0's rows. */
int nh_system_solve_rows_sets(nh_system *sys, const nh_rows *rows, int n_sets, const int *set_ncol,
                              const unsigned char *const *set_active, const double *b, double *x,
                              double *mu, int *n_used);
/* nh_system_solve_rows of one row set for a sequence of right-hand sides
 * that depend on each other (the goal estimate's memory links,
 * adapt/dwr_memory.c): create forms the active rows' compliance W once (A
 * factorised first when the factor is not A's); each solve is then two
 * solves of its ncol columns and the multipliers (rows->m per column in
 * mu, may be NULL), the same solution as nh_system_solve_rows to
 * round-off. destroy accepts NULL. NH_ERR_MEMORY, NH_ERR_NUMERIC. */
typedef struct nh_rows_solver nh_rows_solver;
int nh_rows_solver_create(nh_system *sys, const nh_rows *rows, const unsigned char *active,
                          nh_rows_solver **out);
int nh_rows_solver_solve(nh_system *sys, const nh_rows_solver *rs, int ncol, const double *b,
                         double *x, double *mu);
void nh_rows_solver_destroy(nh_system *sys, nh_rows_solver **rs);
/* The factorisations nh_system_solve_rows made since the last call, and
 * reset the count. */
int nh_system_take_later_factorisations(nh_system *sys);
/* Whether the coming step's solution will be factorised after the step
 * (yes: the goal estimate's duals, nh_system_solve_rows, follow it). That
 * factorisation renews the cycle of the renewal rule, so a step told so
 * solves with its own mesh's factor, by PCG, when the rule (or the factor's
 * age) asks for a renewal at its start, instead of factorising twice
 * (reuse.c). Holds until called again. */
void nh_system_expect_factor_later(nh_system *sys, int yes);

/* A tool in the coupled step: its beam and the prescribed base velocity at
 * the end of the step (linear, angular). */
typedef struct {
  nh_beam *beam;
  nh_beam_dynamic_options options; /* dt (must equal the tissue's), damping, gravity */
  double base_velocity[6];
  const double *f_ext; /* 6 per node, may be NULL */
} nh_coupled_tool;

typedef struct {
  nh_step_stats step;  /* assemble, factor, solve (tissue and tools), t_constraints = all below */
  double t_compliance; /* s: W = J A⁻¹ Jᵀ, tissue (Algorithm 3) and tools */
  double t_mcp;        /* s: the mixed complementarity solve */
  nh_mcp_stats mcp;    /* sweeps, residual, stick/slide/open counts */
  int w_kept;        /* 1: a reused factor's corrections took the W₀ kept from an earlier step */
  nh_rigid supports; /* in->measure_supports: A's rigid modes and the load's turn at the
                        iteration's start (mode -1: not measured) */
} nh_coupled_stats;

/* One backward-Euler step of the tissue (nh_step_dynamic's form) and the
 * tools (nh_beam_dynamic_prepare's form) coupled by `rows` (Algorithm 1):
 * factorise each block, solve the free problems, W = Σ_blocks J A⁻¹ Jᵀ
 * (the tissue's by CHOLMOD sparse solves), λ from nh_mcp_solve warm-started
 * from rows->lambda (tolerance, max_iterations as there; a solve that stops
 * short of tolerance is accepted if its residual is <= accept), correct each block
 * by A⁻¹ Jᵀ λ and update tissue and tools. With no rows, the blocks step
 * independently. The system must not carry hanging-node rows
 * (nh_system_set_hanging_rows): use elimination. Fails with NH_ERR_NUMERIC
 * (a block not positive definite / singular, a non-finite update, the
 * constraint solve not converged: the message names which), NH_ERR_MEMORY.
 * With in->quasi_static (in->dt = 1, the rows' time scale τ, and the
 * tools' options quasi_static) it is one Newton iteration of the static
 * equilibrium instead (docs/interaction.md, "Quasi-static mode"): A = K(u),
 * b = f_ext − f_int(u), δ = A⁻¹ (b + Jᵀλ) per block, w = J δ + g (a tool's
 * base moved by its base_velocity), λ the total forces, u ← u + δ (v is not
 * used); stats->step.residual is the tissue's relative equilibrium residual
 * |b + J_tᵀλ| / max(|f_ext|, |f_int|, |J_tᵀλ|) at the state the iteration
 * started from (so K δ: zero at the solution), and the factor is always
 * the current one (no reuse). */
/* After Newton iterations with the consistent tangent (nh_solve_static; the
 * coupled quasi-static step with in->consistent_tangent): back to the
 * corotational tangent; with `refactor`, assembled at u and factorised, the
 * state the next step's reuse and the goal-oriented estimate's dual solves
 * expect (one assembly and one Cholesky factorisation, added to *st). */
int nh_system_tangent_restore(nh_system *s, const nh_integrator *in, const double *f_ext,
                              const double *u, int refactor, nh_step_stats *st);

int nh_step_coupled(nh_system *sys, const nh_integrator *in, const double *f_ext, double *u,
                    double *v, int n_tools, nh_coupled_tool *tools, nh_rows *rows, double tolerance,
                    double accept, int max_iterations, nh_coupled_stats *stats);

#endif
