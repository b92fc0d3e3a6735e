/* bytes.c — a growable byte buffer and a bounded reader: the checkpoint's
 * payload (sim/checkpoint.c) and the tools' state in it (contact/state.c).
 * A failed allocation or a read past the end is remembered (failed,
 * short_read), so a writer or reader checks once at the end. */
#include "core/core.h"

#include <stdlib.h>
#include <string.h>

void nh_bytes_put(nh_bytes *b, const void *p, size_t n) {
  if (b->failed || n == 0) return;
  if (b->len + n > b->cap) {
    size_t cap = b->cap ? b->cap : 4096;
    while (cap < b->len + n) cap *= 2;
    if (nh_realloc((void **)&b->data, cap, 1)) {
      b->failed = 1;
      return;
    }
    b->cap = cap;
  }
  memcpy(b->data + b->len, p, n);
  b->len += n;
}

void nh_bytes_get(nh_byte_reader *r, void *out, size_t n) {
  if (r->short_read || (size_t)(r->end - r->p) < n) {
    r->short_read = 1;
    if (n) memset(out, 0, n);
    return;
  }
  if (n) memcpy(out, r->p, n);
  r->p += n;
}
