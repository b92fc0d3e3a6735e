/* csv_fields.c — the fields of one line of a comma-separated table
 * (RFC 4180 style, as io/csv.c writes them and 3D Slicer's .fcsv holds
 * them): one home for every reader of such lines. */
#include "core/core.h"

#include <string.h>

int nh_csv_split(char *line, char **field, int max) {
  size_t len = strlen(line);
  while (len > 0 && (line[len - 1] == '\n' || line[len - 1] == '\r')) line[--len] = '\0';
  int n = 0;
  char *p = line;
  for (;;) {
    if (n == max) return n;
    if (*p == '"') {
      char *w = ++p;
      field[n++] = w;
      for (;;) {
        if (*p == '\0') return -1;
        if (*p == '"' && p[1] == '"')
          *w++ = '"', p += 2;
        else if (*p == '"')
          break;
        else
          *w++ = *p++;
      }
      *w = '\0';
      p++;
      if (*p != ',' && *p != '\0') return -1;
    } else {
      field[n++] = p;
      while (*p && *p != ',') p++;
    }
    if (*p == '\0') return n;
    *p++ = '\0';
  }
}

int nh_csv_column(char *const *names, int n, const char *name) {
  for (int i = 0; i < n; i++)
    if (strcmp(names[i], name) == 0) return i;
  return -1;
}
