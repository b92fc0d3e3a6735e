/* test_skull_fissure — skull contact points where one leaf holds surface
 * pieces that face apart (contact/skull.c; docs/theory.md §5c, "Skull
 * contact points"): the analytic brain of cases/dbs (size 140 × 170 × 130
 * mm, centre 0), whose longitudinal fissure is the slab |x| < w = 0.02 a =
 * 1.4 mm above z = e_z = 0.3 c = 19.5 mm (mesh/domain.c). On a grid with an
 * odd number of cells across x a cell column straddles the midline and holds
 * both walls of the fissure (outward normals −x on the wall x = +w, +x on
 * x = −w); the mean of the two lies in the gap, where F/|∇F| is no
 * distance. On 9 × 11 × 8, 11 × 13 × 10 and 17 × 21 × 16 (odd) and 18 × 22 × 17 (even),
 * with integrated cut cells, at rest with gap 0 (every point
 * gets a row at u = 0, so the rows name each point's nodes, shape values
 * and inward normal):
 *  1. every point lies on the surface F = 0: |F(X)| <= 1e-6 h (a point is
 *     accepted where |φ| = |F|/|∇F| <= 1e-6 of its leaf's largest edge,
 *     and |∇F| <= 1: F is 1-Lipschitz, mesh/domain.c);
 *  2. every point lies in its leaf up to the
 *     projection's bounded move: |ξ_k| <= 1 + 2 (h_max / 4) / h_k (the
 *     point starts in the leaf's hull and moves at most a quarter of the
 *     leaf's largest edge);
 *  3. the set of points is mirror symmetric about x = 0 (the brain is, and
 *     so is the grid: F(mirror x) = F(x) bit for bit): every row has a
 *     partner with mirrored position (1e-9 h) and mirrored direction
 *     (1e-9), so the skull force of a mirror-symmetric state has f_x = 0;
 *  4. on the odd grids both fissure walls carry points, as many on each,
 *     none facing the skull: a point on the wall x = ±w (|x| = w to
 *     1e-9 h, z > e_z + 1e-9 h) has a gap g > 0 to it (the skull is the
 *     offset of the hull U, the brain with its fissure filled, and the
 *     walls lie inside U);
 *  5. the points' areas sum to the area of the reconstructed surface
 *     {I F = 0} (Σ_c Σ_q |A_q| over the leaves' cut-cell
 *     surface quadratures, nh_cut_cell, summed here independently of the
 *     clustering) to 1e-12 relative: splitting a leaf's surface into
 *     clusters and merging small parts loses no area.
 *  6. with the gap of cases/dbs/dbs-skull.yaml (1 mm), no row turns its
 *     direction by more than 2° when the whole tissue is shifted by
 *     δ = 2e-3 h along x, y or z. A smooth skull turns a row by δ / R
 *     (R its radius of curvature; 2° needs R below 0.06 h); a point on a
 *     crease of F, or whose skull point X + gap n is on one, turns by the
 *     crease's angle once the shift takes it across: it gets the direction
 *     of whichever side round-off puts it on, and on the mirror plane of
 *     an odd grid that direction pushed it further to that side, so the
 *     antisymmetric part of the displacement grew 1e3-fold per step
 *     (docs/dbs.md; 42° at the hemispheres' crease on 17 × 21 × 16, 8° at
 *     1 mm beside the brainstem on 11 × 13 × 10). The points of this skull
 *     are mirror symmetric too (as 3.).
 *  7. the fissure's floor (z = e_z, |x| < w) and walls get no row with gap
 *     1 mm, at rest or with the whole tissue lifted by the gap: every such
 *     point where the hemisphere ellipsoid's E <= −2 mm (most of them; E the
 *     closed form below) is that far inside the hull (|∇U| <= 1), so at
 *     least 1 mm from the skull after the lift. There are such points on
 *     every grid, on the floor on the odd ones (on the even ones the floor's
 *     few samples join the walls' clusters). (The skull of F reached into
 *     the fissure as a plate 1 mm above the floor, docs/dbs.md: the lifted
 *     floor of the odd grids touched it.)
 * And at points, before any mesh, the skull's level function φ_skull =
 * U/|∇U| (nh_skull_level) against closed forms of the hemisphere
 * ellipsoid E = ρ (q − 1) (mesh/domain.c; ρ = rₓ = 0.55 a here):
 *  0a. on the lateral axis, x = ±(a + t), y = 0, z = e_z: φ_skull = t,
 *      n = ±e_x; above the vertex, x = ±eₓ, y = 0, z = c + t: φ_skull = t,
 *      n = e_z (t from −3 to +2.5 mm); there F = U, so the tissue's own
 *      φ = F/|∇F| is the same;
 *  0b. in the fissure (|x| = w/2, y = 0 and 20 mm, z = 30 and 40 mm: above
 *      the floor, below the hemispheres' crease): F = w − |x| > 0 (the gap,
 *      outside the tissue) while φ_skull = E/|∇E| < 0 (inside the skull's
 *      cavity), ∇E in closed form;
 *  0c. mirror symmetry: φ_skull(−x, y, z) = φ_skull(x, y, z) bit for bit,
 *      the normal's x component flipped.
 * (`scaled`, whose samples are projected from inside, leaves points up to
 * 0.7 mm inside F = 0 beside the creases: not checked here.)
 * Silent on success; NH_VERBOSE=1 prints the numbers. */
#include "check.h"
#include "contact/contact.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <stdint.h>
#include <string.h>

/* Rows of every point of skull s at displacement u (v = 0): the points'
 * rest positions X (3 per row, from the rows' nodes and shape values) and
 * the rows themselves. A positive warm start makes every point take its
 * row whatever its gap. */
static void rest_rows(nh_skull *s, const nh_mesh *m, const double *u, nh_rows *rows, double **X) {
  const int np = nh_skull_points(s), n = 3 * m->n_nodes;
  nh_bytes b = {NULL, 0, 0, 0};
  int32_t count = np, active = 0;
  const double one = 1.0, force[3] = {0, 0, 0};
  nh_bytes_put(&b, &count, sizeof count);
  for (int i = 0; i < np; i++) nh_bytes_put(&b, &one, sizeof one);
  nh_bytes_put(&b, force, sizeof force);
  nh_bytes_put(&b, &active, sizeof active);
  nh_byte_reader r = {b.data, b.data + b.len, 0};
  CHECK_OK(nh_skull_state_load(s, &r));
  free(b.data);
  double *v = calloc((size_t)n, sizeof(double));
  memset(rows, 0, sizeof *rows);
  CHECK_OK(nh_skull_rows(s, m, u, v, 1e-3, rows));
  *X = calloc(3 * (size_t)(rows->m ? rows->m : 1), sizeof(double));
  for (int q = 0; q < rows->m; q++)
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++)
        (*X)[3 * q + k] +=
            rows->N[rows->start[q] + a] * m->X[3 * rows->node[rows->start[q] + a] + k];
  free(v);
}

/* The brain of cases/dbs (size 140 × 170 × 130 mm, centre 0): half sizes and
 * the hemisphere ellipsoid's constants (mesh/domain.c). */
static const double A = 0.07, B = 0.085, C = 0.065;
#define RX (0.55 * A)
#define EX (0.45 * A)
#define RZ (0.7 * C)
#define EZ (0.3 * C)

/* The hemisphere ellipsoid E = ρ (q − 1) at P (ρ = rₓ, the smallest
 * radius), and its gradient if g is not NULL. */
static double hemisphere_grad(const double P[3], double *g) {
  const double qx = (fabs(P[0]) - EX) / RX, qy = P[1] / B, qz = (P[2] - EZ) / RZ;
  const double q = sqrt(qx * qx + qy * qy + qz * qz);
  if (g) {
    g[0] = RX * qx / RX / q * (P[0] < 0 ? -1.0 : 1.0);
    g[1] = RX * qy / B / q;
    g[2] = RX * qz / RZ / q;
  }
  return RX * (q - 1.0);
}

static double hemisphere(const double P[3]) {
  return hemisphere_grad(P, NULL);
}

/* 0. The skull's level function at points (closed forms). */
static void check_level(void) {
  const double center[3] = {0, 0, 0}, size[3] = {2 * A, 2 * B, 2 * C}, w = 0.02 * A;
  nh_domain d;
  nh_skull *s = NULL;
  nh_domain_brain(center, size, &d);
  CHECK_OK(nh_skull_create(&d, 1e-3, &s));
  const double ts[4] = {-3e-3, 0.0, 1e-3, 2.5e-3};
  for (int i = 0; i < 4; i++)
    for (int side = -1; side <= 1; side += 2) {
      const double t = ts[i];
      const double P[2][3] = {{side * (A + t), 0.0, EZ}, {side * EX, 0.0, C + t}};
      const double nexp[2][3] = {{side, 0, 0}, {0, 0, 1}};
      for (int j = 0; j < 2; j++) {
        double n[3], g[3];
        const double phi = nh_skull_level(s, P[j], n);
        const double f = nh_domain_gradient(&d, P[j], g);
        const double phi_f = f / sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
        CHECK_CLOSE(phi, t, 1e-12, j ? "phi_skull above the vertex" : "phi_skull lateral");
        CHECK_CLOSE(phi_f, phi, 1e-15, "the tissue's phi = phi_skull outside the fissure");
        for (int k = 0; k < 3; k++) CHECK_CLOSE(n[k], nexp[j][k], 1e-9, "skull normal");
      }
    }
  const double ys[2] = {0.0, 0.02}, zs[2] = {0.03, 0.04};
  for (int iy = 0; iy < 2; iy++)
    for (int iz = 0; iz < 2; iz++) {
      const double P[3] = {0.5 * w, ys[iy], zs[iz]}, M[3] = {-0.5 * w, ys[iy], zs[iz]};
      double n[3], nm[3], g[3];
      const double e = hemisphere_grad(P, g);
      const double expect = e / sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
      const double phi = nh_skull_level(s, P, n), phi_m = nh_skull_level(s, M, nm);
      CHECK(expect < 0.0, "the fissure point (%g, %g, %g) mm lies outside the ellipsoid",
            1e3 * P[0], 1e3 * P[1], 1e3 * P[2]);
      CHECK_CLOSE(phi, expect, 1e-12, "phi_skull in the fissure (E/|grad E|)");
      CHECK_CLOSE(nh_domain_level(&d, P), w - fabs(P[0]), 1e-15, "F in the fissure (w - |x|)");
      CHECK(phi_m == phi && nm[0] == -n[0] && nm[1] == n[1] && nm[2] == n[2],
            "mirror: phi_skull %.17g / %.17g, n (%g, %g, %g) / (%g, %g, %g)", phi, phi_m, n[0],
            n[1], n[2], nm[0], nm[1], nm[2]);
    }
  nh_skull_destroy(&s);
}

/* Rows without a mirror partner (position to 1e-9 h, direction to 1e-9). */
static int unpaired_rows(const nh_rows *rows, const double *X, double h) {
  int unpaired = 0;
  for (int r = 0; r < rows->m; r++) {
    int found = 0;
    for (int q = 0; q < rows->m && !found; q++) {
      const double *dr = rows->dir + 3 * r, *dq = rows->dir + 3 * q;
      found = fabs(X[3 * q] + X[3 * r]) <= 1e-9 * h &&
              fabs(X[3 * q + 1] - X[3 * r + 1]) <= 1e-9 * h &&
              fabs(X[3 * q + 2] - X[3 * r + 2]) <= 1e-9 * h && fabs(dq[0] + dr[0]) <= 1e-9 &&
              fabs(dq[1] - dr[1]) <= 1e-9 && fabs(dq[2] - dr[2]) <= 1e-9;
    }
    unpaired += !found;
  }
  return unpaired;
}

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  check_level();
  const double center[3] = {0, 0, 0}, size[3] = {0.14, 0.17, 0.13};
  const double w = 0.02 * 0.5 * size[0], ez = 0.3 * 0.5 * size[2];
  const int grids[4][3] = {{9, 11, 8}, {11, 13, 10}, {17, 21, 16}, {18, 22, 17}};
  for (int mode = 1; mode < 2; mode++) /* integrated (1); scaled (0) misses 1 near creases */
    for (int gi = 0; gi < 4; gi++) {
      const int *grid = grids[gi], odd = grid[0] % 2;
      const char *mname = mode ? "integrated" : "scaled";
      nh_domain d;
      nh_domain_brain(center, size, &d);
      d.cut_cells = mode ? NH_CUT_CELLS_INTEGRATED : NH_CUT_CELLS_SCALED;
      nh_mesh *m = NULL;
      nh_skull *s = NULL;
      CHECK_OK(nh_mesh_create(&d, grid, &m));
      CHECK_OK(nh_skull_create(&m->domain, 0.0, &s));
      CHECK_OK(nh_skull_build(s, m));
      double hk[3], h = 0.0;
      for (int k = 0; k < 3; k++) hk[k] = size[k] / grid[k], h = fmax(h, hk[k]);
      nh_rows rows;
      double *X = NULL;
      const int n = 3 * m->n_nodes;
      double *u = calloc((size_t)n, sizeof(double));
      rest_rows(s, m, u, &rows, &X);
      const int np = rows.m;
      CHECK(np == nh_skull_points(s), "%s %dx%dx%d: %d rows for %d points at rest with gap 0",
            mname, grid[0], grid[1], grid[2], np, nh_skull_points(s));
      int bad_on = 0, bad_xi = 0, walls[2] = {0, 0}, bad_wall = 0, unpaired = 0;
      double worst_f = 0.0;
      for (int r = 0; r < np; r++) {
        const int *node = rows.node + rows.start[r];
        const double f = fabs(nh_domain_level(&m->domain, X + 3 * r));
        worst_f = fmax(worst_f, f);
        bad_on += f > 1e-6 * h;
        if (mode) { /* 2. the leaf: the one whose 8 nodes the row names */
          int cell = -1;
          for (int l = 0; l < m->n_leaves && cell < 0; l++) {
            int c = m->leaves[l], same = 1;
            for (int a = 0; a < 8; a++) same &= m->cells[8 * c + a] == node[a];
            if (same) cell = c;
          }
          double Xe[24], lo[3], hi[3];
          CHECK(cell >= 0, "%s: row %d names no leaf", mname, r);
          if (cell < 0) continue;
          nh_mesh_cell_coords(m, m->X, cell, Xe);
          CHECK(nh_hex_is_box(Xe, lo, hi), "leaf %d is not a box", cell);
          for (int k = 0; k < 3; k++) {
            const double xi = (2.0 * X[3 * r + k] - lo[k] - hi[k]) / (hi[k] - lo[k]);
            bad_xi += fabs(xi) > 1.0 + 0.5 * h / (hi[k] - lo[k]) + 1e-12;
          }
        }
        /* 4. the fissure's walls */
        const double x = X[3 * r];
        if (fabs(fabs(x) - w) <= 1e-9 * h && X[3 * r + 2] > ez + 1e-9 * h) {
          walls[x > 0]++;
          bad_wall += !(rows.gap[r] > 0.0); /* inside the hull: no skull in the fissure */
        }
      }
      /* 3. the mirror partner of every row */
      unpaired = unpaired_rows(&rows, X, h);
      CHECK(bad_on == 0,
            "%s %dx%dx%d: %d of %d points off F = 0 by more than 1e-6 h (worst %.3g m)", mname,
            grid[0], grid[1], grid[2], bad_on, np, worst_f);
      CHECK(bad_xi == 0, "%s %dx%dx%d: %d coordinates of points outside their leaf's bound", mname,
            grid[0], grid[1], grid[2], bad_xi);
      CHECK(unpaired == 0, "%s %dx%dx%d: %d of %d points without a mirror partner", mname, grid[0],
            grid[1], grid[2], unpaired, np);
      if (odd)
        CHECK(walls[0] > 0 && walls[0] == walls[1] && bad_wall == 0,
              "%s %dx%dx%d: fissure walls x = -w, +w: %d, %d points (expected as many, > 0), %d "
              "with gap <= 0 to the skull (expected > 0: inside the hull)",
              mname, grid[0], grid[1], grid[2], walls[0], walls[1], bad_wall);
      /* 5. the area of the reconstructed surface, summed leaf by leaf */
      double area = 0.0;
      if (mode) {
        nh_cut_spec spec;
        nh_cut_spec_domain(&spec, &m->domain, NH_CUT_DEPTH);
        for (int l = 0; l < m->n_leaves; l++) {
          double Xe[24], lo[3], hi[3];
          nh_mesh_cell_coords(m, m->X, m->leaves[l], Xe);
          if (!nh_hex_is_box(Xe, lo, hi)) continue;
          nh_cut_moments mom;
          nh_cut_surface surf = {0, 0, NULL};
          CHECK_OK(nh_cut_cell(&spec, lo, hi, &mom, &surf, 0u));
          for (int q = 0; q < surf.n; q++)
            if (surf.point[q].piece == -1) {
              const double *A = surf.point[q].area;
              area += sqrt(A[0] * A[0] + A[1] * A[1] + A[2] * A[2]);
            }
          nh_cut_surface_free(&surf);
        }
        CHECK(fabs(nh_skull_area(s) - area) <= 1e-12 * area,
              "%s %dx%dx%d: points' area %.15g m², the reconstructed surface's %.15g m²", mname,
              grid[0], grid[1], grid[2], nh_skull_area(s), area);
      }
      /* 6. no row turns by more than 2° under a shift of 2e-3 h (gap 1 mm) */
      const double gap = 1e-3;
      nh_skull *sg = NULL;
      nh_rows rg;
      double *Xg = NULL, worst_turn = 0.0;
      int turned = 0;
      CHECK_OK(nh_skull_create(&m->domain, gap, &sg));
      CHECK_OK(nh_skull_build(sg, m));
      rest_rows(sg, m, u, &rg, &Xg);
      CHECK(rg.m == nh_skull_points(sg), "%s %dx%dx%d, gap 1 mm: %d rows for %d points", mname,
            grid[0], grid[1], grid[2], rg.m, nh_skull_points(sg));
      for (int axis = 0; axis < 3; axis++) {
        double *us = calloc((size_t)n, sizeof(double)), *Xs = NULL;
        for (int i = 0; i < m->n_nodes; i++) us[3 * i + axis] = 2e-3 * h;
        nh_rows rs;
        rest_rows(sg, m, us, &rs, &Xs);
        for (int r = 0; r < rg.m && r < rs.m; r++) {
          const double *d0 = rg.dir + 3 * r, *d1 = rs.dir + 3 * r;
          const double turn =
              acos(fmin(1.0, d0[0] * d1[0] + d0[1] * d1[1] + d0[2] * d1[2])) * 180.0 / M_PI;
          worst_turn = fmax(worst_turn, turn);
          if (turn > 2.0) {
            if (verbose)
              printf("  row turns %.1f deg (shift along %c): X = (%.4f, %.4f, %.4f) mm\n", turn,
                     "xyz"[axis], 1e3 * Xg[3 * r], 1e3 * Xg[3 * r + 1], 1e3 * Xg[3 * r + 2]);
            turned++;
          }
        }
        nh_rows_free(&rs);
        free(us), free(Xs);
      }
      CHECK(turned == 0,
            "%s %dx%dx%d, gap 1 mm: %d row directions turn by more than 2 deg (up to %.1f) "
            "under a shift of 2e-3 h: points on a crease",
            mname, grid[0], grid[1], grid[2], turned, worst_turn);
      const int unpaired_g = unpaired_rows(&rg, Xg, h), np_g = rg.m;
      CHECK(unpaired_g == 0, "%s %dx%dx%d, gap 1 mm: %d of %d points without a mirror partner",
            mname, grid[0], grid[1], grid[2], unpaired_g, rg.m);
      /* 7. the fissure's floor gets no row, at rest or with the tissue
       * lifted by the gap (its vertex then presses on the skull): a floor
       * point where the hemisphere ellipsoid has E <= -2 mm is at least 2 mm
       * inside the hull (|∇U| <= 1), so 1 mm from the skull after the lift
       * (the offset of F reached into the fissure as a plate 1 mm above the
       * floor: g = 0 there after the lift) */
      int fissure_pts = 0, floor_pts = 0, floor_rows = 0;
      for (int lift = 0; lift < 2; lift++) {
        nh_skull *sf = NULL;
        nh_rows rf;
        memset(&rf, 0, sizeof rf);
        double *ul = calloc((size_t)n, sizeof(double)), *vl = calloc((size_t)n, sizeof(double));
        for (int i = 0; i < m->n_nodes; i++) ul[3 * i + 2] = lift * gap;
        CHECK_OK(nh_skull_create(&m->domain, gap, &sf));
        CHECK_OK(nh_skull_build(sf, m));
        CHECK_OK(nh_skull_rows(sf, m, ul, vl, 1e-3, &rf));
        if (lift)
          CHECK(rf.m > 0, "%dx%dx%d: no skull row with the tissue lifted by the gap", grid[0],
                grid[1], grid[2]);
        for (int q = 0; q < rg.m; q++) {
          const double *P = Xg + 3 * q;
          if (!(fabs(P[0]) <= w + 1e-9 * h && P[2] >= ez - 1e-9 * h && hemisphere(P) <= -2e-3))
            continue;
          fissure_pts += !lift;
          floor_pts += !lift && fabs(P[2] - ez) <= 1e-9 * h;
          for (int r = 0; r < rf.m; r++) {
            double Y[3] = {0, 0, 0};
            for (int a = 0; a < 8; a++)
              for (int k = 0; k < 3; k++)
                Y[k] += rf.N[rf.start[r] + a] * m->X[3 * rf.node[rf.start[r] + a] + k];
            floor_rows += fabs(Y[0] - P[0]) + fabs(Y[1] - P[1]) + fabs(Y[2] - P[2]) <= 1e-12;
          }
        }
        nh_rows_free(&rf);
        free(ul), free(vl);
        nh_skull_destroy(&sf);
      }
      CHECK(fissure_pts > 0 && (floor_pts > 0 || !odd) && floor_rows == 0,
            "%dx%dx%d, gap 1 mm: %d points on the fissure's walls and floor (expected > 0), %d on "
            "its floor (expected > 0 on odd grids), %d rows of them at rest or lifted by the gap "
            "(expected 0)",
            grid[0], grid[1], grid[2], fissure_pts, floor_pts, floor_rows);
      nh_rows_free(&rg);
      free(Xg);
      nh_skull_destroy(&sg);
      if (verbose)
        printf("%-10s %2dx%2dx%2d: %4d points, area %.6g m² (surface %.6g), worst |F| %.2e m, "
               "walls %d/%d; gap 1 mm: %d points, largest turn %.2f deg, %d deep fissure points "
               "(%d on the floor)\n",
               mname, grid[0], grid[1], grid[2], np, nh_skull_area(s), area, worst_f, walls[0],
               walls[1], np_g, worst_turn, fissure_pts, floor_pts);
      nh_rows_free(&rows);
      free(u), free(X);
      nh_skull_destroy(&s);
      nh_mesh_destroy(&m);
    }
  return nh_test_failures ? 1 : 0;
}
