/* cholesky.c — CHOLMOD factorisation and solves of A (docs/theory.md §4).
 *
 * The symbolic analysis (fill-reducing ordering, elimination tree,
 * supernodes) depends only on the pattern, so it is done on the first
 * factorisation after nh_system_create and reused by every later numeric
 * factorisation. CHOLMOD returns TRUE from cholmod_factorize even when A is
 * not positive definite; the status in cm.status is what tells, and the
 * column where it failed is L->minor. Solves use cholmod_solve2 with
 * workspace kept in the system, so a step allocates nothing. */
#include "solve/system_impl.h"

#include <string.h>

int nh_system_factor(nh_system *s) {
  if (!s->L) {
    s->L = cholmod_analyze(s->A, &s->cm);
    if (!s->L || s->cm.status < CHOLMOD_OK)
      return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD symbolic analysis failed (status %d)", s->cm.status);
    /* operation counts for the renewal rule (reuse.c): the analysis reports
     * the factorisation's flops and nnz(L); A is stored as one triangle */
    s->flops_factor = s->cm.fl;
    s->flops_solve = 4.0 * s->cm.lnz;
    s->flops_iteration = s->flops_solve + 4.0 * (double)cholmod_nnz(s->A, &s->cm);
  }
  s->W_valid = 0; /* the compliance belongs to the previous A */
  s->factor_current = 0;
  int ok = cholmod_factorize(s->A, s->L, &s->cm);
  if (s->cm.status == CHOLMOD_NOT_POSDEF)
    return NH_ERROR(
        NH_ERR_NUMERIC,
        "the system matrix is not positive definite (CHOLMOD stopped at column %d of %d)",
        (int)s->L->minor, s->n_free);
  if (!ok || s->cm.status < CHOLMOD_OK)
    return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD factorisation failed (status %d)", s->cm.status);
  s->factor_current = 1;
  nh_inherit_free(s); /* the system's own factor from now on */
  memcpy(s->u_factored, s->u_assembled, sizeof(double) * 3 * (size_t)s->n_nodes);
  memcpy(s->c_factored, s->c_assembled, sizeof s->c_factored);
  s->factor_age = 0;
  s->refactor_due = 0;
  return NH_OK;
}

int nh_system_solve(nh_system *s, const double *b, double *x) {
  if (!s->L && s->inh) return nh_inherit_apply(s, b, x); /* the preconditioner (inherit.c) */
  if (!s->B) {
    s->B = cholmod_allocate_dense((size_t)s->n_free, 1, (size_t)s->n_free, CHOLMOD_REAL, &s->cm);
    if (!s->B) return NH_ERROR(NH_ERR_MEMORY, "out of memory: solve workspace");
  }
  memcpy(s->B->x, b, sizeof(double) * (size_t)s->n_free);
  if (!cholmod_solve2(CHOLMOD_A, s->L, s->B, NULL, &s->X, NULL, &s->Y, &s->E, &s->cm))
    return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD solve failed (status %d)", s->cm.status);
  memcpy(x, s->X->x, sizeof(double) * (size_t)s->n_free);
  return NH_OK;
}

int nh_system_solve_many(nh_system *s, int ncol, const double *b, double *x) {
  if (ncol <= 0) return NH_OK;
  const size_t n = (size_t)s->n_free;
  if (!s->L && s->inh) {
    for (int c = 0; c < ncol; c++) NH_TRY(nh_inherit_apply(s, b + n * c, x + n * c));
    return NH_OK;
  }
  cholmod_dense *B = cholmod_allocate_dense(n, (size_t)ncol, n, CHOLMOD_REAL, &s->cm);
  if (!B) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d right-hand sides", ncol);
  memcpy(B->x, b, sizeof(double) * n * (size_t)ncol);
  cholmod_dense *X = cholmod_solve(CHOLMOD_A, s->L, B, &s->cm);
  cholmod_free_dense(&B, &s->cm);
  if (!X) return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD solve failed (status %d)", s->cm.status);
  memcpy(x, X->x, sizeof(double) * n * (size_t)ncol);
  cholmod_free_dense(&X, &s->cm);
  return NH_OK;
}
