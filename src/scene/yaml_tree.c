/* yaml_tree.c — YAML text to a small tree and back, with overrides.
 *
 * Parsing uses libyaml's event API (not its document API) so that every node
 * can be checked while its dotted path is known: a recursive descent over the
 * events builds mapping / sequence / scalar nodes and records each node's
 * 1-based line (start_mark.line + 1). The dotted path ("tissue.fixed.0.box")
 * is carried down the recursion only to make messages precise.
 *
 * What is refused, and why:
 *  - anchors and aliases: a scene is short, and an alias would make one
 *    node appear under two keys, which breaks "one node, one line, one key"
 *    messages and the YAML written back;
 *  - explicit tags (!!str, !foo): the schema decides every type;
 *  - keys that are not scalars, duplicate keys (libyaml accepts them; the
 *    last would silently win), and a second document in the stream;
 *  - nesting deeper than NH_YAML_DEPTH (the recursion must stay bounded).
 * Scalars keep whether they were quoted (or block scalars), so that '1' stays
 * a string when the tree is written back and a quoted "1e6" is not a number.
 *
 * Malformed YAML is reported with libyaml's own problem text and the line of
 * its problem mark; reader errors (bad UTF-8, control characters) carry only a
 * byte offset, which is turned into a line by counting newlines in the buffer.
 *
 * An override "a.b.2.c=VALUE" parses VALUE as its own one-document YAML
 * stream (source = override index, line = 0) and grafts it into the tree:
 * missing mapping keys are created (with empty mappings in between), list
 * items are addressed by index and never created. A missing key followed by an
 * index, e.g. "tissue.fixed.0.box=..." without tissue.fixed, is reported as an
 * index beyond a list of 0 rather than creating a mapping named "0".
 *
 * Writing back uses libyaml's emitter into a growing buffer: sequences of
 * scalars in flow style ([0, 0, 1]), everything else in block style. Comments
 * are not kept (libyaml does not report them). */
#include "scene/yaml_tree.h"

#include "core/core.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <yaml.h>

#define NH_YAML_DEPTH    64
#define NH_YAML_FILE_MAX (64L * 1024 * 1024)
#define NH_YAML_KEYBUF   512

/* Where a parse happens, for messages. */
typedef struct {
  yaml_parser_t parser;
  const char *file;          /* the scene file (source 0) */
  int source;                /* 0 or the override index */
  const char *override_text; /* the override (source > 0) */
  const char *override_key;  /* the override's path, for messages about its value */
  const char *root_path;     /* dotted key of the document's root ("" for a file) */
  const unsigned char *buf;  /* the input, to turn a byte offset into a line */
  size_t len;
} nh_reader;

/* Record an input error located at `line` of the reader's source; `fmt`
 * starts with the dotted key when there is one. */
static int reader_fail(const nh_reader *r, int line, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));
static int reader_fail(const nh_reader *r, int line, const char *fmt, ...) {
  char msg[1024], text[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  if (r->source > 0) {
    nh_yaml_one_line(text, sizeof text, r->override_text);
    return NH_ERROR(NH_ERR_INPUT, "--set:%d: %s (--set %s)", r->source, msg, text);
  }
  return NH_ERROR(NH_ERR_INPUT, "%s:%d: %s", r->file, line, msg);
}

/* Record an override error about `path` (not about its value). */
static int override_fail(int index, const char *text, const char *path, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));
static int override_fail(int index, const char *text, const char *path, const char *fmt, ...) {
  char msg[1024], one_line[512];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(msg, sizeof msg, fmt, ap);
  va_end(ap);
  nh_yaml_one_line(one_line, sizeof one_line, text);
  return NH_ERROR(NH_ERR_INPUT, "--set:%d: %s: %s (--set %s)", index, path, msg, one_line);
}

void nh_yaml_join(char *buf, size_t cap, const char *a, const char *sep, const char *b) {
  size_t n = 0;
  const char *parts[3] = {a, sep, b};
  if (cap == 0) return;
  for (int i = 0; i < 3; ++i)
    for (const char *p = parts[i]; *p && n + 1 < cap; ++p) buf[n++] = *p;
  buf[n] = '\0';
}

void nh_yaml_one_line(char *buf, size_t cap, const char *text) {
  size_t n = 0;
  if (cap == 0) return;
  for (const char *p = text; *p && n + 1 < cap; ++p)
    buf[n++] = (unsigned char)*p < 0x20 || *p == 0x7f ? '?' : *p;
  buf[n] = '\0';
}

/* "parent.key" (or "key" at the top) into buf. */
static void join_path(char *buf, size_t cap, const char *parent, const char *key) {
  nh_yaml_join(buf, cap, parent, parent[0] ? "." : "", key);
}

static nh_yaml_node *node_new(nh_yaml_kind kind, int line, int source) {
  nh_yaml_node *n = nh_calloc(1, sizeof *n);
  if (!n) return NULL;
  n->kind = kind;
  n->line = line;
  n->source = source;
  return n;
}

static nh_yaml_node *scalar_new(const char *text, size_t len, int quoted, int line, int source) {
  nh_yaml_node *n = node_new(NH_YAML_SCALAR, line, source);
  if (!n) return NULL;
  n->text = nh_calloc(len + 1, 1);
  if (!n->text) {
    free(n);
    return NULL;
  }
  memcpy(n->text, text, len);
  n->quoted = quoted;
  return n;
}

/* Append (key, value) to a mapping or value to a sequence (key NULL); on
 * failure the caller still owns key and value. */
static int node_append(nh_yaml_node *parent, nh_yaml_node *key, nh_yaml_node *value) {
  int cap = parent->cap;
  NH_TRY(nh_grow((void **)&parent->items, &cap, parent->n + 1, sizeof *parent->items));
  if (parent->kind == NH_YAML_MAP) {
    int kcap = parent->cap;
    NH_TRY(nh_grow((void **)&parent->keys, &kcap, parent->n + 1, sizeof *parent->keys));
  }
  parent->cap = cap;
  if (parent->kind == NH_YAML_MAP) parent->keys[parent->n] = key;
  parent->items[parent->n++] = value;
  return NH_OK;
}

void nh_yaml_free(nh_yaml_node **node) {
  if (!node || !*node) return;
  nh_yaml_node *n = *node;
  for (int i = 0; i < n->n; ++i) {
    if (n->keys) nh_yaml_free(&n->keys[i]);
    nh_yaml_free(&n->items[i]);
  }
  free(n->keys);
  free(n->items);
  free(n->text);
  free(n);
  *node = NULL;
}

const nh_yaml_node *nh_yaml_get(const nh_yaml_node *map, const char *key,
                                const nh_yaml_node **key_node) {
  if (key_node) *key_node = NULL;
  if (!map || map->kind != NH_YAML_MAP) return NULL;
  for (int i = 0; i < map->n; ++i)
    if (strcmp(map->keys[i]->text, key) == 0) {
      if (key_node) *key_node = map->keys[i];
      return map->items[i];
    }
  return NULL;
}

int nh_yaml_is_null(const nh_yaml_node *node) {
  if (!node || node->kind != NH_YAML_SCALAR || node->quoted) return 0;
  const char *t = node->text;
  return !t[0] || !strcmp(t, "~") || !strcmp(t, "null") || !strcmp(t, "Null") || !strcmp(t, "NULL");
}

/* ---- parsing ---- */

/* 1-based line of byte `offset` of the input. */
static int line_of_offset(const nh_reader *r, size_t offset) {
  int line = 1;
  for (size_t i = 0; i < offset && i < r->len; ++i)
    if (r->buf[i] == '\n') ++line;
  return line;
}

/* The next event, or an error with libyaml's problem text. */
static int next_event(nh_reader *r, yaml_event_t *ev) {
  if (yaml_parser_parse(&r->parser, ev)) return NH_OK;
  const yaml_parser_t *p = &r->parser;
  const char *problem = p->problem ? p->problem : "unknown problem";
  if (p->error == YAML_MEMORY_ERROR)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory while parsing YAML");
  if (p->error == YAML_READER_ERROR)
    return reader_fail(r, line_of_offset(r, p->problem_offset), "%s%smalformed YAML: %s (byte %zu)",
                       r->source > 0 ? r->override_key : "", r->source > 0 ? ": " : "", problem,
                       p->problem_offset);
  int line = (int)p->problem_mark.line + 1;
  /* In an override the key stands in for the position; lines mean nothing. */
  const char *key = r->source > 0 ? r->override_key : "";
  const char *colon = r->source > 0 ? ": " : "";
  if (p->context && r->source > 0)
    return reader_fail(r, line, "%s%smalformed YAML: %s (%s)", key, colon, problem, p->context);
  if (p->context)
    return reader_fail(r, line, "%s%smalformed YAML: %s (%s at line %d)", key, colon, problem,
                       p->context, (int)p->context_mark.line + 1);
  return reader_fail(r, line, "%s%smalformed YAML: %s", key, colon, problem);
}

/* Refuse anchors and explicit tags on a node event. */
static int check_plain_node(nh_reader *r, const char *path, int line, const yaml_char_t *anchor,
                            const yaml_char_t *tag) {
  const char *where = path[0] ? path : "top level";
  if (anchor)
    return reader_fail(r, line, "%s: anchors (&%s) and aliases are not supported in a scene", where,
                       (const char *)anchor);
  if (tag)
    return reader_fail(r, line, "%s: tags (%s) are not supported in a scene", where,
                       (const char *)tag);
  return NH_OK;
}

static int parse_node(nh_reader *r, yaml_event_t *ev, const char *path, int depth,
                      nh_yaml_node **out);

/* Parse the items of a sequence whose start event was just read. */
static int parse_sequence(nh_reader *r, nh_yaml_node *seq, const char *path, int depth) {
  for (;;) {
    yaml_event_t ev;
    NH_TRY(next_event(r, &ev));
    if (ev.type == YAML_SEQUENCE_END_EVENT) {
      yaml_event_delete(&ev);
      return NH_OK;
    }
    char child_path[NH_YAML_KEYBUF], index[16];
    snprintf(index, sizeof index, "%d", seq->n);
    join_path(child_path, sizeof child_path, path, index);
    nh_yaml_node *item = NULL;
    NH_TRY(parse_node(r, &ev, child_path, depth + 1, &item));
    int rc = node_append(seq, NULL, item);
    if (rc) {
      nh_yaml_free(&item);
      return rc;
    }
  }
}

/* Parse the pairs of a mapping whose start event was just read. */
static int parse_mapping(nh_reader *r, nh_yaml_node *map, const char *path, int depth) {
  for (;;) {
    yaml_event_t ev;
    NH_TRY(next_event(r, &ev));
    if (ev.type == YAML_MAPPING_END_EVENT) {
      yaml_event_delete(&ev);
      return NH_OK;
    }
    int line = (int)ev.start_mark.line + 1;
    if (ev.type != YAML_SCALAR_EVENT) {
      yaml_event_delete(&ev);
      return reader_fail(r, line, "%s: keys must be plain names, not lists or mappings",
                         path[0] ? path : "top level");
    }
    int rc = check_plain_node(r, path, line, ev.data.scalar.anchor, ev.data.scalar.tag);
    if (rc) {
      yaml_event_delete(&ev);
      return rc;
    }
    nh_yaml_node *key =
        scalar_new((const char *)ev.data.scalar.value, ev.data.scalar.length,
                   ev.data.scalar.style != YAML_PLAIN_SCALAR_STYLE, line, r->source);
    int has_nul = strlen((const char *)ev.data.scalar.value) != ev.data.scalar.length;
    yaml_event_delete(&ev);
    if (!key) return NH_ERR_MEMORY;
    char child_path[NH_YAML_KEYBUF];
    join_path(child_path, sizeof child_path, path, key->text);
    if (has_nul) {
      nh_yaml_free(&key);
      return reader_fail(r, line, "%s: a key contains a NUL character", path[0] ? path : "top");
    }
    for (int i = 0; i < map->n; ++i)
      if (strcmp(map->keys[i]->text, key->text) == 0) {
        int first = map->keys[i]->line;
        nh_yaml_free(&key);
        return reader_fail(r, line, "%s: duplicate key (first given at line %d)", child_path,
                           first);
      }
    nh_yaml_node *value = NULL;
    rc = next_event(r, &ev);
    if (!rc) rc = parse_node(r, &ev, child_path, depth + 1, &value);
    if (!rc) rc = node_append(map, key, value);
    if (rc) {
      nh_yaml_free(&key);
      nh_yaml_free(&value);
      return rc;
    }
  }
}

/* Build the node that starts with event *ev (consumed, whatever happens). */
static int parse_node(nh_reader *r, yaml_event_t *ev, const char *path, int depth,
                      nh_yaml_node **out) {
  int line = (int)ev->start_mark.line + 1;
  const char *where = path[0] ? path : "top level";
  int rc = NH_OK;
  *out = NULL;
  if (depth > NH_YAML_DEPTH) {
    yaml_event_delete(ev);
    return reader_fail(r, line, "%s: nested deeper than %d levels", where, NH_YAML_DEPTH);
  }
  switch (ev->type) {
  case YAML_ALIAS_EVENT:
    rc = reader_fail(r, line, "%s: aliases (*%s) and anchors are not supported in a scene", where,
                     (const char *)ev->data.alias.anchor);
    yaml_event_delete(ev);
    return rc;
  case YAML_SCALAR_EVENT: {
    rc = check_plain_node(r, path, line, ev->data.scalar.anchor, ev->data.scalar.tag);
    if (!rc && strlen((const char *)ev->data.scalar.value) != ev->data.scalar.length)
      rc = reader_fail(r, line, "%s: a value contains a NUL character", where);
    if (!rc) {
      *out = scalar_new((const char *)ev->data.scalar.value, ev->data.scalar.length,
                        ev->data.scalar.style != YAML_PLAIN_SCALAR_STYLE, line, r->source);
      if (!*out) rc = NH_ERR_MEMORY;
    }
    yaml_event_delete(ev);
    return rc;
  }
  case YAML_SEQUENCE_START_EVENT:
  case YAML_MAPPING_START_EVENT: {
    int is_map = ev->type == YAML_MAPPING_START_EVENT;
    rc = is_map ? check_plain_node(r, path, line, ev->data.mapping_start.anchor,
                                   ev->data.mapping_start.tag)
                : check_plain_node(r, path, line, ev->data.sequence_start.anchor,
                                   ev->data.sequence_start.tag);
    yaml_event_delete(ev);
    if (rc) return rc;
    nh_yaml_node *n = node_new(is_map ? NH_YAML_MAP : NH_YAML_SEQ, line, r->source);
    if (!n) return NH_ERR_MEMORY;
    rc = is_map ? parse_mapping(r, n, path, depth) : parse_sequence(r, n, path, depth);
    if (rc) {
      nh_yaml_free(&n);
      return rc;
    }
    *out = n;
    return NH_OK;
  }
  default: {
    int type = (int)ev->type;
    yaml_event_delete(ev);
    return NH_ERROR(NH_ERR_INTERNAL, "unexpected YAML event %d", type);
  }
  }
}

/* Parse a whole stream (at most one document) from r's buffer. */
static int parse_stream(nh_reader *r, nh_yaml_node **root) {
  yaml_event_t ev;
  *root = NULL;
  NH_TRY(next_event(r, &ev)); /* stream start */
  yaml_event_delete(&ev);
  NH_TRY(next_event(r, &ev));
  if (ev.type == YAML_STREAM_END_EVENT) {
    yaml_event_delete(&ev);
    *root = scalar_new("", 0, 0, 1, r->source);
    return *root ? NH_OK : NH_ERR_MEMORY;
  }
  yaml_event_delete(&ev); /* document start */
  NH_TRY(next_event(r, &ev));
  NH_TRY(parse_node(r, &ev, r->root_path, 0, root));
  int rc = next_event(r, &ev); /* document end */
  if (!rc) {
    yaml_event_delete(&ev);
    rc = next_event(r, &ev);
  }
  if (!rc) {
    if (ev.type == YAML_DOCUMENT_START_EVENT)
      rc = reader_fail(r, (int)ev.start_mark.line + 1,
                       "%s%sa second YAML document starts here; "
                       "a scene is one document",
                       r->root_path, r->root_path[0] ? ": " : "");
    yaml_event_delete(&ev);
  }
  if (rc) nh_yaml_free(root);
  return rc;
}

int nh_yaml_parse_file(const char *path, nh_yaml_node **root) {
  *root = NULL;
  FILE *f = fopen(path, "rb");
  if (!f) return NH_ERROR(NH_ERR_INPUT, "%s: cannot open the scene: %s", path, strerror(errno));
  unsigned char *buf = NULL;
  size_t len = 0;
  int cap = 0, rc = NH_OK;
  for (;;) {
    if (len > (size_t)NH_YAML_FILE_MAX) {
      rc = NH_ERROR(NH_ERR_INPUT, "%s: larger than %ld bytes: not a scene", path, NH_YAML_FILE_MAX);
      break;
    }
    rc = nh_grow((void **)&buf, &cap, (int)len + 65536, 1);
    if (rc) break;
    size_t got = fread(buf + len, 1, (size_t)cap - len, f);
    len += got;
    if (got == 0) {
      if (ferror(f)) rc = NH_ERROR(NH_ERR_INPUT, "%s: cannot read the scene", path);
      break;
    }
  }
  fclose(f);
  if (rc) {
    free(buf);
    return rc;
  }
  nh_reader r = {.file = path, .source = 0, .root_path = "", .buf = buf, .len = len};
  if (!yaml_parser_initialize(&r.parser)) {
    free(buf);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory initialising the YAML parser");
  }
  yaml_parser_set_input_string(&r.parser, buf, len);
  rc = parse_stream(&r, root);
  yaml_parser_delete(&r.parser);
  free(buf);
  return rc;
}

/* ---- overrides ---- */

/* A 0-based list index from a path component, or -1 if it is not one. */
static int parse_index(const char *s) {
  if (!s[0] || strlen(s) > 9) return -1;
  for (const char *p = s; *p; ++p)
    if (*p < '0' || *p > '9') return -1;
  return atoi(s);
}

/* Parse an override's VALUE into a node with source `index`. */
static int parse_value(int index, const char *text, const char *key, const char *value,
                       nh_yaml_node **out) {
  nh_reader r = {.source = index, .override_text = text, .override_key = key, .root_path = key};
  r.buf = (const unsigned char *)value;
  r.len = strlen(value);
  if (!yaml_parser_initialize(&r.parser))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory initialising the YAML parser");
  yaml_parser_set_input_string(&r.parser, r.buf, r.len);
  int rc = parse_stream(&r, out);
  yaml_parser_delete(&r.parser);
  if (rc) return rc;
  /* An empty value is most likely a shell quoting slip: refuse it. */
  if ((*out)->kind == NH_YAML_SCALAR && !(*out)->quoted && !(*out)->text[0]) {
    nh_yaml_free(out);
    return override_fail(index, text, key, "missing value after '='");
  }
  (*out)->line = 0;
  return NH_OK;
}

int nh_yaml_apply_override(nh_yaml_node *root, int index, const char *text) {
  const char *eq = strchr(text, '=');
  char key[NH_YAML_KEYBUF];
  size_t klen = eq ? (size_t)(eq - text) : 0;
  while (klen > 0 && (text[klen - 1] == ' ' || text[klen - 1] == '\t')) --klen;
  char one_line[512];
  nh_yaml_one_line(one_line, sizeof one_line, text);
  if (!eq || klen == 0)
    return NH_ERROR(NH_ERR_INPUT,
                    "--set:%d: expected KEY=VALUE (e.g. tissue.grid=[16,8,8]), got '%s'", index,
                    one_line);
  if (klen >= sizeof key)
    return NH_ERROR(NH_ERR_INPUT, "--set:%d: the key of '%s' is too long", index, one_line);
  memcpy(key, text, klen);
  key[klen] = '\0';
  if (key[0] == '.' || key[klen - 1] == '.' || strstr(key, ".."))
    return override_fail(index, text, key, "empty component in the dotted key");
  if (!root || root->kind != NH_YAML_MAP)
    return override_fail(index, text, key, "the scene is not a mapping");

  nh_yaml_node *value = NULL;
  NH_TRY(parse_value(index, text, key, eq + 1, &value));

  /* Walk the path one component at a time; `done` is the path walked so far. */
  char done[NH_YAML_KEYBUF] = "", comp[NH_YAML_KEYBUF];
  nh_yaml_node *cur = root;
  const char *p = key;
  int rc = NH_OK;
  for (;;) {
    const char *dot = strchr(p, '.');
    size_t n = dot ? (size_t)(dot - p) : strlen(p);
    memcpy(comp, p, n);
    comp[n] = '\0';
    int last = dot == NULL;
    char here[NH_YAML_KEYBUF];
    join_path(here, sizeof here, done, comp);
    nh_yaml_node **slot = NULL;
    if (cur->kind == NH_YAML_MAP) {
      for (int i = 0; i < cur->n; ++i)
        if (strcmp(cur->keys[i]->text, comp) == 0) slot = &cur->items[i];
      if (!slot) {
        /* A missing key: create it, unless a list index follows. */
        if (!last) {
          const char *next_end = strchr(dot + 1, '.');
          char next[NH_YAML_KEYBUF];
          size_t m = next_end ? (size_t)(next_end - dot - 1) : strlen(dot + 1);
          memcpy(next, dot + 1, m);
          next[m] = '\0';
          int k = parse_index(next);
          if (k >= 0) {
            char there[NH_YAML_KEYBUF];
            join_path(there, sizeof there, here, next);
            rc = override_fail(index, text, there, "index %d beyond the list of 0 (%s is absent)",
                               k, here);
            break;
          }
        }
        nh_yaml_node *k = scalar_new(comp, n, 0, 0, index);
        nh_yaml_node *v = last ? value : node_new(NH_YAML_MAP, 0, index);
        if (!k || !v || (rc = node_append(cur, k, v)) != NH_OK) {
          nh_yaml_free(&k);
          if (v != value) nh_yaml_free(&v);
          if (!rc) rc = NH_ERR_MEMORY;
          break;
        }
        if (last) {
          value = NULL;
          break;
        }
        cur = v;
      } else if (last) {
        nh_yaml_free(slot);
        *slot = value;
        value = NULL;
        break;
      } else {
        /* `key:` with nothing after it is an empty mapping to fill. */
        if (nh_yaml_is_null(*slot)) {
          nh_yaml_node *m = node_new(NH_YAML_MAP, 0, index);
          if (!m) {
            rc = NH_ERR_MEMORY;
            break;
          }
          nh_yaml_free(slot);
          *slot = m;
        }
        cur = *slot;
      }
    } else if (cur->kind == NH_YAML_SEQ) {
      int k = parse_index(comp);
      if (k < 0) {
        rc = override_fail(index, text, here, "%s is a list: expected an index 0, 1, ...", done);
        break;
      }
      if (k >= cur->n) {
        rc = override_fail(index, text, here, "index %d beyond the list of %d", k, cur->n);
        break;
      }
      if (last) {
        nh_yaml_free(&cur->items[k]);
        cur->items[k] = value;
        value = NULL;
        break;
      }
      cur = cur->items[k];
    } else {
      rc = override_fail(index, text, here, "%s is a single value, not a mapping or a list", done);
      break;
    }
    snprintf(done, sizeof done, "%s", here);
    p = dot + 1;
  }
  nh_yaml_free(&value);
  return rc;
}

/* ---- emitting ---- */

typedef struct {
  char *buf;
  size_t len, cap;
  int failed;
} nh_outbuf;

static int write_handler(void *data, unsigned char *bytes, size_t size) {
  nh_outbuf *o = data;
  if (o->len + size + 1 > o->cap) {
    size_t cap = o->cap ? o->cap : 4096;
    while (cap < o->len + size + 1) cap *= 2;
    if (nh_realloc((void **)&o->buf, cap, 1)) {
      o->failed = 1;
      return 0;
    }
    o->cap = cap;
  }
  memcpy(o->buf + o->len, bytes, size);
  o->len += size;
  o->buf[o->len] = '\0';
  return 1;
}

/* Emit one event; libyaml takes ownership of its contents. */
static int emit(yaml_emitter_t *e, yaml_event_t *ev) {
  if (yaml_emitter_emit(e, ev)) return NH_OK;
  return NH_ERROR(e->error == YAML_MEMORY_ERROR ? NH_ERR_MEMORY : NH_ERR_INTERNAL,
                  "writing YAML: %s", e->problem ? e->problem : "emitter error");
}

static int emit_node(yaml_emitter_t *e, const nh_yaml_node *n) {
  yaml_event_t ev;
  if (n->kind == NH_YAML_SCALAR) {
    /* A null is written as "null" so that it stays a null inside flow lists. */
    const char *text = nh_yaml_is_null(n) ? "null" : n->text;
    if (!yaml_scalar_event_initialize(&ev, NULL, NULL, (yaml_char_t *)text, (int)strlen(text),
                                      !n->quoted, 1, YAML_ANY_SCALAR_STYLE))
      return NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
    return emit(e, &ev);
  }
  int is_map = n->kind == NH_YAML_MAP;
  int flow = !is_map;
  for (int i = 0; i < n->n; ++i)
    if (n->items[i]->kind != NH_YAML_SCALAR) flow = 0;
  int ok =
      is_map ? yaml_mapping_start_event_initialize(&ev, NULL, NULL, 1, YAML_BLOCK_MAPPING_STYLE)
             : yaml_sequence_start_event_initialize(
                   &ev, NULL, NULL, 1, flow ? YAML_FLOW_SEQUENCE_STYLE : YAML_BLOCK_SEQUENCE_STYLE);
  if (!ok) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  NH_TRY(emit(e, &ev));
  for (int i = 0; i < n->n; ++i) {
    if (is_map) NH_TRY(emit_node(e, n->keys[i]));
    NH_TRY(emit_node(e, n->items[i]));
  }
  ok = is_map ? yaml_mapping_end_event_initialize(&ev) : yaml_sequence_end_event_initialize(&ev);
  if (!ok) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  return emit(e, &ev);
}

int nh_yaml_emit(const nh_yaml_node *root, char **text) {
  *text = NULL;
  yaml_emitter_t e;
  nh_outbuf o = {0};
  if (!yaml_emitter_initialize(&e)) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  yaml_emitter_set_output(&e, write_handler, &o);
  yaml_emitter_set_unicode(&e, 1);
  yaml_emitter_set_width(&e, -1);
  yaml_emitter_set_indent(&e, 2);
  yaml_event_t ev;
  int rc = NH_OK;
  if (!yaml_stream_start_event_initialize(&ev, YAML_UTF8_ENCODING))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  if (!rc) rc = emit(&e, &ev);
  if (!rc && !yaml_document_start_event_initialize(&ev, NULL, NULL, NULL, 1))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  if (!rc) rc = emit(&e, &ev);
  if (!rc) rc = emit_node(&e, root);
  if (!rc && !yaml_document_end_event_initialize(&ev, 1))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  if (!rc) rc = emit(&e, &ev);
  if (!rc && !yaml_stream_end_event_initialize(&ev))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  if (!rc) rc = emit(&e, &ev);
  if (!rc && !yaml_emitter_flush(&e)) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  yaml_emitter_delete(&e);
  if (!rc && o.failed) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory writing YAML");
  if (rc) {
    free(o.buf);
    return rc;
  }
  *text = o.buf;
  return NH_OK;
}
