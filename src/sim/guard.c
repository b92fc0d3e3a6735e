/* guard.c — the checks every solved step passes before its results are
 * written (docs/outputs.md, "When a step is not plausible").
 *
 * A linearised step can return numbers that no tissue could produce: an
 * inverted element under an absurd load or a tiny Young's modulus, values
 * that overflow, a step that moves the tissue by more than its own size, a
 * tool reported inside tissue it has left. Each step is checked for:
 *
 * - non-finite displacements or velocities (always fatal: nothing after
 *   them means anything);
 * - inverted cells: det J <= 0 of the deformed cell at any of its 8 corners
 *   or 2x2x2 Gauss points (the corners catch a cell folded at one node that
 *   the Gauss points miss); a cut cell of an immersed domain only where its
 *   tissue is: the tissue part's centroid and those of its corners and of
 *   its 27 quadrature points that lie in the tissue (nh_tissue_cell_inverted;
 *   its fictitious part carries no load and may fold). Counted in steps.csv
 *   `inverted`;
 * - an implausible step: a node moved by more than NH_GUARD_STEP_FRACTION
 *   of the tissue's size (the diagonal of its rest bounding box) in one
 *   step. No physical insertion does that, and an implicit Euler step that
 *   does has left the range where its linearisation means anything;
 * - a tool reported punctured or cutting whose tip lies outside the
 *   tissue's current bounding box widened by one grid cell;
 * - a dynamic step whose Newton iterations left its equations unsolved
 *   (steps.csv `unsolved`, nh_sim_step_unsolved; not with
 *   solver.newton.max_iterations 0, which asks for one linearisation): the
 *   message names the residual, the iterations, the node of the largest
 *   residual entry, its cells and rows and the likely cause
 *   (nh_system_where_dof).
 *
 * With solver.on_invalid: stop (the default) the first of these ends the run
 * with exit 1 naming the step, the cell, node or tool and the reason, before
 * the step writes anything: the frames and rows on disk are those of the
 * last plausible step. With warn, inverted cells, implausible steps, tools
 * and unsolved steps are reported once each (a warning) and the run goes
 * on. */
#include "sim/sim_impl.h"

#include <math.h>
#include <omp.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

/* A node may move by at most this fraction of the tissue's size in a step. */
#define NH_GUARD_STEP_FRACTION 0.5

/* Cell c inverted at the displacements u (see the top of this file). */
static int nh_cell_inverted(const nh_sim *s, int c) {
  return nh_tissue_cell_inverted(s->tissue, c, s->u);
}

/* Leaves from which the check runs on the solver's threads (a passive team
 * costs tens of µs to wake; a leaf's check about half a µs). */
enum { NH_GUARD_PARALLEL_MIN = 512 };

int nh_sim_count_inverted(const nh_sim *s, int *first) {
  const nh_mesh *m = s->mesh;
  const int nl = m->n_leaves, threads = s->scene->solver.threads;
  int count = 0, lo = nl; /* the first inverted leaf in leaf order, whatever the threads */
#pragma omp parallel for schedule(static) reduction(+ : count) reduction(min : lo) \
    num_threads(threads > 0 ? threads : omp_get_max_threads()) if (nl >= NH_GUARD_PARALLEL_MIN)
  for (int l = 0; l < nl; l++)
    if (nh_cell_inverted(s, m->leaves[l])) {
      count++;
      if (l < lo) lo = l;
    }
  *first = lo < nl ? m->leaves[lo] : -1;
  return count;
}

/* Inverted cells at a tool's tip disc (docs/interaction.md, "Tip disc"):
 * the first tool whose active disc acts on a node of an inverted cell
 * appends to msg what it asks of the tissue there, its force F over the
 * disc of radius a as the nominal strain F / (π a² E) (E of that cell): a
 * linear half-space under that pressure sinks by 16 (1 − ν²) / (3 π) times
 * it in disc radii (Timoshenko & Goodier, §138), so a strain of order one
 * is beyond the small-strain material model, and a real tissue would
 * rather be punctured or cut at a lower force. */
static int nh_guard_disc(const nh_sim *s, char *msg, size_t size) {
  const nh_mesh *m = s->mesh;
  const double tau = s->scene->time.mode == NH_MODE_STATIC ? 1.0 : s->scene->time.step;
  for (int t = 0; t < s->scene->n_tools; t++) {
    nh_tip_disc d;
    nh_contact_tip_disc(s->contact, t, tau, &d);
    if (!d.active) continue;
    for (int l = 0; l < m->n_leaves; l++) {
      int c = m->leaves[l], touches = 0;
      for (int a = 0; a < 8 && !touches; a++)
        for (int k = 0; k < d.n_nodes && !touches; k++) touches = d.node[k] == m->cells[8 * c + a];
      if (!touches || !nh_cell_inverted(s, c)) continue;
      double lambda, mu;
      nh_tissue_cell_material(s->tissue, c, &lambda, &mu, NULL);
      const double E = mu * (3.0 * lambda + 2.0 * mu) / (lambda + mu);
      const double strain = d.force / (NH_PI * d.radius * d.radius * E);
      size_t len = strlen(msg);
      snprintf(msg + len, size - len,
               " at the tip disc of tool '%s' (cell %d): its %.3g N over the disc of radius "
               "%.3g mm press the tissue (E = %.3g Pa) by a nominal strain F / (pi a^2 E) = "
               "%.3g, beyond the small-strain material model (a real tissue is punctured or cut "
               "at a lower force: the tool's puncture_force, cutting_force)",
               s->scene->tools[t].name, c, d.force, 1e3 * d.radius, E, strain);
      return 1;
    }
  }
  return 0;
}

/* The tissue's rest size: the diagonal of the nodes' bounding box. */
static double nh_tissue_size(const nh_mesh *m) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) {
      lo[k] = fmin(lo[k], m->X[3 * i + k]);
      hi[k] = fmax(hi[k], m->X[3 * i + k]);
    }
  return sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
              (hi[2] - lo[2]) * (hi[2] - lo[2]));
}

/* The bound (docs/outputs.md, `unsolved`): the Newton tolerance in static
 * mode and with solver.newton, else NH_UNSOLVED_LINEAR (a linearised step
 * that leaves that much is not a solution: solve.h); never below the
 * round-off level of the internal forces (a stiff body at rest has forces
 * at that level: a relative residual of round-off over round-off). */
int nh_sim_step_unsolved(const nh_sim *s, const nh_step_stats *st, double *bound) {
  const nh_scene *sc = s->scene;
  *bound = sc->time.mode == NH_MODE_STATIC    ? sc->solver.tolerance
           : sc->solver.newton_iterations > 0 ? sc->solver.newton_tolerance
                                              : NH_UNSOLVED_LINEAR;
  return st->residual > fmax(*bound, st->residual_floor);
}

int nh_sim_step_guarded(const nh_sim *s) {
  return s->scene->time.mode != NH_MODE_STATIC && s->integrator.newton_iterations != 0;
}

/* Report an invalid step: an error (stop) or, once per kind, a warning. */
static int nh_guard_report(nh_sim *s, int kind, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int nh_guard_report(nh_sim *s, int kind, const char *fmt, ...) {
  char reason[2560];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(reason, sizeof reason, fmt, ap);
  va_end(ap);
  const double t = (s->step + 1) * s->scene->time.step;
  if (!s->scene->solver.on_invalid_warn)
    return NH_ERROR(NH_ERR_NUMERIC,
                    "step %d (t = %g s): %s; stopped before writing this step "
                    "(solver.on_invalid: warn goes on)",
                    s->step + 1, t, reason);
  if (!(s->guard_warned & (1 << kind)))
    nh_log_warn("step %d (t = %g s): %s (solver.on_invalid: warn; reported once)", s->step + 1, t,
                reason);
  s->guard_warned |= 1 << kind;
  return NH_OK;
}

int nh_sim_guard(nh_sim *s, const double *u_start, const nh_step_stats *st) {
  const nh_mesh *m = s->mesh;
  const int n = 3 * m->n_nodes;
  for (int i = 0; i < n; i++)
    if (!isfinite(s->u[i]) || !isfinite(s->v[i]))
      return NH_ERROR(NH_ERR_NUMERIC,
                      "step %d (t = %g s): node %d has a non-finite %s; stopped before writing "
                      "this step",
                      s->step + 1, (s->step + 1) * s->scene->time.step, i / 3,
                      isfinite(s->u[i]) ? "velocity" : "displacement");
  int first = -1;
  s->inverted = nh_sim_count_inverted(s, &first);
  if (s->inverted > 0) {
    char disc[768] = "";
    if (s->contact) nh_guard_disc(s, disc, sizeof disc);
    NH_TRY(nh_guard_report(s, 0,
                           "%d of %d cells inverted (det J <= 0 at a corner or Gauss point; "
                           "first: cell %d, level %d)%s: the load or the material is beyond what "
                           "the model can represent",
                           s->inverted, m->n_leaves, first, m->level[first], disc));
  }
  double bound;
  if (nh_sim_step_guarded(s) && nh_sim_step_unsolved(s, st, &bound)) {
    char where[1536] = "";
    if (!s->scene->solver.on_invalid_warn || !(s->guard_warned & (1 << 3))) {
      snprintf(where, sizeof where, "; the largest residual entry is");
      nh_system_where_dof(s->system, s->u, st->residual_dof,
                          s->contact ? nh_contact_rows(s->contact) : NULL, where, sizeof where);
    }
    const int its = st->iterations - 1, most = s->integrator.newton_iterations;
    NH_TRY(nh_guard_report(
        s, 3,
        "the step's equations are not solved: relative residual %.3g above %g "
        "after %d Newton iteration%s (at most %d %s; steps.csv `unsolved`)%s",
        st->residual, bound, its, its == 1 ? "" : "s", most > 0 ? most : NH_DYNAMIC_NEWTON_MAX,
        most > 0 ? "by solver.newton.max_iterations" : "without solver.newton", where));
  }
  double size = nh_tissue_size(m), worst = 0.0;
  int node = -1;
  for (int i = 0; i < m->n_nodes; i++) {
    double d = 0.0;
    for (int k = 0; k < 3; k++)
      d += (s->u[3 * i + k] - u_start[3 * i + k]) * (s->u[3 * i + k] - u_start[3 * i + k]);
    if (d > worst) worst = d, node = i;
  }
  worst = sqrt(worst);
  if (worst > NH_GUARD_STEP_FRACTION * size)
    NH_TRY(nh_guard_report(s, 1,
                           "node %d moved by %.3g m in one step, more than %g x the tissue's "
                           "size (%.3g m): an implausible step (reduce time.step or check the "
                           "loads)",
                           node, worst, NH_GUARD_STEP_FRACTION, size));
  if (s->contact) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double cell = 0.0;
    for (int k = 0; k < 3; k++) cell = fmax(cell, m->spacing[k]);
    for (int i = 0; i < m->n_nodes; i++)
      for (int k = 0; k < 3; k++) {
        lo[k] = fmin(lo[k], m->X[3 * i + k] + s->u[3 * i + k]);
        hi[k] = fmax(hi[k], m->X[3 * i + k] + s->u[3 * i + k]);
      }
    for (int t = 0; t < s->scene->n_tools; t++) {
      nh_tool_report r;
      nh_contact_report(s->contact, t, &r);
      if (r.state != NH_TOOL_PUNCTURED && r.state != NH_TOOL_CUTTING) continue;
      int inside = 1;
      for (int k = 0; k < 3; k++) inside &= r.tip[k] >= lo[k] - cell && r.tip[k] <= hi[k] + cell;
      if (!inside)
        NH_TRY(nh_guard_report(s, 2,
                               "tool '%s' is %s but its tip [%.4g, %.4g, %.4g] m lies outside "
                               "the tissue (beyond one cell of its bounding box): the tool "
                               "travelled too far in one step (reduce time.step)",
                               s->scene->tools[t].name, nh_tool_state_name(r.state), r.tip[0],
                               r.tip[1], r.tip[2]));
    }
  }
  return NH_OK;
}
