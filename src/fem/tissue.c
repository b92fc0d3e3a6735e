/* tissue.c — element data of the tissue mesh and its lumped mass.
 *
 * K₀ (4.6 kB) depends only on the rest shape of a cell up to translation.
 * A uniform grid has one shape, a refined one a handful per level, so cells
 * share element data through a hash of their rest corners relative to
 * corner 0, quantised to 1e-9 of the cell size. Two shapes that differ by
 * less than that but straddle a quantisation boundary simply get two
 * entries: the cache never merges cells that differ. */
#include "fem/fem.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void nh_tissue_destroy(nh_tissue **tissue) {
  if (!tissue || !*tissue) return;
  nh_tissue *t = *tissue;
  free(t->K0);
  free(t->G0);
  free(t->volume);
  free(t->key);
  free(t->cell_shape);
  free(t->mass);
  free(t);
  *tissue = NULL;
}

static uint64_t nh_shape_hash(const double key[24], double size) {
  uint64_t h = 1469598103934665603ull;
  for (int i = 0; i < 24; i++) {
    int64_t q = (int64_t)llround(key[i] / (1e-9 * size));
    h = (h ^ (uint64_t)q) * 1099511628211ull;
  }
  return h;
}

/* Find or compute the element data for the rest corners Xe. */
static int nh_tissue_shape(nh_tissue *t, const double Xe[24], int *table, int table_size,
                           int *shape) {
  double key[24], size = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      key[3 * a + k] = Xe[3 * a + k] - Xe[k];
      size = fmax(size, fabs(key[3 * a + k]));
    }
  uint64_t h = nh_shape_hash(key, size);
  int slot = (int)(h % (uint64_t)table_size);
  while (table[slot] >= 0) {
    const double *other = t->key + 24 * table[slot];
    int same = 1;
    for (int i = 0; i < 24 && same; i++) same = fabs(other[i] - key[i]) <= 1e-12 * size;
    if (same) {
      *shape = table[slot];
      return NH_OK;
    }
    slot = (slot + 1) % table_size;
  }
  int s = t->n_shapes;
  if (s >= t->cap_shapes) {
    int cap = t->cap_shapes ? 2 * t->cap_shapes : 8;
    double *K0 = realloc(t->K0, sizeof(double) * 576 * cap);
    if (K0) t->K0 = K0;
    double *G0 = realloc(t->G0, sizeof(double) * 24 * cap);
    if (G0) t->G0 = G0;
    double *vol = realloc(t->volume, sizeof(double) * cap);
    if (vol) t->volume = vol;
    double *keys = realloc(t->key, sizeof(double) * 24 * cap);
    if (keys) t->key = keys;
    if (!K0 || !G0 || !vol || !keys) return NH_ERROR(NH_ERR_MEMORY, "out of memory: element data");
    t->cap_shapes = cap;
  }
  if (nh_hex_stiffness(Xe, t->lambda, t->mu, t->K0 + 576 * s, t->G0 + 24 * s, t->volume + s))
    return NH_ERR_INPUT;
  memcpy(t->key + 24 * s, key, sizeof key);
  t->n_shapes++;
  table[slot] = s;
  *shape = s;
  return NH_OK;
}

int nh_tissue_update(nh_tissue *t) {
  const nh_mesh *m = t->mesh;
  if (m->n_cells > t->cap_cells) {
    int *cs = realloc(t->cell_shape, sizeof(int) * (size_t)m->n_cells);
    if (!cs) return NH_ERROR(NH_ERR_MEMORY, "out of memory: cell data");
    for (int c = t->cap_cells; c < m->n_cells; c++) cs[c] = -1;
    t->cell_shape = cs;
    t->cap_cells = m->n_cells;
  }
  if (m->n_nodes > t->cap_nodes) {
    double *mass = realloc(t->mass, sizeof(double) * (size_t)m->n_nodes);
    if (!mass) return NH_ERROR(NH_ERR_MEMORY, "out of memory: nodal mass");
    t->mass = mass;
    t->cap_nodes = m->n_nodes;
  }
  /* The hash table is rebuilt from the shapes already known, then extended. */
  int table_size = 2 * (t->n_shapes + m->n_leaves) + 1;
  int *table = malloc(sizeof(int) * (size_t)table_size);
  if (!table) return NH_ERROR(NH_ERR_MEMORY, "out of memory: shape table");
  for (int i = 0; i < table_size; i++) table[i] = -1;
  for (int s = 0; s < t->n_shapes; s++) {
    double size = 0.0;
    for (int i = 0; i < 24; i++) size = fmax(size, fabs(t->key[24 * s + i]));
    int slot = (int)(nh_shape_hash(t->key + 24 * s, size) % (uint64_t)table_size);
    while (table[slot] >= 0) slot = (slot + 1) % table_size;
    table[slot] = s;
  }
  int rc = NH_OK;
  double Xe[24];
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    int c = m->leaves[l];
    if (t->cell_shape[c] >= 0) continue;
    nh_mesh_cell_coords(m, m->X, c, Xe);
    rc = nh_tissue_shape(t, Xe, table, table_size, &t->cell_shape[c]);
    if (rc == NH_ERR_INPUT)
      NH_ERROR(rc, "cell %d (level %d) has a non-positive Jacobian in its rest shape", c,
               m->level[c]);
  }
  free(table);
  if (rc) return rc;
  memset(t->mass, 0, sizeof(double) * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double mc = t->material.density * m->fill[c] * t->volume[t->cell_shape[c]] / 8.0;
    for (int a = 0; a < 8; a++) t->mass[m->cells[8 * c + a]] += mc;
  }
  return NH_OK;
}

int nh_tissue_create(const nh_mesh *mesh, const nh_material *material, nh_tissue **out) {
  *out = NULL;
  nh_tissue *t = nh_calloc(1, sizeof *t);
  if (!t) return NH_ERR_MEMORY;
  t->mesh = mesh;
  t->material = *material;
  nh_lame(material->young, material->poisson, &t->lambda, &t->mu);
  int rc = nh_tissue_update(t);
  if (rc) {
    nh_tissue_destroy(&t);
    return rc;
  }
  *out = t;
  return NH_OK;
}

void nh_tissue_element(const nh_tissue *t, int c, const double *u, double f[24], double Kt[576]) {
  const nh_mesh *m = t->mesh;
  int s = t->cell_shape[c];
  double Xe[24], ue[24], R[9];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  nh_hex_corot(Xe, ue, t->K0 + 576 * s, t->G0 + 24 * s, R, f, Kt);
  double phi = m->fill[c];
  if (phi != 1.0) {
    for (int i = 0; i < 24; i++) f[i] *= phi;
    if (Kt)
      for (int i = 0; i < 576; i++) Kt[i] *= phi;
  }
}

double nh_tissue_energy(const nh_tissue *t, const double *u) {
  const nh_mesh *m = t->mesh;
  double energy = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l], s = t->cell_shape[c];
    double Xe[24], ue[24], R[9], d[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    /* ½ dᵀ K0 d with d computed as the force is (centroid-relative, no
     * cancellation of the coordinates' magnitude). */
    nh_hex_corotated(Xe, ue, t->G0 + 24 * s, R, d);
    const double *K0 = t->K0 + 576 * s;
    double e = 0.0;
    for (int r = 0; r < 24; r++) {
      double kd = 0.0;
      for (int q = 0; q < 24; q++) kd += K0[24 * r + q] * d[q];
      e += d[r] * kd;
    }
    energy += 0.5 * m->fill[c] * e;
  }
  return energy;
}

void nh_tissue_cell_stress(const nh_tissue *t, int c, const double *u, double s[6]) {
  const nh_mesh *m = t->mesh;
  double Xe[24], ue[24];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  nh_hex_center_stress(Xe, ue, t->G0 + 24 * t->cell_shape[c], t->lambda, t->mu, s);
}
