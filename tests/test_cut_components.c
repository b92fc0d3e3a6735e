/* test_cut_components — connected components of a cut cell's tissue
 * (nh_cut_components, nh_mesh_split_cells; mesh/cutcell.c; docs/dbs.md,
 * "The odd grids' offset").
 *  1. A slot: the unit cube less {|x − 1/2| < 0.05, z > 0.3}, on the cells of
 *     a 3³ and a 4³ grid, lattice depth 2 (sub-box 1/12 and 1/16). On 3³ the
 *     middle column x ∈ [1/3, 2/3] has the lattice plane x = 1/2 inside the
 *     slot (every point there with z > 0.3 is outside the tissue): its cells
 *     with z >= 1/3 hold two components, 32 sub-boxes each (i = 0, 1 and
 *     i = 2, 3), joined in the bottom cell through its lattice layers below
 *     z = 0.3: 3 × 2 = 6 split cells, every other cell one component. On 4³
 *     the cell faces lie on x = 1/2 and the nearest lattice planes x = 1/2 ±
 *     1/16 are tissue: no split cell. Depth 0 (one box): one component.
 *  2. The analytic brain of cases/dbs (mesh/domain.c), whose fissure is the
 *     slab |x| < w = 1.4 mm above z = e_z = 19.5 mm, F >= min(w − |x|, z −
 *     e_z) > 0 in it. On 17 × 21 × 16 and 19 × 22 × 17 (odd across x: the
 *     middle column's lattice plane x = 0 lies in the gap) every leaf of the
 *     middle column wholly above e_z that holds tissue holds exactly two
 *     components, mirror images (F is mirror symmetric; each is the part of a
 *     convex hemisphere on one side); on 18 × 22 × 17 (faces on x = 0) no
 *     leaf beside x = 0 above e_z is split. nh_mesh_split_cells counts at
 *     least the middle column's split leaves.
 * Silent on success; NH_VERBOSE=1 prints the counts. */
#include "check.h"
#include "mesh/mesh.h"

#include <string.h>

static double slot_level(const void *ctx, const double x[3]) {
  (void)ctx;
  return -fmax(fabs(x[0] - 0.5) - 0.05, 0.3 - x[2]); /* > 0 in the slot, < 0 elsewhere */
}

static void slot_test(int verbose) {
  nh_cut_spec spec;
  memset(&spec, 0, sizeof spec);
  spec.level = slot_level, spec.lipschitz = 1.0, spec.depth = 2;
  for (int n = 3; n <= 4; n++) {
    int split = 0;
    for (int k = 0; k < n; k++)
      for (int j = 0; j < n; j++)
        for (int i = 0; i < n; i++) {
          const double lo[3] = {(double)i / n, (double)j / n, (double)k / n};
          const double hi[3] = {(i + 1.0) / n, (j + 1.0) / n, (k + 1.0) / n};
          int nc = -1, label[64];
          CHECK_OK(nh_cut_components(&spec, lo, hi, &nc, label));
          const int expect = n == 3 && i == 1 && k >= 1 ? 2 : 1;
          CHECK(nc == expect, "slot on %d^3, cell (%d, %d, %d): %d components, expected %d", n, i,
                j, k, nc, expect);
          split += nc > 1;
          if (expect == 2)
            for (int b = 0; b < 64; b++)
              CHECK(label[b] >= 0 && (label[b] == label[0]) == (b % 4 < 2),
                    "slot cell (%d, %d, %d), sub-box %d: label %d (sub-box 0: %d)", i, j, k, b,
                    label[b], label[0]);
        }
    CHECK(split == (n == 3 ? 6 : 0), "slot on %d^3: %d split cells, expected %d", n, split,
          n == 3 ? 6 : 0);
    if (verbose) fprintf(stderr, "slot on %d^3: %d split cells\n", n, split);
  }
  spec.depth = 0;
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  int nc = -1;
  CHECK_OK(nh_cut_components(&spec, lo, hi, &nc, NULL));
  CHECK(nc == 1, "depth 0: %d components, expected 1", nc);
}

static void brain_test(int verbose) {
  const double center[3] = {0, 0, 0}, size[3] = {0.14, 0.17, 0.13};
  const double ez = 0.3 * 0.5 * size[2];
  const int grids[3][3] = {{17, 21, 16}, {19, 22, 17}, {18, 22, 17}};
  for (int g = 0; g < 3; g++) {
    const int *grid = grids[g], odd = grid[0] % 2;
    nh_domain d;
    nh_domain_brain(center, size, &d);
    d.cut_cells = NH_CUT_CELLS_INTEGRATED;
    nh_mesh *m = NULL;
    CHECK_OK(nh_mesh_create(&d, grid, &m));
    nh_domain_release(&d);
    if (!m) continue;
    nh_cut_spec spec;
    nh_cut_spec_domain(&spec, &m->domain, NH_CUT_DEPTH);
    const double hx = (odd ? 0.5 : 1.0) * size[0] / grid[0];
    int middle = 0, beside_split = 0;
    for (int l = 0; l < m->n_leaves; l++) {
      double Xe[24], lo[3], hi[3];
      nh_mesh_cell_coords(m, m->X, m->leaves[l], Xe);
      if (!nh_hex_is_box(Xe, lo, hi) || !(lo[2] > ez)) continue;
      const double mid = 0.5 * (lo[0] + hi[0]);
      if (fabs(mid) > hx) continue; /* the column(s) at x = 0: centres 0 (odd) or ±hx/2 */
      int nc = -1, label[64];
      CHECK_OK(nh_cut_components(&spec, lo, hi, &nc, label));
      if (odd) {
        if (nc == 0) continue;
        CHECK(nc == 2, "%dx%dx%d: middle-column leaf at z = %g mm: %d components, expected 2",
              grid[0], grid[1], grid[2], 1e3 * lo[2], nc);
        for (int b = 0; b < 64 && nc == 2; b++) { /* mirror images: i <-> 3 − i */
          const int mb = (3 - b % 4) + 4 * (b / 4);
          CHECK((label[b] < 0) == (label[mb] < 0) && (label[b] < 0 || label[b] != label[mb]),
                "%dx%dx%d: sub-box %d label %d, its mirror %d label %d", grid[0], grid[1], grid[2],
                b, label[b], mb, label[mb]);
        }
        middle++;
      } else {
        beside_split += nc > 1;
      }
    }
    int n_split = -1, most = 0;
    CHECK_OK(nh_mesh_split_cells(m, &n_split, &most));
    if (odd) {
      CHECK(middle > 0, "%dx%dx%d: no middle-column leaf above the fissure's floor", grid[0],
            grid[1], grid[2]);
      CHECK(n_split >= middle, "%dx%dx%d: %d split leaves, fewer than the middle column's %d",
            grid[0], grid[1], grid[2], n_split, middle);
    } else {
      CHECK(beside_split == 0, "%dx%dx%d: %d leaves beside x = 0 split, expected 0", grid[0],
            grid[1], grid[2], beside_split);
    }
    if (verbose)
      fprintf(stderr,
              "%dx%dx%d: %d split leaves (the middle column above e_z: %d), at most %d parts\n",
              grid[0], grid[1], grid[2], n_split, middle, most);
    nh_mesh_destroy(&m);
  }
}

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  slot_test(verbose);
  brain_test(verbose);
  return nh_test_failures ? 1 : 0;
}
