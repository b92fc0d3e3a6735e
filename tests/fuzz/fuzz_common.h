/* fuzz_common.h — what the fuzz targets share: the input written to a
 * scratch file (the readers take paths), and the promise every input-error
 * message keeps (one line, "FILE:LINE: ..." or for the binary formats
 * "FILE: ...", no raw control byte).
 *
 * A broken promise calls abort(), which libFuzzer records as a crash (and
 * tests/fuzz/replay.c as a failure), so the fuzzer checks the messages too. */
#ifndef NH_FUZZ_COMMON_H
#define NH_FUZZ_COMMON_H

#include "core/core.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Write the input to a scratch file of this process and return its path. */
static const char *nh_fuzz_file(const uint8_t *data, size_t size, const char *suffix) {
  static char path[128];
  const char *dir = getenv("TMPDIR") ? getenv("TMPDIR") : "/tmp";
  snprintf(path, sizeof path, "%.64s/nh-fuzz-%ld%s", dir, (long)getpid(), suffix);
  FILE *f = fopen(path, "wb");
  if (!f || (size && fwrite(data, 1, size, f) != size) || fclose(f) != 0) {
    fprintf(stderr, "fuzz: cannot write the scratch file %s\n", path);
    abort();
  }
  return path;
}

/* An input error's message starts with `prefix` followed by ':' and, if
 * `line`, a line number ("PATH:LINE: ..."), else a line number or a space
 * ("PATH: ..." from the binary readers); one line, printable. */
static void nh_fuzz_check_prefix(int rc, const char *prefix, int line) {
  const char *m = nh_error_message();
  if (rc != NH_ERR_INPUT) return;
  size_t n = strlen(prefix);
  const char *p = m + n;
  int digit = p[1] >= '0' && p[1] <= '9';
  int ok = strncmp(m, prefix, n) == 0 && p[0] == ':' && (digit || (!line && p[1] == ' '));
  for (const unsigned char *c = (const unsigned char *)m; ok && *c; ++c)
    if (*c < 0x20 || *c == 0x7f) ok = 0;
  if (!ok) {
    fprintf(stderr,
            "fuzz: an input error's message is not \"%s:%s ...\" on one printable "
            "line:\n%s\n",
            prefix, line ? "LINE:" : "[LINE:]", m);
    abort();
  }
}

/* An input error's message: "PATH:LINE: ..." on one line, printable. */
static inline void nh_fuzz_check_message(int rc, const char *path) {
  nh_fuzz_check_prefix(rc, path, 1);
}

#endif
