/* dwr_memory.c — the error a dynamic step inherits from the steps before
 * it: the goal estimate's memory term (docs/theory.md §6.6, "Memory";
 * Eriksson, Estep, Hansbo & Johnson, "Introduction to adaptive methods
 * for differential equations", Acta Numerica 1995, for the dual carried
 * back through the time steps).
 *
 * The dynamic step (solve/step.c, backward Euler with mass and stiffness
 * damping α, β) is, for the velocity at its end,
 *     A v⁺ = M v + h (f − K u),  u⁺ = u + h v⁺,  A = (1 + hα) M + (hβ + h²) K.
 * The errors of the data u, v (those of the earlier steps) reach the step's
 * error through M and K: with r the step's own residual,
 *     A e_v⁺ = r + M e_v − h K e_u,  e_u⁺ = e_u + h e_v⁺.
 * A functional S(e) = aᵀ e_u + bᵀ e_v of the step's error is then, with
 * the dual A z + Jᵀμ = h a + b, J z = 0 (the rows the goal's dual holds:
 * dwr.c, "Constraints"; a row active at the step holds its position, so
 * J e_u⁺ = 0 and J e_v⁺ = −J e_u / h),
 *     S(e⁺) = zᵀ r + aᵀ e_u − h (K z)ᵀ e_u − μᵀ J e_u / h + (M z)ᵀ e_v,
 * the step's own error, which the goal machinery estimates for the
 * functional a + b/h (its dual is z), plus a functional S' of the previous
 * step's error with
 *     a' = a − h K z − Jᵀμ / h,  b' = M z.
 * Starting from the goal (a, b) = (j, 0), the links S_0 = J, S_1, S_2, …
 * give J(e_u at step n) = Σ_m own_m(step n − m): each link's own error
 * at the step m steps back. The links' duals are computed here, by
 * K = (A − (1 + hα) M) / (hβ + h²) from products with the assembled A
 * (no stiffness matrix of its own), each link's dual from the one
 * before; the goal machinery estimates their own errors in the same pass
 * as the goals (nh_dwr_functionals), and adapt/refine.c carries the links'
 * values from estimate to estimate,
 *     S_m(e⁺) = own_m + S_{m+1}(e),
 * a forward recursion over scalars: the links are the same functionals at
 * every step while A is (a mesh, a step size), so the dual carried back is
 * never solved backwards and no earlier residual is kept.
 *
 * Scaling. The code's duals solve A z = c_K Pᵀ j (c_K = hβ + h², dwr.c);
 * with α_m = c_K a_m and β_m = c_K b_m / h (free-DOF vectors) link m's
 * right-hand side r_m = α_m + β_m, A z_m + Jᵀμ_m = r_m, and
 *     α_{m+1} = α_m − h (A z_m − (1 + hα) M z_m) / (β + h) − Jᵀμ_m,
 *     β_{m+1} = M z_m,
 * with Jᵀμ_m = r_m − A z_m (for β = 0: α_{m+1} = (1 + hα) M z_m − β_m).
 * The held rows' compliance is formed once for all links (nh_rows_solver).
 *
 * The links stop when two in a row have a dual energy (z_mᵀ A z_m)^½ below
 * NH_MEMORY_TOLERANCE of the goal's own, for every goal, or at
 * mem->max_links: for an oscillator of frequency ω the links decay by
 * (1 + hα + (hβ + h²) ω²)^(−½) per step, the memory of the scheme itself
 * (0.78 for the DBS brain's sag, ω² ≈ 180 s⁻², at h = 0.05 s). A quasi-
 * static step has no memory (no link). */
#include "adapt/adapt_impl.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NH_MEMORY_TOLERANCE 0.01

/* y = M x for free-DOF vectors (the lumped mass through the full nodal
 * vector: Pᵀ M P x, as A's mass part), full a workspace of 3 n_nodes. */
static void nh_memory_mass(nh_system *sys, const double *mass, int n_nodes, const double *x,
                           double *full, double *y) {
  nh_system_scatter(sys, x, full);
  for (size_t i = 0; i < 3 * (size_t)n_nodes; i++) full[i] *= mass[i / 3];
  nh_system_gather(sys, full, y);
}

int nh_dwr_memory_duals(nh_system *sys, const nh_rows *rows, double scale, int n_nodes, int nz,
                        const double *j, const nh_dwr_memory *mem, int *n_links, double **z_links,
                        double **mu_links) {
  *n_links = 0, *z_links = NULL, *mu_links = NULL;
  const int nf = nh_system_free_dofs(sys), mr = rows ? rows->m : 0;
  const size_t n3 = 3 * (size_t)n_nodes, nfz = (size_t)nf * (size_t)nz;
  const double h = mem->h, cz = h / (mem->beta + h), cm = 1.0 + h * mem->alpha;
  if (nz == 0 || mem->max_links <= 0) return NH_OK;
  double *a = nh_calloc(nfz, sizeof(double)), *r = nh_calloc(nfz, sizeof(double));
  double *z = nh_calloc(nfz, sizeof(double)), *Az = nh_calloc((size_t)nf + 1, sizeof(double));
  double *Mz = nh_calloc((size_t)nf + 1, sizeof(double)), *full = nh_calloc(n3, sizeof(double));
  double *e0 = nh_calloc((size_t)nz, sizeof(double));
  double *mu = mr ? nh_calloc((size_t)mr * (size_t)nz, sizeof(double)) : NULL;
  unsigned char *active = mr ? nh_calloc((size_t)mr, 1) : NULL;
  int rc =
      a && r && z && Az && Mz && full && e0 && (!mr || (mu && active))
          ? NH_OK
          : NH_ERROR(NH_ERR_MEMORY, "out of memory: the memory term's duals (%d nodes)", n_nodes);
  if (mr && !rc) nh_dwr_active_rows(rows, active);
  nh_rows_solver *rs = NULL; /* the held rows' compliance, once for every link */
  if (!rc) rc = nh_rows_solver_create(sys, mr ? rows : NULL, active, &rs);
  for (int q = 0; q < nz && !rc; q++) { /* link 0: the goals, α_0 = c_K Pᵀ j, β_0 = 0 */
    nh_system_gather(sys, j + n3 * q, a + (size_t)nf * q);
    for (int i = 0; i < nf; i++) a[(size_t)nf * q + i] *= scale;
  }
  if (!rc) memcpy(r, a, nfz * sizeof(double));
  int small = 0;
  for (int m = 0; m <= mem->max_links && !rc; m++) {
    rc = nh_rows_solver_solve(sys, rs, nz, r, z, mu);
    if (rc) break;
    int all_small = 1;
    for (int q = 0; q < nz; q++) { /* the dual's energy, then the next link's α, β */
      double *zq = z + (size_t)nf * q, *aq = a + (size_t)nf * q, *rq = r + (size_t)nf * q;
      nh_system_apply(sys, zq, Az);
      nh_memory_mass(sys, mem->mass, n_nodes, zq, full, Mz);
      double e = 0.0;
      for (int i = 0; i < nf; i++) e += zq[i] * Az[i];
      if (m == 0) e0[q] = e;
      if (!(e <= NH_MEMORY_TOLERANCE * NH_MEMORY_TOLERANCE * e0[q])) all_small = 0;
      for (int i = 0; i < nf; i++) { /* r − A z = Jᵀμ, the held rows' forces */
        aq[i] -= cz * (Az[i] - cm * Mz[i]) + (rq[i] - Az[i]);
        rq[i] = aq[i] + Mz[i];
      }
    }
    if (m == 0) continue; /* the goals' own duals: nh_dwr_functionals solves them */
    small = all_small ? small + 1 : 0;
    if (small == 2) break;
    /* keep link m's duals and multipliers */
    rc = nh_realloc((void **)z_links, n3 * (size_t)nz * (size_t)m, sizeof(double));
    if (!rc && mr) rc = nh_realloc((void **)mu_links, (size_t)mr * nz * (size_t)m, sizeof(double));
    if (rc) {
      rc = NH_ERROR(rc, "out of memory: %d links of the memory term", m);
      break;
    }
    for (int q = 0; q < nz; q++)
      nh_system_scatter(sys, z + (size_t)nf * q, *z_links + n3 * ((size_t)nz * (m - 1) + q));
    if (mr) memcpy(*mu_links + (size_t)mr * nz * (m - 1), mu, sizeof(double) * mr * nz);
    *n_links = m;
  }
  nh_rows_solver_destroy(sys, &rs);
  free(a), free(r), free(z), free(Az), free(Mz), free(full), free(e0), free(mu), free(active);
  if (rc) {
    free(*z_links), free(*mu_links);
    *z_links = *mu_links = NULL, *n_links = 0;
  }
  return rc;
}
