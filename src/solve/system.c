/* system.c — DOF map, sparsity pattern, cell colouring and parallel
 * assembly of A = cM M + cK K.
 *
 * Fixed DOFs are eliminated: the unknowns are the free DOFs, numbered in node
 * order so that each column's rows come out sorted. The pattern is the upper
 * triangle (CHOLMOD stype = +1) of the node graph (two nodes are coupled when
 * they share a leaf). Each leaf stores where each entry of its 24x24 matrix
 * goes (576 ints, -1 for the lower triangle and fixed DOFs), computed once
 * per pattern by binary search, so assembly is a straight scatter.
 *
 * Parallel assembly without races: leaves are coloured greedily so that no
 * two leaves of one colour share a node; colours run one after the other,
 * the leaves of a colour in parallel. Every entry then receives its
 * contributions in colour order whatever the thread count, so the serial and
 * the parallel result are bitwise equal. */
#include "solve/system_impl.h"

#include <math.h>
#include <omp.h>
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
  cholmod_free_factor(&s->L, &s->cm);
  cholmod_free_dense(&s->B, &s->cm);
  cholmod_free_dense(&s->X, &s->cm);
  cholmod_free_dense(&s->Y, &s->cm);
  cholmod_free_dense(&s->E, &s->cm);
  cholmod_finish(&s->cm);
  free(s->free_of);
  free(s->dof_of);
  free(s->diag);
  free(s->scatter);
  free(s->colour_start);
  free(s->colour_leaf);
  for (int i = 0; i < 4; i++) free(s->work[i]);
  for (int i = 0; i < 2; i++) free(s->fwork[i]);
  free(s);
  *sys = NULL;
}

static int nh_int_cmp(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

/* Node adjacency (CSR, each list sorted, self included). */
static int nh_node_graph(const nh_mesh *m, int **ptr_out, int **adj_out) {
  int n = m->n_nodes;
  int *count = calloc((size_t)n + 1, sizeof(int));
  if (!count) return NH_ERROR(NH_ERR_MEMORY, "out of memory: node graph");
  for (int l = 0; l < m->n_leaves; l++)
    for (int a = 0; a < 8; a++) count[m->cells[8 * m->leaves[l] + a] + 1] += 8;
  for (int i = 0; i < n; i++) count[i + 1] += count[i];
  int *adj = malloc(sizeof(int) * (size_t)(count[n] ? count[n] : 1));
  int *fill = malloc(sizeof(int) * (size_t)(n ? n : 1));
  if (!adj || !fill) {
    free(count), free(adj), free(fill);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: node graph");
  }
  memcpy(fill, count, sizeof(int) * (size_t)n);
  for (int l = 0; l < m->n_leaves; l++) {
    const int *e = m->cells + 8 * m->leaves[l];
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++) adj[fill[e[a]]++] = e[b];
  }
  /* Sort and deduplicate each list in place, then compact. */
  int out = 0;
  for (int i = 0; i < n; i++) {
    int lo = count[i], hi = count[i + 1];
    qsort(adj + lo, (size_t)(hi - lo), sizeof(int), nh_int_cmp);
    count[i] = out;
    for (int k = lo; k < hi; k++)
      if (k == lo || adj[k] != adj[k - 1]) adj[out++] = adj[k];
  }
  count[n] = out;
  free(fill);
  *ptr_out = count;
  *adj_out = adj;
  return NH_OK;
}

/* Greedy colouring: colour = lowest not used by a leaf sharing a node. */
static int nh_colour_leaves(nh_system *s) {
  const nh_mesh *m = s->tissue->mesh;
  uint64_t *used = calloc((size_t)m->n_nodes, sizeof(uint64_t));
  int *colour = malloc(sizeof(int) * (size_t)(m->n_leaves ? m->n_leaves : 1));
  if (!used || !colour) {
    free(used), free(colour);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: colouring");
  }
  int n_colours = 0;
  for (int l = 0; l < m->n_leaves; l++) {
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
  s->n_colours = n_colours;
  s->colour_start = calloc((size_t)n_colours + 1, sizeof(int));
  s->colour_leaf = malloc(sizeof(int) * (size_t)(m->n_leaves ? m->n_leaves : 1));
  if (!s->colour_start || !s->colour_leaf) {
    free(used), free(colour);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: colouring");
  }
  for (int l = 0; l < m->n_leaves; l++) s->colour_start[colour[l] + 1]++;
  for (int c = 0; c < n_colours; c++) s->colour_start[c + 1] += s->colour_start[c];
  int next[64];
  for (int c = 0; c < n_colours; c++) next[c] = s->colour_start[c];
  for (int l = 0; l < m->n_leaves; l++) s->colour_leaf[next[colour[l]]++] = l;
  free(used);
  free(colour);
  return NH_OK;
}

static int nh_system_pattern(nh_system *s) {
  const nh_mesh *m = s->tissue->mesh;
  int *ptr = NULL, *adj = NULL;
  NH_TRY(nh_node_graph(m, &ptr, &adj));
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
  s->diag = malloc(sizeof(int) * (size_t)s->n_free);
  if (!s->A || !s->diag) {
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
          if (r == col) s->diag[col] = pos;
          Ai[pos++] = r;
        }
      }
  }
  Ap[s->n_free] = pos;
  free(ptr);
  free(adj);

  s->scatter = malloc(sizeof(int) * 576 * (size_t)(m->n_leaves ? m->n_leaves : 1));
  if (!s->scatter) return NH_ERROR(NH_ERR_MEMORY, "out of memory: scatter maps");
  for (int l = 0; l < m->n_leaves; l++) {
    const int *e = m->cells + 8 * m->leaves[l];
    int *map = s->scatter + 576 * (size_t)l;
    for (int r = 0; r < 24; r++)
      for (int c = 0; c < 24; c++) {
        int fr = s->free_of[3 * e[r / 3] + r % 3], fc = s->free_of[3 * e[c / 3] + c % 3];
        map[24 * r + c] = -1;
        if (fr < 0 || fc < 0 || fr > fc) continue;
        int lo = Ap[fc], hi = Ap[fc + 1] - 1;
        while (lo < hi) { /* rows of a column are sorted */
          int mid = (lo + hi) / 2;
          if (Ai[mid] < fr)
            lo = mid + 1;
          else
            hi = mid;
        }
        map[24 * r + c] = lo;
      }
  }
  return NH_OK;
}

int nh_system_create(const nh_tissue *tissue, const unsigned char *fixed, nh_system **out) {
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
  s->free_of = malloc(sizeof(int) * 3 * (size_t)m->n_nodes);
  s->dof_of = malloc(sizeof(int) * 3 * (size_t)m->n_nodes);
  for (int i = 0; i < 4; i++) s->work[i] = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  for (int i = 0; i < 2; i++) s->fwork[i] = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  if (!s->free_of || !s->dof_of || !s->work[3] || !s->work[0] || !s->work[1] || !s->work[2] ||
      !s->fwork[0] || !s->fwork[1]) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: DOF map");
    goto fail;
  }
  /* A node that no leaf uses has no stiffness and no mass: treat it as fixed. */
  unsigned char *used = calloc((size_t)m->n_nodes, 1);
  if (!used) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: DOF map");
    goto fail;
  }
  for (int l = 0; l < m->n_leaves; l++)
    for (int a = 0; a < 8; a++) used[m->cells[8 * m->leaves[l] + a]] = 1;
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) {
      if (used[i] && !(fixed && fixed[i])) {
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
  if ((rc = nh_system_pattern(s)) || (rc = nh_colour_leaves(s))) goto fail;
  *out = s;
  return NH_OK;
fail:
  nh_system_destroy(&s);
  return rc;
}

void nh_system_assemble(nh_system *s, const double *u, const double *v, double cM, double cK,
                        double *f_int, double *Kv, int threads) {
  const nh_tissue *t = s->tissue;
  const nh_mesh *m = t->mesh;
  double *Ax = s->A->x;
  memset(Ax, 0, sizeof(double) * ((int *)s->A->p)[s->n_free]);
  memset(f_int, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  if (Kv) memset(Kv, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  for (int colour = 0; colour < s->n_colours; colour++) {
    int lo = s->colour_start[colour], hi = s->colour_start[colour + 1];
    /* A parallel region costs tens of µs (far more when cores are shared):
     * only colours of at least 128 cells (≈ 1 ms of element work) are split. */
#pragma omp parallel for num_threads(nt) schedule(static) if (nt > 1 && hi - lo >= 128)
    for (int k = lo; k < hi; k++) {
      int l = s->colour_leaf[k], c = m->leaves[l];
      const int *e = m->cells + 8 * c;
      const int *map = s->scatter + 576 * (size_t)l;
      double f[24], K[576];
      nh_tissue_element(t, c, u, f, K);
      for (int a = 0; a < 8; a++)
        for (int i = 0; i < 3; i++) f_int[3 * e[a] + i] += f[3 * a + i];
      if (Kv) {
        double ve[24];
        nh_mesh_cell_coords(m, v, c, ve);
        for (int r = 0; r < 24; r++) {
          double sum = 0.0;
          for (int q = 0; q < 24; q++) sum += K[24 * r + q] * ve[q];
          Kv[3 * e[r / 3] + r % 3] += sum;
        }
      }
      for (int r = 0; r < 576; r++)
        if (map[r] >= 0) Ax[map[r]] += cK * K[r];
    }
  }
  if (cM != 0.0)
    for (int j = 0; j < s->n_free; j++) Ax[s->diag[j]] += cM * t->mass[s->dof_of[j] / 3];
}

void nh_system_apply(const nh_system *s, const double *x, double *y) {
  const int *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x;
  memset(y, 0, sizeof(double) * (size_t)s->n_free);
  for (int j = 0; j < s->n_free; j++)
    for (int p = Ap[j]; p < Ap[j + 1]; p++) {
      int i = Ai[p];
      y[i] += Ax[p] * x[j];
      if (i != j) y[j] += Ax[p] * x[i];
    }
}

void nh_system_gather(const nh_system *s, const double *full, double *part) {
  for (int j = 0; j < s->n_free; j++) part[j] = full[s->dof_of[j]];
}

void nh_system_scatter(const nh_system *s, const double *part, double *full) {
  for (int j = 0; j < s->n_free; j++) full[s->dof_of[j]] = part[j];
}
