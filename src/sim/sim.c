/* sim.c — the step loop (docs/theory.md; docs/interaction.md for the tools).
 *
 * One step: external forces at the new time (loads by their schedules,
 * gravity), then either a backward-Euler step (dynamic) or a Newton solve to
 * equilibrium under the loads of that pseudo-time (static); with `adapt`,
 * the error of that solution is estimated (SPR); then rows of steps.csv and
 * probes.csv, and a frame when due, so a frame shows a solution on the mesh
 * it was computed on, with its error indicators; last, adapt marks and
 * refines cells and carries the state to the new nodes (nh_adapt_step,
 * Eq. 17), sim rebuilds what depends on the mesh, and the next step
 * continues on the new mesh. Every phase is timed and the times are
 * kept per step for the summary. The initial state is frame 0, so a time
 * series always starts at rest.
 *
 * With adapt.resolve (estimator goal) the step is refined and solved again
 * from its start state, carried to the new mesh, up to N times before its
 * rows are written (nh_sim_resolve), so the written solution is on the mesh
 * its estimate asked for. The tools' start state (saved at the start of
 * every step) is restored too, its embedded points relocated on the new
 * mesh (they are material points); the skull's warm starts and its choice
 * of candidate rows are those after the first solve.
 *
 * Everything that depends on the mesh (fixed nodes, element data, load
 * vectors, probe cells, hanging nodes, the linear system) is built by
 * nh_sim_setup_mesh, at creation and after every refinement. */
#include "sim/sim_impl.h"

#include <dirent.h>
#include <errno.h>
#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const nh_step_columns[] = {"step",
                                              "time",
                                              "dofs",
                                              "free_dofs",
                                              "cells",
                                              "hanging",
                                              "constraints",
                                              "eta",
                                              "eta_rel",
                                              "iterations",
                                              "residual",
                                              "t_assemble",
                                              "t_factor",
                                              "t_solve",
                                              "t_constraints",
                                              "t_adapt",
                                              "t_output",
                                              "t_step",
                                              "work",
                                              "constraint_iterations",
                                              "constraint_residual",
                                              "stick",
                                              "slide",
                                              "cut",
                                              "path_points",
                                              "t_compliance",
                                              "t_mcp",
                                              "factorised",
                                              "pcg_iterations",
                                              "corrections",
                                              "t_factor_reference",
                                              "inverted",
                                              "error_estimate",
                                              "refine_stop",
                                              "resolves",
                                              "tangent_updates",
                                              "skull_contacts",
                                              "skull_fx",
                                              "skull_fy",
                                              "skull_fz"};
static const char *const nh_probe_columns[] = {"step", "time", "name", "x",  "y",
                                               "z",    "ux",   "uy",   "uz", "error_estimate"};

/* probes.csv has error_estimate under estimator goal only. */
static int nh_probe_column_count(const nh_scene *sc) {
  return sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL ? 10 : 9;
}

double nh_sim_point_error(const nh_sim *s, int i) {
  const double *e = nh_adapt_goal_errors(s->adapt);
  if (!e || !s->goal_of_point || s->goal_of_point[i] < 0) return NAN;
  return e[s->goal_of_point[i]];
}

void nh_sim_destroy(nh_sim **sim) {
  if (!sim || !*sim) return;
  nh_sim *s = *sim;
  nh_sim_tools_destroy(s);
  nh_system_destroy(&s->system);
  nh_tissue_destroy(&s->tissue);
  nh_mesh_destroy(&s->mesh);
  free(s->fixed);
  free(s->moved);
  free(s->u);
  free(s->x);
  free(s->v);
  free(s->u_start);
  free(s->v_start);
  free(s->restore_tools);
  free(s->restore_solver);
  free(s->tools_start);
  free(s->solver_start.data);
  free(s->f_ext);
  free(s->drained);
  free(s->load_unit);
  free(s->probe_cell);
  free(s->probe_xi);
  free(s->phase_times);
  free(s->goal_of_point);
  nh_adapt_destroy(&s->adapt);
  nh_hanging_destroy(&s->hanging);
  nh_csv_destroy(&s->steps_csv);
  nh_csv_destroy(&s->probes_csv);
  nh_pvd_destroy(&s->tissue_pvd);
  nh_pvd_destroy(&s->points_pvd);
  if (s->h5) { /* a run that failed: keep its rows if the disk allows, and its message */
    char reason[1024];
    snprintf(reason, sizeof reason, "%s", nh_error_message());
    if (nh_h5_close(&s->h5)) nh_error_set(NH_ERR_IO, __FILE__, __LINE__, "%s", reason);
  }
  free(s);
  *sim = NULL;
}

const nh_mesh *nh_sim_mesh(const nh_sim *s) {
  return s->mesh;
}
const nh_tissue *nh_sim_tissue(const nh_sim *s) {
  return s->tissue;
}
nh_system *nh_sim_system(nh_sim *s) {
  return s->system;
}
double *nh_sim_displacements(nh_sim *s) {
  return s->u;
}
double *nh_sim_velocities(nh_sim *s) {
  return s->v;
}
const unsigned char *nh_sim_fixed(const nh_sim *s) {
  return s->fixed;
}
int nh_sim_step_index(const nh_sim *s) {
  return s->step;
}
double nh_sim_time(const nh_sim *s) {
  return s->time;
}

void nh_sim_external_force(const nh_sim *s, double t, double *f) {
  const int n = 3 * s->mesh->n_nodes;
  const nh_scene *sc = s->scene;
  double g[3]; /* gravity by its schedule, less the tissue's buoyed part */
  nh_scene_tissue_gravity(sc, t, g);
  const double *mass = sc->tissue.buoyant ? s->drained : s->tissue->mass;
  for (int i = 0; i < n; i++) f[i] = mass[i / 3] * g[i % 3];
  for (int l = 0; l < sc->tissue.n_loads + sc->tissue.n_tractions; l++) {
    const int nl = sc->tissue.n_loads;
    double factor = nh_schedule_eval(
        l < nl ? &sc->tissue.loads[l].schedule : &sc->tissue.tractions[l - nl].schedule, t);
    if (factor == 0.0) continue;
    const double *u = s->load_unit + (size_t)l * n;
    for (int i = 0; i < n; i++) f[i] += factor * u[i];
  }
}

/* Prescribed displacements (tissue.fixed's displacement × schedule) of the
 * fixed components at time t, set in u before the step solves: the step
 * keeps fixed DOFs at their values (docs/theory.md §5). */
static void nh_sim_prescribe(nh_sim *s, double t) {
  const nh_scene *sc = s->scene;
  for (int i = 0; i < s->mesh->n_nodes; i++) {
    if (s->moved[i] < 0) continue;
    const nh_fix *fx = &sc->tissue.fix[s->moved[i]];
    double factor = nh_schedule_eval(&fx->schedule, t);
    for (int k = 0; k < 3; k++)
      if (nh_fixed_component(s->fixed, i, k)) s->u[3 * i + k] = factor * fx->displacement[k];
  }
}

void nh_sim_probe_displacement(const nh_sim *s, int i, double u[3]) {
  double N[8];
  nh_hex_shape(s->probe_xi + 3 * i, N);
  const int *e = s->mesh->cells + 8 * s->probe_cell[i];
  u[0] = u[1] = u[2] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) u[k] += N[a] * s->u[3 * e[a] + k];
}

double nh_sim_kinetic_energy(const nh_sim *s) {
  double e = 0.0;
  for (int i = 0; i < 3 * s->mesh->n_nodes; i++)
    e += 0.5 * s->tissue->mass[i / 3] * s->v[i] * s->v[i];
  return e;
}

static int nh_cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

void nh_sim_median_times(const nh_sim *s, double t[7]) {
  for (int p = 0; p < NH_PHASES; p++) t[p] = 0.0;
  const int first = s->first_step, n = s->step - first; /* steps this process timed */
  if (n <= 0) return;
  double *buf = malloc(sizeof(double) * (size_t)n);
  if (!buf) return;
  for (int p = 0; p < NH_PHASES; p++) {
    for (int k = 0; k < n; k++) buf[k] = s->phase_times[NH_PHASES * (first + k) + p];
    qsort(buf, (size_t)n, sizeof(double), nh_cmp_double);
    t[p] = n % 2 ? buf[n / 2] : 0.5 * (buf[n / 2 - 1] + buf[n / 2]);
  }
  free(buf);
}

/* ---- outputs ---- */

/* The tissue's frame: current positions (also left in s->x), the hexahedra
 * of the leaves, displacement, velocity, hanging-node and fixed-node flags,
 * and per cell von Mises stress, level, fill, indicator and Young's modulus.
 * One description, written as tissue_NNNNNN.vtu and (output.hdf5) as the
 * HDF5 frame. */
static int nh_write_tissue_frame(nh_sim *s) {
  const nh_mesh *m = s->mesh;
  const int nc = m->n_leaves, np = m->n_nodes;
  int *conn = nh_calloc(8 * (size_t)nc, sizeof *conn);
  int *offsets = nh_calloc((size_t)nc, sizeof *offsets);
  int *flags = nh_calloc((size_t)np, sizeof *flags);
  double *cell = nh_calloc(5 * (size_t)nc, sizeof *cell);
  double *hang = nh_calloc((size_t)np, sizeof *hang);
  const double *eta = nh_adapt_indicators(s->adapt);
  int rc = conn && offsets && flags && cell && hang
               ? NH_OK
               : NH_ERROR(NH_ERR_MEMORY, "out of memory writing a frame");
  for (int l = 0; l < nc && !rc; l++) {
    int c = m->leaves[l];
    memcpy(conn + 8 * l, m->cells + 8 * c, 8 * sizeof(int));
    offsets[l] = 8 * (l + 1);
    double sig[6];
    nh_tissue_cell_stress(s->tissue, c, s->u, sig);
    cell[l] = nh_von_mises(sig);
    cell[nc + l] = m->level[c];
    cell[2 * nc + l] = m->fill[c];
    cell[3 * nc + l] = eta ? eta[c] : 0.0;
    double lambda, mu; /* the cell's Young's modulus (mixed cells: from the averaged λ, μ) */
    nh_tissue_cell_material(s->tissue, c, &lambda, &mu, NULL);
    cell[4 * nc + l] = mu * (3 * lambda + 2 * mu) / (lambda + mu);
  }
  if (!rc && s->hanging)
    for (int k = 0; k < s->hanging->n_hanging; k++) hang[s->hanging->node[k]] = 1.0;
  for (int i = 0; i < np && !rc; i++) {
    flags[i] = s->fixed[i];
    for (int k = 0; k < 3; k++) s->x[3 * i + k] = m->X[3 * i + k] + s->u[3 * i + k];
  }
  const nh_field pf[3] = {
      {"displacement", 3, s->u, "m"}, {"velocity", 3, s->v, "m/s"}, {"hanging", 1, hang, "1"}};
  const nh_field cf[5] = {{"von_mises", 1, cell, "Pa"},
                          {"level", 1, cell + nc, "1"},
                          {"fill", 1, cell + 2 * nc, "1"},
                          {"eta", 1, cell + 3 * nc, "J^(1/2)"},
                          {"young", 1, cell + 4 * nc, "Pa"}};
  const nh_frame frame = {.n_points = np,
                          .points = s->x,
                          .n_cells = nc,
                          .connectivity = conn,
                          .offsets = offsets,
                          .type = NH_VTK_HEXAHEDRON,
                          .n_point_fields = 3,
                          .point_fields = pf,
                          .n_cell_fields = 5,
                          .cell_fields = cf,
                          .point_int_flags = flags,
                          .point_flag_name = "fixed"};
  if (!rc) rc = nh_pvd_write_frame(s->tissue_pvd, s->step, s->time, &frame);
  if (!rc && s->h5) rc = nh_h5_write_frame(s->h5, s->step, s->time, &frame);
  free(conn), free(offsets), free(flags), free(cell), free(hang);
  return rc;
}

/* The frame of the n embedded points (probes, then targets): vertices at
 * their current positions, their displacement, a target flag and their
 * names; written as points_NNNNNN.vtu. */
static int nh_write_points_frame(nh_sim *s, int n) {
  const nh_scene *sc = s->scene;
  double *x = nh_calloc(3 * (size_t)n, sizeof *x), *u = nh_calloc(3 * (size_t)n, sizeof *u);
  int *conn = nh_calloc((size_t)n, sizeof *conn), *offsets = nh_calloc((size_t)n, sizeof *offsets);
  int *target = nh_calloc((size_t)n, sizeof *target);
  const char **names = nh_calloc((size_t)n, sizeof *names);
  int rc = x && u && conn && offsets && target && names
               ? NH_OK
               : NH_ERROR(NH_ERR_MEMORY, "out of memory writing a frame");
  for (int i = 0; i < n && !rc; i++) {
    const int probe = i < sc->n_probes;
    const double *X = probe ? sc->probes[i].point : sc->targets[i - sc->n_probes].point;
    nh_sim_probe_displacement(s, i, u + 3 * i);
    for (int k = 0; k < 3; k++) x[3 * i + k] = X[k] + u[3 * i + k];
    conn[i] = i;
    offsets[i] = i + 1;
    target[i] = !probe;
    names[i] = probe ? sc->probes[i].name : sc->targets[i - sc->n_probes].name;
  }
  const nh_field pf[1] = {{"displacement", 3, u, "m"}};
  const nh_frame frame = {.n_points = n,
                          .points = x,
                          .n_cells = n,
                          .connectivity = conn,
                          .offsets = offsets,
                          .type = NH_VTK_VERTEX,
                          .n_point_fields = 1,
                          .point_fields = pf,
                          .point_int_flags = target,
                          .point_flag_name = "target",
                          .point_names = names};
  if (!rc) rc = nh_pvd_write_frame(s->points_pvd, s->step, s->time, &frame);
  free(x), free(u), free(conn), free(offsets), free(target), free(names);
  return rc;
}

/* This step's frames: the tissue, the embedded points, the tools. */
static int nh_write_frame(nh_sim *s) {
  const int n_points = s->scene->n_probes + s->scene->n_targets;
  NH_TRY(nh_write_tissue_frame(s));
  if (n_points > 0) NH_TRY(nh_write_points_frame(s, n_points));
  if (s->contact) NH_TRY(nh_sim_tools_frame(s));
  s->last_frame = s->step;
  return NH_OK;
}

static int nh_write_probe_rows(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (s->h5 && sc->n_probes > 0) {
    static const char *const comps[] = {"x", "y", "z", "ux", "uy", "uz"};
    const char **names = malloc(sizeof(char *) * (size_t)sc->n_probes);
    double *vals = malloc(sizeof(double) * 6 * (size_t)sc->n_probes);
    int rc = names && vals ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: probe series");
    for (int i = 0; i < sc->n_probes && !rc; i++) {
      names[i] = sc->probes[i].name;
      nh_sim_probe_displacement(s, i, vals + 6 * i + 3);
      for (int k = 0; k < 3; k++) vals[6 * i + k] = sc->probes[i].point[k] + vals[6 * i + 3 + k];
    }
    if (!rc)
      rc = nh_h5_append_series(s->h5, "probes", s->step, s->time, sc->n_probes, names, 6, comps,
                               vals);
    free(names);
    free(vals);
    NH_TRY(rc);
  }
  for (int i = 0; i < sc->n_probes; i++) {
    double u[3];
    nh_sim_probe_displacement(s, i, u);
    const double *p = sc->probes[i].point;
    if (nh_probe_column_count(sc) == 10)
      NH_TRY(nh_csv_row(s->probes_csv, "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g",
                        s->step, s->time, sc->probes[i].name, p[0] + u[0], p[1] + u[1], p[2] + u[2],
                        u[0], u[1], u[2], nh_sim_point_error(s, i)));
    else
      NH_TRY(nh_csv_row(s->probes_csv, "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g", s->step,
                        s->time, sc->probes[i].name, p[0] + u[0], p[1] + u[1], p[2] + u[2], u[0],
                        u[1], u[2]));
  }
  return s->contact ? nh_sim_tools_rows(s) : NH_OK;
}

/* Is `name` a file a run writes (docs/outputs.md): the tables, collections,
 * frames NAME_NNNNNN.vtu and results_NNNNNN.h5, results.h5/.xdmf, the
 * checkpoint, scene.yaml, a moved-aside results.h5.damaged*, a *.tmp? */
static int nh_is_run_output(const char *name) {
  static const char *const fixed[] = {"scene.yaml",   "steps.csv",      "probes.csv",
                                      "targets.csv",  "tools.csv",      "results.h5",
                                      "results.xdmf", "checkpoint.nhc", NULL};
  for (int i = 0; fixed[i]; i++)
    if (!strcmp(name, fixed[i])) return 1;
  size_t n = strlen(name);
  if (!strncmp(name, "results.h5.damaged", 18)) return 1;
  if (n > 4 && (!strcmp(name + n - 4, ".pvd") || !strcmp(name + n - 4, ".tmp"))) return 1;
  /* PREFIX_NNNNNN.vtu, results_NNNNNN.h5 */
  const char *us = strrchr(name, '_');
  if (!us || us == name) return 0;
  size_t d = strspn(us + 1, "0123456789");
  return d >= 6 && (!strcmp(us + 1 + d, ".vtu") ||
                    (!strcmp(us + 1 + d, ".h5") && !strncmp(name, "results_", 8)));
}

/* A fresh run's folder: refuse one holding a previous run's outputs, or
 * (overwrite) remove them; files that are not outputs are left alone. */
static int nh_claim_folder(const nh_sim *s) {
  const char *dir = s->scene->output.dir;
  DIR *d = opendir(dir);
  if (!d) return NH_OK; /* absent: created next */
  int count = 0, rc = NH_OK;
  char first[256] = "";
  for (struct dirent *e; (e = readdir(d)) && !rc;) {
    if (!nh_is_run_output(e->d_name)) continue;
    if (!count++) snprintf(first, sizeof first, "%s", e->d_name);
    if (s->options.overwrite) {
      char path[NH_PATH_MAX + 300];
      snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
      if (remove(path) != 0)
        rc = NH_ERROR(NH_ERR_IO, "--overwrite: cannot remove '%s': %s", path, strerror(errno));
    }
  }
  closedir(d);
  if (!rc && count && !s->options.overwrite)
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: the output folder holds the files of a previous run (%s and %d more): "
                  "continue it with --restart %s, replace them with --overwrite, or choose "
                  "another --out",
                  dir, first, count - 1, dir);
  return rc;
}

static int nh_open_outputs(nh_sim *s) {
  if (!s->options.restart_dir) NH_TRY(nh_claim_folder(s));
  NH_TRY(nh_mkdir_p(s->scene->output.dir));
  if (s->scene->output.hdf5) {
    const char *yaml = s->scene->yaml ? s->scene->yaml : "";
    const int n_columns = (int)(sizeof nh_step_columns / sizeof *nh_step_columns);
    const char *dir = s->scene->output.dir;
    if (s->options.restart_dir)
      NH_TRY(nh_h5_resume(dir, yaml, NH_VERSION, n_columns, nh_step_columns, s->step, &s->h5));
    else
      NH_TRY(nh_h5_create(dir, yaml, NH_VERSION, n_columns, nh_step_columns, &s->h5));
  }
  if (s->options.restart_dir) {
    const nh_scene *sc = s->scene;
    const char *dir = sc->output.dir;
    char path[NH_PATH_MAX + 64];
    snprintf(path, sizeof path, "%s/steps.csv", dir);
    NH_TRY(nh_csv_resume(path, (int)(sizeof nh_step_columns / sizeof *nh_step_columns),
                         nh_step_columns, s->step, &s->steps_csv));
    snprintf(path, sizeof path, "%s/probes.csv", dir);
    NH_TRY(
        nh_csv_resume(path, nh_probe_column_count(sc), nh_probe_columns, s->step, &s->probes_csv));
    NH_TRY(nh_pvd_resume(dir, "tissue", sc->time.step, s->step, &s->tissue_pvd));
    if (sc->n_probes + sc->n_targets > 0) /* targets are points too */
      NH_TRY(nh_pvd_resume(dir, "points", sc->time.step, s->step, &s->points_pvd));
    NH_TRY(nh_sim_tools_open(s));
    s->last_frame = s->step; /* its frame, if due, was written by the first run */
    return NH_OK;
  }
  const nh_scene *sc = s->scene;
  char path[NH_PATH_MAX + 64];
  const char *dir = sc->output.dir;
  NH_TRY(nh_mkdir_p(dir));
  snprintf(path, sizeof path, "%s/scene.yaml", dir);
  NH_TRY(nh_write_text(path, sc->yaml ? sc->yaml : ""));
  snprintf(path, sizeof path, "%s/steps.csv", dir);
  NH_TRY(nh_csv_create(path, (int)(sizeof nh_step_columns / sizeof *nh_step_columns),
                       nh_step_columns, &s->steps_csv));
  snprintf(path, sizeof path, "%s/probes.csv", dir);
  NH_TRY(nh_csv_create(path, nh_probe_column_count(sc), nh_probe_columns, &s->probes_csv));
  snprintf(path, sizeof path, "%s/tissue.pvd", dir);
  NH_TRY(nh_pvd_create(path, &s->tissue_pvd));
  if (sc->n_probes + sc->n_targets > 0) {
    snprintf(path, sizeof path, "%s/points.pvd", dir);
    NH_TRY(nh_pvd_create(path, &s->points_pvd));
  }
  NH_TRY(nh_sim_tools_open(s));
  NH_TRY(nh_write_probe_rows(s));
  return nh_write_frame(s);
}

/* ---- construction ---- */

/* Resize a per-node array of `comps` doubles to the mesh's node count. */
static int nh_resize(double **a, int n_nodes, int comps) {
  double *p = realloc(*a, sizeof(double) * (size_t)comps * (size_t)(n_nodes ? n_nodes : 1));
  if (!p) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", n_nodes);
  *a = p;
  return NH_OK;
}

/* Everything that depends on the mesh, built at creation (first = 1, which
 * also reports scene errors only the mesh reveals) and after refinement. */
/* A fixed region's tie stiffness is NH_TIE_STIFFNESS E / ℓ², ℓ its smallest
 * size (nh_region_size): the tissue inside moves by about 1/NH_TIE_STIFFNESS
 * of what an elastic body of size ℓ would (docs/theory.md §5). */
#define NH_TIE_STIFFNESS 1.0e3

/* tissue.fixed[r] on an immersed domain is a volumetric tie (all components
 * clamped, no prescribed motion, a geometric region), not a node set. */
static int nh_sim_fixed_is_tie(const nh_scene *sc, int immersed, int r) {
  const nh_fix *fx = &sc->tissue.fix[r];
  return immersed && sc->tissue.fixed[r].kind != NH_REGION_LABEL && fx->axes == 7 &&
         fx->displacement[0] == 0.0 && fx->displacement[1] == 0.0 && fx->displacement[2] == 0.0;
}

static int nh_sim_setup_mesh(nh_sim *s, int first) {
  const nh_scene *sc = s->scene;
  nh_mesh *m = s->mesh;
  const int nn = m->n_nodes, n = 3 * nn;
  unsigned char *fixed = realloc(s->fixed, (size_t)(nn ? nn : 1));
  if (!fixed) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", nn);
  s->fixed = fixed;
  memset(s->fixed, 0, (size_t)nn);
  NH_TRY(nh_resize(&s->x, nn, 3));
  NH_TRY(nh_resize(&s->u_start, nn, 3));
  NH_TRY(nh_resize(&s->v_start, nn, 3));
  NH_TRY(nh_resize(&s->f_ext, nn, 3));
  NH_TRY(nh_resize(&s->drained, nn, 1));
  const int n_unit = sc->tissue.n_loads + sc->tissue.n_tractions;
  NH_TRY(nh_resize(&s->load_unit, nn, 3 * (n_unit ? n_unit : 1)));
  int *moved = realloc(s->moved, sizeof(int) * (size_t)(nn ? nn : 1));
  unsigned char *in = calloc((size_t)(nn ? nn : 1), 1);
  if (moved) s->moved = moved;
  if (!moved || !in) {
    free(in);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", nn);
  }
  for (int i = 0; i < nn; i++) s->moved[i] = -1;
  /* Fixed regions (docs/theory.md §5, "Fixed regions"): on a box domain the
   * nodes inside; on an immersed one a clamp of all components is a stiff
   * volumetric tie over the region's tissue, which converges to the region
   * under refinement (per-axis and prescribed regions stay node sets). */
  const int immersed = m->domain.kind != NH_DOMAIN_BOX;
  for (int r = 0; r < sc->tissue.n_fixed; r++) {
    const nh_region *reg = &sc->tissue.fixed[r];
    const nh_fix *fx = &sc->tissue.fix[r];
    if (nh_sim_fixed_is_tie(sc, immersed, r)) continue; /* tied below */
    memset(in, 0, (size_t)nn);
    int count = nh_mesh_nodes_in_region(m, reg, in);
    const int prescribed =
        fx->displacement[0] != 0.0 || fx->displacement[1] != 0.0 || fx->displacement[2] != 0.0;
    for (int i = 0; i < nn; i++) {
      if (!in[i]) continue;
      /* merge with the components fixed so far; all three: 1 */
      int mask = (s->fixed[i] == 0              ? 0
                  : (s->fixed[i] & NH_FIX_AXES) ? s->fixed[i] & 7
                                                : 7) |
                 fx->axes;
      s->fixed[i] = mask == 7 ? 1 : (unsigned char)(NH_FIX_AXES | mask);
      if (prescribed) s->moved[i] = r;
    }
    char what[256];
    nh_region_describe(reg, what, sizeof what);
    if (!(count > 0 || !first)) free(in);
    NH_CHECK(count > 0 || !first, NH_ERR_INPUT, "%s: the %s contains no node of the mesh",
             reg->where, what);
  }
  /* Hanging nodes: every node not fixed in all three components (a node
   * fixed in some axes keeps the hanging constraint on all three: its
   * masters lie on the same fixed face); the Lagrange variant's rows take
   * whole nodes: there every fixed node is left out. */
  const int lagrange = sc->adapt.hanging == NH_HANGING_LAGRANGE;
  for (int i = 0; i < nn; i++) in[i] = s->fixed[i] == 1 || (lagrange && s->fixed[i]);
  nh_hanging_destroy(&s->hanging);
  int rc_h = sc->adapt.enabled ? nh_hanging_detect(m, in, &s->hanging) : NH_OK;
  free(in);
  NH_TRY(rc_h);
  if (first) {
    nh_material mat = {sc->tissue.young, sc->tissue.poisson, sc->tissue.density,
                       sc->tissue.formulation};
    NH_TRY(nh_tissue_create(m, &mat, &s->tissue));
    if (sc->tissue.n_materials) {
      int n = sc->tissue.n_materials, *labels = malloc(sizeof(int) * (size_t)n);
      nh_material *mats = malloc(sizeof(nh_material) * (size_t)n);
      int rc = labels && mats ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: materials");
      for (int i = 0; i < n && !rc; i++) {
        const nh_label_material *lm = &sc->tissue.materials[i];
        labels[i] = lm->label;
        mats[i] = (nh_material){lm->young, lm->poisson, lm->density, sc->tissue.formulation};
      }
      if (!rc) rc = nh_tissue_set_label_materials(s->tissue, n, labels, mats);
      free(labels), free(mats);
      NH_TRY(rc);
    }
  } else {
    NH_TRY(nh_tissue_update(s->tissue));
  }
  if (immersed && sc->tissue.n_fixed > 0) {
    int nr = sc->tissue.n_fixed;
    double *k = malloc(sizeof(double) * 2 * (size_t)nr), *vol = k + nr;
    if (!k) return NH_ERROR(NH_ERR_MEMORY, "out of memory: ties");
    for (int r = 0; r < nr; r++) {
      double l = nh_region_size(&sc->tissue.fixed[r]);
      k[r] = nh_sim_fixed_is_tie(sc, immersed, r) && l > 0.0 && isfinite(l)
                 ? NH_TIE_STIFFNESS * sc->tissue.young / (l * l)
                 : 0.0;
    }
    int rc = nh_tissue_set_ties(s->tissue, nr, sc->tissue.fixed, k, vol);
    for (int r = 0; r < nr && !rc; r++)
      if (nh_sim_fixed_is_tie(sc, immersed, r) && !(vol[r] > 0.0)) {
        char what[256];
        nh_region_describe(&sc->tissue.fixed[r], what, sizeof what);
        rc = NH_ERROR(first ? NH_ERR_INPUT : NH_ERR_INTERNAL,
                      "%s: the %s holds no tissue (on an immersed domain a fixed region ties the "
                      "tissue inside it, so it needs a volume inside the shape)",
                      sc->tissue.fixed[r].where, what);
      }
    free(k);
    NH_TRY(rc);
  }
  /* The drained mass: all of it, or the part above the fluid level. */
  memcpy(s->drained, s->tissue->mass, sizeof(double) * (size_t)nn);
  if (sc->tissue.buoyant && sc->tissue.buoyancy_has_level) {
    const double *g = sc->gravity;
    double gn = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]),
           up[3] = {-g[0] / gn, -g[1] / gn, -g[2] / gn};
    memset(s->drained, 0, sizeof(double) * (size_t)nn);
    for (int l = 0; l < m->n_leaves; l++) {
      int c = m->leaves[l];
      double above = nh_mesh_cell_fraction_above(m, c, sc->tissue.buoyancy_level, up);
      double rho;
      nh_tissue_cell_material(s->tissue, c, NULL, NULL, &rho);
      double mc = rho * m->fill[c] * s->tissue->volume[s->tissue->cell_shape[c]] / 8.0 * above;
      for (int a = 0; a < 8; a++) s->drained[m->cells[8 * c + a]] += mc;
    }
  }
  memset(s->load_unit, 0, sizeof(double) * (size_t)n * (size_t)n_unit);
  for (int l = 0; l < sc->tissue.n_loads; l++)
    NH_TRY(nh_mesh_region_load(m, &sc->tissue.loads[l].region, sc->tissue.loads[l].force,
                               s->load_unit + (size_t)l * n));
  for (int l = 0; l < sc->tissue.n_tractions; l++)
    NH_TRY(nh_traction_load(m, &sc->tissue.tractions[l],
                            s->load_unit + (size_t)(sc->tissue.n_loads + l) * n, NULL));
  for (int i = 0; i < sc->n_probes + sc->n_targets; i++) {
    /* outside at creation: the scene's fault; later: ours */
    const int pr = i < sc->n_probes;
    const double *X = pr ? sc->probes[i].point : sc->targets[i - sc->n_probes].point;
    NH_CHECK(nh_mesh_locate(m, X, &s->probe_cell[i], s->probe_xi + 3 * i) == NH_OK,
             first ? NH_ERR_INPUT : NH_ERR_INTERNAL,
             "%s: the point [%g, %g, %g] lies outside the tissue%s",
             pr ? sc->probes[i].where : sc->targets[i - sc->n_probes].where, X[0], X[1], X[2],
             first ? "" : " of the refined mesh");
  }
  if (!first && s->contact) NH_TRY(nh_contact_relocate(s->contact, m));
  nh_system_destroy(&s->system);
  int rc = nh_system_create(s->tissue, s->fixed, lagrange ? NULL : s->hanging, &s->system);
  if (rc == NH_ERR_INPUT)
    return NH_ERROR(NH_ERR_INPUT, "%s: every node of the tissue is fixed: nothing to simulate",
                    sc->tissue.where_fixed);
  NH_TRY(rc);
  if (lagrange) NH_TRY(nh_system_set_hanging_rows(s->system, s->hanging));
  return NH_OK;
}

static int nh_sim_build(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (s->options.restart_dir) {
    nh_checkpoint ck;
    NH_TRY(nh_checkpoint_read(s->options.restart_dir, sc, &ck));
    s->mesh = ck.mesh;
    s->u = ck.u;
    s->v = ck.v;
    s->step = s->first_step = ck.step;
    s->time = ck.time;
    s->restore_tools = ck.tools;
    s->restore_tools_size = ck.tools_size;
    s->restore_solver = ck.solver;
    s->restore_solver_size = ck.solver_size;
  } else {
    nh_domain domain;
    NH_TRY(nh_domain_from_scene(sc, &domain));
    int rc = nh_mesh_create(&domain, sc->tissue.grid, &s->mesh);
    nh_domain_release(&domain); /* the mesh holds its own reference */
    NH_TRY(rc);
    s->u = calloc(3 * (size_t)s->mesh->n_nodes, sizeof(double));
    s->v = calloc(3 * (size_t)s->mesh->n_nodes, sizeof(double));
  }
  const int nn = s->mesh->n_nodes;
  const int n_points = sc->n_probes + sc->n_targets;
  s->probe_cell = malloc(sizeof(int) * (size_t)(n_points ? n_points : 1));
  s->probe_xi = malloc(sizeof(double) * 3 * (size_t)(n_points ? n_points : 1));
  if (!s->u || !s->v || !s->probe_cell || !s->probe_xi)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory building the model (%d nodes)", nn);
  if (sc->adapt.enabled) NH_TRY(nh_adapt_create(&sc->adapt, sc->limits.max_cells, &s->adapt));
  if (sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL) {
    double points[3 * NH_MAX_GOALS];
    s->goal_of_point = malloc(sizeof(int) * (size_t)(n_points ? n_points : 1));
    if (!s->goal_of_point) return NH_ERROR(NH_ERR_MEMORY, "out of memory: goals");
    for (int i = 0; i < n_points; i++) s->goal_of_point[i] = -1;
    for (int g = 0; g < sc->adapt.n_goals; g++) {
      int i = sc->adapt.goal[g];
      const double *X =
          i < sc->n_probes ? sc->probes[i].point : sc->targets[i - sc->n_probes].point;
      memcpy(points + 3 * g, X, 3 * sizeof(double));
      s->goal_of_point[i] = g;
    }
    NH_TRY(nh_adapt_set_goals(s->adapt, s->mesh, sc->adapt.n_goals, points));
  }
  s->max_goal_error = NAN;
  s->max_goal_point = -1;
  NH_TRY(nh_sim_setup_mesh(s, 1));
  NH_TRY(nh_sim_tools_build(s));
  s->integrator =
      (nh_integrator){.dt = sc->time.step,
                      .alpha = sc->tissue.damping_mass,
                      .beta = sc->tissue.damping_stiffness,
                      .tolerance = sc->solver.tolerance,
                      .max_iterations = sc->solver.max_iterations,
                      .threads = sc->solver.threads,
                      /* the goal estimate's duals need this step's factor */
                      .reuse = sc->solver.refactor == NH_REFACTOR_AUTO &&
                               !(sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL),
                      .time_factor = getenv("NH_TIME_FACTOR") != NULL,
                      .newton_iterations = sc->solver.newton_iterations,
                      .newton_tolerance = sc->solver.newton_tolerance,
                      .lazy_rotation = sc->solver.lazy_rotation};
  /* --restart: the factor the next step reuses, made again, and the last
   * assembly (the lazy tangents' frames: with `every` too) */
  if (s->restore_solver) {
    int rc = nh_system_reuse_load(s->system, s->restore_solver, s->restore_solver_size,
                                  s->integrator.threads);
    if (rc == NH_ERR_INPUT)
      return NH_ERROR(rc, "--restart: %s: %s", s->options.restart_dir, nh_error_message());
    NH_TRY(rc);
  }
  free(s->restore_solver);
  s->restore_solver = NULL;
  s->cap_steps = sc->time.steps > s->step ? sc->time.steps : s->step + 1;
  s->phase_times =
      calloc((size_t)NH_PHASES * (size_t)(s->cap_steps ? s->cap_steps : 1), sizeof(double));
  if (!s->phase_times) return NH_ERROR(NH_ERR_MEMORY, "out of memory: timing table");
  s->last_frame = -1;
  s->eta = s->eta_rel = NAN;
  return NH_OK;
}

/* ---- adaptivity ---- */

/* After the mesh changed: rebuild everything that depends on it, and make
 * the n_fields state fields (u, v pairs) consistent with it. */
static int nh_sim_rebuild(nh_sim *s, int n_fields, double **state) {
  NH_TRY(nh_sim_setup_mesh(s, 0));
  /* round-off (refinement) and injection (coarsening): hanging values
   * exactly their masters' interpolation */
  for (int f = 0; f < n_fields; f++) {
    nh_hanging_interpolate(s->hanging, state[f], 3);
    if (f % 2 == 1)
      for (int i = 0; i < 3 * s->mesh->n_nodes; i++)
        if (nh_fixed_component(s->fixed, i / 3, i % 3)) state[f][i] = 0.0;
  }
  return NH_OK;
}

/* Refine from this step's estimate (nh_adapt_step) and rebuild everything
 * that depends on the mesh. */
static int nh_sim_refine(nh_sim *s, double **start, int *changed) {
  double *state[4] = {s->u, s->v, start ? start[0] : NULL, start ? start[1] : NULL};
  int n_refined = 0, n_fields = start ? 4 : 2;
  int rc = nh_adapt_step(s->adapt, s->mesh, n_fields, state, &n_refined);
  s->u = state[0];
  s->v = state[1];
  if (start) start[0] = state[2], start[1] = state[3];
  if (changed) *changed = n_refined > 0;
  if (rc || n_refined == 0) return rc;
  return nh_sim_rebuild(s, n_fields, state);
}

int nh_sim_refine_cells(nh_sim *s, const int *cells, int n) {
  NH_CHECK(s->adapt, NH_ERR_INPUT, "refining cells needs an adapt section (its template)");
  double *state[2] = {s->u, s->v};
  int rc = nh_adapt_refine_cells(s->adapt, s->mesh, cells, n, 2, state);
  s->u = state[0];
  s->v = state[1];
  if (rc || n == 0) return rc;
  return nh_sim_rebuild(s, 2, state);
}

/* The outputs of step `step` failed (disk full, folder not writable): the
 * message names the step before the writer's reason (exit 1). */
static int nh_output_failed(int rc, int step) {
  char reason[1024];
  snprintf(reason, sizeof reason, "%s", nh_error_message());
  return NH_ERROR(rc, "step %d: writing the outputs failed: %s", step, reason);
}
/* The error estimate of this step's solution: SPR, or goal-oriented with the
 * step's factor (the coefficient of K in A: 1 static, hβ + h² dynamic). */
static int nh_sim_estimate(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (sc->adapt.estimator != NH_ESTIMATOR_GOAL)
    return nh_adapt_estimate(s->adapt, s->mesh, s->tissue, s->u, s->hanging, &s->eta, &s->eta_rel);
  const double h = sc->time.step;
  double scale = sc->time.mode == NH_MODE_STATIC ? 1.0 : h * sc->tissue.damping_stiffness + h * h;
  return nh_adapt_estimate_goal(s->adapt, s->system, scale, s->mesh, s->tissue, s->u, s->hanging,
                                &s->eta, &s->eta_rel);
}

/* Static mode: a step that does not converge is solved again from its
 * start in 2, 4, … up to 2^NH_STATIC_SPLITS equal load steps (pseudo-time
 * sub-steps: loads, prescribed displacements and the tools' travel at
 * their intermediate values, the constraints' states moved on at each). */
#define NH_STATIC_SPLITS 4

/* The quasi-static step t_new − h → t_new (docs/theory.md §3, "Quasi-static
 * Newton"; docs/interaction.md, "Quasi-static mode" with tools or a skull). */
static int nh_sim_solve_static(nh_sim *s, double t_new, nh_step_stats *st) {
  const double t_old = t_new - s->scene->time.step;
  for (int depth = 0;; depth++) {
    const int parts = 1 << depth;
    nh_integrator in = s->integrator;
    in.dt = (t_new - t_old) / parts;
    nh_step_stats sum = {0}, one = {0};
    int rc = NH_OK;
    for (int k = 1; k <= parts && !rc; k++) {
      double t = k == parts ? t_new : t_old + (t_new - t_old) * k / parts;
      nh_sim_prescribe(s, t);
      nh_sim_external_force(s, t, s->f_ext);
      rc = s->contact ? nh_contact_solve_static(s->contact, s->system, &in, s->mesh, s->f_ext, s->u,
                                                s->v, t, &one)
                      : nh_solve_static(s->system, &in, s->f_ext, s->u, &one);
      sum.t_assemble += one.t_assemble, sum.t_factor += one.t_factor;
      sum.t_solve += one.t_solve, sum.t_constraints += one.t_constraints;
      sum.iterations += one.iterations, sum.factorised += one.factorised;
      sum.residual = one.residual;
    }
    sum.t_factor_reference = sum.factorised > 0 ? sum.t_factor / sum.factorised : 0.0;
    *st = sum;
    if (rc != NH_ERR_NUMERIC || depth == NH_STATIC_SPLITS) return rc;
    /* back to the step's start, and again in twice as many load steps */
    char why[512];
    snprintf(why, sizeof why, "%s", nh_error_message());
    nh_error_clear();
    memcpy(s->u, s->u_start, sizeof(double) * 3 * (size_t)s->mesh->n_nodes);
    if (s->contact) NH_TRY(nh_contact_state_load(s->contact, s->tools_start, s->tools_start_size));
    nh_log_info("step %d (t = %g s): %s; solving it again in %d load steps", s->step + 1, t_new,
                why, 2 * parts);
  }
}

/* The step's solve (dynamic, static or with tools) at time t_new. */
static int nh_sim_solve(nh_sim *s, double t_new, nh_step_stats *st) {
  const nh_scene *sc = s->scene;
  if (sc->time.mode == NH_MODE_STATIC) return nh_sim_solve_static(s, t_new, st);
  nh_sim_external_force(s, t_new, s->f_ext);
  return s->contact ? nh_contact_step(s->contact, s->system, &s->integrator, s->mesh, s->f_ext,
                                      s->u, s->v, t_new, st)
                    : nh_step_dynamic(s->system, &s->integrator, s->f_ext, s->u, s->v, st);
}

/* adapt.resolve: while a goal estimate exceeds the tolerance (or, without
 * tolerance, up to N times), refine and solve the step again from its start
 * state carried to the new mesh (Eq. 17) and the tools' start state, so the
 * step's written solution is on the mesh its estimate asked for. Times add
 * up in *st. */
static int nh_sim_resolve(nh_sim *s, double t_new, double *const start_in[2], nh_step_stats *st,
                          int *resolves) {
  const nh_scene *sc = s->scene;
  const int n = 3 * s->mesh->n_nodes;
  double *start[2] = {malloc(sizeof(double) * n), malloc(sizeof(double) * n)};
  int rc = start[0] && start[1] ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: re-solve");
  if (!rc)
    memcpy(start[0], start_in[0], sizeof(double) * n),
        memcpy(start[1], start_in[1], sizeof(double) * n);
  for (int r = 0; r < sc->adapt.resolve && !rc; r++) {
    int changed = 0;
    if ((rc = nh_sim_refine(s, start, &changed)) || !changed) break;
    memcpy(s->u, start[0], sizeof(double) * 3 * s->mesh->n_nodes);
    memcpy(s->v, start[1], sizeof(double) * 3 * s->mesh->n_nodes);
    /* a stop inside the re-solve restores the start state on this mesh */
    memcpy(s->u_start, start[0], sizeof(double) * 3 * s->mesh->n_nodes);
    memcpy(s->v_start, start[1], sizeof(double) * 3 * s->mesh->n_nodes);
    if (s->contact) { /* the tools' start state, its embedded points on this mesh */
      if ((rc = nh_contact_state_load(s->contact, s->tools_start, s->tools_start_size)) ||
          (rc = nh_contact_relocate(s->contact, s->mesh)))
        break;
      free(s->tools_start);
      s->tools_start = NULL;
      if ((rc = nh_contact_state_save(s->contact, &s->tools_start, &s->tools_start_size))) break;
    }
    nh_step_stats again = {0};
    if ((rc = nh_sim_solve(s, t_new, &again)) || (rc = nh_sim_estimate(s))) break;
    st->t_assemble += again.t_assemble, st->t_factor += again.t_factor;
    st->t_solve += again.t_solve, st->t_constraints += again.t_constraints;
    st->iterations = again.iterations, st->residual = again.residual;
    (*resolves)++;
  }
  free(start[0]), free(start[1]);
  return rc;
}

int nh_sim_create(const nh_scene *scene, const nh_sim_options *options, nh_sim **out) {
  *out = NULL;
  nh_sim *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  s->scene = scene;
  if (options) s->options = *options;
  int rc = nh_sim_build(s);
  if (!rc && !s->options.dry_run && (rc = nh_open_outputs(s)) == NH_ERR_IO)
    rc = nh_output_failed(rc, s->step);
  if (rc) {
    nh_sim_destroy(&s);
    return rc;
  }
  *out = s;
  return NH_OK;
}

/* ---- stepping ---- */

#define NH_TRY_OUTPUT(expr, step)                                                                  \
  do {                                                                                             \
    int nh_out_rc_ = (expr);                                                                       \
    if (nh_out_rc_) return nh_output_failed(nh_out_rc_, (step));                                   \
  } while (0)

int nh_sim_step(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (s->step >= s->cap_steps) {
    int cap = 2 * s->cap_steps + 16;
    double *pt = realloc(s->phase_times, sizeof(double) * NH_PHASES * (size_t)cap);
    if (!pt) return NH_ERROR(NH_ERR_MEMORY, "out of memory: timing table");
    s->phase_times = pt;
    s->cap_steps = cap;
  }
  double t0 = nh_time_now();
  double t_new = (s->step + 1) * sc->time.step;
  nh_sim_prescribe(s, t_new); /* (the loads at t_new: nh_sim_solve) */
  nh_step_stats st = {0};
  memcpy(s->u_start, s->u, sizeof(double) * 3 * (size_t)s->mesh->n_nodes);
  memcpy(s->v_start, s->v, sizeof(double) * 3 * (size_t)s->mesh->n_nodes);
  if (s->contact) { /* a few kB: beams and channels, for a stop inside the step */
    free(s->tools_start);
    s->tools_start = NULL;
    NH_TRY(nh_contact_state_save(s->contact, &s->tools_start, &s->tools_start_size));
  }
  if (s->integrator.reuse) { /* the step may renew the factor before a stop inside it */
    s->solver_start.len = 0;
    nh_system_reuse_save(s->system, &s->solver_start);
    if (s->solver_start.failed)
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: step %d start state", s->step + 1);
  }
  int adapt_now = sc->adapt.enabled && (s->step + 1) % sc->adapt.every == 0;
  int resolve = adapt_now && sc->adapt.resolve > 0;
  double *start[2] = {NULL, NULL}; /* the step's start state, for re-solves */
  if (resolve) {
    const size_t n = 3 * (size_t)s->mesh->n_nodes;
    start[0] = malloc(sizeof(double) * n), start[1] = malloc(sizeof(double) * n);
    if (!start[0] || !start[1]) {
      free(start[0]), free(start[1]);
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: step %d start state", s->step + 1);
    }
    memcpy(start[0], s->u, sizeof(double) * n), memcpy(start[1], s->v, sizeof(double) * n);
  }
  int rc = nh_sim_solve(s, t_new, &st);
  /* A stop that cut the residual's assembly short left u and v updated but
   * the step's residual unknown (NaN): the step is not complete, and goes
   * back to its start like one stopped earlier, so that a continued run
   * computes it again and reports what the uninterrupted run reports. */
  if (!rc && isnan(st.residual) && nh_stop_requested()) rc = nh_stop_check();
  if (!rc && (rc = nh_sim_guard(s, s->u_start))) { /* its message names the step */
    free(start[0]), free(start[1]);
    return rc;
  }
  adapt_now = adapt_now && !rc;
  double ta = nh_time_now();
  s->eta = s->eta_rel = NAN; /* nan in steps.csv: not estimated at this step */
  if (adapt_now) rc = nh_sim_estimate(s);
  int resolves = 0;
  if (!rc && resolve) {
    double t_solves = st.t_assemble + st.t_factor + st.t_solve + st.t_constraints;
    rc = nh_sim_resolve(s, t_new, start, &st, &resolves);
    ta += st.t_assemble + st.t_factor + st.t_solve + st.t_constraints - t_solves;
  }
  free(start[0]), free(start[1]);
  double t_estimate = nh_time_now() - ta;
  if (rc) {
    char reason[1024];
    snprintf(reason, sizeof reason, "%s", nh_error_message());
    return NH_ERROR(rc, "step %d (t = %g s): %s", s->step + 1, t_new, reason);
  }
  s->step++;
  s->time = t_new;
  /* Counts of the mesh the step was solved on (before any refinement). */
  const nh_mesh *m = s->mesh;
  int dofs = 3 * m->n_nodes, free_dofs = nh_system_free_dofs(s->system), cells = m->n_leaves;
  int hanging = s->hanging ? s->hanging->n_hanging : 0;
  nh_contact_stats cc = {0}; /* all zero without tools */
  if (s->contact) nh_contact_stats_get(s->contact, &cc);
  const nh_coupled_stats *cs = &cc.solve;
  int rows = nh_system_constraint_rows(s->system) + cc.rows;
  /* f_ext · u: at a static equilibrium of a linear problem, the energy norm
   * squared of the solution (‖u_h‖²_E = f·u_h), which the adaptivity study
   * uses: for conforming Galerkin solutions ‖u − u_h‖²_E = ‖u‖²_E − ‖u_h‖²_E. */
  double work = 0.0;
  for (int i = 0; i < dofs; i++) work += s->f_ext[i] * s->u[i];
  double t1 = nh_time_now();
  if (!s->options.dry_run) {
    int due =
        (sc->output.every > 0 && s->step % sc->output.every == 0) || s->step == sc->time.steps;
    NH_TRY_OUTPUT(nh_write_probe_rows(s), s->step);
    if (due && s->last_frame != s->step) NH_TRY_OUTPUT(nh_write_frame(s), s->step);
  }
  double t2 = nh_time_now();
  /* A failed refinement still leaves this step's row (written below). */
  /* The estimate of the written solution (before it is refined away). */
  double goal_max = NAN;
  for (int i = 0; s->goal_of_point && i < sc->n_probes + sc->n_targets; i++) {
    double e = nh_sim_point_error(s, i);
    if (e == e && !(e <= goal_max)) goal_max = e;
    if (e == e && !(e <= s->max_goal_error) && (i >= sc->n_probes || sc->n_targets == 0))
      s->max_goal_error = e, s->max_goal_point = i;
  }
  int refine_rc = adapt_now && s->step < sc->time.steps ? nh_sim_refine(s, NULL, NULL) : NH_OK;
  /* What ended this step's last refinement (the last step refines only in
   * its re-solves). */
  double refine_stop = adapt_now && (s->step < sc->time.steps || resolve)
                           ? (double)nh_adapt_last_stop(s->adapt)
                           : NAN;
  char refine_reason[1024] = "";
  if (refine_rc) snprintf(refine_reason, sizeof refine_reason, "%s", nh_error_message());
  double t3 = nh_time_now();
  s->t_adapt = t_estimate + (t3 - t2);
  /* A checkpoint holds the state the next step starts from: after refinement. */
  if (!refine_rc && !s->options.dry_run && sc->output.checkpoint > 0 &&
      s->step % sc->output.checkpoint == 0)
    NH_TRY_OUTPUT(nh_checkpoint_write(s), s->step);
  double t_checkpoint = nh_time_now() - t3; /* counted as output */
  t3 += t_checkpoint;
  double *pt = s->phase_times + NH_PHASES * (size_t)(s->step - 1);
  pt[NH_PHASE_ASSEMBLE] = st.t_assemble;
  pt[NH_PHASE_FACTOR] = st.t_factor;
  pt[NH_PHASE_SOLVE] = st.t_solve;
  pt[NH_PHASE_CONSTRAINTS] = st.t_constraints;
  pt[NH_PHASE_ADAPT] = s->t_adapt;
  pt[NH_PHASE_OUTPUT] = t2 - t1 + t_checkpoint;
  pt[NH_PHASE_STEP] = t3 - t0 - st.t_aside;
  const double row[] = {s->step,
                        s->time,
                        dofs,
                        free_dofs,
                        cells,
                        hanging,
                        rows,
                        s->eta,
                        s->eta_rel,
                        st.iterations,
                        st.residual,
                        st.t_assemble,
                        st.t_factor,
                        st.t_solve,
                        st.t_constraints,
                        s->t_adapt,
                        pt[NH_PHASE_OUTPUT],
                        pt[NH_PHASE_STEP],
                        work,
                        cs->mcp.iterations,
                        cs->mcp.residual,
                        cs->mcp.n_stick,
                        cs->mcp.n_slide,
                        cc.cut,
                        cc.path_points,
                        cs->t_compliance,
                        cs->t_mcp,
                        st.factorised,
                        st.pcg_iterations,
                        st.corrections,
                        st.t_factor_reference,
                        s->inverted,
                        goal_max,
                        refine_stop,
                        resolves,
                        st.tangent_updates,
                        cc.skull_contacts,
                        cc.skull_force[0],
                        cc.skull_force[1],
                        cc.skull_force[2]};
  enum { NH_STEP_COLUMNS = sizeof nh_step_columns / sizeof *nh_step_columns };
  _Static_assert(sizeof row / sizeof *row == NH_STEP_COLUMNS, "one value per steps.csv column");
  if (!s->options.dry_run)
    NH_TRY_OUTPUT(nh_csv_values(s->steps_csv, NH_STEP_COLUMNS, row), s->step);
  if (s->h5) {
    NH_TRY_OUTPUT(nh_h5_append_steps(s->h5, row), s->step);
    /* The checkpoint of this step is on disk: so must be its rows. */
    if (!refine_rc && !s->options.dry_run && sc->output.checkpoint > 0 &&
        s->step % sc->output.checkpoint == 0)
      NH_TRY_OUTPUT(nh_h5_flush(s->h5), s->step);
  }
  /* The scene was validated at creation: nothing refinement meets later is
   * the scene's fault (exit 1, not 2). */
  if (refine_rc)
    return NH_ERROR(refine_rc == NH_ERR_INPUT ? NH_ERR_INTERNAL : refine_rc,
                    "step %d (t = %g s): refinement: %s", s->step, t_new, refine_reason);
  return NH_OK;
}

void nh_sim_request_stop(int signal_number) {
  nh_stop_request(signal_number);
}

int nh_sim_run(nh_sim *s) {
  if (s->options.progress) nh_progress_start(s);
  int rc = NH_OK;
  while (s->step < s->scene->time.steps) {
    /* A step interrupted inside (nh_stop_check in its long loops) left the
     * state of the last complete step: u is restored, v not yet updated. */
    int during = 0;
    if ((rc = nh_sim_step(s))) {
      if (rc != NH_ERR_INTERRUPTED || !nh_stop_requested()) break;
      memcpy(s->u, s->u_start, sizeof(double) * 3 * (size_t)s->mesh->n_nodes);
      memcpy(s->v, s->v_start, sizeof(double) * 3 * (size_t)s->mesh->n_nodes);
      if (s->contact &&
          (rc = nh_contact_state_load(s->contact, s->tools_start, s->tools_start_size)))
        break;
      nh_error_clear();
      rc = NH_OK;
      during = 1;
      s->solver_past = 1;
    }
    if (s->options.progress && !during) nh_progress_update(s);
    if (nh_stop_requested() && s->step < s->scene->time.steps) {
      if (!s->options.dry_run) {
        if (s->last_frame != s->step && (rc = nh_write_frame(s))) break;
        if ((rc = nh_checkpoint_write(s))) break;
      }
      char when[64];
      if (during)
        snprintf(when, sizeof when, "during step %d, after", s->step + 1);
      else
        snprintf(when, sizeof when, "after");
      /* The scene as run (overrides applied) is DIR/scene.yaml: the command
       * continues exactly this run, whatever --set made it. */
      rc = NH_ERROR(NH_ERR_INTERRUPTED,
                    "stopped by signal %d %s step %d of %d (t = %g s); the last frame and a "
                    "checkpoint are in %s; continue with: needlehex run %s/scene.yaml --restart %s",
                    nh_stop_requested(), when, s->step, s->scene->time.steps, s->time,
                    s->scene->output.dir, s->scene->output.dir, s->scene->output.dir);
      break;
    }
  }
  /* results.h5 holds the rows since its last frame in memory: writing them
   * is an output like any other, and can fail like any other. */
  if (!rc && s->h5 && (rc = nh_h5_close(&s->h5))) rc = nh_output_failed(rc, s->step);
  if (s->options.progress) nh_progress_finish(s);
  return rc;
}
