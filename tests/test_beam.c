/* test_beam — the corotational Euler–Bernoulli beam (src/beam, docs/beam.md).
 *
 *  0. Element derivatives: f = ∂U/∂p and K = ∂f/∂p against central
 *     differences along the same increments (x += ε δx, T ← exp(ε δw) T), on
 *     a randomly deformed element with rotations up to ~0.5 rad.
 *  1. Cantilever, tip load P: nodal deflections P s²(3L − s)/(6EI) and
 *     rotations P s(2L − s)/(2EI), tip PL³/3EI, PL²/2EI — exact at the nodes
 *     for cubic elements at any n. The beam is geometrically nonlinear; with
 *     tip rotation θ = 1e-5 the nonlinear terms are O(θ²) = 1e-10 relative
 *     and round-off in the corotated frame O(eps/θ) = 2e-11, so the
 *     tolerance 1e-8 (relative to the tip value) covers both with margin.
 *  2. Own weight q = ρAg (θ ~ 1e-5 again): with consistent loads the nodal
 *     deflections are the exact q s²(6L² − 4Ls + s²)/(24EI) (tip qL⁴/8EI);
 *     with lumped loads (ρAl₀/2 g per node) they are the exact response to
 *     those point loads, Σⱼ Fⱼ G(s, aⱼ) with the cantilever's influence
 *     function G(s, a) = min(s,a)²(3 max(s,a) − min(s,a))/(6EI), which is
 *     what the test expects (and it is not qL⁴/8EI: checked too).
 *  3. Large deflection, (a) tip moment: the exact elastica is a circle of
 *     radius R = EI/M; a chain of n elements under a pure moment has N = 0,
 *     chord l = l₀ and nodal rotations advancing by φ = θ/n, so its nodes lie
 *     exactly on a circle of radius R' = l₀ / (2 sin(φ/2)): the test asserts
 *     this discrete solution (1e-9 L) and the exact one within
 *     |R' − R| ≈ R φ²/24 (O(1/n²)), for θ = π/2 and π.
 *     (b) tip force (Bisshopp–Drucker), PL²/EI = 2: against the elastica
 *     θ'' = (P/EI) cos θ, θ(0) = 0, θ'(L) = 0, integrated by RK4 and shooting
 *     (bisection on θ'(0)) in this file; observed order from n = 8, 16, 32 in
 *     [1.8, 2.2] and the finest error below its Richardson bound.
 *  4. Rigid motions: a rigidly moved rest beam has f = 0; a deformed state
 *     moved rigidly gives f(Qx + t) = Q f(x), same energy, K → Q K Qᵀ.
 *  5. A cantilever along a random direction under a tip load normal to it,
 *     in the nonlinear range, deflects exactly as one along x rotated.
 *  6. Hermite points: on the cantilever of 1 (n = 4), x(s) matches the
 *     exact deflection curve between nodes (1e-8 of the tip deflection) while
 *     the chord misses it by > 1e-3; J matches central differences of x(s);
 *     nh_beam_add_point_force is the exact transpose: ⟨Jδ, F⟩ = ⟨δ, JᵀF⟩.
 *  7. Dynamics: a damped cantilever released under gravity settles to the
 *     static (lumped-gravity) solution; an undamped one never gains energy.
 *  8. Base spin of a bent beam: a needle-like cantilever (E = 50 GPa,
 *     r = 0.415 mm, L = 0.16 m, n = 32) bent by a dead tip force (PL²/EI =
 *     0.01, 0.5 and 2: tip deflections 0.5, 26 and 79 mm) has its base
 *     turned by π about its axis in 20 steps of 0.05 s (the 9° per step of
 *     cases/steering/obstacle.yaml) through the coupled step's three parts
 *     (base velocity π rad/s, then 0 for 20 more steps). Turning every
 *     section about its own tangent changes none of the strains of an
 *     isotropic section (the bending curvature keeps its length, the
 *     torsion stays 0) and the dead load does not depend on the rotations,
 *     so the static shape is still the equilibrium: every node stays where
 *     it was (asserted to 1e-6 of the tip deflection, at every step), and
 *     the tip's d2, turned by π about the tip tangent t, ends at
 *     −d2 + 2 (d2·t) t, i.e. −d2 for the d2 ⟂ t of the rest beam (1e-6).
 *     The step with the symmetrised tangent on the right-hand side fails
 *     this by 10¹⁰⁰ (the spin turned into a lateral load growing twentyfold
 *     per step).
 *  9. The step operator's linear algebra against an independent dense one,
 *     on the needle-like beam of 8 bent by PL²/EI = 0.5: A = (1 + hα) M +
 *     (hβ + h²) K_sym from nh_beam_mass and nh_beam_internal_force, solved
 *     here by LAPACK's dense dposv; (a) as bent (A positive definite: the
 *     band Cholesky of nh_beam_dynamic_prepare); (b) then shortened along
 *     its chord to 20 × the cantilever's buckling force (A indefinite: the
 *     positive part, eigenpairs below 0 only), against K₊ = V max(Λ, 0) Vᵀ
 *     from the full decomposition (dsyevd) here. Both solvers are backward
 *     stable, so each one's solution leaves a residual ‖A y − r‖ ≤ c ε ‖A‖
 *     ‖y‖ in the other's A (asserted 1e-12, against m ε = 2e-14; a wrong
 *     projection leaves up to (hβ + h²) |λ_min(K)| ‖y‖, 5e-10 of max|A| in
 *     (b): asserted ≥ 1e-10), and the two agree to cond(A) ε (LAPACK's
 *     dpocon estimate, 100 ε cond asserted). */
#include "beam/beam.h"
#include "check.h"

#include <lapacke.h>
#include <string.h>

static nh_beam_section section(void) {
  nh_beam_section s = {
      .young = 2e11, .poisson = 0.3, .radius = 5e-4, .inner_radius = 2e-4, .density = 8000};
  return s;
}

static nh_beam *make(const double dir[3], double L, int n) {
  nh_beam_spec sp = {.section = section(), .length = L, .elements = n};
  memcpy(sp.direction, dir, sizeof sp.direction);
  nh_beam *b;
  CHECK_OK(nh_beam_create(&sp, &b));
  return b;
}

/* tol: 1e-12 in the nonlinear range; 1e-9 for the tiny loads of the
 * linear-regime tests, whose Newton corrections stall at ~2e-10 of the
 * displacement (round-off eps·|x| against deflections 1e-5·|x|). */
static nh_beam_static_options opts(int steps, double tol) {
  nh_beam_static_options o = {.load_steps = steps, .max_iterations = 30, .tolerance = tol};
  return o;
}

static double dot3(const double a[3], const double b[3]) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* 0. Element derivatives by central differences. */
static void test_derivatives(void) {
  const double x_dir[3] = {1, 0, 0};
  nh_beam *b = make(x_dir, 0.02, 1);
  double d[12];
  for (int trial = 0; trial < 5; trial++) {
    nh_beam_reset(b);
    for (int i = 0; i < 12; i++) d[i] = (i % 6 < 3 ? 0.002 : 0.4) * nh_rand();
    nh_beam_increment(b, d);
    double Q[9], r[3] = {nh_rand(), nh_rand(), nh_rand()};
    nh_mat3_rotation(r, Q);
    nh_beam_move_rigid(b, Q, NULL, NULL);
    double *x = nh_beam_positions(b), *T = nh_beam_directors(b);
    double x0[6], T0[18], f[12], K[144];
    memcpy(x0, x, sizeof x0), memcpy(T0, T, sizeof T0);
    nh_beam_element_force(b, 0, f, K);
    double fmx = 0;
    for (int i = 0; i < 12; i++) fmx = fmax(fmx, fabs(f[i]) * (i % 6 < 3 ? 0.02 : 1.0));
    for (int k = 0; k < 12; k++) {
      const double eps = k % 6 < 3 ? 1e-7 : 1e-6;
      double fp[12], fm[12], Up, Um, inc[12] = {0};
      inc[k] = eps;
      nh_beam_increment(b, inc);
      Up = nh_beam_element_force(b, 0, fp, NULL);
      memcpy(x, x0, sizeof x0), memcpy(T, T0, sizeof T0);
      inc[k] = -eps;
      nh_beam_increment(b, inc);
      Um = nh_beam_element_force(b, 0, fm, NULL);
      memcpy(x, x0, sizeof x0), memcpy(T, T0, sizeof T0);
      const double scale = k % 6 < 3 ? 1.0 / 0.02 : 1.0; /* fmax is a moment scale */
      CHECK_CLOSE(f[k], (Up - Um) / (2 * eps), 1e-6 * fmx * scale, "f = dU/dp");
      for (int i = 0; i < 12; i++)
        CHECK_CLOSE(K[12 * i + k], (fp[i] - fm[i]) / (2 * eps),
                    1e-6 * sqrt(fabs(K[13 * i]) * fabs(K[13 * k])), "K = df/dp");
    }
  }
  nh_beam_destroy(&b);
}

/* 1. Tip load. */
static void test_tip_load(void) {
  const double L = 0.1, dir[3] = {1, 0, 0};
  for (int n = 1; n <= 10; n += 3) {
    nh_beam *b = make(dir, L, n);
    const double EI = 2e11 * nh_beam_get_constants(b)->inertia;
    const double P = 2e-5 * EI / (L * L); /* tip rotation 1e-5 */
    double *f = calloc((size_t)nh_beam_dofs(b), sizeof(double));
    f[6 * n + 1] = P;
    nh_beam_static_options o = opts(1, 1e-9);
    CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
    const double wtip = P * L * L * L / (3 * EI), ttip = P * L * L / (2 * EI);
    const double *x = nh_beam_positions(b), *X = nh_beam_rest_positions(b);
    for (int a = 0; a <= n; a++) {
      double s = a * L / n, th[3];
      nh_beam_rotation_log(nh_beam_directors(b) + 9 * a, th);
      CHECK_CLOSE(x[3 * a + 1] - X[3 * a + 1], P * s * s * (3 * L - s) / (6 * EI), 1e-8 * wtip,
                  "tip load: nodal deflection");
      CHECK_CLOSE(th[2], P * s * (2 * L - s) / (2 * EI), 1e-8 * ttip, "tip load: nodal rotation");
    }
    free(f);
    nh_beam_destroy(&b);
  }
}

/* 2. Own weight, consistent and lumped loads. */
static void test_gravity(void) {
  const double L = 0.1, dir[3] = {1, 0, 0};
  const int n = 5;
  for (int consistent = 0; consistent <= 1; consistent++) {
    nh_beam *b = make(dir, L, n);
    const nh_beam_constants *c = nh_beam_get_constants(b);
    const double EI = 2e11 * c->inertia, rhoA = 8000 * c->area;
    const double g = 6e-5 * EI / (rhoA * L * L * L); /* tip rotation qL³/6EI = 1e-5 */
    const double q = rhoA * g, wtip = q * L * L * L * L / (8 * EI);
    nh_beam_static_options o = opts(1, 1e-9);
    o.gravity[2] = -g;
    o.consistent_load = consistent;
    CHECK_OK(nh_beam_solve_static(b, &o, NULL, NULL));
    const double *x = nh_beam_positions(b), *X = nh_beam_rest_positions(b);
    for (int a = 0; a <= n; a++) {
      double s = a * L / n, w;
      if (consistent) {
        w = q * s * s * (6 * L * L - 4 * L * s + s * s) / (24 * EI);
      } else {
        w = 0.0;
        for (int j = 1; j <= n; j++) {
          double aj = j * L / n, F = q * L / n * (j == n ? 0.5 : 1.0);
          double lo = fmin(s, aj), hi = fmax(s, aj);
          w += F * lo * lo * (3 * hi - lo) / (6 * EI);
        }
      }
      CHECK_CLOSE(X[3 * a + 2] - x[3 * a + 2], w, 1e-8 * wtip,
                  consistent ? "gravity (consistent): nodal deflection"
                             : "gravity (lumped): nodal deflection");
    }
    if (!consistent) /* lumped loads are not the distributed load at the tip */
      CHECK(fabs(X[3 * n + 2] - x[3 * n + 2] - wtip) > 1e-3 * wtip,
            "lumped gravity should differ from qL^4/8EI");
    nh_beam_destroy(&b);
  }
}

/* 3a. Tip moment: circle. */
static void test_tip_moment(void) {
  const double L = 0.1, dir[3] = {1, 0, 0};
  const double angles[2] = {0.5 * M_PI, M_PI};
  for (int ia = 0; ia < 2; ia++) {
    double prev_err = 0;
    for (int n = 8; n <= 32; n *= 2) {
      nh_beam *b = make(dir, L, n);
      const double EI = 2e11 * nh_beam_get_constants(b)->inertia, th = angles[ia];
      const double M = th * EI / L, R = EI / M, phi = th / n, Rd = (L / n) / (2 * sin(phi / 2));
      double *f = calloc((size_t)nh_beam_dofs(b), sizeof(double));
      f[6 * n + 5] = M;
      nh_beam_static_options o = opts(20, 1e-12);
      nh_beam_stats st;
      CHECK_OK(nh_beam_solve_static(b, &o, f, &st));
      const double *x = nh_beam_positions(b);
      double tip[2] = {x[3 * n], x[3 * n + 1]};
      const double *Tt = nh_beam_directors(b) + 9 * n; /* d1 = (cos θ, sin θ, 0) */
      CHECK_CLOSE(tip[0], Rd * sin(th), 1e-9 * L, "tip moment: discrete circle x");
      CHECK_CLOSE(tip[1], Rd * (1 - cos(th)), 1e-9 * L, "tip moment: discrete circle y");
      CHECK_CLOSE(Tt[0], cos(th), 1e-9, "tip moment: tip rotation (cos)");
      CHECK_CLOSE(Tt[3], sin(th), 1e-9, "tip moment: tip rotation (sin)");
      double err = hypot(tip[0] - R * sin(th), tip[1] - R * (1 - cos(th)));
      double bound = 1.01 * (Rd - R) * hypot(sin(th), 1 - cos(th)) + 1e-9 * L;
      CHECK(err <= bound, "tip moment θ=%g n=%d: |tip − elastica| %.3e > %.3e", th, n, err, bound);
      if (prev_err > 0) {
        double p = log2(prev_err / err);
        CHECK(p > 1.9 && p < 2.1, "tip moment θ=%g: observed order %.3f not 2", th, p);
      }
      prev_err = err;
      free(f);
      nh_beam_destroy(&b);
    }
  }
}

/* 3b. Tip force elastica by RK4 shooting, in units of L, α = PL²/EI, load
 * (0, −P). The FE beam is extensible (EA finite): its axial strain N/EA,
 * N = −P sin θ, shifts the tip by ~P/EA · L = 1.5e-5 L here, more than the
 * discretisation error at n = 32, so the reference is the extensible
 * elastica: with λ = 1 + N/EA = 1 − β sin θ, β = P/EA,
 *   (θ, κ, x, y)' = (κ, α λ cos θ, λ cos θ, λ sin θ),
 * θ(0) = 0, κ(1) = 0 (EI θ' = M = −P (x_L − x), so θ'' = (P/EI) x').
 * Returns κ(1) and the tip. */
static double elastica_shoot(double alpha, double beta, double k0, double tip[2]) {
  double y[4] = {0, k0, 0, 0};
  const int steps = 4000;
  const double h = 1.0 / steps;
  for (int s = 0; s < steps; s++) {
    double k[4][4], z[4];
    for (int st = 0; st < 4; st++) {
      double c = st == 0 ? 0 : (st == 3 ? 1.0 : 0.5);
      for (int i = 0; i < 4; i++) z[i] = y[i] + (st ? c * h * k[st - 1][i] : 0.0);
      const double lam = 1 - beta * sin(z[0]);
      k[st][0] = z[1], k[st][1] = alpha * lam * cos(z[0]);
      k[st][2] = lam * cos(z[0]), k[st][3] = lam * sin(z[0]);
    }
    for (int i = 0; i < 4; i++) y[i] += h / 6 * (k[0][i] + 2 * k[1][i] + 2 * k[2][i] + k[3][i]);
  }
  tip[0] = y[2], tip[1] = y[3];
  return y[1];
}

static void test_tip_force(void) {
  const double L = 0.1, dir[3] = {1, 0, 0}, alpha = 2.0;
  nh_beam_constants c;
  nh_beam_section sec = section();
  CHECK_OK(nh_beam_section_constants(&sec, &c));
  const double beta = alpha * c.inertia / (c.area * L * L);
  double lo = -2 * alpha, hi = 0.0, ref[2];
  for (int it = 0; it < 100; it++) {
    double mid = 0.5 * (lo + hi);
    if (elastica_shoot(alpha, beta, mid, ref) > 0)
      hi = mid;
    else
      lo = mid;
  }
  elastica_shoot(alpha, beta, 0.5 * (lo + hi), ref);
  double err[3];
  int k = 0;
  for (int n = 8; n <= 32; n *= 2, k++) {
    nh_beam *b = make(dir, L, n);
    const double EI = 2e11 * nh_beam_get_constants(b)->inertia;
    double *f = calloc((size_t)nh_beam_dofs(b), sizeof(double));
    f[6 * n + 1] = -alpha * EI / (L * L);
    nh_beam_static_options o = opts(4, 1e-12);
    CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
    const double *x = nh_beam_positions(b);
    err[k] = hypot(x[3 * n] - L * ref[0], x[3 * n + 1] - L * ref[1]);
    free(f);
    nh_beam_destroy(&b);
  }
  double p = log2((err[0]) / (err[1])), p2 = log2(err[1] / err[2]);
  CHECK(p > 1.8 && p < 2.2 && p2 > 1.8 && p2 < 2.2,
        "tip force elastica: observed orders %.3f, %.3f not 2 (errors %.3e %.3e %.3e)", p, p2,
        err[0], err[1], err[2]);
  /* Richardson: the n = 32 error is about err16 / 3 ... /5 for order 2. */
  CHECK(err[2] < 0.4 * err[1] && err[2] < 1e-3 * L, "tip force elastica: n=32 error %.3e", err[2]);
}

/* 4. Rigid motions. */
static void test_rigid(void) {
  const double dir[3] = {0.3, -0.2, 0.9}, L = 0.05;
  const int n = 6, N = 6 * (n + 1);
  nh_beam *b = make(dir, L, n);
  double *f1 = calloc(N, sizeof(double)), *f2 = calloc(N, sizeof(double));
  double *K1 = calloc((size_t)N * N, sizeof(double)), *K2 = calloc((size_t)N * N, sizeof(double));
  const nh_beam_constants *c = nh_beam_get_constants(b);
  const double l0 = L / n, EI = 2e11 * c->inertia, EA = 2e11 * c->area;
  /* Round-off: positions up to |x| ~ 2 m carry errors δ = eps |x|; the frame
   * turns by δ/l0, stretches by δ: forces EA δ/l0, moments EI δ/l0². */
  const double delta = 2.0 * 2.2e-16 * 2.0;
  const double ftol = 10 * EA * delta / l0, mtol = 10 * EI * delta / (l0 * l0);
  for (int trial = 0; trial < 10; trial++) {
    double r[3] = {nh_rand(), nh_rand(), nh_rand()}, t[3] = {nh_rand(), nh_rand(), nh_rand()};
    double nr = sqrt(dot3(r, r)), ang = trial == 0 ? M_PI : M_PI * trial / 10.0, Q[9];
    for (int i = 0; i < 3; i++) r[i] *= ang / nr;
    nh_mat3_rotation(r, Q);
    nh_beam_reset(b);
    nh_beam_move_rigid(b, Q, nh_beam_rest_positions(b) + 3 * n, t);
    double U = nh_beam_internal_force(b, f1, NULL, 0);
    for (int i = 0; i < N; i++)
      CHECK_CLOSE(f1[i], 0.0, i % 6 < 3 ? ftol : mtol, "rigid motion: f = 0");
    CHECK_CLOSE(U, 0.0, ftol * delta, "rigid motion: U = 0");
    /* deformed, then moved */
    nh_beam_reset(b);
    double *d = calloc(N, sizeof(double));
    for (int i = 6; i < N; i++) d[i] = (i % 6 < 3 ? 1e-3 * L : 0.3) * nh_rand();
    nh_beam_increment(b, d);
    free(d);
    double U1 = nh_beam_internal_force(b, f1, K1, 0);
    nh_beam_move_rigid(b, Q, NULL, t);
    double U2 = nh_beam_internal_force(b, f2, K2, 0);
    CHECK_CLOSE(U2, U1, 1e-10 * U1, "rigid motion: energy");
    double fm = 0, km = 0;
    for (int i = 0; i < N; i++) fm = fmax(fm, fabs(f1[i]));
    for (int i = 0; i < N * N; i++) km = fmax(km, fabs(K1[i]));
    for (int a = 0; a < 2 * (n + 1); a++) {
      double qf[3];
      nh_mat3_vec(Q, f1 + 3 * a, qf);
      for (int i = 0; i < 3; i++) CHECK_CLOSE(f2[3 * a + i], qf[i], 1e-10 * fm, "f(Qx) = Q f(x)");
    }
    for (int a = 0; a < 2 * (n + 1); a++)
      for (int c = 0; c < 2 * (n + 1); c++) {
        double B[9], QB[9];
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++) B[3 * i + j] = K1[(size_t)(3 * a + i) * N + 3 * c + j];
        nh_mat3_mul(Q, B, QB);
        nh_mat3_mul_nt(QB, Q, QB);
        for (int i = 0; i < 9; i++)
          CHECK_CLOSE(K2[(size_t)(3 * a + i / 3) * N + 3 * c + i % 3], QB[i], 1e-10 * km,
                      "K(Qx) = Q K Qᵀ");
      }
  }
  free(f1), free(f2), free(K1), free(K2);
  nh_beam_destroy(&b);
}

/* 5. Any direction behaves as x. */
static void test_direction(void) {
  const double L = 0.1, ex[3] = {1, 0, 0};
  const int n = 10;
  nh_beam *bx = make(ex, L, n);
  const double EI = 2e11 * nh_beam_get_constants(bx)->inertia, P = 1.5 * EI / (L * L);
  for (int trial = 0; trial < 3; trial++) {
    double r[3] = {nh_rand(), nh_rand(), nh_rand()}, Q[9];
    if (trial == 0) r[0] = r[1] = 0, r[2] = 0.5 * M_PI; /* x → y */
    nh_mat3_rotation(r, Q);
    const double dir[3] = {Q[0], Q[3], Q[6]};
    nh_beam_spec sp = {.section = section(), .length = L, .elements = n};
    memcpy(sp.direction, dir, sizeof dir);
    sp.normal[0] = Q[1], sp.normal[1] = Q[4], sp.normal[2] = Q[7];
    nh_beam *b;
    CHECK_OK(nh_beam_create(&sp, &b));
    double *f = calloc(6 * (n + 1), sizeof(double)), *fx = calloc(6 * (n + 1), sizeof(double));
    double load[3] = {0, P * 0.6, P * 0.8}; /* in the x-beam's frame */
    memcpy(fx + 6 * n, load, sizeof load);
    nh_mat3_vec(Q, load, f + 6 * n);
    nh_beam_reset(bx);
    nh_beam_static_options o = opts(3, 1e-12);
    CHECK_OK(nh_beam_solve_static(bx, &o, fx, NULL));
    CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
    const double *x = nh_beam_positions(b), *xx = nh_beam_positions(bx);
    double ux[3], qu[3], u[3];
    for (int i = 0; i < 3; i++) ux[i] = xx[3 * n + i] - (i == 0) * L, u[i] = x[3 * n + i];
    nh_mat3_vec(Q, ux, qu);
    CHECK(sqrt(dot3(ux, ux)) > 0.2 * L, "direction: deflection %g is not large",
          sqrt(dot3(ux, ux)));
    double Lq[3] = {Q[0] * L, Q[3] * L, Q[6] * L};
    for (int i = 0; i < 3; i++)
      CHECK_CLOSE(u[i] - Lq[i], qu[i], 1e-9 * L, "direction: tip displacement rotated");
    free(f), free(fx);
    nh_beam_destroy(&b);
  }
  nh_beam_destroy(&bx);
}

/* 6. Hermite points and the transpose. */
static void test_hermite(void) {
  const double L = 0.1, dir[3] = {1, 0, 0};
  const int n = 4;
  nh_beam *b = make(dir, L, n);
  const double EI = 2e11 * nh_beam_get_constants(b)->inertia, P = 2e-5 * EI / (L * L);
  double *f = calloc(6 * (n + 1), sizeof(double));
  f[6 * n + 1] = P;
  nh_beam_static_options o = opts(1, 1e-9);
  CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
  const double wtip = P * L * L * L / (3 * EI);
  const double *xn = nh_beam_positions(b);
  double worst = 0, chord_worst = 0;
  for (int k = 0; k <= 40; k++) {
    double s = L * k / 40.0, x[3], t[3];
    nh_beam_point(b, s, x, t, NULL, NULL, NULL);
    double w = P * s * s * (3 * L - s) / (6 * EI), slope = P * s * (2 * L - s) / (2 * EI);
    worst = fmax(worst, fabs(x[1] - w));
    /* the axial shortening ½∫w'² <= θ_tip² s / 2 is a real O(θ²) effect */
    CHECK_CLOSE(x[0], s, 1e-10 * s + 1e-17, "Hermite point: axial position");
    CHECK_CLOSE(x[1], w, 1e-8 * wtip, "Hermite point: deflection w(s)");
    CHECK_CLOSE(t[1], slope, 1e-8 * slope + 1e-15, "Hermite point: tangent");
    int e = k * n / 40 < n ? k * n / 40 : n - 1;
    double xi = s / (L / n) - e;
    double yc = (1 - xi) * xn[3 * e + 1] + xi * xn[3 * e + 4];
    chord_worst = fmax(chord_worst, fabs(yc - w));
  }
  CHECK(chord_worst > 1e-3 * wtip, "chord error %.3e should be visible", chord_worst);
  /* J against differences; ⟨Jδ, F⟩ = ⟨δ, JᵀF⟩ (nonlinear state). */
  double *d = calloc(6 * (n + 1), sizeof(double)), *g = calloc(6 * (n + 1), sizeof(double));
  for (int i = 6; i < 6 * (n + 1); i++) d[i] = (i % 6 < 3 ? 0.02 * L : 0.3) * nh_rand();
  nh_beam_increment(b, d);
  for (int trial = 0; trial < 20; trial++) {
    double s = L * (0.5 + 0.5 * nh_rand()), J[36], x[3], F[3], dl[12], jd[3] = {0, 0, 0};
    int e;
    nh_beam_point(b, s, x, NULL, &e, NULL, J);
    for (int i = 0; i < 3; i++) F[i] = nh_rand();
    for (int i = 0; i < 12; i++) dl[i] = nh_rand();
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 12; j++) jd[i] += J[12 * i + j] * dl[j];
    memset(g, 0, 6 * (n + 1) * sizeof(double));
    nh_beam_add_point_force(b, s, F, g);
    double lhs = dot3(jd, F), rhs = 0.0;
    for (int j = 0; j < 12; j++) rhs += dl[j] * g[6 * e + j];
    CHECK_CLOSE(rhs, lhs, 1e-14 * (fabs(lhs) + L), "<J d, F> = <d, J^T F>");
    /* central difference of x(s) along dl */
    const double eps = 1e-7;
    double *pos = nh_beam_positions(b), *T = nh_beam_directors(b), save_x[6], save_T[18], xp[3],
           xm[3];
    memcpy(save_x, pos + 3 * e, sizeof save_x), memcpy(save_T, T + 9 * e, sizeof save_T);
    memset(d, 0, 6 * (n + 1) * sizeof(double));
    for (int j = 0; j < 12; j++) d[6 * e + j] = eps * dl[j];
    nh_beam_increment(b, d);
    nh_beam_point(b, s, xp, NULL, NULL, NULL, NULL);
    memcpy(pos + 3 * e, save_x, sizeof save_x), memcpy(T + 9 * e, save_T, sizeof save_T);
    for (int j = 0; j < 12; j++) d[6 * e + j] = -eps * dl[j];
    nh_beam_increment(b, d);
    nh_beam_point(b, s, xm, NULL, NULL, NULL, NULL);
    memcpy(pos + 3 * e, save_x, sizeof save_x), memcpy(T + 9 * e, save_T, sizeof save_T);
    for (int i = 0; i < 3; i++)
      CHECK_CLOSE(jd[i], (xp[i] - xm[i]) / (2 * eps), 1e-7 * L, "J = dx(s)/dp");
  }
  free(d), free(g), free(f);
  nh_beam_destroy(&b);
}

/* 7. Dynamics. */
static void test_dynamic(void) {
  const double L = 0.1, dir[3] = {1, 0, 0};
  const int n = 8, N = 6 * (n + 1);
  nh_beam *ref = make(dir, L, n), *b = make(dir, L, n);
  const nh_beam_constants *c = nh_beam_get_constants(b);
  const double EI = 2e11 * c->inertia, rhoA = 8000 * c->area;
  const double g = 0.3 * EI / (rhoA * L * L * L); /* tip rotation ~0.05: mildly nonlinear */
  nh_beam_static_options o = opts(1, 1e-12);
  o.gravity[2] = -g;
  CHECK_OK(nh_beam_solve_static(ref, &o, NULL, NULL));
  /* first bending frequency ω₁ = 3.516 sqrt(EI/(ρA L⁴)); damp it critically-ish */
  const double w1 = 3.516 * sqrt(EI / (rhoA * L * L * L * L));
  nh_beam_dynamic_options dyn = {.dt = 0.2 / w1, .alpha = 2 * w1, .beta = 0};
  dyn.gravity[2] = -g;
  for (int k = 0; k < 600; k++) CHECK_OK(nh_beam_step_dynamic(b, &dyn, NULL));
  const double *x = nh_beam_positions(b), *xr = nh_beam_positions(ref);
  const double wtip = nh_beam_rest_positions(ref)[3 * n + 2] - xr[3 * n + 2];
  for (int i = 0; i < 3 * (n + 1); i++)
    CHECK_CLOSE(x[i], xr[i], 1e-6 * wtip, "dynamic: settles to the static solution");
  /* undamped: E_kin + U − W_gravity never grows */
  nh_beam_reset(b);
  dyn.alpha = 0;
  double *m = calloc(N, sizeof(double)), *fi = calloc(N, sizeof(double));
  nh_beam_mass(b, m);
  double Emax = -INFINITY, Emin = INFINITY; /* the rest state has energy 0 */
  for (int k = 0; k < 200; k++) {
    CHECK_OK(nh_beam_step_dynamic(b, &dyn, NULL));
    const double *v = nh_beam_velocities(b), *xx = nh_beam_positions(b);
    double Ek = 0, U = nh_beam_internal_force(b, fi, NULL, 0), W = 0;
    for (int i = 0; i < N; i++) Ek += 0.5 * m[i] * v[i] * v[i];
    for (int a = 0; a <= n; a++) W += m[6 * a] * g * (xx[3 * a + 2] - 0);
    double Etot = Ek + U + W;
    Emax = fmax(Emax, Etot), Emin = fmin(Emin, Etot);
  }
  CHECK(Emax <= 1e-9 * fabs(Emin), "undamped dynamics gained energy: %.6e > 0", Emax);
  free(m), free(fi);
  nh_beam_destroy(&ref);
  nh_beam_destroy(&b);
}

/* Section constants and bad input. */
static void test_section(void) {
  nh_beam_section s = section();
  nh_beam_constants c;
  CHECK_OK(nh_beam_section_constants(&s, &c));
  const double r = 5e-4, ri = 2e-4;
  CHECK_CLOSE(c.area, M_PI * (r * r - ri * ri), 1e-15 * c.area, "area");
  CHECK_CLOSE(c.inertia, M_PI * (pow(r, 4) - pow(ri, 4)) / 4, 1e-15 * c.inertia, "inertia");
  CHECK_CLOSE(c.polar, 2 * c.inertia, 0, "polar");
  CHECK_CLOSE(c.shear, 2e11 / 2.6, 1e-15 * c.shear, "shear modulus");
  s.inner_radius = s.radius;
  CHECK(nh_beam_section_constants(&s, &c) == NH_ERR_INPUT, "inner radius = radius accepted");
  nh_beam_spec sp = {.section = section(), .length = 0.1, .elements = 0, .direction = {1, 0, 0}};
  nh_beam *b = NULL;
  CHECK(nh_beam_create(&sp, &b) == NH_ERR_INPUT && !b, "0 elements accepted");
  sp.elements = 2, sp.direction[0] = 0;
  CHECK(nh_beam_create(&sp, &b) == NH_ERR_INPUT && !b, "zero direction accepted");
  nh_error_clear();
}

/* A needle-like tool along x (tests 8 and 9). */
static nh_beam_spec needle_spec(double L, int n) {
  nh_beam_spec sp = {
      .section = {.young = 50e9, .poisson = 0.33, .radius = 4.15e-4, .density = 6450},
      .length = L,
      .elements = n,
      .direction = {1, 0, 0}};
  return sp;
}

/* 8. A bent beam's base turned by π: the centre line stays, the tip turns. */
static void test_spin(void) {
  const double L = 0.16, h = 0.05;
  const int n = 32, N = 6 * (n + 1), steps = 20;
  const nh_beam_spec sp = needle_spec(L, n);
  const double EI = sp.section.young * M_PI * pow(sp.section.radius, 4) / 4;
  const double loads[3] = {0.01, 0.5, 2.0};
  for (int c = 0; c < 3; c++) {
    nh_beam *b;
    CHECK_OK(nh_beam_create(&sp, &b));
    double *f = nh_calloc((size_t)N, sizeof(double)), *dv = nh_calloc((size_t)N, sizeof(double));
    double x0[3 * 33], d20[3], t[3];
    f[6 * n + 1] = loads[c] * EI / (L * L);
    nh_beam_static_options o = opts(10, 1e-12);
    CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
    const double *x = nh_beam_positions(b), *T = nh_beam_directors(b) + 9 * n;
    memcpy(x0, x, sizeof x0);
    for (int i = 0; i < 3; i++) d20[i] = T[3 * i + 1], t[i] = T[3 * i];
    const double defl = x0[3 * n + 1], tol = 1e-6 * defl;
    nh_beam_system *S;
    CHECK_OK(nh_beam_system_create(b, &S));
    nh_beam_dynamic_options d = {.dt = h, .beta = 0.001};
    const double spin[6] = {0, 0, 0, M_PI / (steps * h), 0, 0}, rest[6] = {0};
    double worst = 0.0;
    for (int k = 0; k < 2 * steps; k++) {
      const double *v = k < steps ? spin : rest;
      CHECK_OK(nh_beam_dynamic_prepare(b, &d, f, v, S, dv));
      nh_beam_system_solve(S, dv);
      CHECK_OK(nh_beam_dynamic_finish(b, h, v, dv));
      for (int i = 0; i < 3 * (n + 1); i++) worst = fmax(worst, fabs(x[i] - x0[i]));
    }
    char what[96];
    snprintf(what, sizeof what, "spin, PL^2/EI %g: largest node displacement (m)", loads[c]);
    CHECK_CLOSE(worst, 0.0, tol, what);
    const double dt = dot3(d20, t);
    for (int i = 0; i < 3; i++) {
      snprintf(what, sizeof what, "spin, PL^2/EI %g: tip d2[%d] after the turn", loads[c], i);
      CHECK_CLOSE(T[3 * i + 1], -d20[i] + 2 * dt * t[i], 1e-6, what);
    }
    nh_beam_system_destroy(&S);
    free(f), free(dv);
    nh_beam_destroy(&b);
  }
}

/* max_i |(A y − r)_i| / (‖A‖_max ‖y‖_∞), A dense m x m row-major. */
static double backward_error(const double *A, int m, const double *y, const double *r) {
  double e = 0.0, amax = 0.0, ymax = 0.0;
  for (int i = 0; i < m; i++) {
    double s = -r[i];
    for (int j = 0; j < m; j++)
      s += A[(size_t)i * m + j] * y[j], amax = fmax(amax, fabs(A[i * m + j]));
    e = fmax(e, fabs(s)), ymax = fmax(ymax, fabs(y[i]));
  }
  return e / (amax * ymax);
}

/* 9. Band and projected factorisations against dense LAPACK. */
static void test_step_operator(void) {
  const double L = 0.16, h = 0.01;
  const int n = 32, N = 6 * (n + 1), m = N - 6;
  const nh_beam_spec sp = needle_spec(L, n);
  const double EI = sp.section.young * M_PI * pow(sp.section.radius, 4) / 4;
  const double EA = sp.section.young * M_PI * pow(sp.section.radius, 2);
  nh_beam *b;
  CHECK_OK(nh_beam_create(&sp, &b));
  double *f = calloc(N, sizeof(double)), *K = calloc((size_t)N * N, sizeof(double));
  double *M = calloc(N, sizeof(double)), *A = calloc((size_t)m * m, sizeof(double));
  double *F = calloc((size_t)m * m, sizeof(double)), *w = calloc(m, sizeof(double));
  double *r = calloc(m, sizeof(double)), *y = calloc(m, sizeof(double));
  double *z = calloc(m, sizeof(double)), *fi = calloc(N, sizeof(double));
  double *d = calloc(N, sizeof(double));
  f[6 * n + 1] = 0.5 * EI / (L * L);
  nh_beam_static_options o = opts(10, 1e-12);
  CHECK_OK(nh_beam_solve_static(b, &o, f, NULL));
  nh_beam_system *S;
  CHECK_OK(nh_beam_system_create(b, &S));
  const nh_beam_dynamic_options dyn = {.dt = h, .alpha = 0.5, .beta = 0.002};
  const double cM = 1 + h * dyn.alpha, cK = h * dyn.beta + h * h, still[6] = {0};
  for (int c = 0; c < 2; c++) {
    if (c == 1) { /* shorten along the chord: axial force 20 x π² EI / (4 L²) */
      const double strain = 20 * M_PI * M_PI * EI / (4 * L * L) / EA;
      const double *x = nh_beam_positions(b);
      for (int a = 1; a <= n; a++)
        for (int k = 0; k < 3; k++) d[6 * a + k] = -strain * (x[3 * a + k] - x[k]);
      nh_beam_increment(b, d);
    }
    CHECK_OK(nh_beam_dynamic_prepare(b, &dyn, NULL, still, S, z));
    CHECK(nh_beam_system_projected(S) == c, "case %d: projected %d", c,
          nh_beam_system_projected(S));
    nh_beam_internal_force(b, fi, K, 1);
    nh_beam_mass(b, M);
    for (int i = 0; i < m; i++)
      for (int j = 0; j < m; j++) A[(size_t)i * m + j] = K[(size_t)(i + 6) * N + j + 6];
    double wneg = 0.0;
    if (c == 1) { /* K₊ = V max(Λ, 0) Vᵀ by the full decomposition */
      memcpy(F, A, sizeof(double) * m * m);
      CHECK(LAPACKE_dsyevd(LAPACK_ROW_MAJOR, 'V', 'U', m, F, m, w) == 0, "dsyevd failed");
      wneg = -w[0];
      for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) {
          double s = 0.0;
          for (int k = 0; k < m; k++)
            s += F[(size_t)i * m + k] * fmax(w[k], 0.0) * F[(size_t)j * m + k];
          A[(size_t)i * m + j] = s;
        }
    }
    for (int i = 0; i < m; i++) {
      for (int j = 0; j < m; j++) A[(size_t)i * m + j] *= cK;
      A[(size_t)i * m + i] += cM * M[i + 6];
    }
    double amax = 0.0;
    for (size_t k = 0; k < (size_t)m * m; k++) amax = fmax(amax, fabs(A[k]));
    /* a projection that missed the negative part would leave a residual up
     * to cK |λ_min| ‖y‖: above the tolerance below by 100 */
    CHECK(c == 0 || cK * wneg > 1e-10 * amax,
          "case 1: the negative part %g of max|A| %g is too small", cK * wneg, amax);
    for (int i = 0; i < m; i++) r[i] = nh_rand();
    memcpy(y, r, sizeof(double) * m);
    nh_beam_system_solve(S, y);
    memcpy(F, A, sizeof(double) * m * m), memcpy(z, r, sizeof(double) * m);
    CHECK(LAPACKE_dposv(LAPACK_ROW_MAJOR, 'L', m, 1, F, m, z, 1) == 0, "case %d: dposv failed", c);
    double anorm = 0.0, rcond = 0.0;
    for (int i = 0; i < m; i++) {
      double s = 0.0;
      for (int j = 0; j < m; j++) s += fabs(A[(size_t)i * m + j]);
      anorm = fmax(anorm, s);
    }
    CHECK(LAPACKE_dpocon(LAPACK_ROW_MAJOR, 'L', m, F, m, anorm, &rcond) == 0, "dpocon failed");
    char what[96];
    snprintf(what, sizeof what, "case %d: the beam's solve's backward error in the dense A", c);
    CHECK_CLOSE(backward_error(A, m, y, r), 0.0, 1e-12, what);
    snprintf(what, sizeof what, "case %d: dposv's backward error", c);
    CHECK_CLOSE(backward_error(A, m, z, r), 0.0, 1e-12, what);
    double diff = 0.0, zmax = 0.0;
    for (int i = 0; i < m; i++) diff = fmax(diff, fabs(y[i] - z[i])), zmax = fmax(zmax, fabs(z[i]));
    snprintf(what, sizeof what, "case %d: |y_beam - y_dense| / |y| (cond %.2g)", c, 1.0 / rcond);
    CHECK_CLOSE(diff / zmax, 0.0, 100 * 2.2e-16 / rcond, what);
    /* several right-hand sides at once (the tools' compliance columns):
     * each column solves the dense A to the same backward error */
    double *Y = calloc((size_t)3 * m, sizeof(double)), *R = calloc((size_t)3 * m, sizeof(double));
    for (int k = 0; k < 3 * m; k++) R[k] = Y[k] = nh_rand();
    nh_beam_system_solve_many(S, 3, Y);
    for (int col = 0; col < 3; col++) {
      snprintf(what, sizeof what, "case %d: column %d of the many-column solve's backward error", c,
               col);
      CHECK_CLOSE(backward_error(A, m, Y + (size_t)col * m, R + (size_t)col * m), 0.0, 1e-12, what);
    }
    free(Y), free(R);
  }
  nh_beam_system_destroy(&S);
  free(f), free(K), free(M), free(A), free(F), free(w), free(r), free(y), free(z), free(fi),
      free(d);
  nh_beam_destroy(&b);
}

int main(void) {
  test_section();
  test_derivatives();
  test_tip_load();
  test_gravity();
  test_tip_moment();
  test_tip_force();
  test_rigid();
  test_direction();
  test_hermite();
  test_dynamic();
  test_spin();
  test_step_operator();
  TEST_END();
}
