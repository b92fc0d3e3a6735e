/* test_skull_mortar — the skull's weighted-gap rows (contact/skull.c,
 * tissue.skull.rows: mortar; docs/theory.md §5c, "Weighted-gap rows"):
 * g_a = Σ_q w_q N_a(X_q) g(x_q) / D_a, D_a = Σ_q w_q N_a(X_q), over the
 * cut cells' surface quadrature (tissue.cut_cells: integrated), against
 * closed forms.
 *  1. A flat face: the block [−20, 20]² × [−10, 4.25] mm as a closed STL
 *     surface (single-precision millimetres, exact for these corners; its
 *     signed distance is z − 4.25 mm above the top face's
 *     interior), on 8 × 8 × 6 cells over [−25, 25]² × [−15, 15] mm
 *     (h = 6.25, 6.25, 5 mm: the top face cuts the layer 0 < z < 5 mm at
 *     ℓ = 0.85 of it), skull gap 1 mm, displaced by the linear field
 *     u = (0, 0, αX + βY + γ) (trilinear elements reproduce it). For a node
 *     a of that layer whose tent lies inside the face (|x_a|, |y_a| ≤ 20 mm
 *     − h), N_a on the plane is the bilinear tent T_a(x, y) times ℓ_a, the
 *     node's linear factor in z at the face (0.85 above it, 0.15 below), so
 *       D_a = h_x h_y ℓ_a,   X̄_a = (x_a, y_a, 4.25 mm),
 *       g_a = gap − (α x_a + β y_a + γ),   direction −e_z
 *     (∫ T_a = h_x h_y; T_a is even about the node, so the tent mean of a
 *     linear function is its value there; the reconstructed plane is the
 *     plane, and the rule on each piece integrates T_a x, of degree 3,
 *     exactly). Tolerance 1e-12 of the face's extent / area.
 *  2. An off-centre sphere (R = 3 cm, centre c ≠ 0, g³ cells over its box
 *     widened on the low sides, g = 8, 12), dilated uniformly,
 *     u = ε (X − c), ε = 0.02: every sample (on |X − c| = R) moves to
 *     radius (1 + ε) R, so every row's g_a = gap − ε R; its direction is
 *     the mean of the inward normals −(X_q − c)/R with the row's weights,
 *     so dir = −(X̄_a − c) / |X̄_a − c| with X̄_a the row's mean rest
 *     position. Tolerance: the samples' projection onto the sphere, 1e-9 R.
 *     And the rows share the samples' area by the shape functions'
 *     partition of unity: Σ_a D_a + dropped = the point rows' Σ A (the
 *     same samples, clustered per leaf), to 1e-12.
 *  3. Reaction = load (a pressed block): the sphere of test_skull.c resting
 *     under gravity in its skull (gap 0) held by the weighted-gap rows alone:
 *     Σ λ n / h = −M g at rest, to 1e-6 of the weight; no penetration
 *     beyond 1e-3 of the sag (max over the rows of −g_a).
 * Silent on success; NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "contact/contact.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <stdint.h>
#include <string.h>

/* Binary STL (mm) of the box [lo, hi], outward triangles. */
static int write_box_stl(const char *path, const double lo[3], const double hi[3]) {
  /* the 8 corners, bit k of the index: hi along k */
  double V[8][3];
  for (int v = 0; v < 8; v++)
    for (int k = 0; k < 3; k++) V[v][k] = (v >> k & 1) ? hi[k] : lo[k];
  /* two triangles per face, counter-clockwise seen from outside */
  const int T[12][3] = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                        {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  FILE *f = fopen(path, "wb");
  if (!f) return 1;
  unsigned char header[80] = "box (test_skull_mortar)";
  const uint32_t count = 12;
  fwrite(header, 1, 80, f), fwrite(&count, 4, 1, f);
  for (int t = 0; t < 12; t++) {
    float rec[12] = {0};
    const uint16_t attr = 0;
    for (int v = 0; v < 3; v++)
      for (int k = 0; k < 3; k++) rec[3 + 3 * v + k] = (float)(V[T[t][v]][k] * 1e3);
    fwrite(rec, 4, 12, f), fwrite(&attr, 2, 1, f);
  }
  return fclose(f) != 0;
}

static void flat_face(const char *dir, int verbose) {
  const double blo[3] = {-0.020, -0.020, -0.010}, bhi[3] = {0.020, 0.020, 0.00425};
  const double lo[3] = {-0.025, -0.025, -0.015}, hi[3] = {0.025, 0.025, 0.015};
  const int grid[3] = {8, 8, 6};
  const double gap = 0.001, alpha = 0.004, beta = -0.003, gamma = 2e-4;
  double h[3];
  for (int k = 0; k < 3; k++) h[k] = (hi[k] - lo[k]) / grid[k];
  char stl[1024];
  snprintf(stl, sizeof stl, "%s/skull_mortar_box.stl", dir);
  CHECK(write_box_stl(stl, blo, bhi) == 0, "cannot write %s", stl);
  nh_domain d;
  memset(&d, 0, sizeof d);
  d.kind = NH_DOMAIN_SURFACE;
  CHECK_OK(nh_surface_read(stl, 1e-3, 0, NULL, &d.surface));
  for (int k = 0; k < 3; k++) {
    d.min[k] = d.surface->min[k], d.max[k] = d.surface->max[k];
    d.center[k] = 0.5 * (d.min[k] + d.max[k]), d.half[k] = 0.5 * (d.max[k] - d.min[k]);
  }
  d.cap = 0.01;
  d.cut_cells = NH_CUT_CELLS_INTEGRATED;
  nh_mesh *m = NULL;
  nh_skull *s = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  m->domain = d;
  CHECK_OK(nh_skull_create(&d, gap, &s));
  nh_skull_set_rows(s, NH_SKULL_ROWS_MORTAR);
  CHECK_OK(nh_skull_build(s, m));
  double *u = calloc(3 * (size_t)m->n_nodes, sizeof(double));
  for (int i = 0; i < m->n_nodes; i++)
    u[3 * i + 2] = alpha * m->X[3 * i] + beta * m->X[3 * i + 1] + gamma;
  const int n = nh_skull_points(s);
  nh_skull_row_info *r = calloc((size_t)n, sizeof *r);
  CHECK(nh_skull_weighted_gaps(s, m, u, r, NULL) == n && n > 0, "%d weighted-gap rows", n);
  int checked = 0;
  const double tol = 1e-12 * (bhi[0] - blo[0]);
  for (int i = 0; i < n; i++) {
    const double *X = r[i].X;
    if (fabs(X[0]) > bhi[0] - h[0] + 1e-9 || fabs(X[1]) > bhi[1] - h[1] + 1e-9) continue;
    if (fabs(X[2] - bhi[2]) > 1e-9) continue; /* the side faces' rows */
    /* the node: X̄ on the lattice of node coordinates */
    double node[2];
    for (int k = 0; k < 2; k++) {
      node[k] = lo[k] + h[k] * round((X[k] - lo[k]) / h[k]);
      CHECK(fabs(X[k] - node[k]) <= tol, "row %d: mean position %.15g off the node %.15g (axis %d)",
            i, X[k], node[k], k);
    }
    CHECK(fabs(X[2] - bhi[2]) <= tol, "row %d: mean z %.15g, face %.15g", i, X[2], bhi[2]);
    const double layer = floor((bhi[2] - lo[2]) / h[2]), t = (bhi[2] - lo[2]) / h[2] - layer;
    /* the row's node is the layer's upper (ℓ = t) or lower (ℓ = 1 − t) one */
    const double Da = h[0] * h[1] * t, Db = h[0] * h[1] * (1.0 - t);
    const double area_tol = 1e-12 * h[0] * h[1];
    CHECK(fabs(r[i].area - Da) <= area_tol || fabs(r[i].area - Db) <= area_tol,
          "row %d: D_a %.15g, expected %.15g or %.15g", i, r[i].area, Da, Db);
    const double g = gap - (alpha * node[0] + beta * node[1] + gamma);
    CHECK(fabs(r[i].g - g) <= tol, "row %d at (%g, %g) mm: g_a %.15g, expected %.15g", i,
          1e3 * node[0], 1e3 * node[1], r[i].g, g);
    CHECK(fabs(r[i].dir[0]) <= 1e-12 && fabs(r[i].dir[1]) <= 1e-12 &&
              fabs(r[i].dir[2] + 1.0) <= 1e-12,
          "row %d: direction %g %g %g, expected -e_z", i, r[i].dir[0], r[i].dir[1], r[i].dir[2]);
    checked++;
  }
  /* interior nodes of the face: (2 · 20 mm / 6.25 mm − 1)² = 25 per node layer, two layers */
  CHECK(checked == 2 * 25, "%d rows checked on the flat face, expected 50", checked);
  if (verbose) printf("flat face: %d rows, %d inside the face checked\n", n, checked);
  free(r), free(u);
  nh_skull_destroy(&s);
  nh_mesh_destroy(&m); /* releases the surface (m->domain) */
  remove(stl);
}

static void sphere(int verbose) {
  const double c[3] = {0.0013, -0.0021, 0.0007}, R = 0.03, widen[3] = {0.21, 0.37, 0.53};
  const double gap = 0.001, eps = 0.02;
  const int grids[2] = {8, 12};
  for (int gi = 0; gi < 2; gi++) {
    nh_domain d;
    nh_domain_sphere(c, R, &d);
    d.cut_cells = NH_CUT_CELLS_INTEGRATED;
    double lo[3], hi[3];
    for (int k = 0; k < 3; k++) lo[k] = d.min[k] - widen[k] * R, hi[k] = d.max[k];
    const int g = grids[gi], grid[3] = {g, g, g};
    nh_mesh *m = NULL;
    nh_skull *s = NULL, *pts = NULL;
    CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
    m->domain = d;
    CHECK_OK(nh_skull_create(&d, gap, &s));
    nh_skull_set_rows(s, NH_SKULL_ROWS_MORTAR);
    CHECK_OK(nh_skull_build(s, m));
    CHECK_OK(nh_skull_create(&d, gap, &pts));
    CHECK_OK(nh_skull_build(pts, m));
    double *u = calloc(3 * (size_t)m->n_nodes, sizeof(double));
    for (int i = 0; i < 3 * m->n_nodes; i++) u[i] = eps * (m->X[i] - c[i % 3]);
    const int n = nh_skull_points(s);
    nh_skull_row_info *r = calloc((size_t)n, sizeof *r);
    double dropped = -1.0, worst_g = 0.0, worst_dir = 0.0;
    CHECK(nh_skull_weighted_gaps(s, m, u, r, &dropped) == n && n > 0, "%d weighted-gap rows", n);
    for (int i = 0; i < n; i++) {
      worst_g = fmax(worst_g, fabs(r[i].g - (gap - eps * R)));
      double e[3], len = 0.0;
      for (int k = 0; k < 3; k++) e[k] = r[i].X[k] - c[k], len += e[k] * e[k];
      len = sqrt(len);
      for (int k = 0; k < 3; k++) worst_dir = fmax(worst_dir, fabs(r[i].dir[k] + e[k] / len));
    }
    CHECK(worst_g <= 1e-9 * R, "%d³: weighted gap off gap − εR by %.3g m", g, worst_g);
    CHECK(worst_dir <= 1e-9, "%d³: direction off −(X̄ − c)/|X̄ − c| by %.3g", g, worst_dir);
    const double a_rows = nh_skull_area(s) + dropped, a_pts = nh_skull_area(pts);
    CHECK(fabs(a_rows - a_pts) <= 1e-12 * a_pts, "%d³: rows' area %.15g + dropped, points' %.15g",
          g, a_rows, a_pts);
    if (verbose)
      printf("sphere %2d³: %d rows (%d points), |g − (gap − εR)| ≤ %.2e m, direction ≤ %.2e, "
             "area %.9g (+ %.3g dropped) vs points %.9g, 4πR² %.9g\n",
             g, n, nh_skull_points(pts), worst_g, worst_dir, nh_skull_area(s), dropped, a_pts,
             4 * M_PI * R * R);
    free(r), free(u);
    nh_skull_destroy(&s), nh_skull_destroy(&pts);
    nh_mesh_destroy(&m);
  }
}

/* 3. The sphere of test_skull.c resting in its skull (gap 0) under gravity:
 * contact force = −weight, no penetration. */
static void resting(int verbose) {
  const double R = 0.05, c[3] = {0, 0, 0}, grav = 9.81, h = 0.05;
  nh_domain d;
  nh_domain_sphere(c, R, &d);
  const int grid[3] = {6, 6, 6};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  nh_material mat = {60e3, 0.45, 1000, NH_FORMULATION_BBAR};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  nh_system *sys;
  CHECK_OK(nh_system_create(t, NULL, NULL, &sys));
  nh_skull *sk;
  CHECK_OK(nh_skull_create(&d, 0.0, &sk));
  nh_skull_set_rows(sk, NH_SKULL_ROWS_MORTAR);
  CHECK_OK(nh_skull_build(sk, m));
  const int n = 3 * m->n_nodes;
  double *u = calloc((size_t)n, sizeof(double)), *v = calloc((size_t)n, sizeof(double));
  double *f = calloc((size_t)n, sizeof(double)), weight = 0.0, sag = 0.0;
  for (int i = 0; i < m->n_nodes; i++)
    f[3 * i + 2] = -t->mass[i] * grav, weight += t->mass[i] * grav;
  nh_integrator in = {
      .dt = h, .alpha = 20.0, .tolerance = 1e-8, .max_iterations = 30, .threads = 0};
  nh_rows rows = {0};
  for (int s = 0; s < 40; s++) {
    nh_rows_clear(&rows);
    CHECK_OK(nh_skull_rows(sk, m, u, v, h, &rows));
    nh_coupled_stats st;
    CHECK_OK(nh_step_coupled(sys, &in, f, u, v, 0, NULL, &rows, 1e-10, 1e-6, 5000, &st));
    nh_skull_end_step(sk, &rows, h);
  }
  for (int i = 0; i < m->n_nodes; i++)
    sag = fmax(
        sag, sqrt(u[3 * i] * u[3 * i] + u[3 * i + 1] * u[3 * i + 1] + u[3 * i + 2] * u[3 * i + 2]));
  double F[3];
  int active = 0;
  nh_skull_force(sk, F, &active);
  const double pen = nh_skull_penetration(sk, m, u);
  CHECK(fabs(F[0]) <= 1e-6 * weight && fabs(F[1]) <= 1e-6 * weight &&
            fabs(F[2] - weight) <= 1e-6 * weight,
        "resting sphere: contact force %.9g %.9g %.9g N, weight %.9g N", F[0], F[1], F[2], weight);
  CHECK(pen <= 1e-3 * sag, "resting sphere: penetration %.3g m > 1e-3 of the sag %.3g m", pen, sag);
  if (verbose)
    printf("resting sphere 6³: %d rows pushing, force %.9g %.9g %.9g N, weight %.9g N, "
           "penetration %.2e m, sag %.3e m\n",
           active, F[0], F[1], F[2], weight, pen, sag);
  nh_rows_free(&rows);
  free(u), free(v), free(f);
  nh_skull_destroy(&sk);
  nh_system_destroy(&sys);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(int argc, char **argv) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  flat_face(argc > 1 ? argv[1] : ".", verbose);
  sphere(verbose);
  resting(verbose);
  TEST_END();
}
