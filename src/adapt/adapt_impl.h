/* adapt_impl.h — private to the adapt module: the (η, cell) pairs that
 * marking (mark.c) and the DOF budget (refine.c) sort. */
#ifndef NH_ADAPT_IMPL_H
#define NH_ADAPT_IMPL_H

#include "adapt/adapt.h"

typedef struct {
  double eta;
  int cell;
} nh_mark_entry;

/* qsort order of nh_mark_entry: decreasing η, then increasing cell id. */
int nh_mark_entry_compare(const void *a, const void *b);

#endif
