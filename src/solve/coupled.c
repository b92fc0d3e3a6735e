/* coupled.c — one backward-Euler step of the tissue and the tools coupled by
 * constraint rows: Algorithm 1 of the seed across diagonal blocks
 * (docs/interaction.md "The coupled step").
 *
 * The blocks are the tissue (A_t, sparse, CHOLMOD) and each tool (A_k, dense
 * Cholesky: its tangent is small; see nh_beam_dynamic_prepare). With the right-hand sides of the
 * two integrators,
 *   A_t dv_t = b_t + J_tᵀ λ,   A_k dv_k = b_k + J_kᵀ λ,
 * and the rows' end-of-step rates w = J v_new + g/h:
 *   1. factorise every block, dv_free = A⁻¹ b for each;
 *   2. W = J_t A_t⁻¹ J_tᵀ + Σ_k J_k A_k⁻¹ J_kᵀ: the tissue part by sparse
 *      solves with the sparse Jᵀ (Algorithm 3), each tool's by |rows_k|
 *      dense solves;
 *   3. r = J v_free + g/h (v_free the velocities after the free update, a
 *      tool's base at its prescribed velocity), λ from w = W λ + r and the
 *      rows' laws (nh_mcp_solve, warm-started with the previous λ);
 *   4. dv = dv_free + A⁻¹ Jᵀ λ per block, then v and positions updated.
 J's tissue and tool parts of a row: rows.c; a row between two tools (a
 * nested tool held by its host) has a part in each tool's block, so its
 * W_ii sums both beams' compliances and its λ corrects both. Without tools and rows this
 * is nh_step_dynamic (which may carry hanging-node rows instead).
 *
 * Quasi-static (in->quasi_static): the same four steps are one Newton
 * iteration of the equilibrium f_int(x) = f_ext + Jᵀλ with the rows' laws
 * on the positions: A = K (no mass, no damping; the tools' options say
 * so too), b = f_ext − f_int, τ = in->dt = 1 so the rows' "rates" are
 * w = J δ + g (the new gaps, to first order) and λ are forces, not
 * impulses; u ← u + δ. With in->consistent_tangent the tissue's A is the
 * consistent tangent's symmetric part S (nh_system_factor_symmetric falls
 * back to R K₀ Rᵀ where S is indefinite; docs/theory.md §3 "With tools").
 * The contact module calls it until the residual vanishes
 * (docs/interaction.md, "Quasi-static mode").
 *
 * With in->reuse (solver.refactor: auto) the tissue block may keep an
 * earlier factorisation (reuse.c decides): its solves are then PCG with that
 * factor as preconditioner, W's tissue part is the old factor's W₀, and
 * steps 1-4 for the tissue become the outer correction of
 * nh_corrected_step, exact at its fixed point (docs/performance.md).
 *
 * nh_step_coupled reads as its phases (docs/design.md, "One step"), on the
 * step's work (nh_step_work): assemble (nh_step_assemble, step.c),
 * factorise or reuse (nh_system_factor_or_reuse, reuse.c), the free solve of
 * every block (nh_coupled_free_solve), and with rows the constraint phases
 * (nh_coupled_constraints): the compliance W (nh_coupled_compliance), the
 * tools' free rates (nh_coupled_tool_rates), with a reused factor the
 * corrections (nh_coupled_reused), with the current one the constraint solve
 * (nh_coupled_constraint_solve) and the tissue's correction
 * (nh_coupled_correction), then the tools' corrections; last the update
 * (nh_coupled_update) and the residual (nh_coupled_residual). Each phase
 * keeps the time it measured before: steps.csv's t_* columns are the same
 * intervals. */
#include "solve/system_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Per-tool work of one step. */
typedef struct {
  nh_beam_system *sys; /* the tool's own (nh_beam_step_system), borrowed */
  int mfree;           /* free DOFs of the tool */
  double *dv;          /* mfree: the free update, then the corrected one */
  int *rows;           /* the rows touching this tool */
  int *side;           /* the side of each (nh_row_tool_coef: 1 for a row's second tool) */
  int nrows;
  double *X;    /* mfree x nrows, column-major: A_k⁻¹ J_kᵀ */
  double *vnew; /* all DOFs: end-of-step velocity (base prescribed) */
} nh_tool_work;

/* The work of one coupled step: its problem, what its phases hand on, and
 * its statistics. */
typedef struct {
  nh_system *s;
  const nh_integrator *in;
  const double *f_ext;
  double *u, *v;
  int n_tools;
  nh_coupled_tool *tools;
  nh_rows *rows;
  double tolerance, accept; /* the constraint solve's (nh_constraint_solve) */
  int max_iterations;
  int m;       /* rows (0: none, rows may be NULL) */
  int statics; /* in->quasi_static: a Newton iteration */
  /* the tissue: b, the right-hand side over the unknowns; dv, its update
   * (x_free, then corrected); full, 3 per node (work[3]) */
  double *b, *dv, *full;
  double b_norm, f_scale; /* quasi-static: the residual's parts */
  nh_tool_work *tw;       /* n_tools */
  /* with rows: J_tᵀ, W = W_t + W_tools (m x m each), the free rates r and
   * their part r_tools (the tools' rates and g/h), and scratch */
  cholmod_sparse *Jt;
  double *W, *Wt, *Wtools;
  double *r, *r_tools;
  double *col; /* 2 n_free */
  int *mark;   /* n_free */
  nh_coupled_stats st;
} nh_step_work;

static void nh_tool_work_free(nh_tool_work *w) {
  free(w->dv), free(w->rows), free(w->side), free(w->X), free(w->vnew);
}

static int nh_finite(const double *a, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(a[i])) return 0;
  return 1;
}

/* The step's work: W and its parts, the rates, the tools' blocks. */
static int nh_step_work_alloc(nh_step_work *w) {
  const int m = w->m, nf = w->s->n_free;
  w->tw = nh_calloc((size_t)(w->n_tools > 0 ? w->n_tools : 1), sizeof *w->tw);
  if (!w->tw) return NH_ERR_MEMORY;
  if (m) {
    w->W = nh_calloc(3 * (size_t)m * m, sizeof(double));
    w->r = nh_calloc(2 * (size_t)m, sizeof(double));
    w->col = nh_calloc(2 * (size_t)nf, sizeof(double));
    w->mark = nh_calloc((size_t)nf, sizeof(int));
    if (!w->W || !w->r || !w->col || !w->mark) return NH_ERR_MEMORY;
    w->Wt = w->W + (size_t)m * m, w->Wtools = w->W + 2 * (size_t)m * m;
    w->r_tools = w->r + m;
    for (int i = 0; i < nf; i++) w->mark[i] = -1;
  }
  for (int k = 0; k < w->n_tools; k++) {
    nh_tool_work *t = &w->tw[k];
    t->mfree = nh_beam_dofs(w->tools[k].beam) - 6;
    t->dv = nh_calloc((size_t)t->mfree, sizeof(double));
    t->vnew = nh_calloc((size_t)t->mfree + 6, sizeof(double));
    t->rows = nh_calloc((size_t)(m > 0 ? m : 1), sizeof(int));
    t->side = nh_calloc((size_t)(m > 0 ? m : 1), sizeof(int));
    if (!t->dv || !t->vnew || !t->rows || !t->side) return NH_ERR_MEMORY;
    NH_TRY(nh_beam_step_system(w->tools[k].beam, &t->sys));
  }
  return NH_OK;
}

static void nh_step_work_free(nh_step_work *w) {
  cholmod_free_sparse(&w->Jt, &w->s->cm);
  for (int k = 0; w->tw && k < w->n_tools; k++) nh_tool_work_free(&w->tw[k]);
  free(w->tw), free(w->W), free(w->r), free(w->col), free(w->mark);
}

/* nh_mcp_solve with the acceptance of a stalled solve (see nh_step_coupled). */
static int nh_constraint_solve(nh_step_work *w, const double *r) {
  nh_mcp_stats *st = &w->st.mcp;
  /* quasi-static: the tools' full tangents make W = J A⁻¹ Jᵀ unsymmetric */
  int rc = (w->statics ? nh_mcp_solve_unsymmetric : nh_mcp_solve)(
      w->m, w->W, r, w->rows->law, w->tolerance, w->max_iterations, w->rows->lambda, st);
  /* Projected Gauss-Seidel can stall short of a tight tolerance on nearly
   * dependent friction rows (a stiff needle's shaft points share the
   * axial load in many ways): its best iterate is accepted up to
   * `accept` and its residual reported (steps.csv). */
  if (rc == NH_ERR_NUMERIC && isfinite(st->residual) && st->residual <= w->accept) {
    nh_error_clear();
    rc = NH_OK;
  }
  return rc;
}

/* Free solve: x_free = A⁻¹ b for the tissue (with a reused factor and rows,
 * its solve waits for the corrections: nh_corrected_step) and each tool's
 * block, factorised here (dense). */
static int nh_coupled_free_solve(nh_step_work *w) {
  nh_system *s = w->s;
  nh_step_stats *st = &w->st.step;
  double t2 = nh_time_now();
  if (s->n_rows > 0 || w->m == 0 || s->factor_current)
    NH_TRY(nh_step_free_solve(s, w->in, w->b, w->dv, st));
  st->t_constraints = s->t_constraints;
  st->t_solve = nh_time_now() - t2 - s->t_constraints;
  for (int k = 0; k < w->n_tools; k++) {
    nh_tool_work *t = &w->tw[k];
    nh_coupled_tool *tool = &w->tools[k];
    double t3 = nh_time_now();
    int rc = nh_beam_dynamic_prepare(tool->beam, &tool->options, tool->f_ext, tool->base_velocity,
                                     t->sys, t->dv);
    double t4 = nh_time_now();
    st->t_factor += t4 - t3;
    if (rc) return rc;
    nh_beam_system_solve(t->sys, t->dv);
    st->t_solve += nh_time_now() - t4;
  }
  return NH_OK;
}

/* The rows' key for a kept W₀ (nh_tissue_compliance): m + 1 starts, the
 * tissue nodes, and each row's tool, element, second tool and element;
 * *len its length. NULL without memory. */
static int *nh_rows_key(const nh_rows *rows, int *len) {
  const int m = rows->m, slots = rows->start[m];
  *len = m + 1 + slots + 4 * m;
  int *key = nh_calloc((size_t)*len, sizeof(int));
  if (!key) return NULL;
  memcpy(key, rows->start, sizeof(int) * (size_t)(m + 1));
  memcpy(key + m + 1, rows->node, sizeof(int) * (size_t)slots);
  for (int i = 0; i < m; i++) {
    int *k = key + m + 1 + slots + 4 * i;
    k[0] = rows->tool[i], k[1] = rows->elem[i];
    k[2] = rows->tool2 ? rows->tool2[i] : -1, k[3] = rows->elem2 ? rows->elem2[i] : -1;
  }
  return key;
}

/* The tissue part of W, W_t = J_t A⁻¹ J_tᵀ with the factor (current or
 * reused), and the sum W = W_t + W_tools for the constraint solve. With a
 * reused factor W_t only linearises the outer corrections, whose fixed point
 * does not depend on it (nh_corrected_step): a W_t built with the same
 * factor for rows on the same tissue nodes and tool elements (their
 * directions and weights moved by a step) serves, and is taken again. */
static int nh_tissue_compliance(nh_step_work *w) {
  nh_system *s = w->s;
  const int m = w->m;
  const size_t mm = (size_t)m * m;
  int len = 0, *key = s->L ? nh_rows_key(w->rows, &len) : NULL;
  const int same = key && !s->factor_current && s->w0_serial == s->factor_serial && s->w0_m == m &&
                   s->w0_slots == len && !memcmp(key, s->w0_key, sizeof(int) * len);
  w->st.w_kept = same;
  if (same) {
    memcpy(w->Wt, s->w0, sizeof(double) * mm);
    free(key);
  } else {
    memset(w->Wt, 0, sizeof(double) * mm);
    int rc = nh_system_compliance_add(s, w->Jt, w->Wt);
    s->w0_serial = 0;
    free(s->w0), s->w0 = NULL;
    free(s->w0_key), s->w0_key = key;
    if (rc) return rc;
    if (key && (s->w0 = nh_calloc(mm ? mm : 1, sizeof(double)))) {
      memcpy(s->w0, w->Wt, sizeof(double) * mm);
      s->w0_m = m, s->w0_slots = len, s->w0_serial = s->factor_serial;
    }
  }
  for (size_t k = 0; k < mm; k++) w->W[k] = w->Wt[k] + w->Wtools[k];
  return NH_OK;
}

/* One tool's part of W, W_ij += J_i (A_k⁻¹ J_jᵀ), by one dense solve of its
 * |rows_k| columns (kept in X for the correction). */
static int nh_tool_compliance(nh_step_work *w, nh_tool_work *t) {
  const nh_rows *rows = w->rows;
  const int m = w->m;
  t->X = nh_calloc((size_t)t->mfree * t->nrows, sizeof(double));
  if (!t->X) return NH_ERR_MEMORY;
  for (int a = 0; a < t->nrows; a++)
    nh_row_tool_column(rows, t->rows[a], t->side[a], t->X + (size_t)a * t->mfree);
  nh_beam_system_solve_many(t->sys, t->nrows, t->X);
  for (int a = 0; a < t->nrows; a++) {
    const int i = t->rows[a], d0 = 6 * nh_row_elem(rows, i, t->side[a]) - 6;
    double coef[12];
    nh_row_tool_coef(rows, i, t->side[a], coef);
    for (int c = 0; c < t->nrows; c++) {
      const double *x = t->X + (size_t)c * t->mfree;
      double sum = 0.0;
      for (int q = d0 < 0 ? -d0 : 0; q < 12; q++) sum += coef[q] * x[d0 + q];
      w->Wtools[(size_t)t->rows[c] * m + i] += sum;
    }
  }
  return NH_OK;
}

/* Constraint rows → compliance: J_tᵀ, each row to its tool, the tools'
 * parts of W (exact, dense), then the tissue's (from the factor, current or
 * reused). */
static int nh_coupled_compliance(nh_step_work *w) {
  const nh_rows *rows = w->rows;
  if (!(w->Jt = nh_rows_tissue_jt(w->s, rows, w->mark)))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint rows (%d)", w->m);
  for (int i = 0; i < w->m; i++)
    for (int side = 0; side < 2; side++) { /* a row's tool, then its second tool (if any) */
      const int k = side ? rows->tool2[i] : rows->tool[i], e = nh_row_elem(rows, i, side);
      if (k < 0) continue;
      NH_CHECK(k < w->n_tools && e >= 0 && e < nh_beam_elements(w->tools[k].beam), NH_ERR_INTERNAL,
               "constraint row %d: tool %d element %d out of range", i, k, e);
      NH_CHECK(side == 0 || k != rows->tool[i], NH_ERR_INTERNAL,
               "constraint row %d: both its tool parts on tool %d", i, k);
      nh_tool_work *t = &w->tw[k];
      t->rows[t->nrows] = i, t->side[t->nrows++] = side;
    }
  for (int k = 0; k < w->n_tools; k++)
    if (w->tw[k].nrows) NH_TRY(nh_tool_compliance(w, &w->tw[k]));
  return nh_tissue_compliance(w);
}

/* The tools' free rates and g/h: r_tools = J_tools v_free + g/h. */
static void nh_coupled_tool_rates(nh_step_work *w) {
  const nh_rows *rows = w->rows;
  for (int i = 0; i < w->m; i++) w->r_tools[i] = rows->gap[i] / w->in->dt;
  for (int k = 0; k < w->n_tools; k++) {
    nh_tool_work *t = &w->tw[k];
    if (!t->nrows) continue;
    const double *vb = nh_beam_velocities(w->tools[k].beam);
    memcpy(t->vnew, w->tools[k].base_velocity, 6 * sizeof(double));
    for (int q = 0; q < t->mfree; q++) t->vnew[6 + q] = vb[6 + q] + t->dv[q];
    for (int a = 0; a < t->nrows; a++)
      w->r_tools[t->rows[a]] += nh_row_tool_rate(rows, t->rows[a], t->side[a], t->vnew);
  }
}

/* The tissue's update and the constraint forces with a reused factor (L of
 * an earlier A₀, M = A₀ as preconditioner), exact at convergence.
 * W₀ = J_t A₀⁻¹ J_tᵀ + W_tools is the compliance the factor gives; the true
 * W differs in its tissue part. Each correction k solves, by PCG, the
 * tissue's whole update for the current forces,
 *   dv_k = A⁻¹ (b + J_tᵀ λ_k),
 * and linearises the rates about it with the factor's compliance:
 *   w(λ) ≈ J_t (v + dv_k) + W₀,t (λ − λ_k) + [tools' rates, exact] + g/h,
 *   λ_{k+1} = MCP(W₀, r_k),  r_k = J_t (v + dv_k) − W₀,t λ_k + r_tools.
 * The fixed point is the exact problem: there J_t dv = J_t A⁻¹ b + W_t λ, so
 * w = W λ + r. The map contracts at the rate ‖W₀⁻¹ (W − W₀)‖, the size of
 * A's change since A₀. Stop when max|λ_{k+1} − λ_k| <= tol · max|λ|: the
 * law then holds for rates off by at most ‖W − W₀‖ · tol · max|λ|. The
 * update is dv_k + M⁻¹ J_tᵀ (λ_{k+1} − λ_k) (the last increment, a fraction
 * tol of the whole, needs no more than the preconditioner), which is also
 * the start of the next correction's PCG. One correction (the usual case)
 * costs one PCG solve and one preconditioner solve: a solve fewer than the
 * free solve plus correction of a current factor would take with PCG.
 * Returns NH_OK with *converged = 1, or NH_OK with *converged = 0 (not
 * converged in NH_OUTER_MAX corrections, or a PCG or constraint solve failed
 * numerically: the caller factorises and solves exactly), or another error
 * code (memory). Scratch: w->col (2 n_free), w->full. */
static int nh_corrected_step(nh_step_work *w, int *converged) {
  nh_system *s = w->s;
  nh_rows *rows = w->rows;
  nh_coupled_stats *st = &w->st;
  const int nf = s->n_free, m = w->m;
  double *bk = w->col, *col = w->col + nf, *dv = w->dv;
  double *e = nh_calloc(3 * (size_t)m, sizeof(double));
  if (!e) return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint corrections (%d rows)", m);
  double *rk = e, *prev = e + m, *dl = e + 2 * m;
  int rc = NH_OK;
  *converged = 0;
  for (int k = 0; k < NH_OUTER_MAX; k++) {
    nh_rows_tissue_force(w->Jt, rows->lambda, bk, nf);
    for (int i = 0; i < nf; i++) bk[i] += w->b[i];
    int its = 0, prc = nh_system_pcg(s, bk, dv, k > 0, w->in->tolerance, NH_PCG_MAX, &its);
    st->step.pcg_iterations += its;
    if (prc) {
      if (prc == NH_ERR_NUMERIC) nh_error_clear(), prc = NH_OK; /* the exact path decides */
      rc = prc;
      break;
    }
    nh_rows_tissue_rates(s, rows, w->v, dv, w->r_tools, w->full, rk);
    for (int i = 0; i < m; i++) {
      double w0 = 0.0;
      for (int j = 0; j < m; j++) w0 += w->Wt[(size_t)j * m + i] * rows->lambda[j];
      rk[i] -= w0;
    }
    memcpy(prev, rows->lambda, sizeof(double) * (size_t)m);
    st->step.corrections = k + 1;
    rc = nh_constraint_solve(w, rk);
    if (k > 0) { /* the exact path makes one constraint solve: the others are reuse's */
      st->step.correction_flops += st->mcp.flops;
      st->step.correction_flops_dense += st->mcp.flops_dense;
    }
    if (rc) {
      /* not converged with W₀: the exact path decides (and reports) */
      if (rc == NH_ERR_NUMERIC) nh_error_clear(), rc = NH_OK;
      break;
    }
    double delta = 0.0, scale = 0.0;
    for (int i = 0; i < m; i++) {
      dl[i] = rows->lambda[i] - prev[i];
      delta = fmax(delta, fabs(dl[i]));
      scale = fmax(scale, fabs(rows->lambda[i]));
    }
    nh_rows_tissue_force(w->Jt, dl, col, nf);
    if ((rc = nh_system_solve(s, col, bk))) break;
    for (int i = 0; i < nf; i++) dv[i] += bk[i];
    if (delta <= w->in->tolerance * scale) {
      *converged = 1;
      break;
    }
  }
  free(e);
  return rc;
}

/* With a reused factor: λ and the tissue's update by the corrections; if
 * they do not serve, a factorisation (reuse.c's fallback), the free solve
 * and W from it, and the exact path follows. *tc0 moves by the
 * factorisation's time (not a constraint cost). */
static int nh_coupled_reused(nh_step_work *w, double *tc0) {
  int converged = 0, rc = nh_corrected_step(w, &converged);
  if (rc || converged) return rc;
  double tf = nh_time_now();
  NH_TRY(nh_system_factor(w->s));
  double tf1 = nh_time_now();
  NH_TRY(nh_system_solve(w->s, w->b, w->dv));
  w->st.step.t_factor += tf1 - tf;
  w->st.step.t_factor_reference = tf1 - tf;
  *tc0 += tf1 - tf;
  return nh_tissue_compliance(w);
}

/* Constraint solve with the current factor: the free rates
 * r = J v_free + g/h, λ from w = W λ + r and the rows' laws. */
static int nh_coupled_constraint_solve(nh_step_work *w) {
  nh_rows_tissue_rates(w->s, w->rows, w->v, w->dv, w->r_tools, w->full, w->r);
  return nh_constraint_solve(w, w->r);
}

/* Correction of the tissue: dv += A⁻¹ J_tᵀ λ (quasi-static: the
 * equilibrium residual with this iteration's forces measured first). */
static int nh_coupled_correction(nh_step_work *w) {
  const int nf = w->s->n_free;
  double *b = w->b, *col = w->col;
  nh_rows_tissue_force(w->Jt, w->rows->lambda, col, nf);
  if (w->statics) {
    double r2 = 0.0, j2 = 0.0;
    for (int i = 0; i < nf; i++) r2 += (b[i] + col[i]) * (b[i] + col[i]), j2 += col[i] * col[i];
    w->b_norm = sqrt(r2), w->f_scale = fmax(w->f_scale, sqrt(j2));
  }
  NH_TRY(nh_system_solve(w->s, col, b));
  for (int i = 0; i < nf; i++) w->dv[i] += b[i];
  return NH_OK;
}

/* The constraint phases: rows → W, λ, the corrections of every block. */
static int nh_coupled_constraints(nh_step_work *w) {
  nh_coupled_stats *st = &w->st;
  double tc0 = nh_time_now();
  NH_TRY(nh_coupled_compliance(w));
  double tc1 = nh_time_now();
  st->t_compliance = tc1 - tc0;
  nh_coupled_tool_rates(w);
  int rc = w->s->factor_current ? NH_OK : nh_coupled_reused(w, &tc0);
  double tc2 = nh_time_now();
  if (rc || !w->s->factor_current) {
    st->t_mcp = tc2 - tc1; /* the corrections: PCG and constraint solves */
    NH_TRY(rc);
  } else {
    rc = nh_coupled_constraint_solve(w);
    st->t_mcp = nh_time_now() - tc2;
    NH_TRY(rc);
    NH_TRY(nh_coupled_correction(w));
  }
  for (int k = 0; k < w->n_tools; k++) { /* the tools' corrections A_k⁻¹ J_kᵀ λ */
    nh_tool_work *t = &w->tw[k];
    for (int a = 0; a < t->nrows; a++) {
      const double *x = t->X + (size_t)a * t->mfree, lam = w->rows->lambda[t->rows[a]];
      for (int q = 0; q < t->mfree; q++) t->dv[q] += lam * x[q];
    }
  }
  st->step.t_constraints = nh_time_now() - tc0;
  return NH_OK;
}

/* Update the tissue (nh_step_update); the tools finish after the step's
 * Newton iterations (nh_coupled_finish), which change their λ. */
static int nh_coupled_update(nh_step_work *w) {
  const int nf = w->s->n_free;
  double t6 = nh_time_now();
  if (!nh_finite(w->dv, nf))
    return NH_ERROR(NH_ERR_NUMERIC, "the tissue's velocity update is not finite");
  if (w->statics && w->m == 0) { /* (with rows: measured before the correction) */
    for (int i = 0; i < nf; i++) w->b_norm += w->b[i] * w->b[i];
    w->b_norm = sqrt(w->b_norm);
  }
  nh_step_update(w->s, w->statics, w->in->dt, w->dv, w->u, w->v);
  w->st.step.t_solve += nh_time_now() - t6;
  w->st.step.iterations = 1;
  return NH_OK;
}

/* The tools' update with the step's final λ (nh_beam_dynamic_finish). */
static int nh_coupled_finish(nh_step_work *w) {
  double t0 = nh_time_now();
  for (int k = 0; k < w->n_tools; k++)
    NH_TRY(nh_beam_dynamic_finish(w->tools[k].beam, w->in->dt, w->tools[k].base_velocity,
                                  w->tw[k].dv));
  w->st.step.t_solve += nh_time_now() - t0;
  return NH_OK;
}

/* Residual: quasi-static, the equilibrium residual at the iteration's
 * start; dynamic, after the renewal rule's account, that of the one
 * linearisation (nh_dynamic_residual: full holds the update, col the rows'
 * reaction J_tᵀ λ, which the corrected path left as an increment). */
static void nh_coupled_residual(nh_step_work *w) {
  nh_step_stats *st = &w->st.step;
  if (w->statics) {
    st->residual = w->b_norm / fmax(w->f_scale, 1e-300);
    return;
  }
  double t7 = nh_time_now();
  if (w->in->reuse) nh_system_account(w->s, st);
  if (w->m) nh_rows_tissue_force(w->Jt, w->rows->lambda, w->col, w->s->n_free);
  st->residual =
      nh_dynamic_residual(w->s, w->in, w->f_ext, w->u, w->v, w->full, w->m ? w->col : NULL, w->b);
  st->residual_floor = nh_system_residual_floor(w->s);
  st->residual_dof = w->s->residual_dof;
  st->t_assemble += nh_time_now() - t7;
}

/* The Newton iterations' trigger, target and count (docs/theory.md §3,
 * "Newton iterations in the dynamic step"): with solver.newton, while the
 * residual exceeds its tolerance, at most its count; without, only a step
 * whose one linearisation leaves it above NH_UNSOLVED_LINEAR (and above its
 * round-off level) iterates, towards the same tolerance, at most
 * NH_DYNAMIC_NEWTON_MAX times. */
static int nh_newton_wanted(const nh_integrator *in, const nh_step_stats *st, int it, int *rescue) {
  if (in->newton_iterations >= 0)
    return it < in->newton_iterations && !(st->residual <= in->newton_tolerance);
  if (it == 0) *rescue = st->residual > fmax(NH_UNSOLVED_LINEAR, st->residual_floor);
  return *rescue && it < NH_DYNAMIC_NEWTON_MAX &&
         st->residual > fmax(in->newton_tolerance, st->residual_floor);
}

/* Newton iterations on the step's implicit-Euler equations with the step's
 * rows (dynamic; see nh_step_coupled). The first pass left u_k, v_k, the
 * residual R_k = h (f_ext − f_int(u_k) − C v_k) − M Δv_k + J_tᵀ λ_k in b and
 * A(u_k) assembled; each iteration solves the linearised equations
 *   A_k δ = (R_k − J_tᵀ λ_k) + J_tᵀ λ,   λ from w = W_k λ + r_k and the laws,
 * W_k = J_t A_k⁻¹ J_tᵀ + W_tools, r_k = J_t (v_k + δ_free) + r_tools: the
 * coupled step's phases again with A_k, the rows, their gaps and the tools'
 * blocks unchanged (the rows are linear in the velocities and the tools'
 * blocks are linearised once per step; their update moves by
 * A_j⁻¹ J_jᵀ (λ − λ_k)). Once the residual is below NH_NEWTON_CONSISTENT
 * A_k is the step's exact Jacobian (1 + hα) M + (hβ + h²) K_corot + h² (K −
 * K_corot) + h²β ∂(K_corot v)/∂u (nh_system_set_jacobian), solved by LU
 * without rows (Newton's quadratic rate), and its symmetric part without
 * the last term with rows (Cholesky; the corotational tangent where that is
 * indefinite: nh_system_factor_symmetric); the residual is always that of
 * the step's equations (corotational K in
 * the damping). Hanging-node rows carry their multipliers' increments
 * (nh_system_solve_constrained). */
static int nh_coupled_newton(nh_step_work *w) {
  nh_system *s = w->s;
  const nh_integrator *in = w->in;
  nh_step_stats *st = &w->st.step;
  const int n = 3 * s->n_nodes, nf = s->n_free, m = w->m;
  int rescue = 0, it;
  if (!nh_newton_wanted(in, st, 0, &rescue)) return NH_OK;
  double *dvt = nh_calloc((size_t)n + (size_t)m, sizeof(double)), *lam0 = dvt + n;
  if (!dvt) return NH_ERROR(NH_ERR_MEMORY, "out of memory: Newton iterations of the step");
  memcpy(dvt, w->full, sizeof(double) * (size_t)n); /* Δv so far (w->full: the rates' scratch) */
  const double cM = 1.0 + in->dt * in->alpha, cK = in->dt * in->beta + in->dt * in->dt;
  int rc = NH_OK;
  for (it = 0; !rc && nh_newton_wanted(in, st, it, &rescue); it++) {
    if (nh_stop_requested()) break; /* the step stands as it is (u, v consistent) */
    double t0 = nh_time_now();
    if (m)
      for (int i = 0; i < nf; i++) w->b[i] -= w->col[i]; /* R_k − J_tᵀ λ_k */
    /* Below NH_NEWTON_CONSISTENT the step's exact Jacobian: without rows
     * all of it by LU; with rows (W needs the Cholesky factor) the
     * symmetric part of the tangent's, without the damping's variation
     * (its symmetric part alone slowed the iteration: docs/theory.md §3) */
    const int exact = st->residual <= NH_NEWTON_CONSISTENT;
    const int lu = exact && m == 0 && s->n_rows == 0;
    if (exact) {
      const double h2 = in->dt * in->dt;
      nh_system_set_tangent(s, NH_TANGENT_CONSISTENT);
      nh_system_set_jacobian(s, h2, lu ? h2 * in->beta : 0.0, w->v);
      if (lu && (rc = nh_system_keep_skew(s))) break;
      nh_system_assemble(s, w->u, NULL, cM, cK, s->work[0], NULL, in->threads);
      nh_system_set_jacobian(s, 0.0, 0.0, NULL);
    }
    double t1 = nh_time_now();
    st->t_assemble += t1 - t0;
    if (lu) {
      double tf = 0.0;
      rc = nh_system_solve_lu(s, w->b, w->dv, &tf);
      st->t_factor += tf;
      st->factorised++;
      if (rc) break;
    } else {
      if ((rc = nh_system_factor_symmetric(s, in, w->u, NH_FACTOR_NEWTON, st))) break;
      double t2 = nh_time_now();
      if ((rc = nh_step_free_solve(s, in, w->b, w->dv, st))) break;
      st->t_solve += nh_time_now() - t2;
    }
    if (m) {
      double tc = nh_time_now();
      memcpy(lam0, w->rows->lambda, sizeof(double) * (size_t)m);
      if ((rc = nh_tissue_compliance(w)) || (rc = nh_coupled_constraint_solve(w)) ||
          (rc = nh_coupled_correction(w)))
        break;
      for (int i = 0; i < m; i++) lam0[i] = w->rows->lambda[i] - lam0[i];
      for (int k = 0; k < w->n_tools; k++) { /* A_j⁻¹ J_jᵀ (λ − λ_k) */
        nh_tool_work *t = &w->tw[k];
        for (int a = 0; a < t->nrows; a++) {
          const double *x = t->X + (size_t)a * t->mfree, dl = lam0[t->rows[a]];
          for (int q = 0; q < t->mfree; q++) t->dv[q] += dl * x[q];
        }
      }
      st->t_constraints += nh_time_now() - tc;
    }
    if (!nh_finite(w->dv, nf)) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "the tissue's Newton correction is not finite");
      break;
    }
    double t3 = nh_time_now();
    double *delta = s->work[0];
    nh_system_scatter(s, w->dv, delta);
    for (int i = 0; i < n; i++) {
      w->v[i] += delta[i];
      w->u[i] += in->dt * delta[i];
      dvt[i] += delta[i];
    }
    nh_system_tangent_restore(s, in, w->f_ext, w->u, 0, st); /* corotational, skew dropped */
    if (m) nh_rows_tissue_force(w->Jt, w->rows->lambda, w->col, nf);
    st->residual = nh_dynamic_residual(s, in, w->f_ext, w->u, w->v, dvt, m ? w->col : NULL, w->b);
    st->residual_floor = nh_system_residual_floor(s);
    st->residual_dof = s->residual_dof;
    st->t_assemble += nh_time_now() - t3;
    st->iterations++;
  }
  nh_system_set_jacobian(s, 0.0, 0.0, NULL);
  nh_system_tangent_restore(s, in, w->f_ext, w->u, 0, st);
  memcpy(w->full, dvt, sizeof(double) * (size_t)n); /* the step's nodal update, as documented */
  free(dvt);
  return rc;
}

int nh_step_coupled(nh_system *s, const nh_integrator *in, const double *f_ext, double *u,
                    double *v, int n_tools, nh_coupled_tool *tools, nh_rows *rows, double tolerance,
                    double accept, int max_iterations, nh_coupled_stats *stats) {
  nh_step_work w = {.s = s,
                    .in = in,
                    .f_ext = f_ext,
                    .u = u,
                    .v = v,
                    .n_tools = n_tools,
                    .tools = tools,
                    .rows = rows,
                    .tolerance = tolerance,
                    .accept = accept,
                    .max_iterations = max_iterations,
                    .m = rows ? rows->m : 0,
                    .statics = in->quasi_static,
                    .b = s->fwork[0],
                    .dv = s->fwork[1],
                    .full = s->work[3]};
  NH_CHECK(s->n_rows == 0 || w.m == 0, NH_ERR_INTERNAL,
           "coupled step: hanging-node rows and tool rows cannot be combined");
  int rc = nh_step_work_alloc(&w);
  double t0 = nh_time_now();
  if (w.statics) /* the tissue's tangent of this iteration: S or R K₀ Rᵀ (docs/theory.md §3) */
    nh_system_set_tangent(s,
                          in->consistent_tangent ? NH_TANGENT_CONSISTENT : NH_TANGENT_COROTATIONAL);
  if (!rc) {
    nh_step_begin(s, in);
    nh_step_assemble(s, in, w.statics, f_ext, u, v, w.b, &w.f_scale);
    w.st.step.t_assemble = nh_time_now() - t0;
    rc = nh_stop_check(); /* an assembly cut short */
  }
  w.st.supports.mode = -1;
  if (!rc && w.statics && in->measure_supports && w.m == 0) /* before A is factorised */
    w.st.supports = nh_system_rigid(s, u, w.b);
  s->rows_hint = w.m; /* what an inherited factor's W₀ would cost (reuse.c) */
  if (!rc) rc = nh_system_factor_symmetric(s, in, u, NH_FACTOR_STEP, &w.st.step);
  if (!rc) rc = nh_coupled_free_solve(&w);
  if (!rc && w.m > 0) rc = nh_coupled_constraints(&w);
  if (!rc) rc = nh_coupled_update(&w);
  if (!rc) nh_coupled_residual(&w);
  w.st.step.factorised = s->factor_age == 0;
  if (!rc && !w.statics) rc = nh_coupled_newton(&w);
  if (!rc) rc = nh_coupled_finish(&w);
  w.st.step.tangent_updates = nh_system_lazy_updates(s);
  if (stats) *stats = w.st;
  nh_step_work_free(&w);
  return rc;
}
