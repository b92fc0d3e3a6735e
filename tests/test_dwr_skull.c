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
 * NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "adapt/adapt.h"
#include "contact/contact.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

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

static result run(int depth) {
  result out = {0};
  nh_domain d;
  nh_domain_sphere(centre, R, &d);
  d.cut_cells = NH_CUT_CELLS_INTEGRATED;
  const int grid[3] = {6, 6, 6};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  nh_material mat = {60e3, 0.45, 1000, NH_FORMULATION_BBAR};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
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

int main(void) {
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
