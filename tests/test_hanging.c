/* test_hanging — refinement, hanging nodes and their elimination.
 *
 * 1. Patch test on nested nonconforming meshes: a 3x3x3 grid of distorted
 *    hexahedra, its centre cell refined with a regular template n = 2, 3, 4,
 *    then a child of it that touches the coarse neighbours refined again, and
 *    a boundary cell refined once. A linear field u = A X + c imposed on the
 *    boundary must be reproduced at every node, hanging ones included, to
 *    1e-10: isoparametric trilinear cells represent it exactly and so does
 *    the interpolation that ties a hanging node to its coarse cell.
 * 2. Continuity: under a load that bends the block (a non-linear field), the
 *    displacement seen from the two sides of every leaf face agrees: 5x5
 *    points on each face are evaluated in the leaf and, 1e-9 of a cell
 *    outside the face, in the leaf located on the other side (tolerance
 *    1e-8 of the largest displacement: the offset alone moves u by ~1e-9).
 * 3. Structure: no two nodes share a position; every hanging node's weights
 *    sum to 1 and its masters are not hanging; every node is found by point
 *    location (a probe may sit on a node of a deep hex4 mesh).
 * The templates are built here from their definition (regular n x n x n),
 * independently of the files in templates/. */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "hanging_mesh.h"

static void check_structure(const nh_mesh *m, const nh_hanging *h, int n) {
  for (int i = 0; i < m->n_nodes; i++)
    for (int j = i + 1; j < m->n_nodes; j++) {
      double d = fabs(m->X[3 * i] - m->X[3 * j]) + fabs(m->X[3 * i + 1] - m->X[3 * j + 1]) +
                 fabs(m->X[3 * i + 2] - m->X[3 * j + 2]);
      CHECK(d > 1e-9, "template %d: nodes %d and %d coincide", n, i, j);
    }
  CHECK(h->n_hanging > 0, "template %d: no hanging node found", n);
  for (int k = 0; k < h->n_hanging; k++) {
    double sum = 0.0;
    for (int p = h->start[k]; p < h->start[k + 1]; p++) {
      sum += h->weight[p];
      CHECK(h->index[h->master[p]] < 0, "template %d: master %d of node %d is hanging", n,
            h->master[p], h->node[k]);
    }
    CHECK_CLOSE(sum, 1.0, 1e-12, "sum of hanging weights");
  }
}

static int on_boundary(const double *x) {
  for (int k = 0; k < 3; k++)
    if (x[k] < 1e-9 || x[k] > 0.03 - 1e-9) return 1;
  return 0;
}

static void patch_test(int n) {
  nh_template *t = regular_template(n);
  nh_mesh *m = build_mesh(n, t);
  unsigned char *fixed = calloc(m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = (unsigned char)on_boundary(m->X + 3 * i);
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(m, fixed, &h));
  check_structure(m, h, n);
  /* Every node is found by point location (probes may sit on nodes), in a
   * leaf whose map reproduces its position. */
  for (int i = 0; i < m->n_nodes; i++) {
    int cell;
    double xi[3], N[8];
    int found = nh_mesh_locate(m, m->X + 3 * i, &cell, xi) == NH_OK;
    CHECK(found, "template %d: node %d at [%g, %g, %g] not located", n, i, m->X[3 * i],
          m->X[3 * i + 1], m->X[3 * i + 2]);
    if (!found) continue;
    nh_hex_shape(xi, N);
    double Xe[24], x[3] = {0, 0, 0};
    nh_mesh_cell_coords(m, m->X, cell, Xe);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) x[k] += N[a] * Xe[3 * a + k];
    for (int k = 0; k < 3; k++) CHECK_CLOSE(x[k], m->X[3 * i + k], 1e-12, "located node position");
  }
  nh_material mat = {1e5, 0.35, 1000, NH_FORMULATION_BBAR};
  nh_tissue *ts;
  CHECK_OK(nh_tissue_create(m, &mat, &ts));
  nh_system *s;
  CHECK_OK(nh_system_create(ts, fixed, h, &s));
  const double A[9] = {1e-3, 2e-4, -3e-4, 5e-4, -1e-3, 2e-4, 1e-4, 3e-4, 7e-4},
               c[3] = {1e-4, -2e-4, 5e-5};
  double *u = calloc(3 * m->n_nodes, sizeof(double)), *f = calloc(3 * m->n_nodes, sizeof(double));
  for (int i = 0; i < m->n_nodes; i++)
    if (fixed[i]) {
      nh_mat3_vec(A, m->X + 3 * i, u + 3 * i);
      for (int k = 0; k < 3; k++) u[3 * i + k] += c[k];
    }
  nh_hanging_interpolate(h, u, 3);
  nh_integrator in = {.tolerance = 1e-11, .max_iterations = 50, .threads = 1};
  CHECK_OK(nh_solve_static(s, &in, f, u, NULL));
  double umax = 1e-4 * 0.03 * 3;
  for (int i = 0; i < m->n_nodes; i++) {
    double e[3];
    nh_mat3_vec(A, m->X + 3 * i, e);
    for (int k = 0; k < 3; k++)
      CHECK_CLOSE(u[3 * i + k], e[k] + c[k], 1e-10 * umax, "patch test with hanging nodes");
  }

  /* Continuity under a bending load: clamp x = 0, push the x = 0.03 face. */
  memset(u, 0, sizeof(double) * 3 * m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i] < 1e-9;
  nh_hanging_destroy(&h);
  nh_system_destroy(&s);
  CHECK_OK(nh_hanging_detect(m, fixed, &h));
  CHECK_OK(nh_system_create(ts, fixed, h, &s));
  nh_region tip = {.min = {0.029, 0.0, 0.0}, .max = {0.03, 0.03, 0.03}};
  double force[3] = {0, 0, -0.5};
  CHECK_OK(nh_mesh_region_load(m, &tip, force, f));
  CHECK_OK(nh_solve_static(s, &in, f, u, NULL));
  double big = 0.0;
  for (int i = 0; i < 3 * m->n_nodes; i++) big = fmax(big, fabs(u[i]));
  CHECK(big > 1e-6, "the load bent nothing (%g)", big);
  int faces = 0;
  static const int face_axis[6] = {0, 0, 1, 1, 2, 2};
  for (int l = 0; l < m->n_leaves; l++) {
    int cell = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, cell, Xe);
    for (int fc = 0; fc < 6; fc++)
      for (int p = 0; p < 25; p++) {
        double xi[3];
        xi[face_axis[fc]] = fc % 2 ? 1.0 : -1.0;
        xi[(face_axis[fc] + 1) % 3] = -0.9 + 1.8 * (p % 5) / 4.0;
        xi[(face_axis[fc] + 2) % 3] = -0.9 + 1.8 * (p / 5) / 4.0;
        double N[8], x[3] = {0, 0, 0}, ua[3] = {0, 0, 0}, xo[3], ub[3] = {0, 0, 0}, xib[3];
        nh_hex_shape(xi, N);
        for (int a = 0; a < 8; a++)
          for (int k = 0; k < 3; k++)
            x[k] += N[a] * Xe[3 * a + k], ua[k] += N[a] * u[3 * m->cells[8 * cell + a] + k];
        double xin[3] = {0, 0, 0}; /* a hair outside: away from the cell centre */
        for (int a = 0; a < 8; a++)
          for (int k = 0; k < 3; k++) xin[k] += 0.125 * Xe[3 * a + k];
        for (int k = 0; k < 3; k++) xo[k] = x[k] + 1e-9 * (x[k] - xin[k]);
        int other;
        if (nh_mesh_locate(m, xo, &other, xib) != NH_OK || other == cell) continue; /* outer face */
        double Nb[8];
        nh_hex_shape(xib, Nb);
        for (int a = 0; a < 8; a++)
          for (int k = 0; k < 3; k++) ub[k] += Nb[a] * u[3 * m->cells[8 * other + a] + k];
        for (int k = 0; k < 3; k++)
          CHECK_CLOSE(ub[k], ua[k], 1e-8 * big, "displacement across a face");
        faces++;
      }
  }
  CHECK(faces > 0, "no interior face sampled");
  free(u), free(f), free(fixed);
  nh_system_destroy(&s);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&ts);
  nh_mesh_destroy(&m);
  nh_template_destroy(&t);
}

/* Point location on small cells far from the origin: a 1 cm box at 1 m,
 * refined twice with hex4 (cells of 0.6 mm): the coordinates' round-off
 * (eps |x| = 2e-16 m) exceeds 1e-14 of the cell size, the residual Newton
 * tolerance of nh_hex_invert alone; every node must still be located. */
static void locate_far(void) {
  const double lo[3] = {1.0, 1.0, 1.0}, hi[3] = {1.01, 1.01, 1.01};
  const int grid[3] = {2, 2, 2};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_template *t = regular_template(4);
  int first = 0;
  CHECK_OK(nh_mesh_refine(m, t, &first, 1, NULL));
  const double p[3] = {1.005, 1.005, 1.005};
  int ch = child_near(m, 0, p);
  CHECK_OK(nh_mesh_refine(m, t, &ch, 1, NULL));
  int missed = 0;
  for (int i = 0; i < m->n_nodes; i++) {
    int cell;
    double xi[3];
    missed += nh_mesh_locate(m, m->X + 3 * i, &cell, xi) != NH_OK;
  }
  CHECK(missed == 0, "%d of %d nodes of a far-away hex4 mesh not located", missed, m->n_nodes);
  nh_template_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(void) {
  locate_far();
  for (int n = 2; n <= 4; n++) patch_test(n);
  TEST_END();
}
