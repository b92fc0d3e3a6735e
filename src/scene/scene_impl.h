/* scene_impl.h — private to the scene module: the context of one load and
 * the message and key helpers that reading (scene.c) and trajectory
 * planning (plan.c) share. */
#ifndef NH_SCENE_IMPL_H
#define NH_SCENE_IMPL_H

#include "scene/scene.h"
#include "scene/yaml_tree.h"

#include <stddef.h>

#define NH_KEY_MAX 256

/* What one load knows, for messages. */
typedef struct {
  const char *file;
  const char *const *overrides;
  int n_overrides;
} nh_scene_ctx;

/* Record the one input error of this load, "LOC: KEY: reason" (LOC the
 * node's FILE:LINE or --set:K), and return NH_ERR_INPUT. */
int nh_scene_fail(const nh_scene_ctx *c, const nh_yaml_node *at, const char *key, const char *fmt,
                  ...) __attribute__((format(printf, 4, 5)));
/* "parent.key" (or "key" at the top) into buf[NH_KEY_MAX]; returns buf. */
const char *nh_scene_join(char *buf, const char *parent, const char *key);
/* "parent.i" into buf[NH_KEY_MAX]; returns buf. */
const char *nh_scene_join_index(char *buf, const char *parent, int i);
/* A short, one-line rendering of a node for messages: 'text', a list, ... */
const char *nh_scene_describe(const nh_yaml_node *n, char *buf, size_t cap);
/* The value of key `name` of `map` (*out NULL if absent); a missing
 * required key fails at the mapping's line. */
int nh_scene_field(const nh_scene_ctx *c, const nh_yaml_node *map, const char *path,
                   const char *name, int required, const nh_yaml_node **out);
/* A scalar as a string of at most cap - 1 bytes; fails for a non-scalar,
 * null or too long value. */
int nh_scene_as_string(const nh_scene_ctx *c, const nh_yaml_node *n, const char *key, char *out,
                       size_t cap);

/* Trajectories, release: target and symbolic untils, tool by tool (a host
 * before the tools inside it), after tools and targets are read (plan.c). */
int nh_scene_plan(const nh_scene_ctx *c, const nh_yaml_node *root, nh_scene *s);

#endif
