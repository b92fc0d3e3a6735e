/* test_hex_kernels — the written-out element kernels equal their
 * definitions bit for bit (docs/performance.md, "The adaptive phantom step").
 *   1. nh_hex_corot_tangent for a corotational frame without B-bar is
 *      R K0 Rᵀ block by block; the reference forms each 3x3 block with
 *      nh_mat3_mul and nh_mat3_mul_nt, as the kernel did before it was
 *      written out: memcmp equal, for 50 distorted and rotated elements.
 *   2. nh_hex_inverted is the guard's test !(nh_hex_det(x, ξ) > 0) at the 8
 *      corners and the 2x2x2 Gauss points, computed here point by point
 *      through nh_hex_det: the same answer for 2000 random hexahedra from
 *      mildly to badly distorted (about half inverted), and for a cube, a
 *      mirrored cube, a cube with one corner pushed through the opposite
 *      face (inverted at that corner only) and a flattened one. */
#include "check.h"
#include "fem/fem.h"

#include <string.h>

static int inverted_by_definition(const double x[24]) {
  const double g = 0.57735026918962576; /* 1/√3 */
  for (int p = 0; p < 16; p++) {
    double a = p < 8 ? 1.0 : g;
    double xi[3] = {(p & 1) ? a : -a, (p & 2) ? a : -a, (p & 4) ? a : -a};
    if (!(nh_hex_det(x, xi) > 0.0)) return 1;
  }
  return 0;
}

static void cube(double L, double x[24]) {
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) x[3 * a + k] = 0.5 * L * nh_hex_corner[a][k];
}

int main(void) {
  /* 1. R K0 Rᵀ */
  double lambda, mu;
  nh_lame(1e7, 0.4, &lambda, &mu);
  for (int trial = 0; trial < 50; trial++) {
    double X[24], u[24], K0[576], G0[24], vol, Kt[576], frame[NH_HEX_FRAME], f[24];
    cube(0.01, X);
    for (int i = 0; i < 24; i++) X[i] += 0.002 * nh_rand();
    CHECK_OK(nh_hex_stiffness(X, lambda, mu, 0, K0, G0, NULL, &vol));
    for (int i = 0; i < 24; i++) u[i] = 0.003 * nh_rand(); /* a turn of up to ~0.5 rad */
    nh_hex_corot_force(X, u, K0, G0, NULL, frame, f);
    nh_hex_frame_corotational(frame);
    nh_hex_corot_tangent(K0, G0, NULL, frame, Kt);
    const double *R = frame + NH_FRAME_R;
    int same = 1;
    for (int a = 0; a < 8; a++)
      for (int c = 0; c < 8; c++) {
        double B[9], T[9];
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++) B[3 * i + j] = K0[24 * (3 * a + i) + 3 * c + j];
        nh_mat3_mul(R, B, T);
        nh_mat3_mul_nt(T, R, B);
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++)
            same &= memcmp(&Kt[24 * (3 * a + i) + 3 * c + j], &B[3 * i + j], sizeof(double)) == 0;
      }
    CHECK(same, "trial %d: R K0 Rᵀ differs from the nh_mat3 products", trial);
  }

  /* 2. the inversion test */
  double x[24];
  cube(1.0, x);
  CHECK(!nh_hex_inverted(x) && !inverted_by_definition(x), "the unit cube");
  for (int a = 0; a < 8; a++) x[3 * a + 2] = -x[3 * a + 2];
  CHECK(nh_hex_inverted(x) && inverted_by_definition(x), "the mirrored cube");
  cube(1.0, x);
  for (int k = 0; k < 3; k++) x[18 + k] = -0.45; /* corner 6 through to near corner 0 */
  CHECK(nh_hex_inverted(x) == inverted_by_definition(x) && nh_hex_inverted(x),
        "a corner pushed through");
  cube(1.0, x);
  for (int a = 0; a < 8; a++) x[3 * a + 2] *= 1e-300; /* flat: det > 0 but J singular */
  CHECK(nh_hex_inverted(x) && inverted_by_definition(x), "the flattened cube");
  int agree = 0, bad = 0;
  for (int trial = 0; trial < 2000; trial++) {
    double amp = 0.1 + 0.5 * (trial % 10) / 9.0;
    cube(1.0, x);
    for (int i = 0; i < 24; i++) x[i] += amp * nh_rand();
    int d = inverted_by_definition(x);
    agree += nh_hex_inverted(x) == d, bad += d;
  }
  CHECK(agree == 2000, "nh_hex_inverted differs from the definition in %d of 2000", 2000 - agree);
  CHECK(bad > 200 && bad < 1800, "%d of 2000 inverted: the sample does not test both answers", bad);
  TEST_END();
}
