/* element.c — the corotational Euler–Bernoulli beam element: internal force
 * and consistent tangent (docs/beam.md §2-3).
 *
 * Formulation: Battini & Pacoste (2002), "Co-rotational beam elements with
 * warping effects in instability problems", CMAME 191, with spatial spin
 * increments. Per element, the end states are positions x1, x2 and director
 * matrices T1, T2 (column 1 = beam axis, columns 2, 3 = section axes).
 *
 * Corotated frame E = [e1 e2 e3] (rigid part of the element motion):
 *   e1 = (x2 − x1)/l,  q = ½ (T1 a + T2 a) with a = (0,1,0) (the d2
 *   directors), e3 = e1 × q / |e1 × q|, e2 = e3 × e1.
 * Using the mean of the two nodal d2 directors (Battini's choice rather than
 * Crisfield's mean rotation exp(½ log(T2 T1ᵀ)) T1) keeps the frame and its
 * variation in closed form with no logarithm; both are invariant under
 * rigid motions and give the same small-strain element. It breaks down only
 * if q ∥ e1 (a nodal section turned by 90° against the chord — impossible
 * for a beam that is not torn apart).
 *
 * Local deformations (zero for any rigid motion, by construction):
 *   u = l − l0,  θ̄i = log(Eᵀ Ti)  (rotation vectors in the frame E).
 * Strain energy of the linear Euler–Bernoulli element in its own frame
 * (transverse displacements vanish in E, so the classical 12x12 stiffness
 * reduces to the 7x7 K_l on (u, θ̄1, θ̄2)):
 *   U = ½ EA/l0 u² + ½ GJ/l0 (θ̄1x − θ̄2x)²
 *     + Σ_{y,z} ½ EI/l0 (4 θ̄1² + 4 θ̄2² + 4 θ̄1 θ̄2),
 * local forces f_l = K_l d_l = (N, m1, m2). With the 12 global increments
 * δp = (δx1, δw1, δx2, δw2) expressed in E as δp̄:
 *   δu = r̄ δp̄,  r̄ = (−1,0,0, 0,0,0, 1,0,0, 0,0,0),
 *   ω̄ = Ḡ δp̄ (spin of the frame, in E; Battini's G, derived in beam.md),
 *   δθ̄i = J⁻¹(θ̄i) (δw̄i − ω̄) = J⁻¹(θ̄i) (P̄ δp̄)i,  P̄ = [0 I 0 0; 0 0 0 I] − [Ḡ; Ḡ],
 * with J(θ) the left Jacobian of SO(3) (exp(θ + δθ) = exp(J δθ) exp(θ)),
 *   J⁻¹(θ) = I − ½ S(θ) + η(θ) S(θ)²,  η = (1 − (θ/2) cot(θ/2)) / θ².
 * Internal force: f = E B̄ᵀ f_l, B̄ = [r̄; J⁻¹(θ̄1) P̄₁; J⁻¹(θ̄2) P̄₂].
 *
 * Tangent: the exact derivative of f with respect to δp (so Newton is
 * quadratic), K = E (K1 + K2 + K3 + K4) Eᵀ with
 *   K1 = B̄ᵀ K_l B̄                       material part,
 *   K2 = P̄ᵀ diag(Hi J⁻¹(θ̄i)) P̄          variation of J⁻ᵀ(θ̄i) mi, Hi = ∂(J⁻ᵀ m)/∂θ,
 *   K3 = −[S(f̄_k)]_k Ḡ                  rotation of the frame E (f̄ = B̄ᵀ f_l),
 *   K4 = −∂(Ḡᵀ v)/∂p̄,  v = Σ J⁻ᵀ(θ̄i) mi  variation of Ḡ (l, q̄ move).
 * It is not symmetric away from equilibrium (spin increments are not
 * additive); the dynamic step symmetrises it. Verified against central
 * differences of f in tests/test_beam.c.
 *
 * Small angles: η and η'/θ are evaluated by their Taylor series below
 * θ = 0.1 (the closed forms cancel catastrophically there). */
#include "beam/beam_impl.h"

#include <math.h>
#include <string.h>

void nh_beam_skew(const double a[3], double S[9]) {
  S[0] = 0.0, S[1] = -a[2], S[2] = a[1];
  S[3] = a[2], S[4] = 0.0, S[5] = -a[0];
  S[6] = -a[1], S[7] = a[0], S[8] = 0.0;
}

void nh_beam_rotation_log(const double R[9], double th[3]) {
  /* Shepperd: take the square root of the largest of 1 + tr R and the
   * 1 + 2 R_ii − tr R, so no division by a small number. */
  double tr = R[0] + R[4] + R[8], w, x, y, z;
  if (tr >= R[0] && tr >= R[4] && tr >= R[8]) {
    w = 0.5 * sqrt(1.0 + tr);
    x = (R[7] - R[5]) / (4 * w), y = (R[2] - R[6]) / (4 * w), z = (R[3] - R[1]) / (4 * w);
  } else if (R[0] >= R[4] && R[0] >= R[8]) {
    x = 0.5 * sqrt(fmax(1.0 + R[0] - R[4] - R[8], 0.0));
    w = (R[7] - R[5]) / (4 * x), y = (R[1] + R[3]) / (4 * x), z = (R[2] + R[6]) / (4 * x);
  } else if (R[4] >= R[8]) {
    y = 0.5 * sqrt(fmax(1.0 - R[0] + R[4] - R[8], 0.0));
    w = (R[2] - R[6]) / (4 * y), x = (R[1] + R[3]) / (4 * y), z = (R[5] + R[7]) / (4 * y);
  } else {
    z = 0.5 * sqrt(fmax(1.0 - R[0] - R[4] + R[8], 0.0));
    w = (R[3] - R[1]) / (4 * z), x = (R[2] + R[6]) / (4 * z), y = (R[5] + R[7]) / (4 * z);
  }
  if (w < 0) w = -w, x = -x, y = -y, z = -z;
  double vn = sqrt(x * x + y * y + z * z);
  double k = vn > 0 ? 2.0 * atan2(vn, w) / vn : 2.0;
  th[0] = k * x, th[1] = k * y, th[2] = k * z;
}

/* η(θ) = (1 − (θ/2) cot(θ/2)) / θ² and μ = η'(θ)/θ. */
static void nh_beam_eta(double t, double *eta, double *mu) {
  double t2 = t * t;
  if (t < 0.1) {
    *eta = 1.0 / 12 + t2 / 720 + t2 * t2 / 30240 + t2 * t2 * t2 / 1209600;
    *mu = 2.0 / 720 + 4 * t2 / 30240 + 6 * t2 * t2 / 1209600 + 8 * t2 * t2 * t2 / 47900160;
  } else {
    double s = sin(0.5 * t), ct = cos(0.5 * t) / s;
    *eta = 1.0 / t2 - ct / (2 * t);
    *mu = (-2.0 / (t2 * t) + ct / (2 * t2) + 1.0 / (4 * t * s * s)) / t;
  }
}

/* J⁻¹(θ) = I − ½ S + η S². */
static void nh_beam_jinv(const double th[3], double Ji[9]) {
  double S[9], S2[9], eta, mu;
  nh_beam_eta(nh_vec3_norm(th), &eta, &mu);
  nh_beam_skew(th, S);
  nh_mat3_mul(S, S, S2);
  for (int i = 0; i < 9; i++) Ji[i] = -0.5 * S[i] + eta * S2[i];
  Ji[0] += 1.0, Ji[4] += 1.0, Ji[8] += 1.0;
}

/* H = ∂(J⁻ᵀ(θ) m)/∂θ, J⁻ᵀ m = m + ½ θ × m + η (θ (θ·m) − |θ|² m). */
static void nh_beam_hmat(const double th[3], const double m[3], double H[9]) {
  double t2 = nh_vec3_dot(th, th), eta, mu, Sm[9];
  nh_beam_eta(sqrt(t2), &eta, &mu);
  double tm = nh_vec3_dot(th, m), a[3];
  for (int i = 0; i < 3; i++) a[i] = th[i] * tm - t2 * m[i];
  nh_beam_skew(m, Sm);
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      H[3 * i + j] = -0.5 * Sm[3 * i + j] + mu * a[i] * th[j] +
                     eta * ((i == j ? tm : 0.0) + th[i] * m[j] - 2 * m[i] * th[j]);
}

double nh_beam_corot(const double x1[3], const double x2[3], const double T1[9], const double T2[9],
                     double l0, const nh_beam_constants *c, double young, double dl[7],
                     double Eout[9], double f[12], double K[144]) {
  const double EA = young * c->area, EI = young * c->inertia, GJ = c->shear * c->polar;
  double e1[3], e2[3], e3[3], q1[3], q2[3], q[3], l = 0.0;
  for (int i = 0; i < 3; i++) e1[i] = x2[i] - x1[i], l += e1[i] * e1[i];
  l = sqrt(l);
  for (int i = 0; i < 3; i++) {
    e1[i] /= l;
    q1[i] = T1[3 * i + 1], q2[i] = T2[3 * i + 1], q[i] = 0.5 * (q1[i] + q2[i]);
  }
  nh_vec3_cross(e1, q, e3);
  double n3 = sqrt(e3[0] * e3[0] + e3[1] * e3[1] + e3[2] * e3[2]);
  for (int i = 0; i < 3; i++) e3[i] /= n3;
  nh_vec3_cross(e3, e1, e2);
  double E[9];
  for (int i = 0; i < 3; i++) E[3 * i] = e1[i], E[3 * i + 1] = e2[i], E[3 * i + 2] = e3[i];

  double Rb[9], th1[3], th2[3];
  nh_mat3_mul_tn(E, T1, Rb);
  nh_beam_rotation_log(Rb, th1);
  nh_mat3_mul_tn(E, T2, Rb);
  nh_beam_rotation_log(Rb, th2);
  const double u = l - l0, N = EA / l0 * u, kt = GJ / l0, kb = EI / l0;
  double m1[3] = {kt * (th1[0] - th2[0]), kb * (4 * th1[1] + 2 * th2[1]),
                  kb * (4 * th1[2] + 2 * th2[2])};
  double m2[3] = {-m1[0], kb * (2 * th1[1] + 4 * th2[1]), kb * (2 * th1[2] + 4 * th2[2])};
  double U = 0.5 * N * u;
  for (int i = 0; i < 3; i++) U += 0.5 * (m1[i] * th1[i] + m2[i] * th2[i]);
  if (dl) {
    dl[0] = u;
    for (int i = 0; i < 3; i++) dl[1 + i] = th1[i], dl[4 + i] = th2[i];
  }
  if (Eout) memcpy(Eout, E, sizeof E);
  if (!f && !K) return U;

  /* Frame spin ω̄ = Ḡ δp̄ (Battini's G, docs/beam.md §2.3). */
  double qb[3], qb1[3], qb2[3];
  nh_mat3_tvec(E, q, qb);
  nh_mat3_tvec(E, q1, qb1);
  nh_mat3_tvec(E, q2, qb2);
  const double eta = qb[0] / qb[1], e11 = qb1[0] / qb[1], e12 = qb1[1] / qb[1];
  const double e21 = qb2[0] / qb[1], e22 = qb2[1] / qb[1];
  double G[3][12] = {{0}};
  G[0][2] = eta / l, G[0][3] = 0.5 * e12, G[0][4] = -0.5 * e11;
  G[0][8] = -eta / l, G[0][9] = 0.5 * e22, G[0][10] = -0.5 * e21;
  G[1][2] = 1.0 / l, G[1][8] = -1.0 / l;
  G[2][1] = -1.0 / l, G[2][7] = 1.0 / l;
  double P[6][12];
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 12; j++) P[k][j] = P[3 + k][j] = -G[k][j];
  for (int k = 0; k < 3; k++) P[k][3 + k] += 1.0, P[3 + k][9 + k] += 1.0;

  double Ji1[9], Ji2[9], B[7][12] = {{0}};
  nh_beam_jinv(th1, Ji1);
  nh_beam_jinv(th2, Ji2);
  B[0][0] = -1.0, B[0][6] = 1.0;
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 12; j++)
      for (int k = 0; k < 3; k++) {
        B[1 + i][j] += Ji1[3 * i + k] * P[k][j];
        B[4 + i][j] += Ji2[3 * i + k] * P[3 + k][j];
      }
  const double fl[7] = {N, m1[0], m1[1], m1[2], m2[0], m2[1], m2[2]};
  double fb[12] = {0};
  for (int j = 0; j < 12; j++)
    for (int a = 0; a < 7; a++) fb[j] += B[a][j] * fl[a];
  if (f)
    for (int k = 0; k < 4; k++) nh_mat3_vec(E, fb + 3 * k, f + 3 * k);
  if (!K) return U;

  double Kl[7][7] = {{0}};
  Kl[0][0] = EA / l0;
  Kl[1][1] = Kl[4][4] = kt, Kl[1][4] = Kl[4][1] = -kt;
  for (int a = 2; a <= 3; a++) {
    Kl[a][a] = Kl[a + 3][a + 3] = 4 * kb;
    Kl[a][a + 3] = Kl[a + 3][a] = 2 * kb;
  }
  double Kb[12][12] = {{0}}, KB[7][12] = {{0}};
  for (int a = 0; a < 7; a++)
    for (int j = 0; j < 12; j++)
      for (int b = 0; b < 7; b++) KB[a][j] += Kl[a][b] * B[b][j];
  for (int i = 0; i < 12; i++)
    for (int j = 0; j < 12; j++)
      for (int a = 0; a < 7; a++) Kb[i][j] += B[a][i] * KB[a][j];

  /* K2: variation of J⁻ᵀ(θ̄i) mi through θ̄i. */
  double ms1[3], ms2[3];
  nh_mat3_tvec(Ji1, m1, ms1);
  nh_mat3_tvec(Ji2, m2, ms2);
  for (int nd = 0; nd < 2; nd++) {
    double H[9], HJ[9], HJP[3][12] = {{0}};
    nh_beam_hmat(nd ? th2 : th1, nd ? m2 : m1, H);
    nh_mat3_mul(H, nd ? Ji2 : Ji1, HJ);
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 12; j++)
        for (int k = 0; k < 3; k++) HJP[i][j] += HJ[3 * i + k] * P[3 * nd + k][j];
    for (int a = 0; a < 12; a++)
      for (int j = 0; j < 12; j++)
        for (int i = 0; i < 3; i++) Kb[a][j] += P[3 * nd + i][a] * HJP[i][j];
  }
  /* K3: the frame E turns with ω̄. */
  for (int k = 0; k < 4; k++) {
    double S[9];
    nh_beam_skew(fb + 3 * k, S);
    for (int a = 0; a < 3; a++)
      for (int j = 0; j < 12; j++)
        for (int b = 0; b < 3; b++) Kb[3 * k + a][j] -= S[3 * a + b] * G[b][j];
  }
  /* K4: Ḡ varies with l and with q̄, q̄i (δq̄i = q̄i × ω̄ + w̄i × q̄i). */
  double v[3];
  for (int i = 0; i < 3; i++) v[i] = ms1[i] + ms2[i];
  double Sq1[9], Sq2[9], dq1[3][12] = {{0}}, dq2[3][12] = {{0}}, dq[3][12];
  nh_beam_skew(qb1, Sq1);
  nh_beam_skew(qb2, Sq2);
  for (int a = 0; a < 3; a++) {
    for (int j = 0; j < 12; j++)
      for (int b = 0; b < 3; b++) {
        dq1[a][j] += Sq1[3 * a + b] * G[b][j];
        dq2[a][j] += Sq2[3 * a + b] * G[b][j];
      }
    for (int b = 0; b < 3; b++) dq1[a][3 + b] -= Sq1[3 * a + b], dq2[a][9 + b] -= Sq2[3 * a + b];
    for (int j = 0; j < 12; j++) dq[a][j] = 0.5 * (dq1[a][j] + dq2[a][j]);
  }
  const double rb[12] = {-1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0};
  for (int j = 0; j < 12; j++) {
    double deta = (dq[0][j] - eta * dq[1][j]) / qb[1];
    double de11 = (dq1[0][j] - e11 * dq[1][j]) / qb[1], de12 = (dq1[1][j] - e12 * dq[1][j]) / qb[1];
    double de21 = (dq2[0][j] - e21 * dq[1][j]) / qb[1], de22 = (dq2[1][j] - e22 * dq[1][j]) / qb[1];
    double dg2 = deta / l - eta / (l * l) * rb[j]; /* ∂(η/l) */
    Kb[2][j] -= v[0] * dg2, Kb[8][j] += v[0] * dg2;
    Kb[3][j] -= v[0] * 0.5 * de12, Kb[4][j] += v[0] * 0.5 * de11;
    Kb[9][j] -= v[0] * 0.5 * de22, Kb[10][j] += v[0] * 0.5 * de21;
    for (int a = 0; a < 12; a++) Kb[a][j] += (v[1] * G[1][a] + v[2] * G[2][a]) / l * rb[j];
  }
  /* K = E Kb Eᵀ, 3x3 block by block. */
  for (int bi = 0; bi < 4; bi++)
    for (int bj = 0; bj < 4; bj++) {
      double blk[9];
      for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) blk[3 * a + b] = Kb[3 * bi + a][3 * bj + b];
      nh_mat3_mul(E, blk, blk);
      nh_mat3_mul_nt(blk, E, blk);
      for (int a = 0; a < 3; a++)
        for (int b = 0; b < 3; b++) K[12 * (3 * bi + a) + 3 * bj + b] = blk[3 * a + b];
    }
  return U;
}
