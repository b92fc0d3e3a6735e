/* test_patch — the patch test on a mesh of distorted hexahedra.
 * A linear displacement u = A X + c imposed on the boundary nodes must be
 * reproduced at every interior node, because trilinear elements represent
 * linear fields exactly and the corotational element of a homogeneous
 * deformation has the same R in every cell (F is the same constant), so the
 * interior forces of the linear field cancel. Two fields: a small strain
 * (1e-4) and a finite one (5 % stretch with a 0.5 rad rotation), both solved
 * by the static Newton solver to a residual of 1e-11 (the round-off floor of
 * the corotational residual is about eps / strain = 1e-12 here, see
 * solve/integrate.c); interior nodes must
 * match to 1e-10 relative to the largest displacement. Both formulations:
 * the fully integrated element at ν = 0.3, the B-bar element at ν = 0.3 and
 * at ν = 0.4999 (its mean gradients are exact volume averages, so a linear
 * field has θ̄ = tr ε in every cell and the patch test holds for any ν; the
 * tolerance is the same since the solve is to a relative residual). */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

static void run(const double A[9], const double c[3], double nu, nh_formulation formulation,
                const char *field) {
  char what[160];
  snprintf(what, sizeof what, "%s, nu = %g, %s", field, nu,
           formulation == NH_FORMULATION_BBAR ? "B-bar" : "full");
  const double lo[3] = {0, 0, 0}, hi[3] = {1.0, 0.8, 0.6};
  const int grid[3] = {4, 4, 3};
  nh_mesh *m;
  CHECK_OK(nh_mesh_create_box(lo, hi, grid, &m));
  unsigned char *fixed = calloc((size_t)m->n_nodes, 1);
  nh_test_rng = 12345;
  for (int i = 0; i < m->n_nodes; i++) {
    double *X = m->X + 3 * i;
    int boundary = 0;
    for (int k = 0; k < 3; k++) boundary |= X[k] <= lo[k] + 1e-12 || X[k] >= hi[k] - 1e-12;
    fixed[i] = (unsigned char)boundary;
    /* Distort: move every node (boundary ones within their face) by up to 30 % of a cell. */
    for (int k = 0; k < 3; k++) {
      int on_face = X[k] <= lo[k] + 1e-12 || X[k] >= hi[k] - 1e-12;
      if (!on_face) X[k] += 0.3 * m->spacing[k] * nh_rand();
    }
  }
  nh_material mat = {1e5, nu, 1000, formulation};
  nh_tissue *t;
  CHECK_OK(nh_tissue_create(m, &mat, &t));
  nh_system *s;
  CHECK_OK(nh_system_create(t, fixed, NULL, &s));
  int n = 3 * m->n_nodes;
  double *x = malloc(sizeof(double) * n), *f = calloc(n, sizeof(double)), umax = 0.0;
  for (int i = 0; i < m->n_nodes; i++) {
    double u[3];
    nh_mat3_vec(A, m->X + 3 * i, u);
    for (int k = 0; k < 3; k++) {
      u[k] += c[k];
      umax = fmax(umax, fabs(u[k]));
      x[3 * i + k] = fixed[i] ? u[k] : 0.0; /* x holds displacements */
    }
  }
  nh_integrator in = {.tolerance = 1e-11, .max_iterations = 60, .threads = 1};
  nh_step_stats st;
  CHECK_OK(nh_solve_static(s, &in, f, x, &st));
  for (int i = 0; i < m->n_nodes; i++) {
    if (fixed[i]) continue;
    double u[3];
    nh_mat3_vec(A, m->X + 3 * i, u);
    for (int k = 0; k < 3; k++) CHECK_CLOSE(x[3 * i + k], u[k] + c[k], 1e-10 * umax, what);
  }
  free(x), free(f), free(fixed);
  nh_system_destroy(&s);
  nh_tissue_destroy(&t);
  nh_mesh_destroy(&m);
}

int main(void) {
  const double small[9] = {1e-4, 2e-5, -3e-5, 0.5e-4, -1e-4, 2e-5, 1e-5, 3e-5, 0.7e-4};
  const double c[3] = {1e-3, -2e-3, 5e-4};
  for (int f = 0; f < 3; f++) {
    const double nu = f == 2 ? 0.4999 : 0.3;
    const nh_formulation form = f == 0 ? NH_FORMULATION_FULL : NH_FORMULATION_BBAR;
    run(small, c, nu, form, "small linear field");
    /* A = Q S - I: a finite homogeneous deformation with rotation. At
     * ν = 0.4999 an isochoric S (det S = 1): a finite volume change there
     * would mean a pressure of 10³ μ, not a tissue state. */
    double r[3] = {0.3, -0.2, 0.35}, Q[9], A[9];
    double S[9] = {1.05, 0.01, 0.0, 0.01, 0.98, 0.02, 0.0, 0.02, 1.03};
    if (nu > 0.49) {
      const double iso[9] = {1.05, 0.02, 0.0, 0.0, 1.0 / 1.05, 0.01, 0.0, 0.0, 1.0};
      memcpy(S, iso, sizeof S);
    }
    nh_mat3_rotation(r, Q);
    nh_mat3_mul(Q, S, A);
    for (int i = 0; i < 3; i++) A[4 * i] -= 1.0;
    run(A, c, nu, form, "finite homogeneous deformation");
  }
  TEST_END();
}
