/* test_cholmod_teams — nh_cholmod_factorize (solve/cholesky.c): the OpenMP
 * teams CHOLMOD opens inside cholmod_factorize run on one thread, and the
 * factor is the plain call's.
 * The matrix: the 7-point Laplacian of a 14³ grid plus the identity (2744
 * unknowns, SPD), above CHOLMOD's thresholds for its teams (order > 128,
 * supernodes above 64 columns). Observable: libgomp starts its pool
 * threads at the first team of more than one thread and keeps them, so the
 * process's thread count (/proc/self/task) tells whether a team ran.
 *  1. nh_cholmod_factorize first, in a process that has opened no team:
 *     the thread count does not change, and the max-active-levels ICV is
 *     restored (3 set before, 3 after).
 *  2. The plain cholmod_factorize of the same matrix then starts threads
 *     (the precondition of 1: without it 1 would pass for a CHOLMOD built
 *     without OpenMP) and gives a factor whose values equal 1's bitwise.
 *  3. Inside a parallel region (one thread of a team of 2 calls it) the
 *     factor is again the same, and the ICV untouched.
 * Run with OMP_NUM_THREADS=2 and OMP_THREAD_LIMIT=2 (tests/numerics.cmake). */
#include "check.h"
#include "solve/solve.h"

#include <cholmod.h>
#include <dirent.h>
#include <omp.h>
#include <string.h>

#define G 14

static int threads_now(void) {
  DIR *d = opendir("/proc/self/task");
  int n = 0;
  if (!d) return -1;
  for (struct dirent *e; (e = readdir(d));) n += e->d_name[0] != '.';
  closedir(d);
  return n;
}

/* The upper triangle of the Laplacian plus I, column by column. */
static cholmod_sparse *laplacian(cholmod_common *cm) {
  const int n = G * G * G;
  cholmod_sparse *A = cholmod_allocate_sparse(n, n, 4 * (size_t)n, 1, 1, 1, CHOLMOD_REAL, cm);
  if (!A) return NULL;
  int *p = A->p, *i = A->i, nz = 0;
  double *x = A->x;
  for (int c = 0; c < n; c++) {
    const int cx = c % G, cy = c / G % G, cz = c / (G * G);
    p[c] = nz;
    if (cz > 0) i[nz] = c - G * G, x[nz++] = -1.0;
    if (cy > 0) i[nz] = c - G, x[nz++] = -1.0;
    if (cx > 0) i[nz] = c - 1, x[nz++] = -1.0;
    i[nz] = c, x[nz++] = 7.0;
  }
  p[n] = nz;
  return A;
}

/* The numeric values of a supernodal factor. */
static int same_factor(const cholmod_factor *a, const cholmod_factor *b) {
  if (!a->is_super || !b->is_super || a->xsize != b->xsize) return 0;
  return memcmp(a->x, b->x, sizeof(double) * a->xsize) == 0;
}

int main(void) {
  cholmod_common cm;
  cholmod_start(&cm);
  cm.supernodal = CHOLMOD_SUPERNODAL;
  cholmod_sparse *A = laplacian(&cm);
  CHECK(A != NULL, "the matrix");
  cholmod_factor *L1 = cholmod_analyze(A, &cm), *L2 = cholmod_copy_factor(L1, &cm);
  cholmod_factor *L3 = cholmod_copy_factor(L1, &cm);
  CHECK(L1 && L2 && L3, "the analysis");

  omp_set_max_active_levels(3);
  const int t0 = threads_now();
  CHECK(nh_cholmod_factorize(A, L1, &cm) && cm.status == CHOLMOD_OK, "status %d", cm.status);
  CHECK(threads_now() == t0, "nh_cholmod_factorize started threads: %d -> %d", t0, threads_now());
  CHECK(omp_get_max_active_levels() == 3, "max active levels %d, set 3",
        omp_get_max_active_levels());

  CHECK(cholmod_factorize(A, L2, &cm) && cm.status == CHOLMOD_OK, "status %d", cm.status);
  CHECK(threads_now() > t0,
        "the plain cholmod_factorize started no thread (%d): CHOLMOD opens no team here, so part "
        "1 shows nothing (OMP_THREAD_LIMIT=2 and OMP_NUM_THREADS=2 expected)",
        threads_now());
  CHECK(same_factor(L1, L2), "the factor differs from cholmod_factorize's");

  int ok = 0;
#pragma omp parallel num_threads(2)
  {
#pragma omp single
    ok = nh_cholmod_factorize(A, L3, &cm) && cm.status == CHOLMOD_OK;
  }
  CHECK(ok, "inside a parallel region: status %d", cm.status);
  CHECK(same_factor(L1, L3), "inside a parallel region the factor differs");
  CHECK(omp_get_max_active_levels() == 3, "max active levels %d after the parallel call",
        omp_get_max_active_levels());

  cholmod_free_factor(&L1, &cm), cholmod_free_factor(&L2, &cm), cholmod_free_factor(&L3, &cm);
  cholmod_free_sparse(&A, &cm);
  cholmod_finish(&cm);
  return nh_test_failures ? 1 : 0;
}
