/* hanging.c — hanging nodes of a nonconforming hexahedral mesh (docs/theory.md,
 * "Hanging nodes").
 *
 * A node is hanging when it lies on the boundary (a face or an edge) of a
 * leaf without being one of that leaf's corners: the leaf does not see it, so
 * without a constraint the displacement would jump there. Its value is tied
 * to the trilinear interpolation of the leaf at the node's natural
 * coordinates; when several leaves contain it (e.g. on an edge shared by two
 * coarse cells) the coarsest is used (ties: the lowest cell index), which is
 * the one whose interpolation all finer ones agree with.
 *
 * Detection: node rest positions are sorted into buckets the size of the
 * smallest leaf; each leaf visits the buckets its bounding box covers and
 * tests the nodes there (natural coordinates exactly for box-shaped leaves,
 * by Newton inversion otherwise). A node strictly inside a leaf means a
 * broken mesh and is reported.
 *
 * Chains: a master can itself be hanging (a refined cell next to a cell
 * refined twice). Each hanging node's masters are expanded recursively until
 * only non-hanging nodes remain, merging repeated masters; a cycle is
 * detected by marking nodes in progress.
 *
 * Aggregated nodes (docs/theory.md §5c, "Aggregated nodes"; Badia, Verdugo
 * & Martín 2018, "The aggregated unfitted finite element method for
 * elliptic problems") are the same mechanism with a root leaf that does
 * not contain the node: an ill-posed node of an immersed domain (a corner
 * only of leaves with tissue fraction below the threshold) takes the
 * trilinear field of a nearby well-posed leaf, extrapolated to its natural
 * coordinates outside [−1, 1]³ (nh_find_aggregated). They enter the raw
 * table next to the hanging nodes, so chains through either kind resolve to
 * free masters, and everything downstream (elimination u = P u_free, the
 * Lagrange rows, the contact rows' J through P, interpolation of fields)
 * treats both alike. Extrapolation of a box leaf's trilinear field
 * reproduces every linear field, so the weights sum to 1 and reproduce x. */
#include "mesh/mesh.h"

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

void nh_hanging_destroy(nh_hanging **hanging) {
  if (!hanging || !*hanging) return;
  nh_hanging *h = *hanging;
  free(h->node);
  free(h->start);
  free(h->master);
  free(h->weight);
  free(h->index);
  free(h->aggregated);
  free(h);
  *hanging = NULL;
}

void nh_hanging_interpolate(const nh_hanging *h, double *field, int comps) {
  if (!h) return;
  for (int k = 0; k < h->n_hanging; k++) {
    double *f = field + (size_t)comps * h->node[k];
    for (int i = 0; i < comps; i++) f[i] = 0.0;
    for (int p = h->start[k]; p < h->start[k + 1]; p++)
      for (int i = 0; i < comps; i++)
        f[i] += h->weight[p] * field[(size_t)comps * h->master[p] + i];
  }
}

typedef struct {
  int64_t key;
  int node;
} nh_bucket_entry;

static int nh_entry_cmp(const void *a, const void *b) {
  const nh_bucket_entry *x = a, *y = b;
  if (x->key != y->key) return x->key < y->key ? -1 : 1;
  return (x->node > y->node) - (x->node < y->node);
}

/* Box leaves: natural coordinates by scaling; others by Newton. */
static int nh_natural(const double Xe[24], const double x[3], double xi[3]) {
  int box = 1;
  for (int a = 0; a < 8 && box; a++)
    for (int k = 0; k < 3 && box; k++) {
      double want = nh_hex_corner[a][k] < 0 ? Xe[k] : Xe[18 + k];
      box = fabs(Xe[3 * a + k] - want) <= 1e-12 * fabs(Xe[18 + k] - Xe[k]);
    }
  if (box) {
    for (int k = 0; k < 3; k++) xi[k] = -1.0 + 2.0 * (x[k] - Xe[k]) / (Xe[18 + k] - Xe[k]);
    return NH_OK;
  }
  return nh_hex_invert(Xe, x, xi);
}

/* Raw (unresolved) masters of each node: the corners of its coarsest leaf. */
/* Roots tied with the best one that an aggregated node also takes (its
 * mirror images about the domain's centre in x, y, z: at most 7). */
#define NH_AGG_TWINS 7

typedef struct {
  int *cell;       /* per node: the leaf it hangs on, or -1 */
  double *xi;      /* 3 per node */
  int *twin;       /* NH_AGG_TWINS per node (aggregation only, else NULL): more roots tied with
                      cell in every mirror-invariant key, -1 after the last; the node is then the
                      mean of all its roots' extrapolations */
  double *twin_xi; /* 3 per twin */
} nh_raw;

static int nh_find_raw(const nh_mesh *m, const unsigned char *skip, nh_raw *raw) {
  int n = m->n_nodes, rc = NH_OK;
  double bucket = INFINITY;
  for (int l = 0; l < m->n_leaves; l++) bucket = fmin(bucket, nh_mesh_cell_size(m, m->leaves[l]));
  const double tol = 1e-9 * bucket; /* positions: far below any cell size */
  double lo[3] = {INFINITY, INFINITY, INFINITY};
  for (int i = 0; i < n; i++)
    for (int k = 0; k < 3; k++) lo[k] = fmin(lo[k], m->X[3 * i + k]);
  int64_t dim[3] = {0, 0, 0};
  for (int i = 0; i < n; i++)
    for (int k = 0; k < 3; k++) {
      int64_t b = (int64_t)floor((m->X[3 * i + k] - lo[k]) / bucket) + 1;
      if (b + 1 > dim[k]) dim[k] = b + 1;
    }
  nh_bucket_entry *e = nh_calloc((size_t)(n ? n : 1), sizeof *e);
  if (!e) return NH_ERROR(NH_ERR_MEMORY, "out of memory detecting hanging nodes");
  for (int i = 0; i < n; i++) {
    int64_t b[3];
    for (int k = 0; k < 3; k++) b[k] = (int64_t)floor((m->X[3 * i + k] - lo[k]) / bucket);
    e[i].key = b[0] + dim[0] * (b[1] + dim[1] * b[2]);
    e[i].node = i;
  }
  qsort(e, (size_t)n, sizeof *e, nh_entry_cmp);
  for (int i = 0; i < n; i++) raw->cell[i] = -1;
  for (int l = 0; l < m->n_leaves && !rc; l++) {
    int c = m->leaves[l];
    double Xe[24], bmin[3] = {INFINITY, INFINITY, INFINITY},
                   bmax[3] = {-INFINITY, -INFINITY, -INFINITY};
    nh_mesh_cell_coords(m, m->X, c, Xe);
    for (int a = 0; a < 8; a++)
      for (int k = 0; k < 3; k++)
        bmin[k] = fmin(bmin[k], Xe[3 * a + k]), bmax[k] = fmax(bmax[k], Xe[3 * a + k]);
    int64_t b0[3], b1[3];
    for (int k = 0; k < 3; k++) {
      b0[k] = (int64_t)floor((bmin[k] - tol - lo[k]) / bucket);
      b1[k] = (int64_t)floor((bmax[k] + tol - lo[k]) / bucket);
      if (b0[k] < 0) b0[k] = 0;
    }
    const int *corner = m->cells + 8 * c;
    for (int64_t bz = b0[2]; bz <= b1[2]; bz++)
      for (int64_t by = b0[1]; by <= b1[1]; by++)
        for (int64_t bx = b0[0]; bx <= b1[0]; bx++) {
          int64_t key = bx + dim[0] * (by + dim[1] * bz);
          int lo_i = 0, hi_i = n; /* first entry with this key */
          while (lo_i < hi_i) {
            int mid = (lo_i + hi_i) / 2;
            if (e[mid].key < key)
              lo_i = mid + 1;
            else
              hi_i = mid;
          }
          for (int p = lo_i; p < n && e[p].key == key; p++) {
            int v = e[p].node;
            const double *x = m->X + 3 * v;
            if (x[0] < bmin[0] - tol || x[0] > bmax[0] + tol || x[1] < bmin[1] - tol ||
                x[1] > bmax[1] + tol || x[2] < bmin[2] - tol || x[2] > bmax[2] + tol)
              continue;
            int is_corner = 0;
            for (int a = 0; a < 8; a++) is_corner |= corner[a] == v;
            if (is_corner) continue;
            double xi[3];
            if (nh_natural(Xe, x, xi)) continue;
            double amax = fmax(fabs(xi[0]), fmax(fabs(xi[1]), fabs(xi[2])));
            if (amax > 1 + 1e-8) continue;
            if (amax < 1 - 1e-8) {
              rc = NH_ERROR(NH_ERR_INTERNAL, "node %d lies inside leaf cell %d: broken mesh", v, c);
              break;
            }
            if (skip && skip[v]) continue;
            int old = raw->cell[v];
            if (old < 0 || m->level[c] < m->level[old] ||
                (m->level[c] == m->level[old] && c < old)) {
              raw->cell[v] = c;
              memcpy(raw->xi + 3 * v, xi, sizeof xi);
            }
          }
        }
  }
  free(e);
  return rc;
}

/* A candidate root's rank: the smaller Lebesgue constant of the
 * extrapolation first, Λ = Σ_a |N_a(ξ_v)| = Π_k max(1, |ξ_k|) (the factor by
 * which the root's nodal values, and their errors, are amplified at the
 * node; max_k |ξ_k| ranked a root one cell off in two axes, Λ = 9, with one
 * off in a single axis, Λ = 3, and left the choice to the tissue fraction:
 * the brainstem of tests/anatomy.py then hung each layer's outer nodes on
 * the layer above, a chain that made the stalk up to 13 times too stiff on
 * some grids, docs/theory.md §5c), then one without a hanging corner, the larger tissue fraction,
 * the centre nearer the domain's centre in |x|, then |y|, then |z| (so that a mirror image of the
 * mesh about the domain's centre chooses the mirror image of the root: the cell index is not mirror
 * invariant), the lower index. Reals compare with a relative tolerance of 1e-9 (mirror images agree
 * to round-off). */
typedef struct {
  int cell, hanging;
  double lebesgue, fraction, xi[3], offset[3];
} nh_root;

static int nh_differ(double a, double b) {
  return fabs(a - b) > 1e-9 * fmax(1.0, fabs(b));
}

/* 1: a before b; -1: b before a; 0: tied in every mirror-invariant key (a
 * mirror image of b about the domain's centre, as for a node on a mirror plane). */
static int nh_root_order(const nh_root *a, const nh_root *b) {
  if (b->cell < 0) return 1;
  if (nh_differ(a->lebesgue, b->lebesgue)) return a->lebesgue < b->lebesgue ? 1 : -1;
  if (a->hanging != b->hanging) return a->hanging < b->hanging ? 1 : -1;
  if (nh_differ(a->fraction, b->fraction)) return a->fraction > b->fraction ? 1 : -1;
  for (int k = 0; k < 3; k++)
    if (fabs(a->offset[k] - b->offset[k]) > 1e-9 * fmax(a->offset[k], b->offset[k]))
      return a->offset[k] < b->offset[k] ? 1 : -1;
  return 0;
}

/* True if node w's value depends on an ill-posed node (flag): w is one, or
 * it hangs on a leaf whose corners (with a nonzero weight) do, through
 * chains of at most `depth` hanging nodes (deeper: assumed to). A root with
 * such a corner would make its aggregated node a master of itself (a
 * hanging corner on the face of a coarse leaf that has the node as a corner). */
static int nh_depends_on_ill(const nh_mesh *m, const nh_raw *raw, const unsigned char *flag, int w,
                             int depth) {
  if (flag[w]) return 1;
  if (raw->cell[w] < 0) return 0;
  if (depth == 0) return 1;
  double N[8];
  nh_hex_shape(raw->xi + 3 * w, N);
  for (int a = 0; a < 8; a++)
    if (fabs(N[a]) >= 1e-14 &&
        nh_depends_on_ill(m, raw, flag, m->cells[8 * raw->cell[w] + a], depth - 1))
      return 1;
  return 0;
}

/* The ill-posed nodes' roots into raw (cell, ξ), flagged in *is_agg (per
 * node, allocated here). Rings of leaves: ring 0 the node's own leaves,
 * ring r + 1 the leaves sharing a corner with ring r; the root is the best
 * well-posed leaf (tissue, and no ill-posed corner) of the first ring that
 * has one. */
static int nh_find_aggregated(const nh_mesh *m, const unsigned char *skip,
                              const nh_aggregation *agg, nh_raw *raw, unsigned char **is_agg,
                              int *n_orphans) {
  const int n = m->n_nodes;
  int rc = NH_OK, orphans = 0, cap_ring = 0, cap_next = 0;
  int *start = NULL, *leaf = NULL; /* node -> the leaves it is a corner of (CSR) */
  if ((rc = nh_mesh_node_leaves(m, &start, &leaf))) return rc;
  int *stamp = nh_calloc((size_t)(m->n_cells ? m->n_cells : 1), sizeof(int));
  int *ring = NULL, *next = NULL;
  unsigned char *flag = nh_calloc((size_t)(n ? n : 1), 1);
  if (!stamp || !flag) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory: aggregated nodes");
    goto done;
  }
  const double thr = agg->threshold;
  for (int v = 0; v < n; v++) /* the ill-posed nodes */
    flag[v] = raw->cell[v] < 0 && !(skip && skip[v]) && !(agg->keep && agg->keep[v]) &&
              start[v] < start[v + 1] && agg->support[v] > 0.0 && agg->support[v] < thr;
  for (int v = 0; v < n && !rc; v++) {
    if (!flag[v]) continue;
    int n_ring = 0;
    for (int p = start[v]; p < start[v + 1]; p++) {
      if ((rc = nh_grow((void **)&ring, &cap_ring, n_ring + 1, sizeof(int)))) break;
      ring[n_ring++] = leaf[p];
      stamp[leaf[p]] = v + 1;
    }
    nh_root best = {.cell = -1}, twin[NH_AGG_TWINS];
    int n_twin = 0;
    for (int r = 0; r < NH_AGGREGATE_RINGS && best.cell < 0 && !rc; r++) {
      int n_next = 0;
      for (int i = 0; i < n_ring && !rc; i++)
        for (int a = 0; a < 8 && !rc; a++) {
          int u = m->cells[8 * ring[i] + a];
          for (int p = start[u]; p < start[u + 1] && !rc; p++) {
            int c = leaf[p];
            if (stamp[c] == v + 1) continue;
            stamp[c] = v + 1;
            if ((rc = nh_grow((void **)&next, &cap_next, n_next + 1, sizeof(int)))) break;
            next[n_next++] = c;
            int ill = 0; /* a root: tissue, and no corner that is or hangs on an ill-posed one */
            for (int b = 0; b < 8 && !ill; b++)
              ill = nh_depends_on_ill(m, raw, flag, m->cells[8 * c + b], NH_AGGREGATE_CHAIN);
            if (ill || !(agg->fraction[c] > 0.0)) continue;
            double Xe[24];
            nh_root cand = {.cell = c, .fraction = agg->fraction[c]};
            nh_mesh_cell_coords(m, m->X, c, Xe);
            if (nh_natural(Xe, m->X + 3 * v, cand.xi)) continue;
            cand.lebesgue = 1.0;
            for (int k = 0; k < 3; k++) cand.lebesgue *= fmax(1.0, fabs(cand.xi[k]));
            for (int k = 0; k < 3; k++) {
              double ctr = 0.0;
              for (int b = 0; b < 8; b++) ctr += 0.125 * Xe[3 * b + k];
              cand.offset[k] = fabs(ctr - m->domain.center[k]);
            }
            for (int b = 0; b < 8; b++) cand.hanging |= raw->cell[m->cells[8 * c + b]] >= 0;
            const int order = nh_root_order(&cand, &best);
            if (order > 0) {
              best = cand, n_twin = 0;
            } else if (order == 0 && n_twin < NH_AGG_TWINS) { /* mirror images: all, averaged */
              twin[n_twin++] = cand;
            }
          }
        }
      int *t = ring, tc = cap_ring;
      ring = next, cap_ring = cap_next, n_ring = n_next;
      next = t, cap_next = tc;
    }
    if (rc) break;
    if (best.cell < 0) {
      orphans++;
      flag[v] = 2; /* ill posed without a root: stays free */
      continue;
    }
    raw->cell[v] = best.cell;
    memcpy(raw->xi + 3 * v, best.xi, sizeof best.xi);
    for (int t = 0; t < n_twin; t++) {
      raw->twin[NH_AGG_TWINS * v + t] = twin[t].cell;
      memcpy(raw->twin_xi + 3 * (NH_AGG_TWINS * v + t), twin[t].xi, sizeof twin[t].xi);
    }
  }
  for (int v = 0; v < n; v++) flag[v] = flag[v] == 1;
done:
  free(start), free(leaf), free(stamp), free(ring), free(next);
  if (rc) {
    free(flag);
    return rc;
  }
  *is_agg = flag;
  if (n_orphans) *n_orphans = orphans;
  return NH_OK;
}

/* The aggregated flags of the resolved table. */
static int nh_hanging_mark_aggregated(nh_hanging *h, const unsigned char *is_agg) {
  h->aggregated = nh_calloc((size_t)(h->n_hanging ? h->n_hanging : 1), 1);
  if (!h->aggregated) return NH_ERROR(NH_ERR_MEMORY, "out of memory: aggregated nodes");
  h->n_aggregated = 0;
  for (int k = 0; k < h->n_hanging; k++) {
    h->aggregated[k] = is_agg && is_agg[h->node[k]];
    h->n_aggregated += h->aggregated[k];
  }
  return NH_OK;
}

/* Resolved master lists, built recursively. */
typedef struct {
  const nh_mesh *m;
  nh_raw *raw;
  int *state; /* 0 new, 1 in progress, 2 done */
  int **list;
  double **wts;
  int *len;
} nh_resolver;

static int nh_add_master(nh_resolver *r, int v, int master, double w, int *cap) {
  for (int p = 0; p < r->len[v]; p++)
    if (r->list[v][p] == master) {
      r->wts[v][p] += w;
      return NH_OK;
    }
  if (r->len[v] == *cap) {
    int c2 = *cap;
    NH_TRY(nh_grow((void **)&r->list[v], cap, *cap + 1, sizeof(int)));
    NH_TRY(nh_grow((void **)&r->wts[v], &c2, c2 + 1, sizeof(double)));
  }
  r->list[v][r->len[v]] = master;
  r->wts[v][r->len[v]++] = w;
  return NH_OK;
}

static int nh_resolve(nh_resolver *r, int v) {
  if (r->state[v] == 2) return NH_OK;
  if (r->state[v] == 1)
    return NH_ERROR(NH_ERR_INTERNAL, "hanging node %d depends on itself (a cycle of masters)", v);
  r->state[v] = 1;
  const int *twin = r->raw->twin ? r->raw->twin + NH_AGG_TWINS * v : NULL;
  int n_roots = 1, cap = 0;
  while (twin && n_roots <= NH_AGG_TWINS && twin[n_roots - 1] >= 0) n_roots++;
  const double scale = 1.0 / n_roots;
  for (int root = 0; root < n_roots; root++) {
    const int *corner = r->m->cells + 8 * (root ? twin[root - 1] : r->raw->cell[v]);
    double N[8];
    nh_hex_shape(root ? r->raw->twin_xi + 3 * (NH_AGG_TWINS * v + root - 1) : r->raw->xi + 3 * v,
                 N);
    for (int a = 0; a < 8; a++) {
      if (fabs(N[a]) < 1e-14) continue;
      int u = corner[a];
      if (r->raw->cell[u] < 0) {
        NH_TRY(nh_add_master(r, v, u, scale * N[a], &cap));
      } else {
        NH_TRY(nh_resolve(r, u));
        for (int p = 0; p < r->len[u]; p++)
          NH_TRY(nh_add_master(r, v, r->list[u][p], scale * N[a] * r->wts[u][p], &cap));
      }
    }
  }
  r->state[v] = 2;
  return NH_OK;
}

int nh_hanging_detect(const nh_mesh *m, const unsigned char *skip, nh_hanging **out) {
  return nh_hanging_detect_aggregated(m, skip, NULL, out, NULL);
}

int nh_hanging_detect_aggregated(const nh_mesh *m, const unsigned char *skip,
                                 const nh_aggregation *agg, nh_hanging **out, int *n_orphans) {
  *out = NULL;
  unsigned char *is_agg = NULL;
  if (n_orphans) *n_orphans = 0;
  int n = m->n_nodes, rc = NH_OK;
  nh_raw raw = {.cell = nh_calloc((size_t)(n ? n : 1), sizeof(int)),
                .xi = nh_calloc(3 * (size_t)(n ? n : 1), sizeof(double))};
  nh_resolver r = {.m = m, .raw = &raw};
  r.state = nh_calloc((size_t)(n ? n : 1), sizeof(int));
  r.list = nh_calloc((size_t)(n ? n : 1), sizeof(int *));
  r.wts = nh_calloc((size_t)(n ? n : 1), sizeof(double *));
  r.len = nh_calloc((size_t)(n ? n : 1), sizeof(int));
  nh_hanging *h = nh_calloc(1, sizeof *h);
  if (!raw.cell || !raw.xi || !r.state || !r.list || !r.wts || !r.len || !h) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory detecting hanging nodes");
    goto done;
  }
  if ((rc = nh_find_raw(m, skip, &raw))) goto done;
  if (agg) {
    raw.twin = nh_calloc(NH_AGG_TWINS * (size_t)(n ? n : 1), sizeof(int));
    raw.twin_xi = nh_calloc(3 * NH_AGG_TWINS * (size_t)(n ? n : 1), sizeof(double));
    if (!raw.twin || !raw.twin_xi) {
      rc = NH_ERROR(NH_ERR_MEMORY, "out of memory detecting hanging nodes");
      goto done;
    }
    for (size_t v = 0; v < NH_AGG_TWINS * (size_t)n; v++) raw.twin[v] = -1;
    if ((rc = nh_find_aggregated(m, skip, agg, &raw, &is_agg, n_orphans))) goto done;
  }
  int count = 0, total = 0;
  for (int v = 0; v < n && !rc; v++)
    if (raw.cell[v] >= 0) {
      rc = nh_resolve(&r, v);
      count++;
      total += r.len[v];
    }
  if (rc) goto done;
  h->n_hanging = count;
  h->node = nh_calloc((size_t)(count ? count : 1), sizeof(int));
  h->start = nh_calloc((size_t)(count + 1), sizeof(int));
  h->master = nh_calloc((size_t)(total ? total : 1), sizeof(int));
  h->weight = nh_calloc((size_t)(total ? total : 1), sizeof(double));
  h->index = nh_calloc((size_t)(n ? n : 1), sizeof(int));
  if (!h->node || !h->start || !h->master || !h->weight || !h->index) {
    rc = NH_ERROR(NH_ERR_MEMORY, "out of memory detecting hanging nodes");
    goto done;
  }
  int k = 0, p = 0;
  for (int v = 0; v < n; v++) {
    h->index[v] = -1;
    if (raw.cell[v] < 0) continue;
    h->index[v] = k;
    h->node[k] = v;
    h->start[k] = p;
    for (int q = 0; q < r.len[v]; q++, p++) h->master[p] = r.list[v][q], h->weight[p] = r.wts[v][q];
    k++;
  }
  h->start[k] = p;
  rc = nh_hanging_mark_aggregated(h, is_agg);
done:
  free(is_agg);
  if (r.list)
    for (int v = 0; v < n; v++) free(r.list[v]), free(r.wts[v]);
  free(r.list), free(r.wts), free(r.len), free(r.state), free(raw.cell), free(raw.xi);
  free(raw.twin), free(raw.twin_xi);
  if (rc) nh_hanging_destroy(&h);
  *out = h;
  return rc;
}
