/* locate.c — point location.
 *
 * A material point is located in two stages: the initial grid is regular, so
 * its level-0 cell follows from the point's grid coordinates, through
 * mesh->root (an immersed domain drops the lattice cells that do not meet
 * it; a point there is outside the mesh); when the grid's nodes have been
 * moved, the 26 neighbours of that cell are tried too, and the cell whose
 * inverse map puts the point inside is taken. Below it the
 * point descends through the refinement hierarchy, choosing the child whose
 * inverse map puts it inside [-1, 1]³ (with a small tolerance, so points on
 * faces are found). The inverse map is Newton's method on the trilinear map,
 * started at the centre; for the parallelepipeds of box grids it converges in
 * one step. */
#include "mesh/mesh.h"

#include <float.h>
#include <math.h>

int nh_hex_invert(const double Xe[24], const double x[3], double xi[3]) {
  xi[0] = xi[1] = xi[2] = 0.0;
  /* Converged when the residual is at round-off: 1e-14 of the cell's size
   * plus the round-off of the coordinates themselves (8 eps |X|), which
   * dominates for small cells far from the origin. */
  double size = 0.0, xmax = 0.0;
  for (int k = 0; k < 3; k++) size = fmax(size, fabs(Xe[3 * 6 + k] - Xe[k]));
  for (int i = 0; i < 24; i++) xmax = fmax(xmax, fabs(Xe[i]));
  const double tol = 1e-14 * size + 8 * DBL_EPSILON * xmax;
  for (int it = 0; it < 30; it++) {
    double N[8], dN[8][3], r[3] = {-x[0], -x[1], -x[2]}, J[9] = {0}, Jinv[9], d[3];
    nh_hex_shape(xi, N);
    nh_hex_dshape(xi, dN);
    for (int a = 0; a < 8; a++)
      for (int i = 0; i < 3; i++) {
        r[i] += N[a] * Xe[3 * a + i];
        for (int j = 0; j < 3; j++) J[3 * i + j] += Xe[3 * a + i] * dN[a][j];
      }
    if (nh_mat3_inverse(J, Jinv)) return NH_ERR_NUMERIC;
    nh_mat3_vec(Jinv, r, d);
    for (int k = 0; k < 3; k++) xi[k] -= d[k];
    if (fabs(r[0]) + fabs(r[1]) + fabs(r[2]) <= tol) return NH_OK;
    if (fabs(xi[0]) + fabs(xi[1]) + fabs(xi[2]) > 1e6) return NH_ERR_NUMERIC;
  }
  return NH_ERR_NUMERIC;
}

static int nh_inside(const double xi[3], double tol) {
  return fabs(xi[0]) <= 1 + tol && fabs(xi[1]) <= 1 + tol && fabs(xi[2]) <= 1 + tol;
}

int nh_mesh_locate(const nh_mesh *m, const double x[3], int *cell, double xi[3]) {
  const double tol = 1e-9;
  int ijk[3];
  for (int k = 0; k < 3; k++) {
    double s = (x[k] - m->origin[k]) / m->spacing[k];
    if (s < -tol || s > m->grid[k] + tol) return NH_ERR_INPUT;
    ijk[k] = (int)floor(s);
    if (ijk[k] < 0) ijk[k] = 0;
    if (ijk[k] >= m->grid[k]) ijk[k] = m->grid[k] - 1;
  }
  int c = -1;
  double Xe[24];
  for (int d = 0; d < 27 && c < 0; d++) {
    int q[3] = {ijk[0] + (d + 1) % 3 - 1, ijk[1] + (d / 3 + 1) % 3 - 1,
                ijk[2] + (d / 9 + 1) % 3 - 1};
    if (q[0] < 0 || q[1] < 0 || q[2] < 0 || q[0] >= m->grid[0] || q[1] >= m->grid[1] ||
        q[2] >= m->grid[2])
      continue;
    int cand = q[0] + m->grid[0] * (q[1] + m->grid[1] * q[2]);
    if (m->root) cand = m->root[cand];
    if (cand < 0) continue; /* a cell of the lattice that does not meet the domain */
    nh_mesh_cell_coords(m, m->X, cand, Xe);
    if (nh_hex_invert(Xe, x, xi) == NH_OK && nh_inside(xi, tol)) c = cand;
  }
  if (c < 0) return NH_ERR_INPUT;
  while (m->first_child[c] >= 0) {
    int found = -1;
    for (int ch = m->first_child[c]; ch < m->first_child[c] + m->n_children[c]; ch++) {
      nh_mesh_cell_coords(m, m->X, ch, Xe);
      if (nh_hex_invert(Xe, x, xi) == NH_OK && nh_inside(xi, tol)) {
        found = ch;
        break;
      }
    }
    if (found < 0) return NH_ERR_INPUT;
    c = found;
  }
  *cell = c;
  return NH_OK;
}
