/* markups.c — 3D Slicer markups files written for the user (docs/anatomy.md,
 * "Markups"): a tool's final axis as a Curve, the shifted targets as
 * Fiducials, next to the VTU frames.
 *
 * The reader is anatomy/markups.c (the scene reads points through it, and
 * scene sits below io); the writer is here because every output file is
 * io's: written atomically through io/file.c, on plain arrays. Both use
 * json-c, the writer to build the document and escape the labels.
 *
 * The document is what Slicer itself writes (schema markups-schema-v1.0.3,
 * the version Slicer 5 writes and reads): "@schema", and one entry of
 * "markups" with "type", "name", "coordinateSystem" (RAS: the scene's frame,
 * so the numbers are the scene's points in mm), "coordinateUnits" "mm",
 * "locked", "labelFormat", "lastUsedControlPointNumber" and the
 * "controlPoints", each with "id", "label", "description",
 * "associatedNodeID", "position", "orientation" (identity),
 * "selected", "locked", "visibility" and "positionStatus" "defined"; and a
 * "display" block (colour, labels shown for targets). Numbers are printed
 * with 12 significant digits (sub-nanometre in mm), always with a decimal
 * point or an exponent, as Slicer writes them. */
#include "io/io.h"

#include <json.h>
#include <stdio.h>
#include <string.h>

#define NH_MARKUPS_SCHEMA                                                                          \
  "https://raw.githubusercontent.com/slicer/slicer/main/Modules/Loadable/Markups/Resources/"       \
  "Schema/markups-schema-v1.0.3.json#"

/* Add val under key (val NULL or a failed add sets *fail; val is released). */
static void nh_jadd(json_object *obj, const char *key, json_object *val, int *fail) {
  if (!val || json_object_object_add(obj, key, val) != 0) {
    json_object_put(val);
    *fail = 1;
  }
}

static void nh_jpush(json_object *arr, json_object *val, int *fail) {
  if (!val || json_object_array_add(arr, val) != 0) {
    json_object_put(val);
    *fail = 1;
  }
}

static json_object *nh_jnum(double v) {
  char s[40];
  int n = snprintf(s, sizeof s, "%.12g", v);
  if (!strpbrk(s, ".eEn")) snprintf(s + n, sizeof s - (size_t)n, ".0"); /* a double, as Slicer */
  return json_object_new_double_s(v, s);
}

static json_object *nh_jvec(const double *v, int n, int *fail) {
  json_object *a = json_object_new_array();
  if (!a) *fail = 1;
  for (int i = 0; a && i < n; i++) nh_jpush(a, nh_jnum(v[i]), fail);
  return a;
}

static json_object *nh_jpoint(const char *name, int i, const double x[3], const char *label,
                              int *fail) {
  static const double identity[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  json_object *p = json_object_new_object();
  if (!p) {
    *fail = 1;
    return NULL;
  }
  char id[16], def[96];
  snprintf(id, sizeof id, "%d", i + 1);
  snprintf(def, sizeof def, "%.64s-%d", name, i + 1);
  double mm[3] = {1e3 * x[0], 1e3 * x[1], 1e3 * x[2]};
  nh_jadd(p, "id", json_object_new_string(id), fail);
  nh_jadd(p, "label", json_object_new_string(label ? label : def), fail);
  nh_jadd(p, "description", json_object_new_string(""), fail);
  nh_jadd(p, "associatedNodeID", json_object_new_string(""), fail);
  nh_jadd(p, "position", nh_jvec(mm, 3, fail), fail);
  nh_jadd(p, "orientation", nh_jvec(identity, 9, fail), fail);
  nh_jadd(p, "selected", json_object_new_boolean(1), fail);
  nh_jadd(p, "locked", json_object_new_boolean(1), fail);
  nh_jadd(p, "visibility", json_object_new_boolean(1), fail);
  nh_jadd(p, "positionStatus", json_object_new_string("defined"), fail);
  return p;
}

static json_object *nh_jdisplay(nh_markup_type type, int *fail) {
  /* a tool's axis in yellow, targets in Slicer's default red */
  static const double yellow[3] = {1.0, 0.85, 0.0}, red[3] = {1.0, 0.5, 0.5};
  const double *colour = type == NH_MARKUP_FIDUCIAL ? red : yellow;
  json_object *d = json_object_new_object();
  if (!d) {
    *fail = 1;
    return NULL;
  }
  nh_jadd(d, "visibility", json_object_new_boolean(1), fail);
  nh_jadd(d, "opacity", nh_jnum(1.0), fail);
  nh_jadd(d, "color", nh_jvec(colour, 3, fail), fail);
  nh_jadd(d, "selectedColor", nh_jvec(colour, 3, fail), fail);
  nh_jadd(d, "pointLabelsVisibility", json_object_new_boolean(type == NH_MARKUP_FIDUCIAL), fail);
  nh_jadd(d, "glyphType", json_object_new_string("Sphere3D"), fail);
  nh_jadd(d, "glyphSize", nh_jnum(type == NH_MARKUP_FIDUCIAL ? 3.0 : 1.0), fail);
  nh_jadd(d, "useGlyphScale", json_object_new_boolean(0), fail);
  return d;
}

int nh_markups_write(const char *path, nh_markup_type type, const char *name, int n,
                     const double *points, const char *const *labels) {
  int fail = 0;
  json_object *root = json_object_new_object(), *mk = json_object_new_object(),
              *list = json_object_new_array(), *cps = json_object_new_array();
  if (!root || !mk || !list || !cps) {
    json_object_put(root), json_object_put(mk), json_object_put(list), json_object_put(cps);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: markups %s", path);
  }
  nh_jadd(root, "@schema", json_object_new_string(NH_MARKUPS_SCHEMA), &fail);
  nh_jadd(mk, "type", json_object_new_string(nh_markup_type_name(type)), &fail);
  nh_jadd(mk, "name", json_object_new_string(name), &fail);
  nh_jadd(mk, "coordinateSystem", json_object_new_string("RAS"), &fail);
  nh_jadd(mk, "coordinateUnits", json_object_new_string("mm"), &fail);
  nh_jadd(mk, "locked", json_object_new_boolean(1), &fail);
  nh_jadd(mk, "fixedNumberOfControlPoints", json_object_new_boolean(0), &fail);
  nh_jadd(mk, "labelFormat", json_object_new_string("%N-%d"), &fail);
  nh_jadd(mk, "lastUsedControlPointNumber", json_object_new_int(n), &fail);
  for (int i = 0; i < n; i++)
    nh_jpush(cps, nh_jpoint(name, i, points + 3 * i, labels ? labels[i] : NULL, &fail), &fail);
  nh_jadd(mk, "controlPoints", cps, &fail);
  nh_jadd(mk, "measurements", json_object_new_array(), &fail);
  nh_jadd(mk, "display", nh_jdisplay(type, &fail), &fail);
  nh_jpush(list, mk, &fail);
  nh_jadd(root, "markups", list, &fail);
  const char *text =
      fail
          ? NULL
          : json_object_to_json_string_ext(root, JSON_C_TO_STRING_PRETTY | JSON_C_TO_STRING_SPACED |
                                                     JSON_C_TO_STRING_NOSLASHESCAPE);
  int rc;
  if (!text) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: markups %s", path);
  } else {
    nh_atomic_file a;
    rc = nh_atomic_open(path, "markups file", 0, &a);
    if (!rc) {
      size_t len = strlen(text);
      int failed = fwrite(text, 1, len, a.file) != len || fputc('\n', a.file) == EOF;
      rc = nh_atomic_commit(&a, failed);
    }
  }
  json_object_put(root);
  return rc;
}
