/* test_spr — the stress inside an element, the compliance, SPR recovery, the
 * error indicators and the marking (adapt/spr.c, adapt/mark.c, fem/stress.c).
 *
 * Expected values are derived, not recorded:
 *  1. Element stress. At ξ = 0 it is the centre stress of hex.c (two code
 *     paths). For u = A X every cell has F = I + A (Σₐ Xₐ ⊗ ∇Nₐ = I for any
 *     isoparametric element), d is linear in X, so at every ξ
 *     σ = R D sym(RᵀF − I) Rᵀ with R = polar(I + A), computed here directly.
 *     The compliance inverts D (engineering shears) and sᵀD⁻¹s = σ : ε.
 *     B-bar: the same with the volumetric part κ (det F − 1) I.
 *  2. A linear displacement gives one constant stress: σ* equals it at every
 *     node (interior, boundary, grown and fallback patches) and η = 0.
 *  3. u = ∇φ with φ a cubic: on a rectilinear grid the centre gradient of
 *     the trilinear interpolant of a quadratic u is exact (midpoint rule),
 *     and the Hessian is symmetric, so F is symmetric, R = I and the centre
 *     stresses sample the linear field σ(x) = D ∇∇φ(x) exactly. A linear
 *     least-squares fit of exact linear data is exact: σ* = σ(X) at every
 *     node whose patch spans 3-D (all of them on this grid: interior nodes
 *     directly, boundary nodes through the grown patch). Also ‖u‖²_E, which
 *     the estimator integrates by Gauss points, equals twice the
 *     corotational energy ½ dᵀK₀d (K₀ is the same quadrature).
 *  4. Marking against hand-built ηₑ; Dörfler's minimal count against a
 *     brute-force search over all subsets.
 *  5. The cache of the mesh-dependent weights: the estimate equals the one
 *     that makes them node by node, through refinement and coarsening. */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <omp.h>
#include <string.h>

/* Fully integrated except where a test says otherwise: SPR does not depend
 * on the formulation, and the exactness arguments of 3 are linear ones
 * (B-bar's θ̄ = det F̄ − 1 is not linear in u). */
static nh_material mat = {1e5, 0.35, 1000, NH_FORMULATION_FULL};

/* D ε for engineering Voigt strains e[6]. */
static void voigt_stiffness(double lambda, double mu, const double e[6], double s[6]) {
  double tr = e[0] + e[1] + e[2];
  for (int i = 0; i < 3; i++) s[i] = lambda * tr + 2.0 * mu * e[i];
  for (int i = 3; i < 6; i++) s[i] = mu * e[i];
}

/* Voigt stress of a symmetric tensor S (row-major) and back. */
static void tensor_to_voigt(const double S[9], double s[6]) {
  s[0] = S[0], s[1] = S[4], s[2] = S[8], s[3] = S[5], s[4] = S[2], s[5] = S[1];
}

static double max_abs(const double *v, int n) {
  double r = 0.0;
  for (int i = 0; i < n; i++) r = fmax(r, fabs(v[i]));
  return r;
}

/* Box mesh; interior nodes moved by up to `distort` of a cell. */
static nh_mesh *make_mesh(const double lo[3], const double hi[3], const int grid[3],
                          double distort) {
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  for (int i = 0; i < m->n_nodes; i++) {
    double *X = m->X + 3 * i;
    int interior = 1;
    for (int k = 0; k < 3; k++)
      interior &= X[k] > lo[k] + 1e-9 * m->spacing[k] && X[k] < hi[k] - 1e-9 * m->spacing[k];
    if (interior)
      for (int k = 0; k < 3; k++) X[k] += distort * m->spacing[k] * nh_rand();
  }
  return m;
}

/* The stress of u = A X, F = I + A: σ = R D sym(RᵀF − I) Rᵀ for the fully
 * integrated element; B-bar (the tissue of this test): the same with the
 * volumetric part replaced by κ (det F − 1) I, κ = λ + ⅔μ (fem/hex.c). */
static void homogeneous_stress(const double A[9], double lambda, double mu, double s[6]) {
  double F[9], R[9], RtF[9], E[9], e[6], sl[6], S[9], T[9];
  nh_mat3_identity(F);
  for (int i = 0; i < 9; i++) F[i] += A[i];
  nh_polar_rotation(F, R);
  nh_mat3_mul_tn(R, F, RtF);
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) E[3 * i + j] = 0.5 * (RtF[3 * i + j] + RtF[3 * j + i]);
  for (int i = 0; i < 3; i++) E[4 * i] -= 1.0;
  e[0] = E[0], e[1] = E[4], e[2] = E[8], e[3] = 2 * E[5], e[4] = 2 * E[2], e[5] = 2 * E[1];
  voigt_stiffness(lambda, mu, e, sl);
  double Sl[9] = {sl[0], sl[5], sl[4], sl[5], sl[1], sl[3], sl[4], sl[3], sl[2]};
  if (mat.formulation == NH_FORMULATION_BBAR) {
    double p = (lambda + 2.0 * mu / 3.0) * (nh_mat3_det(F) - 1.0) - lambda * (e[0] + e[1] + e[2]) -
               2.0 * mu / 3.0 * (e[0] + e[1] + e[2]);
    for (int i = 0; i < 3; i++) Sl[4 * i] += p;
  }
  nh_mat3_mul(R, Sl, T);
  nh_mat3_mul_nt(T, R, S);
  tensor_to_voigt(S, s);
}

static void test_element_stress(nh_formulation formulation) {
  mat.formulation = formulation;
  const double lo[3] = {0.1, -0.2, 0.3}, hi[3] = {0.5, 0.1, 0.6};
  const int grid[3] = {3, 2, 2};
  nh_test_rng = 4242;
  nh_mesh *m = make_mesh(lo, hi, grid, 0.25);
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  int n = 3 * m->n_nodes;
  double *u = malloc(sizeof(double) * n);
  for (int i = 0; i < n; i++) u[i] = 1e-2 * nh_rand();
  const double zero[3] = {0, 0, 0};
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double s0[6], sg[6];
    nh_tissue_cell_stress(t, c, u, s0);
    nh_tissue_gauss_stress(t, c, u, zero, sg);
    double scale = max_abs(s0, 6);
    for (int k = 0; k < 6; k++)
      CHECK_CLOSE(sg[k], s0[k], 1e-12 * scale, "gauss stress at xi = 0 vs centre stress");
  }
  /* A finite homogeneous deformation with rotation: F = Q (I + S). */
  double r[3] = {0.3, -0.2, 0.25}, Q[9],
         U[9] = {1.04, 0.01, -0.02, 0.01, 0.97, 0.015, -0.02, 0.015, 1.02}, A[9];
  nh_mat3_rotation(r, Q);
  nh_mat3_mul(Q, U, A);
  for (int i = 0; i < 3; i++) A[4 * i] -= 1.0;
  for (int i = 0; i < m->n_nodes; i++) nh_mat3_vec(A, m->X + 3 * i, u + 3 * i);
  double sx[6];
  homogeneous_stress(A, t->lambda, t->mu, sx);
  double scale = max_abs(sx, 6);
  for (int l = 0; l < m->n_leaves; l++)
    for (int p = 0; p < 5; p++) {
      double xi[3] = {nh_rand(), nh_rand(), nh_rand()}, s[6];
      if (p == 0) xi[0] = xi[1] = xi[2] = -1.0; /* a corner */
      nh_tissue_gauss_stress(t, m->leaves[l], u, xi, s);
      for (int k = 0; k < 6; k++)
        CHECK_CLOSE(s[k], sx[k], 1e-10 * scale, "stress of u = A X at a point xi");
    }

  /* Compliance: D⁻¹ D e = e, sᵀe = σ : ε, and the E-ν form of Hooke's law. */
  double E = mat.young, nu = mat.poisson;
  for (int trial = 0; trial < 20; trial++) {
    double e[6], s[6], e2[6];
    for (int k = 0; k < 6; k++) e[k] = 1e-3 * nh_rand();
    voigt_stiffness(t->lambda, t->mu, e, s);
    nh_voigt_compliance(t->lambda, t->mu, s, e2);
    for (int k = 0; k < 6; k++)
      CHECK_CLOSE(e2[k], e[k], 1e-12 * max_abs(e, 6), "compliance inverts stiffness");
    double Et[9] = {e[0], e[5] / 2, e[4] / 2, e[5] / 2, e[1], e[3] / 2, e[4] / 2, e[3] / 2, e[2]};
    double St[9] = {s[0], s[5], s[4], s[5], s[1], s[3], s[4], s[3], s[2]}, contraction = 0.0,
           dot = 0.0;
    for (int i = 0; i < 9; i++) contraction += St[i] * Et[i];
    for (int k = 0; k < 6; k++) dot += s[k] * e2[k];
    CHECK_CLOSE(dot, contraction, 1e-12 * fabs(contraction) + 1e-300, "s^T D^-1 s = sigma : eps");
    CHECK_CLOSE(e2[0], (s[0] - nu * (s[1] + s[2])) / E, 1e-12 * max_abs(e, 6), "e_xx by E, nu");
    CHECK_CLOSE(e2[3], 2 * (1 + nu) * s[3] / E, 1e-12 * max_abs(e, 6), "gamma_yz by E, nu");
  }
  free(u);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

/* Test 2: linear displacement fields give η = 0. */
static void test_linear_displacement(const int grid[3], double distort, const double A[9],
                                     double tol, const char *what) {
  const double lo[3] = {-0.2, 0.0, 1.0}, hi[3] = {0.3, 0.4, 1.3};
  nh_test_rng = 777;
  nh_mesh *m = make_mesh(lo, hi, grid, distort);
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  const double shift[3] = {1e-3, -2e-3, 5e-4};
  double *u = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) {
    nh_mat3_vec(A, m->X + 3 * i, u + 3 * i);
    for (int k = 0; k < 3; k++) u[3 * i + k] += shift[k];
  }
  double sx[6];
  homogeneous_stress(A, t->lambda, t->mu, sx);
  double scale = max_abs(sx, 6);
  /* The centre stresses themselves scatter by round-off: R is computed from
   * F per cell, and its rounding enters ε amplified by 1/strain. */
  double centre_err = 0.0, node_err = 0.0, cell_err = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    double s[6];
    nh_tissue_cell_stress(t, m->leaves[l], u, s);
    for (int k = 0; k < 6; k++) centre_err = fmax(centre_err, fabs(s[k] - sx[k]) / scale);
  }
  double *ss = malloc(sizeof(double) * 6 * m->n_nodes);
  CHECK_OK(nh_spr_recover(m, t, u, NULL, ss));
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 6; k++) node_err = fmax(node_err, fabs(ss[6 * i + k] - sx[k]) / scale);
  CHECK_CLOSE(node_err, 0.0, tol, what);
  /* The fits do not amplify the scatter of their data (leverage bound). */
  CHECK(node_err <= 2.0 * centre_err + 1e-15, "%s: nodal error %.3g vs centre scatter %.3g", what,
        node_err, centre_err);
  double *eta_cell = calloc((size_t)m->n_cells, sizeof(double)), eta = -1, eta_rel = -1;
  CHECK_OK(nh_spr_estimate(m, t, u, NULL, eta_cell, &eta, &eta_rel));
  double norm = sqrt(2.0 * nh_tissue_energy(t, u));
  CHECK(norm > 0.0, "%s: energy norm is %g", what, norm);
  for (int l = 0; l < m->n_leaves; l++) cell_err = fmax(cell_err, eta_cell[m->leaves[l]] / norm);
  CHECK_CLOSE(eta / norm, 0.0, tol, what);
  CHECK_CLOSE(eta_rel, 0.0, tol, what);
  CHECK_CLOSE(cell_err, 0.0, tol, what);
  if (getenv("NH_VERBOSE"))
    printf("%-48s centre |s_h - s|/|s| %.2e  nodes |s* - s|/|s| %.2e  eta/|u|_E %.2e  max "
           "eta_e/|u|_E %.2e  eta_rel %.2e\n",
           what, centre_err, node_err, eta / norm, cell_err, eta_rel);
  free(u), free(ss), free(eta_cell);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

/* φ = Σ cubic monomials; u = ∇φ, H = ∇∇φ (linear in x). */
static const double phi_a = 2e-3;
static void cubic_gradient(const double x[3], double u[3], double H[9]) {
  double X = x[0] - 1.0, Y = x[1] + 0.5, Z = x[2] - 0.25; /* shifted origin */
  /* φ = a (X³/6 + X²Y/2 − Y Z²/2 + XYZ + Z³/3) */
  u[0] = phi_a * (X * X / 2 + X * Y + Y * Z);
  u[1] = phi_a * (X * X / 2 - Z * Z / 2 + X * Z);
  u[2] = phi_a * (-Y * Z + X * Y + Z * Z);
  double h[9] = {X + Y, X + Z, Y, X + Z, 0.0, -Z + X, Y, -Z + X, -Y + 2 * Z};
  for (int i = 0; i < 9; i++) H[i] = phi_a * h[i];
}

static void exact_stress(const nh_tissue *t, const double x[3], double s[6]) {
  double u[3], H[9];
  cubic_gradient(x, u, H);
  double e[6] = {H[0], H[4], H[8], 2 * H[5], 2 * H[2], 2 * H[1]};
  voigt_stiffness(t->lambda, t->mu, e, s);
}

static void test_linear_stress(void) {
  /* Direct fit of linear data at random points. */
  nh_test_rng = 99;
  for (int trial = 0; trial < 10; trial++) {
    int n = 8 + trial * 3;
    double pts[3 * 40], vals[6 * 40], g[6][3], s0[6], x0[3], out[6], ex[6];
    for (int k = 0; k < 6; k++) {
      s0[k] = 100 * nh_rand();
      for (int j = 0; j < 3; j++) g[k][j] = 1000 * nh_rand();
    }
    /* A jittered cube's corners, then random points inside. */
    for (int i = 0; i < n; i++)
      for (int j = 0; j < 3; j++)
        pts[3 * i + j] =
            5.0 + (i < 8 ? 0.1 * nh_hex_corner[i][j] + 0.02 * nh_rand() : 0.1 * nh_rand());
    for (int i = 0; i < n; i++)
      for (int k = 0; k < 6; k++)
        vals[6 * i + k] =
            s0[k] + g[k][0] * pts[3 * i] + g[k][1] * pts[3 * i + 1] + g[k][2] * pts[3 * i + 2];
    for (int j = 0; j < 3; j++) x0[j] = 5.0 + 0.1 * nh_rand();
    for (int k = 0; k < 6; k++) ex[k] = s0[k] + g[k][0] * x0[0] + g[k][1] * x0[1] + g[k][2] * x0[2];
    CHECK_OK(nh_spr_fit_patch(n, pts, vals, x0, out));
    for (int k = 0; k < 6; k++)
      CHECK_CLOSE(out[k], ex[k], 1e-10 * max_abs(ex, 6), "fit of linear data at random points");
    /* Coplanar points and too few points are refused. */
    for (int i = 0; i < n; i++) pts[3 * i + 2] = 5.0;
    CHECK(nh_spr_fit_patch(n, pts, vals, x0, out) == NH_ERR_NUMERIC, "coplanar points accepted");
    CHECK(nh_spr_fit_patch(3, pts, vals, x0, out) == NH_ERR_NUMERIC, "3 points accepted");
  }

  /* The full pipeline on a rectilinear grid. */
  const double lo[3] = {0.5, -1.0, 0.0}, hi[3] = {1.5, -0.2, 0.6};
  const int grid[3] = {5, 4, 3};
  nh_mesh *m = make_mesh(lo, hi, grid, 0.0);
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes), H[9], scale = 0.0;
  for (int i = 0; i < m->n_nodes; i++) cubic_gradient(m->X + 3 * i, u + 3 * i, H);
  double *ss = malloc(sizeof(double) * 6 * m->n_nodes);
  /* Centre stresses sample the linear field (the premise of the test). */
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24], xc[3] = {0, 0, 0}, s[6], ex[6];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) xc[k] += Xe[3 * a + k] / 8;
    nh_tissue_cell_stress(t, c, u, s);
    exact_stress(t, xc, ex);
    scale = fmax(scale, max_abs(ex, 6));
    for (int k = 0; k < 6; k++) CHECK_CLOSE(s[k], ex[k], 1e-10 * scale, "centre stress exact");
  }
  CHECK_OK(nh_spr_recover(m, t, u, NULL, ss));
  int n_interior = 0;
  double err[2] = {0, 0};
  for (int i = 0; i < m->n_nodes; i++) {
    const double *X = m->X + 3 * i;
    int interior = 1;
    for (int k = 0; k < 3; k++) interior &= X[k] > lo[k] + 1e-9 && X[k] < hi[k] - 1e-9;
    n_interior += interior;
    double ex[6];
    exact_stress(t, X, ex);
    for (int k = 0; k < 6; k++)
      err[interior] = fmax(err[interior], fabs(ss[6 * i + k] - ex[k]) / scale);
    for (int k = 0; k < 6; k++)
      CHECK_CLOSE(ss[6 * i + k], ex[k], 1e-10 * scale,
                  interior ? "SPR at an interior node (8-cell patch)"
                           : "SPR at a boundary node (grown patch)");
  }
  CHECK(n_interior == 4 * 3 * 2, "expected 24 interior nodes, got %d", n_interior);

  /* η > 0 here, and ‖u‖²_E = η²/η_rel² − η² equals twice the energy. */
  double *eta_cell = calloc((size_t)m->n_cells, sizeof(double)), eta, eta_rel;
  CHECK_OK(nh_spr_estimate(m, t, u, NULL, eta_cell, &eta, &eta_rel));
  double norm2 = eta * eta / (eta_rel * eta_rel) - eta * eta, energy = nh_tissue_energy(t, u);
  CHECK(eta > 0.0 && eta_rel > 0.0 && eta_rel < 1.0, "eta %g, eta_rel %g", eta, eta_rel);
  CHECK_CLOSE(norm2, 2.0 * energy, 1e-9 * 2.0 * energy, "|u|_E^2 vs 2 x corotational energy");
  double sum = 0.0;
  for (int l = 0; l < m->n_leaves; l++) sum += eta_cell[m->leaves[l]] * eta_cell[m->leaves[l]];
  CHECK_CLOSE(sqrt(sum), eta, 1e-13 * eta, "eta = (sum eta_e^2)^1/2");
  if (getenv("NH_VERBOSE"))
    printf("linear stress field: |s* - s|/max|s| interior %.2e, boundary %.2e; eta_rel %.3g; "
           "|u|_E^2 vs 2 energy: rel diff %.2e\n",
           err[1], err[0], eta_rel, fabs(norm2 - 2 * energy) / (2 * energy));

  /* Hanging nodes: one node declared hanging between its two x-neighbours. */
  int g0 = grid[0] + 1, g1 = grid[1] + 1, v = 2 + g0 * (2 + g1 * 1);
  int node[1] = {v}, start[2] = {0, 2}, master[2] = {v - 1, v + 1};
  double weight[2] = {0.5, 0.5};
  nh_hanging hang = {
      .n_hanging = 1, .node = node, .start = start, .master = master, .weight = weight};
  double *sh = malloc(sizeof(double) * 6 * m->n_nodes);
  CHECK_OK(nh_spr_recover(m, t, u, &hang, sh));
  for (int k = 0; k < 6; k++)
    CHECK_CLOSE(sh[6 * v + k], 0.5 * (sh[6 * (v - 1) + k] + sh[6 * (v + 1) + k]), 1e-15 * scale,
                "hanging node: half the sum of its masters");
  sh[6 * v] = ss[6 * v]; /* every other node is untouched */
  for (int k = 1; k < 6; k++) sh[6 * v + k] = ss[6 * v + k];
  CHECK(memcmp(sh, ss, sizeof(double) * 6 * m->n_nodes) == 0, "hanging node changed other nodes");
  nh_hanging none = {.n_hanging = 0};
  CHECK_OK(nh_spr_recover(m, t, u, &none, sh));
  CHECK(memcmp(sh, ss, sizeof(double) * 6 * m->n_nodes) == 0, "n_hanging = 0 differs from NULL");
  double eta_h, eta_rel_h;
  CHECK_OK(nh_spr_estimate(m, t, u, &hang, NULL, &eta_h, &eta_rel_h));
  CHECK(eta_h > 0.0, "eta with a hanging node: %g", eta_h);
  /* A master that is itself hanging is refused. */
  int node2[2] = {v, v + 1}, start2[3] = {0, 2, 4}, master2[4] = {v - 1, v + 1, v, v + 2};
  double weight2[4] = {0.5, 0.5, 0.5, 0.5};
  nh_hanging chain = {
      .n_hanging = 2, .node = node2, .start = start2, .master = master2, .weight = weight2};
  CHECK(nh_spr_recover(m, t, u, &chain, sh) == NH_ERR_INTERNAL, "an unresolved chain accepted");
  free(u), free(ss), free(sh), free(eta_cell);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

#include "hanging_mesh.h" /* regular_template */

/* Test 5: a nonconforming mesh (hanging nodes from the refinement code).
 * A 3x3x3 box grid, its centre cell and a boundary cell refined by the
 * regular template n, then the child of the centre cell touching the face
 * x = 1/3 refined again (nested). All cells stay axis-aligned boxes, so the
 * arguments of tests 2 and 3 hold cell by cell: a linear displacement gives
 * η = 0, and for u = ∇φ (exact values at every node, hanging ones included)
 * σ* equals the linear field at every node: non-hanging nodes by their fits
 * (coarse-fine patches included), hanging nodes because interpolating a
 * linear field from the masters is exact. */
static void test_nonconforming(int n) {
  char what[96];
  nh_template *tmpl = regular_template(n);
  const double lo[3] = {0.5, -1.0, 0.0}, hi[3] = {1.5, 0.0, 1.0};
  const int grid[3] = {3, 3, 3};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  int first[2] = {1 + 3 * (1 + 3 * 1), 1 + 3 * (1 + 3 * 0)};
  CHECK_OK(nh_mesh_refine(m, tmpl, first, 2, NULL));
  int best = -1;
  double bd = INFINITY;
  for (int ch = m->first_child[first[0]]; ch < m->first_child[first[0]] + m->n_children[first[0]];
       ch++) {
    double cx = 0.0, cy = 0.0, cz = 0.0;
    for (int a = 0; a < 8; a++) {
      const double *X = m->X + 3 * m->cells[8 * ch + a];
      cx += X[0] / 8, cy += X[1] / 8, cz += X[2] / 8;
    }
    double d = fabs(cx - (0.5 + 1.0 / 3)) + fabs(cy + 0.5) + fabs(cz - 0.5);
    if (d < bd) bd = d, best = ch;
  }
  CHECK_OK(nh_mesh_refine(m, tmpl, &best, 1, NULL));
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(m, NULL, &h));
  CHECK(h->n_hanging > 0, "template %d: no hanging nodes", n);
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes),
         *ss = malloc(sizeof(double) * 6 * m->n_nodes);
  double *eta_cell = calloc((size_t)m->n_cells, sizeof(double)), eta, eta_rel, H[9];

  /* Linear displacement: η = 0. */
  const double A[9] = {1e-2, 2e-3, -3e-3, 5e-3, -1e-2, 2e-3, 1e-3, 3e-3, 7e-3};
  for (int i = 0; i < m->n_nodes; i++) nh_mat3_vec(A, m->X + 3 * i, u + 3 * i);
  CHECK_OK(nh_spr_estimate(m, t, u, h, eta_cell, &eta, &eta_rel));
  double norm = sqrt(2.0 * nh_tissue_energy(t, u)), cell_err = 0.0;
  for (int l = 0; l < m->n_leaves; l++) cell_err = fmax(cell_err, eta_cell[m->leaves[l]] / norm);
  snprintf(what, sizeof what, "template %d, linear displacement: eta / |u|_E", n);
  CHECK_CLOSE(eta / norm, 0.0, 1e-12, what);
  CHECK_CLOSE(cell_err, 0.0, 1e-12, what);
  double lin_eta = eta / norm;

  /* Linear stress field: σ* exact at every node. */
  for (int i = 0; i < m->n_nodes; i++) cubic_gradient(m->X + 3 * i, u + 3 * i, H);
  CHECK_OK(nh_spr_recover(m, t, u, h, ss));
  double scale = 0.0, err[2] = {0, 0};
  for (int i = 0; i < m->n_nodes; i++) {
    double ex[6];
    exact_stress(t, m->X + 3 * i, ex);
    scale = fmax(scale, max_abs(ex, 6));
  }
  snprintf(what, sizeof what, "template %d, linear stress field: sigma* at a node", n);
  for (int i = 0; i < m->n_nodes; i++) {
    double ex[6];
    int hanging = h->index[i] >= 0;
    exact_stress(t, m->X + 3 * i, ex);
    for (int k = 0; k < 6; k++) {
      err[hanging] = fmax(err[hanging], fabs(ss[6 * i + k] - ex[k]) / scale);
      CHECK_CLOSE(ss[6 * i + k], ex[k], 1e-10 * scale, what);
    }
  }
  if (getenv("NH_VERBOSE"))
    printf("nonconforming, template %d (%d leaves, %d hanging): linear u: eta/|u|_E %.2e; "
           "linear stress: |s* - s|/max|s| %.2e (non-hanging), %.2e (hanging)\n",
           n, m->n_leaves, h->n_hanging, lin_eta, err[0], err[1]);
  free(u), free(ss), free(eta_cell);
  nh_tissue_destroy(&t);
  nh_hanging_destroy(&h);
  nh_mesh_destroy(&m);
  nh_template_destroy(&tmpl);
}

/* One thread and several give bitwise the same estimate. */
static void test_threads(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.05, 0.04, 0.03};
  const int grid[3] = {12, 10, 8}; /* above the parallel threshold */
  nh_test_rng = 31337;
  nh_mesh *m = make_mesh(lo, hi, grid, 0.2);
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < 3 * m->n_nodes; i++) u[i] = 1e-4 * nh_rand();
  double *e1 = calloc((size_t)m->n_cells, sizeof(double)),
         *e2 = calloc((size_t)m->n_cells, sizeof(double)), eta1, eta2, r1, r2;
  int saved = omp_get_max_threads();
  omp_set_num_threads(1);
  CHECK_OK(nh_spr_estimate(m, t, u, NULL, e1, &eta1, &r1));
  omp_set_num_threads(4);
  CHECK_OK(nh_spr_estimate(m, t, u, NULL, e2, &eta2, &r2));
  omp_set_num_threads(saved);
  CHECK(memcmp(e1, e2, sizeof(double) * m->n_cells) == 0, "eta_e differs between 1 and 4 threads");
  CHECK(eta1 == eta2 && r1 == r2, "eta differs between threads: %.17g vs %.17g", eta1, eta2);
  free(u), free(e1), free(e2);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

static int contains(const int *list, int n, int c) {
  for (int i = 0; i < n; i++)
    if (list[i] == c) return 1;
  return 0;
}

static void test_marking(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {1.0, 0.4, 0.2};
  const int grid[3] = {5, 2, 1};
  nh_mesh *m = make_mesh(lo, hi, grid, 0.0);
  const double eta[10] = {1.0, 0.5, 0.3, 0.9, 0.0, 0.2, 0.7, 0.31, 0.05, 0.6};
  int marked[10], n;
  nh_mark_params p = {NH_MARK_MAX, 0.5, 0.5, 10, 0.0, 0.0};
  /* max: exactly the cells with η ≥ θ max η (θ max η = 0.5 and 0.3, both present). */
  const double thetas[3] = {0.5, 0.3, 1.0};
  for (int k = 0; k < 3; k++) {
    p.theta = thetas[k];
    CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
    int expect = 0;
    for (int c = 0; c < 10; c++) {
      int want = eta[c] >= thetas[k] * 1.0;
      expect += want;
      CHECK(contains(marked, n, c) == want, "max theta %g: cell %d (eta %g) marked %d", thetas[k],
            c, eta[c], contains(marked, n, c));
    }
    CHECK(n == expect, "max theta %g: %d marked, expected %d", thetas[k], n, expect);
    for (int i = 1; i < n; i++) CHECK(marked[i - 1] < marked[i], "marked ids not ascending");
  }
  /* dorfler: the set reaches the fraction, and no smaller set can (brute force). */
  p.strategy = NH_MARK_DORFLER;
  const double fractions[5] = {0.1, 0.5, 0.8, 0.95, 1.0};
  for (int k = 0; k < 5; k++) {
    p.fraction = fractions[k];
    CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
    double total = 0.0, sum = 0.0;
    for (int c = 0; c < 10; c++) total += eta[c] * eta[c];
    for (int i = 0; i < n; i++) sum += eta[marked[i]] * eta[marked[i]];
    CHECK(sum >= fractions[k] * total * (1 - 1e-14), "dorfler %g: %g of %g", fractions[k], sum,
          total);
    int best = 11;
    for (int set = 0; set < 1024; set++) {
      double s = 0.0;
      int count = 0;
      for (int c = 0; c < 10; c++)
        if (set >> c & 1) s += eta[c] * eta[c], count++;
      if (s >= fractions[k] * total * (1 - 1e-14) && count < best) best = count;
    }
    CHECK(n == best, "dorfler %g: %d marked, the smallest set has %d", fractions[k], n, best);
    CHECK(!contains(marked, n, 4), "dorfler marked a cell with eta = 0");
  }
  p.fraction = 0.5;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 2 && marked[0] == 0 && marked[1] == 3, "dorfler 0.5: expected {0, 3}, got %d cells",
        n);
  /* Ties go to the lower cell id: four equal η, half the total needs two. */
  const double tie[10] = {0, 0.5, 0, 0.5, 0, 0, 0.5, 0, 0.5, 0};
  CHECK_OK(nh_mark_cells(m, tie, &p, marked, &n));
  CHECK(n == 2 && marked[0] == 1 && marked[1] == 3, "dorfler ties: expected {1, 3}, got %d cells",
        n);
  /* max_level excludes. */
  p.strategy = NH_MARK_MAX, p.theta = 0.5;
  m->level[3] = 2, p.max_level = 2;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 4 && !contains(marked, n, 3), "max_level: cell 3 at level 2 marked (%d cells)", n);
  m->level[3] = 1;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 5 && contains(marked, n, 3), "max_level: cell 3 at level 1 not marked (%d)", n);
  p.max_level = 0;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 0, "max_level 0: %d cells marked", n);
  p.max_level = 10;
  /* min_size: cells are 0.2 wide; shrink cell 0 (node 0 is its corner only) to 0.17. */
  m->X[0] += 0.03;
  CHECK_CLOSE(nh_mesh_cell_size(m, 0), 0.17, 1e-12, "smallest edge of cell 0");
  CHECK_CLOSE(nh_mesh_cell_size(m, 1), 0.2, 1e-12, "smallest edge of cell 1");
  p.min_size = 0.09;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 4 && !contains(marked, n, 0), "min_size 0.09: cell 0 (0.17) marked, %d cells", n);
  p.min_size = 0.08;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 5, "min_size 0.08: %d cells marked, expected 5", n);
  p.min_size = 0.11;
  CHECK_OK(nh_mark_cells(m, eta, &p, marked, &n));
  CHECK(n == 0, "min_size 0.11: %d cells marked", n);
  p.min_size = 0.0;
  /* All zero: nothing, with both strategies. */
  const double zero[10] = {0};
  CHECK_OK(nh_mark_cells(m, zero, &p, marked, &n));
  CHECK(n == 0, "max with eta = 0 marked %d", n);
  p.strategy = NH_MARK_DORFLER;
  CHECK_OK(nh_mark_cells(m, zero, &p, marked, &n));
  CHECK(n == 0, "dorfler with eta = 0 marked %d", n);
  /* Bad input. */
  p.fraction = 0.0;
  CHECK(nh_mark_cells(m, eta, &p, marked, &n) == NH_ERR_INPUT, "fraction 0 accepted");
  p.strategy = NH_MARK_MAX, p.theta = 1.5;
  CHECK(nh_mark_cells(m, eta, &p, marked, &n) == NH_ERR_INPUT, "theta 1.5 accepted");
  p.theta = 0.5;
  double bad[10];
  memcpy(bad, eta, sizeof bad);
  bad[7] = -1.0;
  CHECK(nh_mark_cells(m, bad, &p, marked, &n) == NH_ERR_NUMERIC, "negative eta accepted");
  bad[7] = NAN;
  CHECK(nh_mark_cells(m, bad, &p, marked, &n) == NH_ERR_NUMERIC, "NaN eta accepted");
  nh_error_clear();
  nh_mesh_destroy(&m);
}

/* Test 7: SPR's cache of weights (nh_spr_estimate_cached) against the
 * estimate that makes them node by node (nh_spr_estimate), on a 4x3x3 grid
 * through a refinement of corner cell A, its coarsening together with a
 * refinement of the opposite corner cell B (every count — nodes, cells,
 * leaves, hanging nodes — as with A refined, whose weights the cache
 * holds), and B's coarsening back to the grid. At each mesh, for two displacement
 * fields: ηₑ, η and η_rel equal to the uncached ones to round-off, and the
 * weights made again exactly when the mesh changed (a stale cache gives
 * the previous mesh's patches: differences of the order of ηₑ). The
 * cached path's stresses (vectorised over the points, the cached
 * gradients) and the uncached one's (nh_hex_stress_at) are the same
 * arithmetic, so the estimates are also compared bit for bit; and again
 * with the rotations taken from an assembly's frames at u
 * (nh_system_frames_at), which must be there after an assembly at u and
 * not for another u. Both formulations (full and B-bar). */
static void check_cached(nh_spr_cache *k, const nh_mesh *m, const nh_tissue *t, int builds,
                         const char *what) {
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(m, NULL, &h));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes);
  double *e1 = calloc((size_t)m->n_cells, sizeof(double)),
         *e2 = calloc((size_t)m->n_cells, sizeof(double));
  for (int field = 0; field < 2; field++) {
    for (int i = 0; i < 3 * m->n_nodes; i++) u[i] = 1e-4 * nh_rand();
    if (h->n_hanging) /* hanging nodes follow their masters, as in a run */
      for (int j = 0; j < h->n_hanging; j++)
        for (int i = 0; i < 3; i++) {
          double v = 0.0;
          for (int p = h->start[j]; p < h->start[j + 1]; p++)
            v += h->weight[p] * u[3 * h->master[p] + i];
          u[3 * h->node[j] + i] = v;
        }
    double eta1, eta2, r1, r2, scale = 0.0, diff = 0.0;
    CHECK_OK(nh_spr_estimate(m, t, u, h, e1, &eta1, &r1));
    /* the frames of an assembly at u (x = 0 face fixed) */
    unsigned char *fixed = calloc((size_t)m->n_nodes, 1);
    for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i] < 1e-9;
    nh_system *sys;
    CHECK_OK(nh_system_create(t, fixed, h, &sys));
    double *f = calloc(3 * (size_t)m->n_nodes, sizeof(double));
    nh_system_assemble(sys, u, NULL, 1.0, 1.0, f, NULL, 1);
    const double *frames = nh_system_frames_at(sys, t, u);
    CHECK(frames != NULL, "%s: no frames after an assembly at u", what);
    u[0] += 1e-9;
    CHECK(nh_system_frames_at(sys, t, u) == NULL, "%s: frames of another u handed out", what);
    u[0] -= 1e-9;
    CHECK_OK(nh_spr_estimate_cached(k, m, t, u, h, frames, e2, &eta2, &r2));
    CHECK(memcmp(e1, e2, sizeof(double) * m->n_cells) == 0 && eta1 == eta2 && r1 == r2,
          "%s: the estimate with the frames' rotations is not bitwise the uncached one", what);
    nh_system_destroy(&sys);
    free(fixed), free(f);
    memset(e2, 0, sizeof(double) * m->n_cells);
    CHECK_OK(nh_spr_estimate_cached(k, m, t, u, h, NULL, e2, &eta2, &r2));
    CHECK(memcmp(e1, e2, sizeof(double) * m->n_cells) == 0 && eta1 == eta2 && r1 == r2,
          "%s: the cached estimate is not bitwise the uncached one", what);
    for (int l = 0; l < m->n_leaves; l++) {
      int c = m->leaves[l];
      scale = fmax(scale, e1[c]);
      diff = fmax(diff, fabs(e2[c] - e1[c]));
    }
    CHECK(scale > 0.0, "%s: the test field has eta_e = 0", what);
    CHECK_CLOSE(diff / scale, 0.0, 1e-14, what);
    CHECK_CLOSE(eta2, eta1, 1e-14 * eta1, what);
    CHECK_CLOSE(r2, r1, 1e-14 * r1, what);
    CHECK(nh_spr_cache_builds(k) == builds, "%s: the weights were made %d times, expected %d", what,
          nh_spr_cache_builds(k), builds);
    if (getenv("NH_VERBOSE"))
      printf("cache, %s, field %d: %d leaves, %d hanging, max |eta_e cached - uncached| / max "
             "eta_e %.2e\n",
             what, field, m->n_leaves, h->n_hanging, diff / scale);
  }
  free(u), free(e1), free(e2);
  nh_hanging_destroy(&h);
}

static void test_cache(nh_formulation formulation) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.03, 0.03};
  const int grid[3] = {4, 3, 3};
  nh_test_rng = 2718;
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_tissue *t;
  nh_material mt = mat;
  mt.formulation = formulation;
  CHECK_OK(nh_tissue_create(m, &mt, &t));
  nh_template *tmpl = regular_template(2);
  nh_spr_cache *k;
  CHECK_OK(nh_spr_cache_create(&k));
  check_cached(k, m, t, 1, "the grid");
  int A = 0, B = 3 + 4 * (2 + 3 * 2); /* cells (0,0,0) and (3,2,2) */
  CHECK_OK(nh_mesh_refine(m, tmpl, &A, 1, NULL));
  CHECK_OK(nh_tissue_update(t));
  check_cached(k, m, t, 2, "corner A refined");
  const int counts[3] = {m->n_nodes, m->n_cells, m->n_leaves};
  int *map = malloc(sizeof(int) * m->n_nodes);
  CHECK_OK(nh_mesh_coarsen(m, &A, 1, map)); /* no estimate between: the cache holds A's */
  CHECK_OK(nh_mesh_refine(m, tmpl, &B, 1, NULL));
  CHECK_OK(nh_tissue_update(t));
  CHECK(m->n_nodes == counts[0] && m->n_cells == counts[1] && m->n_leaves == counts[2],
        "corner B refined: %d nodes, %d cells, %d leaves; A refined had %d, %d, %d (the test "
        "needs equal counts)",
        m->n_nodes, m->n_cells, m->n_leaves, counts[0], counts[1], counts[2]);
  check_cached(k, m, t, 3, "A coarsened, corner B refined");
  CHECK_OK(nh_mesh_coarsen(m, &B, 1, map));
  CHECK_OK(nh_tissue_update(t));
  check_cached(k, m, t, 4, "B coarsened: the grid again");
  nh_spr_cache_destroy(&k);
  CHECK(k == NULL, "nh_spr_cache_destroy leaves the pointer set");
  free(map);
  nh_template_destroy(&tmpl);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(void) {
  test_element_stress(NH_FORMULATION_BBAR);
  test_element_stress(NH_FORMULATION_FULL);
  const double small[9] = {1e-4, 2e-5, -3e-5, 0.5e-4, -1e-4, 2e-5, 1e-5, 3e-5, 0.7e-4};
  double r[3] = {0.4, 0.1, -0.3}, Q[9], U[9] = {1.05, 0.01, 0.0, 0.01, 0.98, 0.02, 0.0, 0.02, 1.03},
         finite[9];
  nh_mat3_rotation(r, Q);
  nh_mat3_mul(Q, U, finite);
  for (int i = 0; i < 3; i++) finite[4 * i] -= 1.0;
  double medium[9];
  for (int i = 0; i < 9; i++) medium[i] = 100 * small[i]; /* strains of 1e-2 */
  const int box[3] = {4, 3, 3}, layer[3] = {4, 3, 1}, column[3] = {1, 1, 5};
  /* The corotational stress has a round-off floor of about eps / strain (R
   * is computed per cell, its rounding enters ε amplified by 1/strain: the
   * centre stresses of one homogeneous field scatter by 1.2e-11 at strain
   * 1e-4, 1e-13 at 1e-2, measured), so the small field gets 1e-10. */
  test_linear_displacement(box, 0.0, small, 1e-10, "strain 1e-4, box grid");
  test_linear_displacement(box, 0.3, small, 1e-10, "strain 1e-4, perturbed grid");
  test_linear_displacement(layer, 0.0, small, 1e-10, "strain 1e-4, one-layer grid (fallback)");
  test_linear_displacement(box, 0.0, medium, 1e-12, "strain 1e-2, box grid");
  test_linear_displacement(box, 0.3, medium, 1e-12, "strain 1e-2, perturbed grid");
  test_linear_displacement(layer, 0.0, medium, 1e-12, "strain 1e-2, one-layer grid (fallback)");
  test_linear_displacement(box, 0.3, finite, 1e-12, "finite + rotation, perturbed grid");
  test_linear_displacement(column, 0.0, finite, 1e-12, "finite + rotation, one column (fallback)");
  test_linear_stress();
  for (int n = 2; n <= 4; n++) test_nonconforming(n);
  test_threads();
  test_cache(NH_FORMULATION_FULL);
  test_cache(NH_FORMULATION_BBAR);
  test_marking();
  TEST_END();
}
