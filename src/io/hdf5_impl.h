/* hdf5_impl.h — private to the io module: the handle of the HDF5 results
 * (results.h5, its frame files and results.xdmf) and the helpers shared by
 * the writer (hdf5.c, which owns HDF5's error stack: every failed HDF5 call
 * becomes one message through nh_h5_fail) and the resume (hdf5_resume.c). */
#ifndef NH_HDF5_IMPL_H
#define NH_HDF5_IMPL_H

#include "io/io_impl.h"

#include <hdf5.h>

#define NH_H5_FILE_NAME   "results.h5"
#define NH_H5_XDMF_NAME   "results.xdmf"
#define NH_H5_FORMAT_NAME "needlehex-results 1"

/* One time series group (/probes, /targets, /tools, ...). */
typedef struct {
  char *name;
  hid_t group, time, step, values;
  int n_items, n_components;
  char **items, **components; /* fixed at the first append, checked after */
  hsize_t count;
} nh_h5_series;

struct nh_h5 {
  char *dir;
  char *path;         /* DIR/results.h5 */
  hid_t file, frames; /* results.h5, held in memory (hdf5.c, "Durability") */
  hid_t fapl;         /* HDF5's core driver without a backing store */
  int live;           /* created or resumed: nh_h5_close writes the file */
  hid_t steps;
  int n_step_columns;
  hsize_t n_steps;
  int n_series, cap_series;
  nh_h5_series *series;
  nh_xdmf xdmf; /* DIR/results.xdmf: the frames written so far */
  int n_frames;
  int prev_cells;      /* cells of the previous frame (-1: none) */
  int *prev_conn;      /* its connectivity, 8 * prev_cells ints */
  char prev_frame[16]; /* the frame whose file holds that connectivity dataset */
};

/* A handle for DIR with no file open yet (NULL: out of memory, recorded).
 * Also switches HDF5's error printing off: errors come back as return values
 * and one message, never as HDF5's printed stack. */
nh_h5 *nh_h5_alloc(const char *dir, int n_step_columns);

/* Record NH_ERR_IO for a failed HDF5 call on `object` of file `path`: one
 * message with HDF5's innermost reason; clears HDF5's error stack. */
int nh_h5_fail(const char *path, const char *call, const char *object);
/* Is `path` an HDF5 file (H5Fis_hdf5 > 0)? HDF5's errors are cleared. */
int nh_h5_is_hdf5(const char *path);
/* Close *id with `close` if it is valid; *id becomes invalid. */
void nh_h5_close_id(hid_t *id, herr_t (*close)(hid_t));
/* Variable-length UTF-8 string type (caller closes; negative on failure). */
hid_t nh_h5_string_type(void);
/* Write the image of in-memory file `file` to `path` atomically
 * (nh_atomic_open: tmp, rename; no fsync). */
int nh_h5_persist(hid_t file, const char *path);
/* The file of frame NNNNNN, relative to the results folder:
 * "results_NNNNNN.h5". */
void nh_h5_frame_file(const char *frame, char *out, size_t size);

/* n strings: free each and the array (NULL-safe); are the first n of
 * `stored` equal to `names` (none NULL)? */
void nh_h5_free_names(char **names, int n);
int nh_h5_names_equal(char **stored, int n, const char *const *names);

#endif
