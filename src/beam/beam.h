/* beam — corotational Euler–Bernoulli beams with 6 DOF per node: the
 * needle, cannula and electrode (the seed's §2.2; docs/beam.md).
 *
 * A tool is a chain of n straight 2-node elements along a line, from a base
 * point (node 0) in a direction to the tip (node n):
 *
 *      base                                             tip
 *   node 0 ──[e0]── node 1 ──[e1]── … ──[e(n−1)]── node n      s = 0 … L
 *   clamped                                          (arc length at rest)
 *
 * Each node carries a position x (3) and an orientation: a rotation matrix
 * T whose columns are the directors (d1 = beam axis, d2, d3 = cross-section
 * axes), row-major, T[3*i + j] = (d_j)_i. Increments of the 6 DOFs of a node
 * are (δx, δw): a displacement and a spatial rotation vector, applied as
 * x ← x + δx, T ← exp(δw) T. Force vectors are conjugate: (force, moment)
 * per node, so a dead moment M on a node does the work M·δw.
 *
 * DOF order of every nodal vector: 6 per node, node-major, (x y z, wx wy wz).
 * The base node (all 6 DOFs) is prescribed: its state is set by
 * nh_beam_set_base and the solvers never change it. Dense matrices are
 * row-major. All functions are free of I/O. */
#ifndef NH_BEAM_H
#define NH_BEAM_H

#include "core/core.h"

/* Material and hollow (or solid: inner_radius = 0) circular section. */
typedef struct {
  double young;        /* E, Pa, > 0 */
  double poisson;      /* ν in (−1, 0.5) */
  double radius;       /* outer radius r, m, > 0 */
  double inner_radius; /* rᵢ in [0, r), m */
  double density;      /* ρ, kg/m³, >= 0 */
} nh_beam_section;

/* Section constants derived from nh_beam_section. */
typedef struct {
  double area;    /* A = π (r² − rᵢ²) */
  double inertia; /* I = π (r⁴ − rᵢ⁴) / 4, both bending axes */
  double polar;   /* J = 2 I (torsion constant of a circular tube) */
  double shear;   /* G = E / (2 (1 + ν)) */
} nh_beam_constants;

/* A straight tool at rest. */
typedef struct {
  nh_beam_section section;
  double base[3];      /* position of node 0, m */
  double direction[3]; /* axis from base to tip (any length > 0) */
  double length;       /* L, m, > 0 */
  int elements;        /* n >= 1 equal elements */
  double normal[3];    /* d2 at rest; projected orthogonal to the axis. A zero
                          vector (or one parallel to the axis) picks one. */
} nh_beam_spec;

typedef struct nh_beam nh_beam;

/* Check a section and derive its constants. Fails with NH_ERR_INPUT (message
 * names the field) if a value is out of range. */
int nh_beam_section_constants(const nh_beam_section *section, nh_beam_constants *out);

/* Create a tool at rest (x = rest positions, T = rest directors, v = 0).
 * Fails with NH_ERR_INPUT (bad section, length, direction or element count)
 * or NH_ERR_MEMORY. */
int nh_beam_create(const nh_beam_spec *spec, nh_beam **out);
/* Free and set *beam = NULL (NULL-safe). */
void nh_beam_destroy(nh_beam **beam);

int nh_beam_elements(const nh_beam *beam);
int nh_beam_nodes(const nh_beam *beam); /* n + 1 */
int nh_beam_dofs(const nh_beam *beam);  /* 6 (n + 1) */
double nh_beam_length(const nh_beam *beam);
const nh_beam_constants *nh_beam_get_constants(const nh_beam *beam);

/* The current state: positions (3 per node), directors (9 per node),
 * velocities (6 per node: linear, angular (spatial)). Mutable: the caller
 * may write a state (keep each T a rotation). */
double *nh_beam_positions(nh_beam *beam);
double *nh_beam_directors(nh_beam *beam);
double *nh_beam_velocities(nh_beam *beam);
/* Rest positions (3 per node) and rest directors (9 per node). */
const double *nh_beam_rest_positions(const nh_beam *beam);
const double *nh_beam_rest_directors(const nh_beam *beam);

/* Back to rest: x, T at rest, v = 0. */
void nh_beam_reset(nh_beam *beam);

/* Prescribe the base (node 0): position x[3] and directors T[9] (a rotation;
 * NULL keeps the current one). The rest of the beam is not moved: call a
 * solver, or nh_beam_move_rigid for a rigid motion of the whole tool. */
void nh_beam_set_base(nh_beam *beam, const double x[3], const double T[9]);

/* Move every node rigidly: x ← Q (x − c) + c + t, T ← Q T (Q a rotation
 * about the point c[3]; t[3] a translation; c or t may be NULL = 0). */
void nh_beam_move_rigid(nh_beam *beam, const double Q[9], const double c[3], const double t[3]);

/* Apply a DOF increment d (6 per node): x ← x + δx, T ← exp(δw) T. Entries of
 * the base node are applied too (the solvers pass 0 there). */
void nh_beam_increment(nh_beam *beam, const double *d);

/* ---- element ---- */

/* Internal force f[12] (= ∂U/∂(δx1, δw1, δx2, δw2)) of element e at the
 * current state, and, if K != NULL, its consistent tangent K[144] (∂f/∂ the
 * same increments; not symmetric away from equilibrium). Returns the strain
 * energy U of the element. */
double nh_beam_element_force(const nh_beam *beam, int e, double f[12], double K[144]);

/* Element local deformations at the current state: d[7] =
 * (l − l0, θ̄1 (3), θ̄2 (3)), the stretch and the nodal rotations relative to
 * the corotated frame (rotation vectors in that frame), and the frame E[9]
 * (columns e1 along the chord, e2, e3; may be NULL). */
void nh_beam_element_local(const nh_beam *beam, int e, double d[7], double E[9]);

/* The elastic twist along the tool: twist[a] (n + 1 values; may be NULL) is
 * the rotation of node a's section about the axis relative to the base's,
 * Σ_{e < a} (θ̄₂ₓ − θ̄₁ₓ) over the elements (their torsion, whose moment is
 * GJ/l₀ times it, nh_beam_element_local); returns the tip's, rad. A tip
 * that lags a base turned in the positive sense has a negative twist. */
double nh_beam_twist(const nh_beam *beam, double *twist);

/* ---- whole tool ---- */

/* Internal force f_int (6 per node, all nodes) and strain energy (returned)
 * at the current state; if K != NULL, the assembled tangent (dense,
 * dofs x dofs), symmetrised ½(K + Kᵀ) if symmetric != 0. */
double nh_beam_internal_force(const nh_beam *beam, double *f_int, double *K, int symmetric);

/* Lumped mass: the diagonal of M (6 per node). Per element ρAl₀/2 to each
 * node's translations and ρ I_p l₀/2 (I_p = J = 2I, the polar moment of the
 * section) to each of its three rotations (isotropic: see docs/beam.md). */
void nh_beam_mass(const nh_beam *beam, double *m);

/* Add the nodal loads of a uniform gravity g[3] (m/s²) to f (6 per node).
 * consistent = 0: lumped, ρAl₀/2 g per node (= M g; no moments).
 * consistent != 0: the consistent load of the cubic element, ρAl₀/2 g per
 * node and moments ± (ρA l₀²/12) e1 × g, e1 the current chord direction. */
void nh_beam_add_gravity(const nh_beam *beam, const double g[3], int consistent, double *f);

/* ---- points on the deformed axis (cubic Hermite) ---- */

/* The point at rest arc length s ∈ [0, L] (clamped to it) on the cubic
 * Hermite curve of its element through the end positions and end tangents
 * (d1 of each node, scaled by l₀):
 *   x(ξ) = H1 x1 + H2 l₀ t1 + H3 x2 + H4 l₀ t2,  ξ = (s − s_e)/l₀,
 * H1 = 1 − 3ξ² + 2ξ³, H2 = ξ − 2ξ² + ξ³, H3 = 3ξ² − 2ξ³, H4 = ξ³ − ξ².
 * Outputs (each may be NULL): x[3], the unit tangent t[3] = x'/|x'|, the
 * element index *e and ξ, and J[36], the 3x12 map from the element's DOF
 * increments (δx1, δw1, δx2, δw2) to δx (rows x, y, z). */
void nh_beam_point(const nh_beam *beam, double s, double x[3], double t[3], int *e, double *xi,
                   double J[36]);

/* Distribute a force F[3] acting at rest arc length s to nodal forces and
 * moments with the same Hermite weights (f += Jᵀ F, J of nh_beam_point):
 * node 1 gets H1 F and H2 l₀ t1 × F, node 2 gets H3 F and H4 l₀ t2 × F. */
void nh_beam_add_point_force(const nh_beam *beam, double s, const double F[3], double *f);

/* ---- solvers for the tool alone ---- */

typedef struct {
  int load_steps;      /* the load is applied in equal increments (>= 1) */
  int max_iterations;  /* Newton iterations per load step */
  double tolerance;    /* relative residual (see nh_beam_solve_static) */
  double gravity[3];   /* m/s², added to the load at every iterate */
  int consistent_load; /* gravity as consistent (1) or lumped (0) loads */
} nh_beam_static_options;

typedef struct {
  int iterations;  /* total Newton iterations */
  double residual; /* final relative residual */
} nh_beam_stats;

/* Static equilibrium f_int(x) = f_ext + gravity by Newton's method with the
 * consistent tangent, in load_steps equal load increments, starting from the
 * current state; the base node stays where it is. f_ext: dead loads (6 per
 * node, may be NULL). The residual r (free DOFs) is measured with moments
 * divided by the element length l₀ (so both parts are forces); converged
 * when |r| <= tolerance · max(|f_ext|, |f_int|, tiny) in that norm, or when
 * a Newton correction is <= tolerance times the sum of the corrections of
 * this solve (rotations scaled by l₀): the residual has a round-off floor
 * near EA·eps·|x|/l₀ that small transverse loads on slender beams do not
 * clear. Fails
 * with NH_ERR_NUMERIC (singular tangent, non-finite value, or no convergence
 * within max_iterations in some load step; the state is then the last
 * iterate). */
int nh_beam_solve_static(nh_beam *beam, const nh_beam_static_options *options, const double *f_ext,
                         nh_beam_stats *stats);

typedef struct {
  double dt;          /* time step h, s */
  double alpha, beta; /* Rayleigh damping C = α M + β K */
  double gravity[3];  /* m/s², lumped (M g) */
  int quasi_static;   /* a Newton iteration of the static problem (solve/coupled.c): A = K
                         without the mass; with dt = 1, α = β = 0 and v = 0 the right-hand
                         side is the static residual and the base velocity its increment;
                         K is then the full consistent tangent, factorised by LU when its
                         symmetric part is positive definite (A unsymmetric) */
} nh_beam_dynamic_options;

/* One backward-Euler step with one linearisation, the tissue's form
 * (solve/solve.h):
 *   A = (1 + hα) M + (hβ + h²) K,  K the symmetrised tangent,
 *   A dv = h (f_ext + M g − f_int − α M v − β K v) − h² K v,
 *   v ← v + dv,  x ← x + h v_lin,  T ← exp(h ω) T.
 * The base node keeps its state and zero velocity. f_ext: 6 per node (may
 * be NULL). Fails with NH_ERR_NUMERIC (singular A, non-finite value). */
int nh_beam_step_dynamic(nh_beam *beam, const nh_beam_dynamic_options *options,
                         const double *f_ext);

/* The same step in three parts, for a tool coupled to the tissue by
 * constraint rows (Algorithm 1, solve/coupled.c), with a prescribed base
 * velocity (the tool's motion):
 *   prepare: assemble and factorise A (free DOFs: nodes 1 … n, m = 6n; by
 *            Cholesky: A is symmetric, see nh_beam_system_projected; by LU
 *            in the quasi-static case, see its option) and
 *            the right-hand side rhs[m] of the free DOFs for the base
 *            velocity base_velocity[6] (linear, angular) at the end of the step:
 *              rhs = h (f_ext + M g − f_int − α M v − β K v) − h² K v
 *                    − (hβ + h²) K_fb (v_base,new − v_base);
 *   solve:   y ← A⁻¹ y in place (length m), any number of times;
 *   finish:  v ← v + dv (free DOFs), v_base ← base_velocity, then
 *            x ← x + h v, T ← exp(h ω) T for every node, the base included.
 * nh_beam_step_dynamic is prepare + solve + finish with the base at rest. */
typedef struct nh_beam_system nh_beam_system;
int nh_beam_system_create(const nh_beam *beam, nh_beam_system **out);
void nh_beam_system_destroy(nh_beam_system **system);
int nh_beam_dynamic_prepare(nh_beam *beam, const nh_beam_dynamic_options *options,
                            const double *f_ext, const double base_velocity[6],
                            nh_beam_system *system, double *rhs);
void nh_beam_system_solve(const nh_beam_system *system, double *y);
/* The same for nrhs right-hand sides at once, the columns of Y (m x nrhs,
 * column-major): one blocked triangular solve instead of nrhs. */
void nh_beam_system_solve_many(const nh_beam_system *system, int nrhs, double *Y);
/* The beam's own step system, created at the first call and kept (with its
 * work arrays) until nh_beam_destroy: a coupled step prepares it every step
 * without allocating. *out is borrowed. Fails with NH_ERR_MEMORY. */
int nh_beam_step_system(nh_beam *beam, nh_beam_system **out);
/* 1 if the last prepare found A = (1 + hα) M + (hβ + h²) K indefinite (the
 * tool compressed beyond a buckling load of the step) and used K's positive
 * part (eigenvalues clipped at 0) instead; A is then positive definite and
 * the residual still exact. */
int nh_beam_system_projected(const nh_beam_system *system);
int nh_beam_dynamic_finish(nh_beam *beam, double dt, const double base_velocity[6],
                           const double *dv);

/* ---- rotations (exposed for tests and the contact module) ---- */

/* Rotation vector of a rotation matrix (angle in [0, π]), via the
 * quaternion (Shepperd's method): exact inverse of nh_mat3_rotation. */
void nh_beam_rotation_log(const double R[9], double theta[3]);

#endif
