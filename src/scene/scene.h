/* scene — reading a YAML scene (libyaml) into validated plain structs in SI
 * units, with defaults and `--set KEY=VALUE` overrides by dotted path.
 *
 * docs/scene.md lists every key, its type, default and unit. Every
 * error is NH_ERR_INPUT with one message of the form
 *     FILE:LINE: KEY: what is wrong
 * where KEY is the dotted path (e.g. tissue.material.poisson) and, for an
 * override, FILE:LINE is "--set" and the override's position (e.g.
 * "--set:2: tissue.grid: ..."). Values that other modules validate later
 * (e.g. a fixed region that contains no node) carry their `where` string so
 * those modules can report in the same form. */
#ifndef NH_SCENE_H
#define NH_SCENE_H

#include "core/core.h"

#define NH_NAME_MAX  64
#define NH_WHERE_MAX 320 /* "FILE:LINE: KEY" */
#define NH_PATH_MAX  1024

typedef enum { NH_MODE_DYNAMIC = 0, NH_MODE_STATIC = 1 } nh_time_mode;
/* The tissue element's stiffness: B-bar (mean dilatation: the deviatoric
 * part by 2x2x2 Gauss points, the volumetric part with the element's mean
 * volume change; docs/theory.md §2b) or fully integrated (locks as ν → 0.5). */
typedef enum { NH_FORMULATION_BBAR = 0, NH_FORMULATION_FULL = 1 } nh_formulation;

/* How cells cut by an immersed domain's boundary are integrated
 * (tissue.cut_cells, docs/theory.md §5c): scaled by their fill fraction φ,
 * or by the finite cell quadrature over their tissue part. */
typedef enum { NH_CUT_CELLS_SCALED = 0, NH_CUT_CELLS_INTEGRATED = 1 } nh_cut_cells;
/* The skull's contact rows (tissue.skull.rows, docs/theory.md §5c): one per
 * surface point of a cut leaf, or one weighted-gap row per tissue node near
 * the surface (mortar-type averaging of the gap over the surface quadrature). */
typedef enum { NH_SKULL_ROWS_POINTS = 0, NH_SKULL_ROWS_MORTAR = 1 } nh_skull_rows_kind;

typedef enum {
  NH_REGION_BOX = 0,
  NH_REGION_SPHERE = 1,
  NH_REGION_CYLINDER = 2,
  NH_REGION_LABEL = 3
} nh_region_kind;
typedef enum {
  NH_DOMAIN_BOX = 0,
  NH_DOMAIN_BRAIN = 1,
  NH_DOMAIN_MASK = 2,    /* tissue.domain.mask: labelled voxels of a NIfTI image */
  NH_DOMAIN_SURFACE = 3, /* tissue.domain.surface: a closed triangulated surface (STL) */
  NH_DOMAIN_SPHERE = 4   /* a ball, built by tests only (nh_domain_sphere): no scene key */
} nh_domain_kind;

/* A region of space (closed): exactly one of box, sphere, cylinder, label. */
typedef struct {
  nh_region_kind kind;
  double min[3], max[3];   /* box: inclusive bounds */
  double center[3];        /* sphere: centre */
  double start[3], end[3]; /* cylinder: the two ends of its axis (distinct) */
  double radius;           /* sphere, cylinder: > 0 */
  int label;               /* label: the voxels of the scene's label image holding it */
  char where[NH_WHERE_MAX];
} nh_region;

/* A piecewise-linear factor of time: (t[i], value[i]) sorted by t; constant
 * beyond both ends. n == 0 means the constant 1. */
typedef struct {
  int n;
  double *t, *value;
} nh_schedule;

typedef struct {
  nh_region region;
  double force[3];      /* total force, N */
  nh_schedule schedule; /* loads[i].schedule: [[t0, s0], [t1, s1], ...] */
  char where[NH_WHERE_MAX];
} nh_load;

/* tissue.fixed[i]'s options besides its region: which components it fixes
 * and a prescribed displacement of those components. */
typedef struct {
  int axes;               /* bit k set: component k fixed (7 without `axes`: all) */
  double displacement[3]; /* prescribed displacement, m, times the schedule (default 0) */
  nh_schedule schedule;   /* fixed[i].schedule (only with displacement) */
  double refine; /* fixed[i].refine: largest edge of a cell meeting the region, m (0: none) */
} nh_fix;

/* tissue.tractions[i]: a surface load on the tissue's boundary inside a
 * region: a traction vector (N/m², the same on every face) or a pressure p
 * (N/m², traction −p n with n the outward normal), times a schedule. */
typedef struct {
  nh_region region;
  double traction[3];   /* traction, N/m² (when !is_pressure) */
  double pressure;      /* pressure, N/m² (when is_pressure) */
  int is_pressure;      /* given as pressure */
  nh_schedule schedule; /* tractions[i].schedule */
  char where[NH_WHERE_MAX];
} nh_traction;

typedef struct {
  char name[NH_NAME_MAX];
  double point[3];
  char where[NH_WHERE_MAX];
} nh_probe;

/* How a motion segment's `until` was written (tools[i].motion[k].until). */
typedef enum {
  NH_UNTIL_TIME = 0,   /* a number, as written */
  NH_UNTIL_TARGET = 1, /* `until: target`: the tip has travelled the planned depth */
  NH_UNTIL_START = 2   /* `until: start`: the tip is back at its t = 0 position */
} nh_until_kind;

/* One segment of a tool's motion: insertion speed (m/s along `direction`;
 * negative: retraction; any finite value) and base spin (rad/s about
 * `direction`) until time `until` (s). The first
 * `until` is > 0 and the following ones increase strictly, so segment k holds
 * from the previous `until` (0 for k = 0) to its own; after the last one the
 * speed is 0. A symbolic `until` (target, start) is a time here, resolved
 * when the scene is read. */
typedef struct {
  double until, speed;
  double spin;        /* rad/s about the tool's axis, right-handed (default 0, finite) */
  nh_until_kind kind; /* how `until` was given; a symbolic one is resolved to a time at load */
} nh_motion;

/* tools[i]: a needle, cannula or electrode (a corotational beam). */
typedef struct {
  /* tools[i].name (required, [A-Za-z0-9_-]): it names the output files <name>.pvd, so it is
     unique even ignoring case and is not tissue or points (any case) */
  char name[NH_NAME_MAX];
  double length;            /* tools[i].length, m (required, > 0) */
  double radius;            /* tools[i].radius, m (required, > 0) */
  double inner_radius;      /* tools[i].inner_radius, m (default 0: solid; in [0, radius)) */
  int elements;             /* tools[i].elements (default 16, >= 1) */
  double young;             /* tools[i].material.young, Pa (required, > 0) */
  double poisson;           /* tools[i].material.poisson (default 0.3, in (-1, 0.5)) */
  double density;           /* tools[i].material.density, kg/m³ (default 7800, >= 0) */
  double damping_mass;      /* tools[i].damping.mass (Rayleigh α, default 0, >= 0) */
  double damping_stiffness; /* tools[i].damping.stiffness (Rayleigh β, default 0, >= 0) */
  double base[3];           /* tools[i].base, m (required unless trajectory): base at t = 0 */
  double direction[3]; /* tools[i].direction (required unless trajectory, non-zero; unit length) */
  /* tools[i].trajectory {entry, target, standoff, aim} (optional; then base and direction
     are computed from it, and must not be given): direction = unit(aim − entry), the tip at
     t = 0 at entry − standoff · direction; aim is the target's point unless given (the
     compensated aim of `needlehex plan`) */
  int planned;     /* the tool has a trajectory */
  double entry[3]; /* trajectory.entry, m */
  int target;      /* trajectory.target: index in targets (-1: no trajectory) */
  double standoff; /* trajectory.standoff, m (default 0.005, > 0) */
  double aim[3];   /* trajectory.aim, m (default: the target's point) */
  int aimed;       /* trajectory.aim was given */
  double depth;    /* the planned depth D = standoff + |aim − entry|, m */
  int n_motion;    /* tools[i].motion: list of {until, speed, spin} (default: none, at rest) */
  nh_motion *motion;
  double puncture_force;  /* tools[i].interaction.puncture_force, N (default 0, >= 0) */
  double cutting_force;   /* tools[i].interaction.cutting_force, N (default 0, >= 0) */
  double friction;        /* tools[i].interaction.friction, kinetic Coulomb μ (default 0, >= 0) */
  double friction_static; /* tools[i].interaction.friction_static, static μ_s: the threshold
                             to start sliding (default friction, >= friction) */
  double friction_per_length; /* tools[i].interaction.friction_per_length, N/m (default 0, >= 0) */
  double torsion_per_length;  /* tools[i].interaction.torsion_per_length, N·m/m: the channel's
                                 torsional friction (default 0, >= 0; dynamic mode only) */
  double spacing; /* tools[i].interaction.spacing: path-point spacing, m (default 0: one local
                     cell edge; >= 0) */
  double bevel;   /* tools[i].bevel.angle ψ, degrees (default 0: symmetric tip; in [0, 90)) */
  double bevel_toward[3];   /* tools[i].bevel.toward: the side the tip bends to at t = 0, unit and
                               orthogonal to direction (default: the beam's default d2) */
  int inside;               /* tools[i].inside: index of the host tool (-1: none); the host
                               must be another tool listed before this one, not itself nested */
  double release;           /* tools[i].release, s (>= 0; default +inf: never; only with inside) */
  int release_target;       /* release: target, resolved to the end of the host's until: target */
  char where[NH_WHERE_MAX]; /* "FILE:LINE: tools.i" */
} nh_tool_spec;

/* targets[i]: a material point whose distance to a tool's tip is recorded. */
typedef struct {
  char name[NH_NAME_MAX]; /* targets[i].name (required, unique; no commas, quotes or tabs) */
  double point[3];        /* targets[i].point, m (required) */
  int tool;               /* index of targets[i].tool in tools (required, must name a tool) */
  char where[NH_WHERE_MAX];
} nh_target;

/* tissue.materials.LABEL: the material of the voxels holding LABEL. */
typedef struct {
  int label;
  double young, poisson, density;
  char where[NH_WHERE_MAX]; /* "FILE:LINE: tissue.materials.LABEL" */
} nh_label_material;

typedef enum { NH_MARK_MAX = 0, NH_MARK_DORFLER = 1 } nh_mark_strategy;
typedef enum { NH_HANGING_ELIMINATE = 0, NH_HANGING_LAGRANGE = 1 } nh_hanging_method;
typedef enum { NH_REFACTOR_AUTO = 0, NH_REFACTOR_EVERY = 1 } nh_refactor_mode;
typedef enum { NH_ESTIMATOR_SPR = 0, NH_ESTIMATOR_GOAL = 1 } nh_estimator;
typedef enum { NH_GOAL_MARKING_SUM = 0, NH_GOAL_MARKING_EACH = 1 } nh_goal_marking;

/* Most goal quantities adapt.goal may name. */
#define NH_MAX_GOALS 64

/* The adapt section: estimation, marking, template, limits (adapt/refine.c). */
typedef struct {
  int enabled;                  /* the scene has an `adapt` section */
  nh_mark_strategy strategy;    /* adapt.marking.strategy: max (default) | dorfler */
  double theta;                 /* adapt.marking.theta (max): in (0, 1), default 0.3 */
  double fraction;              /* adapt.marking.fraction (dorfler): in (0, 1], default 0.5 */
  nh_goal_marking goal_marking; /* adapt.marking.goals (goal, max): sum (default) | each */
  int goal_leaves; /* adapt.marking.goal_leaves (goal): the leaves meeting a goal's box are
                      marked below max_level (default 0) */
  char template_path[NH_PATH_MAX]; /* adapt.template resolved to a file (default hex2) */
  int max_level;                   /* adapt.max_level: >= 0, default 2 */
  double min_size;                 /* adapt.min_size: m, >= 0, default 0 (no limit) */
  int max_dofs;                    /* adapt.max_dofs: >= 0, default 0 (no budget) */
  int every;                       /* adapt.every: >= 1, default 1 */
  nh_hanging_method hanging;       /* adapt.hanging: eliminate (default) | lagrange */
  nh_estimator estimator;          /* adapt.estimator: spr (default) | goal */
  int n_goals;                     /* goal: the embedded points adapt.goal names ... */
  int goal[NH_MAX_GOALS]; /* ... as indices into probes, then targets (default: every target,
                             else every probe) */
  double tolerance;       /* adapt.tolerance, m, on each goal's estimate (>= 0; 0: none) */
  int resolve;            /* adapt.resolve: re-solves of a step on its refined mesh (>= 0) */
  int resolve_tip;        /* adapt.resolve_tip: goal only, re-solve while the refinement splits
                             a leaf holding a tool's tip (default 1) */
  int local_dual;         /* adapt.local_dual: goal only, the local enriched dual where a goal's
                             leaf holds a tool's rows (dwr_local.c; default 0) */
  int memory;             /* adapt.memory: goal only, the dynamic steps' memory term
                             (dwr_memory.c; default 0) */
  int separate_every; /* adapt.separate_every: every N-th goal estimate solves each goal's duals,
                         the others one combined dual (>= 1, default 1) */
  double coarsen;     /* adapt.coarsen.fraction (0: no coarsening; in (0, 1)) */
  char where[NH_WHERE_MAX];          /* "FILE:LINE: adapt" */
  char where_template[NH_WHERE_MAX]; /* "FILE:LINE: adapt.template" */
} nh_adapt_spec;

/* output.displacement_field.at, output.warped.at: at most this many times */
#define NH_OUTPUT_AT_MAX 64
typedef enum {
  NH_INTERPOLATION_AUTO,
  NH_INTERPOLATION_LINEAR,
  NH_INTERPOLATION_NEAREST
} nh_interpolation;

typedef struct nh_scene {
  char file[NH_PATH_MAX]; /* the scene file as given */
  char name[NH_NAME_MAX]; /* name (required) */

  struct {
    nh_time_mode mode; /* time.mode: dynamic (default) | static */
    double step;       /* time.step, s (default 0.01) */
    double end;        /* time.end, s, as given (0: not given; steps is what a run uses) */
    int steps; /* number of steps: time.steps, or round(time.end / time.step); default 100 */
  } time;

  double gravity[3];            /* gravity (or gravity.vector), m/s² (default 0) */
  nh_schedule gravity_schedule; /* gravity.schedule: its factor of time (default: 1) */

  struct {
    nh_domain_kind domain; /* tissue.domain: box | brain | mask | surface (exactly one, required) */
    double box_min[3], box_max[3];         /* the domain's bounding box: tissue.domain.box, or
                                              brain.center ± brain.size / 2 */
    double brain_center[3], brain_size[3]; /* tissue.domain.brain: center (default 0), size */
    /* tissue.domain.mask {file, labels}: the NIfTI file (resolved against the scene's folder)
       and the labels whose voxels are the tissue; the same image is the label image */
    char mask_file[NH_PATH_MAX];
    int n_mask_labels;
    int *mask_labels;
    /* tissue.domain.surface {file, unit}: STL file (resolved), metres per file unit (default
       0.001: millimetres) */
    char surface_file[NH_PATH_MAX];
    double surface_unit;
    /* tissue.labels {file}: a label image for tissue.materials and {label: N} regions on a
       box, brain or surface domain (mask domains use the mask's image) */
    char labels_file[NH_PATH_MAX];
    char where_domain[NH_WHERE_MAX]; /* "FILE:LINE: tissue.domain.mask" (or .surface) */
    char where_labels[NH_WHERE_MAX]; /* "FILE:LINE: tissue.domain.mask.labels" / tissue.labels */
    int n_materials;
    nh_label_material *materials; /* tissue.materials: {LABEL: {young, poisson, density}} */
    int grid[3];                  /* tissue.grid (default [8, 4, 4]); each >= 1 */
    double young;   /* tissue.material.young, Pa (required, > 0): every voxel without a material */
    double poisson; /* tissue.material.poisson (required, in (-1, 0.5)) */
    double density; /* tissue.material.density, kg/m³ (default 1000, > 0) */
    nh_formulation formulation; /* tissue.material.formulation: bbar (default) | full */
    nh_cut_cells cut_cells;     /* tissue.cut_cells: scaled (default) | integrated */
    double damping_mass;        /* tissue.damping.mass (Rayleigh α, 1/s, default 0, >= 0) */
    double damping_stiffness;   /* tissue.damping.stiffness (Rayleigh β, s, default 0, >= 0) */
    /* tissue.buoyancy {before, after, schedule} (optional): the rest shape is the equilibrium
       under gravity with the fraction `before` of the weight carried by buoyancy, so the
       tissue's body force is ρ g (before − b(t)), b(t) = before + (after − before) s(t)
       (docs/theory.md, "Buoyancy and brain shift") */
    int buoyant;                   /* the scene has tissue.buoyancy */
    double buoyancy_before;        /* tissue.buoyancy.before, in [0, 1] (required) */
    double buoyancy_after;         /* tissue.buoyancy.after, in [0, 1] (required) */
    nh_schedule buoyancy_schedule; /* tissue.buoyancy.schedule (default: 1 from t = 0 on) */
    int buoyancy_has_level;        /* tissue.buoyancy.level given */
    double buoyancy_level[3];      /* tissue.buoyancy.level: a point of the fluid level (the
                                      plane normal to gravity); only tissue above it drains */
    int skull;                     /* tissue.skull given (immersed domains, dynamic mode) */
    double skull_gap; /* tissue.skull.gap, m (default 0, >= 0): the CSF gap to the skull */
    nh_skull_rows_kind skull_rows; /* tissue.skull.rows: points (default) | mortar */
    char where_skull[NH_WHERE_MAX];
    int n_fixed;
    nh_region *fixed; /* tissue.fixed: list of {box | sphere | cylinder, axes?, displacement?,
                         schedule?} */
    nh_fix *fix;      /* the options of each, n_fixed of them */
    int n_loads;
    nh_load *loads; /* tissue.loads: list of {box | sphere | cylinder, force, schedule?} */
    int n_tractions;
    nh_traction *tractions; /* tissue.tractions: {box | sphere | cylinder, traction | pressure,
                               schedule?} */
    char where_fixed[NH_WHERE_MAX];
  } tissue;

  struct {
    double tolerance;   /* solver.tolerance: static Newton relative residual (default 1e-8) */
    int max_iterations; /* solver.max_iterations: static Newton (default 30) */
    int threads;        /* solver.threads: OpenMP threads, 0 = all cores (default 0) */
    nh_refactor_mode refactor; /* solver.refactor: auto (default) | every */
    double lazy_rotation;      /* solver.lazy_rotation: lazy tangents' tolerance (default 0) */
    int on_invalid_warn;       /* solver.on_invalid: stop (0, default) | warn (1) */
    int newton_iterations;     /* solver.newton.max_iterations (dynamic; default 0: none) */
    int newton_given;          /* solver.newton given: its count holds (0: one linearisation);
                                  else a step left unsolved iterates (nh_step_coupled) */
    double newton_tolerance;   /* solver.newton.tolerance (default 1e-8) */
  } solver;

  nh_adapt_spec adapt;

  struct {
    int max_cells; /* limits.max_cells: cap on tissue cells, lattice and refined (default 2e6) */
    nh_read_limits read; /* limits.max_voxels, .max_triangles, .max_file_bytes: what a file the
                            scene names may hold (core.h's defaults) */
  } limits;

  int n_probes;
  nh_probe *probes; /* probes: list of {name, point} */

  int n_tools;
  nh_tool_spec *tools; /* tools: list (absent: tissue only) */
  int n_targets;
  nh_target *targets; /* targets: list of {name, point, tool} */

  /* plan: what `needlehex plan` keeps a bevel-tip needle clear of (docs/cases.md, "Planning
     the steering") */
  struct {
    int n_obstacles;
    nh_region *obstacles;     /* plan.obstacles: list of {box | sphere | cylinder | label} */
    double clearance;         /* plan.clearance, m: from the tool's axis to their surfaces (default
                                 0.001, >= 0) */
    double curvature;         /* plan.curvature, 1/m: the bicycle model's (default 0: estimated from
                                 the wheelbase, then fitted to the plan's first run; >= 0) */
    char where[NH_WHERE_MAX]; /* "FILE:LINE: plan" (empty without the section) */
  } plan;

  struct {
    char dir[NH_PATH_MAX]; /* output.dir (default "out/<name>") */
    int every;             /* output.every: frame every N steps, 0 = last step only (default 1) */
    int hdf5;              /* output.hdf5: results.h5 + results.xdmf (default false) */
    int checkpoint;        /* output.checkpoint: a restart file every N steps, 0 = none (default) */
    struct {
      char reference[NH_PATH_MAX]; /* output.displacement_field.reference: a NIfTI image whose
                                      voxel centres get the field (resolved; "" = none) */
      int n_at;
      double at[NH_OUTPUT_AT_MAX]; /* .at: times (s); the last step writes too */
    } displacement_field;
    struct {
      char image[NH_PATH_MAX]; /* output.warped.image: the image to shift (resolved; "" = none) */
      int n_at;
      double at[NH_OUTPUT_AT_MAX];    /* .at: times (s); the last step writes too */
      nh_interpolation interpolation; /* .interpolation: auto (default) | linear | nearest */
    } warped;
  } output;

  char *yaml; /* the scene as run, overrides applied, as YAML text (owned) */
} nh_scene;

/* Read and validate the scene `path` and apply the overrides
 * `overrides[0..n_overrides)`, each "dotted.path=VALUE" where VALUE is a YAML
 * flow scalar or sequence (e.g. "tissue.grid=[16,8,8]",
 * "tools.0.interaction.friction=0.1"). A path that names no key of the
 * schema, or an index beyond a list, is an error. An override may add a key
 * that the file leaves out.
 * Output: *out, to be freed with nh_scene_destroy.
 * Fails with NH_ERR_INPUT (message FILE:LINE: KEY: reason) on an unreadable
 * file, malformed YAML, an unknown key, a wrong type, a missing required key,
 * or a value out of range; NH_ERR_MEMORY on allocation failure. */
int nh_scene_load(const char *path, int n_overrides, const char *const *overrides, nh_scene **out);

/* Free a scene and set *scene = NULL (accepts NULL). */
void nh_scene_destroy(nh_scene **scene);

/* Value of a schedule at time t (1 if the schedule is empty). */
double nh_schedule_eval(const nh_schedule *s, double t);

/* Gravity at time t: the vector `gravity` times its schedule (m/s²). This is
 * what the tools carry (their full weight: they are not buoyed). */
void nh_scene_gravity(const nh_scene *scene, double t, double g[3]);

/* The body acceleration of the tissue at time t (m/s²; the body force per
 * unit volume is ρ φ times it): nh_scene_gravity without tissue.buoyancy,
 * else nh_scene_gravity × (before − b(t)), b(t) = before + (after − before)
 * s(t), the change of the buoyed fraction since the rest shape. */
void nh_scene_tissue_gravity(const nh_scene *scene, double t, double g[3]);

/* ---- trajectory planning (trajectory.c) ---- */
/* The integral over [from, t] of the speed (spin = 0: the distance travelled
 * along the direction, m) or of the spin (spin = 1: the base's turn about it,
 * rad) of the tool's first n motion segments (n <= n_motion, untils
 * resolved; at rest after them). The one definition of a tool's motion: the
 * contact module moves the tools by it, symbolic untils are resolved by it. */
double nh_scene_motion_integral(const nh_tool_spec *tool, int n, double from, double t, int spin);
/* The distance tools[i]'s tip has travelled along its direction by time t,
 * from its first n motion segments (n <= n_motion; untils of those segments
 * resolved): a nested tool moves with its host until its release and by its
 * own segments after, an outer tool by its own segments. */
double nh_scene_tip_travel(const nh_scene *scene, int i, int n, double t);
/* A planned trajectory from tool->entry to `target` (its aim): sets tool->direction
 * (unit), tool->depth = standoff + distance and tool->base (the tip
 * standoff before the entry point). Returns NH_ERR_INPUT, without a message
 * and with the tool untouched, if the target is the entry point. */
int nh_scene_trajectory_line(nh_tool_spec *tool, const double target[3]);

/* Estimated peak memory (bytes) of a run on `cells` hexahedra: a model
 * fitted to measured peaks of static runs on cube grids of 16³, 24³ and 32³
 * cells (101.7, 407, 1185 MB; the model gives 101.7, 421, 1185 MB):
 * 13.5 kB per cell (element data, the assembled matrix) plus 708 B ×
 * cells^(1/3) per cell (the fill of the sparse Cholesky factor, which for a
 * 3-D grid grows like n^(4/3)). Tools, adaptivity and refinement add to it. */
double nh_scene_memory_estimate(double cells);
/* ---- the key table (keys.c) ---- */
/* Every scene key with its type, default, unit and notes, from the key
 * tables of docs/scene.md compiled into the program (`needlehex keys`). */
void nh_scene_keys_print(void *stdio_file);

/* NH_OK if every key of `allowed` (NULL-terminated) under the section `path`
 * (dotted, "" for the top level, list indices as numbers) has a row in
 * docs/scene.md's tables; else NH_ERR_INTERNAL naming the first that has
 * not (the reader must not accept an undocumented key). */
int nh_scene_keys_check(const char *path, const char *const *allowed);

/* Print a human-readable summary of what will be modelled (for `check`). */
void nh_scene_print(const nh_scene *scene, void *stdio_file);

#endif
