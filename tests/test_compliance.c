/* test_compliance — the compliance W = J A⁻¹ Jᵀ of constraint rows
 * (solve/compliance.c) against an independent computation.
 *
 * A clamped box of 14 x 10 x 10 hexahedra (4950 unknowns: CHOLMOD chooses
 * a supernodal factor, checked) carries m = 203 point rows (not a multiple
 * of the 16 columns of a block), each J_i = n_iᵀ N(ξ_i) on the nodes of a
 * cell: pseudo-random cells, natural coordinates and unit directions, a
 * quarter of them in the cells next to the clamped face (some of their
 * nodes fixed). The reference is W_ref = J X with X = A⁻¹ Jᵀ from dense
 * solves with A (nh_system_solve_many: forward and back substitution, no
 * sparsity exploited). Checked, with tolerance 1e-10 max|W_ref| (round-off
 * of solves with a well-conditioned A is ~1e-14 relative):
 *   - the supernodal path (forward solves on the elimination-tree paths,
 *     supernode by supernode, W = Yᵀ Y): equal to W_ref and symmetric;
 *   - CHOLMOD's sparse solves on the same factor (the other path) equal
 *     to W_ref;
 *   - a simplicial LDLᵀ factor of the same A (the path small systems
 *     take) equal to W_ref;
 *   - W added to, not overwritten (W += ...: (W + W) − W equals W_ref);
 *   - a row set with every column in its own block (m = 1) and the empty set;
 *   - the many-column solves the reference uses (nh_system_solve_many,
 *     nh_system_solve_two): 1 and 2 threads bitwise equal, two blocks
 *     bitwise one, each column the single solve's to 1e-12;
 *   - each W again on 2 OpenMP threads (s->threads): bitwise equal to the 1
 *     thread's W (the supernodal path cuts the work of its widest supernodes
 *     into tasks independently of the threads: here 2 supernodes with 77 %
 *     of the flops, both halves of W written by the tasks).
 * NH_VERBOSE=1 prints the agreements and the time of each path.
 * NH_COMPLIANCE_SIZE=NX,NY,NZ,M: instead, one supernodal run of M rows on an
 * NX x NY x NZ box (1 cm cells), checked as above, then W timed 5 times on 1
 * and 2 threads, with each run's CPU split between this thread and the others
 * (docs/performance.md: 20,25,19,740). */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/system_impl.h"

#include <string.h>
#include <time.h>

static int verbose = 0, repeat = 0;
static unsigned long long rng = 88172645463325252ULL;

static double uniform(void) { /* xorshift64 in [0, 1) */
  rng ^= rng << 13, rng ^= rng >> 7, rng ^= rng << 17;
  return (double)(rng >> 11) / 9007199254740992.0;
}

/* Jᵀ (n_free x m) of m point rows in pseudo-random cells of an nx x ny x nz box. */
static cholmod_sparse *rows_create(nh_system *s, const nh_mesh *mesh, int m, const int grid[3]) {
  cholmod_sparse *Jt = cholmod_allocate_sparse((size_t)s->n_free, (size_t)m, 24 * (size_t)m + 1, 1,
                                               1, 0, CHOLMOD_REAL, &s->cm);
  int *Jp = Jt->p, *Ji = Jt->i, pos = 0;
  double *Jx = Jt->x;
  for (int r = 0; r < m; r++) {
    Jp[r] = pos;
    int l = (int)(uniform() * mesh->n_leaves);
    if (r % 4 == 0) /* a cell at x = max: clamped face */
      l = (int)(uniform() * grid[1] * grid[2]) * grid[0] + grid[0] - 1;
    if (l >= mesh->n_leaves) l = mesh->n_leaves - 1;
    const int c = mesh->leaves[l];
    double xi[3], N[8], n[3], len = 0.0;
    for (int k = 0; k < 3; k++) xi[k] = 2.0 * uniform() - 1.0, n[k] = 2.0 * uniform() - 1.0;
    for (int k = 0; k < 3; k++) len += n[k] * n[k];
    for (int k = 0; k < 3; k++) n[k] /= sqrt(len);
    nh_hex_shape(xi, N);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) {
        int f = s->free_of[3 * mesh->cells[8 * c + a] + k];
        if (f >= 0) Ji[pos] = f, Jx[pos++] = N[a] * n[k];
      }
  }
  Jp[m] = pos;
  cholmod_sort(Jt, &s->cm);
  return Jt;
}

/* W_ref = J A⁻¹ Jᵀ by dense solves. */
static void reference(nh_system *s, cholmod_sparse *Jt, double *W) {
  const int n = s->n_free, m = (int)Jt->ncol;
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  double *B = calloc((size_t)n * m, sizeof(double)), *X = calloc((size_t)n * m, sizeof(double));
  for (int j = 0; j < m; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) B[(size_t)j * n + Ji[p]] = Jx[p];
  CHECK_OK(nh_system_solve_many(s, m, B, X));
  for (int j = 0; j < m; j++)
    for (int i = 0; i < m; i++) {
      double v = 0.0;
      for (int p = Jp[i]; p < Jp[i + 1]; p++) v += Jx[p] * X[(size_t)j * n + Ji[p]];
      W[(size_t)j * m + i] = v;
    }
  free(B), free(X);
}

static double thread_cpu(void) {
  struct timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double max_abs(const double *a, size_t n) {
  double v = 0.0;
  for (size_t i = 0; i < n; i++) v = fmax(v, fabs(a[i]));
  return v;
}

static void compare(const double *W, const double *ref, int m, const char *what) {
  const double tol = 1e-10 * max_abs(ref, (size_t)m * m);
  double worst = 0.0;
  int bad = -1;
  for (size_t k = 0; k < (size_t)m * m; k++) {
    double d = fabs(W[k] - ref[k]);
    if (!(d <= worst)) worst = d, bad = (int)k;
  }
  if (verbose) printf("%-40s max |W - W_ref| = %.3g (max |W_ref| %.3g)\n", what, worst, tol * 1e10);
  if (bad >= 0) CHECK_CLOSE(W[bad], ref[bad], tol, what);
}

/* W of m rows on a clamped box of grid[0] x grid[1] x grid[2] cells of 1 cm. */
/* The many-column solves (nh_system_solve_many, _two) on the dense Jᵀ: on
 * 1 and 2 threads bitwise the same (the columns' chunks depend on their
 * number alone, so each column goes through the same calls), two blocks
 * bitwise the same as one of all their columns, and each column the single
 * solve's to 1e-12 of max |X|. (On this system the chunks' widths do not
 * change the bits at all: one chunk of all 203 columns was measured bitwise
 * the same; narrow blocks, which the BLAS may give other kernels, can.) */
static void many_columns(nh_system *s, cholmod_sparse *Jt) {
  const int n = s->n_free, m = (int)Jt->ncol, m1 = m / 5;
  const size_t nm = (size_t)n * m;
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  double *B = calloc(nm, sizeof(double)), *X1 = calloc(nm, sizeof(double));
  double *X2 = calloc(nm, sizeof(double)), *X3 = calloc(nm, sizeof(double));
  for (int j = 0; j < m; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) B[(size_t)j * n + Ji[p]] = Jx[p];
  s->threads = 1;
  CHECK_OK(nh_system_solve_many(s, m, B, X1));
  s->threads = 2;
  CHECK_OK(nh_system_solve_many(s, m, B, X2));
  CHECK_OK(nh_system_solve_two(s, m1, B, X3, m - m1, B + (size_t)n * m1, X3 + (size_t)n * m1));
  s->threads = 0;
  size_t d12 = 0, d13 = 0;
  for (size_t k = 0; k < nm; k++) d12 += X1[k] != X2[k], d13 += X1[k] != X3[k];
  CHECK(d12 == 0, "%d columns on 2 threads differ from 1 thread in %zu of %zu entries", m, d12, nm);
  CHECK(d13 == 0, "two blocks (%d + %d columns) differ from one in %zu of %zu entries", m1, m - m1,
        d13, nm);
  double scale = max_abs(X1, nm), worst = 0.0, *x = calloc((size_t)n, sizeof(double));
  for (int j = 0; j < m; j++) {
    CHECK_OK(nh_system_solve(s, B + (size_t)n * j, x));
    for (int i = 0; i < n; i++) worst = fmax(worst, fabs(x[i] - X1[(size_t)n * j + i]));
  }
  CHECK(worst <= 1e-12 * scale, "many columns against single solves: %.3g of max |X| %.3g",
        worst / scale, scale);
  if (verbose)
    printf("many columns (%d): 1 and 2 threads bitwise, single solves %.2e\n", m, worst / scale);
  free(B), free(X1), free(X2), free(X3), free(x);
}

static void run(int m, int supernodal, const int grid[3]) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.01 * grid[0], 0.01 * grid[1], 0.01 * grid[2]};
  nh_mesh *mesh;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &mesh));
  nh_material mat = {3000, 0.45, 1040, NH_FORMULATION_BBAR};
  nh_tissue *tissue;
  CHECK_OK(nh_tissue_create(mesh, &mat, &tissue));
  const int nn = mesh->n_nodes;
  unsigned char *fixed = calloc((size_t)nn, 1);
  for (int i = 0; i < nn; i++) fixed[i] = mesh->X[3 * i] > hi[0] - 1e-9;
  nh_system *s;
  CHECK_OK(nh_system_create(tissue, fixed, NULL, &s));
  double *u = calloc(3 * (size_t)nn, sizeof(double)), *f = calloc(3 * (size_t)nn, sizeof(double));
  for (int i = 0; i < 3 * nn; i++) u[i] = 1e-3 * (uniform() - 0.5); /* rotated elements */
  nh_system_assemble(s, u, NULL, 1.0, 0.05 * 0.05, f, NULL, 1);
  if (!supernodal) s->cm.supernodal = CHOLMOD_SIMPLICIAL;
  CHECK_OK(nh_system_factor(s));
  CHECK(s->L->is_super == supernodal, "factor supernodal %d, want %d", (int)s->L->is_super,
        supernodal);
  cholmod_sparse *Jt = rows_create(s, mesh, m, grid);
  const size_t mm = m > 0 ? (size_t)m * m : 1;
  double *ref = calloc(mm, sizeof(double)), *W1 = calloc(mm, sizeof(double)),
         *W2 = calloc(mm, sizeof(double));
  reference(s, Jt, ref);
  char what[80];
  s->threads = 1;
  double t0 = nh_time_now(), c0 = (double)clock() / CLOCKS_PER_SEC;
  CHECK_OK(nh_system_compliance_add(s, Jt, W1));
  double t1 = nh_time_now(), c1 = (double)clock() / CLOCKS_PER_SEC;
  snprintf(what, sizeof what, "%s, m = %d, %d free unknowns, 1 thread",
           supernodal ? "supernodal" : "simplicial", m, s->n_free);
  compare(W1, ref, m, what);
  if (verbose) printf("  %.1f ms (CPU %.1f ms)\n", 1e3 * (t1 - t0), 1e3 * (c1 - c0));
  /* 2 threads: bitwise the same W (the tasks' cut does not depend on them) */
  s->threads = 2;
  t0 = nh_time_now(), c0 = (double)clock() / CLOCKS_PER_SEC;
  CHECK_OK(nh_system_compliance_add(s, Jt, W2));
  t1 = nh_time_now(), c1 = (double)clock() / CLOCKS_PER_SEC;
  snprintf(what, sizeof what, "%s, m = %d, 2 threads", supernodal ? "supernodal" : "simplicial", m);
  compare(W2, ref, m, what);
  if (verbose) printf("  %.1f ms (CPU %.1f ms)\n", 1e3 * (t1 - t0), 1e3 * (c1 - c0));
  int differ = 0;
  for (size_t k = 0; k < (size_t)m * m; k++) differ += W1[k] != W2[k];
  CHECK(differ == 0, "W with 2 threads differs from 1 thread in %d of %zu entries", differ,
        (size_t)m * m);
  for (int rep = 0; rep < repeat; rep++) /* NH_COMPLIANCE_SIZE: the times, least of `repeat` */
    for (int nt = 1; nt <= 2; nt++) {
      memset(W2, 0, sizeof(double) * mm);
      s->threads = nt;
      double m0 = thread_cpu();
      t0 = nh_time_now(), c0 = (double)clock() / CLOCKS_PER_SEC;
      CHECK_OK(nh_system_compliance_add(s, Jt, W2));
      t1 = nh_time_now(), c1 = (double)clock() / CLOCKS_PER_SEC;
      double m1 = thread_cpu();
      /* CPU of this (the master) thread and of the others: on a machine whose
       * cores are taken by other jobs the wall time says little; the larger
       * of the two bounds the wall time on idle cores from below */
      printf("threads %d: wall %.1f ms, CPU %.1f ms (master %.1f, others %.1f)\n", nt,
             1e3 * (t1 - t0), 1e3 * (c1 - c0), 1e3 * (m1 - m0), 1e3 * (c1 - c0 - (m1 - m0)));
    }
  s->threads = 0;
  if (supernodal && !repeat) {
    int asym = 0;
    for (int i = 0; i < m; i++)
      for (int j = 0; j < i; j++) asym += W1[(size_t)i * m + j] != W1[(size_t)j * m + i];
    CHECK(asym == 0, "W not symmetric: %d pairs differ", asym);
    /* W += ...: added to what W holds (here W itself: 2 W to round-off) */
    memcpy(W2, W1, sizeof(double) * mm);
    CHECK_OK(nh_system_compliance_add(s, Jt, W2));
    for (size_t k = 0; k < (size_t)m * m; k++) W2[k] -= W1[k];
    snprintf(what, sizeof what, "W + W - W, m = %d", m);
    compare(W2, ref, m, what);
    memset(W2, 0, sizeof(double) * mm);
    t0 = nh_time_now(), c0 = (double)clock() / CLOCKS_PER_SEC;
    CHECK_OK(nh_system_compliance_add_spsolve(s, Jt, W2));
    t1 = nh_time_now(), c1 = (double)clock() / CLOCKS_PER_SEC;
    snprintf(what, sizeof what, "spsolve on the supernodal factor, m = %d", m);
    compare(W2, ref, m, what);
    if (verbose) printf("  %.1f ms (CPU %.1f ms)\n", 1e3 * (t1 - t0), 1e3 * (c1 - c0));
    if (m > 1) many_columns(s, Jt);
  }
  free(ref), free(W1), free(W2), free(u), free(f), free(fixed);
  cholmod_free_sparse(&Jt, &s->cm);
  nh_system_destroy(&s);
  nh_tissue_destroy(&tissue);
  nh_mesh_destroy(&mesh);
}

int main(void) {
  verbose = getenv("NH_VERBOSE") != NULL;
  /* NH_COMPLIANCE_SIZE=nx,ny,nz,m: one supernodal run at that size instead
   * (docs/performance.md: 20,25,19,740, with NH_VERBOSE=1 for the times) */
  const char *size = getenv("NH_COMPLIANCE_SIZE");
  int g[4];
  if (size && sscanf(size, "%d,%d,%d,%d", &g[0], &g[1], &g[2], &g[3]) == 4) {
    repeat = 5;
    run(g[3], 1, g);
  } else {
    const int grid[3] = {14, 10, 10};
    run(203, 1, grid);
    run(203, 0, grid);
    run(1, 1, grid);
    run(0, 1, grid);
  }
  if (nh_test_failures) fprintf(stderr, "test_compliance: %d failures\n", nh_test_failures);
  return nh_test_failures != 0;
}
