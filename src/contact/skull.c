/* skull.c — frictionless unilateral contact of the brain with a rigid skull
 * (docs/interaction.md, "Skull contact"; docs/theory.md §5c).
 *
 * The skull is the tissue's outer hull offset outwards by the CSF gap: with
 * φ_skull(x) = U(x) / |∇U(x)| (U the domain's hull level, nh_domain_hull_level:
 * for the analytic brain its F without the fissure term, for a mask or a
 * surface F itself; φ_skull is the signed distance to first order, exactly
 * for a sphere), the tissue must stay where φ_skull ≤ gap. The hull keeps
 * the skull out of the brain's longitudinal fissure: the offset of F itself
 * reached into it as a rigid plate 2 (w − gap) = 0.8 mm thick whose lower
 * edge, 1 mm above the fissure's floor, held the floor on some grids and
 * not on others (docs/dbs.md, "Isolating the odd grids' offset"); the falx
 * cerebri there (a dural fold, stiff in tension only) is not modelled. The
 * fissure's walls and floor are tissue surface and keep their points; they
 * lie inside the hull (φ_skull < 0) and get no row unless they move out to
 * the skull. Contact points are points of the immersed surface F = 0 of the
 * rest shape, one per cut leaf, or one per cluster of its surface normals
 * where they face apart, each carrying the surface area it stands for
 * (docs/theory.md §5c, "Skull contact points"). A leaf's surface samples
 * (weight w, point x, outward normal n):
 *   integrated cut cells (tissue.cut_cells: integrated, a box leaf): the
 *     surface quadrature of the cut cell (mesh/cutcell.c, depth
 *     NH_CUT_DEPTH): the pieces Γ_c of {I F = 0} (I F the piecewise linear
 *     interpolant of F on the Kuhn lattice, the boundary of the polyhedron
 *     the stiffness is integrated over), points ξ_q with area vectors A_q:
 *     w = |A_q|, n = A_q / |A_q|. Σ w is the area of the reconstructed
 *     surface: O(s²) from the true one (s = the sub-box edge). The points
 *     belong to that leaf, whose tissue holds Γ_c, with their natural
 *     coordinates in it: never to a neighbour (a neighbour's sliver of
 *     tissue, held only by the stabilisation α, would take the contact
 *     force; tests/skull_force.py);
 *   scaled cut cells (and leaves that are not boxes): 6³ sub-cell midpoints
 *     xₛ of volume dvₛ and the one-sided smeared delta (inside only: the
 *     cells just outside the shape are not in the mesh)
 *       δ_ε(φ) = 2 max(0, 1 + φ/ε) / ε for φ ≤ 0,   ε = 1.5 × the sub-cell edge,
 *     w = δ_ε(φₛ) dvₛ (Σ w → ∫ δ(φ) dV, the area of the surface in the
 *     cell) at the projection xₛ − φₛ n(xₛ); the points are located in the
 *     mesh (they may lie in a neighbour).
 * The samples form one cluster if every normal is within 45° of their
 * weighted mean, else one per dominant direction of n (±x, ±y, ±z): the two
 * walls of the brain's fissure in one leaf (a grid with an odd cell count
 * across) or the faces of a crease. A cluster's point has the area A = Σ w
 * and stands at the weighted mean of its samples, moved onto F = 0 along
 * the normal by three steps x ← x − φ(x) n(x) (φ = F/|∇F|, the tissue's
 * own surface; from the sample nearest the
 * mean if that moves it by more than a quarter of the leaf or leaves it off
 * F = 0). One mean for opposite walls lay in the gap, on
 * whose mid-plane ∇F vanishes: φ = F/|∇F| sent the point 1e9 m away (measured, 17 × 21 × 16: 53
 * points) and its row inverted cells at the first step. A cluster whose
 * point lies on a crease of F, or faces one on the skull, gives one point
 * per side of it (nh_skull_cell_points: a row on a crease takes its
 * direction from round-off, docs/theory.md §5c, "Points on a crease"). The
 * points are material points (cell, ξ), found again after refinement.
 *
 * Each step, point i at its current position x = X + u(X) gives one row
 * of the constraint solver (nh_rows, no tool part):
 *   g = gap − φ_skull(x),   direction n = −∇U/|∇U| at x (inwards),   λ ≥ 0,
 * so the step enforces n·v + g/h ≥ 0 with λ (w = 0) complementary: the
 * point ends the step inside the skull, and only pushes are transmitted
 * (frictionless: no tangential row). The normal is re-evaluated at the
 * current position every step, so the brain may slide along the curved
 * skull. Only points whose gap is below a margin (twice what their
 * current outward speed closes in a step, plus 1 % of their cell's edge)
 * or that pushed in the last step get a row: leaving the others out keeps
 * W = J A⁻¹ Jᵀ small; one that closes faster gets its row the next step
 * (and its violation g < 0 is then removed within that step). λ is warm-started
 * from the point's previous step. The rows' impulses λ / h are the contact
 * forces; λ / (h A) is the contact pressure.
 *
 * Weighted-gap rows (tissue.skull.rows: mortar, nh_skull_build_mortar;
 * docs/theory.md §5c, "Weighted-gap rows"): instead of the clustered points,
 * every leaf's samples are kept (moved onto F = 0), and each node a whose
 * shape function sees some gives one row per cluster K of their normals,
 * the mortar-type weighted gap (Puso & Laursen, "A mortar segment-to-segment
 * contact method for large deformation solid mechanics", 2004) against the
 * rigid skull: g_a = Σ_K w_q N_a(X_q) g(x_q) / D_a, D_a = Σ_K w_q N_a(X_q),
 * direction the same mean of the skull's inward normals, tissue part the
 * widened row Σ_b c_ab u_b with c_ab = Σ_K w_q N_a(X_q) N_b(X_q) / D_a. Their
 * warm starts, forces, relocation and checkpoint are the points' (one
 * "point" per row, at the samples' weighted mean), except the margin's
 * floor, 0.1 % of the edge (NH_SKULL_MORTAR_FLOOR), and a screen that
 * skips the rows far from the skull unevaluated; the goal estimate's
 * data term gives them 0.
 *
 * The points one lattice finer (nh_skull_data_change): the same leaf's
 * points at depth + 1 (`scaled`: 12³ sub-cells), computed once per leaf,
 * each given to the nearest point of its leaf facing its way; the change of
 * each row's gap and direction between them and the row is the goal
 * estimate's constraint data (docs/theory.md §6.6, "Constraint data"). */
#include "contact/contact.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
  double X[3];  /* rest position on F = 0 */
  double N[3];  /* outward unit normal there */
  double area;  /* m², the surface it stands for */
  int cell;     /* leaf holding X */
  double xi[3]; /* its natural coordinates */
  double edge;  /* that leaf's largest edge, m */
  double lam;   /* last impulse (N s), warm start */
  int row;      /* its row this step, or −1 */
  int small;    /* its leaf's tissue fraction is below NH_FILL_MIN (merged away in the build) */
  int crease;   /* it (or its skull point) lies on a crease even after the split: its row
                   keeps the skull's normal at X as its direction */
  int leaf;     /* the leaf whose surface samples made it (cell may be a neighbour: `scaled`) */
  /* a weighted-gap row (NH_SKULL_ROWS_MORTAR): its samples s->mq[q_first ..< q_first + q_count]
   * with their weights w_q N_a(X_q) / D_a, and its tissue part s->mt[t_first ..< + t_count] */
  int q_first, q_count, t_first, t_count;
  double c_abs; /* Σ |w_q N_a(X_q) / D_a| over its samples (> 1 only with N_a < 0) */
  double g_ref; /* its gap at the screen's reference displacement (nh_skull_rows_mortar) */
} nh_skull_point;

/* A sample of the rest surface kept for the weighted-gap rows: rest point,
 * its leaf and natural coordinates there, area weight, outward normal,
 * whether its leaf holds less than NH_FILL_MIN of tissue, and whether it
 * (or its skull point) lies on a crease (nh_skull_crease: its direction is
 * then the skull's at the rest point, as a point row's on a crease). */
typedef struct {
  double X[3], xi[3], w, n[3];
  double edge; /* its leaf's largest edge, m */
  int cell, small, crease;
} nh_skull_msample;

/* A weight of a weighted-gap row: a sample (or a node) and its coefficient. */
typedef struct {
  int i;
  double c;
} nh_skull_weight;

/* At most one point per dominant direction of the outward normal (±x, ±y,
 * ±z) in a leaf. */
#define NH_SKULL_CLUSTERS 6
/* cos 45°: the largest angle between a normal of a smooth piece and its mean */
#define NH_SKULL_COS_CLUSTER 0.70710678118654752
/* A crease of F through a cluster's point (nh_skull_kink): the outward
 * normals a step NH_SKULL_KINK_STEP × the leaf's edge to either side of it,
 * along some axis, more than 2° apart (cos 2°). A smooth surface turns its
 * normal by 2 × 1e-3 edge / R there, 2° only for a radius of curvature R
 * below 0.06 edges; F's own gradient is a central difference of step 1e-6
 * of the domain's largest edge (mesh/domain.c), so the two normals are
 * those of the crease's two sides. */
#define NH_SKULL_KINK_STEP 1e-3
#define NH_SKULL_COS_KINK  0.99939082701909573
/* At most two points per cluster (split once at a crease). */
#define NH_SKULL_MAX_PT (2 * NH_SKULL_CLUSTERS)

/* A leaf's surface points (or, for the weighted-gap rows, the range of its
 * samples in s->ms) as last computed: a function of its corners only, so a
 * leaf whose corners are bitwise the same gets them again without the
 * samples (done = 0: not computed). */
typedef struct {
  double Xe[24];
  double P[NH_SKULL_MAX_PT][3], xi[NH_SKULL_MAX_PT][3], area[NH_SKULL_MAX_PT];
  int crease[NH_SKULL_MAX_PT];
  int n_pt, done;
  double fraction;        /* the leaf's tissue volume / its volume (integrated cut cells) */
  int own;                /* the points belong to this leaf at xi (integrated cut cell) */
  int ms_first, ms_count; /* its weighted-gap samples in s->ms (NH_SKULL_ROWS_MORTAR) */
} nh_skull_cell;

struct nh_skull {
  nh_domain domain;
  double gap;
  int depth; /* the lattice of the integrated leaves' surface quadrature (NH_CUT_DEPTH) */
  nh_skull_point *p;
  int n, cap;
  nh_skull_cell *cell; /* by cell index of the mesh last built on */
  int n_cell;
  nh_skull_cell *fine; /* the same leaves' points one lattice finer (nh_skull_data_change) */
  int n_fine;
  double force[3]; /* last step's total contact force on the tissue, N */
  int active;      /* rows with λ > 0 in the last step */
  nh_skull_rows_kind kind;
  /* the weighted-gap rows' data (NH_SKULL_ROWS_MORTAR) */
  nh_skull_msample *ms; /* every leaf's surface samples */
  int n_ms, cap_ms;
  double *ms_g;        /* per sample: gap − φ_skull(x_q) at the last evaluation */
  double *ms_dir;      /* 3 per sample: −∇U/|∇U| at x_q */
  nh_skull_weight *mq; /* rows' samples */
  nh_skull_weight *mt; /* rows' tissue nodes */
  int n_mq, cap_mq, n_mt, cap_mt;
  double dropped; /* area of samples whose rows were dropped (only small leaves) */
  /* the screen of nh_skull_rows_mortar: the displacement the rows' g_ref were
   * evaluated at (n_ref nodes; 0: none since the build), and per sample the
   * call that last evaluated it */
  double *u_ref;
  int n_ref, stamp;
  int *ms_stamp;
};

int nh_skull_create(const nh_domain *domain, double gap, nh_skull **out) {
  *out = NULL;
  NH_CHECK(domain->kind != NH_DOMAIN_BOX, NH_ERR_INPUT,
           "skull contact needs an immersed domain (its surface is the domain's implicit one)");
  NH_CHECK(gap >= 0.0 && isfinite(gap), NH_ERR_INPUT, "skull gap %g must be >= 0", gap);
  nh_skull *s = nh_calloc(1, sizeof *s);
  if (!s) return NH_ERR_MEMORY;
  s->domain = *domain;
  s->gap = gap;
  s->depth = NH_CUT_DEPTH;
  /* diagnostic (docs/dbs.md, "Effectivity of the estimates"): the points
   * from another lattice, e.g. NH_SKULL_DEPTH=3 for the constraint-data
   * term's measured counterpart */
  const char *env = getenv("NH_SKULL_DEPTH");
  if (env && *env) {
    char *end = NULL;
    long d = strtol(env, &end, 10);
    if (*end == '\0') nh_skull_set_depth(s, (int)d);
  }
  *out = s;
  return NH_OK;
}

int nh_skull_set_depth(nh_skull *s, int depth) {
  NH_CHECK(depth >= 0 && depth < NH_CUT_DEPTH_MAX, NH_ERR_INPUT,
           "skull points: lattice depth %d outside 0..%d", depth, NH_CUT_DEPTH_MAX - 1);
  s->depth = depth;
  s->n_cell = s->n_fine = 0; /* every leaf's points again */
  return NH_OK;
}

void nh_skull_set_rows(nh_skull *s, nh_skull_rows_kind kind) {
  if (s->kind != kind) s->n_cell = 0; /* the leaves' cache holds the other kind's data */
  s->kind = kind;
}

void nh_skull_destroy(nh_skull **skull) {
  if (!skull || !*skull) return;
  free((*skull)->p);
  free((*skull)->cell);
  free((*skull)->fine);
  free((*skull)->ms), free((*skull)->ms_g), free((*skull)->ms_dir), free((*skull)->ms_stamp);
  free((*skull)->u_ref);
  free((*skull)->mq), free((*skull)->mt);
  free(*skull);
  *skull = NULL;
}

/* f / |g| and the unit vector g / |g| (+z where g vanishes). */
static double nh_skull_normalise(double f, double g[3], double n[3]) {
  double len = sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  if (!(len > 0)) len = 1.0, g[0] = g[1] = 0.0, g[2] = 1.0;
  for (int k = 0; k < 3; k++) n[k] = g[k] / len;
  return f / len;
}

/* The tissue's φ = F/|∇F| and its outward unit normal at x: where the
 * contact points are (on F = 0, the fissure's walls and floor included). */
static double nh_skull_distance(const nh_domain *d, const double x[3], double n[3]) {
  double g[3], f = nh_domain_gradient(d, x, g);
  return nh_skull_normalise(f, g, n);
}

/* The skull's level function φ_skull = U/|∇U| (U the domain's outer hull,
 * nh_domain_hull_level: the brain's F without its fissure, F itself for a
 * mask or surface) and its outward unit normal at x: the skull is
 * {φ_skull ≥ gap}. */
static double nh_skull_wall(const nh_domain *d, const double x[3], double n[3]) {
  double g[3], f = nh_domain_hull_gradient(d, x, g);
  return nh_skull_normalise(f, g, n);
}

double nh_skull_level(const nh_skull *s, const double x[3], double n[3]) {
  return nh_skull_wall(&s->domain, x, n);
}

/* A sample of a leaf's surface: its weight (m², the area it stands for),
 * a physical point near F = 0 and the outward unit normal there. */
typedef struct {
  double w, x[3], n[3];
} nh_skull_sample;

/* The clusters of a leaf's samples (docs/theory.md §5c, "Skull contact
 * points"): one if every normal lies within 45° of their weighted mean
 * (a smooth piece of surface), else one per dominant direction of the
 * normal, ±x, ±y, ±z (the largest |n_k|, ties to the lower k: the split
 * is mirror symmetric). Two walls of a slot narrower than the leaf (the
 * longitudinal fissure) or the faces of a crease have normals far apart:
 * their common mean lies in the gap, where F/|∇F| is no distance (∇F
 * vanishes on the gap's mid-plane). cls[q] in [0, n); returns n >= 1. */
static int nh_skull_cluster(const nh_skull_sample *smp, int n, int *cls) {
  double m[3] = {0, 0, 0};
  for (int q = 0; q < n; q++)
    for (int k = 0; k < 3; k++) m[k] += smp[q].w * smp[q].n[k];
  double len = sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2]), wsum = 0.0;
  for (int q = 0; q < n; q++) wsum += smp[q].w;
  int coherent = len > NH_SKULL_COS_CLUSTER * wsum;
  for (int q = 0; q < n && coherent; q++)
    coherent =
        smp[q].n[0] * m[0] + smp[q].n[1] * m[1] + smp[q].n[2] * m[2] >= NH_SKULL_COS_CLUSTER * len;
  if (coherent) {
    for (int q = 0; q < n; q++) cls[q] = 0;
    return 1;
  }
  int id[NH_SKULL_CLUSTERS], n_cls = 0;
  for (int c = 0; c < NH_SKULL_CLUSTERS; c++) id[c] = -1;
  for (int q = 0; q < n; q++) {
    int k = 0;
    for (int j = 1; j < 3; j++)
      if (fabs(smp[q].n[j]) > fabs(smp[q].n[k])) k = j;
    const int c = 2 * k + (smp[q].n[k] < 0.0);
    if (id[c] < 0) id[c] = n_cls++;
    cls[q] = id[c];
  }
  return n_cls;
}

/* x moved onto F = 0 along the normal by three steps x ← x − φ(x) n(x);
 * 1 if that moved it by at most a quarter of the leaf's edge and left
 * |φ| <= 1e-6 of it. */
static int nh_skull_project(const nh_domain *d, const double x[3], double edge, double P[3]) {
  double phi = 0.0, move2 = 0.0, nrm[3];
  memcpy(P, x, 3 * sizeof *P);
  for (int it = 0; it < 3; it++) {
    phi = nh_skull_distance(d, P, nrm);
    for (int k = 0; k < 3; k++) P[k] -= phi * nrm[k];
  }
  phi = nh_skull_distance(d, P, nrm);
  for (int k = 0; k < 3; k++) move2 += (P[k] - x[k]) * (P[k] - x[k]);
  return sqrt(move2) <= 0.25 * edge && fabs(phi) <= 1e-6 * edge;
}

/* The point of a cluster, sample q taken with the fraction part[q] of its
 * weight (0: not in the cluster; ½: a sample shared by the two sides of a
 * crease): its area A = Σ part_q w_q, at the weighted mean of its samples
 * projected onto F = 0 (nh_skull_project). Where that fails, the mean was
 * no place to project from (a cluster around a sharp edge): the cluster's
 * sample nearest the mean, projected the same way (kept even if that fails
 * too: beside a crease seen from inside, where the normal flips from step
 * to step, `scaled`'s points may stay up to a few tenths of a millimetre
 * inside). */
static double nh_skull_cluster_point(const nh_domain *d, const nh_skull_sample *smp, int n,
                                     const double *part, double edge, double P[3]) {
  double a = 0.0, mean[3] = {0, 0, 0};
  for (int q = 0; q < n; q++) {
    if (!(part[q] > 0.0)) continue;
    a += part[q] * smp[q].w;
    for (int k = 0; k < 3; k++) mean[k] += part[q] * smp[q].w * smp[q].x[k];
  }
  if (!(a > 0.0)) return 0.0;
  for (int k = 0; k < 3; k++) mean[k] /= a;
  if (nh_skull_project(d, mean, edge, P)) return a;
  double near[3], best = INFINITY;
  for (int q = 0; q < n; q++) {
    if (!(part[q] > 0.0)) continue;
    double d2 = 0.0;
    for (int k = 0; k < 3; k++) d2 += (smp[q].x[k] - mean[k]) * (smp[q].x[k] - mean[k]);
    if (d2 < best) best = d2, memcpy(near, smp[q].x, sizeof near);
  }
  nh_skull_project(d, near, edge, P);
  return a;
}

/* The normals of F on the two sides of a crease through x, if one runs
 * there (docs/theory.md §5c, "Points on a crease"): along the axis k whose
 * normals n(x − s e_k), n(x + s e_k) (s = NH_SKULL_KINK_STEP × edge) are
 * furthest apart, when they are more than 2° apart (ties to the lower k, so
 * a crease on a mirror plane x = c is found along x). Returns cos of their
 * angle (1: none). */
static double nh_skull_kink(const nh_domain *d,
                            double (*level)(const nh_domain *, const double *, double *),
                            const double x[3], double edge, double na[3], double nb[3]) {
  const double step = NH_SKULL_KINK_STEP * edge;
  double worst = 1.0;
  for (int k = 0; k < 3; k++) {
    double xm[3], xp[3], nm[3], np[3];
    memcpy(xm, x, sizeof xm), memcpy(xp, x, sizeof xp);
    xm[k] -= step, xp[k] += step;
    level(d, xm, nm);
    level(d, xp, np);
    const double c = nm[0] * np[0] + nm[1] * np[1] + nm[2] * np[2];
    if (c < worst && c < NH_SKULL_COS_KINK)
      worst = c, memcpy(na, nm, sizeof nm), memcpy(nb, np, sizeof np);
  }
  return worst;
}

/* cos of the angle of the sharper crease through P or through its skull
 * point P + gap n(P) (1: neither is on a crease), and m = na − nb, the
 * normal of that crease's bisecting plane. */
static double nh_skull_crease(const nh_domain *d, double gap, const double P[3], double edge,
                              double m[3]) {
  double Q[3], nrm[3], na[3], nb[3], ma[3], mb[3];
  nh_skull_distance(d, P, nrm);
  for (int k = 0; k < 3; k++) Q[k] = P[k] + gap * nrm[k];
  const double cp = nh_skull_kink(d, nh_skull_distance, P, edge, na, nb),
               cq = nh_skull_kink(d, nh_skull_wall, Q, edge, ma, mb);
  for (int k = 0; k < 3; k++) m[k] = cp <= cq ? na[k] - nb[k] : ma[k] - mb[k];
  return fmin(cp, cq);
}

/* The next point of leaf f: position P, area, whether it is on a crease. */
static void nh_skull_cell_add(const double P[3], double area, int crease, nh_skull_cell *f) {
  memcpy(f->P[f->n_pt], P, 3 * sizeof *P);
  f->area[f->n_pt] = area;
  f->crease[f->n_pt++] = crease;
}

/* The clustered points of a leaf's samples: n_pt points P with areas.
 * A point on a crease gets the row direction of whichever side round-off
 * puts it on, and that direction pushes it further that way where the
 * crease is a ridge of the skull: the lateral force grows like λ δ / ε
 * with the point's lateral offset δ (ε the gradient's difference step,
 * 1e-7 m), an unstable mode that grew 1e3-fold per step on the odd grids
 * (docs/dbs.md). So a cluster whose point P lies on a crease of F, or
 * whose skull point P + gap n(P) does (the offset of a smooth piece of
 * surface may have one: beside the brainstem, the hemispheres' crease
 * 1 mm out), gives one point per side instead: each sample goes to the
 * side of the crease's bisecting plane (normal na − nb through P) it lies
 * on, half to each if on it, so a leaf symmetric about a mirror plane
 * through the crease keeps mirror-symmetric points. A point still on a
 * crease after that (a sliver of surface within 1e-3 edges of a sharp
 * notch) is flagged: its row keeps the rest normal. */
static int nh_skull_cell_points(const nh_domain *d, double gap, const nh_skull_sample *smp, int n,
                                int *cls, double edge, nh_skull_cell *f) {
  f->n_pt = 0;
  if (n == 0) return NH_OK;
  const int n_cls = nh_skull_cluster(smp, n, cls);
  double *part = nh_calloc(2 * (size_t)n, sizeof *part);
  if (!part) return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull points");
  double *side = part + n;
  for (int c = 0; c < n_cls; c++) {
    for (int q = 0; q < n; q++) part[q] = cls[q] == c;
    double P[3], m[3];
    const double a = nh_skull_cluster_point(d, smp, n, part, edge, P);
    if (!(a > 0.0)) continue;
    const int crease = nh_skull_crease(d, gap, P, edge, m) < 1.0;
    if (crease) {
      double tie = 0.0;
      for (int k = 0; k < 3; k++) tie += fabs(m[k]);
      tie *= 1e-9 * edge; /* on the plane up to P's round-off */
      for (int q = 0; q < n; q++) {
        if (cls[q] != c) {
          part[q] = side[q] = 0.0;
          continue;
        }
        double t = 0.0;
        for (int k = 0; k < 3; k++) t += (smp[q].x[k] - P[k]) * m[k];
        part[q] = t > tie ? 1.0 : (t < -tie ? 0.0 : 0.5);
        side[q] = 1.0 - part[q];
      }
      double Pa[3], Pb[3];
      const double aa = nh_skull_cluster_point(d, smp, n, part, edge, Pa),
                   ab = nh_skull_cluster_point(d, smp, n, side, edge, Pb);
      if (aa > 0.0 && ab > 0.0) {
        double unused[3];
        nh_skull_cell_add(Pa, aa, nh_skull_crease(d, gap, Pa, edge, unused) < 1.0, f);
        nh_skull_cell_add(Pb, ab, nh_skull_crease(d, gap, Pb, edge, unused) < 1.0, f);
        continue;
      }
    }
    nh_skull_cell_add(P, a, crease, f);
  }
  free(part);
  return NH_OK;
}

/* Where a leaf's samples go for the weighted-gap rows: the skull and the
 * leaf (NULL: nowhere). */
typedef struct {
  nh_skull *s;
  int leaf;
  const double *Xe;
} nh_skull_keep;

/* Append a leaf's n samples to k->s's weighted-gap samples: each moved onto
 * F = 0 along its normal (nh_skull_project; kept where it was if that
 * fails), with its natural coordinates in the leaf and whether it lies on a
 * crease. small: the leaf holds less than NH_FILL_MIN of tissue.
 * NH_ERR_MEMORY. */
static int nh_skull_keep_samples(const nh_skull_keep *k, const nh_skull_sample *smp, int n,
                                 double edge, int small) {
  nh_skull *s = k->s;
  for (int q = 0; q < n; q++) {
    if (s->n_ms >= s->cap_ms && nh_grow((void **)&s->ms, &s->cap_ms, s->n_ms + 1, sizeof *s->ms))
      return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull samples");
    nh_skull_msample *m = &s->ms[s->n_ms];
    if (!nh_skull_project(&s->domain, smp[q].x, edge, m->X)) memcpy(m->X, smp[q].x, sizeof m->X);
    if (nh_hex_invert(k->Xe, m->X, m->xi) != NH_OK) continue;
    nh_skull_distance(&s->domain, m->X, m->n);
    double unused[3];
    m->crease = nh_skull_crease(&s->domain, s->gap, m->X, edge, unused) < 1.0;
    m->w = smp[q].w, m->cell = k->leaf, m->small = small, m->edge = edge;
    s->n_ms++;
  }
  return NH_OK;
}

/* The surface points of leaf Xe (n_pt = 0 if the surface misses it) from
 * n³ sub-cell midpoints (n = 6 << fine) and the one-sided smeared delta. */
static int nh_cell_surface(const nh_domain *d, double gap, const double Xe[24], int fine,
                           nh_skull_cell *f, const nh_skull_keep *keep) {
  const int n = 6 << fine;
  double edge = 0.0;
  for (int k = 0; k < 3; k++) edge = fmax(edge, fabs(Xe[18 + k] - Xe[k]));
  const double eps = 1.5 * edge / n;
  nh_skull_sample *smp = nh_calloc((size_t)(n * n * n), sizeof *smp);
  int *cls = nh_calloc((size_t)(n * n * n), sizeof *cls), ns = 0;
  if (!smp || !cls) {
    free(smp), free(cls);
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull points");
  }
  for (int i = 0; i < n; i++)
    for (int j = 0; j < n; j++)
      for (int k = 0; k < n; k++) {
        double xi[3] = {-1 + (2 * i + 1.0) / n, -1 + (2 * j + 1.0) / n, -1 + (2 * k + 1.0) / n};
        double N[8], dN[8][3], x[3] = {0, 0, 0}, J[9] = {0}, nrm[3];
        nh_hex_shape(xi, N);
        nh_hex_dshape(xi, dN);
        for (int a = 0; a < 8; a++)
          for (int p = 0; p < 3; p++) {
            x[p] += N[a] * Xe[3 * a + p];
            for (int q = 0; q < 3; q++) J[3 * p + q] += Xe[3 * a + p] * dN[a][q];
          }
        double phi = nh_skull_distance(d, x, nrm);
        if (phi > 0.0) continue; /* one-sided: outside may be a dropped cell */
        double w =
            2.0 * fmax(0.0, 1.0 + phi / eps) / eps * fabs(nh_mat3_det(J)) * 8.0 / (n * n * n);
        if (w == 0.0) continue;
        nh_skull_sample *s = &smp[ns++];
        s->w = w;
        for (int p = 0; p < 3; p++) s->x[p] = x[p] - phi * nrm[p], s->n[p] = nrm[p];
      }
  int rc = keep ? nh_skull_keep_samples(keep, smp, ns, edge, 0)
                : nh_skull_cell_points(d, gap, smp, ns, cls, edge, f);
  free(smp), free(cls);
  return rc;
}

/* The surface points of an integrated box leaf [lo, hi] from the cut-cell
 * quadrature at lattice depth `depth` (n_pt = 0 if the surface misses the leaf): positions P on
 * F = 0, natural coordinates xi in the leaf, areas; and its tissue
 * fraction. */
static int nh_cell_cut_surface(const nh_domain *d, double gap, int depth, const double lo[3],
                               const double hi[3], nh_skull_cell *f, const nh_skull_keep *keep) {
  nh_cut_spec spec;
  nh_cut_spec_domain(&spec, d, depth);
  nh_cut_moments mom;
  nh_cut_surface surf = {0, 0, NULL};
  int rc = nh_cut_cell(&spec, lo, hi, &mom, &surf, 0u);
  nh_skull_sample *smp = rc ? NULL : nh_calloc((size_t)(surf.n ? surf.n : 1), sizeof *smp);
  int *cls = smp ? nh_calloc((size_t)(surf.n ? surf.n : 1), sizeof *cls) : NULL;
  if (!rc && !cls) rc = NH_ERR_MEMORY;
  int ns = 0;
  double edge = 0.0;
  for (int k = 0; k < 3; k++) edge = fmax(edge, hi[k] - lo[k]);
  for (int q = 0; q < surf.n && !rc; q++) {
    const nh_cut_point *p = &surf.point[q];
    if (p->piece != -1) continue;
    const double w =
        sqrt(p->area[0] * p->area[0] + p->area[1] * p->area[1] + p->area[2] * p->area[2]);
    if (!(w > 0.0)) continue;
    nh_skull_sample *s = &smp[ns++];
    s->w = w;
    for (int k = 0; k < 3; k++)
      s->x[k] = 0.5 * (lo[k] + hi[k]) + 0.5 * (hi[k] - lo[k]) * p->xi[k], s->n[k] = p->area[k] / w;
  }
  nh_cut_surface_free(&surf);
  f->fraction = mom.volume / ((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]));
  if (!rc && keep)
    rc = nh_skull_keep_samples(keep, smp, ns, edge, f->fraction < NH_FILL_MIN);
  else if (!rc)
    rc = nh_skull_cell_points(d, gap, smp, ns, cls, edge, f);
  free(smp), free(cls);
  for (int i = 0; i < f->n_pt && !rc; i++)
    for (int k = 0; k < 3; k++) f->xi[i][k] = (2.0 * f->P[i][k] - lo[k] - hi[k]) / (hi[k] - lo[k]);
  return rc;
}

/* Aggregation of small cut parts: a point whose leaf holds less than
 * NH_FILL_MIN of its volume in tissue gives its area to the nearest point
 * of a leaf that holds more and faces the same way (outward normals less
 * than 90° apart: not the opposite wall of a slot; the nearest of any
 * normal if none does), and is dropped. Such a leaf's outer nodes are held
 * by the stabilisation α alone (and carry almost no mass): a contact row
 * there is met by moving them, not the tissue (a node 1 m away in one
 * step, tests/skull_force.py). The total area is kept. */
/* The point of p[first ..= last], not small, nearest to X among those whose
 * outward normal is less than 90° from N (the nearest of any if none is);
 * −1 if there is none. */
static int nh_skull_nearest_facing(const nh_skull_point *p, int first, int last, const double X[3],
                                   const double N[3]) {
  int best = -1, best_facing = 0;
  double d2best = INFINITY;
  for (int j = first; j <= last; j++) {
    if (p[j].small) continue;
    double d2 = 0.0, dot = 0.0;
    for (int k = 0; k < 3; k++)
      d2 += (p[j].X[k] - X[k]) * (p[j].X[k] - X[k]), dot += p[j].N[k] * N[k];
    const int facing = dot > 0.0;
    if (facing > best_facing || (facing == best_facing && d2 < d2best))
      d2best = d2, best = j, best_facing = facing;
  }
  return best;
}

static void nh_skull_merge_small(nh_skull *s) {
  int n = 0;
  for (int i = 0; i < s->n; i++) {
    if (!s->p[i].small) continue;
    const int best = nh_skull_nearest_facing(s->p, 0, s->n - 1, s->p[i].X, s->p[i].N);
    if (best < 0) return; /* no leaf holds enough tissue: keep every point */
    s->p[best].area += s->p[i].area;
    s->p[i].area = 0.0;
  }
  for (int i = 0; i < s->n; i++)
    if (s->p[i].area > 0.0) s->p[n++] = s->p[i];
  s->n = n;
}

/* The points of leaf Xe: from the lattice s->depth + finer (integrated box
 * leaves), else from (6 << finer)³ sub-cells. */
static int nh_skull_leaf(const nh_skull *s, const double Xe[24], int finer, nh_skull_cell *f,
                         const nh_skull_keep *keep) {
  double lo[3], hi[3];
  memset(f, 0, sizeof *f);
  memcpy(f->Xe, Xe, sizeof f->Xe);
  f->own = nh_domain_integrates_cuts(&s->domain) && nh_hex_is_box(Xe, lo, hi);
  NH_TRY(f->own ? nh_cell_cut_surface(&s->domain, s->gap, s->depth + finer, lo, hi, f, keep)
                : nh_cell_surface(&s->domain, s->gap, Xe, finer, f, keep));
  f->done = 1;
  return NH_OK;
}

/* A node's share of a sample (node, sample, N_a(X_q)), sorted by node. */
typedef struct {
  int node, q;
  double N;
} nh_skull_share;

/* Add c to node's coefficient in the row's tissue part s->mt[first ..< s->n_mt];
 * at[node]: its place there, or −1 (reset by the caller when the row is done). */
static int nh_skull_add_node(nh_skull *s, int *at, int node, double c) {
  if (at[node] >= 0) {
    s->mt[at[node]].c += c;
    return NH_OK;
  }
  if (s->n_mt >= s->cap_mt && nh_grow((void **)&s->mt, &s->cap_mt, s->n_mt + 1, sizeof *s->mt))
    return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull rows");
  at[node] = s->n_mt;
  s->mt[s->n_mt++] = (nh_skull_weight){node, c};
  return NH_OK;
}

/* The weighted-gap rows (docs/theory.md §5c, "Weighted-gap rows"): every
 * leaf's surface samples (w_q, X_q, n_q), and for every node a whose shape
 * function sees some, per cluster of their normals (nh_skull_cluster with
 * the weights w_q N_a(X_q): the fissure's two walls or the faces of a
 * crease apart), one row
 *   D_a = Σ_q w_q N_a(X_q),   g_a = Σ_q (w_q N_a(X_q) / D_a) g(x_q),
 *   tissue part Σ_b c_ab u_b,  c_ab = Σ_q (w_q N_a(X_q) / D_a) N_b(X_q)  (Σ_b c_ab = 1),
 * the gap's average over the node's surface patch and the displacement's
 * average there (its linearisation with one direction, the weighted
 * normal). A row whose samples all lie in leaves with less than NH_FILL_MIN
 * tissue is dropped (its nodes are held by the stabilisation alone; its
 * area is counted in s->dropped). */
static int nh_skull_build_mortar(nh_skull *s, const nh_mesh *m) {
  s->n = s->n_mq = s->n_mt = 0;
  s->dropped = 0.0;
  /* each leaf's samples: copied from the last build where its corners are
   * the same (after a refinement, all but the new leaves), else computed;
   * in the leaves' order either way, so the rows do not depend on the cache */
  nh_skull_msample *old = s->ms;
  s->ms = NULL, s->n_ms = s->cap_ms = 0;
  nh_skull_cell *fresh = nh_calloc((size_t)(m->n_cells ? m->n_cells : 1), sizeof *fresh);
  int rc = fresh ? NH_OK : NH_ERROR(NH_ERR_MEMORY, "out of memory: skull samples");
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    const int c = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_skull_cell *f = &fresh[c];
    const int first = s->n_ms;
    if (c < s->n_cell && s->cell[c].done && !memcmp(s->cell[c].Xe, Xe, sizeof Xe)) {
      *f = s->cell[c];
      const int n = f->ms_count;
      if (n && nh_grow((void **)&s->ms, &s->cap_ms, s->n_ms + n, sizeof *s->ms))
        rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: skull samples");
      else if (n)
        memcpy(s->ms + s->n_ms, old + f->ms_first, (size_t)n * sizeof *s->ms), s->n_ms += n;
    } else {
      const nh_skull_keep keep = {s, c, Xe};
      rc = nh_skull_leaf(s, Xe, 0, f, &keep);
    }
    f->ms_first = first, f->ms_count = s->n_ms - first;
  }
  free(old);
  free(s->cell);
  s->cell = fresh, s->n_cell = fresh ? m->n_cells : 0;
  NH_TRY(rc);
  NH_TRY(nh_realloc((void **)&s->ms_g, (size_t)(s->n_ms ? s->n_ms : 1), sizeof *s->ms_g));
  NH_TRY(nh_realloc((void **)&s->ms_dir, 3 * (size_t)(s->n_ms ? s->n_ms : 1), sizeof *s->ms_dir));
  NH_TRY(nh_realloc((void **)&s->ms_stamp, (size_t)(s->n_ms ? s->n_ms : 1), sizeof *s->ms_stamp));
  memset(s->ms_stamp, 0, (size_t)(s->n_ms ? s->n_ms : 1) * sizeof *s->ms_stamp);
  s->n_ref = s->stamp = 0;
  const int n_share = 8 * s->n_ms;
  nh_skull_share *sh = nh_calloc((size_t)(n_share ? n_share : 1), sizeof *sh);
  nh_skull_share *by_q = nh_calloc((size_t)(n_share ? n_share : 1), sizeof *by_q);
  int *at = nh_calloc((size_t)m->n_nodes + 1, sizeof *at);
  nh_skull_sample *smp = nh_calloc((size_t)(n_share ? n_share : 1), sizeof *smp);
  int *cls = nh_calloc((size_t)(n_share ? n_share : 1), sizeof *cls), n_sh = 0;
  if (!sh || !by_q || !at || !smp || !cls)
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: skull rows");
  for (int q = 0; q < s->n_ms && !rc; q++) {
    double N[8];
    nh_hex_shape(s->ms[q].xi, N);
    for (int a = 0; a < 8; a++)
      /* N_a < 0 too (a sample projected a little out of its leaf): the
       * shares of a sample sum to 1, so Σ_a D_a = Σ_q w_q */
      if (N[a] != 0.0) {
        by_q[n_sh++] = (nh_skull_share){m->cells[8 * s->ms[q].cell + a], q, N[a]};
        at[m->cells[8 * s->ms[q].cell + a] + 1]++;
      }
  }
  /* sorted by node, then sample: a counting sort by node of the shares,
   * which come in the samples' order (a sample's 8 nodes differ) */
  for (int b = 0; b < m->n_nodes && !rc; b++) at[b + 1] += at[b];
  for (int j = 0; j < n_sh && !rc; j++) sh[at[by_q[j].node]++] = by_q[j];
  for (int b = 0; b <= m->n_nodes && !rc; b++) at[b] = -1; /* now: a node's place in a row */
  free(by_q);
  for (int first = 0, last; first < n_sh && !rc; first = last) {
    for (last = first; last < n_sh && sh[last].node == sh[first].node; last++) {
      const nh_skull_msample *ms = &s->ms[sh[last].q];
      nh_skull_sample *t = &smp[last - first];
      t->w = ms->w * sh[last].N;
      memcpy(t->x, ms->X, sizeof t->x), memcpy(t->n, ms->n, sizeof t->n);
    }
    const int n = last - first, n_cls = nh_skull_cluster(smp, n, cls);
    for (int k = 0; k < n_cls && !rc; k++) {
      double D = 0.0, healthy = 0.0;
      for (int j = 0; j < n; j++)
        if (cls[j] == k) D += smp[j].w, healthy += s->ms[sh[first + j].q].small ? 0.0 : smp[j].w;
      if (!(D > 0.0) || !(healthy > 0.0)) {
        s->dropped += D;
        continue;
      }
      if (s->n >= s->cap && nh_grow((void **)&s->p, &s->cap, s->n + 1, sizeof *s->p)) {
        rc = NH_ERR_MEMORY;
        break;
      }
      nh_skull_point *p = &s->p[s->n++];
      memset(p, 0, sizeof *p);
      p->row = p->leaf = -1;
      p->area = D;
      p->q_first = s->n_mq, p->t_first = s->n_mt;
      double nrm[3] = {0, 0, 0}, wmax = -1.0;
      for (int j = 0; j < n && !rc; j++) {
        if (cls[j] != k) continue;
        const nh_skull_msample *ms = &s->ms[sh[first + j].q];
        const double c = smp[j].w / D;
        for (int d = 0; d < 3; d++) p->X[d] += c * ms->X[d], nrm[d] += c * ms->n[d];
        if (smp[j].w > wmax)
          wmax = smp[j].w, p->cell = ms->cell, memcpy(p->xi, ms->xi, sizeof p->xi);
        double N[8];
        p->edge = fmax(p->edge, ms->edge);
        if (s->n_mq >= s->cap_mq &&
            nh_grow((void **)&s->mq, &s->cap_mq, s->n_mq + 1, sizeof *s->mq)) {
          rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: skull rows");
          break;
        }
        s->mq[s->n_mq++] = (nh_skull_weight){sh[first + j].q, c};
        p->c_abs += fabs(c);
        nh_hex_shape(ms->xi, N);
        for (int b = 0; b < 8 && !rc; b++)
          rc = nh_skull_add_node(s, at, m->cells[8 * ms->cell + b], c * N[b]);
      }
      for (int j = p->t_first; j < s->n_mt; j++) at[s->mt[j].i] = -1;
      nh_skull_normalise(0.0, nrm, p->N);
      p->q_count = s->n_mq - p->q_first, p->t_count = s->n_mt - p->t_first;
    }
  }
  free(sh), free(at), free(smp), free(cls);
  return rc;
}

/* The current gap g(x_q) = gap − φ_skull(x_q) and inward direction
 * −∇U/|∇U| at x_q = X_q + u(X_q) of sample q; on a crease, at X_q (a
 * direction from round-off's side of the crease turns a row on a skull
 * ridge into a negative lateral stiffness: the odd grids' mirror symmetry
 * lost, 1e4-fold per step; docs/theory.md §5c, "Points on a crease"). */
static double nh_skull_sample_gap(const nh_skull *s, const nh_mesh *m, const double *u, int q,
                                  double dir[3]) {
  const nh_skull_msample *ms = &s->ms[q];
  double N[8], x[3], nrm[3];
  nh_hex_shape(ms->xi, N);
  const int *e = m->cells + 8 * ms->cell;
  for (int k = 0; k < 3; k++) {
    x[k] = ms->X[k];
    for (int a = 0; a < 8; a++) x[k] += N[a] * u[3 * e[a] + k];
  }
  const double g = s->gap - nh_skull_wall(&s->domain, x, nrm);
  if (ms->crease) nh_skull_wall(&s->domain, ms->X, nrm);
  for (int k = 0; k < 3; k++) dir[k] = -nrm[k];
  return g;
}

/* Weighted-gap row i's gap and unit inward direction at u, from the samples'
 * gaps and directions g_q, dir_q (NULL: evaluated here). */
static double nh_skull_row_gap(const nh_skull *s, const nh_mesh *m, const double *u, int i,
                               const double *g_q, const double *dir_q, double dir[3]) {
  const nh_skull_point *p = &s->p[i];
  double g = 0.0, sum[3] = {0, 0, 0};
  for (int j = p->q_first; j < p->q_first + p->q_count; j++) {
    const int q = s->mq[j].i;
    double d[3], gq;
    if (g_q && dir_q)
      gq = g_q[q], memcpy(d, dir_q + 3 * q, sizeof d);
    else
      gq = nh_skull_sample_gap(s, m, u, q, d);
    g += s->mq[j].c * gq;
    for (int k = 0; k < 3; k++) sum[k] += s->mq[j].c * d[k];
  }
  nh_skull_normalise(0.0, sum, dir);
  return g;
}

int nh_skull_weighted_gaps(const nh_skull *s, const nh_mesh *m, const double *u,
                           nh_skull_row_info *out, double *dropped) {
  if (dropped) *dropped = s->kind == NH_SKULL_ROWS_MORTAR ? s->dropped : 0.0;
  if (s->kind != NH_SKULL_ROWS_MORTAR) return 0;
  for (int i = 0; i < s->n; i++) {
    out[i].g = nh_skull_row_gap(s, m, u, i, NULL, NULL, out[i].dir);
    memcpy(out[i].X, s->p[i].X, sizeof out[i].X);
    out[i].area = s->p[i].area;
  }
  return s->n;
}

int nh_skull_build(nh_skull *s, const nh_mesh *m) {
  if (s->kind == NH_SKULL_ROWS_MORTAR) return nh_skull_build_mortar(s, m);
  s->n = 0;
  /* each leaf's points: kept from the last build where its corners are the
   * same (after a refinement, all but the new leaves), else computed */
  nh_skull_cell *fresh = nh_calloc((size_t)(m->n_cells ? m->n_cells : 1), sizeof *fresh);
  if (!fresh) return NH_ERR_MEMORY;
  for (int l = 0; l < m->n_leaves; l++) {
    int c = m->leaves[l];
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_skull_cell *f = &fresh[c];
    if (c < s->n_cell && s->cell[c].done && !memcmp(s->cell[c].Xe, Xe, sizeof Xe)) {
      *f = s->cell[c];
    } else {
      int rc = nh_skull_leaf(s, Xe, 0, f, NULL);
      if (rc) {
        free(fresh);
        return rc;
      }
    }
    double edge = 0.0;
    for (int k = 0; k < 3; k++) edge = fmax(edge, fabs(Xe[18 + k] - Xe[k]));
    for (int i = 0; i < f->n_pt; i++) {
      double xi[3];
      int cell;
      /* A point of the smeared delta may lie in a neighbour: locate it (it
       * is on the surface, so inside a kept cell unless round-off puts it
       * just outside). */
      if (f->own) {
        cell = c;
        memcpy(xi, f->xi[i], sizeof xi);
      } else if (nh_mesh_locate(m, f->P[i], &cell, xi) != NH_OK) {
        cell = c;
        if (nh_hex_invert(Xe, f->P[i], xi) != NH_OK) continue;
      }
      if (s->n >= s->cap && nh_grow((void **)&s->p, &s->cap, s->n + 1, sizeof *s->p)) {
        free(fresh);
        return NH_ERR_MEMORY;
      }
      nh_skull_point *p = &s->p[s->n++];
      memcpy(p->X, f->P[i], sizeof p->X);
      nh_skull_distance(&s->domain, p->X, p->N);
      memcpy(p->xi, xi, sizeof xi);
      p->area = f->area[i], p->cell = cell, p->lam = 0.0, p->row = -1;
      p->small = f->own && f->fraction < NH_FILL_MIN;
      p->crease = f->crease[i];
      p->edge = edge;
      p->leaf = c;
    }
  }
  free(s->cell);
  s->cell = fresh, s->n_cell = m->n_cells;
  nh_skull_merge_small(s);
  return NH_OK;
}

int nh_skull_points(const nh_skull *s) {
  return s->n;
}

double nh_skull_area(const nh_skull *s) {
  double a = 0.0;
  for (int i = 0; i < s->n; i++) a += s->p[i].area;
  return a;
}

/* Current position of point p. */
static void nh_skull_position(const nh_mesh *m, const double *u, const nh_skull_point *p,
                              double x[3], double N[8]) {
  nh_hex_shape(p->xi, N);
  const int *e = m->cells + 8 * p->cell;
  for (int k = 0; k < 3; k++) {
    x[k] = p->X[k];
    for (int a = 0; a < 8; a++) x[k] += N[a] * u[3 * e[a] + k];
  }
}

double nh_skull_penetration(const nh_skull *s, const nh_mesh *m, const double *u) {
  double worst = 0.0;
  for (int i = 0; i < s->n; i++) {
    double x[3], N[8], nrm[3];
    if (s->kind == NH_SKULL_ROWS_MORTAR) {
      worst = fmax(worst, -nh_skull_row_gap(s, m, u, i, NULL, NULL, nrm));
      continue;
    }
    nh_skull_position(m, u, &s->p[i], x, N);
    worst = fmax(worst, nh_skull_wall(&s->domain, x, nrm) - s->gap);
  }
  return worst;
}

/* Row r of point p: unilateral, no tool part, inward direction dir, gap g,
 * warm-started from p's last impulse. */
static void nh_skull_row_set(nh_rows *rows, int r, const double dir[3], double g,
                             nh_skull_point *p) {
  for (int k = 0; k < 3; k++) rows->dir[3 * r + k] = dir[k];
  rows->tool[r] = -1, rows->elem[r] = -1;
  rows->gap[r] = g;
  rows->law[r] = (nh_row_law){NH_ROW_UNILATERAL, -1, -1, 0.0, 0.0, -1, 0.0, 0, 0};
  rows->lambda[r] = p->lam;
  p->row = r;
}

/* The screen of the weighted-gap rows (nh_skull_rows_mortar). Evaluating
 * every sample's gap each step (seven evaluations of the hull level each,
 * for ~150 samples a row) was ~38 % of a run's CPU (12 × 14 × 11 of
 * dbs-skull.yaml, perf), most of it for rows far from the skull that get
 * no row. A sample's gap g(x_q) = gap − φ_skull(x_q) moves by at most
 * L |x_q − x_q,ref| from its value at a reference displacement u_ref, and
 * |x_q − x_q,ref| ≤ Σ_b |N_b(X_q)| d_b with d_b = |u_b − u_ref,b|, Σ |N_b|
 * ≤ NH_SKULL_SCREEN_N (1 inside the leaf; samples projected a little out of
 * it exceed it slightly). So row a's gap is at least
 *   g_a,ref − L NH_SKULL_SCREEN_N c_abs,a max_b d_b  (b over its nodes),
 * and its closing speed vn at most Σ_b |c_ab| |v_b|; a row whose bounds
 * already keep it out (and whose last impulse is 0) is skipped without
 * evaluating its samples: the rows made are exactly those of evaluating
 * all, so the run is unchanged, bit for bit, and needs no state in the
 * checkpoint. L = NH_SKULL_SCREEN_L bounds |∇φ_skull| (φ_skull = U/|∇U|
 * is a distance to first order, |∇φ| ≈ 1 near the surface). It is not a
 * bound everywhere: deep inside the hull, where |∇U| is small, the fissure
 * floor's row at the brain's centre (g_ref = 50 mm) moved 16 mm for
 * 0.05 mm of its nodes (|Δg| / max d ≈ 320); a row so far in stays far, and on
 * dbs-skull.yaml (10 × 12 × 9 to 16 × 19 × 15) no skipped row would have
 * been made (every skipped row checked against its evaluated gap). All rows are evaluated again at
 * the current u (the new u_ref) when a node has moved more than
 * NH_SKULL_SCREEN_MOVE of the smallest row's edge from u_ref. */
#define NH_SKULL_SCREEN_L    2.0
#define NH_SKULL_SCREEN_N    1.5
#define NH_SKULL_SCREEN_MOVE 0.02
/* A weighted-gap row is made when its gap is below twice what its closing
 * speed closes in a step plus NH_SKULL_MORTAR_FLOOR of its edge (or it
 * pushed in the last step). The point rows' floor, 1 % of the edge, made
 * 34 508 candidate rows over the 60 steps of 14 × 17 × 13 (dbs-skull.yaml),
 * 0.1 % 24 344, and the run the same to 1.4e-13 (four grids: ≤ 3e-12,
 * the contact solve's tolerance; docs/dbs.md): the rows within 1 % of an
 * edge of the skull that do not close on it average the gap over a patch
 * in contact and never push. */
#define NH_SKULL_MORTAR_FLOOR 1e-3

/* |u_b − u_ref,b| of node b. */
static double nh_skull_moved(const double *u, const double *u_ref, int b) {
  const double d[3] = {u[3 * b] - u_ref[3 * b], u[3 * b + 1] - u_ref[3 * b + 1],
                       u[3 * b + 2] - u_ref[3 * b + 2]};
  return nh_vec3_norm(d);
}

/* The weighted-gap rows of nh_skull_rows. */
static int nh_skull_rows_mortar(nh_skull *s, const nh_mesh *m, const double *u, const double *v,
                                double h, nh_rows *rows) {
  const int n_nodes = m->n_nodes;
  double move = 0.0, edge = INFINITY;
  if (s->n_ref == n_nodes)
    for (int b = 0; b < n_nodes; b++) move = fmax(move, nh_skull_moved(u, s->u_ref, b));
  for (int i = 0; i < s->n; i++) edge = fmin(edge, s->p[i].edge);
  const int refresh = s->n_ref != n_nodes || move > NH_SKULL_SCREEN_MOVE * edge;
  if (refresh) {
    NH_TRY(nh_realloc((void **)&s->u_ref, 3 * (size_t)(n_nodes ? n_nodes : 1), sizeof *s->u_ref));
    memcpy(s->u_ref, u, 3 * (size_t)n_nodes * sizeof *u);
    s->n_ref = n_nodes;
  }
  s->stamp++;
  for (int i = 0; i < s->n; i++) {
    nh_skull_point *p = &s->p[i];
    double dir[3], vn = 0.0;
    p->row = -1;
    if (!refresh && p->lam == 0.0) {
      double d = 0.0, vmax = 0.0;
      for (int j = p->t_first; j < p->t_first + p->t_count; j++) {
        d = fmax(d, nh_skull_moved(u, s->u_ref, s->mt[j].i));
        vmax += fabs(s->mt[j].c) * nh_vec3_norm(v + 3 * s->mt[j].i);
      }
      const double low = p->g_ref - NH_SKULL_SCREEN_L * NH_SKULL_SCREEN_N * p->c_abs * d;
      if (low > 2.0 * h * vmax + NH_SKULL_MORTAR_FLOOR * p->edge) continue;
    }
    for (int j = p->q_first; j < p->q_first + p->q_count; j++) {
      const int q = s->mq[j].i;
      if (s->ms_stamp[q] != s->stamp)
        s->ms_stamp[q] = s->stamp, s->ms_g[q] = nh_skull_sample_gap(s, m, u, q, s->ms_dir + 3 * q);
    }
    const double g = nh_skull_row_gap(s, m, u, i, s->ms_g, s->ms_dir, dir);
    if (refresh) p->g_ref = g;
    for (int j = p->t_first; j < p->t_first + p->t_count; j++)
      for (int k = 0; k < 3; k++) vn -= s->mt[j].c * v[3 * s->mt[j].i + k] * dir[k];
    if (g > 2.0 * h * fmax(vn, 0.0) + NH_SKULL_MORTAR_FLOOR * p->edge && p->lam == 0.0) continue;
    int r = nh_rows_add(rows);
    if (r < 0) return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull rows");
    NH_TRY(nh_rows_widen(rows, p->t_count));
    for (int j = 0; j < p->t_count; j++)
      rows->node[rows->start[r] + j] = s->mt[p->t_first + j].i,
                                  rows->N[rows->start[r] + j] = s->mt[p->t_first + j].c;
    nh_skull_row_set(rows, r, dir, g, p);
  }
  return NH_OK;
}

int nh_skull_rows(nh_skull *s, const nh_mesh *m, const double *u, const double *v, double h,
                  nh_rows *rows) {
  if (s->kind == NH_SKULL_ROWS_MORTAR) return nh_skull_rows_mortar(s, m, u, v, h, rows);
  for (int i = 0; i < s->n; i++) {
    nh_skull_point *p = &s->p[i];
    double x[3], N[8], nrm[3], vn = 0.0;
    nh_skull_position(m, u, p, x, N);
    double g = s->gap - nh_skull_wall(&s->domain, x, nrm);
    if (p->crease) /* no direction from round-off's side: the skull's at the rest position */
      nh_skull_wall(&s->domain, p->X, nrm);
    const int *e = m->cells + 8 * p->cell;
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++) vn += N[a] * v[3 * e[a] + k] * nrm[k];
    p->row = -1;
    /* closing speed vn > 0 (outwards): twice a step's approach, plus 1 % of
     * the cell as a floor */
    if (g > 2.0 * h * fmax(vn, 0.0) + 0.01 * p->edge && p->lam == 0.0) continue;
    int r = nh_rows_add(rows);
    if (r < 0) return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull rows");
    for (int a = 0; a < 8; a++)
      rows->node[rows->start[r] + a] = m->cells[8 * p->cell + a],
                                  rows->N[rows->start[r] + a] = N[a];
    for (int k = 0; k < 3; k++) nrm[k] = -nrm[k];
    nh_skull_row_set(rows, r, nrm, g, p);
  }
  return NH_OK;
}

void nh_skull_end_step(nh_skull *s, const nh_rows *rows, double h) {
  s->force[0] = s->force[1] = s->force[2] = 0.0;
  s->active = 0;
  for (int i = 0; i < s->n; i++) {
    nh_skull_point *p = &s->p[i];
    if (p->row < 0) {
      p->lam = 0.0;
      continue;
    }
    p->lam = rows->lambda[p->row];
    if (p->lam > 0.0) s->active++;
    for (int k = 0; k < 3; k++) s->force[k] += p->lam * rows->dir[3 * p->row + k] / h;
  }
}

void nh_skull_force(const nh_skull *s, double force[3], int *active) {
  memcpy(force, s->force, sizeof s->force);
  if (active) *active = s->active;
}

int nh_skull_relocate(nh_skull *s, const nh_mesh *m) {
  /* New leaves are smaller: rebuild the points on them (a finer surface
   * sampling), carrying each new point's warm start from the old point
   * nearest to it. */
  int n_old = s->n;
  nh_skull_point *old = nh_calloc((size_t)(n_old ? n_old : 1), sizeof *old);
  if (!old) return NH_ERROR(NH_ERR_MEMORY, "out of memory: skull points");
  memcpy(old, s->p, sizeof *old * (size_t)n_old);
  int rc = nh_skull_build(s, m);
  for (int i = 0; i < s->n && !rc; i++) {
    double best = INFINITY;
    for (int j = 0; j < n_old; j++) {
      double d2 = 0.0;
      for (int k = 0; k < 3; k++) d2 += (old[j].X[k] - s->p[i].X[k]) * (old[j].X[k] - s->p[i].X[k]);
      if (d2 < best) best = d2, s->p[i].lam = old[j].lam * s->p[i].area / old[j].area;
    }
  }
  free(old);
  return rc;
}

void nh_skull_state_save(const nh_skull *s, nh_bytes *b) {
  int32_t n = s->n, active = s->active;
  nh_bytes_put(b, &n, sizeof n);
  for (int i = 0; i < s->n; i++) nh_bytes_put(b, &s->p[i].lam, sizeof s->p[i].lam);
  nh_bytes_put(b, s->force, sizeof s->force);
  nh_bytes_put(b, &active, sizeof active);
}

int nh_skull_state_load(nh_skull *s, nh_byte_reader *r) {
  int32_t n = -1, active = 0;
  nh_bytes_get(r, &n, sizeof n);
  NH_CHECK(!r->short_read && n == s->n, NH_ERR_INPUT,
           "the checkpoint's skull has %d contact points, the restored mesh %d", (int)n, s->n);
  for (int i = 0; i < s->n; i++) nh_bytes_get(r, &s->p[i].lam, sizeof s->p[i].lam);
  nh_bytes_get(r, s->force, sizeof s->force);
  nh_bytes_get(r, &active, sizeof active);
  s->active = active;
  return NH_OK;
}

double nh_skull_missed(const nh_skull *s, const nh_mesh *m, const double *u) {
  double worst = 0.0;
  for (int i = 0; i < s->n; i++) {
    if (s->p[i].row >= 0) continue;
    double x[3], N[8], nrm[3];
    if (s->kind == NH_SKULL_ROWS_MORTAR) {
      worst = fmax(worst, -nh_skull_row_gap(s, m, u, i, NULL, NULL, nrm) / s->p[i].edge);
      continue;
    }
    nh_skull_position(m, u, &s->p[i], x, N);
    worst = fmax(worst, (nh_skull_wall(&s->domain, x, nrm) - s->gap) / s->p[i].edge);
  }
  return worst;
}

/* A point's gap g = gap − φ_skull(x) at its current position x = P + u(P)
 * (P at natural coordinates xi of cell c) and its row's direction there,
 * as nh_skull_rows makes them (the skull's inward normal; at the rest
 * position P for a point on a crease), with its shape values N. */
static double nh_skull_gap_at(const nh_skull *s, const nh_mesh *m, const double *u, int c,
                              const double xi[3], const double P[3], int crease, double dir[3],
                              double N[8]) {
  nh_skull_point q = {.cell = c};
  double x[3], nrm[3];
  memcpy(q.X, P, sizeof q.X);
  memcpy(q.xi, xi, sizeof q.xi);
  nh_skull_position(m, u, &q, x, N);
  const double g = s->gap - nh_skull_wall(&s->domain, x, nrm);
  if (crease) nh_skull_wall(&s->domain, P, nrm);
  for (int k = 0; k < 3; k++) dir[k] = -nrm[k];
  return g;
}

/* n·w at a point of cell c with shape values N, for field w. */
static double nh_skull_normal_value(const nh_mesh *m, const double *w, int c, const double N[8],
                                    const double dir[3]) {
  double s = 0.0;
  for (int a = 0; a < 8; a++)
    for (int k = 0; k < 3; k++) s += N[a] * dir[k] * w[3 * m->cells[8 * c + a] + k];
  return s;
}

/* The constraint-data term's fine data (docs/theory.md §6.6, "Constraint
 * data"): each leaf's points one lattice finer, each given to the nearest
 * point of the same leaf whose normal faces its way (the nearest of any if
 * none does), weighted by its share of the areas the point receives. */
int nh_skull_data_change(nh_skull *s, const nh_mesh *m, const double *u, int n_fields,
                         const double *w, int stride, double *dc, double *dw) {
  if (s->n_fine < m->n_cells) {
    NH_TRY(nh_realloc((void **)&s->fine, (size_t)m->n_cells, sizeof *s->fine));
    memset(s->fine + s->n_fine, 0, sizeof *s->fine * (size_t)(m->n_cells - s->n_fine));
    s->n_fine = m->n_cells;
  }
  const size_t n3 = 3 * (size_t)m->n_nodes;
  for (int i = 0; i < s->n; i++) {
    const nh_skull_point *p = &s->p[i];
    if (p->row < 0) continue;
    if (s->kind == NH_SKULL_ROWS_MORTAR) { /* not re-sampled: no data term (docs/theory.md §5c) */
      if (dc) dc[p->row] = 0.0;
      for (int q = 0; q < n_fields; q++) dw[(size_t)stride * q + p->row] = 0.0;
      continue;
    }
    const int c = p->leaf;
    double Xe[24];
    nh_mesh_cell_coords(m, m->X, c, Xe);
    nh_skull_cell *f = &s->fine[c];
    if (!f->done || memcmp(f->Xe, Xe, sizeof Xe)) NH_TRY(nh_skull_leaf(s, Xe, 1, f, NULL));
    int first = i, last = i; /* the leaf's points: consecutive (nh_skull_build) */
    while (first > 0 && s->p[first - 1].leaf == c) first--;
    while (last + 1 < s->n && s->p[last + 1].leaf == c) last++;
    double dir_i[3], N_i[8];
    const double g_i = nh_skull_gap_at(s, m, u, p->cell, p->xi, p->X, p->crease, dir_i, N_i);
    double area = 0.0, sum_g = 0.0;
    for (int q = 0; q < n_fields; q++) dw[(size_t)stride * q + p->row] = 0.0;
    for (int j = 0; j < f->n_pt; j++) {
      double nrm[3], xi[3], dir[3], N[8];
      nh_skull_distance(&s->domain, f->P[j], nrm);
      if (nh_skull_nearest_facing(s->p, first, last, f->P[j], nrm) != i) continue;
      if (f->own)
        memcpy(xi, f->xi[j], sizeof xi);
      else if (nh_hex_invert(Xe, f->P[j], xi) != NH_OK)
        continue;
      /* differences to the row's own values: 0 to the last bit where the
       * points are the same */
      area += f->area[j];
      sum_g += f->area[j] * (nh_skull_gap_at(s, m, u, c, xi, f->P[j], p->crease, dir, N) - g_i);
      for (int q = 0; q < n_fields; q++) {
        const double *wq = w + n3 * q;
        dw[(size_t)stride * q + p->row] +=
            f->area[j] * (nh_skull_normal_value(m, wq, c, N, dir) -
                          nh_skull_normal_value(m, wq, p->cell, N_i, dir_i));
      }
    }
    if (dc) dc[p->row] = area > 0.0 ? sum_g / area : 0.0;
    for (int q = 0; q < n_fields; q++) dw[(size_t)stride * q + p->row] /= area > 0.0 ? area : 1.0;
  }
  return NH_OK;
}
