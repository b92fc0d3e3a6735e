/* file.c — files as wholes: mkdir -p, and atomic files (write to a
 * temporary, optionally fsync, rename into place).
 *
 * Every output except the append-only CSV tables is written through
 * nh_atomic_open / nh_atomic_commit: the bytes go to "<path>.tmp", which is
 * flushed, closed (errors of the final flush included: a full disk shows
 * there) and renamed over <path>. rename() within one folder is atomic, so a
 * reader, or a run killed at any instant, sees either the previous file or
 * the new one, never a half-written one. On any failure the temporary is
 * removed and NH_ERR_IO names the path and strerror(errno).
 * fsync is asked for per file (`sync`): the checkpoint uses it, because a
 * restart needs the file's contents to survive a crash of the machine, not
 * only of the run; frames and collections do not, as they are rewritten or
 * superseded at the next step and an fsync per frame would cost a disk
 * round trip each.
 *
 * nh_mkdir_p creates every missing component of a path (mode 0777 minus the
 * umask) and accepts components that already exist as directories. */
#include "io/io_impl.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <unistd.h>

int nh_atomic_open(const char *path, const char *what, int sync, nh_atomic_file *a) {
  NH_CHECK(path && what && a, NH_ERR_INTERNAL, "nh_atomic_open: NULL argument");
  *a = (nh_atomic_file){.what = what, .sync = sync};
  size_t tmp_len = strlen(path) + 5;
  a->path = nh_text_copy(path);
  a->tmp = nh_calloc(tmp_len, 1);
  if (!a->path || !a->tmp) {
    free(a->path), free(a->tmp);
    *a = (nh_atomic_file){0};
    return NH_ERR_MEMORY;
  }
  snprintf(a->tmp, tmp_len, "%s.tmp", path);
  a->file = fopen(a->tmp, "wb");
  if (!a->file) {
    int rc = NH_ERROR(NH_ERR_IO, "cannot write %s '%s': %s", what, path, strerror(errno));
    free(a->path), free(a->tmp);
    *a = (nh_atomic_file){0};
    return rc;
  }
  return NH_OK;
}

int nh_atomic_commit(nh_atomic_file *a, int failed) {
  if (!a->file) return NH_OK;
  failed = failed || ferror(a->file);
  int saved_errno = failed ? errno : 0;
  if (!failed && a->sync && (fflush(a->file) != 0 || fsync(fileno(a->file)) != 0)) {
    failed = 1;
    saved_errno = errno;
  }
  if (fclose(a->file) != 0 && !failed) {
    failed = 1;
    saved_errno = errno;
  }
  if (!failed && rename(a->tmp, a->path) != 0) {
    failed = 1;
    saved_errno = errno;
  }
  int rc = NH_OK;
  if (failed) {
    remove(a->tmp);
    rc = NH_ERROR(NH_ERR_IO, "cannot write %s '%s': %s", a->what, a->path,
                  saved_errno ? strerror(saved_errno) : "write error");
  }
  free(a->path), free(a->tmp);
  *a = (nh_atomic_file){0};
  return rc;
}

int nh_write_text(const char *path, const char *text) {
  NH_CHECK(path && text, NH_ERR_INTERNAL, "nh_write_text: NULL argument");
  nh_atomic_file a;
  NH_TRY(nh_atomic_open(path, "file", 0, &a));
  size_t len = strlen(text);
  return nh_atomic_commit(&a, fwrite(text, 1, len, a.file) != len);
}

static int is_directory(const char *path) {
  struct stat st;
  return stat(path, &st) == 0 && S_ISDIR(st.st_mode);
}

int nh_mkdir_p(const char *path) {
  NH_CHECK(path, NH_ERR_INTERNAL, "nh_mkdir_p: NULL path");
  NH_CHECK(path[0] != '\0', NH_ERR_IO, "cannot create directory '': empty path");
  char *p = nh_text_copy(path);
  if (!p) return NH_ERR_MEMORY;
  int rc = NH_OK;
  /* Create each prefix that ends at a '/' (skipping a leading one), then the whole path. */
  for (char *s = p + 1;; ++s) {
    if (*s != '/' && *s != '\0') continue;
    char saved = *s;
    *s = '\0';
    if (mkdir(p, 0777) != 0 && !(errno == EEXIST && is_directory(p))) {
      int e = errno;
      if (e == EEXIST) e = ENOTDIR;
      rc = NH_ERROR(NH_ERR_IO, "cannot create directory '%s' (at '%s'): %s", path, p, strerror(e));
      break;
    }
    *s = saved;
    if (saved == '\0') break;
    while (s[1] == '/') ++s; /* "a//b" */
    if (s[1] == '\0') break; /* trailing slash */
  }
  free(p);
  return rc;
}
