/* test_dwr_skull — the goal estimate's constraint-data term (adapt/dwr.c,
 * "Constraint data"; docs/theory.md §6.6) for skull contact: does it
 * predict how the goal moves when the skull's points are sampled one
 * lattice finer? Computed by running both.
 *
 * The problem is test_skull's: a sphere of tissue (R = 5 cm, E = 60 kPa,
 * ν = 0.45 B-bar, ρ = 1000 kg/m³, mass damping 20 /s) under gravity (−z)
 * in a spherical cavity of the same radius (gap 0); here off the grid's
 * centre (c = (3, −2, 1) mm) on 6³ cells over its bounding box, cut cells
 * integrated, and the nodes above the plane 0.8 R over the centre held (a
 * sphere in a concentric cavity may turn freely without friction: its
 * rotation would be decided by round-off). 30 backward Euler steps of
 * 0.2 s to rest (the sag's mode, ω ≈ 280 /s, is damped by |1 + iωh| ≈ 56
 * per step). The goal J: the mean u over the box of half-width 5 mm around
 * a point 3.5 cm below the centre, where the skull pushes.
 *
 * Run 1: skull points from the surface quadrature at NH_CUT_DEPTH (u_2);
 * its goal estimate with the constraint-data term C (nh_skull_data_change:
 * the points of depth NH_CUT_DEPTH + 1, the rows' forces Λ = λ/h and the
 * dual's multipliers μ of the step's factor and rows, c_K = h²).
 * Run 2: the same with the points at depth NH_CUT_DEPTH + 1 (u_3).
 * Expected: C ≈ J(u_3) − J(u_2), C being the first-order change of J under
 * the change of the rows' data (exact for a linear problem with the finer
 * rows' own multipliers: tests/test_dwr_rows.c, part 3); here its
 * approximations are the coarse multipliers split over the finer points by
 * area, the same active set and the linearisation, all small for a change
 * of the points by a fraction of a sub-box. Asserted: the vectors C and
 * ΔJ within 11.5° (cos ≥ 0.98) and |C| / |ΔJ| in [0.8, 1.25]; ΔJ resolved
 * (≥ 1e-4 of |J|, the steps converged to 1e-8). Measured: 0.998, cos
 * 1.0000; the μ part alone gave 0.46, so the test fails without the Λ
 * part. Also: C = 0 to the last bit when the data do not change (the finer
 * data taken at the points' own depth: nh_skull_set_depth to one level
 * coarser, so that "one finer" is the points themselves).
 *
 * Part 2 (test_identity): the constrained DWR identity with the skull's
 * own rows, of both kinds (point rows and weighted-gap rows), on a small
 * linear static problem: the sphere above on 4³ cells (V_h) and on every
 * cell refined once (V_f, 8³), the nodes on and above the grid plane
 * z = c_z + R/2 held (a plane of both grids: P u_h is 0 on V_f's held
 * nodes), gravity tilted off −z by 20° (no goal component vanishes by
 * symmetry), the skull at gap 0. On each mesh its rows are
 * nh_skull_rows at rest (u = v = 0: every point may touch), V_f's from its
 * own finer surface sampling (nh_skull_relocate), and the contact problem
 * is solved by a dense LU of [K Jᵀ; J 0] on an active set iterated to
 * consistency (pressing rows kept, open rows dropped, penetrating rows
 * added: an independent path to u_h, u_f). With z_f, μ_f the fine
 * constrained dual of nh_dwr_duals (CHOLMOD factor, W = J A⁻¹ Jᵀ, the
 * active rows as the step's forces tell it), A z_f + J_fᵀμ_f = j,
 * J_f z_f = 0 on the active rows, and u_f's own K u_f + J_fᵀλ_f = f,
 * J_f u_f = −g_f:
 *   J(u_f) − J(P u_h) = f(z_f) − a(P u_h, z_f) − μ_fᵀ c_f(P u_h),
 *   c_f(v) = J_f v + g_f,
 * the residual of P u_h in V_f's equations (equilibrium and the fine
 * rows) weighted by the fine dual: an identity, asserted to 1e-9 relative
 * per component, with the rows' part above 1 % of the change (else the
 * rows would not be tested) and the tissue-alone dual missing by more
 * than 1 %. J(P u_h) = J(u_h) to 1e-12: the goal's box lies inside the
 * tissue, where both meshes integrate it exactly. Measured: 23 of 48
 * point rows active on V_h, 114 of 224 on V_f (weighted-gap rows: 55 of
 * 144, 139 of 508); the identity to 7e-15 … 1.2e-11 of the change; the
 * rows' part 0.19 … 93 times it; the tissue-alone dual off by 51 … 5600
 * times it.
 * NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "adapt/adapt.h"
#include "contact/contact.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "dwr_support.h"
#include "hanging_mesh.h"
#include "immersed.h"

#define STEPS 30

static const double R = 0.05, centre[3] = {0.003, -0.002, 0.001}, H = 0.2;

typedef struct {
  double J[3], E[3], C[3], C_same[3];
  int rows;
} result;

typedef struct {
  nh_skull *skull;
  const nh_mesh *m;
  const double *u;
  int rows;
} skull_ctx;

static int linear(void *ctx, int n, const double *w, double *out) {
  const skull_ctx *c = ctx;
  memset(out, 0, sizeof(double) * (size_t)c->rows * (size_t)n);
  return nh_skull_data_change(c->skull, c->m, c->u, n, w, c->rows, NULL, out);
}

/* The sphere of the header, integrated cut cells, on g³ cells over its
 * bounding box, with its tissue (E 60 kPa, ν 0.45, ρ 1000, B-bar). */
static void sphere_on_grid(int g, nh_domain *d, nh_mesh **m, nh_tissue **t) {
  immersed_ball(centre, R, g, 60e3, d, m, t);
}

static result run(int depth) {
  result out = {0};
  nh_domain d;
  nh_mesh *m;
  nh_tissue *t;
  sphere_on_grid(6, &d, &m, &t);
  /* the nodes above the plane 0.8 R over the centre held: no rigid motion
   * (a sphere in a concentric cavity may turn freely without friction) */
  unsigned char *fixed = calloc(m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) fixed[i] = m->X[3 * i + 2] > centre[2] + 0.8 * R;
  nh_system *sys;
  CHECK_OK(nh_system_create(t, fixed, NULL, &sys));
  nh_skull *sk;
  CHECK_OK(nh_skull_create(&d, 0.0, &sk));
  CHECK_OK(nh_skull_set_depth(sk, depth));
  CHECK_OK(nh_skull_build(sk, m));
  const int nd = 3 * m->n_nodes;
  double *u = calloc(nd, sizeof(double)), *v = calloc(nd, sizeof(double));
  double *f = calloc(nd, sizeof(double));
  for (int i = 0; i < m->n_nodes; i++) f[3 * i + 2] = -t->mass[i] * 9.81;
  nh_integrator in = {
      .dt = H, .alpha = 20.0, .tolerance = 1e-8, .max_iterations = 30, .threads = 0};
  nh_rows rows = {0};
  for (int step = 0; step < STEPS; step++) {
    nh_rows_clear(&rows);
    CHECK_OK(nh_skull_rows(sk, m, u, v, H, &rows));
    nh_coupled_stats st;
    CHECK_OK(nh_step_coupled(sys, &in, f, u, v, 0, NULL, &rows, 1e-10, 1e-6, 5000, &st));
    nh_skull_end_step(sk, &rows, H);
  }
  const double goal[3] = {centre[0], centre[1], centre[2] - 0.035}, radius = 0.005;
  double *j = calloc(nd, sizeof(double));
  for (int k = 0; k < 3; k++) {
    CHECK_OK(nh_goal_functional(m, goal, radius, k, "goal", j));
    for (int i = 0; i < nd; i++) out.J[k] += j[i] * u[i];
  }
  double *dc = calloc(2 * (size_t)(rows.m ? rows.m : 1), sizeof(double)), norm;
  for (int i = 0; i < rows.m; i++) dc[rows.m + i] = rows.lambda[i] / H; /* the rows' forces */
  CHECK_OK(nh_skull_data_change(sk, m, u, 0, NULL, rows.m, dc, NULL));
  skull_ctx ctx = {sk, m, u, rows.m};
  nh_constraint_data data = {.change = dc, .force = dc + rows.m, .linear = linear, .ctx = &ctx};
  nh_dwr_result r = {.estimate = out.E, .norm = &norm, .data = &data, .constraint = out.C};
  CHECK_OK(nh_dwr_estimate(sys, &rows, H * H, m, t, NULL, u, 1, goal, radius, NULL, &r));
  out.rows = r.n_rows;
  /* the same points as "finer" data: the skull one level coarser, whose
   * finer level is the lattice the points were built on */
  CHECK_OK(nh_skull_set_depth(sk, depth - 1));
  memset(dc, 0, sizeof(double) * (size_t)rows.m);
  CHECK_OK(nh_skull_data_change(sk, m, u, 0, NULL, rows.m, dc, NULL));
  double E2[3];
  r.estimate = E2, r.constraint = out.C_same;
  CHECK_OK(nh_dwr_estimate(sys, &rows, H * H, m, t, NULL, u, 1, goal, radius, NULL, &r));
  nh_rows_free(&rows);
  free(u), free(v), free(f), free(j), free(dc), free(fixed);
  nh_skull_destroy(&sk);
  nh_system_destroy(&sys);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  return out;
}

/* part 2's gravity, tilted: no goal component vanishes by symmetry */
static const double gravity[3] = {2.94, -1.96, -9.16};

/* The contact problem on mesh m by dense LU solves on an active set
 * iterated to consistency from the free solution: a row becomes active
 * when the solution penetrates it (c(u) = J u + g < −1e-15 m) and stays
 * so while it presses (KKT multiplier λ < 0: force −λ > 0 along its inward
 * normal). rows->lambda gets
 * the forces −λ (0 on open rows), as a step leaves them. Returns the
 * number of active rows. */
static int contact_solve(const nh_mesh *m, const nh_tissue *t, const unsigned char *fixed,
                         const double *f, nh_rows *rows, double *u) {
  unsigned char *active = malloc((size_t)rows->m);
  double *lambda = malloc(sizeof(double) * (size_t)rows->m);
  memset(active, 0, (size_t)rows->m); /* from the free solution */
  int changed = 1, iter = 0, n_active = 0;
  for (; changed && iter < 50; iter++) {
    CHECK(dwr_dense_solve(m, t, fixed, f, rows, active, u, lambda) == 0, "dense KKT solve");
    changed = 0, n_active = 0;
    for (int i = 0; i < rows->m; i++) {
      const int now =
          active[i] ? lambda[i] < 0.0 : dwr_row_value(rows, i, u) + rows->gap[i] < -1e-15;
      changed |= now != active[i];
      active[i] = (unsigned char)now;
      n_active += now;
    }
  }
  CHECK(!changed, "the active set did not settle in %d iterations", iter);
  for (int i = 0; i < rows->m; i++) {
    CHECK(rows->law[i].kind == NH_ROW_UNILATERAL, "skull row %d is not unilateral", i);
    rows->lambda[i] = active[i] ? -lambda[i] : 0.0;
  }
  free(active), free(lambda);
  return n_active;
}

/* System (rest stiffness, factorised), skull rows at rest and load of the
 * sphere problem of part 2 on mesh m. */
static void identity_setup(nh_mesh *m, nh_skull *sk, nh_tissue *t, unsigned char **fixed,
                           nh_system **s, nh_rows *rows, double **f) {
  const int nd = 3 * m->n_nodes;
  *fixed = calloc(m->n_nodes, 1);
  for (int i = 0; i < m->n_nodes; i++) (*fixed)[i] = m->X[3 * i + 2] > centre[2] + 0.5 * R - 1e-9;
  CHECK_OK(nh_system_create(t, *fixed, NULL, s));
  double *zero = calloc(nd, sizeof(double));
  nh_system_assemble(*s, zero, NULL, 0.0, 1.0, zero, NULL, 0);
  CHECK_OK(nh_system_factor(*s));
  *f = calloc(nd, sizeof(double));
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) (*f)[3 * i + k] = t->mass[i] * gravity[k];
  nh_rows_clear(rows);
  CHECK_OK(nh_skull_rows(sk, m, zero, zero, 1.0, rows));
  CHECK(rows->m > 0, "no skull rows");
  free(zero);
}

static void test_identity(nh_skull_rows_kind kind) {
  const char *name = kind == NH_SKULL_ROWS_MORTAR ? "weighted-gap rows" : "point rows";
  nh_domain d;
  nh_mesh *m;
  nh_tissue *t;
  sphere_on_grid(4, &d, &m, &t);
  nh_skull *sk;
  CHECK_OK(nh_skull_create(&d, 0.0, &sk));
  nh_skull_set_rows(sk, kind);
  CHECK_OK(nh_skull_build(sk, m));
  nh_system *s = NULL;
  unsigned char *fixed = NULL;
  double *f = NULL;
  nh_rows rows = {0};
  identity_setup(m, sk, t, &fixed, &s, &rows, &f);
  const int nc = m->n_nodes, n = 3 * nc, rows_h = rows.m;
  const double goal[3] = {centre[0], centre[1], centre[2] - 0.035}, radius = 0.005;
  double *uh = malloc(sizeof(double) * n), *j = malloc(sizeof(double) * n), Jh[3] = {0};
  const int active_h = contact_solve(m, t, fixed, f, &rows, uh);
  for (int k = 0; k < 3; k++) {
    CHECK_OK(nh_goal_functional(m, goal, radius, k, "goal", j));
    Jh[k] = dwr_dot(n, j, uh);
  }
  /* V_f: every leaf refined once; the rows of its own finer sampling */
  nh_template *t2 = regular_template(2);
  nh_refine_info info = {0};
  const int nl = m->n_leaves;
  int *all = malloc(sizeof(int) * nl);
  memcpy(all, m->leaves, sizeof(int) * nl);
  CHECK_OK(nh_mesh_refine(m, t2, all, nl, &info));
  double *Puh = dwr_prolong(m, &info, uh, nc);
  nh_system_destroy(&s);
  free(fixed), free(f);
  CHECK_OK(nh_tissue_update(t));
  CHECK_OK(nh_skull_relocate(sk, m));
  identity_setup(m, sk, t, &fixed, &s, &rows, &f);
  const int nf = 3 * m->n_nodes;
  double *uf = malloc(sizeof(double) * nf), *jf = malloc(sizeof(double) * 3 * nf);
  double *z = malloc(sizeof(double) * 3 * nf), *z0 = malloc(sizeof(double) * 3 * nf);
  double *mu = malloc(sizeof(double) * 3 * (size_t)rows.m);
  const int active_f = contact_solve(m, t, fixed, f, &rows, uf);
  for (int k = 0; k < 3; k++)
    CHECK_OK(nh_goal_functional(m, goal, radius, k, "goal", jf + (size_t)nf * k));
  int used = -1;
  CHECK_OK(nh_dwr_duals(s, &rows, 1.0, m->n_nodes, 3, jf, z, mu, &used));
  CHECK(used == active_f, "%s: %d rows in the dual, %d active", name, used, active_f);
  CHECK_OK(nh_dwr_duals(s, NULL, 1.0, m->n_nodes, 3, jf, z0, NULL, NULL));
  for (int k = 0; k < 3; k++) {
    const double *jk = jf + (size_t)nf * k, *zk = z + (size_t)nf * k, *z0k = z0 + (size_t)nf * k;
    double zmax = 0.0, rows_part = 0.0;
    for (int i = 0; i < nf; i++) zmax = fmax(zmax, fabs(zk[i]));
    for (int i = 0; i < rows.m; i++) {
      const double mui = mu[(size_t)rows.m * k + i];
      if (rows.lambda[i] > 0.0)
        CHECK(fabs(dwr_row_value(&rows, i, zk)) <= 1e-10 * zmax,
              "%s: the dual violates active row %d by %.3g", name, i, dwr_row_value(&rows, i, zk));
      else
        CHECK(mui == 0.0, "%s: open row %d has mu %g", name, i, mui);
      rows_part -= mui * (dwr_row_value(&rows, i, Puh) + rows.gap[i]);
    }
    const double Juf = dwr_dot(nf, jk, uf), JPuh = dwr_dot(nf, jk, Puh), lhs = Juf - Jh[k];
    const double tissue = dwr_dot(nf, f, zk) - dwr_energy_product(m, t, Puh, zk);
    const double rhs0 = dwr_dot(nf, f, z0k) - dwr_energy_product(m, t, Puh, z0k);
    CHECK(fabs(JPuh - Jh[k]) <= 1e-12 * fmax(fabs(Juf), fabs(Jh[k])),
          "%s k=%d: J(P u_h) %.9e, J(u_h) %.9e", name, k, JPuh, Jh[k]);
    CHECK(fabs(tissue + rows_part - lhs) <= 1e-9 * fabs(lhs),
          "%s k=%d: J(u_f) - J(u_h) = %.9e, f(z_f) - a(P u_h, z_f) - mu_f c_f(P u_h) = %.9e", name,
          k, lhs, tissue + rows_part);
    CHECK(fabs(rows_part) > 1e-2 * fabs(lhs), "%s k=%d: the rows' part is %.1e of the change", name,
          k, rows_part / lhs);
    CHECK(fabs(rhs0 - lhs) > 1e-2 * fabs(lhs),
          "%s k=%d: the tissue-alone dual misses the identity by only %.1e", name, k,
          fabs(rhs0 - lhs) / fabs(lhs));
    if (getenv("NH_VERBOSE"))
      printf("identity, %s, k=%d: %d of %d rows active on V_h, %d of %d on V_f; J(u_f)-J(u_h) = "
             "%.6e m, tissue part %.6e, rows' part %.6e (rel diff %.1e); tissue-alone dual "
             "%.6e (rel diff %.1e)\n",
             name, k, active_h, rows_h, active_f, rows.m, lhs, tissue, rows_part,
             fabs(tissue + rows_part - lhs) / fabs(lhs), rhs0, fabs(rhs0 - lhs) / fabs(lhs));
  }
  nh_rows_free(&rows);
  nh_refine_info_free(&info);
  nh_template_destroy(&t2);
  free(all), free(uh), free(j), free(Puh), free(uf), free(jf), free(z), free(z0), free(mu);
  free(fixed), free(f);
  nh_skull_destroy(&sk);
  nh_system_destroy(&s);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(void) {
  test_identity(NH_SKULL_ROWS_POINTS);
  test_identity(NH_SKULL_ROWS_MORTAR);
  result a = run(NH_CUT_DEPTH), b = run(NH_CUT_DEPTH + 1);
  double dJ[3], dot = 0.0, nd = 0.0, nc = 0.0, ne = 0.0;
  for (int k = 0; k < 3; k++) {
    dJ[k] = b.J[k] - a.J[k];
    dot += dJ[k] * a.C[k], nd += dJ[k] * dJ[k], nc += a.C[k] * a.C[k], ne += a.E[k] * a.E[k];
    CHECK(a.C_same[k] == 0.0, "k=%d: the term is %g with the data unchanged", k, a.C_same[k]);
  }
  nd = sqrt(nd), nc = sqrt(nc), ne = sqrt(ne);
  const double cosine = nd > 0.0 && nc > 0.0 ? dot / (nd * nc) : 0.0;
  if (getenv("NH_VERBOSE"))
    printf("%d active rows; J(u_3) - J(u_2) = (%.4e, %.4e, %.4e) m, C = (%.4e, %.4e, %.4e) m, "
           "|C|/|dJ| = %.3f, cos = %.4f; |E| = %.4e m, |J| = %.4e m\n",
           a.rows, dJ[0], dJ[1], dJ[2], a.C[0], a.C[1], a.C[2], nc / nd, cosine, ne,
           sqrt(a.J[0] * a.J[0] + a.J[1] * a.J[1] + a.J[2] * a.J[2]));
  CHECK(a.rows > 0, "no active skull rows in the dual");
  double nj = sqrt(a.J[0] * a.J[0] + a.J[1] * a.J[1] + a.J[2] * a.J[2]);
  CHECK(nd >= 1e-4 * nj, "the finer skull points move J by %.3e m, < 1e-4 of |J| = %.3e m", nd, nj);
  CHECK(cosine >= 0.98, "C and J(u_3) - J(u_2) %.1f deg apart", acos(cosine) * 57.29578);
  CHECK(nc >= 0.8 * nd && nc <= 1.25 * nd, "|C| = %.3e m against |J(u_3) - J(u_2)| = %.3e m", nc,
        nd);
  TEST_END();
}
