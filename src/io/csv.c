/* csv.c — append-only CSV tables.
 *
 * CSV tables (steps.csv, probes.csv, ...) grow by one row per step, so they
 * are the one kind of output that is not written through tmp + rename: the
 * file is created (truncated) with its header and every row is appended with
 * write(2) at once, so a run that is killed or fails keeps every row it
 * completed. Each row is formatted into memory first and written in one
 * call; if the disk fills in the middle of it, the file is cut back
 * (ftruncate) to its last complete line, so a failed run never leaves half
 * a row.
 *
 * Format: RFC 4180 style, comma separated, '\n' line ends, a header line of
 * column names (quoted only if a name contains a comma, quote or newline).
 * Rows are formatted by the caller (printf style), who owns the quoting of
 * its fields; numbers meant to be read back exactly should use %.17g. A
 * trailing newline in the caller's format is dropped, so a row is always
 * exactly one line.
 *
 * nh_csv_resume re-creates a table from the rows of an interrupted run's
 * file up to a step (the checkpoint's), so that a continued run's table is
 * the uninterrupted one's; a file written with other columns (another
 * version) has its rows mapped by column name and is kept as PATH.old. All failures return
 * NH_ERR_IO with a message naming the path and strerror(errno). */
#include "io/io_impl.h"

#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <fcntl.h>
#include <sys/types.h>
#include <unistd.h>

struct nh_csv {
  int fd;
  off_t size; /* bytes of complete lines on disk */
  char *path;
};

/* Append `len` bytes; on failure cut the file back to its complete lines,
 * so a full disk never leaves half a row. 0 or errno. */
static int csv_append(nh_csv *csv, const char *data, size_t len) {
  size_t done = 0;
  while (done < len) {
    ssize_t n = write(csv->fd, data + done, len - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      int e = n < 0 ? errno : ENOSPC;
      if (ftruncate(csv->fd, csv->size) == 0) lseek(csv->fd, csv->size, SEEK_SET);
      return e;
    }
    done += (size_t)n;
  }
  csv->size += (off_t)len;
  return 0;
}

static char *copy_string(const char *s) {
  char *c = nh_calloc(strlen(s) + 1, 1);
  if (c) strcpy(c, s);
  return c;
}

static int put_csv_field(nh_text *b, const char *s) {
  if (!strpbrk(s, ",\"\r\n")) return nh_text_printf(b, "%s", s);
  NH_TRY(nh_text_printf(b, "\""));
  for (; *s; ++s) NH_TRY(nh_text_printf(b, *s == '"' ? "\"\"" : "%c", *s));
  return nh_text_printf(b, "\"");
}

int nh_csv_create(const char *path, int n_columns, const char *const *columns, nh_csv **out) {
  NH_CHECK(path && out && n_columns >= 1 && columns, NH_ERR_INTERNAL,
           "nh_csv_create: bad arguments");
  *out = NULL;
  nh_csv *csv = nh_calloc(1, sizeof *csv);
  if (!csv) return NH_ERR_MEMORY;
  csv->fd = -1;
  csv->path = copy_string(path);
  if (!csv->path) {
    free(csv);
    return NH_ERR_MEMORY;
  }
  csv->fd = open(path, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
  if (csv->fd < 0) {
    int rc = NH_ERROR(NH_ERR_IO, "cannot create CSV file '%s': %s", path, strerror(errno));
    nh_csv_destroy(&csv);
    return rc;
  }
  nh_text header = {0};
  int rc = NH_OK;
  for (int i = 0; i < n_columns && !rc; ++i) {
    if (i) rc = nh_text_printf(&header, ",");
    if (!rc) rc = put_csv_field(&header, columns[i] ? columns[i] : "");
  }
  if (!rc) rc = nh_text_printf(&header, "\n");
  int e = rc ? 0 : csv_append(csv, header.s, header.len);
  free(header.s);
  if (rc || e) {
    if (e) rc = NH_ERROR(NH_ERR_IO, "cannot write CSV file '%s': %s", path, strerror(e));
    nh_csv_destroy(&csv);
    return rc;
  }
  *out = csv;
  return NH_OK;
}

int nh_csv_row(nh_csv *csv, const char *fmt, ...) {
  NH_CHECK(csv && csv->fd >= 0 && fmt, NH_ERR_INTERNAL, "nh_csv_row: bad arguments");
  char small[1024];
  char *line = small;
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(small, sizeof small, fmt, ap);
  va_end(ap);
  NH_CHECK(n >= 0, NH_ERR_INTERNAL, "CSV '%s': formatting a row failed", csv->path);
  if ((size_t)n + 2 > sizeof small) {
    line = nh_calloc((size_t)n + 2, 1);
    if (!line) return NH_ERROR(NH_ERR_MEMORY, "out of memory writing CSV '%s'", csv->path);
    va_start(ap, fmt);
    vsnprintf(line, (size_t)n + 1, fmt, ap);
    va_end(ap);
  }
  size_t len = (size_t)n;
  while (len > 0 && (line[len - 1] == '\n' || line[len - 1] == '\r')) --len;
  line[len++] = '\n';
  int e = csv_append(csv, line, len);
  if (line != small) free(line);
  if (e) return NH_ERROR(NH_ERR_IO, "cannot write CSV file '%s': %s", csv->path, strerror(e));
  return NH_OK;
}

void nh_csv_destroy(nh_csv **csv) {
  if (!csv || !*csv) return;
  nh_csv *c = *csv;
  /* Every row was written already; a close error here has nothing left to lose. */
  if (c->fd >= 0) close(c->fd);
  free(c->path);
  free(c);
  *csv = NULL;
}

int nh_csv_values(nh_csv *csv, int n, const double *values) {
  char line[64 * 64];
  NH_CHECK(n > 0 && n <= 64, NH_ERR_INTERNAL, "nh_csv_values: %d columns", n);
  size_t len = 0;
  for (int i = 0; i < n; i++)
    len += (size_t)snprintf(line + len, sizeof line - len, i ? ",%.17g" : "%.17g", values[i]);
  return nh_csv_row(csv, "%s", line);
}

enum { CSV_MAX_COLUMNS = 256 };

int nh_csv_resume(const char *path, int n_columns, const char *const *columns, int step,
                  nh_csv **out) {
  NH_CHECK(path && out && n_columns >= 1 && n_columns <= CSV_MAX_COLUMNS && columns,
           NH_ERR_INTERNAL, "nh_csv_resume: bad arguments");
  FILE *f = fopen(path, "r");
  char *text = NULL;
  size_t len = 0;
  if (f) {
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    rewind(f);
    text = nh_calloc((size_t)(size > 0 ? size : 0) + 1, 1);
    if (!text) {
      fclose(f);
      return NH_ERROR(NH_ERR_MEMORY, "out of memory resuming %s", path);
    }
    len = fread(text, 1, (size_t)(size > 0 ? size : 0), f);
    text[len] = '\0';
    fclose(f);
  }
  /* The old header: if it names other columns (a table written by another
   * version of needlehex), the old rows are mapped by column name (a column
   * the old file lacks is left empty) and the old file is kept as PATH.old,
   * so that a column this version no longer writes is not lost. */
  char *line = text ? strchr(text, '\n') : NULL;
  int map[CSV_MAX_COLUMNS], same = 1, n_old = 0;
  char *old_names[CSV_MAX_COLUMNS];
  if (line) {
    *line = '\0';
    if (line > text && line[-1] == '\r') line[-1] = '\0';
    n_old = nh_csv_split(text, old_names, CSV_MAX_COLUMNS);
    if (n_old < 0) n_old = 0; /* not a header: nothing matches, the old file is kept */
    same = n_old == n_columns;
    for (int j = 0; j < n_columns; ++j) {
      map[j] = -1;
      for (int i = 0; i < n_old && map[j] < 0; ++i)
        if (strcmp(old_names[i], columns[j] ? columns[j] : "") == 0) map[j] = i;
      same = same && map[j] == j;
    }
  }
  if (!same) {
    char *aside = nh_text_aside_name(path, "old");
    if (!aside || rename(path, aside) != 0) {
      int rc = NH_ERROR(NH_ERR_IO,
                        "cannot resume '%s' (written with other columns) nor move it "
                        "aside to '%s.old': %s",
                        path, path, aside ? strerror(errno) : "no free name");
      free(aside);
      free(text);
      return rc;
    }
    nh_log_warn("'%s' was written with other columns (another version of needlehex): its rows "
                "up to step %d are kept under this version's columns, matched by name, and the "
                "old file is '%s'",
                path, step, aside);
    free(aside);
  }
  int rc = nh_csv_create(path, n_columns, columns, out);
  while (!rc && line && line[1]) {
    char *start = line + 1, *end = strchr(start, '\n');
    if (end) *end = '\0';
    if (atoi(start) <= step && start[0] >= '0' && start[0] <= '9') {
      if (same) {
        rc = nh_csv_row(*out, "%s", start);
      } else {
        /* a row that does not split (a broken quote) is only in the .old file */
        char *fields[CSV_MAX_COLUMNS];
        int nf = nh_csv_split(start, fields, CSV_MAX_COLUMNS);
        nh_text row = {0};
        for (int j = 0; j < n_columns && !rc; ++j) {
          if (j) rc = nh_text_printf(&row, ",");
          if (!rc && map[j] >= 0 && map[j] < nf) rc = put_csv_field(&row, fields[map[j]]);
        }
        if (!rc && nf > 0) rc = nh_csv_row(*out, "%s", row.s ? row.s : "");
        free(row.s);
      }
    }
    line = end;
  }
  free(text);
  return rc;
}
