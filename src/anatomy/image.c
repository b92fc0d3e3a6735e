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

#include <limits.h>
#include <math.h>
#include <nifti2_io.h>
#include <stdint.h>
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

/* ---- the header ---- */

/* What the reader uses of a NIfTI-1 or NIfTI-2 header, in native byte order
 * and wide types. */
typedef struct {
  int version; /* 1 or 2 */
  int swapped; /* the file's byte order is not this machine's */
  int onefile; /* magic n+1 / n+2: header and voxels in one .nii */
  long long dim[8];
  double pixdim[8];
  int datatype, nbyper, swapsize;
  double vox_offset, scl_slope, scl_inter;
  int qform_code, sform_code, xyzt_units;
  double quatern[3], qoffset[3], srow[3][4];
} nh_nifti_header;

/* The fields of a raw NIfTI-1 or NIfTI-2 header h (already in native order). */
#define NH_NIFTI_FIELDS(out, h)                                                                    \
  do {                                                                                             \
    for (int i_ = 0; i_ < 8; i_++)                                                                 \
      (out)->dim[i_] = (h).dim[i_], (out)->pixdim[i_] = (h).pixdim[i_];                            \
    (out)->datatype = (h).datatype, (out)->vox_offset = (double)(h).vox_offset;                    \
    (out)->scl_slope = (h).scl_slope, (out)->scl_inter = (h).scl_inter;                            \
    (out)->qform_code = (h).qform_code, (out)->sform_code = (h).sform_code;                        \
    (out)->xyzt_units = (h).xyzt_units;                                                            \
    (out)->quatern[0] = (h).quatern_b, (out)->quatern[1] = (h).quatern_c;                          \
    (out)->quatern[2] = (h).quatern_d;                                                             \
    (out)->qoffset[0] = (h).qoffset_x, (out)->qoffset[1] = (h).qoffset_y;                          \
    (out)->qoffset[2] = (h).qoffset_z;                                                             \
    for (int c_ = 0; c_ < 4; c_++)                                                                 \
      (out)->srow[0][c_] = (h).srow_x[c_], (out)->srow[1][c_] = (h).srow_y[c_],                    \
      (out)->srow[2][c_] = (h).srow_z[c_];                                                         \
    (out)->onefile = NIFTI_ONEFILE(h);                                                             \
  } while (0)

/* znzread of n bytes; a gzip error (which znzread returns as (size_t)-1)
 * reads as nothing, and sets *damaged. */
static size_t nh_znz_read(void *buf, size_t n, znzFile fp, int *damaged) {
  size_t got = znzread(buf, 1, n, fp);
  if (got <= n) return got;
  *damaged = 1;
  return 0;
}

/* Read the header of `path` (through znzlib: plain or gzip'd) into h. Only
 * libnifti2's silent calls are used (header version, byte swap): nothing is
 * printed. Fails with NH_ERR_INPUT: unreadable, too short, not NIfTI. */
static int nh_nifti_header_read(const char *path, nh_nifti_header *h) {
  union {
    nifti_1_header n1;
    nifti_2_header n2;
    char bytes[sizeof(nifti_2_header)];
  } raw;
  memset(&raw, 0, sizeof raw);
  znzFile fp = znzopen(path, "rb", nifti_is_gzfile(path));
  if (znz_isnull(fp)) return NH_ERROR(NH_ERR_INPUT, "%s: cannot open the image", path);
  int damaged = 0;
  size_t got = nh_znz_read(raw.bytes, sizeof(nifti_1_header), fp, &damaged);
  int version =
      got == sizeof(nifti_1_header) ? nifti_header_version(raw.bytes, sizeof(nifti_1_header)) : -1;
  if (version == 2) got += nh_znz_read(raw.bytes + got, sizeof(nifti_2_header) - got, fp, &damaged);
  znzclose(fp);
  NH_CHECK(!damaged, NH_ERR_INPUT, "%s: a damaged gzip stream (zlib fails in its first %zu bytes)",
           path, version == 2 ? sizeof(nifti_2_header) : sizeof(nifti_1_header));
  NH_CHECK(got >= sizeof(nifti_1_header), NH_ERR_INPUT,
           "%s: not a NIfTI file (it ends after %zu bytes: a NIfTI header alone has 348)", path,
           got);
  NH_CHECK(version == 1 || version == 2, NH_ERR_INPUT,
           "%s: not a NIfTI file (no valid NIfTI-1 or NIfTI-2 header%s)", path,
           version == 0 ? ": an Analyze 7.5 header without the NIfTI magic" : "");
  NH_CHECK(got == (version == 2 ? sizeof(nifti_2_header) : sizeof(nifti_1_header)), NH_ERR_INPUT,
           "%s: the NIfTI-2 header is truncated (%zu of 540 bytes)", path, got);
  memset(h, 0, sizeof *h);
  h->version = version;
  if (version == 1) {
    h->swapped = raw.n1.sizeof_hdr != (int)sizeof(nifti_1_header);
    if (h->swapped) swap_nifti_header(&raw.n1, 1);
    NH_NIFTI_FIELDS(h, raw.n1);
  } else {
    h->swapped = raw.n2.sizeof_hdr != (int)sizeof(nifti_2_header);
    if (h->swapped) swap_nifti_header(&raw.n2, 2);
    NH_NIFTI_FIELDS(h, raw.n2);
  }
  return NH_OK;
}

/* The voxel types a label image may have. */
static int nh_label_type(int datatype) {
  switch (datatype) {
  case DT_UINT8:
  case DT_INT8:
  case DT_INT16:
  case DT_UINT16:
  case DT_INT32:
  case DT_UINT32:
  case DT_INT64:
  case DT_UINT64:
  case DT_FLOAT32:
  case DT_FLOAT64:
    return 1;
  default:
    return 0;
  }
}

static int nh_finite3(const double *v) {
  return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* Every field the reader uses, in range (docs/anatomy.md, "Reading"). */
static int nh_nifti_header_check(const char *path, nh_nifti_header *h) {
  NH_CHECK(h->dim[0] >= 1 && h->dim[0] <= 7, NH_ERR_INPUT,
           "%s: dim[0] = %lld: the number of dimensions must be 1 to 7", path, h->dim[0]);
  for (int d = 1; d <= 7; d++) {
    if (d > h->dim[0]) {
      h->dim[d] = 1; /* beyond dim[0]: not a dimension of the image */
      continue;
    }
    NH_CHECK(h->dim[d] >= 1, NH_ERR_INPUT,
             "%s: dim[%d] = %lld: every dimension must hold at least one voxel", path, d,
             h->dim[d]);
    NH_CHECK(d <= 3 || h->dim[d] == 1, NH_ERR_INPUT,
             "%s: not a 3D image: dimension %d has %lld entries (time series and vector images "
             "are not label images)",
             path, d, h->dim[d]);
  }
  for (int d = 1; d <= 3; d++)
    NH_CHECK(isfinite(h->pixdim[d]) && h->pixdim[d] > 0, NH_ERR_INPUT,
             "%s: pixdim[%d] = %g: a voxel size must be a positive finite number", path, d,
             h->pixdim[d]);
  NH_CHECK(isfinite(h->pixdim[0]), NH_ERR_INPUT, "%s: pixdim[0] (qfac) = %g: must be 1 or -1", path,
           h->pixdim[0]);
  NH_CHECK(nh_label_type(h->datatype), NH_ERR_INPUT,
           "%s: data type %s (%d) is not a label type (use an integer type, or float with whole "
           "numbers)",
           path, nifti_datatype_string(h->datatype), h->datatype);
  nifti_datatype_sizes(h->datatype, &h->nbyper, &h->swapsize);
  int space = XYZT_TO_SPACE(h->xyzt_units);
  NH_CHECK(space <= NIFTI_UNITS_MICRON, NH_ERR_INPUT,
           "%s: xyzt_units = %d: its spatial code %d is none of NIfTI's (0 unknown, 1 m, 2 mm, "
           "3 um)",
           path, h->xyzt_units, space);
  NH_CHECK(h->qform_code >= 0 && h->qform_code <= NIFTI_XFORM_TEMPLATE_OTHER, NH_ERR_INPUT,
           "%s: qform_code = %d is not a NIfTI transform code (0 to 5)", path, h->qform_code);
  NH_CHECK(h->sform_code >= 0 && h->sform_code <= NIFTI_XFORM_TEMPLATE_OTHER, NH_ERR_INPUT,
           "%s: sform_code = %d is not a NIfTI transform code (0 to 5)", path, h->sform_code);
  if (h->qform_code > 0) {
    const double *q = h->quatern;
    NH_CHECK(nh_finite3(q), NH_ERR_INPUT,
             "%s: the qform's quaternion (quatern_b, c, d) = (%g, %g, %g) is not finite", path,
             q[0], q[1], q[2]);
    /* b² + c² + d² ≤ 1 makes a = √(1 − b² − c² − d²) a rotation's; the
     * float32 fields of a unit quaternion with a = 0 round to 1 + 1e-7. */
    double norm = sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
    NH_CHECK(norm <= 1 + 1e-6, NH_ERR_INPUT,
             "%s: the qform's quaternion (quatern_b, c, d) = (%g, %g, %g) has norm %.9g > 1: not "
             "a rotation",
             path, q[0], q[1], q[2], norm);
    NH_CHECK(nh_finite3(h->qoffset), NH_ERR_INPUT,
             "%s: the qform's offset (qoffset_x, y, z) = (%g, %g, %g) is not finite", path,
             h->qoffset[0], h->qoffset[1], h->qoffset[2]);
  }
  if (h->sform_code > 0) {
    int finite = 1;
    for (int r = 0; r < 3; r++) finite &= nh_finite3(h->srow[r]) && isfinite(h->srow[r][3]);
    NH_CHECK(finite, NH_ERR_INPUT,
             "%s: the sform (srow_x, srow_y, srow_z) holds a value that is not finite", path);
    double M[9], scale = 1.0;
    for (int r = 0; r < 3; r++) {
      for (int c = 0; c < 3; c++) M[3 * r + c] = h->srow[r][c];
      scale *= nh_vec3_norm(M + 3 * r);
    }
    NH_CHECK(fabs(nh_mat3_det(M)) > 1e-12 * scale, NH_ERR_INPUT,
             "%s: the sform's 3 x 3 part is singular (determinant %g): voxels of no volume", path,
             nh_mat3_det(M));
  }
  if (isfinite(h->scl_slope) && h->scl_slope != 0) {
    if (isnan(h->scl_inter)) h->scl_inter = 0; /* as nibabel reads it */
    NH_CHECK(isfinite(h->scl_inter), NH_ERR_INPUT, "%s: scl_inter = %g is not finite", path,
             h->scl_inter);
  } else {
    h->scl_slope = 0; /* 0, NaN or infinite: no scaling (NIfTI-1, "scl_slope") */
  }
  double header = h->version == 2 ? sizeof(nifti_2_header) : sizeof(nifti_1_header);
  NH_CHECK(isfinite(h->vox_offset) && h->vox_offset == floor(h->vox_offset) &&
               h->vox_offset >= (h->onefile ? header : 0),
           NH_ERR_INPUT, "%s: vox_offset = %g: the voxels must start at a whole byte%s", path,
           h->vox_offset, h->onefile ? " after the header" : "");
  return NH_OK;
}

/* The size limits, before anything is allocated: voxels, and the bytes the
 * header implies (for a gzip'd file, the bytes it must expand to). */
static int nh_nifti_header_limits(const char *path, const nh_nifti_header *h,
                                  const nh_read_limits *limits) {
  double nvox = (double)h->dim[1] * (double)h->dim[2] * (double)h->dim[3];
  NH_CHECK(nvox <= limits->max_voxels, NH_ERR_INPUT,
           "%s: %lld x %lld x %lld = %.0f voxels exceed limits.max_voxels = %.0f", path, h->dim[1],
           h->dim[2], h->dim[3], nvox, limits->max_voxels);
  NH_CHECK(nvox <= INT_MAX, NH_ERR_INPUT,
           "%s: %lld x %lld x %lld = %.0f voxels: more than %d are not supported", path, h->dim[1],
           h->dim[2], h->dim[3], nvox, INT_MAX);
  double bytes = h->vox_offset + nvox * h->nbyper;
  NH_CHECK(bytes <= limits->max_file_bytes, NH_ERR_INPUT,
           "%s: its header implies %.0f bytes (vox_offset %.0f + %.0f voxels x %d bytes), more "
           "than limits.max_file_bytes = %.0f",
           path, bytes, h->vox_offset, nvox, h->nbyper, limits->max_file_bytes);
  return NH_OK;
}

/* ---- the voxels ---- */

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

/* Read the voxels from `file` (znzlib, plain or gzip'd; `where` names it in
 * messages) chunk by chunk: exactly nvox × nbyper bytes after vox_offset,
 * then the end of the file. Values go through scl_slope/scl_inter. With
 * values == NULL they are labels, into im->label: whole numbers in int's
 * range (NaN and 2.5 are refused, naming the voxel); else intensities, into
 * values[nvox]: finite numbers. The output's pages are touched only as data
 * arrive (calloc maps a large block without writing it), so a file
 * shorter than its header says costs what it holds, not what it claims. */
static int nh_nifti_voxels(nh_image *im, const char *file, const char *where,
                           const nh_nifti_header *h, double *values) {
  const size_t nvox = (size_t)im->n[0] * im->n[1] * im->n[2];
  const double total = (double)nvox * h->nbyper;
  if (!values) im->label = nh_calloc(nvox, sizeof(int));
  enum { CHUNK = 1 << 20 };
  unsigned char *buf = nh_calloc(CHUNK, 1);
  znzFile fp = znzopen(file, "rb", nifti_is_gzfile(file));
  int rc = NH_OK, damaged = 0;
  if ((!values && !im->label) || !buf)
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: voxels of %s", where);
  if (!rc && znz_isnull(fp)) rc = NH_ERROR(NH_ERR_INPUT, "%s: cannot open the voxel data", where);
  /* Skip to vox_offset by reading: the same for gzip'd and plain files. */
  for (double skipped = 0; !rc && skipped < h->vox_offset;) {
    size_t want = (size_t)fmin(CHUNK, h->vox_offset - skipped);
    size_t got = nh_znz_read(buf, want, fp, &damaged);
    if (got < want)
      rc = NH_ERROR(NH_ERR_INPUT, "%s: the file ends at byte %.0f, before vox_offset = %.0f", where,
                    skipped + got, h->vox_offset);
    skipped += got;
  }
  const size_t per_chunk = CHUNK / (size_t)h->nbyper;
  const double slope = h->scl_slope, inter = h->scl_inter;
  for (size_t v0 = 0; !rc && v0 < nvox; v0 += per_chunk) {
    size_t n = nvox - v0 < per_chunk ? nvox - v0 : per_chunk;
    size_t got = nh_znz_read(buf, n * (size_t)h->nbyper, fp, &damaged);
    if (got < n * (size_t)h->nbyper) {
      rc = NH_ERROR(NH_ERR_INPUT,
                    "%s: %s after %.0f of the %.0f bytes of voxels the header announces (%d x %d "
                    "x %d voxels of %d bytes)",
                    where, damaged ? "a damaged gzip stream" : "the file ends (truncated)",
                    (double)v0 * h->nbyper + got, total, im->n[0], im->n[1], im->n[2], h->nbyper);
      break;
    }
    if (h->swapped && h->swapsize > 1) nifti_swap_Nbytes((int64_t)n, h->swapsize, buf);
    for (size_t i = 0; i < n; i++) {
      int ok = 1; /* nh_label_type admitted the type */
      double value = nh_image_voxel_value(buf, h->datatype, i, &ok);
      if (slope != 0) value = slope * value + inter;
      int good = values ? isfinite(value) : value == floor(value) && fabs(value) <= (double)INT_MAX;
      if (!good) {
        size_t v = v0 + i, a = v % (size_t)im->n[0], b = v / (size_t)im->n[0] % (size_t)im->n[1],
               c = v / ((size_t)im->n[0] * im->n[1]);
        rc = NH_ERROR(NH_ERR_INPUT, "%s: voxel [%zu, %zu, %zu] holds %g, %s", where, a, b, c, value,
                      values ? "not a finite intensity"
                             : "not an integer label (a label image holds whole numbers; "
                               "segment an intensity image first)");
        break;
      }
      if (values)
        values[v0 + i] = value;
      else
        im->label[v0 + i] = (int)value;
    }
  }
  if (!rc && nh_znz_read(buf, 1, fp, &damaged) == 1)
    rc = NH_ERROR(NH_ERR_INPUT,
                  "%s: the file goes on after the %.0f bytes of voxels its header announces "
                  "(%d x %d x %d of %d bytes after vox_offset %.0f): a wrong dimension or data "
                  "type?",
                  where, total, im->n[0], im->n[1], im->n[2], h->nbyper, h->vox_offset);
  if (!znz_isnull(fp)) znzclose(fp);
  free(buf);
  return rc;
}

/* ---- the image ---- */

/* The world transform, spacing and orientation from a checked header. */
static int nh_image_frame(nh_image *im, const nh_nifti_header *h) {
  switch (XYZT_TO_SPACE(h->xyzt_units)) {
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
  nifti_dmat44 Q;
  if (h->sform_code > 0)
    im->xform = "sform";
  else if (h->qform_code > 0) {
    im->xform = "qform";
    Q = nifti_quatern_to_dmat44(h->quatern[0], h->quatern[1], h->quatern[2], h->qoffset[0],
                                h->qoffset[1], h->qoffset[2], h->pixdim[1], h->pixdim[2],
                                h->pixdim[3], h->pixdim[0] < 0 ? -1.0 : 1.0);
  } else
    im->xform = "pixdim";
  for (int r = 0; r < 3; r++) {
    for (int c = 0; c < 3; c++) {
      double a = h->sform_code > 0   ? h->srow[r][c]
                 : h->qform_code > 0 ? Q.m[r][c]
                                     : (r == c ? h->pixdim[r + 1] : 0.0);
      im->A[3 * r + c] = a * im->unit;
    }
    im->t[r] = (h->sform_code > 0 ? h->srow[r][3] : h->qform_code > 0 ? Q.m[r][3] : 0.0) * im->unit;
  }
  int finite = 1;
  for (int i = 0; i < 9; i++) finite &= isfinite(im->A[i]);
  for (int i = 0; i < 3; i++) finite &= isfinite(im->t[i]);
  NH_CHECK(finite && nh_mat3_inverse(im->A, im->Ainv) == NH_OK && fabs(nh_mat3_det(im->A)) > 0,
           NH_ERR_INPUT, "%s: the %s transform is singular or not finite", im->path, im->xform);
  /* The voxel box's corners (indices -1/2 and n - 1/2) within reach. */
  double far = 0.0;
  for (int b = 0; b < 8; b++)
    for (int r = 0; r < 3; r++) {
      double x = im->t[r];
      for (int c = 0; c < 3; c++) x += im->A[3 * r + c] * ((b >> c & 1) ? im->n[c] - 0.5 : -0.5);
      far = isfinite(x) ? fmax(far, fabs(x)) : INFINITY;
    }
  NH_CHECK(far <= NH_IMAGE_MAX_COORDINATE, NH_ERR_INPUT,
           "%s: its voxels reach %g m from the origin (%s transform, %s units): more than %g m is "
           "not a position in a patient or a phantom (check xyzt_units and the transform)",
           im->path, far, im->xform,
           im->unit == 1.0    ? "metre"
           : im->unit == 1e-6 ? "micron"
                              : "millimetre",
           NH_IMAGE_MAX_COORDINATE);
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
  return NH_OK;
}

/* The size of `file` (a regular file within max_file_bytes: an image is
 * opened twice, for its header and for its voxels, which a stream cannot
 * be), into *size. */
static int nh_image_file_size(const char *file, const nh_read_limits *limits, double *size) {
  FILE *f;
  NH_TRY(nh_file_open_limited(file, "image", limits, &f, size));
  fclose(f);
  NH_CHECK(*size >= 0, NH_ERR_INPUT,
           "%s: not a regular file (a FIFO or a device): an image is read from a file", file);
  return NH_OK;
}

/* Header, checks and voxels of the image im->path, whose header is in
 * hdr_file (the .nii itself, or the .hdr of a pair): the voxels as labels
 * when read_data, as intensities into *values when values != NULL. */
static int nh_image_load(nh_image *im, const char *hdr_file, int read_data,
                         const nh_read_limits *limits, double **values) {
  const char *path = im->path;
  double hdr_size, img_size;
  NH_TRY(nh_image_file_size(hdr_file, limits, &hdr_size));
  nh_nifti_header h;
  NH_TRY(nh_nifti_header_read(hdr_file, &h));
  const char *ext = nifti_find_file_extension(path);
  int nii = ext && !strncmp(ext, ".nii", 4);
  NH_CHECK(nii == h.onefile, NH_ERR_INPUT,
           "%s: a %s file with a %s header (magic '%.3s'): rename it %s", path,
           nii ? ".nii" : ".hdr/.img", h.onefile ? "one-file" : "two-file",
           h.onefile ? (h.version == 2 ? "n+2" : "n+1") : (h.version == 2 ? "ni2" : "ni1"),
           nii ? "to a .hdr/.img pair" : "to .nii");
  NH_TRY(nh_nifti_header_check(path, &h));
  NH_TRY(nh_nifti_header_limits(path, &h, limits));
  for (int k = 0; k < 3; k++) im->n[k] = (int)h.dim[k + 1];
  NH_TRY(nh_image_frame(im, &h));
  char *img_file = nifti_findimgname(path, h.onefile ? NIFTI_FTYPE_NIFTI1_1 : NIFTI_FTYPE_NIFTI1_2);
  NH_CHECK(img_file, NH_ERR_INPUT, "%s: cannot find its voxel (.img) file", path);
  char where[2 * NH_ANATOMY_PATH_MAX + 32]; /* the file named, and the .img of a pair */
  if (strcmp(img_file, path))
    snprintf(where, sizeof where, "%s: its voxel file %s", path, img_file);
  else
    snprintf(where, sizeof where, "%s", path);
  int rc = nh_image_file_size(img_file, limits, &img_size);
  if (!rc && !nifti_is_gzfile(img_file)) { /* the size is known: both ways, before reading */
    double need = h.vox_offset + (double)im->n[0] * im->n[1] * im->n[2] * h.nbyper;
    if (img_size != need)
      rc = NH_ERROR(NH_ERR_INPUT,
                    "%s: %.0f bytes, but its header announces %.0f (vox_offset %.0f + %d x %d x "
                    "%d voxels of %d bytes): %s",
                    where, img_size, need, h.vox_offset, im->n[0], im->n[1], im->n[2], h.nbyper,
                    img_size < need ? "truncated" : "longer than its header says");
  }
  if (!rc && read_data) rc = nh_nifti_voxels(im, img_file, where, &h, NULL);
  if (!rc && values) {
    *values = nh_calloc((size_t)im->n[0] * im->n[1] * im->n[2], sizeof(double));
    rc = *values ? nh_nifti_voxels(im, img_file, where, &h, *values)
                 : NH_ERROR(NH_ERR_MEMORY, "out of memory: voxels of %s", where);
  }
  free(img_file);
  return rc;
}

/* nh_image_read, and the voxels as intensities into *values when values
 * != NULL. */
static int nh_image_open(const char *path, int read_data, const nh_read_limits *limits,
                         nh_image **out, double **values) {
  *out = NULL;
  if (values) *values = NULL;
  limits = nh_read_limits_or_default(limits);
  size_t len = strlen(path);
  NH_CHECK(len < NH_ANATOMY_PATH_MAX, NH_ERR_INPUT, "%s: path too long", path);
  /* libnifti2 looks for PATH.nii, PATH.hdr, ... when PATH itself has no
   * NIfTI extension: refuse that, so the file read is the file named. */
  nifti_set_debug_level(0); /* libnifti2 prints nothing (its default level, 1, does) */
  NH_CHECK(nifti_is_complete_filename(path), NH_ERR_INPUT,
           "%s: not a NIfTI file name (expected .nii, .nii.gz, .hdr or .img)", path);
  double size;
  NH_TRY(nh_image_file_size(path, limits, &size));
  char *hdr_file = nifti_findhdrname(path);
  NH_CHECK(hdr_file, NH_ERR_INPUT, "%s: cannot find its header (.hdr) file", path);
  nh_image *im = nh_calloc(1, sizeof *im);
  int rc = im ? NH_OK : NH_ERR_MEMORY;
  if (!rc) {
    memcpy(im->path, path, len + 1);
    im->refs = 1;
    im->lo[0] = 1, im->hi[0] = 0;
    rc = nh_image_load(im, hdr_file, read_data, limits, values);
  }
  free(hdr_file);
  if (rc) {
    nh_image_release(&im);
    if (values) free(*values), *values = NULL;
    return rc;
  }
  *out = im;
  return NH_OK;
}

int nh_image_read(const char *path, int read_data, const nh_read_limits *limits, nh_image **out) {
  return nh_image_open(path, read_data, limits, out, NULL);
}

int nh_image_read_values(const char *path, const nh_read_limits *limits, nh_image **out,
                         double **values) {
  return nh_image_open(path, 0, limits, out, values);
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
  int *sorted = nh_calloc(nvox, sizeof(int));
  if (!sorted) return NH_ERROR(NH_ERR_MEMORY, "out of memory: labels of %s", im->path);
  memcpy(sorted, im->label, sizeof(int) * nvox);
  qsort(sorted, nvox, sizeof(int), nh_int_compare);
  int distinct = 0;
  for (size_t v = 0; v < nvox; v++) distinct += v == 0 || sorted[v] != sorted[v - 1];
  int *l = nh_calloc((size_t)distinct, sizeof(int));
  long *c = nh_calloc((size_t)distinct, sizeof(long));
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
  im->distance = nh_calloc(nvox, sizeof(float));
  int *v = nh_calloc((size_t)nmax, sizeof(int));
  double *z = nh_calloc((size_t)(nmax + 1), sizeof(double)), *g = nh_calloc(nmax, sizeof(double));
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
  im->prefix = nh_calloc(m0 * m1 * ((size_t)n2 + 1), sizeof(int));
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
  im->inside = nh_calloc(nvox, 1);
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
  /* χ within NH_IMAGE_CHI_ROUNDOFF of 1/2 is 1/2: the voxel coordinates
   * A⁻¹ (x − t) round differently for the same world point when the image
   * is stored in another index order (flipped along i with a negative
   * spacing) or at the mirror image of x, so χ = 1/2 exactly (a point
   * midway between an inside and an outside centre, which every lattice of
   * cell-aligned sub-boxes meets) came out as 1/2 ± ulps, F as 0 or ±1e-19:
   * a lattice point in or out, a cell with no tissue or 1e-20 of it, a node
   * free or aggregated (docs/anatomy.md, "Level function"). */
  double chi = nh_image_indicator(im, x);
  if (fabs(chi - 0.5) <= NH_IMAGE_CHI_ROUNDOFF) chi = 0.5;
  double f = (0.5 - chi) * im->level_scale;
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
