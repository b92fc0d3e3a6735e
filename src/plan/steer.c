/* steer.c — `needlehex plan` for a bevel-tip needle: the turn depths and the
 * insertion depth that put the tip on the target while its path keeps a
 * clearance from the obstacles (docs/cases.md, "Planning the steering").
 *
 * Unknowns. The rotation schedule is a plan of the bicycle model
 * (bicycle.c): K = 1 or 2 half turns of the base at depths d_j, and the
 * final depth D, in the plane of the insertion direction and the bevel.
 * The planner does not iterate on (d_j, D) directly but on what they are
 * for the model: q = (a, c*), a the point (in that plane) the model's path
 * ends at — a virtual target — and c* the model path's clearance. The
 * kinematic planner maps q to a schedule (nh_bike_choose: fewest turns, then
 * least excursion, passing the obstacle at exactly c* when the clearance
 * decides); a run's realized schedule (its depths at the turns and at the
 * end, read back from tools.csv) maps back to q = (model end point, model
 * clearance). This change of variables is the bicycle model's Jacobian: in
 * the model's limit (a tissue much stiffer than the needle, κ right) a run
 * ends where its q says, so the residual
 *     F(q) = (miss along x, miss along y, measured clearance − c_goal, miss along z)
 * is q − (T, c_goal), its Jacobian is I, and the first iterate, the bicycle
 * model's solution q₀ = (T, c_goal), is on the target: one run.
 *
 * Out of the plane: the last half turn spins the base by π + θ, which turns
 * the last arc about the tangent at that turn by θ (bicycle.c), so the
 * virtual target a has a z (along e_x × e_y) too: q = (a_x, a_y, c*, a_z),
 * F gains the miss along z, and the kinematic planner maps a to the planar
 * plan ending at a' and the roll θ = atan(a_z / ℓ) (ℓ: a's offset in the
 * plane from the last turn's tangent, ∂z/∂θ = ℓ at θ = 0), a' the point the
 * rotation carries to a; a run's realized schedule maps back through the
 * same rotation, so J = I holds for z as for x and y in the model's limit.
 * A target off the bevel's plane is reached this way; in a tissue that
 * pushes the tip out of the plane (friction, the mesh's asymmetry), the
 * roll corrects that part of the miss, which half turns in the plane cannot.
 *
 * The model learns. After every round the curvature of each arc is fitted
 * to the best run's tip path (nh_bike_fit: in a soft gel the needle's path
 * starts straight and, already bent and deep, curves less after each
 * turn), and the depth lag δ of the tip behind the base's travel
 * (puncture, compression) is taken from it; every run's q is recomputed
 * with the new model, so all runs so far are data in the same coordinates.
 *
 * Iteration (trust.c): Broyden's method on F(q) = 0 from J = I, globalised
 * by a trust region. Every step starts from the best run b so far (least
 * |miss| + clearance deficit): q ← q_b + t d, J d = −F_b, J = I updated by
 * Broyden with the secants of every run that has a residual (nearest b
 * first, orthogonalised so that all these secant equations hold), t ≤ 1
 * the largest fraction whose schedule changes no depth (turns, end) of b's
 * (or the end's z, |Δa_z|, the roll's effect) by more than the radius Δ;
 * the candidate's schedule is b's (as it ran)
 * moved by the model's change from its schedule at q_b to that at q. Δ starts at the first run's
 * miss, halves (to half the step) after a step that gained less than a quarter of what the linear
 * model predicts, or whose simulation failed (a constraint solve that stalls, cells inverted: exit
 * 1; no residual, so no secant), and doubles after a good step at the radius. With the model
 * refitted, J stays near I and the step is the model's own correction; the secants learn what the
 * model misses (how a turn depth moves the later arcs' curvature).
 *
 * Clearance: c_goal = plan.clearance + tolerance. The clearance equation is
 * part of F from the first iterate on when the model's plan is decided by
 * it (the obstacle is in the way), or from the first run whose measured
 * clearance (the tip path's least distance to an obstacle's surface,
 * obstacle.c) is below plan.clearance; the kinematic planner then passes
 * the obstacle at exactly c* (its "exact" mode). Until then c* = c_goal is
 * a lower bound of the model clearance, and F has two components. A plan
 * has converged when |miss| <= tolerance and the measured clearance >=
 * plan.clearance.
 *
 * Curvature to start from: plan.curvature, else κ₀ = tan ψ / (0.32 s +
 * 1.1 d) (the wheelbase the channel gives in a stiff tissue: s the channel
 * spacing, d the advance per step; docs/interaction.md, "Bevel tip"), the
 * same for every arc.
 *
 * Rounds: with --workers N, each round runs N candidates at once
 * (runs.c): the Broyden step and N − 1 probes at the step plus 2 ×
 * tolerance along one unknown of q each, which give J more secants per
 * round.
 *
 * Torsion: with interaction.torsion_per_length τ the tip lags the base; a
 * half turn at inserted length L_j is made of π + λ(L_j) − λ(L_{j−1}) at the
 * base, λ(L) = τ L (L_tool − L)/GJ + τ L²/(2 GJ) the steady lag of a
 * straight needle (docs/interaction.md, "Torsional friction"), so that the
 * tip turns by π. */
#include "beam/beam.h"
#include "contact/contact.h"
#include "io/io.h"
#include "plan/plan_impl.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { NH_Q = NH_TRUST_Q }; /* a_x, a_y, c*, a_z */

/* One run of the plan. */
typedef struct {
  int round, probe;
  double q[NH_Q];        /* the candidate's q (a in the plane, c*, a's z) */
  nh_bike_plan plan;     /* the schedule it ran (model lengths) */
  nh_bike_plan realized; /* the one it realized (depths read back) */
  double delta;          /* the depth lag its base travel allowed for */
  double qr[NH_Q];       /* q of the realized schedule (current model) */
  double F[NH_Q];        /* residual */
  double miss[3], distance, clearance, seconds, twist;
  double turn_angle[NH_BIKE_MAX_ARCS];
  double base[NH_BIKE_MAX_ARCS + 1]; /* base travel at each turn and at the end, m */
  int failed;                        /* its simulation failed */
  char message[512];
  int n;      /* its tip path inside the tissue: */
  double *xy; /* plane coordinates (2 per point) */
  double *s;  /* depths */
} nh_steer_run;

/* The problem. */
typedef struct {
  const nh_scene *s;
  const nh_tool_spec *tool;
  int target;
  nh_bike_frame frame;
  nh_obstacles *obstacles;
  double ez[3], standoff, speed, turn_time, h;
  double T[2], off_plane; /* the target in the plane, and its distance from it */
  double kappa0, delta;   /* κ₀ and the depth lag δ (m) the next candidates allow for */
  double c_goal;
  double gj, tau; /* GJ and torsion_per_length */
  int active;     /* the clearance equation is on */
} nh_steer;

static double dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Plane coordinates of world point x. */
static void nh_to_plane(const nh_steer *P, const double x[3], double xy[2]) {
  double d[3] = {x[0] - P->frame.entry[0], x[1] - P->frame.entry[1], x[2] - P->frame.entry[2]};
  xy[0] = dot3(d, P->frame.ex), xy[1] = dot3(d, P->frame.ey);
}

/* World point of q's virtual target (its plane coordinates and its z, q[3]). */
static void nh_to_world(const nh_steer *P, const double q[NH_Q], double x[3]) {
  for (int k = 0; k < 3; k++)
    x[k] = P->frame.entry[k] + q[0] * P->frame.ex[k] + q[1] * P->frame.ey[k] + q[3] * P->ez[k];
}

/* The components of q the iteration solves for, in its order: a_x, a_y, a_z,
 * then c* when the clearance equation is on. Returns their number. */
static int nh_steer_unknowns(const nh_steer *P, int idx[NH_Q]) {
  idx[0] = 0, idx[1] = 1, idx[2] = 3, idx[3] = 2;
  return P->active ? 4 : 3;
}

/* The steady twist lag of a straight needle with inserted length L. */
static double nh_lag(const nh_steer *P, double L) {
  const double Lt = P->tool->length;
  return P->tau > 0 ? P->tau * L * (Lt - L) / P->gj + P->tau * L * L / (2 * P->gj) : 0.0;
}

/* Set up the frame, speeds, target and curvature from the scene. */
static int nh_steer_setup(nh_steer *P, const nh_scene *s, int target) {
  const nh_tool_spec *t = &s->tools[s->targets[target].tool];
  P->s = s, P->tool = t, P->target = target;
  NH_CHECK(t->inside < 0, NH_ERR_INPUT, "%s: plan: the planned tool must not be nested", t->where);
  /* the entry: where the tool's axis enters the tissue's box */
  double tip0[3], t_in = -INFINITY, t_out = INFINITY;
  for (int k = 0; k < 3; k++) tip0[k] = t->base[k] + t->length * t->direction[k];
  for (int k = 0; k < 3; k++) {
    double d = t->direction[k], lo = s->tissue.box_min[k] - tip0[k],
           hi = s->tissue.box_max[k] - tip0[k];
    if (fabs(d) < 1e-300) {
      if (lo > 0 || hi < 0) t_in = INFINITY;
      continue;
    }
    double a = lo / d, b = hi / d;
    t_in = fmax(t_in, fmin(a, b)), t_out = fmin(t_out, fmax(a, b));
  }
  NH_CHECK(t_in <= t_out && t_in >= 0, NH_ERR_INPUT,
           "%s: plan: the tool's axis does not enter the tissue from outside", t->where);
  P->standoff = t_in;
  for (int k = 0; k < 3; k++) P->frame.entry[k] = tip0[k] + t_in * t->direction[k];
  /* the plane: x along the direction, y the bevel's side at t = 0 (the beam's d2) */
  nh_beam_spec bs = {.section = {t->young, t->poisson, t->radius, t->inner_radius, t->density},
                     .length = t->length,
                     .elements = t->elements};
  memcpy(bs.base, t->base, sizeof bs.base);
  memcpy(bs.direction, t->direction, sizeof bs.direction);
  memcpy(bs.normal, t->bevel_toward, sizeof bs.normal);
  nh_beam *beam = NULL;
  NH_TRY(nh_beam_create(&bs, &beam));
  const double *T0 = nh_beam_rest_directors(beam);
  for (int k = 0; k < 3; k++) P->frame.ex[k] = t->direction[k], P->frame.ey[k] = T0[3 * k + 1];
  const nh_beam_constants *bc = nh_beam_get_constants(beam);
  P->gj = bc->shear * bc->polar;
  nh_beam_destroy(&beam);
  nh_vec3_cross(P->frame.ex, P->frame.ey, P->ez);
  P->tau = t->torsion_per_length;
  /* the motion: the first insertion speed, the first turn's duration (1 s without) */
  P->speed = 0, P->turn_time = 1.0, P->h = s->time.step;
  int turned = 0;
  for (int i = 0; i < t->n_motion; i++) {
    double t0 = i ? t->motion[i - 1].until : 0.0;
    if (P->speed == 0 && t->motion[i].speed > 0) P->speed = t->motion[i].speed;
    if (!turned && t->motion[i].speed == 0 && t->motion[i].spin != 0)
      P->turn_time = t->motion[i].until - t0, turned = 1;
  }
  NH_CHECK(P->speed > 0, NH_ERR_INPUT,
           "%s: plan: the tool's motion has no insertion (a segment with speed > 0): the "
           "planner keeps its speed and plans the depths",
           t->where);
  /* the target in the plane */
  double xt[3];
  memcpy(xt, s->targets[target].point, sizeof xt);
  nh_to_plane(P, xt, P->T);
  double d[3] = {xt[0] - P->frame.entry[0], xt[1] - P->frame.entry[1], xt[2] - P->frame.entry[2]};
  P->off_plane = dot3(d, P->ez);
  /* κ₀ */
  double cell = INFINITY;
  for (int k = 0; k < 3; k++)
    cell = fmin(cell, (s->tissue.box_max[k] - s->tissue.box_min[k]) / s->tissue.grid[k]);
  double spacing = nh_channel_spacing(t->spacing, cell);
  P->kappa0 = s->plan.curvature > 0
                  ? s->plan.curvature
                  : tan(t->bevel * NH_PI / 180) / (0.32 * spacing + 1.1 * P->speed * P->h);
  for (int j = 0; j < NH_BIKE_MAX_ARCS; j++) P->frame.kappa[j] = P->kappa0;
  return NH_OK;
}

/* The candidate's overrides: the tool's motion for schedule p and the end time. */
static int nh_steer_candidate(const nh_steer *P, int tool, nh_steer_run *r, nh_candidate *c) {
  const nh_bike_plan *p = &r->plan;
  char motion[2048];
  size_t len = 0;
  double t = 0, depth = 0, lag_prev = 0;
  int seg = 0;
#define NH_SEG(...)                                                                                \
  do {                                                                                             \
    len += (size_t)snprintf(motion + len, len < sizeof motion ? sizeof motion - len : 0,           \
                            __VA_ARGS__);                                                          \
  } while (0)
  NH_SEG("[");
  if (p->sign0 < 0) { /* a half turn at the entry: the first arc bends away from the bevel */
    r->turn_angle[0] = NH_PI;
    t += P->turn_time;
    NH_SEG("{until: %.17g, speed: 0, spin: %.17g}", t, NH_PI / P->turn_time);
    seg++;
  }
  double done = 0; /* the base's travel so far */
  for (int j = 0; j < p->n; j++) {
    depth += p->len[j];
    double travel = P->standoff + depth + r->delta;
    r->base[j] = travel;
    if (travel > done) {
      t += (travel - done) / P->speed;
      done = travel;
      NH_SEG("%s{until: %.17g, speed: %.17g}", seg++ ? ", " : "", t, P->speed);
    }
    if (j + 1 < p->n) { /* a half turn, the lag of the channel made up for; the last one rolls */
      double lag = nh_lag(P, depth), angle = NH_PI + lag - lag_prev + (j + 2 == p->n ? p->roll : 0);
      lag_prev = lag;
      r->turn_angle[j + (p->sign0 < 0)] = angle;
      t += P->turn_time;
      NH_SEG("%s{until: %.17g, speed: 0, spin: %.17g}", seg++ ? ", " : "", t, angle / P->turn_time);
    }
  }
  NH_SEG("]");
#undef NH_SEG
  if (len >= sizeof motion) return NH_ERROR(NH_ERR_INTERNAL, "plan: motion text too long");
  double steps = ceil(t / P->h - 1e-9);
  NH_TRY(nh_candidate_set(c, "tools.%d.motion=%s", tool, motion));
  NH_TRY(nh_candidate_set(c, "time.end=%.17g", steps * P->h));
  return NH_OK;
}

/* Depth of the path at time t (the last row at or before it). */
static double nh_depth_at(const nh_run_result *res, double t) {
  double d = 0;
  for (int i = 0; i < res->n; i++) {
    if (res->time[i] > t + 1e-9) break;
    d = res->depth[i];
  }
  return d;
}

/* The turn times of a candidate's motion (the start of each turn in the tissue). */
static int nh_turn_times(const nh_steer *P, const nh_steer_run *r, double *times) {
  const nh_bike_plan *p = &r->plan;
  double t = p->sign0 < 0 ? P->turn_time : 0, done = 0;
  int n = 0;
  for (int j = 0; j < p->n; j++) {
    if (r->base[j] > done) t += (r->base[j] - done) / P->speed, done = r->base[j];
    times[n++] = t; /* the end of arc j: a turn, or the end */
    if (j + 1 < p->n) t += P->turn_time;
  }
  return n;
}

/* Read a run: miss, clearance, realized schedule, its path in the plane. */
static int nh_steer_read(const nh_steer *P, nh_steer_run *r, const nh_run_result *res) {
  r->seconds = res->seconds;
  r->failed = res->failed;
  if (res->failed) {
    snprintf(r->message, sizeof r->message, "%s", res->message);
    r->distance = r->clearance = NAN;
    return NH_OK;
  }
  memcpy(r->miss, res->miss, sizeof r->miss);
  r->distance = res->distance;
  r->twist = res->twist;
  r->clearance = nh_obstacles_clearance(P->obstacles, res->n, res->path, NULL);
  double tt[NH_BIKE_MAX_ARCS], prev = 0;
  int n = nh_turn_times(P, r, tt);
  r->realized = r->plan;
  for (int j = 0; j < n; j++) {
    double d = j + 1 == n ? (res->n ? res->depth[res->n - 1] : 0) : nh_depth_at(res, tt[j]);
    r->realized.len[j] = fmax(0.0, d - prev);
    prev = d;
  }
  r->xy = nh_calloc(2 * (size_t)(res->n ? res->n : 1), sizeof(double));
  r->s = nh_calloc((size_t)(res->n ? res->n : 1), sizeof(double));
  if (!r->xy || !r->s) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan");
  r->n = res->n;
  for (int i = 0; i < res->n; i++) {
    nh_to_plane(P, res->path + 3 * i, r->xy + 2 * i);
    r->s[i] = res->depth[i];
  }
  return NH_OK;
}

/* q of the realized schedule and the residual, with the current model. */
static void nh_steer_residual(const nh_steer *P, nh_steer_run *r) {
  if (r->failed) return;
  double end[3];
  nh_bike_end3(&r->realized, P->frame.kappa, end);
  r->qr[0] = end[0], r->qr[1] = end[1];
  r->qr[2] = P->active ? nh_bike_clearance(&P->frame, &r->realized) : r->q[2];
  r->qr[3] = end[2];
  r->F[0] = dot3(r->miss, P->frame.ex);
  r->F[1] = dot3(r->miss, P->frame.ey);
  r->F[2] = P->active ? r->clearance - P->c_goal : 0.0;
  r->F[3] = dot3(r->miss, P->ez);
}

/* The model from run r: each arc's curvature fitted to its path, and the
 * depth lag (planned minus realized depth, mean over the turns and the end,
 * plus the lag the run's base already allowed for). */
static void nh_steer_fit(nh_steer *P, const nh_steer_run *r) {
  if (r->n > 4) nh_bike_fit(&r->realized, r->n, r->xy, r->s, P->frame.kappa);
  double planned = 0, realized = 0, sum = 0;
  for (int j = 0; j < r->plan.n; j++) {
    planned += r->plan.len[j], realized += r->realized.len[j];
    sum += planned + r->delta - realized;
  }
  P->delta = sum / r->plan.n;
}

static double nh_merit(const nh_steer *P, const nh_steer_run *r) {
  return r->failed ? INFINITY : r->distance + fmax(0.0, P->s->plan.clearance - r->clearance);
}

static int nh_converged(const nh_steer *P, const nh_plan_options *o, const nh_steer_run *r) {
  return !r->failed && r->distance <= o->tolerance && r->clearance >= P->s->plan.clearance;
}

/* The schedule the kinematic planner gives q (its clearance part used when
 * active). 0, or −1 when there is none. */
static int nh_steer_choose(const nh_steer *P, const double q[NH_Q], nh_bike_plan *plan,
                           int *active) {
  nh_bike_choice c;
  /* c* may be negative (a path through the obstacle: the clearance is signed): a run
     that cut through maps to its own depth of cut, and the step's change of c* acts
     in full (clamped at 0, the best run's image and the step's plan both passed at
     0 and the first turn did not move: docs/cases.md) */
  double c_star = P->active ? q[2] : P->c_goal;
  /* the roll: the planar plan ends at a', the last arc turned by θ about the
     tangent at the last turn ends at a = (q_x, q_y, q_z): with a's coordinates
     (u, ℓ) along that tangent and its left normal, θ = atan(q_z / ℓ) and a' =
     turn + u t + (ℓ / cos θ) m (a rotation keeps the distance from its axis);
     a' moves the turn, so a fixed point (a' − a is O(θ² ℓ): a few iterations) */
  double a[2] = {q[0], q[1]};
  for (int it = 0; it < 50; it++) {
    /* active: the plan that passes at exactly c*, else one that keeps it */
    if (nh_bike_choose(&P->frame, a, c_star, P->active, &c) != 0 &&
        !(P->active && nh_bike_choose(&P->frame, a, c_star, 0, &c) == 0))
      return -1;
    double turn[2], h, along, lever;
    c.plan.roll = 0;
    if (!nh_bike_roll_lever(&c.plan, P->frame.kappa, turn, &h, &along, &lever)) break;
    const double ct = cos(h), st = sin(h), dx = q[0] - turn[0], dy = q[1] - turn[1];
    const double u = ct * dx + st * dy, l = -st * dx + ct * dy, theta = atan(q[3] / l);
    if (!(fabs(theta) <= NH_PI / 3))
      return -1; /* a on (near) the tangent line: no roll reaches it */
    c.plan.roll = theta;
    const double L = l / cos(theta), b[2] = {turn[0] + u * ct - L * st, turn[1] + u * st + L * ct};
    const double moved = hypot(b[0] - a[0], b[1] - a[1]);
    a[0] = b[0], a[1] = b[1];
    if (moved <= 1e-13) break;
    if (it == 49) return -1;
  }
  *plan = c.plan;
  if (active) *active = c.active;
  return 0;
}

/* The schedule for q; the step from `from` is halved until the kinematic
 * planner finds a plan (at most 12 times). 0, or −1 when none. */
static int nh_steer_plan(const nh_steer *P, const double from[NH_Q], double q[NH_Q],
                         nh_bike_plan *plan, int *active) {
  double step[NH_Q];
  for (int i = 0; i < NH_Q; i++) step[i] = q[i] - from[i];
  for (int it = 0; it < 13; it++) {
    if (nh_steer_choose(P, q, plan, active) == 0) return 0;
    for (int i = 0; i < NH_Q; i++) step[i] *= 0.5, q[i] = from[i] + step[i];
  }
  return -1;
}

/* A number as YAML reads it back (.inf for an infinite clearance). */
static const char *yaml_num(double x, char buf[32]) {
  if (isinf(x)) return x > 0 ? ".inf" : "-.inf";
  if (isnan(x)) return ".nan";
  snprintf(buf, 32, "%.17g", x);
  return buf;
}

/* The turn and end depths of a schedule (n values). */
static void put_depths(FILE *f, const nh_bike_plan *p) {
  double d = 0;
  fprintf(f, "{initial_turn: %s, turns: [", p->sign0 < 0 ? "true" : "false");
  for (int j = 0; j + 1 < p->n; j++) {
    d += p->len[j];
    fprintf(f, "%s%.17g", j ? ", " : "", d);
  }
  fprintf(f, "], depth: %.17g, roll: %.17g}", d + p->len[p->n - 1], p->roll);
}

/* The model's curvatures as a YAML list. */
static void put_kappa(FILE *f, const double *k) {
  fprintf(f, "[");
  for (int j = 0; j < NH_BIKE_MAX_ARCS; j++) fprintf(f, "%s%.17g", j ? ", " : "", k[j]);
  fprintf(f, "]");
}

static int nh_steer_write(const char *out, const char *scene_path, const nh_steer *P,
                          const nh_plan_options *o, const nh_steer_run *runs, int n_runs, int final,
                          int converged, double seconds) {
  char *text = NULL, b[32], b2[32];
  size_t size = 0;
  FILE *f = open_memstream(&text, &size);
  if (!f) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan.yaml");
  const nh_scene *s = P->s;
  const nh_target *g = &s->targets[P->target];
  const nh_steer_run *F = &runs[final];
  double aim[3];
  fprintf(f, "# needlehex plan: steering a bevel-tip needle (docs/cases.md, Planning the\n"
             "# steering). Lengths in m, angles in rad, times in s (wall); miss = tip of the\n"
             "# target's tool minus the target's position at the last step; clearance = the\n"
             "# tip path's least distance to an obstacle's surface; aim = the point the\n"
             "# bicycle model's path of the schedule ends at; depths are the tip's in the\n"
             "# tissue (planned; realized: read back at the turns and the end); curvature:\n"
             "# the model's per arc (first, after one turn, after two), last fitted; roll:\n"
             "# the last half turn's angle beyond pi (rad, right-handed about the heading).\n");
  fprintf(f, "scene: %s\ntarget: %s\ntool: %s\ntarget_point: ", scene_path, g->name, P->tool->name);
  nh_plan_put_vec(f, g->point);
  fprintf(f, "\nentry: ");
  nh_plan_put_vec(f, P->frame.entry);
  fprintf(f, "\nbevel_side: ");
  nh_plan_put_vec(f, P->frame.ey);
  fprintf(f, "\ntolerance: %.17g\nmax_runs: %d\nworkers: %d\nclearance_required: %.17g\n",
          o->tolerance, o->max_runs, o->workers, s->plan.clearance);
  fprintf(f, "curvature: ");
  put_kappa(f, P->frame.kappa);
  fprintf(f, "\ncurvature_initial: %.17g\ndepth_lag: %.17g\nconverged: %s\nruns: %d\ntime: %.3f\n",
          P->kappa0, P->delta, converged ? "true" : "false", n_runs, seconds);
  fprintf(f, "aim: ");
  nh_to_world(P, F->q, aim);
  nh_plan_put_vec(f, aim);
  fprintf(f, "\nmiss: %s\nclearance: %s\nschedule: ", yaml_num(F->distance, b),
          yaml_num(F->clearance, b2));
  put_depths(f, &F->plan);
  fprintf(f, "\nfinal_run: run_%02d\niterations:\n", final + 1);
  for (int k = 0; k < n_runs; k++) {
    const nh_steer_run *r = &runs[k];
    nh_to_world(P, r->q, aim);
    fprintf(f, "  - {run: %d, round: %d, kind: %s, aim: ", k + 1, r->round + 1,
            r->probe ? "probe" : "step");
    nh_plan_put_vec(f, aim);
    if (P->active) fprintf(f, ", clearance_planned: %.17g", r->q[2]);
    fprintf(f, ", schedule: ");
    put_depths(f, &r->plan);
    fprintf(f, ", base_turns: [");
    for (int j = 0; j + 1 < r->plan.n + (r->plan.sign0 < 0); j++)
      fprintf(f, "%s%.17g", j ? ", " : "", r->turn_angle[j]);
    fprintf(f, "], depth_lag: %.17g", r->delta);
    if (r->failed) {
      fprintf(f, ", failed: \"");
      for (const char *c = r->message; *c; c++) fputc(*c == '"' || *c == '\\' ? '\'' : *c, f);
      fprintf(f, "\", miss: .nan, time: %.3f}\n", r->seconds);
      continue;
    }
    fprintf(f, ", realized: ");
    put_depths(f, &r->realized);
    fprintf(f, ", miss_vector: ");
    nh_plan_put_vec(f, r->miss);
    fprintf(f, ", miss: %.17g, clearance: %s, twist: %.17g, time: %.3f}\n", r->distance,
            yaml_num(r->clearance, b), r->twist, r->seconds);
  }
  return nh_plan_yaml_finish(f, &text, out);
}

/* One line per run on stdout. */
static void nh_steer_print(const nh_steer_run *r, int k) {
  double d = 0;
  printf("run %d (round %d, %s): turns at", k + 1, r->round + 1, r->probe ? "probe" : "step");
  for (int j = 0; j + 1 < r->plan.n; j++) printf(" %.2f", 1e3 * (d += r->plan.len[j]));
  printf(" mm%s, roll %.3f deg, depth %.2f mm: ", r->plan.sign0 < 0 ? " (turned at the entry)" : "",
         r->plan.roll * 180 / NH_PI, 1e3 * (d + r->plan.len[r->plan.n - 1]));
  if (r->failed)
    printf("FAILED (%s), %.1f s\n", r->message, r->seconds);
  else
    printf("miss %.4g mm ([%.4g, %.4g, %.4g]), clearance %.4g mm, %.1f s\n", 1e3 * r->distance,
           1e3 * r->miss[0], 1e3 * r->miss[1], 1e3 * r->miss[2], 1e3 * r->clearance, r->seconds);
  fflush(stdout);
}

/* The schedule of a step from the best run b: b's own schedule (as it ran)
 * moved by the model's change from `from` (the model's schedule at b's q)
 * to p, depth by depth: the model acts on the change only, and b's
 * schedule, not the model's image of it, is where the step starts. */
static void nh_steer_shift(const nh_bike_plan *b, const nh_bike_plan *from, nh_bike_plan *p) {
  nh_bike_plan out = *b;
  double cb = 0, cf = 0, cp = 0, prev = 0;
  for (int j = 0; j < b->n; j++) {
    cb += b->len[j], cf += from->len[j], cp += p->len[j];
    double d = fmax(prev, cb + cp - cf);
    out.len[j] = d - prev, prev = d;
  }
  out.roll = b->roll + p->roll - from->roll;
  *p = out;
}

/* The trust region's step length: the largest change of a depth (turns,
 * end) from the best run's schedule, or of the end's z (the roll's effect,
 * |Δa_z|), whichever is larger. qb and d hold the unknowns (idx). */
typedef struct {
  const nh_steer *P;
  nh_bike_plan from;
  double qb[NH_Q]; /* the best run's q, all components */
  int n, idx[NH_Q];
} nh_steer_span;

/* q = the best run's with the unknowns at qb + t d. */
static void nh_steer_unpack(const nh_steer_span *c, const double *qb, const double *d, double t,
                            double q[NH_Q]) {
  memcpy(q, c->qb, sizeof c->qb);
  for (int k = 0; k < c->n; k++) q[c->idx[k]] = qb[k] + t * d[k];
  if (!c->P->active) q[2] = c->P->c_goal;
}

static double nh_steer_length(void *ctx, const double *qb, const double *d, double t) {
  const nh_steer_span *c = ctx;
  double q[NH_Q];
  nh_bike_plan p;
  nh_steer_unpack(c, qb, d, t, q);
  if (nh_steer_choose(c->P, q, &p, NULL)) return INFINITY;
  return fmax(nh_bike_depth_change(&p, &c->from), fabs(q[3] - c->qb[3]));
}

/* The next round's q: the trust region's Broyden step from the best run b
 * (trust.c), every run with a residual a secant. 0, or −1 when none. */
static int nh_steer_step(const nh_steer *P, nh_trust *tr, const nh_steer_run *runs, int n_runs,
                         int best, double *Q, double *F, int *ok, double q[NH_Q],
                         nh_bike_plan *from) {
  nh_steer_span span = {.P = P, .from = runs[best].realized};
  span.n = nh_steer_unknowns(P, span.idx);
  memcpy(span.qb, runs[best].qr, sizeof span.qb);
  for (int i = 0; i < n_runs; i++) {
    for (int k = 0; k < span.n; k++)
      Q[NH_Q * i + k] = runs[i].qr[span.idx[k]], F[NH_Q * i + k] = runs[i].F[span.idx[k]];
    ok[i] = !runs[i].failed;
  }
  nh_steer_choose(P, runs[best].qr, &span.from, NULL); /* else the realized schedule */
  *from = span.from;
  double step[NH_Q], zero[NH_Q] = {0};
  if (nh_trust_step(tr, span.n, n_runs, Q, F, ok, best, nh_steer_length, &span, step)) return -1;
  nh_steer_unpack(&span, step, zero, 0, q);
  if (getenv("NH_PLAN_DEBUG")) {
    for (int i = 0; i < n_runs; i++)
      fprintf(stderr,
              "  run %d: q [%.6g %.6g %.6g %.6g] qr [%.6g %.6g %.6g %.6g] F [%.6g %.6g %.6g "
              "%.6g]\n",
              i + 1, 1e3 * runs[i].q[0], 1e3 * runs[i].q[1], 1e3 * runs[i].q[2], 1e3 * runs[i].q[3],
              1e3 * runs[i].qr[0], 1e3 * runs[i].qr[1], 1e3 * runs[i].qr[2], 1e3 * runs[i].qr[3],
              1e3 * runs[i].F[0], 1e3 * runs[i].F[1], 1e3 * runs[i].F[2], 1e3 * runs[i].F[3]);
    fprintf(stderr, "  best %d, active %d, J [", best + 1, P->active);
    for (int i = 0; i < span.n; i++)
      for (int k = 0; k < span.n; k++)
        fprintf(stderr, "%.4g%s", tr->J[NH_TRUST_Q * i + k],
                k + 1 < span.n   ? " "
                : i + 1 < span.n ? "; "
                                 : "");
    fprintf(stderr, "], t %.3g, step %.3g mm, radius %.3g mm, next q [%.6g %.6g %.6g %.6g]\n",
            tr->t, 1e3 * tr->length, 1e3 * tr->radius, 1e3 * q[0], 1e3 * q[1], 1e3 * q[2],
            1e3 * q[3]);
  }
  return 0;
}

int nh_plan_steer(const char *scene_path, int n_sets, const char *const *sets,
                  const nh_scene *scene, int target, const nh_plan_options *o, const char *out) {
  nh_steer P = {0};
  NH_TRY(nh_steer_setup(&P, scene, target));
  NH_TRY(nh_obstacles_create(scene, &P.obstacles));
  P.frame.obstacles = P.obstacles;
  P.c_goal = scene->plan.clearance + o->tolerance;
  const int workers = o->workers > 1 ? o->workers : 1, tool = scene->targets[target].tool;
  nh_steer_run *runs = nh_calloc((size_t)o->max_runs, sizeof *runs);
  nh_candidate *cand = nh_calloc((size_t)workers, sizeof *cand);
  nh_run_result *res = nh_calloc((size_t)workers, sizeof *res);
  double *Q = nh_calloc(NH_Q * (size_t)o->max_runs, sizeof *Q),
         *F = nh_calloc(NH_Q * (size_t)o->max_runs, sizeof *F);
  int *ok = nh_calloc((size_t)o->max_runs, sizeof *ok);
  int rc =
      runs && cand && res && Q && F && ok ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: plan");
  nh_trust tr;
  nh_trust_init(&tr, INFINITY, 0, INFINITY);
  double t0 = nh_time_now(), q[NH_Q] = {P.T[0], P.T[1], P.c_goal, P.off_plane};
  int n_runs = 0, converged = -1, best = -1, round = 0, active0 = 0;
  nh_bike_plan plan = {0}, from_b = {0};
  if (!rc && nh_steer_plan(&P, q, q, &plan, &active0))
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: plan: the bicycle model (curvature %.4g 1/m) has no path with at most "
                  "two turns to the target that keeps %.3g mm from the obstacles",
                  scene->targets[target].where, P.kappa0, 1e3 * P.c_goal);
  P.active = active0;
  /* Broyden's steps stay in the first plan's homotopy class (around the
     obstacles): its first side and number of turns (a jump to another class
     is no small step in depth, and the secants of one class mislead in another) */
  if (!rc) P.frame.side = plan.sign0 < 0 ? -1 : 1, P.frame.turns = plan.n - 1;
  if (!rc && !o->quiet)
    printf("plan: steering %s to %s at [%.6g, %.6g, %.6g] mm, tolerance %.3g mm, clearance %.3g "
           "mm from %d obstacle%s, curvature %.4g 1/m%s, at most %d runs on %d worker%s\n",
           P.tool->name, scene->targets[target].name, 1e3 * scene->targets[target].point[0],
           1e3 * scene->targets[target].point[1], 1e3 * scene->targets[target].point[2],
           1e3 * o->tolerance, 1e3 * scene->plan.clearance, nh_obstacles_count(P.obstacles),
           nh_obstacles_count(P.obstacles) == 1 ? "" : "s", P.kappa0,
           scene->plan.curvature > 0 ? "" : " (estimated)", o->max_runs, workers,
           workers == 1 ? "" : "s");
  int repeat = 0;
  while (!rc && converged < 0 && n_runs < o->max_runs) {
    /* the round's candidates: the step at q, probes around it */
    const int nc = workers < o->max_runs - n_runs ? workers : o->max_runs - n_runs;
    int idx[NH_Q];
    const int nq = nh_steer_unknowns(&P, idx);
    int made = 0;
    for (int i = 0; i < nc && !rc; i++) {
      nh_steer_run *r = &runs[n_runs + made];
      memset(r, 0, sizeof *r);
      r->round = round, r->probe = i > 0, r->delta = P.delta;
      memcpy(r->q, q, sizeof r->q);
      if (i > 0) r->q[idx[(round + i - 1) % nq]] += 2 * o->tolerance;
      double qq[NH_Q];
      memcpy(qq, r->q, sizeof qq);
      if (nh_steer_plan(&P, best >= 0 ? runs[best].qr : q, qq, &r->plan, NULL)) {
        if (i == 0)
          rc = NH_ERROR(NH_ERR_NUMERIC,
                        "plan: round %d: the bicycle model has no path with at most two turns "
                        "to the corrected aim",
                        round + 1);
        continue;
      }
      memcpy(r->q, qq, sizeof qq);
      if (best >= 0 && isfinite(nh_bike_depth_change(&runs[best].plan, &from_b)) &&
          isfinite(nh_bike_depth_change(&r->plan, &from_b))) {
        nh_steer_shift(&runs[best].plan, &from_b, &r->plan);
        r->delta = runs[best].delta;
      }
      /* a step whose schedule repeats an earlier run's (the radius at its floor,
         J = I, from the same best run): the simulation is deterministic, so it
         would end as that run did; nothing new to learn, the plan stops */
      int again = -1;
      for (int k = 0; i == 0 && k < n_runs && again < 0; k++)
        if (nh_bike_depth_change(&runs[k].plan, &r->plan) <= 1e-12 &&
            fabs(runs[k].plan.roll - r->plan.roll) <= 1e-12 &&
            fabs(runs[k].delta - r->delta) <= 1e-12)
          again = k;
      if (again >= 0) {
        if (!o->quiet)
          printf("plan: stopped: the trust region is at its floor (%.3g mm) and the next step "
                 "repeats run %d's schedule\n",
                 1e3 * tr.radius, again + 1);
        repeat = 1;
        break;
      }
      nh_candidate *c = &cand[made];
      nh_candidate_free(c);
      snprintf(c->dir, sizeof c->dir, "%s/run_%02d", out, n_runs + made + 1);
      rc = nh_steer_candidate(&P, tool, r, c);
      made++;
    }
    if (repeat) break;
    if (!rc)
      rc = nh_runs_execute(scene_path, n_sets, sets, made, cand, workers, P.tool->name,
                           scene->targets[target].name, res);
    for (int i = 0; i < made && !rc; i++) {
      rc = nh_steer_read(&P, &runs[n_runs + i], &res[i]);
      nh_run_result_free(&res[i]);
    }
    const int first = n_runs;
    n_runs += made;
    if (rc) break;
    for (int i = first; i < n_runs && !o->quiet; i++) nh_steer_print(&runs[i], i);
    /* the clearance equation switches on at a run too close to an obstacle */
    for (int i = first; i < n_runs; i++)
      if (!runs[i].failed && runs[i].clearance < scene->plan.clearance &&
          nh_obstacles_count(P.obstacles) > 0)
        P.active = 1;
    for (int i = first; i < n_runs; i++)
      if (nh_converged(&P, o, &runs[i]) &&
          (converged < 0 || runs[i].distance < runs[converged].distance))
        converged = i;
    if (converged >= 0) break;
    /* the best run so far; the model from it; every run's q in the new model */
    const double merit_b = best >= 0 ? nh_merit(&P, &runs[best]) : INFINITY;
    for (int i = 0; i < n_runs; i++)
      if (!runs[i].failed && (best < 0 || nh_merit(&P, &runs[i]) < nh_merit(&P, &runs[best])))
        best = i;
    if (best < 0) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "plan: the first round's runs failed: %s", runs[0].message);
      break;
    }
    /* the trust region: its radius from the first best run's merit (a depth
       change of the order of the miss), then judged by each round's step */
    if (round == 0)
      nh_trust_init(&tr, fmax(nh_merit(&P, &runs[best]), 2 * o->tolerance), 0.1 * o->tolerance,
                    2 * fmax(nh_merit(&P, &runs[best]), 2 * o->tolerance));
    else
      nh_trust_judge(&tr, merit_b, nh_merit(&P, &runs[first]));
    nh_steer_fit(&P, &runs[best]);
    for (int i = 0; i < n_runs; i++) nh_steer_residual(&P, &runs[i]);
    if (!o->quiet) {
      printf("model from run %d: curvature per arc", best + 1);
      for (int j = 0; j < NH_BIKE_MAX_ARCS; j++) printf(" %.4g", P.frame.kappa[j]);
      printf(" 1/m, depth lag %.3g mm; trust radius %.3g mm\n", 1e3 * P.delta, 1e3 * tr.radius);
    }
    if (nh_steer_step(&P, &tr, runs, n_runs, best, Q, F, ok, q, &from_b)) {
      rc = NH_ERROR(NH_ERR_NUMERIC,
                    "plan: round %d: the bicycle model has no path with at most two turns "
                    "within %.3g mm of run %d's depths",
                    round + 2, 1e3 * tr.radius, best + 1);
      break;
    }
    round++;
  }
  double seconds = nh_time_now() - t0;
  int final = converged >= 0 ? converged : best;
  if (n_runs > 0 && final >= 0) {
    int wrc = nh_steer_write(out, scene_path, &P, o, runs, n_runs, final, converged >= 0, seconds);
    if (!wrc) wrc = nh_plan_link_final(out, final + 1);
    if (!rc) rc = wrc;
    if (!rc && !o->quiet)
      printf("plan: %s after %d run%s (%.1f s): run %d, miss %.4g mm, clearance %.4g mm; "
             "%s/plan.yaml, its outputs in %s/final\n",
             converged >= 0 ? "converged" : "NOT converged", n_runs, n_runs == 1 ? "" : "s",
             seconds, final + 1, 1e3 * runs[final].distance, 1e3 * runs[final].clearance, out, out);
    if (!rc && converged < 0)
      rc = NH_ERROR(NH_ERR_NUMERIC,
                    "plan: the best run misses by %.4g mm with clearance %.4g mm after %d runs "
                    "(tolerance %.4g mm, clearance %.4g mm)",
                    1e3 * runs[final].distance, 1e3 * runs[final].clearance, n_runs,
                    1e3 * o->tolerance, 1e3 * scene->plan.clearance);
  }
  for (int i = 0; cand && i < workers; i++) nh_candidate_free(&cand[i]);
  for (int i = 0; res && i < workers; i++) nh_run_result_free(&res[i]);
  for (int i = 0; runs && i < n_runs; i++) free(runs[i].xy), free(runs[i].s);
  free(cand), free(res), free(runs), free(Q), free(F), free(ok);
  nh_obstacles_destroy(&P.obstacles);
  return rc;
}
