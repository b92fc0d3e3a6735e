/* hdf5.c — the HDF5 writer: results.h5 (libhdf5), its series and its frames.
 *
 * One HDF5 file per run holds every series the CSV files hold plus a mesh
 * snapshot at each output frame (an nh_frame of hexahedra, io.h):
 *
 *   /                      attributes: scene (text), version, format
 *   /steps                 float64 [N_steps x n_columns], attribute columns
 *   /<series>/time         float64 [N]          (series: probes, targets, tools)
 *   /<series>/step         int32   [N]
 *   /<series>/values       float64 [N x n_items x n_components]
 *                          attributes names (items), components
 *   /frames/NNNNNN         group, attributes step (int32), time (float64)
 *       points             float64 [n_points x 3]   current positions
 *       connectivity       int32   [n_cells x 8]    VTK/XDMF hexahedron order
 *       point_data/<name>  float64 [n_points] or [n_points x c]; int32 flag
 *       cell_data/<name>   float64 [n_cells] or [n_cells x c]
 *
 * After each frame results.xdmf, the XDMF index of the frames (xdmf.c), is
 * rewritten to list it. A run continued from a checkpoint (`--restart`)
 * reopens and cuts back the file (hdf5_resume.c) and then appends here.
 *
 * Choices:
 * - Steps and series are chunked datasets with an unlimited first dimension,
 *   extended by one row per call (H5Dset_extent + a one-row hyperslab). The
 *   handles stay open for the whole run.
 * - Frames are contiguous (not chunked, not compressed): written once, read
 *   whole. Each frame is its own file DIR/results_NNNNNN.h5 (attributes and
 *   arrays at its root), reached from results.h5 by the external link
 *   /frames/NNNNNN. When a frame's connectivity equals the previous frame's
 *   (the mesh did not change), "connectivity" is an external link to the
 *   dataset in the frame file that holds it (never to another link: HDF5
 *   follows at most 16 in a row), instead of a copy.
 * - Durability: HDF5 never touches the disk. Every file is built in memory
 *   (the core driver, no backing store) and nh_h5_persist writes its image
 *   (H5Fget_file_image) through nh_atomic_open/commit: "<path>.tmp", renamed.
 *   At each frame: the frame file, then results.h5 (linking it), then
 *   results.xdmf, so at any instant every listed frame is complete and every
 *   file opens: a SIGKILL leaves the previous or the new version of each
 *   (0 unreadable files in 300 trials of tests/hdf5_readback.py kill). A full
 *   disk fails in nh_atomic_commit with the OS reason and the tmp file removed;
 *   HDF5 has nothing to flush at close, so no failing H5Fclose is left for
 *   its atexit handler (with files on disk, a full disk made H5Fclose fail
 *   and the handler then crashed in H5F__close_cb). Rows appended after the
 *   last frame reach the disk at the next frame, nh_h5_flush or nh_h5_close.
 *   Cost: results.h5 is rewritten whole at each frame (steps and series:
 *   hundreds of KB for hundreds of steps); measured on
 *   cases/needle-phantom.yaml with a frame every step, 4.3 s against 6.3 s
 *   for the former H5Fflush of one file on disk. The former design (one file
 *   flushed in place) left 1 damaged file in 300 kill trials and 2 in 200
 *   when kills were aimed at a flush: HDF5 1.10 without SWMR does not order
 *   its metadata writes. SWMR is not used: it forbids creating groups and
 *   datasets once started, and a killed SWMR writer's file needs h5clear.
 * - The file uses the library's default (oldest compatible) format, readable
 *   by any HDF5 1.8+ tool (h5py, h5dump, ParaView, MATLAB).
 * - Strings (scene text, names) are variable-length UTF-8 attributes: h5py
 *   returns them as str. Their bytes live in the global heap, so the scene
 *   text has no 64 KiB attribute limit (1 MB tested).
 * - The HDF5 error stack is handled here only (for the resume too): it is
 *   silenced (H5Eset_auto2 with NULL, a process-wide setting, in nh_h5_alloc)
 *   and a failure becomes one NH_ERR_IO message (nh_h5_fail) naming the file,
 *   the HDF5 call, the object and HDF5's innermost reason.
 * - HDF5 frees its global state in its own atexit handler: LeakSanitizer
 *   reports nothing without an explicit H5close, which would also close any
 *   other HDF5 object of the process. */
#include "io/hdf5_impl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHUNK_BYTES 16384

/* ---- small helpers ---- */

void nh_h5_frame_file(const char *frame, char *out, size_t size) {
  snprintf(out, size, "results_%s.h5", frame);
}

/* File access entirely in memory: HDF5's core driver without a backing
 * store, so HDF5 itself never reads or writes the disk after opening. */
static hid_t memory_fapl(void) {
  hid_t fapl = H5Pcreate(H5P_FILE_ACCESS);
  if (fapl >= 0 && H5Pset_fapl_core(fapl, (size_t)1 << 20, 0) < 0) {
    H5Pclose(fapl);
    return H5I_INVALID_HID;
  }
  return fapl;
}

/* A full disk or a read-only folder is NH_ERR_IO with the OS reason; the
 * previous `path` is untouched. */
int nh_h5_persist(hid_t file, const char *path) {
  if (H5Fflush(file, H5F_SCOPE_GLOBAL) < 0) return nh_h5_fail(path, "H5Fflush", "/");
  ssize_t n = H5Fget_file_image(file, NULL, 0);
  if (n < 0) return nh_h5_fail(path, "H5Fget_file_image", "/");
  void *image = nh_calloc(n > 0 ? (size_t)n : 1, 1);
  if (!image) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing '%s' (%zd bytes)", path, n);
  int rc = NH_OK;
  nh_atomic_file a;
  if (H5Fget_file_image(file, image, (size_t)n) != n)
    rc = nh_h5_fail(path, "H5Fget_file_image", "/");
  else if ((rc = nh_atomic_open(path, "HDF5 file", 0, &a)) == NH_OK)
    rc = nh_atomic_commit(&a, n > 0 && fwrite(image, 1, (size_t)n, a.file) != (size_t)n);
  free(image);
  return rc;
}

/* HDF5's innermost error description (where the error was detected). */
static herr_t innermost_cb(unsigned n, const H5E_error2_t *err, void *data) {
  if (n == 0 && err->desc) snprintf(data, 240, "%s", err->desc);
  return 0;
}

int nh_h5_fail(const char *path, const char *call, const char *object) {
  char reason[240] = "";
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, innermost_cb, reason);
  H5Eclear2(H5E_DEFAULT);
  return NH_ERROR(NH_ERR_IO, "HDF5 file '%s': %s failed on '%s'%s%s", path, call, object,
                  reason[0] ? ": " : "", reason);
}

int nh_h5_is_hdf5(const char *path) {
  htri_t is_hdf5 = H5Fis_hdf5(path);
  if (is_hdf5 <= 0) H5Eclear2(H5E_DEFAULT);
  return is_hdf5 > 0;
}

void nh_h5_close_id(hid_t *id, herr_t (*close)(hid_t)) {
  if (*id >= 0) close(*id);
  *id = H5I_INVALID_HID;
}

/* A link name: non-empty, no '/' (HDF5 path separator), no ':' (the XDMF
 * "file:path" separator), not "." (HDF5's current group). */
static int valid_name(const char *s) {
  return s && s[0] && !strpbrk(s, "/:") && strcmp(s, ".") != 0;
}

hid_t nh_h5_string_type(void) {
  hid_t t = H5Tcopy(H5T_C_S1);
  if (t < 0) return t;
  if (H5Tset_size(t, H5T_VARIABLE) < 0 || H5Tset_cset(t, H5T_CSET_UTF8) < 0) {
    H5Tclose(t);
    return H5I_INVALID_HID;
  }
  return t;
}

/* Attribute `name` on `loc`: `n` strings (n < 0: one scalar string). */
static int write_string_attr(const nh_h5 *h, hid_t loc, const char *name, int n,
                             const char *const *strings) {
  int rc = NH_OK;
  hsize_t dims[1] = {(hsize_t)(n < 0 ? 1 : n)};
  hid_t type = nh_h5_string_type();
  hid_t space = n < 0 ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, dims, NULL);
  hid_t attr = H5I_INVALID_HID;
  if (type < 0 || space < 0) {
    rc = nh_h5_fail(h->path, "H5Screate", name);
    goto done;
  }
  attr = H5Acreate2(loc, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  if (attr < 0) {
    rc = nh_h5_fail(h->path, "H5Acreate2", name);
    goto done;
  }
  if (H5Awrite(attr, type, strings) < 0) rc = nh_h5_fail(h->path, "H5Awrite", name);
done:
  nh_h5_close_id(&attr, H5Aclose);
  nh_h5_close_id(&space, H5Sclose);
  nh_h5_close_id(&type, H5Tclose);
  return rc;
}

/* Scalar numeric attribute (file type `ftype`, memory type `mtype`). */
static int write_scalar_attr(const nh_h5 *h, hid_t loc, const char *name, hid_t ftype, hid_t mtype,
                             const void *value) {
  int rc = NH_OK;
  hid_t space = H5Screate(H5S_SCALAR);
  hid_t attr =
      space < 0 ? H5I_INVALID_HID : H5Acreate2(loc, name, ftype, space, H5P_DEFAULT, H5P_DEFAULT);
  if (attr < 0 || H5Awrite(attr, mtype, value) < 0) rc = nh_h5_fail(h->path, "H5Acreate2", name);
  nh_h5_close_id(&attr, H5Aclose);
  nh_h5_close_id(&space, H5Sclose);
  return rc;
}

/* A chunked dataset of shape [0 x row_dims...] extendible along the first
 * dimension; rank <= 3. Returns the dataset id or a negative value (error
 * recorded). */
static hid_t create_extendible(const nh_h5 *h, hid_t loc, const char *name, hid_t ftype,
                               size_t elem_bytes, int rank, const hsize_t *row_dims) {
  hsize_t dims[3] = {0, 1, 1}, maxdims[3] = {H5S_UNLIMITED, 1, 1}, chunk[3] = {1, 1, 1};
  size_t row_bytes = elem_bytes;
  for (int d = 1; d < rank; ++d) {
    dims[d] = maxdims[d] = chunk[d] = row_dims[d - 1];
    row_bytes *= (size_t)row_dims[d - 1];
  }
  chunk[0] = row_bytes < CHUNK_BYTES ? CHUNK_BYTES / row_bytes : 1;
  hid_t space = H5Screate_simple(rank, dims, maxdims);
  hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  hid_t ds = H5I_INVALID_HID;
  if (space < 0 || dcpl < 0 || H5Pset_chunk(dcpl, rank, chunk) < 0) {
    nh_h5_fail(h->path, "H5Pset_chunk", name);
  } else {
    ds = H5Dcreate2(loc, name, ftype, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    if (ds < 0) nh_h5_fail(h->path, "H5Dcreate2", name);
  }
  nh_h5_close_id(&dcpl, H5Pclose);
  nh_h5_close_id(&space, H5Sclose);
  return ds < 0 ? H5I_INVALID_HID : ds;
}

/* Append row number `row` (the current length) to an extendible dataset. */
static int append_row(const nh_h5 *h, hid_t ds, const char *name, hid_t mtype, hsize_t row,
                      const void *data) {
  hsize_t dims[3] = {0, 1, 1}, start[3] = {row, 0, 0}, count[3] = {1, 1, 1};
  hid_t fspace = H5Dget_space(ds);
  int rank = fspace < 0 ? -1 : H5Sget_simple_extent_ndims(fspace);
  if (rank >= 1 && rank <= 3) H5Sget_simple_extent_dims(fspace, dims, NULL);
  nh_h5_close_id(&fspace, H5Sclose);
  if (rank < 1 || rank > 3) return nh_h5_fail(h->path, "H5Sget_simple_extent_dims", name);
  dims[0] = row + 1;
  if (H5Dset_extent(ds, dims) < 0) return nh_h5_fail(h->path, "H5Dset_extent", name);
  for (int d = 1; d < rank; ++d) count[d] = dims[d];
  int rc = NH_OK;
  hid_t mspace = H5Screate_simple(rank, count, NULL);
  fspace = H5Dget_space(ds);
  if (mspace < 0 || fspace < 0 ||
      H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start, NULL, count, NULL) < 0)
    rc = nh_h5_fail(h->path, "H5Sselect_hyperslab", name);
  else if (H5Dwrite(ds, mtype, mspace, fspace, H5P_DEFAULT, data) < 0)
    rc = nh_h5_fail(h->path, "H5Dwrite", name);
  nh_h5_close_id(&mspace, H5Sclose);
  nh_h5_close_id(&fspace, H5Sclose);
  return rc;
}

/* A contiguous dataset [n] (components == 1) or [n x components], written
 * whole from `data`. */
static int write_array(const nh_h5 *h, hid_t loc, const char *name, hid_t ftype, hid_t mtype, int n,
                       int components, const void *data) {
  int rc = NH_OK;
  hsize_t dims[2] = {(hsize_t)n, (hsize_t)components};
  hid_t space = H5Screate_simple(components == 1 ? 1 : 2, dims, NULL);
  hid_t ds = space < 0 ? H5I_INVALID_HID
                       : H5Dcreate2(loc, name, ftype, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (ds < 0)
    rc = nh_h5_fail(h->path, "H5Dcreate2", name);
  else if (n > 0 && H5Dwrite(ds, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
    rc = nh_h5_fail(h->path, "H5Dwrite", name);
  nh_h5_close_id(&ds, H5Dclose);
  nh_h5_close_id(&space, H5Sclose);
  return rc;
}

/* ---- create / close ---- */

nh_h5 *nh_h5_alloc(const char *dir, int n_step_columns) {
  nh_h5 *h = nh_calloc(1, sizeof *h);
  if (!h) return NULL;
  h->file = h->frames = h->steps = H5I_INVALID_HID;
  h->prev_cells = -1;
  h->n_step_columns = n_step_columns;
  H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
  h->dir = nh_text_copy(dir);
  h->path = nh_text_join_path(dir, NH_H5_FILE_NAME);
  h->xdmf.path = nh_text_join_path(dir, NH_H5_XDMF_NAME);
  h->fapl = memory_fapl();
  if (!h->dir || !h->path || !h->xdmf.path || h->fapl < 0) {
    if (h->fapl >= 0) H5Pclose(h->fapl);
    free(h->dir);
    free(h->path);
    nh_xdmf_free(&h->xdmf);
    free(h);
    return NULL;
  }
  return h;
}

int nh_h5_create(const char *dir, const char *scene_text, const char *version, int n_step_columns,
                 const char *const *step_columns, nh_h5 **out) {
  NH_CHECK(dir && out && n_step_columns > 0 && step_columns, NH_ERR_INTERNAL,
           "nh_h5_create: NULL or empty argument");
  *out = NULL;
  for (int j = 0; j < n_step_columns; ++j)
    NH_CHECK(step_columns[j], NH_ERR_INTERNAL, "nh_h5_create: step column %d has no name", j);
  nh_h5 *h = nh_h5_alloc(dir, n_step_columns);
  if (!h) return NH_ERR_MEMORY;
  int rc = NH_OK;
  h->file = H5Fcreate(h->path, H5F_ACC_TRUNC, H5P_DEFAULT, h->fapl);
  if (h->file < 0) {
    rc = nh_h5_fail(h->path, "H5Fcreate", "/");
    goto fail;
  }
  const char *format = NH_H5_FORMAT_NAME;
  if ((rc = write_string_attr(h, h->file, "format", -1, &format))) goto fail;
  if (version && (rc = write_string_attr(h, h->file, "version", -1, &version))) goto fail;
  if (scene_text && (rc = write_string_attr(h, h->file, "scene", -1, &scene_text))) goto fail;

  hsize_t row[1] = {(hsize_t)n_step_columns};
  h->steps = create_extendible(h, h->file, "steps", H5T_IEEE_F64LE, 8, 2, row);
  if (h->steps < 0) {
    rc = NH_ERR_IO;
    goto fail;
  }
  if ((rc = write_string_attr(h, h->steps, "columns", n_step_columns, step_columns))) goto fail;
  h->frames = H5Gcreate2(h->file, "frames", H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (h->frames < 0) {
    rc = nh_h5_fail(h->path, "H5Gcreate2", "/frames");
    goto fail;
  }
  if ((rc = nh_h5_persist(h->file, h->path))) goto fail;
  if ((rc = nh_xdmf_write(&h->xdmf))) goto fail;
  h->live = 1;
  *out = h;
  return NH_OK;
fail:
  nh_h5_close(&h);
  return rc;
}

int nh_h5_flush(nh_h5 *h) {
  NH_CHECK(h, NH_ERR_INTERNAL, "nh_h5_flush: NULL argument");
  return nh_h5_persist(h->file, h->path);
}

void nh_h5_free_names(char **names, int n) {
  if (!names) return;
  for (int i = 0; i < n; ++i) free(names[i]);
  free(names);
}

int nh_h5_close(nh_h5 **hp) {
  if (!hp || !*hp) return NH_OK;
  nh_h5 *h = *hp;
  int rc = NH_OK;
  for (int i = 0; i < h->n_series; ++i) {
    nh_h5_series *s = &h->series[i];
    nh_h5_close_id(&s->time, H5Dclose);
    nh_h5_close_id(&s->step, H5Dclose);
    nh_h5_close_id(&s->values, H5Dclose);
    nh_h5_close_id(&s->group, H5Gclose);
    free(s->name);
    nh_h5_free_names(s->items, s->n_items);
    nh_h5_free_names(s->components, s->n_components);
  }
  free(h->series);
  nh_h5_close_id(&h->steps, H5Dclose);
  nh_h5_close_id(&h->frames, H5Gclose);
  /* The file lives in memory: writing it is the one step that can meet a
   * full disk, and closing it afterwards cannot fail for want of space. */
  if (h->file >= 0 && h->live) rc = nh_h5_persist(h->file, h->path);
  if (h->file >= 0) H5Fclose(h->file);
  H5Pclose(h->fapl);
  free(h->dir);
  free(h->prev_conn);
  free(h->path);
  nh_xdmf_free(&h->xdmf);
  free(h);
  *hp = NULL;
  return rc;
}

/* ---- rows ---- */

int nh_h5_append_steps(nh_h5 *h, const double *row) {
  NH_CHECK(h && row, NH_ERR_INTERNAL, "nh_h5_append_steps: NULL argument");
  NH_TRY(append_row(h, h->steps, "/steps", H5T_NATIVE_DOUBLE, h->n_steps, row));
  h->n_steps++;
  return NH_OK;
}

int nh_h5_names_equal(char **stored, int n, const char *const *names) {
  for (int i = 0; i < n; ++i)
    if (!names[i] || strcmp(stored[i], names[i]) != 0) return 0;
  return 1;
}

static int copy_names(int n, const char *const *names, char ***out) {
  char **c = nh_calloc((size_t)n, sizeof *c);
  if (!c) return NH_ERR_MEMORY;
  for (int i = 0; i < n; ++i) {
    if (!(c[i] = nh_text_copy(names[i]))) {
      nh_h5_free_names(c, n);
      return NH_ERR_MEMORY;
    }
  }
  *out = c;
  return NH_OK;
}

/* Create series group `name` with its three datasets and attributes. */
static int series_create(nh_h5 *h, nh_h5_series *s, const char *name, int n_items,
                         const char *const *items, int n_components,
                         const char *const *components) {
  s->group = s->time = s->step = s->values = H5I_INVALID_HID;
  s->n_items = n_items;
  s->n_components = n_components;
  if (!(s->name = nh_text_copy(name))) return NH_ERR_MEMORY;
  NH_TRY(copy_names(n_items, items, &s->items));
  NH_TRY(copy_names(n_components, components, &s->components));
  s->group = H5Gcreate2(h->file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (s->group < 0) return nh_h5_fail(h->path, "H5Gcreate2", name);
  hsize_t row[2] = {(hsize_t)n_items, (hsize_t)n_components};
  s->time = create_extendible(h, s->group, "time", H5T_IEEE_F64LE, 8, 1, NULL);
  if (s->time < 0) return NH_ERR_IO;
  s->step = create_extendible(h, s->group, "step", H5T_STD_I32LE, 4, 1, NULL);
  if (s->step < 0) return NH_ERR_IO;
  s->values = create_extendible(h, s->group, "values", H5T_IEEE_F64LE, 8, 3, row);
  if (s->values < 0) return NH_ERR_IO;
  NH_TRY(write_string_attr(h, s->values, "names", n_items, items));
  return write_string_attr(h, s->values, "components", n_components, components);
}

int nh_h5_append_series(nh_h5 *h, const char *group, int step, double time, int n_items,
                        const char *const *items, int n_components, const char *const *components,
                        const double *values) {
  NH_CHECK(h && items && components && values, NH_ERR_INTERNAL,
           "nh_h5_append_series: NULL argument");
  NH_CHECK(valid_name(group) && strcmp(group, "steps") && strcmp(group, "frames"), NH_ERR_INTERNAL,
           "nh_h5_append_series: '%s' cannot name a series group", group ? group : "(null)");
  NH_CHECK(n_items > 0 && n_components > 0, NH_ERR_INTERNAL,
           "nh_h5_append_series('%s'): %d items x %d components; both must be positive", group,
           n_items, n_components);
  for (int i = 0; i < n_items; ++i)
    NH_CHECK(items[i], NH_ERR_INTERNAL, "nh_h5_append_series('%s'): item %d has no name", group, i);
  for (int i = 0; i < n_components; ++i)
    NH_CHECK(components[i], NH_ERR_INTERNAL, "nh_h5_append_series('%s'): component %d has no name",
             group, i);
  nh_h5_series *s = NULL;
  for (int i = 0; i < h->n_series && !s; ++i)
    if (strcmp(h->series[i].name, group) == 0) s = &h->series[i];
  if (!s) {
    NH_TRY(nh_grow((void **)&h->series, &h->cap_series, h->n_series + 1, sizeof *h->series));
    s = &h->series[h->n_series++];
    memset(s, 0, sizeof *s);
    NH_TRY(series_create(h, s, group, n_items, items, n_components, components));
  } else {
    NH_CHECK(s->n_items == n_items && s->n_components == n_components &&
                 nh_h5_names_equal(s->items, n_items, items) &&
                 nh_h5_names_equal(s->components, n_components, components),
             NH_ERR_INTERNAL,
             "nh_h5_append_series('%s'): %d items x %d components differ from the first call "
             "(%d x %d, or other names)",
             group, n_items, n_components, s->n_items, s->n_components);
  }
  NH_TRY(append_row(h, s->time, "time", H5T_NATIVE_DOUBLE, s->count, &time));
  NH_TRY(append_row(h, s->step, "step", H5T_NATIVE_INT, s->count, &step));
  NH_TRY(append_row(h, s->values, "values", H5T_NATIVE_DOUBLE, s->count, values));
  s->count++;
  return NH_OK;
}

/* ---- frames ---- */

/* What the frame writer relies on; a failure is a bug in the caller. */
static int check_frame_grid(const nh_h5 *h, const nh_frame *g) {
  NH_CHECK(g->n_points >= 0 && g->n_cells >= 0, NH_ERR_INTERNAL,
           "HDF5 frame in '%s': negative size (%d points, %d cells)", h->path, g->n_points,
           g->n_cells);
  NH_CHECK(g->n_points == 0 || g->points, NH_ERR_INTERNAL, "HDF5 frame in '%s': points missing",
           h->path);
  NH_CHECK(g->n_cells == 0 || g->connectivity, NH_ERR_INTERNAL,
           "HDF5 frame in '%s': connectivity missing", h->path);
  for (int c = 0; c < g->n_cells; ++c) {
    int type = g->types ? g->types[c] : g->type;
    NH_CHECK(type == NH_VTK_HEXAHEDRON && (!g->offsets || g->offsets[c] == 8 * (c + 1)),
             NH_ERR_INTERNAL, "HDF5 frame in '%s': cell %d is not an 8-node hexahedron", h->path,
             c);
  }
  for (long k = 0; k < 8L * g->n_cells; ++k)
    NH_CHECK(g->connectivity[k] >= 0 && g->connectivity[k] < g->n_points, NH_ERR_INTERNAL,
             "HDF5 frame in '%s': connectivity[%ld] = %d outside [0, %d)", h->path, k,
             g->connectivity[k], g->n_points);
  for (int pass = 0; pass < 2; ++pass) {
    int n = pass ? g->n_cell_fields : g->n_point_fields;
    const nh_field *f = pass ? g->cell_fields : g->point_fields;
    int tuples = pass ? g->n_cells : g->n_points;
    NH_CHECK(n == 0 || f, NH_ERR_INTERNAL, "HDF5 frame in '%s': fields missing", h->path);
    for (int i = 0; i < n; ++i)
      NH_CHECK(valid_name(f[i].name) && f[i].components >= 1 && (tuples == 0 || f[i].data),
               NH_ERR_INTERNAL,
               "HDF5 frame in '%s': %s field %d ('%s') has a bad name, no components or no data",
               h->path, pass ? "cell" : "point", i, f[i].name ? f[i].name : "(null)");
  }
  NH_CHECK(!g->point_int_flags || !g->point_flag_name || valid_name(g->point_flag_name),
           NH_ERR_INTERNAL, "HDF5 frame in '%s': bad flag name '%s'", h->path, g->point_flag_name);
  return NH_OK;
}

/* Connectivity: an external link to the dataset of the frame file that holds
 * it when the mesh did not change (always the file that wrote it, never a
 * chain of links), else a new [n_cells x 8] dataset (remembered for the next). */
static int write_connectivity(nh_h5 *h, hid_t frame, const char *frame_name, const nh_frame *g) {
  size_t n = 8 * (size_t)g->n_cells;
  if (h->prev_cells == g->n_cells && g->n_cells > 0 &&
      memcmp(h->prev_conn, g->connectivity, n * sizeof(int)) == 0) {
    char target[32];
    nh_h5_frame_file(h->prev_frame, target, sizeof target);
    if (H5Lcreate_external(target, "/connectivity", frame, "connectivity", H5P_DEFAULT,
                           H5P_DEFAULT) < 0)
      return nh_h5_fail(h->path, "H5Lcreate_external", target);
    return NH_OK;
  }
  NH_TRY(write_array(h, frame, "connectivity", H5T_STD_I32LE, H5T_NATIVE_INT, g->n_cells, 8,
                     g->connectivity));
  NH_TRY(nh_realloc((void **)&h->prev_conn, n, sizeof(int)));
  if (n) memcpy(h->prev_conn, g->connectivity, n * sizeof(int));
  h->prev_cells = g->n_cells;
  snprintf(h->prev_frame, sizeof h->prev_frame, "%s", frame_name);
  return NH_OK;
}

static int write_frame_data(nh_h5 *h, hid_t frame, const char *frame_name, int step, double time,
                            const nh_frame *g) {
  NH_TRY(write_scalar_attr(h, frame, "step", H5T_STD_I32LE, H5T_NATIVE_INT, &step));
  NH_TRY(write_scalar_attr(h, frame, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &time));
  NH_TRY(write_array(h, frame, "points", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, g->n_points, 3,
                     g->points));
  NH_TRY(write_connectivity(h, frame, frame_name, g));
  int rc = NH_OK;
  for (int pass = 0; pass < 2 && rc == NH_OK; ++pass) {
    const char *name = pass ? "cell_data" : "point_data";
    hid_t grp = H5Gcreate2(frame, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (grp < 0) return nh_h5_fail(h->path, "H5Gcreate2", name);
    int n = pass ? g->n_cell_fields : g->n_point_fields;
    const nh_field *f = pass ? g->cell_fields : g->point_fields;
    int tuples = pass ? g->n_cells : g->n_points;
    for (int i = 0; i < n && rc == NH_OK; ++i)
      rc = write_array(h, grp, f[i].name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, tuples,
                       f[i].components, f[i].data);
    if (rc == NH_OK && !pass && g->point_int_flags)
      rc = write_array(h, grp, g->point_flag_name ? g->point_flag_name : "flag", H5T_STD_I32LE,
                       H5T_NATIVE_INT, g->n_points, 1, g->point_int_flags);
    H5Gclose(grp);
  }
  return rc;
}

int nh_h5_write_frame(nh_h5 *h, int step, double time, const nh_frame *grid) {
  NH_CHECK(h && grid, NH_ERR_INTERNAL, "nh_h5_write_frame: NULL argument");
  NH_CHECK(step >= 0 && step <= 999999999, NH_ERR_INTERNAL,
           "nh_h5_write_frame: step %d outside [0, 999999999]", step);
  NH_TRY(check_frame_grid(h, grid));
  char name[16];
  snprintf(name, sizeof name, "%06d", step);
  htri_t exists = H5Lexists(h->frames, name, H5P_DEFAULT);
  NH_CHECK(exists == 0, NH_ERR_INTERNAL, "HDF5 file '%s': frame /frames/%s written twice", h->path,
           name);
  char file[32];
  nh_h5_frame_file(name, file, sizeof file);
  char *path = nh_text_join_path(h->dir, file);
  if (!path) return NH_ERR_MEMORY;
  /* The frame file first (complete on disk, or absent), then results.h5
   * linking it, then the XDMF listing it: each renamed into place. */
  hid_t frame = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, h->fapl);
  int rc = frame < 0 ? nh_h5_fail(path, "H5Fcreate", "/") : NH_OK;
  if (rc == NH_OK) rc = write_frame_data(h, frame, name, step, time, grid);
  if (rc == NH_OK) rc = nh_h5_persist(frame, path);
  if (frame >= 0) H5Fclose(frame);
  free(path);
  if (rc) { /* a frame not on disk is no frame to link to */
    h->prev_cells = -1;
    return rc;
  }
  if (H5Lcreate_external(file, "/", h->frames, name, H5P_DEFAULT, H5P_DEFAULT) < 0)
    return nh_h5_fail(h->path, "H5Lcreate_external", name);
  NH_TRY(nh_h5_persist(h->file, h->path));
  NH_TRY(nh_xdmf_add_frame(&h->xdmf, name, file, time, grid));
  h->n_frames++;
  return nh_xdmf_write(&h->xdmf);
}
