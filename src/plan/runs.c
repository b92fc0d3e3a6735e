/* runs.c — one round of candidate simulations of the steering planner, and
 * what a finished run's folder says.
 *
 * A candidate is the scene with overrides (the user's, then the plan's: the
 * tool's motion and the end time), run into its own folder OUT/run_NN. With
 * --workers N (N >= 2) the round's candidates run as child processes of
 * this one, `needlehex run SCENE --set ... --out OUT/run_NN --overwrite
 * --quiet` (the program itself, /proc/self/exe), at most N at a time, each
 * on one thread (OMP_NUM_THREADS=1: N runs on N cores do not compete inside
 * a run; results do not depend on the thread count), as the study engine
 * (tools/study_engine.py) runs its variants; a child is killed if the
 * planner dies (PR_SET_PDEATHSIG) and its stderr goes to OUT/run_NN.log,
 * removed when it succeeds. Without, they run one after another in this
 * process. Either way the result is read back from the folder, so both
 * give the same numbers: the tip's path (tools.csv rows of the tool inside
 * the tissue, depth > 0), the tool's twist, and the last step's tip and
 * target (targets.csv): the miss tip − target. */
#include "plan/plan_impl.h"

#include "io/io.h"
#include "sim/sim.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

void nh_candidate_free(nh_candidate *c) {
  for (int i = 0; i < c->n_sets; i++) free(c->sets[i]);
  free(c->sets);
  c->sets = NULL, c->n_sets = 0;
}

int nh_candidate_set(nh_candidate *c, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(NULL, 0, fmt, ap);
  va_end(ap);
  char *text = n >= 0 ? nh_calloc((size_t)n + 1, 1) : NULL;
  if (text) {
    va_start(ap, fmt);
    vsnprintf(text, (size_t)n + 1, fmt, ap);
    va_end(ap);
  }
  int cap = c->n_sets; /* grown one at a time: the capacity is the count */
  if (!text || nh_grow((void **)&c->sets, &cap, c->n_sets + 1, sizeof *c->sets)) {
    free(text);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan overrides");
  }
  c->sets[c->n_sets++] = text;
  return NH_OK;
}

void nh_run_result_free(nh_run_result *r) {
  free(r->path), free(r->depth), free(r->time);
  r->path = r->depth = r->time = NULL, r->n = 0;
}

/* ---- reading the folder ---- */

enum { NH_CSV_FIELDS = 32 };

static int nh_read_tools(const char *dir, const char *tool, nh_run_result *r) {
  char path[NH_PATH_MAX + 64], line[4096], *f[NH_CSV_FIELDS];
  snprintf(path, sizeof path, "%s/tools.csv", dir);
  FILE *in = fopen(path, "r");
  if (!in) return NH_ERROR(NH_ERR_IO, "plan: cannot read %s: %s", path, strerror(errno));
  int col[7] = {-1, -1, -1, -1, -1, -1, -1}, cap = 0, rc = NH_OK;
  static const char *const names[7] = {"name", "tip_x", "tip_y", "tip_z", "depth", "twist", "time"};
  if (fgets(line, sizeof line, in)) {
    int n = nh_csv_split(line, f, NH_CSV_FIELDS);
    for (int k = 0; k < 7; k++) col[k] = nh_csv_column(f, n, names[k]);
  }
  for (int k = 0; k < 7 && !rc; k++) /* twist: only with torsion (docs/outputs.md) */
    if (col[k] < 0 && k != 5) rc = NH_ERROR(NH_ERR_IO, "plan: %s has no column %s", path, names[k]);
  r->n = 0;
  while (!rc && fgets(line, sizeof line, in)) {
    int n = nh_csv_split(line, f, NH_CSV_FIELDS);
    if (n <= col[5] || n <= col[6] || n <= col[4] || strcmp(f[col[0]], tool)) continue;
    double x[3] = {atof(f[col[1]]), atof(f[col[2]]), atof(f[col[3]])}, d = atof(f[col[4]]);
    memcpy(r->tip, x, sizeof x);
    r->twist = col[5] >= 0 ? atof(f[col[5]]) : 0.0;
    if (!(d > 0)) continue;
    int c1 = cap, c2 = cap, c3 = cap;
    if (nh_grow((void **)&r->path, &c1, r->n + 1, 3 * sizeof *r->path) ||
        nh_grow((void **)&r->depth, &c2, r->n + 1, sizeof *r->depth) ||
        nh_grow((void **)&r->time, &c3, r->n + 1, sizeof *r->time))
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", path);
    cap = c3;
    if (!rc) {
      memcpy(r->path + 3 * r->n, x, sizeof x);
      r->time[r->n] = atof(f[col[6]]);
      r->depth[r->n++] = d;
    }
  }
  fclose(in);
  return rc;
}

static int nh_read_target(const char *dir, const char *target, nh_run_result *r) {
  char path[NH_PATH_MAX + 64], line[4096], *f[NH_CSV_FIELDS];
  snprintf(path, sizeof path, "%s/targets.csv", dir);
  FILE *in = fopen(path, "r");
  if (!in) return NH_ERROR(NH_ERR_IO, "plan: cannot read %s: %s", path, strerror(errno));
  int col[4] = {-1, -1, -1, -1}, found = 0;
  static const char *const names[4] = {"name", "x", "y", "z"};
  if (fgets(line, sizeof line, in)) {
    int n = nh_csv_split(line, f, NH_CSV_FIELDS);
    for (int k = 0; k < 4; k++) col[k] = nh_csv_column(f, n, names[k]);
  }
  while (col[0] >= 0 && col[3] >= 0 && fgets(line, sizeof line, in)) {
    int n = nh_csv_split(line, f, NH_CSV_FIELDS);
    if (n <= col[3] || strcmp(f[col[0]], target)) continue;
    for (int k = 0; k < 3; k++) r->target[k] = atof(f[col[k + 1]]);
    found = 1;
  }
  fclose(in);
  if (!found) return NH_ERROR(NH_ERR_IO, "plan: %s has no row of target %s", path, target);
  return NH_OK;
}

static int nh_read_run(const char *dir, const char *tool, const char *target, nh_run_result *r) {
  NH_TRY(nh_read_tools(dir, tool, r));
  NH_TRY(nh_read_target(dir, target, r));
  for (int k = 0; k < 3; k++) r->miss[k] = r->tip[k] - r->target[k];
  r->distance = sqrt(r->miss[0] * r->miss[0] + r->miss[1] * r->miss[1] + r->miss[2] * r->miss[2]);
  return NH_OK;
}

/* ---- running ---- */

/* The overrides of candidate c after the user's (a new array of pointers). */
static const char **nh_all_sets(int n_user, const char *const *user, const nh_candidate *c) {
  const char **all = nh_calloc((size_t)(n_user + c->n_sets + 1), sizeof(char *));
  if (!all) return NULL;
  for (int i = 0; i < n_user; i++) all[i] = user[i];
  for (int i = 0; i < c->n_sets; i++) all[n_user + i] = c->sets[i];
  return all;
}

static int nh_run_here(const char *scene_path, int n_user, const char *const *user,
                       const nh_candidate *c, double *seconds) {
  const char **all = nh_all_sets(n_user, user, c);
  if (!all) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan run");
  nh_scene *scene = NULL;
  nh_sim *sim = NULL;
  double t0 = nh_time_now();
  int rc = nh_scene_load(scene_path, n_user + c->n_sets, all, &scene);
  if (!rc && strlen(c->dir) >= sizeof scene->output.dir)
    rc = NH_ERROR(NH_ERR_INPUT, "plan run folder longer than %zu bytes: %s",
                  sizeof scene->output.dir - 1, c->dir);
  if (!rc) {
    memcpy(scene->output.dir, c->dir, strlen(c->dir) + 1);
    nh_sim_options opt = {.dry_run = 0, .progress = 0, .restart_dir = NULL, .overwrite = 1};
    rc = nh_sim_create(scene, &opt, &sim);
    if (!rc) rc = nh_sim_run(sim);
  }
  *seconds = nh_time_now() - t0;
  nh_sim_destroy(&sim);
  nh_scene_destroy(&scene);
  free(all);
  return rc;
}

typedef struct {
  pid_t pid;
  double t0;
  char log[NH_PATH_MAX + 48];
} nh_child;

/* Start candidate c as a child process; its stderr to `log`. */
static int nh_spawn(const char *scene_path, int n_user, const char *const *user,
                    const nh_candidate *c, nh_child *ch) {
  const int argc = 8 + 2 * (n_user + c->n_sets);
  char **argv = nh_calloc((size_t)argc, sizeof(char *));
  if (!argv) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan run");
  int a = 0;
  argv[a++] = "needlehex", argv[a++] = "run", argv[a++] = (char *)scene_path;
  for (int i = 0; i < n_user; i++) argv[a++] = "--set", argv[a++] = (char *)user[i];
  for (int i = 0; i < c->n_sets; i++) argv[a++] = "--set", argv[a++] = c->sets[i];
  argv[a++] = "--out", argv[a++] = (char *)c->dir, argv[a++] = "--overwrite";
  argv[a++] = "--quiet", argv[a] = NULL;
  /* the environment with OMP_NUM_THREADS=1 and OMP_THREAD_LIMIT=1 (main.c's
   * thread policy: CHOLMOD's teams too), built before the fork */
  int ne = 0;
  while (environ[ne]) ne++;
  char **envp = nh_calloc((size_t)ne + 3, sizeof(char *));
  if (!envp) {
    free(argv);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan run");
  }
  int m = 0;
  for (int i = 0; i < ne; i++)
    if (strncmp(environ[i], "OMP_NUM_THREADS=", 16) && strncmp(environ[i], "OMP_THREAD_LIMIT=", 17))
      envp[m++] = environ[i];
  envp[m++] = "OMP_NUM_THREADS=1";
  envp[m++] = "OMP_THREAD_LIMIT=1";
  int fd = open(ch->log, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    free(argv), free(envp);
    return NH_ERROR(NH_ERR_IO, "plan: cannot write %s: %s", ch->log, strerror(errno));
  }
  pid_t parent = getpid();
  ch->t0 = nh_time_now();
  ch->pid = fork();
  if (ch->pid == 0) { /* the child: only async-signal-safe calls until exec */
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);
    dup2(fd, 2);
    int null = open("/dev/null", O_WRONLY);
    if (null >= 0) dup2(null, 1);
    execve("/proc/self/exe", argv, envp);
    _exit(127);
  }
  int err = errno;
  close(fd);
  free(argv), free(envp);
  if (ch->pid < 0) return NH_ERROR(NH_ERR_IO, "plan: cannot start a run: %s", strerror(err));
  return NH_OK;
}

/* The last non-empty line of a file (for a failed child's message). */
static void nh_last_line(const char *path, char *out, size_t size) {
  out[0] = '\0';
  FILE *in = fopen(path, "r");
  if (!in) return;
  char line[1024];
  while (fgets(line, sizeof line, in))
    if (line[0] && line[0] != '\n') {
      size_t n = strcspn(line, "\n");
      if (n >= size) n = size - 1;
      memcpy(out, line, n), out[n] = '\0';
    }
  fclose(in);
}

int nh_runs_execute(const char *scene_path, int n_user, const char *const *user, int n,
                    const nh_candidate *c, int workers, const char *tool, const char *target,
                    nh_run_result *res) {
  int rc = NH_OK;
  for (int i = 0; i < n; i++) memset(&res[i], 0, sizeof res[i]);
  if (workers <= 1) {
    for (int i = 0; i < n && !rc; i++) {
      rc = nh_run_here(scene_path, n_user, user, &c[i], &res[i].seconds);
      if (rc) {
        char msg[sizeof res[i].message];
        snprintf(msg, sizeof msg, "%s", nh_error_message());
        if (rc == NH_ERR_NUMERIC) { /* the simulation failed: a result */
          nh_error_clear();
          rc = NH_OK;
          res[i].failed = 1;
          snprintf(res[i].message, sizeof res[i].message, "%s", msg);
        } else {
          rc = nh_error_set(rc, __FILE__, __LINE__, "plan run %s: %s", c[i].dir, msg);
        }
      }
    }
  } else {
    nh_child *ch = nh_calloc((size_t)n, sizeof *ch);
    if (!ch) return NH_ERROR(NH_ERR_MEMORY, "out of memory: plan runs");
    int started = 0, running = 0, failed = -1, status_failed = 0;
    while (started < n || running > 0) {
      while (!rc && failed < 0 && started < n && running < workers) {
        snprintf(ch[started].log, sizeof ch[started].log, "%s.log", c[started].dir);
        rc = nh_spawn(scene_path, n_user, user, &c[started], &ch[started]);
        if (rc) break;
        started++, running++;
      }
      if (running == 0) break;
      int status;
      pid_t pid = waitpid(-1, &status, 0);
      if (pid < 0) {
        if (errno == EINTR) continue;
        rc = rc ? rc : NH_ERROR(NH_ERR_IO, "plan: waiting for the runs: %s", strerror(errno));
        break;
      }
      for (int i = 0; i < started; i++)
        if (ch[i].pid == pid) {
          res[i].seconds = nh_time_now() - ch[i].t0;
          ch[i].pid = 0;
          running--;
          int code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
          if (code == 0) {
            unlink(ch[i].log);
          } else if (code == 1) { /* the simulation failed: a result */
            char last[400];
            nh_last_line(ch[i].log, last, sizeof last);
            res[i].failed = 1;
            /* the log's path last: a long one is cut, the reason is not */
            snprintf(res[i].message, sizeof res[i].message, "%.400s (%.100s)", last, ch[i].log);
          } else if (failed < 0) {
            failed = i, status_failed = code;
          }
        }
    }
    if (!rc && failed >= 0) {
      char last[1024];
      nh_last_line(ch[failed].log, last, sizeof last);
      rc = NH_ERROR(status_failed == 2 ? NH_ERR_INPUT : NH_ERR_NUMERIC,
                    "plan run %s: exit status %d: %s (the run's messages: %s)", c[failed].dir,
                    status_failed, last[0] ? last : "no message", ch[failed].log);
    }
    free(ch);
  }
  for (int i = 0; i < n && !rc; i++)
    if (!res[i].failed) rc = nh_read_run(c[i].dir, tool, target, &res[i]);
  return rc;
}

int nh_plan_link_final(const char *out, int run) {
  char link[NH_PATH_MAX + 16], name[16];
  snprintf(link, sizeof link, "%s/final", out);
  snprintf(name, sizeof name, "run_%02d", run);
  if (unlink(link) != 0 && errno != ENOENT)
    return NH_ERROR(NH_ERR_IO, "cannot replace %s: %s", link, strerror(errno));
  if (symlink(name, link) != 0)
    return NH_ERROR(NH_ERR_IO, "cannot link %s to %s: %s", link, name, strerror(errno));
  return NH_OK;
}
