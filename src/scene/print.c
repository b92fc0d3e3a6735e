/* print.c — the summary `needlehex check` prints: what the scene will
 * model (domain, material, loads, tools and their planned motion, adapt,
 * outputs), with every value as read and resolved, a function per
 * section. */
#include "scene/scene.h"

#include <math.h>
#include <stdio.h>

static void print_box(FILE *f, const double min[3], const double max[3]) {
  fprintf(f, "[%g, %g, %g] .. [%g, %g, %g] m", min[0], min[1], min[2], max[0], max[1], max[2]);
}

/* ", schedule [[t, s], ...]" (nothing for the constant 1). */
static void print_schedule(FILE *f, const nh_schedule *sch) {
  if (sch->n == 0) return;
  fprintf(f, ", schedule [");
  for (int i = 0; i < sch->n; ++i)
    fprintf(f, "%s[%g, %g]", i ? ", " : "", sch->t[i], sch->value[i]);
  fprintf(f, "]");
}

/* "box [..] .. [..] m", "sphere centre [..] m, radius r m", "cylinder ...". */
static void print_region(FILE *f, const nh_region *r) {
  if (r->kind == NH_REGION_LABEL) {
    fprintf(f, "the voxels of label %d", r->label);
  } else if (r->kind == NH_REGION_SPHERE) {
    fprintf(f, "sphere centre [%g, %g, %g] m, radius %g m", r->center[0], r->center[1],
            r->center[2], r->radius);
  } else if (r->kind == NH_REGION_CYLINDER) {
    fprintf(f, "cylinder [%g, %g, %g] .. [%g, %g, %g] m, radius %g m", r->start[0], r->start[1],
            r->start[2], r->end[0], r->end[1], r->end[2], r->radius);
  } else {
    fprintf(f, "box ");
    print_box(f, r->min, r->max);
  }
}

/* One tool, over a few lines indented under "tools". */
static void print_tool(FILE *f, const nh_scene *s, int i) {
  const nh_tool_spec *t = &s->tools[i];
  fprintf(f, "          %s: length %g m, radius %g m", t->name, t->length, t->radius);
  if (t->inner_radius > 0)
    fprintf(f, ", inner radius %g m (tube)", t->inner_radius);
  else
    fprintf(f, " (solid)");
  fprintf(f, ", %d beam element%s\n", t->elements, t->elements == 1 ? "" : "s");
  fprintf(
      f, "            E = %g Pa, nu = %g, density %g kg/m^3; damping mass %g 1/s, stiffness %g s\n",
      t->young, t->poisson, t->density, t->damping_mass, t->damping_stiffness);
  if (t->planned) {
    const nh_target *g = &s->targets[t->target];
    fprintf(f,
            "            trajectory from entry [%g, %g, %g] m to target %s [%g, %g, %g] m, "
            "standoff %g m: planned depth %.9g m\n",
            t->entry[0], t->entry[1], t->entry[2], g->name, g->point[0], g->point[1], g->point[2],
            t->standoff, t->depth);
    if (t->aimed)
      fprintf(f, "            aimed at [%.9g, %.9g, %.9g] m (trajectory.aim), not at the target\n",
              t->aim[0], t->aim[1], t->aim[2]);
  }
  fprintf(f, "            base [%g, %g, %g] m, direction [%g, %g, %g]\n", t->base[0], t->base[1],
          t->base[2], t->direction[0], t->direction[1], t->direction[2]);
  if (t->n_motion == 0) fprintf(f, "            motion none (at rest)\n");
  for (int k = 0; k < t->n_motion; ++k) {
    static const char *const word[] = {"", " (until: target)", " (until: start)"};
    const nh_motion *m = &t->motion[k];
    fprintf(f, "            %s %g m/s", k == 0 ? "motion" : "      ", m->speed);
    if (m->spin != 0) fprintf(f, ", spin %g rad/s", m->spin);
    fprintf(f, " until %.*g s%s%s\n", m->kind == NH_UNTIL_TIME ? 6 : 9, m->until, word[m->kind],
            k + 1 == t->n_motion ? ", then at rest" : "");
  }
  if (t->bevel > 0) {
    fprintf(f, "            bevel %g deg, the tip bends towards ", t->bevel);
    if (nh_vec3_norm(t->bevel_toward) > 0)
      fprintf(f, "[%g, %g, %g] at t = 0\n", t->bevel_toward[0], t->bevel_toward[1],
              t->bevel_toward[2]);
    else
      fprintf(f, "the tool's default second director at t = 0\n");
  }
  fprintf(f,
          "            puncture %g N, cutting %g N, friction mu %g (static %g) plus %g N/m, path "
          "points every ",
          t->puncture_force, t->cutting_force, t->friction, t->friction_static,
          t->friction_per_length);
  if (t->spacing > 0)
    fprintf(f, "%g m\n", t->spacing);
  else
    fprintf(f, "one cell edge\n");
  if (t->inside >= 0) {
    fprintf(f, "            inside %s, ", s->tools[t->inside].name);
    if (isfinite(t->release))
      fprintf(f, "released at %.*g s%s\n", t->release_target ? 9 : 6, t->release,
              t->release_target ? " (release: target, the end of its host's until: target)" : "");
    else
      fprintf(f, "never released\n");
  }
}

/* The scene, its clock and gravity. */
static void print_time(FILE *f, const nh_scene *s) {
  fprintf(f, "scene     %s (%s)\n", s->name, s->file);
  fprintf(f, "time      %s, %d steps of %g s (end %g s)\n",
          s->time.mode == NH_MODE_STATIC ? "static" : "dynamic", s->time.steps, s->time.step,
          s->time.steps * s->time.step);
  fprintf(f, "gravity   [%g, %g, %g] m/s^2", s->gravity[0], s->gravity[1], s->gravity[2]);
  print_schedule(f, &s->gravity_schedule);
  fprintf(f, "\n");
}

/* The tissue's domain and grid, and its label image. */
static void print_domain(FILE *f, const nh_scene *s) {
  if (s->tissue.domain == NH_DOMAIN_BRAIN) {
    const double *z = s->tissue.brain_size, *c = s->tissue.brain_center;
    fprintf(f, "tissue    brain of size [%g, %g, %g] m centred at [%g, %g, %g] m\n", z[0], z[1],
            z[2], c[0], c[1], c[2]);
    fprintf(f, "          grid %d x %d x %d cells over its bounding box ", s->tissue.grid[0],
            s->tissue.grid[1], s->tissue.grid[2]);
    print_box(f, s->tissue.box_min, s->tissue.box_max);
    fprintf(f, " (the cells that meet the brain are kept)\n");
  } else if (s->tissue.domain == NH_DOMAIN_MASK || s->tissue.domain == NH_DOMAIN_SURFACE) {
    if (s->tissue.domain == NH_DOMAIN_MASK) {
      fprintf(f, "tissue    mask %s, labels", s->tissue.mask_file);
      for (int i = 0; i < s->tissue.n_mask_labels; ++i)
        fprintf(f, "%s %d", i ? "," : "", s->tissue.mask_labels[i]);
      fprintf(f, "\n");
    } else {
      fprintf(f, "tissue    surface %s (%g m per file unit)\n", s->tissue.surface_file,
              s->tissue.surface_unit);
    }
    fprintf(f,
            "          grid %d x %d x %d cells over its bounding box (the cells that meet it "
            "are kept)\n",
            s->tissue.grid[0], s->tissue.grid[1], s->tissue.grid[2]);
  } else {
    fprintf(f, "tissue    box ");
    print_box(f, s->tissue.box_min, s->tissue.box_max);
    fprintf(f, ", grid %d x %d x %d cells (%d nodes)\n", s->tissue.grid[0], s->tissue.grid[1],
            s->tissue.grid[2],
            (s->tissue.grid[0] + 1) * (s->tissue.grid[1] + 1) * (s->tissue.grid[2] + 1));
  }
  if (s->tissue.labels_file[0]) fprintf(f, "labels    %s\n", s->tissue.labels_file);
}

/* The tissue's material(s), damping, buoyancy and skull. */
static void print_material(FILE *f, const nh_scene *s) {
  fprintf(f, "material  E = %g Pa, nu = %g, density %g kg/m^3%s, %s hexahedra\n", s->tissue.young,
          s->tissue.poisson, s->tissue.density,
          s->tissue.n_materials ? " (voxels of other labels)" : "",
          s->tissue.formulation == NH_FORMULATION_FULL ? "fully integrated" : "B-bar");
  for (int i = 0; i < s->tissue.n_materials; ++i) {
    const nh_label_material *m = &s->tissue.materials[i];
    fprintf(f, "          label %d: E = %g Pa, nu = %g, density %g kg/m^3\n", m->label, m->young,
            m->poisson, m->density);
  }
  fprintf(f, "damping   mass %g 1/s, stiffness %g s\n", s->tissue.damping_mass,
          s->tissue.damping_stiffness);
  if (s->tissue.buoyant) {
    fprintf(f, "buoyancy  before %g, after %g of the weight", s->tissue.buoyancy_before,
            s->tissue.buoyancy_after);
    if (s->tissue.buoyancy_has_level)
      fprintf(f, ", fluid level through [%g, %g, %g]", s->tissue.buoyancy_level[0],
              s->tissue.buoyancy_level[1], s->tissue.buoyancy_level[2]);
    if (s->tissue.buoyancy_schedule.n > 0)
      print_schedule(f, &s->tissue.buoyancy_schedule);
    else
      fprintf(f, ", changed at t = 0");
    fprintf(f, "; the tissue carries (before - b(t)) of its weight\n");
  }
  if (s->tissue.skull)
    fprintf(f, "skull     rigid, frictionless, CSF gap %g m\n", s->tissue.skull_gap);
}

/* Fixed regions, loads and tractions. */
static void print_regions(FILE *f, const nh_scene *s) {
  fprintf(f, "fixed     %d region%s\n", s->tissue.n_fixed, s->tissue.n_fixed == 1 ? "" : "s");
  for (int i = 0; i < s->tissue.n_fixed; ++i) {
    const nh_fix *fx = &s->tissue.fix[i];
    fprintf(f, "          tissue.fixed.%d: ", i);
    print_region(f, &s->tissue.fixed[i]);
    if (fx->axes != 7)
      fprintf(f, ", axes%s%s%s", fx->axes & 1 ? " x" : "", fx->axes & 2 ? " y" : "",
              fx->axes & 4 ? " z" : "");
    if (fx->displacement[0] != 0.0 || fx->displacement[1] != 0.0 || fx->displacement[2] != 0.0)
      fprintf(f, ", displacement [%g, %g, %g] m", fx->displacement[0], fx->displacement[1],
              fx->displacement[2]);
    if (fx->schedule.n > 0)
      fprintf(f, ", schedule of %d point%s", fx->schedule.n, fx->schedule.n == 1 ? "" : "s");
    if (fx->refine > 0.0)
      fprintf(f, ", its cells refined to edges <= %g m before the first step", fx->refine);
    fprintf(f, "\n");
  }
  fprintf(f, "loads     %d\n", s->tissue.n_loads);
  for (int i = 0; i < s->tissue.n_loads; ++i) {
    const nh_load *l = &s->tissue.loads[i];
    fprintf(f, "          tissue.loads.%d: force [%g, %g, %g] N over ", i, l->force[0], l->force[1],
            l->force[2]);
    print_region(f, &l->region);
    if (l->schedule.n > 0)
      fprintf(f, ", schedule of %d point%s", l->schedule.n, l->schedule.n == 1 ? "" : "s");
    fprintf(f, "\n");
  }
  if (s->tissue.n_tractions > 0) fprintf(f, "tractions %d\n", s->tissue.n_tractions);
  for (int i = 0; i < s->tissue.n_tractions; ++i) {
    const nh_traction *t = &s->tissue.tractions[i];
    if (t->is_pressure)
      fprintf(f, "          tissue.tractions.%d: pressure %g N/m² on the boundary in ", i,
              t->pressure);
    else
      fprintf(f, "          tissue.tractions.%d: traction [%g, %g, %g] N/m² on the boundary in ", i,
              t->traction[0], t->traction[1], t->traction[2]);
    print_region(f, &t->region);
    if (t->schedule.n > 0)
      fprintf(f, ", schedule of %d point%s", t->schedule.n, t->schedule.n == 1 ? "" : "s");
    fprintf(f, "\n");
  }
}

/* Adaptivity: estimator, marking, template and limits. */
static void print_adapt(FILE *f, const nh_scene *s) {
  const nh_adapt_spec *a = &s->adapt;
  if (!a->enabled) {
    fprintf(f, "adapt     no (the mesh stays fixed)\n");
    return;
  }
  fprintf(f, "adapt     estimator %s, every %d step%s; marking ",
          a->estimator == NH_ESTIMATOR_GOAL ? "goal" : "spr", a->every, a->every == 1 ? "" : "s");
  if (a->strategy == NH_MARK_DORFLER)
    fprintf(f, "dorfler, fraction %g of the total squared error\n", a->fraction);
  else
    fprintf(f, "max, theta %g of the largest error%s\n", a->theta,
            a->estimator != NH_ESTIMATOR_GOAL         ? ""
            : a->goal_marking == NH_GOAL_MARKING_EACH ? " of each goal"
                                                      : " of the goals' sum");
  if (a->estimator == NH_ESTIMATOR_GOAL && a->goal_leaves)
    fprintf(f, "          and every leaf meeting a goal's box, up to max_level\n");
  fprintf(f, "          template %s\n", a->template_path);
  fprintf(f, "          max_level %d, min_size ", a->max_level);
  if (a->min_size > 0)
    fprintf(f, "%g m", a->min_size);
  else
    fprintf(f, "none");
  if (a->max_dofs > 0)
    fprintf(f, ", max_dofs %d", a->max_dofs);
  else
    fprintf(f, ", max_dofs none");
  fprintf(f, ", hanging nodes %s\n", a->hanging == NH_HANGING_LAGRANGE ? "lagrange" : "eliminate");
  if (a->estimator == NH_ESTIMATOR_GOAL) {
    fprintf(f, "          goal:");
    for (int i = 0; i < a->n_goals; i++) {
      int g = a->goal[i];
      fprintf(f, " %s", g < s->n_probes ? s->probes[g].name : s->targets[g - s->n_probes].name);
    }
    fprintf(f, "; tolerance ");
    if (a->tolerance > 0)
      fprintf(f, "%g m", a->tolerance);
    else
      fprintf(f, "none");
    fprintf(f, ", resolve %d%s, separate duals every %d estimates%s%s, graded (2:1)\n", a->resolve,
            a->resolve_tip ? " (and at the tools' tips)" : "", a->separate_every,
            a->local_dual ? ", local dual at held rows" : "",
            a->memory ? ", memory of the dynamic steps" : "");
  }
  if (a->coarsen > 0)
    fprintf(f, "          coarsen below %g of the marking threshold\n", a->coarsen);
}

/* The solver. */
static void print_solver(FILE *f, const nh_scene *s) {
  fprintf(f, "solver    tolerance %g, at most %d iterations, ", s->solver.tolerance,
          s->solver.max_iterations);
  if (s->solver.threads > 0)
    fprintf(f, "%d thread%s, ", s->solver.threads, s->solver.threads == 1 ? "" : "s");
  else
    fprintf(f, "all cores, ");
  fprintf(f, "refactor %s", s->solver.refactor == NH_REFACTOR_EVERY ? "every step" : "auto");
  if (s->solver.lazy_rotation > 0) fprintf(f, ", lazy tangents %g", s->solver.lazy_rotation);
  fputc('\n', f);
}

/* Probes and targets. */
static void print_points(FILE *f, const nh_scene *s) {
  fprintf(f, "probes    %d\n", s->n_probes);
  for (int i = 0; i < s->n_probes; ++i)
    fprintf(f, "          %s at [%g, %g, %g] m\n", s->probes[i].name, s->probes[i].point[0],
            s->probes[i].point[1], s->probes[i].point[2]);
  fprintf(f, "targets   %d\n", s->n_targets);
  for (int i = 0; i < s->n_targets; ++i) {
    const nh_target *t = &s->targets[i];
    fprintf(f, "          %s at [%g, %g, %g] m, distance to the tip of %s\n", t->name, t->point[0],
            t->point[1], t->point[2], s->tools[t->tool].name);
  }
}

/* The output folder and what goes into it. */
static void print_output(FILE *f, const nh_scene *s) {
  if (s->output.every > 0)
    fprintf(f, "output    %s, a frame every %d step%s, hdf5 %s\n", s->output.dir, s->output.every,
            s->output.every == 1 ? "" : "s", s->output.hdf5 ? "yes" : "no");
  else
    fprintf(f, "output    %s, the last step only, hdf5 %s\n", s->output.dir,
            s->output.hdf5 ? "yes" : "no");
  static const char *const how[] = {"auto", "linear", "nearest"};
  const int n_field = s->output.displacement_field.n_at, n_warp = s->output.warped.n_at;
  if (s->output.displacement_field.reference[0]) {
    fprintf(f, "          displacement field on %s at", s->output.displacement_field.reference);
    for (int k = 0; k < n_field; ++k) fprintf(f, " %g s,", s->output.displacement_field.at[k]);
    fprintf(f, " the last step\n");
  }
  if (s->output.warped.image[0]) {
    fprintf(f, "          warped %s (interpolation %s) at", s->output.warped.image,
            how[s->output.warped.interpolation]);
    for (int k = 0; k < n_warp; ++k) fprintf(f, " %g s,", s->output.warped.at[k]);
    fprintf(f, " the last step\n");
  }
}

void nh_scene_print(const nh_scene *s, void *stdio_file) {
  FILE *f = stdio_file ? stdio_file : stdout;
  print_time(f, s);
  print_domain(f, s);
  print_material(f, s);
  print_regions(f, s);
  print_adapt(f, s);
  print_solver(f, s);
  fprintf(f, "tools     %d\n", s->n_tools);
  for (int i = 0; i < s->n_tools; ++i) print_tool(f, s, i);
  print_points(f, s);
  print_output(f, s);
}
