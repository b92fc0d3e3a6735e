/* main.c — the command-line front end (docs/scene.md: scene keys, overrides,
 * errors; docs/outputs.md: what a run writes, restart and signals).
 *
 *   needlehex run SCENE.yaml [--out DIR] [--set KEY=VALUE ...] [--restart DIR] [--overwrite]
 *                 [--quiet]
 *   needlehex check SCENE.yaml [--set KEY=VALUE ...]
 *   needlehex --help | --version
 *
 * Exit status: 0 success; 1 the simulation failed (the message names the
 * step); 2 bad scene or arguments (the message names file, line and key).
 * Every error is one line on stderr, prefixed "needlehex: ".
 *
 * Threads: CHOLMOD's BLAS (Debian's OpenBLAS, pthread build) keeps its
 * workers spinning for ~0.1 s after each call, and an OpenMP team that also
 * spins then fights them for the two cores: on the 16x8x8 phantom assembly
 * went from 1.8 ms to 58 ms per step. With OMP_WAIT_POLICY=passive the
 * OpenMP threads sleep instead, which measured best at every size
 * (docs/performance.md). libgomp reads the variable before main runs, so
 * when the user has not set it we set it and re-execute ourselves once. */
#include "core/core.h"
#include "scene/scene.h"
#include "sim/sim.h"

#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static const char *nh_usage =
    "usage: needlehex run SCENE.yaml [--out DIR] [--set KEY=VALUE ...] [--restart DIR] "
    "[--overwrite]\n"
    "                     [--quiet]\n"
    "       needlehex check SCENE.yaml [--set KEY=VALUE ...]\n"
    "       needlehex --help | --version\n"
    "\n"
    "  run      simulate the scene; outputs go to output.dir (default out/<name>)\n"
    "  check    validate the scene (and the mesh it builds), print what will be modelled\n"
    "  --out DIR          write outputs to DIR (overrides output.dir)\n"
    "  --set KEY=VALUE    override a scene key by dotted path, e.g. --set tissue.grid=[16,8,8]\n"
    "  --restart DIR      continue the run whose outputs (and checkpoint.nhc) are in DIR\n"
    "  --overwrite        replace the outputs of a previous run in the output folder (a run\n"
    "                     into a folder holding them is refused otherwise)\n"
    "  --quiet            no progress line and no summary\n"
    "\n"
    "SIGINT / SIGTERM stop a run within a second, at its last complete step, with a final frame\n"
    "and a checkpoint.\n"
    "\n"
    "exit status: 0 success, 1 simulation failed, 2 bad scene or arguments\n";

static int nh_fail(int code) {
  fprintf(stderr, "needlehex: %s\n", nh_error_message());
  return nh_error_exit_status(code);
}

/* Set OMP_WAIT_POLICY=passive (unless the user chose) and re-execute. On
 * failure to re-execute, carry on with the default policy. */
static void nh_passive_threads(char **argv) {
  if (getenv("OMP_WAIT_POLICY")) return;
  if (setenv("OMP_WAIT_POLICY", "passive", 1) != 0) return;
  execv("/proc/self/exe", argv);
}

int main(int argc, char **argv) {
  nh_passive_threads(argv);
  if (argc < 2) {
    fputs(nh_usage, stderr);
    return 2;
  }
  if (!strcmp(argv[1], "--help") || !strcmp(argv[1], "-h")) {
    fputs(nh_usage, stdout);
    return 0;
  }
  if (!strcmp(argv[1], "--version")) {
    printf("needlehex %s\n", NH_VERSION);
    return 0;
  }
  const char *command = argv[1];
  int is_run = !strcmp(command, "run"), is_check = !strcmp(command, "check");
  if (!is_run && !is_check)
    return nh_fail(NH_ERROR(NH_ERR_INPUT, "unknown command '%s' (try --help)", command));

  const char *scene_path = NULL, *out_dir = NULL, *restart = NULL;
  int quiet = 0, n_set = 0, overwrite = 0;
  const char **sets = calloc((size_t)argc + 1, sizeof(char *));
  if (!sets) return nh_fail(NH_ERROR(NH_ERR_MEMORY, "out of memory"));
  int rc = NH_OK;
  for (int i = 2; i < argc && !rc; i++) {
    const char *a = argv[i];
    if (!strcmp(a, "--set") || !strcmp(a, "--out") || !strcmp(a, "--restart")) {
      if (i + 1 >= argc) {
        rc = NH_ERROR(NH_ERR_INPUT, "%s needs a value", a);
        break;
      }
      if (a[2] == 's')
        sets[n_set++] = argv[++i];
      else if (a[2] == 'o')
        out_dir = argv[++i];
      else
        restart = argv[++i];
    } else if (!strncmp(a, "--set=", 6)) {
      sets[n_set++] = a + 6;
    } else if (!strncmp(a, "--out=", 6)) {
      out_dir = a + 6;
    } else if (!strcmp(a, "--quiet") || !strcmp(a, "-q")) {
      quiet = 1;
    } else if (!strcmp(a, "--overwrite")) {
      overwrite = 1;
    } else if (a[0] == '-') {
      rc = NH_ERROR(NH_ERR_INPUT, "unknown option '%s' (try --help)", a);
    } else if (!scene_path) {
      scene_path = a;
    } else {
      rc = NH_ERROR(NH_ERR_INPUT, "unexpected argument '%s': one scene file per run", a);
    }
  }
  if (!rc && !scene_path)
    rc = NH_ERROR(NH_ERR_INPUT, "%s needs a scene file (try --help)", command);
  if (!rc && out_dir && strlen(out_dir) >= NH_PATH_MAX)
    rc = NH_ERROR(NH_ERR_INPUT, "--out: path too long");
  if (rc) {
    free(sets);
    return nh_fail(rc);
  }
  if (quiet) nh_log_set_level(NH_LOG_QUIET);

  nh_scene *scene = NULL;
  nh_sim *sim = NULL;
  rc = nh_scene_load(scene_path, n_set, sets, &scene);
  free(sets);
  if (rc) return nh_fail(rc);
  if (restart && !is_run) {
    nh_scene_destroy(&scene);
    return nh_fail(NH_ERROR(NH_ERR_INPUT, "--restart goes with run"));
  }
  if (restart) out_dir = restart; /* a continued run writes where it was written */
  if (out_dir) snprintf(scene->output.dir, sizeof scene->output.dir, "%s", out_dir);
  if (is_run) {
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = nh_sim_request_stop;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);
  }

  nh_sim_options opt = {.dry_run = is_check,
                        .progress = is_run && !quiet,
                        .restart_dir = restart,
                        .overwrite = overwrite};
  rc = nh_sim_create(scene, &opt, &sim);
  if (!rc && is_check) nh_scene_print(scene, stdout);
  if (!rc && is_check)
    printf("mesh: %d nodes (%d dofs, %d free), %d cells\n", nh_sim_mesh(sim)->n_nodes,
           3 * nh_sim_mesh(sim)->n_nodes, nh_system_free_dofs(nh_sim_system(sim)),
           nh_sim_mesh(sim)->n_leaves);
  if (!rc && is_check) {
    const nh_mesh *m = nh_sim_mesh(sim);
    const nh_domain *d = &m->domain;
    int lattice = m->grid[0] * m->grid[1] * m->grid[2], kept = 0;
    for (int c = 0; c < m->n_cells; c++) kept += m->parent[c] < 0;
    printf("domain: %s of size [%g, %g, %g] m, %d of %d grid cells kept (fill floor %g), "
           "volume %.6g m^3 (sum of fill x cell volume) vs %.6g m^3 (the shape's)\n",
           nh_domain_name(d), d->max[0] - d->min[0], d->max[1] - d->min[1], d->max[2] - d->min[2],
           kept, lattice, NH_FILL_MIN, nh_mesh_fill_volume(m), nh_domain_volume(d));
    if (d->labels) rc = nh_image_print(d->labels, stdout);
    if (d->surface) nh_surface_print(d->surface, stdout);
  }
  if (!rc && is_run) rc = nh_sim_run(sim);
  int status = rc ? nh_fail(rc) : 0;
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  return status;
}
