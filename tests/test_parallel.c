/* test_parallel — OpenMP assembly equals serial assembly.
 * With the cell colouring, every matrix entry and force component receives
 * its element contributions in colour order whatever the thread count, so
 * 1 and 2 threads must agree bitwise. Independently, a plain serial loop in
 * natural cell order (no colouring) must agree to round-off (1e-13 relative):
 * this catches a race or a lost contribution, which would show as O(1).
 * Each thread count assembles its own system: a second assembly at the same
 * state would keep A's values (lazy tangents, solve/assemble.c).
 * Twice: on a uniform grid (every leaf coloured), and on one with every
 * other cell refined (hex2, a checkerboard of 216 of 432 cells): nearly all
 * of its 1728 fine leaves have a hanging corner and form the last group,
 * computed in parallel and added in leaf order. */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "hanging_mesh.h"

/* 1 and 2 threads bitwise, and a natural-order serial loop to round-off,
 * on mesh m with the nodes `fixed` and hanging nodes h (NULL: none);
 * colours: the plain leaves' colour count expected (0: not checked). */
static void check_threads(nh_mesh *m, unsigned char *fixed, const nh_hanging *h, int colours) {
  nh_material mat = {1e7, 0.4, 1000, NH_FORMULATION_BBAR};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  nh_system *s, *s2;
  CHECK_OK(nh_system_create(t, fixed, h, &s));
  CHECK_OK(nh_system_create(t, fixed, h, &s2));
  CHECK(!colours || nh_system_colours(s) == colours, "%d colours expected, got %d", colours,
        nh_system_colours(s));
  int n = 3 * m->n_nodes, nf = nh_system_free_dofs(s);
  double *x = malloc(sizeof(double) * n), *v = malloc(sizeof(double) * n);
  for (int i = 0; i < n; i++) x[i] = 1e-3 * nh_rand(), v[i] = nh_rand(); /* x: displacements */
  double *f1 = malloc(sizeof(double) * n), *f2 = malloc(sizeof(double) * n);
  double *k1 = malloc(sizeof(double) * n), *k2 = malloc(sizeof(double) * n);
  double *p = malloc(sizeof(double) * nf), *y1 = malloc(sizeof(double) * nf),
         *y2 = malloc(sizeof(double) * nf);
  for (int j = 0; j < nf; j++) p[j] = nh_rand();
  nh_system_assemble(s, x, v, 2.0, 0.5, f1, k1, 1);
  nh_system_apply(s, p, y1);
  nh_system_assemble(s2, x, v, 2.0, 0.5, f2, k2, 2);
  nh_system_apply(s2, p, y2);
  CHECK(memcmp(f1, f2, sizeof(double) * n) == 0, "f_int differs between 1 and 2 threads");
  CHECK(memcmp(k1, k2, sizeof(double) * n) == 0, "K v differs between 1 and 2 threads");
  CHECK(memcmp(y1, y2, sizeof(double) * nf) == 0, "A differs between 1 and 2 threads");

  /* Reference: natural-order serial accumulation of the same element kernels. */
  double *fr = calloc(n, sizeof(double)), *kr = calloc(n, sizeof(double)), fscale = 0.0,
         kscale = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], Ke[576], ve[24];
    nh_tissue_element(t, c, x, fe, Ke);
    nh_mesh_cell_coords(m, v, c, ve);
    for (int r = 0; r < 24; r++) {
      int dof = 3 * m->cells[8 * c + r / 3] + r % 3;
      fr[dof] += fe[r];
      for (int q = 0; q < 24; q++) kr[dof] += Ke[24 * r + q] * ve[q];
    }
  }
  for (int i = 0; i < n; i++)
    fscale = fmax(fscale, fabs(fr[i])), kscale = fmax(kscale, fabs(kr[i]));
  for (int i = 0; i < n; i++) {
    CHECK_CLOSE(f2[i], fr[i], 1e-13 * fscale, "f_int vs natural-order serial");
    CHECK_CLOSE(k2[i], kr[i], 1e-13 * kscale, "K v vs natural-order serial");
  }
  free(x), free(v), free(f1), free(f2), free(k1), free(k2), free(p), free(y1), free(y2), free(fr),
      free(kr);
  nh_system_destroy(&s);
  nh_system_destroy(&s2);
  nh_tissue_destroy(&t);
}

int main(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {24, 12, 12}; /* 432 cells per colour: above the parallel threshold */
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  unsigned char *fixed = calloc((size_t)m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i] > 0.0399;
  check_threads(m, fixed, NULL, 8); /* a structured grid needs 8 colours */
  free(fixed);
  nh_mesh_destroy(&m);

  const int coarse[3] = {12, 6, 6};
  CHECK_OK(nh_mesh_create_box(lo, hi, coarse, &m));
  int *cells = malloc(sizeof(int) * m->n_cells), n_refine = 0;
  for (int k = 0; k < 6; k++)
    for (int j = 0; j < 6; j++)
      for (int i = 0; i < 12; i++)
        if ((i + j + k) % 2 == 0) cells[n_refine++] = i + 12 * (j + 6 * k);
  nh_template *tmpl = regular_template(2);
  CHECK_OK(nh_mesh_refine(m, tmpl, cells, n_refine, NULL));
  fixed = calloc((size_t)m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i] > 0.0399;
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(m, fixed, &h));
  CHECK(h->n_hanging > 0, "the checkerboard has no hanging node");
  check_threads(m, fixed, h, 0);
  nh_hanging_destroy(&h);
  nh_template_destroy(&tmpl);
  free(cells), free(fixed);
  nh_mesh_destroy(&m);
  TEST_END();
}
