/* refine.c — template refinement of leaves (the seed's §2.3, Eq. 17).
 *
 * A marked leaf is replaced by the children of the run's template. The rest
 * position of template node j is Xⱼ = Σₐ Nₐ(ξⱼ) Xₐ over the parent's eight
 * corners (Eq. 17; the same map carries current positions, velocities and
 * any nodal field, which sim does with `nh_refine_info`). The parent stays in
 * the cell array as an inactive cell, so the hierarchy (level, parent,
 * children) is kept. A child's fill fraction is its parent's on a box domain
 * (1); on an immersed domain it is measured again by sampling the shape
 * (nh_domain_cell_fill), floored at NH_FILL_MIN: a child outside the shape
 * stays, with the floor, since cells are never deleted.
 *
 * Nodes are never duplicated: a template node may coincide with a corner of
 * the parent, with a node of a neighbour refined earlier, or with a node of a
 * sibling created a moment before. Every node is looked up in a spatial hash
 * of rest positions before it is created: positions are quantised on a grid
 * ten times finer than the tolerance, and the 27 neighbouring buckets are
 * searched, so two computations of the same point that differ by round-off
 * (they come from different parents) can never miss each other. The
 * tolerance is 1e-6 of the smallest child edge created. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  int64_t *key; /* 3 per slot */
  int *node;    /* -1: empty */
  int size;
  double quantum, tol;
  const nh_mesh *mesh;
} nh_node_hash;

static uint64_t nh_key_hash(const int64_t k[3]) {
  uint64_t h =
      (uint64_t)k[0] * 73856093ull ^ (uint64_t)k[1] * 19349663ull ^ (uint64_t)k[2] * 83492791ull;
  return h ^ (h >> 29);
}

static void nh_quantise(const nh_node_hash *h, const double x[3], int64_t k[3]) {
  for (int i = 0; i < 3; i++) k[i] = (int64_t)floor(x[i] / h->quantum);
}

static void nh_hash_put(nh_node_hash *h, const double x[3], int node) {
  int64_t k[3];
  nh_quantise(h, x, k);
  int slot = (int)(nh_key_hash(k) % (uint64_t)h->size);
  while (h->node[slot] >= 0) slot = (slot + 1) % h->size;
  memcpy(h->key + 3 * slot, k, sizeof k);
  h->node[slot] = node;
}

/* The node within tol of x, or -1. */
static int nh_hash_find(const nh_node_hash *h, const double x[3]) {
  int64_t k0[3];
  nh_quantise(h, x, k0);
  for (int d = 0; d < 27; d++) {
    int64_t k[3] = {k0[0] + d % 3 - 1, k0[1] + (d / 3) % 3 - 1, k0[2] + d / 9 - 1};
    int slot = (int)(nh_key_hash(k) % (uint64_t)h->size);
    while (h->node[slot] >= 0) {
      const int64_t *s = h->key + 3 * slot;
      if (s[0] == k[0] && s[1] == k[1] && s[2] == k[2]) {
        const double *y = h->mesh->X + 3 * h->node[slot];
        if (fabs(y[0] - x[0]) <= h->tol && fabs(y[1] - x[1]) <= h->tol &&
            fabs(y[2] - x[2]) <= h->tol)
          return h->node[slot];
      }
      slot = (slot + 1) % h->size;
    }
  }
  return -1;
}

int nh_mesh_node_leaves(const nh_mesh *m, int **start_out, int **leaf_out) {
  const int nn = m->n_nodes, nl = m->n_leaves;
  int *start = nh_calloc((size_t)nn + 1, sizeof(int));
  int *leaf = nh_calloc(8 * (size_t)(nl > 0 ? nl : 1), sizeof(int));
  int *fill = nh_calloc((size_t)(nn > 0 ? nn : 1), sizeof(int));
  if (!start || !leaf || !fill) {
    free(start), free(leaf), free(fill);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: node-to-leaf adjacency");
  }
  for (int l = 0; l < nl; l++)
    for (int a = 0; a < 8; a++) start[m->cells[8 * m->leaves[l] + a] + 1]++;
  for (int i = 0; i < nn; i++) start[i + 1] += start[i];
  memcpy(fill, start, sizeof(int) * (size_t)nn);
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    for (int a = 0; a < 8; a++) {
      int v = m->cells[8 * c + a];
      /* A degenerate cell may list a node twice: keep it once. */
      if (fill[v] > start[v] && leaf[fill[v] - 1] == c) continue;
      leaf[fill[v]++] = c;
    }
  }
  /* Close the gaps left by duplicates (start[v + 1] is the capacity). */
  int w = 0;
  for (int v = 0; v < nn; v++) {
    int b = start[v], e = fill[v];
    start[v] = w;
    for (int i = b; i < e; i++) leaf[w++] = leaf[i];
  }
  start[nn] = w;
  free(fill);
  *start_out = start, *leaf_out = leaf;
  return NH_OK;
}

double nh_mesh_cell_size(const nh_mesh *m, int c) {
  double size = INFINITY;
  for (int e = 0; e < 12; e++) {
    const double *a = m->X + 3 * m->cells[8 * c + nh_hex_edge[e][0]];
    const double *b = m->X + 3 * m->cells[8 * c + nh_hex_edge[e][1]];
    size = fmin(size, sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                           (a[2] - b[2]) * (a[2] - b[2])));
  }
  return size;
}

void nh_refine_info_free(nh_refine_info *info) {
  if (!info) return;
  free(info->parent);
  free(info->xi);
  memset(info, 0, sizeof *info);
}

/* Make room for `need` cells in every per-cell array. */
static int nh_grow_cells(nh_mesh *m, int need) {
  if (need <= m->cap_cells) return NH_OK;
  int cap = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->cells, &cap, need, 8 * sizeof(int)));
  int c2 = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->level, &c2, need, sizeof(int)));
  c2 = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->parent, &c2, need, sizeof(int)));
  c2 = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->first_child, &c2, need, sizeof(int)));
  c2 = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->n_children, &c2, need, sizeof(int)));
  c2 = m->cap_cells;
  NH_TRY(nh_grow((void **)&m->fill, &c2, need, sizeof(double)));
  m->cap_cells = cap;
  return NH_OK;
}

int nh_mesh_refine(nh_mesh *m, const nh_template *t, const int *cells, int n,
                   nh_refine_info *info) {
  if (info) {
    nh_refine_info_free(info);
    info->first_new = m->n_nodes;
  }
  if (n == 0) return NH_OK;
  /* Tolerance: 1e-6 of the smallest child edge (template spacing x cell size). */
  double min_gap = 2.0;
  for (int a = 0; a < t->n_nodes; a++)
    for (int b = a + 1; b < t->n_nodes; b++) {
      double d =
          fmax(fabs(t->xi[3 * a] - t->xi[3 * b]), fmax(fabs(t->xi[3 * a + 1] - t->xi[3 * b + 1]),
                                                       fabs(t->xi[3 * a + 2] - t->xi[3 * b + 2])));
      min_gap = fmin(min_gap, d);
    }
  double min_size = INFINITY;
  for (int i = 0; i < n; i++) {
    int c = cells[i];
    if (c < 0 || c >= m->n_cells || m->first_child[c] >= 0)
      return NH_ERROR(NH_ERR_INTERNAL, "cell %d cannot be refined: it is not a leaf", c);
    min_size = fmin(min_size, nh_mesh_cell_size(m, c));
  }
  nh_node_hash h = {.mesh = m};
  h.tol = 1e-6 * 0.5 * min_gap * min_size;
  h.quantum = 10 * h.tol;
  int max_nodes = m->n_nodes + n * t->n_nodes;
  h.size = 2 * max_nodes + 1;
  h.key = nh_calloc(3 * (size_t)h.size, sizeof(int64_t));
  h.node = nh_calloc((size_t)h.size, sizeof(int));
  int *map = nh_calloc((size_t)t->n_nodes, sizeof(int));
  int rc = NH_OK;
  if (!h.key || !h.node || !map) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory refining %d cells", n);
    goto done;
  }
  for (int i = 0; i < h.size; i++) h.node[i] = -1;
  for (int i = 0; i < m->n_nodes; i++) nh_hash_put(&h, m->X + 3 * i, i);
  if ((rc = nh_grow((void **)&m->X, &m->cap_nodes, max_nodes, 3 * sizeof(double))) ||
      (rc = nh_grow_cells(m, m->n_cells + n * t->n_children)))
    goto done;
  if (info) {
    info->parent = nh_calloc((size_t)(n * t->n_nodes), sizeof(int));
    info->xi = nh_calloc(3 * (size_t)(n * t->n_nodes), sizeof(double));
    if (!info->parent || !info->xi) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory refining %d cells", n);
      goto done;
    }
  }
  for (int i = 0; i < n; i++) {
    int c = cells[i];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int j = 0; j < t->n_nodes; j++) {
      double N[8], X[3] = {0, 0, 0};
      nh_hex_shape(t->xi + 3 * j, N);
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) X[k] += N[a] * Xe[3 * a + k];
      int node = nh_hash_find(&h, X);
      if (node < 0) {
        node = m->n_nodes++;
        memcpy(m->X + 3 * node, X, sizeof X);
        nh_hash_put(&h, X, node);
        if (info) {
          info->parent[info->n_new] = c;
          memcpy(info->xi + 3 * info->n_new, t->xi + 3 * j, 3 * sizeof(double));
          info->n_new++;
        }
      }
      map[j] = node;
    }
    m->first_child[c] = m->n_cells;
    m->n_children[c] = t->n_children;
    for (int k = 0; k < t->n_children; k++) {
      int ch = m->n_cells++;
      for (int a = 0; a < 8; a++) m->cells[8 * ch + a] = map[t->children[8 * k + a]];
      m->level[ch] = m->level[c] + 1;
      m->parent[ch] = c;
      m->first_child[ch] = -1;
      m->n_children[ch] = 0;
      m->fill[ch] = m->fill[c];
      if (m->domain.kind != NH_DOMAIN_BOX) { /* the child's own share of the shape */
        double Xc[24];
        nh_mesh_cell_coords(m, m->X, ch, Xc);
        m->fill[ch] = fmax(nh_domain_cell_fill(&m->domain, Xc, NULL), NH_FILL_MIN);
      }
    }
  }
  rc = nh_mesh_update_leaves(m);
done:
  free(h.key);
  free(h.node);
  free(map);
  return rc;
}
