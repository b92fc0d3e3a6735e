/* dwr_support.h — the pieces of the DWR identity tests computed on paths of
 * their own (test_dwr, test_dwr_rows, test_dwr_skull): the energy product
 * summed element by element, a nodal field carried to refined nodes, and
 * the constrained solution by a dense LU solve of the saddle-point system. */
#ifndef NH_TEST_DWR_SUPPORT_H
#define NH_TEST_DWR_SUPPORT_H

#include <lapacke.h>
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

/* n_i · w(P_i) of row i's tissue part (widened rows too) for a nodal field w. */
__attribute__((unused)) static double dwr_row_value(const nh_rows *rows, int i, const double *w) {
  double s = 0.0;
  for (int a = rows->start[i]; a < rows->start[i + 1]; a++)
    for (int k = 0; k < 3 && rows->node[a] >= 0; k++)
      s += rows->N[a] * rows->dir[3 * i + k] * w[3 * rows->node[a] + k];
  return s;
}

/* The dense matrix [K Jᵀ; J 0] over the unfixed DOFs and the rows with
 * active[i] != 0 (K summed from the element matrices at rest, J from the
 * rows' shape values), column-major N x N, N = *nf + active rows (malloc'd,
 * NULL when out of memory); dof[3 n_nodes]: the unfixed DOFs' positions,
 * −1 at fixed ones. The rows' tool parts are ignored; no hanging nodes. */
__attribute__((unused)) static double *
dwr_dense_kkt(const nh_mesh *m, const nh_tissue *t, const unsigned char *fixed, const nh_rows *rows,
              const unsigned char *active, int *dof, int *nf_out, int *N_out) {
  int n = 3 * m->n_nodes, nf = 0, na = 0;
  for (int i = 0; i < n; i++) dof[i] = fixed[i / 3] ? -1 : nf++;
  for (int i = 0; i < rows->m; i++) na += active[i] != 0;
  int N = nf + na;
  double *A = calloc((size_t)N * N, sizeof(double)), *zero = calloc(n, sizeof(double));
  if (!A || !zero) {
    free(A), free(zero);
    return NULL;
  }
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], K[576];
    nh_tissue_element(t, c, zero, fe, K);
    for (int r = 0; r < 24; r++)
      for (int q = 0; q < 24; q++) {
        int dr = dof[3 * m->cells[8 * c + r / 3] + r % 3],
            dq = dof[3 * m->cells[8 * c + q / 3] + q % 3];
        if (dr >= 0 && dq >= 0) A[(size_t)dq * N + dr] += K[24 * r + q];
      }
  }
  for (int i = 0, row = nf; i < rows->m; i++) {
    if (!active[i]) continue;
    for (int a = rows->start[i]; a < rows->start[i + 1]; a++)
      for (int k = 0; k < 3 && rows->node[a] >= 0; k++) {
        int d = dof[3 * rows->node[a] + k];
        double v = rows->N[a] * rows->dir[3 * i + k];
        if (d < 0) continue;
        A[(size_t)d * N + row] += v;
        A[(size_t)row * N + d] += v;
      }
    row++;
  }
  free(zero);
  *nf_out = nf, *N_out = N;
  return A;
}

/* The LU factors of dwr_dense_kkt's matrix, kept for several right-hand
 * sides; K: the matrix itself. */
typedef struct {
  int n, nf, N, *dof, *piv;
  double *K, *LU;
  const nh_rows *rows;
  const unsigned char *active;
} dwr_dense;

__attribute__((unused)) static void dwr_dense_free(dwr_dense *d) {
  free(d->dof), free(d->piv), free(d->K), free(d->LU);
  memset(d, 0, sizeof *d);
}

/* Factorise [K Jᵀ; J 0] of the rows with active[i] != 0 (rows and active
 * are kept, not copied). 0, or −1 (out of memory, or a singular matrix). */
__attribute__((unused)) static int dwr_dense_factor(const nh_mesh *m, const nh_tissue *t,
                                                    const unsigned char *fixed, const nh_rows *rows,
                                                    const unsigned char *active, dwr_dense *d) {
  memset(d, 0, sizeof *d);
  d->n = 3 * m->n_nodes, d->rows = rows, d->active = active;
  d->dof = malloc(sizeof(int) * d->n);
  d->K = d->dof ? dwr_dense_kkt(m, t, fixed, rows, active, d->dof, &d->nf, &d->N) : NULL;
  d->LU = d->K ? malloc(sizeof(double) * (size_t)d->N * d->N) : NULL;
  d->piv = d->LU ? malloc(sizeof(int) * d->N) : NULL;
  if (!d->piv) return dwr_dense_free(d), -1;
  memcpy(d->LU, d->K, sizeof(double) * (size_t)d->N * d->N);
  if (LAPACKE_dgetrf(LAPACK_COL_MAJOR, d->N, d->N, d->LU, d->N, d->piv) != 0)
    return dwr_dense_free(d), -1;
  return 0;
}

/* The solution of K u + Jᵀλ = f, J u = −g on the active rows (g the rows'
 * gaps: each active row's c(u) = J u + g held at 0): u[3 n_nodes] (0 at
 * fixed DOFs), lambda[rows->m] (may be NULL; 0 on inactive rows; the KKT
 * multiplier, the force on the tissue being −Jᵀλ). 0, or −1. */
__attribute__((unused)) static int dwr_dense_apply(const dwr_dense *d, const double *f, double *u,
                                                   double *lambda) {
  double *b = calloc(d->N, sizeof(double));
  if (!b) return -1;
  for (int i = 0; i < d->n; i++)
    if (d->dof[i] >= 0) b[d->dof[i]] = f[i];
  for (int i = 0, row = d->nf; i < d->rows->m; i++)
    if (d->active[i]) b[row++] = -d->rows->gap[i];
  const int rc = LAPACKE_dgetrs(LAPACK_COL_MAJOR, 'N', d->N, 1, d->LU, d->N, d->piv, b, d->N);
  if (rc == 0) {
    for (int i = 0; i < d->n; i++) u[i] = d->dof[i] >= 0 ? b[d->dof[i]] : 0.0;
    for (int i = 0, row = d->nf; i < d->rows->m && lambda; i++)
      lambda[i] = d->active[i] ? b[row++] : 0.0;
  }
  free(b);
  return rc ? -1 : 0;
}

/* dwr_dense_apply with a factorisation of its own. */
__attribute__((unused)) static int dwr_dense_solve(const nh_mesh *m, const nh_tissue *t,
                                                   const unsigned char *fixed, const double *f,
                                                   const nh_rows *rows, const unsigned char *active,
                                                   double *u, double *lambda) {
  dwr_dense d;
  if (dwr_dense_factor(m, t, fixed, rows, active, &d)) return -1;
  const int rc = dwr_dense_apply(&d, f, u, lambda);
  dwr_dense_free(&d);
  return rc;
}

#endif
