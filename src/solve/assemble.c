/* assemble.c — the internal force, A = cM M + cK K̃ and K̃ v, with element
 * tangents updated lazily (solver.lazy_rotation; docs/theory.md §4,
 * docs/performance.md "Lazy tangents").
 *
 * The corotational tangent of a leaf depends on the displacements only
 * through its frame: the rotation R (polar of F at the centre) and, for
 * B-bar, C = cof F̄ (fem/hex.c). Most leaves turn little from one assembly
 * to the next, so, as Chentanez et al. ("Interactive simulation of surgical
 * needle insertion and steering") do with their elements' Jacobians, a leaf
 * keeps the frame its tangent in A was built with, R̃ (and C̃), and its
 * tangent is rebuilt only when
 *     δ = max(‖R − R̃‖_F, ‖C − C̃‖_F) > τ,      τ = solver.lazy_rotation.
 * The internal force always uses the current R: the equations solved, and
 * the equilibrium a Newton iteration converges to, are exact; only their
 * linearisation, K̃ in A and in the K̃ v of the damping and implicit terms,
 * lags. The error of a leaf's tangent (R = R̃ + ΔR, ‖ΔR‖₂ ≤ ‖ΔR‖_F ≤ τ, the
 * rotation block-diagonal over the 8 corners):
 *     R K₀ Rᵀ − R̃ K₀ R̃ᵀ = ΔR K₀ Rᵀ + R̃ K₀ ΔRᵀ,  ‖·‖₂ ≤ 2 τ ‖K₀‖₂,
 * and for B-bar's κ V b bᵀ (b = C ḡ) ‖ΔC ḡ bᵀ + b̃ (ΔC ḡ)ᵀ‖₂ ≤
 * τ ‖ḡ‖² (‖C‖₂ + ‖C̃‖₂) κ V; each scaled by φ and by cK in A
 * (tests/test_lazy.c checks this bound on a deformed mesh).
 *
 * τ = 0 is the exact path: a leaf is updated when its frame differs in any
 * bit, and A is then assembled afresh from every leaf's frame, so it is
 * bitwise what an assembly with no history gives. Either way, an assembly in
 * which no leaf is updated (and cM, cK are those A holds) leaves A's values
 * untouched and a factorisation of A current: the assembly at the start of
 * a step repeats the one of the previous step's residual at the same u, and
 * with τ > 0 whole steps may keep A (the factor stays exact, no PCG).
 *
 * With τ > 0 and at most half of the leaves updated, A is updated in place,
 *     A += cK (K̃_new − K̃_old) over the updated leaves,
 * which costs two tangents per updated leaf instead of one per leaf; above
 * half, A is assembled afresh from the frames. The in-place updates add
 * round-off (about eps ‖K₀‖ each) that a fresh assembly (a mesh change, a
 * change of cM or cK, more than half the leaves) clears.
 *
 * An assembly repeated at the same u and v with the same cM, cK and τ
 * (bitwise; A valid) computes nothing: every frame equals the one the last
 * assembly left, so no tangent is updated, A is kept, and the force and
 * K̃ v are the last ones, which the system keeps. That is a dynamic step's
 * first assembly, at the state where the previous step's residual assembled
 * (on the dbs-skull goal run that pass was a fifth of the assembly's
 * samples: docs/performance.md, "The dbs-skull goal run"). The tissue's
 * element data do not change while a system lives (a mesh change builds a
 * new one), as the kept tangents already assume.
 *
 * Two passes, each by colour (system.c): 1. every leaf's force, frame,
 * update decision and K̃ v; 2. A. Within a colour no two leaves share a
 * node, so every entry receives its contributions in colour order whatever
 * the thread count: the result is bitwise that of one thread. The leaves
 * with a hanging corner (the last group, which share masters) have their
 * results computed in parallel into a buffer and added in leaf order, so
 * they too are bitwise those of one thread (on the adaptive hex2 phantom
 * they are three quarters of the leaves). */
#include "solve/system_impl.h"

#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

void nh_system_set_lazy(nh_system *s, double tolerance) {
  s->lazy_tolerance = tolerance;
}

void nh_system_set_tangent(nh_system *s, nh_tangent tangent) {
  int consistent = tangent == NH_TANGENT_CONSISTENT;
  if (consistent != s->consistent) s->a_valid = 0; /* every tangent changes */
  s->consistent = consistent;
}

void nh_system_set_jacobian(nh_system *s, double cG, double cD, const double *v) {
  if (v || s->jac_v) s->a_valid = 0; /* A's next assembly differs: afresh */
  s->jac_v = v;
  s->jac_cG = cG;
  s->jac_cD = cD;
}

int nh_system_lazy_updates(const nh_system *s) {
  return s->lazy_updates;
}

void nh_system_lazy_reset(nh_system *s) {
  s->lazy_updates = 0;
}

/* Ã = Tᵀ Aₑ T (nd x nd, nd = 3 k, into At) of a leaf with a hanging corner.
 * T (8 x k) is sparse: a corner is one effective node (weight 1) or a hanging
 * node's 2 or 4 masters, so both products run over T's nonzeros only, listed
 * once per system in corner order (nz_*, system.c). Each entry still sums its
 * nonzero terms in ascending corner order, as the dense product did, and the
 * skipped terms were exact zeros: the same bits. The products start from
 * their first term, 0 + t (so a −0 term gives +0 as from zeroed storage),
 * instead of zeroing B and Ã first (the zeroing cost a third of this
 * function on the phantom). B: nh_expand_slot(k) doubles of work. */
static void nh_expand(const nh_system *s, int l, const double *Ae, double *B, double *At) {
  const int k = s->eff_start[l + 1] - s->eff_start[l], nd = 3 * k;
  const int lo = s->nz_start[l], hi = s->nz_start[l + 1];
  const int *corner = s->nz_corner, *node = s->nz_node, *first = s->nz_first;
  const double *w = s->nz_w;
  int n_first = 0;
  for (int z = lo; z < hi; z++) n_first += first[z];
  /* a node without a nonzero: zero. It happens: an aggregated node's
   * extrapolated weights (mesh/hanging.c) can vanish or cancel, as at a cut
   * leaf of dbs-skull.yaml at step 4 */
  for (int q = 0; q < k && n_first < k; q++) {
    int seen = 0;
    for (int z = lo; z < hi; z++) seen |= node[z] == q;
    if (seen) continue;
    for (int r = 0; r < 24; r++)
      for (int j = 0; j < 3; j++) B[nd * r + 3 * q + j] = 0.0;
    for (int i = 0; i < 3; i++) memset(At + (size_t)nd * (3 * q + i), 0, sizeof(double) * nd);
  }
  /* B = Aₑ T (24 x nd), nonzero by nonzero (each entry's terms in the
   * nonzeros' order: the row-by-row loop's sums) */
  for (int z = lo; z < hi; z++) {
    double *Bz = B + 3 * node[z];
    const double *Az = Ae + 3 * corner[z], wz = w[z];
    if (first[z])
      for (int r = 0; r < 24; r++)
        for (int j = 0; j < 3; j++) Bz[nd * r + j] = 0.0 + Az[24 * r + j] * wz;
    else
      for (int r = 0; r < 24; r++)
        for (int j = 0; j < 3; j++) Bz[nd * r + j] += Az[24 * r + j] * wz;
  }
  /* Ã = Tᵀ B, its upper triangle: the effective nodes ascend as their free
   * DOFs do (system.c), so the entries A stores (nh_add_leaf) have c >= row */
  for (int z = lo; z < hi; z++)
    for (int i = 0; i < 3; i++) {
      const int d = 3 * node[z] + i;
      double *row = At + (size_t)nd * d;
      const double *Brow = B + (size_t)nd * (3 * corner[z] + i);
      const double wz = w[z];
      if (first[z])
        for (int c = d; c < nd; c++) row[c] = 0.0 + wz * Brow[c];
      else
        for (int c = d; c < nd; c++) row[c] += wz * Brow[c];
    }
}

/* Doubles of nh_expand's work for k effective nodes: B (24 x 3k). */
static size_t nh_expand_slot(int k) {
  return 24 * 3 * (size_t)k;
}

/* Leaf l's matrix in A's storage: Ã (expanded leaves, nh_expand) or Aₑ
 * (plain leaves), its stored entries added at their positions (pair). */
static void nh_add_leaf(const nh_system *s, int l, const double *At, double *Ax) {
  const int *p = s->pair + 2 * s->pair_start[l], *end = s->pair + 2 * s->pair_start[l + 1];
  for (; p < end; p += 2) Ax[p[1]] += At[p[0]];
}

/* δ = max(‖R − R̃‖_F, ‖C − C̃‖_F) of two frames. */
static double nh_frame_change(const double a[NH_HEX_FRAME], const double b[NH_HEX_FRAME]) {
  double r = 0.0, c = 0.0;
  for (int i = 0; i < 9; i++) {
    r += (a[NH_FRAME_R + i] - b[NH_FRAME_R + i]) * (a[NH_FRAME_R + i] - b[NH_FRAME_R + i]);
    c += (a[NH_FRAME_COF + i] - b[NH_FRAME_COF + i]) * (a[NH_FRAME_COF + i] - b[NH_FRAME_COF + i]);
  }
  return sqrt(fmax(r, c));
}

/* The element matrix K split for A: K ← its symmetric part ½ (K + Kᵀ), and
 * (skew != NULL) skew ← the skew-symmetric part ½ (K − Kᵀ). */
static void nh_split_symmetric(double K[576], double *skew) {
  for (int r = 0; r < 24; r++) {
    if (skew) skew[25 * r] = 0.0;
    for (int c = r + 1; c < 24; c++) {
      double a = K[24 * r + c], b = K[24 * c + r], m = 0.5 * (a + b), k = 0.5 * (a - b);
      K[24 * r + c] = K[24 * c + r] = m;
      if (skew) skew[24 * r + c] = k, skew[24 * c + r] = -k;
    }
  }
}

/* A parallel region costs tens of µs (far more when cores are shared): only
 * colours with at least this many leaves to do (≈ 1 ms of element work) are
 * split; the last group (leaves with hanging corners) is computed in
 * parallel and added serially (nh_assemble_group), by the same threshold. */
enum { NH_ASSEMBLE_PARALLEL_MIN = 128 };

/* The last assembly repeated: the same u (and v when K̃ v is asked for), tolerance and
 * coefficients, A valid (see the header). */
static int nh_assembly_repeated(const nh_system *s, const double *u, const double *v,
                                const double *Kv, int fresh) {
  const size_t bytes = sizeof(double) * 3 * (size_t)s->n_nodes;
  return !fresh && s->last_kept >= (Kv ? 2 : 1) && s->lazy_tolerance == s->last_tolerance &&
         !memcmp(u, s->last_u, bytes) && (!Kv || !memcmp(v, s->last_v, bytes));
}

/* Keep this assembly's inputs and outputs for a repetition (nothing kept
 * without memory: the next assembly then computes). */
static void nh_assembly_keep(nh_system *s, const double *u, const double *v, const double *f_int,
                             const double *Kv) {
  const size_t n = 3 * (size_t)s->n_nodes, bytes = sizeof(double) * n;
  s->last_kept = 0;
  if (!s->last_u) {
    s->last_u = nh_calloc(n, sizeof(double)), s->last_v = nh_calloc(n, sizeof(double));
    s->last_f = nh_calloc(n, sizeof(double)), s->last_kv = nh_calloc(n, sizeof(double));
  }
  if (!s->last_u || !s->last_v || !s->last_f || !s->last_kv) return;
  memcpy(s->last_u, u, bytes);
  memcpy(s->last_f, f_int, bytes);
  if (Kv) memcpy(s->last_v, v, bytes), memcpy(s->last_kv, Kv, bytes);
  s->last_tolerance = s->lazy_tolerance;
  s->last_kept = Kv ? 2 : 1;
}

/* Pass 1 for leaf l: its force f, its frame (frame_new) and whether its
 * tangent is updated (s->updated), and with v the product y = K̃ₑ vₑ. */
static void nh_leaf_force(nh_system *s, int l, const double *u, const double *v, int fresh,
                          double f[24], double y[24]) {
  const nh_tissue *t = s->tissue;
  const nh_mesh *m = t->mesh;
  const double tol = s->lazy_tolerance;
  int c = m->leaves[l];
  double *now = s->frame_new + NH_HEX_FRAME * (size_t)l, *old = s->frame + NH_HEX_FRAME * (size_t)l;
  nh_tissue_element_force(t, c, u, f, now);
  if (!s->consistent) nh_hex_frame_corotational(now);
  int update = fresh || (tol > 0.0 ? nh_frame_change(now, old) > tol
                                   : memcmp(now, old, NH_HEX_FRAME * sizeof(double)) != 0);
  s->updated[l] = (unsigned char)update;
  if (v) {
    double ve[24];
    nh_mesh_cell_coords(m, v, c, ve);
    nh_tissue_element_apply(t, c, update ? now : old, ve, y);
  }
}

/* f_int (and Kv) += leaf l's f (and y). */
static void nh_leaf_add_force(const nh_mesh *m, int l, const double f[24], const double *y,
                              double *f_int, double *Kv) {
  const int *e = m->cells + 8 * m->leaves[l];
  for (int a = 0; a < 8; a++)
    for (int i = 0; i < 3; i++) f_int[3 * e[a] + i] += f[3 * a + i];
  if (Kv)
    for (int r = 0; r < 24; r++) Kv[3 * e[r / 3] + r % 3] += y[r];
}

/* Pass 2 for leaf l: K ← its matrix for A (afresh: cM Mₑ + cK K̃ₑ from its
 * frame, updated first; in place: cK (K̃_new − K̃_old)), split into its
 * symmetric part and (skew kept) the skew part N for a consistent tangent. */
static void nh_leaf_matrix(nh_system *s, int l, int full, int jacobian, double cM, double cK,
                           double K[576], double N[576]) {
  const nh_tissue *t = s->tissue;
  const nh_mesh *m = t->mesh;
  int c = m->leaves[l];
  double *frame = s->frame + NH_HEX_FRAME * (size_t)l,
         *now = s->frame_new + NH_HEX_FRAME * (size_t)l;
  if (full) {
    if (s->updated[l]) memcpy(frame, now, NH_HEX_FRAME * sizeof(double));
    /* Aₑ = cK Kₑ + cM Mₑ, Mₑ the lumped mass ρ φ Vₑ / 8 per corner. */
    nh_tissue_element_tangent(t, c, frame, K);
    double me[8];
    nh_tissue_corner_masses(t, c, NULL, me); /* no plane: cannot fail */
    if (jacobian) {                          /* nh_system_set_jacobian */
      double fc[NH_HEX_FRAME], Kc[576], ve[24];
      memcpy(fc, frame, sizeof fc);
      nh_hex_frame_corotational(fc);
      nh_tissue_element_tangent(t, c, fc, Kc);
      nh_mesh_cell_coords(m, s->jac_v, c, ve);
      nh_tissue_element_rate_tangent(t, c, frame, ve, N);
      for (int r = 0; r < 576; r++)
        K[r] = cK * Kc[r] + s->jac_cG * (K[r] - Kc[r]) + s->jac_cD * N[r];
    } else {
      for (int r = 0; r < 576; r++) K[r] *= cK;
    }
    for (int r = 0; r < 24; r++) K[25 * r] += cM * me[r / 3];
  } else {
    double K_old[576];
    nh_tissue_element_tangent(t, c, now, K);
    nh_tissue_element_tangent(t, c, frame, K_old);
    for (int r = 0; r < 576; r++) K[r] = cK * (K[r] - K_old[r]);
    memcpy(frame, now, NH_HEX_FRAME * sizeof(double));
  }
  if (s->consistent) nh_split_symmetric(K, s->skew ? N : NULL);
}

/* The serial group's work: at most this many doubles of results at a time. */
enum { NH_GROUP_DOUBLES = 1 << 20 };

/* Room for `need` doubles of group results and, for `threads` threads, the
 * expansion work of the largest leaf. Returns 0 on success. */
static int nh_group_reserve(nh_system *s, size_t need, int threads) {
  if (need > s->group_cap) {
    free(s->group);
    s->group = nh_calloc(need, sizeof(double));
    s->group_cap = s->group ? need : 0;
    if (!s->group) return NH_ERR_MEMORY;
  }
  if (!s->expand_slot) {
    const nh_mesh *m = s->tissue->mesh;
    int kmax = 0;
    for (int l = 0; l < m->n_leaves; l++)
      if (s->eff_start[l + 1] - s->eff_start[l] > kmax)
        kmax = s->eff_start[l + 1] - s->eff_start[l];
    s->expand_slot = nh_expand_slot(kmax);
  }
  if (threads > s->expand_threads) {
    free(s->expand);
    s->expand = nh_calloc((size_t)threads * s->expand_slot, sizeof(double));
    s->expand_threads = s->expand ? threads : 0;
    if (!s->expand) return NH_ERR_MEMORY;
  }
  return NH_OK;
}

/* Doubles of leaf l's pass-2 result: Ã (or Aₑ), twice with the skew part. */
static size_t nh_leaf_doubles(const nh_system *s, int l) {
  const int k = s->eff_start[l + 1] - s->eff_start[l];
  return (k ? 9 * (size_t)k * k : 576) * (s->consistent && s->skew ? 2 : 1);
}

/* The serial group (leaves with a hanging corner, colour n_colours), leaves
 * [lo, hi) of colour_leaf: their nodes overlap, so each pass computes the
 * leaves' results in parallel into s->group, chunk by chunk, and adds them
 * in leaf order: every entry receives the terms of the one-thread loop in
 * its order, the same bits. Pass 1 (matrix 0): forces and K̃ v; pass 2:
 * A's leaf matrices (only the updated leaves unless full). Returns 0, or
 * NH_ERR_MEMORY with nothing added. */
static int nh_assemble_group(nh_system *s, int lo, int hi, int nt, int matrix, const double *u,
                             const double *v, int fresh, double *f_int, double *Kv, int full,
                             int jacobian, double cM, double cK) {
  const nh_mesh *m = s->tissue->mesh;
  double *Ax = s->A->x;
  const int skew = s->consistent && s->skew != NULL;
  for (int k0 = lo; k0 < hi;) {
    /* the chunk [k0, k1) and its results' offsets */
    size_t need = 0;
    int k1 = k0, work = 0;
    while (k1 < hi) {
      int l = s->colour_leaf[k1];
      size_t d = matrix ? (full || s->updated[l] ? nh_leaf_doubles(s, l) : 0) : 48;
      if (k1 > k0 && need + d > NH_GROUP_DOUBLES) break;
      need += d, work += d > 0, k1++;
    }
    int threads = nt > 1 && work >= NH_ASSEMBLE_PARALLEL_MIN ? nt : 1;
    NH_TRY(nh_group_reserve(s, need + (size_t)(k1 - k0), threads));
    /* offsets stored after the results, as doubles (exact for these sizes) */
    double *off = s->group + need;
    size_t o = 0;
    for (int k = k0; k < k1; k++) {
      int l = s->colour_leaf[k];
      off[k - k0] = (double)o;
      o += matrix ? (full || s->updated[l] ? nh_leaf_doubles(s, l) : 0) : 48;
    }
#pragma omp parallel for num_threads(threads) schedule(dynamic, 4) if (threads > 1)
    for (int k = k0; k < k1; k++) {
      int l = s->colour_leaf[k];
      double *r = s->group + (size_t)off[k - k0];
      if (!matrix) {
        nh_leaf_force(s, l, u, Kv ? v : NULL, fresh, r, r + 24);
        continue;
      }
      if (!full && !s->updated[l]) continue;
      double K[576], N[576];
      nh_leaf_matrix(s, l, full, jacobian, cM, cK, K, N);
      const int n_eff = s->eff_start[l + 1] - s->eff_start[l];
      if (!n_eff) {
        memcpy(r, K, sizeof K);
        if (skew) memcpy(r + 576, N, sizeof N);
        continue;
      }
      double *w = s->expand + s->expand_slot * (size_t)omp_get_thread_num();
      nh_expand(s, l, K, w, r);
      if (skew) nh_expand(s, l, N, w, r + 9 * (size_t)n_eff * n_eff);
    }
    for (int k = k0; k < k1; k++) {
      int l = s->colour_leaf[k];
      const double *r = s->group + (size_t)off[k - k0];
      if (!matrix) {
        nh_leaf_add_force(m, l, r, r + 24, f_int, Kv);
        continue;
      }
      if (!full && !s->updated[l]) continue;
      nh_add_leaf(s, l, r, Ax);
      if (skew) {
        const int n_eff = s->eff_start[l + 1] - s->eff_start[l];
        nh_add_leaf(s, l, r + (n_eff ? 9 * (size_t)n_eff * n_eff : 576), s->skew);
      }
    }
    k0 = k1;
  }
  return NH_OK;
}

void nh_system_assemble(nh_system *s, const double *u, const double *v, double cM, double cK,
                        double *f_int, double *Kv, int threads) {
  const nh_tissue *t = s->tissue;
  const nh_mesh *m = t->mesh;
  const double tol = s->lazy_tolerance;
  const int jacobian = s->consistent && s->jac_v;
  const int fresh = !s->a_valid || cM != s->a_cM || cK != s->a_cK || jacobian;
  s->threads = threads; /* the compliance W's build (compliance.c) runs on the same team */
  if (nh_assembly_repeated(s, u, v, Kv, fresh)) {
    const size_t bytes = sizeof(double) * 3 * (size_t)m->n_nodes;
    memcpy(f_int, s->last_f, bytes);
    if (Kv) memcpy(Kv, s->last_kv, bytes);
    memset(s->updated, 0, (size_t)m->n_leaves); /* as the computed repetition: none */
    return;
  }
  s->last_kept = 0;
  memset(f_int, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  if (Kv) memset(Kv, 0, sizeof(double) * 3 * (size_t)m->n_nodes);
  int nt = threads > 0 ? threads : omp_get_max_threads();
  const int g_lo = s->colour_start[s->n_colours], g_hi = s->colour_start[s->n_colours + 1];

  /* 1. Forces, frames, which tangents to update, and K̃ v. */
  for (int colour = 0; colour < s->n_colours; colour++) {
    /* SIGINT/SIGTERM: the results are left partial; callers ask
     * nh_stop_check after. */
    if (nh_stop_requested()) break;
    int lo = s->colour_start[colour], hi = s->colour_start[colour + 1];
    int parallel = nt > 1 && hi - lo >= NH_ASSEMBLE_PARALLEL_MIN;
#pragma omp parallel for num_threads(nt) schedule(static) if (parallel)
    for (int k = lo; k < hi; k++) {
      int l = s->colour_leaf[k];
      double f[24], y[24];
      nh_leaf_force(s, l, u, Kv ? v : NULL, fresh, f, y);
      nh_leaf_add_force(m, l, f, y, f_int, Kv);
    }
  }
  if (!nh_stop_requested() &&
      nh_assemble_group(s, g_lo, g_hi, nt, 0, u, v, fresh, f_int, Kv, 0, 0, cM, cK))
    goto out_of_memory;
  if (nh_stop_requested()) { /* A and the frames no longer agree: start afresh */
    s->a_valid = 0;
    s->factor_current = 0;
    return;
  }
  nh_assembly_keep(s, u, v, f_int, Kv);
  int todo[66] = {0}, count = 0;
  for (int colour = 0; colour <= s->n_colours; colour++) {
    for (int k = s->colour_start[colour]; k < s->colour_start[colour + 1]; k++)
      todo[colour] += s->updated[s->colour_leaf[k]];
    count += todo[colour];
  }
  s->lazy_updates += count;
  if (count == 0) return; /* A keeps its values (and a factor of it stays current) */

  /* 2. A: afresh from every leaf's frame, or updated in place. */
  s->factor_current = 0; /* A changes: a factor of the old values is now a preconditioner */
  memcpy(s->u_assembled, u, sizeof(double) * 3 * (size_t)m->n_nodes);
  s->c_assembled[0] = cM, s->c_assembled[1] = cK;
  const int full = fresh || tol == 0.0 || 2 * count > m->n_leaves;
  double *Ax = s->A->x;
  if (full) memset(Ax, 0, sizeof(double) * ((int *)s->A->p)[s->n_free]);
  if (full && s->skew) memset(s->skew, 0, sizeof(double) * ((int *)s->A->p)[s->n_free]);
  for (int colour = 0; colour < s->n_colours; colour++) {
    if (nh_stop_requested()) {
      s->a_valid = 0;
      return;
    }
    int lo = s->colour_start[colour], hi = s->colour_start[colour + 1];
    int work = full ? hi - lo : todo[colour];
    int parallel = nt > 1 && work >= NH_ASSEMBLE_PARALLEL_MIN;
#pragma omp parallel for num_threads(nt) schedule(static) if (parallel)
    for (int k = lo; k < hi; k++) {
      int l = s->colour_leaf[k];
      if (!full && !s->updated[l]) continue;
      double K[576], N[576];
      nh_leaf_matrix(s, l, full, jacobian, cM, cK, K, N);
      nh_add_leaf(s, l, K, Ax);
      if (s->consistent && s->skew) nh_add_leaf(s, l, N, s->skew);
    }
  }
  if (nh_stop_requested()) {
    s->a_valid = 0;
    return;
  }
  if (nh_assemble_group(s, g_lo, g_hi, nt, 1, u, v, fresh, f_int, Kv, full, jacobian, cM, cK))
    goto out_of_memory;
  s->a_valid = 1;
  s->a_cM = cM;
  s->a_cK = cK;
  return;
out_of_memory: /* loud: the residual is not finite, the step fails */
  NH_ERROR(NH_ERR_MEMORY, "out of memory: assembly of the leaves with a hanging corner");
  for (int i = 0; i < 3 * m->n_nodes; i++) f_int[i] = NAN;
  s->a_valid = 0;
  s->factor_current = 0;
  s->last_kept = 0;
}

const double *nh_system_frames_at(const nh_system *s, const nh_tissue *tissue, const double *u) {
  /* last_kept: the last computed assembly finished its pass 1 (a stopped or
   * failed one clears it), and a repeated one leaves frame_new as it was */
  if (!s) return NULL;
  const nh_mesh *m = tissue->mesh;
  if (s->tissue != tissue || s->n_nodes != m->n_nodes ||
      s->colour_start[s->n_colours + 1] != m->n_leaves || s->last_kept < 1)
    return NULL;
  return memcmp(u, s->last_u, sizeof(double) * 3 * (size_t)m->n_nodes) ? NULL : s->frame_new;
}
