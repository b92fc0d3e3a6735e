/* fuzz_checkpoint.c — fuzz target: the checkpoint reader
 * (nh_checkpoint_read, behind `needlehex run --restart`) on any payload.
 * The input is the payload after the scene hash: this target writes the
 * header (magic, the format the reader takes (8), byte order, size) and
 * the hash of its own small scene around it and computes the checksum, so
 * the fuzzer explores what a checksum-valid file of a buggy writer could
 * hold (a random file stops at the checksum). Every input must either
 * read (and be freed) or fail with "--restart: PATH: ..."
 * (fuzz_common.h). See fuzz_scene.c. */
#include "fuzz_common.h"
#include "scene/scene.h"
#include "sim/sim_impl.h"

#include <sys/stat.h>

/* The scene of tests/bad/files/make_bad_files.py's checkpoints (box domain). */
static const char nh_fuzz_scene[] = "name: ck\n"
                                    "time: {mode: dynamic, step: 0.01, steps: 4}\n"
                                    "tissue:\n"
                                    "  domain:\n"
                                    "    box: {min: [0, 0, 0], max: [0.02, 0.01, 0.01]}\n"
                                    "  grid: [2, 1, 1]\n"
                                    "  material: {young: 1.0e6, poisson: 0.3, density: 1000}\n";

static uint64_t nh_fuzz_fnv1a(const void *data, size_t n, uint64_t h) {
  const unsigned char *p = data;
  for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ull;
  return h;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size) {
  static nh_scene *scene;
  static char dir[128];
  const uint64_t seed = 14695981039346656037ull;
  if (!scene) {
    const char *yaml =
        nh_fuzz_file((const uint8_t *)nh_fuzz_scene, sizeof nh_fuzz_scene - 1, ".yaml");
    if (nh_scene_load(yaml, 0, NULL, &scene)) {
      fprintf(stderr, "fuzz: the target's scene does not load: %s\n", nh_error_message());
      abort();
    }
    if (snprintf(dir, sizeof dir, "%s.d", yaml) >= (int)sizeof dir) abort();
    mkdir(dir, 0700);
  }
  uint64_t hash = nh_fuzz_fnv1a(scene->yaml, strlen(scene->yaml), seed);
  uint64_t payload = 8 + (uint64_t)size;
  uint64_t sum = nh_fuzz_fnv1a(data, size, nh_fuzz_fnv1a(&hash, 8, seed));
  uint32_t version = 8, order = 0x01020304;
  char path[256];
  snprintf(path, sizeof path, "%s/checkpoint.nhc", dir);
  FILE *f = fopen(path, "wb");
  if (!f || fwrite("NHCKPT\0\1", 8, 1, f) != 1 || fwrite(&version, 4, 1, f) != 1 ||
      fwrite(&order, 4, 1, f) != 1 || fwrite(&payload, 8, 1, f) != 1 ||
      fwrite(&sum, 8, 1, f) != 1 || fwrite(&hash, 8, 1, f) != 1 ||
      (size && fwrite(data, 1, size, f) != size) || fclose(f) != 0) {
    fprintf(stderr, "fuzz: cannot write %s\n", path);
    abort();
  }
  nh_checkpoint ck;
  int rc = nh_checkpoint_read(dir, scene, &ck);
  char prefix[300];
  snprintf(prefix, sizeof prefix, "--restart: %s", path);
  nh_fuzz_check_prefix(rc, prefix, 0);
  if (!rc) {
    nh_mesh_destroy(&ck.mesh);
    free(ck.u), free(ck.v), free(ck.tools), free(ck.solver), free(ck.adapt);
  }
  nh_error_clear();
  return 0;
}
