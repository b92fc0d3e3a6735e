/* scene_impl.h — the scene reader's shared parts (module-private to scene):
 * the context of one load, the typed readers behind every FILE:LINE: KEY
 * message, and the key tables that drive the section readers.
 *
 * A section is read by a table of rows, one per key, in the order the keys
 * are read (which is the order their errors are reported in). A row binds
 * the key to a field of the struct the table fills (by offsetof), with its
 * type, default and bound, so a new scalar key is one row and one field:
 *
 *     static const nh_key solver_rows[] = {
 *         {NH_NUMBER("tolerance", offsetof(nh_scene, solver.tolerance), 1e-8, NH_ABOVE, 0)},
 *         ...
 *         {0},
 *     };
 *
 * nh_read_table refuses the keys of a mapping that no row names (and,
 * through nh_scene_keys_check, a row that docs/scene.md does not document),
 * then reads the rows in order. Keys with structure (regions, motion lists,
 * symbolic times, a domain that is exactly one of four shapes) and cross-checks
 * between keys are the rows' hooks: `read` replaces the typed reading (of
 * a mapping: runs when it is given, before its rows), `check` runs after
 * it, both at the key's place in the order. The table's order is also the
 * order in which "did you mean" looks for the nearest key. */
#ifndef NH_SCENE_IMPL_H
#define NH_SCENE_IMPL_H

#include "anatomy/anatomy.h"
#include "scene/scene.h"
#include "scene/yaml_tree.h"

#include <stddef.h>

#define NH_KEY_MAX 256 /* a dotted key, "tools.3.interaction.friction" */

/* What one load knows: for messages (file, overrides) and for the keys
 * that depend on others. */
typedef struct {
  const char *file;
  const char *const *overrides;
  int n_overrides;
  const char *image; /* the scene's label image (mask or tissue.labels) once read, else NULL */
  const nh_yaml_node *root; /* the scene's tree, overrides applied */
  nh_scene *scene;          /* the scene being read (sections read so far) */
  int item;                 /* the index of the list item being read (tools, probes, targets) */
} nh_ctx;

/* ---- messages and paths (read.c) ---- */

/* Record the one input error of this load, "FILE:LINE: KEY: reason" (or
 * "--set:K: KEY: reason (--set TEXT)") at node `at` (the top of the file when
 * NULL); returns NH_ERR_INPUT. */
int nh_read_fail(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
/* "FILE:LINE: KEY" of node `at` into where[NH_WHERE_MAX]. */
void nh_read_where(const nh_ctx *c, const nh_yaml_node *at, const char *key, char *where);
/* "parent.key" (or "key" at the top) into buf[NH_KEY_MAX]; returns buf. */
const char *nh_read_join(char *buf, const char *parent, const char *key);
/* "parent.i" into buf[NH_KEY_MAX]; returns buf. */
const char *nh_read_index(char *buf, const char *parent, int i);
/* A short, one-line rendering of a node for messages: 'text', a list, a mapping, nothing. */
const char *nh_read_describe(const nh_yaml_node *n, char *buf, size_t cap);
/* Refuse the keys of `map` not in `names` (NULL-terminated), with a "did you
 * mean" hint for a near miss; every name must be documented (keys.c). */
int nh_read_keys(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                 const char *const *names);

/* ---- values (read.c): `key` names the node in messages ---- */

int nh_read_number(const nh_ctx *c, const nh_yaml_node *n, const char *key, double *out);
int nh_read_int(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out);
/* An integer label of an image: >= 0 (mask labels, {label: N} regions). */
int nh_read_label(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out);
int nh_read_bool(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out);
int nh_read_string(const nh_ctx *c, const nh_yaml_node *n, const char *key, char *out, size_t cap);
int nh_read_vec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, double out[3]);
int nh_read_ivec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, int out[3]);
/* One of the words `choices` (NULL-terminated); *out = its index. */
int nh_read_choice(const nh_ctx *c, const nh_yaml_node *n, const char *key,
                   const char *const *choices, int *out);
/* [[t0, s0], [t1, s1], ...] with strictly increasing times (null: none). */
int nh_read_schedule(const nh_ctx *c, const nh_yaml_node *n, const char *key, nh_schedule *s);
/* A point (points.c): [x, y, z] in metres, or {voxel: [i, j, k], image: FILE}, the
 * world position of that voxel's centre (image: default the scene's label image). */
int nh_read_point(const nh_ctx *c, const nh_yaml_node *n, const char *key, double out[3]);

/* ---- keys of a mapping (read.c): `path` is the mapping's dotted key ---- */

/* The value of `name` in `map` (NULL if absent or map is NULL); a required key
 * that is absent is an error at the line of `map`. */
int nh_read_field(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                  int required, const nh_yaml_node **out);
/* A mapping: NULL when absent or null; an error if it is something else (or
 * absent while required). */
int nh_read_section(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                    int required, const nh_yaml_node **out);
/* A list: NULL when absent or null; an error if it is something else. */
int nh_read_list(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                 const nh_yaml_node **out);
/* Refuse v below (or at, if strict) bound, at node `at` (nothing if NULL). */
int nh_read_at_least(const nh_ctx *c, const nh_yaml_node *at, const char *path, const char *name,
                     double v, double bound, int strict);

/* ---- files (read.c) ---- */

/* `value`, a path relative to the scene file's folder unless absolute, into
 * out; snprintf's count. */
int nh_read_relative(const nh_ctx *c, const char *value, char out[NH_PATH_MAX]);
/* The header of the NIfTI file `path` named at `at` (key `key`); an error there. */
int nh_read_image_header(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *path,
                         nh_image **out);

/* ---- key tables (read.c) ---- */

typedef enum {
  NH_KEY_NUMBER,   /* double */
  NH_KEY_INT,      /* int */
  NH_KEY_BOOL,     /* int: 0 or 1 */
  NH_KEY_CHOICE,   /* int (an enum): the index of the word in `choices` */
  NH_KEY_VEC3,     /* double[3] (default 0) */
  NH_KEY_STRING,   /* char[size] (default: set by the section) */
  NH_KEY_SCHEDULE, /* nh_schedule (default: none) */
  NH_KEY_POINT,    /* double[3]: a point, nh_read_point */
  NH_KEY_MAP,      /* a mapping: the rows `rows` fill the same struct */
  NH_KEY_CUSTOM    /* read by `read`; without one, read by another row's hook */
} nh_key_type;

typedef enum {
  NH_ANY = 0,  /* no bound */
  NH_AT_LEAST, /* value >= min: "must be at least MIN, got V" */
  NH_ABOVE     /* value > min: "must be greater than MIN, got V" */
} nh_bound;

typedef struct nh_key nh_key;

/* Where a row's hook is called: the row, the mapping that holds its key
 * (NULL for a null section), the mapping's dotted path, the key's (path.name)
 * and its value (NULL when absent). */
typedef struct {
  const nh_key *row;
  const nh_yaml_node *map;
  const char *path;
  const char *key;
  const nh_yaml_node *at;
} nh_key_site;

/* A row's hook; `base` is the struct the table fills. */
typedef int (*nh_key_hook)(const nh_ctx *c, const nh_key_site *k, void *base);

struct nh_key {
  const char *name;           /* the key (one path component); NULL ends a table */
  nh_key_type type;           /* how its value is read */
  size_t offset;              /* offsetof its field in the struct the table fills */
  double def;                 /* default: number, int, bool, choice index */
  nh_bound bound;             /* number, int: the bound on the value */
  double min;                 /* ... and its value */
  int required;               /* absent: "required key missing" at the mapping */
  const char *const *choices; /* NH_KEY_CHOICE: the words, NULL-terminated */
  size_t size;                /* NH_KEY_STRING: the field's capacity */
  const nh_key *rows;         /* NH_KEY_MAP: the mapping's table */
  nh_key_hook read;           /* called instead of the typed reading, absent or not;
                                 NH_KEY_MAP: called when it is given, before its rows */
  nh_key_hook check;          /* called after the value is read, when the key is given */
};

/* A row's first fields, by type (then, as needed, .required = 1, .check,
 * .read): the key, its field (offsetof), default and bound. A table ends
 * with {NULL}. */
#define NH_ROW(key, type_, field) .name = (key), .type = (type_), .offset = (field)
#define NH_NUMBER(key, field, def_, bound_, min_)                                                  \
  NH_ROW(key, NH_KEY_NUMBER, field), .def = (def_), .bound = (bound_), .min = (min_)
#define NH_INT(key, field, def_, bound_, min_)                                                     \
  NH_ROW(key, NH_KEY_INT, field), .def = (def_), .bound = (bound_), .min = (min_)
#define NH_BOOL(key, field, def_) NH_ROW(key, NH_KEY_BOOL, field), .def = (def_)
#define NH_CHOICE(key, field, def_, words)                                                         \
  NH_ROW(key, NH_KEY_CHOICE, field), .def = (def_), .choices = (words)
#define NH_VEC3(key, field)          NH_ROW(key, NH_KEY_VEC3, field)
#define NH_STRING(key, field, size_) NH_ROW(key, NH_KEY_STRING, field), .size = (size_)
#define NH_SCHEDULE(key, field)      NH_ROW(key, NH_KEY_SCHEDULE, field)
#define NH_POINT(key, field)         NH_ROW(key, NH_KEY_POINT, field)
#define NH_MAP(key, rows_)           .name = (key), .type = NH_KEY_MAP, .rows = (rows_)
#define NH_CUSTOM(key, read_)        .name = (key), .type = NH_KEY_CUSTOM, .read = (read_)

/* Set the defaults of the typed rows of `rows` (recursively into maps) in base. */
void nh_read_defaults(const nh_key *rows, void *base);
/* Refuse the keys of `map` that no row of `rows` names (nh_read_keys). */
int nh_read_row_keys(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                     const nh_key *rows);
/* Read the rows of `rows`, in order, from `map` (NULL: a null section: every
 * typed row absent, hooks still called) into base. */
int nh_read_rows(const nh_ctx *c, const nh_yaml_node *map, const char *path, const nh_key *rows,
                 void *base);
/* The key `name` of `map`, of type `type` (a value: number to point) read
 * into out, without bound; left untouched when absent; *at (if not NULL) is
 * the value's node. */
int nh_read_get(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                nh_key_type type, int required, void *out, const nh_yaml_node **at);
/* nh_read_row_keys (when map is not NULL), then nh_read_rows. */
int nh_read_table(const nh_ctx *c, const nh_yaml_node *map, const char *path, const nh_key *rows,
                  void *base);

/* A `check` hook for the Poisson ratio of a material row (tissue.c): in (-1, 0.5). */
int nh_read_check_poisson(const nh_ctx *c, const nh_key_site *k, void *base);

/* The top-level section `name` (a mapping, optional unless `required`):
 * the defaults of `rows`, then, if it is given, its table. */
int nh_read_top(const nh_ctx *c, const nh_yaml_node *root, const char *name, int required,
                const nh_key *rows, nh_scene *s);

/* ---- sections: one file each, called by read_scene (scene.c) in this order ---- */

int nh_read_time(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);           /* time.c */
int nh_read_gravity(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);        /* time.c */
int nh_read_section_limits(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s); /* solver.c */
int nh_read_tissue(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);         /* tissue.c */
int nh_read_adapt(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);          /* adapt.c */
int nh_read_solver(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);         /* solver.c */
int nh_read_tools(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);          /* tools.c */
int nh_read_solver_newton(const nh_ctx *c, const nh_yaml_node *root,
                          const nh_scene *s);                                /* solver.c */
int nh_read_probes(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);  /* points.c */
int nh_read_targets(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s); /* points.c */
/* adapt.goal, once probes and targets are read (adapt.c). */
int nh_read_adapt_goal(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);
/* Trajectories, release: target and symbolic untils, once targets are read (trajectory.c). */
int nh_read_plans(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);
int nh_read_output(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s); /* solver.c */

/* {min: [3], max: [3]} at `box` with max > min (strict) or max >= min in
 * every component (regions.c). */
int nh_read_box(const nh_ctx *c, const nh_yaml_node *box, const char *path, int strict,
                double min[3], double max[3]);
/* tissue.fixed, tissue.loads, tissue.tractions: lists of regions (regions.c), rows of
 * tissue's table. */
int nh_read_fixed(const nh_ctx *c, const nh_key_site *k, void *scene);
int nh_read_loads(const nh_ctx *c, const nh_key_site *k, void *scene);
int nh_read_tractions(const nh_ctx *c, const nh_key_site *k, void *scene);
/* plan: obstacles (regions), clearance, curvature (regions.c), after tissue. */
int nh_read_plan(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s);

#endif
