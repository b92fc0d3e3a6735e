/* test_skull_surface — the surface quadratures of an immersed sphere off
 * the grid's centre: the skull's contact points (contact/skull.c with
 * tissue.cut_cells: integrated) and the pressure on the immersed surface
 * (fem/traction.c); docs/theory.md §5c, "Skull contact points".
 * The sphere, R = 3 cm, centre c ≠ 0; the grid of g³ cells covers its
 * bounding box widened by 0.21 R, 0.37 R, 0.53 R on the low sides only
 * (nh_mesh_create_box: every cell kept, the sphere as the mesh's domain),
 * so the sphere's centre is neither a node nor a cell centre nor the
 * grid's centre; g = 6, 8, 12, 16, 24:
 *  1. The areas of the points sum to 4πR² (exact) up to the error of the
 *     piecewise linear reconstruction, O(s²) with s = h/4 the sub-box
 *     edge: the relative error e_g shrinks, and the observed order
 *     log(e_6 / e_24) / log 4 is at least 1.8 (2 expected; a one-point or
 *     smeared-delta area would give 1).
 *  2. Every point lies on the sphere (|X − c| = R to 1e-9 R: the three
 *     projection steps are exact on a sphere), belongs to a leaf holding at
 *     least NH_FILL_MIN of its volume in tissue (the aggregation of small
 *     cut parts), at natural coordinates that map to X in that leaf (a
 *     box: x = mid + half ξ) and lie in [-1, 1]³ up to the projection's
 *     move (|ξ| <= 1 + 2 (R − √(R² − h²)) / h: the sagitta of a chord h).
 *  3. A uniform pressure p on the immersed surface (tissue.tractions,
 *     nh_traction_load) has zero net force and torque: |Σ_a f_a| / (p A)
 *     and |Σ_a X_a × f_a| / (p A R) <= 1e-12 (the divergence theorem on the
 *     closed reconstructed polyhedron: Σ A n = 0 and ∮ x × n dA = 0, and the
 *     6-point rule is exact for the linear x on each triangle).
 * Silent on success; NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "contact/contact.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  const double c0[3] = {0.0013, -0.0021, 0.0007}, R = 0.03, widen[3] = {0.21, 0.37, 0.53};
  const double exact = 4.0 * M_PI * R * R;
  const int grids[5] = {6, 8, 12, 16, 24};
  double err[5];
  for (int gi = 0; gi < 5; gi++) {
    nh_domain d;
    nh_domain_sphere(c0, R, &d);
    d.cut_cells = NH_CUT_CELLS_INTEGRATED;
    double lo[3], hi[3];
    for (int k = 0; k < 3; k++) lo[k] = d.min[k] - widen[k] * R, hi[k] = d.max[k];
    const int g = grids[gi], grid[3] = {g, g, g};
    nh_mesh *m = NULL;
    nh_skull *s = NULL;
    CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
    m->domain = d;
    /* 3. the pressure's net force and torque */
    {
      const double p = 1e3;
      double *f = calloc(3 * (size_t)m->n_nodes, sizeof(double)), F[3] = {0, 0, 0},
             T[3] = {0, 0, 0}, A = 0.0;
      nh_traction tr;
      memset(&tr, 0, sizeof tr);
      tr.region.kind = NH_REGION_BOX;
      for (int k = 0; k < 3; k++) tr.region.min[k] = -1.0, tr.region.max[k] = 1.0;
      tr.is_pressure = 1, tr.pressure = p;
      CHECK_OK(nh_traction_load(m, &tr, f, &A));
      for (int i = 0; i < m->n_nodes; i++) {
        const double *x = m->X + 3 * i, *fi = f + 3 * i;
        for (int k = 0; k < 3; k++) F[k] += fi[k];
        T[0] += x[1] * fi[2] - x[2] * fi[1], T[1] += x[2] * fi[0] - x[0] * fi[2],
            T[2] += x[0] * fi[1] - x[1] * fi[0];
      }
      const double fn = sqrt(F[0] * F[0] + F[1] * F[1] + F[2] * F[2]) / (p * A),
                   tn = sqrt(T[0] * T[0] + T[1] * T[1] + T[2] * T[2]) / (p * A * R);
      CHECK(fn <= 1e-12 && tn <= 1e-12, "%d³: pressure's net force %.3g p A, torque %.3g p A R", g,
            fn, tn);
      CHECK(fabs(A - exact) <= 0.05 * exact, "%d³: pressure area %.6g, 4πR² %.6g", g, A, exact);
      if (verbose) printf("%2d³: pressure: net force %.2e p A, torque %.2e p A R\n", g, fn, tn);
      free(f);
    }
    CHECK_OK(nh_skull_create(&d, 0.0, &s));
    CHECK_OK(nh_skull_build(s, m));
    const double area = nh_skull_area(s);
    err[gi] = fabs(area - exact) / exact;
    /* the points: rows at u = 0 give each one's leaf, shape values and rest position */
    nh_rows rows;
    memset(&rows, 0, sizeof rows);
    const int n = 3 * m->n_nodes;
    double *u = calloc((size_t)n, sizeof(double)), *v = calloc((size_t)n, sizeof(double));
    double h = 0.0;
    for (int k = 0; k < 3; k++) h = fmax(h, m->spacing[k]);
    /* with gap 0 every point at rest is at its skull: every point gets a row */
    CHECK_OK(nh_skull_rows(s, m, u, v, 1e-3, &rows));
    CHECK(rows.m == nh_skull_points(s), "%d³: %d rows for %d points at rest with gap 0", g, rows.m,
          nh_skull_points(s));
    const double sag = R - sqrt(R * R - h * h), xi_max = 1.0 + 2.0 * sag / h;
    int bad_on = 0, bad_fraction = 0, bad_xi = 0;
    for (int r = 0; r < rows.m; r++) {
      /* the leaf: the one whose 8 nodes the row names */
      int cell = -1;
      for (int l = 0; l < m->n_leaves && cell < 0; l++) {
        int c = m->leaves[l], same = 1;
        for (int a = 0; a < 8; a++) same &= m->cells[8 * c + a] == rows.node[8 * r + a];
        if (same) cell = c;
      }
      CHECK(cell >= 0, "%d³: row %d names no leaf", g, r);
      if (cell < 0) continue;
      double Xe[24], X[3] = {0, 0, 0}, xi[3];
      nh_mesh_cell_coords(m, m->X, cell, Xe);
      CHECK(nh_hex_is_box(Xe, lo, hi), "%d³: leaf %d is not a box", g, cell);
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) X[k] += rows.N[8 * r + a] * Xe[3 * a + k];
      CHECK_OK(nh_hex_invert(Xe, X, xi));
      double dist = 0.0, xim = 0.0;
      for (int k = 0; k < 3; k++)
        dist += (X[k] - c0[k]) * (X[k] - c0[k]), xim = fmax(xim, fabs(xi[k]));
      bad_on += fabs(sqrt(dist) - R) > 1e-9 * R;
      bad_xi += xim > xi_max;
      nh_cut_moments mom;
      CHECK_OK(nh_cut_domain_cell(&d, lo, hi, NULL, NULL, &mom, NULL));
      bad_fraction +=
          mom.volume < NH_FILL_MIN * (hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]);
    }
    CHECK(bad_on == 0, "%d³: %d points off the sphere by more than 1e-9 R", g, bad_on);
    CHECK(bad_fraction == 0, "%d³: %d points on leaves with tissue fraction < %g", g, bad_fraction,
          NH_FILL_MIN);
    CHECK(bad_xi == 0, "%d³: %d points with |ξ| > %g", g, bad_xi, xi_max);
    if (verbose)
      printf("%2d³: %d points, area %.9g m² (4πR² %.9g), relative error %.3e\n", g,
             nh_skull_points(s), area, exact, err[gi]);
    nh_rows_free(&rows);
    free(u), free(v);
    nh_skull_destroy(&s);
    nh_mesh_destroy(&m); /* releases d, its domain */
  }
  const double order = log(err[0] / err[4]) / log(4.0);
  CHECK(order >= 1.8,
        "area: observed order %.3f from 6³ to 24³ (errors %.3e, %.3e), expected >= 1.8", order,
        err[0], err[4]);
  for (int gi = 1; gi < 5; gi++)
    CHECK(err[gi] < err[gi - 1], "area error %.3e on %d³ not below %.3e on %d³", err[gi], grids[gi],
          err[gi - 1], grids[gi - 1]);
  if (verbose) printf("observed order of the area, 6³ to 24³: %.3f\n", order);
  return nh_test_failures ? 1 : 0;
}
