/* trajectory.c — trajectory planning: the kinematics behind the tool keys that
 * depend on other keys (docs/scene.md, tools), which scene.c resolves once
 * tools and targets are read and reports on at the key's line.
 *  - A planned trajectory (tools.i.trajectory: {target}) runs from the entry
 *    point to the target: its direction, the planned depth (standoff +
 *    distance) and the base, placed so that the tip starts `standoff`
 *    before the entry point on that line (nh_scene_trajectory_line).
 *  - A symbolic until (target: the tip has travelled the planned depth;
 *    start: it is back at its start) needs the tip's travel by a time over
 *    the earlier motion segments, integrated exactly as the contact module
 *    moves the tool: a nested tool with its host until its release and by
 *    its own segments after, an outer tool by its own segments
 *    (nh_scene_tip_travel). */
#include "scene/scene.h"

#include <math.h>

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

double nh_scene_tip_travel(const nh_scene *s, int i, int n, double t) {
  const nh_tool_spec *sp = &s->tools[i];
  if (sp->inside < 0) return segment_travel(sp, n, 0, t);
  const nh_tool_spec *host = &s->tools[sp->inside];
  double release = fmin(sp->release, t);
  return segment_travel(host, host->n_motion, 0, release) + segment_travel(sp, n, release, t);
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
