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

#include <omp.h>
#include <string.h>

/* A CHOLMOD failure in `what`, by its status: out of memory and too large
 * named as such (NH_ERR_MEMORY), anything else by its number. */
static int nh_cholmod_failed(const nh_system *s, const char *what) {
  if (s->cm.status == CHOLMOD_OUT_OF_MEMORY)
    return NH_ERROR(NH_ERR_MEMORY,
                    "CHOLMOD ran out of memory in the %s of %d unknowns (the factor needs "
                    "about %.3g MB)",
                    what, s->n_free, s->L ? 8e-6 * s->cm.lnz : 0.0);
  if (s->cm.status == CHOLMOD_TOO_LARGE)
    return NH_ERROR(NH_ERR_MEMORY, "CHOLMOD: the %s of %d unknowns is too large for its integers",
                    what, s->n_free);
  return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD %s failed (status %d)", what, s->cm.status);
}

int nh_cholmod_factorize(cholmod_sparse *A, cholmod_factor *L, cholmod_common *cm) {
  if (omp_in_parallel()) return cholmod_factorize(A, L, cm);
  const int levels = omp_get_max_active_levels();
  omp_set_max_active_levels(0); /* every team opened meanwhile has one thread */
  int ok = cholmod_factorize(A, L, cm);
  omp_set_max_active_levels(levels);
  return ok;
}

int nh_system_factor(nh_system *s) {
  if (!s->L) {
    s->L = cholmod_analyze(s->A, &s->cm);
    if (!s->L || s->cm.status < CHOLMOD_OK) return nh_cholmod_failed(s, "symbolic analysis");
    /* operation counts for the renewal rule (reuse.c): the analysis reports
     * the factorisation's flops and nnz(L); A is stored as one triangle */
    s->flops_factor = s->cm.fl;
    s->flops_solve = 4.0 * s->cm.lnz;
    s->flops_iteration = s->flops_solve + 4.0 * (double)cholmod_nnz(s->A, &s->cm);
  }
  s->W_valid = 0; /* the compliance belongs to the previous A */
  s->factor_serial++;
  s->factor_current = 0;
  int ok = nh_cholmod_factorize(s->A, s->L, &s->cm);
  s->not_posdef = s->cm.status == CHOLMOD_NOT_POSDEF;
  if (s->not_posdef) { /* the column in A's order, its node, cells and the likely cause */
    const int k = (int)s->L->minor, *perm = s->L->Perm;
    const int col = perm && k < s->n_free ? perm[k] : k;
    char where[1536] = "";
    nh_system_diagnose(s, s->u_assembled, col < s->n_free ? s->dof_of[col] : -1, NULL, NULL, where,
                       sizeof where);
    return NH_ERROR(NH_ERR_NUMERIC,
                    "the system matrix is not positive definite (CHOLMOD stopped at column %d "
                    "of %d); the pivot is%s",
                    k, s->n_free, where);
  }
  if (!ok || s->cm.status < CHOLMOD_OK) return nh_cholmod_failed(s, "factorisation");
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
    return nh_cholmod_failed(s, "solve");
  memcpy(x, s->X->x, sizeof(double) * (size_t)s->n_free);
  return NH_OK;
}

/* OpenBLAS's, when the BLAS linked is OpenBLAS (a weak reference: NULL otherwise). */
#pragma weak openblas_get_num_threads
int openblas_get_num_threads(void);

int nh_system_blas_team(const nh_system *s) {
  /* a BLAS with threads of its own (OPENBLAS_NUM_THREADS > 1) gets the cores instead */
  if (openblas_get_num_threads && openblas_get_num_threads() > 1) return 1;
  return s->threads > 0 ? s->threads : omp_get_max_threads();
}

/* One chunk of columns [c0, c1) of the two blocks (b1, x1: ncol1 columns;
 * b2, x2: the rest), solved with the common cm. */
static int nh_solve_chunk(nh_system *s, cholmod_common *cm, int c0, int c1, int ncol1,
                          const double *b1, double *x1, const double *b2, double *x2) {
  const size_t n = (size_t)s->n_free;
  cholmod_dense *B = cholmod_allocate_dense(n, (size_t)(c1 - c0), n, CHOLMOD_REAL, cm);
  if (!B) return CHOLMOD_OUT_OF_MEMORY;
  double *Bx = B->x;
  for (int c = c0; c < c1; c++)
    memcpy(Bx + n * (size_t)(c - c0), c < ncol1 ? b1 + n * c : b2 + n * (size_t)(c - ncol1),
           sizeof(double) * n);
  cholmod_dense *X = cholmod_solve(CHOLMOD_A, s->L, B, cm);
  cholmod_free_dense(&B, cm);
  if (!X) return cm->status < CHOLMOD_OK ? cm->status : CHOLMOD_INVALID;
  const double *Xx = X->x;
  for (int c = c0; c < c1; c++)
    memcpy(c < ncol1 ? x1 + n * c : x2 + n * (size_t)(c - ncol1), Xx + n * (size_t)(c - c0),
           sizeof(double) * n);
  cholmod_free_dense(&X, cm);
  return CHOLMOD_OK;
}

/* The number of chunks the columns of a many-column solve are cut into: a
 * power of two, by the number of columns alone (never by the threads), so
 * that every column is solved by the same calls on any number of threads
 * and x is bitwise the same; each chunk at least NH_SOLVE_CHUNK_COLUMNS
 * columns, at most NH_SOLVE_CHUNKS chunks. */
enum { NH_SOLVE_CHUNK_COLUMNS = 16, NH_SOLVE_CHUNKS = 4 };
static int nh_solve_chunks(int ncol) {
  int k = 1;
  while (2 * k <= NH_SOLVE_CHUNKS && ncol >= 2 * k * NH_SOLVE_CHUNK_COLUMNS) k *= 2;
  return k;
}

int nh_system_solve_two(nh_system *s, int ncol1, const double *b1, double *x1, int ncol2,
                        const double *b2, double *x2) {
  const int ncol = ncol1 + ncol2;
  if (ncol <= 0) return NH_OK;
  const size_t n = (size_t)s->n_free;
  if (!s->L && s->inh) {
    for (int c = 0; c < ncol; c++)
      NH_TRY(nh_inherit_apply(s, c < ncol1 ? b1 + n * c : b2 + n * (size_t)(c - ncol1),
                              c < ncol1 ? x1 + n * c : x2 + n * (size_t)(c - ncol1)));
    return NH_OK;
  }
  const int nch = nh_solve_chunks(ncol);
  const int threads = omp_in_parallel() ? 1 : nh_system_blas_team(s);
  const int nt = threads < nch ? threads : nch;
  int status = CHOLMOD_OK;
#pragma omp parallel num_threads(nt) if (nt > 1)
  {
    /* thread 0 solves with the system's common, the others with their own */
    cholmod_common own, *cm = &s->cm;
    if (omp_get_thread_num() > 0) {
      cholmod_start(&own);
      own.print = 0, own.error_handler = NULL;
      cm = &own;
    }
#pragma omp for schedule(static)
    for (int k = 0; k < nch; k++) {
      int st = nh_solve_chunk(s, cm, k * ncol / nch, (k + 1) * ncol / nch, ncol1, b1, x1, b2, x2);
      if (st != CHOLMOD_OK) {
#pragma omp atomic write
        status = st;
      }
    }
    if (cm == &own) cholmod_finish(&own);
  }
  if (status == CHOLMOD_OK) return NH_OK;
  s->cm.status = status; /* a chunk's, reported as the system's own solves are */
  return nh_cholmod_failed(s, "solve");
}

int nh_system_solve_many(nh_system *s, int ncol, const double *b, double *x) {
  return nh_system_solve_two(s, ncol, b, x, 0, NULL, NULL);
}
