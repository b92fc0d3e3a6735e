/* sim — the step loop: builds the model a scene names, advances it, probes
 * it, times every phase and writes the outputs of docs/outputs.md. */
#ifndef NH_SIM_H
#define NH_SIM_H

#include "core/core.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "scene/scene.h"
#include "solve/solve.h"

typedef struct nh_sim nh_sim;

typedef struct {
  int dry_run;             /* build and validate only: no output folder, no files (`check`) */
  int progress;            /* print a progress line and a summary on stderr */
  const char *restart_dir; /* continue from DIR/checkpoint.nhc (NULL: start at rest) */
  int overwrite;           /* remove a previous run's outputs from the folder first (else: a
                              folder holding them is refused, NH_ERR_INPUT) */
} nh_sim_options;

/* Build mesh, tissue, loads, probes and the linear system for `scene`
 * (borrowed: it must outlive the simulation), and unless dry_run create the
 * output folder and write the initial frame (step 0). A fresh run (no
 * restart_dir) into a folder holding a previous run's outputs fails with
 * NH_ERR_INPUT unless options->overwrite, which removes them first.
 * Fails with NH_ERR_INPUT for scene errors only the mesh reveals (a fixed
 * region with no node, a load region with no tissue, a probe outside the
 * tissue: message FILE:LINE: KEY: reason), NH_ERR_IO, NH_ERR_MEMORY. */
int nh_sim_create(const nh_scene *scene, const nh_sim_options *options, nh_sim **out);
void nh_sim_destroy(nh_sim **sim);

/* Advance one step (and write its rows and, when due, its frame).
 * Fails with NH_ERR_NUMERIC / NH_ERR_IO; the message names the step. */
int nh_sim_step(nh_sim *sim);
/* Run every remaining step, with progress and a closing summary if asked.
 * After nh_sim_request_stop (a signal handler may call it) the run stops
 * within the current step (its long loops poll the request; the state goes
 * back to the last complete step) or after it, writes a final frame and a
 * checkpoint, and returns NH_ERR_INTERRUPTED with the command that
 * continues it. */
int nh_sim_run(nh_sim *sim);
/* Ask running simulations to stop (async-signal-safe; nh_stop_request). */
void nh_sim_request_stop(int signal_number);

/* Inspection (tests, tools). */
const nh_mesh *nh_sim_mesh(const nh_sim *sim);
const nh_tissue *nh_sim_tissue(const nh_sim *sim);
nh_system *nh_sim_system(nh_sim *sim);
double *nh_sim_displacements(nh_sim *sim); /* u = x − X, 3 per node (writable: tests set states) */
double *nh_sim_velocities(nh_sim *sim);    /* v, 3 per node */
const unsigned char *nh_sim_fixed(const nh_sim *sim);
/* External force at time t (3 per node): loads by their schedules + M g(t),
 * g(t) the tissue's body acceleration (gravity by its schedule, less the
 * buoyed part: nh_scene_tissue_gravity). */
void nh_sim_external_force(const nh_sim *sim, double t, double *f);
int nh_sim_step_index(const nh_sim *sim);
double nh_sim_time(const nh_sim *sim);
/* Displacement of probe i (interpolated in its cell). */
void nh_sim_probe_displacement(const nh_sim *sim, int i, double u[3]);
/* Target i (scene order) now: its current position x (m; a material point,
 * like a probe) and the miss = tip of its tool − x (m; targets.csv's
 * distance is |miss|). The scene must have tools. */
void nh_sim_target_miss(const nh_sim *sim, int i, double x[3], double miss[3]);
/* Under adapt.estimator goal, target i a goal: the estimated error of its
 * tip–target distance (m, ≥ 0; the magnitude of nh_dwr_distance_estimate
 * from the target's goal estimate of this step's solution), else NaN
 * (targets.csv `distance_error_estimate`). */
double nh_sim_target_distance_error(const nh_sim *sim, int i);
/* Under adapt.estimator goal, target i a goal: the geometry term's part of
 * its estimates (dwr.c, "Geometry"): |G| of the position (m) and |−n · G|
 * of the distance (m); 0 without cut cells, NaN otherwise or after a
 * combined estimate (targets.csv `geometry_estimate`,
 * `distance_geometry_estimate`). */
void nh_sim_target_geometry_error(const nh_sim *sim, int i, double *position, double *distance);
/* The same for the constraint-data term (dwr.c, "Constraint data";
 * targets.csv `constraint_estimate`, `distance_constraint_estimate`): 0
 * without rows whose data change (no skull), NaN as above. */
void nh_sim_target_constraint_error(const nh_sim *sim, int i, double *position, double *distance);
/* Refine the n leaves cells[] by the scene's adapt.template, as a
 * refinement after a step would: u and v carried to the new nodes
 * (Eq. 17), everything that depends on the mesh rebuilt, the tools'
 * embedded points relocated. For tests that rebuild a mesh a run made.
 * Fails with NH_ERR_INPUT without an adapt section, as nh_mesh_refine,
 * NH_ERR_MEMORY. */
int nh_sim_refine_cells(nh_sim *sim, const int *cells, int n);
/* Kinetic energy ½ vᵀ M v. */
double nh_sim_kinetic_energy(const nh_sim *sim);
/* Median seconds per step of each phase so far (assemble, factor, solve,
 * constraints, tools, guard, adapt, output, step: steps.csv's t_* columns). */
#define NH_SIM_PHASES 9
void nh_sim_median_times(const nh_sim *sim, double t[NH_SIM_PHASES]);

#endif
