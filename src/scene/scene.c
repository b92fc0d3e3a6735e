/* scene.c — reading and validation: YAML tree to a validated nh_scene.
 *
 * nh_scene_load parses the file into a yaml_tree, applies the `--set`
 * overrides to the tree (so an override is checked exactly like a value in
 * the file), keeps the tree's YAML text as the scene as run, and then walks
 * the schema section by section, filling defaults and checking types and
 * ranges. Each section has a file of its own and is read by a key table
 * (scene_impl.h): a row per key, binding it to its field with its type,
 * default and bound, and hooks for the keys with structure and the
 * cross-checks (end vs steps, min < max, unique names, a domain that is
 * exactly one of box/brain/mask/surface). The order of the sections below
 * is what the keys depend on: the limits before the tissue's grid, tools
 * before targets (a target names its tool), probes and targets before
 * adapt.goal and the trajectories (which name them).
 *
 * The files: read.c holds the typed readers, the messages (FILE:LINE: KEY:
 * reason, described there) and the table reader; time.c (time, gravity),
 * tissue.c (domain, anatomy, material, buoyancy, skull) with regions.c
 * (fixed, loads, tractions), adapt.c, solver.c (solver, output, limits),
 * tools.c, points.c (probes, targets, voxel points) and trajectory.c (the
 * keys resolved once targets are read, and the tools' motion integral);
 * schedule.c evaluates schedules and gravity at a time, once per step;
 * print.c prints the summary of `check`; keys.c holds the documented key
 * table (docs/scene.md) every reader's keys are checked against.
 *
 * Nothing here is global: the context of one load (file name, overrides,
 * the tree, the scene read so far) travels in an nh_ctx. */
#include "scene/scene_impl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* name (required): it names the output folder. */
static int read_name(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  const nh_yaml_node *at;
  char d[96];
  NH_TRY(nh_read_field(c, root, "", "name", 1, &at));
  NH_TRY(nh_read_string(c, at, "name", s->name, sizeof s->name));
  size_t len = strlen(s->name);
  if (len == 0 ||
      strspn(s->name, "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz"
                      "0123456789._-") != len ||
      !strcmp(s->name, ".") || !strcmp(s->name, ".."))
    return nh_read_fail(
        c, at, "name",
        "%s may only contain letters, digits, '.', '_' and '-' (it names the output "
        "folder)",
        nh_read_describe(at, d, sizeof d));
  return NH_OK;
}

/* The whole schema, each section after those its keys depend on. */
static int read_scene(nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  static const char *const keys[] = {"name",   "time",   "gravity", "tissue",  "adapt",
                                     "solver", "tools",  "probes",  "targets", "plan",
                                     "output", "limits", NULL};
  c->root = root;
  c->scene = s;
  NH_TRY(nh_read_keys(c, root, "", keys));
  NH_TRY(read_name(c, root, s));
  NH_TRY(nh_read_time(c, root, s));
  NH_TRY(nh_read_gravity(c, root, s));
  NH_TRY(nh_read_section_limits(c, root, s)); /* before tissue: the grid is checked against them */
  NH_TRY(nh_read_tissue(c, root, s));
  c->image = s->tissue.mask_file[0]     ? s->tissue.mask_file
             : s->tissue.labels_file[0] ? s->tissue.labels_file
                                        : NULL; /* voxel points of probes, targets, entries */
  NH_TRY(nh_read_adapt(c, root, s));
  NH_TRY(nh_read_solver(c, root, s));
  NH_TRY(nh_read_tools(c, root, s));
  NH_TRY(nh_read_solver_newton(c, root, s));
  NH_TRY(nh_read_probes(c, root, s));
  NH_TRY(nh_read_targets(c, root, s));    /* after tools: a target names its tool */
  NH_TRY(nh_read_adapt_goal(c, root, s)); /* after probes and targets: goals name them */
  NH_TRY(nh_read_plans(c, root, s));      /* after targets: a trajectory names its target */
  NH_TRY(nh_read_plan(c, root, s));       /* after tissue: a label obstacle needs its image */
  NH_TRY(nh_read_output(c, root, s));
  return NH_OK;
}

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

/* Parse, override, keep the text, read the schema. */
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
                    (*root)->line, nh_read_describe(*root, d, sizeof d));
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
  free(s->plan.obstacles);
  free(s->yaml);
  free(s);
  *scene = NULL;
}
