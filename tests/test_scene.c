/* test_scene — the scene module: defaults, values, --set overrides, schedules,
 * steps from end/step, the scene-as-run text re-loading to the same struct,
 * the adapt section (defaults, values, where adapt.template resolves), tools
 * and targets (values, defaults, a nested tool, overrides into them),
 * gravity schedules, buoyancy and planned trajectories (the times that
 * until: target / start and release: target resolve to, by hand), and
 * the exact form of input errors (FILE:LINE: KEY: ...).
 *
 * The scenes are written by this program into a fresh temporary directory, so
 * the expected lines and values sit next to the text they come from. Silent
 * on success; on failure prints what was expected and what came out and
 * returns 1. */
#include "check.h"
#include "scene/scene.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char dir[256];

#define EXPECT_NUM(actual, expected)                                                               \
  EXPECT(fabs((double)(actual) - (double)(expected)) <= 1e-12 * (1 + fabs((double)(expected))),    \
         "%s: expected %.17g, got %.17g (tolerance 1e-12 relative)", #actual, (double)(expected),  \
         (double)(actual))

#define EXPECT_STR(actual, expected)                                                               \
  EXPECT(strcmp((actual), (expected)) == 0, "%s: expected '%s', got '%s'", #actual, (expected),    \
         (actual))

/* Write `text` to DIR/name and return the path (static buffer, one at a time). */
static const char *write_scene(const char *name, const char *text) {
  static char path[512];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "w");
  if (!f) {
    fprintf(stderr, "cannot write %s\n", path);
    exit(1);
  }
  fputs(text, f);
  fclose(f);
  return path;
}

/* Load, expecting success; NULL (and a failure) otherwise. */
static nh_scene *load_ok(const char *path, int n, const char *const *overrides, int line) {
  nh_scene *s = NULL;
  int rc = nh_scene_load(path, n, overrides, &s);
  if (rc || !s) {
    fprintf(stderr, "%s:%d: FAILED: loading %s: expected success, got %d: %s\n", __FILE__, line,
            path, rc, nh_error_message());
    ++nh_test_failures;
    return NULL;
  }
  return s;
}

static const char *minimal = "name: minimal\n"
                             "tissue:\n"
                             "  domain:\n"
                             "    box: {min: [0, 0, 0], max: [0.04, 0.02, 0.02]}\n"
                             "  material: {young: 1.0e6, poisson: 0.3}\n";

static void test_defaults(void) {
  const char *path = write_scene("minimal.yaml", minimal);
  nh_scene *s = load_ok(path, 0, NULL, __LINE__);
  if (!s) return;
  EXPECT_STR(s->name, "minimal");
  EXPECT_STR(s->file, path);
  EXPECT(s->time.mode == NH_MODE_DYNAMIC, "mode %d", (int)s->time.mode);
  EXPECT_NUM(s->time.step, 0.01);
  EXPECT(s->time.steps == 100, "steps: expected 100, got %d", s->time.steps);
  for (int i = 0; i < 3; ++i) EXPECT_NUM(s->gravity[i], 0);
  EXPECT_NUM(s->tissue.box_max[0], 0.04);
  EXPECT_NUM(s->tissue.box_max[2], 0.02);
  EXPECT(s->tissue.grid[0] == 8 && s->tissue.grid[1] == 4 && s->tissue.grid[2] == 4,
         "grid: expected [8, 4, 4], got [%d, %d, %d]", s->tissue.grid[0], s->tissue.grid[1],
         s->tissue.grid[2]);
  EXPECT_NUM(s->tissue.young, 1.0e6);
  EXPECT_NUM(s->tissue.poisson, 0.3);
  EXPECT_NUM(s->tissue.density, 1000);
  EXPECT_NUM(s->tissue.damping_mass, 0);
  EXPECT_NUM(s->tissue.damping_stiffness, 0);
  EXPECT(s->tissue.n_fixed == 0 && s->tissue.n_loads == 0 && s->n_probes == 0,
         "fixed %d loads %d probes %d", s->tissue.n_fixed, s->tissue.n_loads, s->n_probes);
  EXPECT(s->n_tools == 0 && !s->tools && s->n_targets == 0 && !s->targets,
         "no tools section: expected no tools and no targets, got %d and %d", s->n_tools,
         s->n_targets);
  EXPECT_NUM(s->solver.tolerance, 1e-8);
  EXPECT(s->solver.max_iterations == 30, "max_iterations %d", s->solver.max_iterations);
  EXPECT(s->solver.threads == 0, "threads %d", s->solver.threads);
  EXPECT_STR(s->output.dir, "out/minimal");
  EXPECT(s->output.every == 1, "every %d", s->output.every);
  EXPECT(s->output.hdf5 == 0, "hdf5 %d", s->output.hdf5);
  /* No adapt section: a fixed mesh; the settings keep their documented defaults. */
  EXPECT(s->adapt.enabled == 0, "adapt.enabled: expected 0, got %d", s->adapt.enabled);
  EXPECT(s->adapt.strategy == NH_MARK_MAX, "strategy %d", (int)s->adapt.strategy);
  EXPECT_NUM(s->adapt.theta, 0.3);
  EXPECT_NUM(s->adapt.fraction, 0.5);
  EXPECT(s->adapt.max_level == 2 && s->adapt.max_dofs == 0 && s->adapt.every == 1,
         "max_level %d max_dofs %d every %d", s->adapt.max_level, s->adapt.max_dofs,
         s->adapt.every);
  EXPECT_NUM(s->adapt.min_size, 0);
  EXPECT(s->adapt.hanging == NH_HANGING_ELIMINATE, "hanging %d", (int)s->adapt.hanging);
  EXPECT(s->yaml && strstr(s->yaml, "minimal"), "yaml text: %s", s->yaml ? s->yaml : "(null)");
  char where[NH_WHERE_MAX];
  snprintf(where, sizeof where, "%s:2: tissue.fixed", path);
  EXPECT_STR(s->tissue.where_fixed, where);
  nh_scene_destroy(&s);
  EXPECT(s == NULL, "destroy must set the pointer to NULL");
  nh_scene_destroy(&s); /* NULL is accepted */
}

static const char *full =
    "# a scene that sets every key\n"                                   /* 1 */
    "name: full-1.0_x\n"                                                /* 2 */
    "time:\n"                                                           /* 3 */
    "  mode: static\n"                                                  /* 4 */
    "  step: 0.25\n"                                                    /* 5 */
    "  end: 2.0\n"                                                      /* 6 */
    "gravity: [0, 0, -9.81]\n"                                          /* 7 */
    "tissue:\n"                                                         /* 8 */
    "  domain:\n"                                                       /* 9 */
    "    box: {min: [-1, -2, -3], max: [1, 2, 3]}\n"                    /* 10 */
    "  grid: [6, 5, 4]\n"                                               /* 11 */
    "  material: {young: 2.5e4, poisson: -0.25, density: 1040}\n"       /* 12 */
    "  damping: {mass: 0.5, stiffness: 0.001}\n"                        /* 13 */
    "  fixed:\n"                                                        /* 14 */
    "    - {box: {min: [-1, -2, -3], max: [-0.9, 2, 3]}}\n"             /* 15 */
    "    - box:\n"                                                      /* 16 */
    "        min: [0.9, -2, -3]\n"                                      /* 17 */
    "        max: [1, 2, 3]\n"                                          /* 18 */
    "  loads:\n"                                                        /* 19 */
    "    - box: {min: [0, 0, 0], max: [1, 2, 3]}\n"                     /* 20 */
    "      force: [1, 2, -3.5]\n"                                       /* 21 */
    "      schedule: [[0, 0], [1, 2], [3, 2], [4, 0]]\n"                /* 22 */
    "    - {box: {min: [0, 0, 0], max: [0, 0, 0]}, force: [0, 0, 1]}\n" /* 23 */
    "solver: {tolerance: 1.0e-10, max_iterations: 12, threads: 3}\n"    /* 24 */
    "probes:\n"                                                         /* 25 */
    "  - {name: \"1\", point: [0.5, 0, 0]}\n"                           /* 26 */
    "  - {name: tip, point: [1, 2, 3]}\n"                               /* 27 */
    "output:\n"                                                         /* 28 */
    "  dir: results/full run\n"                                         /* 29 */
    "  every: 0\n"                                                      /* 30 */
    "  hdf5: true\n";                                                   /* 31 */

/* Every value of `full`, compared field by field (where strings excluded). */
static void check_full(const nh_scene *s, const char *what) {
  EXPECT(!strcmp(s->name, "full-1.0_x"), "%s: name '%s'", what, s->name);
  EXPECT(s->time.mode == NH_MODE_STATIC, "%s: mode %d", what, (int)s->time.mode);
  EXPECT_NUM(s->time.step, 0.25);
  EXPECT(s->time.steps == 8, "%s: steps: expected 2.0 / 0.25 = 8, got %d", what, s->time.steps);
  EXPECT_NUM(s->gravity[2], -9.81);
  EXPECT_NUM(s->tissue.box_min[1], -2);
  EXPECT_NUM(s->tissue.box_max[2], 3);
  EXPECT(s->tissue.grid[0] == 6 && s->tissue.grid[1] == 5 && s->tissue.grid[2] == 4,
         "%s: grid [%d, %d, %d]", what, s->tissue.grid[0], s->tissue.grid[1], s->tissue.grid[2]);
  EXPECT_NUM(s->tissue.young, 2.5e4);
  EXPECT_NUM(s->tissue.poisson, -0.25);
  EXPECT_NUM(s->tissue.density, 1040);
  EXPECT_NUM(s->tissue.damping_mass, 0.5);
  EXPECT_NUM(s->tissue.damping_stiffness, 0.001);
  EXPECT(s->tissue.n_fixed == 2, "%s: n_fixed %d", what, s->tissue.n_fixed);
  if (s->tissue.n_fixed == 2) {
    EXPECT_NUM(s->tissue.fixed[0].max[0], -0.9);
    EXPECT_NUM(s->tissue.fixed[1].min[0], 0.9);
    EXPECT_NUM(s->tissue.fixed[1].max[1], 2);
  }
  EXPECT(s->tissue.n_loads == 2, "%s: n_loads %d", what, s->tissue.n_loads);
  if (s->tissue.n_loads == 2) {
    EXPECT_NUM(s->tissue.loads[0].force[2], -3.5);
    EXPECT(s->tissue.loads[0].schedule.n == 4, "%s: schedule n %d", what,
           s->tissue.loads[0].schedule.n);
    EXPECT(s->tissue.loads[1].schedule.n == 0, "%s: schedule n %d", what,
           s->tissue.loads[1].schedule.n);
    EXPECT_NUM(s->tissue.loads[1].force[2], 1);
  }
  EXPECT_NUM(s->solver.tolerance, 1e-10);
  EXPECT(s->solver.max_iterations == 12 && s->solver.threads == 3, "%s: solver %d %d", what,
         s->solver.max_iterations, s->solver.threads);
  EXPECT(s->n_probes == 2, "%s: n_probes %d", what, s->n_probes);
  if (s->n_probes == 2) {
    EXPECT(!strcmp(s->probes[0].name, "1"), "%s: probe name '%s'", what, s->probes[0].name);
    EXPECT(!strcmp(s->probes[1].name, "tip"), "%s: probe name '%s'", what, s->probes[1].name);
    EXPECT_NUM(s->probes[0].point[0], 0.5);
    EXPECT_NUM(s->probes[1].point[2], 3);
  }
  EXPECT(!strcmp(s->output.dir, "results/full run"), "%s: dir '%s'", what, s->output.dir);
  EXPECT(s->output.every == 0 && s->output.hdf5 == 1, "%s: output %d %d", what, s->output.every,
         s->output.hdf5);
}

static void test_values_and_where(void) {
  const char *path = write_scene("full.yaml", full);
  nh_scene *s = load_ok(path, 0, NULL, __LINE__);
  if (!s) return;
  check_full(s, "full.yaml");
  char where[NH_WHERE_MAX];
  snprintf(where, sizeof where, "%s:14: tissue.fixed", path);
  EXPECT_STR(s->tissue.where_fixed, where);
  snprintf(where, sizeof where, "%s:15: tissue.fixed.0", path);
  EXPECT_STR(s->tissue.fixed[0].where, where);
  snprintf(where, sizeof where, "%s:16: tissue.fixed.1", path);
  EXPECT_STR(s->tissue.fixed[1].where, where);
  snprintf(where, sizeof where, "%s:20: tissue.loads.0", path);
  EXPECT_STR(s->tissue.loads[0].where, where);
  EXPECT_STR(s->tissue.loads[0].region.where, where);
  snprintf(where, sizeof where, "%s:27: probes.1", path);
  EXPECT_STR(s->probes[1].where, where);

  /* The scene as run, written out and read back, gives the same struct. */
  const char *again = write_scene("full_as_run.yaml", s->yaml);
  nh_scene *t = load_ok(again, 0, NULL, __LINE__);
  if (t) {
    check_full(t, "full_as_run.yaml");
    EXPECT_STR(t->yaml, s->yaml); /* and writing it again changes nothing */
    nh_scene_destroy(&t);
  }
  nh_scene_destroy(&s);
}

static void test_steps_from_end(void) {
  static const struct {
    const char *time;
    int steps;
  } cases[] = {
      {"{step: 0.01, end: 2.0}", 200}, /* 2.0 / 0.01 = 200 */
      {"{step: 0.3, end: 1.0}", 3},    /* 3.33 rounds to 3 */
      {"{step: 0.4, end: 1.0}", 3},    /* 2.5 rounds up to 3 */
      {"{step: 0.01, end: 0.001}", 1}, /* 0.1 rounds to 0: at least 1 */
      {"{end: 0.5}", 50},              /* default step 0.01 */
      {"{steps: 7}", 7},
      {"{step: 0.5}", 100}, /* default steps */
  };
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    char text[1024];
    snprintf(text, sizeof text, "%stime: %s\n", minimal, cases[i].time);
    const char *path = write_scene("steps.yaml", text);
    nh_scene *s = load_ok(path, 0, NULL, __LINE__);
    if (!s) continue;
    EXPECT(s->time.steps == cases[i].steps, "time: %s: expected %d steps, got %d", cases[i].time,
           cases[i].steps, s->time.steps);
    nh_scene_destroy(&s);
  }
}

static void test_overrides(void) {
  const char *path = write_scene("override.yaml", full);
  const char *sets[] = {
      "tissue.grid=[16,8,8]",      /* a list replaced whole */
      "tissue.grid.2=9",           /* then one of its items */
      "tissue.material.young=3e5", /* a scalar */
      "time.steps=5",              /* a key absent from the file */
      "time.mode=dynamic",
      "tissue.fixed.1.box.min=[0.5, -2, -3]", /* through a list by index */
      "output.hdf5=false",
      "name=renamed",
      "probes.0.name='2'",
      "solver.threads=1",
  };
  int n = (int)(sizeof sets / sizeof sets[0]);
  nh_scene *s = NULL;
  int rc = nh_scene_load(path, n, sets, &s);
  /* steps (override) replaces the file's end. */
  EXPECT(rc == NH_OK, "steps overriding the file's end: expected success, got %d (%s)", rc,
         nh_error_message());
  if (s) {
    EXPECT(s->time.steps == 5, "steps: expected the override's 5, got %d", s->time.steps);
    EXPECT(!strstr(s->yaml, "end:"), "the scene as run still holds time.end:\n%s", s->yaml);
  }
  nh_scene_destroy(&s);

  sets[3] = "time.step=0.5"; /* a key absent from the file, without the conflict */
  s = load_ok(path, n, sets, __LINE__);
  if (!s) return;
  EXPECT(s->tissue.grid[0] == 16 && s->tissue.grid[1] == 8 && s->tissue.grid[2] == 9,
         "grid: expected [16, 8, 9], got [%d, %d, %d]", s->tissue.grid[0], s->tissue.grid[1],
         s->tissue.grid[2]);
  EXPECT_NUM(s->tissue.young, 3e5);
  EXPECT(s->time.steps == 4, "steps: expected 2.0 / 0.5 = 4, got %d", s->time.steps);
  EXPECT(s->time.mode == NH_MODE_DYNAMIC, "mode %d", (int)s->time.mode);
  EXPECT_NUM(s->tissue.fixed[1].min[0], 0.5);
  EXPECT(s->output.hdf5 == 0, "hdf5 %d", s->output.hdf5);
  EXPECT_STR(s->name, "renamed");
  EXPECT_STR(s->output.dir, "results/full run"); /* given in the file, not derived */
  EXPECT_STR(s->probes[0].name, "2");
  EXPECT(s->solver.threads == 1, "threads %d", s->solver.threads);
  /* A region replaced by an override reports the override as its origin. */
  nh_scene *t = NULL;
  const char *region_set[] = {"tissue.fixed.0={box: {min: [0, 0, 0], max: [1, 1, 1]}}"};
  t = load_ok(path, 1, region_set, __LINE__);
  if (t) {
    EXPECT_STR(t->tissue.fixed[0].where, "--set:1: tissue.fixed.0");
    nh_scene_destroy(&t);
  }
  /* The scene as run carries the overrides. */
  const char *again = write_scene("override_as_run.yaml", s->yaml);
  t = load_ok(again, 0, NULL, __LINE__);
  if (t) {
    EXPECT(t->tissue.grid[2] == 9 && t->time.steps == 4 && !strcmp(t->name, "renamed") &&
               !strcmp(t->probes[0].name, "2") && t->tissue.fixed[1].min[0] == 0.5,
           "re-loaded scene as run differs:\n%s", s->yaml);
    nh_scene_destroy(&t);
  }
  nh_scene_destroy(&s);

  /* Keys absent from the file, with their sections: damping, solver, gravity. */
  path = write_scene("minimal.yaml", minimal);
  const char *add[] = {"tissue.damping.mass=0.25", "tissue.damping.stiffness=1e-3",
                       "solver.max_iterations=7",  "gravity=[0, -9.81, 0]",
                       "output.every=3",           "tissue.density_not_here_but=1"};
  s = load_ok(path, 5, add, __LINE__);
  if (s) {
    EXPECT_NUM(s->tissue.damping_mass, 0.25);
    EXPECT_NUM(s->tissue.damping_stiffness, 1e-3);
    EXPECT(s->solver.max_iterations == 7, "max_iterations %d", s->solver.max_iterations);
    EXPECT_NUM(s->gravity[1], -9.81);
    EXPECT(s->output.every == 3, "every %d", s->output.every);
    EXPECT_NUM(s->solver.tolerance, 1e-8); /* the rest of a created section keeps defaults */
    nh_scene_destroy(&s);
  }
  /* ... but a key the schema does not know is refused, naming the override. */
  rc = nh_scene_load(path, 6, add, &s);
  EXPECT(rc == NH_ERR_INPUT && s == NULL, "unknown key by --set: rc %d", rc);
  EXPECT_STR(
      nh_error_message(),
      "--set:6: tissue.density_not_here_but: unknown key (--set tissue.density_not_here_but=1)");
}

static void test_schedule(void) {
  double t[] = {0, 1, 3, 4}, v[] = {0, 2, 2, 0};
  nh_schedule s = {4, t, v};
  static const double at[][2] = {{-1, 0},  {0, 0},      {0.5, 1}, {1, 2}, {2, 2},
                                 {3.5, 1}, {3.75, 0.5}, {4, 0},   {10, 0}};
  for (size_t i = 0; i < sizeof at / sizeof at[0]; ++i) {
    double got = nh_schedule_eval(&s, at[i][0]);
    EXPECT(fabs(got - at[i][1]) <= 1e-15, "schedule at t = %g: expected %g, got %.17g", at[i][0],
           at[i][1], got);
  }
  nh_schedule empty = {0, NULL, NULL};
  EXPECT(nh_schedule_eval(&empty, 3.0) == 1.0, "empty schedule: expected 1");
  EXPECT(nh_schedule_eval(NULL, 3.0) == 1.0, "NULL schedule: expected 1");
  double t1[] = {2}, v1[] = {0.5};
  nh_schedule one = {1, t1, v1};
  EXPECT(nh_schedule_eval(&one, 0) == 0.5 && nh_schedule_eval(&one, 9) == 0.5,
         "one-point schedule: expected the constant 0.5");
  /* Linear between two points: the midpoint of a random-ish interval. */
  double t2[] = {0.125, 0.625}, v2[] = {-3, 5};
  nh_schedule two = {2, t2, v2};
  EXPECT(fabs(nh_schedule_eval(&two, 0.375) - 1.0) <= 1e-15, "midpoint: expected 1, got %.17g",
         nh_schedule_eval(&two, 0.375));
  /* The schedule read from a scene is the same function. */
  const char *path = write_scene("full.yaml", full);
  nh_scene *sc = load_ok(path, 0, NULL, __LINE__);
  if (sc) {
    EXPECT_NUM(nh_schedule_eval(&sc->tissue.loads[0].schedule, 3.5), 1.0);
    EXPECT_NUM(nh_schedule_eval(&sc->tissue.loads[1].schedule, 3.5), 1.0);
    nh_scene_destroy(&sc);
  }
}

/* ---- adapt ---- */

static char templates_dir[300]; /* DIR/tmpl, where NH_TEMPLATES_DIR points */

/* Create the file DIR/name (its contents do not matter to the scene module). */
static void touch(const char *name) {
  char path[600];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "w");
  if (!f) {
    fprintf(stderr, "cannot write %s\n", path);
    exit(1);
  }
  fputs("# an empty file: the scene module only checks that it is readable\n", f);
  fclose(f);
}

static void test_adapt(void) {
  char text[2048], expected[1024];
  /* An empty section enables adaptivity with every default. */
  snprintf(text, sizeof text, "%sadapt:\n", minimal); /* line 6 */
  const char *path = write_scene("adapt_empty.yaml", text);
  nh_scene *s = load_ok(path, 0, NULL, __LINE__);
  if (s) {
    EXPECT(s->adapt.enabled == 1, "enabled: expected 1, got %d", s->adapt.enabled);
    EXPECT(s->adapt.strategy == NH_MARK_MAX, "strategy %d", (int)s->adapt.strategy);
    EXPECT_NUM(s->adapt.theta, 0.3);
    EXPECT(s->adapt.max_level == 2 && s->adapt.every == 1 && s->adapt.max_dofs == 0,
           "max_level %d every %d max_dofs %d", s->adapt.max_level, s->adapt.every,
           s->adapt.max_dofs);
    EXPECT(s->adapt.hanging == NH_HANGING_ELIMINATE, "hanging %d", (int)s->adapt.hanging);
    EXPECT(s->adapt.resolve == 0 && s->adapt.resolve_tip == 1,
           "resolve %d resolve_tip %d: expected 0 and 1 (docs/scene.md)", s->adapt.resolve,
           s->adapt.resolve_tip);
    snprintf(expected, sizeof expected, "%s/hex2.tmpl", templates_dir);
    EXPECT_STR(s->adapt.template_path, expected);
    snprintf(expected, sizeof expected, "%s:6: adapt", path);
    EXPECT_STR(s->adapt.where, expected);
    snprintf(expected, sizeof expected, "%s:6: adapt.template", path);
    EXPECT_STR(s->adapt.where_template, expected);
    nh_scene_destroy(&s);
  }

  /* Every key. */
  snprintf(text, sizeof text,
           "%s"
           "adapt:\n"                                         /* 6 */
           "  estimator: spr\n"                               /* 7 */
           "  marking: {strategy: dorfler, fraction: 0.75}\n" /* 8 */
           "  template: hex3\n"                               /* 9 */
           "  max_level: 4\n"                                 /* 10 */
           "  min_size: 1.5e-3\n"                             /* 11 */
           "  max_dofs: 120000\n"                             /* 12 */
           "  every: 5\n"                                     /* 13 */
           "  hanging: lagrange\n",                           /* 14 */
           minimal);
  path = write_scene("adapt_full.yaml", text);
  s = load_ok(path, 0, NULL, __LINE__);
  if (s) {
    EXPECT(s->adapt.enabled == 1, "enabled %d", s->adapt.enabled);
    EXPECT(s->adapt.strategy == NH_MARK_DORFLER, "strategy %d", (int)s->adapt.strategy);
    EXPECT_NUM(s->adapt.fraction, 0.75);
    EXPECT_NUM(s->adapt.theta, 0.3); /* untouched */
    snprintf(expected, sizeof expected, "%s/hex3.tmpl", templates_dir);
    EXPECT_STR(s->adapt.template_path, expected);
    snprintf(expected, sizeof expected, "%s:9: adapt.template", path);
    EXPECT_STR(s->adapt.where_template, expected);
    EXPECT(s->adapt.max_level == 4, "max_level %d", s->adapt.max_level);
    EXPECT_NUM(s->adapt.min_size, 1.5e-3);
    EXPECT(s->adapt.max_dofs == 120000, "max_dofs %d", s->adapt.max_dofs);
    EXPECT(s->adapt.every == 5, "every %d", s->adapt.every);
    EXPECT(s->adapt.hanging == NH_HANGING_LAGRANGE, "hanging %d", (int)s->adapt.hanging);
    /* The scene as run reads back to the same settings. */
    const char *again = write_scene("adapt_full_as_run.yaml", s->yaml);
    nh_scene *t = load_ok(again, 0, NULL, __LINE__);
    if (t) {
      EXPECT(t->adapt.enabled && t->adapt.strategy == NH_MARK_DORFLER &&
                 t->adapt.fraction == 0.75 && t->adapt.max_level == 4 &&
                 t->adapt.min_size == 1.5e-3 && t->adapt.max_dofs == 120000 &&
                 t->adapt.every == 5 && t->adapt.hanging == NH_HANGING_LAGRANGE &&
                 !strcmp(t->adapt.template_path, s->adapt.template_path),
             "re-loaded scene as run differs:\n%s", s->yaml);
      nh_scene_destroy(&t);
    }
    nh_scene_destroy(&s);
  }

  /* The max strategy with its theta. */
  snprintf(text, sizeof text, "%sadapt:\n  marking:\n    strategy: max\n    theta: 0.6\n", minimal);
  path = write_scene("adapt_max.yaml", text);
  s = load_ok(path, 0, NULL, __LINE__);
  if (s) {
    EXPECT(s->adapt.strategy == NH_MARK_MAX, "strategy %d", (int)s->adapt.strategy);
    EXPECT_NUM(s->adapt.theta, 0.6);
    nh_scene_destroy(&s);
  }

  /* Template paths: relative to the scene file's folder, or absolute. A name
   * is looked up in NH_TEMPLATES_DIR, never next to the scene. */
  static const struct {
    const char *value, *file; /* the value given; the file it must resolve to, in DIR */
  } paths[] = {
      {"own.tmpl", "own.tmpl"},             /* ends in .tmpl: a path */
      {"sub/own", "sub/own"},               /* has a '/': a path, no suffix added */
      {"./sub/own.tmpl", "./sub/own.tmpl"}, /* kept as written, after the folder */
  };
  char sub[400];
  snprintf(sub, sizeof sub, "%s/sub", dir);
  if (mkdir(sub, 0700) != 0) fprintf(stderr, "cannot create %s\n", sub);
  touch("own.tmpl");
  touch("sub/own");
  touch("sub/own.tmpl");
  for (size_t i = 0; i < sizeof paths / sizeof paths[0]; ++i) {
    snprintf(text, sizeof text, "%sadapt: {template: %s}\n", minimal, paths[i].value);
    path = write_scene("adapt_path.yaml", text);
    s = load_ok(path, 0, NULL, __LINE__);
    if (!s) continue;
    snprintf(expected, sizeof expected, "%s/%s", dir, paths[i].file);
    EXPECT_STR(s->adapt.template_path, expected);
    nh_scene_destroy(&s);
  }
  snprintf(text, sizeof text, "%sadapt: {template: %s/sub/own.tmpl}\n", minimal, dir);
  path = write_scene("adapt_abs.yaml", text);
  s = load_ok(path, 0, NULL, __LINE__);
  if (s) {
    snprintf(expected, sizeof expected, "%s/sub/own.tmpl", dir);
    EXPECT_STR(s->adapt.template_path, expected);
    nh_scene_destroy(&s);
  }

  /* Overrides create the section (so a fixed-mesh scene can adapt from the
   * command line) and report their own place. */
  path = write_scene("minimal.yaml", minimal);
  const char *sets[] = {"adapt.marking.theta=0.45", "adapt.template=hex3", "adapt.max_level=1"};
  s = load_ok(path, 3, sets, __LINE__);
  if (s) {
    EXPECT(s->adapt.enabled == 1, "enabled %d", s->adapt.enabled);
    EXPECT_NUM(s->adapt.theta, 0.45);
    EXPECT(s->adapt.max_level == 1, "max_level %d", s->adapt.max_level);
    snprintf(expected, sizeof expected, "%s/hex3.tmpl", templates_dir);
    EXPECT_STR(s->adapt.template_path, expected);
    EXPECT_STR(s->adapt.where_template, "--set:2: adapt.template");
    nh_scene_destroy(&s);
  }

  /* Without the environment variable, names resolve in the templates the
   * build copies next to its binaries: the same file as
   * dirname($NH_BINARY)/share/needlehex/templates/hex2.tmpl (this test runs
   * from BUILD/tests, the binary is BUILD/needlehex). */
  const char *binary = getenv("NH_BINARY");
  if (binary) {
    char saved[sizeof templates_dir], want[4200];
    struct stat got, expect;
    snprintf(saved, sizeof saved, "%s", templates_dir);
    unsetenv("NH_TEMPLATES_DIR");
    const char *slash = strrchr(binary, '/');
    snprintf(want, sizeof want, "%.*s/share/needlehex/templates/hex2.tmpl",
             slash ? (int)(slash - binary) : 1, slash ? binary : ".");
    snprintf(text, sizeof text, "%sadapt: {template: hex2}\n", minimal);
    path = write_scene("adapt_builtin.yaml", text);
    s = load_ok(path, 0, NULL, __LINE__);
    if (s) {
      EXPECT(stat(s->adapt.template_path, &got) == 0 && stat(want, &expect) == 0 &&
                 got.st_dev == expect.st_dev && got.st_ino == expect.st_ino,
             "template hex2 without NH_TEMPLATES_DIR: %s, expected the file %s",
             s->adapt.template_path, want);
      nh_scene_destroy(&s);
    }
    setenv("NH_TEMPLATES_DIR", saved, 1);
  }
}

/* ---- tools and targets ---- */

/* `minimal` (lines 1-5) followed by two tools, the second inside the first,
 * and two targets. The cannula sets every key; the electrode leaves every
 * optional key at its default. */
static const char *tools_text =
    "tools:\n"                                                          /* 6 */
    "  - name: cannula\n"                                               /* 7 */
    "    length: 0.032\n"                                               /* 8 */
    "    radius: 0.001\n"                                               /* 9 */
    "    inner_radius: 0.0005\n"                                        /* 10 */
    "    elements: 8\n"                                                 /* 11 */
    "    material: {young: 5.0e7, poisson: 0.25, density: 7900}\n"      /* 12 */
    "    damping: {mass: 0.5, stiffness: 0.002}\n"                      /* 13 */
    "    base: [-0.001, 0.01, 0.01]\n"                                  /* 14 */
    "    direction: [0, 3, -4]\n"                                       /* 15 */
    "    motion:\n"                                                     /* 16 */
    "      - {until: 1.5, speed: 0.02}\n"                               /* 17 */
    "      - {until: 2.0, speed: -0.01}\n"                              /* 18 */
    "    interaction:\n"                                                /* 19 */
    "      puncture_force: 0.01\n"                                      /* 20 */
    "      cutting_force: 0.02\n"                                       /* 21 */
    "      friction: 0.05\n"                                            /* 22 */
    "      friction_per_length: 0.3\n"                                  /* 23 */
    "      spacing: 0.0005\n"                                           /* 24 */
    "  - name: electrode-1_A\n"                                         /* 25 */
    "    length: 0.04\n"                                                /* 26 */
    "    radius: 0.0004\n"                                              /* 27 */
    "    material: {young: 2.0e11}\n"                                   /* 28 */
    "    base: [0, 0, 0]\n"                                             /* 29 */
    "    direction: [1.0e-200, 0, 0]\n"                                 /* 30 */
    "    inside: cannula\n"                                             /* 31 */
    "    release: 1.66\n"                                               /* 32 */
    "targets:\n"                                                        /* 33 */
    "  - {name: STN, point: [0.02, 0.01, 0.01], tool: electrode-1_A}\n" /* 34 */
    "  - {name: \"2\", point: [0, 0, -1], tool: cannula}\n";            /* 35 */

/* Every value of tools_text, compared field by field (where strings excluded). */
static void check_tools(const nh_scene *s, const char *what) {
  EXPECT(s->n_tools == 2 && s->n_targets == 2, "%s: n_tools %d n_targets %d", what, s->n_tools,
         s->n_targets);
  if (s->n_tools != 2 || s->n_targets != 2) return;
  const nh_tool_spec *c = &s->tools[0], *e = &s->tools[1];
  EXPECT_STR(c->name, "cannula");
  EXPECT_NUM(c->length, 0.032);
  EXPECT_NUM(c->radius, 0.001);
  EXPECT_NUM(c->inner_radius, 0.0005);
  EXPECT(c->elements == 8, "%s: elements %d", what, c->elements);
  EXPECT_NUM(c->young, 5.0e7);
  EXPECT_NUM(c->poisson, 0.25);
  EXPECT_NUM(c->density, 7900);
  EXPECT_NUM(c->damping_mass, 0.5);
  EXPECT_NUM(c->damping_stiffness, 0.002);
  EXPECT_NUM(c->base[0], -0.001);
  EXPECT_NUM(c->base[2], 0.01);
  /* [0, 3, -4] has length 5. */
  EXPECT_NUM(c->direction[0], 0);
  EXPECT_NUM(c->direction[1], 0.6);
  EXPECT_NUM(c->direction[2], -0.8);
  EXPECT(c->n_motion == 2, "%s: n_motion %d", what, c->n_motion);
  if (c->n_motion == 2) {
    EXPECT_NUM(c->motion[0].until, 1.5);
    EXPECT_NUM(c->motion[0].speed, 0.02);
    EXPECT_NUM(c->motion[1].until, 2.0);
    EXPECT_NUM(c->motion[1].speed, -0.01);
  }
  EXPECT_NUM(c->puncture_force, 0.01);
  EXPECT_NUM(c->cutting_force, 0.02);
  EXPECT_NUM(c->friction, 0.05);
  EXPECT_NUM(c->friction_per_length, 0.3);
  EXPECT_NUM(c->spacing, 0.0005);
  EXPECT(c->inside == -1, "%s: cannula inside %d, expected -1", what, c->inside);
  EXPECT(isinf(c->release) && c->release > 0, "%s: cannula release %g, expected +inf", what,
         c->release);

  /* The electrode: given values, and the documented defaults for the rest. */
  EXPECT_STR(e->name, "electrode-1_A");
  EXPECT_NUM(e->length, 0.04);
  EXPECT_NUM(e->radius, 0.0004);
  EXPECT_NUM(e->inner_radius, 0);
  EXPECT(e->elements == 16, "%s: default elements: expected 16, got %d", what, e->elements);
  EXPECT_NUM(e->young, 2.0e11);
  EXPECT_NUM(e->poisson, 0.3);
  EXPECT_NUM(e->density, 7800);
  EXPECT_NUM(e->damping_mass, 0);
  EXPECT_NUM(e->damping_stiffness, 0);
  for (int k = 0; k < 3; ++k) EXPECT_NUM(e->base[k], 0);
  /* [1e-200, 0, 0]: its squared length underflows, the unit vector does not. */
  EXPECT_NUM(e->direction[0], 1);
  EXPECT_NUM(e->direction[1], 0);
  EXPECT_NUM(e->direction[2], 0);
  EXPECT(e->n_motion == 0 && e->motion == NULL, "%s: electrode motion %d", what, e->n_motion);
  EXPECT_NUM(e->puncture_force, 0);
  EXPECT_NUM(e->cutting_force, 0);
  EXPECT_NUM(e->friction, 0);
  EXPECT_NUM(e->friction_per_length, 0);
  EXPECT_NUM(e->spacing, 0);
  EXPECT(e->inside == 0, "%s: electrode inside %d, expected 0 (cannula)", what, e->inside);
  EXPECT_NUM(e->release, 1.66);

  EXPECT_STR(s->targets[0].name, "STN");
  EXPECT_NUM(s->targets[0].point[0], 0.02);
  EXPECT_NUM(s->targets[0].point[1], 0.01);
  EXPECT(s->targets[0].tool == 1, "%s: targets.0.tool %d, expected 1", what, s->targets[0].tool);
  EXPECT_STR(s->targets[1].name, "2");
  EXPECT_NUM(s->targets[1].point[2], -1);
  EXPECT(s->targets[1].tool == 0, "%s: targets.1.tool %d, expected 0", what, s->targets[1].tool);
}

static void test_tools(void) {
  char text[4096], where[NH_WHERE_MAX];
  snprintf(text, sizeof text, "%s%s", minimal, tools_text);
  const char *path = write_scene("tools.yaml", text);
  nh_scene *s = load_ok(path, 0, NULL, __LINE__);
  if (!s) return;
  check_tools(s, "tools.yaml");
  if (s->n_tools == 2 && s->n_targets == 2) {
    snprintf(where, sizeof where, "%s:7: tools.0", path);
    EXPECT_STR(s->tools[0].where, where);
    snprintf(where, sizeof where, "%s:25: tools.1", path);
    EXPECT_STR(s->tools[1].where, where);
    snprintf(where, sizeof where, "%s:35: targets.1", path);
    EXPECT_STR(s->targets[1].where, where);
  }

  /* `check` prints every tool and target (the summary is for people: only
   * its key facts are checked). */
  FILE *f = tmpfile();
  if (f) {
    char printed[8192] = "";
    nh_scene_print(s, f);
    rewind(f);
    size_t n = fread(printed, 1, sizeof printed - 1, f);
    printed[n] = '\0';
    fclose(f);
    static const char *const expected[] = {
        "tools     2\n",
        "cannula: length 0.032 m, radius 0.001 m, inner radius 0.0005 m",
        "direction [0, 0.6, -0.8]",
        "motion 0.02 m/s until 1.5 s\n",
        "-0.01 m/s until 2 s, then at rest\n",
        "electrode-1_A: length 0.04 m, radius 0.0004 m (solid), 16 beam elements\n",
        "inside cannula, released at 1.66 s\n",
        "targets   2\n",
        "STN at [0.02, 0.01, 0.01] m, distance to the tip of electrode-1_A\n",
    };
    for (size_t i = 0; i < sizeof expected / sizeof expected[0]; ++i)
      EXPECT(strstr(printed, expected[i]), "print: expected '%s' in:\n%s", expected[i], printed);
  }

  /* The scene as run reads back to the same tools and targets. */
  const char *again = write_scene("tools_as_run.yaml", s->yaml);
  nh_scene *t = load_ok(again, 0, NULL, __LINE__);
  if (t) {
    check_tools(t, "tools_as_run.yaml");
    nh_scene_destroy(&t);
  }
  nh_scene_destroy(&s);

  /* Overrides reach into tools and targets by index, like any list. */
  path = write_scene("tools.yaml", text);
  const char *sets[] = {
      "tools.0.interaction.friction=0.1",        /* a value in the file */
      "tools.1.elements=4",                      /* a key the file leaves out */
      "tools.1.release=2.5",                     /* the nested tool's release */
      "tools.1.motion=[{until: 1, speed: 0.5}]", /* a list of mappings, absent from the file */
      "tools.0.direction=[1e300, -1e300, 0]",    /* huge, but not too long to normalise */
      "targets.0.tool=cannula",                  /* a target moved to the other tool */
      "targets.1={name: T2, point: [1, 2, 3], tool: electrode-1_A}", /* a whole entry */
  };
  int n = (int)(sizeof sets / sizeof sets[0]);
  s = load_ok(path, n, sets, __LINE__);
  if (!s) return;
  if (s->n_tools == 2 && s->n_targets == 2) {
    EXPECT_NUM(s->tools[0].friction, 0.1);
    EXPECT_NUM(s->tools[0].puncture_force, 0.01); /* the rest of the section is kept */
    EXPECT(s->tools[1].elements == 4, "elements: expected 4, got %d", s->tools[1].elements);
    EXPECT_NUM(s->tools[1].release, 2.5);
    EXPECT(s->tools[1].n_motion == 1, "n_motion: expected 1, got %d", s->tools[1].n_motion);
    if (s->tools[1].n_motion == 1) {
      EXPECT_NUM(s->tools[1].motion[0].until, 1);
      EXPECT_NUM(s->tools[1].motion[0].speed, 0.5);
    }
    EXPECT_NUM(s->tools[0].direction[0], sqrt(0.5));
    EXPECT_NUM(s->tools[0].direction[1], -sqrt(0.5));
    EXPECT_NUM(s->tools[0].direction[2], 0);
    EXPECT(s->targets[0].tool == 0, "targets.0.tool: expected 0, got %d", s->targets[0].tool);
    EXPECT_STR(s->targets[1].name, "T2");
    EXPECT(s->targets[1].tool == 1, "targets.1.tool: expected 1, got %d", s->targets[1].tool);
    EXPECT_STR(s->targets[1].where, "--set:7: targets.1");
    snprintf(where, sizeof where, "%s:7: tools.0", path);
    EXPECT_STR(s->tools[0].where, where); /* an override of one key keeps the file's place */
  }
  nh_scene_destroy(&s);

  /* An override is checked like the file: a nested host by --set. */
  const char *bad[] = {"tools.0.inside=electrode-1_A"};
  nh_error_clear();
  int rc = nh_scene_load(path, 1, bad, &s);
  EXPECT(rc == NH_ERR_INPUT && s == NULL, "host listed after: rc %d", rc);
  EXPECT_STR(nh_error_message(), "--set:1: tools.0.inside: 'electrode-1_A' is tools.1, listed "
                                 "after this tool: list the host first (--set "
                                 "tools.0.inside=electrode-1_A)");
  nh_scene_destroy(&s);
}

/* ---- gravity schedule, buoyancy, planned trajectories ---- */

/* `minimal` (lines 1-5) followed by a scheduled gravity, buoyancy and two
 * planned tools. The numbers are picked so that every resolved time is
 * plain arithmetic: target − entry = [0.004, 0.006, 0.012], of length 0.014
 * (2² + 3² + 6² = 7²), direction [2, 3, 6] / 7. */
static const char *plans_text =
    "gravity: {vector: [0, 0, -10], schedule: [[0, 0], [1, 1]]}\n"
    "tools:\n"
    "  - name: cannula\n"
    "    length: 0.03\n"
    "    radius: 0.001\n"
    "    material: {young: 5.0e7}\n"
    "    trajectory: {entry: [0.01, 0, 0], target: T, standoff: 0.001}\n"
    "    motion:\n"
    "      - {until: 0.5, speed: 0.002}\n"
    "      - {until: target, speed: 0.01}\n"
    "      - {until: 2.5, speed: 0}\n"
    "      - {until: start, speed: -0.02}\n"
    "  - name: electrode\n"
    "    length: 0.04\n"
    "    radius: 0.0004\n"
    "    material: {young: 2.0e11}\n"
    "    trajectory: {entry: [0.01, 0, 0], target: T, standoff: 0.003}\n"
    "    inside: cannula\n"
    "    release: target\n"
    "    motion:\n"
    "      - {until: 1, speed: 0.05}\n"
    "      - {until: target, speed: 0.004}\n"
    "      - {until: start, speed: -0.01}\n"
    "targets:\n"
    "  - {name: T, point: [0.014, 0.006, 0.012], tool: electrode}\n";

static void check_plans(const nh_scene *s, const char *what) {
  EXPECT(s->n_tools == 2 && s->n_targets == 1, "%s: n_tools %d n_targets %d", what, s->n_tools,
         s->n_targets);
  if (s->n_tools != 2 || s->n_targets != 1) return;
  const nh_tool_spec *c = &s->tools[0], *e = &s->tools[1];
  static const double dir[3] = {2.0 / 7, 3.0 / 7, 6.0 / 7}, entry[3] = {0.01, 0, 0};
  EXPECT(c->planned && e->planned && c->target == 0 && e->target == 0,
         "%s: planned %d %d, target %d %d", what, c->planned, e->planned, c->target, e->target);
  for (int k = 0; k < 3; ++k) {
    EXPECT_NUM(c->direction[k], dir[k]);
    EXPECT_NUM(e->direction[k], dir[k]);
    /* the tip (base + length · direction) at entry − standoff · direction */
    EXPECT_NUM(c->base[k], entry[k] - (0.001 + 0.03) * dir[k]);
    EXPECT_NUM(e->base[k], entry[k] - (0.003 + 0.04) * dir[k]);
  }
  EXPECT_NUM(c->standoff, 0.001);
  EXPECT_NUM(c->depth, 0.001 + 0.014);
  EXPECT_NUM(e->depth, 0.003 + 0.014);
  EXPECT(c->n_motion == 4 && e->n_motion == 3, "%s: n_motion %d %d", what, c->n_motion,
         e->n_motion);
  if (c->n_motion != 4 || e->n_motion != 3) return;
  /* cannula: 0.5 s at 2 mm/s is 1 mm; the other 14 mm of D = 15 mm at 10 mm/s
   * take 1.4 s; held until 2.5 s; back over 15 mm at 20 mm/s: 0.75 s. */
  EXPECT_NUM(c->motion[0].until, 0.5);
  EXPECT_NUM(c->motion[1].until, 0.5 + 0.014 / 0.01);
  EXPECT_NUM(c->motion[2].until, 2.5);
  EXPECT_NUM(c->motion[3].until, 2.5 + 0.015 / 0.02);
  EXPECT(c->motion[0].kind == NH_UNTIL_TIME && c->motion[1].kind == NH_UNTIL_TARGET &&
             c->motion[3].kind == NH_UNTIL_START,
         "%s: kinds %d %d %d", what, c->motion[0].kind, c->motion[1].kind, c->motion[3].kind);
  /* electrode: released when the cannula's until: target ends (1.9 s); its
   * first segment ends before that, so it moves with the cannula's 15 mm;
   * the other 2 mm of D = 17 mm at 4 mm/s take 0.5 s; back over 17 mm at
   * 10 mm/s: 1.7 s. */
  EXPECT(e->release_target, "%s: release_target %d", what, e->release_target);
  EXPECT_NUM(e->release, 1.9);
  EXPECT_NUM(e->motion[0].until, 1);
  EXPECT_NUM(e->motion[1].until, 1.9 + 0.002 / 0.004);
  EXPECT_NUM(e->motion[2].until, 2.4 + 0.017 / 0.01);

  /* gravity by its schedule (tools), and the tissue's without buoyancy */
  static const double g_at[][2] = {{-1, 0}, {0, 0}, {0.25, -2.5}, {1, -10}, {5, -10}};
  for (size_t i = 0; i < sizeof g_at / sizeof g_at[0]; ++i) {
    double g[3], gt[3];
    nh_scene_gravity(s, g_at[i][0], g);
    nh_scene_tissue_gravity(s, g_at[i][0], gt);
    EXPECT(g[0] == 0 && g[1] == 0 && fabs(g[2] - g_at[i][1]) <= 1e-15,
           "%s: gravity at %g s: expected [0, 0, %g], got [%g, %g, %.17g]", what, g_at[i][0],
           g_at[i][1], g[0], g[1], g[2]);
    EXPECT(gt[2] == g[2], "%s: tissue gravity without buoyancy at %g s: %.17g, expected %.17g",
           what, g_at[i][0], gt[2], g[2]);
  }
}

/* nh_scene_motion_integral, the one integral of a tool's motion: segments
 * (until 1, speed 2, spin 0.5), (until 3, speed -1, spin 0), (until 4, speed
 * 0.5, spin 1), at rest after. Expected values are the areas under the
 * piecewise-constant speed (spin), summed by hand; all are exact in binary. */
static void test_motion_integral(void) {
  nh_motion m[3] = {{.until = 1, .speed = 2, .spin = 0.5},
                    {.until = 3, .speed = -1, .spin = 0},
                    {.until = 4, .speed = 0.5, .spin = 1}};
  nh_tool_spec t = {.n_motion = 3, .motion = m};
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0, 0, 0), 0);
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0, 0.5, 0), 1);      /* 2 x 0.5 */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0, 2, 0), 1);        /* 2 x 1 - 1 x 1 */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0, 10, 0), 0.5);     /* 2 - 2 + 0.5, then at rest */
  EXPECT_NUM(nh_scene_motion_integral(&t, 1, 0, 10, 0), 2);       /* the first segment only */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 2, 3.5, 0), -0.75);  /* -1 x 1 + 0.5 x 0.5 */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 5, 4, 0), 0);        /* an empty interval */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0, 10, 1), 1.5);     /* spin: 0.5 x 1 + 1 x 1 */
  EXPECT_NUM(nh_scene_motion_integral(&t, 3, 0.5, 3.5, 1), 0.75); /* 0.5 x 0.5 + 1 x 0.5 */
}

static void test_plans(void) {
  char text[4096];
  snprintf(text, sizeof text, "%s%s", minimal, plans_text);
  const char *path = write_scene("plans.yaml", text);
  nh_scene *s = load_ok(path, 0, NULL, __LINE__);
  if (!s) return;
  check_plans(s, "plans.yaml");

  FILE *f = tmpfile();
  if (f) {
    char printed[8192] = "";
    nh_scene_print(s, f);
    rewind(f);
    size_t n = fread(printed, 1, sizeof printed - 1, f);
    printed[n] = '\0';
    fclose(f);
    static const char *const expected[] = {
        "gravity   [0, 0, -10] m/s^2, schedule [[0, 0], [1, 1]]\n",
        "to target T [0.014, 0.006, 0.012] m, standoff 0.001 m: planned depth 0.015 m\n",
        "0.01 m/s until 1.9 s (until: target)\n",
        "-0.02 m/s until 3.25 s (until: start), then at rest\n",
        "0.004 m/s until 2.4 s (until: target)\n",
        "-0.01 m/s until 4.1 s (until: start), then at rest\n",
        "released at 1.9 s (release: target",
    };
    for (size_t i = 0; i < sizeof expected / sizeof expected[0]; ++i)
      EXPECT(strstr(printed, expected[i]), "print: expected '%s' in:\n%s", expected[i], printed);
  }

  /* The scene as run (symbolic words kept) reads back to the same plans. */
  const char *again = write_scene("plans_as_run.yaml", s->yaml);
  nh_scene *t = load_ok(again, 0, NULL, __LINE__);
  if (t) {
    check_plans(t, "plans_as_run.yaml");
    nh_scene_destroy(&t);
  }
  nh_scene_destroy(&s);

  /* Buoyancy: the tissue carries (b0 − b(t)) g(t), b(t) = b0 + (b1 − b0) s(t).
   * With s stepping from 0 at 1 s to 1 at 2 s and b0 − b1 = 0.5: */
  path = write_scene("plans.yaml", text);
  const char *sets[] = {"tissue.buoyancy={before: 0.75, after: 0.25, schedule: [[1, 0], [2, 1]]}"};
  s = load_ok(path, 1, sets, __LINE__);
  if (s) {
    EXPECT(s->tissue.buoyant, "buoyant: expected 1");
    static const double at[][2] = {
        {0.5, 0}, {1, 0}, {1.5, -10 * 0.5 * 0.5}, {2, -10 * 0.5}, {3, -10 * 0.5}};
    for (size_t i = 0; i < sizeof at / sizeof at[0]; ++i) {
      double g[3], gt[3];
      nh_scene_tissue_gravity(s, at[i][0], gt);
      nh_scene_gravity(s, at[i][0], g);
      EXPECT(fabs(gt[2] - at[i][1]) <= 1e-15 && gt[0] == 0 && gt[1] == 0,
             "tissue gravity at %g s: expected %g, got %.17g", at[i][0], at[i][1], gt[2]);
      EXPECT(g[2] == (at[i][0] >= 1 ? -10 : -5), "tools' gravity at %g s: %g (not buoyed)",
             at[i][0], g[2]);
    }
    nh_scene_destroy(&s);
  }
  /* Without a schedule the change is a step at t = 0; before = after: none. */
  const char *step[] = {"tissue.buoyancy={before: 1, after: 0.25}", "gravity=[0, 0, -10]"};
  s = load_ok(path, 2, step, __LINE__);
  if (s) {
    double g[3];
    nh_scene_tissue_gravity(s, 0.01, g);
    EXPECT(g[2] == -7.5, "step buoyancy at 0.01 s: expected -7.5, got %.17g", g[2]);
    nh_scene_destroy(&s);
  }
  const char *same[] = {"tissue.buoyancy={before: 0.3, after: 0.3}"};
  s = load_ok(path, 1, same, __LINE__);
  if (s) {
    double g[3];
    nh_scene_tissue_gravity(s, 2.0, g);
    EXPECT(g[0] == 0 && g[1] == 0 && g[2] == 0, "before = after: expected 0, got %g", g[2]);
    nh_scene_destroy(&s);
  }
}

/* The head of the small bad scenes below (4 lines), and one valid tool as an
 * unclosed flow mapping, so that a case can add keys before its '}'. */
#define W_HEAD                                                                                     \
  "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"                              \
  "  material: {young: 1, poisson: 0.3}\n"
#define W_TOOL(name)                                                                               \
  "  - {name: " name ", length: 1, radius: 0.1, material: {young: 1}, base: [0,0,0], "             \
  "direction: [1,0,0]"

/* Bad scenes: the message, exactly or by its start ("FILE:LINE: KEY: "). */
static void test_errors(void) {
  static const struct {
    const char *name;   /* file name in DIR */
    const char *text;   /* the scene */
    const char *set;    /* one override, or NULL */
    const char *prefix; /* the message starts with DIR/name + this (or with this for --set) */
  } cases[] = {
      {"wrong_type.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  grid: [8, abc, 4]\n  material: {young: 1, poisson: 0.3}\n",
       NULL, ":4: tissue.grid.1: expected an integer, got 'abc'"},
      {"short_list.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\n",
       NULL, ":3: tissue.domain.box.min: expected a list of 3 numbers, got 2 entries"},
      {"unknown.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3, densty: 3}\n",
       NULL, ":4: tissue.material.densty: unknown key (did you mean 'density'?)"},
      {"missing_tissue.yaml", "# comment\n\nname: w\ntime: {steps: 3}\n", NULL,
       ":3: tissue: required key missing"},
      {"missing_young.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material:\n    poisson: 0.3\n",
       NULL, ":5: tissue.material.young: required key missing"},
      {"nu.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material:\n    young: 1\n    poisson: 0.5\n",
       NULL, ":6: tissue.material.poisson: 0.5 is not below 0.5: incompressible"},
      {"young.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material:\n    young: -2\n    poisson: 0.3\n",
       NULL, ":5: tissue.material.young: must be greater than 0, got -2"},
      {"both.yaml", "name: w\ntime:\n  end: 1\n  steps: 3\n", NULL,
       ":4: time.steps: give either time.end or time.steps, not both"},
      {"box.yaml",
       "name: w\ntissue:\n  domain:\n    box:\n      min: [0, 0, 0]\n      max: [1, 1, 0]\n"
       "  material: {young: 1, poisson: 0.3}\n",
       NULL,
       ":6: tissue.domain.box.max: must be greater than min in every component (z: max 0, "
       "min 0)"},
      {"mask.yaml", "name: w\ntissue:\n  domain:\n    mask: {file: b.nii}\n", NULL,
       ":4: tissue.domain.mask.file: cannot read "},
      {"brain.yaml", "name: w\ntissue:\n  domain:\n    brain: {size: [1, 0, 1]}\n", NULL,
       ":4: tissue.domain.brain.size.1: must be greater than 0, got 0"},
      {"sphere.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\n  fixed:\n    - sphere: {center: [0,0,0], radius: "
       "0}\n",
       NULL, ":6: tissue.fixed.0.sphere.radius: must be greater than 0, got 0"},
      {"two_shapes.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\n  loads:\n    - sphere: {center: [0,0,0], radius: "
       "1}\n"
       "      box: {min: [0,0,0], max: [1,1,1]}\n      force: [0, 0, 1]\n",
       NULL,
       ":7: tissue.loads.0.box: give exactly one of box, sphere, cylinder, label (sphere is "
       "already given)"},
      {"dup.yaml", "name: w\nname: v\n", NULL, ":2: name: duplicate key (first given at line 1)"},
      {"alias.yaml", "name: &n w\n", NULL, ":1: name: anchors (&n) and aliases are not supported"},
      {"docs.yaml", "name: w\n---\nname: v\n", NULL,
       ":2: a second YAML document starts here; a scene is one document"},
      {"malformed.yaml", "name: w\ntissue:\n  grid: [8, 4\n", NULL, ":4: malformed YAML: "},
      {"badname.yaml", "name: a/b\n", NULL, ":1: name: 'a/b' may only contain letters"},
      {"empty.yaml", "", NULL, ":1: the scene is empty"},
      {"schedule.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\n  loads:\n    - box: {min: [0,0,0], max: [1,1,1]}\n"
       "      force: [0, 0, 1]\n      schedule:\n        - [0, 0]\n        - [0, 1]\n",
       NULL, ":10: tissue.loads.0.schedule.1.0: times must increase strictly (0 after 0)"},
      {"probes.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nprobes:\n  - {name: a, point: [0, 0, 0]}\n"
       "  - {name: a, point: [1, 0, 0]}\n",
       NULL, ":7: probes.1.name: 'a' is already the name of probes.0"},
      {"set_index.yaml", NULL, "tissue.fixed.3.box.min=[0,0,0]",
       "--set:1: tissue.fixed.3: index 3 beyond the list of 1 (--set "
       "tissue.fixed.3.box.min=[0,0,0])"},
      {"set_unknown.yaml", NULL, "tissue.material.stiffnes=3",
       "--set:1: tissue.material.stiffnes: unknown key (--set tissue.material.stiffnes=3)"},
      {"set_type.yaml", NULL, "tissue.grid=[16,x,8]",
       "--set:1: tissue.grid.1: expected an integer, got 'x' (--set tissue.grid=[16,x,8])"},
      {"set_syntax.yaml", NULL, "tissue.grid",
       "--set:1: expected KEY=VALUE (e.g. tissue.grid=[16,8,8]), got 'tissue.grid'"},
      {"set_malformed.yaml", NULL, "tissue.grid=[1,2", "--set:1: tissue.grid: malformed YAML: "},
      {"set_tools.yaml", NULL, "tools.0.length=1",
       "--set:1: tools.0: index 0 beyond the list of 0 (tools is absent) (--set "
       "tools.0.length=1)"},
      /* tools and targets (W_HEAD is 4 lines: `tools:` is line 5, the first tool line 6) */
      {"tools_map.yaml", W_HEAD "tools: {name: a}\n", NULL,
       ":5: tools: expected a list, got a mapping"},
      {"tool_map.yaml", W_HEAD "tools:\n  - needle\n", NULL,
       ":6: tools.0: expected a tool {name: ..., length: ..., radius: ..., material: ..., base: "
       "[x, y, z], direction: [x, y, z]}, got 'needle'"},
      {"tool_name.yaml", W_HEAD "tools:\n" W_TOOL("a.b") "}\n", NULL,
       ":6: tools.0.name: 'a.b' must be non-empty and contain only letters, digits, '_' and '-' "
       "(it names the output file NAME.pvd)"},
      {"tool_reserved.yaml", W_HEAD "tools:\n" W_TOOL("Points") "}\n", NULL,
       ":6: tools.0.name: 'Points' is taken: the output folder already holds points.pvd"},
      {"tool_case.yaml", W_HEAD "tools:\n" W_TOOL("a") "}\n" W_TOOL("A") "}\n", NULL,
       ":7: tools.1.name: 'A' differs from the name of tools.0 ('a') only in case"},
      {"tool_missing_material.yaml",
       W_HEAD "tools:\n  - {name: a, length: 1, radius: 0.1, base: [0,0,0], direction: [1,0,0]}\n",
       NULL, ":6: tools.0.material: required key missing"},
      {"tool_density.yaml",
       W_HEAD "tools:\n  - {name: a, length: 1, radius: 0.1, material: {young: 1, density: -1}, "
              "base: [0,0,0], direction: [1,0,0]}\n",
       NULL, ":6: tools.0.material.density: must be at least 0, got -1"},
      {"tool_elements.yaml", W_HEAD "tools:\n" W_TOOL("a") ", elements: 0}\n", NULL,
       ":6: tools.0.elements: must be at least 1, got 0"},
      {"tool_interaction.yaml", W_HEAD "tools:\n" W_TOOL("a") ", interaction: {frictoin: 1}}\n",
       NULL, ":6: tools.0.interaction.frictoin: unknown key (did you mean 'friction'?)"},
      {"tool_spacing.yaml", W_HEAD "tools:\n" W_TOOL("a") ", interaction: {spacing: -1}}\n", NULL,
       ":6: tools.0.interaction.spacing: must be at least 0, got -1"},
      {"tool_motion_zero.yaml", W_HEAD "tools:\n" W_TOOL("a") ", motion: [{until: 0, speed: 1}]}\n",
       NULL, ":6: tools.0.motion.0.until: must be greater than 0, got 0"},
      {"tool_motion_item.yaml", W_HEAD "tools:\n" W_TOOL("a") ", motion: [[1, 2]]}\n", NULL,
       ":6: tools.0.motion.0: expected a segment {until: TIME, speed: SPEED}, got a list"},
      {"tool_motion_speed.yaml", W_HEAD "tools:\n" W_TOOL("a") ", motion: [{until: 1}]}\n", NULL,
       ":6: tools.0.motion.0.speed: required key missing"},
      {"tool_inside_self.yaml", W_HEAD "tools:\n" W_TOOL("a") ", inside: a}\n", NULL,
       ":6: tools.0.inside: a tool cannot be inside itself"},
      {"tool_inside_later.yaml", W_HEAD "tools:\n" W_TOOL("a") ", inside: b}\n" W_TOOL("b") "}\n",
       NULL, ":6: tools.0.inside: 'b' is tools.1, listed after this tool: list the host first"},
      {"tool_inside_nested.yaml",
       W_HEAD
       "tools:\n" W_TOOL("a") "}\n" W_TOOL("b") ", inside: a}\n" W_TOOL("c") ", inside: b}\n",
       NULL,
       ":8: tools.2.inside: 'b' (tools.1) is itself inside 'a': tools nest one level deep only"},
      {"tool_release.yaml",
       W_HEAD "tools:\n" W_TOOL("a") "}\n" W_TOOL("b") ", inside: a, release: -1}\n", NULL,
       ":7: tools.1.release: must be at least 0, got -1"},
      {"target_name.yaml",
       W_HEAD "tools:\n" W_TOOL("a") "}\ntargets:\n  - {name: t, point: [0,0,0], tool: a}\n"
                                     "  - {name: t, point: [1,0,0], tool: a}\n",
       NULL, ":9: targets.1.name: 't' is already the name of targets.0"},
      {"target_comma.yaml",
       W_HEAD "tools:\n" W_TOOL("a") "}\ntargets:\n  - {name: \"t,1\", point: [0,0,0], tool: a}\n",
       NULL, ":8: targets.0.name: 't,1' must be non-empty, without commas, quotes or tabs"},
      {"target_no_tools.yaml", W_HEAD "targets:\n  - {name: t, point: [0,0,0], tool: a}\n", NULL,
       ":6: targets.0.tool: no tool named 'a' (the scene has no tools)"},
      {"target_no_tool.yaml",
       W_HEAD "tools:\n" W_TOOL("a") "}\ntargets:\n  - {name: t, point: [0,0,0]}\n", NULL,
       ":8: targets.0.tool: required key missing"},
      {"target_key.yaml",
       W_HEAD "tools:\n" W_TOOL("a") "}\ntargets:\n  - {name: t, point: [0,0,0], tools: a}\n", NULL,
       ":8: targets.0.tools: unknown key (did you mean 'tool'?)"},
      {"set_scalar.yaml", NULL, "name.first=x",
       "--set:1: name.first: name is a single value, not a mapping or a list"},
      {"adapt_strategy.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking:\n    strategy: largest\n",
       NULL, ":7: adapt.marking.strategy: expected max or dorfler, got 'largest'"},
      {"adapt_theta.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking: {strategy: max, theta: 1}\n",
       NULL, ":6: adapt.marking.theta: must lie in (0, 1), got 1"},
      {"adapt_theta0.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking:\n    theta: 0\n",
       NULL, ":7: adapt.marking.theta: must lie in (0, 1), got 0"},
      {"adapt_theta_dorfler.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking:\n    strategy: dorfler\n"
       "    theta: 0.5\n",
       NULL, ":8: adapt.marking.theta: applies to strategy max only"},
      {"adapt_fraction_max.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking:\n    fraction: 0.5\n",
       NULL,
       ":7: adapt.marking.fraction: applies to strategy dorfler only (the strategy is max, "
       "the default"},
      {"adapt_fraction.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  marking:\n    strategy: dorfler\n"
       "    fraction: 1.25\n",
       NULL, ":8: adapt.marking.fraction: must lie in (0, 1], got 1.25"},
      {"adapt_template.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  max_level: 3\n  template: hex9\n",
       NULL, ":7: adapt.template: no template named 'hex9' (cannot read "},
      {"adapt_template_path.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  template: nowhere/hex2.tmpl\n",
       NULL, ":6: adapt.template: cannot read the template file "},
      {"adapt_template_dir.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  template: sub/\n",
       NULL, ":6: adapt.template: cannot read the template file "},
      {"adapt_estimator.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt: {estimator: zz}\n",
       NULL, ":5: adapt.estimator: expected spr or goal, got 'zz'"},
      {"adapt_goal_spr.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  goal: [p]\n",
       NULL, ":6: adapt.goal: applies to estimator goal only (the estimator is spr, the default)"},
      {"adapt_goal_name.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  estimator: goal\n  goal: [p, q]\n"
       "probes:\n  - {name: p, point: [0.5, 0.5, 0.5]}\n",
       NULL, ":7: adapt.goal.1: no probe or target is named \"q\""},
      {"adapt_goal_none.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  estimator: goal\n",
       NULL, ":6: adapt.estimator: goal needs probes or targets to estimate (the scene has none)"},
      {"adapt_goal_lagrange.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  estimator: goal\n  hanging: lagrange\n",
       NULL, ":7: adapt.hanging: lagrange cannot be used with estimator goal"},
      {"adapt_tolerance.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  estimator: goal\n  tolerance: 0\n",
       NULL, ":7: adapt.tolerance: must be greater than 0, got 0"},
      {"adapt_coarsen.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  coarsen: {fraction: 1.5}\n",
       NULL, ":6: adapt.coarsen.fraction: must lie in (0, 1), got 1.5"},
      {"adapt_hanging.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  hanging: both\n",
       NULL, ":6: adapt.hanging: expected eliminate or lagrange, got 'both'"},
      {"adapt_level.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  max_level: -1\n",
       NULL, ":6: adapt.max_level: must be at least 0, got -1"},
      {"adapt_every.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  every: 0\n",
       NULL, ":6: adapt.every: must be at least 1, got 0"},
      {"adapt_size.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  min_size: -0.001\n",
       NULL, ":6: adapt.min_size: must be at least 0, got -0.001"},
      {"adapt_dofs.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  max_dofs: 1.5\n",
       NULL, ":6: adapt.max_dofs: expected an integer, got '1.5'"},
      {"adapt_key.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt:\n  max_levels: 3\n",
       NULL, ":6: adapt.max_levels: unknown key (did you mean 'max_level'?)"},
      {"adapt_list.yaml",
       "name: w\ntissue:\n  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
       "  material: {young: 1, poisson: 0.3}\nadapt: [spr]\n",
       NULL, ":5: adapt: expected a mapping, got a list"},
      {"set_adapt_theta.yaml", NULL, "adapt.marking.theta=1.5",
       "--set:1: adapt.marking.theta: must lie in (0, 1), got 1.5 (--set "
       "adapt.marking.theta=1.5)"},
      {"set_adapt_template.yaml", NULL, "adapt.template=hex9",
       "--set:1: adapt.template: no template named 'hex9'"},
  };
  const char *with_fixed = "name: w\n"
                           "tissue:\n"
                           "  domain: {box: {min: [0,0,0], max: [1,1,1]}}\n"
                           "  material: {young: 1, poisson: 0.3}\n"
                           "  fixed:\n"
                           "    - {box: {min: [0,0,0], max: [0,1,1]}}\n";
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    const char *path = write_scene(cases[i].name, cases[i].text ? cases[i].text : with_fixed);
    char expected[1024];
    if (cases[i].set)
      snprintf(expected, sizeof expected, "%s", cases[i].prefix);
    else
      snprintf(expected, sizeof expected, "%s%s", path, cases[i].prefix);
    nh_scene *s = NULL;
    nh_error_clear();
    int rc = nh_scene_load(path, cases[i].set ? 1 : 0, &cases[i].set, &s);
    const char *msg = nh_error_message();
    EXPECT(rc == NH_ERR_INPUT && s == NULL, "%s: expected NH_ERR_INPUT, got %d (%s)", cases[i].name,
           rc, msg);
    EXPECT(strncmp(msg, expected, strlen(expected)) == 0,
           "%s: message\n  expected to start with: %s\n  got:                    %s", cases[i].name,
           expected, msg);
    EXPECT(!strchr(msg, '\n'), "%s: the message must be one line: %s", cases[i].name, msg);
    nh_scene_destroy(&s);
  }
  nh_scene *s = NULL;
  char missing[512];
  snprintf(missing, sizeof missing, "%s/no_such_scene.yaml", dir);
  int rc = nh_scene_load(missing, 0, NULL, &s);
  EXPECT(rc == NH_ERR_INPUT && strstr(nh_error_message(), "no_such_scene.yaml: cannot open"),
         "missing file: rc %d, '%s'", rc, nh_error_message());
}

/* The key table (docs/scene.md compiled in): documented keys pass, under
 * list indices and region lists too; an undocumented one is a bug named. */
static void test_key_table(void) {
  static const char *const tissue[] = {"domain", "grid", "material", "buoyancy", NULL};
  static const char *const traj[] = {"entry", "target", "standoff", "aim", NULL};
  static const char *const sphere[] = {"center", "radius", NULL};
  static const char *const motion[] = {"until", "speed", NULL};
  static const char *const top[] = {"name", "time", "tools", "targets", "output", NULL};
  static const char *const bogus[] = {"grid", "gird", NULL};
  EXPECT_OK(nh_scene_keys_check("tissue", tissue));
  EXPECT_OK(nh_scene_keys_check("tools.3.trajectory", traj));
  EXPECT_OK(nh_scene_keys_check("tissue.loads.12.sphere", sphere));
  EXPECT_OK(nh_scene_keys_check("tools.0.motion.2", motion));
  EXPECT_OK(nh_scene_keys_check("", top));
  int rc = nh_scene_keys_check("tissue", bogus);
  EXPECT(rc == NH_ERR_INTERNAL && strstr(nh_error_message(), "tissue.gird"),
         "undocumented tissue.gird: rc %d, message '%s', expected NH_ERR_INTERNAL naming it", rc,
         nh_error_message());
  static const char *const half[] = {"entr", NULL}; /* a prefix of a key is not the key */
  rc = nh_scene_keys_check("tools.0.trajectory", half);
  EXPECT(rc == NH_ERR_INTERNAL, "tools.0.trajectory.entr accepted as documented (rc %d)", rc);

  /* Each key has one row: `needlehex keys` lists every key once (the
   * limits.* rows were once documented twice, in two wordings). */
  FILE *f = tmpfile();
  EXPECT(f != NULL, "tmpfile failed");
  if (!f) return;
  nh_scene_keys_print(f);
  rewind(f);
  static char keys[2048][128];
  int n = 0;
  char line[4096];
  while (fgets(line, sizeof line, f) && n < 2048) {
    line[strcspn(line, "\n")] = '\0';
    if (!line[0] || line[0] == ' ' || strchr(line, ' ')) continue; /* a key's notes, the header */
    for (int i = 0; i < n; i++) EXPECT(strcmp(keys[i], line) != 0, "key %s documented twice", line);
    snprintf(keys[n++], sizeof keys[0], "%.127s", line);
  }
  fclose(f);
  EXPECT(n > 100, "only %d keys listed by nh_scene_keys_print", n);
}

int main(void) {
  const char *tmp = getenv("TMPDIR");
  snprintf(dir, sizeof dir, "%s/nh_test_scene_XXXXXX", tmp && tmp[0] ? tmp : "/tmp");
  if (!mkdtemp(dir)) {
    perror("mkdtemp");
    return 1;
  }
  /* adapt.template names resolve in NH_TEMPLATES_DIR: a folder of this test,
   * holding empty hex2.tmpl and hex3.tmpl (the scene module only checks that
   * the file is readable). */
  snprintf(templates_dir, sizeof templates_dir, "%s/tmpl", dir);
  if (mkdir(templates_dir, 0700) != 0) {
    perror(templates_dir);
    return 1;
  }
  touch("tmpl/hex2.tmpl");
  touch("tmpl/hex3.tmpl");
  setenv("NH_TEMPLATES_DIR", templates_dir, 1);
  test_key_table();
  test_defaults();
  test_values_and_where();
  test_steps_from_end();
  test_overrides();
  test_schedule();
  test_adapt();
  test_tools();
  test_motion_integral();
  test_plans();
  test_errors(); /* after test_adapt, which creates DIR/sub for adapt_template_dir.yaml */
  if (nh_test_failures == 0) {
    /* Clean up only on success, so a failure leaves its scenes to look at. */
    char cmd[512];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", dir);
  } else {
    fprintf(stderr, "test_scene: %d failure%s (scenes kept in %s)\n", nh_test_failures,
            nh_test_failures == 1 ? "" : "s", dir);
  }
  return nh_test_failures ? 1 : 0;
}
