/* dwr_local.c — the goal estimate where a goal's cell holds tool rows: a
 * local enriched dual (docs/theory.md §6.6, "Held rows in the goal's cell";
 * Becker & Rannacher, "An optimal control approach to a posteriori error
 * estimation in finite element methods", 2001; Bangerth & Rannacher,
 * "Adaptive Finite Element Methods for Differential Equations", 2003, §3:
 * the dual's weight from a higher-order / finer local solve).
 *
 * Why. A row that holds the tissue to a tool (the cannula's tip disc in the
 * hold, docs/dbs.md "What the hold's error is") is in the dual: J z = 0 on
 * it. When the row and a goal's box share a cell, the cell's 8 nodes carry
 * both the dual's load j and the held point, and the discrete dual z_h is
 * pinned to ≈ 0 over the cell (and so everywhere: j sits on the pinned
 * nodes). Its recovered error z* − z_h (dwr.c) is ≈ 0 too, so the estimate
 * vanishes while the true dual, 0 on the held points, is of the goal's size
 * a millimetre away. The missing piece is z − z_h near the rows.
 *
 * What. On a patch ω — the leaves that meet a goal's box and hold an
 * active row point with a tool part (the seeds), their bounding box grown
 * by NH_LOCAL_RING seed edges and clipped to the mesh — the constrained
 * dual is solved again on a uniform lattice of spacing h_f = (smallest seed
 * edge) / 2^d, d ≥ NH_LOCAL_DEPTH and fine enough that a held disc spans 3
 * lattice cells (h_f ≤ 2ρ/3; d ≤ NH_LOCAL_MAX_DEPTH):
 *     K_f z_f + C_fᵀ μ = j_f  in ω,   C_f z_f = 0,   z_f = z_h on ∂ω
 * (where ω meets the mesh's boundary: natural, fixed DOFs 0). K_f: the
 * lattice's rest stiffness in the corotated frame of the leaf under each
 * lattice cell (R K₀ Rᵀ, the leaf's material and formulation: B-bar cells'
 * volumetric part κ V ḡ ḡᵀ of each lattice cell), scaled in cut leaves by
 * the lattice cell's tissue fraction (its Gauss points inside; floor
 * NH_LOCAL_PHI_MIN, as the finite cell method's α; a lattice cell under no
 * leaf has only that). j_f: the goal's box mean integrated exactly on the
 * lattice (the functional of nh_goal_functional, 1 / |B ∩ Ω| ∫_B v_k).
 * C_f: every active row with a tissue part whose points lie in ω, sampled
 * again on the lattice — a disc row's disc by nh_disc_points at h_f (the
 * rule nh_rows.disc keeps), a point row at its point x̄ = Σ_a w_a X_a;
 * samples outside ω are left out and the rest renormalised. The
 * quasi-static dual (z ≈ K⁻¹ j, dwr.c "Dual problem": the mass is left
 * out). z_f by a sparse Cholesky factor of K_f (CHOLMOD); μ from
 * W = C_f K_f⁻¹ C_fᵀ by its eigenvectors, eigenvalues below 1e-12 of the
 * largest dropped (dependent rows: C_fᵀ μ is unique, μ is not).
 *
 * The estimate. With u_f, z_f the constrained solutions of a nested fine
 * space (the rows holding the same points, J_f z_f = 0):
 *     J(u_f) − J(u_h) = f(z_f) − a(P u_h, z_f)            (dwr.c, §6.6).
 * Take for z_f the patch's z̃ (z_f in ω, z_h outside) and w = z̃ − z_h
 * (0 outside ω). The coarse equations R_h(u_h)(v_h) = f(v_h) − a(u_h, v_h)
 * + Σ_i Λ_i (J_h v_h)_i = 0 for all v_h (Λ_i the rows' forces on the
 * tissue) give f(z_h) − a(u_h, z_h) = 0 on the active rows, and so
 *     L = R(u_h)(w − I_h w) = Σ_cells φ ∫ (ρ b · w' − σ_h(u_h) : ε(w')) dV
 *                             + Σ_i Λ_i n_i · w'(row i's points),
 * w' = w − P I_h w, I_h w the mesh's nodal interpolant of w (at the nodes
 * whose leaves all lie in ω; 0 elsewhere, hanging nodes their masters'):
 * what the lattice's residual gets wrong on coarse functions (body force
 * lumping and drained share, cut cells, inertia: left out or
 * approximated) is weighted only by the fine part of w. σ_h(u_h): the
 * primal's discrete stress of the leaf under the lattice cell (corotated,
 * B-bar's mean pressure); ε(w'): the lattice field's strain in the same
 * frame (D⁻¹ of its full stress); b: the step's body force per unit mass
 * (loads; 0 without); Λ: nh_constraint_data.force (none without data).
 * L replaces the recovered terms ε_K of the leaves whose centre lies in ω
 * (the patch's part of a(u − u_h, z − z_h)); the terms outside ω, the
 * geometry and the constraint-data terms stay.
 *
 * Applied only where a seed exists (a goal's cell holding a tool row);
 * elsewhere nothing is computed. Skipped (applied = 0) when the lattice
 * would exceed NH_LOCAL_MAX_DOFS. The choices are measured in
 * docs/theory.md §6.6 (tests/test_dwr_local.c): ω one seed edge beyond the
 * seeds gives 0.79–0.87 of the fine error, half of that 0.07–0.25 (the
 * pinned z_h is a poor boundary value near the goal); a lattice that does
 * not resolve the held disc finds only the coarser meshes' error.
 * Workspace: the lattice (nodes, per cell its 24 x 24 matrix, a sparse
 * Cholesky factor of K_f), the duals at the lattice's nodes and the rows'
 * K⁻¹ C_fᵀ. */
#include "adapt/adapt_impl.h"

#include <cholmod.h>
#include <lapacke.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NH_LOCAL_DEPTH     2     /* h_f = smallest seed edge / 2^depth, depth at least this */
#define NH_LOCAL_MAX_DEPTH 4     /* and at most this */
#define NH_LOCAL_RING      1     /* ω: the seeds' box grown by this many seed edges */
#define NH_LOCAL_MAX_DOFS  60000 /* larger patches are skipped */
#define NH_LOCAL_PHI_MIN   1e-3  /* a fine cell's stiffness outside the tissue (as the FCM's α) */
#define NH_GAUSS           0.57735026918962576451 /* 1/√3 */

typedef struct {
  double lo[3], h;
  int n[3];    /* cells per axis */
  int *dof;    /* 3 per lattice node: free DOF index or −1 (∂ω) */
  int nf;      /* free DOFs */
  int *leaf;   /* per fine cell: the mesh leaf under its centre */
  double *phi; /* per fine cell: its tissue fraction (Gauss points inside; floor PHI_MIN) */
  double *Xn;  /* 3 per lattice node: rest position */
  double *zh;  /* nz blocks of 3 per lattice node: z_h at the nodes */
} nh_lattice;

static int nh_lat_node(const nh_lattice *L, int i, int j, int k) {
  return i + (L->n[0] + 1) * (j + (L->n[1] + 1) * k);
}

/* The 8 lattice nodes of fine cell (i, j, k) in nh_hex_corner order. */
static void nh_lat_cell_nodes(const nh_lattice *L, int e, int v[8]) {
  int i = e % L->n[0], j = (e / L->n[0]) % L->n[1], k = e / (L->n[0] * L->n[1]);
  for (int a = 0; a < 8; a++)
    v[a] = nh_lat_node(L, i + (nh_hex_corner[a][0] > 0), j + (nh_hex_corner[a][1] > 0),
                       k + (nh_hex_corner[a][2] > 0));
}

static void nh_lat_cell_coords(const nh_lattice *L, const int v[8], double Xe[24]) {
  for (int a = 0; a < 8; a++) memcpy(Xe + 3 * a, L->Xn + 3 * v[a], 3 * sizeof(double));
}

/* The lattice field f (3 per node) at the rest point x (trilinear in its
 * lattice cell; clamped to the lattice). */
static void nh_lat_sample(const nh_lattice *L, const double *f, const double x[3], double out[3]) {
  int ijk[3], v[8];
  double xi[3], N[8];
  for (int k = 0; k < 3; k++) {
    double s = (x[k] - L->lo[k]) / L->h;
    ijk[k] = (int)fmin(fmax(floor(s), 0.0), L->n[k] - 1.0);
    xi[k] = fmin(fmax(2.0 * (s - ijk[k]) - 1.0, -1.0), 1.0);
  }
  nh_hex_shape(xi, N);
  nh_lat_cell_nodes(L, ijk[0] + L->n[0] * (ijk[1] + L->n[1] * ijk[2]), v);
  out[0] = out[1] = out[2] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) out[k] += N[a] * f[3 * (size_t)v[a] + k];
}

/* The leaf's box [lo, hi] (cells are axis-aligned boxes). */
static void nh_leaf_box(const nh_mesh *m, int c, double lo[3], double hi[3]) {
  double Xe[24];
  nh_mesh_cell_coords(m, m->X, c, Xe);
  for (int k = 0; k < 3; k++) {
    lo[k] = hi[k] = Xe[k];
    for (int a = 1; a < 8; a++)
      lo[k] = fmin(lo[k], Xe[3 * a + k]), hi[k] = fmax(hi[k], Xe[3 * a + k]);
  }
}

/* ∫_a^b of the two 1-D hats of [x0, x0 + h] (left: (x0 + h − x)/h, right). */
static void nh_hat_integrals(double x0, double h, double a, double b, double out[2]) {
  a = fmax(a, x0), b = fmin(b, x0 + h);
  if (!(b > a)) {
    out[0] = out[1] = 0.0;
    return;
  }
  double r = ((b - x0) * (b - x0) - (a - x0) * (a - x0)) / (2.0 * h);
  out[1] = r;
  out[0] = (b - a) - r;
}

/* The mean rest point x̄ of row i's tissue part; 0 if it has none. */
static int nh_row_point(const nh_mesh *m, const nh_rows *rows, int i, double x[3]) {
  double w = 0.0;
  x[0] = x[1] = x[2] = 0.0;
  for (int s = rows->start[i]; s < rows->start[i + 1]; s++) {
    int v = rows->node[s];
    if (v < 0) continue;
    for (int k = 0; k < 3; k++) x[k] += rows->N[s] * m->X[3 * v + k];
    w += rows->N[s];
  }
  if (!(w > 0.0)) return 0;
  for (int k = 0; k < 3; k++) x[k] /= w;
  return 1;
}

/* The leaf's corotated frame, Lamé parameters, density, and the primal's
 * corotated displacement d_u, B-bar's mean gradients and θ̄ (gbar NULL: full). */
typedef struct {
  double Xe[24], R[9], du[24], lambda, mu, rho, theta, lo[3], hi[3];
  const double *G0, *gbar;
} nh_leaf_data;

static void nh_leaf_data_get(const nh_mesh *m, const nh_tissue *t, const double *u, int c,
                             nh_leaf_data *d) {
  double ue[24], cof[9];
  nh_mesh_cell_coords(m, m->X, c, d->Xe);
  nh_mesh_cell_coords(m, u, c, ue);
  d->G0 = t->G0 + 24 * t->cell_shape[c];
  nh_hex_corotated(d->Xe, ue, d->G0, d->R, d->du);
  nh_tissue_cell_material(t, c, &d->lambda, &d->mu, &d->rho);
  d->gbar = nh_tissue_gbar(t, c);
  d->theta = d->gbar ? nh_hex_mean_dilatation(ue, d->gbar, cof) : 0.0;
  nh_leaf_box(m, c, d->lo, d->hi);
}

/* The patch ω and its lattice; *ok 0 when there is no seed or ω cannot be
 * built (header). */
static int nh_lattice_build(const nh_mesh *m, const nh_rows *rows, const unsigned char *active,
                            const double *free_mask, int n_points, const double *points,
                            double radius, nh_lattice *L, int *ok) {
  double slo[3] = {INFINITY, INFINITY, INFINITY}, shi[3] = {-INFINITY, -INFINITY, -INFINITY};
  double hmin = INFINITY, hmax = 0.0, rho = INFINITY;
  *ok = 0;
  for (int i = 0; i < rows->m; i++) {
    double x[3], xi[3], lo[3], hi[3];
    int c;
    if (!active[i] || rows->tool[i] < 0 || !nh_row_point(m, rows, i, x)) continue;
    if (nh_mesh_locate(m, x, &c, xi)) continue;
    nh_leaf_box(m, c, lo, hi);
    int meets = 0;
    for (int p = 0; p < n_points && !meets; p++) {
      int in = 1;
      for (int k = 0; k < 3; k++)
        in &= points[3 * p + k] - radius < hi[k] && points[3 * p + k] + radius > lo[k];
      meets = in;
    }
    if (!meets) continue;
    if (rows->disc[10 * (size_t)i + 9] > 0.0) rho = fmin(rho, rows->disc[10 * (size_t)i + 9]);
    for (int k = 0; k < 3; k++) {
      slo[k] = fmin(slo[k], lo[k]), shi[k] = fmax(shi[k], hi[k]);
      hmin = fmin(hmin, hi[k] - lo[k]), hmax = fmax(hmax, hi[k] - lo[k]);
    }
  }
  if (!(hmax > 0.0)) return NH_OK; /* no seed */
  double blo[3], bhi[3];           /* the mesh's box */
  for (int k = 0; k < 3; k++) blo[k] = bhi[k] = m->X[k];
  for (int v = 1; v < m->n_nodes; v++)
    for (int k = 0; k < 3; k++)
      blo[k] = fmin(blo[k], m->X[3 * v + k]), bhi[k] = fmax(bhi[k], m->X[3 * v + k]);
  int depth = NH_LOCAL_DEPTH; /* and finer until a held disc spans 3 lattice cells */
  while (depth < NH_LOCAL_MAX_DEPTH && hmin / (double)(1 << depth) > 2.0 * rho / 3.0) depth++;
  L->h = hmin / (double)(1 << depth);
  long nn = 1, nfree = 1;
  int outer[3][2]; /* ω's faces on the mesh's boundary: natural there, not z_h */
  for (int k = 0; k < 3; k++) {
    const double tol = 1e-9 * L->h, hi = fmin(shi[k] + NH_LOCAL_RING * hmax, bhi[k]);
    L->lo[k] = fmax(slo[k] - NH_LOCAL_RING * hmax, blo[k]);
    L->n[k] = (int)lround((hi - L->lo[k]) / L->h);
    outer[k][0] = L->lo[k] <= blo[k] + tol, outer[k][1] = hi >= bhi[k] - tol;
    nn *= L->n[k] + 1, nfree *= L->n[k] + 1;
  }
  if (3 * nfree > NH_LOCAL_MAX_DOFS) return NH_OK;
  const int ncell = L->n[0] * L->n[1] * L->n[2];
  L->Xn = nh_calloc(3 * (size_t)nn, sizeof(double));
  L->dof = nh_calloc(3 * (size_t)nn, sizeof(int));
  L->leaf = nh_calloc((size_t)ncell, sizeof(int));
  L->phi = nh_calloc((size_t)ncell, sizeof(double));
  if (!L->Xn || !L->dof || !L->leaf || !L->phi)
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual");
  L->nf = 0;
  for (int k = 0; k <= L->n[2]; k++)
    for (int j = 0; j <= L->n[1]; j++)
      for (int i = 0; i <= L->n[0]; i++) {
        int v = nh_lat_node(L, i, j, k), ijk[3] = {i, j, k}, inner = 1;
        for (int d = 0; d < 3; d++) {
          L->Xn[3 * v + d] = L->lo[d] + L->h * ijk[d];
          inner &= (ijk[d] > 0 || outer[d][0]) && (ijk[d] < L->n[d] || outer[d][1]);
        }
        double held[3] = {1, 1, 1}; /* < ½: a fixed DOF (z = 0) */
        if (inner && free_mask) nh_mesh_sample(m, free_mask, 1, L->Xn + 3 * v, held, NULL);
        for (int d = 0; d < 3; d++) L->dof[3 * v + d] = inner && held[d] > 0.5 ? L->nf++ : -1;
      }
  for (int e = 0; e < ncell; e++) {
    int v[8], c;
    double Xe[24], x[3] = {0, 0, 0}, xi[3];
    nh_lat_cell_nodes(L, e, v);
    nh_lat_cell_coords(L, v, Xe);
    for (int a = 0; a < 8; a++)
      for (int d = 0; d < 3; d++) x[d] += 0.125 * Xe[3 * a + d];
    if (nh_mesh_locate(m, x, &c, xi)) { /* no cell: outside the tissue */
      L->leaf[e] = -1, L->phi[e] = NH_LOCAL_PHI_MIN;
      continue;
    }
    L->leaf[e] = c;
    /* the tissue's part of a fine cell in a cut leaf: its Gauss points inside */
    L->phi[e] = 1.0;
    if (m->fill[c] < 1.0) {
      double gx[24], v8[24];
      unsigned char in[8];
      int n_in = 0;
      for (int g = 0; g < 8; g++)
        for (int d = 0; d < 3; d++)
          gx[3 * g + d] = x[d] + 0.5 * L->h * NH_GAUSS * nh_hex_corner[g][d];
      nh_mesh_sample(m, m->X, 8, gx, v8, in);
      for (int g = 0; g < 8; g++) n_in += in[g];
      L->phi[e] = fmax(n_in / 8.0, NH_LOCAL_PHI_MIN);
    }
  }
  *ok = 1;
  return NH_OK;
}

static void nh_lattice_free(nh_lattice *L) {
  free(L->Xn), free(L->dof), free(L->leaf), free(L->phi), free(L->zh);
  memset(L, 0, sizeof *L);
}

/* Fine cell e's tangent Kt = R (K₀ + κ V ḡ ḡᵀ [B-bar]) Rᵀ and its data. */
static int nh_lat_cell_stiffness(const nh_lattice *L, const nh_leaf_data *d, int e,
                                 double Kt[576]) {
  int v[8];
  double Xe[24], K0[576], G0[24], Gb[24], V;
  nh_lat_cell_nodes(L, e, v);
  nh_lat_cell_coords(L, v, Xe);
  if (nh_hex_stiffness(Xe, d->lambda, d->mu, d->gbar != NULL, K0, G0, Gb, &V))
    return NH_ERROR(NH_ERR_NUMERIC, "local dual: a lattice cell has a non-positive Jacobian");
  if (d->gbar) {
    const double kappa = d->lambda + 2.0 * d->mu / 3.0;
    for (int r = 0; r < 24; r++)
      for (int q = 0; q < 24; q++) K0[24 * r + q] += kappa * V * Gb[r] * Gb[q];
  }
  for (int a = 0; a < 8; a++)
    for (int b = 0; b < 8; b++) {
      double B[9], T[9];
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) B[3 * i + j] = K0[24 * (3 * a + i) + 3 * b + j];
      for (int i = 0; i < 3; i++) /* T = R B */
        for (int j = 0; j < 3; j++)
          T[3 * i + j] =
              d->R[3 * i] * B[j] + d->R[3 * i + 1] * B[3 + j] + d->R[3 * i + 2] * B[6 + j];
      for (int i = 0; i < 3; i++) /* R B Rᵀ */
        for (int j = 0; j < 3; j++)
          Kt[24 * (3 * a + i) + 3 * b + j] = T[3 * i] * d->R[3 * j] +
                                             T[3 * i + 1] * d->R[3 * j + 1] +
                                             T[3 * i + 2] * d->R[3 * j + 2];
    }
  return NH_OK;
}

int nh_dwr_local_term(const nh_mesh *m, const nh_tissue *t, const nh_hanging *h, const double *u,
                      const nh_rows *rows, const double *force, const double *free_mask, int nz,
                      const double *z, int n_points, const double *points, double radius,
                      const double *weights, const nh_geometry_loads *loads, double *L_out,
                      unsigned char *replaced, int *applied) {
  *applied = 0;
  if (!rows || rows->m == 0 || nz == 0) return NH_OK;
  const size_t n3 = 3 * (size_t)m->n_nodes;
  nh_lattice L = {0};
  unsigned char *active = nh_calloc((size_t)rows->m, 1);
  nh_leaf_data *ld = NULL;
  double *Kc = NULL, *jf = NULL, *zf = NULL, *Y = NULL, *W = NULL, *eig = NULL, *rhs = NULL;
  int *ridx = NULL, *aidx = NULL, nr = 0, na = 0, ok = 0, rc = NH_OK;
  /* fine row r: lattice nodes rnode[e] with weights rwt[e], rstart[r] <= e < rstart[r + 1] */
  int *rstart = NULL, *rnode = NULL, cap_r = 0, cap_w = 0;
  double *rwt = NULL, *wl = NULL, *ih = NULL, *pih = NULL; /* w' and its parts */
  int *node_start = NULL, *node_leaf = NULL;
  cholmod_common cm;
  cholmod_start(&cm);
  cholmod_factor *F = NULL;
  cholmod_sparse *K = NULL;
  cholmod_dense *B = NULL, *X = NULL;
  if (!active) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual");
    goto done;
  }
  nh_dwr_active_rows(rows, active);
  if ((rc = nh_lattice_build(m, rows, active, free_mask, n_points, points, radius, &L, &ok)) || !ok)
    goto done;
  const int nx = L.n[0], ny = L.n[1], ncell = nx * ny * L.n[2], nf = L.nf;
  const long nn = (long)(nx + 1) * (ny + 1) * (L.n[2] + 1);
  if (nf == 0) goto done;

  /* the leaves under the lattice and their data */
  ld = nh_calloc((size_t)ncell, sizeof *ld);
  Kc = nh_calloc(576 * (size_t)ncell, sizeof(double));
  L.zh = nh_calloc(3 * (size_t)nn * (size_t)nz, sizeof(double));
  jf = nh_calloc((size_t)nf * (size_t)nz, sizeof(double));
  if (!ld || !Kc || !L.zh || !jf) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual (%d DOFs)", nf);
    goto done;
  }
  int any = -1; /* a leaf under ω: its data stand in where there is none */
  for (int e = 0; e < ncell && any < 0; e++) any = L.leaf[e];
  for (int e = 0; e < ncell; e++) {
    nh_leaf_data_get(m, t, u, L.leaf[e] >= 0 ? L.leaf[e] : any, ld + e);
    if ((rc = nh_lat_cell_stiffness(&L, ld + e, e, Kc + 576 * (size_t)e))) goto done;
    for (int i = 0; i < 576; i++) Kc[576 * (size_t)e + i] *= L.phi[e];
  }
  for (int q = 0; q < nz; q++)
    nh_mesh_sample(m, z + n3 * q, (int)nn, L.Xn, L.zh + 3 * (size_t)nn * q, NULL);

  /* K_f (upper triangle) and the right-hand sides j_f − K_fb z_b */
  {
    cholmod_triplet *T =
        cholmod_allocate_triplet(nf, nf, 576 * (size_t)ncell, 1, CHOLMOD_REAL, &cm);
    if (!T) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's matrix");
      goto done;
    }
    int *Ti = T->i, *Tj = T->j;
    double *Tx = T->x;
    for (int e = 0; e < ncell; e++) {
      int v[8];
      nh_lat_cell_nodes(&L, e, v);
      const double *Ke = Kc + 576 * (size_t)e;
      for (int r = 0; r < 24; r++) {
        int dr = L.dof[3 * v[r / 3] + r % 3];
        if (dr < 0) continue;
        for (int s = 0; s < 24; s++) {
          int ds = L.dof[3 * v[s / 3] + s % 3];
          if (ds < 0) {
            for (int q = 0; q < nz; q++)
              jf[(size_t)nf * q + dr] -=
                  Ke[24 * r + s] * L.zh[3 * (size_t)nn * q + 3 * (size_t)v[s / 3] + s % 3];
          } else if (dr <= ds) {
            Ti[T->nnz] = dr, Tj[T->nnz] = ds, Tx[T->nnz] = Ke[24 * r + s], T->nnz++;
          }
        }
      }
    }
    K = cholmod_triplet_to_sparse(T, T->nnz, &cm);
    cholmod_free_triplet(&T, &cm);
    if (!K) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's matrix");
      goto done;
    }
  }
  /* j_f: each goal box's mean, integrated exactly on the lattice */
  for (int p = 0; p < n_points; p++) {
    const double *P = points + 3 * p;
    double vol = 0.0; /* |B ∩ Ω| on the mesh (fill-weighted), as nh_goal_functional's */
    for (int l = 0; l < m->n_leaves; l++) {
      double lo[3], hi[3], ov = m->fill[m->leaves[l]];
      nh_leaf_box(m, m->leaves[l], lo, hi);
      for (int k = 0; k < 3; k++)
        ov *= fmax(0.0, fmin(hi[k], P[k] + radius) - fmax(lo[k], P[k] - radius));
      vol += ov;
    }
    if (!(vol > 0.0)) continue;
    for (int e = 0; e < ncell; e++) {
      int v[8];
      double hat[3][2], Xe[24];
      nh_lat_cell_nodes(&L, e, v);
      nh_lat_cell_coords(&L, v, Xe);
      for (int k = 0; k < 3; k++)
        nh_hat_integrals(Xe[k], L.h, P[k] - radius, P[k] + radius, hat[k]);
      if (hat[0][0] + hat[0][1] == 0.0 || hat[1][0] + hat[1][1] == 0.0 ||
          hat[2][0] + hat[2][1] == 0.0)
        continue;
      for (int a = 0; a < 8; a++) {
        double s = hat[0][nh_hex_corner[a][0] > 0] * hat[1][nh_hex_corner[a][1] > 0] *
                   hat[2][nh_hex_corner[a][2] > 0] / vol;
        for (int k = 0; k < 3; k++) {
          int dv = L.dof[3 * v[a] + k];
          if (dv < 0) continue;
          for (int q = 0; q < nz; q++) {
            double w = weights[(size_t)3 * n_points * q + 3 * p + k];
            if (w != 0.0) jf[(size_t)nf * q + dv] += w * s;
          }
        }
      }
    }
  }

  /* the rows in ω, sampled on the lattice: a disc row's disc again at h_f
   * (nh_disc_points), a point row at its point */
  ridx = nh_calloc((size_t)rows->m, sizeof(int));
  rstart = nh_calloc((size_t)rows->m + 1, sizeof(int));
  if (!ridx || !rstart) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's rows");
    goto done;
  }
  for (int i = 0; i < rows->m; i++) {
    double pts[3 * NH_DISC_MAX_POINTS], pw[NH_DISC_MAX_POINTS], total = 0.0;
    const double *disc = rows->disc + 10 * (size_t)i;
    if (rows->tool2[i] >= 0) continue;
    int np = nh_disc_points(disc, disc + 3, disc + 6, disc[9], L.h, pts, pw);
    if (np == 0) {
      if (!nh_row_point(m, rows, i, pts)) continue;
      np = 1, pw[0] = 1.0;
    }
    const int first = rstart[nr];
    if (nh_grow((void **)&rnode, &cap_r, first + 8 * np, sizeof *rnode) ||
        nh_grow((void **)&rwt, &cap_w, first + 8 * np, sizeof *rwt)) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's rows");
      goto done;
    }
    int e = first;
    for (int q = 0; q < np; q++) {
      double xi[3], N[8];
      int ijk[3], in = 1, v[8];
      for (int k = 0; k < 3; k++) {
        double s = (pts[3 * q + k] - L.lo[k]) / L.h;
        in &= s > 0.0 && s < L.n[k];
        ijk[k] = (int)fmin(fmax(floor(s), 0.0), L.n[k] - 1.0);
        xi[k] = 2.0 * (s - ijk[k]) - 1.0;
      }
      if (!in) continue; /* outside ω: left out, the rest renormalised */
      nh_hex_shape(xi, N);
      nh_lat_cell_nodes(&L, ijk[0] + nx * (ijk[1] + ny * ijk[2]), v);
      for (int a = 0; a < 8; a++) rnode[e] = v[a], rwt[e++] = pw[q] * N[a];
      total += pw[q];
    }
    if (!(total > 0.0)) continue;
    for (int k = first; k < e; k++) rwt[k] /= total;
    ridx[nr++] = i;
    na += active[i] != 0;
    rstart[nr] = e;
  }

  /* the active ones hold the dual: C_f */
  if (!(aidx = nh_calloc((size_t)(na ? na : 1), sizeof(int)))) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's rows");
    goto done;
  }
  na = 0;
  for (int r = 0; r < nr; r++)
    if (active[ridx[r]]) aidx[na++] = r;

  /* z0 = K⁻¹ (j_f − K_fb z_b); with rows, Y = K⁻¹ C_fᵀ, W μ = C z0 + C_b z_b */
  F = cholmod_analyze(K, &cm);
  if (F) nh_cholmod_factorize(K, F, &cm);
  if (!F || cm.status != CHOLMOD_OK || F->minor < (size_t)nf) {
    rc = NH_ERROR(NH_ERR_NUMERIC, "local dual: the lattice's matrix is not positive definite");
    goto done;
  }
  const int ncol = nz + na;
  B = cholmod_zeros(nf, ncol, CHOLMOD_REAL, &cm);
  if (!B) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's right-hand sides");
    goto done;
  }
  double *Bx = B->x;
  memcpy(Bx, jf, sizeof(double) * (size_t)nf * nz);
  for (int r = 0; r < na; r++)
    for (int e = rstart[aidx[r]]; e < rstart[aidx[r] + 1]; e++)
      for (int k = 0; k < 3; k++) {
        int ds = L.dof[3 * rnode[e] + k];
        if (ds >= 0) Bx[(size_t)nf * (nz + r) + ds] += rwt[e] * rows->dir[3 * ridx[aidx[r]] + k];
      }
  X = cholmod_solve(CHOLMOD_A, F, B, &cm);
  if (!X) {
    rc = NH_ERROR(NH_ERR_NUMERIC, "local dual: the solve failed");
    goto done;
  }
  zf = nh_calloc(3 * (size_t)nn * (size_t)nz, sizeof(double));
  if (!zf) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual");
    goto done;
  }
  const double *Xx = X->x;
  double *mu = NULL;
  if (na > 0) {
    W = nh_calloc((size_t)na * na, sizeof(double));
    eig = nh_calloc((size_t)na, sizeof(double));
    rhs = nh_calloc((size_t)na * (size_t)nz, sizeof(double));
    mu = nh_calloc((size_t)na * (size_t)nz, sizeof(double));
    Y = mu;
    if (!W || !eig || !rhs || !mu) {
      free(mu);
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's rows");
      goto done;
    }
    /* C v over a column of X (free part) plus, for rhs, C_b z_b */
    for (int r = 0; r < na; r++)
      for (int e = rstart[aidx[r]]; e < rstart[aidx[r] + 1]; e++)
        for (int k = 0; k < 3; k++) {
          int node = rnode[e], ds = L.dof[3 * node + k];
          double c = rwt[e] * rows->dir[3 * ridx[aidx[r]] + k];
          for (int col = 0; col < na && ds >= 0; col++)
            W[(size_t)na * col + r] += c * Xx[(size_t)nf * (nz + col) + ds];
          for (int q = 0; q < nz; q++)
            rhs[(size_t)na * q + r] +=
                c * (ds >= 0 ? Xx[(size_t)nf * q + ds] : L.zh[3 * (size_t)nn * q + 3 * node + k]);
        }
    /* W⁺ by its eigenvectors, eigenvalues below 1e-12 of the largest dropped
     * (dependent rows: C_fᵀ μ is unique, μ is not) */
    for (int a = 0; a < na; a++) /* symmetrise round-off */
      for (int b = 0; b < a; b++)
        W[(size_t)na * b + a] = W[(size_t)na * a + b] =
            0.5 * (W[(size_t)na * b + a] + W[(size_t)na * a + b]);
    if (LAPACKE_dsyev(LAPACK_COL_MAJOR, 'V', 'U', na, W, na, eig)) {
      free(mu);
      rc = NH_ERROR(NH_ERR_NUMERIC, "local dual: the rows' compliance has no eigenvalues");
      goto done;
    }
    const double cut = 1e-12 * eig[na - 1];
    for (int q = 0; q < nz; q++)
      for (int a = 0; a < na; a++) {
        if (!(eig[a] > cut)) continue;
        double s = 0.0;
        for (int b = 0; b < na; b++) s += W[(size_t)na * a + b] * rhs[(size_t)na * q + b];
        s /= eig[a];
        for (int b = 0; b < na; b++) mu[(size_t)na * q + b] += s * W[(size_t)na * a + b];
      }
  }
  /* z_f at every lattice node: boundary z_h, inside z0 − Y μ */
  for (int q = 0; q < nz; q++)
    for (long v = 0; v < nn; v++)
      for (int k = 0; k < 3; k++) {
        int dv = L.dof[3 * v + k];
        double s = L.zh[3 * (size_t)nn * q + 3 * v + k];
        if (dv >= 0) {
          s = Xx[(size_t)nf * q + dv];
          for (int r = 0; r < na; r++) s -= Xx[(size_t)nf * (nz + r) + dv] * Y[(size_t)na * q + r];
        }
        zf[3 * (size_t)nn * q + 3 * v + k] = s;
      }
  free(mu), Y = NULL;

  /* w = z_f − z_h at the lattice's nodes (0 on ∂ω), then w' = w − P I_h w:
   * I_h w the mesh's nodal interpolant of w at the nodes all of whose leaves
   * lie inside ω (0 elsewhere; hanging nodes their masters'), carried back
   * to the lattice by the mesh's trilinear fields */
  wl = nh_calloc(3 * (size_t)nn * (size_t)nz, sizeof(double));
  ih = nh_calloc(n3, sizeof(double));
  pih = nh_calloc(3 * (size_t)nn, sizeof(double));
  if (!wl || !ih || !pih || (rc = nh_mesh_node_leaves(m, &node_start, &node_leaf)) != NH_OK) {
    rc = rc ? rc : NH_ERROR(NH_ERR_MEMORY, "out of memory: local dual's weight");
    goto done;
  }
  for (size_t i = 0; i < 3 * (size_t)nn * (size_t)nz; i++) wl[i] = zf[i] - L.zh[i];
  for (int q = 0; q < nz; q++) {
    double *wq = wl + 3 * (size_t)nn * q;
    memset(ih, 0, n3 * sizeof(double));
    for (int v = 0; v < m->n_nodes; v++) {
      int inside = node_start[v + 1] > node_start[v];
      for (int k = node_start[v]; k < node_start[v + 1] && inside; k++) {
        double lo[3], hi[3];
        nh_leaf_box(m, node_leaf[k], lo, hi); /* cell ids */
        for (int d = 0; d < 3; d++)
          inside &= lo[d] >= L.lo[d] - 1e-9 * L.h && hi[d] <= L.lo[d] + L.h * L.n[d] + 1e-9 * L.h;
      }
      if (inside) nh_lat_sample(&L, wq, m->X + 3 * (size_t)v, ih + 3 * (size_t)v);
    }
    if (h) nh_hanging_interpolate(h, ih, 3);
    nh_mesh_sample(m, ih, (int)nn, L.Xn, pih, NULL);
    for (size_t i = 0; i < 3 * (size_t)nn; i++) wq[i] -= pih[i];
  }

  /* L_q = Σ_e φ_e ∫ (ρ b · w' − σ_h(u_h) : ε(w')) + Σ_i Λ_i n_i · w'(rows' points) */
  for (int q = 0; q < nz; q++) {
    L_out[q] = 0.0;
    for (int r = 0; r < nr && force; r++)
      for (int e = rstart[r]; e < rstart[r + 1]; e++)
        for (int k = 0; k < 3; k++)
          L_out[q] += force[ridx[r]] * rwt[e] * rows->dir[3 * ridx[r] + k] *
                      wl[3 * (size_t)nn * q + 3 * (size_t)rnode[e] + k];
  }
  for (int e = 0; e < ncell; e++) {
    const nh_leaf_data *d = ld + e;
    if (L.leaf[e] < 0) continue; /* no tissue */
    int v[8];
    double Xe[24];
    nh_lat_cell_nodes(&L, e, v);
    nh_lat_cell_coords(&L, v, Xe);
    for (int gp = 0; gp < 8; gp++) {
      double xf[3], xl[3], g[24], gl[24], N[8], su[6], x[3] = {0, 0, 0};
      for (int k = 0; k < 3; k++) xf[k] = NH_GAUSS * nh_hex_corner[gp][k];
      nh_hex_shape(xf, N);
      double detJ = nh_hex_gradients(Xe, xf, g);
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) x[k] += N[a] * Xe[3 * a + k];
      for (int k = 0; k < 3; k++) xl[k] = 2.0 * (x[k] - d->lo[k]) / (d->hi[k] - d->lo[k]) - 1.0;
      memcpy(gl, d->G0, sizeof gl);
      nh_hex_gradients(d->Xe, xl, gl);
      nh_hex_rotated_stress(d->R, d->du, gl, d->lambda, d->mu, d->gbar ? &d->theta : NULL, su);
      double eu[6];
      nh_voigt_compliance(d->lambda, d->mu, su, eu);
      for (int q = 0; q < nz; q++) {
        double w[24], dw[24], sw[6], s = 0.0, fb = 0.0;
        for (int a = 0; a < 8; a++)
          for (int k = 0; k < 3; k++) w[3 * a + k] = wl[3 * (size_t)nn * q + 3 * (size_t)v[a] + k];
        for (int a = 0; a < 8; a++) /* Rᵀ w */
          for (int i = 0; i < 3; i++)
            dw[3 * a + i] =
                d->R[i] * w[3 * a] + d->R[3 + i] * w[3 * a + 1] + d->R[6 + i] * w[3 * a + 2];
        nh_hex_rotated_stress(d->R, dw, g, d->lambda, d->mu, NULL, sw);
        for (int i = 0; i < 6; i++) s += sw[i] * eu[i]; /* σ_u : ε(w) = σ(w) : D⁻¹σ_u */
        if (loads)
          for (int a = 0; a < 8; a++)
            for (int k = 0; k < 3; k++) fb += N[a] * loads->body[k] * w[3 * a + k];
        L_out[q] += L.phi[e] * detJ * (d->rho * fb - s);
      }
    }
  }
  for (int l = 0; l < m->n_leaves && replaced; l++) {
    double lo[3], hi[3];
    int in = 1;
    nh_leaf_box(m, m->leaves[l], lo, hi);
    for (int k = 0; k < 3; k++) {
      double c = 0.5 * (lo[k] + hi[k]);
      in &= c > L.lo[k] && c < L.lo[k] + L.h * L.n[k];
    }
    replaced[l] = (unsigned char)in;
  }
  *applied = 1;

done:
  cholmod_free_dense(&X, &cm);
  cholmod_free_dense(&B, &cm);
  cholmod_free_factor(&F, &cm);
  cholmod_free_sparse(&K, &cm);
  cholmod_finish(&cm);
  nh_lattice_free(&L);
  free(active), free(ld), free(Kc), free(jf), free(zf), free(W), free(eig), free(rhs);
  free(ridx), free(aidx), free(rstart), free(rnode), free(rwt), free(wl), free(ih), free(pih);
  free(node_start), free(node_leaf);
  return rc;
}
