/* points.c — tissue material points tied to the tools: the entry point,
 * the channel's front and the channel points (docs/interaction.md).
 *
 * A point is kept by its material position X and located in the leaf that
 * holds it (cell, natural coordinates ξ), so its current position is the
 * trilinear interpolation of X + u over that cell and a refined mesh only
 * locates it again. The inverse, the material point now at a current
 * position x (where the tip is), solves X + u(X) = x by Newton's method
 * with the deformation gradient F = I + ∂u/∂X of the cell. */
#include "contact/contact_impl.h"

#include <string.h>

void nh_point_position(const nh_mesh *m, const double *u, const nh_cpoint *p, double x[3]) {
  double N[8];
  nh_hex_shape(p->xi, N);
  const int *e = m->cells + 8 * p->cell;
  for (int i = 0; i < 3; i++) {
    x[i] = 0.0;
    for (int a = 0; a < 8; a++) x[i] += N[a] * (m->X[3 * e[a] + i] + u[3 * e[a] + i]);
  }
}

int nh_point_set(const nh_mesh *m, nh_cpoint *p, const double X[3]) {
  memcpy(p->X, X, sizeof p->X);
  return nh_mesh_locate(m, X, &p->cell, p->xi);
}

int nh_material_point(const nh_mesh *m, const double *u, const double x[3], const double X0[3],
                      nh_cpoint *p) {
  double X[3] = {X0[0], X0[1], X0[2]};
  for (int it = 0; it < 20; it++) {
    if (nh_point_set(m, p, X)) return NH_ERR_INPUT;
    double Xe[24], N[8], dN[8][3], Jx[9] = {0}, Ji[9], G[9] = {0}, xc[3];
    nh_mesh_cell_coords(m, m->X, p->cell, Xe);
    nh_hex_shape(p->xi, N);
    nh_hex_dshape(p->xi, dN);
    for (int a = 0; a < 8; a++)
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) Jx[3 * i + j] += Xe[3 * a + i] * dN[a][j];
    if (nh_mat3_inverse(Jx, Ji)) return NH_ERR_INPUT;
    const int *e = m->cells + 8 * p->cell;
    for (int a = 0; a < 8; a++) { /* F = I + ∂u/∂X */
      double g[3];
      nh_mat3_tvec(Ji, dN[a], g);
      for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) G[3 * i + j] += u[3 * e[a] + i] * g[j];
    }
    for (int i = 0; i < 3; i++) G[4 * i] += 1.0;
    nh_point_position(m, u, p, xc);
    double r[3] = {x[0] - xc[0], x[1] - xc[1], x[2] - xc[2]}, Fi[9], d[3];
    if (nh_mat3_inverse(G, Fi)) return NH_ERR_INPUT;
    nh_mat3_vec(Fi, r, d);
    for (int i = 0; i < 3; i++) X[i] += d[i];
    if (sqrt(nh_vec3_dot(d, d)) <= 1e-13 * (1.0 + sqrt(nh_vec3_dot(X, X))))
      return nh_point_set(m, p, X);
  }
  return nh_point_set(m, p, X);
}

double nh_channel_spacing(double spacing, double cell) {
  return spacing > 0 ? spacing : cell;
}

double nh_point_spacing(const nh_tool_spec *sp, const nh_mesh *m, const nh_cpoint *p) {
  return nh_channel_spacing(sp->spacing, nh_mesh_cell_size(m, p->cell));
}

void nh_row_tissue(nh_rows *rows, int r, const nh_mesh *m, const nh_cpoint *p) {
  double N[8];
  nh_hex_shape(p->xi, N);
  for (int a = 0; a < 8; a++)
    rows->node[8 * r + a] = m->cells[8 * p->cell + a], rows->N[8 * r + a] = N[a];
}
