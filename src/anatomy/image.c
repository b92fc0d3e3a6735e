/* image.c — NIfTI label images through libnifti2, and the organ they hold as
 * an implicit function (docs/anatomy.md, "Label images").
 *
 * Reading. libnifti2 reads NIfTI-1 and NIfTI-2, gzip'ed or not, and fills
 * both transforms; we take the sform when its code is non-zero (the scanner
 * or atlas frame that tools such as FSL, SPM and 3D Slicer write), else the
 * qform when its code is non-zero, else the pixdim diagonal (the "Analyze"
 * fallback of the NIfTI standard, method 1). That is the rule of the NIfTI-1
 * standard and of nibabel's `affine`. Lengths are converted to metres from
 * xyz_units; files with unknown units (code 0) are taken as millimetres, the
 * unit every neuroimaging tool writes. libnifti2 prints its own diagnostics
 * at debug level ≥ 1; we silence them and report one message of our own.
 *
 * The organ. With χ the trilinear interpolation of the 0/1 indicator of the
 * selected labels between voxel centres (0 outside the image), the organ is
 * {χ > 1/2}: a smooth-ish level set that passes half-way between an inside
 * and an outside centre (exactly the voxel faces for a flat wall along an
 * axis, but cutting the corners of the voxel staircase at 45°), with the
 * gradient ∇χ as its normal. The implicit function is
 *     F(x) = max((1/2 − χ(x)) s,  d_box(x)),   s = 1 / (√3 ‖A⁻¹‖_F),
 * where d_box is the Euclidean distance to the selected voxels' bounding box
 * grown by half a voxel (0 inside it). χ ∈ [0, 1] is trilinear per voxel
 * cell in index space, so each index-space partial derivative is bounded by
 * 1 and |∇ₓχ| ≤ √3 ‖A⁻¹‖₂ ≤ √3 ‖A⁻¹‖_F: the first term is 1-Lipschitz, the
 * second is a distance, and their maximum is 1-Lipschitz. Both are ≤ the
 * distance to the organ where positive ({χ > 1/2} lies within half a voxel
 * of a selected centre, inside the grown box), so F > 0 bounds that distance
 * from below, which the mesh's conservative "may this cell meet the organ"
 * test relies on (docs/theory.md §5b). Inside, F = (1/2 − χ) s < 0. */
#include "anatomy/anatomy.h"

#include <errno.h>
#include <math.h>
#include <nifti2_io.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char nh_orientation_letter(int code) {
  switch (code) {
  case NIFTI_L2R:
    return 'R';
  case NIFTI_R2L:
    return 'L';
  case NIFTI_P2A:
    return 'A';
  case NIFTI_A2P:
    return 'P';
  case NIFTI_I2S:
    return 'S';
  case NIFTI_S2I:
    return 'I';
  default:
    return '?';
  }
}

double nh_image_voxel_value(const void *d, int datatype, size_t v, int *ok) {
  switch (datatype) {
  case DT_UINT8:
    return ((const uint8_t *)d)[v];
  case DT_INT8:
    return ((const int8_t *)d)[v];
  case DT_INT16:
    return ((const int16_t *)d)[v];
  case DT_UINT16:
    return ((const uint16_t *)d)[v];
  case DT_INT32:
    return ((const int32_t *)d)[v];
  case DT_UINT32:
    return ((const uint32_t *)d)[v];
  case DT_INT64:
    return (double)((const int64_t *)d)[v];
  case DT_UINT64:
    return (double)((const uint64_t *)d)[v];
  case DT_FLOAT32:
    return ((const float *)d)[v];
  case DT_FLOAT64:
    return ((const double *)d)[v];
  default:
    *ok = 0;
    return 0.0;
  }
}

static int nh_image_fill(nh_image *im, nifti_image *nim, int read_data) {
  for (int d = 4; d <= 7; d++)
    NH_CHECK(nim->dim[0] < d || nim->dim[d] <= 1, NH_ERR_INPUT,
             "%s: not a 3D image: dimension %d has %lld entries (time series and vector images "
             "are not label images)",
             im->path, d, (long long)nim->dim[d]);
  NH_CHECK(nim->nx >= 1 && nim->ny >= 1 && nim->nz >= 1 && nim->nx < (1 << 20) &&
               nim->ny < (1 << 20) && nim->nz < (1 << 20) &&
               (double)nim->nx * nim->ny * nim->nz < 1e9,
           NH_ERR_INPUT, "%s: unsupported size %lld x %lld x %lld", im->path, (long long)nim->nx,
           (long long)nim->ny, (long long)nim->nz);
  im->n[0] = (int)nim->nx, im->n[1] = (int)nim->ny, im->n[2] = (int)nim->nz;
  switch (nim->xyz_units) {
  case NIFTI_UNITS_METER:
    im->unit = 1.0;
    break;
  case NIFTI_UNITS_MICRON:
    im->unit = 1e-6;
    break;
  default:
    im->unit = 1e-3;
    break; /* mm, or unknown (taken as mm) */
  }
  const nifti_dmat44 *M;
  if (nim->sform_code > 0)
    M = &nim->sto_xyz, im->xform = "sform";
  else if (nim->qform_code > 0)
    M = &nim->qto_xyz, im->xform = "qform";
  else
    M = NULL, im->xform = "pixdim";
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) {
      double a = M ? M->m[r][c] : (r == c ? fabs(nim->pixdim[r + 1]) : 0.0);
      if (!M && r == c && !(a > 0)) a = 1.0; /* pixdim 0: NIfTI's default spacing of 1 */
      im->A[3 * r + c] = a * im->unit;
    }
    im->t[r] = M ? M->m[r][3] * im->unit : 0.0;
  }
  int finite = 1;
  for (int i = 0; i < 9; i++) finite &= isfinite(im->A[i]);
  for (int i = 0; i < 3; i++) finite &= isfinite(im->t[i]);
  NH_CHECK(finite && nh_mat3_inverse(im->A, im->Ainv) == NH_OK && fabs(nh_mat3_det(im->A)) > 0,
           NH_ERR_INPUT, "%s: the %s transform is singular or not finite", im->path, im->xform);
  double frob = 0.0;
  for (int i = 0; i < 9; i++) frob += im->Ainv[i] * im->Ainv[i];
  im->level_scale = 1.0 / (sqrt(3.0) * sqrt(frob));
  for (int c = 0; c < 3; c++)
    im->spacing[c] =
        sqrt(im->A[c] * im->A[c] + im->A[3 + c] * im->A[3 + c] + im->A[6 + c] * im->A[6 + c]);
  int code[3];
  nifti_dmat44 R;
  memset(&R, 0, sizeof R);
  for (int r = 0; r < 3; r++)
    for (int c = 0; c < 3; c++) R.m[r][c] = im->A[3 * r + c];
  R.m[3][3] = 1.0;
  nifti_dmat44_to_orientation(R, &code[0], &code[1], &code[2]);
  for (int c = 0; c < 3; c++) im->orientation[c] = nh_orientation_letter(code[c]);
  im->orientation[3] = '\0';
  if (!read_data) return NH_OK;

  NH_CHECK(nim->data, NH_ERR_INPUT, "%s: the voxel data could not be read", im->path);
  size_t nvox = (size_t)im->n[0] * im->n[1] * im->n[2];
  im->label = malloc(sizeof(int) * nvox);
  if (!im->label) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", im->path);
  double slope = nim->scl_slope, inter = nim->scl_inter;
  int scaled = isfinite(slope) && slope != 0.0 && !(slope == 1.0 && inter == 0.0);
  for (size_t v = 0; v < nvox; v++) {
    int ok = 1;
    double value = nh_image_voxel_value(nim->data, nim->datatype, v, &ok);
    NH_CHECK(ok, NH_ERR_INPUT, "%s: data type %s is not a label type (use an integer type)",
             im->path, nifti_datatype_string(nim->datatype));
    if (scaled) value = slope * value + inter;
    if (!(value == floor(value) && fabs(value) <= 2147483647.0)) {
      size_t i = v % (size_t)im->n[0], j = v / (size_t)im->n[0] % (size_t)im->n[1],
             k = v / ((size_t)im->n[0] * im->n[1]);
      return NH_ERROR(NH_ERR_INPUT,
                      "%s: voxel [%zu, %zu, %zu] holds %g, not an integer label (a label image "
                      "holds whole numbers; segment an intensity image first)",
                      im->path, i, j, k, value);
    }
    im->label[v] = (int)value;
  }
  return NH_OK;
}

int nh_image_read(const char *path, int read_data, nh_image **out) {
  *out = NULL;
  FILE *f = fopen(path, "rb");
  if (!f) return NH_ERROR(NH_ERR_INPUT, "%s: cannot open: %s", path, strerror(errno));
  fclose(f);
  size_t len = strlen(path);
  NH_CHECK(len < NH_ANATOMY_PATH_MAX, NH_ERR_INPUT, "%s: path too long", path);
  /* libnifti2 looks for PATH.nii, PATH.hdr, ... when PATH itself has no
   * NIfTI extension: refuse that, so the file read is the file named. */
  NH_CHECK(nifti_is_complete_filename(path), NH_ERR_INPUT,
           "%s: not a NIfTI file name (expected .nii, .nii.gz, .hdr or .img)", path);
  nifti_set_debug_level(0);
  int version = 0; /* a NIfTI-1 or NIfTI-2 header that passes libnifti2's checks */
  void *header = nifti_read_header(path, &version, 1);
  int is_nifti = header && (version == 1 || version == 2);
  free(header);
  NH_CHECK(is_nifti, NH_ERR_INPUT, "%s: not a NIfTI file (no valid NIfTI-1 or NIfTI-2 header)",
           path);
  nifti_image *nim = nifti_image_read(path, read_data);
  NH_CHECK(nim, NH_ERR_INPUT,
           "%s: libnifti2 could not read it (corrupt or truncated header, data or gzip stream)",
           path);
  nh_image *im = nh_calloc(1, sizeof *im);
  if (!im) {
    nifti_image_free(nim);
    return NH_ERR_MEMORY;
  }
  memcpy(im->path, path, len + 1);
  im->refs = 1;
  im->lo[0] = 1, im->hi[0] = 0;
  int rc = nh_image_fill(im, nim, read_data);
  nifti_image_free(nim);
  if (rc) {
    nh_image_release(&im);
    return rc;
  }
  *out = im;
  return NH_OK;
}

void nh_image_retain(nh_image *im) {
  if (im) im->refs++;
}

void nh_image_release(nh_image **image) {
  if (!image || !*image) return;
  nh_image *im = *image;
  *image = NULL;
  if (--im->refs > 0) return;
  free(im->label);
  free(im->inside);
  free(im->distance);
  free(im->prefix);
  free(im);
}

void nh_image_to_voxel(const nh_image *im, const double x[3], double ijk[3]) {
  double r[3] = {x[0] - im->t[0], x[1] - im->t[1], x[2] - im->t[2]};
  nh_mat3_vec(im->Ainv, r, ijk);
}

void nh_image_to_world(const nh_image *im, const double ijk[3], double x[3]) {
  nh_mat3_vec(im->A, ijk, x);
  for (int k = 0; k < 3; k++) x[k] += im->t[k];
}

int nh_image_contains(const nh_image *im, const double x[3]) {
  double p[3];
  nh_image_to_voxel(im, x, p);
  for (int k = 0; k < 3; k++)
    if (!(p[k] >= -0.5 && p[k] <= im->n[k] - 0.5)) return 0;
  return 1;
}

static size_t nh_voxel_index(const nh_image *im, int i, int j, int k) {
  return (size_t)i + (size_t)im->n[0] * ((size_t)j + (size_t)im->n[1] * (size_t)k);
}

int nh_image_label_at(const nh_image *im, const double x[3]) {
  double p[3];
  int q[3];
  nh_image_to_voxel(im, x, p);
  for (int k = 0; k < 3; k++) {
    if (!(p[k] >= -0.5 && p[k] < im->n[k] - 0.5)) return 0;
    q[k] = (int)floor(p[k] + 0.5);
    if (q[k] > im->n[k] - 1) q[k] = im->n[k] - 1;
  }
  return im->label[nh_voxel_index(im, q[0], q[1], q[2])];
}

static int nh_int_compare(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

int nh_image_labels(const nh_image *im, int **labels, long **counts, int *n) {
  size_t nvox = (size_t)im->n[0] * im->n[1] * im->n[2];
  *labels = NULL, *counts = NULL, *n = 0;
  int *sorted = malloc(sizeof(int) * nvox);
  if (!sorted) return NH_ERROR(NH_ERR_MEMORY, "out of memory: labels of %s", im->path);
  memcpy(sorted, im->label, sizeof(int) * nvox);
  qsort(sorted, nvox, sizeof(int), nh_int_compare);
  int distinct = 0;
  for (size_t v = 0; v < nvox; v++) distinct += v == 0 || sorted[v] != sorted[v - 1];
  int *l = malloc(sizeof(int) * (size_t)distinct);
  long *c = calloc((size_t)distinct, sizeof(long));
  if (!l || !c) {
    free(sorted), free(l), free(c);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: labels of %s", im->path);
  }
  int m = -1;
  for (size_t v = 0; v < nvox; v++) {
    if (v == 0 || sorted[v] != sorted[v - 1]) l[++m] = sorted[v];
    c[m]++;
  }
  free(sorted);
  *labels = l, *counts = c, *n = distinct;
  return NH_OK;
}

int nh_image_print(const nh_image *im, FILE *f) {
  int *labels, n;
  long *counts;
  NH_TRY(nh_image_labels(im, &labels, &counts, &n));
  double voxel = fabs(nh_mat3_det(im->A));
  fprintf(f,
          "image     %s: %d x %d x %d voxels of %g x %g x %g mm, axes i, j, k towards %c, %c, "
          "%c (world from the %s)\n",
          im->path, im->n[0], im->n[1], im->n[2], 1e3 * im->spacing[0], 1e3 * im->spacing[1],
          1e3 * im->spacing[2], im->orientation[0], im->orientation[1], im->orientation[2],
          im->xform);
  fprintf(f, "          %d label%s (voxels, volume):", n, n == 1 ? "" : "s");
  for (int i = 0; i < n; i++)
    fprintf(f, "%s %d (%ld, %.4g mL)", i ? "," : "", labels[i], counts[i], counts[i] * voxel * 1e6);
  fprintf(f, "\n");
  free(labels), free(counts);
  return NH_OK;
}

/* One line of the squared distance transform (Felzenszwalb and Huttenlocher,
 * "Distance transforms of sampled functions"): d[q] = min_p (q − p)² + f[p]
 * over n samples of f (stride `stride`), in place; v, z, g workspace. */
static void nh_edt_line(float *f, size_t stride, int n, int *v, double *z, double *g) {
  const double inf = 1e30;
  for (int q = 0; q < n; q++) g[q] = f[q * stride];
  int k = 0;
  v[0] = 0, z[0] = -inf, z[1] = inf;
  for (int q = 1; q < n; q++) {
    double s;
    for (;;) {
      int p = v[k];
      s = ((g[q] + (double)q * q) - (g[p] + (double)p * p)) / (2.0 * (q - p));
      if (s > z[k] || k == 0) break;
      k--;
    }
    if (s <= z[k]) { /* k == 0 and the new parabola is below everywhere */
      v[0] = q, z[0] = -inf, z[1] = inf;
      continue;
    }
    k++;
    v[k] = q, z[k] = s, z[k + 1] = inf;
  }
  k = 0;
  for (int q = 0; q < n; q++) {
    while (z[k + 1] < q) k++;
    double d = (double)(q - v[k]) * (q - v[k]) + g[v[k]];
    f[q * stride] = (float)fmin(d, inf);
  }
}

/* im->distance: σ_min(A) ≥ 1 / ‖A⁻¹‖_F times the exact index-space
 * Euclidean distance transform of the selected voxels (three 1D passes). */
static int nh_image_distance(nh_image *im) {
  const int n0 = im->n[0], n1 = im->n[1], n2 = im->n[2];
  size_t nvox = (size_t)n0 * n1 * n2;
  int nmax = n0 > n1 ? (n0 > n2 ? n0 : n2) : (n1 > n2 ? n1 : n2);
  free(im->distance);
  im->distance = malloc(sizeof(float) * nvox);
  int *v = malloc(sizeof(int) * (size_t)nmax);
  double *z = malloc(sizeof(double) * (size_t)(nmax + 1)), *g = malloc(sizeof(double) * nmax);
  if (!im->distance || !v || !z || !g) {
    free(v), free(z), free(g);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: distances in %s", im->path);
  }
  for (size_t q = 0; q < nvox; q++) im->distance[q] = im->inside[q] ? 0.0f : 1e30f;
  for (int k = 0; k < n2; k++)
    for (int j = 0; j < n1; j++)
      nh_edt_line(im->distance + nh_voxel_index(im, 0, j, k), 1, n0, v, z, g);
  for (int k = 0; k < n2; k++)
    for (int i = 0; i < n0; i++)
      nh_edt_line(im->distance + nh_voxel_index(im, i, 0, k), (size_t)n0, n1, v, z, g);
  for (int j = 0; j < n1; j++)
    for (int i = 0; i < n0; i++)
      nh_edt_line(im->distance + nh_voxel_index(im, i, j, 0), (size_t)n0 * n1, n2, v, z, g);
  free(v), free(z), free(g);
  /* Prefix sums for box counts. */
  const size_t m0 = (size_t)n0 + 1, m1 = (size_t)n1 + 1;
  free(im->prefix);
  im->prefix = calloc(m0 * m1 * ((size_t)n2 + 1), sizeof(int));
  if (!im->prefix) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", im->path);
  for (int k = 1; k <= n2; k++)
    for (int j = 1; j <= n1; j++)
      for (int i = 1; i <= n0; i++) {
        size_t q = (size_t)i + m0 * ((size_t)j + m1 * (size_t)k);
        im->prefix[q] = im->inside[nh_voxel_index(im, i - 1, j - 1, k - 1)] + im->prefix[q - 1] +
                        im->prefix[q - m0] + im->prefix[q - m0 * m1] - im->prefix[q - 1 - m0] -
                        im->prefix[q - 1 - m0 * m1] - im->prefix[q - m0 - m0 * m1] +
                        im->prefix[q - 1 - m0 - m0 * m1];
      }
  double sigma = sqrt(3.0) * im->level_scale; /* 1 / ‖A⁻¹‖_F ≤ σ_min(A) */
  for (size_t q = 0; q < nvox; q++)
    im->distance[q] = (float)(sigma * sqrt((double)im->distance[q]) * (1 - 1e-6));
  im->reach = 0.0;
  for (int d = 0; d < 4; d++) {
    double u[3] = {1.0, d & 1 ? -1.0 : 1.0, d & 2 ? -1.0 : 1.0}, w[3];
    nh_mat3_vec(im->A, u, w);
    im->reach = fmax(im->reach, sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]));
  }
  return NH_OK;
}

int nh_image_select(nh_image *im, const int *labels, int n) {
  size_t nvox = (size_t)im->n[0] * im->n[1] * im->n[2];
  free(im->inside);
  im->inside = calloc(nvox, 1);
  if (!im->inside) return NH_ERROR(NH_ERR_MEMORY, "out of memory: %s", im->path);
  for (int k = 0; k < 3; k++) im->lo[k] = im->n[k], im->hi[k] = -1;
  for (int k = 0; k < im->n[2]; k++)
    for (int j = 0; j < im->n[1]; j++)
      for (int i = 0; i < im->n[0]; i++) {
        size_t v = nh_voxel_index(im, i, j, k);
        int in = 0;
        for (int s = 0; s < n && !in; s++) in = im->label[v] == labels[s];
        if (!in) continue;
        im->inside[v] = 1;
        int q[3] = {i, j, k};
        for (int a = 0; a < 3; a++) {
          if (q[a] < im->lo[a]) im->lo[a] = q[a];
          if (q[a] > im->hi[a]) im->hi[a] = q[a];
        }
      }
  NH_CHECK(im->hi[0] >= 0, NH_ERR_INPUT, "%s: no voxel holds the selected labels", im->path);
  nh_image_bounds(im, im->box_min, im->box_max);
  return nh_image_distance(im);
}

double nh_image_indicator(const nh_image *im, const double x[3]) {
  double p[3], w[3];
  int q[3];
  nh_image_to_voxel(im, x, p);
  for (int k = 0; k < 3; k++) {
    if (!(p[k] > -1.0 && p[k] < im->n[k])) return 0.0;
    q[k] = (int)floor(p[k]);
    w[k] = p[k] - q[k];
  }
  double chi = 0.0;
  for (int c = 0; c < 8; c++) {
    int i = q[0] + (c & 1), j = q[1] + ((c >> 1) & 1), k = q[2] + ((c >> 2) & 1);
    if (i < 0 || j < 0 || k < 0 || i >= im->n[0] || j >= im->n[1] || k >= im->n[2]) continue;
    if (!im->inside[nh_voxel_index(im, i, j, k)]) continue;
    chi += (c & 1 ? w[0] : 1 - w[0]) * ((c >> 1) & 1 ? w[1] : 1 - w[1]) *
           ((c >> 2) & 1 ? w[2] : 1 - w[2]);
  }
  return chi;
}

/* World bounding box of the index box [lo, hi] (its 8 corners' extent). */
static void nh_index_box_world(const nh_image *im, const double lo[3], const double hi[3],
                               double min[3], double max[3]) {
  for (int k = 0; k < 3; k++) min[k] = INFINITY, max[k] = -INFINITY;
  for (int c = 0; c < 8; c++) {
    double ijk[3], x[3];
    for (int a = 0; a < 3; a++) ijk[a] = (c >> a) & 1 ? hi[a] : lo[a];
    nh_image_to_world(im, ijk, x);
    for (int a = 0; a < 3; a++) min[a] = fmin(min[a], x[a]), max[a] = fmax(max[a], x[a]);
  }
}

int nh_image_meets_box(const nh_image *im, const double lo[3], const double hi[3]) {
  double plo[3] = {INFINITY, INFINITY, INFINITY}, phi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (int c = 0; c < 8; c++) {
    double x[3] = {c & 1 ? hi[0] : lo[0], c & 2 ? hi[1] : lo[1], c & 4 ? hi[2] : lo[2]}, p[3];
    nh_image_to_voxel(im, x, p);
    for (int k = 0; k < 3; k++) plo[k] = fmin(plo[k], p[k]), phi[k] = fmax(phi[k], p[k]);
  }
  /* Selected centres with index in (plo − 1, phi + 1), clipped to the image. */
  int a[3], b[3];
  for (int k = 0; k < 3; k++) {
    double l = floor(plo[k] - 1.0) + 1.0, h = ceil(phi[k] + 1.0) - 1.0;
    a[k] = (int)fmax(l, 0.0), b[k] = (int)fmin(h, im->n[k] - 1.0);
    if (a[k] > b[k]) return 0;
  }
  const size_t m0 = (size_t)im->n[0] + 1, m1 = (size_t)im->n[1] + 1;
#define NH_P(i, j, k) im->prefix[(size_t)(i) + m0 * ((size_t)(j) + m1 * (size_t)(k))]
  long n = (long)NH_P(b[0] + 1, b[1] + 1, b[2] + 1) - NH_P(a[0], b[1] + 1, b[2] + 1) -
           NH_P(b[0] + 1, a[1], b[2] + 1) - NH_P(b[0] + 1, b[1] + 1, a[2]) +
           NH_P(a[0], a[1], b[2] + 1) + NH_P(a[0], b[1] + 1, a[2]) + NH_P(b[0] + 1, a[1], a[2]) -
           NH_P(a[0], a[1], a[2]);
#undef NH_P
  return n > 0;
}

void nh_image_bounds(const nh_image *im, double min[3], double max[3]) {
  double lo[3], hi[3];
  for (int a = 0; a < 3; a++) lo[a] = im->lo[a] - 0.5, hi[a] = im->hi[a] + 0.5;
  nh_index_box_world(im, lo, hi, min, max);
}

void nh_image_extent(const nh_image *im, double min[3], double max[3]) {
  double lo[3] = {-0.5, -0.5, -0.5}, hi[3];
  for (int a = 0; a < 3; a++) hi[a] = im->n[a] - 0.5;
  nh_index_box_world(im, lo, hi, min, max);
}

/* Trilinear interpolation of the distance bound (the nearest voxel's value
 * outside the image's centres). */
static double nh_image_distance_at(const nh_image *im, const double x[3]) {
  double p[3], w[3];
  int q[3];
  nh_image_to_voxel(im, x, p);
  for (int k = 0; k < 3; k++) {
    double c = fmin(fmax(p[k], 0.0), im->n[k] - 1.0);
    q[k] = (int)floor(c);
    if (q[k] > im->n[k] - 2) q[k] = im->n[k] > 1 ? im->n[k] - 2 : 0;
    w[k] = im->n[k] > 1 ? c - q[k] : 0.0;
  }
  double d = 0.0;
  for (int c = 0; c < 8; c++) {
    int i = q[0] + (c & 1), j = q[1] + ((c >> 1) & 1), k = q[2] + ((c >> 2) & 1);
    double wt = (c & 1 ? w[0] : 1 - w[0]) * ((c >> 1) & 1 ? w[1] : 1 - w[1]) *
                ((c >> 2) & 1 ? w[2] : 1 - w[2]);
    if (wt == 0.0) continue;
    d += wt * im->distance[nh_voxel_index(im, i < im->n[0] ? i : im->n[0] - 1,
                                          j < im->n[1] ? j : im->n[1] - 1,
                                          k < im->n[2] ? k : im->n[2] - 1)];
  }
  return d;
}

double nh_image_level(const nh_image *im, const double x[3]) {
  double f = (0.5 - nh_image_indicator(im, x)) * im->level_scale;
  if (f <= 0.0) return f;
  /* The distance bound: for each of the 8 centres v around x, d(x, S) ≥
   * D_v − |x − v| ≥ D_v − reach, so d(x, S) ≥ I(D)(x) − reach; and the
   * organ lies within the boxes v ± 1 (index) of the selected centres S (the
   * support of χ), so its distance is ≥ d(x, S) − reach. Outside the image's
   * centres the clamped values and |x − v| ≤ reach no longer hold: there
   * only the box distance below is used. */
  if (nh_image_contains(im, x)) {
    double p[3];
    nh_image_to_voxel(im, x, p);
    int within = 1;
    for (int k = 0; k < 3; k++) within &= p[k] >= 0.0 && p[k] <= im->n[k] - 1.0;
    if (within) f = fmax(f, nh_image_distance_at(im, x) - 2.0 * im->reach);
  }
  /* Distance to the grown index box, measured in world space through the
   * box's world-space bounding box (a box containing it: a lower bound). */
  const double *lo = im->box_min, *hi = im->box_max;
  double d2 = 0.0;
  for (int k = 0; k < 3; k++) {
    double e = x[k] < lo[k] ? lo[k] - x[k] : (x[k] > hi[k] ? x[k] - hi[k] : 0.0);
    d2 += e * e;
  }
  return fmax(f, sqrt(d2));
}
