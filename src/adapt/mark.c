/* mark.c — which leaves to refine, from the element indicators ηₑ of
 * adapt/spr.c.
 *
 * Two strategies (adapt.marking.strategy):
 *  - max (the seed's Eq. 16): mark every leaf with ηₑ ≥ θ ηₘ, ηₘ = maxₑ ηₑ.
 *  - dorfler (bulk chasing, Dörfler 1996): sort the leaves by decreasing ηₑ,
 *    ties by increasing cell id (deterministic), and mark the shortest prefix
 *    whose Σ ηₑ² reaches fraction · Σ_all ηₑ². The total is summed in the
 *    same order as the prefix, so fraction = 1 terminates on the last leaf
 *    with ηₑ > 0 and never marks a leaf with ηₑ = 0.
 * If ηₘ = 0 (an exactly recovered field) nothing is marked.
 *
 * Limits are applied after the strategy, to the candidates it selected:
 * a candidate is dropped if its level is ≥ max_level, or, when min_size > 0,
 * if its smallest rest edge (nh_mesh_cell_size) times the template's child
 * ratio (smallest child edge over parent edge: 1/2 for hex2, 1/4 for hex4;
 * 1/2 when not given) is < min_size: its children would be smaller than
 * min_size. Applying the limits after
 * selection keeps the meaning of θ and of the fraction independent of the
 * limits: the error that sits in cells that may not be refined any more is
 * not chased elsewhere, the estimate simply stops improving there, which
 * the run reports through η.
 *
 * The result lists cell ids in ascending order (the refinement code may
 * then process them in mesh order). Work: O(L log L) for dorfler (a sort of
 * the L leaves), O(L) for max. */
#include "adapt/adapt_impl.h"

#include <math.h>
#include <stdlib.h>

int nh_mark_entry_compare(const void *pa, const void *pb) {
  const nh_mark_entry *a = pa, *b = pb;
  if (a->eta != b->eta) return a->eta > b->eta ? -1 : 1;
  return (a->cell > b->cell) - (a->cell < b->cell);
}

static int nh_compare_int(const void *a, const void *b) {
  int x = *(const int *)a, y = *(const int *)b;
  return (x > y) - (x < y);
}

int nh_mark_cells(const nh_mesh *m, const double *eta_cell, const nh_mark_params *p, int *marked,
                  int *n_marked) {
  *n_marked = 0;
  NH_CHECK(p->strategy == NH_MARK_MAX || p->strategy == NH_MARK_DORFLER, NH_ERR_INPUT,
           "marking: unknown strategy %d", p->strategy);
  if (p->strategy == NH_MARK_MAX)
    NH_CHECK(p->theta > 0.0 && p->theta <= 1.0, NH_ERR_INPUT,
             "marking: theta = %g must lie in (0, 1]", p->theta);
  else
    NH_CHECK(p->fraction > 0.0 && p->fraction <= 1.0, NH_ERR_INPUT,
             "marking: fraction = %g must lie in (0, 1]", p->fraction);
  double eta_max = 0.0;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    NH_CHECK(isfinite(eta_cell[c]) && eta_cell[c] >= 0.0, NH_ERR_NUMERIC,
             "marking: the error indicator of cell %d is %g", c, eta_cell[c]);
    eta_max = fmax(eta_max, eta_cell[c]);
  }
  if (eta_max == 0.0) return NH_OK;

  int n = 0;
  if (p->strategy == NH_MARK_MAX) {
    double bar = p->theta * eta_max;
    for (int l = 0; l < m->n_leaves; l++)
      if (eta_cell[m->leaves[l]] >= bar) marked[n++] = m->leaves[l];
  } else {
    nh_mark_entry *order = nh_calloc((size_t)m->n_leaves, sizeof *order);
    if (!order) return NH_ERROR(NH_ERR_MEMORY, "out of memory: marking (%d leaves)", m->n_leaves);
    for (int l = 0; l < m->n_leaves; l++) {
      order[l].cell = m->leaves[l];
      order[l].eta = eta_cell[m->leaves[l]];
    }
    qsort(order, (size_t)m->n_leaves, sizeof *order, nh_mark_entry_compare);
    double total = 0.0;
    for (int l = 0; l < m->n_leaves; l++) total += order[l].eta * order[l].eta;
    double goal = p->fraction * total, sum = 0.0;
    for (int l = 0; l < m->n_leaves && order[l].eta > 0.0; l++) {
      marked[n++] = order[l].cell;
      sum += order[l].eta * order[l].eta;
      if (sum >= goal) break;
    }
    free(order);
    qsort(marked, (size_t)n, sizeof(int), nh_compare_int);
  }

  int kept = 0;
  for (int i = 0; i < n; i++) {
    int c = marked[i];
    if (m->level[c] >= p->max_level) continue;
    double ratio = p->child_ratio > 0.0 ? p->child_ratio : 0.5;
    if (p->min_size > 0.0 && ratio * nh_mesh_cell_size(m, c) < p->min_size) continue;
    marked[kept++] = c;
  }
  *n_marked = kept;
  return NH_OK;
}
