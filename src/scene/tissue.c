/* tissue.c — the tissue section: the domain (a box, the analytic brain, a
 * label-image mask or an STL surface), the label image, the grid and its
 * size limits, the material (and materials per label), damping, buoyancy
 * and the skull. Its region lists (fixed, loads, tractions) are regions.c's.
 *
 * Anatomy (docs/anatomy.md). Files are named relative to the scene file's
 * folder unless absolute. Their headers are read here, so that a missing,
 * unreadable or corrupt file fails `check` at its key; the voxels and
 * triangles are read again, in full, when the domain is built
 * (mesh/domain.c), which also checks that every label named exists in the
 * image. */
#include "scene/scene_impl.h"

#include <errno.h>
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* MAP.file (required): a readable file, resolved into out. */
static int read_data_file(const nh_ctx *c, const nh_yaml_node *map, const char *path,
                          char out[NH_PATH_MAX], const nh_yaml_node **at_out) {
  char key[NH_KEY_MAX], value[NH_PATH_MAX];
  const nh_yaml_node *at;
  NH_TRY(nh_read_field(c, map, path, "file", 1, &at));
  nh_read_join(key, path, "file");
  NH_TRY(nh_read_string(c, at, key, value, sizeof value));
  int n = nh_read_relative(c, value, out);
  if (n < 0 || n >= NH_PATH_MAX)
    return nh_read_fail(c, at, key, "the path is longer than %d characters", NH_PATH_MAX - 1);
  struct stat st;
  int err = access(out, R_OK) != 0 ? errno : 0;
  if (!err && stat(out, &st) == 0 && S_ISDIR(st.st_mode)) err = EISDIR;
  if (err) return nh_read_fail(c, at, key, "cannot read %s: %s", out, strerror(err));
  if (at_out) *at_out = at;
  return NH_OK;
}

/* The mapping `node` at `path` with keys among `keys`; else an error that
 * shows the expected form `example`. */
static int expect_mapping(const nh_ctx *c, const nh_yaml_node *node, const char *path,
                          const char *example, const char *const *keys) {
  char d[96];
  if (node->kind != NH_YAML_MAP)
    return nh_read_fail(c, node, path, "expected a mapping %s, got %s", example,
                        nh_read_describe(node, d, sizeof d));
  return nh_read_keys(c, node, path, keys);
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
  NH_TRY(
      nh_read_image_header(c, at_file, nh_read_join(key, path, "file"), s->tissue.mask_file, &im));
  nh_image_extent(im, s->tissue.box_min, s->tissue.box_max);
  nh_image_release(&im);
  nh_read_where(c, at_file, nh_read_join(key, path, "file"), s->tissue.where_domain);
  NH_TRY(nh_read_field(c, mask, path, "labels", 1, &labels));
  nh_read_join(key, path, "labels");
  if (labels->kind != NH_YAML_SEQ || labels->n == 0)
    return nh_read_fail(c, labels, key, "expected a non-empty list of labels [1, 2, ...], got %s",
                        nh_read_describe(labels, d, sizeof d));
  s->tissue.mask_labels = nh_calloc((size_t)labels->n, sizeof(int));
  if (!s->tissue.mask_labels) return NH_ERR_MEMORY;
  for (int i = 0; i < labels->n; ++i) {
    char item[NH_KEY_MAX];
    NH_TRY(
        nh_read_label(c, labels->items[i], nh_read_index(item, key, i), &s->tissue.mask_labels[i]));
    for (int j = 0; j < i; ++j)
      if (s->tissue.mask_labels[j] == s->tissue.mask_labels[i])
        return nh_read_fail(c, labels->items[i], item, "label %d is listed twice",
                            s->tissue.mask_labels[i]);
    s->tissue.n_mask_labels = i + 1;
  }
  nh_read_where(c, labels, key, s->tissue.where_labels);
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
  NH_TRY(nh_read_get(c, node, path, "unit", NH_KEY_NUMBER, 0, &s->tissue.surface_unit, &at_unit));
  NH_TRY(nh_read_at_least(c, at_unit, path, "unit", s->tissue.surface_unit, 0, 1));
  nh_read_join(key, path, "file");
  nh_read_where(c, at_file, key, s->tissue.where_domain);
  nh_surface *surface;
  if (nh_surface_read(s->tissue.surface_file, s->tissue.surface_unit, NH_SURFACE_MIN_EXTENT,
                      &s->limits.read, &surface)) {
    char msg[1024];
    snprintf(msg, sizeof msg, "%s", nh_error_message());
    return nh_read_fail(c, at_file, key, "%s", msg);
  }
  for (int k = 0; k < 3; k++)
    s->tissue.box_min[k] = surface->min[k], s->tissue.box_max[k] = surface->max[k];
  nh_surface_release(&surface);
  return NH_OK;
}

/* tissue.domain.brain {size: [3] > 0 (required), center: [3] (default 0)}. */
static int read_brain(const nh_ctx *c, const nh_yaml_node *brain, nh_scene *s) {
  static const char *const keys[] = {"size", "center", NULL};
  const char *path = "tissue.domain.brain";
  char key[NH_KEY_MAX];
  const nh_yaml_node *at_size;
  NH_TRY(expect_mapping(c, brain, path, "{size: [sx, sy, sz], center: [x, y, z]}", keys));
  s->tissue.domain = NH_DOMAIN_BRAIN;
  NH_TRY(nh_read_get(c, brain, path, "size", NH_KEY_VEC3, 1, s->tissue.brain_size, &at_size));
  for (int i = 0; i < 3; ++i)
    if (!(s->tissue.brain_size[i] > 0))
      return nh_read_fail(c, at_size->items[i], nh_read_index(key, "tissue.domain.brain.size", i),
                          "must be greater than 0, got %g", s->tissue.brain_size[i]);
  NH_TRY(nh_read_get(c, brain, path, "center", NH_KEY_VEC3, 0, s->tissue.brain_center, NULL));
  for (int i = 0; i < 3; ++i) {
    s->tissue.box_min[i] = s->tissue.brain_center[i] - 0.5 * s->tissue.brain_size[i];
    s->tissue.box_max[i] = s->tissue.brain_center[i] + 0.5 * s->tissue.brain_size[i];
  }
  return NH_OK;
}

/* tissue.labels {file} (optional; not with a mask domain, whose image it is). */
static int read_labels_image(const nh_ctx *c, const nh_yaml_node *t, nh_scene *s) {
  static const char *const keys[] = {"file", NULL};
  const nh_yaml_node *node, *at_file;
  char key[NH_KEY_MAX];
  NH_TRY(nh_read_section(c, t, "tissue", "labels", 0, &node));
  if (!node) return NH_OK;
  if (s->tissue.domain == NH_DOMAIN_MASK)
    return nh_read_fail(c, node, "tissue.labels",
                        "a mask domain's image is the label image (give tissue.labels only with a "
                        "box, brain or surface domain)");
  NH_TRY(nh_read_keys(c, node, "tissue.labels", keys));
  NH_TRY(read_data_file(c, node, "tissue.labels", s->tissue.labels_file, &at_file));
  nh_image *im;
  nh_read_join(key, "tissue.labels", "file");
  NH_TRY(nh_read_image_header(c, at_file, key, s->tissue.labels_file, &im));
  nh_image_release(&im);
  nh_read_where(c, at_file, key, s->tissue.where_labels);
  return NH_OK;
}

/* tissue.domain: exactly one of box, brain, mask, surface; then the label
 * image (tissue.labels), which the mask may already be. */
static int read_domain(const nh_ctx *c, const nh_key_site *k, void *base) {
  static const char *const keys[] = {"box", "brain", "mask", "surface", NULL};
  nh_scene *s = base;
  char key[NH_KEY_MAX];
  const nh_yaml_node *domain;
  NH_TRY(nh_read_section(c, k->map, k->path, "domain", 1, &domain));
  NH_TRY(nh_read_keys(c, domain, "tissue.domain", keys));
  if (domain->n == 0)
    return nh_read_fail(c, domain, "tissue.domain", "give one of box, brain, mask, surface");
  if (domain->n > 1)
    return nh_read_fail(c, domain->keys[1],
                        nh_read_join(key, "tissue.domain", domain->keys[1]->text),
                        "give exactly one of box, brain, mask, surface (%s is already given)",
                        domain->keys[0]->text);
  const char *kind = domain->keys[0]->text;
  if (!strcmp(kind, "brain")) {
    NH_TRY(read_brain(c, domain->items[0], s));
  } else if (!strcmp(kind, "box")) {
    s->tissue.domain = NH_DOMAIN_BOX;
    NH_TRY(nh_read_box(c, domain->items[0], "tissue.domain.box", 1, s->tissue.box_min,
                       s->tissue.box_max));
  } else if (!strcmp(kind, "mask")) {
    NH_TRY(read_mask(c, domain->items[0], s));
  } else {
    NH_TRY(read_surface(c, domain->items[0], s));
  }
  return read_labels_image(c, k->map, s);
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
  if (cells <= s->limits.max_cells && 3 * nodes > INT_MAX)
    return nh_read_fail(c, at, "tissue.grid",
                        "%d x %d x %d = %.0f cells: their %.0f nodes have %.0f unknowns, more "
                        "than the %d one mesh can index; coarsen the grid and let `adapt` refine",
                        g[0], g[1], g[2], cells, nodes, 3 * nodes, INT_MAX);
  if (cells > s->limits.max_cells)
    return nh_read_fail(c, at, "tissue.grid",
                        "%d x %d x %d = %.0f cells (%.0f nodes) exceed limits.max_cells = %d "
                        "(a run would need about %s of memory); coarsen the grid and let `adapt` "
                        "refine, or raise limits.max_cells",
                        g[0], g[1], g[2], cells, nodes, s->limits.max_cells, need);
  double ram = (double)sysconf(_SC_PHYS_PAGES) * (double)sysconf(_SC_PAGESIZE);
  if (ram > 0 && nh_scene_memory_estimate(cells) > ram)
    return nh_read_fail(c, at, "tissue.grid",
                        "%d x %d x %d = %.0f cells: a run would need about %s of memory, more "
                        "than this machine's %s; coarsen the grid and let `adapt` refine",
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
    return nh_read_fail(c, box, "tissue.domain.box",
                        "its %d x %d x %d grid cells measure %g x %g x %g m, an aspect ratio of "
                        "%.3g (at most 1e6): such a cell's Jacobian cannot be inverted in double "
                        "precision; give a box and a grid whose cells are closer to cubes",
                        s->tissue.grid[0], s->tissue.grid[1], s->tissue.grid[2], h[0], h[1], h[2],
                        hi / lo);
  return NH_OK;
}

/* tissue.grid (default [8, 4, 4], each >= 1), checked against the limits
 * (read before tissue) and, on a box, the cells' aspect ratio. */
static int read_grid(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_yaml_node *t = k->map, *n = k->at;
  nh_scene *s = base;
  char key[NH_KEY_MAX];
  s->tissue.grid[0] = 8, s->tissue.grid[1] = 4, s->tissue.grid[2] = 4;
  if (n) {
    NH_TRY(nh_read_ivec3(c, n, "tissue.grid", s->tissue.grid));
    for (int i = 0; i < 3; ++i)
      if (s->tissue.grid[i] < 1)
        return nh_read_fail(c, n->items[i], nh_read_index(key, "tissue.grid", i),
                            "a cell count must be at least 1, got %d", s->tissue.grid[i]);
  }
  NH_TRY(check_size(c, n ? n : t, s));
  if (s->tissue.domain == NH_DOMAIN_BOX)
    NH_TRY(check_box_cells(c, nh_yaml_get(t, "domain", NULL)->items[0], s));
  return NH_OK;
}

int nh_read_check_poisson(const nh_ctx *c, const nh_key_site *k, void *base) {
  double nu = *(double *)((char *)base + k->row->offset);
  if (nu >= 0.5)
    return nh_read_fail(c, k->at, k->key,
                        "%g is not below 0.5: incompressible (or beyond) materials are not "
                        "supported; use a value below 0.5, e.g. 0.49",
                        nu);
  if (nu <= -1) return nh_read_fail(c, k->at, k->key, "must be greater than -1, got %g", nu);
  return NH_OK;
}

static const char *const formulations[] = {"bbar", "full", NULL};
static const char *const cut_cells[] = {"scaled", "integrated", NULL};

/* tissue.material: the element's formulation is read first. */
#define M(member) offsetof(nh_scene, tissue.member)
static const nh_key material_rows[] = {
    {NH_CHOICE("formulation", M(formulation), NH_FORMULATION_BBAR, formulations)},
    {NH_NUMBER("young", M(young), 0, NH_ABOVE, 0), .required = 1},
    {NH_NUMBER("poisson", M(poisson), 0, NH_ANY, 0), .required = 1, .check = nh_read_check_poisson},
    {NH_NUMBER("density", M(density), 1000, NH_ABOVE, 0)},
    {0},
};

/* tissue.materials.LABEL: poisson and density default to tissue.material's (set by the caller). */
#define L(member) offsetof(nh_label_material, member)
static const nh_key label_material_rows[] = {
    {NH_NUMBER("young", L(young), 0, NH_ABOVE, 0), .required = 1},
    {NH_NUMBER("poisson", L(poisson), 0, NH_ANY, 0), .check = nh_read_check_poisson},
    {NH_NUMBER("density", L(density), 0, NH_ABOVE, 0)},
    {0},
};

/* tissue.materials {LABEL: {young, poisson, density}} (optional). */
static int read_materials(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  const nh_yaml_node *m;
  char key[NH_KEY_MAX], d[96];
  NH_TRY(nh_read_section(c, k->map, k->path, "materials", 0, &m));
  if (!m || m->n == 0) return NH_OK;
  if (!s->tissue.mask_file[0] && !s->tissue.labels_file[0])
    return nh_read_fail(c, m, "tissue.materials",
                        "materials per label need a label image: give tissue.domain.mask or "
                        "tissue.labels");
  s->tissue.materials = nh_calloc((size_t)m->n, sizeof *s->tissue.materials);
  if (!s->tissue.materials) return NH_ERR_MEMORY;
  for (int i = 0; i < m->n; ++i) {
    nh_label_material *lm = &s->tissue.materials[i];
    nh_read_join(key, "tissue.materials", m->keys[i]->text);
    /* Digits only: a label is a whole number >= 0 (as the key table's N),
     * not -2, +2, 2.0 or 2e0. */
    const char *text = m->keys[i]->text;
    size_t digits = strspn(text, "0123456789");
    double v = digits ? strtod(text, NULL) : -1;
    if (!digits || text[digits] || v > INT_MAX)
      return nh_read_fail(c, m->keys[i], key,
                          "a material's key is a label, a whole number from 0 to %d in digits, "
                          "got %s",
                          INT_MAX, nh_read_describe(m->keys[i], d, sizeof d));
    lm->label = (int)v;
    for (int j = 0; j < i; ++j)
      if (s->tissue.materials[j].label == lm->label)
        return nh_read_fail(c, m->keys[i], key, "label %d has a material already", lm->label);
    if (m->items[i]->kind != NH_YAML_MAP)
      return nh_read_fail(c, m->items[i], key,
                          "expected a mapping {young, poisson, density}, got %s",
                          nh_read_describe(m->items[i], d, sizeof d));
    lm->poisson = s->tissue.poisson, lm->density = s->tissue.density;
    NH_TRY(nh_read_table(c, m->items[i], key, label_material_rows, lm));
    nh_read_where(c, m->keys[i], key, lm->where);
    s->tissue.n_materials = i + 1;
  }
  return NH_OK;
}

static const nh_key damping_rows[] = {
    {NH_NUMBER("mass", M(damping_mass), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("stiffness", M(damping_stiffness), 0, NH_AT_LEAST, 0)},
    {0},
};

/* A fraction of the weight, in [0, 1]. */
static int check_fraction(const nh_ctx *c, const nh_key_site *k, void *base) {
  double v = *(double *)((char *)base + k->row->offset);
  if (!(v >= 0 && v <= 1))
    return nh_read_fail(c, k->at, k->key, "a fraction must lie in [0, 1], got %g", v);
  return NH_OK;
}

/* tissue.buoyancy.level needs gravity (read before) to say what is above it. */
static int check_level(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  s->tissue.buoyancy_has_level = 1;
  if (!(nh_vec3_dot(s->gravity, s->gravity) > 0))
    return nh_read_fail(c, k->at, "tissue.buoyancy.level",
                        "a fluid level needs gravity (its direction says what lies above the "
                        "level); gravity is zero");
  return NH_OK;
}

/* tissue.buoyancy: {before: b0, after: b1, schedule: [[t, s], ...], level:
 * [x, y, z]}. Without a schedule the change is a step at t = 0: s = 1 from
 * the first step on. */
static const nh_key buoyancy_rows[] = {
    {NH_NUMBER("before", M(buoyancy_before), 0, NH_ANY, 0), .required = 1, .check = check_fraction},
    {NH_NUMBER("after", M(buoyancy_after), 0, NH_ANY, 0), .required = 1, .check = check_fraction},
    {NH_SCHEDULE("schedule", M(buoyancy_schedule))},
    {NH_VEC3("level", M(buoyancy_level)), .check = check_level},
    {0},
};

static int buoyancy_given(const nh_ctx *c, const nh_key_site *k, void *base) {
  (void)c, (void)k;
  ((nh_scene *)base)->tissue.buoyant = 1;
  return NH_OK;
}

static const char *const skull_row_kinds[] = {"points", "mortar", NULL};
static const nh_key skull_rows[] = {
    {NH_NUMBER("gap", M(skull_gap), 0, NH_AT_LEAST, 0)},
    {NH_CHOICE("rows", M(skull_rows), NH_SKULL_ROWS_POINTS, skull_row_kinds)},
    {0},
};

/* tissue.skull: {gap: g >= 0 (default 0), rows: points | mortar}, an immersed domain only; given
 * even when null (`skull:`). */
static int read_skull(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  const nh_yaml_node *m, *key;
  NH_TRY(nh_read_section(c, k->map, k->path, "skull", 0, &m));
  nh_yaml_get(k->map, "skull", &key);
  if (!key) return NH_OK;
  if (m) NH_TRY(nh_read_row_keys(c, m, "tissue.skull", skull_rows));
  nh_read_where(c, key, "tissue.skull", s->tissue.where_skull);
  s->tissue.skull = 1;
  if (m) NH_TRY(nh_read_rows(c, m, "tissue.skull", skull_rows, s));
  if (s->tissue.domain == NH_DOMAIN_BOX)
    return nh_read_fail(c, key, "tissue.skull",
                        "needs an immersed domain (brain): the skull is the domain's surface "
                        "offset by the gap");
  return NH_OK;
}

/* The tissue's keys in the order they are read: the domain (and its label
 * image) first, as the grid is checked against it and the materials need
 * the image; `labels` is read by the domain's row. */
static const nh_key tissue_rows[] = {
    {NH_CUSTOM("domain", read_domain), .required = 1},
    {NH_CUSTOM("grid", read_grid)},
    {NH_CHOICE("cut_cells", offsetof(nh_scene, tissue.cut_cells), NH_CUT_CELLS_INTEGRATED,
               cut_cells)},
    {NH_MAP("material", material_rows), .required = 1},
    {NH_CUSTOM("materials", read_materials)},
    {NH_MAP("damping", damping_rows)},
    {NH_MAP("buoyancy", buoyancy_rows), .read = buoyancy_given},
    {NH_CUSTOM("skull", read_skull)},
    {NH_CUSTOM("fixed", nh_read_fixed)},
    {NH_CUSTOM("loads", nh_read_loads)},
    {NH_CUSTOM("tractions", nh_read_tractions)},
    {NH_CUSTOM("labels", NULL)},
    {0},
};

int nh_read_tissue(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return nh_read_top(c, root, "tissue", 1, tissue_rows, s);
}
