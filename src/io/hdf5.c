/* hdf5.c — results.h5 (libhdf5) and its XDMF description results.xdmf.
 *
 * One HDF5 file per run holds every series the CSV files hold plus a mesh
 * snapshot at each output frame:
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
 * results.xdmf (XDMF 3) is a Temporal Collection of Uniform grids, one per
 * frame, whose Topology (Hexahedron), Geometry (XYZ) and Attributes
 * (Node/Cell) reference the datasets above as "results.h5:/frames/...". Each
 * frame carries its own topology and geometry, so frames of a refined mesh
 * (other node and cell counts) are ordinary members of the series.
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
 *   (the core driver, no backing store) and persist() writes its image
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
 * - Resume (nh_h5_resume, `--restart`): results.h5 is read into memory,
 *   every check and read is done first (format, columns, the step column of
 *   /steps and of each series, every kept frame's layout for the XDMF), then
 *   /steps and the series are shrunk with H5Dset_extent and later frames
 *   unlinked (H5Ldelete); the file is written, the files of later frames
 *   are removed, and results.xdmf is rewritten. A file that fails any of it
 *   is moved aside (results.h5.damaged), never changed; the XDMF of kept
 *   frames lists their arrays in name order.
 * - The file uses the library's default (oldest compatible) format, readable
 *   by any HDF5 1.8+ tool (h5py, h5dump, ParaView, MATLAB).
 * - Strings (scene text, names) are variable-length UTF-8 attributes: h5py
 *   returns them as str. Their bytes live in the global heap, so the scene
 *   text has no 64 KiB attribute limit (1 MB tested).
 * - The HDF5 error stack is silenced (H5Eset_auto2 with NULL, a process-wide
 *   setting); a failure becomes one NH_ERR_IO message
 *   naming the file, the HDF5 call, the object and HDF5's innermost reason.
 * - HDF5 frees its global state in its own atexit handler: LeakSanitizer
 *   reports nothing without an explicit H5close, which would also close any
 *   other HDF5 object of the process. */
#include "io/io_impl.h"

#include <dirent.h>
#include <errno.h>
#include <hdf5.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define H5_FILE_NAME   "results.h5"
#define XDMF_FILE_NAME "results.xdmf"
#define FORMAT_NAME    "needlehex-results 1"
#define CHUNK_BYTES    16384

/* One time series group (/probes, /targets, /tools, ...). */
typedef struct {
  char *name;
  hid_t group, time, step, values;
  int n_items, n_components;
  char **items, **components; /* fixed at the first append, checked after */
  hsize_t count;
} h5_series;

struct nh_h5 {
  char *dir;
  char *path;         /* DIR/results.h5 */
  char *xdmf_path;    /* DIR/results.xdmf */
  hid_t file, frames; /* results.h5, held in memory (see "Durability") */
  hid_t fapl;         /* HDF5's core driver without a backing store */
  int live;           /* created or resumed: nh_h5_close writes the file */
  hid_t steps;
  int n_step_columns;
  hsize_t n_steps;
  int n_series, cap_series;
  h5_series *series;
  nh_text grids; /* XDMF <Grid> elements of the frames written so far */
  int n_frames;
  int prev_cells;      /* cells of the previous frame (-1: none) */
  int *prev_conn;      /* its connectivity, 8 * prev_cells ints */
  char prev_frame[16]; /* the frame whose file holds that connectivity dataset */
};

/* ---- small helpers ---- */

static char *copy_string(const char *s) {
  char *c = nh_calloc(strlen(s) + 1, 1);
  if (c) strcpy(c, s);
  return c;
}

static char *join_path(const char *dir, const char *name) {
  size_t n = strlen(dir) + strlen(name) + 2;
  char *p = nh_calloc(n, 1);
  if (p) snprintf(p, n, "%s/%s", dir, name);
  return p;
}

/* The file of frame NNNNNN, relative to the results folder. */
static void frame_file(const char *frame, char *out, size_t size) {
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

static int h5_fail(const char *path, const char *call, const char *object);

/* Write the image of in-memory file `file` to `path` atomically
 * (nh_atomic_open: tmp, rename; no fsync). A full disk or a read-only folder is
 * NH_ERR_IO with the OS reason; the previous `path` is untouched. */
static int persist(hid_t file, const char *path) {
  if (H5Fflush(file, H5F_SCOPE_GLOBAL) < 0) return h5_fail(path, "H5Fflush", "/");
  ssize_t n = H5Fget_file_image(file, NULL, 0);
  if (n < 0) return h5_fail(path, "H5Fget_file_image", "/");
  void *image = malloc(n > 0 ? (size_t)n : 1);
  if (!image) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing '%s' (%zd bytes)", path, n);
  int rc = NH_OK;
  nh_atomic_file a;
  if (H5Fget_file_image(file, image, (size_t)n) != n)
    rc = h5_fail(path, "H5Fget_file_image", "/");
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

/* Record NH_ERR_IO for a failed HDF5 call on `object` of file `path`. */
static int h5_fail(const char *path, const char *call, const char *object) {
  char reason[240] = "";
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, innermost_cb, reason);
  H5Eclear2(H5E_DEFAULT);
  return NH_ERROR(NH_ERR_IO, "HDF5 file '%s': %s failed on '%s'%s%s", path, call, object,
                  reason[0] ? ": " : "", reason);
}

static void close_id(hid_t *id, herr_t (*close)(hid_t)) {
  if (*id >= 0) close(*id);
  *id = H5I_INVALID_HID;
}

/* A link name: non-empty, no '/' (HDF5 path separator), no ':' (the XDMF
 * "file:path" separator), not "." (HDF5's current group). */
static int valid_name(const char *s) {
  return s && s[0] && !strpbrk(s, "/:") && strcmp(s, ".") != 0;
}

/* Variable-length UTF-8 string type (caller closes). */
static hid_t string_type(void) {
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
  hid_t type = string_type();
  hid_t space = n < 0 ? H5Screate(H5S_SCALAR) : H5Screate_simple(1, dims, NULL);
  hid_t attr = H5I_INVALID_HID;
  if (type < 0 || space < 0) {
    rc = h5_fail(h->path, "H5Screate", name);
    goto done;
  }
  attr = H5Acreate2(loc, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  if (attr < 0) {
    rc = h5_fail(h->path, "H5Acreate2", name);
    goto done;
  }
  if (H5Awrite(attr, type, strings) < 0) rc = h5_fail(h->path, "H5Awrite", name);
done:
  close_id(&attr, H5Aclose);
  close_id(&space, H5Sclose);
  close_id(&type, H5Tclose);
  return rc;
}

/* Scalar numeric attribute (file type `ftype`, memory type `mtype`). */
static int write_scalar_attr(const nh_h5 *h, hid_t loc, const char *name, hid_t ftype, hid_t mtype,
                             const void *value) {
  int rc = NH_OK;
  hid_t space = H5Screate(H5S_SCALAR);
  hid_t attr =
      space < 0 ? H5I_INVALID_HID : H5Acreate2(loc, name, ftype, space, H5P_DEFAULT, H5P_DEFAULT);
  if (attr < 0 || H5Awrite(attr, mtype, value) < 0) rc = h5_fail(h->path, "H5Acreate2", name);
  close_id(&attr, H5Aclose);
  close_id(&space, H5Sclose);
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
    h5_fail(h->path, "H5Pset_chunk", name);
  } else {
    ds = H5Dcreate2(loc, name, ftype, space, H5P_DEFAULT, dcpl, H5P_DEFAULT);
    if (ds < 0) h5_fail(h->path, "H5Dcreate2", name);
  }
  close_id(&dcpl, H5Pclose);
  close_id(&space, H5Sclose);
  return ds < 0 ? H5I_INVALID_HID : ds;
}

/* Append row number `row` (the current length) to an extendible dataset. */
static int append_row(const nh_h5 *h, hid_t ds, const char *name, hid_t mtype, hsize_t row,
                      const void *data) {
  hsize_t dims[3] = {0, 1, 1}, start[3] = {row, 0, 0}, count[3] = {1, 1, 1};
  hid_t fspace = H5Dget_space(ds);
  int rank = fspace < 0 ? -1 : H5Sget_simple_extent_ndims(fspace);
  if (rank >= 1 && rank <= 3) H5Sget_simple_extent_dims(fspace, dims, NULL);
  close_id(&fspace, H5Sclose);
  if (rank < 1 || rank > 3) return h5_fail(h->path, "H5Sget_simple_extent_dims", name);
  dims[0] = row + 1;
  if (H5Dset_extent(ds, dims) < 0) return h5_fail(h->path, "H5Dset_extent", name);
  for (int d = 1; d < rank; ++d) count[d] = dims[d];
  int rc = NH_OK;
  hid_t mspace = H5Screate_simple(rank, count, NULL);
  fspace = H5Dget_space(ds);
  if (mspace < 0 || fspace < 0 ||
      H5Sselect_hyperslab(fspace, H5S_SELECT_SET, start, NULL, count, NULL) < 0)
    rc = h5_fail(h->path, "H5Sselect_hyperslab", name);
  else if (H5Dwrite(ds, mtype, mspace, fspace, H5P_DEFAULT, data) < 0)
    rc = h5_fail(h->path, "H5Dwrite", name);
  close_id(&mspace, H5Sclose);
  close_id(&fspace, H5Sclose);
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
    rc = h5_fail(h->path, "H5Dcreate2", name);
  else if (n > 0 && H5Dwrite(ds, mtype, H5S_ALL, H5S_ALL, H5P_DEFAULT, data) < 0)
    rc = h5_fail(h->path, "H5Dwrite", name);
  close_id(&ds, H5Dclose);
  close_id(&space, H5Sclose);
  return rc;
}

/* ---- XDMF ---- */

static int xdmf_write(const nh_h5 *h) {
  nh_text b = {0};
  int rc = nh_text_printf(&b,
                          "<?xml version=\"1.0\" ?>\n"
                          "<!DOCTYPE Xdmf SYSTEM \"Xdmf.dtd\" []>\n"
                          "<Xdmf Version=\"3.0\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n"
                          "  <Domain>\n"
                          "    <Grid Name=\"tissue\" GridType=\"Collection\" "
                          "CollectionType=\"Temporal\">\n"
                          "%s"
                          "    </Grid>\n"
                          "  </Domain>\n"
                          "</Xdmf>\n",
                          h->grids.s ? h->grids.s : "");
  if (rc == NH_OK) rc = nh_write_text(h->xdmf_path, b.s);
  free(b.s);
  return rc;
}

static const char *attribute_type(int components) {
  switch (components) {
  case 1:
    return "Scalar";
  case 3:
    return "Vector";
  case 6:
    return "Tensor6";
  case 9:
    return "Tensor";
  default:
    return "Matrix";
  }
}

/* A <DataItem> referencing results_<frame>.h5:/[<group>/]<name>. */
static int xdmf_item(nh_text *b, const char *frame, const char *group, const char *name, int n,
                     int components, int is_int) {
  NH_TRY(nh_text_printf(b, "          <DataItem Dimensions=\"%d", n));
  if (components > 1) NH_TRY(nh_text_printf(b, " %d", components));
  char file[32];
  frame_file(frame, file, sizeof file);
  NH_TRY(nh_text_printf(b, "\" NumberType=\"%s\" Precision=\"%d\" Format=\"HDF\">%s:/%s%s",
                        is_int ? "Int" : "Float", is_int ? 4 : 8, file, group ? group : "",
                        group ? "/" : ""));
  NH_TRY(nh_text_put_xml(b, name));
  return nh_text_printf(b, "</DataItem>\n");
}

static int xdmf_attribute(nh_text *b, const char *frame, const char *group, const char *name,
                          const char *center, int n, int components, int is_int) {
  NH_TRY(nh_text_printf(b, "        <Attribute Name=\""));
  NH_TRY(nh_text_put_xml(b, name));
  NH_TRY(nh_text_printf(b, "\" AttributeType=\"%s\" Center=\"%s\">\n", attribute_type(components),
                        center));
  NH_TRY(xdmf_item(b, frame, group, name, n, components, is_int));
  return nh_text_printf(b, "        </Attribute>\n");
}

/* Append the <Grid> of one frame to h->grids; on failure h->grids is
 * restored to its previous length. */
static int xdmf_add_frame(nh_h5 *h, const char *frame, double time, const nh_vtu_grid *g) {
  size_t keep = h->grids.len;
  nh_text *b = &h->grids;
  int rc =
      nh_text_printf(b,
                     "      <Grid Name=\"frame_%s\" GridType=\"Uniform\">\n"
                     "        <Time Value=\"%.17g\"/>\n"
                     "        <Topology TopologyType=\"Hexahedron\" NumberOfElements=\"%d\">\n",
                     frame, time, g->n_cells);
  if (rc == NH_OK) rc = xdmf_item(b, frame, NULL, "connectivity", g->n_cells, 8, 1);
  if (rc == NH_OK)
    rc = nh_text_printf(b, "        </Topology>\n        <Geometry GeometryType=\"XYZ\">\n");
  if (rc == NH_OK) rc = xdmf_item(b, frame, NULL, "points", g->n_points, 3, 0);
  if (rc == NH_OK) rc = nh_text_printf(b, "        </Geometry>\n");
  for (int i = 0; rc == NH_OK && i < g->n_point_fields; ++i)
    rc = xdmf_attribute(b, frame, "point_data", g->point_fields[i].name, "Node", g->n_points,
                        g->point_fields[i].components, 0);
  if (rc == NH_OK && g->point_int_flags)
    rc = xdmf_attribute(b, frame, "point_data", g->point_flag_name ? g->point_flag_name : "flag",
                        "Node", g->n_points, 1, 1);
  for (int i = 0; rc == NH_OK && i < g->n_cell_fields; ++i)
    rc = xdmf_attribute(b, frame, "cell_data", g->cell_fields[i].name, "Cell", g->n_cells,
                        g->cell_fields[i].components, 0);
  if (rc == NH_OK) rc = nh_text_printf(b, "      </Grid>\n");
  if (rc) {
    h->grids.len = keep;
    if (h->grids.s) h->grids.s[keep] = '\0';
  }
  return rc;
}

/* ---- create / close ---- */

/* A handle with no file open yet (NULL: out of memory, recorded). Also
 * switches HDF5's error printing off: errors come back as return values and
 * one message, never as HDF5's printed stack. */
static nh_h5 *h5_alloc(const char *dir, int n_step_columns) {
  nh_h5 *h = nh_calloc(1, sizeof *h);
  if (!h) return NULL;
  h->file = h->frames = h->steps = H5I_INVALID_HID;
  h->prev_cells = -1;
  h->n_step_columns = n_step_columns;
  H5Eset_auto2(H5E_DEFAULT, NULL, NULL);
  h->dir = copy_string(dir);
  h->path = join_path(dir, H5_FILE_NAME);
  h->xdmf_path = join_path(dir, XDMF_FILE_NAME);
  h->fapl = memory_fapl();
  if (!h->dir || !h->path || !h->xdmf_path || h->fapl < 0) {
    if (h->fapl >= 0) H5Pclose(h->fapl);
    free(h->dir);
    free(h->path);
    free(h->xdmf_path);
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
  nh_h5 *h = h5_alloc(dir, n_step_columns);
  if (!h) return NH_ERR_MEMORY;
  int rc = NH_OK;
  h->file = H5Fcreate(h->path, H5F_ACC_TRUNC, H5P_DEFAULT, h->fapl);
  if (h->file < 0) {
    rc = h5_fail(h->path, "H5Fcreate", "/");
    goto fail;
  }
  const char *format = FORMAT_NAME;
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
    rc = h5_fail(h->path, "H5Gcreate2", "/frames");
    goto fail;
  }
  if ((rc = persist(h->file, h->path))) goto fail;
  if ((rc = xdmf_write(h))) goto fail;
  h->live = 1;
  *out = h;
  return NH_OK;
fail:
  nh_h5_close(&h);
  return rc;
}

int nh_h5_flush(nh_h5 *h) {
  NH_CHECK(h, NH_ERR_INTERNAL, "nh_h5_flush: NULL argument");
  return persist(h->file, h->path);
}

static void free_names(char **names, int n) {
  if (!names) return;
  for (int i = 0; i < n; ++i) free(names[i]);
  free(names);
}

int nh_h5_close(nh_h5 **hp) {
  if (!hp || !*hp) return NH_OK;
  nh_h5 *h = *hp;
  int rc = NH_OK;
  for (int i = 0; i < h->n_series; ++i) {
    h5_series *s = &h->series[i];
    close_id(&s->time, H5Dclose);
    close_id(&s->step, H5Dclose);
    close_id(&s->values, H5Dclose);
    close_id(&s->group, H5Gclose);
    free(s->name);
    free_names(s->items, s->n_items);
    free_names(s->components, s->n_components);
  }
  free(h->series);
  close_id(&h->steps, H5Dclose);
  close_id(&h->frames, H5Gclose);
  /* The file lives in memory: writing it is the one step that can meet a
   * full disk, and closing it afterwards cannot fail for want of space. */
  if (h->file >= 0 && h->live) rc = persist(h->file, h->path);
  if (h->file >= 0) H5Fclose(h->file);
  H5Pclose(h->fapl);
  free(h->dir);
  free(h->prev_conn);
  free(h->grids.s);
  free(h->path);
  free(h->xdmf_path);
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

static int names_equal(char **stored, int n, const char *const *names) {
  for (int i = 0; i < n; ++i)
    if (!names[i] || strcmp(stored[i], names[i]) != 0) return 0;
  return 1;
}

static int copy_names(int n, const char *const *names, char ***out) {
  char **c = nh_calloc((size_t)n, sizeof *c);
  if (!c) return NH_ERR_MEMORY;
  for (int i = 0; i < n; ++i) {
    if (!(c[i] = copy_string(names[i]))) {
      free_names(c, n);
      return NH_ERR_MEMORY;
    }
  }
  *out = c;
  return NH_OK;
}

/* Create series group `name` with its three datasets and attributes. */
static int series_create(nh_h5 *h, h5_series *s, const char *name, int n_items,
                         const char *const *items, int n_components,
                         const char *const *components) {
  s->group = s->time = s->step = s->values = H5I_INVALID_HID;
  s->n_items = n_items;
  s->n_components = n_components;
  if (!(s->name = copy_string(name))) return NH_ERR_MEMORY;
  NH_TRY(copy_names(n_items, items, &s->items));
  NH_TRY(copy_names(n_components, components, &s->components));
  s->group = H5Gcreate2(h->file, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  if (s->group < 0) return h5_fail(h->path, "H5Gcreate2", name);
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
  h5_series *s = NULL;
  for (int i = 0; i < h->n_series && !s; ++i)
    if (strcmp(h->series[i].name, group) == 0) s = &h->series[i];
  if (!s) {
    NH_TRY(nh_grow((void **)&h->series, &h->cap_series, h->n_series + 1, sizeof *h->series));
    s = &h->series[h->n_series++];
    memset(s, 0, sizeof *s);
    NH_TRY(series_create(h, s, group, n_items, items, n_components, components));
  } else {
    NH_CHECK(s->n_items == n_items && s->n_components == n_components &&
                 names_equal(s->items, n_items, items) &&
                 names_equal(s->components, n_components, components),
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
static int check_frame_grid(const nh_h5 *h, const nh_vtu_grid *g) {
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
static int write_connectivity(nh_h5 *h, hid_t frame, const char *frame_name, const nh_vtu_grid *g) {
  size_t n = 8 * (size_t)g->n_cells;
  if (h->prev_cells == g->n_cells && g->n_cells > 0 &&
      memcmp(h->prev_conn, g->connectivity, n * sizeof(int)) == 0) {
    char target[32];
    frame_file(h->prev_frame, target, sizeof target);
    if (H5Lcreate_external(target, "/connectivity", frame, "connectivity", H5P_DEFAULT,
                           H5P_DEFAULT) < 0)
      return h5_fail(h->path, "H5Lcreate_external", target);
    return NH_OK;
  }
  NH_TRY(write_array(h, frame, "connectivity", H5T_STD_I32LE, H5T_NATIVE_INT, g->n_cells, 8,
                     g->connectivity));
  int *copy = realloc(h->prev_conn, (n ? n : 1) * sizeof(int));
  if (!copy) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing an HDF5 frame");
  if (n) memcpy(copy, g->connectivity, n * sizeof(int));
  h->prev_conn = copy;
  h->prev_cells = g->n_cells;
  snprintf(h->prev_frame, sizeof h->prev_frame, "%s", frame_name);
  return NH_OK;
}

static int write_frame_data(nh_h5 *h, hid_t frame, const char *frame_name, int step, double time,
                            const nh_vtu_grid *g) {
  NH_TRY(write_scalar_attr(h, frame, "step", H5T_STD_I32LE, H5T_NATIVE_INT, &step));
  NH_TRY(write_scalar_attr(h, frame, "time", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &time));
  NH_TRY(write_array(h, frame, "points", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, g->n_points, 3,
                     g->points));
  NH_TRY(write_connectivity(h, frame, frame_name, g));
  int rc = NH_OK;
  for (int pass = 0; pass < 2 && rc == NH_OK; ++pass) {
    const char *name = pass ? "cell_data" : "point_data";
    hid_t grp = H5Gcreate2(frame, name, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    if (grp < 0) return h5_fail(h->path, "H5Gcreate2", name);
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

int nh_h5_write_frame(nh_h5 *h, int step, double time, const nh_vtu_grid *grid) {
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
  frame_file(name, file, sizeof file);
  char *path = join_path(h->dir, file);
  if (!path) return NH_ERR_MEMORY;
  /* The frame file first (complete on disk, or absent), then results.h5
   * linking it, then the XDMF listing it: each renamed into place. */
  hid_t frame = H5Fcreate(path, H5F_ACC_TRUNC, H5P_DEFAULT, h->fapl);
  int rc = frame < 0 ? h5_fail(path, "H5Fcreate", "/") : NH_OK;
  if (rc == NH_OK) rc = write_frame_data(h, frame, name, step, time, grid);
  if (rc == NH_OK) rc = persist(frame, path);
  if (frame >= 0) H5Fclose(frame);
  free(path);
  if (rc) { /* a frame not on disk is no frame to link to */
    h->prev_cells = -1;
    return rc;
  }
  if (H5Lcreate_external(file, "/", h->frames, name, H5P_DEFAULT, H5P_DEFAULT) < 0)
    return h5_fail(h->path, "H5Lcreate_external", name);
  NH_TRY(persist(h->file, h->path));
  NH_TRY(xdmf_add_frame(h, name, time, grid));
  h->n_frames++;
  return xdmf_write(h);
}

/* ---- resume ---- */

/* Names of the links of group `loc`, in name order (*n of them). */
static int link_names(const nh_h5 *h, hid_t loc, const char *what, int *n, char ***out) {
  *n = 0;
  *out = NULL;
  H5G_info_t info;
  if (H5Gget_info(loc, &info) < 0) return h5_fail(h->path, "H5Gget_info", what);
  NH_CHECK(info.nlinks < 100000000, NH_ERR_IO, "HDF5 file '%s': '%s' has %llu members", h->path,
           what, (unsigned long long)info.nlinks);
  char **names = nh_calloc(info.nlinks ? (size_t)info.nlinks : 1, sizeof *names);
  if (!names) return NH_ERR_MEMORY;
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    ssize_t len = H5Lget_name_by_idx(loc, ".", H5_INDEX_NAME, H5_ITER_INC, i, NULL, 0, H5P_DEFAULT);
    if (len >= 0 && (names[i] = nh_calloc((size_t)len + 1, 1)) == NULL) {
      free_names(names, (int)i);
      return NH_ERR_MEMORY;
    }
    if (len < 0 || H5Lget_name_by_idx(loc, ".", H5_INDEX_NAME, H5_ITER_INC, i, names[i],
                                      (size_t)len + 1, H5P_DEFAULT) < 0) {
      free_names(names, (int)i + (len >= 0));
      return h5_fail(h->path, "H5Lget_name_by_idx", what);
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
  if (exists < 0) return h5_fail(h->path, "H5Aexists", what);
  if (!exists) return NH_OK;
  int rc = NH_OK;
  char **raw = NULL;
  hssize_t count = -1;
  hid_t type = string_type(), ftype = H5I_INVALID_HID, space = H5I_INVALID_HID;
  hid_t attr = H5Aopen(loc, name, H5P_DEFAULT);
  if (attr >= 0) ftype = H5Aget_type(attr), space = H5Aget_space(attr);
  if (space >= 0) count = H5Sget_simple_extent_npoints(space);
  if (type < 0 || attr < 0 || ftype < 0 || count < 0) {
    rc = h5_fail(h->path, "H5Aopen", name);
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
    rc = h5_fail(h->path, "H5Aread", name);
    goto done;
  }
  char **c = nh_calloc(count ? (size_t)count : 1, sizeof *c);
  for (hssize_t i = 0; c && i < count; ++i)
    if (!(c[i] = copy_string(raw[i] ? raw[i] : ""))) {
      free_names(c, (int)i);
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
  close_id(&attr, H5Aclose);
  close_id(&space, H5Sclose);
  close_id(&ftype, H5Tclose);
  close_id(&type, H5Tclose);
  return rc;
}

/* Rank (1..3) and dimensions of dataset `ds`. */
static int dataset_dims(const nh_h5 *h, hid_t ds, const char *what, int *rank, hsize_t dims[3]) {
  hid_t space = H5Dget_space(ds);
  *rank = space < 0 ? -1 : H5Sget_simple_extent_ndims(space);
  dims[0] = dims[1] = dims[2] = 1;
  if (*rank >= 1 && *rank <= 3) H5Sget_simple_extent_dims(space, dims, NULL);
  close_id(&space, H5Sclose);
  if (*rank < 1 || *rank > 3) return h5_fail(h->path, "H5Sget_simple_extent_dims", what);
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
    rc = h5_fail(h->path, "H5Sselect_hyperslab", what);
  else if (H5Dread(ds, H5T_NATIVE_DOUBLE, mspace, fspace, H5P_DEFAULT, v) < 0)
    rc = h5_fail(h->path, "H5Dread", what);
  close_id(&mspace, H5Sclose);
  close_id(&fspace, H5Sclose);
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
static int series_open(nh_h5 *h, h5_series *s, const char *name, int step, hsize_t *keep) {
  s->group = s->time = s->step = s->values = H5I_INVALID_HID;
  if (!(s->name = copy_string(name))) return NH_ERR_MEMORY;
  s->group = H5Gopen2(h->file, name, H5P_DEFAULT);
  if (s->group < 0) return h5_fail(h->path, "H5Gopen2", name);
  s->time = H5Dopen2(s->group, "time", H5P_DEFAULT);
  s->step = H5Dopen2(s->group, "step", H5P_DEFAULT);
  s->values = H5Dopen2(s->group, "values", H5P_DEFAULT);
  if (s->time < 0 || s->step < 0 || s->values < 0)
    return h5_fail(h->path, "H5Dopen2", "time, step or values of a series");
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
static int series_trim(nh_h5 *h, h5_series *s, hsize_t keep) {
  hsize_t d1[1] = {keep}, d3[3] = {keep, (hsize_t)s->n_items, (hsize_t)s->n_components};
  if (H5Dset_extent(s->time, d1) < 0 || H5Dset_extent(s->step, d1) < 0 ||
      H5Dset_extent(s->values, d3) < 0)
    return h5_fail(h->path, "H5Dset_extent", s->name);
  s->count = keep;
  return NH_OK;
}

/* The step of frame name NNNNNN (digits only), or -1. */
static long frame_step(const char *name) {
  if (!name[0] || strlen(name) > 9 || strspn(name, "0123456789") != strlen(name)) return -1;
  return strtol(name, NULL, 10);
}

/* Sizes and field names of one stored frame, as the grid xdmf_add_frame
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
    free_names(f->names[p], f->n_names[p]);
    free(f->fields[p]);
  }
}

/* The arrays of group `grp` ("point_data" or "cell_data") of a frame: each
 * [n] or [n x c]; Int32 allowed once in point_data (the flag). */
static int stored_fields(const nh_h5 *h, hid_t frame, const char *frame_name, int pass, hsize_t n,
                         stored_frame *f) {
  const char *group = pass ? "cell_data" : "point_data";
  hid_t grp = H5Gopen2(frame, group, H5P_DEFAULT);
  if (grp < 0) return h5_fail(h->path, "H5Gopen2", group);
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
      rc = h5_fail(h->path, "H5Dopen2", name);
    else
      rc = dataset_dims(h, ds, name, &rank, dims);
    close_id(&type, H5Tclose);
    close_id(&ds, H5Dclose);
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
    return h5_fail(h->path, "H5Lget_info", "connectivity");
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
    return h5_fail(h->path, "H5Lget_val", "connectivity");
  long owner = -1;
  if (strncmp(file, "results_", 8) == 0 && strlen(file) <= 8 + 9 + 3) {
    char digits[16];
    snprintf(digits, sizeof digits, "%.*s", (int)(strlen(file) - 8 - 3), file + 8);
    if (!strcmp(file + strlen(file) - 3, ".h5")) owner = frame_step(digits);
  }
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
  if (frame < 0) return h5_fail(h->path, "H5Gopen2", name);
  stored_frame f = {.flag = -1};
  double time = 0.0;
  int rank[2] = {0, 0}, rc = NH_OK;
  hsize_t dp[3], dc[3];
  hid_t attr = H5Aopen(frame, "time", H5P_DEFAULT);
  hid_t points = H5Dopen2(frame, "points", H5P_DEFAULT);
  hid_t conn = H5Dopen2(frame, "connectivity", H5P_DEFAULT);
  if (attr < 0 || H5Aread(attr, H5T_NATIVE_DOUBLE, &time) < 0)
    rc = h5_fail(h->path, "H5Aread", "time");
  else if (points < 0 || conn < 0)
    rc = h5_fail(h->path, "H5Dopen2", "points or connectivity");
  if (rc == NH_OK) rc = dataset_dims(h, points, "points", &rank[0], dp);
  if (rc == NH_OK) rc = dataset_dims(h, conn, "connectivity", &rank[1], dc);
  if (rc == NH_OK && (rank[0] != 2 || dp[1] != 3 || rank[1] != 2 || dc[1] != 8 || dp[0] > INT_MAX ||
                      dc[0] > INT_MAX / 8))
    rc = NH_ERROR(NH_ERR_IO, "HDF5 file '%s': /frames/%s is not a needlehex frame", h->path, name);
  for (int pass = 0; pass < 2 && rc == NH_OK; ++pass)
    rc = stored_fields(h, frame, name, pass, pass ? dc[0] : dp[0], &f);
  int dummy_flag = 0;
  if (rc == NH_OK) {
    nh_vtu_grid g = {.n_points = (int)dp[0],
                     .n_cells = (int)dc[0],
                     .type = NH_VTK_HEXAHEDRON,
                     .n_point_fields = f.n_fields[0],
                     .point_fields = f.fields[0],
                     .n_cell_fields = f.n_fields[1],
                     .cell_fields = f.fields[1],
                     .point_int_flags = f.flag >= 0 ? &dummy_flag : NULL,
                     .point_flag_name = f.flag >= 0 ? f.names[0][f.flag] : NULL};
    rc = xdmf_add_frame(h, name, time, &g);
  }
  if (rc == NH_OK && last) {
    size_t n = 8 * (size_t)dc[0];
    int *c = realloc(h->prev_conn, (n ? n : 1) * sizeof(int));
    if (!c) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory resuming '%s'", h->path);
    } else {
      h->prev_conn = c;
      if (n && H5Dread(conn, H5T_NATIVE_INT, H5S_ALL, H5S_ALL, H5P_DEFAULT, c) < 0) {
        rc = h5_fail(h->path, "H5Dread", "connectivity");
      } else {
        h->prev_cells = (int)dc[0];
        rc = connectivity_owner(h, frame, name, h->prev_frame, sizeof h->prev_frame);
      }
    }
  }
  stored_frame_free(&f);
  close_id(&attr, H5Aclose);
  close_id(&points, H5Dclose);
  close_id(&conn, H5Dclose);
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
    size_t len = strlen(e->d_name);
    if (len < 8 + 3 + 1 || strncmp(e->d_name, "results_", 8) || strcmp(e->d_name + len - 3, ".h5"))
      continue;
    char digits[16];
    snprintf(digits, sizeof digits, "%.*s", (int)(len - 11), e->d_name + 8);
    if (len - 11 > 9 || frame_step(digits) <= step) continue;
    char *path = join_path(h->dir, e->d_name);
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

  htri_t is_hdf5 = H5Fis_hdf5(h->path);
  if (is_hdf5 <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return NH_ERROR(NH_ERR_IO, "not an HDF5 file, or its superblock is damaged");
  }
  h->file = H5Fopen(h->path, H5F_ACC_RDWR, h->fapl);
  if (h->file < 0) return h5_fail(h->path, "H5Fopen", "/");
  NH_TRY(read_string_attr(h, h->file, "/", "format", &n_format, &format));
  int ours = n_format == 1 && strcmp(format[0], FORMAT_NAME) == 0;
  free_names(format, n_format);
  if (!ours) {
    *foreign = 1;
    return NH_ERROR(NH_ERR_IO, "'%s' was not written by needlehex (no format '%s')", h->path,
                    FORMAT_NAME);
  }
  h->steps = H5Dopen2(h->file, "steps", H5P_DEFAULT);
  if (h->steps < 0) return h5_fail(h->path, "H5Dopen2", "/steps");
  NH_TRY(read_string_attr(h, h->steps, "/steps", "columns", &n_cols, &cols));
  int same = n_cols == h->n_step_columns && names_equal(cols, n_cols, step_columns);
  free_names(cols, n_cols);
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
  if (h->frames < 0) return h5_fail(h->path, "H5Gopen2", "/frames");

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
    h5_series *s = &h->series[h->n_series++];
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
    rc = h5_fail(h->path, "H5Dset_extent", "/steps");
    goto done;
  }
  h->n_steps = keep_steps;
  for (int i = 0; i < h->n_series && rc == NH_OK; ++i) rc = series_trim(h, &h->series[i], keep[i]);
  for (int i = kept; i < n_frames && rc == NH_OK; ++i)
    if (H5Ldelete(h->frames, frames[i], H5P_DEFAULT) < 0)
      rc = h5_fail(h->path, "H5Ldelete", frames[i]);
  if (rc) goto done;
  h->n_frames = kept;
  if ((rc = persist(h->file, h->path))) goto done;
  remove_frame_files(h, step);
  if (last_step < step)
    nh_log_warn("'%s' holds /steps rows up to step %.0f only; the rows of steps %.0f to %d are "
                "missing from it (steps.csv has them)",
                h->path, last_step, last_step + 1, step);
done:
  free_names(members, n_members);
  free_names(frames, n_frames);
  free(keep);
  return rc;
}

/* DIR/results.h5.damaged, or .damaged.2, .3, ... if taken (NULL: none free). */
static char *damaged_name(const char *path) {
  size_t n = strlen(path) + 32;
  char *p = nh_calloc(n, 1);
  for (int k = 1; p && k < 1000; ++k) {
    snprintf(p, n, k == 1 ? "%s.damaged" : "%s.damaged.%d", path, k);
    if (access(p, F_OK) != 0) return p;
  }
  free(p);
  return NULL;
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
  nh_h5 *h = h5_alloc(dir, n_step_columns);
  if (!h) return NH_ERR_MEMORY;
  if (access(h->path, F_OK) != 0) { /* the first run wrote none */
    nh_h5_close(&h);
    return nh_h5_create(dir, scene_text, version, n_step_columns, step_columns, out);
  }
  int foreign = 0;
  int rc = resume_file(h, step_columns, step_col, step, &foreign);
  if (rc == NH_OK) rc = xdmf_write(h);
  if (rc == NH_OK) {
    h->live = 1;
    *out = h;
    return NH_OK;
  }
  char reason[1024];
  snprintf(reason, sizeof reason, "%s", nh_error_message());
  char *path = copy_string(h->path);
  nh_h5_close(&h); /* the file is closed before it is moved or replaced */
  if (!path || rc == NH_ERR_MEMORY) {
    free(path);
    return rc == NH_ERR_MEMORY ? rc : NH_ERR_MEMORY;
  }
  if (foreign) {
    nh_log_warn("%s; it is replaced by a new results file", reason);
  } else {
    char *aside = damaged_name(path);
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
