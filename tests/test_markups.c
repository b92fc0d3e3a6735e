/* test_markups — 3D Slicer markups in and out (docs/anatomy.md, "Markups").
 *  1. Frames and units: one target and one Line written as RAS and as LPS
 *     (x, y negated), in mm and in um, as .mrk.json and as .fcsv (RAS, LPS,
 *     the legacy codes 0 and 1, no CoordinateSystem line: RAS; a "# columns"
 *     line with the columns reordered), and a .mrk.json without
 *     coordinateSystem (the schema's default, LPS): every file gives the same
 *     scene point, the RAS metres written in the test, to round-off (1e-15 m:
 *     one multiplication by 1e-3 or 1e-6). The Line's two points, by label
 *     and by nh_markups_line.
 *  2. Every error names the file and what is wrong: a missing file, a file
 *     above the size limit (a sparse file: refused from its size), not JSON
 *     (the line and column), truncated JSON, JSON without "markups", an
 *     unknown type, coordinateSystem, coordinateUnits, a position that is not
 *     3 numbers, an infinite coordinate (1e999), one 100 m from the origin,
 *     an unknown label (the labels listed, capped at 8 with the count), a
 *     label twice in one markup, a label in two markups, a Curve's, Plane's
 *     and ROI's point, an undefined position, a .fcsv with a bad number, a
 *     bad CoordinateSystem, too few fields, no Line and two Lines.
 *  3. The writer: a Curve of 5 points and Fiducials with labels (one with a
 *     quote, a comma and non-ASCII letters) read back through the reader
 *     give the same points (to 1e-12 m: 12 significant digits in mm),
 *     labels, types and names; a Curve's point is refused as a target; a
 *     file in a missing folder is NH_ERR_IO naming it. The files are left in
 *     the scratch folder for tests/markups_schema.py.
 * Argument: a scratch folder. Silent on success. */
#include "check.h"
#include "io/io.h"

#include <fcntl.h>
#include <string.h>
#include <unistd.h>

static const char *dir;
static char path_buf[1024];

static const char *put(const char *name, const char *text) {
  snprintf(path_buf, sizeof path_buf, "%s/%s", dir, name);
  FILE *f = fopen(path_buf, "w");
  if (!f || fputs(text, f) < 0 || fclose(f) != 0) {
    fprintf(stderr, "cannot write %s\n", path_buf);
    exit(1);
  }
  return path_buf;
}

/* The target STN_R at RAS (12.3, −45.6, 78.9) mm and the Line entry → tip. */
static const double stn[3] = {0.0123, -0.0456, 0.0789};
static const double entry[3] = {0.031, 0.0205, 0.0955}, tip[3] = {0.0125, -0.012, 0.002};

/* A .mrk.json with the target and the Line, in `system` ("" : no key) and
 * `units` (a JSON value), coordinates in that frame and unit. */
static const char *json_file(const char *name, const char *system, const char *units,
                             double scale) {
  double s[3] = {1, 1, 1};
  if (strcmp(system, "RAS") != 0) s[0] = s[1] = -1; /* LPS, or the default LPS */
  char sys[64] = "";
  if (system[0]) snprintf(sys, sizeof sys, "\"coordinateSystem\": \"%s\", ", system);
  static char text[4096];
  snprintf(text, sizeof text,
           "{\"@schema\": \"https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/"
           "Markups/Resources/Schema/markups-schema-v1.0.3.json#\",\n"
           " \"markups\": [\n"
           "  {\"type\": \"Fiducial\", %s\"coordinateUnits\": %s, \"name\": \"targets\",\n"
           "   \"controlPoints\": [{\"id\": \"1\", \"label\": \"STN_R\", \"position\": [%.17g, "
           "%.17g, %.17g], \"positionStatus\": \"defined\"}]},\n"
           "  {\"type\": \"Line\", %s\"coordinateUnits\": %s, \"name\": \"trajectory\",\n"
           "   \"controlPoints\": [{\"label\": \"entry\", \"position\": [%.17g, %.17g, %.17g]},\n"
           "                     {\"label\": \"tip\", \"position\": [%.17g, %.17g, %.17g]}]}\n"
           " ]}\n",
           sys, units, s[0] * stn[0] * scale, s[1] * stn[1] * scale, stn[2] * scale, sys, units,
           s[0] * entry[0] * scale, s[1] * entry[1] * scale, entry[2] * scale,
           s[0] * tip[0] * scale, s[1] * tip[1] * scale, tip[2] * scale);
  return put(name, text);
}

/* A .fcsv with the target; `system` NULL: no CoordinateSystem line. */
static const char *fcsv_file(const char *name, const char *system, int lps, int reorder) {
  double s = lps ? -1.0 : 1.0;
  static char text[2048];
  char sys[64] = "";
  if (system) snprintf(sys, sizeof sys, "# CoordinateSystem = %s\n", system);
  if (reorder)
    snprintf(text, sizeof text,
             "# Markups fiducial file version = 4.10\n%s"
             "# columns = label,id,z,y,x\n"
             "STN_R,vtkMRMLMarkupsFiducialNode_0,%.17g,%.17g,%.17g\n",
             sys, 1e3 * stn[2], s * 1e3 * stn[1], s * 1e3 * stn[0]);
  else
    snprintf(text, sizeof text,
             "# Markups fiducial file version = 4.10\n%s"
             "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n"
             "vtkMRMLMarkupsFiducialNode_1,%.17g,%.17g,%.17g,0,0,0,1,1,1,0,\"other, one\",,\r\n"
             "vtkMRMLMarkupsFiducialNode_0,%.17g,%.17g,%.17g,0,0,0,1,1,1,0,STN_R,,\r\n",
             sys, 1.0, 2.0, 3.0, s * 1e3 * stn[0], s * 1e3 * stn[1], 1e3 * stn[2]);
  return put(name, text);
}

static void expect_point(const char *path, const char *label, const double want[3]) {
  double x[3] = {NAN, NAN, NAN};
  int rc = nh_markups_find_point(path, label, x);
  EXPECT(rc == NH_OK, "%s: %s", path, label);
  for (int k = 0; k < 3; k++) CHECK_CLOSE(x[k], want[k], 1e-15, path);
}

/* The file must be refused with a message holding each of the strings. */
static void expect_error(const char *path, const char *label, const char *a, const char *b) {
  double x[3];
  int rc = nh_markups_find_point(path, label, x);
  const char *msg = nh_error_message();
  CHECK(rc == NH_ERR_INPUT, "%s (%s): rc %d, expected NH_ERR_INPUT", path, label, rc);
  CHECK(strncmp(msg, path, strlen(path)) == 0, "message does not start with the path: %s", msg);
  CHECK(strstr(msg, a), "message lacks \"%s\": %s", a, msg);
  CHECK(!b || strstr(msg, b), "message lacks \"%s\": %s", b, msg);
}

static void frames(void) {
  const char *files[] = {
      json_file("ras_mm.mrk.json", "RAS", "\"mm\"", 1e3),
      json_file("lps_mm.mrk.json", "LPS", "\"mm\"", 1e3),
      json_file("ras_um.mrk.json", "RAS", "\"um\"", 1e6),
      json_file("lps_um.mrk.json", "LPS", "[\"um\", \"UCUM\", \"micrometer\"]", 1e6),
      json_file("default.mrk.json", "", "\"mm\"", 1e3),
  };
  char copy[5][1024];
  for (int i = 0; i < 5; i++) snprintf(copy[i], sizeof copy[i], "%s", files[i]);
  for (int i = 0; i < 5; i++) {
    nh_markups *m;
    EXPECT_OK(nh_markups_read(copy[i], &m));
    if (!m) continue;
    expect_point(copy[i], "STN_R", stn);
    expect_point(copy[i], "entry", entry);
    expect_point(copy[i], "tip", tip);
    double a[3], b[3];
    EXPECT_OK(nh_markups_line(m, NULL, a, b));
    EXPECT_OK(nh_markups_line(m, "trajectory", a, b));
    for (int k = 0; k < 3; k++) {
      CHECK_CLOSE(a[k], entry[k], 1e-15, "line entry");
      CHECK_CLOSE(b[k], tip[k], 1e-15, "line tip");
    }
    CHECK(m->n_markups == 2 && m->markup[1].type == NH_MARKUP_LINE, "%s: markups", copy[i]);
    nh_markups_destroy(&m);
    CHECK(!m, "destroy sets NULL");
  }
  struct {
    const char *name, *system;
    int lps, reorder;
  } f[] = {{"ras.fcsv", "RAS", 0, 0}, {"lps.fcsv", "LPS", 1, 0}, {"zero.fcsv", "0", 0, 0},
           {"one.fcsv", "1", 1, 0},   {"none.fcsv", NULL, 0, 0}, {"cols.fcsv", "LPS", 1, 1}};
  for (int i = 0; i < 6; i++) {
    const char *p = fcsv_file(f[i].name, f[i].system, f[i].lps, f[i].reorder);
    char c[1024];
    snprintf(c, sizeof c, "%s", p);
    expect_point(c, "STN_R", stn);
    if (!f[i].reorder) {
      const double other[3] = {f[i].lps ? -1e-3 : 1e-3, f[i].lps ? -2e-3 : 2e-3, 3e-3};
      expect_point(c, "other, one", other);
    }
  }
}

static void errors(void) {
  char p[1024];
  snprintf(p, sizeof p, "%s/missing.mrk.json", dir);
  expect_error(p, "STN_R", "cannot open", NULL);
  /* a sparse file above the limit: refused from its size */
  snprintf(p, sizeof p, "%s/huge.mrk.json", dir);
  int fd = open(p, O_CREAT | O_TRUNC | O_WRONLY, 0644);
  CHECK(fd >= 0 && ftruncate(fd, NH_MARKUPS_MAX_BYTES + 1) == 0 && close(fd) == 0, "sparse file");
  expect_error(p, "STN_R", "bytes, above the", NULL);
  remove(p);
  expect_error(put("syntax.mrk.json", "{\"markups\": [\n  {\"type\": \"Fiducial\",}\n]}\n"),
               "STN_R", "syntax.mrk.json:2:", "not JSON");
  expect_error(put("short.mrk.json", "{\"markups\": [{\"type\": \"Fid"), "STN_R", "unexpected end",
               NULL);
  expect_error(put("trailing.mrk.json", "{\"markups\": []} x"), "STN_R",
               "trailing.mrk.json:1:17: not JSON", NULL);
  expect_error(put("other.json", "{\"nodes\": [1, 2]}"), "STN_R", "no \"markups\" array", NULL);
  expect_error(put("comment.mrk.json", "# a comment\n"), "STN_R", "neither JSON nor a .fcsv", NULL);
#define MARKUP(body)    "{\"markups\": [" body "]}"
#define POINT(label, x) "{\"label\": \"" label "\", \"position\": " x "}"
  expect_error(put("type.mrk.json", MARKUP("{\"type\": \"Spline\"}")), "STN_R",
               "type \"Spline\" is not one of", NULL);
  expect_error(
      put("system.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"coordinateSystem\": \"IJK\"}")),
      "STN_R", "coordinateSystem \"IJK\" is not RAS or LPS", NULL);
  expect_error(
      put("units.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"coordinateUnits\": \"cm\"}")),
      "STN_R", "coordinateUnits \"cm\" is not mm or um", NULL);
  expect_error(put("two.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"controlPoints\": [" POINT(
                                       "STN_R", "[1, 2]") "]}")),
               "STN_R", "position is not an array of 3 numbers", "controlPoints[0] (\"STN_R\")");
  expect_error(put("text.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"controlPoints\": [" POINT(
                                        "STN_R", "[1, \"2\", 3]") "]}")),
               "STN_R", "position is not an array of 3 numbers", NULL);
  expect_error(put("inf.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"controlPoints\": [" POINT(
                                       "STN_R", "[1, 1e999, 3]") "]}")),
               "STN_R", "not a finite number", NULL);
  expect_error(put("far.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"controlPoints\": [" POINT(
                                       "STN_R", "[1e5, 0, 0]") "]}")),
               "STN_R", "farther than 10 m", "wrong units");
  const char *good = json_file("good.mrk.json", "RAS", "\"mm\"", 1e3);
  char g[1024];
  snprintf(g, sizeof g, "%s", good);
  expect_error(g, "STN_L", "no control point labelled \"STN_L\"",
               "labels: \"STN_R\", \"entry\", \"tip\")");
  char many[8192] = "{\"markups\": [{\"type\": \"Fiducial\", \"controlPoints\": [";
  for (int i = 0; i < 20; i++) {
    size_t len = strlen(many);
    snprintf(many + len, sizeof many - len, "%s{\"label\": \"F-%d\", \"position\": [%d, 0, 0]}",
             i ? ", " : "", i + 1, i);
  }
  strcat(many, "]}]}");
  expect_error(put("many.mrk.json", many), "F-99", "\"F-8\", ... (20 in all)", NULL);
  expect_error(put("dup.mrk.json",
                   MARKUP("{\"type\": \"Fiducial\", \"name\": \"T\", \"controlPoints\": [" POINT(
                       "STN_R", "[1, 2, 3]") ", " POINT("STN_R", "[1, 2, 4]") "]}")),
               "STN_R", "names 2 control points of the Fiducial \"T\"", NULL);
  expect_error(
      put("both.mrk.json", MARKUP("{\"type\": \"Fiducial\", \"name\": \"T\", "
                                  "\"controlPoints\": [" POINT(
                                      "STN_R", "[1, 2, 3]") "]}, "
                                                            "{\"type\": \"Line\", \"name\": \"L\", "
                                                            "\"controlPoints\": [" POINT(
                                                                "STN_R", "[1, 2, 3]") "]}")),
      "STN_R", "more than one markup (Fiducial \"T\" and Line \"L\")", NULL);
  const char *shapes[] = {"Curve", "ClosedCurve", "Plane", "ROI", "Angle"};
  for (int i = 0; i < 5; i++) {
    char text[512], name[64], want[128];
    snprintf(text, sizeof text,
             MARKUP("{\"type\": \"%s\", \"name\": \"S\", \"controlPoints\": [" POINT(
                 "STN_R", "[1, 2, 3]") "]}"),
             shapes[i]);
    snprintf(name, sizeof name, "shape%d.mrk.json", i);
    snprintf(want, sizeof want, "is a control point of the %s \"S\", not a point", shapes[i]);
    expect_error(put(name, text), "STN_R", want, NULL);
  }
  expect_error(put("undefined.mrk.json",
                   MARKUP("{\"type\": \"Fiducial\", \"controlPoints\": [{\"label\": \"STN_R\", "
                          "\"positionStatus\": \"undefined\"}]}")),
               "STN_R", "has no position", NULL);
  expect_error(put("nan.fcsv", "# Markups fiducial file version = 4.10\n"
                               "# CoordinateSystem = LPS\n"
                               "a,1,2,3,0,0,0,1,1,1,0,STN_R,,\n"
                               "b,1,two,3,0,0,0,1,1,1,0,STN_L,,\n"),
               "STN_R", "nan.fcsv:4: y = \"two\" is not a number", NULL);
  expect_error(put("sys.fcsv", "# Markups fiducial file version = 4.10\n"
                               "# CoordinateSystem = 2\n"
                               "a,1,2,3,0,0,0,1,1,1,0,STN_R,,\n"),
               "STN_R", "sys.fcsv:2: CoordinateSystem \"2\"", NULL);
  expect_error(put("short.fcsv", "# Markups fiducial file version = 4.10\n"
                                 "a,1,2,3,0,0,0,1\n"),
               "STN_R", "short.fcsv:2: 8 fields", NULL);
  expect_error(put("quote.fcsv", "# Markups fiducial file version = 4.10\n"
                                 "a,1,2,3,0,0,0,1,1,1,0,\"STN_R,,\n"),
               "STN_R", "quote.fcsv:2: a quoted field is not closed", NULL);
  /* Lines */
  nh_markups *m;
  double a[3], b[3];
  CHECK_OK(nh_markups_read(put("nolines.mrk.json", MARKUP("{\"type\": \"Fiducial\"}")), &m));
  CHECK(nh_markups_line(m, NULL, a, b) == NH_ERR_INPUT &&
            strstr(nh_error_message(), "no Line markup (Lines: none)"),
        "no line: %s", nh_error_message());
  nh_markups_destroy(&m);
  CHECK_OK(nh_markups_read(
      put("lines.mrk.json", MARKUP("{\"type\": \"Line\", \"name\": \"A\"}, {\"type\": \"Line\", "
                                   "\"name\": \"B\"}")),
      &m));
  CHECK(nh_markups_line(m, NULL, a, b) == NH_ERR_INPUT &&
            strstr(nh_error_message(), "2 Line markups: name one (Lines: \"A\", \"B\")"),
        "two lines: %s", nh_error_message());
  CHECK(nh_markups_line(m, "A", a, b) == NH_ERR_INPUT &&
            strstr(nh_error_message(), "the Line \"A\" does not have two defined points"),
        "empty line: %s", nh_error_message());
  nh_markups_destroy(&m);
#undef MARKUP
#undef POINT
}

static void writer(void) {
  double axis[15], targets[9] = {0.0123, -0.0456, 0.0789, -0.011, 0.0, 1e-9, 0.1, 0.2, -0.3};
  for (int i = 0; i < 5; i++)
    for (int k = 0; k < 3; k++) axis[3 * i + k] = entry[k] + (tip[k] - entry[k]) * i / 4.0;
  const char *labels[3] = {"STN_R", "GPi \"left\", ventral", "Zona incerta \xc3\xa9"};
  char curve[1024], fid[1024];
  snprintf(curve, sizeof curve, "%s/electrode.mrk.json", dir);
  snprintf(fid, sizeof fid, "%s/targets.mrk.json", dir);
  CHECK_OK(nh_markups_write(curve, NH_MARKUP_CURVE, "electrode", 5, axis, NULL));
  CHECK_OK(nh_markups_write(fid, NH_MARKUP_FIDUCIAL, "targets", 3, targets, labels));
  nh_markups *m;
  CHECK_OK(nh_markups_read(curve, &m));
  CHECK(m->n_markups == 1 && m->markup[0].type == NH_MARKUP_CURVE &&
            strcmp(m->markup[0].name, "electrode") == 0 && m->n_points == 5,
        "curve read back: %d markups, %d points", m->n_markups, m->n_points);
  for (int i = 0; i < m->n_points && i < 5; i++) {
    char want[32];
    snprintf(want, sizeof want, "electrode-%d", i + 1);
    CHECK(strcmp(m->point[i].label, want) == 0, "label %s, expected %s", m->point[i].label, want);
    for (int k = 0; k < 3; k++) CHECK_CLOSE(m->point[i].x[k], axis[3 * i + k], 1e-12, "curve");
  }
  double x[3];
  CHECK(nh_markups_point(m, "electrode-1", x) == NH_ERR_INPUT, "a curve's point is not a target");
  nh_markups_destroy(&m);
  CHECK_OK(nh_markups_read(fid, &m));
  CHECK(m->n_points == 3 && m->markup[0].type == NH_MARKUP_FIDUCIAL, "fiducials read back");
  for (int i = 0; i < 3; i++) {
    EXPECT_OK(nh_markups_point(m, labels[i], x));
    for (int k = 0; k < 3; k++) CHECK_CLOSE(x[k], targets[3 * i + k], 1e-12, labels[i]);
  }
  nh_markups_destroy(&m);
  char bad[1024];
  snprintf(bad, sizeof bad, "%s/no/such/folder/t.mrk.json", dir);
  int rc = nh_markups_write(bad, NH_MARKUP_FIDUCIAL, "t", 1, targets, NULL);
  CHECK(rc == NH_ERR_IO && strstr(nh_error_message(), bad), "missing folder: %d %s", rc,
        nh_error_message());
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: test_markups SCRATCH_DIR\n");
    return 2;
  }
  dir = argv[1];
  frames();
  errors();
  writer();
  TEST_END();
}
