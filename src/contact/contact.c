/* contact.c — one step of the tools in the tissue, and the state machine
 * (docs/interaction.md).
 *
 * A step (nh_contact_step):
 *   1. begin: the coupled solve's block of every dynamic tool (tools.c),
 *      then per group the rows of each constraint in its current state:
 *      puncture (not punctured yet: the entry point, puncture.c), tip (the
 *      channel's front) and shaft (the channel points; channel.c);
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
  free(c);
  *pc = NULL;
}

/* Before the step t → t + h: the blocks and the rows of every constraint. */
static int nh_contact_begin_step(nh_contact *c, const nh_mesh *m, const double *u, const double *v,
                                 double t, double h) {
  nh_rows_clear(&c->rows);
  double g[3]; /* at the end of the step, as the tissue's loads; tools are not buoyed */
  nh_scene_gravity(c->scene, t + h, g);
  nh_tools_blocks(c, t, h, g);
  for (int i = 0; i < c->n_groups; i++) {
    nh_group *G = &c->groups[i];
    NH_TRY(nh_puncture_rows(c, G, m, u, h));
    NH_TRY(nh_tip_rows(c, G, m, u, t, h));
    NH_TRY(nh_shaft_rows(c, G, m, u, h));
  }
  if (c->skull) NH_TRY(nh_skull_rows(c->skull, m, u, v, h, &c->rows));
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

/* After the solved step (u at t_new): forces, states, nested tools. */
static int nh_contact_end_step(nh_contact *c, const nh_mesh *m, const double *u, double t_new,
                               double h) {
  NH_TRY(nh_tools_clear_forces(c));
  c->cut = 0;
  for (int i = 0; i < c->n_groups; i++) {
    nh_group *G = &c->groups[i];
    nh_group_events ev = {0};
    nh_puncture_update(c, G, h, &ev);
    nh_shaft_update(c, G, h, &ev);
    NH_TRY(nh_tip_update(c, G, m, u, h, &ev));
    NH_TRY(nh_group_transition(c, G, m, u, &ev, t_new, h));
    c->cut += ev.cut;
  }
  for (int k = 0; k < c->n; k++)
    if (c->tools[k].host >= 0) c->tools[k].state = nh_nested_state(c, k, t_new, h);
  nh_tools_follow(c, t_new, h);
  if (c->skull) nh_skull_end_step(c->skull, &c->rows, h);
  return NH_OK;
}

int nh_contact_step(nh_contact *c, nh_system *sys, const nh_integrator *in, const nh_mesh *m,
                    const double *f_ext, double *u, double *v, double t_new, nh_step_stats *stats) {
  const double h = in->dt, t = t_new - h;
  NH_TRY(nh_contact_begin_step(c, m, u, v, t, h));
  int rc = nh_step_coupled(sys, in, f_ext, u, v, c->n_blocks, c->blocks, &c->rows, NH_MCP_TOLERANCE,
                           NH_MCP_ACCEPT, NH_MCP_SWEEPS, &c->solve);
  *stats = c->solve.step;
  if (rc) {
    if (c->rows.m > 0 && c->solve.mcp.iterations >= NH_MCP_SWEEPS) { /* above NH_MCP_ACCEPT */
      char why[512];
      snprintf(why, sizeof why, "%s", nh_error_message());
      return NH_ERROR(rc, "constraint solve (%d rows): %s", c->rows.m, why);
    }
    return rc;
  }
  return nh_contact_end_step(c, m, u, t_new, h);
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

void nh_contact_stats_get(const nh_contact *c, nh_contact_stats *st) {
  st->rows = c->rows.m;
  st->cut = c->cut;
  st->path_points = 0;
  for (int g = 0; g < c->n_groups; g++) st->path_points += c->groups[g].n_chan;
  st->solve = c->solve;
}
