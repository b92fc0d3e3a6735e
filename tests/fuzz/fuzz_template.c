/* fuzz_template.c — fuzz target: the refinement-template loader
 * (nh_template_load) on any bytes; see fuzz_scene.c. */
#include "fuzz_common.h"
#include "mesh/mesh.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = nh_fuzz_file(data, size, ".tmpl");
  nh_template *tmpl = NULL;
  int rc = nh_template_load(path, &tmpl);
  nh_fuzz_check_message(rc, path);
  nh_template_destroy(&tmpl);
  nh_error_clear();
  return 0;
}
