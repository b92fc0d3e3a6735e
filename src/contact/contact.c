/* contact.c — one step of the tools in the tissue, and the state machine
 * (docs/interaction.md).
 *
 * A step (nh_contact_step):
 *   1. begin: the coupled solve's block of every dynamic tool (tools.c),
 *      then per group the rows of each constraint in its current state:
 *      puncture (not punctured yet: the entry point, puncture.c), tip (the
 *      channel's front) and shaft (the channel points; channel.c); then a
 *      released nested tool's rows with its host (nest.c);
 *   2. the coupled step of tissue and tools (nh_step_coupled, Algorithm 1);
 *   3. end: each constraint reads its rows' forces into the group's events
 *      (and the tip cuts forward), the state machine below moves every
 *      tool's state on, nested tools follow their host or are released.
 *
 * The state machine, per group (its outer tool's state), from the events
 * of the step just solved:
 *   puncture rows active   contact (normal force > 0) or outside; at the
 *                          puncture force: punctured, the channel opens at
 *                          the entry point;
 *   not punctured          outside;
 *   punctured              outside if no tip or shaft row was active, else
 *                          retracting (the outer tool's motion is negative
 *                          over the step), cutting (the tip cut forward),
 *                          or punctured;
 * and for a nested tool: its host's state until its release, then outside
 * unless it is tied to the channel (or its host is in the tissue), else
 * retracting or punctured by its own motion. */
#include "contact/contact_impl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* Constraint solve: target tolerance and sweeps of nh_mcp_solve, and the
 * residual accepted when the sweeps stall short of the target (the
 * dimensionless law violation, see solve.h; reported per step). */
#define NH_MCP_TOLERANCE 1e-10
#define NH_MCP_ACCEPT    1e-5
#define NH_MCP_SWEEPS    2000

const char *nh_tool_state_name(nh_tool_state s) {
  static const char *const names[] = {"outside", "contact", "punctured", "cutting", "retracting"};
  return (unsigned)s < 5 ? names[s] : "?";
}

int nh_contact_create(const nh_scene *sc, const nh_mesh *m, nh_contact **out) {
  *out = NULL;
  nh_contact *c = nh_calloc(1, sizeof *c);
  if (!c) return NH_ERR_MEMORY;
  c->scene = sc;
  c->n = sc->n_tools;
  size_t n = (size_t)(c->n ? c->n : 1);
  c->tools = nh_calloc(n, sizeof *c->tools);
  c->groups = nh_calloc(n, sizeof *c->groups);
  c->blocks = nh_calloc(n, sizeof *c->blocks);
  int rc = c->tools && c->groups && c->blocks ? NH_OK : NH_ERR_MEMORY;
  for (int k = 0; k < c->n && !rc; k++) {
    nh_tool *tl = &c->tools[k];
    if (sc->tools[k].inside < 0) { /* an outer tool: a new group */
      tl->group = c->n_groups++;
      nh_group *G = &c->groups[tl->group];
      G->outer = k;
      G->tip_tool = G->entry_row = -1;
    } else { /* a tool listed before this one */
      tl->group = c->tools[sc->tools[k].inside].group;
    }
    rc = nh_tool_init(c, k, m);
    if (!rc && tl->host < 0) nh_puncture_init(&c->groups[tl->group], tl->spec, m);
  }
  if (!rc && sc->tissue.skull) {
    rc = nh_skull_create(&m->domain, sc->tissue.skull_gap, &c->skull);
    if (!rc) nh_skull_set_rows(c->skull, sc->tissue.skull_rows);
    if (!rc) rc = nh_skull_build(c->skull, m);
  }
  if (rc) {
    nh_contact_destroy(&c);
    return rc;
  }
  *out = c;
  return NH_OK;
}

void nh_contact_destroy(nh_contact **pc) {
  nh_contact *c = *pc;
  if (!c) return;
  for (int k = 0; c->tools && k < c->n; k++) {
    nh_beam_destroy(&c->tools[k].beam);
    free(c->tools[k].f_node);
  }
  for (int g = 0; c->groups && g < c->n_groups; g++) free(c->groups[g].chan);
  free(c->tools);
  free(c->groups);
  free(c->blocks);
  nh_skull_destroy(&c->skull);
  nh_rows_free(&c->rows);
  nh_disc_free(&c->disc);
  free(c->du_last);
  free(c);
  *pc = NULL;
}

/* Before the step t → t + h: the blocks and the rows of every constraint,
 * with the rows' time scale τ (h, or 1 quasi-static) and v the tissue's
 * velocity per τ (quasi-static: a predicted increment); `moving`: the
 * tools' bases move over this solve (quasi-static: its first iteration). */
static int nh_contact_begin_step(nh_contact *c, const nh_mesh *m, const double *u, const double *v,
                                 double t, double h, double tau, int moving) {
  nh_rows_clear(&c->rows);
  c->iteration = c->statics && !moving; /* (only whether it is the first one matters) */
  double g[3]; /* at the end of the step, as the tissue's loads; tools are not buoyed */
  nh_scene_gravity(c->scene, t + h, g);
  nh_tools_blocks(c, t, h, tau, moving, g);
  for (int i = 0; i < c->n_groups; i++) {
    nh_group *G = &c->groups[i];
    NH_TRY(nh_puncture_rows(c, G, m, u, tau));
    NH_TRY(nh_tip_rows(c, G, m, u, t, h, tau));
    NH_TRY(nh_shaft_rows(c, G, m, u, t, h, tau));
  }
  NH_TRY(nh_nest_rows(c));
  if (c->skull) NH_TRY(nh_skull_rows(c->skull, m, u, v, tau, &c->rows));
  return NH_OK;
}

/* The state machine of a group (see the top of this file); the puncture
 * opens the channel. */
static int nh_group_transition(nh_contact *c, nh_group *G, const nh_mesh *m, const double *u,
                               const nh_group_events *ev, double t_new, double h) {
  nh_tool *outer = &c->tools[G->outer];
  if (ev->puncture_rows) {
    outer->state = ev->touching ? NH_TOOL_CONTACT : NH_TOOL_OUTSIDE;
    if (ev->yielded) {
      G->punctured = 1;
      outer->state = NH_TOOL_PUNCTURED;
      NH_TRY(nh_channel_open(G, outer->spec, m));
      /* where the entry is now: the depth of this step's report */
      nh_point_position(m, u, &G->chan[0], G->entry_x);
    }
    return NH_OK;
  }
  if (!G->punctured) {
    outer->state = NH_TOOL_OUTSIDE;
    return NH_OK;
  }
  int retracting = nh_tool_speed(outer->spec, t_new - h, h) < 0.0;
  outer->state = !ev->covered ? NH_TOOL_OUTSIDE
                 : retracting ? NH_TOOL_RETRACTING
                 : ev->cut    ? NH_TOOL_CUTTING
                              : NH_TOOL_PUNCTURED;
  if (G->n_chan > 0) nh_point_position(m, u, &G->chan[0], G->entry_x);
  return NH_OK;
}

/* A nested tool's state (see the top of this file). */
static nh_tool_state nh_nested_state(const nh_contact *c, int k, double t_new, double h) {
  const nh_tool *tl = &c->tools[k], *H = &c->tools[tl->host];
  const nh_group *G = &c->groups[tl->group];
  if (!tl->released) return H->state;
  int tied = G->tip_tool == k;
  for (int i = 0; i < G->n_chan; i++) tied |= G->chan[i].tool == k;
  /* in the tissue: tied to it, or inside its host where the host is */
  int in = tied || (G->punctured && H->state != NH_TOOL_OUTSIDE);
  return !in                                         ? NH_TOOL_OUTSIDE
         : nh_tool_speed(tl->spec, t_new - h, h) < 0 ? NH_TOOL_RETRACTING
                                                     : NH_TOOL_PUNCTURED;
}

/* After the solved step (u at t_new): forces, states, nested tools; τ the
 * rows' time scale (forces are λ / τ). Nested tools following their host
 * get its velocity over h, and none quasi-static. */
static int nh_contact_end_step(nh_contact *c, const nh_mesh *m, const double *u, double t_new,
                               double h, double tau) {
  NH_TRY(nh_tools_clear_forces(c));
  c->cut = 0;
  for (int i = 0; i < c->n_groups; i++) {
    nh_group *G = &c->groups[i];
    nh_group_events ev = {0};
    nh_puncture_update(c, G, tau, &ev);
    nh_shaft_update(c, G, tau, &ev);
    NH_TRY(nh_tip_update(c, G, m, u, tau, &ev));
    NH_TRY(nh_group_transition(c, G, m, u, &ev, t_new, h));
    c->cut += ev.cut;
    G->cut = ev.cut;
  }
  for (int k = 0; k < c->n; k++)
    if (c->tools[k].host >= 0) c->tools[k].state = nh_nested_state(c, k, t_new, h);
  nh_tools_follow(c, t_new, c->statics ? 0.0 : h);
  if (c->skull) nh_skull_end_step(c->skull, &c->rows, tau);
  return NH_OK;
}

int nh_contact_step(nh_contact *c, nh_system *sys, const nh_integrator *in, const nh_mesh *m,
                    const double *f_ext, double *u, double *v, double t_new, nh_step_stats *stats) {
  const double h = in->dt, t = t_new - h;
  NH_TRY(nh_contact_begin_step(c, m, u, v, t, h, h, 1));
  int rc = nh_step_coupled(sys, in, f_ext, u, v, c->n_blocks, c->blocks, &c->rows, NH_MCP_TOLERANCE,
                           NH_MCP_ACCEPT, NH_MCP_SWEEPS, &c->solve);
  *stats = c->solve.step;
  if (rc) {
    if (c->rows.m > 0 && c->solve.mcp.sweeps >= NH_MCP_SWEEPS) { /* above NH_MCP_ACCEPT */
      char why[2048];
      snprintf(why, sizeof why, "%s", nh_error_message());
      return NH_ERROR(rc, "constraint solve (%d rows): %s", c->rows.m, why);
    }
    return rc;
  }
  return nh_contact_end_step(c, m, u, t_new, h, h);
}

/* Quasi-static: the redo rule of a skull point pushed through without a
 * row (relative to its cell edge: what the rows' margin covers), and how
 * often one iteration may be solved again for it. */
#define NH_STATIC_MISSED 0.01
#define NH_STATIC_REDOS  4

/* Size of tool k's last increment (its velocities per τ = 1: translations,
 * rotations times the tool's length). */
static double nh_tool_increment(const nh_tool *tl) {
  const double *v = nh_beam_velocities(tl->beam), L = nh_beam_length(tl->beam);
  double s = 0.0;
  for (int i = 0; i < nh_beam_dofs(tl->beam); i++) s += (i % 6 < 3 ? 1.0 : L * L) * v[i] * v[i];
  return sqrt(s);
}

/* The forces of a quasi-static iteration as the next one's warm start (the
 * points' stored forces; nothing else of the states moves). */
static void nh_contact_keep_forces(nh_contact *c) {
  const nh_rows *r = &c->rows;
  for (int g = 0; g < c->n_groups; g++) {
    nh_group *G = &c->groups[g];
    for (int q = 0; q < 3; q++) {
      if (G->entry_row >= 0) G->entry.lam[q] = r->lambda[G->entry_row + q];
      if (G->tip_tool >= 0 && G->front.row >= 0) G->front.lam[q] = r->lambda[G->front.row + q];
      for (int i = 0; i < G->n_chan; i++)
        if (G->chan[i].row >= 0) G->chan[i].lam[q] = r->lambda[G->chan[i].row + q];
    }
  }
  if (c->skull) nh_skull_end_step(c->skull, r, 1.0);
}

static void nh_tools_stop(nh_contact *c) {
  for (int k = 0; k < c->n; k++)
    memset(nh_beam_velocities(c->tools[k].beam), 0,
           sizeof(double) * (size_t)nh_beam_dofs(c->tools[k].beam));
}

int nh_contact_solve_static(nh_contact *c, nh_system *sys, const nh_integrator *in,
                            const nh_mesh *m, const double *f_ext, double *u, double *v,
                            double t_new, nh_step_stats *stats) {
  (void)v;
  const double h = in->dt, t = t_new - h;
  const int n = 3 * m->n_nodes;
  nh_integrator it = *in; /* one Newton iteration per coupled solve, τ = 1 */
  it.dt = 1.0, it.alpha = it.beta = 0.0, it.reuse = 0, it.time_factor = 0;
  it.newton_iterations = 0, it.quasi_static = 1;
  if (c->n_du != n) { /* a new mesh: no prediction */
    free(c->du_last);
    c->du_last = nh_calloc((size_t)n, sizeof(double));
    c->n_du = c->du_last ? n : 0;
  }
  double *work = nh_calloc(3 * (size_t)n, sizeof(double));
  double *acc = nh_calloc((size_t)(c->n ? c->n : 1), sizeof(double));
  if (!c->du_last || !work || !acc) {
    free(work), free(acc);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: quasi-static step");
  }
  double *zero = work, *u_start = work + n, *u_iter = work + 2 * n, *pred = c->du_last;
  memcpy(u_start, u, sizeof(double) * (size_t)n);
  unsigned char *saved = NULL;
  size_t saved_size = 0;
  nh_step_stats sum = {0};
  c->statics = 1;
  nh_tools_stop(c);
  int rc = NH_OK, iter = 0, redos = 0, converged = 0, consistent_steps = 0;
  nh_newton_watch watch = {0}; /* the long no-progress rule */
  /* the no-progress rule, while no constraint row has been active (the rows
   * may hold what A's rigid modes measure as loose) */
  nh_rigid start = {.mode = -1};
  double history[NH_NEWTON_STALL_ITERATIONS + 1];
  int rows_seen = 0;
  double residual = INFINITY, tool_rel = 0.0;
  for (iter = 0; iter < in->max_iterations && !rc && !converged; iter++) {
    memcpy(u_iter, u, sizeof(double) * (size_t)n);
    /* the tissue's consistent tangent (its symmetric part) once the residual is below
     * NH_NEWTON_CONSISTENT, as in the static Newton, but not with a skull:
     * its rows' curvature term is not in the tangent, and without it the
     * consistent tangent's initial-stress part leaves the brain's rigid
     * turn on the skull unstable (docs/interaction.md, "Quasi-static
     * mode") */
    it.consistent_tangent = !c->skull && residual <= NH_NEWTON_CONSISTENT;
    consistent_steps += it.consistent_tangent;
    if (c->skull) {
      free(saved), saved = NULL;
      if ((rc = nh_contact_state_save(c, &saved, &saved_size))) break;
    }
    if ((rc = nh_contact_begin_step(c, m, u, pred, t, h, 1.0, iter == 0))) break;
    it.measure_supports = iter == 0;
    /* A constraint solve that stalls is accepted here whatever its
     * residual: the next iteration starts from its forces, and only the
     * last one must meet NH_MCP_ACCEPT (below). */
    rc = nh_step_coupled(sys, &it, f_ext, u, zero, c->n_blocks, c->blocks, &c->rows,
                         NH_MCP_TOLERANCE, INFINITY, NH_MCP_SWEEPS, &c->solve);
    sum.t_assemble += c->solve.step.t_assemble, sum.t_factor += c->solve.step.t_factor;
    sum.t_solve += c->solve.step.t_solve, sum.t_constraints += c->solve.step.t_constraints;
    sum.factorised += c->solve.step.factorised;
    sum.tangent_updates += c->solve.step.tangent_updates;
    sum.pcg_iterations += c->solve.step.pcg_iterations;
    sum.corrections += c->solve.step.corrections;
    if (rc) {
      if (c->rows.m > 0 && c->solve.mcp.sweeps >= NH_MCP_SWEEPS) {
        char why[2048];
        snprintf(why, sizeof why, "%s", nh_error_message());
        rc = NH_ERROR(rc, "quasi-static iteration %d: constraint solve (%d rows): %s", iter + 1,
                      c->rows.m, why);
      }
      break;
    }
    /* the increment of this iteration predicts the next one's approach */
    for (int i = 0; i < n; i++) pred[i] = u[i] - u_iter[i];
    if (c->skull && redos < NH_STATIC_REDOS && nh_skull_missed(c->skull, m, u) > NH_STATIC_MISSED) {
      /* a point went through the skull without its row: solve this
       * iteration again from its start, the point's approach now known
       * (the increment, kept past the state's load, which holds the
       * predictor of the iteration's start: without it every redo
       * repeated the iteration unchanged) */
      memcpy(u, u_iter, sizeof(double) * (size_t)n);
      memcpy(u_iter, pred, sizeof(double) * (size_t)n);
      if ((rc = nh_contact_state_load(c, saved, saved_size))) break;
      pred = c->du_last;
      memcpy(pred, u_iter, sizeof(double) * (size_t)n);
      nh_tools_stop(c);
      redos++, iter--;
      continue;
    }
    nh_contact_keep_forces(c);
    residual = c->solve.step.residual;
    tool_rel = 0.0;
    for (int k = 0; k < c->n; k++) {
      const nh_tool *tl = &c->tools[k];
      if (tl->dyn < 0) continue;
      double d = nh_tool_increment(tl);
      acc[k] += d;
      if (d > 1e-15 * nh_beam_length(tl->beam)) tool_rel = fmax(tool_rel, d / acc[k]);
    }
    nh_tools_stop(c);
    converged = residual <= in->tolerance && tool_rel <= in->tolerance &&
                !(c->solve.mcp.residual > NH_MCP_ACCEPT);
    rows_seen |= c->rows.m > 0;
    if (iter == 0 && !rows_seen) start = c->solve.supports; /* at the step's start */
    if (iter <= NH_NEWTON_STALL_ITERATIONS) history[iter] = fmax(residual, tool_rel);
    if (!converged && iter == NH_NEWTON_STALL_ITERATIONS && !rows_seen &&
        (rc = nh_newton_progress(sys, "quasi-static Newton with constraints", u_iter, pred, &start,
                                 history, iter, &sum)))
      break;
    /* the long no-progress rule on the larger of the two measures (tools
     * nested in a cannula converge with the tissue's residual at round-off) */
    if (!converged && nh_newton_stalled(&watch, iter, fmax(residual, tool_rel))) {
      char msg[2048];
      snprintf(msg, sizeof msg,
               "quasi-static Newton with constraints makes no progress: relative residual %.3g "
               "and tool correction %.3g at iteration %d, none of the last %d with the larger "
               "below %.3g (iteration %d); %d constraint rows, constraint residual %.3g; the "
               "last increment",
               residual, tool_rel, iter + 1, NH_NEWTON_STALL_LONG, watch.best, watch.best_it + 1,
               c->rows.m, c->solve.mcp.residual);
      nh_system_where(sys, u, pred, &c->rows, msg, sizeof msg);
      rc = NH_ERROR(NH_ERR_NUMERIC, "%s", msg);
    }
  }
  free(saved);
  /* back to the corotational tangent, factorised at the solution (what the
   * next step's reuse and the estimate's dual solves expect) */
  int rc_restore = nh_system_tangent_restore(sys, &it, f_ext, u, consistent_steps > 0 && !rc, &sum);
  if (!rc) rc = rc_restore;
  if (!rc && !converged)
    rc = NH_ERROR(NH_ERR_NUMERIC,
                  "quasi-static Newton with constraints did not converge in %d iterations "
                  "(relative residual %.3g, tool correction %.3g, tolerance %.3g; %d rows, "
                  "constraint residual %.3g)",
                  in->max_iterations, residual, tool_rel, in->tolerance, c->rows.m,
                  c->solve.mcp.residual);
  sum.iterations = iter;
  sum.residual = residual;
  sum.t_factor_reference = sum.factorised > 0 ? sum.t_factor / sum.factorised : 0.0;
  *stats = sum;
  c->solve.step = sum;
  if (!rc) {
    for (int i = 0; i < n; i++) pred[i] = u[i] - u_start[i];
    rc = nh_contact_end_step(c, m, u, t_new, h, 1.0);
  }
  nh_tools_stop(c);
  c->statics = 0;
  free(work), free(acc);
  return rc;
}

int nh_contact_relocate(nh_contact *c, const nh_mesh *m) {
  for (int g = 0; g < c->n_groups; g++) {
    nh_group *G = &c->groups[g];
    int bad = 0;
    if (G->has_entry) bad |= nh_point_set(m, &G->entry, G->entry.X);
    if (G->punctured) bad |= nh_point_set(m, &G->front, G->front.X);
    for (int i = 0; i < G->n_chan; i++) bad |= nh_point_set(m, &G->chan[i], G->chan[i].X);
    NH_CHECK(!bad, NH_ERR_INTERNAL, "tool %s: a path point left the refined mesh",
             c->tools[G->outer].spec->name);
  }
  if (c->skull) NH_TRY(nh_skull_relocate(c->skull, m));
  return NH_OK;
}

const nh_rows *nh_contact_rows(const nh_contact *c) {
  return c ? &c->rows : NULL;
}

int nh_contact_data_change(nh_contact *c, const nh_mesh *m, const double *u, int n_fields,
                           const double *w, double *dc, double *dw) {
  const int rm = c->rows.m;
  if (dc) memset(dc, 0, sizeof(double) * (size_t)rm);
  if (dw) memset(dw, 0, sizeof(double) * (size_t)rm * (size_t)n_fields);
  if (c->skull) NH_TRY(nh_skull_data_change(c->skull, m, u, dw ? n_fields : 0, w, rm, dc, dw));
  return nh_anchor_data_change(c, m, u, dw ? n_fields : 0, w, dc, dw);
}

void nh_contact_stats_get(const nh_contact *c, nh_contact_stats *st) {
  st->rows = c->rows.m;
  st->cut = c->cut;
  st->path_points = 0;
  for (int g = 0; g < c->n_groups; g++) st->path_points += c->groups[g].n_chan;
  st->skull_contacts = 0;
  st->skull_force[0] = st->skull_force[1] = st->skull_force[2] = 0.0;
  if (c->skull) nh_skull_force(c->skull, st->skull_force, &st->skull_contacts);
  st->solve = c->solve;
}
