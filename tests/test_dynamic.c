/* test_dynamic — an undamped cantilever released under a suddenly applied
 * tip load oscillates about its static deflection with the first bending
 * frequency of the same discretisation, and its energy never grows.
 *
 * ω₁ comes from the generalised eigenproblem K φ = ω² M φ of the assembled
 * (rest) stiffness and lumped mass, by inverse iteration started from the
 * static deflection (the bending mode in the load's plane). Backward Euler
 * advances an undamped mode by the factor 1/(1 − iωh), i.e. by a phase of
 * atan(ωh) per step, so the period it shows is T_h = 2π h / atan(ωh): the
 * measured period must equal T_h within 0.5 % (h = T₁/100, the second mode
 * is damped by BE to < 5 % within the first period; the tolerance covers it
 * and the linear interpolation of crossing times).
 *
 * Energy: with the load constant, E = ½vᵀMv + U(x) − f·u is a Lyapunov
 * function of implicit Euler; each step may only lower it (tolerance 1e-9 of
 * the initial drop, for the corotational force not being an exact gradient
 * of U at the 1e-3 strain here). */
#include "sim_util.h"

#include <string.h>

static double dot(const double *a, const double *b, int n) {
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

int main(void) {
  /* 1. Static deflection and ω₁ on the 20 x 2 x 2 mesh. */
  const char *sets_static[] = {"tissue.grid=[20,2,2]", "solver.tolerance=1e-10", NULL};
  nh_scene *scene;
  nh_sim *sim;
  nh_case_open("cantilever.yaml", sets_static, &scene, &sim);
  CHECK_OK(nh_sim_run(sim));
  double u_static[3];
  nh_sim_probe_displacement(sim, 0, u_static);

  nh_system *sys = nh_sim_system(sim);
  const nh_mesh *m = nh_sim_mesh(sim);
  const nh_tissue *t = nh_sim_tissue(sim);
  (void)m;
  int n = 3 * m->n_nodes, nf = nh_system_free_dofs(sys);
  double *f = malloc(sizeof(double) * n), *kv = malloc(sizeof(double) * n);
  double *q = malloc(sizeof(double) * nf), *y = malloc(sizeof(double) * nf);
  double *mq = malloc(sizeof(double) * nf), *full = calloc(n, sizeof(double));
  double *mass = malloc(sizeof(double) * nf);
  for (int i = 0; i < n; i++) full[i] = t->mass[i / 3];
  nh_system_gather(sys, full, mass);
  double *u = nh_sim_displacements(sim);
  nh_system_gather(sys, u, q); /* start: the static deflection */
  memset(full, 0, sizeof(double) * n);
  nh_system_assemble(sys, full, NULL, 0.0, 1.0, f, NULL, 1); /* A = K at rest */
  CHECK_OK(nh_system_factor(sys));
  double omega2 = 0.0;
  for (int it = 0; it < 200; it++) {
    for (int j = 0; j < nf; j++) mq[j] = mass[j] * q[j];
    CHECK_OK(nh_system_solve(sys, mq, y));
    double norm = sqrt(dot(y, y, nf));
    for (int j = 0; j < nf; j++) q[j] = y[j] / norm;
    nh_system_apply(sys, q, y);
    for (int j = 0; j < nf; j++) mq[j] = mass[j] * q[j];
    double w2 = dot(q, y, nf) / dot(q, mq, nf);
    if (fabs(w2 - omega2) <= 1e-14 * w2) break;
    omega2 = w2;
  }
  double omega = sqrt(omega2), T1 = 2 * M_PI / omega;
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);

  /* 2. Dynamic, undamped, h = T₁/100, four periods. */
  double h = T1 / 100;
  char step[64], steps[64];
  snprintf(step, sizeof step, "time.step=%.17g", h);
  snprintf(steps, sizeof steps, "time.steps=%d", 400);
  const char *sets_dyn[] = {"tissue.grid=[20,2,2]", "time.mode=dynamic", step, steps, NULL};
  nh_case_open("cantilever.yaml", sets_dyn, &scene, &sim);
  u = nh_sim_displacements(sim);
  t = nh_sim_tissue(sim); /* the first simulation's tissue is gone */
  double *fext = malloc(sizeof(double) * n);
  nh_sim_external_force(sim, h, fext);
  double prev_u = 0.0, last_cross = -1.0, energy_prev = 0.0, first_drop = 0.0;
  double crossings[64];
  int n_cross = 0;
  for (int k = 1; k <= 400; k++) {
    CHECK_OK(nh_sim_step(sim));
    double tip[3];
    nh_sim_probe_displacement(sim, 0, tip);
    double s = tip[2] - u_static[2]; /* oscillation about the static deflection */
    if (k > 1 && ((prev_u < 0) != (s < 0)) && n_cross < 64) {
      double tc = (k - 1 + prev_u / (prev_u - s)) * h;
      crossings[n_cross++] = tc;
      last_cross = tc;
    }
    prev_u = s;
    double energy = nh_sim_kinetic_energy(sim) + nh_tissue_energy(t, u) - dot(fext, u, n);
    if (k == 1) first_drop = fabs(energy);
    if (k > 1 && !(energy <= energy_prev + 1e-9 * first_drop)) {
      CHECK(0, "energy grew at step %d: %.17g -> %.17g", k, energy_prev, energy);
      break;
    }
    energy_prev = energy;
  }
  (void)last_cross;
  CHECK(n_cross >= 6, "only %d crossings of the static deflection", n_cross);
  /* Period from crossings after the first period (higher modes damped out). */
  int first = 2, last = n_cross - 1;
  double period = 2.0 * (crossings[last] - crossings[first]) / (last - first);
  double expected = 2 * M_PI * h / atan(omega * h);
  if (getenv("NH_VERBOSE"))
    printf(
        "omega1 = %.6g rad/s, T1 = %.6g s, expected BE period %.6g s, measured %.6g s (%+.3f %%)\n",
        omega, T1, expected, period, 100 * (period - expected) / expected);
  CHECK_CLOSE(period, expected, 0.005 * expected, "oscillation period vs first eigenfrequency");
  free(f), free(kv), free(q), free(y), free(mq), free(full), free(mass), free(fext);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  TEST_END();
}
