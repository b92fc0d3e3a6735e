/* contact — the tools (needle, cannula, electrode) and their constraints
 * with the tissue: surface puncture, needle tip, needle shaft (the seed's
 * Eqs. 5-9; docs/interaction.md).
 *
 * The module owns the tools' beams, their prescribed motion and, per tool
 * group (an outer tool and the tools nested inside it), the state machine
 *
 *   outside → contact → punctured → cutting ↔ punctured → retracting
 *
 * and the cut channel: material points of the tissue laid behind the tip
 * as it cuts. Each step (nh_contact_step) it writes the constraint rows of
 * the current states in the solver's row format (nh_rows), solves tissue
 * and tools together (nh_step_coupled) and reads the rows' forces to move
 * the states on. Contact sits above solve: the solver knows rows, laws and
 * beams, not needles. Forces in nh_rows are impulses (N s, the step's
 * velocity form); the thresholds of the laws are set as force × h and
 * reported forces are λ / h. Embedded points are kept in material
 * coordinates, so a refined mesh only relocates them. */
#ifndef NH_CONTACT_H
#define NH_CONTACT_H

#include "beam/beam.h"
#include "core/core.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "solve/solve.h"

typedef enum {
  NH_TOOL_OUTSIDE = 0,
  NH_TOOL_CONTACT = 1,
  NH_TOOL_PUNCTURED = 2,
  NH_TOOL_CUTTING = 3,
  NH_TOOL_RETRACTING = 4
} nh_tool_state;

/* "outside", "contact", ... */
const char *nh_tool_state_name(nh_tool_state state);

typedef struct nh_contact nh_contact;

/* Create the tools of `scene` at rest at t = 0 on `mesh`. Fails with
 * NH_ERR_INPUT (FILE:LINE: tools.i: ...) for a tool whose tip never comes
 * within one cell of the tissue over its motion, NH_ERR_MEMORY. */
int nh_contact_create(const nh_scene *scene, const nh_mesh *mesh, nh_contact **out);
void nh_contact_destroy(nh_contact **contact);

nh_beam *nh_contact_beam(nh_contact *c, int tool);

/* The spacing of a tool's channel points (docs/interaction.md, "Shaft"): the
 * scene's `spacing` if > 0, else `cell`, the edge of the cell the last point
 * lies in. One point per cell edge along the axis is at most one point per
 * cell the axis crosses, so the shaft's lateral rows never outnumber the
 * values the tissue can take along the axis ("Why one point per cell"). */
double nh_channel_spacing(double spacing, double cell);

/* One step t_new − h → t_new of tissue and tools, h = in->dt: the rows of
 * every constraint in its current state on the tissue state (mesh, u, v),
 * the coupled solve (nh_step_coupled: u, v advanced, the tools' beams
 * too), then the constraints' forces move the states on (puncture, cut,
 * channel points laid, nested tools released and following their host).
 * stats: the step's timings. Fails with NH_ERR_NUMERIC (the coupled step;
 * the constraint solve not converged, message with the row count; a tool
 * state not finite), NH_ERR_MEMORY. */
int nh_contact_step(nh_contact *c, nh_system *sys, const nh_integrator *in, const nh_mesh *mesh,
                    const double *f_ext, double *u, double *v, double t_new, nh_step_stats *stats);

/* One pseudo-time step t_new − h → t_new of the quasi-static mode
 * (docs/interaction.md, "Quasi-static mode"): Newton iterations of the
 * equilibrium of tissue and tools with the rows of every constraint
 * rebuilt at each iterate (nh_step_coupled with in->quasi_static; the
 * tools' bases moved by the motion's travel over the step in the first
 * iteration), until the tissue's relative residual and each tool's
 * correction (relative to its increments in the step) are below
 * in->tolerance; then the constraints' forces move the states on as in
 * nh_contact_step. An iteration that pushes a skull point without a row
 * through the skull is solved again with that point's row. v is not
 * changed (0 in the quasi-static mode). Fails with NH_ERR_NUMERIC (no
 * convergence in in->max_iterations, with the residuals; the coupled
 * iteration's errors): the state is then that of the last iterate, and
 * the caller restores what it saved. NH_ERR_MEMORY. */
int nh_contact_solve_static(nh_contact *c, nh_system *sys, const nh_integrator *in,
                            const nh_mesh *mesh, const double *f_ext, double *u, double *v,
                            double t_new, nh_step_stats *stats);

/* After the mesh changed (refinement): relocate every embedded point by its
 * material coordinates. NH_ERR_INTERNAL if one is no longer in the mesh. */
int nh_contact_relocate(nh_contact *c, const nh_mesh *mesh);

/* What a tool does now (tools.csv). Forces are the tissue's on the tool in
 * N: axial = −F·t (t the tip tangent: positive resists insertion),
 * lateral = |F − (F·t) t|; depth = arc length from the entry point to the
 * tip (0 outside). */
typedef struct {
  double tip[3];
  double depth;
  double axial_force, lateral_force;
  nh_tool_state state;
} nh_tool_report;
void nh_contact_report(const nh_contact *c, int tool, nh_tool_report *r);

/* Tool k's tip disc in the last step (docs/interaction.md, "Tip disc"): the
 * puncture rows (its group's outer tool, before the puncture) or the tip
 * rows (the group's tip tool after it). force: |λ| / τ of the disc's three
 * rows, N (τ the rows' time scale: h, or 1 quasi-static); radius: the
 * disc's; node[0..n_nodes): the tissue nodes its rows act on (the last
 * step's rows; valid until the next step). active = 0 (the rest zero) when
 * the tool had no such rows or they carried no force. */
typedef struct {
  int active;
  double force, radius;
  const int *node;
  int n_nodes;
} nh_tip_disc;
void nh_contact_tip_disc(const nh_contact *c, int tool, double tau, nh_tip_disc *d);

/* The host's force on released nested tool k in the last step (N, summed
 * over its rows holding it on the host's axis, docs/interaction.md "Nested
 * tools"; τ the rows' time scale: h, or 1 quasi-static); zero for a tool
 * that had none. The host carries −f. */
void nh_contact_nest_force(const nh_contact *c, int tool, double tau, double f[3]);

/* Of the last step: the constraint rows, the groups whose tip cut (slid
 * forward and moved the front), the channel points laid so far, and what
 * the coupled solve did (timings; sweeps, residual, friction rows sticking
 * and sliding: nh_mcp_stats). */
typedef struct {
  int rows, cut, path_points;
  int skull_contacts;    /* skull points pressing (λ > 0) at the end of the step */
  double skull_force[3]; /* N: the skull's total force on the tissue (nh_skull_force) */
  nh_coupled_stats solve;
} nh_contact_stats;
void nh_contact_stats_get(const nh_contact *c, nh_contact_stats *stats);
/* The first tip row of each group whose tip cut in the last step (its
 * three rows: n1, n2, t), at most cap of them into row; returns how many
 * (0 for c = NULL). */
int nh_contact_fronts(const nh_contact *c, int *row, int cap);
/* Set the anchoring error of the front whose tip rows start at `row` (a
 * row of nh_contact_fronts) from e (m), the estimated error of its disc's
 * mean displacement in the last step (adapt/dwr_front.c): its material
 * point moves by δX with x̄_D(X + δX; u) = x̄_D(X; u) − e (anchor.c; 0 if
 * that point leaves the tissue). NH_ERR_MEMORY. */
int nh_contact_set_front_error(nh_contact *c, const nh_mesh *mesh, const double *u, int row,
                               const double e[3]);
/* How many shaft points' axial friction rows stuck in the last step with
 * no axial data error estimated since they last slid (0 for c = NULL); the
 * first cap of them into row (may be NULL) as their first rows (n1, n2,
 * t). */
int nh_contact_stuck_points(const nh_contact *c, int *row, int cap);
/* Set the axial data error of the shaft point whose rows start at `row`
 * (a row of nh_contact_stuck_points) from e (m), the estimated error
 * t · (u − u_h) of its axial row's tissue part in the last step with that
 * row free (adapt/dwr_front.c, "Shaft points"): δc = −e on that row until
 * it slides (anchor.c). */
void nh_contact_set_point_error(nh_contact *c, int row, double e);
/* The constraint rows of the last step with their forces (the goal
 * estimate's constrained dual, adapt/dwr.c); NULL for c = NULL. */
const nh_rows *nh_contact_rows(const nh_contact *c);
/* The change of the rows' constraints when sampled one lattice finer, at
 * the tissue state u (the goal estimate's constraint-data term,
 * docs/theory.md §6.6, "Constraint data"; nh_skull_data_change for the
 * skull's rows; for the tools' rows, those of the anchors with an
 * anchoring error, anchor.c, the rest 0):
 * dc (may be NULL) the change of each row's gap at u, dw the change of its
 * linearisation applied to the fields w (3 n_nodes each), rows->m per
 * field (rows = nh_contact_rows(c)). NH_ERR_MEMORY, or the cut-cell
 * quadrature's failure. The tools' rows of an anchor (a front, a channel
 * point) change as if anchored at the exact solution's material point
 * (nh_contact_set_front_error; docs/theory.md §6.6, "Anchoring"). */
int nh_contact_data_change(nh_contact *c, const nh_mesh *mesh, const double *u, int n_fields,
                           const double *w, double *dc, double *dw);

/* Force per row of a tool's points for output: for each node of tool k,
 * the sum of the constraint forces (N, on the tool) distributed to its
 * nearest node; f: 3 per node. */
void nh_contact_node_forces(const nh_contact *c, int tool, double *f);

/* The tools' and constraints' state (beams, nesting, states, punctures,
 * channels with their warm-start multipliers, the last step's statistics) as
 * bytes, for checkpoints (contact/state.c): *out (malloc'd, caller frees),
 * *size. NH_ERR_MEMORY. */
int nh_contact_state_save(const nh_contact *c, unsigned char **out, size_t *size);
/* Restore a state saved by nh_contact_state_save, on a contact created from
 * the same scene and mesh. NH_ERR_INPUT if it does not fit, NH_ERR_MEMORY. */
int nh_contact_state_load(nh_contact *c, const unsigned char *data, size_t size);
/* ---- skull contact (contact/skull.c) ----
 * A rigid skull: the tissue's implicit surface offset outwards by `gap`,
 * with frictionless unilateral contact rows of surface points (one per cut
 * leaf, weighted by the area it stands for) solved with the tools' rows by
 * nh_step_coupled (docs/interaction.md, "Skull contact"). */
typedef struct nh_skull nh_skull;

/* A skull around `domain` (immersed: not a box) at distance gap >= 0.
 * Fails with NH_ERR_INPUT (box domain, bad gap; no location in the
 * message: the caller adds it), NH_ERR_MEMORY. */
int nh_skull_create(const nh_domain *domain, double gap, nh_skull **out);
void nh_skull_destroy(nh_skull **skull);
/* The lattice depth of the integrated leaves' surface quadrature the points
 * come from (default NH_CUT_DEPTH; the environment variable NH_SKULL_DEPTH
 * sets it at creation, a diagnostic: docs/dbs.md); the next nh_skull_build
 * uses it. NH_ERR_INPUT outside 0 ..= NH_CUT_DEPTH_MAX − 1. */
int nh_skull_set_depth(nh_skull *skull, int depth);
/* The kind of the skull's rows (default NH_SKULL_ROWS_POINTS): one per
 * clustered surface point of a cut leaf, or NH_SKULL_ROWS_MORTAR, one
 * weighted-gap row per tissue node and normal cluster of the surface
 * samples its shape function sees (docs/theory.md §5c, "Weighted-gap
 * rows"); the next nh_skull_build uses it. */
void nh_skull_set_rows(nh_skull *skull, nh_skull_rows_kind kind);
/* A weighted-gap row at a displacement (nh_skull_weighted_gaps): its gap
 * g_a = Σ_q w_q N_a(X_q) g(x_q) / D_a, unit inward direction, the weighted
 * mean rest position Σ_q w_q N_a(X_q) X_q / D_a of its samples, and its area D_a. */
typedef struct {
  double g, dir[3], X[3], area;
} nh_skull_row_info;
/* Every weighted-gap row at u, in build order (out: nh_skull_points of
 * them); returns their number (0 for point rows). *dropped (may be NULL):
 * the area of the samples whose rows were dropped (leaves with less than
 * NH_FILL_MIN tissue only). For the tests. */
int nh_skull_weighted_gaps(const nh_skull *skull, const nh_mesh *mesh, const double *u,
                           nh_skull_row_info *out, double *dropped);
/* The contact points of the mesh's surface (rest shape), after creation;
 * nh_skull_relocate after refinement keeps the warm starts. */
int nh_skull_build(nh_skull *skull, const nh_mesh *mesh);
int nh_skull_relocate(nh_skull *skull, const nh_mesh *mesh);
/* Number of contact points, and the surface area they represent (m²). */
int nh_skull_points(const nh_skull *skull);
double nh_skull_area(const nh_skull *skull);
/* Append the rows of the points that may touch the skull in the step of
 * length h from the tissue state (u, v) (gap below twice their closing in
 * a step plus 1 % of their cell's edge, or pushing in the last step). */
int nh_skull_rows(nh_skull *skull, const nh_mesh *mesh, const double *u, const double *v, double h,
                  nh_rows *rows);
/* After the solved step: keep each row's impulse (warm start), and the
 * total contact force on the tissue. */
void nh_skull_end_step(nh_skull *skull, const nh_rows *rows, double h);
/* The last step's total contact force on the tissue (N) and the number of
 * rows that pushed (may be NULL). */
void nh_skull_force(const nh_skull *skull, double force[3], int *active);
/* The skull's level function at x: φ_skull = U/|∇U| (m; the skull is
 * {φ_skull ≥ gap}), U the domain's outer hull (nh_domain_hull_level: the
 * analytic brain without its fissure, so the skull stays out of it; a mask's
 * or surface's own F), and n[3] = ∇U/|∇U|, its outward unit normal. */
double nh_skull_level(const nh_skull *skull, const double x[3], double n[3]);
/* The largest penetration φ_skull(x) − gap over all points at u (m, 0 if none). */
double nh_skull_penetration(const nh_skull *skull, const nh_mesh *mesh, const double *u);
/* The skull's state for a checkpoint (contact/state.c): each point's warm
 * start λ and the last step's force. The points themselves are rebuilt from
 * the mesh (nh_skull_build), so loading needs the skull of the same mesh:
 * NH_ERR_INPUT when the point count differs; a short read is left in r. */
void nh_skull_state_save(const nh_skull *skull, nh_bytes *b);
int nh_skull_state_load(nh_skull *skull, nh_byte_reader *r);
/* The largest penetration at u of the points that had no row in the last
 * nh_skull_rows, relative to their cell's edge (0 if none): a solve that
 * moved a point through the skull without its row (quasi-static Newton
 * iterations check it and solve again with the point's approach known). */
double nh_skull_missed(const nh_skull *skull, const nh_mesh *mesh, const double *u);
/* For each point with a row in the last nh_skull_rows (index p->row of that
 * row set), the change of its constraint when its leaf's points are taken
 * one lattice finer (the surface quadrature at depth + 1, or 12³ sub-cells
 * for `scaled`; docs/theory.md §6.6, "Constraint data"): the finer points
 * nearest to it, with weights ω_j = A_j / Σ A_j of their areas, give
 *   dc[row] = Σ_j ω_j (g_j(u) − g(u))                (may be NULL)
 *   dw[stride q + row] = Σ_j ω_j (n_j·w_q(P_j) − n·w_q(P)),  q < n_fields
 * with g = gap − φ(x) at the current positions x = P + u(P) and n the
 * rows' inward normals there (the rest normal on a crease): the change of
 * the gap at u and of the row's linearisation applied to the fields w
 * (3 n_nodes each). Other entries are not touched. The finer points are
 * cached per leaf. NH_ERR_MEMORY, or the cut-cell quadrature's failure. */
int nh_skull_data_change(nh_skull *skull, const nh_mesh *mesh, const double *u, int n_fields,
                         const double *w, int stride, double *dc, double *dw);

#endif
