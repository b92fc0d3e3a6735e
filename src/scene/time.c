/* time.c — the scene's clock and the field every body feels: the time
 * section (mode, step, and the run's length as end or steps) and gravity
 * (a vector, or a vector and a schedule scaling it). */
#include "scene/scene_impl.h"

#include <math.h>

/* The most steps a run may take, from time.steps or time.end / time.step:
 * at 0.01 s a step, over a day of cheap steps; the run keeps a timing row
 * per step, allocated for all steps up front (1e9 steps: 64 GB, refused as
 * "out of memory" before this bound). */
#define NH_STEPS_MAX 1e7
/* The step's range in seconds. Below 1 ns the inertia ρ/Δt² of a 1 mm cell
 * exceeds its stiffness E/h² (E = 1 MPa, ρ = 1000 kg/m³) by more than 1e9,
 * so double precision keeps nothing of a load (at 1e-300 s, ρ/Δt² is
 * infinite and the run "succeeds" standing still); above 1e6 s (11 days)
 * Δt² overflows long before a tissue's rates mean anything. */
#define NH_STEP_MIN 1e-9
#define NH_STEP_MAX 1e6

static const char *const modes[] = {"dynamic", "static", NULL};

#define T(member) offsetof(nh_scene, time.member)
static const nh_key time_rows[] = {
    {NH_CHOICE("mode", T(mode), NH_MODE_DYNAMIC, modes)},
    {NH_NUMBER("step", T(step), 0.01, NH_ABOVE, 0)},
    {NH_NUMBER("end", T(end), 0, NH_ABOVE, 0)},
    {NH_INT("steps", T(steps), 100, NH_AT_LEAST, 1)},
    {0},
};

int nh_read_time(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  NH_TRY(nh_read_top(c, root, "time", 0, time_rows, s));
  const nh_yaml_node *t = nh_yaml_get(root, "time", NULL); /* NULL fields unless a mapping */
  const nh_yaml_node *at_end = nh_yaml_get(t, "end", NULL),
                     *at_steps = nh_yaml_get(t, "steps", NULL),
                     *at_step = nh_yaml_get(t, "step", NULL);
  if (at_step && !(s->time.step >= NH_STEP_MIN && s->time.step <= NH_STEP_MAX))
    return nh_read_fail(c, at_step, "time.step", "%g s is outside [%g, %g] s", s->time.step,
                        NH_STEP_MIN, NH_STEP_MAX);
  if (at_end && at_steps) {
    /* Report at whichever of the two comes second. */
    int steps_later = at_steps->source > at_end->source ||
                      (at_steps->source == at_end->source && at_steps->line >= at_end->line);
    return steps_later ? nh_read_fail(c, at_steps, "time.steps",
                                      "give either time.end or time.steps, not both")
                       : nh_read_fail(c, at_end, "time.end",
                                      "give either time.end or time.steps, not both");
  }
  if (at_end) {
    double steps = floor(s->time.end / s->time.step + 0.5);
    if (steps > NH_STEPS_MAX)
      return nh_read_fail(c, at_end, "time.end", "end / step = %g steps is more than %g", steps,
                          NH_STEPS_MAX);
    s->time.steps = steps < 1 ? 1 : (int)steps;
  }
  if (at_steps && s->time.steps > NH_STEPS_MAX)
    return nh_read_fail(c, at_steps, "time.steps", "%d steps is more than %g", s->time.steps,
                        NH_STEPS_MAX);
  return NH_OK;
}

#define G(member) offsetof(nh_scene, member)
static const nh_key gravity_rows[] = {
    {NH_VEC3("vector", G(gravity)), .required = 1},
    {NH_SCHEDULE("schedule", G(gravity_schedule))},
    {0},
};

int nh_read_gravity(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  const nh_yaml_node *n;
  NH_TRY(nh_read_field(c, root, "", "gravity", 0, &n));
  if (!n) return NH_OK;
  if (n->kind != NH_YAML_MAP) return nh_read_vec3(c, n, "gravity", s->gravity);
  return nh_read_table(c, n, "gravity", gravity_rows, s);
}
