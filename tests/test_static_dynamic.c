/* test_static_dynamic — the static and the dynamic modes agree at
 * equilibrium. cases/phantom-tissue.yaml is run (a) statically at the full
 * load and (b) dynamically with its damping until the motion has died out
 * (2 s, the load ramp ends at 0.1 s); a fixed point of the backward-Euler
 * step has dv = 0, i.e. f_int(x) = f_ext, the static equation, so both must
 * give the same displacements to the static solver's tolerance
 * (1e-7 relative to the largest displacement). */
#include "sim_util.h"

int main(void) {
  nh_scene *s1, *s2;
  nh_sim *a, *b;
  const char *st[] = {"time.mode=static", "time.step=1.0", "time.end=1.0", "solver.tolerance=1e-10",
                      NULL};
  nh_case_open("phantom-tissue.yaml", st, &s1, &a);
  CHECK_OK(nh_sim_run(a));
  const char *dy[] = {"time.end=2.0", NULL};
  nh_case_open("phantom-tissue.yaml", dy, &s2, &b);
  CHECK_OK(nh_sim_run(b));
  const nh_mesh *m = nh_sim_mesh(a);
  const double *ua = nh_sim_displacements(a), *ub = nh_sim_displacements(b);
  double umax = 0.0;
  for (int i = 0; i < 3 * m->n_nodes; i++) umax = fmax(umax, fabs(ua[i]));
  CHECK(umax > 1e-7, "the load moved nothing (max displacement %g m)", umax);
  for (int i = 0; i < 3 * m->n_nodes; i++)
    CHECK_CLOSE(ub[i], ua[i], 1e-7 * umax, "dynamic vs static displacement");
  if (getenv("NH_VERBOSE")) printf("max displacement %.6e m\n", umax);
  nh_sim_destroy(&a);
  nh_sim_destroy(&b);
  nh_scene_destroy(&s1);
  nh_scene_destroy(&s2);
  TEST_END();
}
