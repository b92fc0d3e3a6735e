/* dwr_front.c — the error of a tool's front at the step that anchors it
 * (docs/theory.md §6.6, "Anchoring"; docs/dbs.md, "What the local dual
 * does not see").
 *
 * When a tool's tip cuts, the contact module moves the channel's front to
 * the material point X_f whose tip disc has its mean at the tip under the
 * step's solution: x̄_D(X_f; u_h) = x_tip (contact/channel.c). The exact
 * solution u of the step puts it at X*: x̄_D(X*; u) = x_tip. With
 * e = x̄_D(X_f; u) − x̄_D(X_f; u_h) the error of the disc's mean
 * displacement, x̄_D(X*; u_h) = x_tip − e to first order (the error field
 * smooth over the disc's motion δX = X* − X_f), i.e. δX = −F⁻¹ e. Every
 * later row that holds the front (and the channel points laid from it)
 * then holds the wrong material point: a change of those rows' data that
 * the step's own estimate cannot see, and which docs/dbs.md measured as
 * 98 % of the DBS hold's error. The contact module keeps δX per anchor and
 * turns it into the rows' data change (nh_contact_data_change), which the
 * goal estimate weights by the dual's multipliers (dwr.c, "Constraint
 * data").
 *
 * This file estimates e at the cutting step: the tip rows' tissue parts
 * are the functionals J_q(v) = n_q · Σ_a w_a v_a (q = 0, 1, 2: the rows'
 * directions n1, n2, t, orthonormal, w the disc's node weights), estimated
 * by the goal machinery (nh_dwr_functionals: the constrained dual of the
 * rows below, recovered-error products, geometry and constraint data
 * terms), and e = Σ_q E_q n_q. The goal estimate of the step carries the
 * fronts' duals alongside the goals' (nh_dwr_result.fronts), so that the
 * primal's share (its corotation, recovered stress and Gauss-point errors)
 * is computed once per step; each dual's terms are those of its own
 * estimate, the same numbers as an estimate of the front alone
 * (nh_dwr_front_error). The rows that hold the disc in the dual (the
 * lateral rows, the axial one when it sticks) make their own
 * functional's dual z = 0 with μ its unit vector: their E_q is then the
 * constraint-data term alone, −δc_q, the old front's anchoring error
 * carried to the new front; the cutting row (sliding: not in the dual)
 * gets the step's own discretisation error of the disc's axial mean
 * displacement under the cutting force.
 *
 * Friction rows. In this dual every friction row but the front's own axial
 * row counts as sliding (not held): a sticking friction row holds the
 * step's increment (its gap is the slip, or 0), not the total displacement
 * whose error e is. Held, as in the goals' dual, a shaft point's axial row
 * that sticks in a cutting step halved e there on the DBS case (docs/dbs.md,
 * "The front's anchoring error").
 *
 * Shaft points. A channel point's axial row is a friction row on the slip
 * rate: while it sticks, the tissue at the point follows the tool over each
 * step, so the error of the tissue's total axial displacement there stays
 * what it was when the point stuck. With the row free in the dual (its
 * force taken as data, as a sliding row's friction bound is), the step's
 * estimate of J_p(v) = t · Σ N_a v_a, the axial displacement of the row's
 * tissue part, is that error, e_p: estimated at the first estimate that
 * finds the point sticking, kept by the contact module (nh_cpoint.dc_axial
 * = −e_p) as the axial row's data change until the point slides again
 * (contact/anchor.c), and weighted by the goals' duals, which hold that
 * row, as the front's (μ δc / c_K). Estimated once per sticking, not at
 * every sliding step: on the phantom's goal run the sliding points' columns
 * made the goal estimate's steps 5 % slower. The points' duals share one
 * set of held rows (every friction row free, as in the fronts' duals: a
 * sticking row holds the step's increment, not the total displacement), one
 * column each. */
#include "adapt/adapt_impl.h"

#include <string.h>

/* Add row r's tissue part along its direction, n_r · Σ_a N_a v_a, to the
 * functional j (3 per node). */
static void nh_dwr_row_functional(const nh_rows *rows, int r, double *j) {
  const double *n = rows->dir + 3 * r;
  for (int s = rows->start[r]; s < rows->start[r + 1]; s++) {
    if (rows->node[s] < 0) continue;
    for (int k = 0; k < 3; k++) j[3 * (size_t)rows->node[s] + k] += rows->N[s] * n[k];
  }
}

/* The rows a front's or shaft point's dual holds: the active rows with
 * every friction row free but `keep` (−1: none). A sticking friction row
 * holds the step's increment, not the total displacement whose error these
 * duals estimate (the header). */
static void nh_dwr_hold_but_friction(const nh_rows *rows, int keep, unsigned char *active) {
  nh_dwr_active_rows(rows, active);
  for (int i = 0; i < rows->m; i++)
    if (rows->law[i].kind == NH_ROW_FRICTION && i != keep) active[i] = 0;
}

int nh_dwr_front_setup(const nh_rows *rows, int n_nodes, int row, double *j,
                       unsigned char *active) {
  NH_CHECK(rows && row >= 0 && row + 3 <= rows->m, NH_ERR_INTERNAL,
           "front error: rows %d..%d are not among the step's %d", row, row + 2,
           rows ? rows->m : 0);
  const size_t n3 = 3 * (size_t)n_nodes;
  memset(j, 0, 3 * n3 * sizeof(double));
  for (int q = 0; q < 3; q++) nh_dwr_row_functional(rows, row + q, j + n3 * q);
  nh_dwr_hold_but_friction(rows, row + 2, active); /* the front's own axial row held */
  return NH_OK;
}

int nh_dwr_points_setup(const nh_rows *rows, int n_nodes, int n, const int *row, double *j,
                        unsigned char *active) {
  const size_t n3 = 3 * (size_t)n_nodes;
  memset(j, 0, (size_t)n * n3 * sizeof(double));
  for (int p = 0; p < n; p++) {
    NH_CHECK(rows && row[p] >= 0 && row[p] + 3 <= rows->m, NH_ERR_INTERNAL,
             "shaft point error: rows %d..%d are not among the step's %d", row[p], row[p] + 2,
             rows ? rows->m : 0);
    nh_dwr_row_functional(rows, row[p] + 2, j + n3 * p);
  }
  nh_dwr_hold_but_friction(rows, -1, active);
  return NH_OK;
}

void nh_dwr_front_vector(const nh_rows *rows, int row, const double E[3], double e[3]) {
  e[0] = e[1] = e[2] = 0.0;
  for (int q = 0; q < 3; q++)
    for (int k = 0; k < 3; k++) e[k] += E[q] * rows->dir[3 * (row + q) + k];
}

int nh_dwr_front_error(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *m,
                       const nh_tissue *t, const nh_hanging *h, const double *u, int row,
                       const nh_geometry_loads *loads, const nh_constraint_data *data,
                       double e[3]) {
  e[0] = e[1] = e[2] = 0.0;
  nh_dwr_fronts front = {1, &row, e, 0, NULL, NULL};
  nh_dwr_goals goals = {0, NULL, 0.0, NULL};
  nh_dwr_result out = {.loads = loads, .data = data, .fronts = &front};
  return nh_dwr_functionals(sys, rows, scale, m, t, h, u, 0, 1, NULL, &goals, &out);
}
