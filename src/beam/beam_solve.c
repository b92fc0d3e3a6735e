/* beam_solve.c — solvers for a tool alone: static Newton with load steps and
 * one backward-Euler step (docs/beam.md §7).
 *
 * Unknowns: the 6n DOFs of nodes 1 … n (the base node 0 is prescribed).
 * Static: the consistent tangent is not symmetric (and near a buckling load
 * indefinite), so it is factorised dense by LU with partial pivoting.
 * Dynamic: A = (1 + hα) M + (hβ + h²) K with the symmetrised K is
 * banded (an element couples its two nodes' 12 DOFs: half-bandwidth 11) and
 * factorised by LAPACK's band Cholesky (dpbtrf, 6n · 12² flops); when that
 * finds A indefinite, the tangent's positive part replaces K and A, now
 * dense, is factorised by dense Cholesky ((6n)³/3 flops: 0.07 GFlop for
 * n = 100, milliseconds; nh_beam_dynamic_prepare). The same step quasi-static
 * (a Newton iteration of the coupled equilibrium, A = K): the full
 * consistent tangent by LU (LAPACK dgetrf) when its symmetric part is
 * positive definite, else the symmetric part's positive part as above.
 *
 * Static: Newton on K du = λ_k (f_ext + f_g(x)) − f_int(x), λ_k = k/S for
 * load steps k = 1 … S, each to convergence. The tangent is the exact
 * derivative of f_int (element.c), so convergence is quadratic; the
 * configuration dependence of consistent gravity moments and of dead moments
 * under non-planar rotation (a "dead" moment vector is not conservative for
 * spatial spins) is left out of the tangent: it costs a few iterations, not
 * accuracy, because the residual is exact. The residual norm divides the
 * moment entries by l₀ so forces and moments are commensurable.
 *
 * Stopping: relative residual <= tol, or a Newton correction <= tol times
 * the accumulated corrections of the solve (same scaled norm). The second
 * test is needed because the residual has a round-off floor: positions carry
 * an error ~eps·|x|, which the axial stiffness turns into forces
 * EA·eps·|x|/l₀ per element; for a slender beam under a small transverse
 * load this is 1e-7 of the load (measured 3e-8 for the cantilever of
 * tests/test_beam.c at tip rotation 1e-5), far above a useful tolerance,
 * while the displacements are already converged to round-off.
 *
 * Dynamic: backward Euler with one linearisation, the tissue's form
 * (solve/integrate.c), and the rotation update T ← exp(h ω) T (first-order
 * in h like the translation; the gyroscopic term vanishes because the lumped
 * rotary inertia is isotropic, see beam.c). The step matrix A takes the
 * symmetrised tangent (Cholesky); the right-hand side's K v, β K v and
 * prescribed-base terms take the exact one. That matters for a spinning
 * base: turning every section about its own tangent leaves a bent
 * isotropic beam's strains unchanged, so that velocity field is in the
 * right kernel of the exact K but not of its symmetric part, whose skew
 * remainder (the bending moments' S(m) terms) turned the spin into a
 * spurious lateral load h² ½(K − Kᵀ) v that grew twentyfold per step for a
 * bent needle turned 9° per step (docs/beam.md §2, tests/test_beam.c test 8). */
#include "beam/beam_impl.h"

#include <cblas.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* In-place LU with partial pivoting of the m x m row-major A. Returns
 * NH_ERR_NUMERIC (with a message) on a zero pivot. */
static int nh_beam_lu(double *A, int m, int *piv) {
  double amax = 0.0;
  for (long i = 0; i < (long)m * m; i++) amax = fmax(amax, fabs(A[i]));
  for (int k = 0; k < m; k++) {
    int p = k;
    for (int i = k + 1; i < m; i++)
      if (fabs(A[(size_t)i * m + k]) > fabs(A[(size_t)p * m + k])) p = i;
    piv[k] = p;
    if (!(fabs(A[(size_t)p * m + k]) > 1e-14 * amax))
      return NH_ERROR(NH_ERR_NUMERIC, "beam: singular tangent (pivot %d of %d)", k, m);
    if (p != k)
      for (int j = 0; j < m; j++) {
        double t = A[(size_t)k * m + j];
        A[(size_t)k * m + j] = A[(size_t)p * m + j], A[(size_t)p * m + j] = t;
      }
    const double inv = 1.0 / A[(size_t)k * m + k];
    for (int i = k + 1; i < m; i++) {
      double l = A[(size_t)i * m + k] * inv;
      A[(size_t)i * m + k] = l;
      if (l != 0.0)
        for (int j = k + 1; j < m; j++) A[(size_t)i * m + j] -= l * A[(size_t)k * m + j];
    }
  }
  return NH_OK;
}

static void nh_beam_lu_solve(const double *A, int m, const int *piv, double *x) {
  /* P A = L U with whole rows swapped (L's columns too): permute first. */
  for (int k = 0; k < m; k++) {
    double t = x[k];
    x[k] = x[piv[k]], x[piv[k]] = t;
  }
  for (int k = 0; k < m; k++)
    for (int i = k + 1; i < m; i++) x[i] -= A[(size_t)i * m + k] * x[k];
  for (int k = m - 1; k >= 0; k--) {
    for (int j = k + 1; j < m; j++) x[k] -= A[(size_t)k * m + j] * x[j];
    x[k] /= A[(size_t)k * m + k];
  }
}

/* Copy the free block (DOFs 6 … N−1) of the N x N matrix K into A (m x m). */
static void nh_beam_free_block(const double *K, int N, double *A) {
  const int m = N - 6;
  for (int i = 0; i < m; i++)
    memcpy(A + (size_t)i * m, K + (size_t)(i + 6) * N + 6, m * sizeof(double));
}

/* Norm of the free part of a nodal vector with moments divided by l0. */
static double nh_beam_scaled_norm(const double *r, int N, double l0) {
  double s = 0.0;
  for (int i = 6; i < N; i++) {
    double v = (i % 6 < 3) ? r[i] : r[i] / l0;
    s += v * v;
  }
  return sqrt(s);
}

typedef struct {
  double *f_int, *r, *K, *A, *du;
  int *piv;
} nh_beam_work;

static void nh_beam_work_free(nh_beam_work *w) {
  free(w->f_int), free(w->r), free(w->K), free(w->A), free(w->du), free(w->piv);
}

static int nh_beam_work_alloc(nh_beam_work *w, int N) {
  const size_t m = (size_t)N - 6;
  w->f_int = nh_calloc((size_t)N, sizeof(double));
  w->r = nh_calloc((size_t)N, sizeof(double));
  w->K = nh_calloc((size_t)N * N, sizeof(double));
  w->A = nh_calloc(m * m, sizeof(double));
  w->du = nh_calloc((size_t)N, sizeof(double));
  w->piv = nh_calloc(m, sizeof(int));
  if (!w->f_int || !w->r || !w->K || !w->A || !w->du || !w->piv) {
    nh_beam_work_free(w);
    return NH_ERR_MEMORY;
  }
  return NH_OK;
}

int nh_beam_solve_static(nh_beam *b, const nh_beam_static_options *o, const double *f_ext,
                         nh_beam_stats *stats) {
  NH_CHECK(o->load_steps >= 1 && o->max_iterations >= 1 && o->tolerance > 0, NH_ERR_INPUT,
           "beam static solve: load_steps %d, max_iterations %d, tolerance %g must be positive",
           o->load_steps, o->max_iterations, o->tolerance);
  const int N = 6 * (b->n + 1), m = N - 6;
  const int grav = o->gravity[0] != 0 || o->gravity[1] != 0 || o->gravity[2] != 0;
  nh_beam_work w = {0};
  NH_TRY(nh_beam_work_alloc(&w, N));
  double *load = nh_calloc((size_t)N, sizeof(double)), *acc = nh_calloc((size_t)N, sizeof(double));
  if (!load || !acc) {
    free(load), free(acc);
    nh_beam_work_free(&w);
    return NH_ERR_MEMORY;
  }
  int rc = NH_OK, total = 0;
  double rel = 0.0;
  for (int k = 1; k <= o->load_steps && !rc; k++) {
    const double lam = (double)k / o->load_steps;
    int converged = 0, small_correction = 0;
    for (int it = 0; it <= o->max_iterations; it++) {
      memset(load, 0, (size_t)N * sizeof(double));
      if (f_ext) memcpy(load, f_ext, (size_t)N * sizeof(double));
      if (grav) nh_beam_add_gravity(b, o->gravity, o->consistent_load, load);
      nh_beam_internal_force(b, w.f_int, w.K, 0);
      for (int i = 0; i < N; i++) w.r[i] = lam * load[i] - w.f_int[i];
      double rn = nh_beam_scaled_norm(w.r, N, b->l0);
      double scale =
          fmax(lam * nh_beam_scaled_norm(load, N, b->l0), nh_beam_scaled_norm(w.f_int, N, b->l0));
      scale = fmax(scale, 1e-300);
      rel = rn / scale;
      if (!isfinite(rn)) {
        rc = NH_ERROR(NH_ERR_NUMERIC, "beam static solve: non-finite residual in load step %d", k);
        break;
      }
      if (rel <= o->tolerance || small_correction) {
        converged = 1;
        break;
      }
      if (it == o->max_iterations) break;
      nh_beam_free_block(w.K, N, w.A);
      if ((rc = nh_beam_lu(w.A, m, w.piv))) break;
      memset(w.du, 0, 6 * sizeof(double));
      memcpy(w.du + 6, w.r + 6, (size_t)m * sizeof(double));
      nh_beam_lu_solve(w.A, m, w.piv, w.du + 6);
      nh_beam_increment(b, w.du);
      total++;
      for (int i = 6; i < N; i++) acc[i] += w.du[i];
      /* the correction is at the tolerance (the residual may sit on its
       * round-off floor): evaluate the residual once more and stop */
      small_correction =
          nh_beam_scaled_norm(w.du, N, b->l0) <= o->tolerance * nh_beam_scaled_norm(acc, N, b->l0);
    }
    if (!rc && !converged)
      rc = NH_ERROR(NH_ERR_NUMERIC,
                    "beam static solve: no convergence in load step %d of %d after %d "
                    "iterations (relative residual %.3g > %.3g)",
                    k, o->load_steps, o->max_iterations, rel, o->tolerance);
  }
  if (stats) stats->iterations = total, stats->residual = rel;
  free(load), free(acc);
  nh_beam_work_free(&w);
  return rc;
}

/* A's half-bandwidth in the free DOFs: an element couples the 12 DOFs of
 * its two nodes, so K_ij = 0 for |i − j| > 11. */
#define NH_BEAM_BAND 11

struct nh_beam_system {
  int N, m;               /* all DOFs, free DOFs (N − 6) */
  double *K, *A, *M, *Kv; /* N x N tangent, m x m factor of A, N mass, N work */
  double *B;              /* (NH_BEAM_BAND + 1) x m: A's band Cholesky factor when banded */
  int *piv;               /* m: A's LU pivots when lu */
  int projected;          /* the last prepare clipped negative tangent eigenvalues */
  int lu;                 /* A holds the LU factor of the full (unsymmetric) tangent */
  int banded;             /* B holds the band Cholesky factor of A (A unused) */
  /* prepare's work, every entry written before it is read: the internal
   * force (N), the free block and its symmetric part, the full one
   * (quasi-static), the positive part and a copy (m x m each); the positive
   * part's eigenvalues (m), eigenvectors (m x m) and their supports (2m) */
  double *fi, *Kf, *Kfull, *P, *work, *w, *Z;
  int *support;
};

int nh_beam_system_create(const nh_beam *b, nh_beam_system **out) {
  *out = NULL;
  nh_beam_system *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  s->N = 6 * (b->n + 1), s->m = s->N - 6;
  const size_t N = (size_t)s->N, m = (size_t)s->m;
  s->K = nh_calloc(N * N, sizeof(double));
  s->A = nh_calloc(m * m, sizeof(double));
  s->B = nh_calloc((size_t)(NH_BEAM_BAND + 1) * m, sizeof(double));
  s->M = nh_calloc(N, sizeof(double));
  s->Kv = nh_calloc(N, sizeof(double));
  s->piv = nh_calloc(m, sizeof(int));
  s->fi = nh_calloc(N, sizeof(double));
  s->Kf = nh_calloc(m * m, sizeof(double));
  s->Kfull = nh_calloc(m * m, sizeof(double));
  s->P = nh_calloc(m * m, sizeof(double));
  s->work = nh_calloc(m * m, sizeof(double));
  s->w = nh_calloc(m, sizeof(double));
  s->Z = nh_calloc(m * m, sizeof(double));
  s->support = nh_calloc(2 * m, sizeof(int));
  if (!s->K || !s->A || !s->B || !s->M || !s->Kv || !s->piv || !s->fi || !s->Kf || !s->Kfull ||
      !s->P || !s->work || !s->w || !s->Z || !s->support) {
    nh_beam_system_destroy(&s);
    return NH_ERR_MEMORY;
  }
  *out = s;
  return NH_OK;
}

void nh_beam_system_destroy(nh_beam_system **ps) {
  nh_beam_system *s = *ps;
  if (!s) return;
  free(s->K), free(s->A), free(s->B), free(s->M), free(s->Kv), free(s->piv);
  free(s->fi), free(s->Kf), free(s->Kfull), free(s->P), free(s->work), free(s->w), free(s->Z);
  free(s->support);
  free(s);
  *ps = NULL;
}

int nh_beam_step_system(nh_beam *b, nh_beam_system **out) {
  if (!b->system) NH_TRY(nh_beam_system_create(b, &b->system));
  *out = b->system;
  return NH_OK;
}

/* A = (1 + hα) M + cK K over the free DOFs into s->A; Cholesky in place
 * (lower, row-major = upper column-major for LAPACK, called as the latter:
 * LAPACKE's row-major path transposes the matrix in and out and scans it
 * for NaN at every call, 2 % of an adaptive phantom run with the solves
 * below; docs/phantom.md). Only K's lower row-major triangle is read.
 * Returns 0 on success. */
static int nh_beam_form_factor(nh_beam_system *s, const double *K, double cM, double cK) {
  const int m = s->m;
  for (int i = 0; i < m; i++) {
    double *row = s->A + (size_t)i * m;
    for (int j = 0; j <= i; j++) row[j] = cK * K[(size_t)i * m + j];
    row[i] += cM * s->M[i + 6];
  }
  return LAPACKE_dpotrf_work(LAPACK_COL_MAJOR, 'U', m, s->A, m);
}

/* The same A (K symmetric) in LAPACK's lower band storage, column-major,
 * B[(i − j) + (NH_BEAM_BAND + 1) j] = A_ij for 0 <= i − j <= NH_BEAM_BAND,
 * and its band Cholesky factor in place (dpbtrf: m (kd + 1)² flops against
 * m³/3 dense, 13 000 against 295 000 for the needle's m = 96). *definite:
 * 1 when A is positive definite (the factor is in s->B), else 0. Returns
 * NH_ERR_INTERNAL (with a message) when K has an entry outside the band. */
static int nh_beam_form_band_factor(nh_beam_system *s, const double *K, double cM, double cK,
                                    int *definite) {
  *definite = 0;
  const int m = s->m, ld = NH_BEAM_BAND + 1;
  for (int i = 0; i < m; i++)
    for (int j = 0; j < i - NH_BEAM_BAND; j++)
      if (K[(size_t)i * m + j] != 0.0)
        return NH_ERROR(NH_ERR_INTERNAL, "beam: tangent entry (%d, %d) outside the band %d", i, j,
                        NH_BEAM_BAND);
  for (int j = 0; j < m; j++)
    for (int i = j; i < m && i <= j + NH_BEAM_BAND; i++)
      s->B[(i - j) + (size_t)ld * j] =
          cK * K[(size_t)i * m + j] + (i == j ? cM * s->M[i + 6] : 0.0);
  *definite = LAPACKE_dpbtrf_work(LAPACK_COL_MAJOR, 'L', m, NH_BEAM_BAND, s->B, ld) == 0;
  return NH_OK;
}

/* The positive part of the symmetric K0 (m x m, row-major; K: m x m
 * work), eigenvalues below floor raised to it (cM > 0: floor 0, the negative part
 * dropped; cM = 0: 10⁻⁹ of the largest eigenvalue), into P's lower
 * row-major triangle:
 *   P = Σₖ max(wₖ, floor) vₖvₖᵀ = K + Σ_{wₖ < floor} (floor − wₖ) vₖvₖᵀ,
 * so only the eigenpairs below the floor are computed (dsyevr over the
 * interval (−‖K‖∞ − 1, floor], MRRR), a few for a compressed needle,
 * instead of all of them (dsyevd, then P = C Cᵀ by dsyrk). Work: s's w, Z
 * and support. */
static int nh_beam_positive_part(nh_beam_system *s, const double *K0, double *K, int m, double cM,
                                 double *P) {
  double *w = s->w, *Z = s->Z;
  int *support = s->support, found = 0, rc = NH_OK;
  double norm = 0.0, floor = 0.0;
  for (int i = 0; i < m; i++) {
    double r = 0.0;
    for (int j = 0; j < m; j++) r += fabs(K0[(size_t)i * m + j]);
    norm = fmax(norm, r);
  }
  memcpy(P, K0, sizeof(double) * (size_t)m * m);
  if (cM == 0.0) { /* the largest eigenvalue, for the floor */
    memcpy(K, K0, sizeof(double) * (size_t)m * m);
    if (LAPACKE_dsyevr(LAPACK_COL_MAJOR, 'N', 'I', 'L', m, K, m, 0.0, 0.0, m, m, 0.0, &found, w, Z,
                       m, support) ||
        found != 1)
      rc = NH_ERROR(NH_ERR_NUMERIC, "beam: the largest eigenvalue of the tangent failed");
    else
      floor = 1e-9 * fmax(w[0], 0.0);
  }
  memcpy(K, K0, sizeof(double) * (size_t)m * m);
  if (!rc && LAPACKE_dsyevr(LAPACK_COL_MAJOR, 'V', 'V', 'L', m, K, m, -norm - 1.0, floor, 0, 0, 0.0,
                            &found, w, Z, m, support))
    rc = NH_ERROR(NH_ERR_NUMERIC, "beam dynamic step: eigen-decomposition of the tangent failed");
  for (int k = 0; k < found && !rc; k++) /* column k of Z (column-major): vₖ */
    cblas_dsyr(CblasRowMajor, CblasLower, m, floor - w[k], Z + (size_t)k * m, 1, P, m);
  return rc;
}

int nh_beam_dynamic_prepare(nh_beam *b, const nh_beam_dynamic_options *o, const double *f_ext,
                            const double base_velocity[6], nh_beam_system *s, double *rhs) {
  NH_CHECK(o->dt > 0 && o->alpha >= 0 && o->beta >= 0, NH_ERR_INPUT,
           "beam dynamic step: dt %g must be positive, alpha %g and beta %g >= 0", o->dt, o->alpha,
           o->beta);
  const int N = s->N, m = s->m;
  const double h = o->dt, cK = h * o->beta + h * h, cM = o->quasi_static ? 0.0 : 1.0 + h * o->alpha;
  double *fi = s->fi, *Kf = s->Kf;
  nh_beam_mass(b, s->M);
  /* the exact tangent on the right-hand side (see the file comment: a
   * spinning base), its symmetric part in A */
  nh_beam_internal_force(b, fi, s->K, 0);
  for (int i = 0; i < N; i++) {
    double v = 0.0;
    for (int j = 0; j < N; j++) v += s->K[(size_t)i * N + j] * b->v[j];
    s->Kv[i] = v;
  }
  for (int i = 6; i < N; i++) {
    double fe = (f_ext ? f_ext[i] : 0.0) + (i % 6 < 3 ? s->M[i] * o->gravity[i % 6] : 0.0);
    double r =
        h * (fe - fi[i] - o->alpha * s->M[i] * b->v[i] - o->beta * s->Kv[i]) - h * h * s->Kv[i];
    /* the base's prescribed velocity change moves to the right-hand side */
    for (int j = 0; j < 6; j++) r -= cK * s->K[(size_t)i * N + j] * (base_velocity[j] - b->v[j]);
    rhs[i - 6] = r;
  }
  nh_beam_free_block(s->K, N, Kf);
  int rc = NH_OK;
  s->projected = s->lu = s->banded = 0;
  double *Kfull = NULL; /* quasi-static: the free block of the full tangent */
  if (o->quasi_static) {
    Kfull = s->Kfull;
    memcpy(Kfull, Kf, sizeof(double) * (size_t)m * m);
  }
  for (int i = 0; i < m; i++) /* Kf: the symmetric part (A; the definiteness test) */
    for (int j = 0; j < i; j++) {
      const double k = 0.5 * (Kf[(size_t)i * m + j] + Kf[(size_t)j * m + i]);
      Kf[(size_t)i * m + j] = Kf[(size_t)j * m + i] = k;
    }
  int definite = 0;
  rc = nh_beam_form_band_factor(s, Kf, cM, cK, &definite);
  if (!rc && definite) {
    /* the symmetric part is positive definite: A's band factor serves,
     * quasi-static: factorise the full tangent by LU (A = K, no mass), for
     * Newton's rate */
    s->banded = !Kfull;
    if (Kfull) {
      for (size_t k = 0; k < (size_t)m * m; k++) s->A[k] = cK * Kfull[k];
      if (LAPACKE_dgetrf(LAPACK_ROW_MAJOR, m, m, s->A, m, s->piv) != 0)
        rc = NH_ERROR(NH_ERR_NUMERIC, "beam quasi-static step: the tangent is singular");
      s->lu = 1;
    }
  } else if (!rc) {
    /* A is indefinite: the tool is compressed beyond a buckling load of
     * the step operator. Use the tangent's positive part (eigenvalues
     * clipped at 0, or without mass at 1e-9 of the largest): the residual
     * stays exact, A stays positive definite (dense: the eigenvectors are
     * not local). */
    rc = nh_beam_positive_part(s, Kf, s->work, m, cM, s->P);
    if (!rc && nh_beam_form_factor(s, s->P, cM, cK))
      rc = NH_ERROR(NH_ERR_NUMERIC, "beam dynamic step: the step matrix is not positive definite");
    s->projected = 1;
  }
  return rc;
}

void nh_beam_system_solve_many(const nh_beam_system *s, int nrhs, double *Y) {
  if (nrhs <= 0) return;
  if (s->lu)
    for (int c = 0; c < nrhs; c++) /* row-major LU: one column at a time */
      LAPACKE_dgetrs(LAPACK_ROW_MAJOR, 'N', s->m, 1, s->A, s->m, s->piv, Y + (size_t)c * s->m, 1);
  else if (s->banded)
    LAPACKE_dpbtrs_work(LAPACK_COL_MAJOR, 'L', s->m, NH_BEAM_BAND, nrhs, s->B, NH_BEAM_BAND + 1, Y,
                        s->m);
  else
    LAPACKE_dpotrs_work(LAPACK_COL_MAJOR, 'U', s->m, nrhs, s->A, s->m, Y, s->m);
}

void nh_beam_system_solve(const nh_beam_system *s, double *y) {
  nh_beam_system_solve_many(s, 1, y);
}

int nh_beam_system_projected(const nh_beam_system *s) {
  return s->projected;
}

int nh_beam_dynamic_finish(nh_beam *b, double dt, const double base_velocity[6], const double *dv) {
  const int N = 6 * (b->n + 1);
  for (int i = 0; i < N - 6; i++)
    if (!isfinite(dv[i]))
      return NH_ERROR(NH_ERR_NUMERIC, "beam dynamic step: non-finite velocity update");
  double *d = nh_calloc((size_t)N, sizeof(double));
  if (!d) return NH_ERR_MEMORY;
  memcpy(b->v, base_velocity, 6 * sizeof(double));
  for (int i = 6; i < N; i++) b->v[i] += dv[i - 6];
  for (int i = 0; i < N; i++) d[i] = dt * b->v[i];
  nh_beam_increment(b, d);
  free(d);
  return NH_OK;
}

int nh_beam_step_dynamic(nh_beam *b, const nh_beam_dynamic_options *o, const double *f_ext) {
  const double still[6] = {0, 0, 0, 0, 0, 0};
  nh_beam_system *s = NULL;
  NH_TRY(nh_beam_step_system(b, &s));
  double *dv = nh_calloc((size_t)s->m, sizeof(double));
  int rc = dv ? NH_OK : NH_ERR_MEMORY;
  memset(b->v, 0, 6 * sizeof(double)); /* the base is prescribed and at rest */
  if (!rc) rc = nh_beam_dynamic_prepare(b, o, f_ext, still, s, dv);
  if (!rc) nh_beam_system_solve(s, dv);
  if (!rc) rc = nh_beam_dynamic_finish(b, o->dt, still, dv);
  free(dv);
  return rc;
}
