/* hex.c — the corotational trilinear hexahedron (docs/theory.md §2, the
 * seed's Eqs. 3-4 and 10 for one element).
 *
 * K₀ is integrated by 2x2x2 Gauss points (exact for the trilinear element on
 * parallelepipeds). For isotropic elasticity the 3x3 block coupling nodes a
 * and b needs no B matrix:
 *   K_ab = Σ_g w_g det J_g [ λ gₐ ⊗ g_b + μ g_b ⊗ gₐ + μ (gₐ·g_b) I ]
 * with gₐ = ∇_X Nₐ at the Gauss point; this is Bᵀ D B written out.
 * B-bar (mean dilatation, Hughes 1980, "Generalization of selective
 * integration procedures to anisotropic and nonlinear media"; Nagtegaal,
 * Parks & Rice 1974): K₀ keeps only the deviatoric part, and the volume
 * change is one per element, θ̄ = det F̄ − 1 with F̄ = I + Σ uₐ ⊗ ḡₐ and ḡₐ
 * the volume average of ∇Nₐ, carrying the energy ½ κ V θ̄² (κ = λ + ⅔μ).
 * θ̄ is rotation invariant without R, so R's round-off (which the κ/μ ratio
 * would amplify) does not enter it; for small strain it is the linear B-bar
 * element's Σ ḡₐ·uₐ (docs/theory.md §2b).
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

/* J = Σₐ Xₐ ⊗ ∇_ξ Nₐ(ξ) (∇_ξ Nₐ in dN) and its determinant. */
static double nh_hex_jacobian(const double X[24], const double xi[3], double dN[8][3],
                              double J[9]) {
  memset(J, 0, 9 * sizeof(double));
  nh_hex_dshape(xi, dN);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) J[3 * i + j] += X[3 * a + i] * dN[a][j];
  return nh_mat3_det(J);
}

double nh_hex_det(const double X[24], const double xi[3]) {
  double dN[8][3], J[9];
  const double det = nh_hex_jacobian(X, xi, dN, J);
  return det > 0.0 && nh_mat3_singular(J, det) ? 0.0 : det;
}

/* !(det J > 0) or J singular (nh_hex_det's test) for a corner's J. */
static int nh_hex_bad_jacobian(const double J[9]) {
  const double det = nh_mat3_det(J);
  return !(det > 0.0) || nh_mat3_singular(J, det);
}

/* The corners: at ξ = ξ_p the derivatives ∂N_a/∂ξ_j are ±½ for a = p and
 * p's neighbour along j and exact zeros (±0) for the six others, so J's
 * sums keep only those two terms. A sum that starts at +0 and skips ±0
 * terms gives the same bits (x + ±0 = x for x ≠ 0, +0 + ±0 = +0, and a sum
 * from +0 is never −0), so J is nh_hex_jacobian's. The Gauss points are
 * nh_hex_det's. */
int nh_hex_inverted(const double x[24]) {
  static const double g = 0.57735026918962576; /* 1/√3, as sim/guard.c had it */
  /* p's neighbours along ξ, η, ζ (mesh/mesh.h's corner numbering) */
  static const int along[8][3] = {{1, 3, 4}, {0, 2, 5}, {3, 1, 6}, {2, 0, 7},
                                  {5, 7, 0}, {4, 6, 1}, {7, 5, 2}, {6, 4, 3}};
  for (int p = 0; p < 8; p++) {
    double J[9];
    for (int j = 0; j < 3; j++) {
      const int q = along[p][j], lo = p < q ? p : q, hi = p < q ? q : p;
      const double dlo = 0.5 * nh_hex_corner[lo][j], dhi = 0.5 * nh_hex_corner[hi][j];
      for (int i = 0; i < 3; i++) J[3 * i + j] = (0.0 + x[3 * lo + i] * dlo) + x[3 * hi + i] * dhi;
    }
    if (nh_hex_bad_jacobian(J)) return 1;
  }
  for (int p = 0; p < 8; p++) {
    const double xi[3] = {(p & 1) ? g : -g, (p & 2) ? g : -g, (p & 4) ? g : -g};
    if (!(nh_hex_det(x, xi) > 0.0)) return 1;
  }
  return 0;
}

double nh_hex_gradients(const double X[24], const double xi[3], double g[24]) {
  double dN[8][3], J[9], Jinv[9];
  const double det = nh_hex_jacobian(X, xi, dN, J);
  if (!(det > 0.0) || nh_mat3_inverse(J, Jinv)) return det > 0.0 ? 0.0 : det;
  /* g_a = J⁻ᵀ ∇_ξ N_a */
  for (int a = 0; a < 8; a++) nh_mat3_tvec(Jinv, dN[a], g + 3 * a);
  return det;
}

void nh_hex_point_stiffness(const double g[24], double w, double lambda, double mu, double K[576]) {
  for (int a = 0; a < 8; a++)
    for (int b = 0; b < 8; b++) {
      const double *ga = g + 3 * a, *gb = g + 3 * b;
      double dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
          K[24 * (3 * a + i) + 3 * b + j] +=
              w * (lambda * ga[i] * gb[j] + mu * gb[i] * ga[j] + (i == j ? mu * dot : 0.0));
    }
}

int nh_hex_stiffness(const double X[24], double lambda, double mu, int bbar, double K0[576],
                     double G0[24], double Gbar[24], double *volume) {
  static const double q = 0.57735026918962576451; /* 1/√3 */
  /* B-bar: K0 is the deviatoric part only (λ → −2μ/3, so that
   * λ m mᵀ + μ diag(2,2,2,1,1,1) becomes μ (diag − ⅔ m mᵀ)); the volumetric
   * part is nh_hex_corot's, from the mean gradients. */
  const double lam_gp = bbar ? -2.0 * mu / 3.0 : lambda;
  double gmean[24] = {0};
  memset(K0, 0, 576 * sizeof(double));
  double vol = 0.0;
  for (int gp = 0; gp < 8; gp++) {
    double xi[3] = {q * nh_hex_corner[gp][0], q * nh_hex_corner[gp][1], q * nh_hex_corner[gp][2]};
    double g[24];
    double det = nh_hex_gradients(X, xi, g);
    if (!(det > 0.0)) return NH_ERR_NUMERIC;
    vol += det;
    for (int i = 0; i < 24; i++) gmean[i] += det * g[i];
    nh_hex_point_stiffness(g, det, lam_gp, mu, K0);
  }
  for (int i = 0; i < 24; i++) gmean[i] /= vol;
  if (Gbar) memcpy(Gbar, gmean, sizeof gmean);
  const double centre[3] = {0, 0, 0};
  if (!(nh_hex_gradients(X, centre, G0) > 0.0)) return NH_ERR_NUMERIC;
  *volume = vol;
  return NH_OK;
}

/* The corotated displacements d = Rᵀ uₐ + (Rᵀ − I)(Xₐ − X̄) for the rotation R.
 * Static inline so that the element force keeps it inlined (an out-of-line
 * call made 16×8×8's assembly 2–3 % slower); nh_hex_corotate exports it. */
static inline void nh_hex_corotate_d(const double X[24], const double u[24], const double R[9],
                                     double d[24]) {
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

/* F = I + Σ uₐ ⊗ gₐ, its polar rotation R, and the corotated displacement
 * d of every node. */
static void nh_hex_corotated_F(const double X[24], const double u[24], const double G0[24],
                               double F[9], double R[9], double d[24]) {
  nh_mat3_identity(F);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) F[3 * i + j] += u[3 * a + i] * G0[3 * a + j];
  nh_polar_rotation(F, R);
  nh_hex_corotate_d(X, u, R, d);
}

void nh_hex_corotate(const double X[24], const double u[24], const double R[9], double d[24]) {
  nh_hex_corotate_d(X, u, R, d);
}

void nh_hex_corotated(const double X[24], const double u[24], const double G0[24], double R[9],
                      double d[24]) {
  double F[9];
  nh_hex_corotated_F(X, u, G0, F, R, d);
}

double nh_hex_mean_dilatation(const double u[24], const double Gbar[24], double cof[9]) {
  double H[9] = {0};
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) H[3 * i + j] += u[3 * a + i] * Gbar[3 * a + j];
  /* det(I + H) − 1 = tr H + I₂(H) + det H: no cancellation against 1 */
  double tr = H[0] + H[4] + H[8];
  double i2 = H[0] * H[4] + H[4] * H[8] + H[0] * H[8] - H[1] * H[3] - H[2] * H[6] - H[5] * H[7];
  if (cof) {
    double F[9];
    for (int i = 0; i < 9; i++) F[i] = H[i] + (i % 4 == 0 ? 1.0 : 0.0);
    cof[0] = F[4] * F[8] - F[5] * F[7];
    cof[1] = F[5] * F[6] - F[3] * F[8];
    cof[2] = F[3] * F[7] - F[4] * F[6];
    cof[3] = F[2] * F[7] - F[1] * F[8];
    cof[4] = F[0] * F[8] - F[2] * F[6];
    cof[5] = F[1] * F[6] - F[0] * F[7];
    cof[6] = F[1] * F[5] - F[2] * F[4];
    cof[7] = F[2] * F[3] - F[0] * F[5];
    cof[8] = F[0] * F[4] - F[1] * F[3];
  }
  return tr + i2 + nh_mat3_det(H);
}

/* y = R (K0 x) node by node: the rotated image of K0 x. */
static void nh_rotated_k0(const double K0[576], const double R[9], const double x[24],
                          double y[24]) {
  double kx[24];
  for (int r = 0; r < 24; r++) {
    const double *row = K0 + 24 * r;
    double s = 0.0;
    for (int c = 0; c < 24; c++) s += row[c] * x[c];
    kx[r] = s;
  }
  for (int a = 0; a < 8; a++) nh_mat3_vec(R, kx + 3 * a, y + 3 * a);
}

static void nh_cross(const double a[3], const double b[3], double c[3]) {
  c[0] = a[1] * b[2] - a[2] * b[1];
  c[1] = a[2] * b[0] - a[0] * b[2];
  c[2] = a[0] * b[1] - a[1] * b[0];
}

/* S = [v]×, the matrix of v × ·. */
static void nh_skew(const double v[3], double S[9]) {
  S[0] = 0.0, S[1] = -v[2], S[2] = v[1];
  S[3] = v[2], S[4] = 0.0, S[5] = -v[0];
  S[6] = -v[1], S[7] = v[0], S[8] = 0.0;
}

/* The spin operator Y = (tr V I − V)⁻¹, V = sym(F Rᵀ) the left stretch: the
 * polar rotation's variation is δR = [δω]× R with δω = Y axial(δF Rᵀ − R δFᵀ)
 * (docs/theory.md §2, "Consistent tangent"). tr V I − V has the eigenvalues
 * σᵢ + σⱼ (i ≠ j) of the singular values, one of which carries the sign of
 * det F (core/mat3.c): where the smallest of them falls below 10⁻³ of their
 * mean (a flattened or inverted element, at the polar decomposition's
 * singularity) Y is 0 and the element's tangent drops the variation of R. */
static void nh_spin_operator(const double F[9], const double R[9], double Y[9]) {
  double FRt[9], Z[9];
  nh_mat3_mul_nt(F, R, FRt);
  const double tr = FRt[0] + FRt[4] + FRt[8];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      Z[3 * i + j] = (i == j ? tr : 0.0) - 0.5 * (FRt[3 * i + j] + FRt[3 * j + i]);
  const double mean = (Z[0] + Z[4] + Z[8]) / 3.0;
  if (!(mean > 0.0) || !(nh_mat3_det(Z) > 1e-3 * mean * mean * mean) || nh_mat3_inverse(Z, Y))
    memset(Y, 0, 9 * sizeof(double));
}

void nh_hex_corot_force(const double X[24], const double u[24], const double K0[576],
                        const double G0[24], const nh_hex_volumetric *vol,
                        double frame[NH_HEX_FRAME], double f[24]) {
  double F[9], *R = frame + NH_FRAME_R, *cof = frame + NH_FRAME_COF, *d = frame + NH_FRAME_D;
  nh_hex_corotated_F(X, u, G0, F, R, d);
  nh_spin_operator(F, R, frame + NH_FRAME_SPIN);
  nh_rotated_k0(K0, R, d, f);
  /* B-bar's volumetric part: U = ½ κ V θ̄², θ̄ = det F̄ − 1, F̄ = I + Σ uₐ ⊗ ḡₐ;
   * f = κ V θ̄ bₐ with bₐ = ∂θ̄/∂uₐ = cof(F̄) ḡₐ. */
  if (vol) {
    double theta = nh_hex_mean_dilatation(u, vol->Gbar, cof), kv = vol->kappa * vol->volume, b[3];
    double *Fb = frame + NH_FRAME_FBAR;
    nh_mat3_identity(Fb);
    for (int a = 0; a < 8; a++)
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Fb[3 * i + j] += u[3 * a + i] * vol->Gbar[3 * a + j];
    frame[NH_FRAME_THETA] = theta;
    for (int a = 0; a < 8; a++) {
      nh_mat3_vec(cof, vol->Gbar + 3 * a, b);
      for (int i = 0; i < 3; i++) f[3 * a + i] += kv * theta * b[i];
    }
  } else {
    memset(cof, 0, 19 * sizeof(double)); /* C, F̄ and θ̄ */
  }
}

void nh_hex_frame_corotational(double frame[NH_HEX_FRAME]) {
  memset(frame + NH_FRAME_FBAR, 0, (NH_HEX_FRAME - NH_FRAME_FBAR) * sizeof(double));
}

/* Whether the frame carries the variation of R (Y ≠ 0). */
static int nh_frame_spins(const double frame[NH_HEX_FRAME]) {
  for (int i = 0; i < 9; i++)
    if (frame[NH_FRAME_SPIN + i] != 0.0) return 1;
  return 0;
}

/* Kₐ_b += Gₐ Ω_b, the variation of R applied to R K0 d: δω = Σ_b Ω_b δu_b,
 * Ω_b = Y [R g_b]×, and Gₐ = ∂(R K0 d)ₐ/∂ω = −[(R K0 d)ₐ]× + R (Σ_c K0ₐ_c
 * [d_c]×) Rᵀ (docs/theory.md §2, "Consistent tangent"): d the corotated
 * displacements for the force, Rᵀw for the variation of R K0 Rᵀ w. */
static void nh_add_spin(const double K0[576], const double G0[24], const double frame[NH_HEX_FRAME],
                        const double d[24], double Kt[576]) {
  const double *R = frame + NH_FRAME_R, *Y = frame + NH_FRAME_SPIN;
  double Om[72], G[72], q[24];
  for (int b = 0; b < 8; b++) { /* Ω_b = Y [R g_b]× */
    double Rg[3], S[9];
    nh_mat3_vec(R, G0 + 3 * b, Rg);
    nh_skew(Rg, S);
    nh_mat3_mul(Y, S, Om + 9 * b);
  }
  for (int r = 0; r < 24; r++) {
    double s = 0.0;
    for (int c = 0; c < 24; c++) s += K0[24 * r + c] * d[c];
    q[r] = s;
  }
  for (int a = 0; a < 8; a++) {
    double M[9] = {0}, T[9], fa[3], S[9];
    for (int c = 0; c < 8; c++) { /* M += K0ₐ_c [d_c]× */
      const double *dc = d + 3 * c;
      for (int i = 0; i < 3; i++) {
        const double *k = K0 + 24 * (3 * a + i) + 3 * c;
        M[3 * i] += k[1] * dc[2] - k[2] * dc[1];
        M[3 * i + 1] += k[2] * dc[0] - k[0] * dc[2];
        M[3 * i + 2] += k[0] * dc[1] - k[1] * dc[0];
      }
    }
    nh_mat3_mul(R, M, T);
    nh_mat3_mul_nt(T, R, G + 9 * a);
    nh_mat3_vec(R, q + 3 * a, fa);
    nh_skew(fa, S);
    for (int i = 0; i < 9; i++) G[9 * a + i] -= S[i];
  }
  for (int a = 0; a < 8; a++)
    for (int c = 0; c < 8; c++) {
      double T[9];
      nh_mat3_mul(G + 9 * a, Om + 9 * c, T);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Kt[24 * (3 * a + i) + 3 * c + j] += T[3 * i + j];
    }
}

/* Kₐ_c += s [F̄ (ḡ_c × ḡₐ)]× = s Hₐ_c, Hₐ_c = ∂bₐ/∂u_c (B-bar). */
static void nh_add_dilatation_variation(const nh_hex_volumetric *vol, const double Fbar[9],
                                        double s, double Kt[576]) {
  for (int a = 0; a < 8; a++)
    for (int c = 0; c < 8; c++) {
      double n[3], w[3], S[9];
      nh_cross(vol->Gbar + 3 * c, vol->Gbar + 3 * a, n);
      nh_mat3_vec(Fbar, n, w);
      nh_skew(w, S);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Kt[24 * (3 * a + i) + 3 * c + j] += s * S[3 * i + j];
    }
}

void nh_hex_corot_tangent(const double K0[576], const double G0[24], const nh_hex_volumetric *vol,
                          const double frame[NH_HEX_FRAME], double Kt[576]) {
  const double *R = frame + NH_FRAME_R;
  /* Kₐ_c = (R K0ₐ_c) Rᵀ block by block, written out with the operands and
   * the order of additions of nh_mat3_mul and nh_mat3_mul_nt (the same bits;
   * the calls and copies were a third of the phantom's assembly) */
  const double r00 = R[0], r01 = R[1], r02 = R[2], r10 = R[3], r11 = R[4], r12 = R[5], r20 = R[6],
               r21 = R[7], r22 = R[8];
  for (int a = 0; a < 8; a++) {
    double T[72]; /* R K0ₐ_c for c = 0 … 7: rows 3a … 3a + 2 of K0, rotated */
    const double *k = K0 + 24 * 3 * a;
    for (int j = 0; j < 24; j++) {
      const double k0 = k[j], k1 = k[24 + j], k2 = k[48 + j];
      T[j] = r00 * k0 + r01 * k1 + r02 * k2;
      T[24 + j] = r10 * k0 + r11 * k1 + r12 * k2;
      T[48 + j] = r20 * k0 + r21 * k1 + r22 * k2;
    }
    for (int i = 0; i < 3; i++) {
      double *row = Kt + 24 * (3 * a + i);
      const double *t = T + 24 * i;
      for (int c = 0; c < 8; c++) {
        const double t0 = t[3 * c], t1 = t[3 * c + 1], t2 = t[3 * c + 2];
        row[3 * c] = t0 * r00 + t1 * r01 + t2 * r02;
        row[3 * c + 1] = t0 * r10 + t1 * r11 + t2 * r12;
        row[3 * c + 2] = t0 * r20 + t1 * r21 + t2 * r22;
      }
    }
  }
  if (nh_frame_spins(frame)) nh_add_spin(K0, G0, frame, frame + NH_FRAME_D, Kt);
  /* B-bar: κ V (bₐ ⊗ b_b + θ̄ Hₐ_b), Hₐ_b = ∂bₐ/∂u_b = [F̄ (ḡ_b × ḡₐ)]×. */
  if (vol) {
    double b[24], kv = vol->kappa * vol->volume, theta = frame[NH_FRAME_THETA];
    for (int a = 0; a < 8; a++) nh_mat3_vec(frame + NH_FRAME_COF, vol->Gbar + 3 * a, b + 3 * a);
    for (int r = 0; r < 24; r++)
      for (int c = 0; c < 24; c++) Kt[24 * r + c] += kv * b[r] * b[c];
    if (theta != 0.0) nh_add_dilatation_variation(vol, frame + NH_FRAME_FBAR, kv * theta, Kt);
  }
}

void nh_hex_corot_rate_tangent(const double K0[576], const double G0[24],
                               const nh_hex_volumetric *vol, const double frame[NH_HEX_FRAME],
                               const double w[24], double D[576]) {
  memset(D, 0, 576 * sizeof(double));
  /* R K0 Rᵀ w: the variation of R with Rᵀw in place of d */
  if (nh_frame_spins(frame)) {
    double rw[24];
    for (int a = 0; a < 8; a++) nh_mat3_tvec(frame + NH_FRAME_R, w + 3 * a, rw + 3 * a);
    nh_add_spin(K0, G0, frame, rw, D);
  }
  /* κ V b (bᵀw): κ V [(bᵀw) Hₐ_c + bₐ ⊗ r_c], r_c = Σₐ Hₐ_cᵀ wₐ = Σₐ wₐ × (F̄ (ḡ_c × ḡₐ))
   * (Hₐ_c = [F̄ (ḡ_c × ḡₐ)]×, skew: Hᵀ w = −h × w = w × h) */
  if (vol) {
    double b[24], bw = 0.0, kv = vol->kappa * vol->volume;
    const double *Fbar = frame + NH_FRAME_FBAR;
    for (int a = 0; a < 8; a++) nh_mat3_vec(frame + NH_FRAME_COF, vol->Gbar + 3 * a, b + 3 * a);
    for (int i = 0; i < 24; i++) bw += b[i] * w[i];
    nh_add_dilatation_variation(vol, Fbar, kv * bw, D);
    for (int c = 0; c < 8; c++) {
      double r[3] = {0, 0, 0};
      for (int a = 0; a < 8; a++) {
        double n[3], hv[3], x[3];
        nh_cross(vol->Gbar + 3 * c, vol->Gbar + 3 * a, n);
        nh_mat3_vec(Fbar, n, hv);
        nh_cross(w + 3 * a, hv, x);
        for (int k = 0; k < 3; k++) r[k] += x[k];
      }
      for (int i = 0; i < 24; i++)
        for (int j = 0; j < 3; j++) D[24 * i + 3 * c + j] += kv * b[i] * r[j];
    }
  }
}

void nh_hex_corot_apply(const double K0[576], const double G0[24], const nh_hex_volumetric *vol,
                        const double frame[NH_HEX_FRAME], const double w[24], double y[24]) {
  const double *R = frame + NH_FRAME_R;
  double rw[24];
  for (int a = 0; a < 8; a++) nh_mat3_tvec(R, w + 3 * a, rw + 3 * a);
  /* the variation of R: δω = Σ_b Y (R g_b × w_b); Gₐ δω = −fₐ × δω +
   * R (K0 z)ₐ with z_b = d_b × Rᵀδω, added to Rᵀw before K0 */
  double om[3] = {0, 0, 0};
  const int spins = nh_frame_spins(frame);
  if (spins) {
    const double *d = frame + NH_FRAME_D;
    double s[3] = {0, 0, 0}, Rg[3], c[3], rom[3];
    for (int b = 0; b < 8; b++) {
      nh_mat3_vec(R, G0 + 3 * b, Rg);
      nh_cross(Rg, w + 3 * b, c);
      for (int k = 0; k < 3; k++) s[k] += c[k];
    }
    nh_mat3_vec(frame + NH_FRAME_SPIN, s, om);
    nh_mat3_tvec(R, om, rom);
    for (int b = 0; b < 8; b++) {
      nh_cross(d + 3 * b, rom, c);
      for (int k = 0; k < 3; k++) rw[3 * b + k] += c[k];
    }
  }
  nh_rotated_k0(K0, R, rw, y);
  if (spins) {
    double q[24], fa[3], c[3];
    nh_rotated_k0(K0, R, frame + NH_FRAME_D, q);
    for (int a = 0; a < 8; a++) {
      for (int k = 0; k < 3; k++) fa[k] = q[3 * a + k];
      nh_cross(fa, om, c);
      for (int k = 0; k < 3; k++) y[3 * a + k] -= c[k];
    }
  }
  if (vol) {
    double b[24], bw = 0.0, kv = vol->kappa * vol->volume, theta = frame[NH_FRAME_THETA];
    for (int a = 0; a < 8; a++) nh_mat3_vec(frame + NH_FRAME_COF, vol->Gbar + 3 * a, b + 3 * a);
    for (int i = 0; i < 24; i++) bw += b[i] * w[i];
    for (int i = 0; i < 24; i++) y[i] += kv * bw * b[i];
    if (theta != 0.0)
      for (int a = 0; a < 8; a++)
        for (int c = 0; c < 8; c++) { /* Hₐ_c w_c = (F̄ (ḡ_c × ḡₐ)) × w_c */
          double n[3], v[3], x[3];
          nh_cross(vol->Gbar + 3 * c, vol->Gbar + 3 * a, n);
          nh_mat3_vec(frame + NH_FRAME_FBAR, n, v);
          nh_cross(v, w + 3 * c, x);
          for (int k = 0; k < 3; k++) y[3 * a + k] += kv * theta * x[k];
        }
  }
}

void nh_hex_corot(const double X[24], const double u[24], const double K0[576], const double G0[24],
                  const nh_hex_volumetric *vol, double R[9], double f[24], double Kt[576]) {
  double frame[NH_HEX_FRAME];
  nh_hex_corot_force(X, u, K0, G0, vol, frame, f);
  memcpy(R, frame + NH_FRAME_R, 9 * sizeof(double));
  nh_hex_frame_corotational(frame);
  if (Kt) nh_hex_corot_tangent(K0, G0, vol, frame, Kt);
}
