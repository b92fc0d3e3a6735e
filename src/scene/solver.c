/* solver.c — how a scene is run rather than what it models: the solver
 * section, the outputs and the size limits. */
#include "scene/scene_impl.h"

#include <string.h>

static const char *const on_invalid[] = {"stop", "warn", NULL};
static const char *const refactors[] = {"auto", "every", NULL};

#define S(member) offsetof(nh_scene, solver.member)
/* max_iterations: 0 without solver.newton, 5 by default with it (newton_given). */
static const nh_key newton_rows[] = {
    {NH_INT("max_iterations", S(newton_iterations), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("tolerance", S(newton_tolerance), 1e-8, NH_ABOVE, 0)},
    {0},
};

/* solver.newton given (a mapping): Newton corrections are on, 5 unless said. */
static int newton_given(const nh_ctx *c, const nh_key_site *k, void *base) {
  (void)c, (void)k;
  ((nh_scene *)base)->solver.newton_iterations = 5;
  ((nh_scene *)base)->solver.newton_given = 1;
  return NH_OK;
}

static const nh_key solver_rows[] = {
    {NH_CHOICE("on_invalid", S(on_invalid_warn), 0, on_invalid)},
    {NH_MAP("newton", newton_rows), .read = newton_given},
    {NH_NUMBER("tolerance", S(tolerance), 1e-8, NH_ABOVE, 0)},
    {NH_INT("max_iterations", S(max_iterations), 30, NH_AT_LEAST, 1)},
    {NH_INT("threads", S(threads), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("lazy_rotation", S(lazy_rotation), 0, NH_AT_LEAST, 0)},
    {NH_CHOICE("refactor", S(refactor), NH_REFACTOR_AUTO, refactors)},
    {0},
};

int nh_read_solver(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return nh_read_top(c, root, "solver", 0, solver_rows, s);
}

/* solver.newton iterates the linearised dynamic step (solve/coupled.c); a
 * static solve is Newton already (solver.tolerance, solver.max_iterations),
 * so the key is refused there rather than ignored. */
int nh_read_solver_newton(const nh_ctx *c, const nh_yaml_node *root, const nh_scene *s) {
  const nh_yaml_node *at = nh_yaml_get(nh_yaml_get(root, "solver", NULL), "newton", NULL);
  if (!at) return NH_OK;
  if (s->time.mode == NH_MODE_STATIC)
    return nh_read_fail(c, at, "solver.newton",
                        "is for dynamic steps; a static solve is Newton's already: set "
                        "solver.tolerance and solver.max_iterations instead");
  return NH_OK;
}

/* output.dir must name a folder. */
static int check_dir(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!((nh_scene *)base)->output.dir[0])
    return nh_read_fail(c, k->at, "output.dir", "must not be empty");
  return NH_OK;
}

/* An image named by an output key (FILE relative to the scene): its path
 * resolved into `path` and its header read, so a bad one is refused at its
 * line before the run. */
static int read_output_image(const nh_ctx *c, const nh_key_site *k, char path[NH_PATH_MAX]) {
  char value[NH_PATH_MAX];
  if (!k->at) return NH_OK;
  NH_TRY(nh_read_string(c, k->at, k->key, value, sizeof value));
  int len = nh_read_relative(c, value, path);
  if (len < 0 || len >= NH_PATH_MAX)
    return nh_read_fail(c, k->at, k->key, "the path is longer than %d characters", NH_PATH_MAX - 1);
  nh_image *im;
  NH_TRY(nh_read_image_header(c, k->at, k->key, path, &im));
  nh_image_release(&im);
  return NH_OK;
}

static int read_field_reference(const nh_ctx *c, const nh_key_site *k, void *base) {
  return read_output_image(c, k, ((nh_scene *)base)->output.displacement_field.reference);
}

static int read_warped_image(const nh_ctx *c, const nh_key_site *k, void *base) {
  return read_output_image(c, k, ((nh_scene *)base)->output.warped.image);
}

/* .at: a list of at most NH_OUTPUT_AT_MAX times >= 0 (one after the end of
 * the run writes nothing: the last step writes anyway, and a run shortened
 * by --set time.end keeps its scene valid). */
static int read_times(const nh_ctx *c, const nh_key_site *k, double *at, int *n_at) {
  char d[96], sub[NH_KEY_MAX];
  const nh_yaml_node *list = k->at;
  if (!list) return NH_OK;
  if (list->kind != NH_YAML_SEQ)
    return nh_read_fail(c, list, k->key, "expected a list of times [t, ...] in s, got %s",
                        nh_read_describe(list, d, sizeof d));
  if (list->n > NH_OUTPUT_AT_MAX)
    return nh_read_fail(c, list, k->key, "at most %d times, got %d", NH_OUTPUT_AT_MAX, list->n);
  for (int i = 0; i < list->n; ++i) {
    nh_read_index(sub, k->key, i);
    NH_TRY(nh_read_number(c, list->items[i], sub, &at[i]));
    NH_TRY(nh_read_at_least(c, list->items[i], k->key, sub + strlen(k->key) + 1, at[i], 0, 0));
  }
  *n_at = list->n;
  return NH_OK;
}

static int read_field_times(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  return read_times(c, k, s->output.displacement_field.at, &s->output.displacement_field.n_at);
}

static int read_warped_times(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  return read_times(c, k, s->output.warped.at, &s->output.warped.n_at);
}

static const char *const interpolations[] = {"auto", "linear", "nearest", NULL};

#define O(member) offsetof(nh_scene, output.member)
static const nh_key field_rows[] = {
    {NH_CUSTOM("reference", read_field_reference), .required = 1},
    {NH_CUSTOM("at", read_field_times)},
    {0},
};

static const nh_key warped_rows[] = {
    {NH_CUSTOM("image", read_warped_image), .required = 1},
    {NH_CUSTOM("at", read_warped_times)},
    {NH_CHOICE("interpolation", O(warped.interpolation), NH_INTERPOLATION_AUTO, interpolations)},
    {0},
};

static const nh_key output_rows[] = {
    {NH_STRING("dir", O(dir), NH_PATH_MAX), .check = check_dir},
    {NH_INT("every", O(every), 1, NH_AT_LEAST, 0)},
    {NH_BOOL("hdf5", O(hdf5), 0)},
    {NH_INT("checkpoint", O(checkpoint), 0, NH_AT_LEAST, 0)},
    {NH_MAP("displacement_field", field_rows)},
    {NH_MAP("warped", warped_rows)},
    {0},
};

int nh_read_output(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  nh_yaml_join(s->output.dir, sizeof s->output.dir, "out", "/", s->name); /* out/<name> */
  return nh_read_top(c, root, "output", 0, output_rows, s);
}

static const nh_key limits_rows[] = {
    {NH_INT("max_cells", offsetof(nh_scene, limits.max_cells), 2000000, NH_AT_LEAST, 1)},
    {NH_NUMBER("max_voxels", offsetof(nh_scene, limits.read.max_voxels), 2e8, NH_AT_LEAST, 1)},
    {NH_NUMBER("max_triangles", offsetof(nh_scene, limits.read.max_triangles), 2e7, NH_AT_LEAST,
               1)},
    {NH_NUMBER("max_file_bytes", offsetof(nh_scene, limits.read.max_file_bytes), 4e9, NH_AT_LEAST,
               1)},
    {0},
};

int nh_read_section_limits(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return nh_read_top(c, root, "limits", 0, limits_rows, s);
}
