/* cutcell.c — the finite cell quadrature of a cut cell (docs/theory.md §5b,
 * "Cut cells: the finite cell quadrature").
 *
 * What it computes. For a leaf cell whose rest shape is the axis-aligned box
 * [lo, hi], with natural coordinates ξ ∈ [-1, 1]³ (x = mid + half ξ), the
 * part Ω_c of the cell where every implicit set of the spec is negative:
 *   the tissue {F < 0}     F = spec->level (every nh_domain: 1-Lipschitz);
 *   a region               a box (its six planes), a sphere (|x − c| − r) or
 *                          a cylinder (distance to its axis − r, and the two
 *                          planes of its ends);
 *   a half-space           (x − p)·n < 0 (the drainage level),
 * and of it
 *   the moments   M_ijk = ∫_{Ω_c} ξ^i η^j ζ^k dV,   i, j, k <= 2  (the space Q2),
 *   its volume M_000 and centroid mid + half M_(e_k) / M_000,
 *   optionally a surface quadrature of ∂Ω_c ∩ {F = 0} (and of the cell faces
 *   the caller names: the grid's boundary where the tissue leaves it).
 * From the moments, nh_cut_fit gives weights at the 27 Gauss points of the
 * cell (moment fitting): w = (V⁻¹ ⊗ V⁻¹ ⊗ V⁻¹) M with V_ia = g_a^i, i.e.
 * w_q = ∫_{Ω_c} L_q dV with L_q the Lagrange polynomial of Q2 at point q.
 * The rule integrates every polynomial of Q2 exactly, hence exactly every
 * entry of BᵀDB (∂N_a/∂ξ_k is linear in the two other coordinates), of
 * N_a N_b (ties, consistent mass), N_a (body forces, lumped mass) and ∇N_a
 * (mean gradients of B-bar) of a trilinear box cell: the fitted stiffness
 * Σ_q w_q BᵀDB(ξ_q) IS ∫_{Ω_c} BᵀDB dV, positive semidefinite although some
 * w_q may be negative (a small corner piece gives negative weights).
 * Integrands outside Q2 (the corotated force of a rotating cell, det F̄)
 * are only approximated, and there a negative weight is not harmless.
 *
 * The reconstruction. Each nonlinear set g has a lattice of 2^d sub-boxes
 * per cell edge: d = spec->depth for the tissue; for a sphere or cylinder
 * the smallest d whose sub-box edge is at most nh_region_size / region_sub
 * (default 8), so that a region smaller than a cell, or than the tissue's
 * sub-box, is still resolved, and at least the tissue's depth, so that the
 * region is never reconstructed coarser than the tissue (with size / 8
 * alone, cells under 2 size / 8 took depth 1, sub-boxes of h/2: a cap of
 * radius 8 mm on a ball had −0.78 % of its volume on 32³ cells, −0.85 % on
 * 16³; now −0.21 %, a quarter per halving from 16³ on: tests/test_fcm.c,
 * part 7). g is replaced by its piecewise linear
 * interpolant on the Kuhn (Freudenthal) triangulation of that lattice: every
 * sub-box split into the six tetrahedra around its main diagonal (corner
 * (0,0,0) to (1,1,1)), reflected in each axis k on the upper side of
 * spec->mirror (nh_cut_flip: the grid's centre, so that the triangulation,
 * and every weight, is mirror symmetric; a per-axis slab reflection keeps it
 * conforming and nested), the split of src/fem/traction.c, so that the volume's
 * boundary is the surface that traction.c integrates pressure over: one
 * geometry. Inside a sub-box with local coordinates u ∈ [0, 1]³ sorted
 * u_a >= u_b >= u_c that interpolant is
 *     I g = g_000 + u_a (g_a − g_000) + u_b (g_ab − g_a) + u_c (g_111 − g_ab).
 * The Kuhn triangulation of the lattice 2^(d+1) refines the one of 2^d (its
 * hyperplanes x_i = k, x_i − x_j = k are a subset), so on every tetrahedron
 * of a finer lattice each set's interpolant is linear: all sets are clipped
 * on the tetrahedra of the finest lattice a sub-box needs. Planes are linear:
 * they are used exactly, at any depth. The error of the geometry is that of
 * linear interpolation, O(s²) with s the sub-box edge (one-signed for a
 * convex F: I F >= F, the reconstructed ball lies inside the ball).
 *
 * The octree. A sub-box at depth t is classified per set: inside (the whole
 * box), outside, or cut. For t below a set's lattice depth by the Lipschitz
 * bound at its centre (|g(centre)| > L · half-diagonal: g keeps its sign in
 * the box, and so does its interpolant, whose values at the lattice points
 * inside the box are values of g); at or below its lattice by the 8 corner
 * values of the interpolant (which is linear on the box's Kuhn tetrahedra,
 * so they bound it). A box outside one set is dropped; inside all, its
 * moments are added in closed form; otherwise it is split into 8 until the
 * deepest lattice of the sets that cut it, and there its six tetrahedra are
 * clipped. The result is the integral over the reconstruction, whatever the
 * octree visited: with the same lattice, a cell's moments equal the sum of
 * its 8 children's (tests/test_cutcell.c). F is evaluated at lattice points
 * only, each once (a cache of (2^d + 1)³ values per call).
 *
 * Clipping. A tetrahedron whose vertices carry the values of every cut set
 * (attributes interpolated linearly along edges: they stay the linear
 * interpolants) is cut by one set after the other, depth first: 1 vertex
 * inside gives a tetrahedron, 2 a prism of 3 tetrahedra, 3 the tetrahedron
 * less the one at its outside vertex (moments with a sign). A Kuhn
 * tetrahedron that no set clips is integrated in closed form: with local
 * coordinates u of its box, ∫ u_a^p u_b^q u_c^r over {u_a >= u_b >= u_c}
 * = 1 / ((r + 1)(r + q + 2)(r + q + p + 3)), taken to ξ binomially. Other
 * pieces are integrated in natural coordinates by the Grundmann–Möller rule
 * of degree 7 (35 points; "Invariant integration formulas for the n-simplex
 * by combinatorial methods", 1978): exact for ξ^i η^j ζ^k up to degree 6.
 * Where the tissue's set is clipped, the cut polygon (a triangle, or a quad
 * as two) is the piece of {F = 0}; it is clipped by the sets after it
 * (Sutherland–Hodgman), and each triangle gives 3 edge-midpoint points of
 * weight A/3 (exact for quadratics in ξ), normal turned away from the
 * tetrahedron's most negative vertex. On a grid of equal cells with the same
 * depth the lattices match across faces: the triangles of all cells close
 * up (Σ A n = 0 and Σ ∫ x × n dA = 0 to round-off), and the divergence
 * theorem gives the volume of the same polyhedron. A cell face named in
 * `faces` adds its part inside all sets, split along the same diagonals as
 * the tetrahedra's faces.
 *
 * The lattice across refinement levels is the caller's choice of depth.
 * With 2^2 sub-boxes per edge on every leaf, the surfaces of a coarse and a
 * fine neighbour do not meet (slits: |Σ A n| / A = 1.2e-4 on a ball on 8³
 * cells with half of them refined once); with one lattice per run, depth
 * 2 + L_max − L for a leaf of level L, they meet to round-off, at 3.7 times
 * the cost per coarse cut cell (tests/test_cutcell.c, docs/theory.md §5b).
 *
 * traction.c's immersed surface (4³ sub-cubes per leaf, the same split,
 * edge-midpoint rule) is this surface at depth 2 with a region taken by
 * triangle centres: the integration task must replace it by nh_cut_cell
 * (pressure on Γ ∩ region clipped exactly), not keep both. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NH_CUT_SETS         8    /* the tissue, a box region's six planes, a half-space */
#define NH_CUT_REGION_SUB   8.0  /* default sub-boxes per region size */
#define NH_CUT_REGION_DEPTH 12   /* deepest region lattice */
#define NH_CUT_CACHE_STACK  4913 /* (2^4 + 1)³: the tissue's cache on the stack up to depth 4 */

enum { NH_CUT_LEVEL, NH_CUT_PLANE, NH_CUT_SPHERE, NH_CUT_RADIAL };

typedef struct {
  int kind, depth;
  double lip;
  double a[3], b;       /* plane: g = a·x + b */
  double c[3], e[3], r; /* sphere |x − c| − r; radial: distance to the line c + s e, − r */
} nh_cut_set;

/* A vertex of a clipped piece: natural coordinates and the value of each
 * set that cuts the current sub-box (in the order of cut[]). */
typedef struct {
  double xi[3];
  double g[NH_CUT_SETS];
} nh_cut_vertex;

typedef struct {
  const nh_cut_spec *spec;
  double lo[3], hi[3], mid[3], half[3], jac;
  int n_sets;
  nh_cut_set set[NH_CUT_SETS];
  double *cache;
  int cache_n; /* 2^depth of the tissue */
  nh_cut_moments *out;
  nh_cut_surface *surface;
  unsigned faces;
  int rc;
  int n_cut, level_k; /* sets cutting the current leaf box; position of the tissue's, or -1 */
  double box_a[3], box_len[3]; /* the current leaf box in natural coordinates: [a, a + len] */
} nh_cut_ctx;

/* The six Kuhn tetrahedra of a box, corners by bit index (bit k: upper side
 * of axis k): 0, e_a, e_a + e_b, 7 for each order a, b of the axes. In VTK
 * numbering these are traction.c's {0,1,2,6}, {0,2,3,6}, ... */
static const int nh_kuhn[6][4] = {{0, 1, 3, 7}, {0, 2, 3, 7}, {0, 2, 6, 7},
                                  {0, 4, 6, 7}, {0, 4, 5, 7}, {0, 1, 5, 7}};
/* ... and the order of the axes: tetrahedron q is {u_a >= u_b >= u_c}, u ∈ [0, 1]³ the box's
 * local coordinates. */
static const int nh_kuhn_axes[6][3] = {{0, 1, 2}, {1, 0, 2}, {1, 2, 0},
                                       {2, 1, 0}, {2, 0, 1}, {0, 2, 1}};

static double nh_set_eval(const nh_cut_set *s, const double x[3]) {
  if (s->kind == NH_CUT_PLANE) return s->a[0] * x[0] + s->a[1] * x[1] + s->a[2] * x[2] + s->b;
  double d[3] = {x[0] - s->c[0], x[1] - s->c[1], x[2] - s->c[2]};
  if (s->kind == NH_CUT_RADIAL) {
    double t = d[0] * s->e[0] + d[1] * s->e[1] + d[2] * s->e[2];
    for (int k = 0; k < 3; k++) d[k] -= t * s->e[k];
  }
  return sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - s->r;
}

/* Lattice point I of depth t: (lo (n − I) + hi I) / n, n = 2^t, the same
 * bits at every depth that holds it (scaling by 2 is exact) and on both
 * cells of a shared face. */
static void nh_cut_x(const nh_cut_ctx *c, int t, const int I[3], double x[3]) {
  const double n = ldexp(1.0, t);
  for (int k = 0; k < 3; k++) x[k] = (c->lo[k] * (n - I[k]) + c->hi[k] * I[k]) / n;
}

/* The mirror orientation of box I of depth t (docs/theory.md §5b, "mirror
 * symmetry"): bit k set if the box lies on the upper side of the spec's
 * mirror plane x_k = mirror_k (its centre more than a quarter of its edge
 * above; a box the plane passes through is never flipped). Its Kuhn
 * tetrahedra are then those of the box reflected in axis k, so that the
 * lattice's triangulation is mirror symmetric about every plane x_k =
 * mirror_k that is a lattice plane. */
static unsigned nh_cut_flip(const nh_cut_ctx *c, int t, const int I[3]) {
  if (!c->spec->mirror) return 0u;
  const double n = ldexp(1.0, t);
  unsigned mask = 0u;
  for (int k = 0; k < 3; k++) {
    const double edge = (c->hi[k] - c->lo[k]) / n;
    const double centre = (c->lo[k] * (n - I[k] - 0.5) + c->hi[k] * (I[k] + 0.5)) / n;
    if (centre - c->spec->mirror[k] > 0.25 * edge) mask |= 1u << k;
  }
  return mask;
}

/* Set m at lattice point I of depth t <= its own depth (any depth for a plane). */
static double nh_set_exact(nh_cut_ctx *c, int m, int t, const int I[3]) {
  double x[3];
  if (m == 0) { /* the tissue: cached on its lattice */
    const int sh = c->set[0].depth - t, n = c->cache_n;
    double *v = &c->cache[(I[0] << sh) + (n + 1) * ((I[1] << sh) + (n + 1) * (I[2] << sh))];
    if (isnan(*v)) {
      nh_cut_x(c, t, I, x);
      *v = c->spec->level(c->spec->ctx, x);
      c->out->evals++;
    }
    return *v;
  }
  nh_cut_x(c, t, I, x);
  return nh_set_eval(&c->set[m], x);
}

/* The interpolant of set m at lattice point I of depth t. */
static double nh_set_value(nh_cut_ctx *c, int m, int t, const int I[3]) {
  const nh_cut_set *s = &c->set[m];
  if (s->kind == NH_CUT_PLANE || t <= s->depth) return nh_set_exact(c, m, t, I);
  const int d = s->depth, sh = t - d, n = 1 << d;
  int I0[3], ord[3] = {0, 1, 2};
  double u[3], f[8];
  for (int k = 0; k < 3; k++) {
    I0[k] = I[k] >> sh;
    if (I0[k] >= n) I0[k] = n - 1;
    u[k] = ldexp((double)(I[k] - (I0[k] << sh)), -sh);
  }
  const unsigned flip = nh_cut_flip(c, d, I0); /* the box's Kuhn split, reflected */
  for (int k = 0; k < 3; k++)
    if (flip >> k & 1) u[k] = 1.0 - u[k];
  for (int b = 0; b < 8; b++) {
    const unsigned r = (unsigned)b ^ flip;
    int J[3] = {I0[0] + (int)(r & 1), I0[1] + (int)(r >> 1 & 1), I0[2] + (int)(r >> 2 & 1)};
    f[b] = nh_set_exact(c, m, d, J);
  }
  for (int p = 0; p < 2; p++) /* sort the axes by decreasing u */
    for (int q = 0; q < 2 - p; q++)
      if (u[ord[q]] < u[ord[q + 1]]) {
        int tmp = ord[q];
        ord[q] = ord[q + 1], ord[q + 1] = tmp;
      }
  const int ea = 1 << ord[0], eab = ea | 1 << ord[1];
  return f[0] + u[ord[0]] * (f[ea] - f[0]) + u[ord[1]] * (f[eab] - f[ea]) +
         u[ord[2]] * (f[7] - f[eab]);
}

/* Set m over the box I of depth t: -1 inside, +1 outside, 0 cut. */
static int nh_set_classify(nh_cut_ctx *c, int m, int t, const int I[3]) {
  const nh_cut_set *s = &c->set[m];
  if (s->kind != NH_CUT_PLANE && t < s->depth) { /* Lipschitz bound at the centre */
    const int C[3] = {2 * I[0] + 1, 2 * I[1] + 1, 2 * I[2] + 1};
    double r2 = 0.0;
    for (int k = 0; k < 3; k++) r2 += ldexp(c->half[k], -t) * ldexp(c->half[k], -t);
    const double r = s->lip * sqrt(r2) * (1 + 1e-12), v = nh_set_exact(c, m, t + 1, C);
    return v < -r ? -1 : (v > r ? 1 : 0);
  }
  int neg = 0;
  for (int b = 0; b < 8; b++) {
    int J[3] = {I[0] + (b & 1), I[1] + (b >> 1 & 1), I[2] + (b >> 2 & 1)};
    neg += nh_set_value(c, m, t, J) < 0.0;
  }
  return neg == 8 ? -1 : (neg == 0 ? 1 : 0);
}

/* ---- moments ---- */

static void nh_add_monomials(double m[27], const double xi[3], double w) {
  const double px[3] = {w, w * xi[0], w * xi[0] * xi[0]};
  const double py[3] = {1.0, xi[1], xi[1] * xi[1]};
  const double pz[3] = {1.0, xi[2], xi[2] * xi[2]};
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 3; j++) {
      const double yz = py[j] * pz[k];
      for (int i = 0; i < 3; i++) m[i + 3 * j + 9 * k] += px[i] * yz;
    }
}

/* Grundmann–Möller, s = 3 (degree 7), relative weights (Σ = 1 over the 35
 * points): (−1)^i 2^(−2s) (d + n − 2i)^d / (i! (d + n − i)!) n!, d = 7, n = 3. */
static const double nh_gm_weight[4] = {
    1e7 / 3628800.0 * 6.0 / 64.0, -2097152.0 / 362880.0 * 6.0 / 64.0,
    279936.0 / (2.0 * 40320.0) * 6.0 / 64.0, -16384.0 / (6.0 * 5040.0) * 6.0 / 64.0};

static void nh_tet_moments(nh_cut_ctx *c, const nh_cut_vertex T[4], double sign) {
  double e[3][3];
  for (int q = 0; q < 3; q++)
    for (int k = 0; k < 3; k++) e[q][k] = T[q + 1].xi[k] - T[0].xi[k];
  const double det = e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) -
                     e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0]) +
                     e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]);
  const double vol = sign * fabs(det) / 6.0 * c->jac;
  if (!(vol != 0.0)) return;
  c->out->tets++;
  for (int i = 0; i <= 3; i++) {
    const int S = 3 - i;
    const double den = 10 - 2 * i, w = nh_gm_weight[i] * vol;
    for (int b0 = 0; b0 <= S; b0++)
      for (int b1 = 0; b1 <= S - b0; b1++)
        for (int b2 = 0; b2 <= S - b0 - b1; b2++) {
          const int b3 = S - b0 - b1 - b2;
          const double l[4] = {(2 * b0 + 1) / den, (2 * b1 + 1) / den, (2 * b2 + 1) / den,
                               (2 * b3 + 1) / den};
          double xi[3];
          for (int k = 0; k < 3; k++)
            xi[k] = l[0] * T[0].xi[k] + l[1] * T[1].xi[k] + l[2] * T[2].xi[k] + l[3] * T[3].xi[k];
          nh_add_monomials(c->out->m, xi, w);
        }
  }
}

/* out = in contracted along one axis of the 3 x 3 x 3 tensor (index i + 3 j + 9 k;
 * stride 1, 3, 9): out[.. p ..] = Σ_i C[p][i] in[.. i ..]. */
static void nh_contract(const double C[3][3], const double in[27], int stride, double out[27]) {
  for (int q = 0; q < 27; q++) {
    const int p = q / stride % 3, base = q - p * stride;
    out[q] = C[p][0] * in[base] + C[p][1] * in[base + stride] + C[p][2] * in[base + 2 * stride];
  }
}

/* Kuhn tetrahedron q of the current leaf box, in closed form: with
 * ξ_k = a_k + len_k u_k (len_k < 0 on a flipped axis: u_k from the box's upper
 * side), ∫ u_a^p u_b^q u_c^r over {1 >= u_a >= u_b >= u_c >= 0}
 * is 1 / ((r + 1)(r + q + 2)(r + q + p + 3)), and ξ^i expands binomially. */
static void nh_kuhn_moments(nh_cut_ctx *c, int q, double sign) {
  double R[27], A[3][3][3], t1[27], t2[27];
  const int *ax = nh_kuhn_axes[q];
  for (int e2 = 0; e2 < 3; e2++)
    for (int e1 = 0; e1 < 3; e1++)
      for (int e0 = 0; e0 < 3; e0++) {
        const int e[3] = {e0, e1, e2};
        const int p = e[ax[0]], r1 = e[ax[1]], r2 = e[ax[2]];
        R[e0 + 3 * e1 + 9 * e2] = 1.0 / ((r2 + 1) * (r2 + r1 + 2) * (r2 + r1 + p + 3));
      }
  for (int k = 0; k < 3; k++) { /* A[k][i][m]: coefficient of u^m in ξ_k^i */
    const double a = c->box_a[k], l = c->box_len[k];
    A[k][0][0] = 1.0, A[k][0][1] = A[k][0][2] = 0.0;
    A[k][1][0] = a, A[k][1][1] = l, A[k][1][2] = 0.0;
    A[k][2][0] = a * a, A[k][2][1] = 2.0 * a * l, A[k][2][2] = l * l;
  }
  nh_contract(A[0], R, 1, t1);
  nh_contract(A[1], t1, 3, t2);
  nh_contract(A[2], t2, 9, t1);
  const double w = sign * c->jac * fabs(c->box_len[0] * c->box_len[1] * c->box_len[2]);
  for (int q = 0; q < 27; q++) c->out->m[q] += w * t1[q];
  c->out->kuhn++;
}

/* ---- surface ---- */

static void nh_cut_phys(const nh_cut_ctx *c, const double xi[3], double y[3]) {
  for (int k = 0; k < 3; k++) y[k] = c->mid[k] + c->half[k] * xi[k];
}

/* Triangle p (natural coordinates) with area vector A: its 3 edge midpoints. */
static void nh_emit(nh_cut_ctx *c, const double p[3][3], const double A[3], int piece) {
  nh_cut_surface *s = c->surface;
  if (nh_grow((void **)&s->point, &s->cap, s->n + 3, sizeof *s->point)) {
    c->rc = NH_ERR_MEMORY;
    return;
  }
  for (int e = 0; e < 3; e++) {
    nh_cut_point *q = &s->point[s->n++];
    for (int k = 0; k < 3; k++) {
      q->xi[k] = 0.5 * (p[e][k] + p[(e + 1) % 3][k]);
      q->area[k] = A[k] / 3.0;
    }
    q->piece = piece;
  }
}

/* Fan of the polygon P[0..n) with outward direction: away from `inner`
 * (natural coordinates; level set) or along `dir` (a cell face). */
static void nh_emit_polygon(nh_cut_ctx *c, const nh_cut_vertex *P, int n, const double inner[3],
                            const double dir[3], int piece) {
  double y0[3], yin[3];
  nh_cut_phys(c, P[0].xi, y0);
  if (inner) nh_cut_phys(c, inner, yin);
  for (int q = 1; q + 1 < n && !c->rc; q++) {
    double y1[3], y2[3], u[3], v[3], A[3], p[3][3];
    nh_cut_phys(c, P[q].xi, y1);
    nh_cut_phys(c, P[q + 1].xi, y2);
    for (int k = 0; k < 3; k++) u[k] = y1[k] - y0[k], v[k] = y2[k] - y0[k];
    A[0] = 0.5 * (u[1] * v[2] - u[2] * v[1]);
    A[1] = 0.5 * (u[2] * v[0] - u[0] * v[2]);
    A[2] = 0.5 * (u[0] * v[1] - u[1] * v[0]);
    if (!(A[0] != 0.0 || A[1] != 0.0 || A[2] != 0.0)) continue;
    double side = 0.0;
    for (int k = 0; k < 3; k++) side += A[k] * (inner ? yin[k] - y0[k] : -dir[k]);
    if (side > 0.0)
      for (int k = 0; k < 3; k++) A[k] = -A[k];
    for (int k = 0; k < 3; k++)
      p[0][k] = P[0].xi[k], p[1][k] = P[q].xi[k], p[2][k] = P[q + 1].xi[k];
    nh_emit(c, p, A, piece);
  }
}

/* The point where the edge from u (set k < 0) to v (>= 0) crosses set k's zero. */
static void nh_cross(const nh_cut_vertex *u, const nh_cut_vertex *v, int k, int n_cut,
                     nh_cut_vertex *out) {
  const double s = u->g[k] / (u->g[k] - v->g[k]);
  for (int d = 0; d < 3; d++) out->xi[d] = u->xi[d] + s * (v->xi[d] - u->xi[d]);
  for (int j = 0; j < n_cut; j++) out->g[j] = u->g[j] + s * (v->g[j] - u->g[j]);
}

/* Clip the polygon P[0..n) by the sets first.. of the cut list (keep < 0),
 * then emit it. */
static void nh_clip_emit(nh_cut_ctx *c, const nh_cut_vertex *P, int n, int first,
                         const double inner[3], const double dir[3], int piece) {
  nh_cut_vertex buf[2][4 + NH_CUT_SETS + 4];
  const nh_cut_vertex *cur = P;
  for (int k = first; k < c->n_cut && n >= 3; k++) {
    nh_cut_vertex *next = buf[k & 1];
    int m = 0;
    for (int e = 0; e < n; e++) {
      const nh_cut_vertex *u = &cur[e], *v = &cur[(e + 1) % n];
      const int uin = u->g[k] < 0.0, vin = v->g[k] < 0.0;
      if (uin) next[m++] = *u;
      if (uin != vin) { /* from the inside vertex, as the tetrahedra do */
        if (uin)
          nh_cross(u, v, k, c->n_cut, &next[m++]);
        else
          nh_cross(v, u, k, c->n_cut, &next[m++]);
      }
    }
    cur = next, n = m;
  }
  if (n >= 3) nh_emit_polygon(c, cur, n, inner, dir, piece);
}

/* ---- clipping the tetrahedra ---- */

static void nh_cut_tet(nh_cut_ctx *c, const nh_cut_vertex T[4], int k, int kuhn, double sign);

static void nh_cut_prism(nh_cut_ctx *c, const nh_cut_vertex *a0, const nh_cut_vertex *a1,
                         const nh_cut_vertex *a2, const nh_cut_vertex *b0, const nh_cut_vertex *b1,
                         const nh_cut_vertex *b2, int k, double sign) {
  const nh_cut_vertex t0[4] = {*a0, *a1, *a2, *b0}, t1[4] = {*a1, *a2, *b0, *b1},
                      t2[4] = {*a2, *b0, *b1, *b2};
  nh_cut_tet(c, t0, k, -1, sign);
  nh_cut_tet(c, t1, k, -1, sign);
  nh_cut_tet(c, t2, k, -1, sign);
}

/* sign × the moments of the part of T where the cut sets k.. are negative;
 * kuhn: T is that Kuhn tetrahedron of the leaf box, unclipped (else -1). */
static void nh_cut_tet(nh_cut_ctx *c, const nh_cut_vertex T[4], int k, int kuhn, double sign) {
  if (c->rc) return;
  if (k == c->n_cut) {
    if (kuhn >= 0)
      nh_kuhn_moments(c, kuhn, sign);
    else
      nh_tet_moments(c, T, sign);
    return;
  }
  int in[4], out[4], ni = 0, no = 0;
  for (int q = 0; q < 4; q++) {
    if (T[q].g[k] < 0.0)
      in[ni++] = q;
    else
      out[no++] = q;
  }
  if (!no) {
    nh_cut_tet(c, T, k + 1, kuhn, sign);
    return;
  }
  if (!ni) return;
  nh_cut_vertex P[4];
  int np = 0;
  for (int a = 0; a < ni; a++)
    for (int b = 0; b < no; b++) nh_cross(&T[in[a]], &T[out[b]], k, c->n_cut, &P[np++]);
  if (k == c->level_k && c->surface) { /* the piece of {F = 0} */
    int deepest = in[0];
    for (int a = 1; a < ni; a++)
      if (T[in[a]].g[k] < T[deepest].g[k]) deepest = in[a];
    if (np == 4) {
      const nh_cut_vertex quad[4] = {P[0], P[1], P[3], P[2]};
      nh_clip_emit(c, quad, 4, k + 1, T[deepest].xi, NULL, -1);
    } else {
      nh_clip_emit(c, P, 3, k + 1, T[deepest].xi, NULL, -1);
    }
  }
  if (ni == 1) {
    const nh_cut_vertex S[4] = {T[in[0]], P[0], P[1], P[2]};
    nh_cut_tet(c, S, k + 1, -1, sign);
  } else if (ni == 3) { /* T less the tetrahedron of d and its three crossings */
    const nh_cut_vertex S[4] = {T[out[0]], P[0], P[1], P[2]};
    nh_cut_tet(c, T, k + 1, kuhn, sign);
    nh_cut_tet(c, S, k + 1, -1, -sign);
  } else { /* (a, p_ac, p_ad) and (b, p_bc, p_bd) */
    nh_cut_prism(c, &T[in[0]], &P[0], &P[1], &T[in[1]], &P[2], &P[3], k + 1, sign);
  }
}

/* ---- the octree ---- */

static void nh_box_moments(nh_cut_ctx *c, int t, const int I[3]) {
  double P[3][3];
  for (int k = 0; k < 3; k++) {
    const double a = ldexp(2.0 * I[k], -t) - 1.0, b = ldexp(2.0 * (I[k] + 1), -t) - 1.0;
    P[k][0] = b - a;
    P[k][1] = 0.5 * (b - a) * (b + a);
    P[k][2] = (b - a) * (b * b + a * b + a * a) / 3.0;
  }
  for (int k = 0; k < 3; k++)
    for (int j = 0; j < 3; j++)
      for (int i = 0; i < 3; i++)
        c->out->m[i + 3 * j + 9 * k] += c->jac * P[0][i] * P[1][j] * P[2][k];
}

/* The faces of box I (depth t) on the cell faces of c->faces: whole squares
 * if the box is inside every set (n_cut = 0), else clipped by the cut sets
 * with corner values g[k][b]. */
static void nh_box_faces(nh_cut_ctx *c, int t, const int I[3], double g[][8]) {
  const int n = 1 << t;
  const unsigned flip = nh_cut_flip(c, t, I);
  for (int f = 0; f < 6 && !c->rc; f++) {
    const int ax = f / 2, side = f % 2, p = (ax + 1) % 3, q = (ax + 2) % 3;
    if (!(c->faces >> f & 1) || I[ax] != (side ? n - 1 : 0)) continue;
    nh_cut_vertex V[2][2]; /* V[dp][dq]: from the flipped side on a flipped axis */
    for (int dq = 0; dq < 2; dq++)
      for (int dp = 0; dp < 2; dp++) {
        const int b =
            side << ax | (dp ^ (int)(flip >> p & 1)) << p | (dq ^ (int)(flip >> q & 1)) << q;
        for (int k = 0; k < 3; k++) V[dp][dq].xi[k] = ldexp(2.0 * (I[k] + (b >> k & 1)), -t) - 1.0;
        for (int k = 0; k < c->n_cut; k++) V[dp][dq].g[k] = g[k][b];
      }
    double dir[3] = {0, 0, 0};
    dir[ax] = side ? 1.0 : -1.0;
    const nh_cut_vertex tri[2][3] = {{V[0][0], V[1][0], V[1][1]}, {V[0][0], V[1][1], V[0][1]}};
    for (int h = 0; h < 2; h++) nh_clip_emit(c, tri[h], 3, 0, NULL, dir, f);
  }
}

/* Box I of depth t, inside the sets of `in`. */
static void nh_cut_box(nh_cut_ctx *c, int t, const int I[3], unsigned in) {
  if (c->rc) return;
  c->out->boxes++;
  unsigned cut = 0;
  int need = 0;
  for (int m = 0; m < c->n_sets; m++) {
    if (in >> m & 1) continue;
    const int k = nh_set_classify(c, m, t, I);
    if (k > 0) return;
    if (k < 0) {
      in |= 1u << m;
    } else {
      cut |= 1u << m;
      if (c->set[m].kind != NH_CUT_PLANE && c->set[m].depth > need) need = c->set[m].depth;
    }
  }
  if (!cut) {
    nh_box_moments(c, t, I);
    if (c->surface && c->faces) {
      c->n_cut = 0;
      nh_box_faces(c, t, I, NULL);
    }
    return;
  }
  if (t < need) {
    for (int b = 0; b < 8; b++) {
      const int J[3] = {2 * I[0] + (b & 1), 2 * I[1] + (b >> 1 & 1), 2 * I[2] + (b >> 2 & 1)};
      nh_cut_box(c, t + 1, J, in);
    }
    return;
  }
  /* a leaf: the six tetrahedra clipped by the cut sets */
  double g[NH_CUT_SETS][8];
  c->n_cut = 0, c->level_k = -1;
  for (int m = 0; m < c->n_sets; m++) {
    if (!(cut >> m & 1)) continue;
    if (m == 0) c->level_k = c->n_cut;
    for (int b = 0; b < 8; b++) {
      const int J[3] = {I[0] + (b & 1), I[1] + (b >> 1 & 1), I[2] + (b >> 2 & 1)};
      g[c->n_cut][b] = nh_set_value(c, m, t, J);
    }
    c->n_cut++;
  }
  const unsigned flip = nh_cut_flip(c, t, I);
  for (int k = 0; k < 3; k++) {
    const int f = flip >> k & 1;
    c->box_a[k] = ldexp(2.0 * (I[k] + f), -t) - 1.0;
    c->box_len[k] = f ? -ldexp(2.0, -t) : ldexp(2.0, -t);
  }
  nh_cut_vertex V[8]; /* by bit index in the box's (flipped) local coordinates */
  for (int b = 0; b < 8; b++) {
    const unsigned r = (unsigned)b ^ flip;
    for (int k = 0; k < 3; k++) V[b].xi[k] = ldexp(2.0 * (I[k] + (int)(r >> k & 1)), -t) - 1.0;
    for (int k = 0; k < c->n_cut; k++) V[b].g[k] = g[k][r];
  }
  for (int q = 0; q < 6; q++) {
    const nh_cut_vertex T[4] = {V[nh_kuhn[q][0]], V[nh_kuhn[q][1]], V[nh_kuhn[q][2]],
                                V[nh_kuhn[q][3]]};
    nh_cut_tet(c, T, 0, q, 1.0);
  }
  if (c->surface && c->faces) nh_box_faces(c, t, I, g);
}

/* ---- the sets of a spec ---- */

static void nh_add_plane(nh_cut_ctx *c, const double a[3], double b) {
  nh_cut_set *s = &c->set[c->n_sets++];
  s->kind = NH_CUT_PLANE;
  for (int k = 0; k < 3; k++) s->a[k] = a[k];
  s->b = b;
}

/* Depth of a region's lattice: sub-box edge <= size / sub. */
static int nh_region_depth(const nh_cut_ctx *c, double size, double sub) {
  const double edge = 2.0 * fmax(c->half[0], fmax(c->half[1], c->half[2]));
  int d = 1; /* at least 1: no lattice box straddles a mirror plane through the cell's middle */
  while (d < NH_CUT_REGION_DEPTH && ldexp(edge, -d) > size / sub) d++;
  return d;
}

static int nh_cut_sets(nh_cut_ctx *c, const nh_cut_spec *spec) {
  nh_cut_set *s = &c->set[0];
  s->kind = NH_CUT_LEVEL, s->depth = spec->depth;
  s->lip = spec->lipschitz > 0.0 ? spec->lipschitz : 1.0;
  c->n_sets = 1;
  const nh_region *r = spec->region;
  if (r) {
    const double sub = spec->region_sub > 0.0 ? spec->region_sub : NH_CUT_REGION_SUB;
    if (r->kind == NH_REGION_LABEL)
      return NH_ERROR(NH_ERR_INPUT, "%s: a label region has no cut-cell quadrature", r->where);
    if (r->kind == NH_REGION_BOX) {
      for (int k = 0; k < 3; k++) {
        double a[3] = {0, 0, 0};
        a[k] = 1.0;
        nh_add_plane(c, a, -r->max[k]);
        a[k] = -1.0;
        nh_add_plane(c, a, r->min[k]);
      }
    } else {
      nh_cut_set *q = &c->set[c->n_sets++];
      q->lip = 1.0, q->r = r->radius;
      /* never coarser than the tissue's lattice: the tie of a region larger
       * than a cell then converges with the tissue's O(s²) instead of
       * keeping the size / sub lattice's error on every finer grid */
      const int d_region = nh_region_depth(c, nh_region_size(r), sub);
      q->depth = d_region > spec->depth ? d_region : spec->depth;
      if (r->kind == NH_REGION_SPHERE) {
        q->kind = NH_CUT_SPHERE;
        for (int k = 0; k < 3; k++) q->c[k] = r->center[k];
      } else {
        double e[3], len = 0.0, a[3];
        for (int k = 0; k < 3; k++) e[k] = r->end[k] - r->start[k], len += e[k] * e[k];
        len = sqrt(len);
        q->kind = NH_CUT_RADIAL;
        for (int k = 0; k < 3; k++) q->c[k] = r->start[k], q->e[k] = e[k] / len;
        for (int k = 0; k < 3; k++) a[k] = -q->e[k];
        nh_add_plane(c, a, nh_vec3_dot(q->e, r->start));
        nh_add_plane(c, q->e, -nh_vec3_dot(q->e, r->end));
      }
    }
  }
  if (spec->plane) nh_add_plane(c, spec->plane + 3, -nh_vec3_dot(spec->plane, spec->plane + 3));
  return NH_OK;
}

static double nh_domain_level_fn(const void *ctx, const double x[3]) {
  return nh_domain_level((const nh_domain *)ctx, x);
}

void nh_cut_spec_domain(nh_cut_spec *spec, const nh_domain *domain, int depth) {
  memset(spec, 0, sizeof *spec);
  spec->level = nh_domain_level_fn;
  spec->ctx = domain;
  spec->lipschitz = 1.0;
  spec->depth = depth;
  spec->mirror = domain->center;
}

int nh_cut_cell(const nh_cut_spec *spec, const double lo[3], const double hi[3],
                nh_cut_moments *out, nh_cut_surface *surface, unsigned faces) {
  NH_CHECK(spec->depth >= 0 && spec->depth <= NH_CUT_DEPTH_MAX, NH_ERR_INTERNAL,
           "cut cell: depth %d outside 0..%d", spec->depth, NH_CUT_DEPTH_MAX);
  nh_cut_ctx c;
  memset(&c, 0, sizeof c);
  memset(out, 0, sizeof *out);
  c.spec = spec, c.out = out, c.surface = surface, c.faces = faces;
  c.jac = 1.0;
  for (int k = 0; k < 3; k++) {
    c.lo[k] = lo[k], c.hi[k] = hi[k];
    c.mid[k] = 0.5 * (lo[k] + hi[k]), c.half[k] = 0.5 * (hi[k] - lo[k]);
    c.jac *= c.half[k];
  }
  NH_TRY(nh_cut_sets(&c, spec));
  double stack[NH_CUT_CACHE_STACK];
  c.cache_n = 1 << spec->depth;
  const size_t n_cache = (size_t)(c.cache_n + 1) * (c.cache_n + 1) * (c.cache_n + 1);
  c.cache = n_cache <= NH_CUT_CACHE_STACK ? stack : nh_calloc(n_cache, sizeof *c.cache);
  if (!c.cache) return NH_ERR_MEMORY;
  for (size_t i = 0; i < n_cache; i++) c.cache[i] = NAN;
  const int I[3] = {0, 0, 0};
  nh_cut_box(&c, 0, I, 0u);
  if (c.cache != stack) free(c.cache);
  if (c.rc) return NH_ERROR(c.rc, "out of memory for a cut cell's surface");
  out->volume = out->m[0];
  for (int k = 0; k < 3; k++)
    out->centroid[k] =
        c.mid[k] +
        (out->volume > 0.0 ? c.half[k] * out->m[k == 0 ? 1 : (k == 1 ? 3 : 9)] / out->volume : 0.0);
  return NH_OK;
}

/* ---- moment fitting onto the 27 Gauss points ---- */

/* The Gauss–Legendre nodes of 3 points: −√(3/5), 0, √(3/5). */
static const double nh_gauss3[3] = {-0.77459666924148337704, 0.0, 0.77459666924148337704};

void nh_cut_points(double xi[81]) {
  for (int q = 0; q < 27; q++) {
    xi[3 * q] = nh_gauss3[q % 3];
    xi[3 * q + 1] = nh_gauss3[q / 3 % 3];
    xi[3 * q + 2] = nh_gauss3[q / 9];
  }
}

void nh_cut_fit(const double m[27], double w[27]) {
  /* L_a(ξ) = Σ_i C[a][i] ξ^i, the Lagrange polynomials at the nodes
   * (−s, 0, s), s² = 3/5: (ξ² ∓ sξ)/(2s²) and 1 − ξ²/s². */
  const double s = nh_gauss3[2], s2 = 0.6;
  const double C[3][3] = {
      {0.0, -0.5 / s, 0.5 / s2}, {1.0, 0.0, -1.0 / s2}, {0.0, 0.5 / s, 0.5 / s2}};
  double a[27], b[27];
  nh_contract(C, m, 1, a);
  nh_contract(C, a, 3, b);
  nh_contract(C, b, 9, w);
}

void nh_cut_surface_free(nh_cut_surface *surface) {
  free(surface->point);
  surface->point = NULL;
  surface->n = surface->cap = 0;
}

/* ---- the mesh's cut cells ---- */

int nh_cut_domain_cell(const nh_domain *domain, const double lo[3], const double hi[3],
                       const nh_region *region, const double *plane, nh_cut_moments *moments,
                       double w[27]) {
  return nh_cut_domain_cell_at(domain, NH_CUT_DEPTH, lo, hi, region, plane, moments, w);
}

int nh_cut_domain_cell_at(const nh_domain *domain, int depth, const double lo[3],
                          const double hi[3], const nh_region *region, const double *plane,
                          nh_cut_moments *moments, double w[27]) {
  nh_cut_spec spec;
  nh_cut_spec_domain(&spec, domain, depth);
  spec.region = region;
  spec.plane = plane;
  NH_TRY(nh_cut_cell(&spec, lo, hi, moments, NULL, 0u));
  if (w) nh_cut_fit(moments->m, w);
  return NH_OK;
}

void nh_cut_shape_integrals(const double w[27], double N[8], double NN[64]) {
  double xi[81];
  nh_cut_points(xi);
  for (int a = 0; a < 8; a++) N[a] = 0.0;
  if (NN)
    for (int i = 0; i < 64; i++) NN[i] = 0.0;
  for (int q = 0; q < 27; q++) {
    double Nq[8];
    nh_hex_shape(xi + 3 * q, Nq);
    for (int a = 0; a < 8; a++) {
      N[a] += w[q] * Nq[a];
      if (NN)
        for (int b = 0; b < 8; b++) NN[8 * a + b] += w[q] * Nq[a] * Nq[b];
    }
  }
}

/* ---- connected components of a cut cell's tissue ----
 * The reconstruction I F is linear on each Kuhn tetrahedron, so a sub-box of
 * the lattice holds tissue iff one of its 8 corners has F < 0, and the
 * tissue of two face neighbours meets iff a corner of their common face has
 * F < 0 (I F on that face is the linear interpolant of its 4 corners: no
 * negative corner, no tissue on the face). A sub-box with tissue counts as
 * one piece (at depth 2 a piece narrower than a sub-box could split it: not
 * resolved, as the quadrature does not resolve it either). Union-find with
 * path halving over the (2^depth)³ sub-boxes. */
static int nh_find(int *parent, int i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

int nh_cut_components(const nh_cut_spec *spec, const double lo[3], const double hi[3],
                      int *n_components, int *label) {
  NH_CHECK(spec->depth >= 0 && spec->depth <= NH_CUT_DEPTH_MAX, NH_ERR_INTERNAL,
           "cut cell: depth %d outside 0..%d", spec->depth, NH_CUT_DEPTH_MAX);
  const int n = 1 << spec->depth, p = n + 1;
  const size_t n_boxes = (size_t)n * n * n, n_points = (size_t)p * p * p;
  unsigned char *neg = nh_calloc(n_points, 1);
  int *parent = nh_calloc(n_boxes, sizeof(int));
  if (!neg || !parent) {
    free(neg), free(parent);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: components of a cut cell");
  }
  for (int k = 0; k < p; k++)
    for (int j = 0; j < p; j++)
      for (int i = 0; i < p; i++) {
        const int I[3] = {i, j, k};
        double x[3];
        for (int a = 0; a < 3; a++)
          x[a] = (lo[a] * (n - I[a]) + hi[a] * I[a]) / n; /* the points of nh_cut_x */
        neg[i + p * (j + p * k)] = spec->level(spec->ctx, x) < 0.0;
      }
#define NH_NEG(i, j, k) neg[(i) + p * ((j) + p * (k))]
#define NH_BOX(i, j, k) ((i) + n * ((j) + n * (k)))
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        int any = 0;
        for (int b = 0; b < 8; b++) any |= NH_NEG(i + (b & 1), j + (b >> 1 & 1), k + (b >> 2));
        parent[NH_BOX(i, j, k)] = any ? NH_BOX(i, j, k) : -1;
      }
  for (int k = 0; k < n; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        const int here = NH_BOX(i, j, k);
        if (parent[here] < 0) continue;
        for (int axis = 0; axis < 3; axis++) {
          int I[3] = {i, j, k};
          if (++I[axis] == n) continue;
          const int there = NH_BOX(I[0], I[1], I[2]);
          if (parent[there] < 0) continue;
          /* the common face: corners with coordinate I[axis] along axis */
          int meet = 0;
          for (int b = 0; b < 4; b++) {
            int C[3] = {i, j, k};
            C[axis] = I[axis];
            C[(axis + 1) % 3] += b & 1;
            C[(axis + 2) % 3] += b >> 1;
            meet |= NH_NEG(C[0], C[1], C[2]);
          }
          if (meet) parent[nh_find(parent, here)] = nh_find(parent, there);
        }
      }
#undef NH_NEG
#undef NH_BOX
  /* roots first (find compresses paths), then number them in box order */
  for (size_t b = 0; b < n_boxes; b++)
    if (parent[b] >= 0) parent[b] = nh_find(parent, (int)b);
  int count = 0; /* a root's entry becomes −2 − its number; its members still point at it */
  for (size_t b = 0; b < n_boxes; b++)
    if (parent[b] == (int)b) parent[b] = -2 - count++;
  if (label)
    for (size_t b = 0; b < n_boxes; b++)
      label[b] = parent[b] == -1 ? -1 : -2 - (parent[b] >= 0 ? parent[parent[b]] : parent[b]);
  *n_components = count;
  free(neg), free(parent);
  return NH_OK;
}

int nh_mesh_split_cells(const nh_mesh *m, int *n_split, int *max_components) {
  *n_split = 0;
  if (max_components) *max_components = m->n_leaves > 0;
  if (m->domain.kind == NH_DOMAIN_BOX) return NH_OK;
  nh_cut_spec spec;
  nh_cut_spec_domain(&spec, &m->domain, NH_CUT_DEPTH);
  for (int l = 0; l < m->n_leaves; l++) {
    double Xe[24], lo[3], hi[3], mid[3], diag = 0.0;
    nh_mesh_cell_coords(m, m->X, m->leaves[l], Xe);
    if (!nh_hex_is_box(Xe, lo, hi)) continue;
    for (int k = 0; k < 3; k++)
      mid[k] = 0.5 * (lo[k] + hi[k]), diag += 0.25 * (hi[k] - lo[k]) * (hi[k] - lo[k]);
    if (fabs(nh_domain_level(&m->domain, mid)) > sqrt(diag)) continue; /* 1-Lipschitz: not cut */
    int n = 0;
    NH_TRY(nh_cut_components(&spec, lo, hi, &n, NULL));
    if (n > 1) ++*n_split;
    if (max_components && n > *max_components) *max_components = n;
  }
  return NH_OK;
}
