/* coarsen.c — merging children back into their parent (the inverse of
 * mesh/refine.c; docs/adaptivity.md "Grading and coarsening").
 *
 * A parent whose children are all leaves becomes a leaf again: its children
 * leave the cell array, and the nodes no remaining cell (leaf or ancestor)
 * uses leave the node array. Both arrays are compacted in place, keeping the
 * order of what remains, and every index into them (cells' corners, parent,
 * first_child, root) is renumbered; a node map old → new (−1: removed) lets
 * the caller compact its nodal fields the same way.
 *
 * The state is restricted by injection: a kept node keeps its value, the
 * parent's field is the trilinear interpolation of its corners (which were
 * corners before: refinement never moves a parent's corner). A node that
 * stays because a finer neighbour still uses it, and now lies on the
 * coarsened parent's face or edge, becomes hanging; the caller re-imposes
 * u_h = Σ w u_m there (nh_hanging_interpolate after nh_hanging_detect).
 *
 * Because refinement appends its new nodes and cells at the ends of the
 * arrays, coarsening the cells just refined, with nothing changed in
 * between, gives back the mesh before the refinement exactly (same arrays,
 * same order), and injection gives back the state exactly. */
#include "mesh/mesh.h"

#include <stdlib.h>
#include <string.h>

int nh_mesh_coarsen(nh_mesh *m, const int *parents, int n, int *node_map) {
  int nc = m->n_cells, nn = m->n_nodes;
  for (int i = 0; i < n; i++) {
    int p = parents[i];
    NH_CHECK(p >= 0 && p < nc && m->first_child[p] >= 0, NH_ERR_INTERNAL,
             "cell %d cannot be coarsened: it has no children", p);
    for (int ch = m->first_child[p]; ch < m->first_child[p] + m->n_children[p]; ch++)
      NH_CHECK(m->first_child[ch] < 0, NH_ERR_INTERNAL,
               "cell %d cannot be coarsened: its child %d is refined", p, ch);
  }
  int *cell_map = nh_calloc((size_t)(nc ? nc : 1), sizeof(int));
  unsigned char *used = nh_calloc((size_t)(nn ? nn : 1), 1);
  if (!cell_map || !used) {
    free(cell_map), free(used);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: coarsening %d cells", n);
  }
  for (int c = 0; c < nc; c++) cell_map[c] = 0;
  for (int i = 0; i < n; i++) {
    int p = parents[i];
    for (int ch = m->first_child[p]; ch < m->first_child[p] + m->n_children[p]; ch++)
      cell_map[ch] = -1;
    m->first_child[p] = -1;
    m->n_children[p] = 0;
  }
  int kept = 0;
  for (int c = 0; c < nc; c++)
    if (cell_map[c] == 0) {
      cell_map[c] = kept++;
      for (int a = 0; a < 8; a++) used[m->cells[8 * c + a]] = 1;
    }
  int nodes = 0;
  for (int v = 0; v < nn; v++) node_map[v] = used[v] ? nodes++ : -1;
  for (int v = 0; v < nn; v++)
    if (node_map[v] >= 0 && node_map[v] != v)
      memmove(m->X + 3 * node_map[v], m->X + 3 * v, 3 * sizeof(double));
  for (int c = 0; c < nc; c++) {
    int d = cell_map[c];
    if (d < 0) continue;
    for (int a = 0; a < 8; a++) m->cells[8 * d + a] = node_map[m->cells[8 * c + a]];
    m->level[d] = m->level[c];
    m->parent[d] = m->parent[c] >= 0 ? cell_map[m->parent[c]] : -1;
    m->first_child[d] = m->first_child[c] >= 0 ? cell_map[m->first_child[c]] : -1;
    m->n_children[d] = m->n_children[c];
    m->fill[d] = m->fill[c];
  }
  if (m->root)
    for (int r = 0; r < m->grid[0] * m->grid[1] * m->grid[2]; r++)
      if (m->root[r] >= 0) m->root[r] = cell_map[m->root[r]];
  m->n_cells = kept;
  m->n_nodes = nodes;
  free(cell_map), free(used);
  return nh_mesh_update_leaves(m);
}
