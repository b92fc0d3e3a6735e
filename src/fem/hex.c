/* hex.c — the corotational trilinear hexahedron (docs/theory.md §2, the
 * seed's Eqs. 3-4 and 10 for one element).
 *
 * K₀ is integrated by 2x2x2 Gauss points (exact for the trilinear element on
 * parallelepipeds). For isotropic elasticity the 3x3 block coupling nodes a
 * and b needs no B matrix:
 *   K_ab = Σ_g w_g det J_g [ λ gₐ ⊗ g_b + μ g_b ⊗ gₐ + μ (gₐ·g_b) I ]
 * with gₐ = ∇_X Nₐ at the Gauss point; this is Bᵀ D B written out.
 * The rotation is that of F at the centre (Müller & Gross 2004); the tangent
 * drops the variation of R (the usual corotational approximation: one
 * linearisation per step converges to the same equilibrium, docs/theory.md
 * §2, "Internal force and tangent").
 *
 * Precision: the state is the displacement u, not the position x. With
 * F = I + Σ uₐ ⊗ gₐ and, relative to the rest centroid X̄,
 *   d = Rᵀx − X = Rᵀ uₐ + (Rᵀ − I)(Xₐ − X̄)      (K₀ kills the translation),
 * no term carries the magnitude of the coordinates, so a strain of 1e-6 in a
 * body far from the origin keeps full relative precision. With positions,
 * the residual has a floor near eps |K| |x|, which stalls Newton at 1e-11
 * relative on the cantilever (measured before this change). */
#include "fem/fem.h"

#include <math.h>
#include <string.h>

void nh_lame(double E, double nu, double *lambda, double *mu) {
  *lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
  *mu = E / (2 * (1 + nu));
}

double nh_hex_gradients(const double X[24], const double xi[3], double g[24]) {
  double dN[8][3], J[9] = {0}, Jinv[9];
  nh_hex_dshape(xi, dN);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) J[3 * i + j] += X[3 * a + i] * dN[a][j];
  double det = nh_mat3_det(J);
  if (!(det > 0.0) || nh_mat3_inverse(J, Jinv)) return det > 0.0 ? 0.0 : det;
  /* g_a = J⁻ᵀ ∇_ξ N_a */
  for (int a = 0; a < 8; a++) nh_mat3_tvec(Jinv, dN[a], g + 3 * a);
  return det;
}

int nh_hex_stiffness(const double X[24], double lambda, double mu, double K0[576], double G0[24],
                     double *volume) {
  static const double q = 0.57735026918962576451; /* 1/√3 */
  memset(K0, 0, 576 * sizeof(double));
  double vol = 0.0;
  for (int gp = 0; gp < 8; gp++) {
    double xi[3] = {q * nh_hex_corner[gp][0], q * nh_hex_corner[gp][1], q * nh_hex_corner[gp][2]};
    double g[24];
    double det = nh_hex_gradients(X, xi, g);
    if (!(det > 0.0)) return NH_ERR_NUMERIC;
    vol += det;
    for (int a = 0; a < 8; a++)
      for (int b = 0; b < 8; b++) {
        const double *ga = g + 3 * a, *gb = g + 3 * b;
        double dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++)
            K0[24 * (3 * a + i) + 3 * b + j] +=
                det * (lambda * ga[i] * gb[j] + mu * gb[i] * ga[j] + (i == j ? mu * dot : 0.0));
      }
  }
  const double centre[3] = {0, 0, 0};
  if (!(nh_hex_gradients(X, centre, G0) > 0.0)) return NH_ERR_NUMERIC;
  *volume = vol;
  return NH_OK;
}

/* F = I + Σ uₐ ⊗ gₐ, its polar rotation R, and the corotated displacement
 * d = Rᵀ uₐ + (Rᵀ − I)(Xₐ − X̄) of every node. */
void nh_hex_corotated(const double X[24], const double u[24], const double G0[24], double R[9],
                      double d[24]) {
  double F[9];
  nh_mat3_identity(F);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) F[3 * i + j] += u[3 * a + i] * G0[3 * a + j];
  nh_polar_rotation(F, R);
  double c[3] = {0, 0, 0};
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++) c[i] += 0.125 * X[3 * a + i];
  for (int a = 0; a < 8; a++) {
    double rel[3] = {X[3 * a] - c[0], X[3 * a + 1] - c[1], X[3 * a + 2] - c[2]}, rr[3];
    nh_mat3_tvec(R, u + 3 * a, d + 3 * a);
    nh_mat3_tvec(R, rel, rr);
    for (int i = 0; i < 3; i++) d[3 * a + i] += rr[i] - rel[i];
  }
}

void nh_hex_corot(const double X[24], const double u[24], const double K0[576], const double G0[24],
                  double R[9], double f[24], double Kt[576]) {
  double d[24], fl[24];
  nh_hex_corotated(X, u, G0, R, d);
  for (int r = 0; r < 24; r++) {
    const double *row = K0 + 24 * r;
    double s = 0.0;
    for (int c = 0; c < 24; c++) s += row[c] * d[c];
    fl[r] = s;
  }
  for (int a = 0; a < 8; a++) nh_mat3_vec(R, fl + 3 * a, f + 3 * a);
  if (!Kt) return;
  for (int a = 0; a < 8; a++)
    for (int b = 0; b < 8; b++) {
      double B[9], T[9];
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) B[3 * i + j] = K0[24 * (3 * a + i) + 3 * b + j];
      nh_mat3_mul(R, B, T);
      nh_mat3_mul_nt(T, R, B);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Kt[24 * (3 * a + i) + 3 * b + j] = B[3 * i + j];
    }
}

void nh_hex_center_stress(const double X[24], const double u[24], const double G0[24],
                          double lambda, double mu, double s[6]) {
  double R[9], d[24];
  nh_hex_corotated(X, u, G0, R, d);
  nh_hex_rotated_stress(R, d, G0, lambda, mu, s);
}

double nh_von_mises(const double s[6]) {
  double a = s[0] - s[1], b = s[1] - s[2], c = s[2] - s[0];
  return sqrt(0.5 * (a * a + b * b + c * c) + 3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
}
