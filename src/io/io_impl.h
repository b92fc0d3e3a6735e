/* io_impl.h — private to the io module: a growing text buffer for the XML
 * files (PVD, XDMF) that are rendered in memory and written atomically, the
 * string helpers of the writers, and the XDMF index of the HDF5 frames. */
#ifndef NH_IO_IMPL_H
#define NH_IO_IMPL_H

#include "io/io.h"

#include <stddef.h>

/* ---- text (io/text.c) ---- */
typedef struct {
  char *s; /* NUL-terminated once anything was written */
  size_t len, cap;
} nh_text;

/* Append printf-formatted text. NH_ERR_MEMORY on allocation failure. */
int nh_text_printf(nh_text *b, const char *fmt, ...) __attribute__((format(printf, 2, 3)));
/* Append a string with &, <, >, " escaped for XML text and attributes. */
int nh_text_put_xml(nh_text *b, const char *s);
/* A copy of s; "DIR/NAME". NULL when out of memory (recorded, nh_calloc). */
char *nh_text_copy(const char *s);
char *nh_text_join_path(const char *dir, const char *name);
/* A free name to move `path` aside to: PATH.SUFFIX, or PATH.SUFFIX.2, .3,
 * ... if taken (NULL: none free below 1000, or out of memory). */
char *nh_text_aside_name(const char *path, const char *suffix);

/* ---- the XDMF index of the HDF5 frames (io/xdmf.c) ---- */
typedef struct {
  char *path;    /* DIR/results.xdmf (owned) */
  nh_text grids; /* the <Grid> elements of the frames listed so far */
} nh_xdmf;

/* Add the <Grid> of frame NNNNNN (`frame`) at `time`: the hexahedral
 * `layout`'s sizes, field names and components (its arrays are not read),
 * its datasets referenced in the frame file `file` (relative to the
 * folder). NH_ERR_MEMORY; the index is then as before. */
int nh_xdmf_add_frame(nh_xdmf *x, const char *frame, const char *file, double time,
                      const nh_frame *layout);
/* Write the index of the frames added so far to x->path atomically
 * (nh_write_text). NH_ERR_IO naming the path, NH_ERR_MEMORY. */
int nh_xdmf_write(const nh_xdmf *x);
/* Free the path and the text; *x becomes empty. */
void nh_xdmf_free(nh_xdmf *x);

#endif
