/* scene.c — reading and validation: YAML tree to a validated nh_scene.
 *
 * nh_scene_load parses the file into a yaml_tree, applies the `--set`
 * overrides to the tree (so an override is checked exactly like a value in
 * the file), keeps the tree's YAML text as the scene as run, and then walks
 * the schema section by section, filling defaults and checking types and
 * ranges. The schema is written out as code, one function per section, rather
 * than as a table: the sections have cross-checks (end vs steps, min < max,
 * unique probe names, a domain that is exactly one of box/brain/mask) that a
 * table would hide; tools add a host that must be listed before the tool
 * inside it, and targets name a tool, so tools are read before targets.
 *
 * Messages. Every error is one NH_ERR_INPUT message
 *     FILE:LINE: KEY: reason          (a value from the file)
 *     --set:K: KEY: reason (--set T)  (a value from the K-th override, text T)
 * where LINE is the line of the offending value, of the unknown key, or — for a
 * missing required key — of the mapping that lacks it. Every mapping's keys
 * are checked before its values, so a misspelt key is reported as unknown
 * (with a "did you mean" hint for a near miss) rather than as a missing one.
 * Keys of later features (tissue.domain.mask) are recognised and refused as
 * not supported in this version.
 *
 * Types. A number is a plain scalar that strtod consumes entirely and that is
 * finite; an integer is a number that is integral and fits in an int (8.0 is
 * accepted); a bool is true/false; a quoted scalar is always a string, so
 * young: "1e6" is refused. A YAML null (`key:` with nothing after it) is an
 * empty section for mappings and lists and an error for values.
 *
 * Files. adapt.template is resolved here, so that a scene naming a template
 * that does not exist fails `check` at the key's line: a name (hex2) is the
 * file NAME.tmpl in nh_templates_dir() ($NH_TEMPLATES_DIR, or the templates
 * installed or built next to the binary: core/paths.c); a value with a '/' or ending in
 * .tmpl is a path, relative to the scene file's folder unless absolute (so a
 * scene and its own template travel together). Only readability is checked
 * here; the template's contents are proved by nh_template_load.
 *
 * Nothing here is global: the context of one load (file name, overrides)
 * travels in an nh_ctx.
 *
 * The module's other files: trajectory.c computes the planned trajectories and
 * the tip travel that symbolic untils resolve against; schedule.c evaluates
 * schedules and gravity at a time, once per step; print.c prints the
 * summary of `check`. */
#include "scene/scene.h"

#include "anatomy/anatomy.h"
#include "scene/yaml_tree.h"

#include <ctype.h>
#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

#define NH_KEY_MAX   256
#define NH_STEPS_MAX 1000000000.0

/* What one load knows, for messages. */
typedef struct {
  const char *file;
  const char *const *overrides;
  int n_overrides;
  const char *image; /* the scene's label image (mask or tissue.labels) once read, else NULL */
} nh_ctx;

/* "FILE:LINE" or "--set:K" of a node (the top of the file when NULL). */
static void location(const nh_ctx *c, const nh_yaml_node *at, char *buf, size_t cap) {
  if (at && at->source > 0)
    snprintf(buf, cap, "--set:%d", at->source);
  else
    snprintf(buf, cap, "%s:%d", c->file, at && at->line > 0 ? at->line : 1);
}

/* Record the one input error of this load: "LOC: KEY: reason". */
static int fail(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static int fail(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *fmt, ...) {
  char loc[NH_PATH_MAX + 32], msg[1024], text[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  location(c, at, loc, sizeof loc);
  if (at && at->source > 0 && at->source <= c->n_overrides) {
    nh_yaml_one_line(text, sizeof text, c->overrides[at->source - 1]);
    return NH_ERROR(NH_ERR_INPUT, "%s: %s: %s (--set %s)", loc, key, msg, text);
  }
  return NH_ERROR(NH_ERR_INPUT, "%s: %s: %s", loc, key, msg);
}

/* "LOC: KEY" for the `where` fields. */
static void make_where(const nh_ctx *c, const nh_yaml_node *at, const char *key, char *where) {
  char loc[NH_PATH_MAX + 32];
  location(c, at, loc, sizeof loc);
  nh_yaml_join(where, NH_WHERE_MAX, loc, ": ", key); /* a very long file name is cut */
}

/* "parent.key" (or "key" at the top) into buf[NH_KEY_MAX]. */
static const char *join(char *buf, const char *parent, const char *key) {
  nh_yaml_join(buf, NH_KEY_MAX, parent, parent[0] ? "." : "", key);
  return buf;
}

/* "parent.i" into buf[NH_KEY_MAX]. */
static const char *join_index(char *buf, const char *parent, int i) {
  char index[16];
  snprintf(index, sizeof index, "%d", i);
  nh_yaml_join(buf, NH_KEY_MAX, parent, ".", index);
  return buf;
}

/* A short, one-line rendering of a node for messages: 'text', a list, ... */
static const char *describe(const nh_yaml_node *n, char *buf, size_t cap) {
  if (n->kind == NH_YAML_MAP) return "a mapping";
  if (n->kind == NH_YAML_SEQ) return "a list";
  if (nh_yaml_is_null(n)) return "nothing";
  size_t j = 0;
  buf[j++] = '\'';
  for (const char *p = n->text; *p && j + 8 < cap; ++p) {
    if (p - n->text >= 60) {
      memcpy(buf + j, "...", 3);
      j += 3;
      break;
    }
    buf[j++] = (unsigned char)*p < 0x20 ? '?' : *p; /* keep the message on one line */
  }
  buf[j++] = '\'';
  buf[j] = '\0';
  return buf;
}

/* Edit distance (Levenshtein) of two short keys, capped at 9. */
static int edit_distance(const char *a, const char *b) {
  size_t la = strlen(a), lb = strlen(b);
  if (la > 31 || lb > 31) return 9;
  int d[32][32];
  for (size_t i = 0; i <= la; ++i) d[i][0] = (int)i;
  for (size_t j = 0; j <= lb; ++j) d[0][j] = (int)j;
  for (size_t i = 1; i <= la; ++i)
    for (size_t j = 1; j <= lb; ++j) {
      int sub = d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
      int del = d[i - 1][j] + 1, ins = d[i][j - 1] + 1;
      d[i][j] = sub < del ? (sub < ins ? sub : ins) : (del < ins ? del : ins);
    }
  return d[la][lb];
}

static int in_list(const char *key, const char *const *list) {
  for (; list && *list; ++list)
    if (!strcmp(key, *list)) return 1;
  return 0;
}

/* Refuse keys of `map` that are not in `allowed` (NULL-terminated). */
static int check_keys(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                      const char *const *allowed) {
  char key[NH_KEY_MAX];
  NH_TRY(nh_scene_keys_check(path, allowed)); /* every key it reads is documented */
  for (int i = 0; i < map->n; ++i) {
    const nh_yaml_node *k = map->keys[i];
    if (in_list(k->text, allowed)) continue;
    join(key, path, k->text);
    const char *best = NULL;
    int best_d = 3;
    for (const char *const *a = allowed; *a; ++a) {
      int d = edit_distance(k->text, *a);
      if (d < best_d) best_d = d, best = *a;
    }
    if (best) return fail(c, k, key, "unknown key (did you mean '%s'?)", best);
    return fail(c, k, key, "unknown key");
  }
  return NH_OK;
}

/* ---- typed values ---- */

static int as_number(const nh_ctx *c, const nh_yaml_node *n, const char *key, double *out) {
  char d[96];
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n))
    return fail(c, n, key, "expected a number, got %s", describe(n, d, sizeof d));
  if (n->quoted)
    return fail(c, n, key, "expected a number, got the quoted string %s", describe(n, d, sizeof d));
  char *end = NULL;
  double v = strtod(n->text, &end);
  if (end == n->text || *end || n->text[0] == ' ' || n->text[0] == '\t')
    return fail(c, n, key, "expected a number, got %s", describe(n, d, sizeof d));
  if (!isfinite(v))
    return fail(c, n, key, "expected a finite number, got %s", describe(n, d, sizeof d));
  *out = v;
  return NH_OK;
}

static int as_int(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out) {
  char d[96];
  double v = 0;
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n) || n->quoted)
    return fail(c, n, key, "expected an integer, got %s", describe(n, d, sizeof d));
  char *end = NULL;
  v = strtod(n->text, &end);
  if (end == n->text || *end || !isfinite(v) || v != floor(v))
    return fail(c, n, key, "expected an integer, got %s", describe(n, d, sizeof d));
  if (v > INT_MAX || v < INT_MIN)
    return fail(c, n, key, "%s is too large for an integer", describe(n, d, sizeof d));
  *out = (int)v;
  return NH_OK;
}

static int as_bool(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out) {
  char d[96];
  if (n->kind == NH_YAML_SCALAR && !n->quoted) {
    const char *t = n->text;
    if (!strcmp(t, "true") || !strcmp(t, "True") || !strcmp(t, "TRUE")) return *out = 1, NH_OK;
    if (!strcmp(t, "false") || !strcmp(t, "False") || !strcmp(t, "FALSE")) return *out = 0, NH_OK;
  }
  return fail(c, n, key, "expected true or false, got %s", describe(n, d, sizeof d));
}

static int as_string(const nh_ctx *c, const nh_yaml_node *n, const char *key, char *out,
                     size_t cap) {
  char d[96];
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n))
    return fail(c, n, key, "expected a string, got %s", describe(n, d, sizeof d));
  if (strlen(n->text) >= cap)
    return fail(c, n, key, "%s is longer than %zu characters", describe(n, d, sizeof d), cap - 1);
  memcpy(out, n->text, strlen(n->text) + 1);
  return NH_OK;
}

/* A list of exactly 3 numbers (integers if `ints`). */
static int as_triple(const nh_ctx *c, const nh_yaml_node *n, const char *key, int ints, double *out,
                     int *iout) {
  char d[96], item[NH_KEY_MAX];
  const char *what = ints ? "integers" : "numbers";
  if (n->kind != NH_YAML_SEQ)
    return fail(c, n, key, "expected a list of 3 %s, got %s", what, describe(n, d, sizeof d));
  if (n->n != 3)
    return fail(c, n, key, "expected a list of 3 %s, got %d entr%s", what, n->n,
                n->n == 1 ? "y" : "ies");
  for (int i = 0; i < 3; ++i) {
    join_index(item, key, i);
    if (ints)
      NH_TRY(as_int(c, n->items[i], item, &iout[i]));
    else
      NH_TRY(as_number(c, n->items[i], item, &out[i]));
  }
  return NH_OK;
}

static int as_vec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, double out[3]) {
  return as_triple(c, n, key, 0, out, NULL);
}

static int as_ivec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, int out[3]) {
  return as_triple(c, n, key, 1, NULL, out);
}

/* ---- keys of a mapping ---- */

/* The value of `name` in `map` (NULL if absent); a required key that is absent
 * is an error at the line of `map`. */
static int field(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                 int required, const nh_yaml_node **out) {
  char key[NH_KEY_MAX];
  *out = nh_yaml_get(map, name, NULL);
  if (!*out && required) return fail(c, map, join(key, path, name), "required key missing");
  return NH_OK;
}

/* A mapping section: NULL when absent or null; an error if it is something
 * else (or absent while required). */
static int section(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                   int required, const nh_yaml_node **out) {
  char key[NH_KEY_MAX], d[96];
  NH_TRY(field(c, map, path, name, required, out));
  if (!*out) return NH_OK;
  if ((*out)->kind == NH_YAML_MAP) return NH_OK;
  if (nh_yaml_is_null(*out) && !required) {
    *out = NULL;
    return NH_OK;
  }
  return fail(c, *out, join(key, path, name), "expected a mapping, got %s",
              describe(*out, d, sizeof d));
}

/* A list section: NULL when absent or null. */
static int list_section(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                        const char *name, const nh_yaml_node **out) {
  char key[NH_KEY_MAX], d[96];
  NH_TRY(field(c, map, path, name, 0, out));
  if (!*out || (*out)->kind == NH_YAML_SEQ) return NH_OK;
  if (nh_yaml_is_null(*out)) {
    *out = NULL;
    return NH_OK;
  }
  return fail(c, *out, join(key, path, name), "expected a list, got %s",
              describe(*out, d, sizeof d));
}

/* Typed optional/required fields: the target is left untouched when absent. */
static int get_number(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                      int required, double *out, const nh_yaml_node **at) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *n;
  NH_TRY(field(c, map, path, name, required, &n));
  if (at) *at = n;
  return n ? as_number(c, n, join(key, path, name), out) : NH_OK;
}

static int get_int(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                   int *out, const nh_yaml_node **at) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *n;
  NH_TRY(field(c, map, path, name, 0, &n));
  if (at) *at = n;
  return n ? as_int(c, n, join(key, path, name), out) : NH_OK;
}

static int get_vec3(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                    int required, double out[3], const nh_yaml_node **at) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *n;
  NH_TRY(field(c, map, path, name, required, &n));
  if (at) *at = n;
  return n ? as_vec3(c, n, join(key, path, name), out) : NH_OK;
}

/* Refuse a value below (or at, if strict) a bound. */
static int at_least(const nh_ctx *c, const nh_yaml_node *at, const char *path, const char *name,
                    double v, double bound, int strict) {
  char key[NH_KEY_MAX];
  if (!at) return NH_OK;
  if (strict && !(v > bound))
    return fail(c, at, join(key, path, name), "must be greater than %g, got %g", bound, v);
  if (!strict && !(v >= bound))
    return fail(c, at, join(key, path, name), "must be at least %g, got %g", bound, v);
  return NH_OK;
}

/* ---- sections ---- */

static const char *const axis_name[3] = {"x", "y", "z"};

/* {min: [3], max: [3]} with max > min (strict) or max >= min in every
 * component. */
static int read_box(const nh_ctx *c, const nh_yaml_node *box, const char *path, int strict,
                    double min[3], double max[3]) {
  static const char *const keys[] = {"min", "max", NULL};
  char key[NH_KEY_MAX], d[96];
  if (box->kind != NH_YAML_MAP)
    return fail(c, box, path, "expected a mapping {min: [x, y, z], max: [x, y, z]}, got %s",
                describe(box, d, sizeof d));
  NH_TRY(check_keys(c, box, path, keys));
  const nh_yaml_node *at_max;
  NH_TRY(get_vec3(c, box, path, "min", 1, min, NULL));
  NH_TRY(get_vec3(c, box, path, "max", 1, max, &at_max));
  for (int i = 0; i < 3; ++i)
    if (strict ? !(max[i] > min[i]) : !(max[i] >= min[i]))
      return fail(c, at_max, join(key, path, "max"),
                  "must be %s min in every component (%s: max %g, min %g)",
                  strict ? "greater than" : "at least", axis_name[i], max[i], min[i]);
  return NH_OK;
}

/* A positive radius `name` of the mapping `map` (required). */
static int read_radius(const nh_ctx *c, const nh_yaml_node *map, const char *path, double *radius) {
  const nh_yaml_node *at;
  NH_TRY(get_number(c, map, path, "radius", 1, radius, &at));
  return at_least(c, at, path, "radius", *radius, 0, 1);
}

/* The shape of a region: exactly one of the keys box {min, max},
 * sphere {center, radius}, cylinder {start, end, radius} in the mapping
 * `node` (whose keys the caller has checked). */
static int read_region_shape(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                             nh_region *region) {
  static const char *const shapes[] = {"box", "sphere", "cylinder", "label", NULL};
  static const char *const sphere_keys[] = {"center", "radius", NULL};
  static const char *const cylinder_keys[] = {"start", "end", "radius", NULL};
  char key[NH_KEY_MAX], d[96];
  const nh_yaml_node *shape = NULL, *shape_key = NULL;
  for (int i = 0; i < node->n; ++i) {
    if (!in_list(node->keys[i]->text, shapes)) continue;
    if (shape)
      return fail(c, node->keys[i], join(key, path, node->keys[i]->text),
                  "give exactly one of box, sphere, cylinder, label (%s is already given)",
                  shape_key->text);
    shape = node->items[i], shape_key = node->keys[i];
  }
  if (!shape) return fail(c, node, path, "give one of box, sphere, cylinder, label");
  join(key, path, shape_key->text);
  if (!strcmp(shape_key->text, "label")) { /* the voxels of the label image holding it; */
    region->kind = NH_REGION_LABEL;        /* that image is checked by the domain */
    return as_int(c, shape, key, &region->label);
  }
  if (!strcmp(shape_key->text, "box")) {
    region->kind = NH_REGION_BOX;
    return read_box(c, shape, key, 0, region->min, region->max);
  }
  int sphere = !strcmp(shape_key->text, "sphere");
  if (shape->kind != NH_YAML_MAP)
    return fail(c, shape, key, "expected a mapping %s, got %s",
                sphere ? "{center: [x, y, z], radius: r}"
                       : "{start: [x, y, z], end: [x, y, z], radius: r}",
                describe(shape, d, sizeof d));
  NH_TRY(check_keys(c, shape, key, sphere ? sphere_keys : cylinder_keys));
  if (sphere) {
    region->kind = NH_REGION_SPHERE;
    NH_TRY(get_vec3(c, shape, key, "center", 1, region->center, NULL));
    return read_radius(c, shape, key, &region->radius);
  }
  const nh_yaml_node *at_end;
  region->kind = NH_REGION_CYLINDER;
  NH_TRY(get_vec3(c, shape, key, "start", 1, region->start, NULL));
  NH_TRY(get_vec3(c, shape, key, "end", 1, region->end, &at_end));
  double len2 = 0;
  for (int i = 0; i < 3; ++i)
    len2 += (region->end[i] - region->start[i]) * (region->end[i] - region->start[i]);
  if (!(len2 > 0)) {
    char sub[NH_KEY_MAX];
    return fail(c, at_end, join(sub, key, "end"), "must differ from start (the cylinder's axis)");
  }
  return read_radius(c, shape, key, &region->radius);
}

/* A map at `node` with only `keys`, holding a region shape (read into
 * region); `expected` describes the item for the message. */
static int region_item(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                       const char *const *keys, const char *expected, nh_region *region) {
  char d[96];
  if (node->kind != NH_YAML_MAP)
    return fail(c, node, path, "expected %s, got %s", expected, describe(node, d, sizeof d));
  NH_TRY(check_keys(c, node, path, keys));
  return read_region_shape(c, node, path, region);
}

static int as_choice(const nh_ctx *c, const nh_yaml_node *n, const char *key,
                     const char *const *choices, int *out);
static int read_schedule(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                         nh_schedule *s);

/* A tissue.fixed item: a region {box | sphere | cylinder | label}, the components it
 * fixes (axes: [x, z]; default all) and their prescribed displacement
 * (displacement: [dx, dy, dz] times schedule; default 0). */
static int read_fixed(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                      nh_region *region, nh_fix *fix) {
  static const char *const keys[] = {"box",  "sphere",       "cylinder", "label",
                                     "axes", "displacement", "schedule", NULL};
  static const char *const axis_names[] = {"x", "y", "z", NULL};
  char key[NH_KEY_MAX], sub[NH_KEY_MAX], d[96];
  const nh_yaml_node *axes, *disp, *schedule;
  NH_TRY(region_item(c, node, path, keys,
                     "a region {box: {min, max}}, {sphere: {center, radius}}, "
                     "{cylinder: {start, end, radius}} or {label: N}",
                     region));
  make_where(c, node, path, region->where);
  fix->axes = 7;
  NH_TRY(field(c, node, path, "axes", 0, &axes));
  if (axes) {
    join(key, path, "axes");
    if (axes->kind != NH_YAML_SEQ || axes->n == 0)
      return fail(c, axes, key, "expected a non-empty list of axes among x, y, z, got %s",
                  describe(axes, d, sizeof d));
    fix->axes = 0;
    for (int i = 0; i < axes->n; ++i) {
      int a;
      NH_TRY(as_choice(c, axes->items[i], join_index(sub, key, i), axis_names, &a));
      if (fix->axes & (1 << a))
        return fail(c, axes->items[i], sub, "axis %s is given twice", axis_names[a]);
      fix->axes |= 1 << a;
    }
  }
  NH_TRY(field(c, node, path, "displacement", 0, &disp));
  if (disp) NH_TRY(as_vec3(c, disp, join(key, path, "displacement"), fix->displacement));
  NH_TRY(field(c, node, path, "schedule", 0, &schedule));
  if (schedule && !disp)
    return fail(c, schedule, join(key, path, "schedule"),
                "a schedule scales a prescribed displacement: give displacement too");
  if (schedule) NH_TRY(read_schedule(c, schedule, join(key, path, "schedule"), &fix->schedule));
  return NH_OK;
}

/* [[t0, s0], [t1, s1], ...] with strictly increasing times. */
static int read_schedule(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                         nh_schedule *s) {
  char d[96], item[NH_KEY_MAX], sub[NH_KEY_MAX];
  if (nh_yaml_is_null(node)) return NH_OK;
  if (node->kind != NH_YAML_SEQ)
    return fail(c, node, path, "expected a list of [time, factor] pairs, got %s",
                describe(node, d, sizeof d));
  if (node->n == 0) return NH_OK;
  s->t = nh_calloc((size_t)node->n, sizeof *s->t);
  s->value = nh_calloc((size_t)node->n, sizeof *s->value);
  if (!s->t || !s->value) return NH_ERR_MEMORY;
  for (int i = 0; i < node->n; ++i) {
    const nh_yaml_node *p = node->items[i];
    join_index(item, path, i);
    if (p->kind != NH_YAML_SEQ || p->n != 2)
      return fail(c, p, item, "expected a pair [time, factor], got %s",
                  p->kind == NH_YAML_SEQ ? (p->n == 1 ? "1 entry" : "a list of another length")
                                         : describe(p, d, sizeof d));
    NH_TRY(as_number(c, p->items[0], join_index(sub, item, 0), &s->t[i]));
    NH_TRY(as_number(c, p->items[1], join_index(sub, item, 1), &s->value[i]));
    if (i > 0 && !(s->t[i] > s->t[i - 1]))
      return fail(c, p->items[0], join_index(sub, item, 0),
                  "times must increase strictly (%g after %g)", s->t[i], s->t[i - 1]);
    s->n = i + 1;
  }
  return NH_OK;
}

/* {box | sphere | cylinder, force: [3], schedule: [[t, s], ...]} */
static int read_load(const nh_ctx *c, const nh_yaml_node *node, const char *path, nh_load *load) {
  static const char *const keys[] = {"box",   "sphere",   "cylinder", "label",
                                     "force", "schedule", NULL};
  char key[NH_KEY_MAX];
  NH_TRY(region_item(c, node, path, keys, "a load {box: {min, max}, force: [fx, fy, fz]}",
                     &load->region));
  const nh_yaml_node *schedule;
  NH_TRY(get_vec3(c, node, path, "force", 1, load->force, NULL));
  NH_TRY(field(c, node, path, "schedule", 0, &schedule));
  if (schedule) NH_TRY(read_schedule(c, schedule, join(key, path, "schedule"), &load->schedule));
  make_where(c, node, path, load->where);
  make_where(c, node, path, load->region.where);
  return NH_OK;
}

/* {box | sphere | cylinder, traction: [3] | pressure: p, schedule: [[t, s], ...]} */
static int read_traction(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                         nh_traction *tr) {
  static const char *const keys[] = {"box",      "sphere",   "cylinder", "traction",
                                     "pressure", "schedule", NULL};
  char key[NH_KEY_MAX];
  NH_TRY(region_item(c, node, path, keys,
                     "a traction {box: {min, max}, traction: [tx, ty, tz]} or {box: ..., "
                     "pressure: p}",
                     &tr->region));
  const nh_yaml_node *schedule, *tv, *pv;
  NH_TRY(field(c, node, path, "traction", 0, &tv));
  NH_TRY(field(c, node, path, "pressure", 0, &pv));
  if (!tv && !pv) return fail(c, node, path, "give traction: [tx, ty, tz] (N/m²) or pressure: p");
  if (tv && pv)
    return fail(c, pv, join(key, path, "pressure"),
                "give either traction or pressure, not both (traction is already given)");
  if (tv) NH_TRY(as_vec3(c, tv, join(key, path, "traction"), tr->traction));
  if (pv) NH_TRY(as_number(c, pv, join(key, path, "pressure"), &tr->pressure));
  tr->is_pressure = pv != NULL;
  NH_TRY(field(c, node, path, "schedule", 0, &schedule));
  if (schedule) NH_TRY(read_schedule(c, schedule, join(key, path, "schedule"), &tr->schedule));
  make_where(c, node, path, tr->where);
  make_where(c, node, path, tr->region.where);
  return NH_OK;
}

/* gravity: [gx, gy, gz], or {vector: [gx, gy, gz], schedule: [[t, s], ...]}. */
static int read_gravity(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"vector", "schedule", NULL};
  const nh_yaml_node *n, *schedule;
  NH_TRY(field(c, root, "", "gravity", 0, &n));
  if (!n) return NH_OK;
  if (n->kind != NH_YAML_MAP) return as_vec3(c, n, "gravity", s->gravity);
  NH_TRY(check_keys(c, n, "gravity", keys));
  NH_TRY(get_vec3(c, n, "gravity", "vector", 1, s->gravity, NULL));
  NH_TRY(field(c, n, "gravity", "schedule", 0, &schedule));
  if (schedule) NH_TRY(read_schedule(c, schedule, "gravity.schedule", &s->gravity_schedule));
  return NH_OK;
}

/* A fraction in [0, 1] (required). */
static int get_fraction(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                        const char *name, double *out) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *at;
  NH_TRY(get_number(c, map, path, name, 1, out, &at));
  if (!(*out >= 0 && *out <= 1))
    return fail(c, at, join(key, path, name), "a fraction must lie in [0, 1], got %g", *out);
  return NH_OK;
}

/* tissue.buoyancy: {before: b0, after: b1, schedule: [[t, s], ...], level:
 * [x, y, z]}. Without a schedule the change is a step at t = 0: s = 1 from
 * the first step on. `level` needs gravity (read before) to say what is
 * above it. */
static int read_buoyancy(const nh_ctx *c, const nh_yaml_node *tissue, nh_scene *s) {
  static const char *const keys[] = {"before", "after", "schedule", "level", NULL};
  const char *path = "tissue.buoyancy";
  const nh_yaml_node *m, *schedule;
  NH_TRY(section(c, tissue, "tissue", "buoyancy", 0, &m));
  if (!m) return NH_OK;
  NH_TRY(check_keys(c, m, path, keys));
  s->tissue.buoyant = 1;
  NH_TRY(get_fraction(c, m, path, "before", &s->tissue.buoyancy_before));
  NH_TRY(get_fraction(c, m, path, "after", &s->tissue.buoyancy_after));
  NH_TRY(field(c, m, path, "schedule", 0, &schedule));
  if (schedule)
    NH_TRY(read_schedule(c, schedule, "tissue.buoyancy.schedule", &s->tissue.buoyancy_schedule));
  const nh_yaml_node *at_level;
  NH_TRY(get_vec3(c, m, path, "level", 0, s->tissue.buoyancy_level, &at_level));
  s->tissue.buoyancy_has_level = at_level != NULL;
  double g2 =
      s->gravity[0] * s->gravity[0] + s->gravity[1] * s->gravity[1] + s->gravity[2] * s->gravity[2];
  if (at_level && !(g2 > 0))
    return fail(c, at_level, "tissue.buoyancy.level",
                "a fluid level needs gravity (its direction says what lies above the level); "
                "gravity is zero");
  return NH_OK;
}

/* tissue.skull: {gap: g >= 0 (default 0)}, an immersed domain only. */
static int read_skull(const nh_ctx *c, const nh_yaml_node *tissue, nh_scene *s) {
  static const char *const keys[] = {"gap", NULL};
  const nh_yaml_node *m, *at, *key;
  NH_TRY(section(c, tissue, "tissue", "skull", 0, &m));
  nh_yaml_get(tissue, "skull", &key);
  if (!key) return NH_OK;
  if (m) NH_TRY(check_keys(c, m, "tissue.skull", keys));
  make_where(c, key, "tissue.skull", s->tissue.where_skull);
  s->tissue.skull = 1;
  s->tissue.skull_gap = 0.0;
  if (m) {
    NH_TRY(get_number(c, m, "tissue.skull", "gap", 0, &s->tissue.skull_gap, &at));
    NH_TRY(at_least(c, at, "tissue.skull", "gap", s->tissue.skull_gap, 0, 0));
  }
  if (s->tissue.domain == NH_DOMAIN_BOX)
    return fail(c, key, "tissue.skull",
                "needs an immersed domain (brain): the skull is the domain's surface offset by "
                "the gap");
  return NH_OK;
}

static int read_time(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"mode", "step", "end", "steps", NULL};
  const nh_yaml_node *t, *at_step, *at_end, *at_steps, *at_mode;
  char d[96];
  s->time.mode = NH_MODE_DYNAMIC;
  s->time.step = 0.01;
  s->time.steps = 100;
  NH_TRY(section(c, root, "", "time", 0, &t));
  if (!t) return NH_OK;
  NH_TRY(check_keys(c, t, "time", keys));
  NH_TRY(field(c, t, "time", "mode", 0, &at_mode));
  if (at_mode) {
    const char *m = at_mode->kind == NH_YAML_SCALAR ? at_mode->text : "";
    if (!strcmp(m, "dynamic"))
      s->time.mode = NH_MODE_DYNAMIC;
    else if (!strcmp(m, "static"))
      s->time.mode = NH_MODE_STATIC;
    else
      return fail(c, at_mode, "time.mode", "expected dynamic or static, got %s",
                  describe(at_mode, d, sizeof d));
  }
  NH_TRY(get_number(c, t, "time", "step", 0, &s->time.step, &at_step));
  NH_TRY(at_least(c, at_step, "time", "step", s->time.step, 0, 1));
  double end = 0;
  NH_TRY(get_number(c, t, "time", "end", 0, &end, &at_end));
  NH_TRY(at_least(c, at_end, "time", "end", end, 0, 1));
  NH_TRY(get_int(c, t, "time", "steps", &s->time.steps, &at_steps));
  NH_TRY(at_least(c, at_steps, "time", "steps", s->time.steps, 1, 0));
  if (at_end && at_steps) {
    /* Report at whichever of the two comes second. */
    int steps_later = at_steps->source > at_end->source ||
                      (at_steps->source == at_end->source && at_steps->line >= at_end->line);
    return steps_later
               ? fail(c, at_steps, "time.steps", "give either time.end or time.steps, not both")
               : fail(c, at_end, "time.end", "give either time.end or time.steps, not both");
  }
  if (at_end) {
    double steps = floor(end / s->time.step + 0.5);
    if (steps > NH_STEPS_MAX)
      return fail(c, at_end, "time.end", "end / step = %g steps is more than %g", steps,
                  NH_STEPS_MAX);
    s->time.steps = steps < 1 ? 1 : (int)steps;
  }
  return NH_OK;
}

/* One of the words `choices` (NULL-terminated); *out = its index. */
static int as_choice(const nh_ctx *c, const nh_yaml_node *n, const char *key,
                     const char *const *choices, int *out) {
  char d[96], expected[256] = "";
  if (n->kind == NH_YAML_SCALAR && !nh_yaml_is_null(n))
    for (int i = 0; choices[i]; ++i)
      if (!strcmp(n->text, choices[i])) return *out = i, NH_OK;
  for (int i = 0; choices[i]; ++i) {
    size_t len = strlen(expected);
    snprintf(expected + len, sizeof expected - len, "%s%s",
             i == 0 ? "" : (choices[i + 1] ? ", " : " or "), choices[i]);
  }
  return fail(c, n, key, "expected %s, got %s", expected, describe(n, d, sizeof d));
}

/* A material mapping {young, poisson, density} at `m` (key `path`), and
 * `formulation` (bbar | full) where that pointer is not NULL: young > 0
 * is required; poisson must lie in (-1, 0.5) and is required if
 * `poisson_required`; density is > 0 (`density_strict`) or >= 0. An absent
 * optional key leaves its target (the caller's default) untouched. */
static int read_material_map(const nh_ctx *c, const nh_yaml_node *m, const char *path,
                             int poisson_required, int density_strict, double *young,
                             double *poisson, double *density, int *formulation) {
  static const char *const keys[] = {"young", "poisson", "density", NULL};
  static const char *const tissue_keys[] = {"young", "poisson", "density", "formulation", NULL};
  static const char *const formulations[] = {"bbar", "full", NULL};
  char key[NH_KEY_MAX];
  const nh_yaml_node *at;
  NH_TRY(check_keys(c, m, path, formulation ? tissue_keys : keys));
  if (formulation) {
    NH_TRY(field(c, m, path, "formulation", 0, &at));
    if (at) NH_TRY(as_choice(c, at, join(key, path, "formulation"), formulations, formulation));
  }
  NH_TRY(get_number(c, m, path, "young", 1, young, &at));
  NH_TRY(at_least(c, at, path, "young", *young, 0, 1));
  NH_TRY(get_number(c, m, path, "poisson", poisson_required, poisson, &at));
  if (at && *poisson >= 0.5)
    return fail(c, at, join(key, path, "poisson"),
                "%g is not below 0.5: incompressible (or beyond) materials are not supported; "
                "use a value below 0.5, e.g. 0.49",
                *poisson);
  if (at && *poisson <= -1)
    return fail(c, at, join(key, path, "poisson"), "must be greater than -1, got %g", *poisson);
  NH_TRY(get_number(c, m, path, "density", 0, density, &at));
  NH_TRY(at_least(c, at, path, "density", *density, 0, density_strict));
  return NH_OK;
}

/* PARENT.material (required): read_material_map. */
static int read_material(const nh_ctx *c, const nh_yaml_node *parent, const char *parent_path,
                         int poisson_required, int density_strict, double *young, double *poisson,
                         double *density, int *formulation) {
  char path[NH_KEY_MAX];
  const nh_yaml_node *m;
  join(path, parent_path, "material");
  NH_TRY(section(c, parent, parent_path, "material", 1, &m));
  return read_material_map(c, m, path, poisson_required, density_strict, young, poisson, density,
                           formulation);
}

/* PARENT.damping {mass, stiffness} (optional): Rayleigh alpha, beta >= 0. */
static int read_damping(const nh_ctx *c, const nh_yaml_node *parent, const char *parent_path,
                        double *mass, double *stiffness) {
  static const char *const keys[] = {"mass", "stiffness", NULL};
  char path[NH_KEY_MAX];
  const nh_yaml_node *m, *at;
  join(path, parent_path, "damping");
  NH_TRY(section(c, parent, parent_path, "damping", 0, &m));
  if (!m) return NH_OK;
  NH_TRY(check_keys(c, m, path, keys));
  NH_TRY(get_number(c, m, path, "mass", 0, mass, &at));
  NH_TRY(at_least(c, at, path, "mass", *mass, 0, 0));
  NH_TRY(get_number(c, m, path, "stiffness", 0, stiffness, &at));
  NH_TRY(at_least(c, at, path, "stiffness", *stiffness, 0, 0));
  return NH_OK;
}

/* ---- anatomy: label images, surfaces, materials per label, voxel points ----
 * (docs/anatomy.md). Files are named relative to the scene file's folder
 * unless absolute. Their headers are read here, so that a missing, unreadable
 * or corrupt file fails `check` at its key; the voxels and triangles are
 * read again, in full, when the domain is built (mesh/domain.c), which also
 * checks that every label named exists in the image. */

/* A path relative to the scene file's folder unless absolute; snprintf's count. */
static int scene_relative(const nh_ctx *c, const char *value, char out[NH_PATH_MAX]) {
  const char *slash = strrchr(c->file, '/');
  if (value[0] == '/' || !slash) return snprintf(out, NH_PATH_MAX, "%s", value);
  return snprintf(out, NH_PATH_MAX, "%.*s/%s", (int)(slash - c->file), c->file, value);
}

/* MAP.file (required): a readable file, resolved into out. */
static int read_data_file(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                          char out[NH_PATH_MAX], const nh_yaml_node **at_out) {
  char key[NH_KEY_MAX], value[NH_PATH_MAX];
  const nh_yaml_node *at;
  NH_TRY(field(c, map, path, "file", 1, &at));
  join(key, path, "file");
  NH_TRY(as_string(c, at, key, value, sizeof value));
  int n = scene_relative(c, value, out);
  if (n < 0 || n >= NH_PATH_MAX)
    return fail(c, at, key, "the path is longer than %d characters", NH_PATH_MAX - 1);
  struct stat st;
  int err = access(out, R_OK) != 0 ? errno : 0;
  if (!err && stat(out, &st) == 0 && S_ISDIR(st.st_mode)) err = EISDIR;
  if (err) return fail(c, at, key, "cannot read %s: %s", out, strerror(err));
  if (at_out) *at_out = at;
  return NH_OK;
}

/* The header of the NIfTI file `path` named at `at` (key `key`). */
static int read_image_header(const nh_ctx *c, const nh_yaml_node *at, const char *key,
                             const char *path, nh_image **out) {
  if (nh_image_read(path, 0, NULL, out) == NH_OK) return NH_OK;
  char msg[1024];
  snprintf(msg, sizeof msg, "%s", nh_error_message());
  return fail(c, at, key, "%s", msg);
}

/* The mapping `node` at `path` with keys among `keys`; else an error that
 * shows the expected form `example`. */
static int expect_mapping(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                          const char *example, const char *const *keys) {
  char d[96];
  if (node->kind != NH_YAML_MAP)
    return fail(c, node, path, "expected a mapping %s, got %s", example,
                describe(node, d, sizeof d));
  return check_keys(c, node, path, keys);
}

/* tissue.domain.mask {file, labels: [N, ...]}. */
static int read_mask(const nh_ctx *c, const nh_yaml_node *mask, nh_scene *s) {
  static const char *const keys[] = {"file", "labels", NULL};
  const char *path = "tissue.domain.mask";
  char key[NH_KEY_MAX], d[96];
  const nh_yaml_node *at_file, *labels;
  NH_TRY(expect_mapping(c, mask, path, "{file: FILE.nii.gz, labels: [1, 2]}", keys));
  s->tissue.domain = NH_DOMAIN_MASK;
  NH_TRY(read_data_file(c, mask, path, s->tissue.mask_file, &at_file));
  nh_image *im;
  NH_TRY(read_image_header(c, at_file, join(key, path, "file"), s->tissue.mask_file, &im));
  nh_image_extent(im, s->tissue.box_min, s->tissue.box_max);
  nh_image_release(&im);
  make_where(c, at_file, join(key, path, "file"), s->tissue.where_domain);
  NH_TRY(field(c, mask, path, "labels", 1, &labels));
  join(key, path, "labels");
  if (labels->kind != NH_YAML_SEQ || labels->n == 0)
    return fail(c, labels, key, "expected a non-empty list of labels [1, 2, ...], got %s",
                describe(labels, d, sizeof d));
  s->tissue.mask_labels = nh_calloc((size_t)labels->n, sizeof(int));
  if (!s->tissue.mask_labels) return NH_ERR_MEMORY;
  for (int i = 0; i < labels->n; ++i) {
    char item[NH_KEY_MAX];
    NH_TRY(as_int(c, labels->items[i], join_index(item, key, i), &s->tissue.mask_labels[i]));
    for (int j = 0; j < i; ++j)
      if (s->tissue.mask_labels[j] == s->tissue.mask_labels[i])
        return fail(c, labels->items[i], item, "label %d is listed twice",
                    s->tissue.mask_labels[i]);
    s->tissue.n_mask_labels = i + 1;
  }
  make_where(c, labels, key, s->tissue.where_labels);
  return NH_OK;
}

/* tissue.domain.surface {file, unit (default 0.001: millimetres)}. The whole
 * surface is read here: a bad STL fails at its own line, reported at the key. */
static int read_surface(const nh_ctx *c, const nh_yaml_node *node, nh_scene *s) {
  static const char *const keys[] = {"file", "unit", NULL};
  const char *path = "tissue.domain.surface";
  char key[NH_KEY_MAX];
  const nh_yaml_node *at_file, *at_unit;
  NH_TRY(expect_mapping(c, node, path, "{file: FILE.stl, unit: 0.001}", keys));
  s->tissue.domain = NH_DOMAIN_SURFACE;
  s->tissue.surface_unit = 1e-3;
  NH_TRY(read_data_file(c, node, path, s->tissue.surface_file, &at_file));
  NH_TRY(get_number(c, node, path, "unit", 0, &s->tissue.surface_unit, &at_unit));
  NH_TRY(at_least(c, at_unit, path, "unit", s->tissue.surface_unit, 0, 1));
  join(key, path, "file");
  make_where(c, at_file, key, s->tissue.where_domain);
  nh_surface *surface;
  if (nh_surface_read(s->tissue.surface_file, s->tissue.surface_unit, 0, NULL, &surface)) {
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", nh_error_message());
    return fail(c, at_file, key, "%s", msg);
  }
  for (int k = 0; k < 3; k++)
    s->tissue.box_min[k] = surface->min[k], s->tissue.box_max[k] = surface->max[k];
  nh_surface_release(&surface);
  return NH_OK;
}

/* tissue.labels {file} (optional; not with a mask domain, whose image it is). */
static int read_labels_image(const nh_ctx *c, const nh_yaml_node *t, nh_scene *s) {
  static const char *const keys[] = {"file", NULL};
  const nh_yaml_node *node, *at_file;
  char key[NH_KEY_MAX];
  NH_TRY(section(c, t, "tissue", "labels", 0, &node));
  if (!node) return NH_OK;
  if (s->tissue.domain == NH_DOMAIN_MASK)
    return fail(c, node, "tissue.labels",
                "a mask domain's image is the label image (give tissue.labels only with a box, "
                "brain or surface domain)");
  NH_TRY(check_keys(c, node, "tissue.labels", keys));
  NH_TRY(read_data_file(c, node, "tissue.labels", s->tissue.labels_file, &at_file));
  nh_image *im;
  join(key, "tissue.labels", "file");
  NH_TRY(read_image_header(c, at_file, key, s->tissue.labels_file, &im));
  nh_image_release(&im);
  make_where(c, at_file, key, s->tissue.where_labels);
  return NH_OK;
}

/* tissue.materials {LABEL: {young, poisson, density}} (optional): poisson and
 * density default to tissue.material's. */
static int read_materials(const nh_ctx *c, const nh_yaml_node *t, nh_scene *s) {
  const nh_yaml_node *m;
  char key[NH_KEY_MAX], d[96];
  NH_TRY(section(c, t, "tissue", "materials", 0, &m));
  if (!m || m->n == 0) return NH_OK;
  if (!s->tissue.mask_file[0] && !s->tissue.labels_file[0])
    return fail(c, m, "tissue.materials",
                "materials per label need a label image: give tissue.domain.mask or "
                "tissue.labels");
  s->tissue.materials = nh_calloc((size_t)m->n, sizeof *s->tissue.materials);
  if (!s->tissue.materials) return NH_ERR_MEMORY;
  for (int i = 0; i < m->n; ++i) {
    nh_label_material *lm = &s->tissue.materials[i];
    join(key, "tissue.materials", m->keys[i]->text);
    char *end;
    double v = strtod(m->keys[i]->text, &end);
    if (end == m->keys[i]->text || *end || v != floor(v) || fabs(v) > INT_MAX)
      return fail(c, m->keys[i], key, "a material's key is an integer label, got %s",
                  describe(m->keys[i], d, sizeof d));
    lm->label = (int)v;
    for (int j = 0; j < i; ++j)
      if (s->tissue.materials[j].label == lm->label)
        return fail(c, m->keys[i], key, "label %d has a material already", lm->label);
    if (m->items[i]->kind != NH_YAML_MAP)
      return fail(c, m->items[i], key, "expected a mapping {young, poisson, density}, got %s",
                  describe(m->items[i], d, sizeof d));
    lm->poisson = s->tissue.poisson, lm->density = s->tissue.density;
    NH_TRY(
        read_material_map(c, m->items[i], key, 0, 1, &lm->young, &lm->poisson, &lm->density, NULL));
    make_where(c, m->keys[i], key, lm->where);
    s->tissue.n_materials = i + 1;
  }
  return NH_OK;
}

/* MAP.NAME, a point: [x, y, z] in metres, or {voxel: [i, j, k], image: FILE}
 * (image: default the scene's label image), the world position of that
 * voxel's centre. */
static int get_point(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                     int required, double out[3], const nh_yaml_node **at_out) {
  static const char *const keys[] = {"voxel", "image", NULL};
  char key[NH_KEY_MAX], sub[NH_KEY_MAX], file[NH_PATH_MAX], value[NH_PATH_MAX];
  const nh_yaml_node *n, *at_voxel, *at_image;
  NH_TRY(field(c, map, path, name, required, &n));
  if (at_out) *at_out = n;
  if (!n) return NH_OK;
  join(key, path, name);
  if (n->kind != NH_YAML_MAP) return as_vec3(c, n, key, out);
  NH_TRY(check_keys(c, n, key, keys));
  NH_TRY(field(c, n, key, "voxel", 1, &at_voxel));
  int ijk[3];
  NH_TRY(as_ivec3(c, at_voxel, join(sub, key, "voxel"), ijk));
  NH_TRY(field(c, n, key, "image", 0, &at_image));
  const nh_yaml_node *at = at_image ? at_image : at_voxel;
  if (at_image) {
    NH_TRY(as_string(c, at_image, join(sub, key, "image"), value, sizeof value));
    int len = scene_relative(c, value, file);
    if (len < 0 || len >= NH_PATH_MAX)
      return fail(c, at_image, sub, "the path is longer than %d characters", NH_PATH_MAX - 1);
  } else if (c->image) {
    snprintf(file, sizeof file, "%s", c->image);
  } else {
    return fail(c, at_voxel, sub,
                "a voxel needs an image: give %s.image, or tissue.domain.mask or tissue.labels",
                key);
  }
  nh_image *im;
  NH_TRY(read_image_header(c, at, at_image ? sub : key, file, &im));
  for (int k = 0; k < 3; ++k)
    if (ijk[k] < 0 || ijk[k] >= im->n[k]) {
      int nk = im->n[k];
      nh_image_release(&im);
      return fail(c, at_voxel, join(sub, key, "voxel"),
                  "index %d along %c is outside the image %s (0 .. %d)", ijk[k], "ijk"[k], file,
                  nk - 1);
    }
  double p[3] = {ijk[0], ijk[1], ijk[2]};
  nh_image_to_world(im, p, out);
  nh_image_release(&im);
  return NH_OK;
}

/* A probe or target of a mask domain must lie inside the mask's image. */
static int check_in_image(const nh_ctx *c, const nh_yaml_node *at, const char *key,
                          const nh_scene *s, const double x[3]) {
  if (s->tissue.domain != NH_DOMAIN_MASK) return NH_OK;
  nh_image *im;
  NH_TRY(read_image_header(c, at, key, s->tissue.mask_file, &im));
  int inside = nh_image_contains(im, x);
  double lo[3], hi[3];
  nh_image_extent(im, lo, hi);
  nh_image_release(&im);
  if (inside) return NH_OK;
  return fail(c, at, key,
              "[%g, %g, %g] m lies outside the image %s (world extent [%g, %g, %g] - [%g, %g, "
              "%g] m)",
              x[0], x[1], x[2], s->tissue.mask_file, lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]);
}

/* tissue.domain.brain {size: [3] > 0 (required), center: [3] (default 0)}. */
static int read_brain(const nh_ctx *c, const nh_yaml_node *brain, nh_scene *s) {
  static const char *const keys[] = {"size", "center", NULL};
  const char *path = "tissue.domain.brain";
  char key[NH_KEY_MAX], d[96];
  const nh_yaml_node *at_size;
  if (brain->kind != NH_YAML_MAP)
    return fail(c, brain, path,
                "expected a mapping {size: [sx, sy, sz], center: [x, y, z]}, got %s",
                describe(brain, d, sizeof d));
  NH_TRY(check_keys(c, brain, path, keys));
  s->tissue.domain = NH_DOMAIN_BRAIN;
  NH_TRY(get_vec3(c, brain, path, "size", 1, s->tissue.brain_size, &at_size));
  for (int i = 0; i < 3; ++i)
    if (!(s->tissue.brain_size[i] > 0))
      return fail(c, at_size->items[i], join_index(key, "tissue.domain.brain.size", i),
                  "must be greater than 0, got %g", s->tissue.brain_size[i]);
  NH_TRY(get_vec3(c, brain, path, "center", 0, s->tissue.brain_center, NULL));
  for (int i = 0; i < 3; ++i) {
    s->tissue.box_min[i] = s->tissue.brain_center[i] - 0.5 * s->tissue.brain_size[i];
    s->tissue.box_max[i] = s->tissue.brain_center[i] + 0.5 * s->tissue.brain_size[i];
  }
  return NH_OK;
}

double nh_scene_memory_estimate(double cells) {
  return cells * (13.5e3 + 708.0 * cbrt(cells));
}

/* "12.3 GB" */
static const char *bytes_text(double b, char *buf, size_t cap) {
  static const char *const unit[] = {"B", "kB", "MB", "GB", "TB", "PB"};
  int u = 0;
  while (b >= 1000.0 && u < 5) b /= 1000.0, ++u;
  snprintf(buf, cap, "%.3g %s", b, unit[u]);
  return buf;
}

/* The lattice's size against limits.max_cells and its estimated memory
 * against the machine's physical memory, before anything is allocated
 * (`at`: tissue.grid, or tissue without it). */
static int check_size(const nh_ctx *c, const nh_yaml_node *at, const nh_scene *s) {
  const int *g = s->tissue.grid;
  double cells = (double)g[0] * g[1] * g[2];
  double nodes = (g[0] + 1.0) * (g[1] + 1.0) * (g[2] + 1.0);
  char need[32], have[32];
  bytes_text(nh_scene_memory_estimate(cells), need, sizeof need);
  if (cells > s->limits.max_cells || 3 * nodes > INT_MAX)
    return fail(c, at, "tissue.grid",
                "%d x %d x %d = %.0f cells (%.0f nodes) exceed limits.max_cells = %d "
                "(a run would need about %s of memory); coarsen the grid and let `adapt` "
                "refine, or raise limits.max_cells",
                g[0], g[1], g[2], cells, nodes, s->limits.max_cells, need);
  double ram = (double)sysconf(_SC_PHYS_PAGES) * (double)sysconf(_SC_PAGESIZE);
  if (ram > 0 && nh_scene_memory_estimate(cells) > ram)
    return fail(c, at, "tissue.grid",
                "%d x %d x %d = %.0f cells: a run would need about %s of memory, more than "
                "this machine's %s; coarsen the grid and let `adapt` refine",
                g[0], g[1], g[2], cells, need, bytes_text(ram, have, sizeof have));
  return NH_OK;
}

/* The cells of a box lattice must be invertible in double precision: their
 * Jacobian inverse is refused (nh_mat3_inverse) when the product of the two
 * smaller edge ratios falls below 1e-14. An aspect ratio above 1e6 is
 * refused here, naming the box, before any mesh is built. */
static int check_box_cells(const nh_ctx *c, const nh_yaml_node *box, const nh_scene *s) {
  double h[3], lo = INFINITY, hi = 0.0;
  for (int i = 0; i < 3; ++i) {
    h[i] = (s->tissue.box_max[i] - s->tissue.box_min[i]) / s->tissue.grid[i];
    lo = fmin(lo, h[i]);
    hi = fmax(hi, h[i]);
  }
  if (!(hi / lo <= 1e6) || !isfinite(hi))
    return fail(c, box, "tissue.domain.box",
                "its %d x %d x %d grid cells measure %g x %g x %g m, an aspect ratio of %.3g "
                "(at most 1e6): such a cell's Jacobian cannot be inverted in double "
                "precision; give a box and a grid whose cells are closer to cubes",
                s->tissue.grid[0], s->tissue.grid[1], s->tissue.grid[2], h[0], h[1], h[2], hi / lo);
  return NH_OK;
}

static int read_limits(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"max_cells", NULL};
  const nh_yaml_node *m, *at;
  s->limits.max_cells = 2000000;
  NH_TRY(section(c, root, "", "limits", 0, &m));
  if (!m) return NH_OK;
  NH_TRY(check_keys(c, m, "limits", keys));
  NH_TRY(get_int(c, m, "limits", "max_cells", &s->limits.max_cells, &at));
  return at_least(c, at, "limits", "max_cells", s->limits.max_cells, 1, 0);
}

/* tissue.NAME: a list of items of `size` bytes read by `read` into a new
 * array *items; *n counts each item before it is read, so that destroy frees
 * a half-read one's schedule. */
typedef int (*nh_item_reader)(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                              void *item);
static int read_load_item(const nh_ctx *c, const nh_yaml_node *node, const char *path, void *item) {
  return read_load(c, node, path, item);
}
static int read_traction_item(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                              void *item) {
  return read_traction(c, node, path, item);
}
static int read_items(const nh_ctx *c, const nh_yaml_node *t, const char *name, size_t size,
                      void **items, int *n, nh_item_reader read) {
  char key[NH_KEY_MAX], path[NH_KEY_MAX];
  const nh_yaml_node *list;
  NH_TRY(list_section(c, t, "tissue", name, &list));
  if (!list || list->n == 0) return NH_OK;
  *items = nh_calloc((size_t)list->n, size);
  if (!*items) return NH_ERR_MEMORY;
  join(path, "tissue", name);
  for (int i = 0; i < list->n; ++i) {
    *n = i + 1;
    NH_TRY(read(c, list->items[i], join_index(key, path, i), (char *)*items + (size_t)i * size));
  }
  return NH_OK;
}

static int read_tissue(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"domain", "grid",      "material",  "damping",
                                     "fixed",  "loads",     "tractions", "buoyancy",
                                     "labels", "materials", "skull",     NULL};
  static const char *const domain_keys[] = {"box", "brain", "mask", "surface", NULL};
  char key[NH_KEY_MAX];
  const nh_yaml_node *t, *domain, *n;
  NH_TRY(section(c, root, "", "tissue", 1, &t));
  NH_TRY(check_keys(c, t, "tissue", keys));

  /* domain: exactly one of box, brain, mask, surface. */
  NH_TRY(section(c, t, "tissue", "domain", 1, &domain));
  NH_TRY(check_keys(c, domain, "tissue.domain", domain_keys));
  if (domain->n == 0)
    return fail(c, domain, "tissue.domain", "give one of box, brain, mask, surface");
  if (domain->n > 1)
    return fail(c, domain->keys[1], join(key, "tissue.domain", domain->keys[1]->text),
                "give exactly one of box, brain, mask, surface (%s is already given)",
                domain->keys[0]->text);
  if (!strcmp(domain->keys[0]->text, "brain")) {
    NH_TRY(read_brain(c, domain->items[0], s));
  } else if (!strcmp(domain->keys[0]->text, "box")) {
    s->tissue.domain = NH_DOMAIN_BOX;
    NH_TRY(read_box(c, domain->items[0], "tissue.domain.box", 1, s->tissue.box_min,
                    s->tissue.box_max));
  } else if (!strcmp(domain->keys[0]->text, "mask")) {
    NH_TRY(read_mask(c, domain->items[0], s));
  } else {
    NH_TRY(read_surface(c, domain->items[0], s));
  }
  NH_TRY(read_labels_image(c, t, s));

  /* grid */
  s->tissue.grid[0] = 8, s->tissue.grid[1] = 4, s->tissue.grid[2] = 4;
  NH_TRY(field(c, t, "tissue", "grid", 0, &n));
  if (n) {
    NH_TRY(as_ivec3(c, n, "tissue.grid", s->tissue.grid));
    for (int i = 0; i < 3; ++i)
      if (s->tissue.grid[i] < 1)
        return fail(c, n->items[i], join_index(key, "tissue.grid", i),
                    "a cell count must be at least 1, got %d", s->tissue.grid[i]);
  }
  NH_TRY(check_size(c, n ? n : t, s));
  if (s->tissue.domain == NH_DOMAIN_BOX) NH_TRY(check_box_cells(c, domain->items[0], s));

  s->tissue.density = 1000;
  int formulation = 0; /* bbar: docs/theory.md §2b */
  NH_TRY(read_material(c, t, "tissue", 1, 1, &s->tissue.young, &s->tissue.poisson,
                       &s->tissue.density, &formulation));
  s->tissue.formulation = formulation ? NH_FORMULATION_FULL : NH_FORMULATION_BBAR;
  NH_TRY(read_materials(c, t, s));
  NH_TRY(read_damping(c, t, "tissue", &s->tissue.damping_mass, &s->tissue.damping_stiffness));
  NH_TRY(read_buoyancy(c, t, s));
  NH_TRY(read_skull(c, t, s));

  /* fixed: where_fixed points at the key `fixed:`, or at `tissue:` without it. */
  const nh_yaml_node *fixed, *fixed_key, *tissue_key;
  NH_TRY(list_section(c, t, "tissue", "fixed", &fixed));
  nh_yaml_get(t, "fixed", &fixed_key);
  nh_yaml_get(root, "tissue", &tissue_key);
  make_where(c, fixed_key ? fixed_key : tissue_key, "tissue.fixed", s->tissue.where_fixed);
  if (fixed && fixed->n > 0) {
    s->tissue.fixed = nh_calloc((size_t)fixed->n, sizeof *s->tissue.fixed);
    s->tissue.fix = nh_calloc((size_t)fixed->n, sizeof *s->tissue.fix);
    if (!s->tissue.fixed || !s->tissue.fix) return NH_ERR_MEMORY;
    for (int i = 0; i < fixed->n; ++i) {
      s->tissue.n_fixed = i + 1;
      NH_TRY(read_fixed(c, fixed->items[i], join_index(key, "tissue.fixed", i), &s->tissue.fixed[i],
                        &s->tissue.fix[i]));
    }
  }

  NH_TRY(read_items(c, t, "loads", sizeof *s->tissue.loads, (void **)&s->tissue.loads,
                    &s->tissue.n_loads, read_load_item));
  NH_TRY(read_items(c, t, "tractions", sizeof *s->tissue.tractions, (void **)&s->tissue.tractions,
                    &s->tissue.n_tractions, read_traction_item));
  return NH_OK;
}

/* adapt.template (text `value`, at node `at`, NULL for the default) to a
 * readable file: a name is nh_templates_dir()/NAME.tmpl; a value with a '/' or
 * ending in .tmpl is a path, relative to the scene file's folder unless
 * absolute. The error is reported at `at`, or at `section` for the default. */
static int resolve_template(const nh_ctx *c, const nh_yaml_node *at, const nh_yaml_node *section,
                            const char *value, char out[NH_PATH_MAX]) {
  const nh_yaml_node *where = at ? at : section;
  size_t len = strlen(value);
  int is_path = strchr(value, '/') || (len >= 5 && !strcmp(value + len - 5, ".tmpl"));
  int n;
  if (len == 0) return fail(c, where, "adapt.template", "expected a template name or path");
  if (!is_path) {
    char buf[NH_PATH_MAX];
    const char *dir = nh_templates_dir(buf, sizeof buf);
    n = snprintf(out, NH_PATH_MAX, "%s/%s.tmpl", dir, value);
  } else {
    n = scene_relative(c, value, out);
  }
  if (n < 0 || n >= NH_PATH_MAX)
    return fail(c, where, "adapt.template", "the template's path is longer than %d characters",
                NH_PATH_MAX - 1);
  struct stat st;
  int err = access(out, R_OK) != 0 ? errno : 0;
  if (!err && stat(out, &st) == 0 && S_ISDIR(st.st_mode)) err = EISDIR;
  if (!err) return NH_OK;
  if (is_path)
    return fail(c, where, "adapt.template", "cannot read the template file %s: %s", out,
                strerror(err));
  return fail(c, where, "adapt.template",
              "no template named '%s' (cannot read %s: %s; set NH_TEMPLATES_DIR to the "
              "templates folder, or give a path)",
              value, out, strerror(err));
}

/* adapt: present (even empty) means the mesh adapts. */
static int read_adapt(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"estimator", "marking",  "max_level", "min_size", "max_dofs",
                                     "every",     "template", "hanging",   "goal",     "tolerance",
                                     "resolve",   "coarsen",  NULL};
  static const char *const marking_keys[] = {"strategy", "theta", "fraction", NULL};
  static const char *const coarsen_keys[] = {"fraction", NULL};
  static const char *const estimators[] = {"spr", "goal", NULL};
  static const char *const strategies[] = {"max", "dorfler", NULL};
  static const char *const hangings[] = {"eliminate", "lagrange", NULL};
  const nh_yaml_node *n, *key, *m, *at, *marking;
  char name[NH_PATH_MAX] = "hex2";
  s->adapt.enabled = 0;
  s->adapt.strategy = NH_MARK_MAX;
  s->adapt.theta = 0.3;
  s->adapt.fraction = 0.5;
  s->adapt.max_level = 2;
  s->adapt.min_size = 0;
  s->adapt.max_dofs = 0;
  s->adapt.every = 1;
  s->adapt.hanging = NH_HANGING_ELIMINATE;
  s->adapt.estimator = NH_ESTIMATOR_SPR;
  s->adapt.n_goals = 0;
  s->adapt.tolerance = 0;
  s->adapt.resolve = 0;
  s->adapt.coarsen = 0;
  n = nh_yaml_get(root, "adapt", &key);
  if (!n) return NH_OK;
  s->adapt.enabled = 1;
  make_where(c, key, "adapt", s->adapt.where);
  NH_TRY(section(c, root, "", "adapt", 0, &m));
  if (m) NH_TRY(check_keys(c, m, "adapt", keys));

  NH_TRY(field(c, m, "adapt", "estimator", 0, &at));
  int choice = 0;
  if (at) NH_TRY(as_choice(c, at, "adapt.estimator", estimators, &choice));
  s->adapt.estimator = choice ? NH_ESTIMATOR_GOAL : NH_ESTIMATOR_SPR;
  const nh_yaml_node *at_estimator = at;

  NH_TRY(section(c, m, "adapt", "marking", 0, &marking));
  if (marking) {
    const nh_yaml_node *at_theta, *at_fraction;
    NH_TRY(check_keys(c, marking, "adapt.marking", marking_keys));
    NH_TRY(field(c, marking, "adapt.marking", "strategy", 0, &at));
    if (at) {
      NH_TRY(as_choice(c, at, "adapt.marking.strategy", strategies, &choice));
      s->adapt.strategy = choice ? NH_MARK_DORFLER : NH_MARK_MAX;
    }
    NH_TRY(get_number(c, marking, "adapt.marking", "theta", 0, &s->adapt.theta, &at_theta));
    NH_TRY(
        get_number(c, marking, "adapt.marking", "fraction", 0, &s->adapt.fraction, &at_fraction));
    if (at_theta && s->adapt.strategy != NH_MARK_MAX)
      return fail(c, at_theta, "adapt.marking.theta",
                  "applies to strategy max only (the strategy is dorfler: give fraction)");
    if (at_fraction && s->adapt.strategy != NH_MARK_DORFLER)
      return fail(c, at_fraction, "adapt.marking.fraction",
                  "applies to strategy dorfler only (the strategy is max%s: give theta, or "
                  "strategy: dorfler)",
                  at ? "" : ", the default");
    if (at_theta && !(s->adapt.theta > 0 && s->adapt.theta < 1))
      return fail(c, at_theta, "adapt.marking.theta", "must lie in (0, 1), got %g", s->adapt.theta);
    if (at_fraction && !(s->adapt.fraction > 0 && s->adapt.fraction <= 1))
      return fail(c, at_fraction, "adapt.marking.fraction", "must lie in (0, 1], got %g",
                  s->adapt.fraction);
  }

  NH_TRY(field(c, m, "adapt", "template", 0, &at));
  if (at) NH_TRY(as_string(c, at, "adapt.template", name, sizeof name));
  NH_TRY(resolve_template(c, at, key, name, s->adapt.template_path));
  make_where(c, at ? at : key, "adapt.template", s->adapt.where_template);

  NH_TRY(get_int(c, m, "adapt", "max_level", &s->adapt.max_level, &at));
  NH_TRY(at_least(c, at, "adapt", "max_level", s->adapt.max_level, 0, 0));
  NH_TRY(get_number(c, m, "adapt", "min_size", 0, &s->adapt.min_size, &at));
  NH_TRY(at_least(c, at, "adapt", "min_size", s->adapt.min_size, 0, 0));
  NH_TRY(get_int(c, m, "adapt", "max_dofs", &s->adapt.max_dofs, &at));
  NH_TRY(at_least(c, at, "adapt", "max_dofs", s->adapt.max_dofs, 0, 0));
  NH_TRY(get_int(c, m, "adapt", "every", &s->adapt.every, &at));
  NH_TRY(at_least(c, at, "adapt", "every", s->adapt.every, 1, 0));
  NH_TRY(field(c, m, "adapt", "hanging", 0, &at));
  if (at) {
    NH_TRY(as_choice(c, at, "adapt.hanging", hangings, &choice));
    s->adapt.hanging = choice ? NH_HANGING_LAGRANGE : NH_HANGING_ELIMINATE;
  }
  const int goal = s->adapt.estimator == NH_ESTIMATOR_GOAL;
  if (goal && s->adapt.hanging == NH_HANGING_LAGRANGE)
    return fail(c, at, "adapt.hanging",
                "lagrange cannot be used with estimator goal (the dual problems need the "
                "hanging nodes eliminated)");
  const nh_yaml_node *at_goal;
  NH_TRY(field(c, m, "adapt", "goal", 0, &at_goal));
  if (at_goal && !goal)
    return fail(c, at_goal, "adapt.goal", "applies to estimator goal only (the estimator is %s)",
                at_estimator ? "spr" : "spr, the default");
  NH_TRY(get_number(c, m, "adapt", "tolerance", 0, &s->adapt.tolerance, &at));
  NH_TRY(at_least(c, at, "adapt", "tolerance", s->adapt.tolerance, 0, 1));
  if (at && !goal)
    return fail(c, at, "adapt.tolerance",
                "applies to estimator goal only (m, on the goal "
                "quantities' estimated error)");
  NH_TRY(get_int(c, m, "adapt", "resolve", &s->adapt.resolve, &at));
  NH_TRY(at_least(c, at, "adapt", "resolve", s->adapt.resolve, 0, 0));
  if (at && s->adapt.resolve > 0 && !goal)
    return fail(c, at, "adapt.resolve", "applies to estimator goal only");
  const nh_yaml_node *coarsen;
  NH_TRY(section(c, m, "adapt", "coarsen", 0, &coarsen));
  if (coarsen) {
    NH_TRY(check_keys(c, coarsen, "adapt.coarsen", coarsen_keys));
    NH_TRY(get_number(c, coarsen, "adapt.coarsen", "fraction", 1, &s->adapt.coarsen, &at));
    if (!(s->adapt.coarsen > 0 && s->adapt.coarsen < 1))
      return fail(c, at, "adapt.coarsen.fraction", "must lie in (0, 1), got %g", s->adapt.coarsen);
  }
  return NH_OK;
}

/* adapt.goal, after probes and targets: names to indices of the embedded
 * points (probes, then targets); default every target, else every probe. */
static int read_adapt_goal(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  if (!s->adapt.enabled || s->adapt.estimator != NH_ESTIMATOR_GOAL) return NH_OK;
  const nh_yaml_node *m = nh_yaml_get(root, "adapt", NULL), *list = NULL;
  if (m && m->kind == NH_YAML_MAP) list = nh_yaml_get(m, "goal", NULL);
  s->adapt.n_goals = 0;
  if (!list) {
    int from = s->n_targets > 0 ? s->n_probes : 0;
    int n = s->n_targets > 0 ? s->n_targets : s->n_probes;
    if (n == 0)
      return fail(c, nh_yaml_get(m, "estimator", NULL), "adapt.estimator",
                  "goal needs probes or targets to estimate (the scene has none)");
    if (n > NH_MAX_GOALS) n = NH_MAX_GOALS;
    for (int i = 0; i < n; i++) s->adapt.goal[s->adapt.n_goals++] = from + i;
    return NH_OK;
  }
  char d[96], item[NH_KEY_MAX], name[NH_NAME_MAX];
  if (list->kind != NH_YAML_SEQ || list->n == 0)
    return fail(c, list, "adapt.goal", "expected a list of probe or target names, got %s",
                describe(list, d, sizeof d));
  if (list->n > NH_MAX_GOALS)
    return fail(c, list, "adapt.goal", "at most %d goals, got %d", NH_MAX_GOALS, list->n);
  for (int i = 0; i < list->n; i++) {
    join_index(item, "adapt.goal", i);
    NH_TRY(as_string(c, list->items[i], item, name, sizeof name));
    int found = -1;
    for (int p = 0; p < s->n_probes && found < 0; p++)
      if (!strcmp(s->probes[p].name, name)) found = p;
    for (int t = 0; t < s->n_targets && found < 0; t++)
      if (!strcmp(s->targets[t].name, name)) found = s->n_probes + t;
    if (found < 0) return fail(c, list->items[i], item, "no probe or target is named \"%s\"", name);
    for (int k = 0; k < s->adapt.n_goals; k++)
      if (s->adapt.goal[k] == found)
        return fail(c, list->items[i], item, "\"%s\" is named twice", name);
    s->adapt.goal[s->adapt.n_goals++] = found;
  }
  return NH_OK;
}

static int read_solver(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"tolerance",  "max_iterations", "threads",       "refactor",
                                     "on_invalid", "newton",         "lazy_rotation", NULL};
  static const char *const refactors[] = {"auto", "every", NULL};
  static const char *const newton_keys[] = {"max_iterations", "tolerance", NULL};
  static const char *const on_invalid[] = {"stop", "warn", NULL};
  const nh_yaml_node *m, *at, *newton;
  int choice = 0;
  s->solver.refactor = NH_REFACTOR_AUTO;
  s->solver.tolerance = 1e-8;
  s->solver.max_iterations = 30;
  s->solver.threads = 0;
  s->solver.on_invalid_warn = 0;
  s->solver.newton_iterations = 0;
  s->solver.newton_tolerance = 1e-8;
  s->solver.lazy_rotation = 0.0;
  NH_TRY(section(c, root, "", "solver", 0, &m));
  if (!m) return NH_OK;
  NH_TRY(check_keys(c, m, "solver", keys));
  NH_TRY(field(c, m, "solver", "on_invalid", 0, &at));
  if (at) NH_TRY(as_choice(c, at, "solver.on_invalid", on_invalid, &s->solver.on_invalid_warn));
  NH_TRY(section(c, m, "solver", "newton", 0, &newton));
  if (newton) {
    NH_TRY(check_keys(c, newton, "solver.newton", newton_keys));
    s->solver.newton_iterations = 5;
    NH_TRY(
        get_int(c, newton, "solver.newton", "max_iterations", &s->solver.newton_iterations, &at));
    NH_TRY(at_least(c, at, "solver.newton", "max_iterations", s->solver.newton_iterations, 0, 0));
    NH_TRY(
        get_number(c, newton, "solver.newton", "tolerance", 0, &s->solver.newton_tolerance, &at));
    NH_TRY(at_least(c, at, "solver.newton", "tolerance", s->solver.newton_tolerance, 0, 1));
  }
  NH_TRY(get_number(c, m, "solver", "tolerance", 0, &s->solver.tolerance, &at));
  NH_TRY(at_least(c, at, "solver", "tolerance", s->solver.tolerance, 0, 1));
  NH_TRY(get_int(c, m, "solver", "max_iterations", &s->solver.max_iterations, &at));
  NH_TRY(at_least(c, at, "solver", "max_iterations", s->solver.max_iterations, 1, 0));
  NH_TRY(get_int(c, m, "solver", "threads", &s->solver.threads, &at));
  NH_TRY(at_least(c, at, "solver", "threads", s->solver.threads, 0, 0));
  NH_TRY(get_number(c, m, "solver", "lazy_rotation", 0, &s->solver.lazy_rotation, &at));
  NH_TRY(at_least(c, at, "solver", "lazy_rotation", s->solver.lazy_rotation, 0, 0));
  NH_TRY(field(c, m, "solver", "refactor", 0, &at));
  if (at) {
    NH_TRY(as_choice(c, at, "solver.refactor", refactors, &choice));
    s->solver.refactor = choice ? NH_REFACTOR_EVERY : NH_REFACTOR_AUTO;
  }
  return NH_OK;
}

/* ITEM.name of a probe or target (required): it goes into probes.csv or
 * targets.csv and the VTU point data, so it must be one plain CSV field. */
static int read_point_name(const nh_ctx *c, const nh_yaml_node *item, const char *path,
                           char name[NH_NAME_MAX], const nh_yaml_node **at) {
  char key[NH_KEY_MAX], d[96];
  NH_TRY(field(c, item, path, "name", 1, at));
  NH_TRY(as_string(c, *at, join(key, path, "name"), name, NH_NAME_MAX));
  if (!name[0] || strpbrk(name, ",\"\n\r\t"))
    return fail(c, *at, key, "%s must be non-empty, without commas, quotes or tabs",
                describe(*at, d, sizeof d));
  return NH_OK;
}

static int read_probes(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"name", "point", NULL};
  char path[NH_KEY_MAX], key[NH_KEY_MAX], d[96];
  const nh_yaml_node *list;
  NH_TRY(list_section(c, root, "", "probes", &list));
  if (!list || list->n == 0) return NH_OK;
  s->probes = nh_calloc((size_t)list->n, sizeof *s->probes);
  if (!s->probes) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *p = list->items[i], *at;
    nh_probe *probe = &s->probes[i];
    join_index(path, "probes", i);
    if (p->kind != NH_YAML_MAP)
      return fail(c, p, path, "expected a probe {name: ..., point: [x, y, z]}, got %s",
                  describe(p, d, sizeof d));
    NH_TRY(check_keys(c, p, path, keys));
    NH_TRY(read_point_name(c, p, path, probe->name, &at));
    join(key, path, "name");
    for (int j = 0; j < i; ++j)
      if (!strcmp(s->probes[j].name, probe->name))
        return fail(c, at, key, "%s is already the name of probes.%d", describe(at, d, sizeof d),
                    j);
    NH_TRY(get_point(c, p, path, "point", 1, probe->point, &at));
    NH_TRY(check_in_image(c, at, join(key, path, "point"), s, probe->point));
    make_where(c, p, path, probe->where);
    s->n_probes = i + 1;
  }
  return NH_OK;
}

/* The names of the tools, "'a', 'b'" (for messages), cut to fit `cap`. */
static const char *tool_names(const nh_scene *s, char *buf, size_t cap) {
  size_t len = 0;
  buf[0] = '\0';
  for (int j = 0; j < s->n_tools && len < cap; ++j) {
    int n = snprintf(buf + len, cap - len, "%s'%s'", j ? ", " : "", s->tools[j].name);
    if (n < 0) break;
    len += (size_t)n;
  }
  return buf;
}

/* The word of a symbolic `until` (NH_UNTIL_TIME if `n` is not one). */
static nh_until_kind until_word(const nh_yaml_node *n) {
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n)) return NH_UNTIL_TIME;
  if (!strcmp(n->text, "target")) return NH_UNTIL_TARGET;
  if (!strcmp(n->text, "start")) return NH_UNTIL_START;
  return NH_UNTIL_TIME;
}

/* PATH.motion: [{until, speed}, ...] with `until` > 0 and strictly
 * increasing; absent or empty: the tool stays at rest. `until` may also be
 * the word target (speed > 0) or start (speed < 0) on a tool with a
 * trajectory: read_plans turns it into a time, and checks the order of the
 * times around it then. */
static int read_motion(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                       nh_tool_spec *t) {
  static const char *const keys[] = {"until", "speed", "spin", NULL};
  char motion[NH_KEY_MAX], item[NH_KEY_MAX], key[NH_KEY_MAX], d[96];
  const nh_yaml_node *list;
  NH_TRY(list_section(c, tool, path, "motion", &list));
  if (!list || list->n == 0) return NH_OK;
  join(motion, path, "motion");
  t->motion = nh_calloc((size_t)list->n, sizeof *t->motion);
  if (!t->motion) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *m = list->items[i], *at;
    nh_motion *segment = &t->motion[i];
    join_index(item, motion, i);
    if (m->kind != NH_YAML_MAP)
      return fail(c, m, item, "expected a segment {until: TIME, speed: SPEED}, got %s",
                  describe(m, d, sizeof d));
    NH_TRY(check_keys(c, m, item, keys));
    NH_TRY(get_number(c, m, item, "spin", 0, &segment->spin, NULL));
    NH_TRY(field(c, m, item, "until", 1, &at));
    segment->kind = until_word(at);
    if (segment->kind != NH_UNTIL_TIME) {
      if (!t->planned)
        return fail(c, at, join(key, item, "until"),
                    "%s needs a trajectory (give %s.trajectory: {entry, target}): it is a "
                    "position on the planned path",
                    describe(at, d, sizeof d), path);
      NH_TRY(get_number(c, m, item, "speed", 1, &segment->speed, &at));
      if (segment->kind == NH_UNTIL_TARGET && !(segment->speed > 0))
        return fail(c, at, join(key, item, "speed"),
                    "must be greater than 0 with until: target (the tip advances to the "
                    "target), got %g",
                    segment->speed);
      if (segment->kind == NH_UNTIL_START && !(segment->speed < 0))
        return fail(c, at, join(key, item, "speed"),
                    "must be less than 0 with until: start (the tip withdraws to its start), "
                    "got %g",
                    segment->speed);
      t->n_motion = i + 1;
      continue;
    }
    NH_TRY(as_number(c, at, join(key, item, "until"), &segment->until));
    if (i == 0) NH_TRY(at_least(c, at, item, "until", segment->until, 0, 1));
    if (i > 0 && t->motion[i - 1].kind == NH_UNTIL_TIME &&
        !(segment->until > t->motion[i - 1].until))
      return fail(c, at, join(key, item, "until"), "times must increase strictly (%g after %g)",
                  segment->until, t->motion[i - 1].until);
    NH_TRY(get_number(c, m, item, "speed", 1, &segment->speed, NULL));
    t->n_motion = i + 1;
  }
  return NH_OK;
}

/* PATH.direction (required, non-zero), stored with unit length. */
static int read_direction(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                          double direction[3]) {
  char key[NH_KEY_MAX];
  const nh_yaml_node *at;
  NH_TRY(get_vec3(c, tool, path, "direction", 1, direction, &at));
  /* Scale by the largest component first, so that squaring neither
   * overflows (1e200) nor underflows (1e-200). */
  double scale = 0, norm = 0;
  for (int k = 0; k < 3; ++k) scale = fmax(scale, fabs(direction[k]));
  if (!(scale > 0)) return fail(c, at, join(key, path, "direction"), "must not be the zero vector");
  for (int k = 0; k < 3; ++k) norm += (direction[k] / scale) * (direction[k] / scale);
  norm = sqrt(norm);
  for (int k = 0; k < 3; ++k) direction[k] = direction[k] / scale / norm;
  return NH_OK;
}

/* PATH.inside (optional): the name of a tool listed before this one that is
 * not itself nested; t->inside = its index. */
static int read_host(const nh_ctx *c, const nh_yaml_node *list, int i, const char *path,
                     nh_scene *s) {
  char key[NH_KEY_MAX], host[NH_NAME_MAX], d[96];
  nh_tool_spec *t = &s->tools[i];
  const nh_yaml_node *at;
  NH_TRY(field(c, list->items[i], path, "inside", 0, &at));
  if (!at) return NH_OK;
  NH_TRY(as_string(c, at, join(key, path, "inside"), host, sizeof host));
  for (int j = 0; j < i; ++j) {
    if (strcmp(s->tools[j].name, host) != 0) continue;
    if (s->tools[j].inside >= 0)
      return fail(c, at, key, "%s (tools.%d) is itself inside '%s': tools nest one level deep only",
                  describe(at, d, sizeof d), j, s->tools[s->tools[j].inside].name);
    t->inside = j;
    return NH_OK;
  }
  if (!strcmp(host, t->name)) return fail(c, at, key, "a tool cannot be inside itself");
  for (int j = i + 1; j < list->n; ++j) {
    const nh_yaml_node *name = nh_yaml_get(list->items[j], "name", NULL);
    if (name && name->kind == NH_YAML_SCALAR && !strcmp(name->text, host))
      return fail(c, at, key, "%s is tools.%d, listed after this tool: list the host first",
                  describe(at, d, sizeof d), j);
  }
  return fail(c, at, key, "no tool named %s is listed before this one", describe(at, d, sizeof d));
}

/* PATH.trajectory {entry, target, standoff, aim} (optional): sets
 * t->planned, the entry, the standoff and the aim if given; the target's
 * name is looked up by read_plans, once the targets are read. base and
 * direction must then not be given. */
static int read_trajectory(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                           nh_tool_spec *t) {
  static const char *const keys[] = {"entry", "target", "standoff", "aim", NULL};
  static const char *const computed[] = {"base", "direction", NULL};
  char sub[NH_KEY_MAX], key[NH_KEY_MAX];
  const nh_yaml_node *m, *at;
  t->target = -1;
  t->standoff = 0.005;
  NH_TRY(section(c, tool, path, "trajectory", 0, &m));
  if (!m) return NH_OK;
  for (const char *const *k = computed; *k; ++k) {
    const nh_yaml_node *name;
    if (nh_yaml_get(tool, *k, &name))
      return fail(c, name, join(key, path, *k),
                  "not with trajectory: the trajectory sets the base and the direction");
  }
  join(sub, path, "trajectory");
  NH_TRY(check_keys(c, m, sub, keys));
  t->planned = 1;
  NH_TRY(get_point(c, m, sub, "entry", 1, t->entry, NULL));
  NH_TRY(field(c, m, sub, "target", 1, &at));
  NH_TRY(get_number(c, m, sub, "standoff", 0, &t->standoff, &at));
  NH_TRY(at_least(c, at, sub, "standoff", t->standoff, 0, 1));
  t->aimed = 0;
  NH_TRY(get_vec3(c, m, sub, "aim", 0, t->aim, &at));
  t->aimed = at != NULL;
  return NH_OK;
}

/* PATH.bevel (optional): {angle: DEG, toward: [x, y, z]}; angle in [0, 90),
 * toward non-zero (checked against the direction by resolve_bevel, once a
 * trajectory has set it). */
static int read_bevel(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                      nh_tool_spec *t) {
  static const char *const keys[] = {"angle", "toward", NULL};
  char sub[NH_KEY_MAX], key[NH_KEY_MAX];
  const nh_yaml_node *m, *at;
  NH_TRY(section(c, tool, path, "bevel", 0, &m));
  if (!m) return NH_OK;
  join(sub, path, "bevel");
  NH_TRY(check_keys(c, m, sub, keys));
  NH_TRY(get_number(c, m, sub, "angle", 1, &t->bevel, &at));
  if (!(t->bevel >= 0 && t->bevel < 90))
    return fail(c, at, join(key, sub, "angle"), "must lie in [0, 90) degrees, got %g", t->bevel);
  NH_TRY(get_vec3(c, m, sub, "toward", 0, t->bevel_toward, &at));
  if (at && !(nh_vec3_norm(t->bevel_toward) > 0))
    return fail(c, at, join(key, sub, "toward"), "must not be the zero vector");
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
    return fail(c, nh_yaml_get(bevel, "toward", NULL), join(key, path, "bevel.toward"),
                "is parallel to the tool's direction [%g, %g, %g]: give a side across it",
                t->direction[0], t->direction[1], t->direction[2]);
  }
  for (int k = 0; k < 3; ++k) b[k] /= m;
  return NH_OK;
}

/* tools[i]: one tool, its defaults and its checks (tools before it are read). */
static int read_tool(const nh_ctx *c, const nh_yaml_node *list, int i, nh_scene *s) {
  static const char *const keys[] = {"name",      "length",     "radius",  "inner_radius",
                                     "elements",  "material",   "damping", "base",
                                     "direction", "trajectory", "motion",  "interaction",
                                     "inside",    "release",    "bevel",   NULL};
  static const char *const interaction_keys[] = {
      "puncture_force", "cutting_force",   "friction", "friction_per_length",
      "spacing",        "friction_static", NULL};
  /* Files the output folder holds besides the tools' own. */
  static const char *const reserved[] = {"tissue", "points", NULL};
  char path[NH_KEY_MAX], sub[NH_KEY_MAX], key[NH_KEY_MAX], d[96];
  const nh_yaml_node *node = list->items[i], *at, *m;
  nh_tool_spec *t = &s->tools[i];
  join_index(path, "tools", i);
  t->inner_radius = 0;
  t->elements = 16;
  t->poisson = 0.3;
  t->density = 7800;
  t->inside = -1;
  t->release = INFINITY;
  if (node->kind != NH_YAML_MAP)
    return fail(c, node, path,
                "expected a tool {name: ..., length: ..., radius: ..., material: ..., base: "
                "[x, y, z], direction: [x, y, z]}, got %s",
                describe(node, d, sizeof d));
  NH_TRY(check_keys(c, node, path, keys));

  /* The name names the files <name>.pvd and <name>_NNNNNN.vtu: a plain file
   * name, distinct from the other tools' even on a file system that ignores
   * case, and from the folder's other .pvd files. */
  NH_TRY(field(c, node, path, "name", 1, &at));
  NH_TRY(as_string(c, at, join(key, path, "name"), t->name, sizeof t->name));
  size_t len = strlen(t->name);
  if (len == 0 || strspn(t->name, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                                  "0123456789_-") != len)
    return fail(c, at, key,
                "%s must be non-empty and contain only letters, digits, '_' and '-' (it names "
                "the output file NAME.pvd)",
                describe(at, d, sizeof d));
  for (const char *const *r = reserved; *r; ++r)
    if (!strcasecmp(t->name, *r))
      return fail(c, at, key, "%s is taken: the output folder already holds %s.pvd",
                  describe(at, d, sizeof d), *r);
  for (int j = 0; j < i; ++j) {
    if (!strcmp(s->tools[j].name, t->name))
      return fail(c, at, key, "%s is already the name of tools.%d", describe(at, d, sizeof d), j);
    if (!strcasecmp(s->tools[j].name, t->name))
      return fail(c, at, key,
                  "%s differs from the name of tools.%d ('%s') only in case (tool names name "
                  "files, and some file systems ignore case)",
                  describe(at, d, sizeof d), j, s->tools[j].name);
  }

  NH_TRY(get_number(c, node, path, "length", 1, &t->length, &at));
  NH_TRY(at_least(c, at, path, "length", t->length, 0, 1));
  NH_TRY(get_number(c, node, path, "radius", 1, &t->radius, &at));
  NH_TRY(at_least(c, at, path, "radius", t->radius, 0, 1));
  NH_TRY(get_number(c, node, path, "inner_radius", 0, &t->inner_radius, &at));
  NH_TRY(at_least(c, at, path, "inner_radius", t->inner_radius, 0, 0));
  if (at && !(t->inner_radius < t->radius))
    return fail(c, at, join(key, path, "inner_radius"), "must be less than the radius (%g), got %g",
                t->radius, t->inner_radius);
  NH_TRY(get_int(c, node, path, "elements", &t->elements, &at));
  NH_TRY(at_least(c, at, path, "elements", t->elements, 1, 0));
  NH_TRY(read_material(c, node, path, 0, 0, &t->young, &t->poisson, &t->density, NULL));
  NH_TRY(read_damping(c, node, path, &t->damping_mass, &t->damping_stiffness));
  NH_TRY(read_trajectory(c, node, path, t));
  if (!t->planned) {
    NH_TRY(get_vec3(c, node, path, "base", 1, t->base, NULL));
    NH_TRY(read_direction(c, node, path, t->direction));
  }
  NH_TRY(read_motion(c, node, path, t));
  NH_TRY(read_bevel(c, node, path, t));

  join(sub, path, "interaction");
  NH_TRY(section(c, node, path, "interaction", 0, &m));
  if (m) {
    double *value[] = {&t->puncture_force,      &t->cutting_force, &t->friction,
                       &t->friction_per_length, &t->spacing,       &t->friction_static};
    NH_TRY(check_keys(c, m, sub, interaction_keys));
    t->friction_static = -1;
    for (int k = 0; interaction_keys[k]; ++k) {
      NH_TRY(get_number(c, m, sub, interaction_keys[k], 0, value[k], &at));
      NH_TRY(at_least(c, at, sub, interaction_keys[k], *value[k], 0, 0));
    }
    if (at && t->friction_static < t->friction) /* `at`: friction_static, read last */
      return fail(c, at, join(key, sub, "friction_static"),
                  "the static coefficient must be at least the kinetic one (friction = %g), got %g",
                  t->friction, t->friction_static);
  }
  if (t->friction_static < t->friction) t->friction_static = t->friction;

  NH_TRY(read_host(c, list, i, path, s));
  NH_TRY(field(c, node, path, "release", 0, &at));
  if (at && t->inside < 0)
    return fail(c, at, join(key, path, "release"),
                "applies to a nested tool only (give inside: HOST, the tool it starts in)");
  if (at && until_word(at) == NH_UNTIL_TARGET) {
    t->release_target = 1; /* read_plans: the end of the host's until: target */
  } else if (at) {
    if (at->kind == NH_YAML_SCALAR && !nh_yaml_is_null(at) && !at->quoted &&
        (isalpha((unsigned char)at->text[0]) || at->text[0] == '_'))
      return fail(c, at, join(key, path, "release"), "expected a time or the word target, got %s",
                  describe(at, d, sizeof d));
    NH_TRY(as_number(c, at, join(key, path, "release"), &t->release));
    NH_TRY(at_least(c, at, path, "release", t->release, 0, 0));
  }
  make_where(c, node, path, t->where);
  return NH_OK;
}

static int read_tools(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  const nh_yaml_node *list;
  NH_TRY(list_section(c, root, "", "tools", &list));
  if (!list || list->n == 0) return NH_OK;
  s->tools = nh_calloc((size_t)list->n, sizeof *s->tools);
  if (!s->tools) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    /* Count the tool first so that destroy frees a half-read motion. */
    s->n_tools = i + 1;
    NH_TRY(read_tool(c, list, i, s));
  }
  return NH_OK;
}

static int read_targets(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"name", "point", "tool", NULL};
  char path[NH_KEY_MAX], key[NH_KEY_MAX], tool[NH_NAME_MAX], names[256], d[96];
  const nh_yaml_node *list;
  NH_TRY(list_section(c, root, "", "targets", &list));
  if (!list || list->n == 0) return NH_OK;
  s->targets = nh_calloc((size_t)list->n, sizeof *s->targets);
  if (!s->targets) return NH_ERR_MEMORY;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *p = list->items[i], *at;
    nh_target *target = &s->targets[i];
    join_index(path, "targets", i);
    if (p->kind != NH_YAML_MAP)
      return fail(c, p, path, "expected a target {name: ..., point: [x, y, z], tool: ...}, got %s",
                  describe(p, d, sizeof d));
    NH_TRY(check_keys(c, p, path, keys));
    NH_TRY(read_point_name(c, p, path, target->name, &at));
    join(key, path, "name");
    for (int j = 0; j < i; ++j)
      if (!strcmp(s->targets[j].name, target->name))
        return fail(c, at, key, "%s is already the name of targets.%d", describe(at, d, sizeof d),
                    j);
    NH_TRY(get_point(c, p, path, "point", 1, target->point, &at));
    NH_TRY(check_in_image(c, at, join(key, path, "point"), s, target->point));
    NH_TRY(field(c, p, path, "tool", 1, &at));
    NH_TRY(as_string(c, at, join(key, path, "tool"), tool, sizeof tool));
    target->tool = -1;
    for (int j = 0; j < s->n_tools && target->tool < 0; ++j)
      if (!strcmp(s->tools[j].name, tool)) target->tool = j;
    if (target->tool < 0 && s->n_tools == 0)
      return fail(c, at, key, "no tool named %s (the scene has no tools)",
                  describe(at, d, sizeof d));
    if (target->tool < 0)
      return fail(c, at, key, "no tool named %s (the tools are %s)", describe(at, d, sizeof d),
                  tool_names(s, names, sizeof names));
    make_where(c, p, path, target->where);
    s->n_targets = i + 1;
  }
  return NH_OK;
}

/* tools.i.trajectory (the target's name, now that targets are read): base,
 * direction and planned depth. */
static int resolve_trajectory(const nh_ctx *c, const nh_yaml_node *tool, const char *path,
                              nh_scene *s, int i) {
  nh_tool_spec *t = &s->tools[i];
  char key[NH_KEY_MAX], sub[NH_KEY_MAX], name[NH_NAME_MAX], d[96], names[256];
  const nh_yaml_node *traj = nh_yaml_get(tool, "trajectory", NULL), *at;
  join(sub, path, "trajectory");
  NH_TRY(field(c, traj, sub, "target", 1, &at));
  NH_TRY(as_string(c, at, join(key, sub, "target"), name, sizeof name));
  for (int j = 0; j < s->n_targets && t->target < 0; ++j)
    if (!strcmp(s->targets[j].name, name)) t->target = j;
  if (t->target < 0 && s->n_targets == 0)
    return fail(c, at, key, "no target named %s (the scene has no targets)",
                describe(at, d, sizeof d));
  if (t->target < 0) {
    size_t len = 0;
    names[0] = '\0';
    for (int j = 0; j < s->n_targets && len < sizeof names; ++j) {
      int n =
          snprintf(names + len, sizeof names - len, "%s'%s'", j ? ", " : "", s->targets[j].name);
      if (n < 0) break;
      len += (size_t)n;
    }
    return fail(c, at, key, "no target named %s (the targets are %s)", describe(at, d, sizeof d),
                names);
  }
  /* The aim: the target's point unless trajectory.aim moves it (`needlehex
   * plan`, docs/dbs.md). */
  if (!t->aimed) memcpy(t->aim, s->targets[t->target].point, sizeof t->aim);
  const nh_yaml_node *aim_at = t->aimed ? nh_yaml_get(traj, "aim", NULL) : NULL;
  if (nh_scene_trajectory_line(t, t->aim) == NH_OK) return NH_OK;
  if (aim_at)
    return fail(c, aim_at, join(key, sub, "aim"),
                "the aim is the entry point [%g, %g, %g]: no direction", t->entry[0], t->entry[1],
                t->entry[2]);
  return fail(c, at, key, "target %s is at the entry point [%g, %g, %g]: no direction",
              describe(at, d, sizeof d), t->entry[0], t->entry[1], t->entry[2]);
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
  return fail(c, at, join(key, path, "release"),
              "target: the host '%s' has no motion segment with until: target", host->name);
}

/* tools.i.motion: every symbolic until to a time, then the order of all. */
static int resolve_motion(const nh_ctx *c, const nh_yaml_node *tool, const char *path, nh_scene *s,
                          int i) {
  nh_tool_spec *t = &s->tools[i];
  char motion[NH_KEY_MAX], item[NH_KEY_MAX], key[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(tool, "motion", NULL);
  join(motion, path, "motion");
  for (int k = 0; k < t->n_motion; ++k) {
    nh_motion *m = &t->motion[k];
    const nh_yaml_node *at = nh_yaml_get(list->items[k], "until", NULL);
    join(key, join_index(item, motion, k), "until");
    double t0 = k > 0 ? t->motion[k - 1].until : 0.0;
    if (m->kind != NH_UNTIL_TIME) {
      /* A nested tool follows its host until its release: its own motion
       * starts then. */
      if (t->inside >= 0 && !isfinite(t->release))
        return fail(c, at, key,
                    "%s: the tool follows its host '%s' and is never released (give release)",
                    m->kind == NH_UNTIL_TARGET ? "target" : "start", s->tools[t->inside].name);
      double start = t->inside >= 0 ? fmax(t0, t->release) : t0;
      double travelled = nh_scene_tip_travel(s, i, k, start);
      if (m->kind == NH_UNTIL_TARGET) {
        if (!(travelled < t->depth))
          return fail(c, at, key,
                      "target: by %g s the tip has already travelled %g m, the planned depth is "
                      "%g m",
                      start, travelled, t->depth);
        m->until = start + (t->depth - travelled) / m->speed;
      } else {
        if (!(travelled > 0))
          return fail(c, at, key,
                      "start: by %g s the tip is not ahead of its start (it has travelled %g m)",
                      start, travelled);
        m->until = start + travelled / -m->speed;
      }
    }
    if (!(m->until > t0))
      return fail(c, at, key, "times must increase strictly (%.17g after %.17g%s)", m->until, t0,
                  k > 0 && t->motion[k - 1].kind != NH_UNTIL_TIME
                      ? ", the time the previous segment's until resolves to"
                      : "");
  }
  return NH_OK;
}

/* Trajectories, release: target and symbolic untils, tool by tool (a host
 * before the tools inside it). */
static int read_plans(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  char path[NH_KEY_MAX];
  const nh_yaml_node *list = nh_yaml_get(root, "tools", NULL);
  for (int i = 0; i < s->n_tools; ++i) {
    nh_tool_spec *t = &s->tools[i];
    const nh_yaml_node *tool = list->items[i];
    join_index(path, "tools", i);
    if (t->planned) NH_TRY(resolve_trajectory(c, tool, path, s, i));
    if (t->release_target) NH_TRY(resolve_release(c, tool, path, s, i));
    NH_TRY(resolve_motion(c, tool, path, s, i));
    NH_TRY(resolve_bevel(c, tool, path, t));
  }
  return NH_OK;
}

static int read_output(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"dir", "every", "hdf5", "checkpoint", NULL};
  const nh_yaml_node *m, *at;
  nh_yaml_join(s->output.dir, sizeof s->output.dir, "out", "/", s->name);
  s->output.every = 1;
  s->output.hdf5 = 0;
  s->output.checkpoint = 0;
  NH_TRY(section(c, root, "", "output", 0, &m));
  if (!m) return NH_OK;
  NH_TRY(check_keys(c, m, "output", keys));
  NH_TRY(field(c, m, "output", "dir", 0, &at));
  if (at) {
    NH_TRY(as_string(c, at, "output.dir", s->output.dir, sizeof s->output.dir));
    if (!s->output.dir[0]) return fail(c, at, "output.dir", "must not be empty");
  }
  NH_TRY(get_int(c, m, "output", "every", &s->output.every, &at));
  NH_TRY(at_least(c, at, "output", "every", s->output.every, 0, 0));
  NH_TRY(field(c, m, "output", "hdf5", 0, &at));
  if (at) NH_TRY(as_bool(c, at, "output.hdf5", &s->output.hdf5));
  NH_TRY(get_int(c, m, "output", "checkpoint", &s->output.checkpoint, &at));
  NH_TRY(at_least(c, at, "output", "checkpoint", s->output.checkpoint, 0, 0));
  return NH_OK;
}

static int read_name(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  const nh_yaml_node *at;
  char d[96];
  NH_TRY(field(c, root, "", "name", 1, &at));
  NH_TRY(as_string(c, at, "name", s->name, sizeof s->name));
  size_t len = strlen(s->name);
  if (len == 0 ||
      strspn(s->name, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                      "0123456789._-") != len ||
      !strcmp(s->name, ".") || !strcmp(s->name, ".."))
    return fail(c, at, "name",
                "%s may only contain letters, digits, '.', '_' and '-' (it names the output "
                "folder)",
                describe(at, d, sizeof d));
  return NH_OK;
}

/* The whole schema, in the order of docs/scene.md. */
static int read_scene(nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"name",  "time",   "gravity", "tissue", "adapt",  "solver",
                                     "tools", "probes", "targets", "output", "limits", NULL};
  NH_TRY(check_keys(c, root, "", keys));
  NH_TRY(read_name(c, root, s));
  NH_TRY(read_time(c, root, s));
  NH_TRY(read_gravity(c, root, s));
  NH_TRY(read_limits(c, root, s)); /* before tissue: the grid is checked against them */
  NH_TRY(read_tissue(c, root, s));
  c->image = s->tissue.mask_file[0]     ? s->tissue.mask_file
             : s->tissue.labels_file[0] ? s->tissue.labels_file
                                        : NULL; /* voxel points of probes, targets, entries */
  NH_TRY(read_adapt(c, root, s));
  NH_TRY(read_solver(c, root, s));
  NH_TRY(read_tools(c, root, s));
  NH_TRY(read_probes(c, root, s));
  NH_TRY(read_targets(c, root, s));    /* after tools: a target names its tool */
  NH_TRY(read_adapt_goal(c, root, s)); /* after probes and targets: goals name them */
  NH_TRY(read_plans(c, root, s));      /* after targets: a trajectory names its target */
  NH_TRY(read_output(c, root, s));
  return NH_OK;
}

/* Parse, override, keep the text, read the schema. */
/* time.end and time.steps say the same thing two ways. When an override sets
 * one of them and the file gives the other, the override wins and the file's
 * key is dropped, so that `--set time.steps=20` works on a scene that gives
 * time.end. Both in the file, or both in overrides, remain an error
 * (reported by read_scene). */
static void resolve_time_length(nh_yaml_node *root) {
  nh_yaml_node *time = (nh_yaml_node *)nh_yaml_get(root, "time", NULL);
  if (!time || time->kind != NH_YAML_MAP) return;
  int i_end = -1, i_steps = -1;
  for (int i = 0; i < time->n; i++) {
    if (!strcmp(time->keys[i]->text, "end")) i_end = i;
    if (!strcmp(time->keys[i]->text, "steps")) i_steps = i;
  }
  if (i_end < 0 || i_steps < 0) return;
  int s_end = time->items[i_end]->source, s_steps = time->items[i_steps]->source;
  if ((s_end == 0) == (s_steps == 0)) return;
  int drop = s_end == 0 ? i_end : i_steps;
  nh_yaml_free(&time->keys[drop]);
  nh_yaml_free(&time->items[drop]);
  for (int i = drop; i + 1 < time->n; i++) {
    time->keys[i] = time->keys[i + 1];
    time->items[i] = time->items[i + 1];
  }
  time->n--;
}

static int load(nh_ctx *c, nh_scene *s, nh_yaml_node **root) {
  char d[96];
  NH_TRY(nh_yaml_parse_file(c->file, root));
  if (nh_yaml_is_null(*root))
    return NH_ERROR(NH_ERR_INPUT,
                    "%s:1: the scene is empty: expected a mapping with at least name and tissue",
                    c->file);
  if ((*root)->kind != NH_YAML_MAP)
    return NH_ERROR(NH_ERR_INPUT,
                    "%s:%d: the scene must be a mapping (name: ..., tissue: ...), got %s", c->file,
                    (*root)->line, describe(*root, d, sizeof d));
  for (int k = 1; k <= c->n_overrides; ++k) {
    if (!c->overrides[k - 1]) return NH_ERROR(NH_ERR_INPUT, "--set:%d: missing KEY=VALUE", k);
    NH_TRY(nh_yaml_apply_override(*root, k, c->overrides[k - 1]));
  }
  resolve_time_length(*root);
  NH_TRY(nh_yaml_emit(*root, &s->yaml));
  return read_scene(c, *root, s);
}

int nh_scene_load(const char *path, int n_overrides, const char *const *overrides, nh_scene **out) {
  *out = NULL;
  if (!path) return NH_ERROR(NH_ERR_INPUT, "no scene file given");
  if (n_overrides < 0 || (n_overrides > 0 && !overrides))
    return NH_ERROR(NH_ERR_INTERNAL, "nh_scene_load: bad override array");
  if (strlen(path) >= NH_PATH_MAX)
    return NH_ERROR(NH_ERR_INPUT, "%.64s...: the scene path is longer than %d characters", path,
                    NH_PATH_MAX - 1);
  nh_scene *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  memcpy(s->file, path, strlen(path) + 1);
  nh_ctx c = {.file = path, .overrides = overrides, .n_overrides = n_overrides};
  nh_yaml_node *root = NULL;
  int rc = load(&c, s, &root);
  nh_yaml_free(&root);
  if (rc) {
    nh_scene_destroy(&s);
    return rc;
  }
  *out = s;
  return NH_OK;
}

void nh_scene_destroy(nh_scene **scene) {
  if (!scene || !*scene) return;
  nh_scene *s = *scene;
  for (int i = 0; i < s->tissue.n_loads; ++i) {
    free(s->tissue.loads[i].schedule.t);
    free(s->tissue.loads[i].schedule.value);
  }
  free(s->tissue.loads);
  for (int i = 0; i < s->tissue.n_tractions; ++i) {
    free(s->tissue.tractions[i].schedule.t);
    free(s->tissue.tractions[i].schedule.value);
  }
  free(s->tissue.tractions);
  for (int i = 0; s->tissue.fix && i < s->tissue.n_fixed; ++i) {
    free(s->tissue.fix[i].schedule.t);
    free(s->tissue.fix[i].schedule.value);
  }
  free(s->tissue.fix);
  free(s->tissue.fixed);
  free(s->tissue.mask_labels);
  free(s->tissue.materials);
  free(s->gravity_schedule.t);
  free(s->gravity_schedule.value);
  free(s->tissue.buoyancy_schedule.t);
  free(s->tissue.buoyancy_schedule.value);
  free(s->probes);
  for (int i = 0; i < s->n_tools; ++i) free(s->tools[i].motion);
  free(s->tools);
  free(s->targets);
  free(s->yaml);
  free(s);
  *scene = NULL;
}
