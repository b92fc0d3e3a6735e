/* mesh — nodes, hexahedral cells and their refinement hierarchy; point
 * location in natural coordinates; regions (fixed nodes, loads).
 *
 * Node numbering of a hexahedron (VTK_HEXAHEDRON), natural coordinates
 * ξ = (ξ, η, ζ) ∈ [-1, 1]³:
 *
 *          7 ─────── 6          node  ξ   η   ζ
 *         /|        /|           0   -1  -1  -1
 *        / |       / |           1   +1  -1  -1
 *       4 ─────── 5  |           2   +1  +1  -1
 *       |  3 ─────|─ 2           3   -1  +1  -1
 *   ζ η |/        | /            4   -1  -1  +1
 *   |/  0 ─────── 1              5   +1  -1  +1
 *   └─ξ                          6   +1  +1  +1
 *                                7   -1  +1  +1
 *
 * Cells are never deleted: a refined cell stays in the array as an inactive
 * parent whose children follow it in the hierarchy (first_child, n_children),
 * so every cell knows its level and parent. Numerics loop over the leaves. */
#ifndef NH_MESH_H
#define NH_MESH_H

#include "core/core.h"
#include "scene/scene.h"

typedef struct nh_mesh {
  int n_nodes, cap_nodes;
  double *X; /* rest (material) positions, 3 per node */

  int n_cells, cap_cells;
  int *cells;       /* 8 node indices per cell, VTK order */
  int *level;       /* 0 for cells of the initial grid */
  int *parent;      /* parent cell, -1 at level 0 */
  int *first_child; /* -1 for a leaf */
  int *n_children;
  double *fill; /* fill fraction φ ∈ (0, 1] */

  int n_leaves;
  int *leaves; /* the active cells, ascending */

  int grid[3]; /* the initial grid over [origin, origin + grid * spacing] */
  double origin[3], spacing[3];
} nh_mesh;

/* Natural-coordinate signs of the 8 nodes (table above). */
extern const double nh_hex_corner[8][3];

/* Build a (grid[0] x grid[1] x grid[2]) grid of level-0 cells over the box
 * [min, max]. Node (i, j, k) has index i + (g0+1) (j + (g1+1) k).
 * Fails with NH_ERR_INPUT for a non-positive count or an empty box. */
int nh_mesh_create_box(const double min[3], const double max[3], const int grid[3], nh_mesh **out);
void nh_mesh_destroy(nh_mesh **mesh);

/* Rebuild mesh->leaves from first_child (after refinement). */
int nh_mesh_update_leaves(nh_mesh *mesh);

/* Copy the rest coordinates of cell c into Xe[24] (node-major). */
void nh_mesh_cell_coords(const nh_mesh *mesh, const double *positions, int c, double Xe[24]);

/* Trilinear shape functions N[8] and their derivatives dN[8][3] at ξ. */
void nh_hex_shape(const double xi[3], double N[8]);
void nh_hex_dshape(const double xi[3], double dN[8][3]);

/* Natural coordinates ξ of point x in the hexahedron with corners Xe by
 * Newton's method. Returns NH_OK if it converged (ξ may lie outside
 * [-1,1]³ for points outside the cell), NH_ERR_NUMERIC otherwise. */
int nh_hex_invert(const double Xe[24], const double x[3], double xi[3]);

/* Find the leaf containing the material point x (rest configuration), and
 * its natural coordinates. Points on shared faces go to either cell.
 * Returns NH_OK, or NH_ERR_INPUT (no message) if x is outside the mesh. */
int nh_mesh_locate(const nh_mesh *mesh, const double x[3], int *cell, double xi[3]);

/* True if x lies in the region (closed box, tolerance tol). */
int nh_region_contains(const nh_region *region, const double x[3], double tol);

/* Mark (flags[i] = 1) the nodes inside the region; returns how many nodes it
 * holds, flags may be NULL. */
int nh_mesh_nodes_in_region(const nh_mesh *mesh, const nh_region *region, unsigned char *flags);

/* Consistent nodal forces of a total force `force` spread as a uniform force
 * density over the tissue inside `region` (weighted by φ): adds to f[3 n] the
 * integrals ∫ ρ_f N_a dV over each leaf ∩ region, ρ_f = force / V, where V is
 * the tissue volume inside the region. The integral is exact for cells whose
 * rest shape is an axis-aligned box (every cell of a box grid and of its
 * templates); other cells are sampled by 6³ sub-cell midpoints.
 * Returns NH_ERR_INPUT (message at region->where) if V = 0. */
int nh_mesh_region_load(const nh_mesh *mesh, const nh_region *region, const double force[3],
                        double *f);

#endif
