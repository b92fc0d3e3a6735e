/* test_inherit — a solve after a mesh change with the old mesh's factor
 * extended to the new unknowns (solve/inherit.c) against the solve with a
 * factorisation of the new A (what solver.refactor: every does).
 *
 * The phantom's block (4 x 2 x 2 cm, 8 x 4 x 4 cells, E 10 MPa, ν 0.4,
 * clamped at x = 4 cm), the dynamic A = M + (hβ + h²) K of its 10 ms steps
 * at a displacement with rotated elements:
 *  1. refining: the cells along the needle's axis refined by hex2 (adapt's
 *     nh_adapt_refine_cells: new nodes and hanging nodes);
 *  2. coarsening: from that mesh, the refined families away from the one
 *     holding a displacement merged again (nh_adapt_step with
 *     adapt.coarsen 0.5, θ = 1 and max_level 1: the largest indicator is
 *     at max_level, nothing is refined, the families below half of it merge).
 * In each, the old system is factorised at the old displacement, the new
 * one inherits its factor and solves A x = b by PCG at tol (reuse.c); the
 * reference x* is the direct solve with a factorisation of the new A.
 *
 * The bound, from the PCG stop and the preconditioner's conditioning: the
 * stop √(rᵀBr) <= tol √(bᵀBb) with r = A e gives, with λ the eigenvalues of
 * BA (those of A^½ B A^½), λ_min ‖e‖²_A <= rᵀBr and bᵀBb <= λ_max ‖x*‖²_A, so
 * ‖e‖_A <= tol √(λ_max / λ_min) ‖x*‖_A; the final refinement step
 * x += B r multiplies e by I − BA, of A-norm max |1 − λ| (taken as at least
 * 1). λ are computed here independently of the solver: B formed column by
 * column, the dense generalized eigenproblem A B v = λ v (LAPACK dsygv),
 * which also checks that B is positive definite. The test asserts the bound,
 * that no factorisation of the new A was made for the PCG solve, and that
 * PCG converged in fewer than NH_PCG_MAX iterations. */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/system_impl.h"

#include <lapacke.h>
#include <string.h>

static const double H = 0.01, BETA = 0.001; /* the phantom's step and stiffness damping */
static const double LO[3] = {0, 0, 0}, HI[3] = {0.04, 0.02, 0.02};
static const nh_material MAT = {10.0e6, 0.4, 1000, NH_FORMULATION_BBAR};

/* The mesh's state: tissue, fixed nodes (x = 4 cm), hanging nodes, system. */
typedef struct {
  nh_tissue *tissue;
  unsigned char *fixed;
  nh_hanging *hanging;
  nh_system *s;
} state;

static void state_build(nh_mesh *m, state *st) {
  st->fixed = calloc((size_t)m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) st->fixed[i] = m->X[3 * i] > HI[0] - 1e-9;
  CHECK_OK(nh_tissue_create(m, &MAT, &st->tissue));
  CHECK_OK(nh_hanging_detect(m, st->fixed, &st->hanging));
  CHECK_OK(nh_system_create(st->tissue, st->fixed, st->hanging, &st->s));
}

static void state_free(state *st) {
  nh_system_destroy(&st->s);
  nh_tissue_destroy(&st->tissue);
  nh_hanging_destroy(&st->hanging);
  free(st->fixed);
}

/* A displacement that rotates the elements: a bending of the block. */
static double *bending(const nh_mesh *m, double scale) {
  double *u = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  for (int a = 0; a < m->n_nodes; a++) {
    const double *X = m->X + 3 * a, s = (HI[0] - X[0]) / HI[0];
    u[3 * a + 1] = scale * s * s;
    u[3 * a + 2] = 0.5 * scale * s * s * s;
    u[3 * a] = -scale * s * (X[1] - 0.01);
  }
  return u;
}

static void assemble(state *st, const double *u) {
  double *f = calloc(3 * (size_t)st->s->n_nodes, sizeof(double));
  nh_system_assemble(st->s, u, NULL, 1.0, H * BETA + H * H, f, NULL, 1);
  free(f);
}

static double a_dot(nh_system *s, const double *x, const double *y) {
  double *q = malloc(sizeof(double) * (size_t)s->n_free), sum = 0.0;
  nh_system_apply(s, y, q);
  for (int i = 0; i < s->n_free; i++) sum += x[i] * q[i];
  free(q);
  return sum;
}

/* The eigenvalues of B A for the inherited preconditioner B of s (dense). */
static void spectrum(nh_system *s, double *lmin, double *lmax) {
  const int n = s->n_free;
  double *A = calloc((size_t)n * n, sizeof(double)), *B = calloc((size_t)n * n, sizeof(double));
  double *e = calloc((size_t)n, sizeof(double)), *w = malloc(sizeof(double) * (size_t)n);
  const int *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x;
  for (int j = 0; j < n; j++)
    for (int p = Ap[j]; p < Ap[j + 1]; p++)
      A[(size_t)j * n + Ai[p]] = A[(size_t)Ai[p] * n + j] = Ax[p];
  for (int j = 0; j < n; j++) {
    e[j] = 1.0;
    CHECK_OK(nh_inherit_apply(s, e, B + (size_t)j * n));
    e[j] = 0.0;
  }
  for (int j = 0; j < n; j++) /* symmetric to round-off: its upper triangle is read */
    for (int i = 0; i < j; i++) {
      double d = fabs(B[(size_t)j * n + i] - B[(size_t)i * n + j]);
      CHECK(d <= 1e-8 * fabs(B[(size_t)j * n + j]), "B not symmetric at (%d, %d): %g", i, j, d);
    }
  /* itype 2: A B v = λ v, B positive definite (its Cholesky factor fails otherwise) */
  int info = LAPACKE_dsygv(LAPACK_COL_MAJOR, 2, 'N', 'U', n, A, n, B, n, w);
  CHECK(info == 0, "dsygv: info %d (> n: B is not positive definite)", info);
  *lmin = w[0], *lmax = w[n - 1];
  free(A), free(B), free(e), free(w);
}

/* old: factorised (on the mesh before the change); new: inherits its
 * factor through t, assembled at u_new; PCG against the direct solve. */
static void compare(const char *what, state *old, state *nw, const nh_node_transfer *t,
                    const double *u_new) {
  CHECK_OK(nh_system_inherit(nw->s, old->s, t));
  CHECK(nh_system_inherited(nw->s), "%s: the new system did not inherit the factor", what);
  assemble(nw, u_new);
  nh_integrator in = {.dt = H, .beta = BETA, .tolerance = 1e-8, .reuse = 1};
  nh_step_stats st = {0};
  CHECK_OK(nh_system_factor_or_reuse(nw->s, &in, NH_FACTOR_STEP, &st));
  CHECK(st.factorised == 0 && nh_system_inherited(nw->s), "%s: the step factorised", what);
  const int n = nw->s->n_free;
  double *b = malloc(sizeof(double) * n), *x = malloc(sizeof(double) * n),
         *xs = malloc(sizeof(double) * n);
  for (int i = 0; i < n; i++) b[i] = 1e-6 * sin(0.37 * i + 1.0) * (1.0 + (i % 3)); /* impulses */
  double lmin, lmax;
  spectrum(nw->s, &lmin, &lmax);
  int its = 0;
  double tf = 0.0;
  CHECK_OK(nh_system_solve_reuse(nw->s, b, x, in.tolerance, &its, &tf));
  CHECK(its > 0 && its < NH_PCG_MAX && tf == 0.0 && nh_system_inherited(nw->s),
        "%s: PCG %d iterations, factorisation time %g", what, its, tf);
  /* the reference: a factorisation of the same A */
  CHECK_OK(nh_system_factor(nw->s));
  CHECK_OK(nh_system_solve(nw->s, b, xs));
  double *e = malloc(sizeof(double) * n);
  for (int i = 0; i < n; i++) e[i] = x[i] - xs[i];
  const double err = sqrt(a_dot(nw->s, e, e)), norm = sqrt(a_dot(nw->s, xs, xs));
  const double kappa = lmax / lmin, grow = fmax(1.0, fmax(fabs(1.0 - lmin), fabs(lmax - 1.0)));
  const double bound = grow * in.tolerance * sqrt(kappa) * norm + 1e-13 * norm;
  if (getenv("NH_VERBOSE"))
    printf("%s: %d unknowns, λ(BA) in [%.4f, %.4f], κ %.2f, %d PCG iterations, ‖e‖_A/‖x*‖_A "
           "%.3g, bound %.3g\n",
           what, n, lmin, lmax, kappa, its, err / norm, bound / norm);
  CHECK(lmin > 0.0, "%s: λ_min(BA) = %g", what, lmin);
  CHECK_CLOSE(err, 0.0, bound, what);
  free(b), free(x), free(xs), free(e);
}

int main(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  nh_adapt_spec spec = {.enabled = 1,
                        .strategy = NH_MARK_MAX,
                        .theta = 1.0, /* only the largest: in family 0, at max_level */
                        .max_level = 1,
                        .every = 1,
                        .coarsen = 0.5};
  snprintf(spec.template_path, sizeof spec.template_path, "%s/templates/hex2.tmpl",
           src ? src : ".");
  nh_adapt *a;
  CHECK_OK(nh_adapt_create(&spec, 0, &a));
  nh_mesh *m;
  const int grid[3] = {8, 4, 4};
  CHECK_OK(nh_mesh_create_box(LO, HI, grid, &m));

  /* 1. refining: the 8 cells around the axis y = z = 1 cm in x < 1 cm */
  state s0, s1, s2;
  state_build(m, &s0);
  double *u = bending(m, 2e-3);
  assemble(&s0, u);
  CHECK_OK(nh_system_factor(s0.s));
  int cells[16], n = 0;
  for (int l = 0; l < m->n_leaves && n < 16; l++) {
    const int c = m->leaves[l];
    double lo[3] = {1e9, 1e9, 1e9};
    for (int k = 0; k < 8; k++)
      for (int i = 0; i < 3; i++) lo[i] = fmin(lo[i], m->X[3 * m->cells[8 * c + k] + i]);
    if (lo[0] < 0.01 - 1e-9 && lo[1] > 0.004 && lo[1] < 0.011 && lo[2] > 0.004 && lo[2] < 0.011)
      cells[n++] = c;
  }
  CHECK(n == 8, "%d cells on the axis, expected 8", n);
  double *fields[1] = {u};
  CHECK_OK(nh_adapt_refine_cells(a, m, cells, n, 1, fields));
  u = fields[0];
  const nh_node_transfer *t = nh_adapt_last_transfer(a);
  CHECK(t && t->n_new == m->n_nodes, "no transfer of the refinement");
  state_build(m, &s1);
  CHECK(s1.hanging->n_hanging > 0, "the refined mesh has no hanging node");
  double *u1 = bending(m, 2.2e-3);      /* the state moved on since the factorisation */
  compare("refining", &s0, &s1, t, u1); /* leaves s1 factorised at u1 */
  state_free(&s0);

  /* 2. coarsening: indicators that vanish but in the first refined family
   * (a displacement only at its centre node): the others merge */
  double *z = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  const int c0 = m->first_child[cells[0]];
  const int centre = m->cells[8 * c0 + 6]; /* corner 6 of the first child: the parent's centre */
  z[3 * centre + 1] = 1e-5;
  double eta, eta_rel;
  CHECK_OK(nh_adapt_estimate(a, m, s1.tissue, z, s1.hanging, NULL, &eta, &eta_rel));
  int changed = 0, before = m->n_leaves;
  double *f2[2] = {u1, z};
  CHECK_OK(nh_adapt_step(a, m, 2, f2, &changed));
  u1 = f2[0], z = f2[1];
  CHECK(changed > 0 && m->n_leaves < before, "nothing coarsened (%d leaves, %d before)",
        m->n_leaves, before);
  t = nh_adapt_last_transfer(a);
  CHECK(t && t->n_new == m->n_nodes, "no transfer of the coarsening");
  state_build(m, &s2);
  double *u2 = bending(m, 2.4e-3);
  compare("coarsening", &s1, &s2, t, u2);
  state_free(&s1);
  state_free(&s2);
  nh_adapt_destroy(&a);
  nh_mesh_destroy(&m);
  free(u), free(u1), free(u2), free(z);
  TEST_END();
}
