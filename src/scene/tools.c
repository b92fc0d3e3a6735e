/* tools.c — the tools section: each tool's beam (size, material, damping),
 * where it starts (base and direction, or a planned trajectory), its motion
 * (speed and spin segments, `until` a time or the word target or start),
 * the bevel of its tip, its interaction with the tissue, and nesting (a tool
 * inside a host listed before it, released at a time or when the host's
 * until: target ends). What depends on the targets (a trajectory's target,
 * release: target, symbolic untils) is resolved by trajectory.c once they
 * are read. */
#include "scene/scene_impl.h"

#include <ctype.h>
#include <math.h>
#include <string.h>
#include <strings.h>

#define TL(member) offsetof(nh_tool_spec, member)

/* tools.i.name: it names the files <name>.pvd and <name>_NNNNNN.vtu, so a
 * plain file name, distinct from the other tools' even on a file system that
 * ignores case, and from the folder's other .pvd files. */
static int read_name(const nh_ctx *c, const nh_key_site *k, void *base) {
  static const char *const reserved[] = {"tissue", "points", NULL};
  nh_tool_spec *t = base;
  const nh_tool_spec *tools = c->scene->tools;
  const nh_yaml_node *at = k->at;
  const char *key = k->key;
  char d[96];
  NH_TRY(nh_read_string(c, at, key, t->name, sizeof t->name));
  size_t len = strlen(t->name);
  if (len == 0 || strspn(t->name, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                  "0123456789_-") != len)
    return nh_read_fail(c, at, key,
                        "%s must be non-empty and contain only letters, digits, '_' and '-' (it "
                        "names the output file NAME.pvd)",
                        nh_read_describe(at, d, sizeof d));
  for (const char *const *r = reserved; *r; ++r)
    if (!strcasecmp(t->name, *r))
      return nh_read_fail(c, at, key, "%s is taken: the output folder already holds %s.pvd",
                          nh_read_describe(at, d, sizeof d), *r);
  for (int j = 0; j < c->item; ++j) {
    if (!strcmp(tools[j].name, t->name))
      return nh_read_fail(c, at, key, "%s is already the name of tools.%d",
                          nh_read_describe(at, d, sizeof d), j);
    if (!strcasecmp(tools[j].name, t->name))
      return nh_read_fail(c, at, key,
                          "%s differs from the name of tools.%d ('%s') only in case (tool names "
                          "name files, and some file systems ignore case)",
                          nh_read_describe(at, d, sizeof d), j, tools[j].name);
  }
  return NH_OK;
}

static int check_inner_radius(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_tool_spec *t = base;
  if (!(t->inner_radius < t->radius))
    return nh_read_fail(c, k->at, k->key, "must be less than the radius (%g), got %g", t->radius,
                        t->inner_radius);
  return NH_OK;
}

/* Beam elements of one tool: a finer beam than this resolves nothing the
 * tissue's cells can feel, and 2^31 of them would overflow the node count. */
#define NH_TOOL_MAX_ELEMENTS 100000

static int check_elements(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_tool_spec *t = base;
  if (t->elements > NH_TOOL_MAX_ELEMENTS)
    return nh_read_fail(c, k->at, k->key, "must be at most %d, got %d", NH_TOOL_MAX_ELEMENTS,
                        t->elements);
  return NH_OK;
}

static const nh_key material_rows[] = {
    {NH_NUMBER("young", TL(young), 0, NH_ABOVE, 0), .required = 1},
    {NH_NUMBER("poisson", TL(poisson), 0.3, NH_ANY, 0), .check = nh_read_check_poisson},
    {NH_NUMBER("density", TL(density), 7800, NH_AT_LEAST, 0)},
    {0},
};

static const nh_key damping_rows[] = {
    {NH_NUMBER("mass", TL(damping_mass), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("stiffness", TL(damping_stiffness), 0, NH_AT_LEAST, 0)},
    {0},
};

/* tools.i.trajectory: the target's name is looked up by trajectory.c, once
 * the targets are read. */
static const nh_key trajectory_rows[] = {
    {NH_POINT("entry", TL(entry)), .required = 1},
    {NH_CUSTOM("target", NULL), .required = 1},
    {NH_NUMBER("standoff", TL(standoff), 0.005, NH_ABOVE, 0)},
    {NH_POINT("aim", TL(aim))},
    {0},
};

/* tools.i.trajectory given: the tool is planned; base and direction, which
 * the trajectory sets, must not be given. */
static int trajectory_given(const nh_ctx *c, const nh_key_site *k, void *base) {
  static const char *const computed[] = {"base", "direction", NULL};
  char key[NH_KEY_MAX];
  for (const char *const *name = computed; *name; ++name) {
    const nh_yaml_node *at;
    if (nh_yaml_get(k->map, *name, &at))
      return nh_read_fail(c, at, nh_read_join(key, k->path, *name),
                          "not with trajectory: the trajectory sets the base and the direction");
  }
  ((nh_tool_spec *)base)->planned = 1;
  return NH_OK;
}

/* tools.i.base (required without a trajectory). */
static int read_base(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_tool_spec *t = base;
  if (t->planned) return NH_OK;
  return nh_read_get(c, k->map, k->path, "base", NH_KEY_VEC3, 1, t->base, NULL);
}

/* tools.i.direction (required without a trajectory, non-zero), stored with unit length. */
static int read_direction(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_tool_spec *t = base;
  double *direction = t->direction;
  const nh_yaml_node *at;
  if (t->planned) return NH_OK;
  NH_TRY(nh_read_get(c, k->map, k->path, "direction", NH_KEY_VEC3, 1, direction, &at));
  /* Scale by the largest component first, so that squaring neither
   * overflows (1e200) nor underflows (1e-200). */
  double scale = 0, norm = 0;
  for (int i = 0; i < 3; ++i) scale = fmax(scale, fabs(direction[i]));
  if (!(scale > 0)) return nh_read_fail(c, at, k->key, "must not be the zero vector");
  for (int i = 0; i < 3; ++i) norm += (direction[i] / scale) * (direction[i] / scale);
  norm = sqrt(norm);
  for (int i = 0; i < 3; ++i) direction[i] = direction[i] / scale / norm;
  return NH_OK;
}

/* The word of a symbolic `until` (NH_UNTIL_TIME if `n` is not one). */
static nh_until_kind until_word(const nh_yaml_node *n) {
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n)) return NH_UNTIL_TIME;
  if (!strcmp(n->text, "target")) return NH_UNTIL_TARGET;
  if (!strcmp(n->text, "start")) return NH_UNTIL_START;
  return NH_UNTIL_TIME;
}

/* The speed of a segment that ends at a symbolic until: it must move the tip
 * towards it. */
static int read_symbolic_speed(const nh_ctx *c, const nh_yaml_node *m, const char *item,
                               nh_motion *segment) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *at;
  NH_TRY(nh_read_get(c, m, item, "speed", NH_KEY_NUMBER, 1, &segment->speed, &at));
  if (segment->kind == NH_UNTIL_TARGET && !(segment->speed > 0))
    return nh_read_fail(c, at, nh_read_join(key, item, "speed"),
                        "must be greater than 0 with until: target (the tip advances to the "
                        "target), got %g",
                        segment->speed);
  if (segment->kind == NH_UNTIL_START && !(segment->speed < 0))
    return nh_read_fail(c, at, nh_read_join(key, item, "speed"),
                        "must be less than 0 with until: start (the tip withdraws to its start), "
                        "got %g",
                        segment->speed);
  return NH_OK;
}

/* tools.i.motion: [{until, speed, spin}, ...] with `until` > 0 and strictly
 * increasing; absent or empty: the tool stays at rest. `until` may also be
 * the word target (speed > 0) or start (speed < 0) on a tool with a
 * trajectory: nh_read_plans turns it into a time, and checks the order of
 * the times around it then. */
static int read_motion(const nh_ctx *c, const nh_key_site *k, void *base) {
  static const char *const keys[] = {"until", "speed", "spin", NULL};
  nh_tool_spec *t = base;
  char item[NH_KEY_MAX], key[NH_KEY_MAX], d[96];
  const nh_yaml_node *list;
  NH_TRY(nh_read_list(c, k->map, k->path, "motion", &list));
  if (!list || list->n == 0) return NH_OK;
  t->motion = nh_calloc((size_t)list->n, sizeof *t->motion);
  if (!t->motion) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *m = list->items[i], *at;
    nh_motion *segment = &t->motion[i];
    nh_read_index(item, k->key, i);
    if (m->kind != NH_YAML_MAP)
      return nh_read_fail(c, m, item, "expected a segment {until: TIME, speed: SPEED}, got %s",
                          nh_read_describe(m, d, sizeof d));
    NH_TRY(nh_read_keys(c, m, item, keys));
    NH_TRY(nh_read_get(c, m, item, "spin", NH_KEY_NUMBER, 0, &segment->spin, NULL));
    NH_TRY(nh_read_field(c, m, item, "until", 1, &at));
    segment->kind = until_word(at);
    if (segment->kind != NH_UNTIL_TIME) {
      if (!t->planned)
        return nh_read_fail(c, at, nh_read_join(key, item, "until"),
                            "%s needs a trajectory (give %s.trajectory: {entry, target}): it is "
                            "a position on the planned path",
                            nh_read_describe(at, d, sizeof d), k->path);
      NH_TRY(read_symbolic_speed(c, m, item, segment));
      t->n_motion = i + 1;
      continue;
    }
    NH_TRY(nh_read_number(c, at, nh_read_join(key, item, "until"), &segment->until));
    if (i == 0) NH_TRY(nh_read_at_least(c, at, item, "until", segment->until, 0, 1));
    if (i > 0 && t->motion[i - 1].kind == NH_UNTIL_TIME &&
        !(segment->until > t->motion[i - 1].until))
      return nh_read_fail(c, at, nh_read_join(key, item, "until"),
                          "times must increase strictly (%g after %g)", segment->until,
                          t->motion[i - 1].until);
    NH_TRY(nh_read_get(c, m, item, "speed", NH_KEY_NUMBER, 1, &segment->speed, NULL));
    t->n_motion = i + 1;
  }
  return NH_OK;
}

static int check_angle(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_tool_spec *t = base;
  if (!(t->bevel >= 0 && t->bevel < 90))
    return nh_read_fail(c, k->at, k->key, "must lie in [0, 90) degrees, got %g", t->bevel);
  return NH_OK;
}

/* bevel.toward: non-zero (made orthogonal to the direction by
 * trajectory.c, once a trajectory has set it). */
static int check_toward(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!(nh_vec3_norm(((nh_tool_spec *)base)->bevel_toward) > 0))
    return nh_read_fail(c, k->at, k->key, "must not be the zero vector");
  return NH_OK;
}

static const nh_key bevel_rows[] = {
    {NH_NUMBER("angle", TL(bevel), 0, NH_ANY, 0), .required = 1, .check = check_angle},
    {NH_VEC3("toward", TL(bevel_toward)), .check = check_toward},
    {0},
};

/* The static friction coefficient is at least the kinetic one, which is
 * its default; a torsional friction needs the dynamic mode. */
static int check_friction(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_tool_spec *t = base;
  char key[NH_KEY_MAX];
  const nh_yaml_node *at = nh_yaml_get(k->at, "friction_static", NULL);
  if (at && t->friction_static < t->friction)
    return nh_read_fail(c, at, nh_read_join(key, k->key, "friction_static"),
                        "the static coefficient must be at least the kinetic one (friction = %g), "
                        "got %g",
                        t->friction, t->friction_static);
  if (t->friction_static < t->friction) t->friction_static = t->friction;
  /* the torsional friction resists the spin rate: the dynamic mode's */
  at = nh_yaml_get(k->at, "torsion_per_length", NULL);
  if (at && t->torsion_per_length > 0 && c->scene->time.mode == NH_MODE_STATIC)
    return nh_read_fail(c, at, nh_read_join(key, k->key, "torsion_per_length"),
                        "needs time.mode: dynamic (the torsional friction resists the needle's "
                        "spin rate; the quasi-static mode has none)");
  return NH_OK;
}

static const nh_key interaction_rows[] = {
    {NH_NUMBER("puncture_force", TL(puncture_force), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("cutting_force", TL(cutting_force), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("friction", TL(friction), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("friction_per_length", TL(friction_per_length), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("spacing", TL(spacing), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("friction_static", TL(friction_static), 0, NH_AT_LEAST, 0)}, /* check_friction */
    {NH_NUMBER("torsion_per_length", TL(torsion_per_length), 0, NH_AT_LEAST, 0)},
    {0},
};

/* tools.i.inside (optional): the name of a tool listed before this one that
 * is not itself nested; t->inside = its index (-1: none). */
static int read_host(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_tool_spec *t = base;
  const nh_tool_spec *tools = c->scene->tools;
  const nh_yaml_node *at = k->at, *list = nh_yaml_get(c->root, "tools", NULL);
  const char *key = k->key;
  char host[NH_NAME_MAX], d[96];
  t->inside = -1;
  if (!at) return NH_OK;
  NH_TRY(nh_read_string(c, at, key, host, sizeof host));
  for (int j = 0; j < c->item; ++j) {
    if (strcmp(tools[j].name, host) != 0) continue;
    if (tools[j].inside >= 0)
      return nh_read_fail(c, at, key,
                          "%s (tools.%d) is itself inside '%s': tools nest one level deep only",
                          nh_read_describe(at, d, sizeof d), j, tools[tools[j].inside].name);
    t->inside = j;
    return NH_OK;
  }
  if (!strcmp(host, t->name)) return nh_read_fail(c, at, key, "a tool cannot be inside itself");
  for (int j = c->item + 1; j < list->n; ++j) {
    const nh_yaml_node *name = nh_yaml_get(list->items[j], "name", NULL);
    if (name && name->kind == NH_YAML_SCALAR && !strcmp(name->text, host))
      return nh_read_fail(c, at, key, "%s is tools.%d, listed after this tool: list the host first",
                          nh_read_describe(at, d, sizeof d), j);
  }
  return nh_read_fail(c, at, key, "no tool named %s is listed before this one",
                      nh_read_describe(at, d, sizeof d));
}

/* tools.i.release: a time >= 0, or the word target (resolved by
 * trajectory.c); only with inside. Default: never. */
static int read_release(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_tool_spec *t = base;
  const nh_yaml_node *at = k->at;
  const char *key = k->key;
  char d[96];
  t->release = INFINITY;
  if (!at) return NH_OK;
  if (t->inside < 0)
    return nh_read_fail(c, at, key,
                        "applies to a nested tool only (give inside: HOST, the tool it starts in)");
  if (until_word(at) == NH_UNTIL_TARGET) {
    t->release_target = 1;
    return NH_OK;
  }
  if (at->kind == NH_YAML_SCALAR && !nh_yaml_is_null(at) && !at->quoted &&
      (isalpha((unsigned char)at->text[0]) || at->text[0] == '_'))
    return nh_read_fail(c, at, key, "expected a time or the word target, got %s",
                        nh_read_describe(at, d, sizeof d));
  NH_TRY(nh_read_number(c, at, key, &t->release));
  return nh_read_at_least(c, at, k->path, "release", t->release, 0, 0);
}

/* A tool's keys in the order they are read: a trajectory before base and
 * direction (which it sets), the host before release. */
static const nh_key tool_rows[] = {
    {NH_CUSTOM("name", read_name), .required = 1},
    {NH_NUMBER("length", TL(length), 0, NH_ABOVE, 0), .required = 1},
    {NH_NUMBER("radius", TL(radius), 0, NH_ABOVE, 0), .required = 1},
    {NH_NUMBER("inner_radius", TL(inner_radius), 0, NH_AT_LEAST, 0), .check = check_inner_radius},
    {NH_INT("elements", TL(elements), 16, NH_AT_LEAST, 1), .check = check_elements},
    {NH_MAP("material", material_rows), .required = 1},
    {NH_MAP("damping", damping_rows)},
    {NH_MAP("trajectory", trajectory_rows), .read = trajectory_given},
    {NH_CUSTOM("base", read_base)},
    {NH_CUSTOM("direction", read_direction)},
    {NH_CUSTOM("motion", read_motion)},
    {NH_MAP("bevel", bevel_rows)},
    {NH_MAP("interaction", interaction_rows), .check = check_friction},
    {NH_CUSTOM("inside", read_host)},
    {NH_CUSTOM("release", read_release)},
    {0},
};

int nh_read_tools(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  char path[NH_KEY_MAX], d[96];
  const nh_yaml_node *list;
  NH_TRY(nh_read_list(c, root, "", "tools", &list));
  if (!list || list->n == 0) return NH_OK;
  s->tools = nh_calloc((size_t)list->n, sizeof *s->tools);
  if (!s->tools) return NH_ERR_MEMORY;
  nh_ctx item = *c;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *node = list->items[i];
    nh_tool_spec *t = &s->tools[i];
    s->n_tools = i + 1; /* counted first: destroy frees a half-read motion */
    item.item = i;
    nh_read_index(path, "tools", i);
    nh_read_defaults(tool_rows, t);
    t->target = -1; /* set by the trajectory's target (trajectory.c) */
    if (node->kind != NH_YAML_MAP)
      return nh_read_fail(c, node, path,
                          "expected a tool {name: ..., length: ..., radius: ..., material: ..., "
                          "base: [x, y, z], direction: [x, y, z]}, got %s",
                          nh_read_describe(node, d, sizeof d));
    nh_read_where(c, node, path, t->where);
    NH_TRY(nh_read_table(&item, node, path, tool_rows, t));
  }
  return NH_OK;
}
