/* test_lagrange — the two enforcements of hanging nodes agree.
 * Elimination (u = P u_free, Pᵀ A P) and Lagrange multipliers through the
 * compliance W = J A⁻¹ Jᵀ (the seed's Algorithms 1-3) minimise the same
 * quadratic form over the same constrained space, so every solve must agree
 * to round-off. Checked on the nonconforming meshes of templates 2, 3, 4
 * (distorted, nested): a static bending solve (Newton to 1e-11) and ten
 * dynamic backward-Euler steps with damping; displacements (and velocities)
 * agree to 1e-9 relative, and the Lagrange solution satisfies its rows. */
#include "check.h"
#include "fem/fem.h"
#include "mesh/mesh.h"
#include "solve/solve.h"

#include <string.h>

#include "hanging_mesh.h"

static void compare(int n) {
  nh_template *t = regular_template(n);
  nh_mesh *m = build_mesh(n, t);
  int nn = m->n_nodes;
  unsigned char *fixed = calloc(nn, 1);
  for (int i = 0; i < nn; i++) fixed[i] = m->X[3 * i] < 1e-9;
  nh_hanging *h;
  CHECK_OK(nh_hanging_detect(m, fixed, &h));
  nh_material mat = {1e5, 0.45, 1000, NH_FORMULATION_BBAR};
  nh_tissue *ts;
  CHECK_OK(nh_tissue_create(m, &mat, &ts));
  nh_system *se, *sl;
  CHECK_OK(nh_system_create(ts, fixed, h, &se));
  CHECK_OK(nh_system_create(ts, fixed, NULL, &sl));
  CHECK_OK(nh_system_set_hanging_rows(sl, h));
  CHECK(nh_system_constraint_rows(sl) == 3 * h->n_hanging, "rows %d, want %d",
        nh_system_constraint_rows(sl), 3 * h->n_hanging);
  double *f = calloc(3 * nn, sizeof(double));
  nh_region tip = {.min = {0.029, 0.0, 0.0}, .max = {0.03, 0.03, 0.03}};
  double force[3] = {0.1, 0.2, -0.5};
  CHECK_OK(nh_mesh_region_load(m, &tip, force, f));
  double *ue = calloc(3 * nn, sizeof(double)), *ul = calloc(3 * nn, sizeof(double));
  nh_integrator in = {.dt = 0.01,
                      .alpha = 0.5,
                      .beta = 1e-3,
                      .tolerance = 1e-11,
                      .max_iterations = 50,
                      .threads = 1};
  CHECK_OK(nh_solve_static(se, &in, f, ue, NULL));
  CHECK_OK(nh_solve_static(sl, &in, f, ul, NULL));
  double big = 0.0;
  for (int i = 0; i < 3 * nn; i++) big = fmax(big, fabs(ue[i]));
  for (int i = 0; i < 3 * nn; i++)
    CHECK_CLOSE(ul[i], ue[i], 1e-9 * big, "static: lagrange vs eliminate");
  /* The Lagrange solution satisfies u_h = Σ w u_m. */
  double *ui = malloc(sizeof(double) * 3 * nn);
  memcpy(ui, ul, sizeof(double) * 3 * nn);
  nh_hanging_interpolate(h, ui, 3);
  for (int i = 0; i < 3 * nn; i++)
    CHECK_CLOSE(ul[i], ui[i], 1e-10 * big, "lagrange rows satisfied");

  double *ve = calloc(3 * nn, sizeof(double)), *vl = calloc(3 * nn, sizeof(double));
  memset(ue, 0, sizeof(double) * 3 * nn);
  memset(ul, 0, sizeof(double) * 3 * nn);
  for (int k = 0; k < 10; k++) {
    CHECK_OK(nh_step_dynamic(se, &in, f, ue, ve, NULL));
    CHECK_OK(nh_step_dynamic(sl, &in, f, ul, vl, NULL));
  }
  double bigu = 0.0, bigv = 0.0;
  for (int i = 0; i < 3 * nn; i++) bigu = fmax(bigu, fabs(ue[i])), bigv = fmax(bigv, fabs(ve[i]));
  CHECK(bigu > 1e-9 && bigv > 1e-9, "dynamic: nothing moved (%g, %g)", bigu, bigv);
  for (int i = 0; i < 3 * nn; i++) {
    CHECK_CLOSE(ul[i], ue[i], 1e-9 * bigu, "dynamic u: lagrange vs eliminate");
    CHECK_CLOSE(vl[i], ve[i], 1e-9 * bigv, "dynamic v: lagrange vs eliminate");
  }
  free(f), free(ue), free(ul), free(ve), free(vl), free(ui), free(fixed);
  nh_system_destroy(&se);
  nh_system_destroy(&sl);
  nh_hanging_destroy(&h);
  nh_tissue_destroy(&ts);
  nh_mesh_destroy(&m);
  nh_template_destroy(&t);
}

int main(void) {
  for (int n = 2; n <= 4; n++) compare(n);
  TEST_END();
}
