/* io — VTU (XML UnstructuredGrid, appended raw binary), PVD collections,
 * CSV tables and HDF5 + XDMF results. Writers take plain arrays (frames: one
 * nh_frame for every format); they know nothing of the mesh or the
 * simulation. Every file but the append-only CSV tables is written to
 * "<path>.tmp" and renamed into place (io/file.c), so a reader (or a killed
 * run) never sees a half-written file. The resume functions continue the
 * outputs of an interrupted run at its checkpoint's step. */
#ifndef NH_IO_H
#define NH_IO_H

#include "core/core.h"
#include <stdio.h>

/* ---- frames: one description, every writer ----
 * A frame is a snapshot of one object (the tissue mesh, the embedded points,
 * a tool) at one step: its points, its cells and named fields on either. The
 * caller fills one nh_frame per object and step; every writer of frames
 * takes it as it is: nh_vtu_write (one .vtu file), nh_pvd_write_frame (a
 * .vtu frame of a collection) and nh_h5_write_frame (an HDF5 snapshot and
 * its XDMF entry; hexahedral frames only). The writers only read it. */

/* A field of n tuples of `components` doubles (row-major, tuple i at
 * data[i * components]). Written as Float64; `unit` (SI, e.g. "m", "Pa";
 * "1" for a dimensionless number; NULL: none written) goes into the VTU as
 * the array's UNITS_LABEL (vtkDataArray information key; HDF5 omits it). */
typedef struct {
  const char *name;
  int components;
  const double *data;
  const char *unit;
} nh_field;

/* VTK cell types used by needlehex. */
enum { NH_VTK_VERTEX = 1, NH_VTK_POLY_LINE = 4, NH_VTK_LINE = 3, NH_VTK_HEXAHEDRON = 12 };

typedef struct {
  int n_points;
  const double *points; /* 3 * n_points */
  int n_cells;
  const int *connectivity; /* concatenated point indices of all cells */
  const int *offsets;      /* n_cells: end of each cell in connectivity (VTK convention) */
  const int *types;        /* n_cells VTK cell types; NULL: all `type` */
  int type;                /* used when types == NULL */
  int n_point_fields;
  const nh_field *point_fields;
  int n_cell_fields;
  const nh_field *cell_fields;
  const int *point_int_flags; /* optional: n_points ints written as Int32 "point_flag_name" */
  const char *point_flag_name;
  const char *const *point_names; /* optional: n_points names; VTU only, as the field data
                                     array "names" (UInt8: the names, each followed by '\n') */
} nh_frame;

/* Write `frame` to `path` as a VTU file (UInt64 headers, raw appended data,
 * little-endian), atomically. Fails with NH_ERR_IO naming the path. */
int nh_vtu_write(const char *path, const nh_frame *frame);

/* A PVD collection: the list of (time, file) frames of one object. */
typedef struct nh_pvd nh_pvd;
/* Create an empty collection that will be written to `path`. */
int nh_pvd_create(const char *path, nh_pvd **out);
/* Add a frame (file relative to the PVD's folder) and rewrite the PVD
 * atomically, so that it always lists exactly the frames already written. */
int nh_pvd_add(nh_pvd *pvd, double time, const char *file);
/* Write the frame of step `step` of the collection DIR/PREFIX.pvd: `frame`
 * as DIR/PREFIX_NNNNNN.vtu (NNNNNN = step, zero padded to six digits;
 * nh_vtu_write), then add it at `time` (nh_pvd_add). Fails as those two;
 * NH_ERR_INTERNAL if the collection's path does not end in ".pvd". */
int nh_pvd_write_frame(nh_pvd *pvd, int step, double time, const nh_frame *frame);
/* Continue the collection DIR/PREFIX.pvd of an interrupted run at step
 * `step`: a new collection listing, in step order, the frames
 * PREFIX_NNNNNN.vtu found in DIR with NNNNNN <= step, at time NNNNNN * dt.
 * Fails as nh_pvd_create and nh_pvd_add. */
int nh_pvd_resume(const char *dir, const char *prefix, double dt, int step, nh_pvd **out);
void nh_pvd_destroy(nh_pvd **pvd);

/* A CSV table with a fixed header; rows are appended and flushed. */
typedef struct nh_csv nh_csv;
/* Create (truncate) `path` and write the header line of `n_columns` names. */
int nh_csv_create(const char *path, int n_columns, const char *const *columns, nh_csv **out);
/* Append one row from a printf-style format (no trailing newline needed). */
int nh_csv_row(nh_csv *csv, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Append one row of n (<= 64) numbers, each printed exactly (%.17g). */
int nh_csv_values(nh_csv *csv, int n, const double *values);
void nh_csv_destroy(nh_csv **csv);
/* Continue the table `path` of an interrupted run at step `step`: re-create
 * it (nh_csv_create) and re-append the rows of the old file whose first
 * field, the step, is at most `step` (a missing file: just the header). A
 * file whose header names other columns (another version's) keeps its rows,
 * mapped by column name (empty where it has no such column), and is itself
 * kept as `path`.old (a warning names it).
 * Fails as nh_csv_create and nh_csv_row, NH_ERR_MEMORY; NH_ERR_IO if such
 * a file cannot be moved aside. */
int nh_csv_resume(const char *path, int n_columns, const char *const *columns, int step,
                  nh_csv **out);

/* ---- files (io/file.c) ---- */
/* Create directory `path` and its parents (like mkdir -p). NH_ERR_IO on failure. */
int nh_mkdir_p(const char *path);
/* Copy text to a file atomically (nh_atomic_open, no fsync). */
int nh_write_text(const char *path, const char *text);

/* A file written atomically: the caller writes to `file` ("<path>.tmp"),
 * nh_atomic_commit renames it over the path. */
typedef struct {
  FILE *file;
  char *path, *tmp;
  const char *what; /* names the file in messages: "VTU file", "checkpoint" */
  int sync;         /* fsync before the rename */
} nh_atomic_file;
/* Open "<path>.tmp" for writing (binary). `what` (kept, not copied) names
 * the kind of file in messages. Fails with NH_ERR_IO ("cannot write WHAT
 * 'PATH': reason"), NH_ERR_MEMORY; *a is then closed (commit is a no-op). */
int nh_atomic_open(const char *path, const char *what, int sync, nh_atomic_file *a);
/* Finish the file: `failed` (a write the caller saw fail) or an error of
 * the stream, the fsync (if asked), the close or the rename removes the
 * temporary and returns NH_ERR_IO naming the path; else the file is in
 * place. Frees *a in both cases. */
int nh_atomic_commit(nh_atomic_file *a, int failed);

/* ---- HDF5 results: results.h5 + results.xdmf (io/hdf5.c, the XDMF index
 * io/xdmf.c, the resume io/hdf5_resume.c) ----
 * One HDF5 file per run with the per-step table, time series of named items
 * (probes, targets, tools) and hexahedral mesh snapshots, plus an XDMF file
 * describing the snapshots as a time series (ParaView, meshio). Layout and
 * guarantees: docs/outputs.md. Every failure returns NH_ERR_IO with one
 * message naming the file, the HDF5 call and the object (HDF5's own error
 * printing is switched off); misuse (sizes changing, a frame written twice,
 * cells that are not 8-node hexahedra) returns NH_ERR_INTERNAL. */
typedef struct nh_h5 nh_h5;

/* Create (truncate) DIR/results.h5 with root attributes "format", "version"
 * and "scene" (the scene text as run; NULL: omitted), the empty extendible
 * table /steps with `n_step_columns` columns named by `step_columns`, and an
 * empty DIR/results.xdmf. DIR must exist. *out is NULL on failure. */
int nh_h5_create(const char *dir, const char *scene_text, const char *version, int n_step_columns,
                 const char *const *step_columns, nh_h5 **out);

/* Continue the results file of an interrupted run at step `step` (the
 * checkpoint's): open DIR/results.h5 read-write, cut /steps and every series
 * back to the rows and samples whose step is <= `step` (the column named
 * "step", which step_columns must have; the series' step datasets), delete
 * the frames /frames/NNNNNN with NNNNNN > step, rewrite DIR/results.xdmf for
 * the frames kept, and return a handle that appends after them (a frame on
 * the mesh of the last kept one links its connectivity, as in an
 * uninterrupted run). If /steps then ends before `step` (rows not flushed
 * before a kill), a warning says which rows are missing.
 * A fresh file (nh_h5_create) is started instead, as the first run would
 * have written it, when DIR/results.h5 does not exist, or is an HDF5 file
 * without the needlehex format attribute or with other step columns (a
 * warning says so). A file that cannot be read (not HDF5, damaged by a kill)
 * is renamed to DIR/results.h5.damaged (.damaged.2, ... if taken) and a
 * fresh file started, with a warning naming both files; NH_ERR_IO if it
 * cannot be renamed. Space of deleted frames is not reclaimed (h5repack). */
int nh_h5_resume(const char *dir, const char *scene_text, const char *version, int n_step_columns,
                 const char *const *step_columns, int step, nh_h5 **out);

/* Append one row of n_step_columns doubles to /steps. Reaches the disk at
 * the next frame, nh_h5_flush or nh_h5_close. */
int nh_h5_append_steps(nh_h5 *h, const double *row);

/* Append one sample to the series group /<group> ("probes", "targets",
 * "tools", ...): time[N], step[N] and values[N x n_items x n_components]
 * (values row-major: item i, component k at values[i * n_components + k]).
 * The first call creates the group and fixes the item and component names
 * (attributes "names" and "components" of values); later calls must pass the
 * same counts and names. n_items and n_components must be positive. */
int nh_h5_append_series(nh_h5 *h, const char *group, int step, double time, int n_items,
                        const char *const *items, int n_components, const char *const *components,
                        const double *values);

/* Write the snapshot /frames/NNNNNN (NNNNNN = step, zero padded to six
 * digits; attributes step, time): points, connectivity [n_cells x 8] and the
 * frame's point fields, Int32 point flag and cell fields (not its point
 * names). All cells must be 8-node hexahedra (VTK order). Then flush the
 * file (everything appended so far is on disk) and rewrite results.xdmf
 * atomically to list every frame. */
int nh_h5_write_frame(nh_h5 *h, int step, double time, const nh_frame *frame);

/* Flush everything written so far to the file (H5Fflush). */
int nh_h5_flush(nh_h5 *h);

/* Flush and close the file, free *h and set it to NULL; NULL-safe. Returns
 * NH_ERR_IO if the final flush failed (the handle is freed regardless). */
int nh_h5_close(nh_h5 **h);

/* ---- outputs on the patient's images (io/markups.c, io/nifti.c) ----
 * For the tools that plan DBS (3D Slicer, ANTs, elastix, Lead-DBS): 3D
 * Slicer markups and NIfTI images on the grid of a reference image. Points
 * and vectors come in the scene frame (RAS, metres; anatomy.h). */
#include "anatomy/anatomy.h"

/* Write a 3D Slicer markups file (.mrk.json, schema v1.0.3) holding one
 * markup of `type` (NH_MARKUP_CURVE for a tool's axis, points from base to
 * tip; NH_MARKUP_FIDUCIAL for targets) named `name`, with the n points
 * points[3n] (scene frame) written in RAS millimetres, labelled labels[i]
 * (NULL: "NAME-1", "NAME-2", ..., Slicer's default), every point defined,
 * selected, locked and visible. Atomically. Fails with NH_ERR_IO naming the
 * path, NH_ERR_MEMORY. */
int nh_markups_write(const char *path, nh_markup_type type, const char *name, int n,
                     const double *points, const char *const *labels);

/* Write the displacement u (3 per voxel centre of `reference`, i fastest;
 * scene frame, metres) as an ITK/ANTs displacement field: NIfTI-1, gzip'ed
 * when path ends in .gz, dim = [5, nx, ny, nz, 1, 3], intent vector (1007),
 * float32 components in ITK's physical frame, LPS millimetres
 * (−u_x, −u_y, u_z) · 1000, on the reference's grid: its sform and qform
 * with their codes and its pixdim, in mm (a reference in m or µm is
 * converted). The field maps a point p of the reference (the rest anatomy)
 * to p + u(p), its position after the shift (docs/anatomy.md: which image
 * it moves, and how ANTs, Slicer and transformix apply it). Atomically.
 * Fails with NH_ERR_IO naming the path (and the reference, if its header
 * cannot be read again or no longer matches its size), NH_ERR_MEMORY. */
int nh_nifti_write_displacement(const char *path, const nh_image *reference, const double *u);
/* Write a 0/1 mask (uint8, one per voxel) on the reference's grid, as
 * nh_nifti_write_displacement's geometry. */
int nh_nifti_write_mask(const char *path, const nh_image *reference, const unsigned char *mask);
/* Write one value per voxel on the reference's grid: as float32 (as_float;
 * scl_slope 0: the values themselves), else in the reference's own data
 * type and scaling: stored = (value − scl_inter) / scl_slope when its slope
 * is non-zero, rounded to the nearest integer and clamped to the type's
 * range for an integer type (NaN as 0). */
int nh_nifti_write_scalar(const char *path, const nh_image *reference, const double *values,
                          int as_float);

#endif
