/* refine_cells_tool — a controlled local refinement, for measuring what
 * refining chosen cells does to a goal (docs/dbs.md, "Refinement at the
 * skull: point rows against weighted-gap rows").
 *
 *   refine_cells_tool SCENE STEP STEPS [X,Y,Z ...] [-- KEY=VALUE ...]
 *       loads SCENE with the overrides after "--" (as `needlehex run
 *       --set`), runs STEPS steps without writing files and, before step
 *       STEP + 1 (0: before the first step), refines once, by the scene's
 *       adapt.template, the leaves that hold the points X,Y,Z (metres;
 *       nh_mesh_locate: each must lie in the mesh),
 *       with the state carried to the new nodes as an adaptive run carries
 *       it (nh_sim_refine_cells). Prints one line per step: the step, the
 *       time (s), the dofs and the first target's current position (mm),
 *       or the first probe's displacement (mm) if the scene has no target.
 *       The scene needs an adapt section (its template); to keep its own
 *       estimator from refining, pass adapt.every=1000000.
 * Exit 0 on success, 1 on a failed step, 2 on bad arguments or a bad scene. */
#include "mesh/mesh.h"
#include "sim/sim.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NH_TOOL_MAX_POINTS 256

static int usage(FILE *to, int status) {
  fprintf(to, "usage: refine_cells_tool SCENE STEP STEPS [X,Y,Z ...] [-- KEY=VALUE ...]\n"
              "  refines once, before step STEP + 1, the leaves holding the points\n"
              "  X,Y,Z (m), runs STEPS steps of SCENE (KEY=VALUE: as needlehex run --set)\n"
              "  and prints per step: step, time (s), dofs, the first target's position\n"
              "  (or the first probe's displacement), mm\n");
  return status;
}

/* The leaf holding x (nh_mesh_locate), or -1 with a message. */
static int leaf_at(const nh_mesh *m, const double x[3]) {
  int c;
  double xi[3];
  if (nh_mesh_locate(m, x, &c, xi) == NH_OK) return c;
  fprintf(stderr, "refine_cells_tool: point %g,%g,%g lies outside the mesh\n", x[0], x[1], x[2]);
  return -1;
}

int main(int argc, char **argv) {
  if (argc == 2 && (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h"))) return usage(stdout, 0);
  if (argc < 4) return usage(stderr, 2);
  char *end2, *end3;
  const long step = strtol(argv[2], &end2, 10), steps = strtol(argv[3], &end3, 10);
  if (*end2 || *end3 || step < 0 || steps < 1) return usage(stderr, 2);
  double points[NH_TOOL_MAX_POINTS][3];
  int n_points = 0, a = 4;
  for (; a < argc && strcmp(argv[a], "--"); a++) {
    if (n_points == NH_TOOL_MAX_POINTS || sscanf(argv[a], "%lf,%lf,%lf", &points[n_points][0],
                                                 &points[n_points][1], &points[n_points][2]) != 3)
      return usage(stderr, 2);
    n_points++;
  }
  if (n_points && step >= steps) return usage(stderr, 2); /* the refinement would never happen */
  const int n_sets = a < argc ? argc - a - 1 : 0;
  nh_scene *scene = NULL;
  nh_sim *sim = NULL;
  if (nh_scene_load(argv[1], n_sets, (const char *const *)(argv + a + 1), &scene)) {
    fprintf(stderr, "refine_cells_tool: %s\n", nh_error_message());
    return 2;
  }
  nh_sim_options options = {.dry_run = 1, .progress = 0};
  int rc = nh_sim_create(scene, &options, &sim) ? 2 : 0;
  if (rc) fprintf(stderr, "refine_cells_tool: %s\n", nh_error_message());
  const int has_target = !rc && scene->n_targets > 0;
  if (!rc && !has_target && scene->n_probes == 0) {
    fprintf(stderr, "refine_cells_tool: %s has no target and no probe to print\n", argv[1]);
    rc = 2;
  }
  for (long s = 1; s <= steps && !rc; s++) {
    if (s == step + 1 && n_points) {
      const nh_mesh *m = nh_sim_mesh(sim);
      int cells[NH_TOOL_MAX_POINTS], n_cells = 0;
      for (int p = 0; p < n_points && !rc; p++) {
        const int c = leaf_at(m, points[p]);
        int seen = 0;
        for (int i = 0; i < n_cells; i++) seen |= cells[i] == c;
        if (c < 0)
          rc = 2;
        else if (!seen)
          cells[n_cells++] = c;
      }
      if (!rc && nh_sim_refine_cells(sim, cells, n_cells)) {
        fprintf(stderr, "refine_cells_tool: %s\n", nh_error_message());
        rc = 1;
      }
    }
    if (!rc && nh_sim_step(sim)) {
      fprintf(stderr, "refine_cells_tool: %s\n", nh_error_message());
      rc = 1;
    }
    if (rc) break;
    double x[3], miss[3];
    if (has_target)
      nh_sim_target_miss(sim, 0, x, miss);
    else
      nh_sim_probe_displacement(sim, 0, x);
    printf("%ld %.6g %d %.12e %.12e %.12e\n", s, nh_sim_time(sim), 3 * nh_sim_mesh(sim)->n_nodes,
           1e3 * x[0], 1e3 * x[1], 1e3 * x[2]);
  }
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  return rc;
}
