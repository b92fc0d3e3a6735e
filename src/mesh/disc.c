/* disc.c — a tool's cross-section as material points: the rule of the tip
 * and puncture rows' discs (docs/interaction.md "Tip disc"), shared by the
 * rows (contact/points.c) and the goal estimate's local dual, which samples
 * the same disc on a finer lattice (adapt/dwr_local.c). */
#include "mesh/mesh.h"

#include <math.h>
#include <string.h>

int nh_disc_points(const double X[3], const double nrm[3], const double ref[3], double rho,
                   double h, double *points, double *w) {
  if (!(rho > 0.0)) return 0;
  const int rings = (int)fmin((double)NH_DISC_MAX_RINGS, fmax(1.0, ceil(2.0 * rho / h)));
  /* e1, e2: unit vectors across nrm, e1 along ref's part across nrm (the
   * tool's frame: continuous in the tool's state), without ref the axis
   * least aligned with nrm (exact for a normal along an axis) */
  double e1[3] = {0, 0, 0}, e2[3], nn[3] = {nrm[0], nrm[1], nrm[2]};
  nh_vec3_normalize(nn);
  if (ref && (ref[0] != 0.0 || ref[1] != 0.0 || ref[2] != 0.0)) {
    memcpy(e1, ref, sizeof e1);
  } else {
    int low = 0;
    for (int i = 1; i < 3; i++)
      if (fabs(nrm[i]) < fabs(nrm[low])) low = i;
    e1[low] = 1.0;
  }
  const double c = nh_vec3_dot(e1, nn);
  for (int i = 0; i < 3; i++) e1[i] -= c * nn[i];
  nh_vec3_normalize(e1);
  nh_vec3_cross(nn, e1, e2);
  int n = 0;
  for (int k = 1; k <= rings; k++) {
    const double r = rho * (k - 0.5) / rings,
                 wk = 2.0 * (k - 0.5) / ((double)rings * rings * 6 * k);
    for (int j = 0; j < 6 * k; j++, n++) {
      const double a = 2.0 * NH_PI * j / (6.0 * k), ca = cos(a), sa = sin(a);
      for (int i = 0; i < 3; i++) points[3 * n + i] = X[i] + r * (ca * e1[i] + sa * e2[i]);
      w[n] = wk;
    }
  }
  return n;
}
