/* test_lazy — lazy element tangents (solver.lazy_rotation, solve/assemble.c).
 *
 * A bar 40x20x20 mm (24x12x12 cells, clamped at x = 0) is twisted about its
 * axis by θ(x) = Δ x / L and stretched by ε along x: the cell at x_c turns by
 * about Δ x_c / L, so ‖R − I‖_F ≈ √2 Δ x_c / L. With √2 Δ = 1.5 τ the
 * cells beyond x_c = 2L/3 (a third) exceed the tolerance τ and are rebuilt,
 * in place (at most half are), while the others keep the rest tangent; the
 * stretch (√2 ε = 0.42 τ) moves B-bar's cof F̄ by less than τ. Checked, for
 * the full and the B-bar element:
 *  1. τ = 0: after a history (rest, then the deformed state) the force, K̃ v
 *     and A equal bitwise those of a fresh system assembled at the deformed
 *     state only (the exact path);
 *  2. τ > 0: the force is exact (bitwise the fresh one: it never lags); A's
 *     error E = A_lazy − A_exact obeys, for any p, with p_e the cell's values,
 *       |pᵀ E p| ≤ Σ_e cK φ [2τ ‖K₀‖ + κV ‖ḡ‖² (2‖C‖ + τ) τ] |p_e|²
 *     (Frobenius norms bound the spectral ones; C = cof F̄ at the deformed
 *     state, ‖C̃‖ ≤ ‖C‖ + τ; the derivation is in solve/assemble.c), plus
 *     1e-12 Σ_e cK ‖K₀‖ |p_e|² of in-place round-off; A_lazy p equals, to
 *     round-off, an independent prediction, A_exact p plus cK (K_e(rest) −
 *     K_e(now)) p_e summed over the cells whose frame moved by at most τ
 *     (those keep their rest tangent, the others are rebuilt); and the
 *     error is proportional to the rotation change: τ = 1e-2 against 1e-3
 *     (Δ and ε scaled alike) gives 10× within 20 %;
 *  3. a repeated assembly at a state within τ rebuilds no tangent (A kept);
 *  4. 1 and 2 threads give bitwise the same force, K̃ v and A along the same
 *     history (the in-place path runs in parallel: 144 cells per colour);
 *  5. an assembly repeated at the same u and v hands back the last force and
 *     K̃ v (assemble.c): it must equal a fresh system's at every change of
 *     its inputs, u and v changed in place (same buffers), cM, K̃ v asked for
 *     after an assembly without it, and τ lowered to 0 at the same state
 *     (the lagging tangents must then be rebuilt). */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

enum { NX = 24, NY = 12, NZ = 12 };
static const double L = 0.04, H = 0.02;

/* u at every node: twist Δ x / L about the axis (y, z) = (H/2, H/2), stretch ε. */
static void deform(const nh_mesh *m, double twist, double stretch, double *u) {
  for (int i = 0; i < m->n_nodes; i++) {
    const double *X = m->X + 3 * i;
    double th = twist * X[0] / L, y = X[1] - H / 2, z = X[2] - H / 2;
    u[3 * i] = stretch * X[0];
    u[3 * i + 1] = cos(th) * y - sin(th) * z - y;
    u[3 * i + 2] = sin(th) * y + cos(th) * z - z;
  }
}

static double frob(const double *a, int n) {
  double s = 0.0;
  for (int i = 0; i < n; i++) s += a[i] * a[i];
  return sqrt(s);
}

typedef struct {
  nh_mesh *m;
  nh_tissue *t;
  unsigned char *fixed;
  int n, nf;
  double *u0, *u1, *v, *p, *f[2], *kv[2], *y[2], *full;
} setup;

static const double cM = 2.0, cK = 0.5;

/* Assemble sys through `history` states (u0 then u1, or u1 only). */
static void assemble(setup *S, nh_system *sys, int history, int threads, int out) {
  if (history) nh_system_assemble(sys, S->u0, S->v, cM, cK, S->f[out], S->kv[out], threads);
  nh_system_assemble(sys, S->u1, S->v, cM, cK, S->f[out], S->kv[out], threads);
  nh_system_apply(sys, S->p, S->y[out]);
}

/* The measured |pᵀ E p| and its bound (τ > 0). */
static void error_and_bound(setup *S, double tau, double *error, double *bound) {
  const nh_mesh *m = S->m;
  const nh_tissue *t = S->t;
  double pEp = 0.0, b = 0.0;
  for (int i = 0; i < S->nf; i++) pEp += S->p[i] * (S->y[0][i] - S->y[1][i]);
  const double *gbar0 = nh_tissue_gbar(t, m->leaves[0]);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l], s = t->cell_shape[c];
    double pe[24], ue[24], lambda, mu, cof[9];
    nh_mesh_cell_coords(m, S->full, c, pe);
    double p2 = 0.0;
    for (int i = 0; i < 24; i++) p2 += pe[i] * pe[i];
    double k0 = frob(t->K0 + 576 * s, 576);
    double be = 2.0 * tau * k0 + 1e-12 * k0;
    if (gbar0) {
      const double *g = t->Gbar + 24 * s;
      nh_mesh_cell_coords(m, S->u1, c, ue);
      nh_hex_mean_dilatation(ue, g, cof);
      nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
      double kV = (lambda + 2.0 * mu / 3.0) * t->volume[s], g2 = frob(g, 24);
      be += kV * g2 * g2 * (2.0 * frob(cof, 9) + tau) * tau;
    }
    b += cK * m->fill[c] * be * p2;
  }
  *error = fabs(pEp);
  *bound = b;
}

/* sys's force, K̃ v and A p (from the last assembly) against a fresh
 * system's assembled once at (u, v, c_M): bitwise (τ = 0 has no history). */
static void against_fresh(setup *S, nh_system *sys, const double *u, const double *v, double cm,
                          const char *what, const char *name) {
  nh_system *fresh;
  const size_t bn = sizeof(double) * (size_t)S->n, bf = sizeof(double) * (size_t)S->nf;
  CHECK_OK(nh_system_create(S->t, S->fixed, NULL, &fresh));
  nh_system_assemble(fresh, u, v, cm, cK, S->f[1], S->kv[1], 1);
  nh_system_apply(fresh, S->p, S->y[1]);
  nh_system_apply(sys, S->p, S->y[0]);
  CHECK(!memcmp(S->f[0], S->f[1], bn), "%s: %s: f_int differs from a fresh assembly", name, what);
  CHECK(!memcmp(S->kv[0], S->kv[1], bn), "%s: %s: K v differs from a fresh assembly", name, what);
  CHECK(!memcmp(S->y[0], S->y[1], bf), "%s: %s: A differs from a fresh assembly", name, what);
  nh_system_destroy(&fresh);
}

/* Part 5 on sys (assembled at u1 with tolerance tau, lagging tangents). */
static void repeated(setup *S, double tau, nh_system *sys, const char *name) {
  const size_t bn = sizeof(double) * (size_t)S->n;
  double *u = malloc(bn), *v = malloc(bn);
  memcpy(u, S->u1, bn), memcpy(v, S->v, bn);
  /* τ lowered to 0 at the same state: the tangents kept within τ are rebuilt */
  nh_system_set_lazy(sys, 0.0);
  nh_system_lazy_reset(sys);
  nh_system_assemble(sys, u, v, cM, cK, S->f[0], S->kv[0], 1);
  CHECK(nh_system_lazy_updates(sys) > 0, "%s: tau %g -> 0: no tangent rebuilt", name, tau);
  against_fresh(S, sys, u, v, cM, "tau lowered to 0", name);
  /* the same state again: nothing rebuilt, the same results */
  nh_system_lazy_reset(sys);
  memset(S->f[0], 0, bn), memset(S->kv[0], 0, bn);
  nh_system_assemble(sys, u, v, cM, cK, S->f[0], S->kv[0], 1);
  CHECK(nh_system_lazy_updates(sys) == 0, "%s: repeated: %d tangents rebuilt", name,
        nh_system_lazy_updates(sys));
  against_fresh(S, sys, u, v, cM, "repeated", name);
  /* u changed in place */
  for (int i = 0; i < S->n; i++) u[i] += 1e-3 * tau * H * nh_rand();
  nh_system_assemble(sys, u, v, cM, cK, S->f[0], S->kv[0], 1);
  against_fresh(S, sys, u, v, cM, "u changed", name);
  /* v changed in place */
  for (int i = 0; i < S->n; i++) v[i] = nh_rand();
  nh_system_assemble(sys, u, v, cM, cK, S->f[0], S->kv[0], 1);
  against_fresh(S, sys, u, v, cM, "v changed", name);
  /* another c_M (A afresh) */
  nh_system_assemble(sys, u, v, 2.0 * cM, cK, S->f[0], S->kv[0], 1);
  against_fresh(S, sys, u, v, 2.0 * cM, "c_M changed", name);
  /* without K̃ v at a new state, then with it at the same state */
  for (int i = 0; i < S->n; i++) u[i] -= 1e-3 * tau * H * nh_rand();
  nh_system_assemble(sys, u, NULL, 2.0 * cM, cK, S->f[0], NULL, 1);
  nh_system_assemble(sys, u, v, 2.0 * cM, cK, S->f[0], S->kv[0], 1);
  against_fresh(S, sys, u, v, 2.0 * cM, "K v asked for after an assembly without", name);
  free(u), free(v);
}

/* All checks for one formulation (bbar = 0: full integration). */
static void run(int bbar) {
  setup S = {0};
  const double lo[3] = {0, 0, 0}, hi[3] = {L, H, H};
  const int grid[3] = {NX, NY, NZ};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &S.m));
  nh_material mat = {1e5, 0.45, 1000, bbar ? NH_FORMULATION_BBAR : NH_FORMULATION_FULL};
  CHECK_OK(nh_tissue_create(S.m, &mat, &S.t));
  S.fixed = calloc((size_t)S.m->n_nodes, 1);
  for (int i = 0; i < S.m->n_nodes; i++) S.fixed[i] = S.m->X[3 * i] < 1e-6;
  S.n = 3 * S.m->n_nodes;
  nh_system *probe;
  CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &probe));
  S.nf = nh_system_free_dofs(probe);
  nh_system_destroy(&probe);
  S.u0 = calloc((size_t)S.n, sizeof(double));
  S.u1 = malloc(sizeof(double) * S.n);
  S.v = malloc(sizeof(double) * S.n);
  S.full = malloc(sizeof(double) * S.n);
  S.p = malloc(sizeof(double) * S.nf);
  for (int k = 0; k < 2; k++) {
    S.f[k] = malloc(sizeof(double) * S.n);
    S.kv[k] = malloc(sizeof(double) * S.n);
    S.y[k] = malloc(sizeof(double) * S.nf);
  }
  for (int i = 0; i < S.n; i++) S.v[i] = nh_rand();
  for (int i = 0; i < S.nf; i++) S.p[i] = nh_rand();
  const char *name = bbar ? "B-bar" : "full";
  double err[2] = {0, 0};
  const double taus[2] = {1e-3, 1e-2};

  for (int k = 0; k < 2; k++) {
    double tau = taus[k], twist = 1.5 * tau / sqrt(2.0), stretch = 0.3 * tau;
    deform(S.m, twist, stretch, S.u1);
    nh_system *exact, *zero, *lazy1, *lazy2, *lazy3;
    CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &exact));
    CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &zero));
    CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &lazy1));
    CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &lazy2));
    CHECK_OK(nh_system_create(S.t, S.fixed, NULL, &lazy3));
    nh_system_set_lazy(lazy1, tau);
    const size_t bn = sizeof(double) * (size_t)S.n, bf = sizeof(double) * (size_t)S.nf;

    /* 1. τ = 0 through a history equals a fresh assembly, bitwise. */
    assemble(&S, exact, 0, 0, 1);
    assemble(&S, zero, 1, 0, 0);
    CHECK(!memcmp(S.f[0], S.f[1], bn), "%s: tau 0: f_int differs from the fresh assembly", name);
    CHECK(!memcmp(S.kv[0], S.kv[1], bn), "%s: tau 0: K v differs from the fresh assembly", name);
    CHECK(!memcmp(S.y[0], S.y[1], bf), "%s: tau 0: A differs from the fresh assembly", name);

    /* 2. τ > 0: exact force, bounded tangent error. */
    nh_system_assemble(lazy1, S.u0, S.v, cM, cK, S.f[0], S.kv[0], 1);
    int all = nh_system_lazy_updates(lazy1);
    nh_system_lazy_reset(lazy1);
    nh_system_assemble(lazy1, S.u1, S.v, cM, cK, S.f[0], S.kv[0], 1);
    int updated = nh_system_lazy_updates(lazy1);
    nh_system_apply(lazy1, S.p, S.y[0]);
    CHECK(all == S.m->n_leaves, "%s: the first assembly builds every tangent: %d of %d", name, all,
          S.m->n_leaves);
    CHECK(updated > S.m->n_leaves / 4 && updated < S.m->n_leaves / 2,
          "%s: tau %g: expected about a third of %d tangents rebuilt, got %d", name, tau,
          S.m->n_leaves, updated);
    CHECK(!memcmp(S.f[0], S.f[1], bn), "%s: tau %g: the force is not the exact one", name, tau);
    nh_system_scatter(exact, S.p, S.full);
    double e, b;
    error_and_bound(&S, tau, &e, &b);
    err[k] = e;
    CHECK(e <= b, "%s: tau %g: |p'(A_lazy - A_exact)p| = %.3g above its bound %.3g", name, tau, e,
          b);
    /* Independently: the lazy A is the exact one plus, over the cells whose
     * frame moved by at most τ since the rest state (they keep the rest
     * tangent), cK (K(rest frame) − K(current frame)). */
    double *w = calloc((size_t)S.n, sizeof(double)), *wf = malloc(bf), scale = 0.0;
    int lagging = 0;
    for (int l = 0; l < S.m->n_leaves; l++) {
      int c = S.m->leaves[l];
      double fr0[NH_HEX_FRAME], fr1[NH_HEX_FRAME], fe[24], K0[576], K1[576], pe[24];
      nh_tissue_element_force(S.t, c, S.u0, fe, fr0);
      nh_tissue_element_force(S.t, c, S.u1, fe, fr1);
      nh_hex_frame_corotational(fr0); /* the system's tangent: corotational */
      nh_hex_frame_corotational(fr1);
      double dr = 0.0, dc = 0.0;
      for (int i = 0; i < 9; i++)
        dr += (fr1[i] - fr0[i]) * (fr1[i] - fr0[i]),
            dc += (fr1[9 + i] - fr0[9 + i]) * (fr1[9 + i] - fr0[9 + i]);
      if (sqrt(fmax(dr, dc)) > tau) continue;
      lagging++;
      nh_tissue_element_tangent(S.t, c, fr0, K0);
      nh_tissue_element_tangent(S.t, c, fr1, K1);
      nh_mesh_cell_coords(S.m, S.full, c, pe);
      for (int r = 0; r < 24; r++)
        for (int q = 0; q < 24; q++)
          w[3 * S.m->cells[8 * c + r / 3] + r % 3] += (K0[24 * r + q] - K1[24 * r + q]) * pe[q];
    }
    nh_system_gather(exact, w, wf);
    for (int i = 0; i < S.nf; i++) scale = fmax(scale, fabs(S.y[1][i]));
    double worst = 0.0;
    for (int i = 0; i < S.nf; i++) worst = fmax(worst, fabs(S.y[0][i] - S.y[1][i] - cK * wf[i]));
    CHECK(worst <= 1e-11 * scale,
          "%s: tau %g: lazy A p differs from the prediction by %.3g (> 1e-11 of max |A p| = %.3g)",
          name, tau, worst, scale);
    CHECK(lagging + updated == S.m->n_leaves, "%s: tau %g: %d lagging + %d rebuilt != %d cells",
          name, tau, lagging, updated, S.m->n_leaves);
    free(w), free(wf);

    /* 3. A state within τ of the last rebuilds nothing. */
    double *u1b = malloc(bn);
    memcpy(u1b, S.u1, bn);
    for (int i = 0; i < S.n; i++) u1b[i] += 1e-4 * tau * H * nh_rand();
    nh_system_lazy_reset(lazy1);
    nh_system_assemble(lazy1, u1b, S.v, cM, cK, S.f[1], S.kv[1], 1);
    CHECK(nh_system_lazy_updates(lazy1) == 0, "%s: tau %g: %d tangents rebuilt within tau", name,
          tau, nh_system_lazy_updates(lazy1));
    free(u1b);

    /* 4. 1 and 2 threads along the same history (rest, deformed), bitwise. */
    nh_system_set_lazy(lazy2, tau);
    nh_system_set_lazy(lazy3, tau);
    assemble(&S, lazy2, 1, 1, 0);
    assemble(&S, lazy3, 1, 2, 1);
    CHECK(!memcmp(S.f[0], S.f[1], bn), "%s: tau %g: f_int differs between 1 and 2 threads", name,
          tau);
    CHECK(!memcmp(S.kv[0], S.kv[1], bn), "%s: tau %g: K v differs between 1 and 2 threads", name,
          tau);
    CHECK(!memcmp(S.y[0], S.y[1], bf), "%s: tau %g: A differs between 1 and 2 threads", name, tau);

    /* 5. The repeated assembly's kept results, against fresh systems. */
    repeated(&S, tau, lazy2, name);
    nh_system_destroy(&exact);
    nh_system_destroy(&zero);
    nh_system_destroy(&lazy1);
    nh_system_destroy(&lazy2);
    nh_system_destroy(&lazy3);
  }
  double ratio = err[1] / err[0];
  CHECK(fabs(ratio - 10.0) <= 2.0,
        "%s: the tangent error should scale with the rotation change: E(1e-2)/E(1e-3) = %.3g, "
        "expected 10 within 2",
        name, ratio);
  if (getenv("NH_TEST_VERBOSE"))
    printf("%s: errors %.3e %.3e ratio %.3f\n", name, err[0], err[1], ratio);
  free(S.u0), free(S.u1), free(S.v), free(S.full), free(S.p), free(S.fixed);
  for (int k = 0; k < 2; k++) free(S.f[k]), free(S.kv[k]), free(S.y[k]);
  nh_tissue_destroy(&S.t);
  nh_mesh_destroy(&S.m);
}

int main(void) {
  run(0);
  run(1);
  TEST_END();
}
