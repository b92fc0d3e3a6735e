/* sim.c — the step loop (docs/theory.md; docs/interaction.md for the tools).
 *
 * One step (nh_sim_step) is a sequence of phases, each a function
 * (docs/design.md, "One step"):
 *   predict (nh_sim_predict): the prescribed motion at the new time, and
 *     the step's start state saved (for a stop inside it, and re-solves);
 *   solve (nh_sim_solve): external forces at the new time (loads by their
 *     schedules, gravity), then a backward-Euler step (dynamic; with tools
 *     the contact module's coupled step) or a Newton solve to equilibrium
 *     under the loads of that pseudo-time (static);
 *   guards (nh_sim_guard, guard.c): nothing implausible is written;
 *   estimate (nh_sim_estimate_step): with `adapt`, the error of that
 *     solution (SPR, or goal-oriented), and the re-solves (below);
 *   output of the solution (nh_sim_write_solution): rows of probes.csv
 *     and of the tools, and a frame when due, so a frame shows a solution on
 *     the mesh it was computed on, with its error indicators;
 *   adapt (nh_sim_adapt_mesh): adapt marks and refines cells and carries
 *     the state to the new nodes (nh_adapt_step, Eq. 17), setup.c rebuilds
 *     what depends on the mesh, and the next step continues on the new mesh;
 *   output of the step: a checkpoint when due (the state the next step
 *     starts from), the step's times and its row of steps.csv
 *     (nh_sim_write_row).
 * Every phase is timed and the times are kept per step for the summary.
 * The initial state is frame 0, so a time series always starts at rest.
 *
 * With adapt.resolve (estimator goal) the step is refined and solved again
 * from its start state, carried to the new mesh, up to N times before its
 * rows are written (nh_sim_resolve), so the written solution is on the mesh
 * its estimate asked for. The tools' start state (saved at the start of
 * every step) is restored too, its embedded points relocated on the new
 * mesh (they are material points); the skull's warm starts and its choice
 * of candidate rows are those after the first solve. */
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
                                              "skull_fz",
                                              "constraint_newton",
                                              "constraint_sweeps",
                                              "constraint_method",
                                              "splits",
                                              "unsolved",
                                              "t_tools",
                                              "t_guard"};
static const char *const nh_probe_columns[] = {"step", "time", "name", "x",  "y",
                                               "z",    "ux",   "uy",   "uz", "error_estimate"};

/* probes.csv has error_estimate under estimator goal only. */
static int nh_probe_column_count(const nh_scene *sc) {
  return sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL ? 10 : 9;
}

void nh_sim_destroy(nh_sim **sim) {
  if (!sim || !*sim) return;
  nh_sim *s = *sim;
  nh_sim_tools_destroy(s);
  nh_sim_patient_close(s);
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
  free(s->restore_adapt);
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
 * fixed components at time t, less lag times their values at t_old (a load
 * step from rest, nh_sim_solve_static; else lag = 0), set in u before the
 * step solves: the step keeps fixed DOFs at their values (docs/theory.md §5). */
static void nh_sim_prescribe(nh_sim *s, double t, double lag, double t_old) {
  const nh_scene *sc = s->scene;
  for (int i = 0; i < s->mesh->n_nodes; i++) {
    if (s->moved[i] < 0) continue;
    const nh_fix *fx = &sc->tissue.fix[s->moved[i]];
    double factor = nh_schedule_eval(&fx->schedule, t);
    if (lag != 0.0) factor -= lag * nh_schedule_eval(&fx->schedule, t_old);
    for (int k = 0; k < 3; k++)
      if (nh_fixed_component(s->fixed, i, k)) s->u[3 * i + k] = factor * fx->displacement[k];
  }
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

void nh_sim_median_times(const nh_sim *s, double t[NH_SIM_PHASES]) {
  for (int p = 0; p < NH_PHASES; p++) t[p] = 0.0;
  const int first = s->first_step, n = s->step - first; /* steps this process timed */
  if (n <= 0) return;
  double *buf = nh_calloc((size_t)n, sizeof(double));
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
    cell[2 * nc + l] = nh_tissue_fraction(s->tissue, c);
    cell[3 * nc + l] = eta ? eta[c] : 0.0;
    double lambda, mu; /* the cell's Young's modulus (mixed cells: from the averaged λ, μ) */
    nh_tissue_cell_material(s->tissue, c, &lambda, &mu, NULL);
    cell[4 * nc + l] = mu * (3 * lambda + 2 * mu) / (lambda + mu);
  }
  if (!rc && s->hanging)
    for (int k = 0; k < s->hanging->n_hanging; k++)
      hang[s->hanging->node[k]] = s->hanging->aggregated[k] ? 2.0 : 1.0;
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
    const char **names = nh_calloc((size_t)sc->n_probes, sizeof(char *));
    double *vals = nh_calloc(6 * (size_t)sc->n_probes, sizeof(double));
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
static int nh_is_run_output(const nh_scene *sc, const char *name) {
  static const char *const fixed[] = {
      "scene.yaml", "steps.csv",    "probes.csv",     "targets.csv",      "tools.csv",
      "results.h5", "results.xdmf", "checkpoint.nhc", "targets.mrk.json", "tissue_mask.nii.gz",
      NULL};
  for (int i = 0; fixed[i]; i++)
    if (!strcmp(name, fixed[i])) return 1;
  size_t n = strlen(name);
  for (int k = 0; k < sc->n_tools; k++) /* <tool>.mrk.json */
    if (n == strlen(sc->tools[k].name) + 9 && !strncmp(name, sc->tools[k].name, n - 9) &&
        !strcmp(name + n - 9, ".mrk.json"))
      return 1;
  if (!strncmp(name, "results.h5.damaged", 18)) return 1;
  if (n > 4 && (!strcmp(name + n - 4, ".pvd") || !strcmp(name + n - 4, ".tmp"))) return 1;
  /* PREFIX_NNNNNN.vtu, results_NNNNNN.h5, displacement_ and warped_NNNNNN.nii.gz */
  const char *us = strrchr(name, '_');
  if (!us || us == name) return 0;
  size_t d = strspn(us + 1, "0123456789");
  const char *ext = us + 1 + d;
  return d >= 6 &&
         (!strcmp(ext, ".vtu") || (!strcmp(ext, ".h5") && !strncmp(name, "results_", 8)) ||
          (!strcmp(ext, ".nii.gz") &&
           (!strncmp(name, "displacement_", 13) || !strncmp(name, "warped_", 7))));
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
    if (!nh_is_run_output(s->scene, e->d_name)) continue;
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
  char *text;
  NH_TRY(nh_scene_text_absolute(sc, &text));
  int rc = nh_write_text(path, text);
  free(text);
  NH_TRY(rc);
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
    s->restore_adapt = ck.adapt;
    s->restore_adapt_size = ck.adapt_size;
  } else {
    nh_domain domain;
    NH_TRY(nh_domain_from_scene(sc, &domain));
    int rc = nh_mesh_create(&domain, sc->tissue.grid, &s->mesh);
    nh_domain_release(&domain); /* the mesh holds its own reference */
    NH_TRY(rc);
    NH_TRY(nh_sim_refine_fixed(s));
    s->u = nh_calloc(3 * (size_t)s->mesh->n_nodes, sizeof(double));
    s->v = nh_calloc(3 * (size_t)s->mesh->n_nodes, sizeof(double));
  }
  const int nn = s->mesh->n_nodes;
  const int n_points = sc->n_probes + sc->n_targets;
  s->probe_cell = nh_calloc((size_t)(n_points ? n_points : 1), sizeof(int));
  s->probe_xi = nh_calloc(3 * (size_t)(n_points ? n_points : 1), sizeof(double));
  if (!s->u || !s->v || !s->probe_cell || !s->probe_xi)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory building the model (%d nodes)", nn);
  if (sc->adapt.enabled) {
    NH_TRY(nh_adapt_create(&sc->adapt, sc->limits.max_cells, &s->adapt));
    nh_adapt_keep_regions(s->adapt, sc->tissue.n_fixed, sc->tissue.fixed, sc->tissue.fix);
  }
  if (sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL) {
    double points[3 * NH_MAX_GOALS];
    s->goal_of_point = nh_calloc((size_t)(n_points ? n_points : 1), sizeof(int));
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
  if (s->restore_adapt) { /* --restart: the goal estimate's carried state */
    int rc = nh_adapt_state_load(s->adapt, s->restore_adapt, s->restore_adapt_size);
    free(s->restore_adapt);
    s->restore_adapt = NULL;
    if (rc == NH_ERR_INPUT)
      return NH_ERROR(rc, "--restart: %s: %s", s->options.restart_dir, nh_error_message());
    NH_TRY(rc);
  }
  s->max_goal_error = NAN;
  s->max_goal_point = -1;
  NH_TRY(nh_sim_setup_mesh(s, 1));
  NH_TRY(nh_sim_tools_build(s));
  NH_TRY(nh_sim_patient_open(s));
  s->integrator = (nh_integrator){
      .dt = sc->time.step,
      .alpha = sc->tissue.damping_mass,
      .beta = sc->tissue.damping_stiffness,
      .tolerance = sc->solver.tolerance,
      .max_iterations = sc->solver.max_iterations,
      .threads = sc->solver.threads,
      /* the goal estimate's duals take the reused factor too (nh_system_solve_rows) */
      .reuse = sc->solver.refactor == NH_REFACTOR_AUTO,
      .time_factor = getenv("NH_TIME_FACTOR") != NULL,
      /* without solver.newton: only unsolved steps iterate */
      .newton_iterations = sc->solver.newton_given ? sc->solver.newton_iterations : -1,
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
  /* rows for the first steps; nh_sim_timing_reserve grows the table, so a
   * scene of 1e7 steps does not reserve its whole table up front */
  s->cap_steps = sc->time.steps < 4096 ? sc->time.steps : 4096;
  if (s->cap_steps <= s->step) s->cap_steps = s->step + 1;
  s->phase_times = nh_calloc((size_t)NH_PHASES * (size_t)s->cap_steps, sizeof(double));
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
/* The constraint-data term's linearised change of the rows (dwr.c, "Constraint data"). */
static int nh_sim_rows_linear(void *ctx, int n, const double *w, double *out) {
  nh_sim *s = ctx;
  return nh_contact_data_change(s->contact, s->mesh, s->u, n, w, NULL, out);
}

/* The memory term's links at most (adapt/dwr_memory.c): on dbs.yaml's
 * shift 16 links give the estimates of 32 and 64 to 1 % (docs/dbs.md, "The
 * dynamic steps' memory"), although the links' dual energy has not fallen
 * to 1 % of the goal's by then: the later links are smooth, and their own
 * errors small */
#define NH_MEMORY_MAX_LINKS 16

/* The error estimate of this step's solution: SPR, or goal-oriented with the
 * step's factor (the coefficient of K in A: 1 static, hβ + h² dynamic). */
static int nh_sim_estimate(nh_sim *s) {
  const nh_scene *sc = s->scene;
  /* SPR: with the frames of the step's last assembly, if it was at u */
  if (sc->adapt.estimator != NH_ESTIMATOR_GOAL)
    return nh_adapt_estimate(s->adapt, s->mesh, s->tissue, s->u, s->hanging,
                             nh_system_frames_at(s->system, s->tissue, s->u), &s->eta, &s->eta_rel);
  const double h = sc->time.step;
  double scale = sc->time.mode == NH_MODE_STATIC ? 1.0 : h * sc->tissue.damping_stiffness + h * h;
  /* the geometry term's loads at this step (docs/theory.md §6.6, "Geometry") */
  const int nt = sc->tissue.n_tractions;
  nh_geometry_loads loads = {.n_tractions = nt, .tractions = sc->tissue.tractions};
  nh_scene_tissue_gravity(sc, s->time, loads.body);
  double *buf = nh_calloc((size_t)nt + 1, sizeof(double)), plane[6];
  if (!buf) return NH_ERROR(NH_ERR_MEMORY, "out of memory: goal estimate loads");
  for (int q = 0; q < nt; q++)
    buf[q] = nh_schedule_eval(&sc->tissue.tractions[q].schedule, s->time);
  loads.traction_factor = buf;
  if (nh_sim_drainage_plane(sc, plane)) loads.plane = plane; /* the drained mass's */
  nh_adapt_set_geometry_loads(s->adapt, &loads);
  /* the constraint-data term: the rows one level finer (§6.6, "Constraint data") */
  const nh_rows *rows = nh_contact_rows(s->contact);
  const int rm = rows ? rows->m : 0;
  double *dc = rm > 0 ? nh_calloc(2 * (size_t)rm, sizeof(double)) : NULL;
  int rc = rm > 0 && !dc ? NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint data") : NH_OK;
  nh_constraint_data data = {
      .change = dc, .force = dc ? dc + rm : NULL, .linear = nh_sim_rows_linear, .ctx = s};
  if (!rc && dc) {
    /* the rows' forces: impulses per τ (h, or 1 quasi-static) */
    const double tau = sc->time.mode == NH_MODE_STATIC ? 1.0 : h;
    for (int i = 0; i < rm; i++) dc[rm + i] = rows->lambda[i] / tau;
    rc = nh_contact_data_change(s->contact, s->mesh, s->u, 0, NULL, dc, NULL);
  }
  nh_adapt_set_constraint_data(s->adapt, dc ? &data : NULL);
  /* the anchoring error of the fronts whose tip cut in this step (§6.6,
   * "Anchoring"): the goal estimate of their tip discs' mean displacement,
   * in the same pass (adapt/dwr_front.c), kept by the contact module
   * (anchor.c) for the constraint-data term of the later steps; every
   * front's estimate sees the anchors' errors as the step found them */
  int front_row[8];
  double front_error[8][3];
  /* and the axial error of the shaft points that stick with none estimated
   * since they last slid (dwr_front.c, "Shaft points"), kept as their axial
   * rows' data change until they slide */
  const int n_points = nh_contact_stuck_points(s->contact, NULL, 0);
  int *point_row = nh_calloc((size_t)n_points + 1, sizeof(int));
  double *point_error = nh_calloc((size_t)n_points + 1, sizeof(double));
  if (!rc && (!point_row || !point_error))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: %d shaft points", n_points);
  nh_dwr_fronts fronts = {nh_contact_fronts(s->contact, front_row, 8),
                          front_row,
                          front_error[0],
                          rc ? 0 : nh_contact_stuck_points(s->contact, point_row, n_points),
                          point_row,
                          point_error};
  nh_adapt_set_fronts(s->adapt, fronts.n || fronts.n_points ? &fronts : NULL);
  /* the dynamic step's memory of the earlier steps' errors (adapt/dwr_memory.c) */
  const nh_dwr_memory memory = {.h = h,
                                .alpha = sc->tissue.damping_mass,
                                .beta = sc->tissue.damping_stiffness,
                                .mass = s->tissue->mass,
                                .max_links = NH_MEMORY_MAX_LINKS};
  const int dynamic = sc->time.mode != NH_MODE_STATIC;
  nh_adapt_set_memory(s->adapt, sc->adapt.memory && dynamic ? &memory : NULL, s->step + 1);
  if (!rc)
    rc = nh_adapt_estimate_goal(s->adapt, s->system, rows, scale, s->mesh, s->tissue, s->u,
                                s->hanging, &s->eta, &s->eta_rel);
  for (int i = 0; i < fronts.n && !rc; i++)
    rc = nh_contact_set_front_error(s->contact, s->mesh, s->u, front_row[i], front_error[i]);
  for (int i = 0; i < fronts.n_points && !rc; i++)
    nh_contact_set_point_error(s->contact, point_row[i], point_error[i]);
  nh_adapt_set_geometry_loads(s->adapt, NULL);
  nh_adapt_set_constraint_data(s->adapt, NULL);
  nh_adapt_set_fronts(s->adapt, NULL);
  free(buf), free(dc), free(point_row), free(point_error);
  return rc;
}

/* Static mode: a step that does not converge is solved again from its
 * start in 2, 4, … up to 2^NH_STATIC_SPLITS equal load steps (pseudo-time
 * sub-steps: loads, prescribed displacements and the tools' travel at
 * their intermediate values, the constraints' states moved on at each).
 * A later step starts in equilibrium with the loads at its start time; the
 * first starts from rest, which carries none, so its k-th of n load steps
 * takes the loads and prescribed displacements at its pseudo-time less
 * (1 − k/n) times those at the step's start: a constant load (the default
 * schedule) is ramped, where equal pseudo-times would repeat the step. */
#define NH_STATIC_SPLITS 4

/* The quasi-static step t_new − h → t_new (docs/theory.md §3, "Quasi-static
 * Newton"; docs/interaction.md, "Quasi-static mode" with tools or a skull). */
static int nh_sim_solve_static(nh_sim *s, double t_new, nh_step_stats *st) {
  const double t_old = t_new - s->scene->time.step;
  const int n = 3 * s->mesh->n_nodes, from_rest = s->step == 0;
  double *f_old = NULL; /* the first step's loads at t_old, once it is split */
  int rc = NH_OK;
  for (int depth = 0;; depth++) {
    const int parts = 1 << depth;
    nh_integrator in = s->integrator;
    in.dt = (t_new - t_old) / parts;
    nh_step_stats sum = {0}, one = {0};
    if (from_rest && parts > 1 && !f_old) {
      if (!(f_old = nh_calloc((size_t)n, sizeof(double)))) {
        rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the loads of a split step");
        break;
      }
      nh_sim_external_force(s, t_old, f_old);
    }
    for (int k = 1; k <= parts && !rc; k++) {
      double t = k == parts ? t_new : t_old + (t_new - t_old) * k / parts;
      const double lag = from_rest ? 1.0 - (double)k / parts : 0.0;
      nh_sim_prescribe(s, t, lag, t_old);
      nh_sim_external_force(s, t, s->f_ext);
      if (lag > 0.0)
        for (int i = 0; i < n; i++) s->f_ext[i] -= lag * f_old[i];
      rc = s->contact ? nh_contact_solve_static(s->contact, s->system, &in, s->mesh, s->f_ext, s->u,
                                                s->v, t, &one)
                      : nh_solve_static(s->system, &in, s->f_ext, s->u, &one);
      sum.t_assemble += one.t_assemble, sum.t_factor += one.t_factor;
      sum.t_solve += one.t_solve, sum.t_constraints += one.t_constraints;
      sum.iterations += one.iterations, sum.factorised += one.factorised;
      sum.pcg_iterations += one.pcg_iterations, sum.corrections += one.corrections;
      sum.tangent_updates += one.tangent_updates;
      sum.residual = one.residual;
    }
    sum.t_factor_reference = sum.factorised > 0 ? sum.t_factor / sum.factorised : 0.0;
    sum.load_steps = parts;
    *st = sum;
    if (rc != NH_ERR_NUMERIC || depth == NH_STATIC_SPLITS || one.diagnosed) break;
    /* back to the step's start, and again in twice as many load steps */
    char why[2048];
    snprintf(why, sizeof why, "%s", nh_error_message());
    nh_error_clear();
    rc = NH_OK;
    memcpy(s->u, s->u_start, sizeof(double) * (size_t)n);
    if (s->contact && (rc = nh_contact_state_load(s->contact, s->tools_start, s->tools_start_size)))
      break;
    nh_log_info("step %d (t = %g s): %s; solving it again in %d load steps", s->step + 1, t_new,
                why, 2 * parts);
  }
  free(f_old);
  return rc;
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

/* adapt.resolve_tip applies: estimator goal and tools. */
static int nh_sim_resolves_tip(const nh_sim *s) {
  const nh_scene *sc = s->scene;
  return sc->adapt.estimator == NH_ESTIMATOR_GOAL && sc->adapt.resolve_tip && s->contact &&
         sc->n_tools > 0;
}

/* How many tools have punctured the tissue (punctured, cutting or
 * retracting: inside it). */
static int nh_sim_tools_inside(const nh_sim *s) {
  int n = 0;
  for (int k = 0; s->contact && k < s->scene->n_tools; k++) {
    nh_tool_report tool;
    nh_contact_report(s->contact, k, &tool);
    n += tool.state >= NH_TOOL_PUNCTURED;
  }
  return n;
}

/* adapt.resolve_tip: does the refinement the last estimate asks for
 * (nh_adapt_planned) split a leaf that holds a tool's tip? A leaf holds
 * the tip when its rest box, widened by 1e-3 of its edges, contains the
 * tip's current position (a tip on a face or edge belongs to the leaves on
 * every side; the displacements are far below 1e-3 of a cell). */
static int nh_sim_tip_split(nh_sim *s, int *hit) {
  const nh_scene *sc = s->scene;
  const nh_mesh *m = s->mesh;
  *hit = 0;
  int *cells = nh_calloc((size_t)(m->n_leaves ? m->n_leaves : 1), sizeof(int)), n = 0;
  if (!cells) return NH_ERROR(NH_ERR_MEMORY, "out of memory: refinement plan");
  int rc = nh_adapt_planned(s->adapt, m, cells, &n);
  for (int k = 0; !rc && k < sc->n_tools && !*hit; k++) {
    nh_tool_report tool;
    nh_contact_report(s->contact, k, &tool);
    for (int i = 0; i < n && !*hit; i++) {
      const int *e = m->cells + 8 * cells[i];
      int inside = 1;
      for (int d = 0; d < 3 && inside; d++) {
        double lo = m->X[3 * e[0] + d], hi = lo;
        for (int c = 1; c < 8; c++)
          lo = fmin(lo, m->X[3 * e[c] + d]), hi = fmax(hi, m->X[3 * e[c] + d]);
        double pad = 1e-3 * (hi - lo);
        inside = tool.tip[d] >= lo - pad && tool.tip[d] <= hi + pad;
      }
      *hit = inside;
    }
  }
  free(cells);
  return rc;
}

/* adapt.resolve: while a goal estimate exceeds the tolerance (or, without
 * tolerance, up to N times), refine and solve the step again from its start
 * state carried to the new mesh (Eq. 17) and the tools' start state, so the
 * step's written solution is on the mesh its estimate asked for. Then, with
 * adapt.resolve_tip, the same while the refinement would split a leaf
 * holding a tool's tip (nh_sim_tip_split; at most max_level times, as each
 * splits the tip's leaf one level further): the step that brings the tip
 * into coarse cells (the puncture, a new region) is solved on the cells
 * its own estimate gives the tip, not on those of the step before. Times
 * add up in *st. */
static int nh_sim_resolve(nh_sim *s, double t_new, nh_step_stats *st, int *resolves) {
  const nh_scene *sc = s->scene;
  const int most = sc->adapt.resolve + (nh_sim_resolves_tip(s) ? sc->adapt.max_level : 0);
  const int n = 3 * s->mesh->n_nodes;
  double *start[2] = {nh_calloc(n, sizeof(double)), nh_calloc(n, sizeof(double))};
  int rc = start[0] && start[1] ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: re-solve");
  if (!rc)
    memcpy(start[0], s->u_start, sizeof(double) * n),
        memcpy(start[1], s->v_start, sizeof(double) * n);
  for (int r = 0; r < most && !rc; r++) {
    int changed = 0, tip = 0;
    if (r >= sc->adapt.resolve && ((rc = nh_sim_tip_split(s, &tip)) || !tip)) break;
    /* The tools' start state is loaded before the refinement, on the mesh it
     * was saved on: the refinement then carries it to the new mesh as it
     * carries a solved state (the path points found again, the skull's
     * points rebuilt on the new leaves with their warm starts). The solved
     * state is kept for a refinement that changes nothing. */
    unsigned char *solved = NULL;
    size_t solved_size = 0;
    if (s->contact &&
        ((rc = nh_contact_state_save(s->contact, &solved, &solved_size)) ||
         (rc = nh_contact_state_load(s->contact, s->tools_start, s->tools_start_size)))) {
      free(solved);
      break;
    }
    rc = nh_sim_refine(s, start, &changed);
    if (s->contact && !rc && !changed) rc = nh_contact_state_load(s->contact, solved, solved_size);
    free(solved);
    if (rc || !changed) break;
    memcpy(s->u, start[0], sizeof(double) * 3 * s->mesh->n_nodes);
    memcpy(s->v, start[1], sizeof(double) * 3 * s->mesh->n_nodes);
    /* a stop inside the re-solve restores the start state on this mesh */
    memcpy(s->u_start, start[0], sizeof(double) * 3 * s->mesh->n_nodes);
    memcpy(s->v_start, start[1], sizeof(double) * 3 * s->mesh->n_nodes);
    if (s->contact) { /* the tools' start state on this mesh */
      free(s->tools_start);
      s->tools_start = NULL;
      if ((rc = nh_contact_state_save(s->contact, &s->tools_start, &s->tools_start_size))) break;
    }
    nh_step_stats again = {0};
    if ((rc = nh_sim_solve(s, t_new, &again)) || (rc = nh_sim_estimate(s))) break;
    st->t_assemble += again.t_assemble, st->t_factor += again.t_factor;
    st->t_solve += again.t_solve, st->t_constraints += again.t_constraints;
    /* the re-solve's factorisations and its estimate's (the next step's count otherwise) */
    st->factorised += again.factorised + nh_system_take_later_factorisations(s->system);
    st->iterations = again.iterations, st->residual = again.residual;
    st->residual_floor = again.residual_floor;
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

/* One step as its phases hand it on (nh_sim_step). */
typedef struct {
  double t_new;           /* the time the step solves for */
  int adapt_now, resolve; /* estimate (and refine) at this step; re-solve on the refined mesh */
  int inside;             /* adapt.resolve_tip: tools inside the tissue at the step's start */
  nh_step_stats st;       /* the solve's (the re-solves' phases added) */
  int resolves;
  double t0;         /* the clock at the step's start */
  double t_estimate; /* s: estimate and re-solves, their solves not counted */
  double t_output;   /* s: counts, rows, frame and checkpoint */
  double t_tools;    /* s: the start state saved and the solve's time outside the solver's
                        phases (external forces; the tools' rows, tips and states) */
  double t_guard;    /* s: nh_sim_guard */
  /* steps.csv: the mesh the step was solved on (before any refinement) */
  int dofs, free_dofs, cells, hanging, rows;
  nh_contact_stats cc; /* all zero without tools */
  double work;         /* f_ext · u */
  double goal_max;     /* the largest goal estimate of the written solution */
  double refine_stop;  /* what ended the step's last refinement (NaN: none) */
  int refine_rc;       /* a failed refinement still leaves the step's row */
  char refine_reason[1024];
} nh_sim_record;

/* Room for this step's row of the timing table. */
static int nh_sim_timing_reserve(nh_sim *s) {
  if (s->step < s->cap_steps) return NH_OK;
  int cap = 2 * s->cap_steps + 16;
  NH_TRY(nh_realloc((void **)&s->phase_times, NH_PHASES * (size_t)cap, sizeof(double)));
  memset(s->phase_times + NH_PHASES * (size_t)s->cap_steps, 0,
         sizeof(double) * NH_PHASES * (size_t)(cap - s->cap_steps));
  s->cap_steps = cap;
  return NH_OK;
}

/* Predict: the prescribed motion at t_new (the loads at t_new: nh_sim_solve),
 * and the step's start state saved: u, v, the tools' (a few kB: beams and
 * channels) and the factor reuse's, for a stop inside the step and for the
 * re-solves. */
static int nh_sim_predict(nh_sim *s, nh_sim_record *r) {
  const size_t n = 3 * (size_t)s->mesh->n_nodes;
  nh_sim_prescribe(s, r->t_new, 0.0, 0.0);
  memcpy(s->u_start, s->u, sizeof(double) * n);
  memcpy(s->v_start, s->v, sizeof(double) * n);
  if (s->contact) {
    free(s->tools_start);
    s->tools_start = NULL;
    NH_TRY(nh_contact_state_save(s->contact, &s->tools_start, &s->tools_start_size));
  }
  { /* the step may renew the factor or assemble A before a stop inside it: a
     * checkpoint then holds the factor and the last assembly of its start
     * (with `refactor: every` too, so that the continued step rebuilds no
     * more tangents than the uninterrupted one) */
    s->solver_start.len = 0;
    nh_system_reuse_save(s->system, &s->solver_start);
    if (s->solver_start.failed)
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: step %d start state", s->step + 1);
  }
  return NH_OK;
}

/* Estimate (every adapt.every steps) the error of the step's solution and,
 * with adapt.resolve, refine and solve the step again (nh_sim_resolve). The
 * re-solves' phases add up in r->st; r->t_estimate is the rest. */
static int nh_sim_estimate_step(nh_sim *s, nh_sim_record *r) {
  double ta = nh_time_now();
  s->eta = s->eta_rel = NAN; /* nan in steps.csv: not estimated at this step */
  int rc = r->adapt_now ? nh_sim_estimate(s) : NH_OK;
  r->st.factorised += nh_system_take_later_factorisations(s->system); /* the duals' */
  if (!rc && r->resolve) {
    const nh_step_stats *st = &r->st;
    double t_solves = st->t_assemble + st->t_factor + st->t_solve + st->t_constraints;
    rc = nh_sim_resolve(s, r->t_new, &r->st, &r->resolves);
    ta += st->t_assemble + st->t_factor + st->t_solve + st->t_constraints - t_solves;
  }
  r->t_estimate = nh_time_now() - ta;
  return rc;
}

/* The counts of steps.csv, of the mesh the step was solved on. */
static void nh_sim_count(const nh_sim *s, nh_sim_record *r) {
  const nh_mesh *m = s->mesh;
  r->dofs = 3 * m->n_nodes, r->free_dofs = nh_system_free_dofs(s->system);
  r->cells = m->n_leaves;
  r->hanging = s->hanging ? s->hanging->n_hanging - s->hanging->n_aggregated : 0;
  if (s->contact) nh_contact_stats_get(s->contact, &r->cc);
  r->rows = nh_system_constraint_rows(s->system) + r->cc.rows;
  /* f_ext · u: at a static equilibrium of a linear problem, the energy norm
   * squared of the solution (‖u_h‖²_E = f·u_h), which the adaptivity study
   * uses: for conforming Galerkin solutions ‖u − u_h‖²_E = ‖u‖²_E − ‖u_h‖²_E. */
  r->work = 0.0;
  for (int i = 0; i < r->dofs; i++) r->work += s->f_ext[i] * s->u[i];
}

/* Output of the solution: the rows of the probes and tools, and a frame
 * when due (on the mesh it was solved on, with its indicators). */
static int nh_sim_write_solution(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (s->options.dry_run) return NH_OK;
  int due = (sc->output.every > 0 && s->step % sc->output.every == 0) || s->step == sc->time.steps;
  NH_TRY_OUTPUT(nh_write_probe_rows(s), s->step);
  if (due && s->last_frame != s->step) NH_TRY_OUTPUT(nh_write_frame(s), s->step);
  NH_TRY_OUTPUT(nh_sim_patient_write(s), s->step);
  return NH_OK;
}

/* Adapt: the estimate of the written solution (before it is refined away),
 * then the refinement for the next step (the last step refines only in its
 * re-solves). A failed refinement is kept in r: the step's row comes first. */
static void nh_sim_adapt_mesh(nh_sim *s, nh_sim_record *r) {
  const nh_scene *sc = s->scene;
  r->goal_max = NAN;
  for (int i = 0; s->goal_of_point && i < sc->n_probes + sc->n_targets; i++) {
    double e = nh_sim_point_error(s, i);
    if (e == e && !(e <= r->goal_max)) r->goal_max = e;
    if (e == e && !(e <= s->max_goal_error) && (i >= sc->n_probes || sc->n_targets == 0))
      s->max_goal_error = e, s->max_goal_point = i;
  }
  int last = s->step >= sc->time.steps;
  r->refine_rc = r->adapt_now && !last ? nh_sim_refine(s, NULL, NULL) : NH_OK;
  r->refine_stop = r->adapt_now && (!last || sc->adapt.resolve > 0 || r->resolves > 0)
                       ? (double)nh_adapt_last_stop(s->adapt)
                       : NAN;
  if (r->refine_rc) snprintf(r->refine_reason, sizeof r->refine_reason, "%s", nh_error_message());
}

/* A checkpoint is due after this step (and then its rows must be on disk). */
static int nh_sim_checkpoint_due(const nh_sim *s, const nh_sim_record *r) {
  const nh_scene *sc = s->scene;
  return !r->refine_rc && !s->options.dry_run && sc->output.checkpoint > 0 &&
         s->step % sc->output.checkpoint == 0;
}

/* The step's row of the timing table (the summary's medians); t_end: the
 * clock after its checkpoint. */
static double *nh_sim_record_times(nh_sim *s, const nh_sim_record *r, double t_end) {
  const nh_step_stats *st = &r->st;
  double *pt = s->phase_times + NH_PHASES * (size_t)(s->step - 1);
  pt[NH_PHASE_ASSEMBLE] = st->t_assemble;
  pt[NH_PHASE_FACTOR] = st->t_factor;
  pt[NH_PHASE_SOLVE] = st->t_solve;
  pt[NH_PHASE_CONSTRAINTS] = st->t_constraints;
  pt[NH_PHASE_TOOLS] = r->t_tools;
  pt[NH_PHASE_GUARD] = r->t_guard;
  pt[NH_PHASE_ADAPT] = s->t_adapt;
  pt[NH_PHASE_OUTPUT] = r->t_output;
  pt[NH_PHASE_STEP] = t_end - r->t0 - st->t_aside;
  return pt;
}

/* Output of the step: its times and its row of steps.csv and of
 * results.h5. */
/* steps.csv `unsolved` (nh_sim_step_unsolved, guard.c): every such step
 * counted (the summary); the first warned about, unless the guard reported
 * it (nh_sim_step_guarded). */
static int nh_sim_unsolved(nh_sim *s, const nh_step_stats *st) {
  double bound;
  if (!nh_sim_step_unsolved(s, st, &bound)) return 0;
  /* a guarded step was reported by the guard (solver.on_invalid: warn) */
  if (s->unsolved_steps++ == 0) s->unsolved_first = s->step;
  if (s->unsolved_steps == 1 && !nh_sim_step_guarded(s))
    nh_log_warn("step %d (t = %g s): relative residual %.3g above %g: the step's equations are "
                "not solved (steps.csv `unsolved`; docs/outputs.md)",
                s->step, s->time, st->residual, bound);
  return 1;
}

static int nh_sim_write_row(nh_sim *s, const nh_sim_record *r, double t_end) {
  const nh_step_stats *st = &r->st;
  const int unsolved = nh_sim_unsolved(s, st);
  const nh_coupled_stats *cs = &r->cc.solve;
  const double *pt = nh_sim_record_times(s, r, t_end);
  const double row[] = {s->step,
                        s->time,
                        r->dofs,
                        r->free_dofs,
                        r->cells,
                        r->hanging,
                        r->rows,
                        s->eta,
                        s->eta_rel,
                        st->iterations,
                        st->residual,
                        st->t_assemble,
                        st->t_factor,
                        st->t_solve,
                        st->t_constraints,
                        s->t_adapt,
                        r->t_output,
                        pt[NH_PHASE_STEP],
                        r->work,
                        cs->mcp.iterations,
                        cs->mcp.residual,
                        cs->mcp.n_stick,
                        cs->mcp.n_slide,
                        r->cc.cut,
                        r->cc.path_points,
                        cs->t_compliance,
                        cs->t_mcp,
                        st->factorised,
                        st->pcg_iterations,
                        st->corrections,
                        st->t_factor_reference,
                        s->inverted,
                        r->goal_max,
                        r->refine_stop,
                        r->resolves,
                        st->tangent_updates,
                        r->cc.skull_contacts,
                        r->cc.skull_force[0],
                        r->cc.skull_force[1],
                        r->cc.skull_force[2],
                        cs->mcp.newton_steps,
                        cs->mcp.sweeps,
                        cs->mcp.method,
                        log2(st->load_steps > 0 ? st->load_steps : 1),
                        unsolved,
                        r->t_tools,
                        r->t_guard};
  enum { NH_STEP_COLUMNS = sizeof nh_step_columns / sizeof *nh_step_columns };
  _Static_assert(sizeof row / sizeof *row == NH_STEP_COLUMNS, "one value per steps.csv column");
  if (!s->options.dry_run)
    NH_TRY_OUTPUT(nh_csv_values(s->steps_csv, NH_STEP_COLUMNS, row), s->step);
  if (s->h5) {
    NH_TRY_OUTPUT(nh_h5_append_steps(s->h5, row), s->step);
    /* The checkpoint of this step is on disk: so must be its rows. */
    if (nh_sim_checkpoint_due(s, r)) NH_TRY_OUTPUT(nh_h5_flush(s->h5), s->step);
  }
  return NH_OK;
}

/* A failed step: the message names it (exit 1). */
static int nh_sim_step_failed(const nh_sim *s, int rc, double t_new) {
  char reason[1900];
  snprintf(reason, sizeof reason, "%s", nh_error_message());
  return NH_ERROR(rc, "step %d (t = %g s): %s", s->step + 1, t_new, reason);
}

int nh_sim_step(nh_sim *s) {
  const nh_scene *sc = s->scene;
  NH_TRY(nh_sim_timing_reserve(s));
  nh_sim_record r = {.t0 = nh_time_now(), .t_new = (s->step + 1) * sc->time.step};
  r.adapt_now = sc->adapt.enabled && (s->step + 1) % sc->adapt.every == 0;
  r.resolve = r.adapt_now && (sc->adapt.resolve > 0 || nh_sim_resolves_tip(s));
  r.inside = nh_sim_tools_inside(s);
  NH_TRY(nh_sim_predict(s, &r));
  /* the goal estimate factorises A at the step's solution (its duals) */
  nh_system_expect_factor_later(s->system, r.adapt_now && sc->adapt.estimator == NH_ESTIMATOR_GOAL);
  int rc = nh_sim_solve(s, r.t_new, &r.st);
  const double t_solved = nh_time_now();
  /* what the solver's phases leave of the step so far: the tools' part */
  r.t_tools = t_solved - r.t0 - r.st.t_assemble - r.st.t_factor - r.st.t_solve -
              r.st.t_constraints - r.st.t_aside;
  /* A stop that cut the residual's assembly short left u and v updated but
   * the step's residual unknown (NaN): the step is not complete, and goes
   * back to its start like one stopped earlier, so that a continued run
   * computes it again and reports what the uninterrupted run reports. */
  if (!rc && isnan(r.st.residual) && nh_stop_requested()) rc = nh_stop_check();
  if (!rc && (rc = nh_sim_guard(s, s->u_start, &r.st))) return rc; /* its message names the step */
  r.t_guard = nh_time_now() - t_solved;
  /* adapt.resolve_tip: the step in which a tool punctures is estimated (and
   * re-solved at the tip) whatever adapt.every says: its tip meets cells no
   * estimate has seen (docs/theory.md §6.7) */
  if (!rc && !r.adapt_now && sc->adapt.enabled && nh_sim_resolves_tip(s) &&
      nh_sim_tools_inside(s) > r.inside)
    r.adapt_now = r.resolve = 1;
  r.adapt_now = r.adapt_now && !rc, r.resolve = r.resolve && !rc;
  int rc_estimate = nh_sim_estimate_step(s, &r);
  if (rc || (rc = rc_estimate)) return nh_sim_step_failed(s, rc, r.t_new);
  s->step++;
  s->time = r.t_new;
  double t1 = nh_time_now();
  nh_sim_count(s, &r);
  NH_TRY(nh_sim_write_solution(s));
  double t2 = nh_time_now();
  nh_sim_adapt_mesh(s, &r);
  double t3 = nh_time_now();
  s->t_adapt = r.t_estimate + (t3 - t2);
  /* A checkpoint holds the state the next step starts from: after
   * refinement; not the old mesh's factor (solve/inherit.c), so the run
   * drops it there too and continues as a restarted one would. */
  if (nh_sim_checkpoint_due(s, &r)) {
    nh_system_inherit_drop(s->system);
    NH_TRY_OUTPUT(nh_checkpoint_write(s), s->step);
  }
  double t4 = nh_time_now(); /* the checkpoint counts as output */
  r.t_output = t2 - t1 + (t4 - t3);
  NH_TRY(nh_sim_write_row(s, &r, t4));
  /* The scene was validated at creation: nothing refinement meets later is
   * the scene's fault (exit 1, not 2). */
  if (r.refine_rc)
    return NH_ERROR(r.refine_rc == NH_ERR_INPUT ? NH_ERR_INTERNAL : r.refine_rc,
                    "step %d (t = %g s): refinement: %s", s->step, r.t_new, r.refine_reason);
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
      /* The scene as run (overrides applied, files by absolute path) is
       * DIR/scene.yaml: the command continues exactly this run, whatever
       * --set made it, from any folder (DIR absolute too). */
      char abs[2 * NH_PATH_MAX];
      const char *dir = nh_path_absolute(s->scene->output.dir, abs, sizeof abs);
      rc = NH_ERROR(NH_ERR_INTERRUPTED,
                    "stopped by signal %d %s step %d of %d (t = %g s); the last frame and a "
                    "checkpoint are in %s; continue with: needlehex run %s/scene.yaml --restart %s",
                    nh_stop_requested(), when, s->step, s->scene->time.steps, s->time,
                    s->scene->output.dir, dir, dir);
      break;
    }
  }
  /* results.h5 holds the rows since its last frame in memory: writing them
   * is an output like any other, and can fail like any other. */
  if (!rc && s->h5 && (rc = nh_h5_close(&s->h5))) rc = nh_output_failed(rc, s->step);
  if (s->unsolved_steps > 0)
    nh_log_warn("%d of %d steps left unsolved (relative residual above its bound; the first: step "
                "%d): steps.csv `unsolved`",
                s->unsolved_steps, s->step - s->first_step, s->unsolved_first);
  if (s->options.progress) {
    double median[NH_PHASES];
    nh_sim_median_times(s, median);
    nh_progress_finish(s, median);
  }
  return rc;
}
