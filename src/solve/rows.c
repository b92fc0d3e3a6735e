/* rows.c — constraint rows (nh_rows, solve.h): the row format the contact
 * module writes, and each row's two parts as the coupled step (coupled.c)
 * uses them (docs/interaction.md "Rows: what a constraint is").
 *
 * Row i reads g_i = n_i · (x_tissue(P_i) − x_tool(s_i)). Its tissue part is
 * n · N_a on the three DOFs of each node a of the point's cell, restricted to
 * the unknowns by Pᵀ (hanging masters, fixed nodes dropped): J_t, kept as
 * J_tᵀ (sparse, n_free x m) for the compliance and the corrections. Its tool
 * part is −n · J_beam on the element's 12 DOFs, the base node's dropped
 * (prescribed): J_k, dense per tool. A row between two tools has a second
 * tool part in place of the tissue's, +n · J_beam of the other tool (side 1,
 * tool2): each side is a column of its own tool's block. */
#include "solve/system_impl.h"

#include <stdlib.h>
#include <string.h>

void nh_rows_clear(nh_rows *r) {
  r->m = 0;
}

void nh_rows_free(nh_rows *r) {
  free(r->start), free(r->node), free(r->N), free(r->dir), free(r->tool), free(r->elem), free(r->J);
  free(r->tool2), free(r->elem2), free(r->J2), free(r->gap), free(r->disc), free(r->law),
      free(r->lambda);
  memset(r, 0, sizeof *r);
}

#define NH_GROW(ptr, count)                                                                        \
  do {                                                                                             \
    if (nh_realloc((void **)&(ptr), (size_t)(count), sizeof *(ptr))) return -1; /* an index: -1 */ \
  } while (0)

/* node and N hold at least `slots` entries */
static int nh_rows_slots(nh_rows *r, int slots) {
  if (slots <= r->n_slots) return 0;
  int cap = r->n_slots ? r->n_slots : 256;
  while (cap < slots) cap *= 2;
  NH_GROW(r->node, cap);
  NH_GROW(r->N, cap);
  r->n_slots = cap;
  return 0;
}

int nh_rows_add(nh_rows *r) {
  if (r->m == r->cap) {
    int cap = r->cap ? 2 * r->cap : 32;
    NH_GROW(r->start, cap + 1);
    if (r->cap == 0) r->start[0] = 0;
    NH_GROW(r->dir, 3 * cap);
    NH_GROW(r->tool, cap);
    NH_GROW(r->elem, cap);
    NH_GROW(r->J, 36 * cap);
    NH_GROW(r->tool2, cap);
    NH_GROW(r->elem2, cap);
    NH_GROW(r->J2, 36 * cap);
    NH_GROW(r->gap, cap);
    NH_GROW(r->disc, 10 * cap);
    NH_GROW(r->law, cap);
    NH_GROW(r->lambda, cap);
    r->cap = cap;
  }
  int i = r->m;
  if (nh_rows_slots(r, r->start[i] + 8)) return -1;
  r->m++;
  r->start[i + 1] = r->start[i] + 8;
  for (int a = r->start[i]; a < r->start[i + 1]; a++) r->node[a] = -1, r->N[a] = 0.0;
  memset(r->dir + 3 * i, 0, 3 * sizeof(double));
  r->tool[i] = -1, r->elem[i] = 0;
  memset(r->J + 36 * i, 0, 36 * sizeof(double));
  r->tool2[i] = -1, r->elem2[i] = 0;
  memset(r->J2 + 36 * i, 0, 36 * sizeof(double));
  r->gap[i] = 0.0, r->lambda[i] = 0.0;
  memset(r->disc + 10 * i, 0, 10 * sizeof(double));
  r->law[i] = (nh_row_law){NH_ROW_BILATERAL, -1, -1, 0.0, 0.0, -1, 0.0, 0, 0};
  return i;
}

int nh_rows_widen(nh_rows *r, int count) {
  const int i = r->m - 1;
  if (i < 0 || count < 0) return NH_ERROR(NH_ERR_INTERNAL, "widening no row");
  if (nh_rows_slots(r, r->start[i] + count))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d tissue slots of a row", count);
  r->start[i + 1] = r->start[i] + count;
  for (int a = r->start[i]; a < r->start[i + 1]; a++) r->node[a] = -1, r->N[a] = 0.0;
  return NH_OK;
}

int nh_row_elem(const nh_rows *r, int i, int side) {
  return side ? r->elem2[i] : r->elem[i];
}

void nh_row_tool_coef(const nh_rows *r, int i, int side, double c[12]) {
  const double *n = r->dir + 3 * i, *J = (side ? r->J2 : r->J) + 36 * i, sg = side ? 1.0 : -1.0;
  for (int j = 0; j < 12; j++) c[j] = sg * (n[0] * J[j] + n[1] * J[12 + j] + n[2] * J[24 + j]);
}

double nh_row_tool_rate(const nh_rows *r, int i, int side, const double *v) {
  double c[12], sum = 0.0;
  nh_row_tool_coef(r, i, side, c);
  const double *ve = v + 6 * nh_row_elem(r, i, side);
  for (int j = 0; j < 12; j++) sum += c[j] * ve[j];
  return sum;
}

void nh_row_tool_column(const nh_rows *r, int i, int side, double *col) {
  double c[12];
  nh_row_tool_coef(r, i, side, c);
  for (int j = 0; j < 12; j++) {
    int d = 6 * nh_row_elem(r, i, side) + j - 6;
    if (d >= 0) col[d] += c[j];
  }
}

cholmod_sparse *nh_rows_tissue_jt(nh_system *s, const nh_rows *r, int *mark) {
  const int m = r->m, n = s->n_free;
  size_t nnz = 0;
  for (int a = 0; a < (m ? r->start[m] : 0); a++) {
    int v = r->node[a];
    if (v >= 0) nnz += 3 * (size_t)(s->exp_start[v + 1] - s->exp_start[v]);
  }
  cholmod_sparse *Jt =
      cholmod_allocate_sparse((size_t)n, (size_t)m, nnz ? nnz : 1, 1, 1, 0, CHOLMOD_REAL, &s->cm);
  if (!Jt) return NULL;
  int *Jp = Jt->p, *Ji = Jt->i, pos = 0;
  double *Jx = Jt->x;
  for (int i = 0; i < m; i++) {
    const int start = Jp[i] = pos;
    for (int a = r->start[i]; a < r->start[i + 1]; a++) {
      int v = r->node[a];
      if (v < 0) continue;
      for (int q = s->exp_start[v]; q < s->exp_start[v + 1]; q++) {
        const int *f = s->free_of + 3 * s->exp_node[q];
        for (int k = 0; k < 3; k++) {
          double c = s->exp_w[q] * r->N[a] * r->dir[3 * i + k];
          if (c == 0.0 || f[k] < 0) continue;
          if (mark[f[k]] < start) mark[f[k]] = pos, Ji[pos] = f[k], Jx[pos++] = 0.0;
          Jx[mark[f[k]]] += c;
        }
      }
    }
  }
  Jp[m] = pos;
  for (int p = 0; p < pos; p++) mark[Ji[p]] = -1;
  cholmod_sort(Jt, &s->cm);
  return Jt;
}

void nh_rows_tissue_force(const cholmod_sparse *Jt, const double *lambda, double *col, int nf) {
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  memset(col, 0, sizeof(double) * (size_t)nf);
  for (int j = 0; j < (int)Jt->ncol; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) col[Ji[p]] += Jx[p] * lambda[j];
}

void nh_rows_tissue_rates(const nh_system *s, const nh_rows *rows, const double *v,
                          const double *dv, const double *base, double *full, double *out) {
  nh_system_scatter(s, dv, full);
  for (int i = 0; i < rows->m; i++) {
    double rate = 0.0;
    for (int a = rows->start[i]; a < rows->start[i + 1]; a++) {
      int node = rows->node[a];
      if (node < 0) continue;
      for (int c = 0; c < 3; c++)
        rate += rows->N[a] * rows->dir[3 * i + c] * (v[3 * node + c] + full[3 * node + c]);
    }
    out[i] = base[i] + rate;
  }
}
