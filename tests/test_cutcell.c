/* test_cutcell — the finite cell quadrature of cut cells (src/mesh/cutcell.c,
 * docs/theory.md §5b "Cut cells: the finite cell quadrature").
 *  1. Exactness: the Grundmann–Möller rule's weights sum to 1; a cell inside
 *     the tissue gives the box moments ∫ ξ^i η^j ζ^k = Π (1 − (−1)^(i+1))/(i+1)
 *     times det J; the parts of a cell cut by planes (a box x < x₀, a corner
 *     simplex, its complement) give their closed-form moments (Dirichlet
 *     integrals of the simplex); the 27 fitted weights of a full cell are
 *     the Gauss weights (5/9, 8/9, 5/9)³ det J, and on a cut cell they
 *     integrate every Q2 monomial to its moment (round-off); the moments of
 *     a cell equal the sum of its 8 children's (taken to the parent's
 *     coordinates) when the parent's lattice is the children's, with and
 *     without a sphere region and a half-space.
 *  2. A ball (centre off the lattice) and an ellipsoid on 8 grids, nested
 *     and not: volume, first and central second moments against their
 *     closed forms; the ball's volume lies below the exact one by at most
 *     4πR² · 3s²/(2(R − √3 s)) (F = |x − c| − R is convex, so its
 *     interpolant is above it, by at most 3s²/2 over the curvature radius on
 *     a tetrahedron of diameter √3 s); observed orders of all errors in
 *     [1.7, 2.5].
 *  3. The surface of the ball on every grid closes: Σ A n = 0 and
 *     Σ ∫ x × n dA = 0 to 1e-12 relative; the divergence theorem
 *     Σ ∫ x·n dA / 3 equals the volume of the same cells to 1e-12; its area
 *     converges to 4πR² with order in [1.7, 2.5].
 *  4. The analytic brain of cases/dbs/dbs.yaml: volume, mass and centre of
 *     mass against 10⁷ seeded pseudo-random points (standard errors
 *     computed), within 4 standard errors plus the discretisation error
 *     estimated by the next grid; nested self-convergence order; the brain's
 *     surface (with the grid's faces where the brainstem leaves it) closes.
 *  5. A ball as a label image (NIfTI written here, 0.5 mm voxels) and as an
 *     STL icosphere: volumes of their reconstructions against the ball's,
 *     within the bound of 2. plus the shape's own distance from the ball
 *     (the polyhedron's exact volume; a shell of half a voxel diagonal).
 *     The same ball stored flipped along i (negative x spacing, data
 *     reversed) is the same set: its level function agrees at every point
 *     of a cut lattice whose planes meet χ = 1/2 exactly (F = 0 at the same
 *     points, |ΔF| <= 1e-12 of the level scale), and every cell's tissue
 *     volume is zero in one iff in the other, else equal to 1e-12 of the cell.
 *  6. A sphere region of radius 0.5 mm in a 10 mm cell: its volume to 1 %.
 *  7. On a mesh with two levels (hex2 on half the cells), the slit error
 *     |Σ A n| / A with per-leaf lattices, and round-off with a lattice
 *     conforming across the levels.
 * NH_VERBOSE=1 prints the measured numbers and the cost per cut cell of the
 * brain on 20 x 24 x 16 cells. Silent on success. */
#include "check.h"
#include "hanging_mesh.h"
#include "mesh/mesh.h"

#include <stdint.h>
#include <string.h>
#include <time.h>

static int verbose;

/* ---- helpers ---- */

static int mono(int i, int j, int k) {
  return i + 3 * j + 9 * k;
}
static const int unit_index[3] = {1, 3, 9};

/* Physical moments: ∫ 1, ∫ x_k, ∫ x_k x_l. */
typedef struct {
  double v, x[3], xx[3][3];
} phys;

static void phys_add(phys *P, const double lo[3], const double hi[3], const double m[27]) {
  double c[3], h[3];
  for (int k = 0; k < 3; k++) c[k] = 0.5 * (lo[k] + hi[k]), h[k] = 0.5 * (hi[k] - lo[k]);
  P->v += m[0];
  for (int k = 0; k < 3; k++) P->x[k] += c[k] * m[0] + h[k] * m[unit_index[k]];
  for (int k = 0; k < 3; k++)
    for (int l = 0; l < 3; l++)
      P->xx[k][l] += c[k] * c[l] * m[0] + c[k] * h[l] * m[unit_index[l]] +
                     c[l] * h[k] * m[unit_index[k]] +
                     h[k] * h[l] * m[unit_index[k] + unit_index[l]];
}

/* ∫ (x − c)_k (x − c)_l. */
static double phys_central(const phys *P, const double c[3], int k, int l) {
  return P->xx[k][l] - c[k] * P->x[l] - c[l] * P->x[k] + c[k] * c[l] * P->v;
}

/* Cell (i, j, k) of the n-grid over [lo, hi]. */
static void grid_cell(const double lo[3], const double hi[3], const int n[3], const int ijk[3],
                      double a[3], double b[3]) {
  for (int k = 0; k < 3; k++) {
    a[k] = (lo[k] * (n[k] - ijk[k]) + hi[k] * ijk[k]) / n[k];
    b[k] = (lo[k] * (n[k] - ijk[k] - 1) + hi[k] * (ijk[k] + 1)) / n[k];
  }
}

/* Sums over a surface quadrature of a cell: Σ A n, Σ x × A n, Σ x · A n, Σ |A n|. */
typedef struct {
  double an[3], xan[3], xdotan, area;
} surf_sums;

static void surf_add(surf_sums *S, const nh_cut_surface *s, const double lo[3],
                     const double hi[3]) {
  for (int p = 0; p < s->n; p++) {
    const nh_cut_point *q = &s->point[p];
    double x[3];
    for (int k = 0; k < 3; k++) x[k] = 0.5 * (lo[k] + hi[k]) + 0.5 * (hi[k] - lo[k]) * q->xi[k];
    for (int k = 0; k < 3; k++) S->an[k] += q->area[k];
    S->xan[0] += x[1] * q->area[2] - x[2] * q->area[1];
    S->xan[1] += x[2] * q->area[0] - x[0] * q->area[2];
    S->xan[2] += x[0] * q->area[1] - x[1] * q->area[0];
    S->xdotan += nh_vec3_dot(x, q->area);
    S->area += sqrt(nh_vec3_dot(q->area, q->area));
  }
}

/* ---- level functions of the tests ---- */

typedef struct {
  double c[3], a[3];
} ellipsoid;

/* ρ (q − 1), q = |D⁻¹ (x − c)|, ρ = min a: convex and 1-Lipschitz. */
static double ellipsoid_level(const void *ctx, const double x[3]) {
  const ellipsoid *e = ctx;
  double q = 0.0;
  for (int k = 0; k < 3; k++) q += (x[k] - e->c[k]) * (x[k] - e->c[k]) / (e->a[k] * e->a[k]);
  return fmin(e->a[0], fmin(e->a[1], e->a[2])) * (sqrt(q) - 1.0);
}

static double everywhere(const void *ctx, const double x[3]) {
  (void)ctx, (void)x;
  return -1.0;
}

/* ---- 1. exactness ---- */

static double binom(int n, int k) {
  double r = 1.0;
  for (int i = 1; i <= k; i++) r = r * (n - k + i) / i;
  return r;
}
static double factorial(int n) {
  return n <= 1 ? 1.0 : n * factorial(n - 1);
}

/* ∫ ξ^i over [a, b]. */
static double power_integral(double a, double b, int i) {
  return (pow(b, i + 1) - pow(a, i + 1)) / (i + 1);
}

/* The moments of the natural box [a, b] (per axis) of a cell with det J = jac. */
static void box_moments(const double a[3], const double b[3], double jac, double m[27]) {
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 3; j++)
      for (int i = 0; i < 3; i++)
        m[mono(i, j, k)] = jac * power_integral(a[0], b[0], i) * power_integral(a[1], b[1], j) *
                           power_integral(a[2], b[2], k);
}

/* The moments of the corner simplex {u, v, w >= 0, u + v + w < L} of the
 * natural cube, u = ξ + 1 (det J = 1): binomial expansion of (u − 1)^i and
 * the Dirichlet integrals ∫ u^a v^b w^c = L^(a+b+c+3) a! b! c! / (a+b+c+3)!. */
static void simplex_moments(double L, double m[27]) {
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 3; j++)
      for (int i = 0; i < 3; i++) {
        double s = 0.0;
        for (int a = 0; a <= i; a++)
          for (int b = 0; b <= j; b++)
            for (int c = 0; c <= k; c++)
              s += binom(i, a) * binom(j, b) * binom(k, c) * pow(-1.0, i - a + j - b + k - c) *
                   pow(L, a + b + c + 3) * factorial(a) * factorial(b) * factorial(c) /
                   factorial(a + b + c + 3);
        m[mono(i, j, k)] = s;
      }
}

static void check_moments(const double got[27], const double want[27], double tol,
                          const char *what) {
  for (int q = 0; q < 27; q++)
    if (!(fabs(got[q] - want[q]) <= tol)) {
      fprintf(stderr, "%s: moment (%d, %d, %d): expected %.17g, got %.17g (tol %.3g)\n", what,
              q % 3, q / 3 % 3, q / 9, want[q], got[q], tol);
      nh_test_failures++;
    }
}

/* The children's moments taken to the parent's coordinates: ξ_p = (ξ_c + o)/2. */
static void child_to_parent(const double mc[27], const int o[3], double mp[27]) {
  double T[3][3][3]; /* T[axis][i][a]: coefficient of ξ_c^a in ξ_p^i */
  for (int ax = 0; ax < 3; ax++)
    for (int i = 0; i < 3; i++)
      for (int a = 0; a < 3; a++)
        T[ax][i][a] = a <= i ? binom(i, a) * pow(o[ax], i - a) / pow(2.0, i) : 0.0;
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 3; j++)
      for (int i = 0; i < 3; i++)
        for (int c = 0; c <= k; c++)
          for (int b = 0; b <= j; b++)
            for (int a = 0; a <= i; a++)
              mp[mono(i, j, k)] += T[0][i][a] * T[1][j][b] * T[2][k][c] * mc[mono(a, b, c)];
}

static void test_exactness(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {2, 2, 2}; /* ξ = x − 1, det J = 1 */
  const double ones[3] = {1, 1, 1};
  nh_cut_spec spec;
  nh_cut_moments out;
  double want[27];
  memset(&spec, 0, sizeof spec);
  spec.level = everywhere, spec.lipschitz = 1.0, spec.depth = 2;
  /* a cell inside: the box moments, and the fitted rule is Gauss's */
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  const double a[3] = {-1, -1, -1};
  box_moments(a, ones, 1.0, want);
  check_moments(out.m, want, 1e-15, "cell inside");
  double w[27], xi[81];
  nh_cut_fit(out.m, w);
  const double gw[3] = {5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0};
  for (int q = 0; q < 27; q++)
    CHECK_CLOSE(w[q], gw[q % 3] * gw[q / 3 % 3] * gw[q / 9], 1e-14, "fitted weight = Gauss weight");
  /* planes: a box x < 1.3, the corner simplex x + y + z < 1.3, its complement */
  double plane[6] = {1.3, 0, 0, 1, 0, 0};
  spec.plane = plane;
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  const double b[3] = {0.3, 1, 1};
  box_moments(a, b, 1.0, want);
  check_moments(out.m, want, 1e-13, "the part x < 1.3 (a plane through the tetrahedra)");
  for (int k = 0; k < 3; k++) plane[3 + k] = 1.0;
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  simplex_moments(1.3, want);
  check_moments(out.m, want, 1e-13, "corner simplex x + y + z < 1.3");
  for (int k = 0; k < 3; k++) plane[3 + k] = -1.0;
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  double box[27];
  box_moments(a, ones, 1.0, box);
  for (int q = 0; q < 27; q++) want[q] = box[q] - want[q];
  check_moments(out.m, want, 1e-13, "complement of the corner simplex");
  spec.plane = NULL;

  /* a cut cell: the fitted rule integrates every Q2 monomial */
  nh_domain ball;
  const double centre[3] = {0.0123, -0.0071, 0.0042};
  nh_domain_sphere(centre, 0.02, &ball);
  nh_cut_spec_domain(&spec, &ball, 3);
  const double clo[3] = {0.01, 0.005, -0.004}, chi[3] = {0.022, 0.017, 0.008};
  CHECK_OK(nh_cut_cell(&spec, clo, chi, &out, NULL, 0));
  CHECK(out.volume > 0.1 * 0.012 * 0.012 * 0.012 && out.volume < 0.9 * 0.012 * 0.012 * 0.012,
        "the cell is cut: volume %g", out.volume);
  nh_cut_fit(out.m, w);
  nh_cut_points(xi);
  double neg = 0.0;
  for (int q = 0; q < 27; q++) neg = fmin(neg, w[q]);
  for (int p = 0; p < 27; p++) {
    double s = 0.0;
    for (int q = 0; q < 27; q++)
      s += w[q] * pow(xi[3 * q], p % 3) * pow(xi[3 * q + 1], p / 3 % 3) * pow(xi[3 * q + 2], p / 9);
    CHECK_CLOSE(s, out.m[p], 1e-14 * out.volume, "fitted rule on a Q2 monomial");
  }
  if (verbose)
    printf("cut cell: volume fraction %.4f, smallest fitted weight %.3g of the volume\n",
           out.volume / (0.012 * 0.012 * 0.012), neg / out.volume);

  /* additivity: parent at depth 3 = its 8 children at depth 2, also with a
   * sphere region (its lattice follows the cell size) and a half-space */
  nh_region region;
  memset(&region, 0, sizeof region);
  region.kind = NH_REGION_SPHERE;
  region.radius = 0.004;
  const double rc[3] = {0.0171, 0.0093, 0.0021};
  memcpy(region.center, rc, sizeof rc);
  const double level[6] = {0.0, 0.0, 0.0047, 0.1, 0.2, 1.0};
  for (int variant = 0; variant < 4; variant++) {
    nh_cut_spec_domain(&spec, &ball, 3);
    if (variant == 1 || variant == 2) spec.region = &region;
    if (variant >= 2) spec.plane = level;
    nh_cut_moments parent;
    CHECK_OK(nh_cut_cell(&spec, clo, chi, &parent, NULL, 0));
    spec.depth = 2;
    double sum[27] = {0};
    for (int ch = 0; ch < 8; ch++) {
      double l[3], h[3];
      int o[3];
      for (int k = 0; k < 3; k++) {
        double mid = 0.5 * (clo[k] + chi[k]);
        o[k] = ch >> k & 1 ? 1 : -1;
        l[k] = o[k] > 0 ? mid : clo[k], h[k] = o[k] > 0 ? chi[k] : mid;
      }
      CHECK_OK(nh_cut_cell(&spec, l, h, &out, NULL, 0));
      child_to_parent(out.m, o, sum);
    }
    char what[64];
    snprintf(what, sizeof what, "parent = sum of children (variant %d)", variant);
    check_moments(sum, parent.m, (variant == 1 || variant == 2 ? 1e-11 : 1e-13) * parent.volume,
                  what);
    if (verbose)
      printf("additivity variant %d: volume %.10e, children %.10e\n", variant, parent.volume,
             sum[0]);
  }
}

/* ---- 2, 3. ball and ellipsoid: moments and surface on a sequence of grids ---- */

enum { N_GRIDS = 8 };
static const int grid_sizes[N_GRIDS] = {6, 8, 11, 12, 16, 23, 24, 32};

/* The moments and surface sums of {level < 0} over the n³ grid on [-L, L]³. */
static void grid_integrate(const nh_cut_spec *spec, int n, double L, phys *P, surf_sums *S) {
  const double lo[3] = {-L, -L, -L}, hi[3] = {L, L, L};
  const int g[3] = {n, n, n};
  nh_cut_surface surface = {0};
  memset(P, 0, sizeof *P);
  if (S) memset(S, 0, sizeof *S);
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        const int ijk[3] = {i, j, k};
        double a[3], b[3];
        nh_cut_moments out;
        grid_cell(lo, hi, g, ijk, a, b);
        surface.n = 0;
        CHECK_OK(nh_cut_cell(spec, a, b, &out, S ? &surface : NULL, 0));
        phys_add(P, a, b, out.m);
        if (S) surf_add(S, &surface, a, b);
      }
  nh_cut_surface_free(&surface);
}

static void test_quadrics(void) {
  const double L = 0.04, R = 0.03, c[3] = {0.00311, -0.00473, 0.00229};
  const double axes[3] = {0.034, 0.026, 0.019};
  const double V = 4.0 / 3.0 * M_PI * R * R * R;
  nh_domain ball;
  nh_domain_sphere(c, R, &ball);
  ellipsoid el = {{c[0], c[1], c[2]}, {axes[0], axes[1], axes[2]}};
  const double Ve = 4.0 / 3.0 * M_PI * axes[0] * axes[1] * axes[2];
  double h[N_GRIDS], err[2][6][N_GRIDS], area_err[N_GRIDS];
  const char *what[6] = {"volume",           "first moments",    "second moment xx",
                         "second moment yy", "second moment zz", "second moment xy"};
  for (int g = 0; g < N_GRIDS; g++) {
    const int n = grid_sizes[g];
    h[g] = 2 * L / n;
    const double s = h[g] / 4; /* sub-box edge at depth 2 */
    for (int shape = 0; shape < 2; shape++) {
      nh_cut_spec spec;
      nh_cut_spec_domain(&spec, &ball, 2);
      if (shape) spec.level = ellipsoid_level, spec.ctx = &el;
      phys P;
      surf_sums S;
      grid_integrate(&spec, n, L, &P, shape ? NULL : &S);
      const double vol = shape ? Ve : V;
      const double *ax = shape ? axes : (const double[3]){R, R, R};
      err[shape][0][g] = (P.v - vol) / vol;
      double e1 = 0.0;
      for (int k = 0; k < 3; k++) e1 = fmax(e1, fabs(P.x[k] - c[k] * P.v) / (vol * R));
      err[shape][1][g] = e1 + 1e-300;
      for (int k = 0; k < 3; k++)
        err[shape][2 + k][g] =
            (phys_central(&P, c, k, k) - vol * ax[k] * ax[k] / 5) / (vol * ax[k] * ax[k] / 5);
      err[shape][5][g] = phys_central(&P, c, 0, 1) / (vol * R * R / 5) + 1e-300;
      /* the ball's interpolant lies above F: the volume from below, by at most
       * 4πR² · 3s²/(2(R − √3 s)) */
      if (!shape)
        CHECK(P.v <= V && V - P.v <= 4 * M_PI * R * R * 1.5 * s * s / (R - sqrt(3) * s),
              "ball on %d^3: volume %.9e, expected in [V - bound, V], V = %.9e, bound %.3e", n, P.v,
              V, 4 * M_PI * R * R * 1.5 * s * s / (R - sqrt(3) * s));
      if (shape) CHECK(P.v <= Ve, "ellipsoid on %d^3: volume %.9e above %.9e", n, P.v, Ve);
      if (shape) continue;
      /* the surface closes, and encloses the same volume */
      const double A = S.area;
      CHECK(sqrt(nh_vec3_dot(S.an, S.an)) <= 1e-12 * A, "ball on %d^3: |sum A n| = %.3g, A = %.6g",
            n, sqrt(nh_vec3_dot(S.an, S.an)), A);
      CHECK(sqrt(nh_vec3_dot(S.xan, S.xan)) <= 1e-12 * A * (R + sqrt(nh_vec3_dot(c, c))),
            "ball on %d^3: |sum x x A n| = %.3g, A = %.6g", n, sqrt(nh_vec3_dot(S.xan, S.xan)), A);
      CHECK_CLOSE(S.xdotan / 3, P.v, 1e-12 * P.v, "divergence theorem: the surface's volume");
      area_err[g] = (A - 4 * M_PI * R * R) / (4 * M_PI * R * R);
      if (verbose)
        printf("ball %2d^3: dV/V %.3e  area %.3e  |sum An|/A %.1e  |sum x x An|/(A R) %.1e  "
               "div %.1e\n",
               n, err[0][0][g], area_err[g], sqrt(nh_vec3_dot(S.an, S.an)) / A,
               sqrt(nh_vec3_dot(S.xan, S.xan)) / (A * R), S.xdotan / 3 / P.v - 1);
    }
  }
  for (int shape = 0; shape < 2; shape++)
    for (int q = 0; q < 6; q++) {
      if (q == 1 || q == 5) continue; /* zero by symmetry up to the lattice: printed only */
      double p = nh_test_order(h, err[shape][q], N_GRIDS);
      CHECK(p >= 1.7 && p <= 2.5, "%s, %s: observed order %.3f, expected in [1.7, 2.5]",
            shape ? "ellipsoid" : "ball", what[q], p);
      if (verbose) {
        printf("%s %s: errors", shape ? "ellipsoid" : "ball", what[q]);
        for (int g = 0; g < N_GRIDS; g++) printf(" %.2e", err[shape][q][g]);
        printf("; order %.3f\n", p);
      }
    }
  for (int shape = 0; shape < 2 && verbose; shape++) {
    printf("%s first moments |∫x − cV|/(VR):", shape ? "ellipsoid" : "ball");
    for (int g = 0; g < N_GRIDS; g++) printf(" %.1e", err[shape][1][g]);
    printf("; xy: ");
    for (int g = 0; g < N_GRIDS; g++) printf(" %.1e", err[shape][5][g]);
    printf("\n");
  }
  for (int shape = 0; shape < 2; shape++)
    for (int g = 0; g < N_GRIDS; g++) {
      /* first moments and the product moment vanish by symmetry about c; the
       * lattice breaks it at the size of the volume error */
      CHECK(err[shape][1][g] <= 4 * fabs(err[shape][0][g]) + 1e-13 &&
                fabs(err[shape][5][g]) <= 4 * fabs(err[shape][0][g]) + 1e-13,
            "%s on %d^3: first moment %.3g, xy moment %.3g against a volume error %.3g",
            shape ? "ellipsoid" : "ball", grid_sizes[g], err[shape][1][g], err[shape][5][g],
            err[shape][0][g]);
    }
  double p = nh_test_order(h, area_err, N_GRIDS);
  CHECK(p >= 1.7 && p <= 2.5, "ball area: observed order %.3f, expected in [1.7, 2.5]", p);
  if (verbose) printf("ball area: order %.3f\n", p);
}

/* ---- 4. the analytic brain against Monte Carlo ---- */

/* Box of leaf c and its faces on the domain's box (the grid's boundary). */
static unsigned leaf_box(const nh_mesh *m, int c, double lo[3], double hi[3]) {
  double Xe[24];
  unsigned faces = 0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  for (int k = 0; k < 3; k++) {
    lo[k] = Xe[k], hi[k] = Xe[18 + k];
    if (lo[k] <= m->domain.min[k]) faces |= 1u << (2 * k);
    if (hi[k] >= m->domain.max[k]) faces |= 1u << (2 * k + 1);
  }
  return faces;
}

static void test_brain(void) {
  const double center[3] = {0, 0, 0}, size[3] = {0.14, 0.17, 0.13}, rho = 1040;
  nh_domain d;
  nh_domain_brain(center, size, &d);
  /* Monte Carlo: 10⁷ seeded points in the bounding box */
  const long N = 10000000;
  long in = 0;
  double sx[3] = {0}, sxx[3] = {0};
  nh_test_rng = 20250025ull;
  for (long i = 0; i < N; i++) {
    double x[3];
    for (int k = 0; k < 3; k++) x[k] = center[k] + 0.5 * size[k] * nh_rand();
    if (!(nh_domain_level(&d, x) < 0.0)) continue;
    in++;
    for (int k = 0; k < 3; k++) sx[k] += x[k], sxx[k] += x[k] * x[k];
  }
  const double Vbox = size[0] * size[1] * size[2], pin = (double)in / N;
  const double Vmc = Vbox * pin, se = Vbox * sqrt(pin * (1 - pin) / N);
  double com_mc[3], com_se[3];
  for (int k = 0; k < 3; k++) {
    com_mc[k] = sx[k] / in;
    com_se[k] = sqrt((sxx[k] / in - com_mc[k] * com_mc[k]) / in);
  }
  if (verbose)
    printf("brain Monte Carlo (1e7 points): V %.6e ± %.1e m³ (%.1e), mass %.5f ± %.5f kg, "
           "centre (%.2e ± %.1e, %.3e ± %.1e, %.4e ± %.1e) m\n",
           Vmc, se, se / Vmc, rho * Vmc, rho * se, com_mc[0], com_se[0], com_mc[1], com_se[1],
           com_mc[2], com_se[2]);
  /* the grids: nested 10x12x8 → 20x24x16 → 40x48x32, and neighbours of the sequence */
  enum { NB = 7 };
  const int grids[NB][3] = {{10, 12, 8},  {12, 14, 11}, {14, 17, 13}, {16, 19, 15},
                            {17, 21, 16}, {20, 24, 16}, {40, 48, 32}};
  double V[NB], com[NB][3], h[NB];
  for (int g = 0; g < NB; g++) {
    nh_mesh *m;
    CHECK_OK(nh_mesh_create(&d, grids[g], &m));
    nh_cut_spec spec;
    nh_cut_spec_domain(&spec, &d, 2);
    nh_cut_surface surface = {0};
    phys P;
    surf_sums S;
    memset(&P, 0, sizeof P), memset(&S, 0, sizeof S);
    double t_cut = 0.0;
    long n_cut = 0, evals = 0, boxes = 0, tets = 0, kuhn = 0;
    for (int l = 0; l < m->n_leaves; l++) {
      double lo[3], hi[3];
      unsigned faces = leaf_box(m, m->leaves[l], lo, hi);
      nh_cut_moments out;
      surface.n = 0;
      const clock_t t0 = clock(); /* CPU time: the machine is shared */
      CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, &surface, faces));
      const double dt = (double)(clock() - t0) / CLOCKS_PER_SEC;
      const double full = (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]);
      if (out.volume > 0.0 && out.volume < full * (1 - 1e-12))
        n_cut++, t_cut += dt, evals += out.evals, boxes += out.boxes, tets += out.tets,
            kuhn += out.kuhn;
      phys_add(&P, lo, hi, out.m);
      surf_add(&S, &surface, lo, hi);
    }
    nh_cut_surface_free(&surface);
    V[g] = P.v;
    for (int k = 0; k < 3; k++) com[g][k] = P.x[k] / P.v;
    h[g] = size[0] / grids[g][0];
    CHECK(sqrt(nh_vec3_dot(S.an, S.an)) <= 1e-12 * S.area, "brain %dx%dx%d: |sum A n| / A = %.3g",
          grids[g][0], grids[g][1], grids[g][2], sqrt(nh_vec3_dot(S.an, S.an)) / S.area);
    CHECK_CLOSE(S.xdotan / 3, P.v, 1e-11 * P.v, "brain: divergence theorem");
    if (verbose)
      printf("brain %dx%dx%d: V %.7e (%+.2e of MC, %+.1f se), centre (%+.2e, %.8e, %.8e); "
             "|sum An|/A %.1e, div %.1e; %ld cut cells: %.1f us CPU, %.0f level evaluations, %.0f "
             "sub-boxes, %.0f + %.0f tetrahedra (quadrature + closed form) each, %.3f s in all\n",
             grids[g][0], grids[g][1], grids[g][2], P.v, P.v / Vmc - 1, (P.v - Vmc) / se, com[g][0],
             com[g][1], com[g][2], sqrt(nh_vec3_dot(S.an, S.an)) / S.area, S.xdotan / 3 / P.v - 1,
             n_cut, 1e6 * t_cut / n_cut, (double)evals / n_cut, (double)boxes / n_cut,
             (double)tets / n_cut, (double)kuhn / n_cut, t_cut);
    nh_mesh_destroy(&m);
  }
  /* nested self-convergence and the extrapolated volume */
  const double p = log2((V[5] - V[0]) / (V[6] - V[5]));
  const double Vinf = V[6] + (V[6] - V[5]) / (pow(2.0, p) - 1);
  CHECK(p >= 1.7 && p <= 2.5, "brain: nested order %.3f, expected in [1.7, 2.5]", p);
  double err[NB];
  for (int g = 0; g < NB; g++) err[g] = V[g] - Vinf;
  const double q = nh_test_order(h, err, NB);
  CHECK(q >= 1.7 && q <= 2.5, "brain: order over the 7 grids %.3f, expected in [1.7, 2.5]", q);
  for (int g = 1; g < NB; g++)
    CHECK(fabs(err[g]) < fabs(err[g - 1]), "brain: error %.3g on grid %d not below %.3g", err[g], g,
          err[g - 1]);
  /* against Monte Carlo: 4 standard errors plus the finest grid's own error,
   * bounded by its distance from the extrapolation (twice) */
  const double own = 2 * fabs(V[6] - Vinf);
  CHECK(fabs(V[6] - Vmc) <= 4 * se + own, "brain volume %.7e vs Monte Carlo %.7e ± %.1e", V[6], Vmc,
        se);
  CHECK(fabs(Vinf - Vmc) <= 4 * se, "extrapolated brain volume %.7e vs Monte Carlo %.7e ± %.1e",
        Vinf, Vmc, se);
  for (int k = 0; k < 3; k++) {
    const double own_c = 2 * fabs(com[6][k] - com[5][k]);
    CHECK(fabs(com[6][k] - com_mc[k]) <= 4 * com_se[k] + own_c,
          "brain centre of mass %d: %.5e vs Monte Carlo %.5e ± %.1e", k, com[6][k], com_mc[k],
          com_se[k]);
  }
  /* the centre of mass: z (the axis the brain is not symmetric in; y's offset
   * is 0.27 mm and moves by 0.2 um over the grids, at the reconstruction's
   * noise) converges like the moments it divides, O(h^2): its first moment
   * has nested order 2.5, the quotient's leading errors partly cancel and
   * leave a pre-asymptotic 1.65 over these grids. Asserted: errors against
   * the nested extrapolation fall on every grid, order >= 1.5 over the seven,
   * and the extrapolated centre agrees with Monte Carlo. */
  {
    const double pz = log2((com[5][2] - com[0][2]) / (com[6][2] - com[5][2]));
    const double zinf = com[6][2] + (com[6][2] - com[5][2]) / (pow(2.0, pz) - 1);
    double ez[NB];
    for (int g = 0; g < NB; g++) ez[g] = com[g][2] - zinf;
    const double qz = nh_test_order(h, ez, NB);
    CHECK(qz >= 1.5 && qz <= 2.5,
          "brain centre z: order over the 7 grids %.3f, expected in [1.5, 2.5]", qz);
    for (int g = 1; g < NB; g++)
      CHECK(fabs(ez[g]) < fabs(ez[g - 1]), "brain centre z: error %.3g on grid %d not below %.3g",
            ez[g], g, ez[g - 1]);
    CHECK(fabs(zinf - com_mc[2]) <= 4 * com_se[2],
          "extrapolated brain centre z %.6e vs Monte Carlo %.6e ± %.1e", zinf, com_mc[2],
          com_se[2]);
    if (verbose)
      printf("brain centre z: nested order %.3f, order over 7 grids %.3f, extrapolated %.6e m "
             "(%+.1f se of MC), error on 10x12x8 %.2e m, on 40x48x32 %.2e m\n",
             pz, qz, zinf, (zinf - com_mc[2]) / com_se[2], ez[0], ez[NB - 1]);
  }
  /* x: the brain is mirror symmetric about x = 0, the Kuhn split is not: the
   * centre's x is zero up to the reconstruction's error */
  CHECK(fabs(com[6][0]) <= fabs(V[6] - Vinf) / V[6] * size[0],
        "brain centre x %.3g, expected 0 up to the volume error times the width", com[6][0]);
  if (verbose)
    printf("brain: nested order %.3f, order over 7 grids %.3f, extrapolated V %.7e m³ "
           "(%+.1f se of MC), mass %.5f kg\n",
           p, q, Vinf, (Vinf - Vmc) / se, rho * Vinf);
}

/* ---- 5. a ball as a label image and as an STL surface ---- */

/* NIfTI-1 (uint8, 0.5 mm voxels in mm, sform) of the ball: label 1 where the
 * voxel's centre lies inside. */
static int write_ball_nifti_as(const char *path, const double c[3], double R, double vox, int n,
                               const double origin[3], int flip) {
  unsigned char h[352];
  memset(h, 0, sizeof h);
  const int32_t size = 348;
  const int16_t dim[8] = {3, (int16_t)n, (int16_t)n, (int16_t)n, 1, 1, 1, 1};
  const int16_t datatype = 2, bitpix = 8, qform = 0, sform = 1;
  const float mm = (float)(vox * 1e3), pixdim[8] = {1, mm, mm, mm, 1, 1, 1, 1}, offset = 352;
  /* flip: i runs towards −x from the last centre (data reversed along i) */
  const float sx = flip ? -mm : mm, x0 = (float)((origin[0] + (flip ? (n - 1) * vox : 0.0)) * 1e3);
  const float srow[12] = {
      sx, 0, 0, x0, 0, mm, 0, (float)(origin[1] * 1e3), 0, 0, mm, (float)(origin[2] * 1e3)};
  memcpy(h, &size, 4), memcpy(h + 40, dim, 16), memcpy(h + 70, &datatype, 2);
  memcpy(h + 72, &bitpix, 2), memcpy(h + 76, pixdim, 32), memcpy(h + 108, &offset, 4);
  h[123] = 2; /* millimetres */
  memcpy(h + 252, &qform, 2), memcpy(h + 254, &sform, 2), memcpy(h + 280, srow, 48);
  memcpy(h + 344, "n+1", 4);
  FILE *f = fopen(path, "wb");
  if (!f) return 1;
  fwrite(h, 1, sizeof h, f);
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        /* the voxel centre as the reader maps it: float sform entries */
        const double x[3] = {(srow[3] + sx * i) * 1e-3, (srow[7] + mm * j) * 1e-3,
                             (srow[11] + mm * k) * 1e-3};
        unsigned char v = (x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) +
                              (x[2] - c[2]) * (x[2] - c[2]) <
                          R * R;
        fwrite(&v, 1, 1, f);
      }
  return fclose(f) != 0;
}

static int write_ball_nifti(const char *path, const double c[3], double R, double vox, int n,
                            const double origin[3]) {
  return write_ball_nifti_as(path, c, R, vox, n, origin, 0);
}

/* Binary STL (mm) of the icosahedron subdivided `level` times, vertices on the ball. */
static int write_icosphere(const char *path, const double c[3], double R, int level) {
  const double t = (1 + sqrt(5.0)) / 2;
  const double V0[12][3] = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                            {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                            {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  const int F0[20][3] = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                         {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                         {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                         {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  int nt = 20;
  for (int l = 0; l < level; l++) nt *= 4;
  double *T = malloc(sizeof(double) * 9 * nt), *U = malloc(sizeof(double) * 9 * nt);
  for (int f = 0; f < 20; f++)
    for (int v = 0; v < 3; v++) {
      const double *p = V0[F0[f][v]], n = sqrt(nh_vec3_dot(p, p));
      for (int k = 0; k < 3; k++) T[9 * f + 3 * v + k] = p[k] / n;
    }
  for (int l = 0, cur = 20; l < level; l++, cur *= 4) {
    for (int f = 0; f < cur; f++) {
      double m[3][3], q[6][3]; /* corners 0-2, midpoints of edges 01, 12, 20 */
      for (int e = 0; e < 3; e++) {
        const double *a = T + 9 * f + 3 * e, *b = T + 9 * f + 3 * ((e + 1) % 3);
        for (int k = 0; k < 3; k++) m[e][k] = a[k] + b[k];
        const double n = sqrt(nh_vec3_dot(m[e], m[e]));
        for (int k = 0; k < 3; k++) m[e][k] /= n, q[e][k] = a[k], q[3 + e][k] = m[e][k];
      }
      const int sub[4][3] = {{0, 3, 5}, {3, 1, 4}, {5, 4, 2}, {3, 4, 5}};
      for (int s = 0; s < 4; s++)
        for (int v = 0; v < 3; v++)
          for (int k = 0; k < 3; k++) U[9 * (4 * f + s) + 3 * v + k] = q[sub[s][v]][k];
    }
    double *swap = T;
    T = U, U = swap;
  }
  FILE *fp = fopen(path, "wb");
  if (!fp) return 1;
  unsigned char header[80] = "icosphere (test_cutcell)";
  const uint32_t count = (uint32_t)nt;
  fwrite(header, 1, 80, fp), fwrite(&count, 4, 1, fp);
  for (int f = 0; f < nt; f++) {
    float rec[12] = {0};
    const uint16_t attr = 0;
    for (int v = 0; v < 3; v++)
      for (int k = 0; k < 3; k++)
        rec[3 + 3 * v + k] = (float)((c[k] + R * T[9 * f + 3 * v + k]) * 1e3);
    fwrite(rec, 4, 12, fp), fwrite(&attr, 2, 1, fp);
  }
  free(T), free(U);
  return fclose(fp) != 0;
}

static void set_box(nh_domain *d, const double min[3], const double max[3]) {
  for (int k = 0; k < 3; k++) {
    d->min[k] = min[k], d->max[k] = max[k];
    d->center[k] = 0.5 * (min[k] + max[k]), d->half[k] = 0.5 * (max[k] - min[k]);
  }
}

static void test_image_and_surface(const char *dir) {
  const double c[3] = {0.00311, -0.00473, 0.00229}, R = 0.02, L = 0.03, vox = 0.0005;
  const double origin[3] = {-0.021, -0.0285, -0.0215}, V = 4.0 / 3.0 * M_PI * R * R * R;
  char nii[1024], stl[1024];
  snprintf(nii, sizeof nii, "%s/cutcell_ball.nii", dir);
  snprintf(stl, sizeof stl, "%s/cutcell_ball.stl", dir);
  CHECK(write_ball_nifti(nii, c, R, vox, 96, origin) == 0, "cannot write %s", nii);
  CHECK(write_icosphere(stl, c, R, 5) == 0, "cannot write %s", stl);
  nh_domain mask, surf, ball;
  memset(&mask, 0, sizeof mask), memset(&surf, 0, sizeof surf);
  mask.kind = NH_DOMAIN_MASK, surf.kind = NH_DOMAIN_SURFACE;
  CHECK_OK(nh_image_read(nii, 1, NULL, &mask.image));
  const int label = 1;
  CHECK_OK(nh_image_select(mask.image, &label, 1));
  set_box(&mask, mask.image->box_min, mask.image->box_max);
  CHECK_OK(nh_surface_read(stl, 1e-3, 0, NULL, &surf.surface));
  set_box(&surf, surf.surface->min, surf.surface->max);
  surf.cap = 0.25 * R;
  nh_domain_sphere(c, R, &ball);
  /* the shapes' own volumes: the polyhedron's exactly; the mask's {χ > 1/2}
   * by 4³ samples per voxel (nh_domain_volume) */
  const double Vpoly = nh_surface_volume(surf.surface), Vmask = nh_domain_volume(&mask);
  enum { NS = 5 };
  double h[NS], e_mask[NS], e_stl[NS];
  for (int g = 0; g < NS; g++) {
    const int n = grid_sizes[g];
    const double s = 2 * L / n / 4;
    const double bound = 4 * M_PI * R * R * 1.5 * s * s / (R - sqrt(3) * s);
    nh_cut_spec spec;
    phys Pb, Pm, Ps;
    nh_cut_spec_domain(&spec, &ball, 2);
    grid_integrate(&spec, n, L, &Pb, NULL);
    nh_cut_spec_domain(&spec, &mask, 2);
    grid_integrate(&spec, n, L, &Pm, NULL);
    nh_cut_spec_domain(&spec, &surf, 2);
    grid_integrate(&spec, n, L, &Ps, NULL);
    h[g] = 2 * L / n, e_mask[g] = Pm.v - Vmask, e_stl[g] = Ps.v - Vpoly;
    /* the polyhedron is convex, so its signed distance is: its interpolant is
     * above it, the volume below the polyhedron's */
    CHECK(Ps.v <= Vpoly && Vpoly - Ps.v <= bound,
          "STL ball on %d^3: volume %.7e, expected in [V_poly - %.2e, V_poly = %.7e]", n, Ps.v,
          bound, Vpoly);
    CHECK(fabs(Pm.v - Vmask) <= bound, "mask ball on %d^3: volume %.7e, expected %.7e ± %.2e", n,
          Pm.v, Vmask, bound);
    if (verbose)
      printf("%2d^3 (s %.2f mm): ball %+.3e, mask %+.3e (vs its own %+.3e), STL %+.3e (vs the "
             "polyhedron %+.3e) of 4/3 pi R^3; bound %.2e\n",
             n, 1e3 * s, Pb.v / V - 1, Pm.v / V - 1, Pm.v / Vmask - 1, Ps.v / V - 1,
             Ps.v / Vpoly - 1, bound / V);
  }
  const double pm = nh_test_order(h, e_mask, NS), ps = nh_test_order(h, e_stl, NS);
  CHECK(ps >= 1.7 && ps <= 2.5, "STL ball: observed order %.3f, expected in [1.7, 2.5]", ps);
  CHECK(pm >= 1.5 && pm <= 3.0, "mask ball: observed order %.3f, expected in [1.5, 3]", pm);
  if (verbose)
    printf("mask: {chi > 1/2} %+.2e of the ball; order %.3f. STL: polyhedron %+.2e of the ball "
           "(%d triangles); order %.3f\n",
           Vmask / V - 1, pm, Vpoly / V - 1, surf.surface->n_tri, ps);
  nh_domain_release(&mask), nh_domain_release(&surf);
  remove(nii), remove(stl);
}

/* 5b. The same ball mask stored flipped along i (negative x spacing, data
 * reversed: the same set in world coordinates, as tests/anatomy.py's): with
 * voxel faces on the cut lattice's planes (origin −29.75 mm, 0.5 mm voxels,
 * cells of 7.5 mm over [−30, 30]³, sub-boxes of 1.875 mm) many lattice
 * points lie midway between an inside and an outside centre, where
 * χ = 1/2 exactly. Expected: the level function agrees at every lattice
 * point of depth 2 (F = 0 at exactly the same points, the same sign
 * elsewhere, |ΔF| ≤ 1e-12 of the level scale), and every cell's tissue
 * volume is zero in one iff in the other, and equal to 1e-12 of the cell
 * (the flip changes only the rounding of the voxel coordinates). */
static void test_image_flip(const char *dir) {
  const double c[3] = {0.00311, -0.00473, 0.00229}, R = 0.02, L = 0.03, vox = 0.0005;
  const double origin[3] = {-0.02975, -0.02975, -0.02975};
  char nii[2][1024];
  nh_domain mask[2];
  for (int f = 0; f < 2; f++) {
    snprintf(nii[f], sizeof nii[f], "%s/cutcell_flip%d.nii", dir, f);
    CHECK(write_ball_nifti_as(nii[f], c, R, vox, 120, origin, f) == 0, "cannot write %s", nii[f]);
    memset(&mask[f], 0, sizeof mask[f]);
    mask[f].kind = NH_DOMAIN_MASK;
    CHECK_OK(nh_image_read(nii[f], 1, NULL, &mask[f].image));
    const int label = 1;
    CHECK_OK(nh_image_select(mask[f].image, &label, 1));
    /* one box for both: the cut lattice's mirror point is its centre */
    set_box(&mask[f], mask[0].image->box_min, mask[0].image->box_max);
  }
  const int n = 8, N = 4 * n;
  int zeros = 0, rounded = 0, bad_level = 0, bad_cell = 0, empty = 0;
  for (int k = 0; k <= N; k++)
    for (int j = 0; j <= N; j++)
      for (int i = 0; i <= N; i++) {
        const double x[3] = {-L + 2 * L * i / N, -L + 2 * L * j / N, -L + 2 * L * k / N};
        const double F0 = nh_domain_level(&mask[0], x), F1 = nh_domain_level(&mask[1], x);
        zeros += F0 == 0.0;
        for (int f = 0; f < 2; f++)
          rounded += (f ? F1 : F0) == 0.0 && nh_image_indicator(mask[f].image, x) != 0.5;
        if ((F0 == 0.0) != (F1 == 0.0) || (F0 < 0.0) != (F1 < 0.0) ||
            fabs(F0 - F1) > 1e-12 * mask[0].image->level_scale) {
          if (bad_level++ < 3)
            fprintf(stderr, "flipped mask: F at (%g, %g, %g) mm: %.17g vs %.17g\n", 1e3 * x[0],
                    1e3 * x[1], 1e3 * x[2], F0, F1);
        }
      }
  CHECK(bad_level == 0, "flipped mask: the level function differs at %d lattice points", bad_level);
  CHECK(zeros > 0, "the lattice meets no point with chi = 1/2: the test does not test");
  const double lo[3] = {-L, -L, -L}, hi[3] = {L, L, L};
  const int g[3] = {n, n, n};
  nh_cut_spec spec[2];
  for (int f = 0; f < 2; f++) nh_cut_spec_domain(&spec[f], &mask[f], 2);
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        const int ijk[3] = {i, j, k};
        double a[3], b[3];
        nh_cut_moments out[2];
        grid_cell(lo, hi, g, ijk, a, b);
        for (int f = 0; f < 2; f++) CHECK_OK(nh_cut_cell(&spec[f], a, b, &out[f], NULL, 0));
        const double Vc = (b[0] - a[0]) * (b[1] - a[1]) * (b[2] - a[2]);
        empty += out[0].volume == 0.0;
        if ((out[0].volume == 0.0) != (out[1].volume == 0.0) ||
            fabs(out[0].volume - out[1].volume) > 1e-12 * Vc) {
          if (bad_cell++ < 3)
            fprintf(stderr, "flipped mask: cell (%d, %d, %d) tissue %.17g vs %.17g m^3\n", i, j, k,
                    out[0].volume, out[1].volume);
        }
      }
  CHECK(bad_cell == 0, "flipped mask: the tissue volume differs in %d cells", bad_cell);
  if (verbose)
    printf("flipped mask: %d lattice points with chi = 1/2 (%d of the raw values off 1/2 by "
           "round-off), %d empty cells; level and volumes agree\n",
           zeros, rounded, empty);
  for (int f = 0; f < 2; f++) nh_domain_release(&mask[f]), remove(nii[f]);
}

/* ---- 6. regions smaller than a cell ---- */

static void test_small_regions(void) {
  nh_cut_spec spec;
  memset(&spec, 0, sizeof spec);
  spec.level = everywhere, spec.lipschitz = 1.0, spec.depth = 2;
  const double lo[3] = {0, 0, 0}, hi[3] = {0.01, 0.01, 0.01};
  nh_region r;
  memset(&r, 0, sizeof r);
  nh_cut_moments out;
  /* a ball of radius 0.5 mm, 1/20 of the cell, off-centre */
  r.kind = NH_REGION_SPHERE, r.radius = 0.0005;
  const double rc[3] = {0.00431, 0.00517, 0.00593};
  memcpy(r.center, rc, sizeof rc);
  spec.region = &r;
  double t0 = nh_time_now();
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  double t1 = nh_time_now();
  const double Vs = 4.0 / 3.0 * M_PI * pow(r.radius, 3);
  double s = 0.01; /* the region's sub-box: <= radius / 8 */
  while (s > r.radius / 8) s /= 2;
  const double bound = 4 * M_PI * r.radius * r.radius * 1.5 * s * s / (r.radius - sqrt(3) * s);
  CHECK(out.volume <= Vs && Vs - out.volume <= fmin(bound, 0.01 * Vs),
        "0.5 mm ball in a 10 mm cell: %.6e, expected %.6e - [0, min(%.2e, 1 %%)]", out.volume, Vs,
        bound);
  for (int k = 0; k < 3; k++)
    CHECK_CLOSE(out.centroid[k], rc[k], 1e-3 * r.radius, "small ball's centroid");
  if (verbose)
    printf("0.5 mm ball region in a 10 mm cell: volume %+.2e (bound %.2e), sub-box %.1f um, "
           "%ld tetrahedra, %.1f ms\n",
           out.volume / Vs - 1, bound / Vs, 1e6 * s, out.tets, 1e3 * (t1 - t0));
  /* a thin cylinder (radius 0.3 mm, 5 mm long, oblique) */
  r.kind = NH_REGION_CYLINDER, r.radius = 0.0003;
  const double a[3] = {0.0031, 0.0042, 0.0027}, b[3] = {0.0061, 0.0071, 0.0053};
  memcpy(r.start, a, sizeof a), memcpy(r.end, b, sizeof b);
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  const double len = sqrt((b[0] - a[0]) * (b[0] - a[0]) + (b[1] - a[1]) * (b[1] - a[1]) +
                          (b[2] - a[2]) * (b[2] - a[2]));
  const double Vc = M_PI * r.radius * r.radius * len;
  s = 0.01;
  while (s > r.radius / 8) s /= 2;
  const double bc = 2 * M_PI * r.radius * len * 1.5 * s * s / (r.radius - sqrt(3) * s);
  CHECK(out.volume <= Vc * (1 + 1e-12) && Vc - out.volume <= bc,
        "thin cylinder: %.6e, expected %.6e - [0, %.2e]", out.volume, Vc, bc);
  if (verbose)
    printf("thin cylinder region: volume %+.2e (bound %.2e)\n", out.volume / Vc - 1, bc / Vc);
  /* a box region of 0.4 mm: planes, exact */
  r.kind = NH_REGION_BOX;
  const double bl[3] = {0.0041, 0.0052, 0.0063}, bh[3] = {0.0045, 0.0056, 0.0067};
  memcpy(r.min, bl, sizeof bl), memcpy(r.max, bh, sizeof bh);
  CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, NULL, 0));
  CHECK_CLOSE(out.volume, 0.0004 * 0.0004 * 0.0004, 1e-12 * 0.0004 * 0.0004 * 0.0004,
              "0.4 mm box region: exact");
}

/* ---- 7. two refinement levels: slits of per-leaf lattices ---- */

static void test_levels(void) {
  const double c[3] = {0.00311, -0.00473, 0.00229}, R = 0.02;
  nh_domain ball;
  nh_domain_sphere(c, R, &ball);
  const int grid[3] = {8, 8, 8};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&ball, grid, &m));
  nh_template *t = regular_template(2);
  int *sel = malloc(sizeof(int) * m->n_leaves), n_sel = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    double lo[3], hi[3];
    leaf_box(m, m->leaves[l], lo, hi);
    if (0.5 * (lo[0] + hi[0]) < c[0]) sel[n_sel++] = m->leaves[l];
  }
  CHECK_OK(nh_mesh_refine(m, t, sel, n_sel, NULL));
  for (int conform = 0; conform < 2; conform++) {
    nh_cut_surface surface = {0};
    surf_sums S;
    memset(&S, 0, sizeof S);
    double V = 0.0, t0 = nh_time_now();
    for (int l = 0; l < m->n_leaves; l++) {
      const int cell = m->leaves[l];
      double lo[3], hi[3];
      leaf_box(m, cell, lo, hi);
      nh_cut_spec spec;
      nh_cut_spec_domain(&spec, &ball, conform ? 3 - m->level[cell] : 2);
      nh_cut_moments out;
      surface.n = 0;
      CHECK_OK(nh_cut_cell(&spec, lo, hi, &out, &surface, 0));
      V += out.volume;
      surf_add(&S, &surface, lo, hi);
    }
    const double slit = sqrt(nh_vec3_dot(S.an, S.an)) / S.area;
    if (conform)
      CHECK(slit <= 1e-12, "conforming lattice across two levels: |sum A n| / A = %.3g", slit);
    else
      CHECK(slit > 1e-9, "per-leaf lattices across two levels should leave slits: %.3g", slit);
    if (verbose)
      printf("two levels (8^3, hex2 on x < c): %s: |sum A n|/A %.2e, volume %+.3e, %.3f s\n",
             conform ? "lattice conforming (depth 3 / 2)" : "per-leaf lattice (depth 2 / 2)", slit,
             V / (4.0 / 3.0 * M_PI * R * R * R) - 1, nh_time_now() - t0);
    nh_cut_surface_free(&surface);
  }
  free(sel);
  nh_template_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(int argc, char **argv) {
  verbose = getenv("NH_VERBOSE") != NULL;
  test_exactness();
  test_quadrics();
  test_brain();
  test_image_and_surface(argc > 1 ? argv[1] : ".");
  test_image_flip(argc > 1 ? argv[1] : ".");
  test_small_regions();
  test_levels();
  TEST_END();
}
