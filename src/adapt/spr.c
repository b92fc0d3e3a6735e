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
 * Cache. Steps 2-4 are linear in the centre stresses with weights that
 * depend on the mesh only: σ*(n) = v̄ + Σ_i c_i (v_i − v̄) over the patch's
 * samples (the fit), or Σ φV v / Σ φV (the fallback). nh_spr_estimate_cached
 * keeps every node's patch and weights (nh_spr_cache) and makes them again
 * only when the mesh is not the one they were made for: the key (leaves,
 * their corners, rest positions, φV, hanging nodes) is compared exactly at
 * every use, which costs one pass over the leaves. The adaptive phantom
 * (hex2) changes its mesh 5 times in 120 steps and made every patch, its
 * growth and its 3x3 eigen-decomposition at every step. A step then only
 * combines the stored weights with the new samples, by the same functions
 * in the same order as the node-by-node path: the results are bitwise the
 * same (tests/test_spr.c, through refinement and coarsening). The cache
 * also keeps every leaf's rest gradients and det J at the indicator's 9
 * points (nh_hex_rest_gradients), which step 5 recomputed at every step.
 *
 * A step's arithmetic. With the cache, σₕ at a leaf's 9 points comes from
 * nh_spr_point_stresses and the integrals of step 5 from
 * nh_spr_cell_error: the operations of nh_hex_stress_at and of the
 * point-by-point loop, in their order, one SIMD lane per point, so the
 * same bits (tests/test_spr.c compares the two paths by memcmp). The
 * rotation R of a leaf's stresses is the polar decomposition of F at its
 * centre, which the step's last assembly made too: when the caller hands
 * the frames of an assembly at this very u (nh_system_frames_at, which
 * compares u bitwise; on the adaptive phantom every estimate finds them),
 * R is read from them instead of decomposed again (a cut leaf, whose
 * frame has its own centre gradients, still decomposes). On the adaptive
 * hex2 phantom these cut SPR from 416 to 168 M instructions of a 120-step
 * run (docs/performance.md, "SPR's step").
 *
 * Workspace: per cell a centre, a centre stress and a weight (10 doubles);
 * the node-to-leaf adjacency (CSR, 8 ints per leaf); per thread the patch
 * lists, grown on demand; with a cache, the patches' weights (a cell and a
 * double per sample) and the estimate's arrays, kept between steps. Nodes
 * and cells are processed in parallel with OpenMP; every node's fit depends
 * only on its own sorted patch and every cell's integral only on its own
 * data, and the global sums are taken in leaf order after the parallel
 * loop, so the results are bitwise independent of the number of threads.
 *
 * Failure: NH_ERR_MEMORY if a workspace cannot be allocated (also inside the
 * parallel region, reported after it), NH_ERR_INTERNAL for inconsistent
 * input (tissue of another mesh, missing element data, a bad hanging-node
 * table), NH_ERR_NUMERIC if η is not finite. */
#include "adapt/adapt_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

/* Loops shorter than this run serially (thread start-up costs more). */
#define NH_SPR_PARALLEL_MIN 512

/* The indicator's points: the 2x2x2 Gauss points, then the centre. */
#define NH_SPR_POINTS 9
#define NH_SPR_Q      0.57735026918962576451 /* 1/√3 */
static const double *nh_spr_points(void) {
  /* ±1/√3 in nh_hex_corner's order */
  static const double xi[3 * NH_SPR_POINTS] = {
      -NH_SPR_Q, -NH_SPR_Q, -NH_SPR_Q, NH_SPR_Q, -NH_SPR_Q, -NH_SPR_Q, NH_SPR_Q,
      NH_SPR_Q,  -NH_SPR_Q, -NH_SPR_Q, NH_SPR_Q, -NH_SPR_Q, -NH_SPR_Q, -NH_SPR_Q,
      NH_SPR_Q,  NH_SPR_Q,  -NH_SPR_Q, NH_SPR_Q, NH_SPR_Q,  NH_SPR_Q,  NH_SPR_Q,
      -NH_SPR_Q, NH_SPR_Q,  NH_SPR_Q,  0,        0,         0};
  return xi;
}

static int nh_spr_recover_cached(nh_spr_cache *cache, const nh_mesh *m, const nh_tissue *t,
                                 const nh_hanging *h, int n_fields, const double *stress,
                                 double *sigma_star);

/* σₕ at the indicator's 9 points of a leaf, s[k][p], from its rotation R,
 * corotated displacements d and rest gradients by point last (gT[3a + j][p]
 * = ∂N_a/∂X_j at point p); theta_bar: B-bar's θ̄, NULL for the full
 * formulation. nh_hex_stress_at's arithmetic (fem/stress.c: H = Σₐ dₐ ⊗ gₐ,
 * S = μ (H + Hᵀ) + vol I, R S Rᵀ as nh_mat3_mul then nh_mat3_mul_nt), its
 * sums in its order, vectorised over the points: the same bits. S is
 * symmetric bit for bit (x + y = y + x), so its 6 distinct entries serve
 * for 9, and of R S Rᵀ only the 6 entries s needs are formed. */
NH_ADAPT_VECTOR_CLONES
static void nh_spr_point_stresses(const double R[9], const double d[24],
                                  const double gT[24][NH_SPR_POINTS], double lambda, double mu,
                                  const double *theta_bar, double s[6][NH_SPR_POINTS]) {
  enum { P = NH_SPR_POINTS };
  double H[9][P], vol[P];
  /* omp simd: one lane per point, each lane's sums in their order (GCC's
   * own vectoriser left these loops scalar) */
  for (int i = 0; i < 3; i++)
    for (int j = 0; j < 3; j++)
#pragma omp simd
      for (int p = 0; p < P; p++) {
        double h = 0.0;
        for (int a = 0; a < 8; a++) h += d[3 * a + i] * gT[3 * a + j][p];
        H[3 * i + j][p] = h;
      }
  if (theta_bar) { /* (λ + 2μ/3) θ̄ − 2μ/3 tr H, the constants as stress.c forms them */
    const double kt = (lambda + 2.0 * mu / 3.0) * *theta_bar, c = 2.0 * mu / 3.0;
#pragma omp simd
    for (int p = 0; p < P; p++) vol[p] = kt - c * (H[0][p] + H[4][p] + H[8][p]);
  } else {
#pragma omp simd
    for (int p = 0; p < P; p++) vol[p] = lambda * (H[0][p] + H[4][p] + H[8][p]);
  }
#pragma omp simd
  for (int p = 0; p < P; p++) {
    /* S (the + 0.0 of the off-diagonal entries as stress.c's: −0 becomes +0) */
    const double s00 = mu * (H[0][p] + H[0][p]) + vol[p], s11 = mu * (H[4][p] + H[4][p]) + vol[p],
                 s22 = mu * (H[8][p] + H[8][p]) + vol[p], s01 = mu * (H[1][p] + H[3][p]) + 0.0,
                 s02 = mu * (H[2][p] + H[6][p]) + 0.0, s12 = mu * (H[5][p] + H[7][p]) + 0.0;
    const double S[9] = {s00, s01, s02, s01, s11, s12, s02, s12, s22};
    double T[9]; /* R S */
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++)
        T[3 * i + j] = R[3 * i] * S[j] + R[3 * i + 1] * S[3 + j] + R[3 * i + 2] * S[6 + j];
    /* (T Rᵀ)_ij for (ij) = 00, 11, 22, 12, 02, 01 */
    static const int row[6] = {0, 1, 2, 1, 0, 0}, col[6] = {0, 1, 2, 2, 2, 1};
    for (int k = 0; k < 6; k++) {
      const double *Ti = T + 3 * row[k], *Rj = R + 3 * col[k];
      s[k][p] = Ti[0] * Rj[0] + Ti[1] * Rj[1] + Ti[2] * Rj[2];
    }
  }
}

/* σ* (6 values per node) at a cell's 8 Gauss points, s[i][g] = Σₐ N_a(g)
 * σ*_a,i (NT[a][g] = N_a(g)), each sum over a in order from 0 as the
 * point-by-point loop formed it, one SIMD lane per point (GCC's own
 * vectoriser left the loop scalar): the same bits. */
NH_ADAPT_VECTOR_CLONES
static void nh_spr_interpolate(const double *sigma_star, const int corner[8], const double NT[8][8],
                               double s[6][8]) {
  double v[8][6]; /* local: no aliasing with sigma_star */
  for (int a = 0; a < 8; a++) memcpy(v[a], sigma_star + 6 * (size_t)corner[a], sizeof v[a]);
  for (int i = 0; i < 6; i++)
#pragma omp simd
    for (int g = 0; g < 8; g++) {
      double acc = 0.0;
      for (int a = 0; a < 8; a++) acc += NT[a][g] * v[a][i];
      s[i][g] = acc;
    }
}

/* A leaf's integrands at its 8 Gauss points, summed: *e2 = Σ_g det J_g dᵀD⁻¹d
 * (d = σ* − σₕ) and *n2 = Σ_g det J_g σₕᵀD⁻¹σₕ, from σ* and σₕ by point last
 * (star[k][g], sh[k][g]). D⁻¹ as nh_voigt_compliance forms it and each sum
 * in the order of the point-by-point loop (over k, then g): the same bits,
 * the points vectorised. */
NH_ADAPT_VECTOR_CLONES
static void nh_spr_cell_error(const double star[6][8], const double sh[6][8], const double dJ[8],
                              double lambda, double mu, double *e2, double *n2) {
  const double kl = lambda / (3.0 * lambda + 2.0 * mu);
  double de[8], dn[8];
#pragma omp simd
  for (int g = 0; g < 8; g++) {
    double df[6], sd = 0.0, sn = 0.0;
    for (int k = 0; k < 6; k++) df[k] = star[k][g] - sh[k][g];
    const double kd = kl * (df[0] + df[1] + df[2]), kn = kl * (sh[0][g] + sh[1][g] + sh[2][g]);
    for (int k = 0; k < 3; k++) sd += df[k] * ((df[k] - kd) / (2.0 * mu));
    for (int k = 3; k < 6; k++) sd += df[k] * (df[k] / mu);
    for (int k = 0; k < 3; k++) sn += sh[k][g] * ((sh[k][g] - kn) / (2.0 * mu));
    for (int k = 3; k < 6; k++) sn += sh[k][g] * (sh[k][g] / mu);
    de[g] = sd, dn[g] = sn;
  }
  double se = 0.0, sn = 0.0;
  for (int g = 0; g < 8; g++) se += dJ[g] * de[g], sn += dJ[g] * dn[g];
  *e2 = se, *n2 = sn;
}
static int nh_spr_estimate_with(nh_spr_cache *ws, nh_spr_cache *weights, const nh_mesh *m,
                                const nh_tissue *t, const double *u, const nh_hanging *h,
                                const double *frames, double *eta_cell, double *eta,
                                double *eta_rel);

int nh_spr_fit_patch(int n, const double *points, const double *values, const double x0[3],
                     double out[6]) {
  return nh_spr_fit_patch_n(n, points, 6, values, x0, out);
}

/* The sample weights of a patch's fit at x0 (see nh_spr_fit_patch_n):
 * p(x0) = v̄ + Σ_i c_i (v_i − v̄) for any values v_i at the points. They
 * depend on the points only. NH_ERR_NUMERIC (no message) as nh_spr_fit_patch. */
static int nh_spr_fit_weights(int n, const double *points, const double x0[3], double *c) {
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
   * all components. */
  for (int i = 0; i < n; i++) {
    double y[3];
    for (int k = 0; k < 3; k++) y[k] = (points[3 * i + k] - xbar[k]) / h;
    c[i] = 0.0;
    for (int j = 0; j < 3; j++)
      c[i] += (V[j] * y[0] + V[3 + j] * y[1] + V[6 + j] * y[2]) * vy[j] / w[j];
  }
  return NH_OK;
}

/* out[k] = v̄ + Σ_i c_i (v_i − v̄) for the m components of the samples
 * values[m id_i + k], id_i = cells[i] (or i if cells is NULL). The samples
 * are read row by row (a sample's m components are contiguous; the goal
 * estimate recovers 6 (1 + 36) of them at once). SPR's own 6 components
 * (m = 6 with cells, every step of an SPR run) take v̄ first, then the fit,
 * in two passes. Any other m takes one pass with per-sample weights:
 *   v̄ + Σ_i c_i (v_i − v̄) = Σ_i w_i v_i,  w_i = c_i + (1 − Σ_j c_j) / n
 * (Σ c_j = 0 in exact arithmetic, as Σ y_i = 0; kept so that the identity
 * holds for the c as computed): half the reads of the samples. The two
 * forms differ at round-off, about eps (1 + Σ |c_i|) relative to the
 * largest |v_i|, where Σ c_i² = y0ᵀ C⁻¹ y0 = leverage − 1/n, so
 * Σ |c_i| <= √(n NH_SPR_MAX_LEVERAGE). */
NH_ADAPT_V4_CLONES
static void nh_spr_fit_combine(int n, const int *cells, const double *c, int m,
                               const double *values, double *out) {
  enum { CHUNK = 64, V = CHUNK / 4 };
  if (m == 6 && cells) { /* SPR's own 6 components (every step): the sums below, unrolled */
    double vbar[6] = {0}, fit[6] = {0};
    for (int i = 0; i < n; i++) {
      const double *v = values + 6 * (size_t)cells[i];
      for (int k = 0; k < 6; k++) vbar[k] += v[k];
    }
    for (int k = 0; k < 6; k++) vbar[k] /= n;
    for (int i = 0; i < n; i++) {
      const double *v = values + 6 * (size_t)cells[i];
      for (int k = 0; k < 6; k++) fit[k] += c[i] * (v[k] - vbar[k]);
    }
    for (int k = 0; k < 6; k++) out[k] = vbar[k] + fit[k];
    return;
  }
  double csum = 0.0;
  for (int i = 0; i < n; i++) csum += c[i];
  const double a = (1.0 - csum) / n;
  /* the components in chunks of at most 64, 4 at a time (a chunk's sums in
   * vector registers; GCC's own vectoriser took a shorter last chunk, 30 of
   * the goal estimate's 222, one component at a time), the last < 4 alone */
  for (int k0 = 0; k0 < m; k0 += CHUNK) {
    const int mk = m - k0 < CHUNK ? m - k0 : CHUNK, m4 = mk / 4;
    nh_v4 fit[V], x;
    double tail[3] = {0.0, 0.0, 0.0};
    for (int q = 0; q < V; q++) fit[q] = (nh_v4){0.0, 0.0, 0.0, 0.0};
    for (int i = 0; i < n; i++) {
      const double *v = values + (size_t)m * (cells ? cells[i] : i) + k0, w = c[i] + a;
      for (int q = 0; q < m4; q++) NH_V4_LOAD(x, v + 4 * q), fit[q] += w * x;
      for (int k = 4 * m4; k < mk; k++) tail[k - 4 * m4] += w * v[k];
    }
    for (int q = 0; q < m4; q++) memcpy(out + k0 + 4 * q, &fit[q], sizeof fit[q]);
    for (int k = 4 * m4; k < mk; k++) out[k0 + k] = tail[k - 4 * m4];
  }
}

/* The fallback: out[k] = Σ_i w_i v_i / Σ_i w_i over cells[0..n). */
static void nh_spr_mean(int n, const int *cells, const double *w, int m, const double *values,
                        double *out) {
  double wsum = 0.0;
  for (int k = 0; k < m; k++) out[k] = 0.0;
  for (int i = 0; i < n; i++) {
    for (int k = 0; k < m; k++) out[k] += w[i] * values[(size_t)m * cells[i] + k];
    wsum += w[i];
  }
  for (int k = 0; k < m; k++) out[k] /= wsum;
}

int nh_spr_fit_patch_n(int n, const double *points, int m, const double *values, const double x0[3],
                       double *out) {
  if (n < 4) return NH_ERR_NUMERIC;
  double c_stack[256], *c = n <= 256 ? c_stack : nh_calloc((size_t)n, sizeof(double));
  if (!c) return NH_ERR_MEMORY;
  int rc = nh_spr_fit_weights(n, points, x0, c);
  if (!rc) nh_spr_fit_combine(n, NULL, c, m, values, out);
  if (c != c_stack) free(c);
  return rc;
}

/* Shared, read-only data of a recovery. */
typedef struct {
  const nh_mesh *m;
  const nh_tissue *t;
  const int *start, *adj;     /* node -> leaves having it as a corner (CSR, ascending) */
  const double *centre;       /* 3 per cell */
  const double *weight;       /* per cell: φ V */
  const unsigned char *hangs; /* per node: 1 if hanging */
} nh_spr_ctx;

/* Per-thread workspace: one per OpenMP thread (its error slot is its own, core/error.c). */
typedef struct {
  int *patch, *cand;
  int n_patch, cap_patch, cap_cand;
  double *points, *c; /* the patch's centres (3 each) and sample weights */
  int cap_samples;
  unsigned char *in; /* per cell: 1 while the cell is in cand (all 0 between growths) */
} nh_spr_work;

static void nh_spr_work_free(nh_spr_work *w) {
  free(w->patch), free(w->cand), free(w->points), free(w->c), free(w->in);
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

static int nh_spr_reserve_samples(nh_spr_work *w, int n) {
  if (n <= w->cap_samples) return NH_OK;
  int c = w->cap_samples ? w->cap_samples : 64;
  while (c < n) c *= 2;
  NH_TRY(nh_realloc((void **)&w->points, 3 * (size_t)c, sizeof(double)));
  NH_TRY(nh_realloc((void **)&w->c, (size_t)c, sizeof(double)));
  w->cap_samples = c;
  return NH_OK;
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

/* How σ*(node) is made from the centre samples, for a non-hanging node with at
 * least one leaf: the fit of its patch, grown as the file's essay says
 * (*fitted = 1: the cells w->patch[0..n_patch) with the fit's sample weights
 * w->c, nh_spr_fit_combine), or, every patch refused, the φV-weighted mean of
 * its own leaves (*fitted = 0: the cells in w->patch, their φV in w->c,
 * nh_spr_mean). It depends on the mesh only. NH_ERR_MEMORY (no message). */
static int nh_spr_node_weights(const nh_spr_ctx *x, int node, nh_spr_work *w, int *fitted) {
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
    NH_TRY(nh_spr_reserve_samples(w, n));
    for (int i = 0; i < n; i++)
      memcpy(w->points + 3 * i, x->centre + 3 * w->patch[i], 3 * sizeof(double));
    int rc = nh_spr_fit_weights(n, w->points, X0, w->c);
    if (rc != NH_ERR_NUMERIC) {
      *fitted = 1;
      return rc;
    }
  }
  /* Still rank-deficient: the φV-weighted mean of the node's own patch. */
  NH_TRY(nh_spr_reserve_samples(w, n_own));
  memcpy(w->patch, own, sizeof(int) * (size_t)n_own);
  w->n_patch = n_own;
  for (int i = 0; i < n_own; i++) w->c[i] = x->weight[own[i]];
  *fitted = 0;
  return NH_OK;
}

/* The mesh-dependent part of a recovery (nh_spr_cache): every node's
 * weights as nh_spr_node_weights makes them, in node order (CSR), and the
 * key they were made for (key.c, with each leaf's φV and the hanging
 * nodes), so any change of the mesh (a refinement and a coarsening that
 * leave the counts as they were included) makes them again. The workspace of nh_spr_estimate
 * lives here too, so a step allocates nothing. */
struct nh_spr_cache {
  int builds;
  nh_mesh_key key; /* key.c, with each leaf's φV */
  /* the weights: node v's samples are cell[start[v] .. start[v + 1]) with coef[];
   * fitted[v]: 1 a fit (nh_spr_fit_combine), 0 the mean (nh_spr_mean), -1 no σ* (0) */
  int *start, *cell;
  signed char *fitted;
  double *coef;
  int cap_coef;
  /* per leaf the rest gradients at the indicator's 9 points (the 8 Gauss
   * points, then the centre; nh_hex_rest_gradients), by point last
   * (grad[24 9 l + 9 r + p]: entry r of point p), and det J there */
  double *grad, *grad_det;
  /* nh_spr_estimate's workspace, sized by the mesh */
  double *sigma_star, *err2, *norm2, *stress, *sh, *detJ;
  int cap_ws_nodes, cap_ws_cells, cap_ws_leaves;
};

int nh_spr_cache_create(nh_spr_cache **out) {
  *out = nh_calloc(1, sizeof **out);
  return *out ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR cache");
}

void nh_spr_cache_destroy(nh_spr_cache **cache) {
  if (!cache || !*cache) return;
  nh_spr_cache *k = *cache;
  nh_mesh_key_free(&k->key);
  free(k->start), free(k->cell), free(k->fitted), free(k->coef), free(k->grad), free(k->grad_det);
  free(k->sigma_star), free(k->err2), free(k->norm2), free(k->stress), free(k->sh), free(k->detJ);
  free(k);
  *cache = NULL;
}

int nh_spr_cache_builds(const nh_spr_cache *cache) {
  return cache ? cache->builds : 0;
}

/* Make every node's weights (serially: this runs once per mesh) and the key. */
static int nh_spr_cache_build(nh_spr_cache *k, const nh_spr_ctx *x, const nh_hanging *h) {
  const nh_mesh *m = x->m;
  const int nn = m->n_nodes, nl = m->n_leaves;
  k->key.valid = 0;
  NH_TRY(nh_realloc((void **)&k->start, (size_t)nn + 1, sizeof(int)));
  NH_TRY(nh_realloc((void **)&k->fitted, (size_t)nn + 1, 1));
  nh_spr_work w;
  memset(&w, 0, sizeof w);
  int rc = NH_OK, used = 0;
  for (int v = 0; v < nn && !rc; v++) {
    k->start[v] = used;
    k->fitted[v] = -1;
    if (x->hangs[v] || x->start[v + 1] == x->start[v]) continue;
    int fitted;
    if ((rc = nh_spr_node_weights(x, v, &w, &fitted))) break;
    k->fitted[v] = (signed char)fitted;
    if (used + w.n_patch > k->cap_coef) {
      int c = k->cap_coef ? k->cap_coef : 1024;
      while (c < used + w.n_patch) c *= 2;
      if ((rc = nh_realloc((void **)&k->cell, (size_t)c, sizeof(int))) ||
          (rc = nh_realloc((void **)&k->coef, (size_t)c, sizeof(double))))
        break;
      k->cap_coef = c;
    }
    memcpy(k->cell + used, w.patch, sizeof(int) * (size_t)w.n_patch);
    memcpy(k->coef + used, w.c, sizeof(double) * (size_t)w.n_patch);
    used += w.n_patch;
  }
  nh_spr_work_free(&w);
  if (rc) return rc;
  k->start[nn] = used;
  NH_TRY(nh_realloc((void **)&k->grad, NH_SPR_POINTS * 24 * (size_t)nl + 1, sizeof(double)));
  NH_TRY(nh_realloc((void **)&k->grad_det, NH_SPR_POINTS * (size_t)nl + 1, sizeof(double)));
  const double *xi = nh_spr_points();
  for (int l = 0; l < nl; l++) {
    const int c = m->leaves[l];
    double Xe[24], g[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    const double *G0 = x->t->G0 + 24 * x->t->cell_shape[c];
    double *gT = k->grad + 24 * NH_SPR_POINTS * (size_t)l; /* by point last */
    for (int p = 0; p < NH_SPR_POINTS; p++) {
      k->grad_det[NH_SPR_POINTS * (size_t)l + p] = nh_hex_rest_gradients(Xe, G0, xi + 3 * p, g);
      for (int r = 0; r < 24; r++) gT[NH_SPR_POINTS * r + p] = g[r];
    }
  }
  NH_TRY(nh_mesh_key_set(&k->key, m, x->weight, h));
  k->builds++;
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

/* nh_spr_recover_fields with the mesh-dependent weights from the cache
 * (made again when the mesh is not the one they were made for), or, cache
 * NULL, made node by node as the recovery goes. Bitwise the same either way:
 * the same weights, combined by the same functions. n_fields = 0: only
 * bring the cache to this mesh (stress and sigma_star unused). */
static int nh_spr_recover_cached(nh_spr_cache *cache, const nh_mesh *m, const nh_tissue *t,
                                 const nh_hanging *h, int n_fields, const double *stress,
                                 double *sigma_star) {
  NH_TRY(nh_spr_check(m, t, h));
  const int nv = 6 * n_fields;
  int nn = m->n_nodes, nl = m->n_leaves;
  double *centre = nh_calloc(3 * (size_t)m->n_cells, sizeof(double));
  double *weight = nh_calloc((size_t)m->n_cells, sizeof(double));
  int *start = NULL, *adj = NULL; /* node -> leaves (CSR, ascending) */
  unsigned char *hangs = nh_calloc((size_t)nn, 1);
  int rc = NH_OK;
  if (!centre || !weight || !hangs)
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR workspace (%d nodes, %d cells)", nn,
                  m->n_cells);
  if (rc) goto done;

#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
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

  const int cached = cache && nh_mesh_key_matches(&cache->key, m, weight, h);
  if (!cached) { /* the patches' geometry: centres and the node-to-leaf lists */
    if ((rc = nh_mesh_node_leaves(m, &start, &adj))) goto done;
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
    }
  }
  nh_spr_ctx x = {m, t, start, adj, centre, weight, hangs};
  if (cache && !cached) {
    if ((rc = nh_spr_cache_build(cache, &x, h))) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR cache (%d nodes)", nn);
      goto done;
    }
  }
  int failed = 0;
  if (n_fields == 0) goto done; /* the cache brought to this mesh only */
  if (cache) {
    const nh_spr_cache *k = cache;
#pragma omp parallel for schedule(static) if (nn >= NH_SPR_PARALLEL_MIN)
    for (int v = 0; v < nn; v++) {
      double *out = sigma_star + (size_t)nv * v;
      const int b = k->start[v], n = k->start[v + 1] - b;
      if (k->fitted[v] == 1)
        nh_spr_fit_combine(n, k->cell + b, k->coef + b, nv, stress, out);
      else if (k->fitted[v] == 0)
        nh_spr_mean(n, k->cell + b, k->coef + b, nv, stress, out);
      else
        memset(out, 0, (size_t)nv * sizeof(double));
    }
  } else {
#pragma omp parallel if (nn >= NH_SPR_PARALLEL_MIN)
    {
      nh_spr_work w;
      memset(&w, 0, sizeof w);
#pragma omp for schedule(dynamic, 64)
      for (int v = 0; v < nn; v++) {
        double *out = sigma_star + (size_t)nv * v;
        int fitted;
        if (hangs[v] || start[v + 1] == start[v])
          memset(out, 0, (size_t)nv * sizeof(double));
        else if (nh_spr_node_weights(&x, v, &w, &fitted)) {
#pragma omp atomic write
          failed = 1;
        } else if (fitted)
          nh_spr_fit_combine(w.n_patch, w.patch, w.c, nv, stress, out);
        else
          nh_spr_mean(w.n_patch, w.patch, w.c, nv, stress, out);
      }
      nh_spr_work_free(&w);
    }
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

int nh_spr_recover_fields(const nh_mesh *m, const nh_tissue *t, const nh_hanging *h, int n_fields,
                          const double *stress, double *sigma_star) {
  return nh_spr_recover_cached(NULL, m, t, h, n_fields, stress, sigma_star);
}

int nh_spr_estimate(const nh_mesh *m, const nh_tissue *t, const double *u, const nh_hanging *h,
                    double *eta_cell, double *eta, double *eta_rel) {
  nh_spr_cache *ws = NULL; /* the workspace of this call; the weights made node by node */
  int rc = nh_spr_cache_create(&ws);
  if (!rc) rc = nh_spr_estimate_with(ws, NULL, m, t, u, h, NULL, eta_cell, eta, eta_rel);
  nh_spr_cache_destroy(&ws);
  return rc;
}

/* nh_spr_estimate's workspace in the cache, grown to the mesh. */
static int nh_spr_workspace(nh_spr_cache *k, const nh_mesh *m) {
  const int nn = m->n_nodes > 0 ? m->n_nodes : 1, nc = m->n_cells ? m->n_cells : 1,
            nl = m->n_leaves > 0 ? m->n_leaves : 1;
  if (nn > k->cap_ws_nodes) {
    NH_TRY(nh_realloc((void **)&k->sigma_star, 6 * (size_t)nn, sizeof(double)));
    k->cap_ws_nodes = nn;
  }
  if (nc > k->cap_ws_cells) {
    NH_TRY(nh_realloc((void **)&k->stress, 6 * (size_t)nc, sizeof(double)));
    k->cap_ws_cells = nc;
  }
  if (nl > k->cap_ws_leaves) {
    NH_TRY(nh_realloc((void **)&k->err2, (size_t)nl, sizeof(double)));
    NH_TRY(nh_realloc((void **)&k->norm2, (size_t)nl, sizeof(double)));
    NH_TRY(nh_realloc((void **)&k->sh, 48 * (size_t)nl, sizeof(double)));
    NH_TRY(nh_realloc((void **)&k->detJ, 8 * (size_t)nl, sizeof(double)));
    k->cap_ws_leaves = nl;
  }
  return NH_OK;
}

int nh_spr_estimate_cached(nh_spr_cache *cache, const nh_mesh *m, const nh_tissue *t,
                           const double *u, const nh_hanging *h, const double *frames,
                           double *eta_cell, double *eta, double *eta_rel) {
  return nh_spr_estimate_with(cache, cache, m, t, u, h, frames, eta_cell, eta, eta_rel);
}

/* The estimate with the workspace of ws and the recovery's weights from
 * weights (nh_spr_recover_cached; NULL: node by node). frames (with
 * weights only; may be NULL): an assembly's frames at u
 * (nh_system_frames_at), whose rotations are the ones the stresses need. */
static int nh_spr_estimate_with(nh_spr_cache *ws, nh_spr_cache *weights, const nh_mesh *m,
                                const nh_tissue *t, const double *u, const nh_hanging *h,
                                const double *frames, double *eta_cell, double *eta,
                                double *eta_rel) {
  NH_TRY(nh_spr_check(m, t, h));
  int nl = m->n_leaves;
  if (nh_spr_workspace(ws, m))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: SPR estimate (%d leaves)", nl);
  /* every entry read below is written first (σ* of every node, the
   * samples and sums of every leaf) */
  double *sigma_star = ws->sigma_star, *err2 = ws->err2, *norm2 = ws->norm2, *stress = ws->stress,
         *sh = ws->sh, *detJ = ws->detJ;
  int rc = NH_OK;

  /* σₕ at the 8 Gauss points and, where the cell's rotation is the one
   * nh_tissue_cell_stress uses (every cell but a cut one), at the centre in
   * the same call (the 9th point): one rotation per leaf and step instead of
   * two, the same numbers. With the cache, the rest gradients are its own
   * (made for this mesh first) and the rotation R of such a leaf is taken
   * from the frames when given: the assembly's polar decomposition of the
   * same F (nh_hex_corotated's, at the same u, X and centre gradients). */
  const double *xi = nh_spr_points();
  double NT[8][8]; /* NT[a][g] = N_a at Gauss point g */
  for (int g = 0; g < 8; g++) {
    double N[8];
    nh_hex_shape(xi + 3 * g, N);
    for (int a = 0; a < 8; a++) NT[a][g] = N[a];
  }
  if (weights) NH_TRY(nh_spr_recover_cached(weights, m, t, h, 0, NULL, NULL));
#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    double Xe[24], ue[24], s9[6][NH_SPR_POINTS];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    double lambda, mu;
    nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
    const double *G0 = t->G0 + 24 * t->cell_shape[c], *Gbar = nh_tissue_gbar(t, c);
    const int centre = nh_tissue_g0(t, c) == G0;
    if (weights) {
      double R[9], d[24], theta = Gbar ? nh_hex_mean_dilatation(ue, Gbar, NULL) : 0.0;
      if (frames && centre) {
        memcpy(R, frames + NH_HEX_FRAME * (size_t)l + NH_FRAME_R, sizeof R);
        nh_hex_corotate(Xe, ue, R, d);
      } else {
        nh_hex_corotated(Xe, ue, G0, R, d);
      }
      nh_spr_point_stresses(
          R, d, (const double(*)[NH_SPR_POINTS])(weights->grad + 24 * NH_SPR_POINTS * (size_t)l),
          lambda, mu, Gbar ? &theta : NULL, s9);
    } else {
      double s[6 * NH_SPR_POINTS], det9[NH_SPR_POINTS];
      nh_hex_stress_at(Xe, ue, G0, Gbar, lambda, mu, centre ? 9 : 8, xi, s, det9);
      memcpy(detJ + 8 * (size_t)l, det9, 8 * sizeof(double));
      for (int p = 0; p < (centre ? 9 : 8); p++)
        for (int k = 0; k < 6; k++) s9[k][p] = s[6 * p + k];
    }
    for (int k = 0; k < 6; k++) /* σₕ by point last (sh[48 l + 8k + g]) */
      memcpy(sh + 48 * (size_t)l + 8 * k, s9[k], 8 * sizeof(double));
    if (centre)
      for (int k = 0; k < 6; k++) stress[6 * (size_t)c + k] = s9[k][8];
    else
      nh_tissue_cell_stress(t, c, u, stress + 6 * (size_t)c);
  }
  rc = nh_spr_recover_cached(weights, m, t, h, 1, stress, sigma_star);
  if (rc) return rc;

  int bad_cell = -1;
#pragma omp parallel for schedule(static) if (nl >= NH_SPR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    const double *dJ =
        weights ? weights->grad_det + NH_SPR_POINTS * (size_t)l : detJ + 8 * (size_t)l;
    double star[6][8], e2, n2, lambda, mu;
    nh_tissue_cell_material(t, c, &lambda, &mu, NULL);
    for (int g = 0; g < 8; g++)
      if (!(dJ[g] > 0.0)) {
#pragma omp atomic write
        bad_cell = c;
      }
    nh_spr_interpolate(sigma_star, m->cells + 8 * c, (const double(*)[8])NT, star);
    nh_spr_cell_error((const double(*)[8])star, (const double(*)[8])(sh + 48 * (size_t)l), dJ,
                      lambda, mu, &e2, &n2);
    err2[l] = m->fill[c] * e2;
    norm2[l] = m->fill[c] * n2;
  }
  if (bad_cell >= 0)
    return NH_ERROR(NH_ERR_INTERNAL, "SPR: leaf %d has a non-positive Jacobian at a Gauss point",
                    bad_cell);
  double sum_err = 0.0, sum_norm = 0.0;
  for (int l = 0; l < nl; l++) {
    sum_err += err2[l];
    sum_norm += norm2[l];
    if (eta_cell) eta_cell[m->leaves[l]] = sqrt(fmax(err2[l], 0.0));
  }
  if (!isfinite(sum_err) || !isfinite(sum_norm))
    return NH_ERROR(NH_ERR_NUMERIC,
                    "SPR: the error estimate is not finite (eta^2 = %g, |u|_E^2 = %g)", sum_err,
                    sum_norm);
  if (eta) *eta = sqrt(sum_err);
  if (eta_rel) *eta_rel = sum_err + sum_norm > 0.0 ? sqrt(sum_err / (sum_norm + sum_err)) : 0.0;
  return rc;
}
