/* test_goal_marking — how the goals' indicators make the marking indicator
 * (adapt/refine.c, adapt.marking.goals; docs/theory.md §6.6 "Indicators and
 * marking") on the localized-load block of test_dwr (4 x 2 x 2 cm on the
 * uniform 8x4x4 grid, E 10 kPa, ν 0.3, full element, clamped at x = 4 cm,
 * 1 µN down over the 2 mm cube centred at (1, 1, 1) cm), two goals: the
 * probe p₁ = (1.5, 1.0, 1.0) cm next to the load and p₂ = (0.5, 1.75, 1.75)
 * cm near the free end's upper edge, whose indicators are smaller.
 *
 * The per-goal indicators η_K^p come from nh_dwr_estimate (the dual-weighted
 * estimate itself is test_dwr's); here the marked sets are formed from them
 * independently of refine.c and compared with nh_adapt_planned after
 * nh_adapt_estimate_goal, marking max θ = 0.3, max_level 1. On a uniform
 * grid the 2:1 closure adds no cell, so the planned set is the marking:
 *  1. goals: sum — {K : Σ_p η_K^p ≥ θ max_K' Σ_p η_K'^p};
 *  2. goals: each — ∪_p {K : η_K^p ≥ θ max_K' η_K'^p}, the union of each
 *     goal's own θ-marking.
 *  3. goals: sum with goal_leaves — the set of 1 and every leaf below
 *     max_level whose box overlaps a goal's averaging box p + [−r, r]³:
 *     here the leaves (edge h = 5 mm) with |c − p|_k < h/2 + r in every
 *     component k (c their centre), 8 around p₁ (on a grid corner) and 2
 *     around p₂ (on a grid face).
 * Each asserted equal as sets. The case must exercise the differences: the
 * sum's set misses at least one cell of p₂'s own marking (p₂ crowded out)
 * and at least one leaf of 3's goal boxes, asserted, so that a driver that
 * summed in both modes fails 2 and one that ignored goal_leaves fails 3.
 * NH_VERBOSE=1 prints the sets' sizes. */
#include "check.h"
#include "adapt/adapt.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "dwr_support.h"

static const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
static const int grid[3] = {8, 4, 4};
static const double goals[6] = {0.015, 0.010, 0.010, 0.005, 0.0175, 0.0175};
#define THETA 0.3

/* The cells of `planned` (n of them) as a 0/1 mask over the cells. */
static void mask_of(const int *cells, int n, int n_cells, unsigned char *mask) {
  memset(mask, 0, (size_t)n_cells);
  for (int i = 0; i < n; i++) mask[cells[i]] = 1;
}

int main(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  nh_hanging *h = NULL;
  nh_system *s = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_material mat = {1.0e4, 0.3, 1000, NH_FORMULATION_FULL};
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  const int nn = m->n_nodes, n3 = 3 * nn, nc = m->n_cells;
  unsigned char *fixed = malloc(nn);
  for (int i = 0; i < nn; i++) fixed[i] = m->X[3 * i] > 0.0399;
  CHECK_OK(nh_hanging_detect(m, fixed, &h));
  CHECK_OK(nh_system_create(t, fixed, h, &s));
  double *f = malloc(sizeof(double) * n3), *u = calloc(n3, sizeof(double));
  const int nf = nh_system_free_dofs(s);
  double *b = malloc(sizeof(double) * nf), *x = malloc(sizeof(double) * nf);
  CHECK_OK(dwr_block_load(m, f));
  nh_system_assemble(s, u, NULL, 0.0, 1.0, u, NULL, 0);
  CHECK_OK(nh_system_factor(s));
  nh_system_gather(s, f, b);
  CHECK_OK(nh_system_solve(s, b, x));
  nh_system_scatter(s, x, u);

  /* the per-goal indicators, on their own */
  const double radius = 0.25 * (hi[0] - lo[0]) / grid[0]; /* half the level-1 cell edge */
  double est[6], norm[2], *ind = malloc(sizeof(double) * 2 * nc);
  nh_dwr_result r = {.estimate = est, .norm = norm, .indicator = ind};
  CHECK_OK(nh_dwr_estimate(s, NULL, 1.0, m, t, h, u, 2, goals, radius, NULL, &r));
  double top[2] = {0, 0}, top_sum = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    for (int p = 0; p < 2; p++) top[p] = fmax(top[p], ind[(size_t)nc * p + c]);
    top_sum = fmax(top_sum, ind[c] + ind[(size_t)nc + c]);
  }
  unsigned char *want_sum = calloc(nc, 1), *want_each = calloc(nc, 1), *own2 = calloc(nc, 1);
  unsigned char *want_leaves = calloc(nc, 1);
  const double edge = (hi[0] - lo[0]) / grid[0];
  int n_boxed = 0, boxed_missed = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    want_sum[c] = ind[c] + ind[(size_t)nc + c] >= THETA * top_sum;
    for (int p = 0; p < 2; p++) want_each[c] |= ind[(size_t)nc * p + c] >= THETA * top[p];
    own2[c] = ind[(size_t)nc + c] >= THETA * top[1];
    double Xe[24], centre[3] = {0, 0, 0};
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int q = 0; q < 8; q++)
      for (int k = 0; k < 3; k++) centre[k] += Xe[3 * q + k] / 8;
    int boxed = 0;
    for (int p = 0; p < 2; p++) {
      int in = 1;
      for (int k = 0; k < 3; k++) in &= fabs(centre[k] - goals[3 * p + k]) < 0.5 * edge + radius;
      boxed |= in;
    }
    want_leaves[c] = want_sum[c] || boxed;
    n_boxed += boxed;
    boxed_missed += boxed && !want_sum[c];
  }
  CHECK(n_boxed == 10, "%d leaves overlap the goals' boxes, expected 8 + 2", n_boxed);
  CHECK(boxed_missed > 0, "the sum's marking holds every leaf of the goals' boxes: the case does "
                          "not exercise goal_leaves");
  int missed = 0;
  for (int c = 0; c < nc; c++) missed += own2[c] && !want_sum[c];
  CHECK(missed > 0,
        "the sum's marking holds all of goal 2's own marking: the case does not "
        "crowd goal 2 out (estimates %.3g, %.3g m)",
        norm[0], norm[1]);

  nh_adapt_spec spec = {.enabled = 1,
                        .strategy = NH_MARK_MAX,
                        .theta = THETA,
                        .max_level = 1,
                        .every = 1,
                        .estimator = NH_ESTIMATOR_GOAL,
                        .separate_every = 1};
  snprintf(spec.template_path, sizeof spec.template_path, "%s/templates/hex2.tmpl",
           src ? src : ".");
  int *planned = malloc(sizeof(int) * m->n_leaves);
  unsigned char *got = malloc(nc);
  static const char *const modes[] = {"sum", "each", "sum, goal_leaves"};
  for (int mode = 0; mode < 3; mode++) {
    spec.goal_marking = mode == 1 ? NH_GOAL_MARKING_EACH : NH_GOAL_MARKING_SUM;
    spec.goal_leaves = mode == 2;
    nh_adapt *a = NULL;
    CHECK_OK(nh_adapt_create(&spec, 0, &a));
    CHECK_OK(nh_adapt_set_goals(a, m, 2, goals));
    CHECK_OK(nh_adapt_estimate_goal(a, s, NULL, 1.0, m, t, u, h, NULL, NULL));
    int n = 0;
    CHECK_OK(nh_adapt_planned(a, m, planned, &n));
    mask_of(planned, n, nc, got);
    const unsigned char *want = mode == 2 ? want_leaves : mode ? want_each : want_sum;
    int extra = 0, lacking = 0, size = 0;
    for (int c = 0; c < nc; c++) {
      extra += got[c] && !want[c];
      lacking += want[c] && !got[c];
      size += want[c];
    }
    CHECK(extra == 0 && lacking == 0,
          "goals: %s: the planned set (%d cells) has %d cells beyond the expected %d and lacks %d",
          modes[mode], n, extra, size, lacking);
    if (getenv("NH_VERBOSE"))
      printf("goals: %s: %d cells planned, %d expected (goal 2's own marking: %d cells the sum "
             "misses; estimates %.3g, %.3g m)\n",
             modes[mode], n, size, missed, norm[0], norm[1]);
    nh_adapt_destroy(&a);
  }
  free(planned), free(got), free(want_sum), free(want_each), free(own2), free(ind);
  free(want_leaves);
  free(f), free(u), free(b), free(x), free(fixed);
  nh_system_destroy(&s);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  return nh_test_failures ? 1 : 0;
}
