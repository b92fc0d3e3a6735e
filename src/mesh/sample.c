/* sample.c — a nodal field at arbitrary points and at the voxel centres of
 * an image, and the inverse of the deformation map, for the displacement
 * field and the shifted image written on the patient's images
 * (docs/anatomy.md, "Displacement fields and shifted images").
 *
 * Sampling. u(X) = Σₐ Nₐ(ξ) uₐ over the 8 corners of the leaf holding the
 * rest point X, ξ its natural coordinates: the finite element field itself.
 * The leaf's own 8 nodes suffice on a refined mesh because a hanging node's
 * value is its masters' interpolation: the solver eliminates hanging nodes
 * (u = P u_free, solve/system.c) or ties them by the rows u_h − Σ w u_m = 0
 * solved exactly with the step (solve/compliance.c), and a mesh change sets
 * them by nh_hanging_interpolate (sim.c, nh_sim_rebuild). On a face shared
 * by a coarse leaf and its finer neighbours the fine leaves' bilinear face
 * values then equal the coarse leaf's, so u is continuous across it (the
 * test checks this on both sides of a refinement face).
 *
 * Walking the lattice. The level-0 cells are the cells of a regular lattice
 * (origin, spacing, grid), mesh->root mapping a lattice cell to its kept
 * cell or -1 (dropped: outside the mesh); nodes never move from the lattice
 * in the rest configuration. A point's level-0 cell is therefore found by
 * arithmetic, then the hierarchy is descended to the leaf; an axis-aligned
 * box cell (every level-0 cell, and every child of a template whose children
 * are boxes in natural coordinates) gives ξ in closed form, other cells by
 * Newton's method (nh_hex_invert). The previous point's leaf is tried first:
 * consecutive voxel centres usually share a leaf, so most voxels cost one
 * containment test. A point within round-off of a lattice plane, or any
 * point of a mesh whose level-0 nodes are not on the lattice (tests distort
 * them), falls back to nh_mesh_locate. The tissue mask is 1 where the point
 * lies in a leaf and inside the domain's shape (F < 0; a box domain: the mesh
 * is the tissue); there the value is u, elsewhere 0.
 *
 * The inverse map. The shifted anatomy shows at a point x what was at the
 * rest point X with X + u(X) = x. X is the fixed point of
 *     g(X) = x − u(X),      X_{k+1} = g(X_k).
 * u is continuous and piecewise trilinear, so Lipschitz with constant
 * L = max over leaves of ‖∇u‖₂; |g(X) − g(Y)| = |u(X) − u(Y)| ≤ L |X − Y|,
 * and for L < 1 (no element inverted or folded back; brain shift has
 * |∇u| of a few per cent to some tens of per cent) g is a contraction:
 * the fixed point is unique and the error falls at least by L per
 * iteration, |X_k − X*| ≤ L^k |X_0 − X*|. Stopping rule: the first k with
 * |X_{k+1} − X_k| ≤ tol (default 1e-3 of the smallest voxel spacing); then
 * |X_{k+1} − X*| ≤ L/(1 − L) tol, below tol for L ≤ 1/2. The iterations
 * needed are about log(tol / |X_1 − X_0|) / log L: 4–6 for L = 0.1–0.2 from
 * X_0 = x. X_0 is x − u of the previous voxel's solution (the neighbour
 * along i, or along j or k at a row's start) when that one converged in the
 * tissue, since u varies little between neighbours; else x.
 * Outside the mesh u is taken as 0 (what surrounds the tissue, the skull
 * and the air, does not move), inside the mesh u is the element field also
 * in the part of a cut cell outside the shape (its continuous extension),
 * so the iteration does not see a jump at the tissue's surface. Outcomes:
 *   - converged with X in the tissue (status NH_INVERSE_TISSUE): x lies in
 *     the shifted tissue, warped(x) = I(X);
 *   - converged with X outside the tissue (NH_INVERSE_OUTSIDE): x outside the
 *     mesh gives X = x (the surroundings stay); x in a gap the tissue left
 *     (it receded from the skull) takes X from the extension in the cut
 *     cells, up to one cell beyond the surface, else X = x: the image there
 *     is not tissue's, and the simulation says nothing about it;
 *   - not converged (NH_INVERSE_UNCONVERGED): at the mesh's outer surface,
 *     where u jumps from its value to 0, the iterates cycle between the
 *     mesh and the outside; where L ≥ 1 they need not converge. A
 *     contraction shortens every step, so the iteration stops once three
 *     steps have not (or after max_iterations): X = x, counted in the
 *     statistics.
 * Tissue that moved beyond the mesh's rest extent (the mesh then ends
 * before the shifted surface) is found from points x outside the lattice's
 * box only within max |u| of it: the iteration is restarted there from x
 * clamped to the box. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NH_XI_TOL 1e-9

typedef struct {
  const nh_mesh *m;
  int lattice; /* every level-0 cell is its lattice box (the fast path is exact) */
  int last;    /* the leaf found last, or -1 */
} nh_finder;

/* 1 if cell c is an axis-aligned box (corners within 1e-10 of its size of
 * the box of corners 0 and 6): lo, hi. */
static int nh_cell_box(const nh_mesh *m, int c, double lo[3], double hi[3]) {
  const int *e = m->cells + 8 * c;
  const double *a = m->X + 3 * e[0], *b = m->X + 3 * e[6];
  double size = 0.0;
  for (int k = 0; k < 3; k++) {
    lo[k] = a[k], hi[k] = b[k];
    if (!(hi[k] > lo[k])) return 0;
    size = fmax(size, hi[k] - lo[k]);
  }
  for (int n = 0; n < 8; n++)
    for (int k = 0; k < 3; k++) {
      double want = nh_hex_corner[n][k] > 0 ? hi[k] : lo[k];
      if (fabs(m->X[3 * e[n] + k] - want) > 1e-10 * size) return 0;
    }
  return 1;
}

/* 1 if x lies in cell c (natural coordinates within 1 + NH_XI_TOL): xi. */
static int nh_cell_contains(const nh_mesh *m, int c, const double x[3], double xi[3]) {
  double lo[3], hi[3];
  if (nh_cell_box(m, c, lo, hi)) {
    for (int k = 0; k < 3; k++) xi[k] = (2.0 * x[k] - lo[k] - hi[k]) / (hi[k] - lo[k]);
  } else {
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    if (nh_hex_invert(Xe, x, xi) != NH_OK) return 0;
  }
  for (int k = 0; k < 3; k++)
    if (!(fabs(xi[k]) <= 1.0 + NH_XI_TOL)) return 0;
  return 1;
}

static void nh_finder_init(nh_finder *f, const nh_mesh *m) {
  f->m = m, f->last = -1, f->lattice = 1;
  for (int c = 0; c < m->n_cells && f->lattice; c++) {
    if (m->parent[c] >= 0) continue;
    double lo[3], hi[3];
    f->lattice = nh_cell_box(m, c, lo, hi);
    for (int k = 0; k < 3 && f->lattice; k++) {
      double s = (lo[k] - m->origin[k]) / m->spacing[k];
      f->lattice = fabs(s - floor(s + 0.5)) < 1e-9 &&
                   fabs(hi[k] - lo[k] - m->spacing[k]) <= 1e-9 * m->spacing[k];
    }
  }
}

/* The leaf holding x and its natural coordinates; 0 if x is outside the mesh. */
static int nh_finder_locate(nh_finder *f, const double x[3], int *cell, double xi[3]) {
  const nh_mesh *m = f->m;
  if (f->last >= 0 && nh_cell_contains(m, f->last, x, xi)) {
    *cell = f->last;
    return 1;
  }
  int q[3], on_plane = 0;
  for (int k = 0; k < 3; k++) {
    double s = (x[k] - m->origin[k]) / m->spacing[k];
    if (!(s >= -NH_XI_TOL && s <= m->grid[k] + NH_XI_TOL)) return 0;
    on_plane |= fabs(s - floor(s + 0.5)) < NH_XI_TOL;
    q[k] = (int)floor(s);
    q[k] = q[k] < 0 ? 0 : q[k] >= m->grid[k] ? m->grid[k] - 1 : q[k];
  }
  int c = q[0] + m->grid[0] * (q[1] + m->grid[1] * q[2]);
  if (m->root) c = m->root[c];
  if (c >= 0 && nh_cell_contains(m, c, x, xi)) {
    while (c >= 0 && m->first_child[c] >= 0) {
      int found = -1;
      for (int ch = m->first_child[c]; ch < m->first_child[c] + m->n_children[c] && found < 0; ch++)
        if (nh_cell_contains(m, ch, x, xi)) found = ch;
      c = found;
    }
    if (c >= 0) {
      *cell = f->last = c;
      return 1;
    }
  } else if (c < 0 && f->lattice && !on_plane) {
    return 0; /* a dropped lattice cell: outside the mesh */
  }
  if (nh_mesh_locate(m, x, cell, xi) != NH_OK) return 0;
  f->last = *cell;
  return 1;
}

/* u at x (0 outside the mesh); returns 1 if x is in the mesh, 2 if also in
 * the tissue when `tissue` is asked. */
static int nh_finder_value(nh_finder *f, const double *field, const double x[3], int tissue,
                           double u[3]) {
  int c;
  double xi[3], N[8];
  u[0] = u[1] = u[2] = 0.0;
  if (!nh_finder_locate(f, x, &c, xi)) return 0;
  for (int k = 0; k < 3; k++) xi[k] = fmax(-1.0, fmin(1.0, xi[k]));
  nh_hex_shape(xi, N);
  const int *e = f->m->cells + 8 * c;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) u[k] += N[a] * field[3 * e[a] + k];
  if (!tissue) return 1;
  const nh_domain *d = &f->m->domain;
  return d->kind == NH_DOMAIN_BOX || nh_domain_inside(d, x) ? 2 : 1;
}

void nh_mesh_sample(const nh_mesh *mesh, const double *field, int n, const double *X,
                    double *values, unsigned char *tissue) {
  nh_finder f;
  nh_finder_init(&f, mesh);
  for (int i = 0; i < n; i++) {
    double *u = values + 3 * (size_t)i;
    int in = nh_finder_value(&f, field, X + 3 * (size_t)i, 1, u) == 2;
    if (!in) u[0] = u[1] = u[2] = 0.0;
    if (tissue) tissue[i] = (unsigned char)in;
  }
}

int nh_mesh_sample_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                         double *values, unsigned char *tissue) {
  nh_finder f;
  nh_finder_init(&f, mesh);
  size_t v = 0;
  for (int k = 0; k < image->n[2]; k++) {
    NH_TRY(nh_stop_check());
    for (int j = 0; j < image->n[1]; j++)
      for (int i = 0; i < image->n[0]; i++, v++) {
        double ijk[3] = {i, j, k}, x[3], *u = values + 3 * v;
        nh_image_to_world(image, ijk, x);
        int in = nh_finder_value(&f, field, x, 1, u) == 2;
        if (!in) u[0] = u[1] = u[2] = 0.0;
        if (tissue) tissue[v] = (unsigned char)in;
      }
  }
  return NH_OK;
}

/* ---- the inverse map ---- */

typedef struct {
  nh_finder f;
  const double *field;
  double tol, reach; /* reach: max nodal |u| (restarts from the lattice box) */
  double box_lo[3], box_hi[3];
  int max_iterations;
  nh_inverse_stats st;
  double iterations_sum;
} nh_inverse;

static void nh_inverse_init(nh_inverse *inv, const nh_mesh *m, const double *field,
                            const nh_image *image, const nh_inverse_options *opt) {
  memset(inv, 0, sizeof *inv);
  nh_finder_init(&inv->f, m);
  inv->field = field;
  double h = fmin(image->spacing[0], fmin(image->spacing[1], image->spacing[2]));
  inv->tol = opt && opt->tolerance > 0 ? opt->tolerance : 1e-3 * h;
  inv->max_iterations = opt && opt->max_iterations > 0 ? opt->max_iterations : 100;
  for (int i = 0; i < m->n_nodes; i++) inv->reach = fmax(inv->reach, nh_vec3_norm(field + 3 * i));
  for (int k = 0; k < 3; k++)
    inv->box_lo[k] = m->origin[k], inv->box_hi[k] = m->origin[k] + m->grid[k] * m->spacing[k];
}

/* Iterate from X (in: X_0, out: the result) for the point x. Returns the
 * status; *iterations the evaluations of u. */
static int nh_inverse_iterate(nh_inverse *inv, const double x[3], double X[3], int *iterations) {
  double u[3], step_prev = 0.0, ratio = 0.0;
  int stalls = 0;
  for (int it = 1; it <= inv->max_iterations; it++) {
    nh_finder_value(&inv->f, inv->field, X, 0, u);
    double step = 0.0;
    for (int k = 0; k < 3; k++) {
      double next = x[k] - u[k];
      step += (next - X[k]) * (next - X[k]);
      X[k] = next;
    }
    step = sqrt(step);
    if (step_prev > 10.0 * inv->tol) ratio = fmax(ratio, step / step_prev);
    /* a contraction shortens every step: three that do not mean no
       contraction here (the jump of u at the mesh's surface, or L >= 1) */
    if (it > 1 && step >= step_prev && ++stalls == 3) {
      *iterations = it;
      return NH_INVERSE_UNCONVERGED;
    }
    step_prev = step;
    if (step <= inv->tol) {
      *iterations = it;
      if (nh_finder_value(&inv->f, inv->field, X, 1, u) != 2) return NH_INVERSE_OUTSIDE;
      inv->st.contraction = fmax(inv->st.contraction, ratio);
      return NH_INVERSE_TISSUE;
    }
  }
  *iterations = inv->max_iterations;
  return NH_INVERSE_UNCONVERGED;
}

/* X(x) from the predictor X0 (NULL: x). */
static int nh_inverse_point(nh_inverse *inv, const double x[3], const double X0[3], double X[3]) {
  int iterations, status;
  memcpy(X, X0 ? X0 : x, 3 * sizeof(double));
  status = nh_inverse_iterate(inv, x, X, &iterations);
  int total = iterations;
  if (status != NH_INVERSE_TISSUE) {
    /* Outside the lattice's box but within reach of it: tissue may have
     * moved here; start again from the nearest point of the box. */
    double d2 = 0.0, C[3];
    int outside = 0;
    for (int k = 0; k < 3; k++) {
      C[k] = fmin(fmax(x[k], inv->box_lo[k]), inv->box_hi[k]);
      outside |= C[k] != x[k];
      d2 += (C[k] - x[k]) * (C[k] - x[k]);
    }
    if (outside && sqrt(d2) <= inv->reach) {
      double Y[3];
      memcpy(Y, C, sizeof Y);
      if (nh_inverse_iterate(inv, x, Y, &iterations) == NH_INVERSE_TISSUE) {
        memcpy(X, Y, sizeof Y);
        status = NH_INVERSE_TISSUE;
      }
      total += iterations;
    }
  }
  if (status == NH_INVERSE_UNCONVERGED) memcpy(X, x, 3 * sizeof(double));
  inv->st.points++;
  inv->st.tissue += status == NH_INVERSE_TISSUE;
  inv->st.outside += status == NH_INVERSE_OUTSIDE;
  inv->st.unconverged += status == NH_INVERSE_UNCONVERGED;
  if (total > inv->st.iterations_max) inv->st.iterations_max = total;
  inv->iterations_sum += total;
  return status;
}

/* Walk the voxels of `image`, calling back with each voxel's X and status;
 * predictors from the neighbour along i, or at a row's start along j (the
 * row below) or k (the slice below). */
typedef void (*nh_inverse_visit)(void *ctx, size_t v, const double X[3], int status);

static int nh_inverse_walk(const nh_mesh *mesh, const double *field, const nh_image *image,
                           const nh_inverse_options *opt, nh_inverse_visit visit, void *ctx,
                           nh_inverse_stats *stats) {
  nh_inverse inv;
  nh_inverse_init(&inv, mesh, field, image, opt);
  /* the displacement of the previous voxel, of the first voxel of this row
     and of the first voxel of this slice; `have` when it came from tissue */
  double u_prev[3] = {0}, u_row[3] = {0}, u_slice[3] = {0};
  int have_prev = 0, have_row = 0, have_slice = 0;
  size_t v = 0;
  for (int k = 0; k < image->n[2]; k++) {
    NH_TRY(nh_stop_check());
    for (int j = 0; j < image->n[1]; j++)
      for (int i = 0; i < image->n[0]; i++, v++) {
        double ijk[3] = {i, j, k}, x[3], X0[3], X[3];
        nh_image_to_world(image, ijk, x);
        const double *up = i > 0   ? (have_prev ? u_prev : NULL)
                           : j > 0 ? (have_row ? u_row : NULL)
                                   : (have_slice ? u_slice : NULL);
        if (up)
          for (int c = 0; c < 3; c++) X0[c] = x[c] - up[c];
        int status = nh_inverse_point(&inv, x, up ? X0 : NULL, X);
        have_prev = status == NH_INVERSE_TISSUE;
        for (int c = 0; c < 3; c++) u_prev[c] = x[c] - X[c];
        if (i == 0) {
          memcpy(u_row, u_prev, sizeof u_row), have_row = have_prev;
          if (j == 0) memcpy(u_slice, u_prev, sizeof u_slice), have_slice = have_prev;
        }
        visit(ctx, v, X, status);
      }
  }
  inv.st.iterations_mean = inv.st.points ? inv.iterations_sum / (double)inv.st.points : 0.0;
  if (stats) *stats = inv.st;
  return NH_OK;
}

typedef struct {
  double *X;
  unsigned char *status;
} nh_inverse_out;

static void nh_inverse_store(void *ctx, size_t v, const double X[3], int status) {
  nh_inverse_out *o = ctx;
  if (o->X) memcpy(o->X + 3 * v, X, 3 * sizeof(double));
  if (o->status) o->status[v] = (unsigned char)status;
}

int nh_mesh_inverse_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                          const nh_inverse_options *options, double *X, unsigned char *status,
                          nh_inverse_stats *stats) {
  nh_inverse_out o = {X, status};
  return nh_inverse_walk(mesh, field, image, options, nh_inverse_store, &o, stats);
}

typedef struct {
  const nh_image *image;
  const double *values;
  int nearest;
  double *out;
} nh_warp_out;

static void nh_warp_store(void *ctx, size_t v, const double X[3], int status) {
  (void)status;
  nh_warp_out *o = ctx;
  o->out[v] = nh_image_interpolate(o->image, o->values, X, o->nearest);
}

int nh_mesh_warp_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                       const double *values, int nearest, const nh_inverse_options *options,
                       double *out, nh_inverse_stats *stats) {
  nh_warp_out o = {image, values, nearest, out};
  return nh_inverse_walk(mesh, field, image, options, nh_warp_store, &o, stats);
}
