/* error.c — the last error message, allocation helpers and exit statuses.
 *
 * One message slot per thread: the failing site fills it, NH_TRY carries the
 * code up, and the front end prints it once. A later error replaces an
 * earlier one, so the message a user sees is the one closest to the cause
 * that was recorded last — callers that add context record a new message.
 * A message is one line of printable text whatever the input echoed into it:
 * control bytes (a scene's or template's raw bytes, a newline) are written
 * as \n, \t, \r or \xNN. */
#include "core/core.h"

#include <limits.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static _Thread_local char nh_message[2048];

void nh_escape_control(char *out, size_t size, const char *text) {
  static const char hex[] = "0123456789abcdef";
  size_t n = 0;
  for (const unsigned char *c = (const unsigned char *)text; *c && n + 1 < size; ++c) {
    if (*c >= 0x20 && *c != 0x7f) {
      out[n++] = (char)*c;
      continue;
    }
    if (n + 4 >= size) break; /* no half escape */
    out[n++] = '\\';
    if (*c == '\n' || *c == '\t' || *c == '\r') {
      out[n++] = *c == '\n' ? 'n' : *c == '\t' ? 't' : 'r';
    } else {
      out[n++] = 'x';
      out[n++] = hex[*c >> 4];
      out[n++] = hex[*c & 15];
    }
  }
  if (size) out[n < size ? n : size - 1] = '\0';
}

int nh_error_set(int code, const char *src_file, int src_line, const char *fmt, ...) {
  char raw[sizeof nh_message];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(raw, sizeof raw, fmt, ap);
  va_end(ap);
  nh_escape_control(nh_message, sizeof nh_message, raw);
  const char *dbg = getenv("NH_DEBUG_ERRORS");
  if (dbg && dbg[0] == '1') fprintf(stderr, "[%s:%d] %s\n", src_file, src_line, nh_message);
  return code;
}

const char *nh_error_message(void) {
  return nh_message;
}

void nh_error_clear(void) {
  nh_message[0] = '\0';
}

static volatile sig_atomic_t nh_stop_signal = 0;

void nh_stop_request(int signal_number) {
  nh_stop_signal = signal_number ? signal_number : SIGTERM;
}

int nh_stop_requested(void) {
  return (int)nh_stop_signal;
}

int nh_stop_check(void) {
  if (!nh_stop_signal) return NH_OK;
  return NH_ERROR(NH_ERR_INTERRUPTED, "interrupted by signal %d", (int)nh_stop_signal);
}

int nh_error_exit_status(int code) {
  if (code == NH_OK) return 0;
  return code == NH_ERR_INPUT ? 2 : 1;
}

void *nh_calloc(size_t n, size_t size) {
  void *p = calloc(n ? n : 1, size ? size : 1);
  if (!p) NH_ERROR(NH_ERR_MEMORY, "out of memory allocating %zu x %zu bytes", n, size);
  return p;
}

int nh_realloc(void **ptr, size_t n, size_t size) {
  n = n ? n : 1, size = size ? size : 1;
  if (n > SIZE_MAX / size)
    return NH_ERROR(NH_ERR_MEMORY, "array of %zu x %zu bytes exceeds the address space", n, size);
  void *p = realloc(*ptr, n * size);
  if (!p)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory resizing an array to %zu x %zu bytes", n, size);
  *ptr = p;
  return NH_OK;
}

int nh_grow(void **ptr, int *capacity, int need, size_t size) {
  if (need <= *capacity) return NH_OK;
  int cap = *capacity > 0 ? *capacity : 16;
  while (cap < need) cap = cap > INT_MAX / 2 ? need : 2 * cap; /* no int overflow */
  NH_TRY(nh_realloc(ptr, (size_t)cap, size));
  *capacity = cap;
  return NH_OK;
}
