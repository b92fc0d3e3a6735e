/* io — VTU (XML UnstructuredGrid, appended raw binary), PVD collections and
 * CSV tables. Writers take plain arrays; they know nothing of the mesh or the
 * simulation. Every file is written to "<path>.tmp" and renamed into place,
 * so a reader (or a killed run) never sees a half-written file. */
#ifndef NH_IO_H
#define NH_IO_H

#include "core/core.h"
#include <stdio.h>

/* A field of n tuples of `components` doubles (row-major, tuple i at
 * data[i * components]). Written as Float64. */
typedef struct {
  const char *name;
  int components;
  const double *data;
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
} nh_vtu_grid;

/* Write `grid` to `path` as a VTU file (UInt64 headers, raw appended data,
 * little-endian), atomically. Fails with NH_ERR_IO naming the path. */
int nh_vtu_write(const char *path, const nh_vtu_grid *grid);

/* A PVD collection: the list of (time, file) frames of one object. */
typedef struct nh_pvd nh_pvd;
/* Create an empty collection that will be written to `path`. */
int nh_pvd_create(const char *path, nh_pvd **out);
/* Add a frame (file relative to the PVD's folder) and rewrite the PVD
 * atomically, so that it always lists exactly the frames already written. */
int nh_pvd_add(nh_pvd *pvd, double time, const char *file);
void nh_pvd_destroy(nh_pvd **pvd);

/* A CSV table with a fixed header; rows are appended and flushed. */
typedef struct nh_csv nh_csv;
/* Create (truncate) `path` and write the header line of `n_columns` names. */
int nh_csv_create(const char *path, int n_columns, const char *const *columns, nh_csv **out);
/* Append one row from a printf-style format (no trailing newline needed). */
int nh_csv_row(nh_csv *csv, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
void nh_csv_destroy(nh_csv **csv);

/* Create directory `path` and its parents (like mkdir -p). NH_ERR_IO on failure. */
int nh_mkdir_p(const char *path);
/* Copy text to a file atomically (tmp + rename). */
int nh_write_text(const char *path, const char *text);

#endif
