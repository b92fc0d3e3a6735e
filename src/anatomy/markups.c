/* markups.c — points planned in 3D Slicer: `.mrk.json` markups files and the
 * legacy `.fcsv` fiducial lists, read into the scene frame (docs/anatomy.md,
 * "Markups").
 *
 * Frames. Slicer's world frame is RAS (x right, y anterior, z superior), the
 * frame in which it places a NIfTI image by its sform/qform, which is the
 * scene's frame (anatomy.h). A file states the frame its numbers are in:
 * RAS, or LPS (ITK's and DICOM's patient frame, x left, y posterior), which
 * Slicer writes by default since version 4.11; the two differ by the sign of
 * x and y:  (x, y, z)_RAS = (−x, −y, z)_LPS. Units are mm or um (µm) in a
 * .mrk.json file and mm in a .fcsv; every point is converted to metres.
 *
 * .mrk.json (schema markups-schema-v1.0.3, Slicer 4.11 and later): the JSON
 * is parsed by json-c (Debian's libjson-c), strictly (RFC 8259: no comments,
 * no trailing commas, no NaN; UTF-8 checked), and then walked: markups[] of
 * objects with "type" (required), "name", "coordinateSystem" (default LPS,
 * the schema's), "coordinateUnits" (default mm; a string or the schema's
 * [code, scheme, meaning] triple), "controlPoints"[] with "label",
 * "position" [3 numbers] and "positionStatus" (defined, preview or undefined:
 * only a defined point, or one without a status, has a position). Unknown
 * keys are ignored, as the schema allows (additionalProperties).
 *
 * .fcsv (Slicer up to 4.10, still read by Slicer): "#" header lines, among
 * them "# Markups fiducial file version = V" (the first line, which tells the
 * format), "# CoordinateSystem = RAS | LPS | 0 | 1" (0 is RAS, 1 LPS; no
 * such line: RAS, the frame of the versions before the line existed) and
 * "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID"
 * (those columns when the line is absent); then one comma-separated row per
 * point, a field in double quotes when it holds a comma ("" for a quote).
 *
 * Size. A markups file holds tens of points (kilobytes); a file above
 * NH_MARKUPS_MAX_BYTES (16 MiB) is refused from its size before a byte is
 * parsed, so a wrong path (an image, a log) costs nothing. json-c's default
 * nesting limit (32) bounds the parser's recursion.
 *
 * Lookup. A scene names a point by its label. Labels need not be unique in a
 * Slicer file, so a label is accepted only when it names exactly one point of
 * the file, and that point belongs to a Fiducial or a Line markup (a point of
 * a curve, an angle, a plane or an ROI is a shape's handle, not a target).
 * Line markups also give their two points (a trajectory's entry and target). */
#include "anatomy/anatomy.h"

#include <errno.h>
#include <json.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static const char *const nh_markup_types[] = {"Fiducial",    "Line",  "Angle", "Curve",
                                              "ClosedCurve", "Plane", "ROI"};
enum { NH_MARKUP_TYPES = 7, NH_LIST_MAX = 8 };

const char *nh_markup_type_name(nh_markup_type type) {
  return (int)type >= 0 && (int)type < NH_MARKUP_TYPES ? nh_markup_types[type] : "?";
}

void nh_markups_destroy(nh_markups **markups) {
  if (!markups || !*markups) return;
  nh_markups *m = *markups;
  for (int i = 0; i < m->n_markups; i++) free(m->markup[i].name);
  for (int i = 0; i < m->n_points; i++) free(m->point[i].label);
  free(m->markup);
  free(m->point);
  free(m);
  *markups = NULL;
}

static char *nh_strndup(const char *s, size_t n) {
  char *c = nh_calloc(n + 1, 1);
  if (c) memcpy(c, s, n);
  return c;
}

/* The whole file into *buf (NUL-terminated, *len bytes), refused above the
 * size limit before reading. */
static int nh_markups_slurp(const char *path, char **buf, size_t *len) {
  *buf = NULL, *len = 0;
  FILE *f = fopen(path, "rb");
  if (!f) return NH_ERROR(NH_ERR_INPUT, "%s: cannot open: %s", path, strerror(errno));
  struct stat st;
  if (fstat(fileno(f), &st) != 0 || !S_ISREG(st.st_mode)) {
    fclose(f);
    return NH_ERROR(NH_ERR_INPUT, "%s: not a regular file", path);
  }
  if (st.st_size > NH_MARKUPS_MAX_BYTES) {
    fclose(f);
    return NH_ERROR(NH_ERR_INPUT,
                    "%s: %lld bytes, above the %ld bytes a markups file may have (a markups "
                    "file holds points: is it the right file?)",
                    path, (long long)st.st_size, (long)NH_MARKUPS_MAX_BYTES);
  }
  size_t n = (size_t)st.st_size;
  char *b = nh_calloc(n + 1, 1);
  if (!b) {
    fclose(f);
    return NH_ERR_MEMORY;
  }
  size_t got = fread(b, 1, n, f);
  int bad = ferror(f) || got != n;
  fclose(f);
  if (bad) {
    free(b);
    return NH_ERROR(NH_ERR_INPUT, "%s: read error", path);
  }
  *buf = b, *len = n;
  return NH_OK;
}

/* Convert p (file frame and unit) to the scene frame, checking it. `where`
 * names the point in messages. */
static int nh_markups_convert(const char *path, const char *where, int lps, double unit,
                              const char *unit_name, const double p[3], double x[3]) {
  for (int k = 0; k < 3; k++)
    NH_CHECK(isfinite(p[k]), NH_ERR_INPUT, "%s: %s: coordinate %d is %g, not a finite number", path,
             where, k, p[k]);
  for (int k = 0; k < 3; k++) x[k] = p[k] * unit * (lps && k < 2 ? -1.0 : 1.0);
  NH_CHECK(nh_vec3_norm(x) <= NH_MARKUPS_MAX_COORDINATE, NH_ERR_INPUT,
           "%s: %s: position [%g, %g, %g] %s lies %g m from the origin, farther than %g m: not "
           "a coordinate of the patient (wrong units?)",
           path, where, p[0], p[1], p[2], unit_name, nh_vec3_norm(x), NH_MARKUPS_MAX_COORDINATE);
  return NH_OK;
}

/* ---- .mrk.json ---- */

/* Line and column (from 1) of byte `at` of buf. */
static void nh_line_column(const char *buf, size_t at, int *line, int *column) {
  *line = 1, *column = 1;
  for (size_t i = 0; i < at && buf[i]; i++) {
    if (buf[i] == '\n')
      ++*line, *column = 1;
    else
      ++*column;
  }
}

static int nh_json_parse(const char *path, const char *buf, size_t len, json_object **out) {
  *out = NULL;
  size_t skip = len >= 3 && memcmp(buf, "\xEF\xBB\xBF", 3) == 0 ? 3 : 0; /* a UTF-8 BOM */
  struct json_tokener *tok = json_tokener_new();
  if (!tok) return NH_ERROR(NH_ERR_MEMORY, "out of memory: JSON parser for %s", path);
  json_tokener_set_flags(tok, JSON_TOKENER_STRICT | JSON_TOKENER_VALIDATE_UTF8);
  json_object *root = json_tokener_parse_ex(tok, buf + skip, (int)(len - skip));
  enum json_tokener_error err = json_tokener_get_error(tok);
  size_t end = skip + json_tokener_get_parse_end(tok);
  json_tokener_free(tok);
  int line, column;
  if (!root) {
    nh_line_column(buf, end, &line, &column);
    return NH_ERROR(NH_ERR_INPUT, "%s:%d:%d: not JSON: %s", path, line, column,
                    err == json_tokener_continue ? "unexpected end of the file"
                                                 : json_tokener_error_desc(err));
  }
  while (end < len && strchr(" \t\r\n", buf[end])) end++;
  if (end < len) {
    json_object_put(root);
    nh_line_column(buf, end, &line, &column);
    return NH_ERROR(NH_ERR_INPUT, "%s:%d:%d: not JSON: text after the end of the JSON value", path,
                    line, column);
  }
  *out = root;
  return NH_OK;
}

/* The string member `key` of obj: *s (NULL if absent). NH_ERR_INPUT if it is
 * not a string. */
static int nh_json_string(const char *path, const char *where, json_object *obj, const char *key,
                          const char **s) {
  json_object *v;
  *s = NULL;
  if (!json_object_object_get_ex(obj, key, &v) || json_object_is_type(v, json_type_null))
    return NH_OK;
  NH_CHECK(json_object_is_type(v, json_type_string), NH_ERR_INPUT, "%s: %s: \"%s\" is not a string",
           path, where, key);
  *s = json_object_get_string(v);
  return NH_OK;
}

typedef struct {
  int lps;
  double unit;
  const char *unit_name;
} nh_markup_frame;

/* The frame of markup obj (`where` names it). */
static int nh_json_frame(const char *path, const char *where, json_object *obj,
                         nh_markup_frame *fr) {
  const char *system;
  NH_TRY(nh_json_string(path, where, obj, "coordinateSystem", &system));
  if (!system || strcmp(system, "LPS") == 0)
    fr->lps = 1; /* the schema's default */
  else if (strcmp(system, "RAS") == 0)
    fr->lps = 0;
  else
    return NH_ERROR(NH_ERR_INPUT, "%s: %s: coordinateSystem \"%s\" is not RAS or LPS", path, where,
                    system);
  json_object *u;
  const char *units = "mm";
  if (json_object_object_get_ex(obj, "coordinateUnits", &u) &&
      !json_object_is_type(u, json_type_null)) {
    if (json_object_is_type(u, json_type_array) && json_object_array_length(u) >= 1)
      u = json_object_array_get_idx(u, 0); /* ["mm", "UCUM", "millimeter"] */
    NH_CHECK(json_object_is_type(u, json_type_string), NH_ERR_INPUT,
             "%s: %s: coordinateUnits is not a string", path, where);
    units = json_object_get_string(u);
  }
  if (strcmp(units, "mm") == 0)
    fr->unit = 1e-3, fr->unit_name = "mm";
  else if (strcmp(units, "um") == 0)
    fr->unit = 1e-6, fr->unit_name = "um";
  else
    return NH_ERROR(NH_ERR_INPUT, "%s: %s: coordinateUnits \"%s\" is not mm or um", path, where,
                    units);
  return NH_OK;
}

/* Control point j of markup i: label, position (scene frame), defined. */
static int nh_json_point(nh_markups *m, const char *where_markup, json_object *cp, int j,
                         const nh_markup_frame *fr, nh_markup_point *pt) {
  char where[160];
  snprintf(where, sizeof where, "%s controlPoints[%d]", where_markup, j);
  NH_CHECK(json_object_is_type(cp, json_type_object), NH_ERR_INPUT, "%s: %s is not an object",
           m->path, where);
  const char *label, *status;
  NH_TRY(nh_json_string(m->path, where, cp, "label", &label));
  NH_TRY(nh_json_string(m->path, where, cp, "positionStatus", &status));
  pt->label = nh_strndup(label ? label : "", label ? strlen(label) : 0);
  if (!pt->label) return NH_ERR_MEMORY;
  if (label) {
    size_t len = strlen(where);
    snprintf(where + len, sizeof where - len, " (\"%.40s\")", label);
  }
  NH_CHECK(!status || strcmp(status, "defined") == 0 || strcmp(status, "preview") == 0 ||
               strcmp(status, "undefined") == 0,
           NH_ERR_INPUT, "%s: %s: positionStatus \"%s\" is not defined, preview or undefined",
           m->path, where, status);
  pt->defined = !status || strcmp(status, "defined") == 0;
  json_object *pos;
  if (!json_object_object_get_ex(cp, "position", &pos)) {
    NH_CHECK(!pt->defined, NH_ERR_INPUT, "%s: %s: no position", m->path, where);
    return NH_OK;
  }
  int ok = json_object_is_type(pos, json_type_array) && json_object_array_length(pos) == 3;
  double p[3] = {0, 0, 0};
  for (int k = 0; ok && k < 3; k++) {
    json_object *c = json_object_array_get_idx(pos, (size_t)k);
    ok = json_object_is_type(c, json_type_double) || json_object_is_type(c, json_type_int);
    if (ok) p[k] = json_object_get_double(c);
  }
  NH_CHECK(ok, NH_ERR_INPUT, "%s: %s: position is not an array of 3 numbers", m->path, where);
  if (!pt->defined) return NH_OK; /* a placeholder's numbers mean nothing */
  return nh_markups_convert(m->path, where, fr->lps, fr->unit, fr->unit_name, p, pt->x);
}

static int nh_json_markup(nh_markups *m, json_object *obj, int i) {
  char where[96];
  snprintf(where, sizeof where, "markups[%d]", i);
  NH_CHECK(json_object_is_type(obj, json_type_object), NH_ERR_INPUT, "%s: %s is not an object",
           m->path, where);
  nh_markup *mk = &m->markup[i];
  const char *type, *name;
  NH_TRY(nh_json_string(m->path, where, obj, "type", &type));
  NH_TRY(nh_json_string(m->path, where, obj, "name", &name));
  mk->name = nh_strndup(name ? name : "", name ? strlen(name) : 0);
  if (!mk->name) return NH_ERR_MEMORY;
  if (name) snprintf(where, sizeof where, "markups[%d] (\"%.40s\")", i, name);
  NH_CHECK(type, NH_ERR_INPUT, "%s: %s has no \"type\"", m->path, where);
  int t = 0;
  while (t < NH_MARKUP_TYPES && strcmp(type, nh_markup_types[t]) != 0) t++;
  NH_CHECK(t < NH_MARKUP_TYPES, NH_ERR_INPUT,
           "%s: %s: type \"%s\" is not one of Fiducial, Line, Angle, Curve, ClosedCurve, Plane, "
           "ROI",
           m->path, where, type);
  mk->type = (nh_markup_type)t;
  nh_markup_frame fr = {1, 1e-3, "mm"};
  NH_TRY(nh_json_frame(m->path, where, obj, &fr));
  json_object *cps;
  mk->first = m->n_points, mk->n = 0;
  if (!json_object_object_get_ex(obj, "controlPoints", &cps)) return NH_OK;
  NH_CHECK(json_object_is_type(cps, json_type_array), NH_ERR_INPUT,
           "%s: %s: controlPoints is not an array", m->path, where);
  for (size_t j = 0; j < json_object_array_length(cps); j++) {
    nh_markup_point *pt = &m->point[m->n_points++];
    pt->markup = i;
    NH_TRY(nh_json_point(m, where, json_object_array_get_idx(cps, j), (int)j, &fr, pt));
    mk->n++;
  }
  return NH_OK;
}

static int nh_markups_from_json(nh_markups *m, json_object *root) {
  json_object *list;
  NH_CHECK(json_object_is_type(root, json_type_object) &&
               json_object_object_get_ex(root, "markups", &list) &&
               json_object_is_type(list, json_type_array),
           NH_ERR_INPUT, "%s: not a 3D Slicer markups file (no \"markups\" array)", m->path);
  size_t n = json_object_array_length(list), n_points = 0;
  NH_CHECK(n > 0, NH_ERR_INPUT, "%s: the \"markups\" array is empty", m->path);
  for (size_t i = 0; i < n; i++) {
    json_object *cps;
    if (json_object_object_get_ex(json_object_array_get_idx(list, i), "controlPoints", &cps) &&
        json_object_is_type(cps, json_type_array))
      n_points += json_object_array_length(cps);
  }
  m->markup = nh_calloc(n, sizeof *m->markup);
  m->point = nh_calloc(n_points ? n_points : 1, sizeof *m->point);
  if (!m->markup || !m->point) return NH_ERR_MEMORY;
  for (size_t i = 0; i < n; i++) {
    m->n_markups = (int)i + 1;
    NH_TRY(nh_json_markup(m, json_object_array_get_idx(list, i), (int)i));
  }
  return NH_OK;
}

/* ---- .fcsv ---- */

static const char nh_fcsv_header[] = "# Markups fiducial file version";
static const char *const nh_fcsv_columns[] = {
    "id", "x",   "y",   "z",    "ow",    "ox",   "oy",
    "oz", "vis", "sel", "lock", "label", "desc", "associatedNodeID"};
enum { NH_FCSV_COLUMNS = 14, NH_FCSV_FIELDS = 64 };

static char *nh_trim(char *s) {
  while (*s == ' ' || *s == '\t') s++;
  size_t n = strlen(s);
  while (n > 0 && (s[n - 1] == ' ' || s[n - 1] == '\t')) s[--n] = '\0';
  return s;
}

/* The fiducials of a .fcsv file (buf is modified). */
static int nh_markups_from_fcsv(nh_markups *m, char *buf) {
  int lps = 0, n_rows = 0;
  for (char *p = buf; *p; p++) n_rows += *p == '\n';
  m->markup = nh_calloc(1, sizeof *m->markup);
  m->point = nh_calloc((size_t)n_rows + 1, sizeof *m->point);
  if (!m->markup || !m->point) return NH_ERR_MEMORY;
  m->n_markups = 1;
  const char *base = strrchr(m->path, '/');
  base = base ? base + 1 : m->path;
  size_t stem = strlen(base);
  if (stem > 5 && strcmp(base + stem - 5, ".fcsv") == 0) stem -= 5;
  m->markup[0] = (nh_markup){.name = nh_strndup(base, stem), .type = NH_MARKUP_FIDUCIAL};
  if (!m->markup[0].name) return NH_ERR_MEMORY;
  char columns_line[1024] = "";
  char *names[NH_FCSV_FIELDS];
  int n_names = NH_FCSV_COLUMNS;
  for (int i = 0; i < NH_FCSV_COLUMNS; i++) names[i] = (char *)nh_fcsv_columns[i];
  int ix = 1, iy = 2, iz = 3, il = 11, line = 0;
  char *next = buf;
  while (next && *next) {
    char *row = next;
    next = strchr(row, '\n');
    if (next) *next++ = '\0';
    line++;
    size_t len = strlen(row);
    if (len > 0 && row[len - 1] == '\r') row[--len] = '\0';
    if (row[0] == '#') {
      char *eq = strchr(row, '=');
      if (!eq) continue;
      *eq = '\0';
      char *key = nh_trim(row + 1), *value = nh_trim(eq + 1);
      if (strcmp(key, "CoordinateSystem") == 0) {
        if (strcmp(value, "RAS") == 0 || strcmp(value, "0") == 0)
          lps = 0;
        else if (strcmp(value, "LPS") == 0 || strcmp(value, "1") == 0)
          lps = 1;
        else
          return NH_ERROR(NH_ERR_INPUT,
                          "%s:%d: CoordinateSystem \"%s\" is not RAS, LPS, 0 (RAS) or 1 (LPS)",
                          m->path, line, value);
      } else if (strcmp(key, "columns") == 0) {
        NH_CHECK(strlen(value) < sizeof columns_line, NH_ERR_INPUT, "%s:%d: columns line too long",
                 m->path, line);
        strcpy(columns_line, value);
        n_names = nh_csv_split(columns_line, names, NH_FCSV_FIELDS);
        for (int i = 0; i < n_names; i++) names[i] = nh_trim(names[i]);
        ix = nh_csv_column(names, n_names, "x"), iy = nh_csv_column(names, n_names, "y");
        iz = nh_csv_column(names, n_names, "z"), il = nh_csv_column(names, n_names, "label");
        NH_CHECK(ix >= 0 && iy >= 0 && iz >= 0, NH_ERR_INPUT,
                 "%s:%d: the columns have no x, y and z", m->path, line);
      }
      continue;
    }
    if (*nh_trim(row) == '\0') continue;
    char *field[NH_FCSV_FIELDS];
    int n = nh_csv_split(row, field, NH_FCSV_FIELDS);
    NH_CHECK(n >= 0, NH_ERR_INPUT, "%s:%d: a quoted field is not closed", m->path, line);
    int need = ix > iy ? ix : iy;
    if (iz > need) need = iz;
    if (il > need) need = il;
    NH_CHECK(n > need, NH_ERR_INPUT, "%s:%d: %d fields, expected %d (columns %s)", m->path, line, n,
             n_names, columns_line[0] ? "of the # columns line" : "id,x,y,z,...,label,...");
    double p[3];
    const int at[3] = {ix, iy, iz};
    for (int k = 0; k < 3; k++) {
      char *end;
      errno = 0;
      p[k] = strtod(field[at[k]], &end);
      NH_CHECK(end != field[at[k]] && *nh_trim(end) == '\0', NH_ERR_INPUT,
               "%s:%d: %s = \"%s\" is not a number", m->path, line, names[at[k]], field[at[k]]);
    }
    nh_markup_point *pt = &m->point[m->n_points];
    const char *label = il >= 0 ? field[il] : "";
    pt->label = nh_strndup(label, strlen(label));
    if (!pt->label) return NH_ERR_MEMORY;
    pt->defined = 1;
    m->n_points++, m->markup[0].n++;
    char where[96];
    snprintf(where, sizeof where, "line %d (\"%.40s\")", line, label);
    NH_TRY(nh_markups_convert(m->path, where, lps, 1e-3, "mm", p, pt->x));
  }
  return NH_OK;
}

int nh_markups_read(const char *path, nh_markups **out) {
  *out = NULL;
  NH_CHECK(strlen(path) < NH_ANATOMY_PATH_MAX, NH_ERR_INPUT, "%s: path too long", path);
  char *buf;
  size_t len;
  NH_TRY(nh_markups_slurp(path, &buf, &len));
  nh_markups *m = nh_calloc(1, sizeof *m);
  if (!m) {
    free(buf);
    return NH_ERR_MEMORY;
  }
  strcpy(m->path, path);
  int rc;
  if (strncmp(buf, nh_fcsv_header, sizeof nh_fcsv_header - 1) == 0) {
    rc = nh_markups_from_fcsv(m, buf);
  } else {
    json_object *root = NULL;
    rc = nh_json_parse(path, buf, len, &root);
    if (rc == NH_ERR_INPUT && len > 0 && buf[0] == '#')
      rc = NH_ERROR(NH_ERR_INPUT,
                    "%s: not a markups file: neither JSON nor a .fcsv (whose first line is \"%s "
                    "= ...\")",
                    path, nh_fcsv_header);
    if (!rc) rc = nh_markups_from_json(m, root);
    json_object_put(root);
  }
  free(buf);
  if (rc) {
    nh_markups_destroy(&m);
    return rc;
  }
  *out = m;
  return NH_OK;
}

/* ---- lookup ---- */

/* "'a', 'b', ... (N in all)" of the distinct labels (or Line names) into buf. */
static void nh_list_names(const nh_markups *m, int lines, char *buf, size_t cap) {
  int shown = 0, total = 0;
  size_t len = 0;
  buf[0] = '\0';
  int n = lines ? m->n_markups : m->n_points;
  for (int i = 0; i < n; i++) {
    const char *s;
    if (lines) {
      if (m->markup[i].type != NH_MARKUP_LINE) continue;
      s = m->markup[i].name;
    } else {
      s = m->point[i].label;
    }
    int seen = 0;
    for (int j = 0; j < i && !seen; j++)
      seen = lines ? m->markup[j].type == NH_MARKUP_LINE && strcmp(m->markup[j].name, s) == 0
                   : strcmp(m->point[j].label, s) == 0;
    if (seen) continue;
    total++;
    if (shown == NH_LIST_MAX || len + 48 > cap) continue;
    len += (size_t)snprintf(buf + len, cap - len, "%s\"%.40s\"", shown ? ", " : "", s);
    shown++;
  }
  if (total > shown) snprintf(buf + len, cap - len, ", ... (%d in all)", total);
  if (total == 0) snprintf(buf, cap, "none");
}

int nh_markups_point(const nh_markups *m, const char *label, double x[3]) {
  int found = -1, count = 0, other = -1;
  for (int i = 0; i < m->n_points; i++) {
    if (strcmp(m->point[i].label, label) != 0) continue;
    if (found >= 0 && m->point[i].markup != m->point[found].markup && other < 0) other = i;
    if (found < 0) found = i;
    count++;
  }
  if (found < 0) {
    char list[512];
    nh_list_names(m, 0, list, sizeof list);
    return NH_ERROR(NH_ERR_INPUT, "%s: no control point labelled \"%s\" (labels: %s)", m->path,
                    label, list);
  }
  const nh_markup *mk = &m->markup[m->point[found].markup];
  if (other >= 0) {
    const nh_markup *mo = &m->markup[m->point[other].markup];
    return NH_ERROR(NH_ERR_INPUT,
                    "%s: the label \"%s\" is in more than one markup (%s \"%s\" and %s \"%s\"): "
                    "rename one in Slicer",
                    m->path, label, nh_markup_type_name(mk->type), mk->name,
                    nh_markup_type_name(mo->type), mo->name);
  }
  NH_CHECK(count == 1, NH_ERR_INPUT,
           "%s: the label \"%s\" names %d control points of the %s \"%s\": labels must be unique",
           m->path, label, count, nh_markup_type_name(mk->type), mk->name);
  NH_CHECK(mk->type == NH_MARKUP_FIDUCIAL || mk->type == NH_MARKUP_LINE, NH_ERR_INPUT,
           "%s: \"%s\" is a control point of the %s \"%s\", not a point: a point is taken from a "
           "Fiducial (point list) or a Line markup",
           m->path, label, nh_markup_type_name(mk->type), mk->name);
  NH_CHECK(m->point[found].defined, NH_ERR_INPUT,
           "%s: the control point \"%s\" has no position (positionStatus not \"defined\")", m->path,
           label);
  memcpy(x, m->point[found].x, 3 * sizeof(double));
  return NH_OK;
}

int nh_markups_line(const nh_markups *m, const char *name, double a[3], double b[3]) {
  int found = -1, count = 0;
  for (int i = 0; i < m->n_markups; i++)
    if (m->markup[i].type == NH_MARKUP_LINE && (!name || strcmp(m->markup[i].name, name) == 0)) {
      if (found < 0) found = i;
      count++;
    }
  if (found < 0 || count > 1) {
    char list[512];
    nh_list_names(m, 1, list, sizeof list);
    if (found < 0)
      return NH_ERROR(NH_ERR_INPUT, "%s: no Line markup%s%s%s (Lines: %s)", m->path,
                      name ? " named \"" : "", name ? name : "", name ? "\"" : "", list);
    return NH_ERROR(NH_ERR_INPUT, "%s: %d Line markups%s%s%s: name one (Lines: %s)", m->path, count,
                    name ? " named \"" : "", name ? name : "", name ? "\"" : "", list);
  }
  const nh_markup *mk = &m->markup[found];
  NH_CHECK(mk->n == 2 && m->point[mk->first].defined && m->point[mk->first + 1].defined,
           NH_ERR_INPUT, "%s: the Line \"%s\" does not have two defined points", m->path, mk->name);
  memcpy(a, m->point[mk->first].x, 3 * sizeof(double));
  memcpy(b, m->point[mk->first + 1].x, 3 * sizeof(double));
  return NH_OK;
}

int nh_markups_find_point(const char *path, const char *label, double x[3]) {
  nh_markups *m;
  NH_TRY(nh_markups_read(path, &m));
  int rc = nh_markups_point(m, label, x);
  nh_markups_destroy(&m);
  return rc;
}
