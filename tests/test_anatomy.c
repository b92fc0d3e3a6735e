/* test_anatomy — closed surfaces (STL) and NIfTI label images as domains
 * (docs/anatomy.md).
 *  1. An ellipsoid (semi-axes 30, 20, 15 mm, poles on the x axis) as a
 *     binary STL in millimetres, 96 x 192 latitude-longitude facets: the
 *     enclosed volume by the divergence theorem is the inscribed
 *     polyhedron's, below 4/3 π abc by at most 3 (π/96)² / 4 · (its maximal
 *     sagitta over the smallest semi-axis, a bound on the relative gap)
 *     (0.1 %); Σ φ V of the mesh over it on a 24 x 16 x 12 grid (2.5 mm
 *     cells) is within 1 % of 4/3 π abc.
 *  2. Inside test against the analytic inside on 10⁵ random points of the
 *     box grown by 10 %: no disagreement farther than one grid cell from
 *     the ellipsoid (and in fact none outside the facets' sagitta band,
 *     |q − 1| ≤ 1e-3, q the ellipsoid's radial coordinate). Rays through
 *     vertices: the centre (its ray runs through the pole where 192
 *     triangles meet), points with the (y, z) of facet corners, and a
 *     vertex's own (y, z) just inside and outside along x are classified
 *     as the analytic inside.
 *     The level is the signed distance capped at `cap`: on 2000 random
 *     points of the grown box, |nh_surface_level| equals min(cap, the
 *     minimum over all 36480 triangles of the distance) to 1e-12 m, that
 *     distance computed here another way (the foot on the triangle's plane
 *     if its barycentric weights are ≥ 0, else the nearest of its edges), so
 *     the query's index and its pruning never miss the nearest triangle.
 *  3. Ray entry from outside along −x hits the pole at x = a with the
 *     normal (1, 0, 0) (the cap's facets average to it only at the pole:
 *     checked to the facet angle π/96); a ray that misses has no entry.
 *  4. Reader errors name the file and line: a missing triangle (open
 *     surface), an ASCII keyword out of place, a non-number, a truncated
 *     binary file; an ASCII tetrahedron reads back with its volume 1/6.
 *  5. NIfTI: nibabel's anatomical.nii (Debian's python3-nibabel) reads as
 *     33 x 41 x 25 voxels of 2 mm with axes towards L, A, S from the sform,
 *     voxel (0, 0, 0) at (32, −40, −16) mm and (i, j, k) at
 *     (32 − 2i, −40 + 2j, −16 + 2k) mm (its header's sform); labels of an
 *     intensity image with fractional values are refused; a missing file
 *     and a non-NIfTI file are refused with the file's name.
 *  6. The readers' contract (docs/reliability.md, "File readers"):
 *     - the inside volume by rays (nh_surface_inside_volume) of a unit cube
 *       is 1 to 1e-9 on any ray grid (the inside length is 1 on every ray
 *       through the square, 0 elsewhere: the midpoint rule is exact; the
 *       sum of n² terms rounds by ≤ n² ε ≈ 2e-10 at n = 1024), and
 *       that of the ellipsoid is within 0.2 % of its divergence-theorem
 *       volume on a 1024² grid (the rule's error is that of the silhouette
 *       cells, O(h) relative: 3 × 1/1024 ≈ 0.3 % at most, and of mixed sign);
 *       a 2 x 2 x 100 mm rod along the (y, z) diagonal (400 mm³ exactly)
 *       is read and its 256² rays are within 0.5 % (half the refusal
 *       bound: the silhouette runs at 45°, where unshifted cell centres
 *       err systematically);
 *     - limits given as a parameter: the ellipsoid's 36672-triangle binary
 *       file under max_triangles 1000 and under max_file_bytes 1000, the
 *       ASCII tetrahedron under max_triangles 3, nibabel's image under
 *       max_voxels 1000, each refused naming the limit and its value;
 *     - a stream: an ASCII STL from a FIFO that never ends ("solid" then
 *       spaces, written by a child process) is refused at max_file_bytes =
 *       4096; /dev/zero read as a binary STL announces 0 triangles and is
 *       refused as longer than 84 bytes;
 *     - the cell size: the ellipsoid (largest extent 60 mm) is refused for a
 *       cell of 0.1 m and accepted for 0.05 m.
 * Silent on success; NH_TEST_VERBOSE=1 prints the measured numbers. */
#include "check.h"
#include "mesh/mesh.h"

#include <signal.h>
#include <stdint.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

static int verbose;
static const double ax[3] = {0.030, 0.020, 0.015};
enum { NT = 96, NP = 192 };

static void put_float(unsigned char *b, float f) {
  uint32_t u;
  memcpy(&u, &f, sizeof u);
  for (int k = 0; k < 4; k++) b[k] = (unsigned char)(u >> (8 * k));
}

/* Point of the ellipsoid at polar index i (0: pole +x) and azimuth j, mm. */
static void ellipsoid_point(int i, int j, float p[3]) {
  double th = M_PI * i / NT, ph = 2 * M_PI * (j % NP) / NP;
  p[0] = (float)(1e3 * ax[0] * cos(th));
  p[1] = (float)(i == 0 || i == NT ? 0.0 : 1e3 * ax[1] * sin(th) * cos(ph));
  p[2] = (float)(i == 0 || i == NT ? 0.0 : 1e3 * ax[2] * sin(th) * sin(ph));
}

/* Binary STL of the ellipsoid, skipping triangle `skip` (-1: none). */
static int write_ellipsoid(const char *path, int skip, size_t truncate) {
  int ntri = 2 * NP * (NT - 1), count = 0;
  size_t size = 84 + 50 * (size_t)ntri;
  unsigned char *b = calloc(size, 1);
  memcpy(b, "binary STL of an ellipsoid (test_anatomy)", 41);
  int written = 0;
  for (int i = 0; i < NT; i++)
    for (int j = 0; j < NP; j++) {
      float q[4][3];
      ellipsoid_point(i, j, q[0]), ellipsoid_point(i + 1, j, q[1]);
      ellipsoid_point(i + 1, j + 1, q[2]), ellipsoid_point(i, j + 1, q[3]);
      int tris[2][3] = {{0, 1, 2}, {0, 2, 3}};
      for (int t = 0; t < 2; t++) {
        if ((i == 0 && t == 1) || (i == NT - 1 && t == 0)) continue; /* degenerate at poles */
        if (count++ == skip) continue;
        unsigned char *rec = b + 84 + 50 * (size_t)written++;
        for (int c = 0; c < 3; c++)
          for (int k = 0; k < 3; k++) put_float(rec + 12 + 12 * c + 4 * k, q[tris[t][c]][k]);
      }
    }
  size = 84 + 50 * (size_t)written;
  for (int k = 0; k < 4; k++) b[80 + k] = (unsigned char)((uint32_t)written >> (8 * k));
  if (truncate) size -= truncate;
  FILE *f = fopen(path, "wb");
  if (!f) return 1;
  fwrite(b, 1, size, f);
  fclose(f);
  free(b);
  return 0;
}

static double q_of(const double x[3]) {
  return sqrt(pow(x[0] / ax[0], 2) + pow(x[1] / ax[1], 2) + pow(x[2] / ax[2], 2));
}

/* Distance from p to the segment [a, b]. */
static double segment_distance(const double a[3], const double b[3], const double p[3]) {
  double ab[3], ap[3], l2 = 0.0, t = 0.0;
  for (int k = 0; k < 3; k++) ab[k] = b[k] - a[k], ap[k] = p[k] - a[k], l2 += ab[k] * ab[k];
  for (int k = 0; k < 3; k++) t += ab[k] * ap[k];
  t = fmin(1.0, fmax(0.0, t / l2));
  double d2 = 0.0;
  for (int k = 0; k < 3; k++) d2 += (ap[k] - t * ab[k]) * (ap[k] - t * ab[k]);
  return sqrt(d2);
}

/* Distance from p to triangle v (9 doubles): the foot on its plane if it
 * lies inside (barycentric weights by areas), else the nearest edge. */
static double triangle_distance(const double *v, const double p[3]) {
  double e1[3], e2[3], n[3], w[3];
  for (int k = 0; k < 3; k++) e1[k] = v[3 + k] - v[k], e2[k] = v[6 + k] - v[k];
  n[0] = e1[1] * e2[2] - e1[2] * e2[1], n[1] = e1[2] * e2[0] - e1[0] * e2[2];
  n[2] = e1[0] * e2[1] - e1[1] * e2[0];
  const double nn = n[0] * n[0] + n[1] * n[1] + n[2] * n[2];
  double h = 0.0, f[3];
  for (int k = 0; k < 3; k++) h += (p[k] - v[k]) * n[k];
  for (int k = 0; k < 3; k++) f[k] = p[k] - h / nn * n[k];
  for (int a = 0; a < 3; a++) { /* the sub-triangle opposite corner a */
    const double *b = v + 3 * ((a + 1) % 3), *c = v + 3 * ((a + 2) % 3);
    double u[3], t[3];
    for (int k = 0; k < 3; k++) u[k] = b[k] - f[k], t[k] = c[k] - f[k];
    w[a] = (u[1] * t[2] - u[2] * t[1]) * n[0] + (u[2] * t[0] - u[0] * t[2]) * n[1] +
           (u[0] * t[1] - u[1] * t[0]) * n[2];
  }
  if (w[0] >= 0 && w[1] >= 0 && w[2] >= 0) return fabs(h) / sqrt(nn);
  return fmin(segment_distance(v, v + 3, p),
              fmin(segment_distance(v + 3, v + 6, p), segment_distance(v + 6, v, p)));
}

static void test_ellipsoid(const char *dir) {
  char path[1024];
  snprintf(path, sizeof path, "%s/ellipsoid.stl", dir);
  CHECK(write_ellipsoid(path, -1, 0) == 0, "cannot write %s", path);
  nh_surface *s;
  CHECK_OK(nh_surface_read(path, 1e-3, 0, NULL, &s));
  const double exact = 4.0 / 3.0 * M_PI * ax[0] * ax[1] * ax[2];
  double v = nh_surface_volume(s);
  if (verbose)
    printf("ellipsoid: %d triangles, polyhedron volume %.6e vs %.6e (%.3g)\n", s->n_tri, v, exact,
           v / exact - 1);
  CHECK(v < exact && v > exact * (1 - 1e-3), "polyhedron volume %.6e vs ellipsoid %.6e", v, exact);

  /* The mesh over it. */
  nh_domain d;
  memset(&d, 0, sizeof d);
  d.kind = NH_DOMAIN_SURFACE;
  d.surface = s;
  for (int k = 0; k < 3; k++) {
    d.min[k] = s->min[k], d.max[k] = s->max[k];
    d.center[k] = 0.5 * (d.min[k] + d.max[k]), d.half[k] = 0.5 * (d.max[k] - d.min[k]);
  }
  d.cap = 0.25 * d.half[0];
  const int grid[3] = {24, 16, 12};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  double fv = nh_mesh_fill_volume(m);
  if (verbose)
    printf("ellipsoid mesh 24x16x12: %d cells, sum phi V %.6e (%.3g)\n", m->n_leaves, fv,
           fv / exact - 1);
  CHECK(fabs(fv / exact - 1) < 0.01, "sum phi V %.6e vs %.6e: %.3g > 1 %%", fv, exact,
        fv / exact - 1);
  double h = fmax(m->spacing[0], fmax(m->spacing[1], m->spacing[2]));
  nh_mesh_destroy(&m);

  /* Random points. */
  srand(12345);
  int disagree = 0, far = 0;
  double worst = 0.0;
  for (int p = 0; p < 100000; p++) {
    double x[3];
    for (int k = 0; k < 3; k++) x[k] = 1.1 * ax[k] * (2.0 * rand() / RAND_MAX - 1.0);
    double q = q_of(x);
    int analytic = q < 1.0, got = nh_surface_inside(s, x);
    if (analytic == got) continue;
    disagree++;
    worst = fmax(worst, fabs(q - 1));
    /* q − 1 times the smallest semi-axis bounds the distance from above. */
    if (fabs(q - 1) * ax[0] > h) far++;
  }
  if (verbose) printf("inside test: %d of 1e5 disagree, worst |q - 1| %.3g\n", disagree, worst);
  CHECK(far == 0, "%d points farther than a cell (%g m) from the surface are misclassified", far,
        h);
  CHECK(worst <= 1e-3, "a misclassified point at |q - 1| = %.3g > 1e-3 (the facets' band)", worst);

  /* The level against the distance to every triangle. */
  const double cap = 0.25 * d.half[0];
  double level_err = 0.0;
  for (int p = 0; p < 2000; p++) {
    double x[3], dist = INFINITY;
    for (int k = 0; k < 3; k++) x[k] = 1.1 * ax[k] * (2.0 * rand() / RAND_MAX - 1.0);
    for (int t = 0; t < s->n_tri; t++) dist = fmin(dist, triangle_distance(s->v + 9 * t, x));
    level_err = fmax(level_err, fabs(fabs(nh_surface_level(s, x, cap)) - fmin(dist, cap)));
  }
  if (verbose) printf("level against every triangle's distance: max error %.3g m\n", level_err);
  CHECK(level_err <= 1e-12, "|level| differs from the distance to the nearest triangle by %.3g m",
        level_err);

  /* Rays through vertices and edges. */
  const double centre[3] = {0, 0, 0};
  CHECK(nh_surface_inside(s, centre), "the centre (its ray runs through the pole) is not inside");
  int bad = 0;
  for (int i = 1; i < NT; i += 7)
    for (int j = 0; j < NP; j += 11) {
      float p[3];
      ellipsoid_point(i, j, p);
      for (int side = -1; side <= 1; side += 2) {
        /* Same (y, z) as the vertex: inside just within the surface along x,
         * outside just beyond it (the ray passes exactly through vertices). */
        double x[3] = {p[0] * 1e-3 * (side < 0 ? 0.9 : 1.1) + (p[0] == 0 ? side * 1e-4 : 0),
                       p[1] * 1e-3, p[2] * 1e-3};
        if (fabs(p[0]) < 1e-3) continue; /* near the equator the x offset is not meaningful */
        int want = side < 0, got = nh_surface_inside(s, x);
        bad += want != got;
      }
    }
  CHECK(bad == 0, "%d points on rays through vertices misclassified", bad);

  /* Ray entry at the pole. */
  double base[3] = {0.05, 0, 0}, minus_x[3] = {-1, 0, 0}, tau, X[3], n[3];
  CHECK(nh_surface_ray_entry(s, base, minus_x, &tau, X, n) == 1, "no entry along -x");
  CHECK_CLOSE(X[0], ax[0], 1e-9, "entry x at the pole");
  CHECK_CLOSE(n[0], 1.0, 1.0 - cos(M_PI / NT) + 1e-12, "normal x at the pole");
  double dir2[3] = {0, 0, 1}, base2[3] = {0.05, 0, -0.05};
  CHECK(nh_surface_ray_entry(s, base2, dir2, &tau, X, n) == 0, "a ray beside it hits");
  nh_surface_release(&s);

  /* Errors. */
  CHECK(write_ellipsoid(path, 1234, 0) == 0, "cannot write");
  CHECK(nh_surface_read(path, 1e-3, 0, NULL, &s) == NH_ERR_INPUT &&
            strstr(nh_error_message(), path) && strstr(nh_error_message(), "not a closed surface"),
        "open surface: %s", nh_error_message());
  CHECK(write_ellipsoid(path, -1, 30) == 0, "cannot write");
  CHECK(nh_surface_read(path, 1e-3, 0, NULL, &s) == NH_ERR_INPUT &&
            strstr(nh_error_message(), path) && strstr(nh_error_message(), "not 84 + 50"),
        "truncated: %s", nh_error_message());
  remove(path);
}

static void write_text(const char *path, const char *text) {
  FILE *f = fopen(path, "w");
  fputs(text, f);
  fclose(f);
}

static void test_ascii(const char *dir) {
  char path[1024], want[1100];
  snprintf(path, sizeof path, "%s/tet.stl", dir);
  static const char *const facets[4] = {
      "0 0 0\n vertex 0 1 0\n vertex 1 0 0", "0 0 0\n vertex 1 0 0\n vertex 0 0 1",
      "0 0 0\n vertex 0 0 1\n vertex 0 1 0", "1 0 0\n vertex 0 1 0\n vertex 0 0 1"};
  char text[2048] = "solid tet\n";
  for (int f = 0; f < 4; f++) {
    size_t len = strlen(text);
    snprintf(text + len, sizeof text - len,
             "facet normal 0 0 0\n outer loop\n vertex %s\n endloop\nendfacet\n", facets[f]);
  }
  strcat(text, "endsolid tet\n");
  write_text(path, text);
  nh_surface *s;
  CHECK_OK(nh_surface_read(path, 1.0, 0, NULL, &s));
  CHECK_CLOSE(nh_surface_volume(s), 1.0 / 6.0, 1e-15, "tetrahedron volume");
  double in[3] = {0.1, 0.1, 0.1}, out[3] = {0.5, 0.5, 0.5};
  CHECK(nh_surface_inside(s, in) && !nh_surface_inside(s, out), "tetrahedron inside test");
  nh_surface_release(&s);

  /* Line 4 ("outer loop") misspelt; line 5 holds a non-number. */
  char bad[2048];
  snprintf(bad, sizeof bad, "%s", text);
  char *p = strstr(bad, "outer loop");
  memcpy(p, "outer lop ", 10);
  write_text(path, bad);
  snprintf(want, sizeof want, "%s:3: expected 'loop', got 'lop'", path);
  CHECK(nh_surface_read(path, 1.0, 0, NULL, &s) == NH_ERR_INPUT && strstr(nh_error_message(), want),
        "misspelt keyword: %s", nh_error_message());
  snprintf(bad, sizeof bad, "%s", text);
  p = strstr(bad, "vertex 0 1 0");
  memcpy(p, "vertex 0 x 0", 12);
  write_text(path, bad);
  snprintf(want, sizeof want, "%s:5: vertex: expected a finite number, got 'x'", path);
  CHECK(nh_surface_read(path, 1.0, 0, NULL, &s) == NH_ERR_INPUT && strstr(nh_error_message(), want),
        "non-number: %s", nh_error_message());
  remove(path);
}

static void test_nifti(const char *dir) {
  const char *file = "/usr/lib/python3/dist-packages/nibabel/tests/data/anatomical.nii";
  nh_image *im;
  CHECK_OK(nh_image_read(file, 0, NULL, &im));
  CHECK(im->n[0] == 33 && im->n[1] == 41 && im->n[2] == 25, "size %d %d %d", im->n[0], im->n[1],
        im->n[2]);
  CHECK(!strcmp(im->orientation, "LAS"), "orientation %s", im->orientation);
  CHECK(!strcmp(im->xform, "sform"), "transform %s", im->xform);
  for (int k = 0; k < 3; k++) CHECK_CLOSE(im->spacing[k], 0.002, 1e-15, "spacing");
  double ijk[3] = {3, 5, 7}, x[3], back[3];
  nh_image_to_world(im, ijk, x);
  CHECK_CLOSE(x[0], 0.032 - 0.002 * 3, 1e-15, "world x of voxel (3, 5, 7)");
  CHECK_CLOSE(x[1], -0.040 + 0.002 * 5, 1e-15, "world y");
  CHECK_CLOSE(x[2], -0.016 + 0.002 * 7, 1e-15, "world z");
  nh_image_to_voxel(im, x, back);
  for (int k = 0; k < 3; k++) CHECK_CLOSE(back[k], ijk[k], 1e-12, "voxel back");
  nh_image_release(&im);
  /* The T1 intensities are integers (int16): read as labels they are
   * accepted; the image is then not a segmentation but reads. */
  CHECK_OK(nh_image_read(file, 1, NULL, &im));
  CHECK(im->label[0] != 0 || im->label[1] != 0, "the data were read");
  nh_image_release(&im);

  char path[1024];
  snprintf(path, sizeof path, "%s/missing.nii.gz", dir);
  CHECK(nh_image_read(path, 1, NULL, &im) == NH_ERR_INPUT && strstr(nh_error_message(), path),
        "missing: %s", nh_error_message());
  snprintf(path, sizeof path, "%s/not.nii", dir);
  write_text(path, "this is not a NIfTI file, but it is long enough to hold a header? no.\n");
  CHECK(nh_image_read(path, 1, NULL, &im) == NH_ERR_INPUT && strstr(nh_error_message(), path) &&
            strstr(nh_error_message(), "not a NIfTI"),
        "not NIfTI: %s", nh_error_message());
  remove(path);
}

/* True if the last error message holds `want`. */
static int says(const char *want) {
  return strstr(nh_error_message(), want) != NULL;
}

/* ASCII STL of the parallelepiped corner + b0 e[0] + b1 e[1] + b2 e[2]
 * (b in {0, 1}, e right-handed: the faces point outwards). */
static void write_box(const char *path, const double corner[3], const double e[3][3]) {
  FILE *f = fopen(path, "w");
  static const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                  {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  fputs("solid box\n", f);
  for (int q = 0; q < 6; q++)
    for (int t = 0; t < 2; t++) {
      int c[3] = {quads[q][0], quads[q][t + 1], quads[q][t + 2]};
      fputs("facet normal 0 0 0\n outer loop\n", f);
      for (int k = 0; k < 3; k++) {
        double x[3];
        for (int a = 0; a < 3; a++)
          x[a] = corner[a] + (c[k] & 1) * e[0][a] + (c[k] >> 1 & 1) * e[1][a] +
                 (c[k] >> 2 & 1) * e[2][a];
        fprintf(f, "  vertex %.17g %.17g %.17g\n", x[0], x[1], x[2]);
      }
      fputs(" endloop\nendfacet\n", f);
    }
  fputs("endsolid box\n", f);
  fclose(f);
}

static void write_cube(const char *path) {
  static const double zero[3], unit[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  write_box(path, zero, unit);
}

static void test_contract(const char *dir) {
  char path[1024];
  nh_surface *s;
  /* Inside volume by rays. */
  snprintf(path, sizeof path, "%s/cube.stl", dir);
  write_cube(path);
  CHECK_OK(nh_surface_read(path, 1.0, 0, NULL, &s));
  for (int n = 16; n <= 1024; n *= 4)
    CHECK_CLOSE(nh_surface_inside_volume(s, n, n + 3), 1.0, 1e-9, "unit cube by rays");
  nh_surface_release(&s);
  snprintf(path, sizeof path, "%s/ellipsoid.stl", dir);
  CHECK(write_ellipsoid(path, -1, 0) == 0, "cannot write %s", path);
  CHECK_OK(nh_surface_read(path, 1e-3, 0, NULL, &s));
  double div = nh_surface_volume(s), rays = nh_surface_inside_volume(s, 1024, 1024);
  if (verbose)
    printf("ellipsoid: inside volume by rays %.6e vs %.6e (%.3g)\n", rays, div, rays / div - 1);
  CHECK_CLOSE(rays / div, 1.0, 2e-3, "ellipsoid: inside volume by rays vs divergence");
  nh_surface_release(&s);
  /* A straight rod across the ray grid's diagonal: 2 x 2 x 100 mm along
   * (0, 1, 1)/sqrt 2, 400 mm^3. Its silhouette edges run at 45 degrees, along
   * a grid of cell centres; the shifted columns must keep the reader's
   * 256^2 rays within half the 1 % refusal bound of the exact volume. */
  char rod_path[1024];
  snprintf(rod_path, sizeof rod_path, "%s/rod.stl", dir);
  const double r2 = sqrt(2.0), corner[3] = {0, 0, 0};
  const double rod[3][3] = {{2, 0, 0}, {0, r2, -r2}, {0, 50 * r2, 50 * r2}};
  write_box(rod_path, corner, rod);
  CHECK_OK(nh_surface_read(rod_path, 1e-3, 0, NULL, &s));
  rays = nh_surface_inside_volume(s, 256, 256);
  if (verbose) printf("diagonal rod: inside volume by rays %.6e vs 4e-7 m^3\n", rays);
  CHECK_CLOSE(rays / 4e-7, 1.0, 5e-3, "diagonal rod: inside volume by 256^2 rays");
  CHECK_CLOSE(nh_surface_volume(s) / 4e-7, 1.0, 1e-9, "diagonal rod: divergence volume");
  nh_surface_release(&s);

  /* Limits as a parameter. */
  nh_read_limits lim = nh_read_limits_default;
  lim.max_triangles = 1000;
  CHECK(nh_surface_read(path, 1e-3, 0, &lim, &s) == NH_ERR_INPUT &&
            says("limits.max_triangles = 1000") && says(path),
        "max_triangles: %s", nh_error_message());
  lim = nh_read_limits_default, lim.max_file_bytes = 1000;
  CHECK(nh_surface_read(path, 1e-3, 0, &lim, &s) == NH_ERR_INPUT &&
            says("limits.max_file_bytes = 1000"),
        "max_file_bytes: %s", nh_error_message());
  /* The smallest extent. */
  CHECK(nh_surface_read(path, 1e-3, 0.1, NULL, &s) == NH_ERR_INPUT && says("smaller than 0.1 m"),
        "min_extent 0.1 m: %s", nh_error_message());
  CHECK_OK(nh_surface_read(path, 1e-3, 0.05, NULL, &s));
  nh_surface_release(&s);
  remove(path);
  snprintf(path, sizeof path, "%s/cube.stl", dir);
  lim = nh_read_limits_default, lim.max_triangles = 3;
  CHECK(nh_surface_read(path, 1.0, 0, &lim, &s) == NH_ERR_INPUT &&
            says("more than limits.max_triangles = 3 facets"),
        "ASCII max_triangles: %s", nh_error_message());
  remove(path);
  const char *image = "/usr/lib/python3/dist-packages/nibabel/tests/data/anatomical.nii";
  nh_image *im;
  lim = nh_read_limits_default, lim.max_voxels = 1000;
  CHECK(nh_image_read(image, 0, &lim, &im) == NH_ERR_INPUT &&
            says("33 x 41 x 25 = 33825 voxels exceed limits.max_voxels = 1000"),
        "max_voxels: %s", nh_error_message());

  /* Streams: a FIFO that never ends, /dev/zero. */
  snprintf(path, sizeof path, "%s/endless.stl", dir);
  remove(path);
  CHECK(mkfifo(path, 0600) == 0, "mkfifo %s", path);
  pid_t child = fork();
  if (child == 0) {
    signal(SIGPIPE, SIG_DFL);
    FILE *f = fopen(path, "w");
    fputs("solid endless\n", f);
    for (int i = 0; i < 1 << 20; i++) fputs("    ", f);
    _exit(0);
  }
  lim = nh_read_limits_default, lim.max_file_bytes = 4096;
  CHECK(nh_surface_read(path, 1.0, 0, &lim, &s) == NH_ERR_INPUT &&
            says("goes on past limits.max_file_bytes = 4096"),
        "endless FIFO: %s", nh_error_message());
  kill(child, SIGKILL);
  waitpid(child, NULL, 0);
  remove(path);
  CHECK(nh_surface_read("/dev/zero", 1.0, 0, NULL, &s) == NH_ERR_INPUT &&
            says("goes on after the 84 + 50 x 0 = 84 bytes"),
        "/dev/zero: %s", nh_error_message());
}

int main(int argc, char **argv) {
  verbose = getenv("NH_TEST_VERBOSE") != NULL;
  const char *dir = argc > 1 ? argv[1] : ".";
  test_ellipsoid(dir);
  test_ascii(dir);
  test_nifti(dir);
  test_contract(dir);
  return nh_test_failures ? 1 : 0;
}
