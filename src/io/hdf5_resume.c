/* hdf5_resume.c — continuing the HDF5 results of an interrupted run
 * (`--restart`, nh_h5_resume): results.h5 reopened and cut back to the
 * checkpoint's step, later frame files removed, results.xdmf rebuilt.
 *
 * The run continues from its checkpoint at step S; the first run may have
 * written rows, samples and frames after S (up to its last frame or flush)
 * before it was killed. The continued run must leave the files an
 * uninterrupted run would have written, so everything after S goes:
 *   /steps               rows whose "step" column is > S
 *   /<series>            samples whose step dataset is > S (time, step and
 *                        values cut to the length all three hold)
 *   /frames/NNNNNN       links with NNNNNN > S (H5Ldelete), and their files
 *                        results_NNNNNN.h5, with any a kill left unlinked
 * and results.xdmf is rewritten for the frames kept. The handle then appends
 * as the writer's (hdf5.c) would: a frame on the mesh of the last kept one
 * links that frame's connectivity (read back here).
 *
 * Choices:
 * - Read everything first, change nothing until all of it passed: the
 *   format attribute, the /steps columns, the step column of /steps and of
 *   each series, every kept frame's layout (points [n x 3], connectivity
 *   [m x 8], fields [n] or [n x c], one Int32 point flag) for the XDMF.
 *   Only then are /steps and the series shrunk (H5Dset_extent) and later
 *   frames unlinked; the file is written (nh_h5_persist: tmp + rename) and
 *   the files of later frames are removed.
 * - A file that fails any of it is moved aside (results.h5.damaged,
 *   .damaged.2, ...), never changed, and a fresh file is started (a warning
 *   names both). A readable file that is not needlehex's, or has other step
 *   columns, is replaced (warned). No file at all: a fresh one, silently (the
 *   first run did not write HDF5).
 * - The XDMF of kept frames is rebuilt from their datasets: their arrays
 *   are listed in name order (HDF5's link order), which is the writer's
 *   order only where the writer's was alphabetical; readers look arrays up
 *   by name.
 * - /steps may end before S (rows not flushed before a kill): kept as it
 *   is, with a warning; steps.csv has the rows.
 * - Space of deleted frames and rows is not reclaimed (h5repack does). */
#include "io/hdf5_impl.h"

#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Names of the links of group `loc`, in name order (*n of them). */
static int link_names(const nh_h5 *h, hid_t loc, const char *what, int *n, char ***out) {
  *n = 0;
  *out = NULL;
  H5G_info_t info;
  if (H5Gget_info(loc, &info) < 0) return nh_h5_fail(h->path, "H5Gget_info", what);
  NH_CHECK(info.nlinks < 100000000, NH_ERR_IO, "HDF5 file '%s': '%s' has %llu members", h->path,
           what, (unsigned long long)info.nlinks);
  char **names = nh_calloc(info.nlinks ? (size_t)info.nlinks : 1, sizeof *names);
  if (!names) return NH_ERR_MEMORY;
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    ssize_t len = H5Lget_name_by_idx(loc, ".", H5_INDEX_NAME, H5_ITER_INC, i, NULL, 0, H5P_DEFAULT);
    if (len >= 0 && (names[i] = nh_calloc((size_t)len + 1, 1)) == NULL) {
      nh_h5_free_names(names, (int)i);
      return NH_ERR_MEMORY;
    }
    if (len < 0 || H5Lget_name_by_idx(loc, ".", H5_INDEX_NAME, H5_ITER_INC, i, names[i],
                                      (size_t)len + 1, H5P_DEFAULT) < 0) {
      nh_h5_free_names(names, (int)i + (len >= 0));
      return nh_h5_fail(h->path, "H5Lget_name_by_idx", what);
    }
  }
  *n = (int)info.nlinks;
  *out = names;
  return NH_OK;
}

/* Attribute `name` of object `what` as *n strings (a scalar: *n = 1);
 * absent: *n = 0 and *out = NULL. Not a variable-length string: NH_ERR_IO. */
static int read_string_attr(const nh_h5 *h, hid_t loc, const char *what, const char *name, int *n,
                            char ***out) {
  *n = 0;
  *out = NULL;
  htri_t exists = H5Aexists(loc, name);
  if (exists < 0) return nh_h5_fail(h->path, "H5Aexists", what);
  if (!exists) return NH_OK;
  int rc = NH_OK;
  char **raw = NULL;
  hssize_t count = -1;
  hid_t type = nh_h5_string_type(), ftype = H5I_INVALID_HID, space = H5I_INVALID_HID;
  hid_t attr = H5Aopen(loc, name, H5P_DEFAULT);
  if (attr >= 0) ftype = H5Aget_type(attr), space = H5Aget_space(attr);
  if (space >= 0) count = H5Sget_simple_extent_npoints(space);
  if (type < 0 || attr < 0 || ftype < 0 || count < 0) {
    rc = nh_h5_fail(h->path, "H5Aopen", name);
    goto done;
  }
  if (H5Tget_class(ftype) != H5T_STRING || H5Tis_variable_str(ftype) <= 0) {
    rc = NH_ERROR(NH_ERR_IO, "HDF5 file '%s': attribute '%s' of '%s' is not a string array",
                  h->path, name, what);
    goto done;
  }
  if (!(raw = nh_calloc(count ? (size_t)count : 1, sizeof *raw))) {
    rc = NH_ERR_MEMORY;
    goto done;
  }
  if (H5Aread(attr, type, raw) < 0) {
    rc = nh_h5_fail(h->path, "H5Aread", name);
    goto done;
  }
  char **c = nh_calloc(count ? (size_t)count : 1, sizeof *c);
  for (hssize_t i = 0; c && i < count; ++i)
    if (!(c[i] = nh_text_copy(raw[i] ? raw[i] : ""))) {
      nh_h5_free_names(c, (int)i);
      c = NULL;
    }
  if (c) {
    *n = (int)count;
    *out = c;
  } else {
    rc = NH_ERR_MEMORY;
  }
  for (hssize_t i = 0; i < count; ++i) H5free_memory(raw[i]);
done:
  free(raw);
  nh_h5_close_id(&attr, H5Aclose);
  nh_h5_close_id(&space, H5Sclose);
  nh_h5_close_id(&ftype, H5Tclose);
  nh_h5_close_id(&type, H5Tclose);
  return rc;
}

/* Rank (1..3) and dimensions of dataset `ds`. */
static int dataset_dims(const nh_h5 *h, hid_t ds, const char *what, int *rank, hsize_t dims[3]) {
  hid_t space = H5Dget_space(ds);
  *rank = space < 0 ? -1 : H5Sget_simple_extent_ndims(space);
  dims[0] = dims[1] = dims[2] = 1;
  if (*rank >= 1 && *rank <= 3) H5Sget_simple_extent_dims(space, dims, NULL);
  nh_h5_close_id(&space, H5Sclose);
  if (*rank < 1 || *rank > 3) return nh_h5_fail(h->path, "H5Sget_simple_extent_dims", what);
  return NH_OK;
}

/* Rows [0, n) of column `col` of a [n x m] dataset (col < 0: a 1-D
 * dataset), converted to double, into *out (caller frees). */
static int read_column(const nh_h5 *h, hid_t ds, const char *what, hsize_t n, int col,
                       double **out) {
  double *v = nh_calloc(n ? (size_t)n : 1, sizeof *v);
  if (!v) return NH_ERR_MEMORY;
  *out = v;
  if (n == 0) return NH_OK;
  hsize_t start[2] = {0, (hsize_t)(col < 0 ? 0 : col)}, count[2] = {n, 1};
  hid_t mspace = H5Screate_simple(1, count, NULL), fspace = H5Dget_space(ds);
  int rc = NH_OK;
  if (mspace < 0 || fspace < 0 ||
      H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start, NULL, count, NULL) < 0)
    rc = nh_h5_fail(h->path, "H5Sselect_hyperslab", what);
  else if (H5Dread(ds, H5T_NATIVE_DOUBLE, mspace, fspace, H5P_DEFAULT, v) < 0)
    rc = nh_h5_fail(h->path, "H5Dread", what);
  nh_h5_close_id(&mspace, H5Sclose);
  nh_h5_close_id(&fspace, H5Sclose);
  return rc;
}

/* Rows with a step <= `step`: the rows before the first one past it. */
static hsize_t rows_to_keep(const double *steps, hsize_t n, int step) {
  hsize_t k = 0;
  while (k < n && steps[k] <= step) ++k;
  return k;
}

/* Open series group `name` of the file: its datasets, item and component
 * names, and the number of samples with step <= `step` (*keep). */
static int series_open(nh_h5 *h, nh_h5_series *s, const char *name, int step, hsize_t *keep) {
  s->group = s->time = s->step = s->values = H5I_INVALID_HID;
  if (!(s->name = nh_text_copy(name))) return NH_ERR_MEMORY;
  s->group = H5Gopen2(h->file, name, H5P_DEFAULT);
  if (s->group < 0) return nh_h5_fail(h->path, "H5Gopen2", name);
  s->time = H5Dopen2(s->group, "time", H5P_DEFAULT);
  s->step = H5Dopen2(s->group, "step", H5P_DEFAULT);
  s->values = H5Dopen2(s->group, "values", H5P_DEFAULT);
  if (s->time < 0 || s->step < 0 || s->values < 0)
    return nh_h5_fail(h->path, "H5Dopen2", "time, step or values of a series");
  NH_TRY(read_string_attr(h, s->values, name, "names", &s->n_items, &s->items));
  NH_TRY(read_string_attr(h, s->values, name, "components", &s->n_components, &s->components));
  int rank[3];
  hsize_t dt[3], ds[3], dv[3];
  NH_TRY(dataset_dims(h, s->time, "time", &rank[0], dt));
  NH_TRY(dataset_dims(h, s->step, "step", &rank[1], ds));
  NH_TRY(dataset_dims(h, s->values, "values", &rank[2], dv));
  NH_CHECK(rank[0] == 1 && rank[1] == 1 && rank[2] == 3 && s->n_items > 0 && s->n_components > 0 &&
               dv[1] == (hsize_t)s->n_items && dv[2] == (hsize_t)s->n_components,
           NH_ERR_IO, "HDF5 file '%s': series '/%s' does not have the layout of a needlehex series",
           h->path, name);
  /* After a kill the three may differ in length: keep what all three hold. */
  hsize_t n = dt[0] < ds[0] ? dt[0] : ds[0];
  if (dv[0] < n) n = dv[0];
  double *steps = NULL;
  int rc = read_column(h, s->step, "step", n, -1, &steps);
  if (rc == NH_OK) *keep = rows_to_keep(steps, n, step);
  free(steps);
  return rc;
}

/* Shrink the series to its first `keep` samples. */
static int series_trim(nh_h5 *h, nh_h5_series *s, hsize_t keep) {
  hsize_t d1[1] = {keep}, d3[3] = {keep, (hsize_t)s->n_items, (hsize_t)s->n_components};
  if (H5Dset_extent(s->time, d1) < 0 || H5Dset_extent(s->step, d1) < 0 ||
      H5Dset_extent(s->values, d3) < 0)
    return nh_h5_fail(h->path, "H5Dset_extent", s->name);
  s->count = keep;
  return NH_OK;
}

/* The step of frame name NNNNNN (digits only), or -1. */
static long frame_step(const char *name) {
  if (!name[0] || strlen(name) > 9 || strspn(name, "0123456789") != strlen(name)) return -1;
  return strtol(name, NULL, 10);
}

/* The step of frame file results_NNNNNN.h5 (nh_h5_frame_file), or -1. */
static long frame_file_step(const char *file) {
  size_t len = strlen(file);
  if (len < 8 + 1 + 3 || len - 8 - 3 > 9 || strncmp(file, "results_", 8) ||
      strcmp(file + len - 3, ".h5"))
    return -1;
  char digits[16];
  snprintf(digits, sizeof digits, "%.*s", (int)(len - 8 - 3), file + 8);
  return frame_step(digits);
}

/* Sizes and field names of one stored frame, the layout nh_xdmf_add_frame
 * takes (no data). */
typedef struct {
  int n_names[2];
  char **names[2];
  nh_field *fields[2];
  int n_fields[2];
  int flag; /* index into names[0] of the Int32 point array, or -1 */
} stored_frame;

static void stored_frame_free(stored_frame *f) {
  for (int p = 0; p < 2; ++p) {
    nh_h5_free_names(f->names[p], f->n_names[p]);
    free(f->fields[p]);
  }
}

/* The arrays of group `grp` ("point_data" or "cell_data") of a frame: each
 * [n] or [n x c]; Int32 allowed once in point_data (the flag). */
static int stored_fields(const nh_h5 *h, hid_t frame, const char *frame_name, int pass, hsize_t n,
                         stored_frame *f) {
  const char *group = pass ? "cell_data" : "point_data";
  hid_t grp = H5Gopen2(frame, group, H5P_DEFAULT);
  if (grp < 0) return nh_h5_fail(h->path, "H5Gopen2", group);
  int rc = link_names(h, grp, group, &f->n_names[pass], &f->names[pass]);
  if (rc == NH_OK && !(f->fields[pass] = nh_calloc((size_t)f->n_names[pass] + 1, sizeof(nh_field))))
    rc = NH_ERR_MEMORY;
  for (int i = 0; rc == NH_OK && i < f->n_names[pass]; ++i) {
    const char *name = f->names[pass][i];
    hid_t ds = H5Dopen2(grp, name, H5P_DEFAULT);
    hid_t type = ds < 0 ? H5I_INVALID_HID : H5Dget_type(ds);
    H5T_class_t cls = type < 0 ? H5T_NO_CLASS : H5Tget_class(type);
    int rank = 0;
    hsize_t dims[3];
    if (ds < 0 || type < 0)
      rc = nh_h5_fail(h->path, "H5Dopen2", name);
    else
      rc = dataset_dims(h, ds, name, &rank, dims);
    nh_h5_close_id(&type, H5Tclose);
    nh_h5_close_id(&ds, H5Dclose);
    if (rc) break;
    int is_int = cls == H5T_INTEGER;
    if (rank > 2 || dims[0] != n || (cls != H5T_FLOAT && !is_int) ||
        (is_int && (pass || rank != 1 || f->flag >= 0))) {
      rc = NH_ERROR(NH_ERR_IO, "HDF5 file '%s': /frames/%s/%s/%s is not a needlehex frame array",
                    h->path, frame_name, group, name);
      break;
    }
    if (is_int)
      f->flag = i;
    else
      f->fields[pass][f->n_fields[pass]++] =
          (nh_field){name, rank == 1 ? 1 : (int)dims[1], NULL, NULL};
  }
  H5Gclose(grp);
  return rc;
}

/* The frame whose file holds the connectivity of frame `name` (opened as
 * `frame`): itself, or the one its external link points to. */
static int connectivity_owner(const nh_h5 *h, hid_t frame, const char *name, char *out,
                              size_t size) {
  H5L_info_t info;
  if (H5Lget_info(frame, "connectivity", &info, H5P_DEFAULT) < 0)
    return nh_h5_fail(h->path, "H5Lget_info", "connectivity");
  if (info.type != H5L_TYPE_EXTERNAL) {
    snprintf(out, size, "%s", name);
    return NH_OK;
  }
  char value[256];
  const char *file = NULL, *object = NULL;
  unsigned flags = 0;
  if (info.u.val_size > sizeof value ||
      H5Lget_val(frame, "connectivity", value, sizeof value, H5P_DEFAULT) < 0 ||
      H5Lunpack_elink_val(value, info.u.val_size, &flags, &file, &object) < 0)
    return nh_h5_fail(h->path, "H5Lget_val", "connectivity");
  long owner = frame_file_step(file);
  NH_CHECK(owner >= 0, NH_ERR_IO,
           "HDF5 file '%s': /frames/%s/connectivity links to '%s', not a frame file", h->path, name,
           file);
  snprintf(out, size, "%06d", (int)owner);
  return NH_OK;
}

/* Add the <Grid> of stored frame /frames/<name> to the XDMF text; when
 * `last`, remember its connectivity (a following frame on the same mesh
 * links to it, as in an uninterrupted run). */
static int stored_frame_xdmf(nh_h5 *h, const char *name, int last) {
  hid_t frame = H5Gopen2(h->frames, name, H5P_DEFAULT);
  if (frame < 0) return nh_h5_fail(h->path, "H5Gopen2", name);
  stored_frame f = {.flag = -1};
  double time = 0.0;
  int rank[2] = {0, 0}, rc = NH_OK;
  hsize_t dp[3], dc[3];
  hid_t attr = H5Aopen(frame, "time", H5P_DEFAULT);
  hid_t points = H5Dopen2(frame, "points", H5P_DEFAULT);
  hid_t conn = H5Dopen2(frame, "connectivity", H5P_DEFAULT);
  if (attr < 0 || H5Aread(attr, H5T_NATIVE_DOUBLE, &time) < 0)
    rc = nh_h5_fail(h->path, "H5Aread", "time");
  else if (points < 0 || conn < 0)
    rc = nh_h5_fail(h->path, "H5Dopen2", "points or connectivity");
  if (rc == NH_OK) rc = dataset_dims(h, points, "points", &rank[0], dp);
  if (rc == NH_OK) rc = dataset_dims(h, conn, "connectivity", &rank[1], dc);
  if (rc == NH_OK && (rank[0] != 2 || dp[1] != 3 || rank[1] != 2 || dc[1] != 8 || dp[0] > INT_MAX ||
                      dc[0] > INT_MAX / 8))
    rc = NH_ERROR(NH_ERR_IO, "HDF5 file '%s': /frames/%s is not a needlehex frame", h->path, name);
  for (int pass = 0; pass < 2 && rc == NH_OK; ++pass)
    rc = stored_fields(h, frame, name, pass, pass ? dc[0] : dp[0], &f);
  int dummy_flag = 0;
  if (rc == NH_OK) {
    nh_frame g = {.n_points = (int)dp[0],
                  .n_cells = (int)dc[0],
                  .type = NH_VTK_HEXAHEDRON,
                  .n_point_fields = f.n_fields[0],
                  .point_fields = f.fields[0],
                  .n_cell_fields = f.n_fields[1],
                  .cell_fields = f.fields[1],
                  .point_int_flags = f.flag >= 0 ? &dummy_flag : NULL,
                  .point_flag_name = f.flag >= 0 ? f.names[0][f.flag] : NULL};
    char file[32];
    nh_h5_frame_file(name, file, sizeof file);
    rc = nh_xdmf_add_frame(&h->xdmf, name, file, time, &g);
  }
  if (rc == NH_OK && last) {
    size_t n = 8 * (size_t)dc[0];
    rc = nh_realloc((void **)&h->prev_conn, n, sizeof(int));
    if (rc == NH_OK) {
      int *c = h->prev_conn;
      if (n && H5Dread(conn, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, c) < 0) {
        rc = nh_h5_fail(h->path, "H5Dread", "connectivity");
      } else {
        h->prev_cells = (int)dc[0];
        rc = connectivity_owner(h, frame, name, h->prev_frame, sizeof h->prev_frame);
      }
    }
  }
  stored_frame_free(&f);
  nh_h5_close_id(&attr, H5Aclose);
  nh_h5_close_id(&points, H5Dclose);
  nh_h5_close_id(&conn, H5Dclose);
  H5Gclose(frame);
  return rc;
}

/* Frame names in step order. */
static int by_step(const void *a, const void *b) {
  long x = frame_step(*(char *const *)a), y = frame_step(*(char *const *)b);
  return (x > y) - (x < y);
}

/* Remove DIR/results_NNNNNN.h5 with NNNNNN > step: frames cut by a resume,
 * and any written by a run killed before results.h5 linked them. */
static void remove_frame_files(const nh_h5 *h, int step) {
  DIR *d = opendir(h->dir);
  if (!d) return;
  for (struct dirent *e; (e = readdir(d));) {
    if (frame_file_step(e->d_name) <= step) continue;
    char *path = nh_text_join_path(h->dir, e->d_name);
    if (path) remove(path);
    free(path);
  }
  closedir(d);
}

/* Open h->path and cut it back to step `step` (see nh_h5_resume). On
 * failure *foreign tells a readable file that is not a needlehex results
 * file with these columns (replace it) from a damaged one (move it aside). */
static int resume_file(nh_h5 *h, const char *const *step_columns, int step_col, int step,
                       int *foreign) {
  *foreign = 0;
  int rc = NH_OK, n_cols = 0, n_frames = 0, n_format = 0;
  char **cols = NULL, **frames = NULL, **format = NULL, **members = NULL;
  int n_members = 0;
  double *steps = NULL;
  hsize_t *keep = NULL;
  hsize_t dims[3];
  int rank = 0;

  if (!nh_h5_is_hdf5(h->path))
    return NH_ERROR(NH_ERR_IO, "not an HDF5 file, or its superblock is damaged");
  h->file = H5Fopen(h->path, H5F_ACC_RDWR, h->fapl);
  if (h->file < 0) return nh_h5_fail(h->path, "H5Fopen", "/");
  NH_TRY(read_string_attr(h, h->file, "/", "format", &n_format, &format));
  int ours = n_format == 1 && strcmp(format[0], NH_H5_FORMAT_NAME) == 0;
  nh_h5_free_names(format, n_format);
  if (!ours) {
    *foreign = 1;
    return NH_ERROR(NH_ERR_IO, "'%s' was not written by needlehex (no format '%s')", h->path,
                    NH_H5_FORMAT_NAME);
  }
  h->steps = H5Dopen2(h->file, "steps", H5P_DEFAULT);
  if (h->steps < 0) return nh_h5_fail(h->path, "H5Dopen2", "/steps");
  NH_TRY(read_string_attr(h, h->steps, "/steps", "columns", &n_cols, &cols));
  int same = n_cols == h->n_step_columns && nh_h5_names_equal(cols, n_cols, step_columns);
  nh_h5_free_names(cols, n_cols);
  if (!same) {
    *foreign = 1;
    return NH_ERROR(NH_ERR_IO, "'%s' has other /steps columns than this version writes", h->path);
  }
  NH_TRY(dataset_dims(h, h->steps, "/steps", &rank, dims));
  NH_CHECK(rank == 2 && dims[1] == (hsize_t)h->n_step_columns, NH_ERR_IO,
           "HDF5 file '%s': /steps is not [rows x %d]", h->path, h->n_step_columns);
  NH_TRY(read_column(h, h->steps, "/steps", dims[0], step_col, &steps));
  hsize_t keep_steps = rows_to_keep(steps, dims[0], step);
  double last_step = keep_steps ? steps[keep_steps - 1] : 0.0;
  free(steps);
  h->frames = H5Gopen2(h->file, "frames", H5P_DEFAULT);
  if (h->frames < 0) return nh_h5_fail(h->path, "H5Gopen2", "/frames");

  /* Read everything first (a damaged file fails here, before any change). */
  if ((rc = link_names(h, h->file, "/", &n_members, &members))) goto done;
  if (!(keep = nh_calloc((size_t)n_members + 1, sizeof *keep))) {
    rc = NH_ERR_MEMORY;
    goto done;
  }
  for (int i = 0; i < n_members && rc == NH_OK; ++i) {
    if (!strcmp(members[i], "steps") || !strcmp(members[i], "frames")) continue;
    if ((rc = nh_grow((void **)&h->series, &h->cap_series, h->n_series + 1, sizeof *h->series)))
      break;
    nh_h5_series *s = &h->series[h->n_series++];
    memset(s, 0, sizeof *s);
    rc = series_open(h, s, members[i], step, &keep[h->n_series - 1]);
  }
  if (rc == NH_OK) rc = link_names(h, h->frames, "/frames", &n_frames, &frames);
  for (int i = 0; i < n_frames && rc == NH_OK; ++i)
    if (frame_step(frames[i]) < 0)
      rc = NH_ERROR(NH_ERR_IO, "HDF5 file '%s': '/frames/%s' is not a frame name", h->path,
                    frames[i]);
  if (rc) goto done;
  qsort(frames, (size_t)n_frames, sizeof *frames, by_step);
  int kept = 0;
  while (kept < n_frames && frame_step(frames[kept]) <= step) ++kept;
  for (int i = 0; i < kept && rc == NH_OK; ++i) rc = stored_frame_xdmf(h, frames[i], i == kept - 1);
  if (rc) goto done;

  /* Then cut: rows, samples and frames past the checkpoint. */
  hsize_t steps_dims[2] = {keep_steps, (hsize_t)h->n_step_columns};
  if (H5Dset_extent(h->steps, steps_dims) < 0) {
    rc = nh_h5_fail(h->path, "H5Dset_extent", "/steps");
    goto done;
  }
  h->n_steps = keep_steps;
  for (int i = 0; i < h->n_series && rc == NH_OK; ++i) rc = series_trim(h, &h->series[i], keep[i]);
  for (int i = kept; i < n_frames && rc == NH_OK; ++i)
    if (H5Ldelete(h->frames, frames[i], H5P_DEFAULT) < 0)
      rc = nh_h5_fail(h->path, "H5Ldelete", frames[i]);
  if (rc) goto done;
  h->n_frames = kept;
  if ((rc = nh_h5_persist(h->file, h->path))) goto done;
  remove_frame_files(h, step);
  if (last_step < step)
    nh_log_warn("'%s' holds /steps rows up to step %.0f only; the rows of steps %.0f to %d are "
                "missing from it (steps.csv has them)",
                h->path, last_step, last_step + 1, step);
done:
  nh_h5_free_names(members, n_members);
  nh_h5_free_names(frames, n_frames);
  free(keep);
  return rc;
}

int nh_h5_resume(const char *dir, const char *scene_text, const char *version, int n_step_columns,
                 const char *const *step_columns, int step, nh_h5 **out) {
  NH_CHECK(dir && out && n_step_columns > 0 && step_columns && step >= 0, NH_ERR_INTERNAL,
           "nh_h5_resume: NULL, empty or negative argument");
  *out = NULL;
  int step_col = -1;
  for (int j = 0; j < n_step_columns; ++j) {
    NH_CHECK(step_columns[j], NH_ERR_INTERNAL, "nh_h5_resume: step column %d has no name", j);
    if (step_col < 0 && strcmp(step_columns[j], "step") == 0) step_col = j;
  }
  NH_CHECK(step_col >= 0, NH_ERR_INTERNAL, "nh_h5_resume: no step column named 'step'");
  nh_h5 *h = nh_h5_alloc(dir, n_step_columns);
  if (!h) return NH_ERR_MEMORY;
  if (access(h->path, F_OK) != 0) { /* the first run wrote none */
    nh_h5_close(&h);
    return nh_h5_create(dir, scene_text, version, n_step_columns, step_columns, out);
  }
  int foreign = 0;
  int rc = resume_file(h, step_columns, step_col, step, &foreign);
  if (rc == NH_OK) rc = nh_xdmf_write(&h->xdmf);
  if (rc == NH_OK) {
    h->live = 1;
    *out = h;
    return NH_OK;
  }
  char reason[1024];
  snprintf(reason, sizeof reason, "%s", nh_error_message());
  char *path = nh_text_copy(h->path);
  nh_h5_close(&h); /* the file is closed before it is moved or replaced */
  if (!path || rc == NH_ERR_MEMORY) {
    free(path);
    return rc == NH_ERR_MEMORY ? rc : NH_ERR_MEMORY;
  }
  if (foreign) {
    nh_log_warn("%s; it is replaced by a new results file", reason);
  } else {
    char *aside = nh_text_aside_name(path, "damaged");
    if (!aside || rename(path, aside) != 0) {
      rc = NH_ERROR(NH_ERR_IO, "cannot resume '%s' (%s) nor move it aside to '%s.damaged': %s",
                    path, reason, path, aside ? strerror(errno) : "no free name");
      free(aside);
      free(path);
      return rc;
    }
    nh_log_warn("cannot resume '%s' (%s): moved it to '%s'; a new '%s' holds the steps after %d",
                path, reason, aside, path, step);
    free(aside);
  }
  free(path);
  nh_error_clear();
  return nh_h5_create(dir, scene_text, version, n_step_columns, step_columns, out);
}
