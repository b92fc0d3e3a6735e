/* refine.c — the refinement driver: from the error indicators of the last
 * solution to a refined mesh carrying the state (the seed's §2.3).
 *
 * nh_adapt_estimate computes the SPR indicators ηₑ (adapt/spr.c, Eq. 15) and
 * keeps them for the frame written before refinement. nh_adapt_step then
 *  1. marks leaves (adapt/mark.c: Eq. 16 or Dörfler, max_level, min_size);
 *  2. applies the DOF budget (adapt.max_dofs) and the cell cap
 *     (limits.max_cells): the marked cells are sorted by decreasing ηₑ, ties
 *     by increasing cell id, and the longest prefix whose new nodes (and
 *     new leaves) fit is kept. The new nodes of a cell are
 *     counted as if none were shared with a neighbour (template nodes less
 *     its 8 corners), so the budget holds whatever the sharing; the kept
 *     cells go to the refinement in that order;
 *  3. refines them by the template (mesh/refine.c, hanging nodes allowed);
 *  4. carries every nodal field to the new nodes by Eq. 17: the value at a
 *     new node is the trilinear interpolation of its parent's corner values
 *     at the node's reference coordinates in the parent.
 * What depends on the mesh (element data, loads, hanging-node table, the
 * linear system) is rebuilt by the caller, which then makes the hanging
 * values exactly their masters' interpolation. */
#include "adapt/adapt_impl.h"

#include <stdlib.h>

struct nh_adapt {
  nh_mark_params mark;
  int max_dofs;
  int max_cells;    /* limits.max_cells (0: none) */
  int warned_cells; /* the cap was met (warned once) */
  nh_template *tmpl;
  double *eta_cell; /* per cell id, valid when have_eta */
  int cap_eta, have_eta;
};

int nh_adapt_create(const nh_adapt_spec *spec, int max_cells, nh_adapt **out) {
  *out = NULL;
  nh_adapt *a = nh_calloc(1, sizeof *a);
  if (!a) return NH_ERR_MEMORY;
  int rc = nh_template_load(spec->template_path, &a->tmpl);
  if (rc) {
    free(a);
    return rc;
  }
  a->mark = (nh_mark_params){.strategy = spec->strategy,
                             .theta = spec->theta,
                             .fraction = spec->fraction,
                             .max_level = spec->max_level,
                             .min_size = spec->min_size,
                             .child_ratio = nh_template_child_ratio(a->tmpl)};
  a->max_dofs = spec->max_dofs;
  a->max_cells = max_cells;
  *out = a;
  return NH_OK;
}

void nh_adapt_destroy(nh_adapt **adapt) {
  if (!adapt || !*adapt) return;
  nh_template_destroy(&(*adapt)->tmpl);
  free((*adapt)->eta_cell);
  free(*adapt);
  *adapt = NULL;
}

int nh_adapt_estimate(nh_adapt *a, const nh_mesh *m, const nh_tissue *tissue, const double *u,
                      const nh_hanging *hanging, double *eta, double *eta_rel) {
  if (m->n_cells > a->cap_eta) {
    double *e = realloc(a->eta_cell, sizeof(double) * (size_t)m->n_cells);
    if (!e) return NH_ERROR(NH_ERR_MEMORY, "out of memory: error indicators");
    a->eta_cell = e;
    a->cap_eta = m->n_cells;
  }
  NH_TRY(nh_spr_estimate(m, tissue, u, hanging, a->eta_cell, eta, eta_rel));
  a->have_eta = 1;
  return NH_OK;
}

const double *nh_adapt_indicators(const nh_adapt *a) {
  return a && a->have_eta ? a->eta_cell : NULL;
}

/* Keep the first cells of largest η whose new nodes fit in the budget. */
static int nh_adapt_budget(nh_adapt *a, const nh_mesh *m, int *marked, int *n_marked) {
  nh_mark_entry *order = malloc(sizeof *order * (size_t)*n_marked);
  if (!order) return NH_ERROR(NH_ERR_MEMORY, "out of memory: refinement budget");
  for (int i = 0; i < *n_marked; i++)
    order[i] = (nh_mark_entry){.eta = a->eta_cell[marked[i]], .cell = marked[i]};
  qsort(order, (size_t)*n_marked, sizeof *order, nh_mark_entry_compare);
  for (int i = 0; i < *n_marked; i++) marked[i] = order[i].cell;
  free(order);
  long room = a->max_dofs > 0
                  ? ((long)a->max_dofs - 3L * m->n_nodes) / (3L * (a->tmpl->n_nodes - 8))
                  : *n_marked;
  /* limits.max_cells: each refined cell adds n_children - 1 leaves. */
  long cells =
      a->max_cells > 0 ? ((long)a->max_cells - m->n_leaves) / (a->tmpl->n_children - 1) : *n_marked;
  if (cells < *n_marked && cells <= room && !a->warned_cells) {
    nh_log_warn("refinement stops at limits.max_cells = %d cells (%d now)", a->max_cells,
                m->n_leaves);
    a->warned_cells = 1;
  }
  if (cells < room) room = cells;
  if (room < *n_marked) *n_marked = room > 0 ? (int)room : 0;
  return NH_OK;
}

/* Eq. 17: a new node's values from its parent's corners. */
static void nh_adapt_transfer(const nh_mesh *m, const nh_refine_info *info, int old_nodes,
                              double *f) {
  for (int k = 0; k < info->n_new; k++) {
    double N[8];
    nh_hex_shape(info->xi + 3 * k, N);
    const int *e = m->cells + 8 * info->parent[k];
    for (int i = 0; i < 3; i++) {
      double value = 0.0;
      for (int c = 0; c < 8; c++) value += N[c] * f[3 * e[c] + i];
      f[3 * (old_nodes + k) + i] = value;
    }
  }
}

int nh_adapt_step(nh_adapt *a, nh_mesh *m, int n_fields, double **fields, int *n_refined) {
  *n_refined = 0;
  NH_CHECK(a->have_eta, NH_ERR_INTERNAL, "refinement without error indicators");
  int *marked = malloc(sizeof(int) * (size_t)(m->n_leaves ? m->n_leaves : 1)), n_marked = 0;
  if (!marked) return NH_ERROR(NH_ERR_MEMORY, "out of memory: marking");
  int rc = nh_mark_cells(m, a->eta_cell, &a->mark, marked, &n_marked);
  /* (marked cells keep mark order, and the mesh its numbering, unless a budget binds) */
  int over_cap =
      a->max_cells > 0 && m->n_leaves + (long)n_marked * (a->tmpl->n_children - 1) > a->max_cells;
  if (!rc && (a->max_dofs > 0 || over_cap) && n_marked > 0)
    rc = nh_adapt_budget(a, m, marked, &n_marked);
  if (rc || n_marked == 0) {
    free(marked);
    return rc;
  }
  nh_refine_info info = {0};
  const int old_nodes = m->n_nodes;
  rc = nh_mesh_refine(m, a->tmpl, marked, n_marked, &info);
  free(marked);
  a->have_eta = 0; /* the indicators belonged to the cells just replaced */
  for (int f = 0; f < n_fields && !rc; f++) {
    double *p = realloc(fields[f], sizeof(double) * 3 * (size_t)(m->n_nodes ? m->n_nodes : 1));
    if (!p)
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: %d nodes", m->n_nodes);
    else {
      fields[f] = p;
      nh_adapt_transfer(m, &info, old_nodes, p);
    }
  }
  nh_refine_info_free(&info);
  if (!rc) *n_refined = n_marked;
  return rc;
}
