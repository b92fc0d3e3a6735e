/* log.c — informational and warning lines on stderr, and a monotonic clock. */
#include "core/core.h"

#include <stdarg.h>
#include <stdio.h>
#include <time.h>

static nh_log_level nh_level = NH_LOG_INFO;

void nh_log_set_level(nh_log_level level) {
  nh_level = level;
}

nh_log_level nh_log_get_level(void) {
  return nh_level;
}

void nh_log_info(const char *fmt, ...) {
  if (nh_level < NH_LOG_INFO) return;
  va_list ap;
  va_start(ap, fmt);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fputc('\n', stderr);
}

void nh_log_warn(const char *fmt, ...) {
  char raw[2048], line[2048];
  va_list ap;
  va_start(ap, fmt);
  vsnprintf(raw, sizeof raw, fmt, ap);
  va_end(ap);
  nh_escape_control(line, sizeof line, raw);
  fprintf(stderr, "warning: %s\n", line);
}

double nh_time_now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
