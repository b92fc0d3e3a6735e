/* test_adapt_step — the refinement driver nh_adapt_step (adapt/refine.c).
 *
 * A 4x2x2 box carries u = (x², y z, x y) / L, whose strain is not constant,
 * so SPR gives non-zero indicators; marking with θ = 0.01 selects many
 * cells. Checked against independent derivations:
 *  1. DOF budget: with hex2 (27 nodes, 19 new per cell when none is
 *     shared) and max_dofs = 3 n + 3·19·2 + 5, exactly 2 cells are refined,
 *     and they are the 2 marked cells of largest ηₑ (ties: smaller id),
 *     found here by a plain selection over the indicators; the node count
 *     stays within the budget.
 *  2. Eq. 17: a field linear in the rest position, w = G X + c, is carried
 *     exactly (trilinear interpolation reproduces linear fields): every new
 *     node holds G X + c to 1e-14 relative; old nodes keep their values
 *     bitwise.
 *  3. Without a budget every marked cell is refined; the indicators are
 *     invalid after a refinement (nh_adapt_indicators returns NULL). */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"

#include <string.h>

static const double G[9] = {0.1, -0.2, 0.3, 0.05, 0.4, -0.1, -0.3, 0.2, 0.15};
static const double C[3] = {1e-3, -2e-3, 5e-4};

static void linear_field(const double X[3], double w[3]) {
  for (int i = 0; i < 3; i++)
    w[i] = G[3 * i] * X[0] + G[3 * i + 1] * X[1] + G[3 * i + 2] * X[2] + C[i];
}

/* Build the box, u and w, estimate, and return the driver ready to step. */
static nh_adapt *setup(const nh_adapt_spec *spec, nh_mesh **m, double **u, double **w) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {4, 2, 2};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, m));
  nh_material mat = {1e6, 0.3, 1000, NH_FORMULATION_BBAR};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(*m, &mat, &t));
  const int n = (*m)->n_nodes;
  *u = malloc(sizeof(double) * 3 * n);
  *w = malloc(sizeof(double) * 3 * n);
  for (int a = 0; a < n; a++) {
    const double *X = (*m)->X + 3 * a, L = 0.04;
    (*u)[3 * a] = X[0] * X[0] / L, (*u)[3 * a + 1] = X[1] * X[2] / L,
             (*u)[3 * a + 2] = X[0] * X[1] / L;
    linear_field(X, *w + 3 * a);
  }
  nh_adapt *a;
  CHECK_OK(nh_adapt_create(spec, 0, &a));
  double eta, eta_rel;
  CHECK_OK(nh_adapt_estimate(a, *m, t, *u, NULL, NULL, &eta, &eta_rel));
  CHECK(eta > 0, "eta = %g, expected > 0 for a non-linear field", eta);
  nh_tissue_destroy(&t);
  return a;
}

int main(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  nh_adapt_spec spec = {
      .enabled = 1, .strategy = NH_MARK_MAX, .theta = 0.01, .max_level = 3, .every = 1};
  snprintf(spec.template_path, sizeof spec.template_path, "%s/templates/hex2.tmpl",
           src ? src : ".");

  /* 1 and 2: budget of two cells. */
  nh_mesh *m;
  double *u, *w;
  spec.max_dofs = 0;
  nh_adapt *a = setup(&spec, &m, &u, &w);
  const int n0 = m->n_nodes;
  spec.max_dofs = 3 * n0 + 3 * 19 * 2 + 5;
  nh_adapt_destroy(&a);
  nh_mesh_destroy(&m);
  free(u), free(w);
  a = setup(&spec, &m, &u, &w);
  double *eta = malloc(sizeof(double) * m->n_cells);
  memcpy(eta, nh_adapt_indicators(a), sizeof(double) * m->n_cells);
  int *marked = malloc(sizeof(int) * m->n_leaves), n_marked;
  nh_mark_params mp = {.strategy = NH_MARK_MAX, .theta = 0.01, .max_level = 3, .child_ratio = 0.5};
  CHECK_OK(nh_mark_cells(m, eta, &mp, marked, &n_marked));
  CHECK(n_marked > 2, "marked %d cells, the test needs more than 2", n_marked);
  int expect[2] = {-1, -1}; /* the two largest (eta, -id) among the marked */
  for (int r = 0; r < 2; r++)
    for (int i = 0; i < n_marked; i++) {
      int c = marked[i];
      if (c == expect[0]) continue;
      int e = expect[r];
      if (e < 0 || eta[c] > eta[e] || (eta[c] == eta[e] && c < e)) expect[r] = c;
    }
  double *w_old = malloc(sizeof(double) * 3 * n0);
  memcpy(w_old, w, sizeof(double) * 3 * n0);
  double *fields[2] = {u, w};
  int n_refined = -1;
  CHECK_OK(nh_adapt_step(a, m, 2, fields, &n_refined));
  u = fields[0], w = fields[1];
  CHECK(n_refined == 2, "refined %d cells, expected 2 (budget)", n_refined);
  for (int r = 0; r < 2; r++)
    CHECK(m->first_child[expect[r]] >= 0, "cell %d (eta %g) not refined", expect[r],
          eta[expect[r]]);
  CHECK(3 * m->n_nodes <= spec.max_dofs, "%d dofs above the budget %d", 3 * m->n_nodes,
        spec.max_dofs);
  CHECK(nh_adapt_indicators(a) == NULL, "indicators still offered after refinement");
  CHECK(memcmp(w, w_old, sizeof(double) * 3 * n0) == 0, "old nodes' values changed");
  double scale = 0;
  for (int i = 0; i < 3 * m->n_nodes; i++) scale = fmax(scale, fabs(w[i]));
  for (int k = n0; k < m->n_nodes; k++) {
    double want[3];
    linear_field(m->X + 3 * k, want);
    for (int i = 0; i < 3; i++)
      CHECK_CLOSE(w[3 * k + i], want[i], 1e-14 * scale, "Eq. 17 of a linear field");
  }
  nh_adapt_destroy(&a);
  nh_mesh_destroy(&m);
  free(u), free(w), free(w_old), free(eta), free(marked);

  /* 3: no budget. */
  spec.max_dofs = 0;
  a = setup(&spec, &m, &u, &w);
  marked = malloc(sizeof(int) * m->n_leaves);
  CHECK_OK(nh_mark_cells(m, nh_adapt_indicators(a), &mp, marked, &n_marked));
  fields[0] = u, fields[1] = w;
  CHECK_OK(nh_adapt_step(a, m, 2, fields, &n_refined));
  CHECK(n_refined == n_marked, "refined %d cells, marked %d", n_refined, n_marked);
  nh_adapt_destroy(&a);
  nh_mesh_destroy(&m);
  free(fields[0]), free(fields[1]), free(marked);
  TEST_END();
}
