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
 * is nh_step_dynamic (which may carry hanging-node rows instead). */
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
  r->law[i] = (nh_row_law){NH_ROW_BILATERAL, -1, -1, 0.0, 0.0, -1};
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
          if (c == 0.0) continue;
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
  double *W = m ? nh_calloc((size_t)m * m, sizeof(double)) : NULL;
  double *r = m ? nh_calloc((size_t)m, sizeof(double)) : NULL;
  double *col = m ? nh_calloc((size_t)nf, sizeof(double)) : NULL;
  int *mark = m ? malloc(sizeof(int) * (size_t)nf) : NULL;
  cholmod_sparse *Jt = NULL;
  if (!tw || (m && (!W || !r || !col || !mark))) {
    rc = NH_ERR_MEMORY;
    goto done;
  }
  for (int i = 0; m && i < nf; i++) mark[i] = -1;

  /* 1. Factorise every block and solve the free problems. */
  double t0 = nh_time_now();
  s->t_constraints = 0.0;
  nh_system_reset_multipliers(s); /* this step's hanging-node reactions only */
  nh_system_assemble(s, u, v, 1.0 + h * in->alpha, h * in->beta + h * h, f_int, Kv, in->threads);
  for (int i = 0; i < n; i++) {
    double Mv = t->mass[i / 3] * v[i];
    rhs[i] = h * (f_ext[i] - f_int[i] - in->alpha * Mv - in->beta * Kv[i]) - h * h * Kv[i];
  }
  nh_system_gather(s, rhs, b);
  double t1 = nh_time_now();
  st.step.t_assemble = t1 - t0;
  if ((rc = nh_stop_check())) goto done; /* an assembly cut short */
  if ((rc = nh_system_factor(s))) goto done;
  double t2 = nh_time_now();
  st.step.t_factor = t2 - t1;
  /* (hanging-node rows, if any, are enforced here: then there are no tool rows) */
  if ((rc = nh_system_solve_constrained(s, b, dv))) goto done;
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
    /* 2. The compliance W. */
    double tc0 = nh_time_now();
    if (!(Jt = nh_rows_tissue_jt(s, rows, mark))) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: constraint rows (%d)", m);
      goto done;
    }
    if ((rc = nh_system_compliance_add(s, Jt, W))) goto done;
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
          W[(size_t)w->rows[c] * m + i] += sum;
        }
      }
    }
    double tc1 = nh_time_now();
    st.t_compliance = tc1 - tc0;

    /* 3. Free rates r = J v_free + g/h, then λ. */
    nh_system_scatter(s, dv, full);
    for (int i = 0; i < m; i++) {
      double rate = 0.0;
      for (int a = 0; a < 8; a++) {
        int node = rows->node[8 * i + a];
        if (node < 0) continue;
        for (int c = 0; c < 3; c++)
          rate +=
              rows->N[8 * i + a] * rows->dir[3 * i + c] * (v[3 * node + c] + full[3 * node + c]);
      }
      r[i] = rate + rows->gap[i] / h;
    }
    for (int k = 0; k < n_tools; k++) {
      nh_tool_work *w = &tw[k];
      if (!w->nrows) continue;
      const double *vb = nh_beam_velocities(tools[k].beam);
      memcpy(w->vnew, tools[k].base_velocity, 6 * sizeof(double));
      for (int q = 0; q < w->mfree; q++) w->vnew[6 + q] = vb[6 + q] + w->dv[q];
      for (int a = 0; a < w->nrows; a++)
        r[w->rows[a]] += nh_row_tool_rate(rows, w->rows[a], w->vnew);
    }
    rc = nh_mcp_solve(m, W, r, rows->law, tolerance, max_iterations, rows->lambda, &st.mcp);
    /* Projected Gauss-Seidel can stall short of a tight tolerance on nearly
     * dependent friction rows (a stiff needle's shaft points share the
     * axial load in many ways): its best iterate is accepted up to
     * `accept` and its residual reported (steps.csv). */
    if (rc == NH_ERR_NUMERIC && isfinite(st.mcp.residual) && st.mcp.residual <= accept) {
      nh_error_clear();
      rc = NH_OK;
    }
    double tc2 = nh_time_now();
    st.t_mcp = tc2 - tc1;
    if (rc) goto done;

    /* 4. Corrections A⁻¹ Jᵀ λ. */
    memset(col, 0, sizeof(double) * (size_t)nf);
    const int *Jp = Jt->p, *Ji = Jt->i;
    const double *Jx = Jt->x;
    for (int j = 0; j < m; j++)
      for (int p = Jp[j]; p < Jp[j + 1]; p++) col[Ji[p]] += Jx[p] * rows->lambda[j];
    if ((rc = nh_system_solve(s, col, b))) goto done;
    for (int i = 0; i < nf; i++) dv[i] += b[i];
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
  for (int i = 0; i < n; i++) {
    v[i] += full[i];
    u[i] += h * v[i];
  }
  for (int k = 0; k < n_tools; k++)
    if ((rc = nh_beam_dynamic_finish(tools[k].beam, h, tools[k].base_velocity, tw[k].dv)))
      goto done;
  double t7 = nh_time_now();
  st.step.t_solve += t7 - t6;
  st.step.iterations = 1;
  /* The residual of the one linearisation (full still holds the update). */
  st.step.residual = nh_dynamic_residual(s, in, f_ext, u, v, full, m ? col : NULL, b);
  st.step.t_assemble += nh_time_now() - t7;

done:
  if (stats) *stats = st;
  cholmod_free_sparse(&Jt, &s->cm);
  for (int k = 0; tw && k < n_tools; k++) nh_tool_work_free(&tw[k]);
  free(tw), free(W), free(r), free(col), free(mark);
  return rc;
}
