/* test_mcp — the constraint-force solver nh_mcp_solve (src/solve/mcp.c):
 *  1. all-bilateral rows equal a dense Cholesky solve λ = −W⁻¹ r;
 *  2. unilateral LCPs (m = 1..6, random SPD W) equal the solution found by
 *     enumerating the active sets;
 *  3. one normal + one tangential row: stick → slide exactly at the Coulomb
 *     bound, continuous there (diagonal and coupled W); a one-sided row
 *     (λ_t ∈ [0, bound]) the same where the two-sided λ_t ≥ 0, and where it
 *     would be negative λ_t = 0, λ_n = −r_n / W_nn (the normal alone) with
 *     w_t ≥ 0 (the complementarity of the lower side);
 *  4. a stiff needle block (×1e6) coupled to soft tissue (×1e-6) converges in
 *     the same sweeps and to the same relative accuracy as the unscaled one;
 *  5. a warm start at the solution costs 0-1 sweeps;
 *  6. disc friction: the pair sticks inside the disc, and on it lies on the
 *     circle with the slip opposite to the force;
 *  7. static and kinetic friction on a single shaft point (two lateral normal
 *     rows, one axial friction row) under a load ramp up and down: it sticks
 *     until its force reaches μ_s |λ_n| + c, then slides at μ_k |λ_n| + c,
 *     sticks again below that and needs μ_s again to restart (decoupled W:
 *     exact forces; coupled W: the slide force from an independent
 *     fixed-point solve); the disc pair likewise;
 *  8. known solutions of constructed problems (test_known), and of
 *     problems with an unsymmetric W (test_unsymmetric);
 *  9. ill-conditioned problems on which the sweeps and Newton stall
 *     within the budget, finished by the proximal fallback (test_proximal);
 * 10. the same kind of problems, more rows and a large budget: the sweeps'
 *     Newton probes and the early proximal fallback end them within 100
 *     sweeps (test_probes);
 *  plus bad laws rejected and non-convergence reported. Silent on success. */
#include "solve/solve.h"

#include "check.h"

#include <float.h>
#include <string.h>

#define MAXM 64

static nh_row_law law(nh_row_kind kind) {
  nh_row_law l = {kind, -1, -1, 0.0, 0.0, -1, 0.0, 0, 0};
  return l;
}

/* Random SPD m×m (column-major): G Gᵀ + 0.1 I. */
static void random_spd(int m, double *W) {
  double G[MAXM * MAXM];
  for (int k = 0; k < m * m; k++) G[k] = nh_rand();
  for (int i = 0; i < m; i++)
    for (int j = 0; j < m; j++) {
      double v = i == j ? 0.1 : 0.0;
      for (int k = 0; k < m; k++) v += G[k * m + i] * G[k * m + j];
      W[j * m + i] = v;
    }
}

/* Solve the n×n sub-system W(idx, idx) x = b by dense Cholesky; 0 if not SPD. */
static int chol_solve(int m, const double *W, int n, const int *idx, const double *b, double *x) {
  double L[MAXM * MAXM];
  for (int j = 0; j < n; j++)
    for (int i = 0; i < n; i++) L[j * n + i] = W[idx[j] * m + idx[i]];
  for (int j = 0; j < n; j++) {
    double d = L[j * n + j];
    for (int k = 0; k < j; k++) d -= L[k * n + j] * L[k * n + j];
    if (!(d > 0.0)) return 0;
    d = sqrt(d);
    L[j * n + j] = d;
    for (int i = j + 1; i < n; i++) {
      double v = L[j * n + i];
      for (int k = 0; k < j; k++) v -= L[k * n + i] * L[k * n + j];
      L[j * n + i] = v / d;
    }
  }
  for (int j = 0; j < n; j++) {
    double v = b[j];
    for (int k = 0; k < j; k++) v -= L[k * n + j] * x[k];
    x[j] = v / L[j * n + j];
  }
  for (int j = n - 1; j >= 0; j--) {
    double v = x[j];
    for (int k = j + 1; k < n; k++) v -= L[j * n + k] * x[k];
    x[j] = v / L[j * n + j];
  }
  return 1;
}

static void apply(int m, const double *W, const double *x, const double *r, double *w) {
  for (int i = 0; i < m; i++) {
    double v = r[i];
    for (int j = 0; j < m; j++) v += W[j * m + i] * x[j];
    w[i] = v;
  }
}

static void test_bilateral(void) {
  for (int m = 1; m <= 12; m++) {
    double W[MAXM * MAXM], r[MAXM], lam[MAXM], ref[MAXM], mr[MAXM];
    nh_row_law laws[MAXM];
    int idx[MAXM];
    random_spd(m, W);
    for (int i = 0; i < m; i++) {
      r[i] = nh_rand(), lam[i] = 0.0, mr[i] = -r[i], idx[i] = i;
      laws[i] = law(NH_ROW_BILATERAL);
    }
    CHECK(chol_solve(m, W, m, idx, mr, ref), "random SPD W not SPD (m = %d)", m);
    nh_mcp_stats st;
    CHECK_OK(nh_mcp_solve(m, W, r, laws, 1e-14, 100, lam, &st));
    for (int i = 0; i < m; i++) CHECK_CLOSE(lam[i], ref[i], 1e-10, "bilateral lambda = -W^-1 r");
    CHECK(st.iterations <= 2, "all-bilateral took %d sweeps (m = %d), expected 1-2", st.iterations,
          m);
  }
}

static void test_unilateral(void) {
  for (int m = 1; m <= 6; m++)
    for (int trial = 0; trial < 20; trial++) {
      double W[MAXM * MAXM], r[MAXM], lam[MAXM], w[MAXM], ref[MAXM];
      nh_row_law laws[MAXM];
      random_spd(m, W);
      for (int i = 0; i < m; i++) r[i] = nh_rand(), lam[i] = 0.0, laws[i] = law(NH_ROW_UNILATERAL);
      /* Enumerate active sets: λ_S = −W_SS⁻¹ r_S ≥ 0, w_rest ≥ 0. */
      int found = 0;
      for (int mask = 0; mask < (1 << m) && !found; mask++) {
        int idx[MAXM], n = 0;
        double b[MAXM], x[MAXM], cand[MAXM] = {0};
        for (int i = 0; i < m; i++)
          if (mask >> i & 1) b[n] = -r[i], idx[n++] = i;
        if (n > 0 && !chol_solve(m, W, n, idx, b, x)) continue;
        int ok = 1;
        for (int k = 0; k < n; k++) ok &= x[k] >= 0.0, cand[idx[k]] = x[k];
        double wc[MAXM];
        apply(m, W, cand, r, wc);
        for (int i = 0; i < m; i++)
          if (!(mask >> i & 1)) ok &= wc[i] >= 0.0;
        if (ok) found = 1, memcpy(ref, cand, sizeof(double) * (size_t)m);
      }
      CHECK(found, "no active set solves the LCP (m = %d, trial %d)", m, trial);
      nh_mcp_stats st;
      CHECK_OK(nh_mcp_solve(m, W, r, laws, 1e-14, 100000, lam, &st));
      apply(m, W, lam, r, w);
      for (int i = 0; i < m; i++) {
        CHECK(lam[i] >= 0.0 && w[i] >= -1e-10 && fabs(lam[i] * w[i]) <= 1e-10,
              "complementarity row %d (m = %d): lambda %g, w %g", i, m, lam[i], w[i]);
        CHECK_CLOSE(lam[i], ref[i], 1e-10, "LCP lambda vs enumeration");
      }
    }
}

/* One normal row (0, unilateral) and one tangential row (1, friction on 0):
 * sweep r_t through the stick-slide switch. */
static void friction_case(double Wnn, double Wnt, double Wtt, double mu, double c, int one_sided) {
  double W[4] = {Wnn, Wnt, Wnt, Wtt}, det = Wnn * Wtt - Wnt * Wnt;
  double rn = -1.0;
  nh_row_law laws[2] = {law(NH_ROW_UNILATERAL), law(NH_ROW_FRICTION)};
  laws[1].normal = 0, laws[1].mu = mu, laws[1].threshold = c, laws[1].one_sided = one_sided;
  /* Stick: λ = −W⁻¹ r = a + b r_t. */
  double an = -(Wtt * rn) / det, at = -(-Wnt * rn) / det;
  double bn = -(-Wnt) / det, bt = -(Wnn) / det;
  for (int s = -1; s <= 1; s += 2) {
    /* The switch: a_t + b_t r_t = s (μ (a_n + b_n r_t) + c). */
    double rstar = (s * c + s * mu * an - at) / (bt - s * mu * bn);
    for (int k = -40; k <= 40; k++) {
      double rt = rstar * (1.0 + k / 21.0); /* avoids −r*, the other switch of a diagonal W */
      if (k == 0) rt = rstar;
      double r[2] = {rn, rt}, lam[2] = {0.0, 0.0}, w[2];
      nh_mcp_stats st;
      CHECK_OK(nh_mcp_solve(2, W, r, laws, 1e-14, 10000, lam, &st));
      apply(2, W, lam, r, w);
      double stick_n = an + bn * rt, stick_t = at + bt * rt;
      int stick = fabs(stick_t) <= mu * stick_n + c;
      double en, et;
      if (one_sided && stick_t < 0.0) {
        /* it would pull: λ_t = 0, the normal alone (w_n = 0), and w_t >= 0 */
        CHECK_CLOSE(lam[0], -rn / Wnn, 1e-10, "one-sided: normal force");
        CHECK_CLOSE(lam[1], 0.0, 1e-10, "one-sided: no pull");
        CHECK(w[1] >= -1e-10, "one-sided: w_t = %g < 0 at lambda_t = 0 (r_t = %g)", w[1], rt);
        continue;
      }
      if (stick) {
        en = stick_n, et = stick_t;
      } else {
        double sg = stick_t > 0 ? 1.0 : -1.0;
        en = (-rn - sg * Wnt * c) / (Wnn + sg * Wnt * mu);
        et = sg * (mu * en + c);
        CHECK(w[1] * lam[1] <= 1e-12, "slide: w_t lambda_t = %g > 0 (r_t = %g)", w[1] * lam[1], rt);
      }
      CHECK_CLOSE(lam[0], en, 1e-10, "friction: normal force");
      CHECK_CLOSE(lam[1], et, 1e-10, "friction: tangential force");
      if (k != 0) {
        CHECK(st.n_stick == stick && st.n_slide == !stick,
              "r_t = %g (switch at %g): stick %d slide %d, expected stick %d", rt, rstar,
              st.n_stick, st.n_slide, stick);
      } else {
        /* At the bound both laws hold: continuity of λ. */
        double sg = stick_t > 0 ? 1.0 : -1.0;
        double sn = (-rn - sg * Wnt * c) / (Wnn + sg * Wnt * mu);
        CHECK_CLOSE(stick_n, sn, 1e-10, "continuity of the normal force at the bound");
        CHECK_CLOSE(stick_t, sg * (mu * sn + c), 1e-10, "continuity of the friction at the bound");
        CHECK(st.n_stick + st.n_slide == 1, "one friction row expected");
      }
    }
  }
}

static void test_friction(void) {
  for (int one_sided = 0; one_sided < 2; one_sided++) {
    friction_case(2.0, 0.0, 0.5, 0.3, 0.0, one_sided);
    friction_case(2.0, 0.0, 0.5, 0.3, 0.2, one_sided);
    friction_case(2.0, 0.4, 0.5, 0.3, 0.1, one_sided);
    friction_case(1.0, -0.3, 3.0, 0.5, 0.05, one_sided);
  }
}

/* A needle block (rows 0..nn-1) and a tissue block, bilateral, unilateral and
 * friction rows, coupled; returns sweeps and the relative error. */
static void stiffness_problem(int m, double *W, double *r, nh_row_law *laws) {
  random_spd(m, W);
  for (int i = 0; i < m; i++) r[i] = nh_rand();
  for (int i = 0; i < m; i++) laws[i] = law(NH_ROW_BILATERAL);
  /* Needle rows 0..5: 0 unilateral + 1 friction, 2..5 bilateral; tissue rows
   * 6..: 6 unilateral + 7,8 disc pair, 9 unilateral + 10 friction, rest bilateral. */
  laws[0] = law(NH_ROW_UNILATERAL);
  laws[1] = law(NH_ROW_FRICTION), laws[1].normal = 0, laws[1].mu = 0.3, laws[1].threshold = 0.1;
  laws[6] = law(NH_ROW_UNILATERAL);
  for (int k = 7; k <= 8; k++)
    laws[k] = law(NH_ROW_FRICTION), laws[k].normal = 6, laws[k].mu = 0.4, laws[k].group = 7;
  laws[9] = law(NH_ROW_UNILATERAL);
  laws[10] = law(NH_ROW_FRICTION), laws[10].normal = 9, laws[10].mu = 0.2;
  laws[10].threshold = 0.05;
  r[0] = -fabs(r[0]), r[6] = -2.0, r[9] = -fabs(r[9]);
}

static void test_stiffness_ratio(void) {
  enum { M = 16, NN = 6 };
  double W[M * M], r[M], Ws[M * M], rs[M], s[M];
  nh_row_law laws[M], lawss[M];
  stiffness_problem(M, W, r, laws);
  /* W' = S W S, S = 1e3 on the needle rows, 1e-3 on the tissue: diagonal blocks
   * ×1e6 and ×1e-6; λ' = S⁻¹ λ, and thresholds c' = c / s_i. */
  for (int i = 0; i < M; i++) s[i] = i < NN ? 1e3 : 1e-3;
  for (int j = 0; j < M; j++)
    for (int i = 0; i < M; i++) Ws[j * M + i] = s[i] * W[j * M + i] * s[j];
  for (int i = 0; i < M; i++) {
    rs[i] = s[i] * r[i];
    lawss[i] = laws[i];
    lawss[i].threshold = laws[i].threshold / s[i];
  }
  double lam[M] = {0}, lams[M] = {0}, w[M], ws[M];
  nh_mcp_stats st, sts;
  double tol = 1e-12;
  CHECK_OK(nh_mcp_solve(M, W, r, laws, tol, 100000, lam, &st));
  CHECK_OK(nh_mcp_solve(M, Ws, rs, lawss, tol, 100000, lams, &sts));
  CHECK(abs(st.iterations - sts.iterations) <= (st.iterations + 9) / 10,
        "sweeps unscaled %d vs stiffness ratio 1e12 %d (more than 10%% apart)", st.iterations,
        sts.iterations);
  CHECK(st.residual <= tol && sts.residual <= tol, "residuals %g, %g", st.residual, sts.residual);
  double lmax = 0.0;
  for (int i = 0; i < M; i++) lmax = fmax(lmax, fabs(lam[i]));
  for (int i = 0; i < M; i++)
    CHECK_CLOSE(s[i] * lams[i], lam[i], 1e-9 * lmax, "stiff/soft lambda, rescaled");
  apply(M, W, lam, r, w);
  apply(M, Ws, lams, rs, ws);
  for (int i = 0; i < M; i++)
    if (laws[i].kind == NH_ROW_BILATERAL)
      CHECK_CLOSE(ws[i] / s[i], w[i], 1e-9, "stiff/soft bilateral violation");
  CHECK(st.iterations > 1, "the mixed problem should need several sweeps (took %d)", st.iterations);
}

static void test_warm_start(void) {
  enum { M = 16 };
  double W[M * M], r[M], lam[M] = {0};
  nh_row_law laws[M];
  stiffness_problem(M, W, r, laws);
  nh_mcp_stats st;
  CHECK_OK(nh_mcp_solve(M, W, r, laws, 1e-12, 100000, lam, &st));
  double lam0[M];
  memcpy(lam0, lam, sizeof lam);
  CHECK_OK(nh_mcp_solve(M, W, r, laws, 1e-12, 100000, lam, &st));
  CHECK(st.iterations <= 1, "warm start at the solution took %d sweeps", st.iterations);
  for (int i = 0; i < M; i++) CHECK_CLOSE(lam[i], lam0[i], 1e-12, "warm start moved lambda");
}

/* Normal row 0, tangent pair (1, 2) on a disc. */
static void test_disc(void) {
  double mu = 0.5;
  for (int coupled = 0; coupled <= 1; coupled++)
    for (int k = 0; k < 40; k++) {
      double W[9] = {2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
      if (coupled) { /* anisotropic tangents, coupled to the normal */
        double G[9];
        for (int q = 0; q < 9; q++) G[q] = nh_rand();
        for (int i = 0; i < 3; i++)
          for (int j = 0; j < 3; j++) {
            double v = i == j ? 0.3 : 0.0;
            for (int q = 0; q < 3; q++) v += G[q * 3 + i] * G[q * 3 + j];
            W[j * 3 + i] = v;
          }
      }
      nh_row_law laws[3] = {law(NH_ROW_UNILATERAL), law(NH_ROW_FRICTION), law(NH_ROW_FRICTION)};
      for (int q = 1; q <= 2; q++) laws[q].normal = 0, laws[q].mu = mu, laws[q].group = 1;
      double ang = 0.3 + 0.7 * k, mag = 0.05 * k;
      double r[3] = {-2.0, mag * cos(ang), mag * sin(ang)}, lam[3] = {0}, w[3];
      nh_mcp_stats st;
      CHECK_OK(nh_mcp_solve(3, W, r, laws, 1e-14, 100000, lam, &st));
      apply(3, W, lam, r, w);
      double b = mu * lam[0], f = hypot(lam[1], lam[2]), v = hypot(w[1], w[2]);
      CHECK(lam[0] >= 0.0 && fabs(w[0]) <= 1e-10, "disc: normal w %g, lambda %g", w[0], lam[0]);
      CHECK(f <= b * (1.0 + 1e-12), "disc: |lambda_t| = %.17g > bound %.17g", f, b);
      if (st.n_stick == 2) {
        CHECK(v <= 1e-10, "disc stick: |w_t| = %g", v);
      } else {
        CHECK(st.n_slide == 2, "disc: stick %d slide %d", st.n_stick, st.n_slide);
        CHECK_CLOSE(f, b, 1e-10, "disc slide: |lambda_t| on the circle");
        /* w_t = −ν λ_t, ν ≥ 0: slip opposite to the force. */
        CHECK_CLOSE(w[1] * lam[1] + w[2] * lam[2], -v * f, 1e-10, "disc slide: w_t antiparallel");
      }
      if (!coupled) { /* closed form: stick −r_t/1 if |r_t| ≤ μ λ_n = μ, else −μ r_t/|r_t| */
        double rt = hypot(r[1], r[2]), e = rt <= mu ? 1.0 : mu / rt;
        CHECK_CLOSE(lam[0], 1.0, 1e-12, "disc: diagonal normal force");
        CHECK_CLOSE(lam[1], -e * r[1], 1e-10, "disc: closed form t1");
        CHECK_CLOSE(lam[2], -e * r[2], 1e-10, "disc: closed form t2");
      }
    }
}

static void test_failures(void) {
  double W[4] = {1.0, 0.5, 0.5, 1.0}, r[2] = {-1.0, 1.0}, lam[2] = {0};
  nh_row_law laws[2] = {law(NH_ROW_UNILATERAL), law(NH_ROW_FRICTION)};
  laws[1].normal = 5;
  CHECK(nh_mcp_solve(2, W, r, laws, 1e-10, 100, lam, NULL) == NH_ERR_INPUT, "normal out of range");
  laws[1].normal = 1;
  CHECK(nh_mcp_solve(2, W, r, laws, 1e-10, 100, lam, NULL) == NH_ERR_INPUT, "normal is friction");
  laws[1].normal = 0, laws[1].group = 1;
  CHECK(nh_mcp_solve(2, W, r, laws, 1e-10, 100, lam, NULL) == NH_ERR_INPUT, "pair past the end");
  laws[1].group = -1, laws[1].mu = -1.0;
  CHECK(nh_mcp_solve(2, W, r, laws, 1e-10, 100, lam, NULL) == NH_ERR_INPUT, "negative mu");
  laws[1].mu = 0.3;
  double Wneg[4] = {-1.0, 0.0, 0.0, 1.0};
  CHECK(nh_mcp_solve(2, Wneg, r, laws, 1e-10, 100, lam, NULL) == NH_ERR_NUMERIC, "negative W_ii");
  /* Not converged in 1 sweep on a coupled unilateral problem: best iterate kept. */
  enum { M = 16 };
  double Wb[M * M], rb[M], lb[M] = {0};
  nh_row_law lw[M];
  stiffness_problem(M, Wb, rb, lw);
  nh_mcp_stats st;
  CHECK(nh_mcp_solve(M, Wb, rb, lw, 1e-14, 1, lb, &st) == NH_ERR_NUMERIC,
        "1 Newton step and 1 sweep converged?");
  CHECK(st.sweeps == 1 && st.newton_steps >= 1 && st.method == NH_MCP_FALLBACK &&
            st.iterations == st.sweeps + st.newton_steps && st.residual > 1e-14 &&
            isfinite(st.residual),
        "non-converged stats: %d Newton steps, %d sweeps, method %d, residual %g", st.newton_steps,
        st.sweeps, (int)st.method, st.residual);
  for (int i = 0; i < M; i++) CHECK(isfinite(lb[i]), "best iterate not finite");
  CHECK_OK(nh_mcp_solve(0, NULL, NULL, NULL, 1e-10, 10, NULL, &st));
}

/* A friction row bounded by two bilateral normal rows (a needle point's two
 * lateral rows): the bound is mu |(λ0, λ1)| + c. The bilateral forces are
 * fixed by their own rows (W block-diagonal, the friction row coupled to
 * them so the solve is not trivially separable); sweep the friction row's
 * free violation across the switch. */
static void test_two_normals(void) {
  const double mu = 0.4, c = 0.05;
  double W[9] = {2.0, 0.3, 0.2, 0.3, 1.5, -0.1, 0.2, -0.1, 1.0};
  nh_row_law laws[3] = {law(NH_ROW_BILATERAL), law(NH_ROW_BILATERAL), law(NH_ROW_FRICTION)};
  laws[2].normal = 0, laws[2].normal2 = 1, laws[2].mu = mu, laws[2].threshold = c;
  int switched = 0;
  for (int k = -40; k <= 40; k++) {
    double r[3] = {-1.0, 0.7, 0.05 * k}, lam[3] = {0, 0, 0};
    nh_mcp_stats st;
    CHECK_OK(nh_mcp_solve(3, W, r, laws, 1e-12, 500, lam, &st));
    double w[3];
    for (int i = 0; i < 3; i++) w[i] = r[i] + W[i] * lam[0] + W[3 + i] * lam[1] + W[6 + i] * lam[2];
    double bound = mu * hypot(lam[0], lam[1]) + c;
    CHECK_CLOSE(w[0], 0.0, 1e-10, "two normals: bilateral row 0 holds");
    CHECK_CLOSE(w[1], 0.0, 1e-10, "two normals: bilateral row 1 holds");
    CHECK(fabs(lam[2]) <= bound * (1 + 1e-10), "two normals: |λt| within mu |λn| + c");
    if (fabs(w[2]) > 1e-10) { /* sliding: on the bound, opposing the slip */
      CHECK_CLOSE(fabs(lam[2]), bound, 1e-9 * bound, "two normals: slide on the bound");
      CHECK(lam[2] * w[2] <= 0.0, "two normals: slide opposes the slip");
      switched++;
    }
  }
  CHECK(switched > 0 && switched < 81, "two normals: both stick and slide occur in the sweep");
}

/* Rows 0, 1 bilateral (a shaft point's lateral rows), row 2 axial friction on
 * both with kinetic mu_k, static mu_s, threshold c. A ramp of the axial free
 * violation r2 = ρ_k up to ρ_max and back down, the sliding state carried
 * from load step to load step as the contact module does. Expected forces:
 *   stuck (did not slide before, or arrested): λ = −W⁻¹ r while the stick
 *   force |λ2| is within the bound of the state (μ_s if it stuck before,
 *   μ_k if it slid); otherwise it slides: λ2 = −sign(r2)(μ_k N + c) with N =
 *   |(λ0, λ1)| and (λ0, λ1) = −W_nn⁻¹ (r_n + W_n2 λ2): solved here by a
 *   fixed point on N (a contraction: |W_n2| small). */
static void static_kinetic_case(const double W[9], double mu_k, double mu_s, double c) {
  nh_row_law laws[3] = {law(NH_ROW_BILATERAL), law(NH_ROW_BILATERAL), law(NH_ROW_FRICTION)};
  laws[2].normal = 0, laws[2].normal2 = 1, laws[2].mu = mu_k, laws[2].mu_static = mu_s;
  laws[2].threshold = c;
  const double rn[2] = {-1.0, 0.7};
  /* W_nn⁻¹ (2×2) */
  double det = W[0] * W[4] - W[1] * W[3];
  double Ni[4] = {W[4] / det, -W[1] / det, -W[3] / det, W[0] / det};
  int slid = 0, n_break = 0, n_rearrest = 0, was_sliding = 0, n = 120;
  double lam[3] = {0, 0, 0};
  for (int k = 0; k <= 2 * n; k++) {
    double rt = 3.0 * (k <= n ? k : 2 * n - k) / n; /* 0 → 3 → 0 */
    double r[3] = {rn[0], rn[1], rt};
    /* stick candidate: all three rows bilateral (Cramer on the 3×3) */
    double A[9];
    memcpy(A, W, sizeof A);
    double d3 = A[0] * (A[4] * A[8] - A[7] * A[5]) - A[3] * (A[1] * A[8] - A[7] * A[2]) +
                A[6] * (A[1] * A[5] - A[4] * A[2]);
    double st[3];
    for (int i = 0; i < 3; i++) {
      double B[9];
      memcpy(B, A, sizeof B);
      for (int q = 0; q < 3; q++) B[3 * i + q] = -r[q];
      st[i] = (B[0] * (B[4] * B[8] - B[7] * B[5]) - B[3] * (B[1] * B[8] - B[7] * B[2]) +
               B[6] * (B[1] * B[5] - B[4] * B[2])) /
              d3;
    }
    double mu_state = slid ? mu_k : mu_s;
    int stick = fabs(st[2]) <= mu_state * hypot(st[0], st[1]) + c;
    double e[3];
    if (stick) {
      memcpy(e, st, sizeof e);
    } else {
      double sg = st[2] > 0 ? 1.0 : -1.0, N = hypot(st[0], st[1]);
      for (int it = 0; it < 200; it++) {
        e[2] = sg * (mu_k * N + c);
        double q0 = -(rn[0] + W[6] * e[2]), q1 = -(rn[1] + W[7] * e[2]);
        e[0] = Ni[0] * q0 + Ni[2] * q1, e[1] = Ni[1] * q0 + Ni[3] * q1;
        N = hypot(e[0], e[1]);
      }
      e[2] = sg * (mu_k * N + c);
    }
    laws[2].sliding = slid;
    nh_mcp_stats sts;
    CHECK_OK(nh_mcp_solve(3, W, r, laws, 1e-13, 1000, lam, &sts));
    for (int i = 0; i < 3; i++)
      CHECK(fabs(lam[i] - e[i]) <= 1e-9 * (1 + fabs(e[i])),
            "static/kinetic (mu_k %g, mu_s %g, step %d, r_t %g, slid before %d): lambda_%d "
            "expected %.12g, got %.12g (tol 1e-9 relative)",
            mu_k, mu_s, k, rt, slid, i, e[i], lam[i]);
    /* the solver's state: sliding iff the stick force does not fit the state's bound */
    int slides = !stick;
    CHECK(laws[2].sliding == slides, "static/kinetic step %d: sliding out %d, expected %d", k,
          laws[2].sliding, slides);
    if (!slid && laws[2].sliding && k > 0) n_break++;
    if (was_sliding && !laws[2].sliding) n_rearrest++;
    was_sliding = slid = laws[2].sliding;
  }
  CHECK(n_break == 1 && n_rearrest == 1,
        "static/kinetic: one break-away on the way up and one arrest on the way down expected, "
        "got %d and %d",
        n_break, n_rearrest);
}

/* The break-away load: with decoupled rows the stick force is −r_t / W_tt, so
 * the point breaks at r_t = W_tt (μ_s N + c) and then carries μ_k N + c. */
static void test_static_kinetic(void) {
  const double Wd[9] = {2.0, 0.0, 0.0, 0.0, 1.5, 0.0, 0.0, 0.0, 1.0};
  const double Wc[9] = {2.0, 0.3, 0.2, 0.3, 1.5, -0.1, 0.2, -0.1, 1.0};
  static_kinetic_case(Wd, 0.3, 0.6, 0.05); /* seed: static twice the kinetic */
  static_kinetic_case(Wc, 0.3, 0.6, 0.05);
  static_kinetic_case(Wc, 0.4, 0.4, 0.0); /* μ_s = μ_k: plain Coulomb */
  /* The break-away point in the decoupled case, stated as numbers: N =
   * |(0.5, −0.7/1.5)|; stuck at r_t just below W_tt (μ_s N + c), sliding at
   * μ_k N + c just above it. */
  nh_row_law laws[3] = {law(NH_ROW_BILATERAL), law(NH_ROW_BILATERAL), law(NH_ROW_FRICTION)};
  laws[2].normal = 0, laws[2].normal2 = 1, laws[2].mu = 0.3, laws[2].mu_static = 0.6;
  double N = hypot(0.5, 0.7 / 1.5), rb = 0.6 * N;
  for (int side = -1; side <= 1; side += 2) {
    double r[3] = {-1.0, 0.7, rb * (1 + side * 1e-6)}, lam[3] = {0, 0, 0};
    laws[2].sliding = 0;
    CHECK_OK(nh_mcp_solve(3, Wd, r, laws, 1e-14, 1000, lam, NULL));
    double expect = side < 0 ? -r[2] : -0.3 * N;
    CHECK_CLOSE(lam[2], expect, 1e-12, "static/kinetic break-away force");
    CHECK(laws[2].sliding == (side > 0), "break-away: sliding %d on side %d", laws[2].sliding,
          side);
  }
  /* A disc pair (the puncture's tangential rows) on a unilateral normal,
   * decoupled: stuck up to μ_s λ_n, then on the μ_k circle. */
  double Wp[9] = {1.0, 0, 0, 0, 2.0, 0, 0, 0, 2.0};
  nh_row_law pl[3] = {law(NH_ROW_UNILATERAL), law(NH_ROW_FRICTION), law(NH_ROW_FRICTION)};
  for (int q = 1; q <= 2; q++)
    pl[q].normal = 0, pl[q].group = 1, pl[q].mu = 0.2, pl[q].mu_static = 0.4;
  for (int side = -1; side <= 1; side += 2) {
    double load = 0.4 * 1.0 * 2.0 * (1 + side * 1e-6); /* |stick| = load / W_tt */
    double r[3] = {-1.0, 0.6 * load, 0.8 * load}, lam[3] = {0, 0, 0};
    pl[1].sliding = pl[2].sliding = 0;
    CHECK_OK(nh_mcp_solve(3, Wp, r, pl, 1e-14, 1000, lam, NULL));
    double f = hypot(lam[1], lam[2]), expect = side < 0 ? load / 2.0 : 0.2;
    CHECK_CLOSE(f, expect, 1e-10, "disc static/kinetic: tangential force");
    CHECK(pl[1].sliding == (side > 0) && pl[2].sliding == pl[1].sliding,
          "disc break-away: sliding %d %d on side %d", pl[1].sliding, pl[2].sliding, side);
  }
}

/* ---- 8. problems with a known solution (built from it) ----
 * A problem is built from its solution: rows grouped as the contact module
 * writes them (a bilateral row; a unilateral row, with or without a cap; a
 * needle point: two bilateral lateral rows and an axial friction row
 * bounded by μ|(λ1, λ2)| + c; a contact: a unilateral normal and a 1-D
 * friction row on it; a puncture: a unilateral normal and a disc pair),
 * each row given a state (open / active / at its cap; stick / slide) with a
 * margin, λ* and w* chosen to obey the law in that state, then r = w* − W λ*
 * (in long double). W = Q diag(σ) Qᵀ, Q a random orthogonal matrix (Gram-
 * Schmidt twice), σ log-spaced from 1 down to 1/κ, then S W S with a
 * diagonal S (a stiffness ratio, which the solver's scaling removes). With
 * `blocked` the normal rows (bilateral, unilateral) and the friction rows
 * get independent Q's (W has no normal-friction coupling): the normal forces
 * are then the unique solution of an LCP with a positive definite matrix,
 * the bounds are fixed by them, and the friction forces are the unique
 * minimiser of a strictly convex quadratic over the bounds — λ* is the only
 * solution. The same holds fully coupled when every bound is a constant
 * (μ = 0: a Tresca problem, a strictly convex QP). */
enum { ROW_B, ROW_U, ROW_CAP, ROW_POINT, ROW_CONTACT, ROW_DISC, ROW_TYPES };

typedef struct {
  int m;
  double W[MAXM * MAXM], r[MAXM], lstar[MAXM], wstar[MAXM];
  nh_row_law laws[MAXM];
} known_problem;

static double urand(void) {
  return 0.5 * (nh_rand() + 1.0);
}

/* Random orthogonal Q (n×n, column-major) into Q. */
static void random_orthogonal(int n, double *Q) {
  for (int k = 0; k < n * n; k++) Q[k] = nh_rand();
  for (int j = 0; j < n; j++)
    for (int pass = 0; pass < 2; pass++) {
      for (int k = 0; k < j; k++) {
        double d = 0.0;
        for (int i = 0; i < n; i++) d += Q[k * n + i] * Q[j * n + i];
        for (int i = 0; i < n; i++) Q[j * n + i] -= d * Q[k * n + i];
      }
      double nn = 0.0;
      for (int i = 0; i < n; i++) nn += Q[j * n + i] * Q[j * n + i];
      for (int i = 0; i < n; i++) Q[j * n + i] /= sqrt(nn);
    }
}

/* W(idx, idx) = Q diag(σ) Qᵀ over the rows idx (n of them), σ_k = κ^(−k/(n−1)). */
static void conditioned_block(int m, double *W, int n, const int *idx, double kappa) {
  double Q[MAXM * MAXM], sg[MAXM];
  random_orthogonal(n, Q);
  for (int k = 0; k < n; k++) sg[k] = n > 1 ? pow(kappa, -(double)k / (n - 1)) : 1.0;
  for (int a = 0; a < n; a++)
    for (int b = 0; b < n; b++) {
      long double v = 0.0L;
      for (int k = 0; k < n; k++) v += (long double)Q[k * n + a] * sg[k] * Q[k * n + b];
      W[idx[b] * m + idx[a]] = (double)v;
    }
}

/* Build a problem of about m rows from the group types allowed in `types`
 * (a bit mask of 1 << ROW_*), condition κ, stiffness ratio `ratio` (S from
 * 1/√ratio to √ratio), friction μ (0: Tresca), normal-friction coupling. */
static void known_build(known_problem *p, int m, unsigned types, double kappa, double ratio,
                        double mu, int blocked, double skew) {
  nh_row_law *L = p->laws;
  int n = 0, grp[MAXM], groups = 0;
  while (n < m) {
    const int n0 = n;
    int t;
    do t = (int)(urand() * ROW_TYPES) % ROW_TYPES;
    while (!(types >> t & 1));
    int need = t == ROW_POINT || t == ROW_DISC ? 3 : t == ROW_CONTACT ? 2 : 1;
    if (n + need > MAXM) break;
    if (n + need > m && n > 0) break;
    if (t == ROW_B) {
      L[n] = law(NH_ROW_BILATERAL), p->lstar[n] = nh_rand(), p->wstar[n] = 0.0, n++;
    } else if (t == ROW_U || t == ROW_CAP) {
      L[n] = law(NH_ROW_UNILATERAL);
      double c = t == ROW_CAP ? 0.5 + urand() : 0.0, pick = urand();
      L[n].threshold = c;
      if (pick < 0.33) /* open */
        p->lstar[n] = 0.0, p->wstar[n] = 0.2 + urand();
      else if (t == ROW_CAP && pick > 0.67) /* yields at its cap */
        p->lstar[n] = c, p->wstar[n] = -(0.2 + urand());
      else /* active inside */
        p->lstar[n] = (0.2 + 0.6 * urand()) * (c > 0.0 ? c : 1.0), p->wstar[n] = 0.0;
      n++;
    } else {
      /* the normal(s), then the friction row(s) */
      int nn = t == ROW_POINT ? 2 : 1, f = n + nn;
      double N2 = 0.0;
      for (int k = 0; k < nn; k++) {
        L[n + k] = law(t == ROW_POINT ? NH_ROW_BILATERAL : NH_ROW_UNILATERAL);
        if (t == ROW_POINT) {
          p->lstar[n + k] = nh_rand(), p->wstar[n + k] = 0.0;
        } else if (urand() < 0.25) { /* open contact: the bound is the threshold */
          p->lstar[n + k] = 0.0, p->wstar[n + k] = 0.2 + urand();
        } else {
          p->lstar[n + k] = 0.2 + urand(), p->wstar[n + k] = 0.0;
        }
        N2 += p->lstar[n + k] * p->lstar[n + k];
      }
      double c = t == ROW_DISC ? 0.0 : 0.05 + 0.2 * urand(), b = mu * sqrt(N2) + c;
      int nf = t == ROW_DISC ? 2 : 1;
      for (int k = 0; k < nf; k++) {
        L[f + k] = law(NH_ROW_FRICTION);
        L[f + k].normal = n, L[f + k].normal2 = t == ROW_POINT ? n + 1 : -1;
        L[f + k].mu = mu, L[f + k].threshold = c, L[f + k].group = nf == 2 ? f : -1;
        L[f + k].sliding = 1;
      }
      if (b == 0.0) b = 0.0; /* an open puncture contact: no friction at all */
      int slide = urand() < 0.5 && b > 0.0;
      if (nf == 1) {
        double sg = nh_rand() < 0 ? -1.0 : 1.0;
        p->lstar[f] = slide ? sg * b : (0.8 * nh_rand()) * b;
        p->wstar[f] = slide ? -sg * (0.2 + urand()) : 0.0;
        L[f].sliding = slide || urand() < 0.5; /* a sticking row may have stuck before */
        if (!L[f].sliding) L[f].mu_static = 2.0 * mu;
      } else {
        double a = 2.0 * M_PI * urand(), rho = slide ? 1.0 : 0.8 * urand(), nu = 0.2 + urand();
        p->lstar[f] = rho * b * cos(a), p->lstar[f + 1] = rho * b * sin(a);
        p->wstar[f] = slide ? -nu * cos(a) : 0.0, p->wstar[f + 1] = slide ? -nu * sin(a) : 0.0;
        if (b == 0.0) p->wstar[f] = nh_rand(), p->wstar[f + 1] = nh_rand(); /* free to slip */
      }
      n = f + nf;
    }
    for (int i = n0; i < n; i++) grp[i] = groups;
    groups++;
  }
  p->m = m = n;
  memset(p->W, 0, sizeof p->W);
  int idx[MAXM], k = 0;
  if (blocked) {
    for (int i = 0; i < m; i++)
      if (L[i].kind != NH_ROW_FRICTION) idx[k++] = i;
    conditioned_block(m, p->W, k, idx, kappa);
    int nf = 0;
    for (int i = 0; i < m; i++)
      if (L[i].kind == NH_ROW_FRICTION) idx[nf++] = i;
    if (nf) conditioned_block(m, p->W, nf, idx, kappa);
  } else {
    for (int i = 0; i < m; i++) idx[i] = i;
    conditioned_block(m, p->W, m, idx, kappa);
  }
  if (skew > 0.0) { /* W += skew K/|K|_F, K = G − Gᵀ: W's symmetric part stays */
    double G[MAXM * MAXM], f = 0.0;
    for (int k = 0; k < m * m; k++) G[k] = nh_rand();
    for (int j = 0; j < m; j++)
      for (int i = 0; i < m; i++) f += pow(G[j * m + i] - G[i * m + j], 2);
    for (int j = 0; j < m; j++)
      for (int i = 0; i < m; i++) p->W[j * m + i] += skew * (G[j * m + i] - G[i * m + j]) / sqrt(f);
  }
  /* stiffness ratio: the rows of a group (which share a point) scaled by one
   * S, so its law keeps μ: W → S W S, λ* → S⁻¹ λ*, w* → S w*, thresholds → S⁻¹ */
  double S[MAXM], Sg[MAXM];
  for (int g = 0; g < groups; g++) Sg[g] = pow(ratio, 0.5 * nh_rand());
  for (int i = 0; i < m; i++) S[i] = Sg[grp[i]];
  for (int j = 0; j < m; j++)
    for (int i = 0; i < m; i++) p->W[j * m + i] *= S[i] * S[j];
  for (int i = 0; i < m; i++) {
    p->lstar[i] /= S[i], p->wstar[i] *= S[i];
    if (L[i].kind != NH_ROW_BILATERAL) L[i].threshold /= S[i];
  }
  for (int i = 0; i < m; i++) {
    long double v = p->wstar[i];
    for (int j = 0; j < m; j++) v -= (long double)p->W[j * m + i] * p->lstar[j];
    p->r[i] = (double)v;
  }
}

/* Relative error max|λ − λ*| / max|λ*| of the solver on p from a cold start. */
static double known_error(const known_problem *p, double tol, nh_mcp_stats *st, int *rc,
                          int unsym) {
  nh_row_law laws[MAXM];
  double lam[MAXM] = {0};
  memcpy(laws, p->laws, sizeof(nh_row_law) * (size_t)p->m);
  *rc =
      (unsym ? nh_mcp_solve_unsymmetric : nh_mcp_solve)(p->m, p->W, p->r, laws, tol, 2000, lam, st);
  if (*rc) nh_error_clear();
  double e = 0.0, s = 0.0;
  for (int i = 0; i < p->m; i++)
    e = fmax(e, fabs(lam[i] - p->lstar[i])), s = fmax(s, fabs(p->lstar[i]));
  return s > 0.0 ? e / s : e;
}

/* Every problem of test_known's grid: (set, κ, variant, trial) → its seed
 * position in the random stream is fixed by the order below. Asserted:
 *  - unique solutions (μ = 0: a strictly convex QP; or W without
 *    normal-friction coupling): converged (residual ≤ tol) and
 *    max|λ − λ*| / max|λ*| ≤ 10 m κ ε, the perturbation bound of a linear
 *    system of condition κ (the active pieces, once right, make the problem
 *    one) with ε the double precision unit round-off;
 *  - Coulomb friction coupled to the normals (solutions need not be
 *    unique): converged, for κ ≤ 1e4.
 * Not asserted, counted (NH_TEST_VERBOSE prints them): Coulomb problems at
 * larger κ, where the Tresca fixed point may stall (docs/theory.md, The
 * constraint solve). */
static void test_known(void) {
  static const unsigned sets[] = {1u << ROW_B | 1u << ROW_U | 1u << ROW_CAP, 1u << ROW_POINT,
                                  1u << ROW_CONTACT, 1u << ROW_DISC, (1u << ROW_TYPES) - 1};
  static const double kappas[] = {1.0, 1e4, 1e8, 1e12};
  const double tol = 1e-14;
  const int verbose = getenv("NH_TEST_VERBOSE") != NULL;
  int unasserted = 0, unasserted_failed = 0, newton_max = 0;
  double worst[4] = {0};
  for (int si = 0; si < 5; si++)
    for (int ki = 0; ki < 4; ki++)
      for (int v = 0; v < 8; v++) {
        int blocked = v & 1, m = (v >> 1 & 1) ? 40 : 12;
        double ratio = (v >> 2 & 1) ? 1e6 : 1.0, mu = 0.3;
        for (int trial = 0; trial < 10; trial++) {
          known_problem p;
          int coulomb = trial % 2;
          known_build(&p, m, sets[si], kappas[ki], ratio, coulomb ? mu : 0.0, blocked, 0.0);
          nh_mcp_stats st;
          int rc;
          double e = known_error(&p, tol, &st, &rc, 0);
          int unique = !coulomb || blocked;
          if (verbose)
            printf("set %d kappa %.0e m %d blocked %d ratio %.0e coulomb %d: rc %d method %d "
                   "newton %d sweeps %d res %.2e err %.2e\n",
                   si, kappas[ki], p.m, blocked, ratio, coulomb, rc, (int)st.method,
                   st.newton_steps, st.sweeps, st.residual, e);
          if (unique && !(coulomb && kappas[ki] > 1e8)) {
            double bound = 10.0 * p.m * fmax(kappas[ki], 1.0) * DBL_EPSILON;
            CHECK(rc == NH_OK && e <= bound,
                  "known solution, set %d, kappa %g, m %d, blocked %d, ratio %g, mu %g: rc %d "
                  "(residual %g, tolerance %g), relative error %g > %g",
                  si, kappas[ki], p.m, blocked, ratio, coulomb ? mu : 0.0, rc, st.residual, tol, e,
                  bound);
            worst[ki] = fmax(worst[ki], e / bound);
            if (st.method == NH_MCP_EXACT)
              newton_max = st.newton_steps > newton_max ? st.newton_steps : newton_max;
          } else if (!unique && kappas[ki] <= 1e4) {
            CHECK(rc == NH_OK, "coupled Coulomb, set %d, kappa %g, m %d: rc %d, residual %g", si,
                  kappas[ki], p.m, rc, st.residual);
          } else {
            unasserted++, unasserted_failed += rc != NH_OK;
          }
        }
      }
  if (verbose)
    printf("worst error / bound per kappa: %.2g %.2g %.2g %.2g; most Newton steps %d; "
           "not asserted %d (%d did not converge)\n",
           worst[0], worst[1], worst[2], worst[3], newton_max, unasserted, unasserted_failed);
}

/* An unsymmetric W (nh_mcp_solve_unsymmetric): W = S + N, S the SPD matrix
 * of test_known's problems (condition κ, stiffness ratio), N skew with
 * |N|₂ ≤ |N|_F = 0.5 |S|₂, and r = w* − W λ* for the constructed solution
 * (λ*, w*) whose every row obeys its law exactly (open, active, at its cap,
 * bilateral, sticking and sliding friction with fixed bounds, disc pairs).
 * W's symmetric part is S, so W λ + r is strongly monotone and, the sets
 * being fixed (μ = 0), the solution is unique: the solver must find λ*,
 * within 20 m κ ε (the bound of test_known with cond(W) ≤ 1.5 κ). Then the
 * sweeps' path (more than 200 rows: bilateral block and subspace steps by
 * LU): W = I + 0.2 G/√m (G uniform in [−1, 1], |0.2 G/√m|₂ ≤ 0.35, so the
 * symmetric part is positive definite), 20 bilateral rows and unilateral
 * ones open, active and at their cap, λ* within 1e-10 (tolerance 1e-14,
 * cond(W) ≤ 1.35/0.65). */
static void test_unsymmetric(void) {
  static const unsigned sets[] = {1u << ROW_B | 1u << ROW_U | 1u << ROW_CAP, 1u << ROW_POINT,
                                  1u << ROW_CONTACT, 1u << ROW_DISC, (1u << ROW_TYPES) - 1};
  static const double kappas[] = {1.0, 1e4};
  for (int si = 0; si < 5; si++)
    for (int ki = 0; ki < 2; ki++)
      for (int v = 0; v < 4; v++)
        for (int trial = 0; trial < 5; trial++) {
          known_problem p;
          double ratio = (v & 1) ? 1e6 : 1.0;
          known_build(&p, (v & 2) ? 40 : 12, sets[si], kappas[ki], ratio, 0.0, 0, 0.1);
          double asym = 0.0;
          for (int j = 0; j < p.m; j++)
            for (int i = 0; i < j; i++)
              asym = fmax(asym, fabs(p.W[j * p.m + i] - p.W[i * p.m + j]) /
                                    sqrt(p.W[i * p.m + i] * p.W[j * p.m + j]));
          CHECK(asym > 1e-3, "unsymmetric W: relative asymmetry %g", asym);
          nh_mcp_stats st;
          int rc;
          double e = known_error(&p, 1e-14, &st, &rc, 1);
          double bound = 20.0 * p.m * kappas[ki] * DBL_EPSILON;
          if (getenv("NH_TEST_VERBOSE"))
            printf(
                "unsym set %d kappa %g m %d ratio %g: rc %d method %d newton %d sweeps %d res %.2e "
                "err %.2e\n",
                si, kappas[ki], p.m, ratio, rc, (int)st.method, st.newton_steps, st.sweeps,
                st.residual, e);
          CHECK(rc == NH_OK && e <= bound,
                "unsymmetric W, set %d, kappa %g, m %d, ratio %g: rc %d (residual %g), relative "
                "error %g > %g",
                si, kappas[ki], p.m, ratio, rc, st.residual, e, bound);
        }
  enum { M = 220, NB = 20 };
  double *W = malloc(sizeof(double) * M * M), *r = malloc(sizeof(double) * M);
  double *ls = malloc(sizeof(double) * M), *ws = malloc(sizeof(double) * M);
  double *lam = calloc(M, sizeof(double));
  nh_row_law *laws = malloc(sizeof *laws * M);
  CHECK(W && r && ls && ws && lam && laws, "out of memory");
  if (!(W && r && ls && ws && lam && laws)) return;
  for (int j = 0; j < M; j++)
    for (int i = 0; i < M; i++) W[j * M + i] = (i == j) + 0.2 * nh_rand() / sqrt((double)M);
  for (int i = 0; i < M; i++) {
    double pick = urand();
    laws[i] = law(i < NB ? NH_ROW_BILATERAL : NH_ROW_UNILATERAL);
    if (i < NB) {
      ls[i] = nh_rand(), ws[i] = 0.0;
    } else if (pick < 0.3) {
      ls[i] = 0.0, ws[i] = 0.2 + urand();
    } else if (pick < 0.45) {
      laws[i].threshold = 0.5, ls[i] = 0.5, ws[i] = -(0.2 + urand());
    } else {
      ls[i] = 0.2 + urand(), ws[i] = 0.0;
    }
  }
  for (int i = 0; i < M; i++) {
    long double v = ws[i];
    for (int j = 0; j < M; j++) v -= (long double)W[j * M + i] * ls[j];
    r[i] = (double)v;
  }
  nh_mcp_stats st;
  int rc = nh_mcp_solve_unsymmetric(M, W, r, laws, 1e-14, 5000, lam, &st);
  double e = 0.0;
  for (int i = 0; i < M; i++) e = fmax(e, fabs(lam[i] - ls[i]));
  CHECK(rc == NH_OK && st.sweeps > 0 && e <= 1e-10,
        "unsymmetric W, %d rows (sweeps): rc %d, %d sweeps, %d Newton steps, residual %g, "
        "max|lambda - lambda*| = %g > 1e-10",
        M, rc, st.sweeps, st.newton_steps, st.residual, e);
  free(W), free(r), free(ls), free(ws), free(lam), free(laws);
}

/* The proximal fallback (src/solve/mcp.c, header "Proximal fallback"):
 * ill-conditioned unilateral problems, W the Gaussian kernel exp(−|x_i −
 * x_j|²/ℓ²) + δ I of m random points x_i on the unit sphere (a smooth
 * compliance, its eigenvalues decaying as a surface Green's function's do),
 * with a known solution: λ* = 0.5 + 0.5 z on the rows with z > 0 (w* = 0),
 * λ* = 0 and w* = 0.1 − z on the others, r = w* − W λ*.
 *  a. m = 400, ℓ = 0.7, δ = 1e-10, a budget of 30 iterations: the sweeps
 *     stall and Newton from their iterate does not finish (main before the
 *     fallback: residual 2.4e-3, NH_ERR_NUMERIC); the fallback must solve
 *     it within its own 30, and w must be w* to the conditioning (W's
 *     smallest eigenvalues are near δ).
 *  b. m = 200, 300, 400 × ℓ = 0.3, 0.5, 0.7, 0.9 × δ = 1e-12, 1e-10,
 *     1e-8, a budget of 100: every one solved.
 *  c. the same 36 with a budget of 30: solved, or NH_ERR_NUMERIC with a
 *     finite best iterate whose residual is above the tolerance.
 * Solved means: residual ≤ 1e-10, λ ≥ 0, w ≥ 0 and min(λ, w) = 0 to the
 * tolerance (the laws' conditions, checked on W λ + r directly). */
static nh_mcp_stats proximal_case(int m, double ell, double delta, int budget, int must_solve,
                                  int fallback) {
  enum { MMAX = 400 };
  static double X[3 * MMAX], W[MMAX * MMAX], r[MMAX], ls[MMAX], ws[MMAX], lam[MMAX], w[MMAX];
  static nh_row_law laws[MMAX];
  const double tol = 1e-10;
  nh_test_rng = 88172645463325252ull; /* the points whatever ran before */
  for (int i = 0; i < m; i++) {
    double s = 0.0;
    for (int k = 0; k < 3; k++) X[3 * i + k] = nh_rand(), s += X[3 * i + k] * X[3 * i + k];
    for (int k = 0; k < 3; k++) X[3 * i + k] /= sqrt(s);
  }
  for (int j = 0; j < m; j++)
    for (int i = 0; i < m; i++) {
      double d2 = 0.0;
      for (int k = 0; k < 3; k++)
        d2 += (X[3 * i + k] - X[3 * j + k]) * (X[3 * i + k] - X[3 * j + k]);
      W[(size_t)j * m + i] = exp(-d2 / (ell * ell)) + (i == j ? delta : 0.0);
    }
  for (int i = 0; i < m; i++) {
    const double z = X[3 * i + 2];
    ls[i] = z > 0.0 ? 0.5 + 0.5 * z : 0.0;
    ws[i] = z > 0.0 ? 0.0 : 0.1 - z;
    laws[i] = law(NH_ROW_UNILATERAL), lam[i] = 0.0;
  }
  apply(m, W, ls, ws, r); /* W λ* + w* */
  for (int i = 0; i < m; i++) r[i] = ws[i] - (r[i] - ws[i]);
  nh_mcp_stats st;
  int rc = nh_mcp_solve(m, W, r, laws, tol, budget, lam, &st);
  if (rc) {
    int finite = 1;
    for (int i = 0; i < m; i++) finite &= isfinite(lam[i]);
    CHECK(!must_solve && rc == NH_ERR_NUMERIC && finite && st.residual > tol,
          "proximal m %d, ell %g, delta %g, budget %d: rc %d (%s), residual %.3g", m, ell, delta,
          budget, rc, nh_error_message(), st.residual);
    nh_error_clear();
    return st;
  }
  CHECK(st.residual <= tol && (!fallback || st.method == NH_MCP_FALLBACK),
        "proximal m %d, ell %g, delta %g, budget %d: %d Newton steps, %d sweeps, method %d, "
        "residual %.3g",
        m, ell, delta, budget, st.newton_steps, st.sweeps, (int)st.method, st.residual);
  apply(m, W, lam, r, w);
  double scale = 0.0, lmin = 0.0, wmin = 0.0, comp = 0.0, werr = 0.0;
  for (int i = 0; i < m; i++) {
    scale = fmax(scale, fabs(r[i]));
    lmin = fmin(lmin, lam[i]), wmin = fmin(wmin, w[i]);
    comp = fmax(comp, fabs(fmin(lam[i], w[i])));
    werr = fmax(werr, fabs(w[i] - ws[i]));
  }
  CHECK(lmin >= 0.0 && wmin >= -1e2 * tol * scale && comp <= 1e2 * tol * scale &&
            (!fallback || werr <= 1e-3 * scale),
        "proximal m %d, ell %g, delta %g, budget %d: min lambda %.3g, min w %.3g, |min(lambda, "
        "w)| %.3g, |w - w*| %.3g (scale %.3g)",
        m, ell, delta, budget, lmin, wmin, comp, werr, scale);
  return st;
}

static void test_proximal(void) {
  proximal_case(400, 0.7, 1e-10, 30, 1, 1);
  static const int ms[] = {200, 300, 400};
  static const double ells[] = {0.3, 0.5, 0.7, 0.9}, deltas[] = {1e-12, 1e-10, 1e-8};
  for (int budget = 100; budget >= 30; budget -= 70)
    for (int a = 0; a < 3; a++)
      for (int b = 0; b < 4; b++)
        for (int c = 0; c < 3; c++)
          proximal_case(ms[a], ells[b], deltas[c], budget, budget == 100, 0);
}

/* The Newton probes of a sweeps-first solve and the proximal fallback
 * after NH_MCP_PROX_AFTER = 100 sweeps (src/solve/mcp.c, nh_mcp_attempt,
 * nh_mcp_solve_any): the problems of test_proximal with m = 250 and 400
 * rows (above NH_MCP_EXACT_ROWS, so the sweeps go first), ℓ = 0.3 … 0.9,
 * δ = 1e-12 … 1e-6, a budget of 5000: all 32 solved (proximal_case's
 * checks), every one within 100 sweeps, and at least 24 by the first
 * probe (≤ 10 Newton steps). Measured: sweeps to the budget, then Newton
 * (main before session 19): none within 200 sweeps, 30 took all 5000, two
 * 677 and 686; now 25 by the probe (4-10 Newton steps), 7 by the fallback
 * (16-32 Newton steps in all). */
static void test_probes(void) {
  static const int ms[] = {250, 400};
  static const double ells[] = {0.3, 0.5, 0.7, 0.9}, deltas[] = {1e-12, 1e-10, 1e-8, 1e-6};
  int probe = 0, within = 0;
  for (int a = 0; a < 2; a++)
    for (int b = 0; b < 4; b++)
      for (int c = 0; c < 4; c++) {
        nh_mcp_stats st = proximal_case(ms[a], ells[b], deltas[c], 5000, 1, 0);
        within += st.residual <= 1e-10 && st.sweeps <= 100;
        probe += st.residual <= 1e-10 && st.sweeps <= 100 && st.newton_steps <= 10;
      }
  CHECK(within == 32 && probe >= 24,
        "sweeps first: %d of 32 problems solved within 100 sweeps (expected 32), %d of them by the "
        "first Newton probe (expected >= 24)",
        within, probe);
}

int main(void) {
  test_bilateral();
  test_unilateral();
  test_friction();
  test_stiffness_ratio();
  test_warm_start();
  test_disc();
  test_two_normals();
  test_static_kinetic();
  test_failures();
  test_known();
  test_unsymmetric();
  test_proximal();
  test_probes();
  TEST_END();
}
