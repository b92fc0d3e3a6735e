/* tools.c — the sim module's side of the tools: the scene settings they
 * need, building them, and their outputs (tools.csv, targets.csv,
 * <tool>.pvd frames, the HDF5 series "tools" and "targets";
 * docs/outputs.md). Their step is the contact module's (nh_contact_step). */
#include "sim/sim_impl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *const nh_tool_columns[] = {"step",          "time",  "name",  "tip_x",
                                              "tip_y",         "tip_z", "depth", "axial_force",
                                              "lateral_force", "state", "twist"};
static const char *const nh_target_columns[] = {"step",
                                                "time",
                                                "name",
                                                "x",
                                                "y",
                                                "z",
                                                "distance",
                                                "error_estimate",
                                                "distance_error_estimate",
                                                "geometry_estimate",
                                                "distance_geometry_estimate",
                                                "constraint_estimate",
                                                "distance_constraint_estimate"};

/* The tools' twist is written (tools.csv `twist`, the HDF5 series'
 * component, the frames' point field) when a tool's channel resists its
 * spin: without it the twist is 0 to round-off (docs/outputs.md). */
static int nh_twist_written(const nh_scene *sc) {
  for (int k = 0; k < sc->n_tools; k++)
    if (sc->tools[k].torsion_per_length > 0) return 1;
  return 0;
}

/* How far the tool's motion has advanced it along its axis at time t. */
static double nh_tool_advance(const nh_tool_spec *tool, double t) {
  return nh_scene_motion_integral(tool, tool->n_motion, 0.0, t, 0);
}

/* A tool that travels more than a cell per step jumps over the tissue its
 * constraints should meet: a warning when one step moves it by more than
 * the smallest grid cell edge, exit 2 when by more than the tissue's whole
 * extent (nothing of the insertion would be resolved). `check` says so too. */
static int nh_sim_tools_check_travel(const nh_sim *s) {
  const nh_scene *sc = s->scene;
  const nh_mesh *m = s->mesh;
  double cell = INFINITY, extent = 0.0;
  for (int k = 0; k < 3; k++) {
    cell = fmin(cell, m->spacing[k]);
    extent = fmax(extent, m->spacing[k] * m->grid[k]);
  }
  for (int t = 0; t < sc->n_tools; t++) {
    const nh_tool_spec *tool = &sc->tools[t];
    double fastest = 0.0, travel = 0.0, h = sc->time.step;
    for (int k = 0; k < tool->n_motion; k++) fastest = fmax(fastest, fabs(tool->motion[k].speed));
    /* The largest |p(t + h) − p(t)|: piecewise linear in t, so at a breakpoint. */
    for (int k = -1; k < tool->n_motion; k++)
      for (int side = 0; side < 2; side++) {
        double t = k < 0 ? 0.0 : tool->motion[k].until - side * h;
        if (t >= 0.0)
          travel = fmax(travel, fabs(nh_tool_advance(tool, t + h) - nh_tool_advance(tool, t)));
      }
    NH_CHECK(!(travel > extent), NH_ERR_INPUT,
             "%s: moves up to %.3g m in one step (speeds up to %g m/s, time.step %g s), more "
             "than the tissue's extent (%.3g m): the insertion cannot be resolved; reduce "
             "time.step",
             tool->where, travel, fastest, sc->time.step, extent);
    if (travel > cell)
      nh_log_warn("%s: moves up to %.3g m in one step (speeds up to %g m/s, time.step %g s), "
                  "more than a grid cell (%.3g m): contacts and the cut are resolved only every "
                  "%.1f cells; reduce time.step below %.3g s",
                  tool->where, travel, fastest, sc->time.step, cell, travel / cell, cell / fastest);
  }
  return NH_OK;
}

int nh_sim_tools_build(nh_sim *s) {
  const nh_scene *sc = s->scene;
  if (sc->n_tools == 0 && !sc->tissue.skull) return NH_OK;
  const char *where = sc->n_tools > 0 ? sc->tools[0].where : sc->tissue.where_skull;
  NH_CHECK(!sc->adapt.enabled || sc->adapt.hanging == NH_HANGING_ELIMINATE, NH_ERR_INPUT,
           "%s: adapt.hanging: lagrange cannot be combined with tools (use eliminate)",
           sc->adapt.where);
  NH_TRY(nh_sim_tools_check_travel(s));
  NH_TRY(nh_contact_create(sc, s->mesh, &s->contact));
  if (s->options.restart_dir) {
    NH_CHECK(s->restore_tools, NH_ERR_INPUT,
             "%s: --restart: the checkpoint in %s holds no tool state (written by an older "
             "needlehex): run it again from the start",
             where, s->options.restart_dir);
    int rc = nh_contact_state_load(s->contact, s->restore_tools, s->restore_tools_size);
    if (rc == NH_ERR_INPUT)
      return NH_ERROR(rc, "--restart: %s: %s", s->options.restart_dir, nh_error_message());
    NH_TRY(rc);
    free(s->restore_tools);
    s->restore_tools = NULL;
  }
  s->tool_pvd = nh_calloc((size_t)(sc->n_tools ? sc->n_tools : 1), sizeof *s->tool_pvd);
  if (!s->tool_pvd) return NH_ERROR(NH_ERR_MEMORY, "out of memory: tools");
  return NH_OK;
}

void nh_sim_tools_destroy(nh_sim *s) {
  for (int k = 0; s->tool_pvd && k < s->scene->n_tools; k++) nh_pvd_destroy(&s->tool_pvd[k]);
  free(s->tool_pvd);
  nh_contact_destroy(&s->contact);
  nh_csv_destroy(&s->tools_csv);
  nh_csv_destroy(&s->targets_csv);
}

int nh_sim_tools_open(nh_sim *s) {
  const nh_scene *sc = s->scene;
  char path[NH_PATH_MAX + 2 * NH_NAME_MAX];
  const int resume = s->options.restart_dir != NULL; /* keep the rows and frames <= step */
  if (sc->n_tools > 0) {
    snprintf(path, sizeof path, "%s/tools.csv", sc->output.dir);
    const int nc = nh_twist_written(sc) ? 11 : 10;
    NH_TRY(resume ? nh_csv_resume(path, nc, nh_tool_columns, s->step, &s->tools_csv)
                  : nh_csv_create(path, nc, nh_tool_columns, &s->tools_csv));
    for (int k = 0; k < sc->n_tools; k++) {
      snprintf(path, sizeof path, "%s/%s.pvd", sc->output.dir, sc->tools[k].name);
      NH_TRY(resume ? nh_pvd_resume(sc->output.dir, sc->tools[k].name, sc->time.step, s->step,
                                    &s->tool_pvd[k])
                    : nh_pvd_create(path, &s->tool_pvd[k]));
    }
  }
  if (sc->n_targets > 0) {
    snprintf(path, sizeof path, "%s/targets.csv", sc->output.dir);
    int goal = sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL;
    int nc = goal ? 13 : 7;
    NH_TRY(resume ? nh_csv_resume(path, nc, nh_target_columns, s->step, &s->targets_csv)
                  : nh_csv_create(path, nc, nh_target_columns, &s->targets_csv));
  }
  return NH_OK;
}

int nh_sim_tools_rows(nh_sim *s) {
  const nh_scene *sc = s->scene;
  int rc = NH_OK;
  if (sc->n_tools > 0) {
    const int twist = nh_twist_written(sc), nv = twist ? 8 : 7;
    double *vals = nh_calloc((size_t)nv * (size_t)sc->n_tools, sizeof *vals);
    const char **names = nh_calloc((size_t)sc->n_tools, sizeof *names);
    if (!vals || !names) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: tool rows");
    for (int k = 0; k < sc->n_tools && !rc; k++) {
      nh_tool_report r;
      nh_contact_report(s->contact, k, &r);
      const double tw = twist ? nh_beam_twist(nh_contact_beam(s->contact, k), NULL) : 0.0;
      rc = twist ? nh_csv_row(s->tools_csv,
                              "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%s,%.17g", s->step,
                              s->time, sc->tools[k].name, r.tip[0], r.tip[1], r.tip[2], r.depth,
                              r.axial_force, r.lateral_force, nh_tool_state_name(r.state), tw)
                 : nh_csv_row(s->tools_csv, "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%s",
                              s->step, s->time, sc->tools[k].name, r.tip[0], r.tip[1], r.tip[2],
                              r.depth, r.axial_force, r.lateral_force, nh_tool_state_name(r.state));
      double *v = vals + nv * k;
      v[0] = r.tip[0], v[1] = r.tip[1], v[2] = r.tip[2], v[3] = r.depth;
      v[4] = r.axial_force, v[5] = r.lateral_force, v[6] = r.state;
      if (twist) v[7] = tw;
      names[k] = sc->tools[k].name;
    }
    static const char *const comps[] = {"tip_x",       "tip_y",         "tip_z", "depth",
                                        "axial_force", "lateral_force", "state", "twist"};
    if (!rc && s->h5)
      rc = nh_h5_append_series(s->h5, "tools", s->step, s->time, sc->n_tools, names, nv, comps,
                               vals);
    free(vals);
    free(names);
  }
  if (!rc && sc->n_targets > 0) {
    double *vals = nh_calloc(4 * (size_t)sc->n_targets, sizeof(double));
    const char **names = nh_calloc((size_t)sc->n_targets, sizeof(char *));
    if (!vals || !names) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: target rows");
    for (int i = 0; i < sc->n_targets && !rc; i++) {
      const nh_target *tg = &sc->targets[i];
      double x[3], d[3];
      nh_sim_target_miss(s, i, x, d);
      double dist = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      if (sc->adapt.enabled && sc->adapt.estimator == NH_ESTIMATOR_GOAL) {
        double geo, geo_d, con, con_d;
        nh_sim_target_geometry_error(s, i, &geo, &geo_d);
        nh_sim_target_constraint_error(s, i, &con, &con_d);
        rc = nh_csv_row(s->targets_csv,
                        "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g",
                        s->step, s->time, tg->name, x[0], x[1], x[2], dist,
                        nh_sim_point_error(s, sc->n_probes + i), nh_sim_target_distance_error(s, i),
                        geo, geo_d, con, con_d);
      } else
        rc = nh_csv_row(s->targets_csv, "%d,%.17g,%s,%.17g,%.17g,%.17g,%.17g", s->step, s->time,
                        tg->name, x[0], x[1], x[2], dist);
      vals[4 * i] = x[0], vals[4 * i + 1] = x[1], vals[4 * i + 2] = x[2], vals[4 * i + 3] = dist;
      names[i] = tg->name;
    }
    static const char *const comps[] = {"x", "y", "z", "distance"};
    if (!rc && s->h5)
      rc = nh_h5_append_series(s->h5, "targets", s->step, s->time, sc->n_targets, names, 4, comps,
                               vals);
    free(vals);
    free(names);
  }
  return rc;
}

int nh_sim_tools_frame(nh_sim *s) {
  int rc = NH_OK;
  for (int k = 0; k < s->scene->n_tools && !rc; k++) {
    nh_beam *b = nh_contact_beam(s->contact, k);
    const int nn = nh_beam_nodes(b);
    /* nn - 1 two-node VTK_LINE cells, base to tip (meshio drops poly-lines) */
    int *conn = nh_calloc(2 * (size_t)nn, sizeof *conn), *off = nh_calloc((size_t)nn, sizeof *off);
    double *f = nh_calloc(3 * (size_t)nn, sizeof *f), *vel = nh_calloc(3 * (size_t)nn, sizeof *vel);
    double *arc = nh_calloc((size_t)nn, sizeof *arc), *twist = nh_calloc((size_t)nn, sizeof *twist);
    if (!conn || !off || !f || !vel || !arc || !twist)
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: tool frame");
    if (!rc) {
      const double *v = nh_beam_velocities(b);
      nh_contact_node_forces(s->contact, k, f);
      for (int i = 0; i + 1 < nn; i++) {
        conn[2 * i] = i, conn[2 * i + 1] = i + 1;
        off[i] = 2 * (i + 1);
      }
      for (int i = 0; i < nn; i++) {
        arc[i] = nh_beam_length(b) * i / (nn - 1);
        for (int c = 0; c < 3; c++) vel[3 * i + c] = v[6 * i + c];
      }
      nh_beam_twist(b, twist);
      const nh_field pf[4] = {{"constraint_force", 3, f, "N"},
                              {"velocity", 3, vel, "m/s"},
                              {"arc_length", 1, arc, "m"},
                              {"twist", 1, twist, "rad"}};
      const nh_frame frame = {.n_points = nn,
                              .points = nh_beam_positions(b),
                              .n_cells = nn - 1,
                              .connectivity = conn,
                              .offsets = off,
                              .type = NH_VTK_LINE,
                              .n_point_fields = nh_twist_written(s->scene) ? 4 : 3,
                              .point_fields = pf};
      rc = nh_pvd_write_frame(s->tool_pvd[k], s->step, s->time, &frame);
    }
    free(conn), free(off), free(f), free(vel), free(arc), free(twist);
  }
  return rc;
}
