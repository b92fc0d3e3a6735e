/* grade.c — the 2:1 rule (grading) of refinement and coarsening
 * (docs/adaptivity.md "Grading and coarsening").
 *
 * The rule. No leaf has a face or edge neighbour more than one level
 * coarser. (Corner-only contacts are free.) It keeps every hanging node one
 * level deep along faces and edges and the size jump between neighbours at
 * one template ratio (2 with hex2), which bounds the interpolation error at
 * coarse–fine interfaces and keeps the far field from being left behind a
 * sharp jump (docs/phantom.md: 4:1 jumps at hex4 interfaces).
 *
 * Neighbours by probing. Cells of our meshes nest on the lattice of the
 * initial grid: a coarser leaf that shares a face (edge) with a leaf c
 * contains c's whole face (edge). So the coarser face neighbours of c are
 * found by locating the point just outside the centre of each of its 6
 * faces, and the coarser edge neighbours by the point just outside the
 * midpoint of each of its 12 edges, diagonally (outward along both
 * normals): that point lies strictly inside the neighbour. The points are
 * c's trilinear map at natural coordinates ±(1 + 1e-6) on the fixed axes and
 * 0 on the free ones; a point outside the mesh (the domain's boundary) has
 * no neighbour. The same probes from a cell find a finer neighbour if one
 * touches the face or edge (the point then lies in one of its leaves, or on
 * a face between two of them: either is as fine).
 *
 * Closure. On a graded mesh, refining a leaf c of level l violates the rule
 * only at coarser neighbours of level l − 1 (its children, level l + 1,
 * would face them two levels apart); those are marked too, and so on from
 * each newly marked cell (a worklist), which stops because levels decrease.
 * Coarsening a family (parent P of level l, every child a leaf) violates it
 * only if a leaf of level ≥ l + 2 touches a child's face or edge from
 * outside P: probed from every child, and such families are skipped. */
#include "mesh/mesh.h"

#include <stdlib.h>
#include <string.h>

/* x = Σ Nₐ(ξ) Xₐ (the trilinear map, also just outside [-1, 1]³). */
static void nh_map_point(const double Xe[24], const double xi[3], double x[3]) {
  double N[8];
  nh_hex_shape(xi, N);
  for (int k = 0; k < 3; k++) {
    x[k] = 0.0;
    for (int a = 0; a < 8; a++) x[k] += N[a] * Xe[3 * a + k];
  }
}

/* The 18 probe points of cell c: 6 face centres, then 12 edge midpoints. */
static void nh_probe_points(const nh_mesh *m, int c, double x[18][3]) {
  double Xe[24];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  const double out = 1.0 + 1e-6;
  int q = 0;
  for (int axis = 0; axis < 3; axis++)
    for (int side = -1; side <= 1; side += 2) {
      double xi[3] = {0, 0, 0};
      xi[axis] = side * out;
      nh_map_point(Xe, xi, x[q++]);
    }
  for (int free_axis = 0; free_axis < 3; free_axis++)
    for (int s = 0; s < 4; s++) {
      double xi[3] = {0, 0, 0};
      int a1 = (free_axis + 1) % 3, a2 = (free_axis + 2) % 3;
      xi[a1] = (s & 1 ? 1 : -1) * out;
      xi[a2] = (s & 2 ? 1 : -1) * out;
      nh_map_point(Xe, xi, x[q++]);
    }
}

int nh_mesh_face_edge_leaves(const nh_mesh *m, int c, int out[18]) {
  double x[18][3], xi[3];
  nh_probe_points(m, c, x);
  int n = 0;
  for (int q = 0; q < 18; q++) {
    int leaf;
    if (nh_mesh_locate(m, x[q], &leaf, xi) != NH_OK || leaf == c) continue;
    int seen = 0;
    for (int i = 0; i < n && !seen; i++) seen = out[i] == leaf;
    if (!seen) out[n++] = leaf;
  }
  return n;
}

static int nh_cmp_int(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

int nh_mesh_grade_marks(const nh_mesh *m, int *marked, int *n_marked) {
  unsigned char *flag = nh_calloc((size_t)(m->n_cells ? m->n_cells : 1), 1);
  int *work = nh_calloc((size_t)(m->n_leaves ? m->n_leaves : 1), sizeof(int));
  if (!flag || !work) {
    free(flag), free(work);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: grading %d leaves", m->n_leaves);
  }
  int n = 0, top = 0;
  for (int i = 0; i < *n_marked; i++)
    if (!flag[marked[i]]) flag[marked[i]] = 1, marked[n++] = marked[i], work[top++] = marked[i];
  while (top > 0) {
    int c = work[--top], nb[18];
    int k = nh_mesh_face_edge_leaves(m, c, nb);
    for (int i = 0; i < k; i++) {
      int d = nb[i];
      if (m->level[d] < m->level[c] && !flag[d]) {
        flag[d] = 1;
        marked[n++] = d;
        work[top++] = d;
      }
    }
  }
  qsort(marked, (size_t)n, sizeof(int), nh_cmp_int);
  *n_marked = n;
  free(flag), free(work);
  return NH_OK;
}

int nh_mesh_coarsen_candidates(const nh_mesh *m, const unsigned char *below, int *parents) {
  int n = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    int ch = m->leaves[l], p = m->parent[ch];
    /* Each family once: from its first child. */
    if (p < 0 || m->first_child[p] != ch) continue;
    int ok = 1;
    for (int k = 0; k < m->n_children[p] && ok; k++) {
      int c = ch + k;
      ok = m->first_child[c] < 0 && below[c];
    }
    for (int k = 0; k < m->n_children[p] && ok; k++) {
      int nb[18], cnt = nh_mesh_face_edge_leaves(m, ch + k, nb);
      for (int i = 0; i < cnt && ok; i++) ok = m->level[nb[i]] <= m->level[p] + 1;
    }
    if (ok) parents[n++] = p;
  }
  return n;
}
