/* test_dwr_kernel — the goal estimate's Gauss-point kernel
 * (nh_dwr_dual_terms, adapt/dwr.c) against the terms formed one point at a
 * time from their definitions (docs/theory.md §6.6, "B-bar"; dwr.c header):
 * at each of the 8 points,
 *   σ_h(z)  = nh_hex_rotated_stress(R, d, g, λ, μ, θ̄) with d = Rᵀ w node by
 *             node (fem/hex.c: ε of the corotated values, rotated back; the
 *             kernel forms H = Σₐ wₐ ⊗ R gₐ instead),
 *   σ*_z    = Σₐ N_a σ*_a of the nodal values (through the corner list and
 *             the stride, corners permuted),
 *   e_z     = σ*_z − σ_h(z),  D⁻¹ e_z by nh_voigt_compliance,
 *   a1      = e_zᵀ (D⁻¹ e_u) − e_p,u (I − Π) div z − e_p,z (I − Π) div u
 *             (B-bar; (I − Π) div z = Σₐ dₐ·(gₐ − ḡₐ) of the corotated values,
 *             e_p,z = tr e_z / 3),
 *   a2      = e_zᵀ D⁻¹ e_z,
 * and *eps = Σ det J a1, *ezz = Σ det J a2. Random cells: a rotation, point
 * gradients and their element mean, nodal values of the dual and of the
 * recovered stress, the primal's D⁻¹ e_u, e_p,u and (I − Π) div u, each of a
 * size that makes every term of a1 of the order of μ, so that dropping or
 * misplacing any of them moves eps by O(μ) against a tolerance of 1e-12 of
 * the terms' sizes. Full integration and B-bar, 50 cells each. */
#include "check.h"
#include "adapt/adapt_impl.h"
#include "fem/fem.h"

#include <string.h>

#define CELLS 50

/* The reference of one cell (the arguments as nh_dwr_dual_terms', with the
 * corotated inputs the kernel does not take: g[gp] the point gradients,
 * gbar their mean). *scale: Σ det J (|e_z|·|D⁻¹e_u| + |e_p,u dz| + |e_p,z
 * dev_u| + e_zᵀD⁻¹e_z), the size the terms' round-off is relative to. */
static void reference(const double R[9], const double w[24], const double g[8][24],
                      const double gbar[24], const double *zstar, size_t stride,
                      const int corner[8], const double NT[8][8], double lambda, double mu,
                      int bbar, double tz, const double ceuT[6][8], const double pu[8],
                      const double dev_u[8], const double detJ[8], double *eps, double *ezz,
                      double *scale) {
  double d[24];
  for (int a = 0; a < 8; a++) /* d_a = Rᵀ w_a */
    for (int i = 0; i < 3; i++)
      d[3 * a + i] = R[i] * w[3 * a] + R[3 + i] * w[3 * a + 1] + R[6 + i] * w[3 * a + 2];
  *eps = *ezz = *scale = 0.0;
  for (int gp = 0; gp < 8; gp++) {
    double sh[6], ss[6] = {0}, ez[6], cez[6], a1 = 0.0, a2 = 0.0, s1 = 0.0;
    nh_hex_rotated_stress(R, d, g[gp], lambda, mu, bbar ? &tz : NULL, sh);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 6; k++) ss[k] += NT[a][gp] * zstar[stride * (size_t)corner[a] + k];
    for (int k = 0; k < 6; k++) ez[k] = ss[k] - sh[k];
    nh_voigt_compliance(lambda, mu, ez, cez);
    for (int k = 0; k < 6; k++) {
      a1 += ez[k] * ceuT[k][gp], a2 += ez[k] * cez[k];
      s1 += fabs(ez[k] * ceuT[k][gp]);
    }
    if (bbar) {
      double dz = 0.0, pz = (ez[0] + ez[1] + ez[2]) / 3.0;
      for (int i = 0; i < 24; i++) dz += d[i] * (g[gp][i] - gbar[i]);
      a1 -= pu[gp] * dz + pz * dev_u[gp];
      s1 += fabs(pu[gp] * dz) + fabs(pz * dev_u[gp]);
    }
    *eps += detJ[gp] * a1;
    *ezz += detJ[gp] * a2;
    *scale += detJ[gp] * (s1 + fabs(a2));
  }
}

int main(void) {
  const double E = 1.0e4, nu = 0.45, h = 1e-3; /* a 1 mm cell of soft tissue */
  const double lambda = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
  const int corner[8] = {5, 2, 7, 0, 3, 6, 1, 4};
  enum { FIELDS = 3, FIELD = 1 }; /* the dual's recovered stress: field 1 of 3 per node */
  const size_t stride = 6 * FIELDS;
  double zstar_all[8 * 6 * FIELDS];
  double worst[2] = {0.0, 0.0};
  for (int bbar = 0; bbar < 2; bbar++)
    for (int cell = 0; cell < CELLS; cell++) {
      double rv[3] = {2.0 * nh_rand(), 2.0 * nh_rand(), 2.0 * nh_rand()}, R[9];
      nh_mat3_rotation(rv, R);
      double g[8][24], gbar[24], w[24], RgT[24][8], RdivT[24][8], NT[8][8];
      double ceuT[6][8], pu[8], dev_u[8], detJ[8];
      for (int i = 0; i < 24; i++) gbar[i] = nh_rand() / h;
      for (int gp = 0; gp < 8; gp++)
        for (int i = 0; i < 24; i++) g[gp][i] = gbar[i] + 0.3 * nh_rand() / h;
      for (int i = 0; i < 24; i++) w[i] = 1e-4 * h * nh_rand(); /* strains ~1e-4 */
      for (int gp = 0; gp < 8; gp++) {
        for (int a = 0; a < 8; a++) {
          NT[a][gp] = 0.5 * (1.0 + nh_rand()); /* weights in (0, 1) */
          for (int j = 0; j < 3; j++) {
            double rg = 0.0, rd = 0.0;
            for (int k = 0; k < 3; k++) {
              rg += R[3 * j + k] * g[gp][3 * a + k];
              rd += R[3 * j + k] * (g[gp][3 * a + k] - gbar[3 * a + k]);
            }
            RgT[3 * a + j][gp] = rg, RdivT[3 * a + j][gp] = rd;
          }
        }
        for (int k = 0; k < 6; k++) ceuT[k][gp] = 1e-4 * nh_rand(); /* D⁻¹ e_u: a strain */
        pu[gp] = 1e-4 * mu * nh_rand();                             /* e_p,u: a stress */
        dev_u[gp] = 1e-4 * nh_rand();                               /* (I − Π) div u */
        detJ[gp] = h * h * h / 8.0 * (1.0 + 0.5 * nh_rand());
      }
      for (size_t i = 0; i < sizeof zstar_all / sizeof *zstar_all; i++)
        zstar_all[i] = 1e-4 * mu * nh_rand();
      const double tz = 1e-4 * nh_rand(), *zstar = zstar_all + 6 * FIELD;
      double eps, ezz, re, rz, scale;
      nh_dwr_dual_terms(w, RgT, RdivT, zstar, stride, corner, NT, lambda, mu, bbar, tz, ceuT, pu,
                        dev_u, detJ, &eps, &ezz);
      reference(R, w, g, gbar, zstar, stride, corner, NT, lambda, mu, bbar, tz, ceuT, pu, dev_u,
                detJ, &re, &rz, &scale);
      CHECK(scale > 0.0 && isfinite(eps) && isfinite(ezz), "cell %d: scale %g", cell, scale);
      CHECK_CLOSE(eps, re, 1e-12 * scale, bbar ? "eps (B-bar)" : "eps (full)");
      CHECK_CLOSE(ezz, rz, 1e-12 * scale, bbar ? "ezz (B-bar)" : "ezz (full)");
      worst[bbar] = fmax(worst[bbar], fmax(fabs(eps - re), fabs(ezz - rz)) / scale);
    }
  if (getenv("NH_VERBOSE"))
    printf("largest difference / scale: full %.3g, B-bar %.3g\n", worst[0], worst[1]);
  TEST_END();
}
