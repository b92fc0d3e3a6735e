/* test_brainshift — the loads and supports of a brain-shift scene
 * (docs/theory.md §5: "Buoyancy and brain shift", "Fixed regions").
 *  1. Drainage level (tissue.buoyancy.level). The tissue above the level
 *     loses buoyancy, the tissue below keeps it, so:
 *     a. a level above the whole brain drains nothing: the external force
 *        is exactly 0 (full buoyancy);
 *     b. a level below the whole brain drains everything: the external
 *        force equals, bitwise, that of the same scene without `level`
 *        (today's uniform loss);
 *     c. on a box domain (0.1 m cube, 4³ cells, gravity −z) the total force
 *        is ρ g Δb times the volume above the level: exactly for a level
 *        through the middle of a cell layer (the 8³ sub-samples split
 *        evenly), and within one sub-sample layer (ρ g Δb A h / 8) for a
 *        level elsewhere.
 *  2. Fixed regions on an immersed domain are ties over the region's
 *     tissue. The brain of tests/data/brain.yaml under gravity, static: the
 *     tie forces Σ T u over the whole mesh balance the weight (the elastic
 *     forces of every element sum to zero), to the solver's tolerance; and
 *     the tissue inside the region moves less than 2 % of the largest
 *     displacement (the tie is 10³ E/ℓ²).
 *  3. tissue.fixed.N.refine: the same brain (cut cells integrated) with its
 *     region's neighbourhood
 *     refined to h = 5 mm (base cells ~14 mm): after setup every leaf with a
 *     point inside the region (its corners, centre and 5³ sub-points, by
 *     nh_region_contains) has a largest edge <= h; every leaf all of whose
 *     corners are more than 3 base cells from the region is a cell of the
 *     initial grid (level 0: 2:1 grading widens the refined zone by less
 *     than Σ h₀/2ᵏ < h₀ per side); the mesh was refined at all; and, static
 *     under gravity, the tie forces balance the weight to 1e-8 as in 2.
 *     Both with integrated and with scaled cut cells: the scene has no
 *     adapt section, and the refined mesh's hanging nodes must still be
 *     constrained (without, scaled cut cells stalled Newton at 0.83).
 *  4. Coarsening keeps the refined region: the mesh of 3 with an adapt
 *     section that refines nothing (max_level 0) and merges every family
 *     whose children's SPR indicators are all below 0.9 of the largest
 *     (adapt.coarsen.fraction; with nothing marked the threshold is the
 *     largest indicator), static, two steps under gravity. Before the first
 *     step four initial cells far from the region (more than 3 base cells)
 *     are refined once, so that coarsening has families it may merge. After
 *     each step every leaf that meets the region still has a largest edge
 *     <= refine (the key's definition: coarsening never merges a family
 *     whose parent would be coarser there; the tie's inner families, barely
 *     strained, are below the threshold and would be merged without that
 *     rule), and after the steps leaves were merged (n_leaves fell: nothing
 *     can be refined at max_level 0), else the test would not test.
 * Silent on success; NH_VERBOSE=1 prints the numbers. */
#include "check.h"

#include "sim/sim.h"

static void open_brain(const char *const *sets, nh_scene **sc, nh_sim **sim) {
  const char *src = getenv("NH_SOURCE_DIR");
  char path[1024];
  int n = 0;
  while (sets && sets[n]) n++;
  snprintf(path, sizeof path, "%s/tests/data/brain.yaml", src ? src : ".");
  CHECK_OK(nh_scene_load(path, n, sets, sc));
  nh_sim_options opt = {.dry_run = 1};
  CHECK_OK(nh_sim_create(*sc, &opt, sim));
}

static double *external_force(const char *const *sets, int *n) {
  nh_scene *sc;
  nh_sim *sim;
  open_brain(sets, &sc, &sim);
  *n = 3 * nh_sim_mesh(sim)->n_nodes;
  double *f = malloc(sizeof(double) * (size_t)*n);
  nh_sim_external_force(sim, 1.0, f);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&sc);
  return f;
}

static void test_level_brain(void) {
  int n0, n1, n2;
  const char *uniform[] = {"tissue.buoyancy={before: 1, after: 0.9}", NULL};
  const char *top[] = {"tissue.buoyancy={before: 1, after: 0.9, level: [0, 0, 0.2]}", NULL};
  const char *bottom[] = {"tissue.buoyancy={before: 1, after: 0.9, level: [0, 0, -0.2]}", NULL};
  double *fu = external_force(uniform, &n0), *ft = external_force(top, &n1);
  double *fb = external_force(bottom, &n2);
  CHECK(n0 == n1 && n0 == n2, "meshes differ: %d %d %d", n0, n1, n2);
  double fbig = 0.0;
  for (int i = 0; i < n0; i++) {
    fbig = fmax(fbig, fabs(fu[i]));
    CHECK(ft[i] == 0.0, "level above the brain: force[%d] = %g, expected 0", i, ft[i]);
    CHECK(fb[i] == fu[i], "level below the brain: force[%d] = %.17g, uniform loss %.17g", i, fb[i],
          fu[i]);
  }
  CHECK(fbig > 0.0, "the uniform loss gives no force");
  free(fu), free(ft), free(fb);
}

static double total_z(const char *level) {
  char buoy[160];
  snprintf(buoy, sizeof buoy, "tissue.buoyancy={before: 1, after: 0.5, level: %s}", level);
  const char *sets[] = {"tissue.domain={box: {min: [0, 0, 0], max: [0.1, 0.1, 0.1]}}",
                        "tissue.grid=[4, 4, 4]",
                        "tissue.fixed=[{box: {min: [0, 0, 0], max: [0.1, 0.1, 0]}}]", buoy, NULL};
  int n;
  double *f = external_force(sets, &n), sum = 0.0;
  for (int i = 2; i < n; i += 3) sum += f[i];
  free(f);
  return sum;
}

static void test_level_box(void) {
  const double rho = 1040, g = 9.81, db = 0.5, area = 0.01, h = 0.025;
  double mid = total_z("[0, 0, 0.0375]"); /* the middle of the second cell layer */
  double exact = -rho * g * db * area * (0.1 - 0.0375);
  CHECK_CLOSE(mid, exact, 1e-12 * fabs(exact), "force above a level at a layer's middle");
  double off = total_z("[0, 0, 0.06]");
  double exact_off = -rho * g * db * area * (0.1 - 0.06);
  CHECK_CLOSE(off, exact_off, rho * g * db * area * h / 8, "force above a level at z = 0.06");
  if (getenv("NH_VERBOSE"))
    printf("box: level 0.0375: %.12g N (exact %.12g); 0.06: %.12g N (exact %.12g)\n", mid, exact,
           off, exact_off);
}

/* Part 3's mesh checks (the region tissue.fixed[0], h its refine); with
 * `far`, also that the leaves far from the region are initial cells. */
static void check_refined(const nh_scene *sc, const nh_mesh *m, int far_initial) {
  const nh_region *r = &sc->tissue.fixed[0];
  const double h = sc->tissue.fix[0].refine;
  double h0 = 0.0; /* the initial grid's largest edge */
  int refined = 0, fine = 0, far = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24], lo[3], hi[3], edge = 0.0;
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int k = 0; k < 3; k++) lo[k] = hi[k] = Xe[k];
    for (int a = 1; a < 8; a++)
      for (int k = 0; k < 3; k++)
        lo[k] = fmin(lo[k], Xe[3 * a + k]), hi[k] = fmax(hi[k], Xe[3 * a + k]);
    for (int k = 0; k < 3; k++) edge = fmax(edge, hi[k] - lo[k]);
    if (m->level[c] == 0) h0 = fmax(h0, edge);
    refined += m->level[c] > 0;
    int inside = 0;
    for (int i = 0; i <= 4 && !inside; i++)
      for (int j = 0; j <= 4 && !inside; j++)
        for (int q = 0; q <= 4 && !inside; q++) {
          double x[3] = {lo[0] + (hi[0] - lo[0]) * i / 4.0, lo[1] + (hi[1] - lo[1]) * j / 4.0,
                         lo[2] + (hi[2] - lo[2]) * q / 4.0};
          inside = nh_region_contains(r, x, 0.0);
        }
    if (inside) {
      fine++;
      CHECK(edge <= h * (1 + 1e-12), "leaf %d meets the region with edge %g > refine %g", c, edge,
            h);
    }
  }
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l], near = 0;
    for (int a = 0; a < 8; a++)
      near |= nh_region_distance(r, m->X + 3 * m->cells[8 * c + a]) <= 3 * h0;
    if (near) continue;
    far++;
    CHECK(!far_initial || m->level[c] == 0, "leaf %d far from the region refined (level %d)", c,
          m->level[c]);
  }
  CHECK(refined > 0 && fine > 0 && far > 0, "refined %d, fine at the region %d, far %d", refined,
        fine, far);
  if (getenv("NH_VERBOSE"))
    printf("refine %g (base %g): %d leaves, %d refined, %d at the region, %d far\n", h, h0,
           m->n_leaves, refined, fine, far);
}

static void test_tie(const char *refine, const char *cut_cells) {
  nh_scene *sc;
  nh_sim *sim;
  const char *sets[] = {"solver.tolerance=1e-10", refine, cut_cells, NULL};
  open_brain(sets, &sc, &sim);
  if (refine) check_refined(sc, nh_sim_mesh(sim), 1);
  CHECK_OK(nh_sim_step(sim));
  const nh_mesh *m = nh_sim_mesh(sim);
  const nh_tissue *t = nh_sim_tissue(sim);
  const double *u = nh_sim_displacements(sim);
  int n = 3 * m->n_nodes;
  double *fe = malloc(sizeof(double) * (size_t)n), weight[3] = {0, 0, 0}, tie[3] = {0, 0, 0};
  nh_sim_external_force(sim, 1.0, fe);
  for (int i = 0; i < n; i++) weight[i % 3] += fe[i];
  for (int l = 0; l < m->n_leaves; l++) {
    double f[24];
    nh_tissue_element(t, m->leaves[l], u, f, NULL);
    for (int i = 0; i < 24; i++) tie[i % 3] += f[i];
  }
  for (int k = 0; k < 3; k++)
    CHECK_CLOSE(tie[k], weight[k], 1e-8 * fabs(weight[2]), "tie forces vs the weight");
  /* displacement inside the region against the largest */
  const nh_region *r = &sc->tissue.fixed[0];
  double umax = 0.0, uin = 0.0;
  for (int i = 0; i < m->n_nodes; i++) {
    double a =
        sqrt(u[3 * i] * u[3 * i] + u[3 * i + 1] * u[3 * i + 1] + u[3 * i + 2] * u[3 * i + 2]);
    umax = fmax(umax, a);
    /* the tissue inside the region (a node outside the tissue is not tied) */
    if (nh_region_contains(r, m->X + 3 * i, 0.0) && nh_domain_level(&m->domain, m->X + 3 * i) < 0)
      uin = fmax(uin, a);
  }
  CHECK(uin <= 0.02 * umax, "tissue inside the fixed region moves %g m, %g of the largest", uin,
        uin / umax);
  if (getenv("NH_VERBOSE"))
    printf("tie: weight %.9g N, tie forces %.9g N; inside %.3g m, max %.3g m\n", weight[2], tie[2],
           uin, umax);
  free(fe);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&sc);
}

/* Part 4: coarsening never merges the refined region's cells above refine. */
static void test_coarsen_keeps(void) {
  nh_scene *sc;
  nh_sim *sim;
  const char *sets[] = {"tissue.fixed.0.refine=0.005", "tissue.cut_cells=integrated",
                        "time.steps=2", "adapt={max_level: 0, coarsen: {fraction: 0.9}}", NULL};
  open_brain(sets, &sc, &sim);
  const nh_mesh *m = nh_sim_mesh(sim);
  check_refined(sc, m, 1);
  /* four initial cells far from the region, refined once */
  const nh_region *r = &sc->tissue.fixed[0];
  const double h0 = fmax(m->spacing[0], fmax(m->spacing[1], m->spacing[2]));
  int far[4], n_far = 0;
  for (int l = 0; l < m->n_leaves && n_far < 4; l++) {
    int c = m->leaves[l], near = m->level[c] != 0;
    for (int a = 0; a < 8 && !near; a++)
      near = nh_region_distance(r, m->X + 3 * m->cells[8 * c + a]) <= 3 * h0;
    if (!near) far[n_far++] = c;
  }
  CHECK(n_far == 4, "only %d initial cells far from the region", n_far);
  CHECK_OK(nh_sim_refine_cells(sim, far, n_far));
  m = nh_sim_mesh(sim);
  const int before = m->n_leaves;
  for (int step = 0; step < 2; step++) {
    CHECK_OK(nh_sim_step(sim));
    check_refined(sc, nh_sim_mesh(sim), 0);
  }
  m = nh_sim_mesh(sim);
  CHECK(m->n_leaves < before,
        "no family merged (%d leaves before the steps, %d after): "
        "coarsening did not run, the test does not test",
        before, m->n_leaves);
  if (getenv("NH_VERBOSE"))
    printf("coarsen: %d leaves before the steps, %d after\n", before, m->n_leaves);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&sc);
}

int main(void) {
  test_level_brain();
  test_level_box();
  test_tie(NULL, NULL);
  test_tie("tissue.fixed.0.refine=0.005", "tissue.cut_cells=integrated");
  test_tie("tissue.fixed.0.refine=0.005", "tissue.cut_cells=scaled");
  test_coarsen_keeps();
  TEST_END();
}
