/* adapt_impl.h — private to the adapt module: the (η, cell) pairs that
 * marking (mark.c) and the DOF budget (refine.c) sort. */
#ifndef NH_ADAPT_IMPL_H
#define NH_ADAPT_IMPL_H

#include "adapt/adapt.h"

typedef struct {
  double eta;
  int cell;
} nh_mark_entry;

/* The estimators' inner loops, compiled more than once on x86-64 with GCC
 * and chosen at load time by the CPU; without FMA and with the sums in the
 * source's order every copy computes the same bits.
 *
 * NH_ADAPT_VECTOR_CLONES: loops left to the compiler's vectoriser (SPR's
 * stresses, interpolation and error at the points, spr.c; the duals' centre
 * stresses, dwr.c), for AVX-512, AVX2 and the baseline SSE2.
 *
 * nh_v4, NH_V4_LOAD, NH_ADAPT_V4_CLONES: kernels written on 4-double
 * vectors themselves (GCC's and Clang's vector extension: the arithmetic
 * elementwise, a scalar operand applied to every element; NH_V4_LOAD(v, p):
 * v = p[0..3], any alignment) where the vectoriser shuffled more than it
 * computed (the Gauss-point kernel, dwr.c; SPR's combination of many
 * fields, spr.c: docs/performance.md, "The Gauss-point kernel on explicit
 * vectors"). Their copies: AVX2 (on AVX-512 machines too, where the 4-wide
 * form ran faster than an AVX-512 copy of the same source) and the
 * baseline (pairs of SSE2 halves). */
typedef double nh_v4 __attribute__((vector_size(32)));
#define NH_V4_LOAD(v, p) memcpy(&(v), (p), sizeof(v))
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__ELF__)
#define NH_ADAPT_VECTOR_CLONES __attribute__((target_clones("avx512f", "avx2", "default")))
#define NH_ADAPT_V4_CLONES     __attribute__((target_clones("avx2", "default")))
#else
#define NH_ADAPT_VECTOR_CLONES
#define NH_ADAPT_V4_CLONES
#endif

/* A mesh's identity for the module's caches (key.c): counts, leaves, their
 * corners, rest positions, one number per leaf (the cache's choice) and the
 * hanging nodes, compared exactly. Zero-initialised: matches nothing. */
typedef struct {
  int valid;
  int n_nodes, n_leaves, n_hanging;
  int *leaves, *corners, *hanging; /* n_leaves, 8 n_leaves, n_hanging */
  double *X, *weight;              /* 3 n_nodes, n_leaves */
} nh_mesh_key;

/* Whether k was set for this mesh with weight[c] per cell and the hanging
 * table h (may be NULL: none). */
int nh_mesh_key_matches(const nh_mesh_key *k, const nh_mesh *mesh, const double *weight,
                        const nh_hanging *h);
/* Make k the key of this mesh, weight and h (as nh_mesh_key_matches).
 * Fails with NH_ERR_MEMORY (k then matches nothing). */
int nh_mesh_key_set(nh_mesh_key *k, const nh_mesh *mesh, const double *weight, const nh_hanging *h);
/* Free k's arrays and zero it. */
void nh_mesh_key_free(nh_mesh_key *k);

/* qsort order of nh_mark_entry: decreasing η, then increasing cell id. */
int nh_mark_entry_compare(const void *a, const void *b);

/* The goals of nz functionals: n_points points, the boxes' half-width,
 * weights[3 n_points q + 3p + k] the weight of J_pk in functional q. */
typedef struct {
  int n_points;
  const double *points;
  double radius;
  const double *weights;
} nh_dwr_goals;

/* One dual's terms at a cell's 8 Gauss points (dwr.c, where the arguments
 * are described): *eps = Σ det J (e_zᵀ D⁻¹ e_u, with B-bar's
 * − e_p,u (I − Π) div z − e_p,z (I − Π) div u), *ezz = Σ det J e_zᵀ D⁻¹ e_z.
 * Outside dwr.c for tests/test_dwr_kernel.c only. */
void nh_dwr_dual_terms(const double we[24], const double RgT[24][8], const double RdivT[24][8],
                       const double *zstar, size_t stride, const int corner[8],
                       const double NT[8][8], double lambda, double mu, int bbar, double tz,
                       const double ceuT[6][8], const double pu[8], const double dev_u[8],
                       const double detJ[8], double *eps, double *ezz);

/* The estimates E_q of nz functionals j (3 n_nodes each) of the step's
 * solution u, with the constrained dual of the rows (dwr.c); for each group
 * of `group` consecutive functionals the marking indicator (out->indicator,
 * may be NULL). goals: the box goals the local dual needs (out->local).
 * With out->fronts, the fronts' errors too, from the same primal terms
 * (nz may then be 0: the fronts alone). Fails as nh_dwr_estimate and
 * nh_dwr_front_setup. */
int nh_dwr_functionals(nh_system *sys, const nh_rows *rows, double scale, const nh_mesh *mesh,
                       const nh_tissue *tissue, const nh_hanging *hanging, const double *u, int nz,
                       int group, const double *j, const nh_dwr_goals *goals, nh_dwr_result *out);

/* The 3 dual problems of the front whose tip rows start at `row` among the
 * step's rows (dwr_front.c): j (3 × 3 n_nodes) the functionals
 * n_q · Σ w_a v_a of its rows, active (rows->m) the rows its duals hold:
 * the active rows (nh_dwr_active_rows) with every friction row but the
 * front's axial one sliding. Solved with the goals' duals in one pass
 * (nh_dwr_functionals). NH_ERR_INTERNAL (rows out of range). */
int nh_dwr_front_setup(const nh_rows *rows, int n_nodes, int row, double *j, unsigned char *active);
/* The memory term's links (dwr_memory.c) of the nz goal functionals j
 * (3 n_nodes each): *n_links links, at most mem->max_links, their duals
 * (*z_links, 3 n_nodes for link m ≥ 1 of functional q at nz (m − 1) + q,
 * allocated here) and multipliers (*mu_links, rows->m each, the same
 * order; NULL without rows), each held by the goals' active rows.
 * NH_ERR_MEMORY, or fails as nh_rows_solver_create and _solve. */
int nh_dwr_memory_duals(nh_system *sys, const nh_rows *rows, double scale, int n_nodes, int nz,
                        const double *j, const nh_dwr_memory *mem, int *n_links, double **z_links,
                        double **mu_links);
/* The n dual problems of the shaft points whose rows start at row[p]
 * (dwr_front.c, "Shaft points"): j (n × 3 n_nodes) the functionals
 * t · Σ N_a v_a of their axial rows' tissue parts, active (rows->m) the
 * rows their duals hold: the active rows with every friction row sliding.
 * NH_ERR_INTERNAL (rows out of range). */
int nh_dwr_points_setup(const nh_rows *rows, int n_nodes, int n, const int *row, double *j,
                        unsigned char *active);
/* The front's error e = Σ_q E_q n_q from its duals' estimates E[3]. */
void nh_dwr_front_vector(const nh_rows *rows, int row, const double E[3], double e[3]);

/* The local enriched dual where a goal's box and an active tool row share a
 * leaf (dwr_local.c; docs/theory.md §6.6, "Held rows in the goal's cell").
 * In: the step's state (mesh, tissue, hanging (may be NULL), u, rows and
 * the rows' forces on the tissue, force[rows->m] (N; may be NULL: no row
 * forces in the residual)), free_mask (3 per node: 1
 * on the system's free DOFs, 0 on fixed ones; NULL: all free), the nz
 * coarse duals z
 * (3 n_nodes each), the goals (n_points points, box half-width radius) and
 * the functionals' weights (3 n_points per functional: functional q =
 * Σ_pk weights[3 n_points q + 3p + k] J_pk), the body force (loads, may be
 * NULL). Out: *applied 1 if a patch was solved (else 0 and nothing
 * written); then L[nz] the patch's term and replaced[n_leaves] (may be
 * NULL) 1 for the leaves whose recovered terms it replaces.
 * Fails with NH_ERR_MEMORY, NH_ERR_NUMERIC (the lattice's matrix). */
int nh_dwr_local_term(const nh_mesh *mesh, const nh_tissue *tissue, const nh_hanging *hanging,
                      const double *u, const nh_rows *rows, const double *force,
                      const double *free_mask, int nz, const double *z, int n_points,
                      const double *points, double radius, const double *weights,
                      const nh_geometry_loads *loads, double *L, unsigned char *replaced,
                      int *applied);

#endif
