/* test_dwr — the goal-oriented (dual-weighted residual) estimate of
 * adapt/dwr.c on the localized-load block of cases/adapt-localized.yaml
 * (4 x 2 x 2 cm, E 10 kPa, ν 0.3, clamped at x = 4 cm, 1 µN down over the
 * 2 mm cube centred at (1, 1, 1) cm), goal: the displacement at the probe
 * p = (2.5, 1.0, 1.5) cm, regularised over the box p ± 0.5 mm.
 *
 * The problem is linear: the corotational element at u = 0 is the
 * small-strain element, so A = K (assembled at rest) and u_h = K⁻¹ f.
 *
 *  1. The DWR identity (dwr.c header). V_h: the 8x4x4 grid with three cells
 *     refined (hanging nodes); V_f ⊃ V_h: every leaf refined once more.
 *     With u_f, z_f the primal and dual Galerkin solutions in V_f and P u_h
 *     the coarse solution carried to V_f by Eq. 17 (exact for nested
 *     spaces),
 *       J(u_f) − J(u_h) = f(z_f) − a(P u_h, z_f),
 *     an algebraic identity of the Galerkin equations, so it holds to
 *     round-off (asserted 1e-9 relative, per component). The two sides are
 *     computed on different paths: the left from the solves (through
 *     nh_dwr_duals' gather/solve/scatter for z_f), the right with a(·,·)
 *     summed element by element from the tissue's K₀ (nh_tissue_element),
 *     not from the assembled matrix. Also asserted: J(P u_h) computed on V_f
 *     equals J(u_h) on V_h (the functional is the same on both meshes, the
 *     premise of the identity), and Galerkin orthogonality of the coarse
 *     dual, f(P z_h) − a(P u_h, P z_h) = 0 (relative to f(P z_h)).
 *     A wrong scale of the dual, a gather instead of a scatter, or a
 *     functional that depends on the mesh break these by O(1).
 *  2. Effectivity. Goal-adaptive refinement from 8x4x4 (hex2, marking max
 *     θ = 0.3 on the goal indicators η_K^p, up to level 4) for STEPS
 *     meshes. The true error of the three finest adaptive meshes M is
 *     measured against a converged reference: the finest mesh refined
 *     uniformly by the 2x2x2 and by the 3x3x3 template (spaces with the same
 *     grading, h/2 and h/3 everywhere) give with the finest mesh itself
 *     three values J(h), J(h/2), J(h/3) of the dominant component (z);
 *     their observed order p = log((J₁ − J₂)/(J₂ − J₃)) / log(·) (solved
 *     for unequal ratios by bisection) must lie in [1.5, 3] (O(h²) expected
 *     for a functional of a trilinear solution), and the Richardson value
 *     J_∞ = J₃ + (J₃ − J₂) / ((3/2)^p − 1) is the reference. The reference's
 *     own uncertainty |J_∞ − J₃| is asserted below 1/5 of the smallest true
 *     error it measures. Effectivity θ = |E_p| / |J(u) − J(u_h)| with the
 *     vector error (the x, y components from the h/3 mesh, which are two
 *     orders smaller than z); asserted θ ∈ [0.7, 1.5] on the three finest
 *     adaptive meshes (the band). Run with the fully integrated
 *     element and again with B-bar (the scene's default), whose estimate
 *     carries the mean-dilatation method's own terms (dwr.c, "B-bar"):
 *     without them it overestimates about twofold on this block.
 *  3. The tip–target distance (dwr.c "Distance"): a tool tip held 5 mm from
 *     the probe along the DBS case's trajectory, reversed (the unit vector
 *     (0.211, 0.529, 0.822): the tool comes from above), and
 *     D(v) = |tip − (p + J(v))|. In the identity of 1, with n_h the unit
 *     vector from p + J(u_h) to the tip and z_D the fine dual of
 *     nh_goal_distance_functional(n_h), D(u_f) − D(u_h) = ρ(u_h; z_D) up to
 *     the linearisation of the norm, whose remainder is at most
 *     |J(u_f) − J(u_h)|² / D(u_h) (asserted with that bound added to the
 *     round-off tolerance; the left side from the distances, the right from
 *     the residual). In 2, the effectivity |E_D| / |D_ref − D_h| of
 *     nh_dwr_distance_estimate on the three finest meshes, D_ref from the
 *     reference vector of 2, in the same band [0.7, 1.5].
 *  4. The energy product of the estimate is the tangent's: for one distorted
 *     cell at a rotated and stretched state u, and increments v, w,
 *     Σ_gauss det J σ(v)ᵀ D⁻¹ σ(w) with the stresses dwr.c forms
 *     (nh_hex_rotated_stress of Rᵀv; B-bar: θ̄(v) = Σ bₐ·vₐ) equals vᵀ Kt w
 *     with Kt of nh_hex_corot (full and B-bar, ν = 0.49), to 1e-10
 *     relative: the two are assembled on different paths (Gauss-point
 *     stresses and the compliance against the element matrix). Without the
 *     B-bar term the product differs by O(1) at ν = 0.49.
 *  5. The goals' functionals kept between estimates (nh_goal_cache): on the
 *     8x4x4 grid, with cell A (one of the 8 the probe's box touches)
 *     refined, with A coarsened and its neighbour B (another of the 8)
 *     refined (nodes, cells and leaves as many as with A refined, the new
 *     nodes in the box elsewhere, so the functionals the cache holds are
 *     another mesh's), and B coarsened back to the grid: estimates, norms
 *     and indicators with the cache bitwise equal to those made afresh
 *     (nh_dwr_estimate without it), the functionals made again exactly at
 *     each mesh change and at a new radius, not at a second estimate on
 *     the same mesh; the combined estimate likewise.
 * NH_VERBOSE=1 prints the sequence. */
#include "check.h"
#include "adapt/adapt.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "dwr_support.h"
#include "hanging_mesh.h"

#define STEPS     4
#define MAX_LEVEL 4
#define RADIUS    5e-4

static const double probe[3] = {0.025, 0.010, 0.015};
/* A tool tip 5 mm from the probe along (0.211, 0.529, 0.822) (normalised). */
static void tool_tip(double tip[3]) {
  const double d[3] = {0.211, 0.529, 0.822};
  double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  for (int k = 0; k < 3; k++) tip[k] = probe[k] + 0.005 * d[k] / len;
}

/* D = |tip − (p + J)| for the box means J[3] of a solution; n (may be NULL):
 * the unit vector from p + J to the tip. */
static double distance(const double J[3], double n[3]) {
  double tip[3], d[3];
  tool_tip(tip);
  for (int k = 0; k < 3; k++) d[k] = tip[k] - probe[k] - J[k];
  double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  for (int k = 0; n && k < 3; k++) n[k] = d[k] / len;
  return len;
}
static const double lo[3] = {0, 0, 0}, hi[3] = {0.04, 0.02, 0.02};
static const int grid[3] = {8, 4, 4};

/* The element of the problems built (part 2 runs with both). */
static nh_formulation formulation = NH_FORMULATION_FULL;

typedef struct {
  nh_mesh *m;
  nh_tissue *t;
  unsigned char *fixed;
  nh_hanging *h;
  nh_system *s;
  double *f, *u, *j; /* load, solution, the goal's 3 functionals (3 n each) */
} problem;

static void setup(problem *p) {
  nh_mesh *m = p->m;
  int n = 3 * m->n_nodes;
  if (!p->t) {
    nh_material mat = {1.0e4, 0.3, 1000, formulation};
    CHECK_OK(nh_tissue_create(m, &mat, &p->t));
  } else {
    CHECK_OK(nh_tissue_update(p->t));
  }
  p->fixed = realloc(p->fixed, m->n_nodes);
  for (int i = 0; i < m->n_nodes; i++) p->fixed[i] = m->X[3 * i] > 0.0399;
  nh_hanging_destroy(&p->h);
  CHECK_OK(nh_hanging_detect(m, p->fixed, &p->h));
  nh_system_destroy(&p->s);
  CHECK_OK(nh_system_create(p->t, p->fixed, p->h, &p->s));
  p->f = realloc(p->f, sizeof(double) * n);
  p->u = realloc(p->u, sizeof(double) * n);
  p->j = realloc(p->j, sizeof(double) * 3 * n);
  CHECK_OK(dwr_block_load(m, p->f));
  for (int k = 0; k < 3; k++)
    CHECK_OK(nh_goal_functional(m, probe, RADIUS, k, "probe", p->j + (size_t)n * k));
}

/* u = K⁻¹ f (A = K assembled at rest). */
static void solve(problem *p) {
  int n = 3 * p->m->n_nodes, nf = nh_system_free_dofs(p->s);
  double *w = calloc(n, sizeof(double)), *b = malloc(sizeof(double) * nf);
  double *x = malloc(sizeof(double) * nf);
  nh_system_assemble(p->s, w, NULL, 0.0, 1.0, w, NULL, 0);
  CHECK_OK(nh_system_factor(p->s));
  nh_system_gather(p->s, p->f, b);
  CHECK_OK(nh_system_solve(p->s, b, x));
  nh_system_scatter(p->s, x, p->u);
  free(w), free(b), free(x);
}

static void destroy(problem *p) {
  nh_system_destroy(&p->s);
  nh_hanging_destroy(&p->h);
  nh_tissue_destroy(&p->t);
  nh_mesh_destroy(&p->m);
  free(p->fixed), free(p->f), free(p->u), free(p->j);
}

static void test_identity(void) {
  problem p = {0};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &p.m));
  nh_template *t2 = regular_template(2);
  int first[3] = {1 + 8 * (1 + 4 * 1), 2 + 8 * (1 + 4 * 2), 4 + 8 * (2 + 4 * 2)};
  CHECK_OK(nh_mesh_refine(p.m, t2, first, 3, NULL));
  setup(&p);
  solve(&p);
  int nc = p.m->n_nodes, n = 3 * nc;
  double Jh[3], *uh = malloc(sizeof(double) * n), *zh = malloc(sizeof(double) * 3 * n);
  for (int k = 0; k < 3; k++) Jh[k] = dwr_dot(n, p.j + (size_t)n * k, p.u);
  memcpy(uh, p.u, sizeof(double) * n);
  CHECK_OK(nh_dwr_duals(p.s, NULL, 1.0, nc, 3, p.j, zh, NULL, NULL));

  /* V_f: every leaf refined once. */
  nh_refine_info info = {0};
  int nl = p.m->n_leaves, *all = malloc(sizeof(int) * nl);
  memcpy(all, p.m->leaves, sizeof(int) * nl);
  CHECK_OK(nh_mesh_refine(p.m, t2, all, nl, &info));
  double *Puh = dwr_prolong(p.m, &info, uh, nc);
  setup(&p);
  nh_hanging_interpolate(p.h, Puh, 3);
  solve(&p);
  int nfn = 3 * p.m->n_nodes;
  double *zf = malloc(sizeof(double) * 3 * nfn);
  CHECK_OK(nh_dwr_duals(p.s, NULL, 1.0, p.m->n_nodes, 3, p.j, zf, NULL, NULL));
  for (int k = 0; k < 3; k++) {
    const double *jk = p.j + (size_t)nfn * k, *zk = zf + (size_t)nfn * k;
    double JPuh = dwr_dot(nfn, jk, Puh), Juf = dwr_dot(nfn, jk, p.u);
    double lhs = Juf - Jh[k], rhs = dwr_dot(nfn, p.f, zk) - dwr_energy_product(p.m, p.t, Puh, zk);
    double scale = fmax(fabs(Juf), fabs(Jh[k]));
    CHECK_CLOSE(JPuh, Jh[k], 1e-12 * scale, "J(P u_h) on V_f = J(u_h) on V_h");
    CHECK_CLOSE(rhs, lhs, 1e-9 * fabs(lhs), "DWR identity J(u_f) - J(u_h) = rho(u_h; z_f)");
    double *Pzh = dwr_prolong(p.m, &info, zh + (size_t)n * k, nc);
    nh_hanging_interpolate(p.h, Pzh, 3);
    double fz = dwr_dot(nfn, p.f, Pzh), orth = fz - dwr_energy_product(p.m, p.t, Puh, Pzh);
    CHECK_CLOSE(orth, 0.0, 1e-8 * fabs(fz), "Galerkin orthogonality rho(u_h; P z_h) = 0");
    if (getenv("NH_VERBOSE"))
      printf("identity k=%d: J(u_f)-J(u_h) = %.6e, rho(z_f) = %.6e, rel diff %.1e\n", k, lhs, rhs,
             fabs(lhs - rhs) / fabs(lhs));
    free(Pzh);
  }
  /* The distance functional: its fine dual and the identity up to the
   * linearisation's remainder. */
  double nh_[3], Jf[3], e2 = 0.0;
  double Dh = distance(Jh, nh_);
  for (int k = 0; k < 3; k++) {
    Jf[k] = dwr_dot(nfn, p.j + (size_t)nfn * k, p.u);
    e2 += (Jf[k] - Jh[k]) * (Jf[k] - Jh[k]);
  }
  double *jD = malloc(sizeof(double) * nfn), *zD = malloc(sizeof(double) * nfn);
  CHECK_OK(nh_goal_distance_functional(p.m, probe, nh_, RADIUS, "probe", jD));
  CHECK_OK(nh_dwr_duals(p.s, NULL, 1.0, p.m->n_nodes, 1, jD, zD, NULL, NULL));
  double lhs = distance(Jf, NULL) - Dh,
         rhs = dwr_dot(nfn, p.f, zD) - dwr_energy_product(p.m, p.t, Puh, zD);
  CHECK_CLOSE(rhs, lhs, 1e-9 * fabs(lhs) + e2 / Dh,
              "distance: D(u_f) - D(u_h) = rho(u_h; z_D) + O(|e|^2 / D)");
  if (getenv("NH_VERBOSE"))
    printf("identity distance: D(u_f)-D(u_h) = %.6e, rho(z_D) = %.6e, rel diff %.1e (bound %.1e)\n",
           lhs, rhs, fabs(lhs - rhs) / fabs(lhs), (1e-9 * fabs(lhs) + e2 / Dh) / fabs(lhs));
  free(jD), free(zD);
  nh_refine_info_free(&info);
  free(all), free(uh), free(zh), free(Puh), free(zf);
  nh_template_destroy(&t2);
  destroy(&p);
}

/* The goal-adaptive sequence: per mesh its dofs, J_h (3) and the estimate (3);
 * leaves p on the finest mesh (solved). */
static int adapt_sequence(problem *p, int *dofs, double (*Jh)[3], double (*E)[3]) {
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &p->m));
  nh_template *t2 = regular_template(2);
  int steps = 0;
  for (;;) {
    setup(p);
    solve(p);
    int n = 3 * p->m->n_nodes, ncell = p->m->n_cells;
    double est[3], norm, *ind = malloc(sizeof(double) * ncell);
    nh_dwr_result r = {.estimate = est, .norm = &norm, .indicator = ind};
    CHECK_OK(nh_dwr_estimate(p->s, NULL, 1.0, p->m, p->t, p->h, p->u, 1, probe, RADIUS, NULL, &r));
    dofs[steps] = n;
    for (int k = 0; k < 3; k++)
      Jh[steps][k] = dwr_dot(n, p->j + (size_t)n * k, p->u), E[steps][k] = est[k];
    if (getenv("NH_VERBOSE"))
      printf("adaptive mesh %d: %d dofs, %d leaves, estimate %.3e\n", steps, n, p->m->n_leaves,
             norm);
    steps++;
    if (steps == STEPS) {
      free(ind);
      break;
    }
    nh_mark_params mp = {.strategy = NH_MARK_MAX, .theta = 0.3, .max_level = MAX_LEVEL};
    int *marked = malloc(sizeof(int) * p->m->n_leaves), n_marked = 0;
    CHECK_OK(nh_mark_cells(p->m, ind, &mp, marked, &n_marked));
    CHECK_OK(nh_mesh_refine(p->m, t2, marked, n_marked, NULL));
    free(marked), free(ind);
  }
  nh_template_destroy(&t2);
  return steps;
}

/* J (3 components) on the finest adaptive mesh with every leaf refined by the n x n x n template.
 */
static void refined_reference(int n, double J[3]) {
  problem p = {0};
  int dofs[STEPS];
  double Jh[STEPS][3], E[STEPS][3];
  adapt_sequence(&p, dofs, Jh, E);
  nh_template *tn = regular_template(n);
  int nl = p.m->n_leaves, *all = malloc(sizeof(int) * nl);
  memcpy(all, p.m->leaves, sizeof(int) * nl);
  CHECK_OK(nh_mesh_refine(p.m, tn, all, nl, NULL));
  setup(&p);
  solve(&p);
  int nn = 3 * p.m->n_nodes;
  for (int k = 0; k < 3; k++) J[k] = dwr_dot(nn, p.j + (size_t)nn * k, p.u);
  if (getenv("NH_VERBOSE"))
    printf("finest mesh refined by %d: %d dofs, J = %.9e %.9e %.9e\n", n, nn, J[0], J[1], J[2]);
  free(all);
  nh_template_destroy(&tn);
  destroy(&p);
}

static void test_effectivity(void) {
  problem p = {0};
  int dofs[STEPS];
  double Jh[STEPS][3], E[STEPS][3];
  int steps = adapt_sequence(&p, dofs, Jh, E);
  destroy(&p);
  double J1 = Jh[steps - 1][2], J2[3], J3[3];
  refined_reference(2, J2);
  refined_reference(3, J3);
  /* Observed order from h, h/2, h/3: (J1 − J2)/(J2 − J3) = (1 − 2^-p)/(2^-p − 3^-p). */
  double ratio = (J1 - J2[2]) / (J2[2] - J3[2]), a = 0.5, b = 6.0;
  for (int it = 0; it < 200; it++) {
    double c = 0.5 * (a + b), g = (1 - pow(2, -c)) / (pow(2, -c) - pow(3, -c));
    if (g < ratio)
      a = c; /* g grows with p */
    else
      b = c;
  }
  double order = 0.5 * (a + b);
  double Jinf = J3[2] + (J3[2] - J2[2]) / (pow(1.5, order) - 1.0);
  CHECK(order >= 1.5 && order <= 3.0, "observed order of J on h, h/2, h/3: %.3f not in [1.5, 3]",
        order);
  double smallest = INFINITY;
  for (int s = steps - 3; s < steps; s++) smallest = fmin(smallest, fabs(Jinf - Jh[s][2]));
  CHECK(fabs(Jinf - J3[2]) <= 0.2 * smallest,
        "reference uncertainty |J_inf - J(h/3)| = %.3e above 1/5 of the smallest true error %.3e",
        fabs(Jinf - J3[2]), smallest);
  if (getenv("NH_VERBOSE"))
    printf("order %.3f, J_inf %.9e (|J_inf - J(h/3)| = %.3e)\n", order, Jinf, fabs(Jinf - J3[2]));
  /* The distance: reference from the reference vector (x, y from h/3, z
   * extrapolated); its uncertainty is that of J_inf along n. */
  double Jref[3] = {J3[0], J3[1], Jinf}, tip[3], nref[3];
  tool_tip(tip);
  double Dref = distance(Jref, nref);
  for (int s = steps - 3; s < steps; s++) {
    double x[3] = {probe[0] + Jh[s][0], probe[1] + Jh[s][1], probe[2] + Jh[s][2]};
    double err = Dref - distance(Jh[s], NULL), est = nh_dwr_distance_estimate(E[s], x, tip);
    double theta = fabs(est) / fabs(err);
    if (getenv("NH_VERBOSE"))
      printf("mesh %d: distance error %.3e, estimate %.3e, effectivity %.3f\n", s, err, est, theta);
    CHECK(fabs(nref[2] * (Jinf - J3[2])) <= 0.2 * fabs(err),
          "distance: reference uncertainty %.3e above 1/5 of the error %.3e on mesh %d",
          fabs(nref[2] * (Jinf - J3[2])), fabs(err), s);
    CHECK(theta >= 0.7 && theta <= 1.5,
          "distance effectivity on adaptive mesh %d (%d dofs): expected [0.7, 1.5], got %.3f "
          "(estimate %.3e, error %.3e)",
          s, dofs[s], theta, est, err);
  }
  for (int s = 0; s < steps; s++) {
    double e[3] = {J3[0] - Jh[s][0], J3[1] - Jh[s][1], Jinf - Jh[s][2]};
    double en = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    double En = sqrt(E[s][0] * E[s][0] + E[s][1] * E[s][1] + E[s][2] * E[s][2]);
    double theta = En / en;
    if (getenv("NH_VERBOSE"))
      printf("mesh %d: %6d dofs, J_z %.6e, error %.3e, estimate %.3e (z: %.3e), effectivity %.3f\n",
             s, dofs[s], Jh[s][2], en, En, E[s][2], theta);
    if (s >= steps - 3)
      CHECK(theta >= 0.7 && theta <= 1.5,
            "effectivity on adaptive mesh %d (%d dofs): expected [0.7, 1.5], got %.3f "
            "(estimate %.3e, error %.3e)",
            s, dofs[s], theta, En, en);
  }
}

static double tangent_product(const double X[24], const double u[24], const double v[24],
                              const double w[24], int bbar, int with_volumetric) {
  const double young = 2509.0, nu = 0.49;
  const double lambda = young * nu / ((1 + nu) * (1 - 2 * nu)), mu = young / (2 * (1 + nu));
  double K0[576], G0[24], Gbar[24], V, R[9], d[24], dv[24], dw[24], b[24], cof[9];
  CHECK_OK(nh_hex_stiffness(X, lambda, mu, bbar, K0, G0, Gbar, &V));
  nh_hex_corotated(X, u, G0, R, d);
  nh_hex_mean_dilatation(u, Gbar, cof);
  for (int a = 0; a < 8; a++) nh_mat3_vec(cof, Gbar + 3 * a, b + 3 * a);
  double tv = 0.0, tw = 0.0;
  for (int i = 0; i < 24; i++) tv += b[i] * v[i], tw += b[i] * w[i];
  for (int a = 0; a < 8; a++)
    nh_mat3_tvec(R, v + 3 * a, dv + 3 * a), nh_mat3_tvec(R, w + 3 * a, dw + 3 * a);
  double sum = 0.0;
  for (int gp = 0; gp < 8; gp++) {
    double xi[3], g[24], sv[6], sw[6], e[6];
    for (int k = 0; k < 3; k++) xi[k] = nh_hex_corner[gp][k] / sqrt(3.0);
    memcpy(g, G0, sizeof g);
    double detJ = nh_hex_gradients(X, xi, g);
    const int vol = bbar && with_volumetric;
    nh_hex_rotated_stress(R, dv, g, lambda, mu, vol ? &tv : NULL, sv);
    nh_hex_rotated_stress(R, dw, g, lambda, mu, vol ? &tw : NULL, sw);
    nh_voigt_compliance(lambda, mu, sw, e);
    for (int k = 0; k < 6; k++) sum += detJ * sv[k] * e[k];
  }
  return sum;
}

static void test_tangent_product(void) {
  double X[24], u[24], v[24], w[24];
  unsigned seed = 12345;
  for (int a = 0; a < 8; a++) /* a distorted 1 cm cell */
    for (int k = 0; k < 3; k++) {
      seed = seed * 1103515245u + 12345u;
      X[3 * a + k] = 0.01 * (nh_hex_corner[a][k] > 0) + 1e-3 * ((seed >> 16) % 1000 / 1000.0 - 0.5);
    }
  const double th = 0.4, c = cos(th), s = sin(th); /* rotation about z, 2 % stretch along x */
  for (int a = 0; a < 8; a++) {
    const double *x = X + 3 * a;
    u[3 * a] = c * 1.02 * x[0] - s * x[1] - x[0];
    u[3 * a + 1] = s * 1.02 * x[0] + c * x[1] - x[1];
    u[3 * a + 2] = 0.0;
    for (int k = 0; k < 3; k++) {
      seed = seed * 1103515245u + 12345u;
      v[3 * a + k] = 1e-4 * ((seed >> 16) % 1000 / 1000.0 - 0.5);
      seed = seed * 1103515245u + 12345u;
      w[3 * a + k] = 1e-4 * ((seed >> 16) % 1000 / 1000.0 - 0.5);
    }
  }
  for (int bbar = 0; bbar < 2; bbar++) {
    const double young = 2509.0, nu = 0.49;
    const double lambda = young * nu / ((1 + nu) * (1 - 2 * nu)), mu = young / (2 * (1 + nu));
    double K0[576], G0[24], Gbar[24], V, R[9], f[24], Kt[576];
    CHECK_OK(nh_hex_stiffness(X, lambda, mu, bbar, K0, G0, Gbar, &V));
    nh_hex_volumetric vol = {Gbar, lambda + 2.0 * mu / 3.0, V};
    nh_hex_corot(X, u, K0, G0, bbar ? &vol : NULL, R, f, Kt);
    double ref = 0.0;
    for (int r = 0; r < 24; r++)
      for (int q = 0; q < 24; q++) ref += v[r] * Kt[24 * r + q] * w[q];
    double got = tangent_product(X, u, v, w, bbar, 1);
    CHECK_CLOSE(got, ref, 1e-10 * fabs(ref), "energy product of the estimate's stresses = v Kt w");
    if (bbar) {
      double without = tangent_product(X, u, v, w, bbar, 0);
      CHECK(fabs(without - ref) > 0.1 * fabs(ref),
            "B-bar: the product without the volumetric term should differ (%.3e vs %.3e)", without,
            ref);
    }
    if (getenv("NH_VERBOSE"))
      printf("tangent product (%s): %.9e against v Kt w %.9e\n", bbar ? "bbar" : "full", got, ref);
  }
}

/* Part 5: one mesh's estimates with and without the cache, bitwise, twice;
 * builds: the cache's count expected after them. */
static void check_functionals_cache(problem *p, nh_goal_cache *k, double radius, int builds,
                                    const char *what) {
  setup(p);
  solve(p);
  const int nc = p->m->n_cells;
  const double w[3] = {0.3, -0.5, 0.81};
  double est[2][3], norm[2], ec[2],
      *ind[2] = {calloc(nc, sizeof(double)), calloc(nc, sizeof(double))};
  for (int pass = 0; pass < 2; pass++) {
    nh_dwr_result r = {.estimate = est[0], .norm = norm, .indicator = ind[0]};
    CHECK_OK(nh_dwr_estimate(p->s, NULL, 1.0, p->m, p->t, p->h, p->u, 1, probe, radius, NULL, &r));
    r = (nh_dwr_result){
        .estimate = est[1], .norm = norm + 1, .indicator = ind[1], .functionals = k};
    CHECK_OK(nh_dwr_estimate(p->s, NULL, 1.0, p->m, p->t, p->h, p->u, 1, probe, radius, NULL, &r));
    CHECK(!memcmp(est[0], est[1], sizeof est[0]) && norm[0] == norm[1] &&
              !memcmp(ind[0], ind[1], sizeof(double) * nc),
          "%s, pass %d: cached estimate (%.17g %.17g %.17g) differs from the fresh one (%.17g "
          "%.17g %.17g)",
          what, pass, est[1][0], est[1][1], est[1][2], est[0][0], est[0][1], est[0][2]);
    for (int c = 0; c < 2; c++) {
      r = (nh_dwr_result){.estimate = ec + c, .functionals = c ? k : NULL};
      CHECK_OK(nh_dwr_estimate_combined(p->s, NULL, 1.0, p->m, p->t, p->h, p->u, 1, probe, radius,
                                        NULL, w, &r));
    }
    CHECK(ec[0] == ec[1], "%s, pass %d: cached combined estimate %.17g, fresh %.17g", what, pass,
          ec[1], ec[0]);
    CHECK(nh_goal_cache_builds(k) == builds, "%s: the functionals were made %d times, expected %d",
          what, nh_goal_cache_builds(k), builds);
  }
  if (getenv("NH_VERBOSE"))
    printf("functionals' cache, %s: %d leaves, estimate %.6e, equal to the fresh one\n", what,
           p->m->n_leaves, norm[1]);
  free(ind[0]), free(ind[1]);
}

static void test_functionals_cache(void) {
  problem p = {0};
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &p.m));
  nh_template *t2 = regular_template(2);
  nh_goal_cache *k;
  CHECK_OK(nh_goal_cache_create(&k));
  check_functionals_cache(&p, k, RADIUS, 1, "the grid");
  check_functionals_cache(&p, k, 0.8 * RADIUS, 2, "the grid, another radius");
  /* cells (4,1,2) and (5,1,2): x 20-25 and 25-30 mm, y 5-10, z 10-15 mm,
   * both touching the box (25, 10, 15) mm +- 0.5 mm */
  int A = 4 + 8 * (1 + 4 * 2), B = A + 1;
  CHECK_OK(nh_mesh_refine(p.m, t2, &A, 1, NULL));
  check_functionals_cache(&p, k, RADIUS, 3, "A refined");
  const int counts[3] = {p.m->n_nodes, p.m->n_cells, p.m->n_leaves};
  int *map = malloc(sizeof(int) * p.m->n_nodes);
  CHECK_OK(nh_mesh_coarsen(p.m, &A, 1, map));
  CHECK_OK(nh_mesh_refine(p.m, t2, &B, 1, NULL));
  CHECK(p.m->n_nodes == counts[0] && p.m->n_cells == counts[1] && p.m->n_leaves == counts[2],
        "B refined: %d nodes, %d cells, %d leaves; A refined had %d, %d, %d (the test needs "
        "equal counts)",
        p.m->n_nodes, p.m->n_cells, p.m->n_leaves, counts[0], counts[1], counts[2]);
  check_functionals_cache(&p, k, RADIUS, 4, "A coarsened, B refined");
  CHECK_OK(nh_mesh_coarsen(p.m, &B, 1, map));
  check_functionals_cache(&p, k, RADIUS, 5, "B coarsened: the grid again");
  nh_goal_cache_destroy(&k);
  CHECK(k == NULL, "nh_goal_cache_destroy leaves the pointer set");
  free(map);
  nh_template_destroy(&t2);
  destroy(&p);
}

int main(void) {
  setvbuf(stdout, NULL, _IOLBF, 0);
  test_functionals_cache();
  test_tangent_product();
  test_identity();
  test_effectivity();
  formulation = NH_FORMULATION_BBAR;
  if (getenv("NH_VERBOSE")) printf("B-bar:\n");
  test_effectivity();
  TEST_END();
}
