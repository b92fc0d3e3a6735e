/* probes.c — the embedded points of a run: the probes, then the targets
 * (docs/outputs.md, probes.csv and targets.csv). Material points of the
 * tissue: each is located once per mesh (its cell and natural coordinates),
 * then moves with the cell's nodes. Their current positions, displacements
 * and, under adapt.estimator goal, the estimated errors; a target's miss by
 * its tool's tip. sim.c and tools.c read them here; this file calls neither. */
#include "sim/sim_impl.h"

#include <math.h>

int nh_sim_locate_points(nh_sim *s, int first) {
  const nh_scene *sc = s->scene;
  for (int i = 0; i < sc->n_probes + sc->n_targets; i++) {
    /* outside at creation: the scene's fault; later: ours */
    const int pr = i < sc->n_probes;
    const double *X = pr ? sc->probes[i].point : sc->targets[i - sc->n_probes].point;
    NH_CHECK(nh_mesh_locate(s->mesh, X, &s->probe_cell[i], s->probe_xi + 3 * i) == NH_OK,
             first ? NH_ERR_INPUT : NH_ERR_INTERNAL,
             "%s: the point [%g, %g, %g] lies outside the tissue%s",
             pr ? sc->probes[i].where : sc->targets[i - sc->n_probes].where, X[0], X[1], X[2],
             first ? "" : " of the refined mesh");
  }
  return NH_OK;
}

void nh_sim_probe_displacement(const nh_sim *s, int i, double u[3]) {
  double N[8];
  nh_hex_shape(s->probe_xi + 3 * i, N);
  const int *e = s->mesh->cells + 8 * s->probe_cell[i];
  u[0] = u[1] = u[2] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) u[k] += N[a] * s->u[3 * e[a] + k];
}

void nh_sim_point_position(const nh_sim *s, int i, double x[3]) {
  const nh_scene *sc = s->scene;
  const double *X = i < sc->n_probes ? sc->probes[i].point : sc->targets[i - sc->n_probes].point;
  nh_sim_probe_displacement(s, i, x);
  for (int k = 0; k < 3; k++) x[k] += X[k];
}

double nh_sim_point_error(const nh_sim *s, int i) {
  const double *e = nh_adapt_goal_errors(s->adapt);
  if (!e || !s->goal_of_point || s->goal_of_point[i] < 0) return NAN;
  return e[s->goal_of_point[i]];
}

void nh_sim_target_miss(const nh_sim *s, int i, double x[3], double miss[3]) {
  nh_tool_report r;
  nh_sim_point_position(s, s->scene->n_probes + i, x);
  nh_contact_report(s->contact, s->scene->targets[i].tool, &r);
  for (int k = 0; k < 3; k++) miss[k] = r.tip[k] - x[k];
}

/* |−n · E| of target i's goal for the per-goal vectors E (3 each), or NaN. */
static double nh_sim_target_distance_part(const nh_sim *s, int i, const double *E) {
  const int g = s->goal_of_point ? s->goal_of_point[s->scene->n_probes + i] : -1;
  if (!E || g < 0) return NAN;
  double x[3], miss[3], tip[3];
  nh_sim_target_miss(s, i, x, miss);
  for (int k = 0; k < 3; k++) tip[k] = x[k] + miss[k];
  return fabs(nh_dwr_distance_estimate(E + 3 * g, x, tip));
}

double nh_sim_target_distance_error(const nh_sim *s, int i) {
  return nh_sim_target_distance_part(s, i, nh_adapt_goal_estimates(s->adapt));
}

/* |v| and |−n · v| of target i's part v (3 per goal) of its estimates, or NaN. */
static void nh_sim_target_part(const nh_sim *s, int i, const double *G, double *position,
                               double *distance) {
  const int g = s->goal_of_point ? s->goal_of_point[s->scene->n_probes + i] : -1;
  *position = *distance = NAN;
  if (!G || g < 0) return;
  const double *v = G + 3 * g;
  *position = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  *distance = nh_sim_target_distance_part(s, i, G);
}

void nh_sim_target_geometry_error(const nh_sim *s, int i, double *position, double *distance) {
  nh_sim_target_part(s, i, nh_adapt_goal_geometry(s->adapt), position, distance);
}

void nh_sim_target_constraint_error(const nh_sim *s, int i, double *position, double *distance) {
  nh_sim_target_part(s, i, nh_adapt_goal_constraint(s->adapt), position, distance);
}
