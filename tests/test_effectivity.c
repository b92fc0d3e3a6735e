/* test_effectivity — the effectivity index θ = η / ‖e‖_E of the SPR error
 * estimator (adapt/spr.c) against manufactured solutions, on a sequence of
 * uniform meshes.
 *
 * The problem. On the box Ω = [0, L]³ (L = 1 cm) with isotropic small-strain
 * elasticity (σ = λ tr ε I + 2μ ε, ε = sym ∇u), take smooth, non-polynomial
 * displacements of the separable form
 *   u_i(x) = a ∏_j g_ij(x_j),   g_ij(s) = sin(k_ij s + p_ij),
 * with wave numbers k_ij = κ_ij π / L and phases p_ij (tables below). Two
 * fields: `general` (every strain component, nonzero boundary values, no
 * symmetry between components; its error energy is 95-98 % normal strain)
 * and `shear` (u_i independent of x_i: ε_ii ≡ 0, div u ≡ 0, the error energy
 * is all shear). The second exists because a wrong shear term of D⁻¹ hardly
 * moves θ of the first (measured below). Derivatives are products of the
 * same factors:
 *   ∂_m u_i        = a g'_im(x_m) ∏_{j≠m} g_ij(x_j),
 *   ∂_m ∂_n u_i    = a g'_im g'_in ∏_{j≠m,n} g_ij     (m ≠ n),
 *   ∂_m ∂_m u_i    = a g''_im ∏_{j≠m} g_ij,
 * with g' = k cos(k s + p), g'' = −k² g. The body force that makes u an
 * exact solution is b = −div σ(u). Written out,
 *   σ_ij = λ δ_ij ∂_k u_k + μ (∂_i u_j + ∂_j u_i),
 *   ∂_j σ_ij = λ ∂_i (div u) + μ Δu_i + μ ∂_j ∂_i u_j
 *            = (λ + μ) ∂_i (div u) + μ Δu_i,
 * so   b_i = −(λ + μ) Σ_j ∂_i ∂_j u_j − μ Σ_j ∂_j ∂_j u_i,
 * evaluated from the Hessians above. The formula is checked against central
 * differences of σ(u) at three points (an independent path: a sign or a
 * factor would show far above the 1e-6 tolerance; the differences are
 * accurate to (k d)² ≈ 1e-7).
 *
 * The element is the fully integrated one (formulation full): ε_h below is
 * its strain and its centre stresses are the superconvergent samples; the
 * B-bar element has a different discrete stress (a mean pressure per cell).
 *
 * The discrete problem. Consistent nodal forces f_a = ∫ N_a b dV by 3x3x3
 * Gauss points per cell; u = u_exact (nodal interpolation) prescribed at
 * every boundary node; the static Newton solver to a relative residual of
 * 1e-10. The amplitude a = 1e-4 L (strains and rotations near 3e-4) is a
 * compromise between two limits: the corotational element departs from
 * linear elasticity as the rotations grow, and the relative residual floor
 * of the corotational solver grows like eps / strain (solve/integrate.c).
 * Measured: at a = 1e-6 L the floor is 1.6e-10 (tolerance 1e-10 fails), at
 * 1e-5 L the shear field needs 10 Newton iterations to reach 9.9e-11, at
 * 1e-4 L every solve converges in 3-4 iterations to below 6e-11; and θ and
 * ‖e‖_E agree to 5 digits between a = 1e-6 L (tolerance 1e-9), 1e-5 L and
 * 1e-4 L, so the geometric nonlinearity is invisible in what is asserted.
 *
 * The exact error. ‖e‖²_E = Σ_cells ∫ (ε − ε_h) : C : (ε − ε_h) dV by 4x4x4
 * Gauss points per cell, ε from the analytic gradient and ε_h = sym ∇u_h
 * from the nodal displacements through the shape-function gradients (small
 * strain; the corotational correction is below 1e-5 relative, see above).
 * The integrand is smooth inside a cell and the 4-point rule is exact to
 * degree 7 per direction, so the quadrature error is far below anything
 * asserted.
 *
 * What is asserted, and why:
 *  1. ‖e‖_E converges at the order of the energy norm of trilinear elements,
 *     O(h): between the two finest meshes log(e₁/e₂)/log(h₁/h₂) lies in
 *     [0.85, 1.15] (measured 0.997-1.000).
 *  2. θ → 1. SPR recovers σ* from the centre stresses, which are
 *     superconvergent for the trilinear hexahedron on a uniform grid, so
 *     ‖σ* − σ‖ = O(h^{1+α}) while ‖σ_h − σ‖ = O(h), and θ = 1 + O(h^α).
 *     Boundary nodes use a grown patch extrapolated to the node (spr.c §3):
 *     the same linear fit of superconvergent samples with a larger leverage
 *     (13/8 at a corner against 1/8 inside), i.e. a larger constant, not a
 *     lower order — consistent with the measured |θ − 1|, which falls like
 *     h^1.1-1.2 from n = 4 to 8 and like h^1.9-2.1 beyond (table below).
 *     Asserted: |θ − 1| does not grow from one mesh to the next (slack
 *     0.01), and on the finest mesh θ ∈ [0.9, 1.1]. Zienkiewicz and Zhu
 *     (1992, Part 2) report 0.9-1.2 for linear elements on smooth problems
 *     over mixed meshes; a uniform mesh of a smooth solution is the most
 *     favourable case (superconvergence holds in every patch), so the band
 *     is narrowed to ±0.1 around the asymptotic value 1 once the mesh
 *     resolves the shortest wavelength (1.6 L) with ≥ 25 cells.
 *  3. θ ∈ [0.8, 1.4] on every mesh. The coarse meshes are pre-asymptotic:
 *     at n = 4 the shortest wavelength has 6.4 cells and 56 of the 64 cells
 *     touch the boundary, and SPR overestimates (θ = 1.24-1.32 measured),
 *     as a linear fit over a patch of width 2h cannot follow the field's
 *     curvature. 1.4 is the ceiling: wider would let an estimator that is
 *     off by √2 pass on the coarse meshes.
 * Detection, tried on a private copy of the sources: η × √2 fails every
 * mesh; η / √2 gives θ = 0.72 on the finest mesh; tensor instead of
 * engineering shears in D⁻¹ moves the general field only from 1.016 to 1.003
 * but the shear field to 0.715; σ* without the linear term of the fit (the
 * patch mean) gives 1.14 on the finest mesh; η × 1.15 gives 1.17. All fail.
 *
 * Measured (Release, NH_VERBOSE prints the table):
 *   field    ν      n=4     n=8     n=16    n=24
 *   general  0.30   1.2886  1.1353  1.0367  1.0158
 *   general  0.45   1.3228  1.1486  1.0396  —
 *   shear    0.30   1.2411  1.1032  1.0268  1.0114
 * (ν = 0.45 stops at n = 16 to keep the test short; it adds the λ-dominated
 * regime, where θ behaves as for ν = 0.3.) */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#define LENGTH 0.01 /* box edge L, m */
#ifndef AMPLITUDE
#define AMPLITUDE (1e-4 * LENGTH) /* a, m (header) */
#endif
#ifndef TOLERANCE
#define TOLERANCE 1e-10 /* relative residual of the static solve */
#endif

/* Band of θ on every mesh, on the finest mesh, and the allowed growth of
 * |θ − 1| from one mesh to the next (see the header). */
#define THETA_LO      0.8
#define THETA_HI      1.4
#define THETA_FINE_LO 0.9
#define THETA_FINE_HI 1.1
#define THETA_SLACK   0.01
#define ORDER_LO      0.85
#define ORDER_HI      1.15

/* A manufactured field u_i = a ∏_j sin(k_ij x_j + p_ij), k_ij = κ_ij π / L. */
typedef struct {
  const char *name;
  double kappa[3][3]; /* component i, direction j */
  double phase[3][3];
} field;

/* General: every strain component present, no component vanishing on the
 * boundary, shortest wavelength 2L / 1.25 = 1.6 L. */
static const field general = {"general",
                              {{1.0, 0.5, 0.75}, {0.5, 1.25, 0.5}, {0.75, 0.5, 1.0}},
                              {{0.3, 0.9, 0.5}, {1.1, 0.2, 0.7}, {0.6, 1.3, 0.4}}};
/* Pure shear: κ_ii = 0, p_ii = π/2 make u_i independent of x_i, so
 * ε_ii ≡ 0 and div u ≡ 0; all the strain (and most of the error) is shear,
 * which the general field, dominated by normal strains, does not probe. */
static const field shear = {"shear",
                            {{0.0, 1.0, 0.5}, {0.75, 0.0, 1.0}, {1.0, 0.5, 0.0}},
                            {{M_PI / 2, 0.4, 1.2}, {0.8, M_PI / 2, 0.3}, {0.5, 1.0, M_PI / 2}}};

/* u(x), ∇u (G[3i+m] = ∂_m u_i) and the Hessian (H[9i+3m+n] = ∂_m ∂_n u_i);
 * G and H may be NULL. */
static void exact_field(const field *fd, const double x[3], double u[3], double G[9],
                        double H[27]) {
  for (int i = 0; i < 3; i++) {
    double g[3], dg[3], ddg[3];
    for (int j = 0; j < 3; j++) {
      double k = fd->kappa[i][j] * M_PI / LENGTH, arg = k * x[j] + fd->phase[i][j];
      g[j] = sin(arg), dg[j] = k * cos(arg), ddg[j] = -k * k * sin(arg);
    }
    u[i] = AMPLITUDE * g[0] * g[1] * g[2];
    for (int m = 0; m < 3 && G; m++) {
      double p = AMPLITUDE;
      for (int j = 0; j < 3; j++) p *= j == m ? dg[j] : g[j];
      G[3 * i + m] = p;
    }
    for (int m = 0; m < 3 && H; m++)
      for (int n = 0; n < 3; n++) {
        double p = AMPLITUDE;
        for (int j = 0; j < 3; j++) {
          if (j == m && j == n)
            p *= ddg[j];
          else if (j == m || j == n)
            p *= dg[j];
          else
            p *= g[j];
        }
        H[9 * i + 3 * m + n] = p;
      }
  }
}

/* σ = λ tr ε I + 2μ ε of a displacement gradient G (row-major tensor). */
static void stress_of_gradient(double lambda, double mu, const double G[9], double S[9]) {
  double tr = G[0] + G[4] + G[8];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      S[3 * i + j] = mu * (G[3 * i + j] + G[3 * j + i]) + (i == j ? lambda * tr : 0.0);
}

/* b = −(λ + μ) ∇(div u) − μ Δu (header). */
static void body_force(const field *fd, double lambda, double mu, const double x[3], double b[3]) {
  double u[3], H[27];
  exact_field(fd, x, u, NULL, H);
  for (int i = 0; i < 3; i++) {
    double grad_div = 0.0, lap = 0.0;
    for (int j = 0; j < 3; j++) {
      grad_div += H[9 * j + 3 * i + j]; /* ∂_i ∂_j u_j */
      lap += H[9 * i + 3 * j + j];      /* ∂_j ∂_j u_i */
    }
    b[i] = -(lambda + mu) * grad_div - mu * lap;
  }
}

/* The derivation of b against central differences of σ(u): div σ + b = 0. */
static void check_body_force(const field *fd, double lambda, double mu) {
  const double pts[3][3] = {{0.13, 0.71, 0.42}, {0.9, 0.05, 0.66}, {0.5, 0.5, 0.97}};
  const double d = 1e-4 * LENGTH;
  for (int p = 0; p < 3; p++) {
    double x[3], b[3], div[3] = {0, 0, 0};
    for (int k = 0; k < 3; k++) x[k] = pts[p][k] * LENGTH;
    body_force(fd, lambda, mu, x, b);
    for (int j = 0; j < 3; j++) {
      double xp[3], xm[3], u[3], Gp[9], Gm[9], Sp[9], Sm[9];
      memcpy(xp, x, sizeof xp), memcpy(xm, x, sizeof xm);
      xp[j] += d, xm[j] -= d;
      exact_field(fd, xp, u, Gp, NULL), exact_field(fd, xm, u, Gm, NULL);
      stress_of_gradient(lambda, mu, Gp, Sp), stress_of_gradient(lambda, mu, Gm, Sm);
      for (int i = 0; i < 3; i++) div[i] += (Sp[3 * i + j] - Sm[3 * i + j]) / (2.0 * d);
    }
    /* Central differences are accurate to (k d)² ~ 1e-7 relative. */
    double scale = fmax(fabs(b[0]), fmax(fabs(b[1]), fabs(b[2])));
    for (int i = 0; i < 3; i++)
      CHECK_CLOSE(-div[i], b[i], 1e-6 * scale, "body force b = -div sigma vs finite differences");
  }
}

/* Gauss rule of n points (3 or 4) on [-1, 1]. */
static void gauss_rule(int n, double x[4], double w[4]) {
  if (n == 3) {
    x[0] = -sqrt(0.6), x[1] = 0.0, x[2] = sqrt(0.6);
    w[0] = w[2] = 5.0 / 9.0, w[1] = 8.0 / 9.0;
  } else {
    double a = sqrt(3.0 / 7.0 - 2.0 / 7.0 * sqrt(1.2)), b = sqrt(3.0 / 7.0 + 2.0 / 7.0 * sqrt(1.2));
    x[0] = -b, x[1] = -a, x[2] = a, x[3] = b;
    w[1] = w[2] = (18.0 + sqrt(30.0)) / 36.0, w[0] = w[3] = (18.0 - sqrt(30.0)) / 36.0;
  }
}

/* At natural point xi of the cell with corners Xe: shape functions N, their
 * rest gradients g[8][3], the position x and det J. */
static double cell_point(const double Xe[24], const double xi[3], double N[8], double g[8][3],
                         double x[3]) {
  double dN[8][3], J[9] = {0}, Ji[9];
  nh_hex_shape(xi, N);
  nh_hex_dshape(xi, dN);
  for (int k = 0; k < 3; k++) x[k] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++) {
      x[i] += N[a] * Xe[3 * a + i];
      for (int j = 0; j < 3; j++) J[3 * i + j] += Xe[3 * a + i] * dN[a][j];
    }
  CHECK_OK(nh_mat3_inverse(J, Ji));
  /* ∇_X N_a = J⁻ᵀ ∇_ξ N_a. */
  for (int a = 0; a < 8; a++)
    for (int j = 0; j < 3; j++)
      g[a][j] = Ji[j] * dN[a][0] + Ji[3 + j] * dN[a][1] + Ji[6 + j] * dN[a][2];
  return nh_mat3_det(J);
}

typedef struct {
  int n, dofs, iterations;
  double error, eta, unorm, theta, residual;
  double shear_fraction; /* of ‖e‖²_E: the part 4μ Σ_{i<j} (ε − ε_h)²_ij */
} result;

static result run(const field *fd, int n, double poisson) {
  const double lo[3] = {0, 0, 0}, hi[3] = {LENGTH, LENGTH, LENGTH};
  const int grid[3] = {n, n, n};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {1e5, poisson, 1000, NH_FORMULATION_FULL};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  const double lambda = t->lambda, mu = t->mu;
  const int nn = m->n_nodes;
  unsigned char *fixed = calloc((size_t)nn, 1);
  double *u = calloc(3 * (size_t)nn, sizeof(double)), *f = calloc(3 * (size_t)nn, sizeof(double));
  int n_fixed = 0;
  for (int i = 0; i < nn; i++) {
    const double *X = m->X + 3 * i;
    int boundary = 0;
    for (int k = 0; k < 3; k++) {
      double tol = 1e-9 * m->spacing[k];
      boundary |= X[k] <= lo[k] + tol || X[k] >= hi[k] - tol;
    }
    fixed[i] = (unsigned char)boundary;
    n_fixed += boundary;
    if (boundary) exact_field(fd, X, u + 3 * i, NULL, NULL);
  }
  CHECK(n_fixed == nn - (n - 1) * (n - 1) * (n - 1), "n = %d: %d boundary nodes, expected %d", n,
        n_fixed, nn - (n - 1) * (n - 1) * (n - 1));

  /* Consistent nodal forces, 3x3x3 Gauss. */
  double gx[4], gw[4];
  gauss_rule(3, gx, gw);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int p = 0; p < 27; p++) {
      double xi[3] = {gx[p % 3], gx[(p / 3) % 3], gx[p / 9]}, N[8], g[8][3], x[3], b[3];
      double w = gw[p % 3] * gw[(p / 3) % 3] * gw[p / 9] * cell_point(Xe, xi, N, g, x);
      body_force(fd, lambda, mu, x, b);
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) f[3 * m->cells[8 * c + a] + k] += w * N[a] * b[k];
    }
  }

  nh_system *s;
  CHECK_OK(nh_system_create(t, fixed, NULL, &s));
  nh_integrator in = {.tolerance = TOLERANCE, .max_iterations = 30, .threads = 1};
  nh_step_stats st;
  CHECK_OK(nh_solve_static(s, &in, f, u, &st));

  /* Exact error and exact energy norm, 4x4x4 Gauss. */
  gauss_rule(4, gx, gw);
  double err2 = 0.0, norm2 = 0.0, err2_shear = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int p = 0; p < 64; p++) {
      double xi[3] = {gx[p % 4], gx[(p / 4) % 4], gx[p / 16]}, N[8], g[8][3], x[3];
      double w = gw[p % 4] * gw[(p / 4) % 4] * gw[p / 16] * cell_point(Xe, xi, N, g, x);
      double ue[3], G[9], Gh[9] = {0}, E[9], S[9], SE[9];
      exact_field(fd, x, ue, G, NULL);
      for (int a = 0; a < 8; a++) {
        const double *ua = u + 3 * m->cells[8 * c + a];
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++) Gh[3 * i + j] += ua[i] * g[a][j];
      }
      for (int k = 0; k < 9; k++) E[k] = G[k] - Gh[k];
      /* ε : C : ε = σ(∇e) : ∇e, σ symmetric, so the skew part drops. */
      stress_of_gradient(lambda, mu, E, SE);
      stress_of_gradient(lambda, mu, G, S);
      double e2 = 0.0, u2 = 0.0;
      for (int k = 0; k < 9; k++) e2 += SE[k] * E[k], u2 += S[k] * G[k];
      double sh = 0.0;
      for (int i = 0; i < 3; i++)
        for (int j = i + 1; j < 3; j++)
          sh += mu * (E[3 * i + j] + E[3 * j + i]) * (E[3 * i + j] + E[3 * j + i]);
      err2 += w * e2, norm2 += w * u2, err2_shear += w * sh;
    }
  }

  double eta = -1.0, eta_rel = -1.0;
  double *eta_cell = calloc((size_t)m->n_cells, sizeof(double));
  CHECK_OK(nh_spr_estimate(m, t, u, NULL, eta_cell, &eta, &eta_rel));

  result r = {n,           3 * nn,           st.iterations, sqrt(err2),       eta,
              sqrt(norm2), eta / sqrt(err2), st.residual,   err2_shear / err2};
  free(fixed), free(u), free(f), free(eta_cell);
  nh_system_destroy(&s);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  return r;
}

/* Meshes n = 4, 8, ..., up to `finest` cells per edge (sizes 4, 8, 16, 24). */
static void sequence(const field *fd, double poisson, int finest) {
  const int all[] = {4, 8, 16, 24};
  int count = 0, sizes[4];
  for (int k = 0; k < 4; k++)
    if (all[k] <= finest) sizes[count++] = all[k];
  result r[4];
  nh_material mat = {1e5, poisson, 1000, NH_FORMULATION_FULL};
  double lambda, mu;
  nh_lame(mat.young, mat.poisson, &lambda, &mu);
  check_body_force(fd, lambda, mu);
  int verbose = getenv("NH_VERBOSE") != NULL;
  if (verbose)
    printf("field %s, nu = %.2f\n%4s %8s %12s %12s %10s %7s %8s %8s %8s %6s %9s\n", fd->name,
           poisson, "n", "dofs", "|e|_E", "eta", "|e|/|u|", "shear", "theta", "ord(e)", "ord(eta)",
           "newton", "residual");
  for (int k = 0; k < count; k++) {
    r[k] = run(fd, sizes[k], poisson);
    double oe = 0.0, oh = 0.0;
    if (k > 0) {
      double ratio = log((double)sizes[k] / sizes[k - 1]);
      oe = log(r[k - 1].error / r[k].error) / ratio;
      oh = log(r[k - 1].eta / r[k].eta) / ratio;
    }
    if (verbose)
      printf("%4d %8d %12.5e %12.5e %10.4e %7.3f %8.4f %8.4f %8.4f %6d %9.2e\n", r[k].n, r[k].dofs,
             r[k].error, r[k].eta, r[k].error / r[k].unorm, r[k].shear_fraction, r[k].theta, oe, oh,
             r[k].iterations, r[k].residual);
    CHECK(r[k].theta >= THETA_LO && r[k].theta <= THETA_HI,
          "%s field, nu = %g, n = %d: effectivity %.4f outside [%g, %g] (eta %.4e, |e|_E %.4e)",
          fd->name, poisson, r[k].n, r[k].theta, THETA_LO, THETA_HI, r[k].eta, r[k].error);
    if (k > 0)
      CHECK(fabs(r[k].theta - 1.0) <= fabs(r[k - 1].theta - 1.0) + THETA_SLACK,
            "%s field, nu = %g: |theta - 1| grew from %.4f (n = %d) to %.4f (n = %d), slack %g",
            fd->name, poisson, fabs(r[k - 1].theta - 1.0), r[k - 1].n, fabs(r[k].theta - 1.0),
            r[k].n, THETA_SLACK);
  }
  const result *a = &r[count - 2], *b = &r[count - 1];
  double oe = log(a->error / b->error) / log((double)b->n / a->n);
  CHECK(oe >= ORDER_LO && oe <= ORDER_HI,
        "%s field, nu = %g: order of |e|_E between n = %d and %d is %.4f, expected 1 within "
        "[%g, %g]",
        fd->name, poisson, a->n, b->n, oe, ORDER_LO, ORDER_HI);
  CHECK(b->theta >= THETA_FINE_LO && b->theta <= THETA_FINE_HI,
        "%s field, nu = %g: effectivity on the finest mesh (n = %d) %.4f outside [%g, %g]",
        fd->name, poisson, b->n, b->theta, THETA_FINE_LO, THETA_FINE_HI);
}

int main(void) {
  sequence(&general, 0.3, 24);
  sequence(&general, 0.45, 16);
  sequence(&shear, 0.3, 24);
  TEST_END();
}
