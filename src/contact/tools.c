/* tools.c — tool kinematics: the prescribed motion of each tool's base,
 * nesting (a tool inside its host follows the host's deformed axis until
 * its release), the forces of the last step per tool and the per-tool
 * report (docs/interaction.md, "Nested tools" and "Retraction").
 *
 * A tool's base moves along its direction with the speed of its motion
 * list (m/s per segment, 0 after the last) and turns about it with the
 * spin (rad/s); over a step the base velocity is the travel (turn) of that
 * step divided by h, so the base lands exactly on the planned distance and
 * angle at every step end. The turn reaches the tip through the beam's
 * torsion (docs/interaction.md, "Bevel tip"). A nested tool that is not yet
 * released is kinematic: its nodes sit on the host's centre line at their
 * arc length (offset + k l₀, straight on along the end tangent beyond the
 * host's ends), its directors are the rest directors turned by the rotation
 * taking the rest axis to the host's tangent. Once released it is a beam of
 * its own in the coupled step. */
#include "contact/contact_impl.h"

#include <stdio.h>
#include <string.h>

/* Insertion distance d(t) = ∫₀ᵗ speed (spin = 0), or base turn angle
 * ∫₀ᵗ spin (spin = 1), of the tool's motion list (the scene's definition,
 * by which its symbolic untils were resolved). */
static double nh_motion_integral(const nh_tool_spec *sp, double t, int spin) {
  return nh_scene_motion_integral(sp, sp->n_motion, 0.0, t, spin);
}

static double nh_motion_distance(const nh_tool_spec *sp, double t) {
  return nh_motion_integral(sp, t, 0);
}

double nh_tool_speed(const nh_tool_spec *sp, double t, double h) {
  return (nh_motion_distance(sp, t + h) - nh_motion_distance(sp, t)) / h;
}

/* NH_ERR_INPUT if the tool starts inside the tissue, its tip never comes
 * within one cell of it over its motion, or its motion carries its base
 * into the tissue (a tool shorter than the depth it is pushed to). The whole
 * motion is checked, not the part the run's steps cover: these are faults of
 * the scene, and a run cut short (`time.steps`, `time.end`) before the tool
 * arrives is a valid run of a valid scene. */
static int nh_tool_check_reach(const nh_mesh *m, const nh_tool_spec *sp) {
  double dmax = 0.0;
  for (int i = 0; i < sp->n_motion; i++)
    dmax = fmax(dmax, nh_motion_distance(sp, sp->motion[i].until));
  double tip0[3], tip1[3], base1[3], cell = fmax(m->spacing[0], fmax(m->spacing[1], m->spacing[2]));
  for (int i = 0; i < 3; i++) {
    tip0[i] = sp->base[i] + sp->length * sp->direction[i];
    tip1[i] = tip0[i] + dmax * sp->direction[i];
    base1[i] = sp->base[i] + dmax * sp->direction[i];
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
  NH_CHECK(!nh_domain_inside(&m->domain, base1), NH_ERR_INPUT,
           "%s: the motion carries the base into the tissue: after %g m of travel the base of "
           "this %g m tool is at [%g, %g, %g], inside it (a longer tool or a shorter motion)",
           sp->where, dmax, sp->length, base1[0], base1[1], base1[2]);
  return NH_OK;
}

void nh_tool_follow(nh_tool *in, const nh_tool *host, double h) {
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
    double ax[3], c = nh_vec3_dot(dir, t);
    nh_vec3_cross(dir, t, ax);
    double sn = sqrt(nh_vec3_dot(ax, ax)), ang = atan2(sn, c);
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

int nh_tool_init(nh_contact *c, int k, const nh_mesh *m) {
  nh_tool *tl = &c->tools[k];
  const nh_tool_spec *sp = &c->scene->tools[k];
  tl->spec = sp;
  tl->host = sp->inside;
  tl->nest_row = -1;
  nh_beam_spec bs = {.section = {sp->young, sp->poisson, sp->radius, sp->inner_radius, sp->density},
                     .length = sp->length,
                     .elements = sp->elements};
  memcpy(bs.base, sp->base, sizeof bs.base);
  memcpy(bs.direction, sp->direction, sizeof bs.direction);
  memcpy(bs.normal, sp->bevel_toward, sizeof bs.normal); /* zero: the beam's default d2 */
  int rc = nh_beam_create(&bs, &tl->beam);
  if (rc) {
    char why[256];
    snprintf(why, sizeof why, "%s", nh_error_message());
    return NH_ERROR(rc, "%s: %s", sp->where, why);
  }
  tl->f_node = nh_calloc(3 * (size_t)nh_beam_nodes(tl->beam), sizeof(double));
  if (!tl->f_node) return NH_ERR_MEMORY;
  if (tl->host < 0) return nh_tool_check_reach(m, sp);
  const nh_tool_spec *hs = &c->scene->tools[tl->host];
  double d[3] = {sp->base[0] - hs->base[0], sp->base[1] - hs->base[1], sp->base[2] - hs->base[2]};
  tl->offset = nh_vec3_dot(d, hs->direction);
  nh_tool_follow(tl, &c->tools[tl->host], 0.0);
  return NH_OK;
}

void nh_tools_follow(nh_contact *c, double t_new, double h) {
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    if (tl->host < 0 || tl->released) continue;
    nh_tool_follow(tl, &c->tools[tl->host], h);
    if (t_new >= tl->spec->release - 1e-12 * h) tl->released = 1;
  }
}

void nh_tools_blocks(nh_contact *c, double t, double h, double tau, int moving, const double g[3]) {
  const int statics = c->statics;
  int nd = 0;
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    const nh_tool_spec *sp = tl->spec;
    tl->dyn = -1;
    if (tl->host >= 0 && !tl->released) continue; /* follows its host */
    /* the base translates along `direction` and turns about it (its d1
     * stays `direction`: the base never bends), by the step's travel and
     * turn per τ (the step h, or 1 in the quasi-static mode, whose first
     * iteration moves the base by the whole step; later ones not at all) */
    double rate = moving ? nh_tool_speed(sp, t, h) * h / tau : 0.0,
           spin = moving ? (nh_motion_integral(sp, t + h, 1) - nh_motion_integral(sp, t, 1)) / tau
                         : 0.0;
    for (int i = 0; i < 3; i++)
      tl->base_v[i] = rate * sp->direction[i], tl->base_v[3 + i] = spin * sp->direction[i];
    tl->dyn = nd;
    c->blocks[nd] = (nh_coupled_tool){.beam = tl->beam,
                                      .options = {.dt = tau,
                                                  .alpha = statics ? 0.0 : sp->damping_mass,
                                                  .beta = statics ? 0.0 : sp->damping_stiffness,
                                                  .gravity = {g[0], g[1], g[2]},
                                                  .quasi_static = statics},
                                      .f_ext = NULL};
    memcpy(c->blocks[nd].base_velocity, tl->base_v, sizeof tl->base_v);
    nd++;
  }
  c->n_blocks = nd;
}

int nh_tools_clear_forces(nh_contact *c) {
  for (int k = 0; k < c->n; k++) {
    nh_tool *tl = &c->tools[k];
    memset(tl->F, 0, sizeof tl->F);
    memset(tl->f_node, 0, sizeof(double) * 3 * (size_t)nh_beam_nodes(tl->beam));
    const double *x = nh_beam_positions(tl->beam);
    for (int i = 0; i < 3 * nh_beam_nodes(tl->beam); i++)
      if (!isfinite(x[i]))
        return NH_ERROR(NH_ERR_NUMERIC, "tool %s: position not finite", tl->spec->name);
  }
  return NH_OK;
}

void nh_tool_add_force(nh_tool *tl, const nh_rows *rows, int r, double tau, double s) {
  const double *n = rows->dir + 3 * r;
  int nn = nh_beam_nodes(tl->beam), node = (int)lround(s / nh_beam_length(tl->beam) * (nn - 1));
  node = node < 0 ? 0 : (node >= nn ? nn - 1 : node);
  for (int i = 0; i < 3; i++) {
    double f = -n[i] * rows->lambda[r] / tau;
    tl->F[i] += f;
    tl->f_node[3 * node + i] += f;
  }
}

/* Newton on t(s) · (x − x(s)) = 0, each iterate clamped to the tool
 * [0, L]; beyond an end the answer is the end's tangent extrapolation
 * (an iterate clamped to the end whose correction points out again: the
 * next iteration would repeat it). The stop depends on the corrections
 * only, not on how s's rounding went: a tolerance-sized change of x or of
 * the tool (an iterative solve's) changes s by as little. */
double nh_tool_project(const nh_beam *b, const double x[3], double s0) {
  const double L = nh_beam_length(b);
  double s = s0;
  for (int it = 0; it < 8; it++) {
    double xs[3], t[3], sc = fmin(fmax(s, 0.0), L);
    const int clamped = sc != s;
    nh_beam_point(b, sc, xs, t, NULL, NULL, NULL);
    double d[3] = {x[0] - xs[0], x[1] - xs[1], x[2] - xs[2]};
    double ds = nh_vec3_dot(t, d);
    s = sc + ds;
    if (fabs(ds) < 1e-13 * L || (clamped && (s < 0.0 || s > L))) break;
  }
  return s;
}

nh_beam *nh_contact_beam(nh_contact *c, int k) {
  return c->tools[k].beam;
}

void nh_contact_report(const nh_contact *c, int k, nh_tool_report *r) {
  const nh_tool *tl = &c->tools[k];
  const nh_group *G = &c->groups[tl->group];
  double t[3], L = nh_beam_length(tl->beam);
  nh_beam_point(tl->beam, L, r->tip, t, NULL, NULL, NULL);
  double ft = nh_vec3_dot(tl->F, t), lat[3];
  for (int i = 0; i < 3; i++) lat[i] = tl->F[i] - ft * t[i];
  r->axial_force = -ft;
  r->lateral_force = sqrt(nh_vec3_dot(lat, lat));
  r->state = tl->state;
  r->depth = 0.0;
  if (G->punctured && G->n_chan > 0 && tl->state != NH_TOOL_OUTSIDE) {
    /* the entry point's arc length on this tool (from its tie's, else from
     * the tip: an untied entry is within half a spacing of the tip) */
    const nh_cpoint *e = &G->chan[0];
    double s = nh_tool_project(tl->beam, G->entry_x, e->tool == k ? e->s : L);
    r->depth = fmax(0.0, L - fmax(s, 0.0));
  }
}

void nh_contact_tip_disc(const nh_contact *c, int k, double tau, nh_tip_disc *d) {
  const nh_tool *tl = &c->tools[k];
  const nh_group *G = &c->groups[tl->group];
  const nh_rows *rows = &c->rows;
  *d = (nh_tip_disc){0};
  int r = G->outer == k && G->entry_row >= 0 ? G->entry_row : G->tip_tool == k ? G->front.row : -1;
  if (r < 0 || r + 3 > rows->m) return;
  double f2 = 0.0;
  for (int q = 0; q < 3; q++) f2 += rows->lambda[r + q] * rows->lambda[r + q];
  if (!(f2 > 0.0)) return;
  d->active = 1;
  d->force = sqrt(f2) / tau;
  d->radius = nh_tip_radius(tl->spec);
  d->node = rows->node + rows->start[r];
  d->n_nodes = rows->start[r + 1] - rows->start[r];
}

void nh_contact_node_forces(const nh_contact *c, int k, double *f) {
  memcpy(f, c->tools[k].f_node, sizeof(double) * 3 * (size_t)nh_beam_nodes(c->tools[k].beam));
}
