/* cell.c — the reference hexahedron [-1, 1]³: its corners, faces and edges
 * (numbered as drawn in mesh/mesh.h) and the trilinear shape functions
 *   N_a(ξ) = ⅛ (1 + ξ_a ξ)(1 + η_a η)(1 + ζ_a ζ),
 * ξ_a = (ξ_a, η_a, ζ_a) the corner's signs, which interpolate the corner
 * values of every cell (geometry, displacement, the Eq. 17 transfer to new
 * nodes) and whose gradients give the element's strains. Every other file
 * takes its tables from here, so one numbering holds throughout. */
#include "mesh/mesh.h"

#include <math.h>

const double nh_hex_corner[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                    {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

const int nh_hex_face[6][4] = {{0, 3, 7, 4}, {1, 2, 6, 5}, {0, 1, 5, 4},
                               {3, 2, 6, 7}, {0, 1, 2, 3}, {4, 5, 6, 7}};

const int nh_hex_edge[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};

void nh_hex_shape(const double xi[3], double N[8]) {
  for (int a = 0; a < 8; a++)
    N[a] = 0.125 * (1 + nh_hex_corner[a][0] * xi[0]) * (1 + nh_hex_corner[a][1] * xi[1]) *
           (1 + nh_hex_corner[a][2] * xi[2]);
}

void nh_hex_dshape(const double xi[3], double dN[8][3]) {
  for (int a = 0; a < 8; a++) {
    const double *s = nh_hex_corner[a];
    double f0 = 1 + s[0] * xi[0], f1 = 1 + s[1] * xi[1], f2 = 1 + s[2] * xi[2];
    dN[a][0] = 0.125 * s[0] * f1 * f2;
    dN[a][1] = 0.125 * s[1] * f0 * f2;
    dN[a][2] = 0.125 * s[2] * f0 * f1;
  }
}

int nh_hex_is_box(const double Xe[24], double lo[3], double hi[3]) {
  for (int k = 0; k < 3; k++) lo[k] = Xe[k], hi[k] = Xe[18 + k];
  double tol = 1e-12 * (fabs(hi[0] - lo[0]) + fabs(hi[1] - lo[1]) + fabs(hi[2] - lo[2]));
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) {
      double want = nh_hex_corner[a][k] < 0 ? lo[k] : hi[k];
      if (fabs(Xe[3 * a + k] - want) > tol) return 0;
    }
  return hi[0] > lo[0] && hi[1] > lo[1] && hi[2] > lo[2];
}
