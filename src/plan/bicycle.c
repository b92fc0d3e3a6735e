/* bicycle.c — the kinematic model of a bevel-tip needle (Webster et al.
 * 2006, "Nonholonomic modeling of needle steering"), in the plane the bevel
 * turns in, and the plan the steering planner starts from.
 *
 * Without a turn the tip moves on a circle of curvature κ towards its bevel;
 * a half turn of the base flips the bevel and with it the sign of the
 * curvature. A plan of K turns is K + 1 arcs of curvature σ_j κ_j, σ_j
 * alternating, lengths ℓ_j; each arc has its own curvature magnitude κ_j
 * (Webster's model has one; in a soft tissue a needle already bent and deep
 * curves less after a turn, so the planner fits one per arc to its runs:
 * nh_bike_fit). An arc from (x, y) with heading θ ends at
 *     x' = x + (sin(θ + kℓ) − sin θ)/k,  y' = y − (cos(θ + kℓ) − cos θ)/k,
 *     θ' = θ + kℓ  (k = σκ).
 *
 * Two arcs reach a target T (local frame: start at 0, heading 0, first arc
 * of radius a = 1/κ_a curving towards +y, the second of radius b = 1/κ_b):
 * the first ends at P = a(sin φ, 1 − cos φ) after turning by φ, the second
 * is a circle of radius b around C = ((a + b) sin φ, a − (a + b) cos φ)
 * through T, so |T − C| = b, i.e.
 *     X sin φ + (a − Y) cos φ = (X² + (Y − a)² + a² + 2ab)/(2(a + b)),
 *     sin(φ + β) = (ρ² + a² + 2ab)/(2(a + b)ρ),  ρ = |T − (0, a)|,
 *     β = atan2(a − Y, X):
 * a solution exists iff a ≤ ρ ≤ a + 2b; the shorter of the two is taken,
 * and the second arc's length is b times its clockwise sweep from P to T.
 * With a = b = R: sin(φ + β) = (ρ² + 3R²)/(4Rρ), R ≤ ρ ≤ 3R, test (b)'s
 * expectation (tests/steer_plan.py).
 *
 * The plan the planner starts from (nh_bike_choose): fewest turns first —
 * the one-turn plans (the first arc towards the bevel, or away from it after
 * a half turn at the entry) of least excursion whose path keeps the
 * clearance; if none does, the two-turn plans, whose first arc length is
 * free: scanned over (0, |T|) in 200 steps, the two-arc finish closing each,
 * the feasible one of least excursion chosen, and, if its neighbour of
 * smaller excursion is infeasible, the first arc bisected between them to
 * clearance = c* exactly: the plan then passes the obstacle at c*, and it
 * moves smoothly with T and c* (what Broyden's method in steer.c needs).
 *
 * Out of the plane (the roll): the last turn spins the base by π + θ
 * instead of π. A spin about the tip's heading commutes with the half turns
 * after it, so the whole path after the turn point P turns rigidly by θ
 * about the tangent line there (right-handed about the heading t). With m
 * the heading's left normal in the plane and e₀ the planar end (θ = 0),
 * u = (e₀ − P)·t and ℓ = (e₀ − P)·m:
 *     e(θ) = P + u t + ℓ (cos θ m + sin θ e_z),   ∂e_z/∂θ = ℓ cos θ,
 * so a roll moves the end out of the plane by ℓ sin θ and into it only by
 * ℓ (1 − cos θ) (nh_bike_end3; docs/cases.md, "Out of the plane"). */
#include "plan/plan_impl.h"

#include <math.h>
#include <string.h>

enum { NH_BIKE_SCAN = 200 };
#define NH_BIKE_SAMPLE 2e-4 /* m between the model path's points for the clearance */

double nh_bike_depth_change(const nh_bike_plan *a, const nh_bike_plan *b) {
  if (a->n != b->n || a->sign0 != b->sign0) return INFINITY;
  double da = 0, db = 0, m = 0;
  for (int j = 0; j < a->n; j++) da += a->len[j], db += b->len[j], m = fmax(m, fabs(da - db));
  return m;
}

/* Advance (x, y, θ) along an arc of signed curvature k and length l. */
static void nh_arc(double st[3], double k, double l) {
  double t1 = st[2] + k * l;
  if (fabs(k * l) < 1e-12) {
    st[0] += l * cos(st[2]), st[1] += l * sin(st[2]);
  } else {
    st[0] += (sin(t1) - sin(st[2])) / k;
    st[1] -= (cos(t1) - cos(st[2])) / k;
  }
  st[2] = t1;
}

void nh_bike_point(const nh_bike_plan *p, const double *kappa, double s, double xy[2],
                   double *heading) {
  double st[3] = {0, 0, 0}, sign = p->sign0;
  for (int j = 0; j < p->n && s > 0; j++, sign = -sign) {
    double l = fmin(s, p->len[j]);
    nh_arc(st, sign * kappa[j], l);
    s -= l;
  }
  xy[0] = st[0], xy[1] = st[1];
  if (heading) *heading = st[2];
}

static double nh_bike_length(const nh_bike_plan *p) {
  double L = 0;
  for (int j = 0; j < p->n; j++) L += p->len[j];
  return L;
}

void nh_bike_end(const nh_bike_plan *p, const double *kappa, double end[2], double *heading) {
  nh_bike_point(p, kappa, nh_bike_length(p), end, heading);
}

int nh_bike_roll_lever(const nh_bike_plan *p, const double *kappa, double turn[2], double *heading,
                       double *along, double *lever) {
  if (p->n < 2) return 0;
  double end[2], s = nh_bike_length(p) - p->len[p->n - 1];
  nh_bike_point(p, kappa, s, turn, heading);
  nh_bike_end(p, kappa, end, NULL);
  const double c = cos(*heading), sn = sin(*heading), dx = end[0] - turn[0], dy = end[1] - turn[1];
  *along = c * dx + sn * dy, *lever = -sn * dx + c * dy;
  return 1;
}

void nh_bike_end3(const nh_bike_plan *p, const double *kappa, double end[3]) {
  double turn[2], h, along, lever;
  if (!nh_bike_roll_lever(p, kappa, turn, &h, &along, &lever)) {
    nh_bike_end(p, kappa, end, NULL);
    end[2] = 0;
    return;
  }
  const double m = lever * cos(p->roll);
  end[0] = turn[0] + along * cos(h) - m * sin(h);
  end[1] = turn[1] + along * sin(h) + m * cos(h);
  end[2] = lever * sin(p->roll);
}

int nh_bike_finish(const double start[2], double heading, double sign, double kappa_a,
                   double kappa_b, const double target[2], double len[2]) {
  const double Ra = 1.0 / kappa_a, Rb = 1.0 / kappa_b, c = cos(heading), s = sin(heading);
  double dx = target[0] - start[0], dy = target[1] - start[1];
  double X = c * dx + s * dy, Y = sign * (-s * dx + c * dy); /* local, first arc to +Y */
  double rho = hypot(X, Ra - Y), beta = atan2(Ra - Y, X);
  double q = (rho * rho + Ra * Ra + 2 * Ra * Rb) / (2 * (Ra + Rb) * rho);
  if (!(q <= 1.0 + 1e-12)) return -1;
  double a = asin(fmin(q, 1.0)), best = INFINITY;
  for (int b = 0; b < 2; b++) {
    double phi = (b ? NH_PI - a : a) - beta;
    phi = fmod(phi, 2 * NH_PI);
    if (phi < 0) phi += 2 * NH_PI;
    if (phi > 2 * NH_PI - 1e-12) phi = 0; /* a full turn is none */
    best = fmin(best, phi);
  }
  double Cx = (Ra + Rb) * sin(best), Cy = Ra - (Ra + Rb) * cos(best);
  double sweep = (best + NH_PI / 2) - atan2(Y - Cy, X - Cx); /* clockwise around C */
  sweep = fmod(sweep, 2 * NH_PI);
  if (sweep < 0) sweep += 2 * NH_PI;
  if (sweep > 2 * NH_PI - 1e-9) sweep = 0;
  len[0] = Ra * best, len[1] = Rb * sweep;
  return 0;
}

/* World point of plane point xy. */
static void nh_bike_world(const nh_bike_frame *f, const double xy[2], double x[3]) {
  for (int k = 0; k < 3; k++) x[k] = f->entry[k] + xy[0] * f->ex[k] + xy[1] * f->ey[k];
}

double nh_bike_clearance(const nh_bike_frame *f, const nh_bike_plan *p) {
  if (nh_obstacles_count(f->obstacles) == 0) return INFINITY;
  enum { CHUNK = 256 };
  double pts[3 * CHUNK], L = nh_bike_length(p), best = INFINITY;
  int n = (int)ceil(L / NH_BIKE_SAMPLE) + 1, m = 0;
  for (int i = 0; i < n; i++) {
    double xy[2];
    nh_bike_point(p, f->kappa, L * i / (n - 1 > 0 ? n - 1 : 1), xy, NULL);
    nh_bike_world(f, xy, pts + 3 * m++);
    if (m == CHUNK || i == n - 1) {
      best = fmin(best, nh_obstacles_clearance(f->obstacles, m, pts, NULL));
      m = 0;
    }
  }
  return best;
}

/* The largest distance of the path from the chord from the entry to T. */
static double nh_bike_excursion(const nh_bike_plan *p, const double *kappa, const double T[2]) {
  double L = nh_bike_length(p), n = hypot(T[0], T[1]), worst = 0;
  double u[2] = {n > 0 ? T[0] / n : 1.0, n > 0 ? T[1] / n : 0.0};
  int m = (int)ceil(L / 5e-4) + 1;
  for (int i = 0; i < m; i++) {
    double xy[2];
    nh_bike_point(p, kappa, L * i / (m - 1 > 0 ? m - 1 : 1), xy, NULL);
    worst = fmax(worst, fabs(u[0] * xy[1] - u[1] * xy[0]));
  }
  return worst;
}

/* The plan with first arc ℓ0 (two turns; ℓ0 = 0: one turn) and first sign
 * σ0 reaching T; 0 on success. */
static int nh_bike_make(const nh_bike_frame *f, const double T[2], double sign0, double l0,
                        nh_bike_plan *p) {
  double st[3] = {0, 0, 0}, len[2];
  memset(p, 0, sizeof *p);
  p->sign0 = sign0;
  if (l0 > 0) nh_arc(st, sign0 * f->kappa[0], l0);
  double sign = l0 > 0 ? -sign0 : sign0;
  const double *k = f->kappa + (l0 > 0);
  if (nh_bike_finish(st, st[2], sign, k[0], k[1], T, len)) return -1;
  if (l0 > 0) {
    p->n = 3, p->len[0] = l0, p->len[1] = len[0], p->len[2] = len[1];
  } else {
    p->n = 2, p->len[0] = len[0], p->len[1] = len[1];
  }
  return 0;
}

/* Fill a choice from a plan. */
static void nh_bike_rate(const nh_bike_frame *f, const double T[2], const nh_bike_plan *p,
                         nh_bike_choice *c) {
  c->plan = *p;
  c->clearance = nh_bike_clearance(f, p);
  c->excursion = nh_bike_excursion(p, f->kappa, T);
  c->active = 0;
}

int nh_bike_choose(const nh_bike_frame *f, const double T[2], double clearance, int exact,
                   nh_bike_choice *out) {
  nh_bike_choice best = {.excursion = INFINITY}, c;
  nh_bike_plan p;
  /* one turn, the first arc towards the bevel or (after a turn at the entry) away */
  for (int s = 0; s < 2 && !exact && f->turns != 2; s++) {
    if (f->side && f->side != (s ? -1 : 1)) continue;
    if (nh_bike_make(f, T, s ? -1.0 : 1.0, 0.0, &p)) continue;
    nh_bike_rate(f, T, &p, &c);
    if (c.clearance >= clearance && c.excursion < best.excursion) best = c;
  }
  if (best.excursion < INFINITY) {
    *out = best;
    return 0;
  }
  if (f->turns == 1) return -1;
  /* two turns: scan the first arc */
  const double span = hypot(T[0], T[1]);
  nh_bike_choice scan[2][NH_BIKE_SCAN + 2]; /* a plan exists where .excursion < inf */
  for (int s = 0; s < 2; s++)
    for (int i = 0; i <= NH_BIKE_SCAN + 1; i++) {
      nh_bike_choice *e = &scan[s][i];
      e->excursion = INFINITY;
      if (i == 0 || i > NH_BIKE_SCAN || (f->side && f->side != (s ? -1 : 1))) continue;
      if (nh_bike_make(f, T, s ? -1.0 : 1.0, span * i / (NH_BIKE_SCAN + 1), &p)) continue;
      nh_bike_rate(f, T, &p, e);
    }
  /* the feasible plan of least excursion; in exact mode only those next to an
     infeasible one (where clearance = c* lies between them) */
  int best_i = -1, best_s = 0, best_j = -1;
  for (int s = 0; s < 2; s++)
    for (int i = 1; i <= NH_BIKE_SCAN; i++) {
      const nh_bike_choice *e = &scan[s][i];
      if (!(e->excursion < INFINITY) || e->clearance < clearance) continue;
      int j = -1; /* the infeasible neighbour of smaller excursion, if any */
      for (int d = -1; d <= 1; d += 2) {
        const nh_bike_choice *n = &scan[s][i + d];
        if (n->excursion < INFINITY && n->clearance < clearance &&
            (j < 0 || n->excursion < scan[s][j].excursion))
          j = i + d;
      }
      if (exact && j < 0) continue;
      double key = exact ? scan[s][j].excursion : e->excursion;
      double cur = best_i < 0 ? INFINITY
                   : exact    ? scan[best_s][best_j].excursion
                              : scan[best_s][best_i].excursion;
      if (key < cur) best_i = i, best_s = s, best_j = j;
    }
  if (best_i < 0) return -1;
  best = scan[best_s][best_i];
  int j = best_j;
  if (j >= 0 && (exact || scan[best_s][j].excursion < best.excursion)) {
    /* bisect the first arc between the two to clearance = c* */
    double a = span * best_i / (NH_BIKE_SCAN + 1), b = span * j / (NH_BIKE_SCAN + 1);
    for (int it = 0; it < 60 && fabs(a - b) > 1e-13; it++) {
      double mid = 0.5 * (a + b);
      if (nh_bike_make(f, T, best_s ? -1.0 : 1.0, mid, &p)) {
        b = mid;
        continue;
      }
      nh_bike_rate(f, T, &p, &c);
      if (c.clearance >= clearance)
        a = mid, best = c;
      else
        b = mid;
    }
    best.active = 1;
  }
  *out = best;
  return 0;
}

/* Σ |model(s_i) − measured_i|² over the points of arc j, the arc's curvature k. */
static double nh_fit_cost(const nh_bike_plan *p, double *kappa, int j, double k, int n,
                          const double *xy, const double *s, double s0, double s1) {
  double cost = 0, keep = kappa[j];
  kappa[j] = k;
  for (int i = 0; i < n; i++) {
    if (!(s[i] > s0 && s[i] <= s1)) continue;
    double m[2];
    nh_bike_point(p, kappa, s[i], m, NULL);
    cost +=
        (m[0] - xy[2 * i]) * (m[0] - xy[2 * i]) + (m[1] - xy[2 * i + 1]) * (m[1] - xy[2 * i + 1]);
  }
  kappa[j] = keep;
  return cost;
}

void nh_bike_fit(const nh_bike_plan *p, int n, const double *xy, const double *s, double *kappa) {
  const double g = 0.5 * (sqrt(5.0) - 1.0);
  double s0 = 0;
  for (int j = 0; j < p->n; j++) {
    double s1 = j + 1 == p->n ? INFINITY : s0 + p->len[j];
    int m = 0;
    for (int i = 0; i < n; i++) m += s[i] > s0 && s[i] <= s1;
    if (m >= 4) { /* golden section on log κ_j in [κ_j / 20, 20 κ_j] */
      double a = log(kappa[j] / 20), b = log(kappa[j] * 20);
      double x1 = b - g * (b - a), x2 = a + g * (b - a);
      double f1 = nh_fit_cost(p, kappa, j, exp(x1), n, xy, s, s0, s1);
      double f2 = nh_fit_cost(p, kappa, j, exp(x2), n, xy, s, s0, s1);
      for (int it = 0; it < 80; it++) {
        if (f1 < f2) {
          b = x2, x2 = x1, f2 = f1, x1 = b - g * (b - a);
          f1 = nh_fit_cost(p, kappa, j, exp(x1), n, xy, s, s0, s1);
        } else {
          a = x1, x1 = x2, f1 = f2, x2 = a + g * (b - a);
          f2 = nh_fit_cost(p, kappa, j, exp(x2), n, xy, s, s0, s1);
        }
      }
      kappa[j] = exp(0.5 * (a + b));
    }
    s0 = s1;
  }
  for (int j = p->n; j < NH_BIKE_MAX_ARCS; j++) kappa[j] = kappa[p->n - 1]; /* not run: the last */
}
