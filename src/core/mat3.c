/* mat3.c — 3x3 algebra, symmetric eigen-decomposition and the polar rotation.
 *
 * The corotational hexahedron (docs/theory.md §2) needs R from F = R U at the
 * element centre for every F the step can produce, including inverted
 * (det F < 0) and flattened (det F = 0) elements. Iterative polar schemes
 * (Higham's Newton iteration) divide by det F and fail there. We use the SVD
 * instead: the eigenvectors V of C = FᵀF (cyclic Jacobi, unconditionally
 * convergent for symmetric 3x3) give the right singular vectors; the left
 * ones are u0 = F v0 / |F v0|, u1 = the part of F v1 orthogonal to u0
 * (any unit vector orthogonal to u0 if that part vanishes), u2 = u0 × u1.
 * Building u2 by the cross product makes det U = +1, so the sign of det F is
 * absorbed by the smallest singular value (the "rotation-variant SVD" of
 * Irving et al. 2004) and R = U Vᵀ is always a proper rotation. No division
 * by a quantity that can vanish is left unguarded, so finite F never gives
 * NaN. */
#include "core/core.h"

#include <math.h>
#include <string.h>

double nh_vec3_dot(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

double nh_vec3_norm(const double a[3]) {
  return sqrt(nh_vec3_dot(a, a));
}

void nh_vec3_cross(const double a[3], const double b[3], double c[3]) {
  double t[3] = {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
  c[0] = t[0], c[1] = t[1], c[2] = t[2];
}

double nh_vec3_normalize(double a[3]) {
  double n = nh_vec3_norm(a);
  if (n > 0) a[0] /= n, a[1] /= n, a[2] /= n;
  return n;
}

void nh_mat3_identity(double A[9]) {
  memset(A, 0, 9 * sizeof(double));
  A[0] = A[4] = A[8] = 1.0;
}

void nh_mat3_mul(const double A[9], const double B[9], double C[9]) {
  double T[9];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      T[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
  memcpy(C, T, sizeof T);
}

void nh_mat3_mul_tn(const double A[9], const double B[9], double C[9]) {
  double T[9];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      T[3 * i + j] = A[i] * B[j] + A[3 + i] * B[3 + j] + A[6 + i] * B[6 + j];
  memcpy(C, T, sizeof T);
}

void nh_mat3_mul_nt(const double A[9], const double B[9], double C[9]) {
  double T[9];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
      T[3 * i + j] =
          A[3 * i] * B[3 * j] + A[3 * i + 1] * B[3 * j + 1] + A[3 * i + 2] * B[3 * j + 2];
  memcpy(C, T, sizeof T);
}

void nh_mat3_transpose(const double A[9], double At[9]) {
  double T[9];
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++) T[3 * j + i] = A[3 * i + j];
  memcpy(At, T, sizeof T);
}

double nh_mat3_det(const double A[9]) {
  return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) +
         A[2] * (A[3] * A[7] - A[4] * A[6]);
}

int nh_mat3_singular(const double A[9], double det) {
  double scale = 0.0; /* the largest |A_i|, NaN entries ignored (as fmax would; not a call) */
  for (int i = 0; i < 9; i++) scale = fabs(A[i]) > scale ? fabs(A[i]) : scale;
  return !(fabs(det) > 1e-300 && fabs(det) > 1e-14 * scale * scale * scale);
}

int nh_mat3_inverse(const double A[9], double Ainv[9]) {
  double det = nh_mat3_det(A);
  if (nh_mat3_singular(A, det)) return NH_ERR_NUMERIC;
  double T[9] = {A[4] * A[8] - A[5] * A[7], A[2] * A[7] - A[1] * A[8], A[1] * A[5] - A[2] * A[4],
                 A[5] * A[6] - A[3] * A[8], A[0] * A[8] - A[2] * A[6], A[2] * A[3] - A[0] * A[5],
                 A[3] * A[7] - A[4] * A[6], A[1] * A[6] - A[0] * A[7], A[0] * A[4] - A[1] * A[3]};
  for (int i = 0; i < 9; i++) Ainv[i] = T[i] / det;
  return NH_OK;
}

void nh_mat3_rotation(const double r[3], double R[9]) {
  double th = nh_vec3_norm(r);
  nh_mat3_identity(R);
  if (th == 0.0) return;
  double k[3] = {r[0] / th, r[1] / th, r[2] / th};
  double c = cos(th), s = sin(th), t = 1.0 - c;
  R[0] = c + t * k[0] * k[0];
  R[1] = t * k[0] * k[1] - s * k[2];
  R[2] = t * k[0] * k[2] + s * k[1];
  R[3] = t * k[0] * k[1] + s * k[2];
  R[4] = c + t * k[1] * k[1];
  R[5] = t * k[1] * k[2] - s * k[0];
  R[6] = t * k[0] * k[2] - s * k[1];
  R[7] = t * k[1] * k[2] + s * k[0];
  R[8] = c + t * k[2] * k[2];
}

void nh_mat3_sym_eigen(const double S[9], double w[3], double V[9]) {
  double A[9];
  memcpy(A, S, sizeof A);
  nh_mat3_identity(V);
  for (int sweep = 0; sweep < 64; sweep++) {
    double off = A[1] * A[1] + A[2] * A[2] + A[5] * A[5];
    double diag = A[0] * A[0] + A[4] * A[4] + A[8] * A[8];
    if (off <= 1e-34 * diag || off == 0.0) break;
    static const int P[3][2] = {{0, 1}, {0, 2}, {1, 2}};
    for (int r = 0; r < 3; r++) {
      int p = P[r][0], q = P[r][1];
      double apq = A[3 * p + q];
      if (apq == 0.0) continue;
      /* Rotation zeroing A_pq (Golub & Van Loan, sym.schur2). */
      double tau = (A[3 * q + q] - A[3 * p + p]) / (2.0 * apq);
      double t = (tau >= 0.0 ? 1.0 : -1.0) / (fabs(tau) + sqrt(1.0 + tau * tau));
      double c = 1.0 / sqrt(1.0 + t * t), s = t * c;
      for (int k = 0; k < 3; k++) { /* A <- A G */
        double akp = A[3 * k + p], akq = A[3 * k + q];
        A[3 * k + p] = c * akp - s * akq;
        A[3 * k + q] = s * akp + c * akq;
      }
      for (int k = 0; k < 3; k++) { /* A <- Gᵀ A */
        double apk = A[3 * p + k], aqk = A[3 * q + k];
        A[3 * p + k] = c * apk - s * aqk;
        A[3 * q + k] = s * apk + c * aqk;
      }
      for (int k = 0; k < 3; k++) { /* V <- V G */
        double vkp = V[3 * k + p], vkq = V[3 * k + q];
        V[3 * k + p] = c * vkp - s * vkq;
        V[3 * k + q] = s * vkp + c * vkq;
      }
    }
  }
  w[0] = A[0], w[1] = A[4], w[2] = A[8];
  /* Sort descending, permuting V's columns alongside. */
  for (int i = 0; i < 2; i++)
    for (int j = 0; j < 2 - i; j++)
      if (w[j] < w[j + 1]) {
        double tw = w[j];
        w[j] = w[j + 1], w[j + 1] = tw;
        for (int k = 0; k < 3; k++) {
          double tv = V[3 * k + j];
          V[3 * k + j] = V[3 * k + j + 1], V[3 * k + j + 1] = tv;
        }
      }
  if (nh_mat3_det(V) < 0.0)
    for (int k = 0; k < 3; k++) V[3 * k + 2] = -V[3 * k + 2];
}

void nh_polar_rotation(const double F[9], double R[9]) {
  double C[9], w[3], V[9];
  nh_mat3_mul_tn(F, F, C);
  nh_mat3_sym_eigen(C, w, V);
  double u[3][3], v[3][3];
  for (int i = 0; i < 3; i++) {
    for (int k = 0; k < 3; k++) v[i][k] = V[3 * k + i];
    nh_mat3_vec(F, v[i], u[i]);
  }
  double n0 = nh_vec3_norm(u[0]);
  if (!(n0 > 1e-300) || !isfinite(n0)) { /* F = 0 (or not finite): no rotation to extract */
    nh_mat3_identity(R);
    return;
  }
  for (int k = 0; k < 3; k++) u[0][k] /= n0;
  double d = u[0][0] * u[1][0] + u[0][1] * u[1][1] + u[0][2] * u[1][2];
  for (int k = 0; k < 3; k++) u[1][k] -= d * u[0][k];
  double n1 = nh_vec3_norm(u[1]);
  if (n1 <= 1e-12 * n0) { /* rank 1: any direction orthogonal to u0 */
    double e[3] = {0, 0, 0};
    int m = fabs(u[0][0]) < fabs(u[0][1]) ? (fabs(u[0][0]) < fabs(u[0][2]) ? 0 : 2)
                                          : (fabs(u[0][1]) < fabs(u[0][2]) ? 1 : 2);
    e[m] = 1.0;
    nh_vec3_cross(u[0], e, u[1]);
    n1 = nh_vec3_norm(u[1]);
  }
  for (int k = 0; k < 3; k++) u[1][k] /= n1;
  nh_vec3_cross(u[0], u[1], u[2]);
  /* R = U Vᵀ = Σ_i u_i v_iᵀ */
  for (int a = 0; a < 3; a++)
    for (int b = 0; b < 3; b++)
      R[3 * a + b] = u[0][a] * v[0][b] + u[1][a] * v[1][b] + u[2][a] * v[2][b];
}
