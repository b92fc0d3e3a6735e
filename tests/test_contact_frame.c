/* test_contact_frame — the contact geometry is a continuous function of the
 * state (contact/tools.c nh_tool_project, contact/points.c nh_disc_build;
 * docs/interaction.md "Tip disc"): an iterative solve that changes the
 * state by a tolerance-sized amount (solver.refactor: auto against every,
 * tests/reuse.py) must change the rows by as little. Two rules broke that
 * on the phantom (a needle along x, its tangent's other components
 * round-off):
 *
 *  1. The closest point on a tool, nh_tool_project (a shaft point's arc
 *     length s, whose depth L − s sets its share of the shaft friction): a
 *     needle bent into an arc of radius R = 0.1 m (16 elements, L = 50 mm,
 *     its nodes and directors on the circle), 400 points at s* ∈ (0, L)
 *     offset by up to 0.5 mm across the arc, in its plane and out of it.
 *     The closest point of the circle is s*, and the Hermite curve lies
 *     within l₀⁴ / (384 R³) = 2.5e-10 m of it (l₀ = 3.125 mm), so |s − s*|
 *     must be below 1e-8 m from two starts, s* + 0.2 mm (the last step's s)
 *     and L (an untied point). Beyond the ends the answer is the end's
 *     tangent extrapolation: a point 1 mm past the tip along its tangent
 *     projects to L + 1 mm, one 1 mm behind the base to −1 mm (1e-12 m).
 *     The old stop, `sc != s − ds` after s = sc + ds, tested the rounding
 *     of that sum: it ended one of these 800 projections early (7.8e-7 m
 *     off) and returned 50.71 mm for the point past the tip from mid-needle
 *     (on the phantom: a shaft point's s at step 30 of the adaptive run,
 *     3.5e-7 m off with solver.refactor auto and not with every).
 *  2. The tip disc's in-plane frame: the disc of radius 1.5 mm across the
 *     needle's tangent n = (1, ε₁, ε₂), straddling cell faces (its samples
 *     in four cells, so the ring rule, 6 and 12 points, is not invariant
 *     under a quarter turn). With the tool's frame, e1 along d2 = (0, 1, 0),
 *     the weights for (ε₁, ε₂) = (1e-15, 2e-15) and (2e-15, 1e-15) agree to 1e-12; the
 *     axis rule (ref NULL: e1 the axis least aligned with n) turns the
 *     rings by a quarter turn between the two and must differ (> 1e-4: the
 *     check that this configuration sees the rule at all).
 * NH_VERBOSE=1 prints the numbers. */
#include "beam/beam.h"
#include "check.h"
#include "contact/contact_impl.h"
#include "mesh/mesh.h"

#include <string.h>

#define R_ARC 0.1
#define L_T   0.05
#define N_EL  16

/* The needle bent on the circle of radius R_ARC in the x-y plane, tangent
 * to x at its base (the origin). */
static nh_beam *bent_needle(void) {
  nh_beam_spec sp = {.section = {200e9, 0.3, 0.0005, 0.0, 7800},
                     .base = {0, 0, 0},
                     .direction = {1, 0, 0},
                     .length = L_T,
                     .elements = N_EL,
                     .normal = {0, 1, 0}};
  nh_beam *b = NULL;
  CHECK_OK(nh_beam_create(&sp, &b));
  double *x = nh_beam_positions(b), *T = nh_beam_directors(b);
  for (int a = 0; a <= N_EL; a++) {
    const double ph = L_T * a / N_EL / R_ARC, c = cos(ph), s = sin(ph);
    x[3 * a] = R_ARC * s, x[3 * a + 1] = R_ARC * (1.0 - c), x[3 * a + 2] = 0.0;
    const double Ta[9] = {c, -s, 0, s, c, 0, 0, 0, 1}; /* columns d1, d2, d3 */
    memcpy(T + 9 * a, Ta, sizeof Ta);
  }
  return b;
}

static void projections(int verbose) {
  nh_beam *b = bent_needle();
  double worst = 0.0;
  int off = 0;
  for (int k = 0; k < 400; k++) {
    const double s_star = L_T * (0.02 + 0.96 * (k + 0.5) / 400.0), ph = s_star / R_ARC;
    const double a = 5e-4 * nh_rand(), z = 5e-4 * nh_rand();
    /* the circle's point, its inward normal (towards the centre) and z */
    const double x[3] = {R_ARC * sin(ph) - a * sin(ph), R_ARC * (1.0 - cos(ph)) + a * cos(ph), z};
    const double starts[2] = {s_star + 2e-4, L_T};
    for (int q = 0; q < 2; q++) {
      const double s = nh_tool_project(b, x, starts[q]), e = fabs(s - s_star);
      worst = fmax(worst, e);
      if (!(e <= 1e-8)) {
        if (off++ < 5)
          fprintf(stderr, "projection: s* = %.17g from %.17g: got %.17g (|diff| %.3g > 1e-8)\n",
                  s_star, starts[q], s, e);
      }
    }
  }
  CHECK(off == 0, "%d of 800 projections on the bent needle off by more than 1e-8 m", off);
  /* beyond the ends: the ends' tangent extrapolation */
  double xe[3], te[3];
  nh_beam_point(b, L_T, xe, te, NULL, NULL, NULL);
  const double past[3] = {xe[0] + 1e-3 * te[0], xe[1] + 1e-3 * te[1], xe[2] + 1e-3 * te[2]};
  CHECK_CLOSE(nh_tool_project(b, past, L_T), L_T + 1e-3, 1e-12, "1 mm past the tip");
  CHECK_CLOSE(nh_tool_project(b, past, 0.5 * L_T), L_T + 1e-3, 1e-12, "1 mm past the tip (mid)");
  const double behind[3] = {-1e-3, 0.0, 0.0};
  CHECK_CLOSE(nh_tool_project(b, behind, 0.5 * L_T), -1e-3, 1e-12, "1 mm behind the base");
  if (verbose) printf("projections: largest |s - s*| %.3g m\n", worst);
  nh_beam_destroy(&b);
}

/* Largest difference of two discs' weights, node by node. */
static double disc_difference(const nh_disc *d1, const nh_disc *d2) {
  double diff = 0.0;
  for (int k = 0; k < d1->n; k++) {
    double w2 = 0.0;
    for (int j = 0; j < d2->n; j++)
      if (d2->node[j] == d1->node[k]) w2 = d2->w[j];
    diff = fmax(diff, fabs(d1->w[k] - w2));
  }
  for (int j = 0; j < d2->n; j++) {
    int found = 0;
    for (int k = 0; k < d1->n; k++) found |= d1->node[k] == d2->node[j];
    if (!found) diff = fmax(diff, fabs(d2->w[j]));
  }
  return diff;
}

static void discs(int verbose) {
  const double lo[3] = {0, 0, 0}, hi[3] = {0.01, 0.01, 0.01};
  const int grid[3] = {4, 4, 4};
  nh_mesh *m = NULL;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  nh_cpoint p = {0};
  const double X0[3] = {0.0045, 0.0051, 0.0048}; /* the disc straddles y = 5 mm and z = 5 mm */
  CHECK_OK(nh_point_set(m, &p, X0));
  const double n1[3] = {1, 1e-15, 2e-15}, n2[3] = {1, 2e-15, 1e-15}, d2[3] = {0, 1, 0};
  nh_disc a = {0}, b = {0};
  CHECK_OK(nh_disc_build(&a, m, &p, n1, d2, 1.5e-3));
  CHECK_OK(nh_disc_build(&b, m, &p, n2, d2, 1.5e-3));
  const double tool = disc_difference(&a, &b);
  CHECK(tool <= 1e-12, "tool frame: weights differ by %.3g, expected <= 1e-12", tool);
  CHECK_OK(nh_disc_build(&a, m, &p, n1, NULL, 1.5e-3));
  CHECK_OK(nh_disc_build(&b, m, &p, n2, NULL, 1.5e-3));
  const double axis = disc_difference(&a, &b);
  CHECK(axis > 1e-4, "axis rule: weights differ by %.3g, expected > 1e-4 (a quarter turn)", axis);
  if (verbose) printf("discs: tool frame %.3g, axis rule %.3g\n", tool, axis);
  nh_disc_free(&a), nh_disc_free(&b);
  nh_mesh_destroy(&m);
}

int main(void) {
  const int verbose = getenv("NH_VERBOSE") != NULL;
  projections(verbose);
  discs(verbose);
  TEST_END();
}
