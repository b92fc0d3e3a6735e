/* test_fcm — cut cells integrated by the finite cell quadrature in the
 * tissue (src/fem/tissue.c, docs/theory.md §5c).
 *  1. Immersed patch test: on an immersed ball (analytic and as an STL-free
 *     label-free shape: the analytic brain, no symmetry) on a sequence of
 *     grids (odd and even: the ball's centre at a cell centre and at a node),
 *     the linear field u = −p (X − c) / (3K) (K = λ + ⅔μ) is in equilibrium
 *     with the consistent load of the uniform pressure p on the immersed
 *     surface: the residual f_int(u) − f_p, relative to |f_p|, is round-off
 *     (<= 1e-9) with α = 0. Expected value: the divergence theorem on the
 *     reconstructed polyhedron (stiffness exact for Q2, load exact for
 *     cubics on its faces).
 *  2. The consistency error of the stabilisation is O(α): the residual at
 *     α = 1e-4 and 1e-6 divided by α is the same to 10 % (and nonzero).
 *  3. The pressure of the closed surface has zero net force and torque
 *     (Σ f_a, Σ X_a × f_a, relative to p A and p A R) to 1e-12.
 *  4. A sphere region of radius 0.25 of a cell (smaller than a cell on every
 *     grid) ties a ball under gravity: the tangent with the tie is positive
 *     definite (dense Cholesky) and the tie's reaction Σ_a T_ab u_b equals
 *     the weight Σ_a m_a g to 1e-8 (equilibrium: Σ of internal forces is 0).
 *     The same with a region of fixed radius a = 8 mm centred on the ball's
 *     surface (R = 30 mm; docs/dbs.md's optic-nerve caps), smaller than a
 *     cell on the coarse grids of the sequence 4, 5, 7, 9: the tied
 *     volume is that of the lens ball ∩ region in closed form,
 *     V = π (R + a − d)² (d² + 2da − 3a² + 2dR + 6aR − 3R²) / (12 d), d = R,
 *     to 5 % (the bound of the region's own lattice, as for the h/4 ball),
 *     and the reaction is the weight to 1e-8 on every grid.
 *  5. Mass: Σ m_a = ρ × the quadrature's volume of the ball, which is
 *     within the reconstruction bound of 4πR³/3 (order 2, test_cutcell). */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"

#include <string.h>

static int verbose;

/* f_int(u) over all leaves. */
static void internal_force(const nh_tissue *t, const double *u, double *f) {
  const nh_mesh *m = t->mesh;
  memset(f, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], frame[NH_HEX_FRAME];
    nh_tissue_element_force(t, c, u, fe, frame);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) f[3 * m->cells[8 * c + a] + k] += fe[3 * a + k];
  }
}

static double max_abs(const double *v, int n) {
  double r = 0.0;
  for (int i = 0; i < n; i++) r = fmax(r, fabs(v[i]));
  return r;
}

/* Residual of the patch test at stabilisation alpha, relative to |f_p|. */
static double patch(const nh_domain *d, int g, double alpha, double *force, double *torque) {
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  const int grid[3] = {g, g, g};
  CHECK_OK(nh_mesh_create(d, grid, &m));
  nh_material mat = {3000.0, 0.45, 1000.0, NH_FORMULATION_BBAR};
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  CHECK_OK(nh_tissue_set_stabilisation(t, alpha));
  const int n = 3 * m->n_nodes;
  double *u = calloc((size_t)n, sizeof(double)), *fi = calloc((size_t)n, sizeof(double)),
         *fp = calloc((size_t)n, sizeof(double));
  const double p = 1e-6; /* strain 1e-10: the corotational and det F̄ nonlinearity below round-off */
  nh_traction tr;
  memset(&tr, 0, sizeof tr);
  tr.region.kind = NH_REGION_BOX;
  for (int k = 0; k < 3; k++) tr.region.min[k] = -1.0, tr.region.max[k] = 1.0;
  tr.is_pressure = 1, tr.pressure = p;
  double area = 0.0;
  CHECK_OK(nh_traction_load(m, &tr, fp, &area));
  const double K = t->lambda + 2.0 * t->mu / 3.0;
  for (int i = 0; i < m->n_nodes; i++)
    for (int k = 0; k < 3; k++) u[3 * i + k] = -p * (m->X[3 * i + k] - d->center[k]) / (3.0 * K);
  internal_force(t, u, fi);
  double F[3] = {0, 0, 0}, T[3] = {0, 0, 0}, R = d->half[0];
  for (int i = 0; i < m->n_nodes; i++) {
    const double *x = m->X + 3 * i, *f = fp + 3 * i;
    double r[3] = {x[0] - d->center[0], x[1] - d->center[1], x[2] - d->center[2]};
    for (int k = 0; k < 3; k++) F[k] += f[k];
    T[0] += r[1] * f[2] - r[2] * f[1], T[1] += r[2] * f[0] - r[0] * f[2],
        T[2] += r[0] * f[1] - r[1] * f[0];
  }
  *force = max_abs(F, 3) / (p * area), *torque = max_abs(T, 3) / (p * area * R);
  for (int i = 0; i < n; i++) fi[i] -= fp[i];
  double res = max_abs(fi, n) / max_abs(fp, n);
  free(u), free(fi), free(fp);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
  return res;
}

/* Dense Cholesky in place (lower); 0 if positive definite. */
static int cholesky(double *A, int n) {
  for (int j = 0; j < n; j++) {
    double s = A[(size_t)j * n + j];
    for (int k = 0; k < j; k++) s -= A[(size_t)j * n + k] * A[(size_t)j * n + k];
    if (!(s > 0.0)) return 1;
    A[(size_t)j * n + j] = sqrt(s);
    for (int i = j + 1; i < n; i++) {
      double v = A[(size_t)i * n + j];
      for (int k = 0; k < j; k++) v -= A[(size_t)i * n + k] * A[(size_t)j * n + k];
      A[(size_t)i * n + j] = v / A[(size_t)j * n + j];
    }
  }
  return 0;
}

/* The ball of radius R at c0 on g³ cells, tied by a sphere region and
 * loaded by gravity. radius > 0: the region's radius (fixed), centred on
 * the ball's surface along a skew direction, its tied volume against the
 * lens; radius 0: a quarter of a cell, 0.31 h above c0, against 4πr³/3. */
static void tie_test(int g, double radius) {
  const double c0[3] = {0.0013, -0.0021, 0.0007}, R = 0.03;
  nh_domain d;
  nh_domain_sphere(c0, R, &d);
  d.cut_cells = NH_CUT_CELLS_INTEGRATED;
  nh_mesh *m = NULL;
  nh_tissue *t = NULL;
  const int grid[3] = {g, g, g};
  CHECK_OK(nh_mesh_create(&d, grid, &m));
  nh_material mat = {3000.0, 0.45, 1000.0, NH_FORMULATION_BBAR};
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  const double h = 2.0 * R / g;
  nh_region r;
  memset(&r, 0, sizeof r);
  r.kind = NH_REGION_SPHERE;
  double expect;
  if (radius > 0.0) {
    const double n[3] = {0.36, -0.48, 0.8}; /* a unit vector: the region on the surface */
    for (int k = 0; k < 3; k++) r.center[k] = c0[k] + R * n[k];
    r.radius = radius;
    const double a = radius, d = R;
    expect = M_PI * (R + a - d) * (R + a - d) *
             (d * d + 2 * d * a - 3 * a * a + 2 * d * R + 6 * a * R - 3 * R * R) / (12 * d);
  } else {
    for (int k = 0; k < 3; k++)
      r.center[k] = c0[k] + (k == 2 ? 0.31 * h : 0.0); /* above c: no torque */
    r.radius = 0.25 * h;
    expect = 4.0 / 3.0 * M_PI * pow(r.radius, 3);
  }
  const double kt = 1e9;
  double vol = 0.0;
  CHECK_OK(nh_tissue_set_ties(t, 1, &r, &kt, &vol));
  CHECK_CLOSE(vol, expect, 0.05 * expect, "tied volume of the region ∩ ball");
  const int n = 3 * m->n_nodes;
  double *A = calloc((size_t)n * n, sizeof(double)), *b = calloc((size_t)n, sizeof(double)),
         *u = calloc((size_t)n, sizeof(double));
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double fe[24], frame[NH_HEX_FRAME], Kt[576];
    nh_tissue_element_force(t, c, u, fe, frame);
    nh_tissue_element_tangent(t, c, frame, Kt);
    for (int i = 0; i < 24; i++)
      for (int j = 0; j < 24; j++)
        A[(size_t)(3 * m->cells[8 * c + i / 3] + i % 3) * n + 3 * m->cells[8 * c + j / 3] +
          j % 3] += Kt[24 * i + j];
  }
  const double gz = -9.81;
  double weight = 0.0;
  for (int i = 0; i < m->n_nodes; i++) b[3 * i + 2] = t->mass[i] * gz, weight += t->mass[i] * gz;
  CHECK(cholesky(A, n) == 0, "tangent with a tie of radius h/4 positive definite (grid %d)", g);
  for (int i = 0; i < n; i++) { /* forward, backward */
    double v = b[i];
    for (int k = 0; k < i; k++) v -= A[(size_t)i * n + k] * u[k];
    u[i] = v / A[(size_t)i * n + i];
  }
  for (int i = n - 1; i >= 0; i--) {
    double v = u[i];
    for (int k = i + 1; k < n; k++) v -= A[(size_t)k * n + i] * u[k];
    u[i] = v / A[(size_t)i * n + i];
  }
  double reaction = 0.0; /* Σ_a (T u)_a,z */
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    int e = t->cell_tie[c];
    if (e < 0) continue;
    for (int a = 0; a < 8; a++)
      for (int q = 0; q < 8; q++)
        reaction += t->tie[64 * e + 8 * a + q] * u[3 * m->cells[8 * c + q] + 2];
  }
  CHECK_CLOSE(reaction, weight, 1e-8 * fabs(weight), "tie reaction = weight");
  double umax = max_abs(u, n);
  CHECK(isfinite(umax) && umax > 0.0, "the tie holds the ball (grid %d): max |u| %g", g, umax);
  /* mass = ρ V_h, V_h within the bound of the ball's reconstruction */
  double V = 0.0, s = h / (1 << NH_CUT_DEPTH);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    const nh_tissue_cut *cut = nh_tissue_cell_cut(t, c);
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    V += cut ? cut->volume : h * h * h;
  }
  CHECK_CLOSE(-weight / 9.81, 1000.0 * V, 1e-12 * 1000.0 * V, "mass = ρ V_h");
  double Vx = 4.0 / 3.0 * M_PI * R * R * R,
         bound = 4.0 * M_PI * R * R * 1.5 * s * s / (R - sqrt(3) * s);
  CHECK(V <= Vx && Vx - V <= bound, "ball volume %g within %g below %g", V, bound, Vx);
  if (verbose)
    printf("tie grid %2d, region radius %.4f: cut cells %d, max|u| %.3e m, reaction/weight - 1 "
           "= %.2e, tied volume/exact - 1 = %.2e, (V_h - V)/V = %.2e\n",
           g, r.radius, t->n_cut, umax, reaction / weight - 1.0, vol / expect - 1.0, V / Vx - 1.0);
  free(A), free(b), free(u);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(void) {
  verbose = getenv("NH_VERBOSE") != NULL;
  const double c0[3] = {0.0013, -0.0021, 0.0007};
  nh_domain ball, brain;
  nh_domain_sphere(c0, 0.03, &ball);
  const double bc[3] = {0, 0, 0}, bs[3] = {0.14, 0.17, 0.12};
  nh_domain_brain(bc, bs, &brain);
  ball.cut_cells = brain.cut_cells = NH_CUT_CELLS_INTEGRATED;
  const nh_domain *doms[2] = {&ball, &brain};
  const char *names[2] = {"ball", "brain"};
  const int grids[4] = {5, 6, 8, 11};
  for (int di = 0; di < 2; di++)
    for (int gi = 0; gi < 4; gi++) {
      double F, T, F2, T2;
      double r0 = patch(doms[di], grids[gi], 0.0, &F, &T);
      CHECK(r0 <= 1e-9, "%s %d³: patch test residual %g at α = 0", names[di], grids[gi], r0);
      CHECK(di == 1 || (F <= 1e-12 && T <= 1e-12), "%s %d³: net force %g torque %g", names[di],
            grids[gi], F, T);
      double r4 = patch(doms[di], grids[gi], 1e-4, &F2, &T2),
             r6 = patch(doms[di], grids[gi], 1e-6, &F2, &T2);
      CHECK(r6 > 0.0 && fabs(r4 / 1e-4 / (r6 / 1e-6) - 1.0) < 0.1,
            "%s %d³: consistency error O(α): r(1e-4) = %g, r(1e-6) = %g", names[di], grids[gi], r4,
            r6);
      if (verbose)
        printf("%s %2d³: residual α=0 %.2e, α=1e-6 %.2e, α=1e-4 %.2e; net force %.1e torque %.1e\n",
               names[di], grids[gi], r0, r6, r4, F, T);
    }
  const int tg[4] = {4, 5, 7, 9};
  for (int i = 0; i < 4; i++) tie_test(tg[i], 0.0);
  for (int i = 0; i < 4; i++) tie_test(tg[i], 0.008); /* h = 15 … 6.7 mm, a cap of 8 mm */
  nh_domain_release(&ball);
  nh_domain_release(&brain);
  return nh_test_failures ? 1 : 0;
}
