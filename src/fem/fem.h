/* fem — the corotational trilinear hexahedron (docs/theory.md §2).
 *
 * Per element, with rest corners X, displacements u (current corners
 * x = X + u) and the rest stiffness K₀ (2x2x2 Gauss, isotropic elasticity):
 *   F   = I + Σₐ uₐ ⊗ ∇N_a(0)    deformation gradient at the centre
 *   R   = polar rotation of F     (robust to det F <= 0, core/mat3.c)
 *   fₑ  = R K₀ (Rᵀ x − X)         internal force (blockwise R per node)
 *   Kₑ  = R K₀ Rᵀ + G Ω           tangent: corotational, or consistent with
 *                                 the variation G Ω of R (and, B-bar, of b)
 * K₀ is either the fully integrated one or the B-bar (mean-dilatation) one
 * that does not lock near incompressibility (docs/theory.md §2b).
 * Lumped mass ρ Vₑ / 8 per node; a cut cell of an immersed domain has K₀,
 * mean gradients and mass ρ ∫ N_a integrated over its tissue part by the
 * finite cell quadrature, plus α K_cell on its fictitious part
 * (docs/theory.md §5c); a cell that is not a box scales by its fill φ. Matrices are row-major,
 * 24x24, row 3a+i is node a, component i. Voigt order for stresses: xx, yy, zz, yz, xz, xy.
 *
 * Files, each using only those before it: hex.c (one element: K₀, the
 * rotation, force and tangent) < stress.c (the stress anywhere inside one
 * element, compliance, von Mises) < tissue.c (every leaf of the mesh: the
 * element data cache, materials, mass, ties, forces, cell stresses);
 * traction.c (surface loads) uses only the mesh. */
#ifndef NH_FEM_H
#define NH_FEM_H

#include "core/core.h"
#include "mesh/mesh.h"

#include <stdint.h>

typedef struct {
  double young, poisson, density;
  nh_formulation formulation; /* scene/scene.h; default (0): B-bar */
} nh_material;

/* ---- one element (fem/hex.c) ---- */

/* Rest stiffness K0 (24x24), the shape-function gradients G0[8][3] = ∇_X N_a
 * at the centre, their volume averages Gbar[8][3] = (1/V) ∫ ∇_X N_a dV (may
 * be NULL) and the volume. bbar = 0: K0 = ∫ Bᵀ D B by 2x2x2 Gauss points;
 * bbar = 1: K0 = ∫ Bᵀ D_dev B (Gauss), the deviatoric part only (the
 * volumetric part is nh_hex_corot's, from Gbar).
 * Fails with NH_ERR_NUMERIC (message names nothing: the caller knows the
 * cell) if the Jacobian is not positive at a Gauss point. */
int nh_hex_stiffness(const double X[24], double lambda, double mu, int bbar, double K0[576],
                     double G0[24], double Gbar[24], double *volume);

/* K += w [λ gₐ ⊗ g_b + μ g_b ⊗ gₐ + μ (gₐ·g_b) I] (blocks a, b): one point
 * of ∫ BᵀDB with gradients g[24] and weight w (det J times the rule's). */
void nh_hex_point_stiffness(const double g[24], double w, double lambda, double mu, double K[576]);

/* Rest shape-function gradients g[8][3] = ∇_X Nₐ at ξ; returns det J.
 * g is written only when det J > 0 and J is invertible; otherwise g is left
 * untouched and the return value is <= 0. */
double nh_hex_gradients(const double X[24], const double xi[3], double g[24]);
/* det J at ξ as nh_hex_gradients returns it (0 where det J > 0 but J is not
 * invertible), without the gradients: for checks of the sign alone. */
double nh_hex_det(const double X[24], const double xi[3]);
/* 1 if !(nh_hex_det(x, ξ) > 0) at one of the 8 corners or the 2x2x2 Gauss
 * points of the hexahedron x (the guard's inversion test, sim/guard.c),
 * else 0: the same test at a quarter of the work (see hex.c). */
int nh_hex_inverted(const double x[24]);

/* F = I + Σ uₐ ⊗ G0ₐ, its polar rotation R[9], and the corotated nodal
 * displacements d[24] = Rᵀ uₐ + (Rᵀ − I)(Xₐ − X̄) (= Rᵀxₐ − Xₐ up to a
 * translation, which K0 annihilates). */
void nh_hex_corotated(const double X[24], const double u[24], const double G0[24], double R[9],
                      double d[24]);
/* The corotated displacements d[24] of nh_hex_corotated for a given
 * rotation R[9] (the polar rotation an assembly's frame holds): the same
 * arithmetic, so the same bits for the same R. */
void nh_hex_corotate(const double X[24], const double u[24], const double R[9], double d[24]);

/* B-bar's volumetric part of one element: mean gradients, κ = λ + ⅔μ, V. */
typedef struct {
  const double *Gbar; /* 24 */
  double kappa, volume;
} nh_hex_volumetric;

/* The mean volume change θ̄ = det F̄ − 1, F̄ = I + Σ uₐ ⊗ Gbarₐ, computed
 * without cancellation against 1; cof[9] (may be NULL) receives cof F̄. */
double nh_hex_mean_dilatation(const double u[24], const double Gbar[24], double cof[9]);

/* The state an element's tangent depends on (its "frame"), NH_HEX_FRAME
 * doubles written by nh_hex_corot_force:
 *   R    [NH_FRAME_R ..+9]     the rotation (polar of F at the centre)
 *   C    [NH_FRAME_COF ..+9]   cof F̄ (B-bar; zero without vol)
 *   F̄    [NH_FRAME_FBAR ..+9]  the mean deformation gradient (B-bar; else zero)
 *   θ̄    [NH_FRAME_THETA]      det F̄ − 1 (B-bar; else zero)
 *   Y    [NH_FRAME_SPIN ..+9]  the spin operator (tr V I − V)⁻¹, V = F Rᵀ the
 *                              left stretch (zero at the polar decomposition's
 *                              singularity: the variation of R is then dropped)
 *   d    [NH_FRAME_D ..+24]    the corotated displacements
 * F̄, θ̄, Y and d (from NH_FRAME_FBAR on) carry only the geometric part of the
 * tangent: nh_hex_frame_corotational zeroes them, and the tangent of such a
 * frame is the corotational R K0 Rᵀ (+ κ V bₐ ⊗ b_b). */
enum {
  NH_FRAME_R = 0,
  NH_FRAME_COF = 9,
  NH_FRAME_FBAR = 18,
  NH_FRAME_THETA = 27,
  NH_FRAME_SPIN = 28,
  NH_FRAME_D = 37,
  NH_HEX_FRAME = 61
};

/* Corotational internal force f[24], the rotation R[9] and (if Kt != NULL)
 * the corotational tangent R K0 Rᵀ at nodal displacements u[24]. With vol
 * (B-bar; K0 then deviatoric) f gains κ V θ̄ cof(F̄) ḡₐ and Kt gains
 * κ V bₐ ⊗ b_b, bₐ = cof(F̄) ḡₐ; vol = NULL for the fully integrated one.
 * nh_hex_corot_force, nh_hex_frame_corotational and nh_hex_corot_tangent in
 * one call (the consistent tangent: the first and the last). */
void nh_hex_corot(const double X[24], const double u[24], const double K0[576], const double G0[24],
                  const nh_hex_volumetric *vol, double R[9], double f[24], double Kt[576]);

/* The parts of nh_hex_corot, for tangents kept from an earlier state (lazy
 * updates, solve/assemble.c) and for the consistent tangent. The tangent
 * depends on u only through the element's frame (above).
 * nh_hex_corot_force: f[24] at u[24] and the frame there.
 * nh_hex_corot_tangent: Kt[576] of a frame (row-major, generally not
 *   symmetric): the consistent tangent ∂f/∂u (docs/theory.md §2, "Consistent
 *   tangent"; §2b),
 *     Kt = R K0 Rᵀ + G Ω + κ V (b bᵀ + θ̄ H)
 *   with G Ω the variation of R and θ̄ H that of b (B-bar), or, for a frame
 *   through nh_hex_frame_corotational, R K0 Rᵀ (+ κ V b bᵀ).
 * nh_hex_corot_apply: y = Kt w without forming Kt. */
void nh_hex_corot_force(const double X[24], const double u[24], const double K0[576],
                        const double G0[24], const nh_hex_volumetric *vol,
                        double frame[NH_HEX_FRAME], double f[24]);
void nh_hex_frame_corotational(double frame[NH_HEX_FRAME]);
void nh_hex_corot_tangent(const double K0[576], const double G0[24], const nh_hex_volumetric *vol,
                          const double frame[NH_HEX_FRAME], double Kt[576]);
void nh_hex_corot_apply(const double K0[576], const double G0[24], const nh_hex_volumetric *vol,
                        const double frame[NH_HEX_FRAME], const double w[24], double y[24]);
/* D[576] = ∂(K(u) w)/∂u for a fixed w[24], K(u) the corotational tangent
 * R K0 Rᵀ (+ κ V b bᵀ) at the frame's state (a consistent frame: its Y and
 * F̄; zero spin drops the variation of R as nh_hex_corot_tangent does): the
 * variation of the stiffness-damping force β K(u) v in the dynamic step's
 * exact Jacobian (docs/theory.md §3, "Newton iterations in the dynamic
 * step"). Row-major, not symmetric. */
void nh_hex_corot_rate_tangent(const double K0[576], const double G0[24],
                               const nh_hex_volumetric *vol, const double frame[NH_HEX_FRAME],
                               const double w[24], double D[576]);

/* Lamé parameters from E and ν. */
void nh_lame(double young, double poisson, double *lambda, double *mu);

/* ---- stresses inside an element, compliance, von Mises (fem/stress.c) ----
 * Above the element (hex.c), below the tissue (tissue.c evaluates them for
 * its cells). */

/* Cauchy stress at n natural points xi[3n] of one element: s[6n] (Voigt),
 * σ = R (λ tr ε I + 2 μ ε) Rᵀ with R the element's rotation (polar of F at
 * the centre, as nh_hex_corot) and ε the symmetric gradient of the corotated
 * displacements d = Rᵀu + (Rᵀ − I)(X − X̄) with the rest gradients at ξ;
 * with Gbar (B-bar) the volumetric part is the element's mean,
 * σ = κ θ̄ I + R (2μ dev ε) Rᵀ, θ̄ = det F̄ − 1 (nh_hex_mean_dilatation),
 * κ = λ + ⅔μ.
 * detJ[n] (may be NULL) receives the rest Jacobian determinant at each point.
 * Cannot fail: a point where det J <= 0 (outside a valid cell) uses the
 * centre gradients G0, so s is finite for finite input; callers that need
 * det J > 0 check detJ. */
void nh_hex_stress_at(const double X[24], const double u[24], const double G0[24],
                      const double *Gbar, double lambda, double mu, int n, const double *xi,
                      double *s, double *detJ);
/* The rest gradients at the natural point xi that nh_hex_stress_at uses:
 * g[24] = ∇N_a(ξ) (G0 where det J <= 0); returns det J there. */
double nh_hex_rest_gradients(const double X[24], const double G0[24], const double xi[3],
                             double g[24]);

/* σ = R (λ tr ε I + 2 μ ε) Rᵀ, ε = sym(Σₐ dₐ ⊗ gₐ), for element rotation
 * R[9], corotated nodal values d[24] and shape-function gradients g[24] at a
 * point; s[6] Voigt. With d = Rᵀw (node by node) it is the stress of the
 * tangent R K₀ Rᵀ for nodal values w (an increment, a dual solution): the sum
 * over the 2x2x2 Gauss points of det J σ(w)ᵀ D⁻¹ σ(v) is vᵀ R K₀ Rᵀ w.
 * B-bar (theta_bar not NULL): σ = κ θ̄ I + R (2 μ dev ε) Rᵀ, κ = λ + ⅔μ,
 * θ̄ = *theta_bar the element's mean volume change (for an increment w its
 * linearisation Σₐ bₐ·wₐ, bₐ = cof(F̄) ḡₐ: then the sum above is vᵀ Kt w
 * with the B-bar tangent of nh_hex_corot). */
void nh_hex_rotated_stress(const double R[9], const double d[24], const double g[24], double lambda,
                           double mu, const double *theta_bar, double s[6]);

/* Isotropic compliance e = D⁻¹ s: s[6] Voigt stresses (xx, yy, zz, yz, xz,
 * xy), e[6] engineering strains (εxx, εyy, εzz, γyz, γxz, γxy with γ = 2ε),
 * so that sᵀe = σ : ε and ½ sᵀe is the strain-energy density. */
void nh_voigt_compliance(double lambda, double mu, const double s[6], double e[6]);

/* von Mises equivalent stress of s[6] (Voigt). */
double nh_von_mises(const double s[6]);

/* ---- the tissue: element data cache, mass, forces (fem/tissue.c) ---- */

/* Doubles per cell in nh_tissue.cell_material. */
#define NH_CELL_MATERIAL 9

/* Default stiffness of the fictitious part of a cut cell, as a fraction α
 * of the tissue's (docs/theory.md §5c). */
#define NH_TISSUE_ALPHA 1e-6

/* A cut cell's element data (docs/theory.md §5c), integrated over its
 * tissue part by the finite cell quadrature (mesh/cutcell.c). */
typedef struct nh_tissue_cut {
  double lo[3], hi[3]; /* the rest box they were computed for */
  double lambda, mu;   /* the material they were computed with */
  double w[27];        /* fitted weights (m³) at nh_cut_points */
  double K0[576];      /* (1 − α) ∫_tissue BᵀDB dV + α K_cell (B-bar: D_dev in the first) */
  double G0[24];       /* ∇N at the tissue part's centroid (the rotation's F) */
  double Gbar[24];     /* (1/V_t) ∫_tissue ∇N dV (B-bar's dilatation) */
  double corner[8];    /* ∫_tissue N_a dV */
  double above[8]; /* ∫ N_a dV over the tissue above the drainage plane (nh_tissue_set_drainage)
                      on the entry's own lattice; NaN without a plane */
  double volume, fraction; /* V_t and V_t / V_cell */
  double xi[3];            /* the centroid, natural coordinates */
  /* which points lie in the tissue (level ≤ 0): bit q < 27 the fitted
   * quadrature's point ξ_q (nh_cut_points), bit 27 + a corner a */
  uint64_t inside;
} nh_tissue_cut;

/* The tissue model: material, per-cell element data and the lumped mass.
 * Element data are shared between cells of identical rest shape (all cells
 * of a uniform grid share one K0), found by hashing the rest corners. */
typedef struct nh_tissue {
  const nh_mesh *mesh; /* borrowed */
  nh_material material;
  double lambda, mu;
  /* materials per label (nh_tissue_set_label_materials; n_labels = 0: one material) */
  int n_labels;
  int *label; /* n_labels image labels */
  nh_material *label_material;
  double *Kl, *Km;       /* 576 per shape: K0 for (λ, μ) = (1, 0) and (0, 1) */
  double *cell_material; /* NH_CELL_MATERIAL per cell: the cell's λ, μ, ρ (λ NaN: not computed
                            yet), then the rest corners 0 and 6 of the cell they were mixed for */
  int n_shapes, cap_shapes;
  double *K0;      /* 576 per shape */
  double *G0;      /* 24 per shape */
  double *Gbar;    /* 24 per shape: mean gradients (used by B-bar) */
  double *volume;  /* per shape */
  double *key;     /* 24 per shape: corners relative to corner 0 */
  int *cell_shape; /* per cell (leaves only meaningful), -1 if not computed */
  int cap_cells;
  double *mass; /* lumped nodal mass, per node */
  int cap_nodes;
  /* ties of fixed regions (nh_tissue_set_ties): per cell index into tie or
   * -1, and the first region that ties it (-1: none; for messages) */
  int *cell_tie, *cell_tie_region, cap_cell_tie;
  double *tie; /* 64 per tied cell: k ∫ χ Nₐ N_b dV (8x8) */
  int n_ties, cap_ties;
  /* cut cells of an immersed domain (docs/theory.md §5c): per cell an index
   * into cut, NH_CUT_WHOLE (a box cell all inside: φ = 1) or NH_CUT_NONE
   * (a box domain, or a cell that is not an axis-aligned box: scaled by φ) */
  double alpha; /* the fictitious part's stiffness fraction (NH_TISSUE_ALPHA) */
  int *cell_cut, cap_cell_cut;
  nh_tissue_cut *cut;
  int n_cut, cap_cut;
  /* the goal estimate's geometry term (nh_tissue_set_geometry_cache): per
   * cut entry its data one lattice finer (NH_CUT_DEPTH + 1), kept with the
   * entry; NULL when not cached */
  nh_tissue_cut *fine;
  /* the drainage plane {p, up} whose cut the entries hold (above[]) */
  double drainage[6];
  int has_drainage;
} nh_tissue;
enum { NH_CUT_NONE = -1, NH_CUT_WHOLE = -2 };

/* The cut-cell data of leaf c, or NULL if c is not a cut cell. */
const nh_tissue_cut *nh_tissue_cell_cut(const nh_tissue *tissue, int c);
/* The tissue fraction of leaf c: V_t / V_c of a cut cell, 1 of a whole
 * one, else its fill fraction φ (a box domain: 1). */
double nh_tissue_fraction(const nh_tissue *tissue, int c);
/* The support measure of every node (docs/theory.md §5c, "Aggregated
 * nodes"): μ_v = Σ_L ∫_{tissue ∩ L} N_v dV / Σ_L ∫_L N_v dV over the leaves
 * L it is a corner of (a cut cell's ∫ N_v from its quadrature, any other
 * leaf's φ V_L / 8 over V_L / 8); 0 for a node of no leaf. NH_ERR_MEMORY. */
int nh_tissue_node_support(const nh_tissue *tissue, double *support);
/* Keep (on != 0) or drop the cut cells' data one lattice finer, which the
 * goal estimate's geometry term (nh_tissue_geometry_residual) compares with
 * theirs: computed here for every cut leaf and afterwards, in
 * nh_tissue_update, for the new ones only (a kept leaf keeps its entry).
 * They depend only on the leaf's rest box, its material and α, as the cut
 * entry does. NH_ERR_MEMORY, or the cut-cell quadrature's failure. */
int nh_tissue_set_geometry_cache(nh_tissue *tissue, int on);
/* The drainage plane {p[3], up[3]} (tissue.buoyancy.level; NULL: none):
 * every cut entry, and its finer one, keeps ∫ N_a dV over its tissue above
 * the plane on its own lattice (a half-space cut where the plane crosses
 * the leaf), which nh_tissue_corner_masses and the geometry term then read
 * instead of integrating again. Entries already holding this plane's are
 * kept; later entries get theirs when made. Fails as the cut-cell
 * quadrature. */
int nh_tissue_set_drainage(nh_tissue *tissue, const double *plane);
/* Set the stabilisation α >= 0 and recompute every cut cell. NH_ERR_MEMORY. */
int nh_tissue_set_stabilisation(nh_tissue *tissue, double alpha);
/* At most this many points of a cut cell's tissue (nh_tissue_tissue_points). */
#define NH_TISSUE_POINTS 36
/* The natural points where leaf c holds tissue, for the inversion check:
 * returns -1 for a cell that is not cut (check the whole cell), else the
 * number n of points in xi[3n]: the tissue part's centroid, and those of the
 * 27 points of the fitted quadrature (nh_cut_points) and of the 8 corners
 * that lie in the tissue (the domain's level ≤ 0 there); 0 when the cell
 * holds no tissue. (Inside-ness, not the fitted weights: in a cell with a
 * small tissue part, points of positive weight can lie in its fictitious
 * part.) */
int nh_tissue_tissue_points(const nh_tissue *tissue, int c, double xi[3 * NH_TISSUE_POINTS]);
/* Leaf c is inverted at the displacements u: !(det J > 0) at one of its
 * tissue points (nh_tissue_tissue_points) for a cut cell, or at one of its
 * corners or 2x2x2 Gauss points (nh_hex_inverted) otherwise. The fictitious
 * part of a cut cell carries no load and may fold. The one inversion test of
 * the guard (sim/guard.c) and the failure diagnosis (solve/diagnose.c). */
int nh_tissue_cell_inverted(const nh_tissue *tissue, int c, const double *u);
/* The rotation's gradients G0 (24) of leaf c: at the centre, or at a cut
 * cell's tissue centroid. */
const double *nh_tissue_g0(const nh_tissue *tissue, int c);

/* The mean gradients of leaf c for the stress of its formulation: NULL for
 * the fully integrated element. */
const double *nh_tissue_gbar(const nh_tissue *tissue, int c);

/* Element data for every leaf of `mesh` and the lumped mass.
 * Fails with NH_ERR_INPUT if a cell has a non-positive Jacobian (an inverted
 * rest cell is a meshing error), NH_ERR_MEMORY. */
int nh_tissue_create(const nh_mesh *mesh, const nh_material *material, nh_tissue **out);
/* Materials per label of the domain's label image (mesh->domain.labels):
 * labels[i] has materials[i]; voxels of other labels have the default. A
 * cell gets the volume average (Voigt) of λ, μ and ρ over the tissue in it,
 * measured at NH_FILL_SAMPLES³ sub-cell midpoints (docs/anatomy.md, "Mixed
 * cells"); cells made later by refinement get theirs in nh_tissue_update.
 * n = 0 restores the single material. Fails with NH_ERR_INPUT if n > 0 and
 * the domain has no label image, NH_ERR_MEMORY. */
int nh_tissue_set_label_materials(nh_tissue *tissue, int n, const int *labels,
                                  const nh_material *materials);
/* Lamé parameters and density of leaf c. */
void nh_tissue_cell_material(const nh_tissue *tissue, int c, double *lambda, double *mu,
                             double *density);
/* Lumped mass of leaf c's corners m[8]: ρ_c φ_c V_c / 8 each, or a cut
 * cell's ρ_c ∫_tissue N_a dV. With plane = {p[3], up[3]} (may be NULL) only
 * the tissue above the plane, (x − p)·up > 0, counts (the drained mass of
 * tissue.buoyancy.level): on an immersed box cell by the same quadrature
 * with the half-space as a set, elsewhere as ρ_c φ_c V_c / 8 times
 * nh_mesh_cell_fraction_above. Fails with NH_ERR_MEMORY. */
int nh_tissue_corner_masses(const nh_tissue *tissue, int c, const double *plane, double m[8]);
/* Recompute element data of new cells and the lumped mass after the mesh changed. */
int nh_tissue_update(nh_tissue *tissue);
void nh_tissue_destroy(nh_tissue **tissue);

/* Tie the tissue inside each region to its rest position by a volumetric
 * spring of stiffness k[r] (Pa/m²): energy ½ Σ_r k_r ∫_{region ∩ tissue} |u|²
 * dV, nodal force fₐ = Σ_b Tₐ_b u_b, tangent Tₐ_b I (docs/theory.md §5,
 * "Fixed regions"). Replaces earlier ties; call again after the mesh
 * changed. volume[r] (may be NULL) receives the tissue volume tied by
 * region r. Fails with NH_ERR_MEMORY. */
int nh_tissue_set_ties(nh_tissue *tissue, int n_regions, const nh_region *regions, const double *k,
                       double *volume);

/* The element of leaf c at nodal displacements u (3 per node): force f[24]
 * and corotational tangent Kt[576] (may be NULL), both scaled by φ, plus the
 * cell's tie. */
void nh_tissue_element(const nh_tissue *tissue, int c, const double *u, double f[24],
                       double Kt[576]);
/* The same in parts (lazy and consistent tangents, solve/assemble.c; frame
 * as nh_hex_corot_force): the force f[24] at u and the frame there; the
 * tangent Kt[576] of a frame (nh_hex_corot_tangent); y[24] = Kt w[24] of a
 * frame without forming Kt. All scaled by φ, tie included. */
void nh_tissue_element_force(const nh_tissue *tissue, int c, const double *u, double f[24],
                             double frame[NH_HEX_FRAME]);
/* D[576] = ∂(Kt(u) w)/∂u of the corotational tangent (nh_hex_corot_rate_tangent;
 * the tie is linear: no part), scaled by φ. */
void nh_tissue_element_rate_tangent(const nh_tissue *tissue, int c,
                                    const double frame[NH_HEX_FRAME], const double w[24],
                                    double D[576]);
void nh_tissue_element_tangent(const nh_tissue *tissue, int c, const double frame[NH_HEX_FRAME],
                               double Kt[576]);
void nh_tissue_element_apply(const nh_tissue *tissue, int c, const double frame[NH_HEX_FRAME],
                             const double w[24], double y[24]);

/* Elastic energy Σₑ φ (½ dₑᵀ K0 dₑ + ½ κ V θ̄²) (dₑ = Rᵀxₑ − Xₑ; the second
 * term for B-bar only) at displacements u. */
double nh_tissue_energy(const nh_tissue *tissue, const double *u);

/* Corotational Cauchy stress s[6] (Voigt, Pa) of leaf c at the natural point
 * xi[3] for displacements u (3 per node): nh_hex_stress_at with the cell's
 * element data and material. */
void nh_tissue_gauss_stress(const nh_tissue *tissue, int c, const double *u, const double xi[3],
                            double s[6]);
/* Centre stress of leaf c: nh_tissue_gauss_stress at ξ = 0. */
void nh_tissue_cell_stress(const nh_tissue *tissue, int c, const double *u, double s[6]);

/* ---- the geometry term of the goal estimate (docs/theory.md §6.6, "Geometry") ----
 * The loads of a step that depend on the immersed geometry: the body force
 * per unit mass (gravity by its schedule, less the buoyed part), the
 * drainage plane {p[3], up[3]} above which the mass it acts on lies (NULL:
 * all of it; nh_tissue_corner_masses), and the tractions with their
 * schedule factors. */
typedef struct nh_geometry_loads {
  double body[3];
  const double *plane;
  int n_tractions;
  const nh_traction *tractions;
  const double *traction_factor;
} nh_geometry_loads;
/* The change of leaf c's residual when its cut-cell quadrature goes from
 * depth NH_CUT_DEPTH to NH_CUT_DEPTH + 1 (one lattice finer):
 *     r = (f_ext' − f_ext) − (f_int'(u) − f_int(u))      (primes: depth + 1)
 * over the leaf's 8 nodes (r[24]): the elastic force (K0, B-bar's mean
 * gradients and volume, the centroid's frame), the body force on its mass
 * above the drainage plane (its half-space cut at each depth) and the
 * immersed tractions (loads may be NULL: elastic part only). Ties are not
 * re-integrated. The finer data come from the
 * cache of nh_tissue_set_geometry_cache when it is on (bit for bit what
 * would be computed). Returns 1 for a cut leaf, 0
 * (r zero) otherwise (a box domain, `scaled`, whole or not a box cell), or
 * a negative NH_ERR_* code. */
int nh_tissue_geometry_residual(const nh_tissue *tissue, int c, const double *u,
                                const nh_geometry_loads *loads, double r[24]);

/* ---- surface tractions (traction.c; docs/theory.md "Surface tractions") ----
 * Consistent nodal forces of the traction tr at schedule factor 1: adds
 * ∫_Γ N_a t dA to f[3 n] over the tissue's boundary Γ inside tr's region
 * (the box domain's faces; for an immersed domain the surface F = 0 cut
 * from its cells), t = tr->traction or −tr->pressure n. *area (may be NULL):
 * the area of Γ it integrated over. NH_ERR_INPUT (at tr->where) if the region
 * holds no boundary. */
int nh_traction_load(const nh_mesh *mesh, const nh_traction *tr, double *f, double *area);
/* The immersed-surface part of that load in leaf c alone, on the
 * sub-lattice of 2^depth per cell edge (depth <= NH_CUT_DEPTH + 1), as an
 * element vector fe[24]; returns the area (0 on a box domain). */
double nh_traction_cell(const nh_mesh *mesh, int c, const nh_traction *tr, int depth,
                        double fe[24]);

#endif
