/* read.c — the scene reader's typed values, messages and key tables, shared
 * by the section readers (time.c, tissue.c, regions.c, adapt.c, solver.c,
 * tools.c, points.c, trajectory.c; scene_impl.h says how a table reads).
 *
 * Messages. Every error is one NH_ERR_INPUT message
 *     FILE:LINE: KEY: reason          (a value from the file)
 *     --set:K: KEY: reason (--set T)  (a value from the K-th override, text T)
 * where LINE is the line of the offending value, of the unknown key, or — for a
 * missing required key — of the mapping that lacks it. Every mapping's keys
 * are checked before its values, so a misspelt key is reported as unknown
 * (with a "did you mean" hint for a near miss) rather than as a missing one.
 *
 * Types. A number is a plain scalar that strtod consumes entirely and that is
 * finite; an integer is a number that is integral and fits in an int (8.0 is
 * accepted); a bool is true/false; a quoted scalar is always a string, so
 * young: "1e6" is refused. A YAML null (`key:` with nothing after it) is an
 * empty section for mappings and lists and an error for values. */
#include "scene/scene_impl.h"

#include <limits.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The most rows of one table. */
#define NH_ROWS_MAX 32

/* "FILE:LINE" or "--set:K" of a node (the top of the file when NULL). */
static void location(const nh_ctx *c, const nh_yaml_node *at, char *buf, size_t cap) {
  if (at && at->source > 0)
    snprintf(buf, cap, "--set:%d", at->source);
  else
    snprintf(buf, cap, "%s:%d", c->file, at && at->line > 0 ? at->line : 1);
}

int nh_read_fail(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *fmt, ...) {
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

void nh_read_where(const nh_ctx *c, const nh_yaml_node *at, const char *key, char *where) {
  char loc[NH_PATH_MAX + 32];
  location(c, at, loc, sizeof loc);
  nh_yaml_join(where, NH_WHERE_MAX, loc, ": ", key); /* a very long file name is cut */
}

const char *nh_read_join(char *buf, const char *parent, const char *key) {
  nh_yaml_join(buf, NH_KEY_MAX, parent, parent[0] ? "." : "", key);
  return buf;
}

const char *nh_read_index(char *buf, const char *parent, int i) {
  char index[16];
  snprintf(index, sizeof index, "%d", i);
  nh_yaml_join(buf, NH_KEY_MAX, parent, ".", index);
  return buf;
}

const char *nh_read_describe(const nh_yaml_node *n, char *buf, size_t cap) {
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

int nh_read_keys(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                 const char *const *names) {
  char key[NH_KEY_MAX];
  NH_TRY(nh_scene_keys_check(path, names)); /* every key it reads is documented */
  for (int i = 0; i < map->n; ++i) {
    const nh_yaml_node *k = map->keys[i];
    if (in_list(k->text, names)) continue;
    nh_read_join(key, path, k->text);
    /* The nearest name, the first of several as near (the table's order). */
    const char *best = NULL;
    int best_d = 3;
    for (const char *const *a = names; *a; ++a) {
      int d = edit_distance(k->text, *a);
      if (d < best_d) best_d = d, best = *a;
    }
    if (best) return nh_read_fail(c, k, key, "unknown key (did you mean '%s'?)", best);
    return nh_read_fail(c, k, key, "unknown key");
  }
  return NH_OK;
}

/* ---- values ---- */

int nh_read_number(const nh_ctx *c, const nh_yaml_node *n, const char *key, double *out) {
  char d[96];
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n))
    return nh_read_fail(c, n, key, "expected a number, got %s", nh_read_describe(n, d, sizeof d));
  if (n->quoted)
    return nh_read_fail(c, n, key, "expected a number, got the quoted string %s",
                        nh_read_describe(n, d, sizeof d));
  char *end = NULL;
  double v = strtod(n->text, &end);
  if (end == n->text || *end || n->text[0] == ' ' || n->text[0] == '\t')
    return nh_read_fail(c, n, key, "expected a number, got %s", nh_read_describe(n, d, sizeof d));
  if (!isfinite(v))
    return nh_read_fail(c, n, key, "expected a finite number, got %s",
                        nh_read_describe(n, d, sizeof d));
  *out = v;
  return NH_OK;
}

int nh_read_int(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out) {
  char d[96];
  double v = 0;
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n) || n->quoted)
    return nh_read_fail(c, n, key, "expected an integer, got %s", nh_read_describe(n, d, sizeof d));
  char *end = NULL;
  v = strtod(n->text, &end);
  if (end == n->text || *end || !isfinite(v) || v != floor(v))
    return nh_read_fail(c, n, key, "expected an integer, got %s", nh_read_describe(n, d, sizeof d));
  if (v > INT_MAX || v < INT_MIN)
    return nh_read_fail(c, n, key, "%s is too large for an integer",
                        nh_read_describe(n, d, sizeof d));
  *out = (int)v;
  return NH_OK;
}

int nh_read_label(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out) {
  NH_TRY(nh_read_int(c, n, key, out));
  if (*out < 0)
    return nh_read_fail(c, n, key,
                        "a label is a whole number >= 0 (as in tissue.materials), got %d", *out);
  return NH_OK;
}

int nh_read_bool(const nh_ctx *c, const nh_yaml_node *n, const char *key, int *out) {
  char d[96];
  if (n->kind == NH_YAML_SCALAR && !n->quoted) {
    const char *t = n->text;
    if (!strcmp(t, "true") || !strcmp(t, "True") || !strcmp(t, "TRUE")) return *out = 1, NH_OK;
    if (!strcmp(t, "false") || !strcmp(t, "False") || !strcmp(t, "FALSE")) return *out = 0, NH_OK;
  }
  return nh_read_fail(c, n, key, "expected true or false, got %s",
                      nh_read_describe(n, d, sizeof d));
}

int nh_read_string(const nh_ctx *c, const nh_yaml_node *n, const char *key, char *out, size_t cap) {
  char d[96];
  if (n->kind != NH_YAML_SCALAR || nh_yaml_is_null(n))
    return nh_read_fail(c, n, key, "expected a string, got %s", nh_read_describe(n, d, sizeof d));
  if (strlen(n->text) >= cap)
    return nh_read_fail(c, n, key, "%s is longer than %zu characters",
                        nh_read_describe(n, d, sizeof d), cap - 1);
  memcpy(out, n->text, strlen(n->text) + 1);
  return NH_OK;
}

/* A list of exactly 3 numbers (integers if `ints`). */
static int read_triple(const nh_ctx *c, const nh_yaml_node *n, const char *key, int ints,
                       double *out, int *iout) {
  char d[96], item[NH_KEY_MAX];
  const char *what = ints ? "integers" : "numbers";
  if (n->kind != NH_YAML_SEQ)
    return nh_read_fail(c, n, key, "expected a list of 3 %s, got %s", what,
                        nh_read_describe(n, d, sizeof d));
  if (n->n != 3)
    return nh_read_fail(c, n, key, "expected a list of 3 %s, got %d entr%s", what, n->n,
                        n->n == 1 ? "y" : "ies");
  for (int i = 0; i < 3; ++i) {
    nh_read_index(item, key, i);
    if (ints)
      NH_TRY(nh_read_int(c, n->items[i], item, &iout[i]));
    else
      NH_TRY(nh_read_number(c, n->items[i], item, &out[i]));
  }
  return NH_OK;
}

int nh_read_vec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, double out[3]) {
  return read_triple(c, n, key, 0, out, NULL);
}

int nh_read_ivec3(const nh_ctx *c, const nh_yaml_node *n, const char *key, int out[3]) {
  return read_triple(c, n, key, 1, NULL, out);
}

int nh_read_choice(const nh_ctx *c, const nh_yaml_node *n, const char *key,
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
  return nh_read_fail(c, n, key, "expected %s, got %s", expected, nh_read_describe(n, d, sizeof d));
}

int nh_read_schedule(const nh_ctx *c, const nh_yaml_node *node, const char *path, nh_schedule *s) {
  char d[96], item[NH_KEY_MAX], sub[NH_KEY_MAX];
  if (nh_yaml_is_null(node)) return NH_OK;
  if (node->kind != NH_YAML_SEQ)
    return nh_read_fail(c, node, path, "expected a list of [time, factor] pairs, got %s",
                        nh_read_describe(node, d, sizeof d));
  if (node->n == 0) return NH_OK;
  s->t = nh_calloc((size_t)node->n, sizeof *s->t);
  s->value = nh_calloc((size_t)node->n, sizeof *s->value);
  if (!s->t || !s->value) return NH_ERR_MEMORY;
  for (int i = 0; i < node->n; ++i) {
    const nh_yaml_node *p = node->items[i];
    nh_read_index(item, path, i);
    if (p->kind != NH_YAML_SEQ || p->n != 2)
      return nh_read_fail(c, p, item, "expected a pair [time, factor], got %s",
                          p->kind == NH_YAML_SEQ
                              ? (p->n == 1 ? "1 entry" : "a list of another length")
                              : nh_read_describe(p, d, sizeof d));
    NH_TRY(nh_read_number(c, p->items[0], nh_read_index(sub, item, 0), &s->t[i]));
    NH_TRY(nh_read_number(c, p->items[1], nh_read_index(sub, item, 1), &s->value[i]));
    if (i > 0 && !(s->t[i] > s->t[i - 1]))
      return nh_read_fail(c, p->items[0], nh_read_index(sub, item, 0),
                          "times must increase strictly (%g after %g)", s->t[i], s->t[i - 1]);
    s->n = i + 1;
  }
  return NH_OK;
}

/* ---- keys of a mapping ---- */

int nh_read_field(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                  int required, const nh_yaml_node **out) {
  char key[NH_KEY_MAX];
  *out = nh_yaml_get(map, name, NULL);
  if (!*out && required)
    return nh_read_fail(c, map, nh_read_join(key, path, name), "required key missing");
  return NH_OK;
}

int nh_read_section(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                    int required, const nh_yaml_node **out) {
  char key[NH_KEY_MAX], d[96];
  NH_TRY(nh_read_field(c, map, path, name, required, out));
  if (!*out) return NH_OK;
  if ((*out)->kind == NH_YAML_MAP) return NH_OK;
  if (nh_yaml_is_null(*out) && !required) {
    *out = NULL;
    return NH_OK;
  }
  return nh_read_fail(c, *out, nh_read_join(key, path, name), "expected a mapping, got %s",
                      nh_read_describe(*out, d, sizeof d));
}

int nh_read_list(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                 const nh_yaml_node **out) {
  char key[NH_KEY_MAX], d[96];
  NH_TRY(nh_read_field(c, map, path, name, 0, out));
  if (!*out || (*out)->kind == NH_YAML_SEQ) return NH_OK;
  if (nh_yaml_is_null(*out)) {
    *out = NULL;
    return NH_OK;
  }
  return nh_read_fail(c, *out, nh_read_join(key, path, name), "expected a list, got %s",
                      nh_read_describe(*out, d, sizeof d));
}

int nh_read_at_least(const nh_ctx *c, const nh_yaml_node *at, const char *path, const char *name,
                     double v, double bound, int strict) {
  char key[NH_KEY_MAX];
  if (!at) return NH_OK;
  if (strict && !(v > bound))
    return nh_read_fail(c, at, nh_read_join(key, path, name), "must be greater than %g, got %g",
                        bound, v);
  if (!strict && !(v >= bound))
    return nh_read_fail(c, at, nh_read_join(key, path, name), "must be at least %g, got %g", bound,
                        v);
  return NH_OK;
}

/* ---- files ---- */

int nh_read_relative(const nh_ctx *c, const char *value, char out[NH_PATH_MAX]) {
  const char *slash = strrchr(c->file, '/');
  if (value[0] == '/' || !slash) return snprintf(out, NH_PATH_MAX, "%s", value);
  return snprintf(out, NH_PATH_MAX, "%.*s/%s", (int)(slash - c->file), c->file, value);
}

int nh_read_image_header(const nh_ctx *c, const nh_yaml_node *at, const char *key, const char *path,
                         nh_image **out) {
  if (nh_image_read(path, 0, &c->scene->limits.read, out) == NH_OK) return NH_OK;
  char msg[1024];
  snprintf(msg, sizeof msg, "%s", nh_error_message());
  return nh_read_fail(c, at, key, "%s", msg);
}

/* ---- key tables ---- */

void nh_read_defaults(const nh_key *rows, void *base) {
  for (const nh_key *r = rows; r->name; ++r) {
    void *field = (char *)base + r->offset;
    if (r->type == NH_KEY_NUMBER)
      *(double *)field = r->def;
    else if (r->type == NH_KEY_INT || r->type == NH_KEY_BOOL || r->type == NH_KEY_CHOICE)
      *(int *)field = (int)r->def;
    else if (r->type == NH_KEY_MAP)
      nh_read_defaults(r->rows, base);
  }
}

int nh_read_row_keys(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                     const nh_key *rows) {
  const char *names[NH_ROWS_MAX + 1];
  int n = 0;
  for (const nh_key *r = rows; r->name; ++r) {
    if (n == NH_ROWS_MAX) return NH_ERROR(NH_ERR_INTERNAL, "%s: more than %d keys", path, n);
    names[n++] = r->name;
  }
  names[n] = NULL;
  return nh_read_keys(c, map, path, names);
}

/* The value k->at of row k->row into its field, bound checked. */
static int read_value(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_key *r = k->row;
  void *field = (char *)base + r->offset;
  double v = 0;
  switch (r->type) {
  case NH_KEY_NUMBER:
    NH_TRY(nh_read_number(c, k->at, k->key, field));
    v = *(double *)field;
    break;
  case NH_KEY_INT:
    NH_TRY(nh_read_int(c, k->at, k->key, field));
    v = *(int *)field;
    break;
  case NH_KEY_BOOL:
    return nh_read_bool(c, k->at, k->key, field);
  case NH_KEY_CHOICE:
    return nh_read_choice(c, k->at, k->key, r->choices, field);
  case NH_KEY_VEC3:
    return nh_read_vec3(c, k->at, k->key, field);
  case NH_KEY_STRING:
    return nh_read_string(c, k->at, k->key, field, r->size);
  case NH_KEY_SCHEDULE:
    return nh_read_schedule(c, k->at, k->key, field);
  case NH_KEY_POINT:
    return nh_read_point(c, k->at, k->key, field);
  default:
    return NH_ERROR(NH_ERR_INTERNAL, "%s: a row without a reader", k->key);
  }
  if (r->bound == NH_ANY) return NH_OK;
  return nh_read_at_least(c, k->at, k->path, r->name, v, r->min, r->bound == NH_ABOVE);
}

int nh_read_get(const nh_ctx *c, const nh_yaml_node *map, const char *path, const char *name,
                nh_key_type type, int required, void *out, const nh_yaml_node **at) {
  char key[NH_KEY_MAX];
  nh_key row = {NH_ROW(name, type, 0)};
  nh_key_site k = {&row, map, path, nh_read_join(key, path, name), NULL};
  NH_TRY(nh_read_field(c, map, path, name, required, &k.at));
  if (at) *at = k.at;
  return k.at ? read_value(c, &k, out) : NH_OK;
}

/* One row: a mapping by its table, a hook, or a typed value (then its check). */
static int read_row(const nh_ctx *c, const nh_yaml_node *map, const char *path, const nh_key *r,
                    void *base) {
  char key[NH_KEY_MAX];
  nh_key_site k = {r, map, path, nh_read_join(key, path, r->name), NULL};
  if (r->type == NH_KEY_MAP) {
    NH_TRY(nh_read_section(c, map, path, r->name, r->required, &k.at));
    if (!k.at) return NH_OK;
    if (r->read) NH_TRY(r->read(c, &k, base)); /* the mapping is given */
    NH_TRY(nh_read_table(c, k.at, key, r->rows, base));
  } else {
    NH_TRY(nh_read_field(c, map, path, r->name, r->required, &k.at));
    if (r->read) return r->read(c, &k, base);
    if (!k.at || r->type == NH_KEY_CUSTOM) return NH_OK; /* read by another row's hook */
    NH_TRY(read_value(c, &k, base));
  }
  return k.at && r->check ? r->check(c, &k, base) : NH_OK;
}

int nh_read_rows(const nh_ctx *c, const nh_yaml_node *map, const char *path, const nh_key *rows,
                 void *base) {
  for (const nh_key *r = rows; r->name; ++r) NH_TRY(read_row(c, map, path, r, base));
  return NH_OK;
}

int nh_read_table(const nh_ctx *c, const nh_yaml_node *map, const char *path, const nh_key *rows,
                  void *base) {
  if (map) NH_TRY(nh_read_row_keys(c, map, path, rows));
  return nh_read_rows(c, map, path, rows, base);
}

int nh_read_top(const nh_ctx *c, const nh_yaml_node *root, const char *name, int required,
                const nh_key *rows, nh_scene *s) {
  const nh_yaml_node *m;
  nh_read_defaults(rows, s);
  NH_TRY(nh_read_section(c, root, "", name, required, &m));
  return m ? nh_read_table(c, m, name, rows, s) : NH_OK;
}
