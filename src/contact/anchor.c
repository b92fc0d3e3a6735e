/* anchor.c — the anchoring error of the channel's front and points, and
 * the change of the tools' rows it makes (docs/theory.md §6.6,
 * "Anchoring"; the goal estimate's constraint-data term, adapt/dwr.c).
 *
 * A cut moves the front to the material point X_f whose tip disc has its
 * mean at the tip under the step's discrete solution (channel.c); the
 * exact solution would have put it at X_f + δX, δX = −F⁻¹ e with e the
 * error of the disc's mean displacement at that step (estimated by
 * adapt/dwr_front.c and handed here by nh_contact_set_front_error, which
 * solves x̄_D(X_f + δX; u_h) = x̄_D(X_f; u_h) − e for δX with the same
 * Newton as the cut, nh_material_point, rather than forming F⁻¹). Each
 * point keeps its δX (nh_cpoint.dX): the front carries it from cut to cut
 * until the next estimate replaces it, and a channel point laid between
 * the last point and the front gets the interpolation of theirs, as its
 * material position is (channel.c, nh_channel_lay).
 *
 * The rows holding an anchor then hold the wrong material point. The true
 * anchor's row differs from the step's by its tissue part: the disc (or,
 * for a shaft point, the shape values) at X + δX instead of X. As for the
 * skull's finer points (nh_skull_data_change), the data change of row i is
 *     δc_i = n_i · (x̄(X + δX; u) − x̄(X; u)),   x = X + u,
 *     δ(J w)_i = n_i · (w̄(X + δX) − w̄(X))
 * (the means over the same rule, rebuilt at X + δX; a shaft point's axial
 * row is a friction row on the slip rate whose gap is not the point's
 * position (channel.c, nh_tie_rows): its δc is not that of δX but the
 * error of the tissue's axial displacement there when the point stuck,
 * δc = −e_p (nh_cpoint.dc_axial; adapt/dwr_front.c, "Shaft points"), which
 * the row keeps until the point slides; δ(J w) as the others'),
 * and the goal estimate
 * adds C_q = Σ_i (Λ_i δ(J z_q)_i − μ_qi δc_i / c_K). Sign convention: δX
 * is the exact anchor minus the discrete one, so δc is the exact data
 * minus the discrete, as for the skull, and C_q estimates J(u) − J(u_h)
 * as the rest of the estimate does.
 *
 * The entry point (channel point 0) is placed on the rest surface, not by
 * a solution: its δX is 0. The puncture rows and the rows between tools
 * have no anchor. */
#include "contact/contact_impl.h"

#include <string.h>

/* Row r's tissue part applied to the nodal field w (3 per node), with
 * positions (X + w) if rest is set. */
static void nh_anchor_row_mean(const nh_rows *rows, int r, const nh_mesh *m, const double *w,
                               int rest, double x[3]) {
  x[0] = x[1] = x[2] = 0.0;
  for (int s = rows->start[r]; s < rows->start[r + 1]; s++) {
    const int a = rows->node[s];
    if (a < 0) continue;
    for (int i = 0; i < 3; i++)
      x[i] += rows->N[s] * ((rest ? m->X[3 * a + i] : 0.0) + (w ? w[3 * a + i] : 0.0));
  }
}

/* The moved anchor q's mean of the field v (positions X + v if rest): over
 * the disc d if it has samples, else q's cell with the shape values N. */
static void nh_anchor_moved_mean(const nh_disc *d, const nh_mesh *m, const nh_cpoint *q,
                                 const double N[8], const double *v, int rest, double x[3]) {
  x[0] = x[1] = x[2] = 0.0;
  const int n = d->n ? d->n : 8;
  for (int k = 0; k < n; k++) {
    const int a = d->n ? d->node[k] : m->cells[8 * q->cell + k];
    const double w = d->n ? d->w[k] : N[k];
    for (int i = 0; i < 3; i++)
      x[i] += w * ((rest ? m->X[3 * a + i] : 0.0) + (v ? v[3 * a + i] : 0.0));
  }
}

/* The rows r..r + 2 of anchor p (tip: a front's, else a shaft point's)
 * moved to p->X + p->dX: their data change
 * (dc, may be NULL) and their linearisation's change on the n fields w
 * (dw, rows->m per field, may be NULL), added. A disc row (ρ > 0 in its
 * rule) is rebuilt with its rule at the moved centre. */
static int nh_anchor_rows_change(const nh_rows *rows, const nh_mesh *m, const double *u,
                                 const nh_cpoint *p, int tip, int n, const double *w, double *dc,
                                 double *dw) {
  if (p->row < 0 || p->row + 3 > rows->m) return NH_OK;
  const int r0 = p->row, rm = rows->m;
  if (!tip && dc) dc[r0 + 2] += p->dc_axial;
  if (!(p->dX[0] != 0.0 || p->dX[1] != 0.0 || p->dX[2] != 0.0)) return NH_OK;
  const double *rule = rows->disc + 10 * r0;
  nh_cpoint q = *p;
  /* the rows' anchor: a disc row's rule keeps its centre (a front that cut
   * at the end of the step has moved on since its rows were written) */
  const double *X0 = rule[9] > 0.0 ? rule : p->X;
  double X[3] = {X0[0] + p->dX[0], X0[1] + p->dX[1], X0[2] + p->dX[2]};
  if (nh_point_set(m, &q, X)) return NH_OK; /* the exact anchor outside the mesh: no term */
  nh_disc d = {0};
  if (rule[9] > 0.0) {
    int rc = nh_disc_build(&d, m, &q, rule + 3, rule + 6, rule[9]);
    if (rc || d.n == 0) {
      nh_disc_free(&d);
      return rc;
    }
  }
  double N[8];
  nh_hex_shape(q.xi, N);
  for (int k = 0; k < 3; k++) {
    const int r = r0 + k;
    const double *dir = rows->dir + 3 * r;
    double x1[3], x0[3];
    if (dc && (tip || k < 2)) { /* a shaft point's axial row has no position data */
      nh_anchor_moved_mean(&d, m, &q, N, u, 1, x1);
      nh_anchor_row_mean(rows, r, m, u, 1, x0);
      dc[r] += nh_vec3_dot(dir, x1) - nh_vec3_dot(dir, x0);
    }
    for (int f = 0; f < n && dw; f++) {
      const double *wf = w + 3 * (size_t)m->n_nodes * f;
      nh_anchor_moved_mean(&d, m, &q, N, wf, 0, x1);
      nh_anchor_row_mean(rows, r, m, wf, 0, x0);
      dw[(size_t)rm * f + r] += nh_vec3_dot(dir, x1) - nh_vec3_dot(dir, x0);
    }
  }
  nh_disc_free(&d);
  return NH_OK;
}

int nh_anchor_data_change(const nh_contact *c, const nh_mesh *m, const double *u, int n,
                          const double *w, double *dc, double *dw) {
  for (int g = 0; g < c->n_groups; g++) {
    const nh_group *G = &c->groups[g];
    if (G->tip_tool >= 0) NH_TRY(nh_anchor_rows_change(&c->rows, m, u, &G->front, 1, n, w, dc, dw));
    for (int i = 1; i < G->n_chan; i++)
      NH_TRY(nh_anchor_rows_change(&c->rows, m, u, &G->chan[i], 0, n, w, dc, dw));
  }
  return NH_OK;
}

int nh_contact_fronts(const nh_contact *c, int *row, int cap) {
  int n = 0;
  for (int g = 0; c && g < c->n_groups && n < cap; g++) {
    const nh_group *G = &c->groups[g];
    if (G->cut && G->tip_tool >= 0 && G->front.row >= 0 && G->front.row + 3 <= c->rows.m)
      row[n++] = G->front.row;
  }
  return n;
}

int nh_contact_stuck_points(const nh_contact *c, int *row, int cap) {
  int n = 0;
  for (int g = 0; c && g < c->n_groups; g++) {
    const nh_group *G = &c->groups[g];
    for (int i = 1; i < G->n_chan; i++) {
      const int r = G->chan[i].row;
      if (r < 0 || r + 3 > c->rows.m || c->rows.law[r + 2].kind != NH_ROW_FRICTION ||
          c->rows.law[r + 2].sliding || G->chan[i].dc_axial_set)
        continue;
      if (row && n < cap) row[n] = r;
      n++;
    }
  }
  return n;
}

void nh_contact_set_point_error(nh_contact *c, int row, double e) {
  for (int g = 0; g < c->n_groups; g++) {
    nh_group *G = &c->groups[g];
    for (int i = 1; i < G->n_chan; i++)
      if (G->chan[i].row == row) G->chan[i].dc_axial = -e, G->chan[i].dc_axial_set = 1;
  }
}

int nh_contact_set_front_error(nh_contact *c, const nh_mesh *m, const double *u, int row,
                               const double e[3]) {
  for (int g = 0; g < c->n_groups; g++) {
    nh_group *G = &c->groups[g];
    if (G->tip_tool < 0 || G->front.row != row) continue;
    const double *rule = c->rows.disc + 10 * row;
    nh_cpoint p = G->front;
    double x[3];
    if (rule[9] > 0.0) {
      NH_TRY(nh_disc_build(&c->disc, m, &G->front, rule + 3, rule + 6, rule[9]));
      nh_disc_position(&c->disc, m, u, x);
    } else {
      nh_point_position(m, u, &G->front, x);
    }
    for (int i = 0; i < 3; i++) x[i] -= e[i];
    int rc = nh_material_point(m, u, x, G->front.X, rule + 3, rule + 6, rule[9], &c->disc, &p);
    if (rc == NH_ERR_MEMORY) return rc;
    for (int i = 0; i < 3; i++) G->front.dX[i] = rc ? 0.0 : p.X[i] - G->front.X[i];
  }
  return NH_OK;
}
