/* fuzz_scene.c — fuzz target: the scene reader (nh_scene_load) on any bytes.
 * Every input must either load (and be freed) or fail with a message that
 * keeps fuzz_common.h's promise; sanitizers catch the rest. Built with
 * libFuzzer by tools/fuzz.sh, replayed over its corpus by tests/fuzz/replay.c. */
#include "fuzz_common.h"
#include "scene/scene.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  const char *path = nh_fuzz_file(data, size, ".yaml");
  nh_scene *scene = NULL;
  int rc = nh_scene_load(path, 0, NULL, &scene);
  nh_fuzz_check_message(rc, path);
  nh_scene_destroy(&scene);
  nh_error_clear();
  return 0;
}
