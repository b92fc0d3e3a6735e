/* test_coupled — the coupled step of tissue and tool (nh_step_coupled,
 * solve/coupled.c: Algorithm 1 across the tissue and tool blocks) against an
 * independent solve of the same equations, and the Coulomb stick → slide
 * switch of one shaft point.
 *
 * 1. KKT agreement. One backward-Euler step of a clamped tissue box and a
 *    needle whose base moves at a prescribed velocity (linear and angular),
 *    from a perturbed state (displacements, velocities, bent and twisted
 *    needle, moving base) so that every tangent is non-trivial, tied by 13
 *    bilateral rows: four tissue points, each by n1, n2 and the axial
 *    direction t to a needle point (one on the base element, so the
 *    prescribed base velocity enters the rows), and one tissue point held in
 *    place (a row without a tool part); gaps non-zero. Written out from the
 *    documented equations (solve/solve.h, beam/beam.h),
 *      A_t dv_t             − J_tᵀ λ = b_t,
 *                 A_b dv_b  − J_bᵀ λ = b_b,
 *      J_t dv_t + J_b dv_b           = −(J v_old + g/h),
 *    with A_t = (1 + hα) M + (hβ + h²) K, b_t = h (f_ext − f_int − αMv − βKv)
 *    − h² K v assembled here densely from the element kernels
 *    (nh_tissue_element) over the nodes that are not clamped; A_b and b_b
 *    the free rows of the needle's full system (symmetrised tangent and
 *    lumped mass of a copy of the needle taken before the step) with the
 *    base's prescribed velocity change moved to the right-hand side; J v_old
 *    taken with the base already at its new velocity. The dense KKT matrix is
 *    solved by Gaussian elimination with partial pivoting after Ruiz
 *    equilibration, with iterative refinement (residual checked). The
 *    end-of-step velocity changes of tissue and needle and the multipliers λ
 *    must agree with nh_step_coupled to 1e-8 relative (max-norm of the
 *    difference over the max-norm of the reference), the positions must
 *    follow (u += h v; the needle by nh_beam_increment with h v) and the
 *    rows must hold at the end of the step. The comparison is shown to be
 *    sensitive: the reference with one row's gap negated disagrees by far
 *    more than the tolerance. Run for E = 1e5 and 1e7.
 *    A needle compressed past buckling makes nh_beam_dynamic_prepare take the
 *    tangent's positive part (beam.h); the reference then clips K_ff's
 *    eigenvalues itself (Jacobi). Its tolerance is 10 eps cond(A_b) (about
 *    1e-6; measured 3e-8): the positive part carries the eigensolver's
 *    normwise round-off eps |K|, which does not follow the graded scales of K
 *    (EA/l next to EI/l) and which A_b⁻¹ amplifies up to cond(A_b) ~ 6e8.
 *    With zero rows the tissue's update must be bitwise that of
 *    nh_step_dynamic and the needle's must match the dense solve; with the
 *    base at rest the needle's must be bitwise that of nh_beam_step_dynamic.
 *
 * 2. Stick → slide. One tissue point tied to one needle point by two
 *    bilateral lateral rows (with non-zero gaps, so they carry force) and one
 *    FRICTION axial row bounded by mu |(λ1, λ2)| + c. The base velocity v_b
 *    is swept along the axis. The stick solution (the same step with the
 *    axial row bilateral) gives the axial force that sticking needs; the
 *    switch v* is predicted where its |λ_axial| meets the bound computed from
 *    its own lateral forces (bisection on v_b). Along the sweep: below v* the
 *    friction step sticks, equals the stick step (1e-9) and its axial rate
 *    w = t·(v_tissue − v_tool), recomputed from the end-of-step velocities
 *    and the rows' J, is 0 to 1e-9 relative; above v* it slides, |λ_axial|
 *    equals the bound to 1e-9 relative and λ_axial w ≤ 0 (the force opposes
 *    the slip); the lateral rates stay 0 throughout. At the prediction the
 *    step sticks at v*(1 − 1e-7) and slides at v*(1 + 1e-7).
 *
 * 4. A reused factor's kept W₀ (solve/coupled.c, nh_tissue_compliance).
 *    The tissue held at 9 material points by rows without a tool part,
 *    stepped with reuse (solver.refactor: auto) and, from the same states,
 *    with a factorisation at every step (the exact path of part 1). The
 *    step after the first reuses the factor and takes the first step's W₀
 *    (same factor, same rows' nodes): its end-of-step velocities and λ must
 *    equal the exact path's to 1e-7 relative (the corrections' fixed point
 *    does not depend on W₀; tolerance 1e-10 per solve). The kept W₀ must
 *    not be taken, the results again equal, when a row moves to another
 *    cell, and when the factor is not the one it was built with (a
 *    factorisation in between, then a state that changes A).
 *
 * NH_VERBOSE=1 prints the measured agreements. */
#include "beam/beam.h"
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <float.h>
#include <string.h>

static int verbose = 0;

/* ---- fixtures ---- */

/* The tissue box [0, 0.04] x [0, 0.02]² (4 x 2 x 2 cells), clamped at x = 0.04. */
typedef struct {
  nh_mesh *mesh;
  nh_tissue *tissue;
  unsigned char *fixed;
  nh_system *sys;
  int nn; /* nodes */
} tissue_fix;

static void tissue_open(double young, double poisson, tissue_fix *f) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {4, 2, 2};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &f->mesh));
  nh_material mat = {young, poisson, 1000, NH_FORMULATION_BBAR};
  CHECK_OK(nh_tissue_create(f->mesh, &mat, &f->tissue));
  f->nn = f->mesh->n_nodes;
  f->fixed = calloc((size_t)f->nn, 1);
  for (int i = 0; i < f->nn; i++) f->fixed[i] = f->mesh->X[3 * i] > 0.04 - 1e-9;
  CHECK_OK(nh_system_create(f->tissue, f->fixed, NULL, &f->sys));
}

static void tissue_close(tissue_fix *f) {
  nh_system_destroy(&f->sys);
  nh_tissue_destroy(&f->tissue);
  nh_mesh_destroy(&f->mesh);
  free(f->fixed);
}

/* The needle: 8 elements, length 0.03 along +x from (−0.002, 0.01, 0.01), so
 * its base is outside the box and its tip at x = 0.028 inside. */
static nh_beam *needle_open(void) {
  nh_beam_spec sp = {.section = {5e7, 0.3, 1e-3, 0.0, 7800},
                     .base = {-0.002, 0.01, 0.01},
                     .direction = {1, 0, 0},
                     .length = 0.03,
                     .elements = 8};
  nh_beam *b;
  CHECK_OK(nh_beam_create(&sp, &b));
  return b;
}

/* Copy the state (x, T, v) of one needle into another of the same spec. */
static void needle_copy(nh_beam *from, nh_beam *to) {
  const int nodes = nh_beam_nodes(from);
  memcpy(nh_beam_positions(to), nh_beam_positions(from), sizeof(double) * 3 * nodes);
  memcpy(nh_beam_directors(to), nh_beam_directors(from), sizeof(double) * 9 * nodes);
  memcpy(nh_beam_velocities(to), nh_beam_velocities(from), sizeof(double) * 6 * nodes);
}

static double *dalloc(int n) {
  double *p = calloc((size_t)(n > 0 ? n : 1), sizeof(double));
  if (!p) {
    fprintf(stderr, "out of memory\n");
    exit(1);
  }
  return p;
}

/* max|a − b| / max|b| */
static double rel_diff(const double *a, const double *b, int n) {
  double d = 0.0, s = 0.0;
  for (int i = 0; i < n; i++) d = fmax(d, fabs(a[i] - b[i])), s = fmax(s, fabs(b[i]));
  return s > 0.0 ? d / s : d;
}

static void cross(const double a[3], const double b[3], double c[3]) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

static void normalise(double a[3]) {
  double n = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
  for (int i = 0; i < 3; i++) a[i] /= n;
}

/* Append a bilateral row tying the tissue's material point X to the needle
 * point at arc length s along direction dir (needle = NULL: to the fixed
 * point X, a row without a tool part); the gap is the current
 * n · (x_tissue(X) − x_tool(s)) plus `offset`. */
static int add_row(nh_rows *rows, const tissue_fix *tf, const double *u, nh_beam *needle, double s,
                   const double X[3], const double dir[3], double offset) {
  int i = nh_rows_add(rows);
  CHECK(i >= 0, "nh_rows_add: out of memory");
  if (i < 0) exit(1);
  int cell;
  double xi[3], N[8], x[3];
  CHECK_OK(nh_mesh_locate(tf->mesh, X, &cell, xi));
  nh_hex_shape(xi, N);
  if (needle) {
    nh_beam_point(needle, s, x, NULL, &rows->elem[i], NULL, rows->J + 36 * i);
    rows->tool[i] = 0;
  } else {
    memcpy(x, X, sizeof x);
  }
  double g = 0.0;
  for (int k = 0; k < 3; k++) {
    double p = X[k];
    for (int a = 0; a < 8; a++) p += N[a] * u[3 * tf->mesh->cells[8 * cell + a] + k];
    g += dir[k] * (p - x[k]);
    rows->dir[3 * i + k] = dir[k];
  }
  for (int a = 0; a < 8; a++) rows->node[8 * i + a] = tf->mesh->cells[8 * cell + a];
  memcpy(rows->N + 8 * i, N, sizeof N);
  rows->gap[i] = g + offset;
  return i;
}

/* Lateral directions n1, n2 completing the unit tangent t. */
static void lateral(const double t[3], double n1[3], double n2[3]) {
  const double ez[3] = {0, 0, 1};
  cross(t, ez, n1);
  normalise(n1);
  cross(t, n1, n2);
  normalise(n2);
}

/* ---- dense linear algebra ---- */

/* In-place LU with partial pivoting of the n x n row-major A; 0 on success. */
static int lu_factor(double *A, int n, int *piv) {
  for (int k = 0; k < n; k++) {
    int p = k;
    for (int i = k + 1; i < n; i++)
      if (fabs(A[(size_t)i * n + k]) > fabs(A[(size_t)p * n + k])) p = i;
    piv[k] = p;
    if (A[(size_t)p * n + k] == 0.0) return 1;
    if (p != k)
      for (int j = 0; j < n; j++) {
        double t = A[(size_t)k * n + j];
        A[(size_t)k * n + j] = A[(size_t)p * n + j], A[(size_t)p * n + j] = t;
      }
    for (int i = k + 1; i < n; i++) {
      double l = A[(size_t)i * n + k] /= A[(size_t)k * n + k];
      if (l != 0.0)
        for (int j = k + 1; j < n; j++) A[(size_t)i * n + j] -= l * A[(size_t)k * n + j];
    }
  }
  return 0;
}

static void lu_solve(const double *A, int n, const int *piv, double *x) {
  for (int k = 0; k < n; k++) {
    double t = x[k];
    x[k] = x[piv[k]], x[piv[k]] = t;
  }
  for (int k = 0; k < n; k++)
    for (int i = k + 1; i < n; i++) x[i] -= A[(size_t)i * n + k] * x[k];
  for (int k = n - 1; k >= 0; k--) {
    for (int j = k + 1; j < n; j++) x[k] -= A[(size_t)k * n + j] * x[j];
    x[k] /= A[(size_t)k * n + k];
  }
}

/* Solve A x = b (n x n, row-major, unchanged): Ruiz equilibration
 * D_r A D_c (the blocks' entries span ~12 decades: rotary inertia next to
 * stiffness), LU with partial pivoting of the scaled matrix, and three steps
 * of iterative refinement with long double residuals on the original A.
 * Returns the relative residual max|b − A x| / (max|A| max|x| + max|b|). */
static double dense_solve(int n, const double *A, const double *b, double *x) {
  double *S = dalloc(n * n), *dr = dalloc(n), *dc = dalloc(n), *r = dalloc(n);
  int *piv = malloc(sizeof(int) * (size_t)n);
  for (int i = 0; i < n; i++) dr[i] = dc[i] = 1.0;
  memcpy(S, A, sizeof(double) * (size_t)n * n);
  for (int it = 0; it < 20; it++) {
    for (int i = 0; i < n; i++) {
      double mx = 0.0;
      for (int j = 0; j < n; j++) mx = fmax(mx, fabs(S[(size_t)i * n + j]));
      double f = 1.0 / sqrt(mx);
      dr[i] *= f;
      for (int j = 0; j < n; j++) S[(size_t)i * n + j] *= f;
    }
    for (int j = 0; j < n; j++) {
      double mx = 0.0;
      for (int i = 0; i < n; i++) mx = fmax(mx, fabs(S[(size_t)i * n + j]));
      double f = 1.0 / sqrt(mx);
      dc[j] *= f;
      for (int i = 0; i < n; i++) S[(size_t)i * n + j] *= f;
    }
  }
  CHECK(lu_factor(S, n, piv) == 0, "reference KKT matrix is singular");
  memset(x, 0, sizeof(double) * (size_t)n);
  double res = 0.0;
  for (int step = 0; step < 4; step++) {
    double amax = 0.0, xmax = 0.0, bmax = 0.0, rmax = 0.0;
    for (int i = 0; i < n; i++) {
      long double s = b[i];
      for (int j = 0; j < n; j++) s -= (long double)A[(size_t)i * n + j] * x[j];
      r[i] = (double)s;
      rmax = fmax(rmax, fabs(r[i])), bmax = fmax(bmax, fabs(b[i])), xmax = fmax(xmax, fabs(x[i]));
      for (int j = 0; j < n; j++) amax = fmax(amax, fabs(A[(size_t)i * n + j]));
    }
    res = rmax / (amax * xmax + bmax);
    if (step == 3) break;
    for (int i = 0; i < n; i++) r[i] *= dr[i];
    lu_solve(S, n, piv, r);
    for (int i = 0; i < n; i++) x[i] += dc[i] * r[i];
  }
  free(S), free(dr), free(dc), free(r), free(piv);
  return res;
}

/* Eigen-decomposition K = V diag(w) Vᵀ of the symmetric n x n row-major K
 * (destroyed) by cyclic Jacobi rotations, which keep the graded spectrum of a
 * beam (translational entries ~EA/l next to rotational ~EI/l) accurate. V:
 * n x n row-major, eigenvectors in columns; w: n. */
static void sym_eig(int n, double *K, double *V, double *w) {
  memset(V, 0, sizeof(double) * (size_t)n * n);
  for (int i = 0; i < n; i++) V[(size_t)i * n + i] = 1.0;
  for (int sweep = 0; sweep < 100; sweep++) {
    double off = 0.0, diag = 0.0;
    for (int i = 0; i < n; i++)
      for (int j = 0; j < n; j++)
        if (i != j)
          off += K[(size_t)i * n + j] * K[(size_t)i * n + j];
        else
          diag += K[(size_t)i * n + i] * K[(size_t)i * n + i];
    if (off <= 1e-36 * diag) break;
    for (int p = 0; p < n; p++)
      for (int q = p + 1; q < n; q++) {
        const double apq = K[(size_t)p * n + q];
        if (apq == 0.0) continue;
        const double theta = (K[(size_t)q * n + q] - K[(size_t)p * n + p]) / (2.0 * apq);
        const double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
        const double c = 1.0 / sqrt(t * t + 1.0), sn = t * c;
        for (int k = 0; k < n; k++) { /* columns p, q */
          double kp = K[(size_t)k * n + p], kq = K[(size_t)k * n + q];
          K[(size_t)k * n + p] = c * kp - sn * kq, K[(size_t)k * n + q] = sn * kp + c * kq;
        }
        for (int k = 0; k < n; k++) { /* rows p, q */
          double kp = K[(size_t)p * n + k], kq = K[(size_t)q * n + k];
          K[(size_t)p * n + k] = c * kp - sn * kq, K[(size_t)q * n + k] = sn * kp + c * kq;
        }
        for (int k = 0; k < n; k++) {
          double vp = V[(size_t)k * n + p], vq = V[(size_t)k * n + q];
          V[(size_t)k * n + p] = c * vp - sn * vq, V[(size_t)k * n + q] = sn * vp + c * vq;
        }
      }
  }
  for (int i = 0; i < n; i++) w[i] = K[(size_t)i * n + i];
}

/* The positive part of the symmetric n x n row-major K (eigenvalues clipped
 * at 0), in place. */
static void positive_part(int n, double *K) {
  double *V = dalloc(n * n), *w = dalloc(n);
  sym_eig(n, K, V, w);
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++) {
      double v = 0.0;
      for (int k = 0; k < n; k++)
        v += V[(size_t)i * n + k] * fmax(w[k], 0.0) * V[(size_t)j * n + k];
      K[(size_t)i * n + j] = v;
    }
  free(V), free(w);
}

/* Condition number λ_max / λ_min of the symmetric positive definite A (n x n,
 * row-major, unchanged). */
static double spd_condition(int n, const double *A) {
  double *K = dalloc(n * n), *V = dalloc(n * n), *w = dalloc(n), lo = INFINITY, hi = 0.0;
  memcpy(K, A, sizeof(double) * (size_t)n * n);
  sym_eig(n, K, V, w);
  for (int i = 0; i < n; i++) lo = fmin(lo, w[i]), hi = fmax(hi, w[i]);
  free(K), free(V), free(w);
  return lo > 0.0 ? hi / lo : INFINITY;
}

/* Whether nh_beam_dynamic_prepare takes K's positive part for this state. */
static int prepare_projects(nh_beam *needle, const nh_coupled_tool *tool) {
  nh_beam *c = needle_open();
  needle_copy(needle, c);
  nh_beam_system *bs;
  double *rhs = dalloc(nh_beam_dofs(c));
  CHECK_OK(nh_beam_system_create(c, &bs));
  CHECK_OK(nh_beam_dynamic_prepare(c, &tool->options, tool->f_ext, tool->base_velocity, bs, rhs));
  int projected = nh_beam_system_projected(bs);
  nh_beam_system_destroy(&bs);
  nh_beam_destroy(&c);
  free(rhs);
  return projected;
}

/* ---- the reference step ---- */

typedef struct {
  const tissue_fix *tf;
  const nh_integrator *in;
  const double *f_ext, *u, *v; /* tissue before the step */
  nh_beam *needle;             /* a copy of the needle before the step */
  const nh_beam_dynamic_options *options;
  const double *fb_ext;        /* 6 per needle node, may be NULL */
  const double *base_velocity; /* prescribed, end of step */
  const nh_rows *rows;         /* tool index 0 or −1 */
  int positive_part;           /* A_b with the positive part of K_ff (beam.h) */
  double kappa;                /* out: condition number of A_b */
} kkt_input;

/* The end-of-step velocities of tissue (vt, 3 per node) and needle (vb, 6
 * per node) and the forces λ of the rows, from the dense KKT system of the
 * documented equations. Returns the reference solve's relative residual. */
static double kkt_reference(kkt_input *p, double *vt, double *vb, double *lambda) {
  const nh_mesh *m = p->tf->mesh;
  const nh_tissue *ts = p->tf->tissue;
  const int n3 = 3 * p->tf->nn, N = nh_beam_dofs(p->needle), nb = N - 6, mr = p->rows->m;
  const double h = p->in->dt, cK = h * p->in->beta + h * h;
  int *idx = malloc(sizeof(int) * (size_t)n3), nt = 0;
  for (int i = 0; i < n3; i++) idx[i] = p->tf->fixed[i / 3] ? -1 : nt++;
  const int tot = nt + nb + mr;
  double *A = dalloc(tot * tot), *rhs = dalloc(tot), *z = dalloc(tot);

  /* Tissue: dense K and f_int from the element kernels. */
  double *K = dalloc(n3 * n3), *fi = dalloc(n3);
  for (int l = 0; l < m->n_leaves; l++) {
    const int c = m->leaves[l], *cn = m->cells + 8 * c;
    double fe[24], Ke[576];
    nh_tissue_element(ts, c, p->u, fe, Ke);
    for (int r = 0; r < 24; r++) {
      const int I = 3 * cn[r / 3] + r % 3;
      fi[I] += fe[r];
      for (int q = 0; q < 24; q++) K[(size_t)I * n3 + 3 * cn[q / 3] + q % 3] += Ke[24 * r + q];
    }
  }
  for (int I = 0; I < n3; I++) {
    if (idx[I] < 0) continue;
    double Kv = 0.0, M = ts->mass[I / 3];
    for (int J = 0; J < n3; J++) Kv += K[(size_t)I * n3 + J] * p->v[J];
    rhs[idx[I]] =
        h * (p->f_ext[I] - fi[I] - p->in->alpha * M * p->v[I] - p->in->beta * Kv) - h * h * Kv;
    for (int J = 0; J < n3; J++)
      if (idx[J] >= 0) A[(size_t)idx[I] * tot + idx[J]] = cK * K[(size_t)I * n3 + J];
    A[(size_t)idx[I] * tot + idx[I]] += (1.0 + h * p->in->alpha) * M;
  }

  /* Needle: the full system A_full dv = rhs_full with dv_base = v_base,new −
   * v_base prescribed, restricted to the free rows. */
  const nh_beam_dynamic_options *o = p->options;
  const double hb = o->dt, cKb = hb * o->beta + hb * hb;
  double *Kb = dalloc(N * N), *fb = dalloc(N), *Mb = dalloc(N);
  const double *v_old = nh_beam_velocities(p->needle);
  nh_beam_internal_force(p->needle, fb, Kb, 0); /* the exact K on the rhs (docs/beam.md §2) */
  nh_beam_mass(p->needle, Mb);
  double *Kff = dalloc(nb * nb); /* the free block of ½(K + Kᵀ) in A_b (the rhs keeps K) */
  for (int i = 0; i < nb; i++)
    for (int j = 0; j < nb; j++)
      Kff[(size_t)i * nb + j] =
          0.5 * (Kb[(size_t)(i + 6) * N + j + 6] + Kb[(size_t)(j + 6) * N + i + 6]);
  if (p->positive_part) positive_part(nb, Kff);
  for (int i = 6; i < N; i++) {
    double Kv = 0.0;
    for (int j = 0; j < N; j++) Kv += Kb[(size_t)i * N + j] * v_old[j];
    double fe = (p->fb_ext ? p->fb_ext[i] : 0.0) + (i % 6 < 3 ? Mb[i] * o->gravity[i % 6] : 0.0);
    double r = hb * (fe - fb[i] - o->alpha * Mb[i] * v_old[i] - o->beta * Kv) - hb * hb * Kv;
    for (int j = 0; j < 6; j++) /* A_full[i][j] (M is diagonal: only cK K) */
      r -= cKb * Kb[(size_t)i * N + j] * (p->base_velocity[j] - v_old[j]);
    rhs[nt + i - 6] = r;
    for (int j = 6; j < N; j++)
      A[(size_t)(nt + i - 6) * tot + nt + j - 6] = cKb * Kff[(size_t)(i - 6) * nb + j - 6];
    A[(size_t)(nt + i - 6) * tot + nt + i - 6] += (1.0 + hb * o->alpha) * Mb[i];
  }

  /* Rows: J_t = n N_a on the free tissue DOFs, J_b = −nᵀ J_beam on the
   * element's DOFs (base: prescribed, into the right-hand side). */
  const nh_rows *rw = p->rows;
  for (int i = 0; i < mr; i++) {
    const int row = nt + nb + i;
    const double *n = rw->dir + 3 * i;
    double rate = 0.0;
    for (int a = 0; a < 8; a++) {
      const int node = rw->node[8 * i + a];
      if (node < 0) continue;
      for (int k = 0; k < 3; k++) {
        const int I = 3 * node + k;
        const double c = n[k] * rw->N[8 * i + a];
        rate += c * p->v[I];
        if (idx[I] < 0) continue;
        A[(size_t)row * tot + idx[I]] += c;
        A[(size_t)idx[I] * tot + row] -= c;
      }
    }
    if (rw->tool[i] >= 0) {
      const double *J = rw->J + 36 * i;
      for (int q = 0; q < 12; q++) {
        const double c = -(n[0] * J[q] + n[1] * J[12 + q] + n[2] * J[24 + q]);
        const int d = 6 * rw->elem[i] + q;
        if (d < 6) {
          rate += c * p->base_velocity[d];
          continue;
        }
        rate += c * v_old[d];
        A[(size_t)row * tot + nt + d - 6] += c;
        A[(size_t)(nt + d - 6) * tot + row] -= c;
      }
    }
    rhs[row] = -(rate + rw->gap[i] / h);
  }

  double *Ab = dalloc(nb * nb);
  for (int i = 0; i < nb; i++)
    memcpy(Ab + (size_t)i * nb, A + (size_t)(nt + i) * tot + nt, sizeof(double) * (size_t)nb);
  p->kappa = spd_condition(nb, Ab);
  free(Ab);

  double res = dense_solve(tot, A, rhs, z);
  for (int I = 0; I < n3; I++) vt[I] = p->v[I] + (idx[I] >= 0 ? z[idx[I]] : 0.0);
  for (int j = 0; j < 6; j++) vb[j] = p->base_velocity[j];
  for (int j = 6; j < N; j++) vb[j] = v_old[j] + z[nt + j - 6];
  for (int i = 0; i < mr; i++) lambda[i] = z[nt + nb + i];
  free(idx), free(A), free(rhs), free(z), free(K), free(fi), free(Kb), free(fb), free(Mb),
      free(Kff);
  return res;
}

/* ---- 1. KKT agreement ---- */

/* max |a − a0 − (b − b0)| / max |b − b0|: the velocity changes. */
static double rel_change(const double *a, const double *b, const double *base, int n) {
  double d = 0.0, s = 0.0;
  for (int i = 0; i < n; i++) d = fmax(d, fabs(a[i] - b[i])), s = fmax(s, fabs(b[i] - base[i]));
  return s > 0.0 ? d / s : d;
}

/* One step compared with the reference. compress: uniform axial strain
 * imposed on the needle (on top of the random perturbation); past the
 * cantilever's buckling strain (~7e-4 here) prepare takes K's positive part,
 * which `projected` says to expect. */
static void kkt_case(double young, double poisson, int with_rows, double compress, int projected) {
  double tol = 1e-8;
  tissue_fix tf;
  tissue_open(young, poisson, &tf);
  const int n3 = 3 * tf.nn;
  nh_beam *needle = needle_open(), *copy = needle_open();
  const int N = nh_beam_dofs(needle), nodes = nh_beam_nodes(needle);

  /* A perturbed state: the tissue displaced and moving (clamped nodes at
   * rest), the needle bent, twisted and moving, its base included. */
  double *u = dalloc(n3), *v = dalloc(n3), *f = dalloc(n3), *fb = dalloc(N), *d = dalloc(N);
  for (int i = 0; i < n3; i++) {
    if (tf.fixed[i / 3]) continue;
    u[i] = 1e-4 * nh_rand(), v[i] = 1e-2 * nh_rand(), f[i] = 1e-2 * nh_rand();
  }
  for (int i = 0; i < N; i++) d[i] = (i % 6 < 3 ? 1e-5 : 2e-2) * nh_rand();
  nh_beam_increment(needle, d);
  double *xn = nh_beam_positions(needle);
  for (int a = 1; a < nodes; a++) xn[3 * a] = xn[0] + (1.0 - compress) * (xn[3 * a] - xn[0]);
  double *vn = nh_beam_velocities(needle);
  for (int i = 0; i < N; i++)
    vn[i] = (i % 6 < 3 ? 1e-2 : 1.0) * nh_rand(), fb[i] = 1e-3 * nh_rand();
  vn[0] = 0.015; /* the base was already moving along the axis */

  nh_integrator in = {.dt = 1e-3, .alpha = 0.5, .beta = 1e-3, .threads = 1};
  nh_coupled_tool tool = {
      .beam = needle,
      .options = {.dt = 1e-3, .alpha = 0.3, .beta = 2e-3, .gravity = {0, 0, -9.81}},
      .base_velocity = {0.02, 1e-3, -2e-3, 0.1, -0.2, 0.3},
      .f_ext = fb};

  nh_rows rows = {0};
  if (with_rows) {
    /* s = 0.003 lies on the base element: its rows see the prescribed base
     * velocity. */
    const double s[4] = {0.003, 0.015, 0.022, 0.03};
    for (int p = 0; p < 4; p++) {
      double x[3], t[3], n1[3], n2[3], X[3];
      nh_beam_point(needle, s[p], x, t, NULL, NULL, NULL);
      lateral(t, n1, n2);
      for (int k = 0; k < 3; k++) X[k] = x[k] + 2e-4 * nh_rand(); /* off the cell faces */
      const double *dirs[3] = {n1, n2, t};
      for (int q = 0; q < 3; q++) {
        int i = add_row(&rows, &tf, u, needle, s[p], X, dirs[q], 1e-5 * nh_rand());
        rows.lambda[i] = 1e-3 * nh_rand(); /* a warm start the bilateral solve must ignore */
      }
    }
    /* A tissue point near the clamp held in place along a skew direction. */
    double X[3] = {0.033, 0.004, 0.015}, dir[3] = {1, 2, -2};
    normalise(dir);
    add_row(&rows, &tf, u, NULL, 0.0, X, dir, 3e-6);
  }

  CHECK(prepare_projects(needle, &tool) == projected,
        "E %g, compression %g: nh_beam_dynamic_prepare %s K's positive part", young, compress,
        projected ? "does not take" : "takes");

  /* Snapshots, then the step. */
  double *u0 = dalloc(n3), *v0 = dalloc(n3), *vb0 = dalloc(N), *x0 = dalloc(3 * nodes);
  memcpy(u0, u, sizeof(double) * n3), memcpy(v0, v, sizeof(double) * n3);
  needle_copy(needle, copy);
  memcpy(vb0, vn, sizeof(double) * N);
  memcpy(x0, nh_beam_positions(needle), sizeof(double) * 3 * nodes);
  nh_coupled_stats st;
  CHECK_OK(nh_step_coupled(tf.sys, &in, f, u, v, 1, &tool, &rows, 1e-13, 1e-13, 100, &st));

  double *vt_ref = dalloc(n3), *vb_ref = dalloc(N), *lam_ref = dalloc(rows.m);
  kkt_input kin = {.tf = &tf,
                   .in = &in,
                   .f_ext = f,
                   .u = u0,
                   .v = v0,
                   .needle = copy,
                   .options = &tool.options,
                   .fb_ext = fb,
                   .base_velocity = tool.base_velocity,
                   .rows = &rows,
                   .positive_part = projected};
  double res = kkt_reference(&kin, vt_ref, vb_ref, lam_ref);
  CHECK(res < 1e-14, "reference KKT solve: relative residual %.3g", res);
  /* With K's positive part, A_b carries the eigen-decomposition's round-off,
   * eps |K| in every entry (normwise: it does not follow the graded scales of
   * K), which A_b⁻¹ amplifies by up to its condition number. */
  if (projected) tol = fmax(tol, 10 * DBL_EPSILON * kin.kappa);

  double e_vt = rel_change(v, vt_ref, v0, n3), e_vb = rel_change(vn, vb_ref, vb0, N);
  double e_vt_abs = rel_diff(v, vt_ref, n3), e_vb_abs = rel_diff(vn, vb_ref, N);
  double e_lam = rows.m ? rel_diff(rows.lambda, lam_ref, rows.m) : 0.0;
  CHECK(e_vt <= tol, "E %g: tissue dv vs KKT: relative difference %.3g > %.3g", young, e_vt, tol);
  CHECK(e_vb <= tol, "E %g: needle dv vs KKT: relative difference %.3g > %.3g", young, e_vb, tol);
  CHECK(e_lam <= tol, "E %g: lambda vs KKT: relative difference %.3g > %.3g", young, e_lam, tol);
  for (int i = 0; i < 6; i++)
    CHECK(vn[i] == tool.base_velocity[i], "base velocity %d: %.17g, prescribed %.17g", i, vn[i],
          tool.base_velocity[i]);

  /* Positions follow the end-of-step velocities. */
  double *step = dalloc(n3), *moved = dalloc(n3);
  for (int i = 0; i < n3; i++) step[i] = in.dt * vt_ref[i], moved[i] = u[i] - u0[i];
  double e_u = rel_diff(moved, step, n3);
  CHECK(e_u <= tol, "tissue u − u0 vs h v_KKT: relative difference %.3g > %.3g", e_u, tol);
  for (int i = 0; i < N; i++) d[i] = tool.options.dt * vb_ref[i];
  nh_beam *moved_copy = needle_open();
  needle_copy(copy, moved_copy);
  nh_beam_increment(moved_copy, d);
  double e_x = 0.0, e_T = 0.0, dx = 0.0;
  const double *xa = nh_beam_positions(needle), *xb = nh_beam_positions(moved_copy);
  const double *Ta = nh_beam_directors(needle), *Tb = nh_beam_directors(moved_copy);
  for (int i = 0; i < 3 * nodes; i++)
    e_x = fmax(e_x, fabs(xa[i] - xb[i])), dx = fmax(dx, fabs(xb[i] - x0[i]));
  const double *T0 = nh_beam_directors(copy);
  double dT = 0.0;
  for (int i = 0; i < 9 * nodes; i++)
    e_T = fmax(e_T, fabs(Ta[i] - Tb[i])), dT = fmax(dT, fabs(Tb[i] - T0[i]));
  CHECK(e_x <= tol * dx, "needle x vs x0 + h v_KKT: %.3g > %.3g", e_x, tol * dx);
  CHECK(e_T <= tol * dT, "needle T vs exp(h ω_KKT) T0: %.3g > %.3g", e_T, tol * dT);

  if (with_rows) {
    /* The rows hold at the end of the step: J v_new + g/h = 0. */
    double wmax = 0.0, scale = 0.0;
    for (int i = 0; i < rows.m; i++) {
      double w = rows.gap[i] / in.dt;
      scale = fmax(scale, fabs(w));
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++)
          w += rows.N[8 * i + a] * rows.dir[3 * i + k] * v[3 * rows.node[8 * i + a] + k];
      for (int q = 0; q < 12; q++)
        for (int k = 0; k < 3; k++)
          w -= rows.dir[3 * i + k] * rows.J[36 * i + 12 * k + q] * vn[6 * rows.elem[i] + q];
      wmax = fmax(wmax, fabs(w));
    }
    CHECK(wmax <= 1e-9 * scale, "rows violated at the end of the step: |w| %.3g > %.3g", wmax,
          1e-9 * scale);

    /* Sensitivity: one gap negated in the reference moves it far beyond tol. */
    double *vt2 = dalloc(n3), *vb2 = dalloc(N), *lam2 = dalloc(rows.m);
    rows.gap[4] = -rows.gap[4];
    kkt_reference(&kin, vt2, vb2, lam2);
    rows.gap[4] = -rows.gap[4];
    double e_flip = fmax(rel_diff(rows.lambda, lam2, rows.m), rel_change(v, vt2, v0, n3));
    CHECK(e_flip > 1e4 * tol, "a negated gap is not detected (difference %.3g)", e_flip);
    if (verbose) printf("  negated gap of row 4: difference %.3g\n", e_flip);
    free(vt2), free(vb2), free(lam2);
  } else {
    /* No rows: the tissue's update is nh_step_dynamic's, bit for bit. */
    double *u2 = dalloc(n3), *v2 = dalloc(n3);
    memcpy(u2, u0, sizeof(double) * n3), memcpy(v2, v0, sizeof(double) * n3);
    CHECK_OK(nh_step_dynamic(tf.sys, &in, f, u2, v2, NULL));
    CHECK(memcmp(u2, u, sizeof(double) * n3) == 0 && memcmp(v2, v, sizeof(double) * n3) == 0,
          "no rows: tissue differs from nh_step_dynamic (u %.3g, v %.3g)", rel_diff(u, u2, n3),
          rel_diff(v, v2, n3));
    /* With the base at rest, the needle's update is nh_beam_step_dynamic's. */
    needle_copy(copy, needle);
    needle_copy(copy, moved_copy);
    memset(nh_beam_velocities(needle), 0, 6 * sizeof(double));
    memset(tool.base_velocity, 0, sizeof tool.base_velocity);
    memcpy(u, u0, sizeof(double) * n3), memcpy(v, v0, sizeof(double) * n3);
    CHECK_OK(nh_step_coupled(tf.sys, &in, f, u, v, 1, &tool, &rows, 1e-13, 1e-13, 100, NULL));
    CHECK_OK(nh_beam_step_dynamic(moved_copy, &tool.options, fb));
    CHECK(memcmp(nh_beam_velocities(needle), nh_beam_velocities(moved_copy), sizeof(double) * N) ==
                  0 &&
              memcmp(nh_beam_positions(needle), nh_beam_positions(moved_copy),
                     sizeof(double) * 3 * nodes) == 0 &&
              memcmp(nh_beam_directors(needle), nh_beam_directors(moved_copy),
                     sizeof(double) * 9 * nodes) == 0,
          "no rows, base at rest: needle differs from nh_beam_step_dynamic");
    free(u2), free(v2);
  }
  if (verbose)
    printf(
        "E %g nu %g rows %d projected %d: rel. diff dv tissue %.3g (v %.3g), dv needle %.3g (v "
        "%.3g), "
        "lambda %.3g, u %.3g, needle x %.3g, T %.3g; KKT residual %.3g; cond(A_b) %.3g, tol %.3g\n",
        young, poisson, rows.m, projected, e_vt, e_vt_abs, e_vb, e_vb_abs, e_lam, e_u,
        dx > 0 ? e_x / dx : e_x, dT > 0 ? e_T / dT : e_T, res, kin.kappa, tol);

  free(u), free(v), free(f), free(fb), free(d), free(u0), free(v0), free(vb0), free(x0);
  free(vt_ref), free(vb_ref), free(lam_ref), free(step), free(moved);
  nh_rows_free(&rows);
  nh_beam_destroy(&needle);
  nh_beam_destroy(&copy);
  nh_beam_destroy(&moved_copy);
  tissue_close(&tf);
}

/* ---- 2. stick → slide ---- */

typedef struct {
  tissue_fix tf;
  nh_beam *needle, *rest;
  nh_integrator in;
  nh_coupled_tool tool;
  nh_rows rows;
  double *u, *v, *f;
} fric_fix;

typedef struct {
  double lambda[3], w[3], wscale[3]; /* forces, end-of-step rates, |parts| of the rates */
  double bound;                      /* mu |(λ1, λ2)| + c of this λ */
  nh_mcp_stats mcp;
} trial_out;

/* One step from the fixture's initial state with base velocity vb along x;
 * the axial row with law `kind`. */
static void trial(fric_fix *F, double vb, nh_row_kind kind, trial_out *o) {
  const int n3 = 3 * F->tf.nn;
  memset(F->u, 0, sizeof(double) * n3), memset(F->v, 0, sizeof(double) * n3);
  needle_copy(F->rest, F->needle);
  memset(F->tool.base_velocity, 0, sizeof F->tool.base_velocity);
  F->tool.base_velocity[0] = vb;
  F->rows.law[2].kind = kind;
  memset(F->rows.lambda, 0, sizeof(double) * 3);
  nh_coupled_stats st;
  CHECK_OK(nh_step_coupled(F->tf.sys, &F->in, F->f, F->u, F->v, 1, &F->tool, &F->rows, 1e-14, 1e-14,
                           200, &st));
  o->mcp = st.mcp;
  const nh_rows *r = &F->rows;
  const double *vn = nh_beam_velocities(F->needle);
  for (int i = 0; i < 3; i++) {
    double wt = 0.0, wb = 0.0;
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++)
        wt += r->N[8 * i + a] * r->dir[3 * i + k] * F->v[3 * r->node[8 * i + a] + k];
    for (int q = 0; q < 12; q++)
      for (int k = 0; k < 3; k++)
        wb += r->dir[3 * i + k] * r->J[36 * i + 12 * k + q] * vn[6 * r->elem[i] + q];
    o->w[i] = wt - wb + r->gap[i] / F->in.dt;
    o->wscale[i] = fabs(wt) + fabs(wb) + fabs(r->gap[i] / F->in.dt);
    o->lambda[i] = r->lambda[i];
  }
  o->bound = r->law[2].mu * hypot(o->lambda[0], o->lambda[1]) + r->law[2].threshold;
}

/* Stick margin of the stick solution at vb: |λ_axial| − bound (< 0: sticks). */
static double stick_margin(fric_fix *F, double vb) {
  trial_out o;
  trial(F, vb, NH_ROW_BILATERAL, &o);
  return fabs(o.lambda[2]) - o.bound;
}

static void test_stick_slide(void) {
  fric_fix F = {0};
  tissue_open(1e6, 0.35, &F.tf);
  const int n3 = 3 * F.tf.nn;
  F.needle = needle_open(), F.rest = needle_open();
  F.u = dalloc(n3), F.v = dalloc(n3), F.f = dalloc(n3);
  F.in = (nh_integrator){.dt = 1e-3, .alpha = 0.5, .beta = 1e-3, .threads = 1};
  F.tool = (nh_coupled_tool){
      .beam = F.needle,
      .options = {.dt = 1e-3, .alpha = 0.5, .beta = 1e-3, .gravity = {0, 0, -9.81}}};
  /* One shaft point at s = 0.025 (x = 0.023); the tissue point sits off the
   * axis by (0, 2e-5, −1e-5), so the lateral rows pull it in (g ≠ 0) while
   * the axial gap is 0. */
  const double s = 0.025;
  double x[3], t[3], n1[3], n2[3], X[3];
  nh_beam_point(F.needle, s, x, t, NULL, NULL, NULL);
  lateral(t, n1, n2);
  X[0] = x[0], X[1] = x[1] + 2e-5, X[2] = x[2] - 1e-5;
  add_row(&F.rows, &F.tf, F.u, F.needle, s, X, n1, 0.0);
  add_row(&F.rows, &F.tf, F.u, F.needle, s, X, n2, 0.0);
  add_row(&F.rows, &F.tf, F.u, F.needle, s, X, t, 0.0);
  CHECK(fabs(F.rows.gap[2]) < 1e-18, "axial gap %.3g, want 0", F.rows.gap[2]);
  CHECK(fabs(F.rows.gap[0]) > 1e-6 && fabs(F.rows.gap[1]) > 1e-6, "lateral gaps %.3g %.3g",
        F.rows.gap[0], F.rows.gap[1]);

  /* The bound: mu = 0.3 and a threshold c such that at the top of the sweep
   * (vmax) sticking would need twice the bound, |λ_axial| = 2 (mu |λ_lat| + c):
   * the switch then lies inside the sweep (near vmax / 2). */
  const double vmax = 0.02, mu = 0.3;
  trial_out o;
  trial(&F, vmax, NH_ROW_BILATERAL, &o);
  double c = 0.5 * fabs(o.lambda[2]) - mu * hypot(o.lambda[0], o.lambda[1]);
  CHECK(c > 0.0, "lateral force too large for the sweep: c = %g", c);
  F.rows.law[2] = (nh_row_law){NH_ROW_FRICTION, 0, 1, mu, c, -1, 0.0, 0, 0};

  /* Predicted switch: the stick solution's margin crosses 0. */
  double lo = 0.0, hi = vmax;
  CHECK(stick_margin(&F, lo) < 0.0 && stick_margin(&F, hi) > 0.0,
        "the stick margin does not change sign over [0, %g]", vmax);
  for (int it = 0; it < 200 && hi - lo > 1e-15 * vmax; it++) {
    double mid = 0.5 * (lo + hi);
    if (stick_margin(&F, mid) < 0.0)
      lo = mid;
    else
      hi = mid;
  }
  const double vstar = 0.5 * (lo + hi);

  /* The sweep. */
  double e_stick_w = 0.0, e_stick_l = 0.0, e_slide_b = 0.0, e_lat_w = 0.0;
  int n_stick = 0, n_slide = 0;
  for (int k = 0; k <= 40; k++) {
    const double vb = vmax * k / 40.0;
    trial_out fr, bi;
    trial(&F, vb, NH_ROW_FRICTION, &fr);
    trial(&F, vb, NH_ROW_BILATERAL, &bi);
    for (int i = 0; i < 2; i++) e_lat_w = fmax(e_lat_w, fabs(fr.w[i]) / fr.wscale[i]);
    if (vb < vstar) {
      n_stick++;
      CHECK(fr.mcp.n_stick == 1 && fr.mcp.n_slide == 0, "v_b %g < v* %g: not sticking", vb, vstar);
      CHECK(fabs(fr.lambda[2]) < fr.bound, "v_b %g: |λ_axial| %.17g outside the bound %.17g", vb,
            fabs(fr.lambda[2]), fr.bound);
      double ew = fabs(fr.w[2]) / fr.wscale[2];
      double el = rel_diff(fr.lambda, bi.lambda, 3);
      e_stick_w = fmax(e_stick_w, ew), e_stick_l = fmax(e_stick_l, el);
      CHECK(ew <= 1e-9, "v_b %g sticking: axial rate %.3g (relative %.3g > 1e-9)", vb, fr.w[2], ew);
      CHECK(el <= 1e-9, "v_b %g sticking: λ differs from the stick solve by %.3g > 1e-9", vb, el);
    } else {
      n_slide++;
      CHECK(fr.mcp.n_slide == 1 && fr.mcp.n_stick == 0, "v_b %g > v* %g: not sliding", vb, vstar);
      double eb = fabs(fabs(fr.lambda[2]) - fr.bound) / fr.bound;
      e_slide_b = fmax(e_slide_b, eb);
      CHECK(eb <= 1e-9, "v_b %g sliding: |λ_axial| %.17g vs bound %.17g (relative %.3g > 1e-9)", vb,
            fabs(fr.lambda[2]), fr.bound, eb);
      CHECK(fr.lambda[2] * fr.w[2] <= 0.0,
            "v_b %g sliding: λ_axial %.3g and rate %.3g agree in sign", vb, fr.lambda[2], fr.w[2]);
      CHECK(k == 0 || fabs(fr.w[2]) > 1e-9 * fr.wscale[2] || vb - vstar < 1e-3 * vmax,
            "v_b %g sliding without slip (rate %.3g)", vb, fr.w[2]);
    }
  }
  CHECK(e_lat_w <= 1e-9, "lateral rates %.3g (relative) > 1e-9", e_lat_w);
  CHECK(n_stick >= 5 && n_slide >= 5, "sweep: %d sticking, %d sliding", n_stick, n_slide);

  /* The switch is where the stick solution predicts it. */
  /* The switch is where the stick solution predicts it: by the solver's own
   * count (which calls a row within 1e-9 of its bound sliding) at 1e-7 from
   * v*, and by the laws themselves at 1e-10: just below, the friction step is
   * the stick step (w = 0); just above, λ sits on the bound and slips. */
  const double delta = 1e-7, fine = 1e-10;
  trial_out below, above, fb, fa, sb;
  trial(&F, vstar * (1 - delta), NH_ROW_FRICTION, &below);
  trial(&F, vstar * (1 + delta), NH_ROW_FRICTION, &above);
  CHECK(below.mcp.n_stick == 1, "v*(1 − %g) = %.17g: not sticking (|λ| %.17g, bound %.17g)", delta,
        vstar * (1 - delta), fabs(below.lambda[2]), below.bound);
  CHECK(above.mcp.n_slide == 1, "v*(1 + %g) = %.17g: not sliding (|λ| %.17g, bound %.17g)", delta,
        vstar * (1 + delta), fabs(above.lambda[2]), above.bound);
  trial(&F, vstar * (1 - fine), NH_ROW_FRICTION, &fb);
  trial(&F, vstar * (1 - fine), NH_ROW_BILATERAL, &sb);
  trial(&F, vstar * (1 + fine), NH_ROW_FRICTION, &fa);
  const double e_fb = rel_diff(fb.lambda, sb.lambda, 3), w_fb = fabs(fb.w[2]) / fb.wscale[2];
  const double b_fa = fabs(fabs(fa.lambda[2]) - fa.bound) / fa.bound;
  CHECK(e_fb <= 1e-12 && w_fb <= 1e-12 && fabs(fb.lambda[2]) < fb.bound,
        "v*(1 − %g): not the stick solution (λ differs by %.3g, axial rate %.3g, |λ| − bound %.3g)",
        fine, e_fb, w_fb, fabs(fb.lambda[2]) - fb.bound);
  CHECK(b_fa <= 1e-12 && fa.lambda[2] * fa.w[2] < 0.0,
        "v*(1 + %g): not sliding on the bound (|λ| vs bound %.3g, λ %.3g, axial rate %.3g)", fine,
        b_fa, fa.lambda[2], fa.w[2]);
  if (verbose)
    printf("stick-slide: c %.6g, v* %.12g (of %g); %d stick, %d slide; stick |w|/scale %.3g, "
           "stick λ vs bilateral %.3g, slide |λ| vs bound %.3g, lateral |w|/scale %.3g; "
           "at v*(1∓%g): margins %.3g, %.3g (relative); at v*(1∓%g): stick λ vs bilateral %.3g, "
           "|w|/scale %.3g; slide |λ| vs bound %.3g, w/scale %.3g\n",
           c, vstar, vmax, n_stick, n_slide, e_stick_w, e_stick_l, e_slide_b, e_lat_w, delta,
           (fabs(below.lambda[2]) - below.bound) / below.bound,
           (fabs(above.lambda[2]) - above.bound) / above.bound, fine, e_fb, w_fb, b_fa,
           fa.w[2] / fa.wscale[2]);

  nh_rows_free(&F.rows);
  free(F.u), free(F.v), free(F.f);
  nh_beam_destroy(&F.needle);
  nh_beam_destroy(&F.rest);
  tissue_close(&F.tf);
}

/* ---- 3. a row naming a tool that is not there ---- */

/* Fails with NH_ERR_INTERNAL, leaves the state alone, and (under
 * -DNH_SANITIZE=ON) leaks nothing. */
static void test_bad_row(void) {
  tissue_fix tf;
  tissue_open(1e6, 0.35, &tf);
  const int n3 = 3 * tf.nn;
  nh_beam *needle = needle_open();
  double *u = dalloc(n3), *v = dalloc(n3), *f = dalloc(n3);
  nh_integrator in = {.dt = 1e-3, .alpha = 0.5, .beta = 1e-3, .threads = 1};
  nh_coupled_tool tool = {.beam = needle, .options = {.dt = 1e-3}, .base_velocity = {0.01}};
  nh_rows rows = {0};
  double x[3];
  nh_beam_point(needle, 0.02, x, NULL, NULL, NULL, NULL);
  const double dir[3] = {0, 1, 0};
  add_row(&rows, &tf, u, needle, 0.02, x, dir, 0.0);
  for (int bad = 0; bad < 2; bad++) {
    rows.tool[0] = bad ? 0 : 1, rows.elem[0] = bad ? 8 : 0; /* tool 1 of 1; element 8 of 8 */
    int rc = nh_step_coupled(tf.sys, &in, f, u, v, 1, &tool, &rows, 1e-12, 1e-12, 100, NULL);
    CHECK(rc == NH_ERR_INTERNAL, "row with tool %d, element %d: returned %d, want %d", rows.tool[0],
          rows.elem[0], rc, NH_ERR_INTERNAL);
  }
  double moved = 0.0;
  for (int i = 0; i < n3; i++) moved = fmax(moved, fabs(u[i]) + fabs(v[i]));
  CHECK(moved == 0.0, "a failed step changed the tissue (%.3g)", moved);
  free(u), free(v), free(f);
  nh_rows_free(&rows);
  nh_beam_destroy(&needle);
  tissue_close(&tf);
}

/* ---- 4. a reused factor's kept W₀ ---- */

/* Rows tying the tissue's points X (9, the last moved by `shift` along x)
 * to their rest positions along three directions each, the gaps the
 * current violation plus a small offset. */
static void tie_rows(nh_rows *rows, const tissue_fix *tf, const double *u, double shift) {
  nh_rows_clear(rows);
  const double X[3][3] = {{0.006, 0.005, 0.012}, {0.017, 0.013, 0.006}, {0.026, 0.007, 0.015}};
  const double dirs[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int p = 0; p < 3; p++)
    for (int q = 0; q < 3; q++) {
      double x[3] = {X[p][0] + (p == 2 ? shift : 0.0), X[p][1], X[p][2]};
      add_row(rows, tf, u, NULL, 0.0, x, dirs[q], 1e-6 * (q + 1));
    }
}

/* One step of both paths from the same state (u, v); the reuse path's
 * stats in *st. Checks their agreement. */
static void kept_step(tissue_fix *tf, nh_system *exact, const double *f, double *u, double *v,
                      double shift, nh_coupled_stats *st, const char *what) {
  const int n3 = 3 * tf->nn;
  nh_integrator auto_in = {
      .dt = 1e-3, .alpha = 0.5, .beta = 1e-3, .threads = 1, .tolerance = 1e-10, .reuse = 1};
  nh_integrator every = auto_in;
  every.reuse = 0;
  double *ue = dalloc(n3), *ve = dalloc(n3);
  memcpy(ue, u, sizeof(double) * n3), memcpy(ve, v, sizeof(double) * n3);
  nh_rows ra = {0}, re = {0};
  tie_rows(&ra, tf, u, shift);
  tie_rows(&re, tf, u, shift);
  CHECK_OK(nh_step_coupled(tf->sys, &auto_in, f, u, v, 0, NULL, &ra, 1e-13, 1e-13, 200, st));
  CHECK_OK(nh_step_coupled(exact, &every, f, ue, ve, 0, NULL, &re, 1e-13, 1e-13, 200, NULL));
  double e_v = rel_diff(v, ve, n3), e_l = rel_diff(ra.lambda, re.lambda, ra.m);
  CHECK(e_v <= 1e-7 && e_l <= 1e-7,
        "kept W0, %s: reuse against exact path: v %.3g, lambda %.3g (> 1e-7)", what, e_v, e_l);
  if (verbose)
    printf("  kept W0, %s: W0 kept %d, factorised %d, corrections %d; v %.3g, lambda %.3g\n", what,
           st->w_kept, st->step.factorised, st->step.corrections, e_v, e_l);
  memcpy(u, ue, sizeof(double) * n3), memcpy(v, ve, sizeof(double) * n3); /* the exact state */
  nh_rows_free(&ra), nh_rows_free(&re);
  free(ue), free(ve);
}

/* Two steps from a fresh system and state: the first factorises (and keeps
 * its W₀), the second reuses the factor with the last row moved by `shift`. */
static void kept_sequence(double shift, int more) {
  tissue_fix tf;
  tissue_open(1e5, 0.4, &tf);
  nh_system *exact;
  CHECK_OK(nh_system_create(tf.tissue, tf.fixed, NULL, &exact));
  const int n3 = 3 * tf.nn;
  double *u = dalloc(n3), *v = dalloc(n3), *f = dalloc(n3);
  for (int i = 0; i < n3; i++) {
    if (tf.fixed[i / 3]) continue;
    u[i] = 1e-4 * nh_rand(), v[i] = 5e-2 * nh_rand(), f[i] = 1e-1 * nh_rand();
  }
  nh_coupled_stats st;
  kept_step(&tf, exact, f, u, v, 0.0, &st, "first step");
  CHECK(st.step.factorised == 1 && !st.w_kept,
        "kept W0: the first step must factorise (%d), keep nothing (%d)", st.step.factorised,
        st.w_kept);
  kept_step(&tf, exact, f, u, v, shift, &st, shift == 0.0 ? "same rows" : "a row moved");
  CHECK(st.step.factorised == 0 && st.w_kept == (shift == 0.0),
        "kept W0, row shift %g: the second step reused the factor %d (want 1), W0 %d (want %d)",
        shift, !st.step.factorised, st.w_kept, shift == 0.0);
  if (more) { /* another factor of another A: W0 belongs to the previous one */
    CHECK_OK(nh_system_factor(tf.sys));
    for (int i = 0; i < n3; i++)
      if (!tf.fixed[i / 3]) u[i] += 1e-5 * nh_rand();
    kept_step(&tf, exact, f, u, v, shift, &st, "another factor");
    CHECK(st.step.factorised == 0 && st.w_kept == 0,
          "kept W0: after another factorisation: factorised %d, kept %d (want 0, 0)",
          st.step.factorised, st.w_kept);
  }
  free(u), free(v), free(f);
  nh_system_destroy(&exact);
  tissue_close(&tf);
}

static void test_kept_w0(void) {
  kept_sequence(0.0, 1);  /* kept, then not after another factorisation */
  kept_sequence(0.01, 0); /* the last point in the next cell along x (cells are 10 mm) */
}

int main(void) {
  verbose = getenv("NH_VERBOSE") != NULL;
  kkt_case(1e5, 0.3, 1, 0.0, 0);
  kkt_case(1e7, 0.4, 1, 0.0, 0);
  kkt_case(1e6, 0.35, 1, 1e-2, 1); /* compressed past buckling */
  kkt_case(1e6, 0.35, 0, 0.0, 0);
  test_stick_slide();
  test_bad_row();
  test_kept_w0();
  TEST_END();
}
