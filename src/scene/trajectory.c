/* trajectory.c — trajectory planning: the kinematics behind the tool keys
 * that depend on other keys (docs/scene.md, tools), resolved once tools and
 * targets are read (nh_read_plans) and reported on at the key's line.
 *  - A planned trajectory (tools.i.trajectory: {target}) runs from the entry
 *    point to the target (or its aim): its direction, the planned depth
 *    (standoff + distance) and the base, placed so that the tip starts
 *    `standoff` before the entry point on that line
 *    (nh_scene_trajectory_line).
 *  - release: target is the time the host's until: target segment ends.
 *  - A symbolic until (target: the tip has travelled the planned depth;
 *    start: it is back at its start) needs the tip's travel by a time over
 *    the earlier motion segments: a nested tool moves with its host until
 *    its release and by its own segments after, an outer tool by its own
 *    segments (nh_scene_tip_travel).
 *  - bevel.toward is made orthogonal to the direction, now known.
 * The travel is the integral of the segments' speeds, the base's turn that
 * of their spins (nh_scene_motion_integral): the one definition of a tool's
 * motion, which the contact module moves the tools by, so that a symbolic
 * until ends exactly where the tool is. */
#include "scene/scene_impl.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

double nh_scene_motion_integral(const nh_tool_spec *tool, int n, double from, double t, int spin) {
  /* Segment k holds over [a, until_k), a the previous until (0 for k = 0). */
  double d = 0, a = 0;
  for (int k = 0; k < n && a < t; ++k) {
    const nh_motion *m = &tool->motion[k];
    double t0 = fmax(a, from), t1 = fmin(m->until, t);
    if (t1 > t0) d += (spin ? m->spin : m->speed) * (t1 - t0);
    a = m->until;
  }
  return d;
}

double nh_scene_tip_travel(const nh_scene *s, int i, int n, double t) {
  const nh_tool_spec *sp = &s->tools[i];
  if (sp->inside < 0) return nh_scene_motion_integral(sp, n, 0, t, 0);
  const nh_tool_spec *host = &s->tools[sp->inside];
  double release = fmin(sp->release, t);
  return nh_scene_motion_integral(host, host->n_motion, 0, release, 0) +
         nh_scene_motion_integral(sp, n, release, t, 0);
}

int nh_scene_trajectory_line(nh_tool_spec *t, const double target[3]) {
  /* The distance scaled by its largest component, so that squaring neither
   * overflows nor underflows (as the reading of a direction). */
  double v[3], scale = 0, norm = 0;
  for (int k = 0; k < 3; ++k) v[k] = target[k] - t->entry[k], scale = fmax(scale, fabs(v[k]));
  if (!(scale > 0)) return NH_ERR_INPUT;
  for (int k = 0; k < 3; ++k) norm += (v[k] / scale) * (v[k] / scale);
  norm = sqrt(norm);
  for (int k = 0; k < 3; ++k) t->direction[k] = v[k] / scale / norm;
  double distance = scale * norm;
  t->depth = t->standoff + distance;
  /* The tip (base + length · direction) at entry − standoff · direction. */
  for (int k = 0; k < 3; ++k)
    t->base[k] = t->entry[k] - (t->standoff + t->length) * t->direction[k];
  return NH_OK;
}

/* tools.i.trajectory (the target's name, now that targets are read): base,
 * direction and planned depth. */
static int resolve_trajectory(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                              nh_scene *s, int i) {
  nh_tool_spec *t = &s->tools[i];
  char key[NH_KEY_MAX], sub[NH_KEY_MAX], name[NH_NAME_MAX], d[96], names[256];
  const nh_yaml_node *traj = nh_yaml_get(tool, "trajectory", NULL), *at;
  nh_read_join(sub, path, "trajectory");
  NH_TRY(nh_read_field(c, traj, sub, "target", 1, &at));
  NH_TRY(nh_read_string(c, at, nh_read_join(key, sub, "target"), name, sizeof name));
  for (int j = 0; j < s->n_targets && t->target < 0; ++j)
    if (!strcmp(s->targets[j].name, name)) t->target = j;
  if (t->target < 0 && s->n_targets == 0)
    return nh_read_fail(c, at, key, "no target named %s (the scene has no targets)",
                        nh_read_describe(at, d, sizeof d));
  if (t->target < 0) {
    size_t len = 0;
    names[0] = '\0';
    for (int j = 0; j < s->n_targets && len < sizeof names; ++j) {
      int n =
          snprintf(names + len, sizeof names - len, "%s'%s'", j ? ", " : "", s->targets[j].name);
      if (n < 0) break;
      len += (size_t)n;
    }
    return nh_read_fail(c, at, key, "no target named %s (the targets are %s)",
                        nh_read_describe(at, d, sizeof d), names);
  }
  /* The aim: the target's point unless trajectory.aim moves it (`needlehex
   * plan`, docs/dbs.md). */
  const nh_yaml_node *aim_at = nh_yaml_get(traj, "aim", NULL);
  t->aimed = aim_at != NULL;
  if (!t->aimed) memcpy(t->aim, s->targets[t->target].point, sizeof t->aim);
  if (nh_scene_trajectory_line(t, t->aim) == NH_OK) return NH_OK;
  if (aim_at)
    return nh_read_fail(c, aim_at, nh_read_join(key, sub, "aim"),
                        "the aim is the entry point [%g, %g, %g]: no direction", t->entry[0],
                        t->entry[1], t->entry[2]);
  return nh_read_fail(c, at, key, "target %s is at the entry point [%g, %g, %g]: no direction",
                      nh_read_describe(at, d, sizeof d), t->entry[0], t->entry[1], t->entry[2]);
}

/* tools.i.release: target — the end of the host's until: target segment
 * (the host is listed before, so its times are resolved). */
static int resolve_release(const nh_ctx *c, const nh_yaml_node *tool, const char *path, nh_scene *s,
                           int i) {
  nh_tool_spec *t = &s->tools[i];
  const nh_tool_spec *host = &s->tools[t->inside];
  char key[NH_KEY_MAX];
  const nh_yaml_node *at = nh_yaml_get(tool, "release", NULL);
  for (int k = 0; k < host->n_motion; ++k)
    if (host->motion[k].kind == NH_UNTIL_TARGET) {
      t->release = host->motion[k].until;
      return NH_OK;
    }
  return nh_read_fail(c, at, nh_read_join(key, path, "release"),
                      "target: the host '%s' has no motion segment with until: target", host->name);
}

/* The time a symbolic until of tools[i]'s segment k resolves to: when the tip,
 * moving at the segment's speed from the segment's start, has travelled the
 * planned depth (target) or is back at its start (start). */
static int resolve_until(const nh_ctx *c, const nh_yaml_node *at, const char *key, nh_scene *s,
                         int i, int k) {
  nh_tool_spec *t = &s->tools[i];
  nh_motion *m = &t->motion[k];
  double t0 = k > 0 ? t->motion[k - 1].until : 0.0;
  /* A nested tool follows its host until its release: its own motion starts then. */
  if (t->inside >= 0 && !isfinite(t->release))
    return nh_read_fail(c, at, key,
                        "%s: the tool follows its host '%s' and is never released (give release)",
                        m->kind == NH_UNTIL_TARGET ? "target" : "start", s->tools[t->inside].name);
  double start = t->inside >= 0 ? fmax(t0, t->release) : t0;
  double travelled = nh_scene_tip_travel(s, i, k, start);
  if (m->kind == NH_UNTIL_TARGET) {
    if (!(travelled < t->depth))
      return nh_read_fail(c, at, key,
                          "target: by %g s the tip has already travelled %g m, the planned depth "
                          "is %g m",
                          start, travelled, t->depth);
    m->until = start + (t->depth - travelled) / m->speed;
  } else {
    if (!(travelled > 0))
      return nh_read_fail(c, at, key,
                          "start: by %g s the tip is not ahead of its start (it has travelled %g "
                          "m)",
                          start, travelled);
    m->until = start + travelled / -m->speed;
  }
  return NH_OK;
}

/* tools.i.motion: every symbolic until to a time, then the order of all. */
static int resolve_motion(const nh_ctx *c, const nh_yaml_node *tool, const char *path, nh_scene *s,
                          int i) {
  nh_tool_spec *t = &s->tools[i];
  char motion[NH_KEY_MAX], item[NH_KEY_MAX], key[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(tool, "motion", NULL);
  nh_read_join(motion, path, "motion");
  for (int k = 0; k < t->n_motion; ++k) {
    nh_motion *m = &t->motion[k];
    const nh_yaml_node *at = nh_yaml_get(list->items[k], "until", NULL);
    nh_read_join(key, nh_read_index(item, motion, k), "until");
    double t0 = k > 0 ? t->motion[k - 1].until : 0.0;
    if (m->kind != NH_UNTIL_TIME) NH_TRY(resolve_until(c, at, key, s, i, k));
    if (!(m->until > t0))
      return nh_read_fail(c, at, key, "times must increase strictly (%.17g after %.17g%s)",
                          m->until, t0,
                          k > 0 && t->motion[k - 1].kind != NH_UNTIL_TIME
                              ? ", the time the previous segment's until resolves to"
                              : "");
  }
  return NH_OK;
}

/* tools.i.bevel.toward, once the direction is known: made orthogonal to it
 * and normalised; an error if (nearly) parallel to it. */
static int resolve_bevel(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                         nh_tool_spec *t) {
  char key[NH_KEY_MAX];
  double *b = t->bevel_toward, n = nh_vec3_norm(b), p = nh_vec3_dot(b, t->direction);
  if (n == 0) return NH_OK;
  for (int k = 0; k < 3; ++k) b[k] -= p * t->direction[k];
  double m = nh_vec3_norm(b);
  if (!(m > 1e-6 * n)) {
    const nh_yaml_node *bevel = nh_yaml_get(tool, "bevel", NULL);
    return nh_read_fail(c, nh_yaml_get(bevel, "toward", NULL),
                        nh_read_join(key, path, "bevel.toward"),
                        "is parallel to the tool's direction [%g, %g, %g]: give a side across it",
                        t->direction[0], t->direction[1], t->direction[2]);
  }
  for (int k = 0; k < 3; ++k) b[k] /= m;
  return NH_OK;
}

int nh_read_plans(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  char path[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(root, "tools", NULL);
  for (int i = 0; i < s->n_tools; ++i) { /* a host before the tools inside it */
    nh_tool_spec *t = &s->tools[i];
    const nh_yaml_node *tool = list->items[i];
    nh_read_index(path, "tools", i);
    if (t->planned) NH_TRY(resolve_trajectory(c, tool, path, s, i));
    if (t->release_target) NH_TRY(resolve_release(c, tool, path, s, i));
    NH_TRY(resolve_motion(c, tool, path, s, i));
    NH_TRY(resolve_bevel(c, tool, path, t));
  }
  return NH_OK;
}
