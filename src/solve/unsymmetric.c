/* unsymmetric.c — the static Newton's solve with the consistent tangent
 * (docs/theory.md §3, "Quasi-static Newton"): the assembly keeps the
 * tangent's symmetric part S in A (upper triangle, as CHOLMOD wants it) and
 * its skew-symmetric part N on the same pattern (assemble.c); here the full
 * matrix K = S + N is written in compressed columns and solved by UMFPACK's
 * LU (SuiteSparse, beside CHOLMOD). */
#include "solve/system_impl.h"

#include <stdlib.h>
#include <string.h>
#include <umfpack.h>

int nh_system_keep_skew(nh_system *s) {
  if (s->skew) return NH_OK;
  size_t nz = (size_t)((int *)s->A->p)[s->n_free];
  s->skew = nh_calloc(nz ? nz : 1, sizeof(double));
  if (!s->skew) return NH_ERROR(NH_ERR_MEMORY, "out of memory: the tangent's skew part");
  s->a_valid = 0; /* the next assembly fills it */
  return NH_OK;
}

/* K = S + N in full compressed columns: entry p of A's upper triangle, at
 * (i, j) with i ≤ j, holds S_ij and N_ij; K_ij = S_ij + N_ij and
 * K_ji = S_ij − N_ij. */
static void nh_full_tangent(const nh_system *s, int *Fp, int *Fi, double *Fx, int *fill) {
  const int n = s->n_free, *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x, *N = s->skew;
  for (int j = 0; j < n; j++)
    for (int p = Ap[j]; p < Ap[j + 1]; p++) {
      Fp[j + 1]++;
      if (Ai[p] != j) Fp[Ai[p] + 1]++;
    }
  for (int j = 0; j < n; j++) Fp[j + 1] += Fp[j];
  for (int j = 0; j < n; j++)
    for (int p = Ap[j]; p < Ap[j + 1]; p++) {
      int i = Ai[p], q = Fp[j] + fill[j]++;
      Fi[q] = i, Fx[q] = Ax[p] + N[p];
      if (i != j) {
        q = Fp[i] + fill[i]++;
        Fi[q] = j, Fx[q] = Ax[p] - N[p];
      }
    }
}

int nh_system_solve_lu(nh_system *s, const double *b, double *x, double *t_factor) {
  const int n = s->n_free, nz = ((int *)s->A->p)[n];
  const size_t full = (size_t)(2 * nz - n > 0 ? 2 * nz - n : 1);
  NH_CHECK(s->skew && s->n_rows == 0, NH_ERR_INTERNAL,
           "the LU solve needs the skew part and no multiplier rows");
  int *Fp = nh_calloc((size_t)n + 1, sizeof(int)), *Fi = nh_calloc(full, sizeof(int));
  int *fill = nh_calloc((size_t)n + 1, sizeof(int));
  double *Fx = nh_calloc(full, sizeof(double));
  int rc = NH_OK;
  if (!Fp || !Fi || !fill || !Fx) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the full tangent (%zu entries)", full);
    goto out;
  }
  nh_full_tangent(s, Fp, Fi, Fx, fill);
  void *symbolic = NULL, *numeric = NULL;
  double t0 = nh_time_now();
  int st = umfpack_di_symbolic(n, n, Fp, Fi, Fx, &symbolic, NULL, NULL);
  if (st == UMFPACK_OK) st = umfpack_di_numeric(Fp, Fi, Fx, symbolic, &numeric, NULL, NULL);
  if (t_factor) *t_factor = nh_time_now() - t0;
  if (st == UMFPACK_OK) st = umfpack_di_solve(UMFPACK_A, Fp, Fi, Fx, x, b, numeric, NULL, NULL);
  umfpack_di_free_symbolic(&symbolic);
  umfpack_di_free_numeric(&numeric);
  if (st != UMFPACK_OK)
    rc = NH_ERROR(NH_ERR_NUMERIC, "the consistent tangent's LU failed (UMFPACK status %d%s)", st,
                  st == UMFPACK_WARNING_singular_matrix ? ": singular" : "");
out:
  free(Fp), free(Fi), free(fill), free(Fx);
  return rc;
}
