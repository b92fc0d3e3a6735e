/* plan_impl.h — private to the plan module: the bevel-tip (steering)
 * planner's parts, shared by its files.
 *
 *   plan.c      the command: target compensation of straight tools (Broyden
 *               on the aim), and the dispatch to the steering planner
 *   steer.c     the steering planner: the unknowns q (the kinematic plan's
 *               virtual target and clearance), the model refitted to the runs
 *   trust.c     its iteration on q: Broyden from the best run, in a trust
 *               region on the depths' change
 *   bicycle.c   the kinematic (bicycle) model of a bevel-tip needle in its
 *               plane: arcs of curvature ±κ, the two-arc closed form, the
 *               plan of least excursion that keeps a clearance
 *   obstacle.c  plan.obstacles: the signed distance from a point to each one's
 *               surface, the clearance of a path
 *   runs.c      one round of candidate runs (in this process, or as child
 *               processes `needlehex run`, --workers N) and what a run's
 *               folder says: the tip path (tools.csv), the miss (targets.csv)
 *
 * docs/cases.md, "Planning the steering" explains the method. */
#ifndef NH_PLAN_IMPL_H
#define NH_PLAN_IMPL_H

#include "anatomy/anatomy.h"
#include "plan/plan.h"
#include "scene/scene.h"

#include <stdio.h>

enum { NH_BIKE_MAX_ARCS = 3 }; /* at most two turns */

/* ---- bicycle.c: the kinematic model in the needle's plane ----
 * Plane coordinates: x along the insertion direction, y towards the bevel at
 * t = 0, origin at the entry point; the tip's path is a chain of circular
 * arcs of curvature σ_j κ (σ_j = ±1, alternating: each turn flips the
 * bevel), lengths ℓ_j (the depth in the tissue is their running sum). */
typedef struct {
  int n;                        /* arcs (1 + turns) */
  double sign0;                 /* σ_0: +1 the bevel's side at t = 0, −1 after a turn at 0 */
  double len[NH_BIKE_MAX_ARCS]; /* ℓ_j, m */
  double roll; /* θ: the last turn spins the base by π + θ (right-handed about the heading),
                  so the last arc turns by θ about the tangent there, out of the plane */
} nh_bike_plan;

/* End point (x, y) and heading of a plan with the curvatures κ_j of its
 * arcs (kappa[0 .. NH_BIKE_MAX_ARCS)). */
void nh_bike_end(const nh_bike_plan *p, const double *kappa, double end[2], double *heading);
/* The point at depth s (arc length from the entry, clamped to the plan's
 * length) and, if not NULL, the heading there. */
void nh_bike_point(const nh_bike_plan *p, const double *kappa, double s, double xy[2],
                   double *heading);
/* The roll's lever: the plan's last turn (before its last arc, n >= 2) at
 * point turn[] with heading h, and the plan's planar end e (roll 0):
 * along = (e − turn)·t, lever = (e − turn)·m, t = (cos h, sin h) and m =
 * (−sin h, cos h) its left normal. A roll θ turns the last arc about the
 * tangent line, so the end is turn + along t + lever (cos θ m + sin θ e_z):
 * ∂z_end/∂θ = lever cos θ (docs/cases.md, "Out of the plane"). Returns 0
 * when the plan has no turn (n = 1: no roll), else 1. */
int nh_bike_roll_lever(const nh_bike_plan *p, const double *kappa, double turn[2], double *heading,
                       double *along, double *lever);
/* End point of a plan with its roll: x, y in the plane, z along e_z = e_x ×
 * e_y (the formula above; the planar end when n = 1). */
void nh_bike_end3(const nh_bike_plan *p, const double *kappa, double end[3]);
/* The two-arc finish: from (x0, y0) with heading θ0, an arc of curvature
 * σκ_a then one of −σκ_b that ends at `target`; their lengths in len[2],
 * the first the shorter of the two solutions. 0 on success, −1 when the
 * target cannot be reached so (its distance from the first arc's centre is
 * not in [a, a + 2b], a = 1/κ_a, b = 1/κ_b). */
int nh_bike_finish(const double start[2], double heading, double sign, double kappa_a,
                   double kappa_b, const double target[2], double len[2]);

/* The obstacles of the plan in the plane's frame: the entry E and the axes
 * (x = direction, y = bevel side) map plane points to the world. */
typedef struct nh_obstacles nh_obstacles;
typedef struct {
  double entry[3], ex[3], ey[3];
  double kappa[NH_BIKE_MAX_ARCS]; /* κ_j of the plans' arcs j, 1/m */
  const nh_obstacles *obstacles;  /* may be NULL */
  int side;                       /* 0: the first arc on either side; ±1: only σ_0 = side */
  int turns; /* 0: one or two turns; 1 or 2: only plans with that many (with side, the
                planner keeps the homotopy class of its first plan around the obstacles) */
} nh_bike_frame;

/* What the kinematic planner chose for a virtual target a and clearance c*. */
typedef struct {
  nh_bike_plan plan;
  double clearance; /* the model path's clearance from the obstacles (m; +inf without) */
  int active;       /* the clearance constraint decided the plan (= c*) */
  double excursion; /* the largest distance of the model path from the chord E → a, m */
} nh_bike_choice;

/* The kinematic plan reaching `target` (plane coordinates) with at most two
 * turns and a model clearance >= `clearance` from the frame's obstacles:
 * the one-turn plan (first arc on either side) of least excursion that
 * keeps it, else the two-turn plan (first arc length scanned, then the
 * two-arc finish) of least excursion (f->side, f->turns: only plans with
 * that first side and number of turns); when the clearance decides (the
 * scan's neighbour of smaller excursion does not keep it), the first arc is
 * bisected to clearance = `clearance` exactly (active = 1), so the plan is a
 * smooth function of target and clearance. exact: only such plans (two
 * turns, clearance = `clearance`). 0 on success, −1 when there is none. */
int nh_bike_choose(const nh_bike_frame *f, const double target[2], double clearance, int exact,
                   nh_bike_choice *out);
/* Clearance of the model path of plan p (sampled every 0.2 mm). */
double nh_bike_clearance(const nh_bike_frame *f, const nh_bike_plan *p);
/* Fit the arcs' curvatures kappa[j] (in: the current ones, out: fitted) to
 * a measured tip path (n points: plane coordinates xy[2 i], depth s[i]) of
 * the schedule p, arc after arc: κ_j minimises the squared distance between
 * the model's points (earlier arcs at their fitted curvatures) and the
 * measured ones at the depths of arc j, by golden section on log κ_j in
 * [κ_j / 20, 20 κ_j]; an arc with fewer than 4 points keeps its κ, arcs
 * beyond the plan's take the last one's. */
void nh_bike_fit(const nh_bike_plan *p, int n, const double *xy, const double *s, double *kappa);

/* Largest change of a turn depth or of the final depth between two plans
 * (m); +inf when they differ in their number of arcs or first side. */
double nh_bike_depth_change(const nh_bike_plan *a, const nh_bike_plan *b);

/* ---- trust.c: Broyden's method in a trust region (the theory at its top) ---- */
enum { NH_TRUST_Q = 4, NH_TRUST_MAX_POINTS = 256 };
typedef struct {
  double radius, radius_min, radius_max; /* Δ and its bounds (the caller's length unit) */
  double J[NH_TRUST_Q * NH_TRUST_Q];     /* the last step's Jacobian */
  double t, length;                      /* the last step: fraction of d taken, its length */
  double rho;                            /* the last judged step's ratio ρ */
  double skip;                           /* secants less new than this (|u|/|s|) are skipped */
  int pending;                           /* a step not yet judged */
  int model_only;                        /* the next step with J = I */
} nh_trust;
/* The caller's length of the step q_b + t d (+inf where it has none). */
typedef double (*nh_trust_length)(void *ctx, const double *qb, const double *d, double t);
void nh_trust_init(nh_trust *tr, double radius, double radius_min, double radius_max);
/* J = I updated with the secants of points q[NH_TRUST_Q i], residuals F[NH_TRUST_Q i] (ok[i]:
 * it has one) against point `best`, nearest first (n unknowns used). */
void nh_trust_jacobian(int n, int m, const double *q, const double *F, const int *ok, int best,
                       double skip, double J[NH_TRUST_Q * NH_TRUST_Q]);
/* The next point from `best`: Broyden's step, shortened to the radius;
 * components n.. of out are q_b's. −1 when no fraction of it is short
 * enough. */
int nh_trust_step(nh_trust *tr, int n, int m, const double *q, const double *F, const int *ok,
                  int best, nh_trust_length length, void *ctx, double out[NH_TRUST_Q]);
/* Judge the last step by its point's merit (+inf: failed) against the best
 * merit before it, and update the radius. */
void nh_trust_judge(nh_trust *tr, double merit_best, double merit);

/* ---- obstacle.c ---- */
/* The scene's plan.obstacles (labels read from the scene's label image).
 * NH_ERR_INPUT (the image, a label it does not hold), NH_ERR_MEMORY. */
int nh_obstacles_create(const nh_scene *scene, nh_obstacles **out);
void nh_obstacles_destroy(nh_obstacles **obstacles);
int nh_obstacles_count(const nh_obstacles *obstacles);
/* Signed distance from world point x to the surface of obstacle i (< 0
 * inside): exact for spheres, finite cylinders and boxes; for a label, the
 * distance to the nearest voxel box of the region (its surface voxels),
 * negative inside a voxel of it. */
double nh_obstacle_distance(const nh_obstacles *obstacles, int i, const double x[3]);
/* Clearance of a path of n world points: the least signed distance of a
 * point to any obstacle (+inf without obstacles); *which = that obstacle
 * (may be NULL). */
double nh_obstacles_clearance(const nh_obstacles *obstacles, int n, const double *x, int *which);

/* ---- runs.c ---- */
/* One candidate: the overrides that make it (after the user's) and where it
 * runs. */
typedef struct {
  char dir[NH_PATH_MAX + 32];
  int n_sets;
  char **sets; /* owned */
} nh_candidate;

/* What a finished run's folder says about tool `tool` and target `target`. */
typedef struct {
  double tip[3], target[3], miss[3], distance; /* the last step's */
  double twist;                                /* the tool's twist at the last step, rad */
  int n;                                       /* tip path: rows with depth > 0 */
  double *path;                                /* 3 per row, world */
  double *depth;                               /* per row, m */
  double *time;                                /* per row, s */
  double seconds;                              /* wall time of the run */
  int failed;        /* the simulation failed (exit 1): nothing else is set */
  char message[512]; /* then why */
} nh_run_result;

void nh_run_result_free(nh_run_result *r);
/* Run the candidates c[0..n): in this process one after another (workers
 * <= 1), else as up to `workers` concurrent child processes `needlehex run
 * SCENE --set ... --out DIR --overwrite --quiet` with OMP_NUM_THREADS=1,
 * killed if this process dies. Then read each folder into res[i] (the tool
 * and the target by name). A simulation that fails (exit 1: e.g. a
 * constraint solve that stalls) sets res[i].failed and its message (a
 * child's stderr is kept in DIR.log); a bad scene (exit 2), a folder that
 * cannot be read or a process that cannot be started is returned as the
 * error. */
int nh_runs_execute(const char *scene_path, int n_user, const char *const *user_sets, int n,
                    const nh_candidate *c, int workers, const char *tool, const char *target,
                    nh_run_result *res);
void nh_candidate_free(nh_candidate *c);
/* Append an override (printf format) to a candidate; NH_ERR_MEMORY. */
int nh_candidate_set(nh_candidate *c, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

/* ---- plan.c: plan.yaml, shared by both planners ---- */
/* "[x, y, z]" to full precision. */
void nh_plan_put_vec(FILE *f, const double v[3]);
/* Close the memory stream f (open_memstream's *text, set at the close; freed) and write it to
 * OUT/plan.yaml; NH_ERR_MEMORY (the stream failed), NH_ERR_IO. */
int nh_plan_yaml_finish(FILE *f, char **text, const char *out);
/* OUT/final, a symbolic link to OUT/run_NN (run = NN, from 1): the outputs
 * of the plan's chosen run. NH_ERR_IO naming the link. */
int nh_plan_link_final(const char *out, int run);

/* ---- steer.c ---- */
/* The steering planner (plan.c calls it when the target's tool has a
 * bevel). Arguments as nh_plan_run's; `scene` is the loaded scene. */
int nh_plan_steer(const char *scene_path, int n_sets, const char *const *sets,
                  const nh_scene *scene, int target, const nh_plan_options *o, const char *out);

#endif
