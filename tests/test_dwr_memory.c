/* test_dwr_memory.c — the memory term's links (adapt/dwr_memory.c) against
 * the identity they satisfy, checked with products of their own (the
 * element stiffness summed leaf by leaf, the lumped mass).
 *
 * The links' right-hand sides obey r_{m+1} = (1 + hα + 1) M z_m − M z_{m−1}
 * (β = 0; dwr_memory.c: α_{m+1} = (1 + hα) M z_m − β_m, β_{m+1} = M z_m),
 * with A z_m = r_m, A = (1 + hα) M + h² K, r_0 = h² j. Summing over
 * m = 0 … L, the partial sum P_L = Σ z_m satisfies
 *     h² K P_L = h² j + M (z_{L−1} − (1 + hα) z_L),
 * so that P_L tends to the static dual K⁻¹ j as the links decay: the memory
 * of a steady residual is the quasi-static estimate (docs/theory.md §6.6,
 * "Memory"). With rows held (A z + Jᵀμ = r, J z = 0) and Z the static
 * held dual (K Z + Jᵀν = j, J Z = 0), D = P_L − Z has J D = 0 and
 *     h² Dᵀ K D = Dᵀ M (z_{L−1} − (1 + hα) z_L).
 *  1. no rows: the first identity on every free DOF, to round-off relative
 *     to h² |j|, and P_L within 2 % of K⁻¹ j in energy (the links stop at
 *     1 % of the goal dual's energy norm, two in a row);
 *  2. three bilateral rows at a point: the energy identity to round-off;
 *     and the links' solver (nh_rows_solver: W formed once) against
 *     nh_system_solve_rows for one right-hand side, solution and
 *     multipliers to round-off.
 * A deliberate defect (the factor 1 + hα taken as 1 in dwr_memory.c) fails
 * part 1 by orders of magnitude. NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "adapt/adapt_impl.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "dwr_support.h"

#define H      0.01 /* s */
#define ALPHA  4.0  /* 1/s */
#define RADIUS 5e-4

static const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
static const int grid[3] = {4, 2, 2};
static const double point[3] = {0.015, 0.010, 0.010};

/* y = K v (full nodal vectors), element by element at rest */
static void stiffness_apply(const nh_mesh *m, const nh_tissue *t, const double *v, double *y) {
  double *zero = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  memset(y, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], K[576], ve[24];
    nh_tissue_element(t, c, zero, fe, K);
    nh_mesh_cell_coords(m, v, c, ve);
    for (int a = 0; a < 8; a++)
      for (int i = 0; i < 3; i++) {
        double s = 0.0;
        for (int q = 0; q < 24; q++) s += K[24 * (3 * a + i) + q] * ve[q];
        y[3 * m->cells[8 * c + a] + i] += s;
      }
  }
  free(zero);
}

/* The links of the goal functional j (component 1) on the dynamic system sd
 * with rows (may be NULL): z_0 (nh_dwr_duals) and links 1 … L into *z
 * (L + 1 fields, allocated); returns L. */
static int links(nh_system *sd, const nh_rows *rows, const nh_mesh *m, const nh_tissue *t,
                 const double *j, double **z) {
  const size_t n3 = 3 * (size_t)m->n_nodes;
  const nh_dwr_memory mem = {
      .h = H, .alpha = ALPHA, .beta = 0.0, .mass = t->mass, .max_links = 200};
  int L = 0;
  double *zl = NULL, *mul = NULL;
  CHECK_OK(nh_dwr_memory_duals(sd, rows, H * H, m->n_nodes, 1, j, &mem, &L, &zl, &mul));
  CHECK(L >= 2 && L < 200, "%d links", L);
  *z = calloc(n3 * (size_t)(L + 1), sizeof(double));
  CHECK_OK(nh_dwr_duals(sd, rows, H * H, m->n_nodes, 1, j, *z, NULL, NULL));
  memcpy(*z + n3, zl, sizeof(double) * n3 * (size_t)L);
  free(zl), free(mul);
  return L;
}

int main(void) {
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  unsigned char *fixed = NULL;
  nh_hanging *h = NULL;
  nh_system *ss = NULL, *sd = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {1.0e4, 0.3, 1000, NH_FORMULATION_BBAR};
  CHECK_OK(dwr_block_system(m, &mat, &t, &fixed, &h, &ss)); /* K, factorised */
  const int nn = m->n_nodes;
  const size_t n3 = 3 * (size_t)nn;
  double *zero = calloc(n3, sizeof(double)), *fint = calloc(n3, sizeof(double));
  CHECK_OK(nh_system_create(t, fixed, h, &sd)); /* A = (1 + hα) M + h² K */
  nh_system_assemble(sd, zero, NULL, 1.0 + H * ALPHA, H * H, fint, NULL, 0);
  CHECK_OK(nh_system_factor(sd));
  double *j = calloc(n3, sizeof(double)), *jx = calloc(n3, sizeof(double));
  CHECK_OK(nh_goal_functional(m, point, RADIUS, 0, NULL, jx));
  for (size_t v = 0; v < n3; v += 3) j[v + 1] = jx[v]; /* J(v) = mean v_y over the box */
  const double cm = 1.0 + H * ALPHA;
  double *P = calloc(n3, sizeof(double)), *KP = calloc(n3, sizeof(double));
  double *Z = calloc(n3, sizeof(double)), *D = calloc(n3, sizeof(double));
  double *KD = calloc(n3, sizeof(double)), *w = calloc(n3, sizeof(double));

  /* part 1: no rows */
  double *z = NULL;
  int L = links(sd, NULL, m, t, j, &z);
  for (int k = 0; k <= L; k++)
    for (size_t i = 0; i < n3; i++) P[i] += z[n3 * k + i];
  stiffness_apply(m, t, P, KP);
  double worst = 0.0, jmax = 0.0;
  for (size_t i = 0; i < n3; i++) {
    if (fixed[i / 3]) continue;
    const double mz = t->mass[i / 3] * (z[n3 * (L - 1) + i] - cm * z[n3 * L + i]);
    worst = fmax(worst, fabs(H * H * KP[i] - H * H * j[i] - mz));
    jmax = fmax(jmax, H * H * fabs(j[i]));
  }
  CHECK_OK(nh_dwr_duals(ss, NULL, 1.0, nn, 1, j, Z, NULL, NULL)); /* K Z = j */
  for (size_t i = 0; i < n3; i++) D[i] = P[i] - Z[i];
  const double rel = sqrt(dwr_energy_product(m, t, D, D) / dwr_energy_product(m, t, Z, Z));
  if (getenv("NH_VERBOSE"))
    printf("no rows: %d links, identity residual %.3e of h^2 |j| %.3e; |P - Z|_K / |Z|_K = %.3e\n",
           L, worst, jmax, rel);
  CHECK(worst <= 1e-10 * jmax, "h^2 K P_L - h^2 j - M (z_L-1 - (1 + h alpha) z_L): %.3g of %.3g",
        worst, jmax);
  CHECK(rel < 0.02, "the links' sum is %.3g from the static dual in energy", rel);
  free(z);

  /* part 2: three bilateral rows at a point, held */
  nh_rows rows = {0};
  static const double X[3] = {0.025, 0.012, 0.009};
  for (int r = 0; r < 3; r++) {
    int i = nh_rows_add(&rows), c;
    double xi[3], N[8];
    CHECK_OK(nh_mesh_locate(m, X, &c, xi));
    nh_hex_shape(xi, N);
    for (int a = 0; a < 8; a++)
      rows.node[8 * i + a] = m->cells[8 * c + a], rows.N[8 * i + a] = N[a];
    for (int k = 0; k < 3; k++) rows.dir[3 * i + k] = k == r;
    rows.tool[i] = -1;
    rows.law[i].kind = NH_ROW_BILATERAL;
    rows.lambda[i] = 1e-8;
  }
  L = links(sd, &rows, m, t, j, &z);
  memset(P, 0, sizeof(double) * n3);
  for (int k = 0; k <= L; k++)
    for (size_t i = 0; i < n3; i++) P[i] += z[n3 * k + i];
  CHECK_OK(nh_dwr_duals(ss, &rows, 1.0, nn, 1, j, Z, NULL, NULL)); /* K Z + Jᵀν = j, J Z = 0 */
  for (size_t i = 0; i < n3; i++) {
    D[i] = P[i] - Z[i];
    w[i] = t->mass[i / 3] * (z[n3 * (L - 1) + i] - cm * z[n3 * L + i]);
  }
  stiffness_apply(m, t, D, KD);
  const double lhs = H * H * dwr_dot((int)n3, D, KD), rhs = dwr_dot((int)n3, D, w);
  const double scale = H * H * dwr_dot((int)n3, Z, j);
  if (getenv("NH_VERBOSE"))
    printf(
        "rows: %d links, h^2 D'KD = %.6e, D'M(z_L-1 - (1 + h alpha) z_L) = %.6e (h^2 Z'j %.3e)\n",
        L, lhs, rhs, scale);
  CHECK(fabs(lhs - rhs) <= 1e-10 * scale, "held rows: %.17g against %.17g", lhs, rhs);
  CHECK(lhs > 1e-6 * scale, "held rows: the links' sum equals the static dual (%.3g)", lhs);
  free(z);
  { /* the prepared solver against nh_system_solve_rows */
    const int nf = nh_system_free_dofs(sd);
    double *b = calloc((size_t)nf, sizeof(double)), *x1 = calloc((size_t)nf, sizeof(double));
    double *x2 = calloc((size_t)nf, sizeof(double)), mu1[3], mu2[3];
    nh_system_gather(sd, j, b);
    nh_rows_solver *rs = NULL;
    CHECK_OK(nh_rows_solver_create(sd, &rows, NULL, &rs));
    CHECK_OK(nh_rows_solver_solve(sd, rs, 1, b, x1, mu1));
    CHECK_OK(nh_system_solve_rows(sd, &rows, NULL, 1, b, x2, mu2, NULL));
    double dx = 0.0, xm = 0.0, dm = 0.0, mm = 0.0;
    for (int i = 0; i < nf; i++) dx = fmax(dx, fabs(x1[i] - x2[i])), xm = fmax(xm, fabs(x2[i]));
    for (int i = 0; i < 3; i++) dm = fmax(dm, fabs(mu1[i] - mu2[i])), mm = fmax(mm, fabs(mu2[i]));
    if (getenv("NH_VERBOSE"))
      printf("rows solver: |dx| %.3e of %.3e, |dmu| %.3e of %.3e\n", dx, xm, dm, mm);
    CHECK(dx <= 1e-12 * xm && dm <= 1e-12 * mm && mm > 0.0, "rows solver: dx %.3g, dmu %.3g", dx,
          dm);
    nh_rows_solver_destroy(sd, &rs);
    free(b), free(x1), free(x2);
  }

  nh_rows_free(&rows);
  free(zero), free(fint), free(j), free(jx), free(P), free(KP), free(Z), free(D), free(KD), free(w);
  nh_system_destroy(&sd);
  nh_system_destroy(&ss);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  free(fixed);
  TEST_END();
}
