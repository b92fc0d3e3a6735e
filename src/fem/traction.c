/* traction.c — surface loads on the tissue's boundary (the traction term of
 * the weak form, ∫_Γ N_a t dA; docs/theory.md "Surface tractions").
 *
 * The boundary Γ inside a region, and its outward normal n:
 *   box domain   the faces of leaf cells whose four corners lie on one face
 *                of the domain's box; each face is bilinear, integrated by
 *                2x2 Gauss points (exact for a constant traction on an
 *                axis-aligned face: the integrand is bilinear there); n from
 *                x_s × x_t, turned away from the cell's centre;
 *   immersed     the surface F = 0 inside the cut cells: every leaf is split
 *                into NH_TRACTION_SUB³ sub-cubes of its natural coordinates,
 *                each into the six tetrahedra around its main diagonal
 *                (reflected above the domain's centre, as cutcell.c), and
 *                F = 0 is cut from each tetrahedron with F interpolated
 *                linearly (marching tetrahedra): one triangle or a quad as
 *                two. n is the triangle's normal, turned away from an inside vertex. Each
 *                triangle is integrated by its three edge midpoints (exact
 *                for quadratics in ξ), or, with tissue.cut_cells:
 *                integrated, by 6 points of degree 4 (N_a, a cubic on a
 *                plane, exactly: the immersed patch test of a uniform
 *                pressure, docs/theory.md §5c); the sub-lattice is
 *                cutcell.c's at NH_CUT_DEPTH, so Γ bounds the polyhedron
 *                the stiffness is integrated over. On a grid of equal leaves the triangles of
 *                neighbouring cells share their edges, so the pieces form a
 *                closed polyhedron and Σ n A = 0: a pressure then has no net
 *                force (to round-off). Where the shape leaves the grid's box
 *                (the brainstem), the faces of the box inside F < 0 are part
 *                of Γ too, clipped on the same sub-lattice.
 * A face or triangle belongs to the region if its centre does. The traction
 * is t = traction, or t = −p n for a pressure. */
#include "fem/fem.h"

#include <math.h>
#include <string.h>

/* Sub-cubes per axis of a leaf for the immersed surface: the mesh's, and
 * at most the geometry term's one level finer (nh_traction_cell). */
#define NH_TRACTION_SUB     (1 << NH_CUT_DEPTH)
#define NH_TRACTION_SUB_MAX (2 * NH_TRACTION_SUB)

/* Add w t to the 8 nodes of cell c with shape values N (one quadrature
 * point); c < 0: to the element vector f[24]. */
static void nh_traction_add(const nh_mesh *m, int c, const double N[8], double w, const double t[3],
                            double *f) {
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) f[3 * (c < 0 ? a : m->cells[8 * c + a]) + k] += w * N[a] * t[k];
}

static void nh_traction_vector(const nh_traction *tr, const double n[3], double t[3]) {
  for (int k = 0; k < 3; k++) t[k] = tr->is_pressure ? -tr->pressure * n[k] : tr->traction[k];
}

/* Face `face` of cell c on the domain box (all four corners on one of its planes)? */
static int nh_face_on_box(const nh_mesh *m, const double Xe[24], int face) {
  const nh_domain *d = &m->domain;
  for (int a = 0; a < 3; a++) {
    double tol = 1e-9 * (d->max[a] - d->min[a]);
    for (int side = 0; side < 2; side++) {
      double plane = side ? d->max[a] : d->min[a];
      int on = 1;
      for (int q = 0; q < 4; q++) on &= fabs(Xe[3 * nh_hex_face[face][q] + a] - plane) <= tol;
      if (on) return 1;
    }
  }
  return 0;
}

/* Box domain: the boundary faces of leaf c inside the region. */
static double nh_traction_box_cell(const nh_mesh *m, int c, const double Xe[24],
                                   const nh_traction *tr, double *f) {
  static const double g = 0.57735026918962576; /* 1/√3 */
  double area = 0.0, centre[3] = {0, 0, 0};
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) centre[k] += 0.125 * Xe[3 * a + k];
  for (int face = 0; face < 6; face++) {
    if (!nh_face_on_box(m, Xe, face)) continue;
    const int axis = face / 2;
    const double fixed = face % 2 ? 1.0 : -1.0;
    double xf[3] = {0, 0, 0};
    for (int q = 0; q < 4; q++)
      for (int k = 0; k < 3; k++) xf[k] += 0.25 * Xe[3 * nh_hex_face[face][q] + k];
    if (!nh_region_contains(&tr->region, xf, 1e-12)) continue;
    for (int gi = 0; gi < 4; gi++) {
      double xi[3], N[8], dN[8][3], ds[3] = {0, 0, 0}, dt[3] = {0, 0, 0}, x[3] = {0, 0, 0};
      int s_ax = (axis + 1) % 3, t_ax = (axis + 2) % 3;
      xi[axis] = fixed, xi[s_ax] = gi & 1 ? g : -g, xi[t_ax] = gi & 2 ? g : -g;
      nh_hex_shape(xi, N);
      nh_hex_dshape(xi, dN);
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) {
          x[k] += N[a] * Xe[3 * a + k];
          ds[k] += dN[a][s_ax] * Xe[3 * a + k];
          dt[k] += dN[a][t_ax] * Xe[3 * a + k];
        }
      double n[3] = {ds[1] * dt[2] - ds[2] * dt[1], ds[2] * dt[0] - ds[0] * dt[2],
                     ds[0] * dt[1] - ds[1] * dt[0]};
      double dA = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), t[3];
      if (!(dA > 0.0)) continue;
      double out = 0.0;
      for (int k = 0; k < 3; k++) n[k] /= dA, out += n[k] * (x[k] - centre[k]);
      if (out < 0.0)
        for (int k = 0; k < 3; k++) n[k] = -n[k];
      nh_traction_vector(tr, n, t);
      nh_traction_add(m, c, N, dA, t, f); /* Gauss weights 1 × 1 */
      area += dA;
    }
  }
  return area;
}

/* Position and level at natural coordinates xi of the cell with corners Xe. */
static double nh_cell_level(const nh_domain *d, const double Xe[24], const double xi[3],
                            double x[3]) {
  double N[8];
  nh_hex_shape(xi, N);
  x[0] = x[1] = x[2] = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) x[k] += N[a] * Xe[3 * a + k];
  return nh_domain_level(d, x);
}

/* One triangle (natural coordinates p[3][3], positions y[3][3]) of the
 * surface in cell c, its normal turned away from `inner`, a point strictly
 * inside (F < 0; the outside vertices of a tetrahedron may lie on the
 * surface, F = 0, where the brainstem ends on the grid's box). */
static double nh_traction_triangle(const nh_mesh *m, int c, double p[3][3], double y[3][3],
                                   const double inner[3], const nh_traction *tr, double *f) {
  double e1[3], e2[3], n[3], ctr[3];
  for (int k = 0; k < 3; k++) {
    e1[k] = y[1][k] - y[0][k], e2[k] = y[2][k] - y[0][k];
    ctr[k] = (y[0][k] + y[1][k] + y[2][k]) / 3.0;
  }
  n[0] = e1[1] * e2[2] - e1[2] * e2[1];
  n[1] = e1[2] * e2[0] - e1[0] * e2[2];
  n[2] = e1[0] * e2[1] - e1[1] * e2[0];
  double two_a = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!(two_a > 0.0) || !nh_region_contains(&tr->region, ctr, 1e-12)) return 0.0;
  double side = 0.0;
  for (int k = 0; k < 3; k++) n[k] /= two_a, side += n[k] * (inner[k] - y[0][k]);
  if (side > 0.0)
    for (int k = 0; k < 3; k++) n[k] = -n[k];
  double t[3], A = 0.5 * two_a;
  nh_traction_vector(tr, n, t);
  if (!nh_domain_integrates_cuts(&m->domain)) {
    for (int e = 0; e < 3; e++) { /* edge midpoints, weight A/3 */
      double xi[3], N[8];
      for (int k = 0; k < 3; k++) xi[k] = 0.5 * (p[e][k] + p[(e + 1) % 3][k]);
      nh_hex_shape(xi, N);
      nh_traction_add(m, c, N, A / 3.0, t, f);
    }
    return A;
  }
  /* Strang & Fix / Dunavant's 6-point rule of degree 4: N_a, trilinear,
   * is a cubic on a triangle of a cut plane, so the consistent load of a
   * uniform pressure is exact (the immersed patch test, docs/theory.md §5c). */
  static const double bary[2][2] = {{0.445948490915965, 0.108103018168070},
                                    {0.091576213509771, 0.816847572980459}};
  static const double weight[2] = {0.223381589678011, 0.109951743655322};
  for (int r = 0; r < 2; r++)
    for (int e = 0; e < 3; e++) {
      double xi[3], N[8], b[3] = {bary[r][0], bary[r][0], bary[r][0]};
      b[e] = bary[r][1];
      for (int k = 0; k < 3; k++) xi[k] = b[0] * p[0][k] + b[1] * p[1][k] + b[2] * p[2][k];
      nh_hex_shape(xi, N);
      nh_traction_add(m, c, N, A * weight[r], t, f);
    }
  return A;
}

/* The mirror orientation of sub-cube s of a leaf's lattice (n per axis,
 * lattice points x): cutcell.c's rule (nh_cut_flip) about the domain's
 * centre, so that this surface is the boundary of the cut-cell polyhedron. */
static unsigned nh_traction_flip(const nh_mesh *m, double (*x)[3], int n, const int s[3]) {
  const int lo = s[0] + (n + 1) * (s[1] + (n + 1) * s[2]),
            hi = (s[0] + 1) + (n + 1) * ((s[1] + 1) + (n + 1) * (s[2] + 1));
  unsigned mask = 0u;
  for (int k = 0; k < 3; k++) {
    const double centre = 0.5 * (x[lo][k] + x[hi][k]), edge = fabs(x[hi][k] - x[lo][k]);
    if (centre - m->domain.center[k] > 0.25 * edge) mask |= 1u << k;
  }
  return mask;
}

/* Immersed domain: the surface F = 0 in leaf c inside the region. */
static double nh_traction_immersed_cell(const nh_mesh *m, int c, const double Xe[24],
                                        const nh_traction *tr, int n, double *f) {
  /* the Kuhn split of a cube (VTK corner order) into six tetrahedra around 0–6 */
  static const int tets[6][4] = {{0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6},
                                 {0, 7, 4, 6}, {0, 4, 5, 6}, {0, 5, 1, 6}};
  enum { NV = (NH_TRACTION_SUB_MAX + 1) * (NH_TRACTION_SUB_MAX + 1) * (NH_TRACTION_SUB_MAX + 1) };
  double xi[NV][3], x[NV][3], F[NV];
  /* The level's Lipschitz bound (1 for every domain, mesh.h's nh_cut_spec)
   * at the centre, as the cut-cell quadrature uses it: a leaf wholly
   * outside, or wholly inside and off the grid's box, holds no surface, and
   * the lattice below would find none (one level call instead of (n + 1)³). */
  {
    const double zero[3] = {0.0, 0.0, 0.0};
    double xc[3], r2 = 0.0;
    const double Fc = nh_cell_level(&m->domain, Xe, zero, xc);
    for (int a = 0; a < 8; a++) {
      double d2 = 0.0;
      for (int k = 0; k < 3; k++) d2 += (Xe[3 * a + k] - xc[k]) * (Xe[3 * a + k] - xc[k]);
      r2 = fmax(r2, d2);
    }
    const double r = sqrt(r2) * (1 + 1e-12);
    if (Fc > r) return 0.0;
    int on_box = 0;
    for (int face = 0; face < 6 && !on_box; face++) on_box = nh_face_on_box(m, Xe, face);
    if (Fc < -r && !on_box) return 0.0;
  }
  int neg = 0, pos = 0;
  for (int k = 0; k <= n; k++)
    for (int j = 0; j <= n; j++)
      for (int i = 0; i <= n; i++) {
        int q = i + (n + 1) * (j + (n + 1) * k);
        xi[q][0] = -1.0 + 2.0 * i / n, xi[q][1] = -1.0 + 2.0 * j / n, xi[q][2] = -1.0 + 2.0 * k / n;
        F[q] = nh_cell_level(&m->domain, Xe, xi[q], x[q]);
        neg += F[q] < 0.0, pos += F[q] >= 0.0;
      }
  if (!neg) return 0.0;
  double area = 0.0;
  for (int k = 0; k < n && pos; k++)
    for (int j = 0; j < n; j++)
      for (int i = 0; i < n; i++) {
        int v[8];
        const int ijk[3] = {i, j, k};
        const unsigned flip = nh_traction_flip(m, x, n, ijk);
        for (int a = 0; a < 8; a++) {
          int di = (nh_hex_corner[a][0] > 0) ^ (int)(flip & 1),
              dj = (nh_hex_corner[a][1] > 0) ^ (int)(flip >> 1 & 1),
              dk = (nh_hex_corner[a][2] > 0) ^ (int)(flip >> 2 & 1);
          v[a] = (i + di) + (n + 1) * ((j + dj) + (n + 1) * (k + dk));
        }
        for (int t = 0; t < 6; t++) {
          int in[4], ni = 0, ou[4], no = 0;
          for (int q = 0; q < 4; q++) {
            int id = v[tets[t][q]];
            if (F[id] < 0.0)
              in[ni++] = id;
            else
              ou[no++] = id;
          }
          if (!ni || !no) continue;
          /* the crossing points on the edges from inside to outside vertices */
          double p[4][3], y[4][3];
          int np = 0;
          for (int a = 0; a < ni; a++)
            for (int b = 0; b < no; b++) {
              double s = F[in[a]] / (F[in[a]] - F[ou[b]]);
              for (int d = 0; d < 3; d++) {
                p[np][d] = xi[in[a]][d] + s * (xi[ou[b]][d] - xi[in[a]][d]);
                y[np][d] = x[in[a]][d] + s * (x[ou[b]][d] - x[in[a]][d]);
              }
              np++;
            }
          const double *inner = x[in[0]];
          if (np == 3) {
            area += nh_traction_triangle(m, c, p, y, inner, tr, f);
          } else { /* 2 + 2: the crossings (i0o0, i0o1, i1o0, i1o1) form the quad 0-1-3-2 */
            double pa[3][3], ya[3][3], pb[3][3], yb[3][3];
            const int A[3] = {0, 1, 3}, B[3] = {0, 3, 2};
            for (int q = 0; q < 3; q++)
              for (int d = 0; d < 3; d++) {
                pa[q][d] = p[A[q]][d], ya[q][d] = y[A[q]][d];
                pb[q][d] = p[B[q]][d], yb[q][d] = y[B[q]][d];
              }
            area += nh_traction_triangle(m, c, pa, ya, inner, tr, f);
            area += nh_traction_triangle(m, c, pb, yb, inner, tr, f);
          }
        }
      }
  /* Where the shape leaves the grid (a face of the grid's box with F < 0),
   * the tissue is cut flat: the part of such a face inside F < 0, on the
   * same sub-lattice, each sub-square split along its (low, low)–(high,
   * high) diagonal as the tetrahedra's faces are, clipped by the linear F. */
  double centre[3] = {0, 0, 0};
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) centre[k] += 0.125 * Xe[3 * a + k];
  for (int face = 0; face < 6; face++) {
    if (!nh_face_on_box(m, Xe, face)) continue;
    const int axis = face / 2, s_ax = (axis + 1) % 3, t_ax = (axis + 2) % 3;
    const int fixed = face % 2 ? n : 0;
    for (int b = 0; b < n; b++)
      for (int a = 0; a < n; a++) {
        int id[2][2], sub[3];
        sub[axis] = face % 2 ? n - 1 : 0, sub[s_ax] = a, sub[t_ax] = b;
        const unsigned flip = nh_traction_flip(m, x, n, sub);
        const int fs = flip >> s_ax & 1, ft = flip >> t_ax & 1;
        for (int db = 0; db < 2; db++)
          for (int da = 0; da < 2; da++) {
            int ijk[3];
            ijk[axis] = fixed, ijk[s_ax] = a + (da ^ fs), ijk[t_ax] = b + (db ^ ft);
            id[da][db] = ijk[0] + (n + 1) * (ijk[1] + (n + 1) * ijk[2]);
          }
        const int tri[2][3] = {{id[0][0], id[1][0], id[1][1]}, {id[0][0], id[1][1], id[0][1]}};
        for (int q = 0; q < 2; q++) {
          double p[4][3], y[4][3];
          int np = 0;
          for (int e = 0; e < 3; e++) { /* Sutherland–Hodgman against F < 0 */
            int u = tri[q][e], v = tri[q][(e + 1) % 3];
            if (F[u] < 0.0) {
              memcpy(p[np], xi[u], sizeof p[np]), memcpy(y[np], x[u], sizeof y[np]);
              np++;
            }
            if ((F[u] < 0.0) != (F[v] < 0.0)) {
              double sv = F[u] / (F[u] - F[v]);
              for (int d = 0; d < 3; d++) {
                p[np][d] = xi[u][d] + sv * (xi[v][d] - xi[u][d]);
                y[np][d] = x[u][d] + sv * (x[v][d] - x[u][d]);
              }
              np++;
            }
          }
          for (int k = 1; k + 1 < np; k++) { /* fan */
            double pt[3][3], yt[3][3];
            const int w[3] = {0, k, k + 1};
            for (int r = 0; r < 3; r++)
              for (int d = 0; d < 3; d++) pt[r][d] = p[w[r]][d], yt[r][d] = y[w[r]][d];
            area += nh_traction_triangle(m, c, pt, yt, centre, tr, f);
          }
        }
      }
  }
  return area;
}

int nh_traction_load(const nh_mesh *m, const nh_traction *tr, double *f, double *area) {
  const int immersed = m->domain.kind != NH_DOMAIN_BOX;
  double total = 0.0, Xe[24];
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    total += immersed ? nh_traction_immersed_cell(m, c, Xe, tr, NH_TRACTION_SUB, f)
                      : nh_traction_box_cell(m, c, Xe, tr, f);
  }
  if (area) *area = total;
  NH_CHECK(total > 0.0, NH_ERR_INPUT, "%s: the region contains no part of the tissue's boundary",
           tr->where);
  return NH_OK;
}

double nh_traction_cell(const nh_mesh *m, int c, const nh_traction *tr, int depth, double fe[24]) {
  double Xe[24];
  memset(fe, 0, 24 * sizeof(double));
  if (m->domain.kind == NH_DOMAIN_BOX || depth < 0 || (1 << depth) > NH_TRACTION_SUB_MAX)
    return 0.0;
  nh_mesh_cell_coords(m, m->X, c, Xe);
  return nh_traction_immersed_cell(m, -1 - c, Xe, tr, 1 << depth, fe);
}
