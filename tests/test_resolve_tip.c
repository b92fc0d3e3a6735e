/* test_resolve_tip — adapt.resolve_tip: the step that punctures is solved
 * on the cells its own goal estimate gives the tip, not on the mesh of the
 * step before.
 *
 * cases/phantom/phantom.yaml (goal-oriented, hex2, max_level 2), three
 * steps: the tip starts 0.5 mm before the face x = 0 and advances
 * 0.2 mm per step (2 cm/s, 10 ms), so it enters the block in step 3 (the
 * puncture) at x = 0.1 mm. Before the puncture nothing loads the tissue:
 * the estimates of steps 1 and 2 are zero and refine nothing, so step 3
 * starts on the 8x4x4 grid. The last step refines only in its re-solves,
 * so after step 3 the mesh is the one step 3's written solution was
 * solved on.
 *  - adapt.resolve_tip false: that mesh is the 8x4x4 grid (675 dofs, every
 *    leaf at level 0): the lag this key removes, asserted so that the
 *    check below can tell the two apart.
 *  - the default (true): the puncture force sits at the tip, and the goal
 *    indicators' maximum with it, so the max marking splits the tip's
 *    leaves until they reach max_level: every leaf holding the tip is at
 *    level 2 (reached by max_level = 2 re-solves, one level each).
 *  - the default with adapt.every 4: step 3 is no estimate step of the
 *    schedule (steps 4, 8, ...), but the step in which a tool punctures is
 *    estimated whatever the schedule says, so its tip's leaves are at
 *    level 2 as well (without that rule: level 0, no estimate at all).
 * The tip is taken from the scene's prescribed motion (base + (length +
 * speed t) direction), not from the contact module: the needle's
 * deflection is micrometres, far below the 1e-3 of a cell the leaves'
 * boxes are widened by. */
#include "sim_util.h"

#include "mesh/mesh.h"

#include <math.h>

/* The lowest and highest level of the leaves whose rest box, widened by
 * 1e-3 of its edges, holds x; *n: how many. */
static void tip_levels(const nh_mesh *m, const double x[3], int *lo, int *hi, int *n) {
  *lo = 1 << 30, *hi = -1, *n = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    const int c = m->leaves[l], *e = m->cells + 8 * c;
    int inside = 1;
    for (int d = 0; d < 3; d++) {
      double a = m->X[3 * e[0] + d], b = a;
      for (int k = 1; k < 8; k++) a = fmin(a, m->X[3 * e[k] + d]), b = fmax(b, m->X[3 * e[k] + d]);
      inside = inside && x[d] >= a - 1e-3 * (b - a) && x[d] <= b + 1e-3 * (b - a);
    }
    if (!inside) continue;
    (*n)++;
    *lo = m->level[c] < *lo ? m->level[c] : *lo;
    *hi = m->level[c] > *hi ? m->level[c] : *hi;
  }
}

/* Three steps of the phantom with the overrides; the levels of the tip's leaves after them. */
static void run(const char *resolve_tip, const char *every, int *lo, int *hi, int *n, int *dofs) {
  const char *sets[] = {"adapt.estimator=goal",
                        "adapt.template=hex2",
                        "adapt.max_level=2",
                        resolve_tip,
                        every,
                        "time.steps=3",
                        NULL};
  nh_scene *scene;
  nh_sim *sim;
  nh_case_open("phantom/phantom.yaml", sets, &scene, &sim);
  for (int k = 0; k < 3; k++) CHECK_OK(nh_sim_step(sim));
  const nh_tool_spec *tool = &scene->tools[0];
  const double travel = tool->motion[0].speed * nh_sim_time(sim);
  double tip[3];
  for (int d = 0; d < 3; d++) tip[d] = tool->base[d] + (tool->length + travel) * tool->direction[d];
  CHECK(tip[0] > 0.0 && tip[0] < 0.2e-3,
        "the tip at step 3 is at x = %.3e m, expected in the block's first 0.2 mm", tip[0]);
  const nh_mesh *m = nh_sim_mesh(sim);
  tip_levels(m, tip, lo, hi, n);
  *dofs = 3 * m->n_nodes;
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
}

int main(void) {
  int lo, hi, n, dofs;
  run("adapt.resolve_tip=false", "adapt.every=1", &lo, &hi, &n, &dofs);
  CHECK(dofs == 675 && n > 0 && hi == 0,
        "resolve_tip false: step 3 solved on %d dofs, the tip's %d leaves at levels %d-%d; "
        "expected the 8x4x4 grid (675 dofs, level 0): the lag",
        dofs, n, lo, hi);
  run("adapt.resolve_tip=true", "adapt.every=1", &lo, &hi, &n, &dofs);
  CHECK(n > 0 && lo == 2 && hi == 2,
        "resolve_tip true: the tip's %d leaves at step 3 are at levels %d-%d, expected all at "
        "max_level 2 (%d dofs)",
        n, lo, hi, dofs);
  run("adapt.resolve_tip=true", "adapt.every=4", &lo, &hi, &n, &dofs);
  CHECK(n > 0 && lo == 2 && hi == 2,
        "resolve_tip true, every 4: the tip's %d leaves at the puncture step 3 are at levels "
        "%d-%d, expected all at max_level 2 (%d dofs)",
        n, lo, hi, dofs);
  TEST_END();
}
