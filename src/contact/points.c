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

#include <stdlib.h>
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

/* F = I + ∂u/∂X in p's cell at its ξ; nonzero if the cell's map is singular. */
static int nh_point_gradient(const nh_mesh *m, const double *u, const nh_cpoint *p, double G[9]) {
  double Xe[24], dN[8][3], Jx[9] = {0}, Ji[9];
  nh_mesh_cell_coords(m, m->X, p->cell, Xe);
  nh_hex_dshape(p->xi, dN);
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) Jx[3 * i + j] += Xe[3 * a + i] * dN[a][j];
  if (nh_mat3_inverse(Jx, Ji)) return 1;
  const int *e = m->cells + 8 * p->cell;
  memset(G, 0, 9 * sizeof(double));
  for (int a = 0; a < 8; a++) {
    double g[3];
    nh_mat3_tvec(Ji, dN[a], g);
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++) G[3 * i + j] += u[3 * e[a] + i] * g[j];
  }
  for (int i = 0; i < 3; i++) G[4 * i] += 1.0;
  return 0;
}

int nh_material_point(const nh_mesh *m, const double *u, const double x[3], const double X0[3],
                      const double nrm[3], const double ref[3], double rho, nh_disc *d,
                      nh_cpoint *p) {
  double X[3] = {X0[0], X0[1], X0[2]};
  for (int it = 0; it < 20; it++) {
    if (nh_point_set(m, p, X)) return NH_ERR_INPUT;
    double G[9], xc[3], Fi[9], dX[3];
    if (nh_point_gradient(m, u, p, G)) return NH_ERR_INPUT;
    if (rho > 0.0) {
      NH_TRY(nh_disc_build(d, m, p, nrm, ref, rho));
      nh_disc_position(d, m, u, xc);
    } else {
      nh_point_position(m, u, p, xc);
    }
    double r[3] = {x[0] - xc[0], x[1] - xc[1], x[2] - xc[2]};
    if (nh_mat3_inverse(G, Fi)) return NH_ERR_INPUT;
    nh_mat3_vec(Fi, r, dX);
    for (int i = 0; i < 3; i++) X[i] += dX[i];
    if (sqrt(nh_vec3_dot(dX, dX)) <= 1e-13 * (1.0 + sqrt(nh_vec3_dot(X, X))))
      return nh_point_set(m, p, X);
  }
  return nh_point_set(m, p, X);
}

/* Add weight w of node v to the disc. */
static int nh_disc_add(nh_disc *d, int v, double w) {
  for (int k = 0; k < d->n; k++)
    if (d->node[k] == v) return d->w[k] += w, NH_OK;
  int cap = d->cap;
  if (nh_grow((void **)&d->node, &cap, d->n + 1, sizeof *d->node)) return NH_ERR_MEMORY;
  cap = d->cap;
  if (nh_grow((void **)&d->w, &cap, d->n + 1, sizeof *d->w)) return NH_ERR_MEMORY;
  d->cap = cap;
  d->node[d->n] = v, d->w[d->n++] = w;
  return NH_OK;
}

/* Add the shape values of the material point at X (weight w) to the disc;
 * *inside = 0 when X is outside the tissue. */
static int nh_disc_sample(nh_disc *d, const nh_mesh *m, const double X[3], double w, int *inside) {
  int cell;
  double xi[3], N[8];
  *inside = !nh_mesh_locate(m, X, &cell, xi);
  if (!*inside) return NH_OK;
  nh_hex_shape(xi, N);
  for (int a = 0; a < 8; a++)
    if (N[a] != 0.0) NH_TRY(nh_disc_add(d, m->cells[8 * cell + a], w * N[a]));
  return NH_OK;
}

int nh_disc_build(nh_disc *d, const nh_mesh *m, const nh_cpoint *p, const double nrm[3],
                  const double ref[3], double rho) {
  d->n = 0;
  memcpy(d->X, p->X, sizeof d->X);
  for (int i = 0; i < 3; i++) d->nrm[i] = nrm[i], d->ref[i] = ref ? ref[i] : 0.0;
  d->rho = rho > 0.0 ? rho : 0.0;
  double X[3 * NH_DISC_MAX_POINTS], w[NH_DISC_MAX_POINTS], total = 0.0;
  const int n = nh_disc_points(p->X, nrm, ref, rho, nh_mesh_cell_size(m, p->cell), X, w);
  for (int q = 0; q < n; q++) {
    int in;
    NH_TRY(nh_disc_sample(d, m, X + 3 * q, w[q], &in));
    total += in ? w[q] : 0.0;
  }
  if (total <= 0.0) { /* no disc, or all of it outside: the point itself */
    d->n = 0, total = 1.0, d->rho = 0.0;
    double N[8];
    nh_hex_shape(p->xi, N);
    for (int a = 0; a < 8; a++) NH_TRY(nh_disc_add(d, m->cells[8 * p->cell + a], N[a]));
  }
  for (int k = 0; k < d->n; k++) d->w[k] /= total;
  return NH_OK;
}

void nh_disc_free(nh_disc *d) {
  free(d->node), free(d->w);
  memset(d, 0, sizeof *d);
}

void nh_disc_position(const nh_disc *d, const nh_mesh *m, const double *u, double x[3]) {
  x[0] = x[1] = x[2] = 0.0;
  for (int k = 0; k < d->n; k++)
    for (int i = 0; i < 3; i++)
      x[i] += d->w[k] * (m->X[3 * d->node[k] + i] + u[3 * d->node[k] + i]);
}

int nh_disc_row(nh_rows *rows, int r, const nh_disc *d) {
  NH_TRY(nh_rows_widen(rows, d->n));
  for (int k = 0; k < d->n; k++)
    rows->node[rows->start[r] + k] = d->node[k], rows->N[rows->start[r] + k] = d->w[k];
  double *rec = rows->disc + 10 * r;
  memcpy(rec, d->X, 3 * sizeof(double));
  memcpy(rec + 3, d->nrm, 3 * sizeof(double));
  memcpy(rec + 6, d->ref, 3 * sizeof(double));
  rec[9] = d->rho;
  return NH_OK;
}

double nh_tip_radius(const nh_tool_spec *sp) {
  return sp->radius;
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
    rows->node[rows->start[r] + a] = m->cells[8 * p->cell + a], rows->N[rows->start[r] + a] = N[a];
}
