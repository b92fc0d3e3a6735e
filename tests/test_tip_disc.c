/* test_tip_disc — the tip disc (contact/points.c, nh_disc_build;
 * docs/interaction.md, "Tip disc"): a tool's tip and puncture rows act on the
 * tissue through the mean over the tool's cross-section, so the tissue's
 * compliance at the tip converges under refinement, where a point's
 * diverges.
 *
 * The block [0, 20] x [0, 40] x [0, 40] mm (E 10 kPa, ν 0.3, full
 * integration, linear: the rest tangent), fixed on its back face x = 20 mm,
 * pushed into its front face x = 0 at (0, 20, 20) mm by a unit force along
 * +x, either at that point (rho = 0) or spread over the disc of radius
 * a = 4 mm on the face (rho = a). The compliance c = (mean displacement
 * of the loaded set along x) / force is measured on the grids 2 x 4 x 4,
 * 4 x 8 x 8 and 8 x 16 x 16 (h = 10, 5, 2.5 mm; the load point is a node
 * of each).
 *
 *  1. Disc weights: Σ w = 1 and Σ w X = the disc's centre (1e-12), the
 *     weights reproduce the mean of a linear field over the disc.
 *  2. A point load diverges: in 3-D the displacement under a point force
 *     grows like 1/r (Boussinesq: u = (1 − ν²) F / (π E r)), and a nodal
 *     load sees r ~ h, so c(h/2) / c(h) -> 2: asserted in [1.6, 2.4] for
 *     both halvings.
 *  3. The disc converges: its compliance tends to the mean displacement of
 *     a uniformly loaded disc; the successive changes shrink by at least a
 *     factor 2 (first order or better: the load's edge is a discontinuity),
 *     and the finest lies between 0.6 and 1.05 of the half-space's
 *     16 (1 − ν²) / (3 π² E a) (Timoshenko & Goodier, Theory of Elasticity,
 *     §138: the mean deflection under a uniform circular load; the block is
 *     only 5 a deep and clamped behind, so stiffer than the half-space, by
 *     the Boussinesq displacement at that depth, about a third).
 * NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "contact/contact_impl.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#define E_T   1.0e4
#define NU    0.3
#define A_R   0.004
#define NGRID 3

/* The compliance of the disc of radius rho at (0, 20, 20) mm on grid k. */
static double compliance(int k, double rho, int weights_check) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.02, 0.04, 0.04};
  const int grid[3] = {4 * k, 8 * k, 8 * k};
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  nh_system *s = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {E_T, NU, 1000, NH_FORMULATION_FULL};
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  const int n = 3 * m->n_nodes;
  unsigned char *fixed = calloc((size_t)m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i] > 0.0199;
  CHECK_OK(nh_system_create(t, fixed, NULL, &s));
  double *zero = calloc((size_t)n, sizeof(double)), *f = calloc((size_t)n, sizeof(double));
  double *u = calloc((size_t)n, sizeof(double));
  const int nf = nh_system_free_dofs(s);
  double *b = calloc((size_t)nf, sizeof(double)), *x = calloc((size_t)nf, sizeof(double));
  nh_system_assemble(s, zero, NULL, 0.0, 1.0, zero, NULL, 1);
  CHECK_OK(nh_system_factor(s));

  nh_cpoint p = {0};
  const double X0[3] = {0.0, 0.02, 0.02}, nrm[3] = {-1, 0, 0};
  CHECK_OK(nh_point_set(m, &p, X0));
  nh_disc d = {0};
  CHECK_OK(nh_disc_build(&d, m, &p, nrm, NULL, rho));
  if (weights_check) { /* 1: a partition of unity centred at X0, exact for linear fields */
    double sw = 0.0, sx[3] = {0, 0, 0}, lin = 0.0;
    for (int q = 0; q < d.n; q++) {
      const double *Xq = m->X + 3 * d.node[q];
      sw += d.w[q];
      for (int i = 0; i < 3; i++) sx[i] += d.w[q] * Xq[i];
      lin += d.w[q] * (1.0 + 2.0 * Xq[0] - 3.0 * Xq[1] + 5.0 * Xq[2]);
    }
    CHECK_CLOSE(sw, 1.0, 1e-12, "disc weights: sum");
    for (int i = 0; i < 3; i++) CHECK_CLOSE(sx[i], X0[i], 1e-12 * 0.04, "disc weights: centre");
    CHECK_CLOSE(lin, 1.0 + 2.0 * X0[0] - 3.0 * X0[1] + 5.0 * X0[2], 1e-12, "disc: linear field");
  }
  for (int q = 0; q < d.n; q++) f[3 * d.node[q]] += d.w[q]; /* unit force along +x */
  nh_system_gather(s, f, b);
  CHECK_OK(nh_system_solve(s, b, x));
  nh_system_scatter(s, x, u);
  double c = 0.0;
  for (int q = 0; q < d.n; q++) c += d.w[q] * u[3 * d.node[q]];
  nh_disc_free(&d);
  free(zero), free(f), free(u), free(b), free(x), free(fixed);
  nh_system_destroy(&s);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  return c;
}

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  double cp[NGRID], cd[NGRID];
  for (int g = 0; g < NGRID; g++) {
    cp[g] = compliance(1 << g, 0.0, 0);
    cd[g] = compliance(1 << g, A_R, 1);
    if (verbose)
      printf("h = %.4g mm: point %.6g m/N, disc %.6g m/N\n", 10.0 / (1 << g), cp[g], cd[g]);
  }
  for (int g = 1; g < NGRID; g++) /* 2 */
    CHECK(cp[g] / cp[g - 1] >= 1.6 && cp[g] / cp[g - 1] <= 2.4,
          "point load: compliance ratio %.4g on halving h (%d), expected 2 (1/h) +- 0.4",
          cp[g] / cp[g - 1], g);
  const double d1 = fabs(cd[1] - cd[0]), d2 = fabs(cd[2] - cd[1]); /* 3 */
  CHECK(d2 <= d1 / 1.5, "disc: changes %.4g then %.4g m/N, expected to shrink by >= 1.5", d1, d2);
  const double half = 16.0 * (1.0 - NU * NU) / (3.0 * M_PI * M_PI * E_T * A_R);
  CHECK(cd[NGRID - 1] >= 0.6 * half && cd[NGRID - 1] <= 1.05 * half,
        "disc: compliance %.4g m/N, expected in [0.6, 1.05] x the half-space's %.4g", cd[NGRID - 1],
        half);
  if (verbose) printf("half-space disc %.6g m/N; disc changes %.4g, %.4g\n", half, d1, d2);
  return nh_test_failures ? 1 : 0;
}
