/* dwr_support.h — the pieces of the DWR identity tests computed on paths of
 * their own (test_dwr, test_dwr_rows): the energy product summed element by
 * element, and a nodal field carried to refined nodes. */
#ifndef NH_TEST_DWR_SUPPORT_H
#define NH_TEST_DWR_SUPPORT_H

#include <stdlib.h>
#include <string.h>

#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

__attribute__((unused)) static double dwr_dot(int n, const double *a, const double *b) {
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * b[i];
  return s;
}

/* The localized-load block's load (cases/adapt-localized.yaml): 1 µN down
 * over the 2 mm cube centred at (1, 1, 1) cm; f[3 n_nodes] overwritten. */
__attribute__((unused)) static int dwr_block_load(const nh_mesh *m, double *f) {
  memset(f, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  nh_region load = {.min = {0.009, 0.009, 0.009}, .max = {0.011, 0.011, 0.011}};
  double force[3] = {0, 0, -1e-6};
  return nh_mesh_region_load(m, &load, force, f);
}

/* The block's system on mesh m (the tests' block, clamped at x = 4 cm):
 * tissue of `mat`, the clamp's flags, hanging nodes, and the rest
 * stiffness assembled and factorised; the objects in *t, *fixed, *h, *s are
 * replaced. 0 or the first failure's code. */
__attribute__((unused)) static int dwr_block_system(const nh_mesh *m, const nh_material *mat,
                                                    nh_tissue **t, unsigned char **fixed,
                                                    nh_hanging **h, nh_system **s) {
  nh_tissue_destroy(t);
  nh_hanging_destroy(h);
  nh_system_destroy(s);
  int rc = nh_tissue_create(m, mat, t);
  unsigned char *fx = realloc(*fixed, (size_t)m->n_nodes);
  if (!fx) return NH_ERR_MEMORY;
  *fixed = fx;
  for (int i = 0; i < m->n_nodes; i++) fx[i] = m->X[3 * i] > 0.0399;
  if (!rc) rc = nh_hanging_detect(m, fx, h);
  if (!rc) rc = nh_system_create(*t, fx, *h, s);
  double *zero = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  if (!rc) nh_system_assemble(*s, zero, NULL, 0.0, 1.0, zero, NULL, 0);
  if (!rc) rc = nh_system_factor(*s);
  free(zero);
  return rc;
}

/* a(v, w) = Σ_leaves v_eᵀ φ K₀ w_e, element by element (R = I at rest). */
__attribute__((unused)) static double dwr_energy_product(const nh_mesh *m, const nh_tissue *t,
                                                         const double *v, const double *w) {
  double *zero = calloc(3 * m->n_nodes, sizeof(double)), s = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], K[576], ve[24], we[24];
    nh_tissue_element(t, c, zero, fe, K);
    nh_mesh_cell_coords(m, v, c, ve);
    nh_mesh_cell_coords(m, w, c, we);
    for (int r = 0; r < 24; r++)
      for (int q = 0; q < 24; q++) s += ve[r] * K[24 * r + q] * we[q];
  }
  free(zero);
  return s;
}

/* Carry a nodal field to the nodes `info` created (Eq. 17). */
__attribute__((unused)) static double *dwr_prolong(const nh_mesh *m, const nh_refine_info *info,
                                                   const double *old, int n_old) {
  double *v = calloc(3 * m->n_nodes, sizeof(double));
  memcpy(v, old, sizeof(double) * 3 * n_old);
  for (int k = 0; k < info->n_new; k++) {
    double N[8];
    nh_hex_shape(info->xi + 3 * k, N);
    const int *e = m->cells + 8 * info->parent[k];
    for (int i = 0; i < 3; i++)
      for (int a = 0; a < 8; a++) v[3 * (info->first_new + k) + i] += N[a] * v[3 * e[a] + i];
  }
  return v;
}

#endif
