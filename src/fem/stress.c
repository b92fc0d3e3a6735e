/* stress.c — the corotational stress anywhere inside an element, the
 * isotropic compliance D⁻¹ in Voigt form and the von Mises stress (used by
 * the frames' von_mises, the SPR error estimator, adapt/spr.c, and the
 * goal-oriented one, adapt/dwr.c; docs/theory.md §2 and the seed's Eq. 15).
 *
 * Place in fem: above the element (hex.c gives the rotation, the corotated
 * displacements, the gradients and θ̄), below the tissue (tissue.c
 * evaluates these stresses for its cells: nh_tissue_gauss_stress,
 * nh_tissue_cell_stress). One element's numbers in, no mesh, no cache.
 *
 * The element is the one of hex.c: one rotation R per element, the polar
 * rotation of the deformation gradient at the centre
 *   F = I + Σₐ uₐ ⊗ G0ₐ,   R = polar(F),
 * and the corotated nodal displacements relative to the rest centroid X̄
 *   dₐ = Rᵀuₐ + (Rᵀ − I)(Xₐ − X̄).
 * The small strain at a natural point ξ is that of d with the rest gradients
 * at ξ, gₐ(ξ) = J(ξ)⁻ᵀ ∇_ξ Nₐ(ξ):
 *   ε(ξ) = sym(Σₐ dₐ ⊗ gₐ(ξ)),   σ(ξ) = R (λ tr ε I + 2 μ ε) Rᵀ.
 * R stays the centre's (it is not re-evaluated at ξ): this is the stress
 * field whose energy the element's K₀ integrates, so ∫ σᵀD⁻¹σ over the
 * 2x2x2 Gauss points is twice the element's corotational strain energy. At
 * ξ = 0, gₐ(0) = G0ₐ: the centre stress of the frames and of SPR.
 *
 * B-bar (mean dilatation, docs/theory.md §2b): the volumetric part is the
 * element's mean, σ(ξ) = κ θ̄ I + R (2 μ dev ε(ξ)) Rᵀ with κ = λ + ⅔μ and
 * θ̄ = det F̄ − 1, F̄ = I + Σₐ uₐ ⊗ ḡₐ, ḡₐ the volume average of gₐ
 * (hex.c); again the stress whose energy the element carries.
 *
 * Compliance. With Voigt stresses s = (σxx, σyy, σzz, σyz, σxz, σxy) and
 * engineering strains e = (εxx, εyy, εzz, γyz, γxz, γxy), γ = 2ε:
 *   εᵢᵢ = (σᵢᵢ − λ / (3λ + 2μ) tr σ) / (2μ),   γᵢⱼ = σᵢⱼ / μ,
 * so that sᵀe = σ : ε and ½ sᵀ D⁻¹ s is the strain-energy density.
 *
 * von Mises: σ_vM = √(½((σxx−σyy)² + (σyy−σzz)² + (σzz−σxx)²)
 *                    + 3(σyz² + σxz² + σxy²)). */
#include "fem/fem.h"

#include <math.h>
#include <string.h>

/* σ at one point from R, the corotated nodal values d and the gradients g:
 * full, λ tr ε I + 2με (theta_bar NULL); B-bar, κ θ̄ I + 2μ dev ε
 * (κ = λ + ⅔μ, θ̄ = *theta_bar the element's mean volume change). */
static void nh_point_stress(const double R[9], const double d[24], const double g[24],
                            double lambda, double mu, const double *theta_bar, double s[6]) {
  double H[9] = {0}, S[9], T[9];
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) H[3 * i + j] += d[3 * a + i] * g[3 * a + j];
  double tr = H[0] + H[4] + H[8];
  double vol =
      theta_bar ? (lambda + 2.0 * mu / 3.0) * *theta_bar - 2.0 * mu / 3.0 * tr : lambda * tr;
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      S[3 * i + j] = mu * (H[3 * i + j] + H[3 * j + i]) + (i == j ? vol : 0.0);
  nh_mat3_mul(R, S, T);
  nh_mat3_mul_nt(T, R, S);
  s[0] = S[0], s[1] = S[4], s[2] = S[8], s[3] = S[5], s[4] = S[2], s[5] = S[1];
}

void nh_hex_rotated_stress(const double R[9], const double d[24], const double g[24], double lambda,
                           double mu, const double *theta_bar, double s[6]) {
  nh_point_stress(R, d, g, lambda, mu, theta_bar, s);
}

/* nh_hex_stress_at with the rest gradients of its n points given (g[24 n]). */
static void nh_hex_stress_with(const double X[24], const double u[24], const double G0[24],
                               const double *Gbar, double lambda, double mu, int n, const double *g,
                               double *s) {
  /* The rotation and corotated displacements of the element, as hex.c. */
  double R[9], d[24];
  nh_hex_corotated(X, u, G0, R, d);
  /* B-bar: the mean volume change θ̄ = det F̄ − 1, one per element. */
  double mean_dilatation = Gbar ? nh_hex_mean_dilatation(u, Gbar, NULL) : 0.0;
  for (int p = 0; p < n; p++)
    nh_point_stress(R, d, g + 24 * p, lambda, mu, Gbar ? &mean_dilatation : NULL, s + 6 * p);
}

void nh_hex_stress_at(const double X[24], const double u[24], const double G0[24],
                      const double *Gbar, double lambda, double mu, int n, const double *xi,
                      double *s, double *detJ) {
  double g[24 * 9];
  for (int p0 = 0; p0 < n; p0 += 9) { /* 9 points at a time (callers ask for 1, 8 or 9) */
    const int k = n - p0 < 9 ? n - p0 : 9;
    for (int p = 0; p < k; p++) {
      double det = nh_hex_rest_gradients(X, G0, xi + 3 * (p0 + p), g + 24 * p);
      if (detJ) detJ[p0 + p] = det;
    }
    nh_hex_stress_with(X, u, G0, Gbar, lambda, mu, k, g, s + 6 * p0);
  }
}

double nh_hex_rest_gradients(const double X[24], const double G0[24], const double xi[3],
                             double g[24]) {
  memcpy(g, G0, 24 * sizeof(double));
  return nh_hex_gradients(X, xi, g);
}

void nh_voigt_compliance(double lambda, double mu, const double s[6], double e[6]) {
  double tr = s[0] + s[1] + s[2], k = lambda / (3.0 * lambda + 2.0 * mu) * tr;
  for (int i = 0; i < 3; i++) e[i] = (s[i] - k) / (2.0 * mu);
  for (int i = 3; i < 6; i++) e[i] = s[i] / mu;
}

double nh_von_mises(const double s[6]) {
  double a = s[0] - s[1], b = s[1] - s[2], c = s[2] - s[0];
  return sqrt(0.5 * (a * a + b * b + c * c) + 3.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5]));
}
