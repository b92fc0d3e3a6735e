/* test_grade — the 2:1 rule and coarsening (mesh/grade.c, mesh/coarsen.c).
 *
 *  1. Grading invariant. Random refinement sequences (random leaves marked,
 *     closed by nh_mesh_grade_marks, refined) on a 4x3x2 box grid with the
 *     2x2x2 and the 3x3x3 template, and random coarsening steps in between
 *     (nh_mesh_coarsen_candidates on random flags, nh_mesh_coarsen): after
 *     every step, every pair of leaves that touch along a face or an edge
 *     differs by at most one level. The oracle is independent of the probing
 *     in grade.c: all pairs of leaves, their rest bounding boxes, contact of
 *     dimension >= 1 (the closed boxes overlap with positive length along at
 *     least one axis and touch along the others). It detects a violation:
 *     refining one cell twice without the closure is reported.
 *  2. Refine-then-coarsen with no change restores mesh and state exactly:
 *     on a graded mesh with a nodal field (a smooth function of position,
 *     hanging nodes interpolated), refining a closed random set (field
 *     carried by Eq. 17) and coarsening the same parents gives back every
 *     mesh array and the field bitwise (memcmp).
 *  3. Materials per label follow their cells through coarsening, which
 *     renumbers cells: on a box whose label image gives every cell a
 *     different mix of three materials, a tissue carried through random
 *     refinement and coarsening (nh_tissue_update after each change) holds,
 *     for every leaf, the same λ, μ, ρ and nodal masses as a tissue built
 *     from scratch on the final mesh (bitwise: both mix the same samples). */
#include "anatomy/anatomy.h"
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"

#include <string.h>

#include "hanging_mesh.h"

static void leaf_box(const nh_mesh *m, int c, double lo[3], double hi[3]) {
  for (int k = 0; k < 3; k++) lo[k] = INFINITY, hi[k] = -INFINITY;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      double x = m->X[3 * m->cells[8 * c + a] + k];
      lo[k] = fmin(lo[k], x), hi[k] = fmax(hi[k], x);
    }
}

/* Number of face/edge contacts between leaves more than one level apart. */
static int violations(const nh_mesh *m, int verbose) {
  int n = m->n_leaves, bad = 0;
  double *lo = malloc(sizeof(double) * 3 * n), *hi = malloc(sizeof(double) * 3 * n);
  for (int l = 0; l < n; l++) leaf_box(m, m->leaves[l], lo + 3 * l, hi + 3 * l);
  for (int a = 0; a < n; a++)
    for (int b = a + 1; b < n; b++) {
      int overlap = 0, touch = 1;
      for (int k = 0; k < 3 && touch; k++) {
        double tol = 1e-9 * (hi[3 * a + k] - lo[3 * a + k]);
        double len = fmin(hi[3 * a + k], hi[3 * b + k]) - fmax(lo[3 * a + k], lo[3 * b + k]);
        if (len < -tol)
          touch = 0;
        else if (len > tol)
          overlap++;
      }
      int da = m->level[m->leaves[a]], db = m->level[m->leaves[b]];
      if (touch && overlap >= 1 && abs(da - db) > 1) {
        if (verbose && bad < 3)
          fprintf(stderr, "leaves %d (level %d) and %d (level %d) touch along a face or edge\n",
                  m->leaves[a], da, m->leaves[b], db);
        bad++;
      }
    }
  free(lo), free(hi);
  return bad;
}

static nh_mesh *box_mesh(void) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.03, 0.02};
  const int grid[3] = {4, 3, 2};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  return m;
}

/* Mark about `share` of the leaves below max_level at random, close, refine. */
static void random_refine(nh_mesh *m, const nh_template *t, double share, int max_level,
                          nh_refine_info *info, int *out, int *n_out) {
  int *marked = malloc(sizeof(int) * m->n_leaves), n = 0;
  for (int l = 0; l < m->n_leaves; l++)
    if (m->level[m->leaves[l]] < max_level && 0.5 * (nh_rand() + 1) < share)
      marked[n++] = m->leaves[l];
  CHECK_OK(nh_mesh_grade_marks(m, marked, &n));
  CHECK_OK(nh_mesh_refine(m, t, marked, n, info));
  if (out) memcpy(out, marked, sizeof(int) * n), *n_out = n;
  free(marked);
}

static void random_coarsen(nh_mesh *m, double share) {
  unsigned char *below = calloc(m->n_cells, 1);
  for (int l = 0; l < m->n_leaves; l++) below[m->leaves[l]] = 0.5 * (nh_rand() + 1) < share;
  int *parents = malloc(sizeof(int) * (m->n_leaves / 2 + 1));
  int n = nh_mesh_coarsen_candidates(m, below, parents);
  int *map = malloc(sizeof(int) * m->n_nodes);
  CHECK_OK(nh_mesh_coarsen(m, parents, n, map));
  free(below), free(parents), free(map);
}

static void test_invariant(int n_template) {
  nh_template *t = regular_template(n_template);
  nh_test_rng = 4242 + n_template;
  for (int run = 0; run < 2; run++) {
    nh_mesh *m = box_mesh();
    for (int step = 0; step < 5; step++) {
      random_refine(m, t, 0.1, n_template == 2 ? 4 : 2, NULL, NULL, NULL);
      if (getenv("NH_VERBOSE"))
        printf("template %d run %d step %d: %d leaves\n", n_template, run, step, m->n_leaves);
      int bad = violations(m, 1);
      CHECK(bad == 0,
            "template %d, run %d, refinement %d: %d face/edge contacts more than one "
            "level apart (expected 0)",
            n_template, run, step, bad);
      if (step % 2 == 1) {
        random_coarsen(m, 0.6);
        bad = violations(m, 1);
        CHECK(bad == 0, "template %d, run %d, after coarsening %d: %d violations (expected 0)",
              n_template, run, step, bad);
      }
    }
    nh_mesh_destroy(&m);
  }
  nh_template_destroy(&t);
}

/* The oracle sees an ungraded mesh: one cell refined twice, no closure. */
static void test_oracle(void) {
  nh_template *t = regular_template(2);
  nh_mesh *m = box_mesh();
  int c = 1 + 4 * (1 + 3 * 0);
  CHECK_OK(nh_mesh_refine(m, t, &c, 1, NULL));
  int ch = m->first_child[c];
  CHECK_OK(nh_mesh_refine(m, t, &ch, 1, NULL));
  CHECK(violations(m, 0) > 0, "a cell refined twice beside level-0 cells was not reported");
  /* The closure of the same marking gives a graded mesh. */
  nh_mesh_destroy(&m);
  m = box_mesh();
  CHECK_OK(nh_mesh_refine(m, t, &c, 1, NULL));
  int marked[64] = {m->first_child[c]}, n = 1;
  CHECK_OK(nh_mesh_grade_marks(m, marked, &n));
  CHECK(n > 1, "closure added no neighbour (n = %d)", n);
  CHECK_OK(nh_mesh_refine(m, t, marked, n, NULL));
  CHECK(violations(m, 1) == 0, "the closed refinement is not graded");
  nh_mesh_destroy(&m);
  nh_template_destroy(&t);
}

static void field_of(const nh_mesh *m, double *u) {
  for (int i = 0; i < m->n_nodes; i++) {
    const double *x = m->X + 3 * i;
    u[3 * i] = sin(90 * x[0]) * x[1];
    u[3 * i + 1] = cos(70 * x[1] + x[2]);
    u[3 * i + 2] = x[0] * x[2] * 1e3;
  }
}

static void test_restore(void) {
  nh_template *t = regular_template(2);
  nh_test_rng = 99;
  nh_mesh *m = box_mesh();
  for (int step = 0; step < 3; step++) random_refine(m, t, 0.2, 3, NULL, NULL, NULL);
  nh_hanging *h = NULL;
  CHECK_OK(nh_hanging_detect(m, NULL, &h));
  double *u = malloc(sizeof(double) * 3 * m->n_nodes);
  field_of(m, u);
  nh_hanging_interpolate(h, u, 3);
  /* Snapshot. */
  int nn = m->n_nodes, nc = m->n_cells, nl = m->n_leaves;
  double *X0 = malloc(sizeof(double) * 3 * nn), *u0 = malloc(sizeof(double) * 3 * nn);
  int *cells0 = malloc(sizeof(int) * 8 * nc), *ints0 = malloc(sizeof(int) * 4 * nc);
  int *leaves0 = malloc(sizeof(int) * nl);
  double *fill0 = malloc(sizeof(double) * nc);
  memcpy(X0, m->X, sizeof(double) * 3 * nn), memcpy(u0, u, sizeof(double) * 3 * nn);
  memcpy(cells0, m->cells, sizeof(int) * 8 * nc), memcpy(leaves0, m->leaves, sizeof(int) * nl);
  memcpy(ints0, m->level, sizeof(int) * nc), memcpy(ints0 + nc, m->parent, sizeof(int) * nc);
  memcpy(ints0 + 2 * nc, m->first_child, sizeof(int) * nc);
  memcpy(ints0 + 3 * nc, m->n_children, sizeof(int) * nc);
  memcpy(fill0, m->fill, sizeof(double) * nc);

  nh_refine_info info = {0};
  int *parents = malloc(sizeof(int) * nl), np = 0;
  random_refine(m, t, 0.3, 4, &info, parents, &np);
  CHECK(np > 0, "nothing refined");
  u = realloc(u, sizeof(double) * 3 * m->n_nodes);
  for (int k = 0; k < info.n_new; k++) { /* Eq. 17 */
    double N[8];
    nh_hex_shape(info.xi + 3 * k, N);
    for (int i = 0; i < 3; i++) {
      double s = 0.0;
      for (int a = 0; a < 8; a++) s += N[a] * u[3 * m->cells[8 * info.parent[k] + a] + i];
      u[3 * (info.first_new + k) + i] = s;
    }
  }
  int *map = malloc(sizeof(int) * m->n_nodes), n_before = m->n_nodes;
  CHECK_OK(nh_mesh_coarsen(m, parents, np, map));
  for (int v = 0; v < n_before; v++)
    if (map[v] >= 0) memmove(u + 3 * map[v], u + 3 * v, 3 * sizeof(double));

  CHECK(m->n_nodes == nn && m->n_cells == nc && m->n_leaves == nl,
        "counts after refine+coarsen: nodes %d cells %d leaves %d, expected %d %d %d", m->n_nodes,
        m->n_cells, m->n_leaves, nn, nc, nl);
  if (m->n_nodes == nn && m->n_cells == nc && m->n_leaves == nl) {
    CHECK(!memcmp(X0, m->X, sizeof(double) * 3 * nn), "node positions differ");
    CHECK(!memcmp(u0, u, sizeof(double) * 3 * nn), "the state differs");
    CHECK(!memcmp(cells0, m->cells, sizeof(int) * 8 * nc), "cell corners differ");
    CHECK(!memcmp(leaves0, m->leaves, sizeof(int) * nl), "leaves differ");
    CHECK(!memcmp(ints0, m->level, sizeof(int) * nc), "levels differ");
    CHECK(!memcmp(ints0 + nc, m->parent, sizeof(int) * nc), "parents differ");
    CHECK(!memcmp(ints0 + 2 * nc, m->first_child, sizeof(int) * nc), "first children differ");
    CHECK(!memcmp(ints0 + 3 * nc, m->n_children, sizeof(int) * nc), "child counts differ");
    CHECK(!memcmp(fill0, m->fill, sizeof(double) * nc), "fill fractions differ");
  }
  nh_refine_info_free(&info);
  nh_hanging_destroy(&h);
  free(u), free(X0), free(u0), free(cells0), free(ints0), free(leaves0), free(fill0);
  free(parents), free(map);
  nh_mesh_destroy(&m);
  nh_template_destroy(&t);
}

/* A 12x9x6 voxel image over box_mesh() (voxels of 1/3 of a level-0 cell):
 * labels 1, 2, 3 in a pattern no cell repeats. */
static nh_image *label_image(void) {
  nh_image *im = calloc(1, sizeof *im);
  const int n[3] = {12, 9, 6};
  const double h = 0.01 / 3;
  im->label = malloc(sizeof(int) * n[0] * n[1] * n[2]);
  for (int k = 0; k < 3; k++) {
    im->n[k] = n[k];
    im->A[4 * k] = h, im->Ainv[4 * k] = 1.0 / h, im->spacing[k] = h;
    im->t[k] = 0.5 * h;
  }
  for (int z = 0; z < n[2]; z++)
    for (int y = 0; y < n[1]; y++)
      for (int x = 0; x < n[0]; x++)
        im->label[x + n[0] * (y + n[1] * z)] = 1 + (x * x + 2 * y + 5 * z * x) % 3;
  im->refs = 1;
  return im;
}

static void test_label_materials(void) {
  nh_template *t = regular_template(2);
  nh_test_rng = 7;
  nh_mesh *m = box_mesh();
  m->domain.labels = label_image();
  const int labels[3] = {1, 2, 3};
  const nh_material base = {1e4, 0.45, 1000, NH_FORMULATION_FULL};
  const nh_material mats[3] = {
      {2e4, 0.40, 1100, NH_FORMULATION_FULL},
      {5e3, 0.30, 900, NH_FORMULATION_FULL},
      {8e4, 0.49, 1300, NH_FORMULATION_FULL},
  };
  nh_tissue *carried;
  CHECK_OK(nh_tissue_create(m, &base, &carried));
  CHECK_OK(nh_tissue_set_label_materials(carried, 3, labels, mats));
  int renumbered = 0;
  for (int step = 0; step < 6; step++) {
    random_refine(m, t, 0.3, 3, NULL, NULL, NULL);
    CHECK_OK(nh_tissue_update(carried));
    int cells = m->n_cells;
    random_coarsen(m, 0.7);
    renumbered += m->n_cells < cells;
    CHECK_OK(nh_tissue_update(carried));
  }
  CHECK(renumbered > 0, "no coarsening happened: the test does not test");
  nh_tissue *fresh;
  CHECK_OK(nh_tissue_create(m, &base, &fresh));
  CHECK_OK(nh_tissue_set_label_materials(fresh, 3, labels, mats));
  int bad = 0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double a[3], b[3];
    nh_tissue_cell_material(carried, c, a, a + 1, a + 2);
    nh_tissue_cell_material(fresh, c, b, b + 1, b + 2);
    if (memcmp(a, b, sizeof a)) {
      if (bad++ < 3)
        fprintf(stderr, "leaf %d: carried λ %g μ %g ρ %g, fresh %g %g %g\n", c, a[0], a[1], a[2],
                b[0], b[1], b[2]);
    }
  }
  CHECK(bad == 0, "%d of %d leaves carry another cell's material after coarsening", bad,
        m->n_leaves);
  CHECK(!memcmp(carried->mass, fresh->mass, sizeof(double) * m->n_nodes), "nodal masses differ");
  nh_tissue_destroy(&carried), nh_tissue_destroy(&fresh);
  nh_mesh_destroy(&m);
  nh_template_destroy(&t);
}

int main(void) {
  test_oracle();
  test_invariant(2);
  test_invariant(3);
  test_restore();
  test_label_materials();
  TEST_END();
}
