/* nifti.c — NIfTI-1 images on the grid of a reference image: the
 * displacement field as ITK and ANTs read it, the tissue mask, and scalar
 * images (the image resampled to the shifted anatomy). docs/anatomy.md,
 * "Displacement fields and shifted images".
 *
 * Geometry. The reference's header is read again through libnifti2 and its
 * geometry copied field by field: the sform (srow_x/y/z) and its code, the
 * qform (quaternion b, c, d, offsets, qfac in pixdim[0]) and its code, the
 * voxel sizes pixdim[1..3], so that every reader (ITK prefers the qform in
 * some versions, nibabel and FSL the sform) places the output exactly where
 * it places the reference. xyz_units is mm; a reference in m or µm has its
 * lengths converted (ITK reads lengths as mm whatever the units say).
 *
 * The displacement field follows ITK's NIfTI convention for vector images,
 * which ANTs writes and reads: dim = [5, nx, ny, nz, 1, 3] (the vector along
 * the 5th dimension, an empty time axis), intent_code NIFTI_INTENT_VECTOR
 * (1007), float32, each vector in ITK's physical frame: LPS millimetres,
 * (−u_x, −u_y, u_z) · 1000 for the scene's RAS metres. ITK reads the
 * components as they are, without the RAS flip it applies to the sform.
 *
 * Writing. libnifti2 builds the NIfTI-1 header (nifti_make_new_n1_header,
 * its defaults and magic); the bytes (header, the 4-byte extension flag 0,
 * the voxels at offset 352) go through zlib's gzip stream into an atomic file
 * (io/file.c), because libnifti2's own writer (nifti_image_write) returns no
 * status and prints its failures on stderr whatever the debug level: here a
 * full disk or a missing folder is an NH_ERR_IO naming the path, and a
 * reader never sees half a file. gzip level 1 (zlib's fastest): a float
 * field compresses little better at higher levels and costs several times
 * the time. Voxels are converted and streamed in blocks, never held whole
 * in a second copy. */
#include "io/io.h"

#include <math.h>
#include <nifti2_io.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <zlib.h>

enum { NH_NIFTI_BLOCK = 1 << 14, NH_NIFTI_CHUNK = 1 << 16 };

/* ---- a byte sink: atomic file, gzip'ed or not ---- */
typedef struct {
  nh_atomic_file a;
  int gz, failed, deflating;
  z_stream z;
  unsigned char out[NH_NIFTI_CHUNK];
} nh_nifti_sink;

static int nh_ends_with(const char *s, const char *tail) {
  size_t n = strlen(s), m = strlen(tail);
  return n >= m && strcmp(s + n - m, tail) == 0;
}

static int nh_sink_open(const char *path, nh_nifti_sink **out) {
  nh_nifti_sink *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  s->gz = nh_ends_with(path, ".gz");
  if (s->gz) {
    if (deflateInit2(&s->z, Z_BEST_SPEED, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) {
      free(s);
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: gzip stream for %s", path);
    }
    s->deflating = 1;
  }
  int rc = nh_atomic_open(path, "NIfTI file", 0, &s->a);
  if (rc) {
    if (s->deflating) deflateEnd(&s->z);
    free(s);
    return rc;
  }
  *out = s;
  return NH_OK;
}

/* Deflate what is pending with `flush`, writing full output chunks. */
static void nh_sink_deflate(nh_nifti_sink *s, int flush) {
  for (;;) {
    s->z.next_out = s->out;
    s->z.avail_out = sizeof s->out;
    int zr = deflate(&s->z, flush);
    size_t have = sizeof s->out - s->z.avail_out;
    if (zr == Z_STREAM_ERROR || (have && fwrite(s->out, 1, have, s->a.file) != have)) {
      s->failed = 1;
      return;
    }
    if (flush == Z_FINISH ? zr == Z_STREAM_END : s->z.avail_out != 0) return;
  }
}

static void nh_sink_put(nh_nifti_sink *s, const void *p, size_t n) {
  if (s->failed || n == 0) return;
  if (!s->gz) {
    s->failed = fwrite(p, 1, n, s->a.file) != n;
    return;
  }
  s->z.next_in = (Bytef *)(uintptr_t)p; /* zlib does not write through next_in */
  s->z.avail_in = (uInt)n;              /* n <= a block of voxels: fits */
  nh_sink_deflate(s, Z_NO_FLUSH);
}

static int nh_sink_close(nh_nifti_sink **sink) {
  nh_nifti_sink *s = *sink;
  *sink = NULL;
  if (s->deflating) {
    if (!s->failed) nh_sink_deflate(s, Z_FINISH);
    deflateEnd(&s->z);
  }
  int rc = nh_atomic_commit(&s->a, s->failed);
  free(s);
  return rc;
}

/* ---- the header ---- */

/* A NIfTI-1 header of dims[0..7] and `datatype` with the geometry of the
 * reference (read again from its file); *ref_nim (may be NULL) keeps the
 * reference's header for the caller (free with nifti_image_free). */
static int nh_nifti_header(const char *path, const nh_image *ref, const int64_t dims[8],
                           int datatype, nifti_1_header *hdr, nifti_image **ref_nim) {
  nifti_set_debug_level(0);
  nifti_image *nim = nifti_image_read(ref->path, 0);
  NH_CHECK(nim, NH_ERR_IO,
           "cannot write NIfTI file '%s': its reference %s cannot be read again (its geometry "
           "is copied)",
           path, ref->path);
  int same = nim->nx == ref->n[0] && nim->ny == ref->n[1] && nim->nz == ref->n[2];
  for (int d = 4; d <= 7; d++) same &= nim->dim[0] < d || nim->dim[d] <= 1;
  if (!same) {
    nifti_image_free(nim);
    return NH_ERROR(NH_ERR_IO,
                    "cannot write NIfTI file '%s': its reference %s changed since it was read",
                    path, ref->path);
  }
  for (int d = 1; d <= 3; d++)
    if (dims[d] > 32767) {
      nifti_image_free(nim);
      return NH_ERROR(NH_ERR_IO,
                      "cannot write NIfTI file '%s': %lld voxels along axis %d, above "
                      "NIfTI-1's 32767",
                      path, (long long)dims[d], d);
    }
  nifti_1_header *h = nifti_make_new_n1_header(dims, datatype);
  if (!h) {
    nifti_image_free(nim);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: NIfTI header of %s", path);
  }
  *hdr = *h;
  free(h);
  /* lengths to mm: unknown units are taken as mm, as nh_image_read does */
  double s = nim->xyz_units == NIFTI_UNITS_METER    ? 1e3
             : nim->xyz_units == NIFTI_UNITS_MICRON ? 1e-3
                                                    : 1.0;
  hdr->pixdim[0] = nim->qfac < 0 ? -1.0f : 1.0f;
  hdr->pixdim[1] = (float)(fabs(nim->dx) * s);
  hdr->pixdim[2] = (float)(fabs(nim->dy) * s);
  hdr->pixdim[3] = (float)(fabs(nim->dz) * s);
  if (nim->qform_code > 0) {
    hdr->qform_code = (short)nim->qform_code;
    hdr->quatern_b = (float)nim->quatern_b;
    hdr->quatern_c = (float)nim->quatern_c;
    hdr->quatern_d = (float)nim->quatern_d;
    hdr->qoffset_x = (float)(nim->qoffset_x * s);
    hdr->qoffset_y = (float)(nim->qoffset_y * s);
    hdr->qoffset_z = (float)(nim->qoffset_z * s);
  }
  if (nim->sform_code > 0) {
    hdr->sform_code = (short)nim->sform_code;
    for (int c = 0; c < 4; c++) {
      hdr->srow_x[c] = (float)(nim->sto_xyz.m[0][c] * s);
      hdr->srow_y[c] = (float)(nim->sto_xyz.m[1][c] * s);
      hdr->srow_z[c] = (float)(nim->sto_xyz.m[2][c] * s);
    }
  }
  hdr->xyzt_units = SPACE_TIME_TO_XYZT(NIFTI_UNITS_MM, 0);
  hdr->vox_offset = 352.0f;
  snprintf(hdr->descrip, sizeof hdr->descrip, "needlehex %s", NH_VERSION);
  if (ref_nim)
    *ref_nim = nim;
  else
    nifti_image_free(nim);
  return NH_OK;
}

/* Open the sink and write the header and the 4-byte extension flag. */
static int nh_nifti_begin(const char *path, const nifti_1_header *hdr, nh_nifti_sink **sink) {
  NH_TRY(nh_sink_open(path, sink));
  static const unsigned char no_extension[4] = {0, 0, 0, 0};
  nh_sink_put(*sink, hdr, sizeof *hdr);
  nh_sink_put(*sink, no_extension, sizeof no_extension);
  return NH_OK;
}

static size_t nh_voxels(const nh_image *ref) {
  return (size_t)ref->n[0] * (size_t)ref->n[1] * (size_t)ref->n[2];
}

int nh_nifti_write_displacement(const char *path, const nh_image *ref, const double *u) {
  const int64_t dims[8] = {5, ref->n[0], ref->n[1], ref->n[2], 1, 3, 1, 1};
  nifti_1_header hdr;
  NH_TRY(nh_nifti_header(path, ref, dims, DT_FLOAT32, &hdr, NULL));
  hdr.intent_code = NIFTI_INTENT_VECTOR;
  nh_nifti_sink *sink;
  NH_TRY(nh_nifti_begin(path, &hdr, &sink));
  const size_t nvox = nh_voxels(ref);
  const double scale[3] = {-1e3, -1e3, 1e3}; /* RAS m -> LPS mm */
  float block[NH_NIFTI_BLOCK];
  for (int c = 0; c < 3; c++)
    for (size_t v0 = 0; v0 < nvox; v0 += NH_NIFTI_BLOCK) {
      size_t n = nvox - v0 < NH_NIFTI_BLOCK ? nvox - v0 : NH_NIFTI_BLOCK;
      for (size_t i = 0; i < n; i++) block[i] = (float)(scale[c] * u[3 * (v0 + i) + c]);
      nh_sink_put(sink, block, n * sizeof(float));
    }
  return nh_sink_close(&sink);
}

int nh_nifti_write_mask(const char *path, const nh_image *ref, const unsigned char *mask) {
  const int64_t dims[8] = {3, ref->n[0], ref->n[1], ref->n[2], 1, 1, 1, 1};
  nifti_1_header hdr;
  NH_TRY(nh_nifti_header(path, ref, dims, DT_UINT8, &hdr, NULL));
  nh_nifti_sink *sink;
  NH_TRY(nh_nifti_begin(path, &hdr, &sink));
  const size_t nvox = nh_voxels(ref);
  for (size_t v0 = 0; v0 < nvox; v0 += NH_NIFTI_BLOCK)
    nh_sink_put(sink, mask + v0, nvox - v0 < NH_NIFTI_BLOCK ? nvox - v0 : NH_NIFTI_BLOCK);
  return nh_sink_close(&sink);
}

/* v rounded and clamped to [lo, hi] (NaN: 0). */
static double nh_clamp_round(double v, double lo, double hi) {
  if (isnan(v)) return 0.0;
  v = round(v);
  return v < lo ? lo : v > hi ? hi : v;
}

/* Store v as `datatype` at p; 0 for a type that is not a real number. */
static int nh_nifti_store(int datatype, double v, unsigned char *p) {
  switch (datatype) {
#define NH_STORE_INT(T, LO, HI)                                                                    \
  do {                                                                                             \
    T t_ = (T)nh_clamp_round(v, (LO), (HI));                                                       \
    memcpy(p, &t_, sizeof t_);                                                                     \
  } while (0)
  case DT_UINT8:
    NH_STORE_INT(uint8_t, 0.0, 255.0);
    return 1;
  case DT_INT8:
    NH_STORE_INT(int8_t, -128.0, 127.0);
    return 1;
  case DT_INT16:
    NH_STORE_INT(int16_t, -32768.0, 32767.0);
    return 1;
  case DT_UINT16:
    NH_STORE_INT(uint16_t, 0.0, 65535.0);
    return 1;
  case DT_INT32:
    NH_STORE_INT(int32_t, -2147483648.0, 2147483647.0);
    return 1;
  case DT_UINT32:
    NH_STORE_INT(uint32_t, 0.0, 4294967295.0);
    return 1;
  case DT_INT64: /* the doubles nearest 2^63 that a cast holds */
    NH_STORE_INT(int64_t, -9223372036854775808.0, 9223372036854774784.0);
    return 1;
  case DT_UINT64:
    NH_STORE_INT(uint64_t, 0.0, 18446744073709549568.0);
    return 1;
#undef NH_STORE_INT
  case DT_FLOAT32: {
    float f = (float)v;
    memcpy(p, &f, sizeof f);
    return 1;
  }
  case DT_FLOAT64:
    memcpy(p, &v, sizeof v);
    return 1;
  default:
    return 0;
  }
}

int nh_nifti_write_scalar(const char *path, const nh_image *ref, const double *values,
                          int as_float) {
  const int64_t dims[8] = {3, ref->n[0], ref->n[1], ref->n[2], 1, 1, 1, 1};
  nifti_1_header hdr;
  nifti_image *nim;
  NH_TRY(nh_nifti_header(path, ref, dims, DT_FLOAT32, &hdr, &nim));
  int datatype = as_float ? DT_FLOAT32 : nim->datatype;
  /* as the header stores them (float) */
  double slope = (float)nim->scl_slope, inter = (float)nim->scl_inter;
  int scaled = !as_float && isfinite(slope) && slope != 0.0 && isfinite(inter);
  unsigned char probe[8];
  int ok = nh_nifti_store(datatype, 0.0, probe);
  hdr.intent_code = (short)nim->intent_code;
  memcpy(hdr.intent_name, nim->intent_name, sizeof hdr.intent_name - 1);
  nifti_image_free(nim);
  NH_CHECK(ok, NH_ERR_IO,
           "cannot write NIfTI file '%s': the data type %s of %s is not a real number", path,
           nifti_datatype_string(datatype), ref->path);
  int nbyper, swapsize;
  nifti_datatype_sizes(datatype, &nbyper, &swapsize);
  hdr.datatype = (short)datatype;
  hdr.bitpix = (short)(8 * nbyper);
  hdr.scl_slope = scaled ? (float)slope : 0.0f;
  hdr.scl_inter = scaled ? (float)inter : 0.0f;
  nh_nifti_sink *sink;
  NH_TRY(nh_nifti_begin(path, &hdr, &sink));
  const size_t nvox = nh_voxels(ref);
  unsigned char block[8 * NH_NIFTI_BLOCK];
  for (size_t v0 = 0; v0 < nvox; v0 += NH_NIFTI_BLOCK) {
    size_t n = nvox - v0 < NH_NIFTI_BLOCK ? nvox - v0 : NH_NIFTI_BLOCK;
    for (size_t i = 0; i < n; i++) {
      double v = values[v0 + i];
      nh_nifti_store(datatype, scaled ? (v - inter) / slope : v, block + i * (size_t)nbyper);
    }
    nh_sink_put(sink, block, n * (size_t)nbyper);
  }
  return nh_sink_close(&sink);
}
