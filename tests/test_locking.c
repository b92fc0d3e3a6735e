/* test_locking — the B-bar hexahedron does not lock near incompressibility.
 *
 * The cantilever of cases/cantilever.yaml (0.1 × 0.01 × 0.01 m, clamped at
 * x = 0, 1 mN over the last millimetre) on 40 × 4 × 4 cells, static. Beam
 * theory: the deflection is the bending term, which depends on E only, plus
 * the shear term s/(κGA), G = E/(2(1+ν)), κ = 10(1+ν)/(12+11ν) (Cowper),
 * which grows with ν: Timoshenko gives δ(0.499)/δ(0.3) = 1.0017 here. So a
 * formulation free of volumetric locking deflects at ν = 0.499 within 3 %
 * of its ν = 0.3 deflection (the clamp's Poisson restraint, absent from
 * beam theory, stiffens the root a little more at ν → 0.5; 3 % is the
 * issue's bound). Asserted:
 *   1. B-bar: |δ(0.499)/δ(0.3) − 1| ≤ 0.03.
 *   2. B-bar at ν = 0.4999: the static Newton solve converges and the ratio
 *      stays within 3 %.
 *   3. The test can fail: the fully integrated element at ν = 0.499 deflects
 *      less than 0.9 of its ν = 0.3 value (it locks: the issue measured 61 %).
 * NH_VERBOSE=1 prints the deflections. */
#include "sim_util.h"

static double tip_deflection(double nu, const char *formulation) {
  char pois[64], form[64];
  snprintf(pois, sizeof pois, "tissue.material.poisson=%.17g", nu);
  snprintf(form, sizeof form, "tissue.material.formulation=%s", formulation);
  const char *sets[] = {"tissue.grid=[40,4,4]", pois, form, "solver.tolerance=1e-9", NULL};
  double u[3];
  nh_case_probe("cantilever.yaml", sets, 0, u); /* probe "tip": centre of the end face */
  return -u[2];
}

int main(void) {
  double b3 = tip_deflection(0.3, "bbar"), b499 = tip_deflection(0.499, "bbar");
  double b4999 = tip_deflection(0.4999, "bbar");
  double f3 = tip_deflection(0.3, "full"), f499 = tip_deflection(0.499, "full");
  if (getenv("NH_VERBOSE"))
    printf("B-bar: %.6e (0.3) %.6e (0.499, ratio %.4f) %.6e (0.4999, ratio %.4f)\n"
           "full:  %.6e (0.3) %.6e (0.499, ratio %.4f)\n",
           b3, b499, b499 / b3, b4999, b4999 / b3, f3, f499, f499 / f3);
  CHECK_CLOSE(b499 / b3, 1.0, 0.03, "B-bar: tip deflection at nu = 0.499 / at nu = 0.3");
  CHECK_CLOSE(b4999 / b3, 1.0, 0.03, "B-bar: tip deflection at nu = 0.4999 / at nu = 0.3");
  CHECK(f499 / f3 < 0.9, "full integration should lock at nu = 0.499: ratio %.4f", f499 / f3);
  TEST_END();
}
