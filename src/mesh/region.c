/* region.c — regions of the scene on the mesh: nodes inside a region
 * (Dirichlet sets) and consistent nodal forces of a load region.
 *
 * A region is a closed box, a ball (sphere: centre, radius), a finite
 * cylinder (the points within `radius` of the segment [start, end] whose
 * projection falls on it: flat ends), or the voxels of the domain's label
 * image that hold a label (`{label: N}`, docs/anatomy.md; a point belongs to
 * the voxel whose centre is nearest).
 *
 * A load is a total force F spread as a uniform force density over the
 * tissue inside its region (docs/theory.md §5), so the nodal forces are
 *     f_a = (F / V) ∫_{Ω ∩ region} χ N_a dV,   V = ∫_{Ω ∩ region} χ dV,
 * and refining the mesh does not change the load. The tissue weight χ is the
 * cell's fill fraction φ on a box domain (φ = 1 there), and on an immersed
 * domain the indicator of the shape (F < 0) at the integration point: the
 * load acts on the tissue only, and weighting by φ as well would count a cut
 * cell's emptiness twice. For a cell whose rest shape is an axis-aligned box
 * (every cell of a box grid and of its regular templates) the intersection
 * with a box region is a box in natural coordinates, and since N_a is a
 * product of 1D linear factors the integral factorises into three exact 1D
 * integrals; that path serves box regions on box domains, and on immersed
 * domains where the cell's part of the box lies in the tissue (its corners
 * and centre: a goal point's small box deep in the brain, which 6³ samples
 * of a coarse cell could miss entirely). Everything else (sphere and
 * cylinder regions, boxes across the immersed boundary, the distorted
 * meshes of the tests) is sampled by 6³ sub-cell midpoints, except on an
 * immersed domain's box cells: there loads and ties of box, sphere and
 * cylinder regions use the finite cell quadrature of tissue ∩ region
 * (cutcell.c, nh_cut_domain_cell; the region on its own finer lattice), so
 * a region smaller than a cell ties exactly the tissue inside it.
 *
 * The same sampling gives two more cell quantities: the fraction of a cell's
 * tissue above a fluid level (the drainage of tissue.buoyancy.level) and the
 * tie matrix ∫ χ Nₐ N_b dV over cell ∩ region, which turns a fixed region
 * of an immersed domain into a stiff volumetric spring that converges to the
 * region as the mesh refines (docs/theory.md §5, "Fixed regions"). */
#include "mesh/mesh.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>

int nh_region_contains(const nh_region *r, const double x[3], double tol) {
  if (r->kind == NH_REGION_LABEL) return 0;
  if (r->kind == NH_REGION_SPHERE) {
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) d2 += (x[k] - r->center[k]) * (x[k] - r->center[k]);
    return sqrt(d2) <= r->radius + tol;
  }
  if (r->kind == NH_REGION_CYLINDER) {
    double axis[3], rel[3], len2 = 0.0, t = 0.0;
    for (int k = 0; k < 3; k++) {
      axis[k] = r->end[k] - r->start[k];
      rel[k] = x[k] - r->start[k];
      len2 += axis[k] * axis[k];
      t += rel[k] * axis[k];
    }
    double len = sqrt(len2), s = t / len; /* distance along the axis from start */
    if (s < -tol || s > len + tol) return 0;
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) {
      double e = rel[k] - t / len2 * axis[k];
      d2 += e * e;
    }
    return sqrt(d2) <= r->radius + tol;
  }
  for (int k = 0; k < 3; k++)
    if (x[k] < r->min[k] - tol || x[k] > r->max[k] + tol) return 0;
  return 1;
}

/* nh_region_contains, and for a label region the label of x's voxel. */
static int nh_region_holds(const nh_domain *d, const nh_region *r, const double x[3], double tol) {
  if (r->kind == NH_REGION_LABEL) return d->labels && nh_image_label_at(d->labels, x) == r->label;
  return nh_region_contains(r, x, tol);
}

double nh_region_size(const nh_region *r) {
  if (r->kind == NH_REGION_SPHERE) return r->radius;
  if (r->kind == NH_REGION_CYLINDER) {
    double len2 = 0.0;
    for (int k = 0; k < 3; k++) len2 += (r->end[k] - r->start[k]) * (r->end[k] - r->start[k]);
    return fmin(r->radius, 0.5 * sqrt(len2));
  }
  if (r->kind == NH_REGION_LABEL) return INFINITY;
  double l = INFINITY;
  for (int k = 0; k < 3; k++) l = fmin(l, 0.5 * (r->max[k] - r->min[k]));
  return l;
}

double nh_region_distance(const nh_region *r, const double x[3]) {
  if (r->kind == NH_REGION_LABEL) return NAN;
  if (r->kind == NH_REGION_SPHERE) {
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) d2 += (x[k] - r->center[k]) * (x[k] - r->center[k]);
    return sqrt(d2) - r->radius;
  }
  double out = 0.0, in = -INFINITY;
  if (r->kind == NH_REGION_CYLINDER) {
    /* in the cylinder's axes: t along the axis from start, ρ from it */
    double axis[3], rel[3], len = 0.0, t = 0.0, rho2 = 0.0;
    for (int k = 0; k < 3; k++) axis[k] = r->end[k] - r->start[k], len += axis[k] * axis[k];
    len = sqrt(len);
    for (int k = 0; k < 3; k++) axis[k] /= len, rel[k] = x[k] - r->start[k], t += rel[k] * axis[k];
    for (int k = 0; k < 3; k++) rho2 += (rel[k] - t * axis[k]) * (rel[k] - t * axis[k]);
    double q[2] = {sqrt(rho2) - r->radius, fmax(-t, t - len)}; /* a 2-D box's distance */
    for (int k = 0; k < 2; k++) out += q[k] > 0 ? q[k] * q[k] : 0.0, in = fmax(in, q[k]);
  } else {
    for (int k = 0; k < 3; k++) {
      double q = fmax(r->min[k] - x[k], x[k] - r->max[k]);
      out += q > 0 ? q * q : 0.0, in = fmax(in, q);
    }
  }
  return in > 0 ? sqrt(out) : in;
}

void nh_region_describe(const nh_region *r, char *buf, size_t cap) {
  if (r->kind == NH_REGION_LABEL)
    snprintf(buf, cap, "label %d", r->label);
  else if (r->kind == NH_REGION_SPHERE)
    snprintf(buf, cap, "sphere centre [%g, %g, %g] radius %g", r->center[0], r->center[1],
             r->center[2], r->radius);
  else if (r->kind == NH_REGION_CYLINDER)
    snprintf(buf, cap, "cylinder [%g, %g, %g] - [%g, %g, %g] radius %g", r->start[0], r->start[1],
             r->start[2], r->end[0], r->end[1], r->end[2], r->radius);
  else
    snprintf(buf, cap, "region [%g, %g, %g] - [%g, %g, %g]", r->min[0], r->min[1], r->min[2],
             r->max[0], r->max[1], r->max[2]);
}

static double nh_mesh_tol(const nh_mesh *m) {
  return 1e-9 * fmax(m->spacing[0], fmax(m->spacing[1], m->spacing[2]));
}

int nh_mesh_nodes_in_region(const nh_mesh *m, const nh_region *r, unsigned char *flags) {
  int count = 0;
  double tol = nh_mesh_tol(m);
  for (int i = 0; i < m->n_nodes; i++)
    if (nh_region_holds(&m->domain, r, m->X + 3 * i, tol)) {
      count++;
      if (flags) flags[i] = 1;
    }
  return count;
}

/* Midpoint n × n × n of the rest cell Xe: position, shape values, and the
 * volume it stands for. */
static void nh_cell_sample(const double Xe[24], int n, int i, int j, int k, double x[3],
                           double N[8], double *dv) {
  double xi[3] = {-1 + (2 * i + 1.0) / n, -1 + (2 * j + 1.0) / n, -1 + (2 * k + 1.0) / n};
  double dN[8][3], J[9] = {0};
  nh_hex_shape(xi, N);
  nh_hex_dshape(xi, dN);
  x[0] = x[1] = x[2] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int p = 0; p < 3; p++) {
      x[p] += N[a] * Xe[3 * a + p];
      for (int q = 0; q < 3; q++) J[3 * p + q] += Xe[3 * a + p] * dN[a][q];
    }
  *dv = fabs(nh_mat3_det(J)) * 8.0 / (n * n * n);
}

/* Immersed domain: true if the box cell [lo, hi] clipped to the box region
 * is empty or has its 8 corners and centre inside the tissue (level < 0):
 * then χ = 1 there (the shape's boundary is smooth on the scale of a cell:
 * a clip whose corners are inside is taken as inside) and the exact box
 * integrals apply. A region smaller than the samples' spacing (a goal
 * point's box, docs/theory.md §6.6) would otherwise meet no sample. */
static int nh_clip_in_tissue(const nh_domain *d, const double lo[3], const double hi[3],
                             const nh_region *r) {
  double a[3], b[3];
  for (int k = 0; k < 3; k++) {
    a[k] = fmax(lo[k], r->min[k]), b[k] = fmin(hi[k], r->max[k]);
    if (b[k] <= a[k]) return 1;
  }
  double c[3] = {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])};
  if (!(nh_domain_level(d, c) < 0.0)) return 0;
  for (int q = 0; q < 8; q++) {
    double x[3];
    for (int k = 0; k < 3; k++) x[k] = nh_hex_corner[q][k] < 0 ? a[k] : b[k];
    if (!(nh_domain_level(d, x) < 0.0)) return 0;
  }
  return 1;
}

/* ∫ χ N_a dV over cell ∩ region for the 8 nodes; returns ∫ χ dV. χ is 1 on
 * a box domain (the caller multiplies by φ) and the shape's indicator
 * otherwise: exact for a box region on a box cell (on an immersed domain
 * when the clip lies in the tissue, nh_clip_in_tissue), else by 6 × 6 × 6
 * midpoint samples. */
static double nh_cell_region_integrals(const nh_domain *d, const double Xe[24], const nh_region *r,
                                       double w[8]) {
  double lo[3], hi[3];
  const int immersed = d->kind != NH_DOMAIN_BOX;
  for (int a = 0; a < 8; a++) w[a] = 0.0;
  if (nh_domain_integrates_cuts(d) && r->kind != NH_REGION_LABEL && nh_hex_is_box(Xe, lo, hi)) {
    nh_cut_moments mom;
    double wq[27];
    if (nh_cut_domain_cell(d, lo, hi, r, NULL, &mom, wq)) return 0.0; /* cannot fail here */
    if (!(mom.volume > 0.0)) return 0.0;
    nh_cut_shape_integrals(wq, w, NULL);
    return mom.volume;
  }
  if (r->kind == NH_REGION_BOX && nh_hex_is_box(Xe, lo, hi) &&
      (!immersed || nh_clip_in_tissue(d, lo, hi, r))) {
    double I[3][2]; /* I[k][0]: ∫ ½(1-ξ) dξ, I[k][1]: ∫ ½(1+ξ) dξ over the clipped interval */
    double jac = 1.0;
    for (int k = 0; k < 3; k++) {
      double a = fmax(lo[k], r->min[k]), b = fmin(hi[k], r->max[k]);
      if (b <= a) return 0.0;
      double h = hi[k] - lo[k];
      double s0 = -1 + 2 * (a - lo[k]) / h, s1 = -1 + 2 * (b - lo[k]) / h;
      double len = s1 - s0, sq = 0.5 * (s1 * s1 - s0 * s0);
      I[k][0] = 0.5 * (len - sq);
      I[k][1] = 0.5 * (len + sq);
      jac *= 0.5 * h;
    }
    double vol = 0.0;
    for (int a = 0; a < 8; a++) {
      w[a] = jac * I[0][nh_hex_corner[a][0] > 0] * I[1][nh_hex_corner[a][1] > 0] *
             I[2][nh_hex_corner[a][2] > 0];
      vol += w[a];
    }
    return vol;
  }
  const int n = 6;
  double vol = 0.0, x[3], N[8], dv;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        nh_cell_sample(Xe, n, i, j, k, x, N, &dv);
        if (!nh_region_holds(d, r, x, 0.0)) continue;
        if (immersed && !(nh_domain_level(d, x) < 0.0)) continue;
        for (int a = 0; a < 8; a++) w[a] += N[a] * dv;
        vol += dv;
      }
  return vol;
}

int nh_mesh_region_load(const nh_mesh *m, const nh_region *r, const double force[3], double *f) {
  const int immersed = m->domain.kind != NH_DOMAIN_BOX;
  double volume = 0.0, Xe[24], w[8];
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    volume += (immersed ? 1.0 : m->fill[c]) * nh_cell_region_integrals(&m->domain, Xe, r, w);
  }
  NH_CHECK(volume > 0.0, NH_ERR_INPUT, "%s: the load region holds no tissue", r->where);
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double chi = immersed ? 1.0 : m->fill[c];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    if (nh_cell_region_integrals(&m->domain, Xe, r, w) == 0.0) continue;
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) f[3 * m->cells[8 * c + a] + k] += force[k] * chi * w[a] / volume;
  }
  return NH_OK;
}

double nh_mesh_cell_fraction_above(const nh_mesh *m, int c, const double point[3],
                                   const double up[3]) {
  const int n = 8, immersed = m->domain.kind != NH_DOMAIN_BOX;
  double Xe[24], x[3], N[8], dv;
  double tissue = 0.0, above = 0.0, all = 0.0, all_above = 0.0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  /* A sample is a convex combination of the corners (N_a >= 0, Σ N_a = 1):
   * with every corner on one side of the level, every sample is, and the
   * fraction is 1 or 0 exactly; only cells the level cuts are sampled. */
  int corners_up = 0;
  for (int a = 0; a < 8; a++)
    corners_up += (Xe[3 * a] - point[0]) * up[0] + (Xe[3 * a + 1] - point[1]) * up[1] +
                      (Xe[3 * a + 2] - point[2]) * up[2] >
                  0;
  if (corners_up == 8) return 1.0;
  if (corners_up == 0) return 0.0;
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        nh_cell_sample(Xe, n, i, j, k, x, N, &dv);
        int up_side =
            (x[0] - point[0]) * up[0] + (x[1] - point[1]) * up[1] + (x[2] - point[2]) * up[2] > 0;
        all += dv, all_above += up_side ? dv : 0.0;
        if (immersed && !(nh_domain_level(&m->domain, x) < 0.0)) continue;
        tissue += dv, above += up_side ? dv : 0.0;
      }
  return tissue > 0.0 ? above / tissue : all_above / all;
}

/* The bounding box [lo, hi] of the cell with corners Xe; true if it
 * overlaps the region's bounding box (a box, sphere or cylinder). */
static int nh_cell_box_overlaps(const double Xe[24], const nh_region *r, double lo[3],
                                double hi[3]) {
  double rlo[3], rhi[3];
  for (int k = 0; k < 3; k++) lo[k] = hi[k] = Xe[k];
  for (int a = 1; a < 8; a++)
    for (int k = 0; k < 3; k++)
      lo[k] = fmin(lo[k], Xe[3 * a + k]), hi[k] = fmax(hi[k], Xe[3 * a + k]);
  for (int k = 0; k < 3; k++) {
    if (r->kind == NH_REGION_SPHERE)
      rlo[k] = r->center[k] - r->radius, rhi[k] = r->center[k] + r->radius;
    else if (r->kind == NH_REGION_CYLINDER)
      rlo[k] = fmin(r->start[k], r->end[k]) - r->radius,
      rhi[k] = fmax(r->start[k], r->end[k]) + r->radius;
    else
      rlo[k] = r->min[k], rhi[k] = r->max[k];
    if (hi[k] < rlo[k] || lo[k] > rhi[k]) return 0;
  }
  return 1;
}

int nh_mesh_cell_coarser_at(const nh_mesh *m, int c, const nh_region *r, double h) {
  double Xe[24], lo[3], hi[3], mid[3], half2 = 0.0, edge = 0.0;
  if (r->kind == NH_REGION_LABEL) return 0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  if (!nh_cell_box_overlaps(Xe, r, lo, hi)) return 0;
  for (int k = 0; k < 3; k++) {
    mid[k] = 0.5 * (lo[k] + hi[k]), half2 += 0.25 * (hi[k] - lo[k]) * (hi[k] - lo[k]);
    edge = fmax(edge, hi[k] - lo[k]);
  }
  return edge > h && nh_region_distance(r, mid) <= sqrt(half2);
}

int nh_mesh_region_tie(const nh_mesh *m, int c, const nh_region *r, double T[64], double *volume) {
  const int n = 6, immersed = m->domain.kind != NH_DOMAIN_BOX;
  double Xe[24], x[3], N[8], dv, vol = 0.0;
  for (int i = 0; i < 64; i++) T[i] = 0.0;
  *volume = 0.0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  /* Skip cells far from the region: the bounding boxes do not overlap. */
  double lo[3], hi[3];
  if (!nh_cell_box_overlaps(Xe, r, lo, hi)) return NH_OK;
  if (nh_domain_integrates_cuts(&m->domain) && r->kind != NH_REGION_LABEL &&
      nh_hex_is_box(Xe, lo, hi)) {
    nh_cut_moments mom;
    double wq[27], N[8];
    NH_TRY(nh_cut_domain_cell(&m->domain, lo, hi, r, NULL, &mom, wq));
    if (!(mom.volume > 0.0)) return NH_OK;
    nh_cut_shape_integrals(wq, N, T);
    *volume = mom.volume;
    return NH_OK;
  }
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        nh_cell_sample(Xe, n, i, j, k, x, N, &dv);
        if (!nh_region_contains(r, x, 0.0)) continue;
        if (immersed && !(nh_domain_level(&m->domain, x) < 0.0)) continue;
        for (int a = 0; a < 8; a++)
          for (int b = 0; b < 8; b++) T[8 * a + b] += N[a] * N[b] * dv;
        vol += dv;
      }
  *volume = vol;
  return NH_OK;
}
