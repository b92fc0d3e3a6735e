/* vtu.c — one VTK XML UnstructuredGrid piece, written atomically.
 *
 * The file is the VTK XML "UnstructuredGrid" format, version 1.0, with every
 * DataArray stored in a single <AppendedData encoding="raw"> block:
 *
 *   <?xml version="1.0"?>
 *   <VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian"
 *            header_type="UInt64">
 *     <UnstructuredGrid><Piece NumberOfPoints="N" NumberOfCells="M">
 *       <PointData> Float64 fields..., Int32 flag </PointData>
 *       <CellData>  Float64 fields... </CellData>
 *       <Points>    Float64 x 3 </Points>
 *       <Cells>     Int32 connectivity, Int32 offsets, UInt8 types </Cells>
 *     </Piece></UnstructuredGrid>
 *     <AppendedData encoding="raw">
 *       _[n0][bytes of array 0][n1][bytes of array 1]...
 *     </AppendedData>
 *   </VTKFile>
 *
 * Each array's `offset` attribute counts bytes from the first byte after the
 * '_' to its 8-byte (UInt64) byte count n_k, which is followed by exactly n_k
 * bytes of little-endian data. Arrays are appended in the REVERSE of the
 * order the XML declares them, offsets are plain decimal integers, and a
 * newline follows the last byte: meshio's raw reader depends on all three.
 * It walks the block from offset 0, finds the DataArray whose offset
 * attribute equals the position reached (the first in document order) and
 * rewrites that attribute to a base64 position; appended in document order,
 * a rewritten attribute can equal a later array's raw offset (one probe: the
 * connectivity's new offset 88 was the types' raw one, and meshio failed
 * with "buffer size must be a multiple of element size"). In reverse order
 * every array not yet visited precedes, in the document, every rewritten one.
 *
 * Metadata: an nh_field's unit is written as VTK's UNITS_LABEL information
 * key inside its DataArray (VTK and ParaView read it; meshio ignores it), and
 * optional point names as the field data array "names" (UInt8 text, each
 * name followed by '\n': meshio reads no String arrays).
 *
 * Choices:
 * - Raw rather than base64 or zlib: the tissue frame of a 32x16x16 grid is
 *   written every few steps, and raw costs one fwrite per array. No per-value
 *   formatting touches the binary part; the only conversion is types (int to
 *   UInt8), done into one buffer.
 * - connectivity and offsets are Int32, straight from the caller's int arrays
 *   (no copy). An int holds any index needlehex can allocate; VTK and meshio
 *   read Int32 cell arrays like Int64 ones. If a mesh ever outgrows 2^31
 *   connectivity entries this becomes Int64 with a conversion buffer.
 * - NumberOfComponents is written only for vector fields (> 1), as VTK's
 *   own writer does: VTK defaults it to 1, and meshio then reads a scalar
 *   field as shape (n,) rather than (n, 1).
 * - offsets follow the version-1.0 convention: n_cells entries, the end of
 *   each cell in connectivity (no leading 0).
 * - On a big-endian host the arrays are byte-swapped through a small buffer,
 *   so the file is always little-endian as the header says.
 * - An empty piece (0 points and/or 0 cells) is valid: its arrays have a
 *   byte count of 0 and no data. VTK reads it; meshio 5 cannot read a file
 *   with 0 cells (a meshio limitation, not a format one).
 * - Inconsistent input (offsets decreasing, an index outside [0, n_points),
 *   a field with components < 1) is a caller bug: NH_ERR_INTERNAL, nothing
 *   written.
 * - Atomicity: everything goes to "<path>.tmp", which is closed (errors of
 *   the final flush included) and renamed over <path> (nh_atomic_open /
 *   nh_atomic_commit, io/file.c). On any failure the tmp file is removed and
 *   NH_ERR_IO names the path and strerror(errno). There is no fsync: the
 *   rename protects readers and killed runs, not power loss. */
#include "io/io.h"

#include <errno.h>
#include <limits.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

_Static_assert(sizeof(int) == 4, "Int32 arrays are written straight from int arrays");
_Static_assert(sizeof(double) == 8, "Float64 arrays are written straight from double arrays");

/* One DataArray: its XML attributes and where its bytes come from. */
typedef struct {
  const char *type; /* "Float64", "Int32", "UInt8" */
  const char *name;
  const char *unit; /* UNITS_LABEL, or NULL */
  int field_data;   /* an array of <FieldData> */
  int components;   /* NumberOfComponents, written only when > 1 */
  const void *data;
  size_t elem_size;
  size_t count; /* number of elements (tuples x components) */
  uint64_t offset;
} vtu_array;

static vtu_array make_array(const char *type, const char *name, int components, const void *data,
                            size_t elem_size, size_t count) {
  return (vtu_array){.type = type,
                     .name = name,
                     .components = components,
                     .data = data,
                     .elem_size = elem_size,
                     .count = count};
}

static int host_is_little_endian(void) {
  const uint16_t one = 1;
  unsigned char first;
  memcpy(&first, &one, 1);
  return first == 1;
}

/* Write `count` elements of `elem_size` bytes as little-endian. Returns 0 or -1
 * with errno set. */
static int write_le(FILE *f, const void *data, size_t elem_size, size_t count) {
  if (count == 0) return 0;
  if (elem_size == 1 || host_is_little_endian())
    return fwrite(data, elem_size, count, f) == count ? 0 : -1;
  unsigned char buf[4096];
  const unsigned char *src = data;
  size_t per = sizeof buf / elem_size;
  for (size_t done = 0; done < count;) {
    size_t n = count - done < per ? count - done : per;
    for (size_t i = 0; i < n; ++i)
      for (size_t b = 0; b < elem_size; ++b)
        buf[i * elem_size + b] = src[(done + i) * elem_size + elem_size - 1 - b];
    if (fwrite(buf, elem_size, n, f) != n) return -1;
    done += n;
  }
  return 0;
}

/* Attribute value with the XML specials escaped. */
static void put_xml_attr(FILE *f, const char *s) {
  for (; *s; ++s) {
    switch (*s) {
    case '&':
      fputs("&amp;", f);
      break;
    case '<':
      fputs("&lt;", f);
      break;
    case '>':
      fputs("&gt;", f);
      break;
    case '"':
      fputs("&quot;", f);
      break;
    default:
      fputc(*s, f);
    }
  }
}

static void put_array_xml(FILE *f, const vtu_array *a) {
  fprintf(f, "        <DataArray type=\"%s\" Name=\"", a->type);
  put_xml_attr(f, a->name);
  fputc('"', f);
  if (a->components > 1) fprintf(f, " NumberOfComponents=\"%d\"", a->components);
  if (a->field_data) fprintf(f, " NumberOfTuples=\"%zu\"", a->count); /* VTK needs it there */
  fprintf(f, " format=\"appended\" offset=\"%llu\"", (unsigned long long)a->offset);
  if (!a->unit) {
    fputs("/>\n", f);
    return;
  }
  fputs(">\n          <InformationKey name=\"UNITS_LABEL\" location=\"vtkDataArray\">", f);
  put_xml_attr(f, a->unit);
  fputs("</InformationKey>\n        </DataArray>\n", f);
}

/* Check what the writer relies on; a failure is a bug in the caller. */
static int check_grid(const char *path, const nh_frame *g) {
  NH_CHECK(g->n_points >= 0 && g->n_cells >= 0, NH_ERR_INTERNAL,
           "VTU '%s': negative size (%d points, %d cells)", path, g->n_points, g->n_cells);
  NH_CHECK(g->n_points == 0 || g->points, NH_ERR_INTERNAL, "VTU '%s': points missing", path);
  if (g->n_cells > 0) {
    NH_CHECK(g->offsets && g->connectivity, NH_ERR_INTERNAL,
             "VTU '%s': connectivity or offsets missing", path);
    int prev = 0;
    for (int c = 0; c < g->n_cells; ++c) {
      NH_CHECK(g->offsets[c] >= prev, NH_ERR_INTERNAL,
               "VTU '%s': offsets[%d] = %d is below the previous offset %d", path, c, g->offsets[c],
               prev);
      prev = g->offsets[c];
    }
    for (int k = 0; k < prev; ++k)
      NH_CHECK(g->connectivity[k] >= 0 && g->connectivity[k] < g->n_points, NH_ERR_INTERNAL,
               "VTU '%s': connectivity[%d] = %d outside [0, %d)", path, k, g->connectivity[k],
               g->n_points);
    if (g->types) {
      for (int c = 0; c < g->n_cells; ++c)
        NH_CHECK(g->types[c] >= 0 && g->types[c] <= UCHAR_MAX, NH_ERR_INTERNAL,
                 "VTU '%s': cell %d has type %d, not a VTK cell type", path, c, g->types[c]);
    } else {
      NH_CHECK(g->type >= 0 && g->type <= UCHAR_MAX, NH_ERR_INTERNAL,
               "VTU '%s': cell type %d is not a VTK cell type", path, g->type);
    }
  }
  for (int i = 0; g->point_names && i < g->n_points; ++i)
    NH_CHECK(g->point_names[i] && !strchr(g->point_names[i], '\n'), NH_ERR_INTERNAL,
             "VTU '%s': point name %d is missing or holds a newline", path, i);
  for (int pass = 0; pass < 2; ++pass) {
    int n = pass ? g->n_cell_fields : g->n_point_fields;
    const nh_field *fields = pass ? g->cell_fields : g->point_fields;
    int tuples = pass ? g->n_cells : g->n_points;
    NH_CHECK(n == 0 || fields, NH_ERR_INTERNAL, "VTU '%s': fields missing", path);
    for (int i = 0; i < n; ++i) {
      NH_CHECK(fields[i].name && fields[i].components >= 1 && (tuples == 0 || fields[i].data),
               NH_ERR_INTERNAL, "VTU '%s': %s field %d has no name, components or data", path,
               pass ? "cell" : "point", i);
    }
  }
  return NH_OK;
}

/* The arrays of one frame, in the order the XML declares them (they are
 * appended in reverse), with their offsets, and the two buffers of
 * converted data they point into. */
typedef struct {
  vtu_array *arrays;
  int n_arrays;
  int first_point_field, first_cell_field, points_index; /* ranges of arrays */
  int has_names;
  unsigned char *types; /* the cell types as UInt8 */
  char *names;          /* the point names, each followed by '\n' */
} vtu_layout;

static void vtu_layout_free(vtu_layout *v) {
  free(v->arrays);
  free(v->names);
  free(v->types);
}

static int vtu_layout_build(const nh_frame *grid, vtu_layout *v) {
  *v = (vtu_layout){0};
  const size_t np = (size_t)grid->n_points, nc = (size_t)grid->n_cells;
  const size_t nconn = nc ? (size_t)grid->offsets[nc - 1] : 0;

  /* The types array is the only one that needs converting. */
  v->types = nh_calloc(nc ? nc : 1, 1);
  if (!v->types) return NH_ERR_MEMORY;
  for (size_t c = 0; c < nc; ++c)
    v->types[c] = (unsigned char)(grid->types ? grid->types[c] : grid->type);

  /* The names as one text: each followed by '\n'. */
  size_t names_len = 0;
  for (size_t i = 0; grid->point_names && i < np; ++i)
    names_len += strlen(grid->point_names[i]) + 1;
  v->names = nh_calloc(names_len + 1, 1);
  if (!v->names) return NH_ERR_MEMORY;
  for (size_t i = 0, at = 0; grid->point_names && i < np; ++i)
    at += (size_t)sprintf(v->names + at, "%s\n", grid->point_names[i]);

  v->has_names = grid->point_names != NULL;
  v->n_arrays = v->has_names + grid->n_point_fields + (grid->point_int_flags ? 1 : 0) +
                grid->n_cell_fields + 4;
  vtu_array *arrays = v->arrays = nh_calloc((size_t)v->n_arrays, sizeof *arrays);
  if (!arrays) return NH_ERR_MEMORY;
  int k = 0;
  if (v->has_names) {
    arrays[k] = make_array("UInt8", "names", 1, v->names, 1, names_len);
    arrays[k++].field_data = 1;
  }
  v->first_point_field = k;
  for (int i = 0; i < grid->n_point_fields; ++i) {
    const nh_field *fld = &grid->point_fields[i];
    arrays[k] = make_array("Float64", fld->name, fld->components, fld->data, 8,
                           np * (size_t)fld->components);
    arrays[k++].unit = fld->unit;
  }
  if (grid->point_int_flags) {
    arrays[k] = make_array("Int32", grid->point_flag_name ? grid->point_flag_name : "flag", 1,
                           grid->point_int_flags, 4, np);
    arrays[k++].unit = "1";
  }
  v->first_cell_field = k;
  for (int i = 0; i < grid->n_cell_fields; ++i) {
    const nh_field *fld = &grid->cell_fields[i];
    arrays[k] = make_array("Float64", fld->name, fld->components, fld->data, 8,
                           nc * (size_t)fld->components);
    arrays[k++].unit = fld->unit;
  }
  v->points_index = k;
  arrays[k] = make_array("Float64", "Points", 3, grid->points, 8, 3 * np);
  arrays[k++].unit = "m";
  arrays[k++] = make_array("Int32", "connectivity", 1, grid->connectivity, 4, nconn);
  arrays[k++] = make_array("Int32", "offsets", 1, grid->offsets, 4, nc);
  arrays[k++] = make_array("UInt8", "types", 1, v->types, 1, nc);
  uint64_t offset = 0;
  for (int i = v->n_arrays - 1; i >= 0; --i) {
    arrays[i].offset = offset;
    offset += sizeof(uint64_t) + arrays[i].elem_size * arrays[i].count;
  }
  return NH_OK;
}

/* The XML part, up to the '_' that starts the appended data. */
static void vtu_put_xml(FILE *f, const nh_frame *grid, const vtu_layout *v) {
  fputs("<?xml version=\"1.0\"?>\n"
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\""
        " header_type=\"UInt64\">\n"
        "  <UnstructuredGrid>\n",
        f);
  if (v->has_names) {
    fputs("    <FieldData>\n", f);
    put_array_xml(f, &v->arrays[0]);
    fputs("    </FieldData>\n", f);
  }
  fprintf(f, "    <Piece NumberOfPoints=\"%d\" NumberOfCells=\"%d\">\n", grid->n_points,
          grid->n_cells);
  fputs("      <PointData>\n", f);
  for (int i = v->first_point_field; i < v->first_cell_field; ++i) put_array_xml(f, &v->arrays[i]);
  fputs("      </PointData>\n      <CellData>\n", f);
  for (int i = v->first_cell_field; i < v->points_index; ++i) put_array_xml(f, &v->arrays[i]);
  fputs("      </CellData>\n      <Points>\n", f);
  put_array_xml(f, &v->arrays[v->points_index]);
  fputs("      </Points>\n      <Cells>\n", f);
  for (int i = v->points_index + 1; i < v->n_arrays; ++i) put_array_xml(f, &v->arrays[i]);
  fputs("      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n"
        "  <AppendedData encoding=\"raw\">\n   _",
        f);
}

int nh_vtu_write(const char *path, const nh_frame *grid) {
  NH_CHECK(path && grid, NH_ERR_INTERNAL, "nh_vtu_write: NULL argument");
  NH_TRY(check_grid(path, grid));
  vtu_layout v;
  int rc = vtu_layout_build(grid, &v);
  nh_atomic_file af;
  if (rc == NH_OK) rc = nh_atomic_open(path, "VTU file", 0, &af);
  if (rc) {
    vtu_layout_free(&v);
    return rc;
  }
  FILE *f = af.file;
  vtu_put_xml(f, grid, &v);
  int failed = ferror(f);
  for (int i = v.n_arrays - 1; i >= 0 && !failed; --i) {
    uint64_t bytes = (uint64_t)(v.arrays[i].elem_size * v.arrays[i].count);
    failed = write_le(f, &bytes, sizeof bytes, 1) ||
             write_le(f, v.arrays[i].data, v.arrays[i].elem_size, v.arrays[i].count);
  }
  if (!failed) {
    fputs("\n  </AppendedData>\n</VTKFile>\n", f);
    failed = ferror(f);
  }
  rc = nh_atomic_commit(&af, failed);
  vtu_layout_free(&v);
  return rc;
}
