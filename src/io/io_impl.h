/* io_impl.h — private to the io module: a growing text buffer for the XML
 * files (PVD, XDMF) that are rendered in memory and written atomically. */
#ifndef NH_IO_IMPL_H
#define NH_IO_IMPL_H

#include "io/io.h"

#include <stddef.h>

typedef struct {
  char *s; /* NUL-terminated once anything was written */
  size_t len, cap;
} nh_text;

/* Append printf-formatted text. NH_ERR_MEMORY on allocation failure. */
int nh_text_printf(nh_text *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Append a string with &, <, >, " escaped for XML text and attributes. */
int nh_text_put_xml(nh_text *b, const char *s);

#endif
