/* test_rotation — rigid-rotation invariance of the corotational hexahedron.
 *   1. x = Q X + t for any rotation Q (angles up to π) and translation t
 *      gives f = 0 (to round-off relative to |K0| |X|).
 *   2. For a deformed state x₁ and its rigidly moved copy x₂ = Q x₁ + t:
 *      f(x₂) = Q f(x₁) per node and K(x₂) = Q K(x₁) Qᵀ per 3x3 block.
 * The element is a distorted hexahedron (corners perturbed by 20 %). Both
 * formulations (fully integrated, B-bar), at ν = 0.45 and ν = 0.4999: B-bar
 * only changes K0, which the rotation acts on as on any K0. */
#include "check.h"
#include "fem/fem.h"

static void rotate_nodes(const double Q[9], const double t[3], const double *a, double *b) {
  for (int n = 0; n < 8; n++) {
    nh_mat3_vec(Q, a + 3 * n, b + 3 * n);
    for (int k = 0; k < 3; k++) b[3 * n + k] += t[k];
  }
}

static void check(double nu, int bbar) {
  const double E = 1e4, L = 0.01;
  double lambda, mu;
  nh_lame(E, nu, &lambda, &mu);
  for (int trial = 0; trial < 50; trial++) {
    double X[24], K0[576], G0[24], vol;
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) X[3 * a + k] = L * (0.5 * nh_hex_corner[a][k] + 0.1 * nh_rand());
    double Gbar[24];
    CHECK_OK(nh_hex_stiffness(X, lambda, mu, bbar, K0, G0, Gbar, &vol));
    nh_hex_volumetric vp = {Gbar, lambda + 2.0 * mu / 3.0, vol}, *vpp = bbar ? &vp : NULL;
    double knorm = 0.0;
    for (int i = 0; i < 576; i++) knorm = fmax(knorm, fabs(K0[i]));
    if (bbar) knorm = fmax(knorm, vp.kappa * vol / (L * L)); /* κ V |ḡ|² */
    const double ftol = 1e-12 * knorm * L;

    double r[3] = {nh_rand(), nh_rand(), nh_rand()}, Q[9], R[9], f[24], t[3];
    double n = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    double angle = trial == 0 ? M_PI : M_PI * (trial / 50.0); /* includes 0 and π */
    for (int k = 0; k < 3; k++) r[k] *= angle / n, t[k] = 10 * L * nh_rand();
    nh_mat3_rotation(r, Q);

    double x[24], u[24];
    rotate_nodes(Q, t, X, x);
    for (int i = 0; i < 24; i++) u[i] = x[i] - X[i];
    nh_hex_corot(X, u, K0, G0, vpp, R, f, NULL);
    for (int i = 0; i < 24; i++) CHECK_CLOSE(f[i], 0.0, ftol, "force after a rigid motion");

    /* A deformed state (strains up to 10 %) and its rigidly moved copy. */
    double x1[24], x2[24], f1[24], f2[24], K1[576], K2[576], R1[9], R2[9];
    for (int i = 0; i < 24; i++) x1[i] = X[i] + 0.05 * L * nh_rand();
    rotate_nodes(Q, t, x1, x2);
    double u1[24], u2[24];
    for (int i = 0; i < 24; i++) u1[i] = x1[i] - X[i], u2[i] = x2[i] - X[i];
    nh_hex_corot(X, u1, K0, G0, vpp, R1, f1, K1);
    nh_hex_corot(X, u2, K0, G0, vpp, R2, f2, K2);
    double fmax1 = 0.0;
    for (int i = 0; i < 24; i++) fmax1 = fmax(fmax1, fabs(f1[i]));
    CHECK(fmax1 > 1e3 * ftol, "deformed state gives no force (%g)", fmax1);
    for (int a = 0; a < 8; a++) {
      double qf[3];
      nh_mat3_vec(Q, f1 + 3 * a, qf);
      for (int k = 0; k < 3; k++) CHECK_CLOSE(f2[3 * a + k], qf[k], ftol, "f(Qx) = Q f(x)");
    }
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++) {
        double B[9], T[9];
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++) B[3 * i + j] = K1[24 * (3 * a + i) + 3 * b + j];
        nh_mat3_mul(Q, B, T);
        nh_mat3_mul_nt(T, Q, B);
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++)
            CHECK_CLOSE(K2[24 * (3 * a + i) + 3 * b + j], B[3 * i + j], 1e-12 * knorm,
                        "K(Qx) = Q K(x) Qᵀ");
      }
  }
  /* An inverted element (det F < 0) gives finite forces. */
  double X[24], x[24], K0[576], G0[24], vol, R[9], f[24];
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) X[3 * a + k] = x[3 * a + k] = L * 0.5 * nh_hex_corner[a][k];
  double Gbar[24];
  CHECK_OK(nh_hex_stiffness(X, lambda, mu, bbar, K0, G0, Gbar, &vol));
  nh_hex_volumetric vp = {Gbar, lambda + 2.0 * mu / 3.0, vol};
  double u[24];
  for (int a = 0; a < 8; a++) x[3 * a + 2] = -x[3 * a + 2]; /* mirror: det F = -1 */
  for (int i = 0; i < 24; i++) u[i] = x[i] - X[i];
  nh_hex_corot(X, u, K0, G0, bbar ? &vp : NULL, R, f, NULL);
  for (int i = 0; i < 24; i++) CHECK(isfinite(f[i]), "inverted element: f[%d] not finite", i);
}

int main(void) {
  for (int bbar = 0; bbar < 2; bbar++) {
    check(0.45, bbar);
    check(0.4999, bbar);
  }
  TEST_END();
}
