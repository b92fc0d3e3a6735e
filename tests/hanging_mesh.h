/* hanging_mesh.h — nonconforming test meshes: regular templates built from
 * their definition, and a distorted 3x3x3 grid with nested refinements
 * (test_hanging, test_lagrange). */
#ifndef NH_TEST_HANGING_MESH_H
#define NH_TEST_HANGING_MESH_H

#include "check.h"
#include "mesh/mesh.h"

__attribute__((unused)) static nh_template *regular_template(int n) {
  nh_template *t = calloc(1, sizeof *t);
  int m = n + 1;
  t->n_nodes = m * m * m;
  t->xi = malloc(sizeof(double) * 3 * t->n_nodes);
  for (int k = 0; k < m; k++)
    for (int j = 0; j < m; j++)
      for (int i = 0; i < m; i++) {
        double *x = t->xi + 3 * (i + m * (j + m * k));
        x[0] = -1 + 2.0 * i / n, x[1] = -1 + 2.0 * j / n, x[2] = -1 + 2.0 * k / n;
      }
  t->n_children = n * n * n;
  t->children = malloc(sizeof(int) * 8 * t->n_children);
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++)
        for (int a = 0; a < 8; a++) {
          int di = nh_hex_corner[a][0] > 0, dj = nh_hex_corner[a][1] > 0,
              dk = nh_hex_corner[a][2] > 0;
          t->children[8 * (i + n * (j + n * k)) + a] = (i + di) + m * ((j + dj) + m * (k + dk));
        }
  return t;
}

/* A child of cell c whose centre is nearest to the point p. */
__attribute__((unused)) static int child_near(const nh_mesh *m, int c, const double p[3]) {
  int best = -1;
  double bd = INFINITY;
  for (int ch = m->first_child[c]; ch < m->first_child[c] + m->n_children[c]; ch++) {
    double cx[3] = {0, 0, 0};
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) cx[k] += 0.125 * m->X[3 * m->cells[8 * ch + a] + k];
    double d = (cx[0] - p[0]) * (cx[0] - p[0]) + (cx[1] - p[1]) * (cx[1] - p[1]) +
               (cx[2] - p[2]) * (cx[2] - p[2]);
    if (d < bd) bd = d, best = ch;
  }
  return best;
}

__attribute__((unused)) static nh_mesh *build_mesh(int n, nh_template *t) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.03, 0.03, 0.03};
  const int grid[3] = {3, 3, 3};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_test_rng = 777 + n;
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) {
      double x = m->X[3 * i + k];
      if (x > 1e-9 && x < 0.03 - 1e-9)
        m->X[3 * i + k] += 0.002 * nh_rand(); /* distort interior nodes */
    }
  int centre = 1 + 3 * (1 + 3 * 1), boundary = 1 + 3 * (1 + 3 * 0);
  int first[2] = {centre, boundary};
  CHECK_OK(nh_mesh_refine(m, t, first, 2, NULL));
  /* Again: the child of the centre cell nearest the centre of face x = 0.01. */
  const double p[3] = {0.01, 0.015, 0.015};
  int ch = child_near(m, centre, p);
  CHECK_OK(nh_mesh_refine(m, t, &ch, 1, NULL));
  return m;
}

#endif
