/* system.c — DOF map, sparsity pattern and cell colouring for the
 * assembly of A = cM M + cK K (the assembly itself: assemble.c).
 *
 * Fixed DOFs are eliminated: the unknowns are the free DOFs, numbered in node
 * order so that each column's rows come out sorted. Hanging nodes, when
 * given, are eliminated too: u = P u_free with P the interpolation of their
 * masters (mesh/hanging.c), and A = Pᵀ Aₑ P is assembled leaf by leaf:
 * a leaf with a hanging corner contributes Tᵀ Aₑ T, T mapping its corners to
 * its effective (master) nodes. The lumped mass enters Aₑ as a diagonal, so
 * PᵀMP couples the masters of a hanging node as it must. The pattern is the upper
 * triangle (CHOLMOD stype = +1) of the node graph (two nodes are coupled when
 * they share a leaf). Each leaf stores where the entries of its matrix go
 * that A stores (the upper triangle's, of free DOFs: about half), as pairs
 * (entry, position) found once per pattern by binary search, so assembly is
 * a straight scatter without tests.
 *
 * Parallel assembly without races (assemble.c): leaves are coloured greedily so that no
 * two leaves of one colour share a node; colours run one after the other,
 * the leaves of a colour in parallel. Leaves with a hanging corner share
 * masters with many others (every fine leaf on a coarse face couples that
 * face's corners), so they form one last group whose results are computed in
 * parallel and added serially, in leaf order. Every entry then receives its
 * contributions in colour order whatever the thread count, so the serial and
 * the parallel result are bitwise equal. */
#include "solve/system_impl.h"

#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int nh_system_free_dofs(const nh_system *s) {
  return s->n_free;
}

int nh_system_colours(const nh_system *s) {
  return s->n_colours;
}

void nh_system_destroy(nh_system **sys) {
  if (!sys || !*sys) return;
  nh_system *s = *sys;
  cholmod_free_sparse(&s->A, &s->cm);
  cholmod_free_sparse(&s->Jt, &s->cm);
  free(s->W);
  free(s->lambda_total);
  cholmod_free_factor(&s->L, &s->cm);
  cholmod_free_factor(&s->L_aside, &s->cm);
  nh_inherit_free(s);
  for (int i = 0; i < 4; i++) free(s->pcg[i]);
  cholmod_free_dense(&s->B, &s->cm);
  cholmod_free_dense(&s->X, &s->cm);
  cholmod_free_dense(&s->Y, &s->cm);
  cholmod_free_dense(&s->E, &s->cm);
  cholmod_finish(&s->cm);
  free(s->free_of);
  free(s->dof_of);
  free(s->exp_start);
  free(s->exp_node);
  free(s->exp_w);
  free(s->eff_start);
  free(s->eff_node);
  free(s->nz_start), free(s->nz_corner), free(s->nz_node), free(s->nz_first), free(s->nz_w);
  free(s->pair_start);
  free(s->pair);
  free(s->colour_start);
  free(s->colour_leaf);
  free(s->frame);
  free(s->frame_new);
  free(s->skew);
  free(s->updated);
  free(s->group);
  free(s->expand);
  free(s->last_u), free(s->last_v), free(s->last_f), free(s->last_kv);
  free(s->w0), free(s->w0_key);
  for (int i = 0; i < 4; i++) free(s->work[i]);
  for (int i = 0; i < 2; i++) free(s->fwork[i]);
  free(s->u_assembled), free(s->u_factored);
  free(s);
  *sys = NULL;
}

/* The nodes leaf l couples: its effective nodes if it has a hanging corner
 * (eff_start[l] < eff_start[l + 1]), else its 8 corners. */
static int nh_leaf_nodes(const nh_system *s, int l, const int **nodes) {
  int n_eff = s->eff_start[l + 1] - s->eff_start[l];
  if (n_eff > 0) {
    *nodes = s->eff_node + s->eff_start[l];
    return n_eff;
  }
  *nodes = s->tissue->mesh->cells + 8 * s->tissue->mesh->leaves[l];
  return 8;
}

/* Position of entry (row, col), row <= col, in the CSC upper triangle. */
static int nh_find_entry(const int *Ap, const int *Ai, int row, int col) {
  int lo = Ap[col], hi = Ap[col + 1] - 1;
  while (lo < hi) { /* rows of a column are sorted */
    int mid = (lo + hi) / 2;
    if (Ai[mid] < row)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}

/* Node adjacency (CSR, each list sorted, self included). */
static int nh_node_graph(const nh_system *s, int **ptr_out, int **adj_out) {
  const nh_mesh *m = s->tissue->mesh;
  int n = m->n_nodes;
  int *count = nh_calloc((size_t)n + 1, sizeof(int));
  if (!count) return NH_ERROR(NH_ERR_MEMORY, "out of memory: node graph");
  for (int l = 0; l < m->n_leaves; l++) {
    const int *nodes;
    int k = nh_leaf_nodes(s, l, &nodes);
    for (int a = 0; a < k; a++) count[nodes[a] + 1] += k;
  }
  for (int i = 0; i < n; i++) count[i + 1] += count[i];
  int *adj = nh_calloc((size_t)(count[n] ? count[n] : 1), sizeof(int));
  int *fill = nh_calloc((size_t)(n ? n : 1), sizeof(int));
  if (!adj || !fill) {
    free(count), free(adj), free(fill);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: node graph");
  }
  memcpy(fill, count, sizeof(int) * (size_t)n);
  for (int l = 0; l < m->n_leaves; l++) {
    const int *e;
    int k = nh_leaf_nodes(s, l, &e);
    for (int a = 0; a < k; a++)
      for (int b = 0; b < k; b++) adj[fill[e[a]]++] = e[b];
  }
  /* Deduplicate each list (fill now marks the nodes listed for node i),
   * compact it in place and sort it: a few dozen nodes, by insertion. */
  for (int i = 0; i < n; i++) fill[i] = -1;
  int out = 0;
  for (int i = 0; i < n; i++) {
    int lo = count[i], hi = count[i + 1], first = out;
    count[i] = out;
    for (int k = lo; k < hi; k++) {
      int v = adj[k];
      if (fill[v] == i) continue;
      fill[v] = i;
      int p = out++;
      for (; p > first && adj[p - 1] > v; p--) adj[p] = adj[p - 1];
      adj[p] = v;
    }
  }
  count[n] = out;
  free(fill);
  *ptr_out = count;
  *adj_out = adj;
  return NH_OK;
}

/* Greedy colouring of the plain leaves: colour = lowest not used by a leaf
 * sharing a node. Leaves with a hanging corner go to a last group, added
 * serially (assemble.c). */
static int nh_colour_leaves(nh_system *s) {
  const nh_mesh *m = s->tissue->mesh;
  uint64_t *used = nh_calloc((size_t)m->n_nodes, sizeof(uint64_t));
  int *colour = nh_calloc((size_t)(m->n_leaves ? m->n_leaves : 1), sizeof(int));
  if (!used || !colour) {
    free(used), free(colour);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: colouring");
  }
  int n_colours = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    colour[l] = -1;
    if (s->eff_start[l + 1] > s->eff_start[l]) continue;
    const int *e = m->cells + 8 * m->leaves[l];
    uint64_t mask = 0;
    for (int a = 0; a < 8; a++) mask |= used[e[a]];
    int c = 0;
    while (c < 64 && (mask >> c & 1u)) c++;
    if (c == 64) {
      free(used), free(colour);
      return NH_ERROR(NH_ERR_INTERNAL, "cell colouring needs more than 64 colours");
    }
    colour[l] = c;
    for (int a = 0; a < 8; a++) used[e[a]] |= (uint64_t)1 << c;
    if (c + 1 > n_colours) n_colours = c + 1;
  }
  for (int l = 0; l < m->n_leaves; l++)
    if (colour[l] < 0) colour[l] = n_colours; /* the serial group */
  s->n_colours = n_colours;
  s->colour_start = nh_calloc((size_t)n_colours + 2, sizeof(int));
  s->colour_leaf = nh_calloc((size_t)(m->n_leaves ? m->n_leaves : 1), sizeof(int));
  if (!s->colour_start || !s->colour_leaf) {
    free(used), free(colour);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: colouring");
  }
  for (int l = 0; l < m->n_leaves; l++) s->colour_start[colour[l] + 1]++;
  for (int c = 0; c <= n_colours; c++) s->colour_start[c + 1] += s->colour_start[c];
  int next[65];
  for (int c = 0; c <= n_colours; c++) next[c] = s->colour_start[c];
  for (int l = 0; l < m->n_leaves; l++) s->colour_leaf[next[colour[l]]++] = l;
  free(used);
  free(colour);
  return NH_OK;
}

static int nh_system_pattern(nh_system *s) {
  const nh_mesh *m = s->tissue->mesh;
  int *ptr = NULL, *adj = NULL;
  NH_TRY(nh_node_graph(s, &ptr, &adj));
  /* Count entries per column. */
  size_t nnz = 0;
  for (int col = 0; col < s->n_free; col++) {
    int node = s->dof_of[col] / 3;
    for (int k = ptr[node]; k < ptr[node + 1]; k++)
      for (int i = 0; i < 3; i++) {
        int r = s->free_of[3 * adj[k] + i];
        if (r >= 0 && r <= col) nnz++;
      }
  }
  if (nnz > INT32_MAX) {
    free(ptr), free(adj);
    return NH_ERROR(NH_ERR_MEMORY, "matrix too large: %zu entries", nnz);
  }
  s->A = cholmod_allocate_sparse((size_t)s->n_free, (size_t)s->n_free, nnz, 1, 1, 1, CHOLMOD_REAL,
                                 &s->cm);
  if (!s->A) {
    free(ptr), free(adj);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: matrix with %zu entries", nnz);
  }
  int *Ap = s->A->p, *Ai = s->A->i;
  int pos = 0;
  for (int col = 0; col < s->n_free; col++) {
    Ap[col] = pos;
    int node = s->dof_of[col] / 3;
    for (int k = ptr[node]; k < ptr[node + 1]; k++)
      for (int i = 0; i < 3; i++) {
        int r = s->free_of[3 * adj[k] + i];
        if (r >= 0 && r <= col) {
          Ai[pos++] = r;
        }
      }
  }
  Ap[s->n_free] = pos;
  free(ptr);
  free(adj);

  /* Maps: of a leaf's 576 entries (plain) or (3 n_eff)² (the others) those
   * A stores, with their positions. */
  const size_t nl = (size_t)m->n_leaves;
  int kmax = 8;
  for (int l = 0; l < m->n_leaves; l++)
    if (s->eff_start[l + 1] - s->eff_start[l] > kmax) kmax = s->eff_start[l + 1] - s->eff_start[l];
  int *map = nh_calloc(9 * (size_t)kmax * kmax, sizeof(int)), cap = 0;
  s->pair_start = nh_calloc(nl + 1, sizeof(size_t));
  s->pair = NULL;
  if (!map || !s->pair_start) {
    free(map);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: scatter maps");
  }
  size_t used = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    const int *e;
    int k = nh_leaf_nodes(s, l, &e), nd = 3 * k, n = 0;
    /* A node's free DOFs are consecutive numbers and a column holds all of
     * them that do not exceed it, consecutively: one search per node and
     * column, the node's first free DOF, places the others. */
    for (int c = 0; c < nd; c++) {
      const int fc = s->free_of[3 * e[c / 3] + c % 3];
      for (int a = 0; a < k; a++) {
        const int *fa = s->free_of + 3 * e[a];
        int f0 = fa[0] >= 0 ? fa[0] : fa[1] >= 0 ? fa[1] : fa[2];
        int p0 = fc >= 0 && f0 >= 0 && f0 <= fc ? nh_find_entry(Ap, Ai, f0, fc) : -1;
        for (int i = 0; i < 3; i++) {
          int fr = fa[i], r = 3 * a + i;
          map[nd * r + c] = (p0 < 0 || fr < 0 || fr > fc) ? -1 : p0 + (fr - f0);
          n += map[nd * r + c] >= 0;
        }
      }
    }
    if (used + (size_t)n > (size_t)INT_MAX / 2 ||
        nh_grow((void **)&s->pair, &cap, 2 * (int)(used + (size_t)n), sizeof(int))) {
      free(map);
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: scatter maps");
    }
    s->pair_start[l] = used;
    for (int r = 0; r < nd * nd; r++)
      if (map[r] >= 0) s->pair[2 * used] = r, s->pair[2 * used + 1] = map[r], used++;
  }
  s->pair_start[nl] = used;
  free(map);
  return NH_OK;
}

/* P node by node (exp_*), and the effective nodes and T of leaves with a
 * hanging corner (eff_*). */
/* Node v has a free component (a node fixed in some axes only keeps the others). */
static int nh_node_free(const nh_system *s, int v) {
  const int *f = s->free_of + 3 * v;
  return f[0] >= 0 || f[1] >= 0 || f[2] >= 0;
}

static int nh_system_prolongation(nh_system *s, const unsigned char *fixed, const nh_hanging *h) {
  const nh_mesh *m = s->tissue->mesh;
  int n = m->n_nodes, total = 0;
  for (int v = 0; v < n; v++) {
    int k = h && h->n_hanging ? h->index[v] : -1;
    total += k >= 0 ? h->start[k + 1] - h->start[k] : 1;
  }
  s->exp_start = nh_calloc(((size_t)n + 1), sizeof(int));
  s->exp_node = nh_calloc((size_t)(total ? total : 1), sizeof(int));
  s->exp_w = nh_calloc((size_t)(total ? total : 1), sizeof(double));
  s->eff_start = nh_calloc((size_t)m->n_leaves + 1, sizeof(int));
  if (!s->exp_start || !s->exp_node || !s->exp_w || !s->eff_start)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: hanging-node elimination");
  int p = 0;
  for (int v = 0; v < n; v++) {
    s->exp_start[v] = p;
    int k = h && h->n_hanging ? h->index[v] : -1;
    if (k >= 0) {
      for (int q = h->start[k]; q < h->start[k + 1]; q++)
        if (nh_node_free(s, h->master[q]))
          s->exp_node[p] = h->master[q], s->exp_w[p++] = h->weight[q];
    } else if (nh_node_free(s, v)) {
      s->exp_node[p] = v, s->exp_w[p++] = 1.0;
    }
  }
  s->exp_start[n] = p;
  (void)fixed;
  /* Effective nodes of leaves with a hanging corner: union of the corners'
   * expansions, in ascending order (as their free DOFs: A's upper triangle
   * is then Ã's, which is all assemble.c computes); then T's nonzeros
   * (nz_*), corner by corner, node by node. */
  int cap = 0, used = 0, n_nz = 0, cap_corner = 0, cap_node = 0, cap_first = 0, cap_w = 0;
  s->eff_node = NULL;
  s->nz_start = nh_calloc((size_t)m->n_leaves + 1, sizeof(int));
  if (!s->nz_start) return NH_ERROR(NH_ERR_MEMORY, "out of memory: hanging-node elimination");
  double *T = NULL; /* T[a k + p] of one leaf */
  int *seen = NULL, capT = 0, cap_seen = 0, rc = NH_OK;
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    const int *e = m->cells + 8 * m->leaves[l];
    s->eff_start[l] = used;
    s->nz_start[l] = n_nz;
    int any = 0;
    for (int a = 0; a < 8; a++) any |= h && h->n_hanging && h->index[e[a]] >= 0;
    if (!any) continue;
    int start = used;
    for (int a = 0; a < 8 && !rc; a++)
      for (int q = s->exp_start[e[a]]; q < s->exp_start[e[a] + 1] && !rc; q++) {
        int v = s->exp_node[q], found = 0;
        for (int r = start; r < used && !found; r++) found = s->eff_node[r] == v;
        if (found) continue;
        if ((rc = nh_grow((void **)&s->eff_node, &cap, used + 1, sizeof(int)))) break;
        int r = used++; /* insertion in ascending order */
        for (; r > start && s->eff_node[r - 1] > v; r--) s->eff_node[r] = s->eff_node[r - 1];
        s->eff_node[r] = v;
      }
    int k = used - start;
    if (rc || (rc = nh_grow((void **)&T, &capT, 8 * k, sizeof(double))) ||
        (rc = nh_grow((void **)&seen, &cap_seen, k, sizeof(int))))
      break;
    for (int i = 0; i < 8 * k; i++) T[i] = 0.0;
    for (int a = 0; a < 8; a++)
      for (int q = s->exp_start[e[a]]; q < s->exp_start[e[a] + 1]; q++)
        for (int r = 0; r < k; r++)
          if (s->eff_node[start + r] == s->exp_node[q]) T[a * k + r] += s->exp_w[q];
    /* at most 8 k nonzeros */
    const int need = n_nz + 8 * k;
    if ((rc = nh_grow((void **)&s->nz_corner, &cap_corner, need, sizeof(int))) ||
        (rc = nh_grow((void **)&s->nz_node, &cap_node, need, sizeof(int))) ||
        (rc = nh_grow((void **)&s->nz_first, &cap_first, need, sizeof(int))) ||
        (rc = nh_grow((void **)&s->nz_w, &cap_w, need, sizeof(double))))
      break;
    for (int r = 0; r < k; r++) seen[r] = 0;
    for (int a = 0; a < 8; a++)
      for (int r = 0; r < k; r++) {
        if (T[a * k + r] == 0.0) continue;
        s->nz_corner[n_nz] = a, s->nz_node[n_nz] = r, s->nz_w[n_nz] = T[a * k + r];
        s->nz_first[n_nz++] = !seen[r], seen[r] = 1;
      }
  }
  free(T), free(seen);
  if (rc) return rc;
  s->eff_start[m->n_leaves] = used;
  s->nz_start[m->n_leaves] = n_nz;
  return NH_OK;
}

int nh_system_create(const nh_tissue *tissue, const unsigned char *fixed, const nh_hanging *hanging,
                     nh_system **out) {
  *out = NULL;
  const nh_mesh *m = tissue->mesh;
  nh_system *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  cholmod_start(&s->cm);
  s->cm.print = 0;
  s->cm.error_handler = NULL;
  s->tissue = tissue;
  s->n_nodes = m->n_nodes;
  int rc = NH_OK;
  s->free_of = nh_calloc(3 * (size_t)m->n_nodes, sizeof(int));
  s->dof_of = nh_calloc(3 * (size_t)m->n_nodes, sizeof(int));
  for (int i = 0; i < 4; i++) s->work[i] = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  for (int i = 0; i < 2; i++) s->fwork[i] = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  for (int i = 0; i < 4; i++) s->pcg[i] = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  s->u_assembled = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  s->u_factored = nh_calloc(3 * (size_t)m->n_nodes, sizeof(double));
  if (!s->free_of || !s->dof_of || !s->work[3] || !s->work[0] || !s->work[1] || !s->work[2] ||
      !s->fwork[0] || !s->fwork[1] || !s->pcg[0] || !s->pcg[1] || !s->pcg[2] || !s->pcg[3] ||
      !s->u_assembled || !s->u_factored) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: DOF map");
    goto fail;
  }
  /* A node that no leaf uses has no stiffness and no mass: treat it as fixed. */
  unsigned char *used = nh_calloc((size_t)m->n_nodes, 1);
  if (!used) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: DOF map");
    goto fail;
  }
  for (int l = 0; l < m->n_leaves; l++)
    for (int a = 0; a < 8; a++) used[m->cells[8 * m->leaves[l] + a]] = 1;
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) {
      int hang = hanging && hanging->n_hanging && hanging->index[i] >= 0;
      if (used[i] && !nh_fixed_component(fixed, i, k) && !hang) {
        s->dof_of[s->n_free] = 3 * i + k;
        s->free_of[3 * i + k] = s->n_free++;
      } else {
        s->free_of[3 * i + k] = -1;
      }
    }
  free(used);
  if (s->n_free == 0) {
    rc = NH_ERROR(NH_ERR_INPUT, "every degree of freedom is fixed: nothing to solve");
    goto fail;
  }
  if ((rc = nh_system_prolongation(s, fixed, hanging)) || (rc = nh_system_pattern(s)) ||
      (rc = nh_colour_leaves(s)))
    goto fail;
  size_t nl = m->n_leaves ? (size_t)m->n_leaves : 1;
  s->frame = nh_calloc(NH_HEX_FRAME * nl, sizeof(double));
  s->frame_new = nh_calloc(NH_HEX_FRAME * nl, sizeof(double));
  s->updated = nh_calloc(nl, 1);
  if (!s->frame || !s->frame_new || !s->updated) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: element frames");
    goto fail;
  }
  *out = s;
  return NH_OK;
fail:
  nh_system_destroy(&s);
  return rc;
}

void nh_system_apply(const nh_system *s, const double *x, double *y) {
  const int *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x;
  memset(y, 0, sizeof(double) * (size_t)s->n_free);
  /* Column j holds rows i <= j, sorted, the diagonal last: y[j] receives
   * column j's off-diagonal terms, then its diagonal, and only later columns'
   * terms after that. So the off-diagonal sum runs in a register, in the same
   * order as through memory (the same bits, without a load and a store of
   * y[j] per entry, which the compiler cannot drop: y[i] may be y[j]). */
  for (int j = 0; j < s->n_free; j++) {
    const double xj = x[j];
    double yj = y[j];
    int p = Ap[j], end = Ap[j + 1];
    if (p < end && Ai[end - 1] == j) end--; /* the diagonal, added below */
    for (; p < end; p++) {
      int i = Ai[p];
      y[i] += Ax[p] * xj;
      yj += Ax[p] * x[i];
    }
    y[j] = yj;
    if (end < Ap[j + 1]) y[j] += Ax[end] * xj;
  }
}

void nh_system_gather(const nh_system *s, const double *full, double *part) {
  memset(part, 0, sizeof(double) * (size_t)s->n_free);
  for (int v = 0; v < s->n_nodes; v++)
    for (int q = s->exp_start[v]; q < s->exp_start[v + 1]; q++) {
      const int *f = s->free_of + 3 * s->exp_node[q];
      for (int i = 0; i < 3; i++)
        if (f[i] >= 0) part[f[i]] += s->exp_w[q] * full[3 * v + i];
    }
}

void nh_system_scatter(const nh_system *s, const double *part, double *full) {
  for (int v = 0; v < s->n_nodes; v++) {
    double x[3] = {0, 0, 0};
    for (int q = s->exp_start[v]; q < s->exp_start[v + 1]; q++) {
      const int *f = s->free_of + 3 * s->exp_node[q];
      for (int i = 0; i < 3; i++)
        if (f[i] >= 0) x[i] += s->exp_w[q] * part[f[i]];
    }
    for (int i = 0; i < 3; i++) full[3 * v + i] = x[i];
  }
}
