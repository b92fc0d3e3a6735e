/* fuzz_stl.c — fuzz target: the STL surface reader (nh_surface_read) on any
 * bytes (in millimetres). Every input must either read (then the inside
 * test, the truncated distance and a ray entry are evaluated at the box's
 * centre) or fail with "PATH: ..." or "PATH:LINE: ..." (fuzz_common.h).
 * Limits are small (1e5 triangles, 1e7 bytes). See fuzz_scene.c. */
#include "anatomy/anatomy.h"
#include "fuzz_common.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = nh_fuzz_file(data, size, ".stl");
  const nh_read_limits limits = {.max_voxels = 1e5, .max_triangles = 1e5, .max_file_bytes = 1e7};
  nh_surface *s = NULL;
  int rc = nh_surface_read(path, 1e-3, 0, &limits, &s);
  nh_fuzz_check_prefix(rc, path, 0);
  if (!rc) {
    double c[3], dir[3] = {0.6, 0.64, 0.48}, tau, point[3], normal[3];
    for (int k = 0; k < 3; k++) c[k] = 0.5 * (s->min[k] + s->max[k]);
    (void)nh_surface_inside(s, c);
    (void)nh_surface_level(s, c, 0.1 * (s->max[0] - s->min[0]));
    (void)nh_surface_ray_entry(s, c, dir, &tau, point, normal);
  }
  nh_surface_release(&s);
  nh_error_clear();
  return 0;
}
