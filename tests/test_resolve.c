/* test_resolve — adapt.resolve: a step refined and solved again equals the
 * same step solved directly on its final mesh.
 *
 * cases/adapt-localized.yaml (static, linear in practice) with
 * adapt.estimator goal and adapt.resolve 2, one step: the step is solved on
 * 8x4x4, refined by the goal indicators, solved again from its start state
 * (rest) carried to the new mesh, twice. Independently, on a copy of the
 * final mesh (rebuilt from the run's refinement hierarchy) this test builds the tissue, the fixed
 * nodes (x ≥ 0.0399), the hanging nodes, the system and the load (the case's box and force) and
 * solves the static problem from rest with the case's Newton tolerance.
 * Both are the same computation on the same mesh, so they agree to
 * round-off: asserted 1e-12 of max |u|. The mesh must have been refined
 * (more than the 675 dofs of 8x4x4), else the test proves nothing. */
#include "sim_util.h"

#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

int main(void) {
  const char *sets[] = {"adapt.estimator=goal", "adapt.resolve=2", "time.steps=1", NULL};
  nh_scene *scene;
  nh_sim *sim;
  nh_case_open("adapt-localized.yaml", sets, &scene, &sim);
  CHECK_OK(nh_sim_step(sim));
  const nh_mesh *m = nh_sim_mesh(sim);
  const double *u_sim = nh_sim_displacements(sim);
  CHECK(3 * m->n_nodes > 675, "the step was not refined (%d dofs)", 3 * m->n_nodes);

  /* The final mesh, copied through the refinement hierarchy it records. */
  nh_mesh *copy;
  CHECK_OK(
      nh_mesh_create_box(scene->tissue.box_min, scene->tissue.box_max, scene->tissue.grid, &copy));
  nh_template *t;
  CHECK_OK(nh_template_load(scene->adapt.template_path, &t));
  /* Parents in the order their children were created (ascending first
   * child): the copy then numbers cells and nodes as the run did. */
  for (int next = 0; next < m->n_cells; next++)
    for (int c = 0; c < m->n_cells; c++)
      if (m->first_child[c] == next) CHECK_OK(nh_mesh_refine(copy, t, &c, 1, NULL));
  CHECK(copy->n_nodes == m->n_nodes && copy->n_cells == m->n_cells &&
            !memcmp(copy->X, m->X, sizeof(double) * 3 * m->n_nodes),
        "the copy is not the final mesh (%d nodes, expected %d)", copy->n_nodes, m->n_nodes);

  nh_material mat = {scene->tissue.young, scene->tissue.poisson, scene->tissue.density,
                     scene->tissue.formulation};
  nh_tissue *tissue;
  CHECK_OK(nh_tissue_create(copy, &mat, &tissue));
  unsigned char *fixed = malloc(copy->n_nodes);
  for (int i = 0; i < copy->n_nodes; i++) fixed[i] = copy->X[3 * i] > 0.0399;
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(copy, fixed, &h));
  nh_system *sys;
  CHECK_OK(nh_system_create(tissue, fixed, h, &sys));
  int n = 3 * copy->n_nodes;
  double *f = calloc(n, sizeof(double)), *u = calloc(n, sizeof(double));
  CHECK_OK(
      nh_mesh_region_load(copy, &scene->tissue.loads[0].region, scene->tissue.loads[0].force, f));
  nh_integrator in = {.dt = scene->time.step,
                      .tolerance = scene->solver.tolerance,
                      .max_iterations = scene->solver.max_iterations,
                      .threads = scene->solver.threads};
  nh_step_stats st;
  CHECK_OK(nh_solve_static(sys, &in, f, u, &st));
  double umax = 0.0, diff = 0.0;
  for (int i = 0; i < n; i++)
    umax = fmax(umax, fabs(u[i])), diff = fmax(diff, fabs(u[i] - u_sim[i]));
  CHECK(diff <= 1e-12 * umax,
        "re-solved step against the direct solve on its final mesh: max |diff| %.3e, expected "
        "<= %.3e (1e-12 of max |u| %.3e)",
        diff, 1e-12 * umax, umax);
  free(f), free(u), free(fixed);
  nh_system_destroy(&sys);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&tissue);
  nh_template_destroy(&t);
  nh_mesh_destroy(&copy);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  TEST_END();
}
