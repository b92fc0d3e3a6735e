/* puncture.c — the puncture constraint (the seed's Eqs. 5-7;
 * docs/interaction.md, "Puncture").
 *
 * The entry point P is where the tool's axis ray (base + τ direction)
 * first enters the domain's shape, with n_out the shape's outward normal
 * there (nh_domain_ray_entry: a face of a box, ∇F / |∇F| on the implicit
 * surface of an immersed domain); n_out only decides when the tip is near
 * enough for the rows. Until the tool touches, the entry follows the
 * tissue's motion (nh_puncture_refresh).
 *
 * Rows, while the group has not punctured and the tip is within reach of P
 * (g = t · (x_P − x_tip), t the tip tangent, force on the tissue along +n):
 *   t         unilateral, capped at the puncture force × h: g ≥ 0, and the
 *             row yields (w ≤ 0) once its force reaches the cap;
 *   t1, t2    a Coulomb disc pair across t, bound μ λ_t.
 * After the solve, a normal force at its cap (or any positive normal force
 * for a zero puncture force) is the puncture (Eq. 6): the state machine
 * opens the channel at P (contact.c). */
#include "contact/contact_impl.h"

#include <string.h>

void nh_puncture_init(nh_group *G, const nh_tool_spec *sp, const nh_mesh *m) {
  double tau;
  G->has_entry =
      nh_domain_ray_entry(&m->domain, sp->base, sp->direction, &tau, G->entry.X, G->n_out);
  if (G->has_entry && nh_point_set(m, &G->entry, G->entry.X)) G->has_entry = 0;
}

/* The entry point of a tool that has not touched the tissue yet, on the
 * tissue as it is now: the material point X on the domain's surface whose
 * current position X + u(X) lies on the tool's line. The tissue may have
 * moved since the entry was found (brain shift before the insertion), so
 * the ray is pulled back by u at the last estimate and intersected with the
 * rest surface again, until X stops moving (a fixed point of
 * X = entry(line − u(X)); u varies slowly over a cell, so a few iterations
 * suffice). With u = 0 at the entry, X is unchanged. */
static void nh_puncture_refresh(nh_group *G, const nh_tool_spec *sp, const nh_mesh *m,
                                const double *u) {
  for (int it = 0; it < 20; it++) {
    double x[3], o[3], X[3], n[3], tau;
    nh_point_position(m, u, &G->entry, x);
    for (int i = 0; i < 3; i++) o[i] = sp->base[i] - (x[i] - G->entry.X[i]);
    if (!nh_domain_ray_entry(&m->domain, o, sp->direction, &tau, X, n)) return;
    double dX[3] = {X[0] - G->entry.X[0], X[1] - G->entry.X[1], X[2] - G->entry.X[2]};
    double moved = sqrt(nh_vec3_dot(dX, dX));
    nh_cpoint p = G->entry;
    if (nh_point_set(m, &p, X)) return;
    G->entry = p;
    memcpy(G->n_out, n, sizeof n);
    if (moved <= 1e-9 * nh_mesh_cell_size(m, G->entry.cell)) return;
  }
}

/* Rows for this step? The tip (xt) is within reach of the entry point (xp)
 * along the surface normal: two steps of the tool's base and tip speeds,
 * plus 1e-3 of the entry cell. */
static int nh_puncture_near(const nh_group *G, const nh_tool *tl, const nh_mesh *m,
                            const double xt[3], const double xp[3], double h) {
  nh_beam *b = tl->beam;
  double gap = nh_vec3_dot(G->n_out, xt) - nh_vec3_dot(G->n_out, xp);
  const double *vb = nh_beam_velocities(b) + 6 * (nh_beam_nodes(b) - 1);
  double reach = 2.0 * h *
                     (fabs(tl->base_v[0]) + fabs(tl->base_v[1]) + fabs(tl->base_v[2]) +
                      sqrt(nh_vec3_dot(vb, vb))) +
                 1e-3 * nh_mesh_cell_size(m, G->entry.cell);
  return !(gap > reach);
}

int nh_puncture_rows(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u, double h) {
  nh_tool *tl = &c->tools[G->outer];
  const nh_tool_spec *sp = tl->spec;
  G->entry_row = -1;
  if (G->punctured || !G->has_entry) return NH_OK;
  if (G->entry.lam[0] == 0.0) nh_puncture_refresh(G, sp, m, u); /* not touching yet */
  double xt[3], tt[3], J[36], xi, xp[3];
  int e;
  nh_beam *b = tl->beam;
  nh_beam_point(b, nh_beam_length(b), xt, tt, &e, &xi, J);
  /* the tool's cross-section pressing on the surface: the disc in the
   * surface's plane (docs/interaction.md, "Tip disc") */
  NH_TRY(nh_disc_build(&c->disc, m, &G->entry, G->n_out, NULL, nh_tip_radius(sp)));
  nh_disc_position(&c->disc, m, u, xp);
  if (!nh_puncture_near(G, tl, m, xt, xp, h)) {
    memset(G->entry.lam, 0, sizeof G->entry.lam);
    G->entry.slid = 0;
    return NH_OK;
  }
  /* The rows act along the tip's axis t and across it, not along the
   * face normal: on an oblique tool a normal row's force has a part
   * across the axis that bends the tool while the surface holds (a whole
   * step, however short the contact) and the tip then cuts on, off its
   * line (docs/interaction.md, Puncture). */
  double tan1[3] = {1, 0, 0}, tan2[3], d[3] = {xp[0] - xt[0], xp[1] - xt[1], xp[2] - xt[2]};
  double gap = nh_vec3_dot(tt, d);
  if (fabs(tt[0]) > 0.9) tan1[0] = 0, tan1[1] = 1;
  double ct = nh_vec3_dot(tan1, tt);
  for (int i = 0; i < 3; i++) tan1[i] -= ct * tt[i];
  nh_vec3_normalize(tan1);
  nh_vec3_cross(tan1, tt, tan2);
  const double *dirs[3] = {tt, tan1, tan2};
  nh_rows *rows = &c->rows;
  for (int q = 0; q < 3; q++) {
    int r = nh_rows_add(rows);
    if (r < 0) return NH_ERR_MEMORY;
    if (q == 0) G->entry_row = r;
    NH_TRY(nh_disc_row(rows, r, &c->disc));
    memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
    rows->tool[r] = tl->dyn, rows->elem[r] = e;
    memcpy(rows->J + 36 * r, J, sizeof J);
    rows->gap[r] = q == 0 ? gap : 0.0;
    rows->lambda[r] = G->entry.lam[q];
    /* The normal yields at the puncture force (Eq. 6 within the step). */
    rows->law[r] =
        q == 0 ? (nh_row_law){NH_ROW_UNILATERAL, -1, -1, 0.0, sp->puncture_force * h, -1, 0.0, 0, 0}
               : (nh_row_law){NH_ROW_FRICTION,     G->entry_row,  -1,
                              sp->friction,        0.0,           G->entry_row + 1,
                              sp->friction_static, G->entry.slid, 0};
  }
  return NH_OK;
}

void nh_puncture_update(nh_contact *c, nh_group *G, double h, nh_group_events *ev) {
  if (G->entry_row < 0) return;
  nh_tool *tl = &c->tools[G->outer];
  for (int q = 0; q < 3; q++) {
    G->entry.lam[q] = c->rows.lambda[G->entry_row + q];
    nh_tool_add_force(tl, &c->rows, G->entry_row + q, h, nh_beam_length(tl->beam));
  }
  G->entry.slid = c->rows.law[G->entry_row + 1].sliding;
  double fn = G->entry.lam[0] / h, fp = tl->spec->puncture_force;
  ev->puncture_rows = 1;
  ev->touching = fn > 0;
  /* the normal reached its cap, the puncture force (a zero puncture force:
   * no cap, any contact punctures) */
  ev->yielded = fp > 0 ? fn >= fp * (1.0 - 1e-7) : fn > 0.0;
}
