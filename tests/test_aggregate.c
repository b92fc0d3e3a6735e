/* test_aggregate — aggregated nodes of integrated cut cells (src/mesh/hanging.c,
 * nh_hanging_detect_aggregated; docs/theory.md §5c, "Aggregated nodes").
 *  1. Linear precision: on an immersed ball (centre off the grid) on 5 grids,
 *     and on one grid with a block of cells refined (hanging and aggregated
 *     nodes in one table, chains through both), every aggregated node's
 *     weights sum to 1 and reproduce its rest position, Σ w X_m = X_s, to
 *     1e-12 (relative to the cell size): the extrapolation of a box leaf's
 *     trilinear field is exact for linear fields. Every master is free
 *     (neither hanging nor aggregated), and some nodes are aggregated.
 *  2. Immersed patch test with aggregation on (α = NH_TISSUE_ALPHA): the
 *     static problem of the uniform pressure p on the ball, with the exact
 *     linear field u = −p (X − c) / (3K) prescribed at three nodes near c
 *     (3-2-1, no rigid motion), is solved (u = P u_free) and compared with
 *     that field at every node with tissue under its shape function:
 *     max error <= 1e-3 of max |u| on 5 grids. Expected: the field is in
 *     the constrained space (item 1) and balances the load up to the
 *     stabilisation's O(α) consistency error (test_fcm), which aggregation
 *     keeps from being amplified by a node held only by α K and a sliver.
 *  3. Slivers: a ball whose radius exceeds 3 cells by ε h on a box grid of
 *     8³ cells (its poles poke ε h into the next layer), ε = 0.6 … 0.005 so
 *     that the smallest nonzero tissue fraction of a leaf sweeps 2e-3 … 1.3e-7
 *     (other cut cells hold 2e-3 whatever ε): the
 *     largest displacement under the pressure stays below the exact field's
 *     bound p (R + √3 h) / (3K) (1 + 1e-3) at every node with tissue, and
 *     the error against the field below 1e-3 of max |u| (as in item 2),
 *     with aggregation. Without it (the same solve, NH_VERBOSE prints it)
 *     the error is 0.45–0.74 of max |u|: the sliver nodes.
 *  4. The least extrapolation: on the analytic brain of tests/anatomy.py
 *     (brainstem 2 cells across) on 11 x 13 x 9 and 12 x 14 x 10 cells, every
 *     aggregated node's weights have Σ |w| no larger than the smallest
 *     Lebesgue constant Π_k max(1, |ξ_k|) of the well-posed ring-1 leaves,
 *     enumerated here independently (ranking by max_k |ξ_k| took a root one
 *     cell off in two axes, Σ |w| = 9, where one off in one axis, 3, was
 *     available: the stalk's outer nodes hung on the layer above). */
#include "check.h"
#include "hanging_mesh.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

static int verbose;

/* The aggregated-node table of the mesh's tissue (fixed nodes kept). */
static nh_hanging *aggregate(const nh_mesh *m, const nh_tissue *t, const unsigned char *fixed,
                             double *support) {
  double *fraction = calloc((size_t)m->n_cells, sizeof(double));
  CHECK_OK(nh_tissue_node_support(t, support));
  for (int l = 0; l < m->n_leaves; l++)
    fraction[m->leaves[l]] = nh_tissue_fraction(t, m->leaves[l]);
  nh_aggregation agg = {support, fraction, NH_AGGREGATE_MIN, fixed};
  nh_hanging *h = NULL;
  CHECK_OK(nh_hanging_detect_aggregated(m, fixed, &agg, &h, NULL));
  free(fraction);
  return h;
}

/* Item 1 on table h: returns the number of aggregated nodes. */
static int linear_precision(const nh_mesh *m, const nh_hanging *h, const char *what) {
  double hmin = INFINITY;
  for (int l = 0; l < m->n_leaves; l++) hmin = fmin(hmin, nh_mesh_cell_size(m, m->leaves[l]));
  for (int k = 0; k < h->n_hanging; k++) {
    double sw = 0.0, x[3] = {0, 0, 0};
    for (int p = h->start[k]; p < h->start[k + 1]; p++) {
      sw += h->weight[p];
      for (int i = 0; i < 3; i++) x[i] += h->weight[p] * m->X[3 * h->master[p] + i];
      CHECK(h->index[h->master[p]] < 0, "%s: master %d of node %d is itself constrained", what,
            h->master[p], h->node[k]);
    }
    const double *X = m->X + 3 * h->node[k];
    CHECK_CLOSE(sw, 1.0, 1e-12, "weights of a constrained node sum to 1");
    double d = fmax(fabs(x[0] - X[0]), fmax(fabs(x[1] - X[1]), fabs(x[2] - X[2])));
    CHECK(d <= 1e-12 * hmin, "%s: node %d (%s): Σ w X_m off its position by %g (h %g)", what,
          h->node[k], h->aggregated[k] ? "aggregated" : "hanging", d, hmin);
  }
  return h->n_aggregated;
}

/* Static solve of the uniform pressure p on the tissue's immersed surface
 * with the exact field prescribed at 3-2-1 nodes near c; returns the max
 * error against it and the max |u| over nodes with support > 0. */
static void pressure_solve(const nh_mesh *m, const nh_tissue *t, int with_aggregation,
                           const double c[3], double *err, double *umax, int *n_agg) {
  const int nn = m->n_nodes, n = 3 * nn;
  const double p = 1e-3, K = t->lambda + 2.0 * t->mu / 3.0;
  double h = INFINITY;
  for (int l = 0; l < m->n_leaves; l++) h = fmin(h, nh_mesh_cell_size(m, m->leaves[l]));
  unsigned char *fixed = calloc((size_t)nn, 1);
  const double off[3][3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const unsigned char fix[3] = {1, NH_FIX_AXES | 2 | 4, NH_FIX_AXES | 4};
  for (int q = 0; q < 3; q++) { /* the nodes nearest c, c + h e_x, c + h e_y */
    int best = -1;
    double bd = INFINITY;
    for (int i = 0; i < nn; i++) {
      double d = 0.0;
      for (int k = 0; k < 3; k++) d += pow(m->X[3 * i + k] - c[k] - off[q][k] * h, 2);
      if (d < bd && !fixed[i]) bd = d, best = i;
    }
    fixed[best] = fix[q];
  }
  double *support = calloc((size_t)nn, sizeof(double));
  nh_hanging *hg = with_aggregation ? aggregate(m, t, fixed, support) : NULL;
  if (!hg) CHECK_OK(nh_tissue_node_support(t, support));
  *n_agg = hg ? hg->n_aggregated : 0;
  nh_system *sys = NULL;
  CHECK_OK(nh_system_create(t, fixed, hg, &sys));
  double *u0 = calloc((size_t)n, sizeof(double)), *f = calloc((size_t)n, sizeof(double)),
         *fi = calloc((size_t)n, sizeof(double)), *du = calloc((size_t)n, sizeof(double));
  int nf = nh_system_free_dofs(sys);
  double *b = calloc((size_t)nf, sizeof(double)), *x = calloc((size_t)nf, sizeof(double));
  for (int i = 0; i < nn; i++)
    for (int k = 0; k < 3; k++) u0[3 * i + k] = -p * (m->X[3 * i + k] - c[k]) / (3.0 * K);
  nh_traction tr;
  memset(&tr, 0, sizeof tr);
  tr.region.kind = NH_REGION_BOX;
  for (int k = 0; k < 3; k++) tr.region.min[k] = -1.0, tr.region.max[k] = 1.0;
  tr.is_pressure = 1, tr.pressure = p;
  CHECK_OK(nh_traction_load(m, &tr, f, NULL));
  nh_system_assemble(sys, u0, NULL, 0.0, 1.0, fi, NULL, 1);
  for (int i = 0; i < n; i++) f[i] -= fi[i];
  nh_system_gather(sys, f, b);
  CHECK_OK(nh_system_factor(sys));
  CHECK_OK(nh_system_solve(sys, b, x));
  nh_system_scatter(sys, x, du);
  *err = 0.0, *umax = 0.0;
  double big = 0.0;
  for (int i = 0; i < nn; i++) {
    if (!(support[i] > 0.0)) continue; /* no tissue under its shape function */
    double e = 0.0, a = 0.0, ue = 0.0;
    for (int k = 0; k < 3; k++) {
      e = fmax(e, fabs(du[3 * i + k]));
      a = fmax(a, fabs(u0[3 * i + k] + du[3 * i + k]));
      ue = fmax(ue, fabs(u0[3 * i + k]));
    }
    *err = fmax(*err, e), *umax = fmax(*umax, a), big = fmax(big, ue);
  }
  *err /= big;
  free(u0), free(f), free(fi), free(du), free(b), free(x), free(support), free(fixed);
  nh_system_destroy(&sys);
  nh_hanging_destroy(&hg);
}

static void ball_grids(void) {
  const double c0[3] = {0.0013, -0.0021, 0.0007};
  nh_domain d;
  nh_domain_sphere(c0, 0.03, &d);
  d.cut_cells = NH_CUT_CELLS_INTEGRATED;
  const int grids[5] = {5, 6, 8, 11, 14};
  nh_material mat = {3000.0, 0.45, 1000.0, NH_FORMULATION_BBAR};
  for (int gi = 0; gi < 5; gi++) {
    const int grid[3] = {grids[gi], grids[gi], grids[gi]};
    nh_mesh *m = NULL;
    nh_tissue *t = NULL;
    CHECK_OK(nh_mesh_create(&d, grid, &m));
    CHECK_OK(nh_tissue_create(m, &mat, &t));
    double *support = calloc((size_t)m->n_nodes, sizeof(double));
    nh_hanging *h = aggregate(m, t, NULL, support);
    int n_agg = linear_precision(m, h, "ball");
    CHECK(n_agg > 0, "ball %d³: no aggregated node", grids[gi]);
    double err, umax;
    int na;
    pressure_solve(m, t, 1, c0, &err, &umax, &na);
    CHECK(err <= 1e-3, "ball %d³, aggregated: patch test error %g of max |u| (tolerance 1e-3)",
          grids[gi], err);
    if (verbose) {
      double err0, umax0;
      pressure_solve(m, t, 0, c0, &err0, &umax0, &na);
      printf("ball %2d³: %d aggregated nodes; patch test error %.2e (without aggregation "
             "%.2e)\n",
             grids[gi], n_agg, err, err0);
    }
    nh_hanging_destroy(&h);
    free(support);
    nh_tissue_destroy(&t);
    nh_mesh_destroy(&m);
  }
  /* a refined block: hanging and aggregated nodes in one table */
  const int grid[3] = {6, 6, 6};
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  nh_template *tmpl = regular_template(2);
  int *cells = malloc(sizeof(int) * (size_t)m->n_leaves), nc = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    if (m->X[3 * m->cells[8 * c + 6]] > c0[0] + 1e-9) cells[nc++] = c; /* the half x > c */
  }
  CHECK_OK(nh_mesh_refine(m, tmpl, cells, nc, NULL));
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  double *support = calloc((size_t)m->n_nodes, sizeof(double));
  nh_hanging *h = aggregate(m, t, NULL, support);
  int n_agg = linear_precision(m, h, "refined ball");
  CHECK(n_agg > 0 && h->n_hanging > n_agg, "refined ball: %d aggregated of %d constrained nodes",
        n_agg, h->n_hanging);
  if (verbose)
    printf("refined ball 6³ + half: %d hanging, %d aggregated nodes\n", h->n_hanging - n_agg,
           n_agg);
  nh_hanging_destroy(&h);
  free(support), free(cells);
  nh_template_destroy(&tmpl);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  nh_domain_release(&d);
}

/* Item 3: the ball of radius (3 + ε) h on the box grid [c − 4h, c + 4h]³. */
static void slivers(void) {
  const double c[3] = {0.0, 0.0, 0.0}, h = 0.01;
  const int grid[3] = {8, 8, 8};
  const double lo[3] = {-4 * h, -4 * h, -4 * h}, hi[3] = {4 * h, 4 * h, 4 * h};
  const double eps[7] = {0.6, 0.2, 0.08, 0.04, 0.02, 0.01, 0.005};
  nh_material mat = {3000.0, 0.45, 1000.0, NH_FORMULATION_BBAR};
  double fmin_all = INFINITY, fmax_all = 0.0;
  for (int e = 0; e < 7; e++) {
    const double R = (3.0 + eps[e]) * h;
    nh_domain d;
    nh_domain_sphere(c, R, &d);
    d.cut_cells = NH_CUT_CELLS_INTEGRATED;
    nh_mesh *m = NULL;
    nh_tissue *t = NULL;
    CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
    nh_domain_copy(&m->domain, &d);
    CHECK_OK(nh_tissue_create(m, &mat, &t));
    double smallest = INFINITY;
    for (int l = 0; l < m->n_leaves; l++) {
      double f = nh_tissue_fraction(t, m->leaves[l]);
      if (f > 0.0) smallest = fmin(smallest, f);
    }
    fmin_all = fmin(fmin_all, smallest), fmax_all = fmax(fmax_all, smallest);
    const double K = t->lambda + 2.0 * t->mu / 3.0, p = 1e-3,
                 bound = p * (R + sqrt(3.0) * h) / (3.0 * K);
    double err, umax, err0 = NAN, umax0 = NAN;
    int na;
    pressure_solve(m, t, 1, c, &err, &umax, &na);
    CHECK(umax <= bound * (1 + 1e-3),
          "sliver %.1e: max |u| %g above the exact field's bound %g (aggregated)", smallest, umax,
          bound);
    CHECK(err <= 1e-3, "sliver %.1e: error %g of max |u| (tolerance 1e-3, aggregated)", smallest,
          err);
    if (verbose) {
      int na0;
      pressure_solve(m, t, 0, c, &err0, &umax0, &na0);
      printf("ε %.3f: smallest tissue fraction %.2e, %d aggregated; max|u| / bound %.4f "
             "(without aggregation %.3g), error %.2e (%.2e)\n",
             eps[e], smallest, na, umax / bound, umax0 / bound, err, err0);
    }
    nh_tissue_destroy(&t);
    nh_mesh_destroy(&m);
    nh_domain_release(&d);
  }
  CHECK(fmin_all <= 1e-6 && fmax_all >= 1e-3,
        "the slivers' smallest tissue fraction swept %g … %g, want 1e-6 … 1e-3", fmin_all,
        fmax_all);
}

/* Item 4: the least extrapolation. The analytic brain of tests/anatomy.py
 * (0.144 x 0.176 x 0.128 m; its brainstem, radius 13 mm, is 2 cells across)
 * on box grids with no refinement: for every aggregated node v, the
 * well-posed leaves of ring 1 (tissue, no corner with 0 < μ < μ₀, sharing a
 * corner with a leaf of v) are enumerated here independently, each with the
 * Lebesgue constant of extrapolating its trilinear field to X_v,
 * Λ = Σ_a |N_a(ξ_v)| = Π_k max(1, |ξ_k|); expected: v's weights have
 * Σ |w| <= the smallest Λ (its root's, or the mean of mirror-image roots'). */
static void least_extrapolation(void) {
  const double c0[3] = {0, 0, 0}, size[3] = {0.144, 0.176, 0.128};
  nh_domain d;
  nh_domain_brain(c0, size, &d);
  d.cut_cells = NH_CUT_CELLS_INTEGRATED;
  const int grids[2][3] = {{11, 13, 9}, {12, 14, 10}};
  nh_material mat = {1e6, 0.45, 1040.0, NH_FORMULATION_FULL};
  for (int gi = 0; gi < 2; gi++) {
    nh_mesh *m = NULL;
    nh_tissue *t = NULL;
    CHECK_OK(nh_mesh_create(&d, grids[gi], &m));
    CHECK_OK(nh_tissue_create(m, &mat, &t));
    double *support = calloc((size_t)m->n_nodes, sizeof(double));
    nh_hanging *h = aggregate(m, t, NULL, support);
    int *start = NULL, *leaf = NULL, checked = 0, worse = 0;
    CHECK_OK(nh_mesh_node_leaves(m, &start, &leaf));
    for (int k = 0; k < h->n_hanging; k++) {
      if (!h->aggregated[k]) continue;
      const int v = h->node[k];
      const double *Xv = m->X + 3 * v;
      double best = INFINITY, sum = 0.0;
      for (int p = h->start[k]; p < h->start[k + 1]; p++) sum += fabs(h->weight[p]);
      for (int p = start[v]; p < start[v + 1]; p++) /* v's leaves */
        for (int a = 0; a < 8; a++) {
          const int u = m->cells[8 * leaf[p] + a];
          for (int q = start[u]; q < start[u + 1]; q++) { /* ring 1 */
            const int c = leaf[q];
            int ok = nh_tissue_fraction(t, c) > 0.0;
            for (int b = 0; b < 8 && ok; b++) {
              const double mu = support[m->cells[8 * c + b]];
              ok = !(mu > 0.0 && mu < NH_AGGREGATE_MIN);
            }
            if (!ok) continue;
            double Xe[24], lam = 1.0;
            nh_mesh_cell_coords(m, m->X, c, Xe);
            for (int i = 0; i < 3; i++) {
              const double lo = Xe[i], hi = Xe[18 + i]; /* corners 0 and 6 */
              lam *= fmax(1.0, fabs((2 * Xv[i] - lo - hi) / (hi - lo)));
            }
            best = fmin(best, lam);
          }
        }
      if (!isfinite(best)) continue; /* a root of ring 2 */
      checked++;
      if (!(sum <= best * (1 + 1e-9)) && worse++ < 3)
        fprintf(stderr,
                "brain %dx%dx%d: node %d at (%.1f, %.1f, %.1f) mm extrapolated with sum |w| = %g, "
                "a ring-1 root offers %g\n",
                grids[gi][0], grids[gi][1], grids[gi][2], v, 1e3 * Xv[0], 1e3 * Xv[1], 1e3 * Xv[2],
                sum, best);
    }
    CHECK(checked > 0 && worse == 0,
          "brain %dx%dx%d: %d of %d aggregated nodes extrapolated more than necessary",
          grids[gi][0], grids[gi][1], grids[gi][2], worse, checked);
    if (verbose)
      printf("brain %dx%dx%d: %d aggregated nodes with a ring-1 root, none extrapolated beyond the "
             "least Lebesgue constant\n",
             grids[gi][0], grids[gi][1], grids[gi][2], checked);
    free(start), free(leaf), free(support);
    nh_hanging_destroy(&h);
    nh_tissue_destroy(&t);
    nh_mesh_destroy(&m);
  }
  nh_domain_release(&d);
}

int main(void) {
  verbose = getenv("NH_VERBOSE") != NULL;
  ball_grids();
  slivers();
  least_extrapolation();
  return nh_test_failures ? 1 : 0;
}
