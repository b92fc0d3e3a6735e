/* schedule.c — what the scene gives as functions of time, evaluated at
 * every step: schedules (piecewise linear factors, constant outside their
 * times) and the gravity of tools and tissue (with buoyancy, docs/theory.md
 * "Buoyancy and brain shift"). */
#include "scene/scene.h"

double nh_schedule_eval(const nh_schedule *s, double t) {
  if (!s || s->n == 0) return 1.0;
  if (t <= s->t[0]) return s->value[0];
  if (t >= s->t[s->n - 1]) return s->value[s->n - 1];
  /* Binary search for the interval t[lo] <= t < t[lo + 1]. */
  int lo = 0, hi = s->n - 1;
  while (hi - lo > 1) {
    int mid = lo + (hi - lo) / 2;
    if (s->t[mid] <= t)
      lo = mid;
    else
      hi = mid;
  }
  double w = (t - s->t[lo]) / (s->t[hi] - s->t[lo]);
  return (1 - w) * s->value[lo] + w * s->value[hi];
}

void nh_scene_gravity(const nh_scene *s, double t, double g[3]) {
  double factor = nh_schedule_eval(&s->gravity_schedule, t);
  for (int k = 0; k < 3; ++k) g[k] = factor * s->gravity[k];
}

void nh_scene_tissue_gravity(const nh_scene *s, double t, double g[3]) {
  nh_scene_gravity(s, t, g);
  if (!s->tissue.buoyant) return;
  /* b0 − b(t) = (b0 − b1) s(t): only the change of the buoyed fraction loads the tissue. */
  double b0 = s->tissue.buoyancy_before, b1 = s->tissue.buoyancy_after;
  double change = (b0 - b1) * nh_schedule_eval(&s->tissue.buoyancy_schedule, t);
  for (int k = 0; k < 3; ++k) g[k] *= change;
}
