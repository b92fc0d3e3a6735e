/* adapt.c — the adapt section: the estimator, marking, the refinement
 * template and limits, coarsening, and the goal quantities of the
 * goal-oriented estimator (names of probes and targets, resolved once
 * those are read: nh_read_adapt_goal).
 *
 * adapt.template is resolved here, so that a scene naming a template that
 * does not exist fails `check` at the key's line: a name (hex2) is the file
 * NAME.tmpl in nh_templates_dir() ($NH_TEMPLATES_DIR, or the templates
 * installed or built next to the binary: core/paths.c); a value with a '/'
 * or ending in .tmpl is a path, relative to the scene file's folder unless
 * absolute (so a scene and its own template travel together). Only
 * readability is checked here; the template's contents are proved by
 * nh_template_load. Without an adapt section the default (hex2) is
 * resolved only when a tissue.fixed.N.refine needs it, and a missing file
 * is reported at that key. */
#include "scene/scene_impl.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* adapt.template (text `value`, at node `at`, NULL for the default) to a
 * readable file; the error is reported at `at`, or at `section` for the
 * default, under the dotted key `key`. */
static int resolve_template(const nh_ctx *c, const nh_yaml_node *at, const nh_yaml_node *section,
                            const char *key, const char *value, char out[NH_PATH_MAX]) {
  const nh_yaml_node *where = at ? at : section;
  size_t len = strlen(value);
  int is_path = strchr(value, '/') || (len >= 5 && !strcmp(value + len - 5, ".tmpl"));
  int n;
  if (len == 0) return nh_read_fail(c, where, key, "expected a template name or path");
  if (!is_path) {
    char buf[NH_PATH_MAX];
    const char *dir = nh_templates_dir(buf, sizeof buf);
    n = snprintf(out, NH_PATH_MAX, "%s/%s.tmpl", dir, value);
  } else {
    n = nh_read_relative(c, value, out);
  }
  if (n < 0 || n >= NH_PATH_MAX)
    return nh_read_fail(c, where, key, "the template's path is longer than %d characters",
                        NH_PATH_MAX - 1);
  struct stat st;
  int err = access(out, R_OK) != 0 ? errno : 0;
  if (!err && stat(out, &st) == 0 && S_ISDIR(st.st_mode)) err = EISDIR;
  if (!err) return NH_OK;
  if (is_path)
    return nh_read_fail(c, where, key, "cannot read the template file %s: %s", out, strerror(err));
  return nh_read_fail(c, where, key,
                      "no template named '%s' (cannot read %s: %s; set NH_TEMPLATES_DIR to the "
                      "templates folder, or give adapt.template a path)",
                      value, out, strerror(err));
}

/* adapt.template (default hex2, resolved even when adapt is null). */
static int read_template(const nh_ctx *c, const nh_key_site *k, void *base) {
  nh_scene *s = base;
  char name[NH_PATH_MAX] = "hex2";
  const nh_yaml_node *at = k->at, *key;
  nh_yaml_get(c->root, "adapt", &key);
  if (at) NH_TRY(nh_read_string(c, at, "adapt.template", name, sizeof name));
  NH_TRY(resolve_template(c, at, key, "adapt.template", name, s->adapt.template_path));
  nh_read_where(c, at ? at : key, "adapt.template", s->adapt.where_template);
  return NH_OK;
}

/* adapt.marking: theta goes with max, fraction with dorfler; then their ranges. */
static int check_marking(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_adapt_spec *a = &((nh_scene *)base)->adapt;
  const nh_yaml_node *marking = k->at;
  const nh_yaml_node *at_theta = nh_yaml_get(marking, "theta", NULL),
                     *at_fraction = nh_yaml_get(marking, "fraction", NULL);
  if (at_theta && a->strategy != NH_MARK_MAX)
    return nh_read_fail(c, at_theta, "adapt.marking.theta",
                        "applies to strategy max only (the strategy is dorfler: give fraction)");
  if (at_fraction && a->strategy != NH_MARK_DORFLER)
    return nh_read_fail(c, at_fraction, "adapt.marking.fraction",
                        "applies to strategy dorfler only (the strategy is max%s: give theta, or "
                        "strategy: dorfler)",
                        nh_yaml_get(marking, "strategy", NULL) ? "" : ", the default");
  if (at_theta && !(a->theta > 0 && a->theta < 1))
    return nh_read_fail(c, at_theta, "adapt.marking.theta", "must lie in (0, 1), got %g", a->theta);
  const nh_yaml_node *at_goals = nh_yaml_get(marking, "goals", NULL);
  if (at_goals && a->estimator != NH_ESTIMATOR_GOAL)
    return nh_read_fail(c, at_goals, "adapt.marking.goals", "applies to estimator goal only");
  if (at_goals && a->goal_marking == NH_GOAL_MARKING_EACH && a->strategy != NH_MARK_MAX)
    return nh_read_fail(c, at_goals, "adapt.marking.goals",
                        "each applies to strategy max only (each goal's own theta-marking)");
  const nh_yaml_node *at_leaves = nh_yaml_get(marking, "goal_leaves", NULL);
  if (at_leaves && a->estimator != NH_ESTIMATOR_GOAL)
    return nh_read_fail(c, at_leaves, "adapt.marking.goal_leaves",
                        "applies to estimator goal only");
  if (at_fraction && !(a->fraction > 0 && a->fraction <= 1))
    return nh_read_fail(c, at_fraction, "adapt.marking.fraction", "must lie in (0, 1], got %g",
                        a->fraction);
  return NH_OK;
}

static int goal(const nh_scene *s) {
  return s->adapt.estimator == NH_ESTIMATOR_GOAL;
}

static int check_hanging(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = base;
  if (goal(s) && s->adapt.hanging == NH_HANGING_LAGRANGE)
    return nh_read_fail(c, k->at, "adapt.hanging",
                        "lagrange cannot be used with estimator goal (the dual problems need the "
                        "hanging nodes eliminated)");
  return NH_OK;
}

/* adapt.goal: only with estimator goal; its names are resolved by nh_read_adapt_goal. */
static int check_goal_given(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (k->at && !goal(base))
    return nh_read_fail(c, k->at, "adapt.goal",
                        "applies to estimator goal only (the estimator is %s)",
                        nh_yaml_get(k->map, "estimator", NULL) ? "spr" : "spr, the default");
  return NH_OK;
}

static int check_tolerance(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!goal(base))
    return nh_read_fail(c, k->at, "adapt.tolerance",
                        "applies to estimator goal only (m, on the goal quantities' estimated "
                        "error)");
  return NH_OK;
}

static int check_resolve(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = base;
  if (s->adapt.resolve > 0 && !goal(s))
    return nh_read_fail(c, k->at, "adapt.resolve", "applies to estimator goal only");
  return NH_OK;
}

static int check_resolve_tip(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!goal(base))
    return nh_read_fail(c, k->at, "adapt.resolve_tip", "applies to estimator goal only");
  return NH_OK;
}

static int check_memory(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!goal(base)) return nh_read_fail(c, k->at, "adapt.memory", "applies to estimator goal only");
  return NH_OK;
}

static int check_local_dual(const nh_ctx *c, const nh_key_site *k, void *base) {
  if (!goal(base))
    return nh_read_fail(c, k->at, "adapt.local_dual", "applies to estimator goal only");
  return NH_OK;
}

static int check_separate_every(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = base;
  if (!goal(s))
    return nh_read_fail(c, k->at, "adapt.separate_every", "applies to estimator goal only");
  if (s->adapt.separate_every > 1 && s->adapt.goal_marking == NH_GOAL_MARKING_EACH)
    return nh_read_fail(c, k->at, "adapt.separate_every",
                        "must be 1 with adapt.marking.goals: each (each goal marks by its own "
                        "indicator, which the combined dual does not give)");
  return NH_OK;
}

static int check_coarsen(const nh_ctx *c, const nh_key_site *k, void *base) {
  const nh_scene *s = base;
  if (!(s->adapt.coarsen > 0 && s->adapt.coarsen < 1))
    return nh_read_fail(c, k->at, "adapt.coarsen.fraction", "must lie in (0, 1), got %g",
                        s->adapt.coarsen);
  if (s->adapt.goal_marking == NH_GOAL_MARKING_EACH)
    return nh_read_fail(c, k->at, "adapt.coarsen",
                        "not with adapt.marking.goals: each (its marking threshold is relative to "
                        "each goal's maximum, coarsening's is the goals' summed indicator)");
  return NH_OK;
}

static const char *const estimators[] = {"spr", "goal", NULL};
static const char *const strategies[] = {"max", "dorfler", NULL};
static const char *const hangings[] = {"eliminate", "lagrange", NULL};
static const char *const goal_markings[] = {"sum", "each", NULL};

#define A(member) offsetof(nh_scene, adapt.member)
static const nh_key marking_rows[] = {
    {NH_CHOICE("strategy", A(strategy), NH_MARK_MAX, strategies)},
    {NH_NUMBER("theta", A(theta), 0.3, NH_ANY, 0)}, /* ranges: check_marking */
    {NH_NUMBER("fraction", A(fraction), 0.5, NH_ANY, 0)},
    {NH_CHOICE("goals", A(goal_marking), NH_GOAL_MARKING_SUM, goal_markings)},
    {NH_BOOL("goal_leaves", A(goal_leaves), 0)},
    {0},
};

static const nh_key coarsen_rows[] = {
    {NH_NUMBER("fraction", A(coarsen), 0, NH_ANY, 0), .required = 1, .check = check_coarsen},
    {0},
};

/* The keys in the order they are read: the estimator first, as later keys
 * depend on it. */
static const nh_key adapt_rows[] = {
    {NH_CHOICE("estimator", A(estimator), NH_ESTIMATOR_SPR, estimators)},
    {NH_MAP("marking", marking_rows), .check = check_marking},
    {NH_CUSTOM("template", read_template)},
    {NH_INT("max_level", A(max_level), 2, NH_AT_LEAST, 0)},
    {NH_NUMBER("min_size", A(min_size), 0, NH_AT_LEAST, 0)},
    {NH_INT("max_dofs", A(max_dofs), 0, NH_AT_LEAST, 0)},
    {NH_INT("every", A(every), 1, NH_AT_LEAST, 1)},
    {NH_CHOICE("hanging", A(hanging), NH_HANGING_ELIMINATE, hangings), .check = check_hanging},
    {NH_CUSTOM("goal", check_goal_given)}, /* its names: nh_read_adapt_goal */
    {NH_NUMBER("tolerance", A(tolerance), 0, NH_ABOVE, 0), .check = check_tolerance},
    {NH_INT("resolve", A(resolve), 0, NH_AT_LEAST, 0), .check = check_resolve},
    {NH_BOOL("resolve_tip", A(resolve_tip), 1), .check = check_resolve_tip},
    {NH_BOOL("local_dual", A(local_dual), 0), .check = check_local_dual},
    {NH_BOOL("memory", A(memory), 0), .check = check_memory},
    {NH_INT("separate_every", A(separate_every), 1, NH_AT_LEAST, 1), .check = check_separate_every},
    {NH_MAP("coarsen", coarsen_rows)},
    {0},
};

/* adapt: present (even empty) means the mesh adapts. */
int nh_read_adapt(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  const nh_yaml_node *key, *m;
  nh_read_defaults(adapt_rows, s);
  s->adapt.enabled = 0;
  s->adapt.n_goals = 0;
  if (!nh_yaml_get(root, "adapt", &key)) {
    /* no adapt section: tissue.fixed.N.refine refines by hex2, whose file
     * must then be readable (reported at the first such key) */
    s->adapt.template_path[0] = '\0';
    for (int r = 0; r < s->tissue.n_fixed; r++) {
      if (!(s->tissue.fix[r].refine > 0.0)) continue;
      char item[NH_KEY_MAX];
      snprintf(item, sizeof item, "tissue.fixed.%d.refine", r);
      const nh_yaml_node *tissue = nh_yaml_get(root, "tissue", NULL);
      const nh_yaml_node *list = tissue ? nh_yaml_get(tissue, "fixed", NULL) : NULL;
      const nh_yaml_node *at = list && list->kind == NH_YAML_SEQ && r < list->n
                                   ? nh_yaml_get(list->items[r], "refine", NULL)
                                   : NULL;
      return resolve_template(c, NULL, at ? at : list, item, "hex2", s->adapt.template_path);
    }
    return NH_OK;
  }
  s->adapt.enabled = 1;
  nh_read_where(c, key, "adapt", s->adapt.where);
  NH_TRY(nh_read_section(c, root, "", "adapt", 0, &m));
  return nh_read_table(c, m, "adapt", adapt_rows, s);
}

int nh_read_adapt_goal(const nh_ctx *c, const nh_yaml_node *root, nh_scene *s) {
  if (!s->adapt.enabled || s->adapt.estimator != NH_ESTIMATOR_GOAL) return NH_OK;
  const nh_yaml_node *m = nh_yaml_get(root, "adapt", NULL), *list = NULL;
  if (m && m->kind == NH_YAML_MAP) list = nh_yaml_get(m, "goal", NULL);
  s->adapt.n_goals = 0;
  if (!list) { /* default: every target, else every probe */
    int from = s->n_targets > 0 ? s->n_probes : 0;
    int n = s->n_targets > 0 ? s->n_targets : s->n_probes;
    if (n == 0)
      return nh_read_fail(c, nh_yaml_get(m, "estimator", NULL), "adapt.estimator",
                          "goal needs probes or targets to estimate (the scene has none)");
    if (n > NH_MAX_GOALS) n = NH_MAX_GOALS;
    for (int i = 0; i < n; i++) s->adapt.goal[s->adapt.n_goals++] = from + i;
    return NH_OK;
  }
  char d[96], item[NH_KEY_MAX], name[NH_NAME_MAX];
  if (list->kind != NH_YAML_SEQ || list->n == 0)
    return nh_read_fail(c, list, "adapt.goal", "expected a list of probe or target names, got %s",
                        nh_read_describe(list, d, sizeof d));
  if (list->n > NH_MAX_GOALS)
    return nh_read_fail(c, list, "adapt.goal", "at most %d goals, got %d", NH_MAX_GOALS, list->n);
  for (int i = 0; i < list->n; i++) {
    nh_read_index(item, "adapt.goal", i);
    NH_TRY(nh_read_string(c, list->items[i], item, name, sizeof name));
    int found = -1; /* an index into probes, then targets */
    for (int p = 0; p < s->n_probes && found < 0; p++)
      if (!strcmp(s->probes[p].name, name)) found = p;
    for (int t = 0; t < s->n_targets && found < 0; t++)
      if (!strcmp(s->targets[t].name, name)) found = s->n_probes + t;
    if (found < 0)
      return nh_read_fail(c, list->items[i], item, "no probe or target is named \"%s\"", name);
    for (int k = 0; k < s->adapt.n_goals; k++)
      if (s->adapt.goal[k] == found)
        return nh_read_fail(c, list->items[i], item, "\"%s\" is named twice", name);
    s->adapt.goal[s->adapt.n_goals++] = found;
  }
  return NH_OK;
}
