/* contact.c — tools, their motion, and the puncture / tip / shaft
 * constraints with the tissue (docs/interaction.md).
 *
 * Every tie between a tissue material point P and a tool point at arc
 * length s uses a frame at the tool point: t the Hermite tangent, n1 the
 * node's second director made orthogonal to t, n2 = t × n1. Rows (see
 * nh_rows in solve/solve.h: g = n · (x_P − x_tool), force on the tissue
 * along +n):
 *   shaft point  n1, n2 bilateral (g the lateral offset); t friction with
 *                bound μ |(λ1, λ2)| + friction_per_length × spacing (g = 0);
 *   tip          the same with bound μ |(λ1, λ2)| + cutting_force and
 *                g = t · (x_P − x_tip), P the channel's front;
 *   puncture     t unilateral capped at the puncture force (g = t · (x_P −
 *                x_tip) ≥ 0, P the entry point on the surface; the row
 *                yields at the cap and the tool punctures) and a Coulomb
 *                disc pair across t, bound μ λn.
 * The entry point is where the tool's axis ray (base + τ direction) first
 * enters the domain's shape, with n_out the shape's outward normal there
 * (nh_domain_ray_entry: a face of a box, ∇F / |∇F| on the implicit surface
 * of an immersed domain); n_out only decides when the tip is near enough
 * for the rows. Until the tool touches, the entry follows the tissue's
 * motion (nh_refresh_entry).
 * Thresholds are impulses (force × h), see contact.h. */
#include "contact/contact.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A tissue material point tied to a tool. */
typedef struct {
  double X[3];  /* material position */
  int cell;     /* leaf containing X */
  double xi[3]; /* natural coordinates in it */
  double len;   /* channel length it stands for (spacing), m */
  double s;     /* arc length of its tool point (last projection) */
  int tool;     /* the tool it was tied to in the last step (−1: none) */
  int row;      /* its first row in the last step (−1: none) */
  double lam[3];
} nh_cpoint;

typedef struct {
  const nh_tool_spec *spec;
  nh_beam *beam;
  int host;      /* nested: the host tool; −1 for an outer tool */
  int released;  /* nested: no longer follows its host */
  double offset; /* nested: arc length of its base along the host */
  int dyn;       /* index in this step's dynamic list (−1: kinematic) */
  double base_v[6];
  double F[3];    /* the tissue's force on the tool in the last step, N */
  double *f_node; /* 3 per node: F distributed to the nearest nodes */
  nh_tool_state state;
  /* group data (outer tools only) */
  int has_entry;
  double n_out[3];
  nh_cpoint entry; /* the puncture point; channel point 0 once punctured */
  int entry_row;   /* first puncture row in the last step (−1) */
  int punctured;
  nh_cpoint *chan; /* channel points laid behind the tip (entry first) */
  int n_chan, cap_chan;
  nh_cpoint front;   /* the channel's front: the tip's anchor */
  int tip_tool;      /* the tool with the tip rows in the last step (−1) */
  double entry_x[3]; /* current position of the entry point (after the last step) */
  int cut;           /* the tip rows slid forward in the last step */
} nh_tool;

struct nh_contact {
  const nh_scene *scene;
  int n;
  nh_tool *tools;
  nh_contact_counts counts;
  double h; /* the last step */
};

const char *nh_tool_state_name(nh_tool_state s) {
  static const char *const names[] = {"outside", "contact", "punctured", "cutting", "retracting"};
  return (unsigned)s < 5 ? names[s] : "?";
}

/* ---- small geometry ---- */

static double dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static void cross3(const double a[3], const double b[3], double c[3]) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

static void normalize3(double a[3]) {
  double n = sqrt(dot3(a, a));
  if (n > 0) a[0] /= n, a[1] /= n, a[2] /= n;
}

/* Insertion distance d(t) = ∫₀ᵗ speed of a motion list (speed 0 after the last segment). */
static double nh_motion_distance(const nh_tool_spec *sp, double t) {
  double d = 0.0, t0 = 0.0;
  for (int i = 0; i < sp->n_motion && t0 < t; i++) {
    double t1 = fmin(sp->motion[i].until, t);
    if (t1 > t0) d += sp->motion[i].speed * (t1 - t0);
    t0 = sp->motion[i].until;
  }
  return d;
}

static double nh_motion_speed(const nh_tool_spec *sp, double t, double h) {
  return (nh_motion_distance(sp, t + h) - nh_motion_distance(sp, t)) / h;
}

/* Current position of an embedded tissue point. */
static void nh_point_position(const nh_mesh *m, const double *u, const nh_cpoint *p, double x[3]) {
  double N[8];
  nh_hex_shape(p->xi, N);
  const int *e = m->cells + 8 * p->cell;
  for (int i = 0; i < 3; i++) {
    x[i] = 0.0;
    for (int a = 0; a < 8; a++) x[i] += N[a] * (m->X[3 * e[a] + i] + u[3 * e[a] + i]);
  }
}

/* Set a point's material position and locate it. */
static int nh_point_set(const nh_mesh *m, nh_cpoint *p, const double X[3]) {
  memcpy(p->X, X, sizeof p->X);
  return nh_mesh_locate(m, X, &p->cell, p->xi);
}

/* The material point whose current position is x (Newton on X + u(X) = x,
 * starting from X0). NH_ERR_INPUT if it leaves the tissue. */
static int nh_material_point(const nh_mesh *m, const double *u, const double x[3],
                             const double X0[3], nh_cpoint *p) {
  double X[3] = {X0[0], X0[1], X0[2]};
  for (int it = 0; it < 20; it++) {
    if (nh_point_set(m, p, X)) return NH_ERR_INPUT;
    double Xe[24], N[8], dN[8][3], Jx[9] = {0}, Ji[9], G[9] = {0}, xc[3];
    nh_mesh_cell_coords(m, m->X, p->cell, Xe);
    nh_hex_shape(p->xi, N);
    nh_hex_dshape(p->xi, dN);
    for (int a = 0; a < 8; a++)
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Jx[3 * i + j] += Xe[3 * a + i] * dN[a][j];
    if (nh_mat3_inverse(Jx, Ji)) return NH_ERR_INPUT;
    const int *e = m->cells + 8 * p->cell;
    for (int a = 0; a < 8; a++) { /* F = I + ∂u/∂X */
      double g[3];
      nh_mat3_tvec(Ji, dN[a], g);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) G[3 * i + j] += u[3 * e[a] + i] * g[j];
    }
    for (int i = 0; i < 3; i++) G[4 * i] += 1.0;
    nh_point_position(m, u, p, xc);
    double r[3] = {x[0] - xc[0], x[1] - xc[1], x[2] - xc[2]}, Fi[9], d[3];
    if (nh_mat3_inverse(G, Fi)) return NH_ERR_INPUT;
    nh_mat3_vec(Fi, r, d);
    for (int i = 0; i < 3; i++) X[i] += d[i];
    if (sqrt(dot3(d, d)) <= 1e-13 * (1.0 + sqrt(dot3(X, X)))) return nh_point_set(m, p, X);
  }
  return nh_point_set(m, p, X);
}

/* Closest point of tool b to x: arc length by Newton from s0 (unclamped:
 * the caller decides what lies beyond the ends). */
static double nh_project(const nh_beam *b, const double x[3], double s0) {
  const double L = nh_beam_length(b);
  double s = s0;
  for (int it = 0; it < 8; it++) {
    double xs[3], t[3], sc = fmin(fmax(s, 0.0), L);
    nh_beam_point(b, sc, xs, t, NULL, NULL, NULL);
    double d[3] = {x[0] - xs[0], x[1] - xs[1], x[2] - xs[2]};
    double ds = dot3(t, d);
    s = sc + ds;
    if (fabs(ds) < 1e-13 * L || (sc != s - ds)) break;
  }
  return s;
}

/* ---- creation ---- */

static int nh_contact_check_reach(const nh_scene *sc, const nh_mesh *m, const nh_tool *tl) {
  const nh_tool_spec *sp = tl->spec;
  double dmax = 0.0, T = sc->time.steps * sc->time.step;
  for (int i = 0; i < sp->n_motion; i++)
    dmax = fmax(dmax, nh_motion_distance(sp, fmin(sp->motion[i].until, T)));
  double tip0[3], tip1[3], cell = fmax(m->spacing[0], fmax(m->spacing[1], m->spacing[2]));
  for (int i = 0; i < 3; i++) {
    tip0[i] = sp->base[i] + sp->length * sp->direction[i];
    tip1[i] = tip0[i] + dmax * sp->direction[i];
  }
  NH_CHECK(!nh_domain_inside(&m->domain, tip0), NH_ERR_INPUT,
           "%s: the tip starts inside the tissue at [%g, %g, %g]: place the base so the tool "
           "starts outside",
           sp->where, tip0[0], tip0[1], tip0[2]);
  double d = nh_domain_segment_distance(&m->domain, tip0, tip1);
  NH_CHECK(d <= cell, NH_ERR_INPUT,
           "%s: the tool never meets the tissue: its tip travels from [%g, %g, %g] to "
           "[%g, %g, %g] and stays %g m away from it (check base, direction and motion)",
           sp->where, tip0[0], tip0[1], tip0[2], tip1[0], tip1[1], tip1[2], d);
  return NH_OK;
}

/* Place a nested tool on its host's deformed axis (kinematic follow). */
static void nh_follow_host(nh_tool *in, const nh_tool *host, double h) {
  nh_beam *b = in->beam;
  const int nn = nh_beam_nodes(b);
  const double L = nh_beam_length(host->beam), l0 = nh_beam_length(b) / nh_beam_elements(b);
  double *x = nh_beam_positions(b), *T = nh_beam_directors(b), *v = nh_beam_velocities(b);
  const double *T0 = nh_beam_rest_directors(b), *dir = in->spec->direction;
  for (int k = 0; k < nn; k++) {
    double a = in->offset + k * l0, p[3], t[3], old[3], Q[9], Tn[9], w[3], R[9];
    nh_beam_point(host->beam, fmin(fmax(a, 0.0), L), p, t, NULL, NULL, NULL);
    if (a > L || a < 0) /* beyond the host's ends: straight on along its end tangent */
      for (int i = 0; i < 3; i++) p[i] += (a > L ? a - L : a) * t[i];
    /* the rotation taking the rest axis to t, applied to the rest directors */
    double ax[3], c = dot3(dir, t);
    cross3(dir, t, ax);
    double sn = sqrt(dot3(ax, ax)), ang = atan2(sn, c);
    if (sn > 0)
      for (int i = 0; i < 3; i++) ax[i] *= ang / sn;
    nh_mat3_rotation(ax, Q);
    nh_mat3_mul(Q, T0 + 9 * k, Tn);
    memcpy(old, x + 3 * k, sizeof old);
    nh_mat3_mul_nt(Tn, T + 9 * k, R);
    nh_beam_rotation_log(R, w);
    for (int i = 0; i < 3; i++) {
      x[3 * k + i] = p[i];
      v[6 * k + i] = h > 0 ? (p[i] - old[i]) / h : 0.0;
      v[6 * k + 3 + i] = h > 0 ? w[i] / h : 0.0;
    }
    memcpy(T + 9 * k, Tn, sizeof Tn);
  }
}

int nh_contact_create(const nh_scene *sc, const nh_mesh *m, nh_contact **out) {
  *out = NULL;
  nh_contact *c = nh_calloc(1, sizeof *c);
  if (!c) return NH_ERR_MEMORY;
  c->scene = sc;
  c->n = sc->n_tools;
  c->tools = nh_calloc((size_t)(c->n ? c->n : 1), sizeof *c->tools);
  int rc = c->tools ? NH_OK : NH_ERR_MEMORY;
  for (int k = 0; k < c->n && !rc; k++) {
    nh_tool *tl = &c->tools[k];
    const nh_tool_spec *sp = &sc->tools[k];
    tl->spec = sp;
    tl->host = sp->inside;
    tl->tip_tool = tl->entry_row = -1;
    nh_beam_spec bs = {
        .section = {sp->young, sp->poisson, sp->radius, sp->inner_radius, sp->density},
        .length = sp->length,
        .elements = sp->elements};
    memcpy(bs.base, sp->base, sizeof bs.base);
    memcpy(bs.direction, sp->direction, sizeof bs.direction);
    if ((rc = nh_beam_create(&bs, &tl->beam))) {
      char why[256];
      snprintf(why, sizeof why, "%s", nh_error_message());
      rc = NH_ERROR(rc, "%s: %s", sp->where, why);
      break;
    }
    tl->f_node = nh_calloc(3 * (size_t)nh_beam_nodes(tl->beam), sizeof(double));
    if (!tl->f_node) rc = NH_ERR_MEMORY;
    if (!rc && tl->host < 0) {
      rc = nh_contact_check_reach(sc, m, tl);
      double tau;
      tl->has_entry = !rc && nh_domain_ray_entry(&m->domain, sp->base, sp->direction, &tau,
                                                 tl->entry.X, tl->n_out);
      if (tl->has_entry && nh_point_set(m, &tl->entry, tl->entry.X)) tl->has_entry = 0;
    }
    if (!rc && tl->host >= 0) {
      const nh_tool_spec *hs = &sc->tools[tl->host];
      double d[3] = {sp->base[0] - hs->base[0], sp->base[1] - hs->base[1],
                     sp->base[2] - hs->base[2]};
      tl->offset = dot3(d, hs->direction);
      nh_follow_host(tl, &c->tools[tl->host], 0.0);
    }
  }
  if (rc) {
    nh_contact_destroy(&c);
    return rc;
  }
  *out = c;
  return NH_OK;
}

void nh_contact_destroy(nh_contact **pc) {
  nh_contact *c = *pc;
  if (!c) return;
  for (int k = 0; c->tools && k < c->n; k++) {
    nh_beam_destroy(&c->tools[k].beam);
    free(c->tools[k].chan);
    free(c->tools[k].f_node);
  }
  free(c->tools);
  free(c);
  *pc = NULL;
}

int nh_contact_tools(const nh_contact *c) {
  return c->n;
}

nh_beam *nh_contact_beam(nh_contact *c, int k) {
  return c->tools[k].beam;
}

/* Path-point spacing at p: the scene's, or half the local cell edge. */
static double nh_spacing(const nh_tool_spec *sp, const nh_mesh *m, const nh_cpoint *p) {
  return sp->spacing > 0 ? sp->spacing : 0.5 * nh_mesh_cell_size(m, p->cell);
}

/* Lay channel points from the last one towards `to`, one per spacing. */
static int nh_lay_channel(nh_tool *G, const nh_mesh *m, const nh_cpoint *to) {
  for (;;) {
    const nh_cpoint *last = &G->chan[G->n_chan - 1];
    double d[3] = {to->X[0] - last->X[0], to->X[1] - last->X[1], to->X[2] - last->X[2]};
    double dist = sqrt(dot3(d, d)), sp = nh_spacing(G->spec, m, last);
    if (dist < sp) return NH_OK;
    if (nh_grow((void **)&G->chan, &G->cap_chan, G->n_chan + 1, sizeof *G->chan))
      return NH_ERR_MEMORY;
    nh_cpoint p = {0};
    double X[3];
    for (int i = 0; i < 3; i++) X[i] = last->X[i] + d[i] * sp / dist;
    if (nh_point_set(m, &p, X)) return NH_OK; /* left the tissue */
    p.len = sp, p.tool = -1, p.row = -1;
    G->chan[G->n_chan++] = p;
  }
}

/* ---- rows ---- */

/* The tissue part of a row: the point's cell nodes and shape values. */
static void nh_row_tissue(nh_rows *rows, int r, const nh_mesh *m, const nh_cpoint *p) {
  double N[8];
  nh_hex_shape(p->xi, N);
  for (int a = 0; a < 8; a++)
    rows->node[8 * r + a] = m->cells[8 * p->cell + a], rows->N[8 * r + a] = N[a];
}

/* Three rows tying P to tool k's point at s (shaft or tip); returns the
 * first row or −1 (memory). */
static int nh_tie_rows(nh_contact *c, nh_rows *rows, const nh_mesh *m, const double *u,
                       nh_cpoint *p, int k, double s, double threshold, int tip) {
  nh_tool *tl = &c->tools[k];
  double xb[3], t[3], J[36], xi, xp[3];
  int e;
  nh_beam_point(tl->beam, s, xb, t, &e, &xi, J);
  nh_point_position(m, u, p, xp);
  const double *T = nh_beam_directors(tl->beam) + 9 * (xi < 0.5 ? e : e + 1);
  double n1[3] = {T[1], T[4], T[7]}, n2[3], d = dot3(n1, t);
  for (int i = 0; i < 3; i++) n1[i] -= d * t[i];
  normalize3(n1);
  cross3(t, n1, n2);
  const double *dirs[3] = {n1, n2, t};
  int first = -1;
  for (int q = 0; q < 3; q++) {
    int r = nh_rows_add(rows);
    if (r < 0) return -1;
    if (q == 0) first = r;
    nh_row_tissue(rows, r, m, p);
    memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
    rows->tool[r] = tl->dyn, rows->elem[r] = e;
    memcpy(rows->J + 36 * r, J, sizeof J);
    double g[3] = {xp[0] - xb[0], xp[1] - xb[1], xp[2] - xb[2]};
    rows->gap[r] = (q < 2 || tip) ? dot3(dirs[q], g) : 0.0;
    rows->lambda[r] = p->lam[q];
    if (q == 2)
      rows->law[r] =
          (nh_row_law){NH_ROW_FRICTION, first, first + 1, tl->spec->friction, threshold, -1};
  }
  p->row = first, p->tool = k, p->s = s;
  return first;
}

/* Which tool of group g (outer tool g, then its released nested tools)
 * covers P, and where: the outermost one whose axis passes P at an arc
 * length in [0, L − clearance]. Returns the tool or −1. */
static int nh_cover(nh_contact *c, int g, const double xp[3], double s0, double clear_tip,
                    double *s_out) {
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    if (k != g && (tl->host != g || !tl->released)) continue;
    double L = nh_beam_length(tl->beam);
    double s = nh_project(tl->beam, xp, k == g ? s0 : s0 - tl->offset);
    double clear = k == c->tools[g].tip_tool ? clear_tip : 0.0;
    if (s >= 0.0 && s <= L - clear) {
      *s_out = s;
      return k;
    }
  }
  return -1;
}

/* The leading tool of group g for the tip rows: the outer tool unless it
 * retracts, else a released nested tool that does not; −1 if none. */
static int nh_leader(const nh_contact *c, int g, double t, double h) {
  for (int k = 0; k < c->n; k++) {
    const nh_tool *tl = &c->tools[k];
    if (k != g && (tl->host != g || !tl->released)) continue;
    if (nh_motion_speed(tl->spec, t, h) >= 0.0) return k;
  }
  return -1;
}

/* The entry point of a tool that has not touched the tissue yet, on the
 * tissue as it is now: the material point X on the domain's surface whose
 * current position X + u(X) lies on the tool's line. The tissue may have
 * moved since the entry was found (brain shift before the insertion), so
 * the ray is pulled back by u at the last estimate and intersected with the
 * rest surface again, until X stops moving (a fixed point of
 * X = entry(line − u(X)); u varies slowly over a cell, so a few iterations
 * suffice). With u = 0 at the entry, X is unchanged. */
static void nh_refresh_entry(nh_tool *G, const nh_mesh *m, const double *u) {
  const nh_tool_spec *sp = G->spec;
  for (int it = 0; it < 20; it++) {
    double x[3], o[3], X[3], n[3], tau;
    nh_point_position(m, u, &G->entry, x);
    for (int i = 0; i < 3; i++) o[i] = sp->base[i] - (x[i] - G->entry.X[i]);
    if (!nh_domain_ray_entry(&m->domain, o, sp->direction, &tau, X, n)) return;
    double dX[3] = {X[0] - G->entry.X[0], X[1] - G->entry.X[1], X[2] - G->entry.X[2]};
    double moved = sqrt(dot3(dX, dX));
    nh_cpoint p = G->entry;
    if (nh_point_set(m, &p, X)) return;
    G->entry = p;
    memcpy(G->n_out, n, sizeof n);
    if (moved <= 1e-9 * nh_mesh_cell_size(m, G->entry.cell)) return;
  }
}

static int nh_group_rows(nh_contact *c, int g, const nh_mesh *m, const double *u, double t,
                         double h, nh_rows *rows) {
  nh_tool *G = &c->tools[g];
  const nh_tool_spec *sp = G->spec;
  G->entry_row = -1;
  if (!G->punctured) {
    if (!G->has_entry) return NH_OK;
    if (G->entry.lam[0] == 0.0) nh_refresh_entry(G, m, u); /* not touching yet */
    double xt[3], tt[3], J[36], xi, xp[3];
    int e;
    nh_beam *b = G->beam;
    nh_beam_point(b, nh_beam_length(b), xt, tt, &e, &xi, J);
    nh_point_position(m, u, &G->entry, xp);
    double gap = dot3(G->n_out, xt) - dot3(G->n_out, xp);
    const double *vb = nh_beam_velocities(b) + 6 * (nh_beam_nodes(b) - 1);
    double reach =
        2.0 * h *
            (fabs(G->base_v[0]) + fabs(G->base_v[1]) + fabs(G->base_v[2]) + sqrt(dot3(vb, vb))) +
        1e-3 * nh_mesh_cell_size(m, G->entry.cell);
    if (gap > reach) {
      memset(G->entry.lam, 0, sizeof G->entry.lam);
      return NH_OK;
    }
    /* The rows act along the tip's axis t and across it, not along the
     * face normal: on an oblique tool a normal row's force has a part
     * across the axis that bends the tool while the surface holds (a whole
     * step, however short the contact) and the tip then cuts on, off its
     * line (docs/interaction.md, Puncture). */
    double tan1[3] = {1, 0, 0}, tan2[3], d[3] = {xp[0] - xt[0], xp[1] - xt[1], xp[2] - xt[2]};
    gap = dot3(tt, d);
    if (fabs(tt[0]) > 0.9) tan1[0] = 0, tan1[1] = 1;
    double c = dot3(tan1, tt);
    for (int i = 0; i < 3; i++) tan1[i] -= c * tt[i];
    normalize3(tan1);
    cross3(tan1, tt, tan2);
    const double *dirs[3] = {tt, tan1, tan2};
    for (int q = 0; q < 3; q++) {
      int r = nh_rows_add(rows);
      if (r < 0) return NH_ERR_MEMORY;
      if (q == 0) G->entry_row = r;
      nh_row_tissue(rows, r, m, &G->entry);
      memcpy(rows->dir + 3 * r, dirs[q], 3 * sizeof(double));
      rows->tool[r] = G->dyn, rows->elem[r] = e;
      memcpy(rows->J + 36 * r, J, sizeof J);
      rows->gap[r] = q == 0 ? gap : 0.0;
      rows->lambda[r] = G->entry.lam[q];
      /* The normal yields at the puncture force (Eq. 6 within the step). */
      rows->law[r] = q == 0
                         ? (nh_row_law){NH_ROW_UNILATERAL, -1, -1, 0.0, sp->puncture_force * h, -1}
                         : (nh_row_law){NH_ROW_FRICTION, G->entry_row, -1,
                                        sp->friction,    0.0,          G->entry_row + 1};
    }
    return NH_OK;
  }
  /* Punctured: the tip rows at the front, then a shaft tie per channel point. */
  G->tip_tool = -1;
  int lead = nh_leader(c, g, t, h);
  if (lead >= 0 && c->tools[lead].dyn >= 0) {
    nh_tool *tl = &c->tools[lead];
    double xt[3], tt[3], xf[3];
    nh_beam_point(tl->beam, nh_beam_length(tl->beam), xt, tt, NULL, NULL, NULL);
    nh_point_position(m, u, &G->front, xf);
    double ahead = dot3(tt, xf) - dot3(tt, xt), sp_f = nh_spacing(sp, m, &G->front);
    if (ahead < 0.0) { /* the tip passed the front inside the channel: the front moves to it */
      nh_cpoint p = G->front;
      if (!nh_material_point(m, u, xt, G->front.X, &p)) {
        G->front = p, ahead = 0.0;
        NH_TRY(nh_lay_channel(G, m, &G->front));
      }
    }
    if (ahead <= 0.05 * sp_f) {
      G->tip_tool = lead;
      if (nh_tie_rows(c, rows, m, u, &G->front, lead, nh_beam_length(tl->beam),
                      tl->spec->cutting_force * h, 1) < 0)
        return NH_ERR_MEMORY;
    }
  }
  for (int i = 0; i < G->n_chan; i++) {
    nh_cpoint *p = &G->chan[i];
    double xp[3], s;
    nh_point_position(m, u, p, xp);
    p->row = -1;
    int k = nh_cover(c, g, xp, p->tool >= 0 ? p->s : nh_beam_length(G->beam), 0.5 * p->len, &s);
    if (k < 0 || c->tools[k].dyn < 0) {
      p->tool = -1;
      memset(p->lam, 0, sizeof p->lam);
      continue;
    }
    if (nh_tie_rows(c, rows, m, u, p, k, s, c->tools[k].spec->friction_per_length * p->len * h, 0) <
        0)
      return NH_ERR_MEMORY;
  }
  return NH_OK;
}

int nh_contact_begin_step(nh_contact *c, const nh_mesh *m, const double *u, double t, double h,
                          nh_rows *rows, nh_coupled_tool *tools, int *n_dynamic) {
  nh_rows_clear(rows);
  c->h = h;
  int nd = 0;
  double g[3]; /* at the end of the step, as the tissue's loads; tools are not buoyed */
  nh_scene_gravity(c->scene, t + h, g);
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    const nh_tool_spec *sp = tl->spec;
    tl->dyn = -1;
    if (tl->host >= 0 && !tl->released) continue; /* follows its host */
    double speed = nh_motion_speed(sp, t, h);
    for (int i = 0; i < 3; i++) tl->base_v[i] = speed * sp->direction[i], tl->base_v[3 + i] = 0.0;
    tl->dyn = nd;
    tools[nd] = (nh_coupled_tool){.beam = tl->beam,
                                  .options = {.dt = h,
                                              .alpha = sp->damping_mass,
                                              .beta = sp->damping_stiffness,
                                              .gravity = {g[0], g[1], g[2]}},
                                  .f_ext = NULL};
    memcpy(tools[nd].base_velocity, tl->base_v, sizeof tl->base_v);
    nd++;
  }
  *n_dynamic = nd;
  for (int g = 0; g < c->n; g++)
    if (c->tools[g].host < 0) NH_TRY(nh_group_rows(c, g, m, u, t, h, rows));
  return NH_OK;
}

/* ---- after the step ---- */

/* Add row r's force on the tool (−n λ / h) to the tool's totals. */
static void nh_add_force(nh_tool *tl, const nh_rows *rows, int r, double h, double s) {
  const double *n = rows->dir + 3 * r;
  int nn = nh_beam_nodes(tl->beam), node = (int)lround(s / nh_beam_length(tl->beam) * (nn - 1));
  node = node < 0 ? 0 : (node >= nn ? nn - 1 : node);
  for (int i = 0; i < 3; i++) {
    double f = -n[i] * rows->lambda[r] / h;
    tl->F[i] += f;
    tl->f_node[3 * node + i] += f;
  }
}

/* Friction row r: on its bound? */
static int nh_on_bound(const nh_rows *rows, int r) {
  const nh_row_law *l = &rows->law[r];
  double n = l->normal >= 0 ? fabs(rows->lambda[l->normal]) : 0.0;
  if (l->normal2 >= 0) n = hypot(n, rows->lambda[l->normal2]);
  double b = l->mu * n + l->threshold;
  return fabs(rows->lambda[r]) >= b * (1.0 - 1e-7);
}

int nh_contact_end_step(nh_contact *c, const nh_mesh *m, const double *u, const nh_rows *rows,
                        double t_new, double h) {
  nh_contact_counts cnt = {0};
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    memset(tl->F, 0, sizeof tl->F);
    memset(tl->f_node, 0, sizeof(double) * 3 * (size_t)nh_beam_nodes(tl->beam));
    const double *x = nh_beam_positions(tl->beam);
    for (int i = 0; i < 3 * nh_beam_nodes(tl->beam); i++)
      if (!isfinite(x[i]))
        return NH_ERROR(NH_ERR_NUMERIC, "tool %s: position not finite", tl->spec->name);
  }
  for (int g = 0; g < c->n; g++) {
    nh_tool *G = &c->tools[g];
    if (G->host >= 0) continue;
    G->cut = 0;
    if (G->entry_row >= 0) {
      for (int q = 0; q < 3; q++) {
        G->entry.lam[q] = rows->lambda[G->entry_row + q];
        nh_add_force(G, rows, G->entry_row + q, h, nh_beam_length(G->beam));
      }
      double fn = G->entry.lam[0] / h, fp = G->spec->puncture_force;
      G->state = fn > 0 ? NH_TOOL_CONTACT : NH_TOOL_OUTSIDE;
      /* punctured (Eq. 6): the normal reached its cap, the puncture force
       * (a zero puncture force: no cap, any contact punctures) */
      if (fp > 0 ? fn >= fp * (1.0 - 1e-7) : fn > 0.0) {
        G->punctured = 1;
        G->state = NH_TOOL_PUNCTURED;
        if (nh_grow((void **)&G->chan, &G->cap_chan, 1, sizeof *G->chan)) return NH_ERR_MEMORY;
        G->entry.len = nh_spacing(G->spec, m, &G->entry);
        G->entry.tool = -1, G->entry.row = -1;
        memset(G->entry.lam, 0, sizeof G->entry.lam);
        G->chan[0] = G->entry;
        G->n_chan = 1;
        G->front = G->entry;
      }
      continue;
    }
    if (!G->punctured) {
      G->state = NH_TOOL_OUTSIDE;
      continue;
    }
    int covered = 0;
    for (int i = 0; i < G->n_chan; i++) {
      nh_cpoint *p = &G->chan[i];
      if (p->row < 0) continue;
      covered = 1;
      for (int q = 0; q < 3; q++) {
        p->lam[q] = rows->lambda[p->row + q];
        nh_add_force(&c->tools[p->tool], rows, p->row + q, h, p->s);
      }
    }
    if (G->tip_tool >= 0) {
      nh_tool *tl = &c->tools[G->tip_tool];
      int r = G->front.row;
      covered = 1;
      for (int q = 0; q < 3; q++) {
        G->front.lam[q] = rows->lambda[r + q];
        nh_add_force(tl, rows, r + q, h, nh_beam_length(tl->beam));
      }
      if (nh_on_bound(rows, r + 2) && rows->lambda[r + 2] >= 0.0) { /* cut and advance (Eq. 8) */
        double xt[3];
        nh_beam_point(tl->beam, nh_beam_length(tl->beam), xt, NULL, NULL, NULL, NULL);
        nh_cpoint p = G->front;
        if (!nh_material_point(m, u, xt, G->front.X, &p)) {
          double d[3] = {p.X[0] - G->front.X[0], p.X[1] - G->front.X[1], p.X[2] - G->front.X[2]};
          if (sqrt(dot3(d, d)) > 1e-9 * nh_spacing(G->spec, m, &G->front)) { /* it advanced */
            G->cut = 1;
            cnt.cut++;
          }
          G->front = p;
          NH_TRY(nh_lay_channel(G, m, &G->front));
        }
      }
    }
    int retracting = nh_motion_speed(G->spec, t_new - h, h) < 0.0;
    G->state = !covered     ? NH_TOOL_OUTSIDE
               : retracting ? NH_TOOL_RETRACTING
               : G->cut     ? NH_TOOL_CUTTING
                            : NH_TOOL_PUNCTURED;
    if (G->n_chan > 0) nh_point_position(m, u, &G->chan[0], G->entry_x);
  }
  /* nested tools: release, follow, state */
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    if (tl->host < 0) continue;
    nh_tool *H = &c->tools[tl->host];
    if (!tl->released) {
      nh_follow_host(tl, H, h);
      tl->state = H->state;
      if (t_new >= tl->spec->release - 1e-12 * h) tl->released = 1;
    } else {
      int has = 0;
      for (int i = 0; i < H->n_chan; i++) has |= H->chan[i].tool == k;
      has |= H->tip_tool == k;
      /* in the tissue: tied to it, or inside its host where the host is */
      int in = has || (H->punctured && H->state != NH_TOOL_OUTSIDE);
      tl->state = !in                                           ? NH_TOOL_OUTSIDE
                  : nh_motion_speed(tl->spec, t_new - h, h) < 0 ? NH_TOOL_RETRACTING
                                                                : NH_TOOL_PUNCTURED;
    }
  }
  cnt.path_points = 0;
  for (int g = 0; g < c->n; g++) cnt.path_points += c->tools[g].n_chan;
  c->counts = cnt;
  return NH_OK;
}

int nh_contact_relocate(nh_contact *c, const nh_mesh *m) {
  for (int g = 0; g < c->n; g++) {
    nh_tool *G = &c->tools[g];
    if (G->host >= 0) continue;
    int bad = 0;
    if (G->has_entry) bad |= nh_point_set(m, &G->entry, G->entry.X);
    if (G->punctured) bad |= nh_point_set(m, &G->front, G->front.X);
    for (int i = 0; i < G->n_chan; i++) bad |= nh_point_set(m, &G->chan[i], G->chan[i].X);
    NH_CHECK(!bad, NH_ERR_INTERNAL, "tool %s: a path point left the refined mesh", G->spec->name);
  }
  return NH_OK;
}

void nh_contact_report(const nh_contact *c, int k, nh_tool_report *r) {
  const nh_tool *tl = &c->tools[k];
  const nh_tool *G = tl->host >= 0 ? &c->tools[tl->host] : tl;
  double t[3], L = nh_beam_length(tl->beam);
  nh_beam_point(tl->beam, L, r->tip, t, NULL, NULL, NULL);
  double ft = dot3(tl->F, t), lat[3];
  for (int i = 0; i < 3; i++) lat[i] = tl->F[i] - ft * t[i];
  r->axial_force = -ft;
  r->lateral_force = sqrt(dot3(lat, lat));
  r->state = tl->state;
  r->depth = 0.0;
  if (G->punctured && G->n_chan > 0 && tl->state != NH_TOOL_OUTSIDE) {
    /* the entry point's arc length on this tool */
    const nh_cpoint *e = &G->chan[0];
    double s = nh_project(tl->beam, G->entry_x, e->tool == k ? e->s : 0.0);
    r->depth = fmax(0.0, L - fmax(s, 0.0));
  }
}

void nh_contact_counts_get(const nh_contact *c, nh_contact_counts *counts) {
  *counts = c->counts;
}

void nh_contact_node_forces(const nh_contact *c, int k, double *f) {
  memcpy(f, c->tools[k].f_node, sizeof(double) * 3 * (size_t)nh_beam_nodes(c->tools[k].beam));
}
