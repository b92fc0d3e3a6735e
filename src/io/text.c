/* text.c — a growing text buffer for the XML files of the io module (the
 * buffer doubles; one vsnprintf sizes each append), and the copies of
 * strings and paths the writers keep. */
#include "io/io_impl.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

int nh_text_printf(nh_text *b, const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  int n = vsnprintf(NULL, 0, fmt, ap);
  va_end(ap);
  if (n < 0) return NH_ERROR(NH_ERR_INTERNAL, "text formatting failed");
  if (b->len + (size_t)n + 1 > b->cap) {
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->len + (size_t)n + 1) cap *= 2;
    NH_TRY(nh_realloc((void **)&b->s, cap, 1));
    b->cap = cap;
  }
  va_start(ap, fmt);
  vsnprintf(b->s + b->len, (size_t)n + 1, fmt, ap);
  va_end(ap);
  b->len += (size_t)n;
  return NH_OK;
}

int nh_text_put_xml(nh_text *b, const char *s) {
  for (; *s; ++s) {
    switch (*s) {
    case '&':
      NH_TRY(nh_text_printf(b, "&amp;"));
      break;
    case '<':
      NH_TRY(nh_text_printf(b, "&lt;"));
      break;
    case '>':
      NH_TRY(nh_text_printf(b, "&gt;"));
      break;
    case '"':
      NH_TRY(nh_text_printf(b, "&quot;"));
      break;
    default:
      NH_TRY(nh_text_printf(b, "%c", *s));
    }
  }
  return NH_OK;
}

char *nh_text_copy(const char *s) {
  char *c = nh_calloc(strlen(s) + 1, 1);
  if (c) strcpy(c, s);
  return c;
}

char *nh_text_join_path(const char *dir, const char *name) {
  size_t n = strlen(dir) + strlen(name) + 2;
  char *p = nh_calloc(n, 1);
  if (p) snprintf(p, n, "%s/%s", dir, name);
  return p;
}

char *nh_text_aside_name(const char *path, const char *suffix) {
  size_t n = strlen(path) + strlen(suffix) + 32;
  char *p = nh_calloc(n, 1);
  for (int k = 1; p && k < 1000; ++k) {
    if (k == 1)
      snprintf(p, n, "%s.%s", path, suffix);
    else
      snprintf(p, n, "%s.%s.%d", path, suffix, k);
    if (access(p, F_OK) != 0) return p;
  }
  free(p);
  return NULL;
}
