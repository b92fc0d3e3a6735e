/* sim_impl.h — private to the sim module: the simulation state (sim.c owns
 * it) and the functions of the module's other files, in their dependency
 * order (docs/design.md, "Modules", sim): probes.c, guard.c, checkpoint.c and
 * progress.c call none of the others, setup.c and tools.c call probes.c,
 * sim.c calls them all. The files below sim.c read the state they are given; none calls
 * back into sim.c. */
#ifndef NH_SIM_IMPL_H
#define NH_SIM_IMPL_H

#include "adapt/adapt.h"
#include "contact/contact.h"
#include "io/io.h"
#include "sim/sim.h"

enum {
  NH_PHASE_ASSEMBLE,
  NH_PHASE_FACTOR,
  NH_PHASE_SOLVE,
  NH_PHASE_CONSTRAINTS,
  NH_PHASE_TOOLS,
  NH_PHASE_GUARD,
  NH_PHASE_ADAPT,
  NH_PHASE_OUTPUT,
  NH_PHASE_STEP,
  NH_PHASES
};
_Static_assert(NH_PHASES == NH_SIM_PHASES, "sim.h counts the phases");

typedef struct {
  double t_start, t_last_print;
  int is_tty, printed;
} nh_progress;

struct nh_sim {
  const nh_scene *scene;
  nh_sim_options options;
  nh_mesh *mesh;
  nh_tissue *tissue;
  nh_system *system;
  nh_integrator integrator;
  unsigned char *fixed; /* per node: its fixed components (nh_fixed_component) */
  int *moved;        /* per node: the tissue.fixed item that prescribes its displacement (−1) */
  double *u, *v;     /* displacement and velocity, 3 per node */
  double *x;         /* current positions X + u, for output */
  double *f_ext;     /* 3 per node, work */
  double *drained;   /* per node: the lumped mass that loses buoyancy (tissue above the
                        fluid level; the whole mass without tissue.buoyancy.level) */
  double *load_unit; /* (n_loads + n_tractions) x 3 n: nodal forces of each load, then each
                        traction, at factor 1 */
  int *probe_cell;   /* embedded points: the probes, then the targets */
  double *probe_xi;  /* 3 per point */
  int step;          /* steps done */
  int first_step;    /* the step this process started from (the checkpoint's, or 0) */
  double time;
  double *phase_times; /* NH_PHASES per step */
  int cap_steps;
  /* adaptivity (absent: all NULL / 0) */
  nh_adapt *adapt; /* template, marking, indicators */
  nh_hanging *hanging;
  double eta, eta_rel;
  double t_adapt;  /* s, this step: estimate + mark + refine + rebuild */
  double *u_start; /* u at the start of the step (the guard's increment) */
  double *v_start; /* v at the start of the step (a step interrupted inside goes back to it) */
  int inverted;    /* cells inverted after the last step (steps.csv `inverted`) */
  int unsolved_steps, unsolved_first; /* steps left unsolved (steps.csv `unsolved`), the first */
  int guard_warned;                   /* bit per kind of invalid step already warned about */
  /* estimator goal: goal index of each embedded point (−1: not a goal), the
   * largest estimate so far (summary) and its point */
  int *goal_of_point;
  double max_goal_error;
  int max_goal_point;
  /* tools (absent: contact NULL) */
  nh_contact *contact;
  nh_csv *tools_csv, *targets_csv;
  nh_pvd **tool_pvd;
  /* outputs */
  nh_csv *steps_csv, *probes_csv;
  nh_pvd *tissue_pvd, *points_pvd;
  nh_h5 *h5;                 /* results.h5 when output.hdf5 */
  nh_image *field_reference; /* output.displacement_field.reference (header; NULL: none) */
  nh_image *warp_image;      /* output.warped.image (NULL: none) and its voxel values */
  double *warp_values;
  int warp_nearest; /* resampled by the nearest label, else trilinear */
  int mask_written; /* tissue_mask.nii.gz written */
  int last_frame;
  nh_progress progress;
  unsigned char *restore_tools; /* --restart: the checkpoint's tool state until applied */
  size_t restore_tools_size;
  unsigned char *restore_solver; /* --restart: the checkpoint's factor reuse until applied */
  size_t restore_solver_size;
  unsigned char *restore_adapt; /* --restart: the goal estimate's carried state until applied */
  size_t restore_adapt_size;
  unsigned char *tools_start; /* the tools' state at the start of the step (a step */
  size_t tools_start_size;    /* interrupted inside goes back to it) */
  nh_bytes solver_start;      /* the factor reuse at the start of the step (solver.refactor auto) */
  int solver_past;            /* the step was interrupted inside: the system's reuse state is
                                 past the last complete step, a checkpoint takes solver_start */
};

/* ---- checkpoints (sim/checkpoint.c) ---- */
/* A checkpoint read back: the mesh (owned), u, v (owned), step and time,
 * the tools' state (owned; NULL without tools) and the solver's. */
typedef struct {
  nh_mesh *mesh;
  double *u, *v;
  int step;
  double time;
  unsigned char *tools;
  size_t tools_size;
  unsigned char *solver; /* the factor reuse (owned; NULL before format 3) */
  size_t solver_size;
  unsigned char *adapt; /* the goal estimate's carried state (owned; NULL before format 8) */
  size_t adapt_size;
} nh_checkpoint;

/* The scene as run (sc->yaml) with every file it names (tissue mask,
 * surface and labels files, adapt.template when a path) replaced by the
 * absolute path of the file the reader resolved, as a double-quoted
 * string: what DIR/scene.yaml holds, so that the printed continue command
 * works from any folder, and what a checkpoint's scene hash is taken of
 * (docs/outputs.md, "Restart"). Output *out (the caller frees). */
int nh_scene_text_absolute(const nh_scene *sc, char **out);
/* DIR/checkpoint.nhc */
void nh_checkpoint_path(const char *dir, char *path, size_t size);
/* Write the run's state to <output.dir>/checkpoint.nhc, atomically. */
int nh_checkpoint_write(const nh_sim *sim);
/* Read DIR/checkpoint.nhc for `scene`; NH_ERR_INPUT for a foreign,
 * corrupted or other-scene file. */
int nh_checkpoint_read(const char *dir, const nh_scene *scene, nh_checkpoint *ck);

/* ---- embedded points: probes, then targets (sim/probes.c) ---- */
/* Locate every embedded point in the mesh (its cell and natural
 * coordinates). A point outside the tissue: NH_ERR_INPUT naming the scene's
 * key at creation (first), NH_ERR_INTERNAL after a refinement. */
int nh_sim_locate_points(nh_sim *sim, int first);
/* Current position of embedded point i (probes, then targets). */
void nh_sim_point_position(const nh_sim *sim, int i, double x[3]);
/* Estimated error of embedded point i's displacement (m): the goal estimate
 * of this step's solution, NaN if the point is no goal or none was made. */
double nh_sim_point_error(const nh_sim *sim, int i);

/* ---- step guards (sim/guard.c) ---- */
/* Cells with det J <= 0 at a corner or Gauss point of their deformed shape
 * (*first: the first one, or -1). */
int nh_sim_count_inverted(const nh_sim *sim, int *first);
/* Check the step just solved (u, v; u_start: u before it; st: its stats):
 * non-finite values, inverted cells (sets sim->inverted), an implausible
 * increment, a tool inside tissue it has left, a dynamic step whose Newton
 * iterations left it unsolved (nh_sim_step_guarded). NH_ERR_NUMERIC naming
 * the step and the reason, or with solver.on_invalid: warn a warning and
 * NH_OK. */
int nh_sim_guard(nh_sim *sim, const double *u_start, const nh_step_stats *st);
/* The step's relative residual stayed above its bound (*bound: the Newton
 * tolerance in static mode and with solver.newton, else
 * NH_UNSOLVED_LINEAR) and above the round-off level of its internal forces
 * (steps.csv `unsolved`, which sim.c counts). */
int nh_sim_step_unsolved(const nh_sim *sim, const nh_step_stats *st, double *bound);
/* An unsolved step the guard judges: a dynamic step whose Newton iterations
 * were allowed (not solver.newton.max_iterations 0, one linearisation
 * asked for). */
int nh_sim_step_guarded(const nh_sim *sim);

/* ---- the progress line and the summary (sim/progress.c) ---- */
void nh_progress_start(nh_sim *sim);
void nh_progress_update(nh_sim *sim);
/* The summary; median: seconds per step of each phase (nh_sim_median_times). */
void nh_progress_finish(nh_sim *sim, const double median[NH_PHASES]);

/* ---- what depends on the mesh (sim/setup.c) ---- */
/* Build everything that depends on the mesh: at creation (first = 1, which
 * also reports scene errors only the mesh reveals, NH_ERR_INPUT) and after
 * refinement (the tools' embedded points relocated too). Fails as the
 * builders it calls, NH_ERR_MEMORY. */
int nh_sim_setup_mesh(nh_sim *sim, int first);
/* tissue.fixed.N.refine: refine the new mesh's leaves by adapt.template
 * (2:1 graded) until no leaf is coarser than N.refine at region N
 * (nh_mesh_cell_coarser_at), before anything depends on the mesh.
 * NH_ERR_INPUT (at the region) beyond limits.max_cells, as
 * nh_template_load and nh_mesh_refine. */
int nh_sim_refine_fixed(nh_sim *sim);
/* The drainage plane of tissue.buoyancy.level, {level, −g/|g|} (the drained
 * mass is the tissue above it): 1, or 0 (plane untouched) without one. */
int nh_sim_drainage_plane(const nh_scene *scene, double plane[6]);

/* ---- tools (sim/tools.c) ---- */
/* Create the tools (NULL contact without tools) and their outputs' handles. */
int nh_sim_tools_build(nh_sim *sim);
void nh_sim_tools_destroy(nh_sim *sim);
/* Outputs: open tools.csv, targets.csv and the tool PVDs; rows of this step;
 * the tool frames of this step. */
int nh_sim_tools_open(nh_sim *sim);
int nh_sim_tools_rows(nh_sim *sim);
int nh_sim_tools_frame(nh_sim *sim);

/* ---- outputs on the patient's images (sim/patient.c) ---- */
/* Read the images output.displacement_field and output.warped name (at
 * creation: a bad one stops the run before its first step). Fails as
 * nh_image_read. */
int nh_sim_patient_open(nh_sim *sim);
void nh_sim_patient_close(nh_sim *sim);
/* This step's displacement field and warped image when one of their times
 * falls in it or it is the last; at the last step the tools' axes and the
 * targets as Slicer markups. Fails with NH_ERR_IO, NH_ERR_MEMORY. */
int nh_sim_patient_write(nh_sim *sim);

#endif
