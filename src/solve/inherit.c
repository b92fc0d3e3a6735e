/* inherit.c — a preconditioner across a mesh change: the factor of the
 * mesh before it, extended to the new unknowns (solver.refactor: auto;
 * docs/performance.md, "Across mesh changes").
 *
 * A refinement or coarsening builds a new system (new unknowns, new
 * pattern). Instead of factorising its A at once, the new system keeps the
 * old mesh's factor L₀ (A₀ = L₀ L₀ᵀ) and solves by PCG (reuse.c) with a
 * two-level preconditioner:
 *   - the transfer T the fields were carried by (adapt: Eq. 17 for new
 *     nodes, the identity for kept ones, injection after coarsening), read
 *     between the unknowns, P = R_new T S_old (S_old: the old unknowns to
 *     the old nodes, hanging nodes their masters' interpolation; R_new: the
 *     new nodes' values at the new unknowns). For a refinement P is the
 *     embedding of the old finite element space in the new one (nested
 *     conforming spaces), so PᵀAP ≈ A₀ (equal for the same tangent and
 *     exact integration).
 *   - the new unknowns N: those not kept from the old system (a new node,
 *     or a node that was hanging). They span the hierarchical complement of
 *     P's range; their block A_NN is small and is factorised (once, at the
 *     first step on the mesh; CHOLMOD, its own analysis).
 * One application z = B r is the symmetric two-level (multiplicative)
 * correction, a block Gauss–Seidel sweep N, coarse, N in the hierarchical
 * basis:
 *   z = E A_NN⁻¹ Eᵀ r,
 *   z += P A₀⁻¹ Pᵀ (r − A z),
 *   z += E A_NN⁻¹ Eᵀ (r − A z),
 * (E: the injection of N). B is symmetric; it is positive definite when
 * the smoother is the current block's inverse (then B = S + (I − SA) C (I − AS)
 * with S = E A_NN⁻¹ Eᵀ and C = P A₀⁻¹ Pᵀ, both positive semi-definite and
 * together definite: Pᵀ is one-to-one on the kept unknowns), and stays so
 * while A_NN moves by less than its factorised value (2 Ã_NN ≻ A_NN); PCG
 * stops and the step factorises if not (nh_system_pcg). The condition number
 * of BA is that of the two-level splitting, 1/(1 − γ²) with γ the strengthened
 * Cauchy–Schwarz constant of P's range and the complement (below 1 for
 * nested trilinear spaces, independent of the mesh size), times A's drift
 * from A₀. After a coarsening P is injection and N empty: B = P A₀⁻¹ Pᵀ is
 * the inverse of the Schur complement of A₀ onto the kept nodes, which is
 * spectrally equivalent to the coarse A with the same constant.
 *
 * The renewal rule (reuse.c) goes on counting the cycle the old
 * factorisation opened, with a PCG iteration's cost that of B (one solve with
 * L₀, two more products with A, two solves with the block's factor); the
 * constraint rows' compliance W₀ = J B Jᵀ costs one application per row
 * (nh_inherit_compliance_add), so a step with many rows (skull contact)
 * factorises instead (nh_system_factor_or_reuse). Only one level: a mesh
 * change while the preconditioner is inherited, a system with hanging-node
 * rows (adapt.hanging: lagrange) or `refactor: every` starts from a
 * factorisation. */
#include "solve/system_impl.h"

#include <stdlib.h>
#include <string.h>

struct nh_inherited {
  int n0;             /* unknowns of the old system */
  cholmod_factor *L0; /* its factor */
  cholmod_sparse *Pt; /* n0 x n_free, CSC: column j = row j of P */
  int nN, *N;         /* the new unknowns, ascending */
  int *N_of;          /* n_free: position in N, or -1 */
  cholmod_sparse *ANN;
  cholmod_factor *LNN; /* NULL until the first step on the mesh */
  cholmod_dense *B0, *X0, *Y0, *E0, *BN, *XN, *YN, *EN;
  double *q, *r1; /* n_free */
};

void nh_node_transfer_free(nh_node_transfer *t) {
  if (!t) return;
  free(t->start), free(t->node), free(t->weight);
  *t = (nh_node_transfer){0};
}

void nh_inherit_free(nh_system *s) {
  nh_inherited *h = s->inh;
  if (!h) return;
  cholmod_common *cm = &s->cm;
  cholmod_free_factor(&h->L0, cm);
  cholmod_free_factor(&h->LNN, cm);
  cholmod_free_sparse(&h->Pt, cm);
  cholmod_free_sparse(&h->ANN, cm);
  cholmod_dense **d[8] = {&h->B0, &h->X0, &h->Y0, &h->E0, &h->BN, &h->XN, &h->YN, &h->EN};
  for (int i = 0; i < 8; i++) cholmod_free_dense(d[i], cm);
  free(h->N), free(h->N_of), free(h->q), free(h->r1);
  free(h);
  s->inh = NULL;
}

void nh_system_inherit_drop(nh_system *s) {
  nh_inherit_free(s);
}

int nh_system_inherited(const nh_system *s) {
  return s->inh != NULL;
}

/* Column j of Pᵀ (row j of P): the new unknown j's value from the old
 * unknowns, through the transfer and the old hanging-node interpolation;
 * entries sorted and merged into (row, val) from *n. kept: 1 if it is an
 * old unknown carried unchanged. */
static int nh_inherit_row(const nh_system *s, const nh_system *old, const nh_node_transfer *t,
                          int j, int *row, double *val, int *kept) {
  const int v = s->dof_of[j] / 3, k = s->dof_of[j] % 3;
  int n = 0;
  *kept = 0;
  for (int q = t->start[v]; q < t->start[v + 1]; q++) {
    const int o = t->node[q];
    for (int r = old->exp_start[o]; r < old->exp_start[o + 1]; r++) {
      int f = old->free_of[3 * old->exp_node[r] + k];
      if (f < 0) continue;
      double w = t->weight[q] * old->exp_w[r];
      int p = 0;
      while (p < n && row[p] < f) p++;
      if (p < n && row[p] == f) {
        val[p] += w;
        continue;
      }
      memmove(row + p + 1, row + p, sizeof(int) * (size_t)(n - p));
      memmove(val + p + 1, val + p, sizeof(double) * (size_t)(n - p));
      row[p] = f, val[p] = w, n++;
    }
    if (t->start[v + 1] - t->start[v] == 1 && t->weight[q] == 1.0 &&
        old->exp_start[o + 1] - old->exp_start[o] == 1 && old->exp_node[old->exp_start[o]] == o &&
        old->free_of[3 * o + k] >= 0)
      *kept = 1;
  }
  return n;
}

/* The block of A on N (upper triangle, CSC, values filled by nh_inherit_block_values). */
static int nh_inherit_block(nh_system *s, nh_inherited *h) {
  const int *Ap = s->A->p, *Ai = s->A->i;
  size_t nnz = 0;
  for (int a = 0; a < h->nN; a++)
    for (int p = Ap[h->N[a]]; p < Ap[h->N[a] + 1]; p++) nnz += h->N_of[Ai[p]] >= 0;
  h->ANN = cholmod_allocate_sparse((size_t)h->nN, (size_t)h->nN, nnz ? nnz : 1, 1, 1, 1,
                                   CHOLMOD_REAL, &s->cm);
  if (!h->ANN) return NH_ERROR(NH_ERR_MEMORY, "out of memory: the new unknowns' block");
  int *Np = h->ANN->p, *Ni = h->ANN->i, pos = 0;
  for (int a = 0; a < h->nN; a++) {
    Np[a] = pos;
    for (int p = Ap[h->N[a]]; p < Ap[h->N[a] + 1]; p++)
      if (h->N_of[Ai[p]] >= 0) Ni[pos++] = h->N_of[Ai[p]];
  }
  Np[h->nN] = pos;
  return NH_OK;
}

int nh_system_inherit(nh_system *s, nh_system *old, const nh_node_transfer *t) {
  if (old) s->inherit_its = old->inherit_its; /* what the next mesh change expects */
  if (!old || !old->L || old->inh || old->n_rows > 0 || s->n_rows > 0 || !t ||
      t->n_old != old->n_nodes || t->n_new != s->n_nodes)
    return NH_OK; /* nothing to inherit: the first step factorises */
  nh_inherited *h = nh_calloc(1, sizeof *h);
  if (!h) return NH_ERR_MEMORY;
  s->inh = h;
  const int n = s->n_free;
  h->n0 = old->n_free;
  h->N_of = nh_calloc((size_t)n, sizeof(int));
  h->N = nh_calloc((size_t)n, sizeof(int));
  h->q = nh_calloc((size_t)n, sizeof(double));
  h->r1 = nh_calloc((size_t)n, sizeof(double));
  /* a row has at most (transfer entries) x (masters) entries */
  int most = 1;
  for (int v = 0; v < t->n_new; v++) {
    int c = 0;
    for (int q = t->start[v]; q < t->start[v + 1]; q++)
      c += old->exp_start[t->node[q] + 1] - old->exp_start[t->node[q]];
    if (c > most) most = c;
  }
  int *row = nh_calloc((size_t)most, sizeof(int));
  double *val = nh_calloc((size_t)most, sizeof(double));
  int rc = h->N_of && h->N && h->q && h->r1 && row && val ? NH_OK : NH_ERR_MEMORY;
  /* Pᵀ by columns, counted then filled */
  size_t nnz = 0;
  for (int j = 0; j < n && !rc; j++) {
    int kept;
    nnz += (size_t)nh_inherit_row(s, old, t, j, row, val, &kept);
  }
  if (!rc && !(h->Pt = cholmod_allocate_sparse((size_t)h->n0, (size_t)n, nnz ? nnz : 1, 1, 1, 0,
                                               CHOLMOD_REAL, &s->cm)))
    rc = NH_ERR_MEMORY;
  if (!rc) {
    int *Pp = h->Pt->p, *Pi = h->Pt->i, pos = 0;
    double *Px = h->Pt->x;
    for (int j = 0; j < n; j++) {
      int kept, c = nh_inherit_row(s, old, t, j, row, val, &kept);
      Pp[j] = pos;
      memcpy(Pi + pos, row, sizeof(int) * (size_t)c);
      memcpy(Px + pos, val, sizeof(double) * (size_t)c);
      pos += c;
      h->N_of[j] = kept ? -1 : h->nN;
      if (!kept) h->N[h->nN++] = j;
    }
    Pp[n] = pos;
    rc = nh_inherit_block(s, h);
  }
  free(row), free(val);
  if (rc) {
    nh_inherit_free(s);
    return rc == NH_ERR_MEMORY
               ? NH_ERROR(rc, "out of memory: the preconditioner across a mesh change")
               : rc;
  }
  /* the factor moves over; the renewal rule's cycle goes on */
  h->L0 = old->L;
  old->L = NULL;
  s->factor_age = old->factor_age;
  s->refactor_due = old->refactor_due;
  s->cycle_cost = old->cycle_cost;
  s->cycle_steps = old->cycle_steps;
  /* costs: a factorisation of the new A, guessed from the old one (nested
   * dissection in 3-D: F ~ n²) until its analysis; one iteration, B's */
  double ratio = (double)n / (double)h->n0;
  s->flops_factor = old->flops_factor * ratio * ratio;
  s->flops_solve = old->flops_solve + 4.0 * (double)cholmod_nnz(h->Pt, &s->cm);
  s->flops_iteration = s->flops_solve + 12.0 * (double)cholmod_nnz(s->A, &s->cm);
  return NH_OK;
}

/* The block's factor, from the current A (first step on the mesh). */
static int nh_inherit_prepare(nh_system *s) {
  nh_inherited *h = s->inh;
  if (h->LNN || h->nN == 0) return NH_OK;
  const int *Ap = s->A->p, *Ai = s->A->i;
  const double *Ax = s->A->x;
  double *x = h->ANN->x;
  int pos = 0;
  for (int a = 0; a < h->nN; a++)
    for (int p = Ap[h->N[a]]; p < Ap[h->N[a] + 1]; p++)
      if (h->N_of[Ai[p]] >= 0) x[pos++] = Ax[p];
  h->LNN = cholmod_analyze(h->ANN, &s->cm);
  if (!h->LNN || s->cm.status < CHOLMOD_OK)
    return NH_ERROR(NH_ERR_NUMERIC,
                    "CHOLMOD analysis of the new unknowns' block failed (status %d)", s->cm.status);
  const double lnz = s->cm.lnz;
  int ok = nh_cholmod_factorize(h->ANN, h->LNN, &s->cm);
  if (!ok || s->cm.status != CHOLMOD_OK) /* not positive definite: factorise A instead */
    return NH_ERROR(NH_ERR_NUMERIC, "the new unknowns' block is not positive definite");
  /* its solves: two per application */
  s->flops_solve += 8.0 * lnz;
  s->flops_iteration += 8.0 * lnz;
  return NH_OK;
}

int nh_inherit_ready(nh_system *s) {
  int rc = nh_inherit_prepare(s);
  if (rc == NH_ERR_NUMERIC) { /* the caller factorises A */
    nh_error_clear();
    nh_inherit_free(s);
  }
  return rc == NH_ERR_NUMERIC ? NH_OK : rc;
}

/* z[N] += A_NN⁻¹ r[N] (scratch: the block's dense workspace). */
static int nh_inherit_smooth(nh_system *s, const double *r, double *z) {
  nh_inherited *h = s->inh;
  if (!h->BN &&
      !(h->BN = cholmod_allocate_dense((size_t)h->nN, 1, (size_t)h->nN, CHOLMOD_REAL, &s->cm)))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: solve workspace");
  double *b = h->BN->x;
  for (int a = 0; a < h->nN; a++) b[a] = r[h->N[a]];
  if (!cholmod_solve2(CHOLMOD_A, h->LNN, h->BN, NULL, &h->XN, NULL, &h->YN, &h->EN, &s->cm))
    return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD solve failed (status %d)", s->cm.status);
  const double *x = h->XN->x;
  for (int a = 0; a < h->nN; a++) z[h->N[a]] += x[a];
  return NH_OK;
}

int nh_inherit_apply(nh_system *s, const double *r, double *z) {
  nh_inherited *h = s->inh;
  const int n = s->n_free;
  const int *Pp = h->Pt->p, *Pi = h->Pt->i;
  const double *Px = h->Pt->x;
  double *q = h->q, *r1 = h->r1;
  memset(z, 0, sizeof(double) * (size_t)n);
  const double *res = r;
  if (h->nN > 0) { /* pre-smoothing on the new unknowns */
    NH_TRY(nh_inherit_smooth(s, r, z));
    nh_system_apply(s, z, q);
    for (int i = 0; i < n; i++) r1[i] = r[i] - q[i];
    res = r1;
  }
  /* coarse: z += P A₀⁻¹ Pᵀ res */
  if (!h->B0 &&
      !(h->B0 = cholmod_allocate_dense((size_t)h->n0, 1, (size_t)h->n0, CHOLMOD_REAL, &s->cm)))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: solve workspace");
  double *c = h->B0->x;
  memset(c, 0, sizeof(double) * (size_t)h->n0);
  for (int j = 0; j < n; j++)
    for (int p = Pp[j]; p < Pp[j + 1]; p++) c[Pi[p]] += Px[p] * res[j];
  if (!cholmod_solve2(CHOLMOD_A, h->L0, h->B0, NULL, &h->X0, NULL, &h->Y0, &h->E0, &s->cm))
    return NH_ERROR(NH_ERR_NUMERIC, "CHOLMOD solve failed (status %d)", s->cm.status);
  const double *y = h->X0->x;
  for (int j = 0; j < n; j++) {
    double sum = 0.0;
    for (int p = Pp[j]; p < Pp[j + 1]; p++) sum += Px[p] * y[Pi[p]];
    z[j] += sum;
  }
  if (h->nN > 0) { /* post-smoothing */
    nh_system_apply(s, z, q);
    for (int i = 0; i < n; i++) r1[i] = r[i] - q[i];
    NH_TRY(nh_inherit_smooth(s, r1, z));
  }
  return NH_OK;
}

int nh_inherit_compliance_add(nh_system *s, cholmod_sparse *Jt, double *W) {
  const int n = s->n_free, m = (int)Jt->ncol;
  const int *Jp = Jt->p, *Ji = Jt->i;
  const double *Jx = Jt->x;
  double *col = nh_calloc((size_t)n, sizeof(double)), *z = nh_calloc((size_t)n, sizeof(double));
  if (!col || !z) {
    free(col), free(z);
    return NH_ERR_MEMORY;
  }
  int rc = NH_OK;
  for (int j = 0; j < m && !rc; j++) {
    for (int p = Jp[j]; p < Jp[j + 1]; p++) col[Ji[p]] = Jx[p];
    rc = nh_inherit_apply(s, col, z);
    for (int p = Jp[j]; p < Jp[j + 1]; p++) col[Ji[p]] = 0.0;
    for (int i = j; i < m && !rc; i++) { /* the upper triangle, mirrored: W symmetric */
      double sum = 0.0;
      for (int p = Jp[i]; p < Jp[i + 1]; p++) sum += Jx[p] * z[Ji[p]];
      W[(size_t)j * m + i] += sum;
      if (i != j) W[(size_t)i * m + j] += sum;
    }
  }
  free(col), free(z);
  return rc;
}
