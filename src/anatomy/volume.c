/* volume.c — the interpolation at world points of the voxel values of any
 * scalar NIfTI image (an MRI's intensities as well as labels; image.c reads
 * them, nh_image_read_values): what resampling an image to the shifted
 * anatomy needs (docs/anatomy.md, "The shifted image").
 *
 * Interpolation follows ITK's interpolators, so that an image resampled here
 * and one resampled by ANTs or transformix with the exported field agree:
 * a point is inside the image when its continuous index lies in
 * [-1/2, n - 1/2) along every axis (the voxels' boxes), else the value is 0
 * (ITK's default pixel value); inside, trilinear interpolation between the
 * 8 centres around it, the neighbours clamped to the image in the outer half
 * voxel (constant extension of the edge), or the nearest centre's value for
 * labels (round half up, as nh_image_label_at). */
#include "anatomy/anatomy.h"

#include <math.h>

double nh_image_interpolate(const nh_image *im, const double *values, const double x[3],
                            int nearest) {
  double p[3], w[3];
  int q[3];
  nh_image_to_voxel(im, x, p);
  for (int k = 0; k < 3; k++)
    if (!(p[k] >= -0.5 && p[k] < im->n[k] - 0.5)) return 0.0;
  const size_t n0 = (size_t)im->n[0], n01 = n0 * (size_t)im->n[1];
  if (nearest) {
    for (int k = 0; k < 3; k++) {
      q[k] = (int)floor(p[k] + 0.5);
      if (q[k] > im->n[k] - 1) q[k] = im->n[k] - 1;
    }
    return values[(size_t)q[0] + n0 * (size_t)q[1] + n01 * (size_t)q[2]];
  }
  for (int k = 0; k < 3; k++) {
    double c = fmin(fmax(p[k], 0.0), im->n[k] - 1.0);
    q[k] = im->n[k] > 1 ? (int)fmin(floor(c), im->n[k] - 2.0) : 0;
    w[k] = c - q[k];
  }
  double s = 0.0;
  for (int c = 0; c < 8; c++) {
    int d[3] = {c & 1, (c >> 1) & 1, (c >> 2) & 1};
    double wt = 1.0;
    size_t at = 0, stride[3] = {1, n0, n01};
    for (int k = 0; k < 3; k++) {
      wt *= d[k] ? w[k] : 1.0 - w[k];
      at += stride[k] * (size_t)(q[k] + (im->n[k] > 1 ? d[k] : 0));
    }
    if (wt != 0.0) s += wt * values[at];
  }
  return s;
}
