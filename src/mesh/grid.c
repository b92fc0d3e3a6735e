/* grid.c — the initial hexahedral grid over a domain's bounding box, storage
 * growth and the list of leaves.
 *
 * Nodes and cells of the lattice are numbered lexicographically (x fastest).
 * For a box domain every cell is kept, so node (i, j, k) has index
 * i + (g0+1) (j + (g1+1) k) and cell (i, j, k) index i + g0 (j + g1 k). For an
 * immersed domain (docs/theory.md, "Immersed domain") only the cells that may
 * meet the shape are kept, each with its fill fraction φ (NH_FILL_SAMPLES³
 * midpoints, floored at NH_FILL_MIN); the nodes no kept cell uses are
 * removed, and the survivors keep the lattice's order. Nothing may then
 * compute an index from (i, j, k): point location goes through mesh->root,
 * the lattice-to-cell map, which nh_mesh_index_roots rebuilds for a mesh read
 * back from a checkpoint. Every array grows by doubling, since refinement
 * appends nodes and cells. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void nh_mesh_destroy(nh_mesh **mesh) {
  if (!mesh || !*mesh) return;
  nh_mesh *m = *mesh;
  free(m->X);
  free(m->cells);
  free(m->level);
  free(m->parent);
  free(m->first_child);
  free(m->n_children);
  free(m->fill);
  free(m->leaves);
  free(m->root);
  nh_domain_release(&m->domain);
  free(m);
  *mesh = NULL;
}

int nh_mesh_update_leaves(nh_mesh *m) {
  NH_TRY(nh_realloc((void **)&m->leaves, (size_t)m->n_cells, sizeof(int)));
  m->n_leaves = 0;
  for (int c = 0; c < m->n_cells; c++)
    if (m->first_child[c] < 0) m->leaves[m->n_leaves++] = c;
  return NH_OK;
}

int nh_mesh_create_box(const double min[3], const double max[3], const int grid[3], nh_mesh **out) {
  *out = NULL;
  for (int k = 0; k < 3; k++) {
    NH_CHECK(grid[k] >= 1, NH_ERR_INPUT, "grid: cell count %d along axis %d must be >= 1", grid[k],
             k);
    NH_CHECK(max[k] > min[k], NH_ERR_INPUT, "domain box: max[%d] must exceed min[%d]", k, k);
  }
  nh_mesh *m = nh_calloc(1, sizeof *m);
  if (!m) return NH_ERR_MEMORY;
  const int n0 = grid[0] + 1, n1 = grid[1] + 1, n2 = grid[2] + 1;
  m->n_nodes = m->cap_nodes = n0 * n1 * n2;
  m->n_cells = m->cap_cells = grid[0] * grid[1] * grid[2];
  m->X = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  m->cells = nh_calloc(8 * (size_t)m->n_cells, sizeof(int));
  m->level = nh_calloc((size_t)m->n_cells, sizeof(int));
  m->parent = nh_calloc((size_t)m->n_cells, sizeof(int));
  m->first_child = nh_calloc((size_t)m->n_cells, sizeof(int));
  m->n_children = nh_calloc((size_t)m->n_cells, sizeof(int));
  m->fill = nh_calloc((size_t)m->n_cells, sizeof(double));
  m->root = nh_calloc((size_t)m->n_cells, sizeof(int));
  if (!m->X || !m->cells || !m->level || !m->parent || !m->first_child || !m->n_children ||
      !m->fill || !m->root) {
    nh_mesh_destroy(&m);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory building a %d x %d x %d grid", grid[0], grid[1],
                    grid[2]);
  }
  for (int k = 0; k < 3; k++) {
    m->grid[k] = grid[k];
    m->origin[k] = min[k];
    m->spacing[k] = (max[k] - min[k]) / grid[k];
  }
  for (int k = 0; k < n2; k++)
    for (int j = 0; j < n1; j++)
      for (int i = 0; i < n0; i++) {
        double *x = m->X + 3 * (i + n0 * (j + n1 * k));
        /* The last layer lands exactly on max, not on origin + n * spacing. */
        x[0] = i == grid[0] ? max[0] : min[0] + i * m->spacing[0];
        x[1] = j == grid[1] ? max[1] : min[1] + j * m->spacing[1];
        x[2] = k == grid[2] ? max[2] : min[2] + k * m->spacing[2];
      }
  for (int k = 0; k < grid[2]; k++)
    for (int j = 0; j < grid[1]; j++)
      for (int i = 0; i < grid[0]; i++) {
        int c = i + grid[0] * (j + grid[1] * k);
        int *e = m->cells + 8 * c;
        for (int a = 0; a < 8; a++) {
          int di = nh_hex_corner[a][0] > 0, dj = nh_hex_corner[a][1] > 0,
              dk = nh_hex_corner[a][2] > 0;
          e[a] = (i + di) + n0 * ((j + dj) + n1 * (k + dk));
        }
        m->parent[c] = -1;
        m->first_child[c] = -1;
        m->fill[c] = 1.0;
        m->root[c] = c;
      }
  nh_domain_box(min, max, &m->domain);
  int rc = nh_mesh_update_leaves(m);
  if (rc) {
    nh_mesh_destroy(&m);
    return rc;
  }
  *out = m;
  return NH_OK;
}

void nh_mesh_cell_coords(const nh_mesh *m, const double *positions, int c, double Xe[24]) {
  const int *e = m->cells + 8 * c;
  for (int a = 0; a < 8; a++) memcpy(Xe + 3 * a, positions + 3 * e[a], 3 * sizeof(double));
}

/* Keep the cells with keep[c] (ascending), drop the nodes none of them uses;
 * both keep their order. */
static void nh_mesh_compact(nh_mesh *m, const unsigned char *keep, int *node_map) {
  int nc = 0, nn = 0;
  for (int i = 0; i < m->n_nodes; i++) node_map[i] = -1;
  for (int c = 0; c < m->n_cells; c++)
    if (keep[c])
      for (int a = 0; a < 8; a++) node_map[m->cells[8 * c + a]] = 0;
  for (int i = 0; i < m->n_nodes; i++)
    if (node_map[i] == 0) {
      memmove(m->X + 3 * nn, m->X + 3 * i, 3 * sizeof(double));
      node_map[i] = nn++;
    }
  for (int c = 0; c < m->n_cells; c++) {
    m->root[c] = -1;
    if (!keep[c]) continue;
    for (int a = 0; a < 8; a++) m->cells[8 * nc + a] = node_map[m->cells[8 * c + a]];
    m->fill[nc] = m->fill[c];
    m->root[c] = nc++;
  }
  m->n_nodes = nn;
  m->n_cells = nc;
}

int nh_mesh_create(const nh_domain *d, const int grid[3], nh_mesh **out) {
  *out = NULL;
  NH_TRY(nh_mesh_create_box(d->min, d->max, grid, out));
  nh_mesh *m = *out;
  nh_domain_copy(&m->domain, d);
  if (d->kind == NH_DOMAIN_BOX) return NH_OK;
  unsigned char *keep = nh_calloc((size_t)m->n_cells, 1);
  int *node_map = nh_calloc((size_t)m->n_nodes, sizeof(int));
  int rc = NH_OK, kept = 0;
  if (!keep || !node_map) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory building a %d x %d x %d grid", grid[0], grid[1],
                  grid[2]);
    goto done;
  }
  for (int k = 0; k < grid[2]; k++)
    for (int j = 0; j < grid[1]; j++)
      for (int i = 0; i < grid[0]; i++) {
        int c = i + grid[0] * (j + grid[1] * k), ijk[3] = {i, j, k}, meets;
        double phi = nh_domain_lattice_fill(d, grid, ijk, &meets);
        keep[c] = (unsigned char)meets;
        m->fill[c] = fmax(phi, NH_FILL_MIN);
        kept += meets;
      }
  if (kept == 0) {
    rc = NH_ERROR(NH_ERR_INPUT, "the %s domain meets no cell of the %d x %d x %d grid",
                  nh_domain_name(d), grid[0], grid[1], grid[2]);
    goto done;
  }
  nh_mesh_compact(m, keep, node_map);
  rc = nh_mesh_update_leaves(m);
done:
  free(keep);
  free(node_map);
  if (rc) nh_mesh_destroy(out);
  return rc;
}

int nh_mesh_index_roots(nh_mesh *m) {
  const int n = m->grid[0] * m->grid[1] * m->grid[2];
  NH_CHECK(n > 0, NH_ERR_INPUT, "the mesh has an empty grid %d x %d x %d", m->grid[0], m->grid[1],
           m->grid[2]);
  NH_TRY(nh_realloc((void **)&m->root, (size_t)n, sizeof(int)));
  int *root = m->root;
  for (int i = 0; i < n; i++) root[i] = -1;
  for (int c = 0; c < m->n_cells; c++) {
    if (m->parent[c] >= 0) continue;
    const double *X = m->X + 3 * m->cells[8 * c]; /* corner 0: the lattice point (i, j, k) */
    int ijk[3];
    for (int k = 0; k < 3; k++) {
      double s = (X[k] - m->origin[k]) / m->spacing[k];
      ijk[k] = (int)floor(s + 0.5);
      NH_CHECK(fabs(s - ijk[k]) < 1e-6 && ijk[k] >= 0 && ijk[k] < m->grid[k], NH_ERR_INPUT,
               "level-0 cell %d is not a cell of the %d x %d x %d grid", c, m->grid[0], m->grid[1],
               m->grid[2]);
    }
    int q = ijk[0] + m->grid[0] * (ijk[1] + m->grid[1] * ijk[2]);
    NH_CHECK(root[q] < 0, NH_ERR_INPUT, "level-0 cells %d and %d are the same grid cell", root[q],
             c);
    root[q] = c;
  }
  return NH_OK;
}

double nh_mesh_fill_volume(const nh_mesh *m) {
  const double g = 1.0 / sqrt(3.0);
  double volume = 0.0, Xe[24];
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    double v = 0.0;
    for (int q = 0; q < 8; q++) {
      double xi[3] = {g * nh_hex_corner[q][0], g * nh_hex_corner[q][1], g * nh_hex_corner[q][2]};
      double dN[8][3], J[9] = {0};
      nh_hex_dshape(xi, dN);
      for (int a = 0; a < 8; a++)
        for (int p = 0; p < 3; p++)
          for (int r = 0; r < 3; r++) J[3 * p + r] += Xe[3 * a + p] * dN[a][r];
      v += nh_mat3_det(J);
    }
    volume += m->fill[c] * v;
  }
  return volume;
}
