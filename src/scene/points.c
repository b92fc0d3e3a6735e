/* points.c — material points of the tissue: probes (a displacement
 * recorded) and targets (the distance to a tool's tip recorded), and how a
 * point is given: [x, y, z] in metres, the centre of a voxel of an image, or
 * a control point of a 3D Slicer markups file (also a trajectory's entry
 * and aim). Names go into probes.csv or targets.csv and
 * the VTU point data, so each is one plain CSV field. */
#include "scene/scene_impl.h"

#include <stdio.h>
#include <string.h>

/* {markups: FILE, label: NAME}: the control point NAME of a 3D Slicer
 * markups file (anatomy/markups.c: RAS or LPS, mm or um, into the scene
 * frame); its errors are the file's, at the key's line. */
static int read_markups_point(const nh_ctx *c, const nh_yaml_node *n, const char *key,
                              double out[3]) {
  static const char *const keys[] = {"markups", "label", NULL};
  char sub[NH_KEY_MAX], file[NH_PATH_MAX], value[NH_PATH_MAX], label[NH_NAME_MAX];
  const nh_yaml_node *at_file, *at_label;
  NH_TRY(nh_read_keys(c, n, key, keys));
  NH_TRY(nh_read_field(c, n, key, "markups", 1, &at_file));
  NH_TRY(nh_read_string(c, at_file, nh_read_join(sub, key, "markups"), value, sizeof value));
  int len = nh_read_relative(c, value, file);
  if (len < 0 || len >= NH_PATH_MAX)
    return nh_read_fail(c, at_file, sub, "the path is longer than %d characters", NH_PATH_MAX - 1);
  NH_TRY(nh_read_field(c, n, key, "label", 1, &at_label));
  NH_TRY(nh_read_string(c, at_label, nh_read_join(sub, key, "label"), label, sizeof label));
  if (nh_markups_find_point(file, label, out) == NH_OK) return NH_OK;
  char msg[1024];
  snprintf(msg, sizeof msg, "%s", nh_error_message());
  return nh_read_fail(c, n, key, "%s", msg);
}

int nh_read_point(const nh_ctx *c, const nh_yaml_node *n, const char *key, double out[3]) {
  static const char *const keys[] = {"voxel", "image", NULL};
  char sub[NH_KEY_MAX], file[NH_PATH_MAX], value[NH_PATH_MAX];
  const nh_yaml_node *at_voxel, *at_image;
  if (n->kind != NH_YAML_MAP) return nh_read_vec3(c, n, key, out);
  if (nh_yaml_get(n, "markups", NULL) || nh_yaml_get(n, "label", NULL))
    return read_markups_point(c, n, key, out);
  NH_TRY(nh_read_keys(c, n, key, keys));
  NH_TRY(nh_read_field(c, n, key, "voxel", 1, &at_voxel));
  int ijk[3];
  NH_TRY(nh_read_ivec3(c, at_voxel, nh_read_join(sub, key, "voxel"), ijk));
  NH_TRY(nh_read_field(c, n, key, "image", 0, &at_image));
  const nh_yaml_node *at = at_image ? at_image : at_voxel;
  if (at_image) {
    NH_TRY(nh_read_string(c, at_image, nh_read_join(sub, key, "image"), value, sizeof value));
    int len = nh_read_relative(c, value, file);
    if (len < 0 || len >= NH_PATH_MAX)
      return nh_read_fail(c, at_image, sub, "the path is longer than %d characters",
                          NH_PATH_MAX - 1);
  } else if (c->image) {
    snprintf(file, sizeof file, "%s", c->image);
  } else {
    return nh_read_fail(c, at_voxel, sub,
                        "a voxel needs an image: give %s.image, or tissue.domain.mask or "
                        "tissue.labels",
                        key);
  }
  nh_image *im;
  NH_TRY(nh_read_image_header(c, at, at_image ? sub : key, file, &im));
  for (int k = 0; k < 3; ++k)
    if (ijk[k] < 0 || ijk[k] >= im->n[k]) {
      int nk = im->n[k];
      nh_image_release(&im);
      return nh_read_fail(c, at_voxel, nh_read_join(sub, key, "voxel"),
                          "index %d along %c is outside the image %s (0 .. %d)", ijk[k], "ijk"[k],
                          file, nk - 1);
    }
  double p[3] = {ijk[0], ijk[1], ijk[2]};
  nh_image_to_world(im, p, out);
  nh_image_release(&im);
  return NH_OK;
}

/* A probe or target of a mask domain must lie inside the mask's image. */
static int check_in_image(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = c->scene;
  const double *x = (const double *)((char *)base + k->row->offset);
  if (s->tissue.domain != NH_DOMAIN_MASK) return NH_OK;
  nh_image *im;
  NH_TRY(nh_read_image_header(c, k->at, k->key, s->tissue.mask_file, &im));
  int inside = nh_image_contains(im, x);
  double lo[3], hi[3];
  nh_image_extent(im, lo, hi);
  nh_image_release(&im);
  if (inside) return NH_OK;
  return nh_read_fail(c, k->at, k->key,
                      "[%g, %g, %g] m lies outside the image %s (world extent [%g, %g, %g] - [%g, "
                      "%g, %g] m)",
                      x[0], x[1], x[2], s->tissue.mask_file, lo[0], lo[1], lo[2], hi[0], hi[1],
                      hi[2]);
}

/* ITEM.name of a probe or target (required): one plain CSV field, unique in
 * its list (`names`, `stride` bytes apart, c->item of them before it). */
static int read_point_name(const nh_ctx *c, const nh_key_site *k, const char *list,
                           const char *names, size_t stride, char *name) {
  char d[96];
  NH_TRY(nh_read_string(c, k->at, k->key, name, NH_NAME_MAX));
  if (!name[0] || strpbrk(name, ",\"\n\r\t"))
    return nh_read_fail(c, k->at, k->key, "%s must be non-empty, without commas, quotes or tabs",
                        nh_read_describe(k->at, d, sizeof d));
  for (int j = 0; j < c->item; ++j)
    if (!strcmp(names + (size_t)j * stride, name))
      return nh_read_fail(c, k->at, k->key, "%s is already the name of %s.%d",
                          nh_read_describe(k->at, d, sizeof d), list, j);
  return NH_OK;
}

static int read_probe_name(const nh_ctx *c, const nh_key_site *k, void *base) {
  return read_point_name(c, k, "probes", c->scene->probes->name, sizeof(nh_probe),
                         ((nh_probe *)base)->name);
}

static int read_target_name(const nh_ctx *c, const nh_key_site *k, void *base) {
  return read_point_name(c, k, "targets", c->scene->targets->name, sizeof(nh_target),
                         ((nh_target *)base)->name);
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

/* targets.i.tool: the name of a tool (tools are read before targets). */
static int read_target_tool(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = c->scene;
  const nh_yaml_node *at = k->at;
  const char *key = k->key;
  nh_target *target = base;
  char tool[NH_NAME_MAX], names[256], d[96];
  NH_TRY(nh_read_string(c, at, key, tool, sizeof tool));
  target->tool = -1;
  for (int j = 0; j < s->n_tools && target->tool < 0; ++j)
    if (!strcmp(s->tools[j].name, tool)) target->tool = j;
  if (target->tool < 0 && s->n_tools == 0)
    return nh_read_fail(c, at, key, "no tool named %s (the scene has no tools)",
                        nh_read_describe(at, d, sizeof d));
  if (target->tool < 0)
    return nh_read_fail(c, at, key, "no tool named %s (the tools are %s)",
                        nh_read_describe(at, d, sizeof d), tool_names(s, names, sizeof names));
  return NH_OK;
}

static const nh_key probe_rows[] = {
    {NH_CUSTOM("name", read_probe_name), .required = 1},
    {NH_POINT("point", offsetof(nh_probe, point)), .required = 1, .check = check_in_image},
    {0},
};

static const nh_key target_rows[] = {
    {NH_CUSTOM("name", read_target_name), .required = 1},
    {NH_POINT("point", offsetof(nh_target, point)), .required = 1, .check = check_in_image},
    {NH_CUSTOM("tool", read_target_tool), .required = 1},
    {0},
};

/* NAME: a list of mappings (else "expected EXPECTED") read by `rows` into a
 * new array *items of `size` bytes each, whose `where` is at `where` bytes. */
static int read_points(const nh_ctx *c, const nh_yaml_node *root, const char *name,
                       const char *expected, const nh_key *rows, size_t size, size_t where,
                       void **items, int *n) {
  char path[NH_KEY_MAX], d[96];
  const nh_yaml_node *list;
  NH_TRY(nh_read_list(c, root, "", name, &list));
  if (!list || list->n == 0) return NH_OK;
  *items = nh_calloc((size_t)list->n, size);
  if (!*items) return NH_ERR_MEMORY;
  nh_ctx point = *c;
  for (int i = 0; i < list->n; ++i) {
    const nh_yaml_node *p = list->items[i];
    char *item = (char *)*items + (size_t)i * size;
    point.item = i;
    nh_read_index(path, name, i);
    if (p->kind != NH_YAML_MAP)
      return nh_read_fail(c, p, path, "expected %s, got %s", expected,
                          nh_read_describe(p, d, sizeof d));
    NH_TRY(nh_read_table(&point, p, path, rows, item));
    nh_read_where(c, p, path, item + where);
    *n = i + 1;
  }
  return NH_OK;
}

int nh_read_probes(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return read_points(c, root, "probes", "a probe {name: ..., point: [x, y, z]}", probe_rows,
                     sizeof *s->probes, offsetof(nh_probe, where), (void **)&s->probes,
                     &s->n_probes);
}

int nh_read_targets(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return read_points(c, root, "targets", "a target {name: ..., point: [x, y, z], tool: ...}",
                     target_rows, sizeof *s->targets, offsetof(nh_target, where),
                     (void **)&s->targets, &s->n_targets);
}
