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
 * (more than the 675 dofs of 8x4x4), else the test proves nothing.
 *
 * With tools (cases/needle-phantom.yaml: a needle cutting into the block,
 * dynamic, the tools' state restored for the re-solve): run A adapts only
 * at step K = 30 (adapt.every 30; the needle's tip is then 5.5 mm deep,
 * cutting), estimator goal, resolve 2. Run B is the same scene without
 * re-solves; after its K − 1 steps (the same computation as A's, on the
 * same mesh) its mesh is refined to A's final mesh through
 * nh_sim_refine_cells (A's parents in the order their children were
 * created; the state carried by Eq. 17, the tools' points relocated), then
 * it solves step K directly on that mesh. A's step K must equal B's: u, v
 * of the tissue and the needle's tip agree to 1e-9 of their largest values
 * (the step's constraint solve iterates to solver tolerances from the same
 * warm start; the state carried to the new nodes by one refinement at a
 * time in B and by one or two in A differs by round-off on shared faces).
 * Not restoring the tools' state would advance them twice within the step:
 * an O(1) difference. The same comparison on dbs-skull.yaml's brain shift
 * (a skull, whose contact points are rebuilt on the refined leaves). */
#include "sim_util.h"

#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Largest |a_i − b_i| and |a_i| over n values. */
static void compare(int n, const double *a, const double *b, double *diff, double *scale) {
  *diff = *scale = 0.0;
  for (int i = 0; i < n; i++)
    *diff = fmax(*diff, fabs(a[i] - b[i])), *scale = fmax(*scale, fabs(a[i]));
}

/* Run A (sets_a: re-solves at step K) against run B (sets_b: none; its
 * mesh refined to A's final one after K − 1 steps, then step K solved
 * directly); dofs0 the start mesh's dofs. */
static void test_tools(const char *name, const char *const *sets_a, const char *const *sets_b,
                       int K, int dofs0) {
  nh_scene *sa, *sb;
  nh_sim *a, *b;
  nh_case_open(name, sets_a, &sa, &a);
  nh_case_open(name, sets_b, &sb, &b);
  for (int k = 0; k < K; k++) CHECK_OK(nh_sim_step(a));
  for (int k = 0; k < K - 1; k++) CHECK_OK(nh_sim_step(b));
  const nh_mesh *ma = nh_sim_mesh(a);
  CHECK(3 * ma->n_nodes > dofs0, "%s: the step was not refined (%d dofs)", name, 3 * ma->n_nodes);
  for (int next = 0; next < ma->n_cells; next++)
    for (int c = 0; c < ma->n_cells; c++)
      if (ma->first_child[c] == next) CHECK_OK(nh_sim_refine_cells(b, &c, 1));
  const nh_mesh *mb = nh_sim_mesh(b);
  CHECK(mb->n_nodes == ma->n_nodes && mb->n_cells == ma->n_cells &&
            !memcmp(mb->X, ma->X, sizeof(double) * 3 * ma->n_nodes),
        "B's mesh is not A's final mesh (%d nodes, expected %d)", mb->n_nodes, ma->n_nodes);
  CHECK_OK(nh_sim_step(b));
  CHECK(3 * nh_sim_mesh(b)->n_nodes == 3 * ma->n_nodes, "B refined after its last step");
  const int n = 3 * ma->n_nodes;
  double diff, scale;
  compare(n, nh_sim_displacements(a), nh_sim_displacements(b), &diff, &scale);
  CHECK(diff <= 1e-9 * scale,
        "%s: u of the re-solved step against the direct solve: max "
        "|diff| %.3e, expected <= %.3e (1e-9 of max |u| %.3e)",
        name, diff, 1e-9 * scale, scale);
  compare(n, nh_sim_velocities(a), nh_sim_velocities(b), &diff, &scale);
  CHECK(diff <= 1e-9 * scale,
        "%s: v of the re-solved step against the direct solve: max "
        "|diff| %.3e, expected <= %.3e (1e-9 of max |v| %.3e)",
        name, diff, 1e-9 * scale, scale);
  double xa[3], xb[3], miss_a[3], miss_b[3];
  nh_sim_target_miss(a, 0, xa, miss_a);
  nh_sim_target_miss(b, 0, xb, miss_b);
  double tip_a[3], tip_b[3];
  for (int k = 0; k < 3; k++) tip_a[k] = xa[k] + miss_a[k], tip_b[k] = xb[k] + miss_b[k];
  compare(3, tip_a, tip_b, &diff, &scale);
  CHECK(diff <= 1e-9 * scale, "%s: the tool's tip: max |diff| %.3e m, expected <= %.3e", name, diff,
        1e-9 * scale);
  if (getenv("NH_VERBOSE"))
    printf("%s: %d dofs, tip (%.9f, %.9f, %.9f) m\n", name, n, tip_a[0], tip_a[1], tip_a[2]);
  nh_sim_destroy(&a), nh_sim_destroy(&b);
  nh_scene_destroy(&sa), nh_scene_destroy(&sb);
}

int main(void) {
  /* resolve_tip off in both: it would make the puncture step an adapt step
   * (test_resolve_tip), and this comparison needs the first K − 1 steps on 8x4x4 */
  const char *needle_a[] = {"adapt.estimator=goal",    "adapt.every=30", "adapt.resolve=2",
                            "adapt.resolve_tip=false", "time.steps=30",  NULL};
  const char *needle_b[] = {"adapt.estimator=goal", "adapt.every=30", "adapt.resolve_tip=false",
                            "time.steps=30", NULL};
  test_tools("needle-phantom.yaml", needle_a, needle_b, 30, 675);
  /* With the skull: its points are rebuilt on the refined leaves, each with
   * the warm start of the nearest old point. The re-solve must carry the
   * step's START state there (as B's refinement carries its step K − 1 end
   * state), not the solved one; restoring the start state saved on the old
   * mesh after the refinement failed ("the checkpoint's skull has 686
   * contact points, the restored mesh 752"). The brain shift of
   * dbs-skull.yaml, 14 mm grid, re-solved at step 15 (the tools outside). */
  const char *skull_a[] = {
      "tissue.grid=[10,12,9]", "adapt.estimator=goal",    "adapt.max_level=1", "adapt.every=15",
      "adapt.resolve=1",       "adapt.resolve_tip=false", "time.steps=15",     NULL};
  const char *skull_b[] = {"tissue.grid=[10,12,9]",
                           "adapt.estimator=goal",
                           "adapt.max_level=1",
                           "adapt.every=15",
                           "adapt.resolve_tip=false",
                           "time.steps=15",
                           NULL};
  test_tools("dbs/dbs-skull.yaml", skull_a, skull_b, 15, 3039);
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
