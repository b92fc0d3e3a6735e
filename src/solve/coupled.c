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
 * J's tissue part of a row is n · N_a on the three DOFs of each node a of
 * the point's cell, restricted to the unknowns by Pᵀ (hanging masters,
 * fixed nodes dropped); its tool part is −n · J_beam on the element's 12
 * DOFs, the base node's dropped (prescribed). Without tools and rows this
 * is nh_step_dynamic (which may carry hanging-node rows instead).
 *
 * Quasi-static (in->quasi_static): the same four steps are one Newton
 * iteration of the equilibrium f_int(x) = f_ext + Jᵀλ with the rows' laws
 * on the positions: A = K (no mass, no damping; the tools' options say
 * so too), b = f_ext − f_int, τ = in->dt = 1 so the rows' "rates" are
 * w = J δ + g (the new gaps, to first order) and λ are forces, not
 * impulses; u ← u + δ. The contact module calls it until the residual
 * vanishes (docs/interaction.md, "Quasi-static mode").
 *
 * With in->reuse (solver.refactor: auto) the tissue block may keep an
 * earlier factorisation (reuse.c decides): its solves are then PCG with that
 * factor as preconditioner, W's tissue part is the old factor's W₀, and
 * steps 1-4 for the tissue become the outer correction of
 * nh_corrected_step, exact at its fixed point (docs/performance.md). */
#include "solve/system_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

void nh_rows_clear(nh_rows *r) {
  r->m = 0;
}

void nh_rows_free(nh_rows *r) {
  free(r->node), free(r->N), free(r->dir), free(r->tool), free(r->elem), free(r->J);
  free(r->gap), free(r->law), free(r->lambda);
  memset(r, 0, sizeof *r);
}

#define NH_GROW(ptr, count)                                                                        \
  do {                                                                                             \
    void *q_ = realloc((ptr), sizeof *(ptr) * (size_t)(count));                                    \
    if (!q_) return -1;                                                                            \
    (ptr) = q_;                                                                                    \
  } while (0)

int nh_rows_add(nh_rows *r) {
  if (r->m == r->cap) {
    int cap = r->cap ? 2 * r->cap : 32;
    NH_GROW(r->node, 8 * cap);
    NH_GROW(r->N, 8 * cap);
    NH_GROW(r->dir, 3 * cap);
    NH_GROW(r->tool, cap);
    NH_GROW(r->elem, cap);
    NH_GROW(r->J, 36 * cap);
    NH_GROW(r->gap, cap);
    NH_GROW(r->law, cap);
    NH_GROW(r->lambda, cap);
    r->cap = cap;
  }
  int i = r->m++;
  for (int a = 0; a < 8; a++) r->node[8 * i + a] = -1, r->N[8 * i + a] = 0.0;
  memset(r->dir + 3 * i, 0, 3 * sizeof(double));
  r->tool[i] = -1, r->elem[i] = 0;
  memset(r->J + 36 * i, 0, 36 * sizeof(double));
  r->gap[i] = 0.0, r->lambda[i] = 0.0;
  r->law[i] = (nh_row_law){NH_ROW_BILATERAL, -1, -1, 0.0, 0.0, -1, 0.0, 0};
  return i;
}

/* Row i's tool part as 12 coefficients on the element's DOFs: −nᵀ J. */
static void nh_row_tool_coef(const nh_rows *r, int i, double c[12]) {
  const double *n = r->dir + 3 * i, *J = r->J + 36 * i;
  for (int j = 0; j < 12; j++) c[j] = -(n[0] * J[j] + n[1] * J[12 + j] + n[2] * J[24 + j]);
}

/* The tissue part of the rows as Jᵀ over the unknowns (CSC, n_free x m);
 * mark: n_free ints, all −1 on entry (positions of the current column). */
static cholmod_sparse *nh_rows_tissue_jt(nh_system *s, const nh_rows *r, int *mark) {
  const int m = r->m, n = s->n_free;
  size_t nnz = 0;
  for (int i = 0; i < m; i++)
    for (int a = 0; a < 8; a++) {
      int v = r->node[8 * i + a];
      if (v >= 0) nnz += 3 * (size_t)(s->exp_start[v + 1] - s->exp_start[v]);
    }
  cholmod_sparse *Jt =
      cholmod_allocate_sparse((size_t)n, (size_t)m, nnz ? nnz : 1, 1, 1, 0, CHOLMOD_REAL, &s->cm);
  if (!Jt) return NULL;
  int *Jp = Jt->p, *Ji = Jt->i, pos = 0;
  double *Jx = Jt->x;
  for (int i = 0; i < m; i++) {
    const int start = Jp[i] = pos;
    for (int a = 0; a < 8; a++) {
      int v = r->node[8 * i + a];
      if (v < 0) continue;
      for (int q = s->exp_start[v]; q < s->exp_start[v + 1]; q++) {
        const int *f = s->free_of + 3 * s->exp_node[q];
        for (int k = 0; k < 3; k++) {
          double c = s->exp_w[q] * r->N[8 * i + a] * r->dir[3 * i + k];
          if (c == 0.0 || f[k] < 0) continue;
          if (mark[f[k]] < start) mark[f[k]] = pos, Ji[pos] = f[k], Jx[pos++] = 0.0;
          Jx[mark[f[k]]] += c;
        }
      }
    }
  }
  Jp[m] = pos;
  for (int p = 0; p < pos; p++) mark[Ji[p]] = -1;
  cholmod_sort(Jt, &s->cm);
  return Jt;
}

/* Per-tool work of one step. */
typedef struct {
  nh_beam_system *sys;
  int mfree;  /* free DOFs of the tool */
  double *dv; /* mfree */
  int *rows;  /* the rows touching this tool */
  int nrows;
  double *X;    /* mfree x nrows, column-major: A_k⁻¹ J_kᵀ */
  double *vnew; /* all DOFs: end-of-step velocity (base prescribed) */
} nh_tool_work;

static void nh_tool_work_free(nh_tool_work *w) {
  nh_beam_system_destroy(&w->sys);
  free(w->dv), free(w->rows), free(w->X), free(w->vnew);
}

/* The tool's part of row i applied to the velocities v (all DOFs). */
static double nh_row_tool_rate(const nh_rows *r, int i, const double *v) {
  double c[12], sum = 0.0;
  nh_row_tool_coef(r, i, c);
  const double *ve = v + 6 * r->elem[i];
  for (int j = 0; j < 12; j++) sum += c[j] * ve[j];
  return sum;
}

/* Scatter row i's tool coefficients into a free-DOF column (base dropped). */
static void nh_row_tool_column(const nh_rows *r, int i, double *col) {
  double c[12];
  nh_row_tool_coef(r, i, c);
  for (int j = 0; j < 12; j++) {
    int d = 6 * r->elem[i] + j - 6;
    if (d >= 0) col[d] += c[j];
  }
}

static int nh_finite(const double *a, int n) {
  for (int i = 0; i < n; i++)
    if (!isfinite(a[i])) return 0;
  return 1;
}

/* The tissue part of W with the current factor, W_t = J_t A⁻¹ J_tᵀ, and the
 * sum W = W_t + W_tools for the constraint solve. */
static int nh_tissue_compliance(nh_system *s, cholmod_sparse *Jt, int m, const double *Wtools,
                                double *Wt, double *W) {
  memset(Wt, 0, sizeof(double) * (size_t)m * m);
  NH_TRY(nh_system_compliance_add(s, Jt, Wt));
  for (size_t k = 0; k < (size_t)m * m; k++) W[k] = Wt[k] + Wtools[k];
  return NH_OK;
}

/* col = J_tᵀ λ (n_free values). */
static void nh_jt_scatter(const cholmod_sparse *Jt, const double *lambda, double *col, int nf) {
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  memset(col, 0, sizeof(double) * (size_t)nf);
  for (int j = 0; j < (int)Jt->ncol; j++)
    for (int p = Jp[j]; p < Jp[j + 1]; p++) col[Ji[p]] += Jx[p] * lambda[j];
}

/* nh_mcp_solve with the acceptance of a stalled solve (see nh_step_coupled). */
static int nh_constraint_solve(int m, const double *W, const double *r, nh_rows *rows,
                               double tolerance, double accept, int max_iterations,
                               nh_mcp_stats *st) {
  int rc = nh_mcp_solve(m, W, r, rows->law, tolerance, max_iterations, rows->lambda, st);
  /* Projected Gauss-Seidel can stall short of a tight tolerance on nearly
   * dependent friction rows (a stiff needle's shaft points share the
   * axial load in many ways): its best iterate is accepted up to
   * `accept` and its residual reported (steps.csv). */
  if (rc == NH_ERR_NUMERIC && isfinite(st->residual) && st->residual <= accept) {
    nh_error_clear();
    rc = NH_OK;
  }
  return rc;
}

/* The tissue's end-of-step rates of the rows for a velocity update dv (free
 * DOFs), plus `base` (the tools' rates and g/h): out_i = base_i +
 * n_i · Σ_a N_a (v + P dv)_a; full: 3 per node scratch. */
static void nh_tissue_rates(const nh_system *s, const nh_rows *rows, const double *v,
                            const double *dv, const double *base, double *full, double *out) {
  nh_system_scatter(s, dv, full);
  for (int i = 0; i < rows->m; i++) {
    double rate = 0.0;
    for (int a = 0; a < 8; a++) {
      int node = rows->node[8 * i + a];
      if (node < 0) continue;
      for (int c = 0; c < 3; c++)
        rate += rows->N[8 * i + a] * rows->dir[3 * i + c] * (v[3 * node + c] + full[3 * node + c]);
    }
    out[i] = base[i] + rate;
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
 * Returns 1 (not converged in NH_OUTER_MAX corrections, or a PCG or
 * constraint solve failed: the caller factorises and solves exactly), 0, or
 * another error code (memory). work: 2 n_free scratch, full: 3 per node scratch. */
static int nh_corrected_step(nh_system *s, const nh_integrator *in, cholmod_sparse *Jt,
                             nh_rows *rows, const double *Wt, const double *W,
                             const double *r_tools, const double *b, const double *v,
                             double tolerance, double accept, int max_iterations, double *dv,
                             double *work, double *full, nh_coupled_stats *st) {
  const int nf = s->n_free, m = rows->m;
  double *bk = work, *col = work + nf;
  double *e = nh_calloc(3 * (size_t)m, sizeof(double));
  if (!e) return NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint corrections (%d rows)", m);
  double *rk = e, *prev = e + m, *dl = e + 2 * m;
  int rc = 1;
  for (int k = 0; k < NH_OUTER_MAX; k++) {
    nh_jt_scatter(Jt, rows->lambda, bk, nf);
    for (int i = 0; i < nf; i++) bk[i] += b[i];
    int its = 0, prc = nh_system_pcg(s, bk, dv, k > 0, in->tolerance, NH_PCG_MAX, &its);
    st->step.pcg_iterations += its;
    if (prc) {
      if (prc == NH_ERR_NUMERIC) nh_error_clear(), prc = 1;
      rc = prc;
      break;
    }
    nh_tissue_rates(s, rows, v, dv, r_tools, full, rk);
    for (int i = 0; i < m; i++) {
      double w0 = 0.0;
      for (int j = 0; j < m; j++) w0 += Wt[(size_t)j * m + i] * rows->lambda[j];
      rk[i] -= w0;
    }
    memcpy(prev, rows->lambda, sizeof(double) * (size_t)m);
    st->step.corrections = k + 1;
    rc = nh_constraint_solve(m, W, rk, rows, tolerance, accept, max_iterations, &st->mcp);
    if (k > 0) { /* the exact path makes one constraint solve: the others are reuse's */
      st->step.correction_flops += st->mcp.flops;
      st->step.correction_flops_dense += st->mcp.flops_dense;
    }
    if (rc) {
      /* not converged with W₀: the exact path decides (and reports) */
      if (rc == NH_ERR_NUMERIC) nh_error_clear(), rc = 1;
      break;
    }
    double delta = 0.0, scale = 0.0;
    for (int i = 0; i < m; i++) {
      dl[i] = rows->lambda[i] - prev[i];
      delta = fmax(delta, fabs(dl[i]));
      scale = fmax(scale, fabs(rows->lambda[i]));
    }
    nh_jt_scatter(Jt, dl, col, nf);
    if ((rc = nh_system_solve(s, col, bk))) break;
    for (int i = 0; i < nf; i++) dv[i] += bk[i];
    rc = 1;
    if (delta <= in->tolerance * scale) {
      rc = 0;
      break;
    }
  }
  free(e);
  return rc;
}

double nh_dynamic_residual(nh_system *s, const nh_integrator *in, const double *f_ext,
                           const double *u, const double *v, const double *dv,
                           const double *reaction, double *b) {
  const nh_tissue *t = s->tissue;
  const int n = 3 * s->n_nodes, nf = s->n_free;
  const double h = in->dt;
  double *f_int = s->work[0], *Kv = s->work[1], *R = s->work[2];
  nh_system_assemble(s, u, v, 1.0 + h * in->alpha, h * in->beta + h * h, f_int, Kv, in->threads);
  double fe = 0.0, fi = 0.0, md = 0.0;
  for (int i = 0; i < n; i++) {
    double Mdv = t->mass[i / 3] * dv[i];
    R[i] = h * (f_ext[i] - f_int[i] - in->alpha * t->mass[i / 3] * v[i] - in->beta * Kv[i]) - Mdv;
    fe += f_ext[i] * f_ext[i], fi += f_int[i] * f_int[i], md += Mdv * Mdv;
  }
  if (nh_stop_requested()) return NAN; /* the assembly was cut short: unknown */
  nh_system_gather(s, R, b);
  nh_system_add_reactions(s, b);
  if (reaction)
    for (int i = 0; i < nf; i++) b[i] += reaction[i];
  double r = 0.0;
  for (int i = 0; i < nf; i++) r += b[i] * b[i];
  double scale = fmax(fmax(h * sqrt(fe), h * sqrt(fi)), fmax(sqrt(md), 1e-300));
  return sqrt(r) / scale;
}

int nh_step_coupled(nh_system *s, const nh_integrator *in, const double *f_ext, double *u,
                    double *v, int n_tools, nh_coupled_tool *tools, nh_rows *rows, double tolerance,
                    double accept, int max_iterations, nh_coupled_stats *stats) {
  const nh_tissue *t = s->tissue;
  const int n = 3 * s->n_nodes, nf = s->n_free, m = rows ? rows->m : 0;
  const double h = in->dt;
  double *f_int = s->work[0], *Kv = s->work[1], *rhs = s->work[2], *full = s->work[3];
  double *b = s->fwork[0], *dv = s->fwork[1];
  nh_coupled_stats st = {0};
  NH_CHECK(s->n_rows == 0 || m == 0, NH_ERR_INTERNAL,
           "coupled step: hanging-node rows and tool rows cannot be combined");
  int rc = NH_OK;
  nh_tool_work *tw = nh_calloc((size_t)(n_tools > 0 ? n_tools : 1), sizeof *tw);
  /* W, its tissue part W_t and its tools' part, m x m each */
  double *W = m ? nh_calloc(3 * (size_t)m * m, sizeof(double)) : NULL;
  double *Wt = W ? W + (size_t)m * m : NULL, *Wtools = W ? W + 2 * (size_t)m * m : NULL;
  double *r = m ? nh_calloc(2 * (size_t)m, sizeof(double)) : NULL; /* r, r_tools */
  double *col = m ? nh_calloc(2 * (size_t)nf, sizeof(double)) : NULL;
  int *mark = m ? malloc(sizeof(int) * (size_t)nf) : NULL;
  cholmod_sparse *Jt = NULL;
  if (!tw || (m && (!W || !r || !col || !mark))) {
    rc = NH_ERR_MEMORY;
    goto done;
  }
  double *r_tools = r ? r + m : NULL;
  for (int i = 0; m && i < nf; i++) mark[i] = -1;

  /* 1. Factorise every block (or keep the tissue's recent factor) and solve
   * the free problems; with a reused factor and rows, the tissue's solve
   * waits for the corrections (nh_corrected_step). */
  double t0 = nh_time_now();
  s->t_constraints = 0.0;
  nh_system_reset_multipliers(s); /* this step's hanging-node reactions only */
  nh_system_set_lazy(s, in->lazy_rotation);
  nh_system_lazy_reset(s);
  const int statics = in->quasi_static;
  if (statics) { /* a Newton iteration: A = K(u), b = f_ext − f_int(u) */
    nh_system_assemble(s, u, NULL, 0.0, 1.0, f_int, NULL, in->threads);
    for (int i = 0; i < n; i++) rhs[i] = f_ext[i] - f_int[i];
  } else {
    nh_system_assemble(s, u, v, 1.0 + h * in->alpha, h * in->beta + h * h, f_int, Kv, in->threads);
    for (int i = 0; i < n; i++) {
      double Mv = t->mass[i / 3] * v[i];
      rhs[i] = h * (f_ext[i] - f_int[i] - in->alpha * Mv - in->beta * Kv[i]) - h * h * Kv[i];
    }
  }
  nh_system_gather(s, rhs, b);
  double b_norm = 0.0, f_scale = 0.0; /* quasi-static: the residual's parts */
  if (statics) {
    double fe = 0.0, fi = 0.0;
    for (int i = 0; i < n; i++) fe += f_ext[i] * f_ext[i], fi += f_int[i] * f_int[i];
    f_scale = fmax(sqrt(fe), sqrt(fi));
  }
  double t1 = nh_time_now();
  st.step.t_assemble = t1 - t0;
  if ((rc = nh_stop_check())) goto done; /* an assembly cut short */
  if ((rc = nh_system_prepare(s, in, &st.step))) goto done;
  double t2 = nh_time_now();
  if (s->n_rows > 0) {
    /* hanging-node rows (then there are no tool rows): the factor is current */
    if ((rc = nh_system_solve_constrained(s, b, dv))) goto done;
  } else if (m == 0 || s->factor_current) {
    if ((rc = nh_system_solve_reuse(s, b, dv, in->tolerance, &st.step.pcg_iterations,
                                    &st.step.t_factor)))
      goto done;
  }
  st.step.t_constraints = s->t_constraints;
  st.step.t_solve = nh_time_now() - t2 - s->t_constraints;
  for (int k = 0; k < n_tools; k++) {
    nh_tool_work *w = &tw[k];
    nh_beam *beam = tools[k].beam;
    w->mfree = nh_beam_dofs(beam) - 6;
    w->dv = nh_calloc((size_t)w->mfree, sizeof(double));
    w->vnew = nh_calloc((size_t)w->mfree + 6, sizeof(double));
    w->rows = nh_calloc((size_t)(m > 0 ? m : 1), sizeof(int));
    if (!w->dv || !w->vnew || !w->rows || (rc = nh_beam_system_create(beam, &w->sys))) {
      rc = rc ? rc : NH_ERR_MEMORY;
      goto done;
    }
    double t3 = nh_time_now();
    rc = nh_beam_dynamic_prepare(beam, &tools[k].options, tools[k].f_ext, tools[k].base_velocity,
                                 w->sys, w->dv);
    double t4 = nh_time_now();
    st.step.t_factor += t4 - t3;
    if (rc) goto done;
    nh_beam_system_solve(w->sys, w->dv);
    st.step.t_solve += nh_time_now() - t4;
  }

  if (m > 0) {
    /* 2. The compliance W: the tools' parts (exact, dense), then the tissue's
     * (from the factor, current or reused). */
    double tc0 = nh_time_now();
    if (!(Jt = nh_rows_tissue_jt(s, rows, mark))) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint rows (%d)", m);
      goto done;
    }
    for (int i = 0; i < m; i++) {
      int k = rows->tool[i];
      if (k < 0) continue;
      if (!(k < n_tools && rows->elem[i] >= 0 && rows->elem[i] < nh_beam_elements(tools[k].beam))) {
        /* not NH_CHECK: its early return would leak the work of step 1 */
        rc = NH_ERROR(NH_ERR_INTERNAL, "constraint row %d: tool %d element %d out of range", i, k,
                      rows->elem[i]);
        goto done;
      }
      tw[k].rows[tw[k].nrows++] = i;
    }
    for (int k = 0; k < n_tools; k++) {
      nh_tool_work *w = &tw[k];
      if (!w->nrows) continue;
      w->X = nh_calloc((size_t)w->mfree * w->nrows, sizeof(double));
      if (!w->X) {
        rc = NH_ERR_MEMORY;
        goto done;
      }
      for (int a = 0; a < w->nrows; a++) {
        double *x = w->X + (size_t)a * w->mfree;
        nh_row_tool_column(rows, w->rows[a], x);
        nh_beam_system_solve(w->sys, x);
      }
      for (int a = 0; a < w->nrows; a++) { /* W_ij += J_i (A⁻¹ J_jᵀ) */
        const int i = w->rows[a], d0 = 6 * rows->elem[i] - 6;
        double coef[12];
        nh_row_tool_coef(rows, i, coef);
        for (int c = 0; c < w->nrows; c++) {
          const double *x = w->X + (size_t)c * w->mfree;
          double sum = 0.0;
          for (int q = d0 < 0 ? -d0 : 0; q < 12; q++) sum += coef[q] * x[d0 + q];
          Wtools[(size_t)w->rows[c] * m + i] += sum;
        }
      }
    }
    if ((rc = nh_tissue_compliance(s, Jt, m, Wtools, Wt, W))) goto done;
    double tc1 = nh_time_now();
    st.t_compliance = tc1 - tc0;

    /* The tools' free rates and g/h: r_tools. */
    for (int i = 0; i < m; i++) r_tools[i] = rows->gap[i] / h;
    for (int k = 0; k < n_tools; k++) {
      nh_tool_work *w = &tw[k];
      if (!w->nrows) continue;
      const double *vb = nh_beam_velocities(tools[k].beam);
      memcpy(w->vnew, tools[k].base_velocity, 6 * sizeof(double));
      for (int q = 0; q < w->mfree; q++) w->vnew[6 + q] = vb[6 + q] + w->dv[q];
      for (int a = 0; a < w->nrows; a++)
        r_tools[w->rows[a]] += nh_row_tool_rate(rows, w->rows[a], w->vnew);
    }
    if (!s->factor_current) {
      /* 3'-4'. λ and the tissue's update with the reused factor. */
      rc = nh_corrected_step(s, in, Jt, rows, Wt, W, r_tools, b, v, tolerance, accept,
                             max_iterations, dv, col, full, &st);
      if (rc == 1) { /* the reused factor did not serve: factorise, solve exactly */
        double tf = nh_time_now();
        if ((rc = nh_system_factor(s))) goto done;
        double tf1 = nh_time_now();
        if ((rc = nh_system_solve(s, b, dv))) goto done;
        st.step.t_factor += tf1 - tf;
        st.step.t_factor_reference = tf1 - tf;
        tc0 += tf1 - tf; /* the factorisation is not a constraint cost */
        if ((rc = nh_tissue_compliance(s, Jt, m, Wtools, Wt, W))) goto done;
      }
    }
    double tc2 = nh_time_now();
    if (s->factor_current) {
      /* 3. Free rates r = J v_free + g/h, λ from the exact W; 4. the tissue's
       * correction A⁻¹ J_tᵀ λ. */
      nh_tissue_rates(s, rows, v, dv, r_tools, full, r);
      rc = nh_constraint_solve(m, W, r, rows, tolerance, accept, max_iterations, &st.mcp);
      st.t_mcp = nh_time_now() - tc2;
      if (rc) goto done;
      nh_jt_scatter(Jt, rows->lambda, col, nf);
      if (statics) { /* the equilibrium residual with this iteration's forces */
        double r2 = 0.0, j2 = 0.0;
        for (int i = 0; i < nf; i++) r2 += (b[i] + col[i]) * (b[i] + col[i]), j2 += col[i] * col[i];
        b_norm = sqrt(r2), f_scale = fmax(f_scale, sqrt(j2));
      }
      if ((rc = nh_system_solve(s, col, b))) goto done;
      for (int i = 0; i < nf; i++) dv[i] += b[i];
    } else {
      st.t_mcp = tc2 - tc1; /* the corrections: PCG and constraint solves */
      if (rc) goto done;
    }
    for (int k = 0; k < n_tools; k++) {
      nh_tool_work *w = &tw[k];
      for (int a = 0; a < w->nrows; a++) {
        const double *x = w->X + (size_t)a * w->mfree, lam = rows->lambda[w->rows[a]];
        for (int q = 0; q < w->mfree; q++) w->dv[q] += lam * x[q];
      }
    }
    st.step.t_constraints = nh_time_now() - tc0;
  }

  /* 5. Update. */
  double t6 = nh_time_now();
  if (!nh_finite(dv, nf)) {
    rc = NH_ERROR(NH_ERR_NUMERIC, "the tissue's velocity update is not finite");
    goto done;
  }
  nh_system_scatter(s, dv, full);
  if (statics) {
    if (m == 0) { /* (with rows: measured before the correction, above) */
      for (int i = 0; i < nf; i++) b_norm += b[i] * b[i];
      b_norm = sqrt(b_norm);
    }
    for (int i = 0; i < n; i++) u[i] += full[i];
  } else {
    for (int i = 0; i < n; i++) {
      v[i] += full[i];
      u[i] += h * v[i];
    }
  }
  for (int k = 0; k < n_tools; k++)
    if ((rc = nh_beam_dynamic_finish(tools[k].beam, h, tools[k].base_velocity, tw[k].dv)))
      goto done;
  double t7 = nh_time_now();
  st.step.t_solve += t7 - t6;
  st.step.iterations = 1;
  if (statics) {
    st.step.residual = b_norm / fmax(f_scale, 1e-300);
    goto done;
  }
  if (in->reuse) nh_system_account(s, &st.step);
  /* The residual of the one linearisation (full still holds the update; col
   * the rows' reaction J_tᵀ λ, which the corrected path left as an increment). */
  if (m) nh_jt_scatter(Jt, rows->lambda, col, nf);
  st.step.residual = nh_dynamic_residual(s, in, f_ext, u, v, full, m ? col : NULL, b);
  st.step.t_assemble += nh_time_now() - t7;

done:
  st.step.factorised = s->factor_age == 0;
  st.step.tangent_updates = nh_system_lazy_updates(s);
  if (stats) *stats = st;
  cholmod_free_sparse(&Jt, &s->cm);
  for (int k = 0; tw && k < n_tools; k++) nh_tool_work_free(&tw[k]);
  free(tw), free(W), free(r), free(col), free(mark);
  return rc;
}
