/* test_polar — the polar rotation of core/mat3.c.
 * For any F: R is a proper rotation (RᵀR = I, det R = +1) and finite.
 * For det F > 0: RᵀF is symmetric positive definite (the polar factor U).
 * For det F < 0: RᵀF is symmetric with exactly one negative eigenvalue, the
 * one of smallest magnitude (rotation-variant SVD). F = Q (a rotation) gives
 * R = Q to round-off; rank-deficient and zero F give a rotation, no NaN. */
#include "check.h"
#include "core/core.h"

static void check_rotation(const double R[9], const char *what) {
  double RtR[9];
  nh_mat3_mul_tn(R, R, RtR);
  for (int i = 0; i < 9; i++) {
    CHECK(isfinite(R[i]), "%s: R not finite", what);
    CHECK_CLOSE(RtR[i], i % 4 == 0 ? 1.0 : 0.0, 1e-13, what);
  }
  CHECK_CLOSE(nh_mat3_det(R), 1.0, 1e-13, what);
}

int main(void) {
  for (int trial = 0; trial < 2000; trial++) {
    double F[9], R[9], U[9], w[3], V[9];
    for (int i = 0; i < 9; i++) F[i] = nh_rand();
    if (trial % 4 == 1) /* an inverted element: reflect */
      for (int i = 0; i < 3; i++) F[3 * i] = -F[3 * i];
    nh_polar_rotation(F, R);
    check_rotation(R, "random F");
    nh_mat3_mul_tn(R, F, U);
    double scale = fabs(U[0]) + fabs(U[4]) + fabs(U[8]) + 1e-300;
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++)
        CHECK_CLOSE(U[3 * i + j], U[3 * j + i], 1e-12 * scale, "RᵀF symmetric");
    nh_mat3_sym_eigen(U, w, V);
    double det = nh_mat3_det(F);
    if (det > 0) {
      CHECK(w[2] > -1e-12 * scale, "det F > 0 but U has eigenvalue %g", w[2]);
    } else {
      CHECK(w[1] >= -1e-12 * scale && w[2] <= 1e-12 * scale,
            "det F < 0: eigenvalues of U %g %g %g (want one negative, the last)", w[0], w[1], w[2]);
      CHECK(fabs(w[2]) <= fabs(w[1]) + 1e-12 * scale, "negative eigenvalue is not the smallest");
    }
  }
  /* F = Q: R = Q exactly (to round-off), for angles up to π. */
  for (int trial = 0; trial < 200; trial++) {
    double r[3] = {nh_rand(), nh_rand(), nh_rand()}, Q[9], R[9];
    double n = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]), ang = M_PI * (trial + 0.5) / 200;
    for (int k = 0; k < 3; k++) r[k] *= ang / n;
    nh_mat3_rotation(r, Q);
    nh_polar_rotation(Q, R);
    for (int i = 0; i < 9; i++) CHECK_CLOSE(R[i], Q[i], 1e-13, "R(Q) = Q");
  }
  /* Degenerate F: rank 2, rank 1, zero. */
  double F2[9] = {1, 0, 0, 0, 2, 0, 0, 0, 0}, F1[9] = {1, 2, 3, 2, 4, 6, -1, -2, -3}, F0[9] = {0};
  double R[9];
  nh_polar_rotation(F2, R);
  check_rotation(R, "rank 2");
  nh_polar_rotation(F1, R);
  check_rotation(R, "rank 1");
  nh_polar_rotation(F0, R);
  check_rotation(R, "zero F");
  TEST_END();
}
