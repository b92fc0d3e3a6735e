/* beam_solve.c — solvers for a tool alone: static Newton with load steps and
 * one backward-Euler step (docs/beam.md §7).
 *
 * Unknowns: the 6n DOFs of nodes 1 … n (the base node 0 is prescribed).
 * The tangent is assembled dense and factorised by LU with partial pivoting
 * (the consistent tangent is not symmetric; near a buckling load the
 * symmetrised one is indefinite, so Cholesky/LDLᵀ without pivoting is not
 * safe). Cost (6n)³/3 flops: 0.07 GFlop for n = 100, milliseconds; the
 * coupled simulator factorises the tool's banded block with the tissue's
 * solver instead.
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
 * (solve/integrate.c) with the symmetrised tangent, and the rotation update
 * T ← exp(h ω) T (first-order in h like the translation; the gyroscopic term
 * vanishes because the lumped rotary inertia is isotropic, see beam.c). */
#include "beam/beam_impl.h"

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

int nh_beam_step_dynamic(nh_beam *b, const nh_beam_dynamic_options *o, const double *f_ext) {
  NH_CHECK(o->dt > 0 && o->alpha >= 0 && o->beta >= 0, NH_ERR_INPUT,
           "beam dynamic step: dt %g must be positive, alpha %g and beta %g >= 0", o->dt, o->alpha,
           o->beta);
  const int N = 6 * (b->n + 1), m = N - 6;
  const double h = o->dt;
  nh_beam_work w = {0};
  NH_TRY(nh_beam_work_alloc(&w, N));
  double *M = nh_calloc((size_t)N, sizeof(double)), *Kv = nh_calloc((size_t)N, sizeof(double));
  int rc = NH_OK;
  if (!M || !Kv) {
    rc = NH_ERR_MEMORY;
    goto done;
  }
  nh_beam_mass(b, M);
  memset(b->v, 0, 6 * sizeof(double)); /* the base is prescribed */
  nh_beam_internal_force(b, w.f_int, w.K, 1);
  for (int i = 0; i < N; i++) {
    double s = 0.0;
    for (int j = 0; j < N; j++) s += w.K[(size_t)i * N + j] * b->v[j];
    Kv[i] = s;
  }
  for (int i = 0; i < N; i++) {
    double fe = (f_ext ? f_ext[i] : 0.0) + (i % 6 < 3 ? M[i] * o->gravity[i % 6] : 0.0);
    w.r[i] = h * (fe - w.f_int[i] - o->alpha * M[i] * b->v[i] - o->beta * Kv[i]) - h * h * Kv[i];
  }
  nh_beam_free_block(w.K, N, w.A);
  for (int i = 0; i < m; i++) {
    double *row = w.A + (size_t)i * m;
    for (int j = 0; j < m; j++) row[j] *= h * o->beta + h * h;
    row[i] += (1.0 + h * o->alpha) * M[i + 6];
  }
  if ((rc = nh_beam_lu(w.A, m, w.piv))) goto done;
  memcpy(w.du, w.r + 6, (size_t)m * sizeof(double));
  nh_beam_lu_solve(w.A, m, w.piv, w.du);
  for (int i = 0; i < m; i++) {
    if (!isfinite(w.du[i])) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "beam dynamic step: non-finite velocity update");
      goto done;
    }
    b->v[i + 6] += w.du[i];
  }
  for (int i = 0; i < N; i++) w.r[i] = h * b->v[i];
  nh_beam_increment(b, w.r);
done:
  free(M), free(Kv);
  nh_beam_work_free(&w);
  return rc;
}
