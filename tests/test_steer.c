/* test_steer.c — the steering planner's kinematic model and obstacles
 * (src/plan/bicycle.c, src/plan/obstacle.c, mesh/region.c's distance).
 *
 * Expectations, each derived independently of the code under test:
 *  1. the two-arc finish: forward integration of its two arcs (the arc
 *     formula, here written out again) from random starts, headings, signs
 *     and curvatures (equal, or two) ends on the target (to 1e-12 of the
 *     scale); a target is reachable exactly when its distance from the first
 *     arc's centre lies in [a, a + 2b] (a, b the two radii: the second
 *     circle's centre lies at a + b from the first's, the target on it);
 *  2. the kinematic plan without obstacles has one turn and ends on the
 *     target; with a cylinder across the straight line which the one-turn S
 *     (excursion about 1/(4 kappa) = 10 mm > radius + clearance) passes, it
 *     keeps one turn with at least the clearance asked; in exact mode it has
 *     two turns, ends on the target and passes the cylinder at exactly the
 *     clearance asked (the bisection's tolerance, 1e-9 m), also a negative
 *     one (the signed distance: a path through the cylinder, what a run that
 *     cut through it maps back to); asked for less clearance it stays closer
 *     (monotone);
 *  3. region distances at hand-computed points (sphere, box outside and
 *     inside, finite cylinder beside, beyond an end, at a rim);
 *  4. a label obstacle: label 2 of cases/steering/obstacle.nii.gz, the
 *     voxels (1 mm) whose centres lie within 4 mm of the axis x = 60, y =
 *     40 mm: its voxel staircase lies within half a voxel diagonal in the
 *     (x, y) plane (0.5 √2 mm) of the cylinder's side, so the label's
 *     distance differs from the cylinder's by at most that;
 *  5. the curvature fit recovers the three arcs' κ of a path made by the
 *     model with the same schedule (golden section to 1e-7 relative);
 *  6. the planner's iteration (trust.c), driven as steer.c drives it (step
 *     from the best point, radius judged by each step's merit):
 *     (a) on affine F(q) = A (q − q*) (A = I + E, |E_ij| <= 0.3, n = 2, 3
 *     and 4, no radius limit, no secant skipped) every secant equation is
 *     exact, so once n
 *     secants in general position are in J, J = A: point n + 2 is the root
 *     (to 1e-9 of |F_1|; 50 random A, q*);
 *     (b) on the bicycle model itself with each arc's true curvature off
 *     the model's by +15, −10, +20 % (F = the true end of the model's plan
 *     for q, minus T; depth-change radius as the planner's): F is affine up
 *     to O(|e|/R) relative (R = 1/κ = 33 mm), so once J holds the n = 2
 *     secants (point 4) each step multiplies the error by about |e|/R,
 *     from a first miss e_1 = O(ε L²κ/2) ≈ 10 mm: ≈ 3 mm, 0.3 mm, 3 µm,
 *     3e-10 m: |F| <= 1e-6 m by point n + 2 + 3 = 7, and every best merit
 *     no larger than the one before;
 *     (c) as (b), but a step that changes a depth by more than 2 mm "fails"
 *     (as a run whose cells invert): after each failure the next step is at
 *     most half as long and starts from the same best; the radius (first
 *     |F_1|) reaches 2 mm after at most ⌈log2(|F_1| / 2 mm)⌉ + 1 failures,
 *     the steps then cover the ≤ 2|F_1| of depth at >= 1 mm each, and (b)'s
 *     end game follows: converged (1e-6 m) within 30 points.
 *  7. the roll (nh_bike_end3): a frame (heading, bevel) carried along the
 *     plan in 3-D, each arc bending towards the bevel, each half turn
 *     spinning it about the heading by π (the last by π + θ), ends where
 *     the closed form (the last arc turned by θ about the tangent at the
 *     last turn) says, to 1e-12 m (40 random plans, |θ| <= 1); ∂z/∂θ at θ
 *     = 0 by central differences equals the lever (the end's offset from
 *     that tangent in the plane). */
#include "check.h"
#include "mesh/mesh.h"
#include "plan/plan_impl.h"

#include <string.h>

/* The arc formula, written out again for the check. */
static void arc(double st[3], double k, double l) {
  double t1 = st[2] + k * l;
  st[0] += (sin(t1) - sin(st[2])) / k;
  st[1] -= (cos(t1) - cos(st[2])) / k;
  st[2] = t1;
}

static double urand(double a, double b) {
  return a + (b - a) * rand() / (double)RAND_MAX;
}

static void test_finish(void) {
  srand(7);
  int solved = 0;
  for (int t = 0; t < 2000; t++) {
    /* equal curvatures half the time (Webster's model), else two */
    double ka = urand(1, 50), kb = t % 2 ? ka : urand(1, 50), Ra = 1 / ka, Rb = 1 / kb;
    double R = fmax(Ra, Rb), start[2] = {urand(-R, R), urand(-R, R)};
    double heading = urand(-M_PI, M_PI), sign = rand() % 2 ? 1.0 : -1.0;
    /* a target at distance rho in [0.5 a, 1.2 (a + 2b)] from the first arc's centre */
    double c[2] = {start[0] - sign * Ra * sin(heading), start[1] + sign * Ra * cos(heading)};
    double rho = urand(0.5 * Ra, 1.2 * (Ra + 2 * Rb)), phi = urand(-M_PI, M_PI);
    double T[2] = {c[0] + rho * cos(phi), c[1] + rho * sin(phi)}, len[2];
    int rc = nh_bike_finish(start, heading, sign, ka, kb, T, len);
    int inside = rho >= Ra * (1 + 1e-9) && rho <= (Ra + 2 * Rb) * (1 - 1e-9);
    if (rho < Ra * (1 - 1e-9) || rho > (Ra + 2 * Rb) * (1 + 1e-9))
      CHECK(rc != 0, "rho = %g, a = %g, b = %g: expected no two-arc path", rho, Ra, Rb);
    if (!inside) continue;
    CHECK(rc == 0, "rho = %g in [a, a + 2b] = [%g, %g]: expected a two-arc path", rho, Ra,
          Ra + 2 * Rb);
    if (rc) continue;
    solved++;
    CHECK(len[0] >= 0 && len[1] >= 0 && len[0] <= 2 * M_PI * Ra && len[1] <= 2 * M_PI * Rb,
          "arc lengths %g %g outside [0, 2 pi R]", len[0], len[1]);
    double st[3] = {start[0], start[1], heading};
    arc(st, sign * ka, len[0]);
    arc(st, -sign * kb, len[1]);
    CHECK_CLOSE(st[0], T[0], 1e-12 * (1 + R), "finish: end x");
    CHECK_CLOSE(st[1], T[1], 1e-12 * (1 + R), "finish: end y");
  }
  CHECK(solved > 500, "only %d reachable targets solved", solved);
}

/* A scene holding plan.obstacles only (what nh_obstacles_create reads). */
static nh_scene *scene_with(int n, const nh_region *r, const char *labels) {
  nh_scene *s = calloc(1, sizeof *s);
  s->plan.n_obstacles = n;
  s->plan.obstacles = calloc((size_t)n + 1, sizeof *r);
  memcpy(s->plan.obstacles, r, sizeof *r * (size_t)n);
  if (labels) snprintf(s->tissue.labels_file, sizeof s->tissue.labels_file, "%s", labels);
  return s;
}

static void free_scene(nh_scene *s) {
  free(s->plan.obstacles);
  free(s);
}

static void test_choose(void) {
  nh_region cyl = {.kind = NH_REGION_CYLINDER,
                   .start = {0.06, 0.04, 0.0},
                   .end = {0.06, 0.04, 0.039},
                   .radius = 0.004};
  nh_scene *s = scene_with(1, &cyl, NULL);
  nh_obstacles *ob = NULL;
  CHECK_OK(nh_obstacles_create(s, &ob));
  nh_bike_frame f = {
      .entry = {0, 0.04, 0.0195}, .ex = {1, 0, 0}, .ey = {0, 1, 0}, .kappa = {10, 8, 6}};
  nh_bike_choice c;
  /* without obstacles: one turn, on the target */
  double T1[2] = {0.1, 0.02}, end[2];
  CHECK(nh_bike_choose(&f, T1, 0.001, 0, &c) == 0, "no plan to (0.1, 0.02)");
  CHECK(c.plan.n == 2 && !c.active, "one turn expected, got %d arcs, active %d", c.plan.n,
        c.active);
  nh_bike_end(&c.plan, f.kappa, end, NULL);
  CHECK_CLOSE(end[0], T1[0], 1e-12, "one turn: end x");
  CHECK_CLOSE(end[1], T1[1], 1e-12, "one turn: end y");
  /* the cylinder across the line: the one-turn S passes it (excursion ~ 1/(4 kappa)), so the
     chooser keeps one turn; exact mode gives two turns at exactly the clearance asked */
  f.obstacles = ob;
  double T2[2] = {0.12, 0.0}, last = INFINITY;
  for (double want = 0.003; want >= -0.0025; want -= 0.001) { /* < 0: through the cylinder */
    CHECK(nh_bike_choose(&f, T2, want, 0, &c) == 0, "no plan around the cylinder (%g)", want);
    CHECK(c.plan.n == 2 && !c.active, "one turn expected: %d arcs, active %d", c.plan.n, c.active);
    CHECK(c.clearance >= want, "one turn: clearance %g below %g", c.clearance, want);
    nh_bike_end(&c.plan, f.kappa, end, NULL);
    CHECK_CLOSE(end[0], T2[0], 1e-12, "one turn around: end x");
    CHECK_CLOSE(end[1], T2[1], 1e-12, "one turn around: end y");
    nh_bike_choice e;
    CHECK(nh_bike_choose(&f, T2, want, 1, &e) == 0, "exact mode: no plan");
    CHECK(e.plan.n == 3 && e.active, "exact: two turns, active expected: %d arcs, active %d",
          e.plan.n, e.active);
    nh_bike_end(&e.plan, f.kappa, end, NULL);
    CHECK_CLOSE(end[0], T2[0], 1e-12, "two turns: end x");
    CHECK_CLOSE(end[1], T2[1], 1e-12, "two turns: end y");
    CHECK_CLOSE(e.clearance, want, 1e-9, "two turns: clearance");
    CHECK_CLOSE(nh_bike_clearance(&f, &e.plan), want, 1e-9, "two turns: clearance again");
    CHECK(e.excursion < last, "excursion %g not below %g with less clearance", e.excursion, last);
    last = e.excursion;
  }
  nh_obstacles_destroy(&ob);
  free_scene(s);
}

static void test_regions(void) {
  nh_region sph = {.kind = NH_REGION_SPHERE, .center = {1, 2, 3}, .radius = 0.5};
  CHECK_CLOSE(nh_region_distance(&sph, (double[]){1, 2, 5}), 1.5, 1e-15, "sphere outside");
  CHECK_CLOSE(nh_region_distance(&sph, (double[]){1.2, 2, 3}), -0.3, 1e-15, "sphere inside");
  nh_region box = {.kind = NH_REGION_BOX, .min = {0, 0, 0}, .max = {1, 2, 3}};
  CHECK_CLOSE(nh_region_distance(&box, (double[]){4, 6, 1}), 5.0, 1e-15, "box: corner (3, 4)");
  CHECK_CLOSE(nh_region_distance(&box, (double[]){0.5, 1.8, 1}), -0.2, 1e-15, "box inside");
  nh_region cyl = {.kind = NH_REGION_CYLINDER, .start = {0, 0, 0}, .end = {0, 0, 2}, .radius = 1};
  CHECK_CLOSE(nh_region_distance(&cyl, (double[]){3, 4, 1}), 4.0, 1e-15, "cylinder beside");
  CHECK_CLOSE(nh_region_distance(&cyl, (double[]){0.3, 0, 4}), 2.0, 1e-15, "cylinder beyond end");
  CHECK_CLOSE(nh_region_distance(&cyl, (double[]){4, 0, 6}), 5.0, 1e-15, "cylinder at the rim");
  CHECK_CLOSE(nh_region_distance(&cyl, (double[]){0.5, 0, 1.9}), -0.1, 1e-15, "cylinder inside");
}

static void test_label(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  char path[sizeof((nh_scene *)0)->tissue.labels_file];
  snprintf(path, sizeof path, "%s/cases/steering/obstacle.nii.gz", src ? src : ".");
  nh_region lab = {.kind = NH_REGION_LABEL, .label = 2};
  nh_region cyl = {.kind = NH_REGION_CYLINDER,
                   .start = {0.06, 0.04, -1},
                   .end = {0.06, 0.04, 1},
                   .radius = 0.004};
  nh_scene *s = scene_with(1, &lab, path);
  nh_obstacles *ob = NULL;
  CHECK_OK(nh_obstacles_create(s, &ob));
  const double bound = 0.5 * sqrt(2.0) * 0.001 + 1e-12;
  double worst = 0;
  for (int i = 0; i < 400; i++) {
    double r = urand(0.0045, 0.02), a = urand(-M_PI, M_PI);
    double x[3] = {0.06 + r * cos(a), 0.04 + r * sin(a), urand(0.001, 0.038)};
    double dl = nh_obstacle_distance(ob, 0, x), dc = nh_region_distance(&cyl, x);
    worst = fmax(worst, fabs(dl - dc));
    CHECK(fabs(dl - dc) <= bound, "label vs cylinder at r = %g mm: %g vs %g mm", 1e3 * r, 1e3 * dl,
          1e3 * dc);
  }
  double in[3] = {0.06, 0.04, 0.02};
  CHECK(nh_obstacle_distance(ob, 0, in) < 0, "the axis is inside the label: %g",
        nh_obstacle_distance(ob, 0, in));
  /* the path clearance is the least point distance */
  double path3[9] = {0.07, 0.04, 0.02, 0.06, 0.05, 0.02, 0.03, 0.04, 0.02};
  double cl = nh_obstacles_clearance(ob, 3, path3, NULL);
  double least =
      fmin(nh_obstacle_distance(ob, 0, path3),
           fmin(nh_obstacle_distance(ob, 0, path3 + 3), nh_obstacle_distance(ob, 0, path3 + 6)));
  CHECK_CLOSE(cl, least, 1e-15, "path clearance");
  nh_obstacles_destroy(&ob);
  free_scene(s);
  (void)worst;
}

static void test_fit(void) {
  nh_bike_plan p = {.n = 3, .sign0 = 1, .len = {0.03, 0.05, 0.04}};
  const double kappa[3] = {12.3, 8.1, 5.2};
  enum { N = 120 };
  double xy[2 * N], s[N], k[3] = {10, 10, 10};
  for (int i = 0; i < N; i++) {
    s[i] = 0.12 * (i + 1) / N;
    nh_bike_point(&p, kappa, s[i], xy + 2 * i, NULL);
  }
  nh_bike_fit(&p, N, xy, s, k);
  for (int j = 0; j < 3; j++) CHECK_CLOSE(k[j], kappa[j], 1e-7 * kappa[j], "fitted curvature");
}

/* 7. The roll: the tip's frame (heading t, bevel n) carried along in 3-D,
 * each arc bending towards n, each turn spinning n about t (π, the last
 * π + θ), ends where nh_bike_end3 says; and ∂z/∂θ at θ = 0 is the lever. */
static void frame_arc(double p[3], double t[3], double n[3], double k, double l) {
  const double c = cos(k * l), s = sin(k * l);
  for (int i = 0; i < 3; i++) {
    double ti = t[i], ni = n[i];
    p[i] += (fabs(k) > 0 ? s / k : l) * ti + (fabs(k) > 0 ? (1 - c) / k : 0) * ni;
    t[i] = c * ti + s * ni, n[i] = -s * ti + c * ni;
  }
}

static void frame_spin(const double t[3], double n[3], double a) {
  double b[3] = {t[1] * n[2] - t[2] * n[1], t[2] * n[0] - t[0] * n[2], t[0] * n[1] - t[1] * n[0]};
  for (int i = 0; i < 3; i++) n[i] = cos(a) * n[i] + sin(a) * b[i];
}

static void test_roll(void) {
  srand(7);
  for (int trial = 0; trial < 40; trial++) {
    nh_bike_plan p = {.n = 2 + trial % 2, .sign0 = trial % 4 < 2 ? 1 : -1};
    double kappa[3];
    for (int j = 0; j < 3; j++) kappa[j] = urand(5, 40), p.len[j] = urand(0.005, 0.05);
    p.roll = urand(-1, 1);
    double x[3] = {0, 0, 0}, t[3] = {1, 0, 0}, n[3] = {0, 1, 0}, end[3];
    if (p.sign0 < 0) frame_spin(t, n, M_PI);
    for (int j = 0; j < p.n; j++) {
      frame_arc(x, t, n, kappa[j], p.len[j]);
      if (j + 1 < p.n) frame_spin(t, n, M_PI + (j + 2 == p.n ? p.roll : 0));
    }
    nh_bike_end3(&p, kappa, end);
    for (int i = 0; i < 3; i++) CHECK_CLOSE(end[i], x[i], 1e-12, "rolled end (3-D frame)");
    double turn[2], h, along, lever, e0[3], e1[3];
    CHECK(nh_bike_roll_lever(&p, kappa, turn, &h, &along, &lever) == 1, "no lever");
    p.roll = 1e-6;
    nh_bike_end3(&p, kappa, e1);
    p.roll = -1e-6;
    nh_bike_end3(&p, kappa, e0);
    CHECK_CLOSE((e1[2] - e0[2]) / 2e-6, lever, 1e-9, "dz/droll at 0 against the lever");
  }
}

/* The synthetic planner's problem of test 6. */
typedef struct {
  int kind; /* 0 affine, 1 bicycle */
  int n;    /* unknowns */
  double A[NH_TRUST_Q * NH_TRUST_Q], q0[NH_TRUST_Q];
  nh_bike_frame f; /* the model (bicycle) */
  double kappa[3]; /* the true curvatures */
  double T[2];
  double fail_len; /* a step changing a depth by more: fails (0: never) */
  nh_bike_plan from;
} synth;

static int synth_plan(const synth *S, const double *q, nh_bike_plan *p) {
  nh_bike_choice c;
  if (nh_bike_choose(&S->f, q, 0, 0, &c)) return -1;
  *p = c.plan;
  return 0;
}

/* F(q); −1: no plan (bicycle). */
static int synth_F(const synth *S, const double *q, double *F) {
  if (S->kind == 0) {
    for (int i = 0; i < NH_TRUST_Q; i++) {
      F[i] = 0;
      for (int j = 0; j < S->n; j++) F[i] += S->A[NH_TRUST_Q * i + j] * (q[j] - S->q0[j]);
    }
    return 0;
  }
  nh_bike_plan p;
  if (synth_plan(S, q, &p)) return -1;
  double end[2];
  nh_bike_end(&p, S->kappa, end, NULL);
  F[0] = end[0] - S->T[0], F[1] = end[1] - S->T[1], F[2] = F[3] = 0;
  return 0;
}

static double synth_length(void *ctx, const double *qb, const double *d, double t) {
  synth *S = ctx;
  double q[NH_TRUST_Q] = {0}, dd = 0;
  for (int i = 0; i < S->n; i++) q[i] = qb[i] + t * d[i], dd += d[i] * d[i];
  if (S->kind == 0) return t * sqrt(dd);
  nh_bike_plan p;
  return synth_plan(S, q, &p) ? INFINITY : nh_bike_depth_change(&p, &S->from);
}

/* Drive the iteration from q_1 as steer.c does; returns the 1-based point
 * whose |F| <= tol first (0: not within max points). */
static int synth_run(synth *S, const double *q1, double radius, double tol, int max,
                     const char *what) {
  enum { M = 40 };
  enum { S4 = NH_TRUST_Q };
  double Q[S4 * M] = {0}, F[S4 * M] = {0}, merit[M], lens[M];
  int ok[M] = {0}, best = -1, from[M];
  nh_trust tr;
  nh_trust_init(&tr, radius, 0, 2 * radius);
  if (S->kind == 0) tr.skip = 1e-6; /* every secant (exact) */
  memcpy(Q, q1, S4 * sizeof(double));
  if (max > M) max = M;
  for (int k = 0; k < max; k++) {
    double *q = Q + S4 * k, *Fk = F + S4 * k;
    int failed = synth_F(S, q, Fk) != 0;
    if (!failed && S->fail_len > 0 && k > 0 && lens[k - 1] > S->fail_len) failed = 1;
    ok[k] = !failed;
    double ff = 0;
    for (int i = 0; i < S4; i++) ff += Fk[i] * Fk[i];
    merit[k] = failed ? INFINITY : sqrt(ff);
    if (!failed && merit[k] <= tol) return k + 1;
    const double merit_b = best >= 0 ? merit[best] : INFINITY;
    if (k > 0) nh_trust_judge(&tr, merit_b, merit[k]);
    if (ok[k] && (best < 0 || merit[k] < merit[best])) best = k;
    CHECK(best >= 0, "%s: the first point failed", what);
    if (best < 0) return 0;
    if (k > 0 && failed) {
      /* after a failure: from the same best, at most half as long */
      CHECK(from[k - 1] == best, "%s: point %d failed and the best moved", what, k + 1);
    }
    if (S->kind == 1) synth_plan(S, Q + S4 * best, &S->from);
    if (k + 1 >= max) break;
    if (nh_trust_step(&tr, S->n, k + 1, Q, F, ok, best, synth_length, S, Q + S4 * (k + 1))) {
      CHECK(0, "%s: no step from point %d", what, best + 1);
      return 0;
    }
    lens[k] = tr.length, from[k] = best;
    if (k > 0 && !ok[k] && from[k - 1] == best)
      CHECK(lens[k] <= 0.5 * lens[k - 1] * (1 + 1e-12),
            "%s: point %d failed at a step of %g, "
            "the next is %g (expected at most half)",
            what, k + 1, lens[k - 1], lens[k]);
  }
  return 0;
}

static void test_trust(void) {
  srand(11);
  for (int trial = 0; trial < 50; trial++) {
    synth S = {.kind = 0, .n = 2 + trial % 3};
    for (int i = 0; i < NH_TRUST_Q * NH_TRUST_Q; i++)
      S.A[i] = (i % (NH_TRUST_Q + 1) == 0 ? 1.0 : 0.0) + urand(-0.3, 0.3);
    for (int i = 0; i < NH_TRUST_Q; i++) S.q0[i] = i < S.n ? urand(-1, 1) : 0;
    double q1[NH_TRUST_Q] = {0}, F1[NH_TRUST_Q], ff = 0;
    for (int i = 0; i < S.n; i++) q1[i] = urand(-1, 1);
    synth_F(&S, q1, F1);
    for (int i = 0; i < NH_TRUST_Q; i++) ff += F1[i] * F1[i];
    const double tol = 1e-9 * sqrt(ff);
    int at = synth_run(&S, q1, INFINITY, tol, S.n + 2, "affine");
    CHECK(at > 0 && at <= S.n + 2,
          "affine F, n = %d: root expected at point %d, got %d (0: not "
          "within %d)",
          S.n, S.n + 2, at, S.n + 2);
  }
  /* (b), (c): the bicycle with the wrong curvatures */
  synth S = {.kind = 1, .n = 2, .T = {0.1, 0.01}, .kappa = {34.5, 27, 36}};
  for (int j = 0; j < 3; j++) S.f.kappa[j] = 30;
  S.f.ex[0] = 1, S.f.ey[1] = 1;
  double q1[NH_TRUST_Q] = {S.T[0], S.T[1], 0, 0}, F1[NH_TRUST_Q];
  CHECK(synth_F(&S, q1, F1) == 0, "bicycle: no plan to T");
  CHECK(synth_plan(&S, q1, &S.from) == 0, "bicycle: no plan to T");
  S.f.side = S.from.sign0 < 0 ? -1 : 1, S.f.turns = S.from.n - 1; /* as steer.c: one class */
  const double m1 = hypot(F1[0], F1[1]);
  int at = synth_run(&S, q1, m1, 1e-6, 7, "bicycle");
  CHECK(at > 0 && at <= 7,
        "bicycle: |F| <= 1e-6 m expected by point 7, got %d (0: not) from "
        "|F_1| = %g m",
        at, m1);
  S.fail_len = 0.002;
  at = synth_run(&S, q1, m1, 1e-6, 30, "bicycle, failures");
  CHECK(at > 0 && at <= 30, "bicycle with failed long steps: not converged within 30 points (%d)",
        at);
}

int main(void) {
  test_finish();
  test_choose();
  test_regions();
  test_label();
  test_fit();
  test_trust();
  test_roll();
  return nh_test_failures ? 1 : 0;
}
