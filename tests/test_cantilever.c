/* test_cantilever — static tip deflection of cases/cantilever.yaml under
 * refinement, against beam theory.
 *
 * Beam theory (Timoshenko, since the FE model is 3D elasticity and shear adds
 * ≈ 0.8 % at L/h = 10): a total load P spread uniformly over x ∈ [L−a, L]
 * deflects the free end by
 *   δ = ∫_{L−a}^{L} (P/a) [ s²(3L − s) / (6EI) + s / (κGA) ] ds,
 * κ = 10(1+ν)/(12+11ν) (Cowper). ν = 0 here, so the clamp adds no Poisson
 * restraint and 3D elasticity differs from Timoshenko only by end effects.
 *
 * Trilinear hexahedra converge in displacement at O(h²) (after the locking
 * regime of very coarse meshes). With three meshes h, h/2, h/4 the observed
 * order p = log₂((d₂ − d₁)/(d₃ − d₂)) must lie in [1.7, 2.3], the errors
 * against beam theory must decrease monotonically, and the Richardson
 * extrapolation d₃ + (d₃ − d₂)/(2ᵖ − 1) must agree with beam theory within
 * 1 % (the size of the shear term: a wrong beam formula or a wrong load
 * integration is off by more). */
#include "sim_util.h"

static double tip_deflection(int n) {
  char grid[64];
  snprintf(grid, sizeof grid, "tissue.grid=[%d,%d,%d]", 10 * n, n, n);
  const char *sets[] = {grid, "tissue.material.poisson=0", "solver.tolerance=1e-10", NULL};
  double u[3];
  nh_case_probe("cantilever.yaml", sets, 0, u); /* probe "tip": centre of the end face */
  return -u[2];
}

int main(void) {
  const double E = 1.0e6, nu = 0.0, L = 0.1, b = 0.01, P = 1.0e-3, a = 0.001;
  const double I = b * b * b * b / 12, A = b * b, G = E / (2 * (1 + nu));
  const double kappa = 10 * (1 + nu) / (12 + 11 * nu);
  /* ∫ s²(3L − s) ds = L s³ − s⁴/4; ∫ s ds = s²/2 */
  double s0 = L - a, s1 = L;
  double bend = (L * (s1 * s1 * s1 - s0 * s0 * s0) - (s1 * s1 * s1 * s1 - s0 * s0 * s0 * s0) / 4) /
                (6 * E * I);
  double shear = 0.5 * (s1 * s1 - s0 * s0) / (kappa * G * A);
  double beam = P / a * (bend + shear);

  const int meshes[] = {1, 2, 4, 8};
  double d[4];
  for (int i = 0; i < 4; i++) d[i] = tip_deflection(meshes[i]);
  double p = log2((d[2] - d[1]) / (d[3] - d[2]));
  double extrapolated = d[3] + (d[3] - d[2]) / (pow(2.0, p) - 1);
  if (getenv("NH_VERBOSE")) {
    printf("beam theory (Timoshenko) %.6e m, Euler-Bernoulli %.6e m\n", beam, P / a * bend);
    for (int i = 0; i < 4; i++)
      printf("grid %3d x %d x %d: tip %.6e m, error %.3e\n", 10 * meshes[i], meshes[i], meshes[i],
             d[i], (d[i] - beam) / beam);
    printf("observed order %.3f, extrapolated %.6e (%.3e from beam theory)\n", p, extrapolated,
           (extrapolated - beam) / beam);
  }
  for (int i = 1; i < 4; i++)
    CHECK(fabs(d[i] - beam) < fabs(d[i - 1] - beam), "error grows from mesh %d to %d", i - 1, i);
  CHECK(p >= 1.7 && p <= 2.3, "observed order %.3f outside [1.7, 2.3]", p);
  CHECK_CLOSE(extrapolated, beam, 0.01 * beam, "extrapolated tip deflection vs beam theory");
  TEST_END();
}
