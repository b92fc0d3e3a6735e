/* paths.c — where the program's data files are, relative to the program.
 *
 * An installed needlehex is PREFIX/bin/needlehex with its refinement
 * templates in PREFIX/share/needlehex/templates; the build tree copies the
 * templates to BUILD/share/needlehex/templates next to BUILD/needlehex (and
 * BUILD/tests/test_*). So the templates are looked up, in order:
 *   1. $NH_TEMPLATES_DIR when set and not empty (as given, even if missing:
 *      the user asked for it, and the error names it);
 *   2. EXE/../share/needlehex/templates, 3. EXE/share/needlehex/templates,
 *      the first that is a folder, EXE the folder of /proc/self/exe;
 *   4. "templates" (relative to the working directory) when neither is.
 * No absolute path is compiled in, so a build or an install can be moved. */
#include "core/core.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int nh_exe_dir(char *out, size_t size) {
  if (size == 0) return -1;
  ssize_t n = readlink("/proc/self/exe", out, size - 1);
  if (n <= 0 || (size_t)n >= size - 1) return -1;
  out[n] = '\0';
  char *slash = strrchr(out, '/');
  if (!slash) return -1;
  *slash = '\0';
  return 0;
}

static int is_dir(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

const char *nh_templates_dir(char *buf, size_t size) {
  const char *env = getenv("NH_TEMPLATES_DIR");
  if (env && env[0]) return env;
  char exe[4096];
  static const char *const below[] = {"/../share/needlehex/templates",
                                      "/share/needlehex/templates"};
  if (nh_exe_dir(exe, sizeof exe) == 0)
    for (int i = 0; i < 2; i++) {
      int n = snprintf(buf, size, "%s%s", exe, below[i]);
      if (n > 0 && (size_t)n < size && is_dir(buf)) return buf;
    }
  return "templates";
}

const char *nh_path_absolute(const char *path, char *out, size_t size) {
  if (path[0] == '/' || !getcwd(out, size)) return path;
  size_t n = strlen(out);
  if (n + 1 + strlen(path) + 1 > size) return path;
  snprintf(out + n, size - n, "/%s", path);
  return out;
}
