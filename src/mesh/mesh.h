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

/* ---- refinement templates (mesh/template.c) ----
 * A template is a set of nodes in the parent's natural coordinates [-1, 1]³
 * and child cells (8 node indices each, VTK order); format in
 * templates/README.md. */
typedef struct nh_template {
  char path[NH_PATH_MAX];
  int n_nodes;
  double *xi; /* 3 per node, natural coordinates of the parent */
  int n_children;
  int *children; /* 8 per child, indices into the template's nodes */
} nh_template;

/* Read and validate a template file: every child has a positive Jacobian at
 * its 2x2x2 Gauss points, the children's volumes sum to the parent's (8),
 * no child overlaps another, children are conforming among themselves, and
 * the nodes on each parent face form a tensor-product grid that includes the
 * face's corners. Fails with NH_ERR_INPUT, message "FILE:LINE: reason" (the
 * line of the offending entry; line 0 for whole-file properties). */
int nh_template_load(const char *path, nh_template **out);
/* Smallest child edge over the parent's edge, in natural coordinates
 * (1/2 for hex2, 1/4 for hex4 and for the graded template). */
double nh_template_child_ratio(const nh_template *tmpl);
void nh_template_destroy(nh_template **tmpl);

/* ---- refinement (mesh/refine.c) ---- */

/* Where the nodes created by one refinement came from, for the transfer of
 * state (the seed's Eq. 17): node first_new + k lies at natural coordinates
 * xi[3k..3k+2] of cell parent[k] (a cell that was a leaf before). */
typedef struct {
  int first_new, n_new;
  int *parent;
  double *xi;
} nh_refine_info;

/* Replace each leaf cells[0..n) by the children of `tmpl`. Rest positions of
 * new nodes by Eq. 17 from the parent's corners; a node at a position where
 * a node already exists (a neighbour refined earlier, or a sibling) is that
 * node: nodes are never duplicated. Leaves are rebuilt. `info` (may be NULL)
 * receives where the new nodes lie. Fails with NH_ERR_INTERNAL if a cell is
 * not a leaf (a caller's bug), NH_ERR_MEMORY. */
int nh_mesh_refine(nh_mesh *mesh, const nh_template *tmpl, const int *cells, int n,
                   nh_refine_info *info);
void nh_refine_info_free(nh_refine_info *info);

/* Smallest edge length of cell c's rest shape. */
double nh_mesh_cell_size(const nh_mesh *mesh, int c);

/* ---- hanging nodes (mesh/hanging.c) ----
 * A node is hanging when it lies on a face or an edge of a leaf without
 * being one of its corners; its displacement is the trilinear interpolation
 * of the coarsest such leaf. Chains are resolved: the masters listed are
 * never hanging themselves. */
typedef struct nh_hanging {
  int n_hanging;
  int *node;      /* n_hanging: the hanging nodes */
  int *start;     /* n_hanging + 1: range of each node's masters */
  int *master;    /* masters (non-hanging nodes) */
  double *weight; /* interpolation weights, sum 1 per hanging node */
  int *index;     /* per mesh node: its position in `node`, or -1 */
} nh_hanging;

/* Detect the hanging nodes of the leaves and resolve their chains. Nodes with
 * skip[i] != 0 (fixed nodes; may be NULL) are never hanging: a prescribed
 * value wins over interpolation. Output *out, free with nh_hanging_destroy.
 * Fails with NH_ERR_INTERNAL if a node lies inside a leaf or the chains form
 * a cycle (a broken mesh), NH_ERR_MEMORY. */
int nh_hanging_detect(const nh_mesh *mesh, const unsigned char *skip, nh_hanging **out);
void nh_hanging_destroy(nh_hanging **hanging);
/* Set the hanging entries of a nodal field (3 per node) to the
 * interpolation of their masters. */
void nh_hanging_interpolate(const nh_hanging *hanging, double *field, int components);

#endif
