/* test_tangent — the consistent tangent of the corotational hexahedron
 * (fem/hex.c, docs/theory.md §2 "Consistent tangent", §2b) against central
 * differences of the element force.
 *
 * At random states of large rotation (angles up to 3 rad about random axes)
 * and large strain (a homogeneous stretch of up to ±30 % and a nodal
 * perturbation of 5 % of the cell size, so the corotated displacements are
 * not homogeneous and K₀ d has bending parts) of distorted hexahedra
 * (corners moved by up to 10 % of the size), the tangent of
 * nh_hex_corot_tangent must equal, column by column,
 *     (f(u + h eⱼ) − f(u − h eⱼ)) / 2h,     h = 10⁻⁶ L,
 * within 10⁻⁷ of the largest entry of each part tested on its own:
 *   - the deviatoric corotational part R K₀ d (B-bar's K₀, no vol: the
 *     variation of R alone), at ν = 0.3, 0.45, 0.4999;
 *   - the volumetric part κ V θ̄ b (K₀ = 0: the variation of b alone);
 *   - the fully integrated element and the whole B-bar element.
 * The central difference's error is O(h²/L²) ≈ 10⁻¹² relative (truncation)
 * plus eps |f| / h ≈ 10⁻¹⁰ (round-off), so 10⁻⁷ has margin; the
 * corotational tangent R K₀ Rᵀ (+ κ V b bᵀ) misses the same differences by
 * about the strain (10⁻¹), which is checked to exceed 10⁻³, so the
 * comparison can tell the two apart. Also: nh_hex_corot_apply equals Kt w
 * (10⁻¹² relative), the tangent is objective, K(Qx) = Q K(x) Qᵀ, and the
 * skew-symmetric part of K is at least 10⁻⁴ max |K₀| at these states (so
 * the solver must handle a non-symmetric tangent) while the variation of b
 * is symmetric to round-off.
 *
 * The rate tangent D = ∂(K(u) w)/∂u (nh_hex_corot_rate_tangent, K the
 * corotational tangent, w fixed: the stiffness-damping force's variation in
 * the dynamic step's Jacobian, docs/theory.md §3) against the central
 * differences (K(u + h eⱼ) w − K(u − h eⱼ) w) / 2h, same h and tolerance
 * (the same error analysis: K w is as smooth in u as f). */
#include "check.h"
#include "fem/fem.h"

#include <string.h>

static const double L = 0.01, E = 1e4;

typedef struct {
  double X[24], K0[576], G0[24], Gbar[24], V;
  nh_hex_volumetric vol;
  const nh_hex_volumetric *vp;
} element;

static void force(const element *e, const double u[24], double f[24]) {
  double frame[NH_HEX_FRAME];
  nh_hex_corot_force(e->X, u, e->K0, e->G0, e->vp, frame, f);
}

static void tangent(const element *e, const double u[24], int corotational, double K[576]) {
  double frame[NH_HEX_FRAME], f[24];
  nh_hex_corot_force(e->X, u, e->K0, e->G0, e->vp, frame, f);
  if (corotational) nh_hex_frame_corotational(frame);
  nh_hex_corot_tangent(e->K0, e->G0, e->vp, frame, K);
}

static double maxabs(const double *a, int n) {
  double m = 0.0;
  for (int i = 0; i < n; i++) m = fmax(m, fabs(a[i]));
  return m;
}

/* part: 0 deviatoric (B-bar K₀, no vol), 1 volumetric only, 2 full
 * integration, 3 whole B-bar element. */
static void make(element *e, double nu, int part) {
  double lambda, mu;
  nh_lame(E, nu, &lambda, &mu);
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) e->X[3 * a + k] = L * (0.5 * nh_hex_corner[a][k] + 0.1 * nh_rand());
  CHECK_OK(nh_hex_stiffness(e->X, lambda, mu, part != 2, e->K0, e->G0, e->Gbar, &e->V));
  if (part == 1) memset(e->K0, 0, sizeof e->K0);
  e->vol = (nh_hex_volumetric){e->Gbar, lambda + 2.0 * mu / 3.0, e->V};
  e->vp = part == 1 || part == 3 ? &e->vol : NULL;
}

/* A state of large rotation and strain: x = Q (S X + noise) + t. */
static void state(const element *e, double angle, double u[24], double Q[9]) {
  double S[9], r[3] = {nh_rand(), nh_rand(), nh_rand()}, t[3];
  double n = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
  for (int k = 0; k < 3; k++) r[k] *= angle / n, t[k] = L * nh_rand();
  nh_mat3_rotation(r, Q);
  for (int i = 0; i < 9; i++) S[i] = (i % 4 == 0 ? 1.0 : 0.0) + 0.3 * nh_rand();
  for (int a = 0; a < 8; a++) {
    double y[3], x[3];
    nh_mat3_vec(S, e->X + 3 * a, y);
    for (int k = 0; k < 3; k++) y[k] += 0.05 * L * nh_rand();
    nh_mat3_vec(Q, y, x);
    for (int k = 0; k < 3; k++) u[3 * a + k] = x[k] + t[k] - e->X[3 * a + k];
  }
}

static const char *part_name[] = {"deviatoric (variation of R)", "volumetric (variation of b)",
                                  "fully integrated", "B-bar"};

static void check_part(double nu, int part, double *worst, double *miss) {
  element e;
  make(&e, nu, part);
  double u[24], Q[9], K[576], Kc[576], Kfd[576];
  state(&e, 0.3 + 2.7 * fabs(nh_rand()), u, Q);
  tangent(&e, u, 0, K);
  tangent(&e, u, 1, Kc);
  const double h = 1e-6 * L;
  for (int j = 0; j < 24; j++) {
    double up[24], um[24], fp[24], fm[24];
    memcpy(up, u, sizeof up), memcpy(um, u, sizeof um);
    up[j] += h, um[j] -= h;
    force(&e, up, fp);
    force(&e, um, fm);
    for (int i = 0; i < 24; i++) Kfd[24 * i + j] = (fp[i] - fm[i]) / (2 * h);
  }
  double scale = maxabs(Kfd, 576), err = 0.0, errc = 0.0;
  for (int i = 0; i < 576; i++)
    err = fmax(err, fabs(K[i] - Kfd[i])), errc = fmax(errc, fabs(Kc[i] - Kfd[i]));
  err /= scale, errc /= scale;
  CHECK(err <= 1e-7, "%s, nu %g: consistent tangent vs central differences: %.3g > 1e-7",
        part_name[part], nu, err);
  CHECK(errc >= 1e-3, "%s, nu %g: the corotational tangent should miss by about the strain: %.3g",
        part_name[part], nu, errc);
  *worst = fmax(*worst, err);
  *miss = fmin(*miss, errc);

  /* nh_hex_corot_apply = Kt w */
  double frame[NH_HEX_FRAME], f[24], w[24], y[24], Kw[24];
  nh_hex_corot_force(e.X, u, e.K0, e.G0, e.vp, frame, f);
  for (int i = 0; i < 24; i++) w[i] = nh_rand();
  nh_hex_corot_apply(e.K0, e.G0, e.vp, frame, w, y);
  for (int i = 0; i < 24; i++) {
    Kw[i] = 0.0;
    for (int q = 0; q < 24; q++) Kw[i] += K[24 * i + q] * w[q];
  }
  double kws = maxabs(Kw, 24);
  for (int i = 0; i < 24; i++) CHECK_CLOSE(y[i], Kw[i], 1e-12 * kws, "apply vs Kt w");

  /* The rate tangent D = ∂(K_corot(u) w)/∂u against central differences. */
  double D[576], Dfd[576];
  nh_hex_corot_rate_tangent(e.K0, e.G0, e.vp, frame, w, D);
  for (int j = 0; j < 24; j++) {
    double up[24], um[24], fr[NH_HEX_FRAME], yp[24], ym[24];
    memcpy(up, u, sizeof up), memcpy(um, u, sizeof um);
    up[j] += h, um[j] -= h;
    nh_hex_corot_force(e.X, up, e.K0, e.G0, e.vp, fr, f);
    nh_hex_frame_corotational(fr);
    nh_hex_corot_apply(e.K0, e.G0, e.vp, fr, w, yp);
    nh_hex_corot_force(e.X, um, e.K0, e.G0, e.vp, fr, f);
    nh_hex_frame_corotational(fr);
    nh_hex_corot_apply(e.K0, e.G0, e.vp, fr, w, ym);
    for (int i = 0; i < 24; i++) Dfd[24 * i + j] = (yp[i] - ym[i]) / (2 * h);
  }
  double dscale = maxabs(Dfd, 576), derr = 0.0;
  for (int i = 0; i < 576; i++) derr = fmax(derr, fabs(D[i] - Dfd[i]));
  CHECK(dscale > 0.0 && derr <= 1e-7 * dscale,
        "%s, nu %g: rate tangent d(K w)/du vs central differences: %.3g of %.3g > 1e-7",
        part_name[part], nu, derr, dscale);

  /* Objectivity: the rigidly moved state x₂ = P x + t has K₂ = P K Pᵀ. */
  double P[9], r[3] = {nh_rand(), nh_rand(), nh_rand()}, u2[24], K2[576];
  nh_mat3_rotation(r, P);
  for (int a = 0; a < 8; a++) {
    double x[3], y2[3];
    for (int k = 0; k < 3; k++) x[k] = e.X[3 * a + k] + u[3 * a + k];
    nh_mat3_vec(P, x, y2);
    for (int k = 0; k < 3; k++) u2[3 * a + k] = y2[k] + 0.1 * L - e.X[3 * a + k];
  }
  tangent(&e, u2, 0, K2);
  for (int a = 0; a < 8; a++)
    for (int b = 0; b < 8; b++) {
      double B[9], T[9];
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) B[3 * i + j] = K[24 * (3 * a + i) + 3 * b + j];
      nh_mat3_mul(P, B, T);
      nh_mat3_mul_nt(T, P, B);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
          CHECK_CLOSE(K2[24 * (3 * a + i) + 3 * b + j], B[3 * i + j], 1e-9 * scale,
                      "K(Px + t) = P K(x) Pᵀ");
    }

  /* Symmetry: the variation of b (a second derivative of det F̄) is
   * symmetric; the variation of R is not. */
  double skew = 0.0;
  for (int i = 0; i < 24; i++)
    for (int j = 0; j < i; j++) skew = fmax(skew, fabs(K[24 * i + j] - K[24 * j + i]));
  if (part == 1)
    CHECK(skew <= 1e-12 * scale, "volumetric part: skew part %.3g of %.3g", skew, scale);
  else
    CHECK(skew >= 1e-4 * maxabs(e.K0, 576),
          "%s: the tangent should not be symmetric (skew %.3g, max |K0| %.3g)", part_name[part],
          skew, maxabs(e.K0, 576));
}

int main(void) {
  const double nus[3] = {0.3, 0.45, 0.4999};
  for (int part = 0; part < 4; part++) {
    double worst = 0.0, miss = INFINITY;
    for (int k = 0; k < 3; k++)
      for (int trial = 0; trial < 10; trial++) check_part(nus[k], part, &worst, &miss);
    if (getenv("NH_VERBOSE"))
      printf("%-28s worst relative error %.3g, corotational tangent misses by >= %.3g\n",
             part_name[part], worst, miss);
  }
  TEST_END();
}
