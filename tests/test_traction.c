/* test_traction — surface loads on the tissue's boundary (src/fem/traction.c):
 *  1. box domain, uniform traction t on one face: the nodal forces sum to
 *     t A, every node off the face gets none, and each face node of an
 *     axis-aligned grid gets t × its tributary area (corner ¼, edge ½,
 *     interior 1 cell face) — the exact consistent load of a bilinear face;
 *  2. box domain, pressure on all six faces: integrated area 2(ab + bc + ca)
 *     and zero net force;
 *  3. immersed (the brain): pressure on the whole surface F = 0 cut from the
 *     cells has zero net force (the pieces close up: Σ n A = 0) to round-off
 *     relative to p A, on three grids; the area converges (printed on
 *     failure), and pressure on the upper half pushes down.
 * Silent on success. */
#include "fem/fem.h"

#include "check.h"

#include <stdlib.h>
#include <string.h>

static nh_traction traction_box(const double lo[3], const double hi[3]) {
  nh_traction tr;
  memset(&tr, 0, sizeof tr);
  tr.region.kind = NH_REGION_BOX;
  memcpy(tr.region.min, lo, sizeof tr.region.min);
  memcpy(tr.region.max, hi, sizeof tr.region.max);
  strcpy(tr.where, "test");
  strcpy(tr.region.where, "test");
  return tr;
}

static void test_face(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.01};
  const int grid[3] = {4, 3, 2};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  double rlo[3] = {0.04, -1, -1}, rhi[3] = {1, 1, 1};
  nh_traction tr = traction_box(rlo, rhi);
  tr.traction[0] = 100, tr.traction[1] = -30, tr.traction[2] = 7;
  double *f = calloc(3 * (size_t)m->n_nodes, sizeof *f), area;
  CHECK_OK(nh_traction_load(m, &tr, f, &area));
  const double A = 0.02 * 0.01, dy = 0.02 / 3, dz = 0.01 / 2;
  CHECK_CLOSE(area, A, 1e-15, "face area");
  double sum[3] = {0, 0, 0};
  for (int i = 0; i < m->n_nodes; i++) {
    const double *X = m->X + 3 * i;
    int on = fabs(X[0] - 0.04) < 1e-12;
    int ey = fabs(X[1]) < 1e-12 || fabs(X[1] - 0.02) < 1e-12;
    int ez = fabs(X[2]) < 1e-12 || fabs(X[2] - 0.01) < 1e-12;
    double trib = on ? dy * dz * (ey ? 0.5 : 1.0) * (ez ? 0.5 : 1.0) : 0.0;
    for (int k = 0; k < 3; k++) {
      sum[k] += f[3 * i + k];
      CHECK_CLOSE(f[3 * i + k], tr.traction[k] * trib, 1e-14, "nodal force = t x tributary area");
    }
  }
  for (int k = 0; k < 3; k++) CHECK_CLOSE(sum[k], tr.traction[k] * A, 1e-14, "total force t A");
  free(f);

  /* pressure everywhere */
  double alo[3] = {-1, -1, -1}, ahi[3] = {1, 1, 1};
  tr = traction_box(alo, ahi);
  tr.is_pressure = 1, tr.pressure = 250;
  f = calloc(3 * (size_t)m->n_nodes, sizeof *f);
  CHECK_OK(nh_traction_load(m, &tr, f, &area));
  CHECK_CLOSE(area, 2 * (0.04 * 0.02 + 0.02 * 0.01 + 0.01 * 0.04), 1e-15, "box surface area");
  for (int k = 0; k < 3; k++) {
    double s = 0.0;
    for (int i = 0; i < m->n_nodes; i++) s += f[3 * i + k];
    CHECK_CLOSE(s, 0.0, 1e-13 * 250 * area, "pressure on a closed box: zero net force");
  }
  /* the x = 0 face is pushed in +x: its nodes carry +p × tributary area */
  double fx0 = 0.0;
  for (int i = 0; i < m->n_nodes; i++)
    if (fabs(m->X[3 * i]) < 1e-12) fx0 += f[3 * i];
  /* the x = 0 nodes also carry the ±y, ±z faces' forces, which are along y, z only */
  CHECK_CLOSE(fx0, 250 * 0.02 * 0.01, 1e-13, "pressure pushes the x = 0 face inwards");
  free(f);
  /* a region that holds no boundary */
  double ilo[3] = {0.01, 0.005, 0.002}, ihi[3] = {0.02, 0.015, 0.008};
  tr = traction_box(ilo, ihi);
  tr.traction[0] = 1;
  f = calloc(3 * (size_t)m->n_nodes, sizeof *f);
  CHECK(nh_traction_load(m, &tr, f, NULL) == NH_ERR_INPUT, "no boundary in the region");
  free(f);
  nh_mesh_destroy(&m);
}

static void test_immersed(void) {
  const double center[3] = {0.01, -0.02, 0.03}, size[3] = {0.14, 0.17, 0.10};
  nh_domain d;
  nh_domain_brain(center, size, &d);
  const int grids[3][3] = {{10, 12, 7}, {20, 24, 14}, {40, 48, 28}};
  double areas[3];
  for (int g = 0; g < 3; g++) {
    nh_mesh *m;
    CHECK_OK(nh_mesh_create(&d, grids[g], &m));
    double alo[3] = {-1, -1, -1}, ahi[3] = {1, 1, 1};
    nh_traction tr = traction_box(alo, ahi);
    tr.is_pressure = 1, tr.pressure = 1000;
    double *f = calloc(3 * (size_t)m->n_nodes, sizeof *f);
    CHECK_OK(nh_traction_load(m, &tr, f, &areas[g]));
    for (int k = 0; k < 3; k++) {
      double s = 0.0;
      for (int i = 0; i < m->n_nodes; i++) s += f[3 * i + k];
      CHECK(fabs(s) <= 1e-12 * 1000 * areas[g],
            "brain grid %d: net pressure force %d = %.3g N, expected 0 (tol %.3g = 1e-12 p A)", g,
            k, s, 1e-12 * 1000 * areas[g]);
    }
    /* the upper half (z above the centre) alone: pushed down, by at most p × its area */
    double ulo[3] = {-1, -1, center[2]};
    tr = traction_box(ulo, ahi);
    tr.is_pressure = 1, tr.pressure = 1000;
    memset(f, 0, 3 * (size_t)m->n_nodes * sizeof *f);
    double au;
    CHECK_OK(nh_traction_load(m, &tr, f, &au));
    double fz = 0.0;
    for (int i = 0; i < m->n_nodes; i++) fz += f[3 * i + 2];
    CHECK(fz < 0.0 && -fz <= 1000 * au, "upper half: F_z = %g, expected in [-p A_up, 0), A_up = %g",
          fz, au);
    free(f);
    nh_mesh_destroy(&m);
  }
  /* the cut surface's area converges (piecewise-linear: second order) */
  double e1 = fabs(areas[1] - areas[0]), e2 = fabs(areas[2] - areas[1]);
  CHECK(e2 < 0.5 * e1 && e2 < 0.01 * areas[2],
        "brain surface area not converging: %.6g %.6g %.6g m² (differences %.3g, %.3g)", areas[0],
        areas[1], areas[2], e1, e2);
  if (getenv("NH_VERBOSE"))
    printf("brain area %.8g %.8g %.8g, observed order %.2f\n", areas[0], areas[1], areas[2],
           log(e1 / e2) / log(2.0));
}

int main(void) {
  test_face();
  test_immersed();
  TEST_END();
}
