/* dwr.c — goal-oriented error estimation: the dual-weighted residual for
 * the displacement of points (docs/theory.md "Goal-oriented estimate";
 * Becker & Rannacher 2001, Oden & Prudhomme 2001, and for soft tissue
 * Duprez, Bordas, Bui et al. 2020).
 *
 * Quantity of interest. A point value is not a bounded functional on H¹ in
 * 3-D (the dual solution would be the Green's function, of infinite energy),
 * so each point p is regularised: for a component k,
 *     J_pk(v) = (1 / |B ∩ Ω|) ∫_{B ∩ Ω} v_k dV,   B = p + [−r, r]³,
 * the mean of v_k over the tissue in a box of half-width r around p. Its
 * nodal vector j_a = (1/|B∩Ω|) ∫ N_a dV is the consistent load of a unit
 * force spread over B (mesh/region.c, exact on box cells), so J is the
 * same functional on every mesh of a refinement sequence: J(P u_h) =
 * J_h(u_h) for the prolongation P of nested spaces. For a field that is
 * smooth on the scale of r, J_pk(u) = u_k(p) + O(r² |∇²u|).
 *
 * Dual problem. With A the symmetric matrix factorised for the step's
 * solution (static: the stiffness K; dynamic: (1 + hα) M + (hβ + h²) K),
 * the dual solution of J is z with A z = c_K j, c_K the coefficient of K in
 * A (1 static, hβ + h² dynamic): for the quasi-static steps of our cases
 * (h²K ≫ M), z ≈ K⁻¹ j, the influence function of J. The factor is the
 * step's: every dual costs one forward and one backward triangular solve,
 * all of them in one multi-column pass (nh_system_solve_many). After a step
 * that reused an earlier factor (solver.refactor: auto), A is factorised
 * first (nh_system_solve_rows), and the next steps reuse that factor.
 * Fixed DOFs carry z = 0, hanging nodes their masters' interpolation (z
 * lies in the discrete space). The hanging-node rows of `adapt.hanging:
 * lagrange` are not supported (use elimination).
 *
 * Constraints. A step with constraint rows (skull, the tools' puncture, tip
 * and shaft rows) solves A u + Jᵀλ = f, J u = g on its active rows
 * (nh_dwr_active_rows: bilateral, pressing unilateral, sticking friction
 * rows). Its dual is the saddle point A z + Jᵀμ = c_K j, J z = 0, solved
 * with the step's factor and the rows' compliance W = J A⁻¹ Jᵀ
 * (nh_system_solve_rows: z = z₀ − A⁻¹Jᵀμ, W μ = J z₀, z₀ = A⁻¹ c_K j); the
 * tools' parts of the rows are held. With u_f, u_h constrained solutions
 * on nested meshes, J(u_f − P u_h) = 0 and then J(u_f) − J(u_h) =
 * (A z + Jᵀμ)ᵀ(u_f − P u_h) = zᵀ(f − Jᵀλ_f − A P u_h) = f(z) − a(P u_h, z):
 * the DWR identity holds with the constrained dual (docs/theory.md §6.6).
 *
 * Error representation. For a linear problem a(u, v) = f(v) and conforming
 * Galerkin u_h, z_h: J(u) − J(u_h) = a(u − u_h, z) = f(z) − a(u_h, z) =:
 * ρ(u_h; z) (the residual weighted by the dual), and by Galerkin
 * orthogonality = ρ(u_h; z − z_h) = a(u − u_h, z − z_h). We approximate the
 * last form with the recovered errors of both problems (superconvergent
 * patch recovery, adapt/spr.c, applied to u_h and to each z_h with the same
 * patches; González-Estrada, Nadal, Ródenas, Kerfriden, Bordas and
 * Fuenmayor 2014 do this with an equilibrated SPR):
 *     E_pk = Σ_K ε_K,   ε_K = φ_K ∫_K (σ*_u − σ_h(u))ᵀ D⁻¹ (σ*_z − σ_h(z)) dΩ,
 * (2x2x2 Gauss points; σ_h(z) the tangent stress of z at the state u,
 * that of nh_hex_rotated_stress of Rᵀz, formed as λ tr H I + μ (H + Hᵀ),
 * H = Σₐ zₐ ⊗ R gₐ, with the rotated gradients computed once per cell: the
 * rotations R(·)Rᵀ of the 36 duals' stresses at every Gauss point were
 * 40 % of the integrals' time; each cell with its own material (per
 * label) and its formulation: under B-bar the volumetric part is the
 * element's mean, κ θ̄ I, with θ̄(z) = Σₐ bₐ·zₐ the linearised mean volume
 * change, so that the products are those of the assembled tangent; D⁻¹
 * the cell's compliance). E_pk is signed: it estimates the error with
 * its sign, J(u) − J(u_h). Per point the estimate of the error vector's
 * length is |E_p| = (Σ_k E_pk²)^½ (m).
 *
 * B-bar. The mean-dilatation element is the mixed Q1–P0 method: u_h with
 * the pressure p_h = κ Π div u_h (Π the element mean), Galerkin-orthogonal
 * for B((u, p), (v, q)) = a_dev(u, v) + (p, div v) + (q, div u) − (p, q)/κ,
 * not for the conforming a(·,·). The representation is then
 *     J(u) − J(u_h) = B((e_u, e_p), (e_z, e_q))
 *       = a_dev(e_u, e_z) + (e_p, e_q)/κ − (e_p, (I − Π) div z_h)
 *                                         − (e_q, (I − Π) div u_h),
 * using div e_u = e_p/κ − (I − Π) div u_h (and the same for z). The first
 * two terms are the compliance product of the B-bar stresses' recovered
 * errors above; the last two are added at the Gauss points with the
 * recovered pressure errors e*_p = tr(σ* − σ_h)/3 and (I − Π) div w =
 * Σₐ dₐ·(gₐ − ḡₐ) of the corotated nodal values. Without them the estimate
 * was measured 1.8–2.8 × the error on the localized-load block (B-bar,
 * ν = 0.3), with them 0.95–1.56 (docs/adaptivity.md). The marking
 * indicator keeps the Cauchy–Schwarz bound of the compliance product.
 *
 * Distance. The electrode tip–target distance d = |x_tip − x_T|, with
 * x_T = X_T + J_T(u) the target's current position (the box mean above)
 * and x_tip the tool's tip, a node of its beam. Linearised about the
 * current state, δd = n · (δx_tip − δx_T), n = (x_tip − x_T) / d. The dual
 * sees the tip as held: the beam is not refined (its own discretisation
 * error is not estimated), and the tissue's discretisation error reaches
 * the tip only through the constraint forces, which bend the tool by
 * (compliance of the beam) × (error of the force) — the constraint rows are
 * not in A (below), so the dual of the tissue alone has no path to the tip.
 * Its tissue part is then the functional −n · J_T, whose nodal vector is
 * −Σ_k n_k j_k (nh_goal_distance_functional) and whose dual, by linearity,
 * is −Σ_k n_k z_k: no extra solve. The recovery (SPR) and the integrals
 * are linear in the dual, so its estimate is exactly −Σ_k n_k E_k
 * (nh_dwr_distance_estimate). The held tip is a good model for a stiff
 * tool (docs/adaptivity.md gives the numbers for the DBS cannula and
 * electrode). At d = 0, d is not differentiable; |δd| ≤ |δx_T| there and
 * everywhere, which is why marking keeps the target's position (3
 * components) as its goal: controlling it controls the distance from any
 * direction.
 *
 * Cell indicators. Local contributions ε_K cancel between cells; a cell
 * whose primal and dual errors happen to be orthogonal would never be
 * refined. Marking uses the Cauchy–Schwarz bound of each cell's term
 * instead,
 *     η_K^p = ‖e*_u‖_K (Σ_k ‖e*_{z,pk}‖²_K)^½ ≥ |(ε_K,pk)_k|,
 * (‖·‖_K the cell's energy norm of the recovered error), so Σ_K η_K^p ≥
 * |E_p| up to the recovery's accuracy. As a by-product the primal's SPR
 * indicators ηₑ, η and η_rel of nh_spr_estimate are returned too.
 *
 * Several goals in one dual (Hartmann & Houston, "Goal-oriented a
 * posteriori error estimation for multiple target functionals"): for
 * weights ω_pk, the dual of J_c = Σ ω_pk J_pk is Σ ω_pk z_pk and, the
 * recovery and the integrals being linear in the dual, its estimate is
 * Σ ω_pk E_pk: nh_dwr_estimate_combined solves one dual instead of 3 per
 * point (adapt/refine.c sets the weights from the last separate estimate).
 *
 * Geometry (docs/theory.md §6.6, "Geometry"). The cut cells' quadrature
 * integrates over the reconstruction Ω_d of the tissue (the Kuhn
 * interpolant of its level set on 2^d sub-boxes per edge, d = NH_CUT_DEPTH),
 * not over Ω: the discrete problem itself has a geometric error O(s²),
 * s = h/2^d, which the recovered-stress product does not see. One level
 * finer, the residual of u_h is R_{d+1}(u_h) = Σ_K r_K (R_d(u_h) = 0 at
 * convergence), r_K the change of leaf K's residual
 * (nh_tissue_geometry_residual: elastic force, body force on the mass,
 * immersed tractions), so J(u_{d+1}) − J(u_d) ≈ z_hᵀ R_{d+1}(u_h) (static;
 * the quasi-static limit of a dynamic step, z ≈ K⁻¹ j). With the error
 * O(s²), J(u_Ω) − J(u_d) ≈ (4/3)(J(u_{d+1}) − J(u_d)):
 *     G_q = (4/3) Σ_K z_q,Kᵀ r_K,     η_geo,K = (4/3) (Σ_k (z_pk,Kᵀ r_K)²)^½
 * G_q is added to E_q, η_geo,K to the cell's marking indicator, so cut
 * cells are refined where the geometry dominates (a child's sub-boxes are
 * half its parent's). It vanishes on a box domain, with `scaled`, and in
 * every cell whose level set is planar (the interpolant is exact there).
 * The leaf's data one lattice finer depend only on its rest box and
 * material: the tissue keeps them per cut leaf (nh_tissue_set_geometry_cache)
 * and only the forces at u are evaluated here.
 *
 * Constraint data (docs/theory.md §6.6, "Constraint data"). The skull's
 * rows are a sampling of the surface that changes with the mesh, outside the
 * identity above. With δc_i the change of row i's gap at u when its leaf's
 * points are taken one lattice finer and δ(J w)_i that of its
 * linearisation applied to w (nh_contact_data_change, weights of the finer
 * points by area), the Lagrangian of the step gives, to first order,
 *     C_q = Σ_i ( Λ_i δ(J z_q)_i − μ_qi δc_i / c_K )
 * (Λ_i the row's force, μ_q the dual's multipliers of nh_dwr_duals): the
 * primal's force on the dual through the moved directions and the dual's
 * pressure on the coarse solution's gaps at the finer points. C_q is added
 * to E_q (not to the marking indicators). The tools' rows change by their
 * anchors' error (docs/theory.md §6.6, "Anchoring": contact/anchor.c, with
 * the front's error estimated by dwr_front.c).
 *
 * Held rows in the goal's cell (docs/theory.md §6.6; dwr_local.c). Where
 * an active tool row and a goal's box share a leaf, z_h is pinned to ≈ 0
 * there and its recovered error sees nothing; with out->local the dual is
 * solved again on a finer lattice over a patch around that leaf, z_h as
 * its boundary data, and the patch's residual weighted by z_f − z_h
 * replaces the patch leaves' recovered terms (the marking indicators are
 * not changed).
 *
 * The functionals j_pk are nodal loads of the rest geometry (the box mean
 * over the tissue, cut cells integrated): with out->functionals they are
 * kept between estimates (nh_goal_cache, keyed by key.c) and made again
 * only on a new mesh, points or radius; the same numbers either way.
 *
 * Fronts (dwr_front.c; docs/theory.md §6.6, "Anchoring"). At a step
 * whose tools' tips cut, each front's error comes from 3 functionals (its
 * tip rows' tissue parts) whose duals hold rows of their own
 * (nh_dwr_front_setup), solved with the goals' in one pass
 * (nh_system_solve_rows_sets: one solve of all columns, each set's
 * multipliers from its rows' block of W). With out->fronts they are
 * estimated in the same pass as the goals: their duals follow the goals'
 * through the centre samples, the recovery and the integrals, so the
 * primal's share (its corotation, recovered stress, e_u and D⁻¹ e_u at the
 * Gauss points, the geometry residual) is computed once per step. They
 * have no marking indicator and no local dual. Every dual's terms involve that dual and
 * the primal only (the recovery combines each field's values alone), so
 * the goals' estimates are the same numbers with or without fronts, and
 * each front's those of a pass of its own (nh_dwr_front_error), up to the
 * round-off of their shared solve.
 *
 * Workspace: the duals (3 per point and per front, 3 per node each), the
 * centre samples and recovered nodal stresses of the primal and the duals
 * (6 per cell or node and field), one value per leaf and dual for the
 * ordered sums. The cell
 * loop runs in parallel (OpenMP); sums are taken in leaf order afterwards,
 * so results do not depend on the thread count. */
#include "adapt/adapt_impl.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NH_DWR_PARALLEL_MIN 256

/* The rotated gradients of one point: (Rg)ₐ = R gₐ, a = 0..7 (nh_mat3_vec's
 * sums, inlined: 16 calls per leaf and point otherwise). */
static void nh_dwr_rotate_gradients(const double R[9], const double g[24], double Rg[24]) {
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      Rg[3 * a + i] =
          R[3 * i] * g[3 * a] + R[3 * i + 1] * g[3 * a + 1] + R[3 * i + 2] * g[3 * a + 2];
}

/* The tangent stresses of nq ≤ 8 increments w_q (duals z + n3 q, at the
 * cell's corners) at a point with rotated gradients Rg: the corotational
 * R (λ tr ε I + 2μ ε(Rᵀw)) Rᵀ of nh_hex_rotated_stress, formed without the
 * rotations, R (Rᵀwₐ ⊗ gₐ) Rᵀ = wₐ ⊗ R gₐ and C isotropic: σ = λ tr H I +
 * μ (H + Hᵀ), H = Σₐ wₐ ⊗ (R gₐ). B-bar (b not NULL): κ θ̄ I + 2μ dev ε,
 * θ̄(w) = Σₐ bₐ·wₐ. Vectorised over the duals, each sum in the scalar
 * formula's order; s + 6 stride q receives dual q's 6 components. */
NH_ADAPT_VECTOR_CLONES
static void nh_dwr_dual_stresses(const double *z, size_t n3, int nq, const int corner[8],
                                 const double Rg[24], double lambda, double mu, const double *b,
                                 double *s, size_t stride) {
  double w[24][8] = {{0}}, H[9][8] = {{0}}, tz[8] = {0};
  for (int q = 0; q < nq; q++)
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) w[3 * a + k][q] = z[n3 * q + 3 * (size_t)corner[a] + k];
  for (int i = 0; i < 24 && b; i++)
    for (int q = 0; q < 8; q++) tz[q] += b[i] * w[i][q];
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++)
      for (int j = 0; j < 3; j++)
        for (int q = 0; q < 8; q++) H[3 * i + j][q] += w[3 * a + i][q] * Rg[3 * a + j];
  double sq[6][8];
  for (int q = 0; q < 8; q++) {
    double tr = H[0][q] + H[4][q] + H[8][q];
    double vol = b ? (lambda + 2.0 * mu / 3.0) * tz[q] - 2.0 * mu / 3.0 * tr : lambda * tr;
    sq[0][q] = 2.0 * mu * H[0][q] + vol, sq[1][q] = 2.0 * mu * H[4][q] + vol;
    sq[2][q] = 2.0 * mu * H[8][q] + vol;
    sq[3][q] = mu * (H[5][q] + H[7][q]), sq[4][q] = mu * (H[2][q] + H[6][q]);
    sq[5][q] = mu * (H[1][q] + H[3][q]);
  }
  for (int q = 0; q < nq; q++)
    for (int k = 0; k < 6; k++) s[stride * q + k] = sq[k][q];
}

/* One dual's terms at the 8 Gauss points of a cell (four at a time, on
 * GCC's 4-double vectors: the compiler's own vectorisation of the 8-point
 * loops shuffled more than it computed, 2.2× the time): its tangent stress
 * σ_h(z) (as nh_dwr_dual_stresses, the rotated gradients by point last,
 * RgT[3a + j][gp] = (R g_a(gp))_j), its recovered stress σ*_z interpolated
 * from the nodal values zstar + stride × corner (NT[a][gp] = N_a(gp)),
 * e_z = σ*_z − σ_h(z), D⁻¹ e_z (nh_voigt_compliance) and the point
 * products a1 = e_zᵀ D⁻¹ e_u (ceuT[k][gp] = (D⁻¹ e_u)_k; B-bar:
 * − e_p,u (I − Π) div z − e_p,z (I − Π) div u, with RdivT, pu, dev_u) and
 * a2 = e_zᵀ D⁻¹ e_z, summed with the weights detJ in the points' order:
 * *eps = Σ detJ a1, *ezz = Σ detJ a2. B-bar when bbar, θ̄(z) = tz. Each
 * point's operations are the scalar formulas' in their order (no FMA), so
 * every clone computes the same bits. */
NH_ADAPT_V4_CLONES
void nh_dwr_dual_terms(const double we[24], const double RgT[24][8], const double RdivT[24][8],
                       const double *zstar, size_t stride, const int corner[8],
                       const double NT[8][8], double lambda, double mu, int bbar, double tz,
                       const double ceuT[6][8], const double pu[8], const double dev_u[8],
                       const double detJ[8], double *eps, double *ezz) {
  const nh_v4 zero = {0.0, 0.0, 0.0, 0.0};
  const double c = lambda / (3.0 * lambda + 2.0 * mu); /* nh_voigt_compliance's */
  const double m2 = 2.0 * mu, m23 = 2.0 * mu / 3.0;
  double p1[8], p2[8];
  for (int h = 0; h < 8; h += 4) { /* points h .. h + 3 */
    nh_v4 H[9], ss[6], dz = zero, x, y, w;
    for (int i = 0; i < 3; i++) { /* H = Σₐ wₐ ⊗ (R gₐ), each sum in a's order */
      nh_v4 h0 = zero, h1 = zero, h2 = zero;
      for (int a = 0; a < 8; a++) {
        const double wa = we[3 * a + i];
        NH_V4_LOAD(x, RgT[3 * a] + h), NH_V4_LOAD(y, RgT[3 * a + 1] + h);
        NH_V4_LOAD(w, RgT[3 * a + 2] + h);
        h0 += wa * x, h1 += wa * y, h2 += wa * w;
      }
      H[3 * i] = h0, H[3 * i + 1] = h1, H[3 * i + 2] = h2;
    }
    for (int i = 0; i < 24 && bbar; i++) NH_V4_LOAD(x, RdivT[i] + h), dz += we[i] * x;
    for (int i = 0; i < 6; i++) ss[i] = zero;
    for (int a = 0; a < 8; a++) {
      const double *sa = zstar + stride * (size_t)corner[a];
      NH_V4_LOAD(x, NT[a] + h);
      for (int i = 0; i < 6; i++) ss[i] += x * sa[i];
    }
    const nh_v4 tr = H[0] + H[4] + H[8];
    const nh_v4 vol = bbar ? (lambda + m23) * tz - m23 * tr : lambda * tr;
    nh_v4 ez[6];
    ez[0] = ss[0] - (m2 * H[0] + vol);
    ez[1] = ss[1] - (m2 * H[4] + vol);
    ez[2] = ss[2] - (m2 * H[8] + vol);
    ez[3] = ss[3] - mu * (H[5] + H[7]);
    ez[4] = ss[4] - mu * (H[2] + H[6]);
    ez[5] = ss[5] - mu * (H[1] + H[3]);
    const nh_v4 k = c * (ez[0] + ez[1] + ez[2]);
    nh_v4 a1 = zero, a2 = zero;
    for (int i = 0; i < 6; i++) {
      NH_V4_LOAD(x, ceuT[i] + h);
      a1 += ez[i] * x;
      a2 += ez[i] * (i < 3 ? (ez[i] - k) / m2 : ez[i] / mu);
    }
    if (bbar) { /* the mixed method's terms, header "B-bar" */
      const nh_v4 pz = (ez[0] + ez[1] + ez[2]) / 3.0;
      NH_V4_LOAD(x, pu + h), NH_V4_LOAD(y, dev_u + h);
      a1 -= x * dz + pz * y;
    }
    NH_V4_LOAD(x, detJ + h);
    a1 *= x, a2 *= x;
    memcpy(p1 + h, &a1, sizeof a1), memcpy(p2 + h, &a2, sizeof a2);
  }
  double s1 = 0.0, s2 = 0.0;
  for (int gp = 0; gp < 8; gp++) s1 += p1[gp], s2 += p2[gp];
  *eps = s1, *ezz = s2;
}

/* The element's material and, for B-bar, the derivative b of its mean volume
 * change at the state (bₐ = cof(F̄) ḡₐ, nh_hex_corot) and the change itself:
 * *gbar NULL for the full formulation. */
static void nh_dwr_cell_material(const nh_tissue *t, int c, const double ue[24], double *lambda,
                                 double *mu, const double **gbar, double b[24], double *theta) {
  nh_tissue_cell_material(t, c, lambda, mu, NULL);
  *gbar = nh_tissue_gbar(t, c);
  *theta = 0.0;
  if (!*gbar) return;
  double cof[9];
  *theta = nh_hex_mean_dilatation(ue, *gbar, cof);
  for (int a = 0; a < 8; a++) nh_mat3_vec(cof, *gbar + 3 * a, b + 3 * a);
}

/* (I − Π) div of corotated nodal values d at a point with gradients g:
 * Σₐ dₐ·(gₐ − ḡₐ), the divergence less its element mean. */
static double nh_dwr_divergence_rest(const double d[24], const double g[24],
                                     const double gbar[24]) {
  double s = 0.0;
  for (int i = 0; i < 24; i++) s += d[i] * (g[i] - gbar[i]);
  return s;
}

/* θ̄ of an increment w (a dual; we its values at the cell's corners): Σₐ bₐ·wₐ. */
static double nh_dwr_dilatation(const double we[24], const double b[24]) {
  double s = 0.0;
  for (int i = 0; i < 24; i++) s += b[i] * we[i];
  return s;
}

int nh_goal_functional(const nh_mesh *m, const double point[3], double radius, int k,
                       const char *where, double *j) {
  nh_region box = {.kind = NH_REGION_BOX};
  for (int i = 0; i < 3; i++) box.min[i] = point[i] - radius, box.max[i] = point[i] + radius;
  snprintf(box.where, sizeof box.where, "%s", where ? where : "goal");
  double unit[3] = {0, 0, 0};
  unit[k] = 1.0;
  memset(j, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  return nh_mesh_region_load(m, &box, unit, j);
}

int nh_goal_distance_functional(const nh_mesh *m, const double target[3], const double n[3],
                                double radius, const char *where, double *j) {
  const size_t n3 = 3 * (size_t)m->n_nodes;
  double *jk = nh_calloc(n3, sizeof(double));
  if (!jk) return NH_ERROR(NH_ERR_MEMORY, "out of memory: distance functional");
  int rc = NH_OK;
  memset(j, 0, sizeof(double) * n3);
  for (int k = 0; k < 3 && !rc; k++)
    if (!(rc = nh_goal_functional(m, target, radius, k, where, jk)))
      for (size_t i = 0; i < n3; i++) j[i] -= n[k] * jk[i];
  free(jk);
  return rc;
}

double nh_dwr_distance_estimate(const double E[3], const double target[3], const double tip[3]) {
  double d[3] = {tip[0] - target[0], tip[1] - target[1], tip[2] - target[2]};
  double len = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
  if (!(len > 0.0)) return sqrt(E[0] * E[0] + E[1] * E[1] + E[2] * E[2]);
  return -(d[0] * E[0] + d[1] * E[1] + d[2] * E[2]) / len;
}

void nh_dwr_active_rows(const nh_rows *rows, unsigned char *active) {
  for (int i = 0; i < rows->m; i++) {
    const nh_row_law *law = rows->law + i;
    active[i] = law->kind == NH_ROW_BILATERAL ||
                (law->kind == NH_ROW_UNILATERAL && rows->lambda[i] > 0.0) ||
                (law->kind == NH_ROW_FRICTION && !law->sliding);
  }
}

/* The constraint-data term of the nd duals z (header "Constraint data"),
 *   C_q = Σ_i (Λ_i δ(J z_q)_i − μ_qi δc_i / c_K),
 * μ the duals' multipliers (rows->m each, 0 on the rows a dual dropped;
 * followed by as much workspace), added to E[q] and, for the first nz,
 * stored in out->constraint (if not NULL), the tools' rows' part (their
 * anchors' errors) also in out->inherited (if not NULL). */
static int nh_dwr_constraint_term(const nh_rows *rows, const double *z, double *mu,
                                  const nh_constraint_data *data, double scale, int nd, int nz,
                                  double *E, nh_dwr_result *out) {
  const int m = rows->m;
  double *dz = mu + (size_t)m * nd;
  int rc = data->linear(data->ctx, nd, z, dz);
  if (rc) return NH_ERROR(rc, "goal estimate: the constraints' finer data failed");
  for (int q = 0; q < nd; q++) {
    double s[2] = {0.0, 0.0}; /* the skull's and ties' rows; the tools' (inherited) */
    for (int i = 0; i < m; i++)
      s[rows->tool[i] >= 0] +=
          data->force[i] * dz[(size_t)m * q + i] - mu[(size_t)m * q + i] * data->change[i] / scale;
    E[q] += s[0] + s[1];
    if (q < nz && out->constraint) out->constraint[q] = s[0] + s[1];
    if (q < nz && out->inherited) out->inherited[q] = s[1];
  }
  return NH_OK;
}

/* The duals of n_sets sets of functionals, set k ncol[k] of them at j[k]
 * (3 n_nodes each) with the rows active[k] (NULL: every row), in one solve
 * (nh_system_solve_rows_sets): z and mu of all of them, set after set;
 * otherwise as nh_dwr_duals. */
static int nh_dwr_duals_sets(nh_system *sys, const nh_rows *rows, double scale, int n_nodes,
                             int n_sets, const int *ncol, const unsigned char *const *active,
                             const double *const *j, double *z, double *mu, int *n_rows) {
  const int nf = nh_system_free_dofs(sys);
  int n = 0;
  for (int k = 0; k < n_sets; k++) n += ncol[k];
  if (n_rows) *n_rows = 0;
  NH_CHECK(nh_system_constraint_rows(sys) == 0, NH_ERR_INPUT,
           "the goal-oriented estimate needs hanging nodes eliminated (adapt.hanging: eliminate)");
  double *b = nh_calloc((size_t)nf * (size_t)(n ? n : 1), sizeof(double));
  double *x = nh_calloc((size_t)nf * (size_t)(n ? n : 1), sizeof(double));
  int rc = b && x ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: %d dual problems", n);
  for (int k = 0, q = 0; k < n_sets && !rc; k++)
    for (int i = 0; i < ncol[k]; i++, q++) {
      double *bq = b + (size_t)nf * q;
      nh_system_gather(sys, j[k] + 3 * (size_t)n_nodes * i, bq);
      for (int r = 0; r < nf; r++) bq[r] *= scale;
    }
  if (!rc) {
    const int with_rows = rows && rows->m > 0;
    rc = nh_system_solve_rows_sets(sys, with_rows ? rows : NULL, n_sets, ncol, active, b, x, mu,
                                   n_rows);
  }
  for (int q = 0; q < n && !rc; q++)
    nh_system_scatter(sys, x + (size_t)nf * q, z + 3 * (size_t)n_nodes * q);
  free(b);
  free(x);
  return rc;
}

/* The goals' nz duals with the active rows (nh_dwr_active_rows), the
 * fronts' (3 each, their own rows: nh_dwr_front_setup) and the shaft
 * points' (1 each, one set: nh_dwr_points_setup; fronts may be NULL) in
 * one solve: z and mu for nz + 3 n_fronts + n_points duals. */
static int nh_dwr_all_duals(nh_system *sys, const nh_rows *rows, double scale, int n_nodes, int nz,
                            const double *j, const nh_dwr_fronts *fronts, double *z, double *mu,
                            int *n_rows) {
  const int nfr = fronts ? fronts->n : 0, npt = fronts ? fronts->n_points : 0;
  const int mr = rows ? rows->m : 0, ns = 1 + nfr + (npt > 0);
  const size_t n3 = 3 * (size_t)n_nodes;
  /* the fronts' functionals, then the points' */
  double *jf = nh_calloc(n3 * (size_t)(3 * nfr + npt + 1), sizeof(double));
  unsigned char *act = nh_calloc((size_t)ns * (size_t)(mr ? mr : 1), 1);
  const unsigned char **sets = nh_calloc((size_t)ns, sizeof *sets);
  const double **js = nh_calloc((size_t)ns, sizeof *js);
  int *ncol = nh_calloc((size_t)ns, sizeof(int));
  int rc = jf && act && sets && js && ncol
               ? NH_OK
               : NH_ERROR(NH_ERR_MEMORY, "out of memory: %d dual problems", nz + 3 * nfr + npt);
  if (!rc) {
    ncol[0] = nz, js[0] = j;
    if (mr) nh_dwr_active_rows(rows, act), sets[0] = act;
  }
  for (int f = 0; f < nfr && !rc; f++) {
    ncol[1 + f] = 3, js[1 + f] = jf + 3 * n3 * (size_t)f;
    sets[1 + f] = mr ? act + (size_t)mr * (1 + f) : NULL;
    rc = nh_dwr_front_setup(rows, n_nodes, fronts->row[f], jf + 3 * n3 * (size_t)f,
                            act + (size_t)mr * (1 + f));
  }
  if (npt > 0 && !rc) {
    const int s = 1 + nfr;
    ncol[s] = npt, js[s] = jf + 3 * n3 * (size_t)nfr;
    sets[s] = mr ? act + (size_t)mr * s : NULL;
    rc = nh_dwr_points_setup(rows, n_nodes, npt, fronts->point_row, jf + 3 * n3 * (size_t)nfr,
                             act + (size_t)mr * s);
  }
  if (!rc) rc = nh_dwr_duals_sets(sys, rows, scale, n_nodes, ns, ncol, sets, js, z, mu, n_rows);
  free(jf), free(act), free(sets), free(js), free(ncol);
  return rc;
}

int nh_dwr_duals(nh_system *sys, const nh_rows *rows, double scale, int n_nodes, int n,
                 const double *j, double *z, double *mu, int *n_rows) {
  return nh_dwr_all_duals(sys, rows, scale, n_nodes, n, j, NULL, z, mu, n_rows);
}

/* The estimates E_q of nz functionals j (3 n_nodes each) and, for each group
 * of `group` consecutive functionals, the marking indicator
 * ‖e*_u‖_K (Σ_{q in group} ‖e*_{z_q}‖²_K)^½ (out->indicator, n_cells per
 * group); out->estimate receives the nz E_q, out->norm is not touched; with
 * out->fronts, the fronts' errors in the same pass (header "Fronts"). */
int nh_dwr_functionals(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *m,
                       const nh_tissue *t, const nh_hanging *h, const double *u, int nz, int group,
                       const double *j, const nh_dwr_goals *goals, nh_dwr_result *out) {
  const int n_fronts = out->fronts ? out->fronts->n : 0;
  const int n_points = out->fronts ? out->fronts->n_points : 0;
  const int nn = m->n_nodes, nl = m->n_leaves, ng = nz / group, mr = rows ? rows->m : 0;
  const size_t n3 = 3 * (size_t)nn;
  /* the memory term's links (dwr_memory.c): their duals first */
  int n_links = 0;
  double *z_links = NULL, *mu_links = NULL;
  out->memory_links = 0;
  if (out->memory && nz > 0) {
    int rc = nh_dwr_memory_duals(sys, rows, scale, nn, nz, j, out->memory, &n_links, &z_links,
                                 &mu_links);
    if (rc) return rc;
  }
  /* the duals: the nz functionals', 3 per front, 1 per shaft point, then
   * nz per link of the memory term */
  const int nd0 = nz + 3 * n_fronts + n_points, nd = nd0 + nz * n_links, nfld = 1 + nd;
  double *z = nh_calloc(n3 * (size_t)(nd ? nd : 1), sizeof(double));
  double *samples =
      nh_calloc(6 * (size_t)nfld * (size_t)(m->n_cells ? m->n_cells : 1), sizeof(double));
  double *star = nh_calloc(6 * (size_t)nfld * (size_t)(nn ? nn : 1), sizeof(double));
  double *cell_eps = nh_calloc((size_t)(nd ? nd : 1) * (size_t)(nl ? nl : 1), sizeof(double));
  double *cell_err2 = nh_calloc((size_t)(nl ? nl : 1), sizeof(double));
  double *cell_norm2 = nh_calloc((size_t)(nl ? nl : 1), sizeof(double));
  double *cell_geo = NULL;        /* nd per leaf: the geometry term (header "Geometry") */
  double *mu = NULL;              /* the duals' multipliers (header "Constraint data") */
  unsigned char *replaced = NULL; /* per leaf: its term replaced by the local dual's */
  double *cell_loc = nh_calloc((size_t)(nz ? nz : 1), sizeof(double)), *free_mask = NULL;
  double *E = nh_calloc((size_t)(nd ? nd : 1), sizeof(double)); /* every dual's estimate */
  int rc = NH_OK;
  if (!z || !samples || !star || !cell_eps || !cell_err2 || !cell_norm2 || !cell_loc || !E) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: goal-oriented estimate (%d duals, %d nodes)", nd,
                  nn);
    goto done;
  }
  const int with_data = out->data && mr > 0;
  if (with_data && !(mu = nh_calloc(2 * (size_t)mr * (size_t)nd, sizeof(double)))) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the duals' multipliers (%d rows)", rows->m);
    goto done;
  }
  out->n_rows = 0;
  /* the goals' duals, and each front's holding its own rows (dwr_front.c) */
  if (nd > 0) {
    rc = nh_dwr_all_duals(sys, rows, scale, nn, nz, j, out->fronts, z, mu, &out->n_rows);
    if (rc) goto done;
  }
  if (n_links > 0) {
    memcpy(z + n3 * nd0, z_links, sizeof(double) * n3 * (size_t)nz * n_links);
    if (mu) memcpy(mu + (size_t)mr * nd0, mu_links, sizeof(double) * mr * (size_t)nz * n_links);
  }

  /* Centre samples: the primal's corotational stress, each dual's tangent stress. */
#pragma omp parallel for schedule(static) if (nl >= NH_DWR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    double Xe[24], ue[24], R[9], d[24], lambda, mu, b[24], theta;
    const double *G0 = t->G0 + 24 * t->cell_shape[c], *gbar;
    double *s = samples + 6 * (size_t)nfld * c;
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    nh_hex_corotated(Xe, ue, G0, R, d);
    nh_dwr_cell_material(t, c, ue, &lambda, &mu, &gbar, b, &theta);
    nh_hex_rotated_stress(R, d, G0, lambda, mu, gbar ? &theta : NULL, s);
    double RG0[24];
    nh_dwr_rotate_gradients(R, G0, RG0);
    for (int q = 0; q < nd; q += 8)
      nh_dwr_dual_stresses(z + n3 * q, n3, nd - q < 8 ? nd - q : 8, m->cells + 8 * c, RG0, lambda,
                           mu, gbar ? b : NULL, s + 6 * (1 + (size_t)q), 6);
  }
  if ((rc = nh_spr_recover_fields(m, t, h, nfld, samples, star))) goto done;

  static const double gq = 0.57735026918962576451; /* 1/√3 */
  double xi[24], N[8][8], NT[8][8];
  for (int g = 0; g < 8; g++) {
    for (int k = 0; k < 3; k++) xi[3 * g + k] = gq * nh_hex_corner[g][k];
    nh_hex_shape(xi + 3 * g, N[g]);
  }
  for (int g = 0; g < 8; g++)
    for (int a = 0; a < 8; a++) NT[a][g] = N[g][a];
  for (int c = 0; c < m->n_cells && out->indicator; c++)
    for (int p = 0; p < ng; p++) out->indicator[(size_t)m->n_cells * p + c] = 0.0;
  int bad_cell = -1, geo_rc = 0;
  cell_geo = t->n_cut ? nh_calloc((size_t)nd * (size_t)(nl ? nl : 1), sizeof(double)) : NULL;
  if (t->n_cut && !cell_geo) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the goal estimate's geometry term");
    goto done;
  }
#pragma omp parallel for schedule(static) if (nl >= NH_DWR_PARALLEL_MIN)
  for (int l = 0; l < nl; l++) {
    int c = m->leaves[l];
    const int *corner = m->cells + 8 * c;
    const double *G0 = t->G0 + 24 * t->cell_shape[c];
    double Xe[24], ue[24], R[9], d[24], g[8][24], Rg[8][24], Rdiv[8][24], detJ[8], eu[48], ceu[48];
    double lambda, mu, b[24], theta;
    const double *gbar;
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_mesh_cell_coords(m, u, c, ue);
    nh_hex_corotated(Xe, ue, G0, R, d);
    nh_dwr_cell_material(t, c, ue, &lambda, &mu, &gbar, b, &theta);
    double e2 = 0.0, n2 = 0.0, dev_u[8] = {0};
    for (int gp = 0; gp < 8; gp++) {
      memcpy(g[gp], G0, sizeof g[gp]);
      detJ[gp] = nh_hex_gradients(Xe, xi + 3 * gp, g[gp]);
      nh_dwr_rotate_gradients(R, g[gp], Rg[gp]);
      if (gbar) {
        dev_u[gp] = nh_dwr_divergence_rest(d, g[gp], gbar);
        double gd[24]; /* (I − Π) div w = Σₐ wₐ·R(gₐ − ḡₐ) for a dual w (Rᵀw corotated) */
        for (int i = 0; i < 24; i++) gd[i] = g[gp][i] - gbar[i];
        nh_dwr_rotate_gradients(R, gd, Rdiv[gp]);
      }
      if (!(detJ[gp] > 0.0)) {
#pragma omp atomic write
        bad_cell = c;
      }
      double su[6];
      nh_hex_rotated_stress(R, d, g[gp], lambda, mu, gbar ? &theta : NULL, su);
      for (int k = 0; k < 6; k++) {
        double s = 0.0;
        for (int a = 0; a < 8; a++) s += N[gp][a] * star[6 * ((size_t)nfld * corner[a]) + k];
        eu[6 * gp + k] = s - su[k];
      }
      nh_voigt_compliance(lambda, mu, eu + 6 * gp, ceu + 6 * gp);
      double e[6], de = 0.0, dn = 0.0;
      nh_voigt_compliance(lambda, mu, su, e);
      for (int k = 0; k < 6; k++) de += eu[6 * gp + k] * ceu[6 * gp + k], dn += su[k] * e[k];
      e2 += detJ[gp] * de;
      n2 += detJ[gp] * dn;
    }
    cell_err2[l] = m->fill[c] * e2;
    cell_norm2[l] = m->fill[c] * n2;
    double rg[24];
    int cut = cell_geo ? nh_tissue_geometry_residual(t, c, u, out->loads, rg) : 0;
    if (cut < 0) {
#pragma omp atomic write
      geo_rc = -cut;
      cut = 0;
    }
    for (int q = 0; q < nd && cut; q++) {
      double s = 0.0;
      for (int a = 0; a < 8; a++)
        for (int k = 0; k < 3; k++) s += z[n3 * q + 3 * (size_t)corner[a] + k] * rg[3 * a + k];
      cell_geo[(size_t)nd * l + q] = 4.0 / 3.0 * s;
    }
    /* Rg, Rdiv and D⁻¹ e_u by point last (the 8 points' terms in one
     * pass), the recovered pressure errors of u (B-bar) */
    double RgT[24][8], RdivT[24][8], pu[8], ceuT[6][8];
    for (int gp = 0; gp < 8; gp++) {
      for (int i = 0; i < 24; i++) RgT[i][gp] = Rg[gp][i], RdivT[i][gp] = gbar ? Rdiv[gp][i] : 0.0;
      for (int i = 0; i < 6; i++) ceuT[i][gp] = ceu[6 * gp + i];
      pu[gp] = (eu[6 * gp] + eu[6 * gp + 1] + eu[6 * gp + 2]) / 3.0;
    }
    double zn2 = 0.0, gn2 = 0.0; /* the group's sums for its marking indicator */
    for (int q = 0; q < nd; q++) {
      double ze[24], eps, ezz;
      nh_mesh_cell_coords(m, z + n3 * q, c, ze);
      double tz = gbar ? nh_dwr_dilatation(ze, b) : 0.0;
      nh_dwr_dual_terms(ze, RgT, RdivT, star + 6 * (1 + (size_t)q), 6 * (size_t)nfld, corner, NT,
                        lambda, mu, gbar != NULL, tz, ceuT, pu, dev_u, detJ, &eps, &ezz);
      cell_eps[(size_t)nd * l + q] = m->fill[c] * eps;
      if (q >= nz) continue; /* the fronts' duals do not mark */
      zn2 += m->fill[c] * ezz;
      if (cut) gn2 += cell_geo[(size_t)nd * l + q] * cell_geo[(size_t)nd * l + q];
      if ((q + 1) % group) continue;
      if (out->indicator)
        out->indicator[(size_t)m->n_cells * (q / group) + c] =
            sqrt(fmax(cell_err2[l], 0.0) * fmax(zn2, 0.0)) + sqrt(gn2);
      zn2 = gn2 = 0.0;
    }
  }
  if (geo_rc) {
    rc = NH_ERROR(geo_rc, "goal estimate: the geometry term's cut-cell quadrature failed");
    goto done;
  }
  if (bad_cell >= 0) {
    rc = NH_ERROR(NH_ERR_INTERNAL, "goal estimate: leaf %d has a non-positive Jacobian", bad_cell);
    goto done;
  }
  double sum_err = 0.0, sum_norm = 0.0;
  for (int q = 0; q < nz; q++) {
    if (out->geometry) out->geometry[q] = 0.0;
    if (out->constraint) out->constraint[q] = 0.0;
    if (out->inherited) out->inherited[q] = 0.0;
  }
  if (with_data && (rc = nh_dwr_constraint_term(rows, z, mu, out->data, scale, nd, nz, E, out)))
    goto done;
  /* where a goal's cell holds tool rows: the local enriched dual's term in
   * place of the patch's recovered terms (dwr_local.c) */
  out->local_applied = 0;
  if (out->local && (replaced = nh_calloc((size_t)(nl ? nl : 1), 1)) == NULL) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the local dual's leaves");
    goto done;
  }
  if (out->local && rows && rows->m > 0) { /* the free DOFs as a nodal mask */
    const int nf = nh_system_free_dofs(sys);
    double *ones = nh_calloc((size_t)(nf ? nf : 1), sizeof(double));
    if (!ones || !(free_mask = nh_calloc(n3, sizeof(double)))) {
      free(ones);
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: the local dual's mask");
      goto done;
    }
    for (int i = 0; i < nf; i++) ones[i] = 1.0;
    nh_system_scatter(sys, ones, free_mask);
    free(ones);
  }
  if (out->local &&
      (rc = nh_dwr_local_term(m, t, h, u, rows, out->data ? out->data->force : NULL, free_mask, nz,
                              z, goals->n_points, goals->points, goals->radius, goals->weights,
                              out->loads, cell_loc, replaced, &out->local_applied)))
    goto done;
  for (int q = 0; q < nd; q++) { /* the fronts' duals have no local term: 0 */
    double loc = q < nz && out->local_applied ? cell_loc[q] : 0.0;
    E[q] += loc;
    if (q < nz && out->local_term) out->local_term[q] = loc;
  }
  for (int l = 0; l < nl; l++) {
    sum_err += cell_err2[l];
    sum_norm += cell_norm2[l];
    if (out->eta_cell) out->eta_cell[m->leaves[l]] = sqrt(fmax(cell_err2[l], 0.0));
    const int local = out->local_applied && replaced[l];
    for (int q = 0; q < nd; q++) {
      double g = cell_geo ? cell_geo[(size_t)nd * l + q] : 0.0;
      E[q] += (q < nz && local ? 0.0 : cell_eps[(size_t)nd * l + q]) + g;
      if (q < nz && out->geometry) out->geometry[q] += g;
    }
  }
  for (int q = 0; q < nd; q++)
    if (!isfinite(E[q])) {
      rc = NH_ERROR(NH_ERR_NUMERIC, "goal estimate of %s %d is not finite",
                    q < nz    ? "functional"
                    : q < nd0 ? "front or shaft point functional"
                              : "memory link functional",
                    q < nz    ? q
                    : q < nd0 ? q - nz
                              : q - nd0);
      goto done;
    }
  /* the shaft points' axial errors are their rows' data from this step on
   * (dwr_front.c, "Shaft points"): δc = −E_p on the axial row, which the
   * goals' duals hold, its data 0 until now (the points' own duals leave it
   * free, so their E_p do not depend on it) */
  for (int p = 0; with_data && p < n_points; p++) {
    const int r = out->fronts->point_row[p] + 2;
    const double dc = -E[nz + 3 * n_fronts + p];
    for (int i = 0; i < nz * (1 + n_links); i++) { /* the goals and the links */
      const int q = i < nz ? i : nd0 + i - nz;
      const double c = -mu[(size_t)mr * q + r] * dc / scale;
      E[q] += c;
      if (q >= nz) continue;
      if (out->constraint) out->constraint[q] += c;
      if (out->inherited) out->inherited[q] += c;
    }
  }
  if (nz > 0) memcpy(out->estimate, E, sizeof(double) * (size_t)nz);
  if (out->memory_own && nz > 0) { /* link 0, the goals; then links 1 … n_links */
    memcpy(out->memory_own, E, sizeof(double) * (size_t)nz);
    memcpy(out->memory_own + nz, E + nd0, sizeof(double) * (size_t)nz * n_links);
    out->memory_links = n_links;
  }
  for (int f = 0; f < n_fronts; f++)
    nh_dwr_front_vector(rows, out->fronts->row[f], E + nz + 3 * f, out->fronts->error + 3 * f);
  for (int p = 0; p < n_points; p++) out->fronts->point_error[p] = E[nz + 3 * n_fronts + p];
  if (!isfinite(sum_err) || !isfinite(sum_norm)) {
    rc =
        NH_ERROR(NH_ERR_NUMERIC, "SPR: the error estimate is not finite (eta^2 = %g, |u|_E^2 = %g)",
                 sum_err, sum_norm);
    goto done;
  }
  out->eta = sqrt(sum_err);
  out->eta_rel = sum_err + sum_norm > 0.0 ? sqrt(sum_err / (sum_norm + sum_err)) : 0.0;

done:
  free(z), free(samples), free(star), free(cell_eps), free(cell_err2), free(cell_norm2);
  free(cell_geo), free(mu), free(replaced), free(cell_loc), free(free_mask), free(E);
  free(z_links), free(mu_links);
  return rc;
}

/* The cached functionals (adapt.h): j_pk at j + 3 n_nodes (3p + k), for the
 * mesh of key (fill per leaf, no hanging table: the functionals are nodal
 * loads of the corners) and these points and radius. */
struct nh_goal_cache {
  int builds;
  nh_mesh_key key;
  int n_points;
  double radius;
  double *points, *j; /* 3 n_points; 9 n_points n_nodes */
};

int nh_goal_cache_create(nh_goal_cache **out) {
  *out = nh_calloc(1, sizeof **out);
  return *out ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: goal functionals' cache");
}

void nh_goal_cache_destroy(nh_goal_cache **cache) {
  if (!cache || !*cache) return;
  nh_mesh_key_free(&(*cache)->key);
  free((*cache)->points), free((*cache)->j);
  free(*cache);
  *cache = NULL;
}

int nh_goal_cache_builds(const nh_goal_cache *cache) {
  return cache ? cache->builds : 0;
}

/* The point functionals j_pk (3 per point) of the goals into j. */
static int nh_dwr_point_functionals(const nh_mesh *m, int n_points, const double *points,
                                    double radius, char (*where)[NH_WHERE_MAX], double *j) {
  const size_t n3 = 3 * (size_t)m->n_nodes;
  for (int p = 0; p < n_points; p++) {
    /* the 3 components' loads are the same box integrals (1 · φ w_a / |B ∩ Ω|
     * on component k, 0 · … = +0 on the others): integrated once, for k = 0 */
    double *jx = j + n3 * (size_t)(3 * p);
    NH_TRY(nh_goal_functional(m, points + 3 * p, radius, 0, where ? where[p] : NULL, jx));
    for (int k = 1; k < 3; k++) {
      double *jk = j + n3 * (size_t)(3 * p + k);
      memset(jk, 0, n3 * sizeof(double));
      for (size_t v = 0; v < n3; v += 3) jk[v + k] = jx[v];
    }
  }
  return NH_OK;
}

/* *j = the goals' functionals: the cache's (made first if they are not
 * this mesh's, points' and radius'), or, cache NULL, made into *fresh
 * (allocated here; the caller frees it). */
static int nh_dwr_functionals_of(nh_goal_cache *cache, const nh_mesh *m, int n_points,
                                 const double *points, double radius, char (*where)[NH_WHERE_MAX],
                                 double **fresh, const double **j) {
  const size_t n = 9 * (size_t)n_points * (size_t)m->n_nodes;
  *fresh = NULL, *j = NULL;
  if (!cache) {
    if (!(*fresh = nh_calloc(n ? n : 1, sizeof(double))))
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: %d goal functionals", 3 * n_points);
    NH_TRY(nh_dwr_point_functionals(m, n_points, points, radius, where, *fresh));
    *j = *fresh;
    return NH_OK;
  }
  if (!(nh_mesh_key_matches(&cache->key, m, m->fill, NULL) && cache->n_points == n_points &&
        !memcmp(&cache->radius, &radius, sizeof radius) &&
        !memcmp(cache->points, points, 3 * sizeof(double) * (size_t)n_points))) {
    cache->key.valid = 0;
    NH_TRY(nh_realloc((void **)&cache->j, n + 1, sizeof(double)));
    NH_TRY(nh_realloc((void **)&cache->points, 3 * (size_t)n_points + 1, sizeof(double)));
    NH_TRY(nh_dwr_point_functionals(m, n_points, points, radius, where, cache->j));
    memcpy(cache->points, points, 3 * sizeof(double) * (size_t)n_points);
    cache->n_points = n_points, cache->radius = radius;
    NH_TRY(nh_mesh_key_set(&cache->key, m, m->fill, NULL));
    cache->builds++;
  }
  *j = cache->j;
  return NH_OK;
}

int nh_dwr_estimate(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *m,
                    const nh_tissue *t, const nh_hanging *h, const double *u, int n_points,
                    const double *points, double radius, char (*where)[NH_WHERE_MAX],
                    nh_dwr_result *out) {
  const int nz = 3 * n_points;
  double *fresh = NULL;
  const double *j = NULL;
  double *w = nh_calloc((size_t)nz * (size_t)(nz ? nz : 1), sizeof(double));
  int rc =
      w ? nh_dwr_functionals_of(out->functionals, m, n_points, points, radius, where, &fresh, &j)
        : NH_ERROR(NH_ERR_MEMORY, "out of memory: %d goal functionals", nz);
  for (int q = 0; q < nz && !rc; q++) w[(size_t)nz * q + q] = 1.0; /* functional q is J_q */
  nh_dwr_goals goals = {n_points, points, radius, w};
  if (!rc) rc = nh_dwr_functionals(sys, rows, scale, m, t, h, u, nz, 3, j, &goals, out);
  free(w);
  for (int p = 0; p < n_points && !rc; p++) {
    const double *e = out->estimate + 3 * p;
    out->norm[p] = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
  }
  free(fresh);
  return rc;
}

int nh_dwr_estimate_combined(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *m,
                             const nh_tissue *t, const nh_hanging *h, const double *u, int n_points,
                             const double *points, double radius, char (*where)[NH_WHERE_MAX],
                             const double *weights, nh_dwr_result *out) {
  const size_t n3 = 3 * (size_t)m->n_nodes;
  double *fresh = NULL, *jc = nh_calloc(n3, sizeof(double));
  const double *j = NULL;
  int rc =
      jc ? nh_dwr_functionals_of(out->functionals, m, n_points, points, radius, where, &fresh, &j)
         : NH_ERROR(NH_ERR_MEMORY, "out of memory: combined goal functional");
  for (int p = 0; p < n_points && !rc; p++)
    for (int k = 0; k < 3; k++) {
      const double w = weights[3 * p + k], *jk = j + n3 * (size_t)(3 * p + k);
      if (w == 0.0) continue;
      for (size_t i = 0; i < n3; i++) jc[i] += w * jk[i];
    }
  nh_dwr_goals goals = {n_points, points, radius, weights};
  if (!rc) rc = nh_dwr_functionals(sys, rows, scale, m, t, h, u, 1, 1, jc, &goals, out);
  if (!rc && out->norm) out->norm[0] = fabs(out->estimate[0]);
  free(fresh), free(jc);
  return rc;
}
