/* plan.c — target compensation by Broyden's method on the aim point.
 *
 * The unknown is the aim a ∈ R³, the point the planned trajectories are
 * directed at (tools[].trajectory.aim, the entry fixed); the residual is the
 * final miss m(a) = tip − x_T at the last step of the procedure, with tip
 * the tip of the target's tool (targets[T].tool, the electrode) and x_T the
 * target's current position (a material point: it moves with the brain).
 * One evaluation of m is one whole run of the procedure.
 *
 * Why Broyden from J = I. With a rigid brain the tool goes where it is aimed
 * and the target stays: m(a) = a − X_T, J = I, and the first step lands on
 * the target (the first run is already on it, the planner stops after one
 * run). With brain shift, m(a) ≈ a − X_T − s(a) + δ(a): s the target's shift
 * (gravity, and the cannula's drag, which depends on where it passes), δ the
 * tool's own deflection; both vary slowly with a, so J stays close to I and
 * the fixed-point step a − m (Broyden's first step) already removes most of
 * the miss; Broyden's rank-one updates learn the rest of J from the runs
 * (superlinear convergence near the solution, against the linear rate
 * ‖J − I‖ of the plain fixed-point iteration). A run that misses by more than
 * the one before it resets J to I (the update then learnt a bad model).
 *
 * Every run is a fresh simulation of the scene with the aim overridden as a
 * `--set tools.i.trajectory.aim=[...]` after the user's overrides, for each
 * tool with a trajectory, so OUT/run_NN/scene.yaml is the scene that was run
 * and the last one is the compensated plan, ready to be run again. */
#include "plan/plan.h"

#include "io/io.h"
#include "plan/plan_impl.h"
#include "scene/scene.h"
#include "sim/sim.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { NH_PLAN_SET_MAX = 192 };

typedef struct {
  double aim[3], miss[3], distance, seconds;
} nh_plan_run_record;

static double norm3(const double v[3]) {
  return sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

/* The planned target of the scene: every tool with a trajectory aims at it.
 * Also the aim to start from (the scene's trajectory.aim, else the target). */
static int planned_target(const nh_scene *s, int *target, double aim[3]) {
  *target = -1;
  for (int i = 0; i < s->n_tools; i++) {
    const nh_tool_spec *t = &s->tools[i];
    if (!t->planned) continue;
    if (*target >= 0 && t->target != *target)
      return NH_ERROR(NH_ERR_INPUT,
                      "%s: plan: tools aim at different targets (%s and %s); the planner "
                      "compensates one target",
                      t->where, s->targets[*target].name, s->targets[t->target].name);
    if (*target < 0) memcpy(aim, t->aim, 3 * sizeof(double));
    *target = t->target;
  }
  if (*target < 0)
    return NH_ERROR(NH_ERR_INPUT,
                    "%s: plan: no tool has a trajectory (tools[].trajectory: {entry, target}): "
                    "nothing to aim",
                    s->file);
  return NH_OK;
}

/* The target whose tool has a bevel (the first such), if any: 1 and *target. */
static int steered_target(const nh_scene *s, int *target) {
  for (int i = 0; i < s->n_targets; i++)
    if (s->tools[s->targets[i].tool].bevel > 0) {
      *target = i;
      return 1;
    }
  return 0;
}

/* One run of the procedure aimed at `aim`, outputs in `dir`: its miss. */
static int run_once(const char *scene_path, int n_sets, const char *const *sets,
                    const double aim[3], const char *dir, int run, nh_plan_run_record *rec) {
  const char **all = nh_calloc((size_t)n_sets + NH_PLAN_SET_MAX, sizeof(char *));
  char(*aims)[160] = nh_calloc(NH_PLAN_SET_MAX, sizeof *aims);
  nh_scene *scene = NULL;
  nh_sim *sim = NULL;
  int rc = all && aims ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: plan");
  if (!rc) rc = nh_scene_load(scene_path, n_sets, sets, &scene); /* to count the tools */
  int n = n_sets;
  if (!rc) {
    for (int i = 0; i < n_sets; i++) all[i] = sets[i];
    for (int i = 0; i < scene->n_tools && n < n_sets + NH_PLAN_SET_MAX; i++)
      if (scene->tools[i].planned) {
        snprintf(aims[n - n_sets], sizeof aims[0], "tools.%d.trajectory.aim=[%.17g, %.17g, %.17g]",
                 i, aim[0], aim[1], aim[2]);
        all[n] = aims[n - n_sets];
        n++;
      }
    nh_scene_destroy(&scene);
    rc = nh_scene_load(scene_path, n, all, &scene);
  }
  int target = -1;
  double ignored[3];
  if (!rc) rc = planned_target(scene, &target, ignored);
  if (!rc) {
    snprintf(scene->output.dir, sizeof scene->output.dir, "%.*s", NH_PATH_MAX - 1, dir);
    /* run_NN belongs to the plan: a plan run again replaces its runs */
    nh_sim_options opt = {.dry_run = 0, .progress = 0, .restart_dir = NULL, .overwrite = 1};
    double t0 = nh_time_now();
    rc = nh_sim_create(scene, &opt, &sim);
    if (!rc) rc = nh_sim_run(sim);
    if (!rc) {
      double x[3];
      nh_sim_target_miss(sim, target, x, rec->miss);
      memcpy(rec->aim, aim, sizeof rec->aim);
      rec->distance = norm3(rec->miss);
      rec->seconds = nh_time_now() - t0;
    } else {
      char msg[1024];
      snprintf(msg, sizeof msg, "%s", nh_error_message());
      rc = nh_error_set(rc, __FILE__, __LINE__, "plan run %d (%s): %s", run, dir, msg);
    }
  }
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  free(all);
  free(aims);
  return rc;
}

/* a += d with d = −J⁻¹ m (the fixed-point step −m if J is singular). */
static void broyden_step(const double J[9], const double m[3], double a[3]) {
  double Jinv[9], d[3];
  if (nh_mat3_inverse(J, Jinv) == NH_OK) {
    nh_mat3_vec(Jinv, m, d);
  } else {
    memcpy(d, m, sizeof d);
  }
  for (int k = 0; k < 3; k++) a[k] -= d[k];
}

/* J += (Δm − J Δa) Δaᵀ / (Δaᵀ Δa). */
static void broyden_update(double J[9], const nh_plan_run_record *prev,
                           const nh_plan_run_record *cur) {
  double da[3], dm[3], Jda[3], ss = 0;
  for (int k = 0; k < 3; k++) {
    da[k] = cur->aim[k] - prev->aim[k];
    dm[k] = cur->miss[k] - prev->miss[k];
    ss += da[k] * da[k];
  }
  if (!(ss > 0)) return;
  nh_mat3_vec(J, da, Jda);
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) J[3 * i + j] += (dm[i] - Jda[i]) * da[j] / ss;
}

void nh_plan_put_vec(FILE *f, const double v[3]) {
  fprintf(f, "[%.17g, %.17g, %.17g]", v[0], v[1], v[2]);
}

int nh_plan_yaml_finish(FILE *f, char **text, const char *out) {
  int failed = ferror(f);
  if (fclose(f) != 0) failed = 1;
  char path[NH_PATH_MAX + 16];
  snprintf(path, sizeof path, "%s/plan.yaml", out);
  int rc = failed || !*text ? NH_ERROR(NH_ERR_MEMORY, "out of memory: plan.yaml")
                            : nh_write_text(path, *text);
  free(*text);
  *text = NULL;
  return rc;
}

/* OUT/plan.yaml, composed in memory and written atomically. */
static int write_plan_yaml(const char *out, const char *scene_path, const nh_scene *s, int target,
                           const nh_plan_options *o, const nh_plan_run_record *runs, int n_runs,
                           int converged, double seconds) {
  char *text = NULL;
  size_t size = 0;
  FILE *f = open_memstream(&text, &size);
  if (!f) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan.yaml");
  const nh_target *g = &s->targets[target];
  const nh_tool_spec *tool = NULL;
  for (int i = 0; i < s->n_tools && !tool; i++)
    if (s->tools[i].planned) tool = &s->tools[i];
  fprintf(f, "# needlehex plan: target compensation (docs/dbs.md, Compensated plan).\n"
             "# Lengths in m, times in s (wall); miss = tip of the target's tool minus the\n"
             "# target's position at the last step of the run.\n");
  fprintf(f, "scene: %s\ntarget: %s\ntool: %s\ntarget_point: ", scene_path, g->name,
          s->tools[g->tool].name);
  nh_plan_put_vec(f, g->point);
  fprintf(f, "\nentry: ");
  nh_plan_put_vec(f, tool->entry);
  fprintf(f, "\ntolerance: %.17g\nmax_runs: %d\nconverged: %s\nruns: %d\ntime: %.3f\naim: ",
          o->tolerance, o->max_runs, converged ? "true" : "false", n_runs, seconds);
  nh_plan_put_vec(f, runs[n_runs - 1].aim);
  fprintf(f, "\nmiss: %.17g\nfinal_run: run_%02d\niterations:\n", runs[n_runs - 1].distance,
          n_runs);
  for (int k = 0; k < n_runs; k++) {
    fprintf(f, "  - {run: %d, aim: ", k + 1);
    nh_plan_put_vec(f, runs[k].aim);
    fprintf(f, ", miss_vector: ");
    nh_plan_put_vec(f, runs[k].miss);
    fprintf(f, ", miss: %.17g, time: %.3f}\n", runs[k].distance, runs[k].seconds);
  }
  return nh_plan_yaml_finish(f, &text, out);
}

int nh_plan_run(const char *scene_path, int n_sets, const char *const *sets,
                const nh_plan_options *o) {
  NH_CHECK(o->tolerance > 0 && isfinite(o->tolerance), NH_ERR_INPUT,
           "--tolerance: expected a length > 0 in m, got %g", o->tolerance);
  NH_CHECK(o->max_runs >= 1 && o->max_runs <= 99, NH_ERR_INPUT,
           "--max-runs: expected 1 to 99 runs, got %d", o->max_runs);
  NH_CHECK(o->workers >= 0 && o->workers <= 64, NH_ERR_INPUT,
           "--workers: expected 0 to 64 runs at once, got %d", o->workers);
  nh_scene *scene = NULL;
  NH_TRY(nh_scene_load(scene_path, n_sets, sets, &scene));
  int target = -1;
  double aim[3];
  char out[NH_PATH_MAX];
  if (o->out_dir)
    snprintf(out, sizeof out, "%s", o->out_dir);
  else
    snprintf(out, sizeof out, "out/%s-plan", scene->name);
  int rc = strlen(out) > NH_PATH_MAX - 16 ? NH_ERROR(NH_ERR_INPUT, "--out: path too long") : NH_OK;
  /* a bevel-tip needle is steered: the steering planner (steer.c) */
  int steer = steered_target(scene, &target);
  if (!rc && steer) {
    rc = nh_mkdir_p(out);
    if (!rc) rc = nh_plan_steer(scene_path, n_sets, sets, scene, target, o, out);
    nh_scene_destroy(&scene);
    return rc;
  }
  if (!rc) rc = planned_target(scene, &target, aim);
  if (!rc) rc = nh_mkdir_p(out);
  nh_plan_run_record *runs = nh_calloc((size_t)o->max_runs, sizeof *runs);
  if (!rc && !runs) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: plan");
  double J[9], t0 = nh_time_now();
  nh_mat3_identity(J);
  int n_runs = 0, converged = 0;
  if (!rc && !o->quiet)
    printf("plan: target %s at [%.6g, %.6g, %.6g] mm, tolerance %.3g mm, at most %d runs\n",
           scene->targets[target].name, 1e3 * scene->targets[target].point[0],
           1e3 * scene->targets[target].point[1], 1e3 * scene->targets[target].point[2],
           1e3 * o->tolerance, o->max_runs);
  while (!rc && n_runs < o->max_runs) {
    char dir[NH_PATH_MAX + 16];
    snprintf(dir, sizeof dir, "%s/run_%02d", out, n_runs + 1);
    nh_plan_run_record *r = &runs[n_runs];
    rc = run_once(scene_path, n_sets, sets, aim, dir, n_runs + 1, r);
    if (rc) break;
    n_runs++;
    if (!o->quiet) {
      printf("run %d: aim [%.6g, %.6g, %.6g] mm, miss %.4g mm ([%.4g, %.4g, %.4g]), %.1f s\n",
             n_runs, 1e3 * r->aim[0], 1e3 * r->aim[1], 1e3 * r->aim[2], 1e3 * r->distance,
             1e3 * r->miss[0], 1e3 * r->miss[1], 1e3 * r->miss[2], r->seconds);
      fflush(stdout);
    }
    if (r->distance <= o->tolerance) {
      converged = 1;
      break;
    }
    if (n_runs >= 2) {
      if (r->distance > runs[n_runs - 2].distance)
        nh_mat3_identity(J);
      else
        broyden_update(J, &runs[n_runs - 2], r);
    }
    broyden_step(J, r->miss, aim);
  }
  double seconds = nh_time_now() - t0;
  if (n_runs > 0) {
    int wrc = write_plan_yaml(out, scene_path, scene, target, o, runs, n_runs, converged, seconds);
    if (!wrc) wrc = nh_plan_link_final(out, n_runs);
    if (!rc) rc = wrc;
  }
  if (!rc && !o->quiet)
    printf(
        "plan: %s after %d run%s (%.1f s): aim [%.6g, %.6g, %.6g] mm, miss %.4g mm; %s/plan.yaml, "
        "outputs of the last run in %s/final\n",
        converged ? "converged" : "NOT converged", n_runs, n_runs == 1 ? "" : "s", seconds,
        1e3 * runs[n_runs - 1].aim[0], 1e3 * runs[n_runs - 1].aim[1], 1e3 * runs[n_runs - 1].aim[2],
        1e3 * runs[n_runs - 1].distance, out, out);
  if (!rc && !converged)
    rc = NH_ERROR(NH_ERR_NUMERIC,
                  "plan: the miss is %.4g mm after %d runs, above the tolerance %.4g mm",
                  1e3 * runs[n_runs - 1].distance, n_runs, 1e3 * o->tolerance);
  free(runs);
  nh_scene_destroy(&scene);
  return rc;
}
