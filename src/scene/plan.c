/* plan.c — trajectory planning: the tool keys that depend on other keys,
 * resolved once everything is read (docs/scene.md, "Planned trajectories").
 *
 * For each tool, in list order (a host is listed before the tools inside it,
 * so its times are known when a nested tool needs them):
 *  - trajectory: {target} gives the direction entry → target, the planned
 *    depth (standoff + distance) and the base, so that the tip starts
 *    `standoff` before the entry point on that line;
 *  - release: target is the end of the host's `until: target` segment;
 *  - motion: a symbolic until becomes a time: `target` ends the segment when
 *    the tip has travelled the planned depth, `start` when it is back at its
 *    start, the tip's travel integrated over the earlier segments exactly as
 *    the contact module moves the tool (a nested tool with its host until its
 *    release, by its own segments after). Times must then increase strictly.
 * Every failure is a scene error at the key's line (nh_scene_fail). */
#include "scene/scene_impl.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* Distance along its direction that tools[i]'s tip has travelled by time t,
 * counting the segments [a, b) of `sp` within [from, t] (a = the previous
 * segment's end, 0 for the first) up to segment n (excluded), as the contact
 * module integrates them. */
static double segment_travel(const nh_tool_spec *sp, int n, double from, double t) {
  double d = 0, a = 0;
  for (int k = 0; k < n; ++k) {
    double t0 = fmax(a, from), t1 = fmin(sp->motion[k].until, t);
    if (t1 > t0) d += sp->motion[k].speed * (t1 - t0);
    a = sp->motion[k].until;
  }
  return d;
}

/* The tip travel of tools[i] by time t from its first n segments: a nested
 * tool moves with its host until its release and by its own segments after
 * (as the contact module moves it), an outer tool by its own segments. */
static double tip_travel(const nh_scene *s, int i, int n, double t) {
  const nh_tool_spec *sp = &s->tools[i];
  if (sp->inside < 0) return segment_travel(sp, n, 0, t);
  const nh_tool_spec *host = &s->tools[sp->inside];
  double release = fmin(sp->release, t);
  return segment_travel(host, host->n_motion, 0, release) + segment_travel(sp, n, release, t);
}

/* tools.i.trajectory (the target's name, now that targets are read): base,
 * direction and planned depth. */
static int resolve_trajectory(const nh_scene_ctx *c, const nh_yaml_node *tool, const char *path,
                              nh_scene *s, int i) {
  nh_tool_spec *t = &s->tools[i];
  char key[NH_KEY_MAX], sub[NH_KEY_MAX], name[NH_NAME_MAX], d[96], names[256];
  const nh_yaml_node *traj = nh_yaml_get(tool, "trajectory", NULL), *at;
  nh_scene_join(sub, path, "trajectory");
  NH_TRY(nh_scene_field(c, traj, sub, "target", 1, &at));
  NH_TRY(nh_scene_as_string(c, at, nh_scene_join(key, sub, "target"), name, sizeof name));
  for (int j = 0; j < s->n_targets && t->target < 0; ++j)
    if (!strcmp(s->targets[j].name, name)) t->target = j;
  if (t->target < 0 && s->n_targets == 0)
    return nh_scene_fail(c, at, key, "no target named %s (the scene has no targets)",
                         nh_scene_describe(at, d, sizeof d));
  if (t->target < 0) {
    size_t len = 0;
    names[0] = '\0';
    for (int j = 0; j < s->n_targets && len < sizeof names; ++j) {
      int n =
          snprintf(names + len, sizeof names - len, "%s'%s'", j ? ", " : "", s->targets[j].name);
      if (n < 0) break;
      len += (size_t)n;
    }
    return nh_scene_fail(c, at, key, "no target named %s (the targets are %s)",
                         nh_scene_describe(at, d, sizeof d), names);
  }
  /* The distance scaled by its largest component, so that squaring neither
   * overflows nor underflows (as read_direction). */
  const double *target = s->targets[t->target].point;
  double v[3], scale = 0, norm = 0;
  for (int k = 0; k < 3; ++k) v[k] = target[k] - t->entry[k], scale = fmax(scale, fabs(v[k]));
  if (!(scale > 0))
    return nh_scene_fail(c, at, key, "target %s is at the entry point [%g, %g, %g]: no direction",
                         nh_scene_describe(at, d, sizeof d), t->entry[0], t->entry[1], t->entry[2]);
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

/* tools.i.release: target — the end of the host's until: target segment
 * (the host is listed before, so its times are resolved). */
static int resolve_release(const nh_scene_ctx *c, const nh_yaml_node *tool, const char *path,
                           nh_scene *s, int i) {
  nh_tool_spec *t = &s->tools[i];
  const nh_tool_spec *host = &s->tools[t->inside];
  char key[NH_KEY_MAX];
  const nh_yaml_node *at = nh_yaml_get(tool, "release", NULL);
  for (int k = 0; k < host->n_motion; ++k)
    if (host->motion[k].kind == NH_UNTIL_TARGET) {
      t->release = host->motion[k].until;
      return NH_OK;
    }
  return nh_scene_fail(c, at, nh_scene_join(key, path, "release"),
                       "target: the host '%s' has no motion segment with until: target",
                       host->name);
}

/* tools.i.motion: every symbolic until to a time, then the order of all. */
static int resolve_motion(const nh_scene_ctx *c, const nh_yaml_node *tool, const char *path,
                          nh_scene *s, int i) {
  nh_tool_spec *t = &s->tools[i];
  char motion[NH_KEY_MAX], item[NH_KEY_MAX], key[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(tool, "motion", NULL);
  nh_scene_join(motion, path, "motion");
  for (int k = 0; k < t->n_motion; ++k) {
    nh_motion *m = &t->motion[k];
    const nh_yaml_node *at = nh_yaml_get(list->items[k], "until", NULL);
    nh_scene_join(key, nh_scene_join_index(item, motion, k), "until");
    double t0 = k > 0 ? t->motion[k - 1].until : 0.0;
    if (m->kind != NH_UNTIL_TIME) {
      /* A nested tool follows its host until its release: its own motion
       * starts then. */
      if (t->inside >= 0 && !isfinite(t->release))
        return nh_scene_fail(
            c, at, key, "%s: the tool follows its host '%s' and is never released (give release)",
            m->kind == NH_UNTIL_TARGET ? "target" : "start", s->tools[t->inside].name);
      double start = t->inside >= 0 ? fmax(t0, t->release) : t0;
      double travelled = tip_travel(s, i, k, start);
      if (m->kind == NH_UNTIL_TARGET) {
        if (!(travelled < t->depth))
          return nh_scene_fail(
              c, at, key,
              "target: by %g s the tip has already travelled %g m, the planned depth is "
              "%g m",
              start, travelled, t->depth);
        m->until = start + (t->depth - travelled) / m->speed;
      } else {
        if (!(travelled > 0))
          return nh_scene_fail(
              c, at, key,
              "start: by %g s the tip is not ahead of its start (it has travelled %g m)", start,
              travelled);
        m->until = start + travelled / -m->speed;
      }
    }
    if (!(m->until > t0))
      return nh_scene_fail(c, at, key, "times must increase strictly (%.17g after %.17g%s)",
                           m->until, t0,
                           k > 0 && t->motion[k - 1].kind != NH_UNTIL_TIME
                               ? ", the time the previous segment's until resolves to"
                               : "");
  }
  return NH_OK;
}

int nh_scene_plan(const nh_scene_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  char path[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(root, "tools", NULL);
  for (int i = 0; i < s->n_tools; ++i) {
    nh_tool_spec *t = &s->tools[i];
    const nh_yaml_node *tool = list->items[i];
    nh_scene_join_index(path, "tools", i);
    if (t->planned) NH_TRY(resolve_trajectory(c, tool, path, s, i));
    if (t->release_target) NH_TRY(resolve_release(c, tool, path, s, i));
    NH_TRY(resolve_motion(c, tool, path, s, i));
  }
  return NH_OK;
}
