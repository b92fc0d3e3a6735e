/* grid.c — the initial hexahedral grid over a box, storage growth and the
 * list of leaves.
 *
 * Nodes are numbered lexicographically (x fastest) so that a grid's node
 * index is computable from (i, j, k); cells likewise. Every array grows by
 * doubling, since refinement appends nodes and cells. */
#include "mesh/mesh.h"

#include <stdlib.h>
#include <string.h>

const double nh_hex_corner[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

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
  free(m);
  *mesh = NULL;
}

int nh_mesh_update_leaves(nh_mesh *m) {
  int *leaves = realloc(m->leaves, (size_t)(m->n_cells ? m->n_cells : 1) * sizeof(int));
  if (!leaves) return NH_ERROR(NH_ERR_MEMORY, "out of memory listing leaf cells");
  m->leaves = leaves;
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
  m->X = malloc(sizeof(double) * 3 * (size_t)m->n_nodes);
  m->cells = malloc(sizeof(int) * 8 * (size_t)m->n_cells);
  m->level = calloc((size_t)m->n_cells, sizeof(int));
  m->parent = malloc(sizeof(int) * (size_t)m->n_cells);
  m->first_child = malloc(sizeof(int) * (size_t)m->n_cells);
  m->n_children = calloc((size_t)m->n_cells, sizeof(int));
  m->fill = malloc(sizeof(double) * (size_t)m->n_cells);
  if (!m->X || !m->cells || !m->level || !m->parent || !m->first_child || !m->n_children ||
      !m->fill) {
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
      }
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
