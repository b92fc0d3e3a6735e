/* compliance.c — bilateral constraint rows solved through the compliance
 * matrix (the seed's Eqs. 20-21, Algorithms 1-3; docs/theory.md).
 *
 * With A factorised as P_ᵀ L D Lᵀ P_ (CHOLMOD; D = I for an LLᵀ factor) and
 * rows J, one constrained solve of
 *     A x = b + Jᵀ λ,   J x = 0
 * is
 *     x_free = A⁻¹ b                        (Algorithm 1, line 2)
 *     S = L⁻¹ P_ Jᵀ,  W = Sᵀ D⁻¹ S          (Algorithm 3, sparse right-hand side)
 *     W λ = − J x_free                      (line 3; W dense, Cholesky)
 *     x = x_free + A⁻¹ Jᵀ λ                 (lines 4-5)
 * The rows used now tie hanging nodes to their masters,
 *     u_h − Σ w u_m = 0  per component,
 * the seed's Eq. 19; the state is kept consistent (J u = 0), so the
 * increments obey the homogeneous rows. W is built once per factorisation,
 * by nh_system_compliance_add, the one home of W for every kind of row (the
 * tools' and the skull's rows of coupled.c use it too): for a supernodal
 * factor by forward solves restricted to the elimination-tree paths of the
 * rows, 16 columns at a time, and W = Sᵀ S (below, "The supernodal path");
 * for a simplicial one with CHOLMOD's sparse solves (cholmod_spsolve with
 * CHOLMOD_P, CHOLMOD_L, CHOLMOD_D) and W = Sᵀ (D⁻¹ S) by a sparse product. Its Cholesky
 * factorisation fails only when rows are linearly dependent, reported as a numerical failure. */
#include "solve/system_impl.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

int nh_system_set_hanging_rows(nh_system *s, const nh_hanging *h) {
  cholmod_free_sparse(&s->Jt, &s->cm);
  free(s->W);
  free(s->lambda_total);
  s->W = NULL;
  s->lambda_total = NULL;
  s->W_valid = 0;
  s->n_rows = 0;
  if (!h || h->n_hanging == 0) return NH_OK;
  /* Count entries: per hanging node and component, itself plus its non-fixed masters. */
  size_t nnz = 0;
  int rows = 0;
  for (int k = 0; k < h->n_hanging; k++) {
    if (s->free_of[3 * h->node[k]] < 0) continue; /* fixed: prescribed, not constrained */
    int masters = 0;
    for (int p = h->start[k]; p < h->start[k + 1]; p++)
      masters += s->free_of[3 * h->master[p]] >= 0;
    nnz += 3 * (size_t)(1 + masters);
    rows += 3;
  }
  s->Jt =
      cholmod_allocate_sparse((size_t)s->n_free, (size_t)rows, nnz, 1, 1, 0, CHOLMOD_REAL, &s->cm);
  if (!s->Jt) return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint rows");
  int *Jp = s->Jt->p, *Ji = s->Jt->i;
  double *Jx = s->Jt->x;
  int col = 0, pos = 0;
  for (int k = 0; k < h->n_hanging; k++) {
    if (s->free_of[3 * h->node[k]] < 0) continue;
    for (int i = 0; i < 3; i++) {
      Jp[col++] = pos;
      Ji[pos] = s->free_of[3 * h->node[k] + i];
      Jx[pos++] = 1.0;
      for (int p = h->start[k]; p < h->start[k + 1]; p++) {
        int f = s->free_of[3 * h->master[p] + i];
        if (f < 0) continue;
        Ji[pos] = f;
        Jx[pos++] = -h->weight[p];
      }
    }
  }
  Jp[col] = pos;
  /* Rows of a column must be sorted for CHOLMOD. */
  cholmod_sort(s->Jt, &s->cm);
  s->n_rows = rows;
  s->W = malloc(sizeof(double) * (size_t)rows * (size_t)rows);
  s->lambda_total = calloc((size_t)rows, sizeof(double));
  if (!s->W || !s->lambda_total)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: compliance matrix (%d rows)", rows);
  return NH_OK;
}

int nh_system_constraint_rows(const nh_system *s) {
  return s->n_rows;
}

/* W += J A⁻¹ Jᵀ through CHOLMOD's sparse solves, used for a simplicial
 * factor (small systems: CHOLMOD chooses simplicial LDLᵀ when the factor is
 * cheap; it works on any factor): S = L⁻¹ P Jᵀ, W += Sᵀ D⁻¹ S, NH_COMPLIANCE_BLOCK columns at a
 * time so that a stop request (SIGINT, SIGTERM) is honoured between blocks. Each column's
 * arithmetic is the same as in one CHOLMOD call over all of them. */
#define NH_COMPLIANCE_BLOCK 4

int nh_system_compliance_add_spsolve(nh_system *s, cholmod_sparse *Jt, double *W) {
  cholmod_common *cm = &s->cm;
  const int m = (int)Jt->ncol, nb = (m + NH_COMPLIANCE_BLOCK - 1) / NH_COMPLIANCE_BLOCK;
  cholmod_sparse **S = nh_calloc((size_t)(nb ? nb : 1), sizeof *S);
  cholmod_sparse **DS = nh_calloc((size_t)(nb ? nb : 1), sizeof *DS);
  cholmod_sparse *all = NULL, *St = NULL;
  int cols[NH_COMPLIANCE_BLOCK];
  int rc = S && DS ? NH_OK : NH_ERR_MEMORY, failed = 0;
  /* S_b = L⁻¹ P J_bᵀ and D⁻¹ S_b, block by block. */
  for (int b = 0; b < nb && !rc && !failed; b++) {
    int j0 = b * NH_COMPLIANCE_BLOCK,
        nc = m - j0 < NH_COMPLIANCE_BLOCK ? m - j0 : NH_COMPLIANCE_BLOCK;
    for (int k = 0; k < nc; k++) cols[k] = j0 + k;
    cholmod_sparse *Jb = cholmod_submatrix(Jt, NULL, -1, cols, nc, 1, 1, cm);
    cholmod_sparse *PJ = Jb ? cholmod_spsolve(CHOLMOD_P, s->L, Jb, cm) : NULL;
    S[b] = PJ ? cholmod_spsolve(CHOLMOD_L, s->L, PJ, cm) : NULL;
    DS[b] = S[b] ? cholmod_spsolve(CHOLMOD_D, s->L, S[b], cm) : NULL;
    cholmod_free_sparse(&Jb, cm);
    cholmod_free_sparse(&PJ, cm);
    failed = !DS[b];
    if (!failed) rc = nh_stop_check();
  }
  /* Sᵀ once, then W_b = Sᵀ (D⁻¹ S_b), block by block. */
  if (!rc && !failed && nb) {
    size_t nnz = 0;
    for (int b = 0; b < nb; b++) nnz += cholmod_nnz(S[b], cm);
    all = cholmod_allocate_sparse(Jt->nrow, (size_t)m, nnz ? nnz : 1, 1, 1, 0, CHOLMOD_REAL, cm);
    if (!(failed = !all)) {
      int *Ap = all->p, *Ai = all->i, pos = 0, col = 0;
      double *Ax = all->x;
      for (int b = 0; b < nb; b++) {
        const int *Sp = S[b]->p, *Si = S[b]->i;
        const double *Sx = S[b]->x;
        for (int j = 0; j < (int)S[b]->ncol; j++, col++) {
          Ap[col] = pos;
          for (int p = Sp[j]; p < Sp[j + 1]; p++) Ai[pos] = Si[p], Ax[pos++] = Sx[p];
        }
      }
      Ap[col] = pos;
      failed = !(St = cholmod_transpose(all, 1, cm));
    }
  }
  for (int b = 0; b < nb && !rc && !failed; b++) {
    cholmod_sparse *Wb = cholmod_ssmult(St, DS[b], 0, 1, 0, cm);
    if (!(failed = !Wb)) {
      const int *Wp = Wb->p, *Wi = Wb->i;
      const double *Wx = Wb->x;
      for (int j = 0; j < (int)Wb->ncol; j++)
        for (int p = Wp[j]; p < Wp[j + 1]; p++)
          W[(size_t)(b * NH_COMPLIANCE_BLOCK + j) * m + Wi[p]] += Wx[p];
      rc = nh_stop_check();
    }
    cholmod_free_sparse(&Wb, cm);
  }
  if (!rc && failed)
    rc = NH_ERROR(NH_ERR_NUMERIC, "computing the compliance W failed (CHOLMOD status %d)",
                  cm->status);
  for (int b = 0; b < nb && S && DS; b++) {
    cholmod_free_sparse(&S[b], cm);
    cholmod_free_sparse(&DS[b], cm);
  }
  free(S);
  free(DS);
  cholmod_free_sparse(&all, cm);
  cholmod_free_sparse(&St, cm);
  return rc;
}

/* The supernodal path (the factor of every system large enough to matter).
 *
 * A supernodal factor is LLᵀ (D = I), so W = Yᵀ Y with Y = L⁻¹ P Jᵀ: only
 * the forward solve, half the work of a solve with A. Column j of P Jᵀ is
 * nonzero on the few unknowns of one row (a point's cell); its forward
 * solve y = L⁻¹ b is nonzero only on the ancestors of those unknowns in the
 * elimination tree, a path to the root, and touches only the supernodes on
 * it (Gilbert's theorem). So the columns are solved NH_SUPER_COLUMNS at a
 * time against the union of their paths, each supernode's dense block
 * applied once to all of the block's columns:
 *   for each reached supernode s (ascending: children before parents),
 *     Y_s  ← L_ss⁻¹ Y_s                  (its columns: dense triangle)
 *     Y_r  ← Y_r − L_rs Y_s              (its rows below, in ancestors)
 * Columns are grouped by the supernode where their path starts, in the
 * factor's (postordered) numbering, so a block's columns lie in one subtree
 * and their paths merge early: the union is little more than one path.
 * Then W_IJ = Σ_s Y_I,sᵀ Y_J,s over the supernodes both blocks reach (the
 * others hold zeros of one of them). Blocks are independent, and so are the
 * pairs (I, J): both loops run on `threads` OpenMP threads, each entry of W
 * summed by one thread in a fixed order, so W does not depend on the
 * number of threads. The kernels are written out (rows of NH_SUPER_COLUMNS
 * values contiguous) rather than BLAS calls: CHOLMOD's BLAS has its own
 * thread pool, which would fight the OpenMP team for the cores. */
#define NH_SUPER_COLUMNS 16

typedef struct {
  int nsuper;
  const int *super, *pi, *px, *ls; /* CHOLMOD's supernodal layout */
  const double *lx;
  int *parent;    /* nsuper: parent supernode, −1 at a root */
  int *col_super; /* n: supernode of each (permuted) column */
  int *iperm;     /* n: permuted position of unknown i */
} nh_super_tree;

typedef struct {
  int nc;                    /* columns of J in the block */
  int col[NH_SUPER_COLUMNS]; /* their indices in Jᵀ */
  int nsn;                   /* supernodes reached */
  int *sn;                   /* ascending */
  int *row0;                 /* nsn + 1: first row of each in y */
  double *y;                 /* rows x NH_SUPER_COLUMNS, row-major */
} nh_super_block;

static void nh_super_tree_free(nh_super_tree *t) {
  free(t->parent), free(t->col_super), free(t->iperm);
}

static int nh_super_tree_build(const cholmod_factor *L, nh_super_tree *t) {
  const int n = (int)L->n, ns = (int)L->nsuper;
  t->nsuper = ns;
  t->super = L->super, t->pi = L->pi, t->px = L->px, t->ls = L->s, t->lx = L->x;
  t->parent = malloc(sizeof(int) * (size_t)(ns ? ns : 1));
  t->col_super = malloc(sizeof(int) * (size_t)n);
  t->iperm = malloc(sizeof(int) * (size_t)n);
  if (!t->parent || !t->col_super || !t->iperm) return NH_ERR_MEMORY;
  for (int k = 0; k < ns; k++)
    for (int j = t->super[k]; j < t->super[k + 1]; j++) t->col_super[j] = k;
  for (int k = 0; k < ns; k++) { /* the first row below the diagonal block */
    int nscol = t->super[k + 1] - t->super[k], nsrow = t->pi[k + 1] - t->pi[k];
    t->parent[k] = nsrow > nscol ? t->col_super[t->ls[t->pi[k] + nscol]] : -1;
  }
  const int *perm = L->Perm;
  for (int k = 0; k < n; k++) t->iperm[perm ? perm[k] : k] = k;
  return NH_OK;
}

/* Forward solve of one supernode for the block's rows in x (row r at
 * x + r·NH_SUPER_COLUMNS); t: (nsrow − nscol) x NH_SUPER_COLUMNS scratch.
 * Column-oriented, so that L's columns are read contiguously: the triangle
 * column by column, the rows below accumulated in t four columns at a time
 * and subtracted from their rows once. */
static void nh_super_forward(const nh_super_tree *st, int k, double *x, double *t) {
  enum { C = NH_SUPER_COLUMNS };
  const int k1 = st->super[k], nscol = st->super[k + 1] - k1, nsrow = st->pi[k + 1] - st->pi[k];
  const int noff = nsrow - nscol, *rows = st->ls + st->pi[k] + nscol;
  const double *Lk = st->lx + st->px[k]; /* column-major, nsrow x nscol */
  double *y = x + (size_t)k1 * C;        /* its columns' rows: contiguous */
  for (int j = 0; j < nscol; j++) {      /* Y_s ← L_ss⁻¹ Y_s */
    const double *lj = Lk + (size_t)j * nsrow, d = 1.0 / lj[j];
    double *yj = y + (size_t)j * C;
    for (int c = 0; c < C; c++) yj[c] *= d;
    for (int i = j + 1; i < nscol; i++) {
      double *yi = y + (size_t)i * C;
      for (int c = 0; c < C; c++) yi[c] -= lj[i] * yj[c];
    }
  }
  if (noff == 0) return;
  memset(t, 0, sizeof(double) * (size_t)noff * C); /* t = L_rs Y_s */
  int j = 0;
  for (; j + 4 <= nscol; j += 4) {
    const double *l0 = Lk + (size_t)j * nsrow + nscol, *l1 = l0 + nsrow, *l2 = l1 + nsrow,
                 *l3 = l2 + nsrow;
    const double *y0 = y + (size_t)j * C, *y1 = y0 + C, *y2 = y1 + C, *y3 = y2 + C;
    for (int i = 0; i < noff; i++) {
      double *ti = t + (size_t)i * C;
      for (int c = 0; c < C; c++)
        ti[c] += l0[i] * y0[c] + l1[i] * y1[c] + l2[i] * y2[c] + l3[i] * y3[c];
    }
  }
  for (; j < nscol; j++) {
    const double *l0 = Lk + (size_t)j * nsrow + nscol, *y0 = y + (size_t)j * C;
    for (int i = 0; i < noff; i++)
      for (int c = 0; c < C; c++) t[(size_t)i * C + c] += l0[i] * y0[c];
  }
  for (int i = 0; i < noff; i++) { /* Y_r ← Y_r − t */
    double *xr = x + (size_t)rows[i] * C;
    for (int c = 0; c < C; c++) xr[c] -= t[(size_t)i * C + c];
  }
}

static int nh_int_compare(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

/* Y of one block: its reached supernodes and their rows, packed. x: n x C
 * zeros (returned zero); mark: nsuper ints, none equal to stamp; list:
 * nsuper ints of scratch; scratch: n x C doubles. */
static int nh_super_block_solve(const nh_super_tree *t, const cholmod_sparse *Jt, nh_super_block *b,
                                double *x, int *mark, int stamp, int *list, double *scratch) {
  enum { C = NH_SUPER_COLUMNS };
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  int cnt = 0;
  for (int c = 0; c < b->nc; c++)
    for (int p = Jp[b->col[c]]; p < Jp[b->col[c] + 1]; p++) {
      const int k = t->iperm[Ji[p]];
      x[(size_t)k * C + c] += Jx[p];
      for (int sn = t->col_super[k]; sn >= 0 && mark[sn] != stamp; sn = t->parent[sn])
        mark[sn] = stamp, list[cnt++] = sn;
    }
  qsort(list, (size_t)cnt, sizeof(int), nh_int_compare);
  for (int q = 0; q < cnt; q++) nh_super_forward(t, list[q], x, scratch);
  b->nsn = cnt;
  b->sn = malloc(sizeof(int) * (size_t)(cnt ? cnt : 1));
  b->row0 = malloc(sizeof(int) * (size_t)(cnt + 1));
  int rows = 0;
  for (int q = 0; q < cnt; q++) rows += t->super[list[q] + 1] - t->super[list[q]];
  b->y = malloc(sizeof(double) * (size_t)(rows ? rows : 1) * C);
  if (!b->sn || !b->row0 || !b->y) return NH_ERR_MEMORY;
  rows = 0;
  for (int q = 0; q < cnt; q++) {
    const int k = list[q], k1 = t->super[k], nr = t->super[k + 1] - k1;
    b->sn[q] = k, b->row0[q] = rows;
    memcpy(b->y + (size_t)rows * C, x + (size_t)k1 * C, sizeof(double) * (size_t)nr * C);
    memset(x + (size_t)k1 * C, 0, sizeof(double) * (size_t)nr * C);
    rows += nr;
  }
  b->row0[cnt] = rows;
  return NH_OK;
}

/* W_IJ += Y_Iᵀ Y_J over the supernodes both reach (I's columns by J's). */
static void nh_super_block_pair(const nh_super_block *I, const nh_super_block *J, double *W,
                                int m) {
  enum { C = NH_SUPER_COLUMNS };
  double acc[C][C] = {{0}};
  for (int a = 0, b = 0; a < I->nsn && b < J->nsn;) {
    if (I->sn[a] < J->sn[b]) {
      a++;
    } else if (I->sn[a] > J->sn[b]) {
      b++;
    } else {
      const double *yi = I->y + (size_t)I->row0[a] * C, *yj = J->y + (size_t)J->row0[b] * C;
      for (int r = 0; r < I->row0[a + 1] - I->row0[a]; r++, yi += C, yj += C)
        for (int p = 0; p < C; p++)
          for (int q = 0; q < C; q++) acc[p][q] += yi[p] * yj[q];
      a++, b++;
    }
  }
  for (int p = 0; p < I->nc; p++)
    for (int q = 0; q < J->nc; q++) {
      W[(size_t)J->col[q] * m + I->col[p]] += acc[p][q];
      if (I != J) W[(size_t)I->col[p] * m + J->col[q]] += acc[p][q];
    }
}

typedef struct {
  int key, col;
} nh_column_key;

static int nh_column_key_compare(const void *a, const void *b) {
  const nh_column_key *x = a, *y = b;
  if (x->key != y->key) return (x->key > y->key) - (x->key < y->key);
  return (x->col > y->col) - (x->col < y->col);
}

static int nh_compliance_add_supernodal(nh_system *s, cholmod_sparse *Jt, double *W, int threads) {
  enum { C = NH_SUPER_COLUMNS };
  const int m = (int)Jt->ncol, n = (int)s->L->n, nb = (m + C - 1) / C;
  const int nt = threads > 0 ? threads : omp_get_max_threads();
  const int *Jp = Jt->p, *Ji = Jt->i;
  nh_super_tree t = {0};
  nh_super_block *blk = nh_calloc((size_t)(nb ? nb : 1), sizeof *blk);
  nh_column_key *key = malloc(sizeof *key * (size_t)(m ? m : 1));
  int rc = blk && key ? nh_super_tree_build(s->L, &t) : NH_ERR_MEMORY;
  if (!rc) {
    /* the first supernode of each column's path: columns of one subtree together */
    for (int j = 0; j < m; j++) {
      key[j].col = j, key[j].key = t.nsuper;
      for (int p = Jp[j]; p < Jp[j + 1]; p++) {
        int sn = t.col_super[t.iperm[Ji[p]]];
        if (sn < key[j].key) key[j].key = sn;
      }
    }
    qsort(key, (size_t)m, sizeof *key, nh_column_key_compare);
    for (int b = 0; b < nb; b++) {
      blk[b].nc = m - b * C < C ? m - b * C : C;
      for (int c = 0; c < blk[b].nc; c++) blk[b].col[c] = key[b * C + c].col;
    }
  }
  int failed = 0, stopped = 0;
  if (!rc) {
#pragma omp parallel num_threads(nt) if (nb > 1)
    {
      double *x = nh_calloc((size_t)n * C, sizeof(double));
      int *mark = malloc(sizeof(int) * (size_t)(t.nsuper ? t.nsuper : 1));
      int *list = malloc(sizeof(int) * (size_t)(t.nsuper ? t.nsuper : 1));
      double *scratch = malloc(sizeof(double) * (size_t)n * C);
      int ok = x && mark && list && scratch;
      for (int k = 0; ok && k < t.nsuper; k++) mark[k] = -1;
#pragma omp for schedule(dynamic)
      for (int b = 0; b < nb; b++) {
        if (!ok || failed || stopped) continue;
        if (nh_stop_requested()) {
#pragma omp atomic write
          stopped = 1;
          continue;
        }
        if (nh_super_block_solve(&t, Jt, &blk[b], x, mark, b, list, scratch)) ok = 0;
      }
      if (!ok) {
#pragma omp atomic write
        failed = 1;
      }
      free(x), free(mark), free(list), free(scratch);
    }
  }
  if (!rc && !failed && !stopped) {
    /* pairs I <= J, the row J of the upper triangle of blocks as one task */
#pragma omp parallel for num_threads(nt) schedule(dynamic) if (nb > 1)
    for (int J = 0; J < nb; J++)
      for (int I = 0; I <= J; I++) nh_super_block_pair(&blk[I], &blk[J], W, m);
  }
  if (!rc && failed) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the compliance (%d rows)", m);
  if (!rc && stopped) rc = nh_stop_check();
  for (int b = 0; blk && b < nb; b++) free(blk[b].sn), free(blk[b].row0), free(blk[b].y);
  free(blk), free(key);
  nh_super_tree_free(&t);
  return rc;
}

int nh_system_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W, int threads) {
  if (s->L->is_super) return nh_compliance_add_supernodal(s, Jt, W, threads);
  return nh_system_compliance_add_spsolve(s, Jt, W);
}

/* W = J A⁻¹ Jᵀ of the hanging rows and its dense Cholesky factor, in place. */
static int nh_compliance_build(nh_system *s) {
  int m = s->n_rows;
  memset(s->W, 0, sizeof(double) * (size_t)m * (size_t)m);
  int rc = nh_system_compliance_add(s, s->Jt, s->W, 0);
  /* Dense Cholesky W = G Gᵀ, lower triangle in place (column-major). */
  for (int j = 0; j < m && !rc; j++) {
    if (j % 16 == 0 && (rc = nh_stop_check())) break;
    double *cj = s->W + (size_t)j * m;
    double d = cj[j];
    for (int k = 0; k < j; k++) d -= s->W[(size_t)k * m + j] * s->W[(size_t)k * m + j];
    if (!(d > 1e-14 * fabs(cj[j]))) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "the constraint rows are linearly dependent (row %d of %d)", j,
                    m);
      break;
    }
    d = sqrt(d);
    cj[j] = d;
    for (int i = j + 1; i < m; i++) {
      double v = cj[i];
      for (int k = 0; k < j; k++) v -= s->W[(size_t)k * m + i] * s->W[(size_t)k * m + j];
      cj[i] = v / d;
    }
    /* Mirror into the upper triangle for the row access above. */
    for (int i = j + 1; i < m; i++) s->W[(size_t)i * m + j] = cj[i];
  }
  if (!rc) s->W_valid = 1;
  return rc;
}

int nh_system_solve_constrained(nh_system *s, const double *b, double *x) {
  NH_TRY(nh_system_solve(s, b, x));
  if (s->n_rows == 0) return NH_OK;
  double t0 = nh_time_now();
  if (!s->W_valid) NH_TRY(nh_compliance_build(s));
  int m = s->n_rows, n = s->n_free;
  const int *Jp = s->Jt->p, *Ji = s->Jt->i;
  const double *Jx = s->Jt->x;
  double *lambda = malloc(sizeof(double) * (size_t)m);
  double *r = malloc(sizeof(double) * (size_t)n), *y = malloc(sizeof(double) * (size_t)n);
  if (!lambda || !r || !y) {
    free(lambda), free(r), free(y);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint solve");
  }
  for (int j = 0; j < m; j++) { /* − J x_free */
    double v = 0.0;
    for (int p = Jp[j]; p < Jp[j + 1]; p++) v += Jx[p] * x[Ji[p]];
    lambda[j] = -v;
  }
  for (int j = 0; j < m; j++) { /* G z = rhs */
    double v = lambda[j];
    for (int k = 0; k < j; k++) v -= s->W[(size_t)k * m + j] * lambda[k];
    lambda[j] = v / s->W[(size_t)j * m + j];
  }
  for (int j = m - 1; j >= 0; j--) { /* Gᵀ λ = z */
    double v = lambda[j];
    for (int k = j + 1; k < m; k++) v -= s->W[(size_t)j * m + k] * lambda[k];
    lambda[j] = v / s->W[(size_t)j * m + j];
  }
  memset(r, 0, sizeof(double) * (size_t)n); /* Jᵀ λ */
  for (int j = 0; j < m; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) r[Ji[p]] += Jx[p] * lambda[j];
  int rc = nh_system_solve(s, r, y);
  if (!rc) {
    for (int i = 0; i < n; i++) x[i] += y[i];
    for (int j = 0; j < m; j++) s->lambda_total[j] += lambda[j];
  }
  free(lambda), free(r), free(y);
  s->t_constraints += nh_time_now() - t0;
  return rc;
}

void nh_system_reset_multipliers(nh_system *s) {
  if (s->lambda_total) memset(s->lambda_total, 0, sizeof(double) * (size_t)s->n_rows);
}

void nh_system_add_reactions(const nh_system *s, double *b) {
  if (s->n_rows == 0) return;
  const int *Jp = s->Jt->p, *Ji = s->Jt->i;
  const double *Jx = s->Jt->x;
  for (int j = 0; j < s->n_rows; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) b[Ji[p]] += Jx[p] * s->lambda_total[j];
}
