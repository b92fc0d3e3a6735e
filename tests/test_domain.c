/* test_domain — the immersed brain domain, sphere/cylinder regions, and a
 * brain under gravity (docs/theory.md, "Immersed domain").
 *  1. Volume: Σ φ_c V_c of the brain's kept cells on a 10x12x8 and a
 *     20x24x16 grid is the shape's volume (nh_domain_volume, by line
 *     integrals independent of the cell sampling) to 2 %; the line integral
 *     itself agrees with a plain lattice count of F < 0 to 1e-3. A box
 *     domain keeps every cell with φ = 1 and its exact volume.
 *  2. Mirror symmetry: lattice cell (i, j, k) is kept iff (g0−1−i, j, k) is,
 *     with a bitwise equal φ (even and odd g0).
 *  3. Ray entry: the point lies on F = 0 to 1e-9 of the box's edge, the
 *     ray is outside just before it, the normal is a 4th-order
 *     finite-difference gradient of F normalised (1e-6), and points against
 *     the ray; rays that miss, or start inside, have no entry. On a box the
 *     entry is the face point with the face's normal.
 *  4. Location: a point inside the shape is located, a bounding-box corner
 *     (a dropped cell) is outside the mesh.
 *  5. Regions on a box grid: the nodes of a sphere and of a slanted cylinder
 *     are those counted directly from the lattice formula; a load over a
 *     sphere sums to its total force, before and after refining every cell
 *     and after refining every eighth leaf; on the brain, the load of a box
 *     region sums to its force too, and that of a box smaller than the
 *     cells' integration samples (a goal point's box) has the box centre as
 *     its first moment, exactly.
 *  6. Refinement on the brain: children's φ measured on the shape keeps the
 *     volume within 2 % and each parent's φ V within 2 % of its cell volume.
 *  7. A static brain (10x12x8, clamped by a cylinder around the brainstem,
 *     vertical gravity) converges with finite displacements that are
 *     mirror symmetric: u_x odd, u_y, u_z even in x − cx, to 1e-10 of max |u|.
 * Silent on success. NH_TEST_VERBOSE=1 prints the measured numbers. */
#include "check.h"
#include "mesh/mesh.h"
#include "sim/sim.h"

#include <string.h>
#include <time.h>

#include "hanging_mesh.h"

static int verbose;
static double brain_volume; /* nh_domain_volume of the brain, once */

static const double brain_center[3] = {0.01, -0.02, 0.03}, brain_size[3] = {0.14, 0.17, 0.10};

static double now(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

static void test_volume(void) {
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  double t0 = now(), ref = brain_volume = nh_domain_volume(&d), t_ref = now() - t0;
  /* An independent check of the reference: count F < 0 at the midpoints of
   * a 200 x 240 x 140 lattice (0.7 mm). */
  const int n[3] = {200, 240, 140};
  long count = 0;
  for (int k = 0; k < n[2]; k++)
    for (int j = 0; j < n[1]; j++)
      for (int i = 0; i < n[0]; i++) {
        double x[3] = {d.min[0] + (i + 0.5) * brain_size[0] / n[0],
                       d.min[1] + (j + 0.5) * brain_size[1] / n[1],
                       d.min[2] + (k + 0.5) * brain_size[2] / n[2]};
        count += nh_domain_level(&d, x) < 0;
      }
  double lattice = count * brain_size[0] * brain_size[1] * brain_size[2] / n[0] / n[1] / n[2];
  CHECK(fabs(lattice - ref) <= 1e-3 * ref, "reference volume %.9g vs lattice count %.9g", ref,
        lattice);
  if (verbose)
    printf("brain volume: line integrals %.9g m^3 (%.3f s), lattice count %.9g (rel diff %.2e)\n",
           ref, t_ref, lattice, fabs(lattice - ref) / ref);
  const int grids[2][3] = {{10, 12, 8}, {20, 24, 16}};
  for (int g = 0; g < 2; g++) {
    nh_mesh *m;
    t0 = now();
    CHECK_OK(nh_mesh_create(&d, grids[g], &m));
    double t_mesh = now() - t0, v = nh_mesh_fill_volume(m);
    CHECK(fabs(v - ref) <= 0.02 * ref, "grid %d: fill volume %.9g vs %.9g (%.2f %%)", g, v, ref,
          100 * (v - ref) / ref);
    int floor_cells = 0;
    for (int c = 0; c < m->n_cells; c++) {
      CHECK(m->fill[c] >= NH_FILL_MIN && m->fill[c] <= 1, "cell %d fill %g", c, m->fill[c]);
      floor_cells += m->fill[c] == NH_FILL_MIN;
    }
    /* every node belongs to a kept cell */
    unsigned char *used = calloc((size_t)m->n_nodes, 1);
    for (int i = 0; i < 8 * m->n_cells; i++) used[m->cells[i]] = 1;
    int unused = 0;
    for (int i = 0; i < m->n_nodes; i++) unused += !used[i];
    CHECK(unused == 0, "%d nodes used by no cell", unused);
    free(used);
    if (verbose)
      printf("grid %dx%dx%d: %d of %d cells kept (%d at the floor), %d nodes, fill volume %.9g "
             "(%+.3f %%), built in %.3f s\n",
             grids[g][0], grids[g][1], grids[g][2], m->n_cells,
             grids[g][0] * grids[g][1] * grids[g][2], floor_cells, m->n_nodes, v,
             100 * (v - ref) / ref, t_mesh);
    nh_mesh_destroy(&m);
  }
  /* A box domain: the box grid itself. */
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {8, 4, 4};
  nh_domain box;
  nh_domain_box(lo, hi, &box);
  nh_mesh *a, *b;
  CHECK_OK(nh_mesh_create(&box, grid, &a));
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &b));
  CHECK(a->n_cells == 128 && a->n_nodes == 225, "box: %d cells, %d nodes", a->n_cells, a->n_nodes);
  CHECK(!memcmp(a->X, b->X, sizeof(double) * 3 * 225) &&
            !memcmp(a->cells, b->cells, sizeof(int) * 8 * 128),
        "box domain mesh differs from the box grid");
  for (int c = 0; c < a->n_cells; c++) CHECK(a->fill[c] == 1.0, "box fill %g", a->fill[c]);
  CHECK_CLOSE(nh_mesh_fill_volume(a), 0.04 * 0.02 * 0.02, 1e-18, "box fill volume");
  CHECK_CLOSE(nh_domain_volume(&box), 0.04 * 0.02 * 0.02, 1e-18, "box volume");
  nh_mesh_destroy(&a);
  nh_mesh_destroy(&b);
}

static void test_symmetry(void) {
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  const int grids[2][3] = {{10, 12, 8}, {11, 12, 8}};
  for (int g = 0; g < 2; g++) {
    const int *G = grids[g];
    nh_mesh *m;
    CHECK_OK(nh_mesh_create(&d, G, &m));
    int bad = 0, kept = 0;
    for (int k = 0; k < G[2]; k++)
      for (int j = 0; j < G[1]; j++)
        for (int i = 0; i < G[0]; i++) {
          int c = m->root[i + G[0] * (j + G[1] * k)];
          int cm = m->root[(G[0] - 1 - i) + G[0] * (j + G[1] * k)];
          kept += c >= 0;
          if ((c < 0) != (cm < 0) || (c >= 0 && m->fill[c] != m->fill[cm])) bad++;
        }
    CHECK(bad == 0, "grid %d: %d cells differ from their mirror image", g, bad);
    CHECK(kept == m->n_cells, "grid %d: root map lists %d cells of %d", g, kept, m->n_cells);
    nh_mesh_destroy(&m);
  }
}

static void unit(double v[3]) {
  double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  for (int k = 0; k < 3; k++) v[k] /= n;
}

static void test_ray_entry(void) {
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  const double L = 0.17, *c = brain_center;
  /* base (relative to the centre), direction: from above (a hemisphere),
   * from the side, from the front, from below towards the brainstem,
   * straight down the fissure (enters at its floor), slanted. */
  const double rays[6][2][3] = {
      {{0.03, 0.01, 0.2}, {0, 0, -1}}, {{-0.2, 0.005, 0.03}, {1, 0, 0}},
      {{0.02, 0.3, 0.04}, {0, -2, 0}}, {{0.0, -0.01275, -0.1}, {0, 0, 1}},
      {{0.0, 0.0, 0.2}, {0, 0, -1}},   {{0.15, 0.1, 0.15}, {-1, -0.8, -1}}};
  for (int r = 0; r < 6; r++) {
    double tau, p[3], n[3],
        base[3] = {c[0] + rays[r][0][0], c[1] + rays[r][0][1], c[2] + rays[r][0][2]};
    int hit = nh_domain_ray_entry(&d, base, rays[r][1], &tau, p, n);
    CHECK(hit, "ray %d: no entry", r);
    if (!hit) continue;
    double f = nh_domain_level(&d, p);
    CHECK(fabs(f) <= 1e-9 * L, "ray %d: F(entry) = %g", r, f);
    double dir[3] = {rays[r][1][0], rays[r][1][1], rays[r][1][2]}, before[3], g[3];
    unit(dir);
    for (int k = 0; k < 3; k++) {
      CHECK_CLOSE(p[k], base[k] + tau * rays[r][1][k], 1e-15, "entry on the ray");
      before[k] = p[k] - 1e-7 * L * dir[k];
    }
    CHECK(nh_domain_level(&d, before) > 0, "ray %d: inside before its entry", r);
    /* independent gradient: 4th-order central differences, step 1e-5 L */
    const double e = 1e-5 * L;
    for (int k = 0; k < 3; k++) {
      double x[4][3];
      for (int s = 0; s < 4; s++) {
        memcpy(x[s], p, sizeof x[s]);
        x[s][k] += (s == 0 ? -2 : s == 1 ? -1 : s == 2 ? 1 : 2) * e;
      }
      g[k] = (nh_domain_level(&d, x[0]) - 8 * nh_domain_level(&d, x[1]) +
              8 * nh_domain_level(&d, x[2]) - nh_domain_level(&d, x[3])) /
             (12 * e);
    }
    unit(g);
    for (int k = 0; k < 3; k++) CHECK_CLOSE(n[k], g[k], 1e-6, "normal vs gradient");
    CHECK(n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2] < 0, "ray %d: normal along the ray", r);
    if (r == 4) /* the fissure's floor: z = cz + 0.3 c, normal +z */
      CHECK_CLOSE(p[2], c[2] + 0.3 * 0.05, 1e-12, "fissure floor");
    if (verbose)
      printf("ray %d: entry [%.6f, %.6f, %.6f], F %.2e, normal [%.4f, %.4f, %.4f]\n", r, p[0], p[1],
             p[2], f, n[0], n[1], n[2]);
  }
  double tau = -1, p[3] = {7, 7, 7}, n[3];
  const double miss_base[3] = {c[0] + 0.2, c[1] + 0.2, c[2]}, miss_dir[3] = {1, 0, 0};
  CHECK(!nh_domain_ray_entry(&d, miss_base, miss_dir, &tau, p, n), "a ray away from it enters");
  const double graze_base[3] = {c[0] - 0.2, c[1], c[2] + 0.0501}, graze_dir[3] = {1, 0, 0};
  CHECK(!nh_domain_ray_entry(&d, graze_base, graze_dir, &tau, p, n), "a ray above it enters");
  const double in_base[3] = {c[0] + 0.03, c[1], c[2] + 0.01}, in_dir[3] = {0, 0, 1};
  CHECK(nh_domain_level(&d, in_base) < 0, "the inner point is not inside");
  CHECK(!nh_domain_ray_entry(&d, in_base, in_dir, &tau, p, n), "a ray from inside enters");
  CHECK(tau == -1 && p[0] == 7, "outputs touched without an entry");
  /* box: face point, face normal */
  nh_domain box;
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  nh_domain_box(lo, hi, &box);
  const double b0[3] = {-0.001, 0.01, 0.01}, bd[3] = {1, 0, 0};
  CHECK(nh_domain_ray_entry(&box, b0, bd, &tau, p, n), "box: no entry");
  CHECK(tau == 0.001 && p[0] == 0 && p[1] == 0.01 && n[0] == -1 && n[1] == 0 && n[2] == 0,
        "box entry tau %g point [%g, %g, %g] normal [%g, %g, %g]", tau, p[0], p[1], p[2], n[0],
        n[1], n[2]);
  CHECK(nh_domain_segment_distance(&box, b0, b0) == 0.001, "box distance");
}

static void test_locate(void) {
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  const int grid[3] = {10, 12, 8};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  const double *c0 = brain_center, inside[3] = {c0[0] + 0.03, c0[1], c0[2] + 0.01};
  int c;
  double xi[3];
  CHECK(nh_mesh_locate(m, inside, &c, xi) == NH_OK, "an inner point is not located");
  const double corner[3] = {d.min[0] + 1e-4, d.min[1] + 1e-4, d.min[2] + 1e-4};
  CHECK(nh_mesh_locate(m, corner, &c, xi) == NH_ERR_INPUT, "a dropped cell's point is located");
  /* restart path: the root map rebuilt from the cells is the same */
  int n = grid[0] * grid[1] * grid[2], *root = malloc(sizeof(int) * (size_t)n);
  memcpy(root, m->root, sizeof(int) * (size_t)n);
  CHECK_OK(nh_mesh_index_roots(m));
  CHECK(!memcmp(root, m->root, sizeof(int) * (size_t)n), "rebuilt root map differs");
  free(root);
  nh_mesh_destroy(&m);
}

/* Sum of the nodal load vector, 3 components. */
static void load_sum(const nh_mesh *m, const nh_region *r, const double F[3], double sum[3]) {
  double *f = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  CHECK_OK(nh_mesh_region_load(m, r, F, f));
  sum[0] = sum[1] = sum[2] = 0.0;
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) sum[k] += f[3 * i + k];
  free(f);
}

static void test_regions(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
  const int grid[3] = {16, 8, 8};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_region sphere = {.kind = NH_REGION_SPHERE, .center = {0.02, 0.01, 0.01}, .radius = 0.0061};
  nh_region cyl = {.kind = NH_REGION_CYLINDER,
                   .start = {0.005, 0.002, 0.004},
                   .end = {0.035, 0.018, 0.015},
                   .radius = 0.004};
  strcpy(sphere.where, "sphere"), strcpy(cyl.where, "cylinder");
  /* direct counts over the lattice points (i h, j h, k h), h = 0.0025 */
  int want_s = 0, want_c = 0;
  for (int k = 0; k <= 8; k++)
    for (int j = 0; j <= 8; j++)
      for (int i = 0; i <= 16; i++) {
        double x = 0.0025 * i, y = 0.0025 * j, z = 0.0025 * k;
        double dx = x - 0.02, dy = y - 0.01, dz = z - 0.01;
        want_s += dx * dx + dy * dy + dz * dz <= 0.0061 * 0.0061;
        double a[3] = {0.03, 0.016, 0.011}, r[3] = {x - 0.005, y - 0.002, z - 0.004};
        double aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
        double t = (r[0] * a[0] + r[1] * a[1] + r[2] * a[2]) / aa, p2 = 0.0;
        for (int q = 0; q < 3; q++) p2 += (r[q] - t * a[q]) * (r[q] - t * a[q]);
        want_c += t >= 0 && t <= 1 && p2 <= 0.004 * 0.004;
      }
  int got_s = nh_mesh_nodes_in_region(m, &sphere, NULL);
  int got_c = nh_mesh_nodes_in_region(m, &cyl, NULL);
  CHECK(got_s == want_s && want_s > 0, "sphere: %d nodes, counted %d", got_s, want_s);
  CHECK(got_c == want_c && want_c > 0, "cylinder: %d nodes, counted %d", got_c, want_c);
  if (verbose) printf("regions: sphere %d nodes, cylinder %d nodes\n", got_s, got_c);
  /* the load of the sphere and of the cylinder sums to the force, before
   * and after refinement (all cells; then every other leaf) */
  const double F[3] = {0.3, -1.2, 2.5};
  nh_template *t = regular_template(2);
  for (int pass = 0; pass < 3; pass++) {
    double s[3];
    for (int q = 0; q < 2; q++) {
      load_sum(m, q ? &cyl : &sphere, F, s);
      for (int k = 0; k < 3; k++)
        CHECK_CLOSE(s[k], F[k], 1e-12 * fabs(F[k]), q ? "cylinder load" : "sphere load");
    }
    int n = 0, *cells = malloc(sizeof(int) * (size_t)m->n_leaves);
    for (int l = 0; l < m->n_leaves; l++)
      if (pass == 0 || l % 8 == 0) cells[n++] = m->leaves[l];
    if (pass < 2) CHECK_OK(nh_mesh_refine(m, t, cells, n, NULL));
    free(cells);
  }
  nh_mesh_destroy(&m);
  /* a box load on the brain acts on the tissue inside the shape */
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  const int bg[3] = {10, 12, 8};
  CHECK_OK(nh_mesh_create(&d, bg, &m));
  nh_region box = {.kind = NH_REGION_BOX, .min = {-1, -1, -1}, .max = {1, 1, 1}};
  strcpy(box.where, "box");
  double s[3];
  load_sum(m, &box, F, s);
  for (int k = 0; k < 3; k++) CHECK_CLOSE(s[k], F[k], 1e-13 * fabs(F[k]), "brain box load");
  nh_region inner = {.kind = NH_REGION_SPHERE, .radius = 0.006};
  for (int k = 0; k < 3; k++)
    inner.center[k] = brain_center[k] + (k == 0 ? 0.03 : k == 2 ? 0.01 : 0);
  strcpy(inner.where, "inner sphere");
  load_sum(m, &inner, F, s); /* in the right hemisphere */
  for (int k = 0; k < 3; k++) CHECK_CLOSE(s[k], F[k], 1e-13 * fabs(F[k]), "brain sphere load");
  /* a box smaller than the 6³ samples' spacing (14 mm / 6) deep in the
   * tissue (a goal point's box): its load sums to F and its first moment
   * Σ f_a X_a is F ⊗ the box centre (the mean position of a uniform
   * density; trilinear shape functions reproduce x), both exactly */
  nh_region small = {.kind = NH_REGION_BOX};
  strcpy(small.where, "small box");
  for (int k = 0; k < 3; k++) {
    double c = inner.center[k] + 0.0013 * (k + 1);
    small.min[k] = c - 0.000875, small.max[k] = c + 0.000875;
  }
  double *f = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  CHECK_OK(nh_mesh_region_load(m, &small, F, f));
  for (int k = 0; k < 3; k++) {
    double sum = 0.0, moment = 0.0, c = 0.5 * (small.min[k] + small.max[k]);
    for (int i = 0; i < m->n_nodes; i++)
      sum += f[3 * i + k], moment += f[3 * i + k] * m->X[3 * i + k];
    CHECK_CLOSE(sum, F[k], 1e-13 * fabs(F[k]), "brain small box load");
    CHECK_CLOSE(moment, F[k] * c, 1e-12 * fabs(F[k] * c), "brain small box load: first moment");
  }
  free(f);
  nh_template_destroy(&t);
  nh_mesh_destroy(&m);
}

static void test_refine(void) {
  nh_domain d;
  nh_domain_brain(brain_center, brain_size, &d);
  const int grid[3] = {10, 12, 8};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  double ref = brain_volume;
  nh_template *t = regular_template(2);
  int n0 = m->n_cells, *cells = malloc(sizeof(int) * (size_t)n0);
  for (int c = 0; c < n0; c++) cells[c] = c;
  double v0 = nh_mesh_fill_volume(m);
  CHECK_OK(nh_mesh_refine(m, t, cells, n0, NULL));
  double v1 = nh_mesh_fill_volume(m);
  CHECK(fabs(v1 - ref) <= 0.02 * ref, "refined fill volume %.9g vs %.9g", v1, ref);
  double cell_volume = (0.14 / 10) * (0.17 / 12) * (0.10 / 8);
  int bad = 0;
  for (int c = 0; c < n0; c++) {
    double sum = 0.0;
    for (int ch = m->first_child[c]; ch < m->first_child[c] + m->n_children[c]; ch++)
      sum += m->fill[ch] * cell_volume / 8;
    /* the floor of the parent or of its children shifts φ V by at most 8 floors */
    if (fabs(sum - m->fill[c] * cell_volume) > 0.02 * cell_volume + 8 * NH_FILL_MIN * cell_volume)
      bad++;
  }
  CHECK(bad == 0, "%d parents whose children's fill disagrees", bad);
  if (verbose)
    printf("refined all cells: fill volume %.9g -> %.9g (%+.3f %%)\n", v0, v1,
           100 * (v1 - ref) / ref);
  free(cells);
  nh_template_destroy(&t);
  nh_mesh_destroy(&m);
}

static void test_gravity(void) {
  const char *src = getenv("NH_SOURCE_DIR");
  char path[1024];
  snprintf(path, sizeof path, "%s/tests/data/brain.yaml", src ? src : ".");
  nh_scene *sc;
  nh_sim *sim;
  CHECK_OK(nh_scene_load(path, 0, NULL, &sc));
  nh_sim_options opt = {.dry_run = 1};
  double t0 = now();
  CHECK_OK(nh_sim_create(sc, &opt, &sim));
  CHECK_OK(nh_sim_step(sim));
  double t_run = now() - t0;
  const nh_mesh *m = nh_sim_mesh(sim);
  const double *u = nh_sim_displacements(sim), cx = m->domain.center[0];
  double umax = 0.0, err = 0.0;
  int finite = 1, unpaired = 0;
  for (int i = 0; i < 3 * m->n_nodes; i++) {
    finite &= isfinite(u[i]);
    umax = fmax(umax, fabs(u[i]));
  }
  CHECK(finite && umax > 0, "displacements not finite or zero (max %g)", umax);
  for (int i = 0; i < m->n_nodes; i++) {
    const double *X = m->X + 3 * i;
    int j = -1;
    for (int q = 0; q < m->n_nodes && j < 0; q++) {
      const double *Y = m->X + 3 * q;
      if (fabs((Y[0] - cx) + (X[0] - cx)) < 1e-12 && fabs(Y[1] - X[1]) < 1e-12 &&
          fabs(Y[2] - X[2]) < 1e-12)
        j = q;
    }
    if (j < 0) {
      unpaired++;
      continue;
    }
    err = fmax(err, fabs(u[3 * i] + u[3 * j]));
    err = fmax(err, fabs(u[3 * i + 1] - u[3 * j + 1]));
    err = fmax(err, fabs(u[3 * i + 2] - u[3 * j + 2]));
  }
  CHECK(unpaired == 0, "%d nodes without a mirror node", unpaired);
  CHECK(err <= 1e-10 * umax, "mirror asymmetry %g of max |u| %g", err, umax);
  if (verbose)
    printf("gravity: %d nodes, max |u| %.6g m, mirror asymmetry %.3g (relative %.2e), %.3f s\n",
           m->n_nodes, umax, err, err / umax, t_run);
  nh_sim_destroy(&sim);
  nh_scene_destroy(&sc);
}

int main(void) {
  verbose = getenv("NH_TEST_VERBOSE") && atoi(getenv("NH_TEST_VERBOSE"));
  test_volume();
  test_symmetry();
  test_ray_entry();
  test_locate();
  test_regions();
  test_refine();
  test_gravity();
  TEST_END();
}
