/* yaml_tree — a small YAML document tree (module-private to scene).
 *
 * A scene file is parsed with libyaml into nodes that are a mapping, a
 * sequence or a scalar, each remembering where it came from: the 1-based line
 * in the scene file, or the 1-based index of the `--set` override that put it
 * there. The section readers (scene_impl.h) walk this tree to fill nh_scene
 * and report errors as "FILE:LINE: KEY: ..." or "--set:K: KEY: ...". The
 * tree can be written back as YAML text (the scene as run).
 *
 * Errors are NH_ERR_INPUT with one message (or NH_ERR_MEMORY). */
#ifndef NH_YAML_TREE_H
#define NH_YAML_TREE_H

#include <stddef.h>

typedef enum { NH_YAML_MAP = 0, NH_YAML_SEQ = 1, NH_YAML_SCALAR = 2 } nh_yaml_kind;

typedef struct nh_yaml_node nh_yaml_node;
struct nh_yaml_node {
  nh_yaml_kind kind;
  int line;             /* 1-based line in the scene file (0 for a node from an override) */
  int source;           /* 0: the scene file; K >= 1: the K-th --set override */
  char *text;           /* scalar: its text, NUL-terminated (NULL for a map or a sequence) */
  int quoted;           /* scalar: written quoted or as a block scalar, so a string */
  int n, cap;           /* map: number of pairs; sequence: number of items */
  nh_yaml_node **keys;  /* map: n key scalars */
  nh_yaml_node **items; /* map: n values (items[i] belongs to keys[i]); sequence: n items */
};

/* Parse the YAML file `path` into a tree. An empty file gives a null scalar.
 * Output: *root, to be freed with nh_yaml_free.
 * Fails with NH_ERR_INPUT on an unreadable file, malformed YAML (libyaml's
 * problem with FILE:LINE), anchors, aliases, tags, non-scalar keys, duplicate
 * keys or more than one document; NH_ERR_MEMORY on allocation failure. */
int nh_yaml_parse_file(const char *path, nh_yaml_node **root);

/* Apply the override `text` ("dotted.path=VALUE"), the `index`-th (1-based)
 * of the command line, to the mapping `root`. VALUE is parsed as YAML (a flow
 * scalar or a list such as [16,8,8]). Mapping keys are found by name and
 * created when missing (the schema decides later whether they exist);
 * sequence items are found by a 0-based index, and an index beyond the list is
 * an error. Nodes created carry source = index.
 * Fails with NH_ERR_INPUT ("--set:K: PATH: reason (--set TEXT)") or
 * NH_ERR_MEMORY. */
int nh_yaml_apply_override(nh_yaml_node *root, int index, const char *text);

/* Write the tree as YAML text: lists of scalars in flow style, everything else
 * in block style; quoted scalars stay quoted.
 * Output: *text (NUL-terminated, free with free()). Fails with NH_ERR_MEMORY
 * or NH_ERR_INTERNAL (libyaml refused the event stream). */
int nh_yaml_emit(const nh_yaml_node *root, char **text);

/* Free a tree and set *node = NULL (accepts NULL). */
void nh_yaml_free(nh_yaml_node **node);

/* The value of `key` in the mapping `map`, or NULL when map is NULL or not a
 * mapping or has no such key. If key_node is not NULL it receives the key. */
const nh_yaml_node *nh_yaml_get(const nh_yaml_node *map, const char *key,
                                const nh_yaml_node **key_node);

/* True for a plain scalar that YAML reads as null: "", "~", "null", "Null",
 * "NULL". */
int nh_yaml_is_null(const nh_yaml_node *node);

/* buf = a sep b, cut to fit `cap` bytes (always NUL-terminated). */
void nh_yaml_join(char *buf, size_t cap, const char *a, const char *sep, const char *b);

/* A copy of `text` with control characters replaced by '?', cut to fit
 * `cap` bytes: messages stay on one line. */
void nh_yaml_one_line(char *buf, size_t cap, const char *text);

#endif
