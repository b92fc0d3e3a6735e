/* spr.c — superconvergent patch recovery (Zienkiewicz & Zhu 1992) and the
 * element error indicators of the seed's §2.3, Eq. 15 (docs/theory.md).
 *
 * What it computes. The finite-element stress σₕ is discontinuous between
 * elements and one order less accurate than the displacement, except at the
 * superconvergent points, which for the trilinear hexahedron are the element
 * centres. SPR builds from these centre values a continuous field σ* that is
 * more accurate than σₕ, and uses σ* − σₕ as the error of σₕ:
 *
 *  1. Centre stresses. σₕ(cₑ) of every leaf e (nh_tissue_cell_stress, the
 *     corotational stress at ξ = 0) at the rest centroid cₑ of its corners.
 *     Positions are rest (material) positions throughout: σ* is a field over
 *     the reference body, like u.
 *  2. Nodal fits. For every node n that is a corner of a leaf and not
 *     hanging, the patch is the set of leaves having n as a corner. Each of
 *     the 6 stress components is fitted by least squares with a linear
 *     polynomial p(x) = a₀ + a·(x − x̄) to the centre stresses of the patch,
 *     and σ*(n) = p(X_n). The coordinates are centred at the centroid x̄ of
 *     the patch's centres and scaled by their largest distance from it: the
 *     4x4 normal equations then split into the mean (a₀ = mean of the
 *     samples) and a 3x3 system with the scatter matrix C = Σ yyᵀ, solved by
 *     its eigen-decomposition (nh_spr_fit_patch). A field that is exactly
 *     linear is reproduced to round-off, and a constant one exactly up to
 *     the rounding of its mean, whatever the conditioning of C.
 *  3. Small and boundary patches. A fit is refused (nh_spr_fit_patch) if
 *     the patch has fewer than 4 cells, if its centres do not span 3-D
 *     (smallest eigenvalue of C below NH_SPR_RCOND times the largest: the
 *     4 cells at a face node of a box have coplanar centres, a one-layer
 *     mesh has all of them in one plane), or if the value at the node is
 *     ill-conditioned: its leverage 1/n + y₀ᵀC⁻¹y₀ (y₀ the scaled node
 *     position; the factor by which the fit multiplies the variance of
 *     independent errors of the samples) exceeds NH_SPR_MAX_LEVERAGE = 4.
 *     The leverage test catches nearly coplanar centres with the node off
 *     their plane — a face node of a distorted mesh — where the rank test
 *     alone let the extrapolation amplify round-off 20-fold (measured in
 *     tests/test_spr.c, perturbed grid); an 8-cell interior patch of a box
 *     grid has leverage 1/8. A refused patch is GROWN by one ring — every
 *     leaf sharing a node (corner) with a cell of the patch is added — and
 *     the fit retried, at most twice. On a box grid one growth turns a
 *     corner node's single cell into 2x2x2 cells, an edge node's 2 cells
 *     into 2x2x4 and a face node's 4 into 4x4x2, which all fit (leverage
 *     13/8 at a corner). If the fit is still refused after two growths (a
 *     mesh one cell thick), σ*(n) is the volume-weighted (φ V) average of
 *     the centre stresses of the node's own, ungrown patch: a constant,
 *     local, always defined value (it reproduces a constant field, not a
 *     linear one). Zienkiewicz and Zhu recommend evaluating the polynomials
 *     of interior patches at boundary nodes instead; growing the patch is our
 *     simpler choice: one rule for boundary nodes, coarse-fine interfaces and
 *     degenerate patches, and for a boundary node the grown patch contains
 *     the adjacent interior patch's cells anyway. Either way the fit
 *     extrapolates to a boundary node, which sits at the edge of its patch.
 *  4. Hanging nodes. A hanging node gets no fit of its own: σ*(h) =
 *     Σ w σ*(master) with the interpolation weights of its displacement, so
 *     σ* restricted to a nonconforming face is the coarse side's bilinear
 *     field and σ* is continuous across it. Masters are never hanging (the
 *     chains are resolved by mesh/hanging.c); we check it.
 *     Nodes that belong to no leaf (corners of refined parents only) get 0.
 *  5. Indicators. Inside a leaf σ* is the trilinear interpolation of its 8
 *     nodal values. With D⁻¹ the isotropic compliance (fem/stress.c),
 *       ηₑ² = φₑ ∫ₑ (σ* − σₕ)ᵀ D⁻¹ (σ* − σₕ) dΩ,
 *     integrated by 2x2x2 Gauss points of the rest shape, σₕ at the Gauss
 *     points by nh_hex_stress_at (the element's rotation, the strain at the
 *     point). This is the seed's Eq. 15 with ε written as D⁻¹σ. Globally
 *       η = (Σ ηₑ²)^½,  ‖u‖²_E = Σₑ φₑ ∫ₑ σₕᵀ D⁻¹ σₕ dΩ,
 *       η_rel = η / (‖u‖²_E + η²)^½   (0 when both vanish).
 *     ‖u‖²_E is twice the strain energy of the corotational model.
 *
 * Workspace: per cell a centre, a centre stress and a weight (10 doubles);
 * the node-to-leaf adjacency (CSR, 8 ints per leaf); per thread the patch
 * lists, grown on demand. Nodes and cells are processed in parallel with
 * OpenMP; every node's fit depends only on its own sorted patch and every
 * cell's integral only on its own data, and the global sums are taken in
 * leaf order after the parallel loop, so the results are bitwise
 * independent of the number of threads.
 *
 * Failure: NH_ERR_MEMORY if a workspace cannot be allocated (also inside the
 * parallel region, reported after it), NH_ERR_INTERNAL for inconsistent
 * input (tissue of another mesh, missing element data, a bad hanging-node
 * table), NH_ERR_NUMERIC if η is not finite. */
#include "adapt/adapt.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Loops shorter than this run serially (thread start-up costs more). */
#define NH_SPR_PARALLEL_MIN 512

int nh_spr_fit_patch(int n, const double *points, const double *values, const double x0[3],
                     double out[6]) {
  return nh_spr_fit_patch_n(n, points, 6, values, x0, out);
}

int nh_spr_fit_patch_n(int n, const double *points, int m, const double *values, const double x0[3],
                       double *out) {
  if (n < 4) return NH_ERR_NUMERIC;
  double xbar[3] = {0, 0, 0};
  for (int i = 0; i < n; i++)
    for (int k = 0; k < 3; k++) xbar[k] += points[3 * i + k];
  for (int k = 0; k < 3; k++) xbar[k] /= n;
  double h = 0.0;
  for (int i = 0; i < n; i++) {
    double r2 = 0.0;
    for (int k = 0; k < 3; k++) r2 += (points[3 * i + k] - xbar[k]) * (points[3 * i + k] - xbar[k]);
    h = fmax(h, r2);
  }
  h = sqrt(h);
  if (!(h > 0.0)) return NH_ERR_NUMERIC;
  /* Scatter matrix C = Σ y yᵀ, y = (x − x̄)/h; it depends on the points only. */
  double C[9] = {0};
  for (int i = 0; i < n; i++) {
    double y[3];
    for (int k = 0; k < 3; k++) y[k] = (points[3 * i + k] - xbar[k]) / h;
    for (int r = 0; r < 3; r++)
      for (int s = 0; s < 3; s++) C[3 * r + s] += y[r] * y[s];
  }
  double w[3], V[9];
  nh_mat3_sym_eigen(C, w, V);
  if (!(w[2] > NH_SPR_RCOND * w[0])) return NH_ERR_NUMERIC;
  double y0[3], vy[3], leverage = 1.0 / n;
  for (int k = 0; k < 3; k++) y0[k] = (x0[k] - xbar[k]) / h;
  for (int j = 0; j < 3; j++) {
    vy[j] = V[j] * y0[0] + V[3 + j] * y0[1] + V[6 + j] * y0[2];
    leverage += vy[j] * vy[j] / w[j];
  }
  if (!(leverage <= NH_SPR_MAX_LEVERAGE)) return NH_ERR_NUMERIC;
  /* p(x0) = v̄ + y0ᵀ C⁻¹ b = v̄ + Σ_i c_i (v_i − v̄), b = Σ_i y_i (v_i − v̄), with the
   * sample weights c_i = y_iᵀ C⁻¹ y0 = Σ_j (V_jᵀ y_i)(V_jᵀ y0) / w_j shared by
   * all m components. */
  double c_stack[256], *c = n <= 256 ? c_stack : nh_calloc((size_t)n, sizeof(double));
  if (!c) return NH_ERR_MEMORY;
  for (int i = 0; i < n; i++) {
    double y[3];
    for (int k = 0; k < 3; k++) y[k] = (points[3 * i + k] - xbar[k]) / h;
    c[i] = 0.0;
    for (int j = 0; j < 3; j++)
      c[i] += (V[j] * y[0] + V[3 + j] * y[1] + V[6 + j] * y[2]) * vy[j] / w[j];
  }
  for (int k = 0; k < m; k++) {
    double vbar = 0.0, fit = 0.0;
    for (int i = 0; i < n; i++) vbar += values[(size_t)m * i + k];
    vbar /= n;
    for (int i = 0; i < n; i++) fit += c[i] * (values[(size_t)m * i + k] - vbar);
    out[k] = vbar + fit;
  }
  if (c != c_stack) free(c);
  return NH_OK;
}

/* Shared, read-only data of a recovery. */
typedef struct {
  const nh_mesh *m;
  const int *start, *adj;     /* node -> leaves having it as a corner (CSR, ascending) */
  const double *centre;       /* 3 per cell */
  const double *stress;       /* nv per cell: the centre stresses of the fields */
  int nv;                     /* values per sample: 6 per field */
  const double *weight;       /* per cell: φ V */
  const unsigned char *hangs; /* per node: 1 if hanging */
} nh_spr_ctx;

/* Per-thread workspace: one per OpenMP thread (its error slot is its own, core/error.c). */
typedef struct {
  int *patch, *cand;
  int n_patch, cap_patch, cap_cand;
  double *points, *values;
  int cap_samples;
  unsigned char *in; /* per cell: 1 while the cell is in cand (all 0 between growths) */
} nh_spr_work;

static void nh_spr_work_free(nh_spr_work *w) {
  free(w->patch), free(w->cand), free(w->points), free(w->values), free(w->in);
  memset(w, 0, sizeof *w);
}

static int nh_spr_reserve_int(int **p, int *cap, int need) {
  if (need <= *cap) return 0;
  int c = *cap ? *cap : 64;
  while (c < need) c *= 2;
  NH_TRY(nh_realloc((void **)p, (size_t)c, sizeof(int)));
  *cap = c;
  return 0;
}

/* Replace the patch by every leaf that shares a corner with one of its cells,
 * in ascending order (the order of the fit's sums). The corners' lists hold
 * a cell up to 8 times over (a face node's 4 cells list 32 corners with up
 * to 8 cells each, 32 cells distinct), so duplicates are dropped as they
 * come, by a mark per cell, and the distinct cells sorted by insertion (the
 * lists arrive in ascending runs): a qsort of the whole
 * list was a tenth of an adaptive phantom run (docs/phantom.md, "Again
 * after the SPR patch growth and the needle's LAPACK calls"). */
static int nh_spr_grow(const nh_spr_ctx *x, nh_spr_work *w) {
  if (!w->in && !(w->in = nh_calloc((size_t)x->m->n_cells, 1))) return NH_ERR_MEMORY;
  int n = 0;
  for (int i = 0; i < w->n_patch; i++) {
    const int *corner = x->m->cells + 8 * w->patch[i];
    for (int a = 0; a < 8; a++) {
      int v = corner[a], len = x->start[v + 1] - x->start[v];
      if (nh_spr_reserve_int(&w->cand, &w->cap_cand, n + len)) return NH_ERR_MEMORY;
      for (const int *c = x->adj + x->start[v], *e = c + len; c < e; c++)
        if (!w->in[*c]) w->in[*c] = 1, w->cand[n++] = *c;
    }
  }
  for (int i = 1; i < n; i++) {
    int c = w->cand[i], j = i;
    for (; j > 0 && w->cand[j - 1] > c; j--) w->cand[j] = w->cand[j - 1];
    w->cand[j] = c;
  }
  for (int i = 0; i < n; i++) w->in[w->cand[i]] = 0;
  int *t = w->patch, tc = w->cap_patch;
  w->patch = w->cand, w->cap_patch = w->cap_cand, w->n_patch = n;
  w->cand = t, w->cap_cand = tc;
  return NH_OK;
}

/* σ*(node) for a non-hanging node with at least one leaf. */
static int nh_spr_node(const nh_spr_ctx *x, int node, nh_spr_work *w, double *out) {
  const int nv = x->nv;
  const int *own = x->adj + x->start[node];
  int n_own = x->start[node + 1] - x->start[node];
  if (nh_spr_reserve_int(&w->patch, &w->cap_patch, n_own)) return NH_ERR_MEMORY;
  memcpy(w->patch, own, sizeof(int) * (size_t)n_own);
  w->n_patch = n_own;
  const double *X0 = x->m->X + 3 * node;
  for (int ring = 0; ring <= 2; ring++) {
    if (ring > 0 && nh_spr_grow(x, w)) return NH_ERR_MEMORY;
    int n = w->n_patch;
    if (n < 4) continue;
    if (n > w->cap_samples) {
      int c = w->cap_samples ? w->cap_samples : 64;
      while (c < n) c *= 2;
      NH_TRY(nh_realloc((void **)&w->points, 3 * (size_t)c, sizeof(double)));
      NH_TRY(nh_realloc((void **)&w->values, (size_t)nv * (size_t)c, sizeof(double)));
      w->cap_samples = c;
    }
    for (int i = 0; i < n; i++) {
      int c = w->patch[i];
      memcpy(w->points + 3 * i, x->centre + 3 * c, 3 * sizeof(double));
      memcpy(w->values + (size_t)nv * i, x->stress + (size_t)nv * c, (size_t)nv * sizeof(double));
    }
    int rc = nh_spr_fit_patch_n(n, w->points, nv, w->values, X0, out);
    if (rc != NH_ERR_NUMERIC) return rc;
  }
  /* Still rank-deficient: the φV-weighted mean of the node's own patch. */
  double wsum = 0.0;
  for (int k = 0; k < nv; k++) out[k] = 0.0;
  for (int i = 0; i < n_own; i++) {
    int c = own[i];
    for (int k = 0; k < nv; k++) out[k] += x->weight[c] * x->stress[(size_t)nv * c + k];
    wsum += x->weight[c];
  }
  for (int k = 0; k < nv; k++) out[k] /= wsum;
  return NH_OK;
}

static int nh_spr_check(const nh_mesh *m, const nh_tissue *t, const nh_hanging *h) {
  NH_CHECK(m && t && t->mesh == m, NH_ERR_INTERNAL, "SPR: the tissue does not belong to the mesh");
  NH_CHECK(t->cap_cells >= m->n_cells, NH_ERR_INTERNAL,
           "SPR: the tissue has element data for %d cells, the mesh has %d (call "
           "nh_tissue_update after refinement)",
           t->cap_cells, m->n_cells);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    NH_CHECK(t->cell_shape[c] >= 0 && t->cell_shape[c] < t->n_shapes, NH_ERR_INTERNAL,
             "SPR: leaf %d has no element data (call nh_tissue_update after refinement)", c);
  }
  if (!h || h->n_hanging == 0) return NH_OK;
  NH_CHECK(h->n_hanging > 0 && h->node && h->start && h->master && h->weight, NH_ERR_INTERNAL,
           "SPR: malformed hanging-node table (%d nodes)", h->n_hanging);
  for (int k = 0; k < h->n_hanging; k++) {
    NH_CHECK(h->node[k] >= 0 && h->node[k] < m->n_nodes, NH_ERR_INTERNAL,
             "SPR: hanging node %d out of range", h->node[k]);
    NH_CHECK(h->start[k] <= h->start[k + 1], NH_ERR_INTERNAL,
             "SPR: hanging node %d has a negative master count", h->node[k]);
    for (int p = h->start[k]; p < h->start[k + 1]; p++)
      NH_CHECK(h->master[p] >= 0 && h->master[p] < m->n_nodes, NH_ERR_INTERNAL,
               "SPR: master %d of hanging node %d out of range", h->master[p], h->node[k]);
  }
  return NH_OK;
}

int nh_spr_recover(const nh_mesh *m, const nh_tissue *t, const double *u, const nh_hanging *h,
                   double *sigma_star) {
  NH_TRY(nh_spr_check(m, t, h));
  double *stress = nh_calloc(6 * (size_t)(m->n_cells ? m->n_cells : 1), sizeof(double));
  if (!stress) return NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR samples (%d cells)", m->n_cells);
  const int nl = m->n_leaves;
#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) nh_tissue_cell_stress(t, m->leaves[l], u, stress + 6 * m->leaves[l]);
  int rc = nh_spr_recover_fields(m, t, h, 1, stress, sigma_star);
  free(stress);
  return rc;
}

int nh_spr_recover_fields(const nh_mesh *m, const nh_tissue *t, const nh_hanging *h, int n_fields,
                          const double *stress, double *sigma_star) {
  NH_TRY(nh_spr_check(m, t, h));
  const int nv = 6 * n_fields;
  int nn = m->n_nodes, nl = m->n_leaves;
  double *centre = nh_calloc(3 * (size_t)m->n_cells, sizeof(double));
  double *weight = nh_calloc((size_t)m->n_cells, sizeof(double));
  int *start = NULL, *adj = NULL; /* node -> leaves (CSR, ascending) */
  unsigned char *hangs = nh_calloc((size_t)nn, 1);
  int rc = nh_mesh_node_leaves(m, &start, &adj);
  if (!rc && (!centre || !weight || !hangs))
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR workspace (%d nodes, %d cells)", nn,
                  m->n_cells);
  if (rc) goto done;

#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int k = 0; k < 3; k++) {
      double s = 0.0;
      for (int a = 0; a < 8; a++) s += Xe[3 * a + k];
      centre[3 * c + k] = 0.125 * s;
    }
    weight[c] = m->fill[c] * t->volume[t->cell_shape[c]];
  }

  if (h)
    for (int k = 0; k < h->n_hanging; k++) hangs[h->node[k]] = 1;
  if (h)
    for (int k = 0; k < h->n_hanging; k++)
      for (int p = h->start[k]; p < h->start[k + 1]; p++)
        if (hangs[h->master[p]]) {
          rc = NH_ERROR(NH_ERR_INTERNAL, "SPR: master %d of hanging node %d is itself hanging",
                        h->master[p], h->node[k]);
          goto done;
        }

  nh_spr_ctx x = {m, start, adj, centre, stress, nv, weight, hangs};
  int failed = 0;
#pragma omp parallel if (nn >= NH_SPR_PARALLEL_MIN)
  {
    nh_spr_work w;
    memset(&w, 0, sizeof w);
#pragma omp for schedule(dynamic, 64)
    for (int v = 0; v < nn; v++) {
      double *out = sigma_star + (size_t)nv * v;
      if (hangs[v] || start[v + 1] == start[v]) {
        memset(out, 0, (size_t)nv * sizeof(double));
        continue;
      }
      if (nh_spr_node(&x, v, &w, out)) {
#pragma omp atomic write
        failed = 1;
      }
    }
    nh_spr_work_free(&w);
  }
  if (failed) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR patch workspace");
    goto done;
  }
  if (h)
    for (int k = 0; k < h->n_hanging; k++) {
      double *out = sigma_star + (size_t)nv * h->node[k];
      for (int p = h->start[k]; p < h->start[k + 1]; p++)
        for (int i = 0; i < nv; i++)
          out[i] += h->weight[p] * sigma_star[(size_t)nv * h->master[p] + i];
    }

done:
  free(centre), free(weight), free(start), free(adj), free(hangs);
  return rc;
}

int nh_spr_estimate(const nh_mesh *m, const nh_tissue *t, const double *u, const nh_hanging *h,
                    double *eta_cell, double *eta, double *eta_rel) {
  NH_TRY(nh_spr_check(m, t, h));
  int nl = m->n_leaves;
  const size_t nl1 = (size_t)(nl > 0 ? nl : 1);
  double *sigma_star = nh_calloc(6 * (size_t)(m->n_nodes > 0 ? m->n_nodes : 1), sizeof(double));
  double *err2 = nh_calloc(nl1, sizeof(double)), *norm2 = nh_calloc(nl1, sizeof(double));
  double *stress = nh_calloc(6 * (size_t)(m->n_cells ? m->n_cells : 1), sizeof(double));
  double *sh = nh_calloc(48 * nl1, sizeof(double)), *detJ = nh_calloc(8 * nl1, sizeof(double));
  int rc = NH_OK;
  if (!sigma_star || !err2 || !norm2 || !stress || !sh || !detJ) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR estimate");
    goto done;
  }

  /* σₕ at the 8 Gauss points and, where the cell's rotation is the one
   * nh_tissue_cell_stress uses (every cell but a cut one), at the centre in
   * the same call (the 9th point): one polar decomposition per leaf and
   * step instead of two, the same numbers */
  static const double q = 0.57735026918962576451; /* 1/√3 */
  double xi[27], N[8][8];
  for (int g = 0; g < 8; g++) {
    for (int k = 0; k < 3; k++) xi[3 * g + k] = q * nh_hex_corner[g][k];
    nh_hex_shape(xi + 3 * g, N[g]);
  }
  xi[24] = xi[25] = xi[26] = 0.0;
#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    double Xe[24], ue[24], s9[54], det9[9];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    double lambda, mu;
    nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
    const double *G0 = t->G0 + 24 * t->cell_shape[c];
    const int centre = nh_tissue_g0(t, c) == G0;
    nh_hex_stress_at(Xe, ue, G0, nh_tissue_gbar(t, c), lambda, mu, centre ? 9 : 8, xi, s9, det9);
    memcpy(sh + 48 * (size_t)l, s9, 48 * sizeof(double));
    memcpy(detJ + 8 * (size_t)l, det9, 8 * sizeof(double));
    if (centre)
      memcpy(stress + 6 * (size_t)c, s9 + 48, 6 * sizeof(double));
    else
      nh_tissue_cell_stress(t, c, u, stress + 6 * (size_t)c);
  }
  rc = nh_spr_recover_fields(m, t, h, 1, stress, sigma_star);
  if (rc) goto done;

  int bad_cell = -1;
#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    const int *corner = m->cells + 8 * c;
    const double *shl = sh + 48 * (size_t)l, *dJ = detJ + 8 * (size_t)l;
    double e2 = 0.0, n2 = 0.0, lambda, mu;
    nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
    for (int g = 0; g < 8; g++) {
      if (!(dJ[g] > 0.0)) {
#pragma omp atomic write
        bad_cell = c;
      }
      double diff[6], e[6];
      for (int k = 0; k < 6; k++) {
        double s = 0.0;
        for (int a = 0; a < 8; a++) s += N[g][a] * sigma_star[6 * corner[a] + k];
        diff[k] = s - shl[6 * g + k];
      }
      nh_voigt_compliance(lambda, mu, diff, e);
      double de = 0.0;
      for (int k = 0; k < 6; k++) de += diff[k] * e[k];
      nh_voigt_compliance(lambda, mu, shl + 6 * g, e);
      double dn = 0.0;
      for (int k = 0; k < 6; k++) dn += shl[6 * g + k] * e[k];
      e2 += dJ[g] * de;
      n2 += dJ[g] * dn;
    }
    err2[l] = m->fill[c] * e2;
    norm2[l] = m->fill[c] * n2;
  }
  if (bad_cell >= 0) {
    rc = NH_ERROR(NH_ERR_INTERNAL, "SPR: leaf %d has a non-positive Jacobian at a Gauss point",
                  bad_cell);
    goto done;
  }
  double sum_err = 0.0, sum_norm = 0.0;
  for (int l = 0; l < nl; l++) {
    sum_err += err2[l];
    sum_norm += norm2[l];
    if (eta_cell) eta_cell[m->leaves[l]] = sqrt(fmax(err2[l], 0.0));
  }
  if (!isfinite(sum_err) || !isfinite(sum_norm)) {
    rc =
        NH_ERROR(NH_ERR_NUMERIC, "SPR: the error estimate is not finite (eta^2 = %g, |u|_E^2 = %g)",
                 sum_err, sum_norm);
    goto done;
  }
  if (eta) *eta = sqrt(sum_err);
  if (eta_rel) *eta_rel = sum_err + sum_norm > 0.0 ? sqrt(sum_err / (sum_norm + sum_err)) : 0.0;

done:
  free(sigma_star), free(err2), free(norm2), free(stress), free(sh), free(detJ);
  return rc;
}
