/* mesh — nodes, hexahedral cells and their refinement hierarchy; point
 * location in natural coordinates; regions (fixed nodes, loads).
 *
 * The reference hexahedron (mesh/cell.c), natural coordinates
 * ξ = (ξ, η, ζ) ∈ [-1, 1]³, corners in VTK_HEXAHEDRON order:
 *
 *          7 ─────── 6          corner  ξ   η   ζ
 *         /|        /|             0   -1  -1  -1
 *        / |       / |             1   +1  -1  -1
 *       4 ─────── 5  |             2   +1  +1  -1
 *       |  3 ─────|─ 2             3   -1  +1  -1
 *   ζ η |/        | /              4   -1  -1  +1
 *   |/  0 ─────── 1                5   +1  -1  +1
 *   └─ξ                            6   +1  +1  +1
 *                                  7   -1  +1  +1
 *
 * Faces (nh_hex_face), by the coordinate held fixed; the corners run
 * counter-clockwise seen from outside the cell for faces 1, 2, 5 and from
 * inside for faces 0, 3, 4:
 *
 *   face 0: ξ = -1   0 3 7 4        face 1: ξ = +1   1 2 6 5
 *   face 2: η = -1   0 1 5 4        face 3: η = +1   3 2 6 7
 *   face 4: ζ = -1   0 1 2 3        face 5: ζ = +1   4 5 6 7
 *
 * Edges (nh_hex_edge): e0–e3 around the bottom face ζ = -1, e4–e7 around the
 * top face ζ = +1, e8–e11 along ζ:
 *
 *            7 ───e6──── 6            edge  corners   edge  corners
 *           /|          /|             e0    0 1       e6    6 7
 *         e7 e11      e5 e10           e1    1 2       e7    7 4
 *         /  |        /  |             e2    2 3       e8    0 4
 *        4 ───e4──── 5   |             e3    3 0       e9    1 5
 *        |   3 ───e2─|── 2             e4    4 5       e10   2 6
 *        e8 /        e9 /              e5    5 6       e11   3 7
 *        | e3        | e1
 *        |/          |/
 *        0 ───e0──── 1
 *
 * Cells are never deleted: a refined cell stays in the array as an inactive
 * parent whose children follow it in the hierarchy (first_child, n_children),
 * so every cell knows its level and parent. Numerics loop over the leaves. */
#ifndef NH_MESH_H
#define NH_MESH_H

#include "anatomy/anatomy.h"
#include "core/core.h"
#include "scene/scene.h"

/* ---- the tissue's domain (mesh/domain.c) ----
 * The shape the tissue fills, as an implicit function F (F < 0 inside,
 * docs/theory.md "Immersed domain"): a box, the analytic brain (two
 * ellipsoidal hemispheres split by a longitudinal fissure, and a brainstem),
 * the selected labels of a NIfTI image or a closed surface (docs/anatomy.md),
 * which the grid over its bounding box resolves by cell fill fractions φ.
 * F is 1-Lipschitz: F(x) > 0 is a lower bound of the distance to the shape.
 * A domain holds references to its image and surface: copy it with
 * nh_domain_copy and drop it with nh_domain_release. */
typedef struct nh_domain {
  nh_domain_kind kind;
  double min[3], max[3];     /* bounding box (exactly the shape's extent) */
  double center[3], half[3]; /* its centre and half sizes */
  nh_image *image;           /* mask: the image whose selected labels are the shape */
  nh_surface *surface;       /* surface: the closed surface */
  nh_image *labels;          /* the label image of materials and {label: N} regions, or NULL */
  double cap;                /* surface: F is the signed distance truncated at ±cap */
  nh_cut_cells cut_cells;    /* tissue.cut_cells: how an immersed domain's box cells are
                                integrated (stiffness, mass, ties, loads, tractions) */
} nh_domain;

/* Floor of the fill fraction: a cell that barely meets the shape keeps
 * φ = NH_FILL_MIN so that the stiffness stays positive definite. */
#define NH_FILL_MIN 0.05
/* Sub-cell midpoints per axis that measure a cell's fill fraction. */
#define NH_FILL_SAMPLES 8

/* The box [min, max] (max > min in every component). */
void nh_domain_box(const double min[3], const double max[3], nh_domain *domain);
/* The brain of bounding box center ± size / 2 (size > 0). */
void nh_domain_brain(const double center[3], const double size[3], nh_domain *domain);
/* The ball of the given centre and radius (tests: no scene key builds it). */
void nh_domain_sphere(const double center[3], double radius, nh_domain *domain);
/* The scene's tissue.domain, reading its image or surface and the label
 * image (tissue.labels). Fails with NH_ERR_INPUT, message "FILE:LINE: KEY:
 * reason" at the scene's key: an unreadable or corrupt file, a label of
 * tissue.domain.mask.labels or tissue.materials that no voxel holds.
 * Release with nh_domain_release. */
int nh_domain_from_scene(const nh_scene *scene, nh_domain *domain);
/* True if the domain is immersed and its cut box cells are integrated by
 * the finite cell quadrature (tissue.cut_cells: integrated), false if they
 * are scaled by their fill fraction. */
int nh_domain_integrates_cuts(const nh_domain *domain);
/* *dst = *src with a new reference to its image, surface and label image. */
void nh_domain_copy(nh_domain *dst, const nh_domain *src);
/* Drop the references the domain holds (keeps kind and box). */
void nh_domain_release(nh_domain *domain);
/* "box", "brain", "mask", "surface" or "sphere". */
const char *nh_domain_name(const nh_domain *domain);

/* F(x): negative inside, positive outside, 1-Lipschitz. */
double nh_domain_level(const nh_domain *domain, const double x[3]);
/* F(x), and its gradient g[3] by central differences (step 1e-6 of the
 * largest edge). */
double nh_domain_gradient(const nh_domain *domain, const double x[3], double g[3]);
/* The level function of the domain's outer hull: the analytic brain's U
 * (mesh/domain.c: hemispheres and brainstem, the longitudinal fissure
 * filled), F for every other kind (a mask or surface is the only geometry
 * it has). U <= F, equal outside the fissure; 1-Lipschitz. */
double nh_domain_hull_level(const nh_domain *domain, const double x[3]);
/* U(x) of nh_domain_hull_level, and its gradient g[3] by the central
 * differences of nh_domain_gradient. */
double nh_domain_hull_gradient(const nh_domain *domain, const double x[3], double g[3]);
/* True if x lies strictly inside (box: min < x < max componentwise; else F < 0). */
int nh_domain_inside(const nh_domain *domain, const double x[3]);

/* First entry of the ray base + τ dir (τ > 0, dir need not be unit) into
 * the shape: τ, the point and the unit outward normal there. Box: exact
 * ray–box intersection, normal the face's. Other shapes: marching along the
 * ray in steps of 1e-3 of the bounding box's largest edge, then bisection to
 * 1e-13 of that edge; normal ∇F / |∇F| by central differences.
 * Returns 1 if the ray enters the shape, 0 if it misses it or base is not
 * outside (the outputs are then untouched). */
int nh_domain_ray_entry(const nh_domain *domain, const double base[3], const double dir[3],
                        double *tau, double point[3], double normal[3]);

/* Distance from the segment [a, b] to the shape, sampled at 201 points (box:
 * the exact distance of each sample; other shapes: 0 if the segment meets
 * the shape, else the least F / |∇F|, a first-order estimate). */
double nh_domain_segment_distance(const nh_domain *domain, const double a[3], const double b[3]);

/* Volume of the shape: exact for the box; for the brain the reference
 * integral of docs/theory.md (lines along x through a 256 x 256 midpoint grid
 * in y, z, each line's inside intervals found by sign changes at 256 points
 * and bisection), independent of the cell sampling. */
double nh_domain_volume(const nh_domain *domain);

/* Fill fraction of the hexahedron with rest corners Xe: the fraction of
 * NH_FILL_SAMPLES³ sub-cell midpoints (of the trilinear map, weighted by
 * det J) inside the shape. *meets (may be NULL) is set to 1 if the cell may
 * meet the shape: some midpoint has F no larger than its sub-cell's
 * circumradius (never 0 for a cell that meets it, F being 1-Lipschitz). */
double nh_domain_cell_fill(const nh_domain *domain, const double Xe[24], int *meets);
/* The same for cell ijk of the grid[3] lattice over the domain's bounding
 * box, with the midpoints' offsets from the centre computed exactly, so that
 * mirror cells about x = cx get bitwise equal fractions. */
double nh_domain_lattice_fill(const nh_domain *domain, const int grid[3], const int ijk[3],
                              int *meets);

typedef struct nh_mesh {
  int n_nodes, cap_nodes;
  double *X; /* rest (material) positions, 3 per node */

  int n_cells, cap_cells;
  int *cells;       /* 8 node indices per cell, VTK order */
  int *level;       /* 0 for cells of the initial grid */
  int *parent;      /* parent cell, -1 at level 0 */
  int *first_child; /* -1 for a leaf */
  int *n_children;
  double *fill; /* fill fraction φ ∈ [NH_FILL_MIN, 1] (1 for a box domain) */

  int n_leaves;
  int *leaves; /* the active cells, ascending */

  int grid[3]; /* the initial grid over [origin, origin + grid * spacing] */
  double origin[3], spacing[3];
  int *root;        /* grid[0] grid[1] grid[2]: the level-0 cell at lattice (i, j, k), index
                       i + grid[0] (j + grid[1] k), or -1 where the cell was dropped */
  nh_domain domain; /* the shape the cells resolve (refinement measures φ on it) */
} nh_mesh;

/* ---- the reference hexahedron (mesh/cell.c; numbering drawn above) ---- */
/* Natural-coordinate signs of the 8 corners. */
extern const double nh_hex_corner[8][3];
/* The 4 corners of each of the 6 faces. */
extern const int nh_hex_face[6][4];
/* The 2 corners of each of the 12 edges. */
extern const int nh_hex_edge[12][2];
/* Trilinear shape functions N[8] and their derivatives dN[8][3] at ξ. */
void nh_hex_shape(const double xi[3], double N[8]);
void nh_hex_dshape(const double xi[3], double dN[8][3]);
/* True if the corners Xe[24] form an axis-aligned box [lo, hi] (to 1e-12 of
 * its size, corners in VTK order); lo and hi are corners 0 and 6. */
int nh_hex_is_box(const double Xe[24], double lo[3], double hi[3]);

/* Build a (grid[0] x grid[1] x grid[2]) grid of level-0 cells over the box
 * [min, max]. Node (i, j, k) has index i + (g0+1) (j + (g1+1) k), cell
 * (i, j, k) index i + g0 (j + g1 k), every φ = 1.
 * Fails with NH_ERR_INPUT for a non-positive count or an empty box. */
int nh_mesh_create_box(const double min[3], const double max[3], const int grid[3], nh_mesh **out);
/* Build the grid over the domain's bounding box and keep the cells that may
 * meet the shape (nh_domain_cell_fill), each with its fill fraction floored
 * at NH_FILL_MIN; unused nodes are removed and both nodes and cells keep the
 * lattice's lexicographic order (mesh->root maps lattice cells to cells).
 * A box domain gives exactly nh_mesh_create_box. Fails as nh_mesh_create_box,
 * and with NH_ERR_INPUT if no cell meets the shape. */
int nh_mesh_create(const nh_domain *domain, const int grid[3], nh_mesh **out);
/* Rebuild mesh->root from the level-0 cells (parent -1) and their first
 * corner's lattice position (after reading a mesh back). NH_ERR_INPUT if a
 * level-0 cell is not on the lattice, NH_ERR_MEMORY. */
int nh_mesh_index_roots(nh_mesh *mesh);
/* Σ φ_c V_c over the leaves (V_c by 2x2x2 Gauss points): the tissue volume. */
double nh_mesh_fill_volume(const nh_mesh *mesh);
void nh_mesh_destroy(nh_mesh **mesh);

/* Rebuild mesh->leaves from first_child (after refinement). */
int nh_mesh_update_leaves(nh_mesh *mesh);

/* Copy the rest coordinates of cell c into Xe[24] (node-major). */
void nh_mesh_cell_coords(const nh_mesh *mesh, const double *positions, int c, double Xe[24]);

/* Natural coordinates ξ of point x in the hexahedron with corners Xe by
 * Newton's method. Returns NH_OK if it converged (ξ may lie outside
 * [-1,1]³ for points outside the cell), NH_ERR_NUMERIC otherwise. */
int nh_hex_invert(const double Xe[24], const double x[3], double xi[3]);

/* Find the leaf containing the material point x (rest configuration), and
 * its natural coordinates. Points on shared faces go to either cell.
 * Returns NH_OK, or NH_ERR_INPUT (no message) if x is outside the mesh. */
int nh_mesh_locate(const nh_mesh *mesh, const double x[3], int *cell, double xi[3]);

/* True if x lies in the region (closed, enlarged by tol); 0 for a label
 * region (it needs the label image: the mesh functions below test it). */
int nh_region_contains(const nh_region *region, const double x[3], double tol);
/* The region's smallest size: a sphere's radius, a cylinder's radius (or
 * half its length if shorter), a box's smallest half-extent (a label
 * region: +inf). */
double nh_region_size(const nh_region *region);
/* Signed distance from x to the surface of a box, sphere or finite cylinder
 * (its side and its flat ends): negative inside; NAN for a label region
 * (its voxels are the image's: plan/obstacle.c). */
double nh_region_distance(const nh_region *region, const double x[3]);
/* "box [..] - [..]", "sphere centre [..] radius r", "cylinder [..] - [..] radius r", "label N". */
void nh_region_describe(const nh_region *region, char *buf, size_t cap);

/* True if cell c is coarser than h at the region (tissue.fixed.N.refine):
 * the largest edge of its rest bounding box exceeds h and that box may meet
 * the region (the boxes overlap and the region's distance from the box's
 * centre is at most its half-diagonal: a cell that meets the region is
 * never missed); 0 for a label region. */
int nh_mesh_cell_coarser_at(const nh_mesh *mesh, int c, const nh_region *region, double h);
/* Mark (flags[i] = 1) the nodes inside the region; returns how many nodes it
 * holds, flags may be NULL. */
int nh_mesh_nodes_in_region(const nh_mesh *mesh, const nh_region *region, unsigned char *flags);

/* Consistent nodal forces of a total force `force` spread as a uniform force
 * density over the tissue inside `region`: adds to f[3 n] the integrals
 * ∫ ρ_f N_a dV over each leaf ∩ region ∩ tissue, ρ_f = force / V, where V is
 * the tissue volume inside the region. Tissue is the cell weighted by φ for a
 * box domain, and the points inside the shape (F < 0) for an immersed one.
 * The integral is exact for a box region over cells whose rest shape is an
 * axis-aligned box on a box domain (every cell of a box grid and of its
 * templates); otherwise each cell is sampled by 6³ sub-cell midpoints.
 * Returns NH_ERR_INPUT (message at region->where) if V = 0. */
int nh_mesh_region_load(const nh_mesh *mesh, const nh_region *region, const double force[3],
                        double *f);

/* The fraction of leaf c's tissue that lies above the plane through `point`
 * normal to `up` ((x − point)·up > 0), by 8³ sub-cell midpoints of the rest
 * shape; tissue is every point on a box domain and the points inside the
 * shape on an immersed one (a cell with no such point counts all its
 * points). 0: all below, 1: all above. */
double nh_mesh_cell_fraction_above(const nh_mesh *mesh, int c, const double point[3],
                                   const double up[3]);

/* The tie of leaf c to a region: T[8x8] = ∫ χ Nₐ N_b dV over the cell ∩
 * region ∩ tissue (χ as for loads), by the finite cell quadrature of the
 * region's and the domain's level sets on integrated box cells, else by 6³
 * sub-cell midpoints; *volume is that volume (0: the cell does not meet the
 * region, T all zero). Fails (out of memory) only in the quadrature. */
int nh_mesh_region_tie(const nh_mesh *mesh, int c, const nh_region *region, double T[64],
                       double *volume);

/* ---- cut cells: the finite cell quadrature (mesh/cutcell.c) ----
 * The tissue part of a box cell [lo, hi] (natural coordinates ξ ∈ [-1, 1]³,
 * x = (lo + hi)/2 + (hi − lo)/2 ξ): {level < 0}, intersected with a region
 * and a half-space if given, each reconstructed piecewise linearly on the
 * Kuhn tetrahedra of a lattice of sub-boxes (cutcell.c's essay). */
typedef double (*nh_level_fn)(const void *ctx, const double x[3]);
typedef struct nh_cut_spec {
  nh_level_fn level; /* the tissue {level(x) < 0}; nh_cut_spec_domain: nh_domain_level */
  const void *ctx;   /* level's first argument */
  double lipschitz;  /* |level(x) − level(y)| <= lipschitz |x − y| (1 for every nh_domain) */
  int depth;         /* its lattice: 2^depth sub-boxes per cell edge, 0 ..= NH_CUT_DEPTH_MAX */
  const nh_region *region; /* NULL, or also inside this box, sphere or cylinder */
  double region_sub;    /* region's lattice: sub-box edge <= nh_region_size / region_sub (0: 8) */
  const double *plane;  /* NULL, or {p[3], n[3]}: also (x − p)·n < 0 */
  const double *mirror; /* NULL, or a point: each lattice box above mirror[k] in axis k is split
                           as its reflection in axis k (nh_cut_spec_domain: the grid's centre) */
} nh_cut_spec;
#define NH_CUT_DEPTH_MAX 6
typedef struct nh_cut_moments {
  double m[27];  /* M_ijk = ∫ ξ^i η^j ζ^k dV over the part, at i + 3 j + 9 k (i, j, k <= 2) */
  double volume; /* m[0] */
  double centroid[3];            /* physical (the cell's centre if volume = 0) */
  long evals, boxes, tets, kuhn; /* work: level calls, sub-boxes visited, clipped tetrahedra
                                    integrated by quadrature, whole ones in closed form */
} nh_cut_moments;
/* A point of a surface quadrature: natural coordinates, outward unit normal
 * times its weight (physical area), piece -1 for {level = 0}, else the cell face 0..5. */
typedef struct nh_cut_point {
  double xi[3], area[3];
  int piece;
} nh_cut_point;
typedef struct nh_cut_surface {
  int n, cap;
  nh_cut_point *point;
} nh_cut_surface;
/* spec = the domain's tissue on a lattice of the given depth, no region, no plane. */
void nh_cut_spec_domain(nh_cut_spec *spec, const nh_domain *domain, int depth);
/* Moments of the part in the box cell [lo, hi]; if surface is not NULL,
 * appends the quadrature of its boundary {level = 0} and of the cell faces
 * f with bit f of `faces` set (exact for quadratics in ξ on the
 * reconstruction; 3 points per triangle). NH_ERR_INPUT (at region->where)
 * for a label region, NH_ERR_INTERNAL for a depth out of range,
 * NH_ERR_MEMORY. */
int nh_cut_cell(const nh_cut_spec *spec, const double lo[3], const double hi[3],
                nh_cut_moments *out, nh_cut_surface *surface, unsigned faces);
/* The 27 points ξ_q (3 per point, q = a + 3 b + 9 c at Gauss–Legendre
 * nodes a, b, c of 3) and the weights w_q with Σ_q w_q p(ξ_q) = ∫ p dV for
 * every p in Q2 (moment fitting). */
void nh_cut_points(double xi[81]);
void nh_cut_fit(const double m[27], double w[27]);
void nh_cut_surface_free(nh_cut_surface *surface);
/* The connected components of the tissue {I level < 0} in the box cell
 * [lo, hi] on the lattice of spec->depth (the level only; region, plane and
 * mirror are ignored): sub-boxes with a corner inside are joined across a
 * face with a corner inside (cutcell.c). *n_components: 0 for no tissue; if
 * label is not NULL, per sub-box (i + n (j + n k), n = 2^depth) its
 * component 0 .. *n_components − 1, or −1 (no tissue). One element per cell
 * glues components that are apart in the tissue (docs/theory.md §5c,
 * "Disconnected cut cells"). NH_ERR_INTERNAL for a depth out of range,
 * NH_ERR_MEMORY. */
int nh_cut_components(const nh_cut_spec *spec, const double lo[3], const double hi[3],
                      int *n_components, int *label);
/* The box leaves of m whose tissue (the domain's, at depth NH_CUT_DEPTH) is
 * in several components (nh_cut_components): their number, and the largest
 * component count of a leaf (may be NULL). 0 for a box domain. Fails as
 * nh_cut_components. */
int nh_mesh_split_cells(const nh_mesh *m, int *n_split, int *max_components);
/* The lattice depth of the mesh's cut cells: 2^NH_CUT_DEPTH sub-boxes per
 * cell edge for stiffness, mass, loads, ties and drainage (fem/tissue.c,
 * mesh/region.c), the sub-lattice of the immersed surface (fem/traction.c),
 * so that volume and surface are one polyhedron. */
#define NH_CUT_DEPTH 2
/* The part of the box cell [lo, hi] inside the domain's shape, a region
 * (may be NULL) and the half-space {(x − p)·n < 0} (plane = {p, n}, may be
 * NULL) at depth NH_CUT_DEPTH: its moments and the 27 fitted weights w
 * (nh_cut_fit; may be NULL). Fails as nh_cut_cell. */
int nh_cut_domain_cell(const nh_domain *domain, const double lo[3], const double hi[3],
                       const nh_region *region, const double *plane, nh_cut_moments *moments,
                       double w[27]);
/* The same on the lattice of the given depth (the goal estimate's geometry
 * term compares NH_CUT_DEPTH with NH_CUT_DEPTH + 1, adapt/dwr.c). */
int nh_cut_domain_cell_at(const nh_domain *domain, int depth, const double lo[3],
                          const double hi[3], const nh_region *region, const double *plane,
                          nh_cut_moments *moments, double w[27]);
/* From fitted weights w: N[a] = Σ_q w_q N_a(ξ_q) = ∫ N_a dV and (NN may be
 * NULL) NN[8a + b] = ∫ N_a N_b dV over the part (exact: Q2 integrands). */
void nh_cut_shape_integrals(const double w[27], double N[8], double NN[64]);

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

/* ---- a tool's cross-section as material points (mesh/disc.c) ----
 * The disc of radius rho about X across nrm (docs/interaction.md "Tip
 * disc"): n rings at radii rho (k − ½)/n, k = 1..n, of 6k equally spaced
 * points, weight 2(k − ½)/(6k n²) each (the midpoint rule in r, exact in
 * θ), n = ⌈2 rho / h⌉ clamped to [1, NH_DISC_MAX_RINGS] (samples at most
 * h/2 apart); each ring starts on ref's part across nrm (ref NULL or 0: the
 * axis least aligned with nrm). Writes the points X[3 each] and weights w
 * (Σ w = 1); returns their count, at most NH_DISC_MAX_POINTS (0 if
 * rho <= 0). */
#define NH_DISC_MAX_RINGS  8
#define NH_DISC_MAX_POINTS (3 * NH_DISC_MAX_RINGS * (NH_DISC_MAX_RINGS + 1))
int nh_disc_points(const double X[3], const double nrm[3], const double ref[3], double rho,
                   double h, double *points, double *w);

/* Smallest edge length of cell c's rest shape. */
/* Node -> the leaves having it as a corner, in CSR form: the leaves of node
 * v are leaf[start[v] .. start[v + 1]), ascending, each once. Both arrays
 * are allocated here (the caller frees them). */
int nh_mesh_node_leaves(const nh_mesh *mesh, int **start, int **leaf);
double nh_mesh_cell_size(const nh_mesh *mesh, int c);

/* ---- grading and coarsening (mesh/grade.c, mesh/coarsen.c) ----
 * The 2:1 rule: no leaf has a face or edge neighbour leaf more than one
 * level coarser (corner contacts are free). grade.c explains the search. */

/* The distinct leaves other than c met just outside the centres of leaf c's
 * 6 faces and the midpoints of its 12 edges (diagonally outward): every
 * coarser or equal face/edge neighbour, and a finer one wherever one
 * touches. Returns their count (<= 18), ids in out. */
int nh_mesh_face_edge_leaves(const nh_mesh *mesh, int c, int out[18]);

/* Close a set of leaves to refine under the 2:1 rule: on a graded mesh, add
 * every coarser face/edge neighbour that refining the set would leave two
 * levels apart, recursively. marked[] has room for mesh->n_leaves ids; on
 * return it holds the closed set, ascending, without repeats, and *n_marked
 * its size. Fails with NH_ERR_MEMORY. */
int nh_mesh_grade_marks(const nh_mesh *mesh, int *marked, int *n_marked);

/* Families that may be merged: parents whose children are all leaves with
 * below[child] != 0, and whose merging keeps the 2:1 rule (no leaf of level
 * >= parent's + 2 touches a child's face or edge). parents[] has room for
 * mesh->n_leaves / 2 ids; returns the count (ascending). */
int nh_mesh_coarsen_candidates(const nh_mesh *mesh, const unsigned char *below, int *parents);

/* Merge the children of parents[0..n) (each with only leaf children) back
 * into their parents: the children and the nodes no remaining cell uses are
 * removed, both arrays compacted in order (coarsen.c). node_map[old n_nodes]
 * receives each old node's new index, or -1 if removed. Coarsening the cells
 * a refinement just refined restores the mesh exactly. Fails with
 * NH_ERR_INTERNAL (a parent without children, or with a refined child),
 * NH_ERR_MEMORY. */
int nh_mesh_coarsen(nh_mesh *mesh, const int *parents, int n, int *node_map);

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
  /* aggregated nodes (nh_hanging_detect_aggregated): tied by extrapolation */
  int n_aggregated;
  unsigned char *aggregated; /* n_hanging: 1 for an aggregated node, 0 for a hanging one */
} nh_hanging;

/* Detect the hanging nodes of the leaves and resolve their chains. Nodes with
 * skip[i] != 0 (fixed nodes; may be NULL) are never hanging: a prescribed
 * value wins over interpolation. Output *out, free with nh_hanging_destroy.
 * Fails with NH_ERR_INTERNAL if a node lies inside a leaf or the chains form
 * a cycle (a broken mesh), NH_ERR_MEMORY. */
int nh_hanging_detect(const nh_mesh *mesh, const unsigned char *skip, nh_hanging **out);

/* Aggregated nodes of an immersed domain with integrated cut cells
 * (docs/theory.md §5c, "Aggregated nodes"; Badia, Verdugo & Martín 2018).
 * A node's support measure is the tissue share of its shape function over
 * the leaves it is a corner of,
 *     μ_v = Σ_L ∫_{Ω ∩ L} N_v dV / Σ_L ∫_L N_v dV   (the lumped mass over the full cells'),
 * and the node is ill posed when 0 < μ_v < threshold (a node without
 * tissue, μ_v = 0, stays as it is). An ill-posed node is tied, like a
 * hanging node, to the trilinear field of a well-posed root leaf (tissue,
 * and no ill-posed corner) extrapolated to it: u_s = Σ_a N_a(ξ_s) u_a, ξ_s
 * its natural coordinates in the root (outside [−1, 1]³). The root is
 * searched in NH_AGGREGATE_RINGS rings of corner neighbours of the node's
 * leaves, the first ring with one; in it the smallest Lebesgue constant of
 * the extrapolation, Σ_a |N_a(ξ_s)| = Π_k max(1, |ξ_s,k|) (ties:
 * no hanging corner, then the larger tissue fraction, then the leaf centre
 * nearest the domain's centre in |x|, |y|, |z| (mirror invariant), then the
 * lower cell index). A node without one stays free. */
#define NH_AGGREGATE_MIN   0.125
#define NH_AGGREGATE_RINGS 2
/* Hanging chains followed when a root's corner is checked for an ill-posed master. */
#define NH_AGGREGATE_CHAIN 4
typedef struct {
  const double *support;     /* per node: μ_v */
  const double *fraction;    /* per cell (leaves read): the tissue fraction V_t / V_c */
  double threshold;          /* ill posed: 0 < μ_v < threshold (NH_AGGREGATE_MIN) */
  const unsigned char *keep; /* per node, may be NULL: never aggregated (a fixed component) */
} nh_aggregation;
/* nh_hanging_detect, and with agg != NULL the aggregated nodes too, in one
 * table (chains through hanging and aggregated nodes resolved to free
 * masters). n_orphans (may be NULL): ill-posed nodes left free for want of a
 * root. Fails as nh_hanging_detect. */
int nh_hanging_detect_aggregated(const nh_mesh *mesh, const unsigned char *skip,
                                 const nh_aggregation *agg, nh_hanging **out, int *n_orphans);
void nh_hanging_destroy(nh_hanging **hanging);
/* Set the hanging entries of a nodal field (3 per node) to the
 * interpolation of their masters. */
void nh_hanging_interpolate(const nh_hanging *hanging, double *field, int components);

/* ---- a nodal field at points and on images; the inverse map (mesh/sample.c) ----
 * `field` holds 3 values per node (a displacement u, metres). A point X of
 * the rest configuration is located in its leaf and u(X) = Σₐ Nₐ(ξ) uₐ over
 * the leaf's 8 corners (hanging corners included: their values are their
 * masters' interpolation, so u is continuous across refinement faces). */

/* u at n rest points X[3n] into values[3n]; tissue[n] (may be NULL) is 1
 * where X lies in the tissue: in a leaf and inside the domain's shape (a box
 * domain: the mesh itself). Elsewhere values are 0. */
void nh_mesh_sample(const nh_mesh *mesh, const double *field, int n, const double *X,
                    double *values, unsigned char *tissue);
/* u at every voxel centre of `image` (i fastest; values[3 nvox]) and the
 * tissue mask (tissue[nvox], may be NULL), as nh_mesh_sample, located by
 * walking the lattice (sample.c). NH_ERR_INTERRUPTED when a stop is requested
 * (polled per slice). */
int nh_mesh_sample_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                         double *values, unsigned char *tissue);

/* The inverse map X(x): X + u(X) = x, by the fixed-point iteration
 * X_{k+1} = x − u(X_k) (sample.c: convergence, stopping, what happens outside
 * the tissue). */
typedef struct {
  double tolerance;   /* stop when |X_{k+1} − X_k| <= tolerance (m); 0: 1e-3 of the
                         image's smallest voxel spacing */
  int max_iterations; /* 0: 100 */
} nh_inverse_options;
typedef struct {
  long points;        /* voxels */
  long tissue;        /* X(x) in the tissue: x is in the shifted tissue */
  long outside;       /* X(x) outside the tissue (x outside the mesh: X = x) */
  long unconverged;   /* no convergence (3 steps not shorter, or max_iterations): X = x */
  int iterations_max; /* evaluations of u for one voxel, at most */
  double iterations_mean;
  double contraction; /* the largest ratio |X_{k+1} − X_k| / |X_k − X_{k−1}| (steps
                         above 10 tol) of the voxels that converged in the tissue: an
                         estimate of L (a path that crossed the mesh's surface can exceed it) */
} nh_inverse_stats;
enum { NH_INVERSE_OUTSIDE = 0, NH_INVERSE_TISSUE = 1, NH_INVERSE_UNCONVERGED = 2 };
/* X(x) at every voxel centre x of `image` into X[3 nvox] (may be NULL),
 * status[nvox] (NH_INVERSE_*, may be NULL) and *stats (may be NULL).
 * NH_ERR_INTERRUPTED as nh_mesh_sample_image. */
int nh_mesh_inverse_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                          const nh_inverse_options *options, double *X, unsigned char *status,
                          nh_inverse_stats *stats);
/* The image resampled to the shifted anatomy: out[v] = I(X(x_v)) for every
 * voxel centre x_v, I the interpolation of `values` (given at the voxel
 * centres of `image`) by nh_image_interpolate (trilinear, or the nearest
 * label when `nearest`). out may not alias values. NH_ERR_INTERRUPTED as
 * nh_mesh_sample_image. */
int nh_mesh_warp_image(const nh_mesh *mesh, const double *field, const nh_image *image,
                       const double *values, int nearest, const nh_inverse_options *options,
                       double *out, nh_inverse_stats *stats);

#endif
