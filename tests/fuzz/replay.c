/* replay.c — runs a fuzz target's LLVMFuzzerTestOneInput over files and
 * folders of inputs without libFuzzer: the seed corpus and the crashes the
 * fuzzer found (tests/fuzz/regressions/TARGET), in every build, so a fixed
 * crash stays fixed. Silent on success; a crash or a broken message promise
 * aborts (fuzz_common.h) naming the input first.
 *
 *   replay_TARGET PATH...   (a folder: every regular file in it, sorted) */
#include <dirent.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "core/core.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static int run_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "replay: cannot open %s\n", path);
    return 1;
  }
  uint8_t *buf = NULL;
  size_t n = 0, cap = 0;
  for (;;) {
    if (n == cap) {
      cap = cap ? 2 * cap : 4096;
      uint8_t *b = realloc(buf, cap);
      if (!b) {
        fclose(f);
        free(buf);
        return 1;
      }
      buf = b;
    }
    size_t got = fread(buf + n, 1, cap - n, f);
    if (!got) break;
    n += got;
  }
  fclose(f);
  if (getenv("NH_VERBOSE")) fprintf(stderr, "replay: %s\n", path);
  LLVMFuzzerTestOneInput(buf, n);
  free(buf);
  return 0;
}

int main(int argc, char **argv) {
  nh_log_set_level(NH_LOG_QUIET);
  int failed = 0, count = 0;
  for (int i = 1; i < argc; ++i) {
    struct stat st;
    if (stat(argv[i], &st) != 0) {
      fprintf(stderr, "replay: no such file or folder %s\n", argv[i]);
      failed = 1;
      continue;
    }
    if (!S_ISDIR(st.st_mode)) {
      failed |= run_file(argv[i]);
      ++count;
      continue;
    }
    struct dirent **list = NULL;
    int n = scandir(argv[i], &list, NULL, alphasort);
    for (int k = 0; k < n; ++k) {
      char path[4096];
      snprintf(path, sizeof path, "%s/%s", argv[i], list[k]->d_name);
      if (stat(path, &st) == 0 && S_ISREG(st.st_mode)) {
        failed |= run_file(path);
        ++count;
      }
      free(list[k]);
    }
    free(list);
  }
  if (count == 0) {
    fprintf(stderr, "replay: no input found\n");
    return 1;
  }
  return failed;
}
