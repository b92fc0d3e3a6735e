/* sim_util.h — load a case of cases/ with overrides and build a dry-run
 * simulation of it (no output files), for tests that drive the simulator. */
#ifndef NH_TEST_SIM_UTIL_H
#define NH_TEST_SIM_UTIL_H

#include "check.h"
#include "sim/sim.h"

#include <stdio.h>

static void nh_case_path(const char *name, char *path, size_t size) {
  const char *src = getenv("NH_SOURCE_DIR");
  snprintf(path, size, "%s/cases/%s", src ? src : ".", name);
}

/* Load cases/NAME with the overrides (NULL-terminated) and create a dry-run sim. */
static void nh_case_open(const char *name, const char *const *sets, nh_scene **scene,
                         nh_sim **sim) {
  char path[1024];
  int n = 0;
  while (sets && sets[n]) n++;
  nh_case_path(name, path, sizeof path);
  CHECK_OK(nh_scene_load(path, n, sets, scene));
  nh_sim_options opt = {.dry_run = 1, .progress = 0};
  CHECK_OK(nh_sim_create(*scene, &opt, sim));
}

/* Run cases/NAME with the overrides to its end; u = displacement of probe i. */
static inline void nh_case_probe(const char *name, const char *const *sets, int i, double u[3]) {
  nh_scene *scene;
  nh_sim *sim;
  nh_case_open(name, sets, &scene, &sim);
  CHECK_OK(nh_sim_run(sim));
  nh_sim_probe_displacement(sim, i, u);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
}

#endif
