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
 * increments obey the homogeneous rows. S is computed with CHOLMOD's sparse
 * solves (cholmod_spsolve with CHOLMOD_P, CHOLMOD_L, CHOLMOD_D), which exploit
 * the sparsity of Jᵀ; W = Sᵀ (D⁻¹ S) by a sparse product, then densified.
 * W is built once per factorisation. Its Cholesky factorisation fails only
 * when rows are linearly dependent, reported as a numerical failure. */
#include "solve/system_impl.h"

#include <math.h>
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

/* W = J A⁻¹ Jᵀ (Algorithm 3) for the rows Jᵀ (n_free x m, CSC), added to the
 * dense column-major W (m x m): S = L⁻¹ P Jᵀ by sparse solves, W += Sᵀ D⁻¹ S. */
/* Columns of J per block of the compliance: a stop request (SIGINT,
 * SIGTERM) is honoured between blocks. Each column's arithmetic is the
 * same as in one CHOLMOD call over all of them. */
#define NH_COMPLIANCE_BLOCK 4

int nh_system_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W) {
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
  for (int b = 0; b < nb && !rc && !failed; b++) {
    cholmod_sparse *next = all ? cholmod_horzcat(all, S[b], 1, cm) : cholmod_copy_sparse(S[b], cm);
    cholmod_free_sparse(&all, cm);
    all = next;
    failed = !all;
  }
  if (!rc && !failed && nb) failed = !(St = cholmod_transpose(all, 1, cm));
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

/* W = J A⁻¹ Jᵀ of the hanging rows and its dense Cholesky factor, in place. */
static int nh_compliance_build(nh_system *s) {
  int m = s->n_rows;
  memset(s->W, 0, sizeof(double) * (size_t)m * (size_t)m);
  int rc = nh_system_compliance_add(s, s->Jt, s->W);
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
