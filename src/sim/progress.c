/* progress.c — what a run prints while it goes and when it ends.
 *
 * On a terminal, one line rewritten in place (at most 5 times a second):
 * step/total, simulated time, DOFs, ms per step, ETA. When stderr is not a
 * terminal (CI, logs), a plain line every 10 % of the run or every 10 s.
 * At the end a summary: steps, DOFs, median ms/step by phase, output folder.
 * A continued run (--restart) counts, times and medians only the steps this
 * process computed. sim.c feeds it: it reads the run's state and the
 * medians it is given, and calls nothing of sim.c. */
#include "sim/sim_impl.h"

#include <stdio.h>
#include <unistd.h>

void nh_progress_start(nh_sim *s) {
  s->progress.t_start = s->progress.t_last_print = nh_time_now();
  s->progress.is_tty = isatty(fileno(stderr));
  s->progress.printed = 0;
}

void nh_progress_update(nh_sim *s) {
  int total = s->scene->time.steps;
  double now = nh_time_now(), elapsed = now - s->progress.t_start;
  int done = s->step - s->first_step; /* by this process: what the clock measured */
  double per_step = done > 0 ? elapsed / done : 0.0;
  double eta = per_step * (total - s->step);
  int dofs = 3 * s->mesh->n_nodes;
  if (s->progress.is_tty) {
    if (now - s->progress.t_last_print < 0.2 && s->step < total) return;
    fprintf(stderr, "\r  step %d/%d  t = %.4g s  dofs %d  %.2f ms/step  ETA %.1f s   ", s->step,
            total, s->time, dofs, 1e3 * per_step, eta);
    s->progress.printed = 1;
  } else {
    int tenth = total >= 10 ? total / 10 : 1;
    if (s->step % tenth != 0 && now - s->progress.t_last_print < 10.0 && s->step < total) return;
    fprintf(stderr, "  step %d/%d  t = %.4g s  dofs %d  %.2f ms/step  ETA %.1f s\n", s->step, total,
            s->time, dofs, 1e3 * per_step, eta);
  }
  s->progress.t_last_print = now;
}

void nh_progress_finish(nh_sim *s, const double t[NH_PHASES]) {
  if (s->progress.is_tty && s->progress.printed) fputc('\n', stderr);
  int done = s->step - s->first_step;
  if (s->first_step > 0)
    fprintf(stderr, "%s: continued from step %d: %d steps now, to step %d\n", s->scene->name,
            s->first_step, done, s->step);
  fprintf(stderr,
          "%s: %d steps, %d dofs (%d free), %d cells, %.2f s\n"
          "  median ms/step: assemble %.3f  factor %.3f  solve %.3f  constraints %.3f  "
          "tools %.3f  guard %.3f  adapt %.3f  output %.3f  | step %.3f\n",
          s->scene->name, done, 3 * s->mesh->n_nodes, nh_system_free_dofs(s->system),
          s->mesh->n_leaves, nh_time_now() - s->progress.t_start, 1e3 * t[NH_PHASE_ASSEMBLE],
          1e3 * t[NH_PHASE_FACTOR], 1e3 * t[NH_PHASE_SOLVE], 1e3 * t[NH_PHASE_CONSTRAINTS],
          1e3 * t[NH_PHASE_TOOLS], 1e3 * t[NH_PHASE_GUARD], 1e3 * t[NH_PHASE_ADAPT],
          1e3 * t[NH_PHASE_OUTPUT], 1e3 * t[NH_PHASE_STEP]);
  if (s->max_goal_point >= 0) {
    const nh_scene *sc = s->scene;
    int i = s->max_goal_point;
    fprintf(stderr, "  largest estimated %s error: %.3e m (%s)\n",
            i < sc->n_probes ? "probe" : "target", s->max_goal_error,
            i < sc->n_probes ? sc->probes[i].name : sc->targets[i - sc->n_probes].name);
  }
  if (!s->options.dry_run) fprintf(stderr, "  output: %s/\n", s->scene->output.dir);
}
