/* regions.c — regions of space and the tissue's lists of them: fixed
 * regions (with the components they fix and a prescribed displacement),
 * loads (a total force) and tractions (a traction vector or a pressure),
 * each exactly one shape — box, sphere, cylinder or the voxels of a label —
 * with an optional schedule. The shape is read right after the item's keys
 * are checked, the item's other keys by its table. */
#include "scene/scene_impl.h"

#include <string.h>

static const char *const axis_name[3] = {"x", "y", "z"};

int nh_read_box(const nh_ctx *c, const nh_yaml_node *box, const char *path, int strict,
                double min[3], double max[3]) {
  static const char *const keys[] = {"min", "max", NULL};
  char key[NH_KEY_MAX], d[96];
  if (box->kind != NH_YAML_MAP)
    return nh_read_fail(c, box, path, "expected a mapping {min: [x, y, z], max: [x, y, z]}, got %s",
                        nh_read_describe(box, d, sizeof d));
  NH_TRY(nh_read_keys(c, box, path, keys));
  const nh_yaml_node *at_max;
  NH_TRY(nh_read_get(c, box, path, "min", NH_KEY_VEC3, 1, min, NULL));
  NH_TRY(nh_read_get(c, box, path, "max", NH_KEY_VEC3, 1, max, &at_max));
  for (int i = 0; i < 3; ++i)
    if (strict ? !(max[i] > min[i]) : !(max[i] >= min[i]))
      return nh_read_fail(c, at_max, nh_read_join(key, path, "max"),
                          "must be %s min in every component (%s: max %g, min %g)",
                          strict ? "greater than" : "at least", axis_name[i], max[i], min[i]);
  return NH_OK;
}

/* A positive radius (required) of the mapping `map`. */
static int read_radius(const nh_ctx *c, const nh_yaml_node *map, const char *path, double *radius) {
  const nh_yaml_node *at;
  NH_TRY(nh_read_get(c, map, path, "radius", NH_KEY_NUMBER, 1, radius, &at));
  return nh_read_at_least(c, at, path, "radius", *radius, 0, 1);
}

static int is_shape(const char *key) {
  return !strcmp(key, "box") || !strcmp(key, "sphere") || !strcmp(key, "cylinder") ||
         !strcmp(key, "label");
}

/* The shape of a region: exactly one of the keys box {min, max},
 * sphere {center, radius}, cylinder {start, end, radius}, label N in the
 * mapping `node` (whose keys the caller has checked). */
static int read_shape(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                      nh_region *region) {
  static const char *const sphere_keys[] = {"center", "radius", NULL};
  static const char *const cylinder_keys[] = {"start", "end", "radius", NULL};
  char key[NH_KEY_MAX], d[96];
  const nh_yaml_node *shape = NULL, *shape_key = NULL;
  for (int i = 0; i < node->n; ++i) {
    if (!is_shape(node->keys[i]->text)) continue;
    if (shape)
      return nh_read_fail(c, node->keys[i], nh_read_join(key, path, node->keys[i]->text),
                          "give exactly one of box, sphere, cylinder, label (%s is already given)",
                          shape_key->text);
    shape = node->items[i], shape_key = node->keys[i];
  }
  if (!shape) return nh_read_fail(c, node, path, "give one of box, sphere, cylinder, label");
  nh_read_join(key, path, shape_key->text);
  if (!strcmp(shape_key->text, "label")) { /* the voxels of the label image holding it; */
    region->kind = NH_REGION_LABEL;        /* that image is checked by the domain */
    return nh_read_label(c, shape, key, &region->label);
  }
  if (!strcmp(shape_key->text, "box")) {
    region->kind = NH_REGION_BOX;
    return nh_read_box(c, shape, key, 0, region->min, region->max);
  }
  int sphere = !strcmp(shape_key->text, "sphere");
  if (shape->kind != NH_YAML_MAP)
    return nh_read_fail(c, shape, key, "expected a mapping %s, got %s",
                        sphere ? "{center: [x, y, z], radius: r}"
                               : "{start: [x, y, z], end: [x, y, z], radius: r}",
                        nh_read_describe(shape, d, sizeof d));
  NH_TRY(nh_read_keys(c, shape, key, sphere ? sphere_keys : cylinder_keys));
  if (sphere) {
    region->kind = NH_REGION_SPHERE;
    NH_TRY(nh_read_get(c, shape, key, "center", NH_KEY_VEC3, 1, region->center, NULL));
    return read_radius(c, shape, key, &region->radius);
  }
  const nh_yaml_node *at_end;
  region->kind = NH_REGION_CYLINDER;
  NH_TRY(nh_read_get(c, shape, key, "start", NH_KEY_VEC3, 1, region->start, NULL));
  NH_TRY(nh_read_get(c, shape, key, "end", NH_KEY_VEC3, 1, region->end, &at_end));
  double len2 = 0;
  for (int i = 0; i < 3; ++i)
    len2 += (region->end[i] - region->start[i]) * (region->end[i] - region->start[i]);
  if (!(len2 > 0)) {
    char sub[NH_KEY_MAX];
    return nh_read_fail(c, at_end, nh_read_join(sub, key, "end"),
                        "must differ from start (the cylinder's axis)");
  }
  return read_radius(c, shape, key, &region->radius);
}

/* An item of a region list: a mapping (else "expected EXPECTED") with the
 * keys of `rows`, its shape into region, then the rest of its rows into base. */
static int read_item(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                     const char *expected, const nh_key *rows, nh_region *region, void *base) {
  char d[96];
  if (node->kind != NH_YAML_MAP)
    return nh_read_fail(c, node, path, "expected %s, got %s", expected,
                        nh_read_describe(node, d, sizeof d));
  NH_TRY(nh_read_row_keys(c, node, path, rows));
  NH_TRY(read_shape(c, node, path, region));
  nh_read_where(c, node, path, region->where);
  return nh_read_rows(c, node, path, rows, base);
}

/* tissue.fixed.N.axes: a non-empty list of x, y, z, none twice (default: all). */
static int read_axes(const nh_ctx *c, const nh_key_site *k, void *base) {
  static const char *const axis_names[] = {"x", "y", "z", NULL};
  const nh_yaml_node *axes = k->at;
  nh_fix *fix = base;
  char sub[NH_KEY_MAX], d[96];
  fix->axes = 7;
  if (!axes) return NH_OK;
  if (axes->kind != NH_YAML_SEQ || axes->n == 0)
    return nh_read_fail(c, axes, k->key, "expected a non-empty list of axes among x, y, z, got %s",
                        nh_read_describe(axes, d, sizeof d));
  fix->axes = 0;
  for (int i = 0; i < axes->n; ++i) {
    int a;
    NH_TRY(nh_read_choice(c, axes->items[i], nh_read_index(sub, k->key, i), axis_names, &a));
    if (fix->axes & (1 << a))
      return nh_read_fail(c, axes->items[i], sub, "axis %s is given twice", axis_names[a]);
    fix->axes |= 1 << a;
  }
  return NH_OK;
}

/* tissue.fixed.N.schedule scales the prescribed displacement: only with one. */
static int read_fix_schedule(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!k->at) return NH_OK;
  if (!nh_yaml_get(k->map, "displacement", NULL))
    return nh_read_fail(c, k->at, k->key,
                        "a schedule scales a prescribed displacement: give displacement too");
  return nh_read_schedule(c, k->at, k->key, &((nh_fix *)base)->schedule);
}

/* tissue.tractions.N: exactly one of traction [3] and pressure p. */
static int read_traction(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_traction *tr = base;
  char key[NH_KEY_MAX];
  const nh_yaml_node *tv = k->at, *pv = nh_yaml_get(k->map, "pressure", NULL);
  if (!tv && !pv)
    return nh_read_fail(c, k->map, k->path, "give traction: [tx, ty, tz] (N/m²) or pressure: p");
  if (tv && pv)
    return nh_read_fail(c, pv, nh_read_join(key, k->path, "pressure"),
                        "give either traction or pressure, not both (traction is already given)");
  if (tv) NH_TRY(nh_read_vec3(c, tv, k->key, tr->traction));
  if (pv) NH_TRY(nh_read_number(c, pv, nh_read_join(key, k->path, "pressure"), &tr->pressure));
  tr->is_pressure = pv != NULL;
  return NH_OK;
}

/* The shape keys (box, sphere, cylinder, label) are read by read_shape,
 * before the rest of the item. */
static const nh_key fixed_rows[] = {
    {NH_CUSTOM("box", NULL)},
    {NH_CUSTOM("sphere", NULL)},
    {NH_CUSTOM("cylinder", NULL)},
    {NH_CUSTOM("label", NULL)},
    {NH_CUSTOM("axes", read_axes)},
    {NH_VEC3("displacement", offsetof(nh_fix, displacement))},
    {NH_CUSTOM("schedule", read_fix_schedule)},
    {NH_NUMBER("refine", offsetof(nh_fix, refine), 0.0, NH_ABOVE, 0.0)},
    {0},
};

static const nh_key load_rows[] = {
    {NH_CUSTOM("box", NULL)},
    {NH_CUSTOM("sphere", NULL)},
    {NH_CUSTOM("cylinder", NULL)},
    {NH_CUSTOM("label", NULL)},
    {NH_VEC3("force", offsetof(nh_load, force)), .required = 1},
    {NH_SCHEDULE("schedule", offsetof(nh_load, schedule))},
    {0},
};

static const nh_key traction_rows[] = {
    {NH_CUSTOM("box", NULL)},
    {NH_CUSTOM("sphere", NULL)},
    {NH_CUSTOM("cylinder", NULL)},
    {NH_CUSTOM("traction", read_traction)},
    {NH_CUSTOM("pressure", NULL)}, /* read by read_traction */
    {NH_SCHEDULE("schedule", offsetof(nh_traction, schedule))},
    {0},
};

int nh_read_fixed(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  char key[NH_KEY_MAX];
  const nh_yaml_node *fixed, *fixed_key, *tissue_key;
  NH_TRY(nh_read_list(c, k->map, k->path, "fixed", &fixed));
  /* where_fixed points at the key `fixed:`, or at `tissue:` without it. */
  nh_yaml_get(k->map, "fixed", &fixed_key);
  nh_yaml_get(c->root, "tissue", &tissue_key);
  nh_read_where(c, fixed_key ? fixed_key : tissue_key, "tissue.fixed", s->tissue.where_fixed);
  if (!fixed || fixed->n == 0) return NH_OK;
  s->tissue.fixed = nh_calloc((size_t)fixed->n, sizeof *s->tissue.fixed);
  s->tissue.fix = nh_calloc((size_t)fixed->n, sizeof *s->tissue.fix);
  if (!s->tissue.fixed || !s->tissue.fix) return NH_ERR_MEMORY;
  for (int i = 0; i < fixed->n; ++i) {
    s->tissue.n_fixed = i + 1; /* counted first: destroy frees a half-read schedule */
    NH_TRY(read_item(c, fixed->items[i], nh_read_index(key, "tissue.fixed", i),
                     "a region {box: {min, max}}, {sphere: {center, radius}}, "
                     "{cylinder: {start, end, radius}} or {label: N}",
                     fixed_rows, &s->tissue.fixed[i], &s->tissue.fix[i]));
  }
  return NH_OK;
}

/* tissue.NAME: a list of items of `size` bytes into a new array *items, each
 * a region (at `region` bytes into the item) and the rows `rows`; *n counts
 * each item before it is read, so that destroy frees a half-read one's
 * schedule. */
static int read_list(const nh_ctx *c, const nh_yaml_node *t, const char *name, const char *expected,
                     const nh_key *rows, size_t size, size_t region, void **items, int *n) {
  char key[NH_KEY_MAX], path[NH_KEY_MAX];
  const nh_yaml_node *list;
  NH_TRY(nh_read_list(c, t, "tissue", name, &list));
  if (!list || list->n == 0) return NH_OK;
  *items = nh_calloc((size_t)list->n, size);
  if (!*items) return NH_ERR_MEMORY;
  nh_read_join(path, "tissue", name);
  for (int i = 0; i < list->n; ++i) {
    char *item = (char *)*items + (size_t)i * size;
    *n = i + 1;
    NH_TRY(read_item(c, list->items[i], nh_read_index(key, path, i), expected, rows,
                     (nh_region *)(item + region), item));
  }
  return NH_OK;
}

int nh_read_loads(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  NH_TRY(read_list(c, k->map, "loads", "a load {box: {min, max}, force: [fx, fy, fz]}", load_rows,
                   sizeof *s->tissue.loads, offsetof(nh_load, region), (void **)&s->tissue.loads,
                   &s->tissue.n_loads));
  for (int i = 0; i < s->tissue.n_loads; ++i)
    memcpy(s->tissue.loads[i].where, s->tissue.loads[i].region.where, NH_WHERE_MAX);
  return NH_OK;
}

int nh_read_tractions(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  NH_TRY(read_list(c, k->map, "tractions",
                   "a traction {box: {min, max}, traction: [tx, ty, tz]} or {box: ..., "
                   "pressure: p}",
                   traction_rows, sizeof *s->tissue.tractions, offsetof(nh_traction, region),
                   (void **)&s->tissue.tractions, &s->tissue.n_tractions));
  for (int i = 0; i < s->tissue.n_tractions; ++i)
    memcpy(s->tissue.tractions[i].where, s->tissue.tractions[i].region.where, NH_WHERE_MAX);
  return NH_OK;
}

/* plan (optional): what `needlehex plan` steers a bevel-tip needle around
 * (docs/cases.md, "Planning the steering"): obstacles (regions; a label
 * needs the scene's label image), the clearance from the tool's axis to
 * their surfaces, and the bicycle model's curvature. */
static const nh_key obstacle_rows[] = {
    {NH_CUSTOM("box", NULL)},
    {NH_CUSTOM("sphere", NULL)},
    {NH_CUSTOM("cylinder", NULL)},
    {NH_CUSTOM("label", NULL)},
    {0},
};

static int read_obstacles(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  char key[NH_KEY_MAX];
  const nh_yaml_node *list;
  NH_TRY(nh_read_list(c, k->map, k->path, "obstacles", &list));
  if (!list || list->n == 0) return NH_OK;
  s->plan.obstacles = nh_calloc((size_t)list->n, sizeof *s->plan.obstacles);
  if (!s->plan.obstacles) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    nh_region *r = &s->plan.obstacles[i];
    s->plan.n_obstacles = i + 1;
    NH_TRY(read_item(c, list->items[i], nh_read_index(key, "plan.obstacles", i),
                     "an obstacle {box: {min, max}}, {sphere: {center, radius}}, "
                     "{cylinder: {start, end, radius}} or {label: N}",
                     obstacle_rows, r, r));
    if (r->kind == NH_REGION_LABEL && !c->image) {
      char sub[NH_KEY_MAX];
      return nh_read_fail(c, list->items[i], nh_read_join(sub, key, "label"),
                          "a label obstacle needs the scene's label image (tissue.labels or "
                          "tissue.domain.mask)");
    }
  }
  return NH_OK;
}

#define P(member) offsetof(nh_scene, plan.member)
static const nh_key plan_rows[] = {
    {NH_CUSTOM("obstacles", read_obstacles)},
    {NH_NUMBER("clearance", P(clearance), 0.001, NH_AT_LEAST, 0)},
    {NH_NUMBER("curvature", P(curvature), 0, NH_AT_LEAST, 0)},
    {0},
};
#undef P

int nh_read_plan(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  NH_TRY(nh_read_top(c, root, "plan", 0, plan_rows, s));
  const nh_yaml_node *m = nh_yaml_get(root, "plan", NULL);
  if (m) nh_read_where(c, m, "plan", s->plan.where);
  return NH_OK;
}
