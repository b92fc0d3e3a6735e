/* solver.c — how a scene is run rather than what it models: the solver
 * section, the outputs and the size limits. */
#include "scene/scene_impl.h"

static const char *const on_invalid[] = {"stop", "warn", NULL};
static const char *const refactors[] = {"auto", "every", NULL};

#define S(member) offsetof(nh_scene, solver.member)
/* max_iterations: 0 without solver.newton, 5 by default with it (newton_given). */
static const nh_key newton_rows[] = {
    {NH_INT("max_iterations", S(newton_iterations), 0, NH_AT_LEAST, 0)},
    {NH_NUMBER("tolerance", S(newton_tolerance), 1e-8, NH_ABOVE, 0)},
    {NULL},
};

/* solver.newton given (a mapping): Newton corrections are on, 5 unless said. */
static int newton_given(const nh_ctx *c, const nh_key_site *k, void *base) {
  (void)c, (void)k;
  ((nh_scene *)base)->solver.newton_iterations = 5;
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
    {NULL},
};

int nh_read_solver(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return nh_read_top(c, root, "solver", 0, solver_rows, s);
}

/* output.dir must name a folder. */
static int check_dir(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!((nh_scene *)base)->output.dir[0])
    return nh_read_fail(c, k->at, "output.dir", "must not be empty");
  return NH_OK;
}

#define O(member) offsetof(nh_scene, output.member)
static const nh_key output_rows[] = {
    {NH_STRING("dir", O(dir), NH_PATH_MAX), .check = check_dir},
    {NH_INT("every", O(every), 1, NH_AT_LEAST, 0)},
    {NH_BOOL("hdf5", O(hdf5), 0)},
    {NH_INT("checkpoint", O(checkpoint), 0, NH_AT_LEAST, 0)},
    {NULL},
};

int nh_read_output(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  nh_yaml_join(s->output.dir, sizeof s->output.dir, "out", "/", s->name); /* out/<name> */
  return nh_read_top(c, root, "output", 0, output_rows, s);
}

static const nh_key limits_rows[] = {
    {NH_INT("max_cells", offsetof(nh_scene, limits.max_cells), 2000000, NH_AT_LEAST, 1)},
    {NULL},
};

int nh_read_limits(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  return nh_read_top(c, root, "limits", 0, limits_rows, s);
}
