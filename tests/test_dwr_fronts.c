/* test_dwr_fronts.c — the fronts' errors estimated in the goal estimate's
 * pass (adapt/dwr_front.c, nh_dwr_result.fronts) against each front
 * estimated alone (nh_dwr_front_error) and the goals estimated without
 * fronts.
 *
 * The block of test_dwr_rows (4 × 2 × 2 cells of 1 cm, clamped at x = 4 cm,
 * B-bar) at a smooth state u, with eight rows: front A (rows 0–2 at one
 * point along x, y, z: bilateral, bilateral, sticking friction), a
 * sticking friction row (3), front B (rows 4–6 along an oblique
 * orthonormal frame: pressing unilateral, bilateral, sliding friction) and
 * a unilateral row that does not press (7); data changes, forces and a
 * linearised change (δ(J w)_i = 0.01 n_i · w(P_i)) on every row, so the
 * constraint-data term is not zero. Every dual's terms are its own (the
 * duals meet only in sums over each dual's own terms, and in the solve), so:
 *  1. a goal estimate of 2 points with the two fronts gives the goals'
 *     estimates, indicators, η and η_rel of the estimate without fronts,
 *     and each front's e of nh_dwr_front_error, to round-off (1e-12
 *     relative: the goals' and fronts' duals share one solve, whose BLAS
 *     calls differ from each set's alone; a front's dual with the goals'
 *     rows would be off by O(1)): 6 goal duals and 6 fronts' duals, so
 *     front B's straddle the 8-dual blocks of the centre stresses;
 *  2. the same for the combined functional of the goals (one dual);
 *  3. a front's dual treats every friction row but its own axial row as
 *     sliding (the header of dwr_front.c): front B's e is bitwise the same
 *     when row 3 slides, while the goals' estimates change (row 3 is in
 *     their dual);
 *  4. front A's rows all hold its dual: z = 0, μ = c_K e_q, so e = −(δc_0,
 *     δc_1, δc_2) to round-off (test_dwr_rows, part 5); front B's e is not
 *     zero and differs from −Σ_q δc_{4+q} n_q by more than 1 % (its
 *     sliding axial row leaves a dual that is not zero);
 *  5. a shaft point's dual (dwr_front.c, "Shaft points") is its axial
 *     functional with every friction row free: with both fronts' axial
 *     rows sliding, points at their rows have t · e of those fronts, to
 *     round-off, in one pass with the goals and the fronts, whose numbers
 *     do not change;
 *  6. with front A's axial row sticking (held in the goals' duals), a point
 *     at its rows changes the goals' estimates exactly as −e_p added to
 *     that row's data change does.
 * NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "dwr_support.h"

#define RADIUS 5e-4
#define NROWS  8
/* the goals' and the fronts' duals share one solve (nh_system_solve_rows_sets):
 * their columns and W's block go through other BLAS calls than alone */
#define ROUNDOFF 1e-12

/* max |a − b| / max |a| */
static double max_rel_diff(int n, const double *a, const double *b) {
  double d = 0.0, s = 0.0;
  for (int i = 0; i < n; i++) d = fmax(d, fabs(a[i] - b[i])), s = fmax(s, fabs(a[i]));
  return s > 0.0 ? d / s : d;
}

static const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
static const int grid[3] = {4, 2, 2};
static const double points[6] = {0.025, 0.010, 0.015, 0.015, 0.015, 0.005};
static const double weights[6] = {0.7, -1.3, 0.2, -0.4, 1.1, 2.5};

typedef struct {
  const nh_mesh *m;
  const nh_rows *rows;
} linear_ctx;

/* δ(J w)_i = 0.01 n_i · w(P_i) for each of the n fields w. */
static int row_change(void *ctx, int n, const double *w, double *out) {
  const linear_ctx *x = ctx;
  const size_t n3 = 3 * (size_t)x->m->n_nodes;
  for (int q = 0; q < n; q++)
    for (int i = 0; i < x->rows->m; i++) {
      double s = 0.0;
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++)
          s += x->rows->N[8 * i + a] * x->rows->dir[3 * i + k] *
               w[n3 * q + 3 * (size_t)x->rows->node[8 * i + a] + k];
      out[(size_t)x->rows->m * q + i] = 0.01 * s;
    }
  return NH_OK;
}

static void make_rows(const nh_mesh *m, nh_rows *rows) {
  static const double X[NROWS][3] = {
      {0.015, 0.007, 0.012}, {0.015, 0.007, 0.012}, {0.015, 0.007, 0.012}, {0.011, 0.009, 0.004},
      {0.027, 0.012, 0.009}, {0.027, 0.012, 0.009}, {0.027, 0.012, 0.009}, {0.006, 0.014, 0.017}};
  static const double dir[NROWS][3] = {{1, 0, 0},     {0, 1, 0}, {0, 0, 1},      {0, 0, 1},
                                       {0.6, 0, 0.8}, {0, 1, 0}, {-0.8, 0, 0.6}, {0, 1, 0}};
  static const nh_row_kind kind[NROWS] = {NH_ROW_BILATERAL, NH_ROW_BILATERAL,  NH_ROW_FRICTION,
                                          NH_ROW_FRICTION,  NH_ROW_UNILATERAL, NH_ROW_BILATERAL,
                                          NH_ROW_FRICTION,  NH_ROW_UNILATERAL};
  static const int sliding[NROWS] = {0, 0, 0, 0, 0, 0, 1, 0};
  static const double lambda[NROWS] = {2e-8, -1e-8, 3e-8, 1e-8, 4e-8, 2e-8, 1e-8, 0.0};
  for (int i = 0; i < NROWS; i++) {
    int r = nh_rows_add(rows), c;
    double xi[3], N[8];
    CHECK(r == i, "row %d added as %d", i, r);
    CHECK_OK(nh_mesh_locate(m, X[i], &c, xi));
    nh_hex_shape(xi, N);
    for (int a = 0; a < 8; a++)
      rows->node[8 * r + a] = m->cells[8 * c + a], rows->N[8 * r + a] = N[a];
    memcpy(rows->dir + 3 * r, dir[i], sizeof dir[i]);
    rows->tool[r] = -1;
    rows->law[r].kind = kind[i];
    rows->law[r].sliding = sliding[i];
    rows->lambda[r] = lambda[i];
  }
}

/* A goal estimate (separate, or combined with `weights`) with the fronts
 * (may be NULL) into E (6 or 1), ind (2 or 1 per cell), *r. */
static void estimate(nh_system *s, const nh_rows *rows, const nh_mesh *m, const nh_tissue *t,
                     const nh_hanging *h, const double *u, const nh_constraint_data *data,
                     int combined, nh_dwr_fronts *fronts, double *E, double *ind,
                     nh_dwr_result *r) {
  double norm[2];
  *r = (nh_dwr_result){
      .estimate = E, .norm = norm, .indicator = ind, .data = data, .fronts = fronts};
  if (combined)
    CHECK_OK(
        nh_dwr_estimate_combined(s, rows, 1.0, m, t, h, u, 2, points, RADIUS, NULL, weights, r));
  else
    CHECK_OK(nh_dwr_estimate(s, rows, 1.0, m, t, h, u, 2, points, RADIUS, NULL, r));
}

int main(void) {
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  unsigned char *fixed = NULL;
  nh_hanging *h = NULL;
  nh_system *s = NULL;
  nh_rows rows = {0};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {1.0e4, 0.3, 1000, NH_FORMULATION_BBAR};
  CHECK_OK(dwr_block_system(m, &mat, &t, &fixed, &h, &s));
  make_rows(m, &rows);
  const int nn = m->n_nodes, nc = m->n_cells;
  double *u = calloc(3 * (size_t)nn, sizeof(double));
  for (int i = 0; i < nn; i++) { /* smooth, 0 on the clamp at x = 4 cm */
    if (fixed[i]) continue;
    const double *X = m->X + 3 * i, d = 0.04 - X[0];
    u[3 * i] = 2e-4 * d * X[1] / 0.04, u[3 * i + 1] = -3e-4 * d * X[2] / 0.02;
    u[3 * i + 2] = 1e-4 * d * (X[0] + X[1]) / 0.04;
  }
  double change[NROWS], force[NROWS];
  for (int i = 0; i < NROWS; i++)
    change[i] = 1e-6 * (i + 1) * (i % 2 ? -1 : 1), force[i] = 1e-3 * (i - 3);
  linear_ctx lx = {m, &rows};
  nh_constraint_data data = {.change = change, .force = force, .linear = row_change, .ctx = &lx};

  double eA[3], eB[3];
  CHECK_OK(nh_dwr_front_error(s, &rows, 1.0, m, t, h, u, 0, NULL, &data, eA));
  CHECK_OK(nh_dwr_front_error(s, &rows, 1.0, m, t, h, u, 4, NULL, &data, eB));
  double eB_data[3] = {0, 0, 0}, off = 0.0; /* front B's data term alone */
  for (int q = 0; q < 3; q++)
    for (int k = 0; k < 3; k++) eB_data[k] -= change[4 + q] * rows.dir[3 * (4 + q) + k];
  for (int k = 0; k < 3; k++) {
    CHECK_CLOSE(eA[k], -change[k], 1e-9 * fabs(change[k]), "held front A: e = -dc");
    off = fmax(off, fabs(eB[k] - eB_data[k]));
  }
  CHECK(off > 0.01 * sqrt(dwr_dot(3, eB_data, eB_data)),
        "front B: e = (%g, %g, %g) is its data term alone", eB[0], eB[1], eB[2]);
  if (getenv("NH_VERBOSE"))
    printf("e_A = (%.6e, %.6e, %.6e), e_B = (%.6e, %.6e, %.6e)\n", eA[0], eA[1], eA[2], eB[0],
           eB[1], eB[2]);

  for (int combined = 0; combined < 2; combined++) { /* parts 1 and 2 */
    const int ne = combined ? 1 : 6, ni = combined ? 1 : 2;
    double E0[6], E1[6], *ind0 = calloc((size_t)(2 * nc), sizeof(double));
    double *ind1 = calloc((size_t)(2 * nc), sizeof(double)), err[6];
    int row[2] = {0, 4};
    nh_dwr_fronts fronts = {2, row, err, 0, NULL, NULL};
    nh_dwr_result r0, r1;
    estimate(s, &rows, m, t, h, u, &data, combined, NULL, E0, ind0, &r0);
    estimate(s, &rows, m, t, h, u, &data, combined, &fronts, E1, ind1, &r1);
    const char *what = combined ? "combined" : "separate";
    const double dE = max_rel_diff(ne, E0, E1), dI = max_rel_diff(ni * nc, ind0, ind1);
    const double dA = max_rel_diff(3, eA, err), dB = max_rel_diff(3, eB, err + 3);
    if (getenv("NH_VERBOSE"))
      printf("%s: relative differences E %.2e, indicators %.2e, e_A %.2e, e_B %.2e\n", what, dE, dI,
             dA, dB);
    CHECK(dE <= ROUNDOFF, "%s: the goals' estimates changed with fronts (%.3g)", what, dE);
    CHECK(dI <= ROUNDOFF, "%s: the goals' indicators changed with fronts (%.3g)", what, dI);
    CHECK(fabs(r0.eta - r1.eta) <= ROUNDOFF * fabs(r0.eta) &&
              fabs(r0.eta_rel - r1.eta_rel) <= ROUNDOFF * fabs(r0.eta_rel),
          "%s: eta %.17g / %.17g, eta_rel %.17g / %.17g", what, r0.eta, r1.eta, r0.eta_rel,
          r1.eta_rel);
    CHECK(r0.n_rows == r1.n_rows && r0.n_rows == 6, "%s: %d and %d rows in the goals' duals, not 6",
          what, r0.n_rows, r1.n_rows);
    CHECK(dA <= ROUNDOFF, "%s: front A's e (%.17g, %.17g, %.17g) is not its own", what, err[0],
          err[1], err[2]);
    CHECK(dB <= ROUNDOFF, "%s: front B's e (%.17g, %.17g, %.17g) is not its own", what, err[3],
          err[4], err[5]);
    free(ind0), free(ind1);
  }

  /* part 3: row 3 sliding leaves front B's dual as it was, not the goals' */
  double E0[6], E1[6], eB1[3];
  nh_dwr_result r;
  estimate(s, &rows, m, t, h, u, &data, 0, NULL, E0, NULL, &r);
  rows.law[3].sliding = 1;
  estimate(s, &rows, m, t, h, u, &data, 0, NULL, E1, NULL, &r);
  CHECK_OK(nh_dwr_front_error(s, &rows, 1.0, m, t, h, u, 4, NULL, &data, eB1));
  CHECK(!memcmp(eB, eB1, sizeof eB), "front B's e depends on friction row 3's state");
  CHECK(memcmp(E0, E1, sizeof E0), "the goals' estimates do not see friction row 3");

  /* part 5: shaft points, one dual each with every friction row free: with
   * front A's axial row 2 sliding too, a point at front B's rows and one at
   * front A's have the errors of those fronts along their axial rows,
   * t · e, to round-off, estimated in the pass of the goals and the
   * fronts, and the goals' estimates and the fronts' e do not change */
  rows.law[2].sliding = 1;
  double eA2[3], E2[6], E3[6], ferr[6], perr[2];
  CHECK_OK(nh_dwr_front_error(s, &rows, 1.0, m, t, h, u, 0, NULL, &data, eA2));
  estimate(s, &rows, m, t, h, u, &data, 0, NULL, E2, NULL, &r);
  int frow[2] = {0, 4}, prow[2] = {4, 0};
  nh_dwr_fronts fp = {2, frow, ferr, 2, prow, perr};
  estimate(s, &rows, m, t, h, u, &data, 0, &fp, E3, NULL, &r);
  const double tB = dwr_dot(3, eB1, rows.dir + 3 * 6), tA = dwr_dot(3, eA2, rows.dir + 3 * 2);
  if (getenv("NH_VERBOSE"))
    printf("points: %.17g against t.e_B %.17g, %.17g against t.e_A %.17g\n", perr[0], tB, perr[1],
           tA);
  CHECK(max_rel_diff(6, E2, E3) <= ROUNDOFF, "the goals' estimates changed with shaft points");
  CHECK(max_rel_diff(3, eA2, ferr) <= ROUNDOFF && max_rel_diff(3, eB1, ferr + 3) <= ROUNDOFF,
        "the fronts' e changed with shaft points");
  CHECK(fabs(perr[0] - tB) <= ROUNDOFF * sqrt(dwr_dot(3, eB1, eB1)),
        "the point at front B's rows: %.17g, not t . e_B = %.17g", perr[0], tB);
  CHECK(fabs(perr[1] - tA) <= ROUNDOFF * sqrt(dwr_dot(3, eA2, eA2)),
        "the point at front A's rows: %.17g, not t . e_A = %.17g", perr[1], tA);
  CHECK(fabs(tA + change[2]) > 0.01 * fabs(change[2]),
        "front A's axial error %.3g is its data term alone with its axial row sliding", tA);

  /* part 6: a sticking point's error is its axial row's data from the step
   * that estimates it: the goals' estimates with the point equal those
   * without it and with δc_2 − e_p as row 2's data, to round-off */
  rows.law[2].sliding = 0;
  int p0 = 0;
  double E4[6], E5[6], e0;
  nh_dwr_fronts fq = {0, NULL, NULL, 1, &p0, &e0};
  estimate(s, &rows, m, t, h, u, &data, 0, &fq, E4, NULL, &r);
  const double c2 = change[2];
  change[2] = c2 - e0;
  estimate(s, &rows, m, t, h, u, &data, 0, NULL, E5, NULL, &r);
  change[2] = c2;
  estimate(s, &rows, m, t, h, u, &data, 0, NULL, E2, NULL, &r);
  if (getenv("NH_VERBOSE"))
    printf("sticking point: e_p %.6e; goals' estimates with it / with its data / without: %.6e "
           "%.6e %.6e\n",
           e0, E4[0], E5[0], E2[0]);
  CHECK(max_rel_diff(6, E5, E4) <= ROUNDOFF,
        "the sticking point's same-step term is not its data term (%.3g)", max_rel_diff(6, E5, E4));
  CHECK(max_rel_diff(6, E2, E4) > 1e-6, "the sticking point's error changes no goal estimate");

  nh_rows_free(&rows);
  nh_system_destroy(&s);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  free(fixed), free(u);
  return nh_test_failures ? 1 : 0;
}
