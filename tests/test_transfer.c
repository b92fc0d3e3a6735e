/* test_transfer — refinement and state transfer keep a deformed equilibrium.
 *
 * The phantom block (8x4x4, clamped at x = 0.04, pushed on a small region)
 * is solved statically; the cells SPR marks (θ = 0.3) are refined with
 * hex2 and u is carried to the new nodes by Eq. 17.
 *  1. The field does not change: inside every refined parent, the child
 *     trilinear interpolation of corner values sampled from the parent's
 *     trilinear field is that field (box cells), so at probes spread over
 *     the block the displacement is the same before and after, to 1e-12.
 *  2. No spurious jump afterwards: continuing with damped backward-Euler
 *     steps under the same load, the probes move from the coarse to the
 *     refined equilibrium without overshooting the difference between the
 *     two by more than 5 % — a transfer that broke equilibrium (e.g.
 *     forgetting the hanging constraints or mis-placing nodes) kicks the
 *     block by far more than the discretisation change.
 *  3. The refined run converges to the refined static equilibrium (1e-6). */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "hanging_mesh.h"

#define NP 5
static const double probes[NP][3] = {{0.0025, 0.01, 0.01},
                                     {0.006, 0.009, 0.011},
                                     {0.013, 0.0125, 0.004},
                                     {0.02, 0.01, 0.01},
                                     {0.031, 0.017, 0.002}};

static void probe_values(const nh_mesh *m, const double *u, double out[NP][3]) {
  for (int p = 0; p < NP; p++) {
    int c;
    double xi[3], N[8];
    CHECK_OK(nh_mesh_locate(m, probes[p], &c, xi));
    nh_hex_shape(xi, N);
    for (int k = 0; k < 3; k++) {
      out[p][k] = 0.0;
      for (int a = 0; a < 8; a++) out[p][k] += N[a] * u[3 * m->cells[8 * c + a] + k];
    }
  }
}

static nh_system *make_system(nh_mesh *m, nh_tissue *t, unsigned char **fixed, nh_hanging **h,
                              double **f) {
  *fixed = realloc(*fixed, m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) (*fixed)[i] = m->X[3 * i] > 0.0399;
  nh_hanging_destroy(h);
  CHECK_OK(nh_hanging_detect(m, *fixed, h));
  nh_system *s;
  CHECK_OK(nh_system_create(t, *fixed, *h, &s));
  *f = realloc(*f, sizeof(double) * 3 * m->n_nodes);
  memset(*f, 0, sizeof(double) * 3 * m->n_nodes);
  nh_region load = {.min = {0, 0.0075, 0.0075}, .max = {0.005, 0.0125, 0.0125}};
  double force[3] = {1.0, 0.3, -0.2};
  CHECK_OK(nh_mesh_region_load(m, &load, force, *f));
  return s;
}

int main(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {8, 4, 4};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {1e7, 0.4, 1000, NH_FORMULATION_BBAR};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  unsigned char *fixed = NULL;
  nh_hanging *h = NULL;
  double *f = NULL;
  nh_system *s = make_system(m, t, &fixed, &h, &f);
  double *u = calloc(3 * m->n_nodes, sizeof(double));
  nh_integrator in = {.dt = 0.01,
                      .alpha = 1.0,
                      .beta = 1e-4,
                      .tolerance = 1e-11,
                      .max_iterations = 50,
                      .threads = 1};
  CHECK_OK(nh_solve_static(s, &in, f, u, NULL));
  double before[NP][3], after[NP][3];
  probe_values(m, u, before);

  double *eta = malloc(sizeof(double) * m->n_cells), eg, er;
  CHECK_OK(nh_spr_estimate(m, t, u, h, eta, &eg, &er));
  int *marked = malloc(sizeof(int) * m->n_leaves), n_marked;
  nh_mark_params mp = {.strategy = NH_MARK_MAX, .theta = 0.3, .max_level = 3};
  CHECK_OK(nh_mark_cells(m, eta, &mp, marked, &n_marked));
  CHECK(n_marked > 0 && n_marked < m->n_leaves, "marked %d of %d cells", n_marked, m->n_leaves);
  nh_template *tmpl = regular_template(2);
  nh_refine_info info = {0};
  int old = m->n_nodes;
  CHECK_OK(nh_mesh_refine(m, tmpl, marked, n_marked, &info));
  u = realloc(u, sizeof(double) * 3 * m->n_nodes);
  for (int k = 0; k < info.n_new; k++) { /* Eq. 17 */
    double N[8];
    nh_hex_shape(info.xi + 3 * k, N);
    for (int i = 0; i < 3; i++) {
      double v = 0.0;
      for (int a = 0; a < 8; a++) v += N[a] * u[3 * m->cells[8 * info.parent[k] + a] + i];
      u[3 * (old + k) + i] = v;
    }
  }
  nh_system_destroy(&s);
  CHECK_OK(nh_tissue_update(t));
  s = make_system(m, t, &fixed, &h, &f);
  CHECK(h->n_hanging > 0, "refinement made no hanging node");
  probe_values(m, u, after);
  double umax = 0.0;
  for (int p = 0; p < NP; p++)
    for (int k = 0; k < 3; k++) umax = fmax(umax, fabs(before[p][k]));
  for (int p = 0; p < NP; p++)
    for (int k = 0; k < 3; k++)
      CHECK_CLOSE(after[p][k], before[p][k], 1e-12 * umax,
                  "probe displacement across the transfer");

  /* The refined static equilibrium, for reference. */
  double *ufine = malloc(sizeof(double) * 3 * m->n_nodes);
  memcpy(ufine, u, sizeof(double) * 3 * m->n_nodes);
  CHECK_OK(nh_solve_static(s, &in, f, ufine, NULL));
  double fine[NP][3];
  probe_values(m, ufine, fine);
  double change = 0.0;
  for (int p = 0; p < NP; p++)
    for (int k = 0; k < 3; k++) change = fmax(change, fabs(fine[p][k] - before[p][k]));
  CHECK(change > 1e-4 * umax, "refinement changed nothing (%g): the test would be vacuous", change);

  /* Damped dynamics from the transferred state. */
  double *v = calloc(3 * m->n_nodes, sizeof(double));
  double worst = 0.0;
  for (int step = 0; step < 200; step++) {
    CHECK_OK(nh_step_dynamic(s, &in, f, u, v, NULL));
    double now[NP][3];
    probe_values(m, u, now);
    for (int p = 0; p < NP; p++)
      for (int k = 0; k < 3; k++) {
        double lo_ = fmin(before[p][k], fine[p][k]), hi_ = fmax(before[p][k], fine[p][k]);
        double out = fmax(lo_ - now[p][k], now[p][k] - hi_);
        worst = fmax(worst, out);
      }
  }
  CHECK(worst <= 0.05 * change, "probes left the band between the two equilibria by %g (change %g)",
        worst, change);
  double last[NP][3];
  probe_values(m, u, last);
  for (int p = 0; p < NP; p++)
    for (int k = 0; k < 3; k++)
      CHECK_CLOSE(last[p][k], fine[p][k], 1e-6 * umax,
                  "dynamic run reaches the refined equilibrium");
  if (getenv("NH_VERBOSE"))
    printf("marked %d cells, %d hanging nodes, max change %.3e m (of %.3e), worst excursion %.3e\n",
           n_marked, h->n_hanging, change, umax, worst);
  nh_refine_info_free(&info);
  free(u), free(v), free(ufine), free(eta), free(marked), free(fixed), free(f);
  nh_template_destroy(&tmpl);
  nh_system_destroy(&s);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  TEST_END();
}
