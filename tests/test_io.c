/* test_io — writes VTU, PVD and CSV files with known contents and checks the
 * writers' return codes, their atomicity (no "*.tmp" left behind) and their
 * nh_test_failures (a missing folder gives NH_ERR_IO naming the path).
 *
 * usage: test_io [DIR]
 *   DIR given: the files are written there (created if needed) and kept, for
 *   tests/io_readback.py DIR, which reads them back with VTK and meshio and
 *   compares every value with the formulas below. ctest passes a fixed
 *   scratch folder and runs io_readback after this test (a fixture).
 *   No DIR: a fresh folder under $NH_WORK or /tmp, removed on success.
 *
 * The values written are defined by formulas that tests/io_readback.py
 * repeats exactly (keep the two in step):
 *
 *   hex.vtu: 3 x 2 x 2 points, i = ix + 3 iy + 6 iz, two hexahedra sharing the
 *     face x = 0.01;
 *     point i         = (0.01 ix, 0.02 iy, 0.03 iz)
 *     displacement[i] = (0.001 i, -0.002 i, 0.5 + i)
 *     velocity[i]     = (0.25 i, 1 / (i + 1), -3 i)
 *     fixed[i]        = 1 if i % 3 == 0 else 0              (Int32)
 *     cell c = 0, 1: (n(c,0,0), n(c+1,0,0), n(c+1,1,0), n(c,1,0),
 *                     n(c,0,1), n(c+1,0,1), n(c+1,1,1), n(c,1,1)), VTK_HEXAHEDRON
 *     von_mises[c] = 1500 (c + 1), level[c] = c
 *   empty_cells.vtu: points (0.1 i, 0, 0), i < 4, displacement as above,
 *     0 cells, cell field von_mises with 0 tuples.
 *   empty.vtu: 0 points, 0 cells, point field displacement, cell field von_mises.
 *   lines.vtu: points (0.1 i, 0, 0), i < 6, displacement as above; cells
 *     POLY_LINE (0 1 2 3), LINE (3 4), LINE (4 5), VERTEX (5); von_mises as above.
 *   vertices.vtu: points (0.1 i, 0.2 i, 0.3 i), i < 3, one VERTEX per point
 *     (types == NULL), displacement as above.
 *   single.vtu: the point (0.1, 0.2, 0.3) as one VERTEX, displacement of
 *     point 1 above.
 *   named.vtu: single.vtu with the Int32 flag "target" = 1, names "STN".
 *   named3.vtu: vertices.vtu with names "a", "probe 2", "STN".
 *   Units (VTK's UNITS_LABEL): displacement m, velocity m/s, von_mises Pa,
 *     flags 1, Points m; hex.vtu's level has none.
 *   series.pvd: frames k = 0, 1, 2 at times {0, 0.05, 0.1 + 0.2}, files
 *     series_%06d.vtu with step 5 k; each is hex.vtu with every displacement
 *     component multiplied by (k + 1) (after computing it as above).
 *   escape.pvd: one frame, time 1.5, file "odd &<name>.vtu" (= hex.vtu).
 *   framed.pvd: series.pvd again, its frames written by nh_pvd_write_frame
 *     (steps 0, 5, 10): checked here to equal series.pvd and its frames byte
 *     for byte but for the prefix (the names DIR/PREFIX_NNNNNN.vtu built by
 *     hand for series.pvd); notpvd.xml: a collection not named *.pvd, whose
 *     nh_pvd_write_frame is refused (NH_ERR_INTERNAL).
 *   table.csv: header step,time,name,x,"note, quoted"; rows i < 5:
 *     i, 0.01 i, p<i>, 1 / (i + 3), n<i>  (doubles with %.17g).
 *   long.csv: header "long"; one row of 3000 'x'.
 *   hello.txt: "hello\nworld\n". */
#include "check.h"
#include "io/io.h"

#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char dir[4096];

static const char *in_dir(const char *name) {
  static char buf[4][8192];
  static int next = 0;
  char *b = buf[next++ % 4];
  snprintf(b, sizeof buf[0], "%s/%s", dir, name);
  return b;
}

static const char *const written[] = {
    "hex.vtu",           "empty_cells.vtu",   "empty.vtu",         "lines.vtu",
    "vertices.vtu",      "series.pvd",        "series_000000.vtu", "series_000005.vtu",
    "series_000010.vtu", "escape.pvd",        "odd &<name>.vtu",   "table.csv",
    "long.csv",          "hello.txt",         "bad.vtu",           "full.vtu",
    "full.txt",          "named.vtu",         "named3.vtu",        "single.vtu",
    "framed.pvd",        "framed_000000.vtu", "framed_000005.vtu", "framed_000010.vtu",
    "notpvd.xml",        "resume.csv",        "resume.csv.old",    "same.csv",
};
enum { N_WRITTEN = sizeof written / sizeof written[0] };

static void remove_written(void) {
  char tmp[8300];
  for (int i = 0; i < N_WRITTEN; ++i) {
    remove(in_dir(written[i]));
    snprintf(tmp, sizeof tmp, "%s.tmp", in_dir(written[i]));
    remove(tmp);
  }
  rmdir(in_dir("mk/a/b/c"));
  rmdir(in_dir("mk/a/b"));
  rmdir(in_dir("mk/a"));
  rmdir(in_dir("mk"));
}

static int file_exists(const char *path) {
  struct stat st;
  return stat(path, &st) == 0;
}

/* ---- hex.vtu ---- */
enum { HX = 3, HY = 2, HZ = 2, HN = HX * HY * HZ, HC = 2 };

static int hex_node(int ix, int iy, int iz) {
  return ix + HX * iy + HX * HY * iz;
}

static void displacement_of(int i, double d[3]) {
  d[0] = 0.001 * i;
  d[1] = -0.002 * i;
  d[2] = 0.5 + i;
}

typedef struct {
  double points[3 * HN], displacement[3 * HN], velocity[3 * HN];
  int fixed[HN];
  int connectivity[8 * HC], offsets[HC];
  double von_mises[HC], level[HC];
  nh_field point_fields[2], cell_fields[2];
  nh_frame grid;
} hex_data;

static void hex_build(hex_data *h, int frame) {
  for (int iz = 0; iz < HZ; ++iz)
    for (int iy = 0; iy < HY; ++iy)
      for (int ix = 0; ix < HX; ++ix) {
        int i = hex_node(ix, iy, iz);
        h->points[3 * i + 0] = 0.01 * ix;
        h->points[3 * i + 1] = 0.02 * iy;
        h->points[3 * i + 2] = 0.03 * iz;
        displacement_of(i, &h->displacement[3 * i]);
        for (int a = 0; a < 3; ++a) h->displacement[3 * i + a] *= (frame + 1);
        h->velocity[3 * i + 0] = 0.25 * i;
        h->velocity[3 * i + 1] = 1.0 / (i + 1);
        h->velocity[3 * i + 2] = -3.0 * i;
        h->fixed[i] = i % 3 == 0;
      }
  for (int c = 0; c < HC; ++c) {
    int *n = &h->connectivity[8 * c];
    n[0] = hex_node(c, 0, 0), n[1] = hex_node(c + 1, 0, 0);
    n[2] = hex_node(c + 1, 1, 0), n[3] = hex_node(c, 1, 0);
    n[4] = hex_node(c, 0, 1), n[5] = hex_node(c + 1, 0, 1);
    n[6] = hex_node(c + 1, 1, 1), n[7] = hex_node(c, 1, 1);
    h->offsets[c] = 8 * (c + 1);
    h->von_mises[c] = 1500.0 * (c + 1);
    h->level[c] = c;
  }
  h->point_fields[0] = (nh_field){"displacement", 3, h->displacement, "m"};
  h->point_fields[1] = (nh_field){"velocity", 3, h->velocity, "m/s"};
  h->cell_fields[0] = (nh_field){"von_mises", 1, h->von_mises, "Pa"};
  h->cell_fields[1] = (nh_field){"level", 1, h->level, NULL};
  h->grid = (nh_frame){.n_points = HN,
                       .points = h->points,
                       .n_cells = HC,
                       .connectivity = h->connectivity,
                       .offsets = h->offsets,
                       .types = NULL,
                       .type = NH_VTK_HEXAHEDRON,
                       .n_point_fields = 2,
                       .point_fields = h->point_fields,
                       .n_cell_fields = 2,
                       .cell_fields = h->cell_fields,
                       .point_int_flags = h->fixed,
                       .point_flag_name = "fixed"};
}

static void write_vtus(void) {
  hex_data h;
  hex_build(&h, 0);
  EXPECT_OK(nh_vtu_write(in_dir("hex.vtu"), &h.grid));

  /* 4 points, 0 cells */
  double p4[12] = {0}, d4[12];
  for (int i = 0; i < 4; ++i) {
    p4[3 * i] = 0.1 * i;
    displacement_of(i, &d4[3 * i]);
  }
  nh_field pf4 = {"displacement", 3, d4, "m"};
  nh_field cf0 = {"von_mises", 1, NULL, "Pa"};
  nh_frame g4 = {.n_points = 4,
                 .points = p4,
                 .type = NH_VTK_HEXAHEDRON,
                 .n_point_fields = 1,
                 .point_fields = &pf4,
                 .n_cell_fields = 1,
                 .cell_fields = &cf0};
  EXPECT_OK(nh_vtu_write(in_dir("empty_cells.vtu"), &g4));

  /* 0 points, 0 cells */
  nh_field pf0 = {"displacement", 3, NULL, "m"};
  nh_frame g0 = {.type = NH_VTK_HEXAHEDRON,
                 .n_point_fields = 1,
                 .point_fields = &pf0,
                 .n_cell_fields = 1,
                 .cell_fields = &cf0};
  EXPECT_OK(nh_vtu_write(in_dir("empty.vtu"), &g0));

  /* mixed poly-line, lines and a vertex */
  double p6[18] = {0}, d6[18];
  for (int i = 0; i < 6; ++i) {
    p6[3 * i] = 0.1 * i;
    displacement_of(i, &d6[3 * i]);
  }
  int conn6[] = {0, 1, 2, 3, 3, 4, 4, 5, 5};
  int off6[] = {4, 6, 8, 9};
  int types6[] = {NH_VTK_POLY_LINE, NH_VTK_LINE, NH_VTK_LINE, NH_VTK_VERTEX};
  double vm6[4];
  for (int c = 0; c < 4; ++c) vm6[c] = 1500.0 * (c + 1);
  nh_field pf6 = {"displacement", 3, d6, "m"};
  nh_field cf6 = {"von_mises", 1, vm6, "Pa"};
  nh_frame g6 = {.n_points = 6,
                 .points = p6,
                 .n_cells = 4,
                 .connectivity = conn6,
                 .offsets = off6,
                 .types = types6,
                 .n_point_fields = 1,
                 .point_fields = &pf6,
                 .n_cell_fields = 1,
                 .cell_fields = &cf6};
  EXPECT_OK(nh_vtu_write(in_dir("lines.vtu"), &g6));

  /* vertices, one cell type for all (types == NULL) */
  double p3[9], d3[9];
  int conn3[3], off3[3];
  for (int i = 0; i < 3; ++i) {
    p3[3 * i] = 0.1 * i, p3[3 * i + 1] = 0.2 * i, p3[3 * i + 2] = 0.3 * i;
    displacement_of(i, &d3[3 * i]);
    conn3[i] = i;
    off3[i] = i + 1;
  }
  nh_field pf3 = {"displacement", 3, d3, "m"};
  nh_frame g3 = {.n_points = 3,
                 .points = p3,
                 .n_cells = 3,
                 .connectivity = conn3,
                 .offsets = off3,
                 .type = NH_VTK_VERTEX,
                 .n_point_fields = 1,
                 .point_fields = &pf3};
  EXPECT_OK(nh_vtu_write(in_dir("vertices.vtu"), &g3));

  /* One vertex with only a displacement: appended in document order, meshio
     could not read it (its offset rewriting hit the types' offset). */
  nh_field pf1 = {"displacement", 3, d3 + 3, "m"};
  nh_frame g1 = {.n_points = 1,
                 .points = p3 + 3,
                 .n_cells = 1,
                 .connectivity = conn3,
                 .offsets = off3,
                 .type = NH_VTK_VERTEX,
                 .n_point_fields = 1,
                 .point_fields = &pf1};
  EXPECT_OK(nh_vtu_write(in_dir("single.vtu"), &g1));
  /* The same, named and with a flag (a points_NNNNNN.vtu with one target). */
  const char *names1[] = {"STN"};
  int flag1[] = {1};
  g1.point_int_flags = flag1;
  g1.point_flag_name = "target";
  g1.point_names = names1;
  EXPECT_OK(nh_vtu_write(in_dir("named.vtu"), &g1));
  /* Three named vertices: the names in order. */
  const char *names3[] = {"a", "probe 2", "STN"};
  g3.point_names = names3;
  EXPECT_OK(nh_vtu_write(in_dir("named3.vtu"), &g3));

  /* A caller bug (index out of range) is refused and writes nothing. */
  hex_build(&h, 0);
  h.connectivity[5] = HN;
  int rc = nh_vtu_write(in_dir("bad.vtu"), &h.grid);
  EXPECT(rc == NH_ERR_INTERNAL, "bad connectivity: got %d, expected NH_ERR_INTERNAL", rc);
  EXPECT(!file_exists(in_dir("bad.vtu")), "bad.vtu exists after a refused write");
}

/* Whole file of `path` (NUL-terminated; caller frees), *n bytes; NULL if
 * unreadable. */
static char *read_file(const char *path, size_t *n) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  char *s = NULL;
  size_t cap = 0;
  *n = 0;
  for (;;) {
    if (*n + 4096 + 1 > cap) {
      char *p = realloc(s, cap = 2 * cap + 8192);
      if (!p) break;
      s = p;
    }
    size_t got = fread(s + *n, 1, 4096, f);
    *n += got;
    if (got < 4096) break;
  }
  fclose(f);
  if (s) s[*n] = '\0';
  return s;
}

/* Are files a and b equal, b after replacing every `from` of a by `to`
 * (same length; NULL: none)? */
static int same_bytes(const char *a, const char *b, const char *from, const char *to) {
  size_t na = 0, nb = 0;
  char *x = read_file(a, &na), *y = read_file(b, &nb);
  int same = x && y && na == nb;
  for (char *p = x; same && from && (p = strstr(p, from)); p += strlen(from))
    memcpy(p, to, strlen(to));
  same = same && memcmp(x, y, na) == 0;
  free(x);
  free(y);
  return same;
}

static void write_pvds(void) {
  const double times[3] = {0.0, 0.05, 0.1 + 0.2};
  nh_pvd *pvd = NULL;
  EXPECT_OK(nh_pvd_create(in_dir("series.pvd"), &pvd));
  EXPECT(pvd != NULL, "nh_pvd_create gave NULL");
  if (!pvd) return;
  for (int k = 0; k < 3; ++k) {
    hex_data h;
    hex_build(&h, k);
    char name[64];
    snprintf(name, sizeof name, "series_%06d.vtu", 5 * k);
    EXPECT_OK(nh_vtu_write(in_dir(name), &h.grid));
    EXPECT_OK(nh_pvd_add(pvd, times[k], name));
  }
  nh_pvd_destroy(&pvd);
  EXPECT(pvd == NULL, "nh_pvd_destroy did not null the pointer");
  nh_pvd_destroy(&pvd); /* harmless twice */

  /* The same collection through nh_pvd_write_frame. */
  EXPECT_OK(nh_pvd_create(in_dir("framed.pvd"), &pvd));
  for (int k = 0; pvd && k < 3; ++k) {
    hex_data h;
    hex_build(&h, k);
    EXPECT_OK(nh_pvd_write_frame(pvd, 5 * k, times[k], &h.grid));
  }
  nh_pvd_destroy(&pvd);
  for (int k = 0; k < 3; ++k) {
    char a[64], b[64];
    snprintf(a, sizeof a, "series_%06d.vtu", 5 * k);
    snprintf(b, sizeof b, "framed_%06d.vtu", 5 * k);
    EXPECT(same_bytes(in_dir(a), in_dir(b), NULL, NULL),
           "%s differs from %s (the same frame, written by nh_pvd_write_frame)", b, a);
  }
  EXPECT(same_bytes(in_dir("series.pvd"), in_dir("framed.pvd"), "series_", "framed_"),
         "framed.pvd does not list framed_NNNNNN.vtu as series.pvd lists series_NNNNNN.vtu");
  EXPECT_OK(nh_pvd_create(in_dir("notpvd.xml"), &pvd));
  if (pvd) {
    hex_data h;
    hex_build(&h, 0);
    int rc = nh_pvd_write_frame(pvd, 0, 0.0, &h.grid);
    EXPECT(rc == NH_ERR_INTERNAL, "frame of notpvd.xml: got %d, expected NH_ERR_INTERNAL", rc);
  }
  nh_pvd_destroy(&pvd);

  hex_data h;
  hex_build(&h, 0);
  EXPECT_OK(nh_vtu_write(in_dir("odd &<name>.vtu"), &h.grid));
  EXPECT_OK(nh_pvd_create(in_dir("escape.pvd"), &pvd));
  if (pvd) EXPECT_OK(nh_pvd_add(pvd, 1.5, "odd &<name>.vtu"));
  nh_pvd_destroy(&pvd);
}

static void write_csvs(void) {
  const char *columns[] = {"step", "time", "name", "x", "note, quoted"};
  nh_csv *csv = NULL;
  EXPECT_OK(nh_csv_create(in_dir("table.csv"), 5, columns, &csv));
  if (!csv) return;
  for (int i = 0; i < 5; ++i) {
    /* One row's format ends in a newline: it must not produce an empty line. */
    if (i == 2)
      EXPECT_OK(nh_csv_row(csv, "%d,%.17g,p%d,%.17g,n%d\n", i, 0.01 * i, i, 1.0 / (i + 3), i));
    else
      EXPECT_OK(nh_csv_row(csv, "%d,%.17g,p%d,%.17g,n%d", i, 0.01 * i, i, 1.0 / (i + 3), i));
  }
  /* Rows are flushed: the file is complete before the table is closed. */
  FILE *f = fopen(in_dir("table.csv"), "r");
  EXPECT(f != NULL, "cannot reopen table.csv");
  if (f) {
    int lines = 0, ch;
    while ((ch = fgetc(f)) != EOF) lines += ch == '\n';
    fclose(f);
    EXPECT(lines == 6, "table.csv has %d lines before close, expected 6", lines);
  }
  nh_csv_destroy(&csv);
  EXPECT(csv == NULL, "nh_csv_destroy did not null the pointer");

  const char *long_column[] = {"long"};
  EXPECT_OK(nh_csv_create(in_dir("long.csv"), 1, long_column, &csv));
  if (csv) {
    char row[3001];
    memset(row, 'x', 3000);
    row[3000] = '\0';
    EXPECT_OK(nh_csv_row(csv, "%s", row));
  }
  nh_csv_destroy(&csv);

  EXPECT_OK(nh_write_text(in_dir("hello.txt"), "hello\nworld\n"));
}

static char *read_all(const char *path) {
  FILE *f = fopen(path, "r");
  if (!f) return NULL;
  char *s = calloc(1 << 16, 1);
  size_t n = s ? fread(s, 1, (1 << 16) - 1, f) : 0;
  if (s) s[n] = '\0';
  fclose(f);
  return s;
}

/* Continuing a table (nh_csv_resume): with the same columns the rows up to
 * the step are kept byte for byte; with another version's columns they are
 * mapped by name (quoted fields included), a new column is empty, and the
 * old file survives as .old, unchanged. */
static void resume_csvs(void) {
  const char *same_text = "step,x\n0,1.5\n1,2.5\n2,3.5\n";
  EXPECT_OK(nh_write_text(in_dir("same.csv"), same_text));
  const char *same_columns[] = {"step", "x"};
  nh_csv *csv = NULL;
  EXPECT_OK(nh_csv_resume(in_dir("same.csv"), 2, same_columns, 1, &csv));
  if (csv) EXPECT_OK(nh_csv_row(csv, "2,9"));
  nh_csv_destroy(&csv);
  char *got = read_all(in_dir("same.csv"));
  EXPECT(got && strcmp(got, "step,x\n0,1.5\n1,2.5\n2,9\n") == 0, "same.csv resumed: '%s'",
         got ? got : "(unreadable)");
  free(got);
  EXPECT(!file_exists(in_dir("same.csv.old")), "same columns: the file was moved aside");

  const char *old_text = "step,time,\"note, quoted\",gone\n"
                         "0,0,\"a, \"\"0\"\"\",g0\n"
                         "1,0.5,\"a, \"\"1\"\"\",g1\n"
                         "2,1,plain,g2\n"
                         "3,1.5,late,g3\n";
  EXPECT_OK(nh_write_text(in_dir("resume.csv"), old_text));
  const char *columns[] = {"step", "time", "added", "note, quoted"};
  EXPECT_OK(nh_csv_resume(in_dir("resume.csv"), 4, columns, 2, &csv));
  nh_csv_destroy(&csv);
  got = read_all(in_dir("resume.csv"));
  const char *want = "step,time,added,\"note, quoted\"\n"
                     "0,0,,\"a, \"\"0\"\"\"\n"
                     "1,0.5,,\"a, \"\"1\"\"\"\n"
                     "2,1,,plain\n";
  EXPECT(got && strcmp(got, want) == 0, "resume.csv mapped by name:\n%s\nexpected:\n%s",
         got ? got : "(unreadable)", want);
  free(got);
  got = read_all(in_dir("resume.csv.old"));
  EXPECT(got && strcmp(got, old_text) == 0, "resume.csv.old is not the old file: '%s'",
         got ? got : "(missing)");
  free(got);
}

/* Every writer fails with NH_ERR_IO and a message naming the path. */
static void check_failures(void) {
  const char *missing = in_dir("no/such/folder/x.vtu");
  hex_data h;
  hex_build(&h, 0);
  nh_error_clear();
  int rc = nh_vtu_write(missing, &h.grid);
  EXPECT(rc == NH_ERR_IO, "VTU into a missing folder: got %d, expected NH_ERR_IO", rc);
  EXPECT(strstr(nh_error_message(), missing) != NULL, "message '%s' does not name '%s'",
         nh_error_message(), missing);

  const char *missing_pvd = in_dir("no/such/folder/x.pvd");
  nh_pvd *pvd = NULL;
  nh_error_clear();
  rc = nh_pvd_create(missing_pvd, &pvd);
  EXPECT(rc == NH_ERR_IO && pvd == NULL, "PVD into a missing folder: got %d", rc);
  EXPECT(strstr(nh_error_message(), missing_pvd) != NULL, "message '%s' does not name '%s'",
         nh_error_message(), missing_pvd);

  const char *missing_csv = in_dir("no/such/folder/x.csv");
  const char *columns[] = {"a"};
  nh_csv *csv = NULL;
  nh_error_clear();
  rc = nh_csv_create(missing_csv, 1, columns, &csv);
  EXPECT(rc == NH_ERR_IO && csv == NULL, "CSV into a missing folder: got %d", rc);
  EXPECT(strstr(nh_error_message(), missing_csv) != NULL, "message '%s' does not name '%s'",
         nh_error_message(), missing_csv);

  const char *missing_txt = in_dir("no/such/folder/x.txt");
  nh_error_clear();
  rc = nh_write_text(missing_txt, "x");
  EXPECT(rc == NH_ERR_IO, "text into a missing folder: got %d", rc);
  EXPECT(strstr(nh_error_message(), missing_txt) != NULL, "message '%s' does not name '%s'",
         nh_error_message(), missing_txt);
  EXPECT(!file_exists(in_dir("no")), "a failed write created a folder");

  /* A full disk: "<path>.tmp" is a link to /dev/full, so opening succeeds and
   * writing fails (ENOSPC, at the latest when fclose flushes). The writer must
   * report it, remove the tmp file and leave no file at the path. */
  if (file_exists("/dev/full")) {
    const char *full[2] = {in_dir("full.vtu"), in_dir("full.txt")};
    for (int k = 0; k < 2; ++k) {
      char tmp[8300];
      snprintf(tmp, sizeof tmp, "%s.tmp", full[k]);
      remove(tmp);
      EXPECT(symlink("/dev/full", tmp) == 0, "symlink %s: %s", tmp, strerror(errno));
      nh_error_clear();
      rc = k == 0 ? nh_vtu_write(full[k], &h.grid) : nh_write_text(full[k], "x");
      EXPECT(rc == NH_ERR_IO, "%s on a full disk: got %d, expected NH_ERR_IO", full[k], rc);
      EXPECT(strstr(nh_error_message(), full[k]) != NULL, "message '%s' does not name '%s'",
             nh_error_message(), full[k]);
      EXPECT(!file_exists(full[k]), "%s exists after a failed write", full[k]);
      struct stat lst;
      EXPECT(lstat(tmp, &lst) != 0, "%s left behind after a failed write", tmp);
      remove(tmp);
    }
  }

  /* mkdir -p: nested, idempotent, trailing slash; a file in the way fails. */
  EXPECT_OK(nh_mkdir_p(in_dir("mk/a/b/c")));
  EXPECT_OK(nh_mkdir_p(in_dir("mk/a/b/c")));
  EXPECT_OK(nh_mkdir_p(in_dir("mk/a/b/")));
  struct stat st;
  EXPECT(stat(in_dir("mk/a/b/c"), &st) == 0 && S_ISDIR(st.st_mode), "mk/a/b/c is not a folder");
  const char *blocked = in_dir("hello.txt/sub");
  nh_error_clear();
  rc = nh_mkdir_p(blocked);
  EXPECT(rc == NH_ERR_IO, "mkdir -p through a file: got %d, expected NH_ERR_IO", rc);
  EXPECT(strstr(nh_error_message(), blocked) != NULL, "message '%s' does not name '%s'",
         nh_error_message(), blocked);
}

static void check_no_tmp(void) {
  DIR *d = opendir(dir);
  EXPECT(d != NULL, "cannot list %s: %s", dir, strerror(errno));
  if (!d) return;
  struct dirent *e;
  while ((e = readdir(d))) {
    size_t n = strlen(e->d_name);
    EXPECT(!(n >= 4 && strcmp(e->d_name + n - 4, ".tmp") == 0), "%s/%s left behind", dir,
           e->d_name);
  }
  closedir(d);
}

int main(int argc, char **argv) {
  int keep = argc > 1;
  if (keep) {
    snprintf(dir, sizeof dir, "%s", argv[1]);
    if (nh_mkdir_p(dir)) {
      fprintf(stderr, "test_io: %s\n", nh_error_message());
      return 1;
    }
    remove_written(); /* a fresh start: files of an earlier run must not count */
  } else {
    const char *base = getenv("NH_WORK");
    snprintf(dir, sizeof dir, "%s/test_io_XXXXXX", base && base[0] ? base : "/tmp");
    if (!mkdtemp(dir)) {
      fprintf(stderr, "test_io: mkdtemp %s: %s\n", dir, strerror(errno));
      return 1;
    }
  }

  write_vtus();
  write_pvds();
  write_csvs();
  resume_csvs();
  check_failures();
  check_no_tmp();

  if (nh_test_failures) {
    fprintf(stderr, "test_io: %d failure(s); files kept in %s\n", nh_test_failures, dir);
    return 1;
  }
  if (!keep) {
    remove_written();
    rmdir(dir);
  }
  return 0;
}
