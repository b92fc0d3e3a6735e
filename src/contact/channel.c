/* channel.c — the tip and shaft constraints in the cut channel (the seed's
 * Eqs. 8-9; docs/interaction.md, "Tip" and "Shaft").
 *
 * Once a group has punctured, the channel is a list of tissue material
 * points laid behind the tip one spacing apart, the entry point first, and
 * its front is the material point the tip is anchored to. Every tie between
 * such a point P and a tool point at arc length s uses a frame at the tool
 * point: t the Hermite tangent, n1 the node's second director made
 * orthogonal to t, n2 = t × n1. Rows (nh_rows, solve/solve.h:
 * g = n · (x_P − x_tool), force on the tissue along +n):
 *   shaft point  n1, n2 bilateral (g the lateral offset); t friction with
 *                bound μ |(λ1, λ2)| + friction_per_length × w, w the length
 *                of channel the point carries (nh_shaft_bounds: Σ w is the
 *                inserted length, the line integral) (g = 0;
 *                quasi-static: the slip s − s0 along the tool since the step's
 *                first iteration, so the law holds for the whole step):
 *                it sticks, or slides as the tool moves in or out; a point
 *                that stuck in the last step needs μ_s |(λ1, λ2)| + ... to
 *                start sliding (friction_static; nh_cpoint.slid);
 *                With interaction.torsion_per_length > 0 (dynamic mode) a
 *                fourth, torsional friction row on the tool's spin at s, bound
 *                torsion_per_length × spacing × τ: the tissue resists a turn
 *                of the base, which reaches the tip with a lag;
 *   tip          the same at the front with bound μ |(λ1, λ2)| + cutting
 *                force × τ and g = t · (x_P − x_tip), the axial row
 *                one-sided (λ ≥ 0: it resists the tip's advance, it does
 *                not pull a tip moving back; docs/interaction.md, "Tip").
 * τ is the rows' time scale: the step h (dynamic: λ are impulses), or 1
 * (quasi-static: λ are forces); thresholds are force × τ, forces λ / τ.
 * A bevel tip (tools.N.bevel, Chentanez et al. 2009 §3.5) cuts off its
 * axis: when the tip cuts a distance d, the new front is the material point
 * at x_tip + d tan ψ b, b the tip's n1 (its second director across t), so
 * the lateral rows pull the tip that way in the following steps and the
 * tissue's reaction bends the needle. The base's spin turns b.
 * The tip rows belong to the group's leading tool (the outer tool unless it
 * retracts, else a released nested tool that does not): when their axial
 * row slides forward on its bound the tip cuts (Eq. 8) and the front moves
 * to the material point at the tip, laying channel points on the way. A
 * channel point is tied to the outermost tool of the group whose axis
 * passes it within the tool's length; a retracting tool uncovers the
 * points it leaves, which then have no rows.
 * The hand-over: a point that passes from one tool of the group to another
 * (the cannula retracts past it and the electrode inside covers it) keeps
 * its lateral offset o to the new tool's axis, and its lateral rows hold
 * g = n · (x_P − x_tool − o) for o closed by at most NH_HANDOVER_RATE of
 * the point's spacing per step: the tissue moves onto the new axis over
 * several steps instead of jumping across the difference of the two axes
 * in one (docs/interaction.md, "Nested tools"). */
#include "contact/contact_impl.h"

#include <string.h>

/* The hand-over's rate: the fraction of a point's spacing (one local cell
 * edge) its remaining offset closes per step: 5 % of a cell, as when the
 * spacing was half a cell and the rate 0.1. */
#define NH_HANDOVER_RATE 0.05

int nh_channel_open(nh_group *G, const nh_tool_spec *sp, const nh_mesh *m) {
  if (nh_grow((void **)&G->chan, &G->cap_chan, 1, sizeof *G->chan)) return NH_ERR_MEMORY;
  G->entry.len = nh_point_spacing(sp, m, &G->entry);
  G->entry.tool = -1, G->entry.row = -1;
  memset(G->entry.lam, 0, sizeof G->entry.lam);
  G->entry.slid = 0;
  G->chan[0] = G->entry;
  G->n_chan = 1;
  G->front = G->entry;
  return NH_OK;
}

/* Lay channel points from the last one towards `to`, one per spacing. An
 * explicit spacing finer than the cell a point is laid from is the user's
 * choice: warned once per group, not refused (docs/interaction.md, "Why one
 * point per cell": the rule is sufficient, not necessary). */
static int nh_channel_lay(nh_group *G, const nh_tool_spec *spec, const nh_mesh *m,
                          const nh_cpoint *to) {
  for (;;) {
    const nh_cpoint *last = &G->chan[G->n_chan - 1];
    double d[3] = {to->X[0] - last->X[0], to->X[1] - last->X[1], to->X[2] - last->X[2]};
    double dist = sqrt(nh_vec3_dot(d, d)), sp = nh_point_spacing(spec, m, last);
    if (dist < sp) return NH_OK;
    double cell = nh_mesh_cell_size(m, last->cell);
    if (!G->fine_warned && sp < (1.0 - 1e-9) * cell) {
      nh_log_warn("%s: interaction.spacing %.3g m is finer than the cell the channel reaches "
                  "(edge %.3g m): more shaft rows than the tissue's nodes along the needle can "
                  "satisfy apart, and the shaft may lock (docs/interaction.md, \"Why one point "
                  "per cell\"); 0 lays one point per cell edge",
                  spec->where, sp, cell);
      G->fine_warned = 1;
    }
    double X[3], dX[3];         /* before the array grows: `last` points into it */
    for (int i = 0; i < 3; i++) /* the anchoring error as the position: interpolated (anchor.c) */
      X[i] = last->X[i] + d[i] * sp / dist,
      dX[i] = last->dX[i] + (to->dX[i] - last->dX[i]) * sp / dist;
    if (nh_grow((void **)&G->chan, &G->cap_chan, G->n_chan + 1, sizeof *G->chan))
      return NH_ERR_MEMORY;
    nh_cpoint p = {0};
    if (nh_point_set(m, &p, X)) return NH_OK; /* left the tissue */
    p.len = sp, p.tool = -1, p.row = -1;
    memcpy(p.dX, dX, sizeof dX);
    G->chan[G->n_chan++] = p;
  }
}

void nh_frame_normal(const double *T, const double t[3], double n1[3]) {
  double d = T[1] * t[0] + T[4] * t[1] + T[7] * t[2];
  n1[0] = T[1] - d * t[0], n1[1] = T[4] - d * t[1], n1[2] = T[7] - d * t[2];
  nh_vec3_normalize(n1);
}

/* The tip's frame normal: the tip node's second director made orthogonal
 * to the tip tangent t (the n1 of the tip rows; the bevel direction, and
 * where the tip disc's rings start: the disc turns with the tool, not with
 * the round-off of t's small components, docs/interaction.md "Tip disc"). */
static void nh_tip_normal(nh_beam *beam, const double t[3], double b[3]) {
  nh_frame_normal(nh_beam_directors(beam) + 9 * (nh_beam_nodes(beam) - 1), t, b);
}

/* The torsion row of a shaft point (docs/interaction.md, "Torsional
 * friction"): a friction row on the tool's rate of rotation about its
 * tangent t at s, ω_t(s) = t · ((1 − ξ) ω_e + ξ ω_{e+1}) (the rotations of
 * the element's nodes interpolated as the torsion field of the beam,
 * linear), with bound `threshold` = torsion_per_length × len × τ and g = 0:
 * w = −ω_t(s), so the channel resists the needle's spin and nothing else.
 * The tissue has no rotational DOFs: its reaction couple is not applied (a
 * row without a tissue part). Returns the row or −1 (memory). */
static int nh_torsion_row(nh_rows *rows, const nh_tool *tl, const nh_cpoint *p, int e, double xi,
                          const double t[3], double threshold) {
  int r = nh_rows_add(rows);
  if (r < 0) return -1;
  memcpy(rows->dir + 3 * r, t, 3 * sizeof(double));
  rows->tool[r] = tl->dyn, rows->elem[r] = e;
  double *J = rows->J + 36 * r; /* row-major 3 x 12: (δx1, δw1, δx2, δw2) -> ω(s) */
  for (int i = 0; i < 3; i++) J[12 * i + 3 + i] = 1.0 - xi, J[12 * i + 9 + i] = xi;
  rows->lambda[r] = p->lam[3];
  rows->law[r] = (nh_row_law){NH_ROW_FRICTION, -1, -1, 0.0, threshold, -1, 0.0, 1, 0};
  return r;
}

/* The torsion rows' bound of a shaft point of tool tl (0: none). */
static double nh_torsion_threshold(const nh_contact *c, const nh_tool *tl, const nh_cpoint *p,
                                   double tau) {
  return c->statics ? 0.0 : tl->spec->torsion_per_length * p->len * tau;
}

/* Three rows tying P to tool k's point at s (shaft or tip), and a fourth,
 * the torsion row, when `torsion` > 0; returns the first row or −1
 * (memory). */
static int nh_tie_rows(nh_contact *c, const nh_mesh *m, const double *u, nh_cpoint *p, int k,
                       double s, double threshold, double torsion, int tip) {
  nh_tool *tl = &c->tools[k];
  nh_rows *rows = &c->rows;
  double xb[3], t[3], J[36], xi, xp[3];
  int e;
  nh_beam_point(tl->beam, s, xb, t, &e, &xi, J);
  double n1[3], n2[3];
  nh_frame_normal(nh_beam_directors(tl->beam) + 9 * (xi < 0.5 ? e : e + 1), t, n1);
  if (tip) { /* the tip acts through its cross-section (docs/interaction.md, "Tip disc") */
    if (nh_disc_build(&c->disc, m, p, t, n1, nh_tip_radius(tl->spec))) return -1;
    nh_disc_position(&c->disc, m, u, xp);
  } else {
    nh_point_position(m, u, p, xp);
  }
  nh_vec3_cross(t, n1, n2);
  const double *dirs[3] = {n1, n2, t};
  int first = -1;
  for (int q = 0; q < 3; q++) {
    int r = nh_rows_add(rows);
    if (r < 0) return -1;
    if (q == 0) first = r;
    if (!tip)
      nh_row_tissue(rows, r, m, p);
    else if (nh_disc_row(rows, r, &c->disc))
      return -1;
    memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
    rows->tool[r] = tl->dyn, rows->elem[r] = e;
    memcpy(rows->J + 36 * r, J, sizeof J);
    double g[3] = {xp[0] - xb[0], xp[1] - xb[1], xp[2] - xb[2]};
    if (q == 0 && !tip && p->tool >= 0 && p->tool != k) /* handed over: its offset is allowed */
      for (int i = 0; i < 3; i++) p->handover[i] = g[i] - nh_vec3_dot(g, t) * t[i];
    if (q < 2 && !tip)
      for (int i = 0; i < 3; i++) g[i] -= p->handover[i];
    rows->gap[r] = (q < 2 || tip) ? nh_vec3_dot(dirs[q], g) : 0.0;
    if (q == 2 && !tip && c->statics) { /* the shaft's slip since the step began */
      if (c->iteration == 0 || p->tool != k) p->s0 = s;
      rows->gap[r] = s - p->s0;
    }
    rows->lambda[r] = p->lam[q];
    if (q == 2) /* the tip's axial row resists advance, it cannot pull: one-sided */
      rows->law[r] = (nh_row_law){NH_ROW_FRICTION,           first,     first + 1,
                                  tl->spec->friction,        threshold, -1,
                                  tl->spec->friction_static, p->slid,   tip};
  }
  if (torsion > 0.0 && nh_torsion_row(rows, tl, p, e, xi, t, torsion) < 0) return -1;
  p->row = first, p->tool = k, p->s = s;
  return first;
}

/* Tool k in group G's order: the outer tool, then its released nested tools. */
static int nh_in_group(const nh_contact *c, const nh_group *G, int k) {
  const nh_tool *tl = &c->tools[k];
  return k == G->outer || (tl->host == G->outer && tl->released);
}

/* Which tool of group G covers P, and where: the outermost one whose axis
 * passes P at an arc length in [0, L − clearance]. A point alongside a tool
 * but within its clearance (s in (L − clearance, L]) is covered by none:
 * the tools inside it are in its bore, held by it (nest.c), and a point
 * tied to one of them there would tie the tissue a fraction of a spacing
 * behind the tip rows to the same rigid section. Returns the tool or −1. */
static int nh_cover(const nh_contact *c, const nh_group *G, const double xp[3], double s0,
                    double clear_tip, double *s_out) {
  for (int k = 0; k < c->n; k++) {
    if (!nh_in_group(c, G, k)) continue;
    const nh_tool *tl = &c->tools[k];
    double L = nh_beam_length(tl->beam);
    double s = nh_tool_project(tl->beam, xp, k == G->outer ? s0 : s0 - tl->offset);
    double clear = k == G->tip_tool ? clear_tip : 0.0;
    if (s >= 0.0 && s <= L - clear) {
      *s_out = s;
      return k;
    }
    if (s >= 0.0 && s <= L) return -1; /* within its tip's clearance */
  }
  return -1;
}

/* The leading tool of group G for the tip rows: the outer tool unless it
 * retracts, else a released nested tool that does not; −1 if none. */
static int nh_leader(const nh_contact *c, const nh_group *G, double t, double h) {
  for (int k = 0; k < c->n; k++)
    if (nh_in_group(c, G, k) && nh_tool_speed(c->tools[k].spec, t, h) >= 0.0) return k;
  return -1;
}

int nh_tip_rows(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u, double t, double h,
                double tau) {
  if (!G->punctured) return NH_OK;
  const nh_tool_spec *sp = c->tools[G->outer].spec;
  G->tip_tool = -1;
  int lead = nh_leader(c, G, t, h);
  if (lead < 0 || c->tools[lead].dyn < 0) return NH_OK;
  nh_tool *tl = &c->tools[lead];
  double xt[3], tt[3], xf[3], nt[3];
  const double rho = nh_tip_radius(tl->spec);
  nh_beam_point(tl->beam, nh_beam_length(tl->beam), xt, tt, NULL, NULL, NULL);
  nh_tip_normal(tl->beam, tt, nt);
  NH_TRY(nh_disc_build(&c->disc, m, &G->front, tt, nt, rho));
  nh_disc_position(&c->disc, m, u, xf);
  double ahead = nh_vec3_dot(tt, xf) - nh_vec3_dot(tt, xt),
         sp_f = nh_point_spacing(sp, m, &G->front);
  /* the tip passed the front inside the channel: the front moves to it
   * (quasi-static: at the step's start only; within the step the tip row's
   * gap is the tip's advance past the front, whose slide is the cut) */
  if (ahead < 0.0 && c->iteration == 0) {
    nh_cpoint p = G->front;
    double xa[3]; /* a bevel's front keeps its offset across the tip: it moves along t only */
    for (int i = 0; i < 3; i++) xa[i] = tl->spec->bevel > 0 ? xf[i] - ahead * tt[i] : xt[i];
    int rc = nh_material_point(m, u, xa, G->front.X, tt, nt, rho, &c->disc, &p);
    if (rc == NH_ERR_MEMORY) return rc;
    if (!rc) {
      G->front = p, ahead = 0.0;
      NH_TRY(nh_channel_lay(G, sp, m, &G->front));
    }
  }
  if (ahead <= 0.05 * sp_f) {
    G->tip_tool = lead;
    if (nh_tie_rows(c, m, u, &G->front, lead, nh_beam_length(tl->beam),
                    tl->spec->cutting_force * tau, 0.0, 1) < 0)
      return NH_ERR_MEMORY;
  }
  return NH_OK;
}

/* Friction row r: on its bound? */
static int nh_on_bound(const nh_rows *rows, int r) {
  const nh_row_law *l = &rows->law[r];
  double n = l->normal >= 0 ? fabs(rows->lambda[l->normal]) : 0.0;
  if (l->normal2 >= 0) n = hypot(n, rows->lambda[l->normal2]);
  double b = l->mu * n + l->threshold;
  return fabs(rows->lambda[r]) >= b * (1.0 - 1e-7);
}

int nh_tip_update(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u, double h,
                  nh_group_events *ev) {
  if (G->tip_tool < 0) return NH_OK;
  const nh_rows *rows = &c->rows;
  const nh_tool_spec *sp = c->tools[G->outer].spec;
  nh_tool *tl = &c->tools[G->tip_tool];
  int r = G->front.row;
  ev->covered = 1;
  for (int q = 0; q < 3; q++) {
    G->front.lam[q] = rows->lambda[r + q];
    nh_tool_add_force(tl, rows, r + q, h, nh_beam_length(tl->beam));
  }
  G->front.slid = rows->law[r + 2].sliding;
  if (!nh_on_bound(rows, r + 2) || rows->lambda[r + 2] < 0.0) return NH_OK; /* it sticks */
  /* cut and advance (Eq. 8): the front moves to the material point at the
   * tip; a bevel moves it on by d tan ψ along the tip's bevel direction
   * (d the tip's advance along its tangent past the old front) */
  double xt[3], tt[3], xf[3], nt[3];
  const double rho = nh_tip_radius(tl->spec);
  nh_beam_point(tl->beam, nh_beam_length(tl->beam), xt, tt, NULL, NULL, NULL);
  nh_tip_normal(tl->beam, tt, nt);
  if (tl->spec->bevel > 0) {
    NH_TRY(nh_disc_build(&c->disc, m, &G->front, tt, nt, rho));
    nh_disc_position(&c->disc, m, u, xf);
    const double d = fmax(0.0, nh_vec3_dot(tt, xt) - nh_vec3_dot(tt, xf)),
                 h_bevel = d * tan(tl->spec->bevel * NH_PI / 180.0);
    for (int i = 0; i < 3; i++) xt[i] += h_bevel * nt[i];
  }
  nh_cpoint p = G->front;
  int rc = nh_material_point(m, u, xt, G->front.X, tt, nt, rho, &c->disc, &p);
  if (rc) return rc == NH_ERR_MEMORY ? rc : NH_OK;
  double d[3] = {p.X[0] - G->front.X[0], p.X[1] - G->front.X[1], p.X[2] - G->front.X[2]};
  if (sqrt(nh_vec3_dot(d, d)) > 1e-9 * nh_point_spacing(sp, m, &G->front))
    ev->cut = 1; /* it advanced */
  G->front = p;
  return nh_channel_lay(G, sp, m, &G->front);
}

/* The constant part of the axial bounds (docs/interaction.md, "The line
 * integral"): friction_per_length × w × τ per tied point, w the length of
 * channel it carries. On the ramp's tool (the one with the tip rows, else,
 * with no tip rows — retracting, or re-entering the channel — the tool of
 * the deepest tied point) a point at d = L − s behind that tool's tip has
 * progressed a = max(d − len/2, 0) past where it is tied (d = len/2; the
 * entry point a = d: it carries the channel from the surface on), and
 * carries w = a − a', a' the progress of the next deeper tied point: it
 * joins with w = 0, grows with the tip's advance until the next point
 * joins, then keeps the current length between the two; the bounds sum to
 * friction_per_length × the entry's d, the inserted length, continuous in
 * depth on every grid (the line integral of the shaft's friction). The
 * deepest point carries at most two of its spacings (a tip beyond the
 * channel's last point, as after leaving the tissue, adds no more). A point
 * on another tool of the group carries its spacing, the entry point 1.5 of
 * it. Until the entry point is tied (d below half its spacing) the tip's
 * axial row carries that first part of the channel, friction_per_length ×
 * d. A dynamic step's rows are written at its start: d is taken at its end,
 * d + the ramp tool's prescribed travel over t → t + h (backward Euler, as
 * the quasi-static step's last iteration, whose rows are written at the
 * step's end), so the two modes agree. */
static void nh_shaft_bounds(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u, double t,
                            double h, double tau) {
  int ramp = G->tip_tool;
  for (int i = G->n_chan - 1; ramp < 0 && i >= 0; i--)
    if (G->chan[i].row >= 0) ramp = G->chan[i].tool;
  const double travel = c->statics || ramp < 0 ? 0.0 : nh_tool_speed(c->tools[ramp].spec, t, h) * h;
  double deeper = -1.0; /* the progress a' of the next deeper tied point (−1: none) */
  for (int i = G->n_chan - 1; i >= 0; i--) {
    const nh_cpoint *p = &G->chan[i];
    if (p->row < 0) continue;
    const nh_tool *tl = &c->tools[p->tool];
    double w = i == 0 ? 1.5 * p->len : p->len;
    if (p->tool == ramp) {
      const double d = nh_beam_length(tl->beam) - p->s + travel,
                   a = i == 0 ? fmax(d, 0.0) : fmax(d - 0.5 * p->len, 0.0);
      w = deeper < 0.0 ? fmin(a, 2.0 * p->len) : fmax(a - deeper, 0.0);
      deeper = a;
    }
    c->rows.law[p->row + 2].threshold = tl->spec->friction_per_length * w * tau;
  }
  if (G->tip_tool < 0 || G->n_chan == 0 || G->chan[0].row >= 0) return;
  const nh_tool *tl = &c->tools[G->tip_tool];
  const double L = nh_beam_length(tl->beam);
  double xe[3];
  nh_point_position(m, u, &G->chan[0], xe);
  const double d = fmin(fmax(L - nh_tool_project(tl->beam, xe, L) + travel, 0.0),
                        0.5 * G->chan[0].len + fmax(travel, 0.0));
  c->rows.law[G->front.row + 2].threshold += tl->spec->friction_per_length * d * tau;
}

int nh_shaft_rows(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u, double t, double h,
                  double tau) {
  if (!G->punctured) return NH_OK;
  const double L = nh_beam_length(c->tools[G->outer].beam);
  for (int i = 0; i < G->n_chan; i++) {
    nh_cpoint *p = &G->chan[i];
    double xp[3], s;
    nh_point_position(m, u, p, xp);
    p->row = -1;
    /* hysteresis within a quasi-static step: a point tied at the previous
     * iteration stays tied up to the tip (clearance 0), one that was not
     * gets its rows only half a spacing behind it */
    const double clear = c->statics && c->iteration && p->tool >= 0 ? 0.0 : 0.5 * p->len;
    int k = nh_cover(c, G, xp, p->tool >= 0 ? p->s : L, clear, &s);
    if (k < 0 || c->tools[k].dyn < 0) { /* uncovered: no rows */
      p->tool = -1, p->slid = 0;
      memset(p->lam, 0, sizeof p->lam);
      memset(p->handover, 0, sizeof p->handover);
      continue;
    }
    const nh_tool *tl = &c->tools[k];
    /* the axial bound's constant part is set below, once the ramp's tool is known */
    if (nh_tie_rows(c, m, u, p, k, s, 0.0, nh_torsion_threshold(c, tl, p, tau), 0) < 0)
      return NH_ERR_MEMORY;
  }
  nh_shaft_bounds(c, G, m, u, t, h, tau);
  return NH_OK;
}

void nh_shaft_update(nh_contact *c, nh_group *G, double h, nh_group_events *ev) {
  for (int i = 0; i < G->n_chan; i++) {
    nh_cpoint *p = &G->chan[i];
    if (p->row < 0) continue;
    ev->covered = 1;
    for (int q = 0; q < 3; q++) {
      p->lam[q] = c->rows.lambda[p->row + q];
      nh_tool_add_force(&c->tools[p->tool], &c->rows, p->row + q, h, p->s);
    }
    p->slid = c->rows.law[p->row + 2].sliding;
    if (p->slid) p->dc_axial = 0.0, p->dc_axial_set = 0; /* estimated again when it sticks */
    double o = sqrt(nh_vec3_dot(p->handover, p->handover)), close = NH_HANDOVER_RATE * p->len;
    for (int q = 0; q < 3; q++) p->handover[q] *= o > close ? 1.0 - close / o : 0.0;
    /* the torsion row follows the three: a moment, kept as the next warm start */
    if (nh_torsion_threshold(c, &c->tools[p->tool], p, 1.0) > 0.0)
      p->lam[3] = c->rows.lambda[p->row + 3];
  }
}
