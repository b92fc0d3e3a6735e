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
 * Under adapt.estimator goal (nh_adapt_estimate_goal, adapt/dwr.c) the
 * indicators are the goal indicators summed over the goals above
 * adapt.tolerance (between separate estimates: the combined dual's; with
 * adapt.marking.goals each, the largest of each goal's indicator over its
 * own maximum; with adapt.marking.goal_leaves, the leaves meeting a
 * goal's averaging box below max_level raised to the largest indicator,
 * nh_adapt_mark_goal_leaves); with
 * a tolerance, marking looks only at cells that can still be refined (so
 * the goal error is chased below it; without one, that would refine every
 * cell near the goals to max_level: docs/adaptivity.md), and the marked
 * set is closed under the 2:1 rule (mesh/grade.c; with a budget the sorted
 * prefix is shortened until the closed set fits). With adapt.coarsen,
 *  5. families whose children all have an indicator (under goal: summed
 *     over every goal) below fraction × the smallest marked indicator (the
 *     largest one when nothing was marked) and whose merge keeps the 2:1
 *     rule are merged (mesh/coarsen.c); the fields are compacted by
 *     injection. Cells created by this refinement have no indicator and stay.
 * What depends on the mesh (element data, loads, hanging-node table, the
 * linear system) is rebuilt by the caller, which then makes the hanging
 * values exactly their masters' interpolation. */
#include "adapt/adapt_impl.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct nh_adapt {
  nh_mark_params mark;
  int max_dofs;
  int max_cells;    /* limits.max_cells (0: none) */
  int warned_cells; /* the cap was met (warned once) */
  nh_template *tmpl;
  int n_keep;             /* nh_adapt_keep_regions: coarsening's floor at regions */
  const nh_region *keep;  /* n_keep regions ... */
  const nh_fix *keep_fix; /* ... and their refine: the largest edge there (0: none) */
  double *eta_cell;       /* per cell id, valid when have_eta */
  int cap_eta, have_eta;
  nh_spr_cache *spr;          /* SPR's weights of the current mesh (spr.c) */
  nh_goal_cache *functionals; /* the goals' functionals of the current mesh (dwr.c) */
  /* goal-oriented estimation (estimator goal) */
  int goal, grade;                /* estimator goal; refinement closed by the 2:1 rule */
  double tolerance;               /* m (0: none) */
  const nh_geometry_loads *loads; /* the geometry term's loads (may be NULL) */
  const nh_constraint_data *data; /* the constraint-data term's data (may be NULL) */
  nh_dwr_fronts *fronts;          /* the fronts estimated with the goals (may be NULL) */
  double coarsen;                 /* fraction of the marking threshold (0: none) */
  int n_goals;                    /* goal points */
  double *goal_points;            /* 3 per goal */
  double radius;                  /* half-width of the averaging box */
  double *goal_error;             /* per goal: |E_p| of the last estimate, valid when have_eta */
  double *goal_est;               /* per goal: the signed E_pk (3), valid when have_eta */
  double *goal_geo;               /* per goal: its geometry part G_pk (3, in goal_est) */
  double *goal_cons;              /* per goal: its constraint-data part C_pk (3, in goal_est) */
  double *goal_inh;   /* per goal: the tools' rows' part of C_pk, inherited (3; NaN: not split) */
  double *goal_ind;   /* n_goals x cap_eta */
  double *eta_all;    /* per cell: Σ over every goal (coarsening: a goal below tolerance still
                         needs its cells) */
  int n_active;       /* goals above tolerance at the last estimate */
  nh_adapt_stop stop; /* what ended the last refinement */
  /* the nodal transfer of the last mesh change (the fields' Eq. 17 and
   * injection as a map), valid when have_transfer */
  nh_node_transfer transfer;
  int have_transfer;
  /* several goals in one dual (dwr.c): every separate_every-th estimate
   * solves each goal's duals and sets the weights, the others one dual */
  int separate_every, since_separate, have_weights;
  int local_dual;   /* adapt.local_dual: the local enriched dual at held rows (dwr_local.c) */
  int each_goal;    /* adapt.marking.goals: each (every goal's indicator over its own maximum) */
  int goal_leaves;  /* adapt.marking.goal_leaves: the leaves meeting a goal's box are marked */
  double *weight;   /* 3 per goal: ω_pk = E_pk / |E_p| of the last separate estimate */
  double *sep_est;  /* 3 per goal: E_pk of the last separate estimate */
  double *goal_top; /* per goal: its largest indicator over the leaves (marking.goals each) */
  double sep_sum;   /* Σ_p |E_p| of the last separate estimate (= Σ ω E there) */
  /* the memory term (dwr_memory.c): the dynamic step's data of the next
   * estimate (have_memory), its step; the links' values S_m (m = 0 …
   * max_links, 3 n_goals each) after the last separate estimate (mem_cur,
   * at step cur_step) and after the last one at an earlier step (mem_base,
   * at base_step: a re-solve estimates its step again from it); own, the
   * links' own estimates of an estimate */
  nh_dwr_memory memory;
  int have_memory, memory_step, cur_step, base_step, cap_links;
  int sep_memory;               /* the last separate estimate had the memory term */
  uint64_t cur_rows, base_rows; /* the duals' held rows at cur_step, base_step (a hash) */
  double *mem_cur, *mem_base, *mem_own;
};

int nh_adapt_create(const nh_adapt_spec *spec, int max_cells, nh_adapt **out) {
  *out = NULL;
  nh_adapt *a = nh_calloc(1, sizeof *a);
  if (!a) return NH_ERR_MEMORY;
  int rc = nh_template_load(spec->template_path, &a->tmpl);
  if (rc) {
    free(a);
    if (rc != NH_ERR_INPUT || !spec->where_template[0]) return rc;
    char msg[1024]; /* a bad template: reported at the scene's adapt.template */
    snprintf(msg, sizeof msg, "%s", nh_error_message());
    return NH_ERROR(rc, "%s: %s", spec->where_template, msg);
  }
  a->mark = (nh_mark_params){.strategy = spec->strategy,
                             .theta = spec->theta,
                             .fraction = spec->fraction,
                             .max_level = spec->max_level,
                             .min_size = spec->min_size,
                             .child_ratio = nh_template_child_ratio(a->tmpl)};
  a->max_dofs = spec->max_dofs;
  a->max_cells = max_cells;
  a->goal = spec->estimator == NH_ESTIMATOR_GOAL;
  a->grade = a->goal;
  a->tolerance = spec->tolerance;
  a->coarsen = spec->coarsen;
  a->separate_every = spec->separate_every > 0 ? spec->separate_every : 1;
  a->local_dual = spec->local_dual;
  a->each_goal = spec->goal_marking == NH_GOAL_MARKING_EACH;
  a->goal_leaves = spec->goal_leaves;
  *out = a;
  return NH_OK;
}

void nh_adapt_destroy(nh_adapt **adapt) {
  if (!adapt || !*adapt) return;
  nh_template_destroy(&(*adapt)->tmpl);
  nh_spr_cache_destroy(&(*adapt)->spr);
  nh_goal_cache_destroy(&(*adapt)->functionals);
  free((*adapt)->eta_cell);
  free((*adapt)->goal_points);
  free((*adapt)->goal_error);
  free((*adapt)->goal_est);
  free((*adapt)->goal_geo);
  free((*adapt)->goal_cons);
  free((*adapt)->goal_inh);
  free((*adapt)->goal_ind);
  free((*adapt)->eta_all);
  nh_node_transfer_free(&(*adapt)->transfer);
  free((*adapt)->weight);
  free((*adapt)->sep_est), free((*adapt)->goal_top);
  free((*adapt)->mem_cur), free((*adapt)->mem_base), free((*adapt)->mem_own);
  free(*adapt);
  *adapt = NULL;
}

int nh_adapt_estimate(nh_adapt *a, const nh_mesh *m, const nh_tissue *tissue, const double *u,
                      const nh_hanging *hanging, const double *frames, double *eta,
                      double *eta_rel) {
  if (m->n_cells > a->cap_eta) {
    NH_TRY(nh_realloc((void **)&a->eta_cell, (size_t)m->n_cells, sizeof(double)));
    a->cap_eta = m->n_cells;
  }
  if (!a->spr) NH_TRY(nh_spr_cache_create(&a->spr));
  NH_TRY(nh_spr_estimate_cached(a->spr, m, tissue, u, hanging, frames, a->eta_cell, eta, eta_rel));
  a->have_eta = 1;
  return NH_OK;
}

int nh_adapt_set_goals(nh_adapt *a, const nh_mesh *m, int n, const double *points) {
  free(a->goal_points), free(a->goal_error), free(a->goal_est), free(a->weight), free(a->sep_est);
  free(a->goal_top);
  free(a->goal_geo), free(a->goal_cons), free(a->goal_inh);
  a->goal_points = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->goal_error = nh_calloc((size_t)(n ? n : 1), sizeof(double));
  a->goal_est = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->goal_geo = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->goal_cons = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->goal_inh = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->weight = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->sep_est = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double));
  a->goal_top = nh_calloc((size_t)(n ? n : 1), sizeof(double));
  if (!a->goal_points || !a->goal_error || !a->goal_est || !a->goal_geo || !a->goal_cons ||
      !a->goal_inh || !a->weight || !a->sep_est || !a->goal_top)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: goals");
  a->have_weights = 0;
  memcpy(a->goal_points, points, sizeof(double) * 3 * (size_t)n);
  a->n_goals = n;
  double h = fmin(m->spacing[0], fmin(m->spacing[1], m->spacing[2]));
  a->radius = 0.5 * h * pow(a->mark.child_ratio, a->mark.max_level);
  return NH_OK;
}

void nh_adapt_set_geometry_loads(nh_adapt *a, const nh_geometry_loads *loads) {
  a->loads = loads;
}

void nh_adapt_set_constraint_data(nh_adapt *a, const nh_constraint_data *data) {
  a->data = data;
}

void nh_adapt_set_fronts(nh_adapt *a, nh_dwr_fronts *fronts) {
  a->fronts = fronts;
}

void nh_adapt_set_memory(nh_adapt *a, const nh_dwr_memory *memory, int step) {
  a->have_memory = memory != NULL;
  if (memory) a->memory = *memory;
  a->memory_step = step;
}

/* Which rows the goals' duals hold (nh_dwr_active_rows): an FNV-1a hash of
 * each active row's kind, tools and tissue nodes, so that two steps whose
 * duals hold the same rows hash the same (the rows' weights and directions
 * may move: a channel point's weights as the tool slides). */
static uint64_t nh_adapt_held_rows(const nh_rows *rows) {
  uint64_t hash = 1469598103934665603u;
  const int m = rows ? rows->m : 0;
  unsigned char *active = m ? nh_calloc((size_t)m, 1) : NULL;
  if (!active) return m ? 0 : hash; /* out of memory: matches nothing but another failure */
  nh_dwr_active_rows(rows, active);
  for (int i = 0; i < m; i++) {
    if (!active[i]) continue;
    int key[3] = {rows->law[i].kind, rows->tool[i], rows->tool2 ? rows->tool2[i] : -1};
    for (int k = 0; k < 3 + rows->start[i + 1] - rows->start[i]; k++) {
      uint32_t v = (uint32_t)(k < 3 ? key[k] : rows->node[rows->start[i] + k - 3]);
      for (int b = 0; b < 4; b++) hash = (hash ^ ((v >> (8 * b)) & 0xffu)) * 1099511628211u;
    }
  }
  free(active);
  return hash;
}

/* The memory term after a separate estimate at step a->memory_step whose
 * links' own estimates are a->mem_own (links 0 … n_links): from the links'
 * values k steps before (the last estimate at an earlier step), S_m =
 * Σ_{i<k} own_{m+i} + S_{m+k}(base) (dwr_memory.c; the k − 1 steps between
 * two estimates taken with this step's own errors), and the goals'
 * estimates E_q = S_0, the memory part S_0 − own_0 also in the inherited
 * part (no refinement of this step reduces it). Only with memory (a
 * dynamic step, adapt.memory: the same at every step of a run). */
static int nh_adapt_memory_update(nh_adapt *a, int n_links, uint64_t held) {
  const int nz = 3 * a->n_goals, cap = a->memory.max_links + 1;
  if (cap > a->cap_links) {
    NH_TRY(nh_realloc((void **)&a->mem_cur, (size_t)cap * nz, sizeof(double)));
    NH_TRY(nh_realloc((void **)&a->mem_base, (size_t)cap * nz, sizeof(double)));
    for (size_t i = (size_t)a->cap_links * nz; i < (size_t)cap * nz; i++)
      a->mem_cur[i] = a->mem_base[i] = 0.0;
    a->cap_links = cap;
  }
  if (a->memory_step != a->cur_step) { /* the first estimate at this step */
    memcpy(a->mem_base, a->mem_cur, sizeof(double) * (size_t)a->cap_links * nz);
    a->base_step = a->cur_step, a->base_rows = a->cur_rows;
    a->cur_step = a->memory_step;
  }
  a->cur_rows = held;
  const int k = a->cur_step - a->base_step > 0 ? a->cur_step - a->base_step : 1;
  /* the links are the same functionals only while the duals hold the same
   * rows: the earlier steps' values of other links are dropped */
  const int same = a->base_rows == held;
  for (int m = 0; m < a->cap_links; m++)
    for (int q = 0; q < nz; q++) {
      double S = same && m + k < a->cap_links ? a->mem_base[(size_t)nz * (m + k) + q] : 0.0;
      for (int i = 0; i < k && m + i <= n_links; i++) S += a->mem_own[(size_t)nz * (m + i) + q];
      a->mem_cur[(size_t)nz * m + q] = S;
    }
  for (int q = 0; q < nz; q++) {
    const double memory = a->mem_cur[q] - a->goal_est[q];
    a->goal_est[q] += memory;
    a->goal_inh[q] += memory;
  }
  return NH_OK;
}

/* Whether goal p is above the tolerance by the part of its last estimate
 * that refining this mesh can reduce: E_p without the tools' rows' part of
 * its constraint-data term, their anchors' errors, which were made at the
 * steps that anchored them (docs/theory.md §6.6, "Anchoring"). Counting
 * them made tolerance mode refine the DBS hold to 2× the dofs, where the
 * error is the insertion's (docs/dbs.md, "The front's anchoring error").
 * After a combined estimate (not split: NaN) the whole estimate counts;
 * without a tolerance, any nonzero estimate. */
static int nh_adapt_goal_above(const nh_adapt *a, int p) {
  if (!(a->tolerance > 0.0)) return !(a->goal_error[p] <= 0.0); /* no tolerance: any error */
  const double *e = a->goal_est + 3 * p, *i = a->goal_inh + 3 * p;
  double r2 = 0.0;
  for (int k = 0; k < 3; k++) {
    double r = isnan(i[k]) ? e[k] : e[k] - i[k];
    r2 += r * r;
  }
  return !(sqrt(r2) <= a->tolerance);
}

/* adapt.marking.goal_leaves: every leaf below max_level whose rest box
 * overlaps the box B = p + [−r, r]³ of a goal still above tolerance gets
 * the largest indicator, so that the marking (max: any θ; dorfler: first)
 * refines it. J_p is the mean over B, whose half-width r is half the finest
 * cell's edge: in a coarser leaf the discrete J_p is the mean of that
 * leaf's trilinear interpolant, and the interpolation error at p is not
 * what the estimate weights (the dual's load lies inside one leaf, and its
 * recovered error there is as smooth as the leaf). Measured on the phantom
 * (docs/phantom.md, "Why 1A–1E do not converge"): the probes' own leaves
 * stayed at level 0–1 in the puncture steps. */
static void nh_adapt_mark_goal_leaves(nh_adapt *a, const nh_mesh *m) {
  double top = 0.0;
  for (int l = 0; l < m->n_leaves; l++) top = fmax(top, a->eta_cell[m->leaves[l]]);
  if (!(top > 0.0)) return; /* nothing loads the tissue yet: nothing to refine for */
  for (int l = 0; l < m->n_leaves; l++) {
    const int c = m->leaves[l];
    if (m->level[c] >= a->mark.max_level) continue;
    double Xe[24], lo[3], hi[3];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int k = 0; k < 3; k++) lo[k] = hi[k] = Xe[k];
    for (int q = 1; q < 8; q++)
      for (int k = 0; k < 3; k++)
        lo[k] = fmin(lo[k], Xe[3 * q + k]), hi[k] = fmax(hi[k], Xe[3 * q + k]);
    for (int p = 0; p < a->n_goals; p++) {
      if (!nh_adapt_goal_above(a, p)) continue;
      const double *x = a->goal_points + 3 * p;
      int meets = 1;
      for (int k = 0; k < 3; k++) meets &= lo[k] < x[k] + a->radius && hi[k] > x[k] - a->radius;
      if (meets) {
        a->eta_cell[c] = top;
        break;
      }
    }
  }
}

int nh_adapt_estimate_goal(nh_adapt *a, nh_system *sys, const nh_rows *rows, double scale,
                           const nh_mesh *m, const nh_tissue *tissue, const double *u,
                           const nh_hanging *hanging, double *eta, double *eta_rel) {
  NH_CHECK(a->goal && a->n_goals > 0, NH_ERR_INTERNAL, "goal estimate without goals");
  if (m->n_cells > a->cap_eta) {
    NH_TRY(nh_realloc((void **)&a->eta_cell, (size_t)m->n_cells, sizeof(double)));
    NH_TRY(
        nh_realloc((void **)&a->goal_ind, (size_t)m->n_cells * (size_t)a->n_goals, sizeof(double)));
    NH_TRY(nh_realloc((void **)&a->eta_all, (size_t)m->n_cells, sizeof(double)));
    a->cap_eta = m->n_cells;
  }
  if (!a->functionals) NH_TRY(nh_goal_cache_create(&a->functionals));
  a->have_eta = 0; /* until this estimate is complete */
  const int combined = a->have_weights && a->since_separate + 1 < a->separate_every;
  nh_dwr_result r = {.estimate = a->goal_est,
                     .norm = a->goal_error,
                     .indicator = a->goal_ind,
                     .loads = a->loads,
                     .geometry = a->goal_geo,
                     .data = a->data,
                     .constraint = a->goal_cons,
                     .inherited = a->goal_inh,
                     .local = a->local_dual,
                     .functionals = a->functionals,
                     .fronts = a->fronts};
  if (!combined) {
    if (a->have_memory) {
      size_t n = (size_t)(a->memory.max_links + 1) * 3 * (size_t)a->n_goals;
      NH_TRY(nh_realloc((void **)&a->mem_own, n, sizeof(double)));
      r.memory = &a->memory, r.memory_own = a->mem_own;
    }
    NH_TRY(nh_dwr_estimate(sys, rows, scale, m, tissue, hanging, u, a->n_goals, a->goal_points,
                           a->radius, NULL, &r));
    a->sep_memory = 0;
    /* the weights of the combined functional: each goal's error direction */
    a->sep_sum = 0.0;
    for (int p = 0; p < a->n_goals; p++) {
      double e = a->goal_error[p];
      for (int k = 0; k < 3; k++) {
        a->sep_est[3 * p + k] = a->goal_est[3 * p + k];
        a->weight[3 * p + k] = e > 0.0 ? a->goal_est[3 * p + k] / e : 0.0;
      }
      a->sep_sum += e;
    }
    a->have_weights = a->sep_sum > 0.0 && isfinite(a->sep_sum);
    a->since_separate = 0;
    /* the memory term on top of the step's own estimates (the weights and
     * the combined estimates' ratio are the own estimates') */
    if (a->have_memory) NH_TRY(nh_adapt_memory_update(a, r.memory_links, nh_adapt_held_rows(rows)));
    a->sep_memory = a->have_memory;
    for (int p = 0; p < a->n_goals; p++) {
      const double *e = a->goal_est + 3 * p;
      a->goal_error[p] = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    }
  } else {
    double Ec = 0.0;
    r.estimate = &Ec, r.norm = NULL, r.geometry = NULL, r.constraint = NULL, r.inherited = NULL;
    NH_TRY(nh_dwr_estimate_combined(sys, rows, scale, m, tissue, hanging, u, a->n_goals,
                                    a->goal_points, a->radius, NULL, a->weight, &r));
    /* each goal's estimate carried from the last separate one by the
     * combined functional's ratio ρ = E_c / Σ_p |E_p| */
    const double rho = Ec / a->sep_sum;
    for (int p = 0; p < a->n_goals; p++) {
      double *e = a->goal_est + 3 * p;
      for (int k = 0; k < 3; k++) { /* and the last separate estimate's memory part */
        const int q = 3 * p + k;
        e[k] = rho * a->sep_est[q] + (a->sep_memory ? a->mem_cur[q] - a->mem_own[q] : 0.0);
      }
      for (int k = 0; k < 3; k++) /* not split */
        a->goal_geo[3 * p + k] = a->goal_cons[3 * p + k] = a->goal_inh[3 * p + k] = NAN;
      a->goal_error[p] = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
    }
    a->since_separate++;
  }
  /* The marking indicator over the goals still above tolerance: their sum
   * (combined: the one dual's, over every goal), or with marking.goals each
   * the largest of their indicators each divided by its own maximum over
   * the leaves, so that marking by θ of the maximum (1) marks the union of
   * every goal's own θ-marking: a goal with a small estimate is not crowded
   * out by the others (docs/phantom.md, "The goal runs' far probes"). */
  a->n_active = 0;
  for (int p = 0; p < a->n_goals; p++) a->n_active += nh_adapt_goal_above(a, p);
  const int each = a->each_goal && !combined;
  for (int p = 0; p < (each ? a->n_goals : 0); p++) {
    const double *gi = a->goal_ind + (size_t)m->n_cells * p;
    double top = 0.0;
    for (int l = 0; l < m->n_leaves; l++) top = fmax(top, gi[m->leaves[l]]);
    a->goal_top[p] = top;
  }
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double sum = 0.0, all = 0.0;
    for (int p = 0; p < (combined ? 1 : a->n_goals); p++) {
      double v = a->goal_ind[(size_t)m->n_cells * p + c];
      all += v;
      if (!combined && !nh_adapt_goal_above(a, p)) continue;
      if (!each)
        sum += v;
      else if (a->goal_top[p] > 0.0)
        sum = fmax(sum, v / a->goal_top[p]);
    }
    a->eta_cell[c] = sum;
    a->eta_all[c] = all;
  }
  if (a->goal_leaves) nh_adapt_mark_goal_leaves(a, m);
  if (eta) *eta = r.eta;
  if (eta_rel) *eta_rel = r.eta_rel;
  a->have_eta = 1;
  return NH_OK;
}

/* The carried state (adapt.h): i32 n_goals (0: none, nothing follows),
 * i32 have_weights, since_separate, f64 sep_sum, f64 weight[3 n],
 * sep_est[3 n]; the memory term: i32 cur_step, base_step, cap_links,
 * sep_memory, u64 cur_rows, base_rows, f64 mem_cur[cap 3 n],
 * mem_base[cap 3 n], own_0[3 n]. */
void nh_adapt_state_save(const nh_adapt *a, nh_bytes *b) {
  const int n = a && a->goal ? a->n_goals : 0, nz = 3 * n;
  int32_t head[3] = {n, a ? a->have_weights : 0, a ? a->since_separate : 0};
  nh_bytes_put(b, head, sizeof head);
  if (n == 0) return;
  nh_bytes_put(b, &a->sep_sum, sizeof(double));
  nh_bytes_put(b, a->weight, sizeof(double) * nz);
  nh_bytes_put(b, a->sep_est, sizeof(double) * nz);
  int32_t mem[4] = {a->cur_step, a->base_step, a->cap_links, a->sep_memory};
  uint64_t rows[2] = {a->cur_rows, a->base_rows};
  nh_bytes_put(b, mem, sizeof mem);
  nh_bytes_put(b, rows, sizeof rows);
  nh_bytes_put(b, a->mem_cur, sizeof(double) * (size_t)a->cap_links * nz);
  nh_bytes_put(b, a->mem_base, sizeof(double) * (size_t)a->cap_links * nz);
  for (int q = 0; q < nz; q++) {
    double own = a->mem_own && a->sep_memory ? a->mem_own[q] : 0.0;
    nh_bytes_put(b, &own, sizeof own);
  }
}

int nh_adapt_state_load(nh_adapt *a, const unsigned char *data, size_t size) {
  nh_byte_reader r = {data, data + size, 0};
  int32_t head[3] = {0, 0, 0}, mem[4] = {0, 0, 0, 0};
  nh_bytes_get(&r, head, sizeof head);
  const int n = a && a->goal ? a->n_goals : 0, nz = 3 * n;
  if (r.short_read || head[0] != n)
    return NH_ERROR(NH_ERR_INPUT, "the goal estimate's state has %d goals, the scene %d",
                    (int)head[0], n);
  if (n == 0)
    return r.p == r.end ? NH_OK : NH_ERROR(NH_ERR_INPUT, "the goal estimate's state goes on");
  nh_bytes_get(&r, &a->sep_sum, sizeof(double));
  nh_bytes_get(&r, a->weight, sizeof(double) * nz);
  nh_bytes_get(&r, a->sep_est, sizeof(double) * nz);
  uint64_t rows[2] = {0, 0};
  nh_bytes_get(&r, mem, sizeof mem);
  nh_bytes_get(&r, rows, sizeof rows);
  const int cap = mem[2];
  if (r.short_read || cap < 0 || cap > 1 + (int)((r.end - r.p) / (sizeof(double) * (nz ? nz : 1))))
    return NH_ERROR(NH_ERR_INPUT, "the goal estimate's state is malformed (%d links)", cap);
  if (cap > 0) {
    NH_TRY(nh_realloc((void **)&a->mem_cur, (size_t)cap * nz, sizeof(double)));
    NH_TRY(nh_realloc((void **)&a->mem_base, (size_t)cap * nz, sizeof(double)));
    NH_TRY(nh_realloc((void **)&a->mem_own, (size_t)cap * nz, sizeof(double)));
    memset(a->mem_own, 0, sizeof(double) * (size_t)cap * nz);
  }
  nh_bytes_get(&r, a->mem_cur, sizeof(double) * (size_t)cap * nz);
  nh_bytes_get(&r, a->mem_base, sizeof(double) * (size_t)cap * nz);
  for (int q = 0; q < nz; q++)
    nh_bytes_get(&r, cap > 0 ? a->mem_own + q : &(double){0}, sizeof(double));
  if (r.short_read || r.p != r.end)
    return NH_ERROR(NH_ERR_INPUT, "the goal estimate's state %s",
                    r.short_read ? "ends early" : "goes on");
  a->have_weights = head[1], a->since_separate = head[2];
  a->cur_step = mem[0], a->base_step = mem[1], a->cap_links = cap, a->sep_memory = mem[3];
  a->cur_rows = rows[0], a->base_rows = rows[1];
  return NH_OK;
}

const double *nh_adapt_goal_errors(const nh_adapt *a) {
  return a && a->goal && a->have_eta ? a->goal_error : NULL;
}

const double *nh_adapt_goal_estimates(const nh_adapt *a) {
  return a && a->goal && a->have_eta ? a->goal_est : NULL;
}

const double *nh_adapt_goal_geometry(const nh_adapt *a) {
  return a && a->goal && a->have_eta ? a->goal_geo : NULL;
}

const double *nh_adapt_goal_constraint(const nh_adapt *a) {
  return a && a->goal && a->have_eta ? a->goal_cons : NULL;
}

const nh_node_transfer *nh_adapt_last_transfer(const nh_adapt *a) {
  return a && a->have_transfer ? &a->transfer : NULL;
}

nh_adapt_stop nh_adapt_last_stop(const nh_adapt *a) {
  return a ? a->stop : NH_ADAPT_REFINED;
}

const double *nh_adapt_indicators(const nh_adapt *a) {
  return a && a->have_eta ? a->eta_cell : NULL;
}

/* Keep the first cells of largest η whose new nodes fit in the budget. */
static int nh_adapt_budget(nh_adapt *a, const nh_mesh *m, int *marked, int *n_marked) {
  nh_mark_entry *order = nh_calloc((size_t)*n_marked, sizeof *order);
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

/* Close the marked set under the 2:1 rule; with a budget, shorten the
 * (η-sorted) prefix until the closed set fits. */
static int nh_adapt_close(const nh_adapt *a, const nh_mesh *m, int *marked, int *n_marked) {
  int *order = nh_calloc((size_t)(*n_marked ? *n_marked : 1), sizeof(int));
  if (!order) return NH_ERROR(NH_ERR_MEMORY, "out of memory: grading");
  memcpy(order, marked, sizeof(int) * (size_t)*n_marked);
  long room =
      a->max_dofs > 0 ? ((long)a->max_dofs - 3L * m->n_nodes) / (3L * (a->tmpl->n_nodes - 8)) : -1;
  int k = *n_marked, rc = NH_OK;
  for (;;) {
    int n = k;
    memcpy(marked, order, sizeof(int) * (size_t)k);
    if ((rc = nh_mesh_grade_marks(m, marked, &n))) break;
    if (room < 0 || n <= room || k == 0) {
      *n_marked = n;
      break;
    }
    k -= k / 4 > 0 ? k / 4 : 1;
  }
  free(order);
  return rc;
}

/* The transfer of a refinement (before any coarsening of the same step):
 * the old nodes keep their values, a new node takes Eq. 17's trilinear
 * weights of its parent's corners (nh_adapt_transfer). */
static int nh_adapt_transfer_refine(nh_adapt *a, const nh_mesh *m, const nh_refine_info *info,
                                    int old_nodes) {
  nh_node_transfer *t = &a->transfer;
  const int n = old_nodes + info->n_new;
  NH_TRY(nh_realloc((void **)&t->start, (size_t)n + 1, sizeof(int)));
  NH_TRY(nh_grow((void **)&t->node, &t->cap, old_nodes + 8 * info->n_new, sizeof(int)));
  int cap = 0;
  NH_TRY(nh_grow((void **)&t->weight, &cap, t->cap, sizeof(double)));
  int q = 0;
  for (int v = 0; v < old_nodes; v++) t->start[v] = q, t->node[q] = v, t->weight[q++] = 1.0;
  for (int k = 0; k < info->n_new; k++) {
    double N[8];
    nh_hex_shape(info->xi + 3 * k, N);
    const int *e = m->cells + 8 * info->parent[k];
    t->start[old_nodes + k] = q;
    for (int c = 0; c < 8; c++)
      if (N[c] != 0.0) t->node[q] = e[c], t->weight[q++] = N[c];
  }
  t->start[n] = q;
  t->n_old = old_nodes, t->n_new = n;
  a->have_transfer = 1;
  return NH_OK;
}

/* After a coarsening: the transfer's rows of the kept nodes, compacted by
 * node_map (injection; map is increasing). Without a refinement before it in
 * the step, the transfer starts as the identity. */
static void nh_adapt_transfer_compact(nh_adapt *a, int old_nodes, const int *map) {
  nh_node_transfer *t = &a->transfer;
  if (!a->have_transfer) return; /* (set up by nh_adapt_step) */
  int q = 0, w = 0;
  for (int v = 0; v < old_nodes; v++) {
    int lo = t->start[v], hi = t->start[v + 1];
    if (map[v] < 0) continue;
    t->start[w++] = q;
    for (int p = lo; p < hi; p++) t->node[q] = t->node[p], t->weight[q++] = t->weight[p];
  }
  t->start[w] = q;
  t->n_new = w;
}

/* Merge families whose children all have η below fraction x threshold
 * (cells created by this step's refinement have no η and stay), compact the
 * fields. *n_merged: families merged. */
static int nh_adapt_coarsen(nh_adapt *a, nh_mesh *m, int old_cells, double threshold, int n_fields,
                            double **fields, int *n_merged) {
  *n_merged = 0;
  unsigned char *below = nh_calloc((size_t)(m->n_cells ? m->n_cells : 1), 1);
  int *parents = nh_calloc((size_t)(m->n_leaves / 2 + 1), sizeof(int));
  int *map = nh_calloc((size_t)(m->n_nodes ? m->n_nodes : 1), sizeof(int));
  int rc = below && parents && map ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: coarsening");
  if (!rc) {
    for (int l = 0; l < m->n_leaves; l++) {
      int c = m->leaves[l];
      const double *eta = a->goal ? a->eta_all : a->eta_cell;
      below[c] = c < old_cells && eta[c] < a->coarsen * threshold;
      for (int r = 0; r < a->n_keep && below[c] && m->parent[c] >= 0; r++)
        if (a->keep_fix[r].refine > 0.0 &&
            nh_mesh_cell_coarser_at(m, m->parent[c], &a->keep[r], a->keep_fix[r].refine))
          below[c] = 0;
    }
    int n = nh_mesh_coarsen_candidates(m, below, parents), old_nodes = m->n_nodes;
    if (n > 0 && !(rc = nh_mesh_coarsen(m, parents, n, map))) {
      for (int f = 0; f < n_fields; f++)
        for (int v = 0; v < old_nodes; v++)
          if (map[v] >= 0) memmove(fields[f] + 3 * map[v], fields[f] + 3 * v, 3 * sizeof(double));
      *n_merged = n;
      nh_adapt_transfer_compact(a, old_nodes, map);
    }
  }
  free(below), free(parents), free(map);
  return rc;
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

void nh_adapt_keep_regions(nh_adapt *a, int n, const nh_region *regions, const nh_fix *fix) {
  a->n_keep = n, a->keep = regions, a->keep_fix = fix;
}

int nh_adapt_refine_cells(nh_adapt *a, nh_mesh *m, const int *cells, int n, int n_fields,
                          double **fields) {
  const int old_nodes = m->n_nodes;
  nh_refine_info info = {0};
  a->have_transfer = 0;
  int rc = nh_mesh_refine(m, a->tmpl, cells, n, &info);
  if (!rc) rc = nh_adapt_transfer_refine(a, m, &info, old_nodes);
  for (int f = 0; f < n_fields && !rc; f++) {
    rc = nh_realloc((void **)&fields[f], 3 * (size_t)m->n_nodes, sizeof(double));
    if (!rc) nh_adapt_transfer(m, &info, old_nodes, fields[f]);
  }
  nh_refine_info_free(&info);
  if (n > 0) a->have_eta = 0;
  return rc;
}

/* Steps 1 and 2 and the 2:1 closure: the cells nh_adapt_step refines
 * (marked[], room for m->n_leaves; ascending unless a budget sorted them),
 * the smallest marked η (coarsening's reference; nothing marked: the
 * largest) and what ends the refinement. Changes nothing in a or m. */
static int nh_adapt_select(nh_adapt *a, const nh_mesh *m, int *marked, int *n_marked,
                           double *threshold, nh_adapt_stop *stop) {
  *n_marked = 0;
  *threshold = 0.0;
  for (int l = 0; l < m->n_leaves; l++) /* nothing marked: the largest indicator */
    *threshold = fmax(*threshold, (a->goal ? a->eta_all : a->eta_cell)[m->leaves[l]]);
  if (a->goal && a->n_active == 0) {
    *stop = NH_ADAPT_TOLERANCE;
    return NH_OK;
  }
  /* Tolerance mode: θ and the fraction refer to the cells that can still
   * be refined, so that the goal error is chased below the tolerance
   * (mark.c applies the limits after selection: a goal whose largest
   * contributions sit at max_level would refine nothing more). */
  const double *eta = a->eta_cell;
  double *eligible = NULL;
  if (a->goal && a->tolerance > 0) {
    eligible = nh_calloc((size_t)m->n_cells, sizeof(double));
    if (!eligible) return NH_ERROR(NH_ERR_MEMORY, "out of memory: marking");
    double ratio = a->mark.child_ratio > 0.0 ? a->mark.child_ratio : 0.5;
    for (int l = 0; l < m->n_leaves; l++) {
      int c = m->leaves[l];
      int limit = m->level[c] >= a->mark.max_level ||
                  (a->mark.min_size > 0.0 && ratio * nh_mesh_cell_size(m, c) < a->mark.min_size);
      eligible[c] = limit ? 0.0 : a->eta_cell[c];
    }
    eta = eligible;
  }
  int rc = nh_mark_cells(m, eta, &a->mark, marked, n_marked);
  free(eligible);
  *stop = *n_marked > 0 ? NH_ADAPT_REFINED : NH_ADAPT_LIMIT;
  for (int i = 0; i < *n_marked; i++) *threshold = fmin(*threshold, a->eta_cell[marked[i]]);
  int wanted = *n_marked;
  /* (marked cells keep mark order, and the mesh its numbering, unless a budget binds) */
  int over_cap =
      a->max_cells > 0 && m->n_leaves + (long)*n_marked * (a->tmpl->n_children - 1) > a->max_cells;
  if (!rc && (a->max_dofs > 0 || over_cap) && *n_marked > 0)
    rc = nh_adapt_budget(a, m, marked, n_marked);
  if (!rc && a->grade && *n_marked > 0) rc = nh_adapt_close(a, m, marked, n_marked);
  if (!rc && *n_marked < wanted) *stop = NH_ADAPT_BUDGET;
  return rc;
}

int nh_adapt_planned(nh_adapt *a, const nh_mesh *m, int *cells, int *n) {
  *n = 0;
  NH_CHECK(a->have_eta, NH_ERR_INTERNAL, "refinement without error indicators");
  double threshold;
  nh_adapt_stop stop;
  return nh_adapt_select(a, m, cells, n, &threshold, &stop);
}

int nh_adapt_step(nh_adapt *a, nh_mesh *m, int n_fields, double **fields, int *n_refined) {
  *n_refined = 0;
  NH_CHECK(a->have_eta, NH_ERR_INTERNAL, "refinement without error indicators");
  int *marked = nh_calloc((size_t)(m->n_leaves ? m->n_leaves : 1), sizeof(int)), n_marked = 0;
  if (!marked) return NH_ERROR(NH_ERR_MEMORY, "out of memory: marking");
  double threshold = 0.0;
  int rc = nh_adapt_select(a, m, marked, &n_marked, &threshold, &a->stop);
  if (rc) {
    free(marked);
    return rc;
  }
  const int old_cells = m->n_cells;
  a->have_transfer = 0;
  if (n_marked > 0) rc = nh_adapt_refine_cells(a, m, marked, n_marked, n_fields, fields);
  free(marked);
  if (!rc && !a->have_transfer && a->coarsen > 0) { /* coarsening alone: from the identity */
    nh_refine_info none = {0};
    rc = nh_adapt_transfer_refine(a, m, &none, m->n_nodes);
  }
  int n_merged = 0;
  if (!rc && a->coarsen > 0)
    rc = nh_adapt_coarsen(a, m, old_cells, threshold, n_fields, fields, &n_merged);
  if (n_marked > 0 || n_merged > 0) a->have_eta = 0; /* the indicators belonged to the old cells */
  if (!rc) *n_refined = n_marked + n_merged;
  if (rc || *n_refined == 0) a->have_transfer = 0;
  return rc;
}
