/* test_sample — a nodal field at points and voxel centres, and the inverse
 * map (src/mesh/sample.c; docs/anatomy.md, "Displacement fields and
 * shifted images").
 *  1. A box mesh (4 x 3 x 2 cells of 1 cm) with two cells refined by hex2
 *     and a child refined again (hanging nodes, chains). A linear field
 *     u = a + B X is represented exactly by trilinear elements: sampled at
 *     1000 random points and at every voxel centre of a rotated image
 *     (direction cosines a rotation, 1.3 mm voxels) it equals a + B X to
 *     1e-15 m (round-off of |u| ~ 1e-3 m).
 *  2. A nonlinear field (sines at the non-hanging nodes, hanging nodes their
 *     masters' interpolation, as the solver keeps them): continuous across
 *     the refinement faces (points 1e-9 h on either side differ by less than
 *     1e-8 |u|: the Lipschitz bound times 2e-9 h, plus round-off); the
 *     lattice walk equals an independent evaluation (nh_mesh_locate, then
 *     Σ Nₐ uₐ) at every voxel centre to 1e-15 m.
 *  3. An immersed ball (radius 13 mm on a 6³ grid): the tissue mask is 1 at
 *     the voxel centres inside the ball and 0 outside (centres within 1e-9 m
 *     of the sphere skipped), with value 0 where the mask is 0; points
 *     outside the lattice's box are outside.
 *  4. The inverse map of u = a + B X, B symmetric with eigenvalues 0.2,
 *     −0.15, 0.1 (L = ‖B‖₂ = 0.2): X(x) = (I + B)⁻¹ (x − a) is known; every
 *     voxel converges in the tissue with |X − X*| ≤ L/(1 − L) tol + 1e-15;
 *     the contraction ratio seen is ≤ L; the iterations are at most
 *     1 + ⌈log(tol / ((1 + L) 2 max|u|)) / log L⌉ (the contraction argument:
 *     |X_{k+1} − X_k| ≤ L^k (1 + L) |X_0 − X*|, |X_0 − X*| ≤ 2 max|u|).
 *  5. The outcomes on a box translated by t = 3 mm along x, on rows of
 *     voxel centres through it: x − t in the box: X = x − t in the tissue
 *     (also for x beyond the box, found by the restart from the box's
 *     surface); x in the box but x − t not (the iterates cycle across the
 *     −x face, where u jumps to 0): unconverged, X = x, stopped within 10
 *     evaluations of u; else outside, X = x.
 *  6. The warp of a smooth field u = a + ε g(X), g a Gaussian bump
 *     (σ = 8 mm, ε = 1.5 mm), nodal values on a 1 mm mesh: for an image
 *     linear in x (trilinear interpolation exact) the warped value equals
 *     c · X*(x) + d, X* the exact inverse of the closed form (Newton with
 *     the analytic Jacobian), to |c| (e_h / (1 − L) + tol L / (1 − L)),
 *     e_h = √3 (h²/8) · 3 · 2ε/σ², the trilinear interpolation bound
 *     (h²/8) Σ_k max|∂²u/∂X_k²| per component with |∂²g/∂x²| ≤ 2/σ²; for a
 *     label image (a ball) the nearest-label warp equals the label of the
 *     voxel nearest X*, wherever X*'s index is farther than the bound from a
 *     rounding boundary.
 * Silent on success; NH_TEST_VERBOSE=1 prints the measured numbers. */
#include "check.h"
#include "hanging_mesh.h"

#include <string.h>

static int verbose;

/* An image of n voxels with world = R diag(h) ijk + t (metres), header only. */
static nh_image *make_image(const int n[3], const double R[9], const double h[3],
                            const double t[3]) {
  nh_image *im = calloc(1, sizeof *im);
  im->refs = 1;
  for (int k = 0; k < 3; k++) {
    im->n[k] = n[k], im->t[k] = t[k], im->spacing[k] = h[k];
    for (int r = 0; r < 3; r++) im->A[3 * r + k] = R[3 * r + k] * h[k];
  }
  CHECK_OK(nh_mat3_inverse(im->A, im->Ainv));
  return im;
}

static size_t voxels(const nh_image *im) {
  return (size_t)im->n[0] * im->n[1] * im->n[2];
}

static void voxel_centre(const nh_image *im, size_t v, double x[3]) {
  double ijk[3] = {(double)(v % im->n[0]), (double)(v / im->n[0] % im->n[1]),
                   (double)(v / ((size_t)im->n[0] * im->n[1]))};
  nh_image_to_world(im, ijk, x);
}

static const double a_lin[3] = {1.0e-3, -2.0e-3, 0.5e-3};
static double B_lin[9];

static void linear_u(const double X[3], double u[3]) {
  nh_mat3_vec(B_lin, X, u);
  for (int k = 0; k < 3; k++) u[k] += a_lin[k];
}

/* B = Q diag(0.2, −0.15, 0.1) Qᵀ, Q a rotation. */
static void make_B(void) {
  double Q[9], D[9] = {0.2, 0, 0, 0, -0.15, 0, 0, 0, 0.1}, QD[9];
  const double rv[3] = {0.3, -0.5, 0.2};
  nh_mat3_rotation(rv, Q);
  nh_mat3_mul(Q, D, QD);
  nh_mat3_mul_nt(QD, Q, B_lin);
}

static nh_mesh *refined_box(const double lo[3], const double hi[3], const int grid[3],
                            nh_hanging **hang) {
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_template *t = regular_template(2);
  int first[2] = {1 + grid[0] * (1 + grid[1] * 0), 2 + grid[0] * (1 + grid[1] * 1)};
  CHECK_OK(nh_mesh_refine(m, t, first, 2, NULL));
  int again = m->first_child[first[0]] + 7; /* the child at the (+, +, +) corner */
  CHECK_OK(nh_mesh_refine(m, t, &again, 1, NULL));
  nh_template_destroy(&t);
  CHECK_OK(nh_hanging_detect(m, NULL, hang));
  CHECK((*hang)->n_hanging > 0, "the mesh has hanging nodes");
  return m;
}

/* Σ Nₐ uₐ at x through nh_mesh_locate (the independent path); 0 if outside. */
static int locate_value(const nh_mesh *m, const double *field, const double x[3], double u[3]) {
  int c;
  double xi[3], N[8];
  u[0] = u[1] = u[2] = 0.0;
  if (nh_mesh_locate(m, x, &c, xi) != NH_OK) return 0;
  nh_hex_shape(xi, N);
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) u[k] += N[a] * field[3 * m->cells[8 * c + a] + k];
  return 1;
}

static void sampling(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.03, 0.02};
  const int grid[3] = {4, 3, 2};
  nh_hanging *hang;
  nh_mesh *m = refined_box(lo, hi, grid, &hang);
  double *field = malloc(sizeof(double) * 3 * m->n_nodes);
  /* 1. linear */
  for (int i = 0; i < m->n_nodes; i++) linear_u(m->X + 3 * i, field + 3 * i);
  double X[3000], val[3000], want[3];
  unsigned char in[1000];
  nh_test_rng = 42;
  for (int i = 0; i < 1000; i++)
    for (int k = 0; k < 3; k++) X[3 * i + k] = lo[k] + (hi[k] - lo[k]) * 0.5 * (1 + nh_rand());
  nh_mesh_sample(m, field, 1000, X, val, in);
  double err = 0.0;
  for (int i = 0; i < 1000; i++) {
    CHECK(in[i], "point %d in the box is in the tissue", i);
    linear_u(X + 3 * i, want);
    for (int k = 0; k < 3; k++) err = fmax(err, fabs(val[3 * i + k] - want[k]));
  }
  CHECK_CLOSE(err, 0.0, 1e-15, "linear field at random points");
  double R[9];
  const double rv[3] = {0.2, 0.1, -0.4}, h[3] = {1.3e-3, 1.3e-3, 1.3e-3},
               t[3] = {0.006, 0.004, 0.002};
  nh_mat3_rotation(rv, R);
  const int n[3] = {24, 18, 12};
  nh_image *im = make_image(n, R, h, t);
  size_t nv = voxels(im);
  double *u = malloc(sizeof(double) * 3 * nv), *u2 = malloc(sizeof(double) * 3 * nv);
  unsigned char *mask = malloc(nv);
  CHECK_OK(nh_mesh_sample_image(m, field, im, u, mask));
  err = 0.0;
  long inside = 0;
  for (size_t v = 0; v < nv; v++) {
    double x[3];
    voxel_centre(im, v, x);
    int in_box = 1;
    for (int k = 0; k < 3; k++) in_box &= x[k] > lo[k] + 1e-12 && x[k] < hi[k] - 1e-12;
    CHECK(mask[v] == in_box, "voxel %zu: mask %d, in the box %d", v, mask[v], in_box);
    inside += mask[v];
    linear_u(x, want);
    for (int k = 0; k < 3 && in_box; k++) err = fmax(err, fabs(u[3 * v + k] - want[k]));
    for (int k = 0; k < 3 && !mask[v]; k++) CHECK(u[3 * v + k] == 0.0, "0 outside the tissue");
  }
  CHECK_CLOSE(err, 0.0, 1e-15, "linear field at voxel centres");
  CHECK(inside > 1000 && inside < (long)nv, "the image is partly inside (%ld of %zu)", inside, nv);
  /* 2. nonlinear, hanging nodes interpolated */
  for (int i = 0; i < m->n_nodes; i++) {
    const double *p = m->X + 3 * i;
    field[3 * i] = 1e-3 * sin(150 * p[0] + 40 * p[2]);
    field[3 * i + 1] = 1e-3 * cos(90 * p[1]) * sin(200 * p[2]);
    field[3 * i + 2] = 1e-3 * sin(120 * p[0] * p[1] / 0.03);
  }
  nh_hanging_interpolate(hang, field, 3);
  CHECK_OK(nh_mesh_sample_image(m, field, im, u, mask));
  err = 0.0;
  for (size_t v = 0; v < nv; v++) {
    double x[3], w[3];
    voxel_centre(im, v, x);
    if (!mask[v]) continue;
    CHECK(locate_value(m, field, x, w), "voxel %zu located", v);
    for (int k = 0; k < 3; k++) err = fmax(err, fabs(u[3 * v + k] - w[k]));
  }
  CHECK_CLOSE(err, 0.0, 1e-15, "lattice walk vs nh_mesh_locate");
  /* continuity across the faces of the refined cells: x = 0.01 and 0.02 (the
     first cell spans [0.01, 0.02] x [0.01, 0.02] x [0, 0.01]) and the face
     y = 0.02 of its refined child's neighbours */
  double jump = 0.0, umax = 1e-3;
  const double eps = 1e-9 * 0.01;
  for (int s = 0; s < 400; s++) {
    double p[3] = {0.01 + 0.01 * (s % 2), 0.01 + 0.01 * (0.5 + 0.5 * nh_rand()),
                   0.005 + 0.005 * nh_rand()};
    int axis = 0;
    if (s >= 200) { /* the face z = 0.01 above the first refined cell */
      p[0] = 0.01 + 0.01 * (0.5 + 0.5 * nh_rand()), p[2] = 0.01, axis = 2;
    }
    double pa[3], pb[3], ua[3], ub[3];
    memcpy(pa, p, sizeof pa), memcpy(pb, p, sizeof pb);
    pa[axis] -= eps, pb[axis] += eps;
    nh_mesh_sample(m, field, 1, pa, ua, NULL);
    nh_mesh_sample(m, field, 1, pb, ub, NULL);
    for (int k = 0; k < 3; k++) jump = fmax(jump, fabs(ua[k] - ub[k]));
  }
  CHECK_CLOSE(jump, 0.0, 1e-8 * umax, "continuity across refinement faces");
  if (verbose) printf("sampling: %ld of %zu voxels inside; jump %.3g m\n", inside, nv, jump);
  free(u), free(u2), free(mask), free(field);
  nh_image_release(&im);
  nh_hanging_destroy(&hang);
  nh_mesh_destroy(&m);
}

static void ball_mask(void) {
  const double c[3] = {0.001, -0.002, 0.0005}, r = 0.013;
  nh_domain d;
  nh_domain_sphere(c, r, &d);
  nh_mesh *m;
  const int grid[3] = {6, 6, 6};
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  double *field = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < 3 * m->n_nodes; i++) field[i] = 1e-3;
  double I[9];
  nh_mat3_identity(I);
  const int n[3] = {20, 20, 20};
  const double h[3] = {1.6e-3, 1.6e-3, 1.6e-3}, t[3] = {-0.0142, -0.0172, -0.0147};
  nh_image *im = make_image(n, I, h, t);
  size_t nv = voxels(im);
  double *u = malloc(sizeof(double) * 3 * nv);
  unsigned char *mask = malloc(nv);
  CHECK_OK(nh_mesh_sample_image(m, field, im, u, mask));
  long in = 0, bad = 0;
  for (size_t v = 0; v < nv; v++) {
    double x[3], dx[3];
    voxel_centre(im, v, x);
    for (int k = 0; k < 3; k++) dx[k] = x[k] - c[k];
    double dist = nh_vec3_norm(dx) - r;
    in += mask[v];
    if (fabs(dist) > 1e-9 && mask[v] != (dist < 0)) bad++;
    if (mask[v]) CHECK(fabs(u[3 * v] - 1e-3) < 1e-15, "u inside");
    if (!mask[v]) CHECK(u[3 * v] == 0.0 && u[3 * v + 1] == 0.0, "u = 0 outside");
  }
  CHECK(bad == 0, "%ld voxels with the wrong mask", bad);
  CHECK(in > 1000, "%ld voxels in the ball", in);
  double far[3] = {0.5, 0, 0}, uf[3];
  unsigned char inf;
  nh_mesh_sample(m, field, 1, far, uf, &inf);
  CHECK(!inf && uf[0] == 0.0, "a point outside the lattice is outside");
  free(u), free(mask), free(field);
  nh_image_release(&im);
  nh_mesh_destroy(&m);
  nh_domain_release(&d);
}

static void inverse_linear(void) {
  /* a mesh well around the image, so that every X* lies inside it */
  const double lo[3] = {-0.03, -0.03, -0.03}, hi[3] = {0.05, 0.05, 0.05};
  const int grid[3] = {8, 8, 8};
  nh_hanging *hang;
  nh_mesh *m = refined_box(lo, hi, grid, &hang);
  double *field = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) linear_u(m->X + 3 * i, field + 3 * i);
  double I[9];
  nh_mat3_identity(I);
  const int n[3] = {16, 14, 12};
  const double h[3] = {1e-3, 1.2e-3, 1.5e-3}, t[3] = {0.002, 0.001, 0.0};
  nh_image *im = make_image(n, I, h, t);
  size_t nv = voxels(im);
  double *X = malloc(sizeof(double) * 3 * nv), IB[9], IBinv[9];
  unsigned char *status = malloc(nv);
  nh_mat3_identity(IB);
  for (int i = 0; i < 9; i++) IB[i] += B_lin[i];
  CHECK_OK(nh_mat3_inverse(IB, IBinv));
  nh_inverse_stats st;
  CHECK_OK(nh_mesh_inverse_image(m, field, im, NULL, X, status, &st));
  const double L = 0.2, tol = 1e-3 * 1e-3;
  double err = 0.0, umax = 0.0;
  for (size_t v = 0; v < nv; v++) {
    double x[3], r[3], Xs[3], u[3];
    voxel_centre(im, v, x);
    for (int k = 0; k < 3; k++) r[k] = x[k] - a_lin[k];
    nh_mat3_vec(IBinv, r, Xs);
    linear_u(Xs, u);
    umax = fmax(umax, nh_vec3_norm(u));
    CHECK(status[v] == NH_INVERSE_TISSUE, "voxel %zu: status %d", v, status[v]);
    for (int k = 0; k < 3; k++) err = fmax(err, fabs(X[3 * v + k] - Xs[k]));
  }
  CHECK_CLOSE(err, 0.0, L / (1 - L) * tol + 1e-15, "inverse of a linear map");
  int bound = 1 + (int)ceil(log(tol / ((1 + L) * 2 * umax)) / log(L));
  CHECK(st.iterations_max <= bound, "iterations %d, bound %d", st.iterations_max, bound);
  CHECK(st.contraction <= L + 1e-9, "contraction %g > L = %g", st.contraction, L);
  CHECK(st.points == (long)nv && st.tissue == (long)nv && st.unconverged == 0, "statistics");
  if (verbose)
    printf("inverse (linear, L = %.2f): error %.3g m (tol %.3g m), iterations max %d mean %.2f "
           "(bound %d), contraction seen %.3f\n",
           L, err, tol, st.iterations_max, st.iterations_mean, bound, st.contraction);
  free(X), free(status), free(field);
  nh_image_release(&im);
  nh_hanging_destroy(&hang);
  nh_mesh_destroy(&m);
}

/* A box translated by t: the three outcomes of the inverse map. */
static void inverse_outcomes(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.02, 0.02, 0.02}, t[3] = {3e-3, 0, 0};
  const int grid[3] = {4, 4, 4};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  double *field = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) memcpy(field + 3 * i, t, sizeof t);
  double I[9];
  nh_mat3_identity(I);
  /* voxel centres at x = -4.5 .. 25.5 mm (1 mm), y and z inside the box */
  const int n[3] = {31, 3, 3};
  const double h[3] = {1e-3, 5e-3, 5e-3}, o[3] = {-4.5e-3, 5e-3, 5e-3};
  nh_image *im = make_image(n, I, h, o);
  size_t nv = voxels(im);
  double *X = malloc(sizeof(double) * 3 * nv);
  unsigned char *status = malloc(nv);
  nh_inverse_stats st;
  CHECK_OK(nh_mesh_inverse_image(m, field, im, NULL, X, status, &st));
  long count[3] = {0, 0, 0};
  for (size_t v = 0; v < nv; v++) {
    double x[3], want[3];
    voxel_centre(im, v, x);
    int from_tissue = x[0] - t[0] > lo[0] && x[0] - t[0] < hi[0];
    int in_box = x[0] > lo[0] && x[0] < hi[0];
    int expect = from_tissue ? NH_INVERSE_TISSUE
                 : in_box    ? NH_INVERSE_UNCONVERGED
                             : NH_INVERSE_OUTSIDE;
    for (int k = 0; k < 3; k++) want[k] = x[k] - (from_tissue ? t[k] : 0.0);
    CHECK(status[v] == expect, "x = %g mm: status %d, expected %d", 1e3 * x[0], status[v], expect);
    for (int k = 0; k < 3; k++) CHECK_CLOSE(X[3 * v + k], want[k], 1e-12, "X of an outcome");
    count[status[v]]++;
  }
  /* 20 centres along x come from the tissue (3 of them beyond the box, x in
     (20, 23) mm), 3 cycle at the -x face (x in (0, 3) mm), 8 are outside */
  CHECK(count[NH_INVERSE_TISSUE] == 20 * 9 && count[NH_INVERSE_UNCONVERGED] == 3 * 9,
        "outcomes: %ld tissue, %ld unconverged, %ld outside", count[1], count[2], count[0]);
  CHECK(st.iterations_max <= 10, "iterations at most %d", st.iterations_max);
  if (verbose)
    printf(
        "outcomes (box moved 3 mm): %ld tissue, %ld unconverged, %ld outside, iterations max %d\n",
        count[1], count[2], count[0], st.iterations_max);
  free(X), free(status), free(field);
  nh_image_release(&im);
  nh_mesh_destroy(&m);
}

/* The smooth field u = a + ε exp(−|X − c|²/σ²) e and its Jacobian. */
static const double bump_c[3] = {0.012, 0.010, 0.009}, bump_e[3] = {0.6, -0.48, 0.64};
static const double bump_eps = 1.5e-3, bump_sigma = 8e-3;
static const double bump_a[3] = {0.7e-3, 0.4e-3, -1.1e-3};

static void bump_u(const double X[3], double u[3], double J[9]) {
  double r2 = 0.0, d[3];
  for (int k = 0; k < 3; k++) d[k] = X[k] - bump_c[k], r2 += d[k] * d[k];
  double g = bump_eps * exp(-r2 / (bump_sigma * bump_sigma));
  for (int k = 0; k < 3; k++) u[k] = bump_a[k] + g * bump_e[k];
  if (J)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++)
        J[3 * i + j] = bump_e[i] * g * (-2.0 * d[j]) / (bump_sigma * bump_sigma);
}

/* X* with X* + u(X*) = x by Newton's method on the closed form. */
static void bump_inverse(const double x[3], double X[3]) {
  memcpy(X, x, 3 * sizeof(double));
  for (int it = 0; it < 50; it++) {
    double u[3], J[9], r[3], d[3], Jinv[9];
    bump_u(X, u, J);
    for (int k = 0; k < 3; k++) r[k] = X[k] + u[k] - x[k], J[4 * k] += 1.0;
    CHECK_OK(nh_mat3_inverse(J, Jinv));
    nh_mat3_vec(Jinv, r, d);
    for (int k = 0; k < 3; k++) X[k] -= d[k];
    if (nh_vec3_norm(d) < 1e-16) break;
  }
}

static void warp_smooth(void) {
  const double lo[3] = {-0.01, -0.01, -0.01}, hi[3] = {0.034, 0.03, 0.028};
  const int grid[3] = {44, 40, 38}; /* h = 1 mm */
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  double *field = malloc(sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) bump_u(m->X + 3 * i, field + 3 * i, NULL);
  double R[9];
  const double rv[3] = {0.0, 0.0, 0.3}, hv[3] = {0.8e-3, 0.8e-3, 0.8e-3}, t[3] = {0.0, 0.0, 0.0};
  nh_mat3_rotation(rv, R);
  const int n[3] = {28, 26, 24};
  nh_image *im = make_image(n, R, hv, t);
  size_t nv = voxels(im);
  /* a linear intensity and a ball of label 7 */
  const double cgrad[3] = {3.0e4, -1.0e4, 2.0e4}, d0 = 500.0, ball_c[3] = {0.011, 0.009, 0.010},
               ball_r = 0.005;
  double *lin = malloc(sizeof(double) * nv), *lab = malloc(sizeof(double) * nv),
         *out = malloc(sizeof(double) * nv), *outl = malloc(sizeof(double) * nv);
  for (size_t v = 0; v < nv; v++) {
    double x[3], dx[3];
    voxel_centre(im, v, x);
    lin[v] = d0 + nh_vec3_dot(cgrad, x);
    for (int k = 0; k < 3; k++) dx[k] = x[k] - ball_c[k];
    lab[v] = nh_vec3_norm(dx) < ball_r ? 7.0 : 0.0;
  }
  nh_inverse_stats st, stl;
  CHECK_OK(nh_mesh_warp_image(m, field, im, lin, 0, NULL, out, &st));
  CHECK_OK(nh_mesh_warp_image(m, field, im, lab, 1, NULL, outl, &stl));
  /* L = max |∇u| ≤ ε √2 e^{-1/2} / σ (the Gaussian's steepest slope) */
  const double L = bump_eps * sqrt(2.0) * exp(-0.5) / bump_sigma, h = 1e-3;
  const double tol = 1e-3 * 0.8e-3;
  const double eh = sqrt(3.0) * h * h / 8.0 * 3.0 * 2.0 * bump_eps / (bump_sigma * bump_sigma);
  const double xbound = eh / (1 - L) + tol * L / (1 - L);
  double err = 0.0;
  long checked = 0, mismatched = 0;
  for (size_t v = 0; v < nv; v++) {
    double x[3], Xs[3], p[3];
    voxel_centre(im, v, x);
    bump_inverse(x, Xs);
    nh_image_to_voxel(im, Xs, p);
    int inside = 1;
    for (int k = 0; k < 3; k++) inside &= p[k] >= 0.0 && p[k] <= n[k] - 1.0;
    if (!inside) continue; /* the analytic warp samples outside the image */
    double want = d0 + nh_vec3_dot(cgrad, Xs);
    err = fmax(err, fabs(out[v] - want));
    /* nearest label, away from rounding boundaries */
    double margin = 1.0;
    for (int k = 0; k < 3; k++) margin = fmin(margin, fabs(p[k] - floor(p[k]) - 0.5));
    if (margin * 0.8e-3 > xbound) {
      checked++;
      mismatched += outl[v] != nh_image_interpolate(im, lab, Xs, 1);
    }
  }
  CHECK_CLOSE(err, 0.0, nh_vec3_norm(cgrad) * xbound, "linear image warped vs analytic warp");
  CHECK(mismatched == 0 && checked > (long)nv / 2, "%ld of %ld labels differ", mismatched, checked);
  CHECK(st.unconverged == 0 && stl.unconverged == 0, "unconverged voxels");
  if (verbose)
    printf("warp (smooth bump, L <= %.3f): intensity error %.3g (bound %.3g), labels checked %ld "
           "of %zu, iterations max %d mean %.2f, contraction seen %.3f\n",
           L, err, nh_vec3_norm(cgrad) * xbound, checked, nv, st.iterations_max, st.iterations_mean,
           st.contraction);
  free(lin), free(lab), free(out), free(outl), free(field);
  nh_image_release(&im);
  nh_mesh_destroy(&m);
}

int main(void) {
  verbose = getenv("NH_TEST_VERBOSE") != NULL;
  make_B();
  sampling();
  ball_mask();
  inverse_linear();
  inverse_outcomes();
  warp_smooth();
  TEST_END();
}
