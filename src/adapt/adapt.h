/* adapt — a posteriori error estimation by superconvergent patch recovery
 * (SPR, the seed's §2.3, Eq. 15), the marking of leaves for refinement
 * (Eq. 16 and Dörfler's bulk criterion), and the refinement driver that
 * marks, applies the DOF budget, refines by the template and carries the
 * state to the new nodes (Eq. 17). The algorithms and their choices
 * (boundary patches, hanging nodes, budget) are described at the top of
 * adapt/spr.c, adapt/mark.c and adapt/refine.c.
 *
 * Conventions: stresses are Voigt (xx, yy, zz, yz, xz, xy), Pa; arrays
 * "per node" have mesh->n_nodes entries, arrays "per cell" mesh->n_cells
 * entries indexed by cell id (only the leaves are meaningful). The
 * displacement u has 3 entries per node. `hanging` may be NULL (a conforming
 * mesh) or hold n_hanging = 0. */
#ifndef NH_ADAPT_H
#define NH_ADAPT_H

#include "core/core.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "solve/solve.h"

/* When a patch fit is refused (and the patch grown). With y the sample
 * points centred at their centroid and scaled to unit radius, C = Σ yyᵀ and
 * y0 the scaled evaluation point:
 *  - rank: the smallest eigenvalue of C is below NH_SPR_RCOND times the
 *    largest (coplanar or collinear points: the gradient is undetermined);
 *  - conditioning at the node: the leverage 1/n + y0ᵀC⁻¹y0, the factor by
 *    which the fit multiplies the variance of independent errors of the
 *    samples at y0, exceeds NH_SPR_MAX_LEVERAGE (nearly coplanar centres and
 *    a node off their plane: the extrapolation would amplify round-off and
 *    discretisation noise). A full 8-cell patch of a box grid has leverage
 *    1/8, a box corner node with its grown 2x2x2 patch 13/8. */
#define NH_SPR_RCOND        1e-10
#define NH_SPR_MAX_LEVERAGE 4.0

/* Least-squares fit of the linear polynomial p(x) = a₀ + a·(x − x̄) to n
 * samples values[6n] (6 components each, fitted independently) at points
 * points[3n], evaluated at x0[3]: out[6] = p(x0). Coordinates are centred at
 * the samples' centroid x̄ and scaled by their largest distance from it, so
 * the constant term is the samples' mean and a linear field is reproduced to
 * round-off.
 * Returns NH_OK, or NH_ERR_NUMERIC without recording a message (the caller
 * decides what to do; out is untouched) if n < 4, the points do not span
 * 3-D, or the value at x0 is ill-conditioned (NH_SPR_RCOND,
 * NH_SPR_MAX_LEVERAGE). */
int nh_spr_fit_patch(int n, const double *points, const double *values, const double x0[3],
                     double out[6]);
/* The same fit for m values per sample (values[m n], out[m]): the sample
 * weights depend on the points only, so fields that share the points are fitted
 * together. Returns as nh_spr_fit_patch, or NH_ERR_MEMORY (no message) for a
 * patch of more than 256 samples whose weights cannot be allocated. */
int nh_spr_fit_patch_n(int n, const double *points, int m, const double *values, const double x0[3],
                       double *out);

/* Recovered nodal stresses σ*.
 * In:  mesh and tissue (tissue->mesh == mesh, element data up to date for
 *      every leaf), displacements u, hanging nodes (or NULL).
 * Out: sigma_star[6 n_nodes]: the patch-recovered stress of every node that
 *      is a corner of a leaf; hanging nodes get their masters' interpolation
 *      Σ w σ*(master); nodes that belong to no leaf get 0.
 * Fails with NH_ERR_INTERNAL (message) if the tissue does not belong to the
 * mesh, a leaf has no element data or the hanging-node table is
 * inconsistent (an index out of range, a master that is itself hanging),
 * NH_ERR_MEMORY. Uses OpenMP; the result does not depend on the number of
 * threads (bitwise). */
int nh_spr_recover(const nh_mesh *mesh, const nh_tissue *tissue, const double *u,
                   const nh_hanging *hanging, double *sigma_star);
/* Recovery of n_fields stress fields at once from their centre samples.
 * In:  stress[6 n_fields per cell id] (leaves read): field f's centre stress
 *      of cell c at stress[6 (n_fields c + f) ..]; mesh, tissue, hanging as
 *      nh_spr_recover.
 * Out: sigma_star[6 n_fields per node], laid out the same way.
 * Every field gets the patches, growth and fallback nh_spr_recover would give
 * it alone (they depend on the mesh only). Fails as nh_spr_recover. */
int nh_spr_recover_fields(const nh_mesh *mesh, const nh_tissue *tissue, const nh_hanging *hanging,
                          int n_fields, const double *stress, double *sigma_star);

/* Element error indicators and the global estimate (seed Eq. 15, energy
 * form): ηₑ² = φₑ ∫ₑ (σ* − σₕ)ᵀ D⁻¹ (σ* − σₕ) dΩ (2x2x2 Gauss, σ* the
 * trilinear interpolation of the recovered nodal stresses, σₕ the element's
 * corotational stress at the Gauss point).
 * In:  as nh_spr_recover.
 * Out: eta_cell[n_cells] (ηₑ ≥ 0 for every leaf, other entries untouched;
 *      may be NULL), *eta = (Σ ηₑ²)^½, *eta_rel = η / (‖u‖²_E + η²)^½ with
 *      ‖u‖²_E = Σₑ φₑ ∫ₑ σₕᵀ D⁻¹ σₕ dΩ (0 if both vanish); eta, eta_rel may
 *      be NULL.
 * Fails as nh_spr_recover, and with NH_ERR_NUMERIC (message) if η or ‖u‖_E
 * is not finite (a NaN or Inf in u). Thread-count independent (bitwise). */
int nh_spr_estimate(const nh_mesh *mesh, const nh_tissue *tissue, const double *u,
                    const nh_hanging *hanging, double *eta_cell, double *eta, double *eta_rel);

/* The part of SPR that depends on the mesh only, kept between steps: every
 * node's patch and fit weights (σ*(n) = Σ_i w_i σ_i over its patch's centre
 * stresses), checked against the mesh at every use (leaves, corners, rest
 * positions, φV, hanging nodes; exactly) and made again when it changed;
 * also the estimate's workspace. */
typedef struct nh_spr_cache nh_spr_cache;
/* An empty cache. Fails with NH_ERR_MEMORY. */
int nh_spr_cache_create(nh_spr_cache **out);
/* Free and set *cache = NULL (accepts NULL). */
void nh_spr_cache_destroy(nh_spr_cache **cache);
/* How many times the weights were made (0 for NULL): the tests' window. */
int nh_spr_cache_builds(const nh_spr_cache *cache);
/* nh_spr_estimate with the weights from cache (made again first if the
 * mesh is not theirs): bitwise the same results. frames (may be NULL): the
 * frames of an assembly of this tissue at this u (nh_system_frames_at), whose
 * rotations the stresses then take instead of decomposing F again (the same
 * bits). Fails as nh_spr_estimate. */
int nh_spr_estimate_cached(nh_spr_cache *cache, const nh_mesh *mesh, const nh_tissue *tissue,
                           const double *u, const nh_hanging *hanging, const double *frames,
                           double *eta_cell, double *eta, double *eta_rel);

/* Marking parameters (the scene's adapt section). */
typedef struct {
  int strategy;    /* NH_MARK_MAX | NH_MARK_DORFLER (scene/scene.h) */
  double theta;    /* max: mark ηₑ ≥ θ maxₑ ηₑ, θ ∈ (0, 1] */
  double fraction; /* dorfler: smallest set with Σ ηₑ² ≥ fraction Σ_all ηₑ², in (0, 1] */
  int max_level;   /* cells with level >= max_level are not refined */
  double min_size;    /* if > 0: cells whose children would be smaller than this are not refined */
  double child_ratio; /* smallest child edge / parent edge of the template (0: 1/2) */
} nh_mark_params;

/* Mark leaves for refinement.
 * In:  mesh, eta_cell[n_cells] (indexed by cell id, read for leaves only,
 *      each finite and >= 0), params.
 * Out: marked[] (room for mesh->n_leaves ids) receives the marked cell ids in
 *      ascending order, *n_marked their count (0 if every ηₑ is 0).
 * The strategy selects candidates among all leaves; candidates at
 * max_level or below the size limit are then dropped (mark.c).
 * Fails with NH_ERR_INPUT (message) for an unknown strategy or θ / fraction
 * outside (0, 1], NH_ERR_NUMERIC (message) for a negative or non-finite ηₑ,
 * NH_ERR_MEMORY. */
int nh_mark_cells(const nh_mesh *mesh, const double *eta_cell, const nh_mark_params *params,
                  int *marked, int *n_marked);

/* ---- the refinement driver (refine.c) ---- */
typedef struct nh_adapt nh_adapt; /* template, marking parameters, indicators */

/* Create the driver of the scene's adapt section: loads spec->template_path;
 * refinement never makes more than max_cells leaves (0: no cap; one warning
 * when it stops there).
 * Fails as nh_template_load (NH_ERR_INPUT for a bad template, its message
 * prefixed by spec->where_template: "SCENE:LINE: adapt.template: "),
 * NH_ERR_MEMORY. */
int nh_adapt_create(const nh_adapt_spec *spec, int max_cells, nh_adapt **out);
/* Free and set *adapt = NULL (accepts NULL). */
void nh_adapt_destroy(nh_adapt **adapt);

/* Estimate the error of the solution u (nh_spr_estimate) and keep the
 * element indicators for nh_adapt_indicators and nh_adapt_step. frames: as
 * nh_spr_estimate_cached (may be NULL).
 * Out: *eta, *eta_rel as nh_spr_estimate. Fails as nh_spr_estimate,
 * NH_ERR_MEMORY. */
int nh_adapt_estimate(nh_adapt *adapt, const nh_mesh *mesh, const nh_tissue *tissue,
                      const double *u, const nh_hanging *hanging, const double *frames, double *eta,
                      double *eta_rel);

/* The indicators ηₑ of the last estimate (per cell id, leaves meaningful),
 * or NULL if there is none for the current mesh (none made yet, or the mesh
 * was refined since; also for adapt = NULL). */
const double *nh_adapt_indicators(const nh_adapt *adapt);

/* One refinement from the last estimate: mark (nh_mark_cells; under
 * estimator goal by the goal indicators, in tolerance mode among the cells
 * that can still be refined, nothing when every goal is below tolerance),
 * keep the cells of largest ηₑ within the DOF budget, close the set under
 * the 2:1 rule (estimator goal), refine them by the template
 * (nh_mesh_refine), carry each of the n_fields nodal fields (3 values per
 * node; fields[f] is reallocated to the new node count) to the new nodes by
 * Eq. 17, and with adapt.coarsen merge the families whose indicators are
 * below the fraction of the marking threshold (fields compacted by
 * injection; refine.c).
 * Out: *n_refined, the number of cells refined plus families merged (0:
 *      mesh and fields untouched, the indicators still valid);
 *      nh_adapt_last_stop says what ended the refinement.
 * The caller rebuilds what depends on the mesh and re-interpolates hanging
 * values. Fails as nh_mark_cells, nh_mesh_refine and nh_mesh_coarsen,
 * NH_ERR_INTERNAL without an estimate, NH_ERR_MEMORY; after a failure the
 * mesh may be refined but the fields not transferred. */
int nh_adapt_step(nh_adapt *adapt, nh_mesh *mesh, int n_fields, double **fields, int *n_refined);

/* The leaves the next nh_adapt_step would refine (marking, budget, 2:1
 * closure; coarsening aside), without refining them: cells[] (room for
 * mesh->n_leaves ids), *n their count. Mesh and indicators untouched.
 * Fails as nh_adapt_step's marking, NH_ERR_INTERNAL without an estimate. */
int nh_adapt_planned(nh_adapt *adapt, const nh_mesh *mesh, int *cells, int *n);
/* Refine the n leaves cells[] by the driver's template (nh_mesh_refine, in
 * that order) and carry the n_fields nodal fields to the new nodes by
 * Eq. 17 (fields[f] reallocated); the last estimate no longer applies.
 * nh_adapt_step's refinement, for given cells. Fails as nh_mesh_refine,
 * NH_ERR_MEMORY. */
int nh_adapt_refine_cells(nh_adapt *adapt, nh_mesh *mesh, const int *cells, int n, int n_fields,
                          double **fields);

/* The nodal transfer of the last mesh change made by nh_adapt_step or
 * nh_adapt_refine_cells (refinement's Eq. 17, then coarsening's injection):
 * how the fields were carried, as a linear map old nodes → new nodes (the
 * solver's preconditioner across the change uses it: solve/inherit.c).
 * NULL when the last call changed nothing or failed. Valid until the next
 * such call. */
const nh_node_transfer *nh_adapt_last_transfer(const nh_adapt *adapt);

/* Coarsening never makes a leaf coarser than fix[r].refine at region r
 * (nh_mesh_cell_coarser_at; tissue.fixed.N.refine, 0: none): a family
 * whose parent would be is never merged. The arrays are the caller's and
 * must outlive the driver. */
void nh_adapt_keep_regions(nh_adapt *adapt, int n, const nh_region *regions, const nh_fix *fix);

/* What ended the last nh_adapt_step (steps.csv `refine_stop`). */
typedef enum {
  NH_ADAPT_REFINED = 0,   /* every marked cell was refined */
  NH_ADAPT_TOLERANCE = 1, /* estimator goal: every goal estimate <= adapt.tolerance */
  NH_ADAPT_BUDGET = 2,    /* adapt.max_dofs left marked cells unrefined */
  NH_ADAPT_LIMIT = 3      /* nothing to refine (max_level, min_size, or every η 0) */
} nh_adapt_stop;
nh_adapt_stop nh_adapt_last_stop(const nh_adapt *adapt);

/* Estimator goal: the points whose displacement is the goal (rest positions,
 * 3 each); the averaging box's half-width is half the edge of the finest cell
 * refinement can make (the initial grid's smallest spacing times the
 * template's child ratio to the power max_level). NH_ERR_MEMORY. */
int nh_adapt_set_goals(nh_adapt *adapt, const nh_mesh *mesh, int n, const double *points);
/* Goal-oriented estimate of the solution u with the factor `sys` holds
 * and the step's constraint rows (may be NULL) (nh_dwr_estimate; scale as
 * there). Every adapt.separate_every-th call (and while no goal has a
 * non-zero estimate) solves each goal's duals, keeps each goal's |E_p|
 * and E_pk, sets the combined functional's weights ω_pk = E_pk / |E_p|
 * and marks by Σ η_K^p over the goals whose estimate exceeds
 * adapt.tolerance (all goals without tolerance); the calls between solve
 * one dual (nh_dwr_estimate_combined), mark by its indicator and scale the
 * last separate E_pk by E_c / Σ_p |E_p| (dwr.c, docs/theory.md §6.6).
 * *eta, *eta_rel: the primal's SPR estimate. Fails as nh_dwr_estimate,
 * NH_ERR_MEMORY. */
int nh_adapt_estimate_goal(nh_adapt *adapt, nh_system *sys, const nh_rows *rows, double scale,
                           const nh_mesh *mesh, const nh_tissue *tissue, const double *u,
                           const nh_hanging *hanging, double *eta, double *eta_rel);
/* The loads the next goal estimates' geometry term uses (dwr.c,
 * "Geometry"); kept by pointer, NULL: the elastic part only. */
void nh_adapt_set_geometry_loads(nh_adapt *adapt, const nh_geometry_loads *loads);
/* The change of a constrained step's rows when their constraints are
 * sampled one level finer (dwr.c, "Constraint data"), one value per row of
 * the rows the estimate is given: */
typedef struct {
  const double *change; /* δc_i: the change of row i's gap at the solution u, m */
  const double *force;  /* Λ_i: the force of row i on the tissue along its direction, N */
  /* δ(J w)_i: the change of row i's linearisation applied to n fields w
   * (3 n_nodes each); out: rows->m per field. 0 or an error code. */
  int (*linear)(void *ctx, int n, const double *w, double *out);
  void *ctx;
} nh_constraint_data;

/* The constraint data the next goal estimates' constraint-data term uses
 * (dwr.c, "Constraint data"); kept by pointer, NULL: no term. */
void nh_adapt_set_constraint_data(nh_adapt *adapt, const nh_constraint_data *data);
/* The fronts a goal estimate also estimates (dwr_front.c; docs/theory.md
 * §6.6, "Anchoring"): in, n fronts and row[n], each front's first tip row
 * among the step's rows (its disc's rows n1, n2, t); out, error[3 n], each
 * front's e (m, nh_dwr_front_error). And shaft points: in, n_points and
 * point_row[n_points], each point's first row (n1, n2, t); out,
 * point_error[n_points], the estimated error of its axial row's tissue
 * part, t · (u − u_h), with that row free in its dual (m; dwr_front.c,
 * "Shaft points"). */
typedef struct {
  int n;
  const int *row;
  double *error;
  int n_points;
  const int *point_row;
  double *point_error;
} nh_dwr_fronts;

/* A dynamic step's data for the goal estimate's memory term
 * (dwr_memory.c; docs/theory.md §6.6, "Memory"): the step h (s), the mass
 * and stiffness damping α (1/s) and β (s), the lumped nodal mass, and at
 * most max_links links. */
typedef struct {
  double h, alpha, beta;
  const double *mass;
  int max_links;
} nh_dwr_memory;

/* The dynamic step's data of the next goal estimates' memory term
 * (dwr_memory.c; NULL: a quasi-static step, no memory), copied, and the
 * step they estimate (a second estimate at the same step, after a
 * re-solve, starts from the same earlier steps). */
void nh_adapt_set_memory(nh_adapt *adapt, const nh_dwr_memory *memory, int step);
/* The fronts whose errors the next goal estimates also estimate, in the
 * same pass (nh_dwr_result.fronts; their errors written to fronts->error);
 * kept by pointer, NULL: none. */
void nh_adapt_set_fronts(nh_adapt *adapt, nh_dwr_fronts *fronts);
/* The goal estimate's state that later estimates carry (the combined
 * dual's weights and the last separate estimates, the memory term's links'
 * values): appended to b, and read back from data (what save wrote, for a
 * scene with the same goals) so that a restarted run estimates as the
 * uninterrupted one. load: NH_ERR_INPUT (message) for a state of other
 * goals or a malformed one, NH_ERR_MEMORY. */
void nh_adapt_state_save(const nh_adapt *adapt, nh_bytes *b);
int nh_adapt_state_load(nh_adapt *adapt, const unsigned char *data, size_t size);
/* |E_p| per goal of the last goal estimate (m), or NULL (none for this mesh). */
const double *nh_adapt_goal_errors(const nh_adapt *adapt);
/* The signed E_pk (3 per goal, m) of the last goal estimate, or NULL. */
const double *nh_adapt_goal_estimates(const nh_adapt *adapt);
/* The geometry part G_pk (3 per goal, m; included in the estimates) of the
 * last goal estimate (dwr.c, "Geometry"; 0 without cut cells, NaN after a
 * combined estimate, which does not split it), or NULL. */
const double *nh_adapt_goal_geometry(const nh_adapt *adapt);
/* The constraint-data part C_pk (3 per goal, m; included in the estimates)
 * of the last goal estimate (dwr.c, "Constraint data"; 0 without
 * constraint rows whose data change, NaN after a combined estimate), or
 * NULL. */
const double *nh_adapt_goal_constraint(const nh_adapt *adapt);

/* ---- goal-oriented estimate: the dual-weighted residual (adapt/dwr.c) ---- */

/* Nodal vector j[3 n_nodes] (overwritten) of the regularised point
 * functional J(v) = mean of v_k over the tissue inside the box of half-width
 * `radius` centred at point: J(v) = Σ j·v. `where` names the point in
 * messages. Fails with NH_ERR_INPUT (message) if the box holds no tissue. */
int nh_goal_functional(const nh_mesh *mesh, const double point[3], double radius, int k,
                       const char *where, double *j);

/* The goals' point functionals (nh_goal_functional, 3 per point), which
 * depend on the rest geometry only, kept between estimates: checked at
 * every use against the mesh (key.c: leaves, corners, rest positions and
 * each leaf's fill φ, exactly) and the points and radius (bitwise), and
 * made again when any of them changed. */
typedef struct nh_goal_cache nh_goal_cache;
/* An empty cache. Fails with NH_ERR_MEMORY. */
int nh_goal_cache_create(nh_goal_cache **out);
/* Free and set *cache = NULL (accepts NULL). */
void nh_goal_cache_destroy(nh_goal_cache **cache);
/* How many times the functionals were made (0 for NULL): the tests' window. */
int nh_goal_cache_builds(const nh_goal_cache *cache);

/* The tip–target distance d(v) = |x_tip − x_T(v)|, x_T(v) = X_T + J_T(v)
 * (J_T the box mean of nh_goal_functional), linearised about the current
 * state with the tip held (dwr.c, "Distance"): its tissue part is
 * −n · J_T(v), n = unit(x_tip − x_T). Nodal vector j[3 n_nodes]
 * (overwritten) = −Σ_k n_k j_k. Fails as nh_goal_functional. */
int nh_goal_distance_functional(const nh_mesh *mesh, const double target[3], const double n[3],
                                double radius, const char *where, double *j);
/* The estimate of d(u) − d(u_h) from the target's signed estimates
 * E[3] (E_k ≈ J_Tk(u) − J_Tk(u_h)) and the current target and tip
 * positions: −n · E. When tip and target coincide (d not differentiable)
 * the bound |E| ≥ |d(u) − d(u_h)| (to first order). */
double nh_dwr_distance_estimate(const double E[3], const double target[3], const double tip[3]);

/* Which rows of a constrained step the dual keeps (dwr.c, "Constraints"):
 * active[i] = 1 for a bilateral row, a unilateral row that presses
 * (λ > 0) and a friction row that sticks (law.sliding 0); 0 otherwise. */
void nh_dwr_active_rows(const nh_rows *rows, unsigned char *active);

/* Dual solutions of n functionals with the system's current factor A and
 * the active rows (nh_dwr_active_rows) of the step's constraint rows
 * `rows` (may be NULL: the tissue alone):
 *   A z_q + J_tᵀ μ_q = scale Pᵀ j_q,  J_t z_q = 0  (nh_system_solve_rows),
 * z_q = P (the free part) for j[3 n_nodes n] (q-th at j + 3 n_nodes q), z
 * likewise (fixed DOFs 0, hanging nodes their masters' interpolation).
 * mu (may be NULL): the multipliers μ_q, rows->m per dual (0 on the rows
 * not active). *n_rows (may be NULL): the active rows used.
 * Fails with NH_ERR_INPUT (message) if the system carries constraint rows
 * (hanging nodes by Lagrange multipliers), NH_ERR_MEMORY, NH_ERR_NUMERIC. */
int nh_dwr_duals(nh_system *sys, const nh_rows *rows, double scale, int n_nodes, int n,
                 const double *j, double *z, double *mu, int *n_rows);

/* What nh_dwr_estimate returns (arrays allocated by the caller). */
typedef struct {
  double *estimate;    /* 3 per point: E_pk ≈ J_pk(u) − J_pk(u_h), signed, m */
  double *norm;        /* per point: |E_p| = (Σ_k E_pk²)^½, m */
  double *indicator;   /* n_points x n_cells (may be NULL): η_K^p at [n_cells p + c], m */
  double *eta_cell;    /* n_cells (may be NULL): the primal's SPR indicators ηₑ */
  double eta, eta_rel; /* the primal's SPR estimate (as nh_spr_estimate) */
  int n_rows;          /* constraint rows in the duals (nh_dwr_duals) */
  /* The geometry term (dwr.c, "Geometry"), on a mesh with cut cells: in,
   * the step's geometry-dependent loads (NULL: the elastic part only); out,
   * geometry (may be NULL) the part of each estimate that is the geometry
   * term, G_q (included in estimate). */
  const nh_geometry_loads *loads;
  double *geometry;
  /* The constraint-data term (dwr.c, "Constraint data"): in, data (may be
   * NULL: no term); out, constraint (may be NULL) the part of each
   * estimate that is the term, C_q (included in estimate), and inherited
   * (may be NULL) the part of C_q from the tools' rows: their anchors'
   * errors, made at the steps that anchored them (docs/theory.md §6.6,
   * "Anchoring"), which no refinement of this step reduces. */
  const nh_constraint_data *data;
  double *constraint, *inherited;
  /* The local enriched dual where a goal's cell holds tool rows
   * (dwr_local.c): in, local (0: off); out, local_term (may be NULL) the
   * patch's term L_q (0 where not applied; included in estimate, in place
   * of the recovered terms of the patch's leaves) and local_applied (1 if
   * a patch was solved). */
  int local;
  double *local_term;
  int local_applied;
  /* in (may be NULL: made afresh): the goals' functionals kept between
   * estimates (nh_goal_cache); the same numbers either way */
  nh_goal_cache *functionals;
  /* in/out (may be NULL: none): the fronts whose errors the same pass
   * estimates (dwr_front.c), each with the dual of its own rows; no
   * marking indicator, no local dual */
  nh_dwr_fronts *fronts;
  /* in (may be NULL: none, a quasi-static step): the dynamic step's data for
   * the memory term's links (dwr_memory.c); out, memory_own (may be NULL
   * without memory) each link's own estimate, link m of functional q at
   * [nz m + q] for m = 0 … memory_links (m = 0: the estimate itself), room
   * for max_links + 1 links, and memory_links, the links computed */
  const nh_dwr_memory *memory;
  double *memory_own;
  int memory_links;
} nh_dwr_result;

/* Goal-oriented estimate of the displacement at n_points points[3 each]
 * (regularised over boxes of half-width radius) for the solution u of the
 * system whose factor `sys` holds, with the step's constraint rows (may be
 * NULL; nh_dwr_duals); scale = the coefficient of K in the factorised
 * matrix (1 static, hβ + h² dynamic). dwr.c gives the formulas.
 * where[p] (may be NULL) names point p in messages. Fails as
 * nh_goal_functional, nh_dwr_duals and nh_spr_recover, and with
 * NH_ERR_NUMERIC if an estimate is not finite. Thread-count independent. */
int nh_dwr_estimate(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *mesh,
                    const nh_tissue *tissue, const nh_hanging *hanging, const double *u,
                    int n_points, const double *points, double radius, char (*where)[NH_WHERE_MAX],
                    nh_dwr_result *out);

/* The same for the one combined functional J_c = Σ_pk weights[3p+k] J_pk
 * (dwr.c, "Several goals in one dual"): one dual solve. out->estimate[0] =
 * E_c (= Σ_pk weights_pk E_pk of nh_dwr_estimate, to round-off, for a
 * linear problem), out->norm[0] (if not NULL) = |E_c|, out->indicator (if
 * not NULL) n_cells values ‖e*_u‖_K ‖e*_{z_c}‖_K; eta_cell, eta, eta_rel,
 * n_rows as there. Fails as nh_dwr_estimate. */
int nh_dwr_estimate_combined(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *mesh,
                             const nh_tissue *tissue, const nh_hanging *hanging, const double *u,
                             int n_points, const double *points, double radius,
                             char (*where)[NH_WHERE_MAX], const double *weights,
                             nh_dwr_result *out);

/* The error e (m) of the mean displacement of the tip disc whose three
 * rows (directions n1, n2, t) start at `row` among the step's rows: the
 * anchoring error of the front a cutting step sets there (dwr_front.c;
 * docs/theory.md §6.6, "Anchoring"). e = Σ_q E_q n_q, E_q the goal
 * estimate of the row's tissue part n_q · Σ w_a v_a (constrained dual,
 * geometry term with loads (may be NULL), constraint-data term with data
 * (may be NULL), the latter carrying the old front's anchoring error).
 * sys, rows, scale, u as nh_dwr_estimate. The front alone: a goal
 * estimate gives the same e for its nh_dwr_result.fronts in its own pass.
 * NH_ERR_INTERNAL (row out of range), or fails as nh_dwr_estimate. */
int nh_dwr_front_error(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *mesh,
                       const nh_tissue *tissue, const nh_hanging *hanging, const double *u, int row,
                       const nh_geometry_loads *loads, const nh_constraint_data *data, double e[3]);

#endif
