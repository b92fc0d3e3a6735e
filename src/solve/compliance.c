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
 * rows, supernode by supernode in BLAS-3 calls, and W = Sᵀ S (below, "The
 * supernodal path");
 * for a simplicial one with CHOLMOD's sparse solves (cholmod_spsolve with
 * CHOLMOD_P, CHOLMOD_L, CHOLMOD_D) and W = Sᵀ (D⁻¹ S) by a sparse product. Its Cholesky
 * factorisation fails only when rows are linearly dependent, reported as a numerical failure. */
#include "solve/system_impl.h"

#include <cblas.h>
#include <lapacke.h>
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
  s->W = nh_calloc((size_t)rows * (size_t)rows, sizeof(double));
  s->lambda_total = nh_calloc((size_t)rows, sizeof(double));
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
 * elimination tree, a path to the root (Gilbert's theorem), and touches
 * only the supernodes on it. The columns are grouped in blocks of
 * NH_SUPER_COLUMNS, sorted by the supernode where their path starts (in the
 * factor's postordered numbering), so a block's columns lie in one subtree
 * and their paths merge early; a block's Y is kept packed over the
 * supernodes its columns reach. Then one pass over the supernodes s in
 * ascending order (children before parents), on the k blocks that reach s,
 * with Z = [Y_s of those blocks]ᵀ (k·NH_SUPER_COLUMNS x nscol):
 *   Z ← Z L_ss⁻ᵀ                       (dtrsm: Y_s = L_ss⁻¹ Y_s, final)
 *   W += Z Zᵀ, scattered               (dsyrk: s's share of Yᵀ Y)
 *   Y_r ← Y_r − (Z L_rsᵀ)ᵀ             (dgemm: the rows below, in ancestors)
 * Each supernode is applied once, to every column that needs it, in BLAS-3
 * calls whose width is the number of rows whose paths cross it: the top
 * separators, where most of L and of the work is, are crossed by all rows
 * and run at dense speed, split into tasks on the OpenMP threads
 * (nh_super_apply); near the leaves the calls are small and few columns pay
 * for them. The flops are those of the
 * restricted forward solves and of the pairs of paths that meet, about
 * Σ_s k_s C (nscol² + 2 noff·nscol) + (k_s C)² nscol (C = NH_SUPER_COLUMNS).
 * Measured on a 20 x 25 x 19 box (32760 unknowns) with 740 point rows in
 * random cells, CPU time with one BLAS thread: 0.19 s with C = 16, 0.21 s
 * with 32, 0.25 s with 64; CHOLMOD's spsolve path 4.0 s; the same
 * column-blocked forward solves with hand-written kernels instead of BLAS,
 * 1.16 s (C = 16) and 0.56 s (C = 32). */
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
  int *row0;                 /* nsuper: first row of each reached supernode in y, −1 if not */
  double *y;                 /* reached rows x NH_SUPER_COLUMNS, row-major */
} nh_super_block;

static void nh_super_tree_free(nh_super_tree *t) {
  free(t->parent), free(t->col_super), free(t->iperm);
}

static int nh_super_tree_build(const cholmod_factor *L, nh_super_tree *t) {
  const int n = (int)L->n, ns = (int)L->nsuper;
  t->nsuper = ns;
  t->super = L->super, t->pi = L->pi, t->px = L->px, t->ls = L->s, t->lx = L->x;
  t->parent = nh_calloc((size_t)(ns ? ns : 1), sizeof(int));
  t->col_super = nh_calloc((size_t)(n ? n : 1), sizeof(int));
  t->iperm = nh_calloc((size_t)(n ? n : 1), sizeof(int));
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

/* The supernodes block b reaches, its packed y with the right-hand side
 * P J_bᵀ scattered in; count[s] += 1 for each. */
static int nh_super_block_open(const nh_super_tree *t, const cholmod_sparse *Jt, nh_super_block *b,
                               int *count) {
  enum { C = NH_SUPER_COLUMNS };
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  if (!(b->row0 = nh_calloc((size_t)t->nsuper, sizeof(int)))) return NH_ERR_MEMORY;
  for (int k = 0; k < t->nsuper; k++) b->row0[k] = -1;
  for (int c = 0; c < b->nc; c++)
    for (int p = Jp[b->col[c]]; p < Jp[b->col[c] + 1]; p++)
      for (int sn = t->col_super[t->iperm[Ji[p]]]; sn >= 0 && b->row0[sn] < 0; sn = t->parent[sn])
        b->row0[sn] = 0, count[sn]++;
  int rows = 0; /* offsets in ascending supernode order */
  for (int k = 0; k < t->nsuper; k++)
    if (b->row0[k] >= 0) b->row0[k] = rows, rows += t->super[k + 1] - t->super[k];
  if (!(b->y = nh_calloc((size_t)(rows ? rows : 1) * C, sizeof(double)))) return NH_ERR_MEMORY;
  for (int c = 0; c < b->nc; c++)
    for (int p = Jp[b->col[c]]; p < Jp[b->col[c] + 1]; p++) {
      const int k = t->iperm[Ji[p]], sn = t->col_super[k];
      b->y[(size_t)(b->row0[sn] + k - t->super[sn]) * C + c] += Jx[p];
    }
  return NH_OK;
}

typedef struct {
  int key, col;
} nh_column_key;

static int nh_column_key_compare(const void *a, const void *b) {
  const nh_column_key *x = a, *y = b;
  if (x->key != y->key) return (x->key > y->key) - (x->key < y->key);
  return (x->col > y->col) - (x->col < y->col);
}

/* Supernode k for its blocks blk[list[0..nk)]: solve, W += Z Zᵀ, update the
 * ancestors' rows, on OpenMP threads that each call BLAS single-threaded
 * (src/main.c runs BLAS on one thread). A supernode whose flops exceed
 * NH_SUPER_PARALLEL_FLOPS (the top separators: for 740 rows on 31200
 * unknowns, 22 of the 836 supernodes the rows reach, with 93 % of the
 * flops) has its kC rows of Z cut
 * into NH_SUPER_SPLIT chunks of whole blocks, a cut that depends on nk and
 * the supernode only, never on the number of threads, and its work into
 * independent tasks, one or two BLAS calls each:
 *   per chunk a:        Z_a ← Z_a L_ss⁻ᵀ (dtrsm; the rows of Z are independent),
 *                       U_a = Z_a L_rsᵀ (dgemm) and Y_r of a's blocks −= U_aᵀ;
 *   per pair b <= a:    G_ab = Z_a Z_bᵀ (dsyrk on the diagonal, dgemm off it)
 *                       added to W at the pairs of columns (a, b), both halves.
 * Chunk tasks write only their own blocks' y, pair tasks only their own
 * pairs of W's entries: the tasks of one phase touch disjoint memory, and
 * every entry is computed by the same calls whichever thread runs them, so W
 * is bitwise the same for any number of threads (tests/test_compliance.c).
 * Other supernodes are one chunk, serial (a parallel region costs tens of
 * µs). Two chunks, for 2 cores: with 2 the two phases split evenly (chunks
 * 1 + 1, pairs 1 + 1 + 2 halves); each cut repacks L's panel and adds small
 * calls, measured 5-10 % more CPU per cut at 740 rows; 4 chunks measured no
 * faster on 2 cores. Scratch per thread: ws (nh_super_scratch). */
enum { NH_SUPER_SPLIT = 2, NH_SUPER_PARALLEL_FLOPS = 20000000 };

typedef struct {
  double *G, *U; /* per thread: a pair's G and a chunk's U (sizes: the widest chunk) */
} nh_super_scratch;

static void nh_super_chunk(const nh_super_tree *t, int k, nh_super_block *blk, const int *list,
                           int a0, int a1, double *Z, int kc, double *U) {
  enum { C = NH_SUPER_COLUMNS };
  const int k1 = t->super[k], nscol = t->super[k + 1] - k1, nsrow = t->pi[k + 1] - t->pi[k];
  const int noff = nsrow - nscol, rows_a = (a1 - a0) * C, *rows = t->ls + t->pi[k] + nscol;
  const double *Lk = t->lx + t->px[k]; /* column-major, nsrow x nscol */
  double *Za = Z + (size_t)a0 * C;
  for (int a = a0; a < a1; a++) { /* Z = [Y_s]ᵀ */
    const double *y = blk[list[a]].y + (size_t)blk[list[a]].row0[k] * C;
    for (int r = 0; r < nscol; r++)
      memcpy(Z + (size_t)r * kc + (size_t)a * C, y + (size_t)r * C, sizeof(double) * C);
  }
  cblas_dtrsm(CblasColMajor, CblasRight, CblasLower, CblasTrans, CblasNonUnit, rows_a, nscol, 1.0,
              Lk, nsrow, Za, kc);
  if (noff == 0) return;
  cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, rows_a, noff, nscol, 1.0, Za, kc, Lk + nscol,
              nsrow, 0.0, U, rows_a);
  for (int i = 0; i < noff; i++) {
    const int r = rows[i], sn = t->col_super[r];
    for (int a = a0; a < a1; a++) {
      nh_super_block *b = &blk[list[a]];
      double *dst = b->y + (size_t)(b->row0[sn] + r - t->super[sn]) * C;
      const double *u = U + (size_t)i * rows_a + (size_t)(a - a0) * C;
      for (int c = 0; c < C; c++) dst[c] -= u[c];
    }
  }
}

static void nh_super_pair(const nh_super_tree *t, int k, const nh_super_block *blk, const int *list,
                          int a0, int a1, int b0, int b1, const double *Z, int kc, double *G,
                          double *W, int m) {
  enum { C = NH_SUPER_COLUMNS };
  const int nscol = t->super[k + 1] - t->super[k], ra = (a1 - a0) * C, rb = (b1 - b0) * C;
  const double *Za = Z + (size_t)a0 * C, *Zb = Z + (size_t)b0 * C;
  if (a0 == b0)
    cblas_dsyrk(CblasColMajor, CblasLower, CblasNoTrans, ra, nscol, 1.0, Za, kc, 0.0, G, ra);
  else
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasTrans, ra, rb, nscol, 1.0, Za, kc, Zb, kc, 0.0, G,
                ra);
  for (int q = 0; q < rb; q++) { /* G(p, q): row p of chunk a, q of chunk b */
    const nh_super_block *bq = &blk[list[b0 + q / C]];
    if (q % C >= bq->nc) continue;
    const int cq = bq->col[q % C];
    for (int p = a0 == b0 ? q : 0; p < ra; p++) {
      const nh_super_block *bp = &blk[list[a0 + p / C]];
      if (p % C >= bp->nc) continue;
      const int cp = bp->col[p % C];
      const double g = G[(size_t)q * ra + p];
      W[(size_t)cq * m + cp] += g;
      if (cp != cq) W[(size_t)cp * m + cq] += g;
    }
  }
}

/* The split of a supernode's nk blocks: into NH_SUPER_SPLIT chunks (fewer
 * if fewer blocks) when its flops exceed NH_SUPER_PARALLEL_FLOPS, else one;
 * chunk c holds blocks [c nk / n, (c + 1) nk / n). */
static int nh_super_split(const nh_super_tree *t, int k, int nk) {
  const int nscol = t->super[k + 1] - t->super[k], nsrow = t->pi[k + 1] - t->pi[k];
  const double kc = (double)nk * NH_SUPER_COLUMNS;
  const double flops = kc * nscol * (nscol + 2.0 * (nsrow - nscol) + kc);
  if (flops <= NH_SUPER_PARALLEL_FLOPS) return 1;
  return nk < NH_SUPER_SPLIT ? nk : NH_SUPER_SPLIT;
}

static void nh_super_apply(const nh_super_tree *t, int k, nh_super_block *blk, const int *list,
                           int nk, double *Z, nh_super_scratch *ws, int threads, double *W, int m) {
  enum { C = NH_SUPER_COLUMNS };
  const int kc = nk * C, nch = nh_super_split(t, k, nk), npair = nch * (nch + 1) / 2;
  const int nt = nch > 1 ? threads : 1;
#pragma omp parallel num_threads(nt) if (nt > 1)
  {
    const nh_super_scratch *w = &ws[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int c = 0; c < nch; c++)
      nh_super_chunk(t, k, blk, list, c * nk / nch, (c + 1) * nk / nch, Z, kc, w->U);
      /* (the implied barrier: every row of Z solved) */
#pragma omp for schedule(dynamic, 1)
    for (int q = 0; q < npair; q++) {
      int a = 0; /* q = a (a + 1) / 2 + b, b <= a */
      while ((a + 1) * (a + 2) / 2 <= q) a++;
      const int b = q - a * (a + 1) / 2;
      nh_super_pair(t, k, blk, list, a * nk / nch, (a + 1) * nk / nch, b * nk / nch,
                    (b + 1) * nk / nch, Z, kc, w->G, W, m);
    }
  }
}

static int nh_compliance_add_supernodal(nh_system *s, cholmod_sparse *Jt, double *W) {
  enum { C = NH_SUPER_COLUMNS };
  const int m = (int)Jt->ncol, nb = (m + C - 1) / C;
  const int *Jp = Jt->p, *Ji = Jt->i;
  nh_super_tree t = {0};
  nh_super_block *blk = nh_calloc((size_t)(nb ? nb : 1), sizeof *blk);
  nh_column_key *key = nh_calloc((size_t)(m ? m : 1), sizeof *key);
  int *count = NULL, *start = NULL, *list = NULL;
  const int nt = nh_system_blas_team(s);
  nh_super_scratch *ws = nh_calloc((size_t)nt, sizeof *ws);
  double *Z = NULL, *G = NULL, *U = NULL;
  int rc = blk && key && ws ? nh_super_tree_build(s->L, &t) : NH_ERR_MEMORY;
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
    count = nh_calloc((size_t)t.nsuper + 1, sizeof(int));
    start = nh_calloc(((size_t)t.nsuper + 1), sizeof(int));
    if (!count || !start) rc = NH_ERR_MEMORY;
  }
  for (int b = 0; b < nb && !rc; b++) {
    blk[b].nc = m - b * C < C ? m - b * C : C;
    for (int c = 0; c < blk[b].nc; c++) blk[b].col[c] = key[b * C + c].col;
    rc = nh_super_block_open(&t, Jt, &blk[b], count);
  }
  /* scratch: Z of the widest supernode; per thread a chunk's U and a pair's G */
  size_t zmax = 1, gmax = 1, umax = 1;
  if (!rc) { /* the blocks of each supernode, and the scratch the widest needs */
    start[0] = 0;
    for (int k = 0; k < t.nsuper; k++) {
      start[k + 1] = start[k] + count[k];
      const size_t nscol = (size_t)(t.super[k + 1] - t.super[k]);
      const size_t noff = (size_t)(t.pi[k + 1] - t.pi[k]) - nscol;
      const int n = count[k] ? nh_super_split(&t, k, count[k]) : 1;
      const size_t kc = (size_t)count[k] * C, hc = (size_t)((count[k] + n - 1) / n) * C;
      if (kc * nscol > zmax) zmax = kc * nscol;
      if (hc * hc > gmax) gmax = hc * hc;
      if (hc * noff > umax) umax = hc * noff;
      count[k] = 0;
    }
    if (!(list = nh_calloc((size_t)(start[t.nsuper] ? start[t.nsuper] : 1), sizeof(int))))
      rc = NH_ERR_MEMORY;
    for (int b = 0; b < nb && !rc; b++)
      for (int k = 0; k < t.nsuper; k++)
        if (blk[b].row0[k] >= 0) list[start[k] + count[k]++] = b;
    Z = nh_calloc(zmax, sizeof(double)), G = nh_calloc(nt * gmax, sizeof(double));
    U = nh_calloc(nt * umax, sizeof(double));
    if (!Z || !G || !U) rc = NH_ERR_MEMORY;
    for (int i = 0; i < nt && !rc; i++) ws[i].G = G + i * gmax, ws[i].U = U + i * umax;
  }
  for (int k = 0; k < t.nsuper && !rc; k++) {
    if (count[k] == 0) continue;
    nh_super_apply(&t, k, blk, list + start[k], count[k], Z, ws, nt, W, m);
    rc = nh_stop_check();
  }
  if (rc == NH_ERR_MEMORY)
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the compliance of %d rows", m);
  for (int b = 0; blk && b < nb; b++) free(blk[b].row0), free(blk[b].y);
  free(blk), free(key), free(count), free(start), free(list), free(Z), free(G), free(U);
  free(ws);
  nh_super_tree_free(&t);
  return rc;
}

int nh_system_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W) {
  if (!s->L && s->inh) return nh_inherit_compliance_add(s, Jt, W); /* W₀ = J B Jᵀ */
  if (s->L->is_super) return nh_compliance_add_supernodal(s, Jt, W);
  return nh_system_compliance_add_spsolve(s, Jt, W);
}

/* W = J A⁻¹ Jᵀ of the hanging rows and its dense Cholesky factor, in place. */
static int nh_compliance_build(nh_system *s) {
  int m = s->n_rows;
  memset(s->W, 0, sizeof(double) * (size_t)m * (size_t)m);
  int rc = nh_system_compliance_add(s, s->Jt, s->W);
  /* Dense Cholesky W = G Gᵀ, lower triangle in place (column-major), by
   * LAPACK (blocked: thousands of hanging rows are O(m³)). A pivot below
   * 1e-14 of its diagonal means linearly dependent rows. */
  double *diag = rc ? NULL : nh_calloc((size_t)(m ? m : 1), sizeof(double));
  if (!rc && !diag) rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: compliance (%d rows)", m);
  if (!rc) {
    for (int j = 0; j < m; j++) diag[j] = s->W[(size_t)j * m + j];
    int info = (int)LAPACKE_dpotrf(LAPACK_COL_MAJOR, 'L', m, s->W, m);
    for (int j = 0; j < m && !info; j++) {
      double g = s->W[(size_t)j * m + j];
      if (!(g * g > 1e-14 * fabs(diag[j]))) info = j + 1;
    }
    if (info)
      rc = NH_ERROR(NH_ERR_NUMERIC, "the constraint rows are linearly dependent (row %d of %d)",
                    info - 1, m);
    if (!rc) rc = nh_stop_check();
  }
  free(diag);
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
  double *lambda = nh_calloc((size_t)m, sizeof(double));
  double *r = nh_calloc((size_t)n, sizeof(double)), *y = nh_calloc((size_t)n, sizeof(double));
  if (!lambda || !r || !y) {
    free(lambda), free(r), free(y);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint solve");
  }
  for (int j = 0; j < m; j++) { /* − J x_free */
    double v = 0.0;
    for (int p = Jp[j]; p < Jp[j + 1]; p++) v += Jx[p] * x[Ji[p]];
    lambda[j] = -v;
  }
  LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', m, 1, s->W, m, lambda, m); /* G Gᵀ λ = rhs */
  memset(r, 0, sizeof(double) * (size_t)n);                        /* Jᵀ λ */
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

/* The dual of a constrained step (solve.h): the active rows' tissue parts
 * compacted into a row set of their own, W of it, and the pivoted Cholesky
 * factor of D W D (D = diag(W)^−½) for the multipliers; A factorised first
 * when the factor is not A's.
 *
 * The correction A⁻¹ J_tᵀ μ takes one of two routes, by the number m of
 * active rows against the ncol right-hand sides:
 *   m >= ncol: W by nh_system_compliance_add (restricted forward solves),
 *     then A⁻¹ (J_tᵀ μ), a second solve of ncol columns;
 *   m <  ncol: G = A⁻¹ J_tᵀ, its m columns solved with the ncol of A⁻¹ b
 *     in one call (nh_system_solve_two), W = J_t G and the correction G μ
 *     (a dense n x m by m x ncol product).
 * The second costs an m-column solve where the first costs an ncol-column
 * one (the phantom's goal estimate: 36 duals, 3 to ~50 active rows); W =
 * J_t G is then nearly free, m² sparse dot products (the phantom's goal run:
 * under 10e6 instructions where the compliance path took 110e6 on the same
 * 29 calls, docs/performance.md). J_t G is symmetric only to round-off:
 * its lower triangle is formed and mirrored (dpstrf reads the lower one;
 * the scaling reads both). The two routes agree to round-off
 * (tests/test_dwr_rows.c). */
/* The multipliers' factor of the ms rows at place[0..ms) of the m x m
 * compliance W: D = diag(W)^−½ over them (d; a row without free DOFs, 0:
 * dropped) and the pivoted Cholesky factor of D W D (Ws, ms x ms; piv,
 * *rank: pivots below 1e-12 relative truncated). */
static int nh_dual_factor(const double *W, int m, const int *place, int ms, double *d, double *Ws,
                          int *piv, int *rank) {
  for (int a = 0; a < ms; a++) {
    double w = W[(size_t)place[a] * m + place[a]];
    d[a] = w > 0.0 ? 1.0 / sqrt(w) : 0.0;
  }
  for (int a = 0; a < ms; a++)
    for (int e = 0; e < ms; e++)
      Ws[(size_t)a * ms + e] = W[(size_t)place[a] * m + place[e]] * d[a] * d[e];
  *rank = 0;
  int info = (int)LAPACKE_dpstrf(LAPACK_COL_MAJOR, 'L', ms, Ws, ms, piv, rank, 1e-12);
  return info < 0 ? NH_ERROR(NH_ERR_NUMERIC, "constrained dual: dpstrf failed (%d)", info) : NH_OK;
}

/* The multipliers μ of nk columns x (n each) for the rows at place[0..ms)
 * of Jt (a factor of nh_dual_factor): L₁₁ L₁₁ᵀ y₁ = (Pᵀ D J x)₁, y₂ = 0,
 * μ = D P y, written at mu[m q + place[a]]; c (ms nk) and cp (rank nk)
 * workspace. */
static void nh_dual_multipliers(const cholmod_sparse *Jt, const int *place, int ms, const double *d,
                                const double *Ws, const int *piv, int rank, int n, int nk,
                                const double *x, double *c, double *cp, double *mu, int m) {
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  for (int q = 0; q < nk; q++) /* D J x */
    for (int a = 0; a < ms; a++) {
      const int j = place[a];
      double v = 0.0;
      for (int p = Jp[j]; p < Jp[j + 1]; p++) v += Jx[p] * x[(size_t)n * q + Ji[p]];
      c[(size_t)ms * q + a] = d[a] * v;
    }
  for (int q = 0; q < nk; q++)
    for (int i = 0; i < rank; i++) cp[(size_t)rank * q + i] = c[(size_t)ms * q + piv[i] - 1];
  LAPACKE_dpotrs(LAPACK_COL_MAJOR, 'L', rank, nk, Ws, ms, cp, rank);
  for (int q = 0; q < nk; q++)
    for (int i = 0; i < rank; i++) {
      const int a = piv[i] - 1;
      mu[(size_t)m * q + place[a]] = d[a] * cp[(size_t)rank * q + i];
    }
}

/* J_tᵀ (n_free x m) of the m rows with pos[i] >= 0, in row order (their
 * tissue parts compacted into a row set of their own), row[k] the k-th
 * one's index in rows. NULL: out of memory. */
static cholmod_sparse *nh_rows_held_jt(nh_system *s, const nh_rows *rows, const int *pos, int m,
                                       int *row) {
  int slots = 0;
  for (int i = 0; i < rows->m; i++)
    if (pos[i] >= 0) slots += rows->start[i + 1] - rows->start[i];
  nh_rows sub = {.m = m, .cap = m, .n_slots = slots};
  sub.start = nh_calloc((size_t)m + 1, sizeof(int));
  sub.node = nh_calloc((size_t)slots + 1, sizeof(int));
  sub.N = nh_calloc((size_t)slots + 1, sizeof(double));
  sub.dir = nh_calloc(3 * (size_t)m, sizeof(double));
  int *mark = nh_calloc((size_t)(s->n_free ? s->n_free : 1), sizeof(int));
  cholmod_sparse *Jt = NULL;
  if (sub.start && sub.node && sub.N && sub.dir && mark) {
    for (int i = 0, k = 0; i < rows->m; i++) {
      if (pos[i] < 0) continue;
      const int a = rows->start[i], len = rows->start[i + 1] - a;
      sub.start[k + 1] = sub.start[k] + len;
      memcpy(sub.node + sub.start[k], rows->node + a, (size_t)len * sizeof(int));
      memcpy(sub.N + sub.start[k], rows->N + a, (size_t)len * sizeof(double));
      memcpy(sub.dir + 3 * k, rows->dir + 3 * i, 3 * sizeof(double));
      row[k++] = i;
    }
    for (int i = 0; i < s->n_free; i++) mark[i] = -1;
    Jt = nh_rows_tissue_jt(s, &sub, mark);
  }
  free(sub.start), free(sub.node), free(sub.N), free(sub.dir), free(mark);
  return Jt;
}

/* Row i is in set k: the set has columns and holds the row (active NULL: every row). */
static int nh_set_holds(const int *set_ncol, const unsigned char *const *set_active, int k, int i) {
  return set_ncol[k] > 0 && (!set_active[k] || set_active[k][i]);
}

int nh_system_solve_rows_sets(nh_system *s, const nh_rows *rows, int n_sets, const int *set_ncol,
                              const unsigned char *const *set_active, const double *b, double *x,
                              double *mu_out, int *n_used) {
  const int n = s->n_free, mr = rows ? rows->m : 0;
  int ncol = 0;
  for (int k = 0; k < n_sets; k++) ncol += set_ncol[k];
  if (n_used) *n_used = 0;
  if (mu_out && rows) memset(mu_out, 0, sizeof(double) * (size_t)mr * (size_t)ncol);
  if (ncol > 0 && !s->factor_current) NH_TRY(nh_system_factor_later(s));
  /* the union of the sets' active rows: row i at place pos[i] (−1: in none) */
  int *pos = nh_calloc((size_t)(mr ? mr : 1), sizeof(int)), m = 0;
  if (!pos) return NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual (%d rows)", mr);
  for (int i = 0; i < mr; i++) {
    int in = 0;
    for (int k = 0; k < n_sets && !in; k++) in = nh_set_holds(set_ncol, set_active, k, i);
    pos[i] = in ? m++ : -1;
  }
  if (m == 0 || ncol <= 0) {
    free(pos);
    return nh_system_solve_many(s, ncol, b, x);
  }
  int *piv = nh_calloc((size_t)m, sizeof(int));
  int *place = nh_calloc((size_t)m, sizeof(int)), *row = nh_calloc((size_t)m, sizeof(int));
  double *W = nh_calloc((size_t)m * (size_t)m, sizeof(double));  /* the union's, unscaled */
  double *Ws = nh_calloc((size_t)m * (size_t)m, sizeof(double)); /* a set's block, scaled */
  double *d = nh_calloc((size_t)m, sizeof(double));
  double *mu = nh_calloc((size_t)m * (size_t)ncol, sizeof(double)); /* at the union's places */
  double *c = nh_calloc(2 * (size_t)m * (size_t)ncol, sizeof(double)), *cp = c + (size_t)m * ncol;
  /* the second solve's right-hand sides and solutions: J_tᵀ μ and A⁻¹ J_tᵀ μ
   * (ncol columns), or with m < ncol J_tᵀ and G = A⁻¹ J_tᵀ (m columns) */
  const int direct = m < ncol, ncol2 = direct ? m : ncol;
  double *f = nh_calloc((size_t)n * (size_t)ncol2, sizeof(double));
  double *y = nh_calloc((size_t)n * (size_t)ncol2, sizeof(double));
  cholmod_sparse *Jt = NULL;
  int rc = piv && place && row && W && Ws && d && mu && c && f && y
               ? NH_OK
               : NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual (%d rows)", m);
  if (!rc && !(Jt = nh_rows_held_jt(s, rows, pos, m, row)))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual (%d rows)", m);
  if (!rc && direct) {
    const int *Jp = Jt->p, *Ji = Jt->i;
    const double *Jx = Jt->x;
    for (int j = 0; j < m; j++) /* J_tᵀ dense (f was zeroed by calloc) */
      for (int p = Jp[j]; p < Jp[j + 1]; p++) f[(size_t)n * j + Ji[p]] = Jx[p];
    rc = nh_system_solve_two(s, ncol, b, x, m, f, y); /* A⁻¹ b and G in one call */
    for (int j = 0; j < m && !rc; j++)                /* W = J_t G, lower triangle, mirrored */
      for (int i = j; i < m; i++) {
        double v = 0.0;
        for (int p = Jp[i]; p < Jp[i + 1]; p++) v += Jx[p] * y[(size_t)n * j + Ji[p]];
        W[(size_t)j * m + i] = W[(size_t)i * m + j] = v;
      }
  } else if (!rc && !(rc = nh_system_solve_many(s, ncol, b, x)))
    rc = nh_system_compliance_add(s, Jt, W);
  /* Each set's multipliers from its rows' block of W: with D = diag(W)^−½,
   * Pᵀ (D W D) P = L Lᵀ up to rank r, L₁₁ L₁₁ᵀ y₁ = (Pᵀ D J A⁻¹ b)₁, y₂ = 0,
   * μ = D P y. */
  for (int k = 0, c0 = 0; k < n_sets && !rc; c0 += set_ncol[k++]) {
    const int nk = set_ncol[k];
    int ms = 0, rank = 0;
    for (int i = 0; i < mr; i++)
      if (pos[i] >= 0 && nh_set_holds(set_ncol, set_active, k, i)) place[ms++] = pos[i];
    if (ms == 0) continue;
    if (k == 0 && n_used) *n_used = ms;
    rc = nh_dual_factor(W, m, place, ms, d, Ws, piv, &rank);
    if (rc || rank == 0) continue;
    nh_dual_multipliers(Jt, place, ms, d, Ws, piv, rank, n, nk, x + (size_t)n * c0, c, cp,
                        mu + (size_t)m * c0, m);
    for (int q = 0; q < nk && mu_out; q++)
      for (int j = 0; j < m; j++)
        mu_out[(size_t)mr * (c0 + q) + row[j]] = mu[(size_t)m * (c0 + q) + j];
  }
  if (!rc && direct) /* x −= G μ */
    cblas_dgemm(CblasColMajor, CblasNoTrans, CblasNoTrans, n, ncol, m, -1.0, y, n, mu, m, 1.0, x,
                n);
  else if (!rc) {
    for (int q = 0; q < ncol; q++)
      nh_rows_tissue_force(Jt, mu + (size_t)m * q, f + (size_t)n * q, n);
    rc = nh_system_solve_many(s, ncol, f, y);
    for (size_t i = 0; !rc && i < (size_t)n * (size_t)ncol; i++) x[i] -= y[i];
  }
  if (Jt) cholmod_free_sparse(&Jt, &s->cm);
  free(pos), free(place), free(row), free(Ws), free(piv), free(W), free(d), free(mu);
  free(c), free(f), free(y);
  return rc;
}

int nh_system_solve_rows(nh_system *s, const nh_rows *rows, const unsigned char *active, int ncol,
                         const double *b, double *x, double *mu_out, int *n_used) {
  return nh_system_solve_rows_sets(s, rows, 1, &ncol, &active, b, x, mu_out, n_used);
}

/* The constrained dual of one row set for a sequence of right-hand sides
 * (solve.h): the active rows' tissue parts compacted, their compliance W by
 * nh_system_compliance_add (restricted forward solves, once), and the
 * pivoted factor of D W D; each solve is A⁻¹ b, the multipliers, and
 * A⁻¹ J_tᵀ μ: two solves of its own columns, where nh_system_solve_rows
 * forms W (or G = A⁻¹ J_tᵀ) again at every call. */
struct nh_rows_solver {
  int m, mr, rank; /* active rows, all rows, the factor's rank */
  int *row, *place, *piv;
  double *d, *Ws;
  cholmod_sparse *Jt;
};

void nh_rows_solver_destroy(nh_system *s, nh_rows_solver **rs) {
  if (!rs || !*rs) return;
  if ((*rs)->Jt) cholmod_free_sparse(&(*rs)->Jt, &s->cm);
  free((*rs)->row), free((*rs)->place), free((*rs)->piv), free((*rs)->d), free((*rs)->Ws);
  free(*rs);
  *rs = NULL;
}

int nh_rows_solver_create(nh_system *s, const nh_rows *rows, const unsigned char *active,
                          nh_rows_solver **out) {
  *out = NULL;
  if (!s->factor_current) NH_TRY(nh_system_factor_later(s));
  nh_rows_solver *rs = nh_calloc(1, sizeof *rs);
  if (!rs) return NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual");
  const int mr = rows ? rows->m : 0;
  int *pos = nh_calloc((size_t)(mr ? mr : 1), sizeof(int)), m = 0;
  for (int i = 0; pos && i < mr; i++) pos[i] = !active || active[i] ? m++ : -1;
  rs->m = m, rs->mr = mr;
  double *W = nh_calloc((size_t)(m ? m : 1) * (size_t)(m ? m : 1), sizeof(double));
  rs->row = nh_calloc((size_t)(m ? m : 1), sizeof(int));
  rs->place = nh_calloc((size_t)(m ? m : 1), sizeof(int));
  rs->piv = nh_calloc((size_t)(m ? m : 1), sizeof(int));
  rs->d = nh_calloc((size_t)(m ? m : 1), sizeof(double));
  rs->Ws = nh_calloc((size_t)(m ? m : 1) * (size_t)(m ? m : 1), sizeof(double));
  int rc = pos && W && rs->row && rs->place && rs->piv && rs->d && rs->Ws
               ? NH_OK
               : NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual (%d rows)", m);
  for (int k = 0; k < m && !rc; k++) rs->place[k] = k; /* every held row in the one set */
  if (!rc && m > 0 && !(rs->Jt = nh_rows_held_jt(s, rows, pos, m, rs->row)))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual (%d rows)", m);
  if (!rc && m > 0) rc = nh_system_compliance_add(s, rs->Jt, W);
  if (!rc && m > 0) rc = nh_dual_factor(W, m, rs->place, m, rs->d, rs->Ws, rs->piv, &rs->rank);
  free(pos), free(W);
  if (rc) nh_rows_solver_destroy(s, &rs);
  *out = rs;
  return rc;
}

int nh_rows_solver_solve(nh_system *s, const nh_rows_solver *rs, int ncol, const double *b,
                         double *x, double *mu_out) {
  const int n = s->n_free, m = rs->m, k = rs->rank;
  if (mu_out) memset(mu_out, 0, sizeof(double) * (size_t)rs->mr * (size_t)ncol);
  NH_TRY(nh_system_solve_many(s, ncol, b, x));
  if (m == 0 || k == 0) return NH_OK;
  double *mu = nh_calloc((size_t)m * (size_t)ncol, sizeof(double));
  double *c = nh_calloc((size_t)(m + k) * (size_t)ncol, sizeof(double));
  double *f = nh_calloc((size_t)n * (size_t)ncol, sizeof(double));
  double *y = nh_calloc((size_t)n * (size_t)ncol, sizeof(double));
  int rc = mu && c && f && y ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: constrained dual");
  if (!rc) {
    nh_dual_multipliers(rs->Jt, rs->place, m, rs->d, rs->Ws, rs->piv, k, n, ncol, x, c,
                        c + (size_t)m * ncol, mu, m);
    for (int q = 0; q < ncol; q++)
      nh_rows_tissue_force(rs->Jt, mu + (size_t)m * q, f + (size_t)n * q, n);
    rc = nh_system_solve_many(s, ncol, f, y);
  }
  for (size_t i = 0; !rc && i < (size_t)n * (size_t)ncol; i++) x[i] -= y[i];
  for (int q = 0; !rc && mu_out && q < ncol; q++)
    for (int j = 0; j < m; j++) mu_out[(size_t)rs->mr * q + rs->row[j]] = mu[(size_t)m * q + j];
  free(mu), free(c), free(f), free(y);
  return rc;
}
