/* fuzz_markups.c — fuzz target: the 3D Slicer markups reader
 * (nh_markups_read: .mrk.json and .fcsv) on any bytes. Every input must
 * either read (then the lookups a scene makes are asked: the first point's
 * label, a label no file has, the only Line, the first markup's name as a
 * Line) or fail with "PATH: ..." or "PATH:LINE[:COLUMN]: ..." on one
 * printable line (fuzz_common.h); so must every lookup. See fuzz_scene.c. */
#include "anatomy/anatomy.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = nh_fuzz_file(data, size, ".mrk.json");
  nh_markups *m = NULL;
  int rc = nh_markups_read(path, &m);
  nh_fuzz_check_prefix(rc, path, 0);
  if (!rc) {
    double x[3], a[3], b[3];
    if (m->n_points > 0) nh_fuzz_check_prefix(nh_markups_point(m, m->point[0].label, x), path, 0);
    nh_fuzz_check_prefix(nh_markups_point(m, "no such label", x), path, 0);
    nh_fuzz_check_prefix(nh_markups_line(m, NULL, a, b), path, 0);
    if (m->n_markups > 0)
      nh_fuzz_check_prefix(nh_markups_line(m, m->markup[0].name, a, b), path, 0);
  }
  nh_markups_destroy(&m);
  nh_error_clear();
  return 0;
}
