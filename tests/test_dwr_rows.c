/* test_dwr_rows — the goal-oriented estimate of a constrained step
 * (adapt/dwr.c, "Constraints" and "Several goals in one dual") on a small
 * linear problem: the block 4 x 2 x 2 cm (E 10 kPa, ν 0.3, full element),
 * clamped at x = 4 cm, 1 µN down over the 2 mm cube centred at (1, 1, 1) cm,
 * with six constraint rows (no tool part, gap 0):
 *   r0, r1  unilateral, normal +z, on the bottom face, pressing (λ > 0);
 *   r2      friction row along x on the bottom face, sticking;
 *   r3      unilateral on the top face, open (λ = 0);
 *   r4      bilateral (a tie) inside, along (0.6, 0, 0.8);
 *   r5      friction row along y on the bottom face, sliding.
 * The active set of the dual (nh_dwr_active_rows) is then {r0, r1, r2, r4}:
 * the problem whose solution the estimate sees is A u + Jᵀλ = f, J u = 0 on
 * those four rows, bilateral.
 *
 *  1. The constrained DWR identity. V_h: the 4x2x2 grid; V_f: every cell
 *     refined once (8x4x4). u_h, u_f: the constrained solutions on both,
 *     computed independently of the code under test by a dense LU solve of
 *     the saddle-point system [K Jᵀ; J 0] (K summed from the element
 *     matrices nh_tissue_element, J from the rows' shape values). z_f: the
 *     fine constrained dual of nh_dwr_duals (CHOLMOD factor, compliance
 *     W = J A⁻¹ Jᵀ, nh_system_solve_rows). With P u_h the coarse solution
 *     carried to V_f (exact, nested), J_f P u_h = 0 (same points), so
 *       J(u_f) − J(u_h) = f(z_f) − a(P u_h, z_f)
 *     is an identity of the Galerkin equations (docs/theory.md §6.6,
 *     "Constraints"), asserted to 1e-9 relative per component. Also: z_f
 *     satisfies the active rows (J_f z_f = 0 to 1e-10 of max |z_f|), and
 *     the dual of the tissue alone (rows NULL) misses the identity by more
 *     than 1 % (the rows matter here: the test can fail).
 *  2. The combined dual (Hartmann & Houston): for two goal points, weights
 *     ω_pk of mixed signs, the estimate of the one dual of Σ ω_pk J_pk
 *     (nh_dwr_estimate_combined) equals Σ ω_pk E_pk of the separate
 *     estimates (nh_dwr_estimate) to 1e-10 relative: the recovery and the
 *     integrals are linear in the dual, and so is the constrained solve.
 *  3. Constraint data (test_data_change): the exact identity for moved
 *     points and changed gaps with the perturbed dual; with rows 0 and 4
 *     given a tool, the estimate's inherited part (the tools' rows') is
 *     their terms of that identity, and the whole term unchanged.
 *  4. Anchoring (test_anchor; docs/theory.md §6.6, "Anchoring"): the tie r4
 *     holds its material point P at a fixed place; the exact solution would
 *     hold P + ε δX. Row r4 then reads n·(x(P + ε δX) − x_0), gap
 *     g' = n·ε δX, and with the unperturbed dual (z, μ of the rows as they
 *     are, nh_dwr_duals) and Λ = −λ_f the first-order change is
 *       J(u_ε) − J(u_f) ≈ Λ₄ δ(J z)₄ − μ₄ δc₄,
 *       δc₄ = n·(x(P + ε δX; u_f) − x(P; u_f)),  δ(J z)₄ = n·(z(P + ε δX) − z(P)),
 *     the term contact/anchor.c adds. Checked against dense solves at
 *     ε = 1, 1/2, 1/4 (δX = (0.1, 0.05, 0.15) mm in 5 mm cells, P on a
 *     node, P + ε δX in one cell): the remainder must fall with order 2
 *     (observed order in [1.8, 2.2]; it is the product of two O(ε)
 *     changes, J' − J and z' − z), be below 10 % of the change at ε = 1,
 *     and the μ part must be above 5 % of it (else the test would not test
 *     the term). The tie's force here is 3e-8 N against a change of the
 *     goal of 1e-5 m: the Λ part is 1e-6 of it, so this checks the μ part.
 *  5. The front's error (nh_dwr_front_error, adapt/dwr_front.c): three
 *     bilateral rows at one point along x, y, z (a held front) with data
 *     changes δc_q and no force. The dual of a held row's own tissue part
 *     is z = 0, μ = c_K e_q (Jᵀμ is the load), so its estimate is the data
 *     term alone, E_q = −δc_q: e = −(δc_0, δc_1, δc_2) to round-off (the
 *     old front's anchoring error carried to the new one). With the
 *     friction row r2 of the header as the third row and sliding, the dual
 *     is not zero and e_2 differs from −δc_2 by more than 1 %.
 *  6. The constrained solve itself (test_solve_rows): x and μ of
 *     nh_system_solve_rows against the dense KKT solve for 2, 4 and 7
 *     right-hand sides on the fine problem's 4 active rows, so both of its
 *     routes (m >= ncol: the compliance path and a second ncol-column
 *     solve; m < ncol: G = A⁻¹ J_tᵀ, x −= G μ) are checked.
 * NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <lapacke.h>
#include <string.h>

#include "dwr_support.h"
#include "hanging_mesh.h"

#define RADIUS 5e-4
#define NROWS  6

static const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
static const int grid[3] = {4, 2, 2};
static const double points[6] = {0.025, 0.010, 0.015, 0.015, 0.015, 0.005};

typedef struct {
  nh_mesh *m;
  nh_tissue *t;
  unsigned char *fixed;
  nh_hanging *h;
  nh_system *s;
  nh_rows rows;
  double *f, *j; /* load, the first goal's 3 functionals (3 n each) */
} problem;

/* The six rows of the header on the current mesh, each point moved by
 * shift[i] (may be NULL) and given the gap g[i] (may be NULL: 0). */
static void make_rows_data(problem *p, const double (*shift)[3], const double *g) {
  static const double X[NROWS][3] = {{0.007, 0.006, 0.0},   {0.013, 0.014, 0.0},
                                     {0.011, 0.009, 0.0},   {0.022, 0.010, 0.020},
                                     {0.015, 0.005, 0.010}, {0.009, 0.012, 0.0}};
  static const double dir[NROWS][3] = {{0, 0, 1}, {0, 0, 1},     {1, 0, 0},
                                       {0, 0, 1}, {0.6, 0, 0.8}, {0, 1, 0}};
  static const nh_row_kind kind[NROWS] = {NH_ROW_UNILATERAL, NH_ROW_UNILATERAL, NH_ROW_FRICTION,
                                          NH_ROW_UNILATERAL, NH_ROW_BILATERAL,  NH_ROW_FRICTION};
  static const double lambda[NROWS] = {1e-7, 2e-7, 1e-8, 0.0, 3e-8, 1e-8};
  nh_rows_clear(&p->rows);
  for (int i = 0; i < NROWS; i++) {
    int r = nh_rows_add(&p->rows), c;
    CHECK(r == i, "row %d added as %d", i, r);
    double xi[3], N[8], Xe[24], x[3] = {0, 0, 0}, P[3];
    for (int k = 0; k < 3; k++) P[k] = X[i][k] + (shift ? shift[i][k] : 0.0);
    CHECK_OK(nh_mesh_locate(p->m, P, &c, xi));
    nh_hex_shape(xi, N);
    nh_mesh_cell_coords(p->m, p->m->X, c, Xe);
    for (int a = 0; a < 8; a++) {
      p->rows.node[8 * r + a] = p->m->cells[8 * c + a];
      p->rows.N[8 * r + a] = N[a];
      for (int k = 0; k < 3; k++) x[k] += N[a] * Xe[3 * a + k];
    }
    for (int k = 0; k < 3; k++) CHECK_CLOSE(x[k], P[k], 1e-15, "row point located");
    memcpy(p->rows.dir + 3 * r, dir[i], sizeof dir[i]);
    p->rows.tool[r] = -1;
    p->rows.gap[r] = g ? g[i] : 0.0;
    p->rows.law[r].kind = kind[i];
    p->rows.law[r].sliding = i == 5;
    p->rows.lambda[r] = lambda[i];
  }
}

static void make_rows(problem *p) {
  make_rows_data(p, NULL, NULL);
}

static void setup(problem *p) {
  nh_mesh *m = p->m;
  int n = 3 * m->n_nodes;
  nh_material mat = {1.0e4, 0.3, 1000, NH_FORMULATION_FULL};
  CHECK_OK(dwr_block_system(m, &mat, &p->t, &p->fixed, &p->h, &p->s));
  p->f = realloc(p->f, sizeof(double) * n);
  p->j = realloc(p->j, sizeof(double) * 3 * n);
  CHECK_OK(dwr_block_load(m, p->f));
  for (int k = 0; k < 3; k++)
    CHECK_OK(nh_goal_functional(m, points, RADIUS, k, "probe", p->j + (size_t)n * k));
  make_rows(p);
}

static const unsigned char active_rows[NROWS] = {1, 1, 1, 0, 1, 0};

static int active_row(int i) {
  return active_rows[i];
}

/* [K Jᵀ; J 0] of the problem's active rows (dwr_dense_kkt). */
static double *dense_kkt(const problem *p, int *dof, int *nf_out, int *N_out) {
  return dwr_dense_kkt(p->m, p->t, p->fixed, &p->rows, active_rows, dof, nf_out, N_out);
}

/* The constrained solution by a dense LU solve (dwr_dense_solve). */
static void dense_solve(const problem *p, double *u, double *lambda) {
  CHECK(dwr_dense_solve(p->m, p->t, p->fixed, p->f, &p->rows, active_rows, u, lambda) == 0,
        "dense KKT solve");
}

static double row_value(const nh_rows *rows, int i, const double *w) {
  return dwr_row_value(rows, i, w);
}

static int rows_n3; /* 3 n_nodes of the fields row_change is given */

static void destroy(problem *p) {
  nh_system_destroy(&p->s);
  nh_hanging_destroy(&p->h);
  nh_tissue_destroy(&p->t);
  nh_mesh_destroy(&p->m);
  nh_rows_free(&p->rows);
  free(p->fixed), free(p->f), free(p->j);
}

/* Part 2 on the coarse problem with its solution uh. */
static void test_combined(problem *p, const double *uh) {
  const int nc = p->m->n_cells;
  double E[6], norm[2], Ec, nc_norm;
  double *ind = malloc(sizeof(double) * 2 * nc), *indc = malloc(sizeof(double) * nc);
  nh_dwr_result r = {.estimate = E, .norm = norm, .indicator = ind};
  CHECK_OK(nh_dwr_estimate(p->s, &p->rows, 1.0, p->m, p->t, p->h, uh, 2, points, RADIUS, NULL, &r));
  CHECK(r.n_rows == 4, "separate estimate: %d rows in the duals, expected 4", r.n_rows);
  const double w[6] = {0.7, -1.3, 0.2, -0.4, 1.1, 2.5};
  double sum = 0.0, scale = 0.0;
  for (int q = 0; q < 6; q++) sum += w[q] * E[q], scale += fabs(w[q] * E[q]);
  nh_dwr_result rc = {.estimate = &Ec, .norm = &nc_norm, .indicator = indc};
  CHECK_OK(nh_dwr_estimate_combined(p->s, &p->rows, 1.0, p->m, p->t, p->h, uh, 2, points, RADIUS,
                                    NULL, w, &rc));
  CHECK(scale > 0.0, "separate estimates vanish");
  CHECK_CLOSE(Ec, sum, 1e-10 * scale, "combined estimate = sum of weighted separate estimates");
  CHECK_CLOSE(rc.eta, r.eta, 1e-14 * r.eta, "the primal's SPR estimate is the same");
  if (getenv("NH_VERBOSE"))
    printf("combined: E_c = %.9e, sum w E = %.9e (rel diff %.1e)\n", Ec, sum,
           fabs(Ec - sum) / scale);
  free(ind), free(indc);
}

/* Part 3 on the fine problem: its rows' data changed (points moved, gaps
 * set), as a finer sampling of a constraint changes them. With u_f, λ_f
 * the solution for the rows J u = 0 and u_f' the one for the new rows
 * J' u = −g' (dense, independent: K u + Jᵀλ = f), and z', μ' the dual for
 * the new rows (nh_dwr_duals: A z' + J'ᵀμ' = j, J' z' = 0),
 *   J(u_f') − J(u_f) = z'ᵀK(u_f' − u_f) + μ'ᵀJ'(u_f' − u_f)
 *                    = λ_fᵀ(J − J') z' − μ'ᵀ c'(u_f),   c'(v) = J' v + g',
 * exactly (docs/theory.md §6.6, "Constraint data"). The code's term, given
 * the rows' forces Λ = −λ_f, δc_i = c'_i(u_f) and δ(J w)_i = (J' − J)_i w,
 * must be that (both parts of it matter here: the test fails without
 * either), and the open and the sliding rows (not in the dual) must not
 * count through μ. */
typedef struct {
  const nh_rows *old, *new;
} row_pair;

static int row_change(void *ctx, int n, const double *w, double *out) {
  const row_pair *rp = ctx;
  const int m = rp->new->m;
  for (int q = 0; q < n; q++)
    for (int i = 0; i < m; i++)
      out[(size_t)m * q + i] = row_value(rp->new, i, w + (size_t)q * rows_n3) -
                               row_value(rp->old, i, w + (size_t)q * rows_n3);
  return NH_OK;
}

static void test_data_change(problem *p) {
  const double shift[NROWS][3] = {{4e-4, -3e-4, 0}, {-5e-4, 2e-4, 0},    {3e-4, 3e-4, 0},
                                  {0, 0, 0},        {2e-4, 1e-4, -3e-4}, {0, 0, 0}};
  const double g[NROWS] = {2e-9, -1e-9, 5e-10, 7e-9, 1e-9, 3e-9};
  const int n = 3 * p->m->n_nodes;
  rows_n3 = n;
  double *uf = malloc(sizeof(double) * n), *uf2 = malloc(sizeof(double) * n);
  double *z = malloc(sizeof(double) * 3 * n), lambda[NROWS], lambda2[NROWS];
  double mu[3 * NROWS], dc[NROWS], force[NROWS], E[3], norm, C[3];
  dense_solve(p, uf, lambda);
  nh_rows old = p->rows;
  p->rows = (nh_rows){0};
  make_rows_data(p, shift, g);
  dense_solve(p, uf2, lambda2);
  CHECK_OK(nh_dwr_duals(p->s, &p->rows, 1.0, p->m->n_nodes, 3, p->j, z, mu, NULL));
  for (int i = 0; i < NROWS; i++) {
    dc[i] = row_value(&p->rows, i, uf) + p->rows.gap[i];
    force[i] = -lambda[i];
  }
  row_pair rp = {&old, &p->rows};
  nh_constraint_data data = {.change = dc, .force = force, .linear = row_change, .ctx = &rp};
  nh_dwr_result r = {.estimate = E, .norm = &norm, .data = &data, .constraint = C};
  CHECK_OK(nh_dwr_estimate(p->s, &p->rows, 1.0, p->m, p->t, p->h, uf, 1, points, RADIUS, NULL, &r));
  double primal_max = 0.0;
  for (int k = 0; k < 3; k++) {
    const double *zk = z + (size_t)n * k, *jk = p->j + (size_t)n * k;
    const double lhs = dwr_dot(n, jk, uf2) - dwr_dot(n, jk, uf);
    double primal = 0.0, dual = 0.0;
    for (int i = 0; i < NROWS; i++) {
      if (!active_row(i))
        CHECK(mu[NROWS * k + i] == 0.0, "k=%d: row %d is not in the dual but has mu %g", k, i,
              mu[NROWS * k + i]);
      primal += lambda[i] * (row_value(&old, i, zk) - row_value(&p->rows, i, zk));
      dual -= mu[NROWS * k + i] * dc[i];
    }
    CHECK_CLOSE(primal + dual, lhs, 1e-9 * fabs(lhs),
                "J(u_f') - J(u_f) = lambda_f (J - J') z' - mu' c'(u_f)");
    CHECK_CLOSE(C[k], primal + dual, 1e-10 * fabs(lhs), "the code's constraint-data term");
    CHECK(fabs(dual) > 0.05 * fabs(lhs), "k=%d: the mu part is %.1e of the change: no test", k,
          dual / lhs);
    primal_max = fmax(primal_max, fabs(primal / lhs));
    if (getenv("NH_VERBOSE"))
      printf("data change k=%d: J(u_f')-J(u_f) = %.6e, lambda part %.6e, mu part %.6e, code %.6e "
             "(rel diff %.1e)\n",
             k, lhs, primal, dual, C[k], fabs(C[k] - lhs) / fabs(lhs));
  }
  CHECK(primal_max > 0.05, "the lambda part is at most %.1e of the change: no test", primal_max);
  /* The tools' rows' part, inherited (their anchors' errors, which
   * tolerance mode does not chase; refine.c): rows 0 and 4 as a tool's
   * (tool 0; the dual does not read the tool part), the rest ties. It
   * must be those rows' terms of the sum above, and C unchanged. */
  double C2[3], inh[3];
  p->rows.tool[0] = p->rows.tool[4] = 0;
  nh_dwr_result r2 = {
      .estimate = E, .norm = &norm, .data = &data, .constraint = C2, .inherited = inh};
  CHECK_OK(
      nh_dwr_estimate(p->s, &p->rows, 1.0, p->m, p->t, p->h, uf, 1, points, RADIUS, NULL, &r2));
  for (int k = 0; k < 3; k++) {
    const double *zk = z + (size_t)n * k;
    double tools = 0.0;
    for (int i = 0; i < NROWS; i += 4)
      tools += lambda[i] * (row_value(&old, i, zk) - row_value(&p->rows, i, zk)) -
               mu[NROWS * k + i] * dc[i];
    CHECK_CLOSE(C2[k], C[k], 1e-12 * fabs(C[k]), "the constraint term, summed in two parts");
    CHECK_CLOSE(inh[k], tools, 1e-10 * fabs(C[k]), "the tools' rows' (inherited) part");
    CHECK(fabs(tools) > 0.05 * fabs(C[k]) && fabs(C[k] - tools) > 0.05 * fabs(C[k]),
          "k=%d: the tools' part %.1e of C: no test", k, tools / C[k]);
  }
  nh_rows_free(&p->rows);
  p->rows = old;
  free(uf), free(uf2), free(z);
}

static void test_anchor(problem *p) {
  const double dX[3] = {1e-4, 0.5e-4, 1.5e-4}, *n4 = p->rows.dir + 3 * 4;
  const int n = 3 * p->m->n_nodes;
  rows_n3 = n;
  double *uf = malloc(sizeof(double) * n), *ue = malloc(sizeof(double) * n);
  double *z = malloc(sizeof(double) * 3 * n), lambda[NROWS], mu[3 * NROWS], rem[3][3], dj[3][3];
  dense_solve(p, uf, lambda);
  CHECK_OK(nh_dwr_duals(p->s, &p->rows, 1.0, p->m->n_nodes, 3, p->j, z, mu, NULL));
  nh_rows old = p->rows;
  p->rows = (nh_rows){0};
  for (int e = 0; e < 3; e++) {
    const double eps = 1.0 / (1 << e);
    double shift[NROWS][3] = {{0}}, g[NROWS] = {0};
    for (int k = 0; k < 3; k++) shift[4][k] = eps * dX[k];
    g[4] = eps * nh_vec3_dot(n4, dX); /* the tie holds the moved point where P was held */
    make_rows_data(p, shift, g);
    dense_solve(p, ue, NULL);
    const double dc = row_value(&p->rows, 4, uf) + g[4] - row_value(&old, 4, uf);
    for (int k = 0; k < 3; k++) {
      const double *zk = z + (size_t)n * k;
      const double lhs =
          dwr_dot(n, p->j + (size_t)n * k, ue) - dwr_dot(n, p->j + (size_t)n * k, uf);
      const double dual = -mu[NROWS * k + 4] * dc;
      const double primal = -lambda[4] * (row_value(&p->rows, 4, zk) - row_value(&old, 4, zk));
      rem[e][k] = lhs - primal - dual;
      dj[e][k] = lhs;
      if (e == 0)
        CHECK(fabs(dual) > 0.05 * fabs(lhs), "k=%d: the mu part is %.1e of the change: no test", k,
              dual / lhs);
      if (getenv("NH_VERBOSE"))
        printf("anchor eps=%.3f k=%d: dJ = %.6e, Lambda dJz = %.6e, -mu dc = %.6e, remainder "
               "%.3e (%.1e of dJ)\n",
               eps, k, lhs, primal, dual, rem[e][k], rem[e][k] / lhs);
    }
    nh_rows_free(&p->rows);
  }
  for (int k = 0; k < 3; k++) {
    CHECK(fabs(rem[0][k]) < 0.1 * fabs(dj[0][k]), "k=%d: remainder %.2e of dJ %.2e at eps = 1", k,
          rem[0][k], dj[0][k]);
    for (int e = 0; e < 2; e++) {
      const double order = log2(fabs(rem[e][k] / rem[e + 1][k]));
      CHECK(order > 1.8 && order < 2.2, "k=%d: remainder order %.3f between eps = %g and %g", k,
            order, 1.0 / (1 << e), 1.0 / (2 << e));
      if (getenv("NH_VERBOSE")) printf("anchor k=%d: remainder order %.3f\n", k, order);
    }
  }
  p->rows = old;
  free(uf), free(ue), free(z);
}

static int no_change(void *ctx, int n, const double *w, double *out) {
  (void)w;
  const int m = *(const int *)ctx;
  memset(out, 0, sizeof(double) * (size_t)m * (size_t)n);
  return NH_OK;
}

static void test_front(problem *p) {
  static const double P[3] = {0.015, 0.007, 0.012}, dc[3] = {2e-6, -3e-6, 5e-6};
  nh_rows rows = {0};
  double force[3] = {0, 0, 0}, change[3], e[3];
  int c, m = 3;
  double xi[3], N[8];
  CHECK_OK(nh_mesh_locate(p->m, P, &c, xi));
  nh_hex_shape(xi, N);
  for (int q = 0; q < 3; q++) {
    int r = nh_rows_add(&rows);
    for (int a = 0; a < 8; a++)
      rows.node[8 * r + a] = p->m->cells[8 * c + a], rows.N[8 * r + a] = N[a];
    rows.dir[3 * r + q] = 1.0;
    rows.tool[r] = -1;
    rows.law[r].kind = NH_ROW_BILATERAL;
    change[q] = dc[q];
  }
  nh_constraint_data data = {.change = change, .force = force, .linear = no_change, .ctx = &m};
  double *u = calloc(3 * (size_t)p->m->n_nodes, sizeof(double));
  dense_solve(p, u, NULL);
  CHECK_OK(nh_dwr_front_error(p->s, &rows, 1.0, p->m, p->t, p->h, u, 0, NULL, &data, e));
  for (int k = 0; k < 3; k++) {
    CHECK_CLOSE(e[k], -dc[k], 1e-9 * fabs(dc[k]), "held front: e = -dc");
    if (getenv("NH_VERBOSE")) printf("front k=%d: e = %.9e, -dc = %.9e\n", k, e[k], -dc[k]);
  }
  rows.law[2] = (nh_row_law){NH_ROW_FRICTION, 0, 1, 0.1, 1e-9, -1, 0.1, 1, 1};
  CHECK_OK(nh_dwr_front_error(p->s, &rows, 1.0, p->m, p->t, p->h, u, 0, NULL, &data, e));
  CHECK(fabs(e[2] + dc[2]) > 0.01 * fabs(dc[2]), "cutting row: e_2 = %.3e is the data term alone",
        e[2]);
  if (getenv("NH_VERBOSE")) printf("front, sliding axial row: e_2 = %.9e\n", e[2]);
  nh_rows_free(&rows);
  free(u);
}

/* Part 6: nh_system_solve_rows itself against the dense KKT solve, for
 * NCOL_MAX right-hand sides b_q (smooth, made up, nonzero on every free
 * DOF): A x_q + J_tᵀ μ_q = b_q, J_t x_q = 0 on the four active rows, by
 * LU of [K Jᵀ; J 0] (dense_kkt). ncol = 2 and 4 take the compliance path
 * (m = 4 >= ncol: W by nh_system_compliance_add, a second solve of ncol
 * columns), ncol = 7 the other (m < ncol: G = A⁻¹ J_tᵀ, W = J_t G,
 * x −= G μ). x and μ must match to 1e-10 of their largest entries (the
 * round-off of the two factorisations on this problem: measured 6e-15 to
 * 1.1e-14, NH_VERBOSE=1), and the two routes' common columns to 1e-12
 * (measured 3e-15). */
#define NCOL_MAX 7

static void test_solve_rows(problem *p) {
  const int n = 3 * p->m->n_nodes, nf = nh_system_free_dofs(p->s), ncols[3] = {2, 4, NCOL_MAX};
  int *dof = malloc(sizeof(int) * n), nk, N;
  double *A = dense_kkt(p, dof, &nk, &N);
  double *bfull = malloc(sizeof(double) * n), *bd = calloc((size_t)N * NCOL_MAX, sizeof(double));
  double *b = malloc(sizeof(double) * nf * NCOL_MAX), *x = malloc(sizeof(double) * nf * NCOL_MAX);
  double *x7 = malloc(sizeof(double) * nf * NCOL_MAX), mu[NROWS * NCOL_MAX], mu7[NROWS * NCOL_MAX];
  double *xq = malloc(sizeof(double) * n);
  int *piv = malloc(sizeof(int) * N);
  CHECK(nk == nf, "dense KKT: %d unfixed DOFs, the system has %d", nk, nf);
  for (int q = 0; q < NCOL_MAX; q++) {
    for (int i = 0; i < n; i++) bfull[i] = 1e-6 * sin(0.37 * i + 1.1 * q) * (1.0 + 0.1 * q);
    nh_system_gather(p->s, bfull, b + (size_t)nf * q);
    for (int i = 0; i < n; i++)
      if (dof[i] >= 0) bd[(size_t)N * q + dof[i]] = bfull[i];
  }
  CHECK(LAPACKE_dgesv(LAPACK_COL_MAJOR, N, NCOL_MAX, A, N, piv, bd, N) == 0, "dense KKT solve");
  for (int c = 2; c >= 0; c--) { /* ncol = 7 first: the other routes are compared with it */
    const int ncol = ncols[c];
    int used = -1;
    CHECK_OK(nh_system_solve_rows(p->s, &p->rows, active_rows, ncol, b, x, mu, &used));
    CHECK(used == 4, "ncol=%d: %d active rows, expected 4", ncol, used);
    double xmax = 0.0, xerr = 0.0, mumax = 0.0, muerr = 0.0, xdiff = 0.0, mudiff = 0.0;
    for (int q = 0; q < ncol; q++) {
      nh_system_scatter(p->s, x + (size_t)nf * q, xq);
      for (int i = 0; i < n; i++) {
        const double e = dof[i] >= 0 ? bd[(size_t)N * q + dof[i]] : 0.0;
        xmax = fmax(xmax, fabs(e)), xerr = fmax(xerr, fabs(xq[i] - e));
      }
      for (int i = 0, row = nk; i < NROWS; i++) {
        const double e = active_rows[i] ? bd[(size_t)N * q + row++] : 0.0, v = mu[NROWS * q + i];
        mumax = fmax(mumax, fabs(e)), muerr = fmax(muerr, fabs(v - e));
        if (ncol < NCOL_MAX) mudiff = fmax(mudiff, fabs(v - mu7[NROWS * q + i]));
      }
      for (int i = 0; i < nf && ncol < NCOL_MAX; i++)
        xdiff = fmax(xdiff, fabs(x[(size_t)nf * q + i] - x7[(size_t)nf * q + i]));
    }
    CHECK(xmax > 0.0 && mumax > 0.0, "ncol=%d: the dense solution vanishes", ncol);
    CHECK(xerr <= 1e-10 * xmax, "ncol=%d: max |x - x_dense| = %.3e, 1e-10 of max |x| = %.3e", ncol,
          xerr, 1e-10 * xmax);
    CHECK(muerr <= 1e-10 * mumax, "ncol=%d: max |mu - mu_dense| = %.3e, 1e-10 of max |mu| = %.3e",
          ncol, muerr, 1e-10 * mumax);
    if (ncol < NCOL_MAX) {
      CHECK(xdiff <= 1e-12 * xmax, "ncol=%d: x differs from ncol=%d's by %.3e (max |x| %.3e)", ncol,
            NCOL_MAX, xdiff, xmax);
      CHECK(mudiff <= 1e-12 * mumax, "ncol=%d: mu differs from ncol=%d's by %.3e (max |mu| %.3e)",
            ncol, NCOL_MAX, mudiff, mumax);
    } else
      memcpy(x7, x, sizeof(double) * nf * NCOL_MAX), memcpy(mu7, mu, sizeof mu);
    if (getenv("NH_VERBOSE"))
      printf("solve_rows ncol=%d: |x - dense| %.1e of max |x|, |mu - dense| %.1e of max |mu|; "
             "against ncol=%d: x %.1e, mu %.1e\n",
             ncol, xerr / xmax, muerr / mumax, NCOL_MAX, xdiff / xmax, mudiff / mumax);
  }
  free(dof), free(A), free(bfull), free(bd), free(b), free(x), free(x7), free(xq), free(piv);
}

int main(void) {
  problem p = {0};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &p.m));
  setup(&p);
  int nc = p.m->n_nodes, n = 3 * nc;
  double Jh[3], *uh = malloc(sizeof(double) * n);
  dense_solve(&p, uh, NULL);
  for (int k = 0; k < 3; k++) Jh[k] = dwr_dot(n, p.j + (size_t)n * k, uh);
  for (int i = 0; i < NROWS; i++)
    if (active_row(i))
      CHECK_CLOSE(row_value(&p.rows, i, uh), 0.0, 1e-12 * fabs(Jh[2]), "coarse rows hold");
  test_combined(&p, uh);

  /* V_f: every leaf refined once. */
  nh_template *t2 = regular_template(2);
  nh_refine_info info = {0};
  int nl = p.m->n_leaves, *all = malloc(sizeof(int) * nl);
  memcpy(all, p.m->leaves, sizeof(int) * nl);
  CHECK_OK(nh_mesh_refine(p.m, t2, all, nl, &info));
  double *Puh = dwr_prolong(p.m, &info, uh, nc);
  setup(&p);
  int nfn = 3 * p.m->n_nodes;
  double *uf = malloc(sizeof(double) * nfn), *zf = malloc(sizeof(double) * 3 * nfn);
  double *z0 = malloc(sizeof(double) * 3 * nfn);
  dense_solve(&p, uf, NULL);
  int used = -1;
  CHECK_OK(nh_dwr_duals(p.s, &p.rows, 1.0, p.m->n_nodes, 3, p.j, zf, NULL, &used));
  CHECK(used == 4, "active rows in the dual: %d, expected 4", used);
  CHECK_OK(nh_dwr_duals(p.s, NULL, 1.0, p.m->n_nodes, 3, p.j, z0, NULL, NULL));
  for (int k = 0; k < 3; k++) {
    const double *jk = p.j + (size_t)nfn * k, *zk = zf + (size_t)nfn * k,
                 *z0k = z0 + (size_t)nfn * k;
    double zmax = 0.0;
    for (int i = 0; i < nfn; i++) zmax = fmax(zmax, fabs(zk[i]));
    for (int i = 0; i < NROWS; i++) {
      if (active_row(i)) {
        CHECK_CLOSE(row_value(&p.rows, i, zk), 0.0, 1e-10 * zmax, "the dual obeys the active rows");
        CHECK_CLOSE(row_value(&p.rows, i, Puh), 0.0, 1e-12 * fabs(Jh[2]), "J_f P u_h = 0");
      }
    }
    double JPuh = dwr_dot(nfn, jk, Puh), Juf = dwr_dot(nfn, jk, uf);
    double lhs = Juf - Jh[k], rhs = dwr_dot(nfn, p.f, zk) - dwr_energy_product(p.m, p.t, Puh, zk);
    double rhs0 = dwr_dot(nfn, p.f, z0k) - dwr_energy_product(p.m, p.t, Puh, z0k);
    double scale = fmax(fabs(Juf), fabs(Jh[k]));
    CHECK_CLOSE(JPuh, Jh[k], 1e-12 * scale, "J(P u_h) on V_f = J(u_h) on V_h");
    CHECK_CLOSE(rhs, lhs, 1e-9 * fabs(lhs),
                "constrained DWR identity J(u_f) - J(u_h) = rho(u_h; z_f)");
    CHECK(fabs(rhs0 - lhs) > 1e-2 * fabs(lhs),
          "k=%d: the unconstrained dual misses the identity by only %.2e relative", k,
          fabs(rhs0 - lhs) / fabs(lhs));
    if (getenv("NH_VERBOSE"))
      printf("identity k=%d: J(u_f)-J(u_h) = %.6e, rho(z_f) = %.6e (rel diff %.1e), "
             "tissue-alone dual %.6e (rel diff %.1e)\n",
             k, lhs, rhs, fabs(lhs - rhs) / fabs(lhs), rhs0, fabs(lhs - rhs0) / fabs(lhs));
  }
  test_data_change(&p);
  test_anchor(&p);
  test_front(&p);
  test_solve_rows(&p);
  nh_refine_info_free(&info);
  nh_template_destroy(&t2);
  free(all), free(uh), free(Puh), free(uf), free(zf), free(z0);
  destroy(&p);
  return nh_test_failures ? 1 : 0;
}
